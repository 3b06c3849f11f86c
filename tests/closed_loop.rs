//! Closed-loop behaviour of the library's step against the hal-sim plant.

use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions, SimOutput};
use hter::alarm::Indication;
use hter::control::AdaptiveMode;

fn sim(scenario: &str, controller: ControllerChoice, plant: PlantChoice, load: Load) -> SimOutput {
    sim_spec(scenario, ControllerSpec::new(controller), plant, load)
}

/// PI pulls the full-load H-TER I carrier from 28 °C to 4 °C without
/// going below 2 °C and then holds it within ±0.5 °C.
#[test]
fn pi_pulls_down_from_28_to_4_without_freezing_and_holds() {
    let out = sim("step", ControllerChoice::Pi, PlantChoice::Hter1, Load::Full);
    let m = &out.metrics;
    assert!(m.tracking.min_temp_c >= 2.0, "load went down to {} °C", m.tracking.min_temp_c);
    // The pull-down: the first sample within ±0.5 °C. (`settle_time_s` is the last exit from
    // ±0.2 °C, which the supervisor's two-hourly supply-switch test can move past 2 h.)
    let arrived = out.rows.iter().find(|r| (r.true_temp_c - 4.0).abs() <= 0.5).expect("never reached 4 ± 0.5 °C");
    assert!(arrived.t_s < 2.0 * 3600.0, "pull-down took {} s", arrived.t_s);
    assert!(m.tracking.settle_time_s.is_some(), "never settled within ±0.2 °C: {m:?}");
    assert!(out.rows.iter().filter(|r| r.t_s >= arrived.t_s).all(|r| (r.true_temp_c - 4.0).abs() <= 0.5), "{m:?}");
    // It really started warm.
    assert!(out.rows[0].true_temp_c > 27.0);
    // The alarm indicator shows the warm box (out of range) from the first sample and goes
    // off once the measured load is within 2–8 °C: a pull-down is no fault, nothing latches.
    assert_eq!(out.rows[0].alarm, Indication::OutOfRange);
    let inside = out.rows.iter().position(|r| (2.0..=8.0).contains(&r.temp_c)).expect("reaches 2–8 °C");
    assert!(out.rows[..inside].iter().all(|r| r.alarm == Indication::OutOfRange));
    assert!(out.rows[inside..].iter().all(|r| r.alarm == Indication::Off), "indicator on after the pull-down");
    assert!((m.alarm_indicator_s - inside as f64 * 10.0).abs() < 1e-9, "{} s", m.alarm_indicator_s);
}

#[test]
fn baselines_never_take_the_load_below_2_on_piecewise() {
    for c in [ControllerChoice::Onoff, ControllerChoice::P, ControllerChoice::Pi] {
        for (plant, load) in
            [(PlantChoice::Hter1, Load::Full), (PlantChoice::Hter1, Load::Half), (PlantChoice::Hter2, Load::Full)]
        {
            let m = sim("piecewise", c, plant, load).metrics;
            assert!(m.tracking.min_temp_c >= 2.0, "{c:?} {plant:?} {load:?}: min {}", m.tracking.min_temp_c);
            assert!(m.tracking.max_temp_c <= 8.0, "{c:?} {plant:?} {load:?}: max {}", m.tracking.max_temp_c);
            // Nothing wrong, nothing to see: the board's alarm indicator stays off.
            assert_eq!(m.alarm_indicator_first_s, None, "{c:?} {plant:?} {load:?}: indicator on");
        }
    }
}

#[test]
fn pi_has_less_steady_state_error_than_onoff() {
    // The integral action removes the offset that On-Off's hysteresis leaves.
    let pi = sim("piecewise", ControllerChoice::Pi, PlantChoice::Hter1, Load::Full).metrics;
    let onoff = sim("piecewise", ControllerChoice::Onoff, PlantChoice::Hter1, Load::Full).metrics;
    assert!(pi.tracking.steady_state_error_c < onoff.tracking.steady_state_error_c, "pi {pi:?}\nonoff {onoff:?}");
}

#[test]
fn disturbance_is_rejected_by_pi() {
    let m = sim("disturbance", ControllerChoice::Pi, PlantChoice::Hter1, Load::Full).metrics;
    assert!(m.tracking.max_temp_c < 6.0, "{m:?}");
    assert!(m.tracking.steady_state_error_c < 0.2, "{m:?}");
}

