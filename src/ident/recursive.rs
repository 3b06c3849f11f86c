//! Recursive extended least squares (RELS) for ARMAX, per sample ([`Rels`]) and over a record
//! ([`run`], which also does plain RLS for ARX).
//!
//! The C coefficients are estimated by extending φ with past *a-posteriori* residuals
//! ê(t) = y(t) − φ(t)ᵀθ(t) (Ljung, *System Identification*, 2nd ed., 1999, §11.5 "Recursive
//! pseudolinear regressions"; Åström & Wittenmark, *Adaptive Control*, 2nd ed., §2.3 "extended
//! least squares"):
//!
//! ```text
//! φ(t) = [−y(t−1) … −y(t−na), u(t−nk) … u(t−nk−nb+1), ê(t−1) … ê(t−nc)]
//! θ(t) = θ(t−1) + K(t) (y(t) − φ(t)ᵀθ(t−1))            (the RLS update of `rls`)
//! ê(t) = y(t) − φ(t)ᵀθ(t)
//! ```
//!
//! Without the ê columns, least squares on ARMAX data is biased: the coloured noise C e
//! correlates with the past outputs in φ. Using a-posteriori rather than a-priori residuals
//! makes the pseudolinear regression converge under a weaker positive-realness condition on
//! 1/C (Ljung §11.5).

use nalgebra::SVector;

use super::model::{Regressor, Structure};
use super::rls::{EstError, Rls, RlsConfig};

/// Past residuals kept by [`run`] (C order ≤ 2).
const MAX_NC: usize = 2;

/// RELS state: an [`Rls`] whose regressor carries the residuals it produces.
#[derive(Clone, Debug, PartialEq)]
pub struct Rels<const N: usize> {
    rls: Rls<N>,
}

impl<const N: usize> Rels<N> {
    /// Starts at `theta0` (θ = [a, b, c]) with P = p0·I.
    pub fn new(cfg: &RlsConfig, theta0: SVector<f32, N>) -> Self {
        Self { rls: Rls::new(cfg, theta0) }
    }

    /// One RELS step for output `y` (physical units) at time t: φ(t) from `reg` (data up to
    /// t − 1 and the residuals pushed so far), the RLS update against `reg.y_dev(y)`, then the
    /// a-posteriori residual ê(t) pushed into `reg` (0 when the update is refused, so the
    /// residual history stays aligned with time). The caller still records the sample with
    /// [`Regressor::push`] once u(t) is known.
    ///
    /// Returns the a-priori error ε(t) (scaled deviation units), `Ok(None)` while the regressor
    /// is filling, or the estimator's error (θ unchanged; [`EstError`]). `N` must be na + nb + nc.
    pub fn update<const NA: usize, const NB: usize, const NC: usize>(
        &mut self,
        cfg: &RlsConfig,
        reg: &mut Regressor<NA, NB, NC>,
        y: f32,
    ) -> Result<Option<f32>, EstError> {
        let Some(phi) = reg.phi::<N>() else {
            reg.push_residual(0.0);
            return Ok(None);
        };
        match self.rls.update(cfg, &phi, reg.y_dev(y)) {
            Ok(eps) => {
                reg.push_residual(self.rls.posterior_error());
                Ok(Some(eps))
            }
            Err(e) => {
                reg.push_residual(0.0);
                Err(e)
            }
        }
    }

    /// The underlying estimator (θ, trace(P), P, errors).
    pub fn rls(&self) -> &Rls<N> {
        &self.rls
    }

    /// The estimate θ = [a, b, c].
    pub fn theta(&self) -> &SVector<f32, N> {
        self.rls.theta()
    }

    /// trace(P).
    pub fn trace_p(&self) -> f32 {
        self.rls.trace_p()
    }

    /// A-priori error of the last accepted update.
    pub fn prediction_error(&self) -> f32 {
        self.rls.prediction_error()
    }

    /// A-posteriori error (the residual ê) of the last accepted update.
    pub fn posterior_error(&self) -> f32 {
        self.rls.posterior_error()
    }

