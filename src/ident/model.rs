//! Black-box model structures (Ljung, *System Identification*, 2nd ed., 1999, §4.2, eqs. 4.7
//! and 4.15):
//!
//! ```text
//! ARX:    A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + e(t)
//! ARMAX:  A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + C(q⁻¹) e(t)
//! A = 1 + a1 q⁻¹ + … + a_na q^−na,  B = b0 + … + b_{nb−1} q^−(nb−1),  C = 1 + c1 q⁻¹ + … + c_nc q^−nc
//! ```
//!
//! Linear regression form `y(t) = φ(t)ᵀθ + e(t)` (Ljung eq. 4.13; for ARMAX the pseudolinear
//! form of eq. 4.20, with the unknown e replaced by the residuals ê):
//! `φ(t) = [−y(t−1) … −y(t−na), u(t−nk) … u(t−nk−nb+1), ê(t−1) … ê(t−nc)]`,
//! `θ = [a1 … a_na, b0 … b_{nb−1}, c1 … c_nc]`. For ARX, nc = 0.
//!
//! Two forms of the same thing:
//! - [`Structure`]: orders as runtime values (bounded by [`MAX_PARAMS`]), regressors built from
//!   whole records (slices). For the host tool, which compares orders 1, 2 and 4 on one log.
//! - [`Regressor`]: orders as const generics, for a per-sample estimator. It keeps the last na
//!   outputs, nk + nb − 1 inputs and nc residuals in fixed arrays and builds φ(t) every sample;
//!   [`Regressor::predict`] predicts one step ahead with a [`Model`]. Nothing allocates and
//!   nothing indexes out of range.
//!
//! The estimated model itself is the crate's one [`Model`] (θ splits into it with
//! [`Model::from_theta`]); the order bounds are that module's.
//!
//! **Deviation variables and scaling.** Every model here is linear without a constant term, so
//! it describes deviations from an operating point: `ỹ = (y − y0) / y_s`, `ũ = (u − u0) / u_s`
//! ([`OperatingPoint`]). The scale factors bring φ to order one (temperatures of tens of °C next
//! to duties below one would otherwise make the columns of φ differ by two decades, which f32
//! recursive least squares cannot afford on this plant, see [`crate::ident`]). A model estimated
//! on scaled data has the same a and c, and `b_physical = b_scaled · y_s / u_s`
//! ([`OperatingPoint::unscale`]).

use crate::model::{Model, ModelError, MAX_K, MAX_NA, MAX_NB, MAX_NC};
use nalgebra::SVector;

/// Largest na + nb + nc supported.
pub const MAX_PARAMS: usize = 12;
const _: () = assert!(MAX_NA + MAX_NB + MAX_NC <= MAX_PARAMS);

/// Largest delay nk supported, samples: the model's [`MAX_K`].
pub const MAX_NK: usize = MAX_K;

/// Input history kept by [`Regressor`]: u(t−1) … u(t−nk−nb+1) for the largest nk and nb.
const U_HIST: usize = MAX_NK + MAX_NB - 1;

/// Orders and delay of an ARX/ARMAX model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Structure {
    /// A order.
    pub na: usize,
    /// Number of B coefficients.
    pub nb: usize,
    /// C order (0 for ARX).
    pub nc: usize,
    /// Delay, samples (≥ 1).
    pub nk: usize,
}

impl Structure {
    /// Checked constructor: the bounds of [`Model`] (1 ≤ na ≤ [`MAX_NA`], 1 ≤ nb ≤ [`MAX_NB`],
    /// nc ≤ [`MAX_NC`], 1 ≤ nk ≤ [`MAX_NK`]).
    pub fn new(na: usize, nb: usize, nc: usize, nk: usize) -> Result<Self, ModelError> {
        if (1..=MAX_NA).contains(&na) && (1..=MAX_NB).contains(&nb) && nc <= MAX_NC && (1..=MAX_NK).contains(&nk) {
            Ok(Self { na, nb, nc, nk })
        } else {
            Err(ModelError::Order)
        }
    }

    /// The model of θ = [a, b, c] (f32) in this structure.
    pub fn model(&self, theta: &[f32]) -> Result<Model, ModelError> {
        Model::from_theta(theta, self.na, self.nb, self.nc, self.nk)
    }

    /// Number of parameters na + nb + nc.
    pub fn n_params(&self) -> usize {
        self.na + self.nb + self.nc
    }

    /// First sample index t at which φ(t) uses no data before the record.
    pub fn first_index(&self) -> usize {
        self.na.max(self.nk + self.nb - 1).max(self.nc)
    }