fn spec(choice: ControllerChoice) -> ControllerSpec {
    ControllerSpec::new(choice)
}

/// GPC designed on a model and run on that same model as an ideal plant settles exactly: the
/// prediction, the design and the ARX plant agree end to end.
#[test]
fn gpc_on_its_own_arx_model_tracks_piecewise_without_offset() {
    let m = hal_sim::arx::parse("arx:-1.88715,0.88824;-0.0073535,-0.019729;1").unwrap();
    let scenario = Scenario::resolve("piecewise").unwrap();
    let mut controller = spec(ControllerChoice::Gpc);
    controller.model = Some(m);
    // With an exact model nothing argues for caution: a light increment weight.
    controller.gpc.lambda = 0.1;
    let out = run(&SimOptions {
        drive: Default::default(),
        duration_s: scenario.duration_s,
        scenario,
        controller,
        plant: PlantChoice::Arx(m),
        load: Load::Full,
        ambient_c: 14.0,
        seed: 1,
        faults: vec![],
        module_sense: false,
    })
    .unwrap();
    assert!(out.metrics.tracking.steady_state_error_c < 0.01, "{:?}", out.metrics);
    assert!(out.metrics.tracking.min_temp_c >= 2.0);
}

/// The self-tuner's mode in every row, with the time it began: one entry per mode change.
fn mode_changes(out: &SimOutput) -> Vec<(f64, AdaptiveMode)> {
    let mut changes: Vec<(f64, AdaptiveMode)> = Vec::new();
    for r in &out.rows {
        let m = r.adaptive_mode.expect("the self-tuner's mode is logged every sample");
        if changes.last().is_none_or(|&(_, last)| last != m) {
            changes.push((r.t_s, m));
        }
    }
    changes
}

/// Self-tuning GPC on the physical plant: never below 2 °C on the piecewise experiment; its own
/// estimate becomes trusted (mode `adaptive`) before the last setpoint step and it never needs
/// the fallback PI on healthy hardware; and it survives a supply sag from 12 to 10 V mid-run
/// with a finite estimate throughout.
#[test]
fn self_tuning_gpc_stays_in_range_and_trusts_its_own_estimate() {
    for (plant, load) in
        [(PlantChoice::Hter1, Load::Full), (PlantChoice::Hter1, Load::Half), (PlantChoice::Hter2, Load::Full)]
    {
        let out = sim_spec("piecewise", spec(ControllerChoice::Gpc), plant, load);
        let m = &out.metrics;
        assert!(m.tracking.min_temp_c >= 2.0 && m.tracking.max_temp_c <= 8.0, "{plant:?} {load:?}: {m:?}");
        let changes = mode_changes(&out);
        // Before the last setpoint step (2 440 s of the 1-hour run). Measured: adaptive from 0 s
        // on H-TER I (full and half load), from 2 120 s on H-TER II, whose 4-term B (seven
        // parameters) needs the 6 °C and 3 °C steps' data before its estimate passes the checks
        // (with the 2-term B it was 0–480 s on all three); until then GPC runs on the start model.
        let engaged = changes.iter().find(|&&(_, m)| m == AdaptiveMode::Adaptive).map(|&(t, _)| t);
        assert!(engaged.is_some_and(|t| t < 2440.0), "{plant:?} {load:?}: {changes:?}");
        assert!(changes.iter().all(|&(_, m)| m != AdaptiveMode::Fallback), "{plant:?} {load:?}: {changes:?}");
    }
    let mut scenario = Scenario::resolve("disturbance").unwrap();
    scenario.changes = vec![(1800.0, hal_sim::scenario::Change::Supply(10.0))];
    let out = run(&SimOptions {
        drive: Default::default(),
        duration_s: scenario.duration_s,
        scenario,
        controller: spec(ControllerChoice::Gpc),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 3,
        faults: vec![],
        module_sense: false,
    })
    .unwrap();
    assert!(out.metrics.tracking.min_temp_c >= 2.0 && out.metrics.tracking.max_temp_c <= 8.0, "{:?}", out.metrics);
    assert!(mode_changes(&out).iter().all(|&(_, m)| m != AdaptiveMode::Fallback), "{:?}", mode_changes(&out));
    let finite = |r: &hal_sim::sim::Row| [r.a1, r.a2, r.b0, r.b1].iter().all(|p| p.is_some_and(f32::is_finite));
    assert!(out.rows.iter().all(finite), "a non-finite estimate");
}

