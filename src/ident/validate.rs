//! Model validation on recorded data, in f64 (host tool and tests; no allocation, slices in):
//!
//! - **one-step-ahead MSE**: mean of (y(t) − φ(t)ᵀθ)², the measure the identification
//!   method reports (its 2nd-order models of the real carriers reached 0.0009 and 0.0007 °C²);
//! - **simulated fit**: the model run from the input alone (MATLAB `compare`),
//!   `fit = 100 (1 − ‖y − ŷ_sim‖ / ‖y − ȳ‖)` %;
//! - **poles and zeros**: roots of `z^na A(z⁻¹)` and `z^(nb−1) B(z⁻¹)` (closed form up to
//!   order 2, Durand–Kerner iteration above), with |p| < 1 for stability;
//! - **residual autocorrelation** r(τ)/r(0) for τ = 1…, against the ±1.96/√N whiteness band
//!   (Ljung 1999, §16.6 "Residual analysis");
//! - **order selection** ([`choose_order`]): the lowest order whose model is stable and whose
//!   simulated fit is within a few points of the best stable fit — parsimony (Ljung 1999, §16.4
//!   "Comparing model structures"): parameters that buy no simulation accuracy only add
//!   variance, and on the MCU every extra parameter costs the adaptive controller;
//! - **delay selection** ([`choose_delay`]): the delay whose model simulates the record best
//!   among the stable ones.
//!
//! ```text
//! MSE  = 1/M Σ_t (y(t) − φ(t)ᵀθ)²                 one-step-ahead, t = first index … N−1
//! fit  = 100 · (1 − ‖y − ŷ_sim‖₂ / ‖y − ȳ‖₂)  %    ŷ_sim from A ŷ_sim = q^−nk B u only
//! r(τ) = Σ_t (ε(t) − ε̄)(ε(t+τ) − ε̄) / Σ_t (ε(t) − ε̄)²,   white if |r(τ)| < 1.96/√N
//! ```

use super::model::Structure;

/// A complex number (re, im).
pub type Complex = (f64, f64);

/// One-step-ahead prediction errors ε(t) = y(t) − φ(t)ᵀθ for t ≥ first index, written to
/// `eps` (same length as y; earlier entries 0). For ARMAX the residuals feed back as ê.
/// Returns the mean of ε² over the predicted samples.
pub fn one_step(s: &Structure, theta: &[f64], y: &[f64], u: &[f64], eps: &mut [f64]) -> f64 {
    let n = y.len().min(u.len()).min(eps.len());
    let mut phi = [0.0f64; super::model::MAX_PARAMS];
    let (mut sum, mut count) = (0.0, 0usize);
    for t in 0..n {
        eps[t] = 0.0;
        if t < s.first_index() {
            continue;
        }
        let (head, _) = eps.split_at(t);
        if !s.regressor(y, u, head, t, &mut phi) {
            continue;
        }
        let pred: f64 = phi[..s.n_params()].iter().zip(theta).map(|(a, b)| a * b).sum();
        let e = y[t] - pred;
        eps[t] = e;
        sum += e * e;
        count += 1;
    }
    if count == 0 {
        f64::NAN
    } else {
        sum / count as f64
    }
}

/// Simulates the deterministic part from the input alone into `ysim`, starting from the
/// measured outputs for t < first index. Returns the fit in %.
pub fn simulate_fit(s: &Structure, theta: &[f64], y: &[f64], u: &[f64], ysim: &mut [f64]) -> f64 {
    let n = y.len().min(u.len()).min(ysim.len());
    let start = s.first_index();
    for t in 0..n {
        if t < start {
            ysim[t] = y[t];
            continue;
        }
        let mut v = 0.0;
        for i in 0..s.na {
            v -= theta[i] * ysim[t - 1 - i];
        }
        for i in 0..s.nb {
            v += theta[s.na + i] * u[t - s.nk - i];
        }
        ysim[t] = v;
    }
    fit_percent(&y[..n], &ysim[..n])
}

/// `100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)`.
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> f64 {
    let n = y.len().min(yhat.len());
    if n == 0 {
        return f64::NAN;
    }
    let mean = y[..n].iter().sum::<f64>() / n as f64;
    let num: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b) * (a - b)).sum();
    let den: f64 = y[..n].iter().map(|a| (a - mean) * (a - mean)).sum();
    100.0 * (1.0 - libm::sqrt(num / den))
}

