//! Holdover accuracy on the `power-cut` scenario (SPEC §9; issue 17): holding 4 °C, the supply
//! goes to 0 V at 2 h; the step's estimate just before the cut (`holdover_predicted_s`) against
//! the time the true load takes to pass 8 °C (`holdover_actual_s`). Target: within 15 % of the
//! actual, on H-TER I and II, full and half load, at 25, 32 and 43 °C.
//!
//! - On the stored start model (identified at full load), the six full-load cases meet it; the
//!   half-load ones do not (24–41 % optimistic: half the water warms faster) and are not tested
//!   here.
//! - With the carrier commissioned at the load it carries (the board's on-board
//!   commissioning, [`hal_sim::commission`]) all twelve meet it when the fit may keep the
//!   carriers' fast mode (`SignRule::Monotone`, b1 > 0). With the board's default rule (every
//!   b_i ≤ 0) H-TER II meets it at both loads; H-TER I does not (its fit comes out first order
//!   plus delay, too slow in the first minutes) and is not tested here.
//! - As the board does it (one run, two models: the self-tuner starts from the every-b_i ≤ 0
//!   control model, the holdover runs on the monotone cabinet model,
//!   [`hal_sim::commission::commission_board`]): all twelve meet it.
//!
//! The runs print their table (`--nocapture`).

use hal_sim::commission::{commission, commission_board};
use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};
use hter::ident::commission::SignRule;
use hter::model::Model;

/// The largest error allowed, as a fraction of the actual holdover.
const TOLERANCE: f64 = 0.15;

/// The self-tuner's start and the holdover's model (the carrier's start model when `None`).
type Stored = (Option<Model>, Option<Model>);

/// One model for both, as `hter sim --commission RULE`: the self-tuner's start if it trusts it.
fn one(m: Option<Model>) -> Stored {
    (m.filter(|m| hter::control::adaptive::plausible_model(&hter::profile::ADAPTIVE_GPC, m)), m)
}

/// (predicted, actual) holdover, s, of `power-cut` on `plant` at `load` and `ambient_c`, the
/// self-tuner starting from and the holdover running on `stored`.
fn power_cut(plant: PlantChoice, load: Load, ambient_c: f64, (initial, holdover): Stored) -> (f64, f64) {
    let mut spec = ControllerSpec::new(ControllerChoice::Gpc);
    spec.initial = initial;
    spec.holdover = holdover;
    let opts = SimOptions { plant, load, ambient_c, ..SimOptions::new(Scenario::resolve("power-cut").unwrap(), spec) };
    let h = run(&opts).unwrap().metrics.holdover.expect("a power-cut run reports its holdover");
    (h.predicted_s.expect("an estimate before the cut"), h.actual_s.expect("the load passed 8 °C"))
}

fn name(plant: PlantChoice) -> &'static str {
    match plant {
        PlantChoice::Hter1 => "hter1",
        _ => "hter2",
    }
}

