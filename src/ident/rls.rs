//! Recursive least squares with forgetting, in Bierman's U-D factorised form.
//!
//! Model `y(t) = φ(t)ᵀ θ + e(t)`. The textbook covariance update (Ljung, *System
//! Identification*, 2nd ed., 1999, §11.2 "The recursive least-squares algorithm", with
//! forgetting factor; Åström & Wittenmark, *Adaptive Control*, 2nd ed., 1995, §2.2)
//!
//! ```text
//! ε(t) = y(t) − φᵀ θ(t−1)                 a-priori prediction error
//! K    = P φ / (λ_f + φᵀ P φ)
//! θ(t) = θ(t−1) + K ε(t)
//! P(t) = (P − K φᵀ P) / λ_f
//! ε̄(t) = y(t) − φᵀ θ(t) = ε(t) λ_f / (λ_f + φᵀ P φ)     a-posteriori error
//! ```
//!
//! is fragile in f32 on this plant: at the sampling period the poles sit near 1
//! (1 + a1 + a2 ≈ 1e-3), so consecutive outputs in φ are almost collinear, P spans many decades,
//! and the subtraction `P − KφᵀP` cancels almost all digits in the well-excited directions. On
//! a plant with 1 + a1 + a2 = 5e-5 it loses positive definiteness within 10⁴ samples
//! (`tests/ident_rls.rs`); an indefinite P can then drive λ_f + φᵀPφ to zero or below, and the
//! update diverges. What this module does about it:
//!
//! 1. **U-D factorisation** (Bierman, *Factorization Methods for Discrete Sequential
//!    Estimation*, 1977, ch. V; Thornton & Bierman 1980; Ljung 1999 §11.7 "Implementation"):
//!    P = U D Uᵀ with U unit upper triangular and D diagonal. The update works on U and D
//!    directly, so P is symmetric by construction and positive definite as long as every
//!    d_i > 0 — which the update preserves in exact arithmetic and [`Rls::update`] checks. Like
//!    every square-root method it works with the condition number of √P, not of P.
//! 2. **Bounded trace** against estimator windup: with λ_f < 1 and no excitation, P grows as
//!    λ_f^−t in the unexcited directions until a single new excitation throws θ off (a
//!    "burst"). After each update, if trace(P) exceeds `trace_max`, D is scaled down to that
//!    trace (the constant-trace idea; Åström & Wittenmark, *Adaptive Control*, ch. 11 on
//!    estimator windup). Scaling D by a positive number keeps P symmetric positive definite.
//!    [`Rls::reset_covariance`] restores P = p0·I after a detected plant change.
//! 3. **Nothing non-finite gets in**: φ, y and the updated state are checked; on failure the
//!    previous state is kept and [`EstError`] returned.
//! 4. **Scaled deviation variables**: φ should hold deviations from an operating point (or
//!    increments), of order one. [`crate::ident::model::Regressor`] builds such regressors from
//!    raw samples with an [`crate::ident::model::OperatingPoint`] (y0, u0 and scale factors).
//!
//! The a-posteriori error ε̄ falls out of the update for free (α = λ_f + φᵀPφ is computed
//! anyway); RELS feeds it back as the residual ê(t).
//!
//! Cost for N parameters: about 2N² + 5N multiplications and 2N divisions for the U-D update,
//! plus O(N²) for the finiteness checks and the trace — of the order of 150 flops for the
//! 4-parameter model the adaptive controllers run every sample. No allocation, no square root.
#![allow(non_snake_case)]

use crate::numerics::finite_probe;
use nalgebra::{SMatrix, SVector};

/// Why an update was refused: θ is unchanged either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EstError {
    /// φ or y contained NaN or infinity: nothing changed.
    NonFinite,
    /// The update produced a non-finite or non-positive factor (numerical breakdown): θ kept,
    /// P restarted at p0·I.
    Diverged,
}

/// RLS settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RlsConfig {
    /// Forgetting factor λ_f in (0, 1].
    pub forgetting: f32,
    /// Initial covariance P(0) = p0 · I.
    pub p0: f32,
    /// Largest trace(P) allowed (windup bound).
    pub trace_max: f32,
}

