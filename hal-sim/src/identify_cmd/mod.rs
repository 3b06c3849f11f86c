//! `hter identify`: fit an ARX/ARMAX model to a logged run.
//!
//! `hter identify --input prbs.csv` (the defaults `--method oe --nk auto --operating-point
//! auto`) answers which order the carrier needs by the criterion the answer is judged on, the
//! simulated fit: output error, each order at its best delay, from
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
//!    gain and the simulated fit (on a logged step of a TCLab heater: fit ≈ 96 % from the
//!    initial rest, ≈ 0 % around the means). `--operating-point mean` remains for logs that do not start
//!    at rest (e.g. a long closed-loop record around a setpoint).
//! 6. Estimate (`--method`):
//!    - `oe` (default): **output error**, minimising V = Σ (y − q^−nk B/A u)², the error of the
//!      model simulated from the input alone ([`hter::ident::oe`]: Levenberg–Marquardt with the
//!      gradient ψ = φ_x/A, Ljung 1999 §10.2–10.3; A kept stable). Equation-error methods
//!      (LS, RLS, IV) minimise A y − B u, which weights the fit by |A(e^{iω})|², a high-pass on
//!      this slow plant (Ljung §8.5): on the H-TER I PRBS run IV's 2nd-order model simulates at
//!      66 % where OE's reaches 95 %. V is not convex, so the search runs from several starts
//!      and keeps the lowest V ([`hter::ident::oe_search`]: the IV and LS estimates, the same
//!      structure at the neighbouring delay, and the lower-order OE model with an extra pole).
//!      Since one start is the lower-order model itself, each order fits at least as well as
//!      the one below it. ARX structure only (nc = 0); f64, on the host.
//!    - `ls`, `iv`: batch least squares and instrumental variables in f64
//!      ([`hter::ident::batch::least_squares`], [`hter::ident::batch::instrumental_variables`]:
//!      least squares, then rounds with instruments simulated from the previous model).
//!    - `rls`, `rels`: the firmware's f32 estimators (RLS for ARX, RELS for ARMAX, with
//!      forgetting λ_f; [`hter::ident::recursive::run`]) on signals scaled to order one
//!      (ỹ / max|ỹ|, ũ / max|ũ|; b is scaled back afterwards); the reported parameters are the
//!      final estimates θ(N).
//!
//!    The delay (`--nk`): a number of samples 1–10, or `auto` (default): the structure is fitted
//!    at every delay 1–10 and the one with the best stable simulated fit is kept — per order in
//!    the comparison ([`hter::ident::validate::choose_delay`]; each order at its own best
//!    delay, so no order is judged at a delay chosen
//!    for another; a 1st-order model takes a longer delay to stand in for the lags it lacks).
//!    The scan is reported (`delay_scan`, `delay_reason`; `nk` is the reported model's delay).
//!    Dead time, RTD lag and the F_a filter add up to 40–90 s on the carriers; on H-TER I the
//!    2nd-order fit climbs from 84.7 % at nk = 1 to 94.8 % at nk = 9.
//! 7. Validate ([`hter::ident::validate`]): one-step-ahead MSE (°C², on the data the model was
//!    estimated from; the ARX predictor ŷ = φᵀθ with the estimated θ for every method, so
//!    every method's MSE is the same measure), simulated-output fit % (the model run from the input
//!    alone, starting from the measured initial condition, as MATLAB `compare`), poles and
//!    zeros with stability, static gain B(1)/A(1) in °C per unit duty, time constants −Ts/ln p
//!    of the real positive poles, and the residual autocorrelation at lags 1–20 against
//!    ±1.96/√N (of the ARX one-step residuals: for an OE model they are not expected to be
//!    white, its noise model is H = 1 on the output).
//! 8. Compare orders 1, 2 and 4 (na = nb, same method and nc; the given delay or each order's
//!    best) and pick the lowest stable order within
//!    [`hter::ident::validate::ORDER_TOLERANCE_POINTS`] fit points of the best
//!    ([`hter::ident::validate::choose_order`]); the report says why, against every other
//!    order. `--auto-order` makes that the reported model instead of the requested one (default
//!    na = nb = 2).
//!
//! # Layout
//!
//! - `args`: the command-line arguments.
//! - `load`: reading the log and the pre-processing of steps 1–5.
//! - `fit`: estimation, validation, the delay scan and the order comparison (steps 6–8; the
//!   estimators themselves are in [`hter::ident`]).
//! - `report`: the text and JSON reports; `plot`: the `--plot` figure.

mod args;
mod fit;
mod load;
mod plot;
mod report;
#[cfg(test)]
mod test_logs;

use anyhow::{bail, Context, Result};
use hter::ident::model::Structure;
use hter::ident::oe_search::OeMemo;

