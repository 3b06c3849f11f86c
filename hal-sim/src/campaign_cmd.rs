//! `hter campaign`: many randomized 24 h missions in parallel, judged against the cold-chain
//! rules (the rules are on [`crate::mission::MissionReport`]).

use std::collections::BTreeMap;
use std::io::IsTerminal;

use anyhow::{bail, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;

use crate::fault::{Fault, FaultClass};
use crate::mission::{self, Mission, MissionReport};
use crate::sim::{self, ControllerChoice, ControllerSpec};
use crate::sim_cmd::whole;

/// Most missions one campaign may run.
pub const MAX_MISSIONS: u64 = 1_000_000;

/// `hter campaign` arguments.
#[derive(clap::Args, Debug)]
pub struct CampaignArgs {
    /// Number of randomized 24 h missions.
    #[arg(long, allow_negative_numbers = true, value_parser = whole("the number of missions", 1, MAX_MISSIONS))]
    pub missions: u64,
    /// Seed of the first mission; mission i has seed S + i.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = whole("the first mission's seed", 0, u64::MAX))]
    pub seed: u64,
    /// Controller (default: the self-tuning GPC the adaptive firmware runs).
    #[arg(long, value_enum, default_value = "gpc")]
    pub controller: ControllerChoice,
    /// Print one JSON object instead of the summary table.
    #[arg(long)]
    pub json: bool,
    /// Exit non-zero (after the report) when any mission fails (for CI).
    #[arg(long)]
    pub strict: bool,
    /// How the modules are driven: ssr (the default) or buck.
    #[arg(long, value_enum, default_value = "ssr")]
    pub drive: sim::Drive,
    /// Run every mission on a board that reads the modules' voltage in the conversion window
    /// (a board change the reference board does not have; SSR drive only): a shorted SSR is
    /// found within two samples (`hter::supervisor::module`).
    #[arg(long)]
    pub module_sense: bool,
}

/// Detection figures of one injected fault kind.
#[derive(Clone, Debug, Default, Serialize)]
pub struct KindFigures {
    /// Missions that carried it.
    pub injected: u64,
    /// Of which the step reported it.
    pub detected: u64,
    /// Whether the step has a detection for it (the fault table lists the reports that count;
    /// missed detections of kinds without one would not be mission failures).
    pub detector: bool,
    /// Of the missed ones, those the fault never showed in (a dead SSR during a cold spell
    /// that never asked for cooling; see `mission::evaluate`): not failures.
    pub not_observable: u64,
    /// Longest time from injection to detection, s.
    pub max_latency_s: Option<f64>,
}

/// A failing mission.
#[derive(Clone, Debug, Serialize)]
pub struct FailureDetail {
    /// The mission's seed.
    pub seed: u64,
    /// Why it failed.
    pub reasons: Vec<String>,
    /// The command that replays it.
    pub replay: String,
}

/// The `hter campaign --json` object.
#[derive(Clone, Debug, Serialize)]
pub struct CampaignSummary {
    /// Missions run.
    pub missions: u64,
    /// Controller.
    pub controller: String,
    /// How the modules were driven (`ssr` or `buck`).
    pub drive: String,
    /// The board read the modules' voltage (`--module-sense`).
    pub module_sense: bool,
    /// Seed of the first mission.
    pub seed: u64,
    /// Total time with the load below 0 °C over all missions, min.
    pub freeze_minutes: f64,
    /// Missions with any time below 0 °C.
    pub freeze_missions: u64,
    /// Fraction of the judged time (after pull-down, before any fault but a restart the board
    /// comes back from, outside cold ambient) with the load outside 2–8 °C.
    pub fraction_outside_2_8: f64,
    /// Judged time, h.
    pub judged_hours: f64,
    /// Judged time outside 2–8 °C, min.
    pub outside_minutes: f64,
    /// Of which above 8 °C after 30 min of full cooling (the carrier's capacity), min.
    pub capacity_minutes: f64,
    /// Cold-ambient time after pull-down and before any fault (not judged), min.
    pub cold_ambient_minutes: f64,
    /// Of which outside 2–8 °C (below 2 °C: the carrier cannot heat), min.
    pub cold_ambient_outside_minutes: f64,
    /// Missions that had any cold-ambient time.
    pub cold_ambient_missions: u64,
    /// Hardware faults injected.
    pub faults_injected: u64,
    /// Of which the step reported.
    pub faults_detected: u64,
    /// Of the injected faults whose kind has a detector, the ones missed.
    pub faults_missed_with_detector: u64,
    /// Per kind.
    pub faults_by_kind: BTreeMap<String, KindFigures>,
    /// Missions in which the step reported a hardware fault that was not injected.
    pub spurious_missions: u64,
    /// Spurious reports per kind (missions).
    pub spurious_by_kind: BTreeMap<String, u64>,
    /// Missions in which the step reported, after the injected hardware fault, another one
    /// (a misdiagnosis: not a failure, the injected fault's own report is what is judged).
    pub misreported_missions: u64,
    /// Those reports per injected fault and reported kind, `"fault → kind"` (missions).
    pub misreported_by_kind: BTreeMap<String, u64>,
    /// Missions with sensor spikes (not a hardware fault).
    pub spikes_injected: u64,
    /// Of which the step reported spikes.
    pub spikes_reported: u64,
    /// Lowest true load temperature of any mission, anywhere, °C.
    pub worst_min_c: f64,
    /// Highest true load temperature in any judged window, °C.
    pub worst_max_c: f64,
    /// The freeze margin: over the missions without a hardware fault, the lowest true load
    /// temperature after pull-down outside cold ambient, °C (`None`: no such sample), and the
    /// mission it was in.
    pub fault_free_min_c: Option<f64>,
    /// See [`Self::fault_free_min_c`].
    pub fault_free_min_seed: Option<u64>,
    /// Over the missions with a hardware fault, after it and outside cold ambient: the lowest
    /// true load temperature, °C, and the mission it was in…
    pub fault_min_c: Option<f64>,
    /// See [`Self::fault_min_c`].
    pub fault_min_seed: Option<u64>,
    /// …the longest time below 2 °C in one mission, s, and all of it, min.
    pub fault_below_2_max_s: f64,
    /// See [`Self::fault_below_2_max_s`].
    pub fault_below_2_minutes: f64,
    /// The hour after a restart the board comes back from (a brown-out, a fail-safe stop;
    /// [`MissionReport::restart_span_c`]): the missions watched, and the lowest and the highest
    /// true load temperature over them, °C, with the mission each was in.
    pub restart_missions: u64,
    /// See [`Self::restart_missions`].
    pub restart_min_c: Option<f64>,
    /// See [`Self::restart_missions`].
    pub restart_min_seed: Option<u64>,
    /// See [`Self::restart_missions`].
    pub restart_max_c: Option<f64>,
    /// See [`Self::restart_missions`].
    pub restart_max_seed: Option<u64>,
    /// Freeze-guard trips after pull-down, before any hardware fault and outside cold ambient
    /// ([`MissionReport::guard_trips`]), over all missions, and the missions that had one.
    pub guard_trips: u64,
    /// See [`Self::guard_trips`].
    pub guard_trip_missions: u64,
    /// Those missions' seeds, to replay with `hter sim --mission-seed N --csv F` (the `mode`
    /// column shows each trip).
    pub guard_trip_seeds: Vec<u64>,
    /// Missions whose pull-down took longest, s (None if none ended).
    pub longest_pulldown_s: Option<f64>,
    /// Seeds of the failing missions.
    pub failures: Vec<u64>,
    /// Why each failed and how to replay it.
    pub failure_details: Vec<FailureDetail>,
    /// Wall time of the campaign, s.
    pub wall_s: f64,
}

/// The replay command of one mission: the same seed, controller, drive and board (`--drive`
/// and `--module-sense` are named only when they are not the reference board's, so its lines
/// read as they always did).
pub fn replay_command(seed: u64, controller: ControllerChoice, drive: sim::Drive, module_sense: bool) -> String {
    let c = clap::ValueEnum::to_possible_value(&controller).map_or("gpc".to_string(), |v| v.get_name().to_string());
    let d = match drive {
        sim::Drive::Ssr => String::new(),
        other => format!(" --drive {}", other.name()),
    };
    let m = if module_sense { " --module-sense" } else { "" };
    format!("hter sim --mission-seed {seed} --controller {c}{d}{m} --json")
}

/// Runs one mission on the reference board and judges it.
pub fn run_mission(seed: u64, controller: ControllerChoice) -> Result<MissionReport> {
    run_mission_on(seed, controller, sim::Drive::Ssr, false)
}

/// Runs one mission with the modules on `drive`, on a board with the module-side sense if
/// `module_sense`, and judges it.
pub fn run_mission_on(
    seed: u64,
    controller: ControllerChoice,
    drive: sim::Drive,
    module_sense: bool,
) -> Result<MissionReport> {
    let m = Mission::generate(seed);
    let out = sim::run(&sim::SimOptions { drive, module_sense, ..m.options(ControllerSpec::new(controller)) })?;
    Ok(mission::evaluate(&m, &out))
}

/// Summarizes judged missions run with `controller` on `drive`.
pub fn summarize(
    reports: &[MissionReport],
    controller: ControllerChoice,
    drive: sim::Drive,
    module_sense: bool,
    seed: u64,
    wall_s: f64,
) -> CampaignSummary {
    let mut by_kind: BTreeMap<String, KindFigures> = Fault::ALL
        .into_iter()
        .filter(|f| f.spec().class != FaultClass::Nuisance)
        .map(|f| {
            (f.name().to_string(), KindFigures { detector: !f.spec().detected_by.is_empty(), ..Default::default() })
        })
        .collect();
    let sum = |f: &dyn Fn(&MissionReport) -> f64| reports.iter().map(f).sum::<f64>();
    let judged_s = sum(&|r| r.judged_s);
    let outside_s = sum(&|r| r.outside_s);
    let mut failures = Vec::new();
    let mut details = Vec::new();
    for r in reports {
        if let Some((kind, t, at)) = r.fault {
            let k = by_kind.entry(kind.name().to_string()).or_default();
            k.injected += 1;
            if let Some(at) = at {
                k.detected += 1;
                k.max_latency_s = Some(k.max_latency_s.map_or(at - t, |x: f64| x.max(at - t)));
            } else if k.detector && !r.fault_detectable {
                k.not_observable += 1;
            }
        }
        if !r.reasons.is_empty() {
            failures.push(r.seed);
            details.push(FailureDetail {
                seed: r.seed,
                reasons: r.reasons.clone(),
                replay: replay_command(r.seed, controller, drive, module_sense),
            });
        }
    }
    let faults_injected = by_kind.values().map(|k| k.injected).sum();
    let faults_detected = by_kind.values().map(|k| k.detected).sum();
    let faults_missed_with_detector =
        by_kind.values().filter(|k| k.detector).map(|k| k.injected - k.detected - k.not_observable).sum();
    // The (temperature, seed) of `f` over `reports` that `first` puts first: the lowest with
    // `f64::lt`, the highest with `f64::gt`; the earliest mission of equal ones.
    let extreme = |f: &dyn Fn(&MissionReport) -> Option<f64>, first: fn(&f64, &f64) -> bool| {
        reports.iter().filter_map(|r| f(r).map(|c| (c, r.seed))).reduce(|a, b| if first(&b.0, &a.0) { b } else { a })
    };
    let lowest = |f: &dyn Fn(&MissionReport) -> Option<f64>| extreme(f, f64::lt);
    let free_min = lowest(&|r| if r.fault.is_none() { r.margin_c } else { None });
    let fault_min = lowest(&|r| r.fault_min_c);
    let restart_min = lowest(&|r| r.restart_span_c.map(|(lo, _)| lo));
    let restart_max = extreme(&|r| r.restart_span_c.map(|(_, hi)| hi), f64::gt);
    CampaignSummary {
        missions: reports.len() as u64,
        controller: format!("{controller:?}").to_lowercase(),
        drive: drive.name().to_string(),
        module_sense,
        seed,
        freeze_minutes: sum(&|r| r.freeze_s) / 60.0,
        freeze_missions: reports.iter().filter(|r| r.freeze_s > 0.0).count() as u64,
        fraction_outside_2_8: if judged_s > 0.0 { outside_s / judged_s } else { 0.0 },
        judged_hours: judged_s / 3600.0,
        outside_minutes: outside_s / 60.0,
        capacity_minutes: sum(&|r| r.capacity_s) / 60.0,
        cold_ambient_minutes: sum(&|r| r.cold_ambient_s) / 60.0,
        cold_ambient_outside_minutes: sum(&|r| r.cold_outside_s) / 60.0,
        cold_ambient_missions: reports.iter().filter(|r| r.cold_ambient_s > 0.0).count() as u64,
        faults_injected,
        faults_detected,
        faults_missed_with_detector,
        faults_by_kind: by_kind,
        spurious_missions: reports.iter().filter(|r| !r.spurious.is_empty()).count() as u64,
        spurious_by_kind: tally(reports.iter().flat_map(|r| r.spurious.iter().map(|(k, _)| k.name().to_string()))),
        misreported_missions: reports.iter().filter(|r| !r.misreported.is_empty()).count() as u64,
        misreported_by_kind: tally(
            reports
                .iter()
                .filter_map(|r| r.fault.map(|(f, _, _)| (f, &r.misreported)))
                .flat_map(|(f, list)| list.iter().map(move |(k, _)| format!("{} → {}", f.name(), k.name()))),
        ),
        spikes_injected: reports.iter().filter(|r| r.spikes.is_some()).count() as u64,
        spikes_reported: reports.iter().filter(|r| matches!(r.spikes, Some((_, Some(_))))).count() as u64,
        worst_min_c: reports.iter().map(|r| r.min_c).fold(f64::INFINITY, f64::min),
        worst_max_c: reports.iter().filter_map(|r| r.max_judged_c).fold(f64::NEG_INFINITY, f64::max),
        fault_free_min_c: free_min.map(|(c, _)| c),
        fault_free_min_seed: free_min.map(|(_, s)| s),
        fault_min_c: fault_min.map(|(c, _)| c),
        fault_min_seed: fault_min.map(|(_, s)| s),
        fault_below_2_max_s: reports.iter().map(|r| r.fault_below_2_s).fold(0.0, f64::max),
        fault_below_2_minutes: sum(&|r| r.fault_below_2_s) / 60.0,
        restart_missions: reports.iter().filter(|r| r.restart_span_c.is_some()).count() as u64,
        restart_min_c: restart_min.map(|(c, _)| c),
        restart_min_seed: restart_min.map(|(_, s)| s),
        restart_max_c: restart_max.map(|(c, _)| c),
        restart_max_seed: restart_max.map(|(_, s)| s),
        guard_trips: reports.iter().map(|r| u64::from(r.guard_trips)).sum(),
        guard_trip_missions: reports.iter().filter(|r| r.guard_trips > 0).count() as u64,
        guard_trip_seeds: reports.iter().filter(|r| r.guard_trips > 0).map(|r| r.seed).collect(),
        longest_pulldown_s: reports.iter().filter_map(|r| r.pulldown_s).reduce(f64::max),
        failures,
        failure_details: details,
        wall_s,
    }
}

/// How many times each key occurs.
fn tally(keys: impl Iterator<Item = String>) -> BTreeMap<String, u64> {
    keys.fold(BTreeMap::new(), |mut m, key| {
        *m.entry(key).or_insert(0) += 1;
        m
    })
}

/// The seed of the last of `missions` missions from `seed` (seed + missions − 1), `None` when
/// it does not fit 64 bits or there are no missions. (seed + missions overflowed one seed early:
/// the last two seeds could not be run.)
pub fn last_seed(seed: u64, missions: u64) -> Option<u64> {
    seed.checked_add(missions.checked_sub(1)?)
}

/// `hter campaign`.
pub fn run(a: &CampaignArgs) -> Result<()> {
    if a.module_sense && a.drive == sim::Drive::Buck {
        bail!("{}", crate::sim_cmd::MODULE_SENSE_SSR_ONLY);
    }
    if a.missions == 0 {
        bail!("--missions must be at least 1");
    }
    if a.missions > MAX_MISSIONS {
        bail!("--missions must be at most {MAX_MISSIONS}, got {}", a.missions);
    }
    if last_seed(a.seed, a.missions).is_none() {
        bail!(
            "--seed {} with --missions {}: the last mission's seed (seed + missions − 1) overflows a 64-bit seed",
            a.seed,
            a.missions
        );
    }
    let start = std::time::Instant::now();
    let pb = if a.json || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        let pb = ProgressBar::with_draw_target(Some(a.missions), ProgressDrawTarget::stderr());
        if let Ok(style) = ProgressStyle::with_template("{bar:40} {pos}/{len} missions  {elapsed} (eta {eta})") {
            pb.set_style(style);
        }
        pb
    };
    let controller = a.controller;
    let reports: Vec<MissionReport> = (0..a.missions)
        .into_par_iter()
        .map(|i| {
            let r = run_mission_on(a.seed + i, controller, a.drive, a.module_sense);
            pb.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    pb.finish_and_clear();
    let s = summarize(&reports, controller, a.drive, a.module_sense, a.seed, start.elapsed().as_secs_f64());
    if a.json {
        println!("{}", serde_json::to_string(&s)?);
        for f in &s.failure_details {
            eprintln!("mission {} failed ({}); replay: {}", f.seed, f.reasons.join("; "), f.replay);
        }
    } else {
        print_table(&s);
    }
    if a.strict && !s.failures.is_empty() {
        bail!("{} of {} missions failed (seeds {:?})", s.failures.len(), s.missions, s.failures);
    }
    Ok(())
}

fn print_table(s: &CampaignSummary) {
    println!(
        "campaign: {} randomized 24 h missions (seeds {}…{}), controller {}, {} drive{}, {:.1} s wall",
        s.missions,
        s.seed,
        last_seed(s.seed, s.missions).unwrap_or(u64::MAX),
        s.controller,
        s.drive,
        if s.module_sense { ", module-side sense" } else { "" },
        s.wall_s
    );
    println!();
    println!("| figure | value |");
    println!("| --- | --- |");
    println!("| minutes below 0 °C (all missions) | {:.1} ({} missions) |", s.freeze_minutes, s.freeze_missions);
    println!("| lowest load temperature | {:.2} °C |", s.worst_min_c);
    println!(
        "| highest load temperature after pull-down, before faults (restarts judged through) | {:.2} °C |",
        s.worst_max_c
    );
    if let (Some(c), Some(seed)) = (s.fault_free_min_c, s.fault_free_min_seed) {
        println!("| freeze margin: lowest load after pull-down, fault-free missions, warm ambient | {c:.2} °C (mission {seed}) |");
    }
    println!(
        "| freeze-guard trips after pull-down, before faults, warm ambient | {} in {} missions {:?} |",
        s.guard_trips, s.guard_trip_missions, s.guard_trip_seeds
    );
    if let (Some(c), Some(seed)) = (s.fault_min_c, s.fault_min_seed) {
        println!(
            "| after a hardware fault, warm ambient: lowest load, time below 2 °C | {c:.2} °C (mission {seed}); {:.1} min in all, at most {:.0} s in one mission |",
            s.fault_below_2_minutes, s.fault_below_2_max_s
        );
    }
    if let (Some(lo), Some(lo_seed), Some(hi), Some(hi_seed)) =
        (s.restart_min_c, s.restart_min_seed, s.restart_max_c, s.restart_max_seed)
    {
        println!(
            "| the hour after a restart (brown-out, fail-safe stop), warm ambient: lowest / highest load | {lo:.2} °C (mission {lo_seed}) / {hi:.2} °C (mission {hi_seed}), {} missions |",
            s.restart_missions
        );
    }
    println!(
        "| outside 2–8 °C after pull-down, before faults (restarts judged through) | {:.4} % ({:.1} min of {:.0} h; {:.1} min above 8 °C at full cooling for 30 min: capacity) |",
        100.0 * s.fraction_outside_2_8,
        s.outside_minutes,
        s.judged_hours,
        s.capacity_minutes
    );
    println!(
        "| cold ambient (< {} °C, not judged) | {:.0} min in {} missions, {:.0} min of it outside 2–8 °C |",
        mission::COLD_AMBIENT_C,
        s.cold_ambient_minutes,
        s.cold_ambient_missions,
        s.cold_ambient_outside_minutes
    );
    println!("| hardware faults detected | {} of {} |", s.faults_detected, s.faults_injected);
    println!(
        "| hardware faults reported without a fault | {} missions {:?} |",
        s.spurious_missions, s.spurious_by_kind
    );
    println!(
        "| another fault reported after the injected one | {} missions {:?} |",
        s.misreported_missions, s.misreported_by_kind
    );
    println!("| sensor spikes reported | {} of {} missions |", s.spikes_reported, s.spikes_injected);
    println!("| failing missions | {} |", s.failures.len());
    println!();
    println!("| fault kind | injected | detected | never showed | detector in the library | worst latency (s) |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for (name, k) in &s.faults_by_kind {
        println!(
            "| {name} | {} | {} | {} | {} | {} |",
            k.injected,
            k.detected,
            k.not_observable,
            if k.detector { "yes" } else { "no" },
            k.max_latency_s.map_or("–".to_string(), |l| format!("{l:.0}"))
        );
    }
    if s.cold_ambient_minutes > 0.0 {
        println!();
        println!(
            "note: the carrier only cools; below {} °C ambient it cannot keep the load above 2 °C. That",
            mission::COLD_AMBIENT_C
        );
        println!("time is reported above and not judged; on a real carrier the recorder's alarms still apply.");
    }
    for f in &s.failure_details {
        println!();
        println!("FAILED mission {}: {}", f.seed, f.reasons.join("; "));
        println!("  replay: {}", f.replay);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_seed_is_seed_plus_missions_minus_one() {
        assert_eq!(last_seed(1, 3), Some(3));
        assert_eq!(last_seed(u64::MAX, 1), Some(u64::MAX));
        assert_eq!(last_seed(u64::MAX - 1, 2), Some(u64::MAX));
        assert_eq!(last_seed(u64::MAX - 1, 3), None);
        assert_eq!(last_seed(u64::MAX, 2), None);
        assert_eq!(last_seed(5, 0), None);
    }

    #[test]
    fn the_replay_command_names_the_drive_it_ran_on() {
        assert_eq!(
            replay_command(116, ControllerChoice::Pi, sim::Drive::Ssr, false),
            "hter sim --mission-seed 116 --controller pi --json"
        );
        assert_eq!(
            replay_command(7, ControllerChoice::Gpc, sim::Drive::Buck, false),
            "hter sim --mission-seed 7 --controller gpc --drive buck --json"
        );
        assert_eq!(
            replay_command(9, ControllerChoice::Gpc, sim::Drive::Ssr, true),
            "hter sim --mission-seed 9 --controller gpc --module-sense --json"
        );
    }
}
