//! The simulated board stores what the firmware stores, when it does: the cold-chain history
//! through the board's `persist::Recorder` and the self-tuner's model through the board's
//! `persist::ModelCadence`, both at the cadence of the board profile (`hter::profile`).

use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, Fault, SimOptions, SimOutput};
use hter::coldchain::AlarmKind;
use hter::control::AdaptiveMode;
use hter::persist::{HistoryRecord, ModelRecord, ResetCause, Save};
use hter::profile::{samples, HISTORY_SAVE_S, MODEL_SAVE_S};

const TS_S: f64 = 10.0;
const DAY_S: f64 = 86_400.0;

/// A day of self-tuning GPC on the half load, where the estimate is trusted most of the time.
fn day(faults: &[&str]) -> SimOutput {
    let mut opts = SimOptions::new(Scenario::resolve("half-load").unwrap(), ControllerSpec::new(ControllerChoice::Gpc));
    opts.duration_s = DAY_S;
    opts.faults = faults.iter().map(|f| Fault::parse(f).unwrap()).collect();
    run(&opts).unwrap()
}

fn history_times(out: &SimOutput) -> Vec<f64> {
    out.stores.iter().filter(|(_, s)| matches!(s, Save::History(_))).map(|(t, _)| *t).collect()
}

fn models(out: &SimOutput) -> Vec<(f64, ModelRecord)> {
    out.stores.iter().filter_map(|(t, s)| if let Save::Model(m) = s { Some((*t, *m)) } else { None }).collect()
}

/// Rows in (t0, t1] in which the self-tuner's estimate was trusted.
fn adaptive_rows(out: &SimOutput, t0: f64, t1: f64) -> usize {
    out.rows.iter().filter(|r| r.t_s > t0 && r.t_s <= t1 && r.adaptive_mode == Some(AdaptiveMode::Adaptive)).count()
}

#[test]
fn a_day_stores_the_history_hourly_and_the_model_after_every_4_h_of_trust() {
    let out = day(&[]);
    assert!(out.metrics.alarms.is_empty(), "{:?}", out.metrics.alarms);
    // Every 360th recorded sample (the hour's last), the first at 3590 s: 24 in a day.
    let every = f64::from(samples(HISTORY_SAVE_S, TS_S as f32));
    assert_eq!(every, 360.0);
    let want: Vec<f64> = (1..=24).map(|h| (h as f64 * every - 1.0) * TS_S).collect();
    assert_eq!(history_times(&out), want);
    assert!(out.stores.iter().all(|(_, s)| matches!(s, Save::History(_) | Save::Model(_))));
    // The last hourly record holds the day.
    let Some((_, Save::History(last))) = out.stores.iter().rev().find(|(_, s)| matches!(s, Save::History(_))) else {
        unreachable!()
    };
    assert_eq!(last.recorded_s, 86_390);

    // The model: once per 1440 samples of trusted estimate (the count begins in the hour of
    // pre-roll before the record), each store the estimate the self-tuner trusted that sample.
    let trust = samples(MODEL_SAVE_S, TS_S as f32) as usize;
    assert_eq!(trust, 1440);
    let stored = models(&out);
    assert!(stored.len() >= 4, "{stored:?}");
    for pair in stored.windows(2) {
        assert_eq!(adaptive_rows(&out, pair[0].0, pair[1].0), trust, "between {} and {} s", pair[0].0, pair[1].0);
    }
    for (t, rec) in &stored {
        let row = out.rows.iter().find(|r| r.t_s == *t).unwrap();
        assert_eq!(row.adaptive_mode, Some(AdaptiveMode::Adaptive), "stored at {t} s");
        // All four B terms of the self-tuner's estimate (`ESTIMATED_NB`), as the row shows them,
        // with the tail b1 … b3 clipped at zero as the laws get it (`SelfTuning::estimate`).
        let mut theta = [row.a1, row.a2, row.b0, row.b1, row.b2, row.b3].map(Option::unwrap);
        for b in &mut theta[3..] {
            *b = b.min(0.0);
        }
        assert_eq!(rec.theta, theta, "stored at {t} s");
        assert_eq!(rec.k, 5);
    }
}

#[test]
fn a_brownout_stores_the_reset_and_restarts_both_counts() {
    const RESET_S: f64 = 20_000.0;
    let out = day(&["brownout@20000"]);
    let at = out.stores.iter().find(|(t, _)| *t >= RESET_S).expect("a store at the reset");
    let Save::History(h) = at.1 else { panic!("{at:?}") };
    assert_eq!((at.0, h.resets_by(ResetCause::BrownOut)), (RESET_S, 1));
    // The hourly store counts again from the reset (the reset's own sample is the first of
    // the 360), as a board's does from its boot.
    let times = history_times(&out);
    let next = times.iter().find(|t| **t > RESET_S).unwrap();
    assert_eq!(*next, RESET_S + 359.0 * TS_S);
    // So does the model's: the first store after the reset needs 360 trusted samples of its
    // own (a boot's first store comes after a quarter of the 1440, `ModelCadence`), where the
    // count from before the reset would have been due at 1440 less what it carried; then every
    // 1440 again.
    let stored = models(&out);
    let (before, after): (Vec<f64>, Vec<f64>) = stored.iter().map(|(t, _)| *t).partition(|t| *t < RESET_S);
    let last_before = *before.last().expect("a model stored before the reset");
    let carried = adaptive_rows(&out, last_before, RESET_S - TS_S);
    let trusted_after = |t: f64| adaptive_rows(&out, RESET_S - TS_S, t);
    match after.first() {
        Some(&t) => assert_eq!(trusted_after(t), 360, "first store after the reset at {t} s"),
        None => assert!(trusted_after(f64::INFINITY) < 360),
    }
    assert_ne!(carried, 1440 - 360, "the run must tell the two counts apart");
    if let [first, second, ..] = after[..] {
        assert_eq!(adaptive_rows(&out, first, second), 1440, "then every 1440 trusted samples");
    }
}