    /// Resets P to p0·I, keeping θ.
    pub fn reset_covariance(&mut self, cfg: &RlsConfig) {
        self.rls.reset_covariance(cfg);
    }
}

/// Runs RLS (nc = 0) or RELS (nc > 0) over `y`, `u` (deviation variables, ideally scaled to
/// order one), calling `on_step(t, θ, ε)` after each accepted update. `N` must equal
/// `s.n_params()`. Samples whose update is refused (non-finite data) are skipped and counted;
/// their residual is taken as 0.
pub fn run<const N: usize>(
    s: &Structure,
    cfg: &RlsConfig,
    theta0: SVector<f32, N>,
    y: &[f32],
    u: &[f32],
    mut on_step: impl FnMut(usize, &SVector<f32, N>, f32),
) -> Result<(Rls<N>, u32), EstError> {
    if s.n_params() != N || s.nc > MAX_NC {
        return Err(EstError::Diverged);
    }
    let mut rls = Rls::<N>::new(cfg, theta0);
    let mut resid = [0.0f32; MAX_NC];
    let mut skipped = 0u32;
    let n = y.len().min(u.len());
    // The y and u part of φ; the residual part is appended from `resid`.
    let arx = Structure { nc: 0, ..*s };
    for t in s.first_index()..n {
        let mut phi = [0.0f32; N];
        if !arx.regressor(y, u, &[], t, &mut phi) {
            continue;
        }
        // ê(t−1−i), newest first.
        for (dst, e) in phi.iter_mut().skip(s.na + s.nb).zip(resid.iter()) {
            *dst = *e;
        }
        let phiv = SVector::<f32, N>::from(phi);
        let post = match rls.update(cfg, &phiv, y[t]) {
            Ok(eps) => {
                on_step(t, rls.theta(), eps);
                rls.posterior_error()
            }
            Err(_) => {
                skipped += 1;
                0.0
            }
        };
        resid.rotate_right(1);
        resid[0] = post;
    }
    Ok((rls, skipped))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::model::OperatingPoint;

    #[test]
    fn per_sample_rels_equals_the_record_runner() {
        // ARMAX(1,1,1): y(t) = 0.9 y(t−1) + 0.5 u(t−1) + e(t) + 0.5 e(t−1).
        let n = 3000;
        let mut seed = 99u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let u: std::vec::Vec<f32> = (0..n).map(|t| if (t / 7) % 3 == 0 { 1.0 } else { -1.0 }).collect();
        let e: std::vec::Vec<f32> = (0..n).map(|_| 0.2 * rnd()).collect();
        let mut y = std::vec![0.0f32; n];
        for t in 1..n {
            y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + e[t] + 0.5 * e[t - 1];
        }
        let cfg = RlsConfig::DEFAULT;
        let s = Structure::new(1, 1, 1, 1).unwrap();
        let (rls, skipped) = run::<3>(&s, &cfg, SVector::zeros(), &y, &u, |_, _, _| {}).unwrap();
        assert_eq!(skipped, 0);
        let mut rels = Rels::<3>::new(&cfg, SVector::zeros());
        let mut reg = Regressor::<1, 1, 1>::new(1, OperatingPoint::IDENTITY).unwrap();
        for t in 0..n {
            let r = rels.update(&cfg, &mut reg, y[t]).unwrap();
            assert_eq!(r.is_none(), t < 1);
            reg.push(y[t], u[t]);
        }
        assert_eq!(rels.theta(), rls.theta());
        let th = rels.theta();
        assert!((th[0] + 0.9).abs() < 0.03 && (th[1] - 0.5).abs() < 0.03, "{th}");
        assert!((th[2] - 0.5).abs() < 0.1, "c1 = {}", th[2]);
        // A NaN sample is refused, the state kept, and the residual slot filled with 0.
        let before = rels.clone();
        assert_eq!(rels.update(&cfg, &mut reg, f32::NAN), Err(EstError::NonFinite));
        assert_eq!(rels.rls(), before.rls());
    }
}
