//! Output-error (OE) identification in f64: the parameters of `x = q^−nk B/A u` that make the
//! model's **simulated** output match the record, by a damped Gauss–Newton (Levenberg–Marquardt)
//! search. Host side (`hter identify --method oe`); no allocation, slices in, like
//! [`super::validate`].
//!
//! # Why
//!
//! ARX least squares minimises the one-step-ahead *equation* error `A y − q^−nk B u`, which
//! weights the model's fit by A(e^{iω}) — on a slow plant with poles near 1 that is a high-pass
//! weighting: LS buys sample-to-sample detail (sensor lag, quantisation, noise colour) at the
//! price of the slow dynamics and the static gain (Ljung 1999, §8.5 "frequency-domain
//! description of the limit model"). Instrumental variables remove the noise bias but keep the
//! equation-error weighting. What a controller's predictions and the simulated fit of MATLAB
//! `compare` need is the *output* error, which this module minimises directly.
//!
//! # Equations
//!
//! Output-error model (Ljung 1999, §4.2, the OE structure, with Ljung's F written A here) and its
//! criterion, the sum of squared simulation errors from the measured initial condition (the
//! same simulation as [`super::validate::simulate_fit`], so minimising V maximises the fit):
//!
//! ```text
//! y(t) = q^−nk B(q⁻¹)/A(q⁻¹) u(t) + e(t)
//! x(t) = −a1 x(t−1) − … − a_na x(t−na) + b0 u(t−nk) + … + b_{nb−1} u(t−nk−nb+1) = φ_x(t)ᵀθ
//! x(t) = y(t) for t < t0 = first index of the structure;   ε(t) = y(t) − x(t)
//! V(θ) = Σ_{t ≥ t0} ε(t)²
//! ```
//!
//! Gradient of the simulated output (Ljung 1999, §10.3 "computing gradients", the OE case;
//! Söderström & Stoica, *System Identification*, 1989, ch. 7 "prediction error methods"):
//! differentiating the recursion gives the regressor built from the *simulated* output,
//! filtered through 1/A:
//!
//! ```text
//! ψ(t) = ∂x(t)/∂θ = φ_x(t) − a1 ψ(t−1) − … − a_na ψ(t−na),   ψ(t) = 0 for t < t0
//! ```
//!
//! Levenberg–Marquardt step (Ljung 1999, §10.2, Gauss–Newton with the Levenberg–Marquardt
//! regularisation; Marquardt, "An algorithm for least-squares estimation of nonlinear
//! parameters", *SIAM J. Appl. Math.* 11(2), 1963, with his diagonal scaling):
//!
//! ```text
//! R = Σ ψψᵀ,  g = Σ ψ ε,   (R + μ·diag(R)) δ = g,   θ ← θ + δ   if V(θ + δ) < V(θ) and A stable
//! ```
//!
//! An accepted step divides μ by [`MU_DOWN`]; a step that does not lower V, or that puts a root
//! of A on or outside the unit circle (the simulation and hence the predictor would diverge:
//! the OE predictor is stable only for stable A, Ljung §4.2), is refused and μ grows by
//! [`MU_UP`], which shortens the step and turns it toward the gradient. Since every accepted
//! step lowers V and stays stable, the search never leaves the stability region it starts in.
//! The search stops when a step lowers V by less than a relative `rel_tolerance`, or V is
//! zero to rounding, or no μ up to [`MU_MAX`] gives a descent (a minimum to working
//! precision), or after `max_iterations`.
//!
//! V is not convex in θ (Ljung 1999, §10.5 "local solutions and initial values"): the search
//! finds the local minimum its start leads to. [`super::oe_search`] runs it from several starts
//! (the IV estimate, least squares and a few 2nd-pole starts built from the lower-order OE
//! model) and keeps the best.
//!
//! # Glossary
//!
//! - x — simulated output; ε — output error y − x; V — criterion Σε².
//! - φ_x — the ARX regressor built from x instead of y; ψ — gradient ∂x/∂θ.
//! - R, g — Gauss–Newton Hessian approximation and gradient; δ — step; μ — damping.

