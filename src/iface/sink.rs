//! Text out without `core::fmt`: the replies, the refusals and the `history` rows are written
//! through a [`Sink`], which takes string slices and writes integers and [`Fixed`] decimals
//! digit by digit.
//!
//! Why not `core::fmt`: `core::fmt::write` calls each argument's formatting function through a
//! pointer, and a `Display` may format again, so a call chain through it can nest without a
//! bound the image shows: `cargo xtask audit` cannot bound the stack of a firmware that links it
//! (README, "The whole stack is bounded"). It also cost ≈ 2 KB of flash in the interface build
//! (`Formatter::pad`, `pad_integral`, the integer `Display`s, `core::fmt::write`). What the
//! interface writes needs none of its generality: string slices, unsigned integers and decimals
//! of a fixed number of places ([`Fixed`]).
//!
//! A sink that runs out of room returns [`Full`] (what `core::fmt::Error` said before); the
//! writers stop at the first one. The firmware's reply buffer and `history` row are sinks; on the
//! host (feature `alloc`, and the crate's tests) so is a `String`, and `Display` for [`Fixed`] and
//! [`super::Refusal`] writes through the same code ([`core::fmt::Formatter`] is a sink).

use super::num::Fixed;

/// The sink has no room for what was written (some of it may have been kept: the caller marks
/// the whole text as lost, as the firmware's reply buffer does).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Full;

/// What a write returns.
pub type Written = Result<(), Full>;

/// Where text goes: string slices in, in order.
pub trait Sink {
    /// Appends `s`, or returns [`Full`] if it does not fit.
    fn str(&mut self, s: &str) -> Written;

    /// Appends `n` in decimal, without sign or padding.
    fn uint(&mut self, n: u64) -> Written {
        digits(self, n, 1)
    }

    /// Appends `x` as [`Fixed`] prints it: `decimals` places (at most 6), rounded half away from
    /// zero (in f32: exact to the digit for the interface's values, which carry far fewer than 7
    /// significant digits); a non-finite value, or one whose scaled value passes ±2·10⁹, is `-`,
    /// the interface's "no value".
    fn fixed(&mut self, x: f32, decimals: u8) -> Written {
        let decimals = decimals.min(6);
        let scale = 10u32.pow(u32::from(decimals));
        let scaled = x * scale as f32;
        // NaN fails both comparisons.
        if !(scaled > -2.0e9 && scaled < 2.0e9) {
            return self.str("-");
        }
        let n = if scaled < 0.0 { (scaled - 0.5) as i32 } else { (scaled + 0.5) as i32 };
        if n < 0 {
            self.str("-")?;
        }
        let n = n.unsigned_abs();
        if decimals == 0 {
            return self.uint(u64::from(n));
        }
        self.uint(u64::from(n / scale))?;
        self.str(".")?;
        digits(self, u64::from(n % scale), decimals)
    }
}

/// The decimal digits, one `&str` each.
const DIGITS: &str = "0123456789";

/// Appends `n` in decimal with at least `width` digits (zeros in front; at most 20), most
/// significant first, one [`Sink::str`] per digit: no recursion, no buffer to reverse or to turn
/// back into a `str` (`core::str::from_utf8` costs ≈ 500 B of flash; a buffer filled through
/// `heapless::String::push` cost more than this whole writer).
fn digits<S: Sink + ?Sized>(out: &mut S, n: u64, width: u8) -> Written {
    // The power of ten of the first digit written: n's own, or the width's.
    let (mut p, mut w) = (1u64, 1u8);
    // p ≤ n / 10 keeps 10·p ≤ n, and w < 20 keeps 10·p ≤ 10¹⁹: no overflow.
    while p <= n / 10 || w < width.min(20) {
        p *= 10;
        w += 1;
    }
    loop {
        let d = (n / p % 10) as usize;
        out.str(DIGITS.get(d..d + 1).unwrap_or("?"))?;
        if p < 10 {
            return Ok(());
        }
        p /= 10;
    }
}

/// A value with a wire text: what the crate's `put!` writer takes (its replies, refusals and
/// `history` rows).
pub trait Text {
    /// Writes the text to `out`.
    fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written;
}

impl Text for &str {
    fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
        out.str(self)
    }
}

impl Text for Fixed {
    fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
        out.fixed(self.0, self.1)
    }
}

macro_rules! text_uint {
    ($($t:ty),*) => {$(
        impl Text for $t {
            fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
                out.uint(u64::from(*self))
            }
        }
    )*};
}
text_uint!(u8, u16, u32, u64);

