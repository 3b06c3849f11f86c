//! Batch least squares in f64 (Ljung 1999, eq. 7.34): θ = (ΦᵀΦ)⁻¹ Φᵀ Y, accumulated row by
//! row into the normal equations (no storage of Φ) and solved by Cholesky. The reference the
//! f32 recursive estimator is checked against, and the `ls` method of `hter identify`.
//!
//! [`BatchIv`] is the instrumental-variable estimate (Ljung 1999, §7.6, eq. 7.118; Söderström &
//! Stoica, *System Identification*, ch. 8): θ = (Σ ζ φᵀ)⁻¹ Σ ζ y, with instruments ζ(t) built
//! like φ(t) but from the noise-free simulated output x(t) of a first model instead of the
//! measured y. ζ correlates with φ but not with the equation error, so coloured noise — which
//! biases ARX least squares toward a fast, one-step-ahead fit — does not bias it; the estimate
//! aims at the simulated output, which is what a controller's predictions need.

use super::model::MAX_PARAMS;

/// Why the batch solution failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BatchError {
    /// ΦᵀΦ is singular (not enough excitation or too few rows).
    Singular,
    /// More parameters than [`MAX_PARAMS`], or a non-finite row.
    Input,
}

/// Normal-equation accumulator for up to [`MAX_PARAMS`] parameters.
#[derive(Clone, Debug)]
pub struct BatchLs {
    n: usize,
    ata: [[f64; MAX_PARAMS]; MAX_PARAMS],
    aty: [f64; MAX_PARAMS],
    rows: usize,
}

impl BatchLs {
    /// An accumulator for `n` parameters.
    pub fn new(n: usize) -> Result<Self, BatchError> {
        if n == 0 || n > MAX_PARAMS {
            return Err(BatchError::Input);
        }
        Ok(Self { n, ata: [[0.0; MAX_PARAMS]; MAX_PARAMS], aty: [0.0; MAX_PARAMS], rows: 0 })
    }

    /// Adds one row φ, y.
    pub fn add(&mut self, phi: &[f64], y: f64) -> Result<(), BatchError> {
        if phi.len() < self.n || !y.is_finite() || phi[..self.n].iter().any(|x| !x.is_finite()) {
            return Err(BatchError::Input);
        }
        for i in 0..self.n {
            for j in 0..self.n {
                self.ata[i][j] += phi[i] * phi[j];
            }
            self.aty[i] += phi[i] * y;
        }
        self.rows += 1;
        Ok(())
    }

    /// Rows added.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Solves the normal equations into `theta[..n]`.
    pub fn solve(&self, theta: &mut [f64]) -> Result<(), BatchError> {
        solve_symmetric(&self.ata, &self.aty, self.n, theta)
    }
}

