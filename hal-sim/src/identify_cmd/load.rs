//! Reading a log and pre-processing it for identification (steps 1–5 of the module docs of
//! [`super`]): columns, time axis, decimation, output filter, operating point, prefilter.

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use hter::filter::{FirstOrder, FirstOrderConfig};
use serde::Serialize;

use super::args::OperatingPointChoice;
use crate::log;
use crate::sim_cmd::shown;

/// The operating point removed.
#[derive(Clone, Debug, Serialize)]
pub struct OperatingPoint {
    /// How it was taken (`initial` or `mean`; `auto` resolves to one of them).
    pub kind: OperatingPointChoice,
    /// Why, in words.
    pub why: String,
    /// Output there, °C.
    pub temp_c: f64,
    /// Input there, duty.
    pub duty: f64,
    /// Samples averaged for the output.
    pub samples: usize,
}

/// The data after pre-processing.
#[derive(Clone, Debug)]
pub struct Data {
    /// Sample period, s.
    pub ts_s: f64,
    /// Time of each sample, s.
    pub t: Vec<f64>,
    /// Output deviation, °C.
    pub y: Vec<f64>,
    /// Input deviation, duty.
    pub u: Vec<f64>,
    /// Output deviation prefiltered for the estimation (= `y` without `--prefilter`).
    pub y_est: Vec<f64>,
    /// Input deviation prefiltered for the estimation (= `u` without `--prefilter`).
    pub u_est: Vec<f64>,
    /// Operating point removed.
    pub op: OperatingPoint,
}

/// Checks that the times increase with a uniform period; returns the period (median interval).
fn check_time_axis(path: &Path, t: &[f64]) -> Result<f64> {
    log::check_increasing(path, t)?;
    if t.len() < 2 {
        bail!("'{}' has {} data rows; identification needs many more", path.display(), t.len());
    }
    let mut dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let ts = dts[dts.len() / 2];
    if let Some(i) = t.windows(2).position(|w| ((w[1] - w[0]) - ts).abs() > 0.05 * ts) {
        // Interval from data row i to row i + 1; data row k is on line k + 2.
        bail!(
            "'{}' line {}: t_s steps by {} s but the sample period is {} s; identification needs a uniform period (resample the log first)",
            path.display(),
            i + 3,
            t[i + 1] - t[i],
            ts
        );
    }
    Ok(ts)
}

/// Refuses, with its line, a duty outside [0, 1] (the SSR's on-fraction: one row of 1e30 gave a
/// fit and exit 0) and a temperature no Pt100 can report (outside IEC 60751's −200…850 °C) in
/// an output column of °C (`*_c`; `--y-column` may name another quantity).
fn check_physical(path: &Path, duty: &[f64], y_column: &str, y: &[f64]) -> Result<()> {
    // Data row i is on line i + 2.
    if let Some((i, d)) = duty.iter().enumerate().find(|(_, d)| !(0.0..=1.0).contains(*d)) {
        bail!("'{}' line {}, column 'duty': {} is outside 0…1", path.display(), i + 2, shown(*d));
    }
    if y_column.ends_with("_c") {
        let (lo, hi) = (f64::from(hter::rtd::T_MIN_C), f64::from(hter::rtd::T_MAX_C));
        if let Some((i, t)) = y.iter().enumerate().find(|(_, t)| !(lo..=hi).contains(*t)) {
            bail!(
                "'{}' line {}, column '{y_column}': {} °C is outside the Pt100 range of IEC 60751 ({lo}…{hi} °C)",
                path.display(),
                i + 2,
                shown(*t)
            );
        }
    }
    Ok(())
}

/// Largest output drift during the initial constant-duty segment for the log to count as
/// starting at rest, as a fraction of the record's output range. The real heater logs drift
/// 0 % and 0.7 % (quantisation), a log that starts with the excitation already on ≈ 35 %.
const REST_DRIFT_FRACTION: f64 = 0.05;

/// The operating point of `y`, `u` (before removal).
fn operating_point(kind: OperatingPointChoice, y: &[f64], u: &[f64]) -> OperatingPoint {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    // The initial segment: the duty keeps its first value (at most 10 % of the record).
    let u0 = u.first().copied().unwrap_or(0.0);
    let rest = u.iter().take_while(|v| **v == u0).count();
    let samples = rest.min(y.len() / 10).max(1).min(y.len());
    let seg = &y[..samples];
    let third = (samples / 3).max(1);
    let drift = (mean(&seg[samples - third..]) - mean(&seg[..third])).abs();
    let range = y.iter().copied().fold(f64::NEG_INFINITY, f64::max) - y.iter().copied().fold(f64::INFINITY, f64::min);
    let at_rest = samples >= 5 && drift <= REST_DRIFT_FRACTION * range;
    let initial =
        |why: String| OperatingPoint { kind: OperatingPointChoice::Initial, why, temp_c: mean(seg), duty: u0, samples };
    let means = |why: String| OperatingPoint {
        kind: OperatingPointChoice::Mean,
        why,
        temp_c: mean(y),
        duty: mean(u),
        samples: y.len(),
    };
    let rest_note = format!(
        "the output drifts {drift:.3} °C over the first {samples} samples at constant duty, {:.1} % of its range",
        100.0 * drift / range.max(f64::MIN_POSITIVE)
    );
    match kind {
        OperatingPointChoice::Initial => initial(format!("asked for; {rest_note}")),
        OperatingPointChoice::Mean => means("asked for".into()),
        OperatingPointChoice::Auto if at_rest => initial(format!("the log starts at rest: {rest_note}")),
        OperatingPointChoice::Auto => means(format!("the log does not start at rest: {rest_note}")),
    }
}