fn sim_spec(scenario: &str, controller: ControllerSpec, plant: PlantChoice, load: Load) -> SimOutput {
    run(&options(scenario, controller, plant, load, 28.0, 7)).unwrap()
}

/// A run of `scenario` for its whole duration, with no fault.
fn options(
    scenario: &str,
    controller: ControllerSpec,
    plant: PlantChoice,
    load: Load,
    ambient_c: f64,
    seed: u64,
) -> SimOptions {
    let scenario = Scenario::resolve(scenario).unwrap();
    SimOptions {
        drive: Default::default(),
        duration_s: scenario.duration_s,
        scenario,
        controller,
        plant,
        load,
        ambient_c,
        seed,
        faults: vec![],
        module_sense: false,
    }
}

/// The method's conclusions on `piecewise`, with the self-tuning laws at their
/// defaults, each carrier's own start model and seed 7: IGMVC holds the steady-state error
/// within ±0.15 °C on the full load, the half load and H-TER II; GPC has a lower IAE than IGMVC
/// and PI on all three; no controller takes the load below 2 °C. (Across seeds 1–8 two runs
/// sit at the edge — EXPERIMENTS.md.)
#[test]
fn seed_conclusions_hold_on_piecewise() {
    for (plant, load) in
        [(PlantChoice::Hter1, Load::Full), (PlantChoice::Hter1, Load::Half), (PlantChoice::Hter2, Load::Full)]
    {
        let run = |c| sim("piecewise", c, plant, load).metrics;
        let (pi, gmvc, igmvc, gpc) = (
            run(ControllerChoice::Pi),
            run(ControllerChoice::Gmvc),
            run(ControllerChoice::Igmvc),
            run(ControllerChoice::Gpc),
        );
        for m in [&pi, &gmvc, &igmvc, &gpc] {
            assert!(m.tracking.min_temp_c >= 2.0 && m.tracking.max_temp_c <= 8.0, "{plant:?} {load:?}: {m:?}");
            assert_eq!(m.alarm_indicator_first_s, None, "{plant:?} {load:?}: indicator on: {m:?}");
        }
        assert!(igmvc.tracking.steady_state_error_c <= 0.15, "{plant:?} {load:?} IGMVC: {igmvc:?}");
        assert!(
            gpc.tracking.iae < pi.tracking.iae,
            "{plant:?} {load:?}: GPC {} vs PI {}",
            gpc.tracking.iae,
            pi.tracking.iae
        );
        assert!(
            gpc.tracking.iae < igmvc.tracking.iae,
            "{plant:?} {load:?}: GPC {} vs IGMVC {}",
            gpc.tracking.iae,
            igmvc.tracking.iae
        );
    }
}

/// Self-tuning GPC lands a fast descent without the freeze guard (issue 15): on `half-load` in
/// a 20 °C room the half-loaded H-TER I steps from 6 to 3 °C at full duty and its RTD falls
/// 1.5 °C a minute near 4 °C, which the guard's 120 s look-ahead carried past its 1.5 °C cut on
/// every seed (one trip each, the load then undershooting to 2.72 °C). The soft floor's guard
/// row (`hter::control::gpc::GpcStaged`, "Soft floor") eases the plan before that: no trip on
/// seeds 1–8, the load never below 2.8 °C, and the run's IAE no more than 1.4 × the bound.
/// In a cooler room, 12 and 16 °C, the descent is faster still: there the four runs of seeds
/// 1–24 that tripped with the floor alone (the one sample in nine that may not skip its design
/// stage goes without the floor and asked for full duty again mid-landing) are checked too,
/// against that sample never raising the duty.
#[test]
fn self_tuning_gpc_lands_a_fast_descent_without_tripping_the_freeze_guard() {
    let runs = (1..=8).map(|s| (20.0, s)).chain([(12.0, 1), (12.0, 3), (12.0, 14), (16.0, 1)]);
    for (ambient, seed) in runs {
        let gpc = ControllerSpec::new(ControllerChoice::Gpc);
        let opts = options("half-load", gpc, PlantChoice::Hter1, Load::Half, ambient, seed);
        let m = run(&opts).unwrap().metrics;
        let bound = hal_sim::bound::bound(&opts).unwrap().iae;
        let at = format!("{ambient} °C, seed {seed}");
        assert_eq!(m.freeze_guard_trips, 0, "{at}: {m:?}");
        assert!(m.tracking.min_temp_c >= 2.8, "{at}: lowest {} °C", m.tracking.min_temp_c);
        assert!(m.tracking.iae <= 1.4 * bound, "{at}: IAE {} against the bound {bound}", m.tracking.iae);
    }
}