/// Solves `M θ = r` for a symmetric positive definite `M` (its leading `n × n` block) into
/// `theta[..n]` by Cholesky, `M = L Lᵀ`. A pivot below 1e-14 of the largest diagonal entry
/// counts as singular. Shared by [`BatchLs`] and the damped Gauss–Newton steps of
/// [`super::oe`].
pub fn solve_symmetric(
    m: &[[f64; MAX_PARAMS]; MAX_PARAMS],
    r: &[f64; MAX_PARAMS],
    n: usize,
    theta: &mut [f64],
) -> Result<(), BatchError> {
    if n == 0 || n > MAX_PARAMS || theta.len() < n {
        return Err(BatchError::Input);
    }
    // Cholesky with a relative pivot threshold.
    let scale = (0..n).map(|i| m[i][i]).fold(0.0f64, f64::max);
    let mut l = [[0.0f64; MAX_PARAMS]; MAX_PARAMS];
    for i in 0..n {
        for j in 0..=i {
            let mut s = m[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > 1e-14 * scale) {
                    return Err(BatchError::Singular);
                }
                l[i][i] = libm::sqrt(s);
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut z = [0.0f64; MAX_PARAMS];
    for i in 0..n {
        let mut s = r[i];
        for k in 0..i {
            s -= l[i][k] * z[k];
        }
        z[i] = s / l[i][i];
    }
    for i in (0..n).rev() {
        let mut s = z[i];
        for k in i + 1..n {
            s -= l[k][i] * theta[k];
        }
        theta[i] = s / l[i][i];
    }
    Ok(())
}

/// Instrumental-variable accumulator: Σ ζ φᵀ and Σ ζ y for up to [`MAX_PARAMS`] parameters.
#[derive(Clone, Debug)]
pub struct BatchIv {
    n: usize,
    zp: [[f64; MAX_PARAMS]; MAX_PARAMS],
    zy: [f64; MAX_PARAMS],
    rows: usize,
}

impl BatchIv {
    /// An accumulator for `n` parameters.
    pub fn new(n: usize) -> Result<Self, BatchError> {
        if n == 0 || n > MAX_PARAMS {
            return Err(BatchError::Input);
        }
        Ok(Self { n, zp: [[0.0; MAX_PARAMS]; MAX_PARAMS], zy: [0.0; MAX_PARAMS], rows: 0 })
    }

    /// Adds one row: instruments ζ, regressor φ, output y.
    pub fn add(&mut self, zeta: &[f64], phi: &[f64], y: f64) -> Result<(), BatchError> {
        let n = self.n;
        if zeta.len() < n
            || phi.len() < n
            || !y.is_finite()
            || zeta[..n].iter().chain(&phi[..n]).any(|x| !x.is_finite())
        {
            return Err(BatchError::Input);
        }
        for i in 0..n {
            for j in 0..n {
                self.zp[i][j] += zeta[i] * phi[j];
            }
            self.zy[i] += zeta[i] * y;
        }
        self.rows += 1;
        Ok(())
    }

    /// Solves Σ ζ φᵀ θ = Σ ζ y into `theta[..n]` by Gaussian elimination with partial pivoting
    /// (the matrix is not symmetric).
    pub fn solve(&self, theta: &mut [f64]) -> Result<(), BatchError> {
        let n = self.n;
        if theta.len() < n {
            return Err(BatchError::Input);
        }
        let mut m = self.zp;
        let mut r = self.zy;
        let scale = m.iter().take(n).flat_map(|row| row[..n].iter()).fold(0.0f64, |a, v| a.max(v.abs()));
        for c in 0..n {
            let p = (c..n).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs())).unwrap_or(c);
            if !(m[p][c].abs() > 1e-13 * scale) {
                return Err(BatchError::Singular);
            }
            m.swap(c, p);
            r.swap(c, p);
            for i in c + 1..n {
                let f = m[i][c] / m[c][c];
                for j in c..n {
                    m[i][j] -= f * m[c][j];
                }
                r[i] -= f * r[c];
            }
        }
        for i in (0..n).rev() {
            let mut s = r[i];
            for j in i + 1..n {
                s -= m[i][j] * theta[j];
            }
            theta[i] = s / m[i][i];
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_linear_relation() {
        let mut b = BatchLs::new(2).unwrap();
        for i in 0..10 {
            let x = i as f64;
            b.add(&[x, 1.0], 3.0 * x - 2.0).unwrap();
        }
        let mut th = [0.0; 2];
        b.solve(&mut th).unwrap();
        assert!((th[0] - 3.0).abs() < 1e-12 && (th[1] + 2.0).abs() < 1e-12);
        let mut s = BatchLs::new(2).unwrap();
        s.add(&[1.0, 1.0], 1.0).unwrap();
        s.add(&[2.0, 2.0], 2.0).unwrap();
        assert_eq!(s.solve(&mut th), Err(BatchError::Singular));
    }

    /// With the instruments equal to the regressors IV is least squares.
    #[test]
    fn iv_with_phi_as_instruments_is_least_squares() {
        let (mut ls, mut iv) = (BatchLs::new(3).unwrap(), BatchIv::new(3).unwrap());
        let mut seed = 7u32;
        for i in 0..50 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let x = [f64::from(i % 7), f64::from(seed >> 20) / 4096.0, 1.0];
            let y = 0.5 * x[0] - 2.0 * x[1] + 0.25 + f64::from(seed >> 28) * 0.01;
            ls.add(&x, y).unwrap();
            iv.add(&x, &x, y).unwrap();
        }
        let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
        ls.solve(&mut a).unwrap();
        iv.solve(&mut b).unwrap();
        for i in 0..3 {
            assert!((a[i] - b[i]).abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }
}
