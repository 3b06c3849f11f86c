//! Decimal numbers on the wire, without `core::fmt`'s float code.
//!
//! Why hand-written: `f32::from_str` and `{}` on an f32 pull in core's `dec2flt`/`flt2dec`
//! (several KiB of flash each) into a firmware that has a few hundred bytes to spare, and
//! `from_str` accepts `nan`, `inf` and exponents, which no setting wants. The interface only
//! needs plain decimals of a few digits: `-12.345`, `5`, `0.5`.
//!
//! A [`Decimal`] keeps how the value was written as well as its value: how many decimals it
//! carries and how many significant digits, so that a setting can refuse a value finer than
//! it keeps (`5.001` for a setpoint kept and shown to 0.01 °C) rather than round it out of
//! sight, and one with more digits than an f32 holds.

use core::fmt;

use super::sink::Sink;

/// Most significant digits a setting's value may have: 7 keep the mantissa below 2²⁴, so it and
/// the power of ten are exact in f32 and their one division is correctly rounded: the value is
/// the f32 nearest the decimal, as `str::parse` gives. Zeros before the first non-zero digit and
/// after the last non-zero decimal are not counted (`0005.5000` has 2).
pub const MAX_DIGITS: u8 = 7;

/// A plain decimal as written: its value and how finely it is written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decimal {
    /// The value: the f32 nearest the decimal when it has at most [`MAX_DIGITS`] digits and 9
    /// decimals; otherwise within an f32 rounding or two of it (from its first 9 significant
    /// digits). Such a value can come out on a range's bound (`2.4999999999` as 2.5), which is
    /// why a setting checks its step too: no setting takes a value that fine.
    pub value: f32,
    /// Decimals up to the last non-zero one: `5.10` has 1, `5`, `5.` and `5.00` none
    /// (saturating at 255).
    pub decimals: u8,
    /// Significant digits: from the first non-zero digit through the last integer digit or the
    /// last non-zero decimal (`0.05` has 1, `100` 3, `5.10` 2, `1.05` 3; saturating at 255).
    pub digits: u8,
}

/// A plain decimal: an optional `-`, digits, optionally `.` and more digits (at least one digit
/// in all), of any length. `nan`, `inf`, exponents, `+`, spaces, a bare `.` and empty strings are
/// `None`. How many digits a setting takes is the setting's to check ([`Decimal`]).
pub fn parse_decimal(s: &str) -> Option<Decimal> {
    let (neg, mut body) = match s.as_bytes() {
        [b'-', rest @ ..] => (true, rest),
        b => (false, b),
    };
    // Zeros after the last non-zero decimal are no digits (and would cost the mantissa its
    // exactness: `1.2340000000` is 1234 × 10⁻³, not 123400000 rounded to f32 × 10⁻⁸).
    let mut any = false;
    if body.contains(&b'.') {
        while let [rest @ .., b'0'] = body {
            body = rest;
            any = true;
        }
    }
    let mut point = false;
    // value = mantissa × 10^exp, from the first 9 significant digits: they fit a u32 and are
    // more than an f32 resolves.
    let (mut mantissa, mut exp) = (0u32, 0i32);
    let (mut decimals, mut digits) = (0u8, 0u8);
    for &c in body {
        if c == b'.' && !point {
            point = true;
            continue;
        }
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            return None;
        }
        any = true;
        if point {
            decimals = decimals.saturating_add(1);
        }
        if digits > 0 || d != 0 {
            digits = digits.saturating_add(1);
        }
        if mantissa < 100_000_000 {
            mantissa = mantissa * 10 + u32::from(d);
            exp -= i32::from(point);
        } else if !point {
            exp += 1;
        }
    }
    if !any {
        return None;
    }
    let x = scale10(mantissa as f32, exp);
    Some(Decimal { value: if neg { -x } else { x }, decimals, digits })
}