impl RlsConfig {
    /// λ_f = 1 (no forgetting), P(0) = 1000·I, trace bound 1e4.
    pub const DEFAULT: RlsConfig = RlsConfig { forgetting: 1.0, p0: 1000.0, trace_max: 1e4 };

    /// True if λ_f ∈ (0, 1], p0 > 0 and trace_max ≥ p0, all finite.
    pub const fn is_valid(&self) -> bool {
        self.forgetting > 0.0
            && self.forgetting <= 1.0
            && self.p0 > 0.0
            && self.p0.is_finite()
            && self.trace_max.is_finite()
            && self.trace_max >= self.p0
    }

    /// p0, or the default's where p0 is not finite and positive.
    fn start_variance(&self) -> f32 {
        // Positive and finite (NaN fails both), in two comparisons.
        if self.p0 > 0.0 && self.p0 < f32::INFINITY {
            self.p0
        } else {
            RlsConfig::DEFAULT.p0
        }
    }
}

/// The variance [`Rls::hold`] leaves a held parameter with.
pub const HELD_VARIANCE: f32 = 1e-9;

/// RLS state for N parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Rls<const N: usize> {
    theta: SVector<f32, N>,
    /// Unit upper-triangular factor (the diagonal is implicitly 1 and not read).
    u: SMatrix<f32, N, N>,
    d: SVector<f32, N>,
    updates: u32,
    eps: f32,
    eps_post: f32,
    /// trace(P), kept by every change of the factors (the self-tuner logs it every sample).
    trace: f32,
}

impl<const N: usize> Rls<N> {
    /// Starts at `theta0` with P = p0·I.
    pub fn new(cfg: &RlsConfig, theta0: SVector<f32, N>) -> Self {
        let p0 = cfg.start_variance();
        Self {
            theta: theta0,
            u: SMatrix::identity(),
            d: SVector::repeat(p0),
            updates: 0,
            eps: 0.0,
            eps_post: 0.0,
            trace: N as f32 * p0,
        }
    }

    /// The estimate θ.
    pub fn theta(&self) -> &SVector<f32, N> {
        &self.theta
    }

    /// Updates made so far.
    pub fn updates(&self) -> u32 {
        self.updates
    }

    /// A-priori prediction error ε(t) = y(t) − φ(t)ᵀθ(t−1) of the last accepted update.
    pub fn prediction_error(&self) -> f32 {
        self.eps
    }

    /// A-posteriori error ε̄(t) = y(t) − φ(t)ᵀθ(t) of the last accepted update.
    pub fn posterior_error(&self) -> f32 {
        self.eps_post
    }

    /// The covariance P = U D Uᵀ (for logging and tests; the update never forms it).
    pub fn covariance(&self) -> SMatrix<f32, N, N> {
        let mut p = SMatrix::<f32, N, N>::zeros();
        for i in 0..N {
            for j in 0..N {
                let mut s = 0.0;
                for k in i.max(j)..N {
                    s += self.uu(i, k) * self.d[k] * self.uu(j, k);
                }
                p[(i, j)] = s;
            }
        }
        p
    }

    /// The factors (U unit upper triangular, D) of P = U D Uᵀ. P is symmetric by construction
    /// and positive definite exactly when every d_k > 0.
    pub fn factors(&self) -> (SMatrix<f32, N, N>, SVector<f32, N>) {
        let mut u = SMatrix::<f32, N, N>::identity();
        for i in 0..N {
            for j in i + 1..N {
                u[(i, j)] = self.u[(i, j)];
            }
        }
        (u, self.d)
    }

    /// trace(P), as the last change of the factors left it.
    pub fn trace_p(&self) -> f32 {
        self.trace
    }

    fn uu(&self, i: usize, j: usize) -> f32 {
        if i == j {
            1.0
        } else if i < j {
            self.u[(i, j)]
        } else {
            0.0
        }
    }

