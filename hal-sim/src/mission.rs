//! Randomized 24 h missions for `hter campaign`: each mission is fully determined by
//! its seed, so any mission of a campaign replays alone with `hter sim --mission-seed N`.
//!
//! A mission draws, from a ChaCha8 stream seeded with its seed:
//! - the carrier: H-TER I or II, full load, with every heat capacity and thermal conductance of
//!   [`PlantParams`] scaled by its own factor in [0.5, 1.5] (the Peltier module, the RTD and
//!   the dead time stay nominal: they come from datasheets, not from the build);
//! - the ambient: a day/night cycle, amplitude 2…10 °C around a mean chosen so that the whole
//!   cycle stays within 0…43 °C, in steps of 30…60 min, with a random phase;
//! - 0…6 lid openings (10…20 W for 1…5 min);
//! - with probability ½ a supply sag (12 V → 9.5…11 V for 30…120 min);
//! - with probability 0.3 sensor spikes from a random time on (not a hardware fault: the step
//!   ignores each spike and reports them);
//! - with probability 0.2 one hardware fault, uniform over the table's
//!   [`FaultClass::Hardware`] faults, at a random time between 2 h and 22 h;
//! - in a mission without one, with probability [`BOARD_FAULT_P`] one fault of the board
//!   around the step, uniform over the [`FaultClass::Board`] faults, at a random time between
//!   2 h and 22 h, drawn from a second stream (seeded from the seed and
//!   [`BOARD_FAULT_STREAM`]) so that none of the draws above depends on the board-fault draw.
//!
//! The setpoint is 4 °C; the run starts at ambient with cooling off (pull-down).
//!
//! The evaluation ([`evaluate`]) and its rules are documented on [`MissionReport`].

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use hter::event::EventKind;
use hter::step::Mode;

use crate::fault::{Fault, FaultClass};
use crate::metrics::Detected;
use crate::plant::{Load, PlantParams};
use crate::scenario::{day_night, Change, Scenario, Start, DAY_S};
use crate::sim::{ControllerSpec, PlantChoice, RowMode, SimOptions, SimOutput};

/// Probability of a board fault in a mission without a hardware fault: 0.2, so a 40-mission
/// campaign carries about six and 1000 missions about 160, about 23 of each of the seven kinds
/// (a shorted supply switch, a hung loop and the five fail-safe stops), as many as of each of
/// the nine hardware kinds (0.2 of 1000 missions over nine). It was 0.1 over two kinds until
/// the fail-safe stops were simulated.
pub const BOARD_FAULT_P: f64 = 0.2;

/// Salt of the board-fault stream's seed.
pub const BOARD_FAULT_STREAM: u64 = 0x62_6f61_7264; // "board"

/// Setpoint of every mission, °C.
pub const MISSION_SETPOINT_C: f64 = 4.0;

/// A sample counts as "cold ambient" when the ambient is below this, °C, now or within
/// [`COLD_LAG_S`] before: the carrier only cools, so it cannot keep the load above 2 °C there.
pub const COLD_AMBIENT_C: f64 = 4.0;

/// How long a cold spell keeps affecting the load after the ambient is back above
/// [`COLD_AMBIENT_C`], s (the carrier's slowest time constants are ≈ 1 h).
pub const COLD_LAG_S: f64 = 7200.0;

/// How long after a restart the campaign watches the load's extremes, s (an hour: the step and
/// the self-tuner start again from what flash holds, and the load settles well within it).
pub const RESTART_WATCH_S: f64 = 3600.0;

/// Largest time outside 2–8 °C in the judged window (after pull-down, before any fault but a
/// restart, outside cold ambient) that a mission may have and still pass, s (one minute: six
/// samples).
pub const OUTSIDE_TOLERANCE_S: f64 = 60.0;