use super::batch::solve_symmetric;
use super::model::{Structure, MAX_PARAMS};
use super::validate;

/// Damping divides by this after an accepted step.
pub const MU_DOWN: f64 = 5.0;
/// Damping multiplies by this after a refused step.
pub const MU_UP: f64 = 10.0;
/// Largest damping tried before the search counts as converged: with μ·diag(R) 10¹⁰ times R
/// the step is a gradient step of negligible length, so no descent is left to find.
pub const MU_MAX: f64 = 1e10;

/// Outputs larger than this (in the data's unit) count as a diverged simulation.
const DIVERGED: f64 = 1e12;

/// Search settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OeConfig {
    /// Most Gauss–Newton iterations.
    pub max_iterations: u32,
    /// Stop when an accepted step lowers V by less than this fraction of V.
    pub rel_tolerance: f64,
    /// Initial damping μ (relative to diag R).
    pub mu0: f64,
}

impl OeConfig {
    /// 200 iterations, relative tolerance 1e-10, μ₀ = 1e-3. On the 2 340-sample PRBS runs the
    /// searches end in 5–60 iterations; the tolerance is far below what changes a fit in its
    /// first decimal (fit depends on √V).
    pub const DEFAULT: OeConfig = OeConfig { max_iterations: 200, rel_tolerance: 1e-10, mu0: 1e-3 };
}

impl Default for OeConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why the search could not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OeError {
    /// nc > 0 (OE fits B/A only), or θ shorter than na + nb.
    Structure,
    /// Records shorter than the structure needs, or a non-finite value in y, u or θ.
    Input,
    /// The start has a root of A on or outside the unit circle (its simulation diverges).
    Unstable,
}

/// How a search ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OeOutcome {
    /// V at the start.
    pub initial_cost: f64,
    /// V at the end.
    pub cost: f64,
    /// Accepted steps.
    pub iterations: u32,
    /// Stopped on the tolerance or at a minimum, not on `max_iterations`.
    pub converged: bool,
}

/// Largest modulus of the roots of A = 1 + a1 q⁻¹ + … (na ≤ 4); 0 for na = 0.
pub fn max_pole_modulus(a: &[f64]) -> f64 {
    let mut r = [(0.0, 0.0); 4];
    let n = validate::roots_monic(a, &mut r);
    r[..n].iter().map(|p| validate::abs(*p)).fold(0.0, f64::max)
}

/// True if every root of A is strictly inside the unit circle and every coefficient finite.
pub fn is_stable(a: &[f64]) -> bool {
    a.iter().all(|v| v.is_finite()) && max_pole_modulus(a) < 1.0
}

/// V(θ) = Σ_{t ≥ t0} (y − x)², x simulated as in the module docs; +∞ if the simulation
/// diverges or a value is not finite.
pub fn cost(s: &Structure, theta: &[f64], y: &[f64], u: &[f64]) -> f64 {
    pass(s, theta, y, u, None)
}

/// Σψψᵀ and Σψε of one pass.
struct Normal {
    r: [[f64; MAX_PARAMS]; MAX_PARAMS],
    g: [f64; MAX_PARAMS],
}

