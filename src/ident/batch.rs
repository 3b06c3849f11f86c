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
//!
//! [`least_squares`] and [`instrumental_variables`] run the two on a whole record of an ARX
//! structure (the `ls` and `iv` methods of `hter identify`, and the first starts of the
//! output-error search in [`super::oe_search`]). The IV estimate is iterated: the first
//! instruments are simulated from the least-squares model, each later round's from the model
//! of the round before, for [`IV_ROUNDS`] rounds.

use super::model::{Structure, MAX_PARAMS};
use super::validate;

/// Why the batch solution failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BatchError {
    /// ΦᵀΦ is singular (not enough excitation or too few rows).
    Singular,
    /// More parameters than [`MAX_PARAMS`], or a non-finite row.
    Input,
    /// An ARMAX structure (nc > 0) given to a record estimator, which fits ARX only.
    Structure,
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

/// Rounds of [`instrumental_variables`] after the least-squares start (fewer when a round is
/// singular or its model's simulation diverges).
pub const IV_ROUNDS: usize = 3;

/// Simulated outputs beyond this magnitude (in the data's unit) make no instruments: the model
/// they come from is unstable or nearly so.
const IV_DIVERGED: f64 = 1e6;

/// Batch least squares of an ARX structure on the whole record (deviation variables y, u of
/// equal length) into `theta[..n_params]`.
pub fn least_squares(s: &Structure, y: &[f64], u: &[f64], theta: &mut [f64]) -> Result<(), BatchError> {
    if s.nc > 0 {
        return Err(BatchError::Structure);
    }
    let n = s.n_params();
    let mut ls = BatchLs::new(n)?;
    let mut phi = [0.0f64; MAX_PARAMS];
    for t in s.first_index()..y.len() {
        if s.regressor(y, u, &[], t, &mut phi) {
            ls.add(&phi[..n], y[t])?;
        }
    }
    ls.solve(theta)
}

/// Iterated instrumental variables of an ARX structure on the whole record, from the start
/// `theta[..n_params]` (the least-squares estimate), in place. `x` (at least `y.len()` long)
/// holds the simulated outputs the instruments are built from.
///
/// Each round's instruments come from the previous model; the iterate whose simulation fits the
/// record best is kept, since a round can overshoot into an unstable model, whose simulation is
/// no instrument and no model. A singular round or a diverging simulation ends the rounds.
pub fn instrumental_variables(
    s: &Structure,
    y: &[f64],
    u: &[f64],
    theta: &mut [f64],
    x: &mut [f64],
) -> Result<(), BatchError> {
    if s.nc > 0 {
        return Err(BatchError::Structure);
    }
    let n = s.n_params();
    if theta.len() < n || x.len() < y.len() || n > MAX_PARAMS {
        return Err(BatchError::Input);
    }
    let x = &mut x[..y.len()];
    let mut th = [0.0f64; MAX_PARAMS];
    th[..n].copy_from_slice(&theta[..n]);
    let (mut zeta, mut phi) = ([0.0f64; MAX_PARAMS], [0.0f64; MAX_PARAMS]);
    let mut best = (validate::simulate_fit(s, &th[..n], y, u, x), th);
    for _ in 0..IV_ROUNDS {
        validate::simulate_fit(s, &th[..n], y, u, x);
        if x.iter().any(|v| !v.is_finite() || v.abs() >= IV_DIVERGED) {
            break;
        }
        let mut iv = BatchIv::new(n)?;
        for t in s.first_index()..y.len() {
            if s.regressor(x, u, &[], t, &mut zeta) && s.regressor(y, u, &[], t, &mut phi) {
                iv.add(&zeta[..n], &phi[..n], y[t])?;
            }
        }
        let mut next = [0.0f64; MAX_PARAMS];
        if iv.solve(&mut next).is_err() {
            break;
        }
        th = next;
        let f = validate::simulate_fit(s, &th[..n], y, u, x);
        if f.is_finite() && (best.0.is_nan() || f > best.0) {
            best = (f, th);
        }
    }
    theta[..n].copy_from_slice(&best.1[..n]);
    Ok(())
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

    /// Output-error plant y = B/A u + v with white v: the equation error A v is coloured, so
    /// least squares is biased (it pulls the pole toward zero); iterated IV is not, and
    /// simulates the record better.
    #[test]
    fn iv_removes_the_bias_least_squares_has_under_coloured_noise() {
        let n = 4000;
        let (mut x1, mut u1) = (0.0f64, 0.0f64);
        let mut state = 0xACE1u16;
        let mut seed = 99u32;
        let (mut y, mut u) = (std::vec::Vec::with_capacity(n), std::vec::Vec::with_capacity(n));
        for t in 0..n {
            // Noise-free x(t) = 0.95 x(t−1) + 0.5 u(t−1).
            let x = 0.95 * x1 + 0.5 * u1;
            if t % 3 == 0 {
                let bit = (state ^ (state >> 2) ^ (state >> 3) ^ (state >> 5)) & 1;
                state = (state >> 1) | (bit << 15);
            }
            let ut = if state & 1 == 1 { 1.0 } else { -1.0 };
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5) * 2.0;
            y.push(x + v);
            u.push(ut);
            (x1, u1) = (x, ut);
        }
        let s = Structure::new(1, 1, 0, 1).unwrap();
        let mut ls = [0.0; 2];
        least_squares(&s, &y, &u, &mut ls).unwrap();
        let mut iv = ls;
        let mut x = std::vec![0.0; n];
        instrumental_variables(&s, &y, &u, &mut iv, &mut x).unwrap();
        assert!((ls[0] + 0.95).abs() > 0.03, "LS should be biased here: a1 = {}", ls[0]);
        assert!((iv[0] + 0.95).abs() < 0.01, "IV a1 = {} (want −0.95)", iv[0]);
        assert!((iv[1] - 0.5).abs() < 0.05, "IV b0 = {} (want 0.5)", iv[1]);
        let fit_ls = validate::simulate_fit(&s, &ls, &y, &u, &mut x);
        let fit_iv = validate::simulate_fit(&s, &iv, &y, &u, &mut x);
        assert!(fit_iv > fit_ls, "IV fit {fit_iv} vs LS {fit_ls}");
    }

    #[test]
    fn record_estimators_refuse_armax_and_short_buffers() {
        let armax = Structure::new(1, 1, 1, 1).unwrap();
        let (y, u) = ([0.0, 1.0, 0.5, 0.2], [1.0, 0.0, 1.0, 0.0]);
        let mut th = [0.0; 3];
        assert_eq!(least_squares(&armax, &y, &u, &mut th), Err(BatchError::Structure));
        assert_eq!(instrumental_variables(&armax, &y, &u, &mut th, &mut [0.0; 4]), Err(BatchError::Structure));
        let s = Structure::new(1, 1, 0, 1).unwrap();
        assert_eq!(instrumental_variables(&s, &y, &u, &mut th, &mut [0.0; 3]), Err(BatchError::Input));
        // Constant data leave the normal equations singular.
        assert_eq!(least_squares(&s, &[1.0; 20], &[0.5; 20], &mut th), Err(BatchError::Singular));
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
