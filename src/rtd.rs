//! Platinum RTD: Callendar–Van Dusen equation both ways (IEC 60751:2008).
//!
//! ```text
//! T ≥ 0 °C:  R(T) = R0 · (1 + A·T + B·T²)
//! T < 0 °C:  R(T) = R0 · (1 + A·T + B·T² + C·(T − 100)·T³)
//! A = 3.9083e-3 /°C,  B = −5.775e-7 /°C²,  C = −4.183e-12 /°C⁴   (IEC 60751)
//! ```
//!
//! The inverse for R ≥ R0 is the positive root of the quadratic. Below 0 °C the C term makes it
//! a quartic; we start from the quadratic root (error < 0.03 °C at −50 °C) and polish with two
//! Newton steps, which converges to f32 precision over the whole −200…0 °C range.
//!
//! Glossary: R0 — nominal resistance at 0 °C (100 Ω for Pt100, 1000 Ω for Pt1000).

use crate::units::{Celsius, Ohms};

/// IEC 60751 coefficient A, 1/°C.
pub const A: f32 = 3.9083e-3;
/// IEC 60751 coefficient B, 1/°C².
pub const B: f32 = -5.775e-7;
/// IEC 60751 coefficient C, 1/°C⁴ (applies below 0 °C only).
pub const C: f32 = -4.183e-12;

/// Lowest temperature the standard covers, °C.
pub const T_MIN_C: f32 = -200.0;
/// Highest temperature the standard covers, °C.
pub const T_MAX_C: f32 = 850.0;

/// Why an RTD conversion was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RtdError {
    /// The input was NaN or infinite.
    NonFinite,
    /// The input lies outside the −200…850 °C range of IEC 60751 (or its resistance image).
    OutOfRange,
}

/// A platinum RTD of nominal resistance `r0_ohm` at 0 °C.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Rtd {
    /// Resistance at 0 °C, Ω.
    pub r0_ohm: f32,
}

impl Rtd {
    /// Pt100: 100 Ω at 0 °C.
    pub const PT100: Rtd = Rtd { r0_ohm: 100.0 };
    /// Pt1000: 1000 Ω at 0 °C.
    pub const PT1000: Rtd = Rtd { r0_ohm: 1000.0 };

    /// Resistance at temperature `t`.
    pub fn resistance(&self, t: Celsius) -> Result<Ohms, RtdError> {
        let t = t.0;
        if !t.is_finite() {
            return Err(RtdError::NonFinite);
        }
        if !(T_MIN_C..=T_MAX_C).contains(&t) {
            return Err(RtdError::OutOfRange);
        }
        Ok(Ohms(self.r0_ohm * ratio(t)))
    }

    /// Temperature at resistance `r`.
    pub fn temperature(&self, r: Ohms) -> Result<Celsius, RtdError> {
        let r = r.0;
        if !r.is_finite() {
            return Err(RtdError::NonFinite);
        }
        let w = r / self.r0_ohm;
        // 1e-4 of slack admits the rounded table values at the very ends of the range.
        if !(ratio(T_MIN_C) - 1e-4..=ratio(T_MAX_C) + 1e-4).contains(&w) {
            return Err(RtdError::OutOfRange);
        }
        // Positive root of B·T² + A·T + (1 − W) = 0, written to avoid cancellation. The root
        // through `numerics::sqrtf` (the FPU's instruction on the board, the same correctly
        // rounded value as `libm::sqrtf`): `libm`'s software root and its 256-byte table were
        // linked into the firmware for this one call.
        let disc = A * A - 4.0 * B * (1.0 - w);
        let mut t = 2.0 * (w - 1.0) / (A + crate::numerics::sqrtf(disc));
        if w < 1.0 {
            for _ in 0..2 {
                let f = ratio(t) - w;
                let df = A + 2.0 * B * t + C * (4.0 * t - 300.0) * t * t;
                t -= f / df;
            }
        }
        Ok(Celsius(t))
    }
}

/// R(T)/R0.
fn ratio(t: f32) -> f32 {
    let base = 1.0 + A * t + B * t * t;
    if t < 0.0 {
        base + C * (t - 100.0) * t * t * t
    } else {
        base
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // IEC 60751:2008 table values for Pt100 (Ω), an independent reference.
    const TABLE: &[(f32, f32)] = &[
        (-200.0, 18.52),
        (-100.0, 60.26),
        (-50.0, 80.31),
        (-20.0, 92.16),
        (0.0, 100.00),
        (4.0, 101.56),
        (20.0, 107.79),
        (50.0, 119.40),
        (100.0, 138.51),
        (200.0, 175.86),
        (400.0, 247.09),
        (850.0, 390.48),
    ];

    #[test]
    fn pt100_matches_iec_60751_table_both_ways() {
        for &(t, r) in TABLE {
            let got = Rtd::PT100.resistance(Celsius(t)).unwrap().0;
            assert!((got - r).abs() <= 0.006, "R({t}) = {got}, table {r}");
            let back = Rtd::PT100.temperature(Ohms(r)).unwrap().0;
            // Table values are rounded to 0.01 Ω, i.e. about 0.026 °C.
            assert!((back - t).abs() <= 0.03, "T({r}) = {back}, table {t}");
        }
    }

    #[test]
    fn pt1000_is_ten_times_pt100() {
        for &(t, r) in TABLE {
            let got = Rtd::PT1000.resistance(Celsius(t)).unwrap().0;
            assert!((got - 10.0 * r).abs() <= 0.06, "R({t}) = {got}");
        }
    }

    #[test]
    fn round_trip_is_tight_around_the_cold_chain_range() {
        let mut t = -60.0f32;
        while t <= 80.0 {
            let r = Rtd::PT100.resistance(Celsius(t)).unwrap();
            let back = Rtd::PT100.temperature(r).unwrap().0;
            assert!((back - t).abs() < 2e-3, "{t} -> {} -> {back}", r.0);
            t += 0.37;
        }
    }

    #[test]
    fn bad_inputs_are_refused() {
        assert_eq!(Rtd::PT100.temperature(Ohms(f32::NAN)), Err(RtdError::NonFinite));
        assert_eq!(Rtd::PT100.temperature(Ohms(-1.0)), Err(RtdError::OutOfRange));
        assert_eq!(Rtd::PT100.temperature(Ohms(1e6)), Err(RtdError::OutOfRange));
        assert_eq!(Rtd::PT100.resistance(Celsius(-300.0)), Err(RtdError::OutOfRange));
        assert_eq!(Rtd::PT100.resistance(Celsius(f32::INFINITY)), Err(RtdError::NonFinite));
    }
}
