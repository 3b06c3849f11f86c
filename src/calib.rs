//! Two-point calibration of the measurement chain: an ice bath and a second bath against a
//! reference thermometer give two (measured, true) pairs.
//!
//! The seed calibrated its RTD channel in an ice-water bath against a reference thermometer
//! (SIRIM) and fitted a straight line. We do the same with two points: the ice bath (the
//! reference reads ≈ 0 °C) and a second reference point (e.g. room temperature or a warm
//! bath), and correct every reading with
//!
//! ```text
//! T_cal = gain · T_meas + offset_c,   gain = (r₁ − r₀)/(m₁ − m₀),   offset_c = r₀ − gain · m₀
//! ```
//!
//! where mᵢ is what the channel read and rᵢ what the reference read at point i. A straight line
//! absorbs lead-resistance offset, reference-resistor tolerance and amplifier gain error.
//!
//! **How large a correction may be.** Those errors together are about a degree: a class B Pt100
//! is within ±0.35 °C between 0 and 10 °C (IEC 60751), 0.1 % on the reference resistor is
//! ±0.26 °C, and a metre of two-wire lead adds ≈ +0.5 °C. A line that moves a reading in the
//! carrier's range (0…10 °C) by more than [`MAX_CORRECTION_C`] is a broken channel or a typing
//! error (a reference entered in the measured column, the ice point's reference not the ice
//! bath's), and it is refused: such a line once let a board read 5.00 °C while its load sat at
//! −4.4 °C (an ice point of (0, 9) with a warm point of (100, 100): gain 0.91, offset +9 °C),
//! the freeze guard reading the same false 5 °C.

use crate::units::Celsius;

/// Why a calibration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalError {
    /// A point was NaN or infinite.
    NonFinite,
    /// The two measured points are closer than 1 °C: the slope would be meaningless.
    PointsTooClose,
    /// The fitted gain is outside 0.9…1.1: the channel is broken, not mis-calibrated.
    ImplausibleGain,
    /// The line moves a reading between 0 and 10 °C by more than [`MAX_CORRECTION_C`].
    ImplausibleCorrection,
}

/// Largest correction a calibration may apply to a reading between 0 and 10 °C, °C (module
/// docs: the channel's own errors are about a degree).
pub const MAX_CORRECTION_C: f32 = 1.5;

/// The lowest gain a fit accepts ([`CalError::ImplausibleGain`] below it).
pub const MIN_GAIN: f32 = 0.9;

/// The highest gain a fit accepts ([`CalError::ImplausibleGain`] above it).
pub const MAX_GAIN: f32 = 1.1;

/// A straight-line correction `T_cal = gain · T_meas + offset_c`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TwoPoint {
    /// Slope, dimensionless.
    pub gain: f32,
    /// Offset, °C.
    pub offset_c: f32,
}

impl Default for TwoPoint {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl TwoPoint {
    /// No correction.
    pub const IDENTITY: TwoPoint = TwoPoint { gain: 1.0, offset_c: 0.0 };

    /// Fits the line through (measured, reference) at the ice bath and at a second point.
    /// A `const fn`, so a board's configuration can hold its calibration as a constant that is
    /// checked when the firmware compiles (`firmware/src/config.rs`).
    pub const fn from_points(
        measured_ice: Celsius,
        reference_ice: Celsius,
        measured_hot: Celsius,
        reference_hot: Celsius,
    ) -> Result<TwoPoint, CalError> {
        let (m0, r0, m1, r1) = (measured_ice.0, reference_ice.0, measured_hot.0, reference_hot.0);
        if !(m0.is_finite() && r0.is_finite() && m1.is_finite() && r1.is_finite()) {
            return Err(CalError::NonFinite);
        }
        if (m1 - m0).abs() < 1.0 {
            return Err(CalError::PointsTooClose);
        }
        let gain = (r1 - r0) / (m1 - m0);
        Self::checked(gain, r0 - gain * m0)
    }

    /// The line `gain`, `offset_c` if a calibration may apply it: a gain within
    /// [`MIN_GAIN`]…[`MAX_GAIN`] and a correction of a reading between 0 and 10 °C of at most
    /// [`MAX_CORRECTION_C`]. [`Self::from_points`]' checks of its fit, and what a stored line
    /// must pass (`persist::CalibrationRecord::decode`). `gain` and `offset_c` finite.
    pub const fn checked(gain: f32, offset_c: f32) -> Result<TwoPoint, CalError> {
        if !(gain >= MIN_GAIN && gain <= MAX_GAIN) {
            return Err(CalError::ImplausibleGain);
        }
        // The correction gain·t + offset − t is linear in t: its ends bound it on 0…10 °C.
        let at_10 = (gain - 1.0) * 10.0 + offset_c;
        if !(offset_c.abs() <= MAX_CORRECTION_C && at_10.abs() <= MAX_CORRECTION_C) {
            return Err(CalError::ImplausibleCorrection);
        }
        Ok(TwoPoint { gain, offset_c })
    }

