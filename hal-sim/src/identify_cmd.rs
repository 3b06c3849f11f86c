//! `hter identify`: fit an ARX/ARMAX model to a logged run (SPEC §3; seed chapter 4).
//!
//! Pipeline: read `t_s, duty, temp_c` → check a uniform sample period → optional first-order
//! filter F_a on the temperature (the seed filtered its PRBS records) → deviation variables
//! (the means of temperature and duty are removed, so an ambient offset or a mean duty never
//! biases the model: with `A y = B u + d`, the means satisfy `A(1) ȳ = B(1) ū + d` and
//! subtracting leaves `A (y − ȳ) = B (u − ū) + e`) → estimate (batch LS in f64, or the
//! firmware's f32 RLS/RELS) → validate (one-step MSE, simulated fit, poles/zeros, residual
//! whiteness) → compare 1st/2nd/4th order and explain the choice.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use hter::filter::{FirstOrder, FirstOrderConfig};
use hter::ident::batch::BatchLs;
use hter::ident::model::Structure;
use hter::ident::recursive;
use hter::ident::rls::RlsConfig;
use hter::ident::validate::{self, Complex};
use nalgebra::SVector;
use serde::Serialize;

use crate::{log, plot};

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
}

/// Arguments of `hter identify`.
#[derive(clap::Args, Debug, Clone)]
pub struct IdentifyArgs {
    /// CSV log with columns t_s, duty (input) and temp_c (output).
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
    /// Delay in samples (1–10).
    #[arg(long, default_value_t = 1)]
    pub nk: usize,
    /// Estimator.
    #[arg(long, value_enum, default_value = "rls")]
    pub method: Method,
    /// Forgetting factor λ_f of rls/rels, in (0, 1].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub forgetting: f64,
    /// First-order filter parameter F_a in [0, 1) applied to the temperature first.
    #[arg(long, allow_negative_numbers = true)]
    pub filter: Option<f64>,
    /// Prefilter both temperature and duty with the same first-order low-pass (pole in [0, 1))
    /// before fitting (Ljung 1999, §14.4): weights the equation-error fit toward the slow
    /// dynamics that matter for control, instead of the one-sample-ahead detail ARX favours.
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
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Plot parameter convergence and measured vs simulated output (.png or .svg).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// A model fitted and validated.
#[derive(Clone, Debug, Serialize)]
pub struct Fit {
    /// a1 … a_na.
    pub a: Vec<f64>,
    /// b0 … b_{nb−1}.
    pub b: Vec<f64>,
    /// c1 … c_nc.
    pub c: Vec<f64>,
    /// Delay, samples.
    pub nk: usize,
    /// One-step-ahead mean squared prediction error, °C².
    pub mse: f64,
    /// Simulated-output fit, %.
    pub fit_percent: f64,
    /// Poles (re, im).
    pub poles: Vec<Complex>,
    /// Zeros (re, im).
    pub zeros: Vec<Complex>,
    /// All poles strictly inside the unit circle.
    pub stable: bool,
    /// B(1)/A(1), °C per unit duty.
    pub static_gain_c_per_duty: f64,
    /// −Ts/ln|p| for each pole with 0 < |p| < 1, s.
    pub time_constants_s: Vec<f64>,
    /// Residual autocorrelation lags 1–20 outside ±1.96/√N.
    pub residual_lags_outside_band: usize,
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
    /// Simulated fit, %.
    pub fit_percent: f64,
    /// One-step MSE, °C².
    pub mse: f64,
    /// Stable poles.
    pub stable: bool,
}

/// The `--json` report.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The model asked for.
    #[serde(flatten)]
    pub fit: Fit,
    /// Estimator.
    pub method: Method,
    /// Sample period, s.
    pub ts_s: f64,
    /// Samples used.
    pub rows: usize,
    /// Operating point removed: mean temperature, °C.
    pub mean_temp_c: f64,
    /// Operating point removed: mean duty.
    pub mean_duty: f64,
    /// Filter parameter applied, if any.
    pub filter: Option<f64>,
    /// 1st/2nd/4th order fits with the same method and delay.
    pub order_comparison: Vec<OrderRow>,
    /// Order the comparison recommends.
    pub chosen_order: usize,
    /// Why.
    pub reason: String,
}