/// Runs every case in parallel (each is independent) and checks each against [`TOLERANCE`].
fn check(what: &str, cases: &[(PlantChoice, Load, f64)], stored: impl Fn(PlantChoice, Load, f64) -> Stored + Sync) {
    let results: Vec<(f64, f64)> = std::thread::scope(|s| {
        let handles: Vec<_> = cases
            .iter()
            .map(|&(p, l, a)| {
                let stored = &stored;
                s.spawn(move || power_cut(p, l, a, stored(p, l, a)))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let mut misses = Vec::new();
    for (&(p, l, a), &(predicted, actual)) in cases.iter().zip(&results) {
        let err = (predicted - actual) / actual;
        println!(
            "{what}: {} {} {a} °C: predicted {predicted:.0} s, actual {actual:.0} s, {:+.1} %",
            name(p),
            format!("{l:?}").to_lowercase(),
            100.0 * err
        );
        if err.abs() > TOLERANCE {
            misses.push(format!(
                "{} {} {a} °C: {predicted:.0} vs {actual:.0} s",
                name(p),
                format!("{l:?}").to_lowercase()
            ));
        }
    }
    assert!(misses.is_empty(), "{what}: outside ±15 %: {misses:?}");
}

fn cases(plants: &[PlantChoice], loads: &[Load]) -> Vec<(PlantChoice, Load, f64)> {
    let mut v = Vec::new();
    for &p in plants {
        for &l in loads {
            for a in [25.0, 32.0, 43.0] {
                v.push((p, l, a));
            }
        }
    }
    v
}

#[test]
fn the_stored_full_load_model_is_within_15_percent_at_full_load() {
    check("start model", &cases(&[PlantChoice::Hter1, PlantChoice::Hter2], &[Load::Full]), |_, _, _| (None, None));
}

fn params(p: PlantChoice, l: Load) -> hal_sim::plant::PlantParams {
    SimOptions {
        plant: p,
        load: l,
        ..SimOptions::new(Scenario::resolve("power-cut").unwrap(), ControllerSpec::new(ControllerChoice::Gpc))
    }
    .plant_params()
    .unwrap()
}

/// The carrier commissioned where it runs (its load and ambient) with one sign rule, then cut.
fn commissioned(sign: SignRule) -> impl Fn(PlantChoice, Load, f64) -> Stored + Sync {
    move |p, l, a| one(Some(commission(params(p, l), a, 1, sign).expect("commissioning succeeds")))
}

/// The carrier commissioned where it runs as the board's App does: the control model for the
/// self-tuner, the cabinet model for the holdover (`hter sim --commission board`).
#[test]
fn commissioned_by_the_board_every_case_is_within_15_percent() {
    check(
        "commissioned (board: control + cabinet model)",
        &cases(&[PlantChoice::Hter1, PlantChoice::Hter2], &[Load::Full, Load::Half]),
        |p, l, a| {
            let c = commission_board(params(p, l), a, 1).expect("commissioning succeeds");
            (Some(c.control), Some(c.cabinet))
        },
    );
}

#[test]
fn commissioned_at_its_load_every_case_is_within_15_percent() {
    check(
        "commissioned (monotone)",
        &cases(&[PlantChoice::Hter1, PlantChoice::Hter2], &[Load::Full, Load::Half]),
        commissioned(SignRule::Monotone),
    );
}

#[test]
fn commissioned_with_the_boards_rule_h_ter_ii_is_within_15_percent_at_both_loads() {
    check(
        "commissioned (every coefficient)",
        &cases(&[PlantChoice::Hter2], &[Load::Full, Load::Half]),
        commissioned(SignRule::EveryCoefficient),
    );
}

/// After a brown-out's restart (a fresh step, as at every boot) the step shows no estimate until
/// its mean duty has settled ([`hter::holdover::SETTLE_SAMPLES`] samples of `None`; the mean
/// started at 0 gave the 48 h horizon there); settled, the estimate is minutes again and the one
/// at the cut as right as without the restart.
#[test]
fn no_estimate_until_the_mean_duty_has_settled_after_a_boot_or_a_brownout() {
    use hal_sim::fault::Fault;
    use hter::holdover::{HORIZON_S, SETTLE_SAMPLES};
    let settle = SETTLE_SAMPLES as usize;
    let brownout_s = 1800.0;
    let opts = SimOptions {
        faults: vec![(brownout_s, Fault::Brownout)],
        ..SimOptions::new(Scenario::resolve("power-cut").unwrap(), ControllerSpec::new(ControllerChoice::Gpc))
    };
    let out = run(&opts).unwrap();
    let before_cut: Vec<(f64, Option<f64>)> =
        out.rows.iter().take_while(|r| r.t_s < 7200.0).map(|r| (r.t_s, r.holdover_s)).collect();
    assert!(before_cut.iter().all(|(_, h)| *h != Some(f64::from(HORIZON_S))), "the horizon shown while holding");
    let restart = before_cut.iter().position(|(t, _)| *t >= brownout_s).unwrap();
    let after: Vec<Option<f64>> = before_cut[restart..].iter().map(|(_, h)| *h).collect();
    assert!(after[..settle].iter().all(Option::is_none), "an estimate before the mean settled: {:?}", &after[..settle]);
    let first = after.iter().position(Option::is_some).expect("an estimate once settled");
    assert!(first < settle + 20, "the first estimate only {first} samples after the restart");
    assert!(after[first..].iter().all(|h| h.is_some_and(|h| (60.0..3600.0).contains(&h))), "{:?}", &after[first..]);
    let h = out.metrics.holdover.unwrap();
    let (predicted, actual) = (h.predicted_s.unwrap(), h.actual_s.unwrap());
    assert!(((predicted - actual) / actual).abs() <= TOLERANCE, "{predicted} vs {actual} s");
}

/// The ambient rises from 12 to 43 °C (a carrier taken out of a cool room into the sun) and the
/// supply is cut 11 minutes later; the reference is the plant's own answer (the true load from
/// the cut to past 8 °C). At 12 °C the start model's sweeps cross after thousands of seconds and
/// a sweep runs for a sixth of what it finds: the sweep under way at the rise kept running on
/// the cold room's T₀ and ū and the estimate at the cut was 7193 s against the 280 s the load
/// took. The 5-minute mean ū still lags the new duty by ≈ 6 % of its change 66 samples on
/// (`(1 − w)ⁿ (1 + n w/(1 − w))`, w = 1/15), so the bound is the 15 % plus that lag's share:
/// +50 %, against +2469 % before the sweep followed the present T₀ and ū.
#[test]
fn the_estimate_follows_a_rise_of_the_ambient_within_minutes() {
    use hal_sim::scenario::{Change, PowerCut};
    let (rise_s, cut_s) = (3600.0, 3600.0 + 660.0);
    let mut scenario = Scenario::resolve("power-cut").unwrap();
    scenario.changes = vec![(rise_s, Change::Ambient(43.0)), (cut_s, Change::Supply(0.0))];
    scenario.cut = Some(PowerCut { at_s: cut_s, limit_c: f64::from(hter::holdover::LIMIT_C) });
    let opts = SimOptions {
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 12.0,
        ..SimOptions::new(scenario, ControllerSpec::new(ControllerChoice::Gpc))
    };
    let h = run(&opts).unwrap().metrics.holdover.unwrap();
    let (predicted, actual) = (h.predicted_s.unwrap(), h.actual_s.unwrap());
    println!("ambient 12 → 43 °C, cut 11 min later: predicted {predicted:.0} s, actual {actual:.0} s");
    assert!(predicted <= 1.5 * actual, "{predicted:.0} s predicted, the load took {actual:.0} s");
}