    /// Resets P to p0·I, keeping θ and the update count, as [`Self::new`] starts it (after a
    /// detected plant change, or a breakdown in [`Self::update`], which leaves U no longer the
    /// factor of a covariance). Out of line and cold: it never runs on a sample with sane data,
    /// and written as fills (≈ 250 B of flash less than the constructor, inlined and unrolled).
    #[cold]
    #[inline(never)]
    pub fn reset_covariance(&mut self, cfg: &RlsConfig) {
        let p0 = cfg.start_variance();
        self.u.fill(0.0);
        self.u.fill_diagonal(1.0);
        self.d.fill(p0);
        self.trace = N as f32 * p0;
        self.eps = 0.0;
        self.eps_post = 0.0;
    }

    /// Projects θ onto the half-space cᵀθ ≥ `c0` if it lies outside: θ ← θ + P c (c0 − cᵀθ) /
    /// (cᵀ P c), the point of the boundary nearest θ in the metric of P⁻¹ (the information the
    /// data have given), so the move is along the directions the data determine least (Goodwin
    /// & Sin 1984, §3.3.8). P is not changed. Returns true if θ moved; false if it was inside,
    /// or `c`, `c0` or P give no finite step (θ unchanged).
    ///
    /// P c = U D Uᵀ c from the factors: N² multiply-adds, and only when the constraint is
    /// violated (one dot product otherwise).
    pub fn project_onto_halfspace(&mut self, c: &SVector<f32, N>, c0: f32) -> bool {
        let v = c.dot(&self.theta);
        if !(v < c0) {
            return false;
        }
        // f = Uᵀ c (U unit upper triangular), g = D f, cᵀPc = fᵀ D f.
        let mut g = [0.0f32; N];
        let mut cpc = 0.0f32;
        for j in 0..N {
            let mut f = c[j];
            for i in 0..j {
                f += self.u[(i, j)] * c[i];
            }
            g[j] = self.d[j] * f;
            cpc += f * g[j];
        }
        let s = (c0 - v) / cpc;
        if !(s.is_finite() && cpc > 0.0) {
            return false;
        }
        // θ += (U g) s.
        let mut moved = self.theta;
        for i in 0..N {
            let mut pc = g[i];
            for j in i + 1..N {
                pc += self.u[(i, j)] * g[j];
            }
            moved[i] += pc * s;
        }
        let mut probe = 0.0f32;
        for x in moved.iter() {
            probe += finite_probe(*x);
        }
        if probe == 0.0 {
            self.theta = moved;
            true
        } else {
            false
        }
    }

    /// Keeps parameter `k` where it is: its variance in P is set to `HELD_VARIANCE`, so an
    /// update with φ_k = 0 leaves θ_k and its coupling to the others (zero, as P starts) as they
    /// are, and it adds nothing to trace(P). Call it after every update that should hold k
    /// (forgetting grows the variance by 1/λ_f each time). Out of range: nothing.
    pub fn hold(&mut self, k: usize) {
        self.set_variance(k, HELD_VARIANCE);
    }

    /// Sets the variance of parameter `k` in P's factor D to `v` (finite and positive, else
    /// nothing; out of range: nothing). P = U D Uᵀ: this is P_kk only while row k of U is
    /// zero off the diagonal, as it is from [`Rls::new`] until the first update.
    pub fn set_variance(&mut self, k: usize, v: f32) {
        if let (Some(d), true) = (self.d.get_mut(k), v.is_finite() && v > 0.0) {
            self.trace += v - *d;
            *d = v;
        }
    }

    /// Prediction φᵀθ.
    pub fn predict(&self, phi: &SVector<f32, N>) -> f32 {
        phi.dot(&self.theta)
    }

