//! Black-box model structures (Ljung, *System Identification*, 2nd ed., §4.2):
//!
//! ```text
//! ARX:    A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + e(t)
//! ARMAX:  A(q⁻¹) y(t) = q^−nk B(q⁻¹) u(t) + C(q⁻¹) e(t)
//! A = 1 + a1 q⁻¹ + … + a_na q^−na,  B = b0 + … + b_{nb−1} q^−(nb−1),  C = 1 + c1 q⁻¹ + … + c_nc q^−nc
//! ```
//!
//! Linear regression form `y(t) = φ(t)ᵀθ + e(t)` with
//! `φ(t) = [−y(t−1) … −y(t−na), u(t−nk) … u(t−nk−nb+1), ê(t−1) … ê(t−nc)]`,
//! `θ = [a1 … a_na, b0 … b_{nb−1}, c1 … c_nc]`. ê are the residuals (RELS) — for ARX, nc = 0.
//!
//! The orders are runtime values bounded by [`MAX_PARAMS`]; the estimator's parameter count is
//! a const generic chosen at the call site (on the MCU, N = 4 for the 2nd-order model).

/// Largest na + nb + nc supported.
pub const MAX_PARAMS: usize = 12;

/// Why a structure was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StructureError {
    /// na must be 1…4, nb 1…4, nc 0…2, nk 1…10.
    Orders,
}

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
    /// Checked constructor.
    pub fn new(na: usize, nb: usize, nc: usize, nk: usize) -> Result<Self, StructureError> {
        if (1..=4).contains(&na) && (1..=4).contains(&nb) && nc <= 2 && (1..=10).contains(&nk) {
            Ok(Self { na, nb, nc, nk })
        } else {
            Err(StructureError::Orders)
        }
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
        assert_eq!(Structure::new(5, 1, 0, 1), Err(StructureError::Orders));
        assert_eq!(Structure::new(2, 2, 0, 0), Err(StructureError::Orders));
    }
}
