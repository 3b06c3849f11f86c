//! Injected hardware faults (`hter sim --fault KIND@T_S`): each is detected, nothing is detected
//! before it, and the load never reaches 0 °C.

use hal_sim::fault::Fault;
use hal_sim::metrics::Detected;
use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{
    run, run_with, BoardOptions, ControllerChoice, ControllerSpec, PlantChoice, RowMode, SamplePhase, SimOptions,
    SimOutput,
};
use hter::alarm::Indication;
use hter::event::EventKind;
use hter::persist::ResetCause;
use hter::step::Mode;

const AT_S: f64 = 3600.0;

/// Both carriers, full and half loaded.
const PLANTS: [(PlantChoice, Load); 4] = [
    (PlantChoice::Hter1, Load::Full),
    (PlantChoice::Hter1, Load::Half),
    (PlantChoice::Hter2, Load::Full),
    (PlantChoice::Hter2, Load::Half),
];

/// `c` on `plant` with `load` at `ambient_c` through `sc` for `duration_s` with `faults`, seed 5;
/// GPC with the module-side sense on the board too (the modules' own Seebeck voltage in the
/// conversion window is no short), the other laws without.
fn on_the_plants_board(
    c: ControllerChoice,
    plant: PlantChoice,
    load: Load,
    ambient_c: f64,
    sc: Scenario,
    duration_s: f64,
    faults: Vec<(f64, Fault)>,
) -> SimOutput {
    // Every one of these runs exists: a failed run is a failure, not a case to skip.
    let case = format!("{c:?} {} {plant:?} {load:?} {ambient_c} °C", sc.name);
    run(&SimOptions {
        drive: Default::default(),
        duration_s,
        scenario: sc,
        controller: ControllerSpec::new(c),
        plant,
        load,
        ambient_c,
        seed: 5,
        faults,
        module_sense: c == ControllerChoice::Gpc,
    })
    .unwrap_or_else(|e| panic!("{case}: {e}"))
}

fn with_fault(kind: Fault, controller: ControllerChoice) -> SimOutput {
    let scenario = Scenario::resolve("disturbance").unwrap();
    run(&SimOptions {
        drive: Default::default(),
        duration_s: scenario.duration_s,
        scenario,
        controller: ControllerSpec::new(controller),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 11,
        faults: vec![(AT_S, kind)],
        module_sense: false,
    })
    .unwrap()
}

/// Asserts the fault's most specific detection (the first of its table row) is reported
/// within `within_s` of the injection, and nothing before it.
fn check(kind: Fault, within_s: f64) {
    check_with(kind, within_s, &[ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Onoff]);
}

fn check_with(kind: Fault, within_s: f64, controllers: &[ControllerChoice]) {
    let detected = kind.spec().detected_by[0];
    for &c in controllers {
        let out = with_fault(kind, c);
        let m = &out.metrics;
        assert!(m.faults_detected.iter().all(|f| f.t_s >= AT_S), "{kind:?}/{c:?}: detection before the fault: {m:?}");
        let first = m.faults_detected.iter().find(|f| f.kind == detected);
        let first =
            first.unwrap_or_else(|| panic!("{kind:?}/{c:?}: {detected} never reported: {:?}", m.faults_detected));
        assert!(first.t_s - AT_S <= within_s, "{kind:?}/{c:?}: detected after {} s", first.t_s - AT_S);
        assert!(m.tracking.min_temp_c > 0.0, "{kind:?}/{c:?}: load reached {} °C", m.tracking.min_temp_c);
        // The board's alarm indicator (`hter::alarm`): off until the fault, on by its detection
        // at the latest, and, nobody pressing the button, on from then to the end.
        let on = m.alarm_indicator_first_s.unwrap_or_else(|| panic!("{kind:?}/{c:?}: the indicator never came on"));
        assert!(on >= AT_S && on <= first.t_s, "{kind:?}/{c:?}: indicator on at {on} s, detection at {} s", first.t_s);
        let last = out.rows.last().map_or(0.0, |r| r.t_s);
        assert!(
            out.rows.iter().filter(|r| r.t_s >= first.t_s).all(|r| r.alarm != Indication::Off),
            "{kind:?}/{c:?}: indicator went off"
        );
        assert!(m.alarm_indicator_s >= last - first.t_s, "{kind:?}/{c:?}: {} s on", m.alarm_indicator_s);
        // The MCU kept stepping: the board's own alarm hardware never sounded.
        assert!(m.alarm_hw_first_s.is_none() && out.rows.iter().all(|r| !r.alarm_hw), "{kind:?}/{c:?}: alarm hardware");
    }
}

#[test]
fn open_and_short_sensors_are_detected_within_two_samples() {
    check(Fault::SensorOpen, 20.0);
    check(Fault::SensorShort, 20.0);
}

#[test]
fn a_stuck_converter_is_detected() {
    check(Fault::SensorStuck, 1800.0);
}

#[test]
fn spikes_are_detected_and_filtered_out() {
    check(Fault::SensorSpikes, 1800.0);
    // Filtered: control goes on, the load stays on target.
    let m = with_fault(Fault::SensorSpikes, ControllerChoice::Pi).metrics;
    assert!(m.tracking.min_temp_c > 3.5 && m.tracking.max_temp_c < 6.0, "{m:?}");
}

#[test]
fn a_shorted_ssr_is_detected_and_the_supply_switch_opened() {
    check(Fault::SsrStuckOn, 1800.0);
}

/// After a shorted SSR the step limps home: the supply-enable switch does the On-Off control,
/// and the load stays in 2–8 °C instead of warming to the ambient (it did, with the supply
/// latched off, before limp-home).
#[test]
fn a_shorted_ssr_limps_home_within_2_to_8() {
    for plant in [PlantChoice::Hter1, PlantChoice::Hter2] {
        for c in [ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Onoff] {
            let scenario = Scenario::resolve("disturbance").unwrap();
            let out = run(&SimOptions {
                drive: Default::default(),
                duration_s: scenario.duration_s,
                scenario,
                controller: ControllerSpec::new(c),
                plant,
                load: Load::Full,
                ambient_c: 28.0,
                seed: 11,
                faults: vec![(AT_S, Fault::SsrStuckOn)],
                module_sense: false,
            })
            .unwrap();
            let at = out
                .metrics
                .faults_detected
                .iter()
                .find(|f| f.kind == Detected::Event(EventKind::SsrStuckOn))
                .expect("detected")
                .t_s;
            let after: Vec<_> = out.rows.iter().filter(|r| r.t_s > at + 1800.0).collect();
            assert!(after.len() > 100, "{plant:?} {c:?}: too little left after {at} s");
            assert!(after.iter().all(|r| r.mode == RowMode::Step(Mode::LimpHome)), "{plant:?} {c:?}");
            let (lo, hi) =
                after.iter().fold((f64::MAX, f64::MIN), |(lo, hi), r| (lo.min(r.true_temp_c), hi.max(r.true_temp_c)));
            // The thermostat on the freeze guard's look-ahead (`LimpConfig`): on the reading
            // alone the supply stayed on the RTD's lag too long and the lows were 2.9–3.1 °C.
            assert!(lo > 3.5 && hi < 8.0, "{plant:?} {c:?}: {lo:.2}…{hi:.2} °C in limp-home");
            // Really switched: full cooling and none, both.
            assert!(after.iter().any(|r| r.duty == 0.0) && after.iter().any(|r| r.duty > 0.99), "{plant:?} {c:?}");
        }
    }
}