/// Roots of the monic polynomial `z^n + c[0] z^(n−1) + … + c[n−1]` (n ≤ 4) into `out[..n]`.
pub fn roots_monic(c: &[f64], out: &mut [Complex; 4]) -> usize {
    let n = c.len().min(4);
    match n {
        0 => 0,
        1 => {
            out[0] = (-c[0], 0.0);
            1
        }
        2 => {
            let (b, cc) = (c[0], c[1]);
            let disc = b * b - 4.0 * cc;
            if disc >= 0.0 {
                let r = libm::sqrt(disc);
                // Stable form: avoid cancellation between −b and ±r.
                let q = -0.5 * (b + b.signum() * r);
                let (r1, r2) = if q != 0.0 { (q, cc / q) } else { (0.0, 0.0) };
                out[0] = (r1, 0.0);
                out[1] = (r2, 0.0);
            } else {
                let im = libm::sqrt(-disc) / 2.0;
                out[0] = (-b / 2.0, im);
                out[1] = (-b / 2.0, -im);
            }
            2
        }
        _ => {
            // Durand–Kerner (Weierstrass) iteration from the usual non-real start points.
            let f = |z: Complex| {
                let mut acc: Complex = (1.0, 0.0);
                for ci in &c[..n] {
                    acc = cadd(cmul(acc, z), (*ci, 0.0));
                }
                acc
            };
            let mut z = [(0.0, 0.0); 4];
            let mut w: Complex = (1.0, 0.0);
            for zi in z.iter_mut().take(n) {
                *zi = w;
                w = cmul(w, (0.4, 0.9));
            }
            for _ in 0..500 {
                let mut moved = 0.0f64;
                for i in 0..n {
                    let mut den: Complex = (1.0, 0.0);
                    for j in 0..n {
                        if i != j {
                            den = cmul(den, csub(z[i], z[j]));
                        }
                    }
                    let step = cdiv(f(z[i]), den);
                    z[i] = csub(z[i], step);
                    moved = moved.max(step.0.abs() + step.1.abs());
                }
                if moved < 1e-14 {
                    break;
                }
            }
            out[..n].copy_from_slice(&z[..n]);
            n
        }
    }
}

fn cadd(a: Complex, b: Complex) -> Complex {
    (a.0 + b.0, a.1 + b.1)
}
fn csub(a: Complex, b: Complex) -> Complex {
    (a.0 - b.0, a.1 - b.1)
}
fn cmul(a: Complex, b: Complex) -> Complex {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}
fn cdiv(a: Complex, b: Complex) -> Complex {
    let d = b.0 * b.0 + b.1 * b.1;
    if d == 0.0 {
        return (0.0, 0.0);
    }
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// Modulus of a complex number.
pub fn abs(z: Complex) -> f64 {
    libm::sqrt(z.0 * z.0 + z.1 * z.1)
}

/// Normalised autocorrelation r(τ)/r(0) of `x` for τ = 1…out.len().
pub fn autocorrelation(x: &[f64], out: &mut [f64]) {
    let n = x.len();
    let mean = if n > 0 { x.iter().sum::<f64>() / n as f64 } else { 0.0 };
    let r0: f64 = x.iter().map(|v| (v - mean) * (v - mean)).sum();
    for (k, o) in out.iter_mut().enumerate() {
        let tau = k + 1;
        let r: f64 = if tau < n { (0..n - tau).map(|t| (x[t] - mean) * (x[t + tau] - mean)).sum() } else { 0.0 };
        *o = if r0 > 0.0 { r / r0 } else { 0.0 };
    }
}

/// The 95 % confidence band ±1.96/√N of a normalised autocorrelation estimated from N samples
/// of white noise.
pub fn whiteness_band(n: usize) -> f64 {
    if n == 0 {
        f64::INFINITY
    } else {
        1.96 / libm::sqrt(n as f64)
    }
}

/// One model in an order comparison.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrderCandidate {
    /// Model order (na = nb).
    pub order: usize,
    /// Simulated-output fit, %.
    pub fit_percent: f64,
    /// All poles strictly inside the unit circle.
    pub stable: bool,
}

/// Default tolerance of [`choose_order`], fit points: differences of a few points are within
/// what a different record of the same plant changes.
pub const ORDER_TOLERANCE_POINTS: f64 = 3.0;

/// Index of the lowest-order candidate that is stable and fits within `tolerance_points` of the
/// best stable fit; `None` if no candidate is stable with a finite fit.
pub fn choose_order(candidates: &[OrderCandidate], tolerance_points: f64) -> Option<usize> {
    let usable = |c: &OrderCandidate| c.stable && c.fit_percent.is_finite();
    let best = candidates.iter().filter(|c| usable(c)).map(|c| c.fit_percent).fold(f64::NEG_INFINITY, f64::max);
    candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| usable(c) && c.fit_percent >= best - tolerance_points)
        .min_by_key(|(_, c)| c.order)
        .map(|(i, _)| i)
}

/// One model in a delay scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DelayCandidate {
    /// Simulated-output fit, %.
    pub fit_percent: f64,
    /// All poles strictly inside the unit circle.
    pub stable: bool,
}

