//! `hter monitor`: the cold-chain record of any CSV log (SPEC §3, §6), computed by the same
//! library monitor the firmware runs.

use std::path::PathBuf;

use anyhow::{bail, Result};
use hter::coldchain::ColdChainMonitor;
use serde::Serialize;

use crate::log;

/// Arguments of `hter monitor`.
#[derive(clap::Args, Debug, Clone)]
pub struct MonitorArgs {
    /// CSV log with columns t_s and temp_c.
    #[arg(long)]
    pub input: PathBuf,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// One alarm of the report.
#[derive(Debug, Serialize, PartialEq)]
pub struct AlarmOut {
    /// Kind (`heat_10h`, `freeze_60min`, `ship_45c_1h`, `ship_30c_10h`).
    pub kind: &'static str,
    /// Start of the qualifying run, s.
    pub start_s: f64,
    /// Trigger time, s.
    pub trigger_s: f64,
}

/// The `--json` report.
#[derive(Debug, Serialize)]
pub struct Report {
    /// Alarms raised.
    pub alarms: Vec<AlarmOut>,
    /// Mean kinetic temperature, °C.
    pub mkt_c: f64,
    /// Lowest temperature, °C.
    pub min_c: f64,
    /// Highest temperature, °C.
    pub max_c: f64,
    /// Time below +2 °C, s.
    pub time_below_2_s: f64,
    /// Time above +8 °C, s.
    pub time_above_8_s: f64,
    /// Number of excursions outside 2–8 °C.
    pub excursions: u32,
}

/// Runs the monitor over a log.
pub fn report(t: &[f64], temp: &[f64]) -> Result<Report> {
    if t.len() < 2 {
        bail!("the log needs at least 2 samples, it has {}", t.len());
    }
    let mut m = ColdChainMonitor::new();
    let mut alarms = Vec::new();
    // The monitor's clock is integer ms, from 0 or from the first sample if that is earlier.
    let t0 = t.first().copied().unwrap_or(0.0).min(0.0);
    for (&ts, &c) in t.iter().zip(temp) {
        for a in m.push(((ts - t0) * 1000.0).round() as u64, c as f32).into_iter().flatten() {
            alarms.push(AlarmOut { kind: a.kind.name(), start_s: a.start_s() + t0, trigger_s: a.trigger_s() + t0 });
        }
    }
    let f = |x: Option<f32>| x.map_or(f64::NAN, f64::from);
    Ok(Report {
        alarms,
        mkt_c: f(m.mkt_c()),
        min_c: f(m.min_c()),
        max_c: f(m.max_c()),
        time_below_2_s: m.time_below_2_ms() as f64 / 1000.0,
        time_above_8_s: m.time_above_8_ms() as f64 / 1000.0,
        excursions: m.excursion_count(),
    })
}

/// `hter monitor`.
pub fn run(args: &MonitorArgs) -> Result<()> {
    let cols = log::read_columns(&args.input, &["t_s", "temp_c"])?;
    log::check_increasing(&args.input, &cols[0])?;
    if cols[0].last().is_some_and(|&t| t > 16_000_000.0) {
        bail!("'{}': t_s beyond 16e6 s (185 days) is not supported", args.input.display());
    }
    let r = report(&cols[0], &cols[1])?;
    if args.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    let hours = |s: f64| s / 3600.0;
    println!("cold-chain record of {} ({} samples)", args.input.display(), cols[0].len());
    println!("  mean kinetic temperature  {:7.2} °C  (WHO: must lie within 2–8 °C)", r.mkt_c);
    println!("  min / max                 {:7.2} / {:.2} °C", r.min_c, r.max_c);
    println!("  time below +2 °C          {:7.2} h", hours(r.time_below_2_s));
    println!("  time above +8 °C          {:7.2} h", hours(r.time_above_8_s));
    println!("  excursions outside 2–8 °C {:7}", r.excursions);
    if r.alarms.is_empty() {
        println!("  alarms                    none");
    }
    for a in &r.alarms {
        println!("  ALARM {:<14} started at {:.0} s, triggered at {:.0} s", a.kind, a.start_s, a.trigger_s);
    }
    Ok(())
}