/// A +1.5 °C step of the reading is caught in three samples, measured and subtracted: the load
/// stays on target instead of being cooled 1.5 °C too far (without the offset check the load
/// reaches 2.4 °C with PI and 1.6 °C with On-Off).
#[test]
fn a_sensor_offset_is_detected_and_compensated() {
    check(Fault::SensorOffset, 40.0);
    for c in [ControllerChoice::Pi, ControllerChoice::Onoff] {
        let m = with_fault(Fault::SensorOffset, c).metrics;
        assert!(m.tracking.min_temp_c > 2.5, "{c:?}: {m:?}");
    }
}

/// The measured module supply falling from 12 to 9 V is reported within three samples.
#[test]
fn a_supply_sag_is_detected() {
    check(Fault::SupplySag, 40.0);
}

/// A 15 W heat load (the lid left open) is reported within half an hour by the controllers that
/// hold the load on target. On-Off is not in the list: its own ±0.3 °C limit cycle hides the
/// change of duty this check looks for (a known gap).
#[test]
fn an_open_lid_is_detected() {
    check_with(
        Fault::LidOpen,
        1800.0,
        &[ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Igmvc, ControllerChoice::Gmvc],
    );
}

#[test]
fn an_open_ssr_is_detected() {
    check(Fault::SsrStuckOff, 1800.0);
}

/// An SSR (or the modules) dead before the pull-down: the load stays at the ambient, at full
/// duty, neither warming (the SSR checks' warming tests) nor falling. Found once full duty has
/// held a load above every healthy carrier's full-cooling floor for 10 min without taking 0.5 °C
/// off it (`StuckOffConfig::stalled_on_s`); before, nothing until the 10 h heat alarm, with the
/// status `normal` and no event in the record. The module-side sense cannot see it (it reads the
/// modules only in the window where the SSR is commanded off).
#[test]
fn an_ssr_dead_before_the_pull_down_is_detected_within_eleven_minutes() {
    for c in [ControllerChoice::Gpc, ControllerChoice::Pi, ControllerChoice::Onoff] {
        for (plant, load) in PLANTS {
            for ambient_c in [20.0, 28.0, 43.0] {
                let sc = Scenario::resolve("step").unwrap();
                let out = on_the_plants_board(c, plant, load, ambient_c, sc, 7200.0, vec![(0.0, Fault::SsrStuckOff)]);
                let m = &out.metrics;
                let case = format!("{c:?} {plant:?} {load:?} {ambient_c} °C");
                let found = m.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SsrStuckOff));
                let found = found.unwrap_or_else(|| panic!("{case}: never reported: {:?}", m.faults_detected));
                assert!(found.t_s <= 660.0, "{case}: found at {} s", found.t_s);
                assert!(
                    out.rows.iter().all(|r| r.mode == RowMode::Step(Mode::Normal)),
                    "{case}: mode normal throughout"
                );
            }
        }
    }
}

/// Missions that `hter campaign` once failed, each for a reason since fixed in the step:
/// 230 and 588 (a heavy carrier's slow coast after pull-down taken for a shorted SSR), 11338 (a
/// light carrier's coast, seen through the sensor lag, tripping the freeze guard's shorted-SSR
/// check), 11047 and 11205 (three spikes in a row taken for a sensor offset), 10805 (a lid
/// opening hidden by the pull-down still in the duty averages), 257 and 925 (a dead SSR on a
/// cool day), 28631 (a very light carrier on a shorted SSR cooled to −0.03 °C between two
/// freeze-guard trips), 27640 (a shorted SSR holding the load at its 1.5 °C floor on a hot day,
/// found by the supply probe), 22550 and 26642 (a lid opening during a probe taken for a
/// shorted SSR), 3101 and 8885 (a heavy H-TER II water load weakly coupled to its wall coasting
/// after the pull-down, read as a shorted SSR by one-minute windows: path 3 now compares two
/// minutes), 20465 (a lid opened 49 s into a supply probe warmed a light load 0.157 °C in 30 s,
/// read as a shorted SSR: a turn-up is now a short only when a second probe turns up too) and
/// 26762 (three spikes in a row within 0.6 °C of each other, read as a 45 °C sensor offset: a
/// step too large to compensate now holds six samples, as a spike run does to be a jump), 5639,
/// 20602, 22766 and 45876 (a pull-down from a cool ambient, 7–12 °C, on a heavy stainless wall
/// weakly coupled to its water: GPC cut the duty at 4.1–4.5 °C on the start model and the cold
/// stored in the wall carried the load on to 1.5–1.9 °C, 410–1050 s below 2 °C; the self-tuner's
/// first approach now aims above the setpoint by the rate of fall, and they bottom out at
/// 2.65–3.35 °C), 41783 (a light load a 1.6 °C ambient held at 1.7 °C, its supply switch closed
/// with nothing asked, frozen to −0.09 °C by an SSR short in the 50 s the freeze guard needed:
/// below the 2 °C floor with nothing asked and the load still, the switch now opens too),
/// 47432 (the first form of that rule opened on a heavy load a short was taking down at
/// −0.12 °C/min and hid the short for the rest of the day: the load must stand still) and 42451
/// (a short behind a supply switch the freeze guard held open to the end of the mission
/// conducted nothing, and is no longer counted as a fault that showed), 42110 (a lid left open on
/// a carrier at full duty for hours at 42 °C: the `ssr_stuck_off` warning of an earlier opening
/// covered the whole run of full duty; it is now armed again once the load stops warming) and
/// 49578 (a +1.5 °C offset that began on the sample after a spike became the reference unseen:
/// the first good reading after a spike is now checked for a step against the reference carried
/// on by the load's trend), 9515, 24204, 70549, 72870 and 110774 (the README's campaign section)
/// and 117730 (a shorted SSR on a heavy carrier that turned up by 0.12–0.15 °C in 30 s, under
/// the 0.15 °C verdict the supply probe then had). All must now pass.
#[test]
fn campaign_missions_that_once_failed_pass() {
    use hal_sim::mission::{evaluate, Mission};
    for seed in [
        230, 588, 11338, 11047, 11205, 10805, 257, 925, 28631, 27640, 22550, 26642, 3101, 8885, 20465, 26762, 5639,
        20602, 22766, 45876, 41783, 47432, 42451, 42110, 49578, 9515, 24204, 70549, 72870, 110774, 117730,
    ] {
        let m = Mission::generate(seed);
        let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
        let r = evaluate(&m, &out);
        assert!(r.reasons.is_empty(), "mission {seed}: {:?}", r.reasons);
        assert!(
            r.spurious.iter().all(|(k, _)| {
                ![Detected::Event(EventKind::SsrStuckOn), Detected::Event(EventKind::SensorOffset)].contains(k)
            }),
            "{seed}: {:?}",
            r.spurious
        );
    }
}

