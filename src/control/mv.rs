//! Generalized minimum-variance control: GMVC (Clarke & Gawthrop, "Self-tuning controller",
//! Proc. IEE 122(9), 1975; "Self-tuning control", Proc. IEE 126(6), 1979) and its incremental
//! form IGMVC (seed §5.3.1–5.3.2).
//!
//! **GMVC** minimises `J = E{(P y(t+k) − R w(t))² + (S u(t))²}` with scalar weights P, R, S.
//! With `P = A E + q^−k F` ([`super::diophantine`]) and `G = E B`,
//!
//! ```text
//! P ŷ(t+k|t) = F y(t) + G u(t) + E(1) d,     u(t) = g0 (R w − F y(t) − Σ_{i≥1} g_i u(t−i) − E(1) d) / (g0² + S²)
//! ```
//!
//! where d is the constant offset of the model (`A y = q^−k B u + d`, the ambient's share of
//! the load temperature), tracked by a slow filter of the equation error. S > 0 trades
//! control effort for a steady-state offset, as the seed observed.
//!
//! **IGMVC** weights the increment instead: `J = E{(y(t+k) − w)² + λ Δu(t)²}` on the CARIMA model
//! `Ã y = q^−k B Δu + e` with Ã = ΔA, `1 = Ã E + q^−k F`, `G = E B`:
//!
//! ```text
//! Δu(t) = g0 (w − F y(t) − Σ_{i≥1} g_i Δu(t−i)) / (g0² + λ)
//! ```
//!
//! The Δ in the model gives integral action: no offset at steady state, whatever d is.
//! The identity is solved from the current model every sample, so the same code serves the
//! fixed-model and the self-tuning controllers.

use super::diophantine::{self, MAX_A, MAX_F};
use super::gpc::shift_in;
use super::model::{Model, MAX_K, MAX_NA, MAX_NB};

/// Why no control could be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MvError {
    /// Weights out of range (P ≠ 0, S ≥ 0, λ ≥ 0, all finite).
    Config,
    /// The Diophantine identity could not be solved for this model.
    Diophantine,
    /// g0² + weight is zero: the model has no gain at delay k and no weight regularises it.
    Singular,
    /// A non-finite number appeared.
    NonFinite,
}

/// GMVC weights.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GmvcConfig {
    /// Output weight P.
    pub p: f32,
    /// Reference weight R (R = P for unity static tracking when S = 0).
    pub r: f32,
    /// Control weight S, °C per unit duty.
    pub s: f32,
}

impl GmvcConfig {
    /// P = R = 1, S = 0.05: a small control weight keeps the duty from banging between 0 and 1
    /// on this slow plant; the seed's Fig. 5.14 shows the offset growing with S.
    pub const DEFAULT: GmvcConfig = GmvcConfig { p: 1.0, r: 1.0, s: 0.05 };
}

/// IGMVC weight.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IgmvcConfig {
    /// Weight λ on Δu², (°C per unit duty)².
    pub lambda: f32,
}

impl IgmvcConfig {
    /// λ = 0.01.
    pub const DEFAULT: IgmvcConfig = IgmvcConfig { lambda: 0.01 };
}

const HY: usize = MAX_F + 1;
const HU: usize = MAX_K + MAX_NB + 1;

/// Histories shared by both laws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MvState {
    y: [f32; HY],       // y(t), y(t−1), …
    u: [f32; HU],       // u(t−1), u(t−2), …
    d_hat: Option<f32>, // offset estimate (GMVC)
    primed: bool,
}

/// Pole of the offset filter of GMVC (time constant ≈ 20 samples).
const D_POLE: f32 = 0.95;

impl MvState {
    /// Empty history holding `u0`.
    pub fn new(u0: f32) -> Self {
        Self { y: [0.0; HY], u: [u0; HU], d_hat: None, primed: false }
    }

    /// The last applied u.
    pub fn u_prev(&self) -> f32 {
        self.u[0]
    }

    /// Takes y(t).
    pub fn push_y(&mut self, y: f32, m: &Model) -> Result<(), MvError> {
        if !y.is_finite() {
            return Err(MvError::NonFinite);
        }
        if self.primed {
            // Not `copy_within`: a memmove call on the M4 (this runs every sample).
            shift_in(&mut self.y, y);
        } else {
            self.y = [y; HY];
            self.primed = true;
        }
        // Equation error of A y(t) = B u(t−k) + d.
        let mut d = self.y[0];
        for i in 0..m.na {
            d += m.a[i] * self.y[i + 1];
        }
        for i in 0..m.nb {
            d -= m.b[i] * self.u.get(m.k + i - 1).copied().unwrap_or(0.0);
        }
        if d.is_finite() {
            self.d_hat = Some(match self.d_hat {
                Some(prev) => D_POLE * prev + (1.0 - D_POLE) * d,
                None => d,
            });
        }
        Ok(())
    }

    /// Records the u actually applied this sample.
    pub fn track(&mut self, applied: f32) {
        if applied.is_finite() {
            shift_in(&mut self.u, applied);
        }
    }

    /// Δu(t − m) for m ≥ 1.
    fn du_past(&self, m: usize) -> f32 {
        match (self.u.get(m - 1), self.u.get(m)) {
            (Some(a), Some(b)) => a - b,
            _ => 0.0,
        }
    }

