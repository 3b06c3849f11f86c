//! `hter identify`: fit an ARX/ARMAX model to a logged run (SPEC §3; seed chapter 4).
//!
//! `hter identify --input prbs.csv` (the defaults `--method oe --nk auto --operating-point
//! auto`) answers the seed's question — which order does the carrier need? — by the criterion
//! the answer is judged on, the simulated fit: output error, each order at its best delay, from
//! the rest the log starts at. On `hter sim --scenario prbs` runs it finds 2nd order within
//! 1.1 (H-TER I) and 0.3 (H-TER II) points of 4th and 10.0 and 3.5 points above 1st, and
//! chooses 2.
//!
//! Pipeline:
//!
//! 1. Read `t_s`, `duty` (input u) and `temp_c` (output y; `--y-column` picks another) from the
//!    CSV ([`crate::log::read_columns`]: columns by name, one-line errors with line numbers).
//! 2. Check the time axis: strictly increasing, and uniform — every interval within 5 % of the
//!    median interval, which is the sample period Ts. The first offending line is named.
//! 3. Optionally average every `--decimate` samples into one (logs sampled much faster than
//!    the plant moves, where quantisation noise dominates every single step).
//! 4. Optionally filter the output with the firmware's first-order filter
//!    `y_f(t) = F_a y_f(t−1) + (1 − F_a) y(t)` (`--filter F_a`, [`hter::filter::FirstOrder`]).
//!    Only y is filtered, as in the measurement chain: the model then describes duty → filtered
//!    temperature, which is what the controller sees.
//!    `--prefilter L` is different: the same low-pass L(q) = (1 − L)/(1 − L q⁻¹) on both u and
//!    y, for the estimation only (Ljung 1999, §14.4 "prefiltering"). Since L commutes with A and
//!    B, the model is unchanged, but the equation-error fit is weighted toward the slow dynamics
//!    that matter for control instead of the sample-to-sample detail (quantisation noise) ARX
//!    otherwise favours. MSE, fit and residuals are computed on the unprefiltered data.
//! 5. Deviation variables around an operating point (y0, u0) ([`OperatingPointChoice`]). The
//!    default is the **initial rest**: u0 = u(0) and y0 = the mean of y while the duty keeps its
//!    initial value (at most the first 10 % of the record). An identification experiment
//!    starts at steady state, so that point is an equilibrium of the plant and the offset-free
//!    model `A ỹ = q^−nk B ũ` holds exactly. The record means are *not* an equilibrium when the
//!    record is a transient (a step response never averages to a steady state): the leftover
//!    constant in `A ỹ = B ũ + d`, divided by A(1) ≈ 1e-3 of a slow plant, wrecks the static
//!    gain and the simulated fit (on `tclab-heater-step.csv`: fit ≈ 96 % from the initial
//!    rest, ≈ 0 % around the means). `--operating-point mean` remains for logs that do not start
//!    at rest (e.g. a long closed-loop record around a setpoint).
//! 6. Estimate (`--method`):
//!    - `oe` (default): **output error**, minimising V = Σ (y − q^−nk B/A u)², the error of the
//!      model simulated from the input alone ([`hter::ident::oe`]: Levenberg–Marquardt with the
//!      gradient ψ = φ_x/A, Ljung 1999 §10.2–10.3; A kept stable). Equation-error methods
//!      (LS, RLS, IV) minimise A y − B u, which weights the fit by |A(e^{iω})|², a high-pass on
//!      this slow plant (Ljung §8.5): on the H-TER I PRBS run IV's 2nd-order model simulates at
//!      66 % where OE's reaches 95 %. V is not convex, so the search starts from the IV and LS
//!      estimates, the same structure at the neighbouring delay, and the lower-order OE model
//!      (order 4 from 2, 2 from 1) both as it is and with an extra pole at 0.5/0.8/0.95/0.98
//!      and the B that fits best for those poles; every start gets 6 iterations, the best 2
//!      run to convergence, and the lowest V wins (Ljung §10.5). Since one start is the
//!      lower-order model itself, each order fits at least as well as the one below it (up to
//!      the few initial samples taken from the record). ARX structure only (nc = 0); f64, on
//!      the host.
//!    - `ls`, `iv`: batch least squares and instrumental variables in f64
//!      ([`hter::ident::batch`]).
//!    - `rls`, `rels`: the firmware's f32 estimators (RLS for ARX, RELS for ARMAX, with
//!      forgetting λ_f; [`hter::ident::recursive::run`]) on signals scaled to order one
//!      (ỹ / max|ỹ|, ũ / max|ũ|; b is scaled back afterwards); the reported parameters are the
//!      final estimates θ(N).
//!
//!    The delay (`--nk`): a number of samples 1–10, or `auto` (default): the structure is fitted
//!    at every delay 1–10 and the one with the best stable simulated fit is kept — per order in
//!    the comparison (each order at its own best delay, so no order is judged at a delay chosen
//!    for another; a 1st-order model takes a longer delay to stand in for the lags it lacks).
//!    The scan is reported (`delay_scan`, `delay_reason`; `nk` is the reported model's delay).
//!    Dead time, RTD lag and the F_a filter add up to 40–90 s on the carriers; on H-TER I the
//!    2nd-order fit climbs from 84.7 % at nk = 1 to 94.8 % at nk = 9.
//! 7. Validate ([`hter::ident::validate`]): one-step-ahead MSE (°C², on the data the model was
//!    estimated from; the ARX predictor ŷ = φᵀθ with the estimated θ for every method, so the
//!    numbers compare with the seed's), simulated-output fit % (the model run from the input
//!    alone, starting from the measured initial condition, as MATLAB `compare`), poles and
//!    zeros with stability, static gain B(1)/A(1) in °C per unit duty, time constants −Ts/ln p
//!    of the real positive poles, and the residual autocorrelation at lags 1–20 against
//!    ±1.96/√N (of the ARX one-step residuals: for an OE model they are not expected to be
//!    white, its noise model is H = 1 on the output).
//! 8. Compare orders 1, 2 and 4 (na = nb, same method and nc; the given delay or each order's
//!    best) and pick the lowest stable order within [`validate::ORDER_TOLERANCE_POINTS`] fit
//!    points of the best ([`validate::choose_order`]); the report says why, against every other
//!    order. `--auto-order` makes that the reported model instead of the requested one (default
//!    na = nb = 2).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use hter::filter::{FirstOrder, FirstOrderConfig};
use hter::ident::batch::{BatchIv, BatchLs};
use hter::ident::model::{Structure, MAX_NK, MAX_PARAMS};
use hter::ident::oe::{self, OeConfig};
use hter::ident::recursive;
use hter::ident::rls::RlsConfig;
use hter::ident::validate::{self, Complex, OrderCandidate};
use nalgebra::SVector;
use serde::Serialize;

use crate::{log, plot};

/// Residual autocorrelation lags reported.
const LAGS: usize = 20;

/// A dominant time constant beyond this many record lengths is flagged in the text report: the
/// record cannot tell such a pole from an integrator (on `tclab-heater-multistep.csv` the OE
/// models put a pole within 1e-10 of 1 to follow the board's drift), so the static gain
/// B(1)/A(1) divides by almost nothing.
const SLOW_POLE_RECORDS: f64 = 10.0;

/// A pole counts as real positive when its angle is below this, rad: its oscillation period
/// would exceed 2π/1e-3 ≈ 6000 samples. Repeated real poles come out of the quadratic formula
/// with a tiny imaginary part (√ of a rounding error), which must not hide their time constant.
const REAL_ANGLE_RAD: f64 = 1e-3;

/// True for a pole that behaves as a real one in (0, 1): a first-order lag.
fn is_real_lag(p: &Complex) -> bool {
    p.0 > 0.0 && is_real(p) && validate::abs(*p) < 1.0
}

/// Estimation method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Batch least squares (f64), ARX.
    Ls,
    /// Recursive least squares (the firmware's f32 estimator), ARX.
    Rls,
    /// Recursive extended least squares, ARMAX (nc ≥ 1).
    Rels,
    /// Instrumental variables (f64), ARX: least squares, then three rounds with instruments
    /// simulated from the previous model. Unbiased under coloured noise, but still an
    /// equation-error criterion.
    Iv,
    /// Output error (f64), ARX structure: Levenberg–Marquardt on the simulated-output error
    /// ([`hter::ident::oe`]) from the IV and LS estimates and from lower-order OE models with a
    /// few second-pole starts; the best is kept. Maximises the simulated fit itself.
    Oe,
}

