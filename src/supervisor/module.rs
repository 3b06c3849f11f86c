//! Module-side sense: a shorted SSR found by the voltage across the modules, not by the load.
//!
//! The SSR's other checks ([`super::ssr`]) infer a short from the temperature: a fall with no
//! cooling asked, a freeze-guard trip nobody asked for. Through the RTD's ≈ 50 s of lag, and
//! on a light carrier whose cold plate keeps cooling after the supply opens, that comes late:
//! in `hter campaign --missions 10000 --seed 3001` the loads after a shorted SSR went as low as
//! 0.86 °C, and 384 minutes below 2 °C in all, even where the short was found in 100 s (the
//! cold already stored in the cold plate does the rest).
//!
//! A board with a divider on the modules' side of the SSR (an ADC channel; the reference board
//! has none, the firmware's `module-sense` build reads it on PC1, README "Fail-loud alarm,
//! switch sense and what is unverified") can read the
//! modules in the conversion window at the end of each PWM period, where the SSR is commanded
//! off at every duty below full ([`crate::adc::SampleWindow`] keeps its edges out). There a
//! working SSR leaves only the modules' own Seebeck voltage, α ΔT ≤ 0.053 V/K × 60 K ≈ 3.2 V;
//! a shorted one leaves the supply. The reading counts as powered by the supply switch check's
//! rule ([`super::switch::SwitchConfig::powered_above_v`]: above half the measured supply, 6 V
//! without a supply measurement) but never below [`SEEBECK_MAX_V`], so that a sagging supply
//! does not bring the limit down to what the modules give back themselves. Two powered readings
//! in a row (one could be a glitch), each after a sample whose output had the switch closed and
//! the duty below full cooling ([`super::ssr::SsrConfig::full_duty`]), are a shorted SSR: the
//! supervisor limps home. A board that never calls [`crate::step::Carrier::observe_module_v`]
//! has no such check.
//!
//! Measured in the simulator, which models the modules' voltage (`hter campaign --module-sense`,
//! the same 10 000 missions): 7.2 minutes below 2 °C after any hardware fault instead of 384,
//! lowest 1.77 °C instead of 0.86 (what is left is limp home's On-Off on the lightest carriers).

use super::switch::SwitchConfig;

/// Powered readings in a row that make a short.
pub const CONFIRM_SAMPLES: u8 = 2;

/// The least a powered reading must exceed, V: above the modules' own Seebeck voltage
/// (0.053 V/K × 60 K ≈ 3.2 V across a TEC1-12706-class module), with margin. A shorted SSR on
/// any supply that cools (≥ 5 V) reads more.
pub const SEEBECK_MAX_V: f32 = 4.0;

/// State of the module-side check.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ModuleSense {
    /// The modules' voltage read for this sample, V (`None`: no sense, or not read).
    v: Option<f32>,
    /// The previous output left the SSR off in the conversion window with the switch closed:
    /// the reading for this sample can tell a short.
    window_off: bool,
    /// Powered readings in a row, each with the window off.
    run: u8,
}

impl ModuleSense {
    /// Takes the modules' voltage read in the conversion window, V, for the next sample.
    pub(crate) fn observe(&mut self, v: f32) {
        self.v = Some(v);
    }

    /// Whether this sample's reading confirms a shorted SSR, against the measured supply
    /// `supply_v` (the supply switch check's limits).
    pub(crate) fn shorted(&mut self, cfg: &SwitchConfig, supply_v: Option<f32>) -> bool {
        let Some(v) = self.v.take() else { return false };
        let limit = cfg.powered_above_v(supply_v, SEEBECK_MAX_V);
        // NaN (a broken sense) is not powered: it fails `>`.
        self.run = if self.window_off && v > limit { self.run.saturating_add(1) } else { 0 };
        self.run >= CONFIRM_SAMPLES
    }

    /// Remembers whether this sample's output leaves the SSR off in the next conversion window:
    /// the switch `closed` and the `duty` below `full_duty`.
    pub(crate) fn note_output(&mut self, closed: bool, duty: f32, full_duty: f32) {
        self.window_off = closed && duty < full_duty;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CFG: SwitchConfig = SwitchConfig::DEFAULT;
    const FULL: f32 = 0.9;

    /// One sample: the reading `v` (at a 12 V supply) is judged, then the output is noted.
    fn sample(m: &mut ModuleSense, v: f32, closed: bool, duty: f32) -> bool {
        m.observe(v);
        let found = m.shorted(&CFG, Some(12.0));
        m.note_output(closed, duty, FULL);
        found
    }

    #[test]
    fn two_powered_readings_with_the_ssr_commanded_off_are_a_short() {
        let mut m = ModuleSense::default();
        // The first reading has no output before it: not judged.
        assert!(!sample(&mut m, 11.9, true, 0.3));
        assert!(!sample(&mut m, 11.9, true, 0.3), "one powered reading is not yet a short");
        assert!(sample(&mut m, 11.9, true, 0.3));
    }

    #[test]
    fn the_modules_seebeck_voltage_is_not_a_short() {
        let mut m = ModuleSense::default();
        // 60 K across a TEC1-12706-class module: 3.2 V, under half the 12 V supply.
        for _ in 0..100 {
            assert!(!sample(&mut m, 3.2, true, 0.0));
        }
        // A sagging supply lowers the limit with it (9 V: 4.5 V), never below the Seebeck bound.
        m.observe(4.4);
        assert!(!m.shorted(&CFG, Some(9.0)));
        m.observe(3.9);
        assert!(!m.shorted(&CFG, Some(6.0)));
        m.observe(3.9);
        assert!(!m.shorted(&CFG, Some(2.0)));
        // A short on a 6 V supply still reads above it: two readings in a row.
        m.observe(5.9);
        assert!(!m.shorted(&CFG, Some(6.0)));
        m.observe(5.9);
        assert!(m.shorted(&CFG, Some(6.0)));
    }

    #[test]
    fn full_cooling_or_an_open_switch_tells_nothing() {
        let mut m = ModuleSense::default();
        // At full duty the SSR is on in the window: the supply there is the drive, not a short.
        for _ in 0..10 {
            assert!(!sample(&mut m, 12.0, true, 1.0));
        }
        // With the switch open a powered reading is the switch check's business.
        for _ in 0..10 {
            assert!(!sample(&mut m, 12.0, false, 0.0));
        }
        // One reading after an output that could tell, then full duty again: the run restarts.
        assert!(!sample(&mut m, 12.0, true, 1.0));
        assert!(!sample(&mut m, 12.0, true, 0.2));
        assert!(!sample(&mut m, 12.0, true, 1.0));
        assert!(!sample(&mut m, 12.0, true, 0.2));
        assert!(!sample(&mut m, 12.0, true, 0.2));
        assert!(sample(&mut m, 12.0, true, 0.2));
    }

    #[test]
    fn a_broken_sense_or_no_reading_is_not_a_short() {
        let mut m = ModuleSense::default();
        for _ in 0..10 {
            assert!(!sample(&mut m, f32::NAN, true, 0.0));
        }
        // No reading this sample (a board without the sense): nothing judged, the run kept.
        let mut m = ModuleSense::default();
        assert!(!sample(&mut m, 12.0, true, 0.0));
        assert!(!sample(&mut m, 12.0, true, 0.0));
        assert!(!m.shorted(&CFG, Some(12.0)));
        // Without a supply measurement the limit is 6 V.
        m.observe(7.0);
        assert!(m.shorted(&CFG, None));
    }
}