/// A first-order filter configuration from a command-line value, or a one-line error naming
/// the flag. The filter runs in f32, as on the board: a value that rounds to 1 there
/// (0.99999999999) is refused as what it becomes, not as what was typed.
fn first_order_cfg(flag: &str, fa: Option<f64>) -> Result<Option<FirstOrderConfig>> {
    fa.map(|fa| {
        let single = fa as f32;
        FirstOrderConfig::new(single).filter(|_| fa.is_finite()).ok_or_else(|| {
            if fa.is_finite() && f64::from(single) != fa && (0.0..1.0).contains(&fa) {
                anyhow!("--{flag} must be in [0, 1), got {fa}, which is {single} in the filter's f32 arithmetic (at most {})", 1.0 - f32::EPSILON / 2.0)
            } else {
                anyhow!("--{flag} must be in [0, 1), got {}", shown(fa))
            }
        })
    })
    .transpose()
}

/// `x` through the first-order filter (initialised at the first sample).
fn first_order(cfg: &FirstOrderConfig, x: &[f64]) -> Vec<f64> {
    let mut f = FirstOrder::default();
    x.iter().map(|v| f64::from(f.step(cfg, *v as f32))).collect()
}

/// Reads and pre-processes a log (steps 1–5 of the module docs of [`super`]).
pub fn load(
    path: &Path,
    y_column: &str,
    filter: Option<f64>,
    prefilter: Option<f64>,
    decimate: usize,
    op: OperatingPointChoice,
) -> Result<Data> {
    if decimate == 0 {
        bail!("--decimate must be at least 1");
    }
    let filter_cfg = first_order_cfg("filter", filter)?;
    let prefilter_cfg = first_order_cfg("prefilter", prefilter)?;
    // Opening a directory succeeds; reading it failed as "line 1: Is a directory".
    if path.is_dir() {
        bail!("cannot read '{}': is a directory", path.display());
    }
    let cols = log::read_columns(path, &["t_s", "duty", y_column])?;
    let ts_raw = check_time_axis(path, &cols[0])?;
    check_physical(path, &cols[1], y_column, &cols[2])?;
    // A record whose input or output never moves says nothing about the dynamics, yet output
    // error and RLS fitted it: gains of 1e12 °C per unit duty from a constant duty, a "stable"
    // model with no fit from a constant temperature.
    for (col, name, what) in [(&cols[1], "duty", "input"), (&cols[2], y_column, "output")] {
        if let Some(&v0) = col.first().filter(|&&v0| col.iter().all(|&v| v == v0)) {
            bail!(
                "'{}': {name} is {v0} in every row: identification needs the {what} ({name}) to change during the record",
                path.display()
            );
        }
    }
    let avg =
        |v: &[f64]| -> Vec<f64> { v.chunks_exact(decimate).map(|c| c.iter().sum::<f64>() / decimate as f64).collect() };
    // The operating point is a level: found on the raw samples (where the initial rest is
    // longest), then removed from the decimated and filtered ones.
    let op = operating_point(op, &cols[2], &cols[1]);
    let t: Vec<f64> = cols[0].chunks_exact(decimate).map(|c| c[0]).collect();
    let (u, y) = (avg(&cols[1]), avg(&cols[2]));
    if y.is_empty() {
        bail!("'{}' has {} data rows, fewer than --decimate {decimate}", path.display(), cols[0].len());
    }
    let y = match &filter_cfg {
        Some(cfg) => first_order(cfg, &y),
        None => y,
    };
    let y: Vec<f64> = y.iter().map(|v| v - op.temp_c).collect();
    let u: Vec<f64> = u.iter().map(|v| v - op.duty).collect();
    let (y_est, u_est) = match &prefilter_cfg {
        Some(cfg) => (first_order(cfg, &y), first_order(cfg, &u)),
        None => (y.clone(), u.clone()),
    };
    Ok(Data { ts_s: ts_raw * decimate as f64, t, y, u, y_est, u_est, op })
}

#[cfg(test)]
mod tests {
    use super::super::test_logs::{synthetic_log, write};
    use super::*;

    #[test]
    fn operating_point_is_the_initial_rest_only_when_the_log_starts_at_rest() {
        let log = write("rest", &synthetic_log(600));
        let d = load(&log, "temp_c", None, None, 1, OperatingPointChoice::Auto).unwrap();
        assert_eq!(d.op.kind, OperatingPointChoice::Initial, "{}", d.op.why);
        assert_eq!(d.op.samples, 20);
        // A ramp while the duty holds still is not rest.
        let ramp_y: Vec<f64> = (0..100).map(|t| if t < 30 { t as f64 } else { 30.0 }).collect();
        let ramp_u: Vec<f64> = (0..100).map(|t| if t < 30 { 0.2 } else { 0.5 }).collect();
        let op = operating_point(OperatingPointChoice::Auto, &ramp_y, &ramp_u);
        assert_eq!(op.kind, OperatingPointChoice::Mean, "{}", op.why);
        assert!(op.why.contains("does not start at rest"));
        let flat_y: Vec<f64> = (0..100).map(|t| if t < 30 { 1.0 } else { 30.0 }).collect();
        let op = operating_point(OperatingPointChoice::Auto, &flat_y, &ramp_u);
        assert_eq!((op.kind, op.temp_c, op.duty, op.samples), (OperatingPointChoice::Initial, 1.0, 0.2, 10));
    }
}