/// `x` × 10^`e`: for −9 ≤ `e` < 0 one correctly rounded division (10⁹ and every power below it
/// are exact in f32), for `e` > 0 products exact while they stay below 2²⁴; beyond, a rounding
/// per step (only for values far outside what any setting takes).
fn scale10(mut x: f32, mut e: i32) -> f32 {
    let mut p = 1.0f32;
    while e < 0 && p < 1e9 {
        p *= 10.0;
        e += 1;
    }
    x /= p;
    while e < 0 {
        x /= 10.0;
        e += 1;
    }
    while e > 0 {
        x *= 10.0;
        e -= 1;
    }
    x
}

/// A whole number of at most 10 digits that fits a `u32` (`0`, `3600`, `4000000000`); anything
/// else, a sign or a `.` included, is `None`. For values past [`parse_decimal`]'s 7 digits: the
/// record's seconds, which pass 10⁷ after 116 days of service.
pub fn parse_whole(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 10 {
        return None;
    }
    let mut n: u32 = 0;
    for &c in s.as_bytes() {
        let d = c.checked_sub(b'0').filter(|d| *d <= 9)?;
        n = n.checked_mul(10)?.checked_add(u32::from(d))?;
    }
    Some(n)
}

/// A comma-separated list of exactly `N` decimals (`-1.8,0.81`), each with its text as written.
pub fn parse_list<const N: usize>(s: &str) -> Option<[(&str, Decimal); N]> {
    let mut out = [("", Decimal { value: 0.0, decimals: 0, digits: 0 }); N];
    let mut parts = s.split(',');
    for slot in out.iter_mut() {
        let t = parts.next()?;
        *slot = (t, parse_decimal(t)?);
    }
    if parts.next().is_some() {
        return None;
    }
    Some(out)
}

/// An f32 printed with a fixed number of decimals (at most 6), rounded half away from zero (in
/// f32: exact to the digit for the interface's values, which carry far fewer than 7 significant
/// digits); a non-finite value, or one whose scaled value passes ±2·10⁹, prints as `-` (the
/// interface's "no value").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed(pub f32, pub u8);

