//! Ratiometric ADC front end of the RTD: counts → ohms, and the open/short classification.
//!
//! The RTD (4-wire) and a precision reference resistor `R_ref` carry the same excitation
//! current; the voltage across the RTD is amplified by `gain` and converted with the voltage
//! across `R_ref` as the ADC reference, so supply and current drift cancel:
//!
//! ```text
//! counts / full_scale = gain · R_rtd / R_ref      ⇒      R_rtd = counts · R_ref / (gain · full_scale)
//! ```
//!
//! Defaults (see [`AdcFrontEnd::DEFAULT`]): Pt100, `R_ref` = 2 kΩ, `gain` = 15, so full scale is
//! 133.3 Ω (≈ 86 °C) and a 16-bit result (12-bit converter, ×256 hardware oversampling shifted
//! right by 4) has a step of 2.03 mΩ ≈ 0.0053 °C — four times finer than the 0.02 °C target.
//!
//! An open RTD drives the amplifier to its rail (counts at full scale); a shorted one reads the
//! lead resistance only, far below any plausible temperature.

use crate::units::Ohms;

/// Why a conversion does not describe a working sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdcError {
    /// Counts at or near full scale: broken RTD or lead (open circuit).
    Open,
    /// Resistance below [`AdcFrontEnd::short_below_ohm`]: RTD or leads shorted.
    Short,
}

/// Configuration of the ratiometric front end.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcFrontEnd {
    /// Counts at the ADC reference (e.g. 65535 for a 16-bit oversampled result).
    pub full_scale_counts: u32,
    /// Reference resistor, Ω (0.1 % metal film in the design).
    pub r_ref_ohm: f32,
    /// Amplifier gain between the RTD and the ADC, V/V.
    pub gain: f32,
    /// Counts this close to full scale are an open circuit (the amplifier saturates there).
    pub open_margin_counts: u32,
    /// Resistances below this are a short, Ω (a Pt100 is 18.5 Ω at −200 °C; leads are < 2 Ω).
    pub short_below_ohm: f32,
}

impl AdcFrontEnd {
    /// The board's default front end (Pt100, 2 kΩ reference, gain 15, 16-bit oversampled).
    pub const DEFAULT: AdcFrontEnd = AdcFrontEnd {
        full_scale_counts: 65_535,
        r_ref_ohm: 2_000.0,
        gain: 15.0,
        // 0.1 % of full scale: ~0.13 Ω, far above the noise, far below any usable reading.
        open_margin_counts: 64,
        short_below_ohm: 50.0,
    };

    /// Resistance for `counts`, or why the counts cannot come from a working RTD.
    pub fn ohms(&self, counts: u32) -> Result<Ohms, AdcError> {
        if counts.saturating_add(self.open_margin_counts) >= self.full_scale_counts {
            return Err(AdcError::Open);
        }
        let r = counts as f32 * self.r_ref_ohm / (self.gain * self.full_scale_counts as f32);
        if r < self.short_below_ohm {
            return Err(AdcError::Short);
        }
        Ok(Ohms(r))
    }

    /// Counts an ideal converter would give for `r` (used by tests and calibration tools).
    pub fn counts(&self, r: Ohms) -> u32 {
        let x = r.0 * self.gain * self.full_scale_counts as f32 / self.r_ref_ohm;
        if x.is_finite() {
            libm::roundf(x.clamp(0.0, self.full_scale_counts as f32)) as u32
        } else {
            self.full_scale_counts
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_to_ohms_round_trip_and_resolution() {
        let fe = AdcFrontEnd::DEFAULT;
        let c = fe.counts(Ohms(101.56));
        let r = fe.ohms(c).unwrap().0;
        assert!((r - 101.56).abs() < 0.002, "{r}");
        let step = fe.ohms(c + 1).unwrap().0 - r;
        assert!((step - 2000.0 / (15.0 * 65535.0)).abs() < 1e-5, "{step}");
    }

    #[test]
    fn open_and_short_are_flagged() {
        let fe = AdcFrontEnd::DEFAULT;
        assert_eq!(fe.ohms(65_535), Err(AdcError::Open));
        assert_eq!(fe.ohms(65_500), Err(AdcError::Open));
        assert_eq!(fe.ohms(u32::MAX), Err(AdcError::Open));
        assert_eq!(fe.ohms(0), Err(AdcError::Short));
        assert_eq!(fe.ohms(fe.counts(Ohms(2.0))), Err(AdcError::Short));
        assert!(fe.ohms(fe.counts(Ohms(80.0))).is_ok());
    }
}