    /// GMVC: the u(t) to apply (unclipped).
    pub fn gmvc(&self, m: &Model, cfg: &GmvcConfig, w: f32) -> Result<f32, MvError> {
        if !(cfg.p.is_finite() && cfg.r.is_finite() && cfg.s.is_finite() && cfg.p != 0.0 && cfg.s >= 0.0) {
            return Err(MvError::Config);
        }
        let mut a = [0.0f32; MAX_A];
        a[0] = 1.0;
        a[1..=m.na].copy_from_slice(&m.a[..m.na]);
        let sol = diophantine::solve(&a[..=m.na], &[cfg.p], m.k).ok_or(MvError::Diophantine)?;
        let g = conv(&sol.e[..sol.ne], &m.b[..m.nb]);
        let e1: f32 = sol.e[..sol.ne].iter().sum();
        let mut rest = cfg.r * w - e1 * self.d_hat.unwrap_or(0.0);
        for i in 0..sol.nf {
            rest -= sol.f[i] * self.y[i];
        }
        for (i, gi) in g.iter().enumerate().skip(1) {
            rest -= gi * self.u.get(i - 1).copied().unwrap_or(0.0);
        }
        let den = g[0] * g[0] + cfg.s * cfg.s;
        if !(den > 1e-12) {
            return Err(MvError::Singular);
        }
        let u = g[0] * rest / den;
        if u.is_finite() {
            Ok(u)
        } else {
            Err(MvError::NonFinite)
        }
    }

    /// IGMVC: the u(t) = u(t−1) + Δu(t) to apply (unclipped).
    pub fn igmvc(&self, m: &Model, cfg: &IgmvcConfig, w: f32) -> Result<f32, MvError> {
        if !(cfg.lambda.is_finite() && cfg.lambda >= 0.0) {
            return Err(MvError::Config);
        }
        let at = m.atilde();
        let sol = diophantine::solve(&at[..m.na + 2], &[1.0], m.k).ok_or(MvError::Diophantine)?;
        let g = conv(&sol.e[..sol.ne], &m.b[..m.nb]);
        let mut rest = w;
        for i in 0..sol.nf {
            rest -= sol.f[i] * self.y[i];
        }
        for (i, gi) in g.iter().enumerate().skip(1) {
            rest -= gi * self.du_past(i);
        }
        let den = g[0] * g[0] + cfg.lambda;
        if !(den > 1e-12) {
            return Err(MvError::Singular);
        }
        let u = self.u[0] + g[0] * rest / den;
        if u.is_finite() {
            Ok(u)
        } else {
            Err(MvError::NonFinite)
        }
    }
}

/// Product of two polynomials (coefficients in q⁻¹), fixed size.
fn conv(e: &[f32], b: &[f32]) -> [f32; MAX_K + MAX_NB] {
    let mut g = [0.0f32; MAX_K + MAX_NB];
    for (i, ei) in e.iter().enumerate() {
        for (j, bj) in b.iter().enumerate() {
            if let Some(gij) = g.get_mut(i + j) {
                *gij += ei * bj;
            }
        }
    }
    g
}

// Keep the sizes honest: F of a 4th-order Ã fits the history.
const _: () = assert!(HY > MAX_NA + 1);

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs a law in closed loop on the model itself (no noise) and returns the final y.
    fn closed_loop(incremental: bool, d: f32) -> (f32, f32) {
        // y(t) = 0.9 y(t−1) − 0.5 u(t−1) + d : a cooler with offset d (ambient share).
        let m = Model::new(&[-0.9], &[-0.5], &[], 1).unwrap();
        let mut s = MvState::new(0.0);
        let (mut y, mut u_prev) = (d / 0.1, 0.0f32);
        for _ in 0..300 {
            s.push_y(y, &m).unwrap();
            let u = if incremental {
                s.igmvc(&m, &IgmvcConfig { lambda: 0.1 }, 4.0).unwrap()
            } else {
                s.gmvc(&m, &GmvcConfig { p: 1.0, r: 1.0, s: 0.3 }, 4.0).unwrap()
            };
            s.track(u);
            y = 0.9 * y - 0.5 * u + d;
            u_prev = u;
        }
        (y, u_prev)
    }

    #[test]
    fn igmvc_has_no_offset() {
        let (y, u) = closed_loop(true, 2.8);
        assert!((y - 4.0).abs() < 1e-3, "y = {y}, u = {u}");
        // Steady state: 0.1 y = −0.5 u + 2.8 ⇒ u = (2.8 − 0.4)/0.5 = 4.8.
        assert!((u - 4.8).abs() < 1e-2, "u = {u}");
    }

    #[test]
    fn gmvc_with_control_weight_leaves_an_offset_that_shrinks_with_s() {
        let (y, _) = closed_loop(false, 2.8);
        assert!((y - 4.0).abs() > 1e-3, "S > 0 should leave an offset, y = {y}");
        assert!((y - 4.0).abs() < 1.0, "but a bounded one, y = {y}");
    }

    #[test]
    fn weights_are_checked() {
        let m = Model::new(&[-0.9], &[-0.5], &[], 1).unwrap();
        let s = MvState::new(0.0);
        assert_eq!(s.igmvc(&m, &IgmvcConfig { lambda: -1.0 }, 4.0), Err(MvError::Config));
        assert_eq!(s.gmvc(&m, &GmvcConfig { p: 0.0, r: 1.0, s: 0.0 }, 4.0), Err(MvError::Config));
    }
}
