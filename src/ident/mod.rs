//! Black-box identification of the carrier: ARX/ARMAX structures, recursive
//! least squares with forgetting (f32, U-D factorised, for the MCU), recursive extended least
//! squares, batch least squares and output-error refinement (f64 reference and offline tool),
//! PRBS excitation, and
//! validation (one-step MSE, simulated fit, poles/zeros, residual whiteness, order choice).
//!
//! # Equations
//!
//! Model structures (Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, §4.2;
//! Åström & Wittenmark, *Computer-Controlled Systems*, 3rd ed., 1997, ch. 13):
//!
//! ```text
//! ARX:    A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + e(t)
//! ARMAX:  A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + C(q⁻¹) e(t)
//! A = 1 + a1 q⁻¹ + … + a_na q^−na,  B = b0 + … + b_{nb−1} q^−(nb−1),  C = 1 + c1 q⁻¹ + … + c_nc q^−nc
//! y(t) = φ(t)ᵀ θ + e(t),  φ(t) = [−y(t−1) … −y(t−na), u(t−nk) … u(t−nk−nb+1), ê(t−1) … ê(t−nc)]
//! ```
//!
//! Batch least squares (Ljung §7.3): `θ̂ = (Σ φφᵀ)⁻¹ Σ φ y` ([`batch`]).
//!
//! Recursive least squares with forgetting factor λ_f (Ljung §11.2; Åström & Wittenmark,
//! *Adaptive Control*, 2nd ed., 1995, §2.2) ([`rls`]):
//!
//! ```text
//! ε(t) = y(t) − φᵀθ(t−1),  K = Pφ / (λ_f + φᵀPφ),  θ(t) = θ(t−1) + K ε(t),  P(t) = (P − KφᵀP) / λ_f
//! ```
//!
//! Recursive extended least squares (Ljung §11.5, pseudolinear regression; Åström &
//! Wittenmark, *Adaptive Control*, §2.3): the same update with φ extended by the a-posteriori
//! residuals ê(t) = y(t) − φ(t)ᵀθ(t), which estimates C ([`recursive`]).
//!
//! Output error ([`oe`], Ljung §4.2 and §10.2–10.3): minimise V(θ) = Σ (y − q^−nk B/A u)², the
//! simulated-output error, by Levenberg–Marquardt with ψ = φ_x / A as gradient.
//!
//! Validation ([`validate`]): MSE = mean (y − φᵀθ)², fit = 100 (1 − ‖y − ŷ_sim‖/‖y − ȳ‖) %,
//! poles = roots of z^na A(z⁻¹), residual autocorrelation against ±1.96/√N (Ljung §16.6).
//!
//! # Why f32 RLS needs care here, and what is done
//!
//! The carrier is slow: at the sampling period its poles are close to 1 (1 + a1 + a2 ≈ 1e-3),
//! so the columns −y(t−1), −y(t−2) of φ are nearly equal, ΦᵀΦ is ill-conditioned, and P spans
//! many decades. The covariance-form update `P − KφᵀP` then cancels most of f32's 24 bits in
//! the well-excited directions and loses positive definiteness (within 10⁴ samples on a
//! 1 + a1 + a2 = 5e-5 plant, `tests/ident_rls.rs`), after which λ_f + φᵀPφ can vanish and θ
//! diverge. The estimator is made robust by:
//!
//! 1. **Deviation variables and scaling** ([`model::OperatingPoint`], [`model::Regressor`]):
//!    y and u enter as `(y − y0)/y_s`, `(u − u0)/u_s`, so φ is of order one and has no large
//!    common offset (an ambient of 28 °C next to a swing of 0.5 °C would otherwise hide the
//!    information in the last digits). The self-tuning controller takes another route to the
//!    same end: its regressor carries a constant 1, so an offset parameter d absorbs the
//!    operating point ([`crate::control::adaptive`] says why not increments Δy, Δu).
//! 2. **U-D factorisation** (Bierman 1977): P = U D Uᵀ is updated in its factors, so P stays
//!    symmetric by construction and positive definite while every d_i > 0 (checked every
//!    update).
//! 3. **Bounded trace**: with λ_f < 1 and poor excitation (constant duty at steady state), P
//!    would grow as λ_f^−t (estimator windup); D is scaled down whenever trace(P) exceeds
//!    `trace_max`, and [`rls::Rls::reset_covariance`] restarts P after a detected change.
//! 4. **No update on non-finite data**: φ, y and the new state are checked; on failure the
//!    update returns [`rls::EstError`] and the previous state is kept.
//!
//! `tests/ident_rls.rs` checks the result against f64 batch least squares on a
//! near-integrating plant and checks P under 10⁶ samples of windup-prone constant input.
//!
//! # Glossary
//!
//! - θ — parameter vector [a, b, c]; φ — regressor; N — number of parameters na + nb + nc.
//! - na, nb, nc — orders of A, B (number of b coefficients) and C; nk — delay in samples (≥ 1).
//! - P — parameter covariance (up to the noise variance); U, D — its U-D factors.
//! - λ_f — forgetting factor in (0, 1]; memory ≈ 1/(1 − λ_f) samples.
//! - ε — a-priori prediction error y − φᵀθ(t−1); ε̄ or ê — a-posteriori error y − φᵀθ(t).
//! - RLS, RELS — recursive (extended) least squares; LS — batch least squares.
//! - PRBS — pseudo-random binary sequence (maximum-length shift register).
//! - fit — simulated-output fit in % (MATLAB `compare`); MSE — mean squared one-step error.
//! - operating point (y0, u0) — the values deviations are taken from; scale factors y_s, u_s.
//!
//! # Modules
//!
//! - [`model`]: structures, per-sample [`model::Regressor`] (and one-step prediction with a
//!   [`crate::model::Model`]), [`model::OperatingPoint`].
//! - [`rls`]: f32 U-D RLS ([`rls::Rls`], [`rls::RlsConfig`], [`rls::EstError`]).
//! - [`recursive`]: RELS ([`recursive::Rels`]) and a record runner for RLS/RELS.
//! - [`batch`]: f64 batch least squares and instrumental variables through the normal
//!   equations, and both run on a whole record.
//! - [`oe`]: f64 output-error refinement (Levenberg–Marquardt on the simulated-output error).
//! - [`oe_search`]: the multi-start output-error search over [`oe`] (f64, host side).
//! - [`prbs`]: PRBS generator for the SSR.
//! - [`validate`]: MSE, fit, roots, autocorrelation, order choice (f64, host side).
#![allow(non_snake_case)]

pub mod batch;
pub mod commission;
pub mod model;
pub mod oe;
pub mod oe_search;
pub mod prbs;
pub mod recursive;
pub mod rls;
pub mod validate;