/// Mission 42047 (`--seed 40001`): an NMI stop while holding 4 °C, and the first reading of the
/// boot after it a sensor spike, 54 °C over a load at 4.01 °C. The two readings after it outvote
/// it, but the self-tuner had taken the spike in: its next update took b to −0.74 (the stored
/// model's b0 is −0.0075), and the law, trusting that estimate, swung the load between 2.1 and
/// 5.7 °C for two hours. The outvote's sample now runs without the controller, as a sensor
/// fault's do, and the estimator waits out the gap: the estimate stays the stored model's. With
/// that alone the hour after the restart held 3.09–4.13 °C: the law's y history still held the
/// spike, and its first requests after the outvote cooled at full duty. A skipped sample now
/// also forgets the law's measured past (`LawState::reprime`): 3.97–4.28 °C.
#[test]
fn a_spike_on_a_restarts_first_reading_does_not_corrupt_the_estimate() {
    use hal_sim::mission::Mission;
    let m = Mission::generate(42047);
    let (tf, kind) = m.hardware_fault.unwrap();
    assert_eq!(kind, Fault::BoardFault(hter::failsafe::StopKind::Nmi));
    let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
    let hour: Vec<_> = out.rows.iter().filter(|r| r.t_s >= tf && r.t_s < tf + 3600.0).collect();
    let boot = hour.first().unwrap();
    assert!(boot.temp_c > 50.0, "the boot's first reading is the spike: {} °C", boot.temp_c);
    let (lo, hi) = hour.iter().fold((f64::MAX, f64::MIN), |(lo, hi), r| (lo.min(r.true_temp_c), hi.max(r.true_temp_c)));
    assert!(lo > 3.8 && hi < 4.4, "the hour after the restart: {lo:.2}–{hi:.2} °C");
    let b0: Vec<f32> = hour.iter().filter_map(|r| r.b0).collect();
    assert!(b0.iter().all(|b| (-0.01..-0.005).contains(b)), "b0 left the stored model's: {b0:?}");
}

/// Mission 117730 (`--seed 110001`): after the supply probe found the short, limp home's
/// thermostat opened and closed the supply all day, and after every off period the heavy load
/// warmed on at full cooling for 6 min; each was reported as an SSR stuck off too (11 reports,
/// a technician sent to the wrong part). Full duty after the supply was open is now tested only
/// after twice the stuck-off window (`SsrMonitor::warms_at_full_duty`).
#[test]
fn a_short_is_not_also_reported_as_an_open_ssr() {
    use hal_sim::mission::{evaluate, Mission};
    let m = Mission::generate(117730);
    let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
    let r = evaluate(&m, &out);
    assert!(matches!(r.fault, Some((Fault::SsrStuckOn, _, Some(_)))), "{:?}", r.fault);
    assert!(r.misreported.iter().all(|(k, _)| *k != Detected::Event(EventKind::SsrStuckOff)), "{:?}", r.misreported);
}

/// Mission 6391 (`--seed 1`): a light carrier whose SSR shorts at 17 h. Limp home's thermostat
/// read the RTD, which shows the water ≈ 50 s late; at full cooling this load falls 0.4 °C in
/// 10 s, so each cycle ran on until the water was 1.2–1.6 °C (0.8 °C once) before the supply
/// opened. On the freeze guard's look-ahead (`LimpConfig`) the cycles' lows are 1.8–2.3 °C.
#[test]
fn a_light_carrier_limps_home_without_cooling_its_load_to_near_freezing() {
    use hal_sim::mission::Mission;
    let out = run(&Mission::generate(6391).options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
    let from = out.rows.iter().position(|r| r.mode == RowMode::Step(Mode::LimpHome)).expect("limp home");
    let limp = &out.rows[from..];
    assert!(limp.len() > 1000, "{} samples of limp home", limp.len());
    // It cycles: the supply switched on (full duty in limp home) time and again…
    let on = |r: &&hal_sim::sim::Row| r.mode == RowMode::Step(Mode::LimpHome) && r.duty > 0.99;
    let cycles = limp.windows(2).filter(|w| !on(&&w[0]) && on(&&w[1])).count();
    assert!(cycles > 20, "{cycles} cycles");
    // …and the water's lowest from the first limp-home sample on (the fall before the short was
    // found, to 1.14 °C, is not limp home's).
    let lowest = limp.iter().map(|r| r.true_temp_c).fold(f64::MAX, f64::min);
    assert!(lowest > 1.7, "lowest in limp home {lowest:.2} °C");
}

/// A board that reads the modules' voltage in the conversion window (`--module-sense`,
/// `hter::supervisor::module`) finds a shorted SSR within two samples, before the load has
/// moved: campaign missions 10799, 28631, 700212 and 202055 (light H-TER I carriers; the
/// reference board finds the short from the load's fall, 70–300 s later, and their loads reach
/// 0.86, 0.58, 1.25 and 0.20 °C) stay above 1.4 °C, 9515 above 2.3 °C. What is left below 2 °C
/// is limp home's On-Off on these very light loads, not the short's detection.
#[test]
fn a_module_side_sense_finds_a_shorted_ssr_within_two_samples() {
    use hal_sim::mission::Mission;
    for (seed, floor_c) in [(10799, 1.75), (28631, 1.75), (700212, 2.8), (9515, 2.3), (202055, 1.4)] {
        let m = Mission::generate(seed);
        let opts = m.options(ControllerSpec::new(ControllerChoice::Gpc));
        let (at, _) = opts.faults.iter().copied().find(|f| f.1 == Fault::SsrStuckOn).expect("a shorted SSR");
        let found = |o: &SimOutput| {
            o.metrics.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SsrStuckOn)).map(|f| f.t_s)
        };
        let plain = run(&opts).unwrap();
        let sensed = run(&SimOptions { module_sense: true, ..opts }).unwrap();
        let (t_plain, t_sensed) = (found(&plain).expect("found"), found(&sensed).expect("found"));
        // The first sample at or after the fault sees it, the next confirms it.
        assert!(t_sensed - at <= 20.0 + 1e-9, "mission {seed}: found {} s after the short", t_sensed - at);
        assert!(t_sensed < t_plain, "mission {seed}: {t_sensed} s with the sense, {t_plain} s without");
        let (lo_plain, lo_sensed) = (plain.metrics.tracking.min_temp_c, sensed.metrics.tracking.min_temp_c);
        assert!(
            lo_sensed > floor_c && lo_sensed > lo_plain,
            "mission {seed}: lowest {lo_sensed:.2} °C ({lo_plain:.2} without)"
        );
    }
}

