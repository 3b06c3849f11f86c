//! Supply-switch check: the modules' supply switch (the second cut-off after the SSR) shorted.
//!
//! The switched rail — the supply measured *after* the switch — is judged whenever the switch
//! has been open long enough for a working one to have emptied the rail: reading powered, the
//! switch is shorted ([`EventKind::SupplySwitchShorted`], reported once; the alarm latches on
//! it). That happens two ways:
//!
//! - whenever the supervisor opens the switch anyway (sensor fault, freeze guard, supply probe,
//!   limp home), on the rail read after [`SwitchConfig::settle_s`] open;
//! - in normal control, by a **test pulse** every [`SwitchConfig::test_interval_s`]: the step
//!   asks for it ([`crate::step::StepOutput::switch_test`]), and the board opens the switch for
//!   [`TEST_PULSE_MS`] with the drive running, reads the rail at the end, closes the switch again
//!   and hands the reading to the next step
//!   ([`crate::step::Carrier::observe_switch_test_v`]).
//!
//! Without a rail measurement (a board without the sense, a replayed trace) there is no check
//! and no test.
//!
//! **Why a pulse.** A test that opened the switch for two whole samples (20 s, the rail judged
//! on the second reading) cost the modules 20 s of cooling and let the unpowered modules conduct
//! the hot side's heat back: the load rose 0.18–0.32 °C on a half-loaded H-TER I every time (the
//! RTD sees it only after its 40 s of lag, too late for feedback), more than the 0.1 °C a steady
//! hold must keep (issue 18). The pulse costs 50 ms of drive — 0.5 % of one sample's cooling.
//! It needs a working switch's rail to empty within the pulse. On the SSR board nothing but the
//! 57 kΩ sense divider and the MOSFET's nanofarads sit after the switch (τ well under a
//! millisecond). On the buck board the 100 µF input capacitor (README, wiring) would only bleed
//! through the divider (τ ≈ 5.7 s) with the converter idle, and a synchronous buck at duty D
//! holds its input at the module's Seebeck voltage ÷ D (at D = 0.15 and a 20 K difference,
//! 1.06 V / 0.15 ≈ 7 V: over the 6 V limit), so the firmware drives the buck at its ceiling
//! (0.95) for the pulse: the capacitor empties into the 2 Ω module in ≈ 0.2 ms. Either way the
//! rail then reads what the module gives back through the conducting drive, its Seebeck voltage
//! αΔT — 0.053 V/K × up to 60 K ≈ 3.2 V — under the 6 V limit (half the 12 V supply), as it did
//! at the end of the 20 s openings the test once was.
//!
//! A test pulse leaves the duty what the controller asked, and the controller is not told of
//! it: the 50 ms are a disturbance far below the sensor's resolution.

use super::{samples_u32, samples_u8};
use crate::event::EventKind;
use crate::units::max_f32;

/// How long the board opens the switch for a test pulse before it reads the rail, ms (see the
/// module's note for why this empties a working switch's rail on both drives).
pub const TEST_PULSE_MS: u32 = 50;

/// Settings of the supply-switch check.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SwitchConfig {
    /// With the switch commanded open, the switched rail reading above this fraction of the
    /// measured supply is a short (a working, open switch leaves the rail at the bleeder's few
    /// millivolts; a shorted one at the supply minus its ≈ 0.1 V drop)…
    pub open_max_fraction: f32,
    /// …but never below this, V (a dead or missing supply reads noise, not a short)…
    pub open_floor_v: f32,
    /// …or, without a supply measurement, above this, V (half the 12 V nominal).
    pub open_max_v: f32,
    /// When the supervisor opens the switch itself, it must have been open this long before the
    /// rail is judged, s (20 s = 2 samples, so the first reading after opening — the buck's
    /// input capacitor still bleeding through the divider with the drive off — never counts).
    pub settle_s: f32,
    /// Time between test pulses when nothing else opened the switch, s; 0: no test pulses (an
    /// identification run, whose record should see only its own excitation; the switch is then
    /// only judged when the supervisor opens it). 7200 s = 2 h finds a latent short well within
    /// the day, and within any 24 h `hter campaign` mission whose drive runs after the fault.
    pub test_interval_s: f32,
}