/// The data after pre-processing.
pub struct Data {
    /// Sample period, s.
    pub ts_s: f64,
    /// Time of each sample, s.
    pub t: Vec<f64>,
    /// Output deviation, °C.
    pub y: Vec<f64>,
    /// Input deviation, duty.
    pub u: Vec<f64>,
    /// Means removed.
    pub mean_y: f64,
    /// Means removed.
    pub mean_u: f64,
}

/// Reads and pre-processes a log.
pub fn load(path: &Path, y_column: &str, filter: Option<f64>, prefilter: Option<f64>, decimate: usize) -> Result<Data> {
    let cols = log::read_columns(path, &["t_s", "duty", y_column])?;
    log::check_increasing(path, &cols[0])?;
    if decimate == 0 {
        bail!("--decimate must be at least 1");
    }
    let avg =
        |v: &[f64]| -> Vec<f64> { v.chunks_exact(decimate).map(|c| c.iter().sum::<f64>() / decimate as f64).collect() };
    let first = |v: &[f64]| -> Vec<f64> { v.chunks_exact(decimate).map(|c| c[0]).collect() };
    let (t, u, mut y) = (first(&cols[0]), avg(&cols[1]), avg(&cols[2]));
    if t.len() < 3 {
        bail!("'{}' has {} rows; identification needs many more", path.display(), t.len());
    }
    // The median interval is the sample period; the first interval off by > 5 % is named.
    let mut dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let ts = dts[dts.len() / 2];
    if let Some(i) = t.windows(2).position(|w| ((w[1] - w[0]) - ts).abs() > 0.05 * ts) {
        bail!(
            "'{}' line {}: sample interval {} s differs from the period {} s by more than 5 % (resample the log first)",
            path.display(),
            (i + 1) * decimate + 2,
            t[i + 1] - t[i],
            ts
        );
    }
    let first_order = |name: &str, fa: f64, x: &mut [f64]| -> Result<()> {
        let cfg = FirstOrderConfig::new(fa as f32).ok_or_else(|| anyhow!("--{name} must be in [0, 1), got {fa}"))?;
        let mut f = FirstOrder::default();
        for v in x.iter_mut() {
            *v = f64::from(f.step(&cfg, *v as f32));
        }
        Ok(())
    };
    if let Some(fa) = filter {
        first_order("filter", fa, &mut y)?;
    }
    let mut u = u;
    if let Some(fa) = prefilter {
        first_order("prefilter", fa, &mut y)?;
        first_order("prefilter", fa, &mut u)?;
    }
    let mean_y = y.iter().sum::<f64>() / y.len() as f64;
    let mean_u = u.iter().sum::<f64>() / u.len() as f64;
    Ok(Data {
        ts_s: ts,
        t,
        y: y.iter().map(|v| v - mean_y).collect(),
        u: u.iter().map(|v| v - mean_u).collect(),
        mean_y,
        mean_u,
    })
}