/// Missions 281, 623 and 950 (`--seed 1`): a carrier at full duty for hours in a 42 °C heat,
/// its load more than 1 °C above the setpoint. The lid detector's "overwhelmed" report re-armed
/// on its duty averages, which at full duty do not part, and came every other sample: 68, 63 and
/// 131 `lid_open` reports. It now re-arms once the load is held again.
#[test]
fn an_overwhelmed_carrier_is_reported_once_not_every_other_sample() {
    use hal_sim::mission::Mission;
    for seed in [281, 623, 950] {
        let out = run(&Mission::generate(seed).options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
        let lids = out.metrics.faults_detected.iter().filter(|d| d.kind == Detected::Event(EventKind::LidOpen)).count();
        assert!((1..=2).contains(&lids), "mission {seed}: {lids} lid_open reports");
    }
}

/// No detector fires on healthy hardware across the baseline scenarios, controllers and plants.
#[test]
fn no_false_detections_without_faults() {
    for c in [ControllerChoice::Onoff, ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Igmvc] {
        for scenario in ["step", "piecewise", "disturbance"] {
            for (plant, load) in PLANTS {
                for ambient_c in [20.0, 28.0, 35.0] {
                    let sc = Scenario::resolve(scenario).unwrap();
                    let duration_s = sc.duration_s;
                    let out = on_the_plants_board(c, plant, load, ambient_c, sc, duration_s, vec![]);
                    assert!(
                        out.metrics.faults_detected.is_empty(),
                        "{c:?} {scenario} {plant:?} {load:?} {ambient_c} (module sense {}): {:?}",
                        c == ControllerChoice::Gpc,
                        out.metrics.faults_detected
                    );
                    assert_eq!(out.metrics.alarm_hw_first_s, None, "{c:?} {scenario} {plant:?} {load:?} {ambient_c}");
                }
            }
        }
    }
}

#[test]
fn fault_strings_are_checked() {
    assert!(Fault::parse("sensor-open@10").is_ok());
    assert!(Fault::parse("sensor-opn@10").unwrap_err().to_string().contains("unknown fault"));
    assert!(Fault::parse("sensor-open").is_err());
    assert!(Fault::parse("sensor-open@-1").is_err());
    assert!(Fault::parse("sensor-open@nan").is_err());
}

/// A brownout restarts the step from scratch: nothing freezes, the restart is reported (the reset flags) and nothing else, and
/// control resumes on the setpoint (with nothing persisted yet: the restart is 1 h in).
#[test]
fn a_brownout_restart_is_safe_and_control_resumes() {
    for c in [ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Onoff] {
        let out = with_fault(Fault::Brownout, c);
        let m = &out.metrics;
        // Reported with the first sample after the restart (the reset flags), and nothing else.
        let kinds: Vec<_> = m.faults_detected.iter().map(|f| (f.kind, f.t_s)).collect();
        assert_eq!(kinds, [(Detected::Event(EventKind::Restarted(ResetCause::BrownOut)), AT_S)], "{c:?}");
        assert!(m.tracking.min_temp_c > 2.0 && m.tracking.max_temp_c < 8.0, "{c:?}: {m:?}");
        let after: Vec<_> = out.rows.iter().filter(|r| r.t_s > AT_S + 1800.0).collect();
        assert!(after.iter().any(|r| r.duty > 0.0), "{c:?}: no cooling after the restart");
        assert!(after.iter().all(|r| (r.true_temp_c - 4.0).abs() < 1.5), "{c:?}: not back on the setpoint");
    }
}

/// After a brownout the self-tuner restarts from the model it had persisted (every 4 h of
/// trusted learning, as the firmware saves it), not from its built-in start model. Started here
/// from a model of H-TER II on an H-TER I carrier, it has learnt a different B by the time the
/// power dips at 5.5 h; the restart picks up the one it stored. (The first store comes 4 h
/// after the estimate is first trusted for good, about 1 h in: at 5 h it was 30 samples short
/// once the first approach's lead made the pull-down land more slowly, issue 19.)
#[test]
fn a_brownout_restarts_from_the_persisted_model() {
    let scenario = Scenario::resolve("step").unwrap();
    let mut spec = ControllerSpec::new(ControllerChoice::Gpc);
    let other = hter::profile::START_MODEL_HTER2;
    spec.initial = Some(other);
    let mut opts = SimOptions::new(scenario, spec);
    opts.duration_s = 6.5 * 3600.0;
    opts.faults = vec![Fault::parse("brownout@19800").unwrap()];
    let out = run(&opts).unwrap();
    let b0 = |t: f64| out.rows.iter().find(|r| r.t_s >= t).and_then(|r| r.b0).unwrap();
    // The last model the board stored before the power dipped.
    let persisted = out
        .stores
        .iter()
        .rev()
        .find_map(|(t, s)| match s {
            hter::persist::Save::Model(r) if *t < 19800.0 => Some(*r),
            _ => None,
        })
        .expect("a model stored before the brownout");
    let start = other.b()[0];
    assert!(
        (persisted.theta[2] - start).abs() > 0.002,
        "the stored estimate should have moved: {start} → {persisted:?}"
    );
    // The first sample after the restart is designed on the stored model, not the start model.
    assert_eq!(b0(19800.0), persisted.theta[2], "restart b0, stored {persisted:?}, start {start}");
    assert!(out.metrics.tracking.min_temp_c > 2.0, "{:?}", out.metrics);
}

/// A shorted supply-enable switch is invisible to the supply divider (upstream of it): the
/// switched-rail sense finds it the next time the switch is commanded open — at the latest at
/// the two-hourly test pulse (50 ms open, the rail judged on the next sample) — and the alarm
/// latches on it.
#[test]
fn a_shorted_supply_switch_is_detected_within_two_hours() {
    check(Fault::SupplySwitchShort, 2.0 * 3600.0 + 60.0);
    // Injected anywhere between two test pulses: found within two hours (and a minute of
    // margin), every controller, both carriers.
    let mut worst: f64 = 0.0;
    for c in [ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Onoff] {
        for plant in [PlantChoice::Hter1, PlantChoice::Hter2] {
            for at_s in [3700.0, 6000.0, 9000.0] {
                let scenario = Scenario::resolve("disturbance").unwrap();
                let mut opts = SimOptions::new(scenario, ControllerSpec::new(c));
                opts.duration_s = 6.0 * 3600.0;
                opts.plant = plant;
                opts.faults = vec![(at_s, Fault::SupplySwitchShort)];
                let m = run(&opts).unwrap().metrics;
                let t = m
                    .faults_detected
                    .iter()
                    .find(|f| f.kind == Detected::Event(EventKind::SupplySwitchShorted))
                    .map(|f| f.t_s);
                assert!(
                    t.is_some_and(|t| t >= at_s && t <= at_s + 2.0 * 3600.0 + 60.0),
                    "{c:?} {plant:?} {at_s}: {:?}",
                    m.faults_detected
                );
                worst = worst.max(t.unwrap_or(0.0) - at_s);
                // Reported once; control goes on through the SSR.
                assert_eq!(m.faults_detected.len(), 1, "{c:?} {plant:?} {at_s}: {:?}", m.faults_detected);
                assert!(m.tracking.min_temp_c > 2.5 && m.tracking.max_temp_c < 6.0, "{c:?} {plant:?} {at_s}: {m:?}");
            }
        }
    }
    eprintln!("supply-switch-short: worst detection latency {worst} s");
}

/// The step stops being called (the control loop hung) while self-tuning GPC holds 4 °C with
/// the SSR modulating: the SSR timer keeps its last duty, and only the board's heartbeat
/// monostable (15 s) opens the supply switch and sounds the alarm hardware, within 2 Ts.
#[test]
fn a_firmware_hang_opens_the_supply_and_sounds_the_alarm_hardware() {
    const TS: f64 = 10.0;
    // Not at 3600 s, where the switch test pulse is due.
    const AT_S: f64 = 5000.0;
    let mut opts =
        SimOptions::new(Scenario::resolve("disturbance").unwrap(), ControllerSpec::new(ControllerChoice::Gpc));
    opts.seed = 11;
    opts.faults = vec![(AT_S, Fault::FirmwareHang)];
    let out = run(&opts).unwrap();
    let m = &out.metrics;
    let before = out.rows.iter().rev().find(|r| r.t_s < AT_S).unwrap();
    assert!(before.duty > 0.05 && before.duty < 1.0, "cooling when it hangs: {}", before.duty);
    let at = m.alarm_hw_first_s.expect("the alarm hardware never sounded");
    eprintln!("firmware-hang@{AT_S}: alarm hardware and supply open at {at} s (last beat {} s)", before.t_s);
    assert!(at > AT_S && at <= AT_S + 2.0 * TS, "alarm hardware at {at} s");
    let kinds: Vec<_> = m.faults_detected.iter().map(|f| (f.kind, f.t_s)).collect();
    assert_eq!(kinds, [(Detected::FirmwareHang, at)]);
    // Before the expiry the hung timer still cooled; from the first sample after it, nothing.
    let after: Vec<_> = out.rows.iter().filter(|r| r.t_s >= AT_S + 2.0 * TS).collect();
    assert!(after.len() > 500);
    assert!(after.iter().all(|r| r.duty == 0.0 && r.alarm_hw && r.mode == RowMode::Hung));
    assert!(out.rows.iter().filter(|r| r.t_s < AT_S).all(|r| !r.alarm_hw));
    // No freeze: the load only warms from there.
    let t_hang = before.true_temp_c;
    let min_after = after.iter().map(|r| r.true_temp_c).fold(f64::MAX, f64::min);
    let last = after.last().unwrap().true_temp_c;
    assert!(min_after > t_hang - 0.2 && last > t_hang + 3.0, "{t_hang} → min {min_after}, end {last}");
    // A brownout restarts the MCU: the hang ends and the step cools again.
    let scenario = Scenario::resolve("disturbance").unwrap();
    let mut opts = SimOptions::new(scenario, ControllerSpec::new(ControllerChoice::Gpc));
    opts.faults = vec![Fault::parse("firmware-hang@3600").unwrap(), Fault::parse("brownout@5400").unwrap()];
    let out = run(&opts).unwrap();
    assert!(out.rows.iter().filter(|r| r.t_s >= 5400.0).all(|r| r.mode != RowMode::Hung));
    assert!(out.rows.iter().any(|r| r.t_s > 5400.0 && r.duty > 0.0));
}

/// The board's own fail-safe stops (`hter sim --fault board-fault-KIND@T`): the stop path, a
/// reset and a boot that restarts the step from flash. The stop is reported with the boot's first
/// sample, and only it; the indicator is latched from then to the end (nobody acknowledges); the
/// boot's history counts the stop and is stored at once (an alarm history: a stop behind the
/// write gate's minute never reached the record on a board that stopped in every minute); and
/// control resumes on the setpoint with the load within 2–8 °C. A control stall misses a sample
/// first (the glue's stall check stops the loop two sample periods after its last completed
/// step), and the heartbeat's monostable sounds the alarm hardware on the way; the other stops
/// reset before it can lapse.
#[test]
fn a_board_fault_is_reported_latched_and_stored_and_control_resumes() {
    use hter::failsafe::StopKind;
    use hter::persist::Save;
    for kind in StopKind::ALL {
        let stall = kind == StopKind::ControlStall;
        // The boot that reports it: at once, or when the stall check stops the hung loop.
        let boot_s = AT_S + if stall { 10.0 } else { 0.0 };
        for c in [ControllerChoice::Pi, ControllerChoice::Gpc, ControllerChoice::Onoff] {
            let out = with_fault(Fault::BoardFault(kind), c);
            let m = &out.metrics;
            let case = format!("{kind:?}/{c:?}");
            let reports: Vec<_> = m
                .faults_detected
                .iter()
                .filter(|f| f.kind != Detected::FirmwareHang)
                .map(|f| (f.kind, f.t_s))
                .collect();
            assert_eq!(reports, [(Detected::Event(EventKind::BoardFault(kind)), boot_s)], "{case}");
            match m.alarm_hw_first_s {
                Some(hw) => assert!(stall && hw > AT_S - 10.0 && hw < boot_s, "{case}: alarm hardware at {hw} s"),
                None => assert!(!stall, "{case}: a 20 s stall outlasts the 15 s monostable"),
            }
            let hung: Vec<_> = out.rows.iter().filter(|r| r.mode == RowMode::Hung).map(|r| r.t_s).collect();
            assert_eq!(hung, if stall { vec![AT_S] } else { vec![] }, "{case}");
            assert_eq!(m.alarm_indicator_first_s, Some(boot_s), "{case}");
            assert!(out.rows.iter().filter(|r| r.t_s >= boot_s).all(|r| r.alarm != Indication::Off), "{case}");
            let stored = out.stores.iter().find_map(|(t, s)| match s {
                Save::AlarmHistory(h) if *t == boot_s => Some(*h),
                _ => None,
            });
            let stored = stored.unwrap_or_else(|| panic!("{case}: no alarm history stored at the boot"));
            assert_eq!(stored.stops_of(kind), 1, "{case}");
            assert!(m.tracking.min_temp_c > 2.0 && m.tracking.max_temp_c < 8.0, "{case}: {m:?}");
            let after: Vec<_> = out.rows.iter().filter(|r| r.t_s > boot_s + 1800.0).collect();
            assert!(after.iter().any(|r| r.duty > 0.0), "{case}: no cooling after the restart");
            assert!(after.iter().all(|r| (r.true_temp_c - 4.0).abs() < 1.5), "{case}: not back on the setpoint");
        }
    }
    // A brown-out is no stop: it latches nothing (`restarted_brownout` is a record, not an alarm).
    let out = with_fault(Fault::Brownout, ControllerChoice::Gpc);
    assert_eq!(out.metrics.alarm_indicator_first_s, None);
}

/// The SSR's switching disturbance on the ADC: a conversion that starts on the SSR's falling
/// edge is biased; one at the board's fixed phase, with the duty cleared of the window, is
/// not (within the front end's 1.5 counts of noise). Counts against the simulator's ideal
/// conversion over a pull-down and hold (hundreds of modulated samples).
#[test]
fn edge_aligned_samples_are_biased_and_synchronised_ones_are_not() {
    for c in [ControllerChoice::Pi, ControllerChoice::Gpc] {
        let errors = |phase: SamplePhase| -> (f64, f64, usize) {
            let opts = SimOptions::new(Scenario::resolve("step").unwrap(), ControllerSpec::new(c));
            let out = run_with(&opts, &BoardOptions { sample_phase: phase }).unwrap();
            // Samples whose preceding SSR period switched (the duty applied before them in (0, 1)).
            let e: Vec<f64> = out
                .rows
                .windows(2)
                .filter(|w| w[0].duty > 0.0 && w[0].duty < 1.0)
                .map(|w| f64::from(w[1].counts) - w[1].ideal_counts)
                .collect();
            let n = e.len() as f64;
            let mean = e.iter().sum::<f64>() / n;
            let rms = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
            (mean, rms, e.len())
        };
        let (edge_mean, _, n_edge) = errors(SamplePhase::EdgeAligned);
        let (sync_mean, sync_rms, n_sync) = errors(SamplePhase::Synchronised);
        eprintln!(
            "{c:?}: edge-aligned mean error {edge_mean:.2} counts ({n_edge} samples); synchronised {sync_mean:.3} counts, rms {sync_rms:.2} ({n_sync} samples)"
        );
        assert!(n_edge > 300 && n_sync > 300, "{n_edge} {n_sync}");
        assert!(edge_mean > 50.0, "{c:?}: edge-aligned bias {edge_mean}");
        assert!(sync_mean.abs() < 0.3 && sync_rms < 1.8, "{c:?}: synchronised {sync_mean} (rms {sync_rms})");
    }
}

/// Missions 741, 1031, 1176 and 1533 on the buck drive (`hter campaign --missions 10000 --drive
/// buck`): a 15 W lid left open raised the buck's holding duty by 0.2–0.3, and its averages parted
/// by 0.078–0.096, under the lid check's 0.1 (27 of the campaign's 218 lids; the SSR finds all
/// 218). The buck's lid check now takes the cooling the duty pumps in the SSR's units
/// (`LidConfig::BUCK`): each lid is reported. On the SSR the same missions report theirs as
/// before.
#[test]
fn a_lid_left_open_is_found_on_the_buck_drive_too() {
    use hal_sim::mission::{evaluate, Mission};
    use hal_sim::plant::Drive;
    for seed in [741, 1031, 1176, 1533] {
        let m = Mission::generate(seed);
        assert_eq!(m.hardware_fault.map(|(_, f)| f), Some(Fault::LidOpen), "mission {seed}");
        for drive in [Drive::Buck, Drive::Ssr] {
            let out = run(&SimOptions { drive, ..m.options(ControllerSpec::new(ControllerChoice::Gpc)) }).unwrap();
            let r = evaluate(&m, &out);
            assert!(r.reasons.is_empty(), "mission {seed} on {drive:?}: {:?}", r.reasons);
        }
    }
}

/// Missions 88618 (`hter campaign --missions 10000 --seed 80001`) and 68435 (`--seed 60001
/// --drive buck`): a lid opened in a room that had been cooling for hours. The holding duty had
/// been falling, the lid check's slow average lagged 0.045 above its fast one, and the lid's
/// rise parted them by 0.096 (SSR, check 0.1) and 0.088 (buck, 0.09) at most: never reported.
/// The slow average is now held at or below the fast one: both are reported.
#[test]
fn a_lid_opened_in_a_cooling_room_is_reported() {
    use hal_sim::mission::{evaluate, Mission};
    use hal_sim::plant::Drive;
    for (seed, drive) in [(88618, Drive::Ssr), (68435, Drive::Buck)] {
        let m = Mission::generate(seed);
        assert_eq!(m.hardware_fault.map(|(_, f)| f), Some(Fault::LidOpen), "mission {seed}");
        let out = run(&SimOptions { drive, ..m.options(ControllerSpec::new(ControllerChoice::Gpc)) }).unwrap();
        let r = evaluate(&m, &out);
        assert!(r.reasons.is_empty(), "mission {seed} on {drive:?}: {:?}", r.reasons);
    }
}

/// Mission 83165 (`hter campaign --missions 10000 --seed 80001 --drive buck`): the buck's high
/// side shorted in a 29 °C room. The freeze guard's trips, the only protection, came 30.2, 46.3,
/// 30.7 and 31.8 min apart, each just past path 1's half hour, and the supply probe's turn-up
/// (0.10–0.11 °C in 30 s) stayed under its 0.12: the load was held at 1.5–3 °C by the guard for
/// the mission's last 5.7 h and nothing was reported. On the buck path 1 waits 45 min
/// (`StuckOnConfig::BUCK`): the short is found at the second trip, 67 min after it.
#[test]
fn a_shorted_buck_tripping_every_half_hour_is_found() {
    use hal_sim::mission::{evaluate, Mission};
    use hal_sim::plant::Drive;
    let m = Mission::generate(83165);
    let (at, fault) = m.hardware_fault.expect("a hardware fault");
    assert_eq!(fault, Fault::SsrStuckOn);
    let out = run(&SimOptions { drive: Drive::Buck, ..m.options(ControllerSpec::new(ControllerChoice::Gpc)) }).unwrap();
    let r = evaluate(&m, &out);
    assert!(r.reasons.is_empty(), "{:?}", r.reasons);
    let found = out.metrics.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SsrStuckOn));
    let found = found.expect("the short is reported").t_s;
    assert!(found - at < 4500.0, "found {} s after the short", found - at);
}