/// Index of the candidate with the best simulated fit among those that are stable with a
/// finite fit (the first of equal fits: the shortest delay of a scan in increasing order); the
/// first candidate if none is, so that a scan still reports a model; `None` for no candidates.
pub fn choose_delay(candidates: &[DelayCandidate]) -> Option<usize> {
    let rank = |c: &DelayCandidate| {
        if c.stable && c.fit_percent.is_finite() {
            c.fit_percent
        } else {
            f64::NEG_INFINITY
        }
    };
    let mut best = None;
    for (i, c) in candidates.iter().enumerate() {
        if best.is_none_or(|b: usize| candidates.get(b).is_some_and(|b| rank(c) > rank(b))) {
            best = Some(i);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_model_fits_100_percent_with_zero_error() {
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let th = [-1.5, 0.56, 0.5, 0.25];
        let n = 200;
        let u: std::vec::Vec<f64> = (0..n).map(|t| if (t / 10) % 2 == 0 { 1.0 } else { 0.0 }).collect();
        let mut y = std::vec![0.0; n];
        for t in 2..n {
            y[t] = 1.5 * y[t - 1] - 0.56 * y[t - 2] + 0.5 * u[t - 1] + 0.25 * u[t - 2];
        }
        let mut e = std::vec![0.0; n];
        assert!(one_step(&s, &th, &y, &u, &mut e) < 1e-24);
        let mut ys = std::vec![0.0; n];
        assert!((simulate_fit(&s, &th, &y, &u, &mut ys) - 100.0).abs() < 1e-9);
    }

    #[test]
    fn mse_by_hand() {
        // y(t) = 0.5 y(t−1) + u(t−1) predicted with a = −0.5, b = 1; data off by 0.1 and −0.2.
        let s = Structure::new(1, 1, 0, 1).unwrap();
        let y = [0.0, 1.1, 1.35];
        let u = [1.0, 1.0, 0.0];
        let mut e = [0.0; 3];
        // ε(1) = 1.1 − (0.5·0 + 1) = 0.1; ε(2) = 1.35 − (0.55 + 1) = −0.2 → MSE = 0.025.
        assert!((one_step(&s, &[-0.5, 1.0], &y, &u, &mut e) - 0.025).abs() < 1e-12);
    }

    #[test]
    fn poles_of_known_polynomials() {
        let mut r = [(0.0, 0.0); 4];
        // (z − 0.9)(z − 0.5) = z² − 1.4 z + 0.45
        assert_eq!(roots_monic(&[-1.4, 0.45], &mut r), 2);
        let mut re = [r[0].0, r[1].0];
        re.sort_by(f64::total_cmp);
        assert!((re[0] - 0.5).abs() < 1e-12 && (re[1] - 0.9).abs() < 1e-12);
        // z² − z + 0.5: 0.5 ± 0.5 i, |p| = 0.7071
        roots_monic(&[-1.0, 0.5], &mut r);
        assert!((abs(r[0]) - 0.5f64.sqrt()).abs() < 1e-12 && (r[0].1.abs() - 0.5).abs() < 1e-12);
        // (z − 0.9)²(z − 0.5)² = z⁴ − 2.8 z³ + 2.86 z² − 1.26 z + 0.2025
        assert_eq!(roots_monic(&[-2.8, 2.86, -1.26, 0.2025], &mut r), 4);
        let mut m: std::vec::Vec<f64> = r.iter().map(|z| abs(*z)).collect();
        m.sort_by(f64::total_cmp);
        assert!((m[0] - 0.5).abs() < 1e-5 && (m[3] - 0.9).abs() < 1e-5, "{m:?}");
    }

    #[test]
    fn order_choice_prefers_the_simplest_adequate_stable_model() {
        let c = |order, fit_percent, stable| OrderCandidate { order, fit_percent, stable };
        // 2nd order within 3 points of the best: chosen over 4th; 1st is too poor.
        let rows = [c(1, 80.0, true), c(2, 94.0, true), c(4, 96.5, true)];
        assert_eq!(choose_order(&rows, 3.0), Some(1));
        // The best is unstable: it does not count.
        let rows = [c(1, 80.0, true), c(2, 81.0, true), c(4, 99.0, false)];
        assert_eq!(choose_order(&rows, 3.0), Some(0));
        let rows = [c(1, 80.0, false), c(2, f64::NAN, true)];
        assert_eq!(choose_order(&rows, 3.0), None);
        assert!((whiteness_band(400) - 0.098).abs() < 1e-12);
    }

    #[test]
    fn delay_choice_takes_the_best_stable_fit_and_the_first_of_equals() {
        let c = |fit_percent, stable| DelayCandidate { fit_percent, stable };
        // The unstable best and the NaN do not count; of the two 90s the first is kept.
        let scan = [c(80.0, true), c(90.0, true), c(99.0, false), c(90.0, true), c(f64::NAN, true)];
        assert_eq!(choose_delay(&scan), Some(1));
        // None usable: the first still stands for the scan.
        assert_eq!(choose_delay(&[c(95.0, false), c(f64::INFINITY, true)]), Some(0));
        assert_eq!(choose_delay(&[]), None);
    }

    #[test]
    fn white_noise_is_white_and_a_sine_is_not() {
        let mut seed = 1u64;
        let x: std::vec::Vec<f64> = (0..4000)
            .map(|_| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        let mut r = [0.0; 10];
        autocorrelation(&x, &mut r);
        assert!(r.iter().all(|v| v.abs() < 1.96 / (4000f64).sqrt() * 2.0), "{r:?}");
        let s: std::vec::Vec<f64> = (0..4000).map(|t| (t as f64 * 0.05).sin()).collect();
        autocorrelation(&s, &mut r);
        assert!(r[0] > 0.9);
    }
}