pub use args::{Delay, IdentifyArgs, Method, OperatingPointChoice};
pub use fit::{compare, fit, Comparison, DelayRow, Fit, OrderRow};
pub use load::{load, Data, OperatingPoint};
pub use report::Report;

use fit::{delay_reason, fit_delay, orders_error};

/// Smallest forgetting factor λ_f `--forgetting` accepts. RLS with λ_f remembers about
/// 1/(1 − λ_f) samples, and it must remember at least as many as the smallest model has
/// parameters (two: na = nb = 1) to determine them; below that each update fits the last sample
/// alone (λ_f = 1e-10 gave B ≈ ±6e6 and an unstable A, with exit 0).
pub const FORGETTING_MIN: f32 = 0.5;

/// `hter identify`.
pub fn run(args: &IdentifyArgs) -> Result<()> {
    // The estimator runs in f32: checked as it will run (1e-50 was 0 there, and then 1).
    let forgetting_arg = args.forgetting.unwrap_or(1.0);
    let forgetting = crate::sim_cmd::single("forgetting", forgetting_arg)?;
    if !(FORGETTING_MIN..=1.0).contains(&forgetting) {
        bail!("--forgetting must be in [{FORGETTING_MIN}, 1], got {}", crate::sim_cmd::shown(forgetting_arg));
    }
    // The batch methods forget nothing: `--forgetting 0.9` was ignored, and the JSON still
    // said "forgetting": 0.9. 1 (no forgetting) is what they do, and stays accepted.
    if args.forgetting.is_some_and(|f| f != 1.0) && !matches!(args.method, Method::Rls | Method::Rels) {
        let m = format!("{:?}", args.method).to_lowercase();
        bail!("--forgetting applies to --method rls and rels only: --method {m} has no forgetting");
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
    let cmp = compare(&d, args.nk, nc, args.method, forgetting_arg, &mut memo);
    let (na, nb) = if args.auto_order && cmp.chosen > 0 { (cmp.chosen, cmp.chosen) } else { (args.na, args.nb) };
    let done = cmp.fits.iter().find(|(order, _, _)| na == nb && *order == na);
    let (f, scan) = match done {
        Some((_, f, scan)) => (f.clone(), scan.clone()),
        None => fit_delay(&d, na, nb, nc, args.nk, args.method, forgetting_arg, &mut memo)?,
    };
    let s = Structure::new(na, nb, nc, f.nk).map_err(|_| orders_error(na, nb, nc, f.nk))?;
    if let Some(p) = &args.plot {
        plot::plot_fit(p, &d, &s, &f)?;
    }
    let delay_reason = delay_reason(&f, &scan, d.ts_s);
    let report = Report {
        fit: f,
        na: s.na,
        nb: s.nb,
        method: args.method,
        forgetting: forgetting_arg,
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
    let text = if args.json { serde_json::to_string(&report)? + "\n" } else { report::report_text(args, &s, &report) };
    // One write: a full disk is the one-line error `main` gives every command, not an exit 0
    // with the report lost (a closed pipe ends the process at the write, as it ends `cat`).
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes()).and_then(|()| out.flush()).context("cannot write to stdout")
}

#[cfg(test)]
mod tests {
    use super::test_logs::{args, err, synthetic_log, write};
    use super::*;
    use std::path::PathBuf;

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
        let few: String = std::iter::once("t_s,duty,temp_c\n".to_string())
            .chain((0..20).map(|i| format!("{i},0.{},4.{i}\n", i % 2 + 4)))
            .collect();
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
        for bad in [0.0, 1.5, -0.5, 0.49] {
            let mut a = args(ok.clone());
            a.forgetting = Some(bad);
            assert!(err(&a).contains("--forgetting must be in [0.5, 1]"), "{bad}");
        }
        // Not a number, or one the estimator's f32 cannot hold (1e-50 was 0 there).
        for (bad, why) in [(f64::NAN, "finite"), (1e-50, "too small"), (1e39, "too large")] {
            let mut a = args(ok.clone());
            a.forgetting = Some(bad);
            assert!(err(&a).contains(why), "{bad}");
        }
        // A batch method has no forgetting to apply: 0.9 was ignored, and the JSON said 0.9.
        for method in [Method::Ls, Method::Iv, Method::Oe] {
            let mut a = args(ok.clone());
            (a.method, a.forgetting) = (method, Some(0.9));
            assert!(err(&a).contains("--forgetting applies to --method rls and rels only"), "{method:?}");
        }
        // 1 is no forgetting, what a batch method does: accepted (SPEC §3's `--method ls
        // --forgetting L`).
        let mut a = args(ok.clone());
        a.forgetting = Some(1.0);
        assert!(run(&a).is_ok());
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
}