/// A restart builds the self-tuner as the board's boot does, from the board's boot duty
/// (`profile::BOOT_DUTY`, the fallback PI's bias: `profile::SelfTuningOrPi::new`, `App::new`), and until GPC's first staged design is complete
/// (four samples) the PI drives on the reading (`hter::control::adaptive`, "The first samples").
/// The simulator once built it from the run's start duty, which GPC then held: 0 on a mission
/// that starts from the ambient. Mission 108161 (`hter campaign --missions 10000 --seed 100001`),
/// a light carrier at full duty and 7.3 °C in a 42 °C room, had 40 s without cooling after a
/// control stall's restart and the load rose to 8.19 °C (120 s above 8 °C); held at the board's
/// 0.4 it peaked at 7.85 °C. The PI, 3.3 °C above the setpoint, cools at full duty.
#[test]
fn a_restart_starts_from_the_boards_boot_duty_and_the_pi_drives_until_the_first_design() {
    use hal_sim::mission::{evaluate, Mission};
    // Near the setpoint the boot's first duty is the PI's first output from its bias,
    // bias + (kp + kp·Ts/Ti)·(y − w), to the PWM's step of 0.001.
    let out = gpc_disturbance(&[(3000.0, Fault::Brownout)], Some(4000.0));
    let pi = hter::profile::PI;
    let [i] = boots(&out)[..] else { panic!("one restart") };
    let r = &out.rows[i];
    let ts = f64::from(hter::step::CarrierConfig::DEFAULT.ts_s);
    let gain = f64::from(pi.kp_per_c) * (1.0 + ts / f64::from(pi.ti_s));
    let expected = f64::from(hter::profile::BOOT_DUTY) + gain * (r.temp_c - r.setpoint_c);
    assert!((r.duty - expected).abs() <= 1e-3, "boot duty {} at {} °C, expected {expected}", r.duty, r.temp_c);
    // Far above it, the PI cools fully through the four samples.
    let m = Mission::generate(108161);
    let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
    let found = boots(&out);
    assert!(!found.is_empty(), "the mission restarts");
    for i in found {
        for r in &out.rows[i..i + 4] {
            assert!(
                r.duty >= 0.99,
                "{} s after the boot at {} s: duty {}",
                r.t_s - out.rows[i].t_s,
                out.rows[i].t_s,
                r.duty
            );
        }
    }
    let r = evaluate(&m, &out);
    assert!(r.reasons.is_empty(), "{:?}", r.reasons);
}