/// After a step the wall and the cold plate keep pulling the water the step's way, beyond the
/// self-tuner's model and GPC's horizon; the reset at rest (`hter::control::adaptive`, "Reset
/// at rest") is the integral action on what the model misses. Measured on the half-loaded
/// H-TER I, `piecewise`, 28 °C: the mean of the true load's error over the last quarter of each
/// setpoint's hold, at its worst over the three steps, averaged over seeds 1–4, is 0.013 °C
/// (0.022 °C before the reset, each seed 0.018–0.023: the 6 → 3 °C step's undershoot still
/// coming back); and the steady-state error stays within 0.06 °C on every seed.
#[test]
fn at_rest_the_reset_brings_the_half_load_back_to_its_setpoint() {
    let mut offsets = Vec::new();
    for seed in 1..=4 {
        let gpc = ControllerSpec::new(ControllerChoice::Gpc);
        let out = run(&options("half-load", gpc, PlantChoice::Hter1, Load::Half, 28.0, seed)).unwrap();
        let rows = &out.rows;
        let changes: Vec<usize> =
            (1..rows.len()).filter(|&i| rows[i].setpoint_c != rows[i - 1].setpoint_c).chain([rows.len()]).collect();
        assert_eq!(changes.len(), 4, "three steps and the end");
        let worst = changes
            .windows(2)
            .map(|h| {
                let tail = &rows[h[0] + 3 * (h[1] - h[0]) / 4..h[1]];
                (tail.iter().map(|r| r.true_temp_c - r.setpoint_c).sum::<f64>() / tail.len() as f64).abs()
            })
            .fold(0.0, f64::max);
        offsets.push(worst);
        let m = &out.metrics.tracking;
        assert!(m.steady_state_error_c <= 0.06, "seed {seed}: {m:?}");
    }
    let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
    assert!(mean <= 0.016, "the holds end {offsets:?} °C off their setpoints on average");
}

/// The sample that may not skip its design stage holds the duty only after a floor sample
/// (`hter::control::gpc::GpcStaged`, "Constrained"): campaign mission 4207 (`hter sim
/// --mission-seed 4207`) pulls a light carrier down from 13.9 °C, its duty banging between the
/// rails on box-limited plans, and a hold there kept the duty at 0 at 120 s when the load
/// needed cooling: after the pull-down it rose back to 8.29 °C, 40 s above 8 °C. Clipped into
/// the box as before the hold, the load peaked at 8.01 °C (10 s above). Since the fallback PI
/// drives the first four samples (`hter::control::adaptive`, "The first samples") the pull-down
/// starts 40 s sooner at full duty, the bang between the rails comes at other readings, and the
/// load peaks at 8.16 °C (20 s above) after first crossing 8 °C 40 s sooner.
#[test]
fn the_sample_that_may_not_skip_holds_the_duty_only_after_a_floor_sample() {
    use hal_sim::mission::{evaluate, Mission};
    let m = Mission::generate(4207);
    let r = evaluate(&m, &run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap());
    let max = r.max_judged_c.unwrap_or(f64::NAN);
    assert!(max <= 8.2 && r.outside_s <= 20.0, "highest {max} °C, {} s outside 2–8 °C", r.outside_s);
}

