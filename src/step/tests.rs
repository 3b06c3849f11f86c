//! The step's own tests; each detector's are beside it in `crate::supervisor`.

use super::*;
use crate::control::AnyController;
use proptest::prelude::*;

/// The counts the default front end reads at `t` °C.
pub(crate) fn counts_at(t: f32) -> u32 {
    let cfg = CarrierConfig::DEFAULT;
    cfg.adc.counts(cfg.rtd.resistance(Celsius(t)).unwrap())
}

/// A default carrier under the profile's PI.
pub(crate) fn pi_carrier() -> Carrier<AnyController> {
    Carrier::new(ValidConfig::DEFAULT, AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)))
}

/// The kinds of a sample's events, in order.
pub(crate) fn kinds(out: &StepOutput) -> Vec<EventKind> {
    out.events.iter().map(|e| e.kind).collect()
}

#[test]
fn a_configuration_the_step_cannot_honour_is_refused_before_it_runs() {
    let mut cfg = CarrierConfig::DEFAULT;
    // A stuck-on window the SSR monitor's history cannot hold would switch that check off.
    cfg.supervisor.ssr.stuck_on.window_s = 600.0;
    assert_eq!(cfg.validated().err(), Some(ConfigError::Window("ssr.stuck_on.window_s")));
    let setpoints = CarrierConfig { setpoint_min_c: 8.0, setpoint_max_c: 2.0, ..CarrierConfig::DEFAULT };
    assert_eq!(setpoints.validated().err(), Some(ConfigError::Setpoints));
    let nan = CarrierConfig { plausible_max_c: f32::NAN, ..CarrierConfig::DEFAULT };
    assert_eq!(nan.validated().err(), Some(ConfigError::Setpoints));
    let filter = CarrierConfig { filter: crate::filter::FirstOrderConfig { fa: 1.0 }, ..CarrierConfig::DEFAULT };
    assert_eq!(filter.validated().err(), Some(ConfigError::Filter));
    let ts = CarrierConfig { ts_s: -10.0, ..CarrierConfig::DEFAULT };
    assert_eq!(ts.validated().err(), Some(ConfigError::SamplePeriod));
    assert_eq!(CarrierConfig::DEFAULT.validated(), Ok(ValidConfig::DEFAULT));
}

#[test]
fn measures_within_the_resolution() {
    let mut c = pi_carrier();
    let out = c.step(&StepInput { t_ms: 0, counts: counts_at(4.0), setpoint_c: 4.0 });
    assert!((out.temp_c.0 - 4.0).abs() < 0.01, "{:?}", out.temp_c);
    assert_eq!(out.mode, Mode::Normal);
    assert!(out.supply_enable);
}

#[test]
fn setpoint_below_two_degrees_is_clamped() {
    let mut c = pi_carrier();
    let out = c.step(&StepInput { t_ms: 0, counts: counts_at(4.0), setpoint_c: -5.0 });
    assert_eq!(out.setpoint_c.0, 2.0);
    assert_eq!(kinds(&out), [EventKind::SetpointClamped]);
    let again = c.step(&StepInput { t_ms: 10_000, counts: counts_at(4.0), setpoint_c: -5.0 });
    assert!(again.events.is_empty(), "reported when the clamp begins");
    let nan = c.step(&StepInput { t_ms: 20_000, counts: counts_at(4.0), setpoint_c: f32::NAN });
    assert_eq!(nan.setpoint_c.0, 4.0);
    let high = c.step(&StepInput { t_ms: 30_000, counts: counts_at(4.0), setpoint_c: 9.0 });
    assert_eq!(high.setpoint_c.0, 8.0);
}