/// The delay nk: given, or scanned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delay {
    /// Fit every delay 1…[`MAX_NK`] and keep the best simulated fit.
    Auto,
    /// This many samples.
    Samples(usize),
}

impl std::str::FromStr for Delay {
    type Err = String;
    fn from_str(v: &str) -> Result<Self, String> {
        if v == "auto" {
            return Ok(Delay::Auto);
        }
        v.parse().map(Delay::Samples).map_err(|_| format!("'{v}' is not a delay: give 1–{MAX_NK} samples or 'auto'"))
    }
}

/// Where the deviation variables are taken from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OperatingPointChoice {
    /// `initial` if the log starts at rest, else `mean`.
    Auto,
    /// u(0) and the mean of y while the duty keeps its initial value (the log starts at rest).
    Initial,
    /// The means of y and u over the record.
    Mean,
}

/// Arguments of `hter identify`.
#[derive(clap::Args, Debug, Clone)]
pub struct IdentifyArgs {
    /// CSV log with a header row and columns t_s, duty (input) and temp_c (output), any order.
    #[arg(long)]
    pub input: PathBuf,
    /// Order of A (1–4).
    #[arg(long, default_value_t = 2)]
    pub na: usize,
    /// Number of B coefficients (1–4).
    #[arg(long, default_value_t = 2)]
    pub nb: usize,
    /// Order of C (0–2; rels needs ≥ 1 and uses 1 when 0 is given).
    #[arg(long, default_value_t = 0)]
    pub nc: usize,
    /// Delay in samples (1–10), or `auto`: fit each delay 1–10 and keep the best simulated fit
    /// (per order in the 1/2/4 comparison).
    #[arg(long, default_value = "auto")]
    pub nk: Delay,
    /// Estimator: oe (output error, the default), ls, iv, rls or rels.
    #[arg(long, value_enum, default_value = "oe")]
    pub method: Method,
    /// Forgetting factor λ_f of rls/rels, in (0, 1].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub forgetting: f64,
    /// First-order filter parameter F_a in [0, 1) applied to the output first.
    #[arg(long, allow_negative_numbers = true)]
    pub filter: Option<f64>,
    /// Prefilter both duty and temperature with the same first-order low-pass (pole in [0, 1))
    /// before estimating (Ljung 1999, §14.4): weights the equation-error fit toward the slow
    /// dynamics that matter for control, instead of the one-sample-ahead detail ARX favours.
    /// Validation uses the unprefiltered data.
    #[arg(long, allow_negative_numbers = true)]
    pub prefilter: Option<f64>,
    /// Output column to identify from (e.g. raw_temp_c for the unfiltered reading of a
    /// `hter sim` trace).
    #[arg(long, default_value = "temp_c")]
    pub y_column: String,
    /// Average every N samples into one before identifying (for logs sampled much faster than
    /// the plant moves, where quantisation noise would dominate each step).
    #[arg(long, default_value_t = 1)]
    pub decimate: usize,
    /// Operating point removed: initial (the log starts at rest), mean, or auto (initial when
    /// the log starts at rest, else mean).
    #[arg(long, value_enum, default_value = "auto")]
    pub operating_point: OperatingPointChoice,
    /// Report the order the 1/2/4 comparison chooses (na = nb) instead of --na/--nb.
    #[arg(long)]
    pub auto_order: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Plot parameter convergence and measured vs simulated output (.png or .svg).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// A model fitted and validated (physical units: °C, duty, s).
#[derive(Clone, Debug, Serialize)]
pub struct Fit {
    /// a1 … a_na (A without its leading 1).
    pub a: Vec<f64>,
    /// b0 … b_{nb−1}, °C per unit duty.
    pub b: Vec<f64>,
    /// c1 … c_nc (C without its leading 1).
    pub c: Vec<f64>,
    /// Delay, samples.
    pub nk: usize,
    /// One-step-ahead mean squared prediction error, °C² (on the output the model was estimated
    /// from: filtered if `--filter` was given).
    pub mse: f64,
    /// Simulated-output fit, %.
    pub fit_percent: f64,
    /// Poles (re, im): roots of z^na A(z⁻¹).
    pub poles: Vec<Complex>,
    /// Zeros (re, im): roots of z^(nb−1) B(z⁻¹).
    pub zeros: Vec<Complex>,
    /// All poles strictly inside the unit circle.
    pub stable: bool,
    /// B(1)/A(1), °C per unit duty.
    pub static_gain_c_per_duty: f64,
    /// −Ts/ln |p| for each real pole 0 < p < 1, s (slowest first).
    pub time_constants_s: Vec<f64>,
    /// −Ts/ln|p| of the pole of largest modulus < 1, s: the dominant time constant (the
    /// envelope's for a complex pair).
    pub dominant_time_constant_s: Option<f64>,
    /// Normalised residual autocorrelation at lags 1–20.
    pub residual_autocorrelation: Vec<f64>,
    /// The ±1.96/√N band the autocorrelation is compared with.
    pub whiteness_band: f64,
    /// Lags outside the band.
    pub residual_lags_outside_band: usize,
    /// Samples whose recursive update was refused.
    pub skipped_updates: u32,
    #[serde(skip)]
    theta_history: Vec<(f64, Vec<f64>)>,
    #[serde(skip)]
    ysim: Vec<f64>,
}

/// One row of the order comparison.
#[derive(Clone, Debug, Serialize)]
pub struct OrderRow {
    /// na = nb.
    pub order: usize,
    /// Delay of this row's model, samples.
    pub nk: usize,
    /// Simulated fit, %.
    pub fit_percent: f64,
    /// One-step MSE, °C².
    pub mse: f64,
    /// Stable poles.
    pub stable: bool,
    /// Dominant time constant −Ts/ln|p| of the slowest pole, s (envelope for a complex pair).
    pub dominant_time_constant_s: Option<f64>,
    /// Static gain, °C per unit duty.
    pub static_gain_c_per_duty: f64,
}

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

/// The `--json` report.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The reported model (contract fields `a, b, c, nk, mse, fit_percent` and extras).
    #[serde(flatten)]
    pub fit: Fit,
    /// na of the reported model.
    pub na: usize,
    /// nb of the reported model.
    pub nb: usize,
    /// Estimator.
    pub method: Method,
    /// Forgetting factor used by rls/rels.
    pub forgetting: f64,
    /// Sample period after decimation, s.
    pub ts_s: f64,
    /// Dead time nk·Ts, s.
    pub dead_time_s: f64,
    /// `given` (--nk N) or `auto` (the delay with the best simulated fit of 1–10).
    pub nk_choice: &'static str,
    /// Simulated fit of the reported structure at each delay tried (empty when given).
    pub delay_scan: Vec<DelayRow>,
    /// Why the reported delay, in words.
    pub delay_reason: String,
    /// Samples used.
    pub rows: usize,
    /// Decimation factor applied.
    pub decimate: usize,
    /// Filter parameter applied to the output, if any.
    pub filter: Option<f64>,
    /// Prefilter pole applied to both signals for the estimation, if any.
    pub prefilter: Option<f64>,
    /// Deviation variables are taken from here.
    pub operating_point: OperatingPoint,
    /// 1st/2nd/4th order fits with the same method and nc, at the given delay or each at its
    /// best delay (`--nk auto`).
    pub order_comparison: Vec<OrderRow>,
    /// Order the comparison recommends (0 if none is stable).
    pub chosen_order: usize,
    /// Why.
    pub reason: String,
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
/// the flag.
fn first_order_cfg(flag: &str, fa: Option<f64>) -> Result<Option<FirstOrderConfig>> {
    fa.map(|fa| {
        FirstOrderConfig::new(fa as f32)
            .filter(|_| fa.is_finite())
            .ok_or_else(|| anyhow!("--{flag} must be in [0, 1), got {fa}"))
    })
    .transpose()
}

/// `x` through the first-order filter (initialised at the first sample).
fn first_order(cfg: &FirstOrderConfig, x: &[f64]) -> Vec<f64> {
    let mut f = FirstOrder::default();
    x.iter().map(|v| f64::from(f.step(cfg, *v as f32))).collect()
}

/// Reads and pre-processes a log (steps 1–5 of the module docs).
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
    let cols = log::read_columns(path, &["t_s", "duty", y_column])?;
    let ts_raw = check_time_axis(path, &cols[0])?;
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

/// Largest magnitude of `v`, or 1 if it is zero (a scale factor for the f32 estimator).
fn scale_of(v: &[f64]) -> f64 {
    let m = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if m > 0.0 && m.is_finite() {
        m
    } else {
        1.0
    }
}

/// θ in physical units from θ estimated on ỹ/ys, ũ/us: b · ys/us, a and c unchanged.
fn unscale(s: &Structure, th: &[f64], ys: f64, us: f64) -> Vec<f64> {
    th.iter().enumerate().map(|(i, v)| if i >= s.na && i < s.na + s.nb { v * ys / us } else { *v }).collect()
}

/// An estimate in physical units.
struct Estimate {
    /// θ = [a, b, c].
    theta: Vec<f64>,
    /// (time in s, θ) every few samples, for the recursive methods.
    history: Vec<(f64, Vec<f64>)>,
    /// Recursive updates refused.
    skipped: u32,
}

/// Second poles of the output-error starts: added to the lower-order OE model (and a slow pole
/// for 1st order). The 2nd-order OE criterion on the H-TER I PRBS run has a local minimum with
/// a fast second pole (≈ 0.25–0.54) besides the global one near 0.95; starts across 0.5…0.98
/// lead to both, and the better is kept.
const OE_EXTRA_POLES: [f64; 4] = [0.5, 0.8, 0.95, 0.98];

/// Slow poles of the 1st-order OE starts: time constants of 95 s, 16 min and 83 min at
/// Ts = 10 s, spanning the carriers' and the TCLab heater's.
const OE_FIRST_POLES: [f64; 3] = [0.9, 0.99, 0.998];

/// Iterations every OE start gets before only the best [`OE_FINALISTS`] are refined to the end.
const OE_SCREEN_ITERATIONS: u32 = 6;

/// Starts refined to convergence after screening.
const OE_FINALISTS: usize = 2;

/// Output-error models already searched on one record, by (na, nb, nk) (`None`: no start gave
/// a stable model): the lower-order and neighbouring-delay models later searches start from,
/// and what the order comparison and the reported model share.
#[derive(Default)]
pub struct OeMemo(std::collections::HashMap<(usize, usize, usize), Option<Vec<f64>>>);

/// Coefficients of the product of two polynomials in q⁻¹ (leading coefficient first).
fn polymul(p: &[f64], q: &[f64]) -> Vec<f64> {
    let mut r = vec![0.0; p.len() + q.len() - 1];
    for (i, a) in p.iter().enumerate() {
        for (j, b) in q.iter().enumerate() {
            r[i + j] += a * b;
        }
    }
    r
}

/// (1 − p q⁻¹)^k.
fn lag_factor(p: f64, k: usize) -> Vec<f64> {
    (0..k).fold(vec![1.0], |acc, _| polymul(&acc, &[1.0, -p]))
}

/// The B that fits the output best for a fixed A (monic, without its leading 1): the OE
/// criterion is linear in B once A is fixed, y ≈ Σ_j b_j w(t − nk − j) with w = u/A (the
/// inner least-squares problem of separable least squares, Golub & Pereyra 1973). A good start
/// for a given set of poles. `None` for an unstable A or a singular problem.
fn best_b_for(d: &Data, s: &Structure, a: &[f64]) -> Option<Vec<f64>> {
    if !oe::is_stable(a) {
        return None;
    }
    let mut w = vec![0.0; d.u_est.len()];
    for t in 0..w.len() {
        w[t] = d.u_est[t] - a.iter().enumerate().filter(|(i, _)| *i < t).map(|(i, ai)| ai * w[t - 1 - i]).sum::<f64>();
    }
    let mut ls = BatchLs::new(s.nb).ok()?;
    let mut phi = [0.0f64; MAX_PARAMS];
    for t in s.first_index()..d.y_est.len() {
        for j in 0..s.nb {
            phi[j] = w[t - s.nk - j];
        }
        ls.add(&phi[..s.nb], d.y_est[t]).ok()?;
    }
    let mut b = vec![0.0; s.nb];
    ls.solve(&mut b).ok()?;
    Some(b)
}

/// The lower-order structure an OE search of `s` starts from: 4 → 2, otherwise one less.
fn reduced(order: usize) -> usize {
    if order == 4 {
        2
    } else {
        order.saturating_sub(1).max(1)
    }
}

/// Output-error estimate of an ARX structure (module docs, step 6): Levenberg–Marquardt from
/// every start, the best few refined to convergence, the lowest V kept.
fn estimate_oe(d: &Data, s: &Structure, memo: &mut OeMemo) -> Result<Vec<f64>> {
    if s.nc > 0 {
        bail!("method oe fits ARX only: use --method rels for nc > 0");
    }
    let key = (s.na, s.nb, s.nk);
    let none = || anyhow!("no output-error start gave a stable model");
    if let Some(done) = memo.0.get(&key) {
        return done.clone().ok_or_else(none);
    }
    let (na, nb) = (s.na, s.nb);
    let mut starts: Vec<Vec<f64>> = Vec::new();
    // The equation-error estimates.
    for m in [Method::Iv, Method::Ls] {
        if let Ok(e) = estimate(d, s, m, 1.0, memo) {
            starts.push(e.theta);
        }
    }
    // The same structure one sample earlier or later, if already searched: nearly the same
    // model, shifted.
    for k in [s.nk.checked_sub(1), Some(s.nk + 1)].into_iter().flatten() {
        if let Some(Some(th)) = memo.0.get(&(na, nb, k)) {
            starts.push(th.clone());
        }
    }
    let with_best_b = |a: Vec<f64>| -> Option<Vec<f64>> {
        let b = best_b_for(d, s, &a[1..])?;
        Some(a[1..].iter().chain(&b).copied().collect())
    };
    if na == 1 && nb == 1 {
        starts.extend(OE_FIRST_POLES.iter().filter_map(|&p| with_best_b(vec![1.0, -p])));
    } else if let Ok(r) = Structure::new(reduced(na), reduced(nb), 0, s.nk) {
        if let Ok(low) = estimate_oe(d, &r, memo) {
            let a_low: Vec<f64> = std::iter::once(1.0).chain(low[..r.na].iter().copied()).collect();
            let b_low = &low[r.na..];
            for p in OE_EXTRA_POLES {
                let a = polymul(&a_low, &lag_factor(p, na - r.na));
                // The lower-order model itself (the extra pole cancelled by a zero when B
                // grows too): the search can only improve on it.
                let b = polymul(b_low, &lag_factor(p, nb - r.nb));
                starts.push(a[1..].iter().chain(&b[..nb]).copied().collect());
                // Its poles and an extra lag, with the B that fits best for them.
                starts.extend(with_best_b(a));
            }
        }
    }
    let cfg = OeConfig::DEFAULT;
    let screen = OeConfig { max_iterations: OE_SCREEN_ITERATIONS, ..cfg };
    let mut screened: Vec<(f64, Vec<f64>)> = starts
        .into_iter()
        .filter_map(|mut th| {
            let out = oe::refine(s, &screen, &mut th, &d.y_est, &d.u_est).ok()?;
            Some((out.cost, th))
        })
        .collect();
    screened.sort_by(|x, y| x.0.total_cmp(&y.0));
    let best = screened
        .into_iter()
        .take(OE_FINALISTS)
        .filter_map(|(_, mut th)| {
            let out = oe::refine(s, &cfg, &mut th, &d.y_est, &d.u_est).ok()?;
            Some((out.cost, th))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, th)| th);
    memo.0.insert(key, best.clone());
    best.ok_or_else(none)
}

/// Estimates θ = [a, b, c] and, for the recursive methods, its history and the refused count.
fn estimate(d: &Data, s: &Structure, method: Method, forgetting: f64, memo: &mut OeMemo) -> Result<Estimate> {
    let n = s.n_params();
    if method == Method::Oe {
        let theta = estimate_oe(d, s, memo)?;
        return Ok(Estimate { theta, history: Vec::new(), skipped: 0 });
    }
    if method == Method::Iv {
        if s.nc > 0 {
            bail!("method iv fits ARX only: use --method rels for nc > 0");
        }
        let mut th = estimate(d, s, Method::Ls, forgetting, memo)?.theta;
        let (mut x, mut zeta, mut phi) = (vec![0.0; d.y_est.len()], [0.0f64; MAX_PARAMS], [0.0f64; MAX_PARAMS]);
        // Each round's instruments come from the previous model; the iterate whose simulation
        // fits the estimation data best is kept (an IV round can overshoot into an unstable
        // model, whose simulation is no instrument and no model).
        let mut best = (validate::simulate_fit(s, &th, &d.y_est, &d.u_est, &mut x), th.clone());
        for _ in 0..3 {
            validate::simulate_fit(s, &th, &d.y_est, &d.u_est, &mut x);
            if x.iter().any(|v| !v.is_finite() || v.abs() >= 1e6) {
                break;
            }
            let mut iv = BatchIv::new(n).map_err(|e| anyhow!("instrumental variables: {e:?}"))?;
            for t in s.first_index()..d.y_est.len() {
                if s.regressor(&x, &d.u_est, &[], t, &mut zeta) && s.regressor(&d.y_est, &d.u_est, &[], t, &mut phi) {
                    iv.add(&zeta[..n], &phi[..n], d.y_est[t]).map_err(|e| anyhow!("instrumental variables: {e:?}"))?;
                }
            }
            let mut next = vec![0.0; n];
            if iv.solve(&mut next).is_err() {
                break;
            }
            th = next;
            let f = validate::simulate_fit(s, &th, &d.y_est, &d.u_est, &mut x);
            if f.is_finite() && (best.0.is_nan() || f > best.0) {
                best = (f, th.clone());
            }
        }
        let th = best.1;
        return Ok(Estimate { theta: th, history: Vec::new(), skipped: 0 });
    }
    if method == Method::Ls {
        if s.nc > 0 {
            bail!("method ls fits ARX only: use --method rels for nc > 0");
        }
        let mut ls = BatchLs::new(n).map_err(|e| anyhow!("batch least squares: {e:?}"))?;
        let mut phi = [0.0f64; MAX_PARAMS];
        for t in s.first_index()..d.y_est.len() {
            if s.regressor(&d.y_est, &d.u_est, &[], t, &mut phi) {
                ls.add(&phi[..n], d.y_est[t]).map_err(|e| anyhow!("batch least squares: {e:?}"))?;
            }
        }
        let mut th = vec![0.0; n];
        ls.solve(&mut th).map_err(|_| {
            anyhow!("the data do not excite the model enough to identify it (singular normal equations): the duty must change during the record")
        })?;
        return Ok(Estimate { theta: th, history: Vec::new(), skipped: 0 });
    }
    // Signals are scaled to |x| ≤ 1, so P(0) = 1e6·I is a prior worth 1e-6 of one sample: RLS
    // with λ_f = 1 then ends within rounding of batch LS. The trace bound only acts with λ_f < 1.
    let cfg = RlsConfig { forgetting: forgetting as f32, p0: 1e6, trace_max: 1e8 };
    let (ys, us) = (scale_of(&d.y_est), scale_of(&d.u_est));
    let yf: Vec<f32> = d.y_est.iter().map(|&v| (v / ys) as f32).collect();
    let uf: Vec<f32> = d.u_est.iter().map(|&v| (v / us) as f32).collect();
    let every = (d.y.len() / 400).max(1);
    let (ts, t0) = (d.ts_s, d.t[0]);
    let mut history = Vec::new();
    let mut record = |t: usize, th: &[f32]| {
        if t.is_multiple_of(every) {
            let th: Vec<f64> = th.iter().map(|&v| f64::from(v)).collect();
            history.push((t0 + t as f64 * ts, unscale(s, &th, ys, us)));
        }
    };
    macro_rules! run_n {
        ($($k:literal),*) => {
            match n {
                $($k => {
                    let (r, skipped) = recursive::run::<$k>(s, &cfg, SVector::zeros(), &yf, &uf, |t, th, _| {
                        record(t, th.as_slice())
                    })
                    .map_err(|e| anyhow!("estimator failed: {e:?}"))?;
                    let th: Vec<f64> = r.theta().iter().map(|&v| f64::from(v)).collect();
                    (th, skipped)
                })*
                _ => bail!("unsupported number of parameters {n}"),
            }
        };
    }
    let (th, skipped) = run_n!(2, 3, 4, 5, 6, 7, 8, 9, 10);
    Ok(Estimate { theta: unscale(s, &th, ys, us), history, skipped })
}

/// Fits and validates one structure.
pub fn fit(d: &Data, s: &Structure, method: Method, forgetting: f64) -> Result<Fit> {
    fit_memo(d, s, method, forgetting, &mut OeMemo::default())
}

/// [`fit`], sharing the output-error searches already done on this record.
fn fit_memo(d: &Data, s: &Structure, method: Method, forgetting: f64, memo: &mut OeMemo) -> Result<Fit> {
    let n = s.n_params();
    let min_rows = s.first_index() + 10 * n;
    if d.y.len() < min_rows {
        bail!(
            "too few rows ({}) for na={} nb={} nc={} nk={}: need at least {min_rows}",
            d.y.len(),
            s.na,
            s.nb,
            s.nc,
            s.nk
        );
    }
    let Estimate { theta, history: theta_history, skipped: skipped_updates } =
        estimate(d, s, method, forgetting, memo)?;
    if theta.iter().any(|v| !v.is_finite()) {
        bail!("the estimate is not finite: the data may be constant or corrupt");
    }
    let mut eps = vec![0.0; d.y.len()];
    let mse = validate::one_step(s, &theta, &d.y, &d.u, &mut eps);
    let mut ysim = vec![0.0; d.y.len()];
    let fit_percent = validate::simulate_fit(s, &theta, &d.y, &d.u, &mut ysim);
    let a = theta[..s.na].to_vec();
    let b = theta[s.na..s.na + s.nb].to_vec();
    let c = theta[s.na + s.nb..].to_vec();
    let mut r = [(0.0, 0.0); 4];
    let np = validate::roots_monic(&a, &mut r);
    let poles = r[..np].to_vec();
    let zeros = if b.len() > 1 && b[0] != 0.0 {
        let monic: Vec<f64> = b[1..].iter().map(|v| v / b[0]).collect();
        let nz = validate::roots_monic(&monic, &mut r);
        r[..nz].to_vec()
    } else {
        vec![]
    };
    let stable = poles.iter().all(|p| validate::abs(*p) < 1.0);
    let static_gain = b.iter().sum::<f64>() / (1.0 + a.iter().sum::<f64>());
    let mut time_constants_s: Vec<f64> =
        poles.iter().filter(|p| is_real_lag(p)).map(|p| -d.ts_s / validate::abs(*p).ln()).collect();
    time_constants_s.sort_by(|x, y| y.total_cmp(x));
    let slowest = poles.iter().map(|p| validate::abs(*p)).fold(0.0f64, f64::max);
    let dominant_time_constant_s = (slowest > 0.0 && slowest < 1.0).then(|| -d.ts_s / slowest.ln());
    let resid = &eps[s.first_index()..];
    let mut ac = [0.0; LAGS];
    validate::autocorrelation(resid, &mut ac);
    let band = validate::whiteness_band(resid.len());
    Ok(Fit {
        a,
        b,
        c,
        nk: s.nk,
        mse,
        fit_percent,
        poles,
        zeros,
        stable,
        static_gain_c_per_duty: static_gain,
        time_constants_s,
        dominant_time_constant_s,
        residual_lags_outside_band: ac.iter().filter(|v| v.abs() > band).count(),
        residual_autocorrelation: ac.to_vec(),
        whiteness_band: band,
        skipped_updates,
        theta_history,
        ysim,
    })
}

/// One delay of a scan.
#[derive(Clone, Debug, Serialize)]
pub struct DelayRow {
    /// Delay, samples.
    pub nk: usize,
    /// Simulated fit, %.
    pub fit_percent: f64,
    /// Stable poles.
    pub stable: bool,
}

/// A usable model ranks above an unusable one, then by simulated fit.
fn rank(f: &Fit) -> f64 {
    if f.stable && f.fit_percent.is_finite() {
        f.fit_percent
    } else {
        f64::NEG_INFINITY
    }
}

/// The orders-out-of-range error.
fn orders_error(na: usize, nb: usize, nc: usize, nk: usize) -> anyhow::Error {
    anyhow!("orders out of range: need na 1–4, nb 1–4, nc 0–2, nk 1–10 (got na={na} nb={nb} nc={nc} nk={nk})")
}

/// Fits (na, nb, nc) at the given delay, or at every delay 1…[`MAX_NK`] keeping the best
/// stable simulated fit (the scan is returned; empty for a given delay).
#[allow(clippy::too_many_arguments)]
fn fit_delay(
    d: &Data,
    na: usize,
    nb: usize,
    nc: usize,
    nk: Delay,
    method: Method,
    forgetting: f64,
    memo: &mut OeMemo,
) -> Result<(Fit, Vec<DelayRow>)> {
    let at = |k: usize, memo: &mut OeMemo| {
        Structure::new(na, nb, nc, k)
            .map_err(|_| orders_error(na, nb, nc, k))
            .and_then(|s| fit_memo(d, &s, method, forgetting, memo))
    };
    if let Delay::Samples(k) = nk {
        return Ok((at(k, memo)?, Vec::new()));
    }
    let (mut best, mut scan, mut first_err): (Option<Fit>, Vec<DelayRow>, Option<anyhow::Error>) = (None, vec![], None);
    for k in 1..=MAX_NK {
        match at(k, memo) {
            Ok(f) => {
                scan.push(DelayRow { nk: k, fit_percent: f.fit_percent, stable: f.stable });
                if best.as_ref().is_none_or(|b| rank(&f) > rank(b)) {
                    best = Some(f);
                }
            }
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    match best {
        Some(f) => Ok((f, scan)),
        None => Err(first_err.unwrap_or_else(|| anyhow!("no delay could be fitted"))),
    }
}

/// Why the reported delay: the scan in words (empty for a given delay).
fn delay_reason(f: &Fit, scan: &[DelayRow], ts_s: f64) -> String {
    if scan.is_empty() {
        return format!("nk = {} given (--nk)", f.nk);
    }
    let list: Vec<String> = scan.iter().map(|r| format!("{}: {}", r.nk, fmt_fit(r.fit_percent, r.stable))).collect();
    let edge = if f.nk == MAX_NK {
        format!("; the best is at the end of the scan, so the dead time may exceed {MAX_NK} samples (try --decimate)")
    } else {
        String::new()
    };
    format!(
        "nk = {} ({} s) has the best simulated fit of the delays 1–{MAX_NK} for this structure ({}){edge}",
        f.nk,
        f.nk as f64 * ts_s,
        list.join(", ")
    )
}

/// The 1/2/4 order comparison.
pub struct Comparison {
    /// One row per order that could be fitted.
    pub rows: Vec<OrderRow>,
    /// Chosen order (0 if none is stable).
    pub chosen: usize,
    /// Why, in words.
    pub reason: String,
    /// The fitted models and their delay scans, by order.
    fits: Vec<(usize, Fit, Vec<DelayRow>)>,
}

/// Compares orders 1, 2, 4 (na = nb, same nc; the given delay, or each order at its best delay
/// with `Delay::Auto`) and picks one with [`validate::choose_order`].
pub fn compare(d: &Data, nk: Delay, nc: usize, method: Method, forgetting: f64, memo: &mut OeMemo) -> Comparison {
    let mut rows = Vec::new();
    let mut fits = Vec::new();
    let mut failed = Vec::new();
    for order in [1usize, 2, 4] {
        match fit_delay(d, order, order, nc, nk, method, forgetting, memo) {
            Ok((f, scan)) => {
                rows.push(OrderRow {
                    order,
                    nk: f.nk,
                    fit_percent: f.fit_percent,
                    mse: f.mse,
                    stable: f.stable,
                    dominant_time_constant_s: f.dominant_time_constant_s,
                    static_gain_c_per_duty: f.static_gain_c_per_duty,
                });
                fits.push((order, f, scan));
            }
            Err(e) => failed.push(format!("order {order} could not be fitted ({e})")),
        }
    }
    let candidates: Vec<OrderCandidate> =
        rows.iter().map(|r| OrderCandidate { order: r.order, fit_percent: r.fit_percent, stable: r.stable }).collect();
    let tol = validate::ORDER_TOLERANCE_POINTS;
    let Some(i) = validate::choose_order(&candidates, tol) else {
        failed.insert(0, "no order gave a stable model with a finite fit".into());
        return Comparison { rows, chosen: 0, reason: failed.join("; "), fits };
    };
    let chosen = &rows[i];
    let best = candidates
        .iter()
        .filter(|c| c.stable && c.fit_percent.is_finite())
        .map(|c| c.fit_percent)
        .fold(f64::NEG_INFINITY, f64::max);
    let delay = |r: &OrderRow| if nk == Delay::Auto { format!(" (nk {})", r.nk) } else { String::new() };
    let mut why = vec![format!(
        "order {}{} is the lowest stable order whose simulated fit ({:.1} %) is within {tol} points of the best stable fit ({best:.1} %)",
        chosen.order,
        delay(chosen),
        chosen.fit_percent
    )];
    for r in rows.iter().filter(|r| r.order != chosen.order) {
        let note = if !r.stable {
            "unstable".to_string()
        } else if r.order < chosen.order {
            format!("{:.1} points below: more than {tol} below the best", chosen.fit_percent - r.fit_percent)
        } else if r.fit_percent > chosen.fit_percent {
            format!(
                "only {:.1} points better: the extra parameters are not worth it",
                r.fit_percent - chosen.fit_percent
            )
        } else {
            "no better".to_string()
        };
        why.push(format!("order {}{}: {} ({note})", r.order, delay(r), fmt_fit(r.fit_percent, r.stable)));
    }
    why.extend(failed);
    let order = chosen.order;
    Comparison { rows, chosen: order, reason: why.join("; "), fits }
}

/// `hter identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    if !(args.forgetting.is_finite() && args.forgetting > 0.0 && args.forgetting <= 1.0) {
        bail!("--forgetting must be in (0, 1], got {}", args.forgetting);
    }
    let nc = if args.method == Method::Rels && args.nc == 0 { 1 } else { args.nc };
    let nk_check = match args.nk {
        Delay::Samples(k) => k,
        Delay::Auto => 1,
    };
    Structure::new(args.na, args.nb, nc, nk_check).map_err(|_| orders_error(args.na, args.nb, nc, nk_check))?;
    if args.method != Method::Rels && nc > 0 {
        bail!("nc > 0 (ARMAX) needs --method rels");
    }
    let d = load(&args.input, &args.y_column, args.filter, args.prefilter, args.decimate, args.operating_point)?;
    let mut memo = OeMemo::default();
    let cmp = compare(&d, args.nk, nc, args.method, args.forgetting, &mut memo);
    let (na, nb) = if args.auto_order && cmp.chosen > 0 { (cmp.chosen, cmp.chosen) } else { (args.na, args.nb) };
    let done = cmp.fits.iter().find(|(order, _, _)| na == nb && *order == na);
    let (f, scan) = match done {
        Some((_, f, scan)) => (f.clone(), scan.clone()),
        None => fit_delay(&d, na, nb, nc, args.nk, args.method, args.forgetting, &mut memo)?,
    };
    let s = Structure::new(na, nb, nc, f.nk).map_err(|_| orders_error(na, nb, nc, f.nk))?;
    if let Some(p) = &args.plot {
        plot_fit(p, &d, &s, &f)?;
    }
    let delay_reason = delay_reason(&f, &scan, d.ts_s);
    let report = Report {
        fit: f,
        na: s.na,
        nb: s.nb,
        method: args.method,
        forgetting: args.forgetting,
        ts_s: d.ts_s,
        dead_time_s: s.nk as f64 * d.ts_s,
        nk_choice: if scan.is_empty() { "given" } else { "auto" },
        delay_scan: scan,
        delay_reason,
        rows: d.y.len(),
        decimate: args.decimate,
        filter: args.filter,
        prefilter: args.prefilter,
        operating_point: d.op,
        order_comparison: cmp.rows,
        chosen_order: cmp.chosen,
        reason: cmp.reason,
    };
    if args.json {
        use std::io::Write;
        let _ = writeln!(std::io::stdout(), "{}", serde_json::to_string(&report)?);
    } else {
        print_report(args, &s, &report);
    }
    Ok(())
}

fn poly(name: &str, lead: Option<f64>, c: &[f64]) -> String {
    let mut s = format!("{name}(q⁻¹) = ");
    let mut first = true;
    if let Some(l) = lead {
        s += &format!("{l}");
        first = false;
    }
    for (i, v) in c.iter().enumerate() {
        let k = if lead.is_some() { i + 1 } else { i };
        let sign = match (*v < 0.0, first) {
            (true, _) => "−",
            (false, true) => "",
            (false, false) => "+",
        };
        let term = if k == 0 { format!("{:.6}", v.abs()) } else { format!("{:.6} q^-{k}", v.abs()) };
        s += &if first { format!("{sign}{term}") } else { format!(" {sign} {term}") };
        first = false;
    }
    s
}

/// 4 significant digits, in scientific notation only for small values.
fn fmt_small(v: f64) -> String {
    if v.abs() >= 0.01 || v == 0.0 {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// True if `p` is real up to rounding (see [`REAL_ANGLE_RAD`]).
fn is_real(p: &Complex) -> bool {
    p.1.abs() <= REAL_ANGLE_RAD * validate::abs(*p)
}

/// `re` for a real number, `re±im i` otherwise.
fn fmt_complex(p: &Complex) -> String {
    if is_real(p) {
        format!("{:.5}", p.0)
    } else {
        format!("{:.5}{:+.5}i", p.0, p.1)
    }
}

fn describe_pole(p: &Complex, ts: f64) -> String {
    let m = validate::abs(*p);
    let kind = if m >= 1.0 {
        "on or outside the unit circle".to_string()
    } else if is_real_lag(p) {
        format!("τ = {:.1} s", -ts / m.ln())
    } else if is_real(p) {
        "real ≤ 0: alternating, no physical time constant".to_string()
    } else {
        format!("complex, envelope τ = {:.1} s", -ts / m.ln())
    };
    format!("{} (|p| = {m:.5}, {kind})", fmt_complex(p))
}

fn print_report(args: &IdentifyArgs, s: &Structure, r: &Report) {
    let mut out = String::new();
    // One write at the end: a closed pipe (`| head`) is not worth a panic.
    macro_rules! line {
        ($($arg:tt)*) => {{
            out.push_str(&format!($($arg)*));
            out.push('\n');
        }};
    }
    let f = &r.fit;
    line!(
        "identification of {} ({} samples, Ts = {} s{})",
        args.input.display(),
        r.rows,
        r.ts_s,
        if r.decimate > 1 { format!(", {} raw samples averaged per sample", r.decimate) } else { String::new() }
    );
    let op = &r.operating_point;
    let how = match op.kind {
        OperatingPointChoice::Initial => format!("initial rest, mean of {} samples", op.samples),
        _ => "record means".to_string(),
    };
    line!(
        "  operating point removed: {:.3} °C at duty {:.3} ({how}){}\n    because {}",
        op.temp_c,
        op.duty,
        r.filter.map(|fa| format!("; output filtered with F_a = {fa}")).unwrap_or_default()
            + &r.prefilter
                .map(|l| format!("; u and y prefiltered with pole {l} for the estimation"))
                .unwrap_or_default(),
        op.why
    );
    let kind = if s.nc > 0 { "ARMAX" } else { "ARX" };
    let method = match r.method {
        Method::Ls => "batch least squares (f64)".to_string(),
        Method::Iv => "instrumental variables (f64, instruments simulated from the LS model)".to_string(),
        Method::Oe => {
            "output error (f64 Levenberg–Marquardt on the simulated output; best of the IV, LS and lower-order starts)"
                .to_string()
        }
        Method::Rls => format!("f32 RLS, λ_f = {}", r.forgetting),
        Method::Rels => format!("f32 RELS, λ_f = {}", r.forgetting),
    };
    line!(
        "  model {kind}(na={}, nb={}, nc={}, nk={}) by {method}{}",
        s.na,
        s.nb,
        s.nc,
        s.nk,
        if args.auto_order { " (order chosen by the comparison)" } else { "" }
    );
    line!("    {}", poly("A", Some(1.0), &f.a));
    line!("    {}   (delay nk = {} × Ts = {} s)", poly("B", None, &f.b), f.nk, r.dead_time_s);
    line!("  delay               {}", r.delay_reason);
    if !f.c.is_empty() {
        line!("    {}", poly("C", Some(1.0), &f.c));
    }
    if f.skipped_updates > 0 {
        line!("    ({} recursive updates refused on non-finite data)", f.skipped_updates);
    }
    line!("  one-step MSE        {} °C²", fmt_small(f.mse));
    if f.stable {
        line!("  simulated fit       {}", fmt_fit(f.fit_percent, f.stable));
    } else {
        line!("  simulated fit       – (the model is unstable: its simulation diverges)");
    }
    line!("  static gain         {:.3} °C per unit duty", f.static_gain_c_per_duty);
    let record_s = r.rows as f64 * r.ts_s;
    if let Some(tau) = f.dominant_time_constant_s.filter(|tau| *tau > SLOW_POLE_RECORDS * record_s) {
        line!(
            "    (the slowest pole's τ = {tau:.0} s is more than {SLOW_POLE_RECORDS}× the {record_s:.0} s record: the model integrates, and its static gain is an extrapolation the data do not determine)"
        );
    }
    line!(
        "  stability           {}",
        if f.stable {
            "stable (all poles inside the unit circle)"
        } else {
            "UNSTABLE (a pole on or outside the unit circle)"
        }
    );
    for p in &f.poles {
        line!("  pole                {}", describe_pole(p, r.ts_s));
    }
    for z in &f.zeros {
        line!(
            "  zero                {}{}",
            fmt_complex(z),
            if validate::abs(*z) > 1.0 { " (outside the unit circle)" } else { "" }
        );
    }
    let tc: Vec<String> = f.time_constants_s.iter().map(|t| format!("{t:.1} s")).collect();
    line!(
        "  time constants      {}",
        if tc.is_empty() { "none (no real pole in (0, 1))".to_string() } else { tc.join(", ") }
    );
    line!(
        "  residual whiteness  {} of {LAGS} autocorrelation lags outside ±{:.3} (95 % band){}",
        f.residual_lags_outside_band,
        f.whiteness_band,
        // Of 20 lags of white noise, 1 is expected outside the 95 % band and 3 or more happen
        // with probability 7.5 %.
        if f.residual_lags_outside_band <= 2 {
            ": consistent with white noise"
        } else {
            ": not white, the noise is coloured or the model misses dynamics"
        }
    );
    let auto = matches!(args.nk, Delay::Auto);
    line!(
        "  order comparison (na = nb, same method and nc, {}):",
        if auto { "each order at its best delay" } else { "same delay" }
    );
    for o in &r.order_comparison {
        line!(
            "    order {}: nk {:>2}, fit {:>8}, MSE {} °C², gain {:8.3} °C/duty, dominant τ {}, {}",
            o.order,
            o.nk,
            fmt_fit(o.fit_percent, o.stable),
            fmt_small(o.mse),
            o.static_gain_c_per_duty,
            o.dominant_time_constant_s.map(|t| format!("{t:.1} s")).unwrap_or_else(|| "–".into()),
            if o.stable { "stable" } else { "unstable" }
        );
    }
    line!("  chosen order: {} — {}", r.chosen_order, r.reason);
    use std::io::Write;
    let _ = std::io::stdout().write_all(out.as_bytes());
}

fn plot_fit(path: &Path, d: &Data, s: &Structure, f: &Fit) -> Result<()> {
    let minutes = |t: f64| t / 60.0;
    let mut panels = Vec::new();
    if !f.theta_history.is_empty() {
        let series = |range: std::ops::Range<usize>, name: &dyn Fn(usize) -> String| -> Vec<plot::Series> {
            range
                .map(|i| plot::Series {
                    name: name(i),
                    points: f.theta_history.iter().filter_map(|(t, th)| th.get(i).map(|v| (minutes(*t), *v))).collect(),
                })
                .collect()
        };
        let (na, nb) = (s.na, s.nb);
        panels.push(plot::Panel {
            title: "Parameter convergence: A and C (recursive estimate)".into(),
            y_label: "a, c".into(),
            series: series(0..na, &|i| format!("a{}", i + 1))
                .into_iter()
                .chain(series(na + nb..s.n_params(), &|i| format!("c{}", i - na - nb + 1)))
                .collect(),
            y_range: None,
        });
        panels.push(plot::Panel {
            title: "Parameter convergence: B".into(),
            y_label: "b (°C/duty)".into(),
            series: series(na..na + nb, &|i| format!("b{}", i - na)),
            y_range: None,
        });
    }
    let y0 = d.op.temp_c;
    panels.push(plot::Panel {
        title: format!("Measured vs simulated output (fit {:.1} %)", f.fit_percent),
        y_label: "°C".into(),
        series: vec![
            plot::Series {
                name: "measured".into(),
                points: d.t.iter().zip(&d.y).map(|(t, y)| (minutes(*t), y + y0)).collect(),
            },
            plot::Series {
                name: "simulated from the input".into(),
                points: d.t.iter().zip(&f.ysim).map(|(t, y)| (minutes(*t), y + y0)).collect(),
            },
        ],
        y_range: None,
    });
    plot::panels(path, "hter identify", "time (min)", &panels)
}

/// A simulated fit for people: an unstable model's simulation diverges, and its "fit" of
/// −10⁸⁰ % says nothing the word "unstable" does not (the JSON keeps the number).
fn fmt_fit(fit_percent: f64, stable: bool) -> String {
    if stable && fit_percent.is_finite() {
        format!("{fit_percent:.1} %")
    } else {
        "–".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let p = std::env::temp_dir().join(format!("hter-ident-{}-{name}.csv", std::process::id()));
        std::fs::write(&p, text).unwrap();
        p
    }

    fn args(input: PathBuf) -> IdentifyArgs {
        IdentifyArgs {
            input,
            na: 2,
            nb: 2,
            nc: 0,
            nk: Delay::Samples(1),
            method: Method::Ls,
            forgetting: 1.0,
            filter: None,
            prefilter: None,
            y_column: "temp_c".into(),
            decimate: 1,
            operating_point: OperatingPointChoice::Initial,
            auto_order: false,
            json: true,
            plot: None,
        }
    }

    fn err(a: &IdentifyArgs) -> String {
        let e = run(a).unwrap_err().to_string();
        assert!(!e.contains('\n'), "not one line: {e}");
        e
    }

    /// A log of y(t) = 1.8 y(t−1) − 0.81 y(t−2) + 2 u(t−1) + u(t−2) around 25 °C and duty 0.3,
    /// starting at rest, with a PRBS-like duty.
    fn synthetic_log(n: usize) -> String {
        synthetic_log_delayed(n, 1, 0.0)
    }

    /// [`synthetic_log`] with the input delayed by `nk` samples and white noise of amplitude
    /// ±`noise` °C added to the logged output (an output-error system).
    fn synthetic_log_delayed(n: usize, nk: usize, noise: f64) -> String {
        let mut text = String::from("duty,extra,t_s,temp_c\n");
        let (mut y1, mut y2) = (0.0f64, 0.0);
        let mut past_u = vec![0.0f64; nk + 1];
        let mut state = 0b1010_1100u8;
        let mut seed = 5u32;
        for t in 0..n {
            let (u1, u2) = (past_u[nk - 1], past_u[nk]);
            let y = 1.8 * y1 - 0.81 * y2 + 2.0 * u1 + u2;
            let u = if t < 20 {
                0.0
            } else {
                // 8-bit LFSR bit, held 4 samples.
                if t % 4 == 0 {
                    let fb = (state >> 7) ^ (state >> 5) ^ (state >> 4) ^ (state >> 3);
                    state = (state << 1) | (fb & 1);
                }
                if state & 1 == 1 {
                    0.1
                } else {
                    -0.1
                }
            };
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = noise * (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5) * 2.0;
            text += &format!("{},x,{},{}\n", 0.3 + u, 10.0 * t as f64, 25.0 + y + v);
            (y2, y1) = (y1, y);
            past_u.rotate_right(1);
            past_u[0] = u;
        }
        text
    }

    /// Output-error plant y = B/A u + v with white v: the equation error A v is coloured, so
    /// least squares is biased (it pulls the pole toward zero); IV is not.
    #[test]
    fn iv_removes_the_bias_least_squares_has_under_coloured_noise() {
        let n = 4000;
        let (mut x1, mut u1) = (0.0f64, 0.0f64);
        let mut state = 0xACE1u16;
        let mut seed = 99u32;
        let (mut y, mut u) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for t in 0..n {
            // Noise-free x(t) = 0.95 x(t−1) + 0.5 u(t−1).
            let x = 0.95 * x1 + 0.5 * u1;
            if t % 3 == 0 {
                let bit = (state ^ (state >> 2) ^ (state >> 3) ^ (state >> 5)) & 1;
                state = (state >> 1) | (bit << 15);
            }
            let ut = if state & 1 == 1 { 1.0 } else { -1.0 };
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5) * 2.0;
            y.push(x + v);
            u.push(ut);
            (x1, u1) = (x, ut);
        }
        let d = Data {
            ts_s: 10.0,
            t: (0..n).map(|i| 10.0 * i as f64).collect(),
            y_est: y.clone(),
            u_est: u.clone(),
            y,
            u,
            op: OperatingPoint {
                kind: OperatingPointChoice::Initial,
                why: String::new(),
                temp_c: 0.0,
                duty: 0.0,
                samples: 0,
            },
        };
        let s = Structure::new(1, 1, 0, 1).unwrap();
        let ls = fit(&d, &s, Method::Ls, 1.0).unwrap();
        let iv = fit(&d, &s, Method::Iv, 1.0).unwrap();
        assert!((ls.a[0] + 0.95).abs() > 0.03, "LS should be biased here: a1 = {}", ls.a[0]);
        assert!((iv.a[0] + 0.95).abs() < 0.01, "IV a1 = {} (want −0.95)", iv.a[0]);
        assert!((iv.b[0] - 0.5).abs() < 0.05, "IV b0 = {} (want 0.5)", iv.b[0]);
        assert!(iv.fit_percent > ls.fit_percent, "IV fit {} vs LS {}", iv.fit_percent, ls.fit_percent);
    }

    #[test]
    fn missing_column_is_named() {
        let e = err(&args(write("missing", "t_s,temp_c\n0,1\n")));
        assert!(e.contains("missing column 'duty'"), "{e}");
    }

    #[test]
    fn bad_cells_name_line_and_column() {
        let e = err(&args(write("bad", "t_s,duty,temp_c\n0,0.5,4\n1,0.5,x\n")));
        assert!(e.contains("line 3") && e.contains("temp_c"), "{e}");
        let e = err(&args(write("inf", "t_s,duty,temp_c\n0,0.5,4\n1,inf,4\n")));
        assert!(e.contains("line 3") && e.contains("duty") && e.contains("finite"), "{e}");
    }

    #[test]
    fn too_few_rows_and_bad_time_axis() {
        let few: String =
            std::iter::once("t_s,duty,temp_c\n".to_string()).chain((0..20).map(|i| format!("{i},0.5,4\n"))).collect();
        let e = err(&args(write("few", &few)));
        assert!(e.contains("too few rows (20)"), "{e}");
        let jump = write("jump", "t_s,duty,temp_c\n0,0,1\n1,0,1\n2,0,1\n10,0,1\n11,0,1\n");
        let e = err(&args(jump));
        assert!(e.contains("line 5") && e.contains("uniform"), "{e}");
        let back = write("back", "t_s,duty,temp_c\n0,0,1\n1,0,1\n1,0,1\n");
        let e = err(&args(back));
        assert!(e.contains("line 4") && e.contains("increase"), "{e}");
    }

    #[test]
    fn impossible_parameters_are_refused() {
        let ok = write("params", &synthetic_log(200));
        for bad in [0.0, 1.5, -0.5, f64::NAN] {
            let mut a = args(ok.clone());
            a.forgetting = bad;
            assert!(err(&a).contains("--forgetting must be in (0, 1]"), "{bad}");
        }
        for bad in [1.0, -0.1, 2.0] {
            let mut a = args(ok.clone());
            a.filter = Some(bad);
            assert!(err(&a).contains("--filter must be in [0, 1)"), "{bad}");
            let mut a = args(ok.clone());
            a.prefilter = Some(bad);
            assert!(err(&a).contains("--prefilter must be in [0, 1)"), "{bad}");
        }
        let mut a = args(ok.clone());
        a.na = 7;
        assert!(err(&a).contains("orders out of range"));
        let mut a = args(ok.clone());
        a.nk = Delay::Samples(0);
        assert!(err(&a).contains("orders out of range"));
        let mut a = args(ok.clone());
        a.nk = Delay::Samples(11);
        assert!(err(&a).contains("orders out of range"));
        let mut a = args(ok.clone());
        (a.method, a.nc) = (Method::Oe, 1);
        assert!(err(&a).contains("--method rels"));
        assert_eq!("auto".parse::<Delay>(), Ok(Delay::Auto));
        assert_eq!("7".parse::<Delay>(), Ok(Delay::Samples(7)));
        assert!("x".parse::<Delay>().unwrap_err().contains("'x' is not a delay"));
        let mut a = args(ok.clone());
        a.nc = 1;
        assert!(err(&a).contains("--method rels"));
        let mut a = args(ok);
        a.decimate = 0;
        assert!(err(&a).contains("--decimate"));
        assert!(err(&args(PathBuf::from("/no/such.csv"))).contains("cannot read"));
    }

    #[test]
    fn recovers_an_exact_model_from_a_raw_log() {
        let log = write("exact", &synthetic_log(600));
        let d = load(&log, "temp_c", None, None, 1, OperatingPointChoice::Initial).unwrap();
        assert_eq!(d.ts_s, 10.0);
        assert!((d.op.temp_c - 25.0).abs() < 1e-12 && (d.op.duty - 0.3).abs() < 1e-12);
        let s = Structure::new(2, 2, 0, 1).unwrap();
        for method in [Method::Ls, Method::Rls, Method::Oe] {
            let f = fit(&d, &s, method, 1.0).unwrap();
            let th: Vec<f64> = f.a.iter().chain(&f.b).copied().collect();
            let want = [-1.8, 0.81, 2.0, 1.0];
            for (got, want) in th.iter().zip(want) {
                assert!((got - want).abs() < 1e-3 * want.abs().max(1.0), "{method:?}: {th:?}");
            }
            assert!(f.fit_percent > 99.9, "{method:?}: fit {}", f.fit_percent);
            assert!(f.mse < 1e-6, "{method:?}: mse {}", f.mse);
            assert!(f.stable);
            // Poles 0.9, 0.9: τ = −10/ln 0.9 = 94.9 s; gain 3/0.01 = 300.
            assert!((f.time_constants_s[0] - 94.9).abs() < 0.5, "{:?}", f.time_constants_s);
            assert!((f.static_gain_c_per_duty - 300.0).abs() < 3.0);
        }
        // The same low-pass on u and y commutes with A and B: the prefiltered fit finds the
        // same model, validated on the unprefiltered data.
        let p = load(&log, "temp_c", None, Some(0.7), 1, OperatingPointChoice::Initial).unwrap();
        assert!(p.y_est != p.y && p.y == d.y);
        let f = fit(&p, &s, Method::Ls, 1.0).unwrap();
        let th: Vec<f64> = f.a.iter().chain(&f.b).copied().collect();
        for (got, want) in th.iter().zip([-1.8, 0.81, 2.0, 1.0]) {
            assert!((got - want).abs() < 1e-6 * want.abs().max(1.0), "prefiltered: {th:?}");
        }
        assert!(f.fit_percent > 99.99);
        // Noiseless 2nd-order data leave the 4th-order normal equations singular: the
        // comparison says so and still chooses 2 over the poorer 1st order.
        let c = compare(&d, Delay::Samples(1), 0, Method::Ls, 1.0, &mut OeMemo::default());
        let reason = &c.reason;
        assert_eq!(c.rows.iter().map(|r| r.order).collect::<Vec<_>>(), [1, 2], "{reason}");
        assert_eq!(c.chosen, 2, "{reason}");
        assert!(reason.contains("order 1: ") && reason.contains("order 4 could not be fitted"), "{reason}");
    }

    /// `--nk auto`: every delay 1–10 is fitted and the true one (4) has the best simulated fit,
    /// for output error and for least squares, on a noisy output-error system.
    #[test]
    fn delay_scan_finds_the_true_delay() {
        let log = write("delay", &synthetic_log_delayed(800, 4, 0.5));
        let d = load(&log, "temp_c", None, None, 1, OperatingPointChoice::Initial).unwrap();
        for method in [Method::Oe, Method::Iv] {
            let (f, scan) = fit_delay(&d, 2, 2, 0, Delay::Auto, method, 1.0, &mut OeMemo::default()).unwrap();
            assert_eq!(scan.iter().map(|r| r.nk).collect::<Vec<_>>(), (1..=10).collect::<Vec<_>>());
            assert_eq!(f.nk, 4, "{method:?}: {scan:?}");
            let best = scan.iter().map(|r| r.fit_percent).fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(f.fit_percent, best);
            assert!(f.fit_percent > 95.0, "{method:?}: {}", f.fit_percent);
            let why = delay_reason(&f, &scan, d.ts_s);
            assert!(why.starts_with("nk = 4 (40 s) has the best simulated fit") && why.contains("10: "), "{why}");
        }
        // A given delay is fitted as given.
        let (f, scan) = fit_delay(&d, 2, 2, 0, Delay::Samples(2), Method::Oe, 1.0, &mut OeMemo::default()).unwrap();
        assert!(f.nk == 2 && scan.is_empty());
    }

    /// Least squares is biased on an output-error system with noise (the equation error A v is
    /// coloured); the OE estimate is not, and simulates the record better.
    #[test]
    fn output_error_beats_least_squares_on_a_noisy_output_error_log() {
        let log = write("oe-noise", &synthetic_log_delayed(1500, 1, 1.0));
        let d = load(&log, "temp_c", None, None, 1, OperatingPointChoice::Initial).unwrap();
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let ls = fit(&d, &s, Method::Ls, 1.0).unwrap();
        let oe = fit(&d, &s, Method::Oe, 1.0).unwrap();
        // Measured: OE a = (−1.7936, 0.8039), gain 300.5 °C/duty, fit 92.6 %; LS a = (−1.020,
        // 0.036), gain 436, fit 47.6 %. (The split of B between b0 and b1 is poorly determined
        // by this input, their sum is not.)
        let a_err = |f: &Fit| f.a.iter().zip([-1.8, 0.81]).map(|(g, w)| (g - w).abs()).fold(0.0, f64::max);
        assert!(a_err(&oe) < 0.02 && a_err(&ls) > 0.3, "a: OE {:?}, LS {:?}", oe.a, ls.a);
        assert!(
            oe.fit_percent > 90.0 && oe.fit_percent > ls.fit_percent + 20.0,
            "OE {} % vs LS {} %",
            oe.fit_percent,
            ls.fit_percent
        );
        assert!(
            (oe.static_gain_c_per_duty - 300.0).abs() < 6.0 && (ls.static_gain_c_per_duty - 300.0).abs() > 50.0,
            "{}",
            oe.static_gain_c_per_duty
        );
    }

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

    #[test]
    fn json_report_has_the_contract_fields() {
        let log = write("json", &synthetic_log(400));
        let d = load(&log, "temp_c", None, None, 1, OperatingPointChoice::Initial).unwrap();
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let f = fit(&d, &s, Method::Rls, 1.0).unwrap();
        let c = compare(&d, Delay::Samples(1), 0, Method::Rls, 1.0, &mut OeMemo::default());
        let (order_comparison, chosen_order, reason) = (c.rows, c.chosen, c.reason);
        let r = Report {
            fit: f,
            na: 2,
            nb: 2,
            method: Method::Rls,
            forgetting: 1.0,
            ts_s: d.ts_s,
            dead_time_s: 10.0,
            nk_choice: "given",
            delay_scan: vec![],
            delay_reason: String::new(),
            rows: d.y.len(),
            decimate: 1,
            filter: None,
            prefilter: None,
            operating_point: d.op,
            order_comparison,
            chosen_order,
            reason,
        };
        let v: serde_json::Value = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
        for key in [
            "a",
            "b",
            "c",
            "nk",
            "mse",
            "fit_percent",
            "poles",
            "zeros",
            "stable",
            "order_comparison",
            "chosen_order",
            "reason",
            "ts_s",
            "nk_choice",
            "delay_scan",
            "delay_reason",
        ] {
            assert!(v.get(key).is_some(), "missing {key}");
        }
        assert_eq!(v["a"].as_array().unwrap().len(), 2, "a without the leading 1");
        assert_eq!(v["c"].as_array().unwrap().len(), 0);
        assert_eq!(v["nk"], 1);
    }
}
