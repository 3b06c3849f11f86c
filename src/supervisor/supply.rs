//! Supply monitor: the measured supply of the Peltier modules sagging below its minimum (a
//! failing battery, a weak car socket or solar panel). Cooling power falls with the square of
//! the voltage, so a sag is reported ([`EventKind::SupplySag`]) once, and re-armed only when the
//! supply is clearly back, so a supply hovering at the threshold does not report every minute.

use super::samples_u8;
use crate::event::EventKind;

/// Settings of the supply monitor.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SupplyConfig {
    /// A sag is the supply below this, V (12 V nominal − 10 %)…
    pub min_v: f32,
    /// …for this long in a row, s (30 s = 3 samples).
    pub sag_s: f32,
    /// The report re-arms once the supply is at or above `min_v` plus this, V.
    pub rearm_margin_v: f32,
}

impl SupplyConfig {
    /// The reference board's settings.
    pub const DEFAULT: SupplyConfig = SupplyConfig { min_v: 10.8, sag_s: 30.0, rearm_margin_v: 0.5 };
}

/// The supply monitor's state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SupplyMonitor {
    /// Samples below the minimum that are a sag.
    sag_n: u8,
    /// The last measured supply, V (`None`: the board does not measure it).
    v: Option<f32>,
    /// Samples in a row below the minimum.
    low_run: u8,
    reported: bool,
}

impl SupplyMonitor {
    pub(crate) fn new(cfg: &SupplyConfig, ts_s: f32) -> Self {
        SupplyMonitor { sag_n: samples_u8(cfg.sag_s, ts_s), v: None, low_run: 0, reported: false }
    }

    /// Takes the measured supply for the next sample, V (`None`: not read: no check this
    /// sample, and the run of low samples neither grows nor ends).
    pub(crate) fn observe(&mut self, v: Option<f32>) {
        self.v = v;
    }

    /// The last measured supply, V.
    pub(crate) fn v(&self) -> Option<f32> {
        self.v
    }

    /// The check, once a sample, on the last measured supply (none: no check).
    pub(crate) fn run(&mut self, cfg: &SupplyConfig, emit: &mut impl FnMut(EventKind)) {
        let Some(v) = self.v else { return };
        if v < cfg.min_v {
            self.low_run = self.low_run.saturating_add(1);
            if self.low_run >= self.sag_n && !self.reported {
                self.reported = true;
                emit(EventKind::SupplySag);
            }
        } else {
            self.low_run = 0;
            if v >= cfg.min_v + cfg.rearm_margin_v {
                self.reported = false;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the monitor over `volts`; the samples that reported a sag.
    fn sags(m: &mut SupplyMonitor, volts: &[f32]) -> Vec<usize> {
        let mut out = Vec::new();
        for (k, v) in volts.iter().enumerate() {
            m.observe(Some(*v));
            let mut n = 0;
            m.run(&SupplyConfig::DEFAULT, &mut |e| {
                assert_eq!(e, EventKind::SupplySag);
                n += 1;
            });
            if n > 0 {
                out.push(k);
            }
        }
        out
    }

    #[test]
    fn a_sag_is_three_samples_below_the_minimum() {
        let mut m = SupplyMonitor::new(&SupplyConfig::DEFAULT, 10.0);
        assert_eq!(sags(&mut m, &[12.0, 10.7, 10.7, 10.8, 10.7, 10.7]), [] as [usize; 0], "10.8 V is not below");
        assert_eq!(sags(&mut m, &[10.7]), [0], "the third in a row");
        assert_eq!(sags(&mut m, &[10.7; 20]), [] as [usize; 0], "once");
    }

    #[test]
    fn it_re_arms_at_the_minimum_plus_half_a_volt() {
        let mut m = SupplyMonitor::new(&SupplyConfig::DEFAULT, 10.0);
        assert_eq!(sags(&mut m, &[10.0, 10.0, 10.0]), [2]);
        // Back to 11.2 V: not re-armed.
        assert_eq!(sags(&mut m, &[11.2, 10.0, 10.0, 10.0]), [] as [usize; 0]);
        // 11.3 V re-arms.
        assert_eq!(sags(&mut m, &[11.3, 10.0, 10.0, 10.0]), [3]);
    }

    #[test]
    fn no_measurement_no_check() {
        let mut m = SupplyMonitor::new(&SupplyConfig::DEFAULT, 10.0);
        for _ in 0..10 {
            m.run(&SupplyConfig::DEFAULT, &mut |e| panic!("{e:?}"));
        }
        assert_eq!(m.v(), None);
    }
}