/// The boot duty is below the full load's holding duty (`profile::BOOT_DUTY`, 0.2): a light
/// carrier in a cool room holds at a few hundredths, and from the old 0.4 the PI cooled it for
/// three samples after a brown-out. Buck mission 103202 (`hter campaign --missions 10000 --seed
/// 100001 --drive buck`: H-TER I at 4 °C in a 7 °C room) fell 4.0 → 2.75 °C and tripped the
/// freeze guard; from 0.2 it stays above 3.4 °C.
#[test]
fn a_boot_does_not_cool_a_light_carrier_holding_at_a_few_hundredths() {
    use hal_sim::mission::{evaluate, Mission};
    use hal_sim::plant::Drive;
    let m = Mission::generate(103202);
    let out = run(&SimOptions { drive: Drive::Buck, ..m.options(ControllerSpec::new(ControllerChoice::Gpc)) }).unwrap();
    let [i] = boots(&out)[..] else { panic!("one restart") };
    let t0 = out.rows[i].t_s;
    let hour = out.rows[i..].iter().take_while(|r| r.t_s < t0 + 3600.0);
    let lowest = hour.map(|r| r.true_temp_c).fold(f64::INFINITY, f64::min);
    assert!(lowest >= 3.2, "the load fell to {lowest} °C in the hour after the boot at {t0} s");
    assert_eq!(out.metrics.freeze_guard_trips, 0);
    let r = evaluate(&m, &out);
    assert!(r.reasons.is_empty(), "{:?}", r.reasons);
}