/// One simulation of the record: returns V and, with `normal`, accumulates R and g.
fn pass(s: &Structure, theta: &[f64], y: &[f64], u: &[f64], mut normal: Option<&mut Normal>) -> f64 {
    let (na, nb, n) = (s.na, s.nb, s.na + s.nb);
    let len = y.len().min(u.len());
    let t0 = s.first_index();
    // x(t−1−i) and ψ(t−1−i), i = 0 … na−1.
    let mut xh = [0.0f64; 4];
    let mut ph = [[0.0f64; MAX_PARAMS]; 4];
    if let Some(nm) = normal.as_deref_mut() {
        nm.r = [[0.0; MAX_PARAMS]; MAX_PARAMS];
        nm.g = [0.0; MAX_PARAMS];
    }
    let mut v = 0.0;
    for t in 0..len {
        let (x, psi) = if t < t0 {
            (y[t], [0.0f64; MAX_PARAMS])
        } else {
            let mut phi = [0.0f64; MAX_PARAMS];
            for i in 0..na {
                phi[i] = -xh[i];
            }
            for j in 0..nb {
                phi[na + j] = u[t - s.nk - j];
            }
            let x: f64 = phi[..n].iter().zip(theta).map(|(p, th)| p * th).sum();
            if !(x.abs() < DIVERGED) {
                return f64::INFINITY;
            }
            let e = y[t] - x;
            v += e * e;
            let mut psi = phi;
            if let Some(nm) = normal.as_deref_mut() {
                for i in 0..na {
                    for k in 0..n {
                        psi[k] -= theta[i] * ph[i][k];
                    }
                }
                for k in 0..n {
                    for l in 0..=k {
                        nm.r[k][l] += psi[k] * psi[l];
                    }
                    nm.g[k] += psi[k] * e;
                }
            }
            (x, psi)
        };
        for i in (1..na).rev() {
            xh[i] = xh[i - 1];
            ph[i] = ph[i - 1];
        }
        if na > 0 {
            xh[0] = x;
            ph[0] = psi;
        }
    }
    if let Some(nm) = normal {
        for k in 0..n {
            for l in k + 1..n {
                nm.r[k][l] = nm.r[l][k];
            }
        }
    }
    if v.is_finite() {
        v
    } else {
        f64::INFINITY
    }
}