impl Text for usize {
    fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
        // usize is 32 bits on the board, 64 on the host: never wider than u64.
        out.uint(*self as u64)
    }
}

/// Writes each piece (a [`Text`]: `&str`, [`Fixed`], an unsigned integer) to the sink in turn,
/// stopping at the first [`Full`]; evaluates to a [`Written`]. `put!(out, "k=", Fixed(x, 2),
/// "\r\n")` writes what `write!(out, "k={}\r\n", Fixed(x, 2))` wrote.
macro_rules! put {
    ($out:expr $(, $piece:expr)* $(,)?) => {{
        let out = &mut *$out;
        'put: {
            $(
                if let Err(e) = $crate::iface::sink::Text::put(&$piece, out) {
                    break 'put Err(e);
                }
            )*
            Ok(())
        }
    }};
}
pub(crate) use put;

impl<const N: usize> Sink for heapless::String<N> {
    fn str(&mut self, s: &str) -> Written {
        self.push_str(s).map_err(|_| Full)
    }
}

/// `Display` through a sink (`Fixed`'s, `Refusal`'s): for the host and the tests; the firmware
/// formats nothing with `core::fmt`.
impl Sink for core::fmt::Formatter<'_> {
    fn str(&mut self, s: &str) -> Written {
        self.write_str(s).map_err(|_| Full)
    }
}

#[cfg(any(test, feature = "alloc"))]
impl Sink for alloc::string::String {
    fn str(&mut self, s: &str) -> Written {
        self.push_str(s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::String;

    #[test]
    fn integers_read_as_std_writes_them() {
        for n in [0u64, 1, 9, 10, 11, 99, 100, 101, 4_294_967_295, 4_294_967_296, 10u64.pow(19), u64::MAX]
            .into_iter()
            .chain((0..2000).map(|i| i * 7919))
        {
            let mut s = String::new();
            s.uint(n).unwrap();
            assert_eq!(s, format!("{n}"));
        }
        for (n, width, want) in [(0u64, 3u8, "000"), (5, 2, "05"), (123, 2, "123"), (7, 25, "00000000000000000007")] {
            let mut s = String::new();
            digits(&mut s, n, width).unwrap();
            assert_eq!(s, want);
        }
    }

    /// What `Fixed`'s `Display` wrote through `core::fmt` before the sink.
    fn through_core_fmt(x: f32, decimals: u8) -> String {
        let decimals = u32::from(decimals.min(6));
        let scale = 10u32.pow(decimals);
        let scaled = x * scale as f32;
        if !(scaled > -2.0e9 && scaled < 2.0e9) {
            return "-".into();
        }
        let n = if scaled < 0.0 { (scaled - 0.5) as i32 } else { (scaled + 0.5) as i32 };
        let sign = if n < 0 { "-" } else { "" };
        let n = n.unsigned_abs();
        if decimals == 0 {
            format!("{sign}{n}")
        } else {
            format!("{sign}{}.{:0width$}", n / scale, n % scale, width = decimals as usize)
        }
    }

    #[test]
    fn decimals_read_as_core_fmt_wrote_them() {
        let specials = [0.0f32, -0.0, 0.004, -0.004, 0.005, -0.005, 1e-7, 2.5, 7.5, -43.7, 1.0e9, -1.99e9, 3.0e9];
        let sweep = (-30_000..30_000).map(|i| i as f32 * 0.000_731_9);
        let wide = (-2_000..2_000).map(|i| i as f32 * 1_234.567);
        for x in specials.into_iter().chain(sweep).chain(wide).chain([f32::NAN, f32::INFINITY, f32::NEG_INFINITY]) {
            for decimals in 0..=7 {
                let mut s = String::new();
                s.fixed(x, decimals).unwrap();
                assert_eq!(s, through_core_fmt(x, decimals), "{x} {decimals}");
            }
        }
    }

    #[test]
    fn pieces_are_written_in_order_and_a_full_sink_says_so() {
        let mut s = String::new();
        put!(&mut s, "t=", 12u32, ",x=", Fixed(-1.5, 2), ",k=", 3usize).unwrap();
        assert_eq!(s, "t=12,x=-1.50,k=3");
        // A sink of 4 bytes at most, as the firmware's buffers are.
        let mut small = heapless::String::<4>::new();
        assert_eq!(put!(&mut small, "ab", 12u8), Ok(()));
        assert_eq!(put!(&mut small, "c"), Err(Full));
        assert_eq!(small.as_str(), "ab12");
        let mut small = heapless::String::<4>::new();
        assert_eq!(small.uint(123_456), Err(Full));
    }
}