    /// Fills `phi[..n_params]` with φ(t) from the records (deviation variables). `e` may be
    /// empty when nc = 0. Returns `false` if t is too early or a slice is too short.
    pub fn regressor<T: Copy + core::ops::Neg<Output = T> + Default>(
        &self,
        y: &[T],
        u: &[T],
        e: &[T],
        t: usize,
        phi: &mut [T],
    ) -> bool {
        if t < self.first_index() || t >= y.len() || t >= u.len() || phi.len() < self.n_params() {
            return false;
        }
        if self.nc > 0 && t > e.len() {
            return false;
        }
        for i in 0..self.na {
            phi[i] = -y[t - 1 - i];
        }
        for i in 0..self.nb {
            phi[self.na + i] = u[t - self.nk - i];
        }
        for i in 0..self.nc {
            phi[self.na + self.nb + i] = e.get(t - 1 - i).copied().unwrap_or_default();
        }
        true
    }
}

/// Operating point and scale factors of the deviation variables
/// `ỹ = (y − y0) / y_scale`, `ũ = (u − u0) / u_scale`.
///
/// Choose y0, u0 where the data start at rest (or the record's means), and the scales so that
/// ỹ and ũ are of order one over the experiment (e.g. the expected temperature swing in °C and
/// the duty swing).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OperatingPoint {
    /// Output at the operating point (°C for the carrier).
    pub y0: f32,
    /// Input at the operating point (duty).
    pub u0: f32,
    /// Output scale (same unit as y), > 0.
    pub y_scale: f32,
    /// Input scale (same unit as u), > 0.
    pub u_scale: f32,
}

impl OperatingPoint {
    /// No offset, no scaling: the data are already deviation variables of order one.
    pub const IDENTITY: OperatingPoint = OperatingPoint { y0: 0.0, u0: 0.0, y_scale: 1.0, u_scale: 1.0 };

    /// Checked constructor: `None` unless y0 and u0 are finite and both scales finite and > 0.
    pub fn new(y0: f32, u0: f32, y_scale: f32, u_scale: f32) -> Option<Self> {
        let ok = y0.is_finite()
            && u0.is_finite()
            && y_scale.is_finite()
            && u_scale.is_finite()
            && y_scale > 0.0
            && u_scale > 0.0;
        ok.then_some(Self { y0, u0, y_scale, u_scale })
    }

    /// ỹ = (y − y0) / y_scale.
    pub fn y_dev(&self, y: f32) -> f32 {
        (y - self.y0) / self.y_scale
    }

    /// ũ = (u − u0) / u_scale.
    pub fn u_dev(&self, u: f32) -> f32 {
        (u - self.u0) / self.u_scale
    }

    /// y = y0 + ỹ · y_scale (back from deviation units).
    pub fn y_abs(&self, y_dev: f32) -> f32 {
        self.y0 + y_dev * self.y_scale
    }

    /// u = u0 + ũ · u_scale.
    pub fn u_abs(&self, u_dev: f32) -> f32 {
        self.u0 + u_dev * self.u_scale
    }

    /// A model estimated in these scaled deviations, in physical deviation units:
    /// `b · y_scale / u_scale` (a and c are dimensionless and stay).
    pub fn unscale(&self, m: &Model) -> Result<Model, ModelError> {
        m.with_b_scaled(self.y_scale / self.u_scale)
    }
}

/// Per-sample regressor builder for an ARMAX(NA, NB, NC) structure with delay nk (ARX: NC = 0).
///
/// Each sample: build φ(t) with [`Regressor::phi`] (it uses only data up to t − 1), update the
/// estimator against [`Regressor::y_dev`]`(y(t))`, then record the sample with
/// [`Regressor::push`] once u(t) is known (and, for RELS, the residual with
/// [`Regressor::push_residual`]; [`crate::ident::recursive::Rels`] does that itself).
/// Values are stored as scaled deviations ([`OperatingPoint`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Regressor<const NA: usize, const NB: usize, const NC: usize> {
    op: OperatingPoint,
    nk: usize,
    /// ỹ(t−1), ỹ(t−2), … newest first.
    y: [f32; NA],
    /// ũ(t−1), ũ(t−2), … newest first.
    u: [f32; U_HIST],
    /// ê(t−1), … newest first.
    e: [f32; NC],
    /// Samples pushed, saturating at the history length needed.
    filled: usize,
}

impl<const NA: usize, const NB: usize, const NC: usize> Regressor<NA, NB, NC> {
    /// Parameters of the structure, na + nb + nc.
    pub const N_PARAMS: usize = NA + NB + NC;