/// The rows of `out` a restart's boot reports (`restarted_*`), in order.
fn boots(out: &SimOutput) -> Vec<usize> {
    let restarted = |r: &hal_sim::sim::Row| r.events.iter().any(|e| matches!(e.kind, EventKind::Restarted(_)));
    out.rows.iter().enumerate().filter(|(_, r)| restarted(r)).map(|(i, _)| i).collect()
}

/// A load at 2.1–2.4 °C in a cold room (0.9–3 °C), the supply switch open with nothing asked,
/// restarted by a brown-out or a fail-safe stop: GPC held the boot duty, 0.4, for the four
/// samples of its first design, the load fell to 1.3–1.7 °C, and the freeze guard's trip while
/// it fell fast was taken for a shorted SSR (a false `ssr_stuck_on`, stored: limp home until a
/// service reset). Missions 60267, 66503 and 68757 (`hter campaign --missions 10000 --seed
/// 60001`). The PI, on the reading, asks for no cooling.
#[test]
fn a_boot_on_a_cold_load_is_not_taken_for_a_shorted_ssr() {
    use hal_sim::mission::{evaluate, Mission};
    for seed in [60267, 66503, 68757] {
        let m = Mission::generate(seed);
        let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
        let r = evaluate(&m, &out);
        assert!(r.reasons.is_empty(), "mission {seed}: {:?}", r.reasons);
        assert!(
            r.misreported.iter().chain(&r.spurious).all(|(k, _)| *k != Detected::Event(EventKind::SsrStuckOn)),
            "mission {seed}: {:?} {:?}",
            r.misreported,
            r.spurious
        );
        let &[boot, ..] = &boots(&out)[..] else { panic!("mission {seed} restarts") };
        assert!(out.rows[boot..boot + 4].iter().all(|r| r.duty == 0.0), "mission {seed}: the boot cools");
    }
}

