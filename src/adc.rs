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
//!
//! ## Forming the ratio on the STM32L476RG
//! In the LQFP64 package of the reference board the ADC's VREF+ is bonded to VDDA, so the
//! reference-resistor voltage cannot be the converter's reference. The board converts both
//! voltages against VDDA instead — the amplified RTD voltage `s = gain · I · R_rtd / VDDA` and
//! the reference-resistor voltage `r = I · R_ref / VDDA`, each in 16-bit counts — and
//! [`ratiometric_counts`] forms `full_scale · s / r`, the counts of the equation above: VDDA
//! and the excitation current I cancel as they would with a true ratiometric converter. With
//! 1 mA through 2 kΩ (r ≈ 2.0 V ≈ 39 700 counts of 3.3 V) one count of the RTD conversion is
//! 1.65 counts of the ratio, 3.4 mΩ ≈ 0.009 °C: the resolution on the board (see
//! `firmware/src/board.rs`), within the 0.02 °C target. The simulator generates the ratio
//! directly.
//!
//! ## Supply voltage
//! [`SupplySense`] turns a divided conversion of the modules' supply into volts, with VDDA
//! measured against the MCU's factory-calibrated internal reference (VREFINT), so the reading
//! does not depend on the 3.3 V regulator's tolerance.
//!
//! ## When to convert: the SSR's PWM phase
//! Each SSR edge switches ≈ 4 A in the module leads; the inductive kick and the ground bounce
//! reach the front end as a disturbance that decays within a few milliseconds. A conversion
//! that happens to start on an edge is biased (the simulator models +400 counts decaying with
//! τ = 1 ms, a model, not a measurement: `hal-sim/src/periph.rs`). [`SampleWindow`] fixes where
//! in the PWM period the conversions run, and [`SampleWindow::clear_duty`] keeps the SSR's
//! falling edge out of it. [`ReferenceWindow`] checks the reference-resistor conversions taken
//! before and after the RTD's.

use crate::units::{Duty, Ohms};

/// Why a conversion does not describe a working sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdcError {
    /// Counts at or near full scale: broken RTD or lead (open circuit).
    Open,
    /// Resistance below [`AdcFrontEnd::short_below_ohm`]: RTD or leads shorted.
    Short,
    /// The reference-resistor conversions around the RTD's are outside their window or disagree
    /// ([`ReferenceWindow::check`]): the ratio cannot be trusted.
    ReferenceOutOfRange,
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

/// The 16-bit ratio `full_scale · signal / reference` of two conversions of the same excitation
/// (see the module docs), saturated at `full_scale`. A missing reference (an open reference
/// resistor or no excitation: `reference` = 0) gives `full_scale`, which [`AdcFrontEnd::ohms`]
/// reports as an open sensor.
pub fn ratiometric_counts(signal: u32, reference: u32, full_scale: u32) -> u32 {
    if reference == 0 {
        return full_scale;
    }
    let ratio = u64::from(full_scale) * u64::from(signal) / u64::from(reference);
    u32::try_from(ratio).map_or(full_scale, |r| r.min(full_scale))
}

/// Where in the SSR's PWM period the reference, RTD and reference conversions run, and the
/// duties that keep the SSR's edges away from them.
///
/// The SSR turns on at the start of each period (phase 0) and off at `duty · period`. The
/// window sits at the end of the period, so the rising edge is a whole period minus the window
/// away; the falling edge is moved out of the window and the `settle_ms` before it by
/// [`SampleWindow::clear_duty`]. Valid when `settle_ms ≤ start_ms` and `start_ms + len_ms ≤
/// period_ms` ([`SampleWindow::is_valid`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SampleWindow {
    /// SSR PWM period, ms (the board's TIM3: 1 s).
    pub period_ms: u32,
    /// Start of the conversions, ms after the SSR's rising edge.
    pub start_ms: u32,
    /// Length of the window, ms: reference, RTD and reference conversion.
    pub len_ms: u32,
    /// Quiet time an edge must leave before the window, ms.
    pub settle_ms: u32,
}

impl SampleWindow {
    /// The last 30 ms of the 1 s period: three ×256-oversampled conversions of ≈ 4 ms each
    /// (the reference, the RTD, the reference again) with room to spare, plus 10 ms of settling
    /// before it — ten time constants of the 1 ms switching disturbance modelled in the
    /// simulator (e⁻¹⁰: 0.02 counts of a 400-count kick). Duties between 0.96 and 1 become one
    /// of the two: a 4 % step at the top of the range, where the controller only passes
    /// through on its way to full cooling.
    pub const DEFAULT: SampleWindow = SampleWindow { period_ms: 1000, start_ms: 970, len_ms: 30, settle_ms: 10 };

    /// Whether the window and its settling time fit inside one period.
    pub const fn is_valid(&self) -> bool {
        self.period_ms > 0 && self.settle_ms <= self.start_ms && self.start_ms + self.len_ms <= self.period_ms
    }