    /// One update with regressor `phi` and output `y`; returns the a-priori error ε(t).
    ///
    /// Two passes over U (Uᵀφ, then the update, which also sums the trace) and the finiteness
    /// checks folded into one sum of x − x (+0 for a finite x, NaN otherwise) over θ and the
    /// trace: every sample of the self-tuning controller runs this on the M4F. The
    /// floating-point operations and their order are those of Bierman's algorithm as written
    /// in the comments. Until 2026-12-06 the update, the forgetting with the checks, and the
    /// trace were three passes over U after Uᵀφ: the same bits, ≈ 500 instructions more in
    /// the worst sample of the board's build (`cargo xtask pil`).
    ///
    /// Non-finite data are refused before anything changes ([`EstError::NonFinite`]). U is
    /// updated in place (a copy of it to fall back on was two 196-byte copies a sample for
    /// seven parameters, ≈ 400 instructions on the board's build), so an update whose result
    /// is not a covariance (α ≤ 0, a d ≤ 0, or a value that overflowed, trace(P) included,
    /// which finite data can reach only by overflowing f32) keeps θ and restarts P at p0·I, as
    /// [`Self::reset_covariance`] does ([`EstError::Diverged`]).
    pub fn update(&mut self, cfg: &RlsConfig, phi: &SVector<f32, N>, y: f32) -> Result<f32, EstError> {
        // An index loop, not nalgebra's iterator: built for size (the firmware's "z"), each
        // of its steps can be an out-of-line call.
        let mut probe = finite_probe(y);
        for j in 0..N {
            probe += finite_probe(phi[j]);
        }
        if probe != 0.0 {
            return Err(EstError::NonFinite);
        }
        let lambda = if cfg.forgetting > 0.0 && cfg.forgetting <= 1.0 { cfg.forgetting } else { 1.0 };
        let eps = y - self.predict(phi);

        // Bierman's measurement update with noise variance λ_f (Bierman 1977, p. 100): f = Uᵀφ
        // on U before the update, then one pass over U's columns with g_j = d_j f_j, the
        // forgetting P ← P / λ_f on each d_j as it is made, and trace(P) = Σ_j d_j (1 + Σ_i
        // U_ij²) summed from each column as it is written.
        let u = &mut self.u;
        let mut f = [0.0f32; N];
        for j in 0..N {
            let mut s = phi[j];
            for i in 0..j {
                s += u[(i, j)] * phi[i];
            }
            f[j] = s;
        }
        let mut d = self.d;
        let mut b = [0.0f32; N];
        let mut alpha = lambda;
        let mut tr = 0.0f32;
        let mut positive = true;
        for j in 0..N {
            let g = f[j] * d[j];
            let beta = alpha;
            alpha += f[j] * g;
            let p = -f[j] / beta;
            d[j] *= beta / alpha;
            d[j] /= lambda;
            positive &= d[j] > 0.0;
            let mut col = 0.0f32;
            for i in 0..j {
                let uij = u[(i, j)];
                let v = uij + b[i] * p;
                u[(i, j)] = v;
                col += v * v;
                b[i] += g * uij;
            }
            b[j] = g;
            col += 1.0; // U_jj² (U is unit upper triangular)
            tr += d[j] * col;
        }
        // K = b / α, θ ← θ + K ε.
        let mut theta = self.theta;
        let mut probe = 0.0f32;
        for j in 0..N {
            theta[j] += (b[j] / alpha) * eps;
            probe += finite_probe(theta[j]);
        }
        // Every term of the trace is d_j (1 + Σ U_ij²) ≥ 0 once every d_j > 0, so a finite
        // trace means every d_j and U_ij is finite (a NaN or an infinity anywhere makes it
        // non-finite), and one that overflowed is a breakdown too.
        probe += finite_probe(tr);
        if !(positive && alpha > 0.0) || probe != 0.0 {
            self.reset_covariance(cfg);
            return Err(EstError::Diverged);
        }
        self.theta = theta;
        self.d = d;
        self.trace = if tr > cfg.trace_max {
            let scale = cfg.trace_max / tr;
            self.d *= scale;
            tr * scale
        } else {
            tr
        };
        self.updates = self.updates.saturating_add(1);
        self.eps = eps;
        // ε̄ = ε (1 − φᵀK) = ε λ_f / α, α = λ_f + φᵀPφ ≥ λ_f > 0.
        self.eps_post = eps * (lambda / alpha);
        Ok(eps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_covariance_form_on_a_small_problem() {
        // Same data through the textbook update in f64 and through U-D in f32.
        let cfg = RlsConfig { forgetting: 0.99, p0: 100.0, trace_max: 1e9 };
        let mut ud = Rls::<3>::new(&cfg, SVector::zeros());
        let mut p = nalgebra::Matrix3::<f64>::identity() * 100.0;
        let mut th = nalgebra::Vector3::<f64>::zeros();
        let truth = [0.5, -1.0, 2.0];
        let mut seed = 12345u32;
        for _ in 0..200 {
            let mut phi = [0.0f64; 3];
            for x in phi.iter_mut() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *x = (seed >> 8) as f64 / (1u32 << 24) as f64 - 0.5;
            }
            let y: f64 = phi.iter().zip(truth).map(|(a, b)| a * b).sum::<f64>() + 0.01 * phi[0];
            let ph = nalgebra::Vector3::from(phi);
            let k = p * ph / (0.99 + (ph.transpose() * p * ph)[0]);
            th += k * (y - ph.dot(&th));
            p = (p - k * ph.transpose() * p) / 0.99;
            let phf = SVector::<f32, 3>::new(phi[0] as f32, phi[1] as f32, phi[2] as f32);
            ud.update(&cfg, &phf, y as f32).unwrap();
        }
        for i in 0..3 {
            assert!((f64::from(ud.theta()[i]) - th[i]).abs() < 1e-4, "{i}: {} vs {}", ud.theta()[i], th[i]);
        }
        let pu = ud.covariance();
        for i in 0..3 {
            for j in 0..3 {
                assert!((f64::from(pu[(i, j)]) - p[(i, j)]).abs() < 1e-3 * p[(i, j)].abs().max(1e-3), "P[{i}{j}]");
            }
        }
    }

    #[test]
    fn a_variance_set_at_the_start_is_that_parameter_s_prior() {
        // P(0) = diag(0.01, 0.01, 1) through `set_variance` against the textbook update in f64
        // started from that P: the third parameter (an offset, φ = 1) takes the first error.
        let cfg = RlsConfig { forgetting: 0.995, p0: 0.01, trace_max: 1e9 };
        let mut ud = Rls::<3>::new(&cfg, SVector::from([0.5, -1.0, 0.0]));
        ud.set_variance(2, 1.0);
        ud.set_variance(7, 1.0);
        ud.set_variance(0, f32::NAN);
        assert!((ud.trace_p() - 1.02).abs() < 1e-6);
        let mut p = nalgebra::Matrix3::<f64>::from_diagonal(&nalgebra::Vector3::new(0.01, 0.01, 1.0));
        let mut th = nalgebra::Vector3::<f64>::new(0.5, -1.0, 0.0);
        let mut seed = 777u32;
        for _ in 0..50 {
            let mut phi = [0.0f64, 0.0, 1.0];
            for x in phi.iter_mut().take(2) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *x = (seed >> 8) as f64 / (1u32 << 24) as f64 - 0.5;
            }
            // The model is right; the offset, 3, is not known.
            let y = 0.5 * phi[0] - phi[1] + 3.0;
            let ph = nalgebra::Vector3::from(phi);
            let k = p * ph / (0.995 + (ph.transpose() * p * ph)[0]);
            th += k * (y - ph.dot(&th));
            p = (p - k * ph.transpose() * p) / 0.995;
            let phf = SVector::<f32, 3>::new(phi[0] as f32, phi[1] as f32, 1.0);
            ud.update(&cfg, &phf, y as f32).unwrap();
        }
        for i in 0..3 {
            assert!((f64::from(ud.theta()[i]) - th[i]).abs() < 1e-4, "{i}: {} vs {}", ud.theta()[i], th[i]);
        }
        // The offset is learnt; the model moved by a fraction of the error.
        assert!((ud.theta()[2] - 3.0).abs() < 0.1, "offset {}", ud.theta()[2]);
        assert!((ud.theta()[0] - 0.5).abs() < 0.05 && (ud.theta()[1] + 1.0).abs() < 0.05, "{:?}", ud.theta());
    }