/// A brown-out in a long hold restarts the self-tuner from its stored model without a swing
/// (`hter::control::adaptive`, "Resumed from a stored model"): the stored model holds no
/// offset, and with P(0) = I the restart's first error went into B as much as into the offset;
/// the law on that B swung the load between 3.50 and 4.41 °C for 15 minutes. Resumed, the load
/// stays within 0.15 °C of its 4 °C, and the estimate is trusted again within the hour and for
/// the rest of the day. (0.1 °C until the simulated restart started the law from the board's
/// boot duty, 0.4, which GPC held for the four samples its first design takes, where the
/// holding duty had been used: 0.12 °C of it is that start, no swing; the same with the fallback
/// PI driving those four samples, `hter::control::adaptive`, "The first samples".) Since the
/// boot starts every law from the board's boot duty, 0.2 (`profile::BOOT_DUTY`), under the 0.46
/// this load holds at, the load warms by up to 0.55 °C in the first minutes after the restart,
/// never more than 0.15 °C below the setpoint, and within 0.15 °C of it from 10 minutes on.
#[test]
fn a_brownout_in_a_hold_resumes_from_the_stored_model_without_a_swing() {
    const RESET_S: f64 = 20_000.0;
    let out = day(&["brownout@20000"]);
    let after: Vec<_> = out.rows.iter().filter(|r| r.t_s >= RESET_S).collect();
    let error = |r: &&hal_sim::sim::Row| r.true_temp_c - r.setpoint_c;
    let (low, high) = after.iter().map(error).fold((0.0, 0.0), |(l, h), e| (f64::min(l, e), f64::max(h, e)));
    assert!(low >= -0.15 && high <= 0.6, "{low:.2} … {high:.2} °C from the setpoint after the restart");
    let settled = after.iter().filter(|r| r.t_s >= RESET_S + 600.0).map(error).fold(0.0, |w, e| f64::max(w, e.abs()));
    assert!(settled <= 0.15, "{settled:.2} °C from the setpoint 10 minutes after the restart");
    let mut late = after.iter().filter(|r| r.t_s >= RESET_S + 3600.0);
    assert!(late.all(|r| r.adaptive_mode == Some(AdaptiveMode::Adaptive)), "not adaptive an hour on");
    // The trust decision settles once: frozen at the restart, adaptive when the estimate is
    // trusted again. The stored estimate sits on the static-gain cone's far edge (≈ −1 000
    // °C/duty, an integrator-like A), and when the projection bounded the raw B(1) while the
    // trust check took the B with its warming tail clipped, it went in and out of the set every
    // few samples: 44 mode changes in 20 minutes, each a logged event.
    let changes = after.windows(2).filter(|w| w[0].adaptive_mode != w[1].adaptive_mode).count();
    assert!(changes <= 2, "{changes} mode changes after the restart");
}

/// A brown-out loses what the board's RAM held, as on the board: the record restarts from the
/// history last stored, so the samples between that store and the cut are not in it, and a WHO
/// alarm's run goes on from where the store left it. A dead SSR (the load warms from 600 s)
/// and a cut 6 h later: `heat_10h` comes as late as the store was before the cut, and the day's
/// time above 8 °C is short by as much.
#[test]
fn a_brownout_restarts_the_record_from_the_last_store() {
    const RESET_S: f64 = 21_600.0;
    let kept = day(&["ssr-stuck-off@600"]);
    let cut = day(&["ssr-stuck-off@600", "brownout@21600"]);
    let heat = |out: &SimOutput| {
        let a: Vec<f64> = out.metrics.alarms.iter().filter(|a| a.kind == AlarmKind::Heat10h).map(|a| a.t_s).collect();
        assert_eq!(a.len(), 1, "{:?}", out.metrics.alarms);
        a[0]
    };
    let stored_before = history_times(&cut).into_iter().filter(|t| *t < RESET_S).fold(f64::NAN, f64::max);
    let lost = RESET_S - stored_before;
    // The load is outside 2…8 °C from well before the cut, so the history is stored every
    // 10 minutes (`persist::EXCURSION_SAVES`): at most that much is lost.
    assert!(lost > 0.0 && lost <= 600.0, "last store {stored_before} s before the cut at {RESET_S} s");
    assert_eq!(heat(&cut), heat(&kept) + lost);
    // The last store of the day, and what it holds: the cut's record misses the lost span.
    let last = |out: &SimOutput| {
        let Some((t, Save::History(h))) = out.stores.iter().rev().find(|(_, s)| matches!(s, Save::History(_))) else {
            panic!("no history stored")
        };
        (*t, *h)
    };
    let ((tk, k), (tc, c)) = (last(&kept), last(&cut));
    assert_eq!((k.resets_by(ResetCause::BrownOut), c.resets_by(ResetCause::BrownOut)), (0, 1));
    // Time the record does not cover by the store, and time above 8 °C it misses (the load is
    // above 8 °C throughout after the first hours).
    let unrecorded = |t: f64, h: &HistoryRecord| t - f64::from(h.recorded_s);
    assert_eq!(unrecorded(tc, &c) - unrecorded(tk, &k), lost);
    assert_eq!((tc - f64::from(c.above_8_s)) - (tk - f64::from(k.above_8_s)), lost);
}
