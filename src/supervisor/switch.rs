//! Supply-switch check: the modules' supply switch (the second cut-off after the SSR) shorted.
//!
//! The switched rail — the supply measured *after* the switch — is judged whenever the switch
//! has been commanded open for [`SwitchConfig::settle_s`]: reading powered, the switch is
//! shorted ([`EventKind::SupplySwitchShorted`], reported once; the alarm latches on it). The
//! switch opens for that whenever the supervisor opens it anyway (sensor fault, freeze guard,
//! supply probe, limp home), and otherwise for a test every [`SwitchConfig::test_interval_s`]
//! in normal control, once the load is at or below its setpoint. Without a rail measurement (a
//! board without the sense, a replayed trace) there is no check and no test opening.
//!
//! A test opening leaves the duty what the controller asked: told that none was applied, a PI's
//! anti-windup tracking would unwind its integral and let the load warm by 0.6 °C over the
//! next 10 min; the 20 s without supply are a small disturbance it rejects.

use super::{samples_u32, samples_u8};
use crate::event::EventKind;
use crate::units::max_f32;

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
    /// The switch must have been commanded open this long before the rail is judged, s (20 s =
    /// 2 samples, so the first reading after opening, the rail's capacitance still bleeding
    /// down, never counts). A test opening lasts as long.
    pub settle_s: f32,
    /// Time between test openings when nothing else opened the switch, s; 0: no test openings
    /// (an identification run, whose record a 20 s gap in the input would spoil; the switch is
    /// then only judged when the supervisor opens it). 7200 s = 2 h: an unpowered module lets
    /// its hot side's heat flow back, and the load warms by up to ≈ 0.25 °C (half-loaded H-TER I
    /// in hal-sim) before the controller has it back, so a test waits until the load is at or
    /// below its setpoint (it then ends at most that much above it, deep inside 2–8 °C); a load
    /// held above its setpoint at full capacity is never opened on. Every 2 h finds a latent
    /// short well within the day, and within any 24 h `hter campaign` mission whose load
    /// reaches its setpoint after the fault.
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
}

/// State of the supply-switch check, counted in samples.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SwitchCheck {
    /// Samples open before the rail is judged, and the length of a test opening.
    settle_n: u8,
    /// Samples between test openings (0: none).
    interval_n: u32,
    /// The switched rail measured for this sample, V (`None`: the board has no sense).
    rail_v: Option<f32>,
    /// The supply-enable level of the previous output (what the rail now shows).
    last_enable: bool,
    /// Samples in a row the switch has been commanded open, up to the previous output.
    open_run: u8,
    reported: bool,
    /// Samples since the rail was last seen with the switch open long enough to judge it.
    since_check: u32,
    /// Samples of the test opening still to go.
    test_left: u8,
    /// No test openings for now (an identification run: an opening would spoil its record).
    held: bool,
}

impl SwitchCheck {
    pub(crate) fn new(cfg: &SwitchConfig, ts_s: f32) -> Self {
        SwitchCheck {
            settle_n: samples_u8(cfg.settle_s, ts_s),
            interval_n: samples_u32(cfg.test_interval_s, ts_s),
            rail_v: None,
            last_enable: true,
            open_run: 0,
            reported: false,
            since_check: 0,
            test_left: 0,
            held: false,
        }
    }

    /// Holds the periodic test openings off (`true`) or lets them resume; the switch is still
    /// checked whenever another mode opens it.
    pub(crate) fn hold_tests(&mut self, held: bool) {
        self.held = held;
    }

    /// Takes the switched rail measured for the next sample, V.
    pub(crate) fn observe(&mut self, v: f32) {
        self.rail_v = Some(v);
    }

    /// The shorted-switch detector, run every sample on the rail measured with the switch in
    /// the state of the previous output, against the measured supply `supply_v`.
    pub(crate) fn check(&mut self, cfg: &SwitchConfig, supply_v: Option<f32>, emit: &mut impl FnMut(EventKind)) {
        let Some(rail) = self.rail_v else { return };
        self.open_run = if self.last_enable { 0 } else { self.open_run.saturating_add(1) };
        if self.open_run < self.settle_n {
            return;
        }
        self.since_check = 0;
        let limit = match supply_v {
            Some(v) if v.is_finite() => max_f32(cfg.open_max_fraction * v, cfg.open_floor_v),
            _ => cfg.open_max_v,
        };
        // NaN (a broken sense) is not a short: it fails `>`.
        if rail > limit && !self.reported {
            self.reported = true;
            emit(EventKind::SupplySwitchShorted);
        }
    }