impl SwitchConfig {
    /// The reference board's settings.
    pub const DEFAULT: SwitchConfig = SwitchConfig {
        open_max_fraction: 0.5,
        open_floor_v: 2.0,
        open_max_v: 6.0,
        settle_s: 20.0,
        test_interval_s: 7200.0,
    };

    /// The reading above which a node behind the supply reads powered, V: [`Self::open_max_fraction`]
    /// of the measured supply `supply_v` but never below `floor_v`, or [`Self::open_max_v`]
    /// without a (finite) supply measurement. The switch check's floor is
    /// [`Self::open_floor_v`]; the module-side sense's is above the modules' Seebeck voltage.
    pub fn powered_above_v(&self, supply_v: Option<f32>, floor_v: f32) -> f32 {
        match supply_v {
            Some(v) if v.is_finite() => max_f32(self.open_max_fraction * v, floor_v),
            _ => self.open_max_v,
        }
    }
}

/// State of the supply-switch check, counted in samples.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SwitchCheck {
    /// Samples open before the rail is judged.
    settle_n: u8,
    /// Samples between test pulses (0: none).
    interval_n: u32,
    /// The switched rail measured for this sample, V (`None`: the board has no sense).
    rail_v: Option<f32>,
    /// The rail read at the end of a test pulse since the last sample, V.
    pulse_v: Option<f32>,
    /// The supply-enable level of the previous output (what the rail now shows).
    last_enable: bool,
    /// Samples in a row the switch has been commanded open, up to the previous output.
    open_run: u8,
    reported: bool,
    /// Samples since the rail was last judged or a test pulse was asked for.
    since_check: u32,
    /// No test pulses for now (an identification run).
    held: bool,
}

impl SwitchCheck {
    pub(crate) fn new(cfg: &SwitchConfig, ts_s: f32) -> Self {
        SwitchCheck {
            settle_n: samples_u8(cfg.settle_s, ts_s),
            interval_n: samples_u32(cfg.test_interval_s, ts_s),
            rail_v: None,
            pulse_v: None,
            last_enable: true,
            open_run: 0,
            reported: false,
            since_check: 0,
            held: false,
        }
    }

    /// Holds the periodic test pulses off (`true`) or lets them resume; the switch is still
    /// checked whenever another mode opens it.
    pub(crate) fn hold_tests(&mut self, held: bool) {
        self.held = held;
    }

    /// Takes the switched rail measured for the next sample, V (`None`: not read: no judgement
    /// and no test pulse this sample).
    pub(crate) fn observe(&mut self, v: Option<f32>) {
        self.rail_v = v;
    }

    /// Takes the switched rail read at the end of a test pulse, V, for the next sample.
    pub(crate) fn observe_pulse(&mut self, v: f32) {
        self.pulse_v = Some(v);
    }

    /// The shorted-switch detector, run every sample on the rail measured with the switch in
    /// the state of the previous output (or at the end of a test pulse), against the measured
    /// supply `supply_v`.
    pub(crate) fn check(&mut self, cfg: &SwitchConfig, supply_v: Option<f32>, emit: &mut impl FnMut(EventKind)) {
        let pulse = self.pulse_v.take();
        let Some(rail) = self.rail_v else { return };
        self.open_run = if self.last_enable { 0 } else { self.open_run.saturating_add(1) };
        let rail = match pulse {
            Some(v) => v,
            None if self.open_run >= self.settle_n => rail,
            None => return,
        };
        self.since_check = 0;
        let limit = cfg.powered_above_v(supply_v, cfg.open_floor_v);
        // NaN (a broken sense) is not a short: it fails `>`.
        if rail > limit && !self.reported {
            self.reported = true;
            emit(EventKind::SupplySwitchShorted);
        }
    }

    /// Whether this sample asks the board for a test pulse: one every interval, only in normal
    /// control with the switch closed (`normal`: every other mode opens it itself, or needs it
    /// closed to limp home), only with the sense present, and never once a short has been found
    /// (the test can tell nothing more).
    pub(crate) fn test_due(&mut self, normal: bool) -> bool {
        if self.interval_n == 0 || self.rail_v.is_none() || self.reported || !normal || self.held {
            return false;
        }
        self.since_check = self.since_check.saturating_add(1);
        let due = self.since_check >= self.interval_n;
        if due {
            self.since_check = 0;
        }
        due
    }