/// Refines θ = [a1 … a_na, b0 … b_{nb−1}] in place toward the nearest minimum of V (module docs).
/// `theta` keeps the best point found; its A stays stable.
pub fn refine(s: &Structure, cfg: &OeConfig, theta: &mut [f64], y: &[f64], u: &[f64]) -> Result<OeOutcome, OeError> {
    let n = s.na + s.nb;
    if s.nc > 0 || theta.len() < n {
        return Err(OeError::Structure);
    }
    let len = y.len().min(u.len());
    if len <= s.first_index() + n || y[..len].iter().chain(&u[..len]).chain(&theta[..n]).any(|v| !v.is_finite()) {
        return Err(OeError::Input);
    }
    if !is_stable(&theta[..s.na]) {
        return Err(OeError::Unstable);
    }
    let mut normal = Normal { r: [[0.0; MAX_PARAMS]; MAX_PARAMS], g: [0.0; MAX_PARAMS] };
    let mut v = pass(s, theta, y, u, Some(&mut normal));
    if !v.is_finite() {
        return Err(OeError::Unstable);
    }
    let initial_cost = v;
    let energy: f64 = y[s.first_index()..len].iter().map(|v| v * v).sum();
    let mut mu = cfg.mu0;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < cfg.max_iterations {
        if v <= 1e-28 * energy {
            converged = true;
            break;
        }
        let dmax = (0..n).map(|k| normal.r[k][k]).fold(0.0f64, f64::max);
        let mut accepted = None;
        while mu <= MU_MAX {
            let mut m = normal.r;
            for k in 0..n {
                // A floor on the scaling keeps a parameter the data hardly see damped too.
                m[k][k] += mu * normal.r[k][k].max(1e-12 * dmax);
            }
            let mut delta = [0.0f64; MAX_PARAMS];
            if solve_symmetric(&m, &normal.g, n, &mut delta).is_ok() {
                let mut trial = [0.0f64; MAX_PARAMS];
                for k in 0..n {
                    trial[k] = theta[k] + delta[k];
                }
                if is_stable(&trial[..s.na]) {
                    let vt = cost(s, &trial[..n], y, u);
                    if vt < v {
                        accepted = Some((trial, vt));
                        break;
                    }
                }
            }
            mu *= MU_UP;
        }
        let Some((trial, vt)) = accepted else {
            converged = true;
            break;
        };
        theta[..n].copy_from_slice(&trial[..n]);
        iterations += 1;
        let small = v - vt <= cfg.rel_tolerance * v;
        v = pass(s, theta, y, u, Some(&mut normal));
        mu = (mu / MU_DOWN).max(1e-15);
        if small {
            converged = true;
            break;
        }
    }
    Ok(OeOutcome { initial_cost, cost: v, iterations, converged })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// u: a ±1 PRBS-like square sequence held `hold` samples (15-bit LFSR).
    pub(crate) fn input(n: usize, hold: usize) -> std::vec::Vec<f64> {
        let mut state = 0xACE1u16;
        (0..n)
            .map(|t| {
                if t % hold == 0 {
                    let bit = (state ^ (state >> 2) ^ (state >> 3) ^ (state >> 5)) & 1;
                    state = (state >> 1) | (bit << 15);
                }
                if state & 1 == 1 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect()
    }

    /// Simulates `theta` on `u` from rest.
    pub(crate) fn simulate(s: &Structure, theta: &[f64], u: &[f64]) -> std::vec::Vec<f64> {
        let zeros = std::vec![0.0; u.len()];
        let mut y = std::vec![0.0; u.len()];
        validate::simulate_fit(s, theta, &zeros, u, &mut y);
        y
    }

    /// A known 2nd-order OE system with a 3-sample delay, noise free: the search must find it
    /// exactly from a poor start (poles 0.5 and 0.3 instead of 0.95 and 0.8, gain 1/4 of true).
    #[test]
    fn recovers_an_exact_output_error_system_from_a_poor_start() {
        let s = Structure::new(2, 2, 0, 3).unwrap();
        // A = (1 − 0.95 q⁻¹)(1 − 0.8 q⁻¹), B = 0.02 + 0.01 q⁻¹: gain 0.03/0.01 = 3.
        let truth = [-1.75, 0.76, 0.02, 0.01];
        let u = input(1500, 7);
        let y = simulate(&s, &truth, &u);
        let mut th = [-0.8, 0.15, 0.1, 0.0];
        let out = refine(&s, &OeConfig::DEFAULT, &mut th, &y, &u).unwrap();
        assert!(out.converged && out.cost < 1e-20 * out.initial_cost, "{out:?}");
        for (got, want) in th.iter().zip(truth) {
            assert!((got - want).abs() < 1e-6, "{th:?}");
        }
        let mut ys = std::vec![0.0; y.len()];
        assert!(validate::simulate_fit(&s, &th, &y, &u, &mut ys) > 99.9999);
    }

    /// A 3rd-order plant, (1 − 0.97 q⁻¹)(1 − 0.7 q⁻¹)(1 − 0.5 q⁻¹) with B = 0.0045 (gain
    /// 0.0045/(0.03·0.3·0.5) = 1), on [`input`], plus noise through 1/(1 − 0.9 q⁻¹): slow and
    /// coloured. Returns (y, u).
    pub(crate) fn mismatched_record() -> (std::vec::Vec<f64>, std::vec::Vec<f64>) {
        let s3 = Structure::new(3, 1, 0, 1).unwrap();
        let u = input(3000, 25);
        let x = simulate(&s3, &[-2.17, 1.514, -0.3395, 0.0045], &u);
        let mut seed = 12345u32;
        let mut v = 0.0;
        let y = x
            .iter()
            .map(|xt| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                v = 0.9 * v + 0.02 * (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5);
                xt + v
            })
            .collect();
        (y, u)
    }

    /// The criterion is the simulation error: data from a 3rd-order plant plus coloured noise,
    /// fitted with a 2nd-order model. Least squares (equation error) favours the one-step
    /// detail; OE simulates the record better and finds the static gain.
    #[test]
    fn output_error_beats_least_squares_under_mismatch_and_coloured_noise() {
        let (y, u) = mismatched_record();
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let mut ls = super::super::batch::BatchLs::new(4).unwrap();
        let mut phi = [0.0; MAX_PARAMS];
        for t in s.first_index()..y.len() {
            s.regressor(&y, &u, &[], t, &mut phi);
            ls.add(&phi[..4], y[t]).unwrap();
        }
        let mut th_ls = [0.0; 4];
        ls.solve(&mut th_ls).unwrap();
        let mut th = th_ls;
        let out = refine(&s, &OeConfig::DEFAULT, &mut th, &y, &u).unwrap();
        assert!(out.cost < out.initial_cost, "{out:?}");
        let mut ys = std::vec![0.0; y.len()];
        let fit_ls = validate::simulate_fit(&s, &th_ls, &y, &u, &mut ys);
        let fit_oe = validate::simulate_fit(&s, &th, &y, &u, &mut ys);
        let gain = |th: &[f64]| (th[2] + th[3]) / (1.0 + th[0] + th[1]);
        // Measured: OE fit 97.3 %, gain 0.998; LS 91.4 %, gain 1.086.
        assert!(fit_oe > fit_ls + 4.0 && fit_oe > 95.0, "OE {fit_oe} % vs LS {fit_ls} %");
        assert!((gain(&th) - 1.0).abs() < 0.01, "OE gain {}", gain(&th));
        assert!((gain(&th_ls) - 1.0).abs() > 2.0 * (gain(&th) - 1.0).abs(), "LS gain {}", gain(&th_ls));
        assert!(is_stable(&th[..2]));
    }

    #[test]
    fn refuses_unstable_starts_armax_and_short_records() {
        let s = Structure::new(1, 1, 0, 1).unwrap();
        let u = input(100, 3);
        let y = simulate(&s, &[-0.5, 1.0], &u);
        assert_eq!(refine(&s, &OeConfig::DEFAULT, &mut [-1.01, 1.0], &y, &u), Err(OeError::Unstable));
        assert_eq!(refine(&s, &OeConfig::DEFAULT, &mut [-0.5, f64::NAN], &y, &u), Err(OeError::Input));
        assert_eq!(refine(&s, &OeConfig::DEFAULT, &mut [-0.5, 1.0], &y[..3], &u[..3]), Err(OeError::Input));
        let armax = Structure::new(1, 1, 1, 1).unwrap();
        assert_eq!(refine(&armax, &OeConfig::DEFAULT, &mut [-0.5, 1.0, 0.1], &y, &u), Err(OeError::Structure));
        assert!(is_stable(&[-1.9514, 0.9516]) && !is_stable(&[-2.0, 1.0]));
        assert!(cost(&s, &[-0.5, 1.0], &y, &u) < 1e-24);
    }

    /// ψ from the recursion matches finite differences of the simulated output's V: checks
    /// the gradient g = Σψε against −½ ∂V/∂θ.
    #[test]
    fn gradient_matches_finite_differences() {
        let s = Structure::new(2, 2, 0, 2).unwrap();
        let u = input(400, 5);
        let y = simulate(&s, &[-1.6, 0.64, 0.3, 0.1], &u);
        let th = [-1.5, 0.58, 0.25, 0.12];
        let mut nm = Normal { r: [[0.0; MAX_PARAMS]; MAX_PARAMS], g: [0.0; MAX_PARAMS] };
        pass(&s, &th, &y, &u, Some(&mut nm));
        for k in 0..4 {
            let h = 1e-6;
            let (mut p, mut m) = (th, th);
            p[k] += h;
            m[k] -= h;
            let dv = (cost(&s, &p, &y, &u) - cost(&s, &m, &y, &u)) / (2.0 * h);
            assert!((nm.g[k] + 0.5 * dv).abs() < 1e-5 * dv.abs().max(1.0), "θ{k}: g {} vs {}", nm.g[k], -0.5 * dv);
        }
    }
}