/// `guard_trips` counts the freeze guard's trips in the freeze margin's window only (after
/// pull-down, before the hardware fault, warm ambient): where the control alone should have
/// kept the load up. Mission 64000 (`--seed 60001`: a light carrier from a 7.6 °C ambient, no
/// hardware fault) trips it once on its first approach to 4 °C, at 380 s, and that trip is the
/// run's only one (mission 206 of `--seed 1` was, until the fallback PI drove the first four
/// samples; it no longer trips); mission 6391's shorted SSR trips it 25 times, all after the
/// short, none counted.
/// (How many limp home's On-Off cycles trip after the short moves with any change of the duty
/// history before it, 25–27 so far: the test asks for many, not for one number.)
#[test]
fn guard_trips_count_the_control_s_own_trips_not_a_fault_s() {
    use hal_sim::mission::{evaluate, Mission};
    for (seed, counted, all) in [(64000, 1, 1..=1), (6391, 0, 20..=40)] {
        let m = Mission::generate(seed);
        let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
        let r = evaluate(&m, &out);
        assert!(all.contains(&out.metrics.freeze_guard_trips), "mission {seed}: {}", out.metrics.freeze_guard_trips);
        assert_eq!(r.guard_trips, counted, "mission {seed}");
    }
}

/// Self-tuning GPC on a full H-TER I at 28 °C through the `disturbance` scenario (seed 11), with
/// `faults`, for `duration_s` (the scenario's own when `None`).
fn gpc_disturbance(faults: &[(f64, Fault)], duration_s: Option<f64>) -> SimOutput {
    let scenario = Scenario::resolve("disturbance").unwrap();
    run(&SimOptions {
        drive: Default::default(),
        duration_s: duration_s.unwrap_or(scenario.duration_s),
        scenario,
        controller: ControllerSpec::new(ControllerChoice::Gpc),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 11,
        faults: faults.to_vec(),
        module_sense: false,
    })
    .unwrap()
}

/// A restart is no acknowledgement: spikes found an hour before a brown-out keep the indicator
/// on through it (the latch restarts from the stored history); it went `off` at the restart,
/// and on again only if the sensor spiked anew (`hter sim --fault sensor-spikes@1000
/// --fault brownout@8000`: off from 8000 to 8660 s).
#[test]
fn an_unacknowledged_alarm_survives_a_brownout() {
    let out = gpc_disturbance(&[(AT_S, Fault::SensorSpikes), (AT_S + 3600.0, Fault::Brownout)], None);
    let found = out.metrics.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SensorSpikes));
    let found = found.expect("the spikes are reported").t_s;
    assert!(found < AT_S + 3600.0, "before the brown-out: {found} s");
    let after: Vec<_> = out.rows.iter().filter(|r| r.t_s >= found).collect();
    assert!(after.iter().any(|r| r.t_s >= AT_S + 3600.0), "the run goes past the brown-out");
    assert!(after.iter().all(|r| r.alarm != Indication::Off), "the indicator went off");
}

/// The sensor offset the board subtracts survives a brown-out: the restarted board subtracts it
/// from its first sample, and the load is held where the reading says. It was RAM alone: after
/// the restart the lead read 1.5 °C warm again, and the load was held 1.5 °C colder than shown
/// (`hter sim --fault sensor-offset@3000 --fault brownout@10000`: 2.45–4.04 °C true after the
/// restart, 2.50 °C for a reading of 3.98 °C at the end).
#[test]
fn a_sensor_offset_stays_compensated_through_a_brownout() {
    let brownout_s = AT_S + 3600.0;
    let out =
        gpc_disturbance(&[(AT_S, Fault::SensorOffset), (brownout_s, Fault::Brownout)], Some(brownout_s + 3.0 * 3600.0));
    let found = out.metrics.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SensorOffset));
    assert!(found.expect("the offset is reported").t_s < brownout_s);
    // From an hour after the restart, the reading is the load, and the load is on target.
    let late: Vec<_> = out.rows.iter().filter(|r| r.t_s >= brownout_s + 3600.0).collect();
    assert!(late.len() > 100, "the run goes on after the brown-out: {} samples", late.len());
    for r in &late {
        let read = r.raw_temp_c.expect("a reading");
        assert!((read - r.true_temp_c).abs() < 0.15, "t={} s: read {read:.2} °C, true {:.2} °C", r.t_s, r.true_temp_c);
        assert!(r.true_temp_c > 3.0, "t={} s: the load at {:.2} °C", r.t_s, r.true_temp_c);
    }
}

/// A shorted SSR stays known through a brown-out: the restarted board limps home from its first
/// sample. It was RAM alone: the restart handed the modules back to the controller, which cooled
/// flat out (the load warm after limp home's off period) until the checks found the short
/// again, 320 s later with the load at 1.88 °C (`hter sim --scenario disturbance --fault
/// ssr-stuck-on@3000 --fault brownout@10000`; 4.03 °C at the lowest now).
#[test]
fn a_shorted_ssr_limps_home_through_a_brownout() {
    let brownout_s = AT_S + 2.0 * 3600.0;
    let out = gpc_disturbance(&[(AT_S, Fault::SsrStuckOn), (brownout_s, Fault::Brownout)], Some(brownout_s + 3600.0));
    let found = out.metrics.faults_detected.iter().find(|f| f.kind == Detected::Event(EventKind::SsrStuckOn));
    assert!(found.expect("the short is found").t_s < brownout_s);
    let after: Vec<_> = out.rows.iter().filter(|r| r.t_s >= brownout_s).collect();
    assert!(after.len() > 300, "the run goes on after the brown-out: {} samples", after.len());
    assert!(after.iter().all(|r| r.mode == RowMode::Step(Mode::LimpHome)), "limp home from the first sample");
    let lowest = after.iter().map(|r| r.true_temp_c).fold(f64::MAX, f64::min);
    assert!(lowest > 3.5, "the load at {lowest:.2} °C after the restart");
    // One short, found once: the restart does not find it again.
    let found = out.metrics.faults_detected.iter().filter(|f| f.kind == Detected::Event(EventKind::SsrStuckOn));
    assert_eq!(found.count(), 1);
}
