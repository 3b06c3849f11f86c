//! Batch least squares in f64 (Ljung 1999, eq. 7.34): θ = (ΦᵀΦ)⁻¹ Φᵀ Y, accumulated row by
//! row into the normal equations (no storage of Φ) and solved by Cholesky. The reference the
//! f32 recursive estimator is checked against, and the `ls` method of `hter identify`.

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
        let n = self.n;
        if theta.len() < n {
            return Err(BatchError::Input);
        }
        // Cholesky with a relative pivot threshold.
        let scale = (0..n).map(|i| self.ata[i][i]).fold(0.0f64, f64::max);
        let mut l = [[0.0f64; MAX_PARAMS]; MAX_PARAMS];
        for i in 0..n {
            for j in 0..=i {
                let mut s = self.ata[i][j];
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
            let mut s = self.aty[i];
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
}