/// Fits and validates one structure.
pub fn fit(d: &Data, s: &Structure, method: Method, forgetting: f64) -> Result<Fit> {
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
    let mut history = Vec::new();
    let theta: Vec<f64> = match method {
        Method::Ls => {
            if s.nc > 0 {
                bail!("method ls fits ARX only: use --method rels for nc > 0");
            }
            let mut ls = BatchLs::new(n).map_err(|e| anyhow!("{e:?}"))?;
            let mut phi = [0.0f64; 12];
            for t in s.first_index()..d.y.len() {
                if s.regressor(&d.y, &d.u, &[], t, &mut phi) {
                    ls.add(&phi[..n], d.y[t]).map_err(|e| anyhow!("{e:?}"))?;
                }
            }
            let mut th = vec![0.0; n];
            ls.solve(&mut th).map_err(|_| {
                anyhow!("the data do not excite the model enough to identify it (singular normal equations)")
            })?;
            th
        }
        Method::Rls | Method::Rels => {
            let cfg = RlsConfig { forgetting: forgetting as f32, p0: 1e4, trace_max: 1e6 };
            let yf: Vec<f32> = d.y.iter().map(|&v| v as f32).collect();
            let uf: Vec<f32> = d.u.iter().map(|&v| v as f32).collect();
            let every = (d.y.len() / 400).max(1);
            let ts = d.ts_s;
            let t0 = d.t[0];
            macro_rules! run_n {
                ($($k:literal),*) => {
                    match n {
                        $($k => {
                            let (r, _) = recursive::run::<$k>(s, &cfg, SVector::zeros(), &yf, &uf, |t, th, _| {
                                if t % every == 0 {
                                    history.push((t0 + t as f64 * ts, th.iter().map(|&v| f64::from(v)).collect()));
                                }
                            })
                            .map_err(|e| anyhow!("estimator failed: {e:?}"))?;
                            r.theta().iter().map(|&v| f64::from(v)).collect()
                        })*
                        _ => bail!("unsupported number of parameters {n}"),
                    }
                };
            }
            run_n!(2, 3, 4, 5, 6, 7, 8, 9, 10)
        }
    };
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
    let a1 = 1.0 + a.iter().sum::<f64>();
    let static_gain = b.iter().sum::<f64>() / a1;
    let time_constants_s =
        poles.iter().map(|p| validate::abs(*p)).filter(|m| *m > 0.0 && *m < 1.0).map(|m| -d.ts_s / m.ln()).collect();
    let resid = &eps[s.first_index()..];
    let mut ac = [0.0; 20];
    validate::autocorrelation(resid, &mut ac);
    let band = 1.96 / (resid.len() as f64).sqrt();
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
        residual_lags_outside_band: ac.iter().filter(|v| v.abs() > band).count(),
        theta_history: history,
        ysim,
    })
}

/// Compares orders 1, 2, 4 (na = nb) and picks the lowest stable one within 3 fit points of
/// the best: extra parameters that do not buy simulation accuracy only add variance (and
/// controller cost on the MCU).
pub fn compare(d: &Data, nk: usize, nc: usize, method: Method, forgetting: f64) -> (Vec<OrderRow>, usize, String) {
    let mut rows = Vec::new();
    for order in [1usize, 2, 4] {
        let Ok(s) = Structure::new(order, order, nc, nk) else {
            continue;
        };
        if let Ok(f) = fit(d, &s, method, forgetting) {
            rows.push(OrderRow { order, fit_percent: f.fit_percent, mse: f.mse, stable: f.stable });
        }
    }
    let best = rows
        .iter()
        .filter(|r| r.stable && r.fit_percent.is_finite())
        .map(|r| r.fit_percent)
        .fold(f64::NEG_INFINITY, f64::max);
    let chosen = rows.iter().find(|r| r.stable && r.fit_percent >= best - 3.0);
    match chosen {
        Some(c) => {
            let higher: Vec<String> = rows
                .iter()
                .filter(|r| r.order > c.order)
                .map(|r| {
                    format!(
                        "order {} fits {:.1} %{}",
                        r.order,
                        r.fit_percent,
                        if r.stable { "" } else { " (unstable)" }
                    )
                })
                .collect();
            let lower: Vec<String> = rows
                .iter()
                .filter(|r| r.order < c.order)
                .map(|r| format!("order {} only {:.1} %", r.order, r.fit_percent))
                .collect();
            let mut reason = format!("order {} fits {:.1} % (best {:.1} %)", c.order, c.fit_percent, best);
            if !higher.is_empty() {
                reason += &format!(
                    "; {} — no more than 3 points better, so the extra parameters are not worth it",
                    higher.join(", ")
                );
            }
            if !lower.is_empty() {
                reason += &format!("; {} — too simple", lower.join(", "));
            }
            (rows.clone(), c.order, reason)
        }
        None => (rows, 0, "no order gave a stable model".into()),
    }
}