    /// Remembers the supply-enable level this sample outputs (the next rail reading shows it).
    pub(crate) fn note_enable(&mut self, enable: bool) -> bool {
        self.last_enable = enable;
        enable
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check() -> SwitchCheck {
        SwitchCheck::new(&SwitchConfig::DEFAULT, 10.0)
    }

    /// One sample: the rail reads `rail_v`, the check runs, then the output `enable`.
    fn sample(c: &mut SwitchCheck, rail_v: f32, supply_v: Option<f32>, enable: bool) -> bool {
        c.observe(Some(rail_v));
        let mut found = false;
        c.check(&SwitchConfig::DEFAULT, supply_v, &mut |e| {
            assert_eq!(e, EventKind::SupplySwitchShorted);
            found = true;
        });
        c.note_enable(enable);
        found
    }

    #[test]
    fn the_rail_is_judged_on_the_second_sample_open() {
        let mut c = check();
        assert_eq!((c.settle_n, c.interval_n), (2, 720));
        assert!(!sample(&mut c, 11.9, Some(12.0), false));
        assert!(!sample(&mut c, 11.9, Some(12.0), false), "the first reading open still bleeds down");
        assert!(sample(&mut c, 11.9, Some(12.0), false), "the second is judged");
        assert!(!sample(&mut c, 11.9, Some(12.0), false), "reported once");
    }

    #[test]
    fn the_limit_is_half_the_supply_with_a_floor_or_six_volts_without_it() {
        let judged = |rail: f32, supply: Option<f32>| {
            let mut c = check();
            sample(&mut c, rail, supply, false);
            sample(&mut c, rail, supply, false);
            sample(&mut c, rail, supply, false)
        };
        assert!(!judged(6.0, Some(12.0)) && judged(6.01, Some(12.0)));
        assert!(!judged(2.0, Some(1.0)) && judged(2.01, Some(1.0)), "the 2 V floor");
        assert!(!judged(6.0, None) && judged(6.01, None));
        assert!(!judged(6.0, Some(f32::NAN)) && judged(6.01, Some(f32::NAN)));
        assert!(!judged(f32::NAN, Some(12.0)), "a broken sense is no short");
    }

    /// Runs `n` samples of normal control (or not) with a working switch; the samples that
    /// asked for a test pulse (whose reading, the rail emptied, comes with the next sample).
    fn pulses(c: &mut SwitchCheck, n: u32, normal: bool) -> Vec<u32> {
        let mut pulsed = false;
        (0..n)
            .filter(|_| {
                c.observe(Some(11.9));
                if pulsed {
                    c.observe_pulse(0.01);
                }
                c.check(&SwitchConfig::DEFAULT, Some(12.0), &mut |e| panic!("{e:?}"));
                pulsed = c.test_due(normal);
                c.note_enable(true);
                pulsed
            })
            .collect()
    }

    #[test]
    fn a_test_pulse_every_two_hours() {
        assert_eq!(pulses(&mut check(), 1500, true), [719, 1439]);
        // Not outside normal control.
        assert_eq!(pulses(&mut check(), 1500, false), [] as [u32; 0]);
        // Not while held (an identification run), and again once released.
        let mut c = check();
        c.hold_tests(true);
        assert_eq!(pulses(&mut c, 1500, true), [] as [u32; 0]);
        c.hold_tests(false);
        assert_eq!(pulses(&mut c, 1500, true), [719, 1439], "a full interval after");
        // Not with test pulses off.
        let mut c = SwitchCheck::new(&SwitchConfig { test_interval_s: 0.0, ..SwitchConfig::DEFAULT }, 10.0);
        assert_eq!(pulses(&mut c, 1500, true), [] as [u32; 0]);
        // Not without the sense, nor once a short was found.
        let mut c = check();
        assert!((0..1500).all(|_| !c.test_due(true)), "no sense");
        let mut c = check();
        sample(&mut c, 11.9, Some(12.0), false);
        sample(&mut c, 11.9, Some(12.0), false);
        assert!(sample(&mut c, 11.9, Some(12.0), true));
        assert!((0..1500).all(|_| !c.test_due(true)), "found");
    }

    #[test]
    fn a_pulse_reading_is_judged_at_once() {
        // Powered at the end of the pulse: shorted, on the next sample, with the switch closed.
        let mut c = check();
        sample(&mut c, 11.9, Some(12.0), true);
        c.observe_pulse(11.8);
        assert!(sample(&mut c, 11.9, Some(12.0), true));
        // Emptied: a working switch; the reading is used once.
        let mut c = check();
        c.observe_pulse(0.02);
        assert!(!sample(&mut c, 11.9, Some(12.0), true));
        assert!(!sample(&mut c, 11.9, Some(12.0), true), "the closed rail is never judged");
        // A broken sense (NaN) is no short; a dead supply's noise neither (the 2 V floor).
        let mut c = check();
        c.observe_pulse(f32::NAN);
        assert!(!sample(&mut c, 11.9, Some(12.0), true));
        c.observe_pulse(0.3);
        assert!(!sample(&mut c, 0.3, Some(0.0), true));
    }
}

/// The supply-switch check as the step runs it.
#[cfg(test)]
mod carrier {
    use crate::control::AnyController;
    use crate::event::EventKind;
    use crate::step::tests::{counts_at, pi_carrier as carrier};
    use crate::step::{Carrier, CarrierConfig, Mode, StepInput};
    use crate::units::Duty;