    const SUPPORTED: () = assert!(
        NA >= 1 && NA <= MAX_NA && NB >= 1 && NB <= MAX_NB && NC <= MAX_NC,
        "supported orders: na 1..=4, nb 1..=4, nc 0..=2"
    );

    /// Empty history with delay `nk` (1…[`MAX_NK`]) around the operating point `op`.
    pub fn new(nk: usize, op: OperatingPoint) -> Result<Self, ModelError> {
        let () = Self::SUPPORTED;
        if !(1..=MAX_NK).contains(&nk) {
            return Err(ModelError::Order);
        }
        Ok(Self { op, nk, y: [0.0; NA], u: [0.0; U_HIST], e: [0.0; NC], filled: 0 })
    }

    /// The operating point and scales.
    pub fn operating_point(&self) -> &OperatingPoint {
        &self.op
    }

    /// Delay nk, samples.
    pub fn nk(&self) -> usize {
        self.nk
    }

    /// Samples of history needed before φ is complete: max(na, nk + nb − 1).
    pub fn needed(&self) -> usize {
        NA.max(self.nk + NB - 1)
    }

    /// True once enough samples were pushed for φ(t) to use measured data only.
    pub fn ready(&self) -> bool {
        self.filled >= self.needed()
    }

    /// The estimator's target for output y(t): ỹ(t) = (y − y0) / y_scale.
    pub fn y_dev(&self, y: f32) -> f32 {
        self.op.y_dev(y)
    }

    /// Records sample t: output y(t) and input u(t), in physical units. Non-finite values are
    /// stored as given, so the estimator refuses the next na (or nk + nb − 1) updates instead of
    /// learning from a substitute.
    pub fn push(&mut self, y: f32, u: f32) {
        self.y.rotate_right(1);
        self.u.rotate_right(1);
        if let Some(v) = self.y.first_mut() {
            *v = self.op.y_dev(y);
        }
        if let Some(v) = self.u.first_mut() {
            *v = self.op.u_dev(u);
        }
        self.filled = (self.filled + 1).min(U_HIST + NA);
    }

    /// Records the residual ê(t) (scaled deviation units) for the C part of φ.
    pub fn push_residual(&mut self, e: f32) {
        if NC > 0 {
            self.e.rotate_right(1);
            if let Some(v) = self.e.first_mut() {
                *v = e;
            }
        }
    }

    /// Forgets the history (after a sensor fault, a gap in the data or a mode change).
    pub fn clear(&mut self) {
        self.y = [0.0; NA];
        self.u = [0.0; U_HIST];
        self.e = [0.0; NC];
        self.filled = 0;
    }

    /// φ(t) = [−ỹ(t−1) … −ỹ(t−na), ũ(t−nk) … ũ(t−nk−nb+1), ê(t−1) … ê(t−nc)], or `None` until
    /// [`Regressor::ready`]. `N` must be na + nb + nc (checked at compile time).
    pub fn phi<const N: usize>(&self) -> Option<SVector<f32, N>> {
        const { assert!(N == NA + NB + NC, "phi::<N>() needs N = NA + NB + NC") };
        if !self.ready() {
            return None;
        }
        let mut phi = SVector::<f32, N>::zeros();
        for (dst, y) in phi.iter_mut().zip(self.y.iter()) {
            *dst = -*y;
        }
        let us = self.u.iter().skip(self.nk - 1).take(NB);
        for (dst, u) in phi.iter_mut().skip(NA).zip(us) {
            *dst = *u;
        }
        for (dst, e) in phi.iter_mut().skip(NA + NB).zip(self.e.iter()) {
            *dst = *e;
        }
        Some(phi)
    }