    /// The corrected temperature.
    pub fn apply(&self, t: Celsius) -> Celsius {
        Celsius(self.gain * t.0 + self.offset_c)
    }
}

/// What replacing one calibration by another does to the readings: every reading the channel
/// gives moves from `T_old` to `T_new = gain · T_old + shift_c`. Both lines are straight, so
/// their composition is one:
///
/// ```text
/// T_meas = (T_old − offset_old)/gain_old,   T_new = gain_new · T_meas + offset_new
///        ⇒ gain = gain_new/gain_old,        shift_c = offset_new − gain · offset_old
/// ```
///
/// A straight line also maps any weighted mean of readings whose weights sum to one (a
/// first-order filter's value) onto the same mean of the mapped readings, and a difference of
/// two readings onto `gain` times it: what was measured through the old line can be carried
/// over to the new one exactly ([`crate::step::Carrier::set_calibration`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recalibration {
    /// Slope of the change, dimensionless (`gain_new/gain_old`).
    pub gain: f32,
    /// Offset of the change, °C.
    pub shift_c: f32,
}

impl Recalibration {
    /// The change from `old` to `new`; `None` if `old` cannot be inverted (a gain of zero, or a
    /// line that is not finite: a [`TwoPoint`] made by [`TwoPoint::from_points`] never is).
    pub fn between(old: &TwoPoint, new: &TwoPoint) -> Option<Recalibration> {
        let gain = new.gain / old.gain;
        let shift_c = new.offset_c - gain * old.offset_c;
        (gain.is_finite() && gain > 0.0 && shift_c.is_finite()).then_some(Recalibration { gain, shift_c })
    }

    /// A temperature read through the old line, as the new one reads it, °C.
    pub fn level(&self, t_c: f32) -> f32 {
        self.gain * t_c + self.shift_c
    }

    /// A difference of two temperatures read through the old line, as the new one reads it, °C.
    pub fn difference(&self, d_c: f32) -> f32 {
        self.gain * d_c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrects_offset_and_gain_exactly_at_both_points() {
        // Channel reads 0.3 °C in the ice bath and 25.6 °C where the reference says 25.0 °C.
        let cal = TwoPoint::from_points(Celsius(0.3), Celsius(0.0), Celsius(25.6), Celsius(25.0)).unwrap();
        assert!((cal.apply(Celsius(0.3)).0 - 0.0).abs() < 1e-5);
        assert!((cal.apply(Celsius(25.6)).0 - 25.0).abs() < 1e-5);
        // Linear in between.
        assert!((cal.apply(Celsius(12.95)).0 - 12.5).abs() < 1e-4);
    }

    #[test]
    fn refuses_degenerate_points() {
        let c = Celsius;
        assert_eq!(TwoPoint::from_points(c(0.1), c(0.0), c(0.5), c(0.4)), Err(CalError::PointsTooClose));
        assert_eq!(TwoPoint::from_points(c(0.0), c(0.0), c(20.0), c(30.0)), Err(CalError::ImplausibleGain));
        assert_eq!(TwoPoint::from_points(c(f32::NAN), c(0.0), c(20.0), c(20.0)), Err(CalError::NonFinite));
    }

    #[test]
    fn a_recalibration_maps_readings_through_the_old_line_onto_the_new_one() {
        let c = Celsius;
        let old = TwoPoint::from_points(c(0.3), c(0.0), c(25.6), c(25.0)).unwrap();
        let new = TwoPoint::from_points(c(0.0), c(1.4), c(25.0), c(25.0)).unwrap();
        let r = Recalibration::between(&old, &new).unwrap();
        for m in [-5.0, 0.0, 4.0, 8.0, 30.0] {
            let (t_old, t_new) = (old.apply(c(m)).0, new.apply(c(m)).0);
            assert!((r.level(t_old) - t_new).abs() < 1e-5, "{m}: {} vs {t_new}", r.level(t_old));
        }
        let d = old.apply(c(5.0)).0 - old.apply(c(4.0)).0;
        assert!((r.difference(d) - (new.apply(c(5.0)).0 - new.apply(c(4.0)).0)).abs() < 1e-6);
        assert_eq!(
            Recalibration::between(&TwoPoint::IDENTITY, &TwoPoint::IDENTITY),
            Some(Recalibration { gain: 1.0, shift_c: 0.0 })
        );
        assert_eq!(Recalibration::between(&TwoPoint { gain: 0.0, offset_c: 0.0 }, &new), None);
    }

    /// The interface sweep's pair: each point was accepted with the other's default, together
    /// they read a −4.4 °C load as 5.00 °C.
    #[test]
    fn refuses_a_line_that_moves_the_carriers_range_by_more_than_a_degree_and_a_half() {
        let c = Celsius;
        let e = Err(CalError::ImplausibleCorrection);
        assert_eq!(TwoPoint::from_points(c(0.0), c(9.0), c(100.0), c(100.0)), e);
        // An offset of 1.6 °C at both ends; 1.4 °C passes.
        assert_eq!(TwoPoint::from_points(c(0.0), c(1.6), c(25.0), c(26.6)), e);
        assert!(TwoPoint::from_points(c(0.0), c(1.4), c(25.0), c(26.4)).is_ok());
        // Gain 1.1 with no offset at 0 °C: +1.0 °C at 10 °C passes; with 0.6 °C more at 0 °C,
        // +1.6 °C at 10 °C does not.
        assert!(TwoPoint::from_points(c(0.0), c(0.0), c(10.0), c(11.0)).is_ok());
        assert_eq!(TwoPoint::from_points(c(0.0), c(0.6), c(10.0), c(11.6)), e);
    }
}