/// `hter identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    if !(args.forgetting.is_finite() && args.forgetting > 0.0 && args.forgetting <= 1.0) {
        bail!("--forgetting must be in (0, 1], got {}", args.forgetting);
    }
    let nc = if args.method == Method::Rels && args.nc == 0 { 1 } else { args.nc };
    let s = Structure::new(args.na, args.nb, nc, args.nk).map_err(|_| {
        anyhow!(
            "orders out of range: need na 1–4, nb 1–4, nc 0–2, nk 1–10 (got na={} nb={} nc={} nk={})",
            args.na,
            args.nb,
            nc,
            args.nk
        )
    })?;
    if args.method != Method::Rels && nc > 0 {
        bail!("nc > 0 (ARMAX) needs --method rels");
    }
    let d = load(&args.input, &args.y_column, args.filter, args.prefilter, args.decimate)?;
    let f = fit(&d, &s, args.method, args.forgetting)?;
    let (order_comparison, chosen_order, reason) = compare(&d, s.nk, nc, args.method, args.forgetting);
    if let Some(p) = &args.plot {
        plot_fit(p, &d, &f)?;
    }
    let report = Report {
        fit: f,
        method: args.method,
        ts_s: d.ts_s,
        rows: d.y.len(),
        mean_temp_c: d.mean_y,
        mean_duty: d.mean_u,
        filter: args.filter,
        order_comparison,
        chosen_order,
        reason,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
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
        let sign = if *v < 0.0 {
            "−"
        } else if first {
            ""
        } else {
            "+"
        };
        let term = if k == 0 { format!("{:.6}", v.abs()) } else { format!("{:.6} q⁻{}", v.abs(), k) };
        s += &if first { format!("{sign}{term}") } else { format!(" {sign} {term}") };
        first = false;
    }
    s
}

fn print_report(args: &IdentifyArgs, s: &Structure, r: &Report) {
    let f = &r.fit;
    println!("identification of {} ({} samples, Ts = {:.3} s)", args.input.display(), r.rows, r.ts_s);
    println!(
        "  operating point removed: {:.3} °C, duty {:.3}{}",
        r.mean_temp_c,
        r.mean_duty,
        r.filter.map(|fa| format!("; filtered with F_a = {fa}")).unwrap_or_default()
    );
    let kind = if s.nc > 0 { "ARMAX" } else { "ARX" };
    println!(
        "  {kind}(na={}, nb={}, nc={}, nk={}) by {:?}, λ_f = {}",
        s.na, s.nb, s.nc, s.nk, r.method, args.forgetting
    );
    println!("  {}", poly("A", Some(1.0), &f.a));
    println!("  {}   (delay q⁻{})", poly("B", None, &f.b), f.nk);
    if !f.c.is_empty() {
        println!("  {}", poly("C", Some(1.0), &f.c));
    }
    println!("  one-step MSE        {:.3e} °C²", f.mse);
    println!("  simulated fit       {:.1} %", f.fit_percent);
    println!("  static gain         {:.3} °C per unit duty", f.static_gain_c_per_duty);
    let p: Vec<String> = f
        .poles
        .iter()
        .map(|(re, im)| format!("{re:.5}{:+.5}i (|p| = {:.5})", im, (re * re + im * im).sqrt()))
        .collect();
    println!("  poles               {}  → {}", p.join(", "), if f.stable { "stable" } else { "UNSTABLE" });
    let z: Vec<String> = f.zeros.iter().map(|(re, im)| format!("{re:.4}{im:+.4}i")).collect();
    if !z.is_empty() {
        println!("  zeros               {}", z.join(", "));
    }
    let tc: Vec<String> = f.time_constants_s.iter().map(|t| format!("{t:.0} s")).collect();
    println!("  time constants      {}", tc.join(", "));
    println!("  residual whiteness  {} of 20 autocorrelation lags outside the 95 % band", f.residual_lags_outside_band);
    println!("  order comparison (na = nb, same method and delay):");
    for o in &r.order_comparison {
        println!(
            "    order {}: fit {:6.1} %, MSE {:.3e} °C², {}",
            o.order,
            o.fit_percent,
            o.mse,
            if o.stable { "stable" } else { "unstable" }
        );
    }
    println!("  chosen order: {} — {}", r.chosen_order, r.reason);
}