    #[test]
    fn refuses_non_finite_data_and_keeps_its_state() {
        let cfg = RlsConfig::DEFAULT;
        let mut r = Rls::<2>::new(&cfg, nalgebra::Vector2::new(1.0, 2.0));
        let before = r.clone();
        assert_eq!(r.update(&cfg, &nalgebra::Vector2::new(f32::NAN, 1.0), 1.0), Err(EstError::NonFinite));
        assert_eq!(r.update(&cfg, &nalgebra::Vector2::new(1.0, 1.0), f32::INFINITY), Err(EstError::NonFinite));
        assert_eq!(r, before);
    }

    #[test]
    fn a_breakdown_keeps_theta_and_restarts_the_covariance() {
        // Finite data that overflow f32 in φᵀPφ: α becomes infinite and every d with it 0.
        let cfg = RlsConfig { forgetting: 0.98, p0: 100.0, trace_max: 1e9 };
        let mut r = Rls::<3>::new(&cfg, SVector::from([0.5, -1.0, 2.0]));
        let mut seed = 99u32;
        for _ in 0..40 {
            let mut phi = [0.0f32; 3];
            for x in phi.iter_mut() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *x = (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
            }
            let y = 0.4 * phi[0] - 0.9 * phi[1] + 2.1 * phi[2];
            r.update(&cfg, &SVector::from(phi), y).unwrap();
        }
        let (u_before, _) = r.factors();
        assert!((0..3).any(|j| (0..j).any(|i| u_before[(i, j)] != 0.0)), "U has been updated");
        let theta = *r.theta();
        let updates = r.updates();
        let huge = SVector::from([1e30f32, -1e30, 1e30]);
        assert_eq!(r.update(&cfg, &huge, 0.0), Err(EstError::Diverged));
        // θ as it was; P = p0·I (U's updated entries did not survive).
        assert_eq!(*r.theta(), theta);
        assert_eq!(r.covariance(), SMatrix::<f32, 3, 3>::identity() * 100.0);
        assert_eq!((r.trace_p(), r.updates()), (300.0, updates));
        // The whole state is the constructor's, but for the update count.
        assert_eq!(r, Rls { updates, ..Rls::new(&cfg, theta) });
        // It goes on learning from there.
        let mut fresh = Rls::<3>::new(&cfg, theta);
        let phi = SVector::from([0.3f32, -0.2, 0.1]);
        assert_eq!(r.update(&cfg, &phi, 1.0), fresh.update(&cfg, &phi, 1.0));
        assert_eq!(r.theta(), fresh.theta());
    }

    #[test]
    fn a_trace_that_overflows_is_a_breakdown() {
        // Every factor finite, their trace not: before the check on the trace, the clip scaled
        // D by trace_max / ∞ = 0 and the estimator stopped learning without a word.
        let cfg = RlsConfig { forgetting: 1.0, p0: 2e38, trace_max: 1e9 };
        let mut r = Rls::<3>::new(&cfg, SVector::from([0.5, -1.0, 2.0]));
        let phi = SVector::from([1e-30f32, 0.0, 0.0]);
        assert_eq!(r.update(&cfg, &phi, 0.0), Err(EstError::Diverged));
        assert_eq!(*r.theta(), SVector::from([0.5, -1.0, 2.0]));
        assert_eq!(r.factors().1, SVector::from([2e38f32; 3]));
    }

    #[test]
    fn trace_is_bounded_without_excitation() {
        let cfg = RlsConfig { forgetting: 0.9, p0: 10.0, trace_max: 50.0 };
        let mut r = Rls::<2>::new(&cfg, SVector::zeros());
        for _ in 0..10_000 {
            r.update(&cfg, &nalgebra::Vector2::new(1.0, 0.0), 0.0).unwrap();
            assert!(r.trace_p() <= 50.0 * 1.0001);
        }
    }
}