    /// `d` moved so that the SSR's falling edge (at `d · period`) is neither inside the window
    /// nor within `settle_ms` before it: a duty whose edge would fall there goes to the nearer
    /// edge outside (the start of the settling time, or the end of the window; a window that
    /// ends with the period gives 1.0, no falling edge at all). 0 and 1 have no edge and stay.
    /// An invalid window leaves `d` as it is.
    pub fn clear_duty(&self, d: Duty) -> Duty {
        if !self.is_valid() {
            return d;
        }
        let p = self.period_ms as f32;
        let lo = (self.start_ms - self.settle_ms) as f32 / p;
        let hi = (self.start_ms + self.len_ms) as f32 / p;
        let x = d.get();
        if x > lo && x < hi {
            Duty::saturating(if x - lo < hi - x { lo } else { hi })
        } else {
            d
        }
    }
}

/// The window the reference-resistor conversion must fall in, and how far the conversions
/// before and after the RTD's may disagree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReferenceWindow {
    /// Lowest plausible reference conversion, counts.
    pub min_counts: u32,
    /// Highest plausible reference conversion, counts.
    pub max_counts: u32,
    /// Largest difference between the conversion before and after the RTD's, counts.
    pub max_diff_counts: u32,
}

impl ReferenceWindow {
    /// 1 mA ± 5 % through 2 kΩ against VDDA 3.0…3.6 V, in 16-bit counts: 1.9 V / 3.6 V = 0.528
    /// (34 590 counts) to 2.1 V / 3.0 V = 0.70 (45 875), widened to 34 000…46 500. The two
    /// conversions are ≈ 8 ms apart: the excitation cannot move measurably, and with ≈ 1.5
    /// counts of noise on each their difference exceeds 16 counts (7σ) by chance about once in
    /// 10¹² samples; 16 counts of the reference is 0.04 % of the ratio, 0.1 °C at the RTD.
    pub const DEFAULT: ReferenceWindow =
        ReferenceWindow { min_counts: 34_000, max_counts: 46_500, max_diff_counts: 16 };

    /// The reference to form the ratio with (the mean of `before` and `after`, which cancels
    /// a linear drift across the RTD conversion), or [`AdcError::ReferenceOutOfRange`] when
    /// either is outside the window or they disagree by more than `max_diff_counts`.
    pub fn check(&self, before: u32, after: u32) -> Result<u32, AdcError> {
        let inside = |c: u32| (self.min_counts..=self.max_counts).contains(&c);
        if !inside(before) || !inside(after) || before.abs_diff(after) > self.max_diff_counts {
            return Err(AdcError::ReferenceOutOfRange);
        }
        // In u64 the sum cannot overflow; the mean (rounded half up) fits back in u32.
        Ok((u64::from(before) + u64::from(after)).div_ceil(2) as u32)
    }
}

/// Measurement of the Peltier modules' supply through a resistive divider, with VDDA taken from
/// the internal reference (RM0351 §16.4.34: VDDA = 3.0 V · VREFINT_CAL / VREFINT_DATA, with
/// VREFINT_CAL the 12-bit conversion of VREFINT at VDDA = 3.0 V stored in system memory).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SupplySense {
    /// Divider ratio (R_top + R_bottom) / R_bottom.
    pub divider: f32,
    /// VDDA at which VREFINT_CAL was measured, V (3.0 on the STM32L4).
    pub vrefint_cal_vdda_v: f32,
    /// Full scale of VREFINT_CAL, counts (12-bit: 4095).
    pub vrefint_cal_full_scale: u32,
}

impl SupplySense {
    /// The reference board: 47 kΩ over 10 kΩ (12 V → 2.1 V; up to 18.8 V before the ADC
    /// saturates).
    pub const DEFAULT: SupplySense =
        SupplySense { divider: 5.7, vrefint_cal_vdda_v: 3.0, vrefint_cal_full_scale: 4095 };

