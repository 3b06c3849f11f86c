//! Running the recursive estimators over a record: RLS for ARX, and RELS for ARMAX, where the
//! C coefficients are estimated by extending φ with past *a-posteriori* residuals
//! ê(t) = y(t) − φ(t)ᵀθ(t) (Ljung 1999, §11.3 and eq. 11.56; Åström & Wittenmark, *Adaptive
//! Control*, §2.4 "extended least squares"). Without them, LS on ARMAX data is biased: the
//! coloured noise correlates with the past outputs in φ.

use nalgebra::SVector;

use super::model::Structure;
use super::rls::{EstError, Rls, RlsConfig};

/// Past residuals kept for RELS (C order ≤ 2).
const MAX_NC: usize = 2;

/// Runs RLS (nc = 0) or RELS (nc > 0) over `y`, `u` (deviation variables), calling
/// `on_step(t, θ, ε)` after each update. `N` must equal `s.n_params()`.
/// Samples whose update is refused (non-finite data) are skipped and counted.
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
    let mut phi = [0.0f32; N];
    let n = y.len().min(u.len());
    // The y and u part of φ; the residual part is appended from `resid`.
    let arx = Structure { nc: 0, ..*s };
    for t in s.first_index()..n {
        let mut full = [0.0f32; N];
        if !arx.regressor(y, u, &[], t, &mut full) {
            continue;
        }
        // ê(t−1−i), newest first.
        for i in 0..s.nc {
            full[s.na + s.nb + i] = resid[i];
        }
        phi.copy_from_slice(&full);
        let phiv = SVector::<f32, N>::from(phi);
        match rls.update(cfg, &phiv, y[t]) {
            Ok(eps) => {
                let post = y[t] - rls.predict(&phiv);
                resid.copy_within(0..MAX_NC - 1, 1);
                resid[0] = if post.is_finite() { post } else { 0.0 };
                on_step(t, rls.theta(), eps);
            }
            Err(_) => skipped += 1,
        }
    }
    Ok((rls, skipped))
}