fn plot_fit(path: &Path, d: &Data, f: &Fit) -> Result<()> {
    let mut panels = Vec::new();
    if !f.theta_history.is_empty() {
        let n = f.theta_history[0].1.len();
        let names: Vec<String> = (0..n)
            .map(|i| {
                if i < f.a.len() {
                    format!("a{}", i + 1)
                } else if i < f.a.len() + f.b.len() {
                    format!("b{}", i - f.a.len())
                } else {
                    format!("c{}", i - f.a.len() - f.b.len() + 1)
                }
            })
            .collect();
        panels.push(plot::Panel {
            title: "Parameter convergence (recursive estimate)".into(),
            y_label: "θ".into(),
            series: (0..n)
                .map(|i| plot::Series {
                    name: names[i].clone(),
                    points: f.theta_history.iter().map(|(t, th)| (*t / 60.0, th[i])).collect(),
                })
                .collect(),
            y_range: None,
        });
    }
    panels.push(plot::Panel {
        title: format!("Measured vs simulated output (fit {:.1} %)", f.fit_percent),
        y_label: "°C".into(),
        series: vec![
            plot::Series {
                name: "measured".into(),
                points: d.t.iter().zip(&d.y).map(|(t, y)| (t / 60.0, y + d.mean_y)).collect(),
            },
            plot::Series {
                name: "simulated".into(),
                points: d.t.iter().zip(&f.ysim).map(|(t, y)| (t / 60.0, y + d.mean_y)).collect(),
            },
        ],
        y_range: None,
    });
    plot::panels(path, "hter identify", "time (min)", &panels)
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
            nk: 1,
            method: Method::Ls,
            forgetting: 1.0,
            filter: None,
            prefilter: None,
            y_column: "temp_c".into(),
            decimate: 1,
            json: true,
            plot: None,
        }
    }

    #[test]
    fn malformed_logs_are_one_line_errors() {
        let missing = write("missing", "t_s,temp_c\n0,1\n");
        let e = run(&args(missing)).unwrap_err().to_string();
        assert!(e.contains("missing column 'duty'"), "{e}");
        let bad = write("bad", "t_s,duty,temp_c\n0,0.5,4\n1,0.5,x\n");
        let e = run(&args(bad)).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("temp_c"), "{e}");
        let few: String =
            std::iter::once("t_s,duty,temp_c\n".to_string()).chain((0..20).map(|i| format!("{i},0.5,4\n"))).collect();
        let e = run(&args(write("few", &few))).unwrap_err().to_string();
        assert!(e.contains("too few rows"), "{e}");
        let mut a = args(write("ok", &few));
        a.forgetting = 1.5;
        assert!(run(&a).unwrap_err().to_string().contains("--forgetting"));
        let jump = write("jump", "t_s,duty,temp_c\n0,0,1\n1,0,1\n2,0,1\n10,0,1\n");
        assert!(run(&args(jump)).unwrap_err().to_string().contains("line 5"));
        for e in [missing_e(), bad_orders()] {
            assert!(!e.contains('\n'));
        }
    }

    fn missing_e() -> String {
        run(&args(PathBuf::from("/no/such.csv"))).unwrap_err().to_string()
    }

    fn bad_orders() -> String {
        let mut a = args(PathBuf::from("/no/such.csv"));
        a.na = 7;
        let e = run(&a).unwrap_err().to_string();
        assert!(e.contains("orders out of range"));
        e
    }
}