    /// One-step-ahead prediction ŷ(t|t−1) = φ(t)ᵀθ of model `m` in this regressor's deviation
    /// units (for ARMAX with the residuals the regressor holds: the predictor
    /// C ŷ = (C − A) y + q^−nk B u of Ljung eq. 4.18). `None` until the regressor is ready, or
    /// when `m` has another structure.
    pub fn predict(&self, m: &Model) -> Option<f32> {
        if (m.na(), m.nb(), m.nc(), m.k()) != (NA, NB, NC, self.nk) || !self.ready() {
            return None;
        }
        let mut acc = 0.0f32;
        for (a, y) in m.a().iter().zip(self.y.iter()) {
            acc -= a * y;
        }
        let us = self.u.iter().skip(self.nk - 1).take(NB);
        for (b, u) in m.b().iter().zip(us) {
            acc += b * u;
        }
        for (c, e) in m.c().iter().zip(self.e.iter()) {
            acc += c * e;
        }
        Some(acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regressor_layout() {
        let s = Structure::new(2, 2, 1, 1).unwrap();
        let y = [1.0, 2.0, 3.0, 4.0];
        let u = [10.0, 20.0, 30.0, 40.0];
        let e = [0.1, 0.2, 0.3, 0.4];
        let mut phi = [0.0; 5];
        assert!(s.regressor(&y, &u, &e, 2, &mut phi));
        assert_eq!(phi, [-2.0, -1.0, 20.0, 10.0, 0.2]);
        assert!(!s.regressor(&y, &u, &e, 1, &mut phi));
        assert_eq!(Structure::new(5, 1, 0, 1), Err(ModelError::Order));
        assert_eq!(Structure::new(2, 2, 0, 0), Err(ModelError::Order));
    }

    #[test]
    fn streaming_regressor_matches_the_record_form() {
        // Same data through Structure::regressor (slices) and Regressor (per sample), nk = 2.
        let s = Structure::new(2, 3, 1, 2).unwrap();
        let op = OperatingPoint::new(20.0, 0.5, 2.0, 0.25).unwrap();
        let mut reg = Regressor::<2, 3, 1>::new(2, op).unwrap();
        let raw_y = [20.0f32, 21.0, 23.0, 22.0, 24.0, 25.0, 20.0, 19.0];
        let raw_u = [0.5f32, 0.75, 0.25, 1.0, 0.0, 0.5, 0.75, 1.0];
        let y: std::vec::Vec<f32> = raw_y.iter().map(|v| op.y_dev(*v)).collect();
        let u: std::vec::Vec<f32> = raw_u.iter().map(|v| op.u_dev(*v)).collect();
        let e: std::vec::Vec<f32> = (0..8).map(|i| i as f32 * 0.1).collect();
        for t in 0..8 {
            let mut want = [0.0f32; 6];
            let ok = s.regressor(&y, &u, &e, t, &mut want);
            assert_eq!(reg.ready(), ok, "t = {t}");
            match reg.phi::<6>() {
                Some(phi) => assert_eq!(phi.as_slice(), &want, "t = {t}"),
                None => assert!(!ok),
            }
            reg.push(raw_y[t], raw_u[t]);
            reg.push_residual(e[t]);
        }
        assert_eq!(Regressor::<2, 2, 0>::new(0, op), Err(ModelError::Order));
        assert_eq!(Regressor::<2, 2, 0>::new(11, op), Err(ModelError::Order));
        assert!(OperatingPoint::new(0.0, 0.0, 0.0, 1.0).is_none());
        assert!(OperatingPoint::new(f32::NAN, 0.0, 1.0, 1.0).is_none());
    }

    #[test]
    fn prediction_follows_the_difference_equation() {
        // y(t) = 1.5 y(t−1) − 0.56 y(t−2) + 0.5 u(t−1) + 0.25 u(t−2)
        let theta = [-1.5f32, 0.56, 0.5, 0.25];
        let m = Structure::new(2, 2, 0, 1).unwrap().model(&theta).unwrap();
        let u: std::vec::Vec<f32> = (0..40).map(|t| if (t / 5) % 2 == 0 { 1.0 } else { 0.0 }).collect();
        let mut y = std::vec![0.0f32; 40];
        y[0] = 0.3;
        y[1] = 0.2;
        for t in 2..40 {
            y[t] = 1.5 * y[t - 1] - 0.56 * y[t - 2] + 0.5 * u[t - 1] + 0.25 * u[t - 2];
        }
        let mut reg = Regressor::<2, 2, 0>::new(1, OperatingPoint::IDENTITY).unwrap();
        for t in 0..40 {
            if let Some(p) = reg.predict(&m) {
                assert!((p - y[t]).abs() < 1e-5, "t = {t}");
                let phi = reg.phi::<4>().unwrap();
                assert!((phi.dot(&SVector::from(theta)) - p).abs() < 1e-6);
            } else {
                assert!(t < 2);
            }
            reg.push(y[t], u[t]);
        }
        // A model of another structure or delay predicts nothing with this regressor.
        assert_eq!(reg.predict(&m.with_delay(2).unwrap()), None);
        assert_eq!(reg.predict(&Structure::new(1, 2, 0, 1).unwrap().model(&[-0.9, 0.5, 0.25]).unwrap()), None);
        let op = OperatingPoint::new(0.0, 0.0, 10.0, 0.5).unwrap();
        assert_eq!(op.unscale(&m).unwrap().b()[..2], [10.0, 5.0]);
    }
}