    /// Whether this sample opens the switch for the periodic test: only in normal control
    /// (`normal`: every other mode opens it itself, or needs it closed to limp home), only with
    /// the sense present, never once a short has been found (the test can tell nothing more),
    /// and only starting with the filtered load `temp_c` at or below the setpoint `w`.
    pub(crate) fn test_due(&mut self, normal: bool, temp_c: f32, w: f32) -> bool {
        if self.interval_n == 0 || self.rail_v.is_none() || self.reported || !normal || self.held {
            self.test_left = 0;
            return false;
        }
        self.since_check = self.since_check.saturating_add(1);
        if self.test_left == 0 && self.since_check >= self.interval_n && temp_c <= w {
            self.test_left = self.settle_n;
        }
        if self.test_left > 0 {
            self.test_left -= 1;
            true
        } else {
            false
        }
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
        c.observe(rail_v);
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

    /// Runs `n` samples of normal control with the load at `temp_c` and the setpoint `w`,
    /// a working switch, the test openings the only ones; the samples that opened it.
    fn openings(c: &mut SwitchCheck, n: u32, normal: bool, temp_c: f32, w: f32) -> Vec<u32> {
        let mut enabled = true;
        (0..n)
            .filter(|_| {
                c.observe(if enabled { 11.9 } else { 0.01 });
                c.check(&SwitchConfig::DEFAULT, Some(12.0), &mut |e| panic!("{e:?}"));
                let test = c.test_due(normal, temp_c, w);
                enabled = c.note_enable(!test);
                test
            })
            .collect()
    }

    #[test]
    fn a_test_opening_every_two_hours_of_two_samples() {
        assert_eq!(openings(&mut check(), 1500, true, 5.0, 5.1), [719, 720, 1440, 1441]);
        // Not above the setpoint, not outside normal control.
        assert_eq!(openings(&mut check(), 1500, true, 5.2, 5.1), [] as [u32; 0]);
        assert_eq!(openings(&mut check(), 1500, false, 5.0, 5.1), [] as [u32; 0]);
        // Not while held (an identification run), and again once released.
        let mut c = check();
        c.hold_tests(true);
        assert_eq!(openings(&mut c, 1500, true, 5.0, 5.1), [] as [u32; 0]);
        c.hold_tests(false);
        assert_eq!(openings(&mut c, 1500, true, 5.0, 5.1), [719, 720, 1440, 1441], "a full interval after");
        // Not with test openings off.
        let mut c = SwitchCheck::new(&SwitchConfig { test_interval_s: 0.0, ..SwitchConfig::DEFAULT }, 10.0);
        assert_eq!(openings(&mut c, 1500, true, 5.0, 5.1), [] as [u32; 0]);
        // Not without the sense, nor once a short was found.
        let mut c = check();
        assert!((0..1500).all(|_| !c.test_due(true, 5.0, 5.1)), "no sense");
        let mut c = check();
        sample(&mut c, 11.9, Some(12.0), false);
        sample(&mut c, 11.9, Some(12.0), false);
        assert!(sample(&mut c, 11.9, Some(12.0), true));
        assert!((0..1500).all(|_| !c.test_due(true, 5.0, 5.1)), "found");
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

    /// Runs `n` samples holding 5 °C at setpoint `w` with the rail reading what a switch that is
    /// `shorted` (or not) shows; returns the samples that opened the switch and when the short
    /// was reported.
    fn run(n: u32, shorted: bool, w: f32) -> (Vec<u32>, Option<u32>) {
        let mut c = carrier();
        let (mut opened, mut found, mut enabled) = (Vec::new(), None, true);
        for k in 0..n {
            c.observe_supply_v(12.0);
            c.observe_switched_rail_v(if enabled || shorted { 11.9 } else { 0.01 });
            let out = c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: w });
            if out.events.iter().any(|e| e.kind == EventKind::SupplySwitchShorted) {
                assert!(found.is_none(), "reported twice");
                found = Some(k);
            }
            enabled = out.supply_enable;
            if !enabled {
                // The controller's duty stays (the switch alone opens).
                assert_eq!(out.duty, Duty::saturating(out.requested), "sample {k}");
                assert_eq!(out.mode, Mode::Normal);
                opened.push(k);
            }
        }
        (opened, found)
    }

    #[test]
    fn a_shorted_switch_is_found_by_the_test_opening() {
        let (opened, found) = run(1600, true, 5.1);
        assert_eq!(opened[..2], [719, 720], "first test after two hours, two samples");
        assert_eq!(found, Some(721), "judged on the second reading with the switch open");
        // Found: no more test openings.
        assert_eq!(opened.len(), 2, "{opened:?}");
        let (opened, found) = run(1600, false, 5.1);
        assert_eq!(found, None);
        assert_eq!(opened, [719, 720, 1440, 1441], "one test every two hours");
        // A load above its setpoint is never opened on (the test would warm it further).
        assert_eq!(run(1600, true, 4.9), (vec![], None));
    }

    #[test]
    fn no_sense_no_test_and_no_check() {
        let mut c = carrier();
        for k in 0..1600u32 {
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.supply_enable && out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted));
        }
        // Test openings off (an identification run): the sense alone opens nothing.
        let mut cfg = CarrierConfig::DEFAULT;
        cfg.supervisor.switch.test_interval_s = 0.0;
        let mut c =
            Carrier::new(cfg.validated().unwrap(), AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)));
        for k in 0..1600u32 {
            c.observe_switched_rail_v(11.9);
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.supply_enable, "sample {k}");
        }
    }

    #[test]
    fn a_rail_that_bleeds_down_slowly_is_no_short() {
        // The first reading after opening still shows the rail's charge: not judged.
        let mut c = carrier();
        let (mut enabled, mut open_for, mut opened) = (true, 0, 0);
        for k in 0..1600u32 {
            c.observe_supply_v(12.0);
            open_for = if enabled { 0 } else { open_for + 1 };
            c.observe_switched_rail_v(if enabled || open_for == 1 { 11.9 } else { 0.05 });
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted), "sample {k}");
            enabled = out.supply_enable;
            opened += u32::from(!enabled);
        }
        assert_eq!(opened, 4, "two test openings were judged");
        // The floor: a dead supply (0 V) whose rail reads a little noise is not a short.
        let mut c = carrier();
        for k in 0..1600u32 {
            c.observe_supply_v(0.0);
            c.observe_switched_rail_v(0.3);
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted), "sample {k}");
            opened += u32::from(!out.supply_enable);
        }
        assert_eq!(opened, 8, "and judged twice more");
    }
}