/// A refused estimate freezes the law on the model its last rest confirmed
/// (`hter::control::adaptive`, "Frozen on the rest's model"): on campaign mission 4384 (`hter
/// sim --mission-seed 4384`, a light H-TER I carrier, the room down to 9 °C) a warming pulse at
/// 13.3 h ends a long rest at duty 0.14, GPC rings the duty between 0 and 1, and the estimate
/// drifts to a near double pole at 1 with a warming b3 that cancels most of its cooling terms.
/// Frozen on that last trusted model, GPC held the load 0.4 °C below the setpoint in a
/// rail-to-rail cycle for 4.4 h: mean error 0.34 °C from 13 h to the end, lowest 2.25 °C. On
/// the rest's model: 0.055 °C (PI 0.051), lowest 2.93 °C; with the estimator also held at a
/// rail, which kept that estimate plausible for longer, 0.091 °C and 2.75 °C. Refused as soon
/// as its warming tail cancels more than 0.7 of the cooling ("Projection"): 0.028 °C, lowest
/// 3.62 °C.
#[test]
fn a_drifted_estimate_freezes_the_law_on_the_model_of_the_last_rest() {
    use hal_sim::mission::{evaluate, Mission};
    let m = Mission::generate(4384);
    let out = run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
    let late: Vec<_> = out.rows.iter().filter(|r| r.t_s >= 13.0 * 3600.0).collect();
    assert!(
        late.iter().any(|r| r.adaptive_mode == Some(AdaptiveMode::Frozen)),
        "the run no longer refuses its estimate after the rest: the test does not reach the case"
    );
    let mean = late.iter().map(|r| (r.true_temp_c - r.setpoint_c).abs()).sum::<f64>() / late.len() as f64;
    let lowest = late.iter().map(|r| r.true_temp_c).fold(f64::INFINITY, f64::min);
    assert!(mean <= 0.05 && lowest >= 3.3, "mean error {mean:.3} °C, lowest {lowest:.2} °C from 13 h");
    assert_eq!(evaluate(&m, &out).guard_trips, 0, "freeze-guard trips");
}

/// A half-loaded H-TER I pulled down from 28 °C holds its setpoint: with the estimator held
/// while the duty sits at one rail (module docs of `hter::control::adaptive`, "Held at a
/// rail"), the half-hour at full duty no longer drifts B out of the plausible set, and GPC does
/// not end the day frozen with the duty going 0 ↔ 1 (seed 4: steady-state error 0.419 °C and
/// hours `frozen` before; 0.025 °C). Seeds 1–4 at 28 °C; each run trusts its estimate over the
/// last hour.
#[test]
fn a_pull_down_at_full_duty_leaves_the_estimate_trusted_and_the_hold_steady() {
    for seed in 1..=4 {
        let out = run(&options(
            "step",
            ControllerSpec::new(ControllerChoice::Gpc),
            PlantChoice::Hter1,
            Load::Half,
            28.0,
            seed,
        ))
        .unwrap();
        let sse = out.metrics.tracking.steady_state_error_c;
        assert!(sse <= 0.05, "seed {seed}: steady-state error {sse:.3} °C");
        let end = out.rows.last().unwrap().t_s;
        let frozen = out
            .rows
            .iter()
            .filter(|r| r.t_s >= end - 3600.0 && r.adaptive_mode != Some(AdaptiveMode::Adaptive))
            .count();
        assert_eq!(frozen, 0, "seed {seed}: samples not adaptive in the last hour");
    }
}

