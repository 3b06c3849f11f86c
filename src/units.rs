//! Units as types for values that cross module boundaries.
//!
//! Inside a module, plain `f32` with a unit suffix (`_c`, `_s`, `_ohm`) is used; when a value
//! leaves a module it carries its unit in its type so a resistance can never be passed where a
//! temperature is expected.

/// A temperature in degrees Celsius.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Celsius(pub f32);

/// A resistance in ohms.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ohms(pub f32);

/// A PWM duty cycle, guaranteed finite and within [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Duty(f32);

impl Duty {
    /// Cooling off.
    pub const OFF: Duty = Duty(0.0);
    /// Cooling fully on.
    pub const FULL: Duty = Duty(1.0);

    /// Checked constructor: `None` unless `x` is finite and within [0, 1].
    pub fn new(x: f32) -> Option<Duty> {
        if x.is_finite() && (0.0..=1.0).contains(&x) {
            Some(Duty(x))
        } else {
            None
        }
    }

    /// Saturating constructor: clips to [0, 1]; a non-finite request becomes [`Duty::OFF`]
    /// (the safe state for a cooler that could freeze its load).
    pub fn saturating(x: f32) -> Duty {
        if x.is_finite() {
            Duty(x.clamp(0.0, 1.0))
        } else {
            Duty::OFF
        }
    }

    /// The duty as a fraction in [0, 1].
    pub fn get(self) -> f32 {
        self.0
    }
}

/// min of two finite numbers as a compare-and-select. `f32::min` is a call to `fminf` on the
/// Cortex-M4F (its NaN handling is software, ≈ 15 instructions a call: `cargo xtask pil`).
#[inline(always)]
pub(crate) fn min_f32(a: f32, b: f32) -> f32 {
    if b < a {
        b
    } else {
        a
    }
}

/// max of two finite numbers as a compare-and-select (see [`min_f32`]).
#[inline(always)]
pub(crate) fn max_f32(a: f32, b: f32) -> f32 {
    if b > a {
        b
    } else {
        a
    }
}

/// Milliseconds as f32 seconds, rounded (exact for whole seconds up to 1.5 days, within one
/// f32 step beyond): for the records kept in f32. Two u32 conversions rather than the u64 one,
/// which is a library call on the Cortex-M4F (the high word is 0 for the first 49 days). Out
/// of line: −124 B of the `module-sense` firmware for +27 instructions in `cargo xtask pil`'s
/// worst sample (2026-12-07, to make room for the stops kept until stored).
#[inline(never)]
pub fn secs_f32(ms: u64) -> f32 {
    ((ms >> 32) as u32 as f32 * 4_294_967_296.0 + ms as u32 as f32) / 1000.0
}

/// Milliseconds as f64 seconds, for display: every millisecond count up to 2⁵³ is exact.
pub fn secs_f64(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duty_rejects_out_of_range_and_nan() {
        assert!(Duty::new(-0.01).is_none());
        assert!(Duty::new(1.01).is_none());
        assert!(Duty::new(f32::NAN).is_none());
        assert_eq!(Duty::new(0.25).map(Duty::get), Some(0.25));
        assert_eq!(Duty::saturating(f32::NAN), Duty::OFF);
        assert_eq!(Duty::saturating(f32::INFINITY), Duty::OFF);
        assert_eq!(Duty::saturating(3.0), Duty::FULL);
        assert_eq!(Duty::saturating(-3.0), Duty::OFF);
    }
}