/// For the host and the tests (`to_string()`): the same text as [`super::sink::Sink::fixed`],
/// which the firmware writes it with.
impl fmt::Display for Fixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.fixed(self.0, self.1).map_err(|_| fmt::Error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::ToString;

    fn value(s: &str) -> Option<f32> {
        parse_decimal(s).map(|d| d.value)
    }

    #[test]
    fn plain_decimals_parse_exactly_as_written() {
        for (s, x) in
            [("5", 5.0f32), ("5.00", 5.0), ("-1.8", -1.8), ("0.5", 0.5), (".5", 0.5), ("7.", 7.0), ("2.5", 2.5)]
        {
            assert_eq!(value(s), Some(x), "{s}");
        }
        // Against the standard library's parser on a grid of decimals.
        for i in -20_000i32..20_000 {
            let s = format!("{}.{:03}", i / 1000, (i % 1000).abs());
            let s = if i < 0 && i > -1000 { format!("-{s}") } else { s };
            assert_eq!(value(&s), Some(s.parse::<f32>().unwrap()), "{s}");
        }
        // Every value of at most 7 significant digits and 9 decimals, as written with zeros around.
        for (m, d) in [(1u32, 9u32), (9_999_999, 7), (1_234_567, 0), (7_500_000, 6), (1, 0), (12_345, 9)] {
            let s = format!("{}", f64::from(m) / 10f64.powi(d as i32));
            let padded = format!("000{s}{}", if s.contains('.') { "000" } else { ".000" });
            for t in [s.clone(), padded, format!("-{s}")] {
                assert_eq!(value(&t), Some(t.parse::<f32>().unwrap()), "{t}");
            }
        }
    }

    #[test]
    fn a_decimal_counts_its_decimals_and_significant_digits_as_written() {
        for (s, decimals, digits) in [
            ("5", 0, 1),
            ("5.00000000", 0, 1),
            ("0004.50", 1, 2),
            ("5.001", 3, 4),
            ("2.4999", 4, 5),
            ("0.05", 2, 1),
            ("1.05", 2, 3),
            ("100", 0, 3),
            ("-0.0000001", 7, 1),
            ("12345678", 0, 8),
            ("-1.8594051", 7, 8),
            ("0", 0, 0),
            ("-0.000", 0, 0),
        ] {
            let d = parse_decimal(s).unwrap();
            assert_eq!((d.decimals, d.digits), (decimals, digits), "{s}");
        }
        // Beyond an f32's digits, the value is still near the decimal, whatever its length.
        for (s, x) in [
            ("2.4999999999", 2.5f32),
            ("5.00000000000001", 5.0),
            ("123456789012", 1.234_567_9e11),
            ("0.000000000000123", 1.23e-13),
            ("-99999999999999999999999999999999", -1e32),
        ] {
            let v = value(s).unwrap();
            assert!((v - x).abs() <= x.abs() * 1e-6, "{s}: {v}");
        }
        // A string of 81 digits (the longest a request can carry) neither panics nor saturates oddly.
        let long = "9".repeat(81);
        let d = parse_decimal(&long).unwrap();
        assert!(d.value > 1e38 && d.digits == 81 && d.decimals == 0, "{d:?}");
        let tiny = format!("0.{}1", "0".repeat(78));
        let d = parse_decimal(&tiny).unwrap();
        assert!(d.value >= 0.0 && d.value < 1e-30 && d.decimals == 79 && d.digits == 1, "{d:?}");
        assert_eq!(parse_decimal(&format!("1.{}", "0".repeat(300))).map(|d| d.decimals), Some(0));
        assert_eq!(parse_decimal(&format!("0.{}1", "0".repeat(300))).map(|d| d.decimals), Some(255));
    }

    #[test]
    fn anything_but_a_plain_decimal_is_refused() {
        for s in [
            "", "-", ".", "-.", "nan", "NaN", "inf", "-inf", "1e3", "+5", " 5", "5 ", "1.2.3", "0x10", "5,0", "--5",
            "5-", "١",
        ] {
            assert_eq!(parse_decimal(s), None, "{s:?}");
        }
    }

    #[test]
    fn lists_need_exactly_their_length() {
        let l = parse_list::<2>("-1.8,0.810").unwrap();
        assert_eq!(l.map(|(t, d)| (t, d.value, d.decimals)), [("-1.8", -1.8, 1), ("0.810", 0.81, 2)]);
        assert_eq!(parse_list::<2>("-1.8"), None);
        assert_eq!(parse_list::<2>("-1.8,0.81,1"), None);
        assert_eq!(parse_list::<2>("-1.8,nan"), None);
        assert_eq!(parse_list::<2>(","), None);
    }

    #[test]
    fn fixed_matches_std_formatting_and_prints_no_value_as_a_dash() {
        for i in -5000..5000 {
            let x = i as f32 * 0.0137;
            // Near a tie the f32 product rounds where std rounds the exact binary value: such
            // values are a 1-digit question neither answer settles.
            let frac = (f64::from(x) * 100.0).abs().fract();
            if (frac - 0.5).abs() < 1e-3 {
                continue;
            }
            assert_eq!(Fixed(x, 2).to_string(), format!("{:.2}", x as f64).replace("-0.00", "0.00"), "{x}");
            assert_eq!(Fixed(x, 0).to_string(), format!("{:.0}", (x as f64).round()).replace("-0", "0"), "{x}");
        }
        assert_eq!(Fixed(f32::NAN, 2).to_string(), "-");
        assert_eq!(Fixed(f32::INFINITY, 2).to_string(), "-");
        assert_eq!(Fixed(-0.004, 2).to_string(), "0.00");
        assert_eq!(Fixed(4.0, 2).to_string(), "4.00");
        assert_eq!(Fixed(-1.936244, 6).to_string(), "-1.936244");
        assert_eq!(Fixed(3.0e9, 0).to_string(), "-");
    }

    #[test]
    fn whole_numbers_take_ten_digits_and_nothing_else() {
        assert_eq!(parse_whole("0"), Some(0));
        assert_eq!(parse_whole("10000000"), Some(10_000_000));
        assert_eq!(parse_whole("4294967295"), Some(u32::MAX));
        for bad in ["", "4294967296", "00000000000", "-1", "+1", "1.0", "1e3", " 1", "x"] {
            assert_eq!(parse_whole(bad), None, "{bad}");
        }
    }
}