    /// The supply, V, from the divided conversion `supply` and the conversion `vrefint` of the
    /// internal reference, both with the same oversampling (any: its scale cancels), given the
    /// factory `vrefint_cal`. `None` when a conversion or the calibration word is 0 (no
    /// reference, a blank calibration): the supply check then stays off rather than report a
    /// made-up voltage.
    ///
    /// With F the oversampled full scale, VDDA = V_cal · cal · (F / cal_full_scale) / vrefint and
    /// V_in = VDDA · supply / F, so F drops out: V = divider · V_cal · cal · supply /
    /// (cal_full_scale · vrefint).
    pub fn volts(&self, supply: u32, vrefint: u32, vrefint_cal: u16) -> Option<f32> {
        if vrefint == 0 || vrefint_cal == 0 || self.vrefint_cal_full_scale == 0 {
            return None;
        }
        let v = self.divider * self.vrefint_cal_vdda_v * f32::from(vrefint_cal) * supply as f32
            / (self.vrefint_cal_full_scale as f32 * vrefint as f32);
        v.is_finite().then_some(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratio_of_two_conversions_is_the_front_end_counts() {
        let fe = AdcFrontEnd::DEFAULT;
        // 1 mA through a Pt100 at 4 °C (101.56 Ω) and 2 kΩ, gain 15, VDDA 3.3 V, 16-bit.
        let to_counts = |v: f64| (v / 3.3 * 65_535.0).round() as u32;
        let (s, r) = (to_counts(15.0 * 1e-3 * 101.56), to_counts(1e-3 * 2000.0));
        let c = ratiometric_counts(s, r, fe.full_scale_counts);
        let ohms = fe.ohms(c).unwrap().0;
        // Quantisation of the two conversions: within 2 counts of the RTD conversion.
        assert!((ohms - 101.56).abs() < 2.0 * 3.3 / 65_535.0 / 15.0 / 1e-3, "{ohms}");
        // The same at another VDDA and excitation: both cancel.
        let to_counts_28 = |v: f64| (v / 2.8 * 65_535.0).round() as u32;
        let c2 = ratiometric_counts(to_counts_28(15.0 * 0.9e-3 * 101.56), to_counts_28(0.9e-3 * 2000.0), 65_535);
        assert!((fe.ohms(c2).unwrap().0 - 101.56).abs() < 0.01);
        // No reference, or a signal beyond it: full scale, an open sensor.
        assert_eq!(ratiometric_counts(30_000, 0, 65_535), 65_535);
        assert_eq!(ratiometric_counts(0, 0, 65_535), 65_535);
        assert_eq!(fe.ohms(ratiometric_counts(65_535, 20_000, 65_535)), Err(AdcError::Open));
        assert_eq!(ratiometric_counts(u32::MAX, 1, 65_535), 65_535);
    }

    #[test]
    fn supply_volts_from_the_divider_and_vrefint() {
        let s = SupplySense::DEFAULT;
        // A typical VREFINT_CAL (1.212 V at 3.0 V: 1655 of 4095); VDDA really 3.28 V.
        let (cal, vdda) = (1655u16, 3.28f64);
        let vref_v = 3.0 * f64::from(cal) / 4095.0;
        let conv = |v: f64| (v / vdda * 65_520.0).round() as u32;
        for supply in [9.0f64, 10.8, 12.0, 13.8] {
            let v = s.volts(conv(supply / 5.7), conv(vref_v), cal).unwrap();
            assert!((f64::from(v) - supply).abs() < 0.01, "{supply} V read as {v}");
        }
        assert_eq!(s.volts(30_000, 0, cal), None);
        assert_eq!(s.volts(30_000, 20_000, 0), None);
    }

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
    #[test]
    fn cleared_duties_keep_the_falling_edge_out_of_the_window() {
        let w = SampleWindow::DEFAULT;
        assert!(w.is_valid());
        let d = |x: f32| w.clear_duty(Duty::new(x).unwrap()).get();
        for x in [0.0, 0.001, 0.3, 0.5, 0.96, 1.0] {
            assert_eq!(d(x), x, "{x} has its edge outside already");
        }
        assert_eq!(d(0.97), 0.96);
        assert_eq!(d(0.979), 0.96);
        assert_eq!(d(0.981), 1.0);
        assert_eq!(d(0.999), 1.0);
        // Every duty at 0.1 % steps: the edge is at least `settle_ms` before the window or
        // there is none.
        for k in 0..=1000 {
            let x = d(k as f32 / 1000.0);
            let edge_ms = x * 1000.0;
            assert!(x == 1.0 || edge_ms <= 960.0 + 1e-3, "{k}: edge at {edge_ms} ms");
        }
        // A window that does not fit leaves the duty alone.
        let bad = SampleWindow { start_ms: 5, ..w };
        assert_eq!(bad.clear_duty(Duty::new(0.97).unwrap()).get(), 0.97);
    }

    #[test]
    fn reference_outside_its_window_or_moving_is_an_error() {
        let r = ReferenceWindow::DEFAULT;
        assert_eq!(r.check(39_700, 39_704), Ok(39_702));
        assert_eq!(r.check(39_700, 39_716), Ok(39_708));
        assert_eq!(r.check(39_700, 39_717), Err(AdcError::ReferenceOutOfRange));
        assert_eq!(r.check(33_999, 34_000), Err(AdcError::ReferenceOutOfRange));
        assert_eq!(r.check(46_500, 46_501), Err(AdcError::ReferenceOutOfRange));
        assert_eq!(r.check(0, 0), Err(AdcError::ReferenceOutOfRange), "no excitation");
        assert_eq!(r.check(u32::MAX, u32::MAX), Err(AdcError::ReferenceOutOfRange));
    }
}