#[test]
fn restarts_and_board_faults_are_reported_with_the_next_sample() {
    let mut c = pi_carrier();
    c.note_reset(crate::persist::ResetCause::Watchdog);
    c.note_board_fault(crate::failsafe::StopKind::Panic);
    let out = c.step(&StepInput { t_ms: 0, counts: counts_at(4.0), setpoint_c: 4.0 });
    assert_eq!(
        kinds(&out),
        [
            EventKind::Restarted(crate::persist::ResetCause::Watchdog),
            EventKind::BoardFault(crate::failsafe::StopKind::Panic)
        ]
    );
    assert!(c.step(&StepInput { t_ms: 10_000, counts: counts_at(4.0), setpoint_c: 4.0 }).events.is_empty());
    // A stop the boot before did not store and the one after it: both, oldest first.
    c.note_board_fault(crate::failsafe::StopKind::Panic);
    c.note_board_fault(crate::failsafe::StopKind::HardFault);
    // A third replaces the newest, not a mix of two kinds' bits.
    c.note_board_fault(crate::failsafe::StopKind::ControlStall);
    let out = c.step(&StepInput { t_ms: 20_000, counts: counts_at(4.0), setpoint_c: 4.0 });
    assert_eq!(
        kinds(&out),
        [
            EventKind::BoardFault(crate::failsafe::StopKind::Panic),
            EventKind::BoardFault(crate::failsafe::StopKind::ControlStall)
        ]
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    /// Arbitrary conversions (including stuck runs, rails and noise) never panic, never give
    /// a non-finite or out-of-range duty.
    #[test]
    fn arbitrary_counts_give_a_valid_duty(counts in proptest::collection::vec(prop_oneof![any::<u32>(), 0u32..70_000, Just(49_900u32)], 1..400)) {
        let mut c = pi_carrier();
        for (k, n) in counts.iter().enumerate() {
            let out = c.step(&StepInput { t_ms: k as u64 * 10_000, counts: *n, setpoint_c: 4.0 });
            prop_assert!(out.duty.get().is_finite() && (0.0..=1.0).contains(&out.duty.get()));
        }
    }
}

#[test]
fn below_the_floor_with_nothing_asked_the_supply_switch_opens_too() {
    // A load held cold by a cold ambient, the controller asking for nothing: the switch opens,
    // in normal control (no event: nothing is wrong), and closes again once the load is back
    // at the floor. The load drifts slowly, so the freeze guard never trips.
    let mut c = pi_carrier();
    let mut t_ms = 0;
    let mut run = |c: &mut Carrier<AnyController>, temp: f32, n: u32| {
        let mut out = None;
        for k in 0..n {
            // The converter's noise (constant counts read as a stuck sensor).
            let o = c.step(&StepInput { t_ms, counts: counts_at(temp) + k % 3, setpoint_c: 4.0 });
            assert_eq!((o.mode, o.duty), (Mode::Normal, Duty::OFF), "{temp} °C");
            assert!(o.events.is_empty(), "{temp} °C: {:?}", kinds(&o));
            t_ms += 10_000;
            out = Some(o);
        }
        out.unwrap()
    };
    let floor = CarrierConfig::DEFAULT.supervisor.freeze.idle_open_c;
    assert!(run(&mut c, floor + 0.05, 30).supply_enable, "at the floor: closed");
    assert!(!run(&mut c, floor - 0.1, 30).supply_enable, "below it, nothing asked: open");
    assert!(run(&mut c, floor + 0.05, 30).supply_enable, "back at the floor: closed again");
    // Falling at 0.18 °C/min with nothing asked (what a shorted SSR does to a heavy load) is for
    // the freeze guard and the SSR checks to see: the switch stays closed below the floor until
    // they act. (The SSR checks' supply probe, which would open it on such a fall after 10 min,
    // is off.)
    let mut cfg = CarrierConfig::DEFAULT;
    cfg.supervisor.ssr.probe.fall_c = f32::INFINITY;
    let mut c = Carrier::new(cfg.validated().unwrap(), AnyController::Pi(crate::profile::pi(cfg.ts_s)));
    let (mut temp, mut below_floor_closed) = (floor + 0.15, 0);
    for k in 0..60u32 {
        let o = c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(temp) + k % 3, setpoint_c: 4.0 });
        if o.mode != Mode::Normal {
            assert!(below_floor_closed >= 3, "{below_floor_closed} samples below the floor, switch closed");
            return;
        }
        assert_eq!((o.mode, o.duty, o.supply_enable), (Mode::Normal, Duty::OFF, true), "{temp} °C");
        below_floor_closed += u32::from(o.temp_c.0 < floor);
        if k >= 30 {
            temp -= 0.03;
        }
    }
    panic!("the guard and the SSR checks never saw the fall");
}

#[test]
fn a_missing_rail_or_supply_reading_is_no_reading_not_the_last_one() {
    // The switch opens below the floor with nothing asked (the test above). A board whose
    // switched-rail readings go missing there (a VREFINT conversion reading 0: `None`) must not
    // have the rail it read with the switch closed judged as the rail with it open.
    let floor = CarrierConfig::DEFAULT.supervisor.freeze.idle_open_c;
    let run = |rail_when_open: Option<f32>, supply_after: fn(u32) -> Option<f32>| {
        let mut c = pi_carrier();
        let (mut events, mut open) = (Vec::new(), 0);
        for k in 0..60u32 {
            let open_phase = k >= 30;
            let temp = if open_phase { floor - 0.1 } else { floor + 0.05 };
            let supply_v = if open_phase { supply_after(k - 30) } else { Some(12.0) };
            let switched_v = if open_phase { rail_when_open } else { Some(12.0) };
            c.observe(&BoardReadings { supply_v, switched_v, ..BoardReadings::default() });
            let o =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(temp) + k % 3, setpoint_c: 4.0 });
            assert_eq!(o.mode, Mode::Normal, "sample {k}");
            open += u32::from(!o.supply_enable);
            events.extend(kinds(&o));
        }
        // Open for most of the cold half: long enough for the check to judge the rail.
        assert!(open >= 20, "{open} samples open");
        events
    };
    // The check works here: a rail read powered with the switch open is a short…
    let good: fn(u32) -> Option<f32> = |_| Some(12.0);
    assert_eq!(run(Some(12.0), good), [EventKind::SupplySwitchShorted]);
    // …and one read dead is none.
    assert_eq!(run(Some(0.0), good), []);
    // No reading is no judgement: the rail read before the switch opened is not judged.
    assert_eq!(run(None, good), []);
    // A supply sag is three readings below the minimum; one low reading and then none is not
    // one (every later sample judged that one reading again)…
    assert_eq!(run(Some(0.0), |k| if k == 0 { Some(10.0) } else { None }), []);
    // …three are, missing readings between them or not.
    assert_eq!(run(Some(0.0), |k| if k % 2 == 0 && k < 6 { Some(10.0) } else { None }), [EventKind::SupplySag]);
}