/// Self-tuning copes with the plant changing under it: at 4 °C the supply sags from 12 to 9 V
/// after an hour (a quarter less cooling power) and the ambient jumps from 28 to 36 °C after two.
/// Every law keeps the load within 2–8 °C and is back within ±0.3 °C of the setpoint in the
/// last half hour of the hold. Through the hold GPC's and IGMVC's estimators are paused at rest
/// (module docs of `hter::control::adaptive`, "Paused at rest": the changes never take the load
/// 0.3 °C off, at most 0.12 °C), so their estimates stay bit for bit (GMVC's duty touches the
/// rails, which ends its rests); the setpoint steps after it (4 → 6 → 3 →
/// 4 °C from 4 h) excite it, and it follows the plant: the estimated effect of the duty, B(1) =
/// b0 + … + b3, comes out at least 15 % smaller in magnitude than before the sag (less cooling
/// per unit duty at 9 V; measured 22 % GMVC, 33 % IGMVC, 49 % GPC at its smallest).
///
/// (What the estimate converges to, and what it does not, is
/// `self_tuner_learns_the_plants_response_over_the_horizon_from_a_wrong_start`.)
#[test]
fn self_tuning_laws_survive_a_plant_change_mid_run() {
    use hal_sim::scenario::{Change, Start};
    for c in [ControllerChoice::Gmvc, ControllerChoice::Igmvc, ControllerChoice::Gpc] {
        let scenario = Scenario {
            name: "plant-change".into(),
            description: "supply sag then hotter ambient at 4 °C".into(),
            start: Start::Holding(4.0),
            setpoints: vec![(0.0, 4.0), (14400.0, 6.0), (16200.0, 3.0), (18000.0, 4.0)],
            changes: vec![(3600.0, Change::Supply(9.0)), (7200.0, Change::Ambient(36.0))],
            duration_s: 5.5 * 3600.0,
            load: None,
            excitation: false,
            cut: None,
        };
        let out = run(&SimOptions {
            drive: Default::default(),
            duration_s: scenario.duration_s,
            scenario,
            controller: spec(c),
            plant: PlantChoice::Hter1,
            load: Load::Full,
            ambient_c: 28.0,
            seed: 5,
            faults: vec![],
            module_sense: false,
        })
        .unwrap();
        let m = &out.metrics;
        assert!(m.tracking.min_temp_c >= 2.0 && m.tracking.max_temp_c <= 8.0, "{c:?}: {m:?}");
        let tail = out.rows.iter().filter(|r| r.t_s >= 3.5 * 3600.0 && r.t_s < 4.0 * 3600.0);
        let worst = tail.map(|r| (r.true_temp_c - 4.0).abs()).fold(0.0, f64::max);
        assert!(worst <= 0.3, "{c:?}: |T − 4| up to {worst} °C in the last half hour of the hold");
        let b_sum = |r: &hal_sim::sim::Row| r.b0.unwrap() + r.b1.unwrap() + r.b2.unwrap() + r.b3.unwrap();
        let at = |t: f64| b_sum(out.rows.iter().find(|r| r.t_s >= t).unwrap());
        let before = at(3500.0);
        assert!(before < 0.0, "{c:?}: B(1) {before} must cool");
        if c != ControllerChoice::Gmvc {
            // (GMVC's duty touches the rails at rest, which ends the rest each time.)
            assert_eq!(at(14000.0).to_bits(), before.to_bits(), "{c:?}: the estimator is paused through the hold");
        }
        let excited = out.rows.iter().filter(|r| r.t_s >= 14400.0).map(b_sum);
        let least = excited.fold(f32::NEG_INFINITY, f32::max);
        assert!(
            least < 0.0 && least.abs() <= 0.85 * before.abs(),
            "{c:?}: B(1) {before} → {least}: did not follow the sag"
        );
    }
}

/// The physical plant's response to a unit duty step as the step's controller sees it: the
/// RTD's temperature of [`Plant::sensed_step`](hal_sim::plant::Plant::sensed_step) (samples of
/// 10 s from the steady state holding `load_c`, the duty raised by `delta`) through the step's
/// first-order filter (F_a = 0.5), as a change from the start per unit duty. Index j − 1 is the
/// response j samples after the step.
fn plant_step_response(
    params: hal_sim::plant::PlantParams,
    ambient_c: f64,
    load_c: f64,
    delta: f64,
    n: usize,
) -> Vec<f64> {
    let (sensed, _) = hal_sim::plant::Plant::sensed_step(params, ambient_c, load_c, delta, 10.0, n).unwrap();
    let fa = f64::from(hter::step::CarrierConfig::DEFAULT.filter.fa);
    let y0 = sensed[0];
    let mut y = y0;
    sensed[1..]
        .iter()
        .map(|&t| {
            y = fa * y + (1.0 - fa) * t;
            (y - y0) / delta
        })
        .collect()
}

/// The step response of `y(t) = −a1 y(t−1) − a2 y(t−2) + b0 u(t−k) + b1 u(t−k−1)` to a unit
/// step at t = 0, samples 1 … n (written out here, apart from the library's GPC).
fn model_step_response(a: [f64; 2], b: &[f64], k: usize, n: usize) -> Vec<f64> {
    let u = |t: i64| if t >= 0 { 1.0 } else { 0.0 };
    let mut y = vec![0.0f64; n + 1];
    for t in 1..=n {
        let past = |m: usize| if t >= m { y[t - m] } else { 0.0 };
        let t_i = t as i64;
        let forced: f64 = b.iter().enumerate().map(|(i, bi)| bi * u(t_i - (k + i) as i64)).sum();
        y[t] = -a[0] * past(1) - a[1] * past(2) + forced;
    }
    y[1..].to_vec()
}

