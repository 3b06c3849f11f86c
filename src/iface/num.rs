//! Decimal numbers on the wire, without `core::fmt`'s float code.
//!
//! Why hand-written: `f32::from_str` and `{}` on an f32 pull in core's `dec2flt`/`flt2dec`
//! (several KiB of flash each) into a firmware that has a few hundred bytes to spare, and
//! `from_str` accepts `nan`, `inf` and exponents, which no setting wants. The interface only
//! needs plain decimals of a few digits: `-12.345`, `5`, `0.5`.

use core::fmt;

/// Most digits a decimal may have (integer and fraction together): 7 keep the mantissa below
/// 2²⁴, so it and the power of ten are exact in f32 and their one division is correctly rounded:
/// the result is the f32 nearest the decimal, as `str::parse` gives.
pub const MAX_DIGITS: usize = 7;

/// A plain decimal: an optional sign, digits, optionally `.` and more digits (at least one digit
/// in all, at most [`MAX_DIGITS`]). `nan`, `inf`, exponents, `+`, spaces, a bare `.` and empty
/// strings are `None`.
pub fn parse_decimal(s: &str) -> Option<f32> {
    let (neg, body) = match s.as_bytes().first() {
        Some(b'-') => (true, s.get(1..)?),
        _ => (false, s),
    };
    let mut mantissa: u32 = 0;
    let mut digits = 0usize;
    let mut frac_digits: Option<u32> = None;
    for &c in body.as_bytes() {
        match c {
            b'0'..=b'9' => {
                digits += 1;
                if digits > MAX_DIGITS {
                    return None;
                }
                mantissa = mantissa * 10 + u32::from(c - b'0');
                if let Some(f) = frac_digits.as_mut() {
                    *f += 1;
                }
            }
            b'.' if frac_digits.is_none() => frac_digits = Some(0),
            _ => return None,
        }
    }
    if digits == 0 {
        return None;
    }
    let x = mantissa as f32 / 10u32.pow(frac_digits.unwrap_or(0)) as f32;
    Some(if neg { -x } else { x })
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

/// A comma-separated list of exactly `N` decimals (`-1.8,0.81`).
pub fn parse_list<const N: usize>(s: &str) -> Option<[f32; N]> {
    let mut out = [0.0f32; N];
    let mut parts = s.split(',');
    for slot in out.iter_mut() {
        *slot = parse_decimal(parts.next()?)?;
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

impl fmt::Display for Fixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Fixed(x, decimals) = *self;
        let decimals = u32::from(decimals.min(6));
        let scale = 10u32.pow(decimals);
        let scaled = x * scale as f32;
        // NaN fails both comparisons.
        if !(scaled > -2.0e9 && scaled < 2.0e9) {
            return f.write_str("-");
        }
        let n = if scaled < 0.0 { (scaled - 0.5) as i32 } else { (scaled + 0.5) as i32 };
        let sign = if n < 0 { "-" } else { "" };
        let n = n.unsigned_abs();
        if decimals == 0 {
            write!(f, "{sign}{n}")
        } else {
            write!(f, "{sign}{}.{:0width$}", n / scale, n % scale, width = decimals as usize)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::ToString;

    #[test]
    fn plain_decimals_parse_exactly_as_written() {
        for (s, x) in
            [("5", 5.0f32), ("5.00", 5.0), ("-1.8", -1.8), ("0.5", 0.5), (".5", 0.5), ("7.", 7.0), ("2.5", 2.5)]
        {
            assert_eq!(parse_decimal(s), Some(x), "{s}");
        }
        // Against the standard library's parser on a grid of decimals.
        for i in -20_000i32..20_000 {
            let s = format!("{}.{:03}", i / 1000, (i % 1000).abs());
            let s = if i < 0 && i > -1000 { format!("-{s}") } else { s };
            assert_eq!(parse_decimal(&s), Some(s.parse::<f32>().unwrap()), "{s}");
        }
    }

    #[test]
    fn anything_but_a_plain_decimal_is_refused() {
        for s in [
            "",
            "-",
            ".",
            "nan",
            "NaN",
            "inf",
            "-inf",
            "1e3",
            "+5",
            " 5",
            "5 ",
            "1.2.3",
            "0x10",
            "5,0",
            "12345678",
            "1.2345678",
        ] {
            assert_eq!(parse_decimal(s), None, "{s:?}");
        }
    }

    #[test]
    fn lists_need_exactly_their_length() {
        assert_eq!(parse_list::<2>("-1.8,0.81"), Some([-1.8, 0.81]));
        assert_eq!(parse_list::<2>("-1.8"), None);
        assert_eq!(parse_list::<2>("-1.8,0.81,1"), None);
        assert_eq!(parse_list::<2>("-1.8,nan"), None);
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