/// One randomized mission.
#[derive(Clone, Debug)]
pub struct Mission {
    /// Its seed (also the ADC noise seed).
    pub seed: u64,
    /// The carrier's parameters.
    pub params: PlantParams,
    /// Scale factors applied to the capacities and conductances, by parameter name.
    pub factors: Vec<(&'static str, f64)>,
    /// Ambient at t = 0, °C.
    pub ambient0_c: f64,
    /// Setpoint, ambient, lid openings and supply sag.
    pub scenario: Scenario,
    /// Every fault injected, spikes included.
    pub faults: Vec<(f64, Fault)>,
    /// The hardware fault, if any.
    pub hardware_fault: Option<(f64, Fault)>,
    /// When sensor spikes start, if they do.
    pub spikes_s: Option<f64>,
}

impl Mission {
    /// The mission of a seed.
    pub fn generate(seed: u64) -> Mission {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let stainless = rng.gen_bool(0.5);
        let mut params = if stainless { PlantParams::hter2(Load::Full) } else { PlantParams::hter1(Load::Full) };
        let mut factors = Vec::new();
        {
            let p = &mut params;
            let fields: [(&'static str, &mut f64); 11] = [
                ("c_hot", &mut p.c_hot_j_per_k),
                ("g_hot", &mut p.g_hot_w_per_k),
                ("c_cold", &mut p.c_cold_j_per_k),
                ("g_cold_wall", &mut p.g_cold_wall_w_per_k),
                ("g_cold_air", &mut p.g_cold_air_w_per_k),
                ("c_wall", &mut p.c_wall_j_per_k),
                ("g_wall_water", &mut p.g_wall_water_w_per_k),
                ("g_air_wall", &mut p.g_air_wall_w_per_k),
                ("c_air", &mut p.c_air_j_per_k),
                ("g_leak", &mut p.g_leak_w_per_k),
                ("c_water", &mut p.c_water_j_per_k),
            ];
            for (name, v) in fields {
                let f = rng.gen_range(0.5..=1.5);
                *v *= f;
                factors.push((name, f));
            }
        }

        // Ambient: day/night staircase within 0…43 °C.
        let amplitude = rng.gen_range(2.0..=10.0);
        let mean = rng.gen_range(amplitude..=43.0 - amplitude);
        let step_s = f64::from(rng.gen_range(30u32..=60)) * 60.0;
        let t_peak = rng.gen_range(0.0..DAY_S);
        let mut changes = day_night(0.0, DAY_S, step_s, mean, amplitude, t_peak);
        let ambient0_c = match changes.first() {
            Some((_, Change::Ambient(a))) => *a,
            _ => mean,
        };

        // Lid openings.
        for _ in 0..rng.gen_range(0..=6) {
            let t = rng.gen_range(3600.0..DAY_S - 600.0).round();
            let w = rng.gen_range(10.0..=20.0);
            let d = f64::from(rng.gen_range(1u32..=5)) * 60.0;
            changes.push((t, Change::ExtraHeat(w)));
            changes.push((t + d, Change::ExtraHeat(0.0)));
        }
        // Supply sag.
        if rng.gen_bool(0.5) {
            let t = rng.gen_range(3600.0..DAY_S - 7200.0).round();
            let v = rng.gen_range(9.5..=11.0);
            let d = f64::from(rng.gen_range(30u32..=120)) * 60.0;
            changes.push((t, Change::Supply(v)));
            changes.push((t + d, Change::Supply(params.supply_v)));
        }
        let mut spikes_s = rng.gen_bool(0.3).then(|| rng.gen_range(3600.0..23.0 * 3600.0_f64).round());
        let hardware = Fault::of_class(FaultClass::Hardware);
        let mut hardware_fault = rng.gen_bool(0.2).then(|| {
            let kind = hardware[rng.gen_range(0..hardware.len())];
            (rng.gen_range(2.0 * 3600.0..22.0 * 3600.0_f64).round(), kind)
        });
        if hardware_fault.is_none() {
            let mut board = ChaCha8Rng::seed_from_u64(seed ^ BOARD_FAULT_STREAM);
            if board.gen_bool(BOARD_FAULT_P) {
                let kinds = Fault::of_class(FaultClass::Board);
                let kind = kinds[board.gen_range(0..kinds.len())];
                hardware_fault = Some((board.gen_range(2.0 * 3600.0..22.0 * 3600.0_f64).round(), kind));
            }
        }

        // A fault is a lasting state: keep the scheduled changes from undoing it.
        if let Some((tf, kind)) = hardware_fault {
            match kind {
                Fault::LidOpen => changes.retain(|(t, c)| !(matches!(c, Change::ExtraHeat(_)) && *t >= tf)),
                // The hardware sag replaces the mission's own: one still under way at `tf`
                // would already have been reported, leaving nothing new to detect.
                Fault::SupplySag => changes.retain(|(_, c)| !matches!(c, Change::Supply(_))),
                // A later spike fault would replace the sensor fault in the simulated front end.
                Fault::SensorOpen | Fault::SensorShort | Fault::SensorStuck | Fault::SensorOffset
                    if spikes_s.is_some_and(|ts| ts >= tf) =>
                {
                    spikes_s = None;
                }
                _ => {}
            }
        }
        changes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut faults = Vec::new();
        if let Some(t) = spikes_s {
            faults.push((t, Fault::SensorSpikes));
        }
        if let Some(f) = hardware_fault {
            faults.push(f);
        }
        let fault_text =
            hardware_fault.map_or("no hardware fault".to_string(), |(t, k)| format!("{} at {:.0} s", k.name(), t));
        let scenario = Scenario {
            name: format!("mission-{seed}"),
            description: format!(
                "randomized mission {seed}: {}, ambient {:.1} ± {:.1} °C, {}",
                if stainless { "H-TER II" } else { "H-TER I" },
                mean,
                amplitude,
                fault_text
            ),
            start: Start::Ambient,
            setpoints: vec![(0.0, MISSION_SETPOINT_C)],
            changes,
            duration_s: DAY_S,
            load: None,
            excitation: false,
            cut: None,
        };
        Mission { seed, params, factors, ambient0_c, scenario, faults, hardware_fault, spikes_s }
    }

    /// The run of this mission with `controller`.
    pub fn options(&self, controller: ControllerSpec) -> SimOptions {
        SimOptions {
            plant: PlantChoice::Custom(self.params),
            ambient_c: self.ambient0_c,
            seed: self.seed,
            faults: self.faults.clone(),
            ..SimOptions::new(self.scenario.clone(), controller)
        }
    }
}

/// Reports that are warnings about the mission's own disturbances, not faults: `ssr_stuck_off`
/// (the load warms at full duty, e.g. a lid opening), `supply_sag` (the mission's scheduled
/// sag is real) and `lid_open` (its lid openings are real). None changes the control.
fn is_warning(d: Detected) -> bool {
    matches!(d, Detected::Event(EventKind::SsrStuckOff | EventKind::SupplySag | EventKind::LidOpen))
}

/// The verdict on one mission.
///
/// - **Pull-down** ends at the first sample with the true load temperature within 2–8 °C.
/// - **Judged window**: from the end of pull-down to the fault (or the end), minus
///   cold-ambient samples (ambient below [`COLD_AMBIENT_C`] now or within [`COLD_LAG_S`]). A
///   restart the board comes back from (a brown-out, a fail-safe stop: [`Fault::restarts`])
///   does not end it: the carrier after the boot is held to the same band as before.
/// - **Fails** when the load is ever below 0 °C (anywhere, faults and cold ambient included),
///   or an injected fault that showed in the run (`fault_detectable`) is not detected by the
///   end of the run, or the step reports a hardware fault that was not injected, other than
///   the warnings about the mission's own disturbances, `ssr_stuck_off`, `supply_sag` and
///   `lid_open` (a false `ssr_stuck_on` latches the modules' supply off for the rest of the
///   mission; `ssr_stuck_off` without a fault is the step warning that the load warms at full
///   duty, e.g. during a lid opening, and changes nothing in the control: reported, not a
///   failure),
///   or the judged window has more than [`OUTSIDE_TOLERANCE_S`] outside 2–8 °C not counting
///   time above 8 °C after 30 min of full cooling (the carrier's capacity: a randomized
///   carrier at 40 °C may not hold 8 °C with any controller; that time still counts in the
///   campaign's fraction outside 2–8 °C and is reported as `capacity_minutes`), or the
///   pull-down never reaches 2–8 °C (outside cold ambient).
#[derive(Clone, Debug, Serialize)]
pub struct MissionReport {
    /// The mission's seed.
    pub seed: u64,
    /// Time below 0 °C, s.
    pub freeze_s: f64,
    /// Length of the judged window, s.
    pub judged_s: f64,
    /// Time outside 2–8 °C in the judged window, s.
    pub outside_s: f64,
    /// Of `outside_s`, the time above 8 °C after at least 30 min of full cooling: the
    /// carrier's capacity, not its control (no controller can do better there).
    pub capacity_s: f64,
    /// Cold-ambient time in the judged window's span (after pull-down, before any fault but a
    /// restart), s.
    pub cold_ambient_s: f64,
    /// Of which outside 2–8 °C, s.
    pub cold_outside_s: f64,
    /// End of pull-down, s (None: never).
    pub pulldown_s: Option<f64>,
    /// Lowest true load temperature of the whole run, °C.
    pub min_c: f64,
    /// Highest true load temperature in the judged window, °C (None: empty window).
    pub max_judged_c: Option<f64>,
    /// The hardware fault: (kind, injected at s, detected at s).
    pub fault: Option<(Fault, f64, Option<f64>)>,
    /// Whether the fault showed in this run, so that its detection was due (see
    /// [`evaluate`]: a dead SSR in a cold spell that never asks for cooling does not).
    pub fault_detectable: bool,
    /// Sensor spikes: (injected at s, first report at s).
    pub spikes: Option<(f64, Option<f64>)>,
    /// The freeze margin: the lowest true load temperature after pull-down and before the
    /// hardware fault (or the end), cold-ambient samples left out, °C (`None`: no such sample).
    pub margin_c: Option<f64>,
    /// After the hardware fault, cold-ambient samples left out: the lowest true load
    /// temperature, °C, and the time below 2 °C, s.
    pub fault_min_c: Option<f64>,
    /// See [`Self::fault_min_c`].
    pub fault_below_2_s: f64,
    /// After a restart the board comes back from ([`Fault::restarts`]): the lowest and the
    /// highest true load temperature in the [`RESTART_WATCH_S`] after it, after pull-down,
    /// cold-ambient samples left out, °C (`None`: no restart, or no such sample).
    pub restart_span_c: Option<(f64, f64)>,
    /// Freeze-guard trips in the freeze margin's window (after pull-down, before the hardware
    /// fault, cold ambient left out): entries of the step into `freeze_guard` where the
    /// controller alone should have kept the load up, the supervisor acting as the first line.
    pub guard_trips: u32,
    /// Hardware-fault reports without a fault behind them (before the injected fault, or in a
    /// mission without one): (kind, first report at s), one per kind.
    pub spurious: Vec<(Detected, f64)>,
    /// Reports of another hardware fault than the injected one, after it (a misdiagnosis, which
    /// sends a technician to the wrong part): (kind, first report at s), one per kind.
    pub misreported: Vec<(Detected, f64)>,
    /// Why the mission failed (empty: passed).
    pub reasons: Vec<String>,
}

/// Judges a finished mission run (rules on [`MissionReport`]).
pub fn evaluate(m: &Mission, out: &SimOutput) -> MissionReport {
    let ts = out.ts_s;
    let t_fault = m.hardware_fault.map_or(f64::INFINITY, |(t, _)| t);
    // The judged window ends at a fault, but not at a restart the board comes back from.
    let restarted = m.hardware_fault.is_some_and(|(_, k)| k.restarts());
    let judged_until = if restarted { f64::INFINITY } else { t_fault };
    let mut freeze_s = 0.0;
    let mut judged_s = 0.0;
    let mut outside_s = 0.0;
    let mut capacity_s = 0.0;
    let mut full_run = 0u32;
    let mut cold_s = 0.0;
    let mut cold_outside_s = 0.0;
    let mut pulldown_s = None;
    let mut min_c = f64::INFINITY;
    let mut max_judged_c: Option<f64> = None;
    let (mut margin_c, mut fault_min_c, mut fault_below_2_s) = (None::<f64>, None::<f64>, 0.0);
    let mut restart_span_c: Option<(f64, f64)> = None;
    let mut last_cold = f64::NEG_INFINITY;
    let (mut guard_trips, mut guarded) = (0u32, false);
    for r in &out.rows {
        let guard = matches!(r.mode, RowMode::Step(Mode::FreezeGuard));
        let entered = guard && !guarded;
        guarded = guard;
        let t = r.true_temp_c;
        full_run = if r.duty >= 0.99 { full_run + 1 } else { 0 };
        min_c = min_c.min(t);
        if t < 0.0 {
            freeze_s += ts;
        }
        if r.ambient_c < COLD_AMBIENT_C {
            last_cold = r.t_s;
        }
        let inside = (2.0..=8.0).contains(&t);
        if pulldown_s.is_none() && inside {
            pulldown_s = Some(r.t_s);
        }
        // The freeze margin: the lowest load after pull-down outside cold ambient, before the
        // fault; after it, how low the fault took the load and for how long below 2 °C.
        if pulldown_s.is_some() && r.t_s - last_cold > COLD_LAG_S {
            let lowest = if r.t_s < t_fault { &mut margin_c } else { &mut fault_min_c };
            *lowest = Some(lowest.map_or(t, |x| x.min(t)));
            if r.t_s < t_fault && entered {
                guard_trips += 1;
            }
            if r.t_s >= t_fault && t < 2.0 {
                fault_below_2_s += ts;
            }
            if restarted && (t_fault..t_fault + RESTART_WATCH_S).contains(&r.t_s) {
                restart_span_c = Some(restart_span_c.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t))));
            }
        }
        if pulldown_s.is_none() || r.t_s >= judged_until {
            continue;
        }
        if r.t_s - last_cold <= COLD_LAG_S {
            cold_s += ts;
            if !inside {
                cold_outside_s += ts;
            }
            continue;
        }
        judged_s += ts;
        if !inside {
            outside_s += ts;
            if t > 8.0 && f64::from(full_run) * ts >= 1800.0 {
                capacity_s += ts;
            }
        }
        max_judged_c = Some(max_judged_c.map_or(t, |x| x.max(t)));
    }
    let detected = &out.metrics.faults_detected;
    let fault = m.hardware_fault.map(|(tf, kind)| {
        let at = detected.iter().find(|d| d.t_s >= tf && kind.detected_by(d.kind)).map(|d| d.t_s);
        (kind, tf, at)
    });
    // A dead SSR shows only once cooling is needed: after a fault in a cold spell that never
    // warms the load 1 °C past its setpoint there was nothing to see.
    let fault_detectable = m.hardware_fault.is_some_and(|(tf, k)| {
        match k {
            Fault::SsrStuckOff => out.rows.iter().any(|r| r.t_s >= tf && r.true_temp_c > MISSION_SETPOINT_C + 1.0),
            // A shorted SSR shows only once less than full cooling is wanted: in a heat that
            // needs full cooling and still leaves the load above its setpoint it never does.
            // Nor behind an open supply switch, where it conducts nothing: a cold spell the
            // freeze guard holds off to the end of the mission never shows it.
            Fault::SsrStuckOn => {
                out.rows.iter().any(|r| r.t_s >= tf && r.supply_enable && r.true_temp_c < MISSION_SETPOINT_C - 1.0)
            }
            // A shorted switch shows only once the step asks for a test pulse with a sample
            // after it to take it, or commands the switch open for two samples.
            Fault::SupplySwitchShort => out
                .rows
                .windows(2)
                .any(|w| w[0].t_s >= tf && (w[0].switch_test || (!w[0].supply_enable && !w[1].supply_enable))),
            _ => true,
        }
    });
    let spikes = m.spikes_s.map(|ts0| {
        (ts0, detected.iter().find(|d| d.t_s >= ts0 && Fault::SensorSpikes.detected_by(d.kind)).map(|d| d.t_s))
    });

    // A nuisance's report is expected whenever the nuisance is there: never spurious.
    let nuisances = Fault::of_class(FaultClass::Nuisance);
    let mut spurious: Vec<(Detected, f64)> = Vec::new();
    let mut misreported: Vec<(Detected, f64)> = Vec::new();
    for d in detected.iter().filter(|d| !nuisances.iter().any(|f| f.detected_by(d.kind))) {
        let list = match m.hardware_fault {
            _ if d.t_s < t_fault => &mut spurious,
            Some((_, kind)) if !kind.detected_by(d.kind) => &mut misreported,
            _ => continue,
        };
        if !list.iter().any(|(k, _)| *k == d.kind) {
            list.push((d.kind, d.t_s));
        }
    }

    let mut reasons = Vec::new();
    // `ssr_stuck_off` without a fault is the step's own warning that the load warms at full
    // duty (a lid opening or a sag in the heat): it changes nothing in the control, so it is
    // reported, not a failure. Any other spurious report puts the step in a safe state.
    for (k, t) in spurious.iter().filter(|(k, _)| !is_warning(*k)) {
        reasons.push(format!("{k} reported at {t:.0} s without a fault"));
    }
    if freeze_s > 0.0 || min_c < 0.0 {
        reasons.push(format!("load below 0 °C for {:.0} min (min {min_c:.2} °C)", freeze_s / 60.0));
    }
    if let Some((kind, tf, None)) = fault {
        if fault_detectable {
            reasons.push(format!("{} at {tf:.0} s not detected", kind.name()));
        }
    }
    if outside_s - capacity_s > OUTSIDE_TOLERANCE_S {
        reasons.push(format!(
            "{:.0} s outside 2–8 °C after pull-down, {:.0} s of it at the carrier's capacity (tolerance {OUTSIDE_TOLERANCE_S:.0} s)",
            outside_s, capacity_s
        ));
    }
    if pulldown_s.is_none() && m.ambient0_c >= COLD_AMBIENT_C && t_fault > 4.0 * 3600.0 {
        reasons.push("pull-down never reached 2–8 °C".into());
    }
    MissionReport {
        seed: m.seed,
        freeze_s,
        judged_s,
        outside_s,
        capacity_s,
        cold_ambient_s: cold_s,
        cold_outside_s,
        pulldown_s,
        min_c,
        max_judged_c,
        margin_c,
        fault_min_c,
        fault_below_2_s,
        restart_span_c,
        guard_trips,
        fault,
        fault_detectable,
        spikes,
        spurious,
        misreported,
        reasons,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn missions_stay_within_their_ranges() {
        for seed in 0..200 {
            let m = Mission::generate(seed);
            for (name, f) in &m.factors {
                assert!((0.5..=1.5).contains(f), "{seed} {name} {f}");
            }
            for (t, c) in &m.scenario.changes {
                assert!((0.0..DAY_S).contains(t), "{seed}: change at {t}");
                if let Change::Ambient(a) = c {
                    assert!((0.0..=43.0).contains(a), "{seed}: ambient {a}");
                }
            }
            if let Some((t, f)) = m.hardware_fault {
                assert!((7200.0..=22.0 * 3600.0).contains(&t) && f.spec().class != FaultClass::Nuisance);
            }
        }
        let kinds: Vec<_> = (0..1000).filter_map(|s| Mission::generate(s).hardware_fault.map(|(_, k)| k)).collect();
        let board_faults = Fault::of_class(FaultClass::Board);
        let board = kinds.iter().filter(|k| board_faults.contains(k)).count();
        let with_fault = kinds.len() - board;
        assert!((150..=250).contains(&with_fault), "{with_fault}");
        // 0.2 of the ≈ 800 missions without a hardware fault.
        assert!((120..=200).contains(&board), "{board}");
        // Every kind is drawn, and seeds give different carriers.
        let hardware = Fault::of_class(FaultClass::Hardware);
        assert!(hardware.iter().chain(&board_faults).all(|b| kinds.contains(b)));
        let mut carriers: Vec<_> = (0..200).map(|s| Mission::generate(s).params.c_water_j_per_k.to_bits()).collect();
        carriers.sort_unstable();
        carriers.dedup();
        assert_eq!(carriers.len(), 200, "two seeds drew the same carrier");
    }

    /// A restart the board comes back from (a brown-out, a fail-safe stop) does not end the
    /// judged window: the window of such a mission reaches past the fault, where any other
    /// fault's ends at it. The first missions of each kind without cold ambient.
    #[test]
    fn the_judged_window_goes_on_through_a_restart_and_ends_at_any_other_fault() {
        use crate::sim::{self, ControllerChoice, ControllerSpec};
        use hter::failsafe::StopKind;
        let kinds = [Fault::Brownout, Fault::BoardFault(StopKind::Panic), Fault::BoardFault(StopKind::ControlStall)];
        let others = [Fault::SensorOpen, Fault::FirmwareHang];
        for kind in kinds.into_iter().chain(others) {
            let m = (1..)
                .map(Mission::generate)
                .find(|m| m.hardware_fault.is_some_and(|(_, k)| k == kind) && m.ambient0_c > 15.0)
                .unwrap();
            let (tf, _) = m.hardware_fault.unwrap();
            let out = sim::run(&m.options(ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
            let r = evaluate(&m, &out);
            assert!(r.reasons.is_empty() && r.cold_ambient_s == 0.0, "mission {}: {r:?}", m.seed);
            let before_fault = tf - r.pulldown_s.unwrap();
            if kind.restarts() {
                assert!(r.judged_s > before_fault + 3600.0, "mission {} ({kind:?}): {} s judged", m.seed, r.judged_s);
            } else {
                // Up to the sample at or after the fault (faults fall between samples).
                assert!(r.judged_s <= before_fault + 10.0, "mission {} ({kind:?}): {} s judged", m.seed, r.judged_s);
            }
        }
    }
}
