//! The reports of `hter identify`: one JSON object (`--json`) or the text summary.

use hter::ident::model::Structure;
use hter::ident::validate::{self, Complex};
use serde::Serialize;

use super::args::{Delay, IdentifyArgs, Method, OperatingPointChoice};
use super::fit::{is_real, is_real_lag, DelayRow, Fit, OrderRow, LAGS, STABLE_ABS_BELOW};
use super::load::OperatingPoint;

/// A dominant time constant beyond this many record lengths is flagged in the text report: the
/// record cannot tell such a pole from an integrator (on a TCLab heater log that drifts, the OE
/// models put a pole within 1e-10 of 1 to follow the drift), so the static gain B(1)/A(1)
/// divides by almost nothing.
const SLOW_POLE_RECORDS: f64 = 10.0;

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

/// `name(q⁻¹) = …` with six decimals: `lead` is written before `c` (the 1 of A and C; none
/// for B).
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

/// `re` for a real number, `re±im i` otherwise.
fn fmt_complex(p: &Complex) -> String {
    if is_real(p) {
        format!("{:.5}", p.0)
    } else {
        format!("{:.5}{:+.5}i", p.0, p.1)
    }
}

/// A pole with its modulus and what it means physically.
fn describe_pole(p: &Complex, ts: f64) -> String {
    let m = validate::abs(*p);
    let kind = if m >= STABLE_ABS_BELOW {
        "on or outside the unit circle: not stable".to_string()
    } else if is_real_lag(p) {
        format!("τ = {:.1} s", -ts / m.ln())
    } else if is_real(p) {
        "real ≤ 0: alternating, no physical time constant".to_string()
    } else {
        format!("complex, envelope τ = {:.1} s", -ts / m.ln())
    };
    format!("{} (|p| = {m:.5}, {kind})", fmt_complex(p))
}

/// The text report, printed by the caller in one write.
pub(super) fn report_text(args: &IdentifyArgs, s: &Structure, r: &Report) -> String {
    let mut out = String::new();
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
        compact(r.ts_s),
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
    line!("    {}   (delay nk = {} × Ts = {} s)", poly("B", None, &f.b), f.nk, compact(r.dead_time_s));
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
    out
}

/// A time in seconds for people: 12 significant digits, which hides the binary rounding of a
/// period taken from decimal timestamps (1e-5 s, not 0.000010000000000000026 s) and keeps every
/// digit a log's period has; exponent form beyond everyday magnitudes.
pub(super) fn compact(s: f64) -> String {
    let rounded = format!("{s:.11e}").parse().unwrap_or(s);
    crate::sim_cmd::shown(rounded)
}

/// A simulated fit for people: an unstable model's simulation diverges, and its "fit" of
/// −10⁸⁰ % says nothing the word "unstable" does not (the JSON keeps the number).
pub(super) fn fmt_fit(fit_percent: f64, stable: bool) -> String {
    if stable && fit_percent.is_finite() {
        format!("{fit_percent:.1} %")
    } else {
        "–".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::super::fit::{compare, fit};
    use super::super::load::load;
    use super::super::test_logs::{synthetic_log, write};
    use super::*;
    use hter::ident::oe_search::OeMemo;

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