/// Closed-loop convergence of the self-tuner, measured where the law uses the model: its
/// predicted response to the duty over GPC's horizon (30 samples, 5 min) and twice that. Started
/// from a model whose cooling effect is half the real one (the start model's B halved), after
/// `piecewise` on the full-load H-TER I, the estimate's step response at 30 and 60 samples is
/// within 15 % and 10 % of the physical plant's own (computed from the plant model alone,
/// [`plant_step_response`]), where the start was 50 % off, on seeds 1–4. Measured with the
/// 4-term B (issue 15), seeds 1–8: 12–15 % under at 30 samples, 6–8 % at 60; the 2-term B it
/// replaced was within 10 % at both, and controlled worse (EXPERIMENTS.md).
///
/// The static gain B(1)/A(1) does not converge and is not asserted: it ends at −16.4 … −16.8 °C
/// per unit duty on seeds 1–8 (−17.5 … −17.9 with the 2-term B) against the plant's −42.8 at
/// 4 °C. The plant's slow mode
/// (τ ≈ 50 min, the water) is far beyond what an hour of regulated data excites, and A(1) =
/// 1 + a1 + a2 ≈ 2·10⁻⁴ makes the gain a ratio of two small numbers that a small bias of
/// equation-error least squares moves far. What GPC predicts over its horizon is what it
/// learns; the integral action of the incremental law removes the rest.
#[test]
fn self_tuner_learns_the_plants_response_over_the_horizon_from_a_wrong_start() {
    use hal_sim::plant::PlantParams;
    use hter::model::Model;
    use hter::profile::START_MODEL_HTER1 as M;
    let truth = plant_step_response(PlantParams::hter1(Load::Full), 28.0, 4.0, 0.05, 60);
    // The reference is a cooler: colder with more duty, monotonically, after a dead time.
    assert!(truth[2].abs() < 0.05 * truth[29].abs(), "{truth:?}");
    assert!(truth.windows(2).all(|w| w[1] <= w[0] + 1e-9), "{truth:?}");
    let at = |g: &[f64]| [g[29], g[59]];
    let start = Model::second_order([M.a()[0], M.a()[1]], [0.5 * M.b()[0], 0.5 * M.b()[1]], M.k()).unwrap();
    let g_start = model_step_response(
        [M.a()[0], M.a()[1]].map(f64::from),
        &[0.5 * M.b()[0], 0.5 * M.b()[1]].map(f64::from),
        M.k(),
        60,
    );
    for (g, t) in at(&g_start).iter().zip(at(&truth)) {
        assert!((g / t - 1.0).abs() > 0.4, "the start is not wrong: {g} vs the plant's {t}");
    }
    for seed in 1..=4 {
        let scenario = Scenario::resolve("piecewise").unwrap();
        let out = run(&SimOptions {
            drive: Default::default(),
            duration_s: scenario.duration_s,
            scenario,
            controller: ControllerSpec { initial: Some(start), ..spec(ControllerChoice::Gpc) },
            plant: PlantChoice::Hter1,
            load: Load::Full,
            ambient_c: 28.0,
            seed,
            faults: vec![],
            module_sense: false,
        })
        .unwrap();
        let last = out.rows.last().unwrap();
        let [a1, a2, b0, b1, b2, b3] =
            [last.a1, last.a2, last.b0, last.b1, last.b2, last.b3].map(|p| f64::from(p.unwrap()));
        let g = model_step_response([a1, a2], &[b0, b1, b2, b3], M.k(), 60);
        for ((n, tol), (g, t)) in [(30, 0.15), (60, 0.10)].iter().zip(at(&g).iter().zip(at(&truth))) {
            assert!(
                (g / t - 1.0).abs() <= *tol,
                "seed {seed}: {n}-sample response {g:.2} vs the plant's {t:.2} °C per unit duty"
            );
        }
    }
}