    /// Runs `n` samples holding 5 °C at setpoint `w` with the supply at `supply_v` and the rail
    /// reading what a switch that is `shorted` (or not) shows, the test pulses read the same way;
    /// returns the samples that asked for a pulse and when the short was reported.
    fn run(n: u32, shorted: bool, w: f32, supply_v: f32) -> (Vec<u32>, Option<u32>) {
        let mut c = carrier();
        let (mut pulsed, mut found, mut pulse) = (Vec::new(), None, false);
        let rail = if supply_v > 1.0 { 11.9 } else { 0.3 };
        for k in 0..n {
            c.observe_supply_v(supply_v);
            c.observe_switched_rail_v(rail);
            if pulse {
                c.observe_switch_test_v(if shorted { rail } else { 0.01 });
            }
            let out = c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: w });
            if out.events.iter().any(|e| e.kind == EventKind::SupplySwitchShorted) {
                assert!(found.is_none(), "reported twice");
                found = Some(k);
            }
            // The pulse leaves the switch closed and the controller's duty as asked.
            assert!(out.supply_enable && out.mode == Mode::Normal, "sample {k}");
            assert_eq!(out.duty, Duty::saturating(out.requested), "sample {k}");
            pulse = out.switch_test;
            if pulse {
                pulsed.push(k);
            }
        }
        (pulsed, found)
    }

    #[test]
    fn a_shorted_switch_is_found_by_the_test_pulse() {
        let (pulsed, found) = run(1600, true, 4.9, 12.0);
        assert_eq!(pulsed, [719], "first test after two hours; found, no more");
        assert_eq!(found, Some(720), "judged on the next sample");
        let (pulsed, found) = run(1600, false, 4.9, 12.0);
        assert_eq!(found, None);
        assert_eq!(pulsed, [719, 1439], "one test every two hours");
        // Whatever the duty: below its setpoint the PI winds it down to 0.
        assert_eq!(run(1600, false, 5.1, 12.0), (vec![719, 1439], None));
        // A dead supply (0 V) whose rail reads a little noise is not a short.
        assert_eq!(run(1600, true, 4.9, 0.0), (vec![719, 1439], None));
    }

    #[test]
    fn no_sense_no_test_and_no_check() {
        let mut c = carrier();
        for k in 0..1600u32 {
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 4.9 });
            assert!(out.supply_enable && !out.switch_test);
            assert!(out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted));
        }
        // Test pulses off (an identification run): the sense alone asks for nothing.
        let mut cfg = CarrierConfig::DEFAULT;
        cfg.supervisor.switch.test_interval_s = 0.0;
        let mut c =
            Carrier::new(cfg.validated().unwrap(), AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)));
        for k in 0..1600u32 {
            c.observe_switched_rail_v(11.9);
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 4.9 });
            assert!(out.supply_enable && !out.switch_test, "sample {k}");
        }
    }
}
