//! The linear discrete-time model of the carrier: what identification estimates, what the
//! self-tuner trusts and persists, and what the model-based laws are designed from.
//!
//! ```text
//! A(q⁻¹) y(t) = q^−k B(q⁻¹) u(t) + C(q⁻¹) e(t)            (ARX: C = 1; Ljung, System Identification, 2nd ed., §4.2)
//! A(q⁻¹) y(t) = q^−k B(q⁻¹) u(t) + C(q⁻¹) e(t) / Δ        (CARIMA, the predictive laws' view; Clarke et al. 1987)
//! A = 1 + a1 q⁻¹ + … + a_na q⁻na,   B = b0 + b1 q⁻¹ + … + b_{nb−1} q^−(nb−1),   C = 1 + c1 q⁻¹ + …
//! ```
//!
//! Orders are bounded at compile time ([`MAX_NA`], [`MAX_NB`], [`MAX_NC`], [`MAX_K`]) so the
//! model is `Copy` and lives on the stack. Its fields are private: every [`Model`] was built by
//! a checked constructor, so 1 ≤ na ≤ [`MAX_NA`], 1 ≤ nb ≤ [`MAX_NB`], nc ≤ [`MAX_NC`],
//! 1 ≤ k ≤ [`MAX_K`], every coefficient is finite and the unused ones are zero — code that
//! indexes the coefficients by the orders cannot go out of range.
//!
//! Glossary: na, nb, nc — orders of A, B (number of b coefficients) and C; k — delay in samples;
//! Ã = ΔA — A times the difference operator Δ = 1 − q⁻¹.

/// Largest A order.
pub const MAX_NA: usize = 4;
/// Most B coefficients.
pub const MAX_NB: usize = 4;
/// Largest C order.
pub const MAX_NC: usize = 2;
/// Largest delay, samples.
pub const MAX_K: usize = 10;

/// Why a model (or a model structure) was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// An order or the delay is outside the supported range: 1 ≤ na ≤ [`MAX_NA`],
    /// 1 ≤ nb ≤ [`MAX_NB`], nc ≤ [`MAX_NC`], 1 ≤ k ≤ [`MAX_K`].
    Order,
    /// A coefficient is NaN or infinite.
    NonFinite,
}

/// An ARX/ARMAX/CARIMA model with bounded orders (see the module docs for its invariants).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Model {
    a: [f32; MAX_NA],
    b: [f32; MAX_NB],
    c: [f32; MAX_NC],
    na: usize,
    nb: usize,
    nc: usize,
    k: usize,
}

/// Are the orders and the delay within the supported range?
const fn orders_ok(na: usize, nb: usize, nc: usize, k: usize) -> bool {
    na >= 1 && na <= MAX_NA && nb >= 1 && nb <= MAX_NB && nc <= MAX_NC && k >= 1 && k <= MAX_K
}

impl Model {
    /// y(t) = y(t−1) + u(t−1)·0: a placeholder that lets histories advance when no model is known.
    pub const NEUTRAL: Model =
        Model { a: [-1.0, 0.0, 0.0, 0.0], b: [0.0; MAX_NB], c: [0.0; MAX_NC], na: 1, nb: 1, nc: 0, k: 1 };

    /// All zeros, orders included: not a model any constructor gives, only a placeholder for
    /// storage that is written before it is read (a `GpcStaged` bank before its first
    /// design), which a board then fills with a memset instead of copying a constant.
    pub(crate) const ZERO: Model =
        Model { a: [0.0; MAX_NA], b: [0.0; MAX_NB], c: [0.0; MAX_NC], na: 0, nb: 0, nc: 0, k: 0 };

    /// Builds a model from coefficient slices (a without the leading 1, c likewise).
    pub fn new(a: &[f32], b: &[f32], c: &[f32], k: usize) -> Result<Model, ModelError> {
        if !orders_ok(a.len(), b.len(), c.len(), k) {
            return Err(ModelError::Order);
        }
        if a.iter().chain(b).chain(c).any(|x| !x.is_finite()) {
            return Err(ModelError::NonFinite);
        }
        // Element by element: a run-time-length copy is a memcpy call on the M4, and the
        // self-tuning controller builds a model every sample.
        let pad = |v: &[f32], i: usize| v.get(i).copied().unwrap_or(0.0);
        Ok(Model {
            a: core::array::from_fn(|i| pad(a, i)),
            b: core::array::from_fn(|i| pad(b, i)),
            c: core::array::from_fn(|i| pad(c, i)),
            na: a.len(),
            nb: b.len(),
            nc: c.len(),
            k,
        })
    }

    /// The second-order model A = 1 + a1 q⁻¹ + a2 q⁻², B = b0 + b1 q⁻¹, C = 1, delay `k` (the
    /// self-tuner's structure); usable in constants.
    pub const fn second_order(a: [f32; 2], b: [f32; 2], k: usize) -> Result<Model, ModelError> {
        if !orders_ok(2, 2, 0, k) {
            return Err(ModelError::Order);
        }
        if !(a[0].is_finite() && a[1].is_finite() && b[0].is_finite() && b[1].is_finite()) {
            return Err(ModelError::NonFinite);
        }
        Ok(Model { a: [a[0], a[1], 0.0, 0.0], b: [b[0], b[1], 0.0, 0.0], c: [0.0; MAX_NC], na: 2, nb: 2, nc: 0, k })
    }

    /// Splits θ = [a1 … a_na, b0 … b_{nb−1}, c1 … c_nc] (the identification parameter vector)
    /// into a model with delay `k`. θ must hold exactly na + nb + nc values.
    pub fn from_theta(theta: &[f32], na: usize, nb: usize, nc: usize, k: usize) -> Result<Model, ModelError> {
        if na.checked_add(nb).and_then(|n| n.checked_add(nc)) != Some(theta.len()) {
            return Err(ModelError::Order);
        }
        let (a, rest) = theta.split_at_checked(na).ok_or(ModelError::Order)?;
        let (b, c) = rest.split_at_checked(nb).ok_or(ModelError::Order)?;
        Model::new(a, b, c, k)
    }

    /// a1 … a_na (without the leading 1), zero beyond na.
    pub const fn a(&self) -> &[f32; MAX_NA] {
        &self.a
    }

    /// b0 … b_{nb−1}, zero beyond nb.
    pub const fn b(&self) -> &[f32; MAX_NB] {
        &self.b
    }

    /// c1 … c_nc (without the leading 1), zero beyond nc.
    pub const fn c(&self) -> &[f32; MAX_NC] {
        &self.c
    }

    /// A order, 1 … [`MAX_NA`].
    pub const fn na(&self) -> usize {
        self.na
    }

    /// Number of B coefficients, 1 … [`MAX_NB`].
    pub const fn nb(&self) -> usize {
        self.nb
    }

    /// C order, 0 … [`MAX_NC`].
    pub const fn nc(&self) -> usize {
        self.nc
    }

    /// Delay in samples, 1 … [`MAX_K`].
    pub const fn k(&self) -> usize {
        self.k
    }

    /// The same model with delay `k`.
    pub fn with_delay(&self, k: usize) -> Result<Model, ModelError> {
        if !orders_ok(self.na, self.nb, self.nc, k) {
            return Err(ModelError::Order);
        }
        Ok(Model { k, ..*self })
    }

    /// The same model with B multiplied by `gain` (a change of the input's or the output's
    /// unit: A and C are dimensionless).
    pub fn with_b_scaled(&self, gain: f32) -> Result<Model, ModelError> {
        let b = self.b.map(|x| x * gain);
        if b.iter().any(|x| !x.is_finite()) {
            return Err(ModelError::NonFinite);
        }
        Ok(Model { b, ..*self })
    }

    /// Steady-state gain B(1)/A(1), output units per input unit (`None` if A(1) ≈ 0).
    pub fn static_gain(&self) -> Option<f32> {
        let a1 = 1.0 + self.a.iter().sum::<f32>();
        let b1: f32 = self.b.iter().sum();
        (a1.abs() > 1e-9).then(|| b1 / a1)
    }

    /// Ã = Δ·A = (1 − q⁻¹) A: coefficients ã_0 = 1, ã_1 … ã_{na+1}.
    ///
    /// ã_i = a_i − a_{i−1} (a_0 = 1) over the whole array: the unused a_i are zero (module
    /// docs), so beyond na + 1 it gives 0 − 0 = +0 and at na + 1 it gives 0 − a_na, the values
    /// a loop to na + 1 writes, bit for bit. A fixed length unrolls with no branch or bounds
    /// check; the step computes Ã several times a sample (`cargo xtask pil`).
    pub fn atilde(&self) -> [f32; MAX_NA + 2] {
        let a = |i: usize| match i {
            0 => 1.0,
            _ => self.a.get(i - 1).copied().unwrap_or(0.0),
        };
        core::array::from_fn(|i| if i == 0 { 1.0 } else { a(i) - a(i - 1) })
    }

    /// True if all roots of A lie strictly inside the unit circle (Jury's criterion for
    /// orders 1 and 2; for higher orders, Schur–Cohn reduction).
    pub fn a_is_stable(&self) -> bool {
        match self.na {
            1 => self.a[0].abs() < 1.0,
            2 => second_order_stable(self.a[0], self.a[1]),
            _ => schur_stable(&self.a, self.na),
        }
    }

    /// Simulates the deterministic part `A y_sim = q^−k B u` from the input alone (C and the
    /// noise play no part). For t < max(na, k + nb − 1) the output is taken from `y_init` (the
    /// measured initial condition; zero where `y_init` is shorter), after that only the model's
    /// own past outputs are used. Writes `min(u.len(), y_out.len())` samples and returns that
    /// count.
    pub fn simulate(&self, u: &[f32], y_init: &[f32], y_out: &mut [f32]) -> usize {
        let n = u.len().min(y_out.len());
        let start = self.na.max(self.k + self.nb - 1);
        for t in 0..n {
            if t < start {
                y_out[t] = y_init.get(t).copied().unwrap_or(0.0);
                continue;
            }
            let mut v = 0.0f32;
            for i in 0..self.na {
                v -= self.a[i] * y_out[t - 1 - i];
            }
            for i in 0..self.nb {
                v += self.b[i] * u[t - self.k - i];
            }
            y_out[t] = v;
        }
        n
    }
}

/// Are both roots of 1 + a1 z⁻¹ + a2 z⁻² inside the unit circle? Jury's conditions |a2| < 1 and
/// |a1| < 1 + a2 (a first-order A is a2 = 0). The self-tuner's every-sample check: a caller that
/// only has second-order models uses this and leaves the general recursion (and the software
/// f64 it needs on the M4F, ≈ 2 KB of flash) out of its binary.
///
/// The comparison is exact in f32 (no software f64 either): 1 + a2 = s + e exactly, with
/// s = fl(1 + a2) and e = a2 − (s − 1) (Fast2Sum, since |a2| < 1; Higham, "Accuracy and Stability
/// of Numerical Algorithms", §4.3), so |a1| < 1 + a2 ⟺ |a1| − s < e. |a1| − s is exact when
/// s/2 ≤ |a1| ≤ 2s (Sterbenz's lemma); outside that its sign is that of the exact difference,
/// and |e| ≤ ulp(s)/2 cannot change the verdict.
pub fn second_order_stable(a1: f32, a2: f32) -> bool {
    if !(a2.abs() < 1.0) {
        return false;
    }
    let s = 1.0 + a2;
    let e = a2 - (s - 1.0);
    a1.abs() - s < e
}

/// Schur–Cohn test: are all roots of 1 + a1 z⁻¹ + … + a_n z⁻ⁿ (the first `n` of `a`) inside the
/// unit circle? Step-down (Levinson) recursion on the coefficients, in f64 for margin near
/// |z| = 1 (software on the M4F, ≈ 1 000 instructions: orders 1 and 2 use Jury's conditions).
fn schur_stable(a: &[f32; MAX_NA], n: usize) -> bool {
    let n = n.min(MAX_NA);
    let mut p = [0.0f64; MAX_NA + 1];
    p[0] = 1.0;
    for (dst, src) in p[1..].iter_mut().zip(a).take(n) {
        *dst = f64::from(*src);
    }
    let mut m = n;
    while m > 0 {
        let km = p[m];
        if !(km.abs() < 1.0) {
            return false;
        }
        let den = 1.0 - km * km;
        let mut q = [0.0f64; MAX_NA + 1];
        for i in 0..m {
            q[i] = (p[i] - km * p[m - i]) / den;
        }
        p = q;
        m -= 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atilde_is_the_product_of_delta_and_a_bit_for_bit() {
        // (1 − q⁻¹)·A by a plain convolution of [1, a_1 … a_na] with [1, −1], zeros beyond.
        let conv = |a: &[f32]| {
            let poly: Vec<f32> = core::iter::once(1.0).chain(a.iter().copied()).collect();
            let mut out = [0.0f32; MAX_NA + 2];
            for (i, p) in poly.iter().enumerate() {
                out[i] += p;
                out[i + 1] -= p;
            }
            out
        };
        let mut seed = 777u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 23) as f32 - 1.0
        };
        for na in 1..=MAX_NA {
            for case in 0..200 {
                let mut a: Vec<f32> = (0..na).map(|_| 2.0 * next()).collect();
                if case == 0 {
                    a.iter_mut().for_each(|x| *x = -0.0);
                }
                let m = Model::new(&a, &[-0.1], &[], 3).unwrap();
                let want = conv(&a);
                let got = m.atilde();
                for i in 0..MAX_NA + 2 {
                    assert_eq!(got[i].to_bits(), want[i].to_bits(), "na {na}, ã_{i}: {got:?} against {want:?}");
                }
            }
        }
    }

    #[test]
    fn second_order_check_is_exact_against_f64() {
        let exact = |a1: f32, a2: f32| a2.abs() < 1.0 && f64::from(a1.abs()) < 1.0 + f64::from(a2);
        // (f64 is exact for these: |a2| ≥ 2⁻³⁰.) The carrier's poles sit within 1e-4 of 1: probe
        // the boundary |a1| = 1 + a2 ulp by ulp.
        for a2 in [0.751_4f32, 0.999_9, -0.999_999, 9.5e-7, -0.5, 0.0, 0.3] {
            let edge = (1.0f64 + f64::from(a2)) as f32;
            let mut x = edge;
            for _ in 0..4 {
                x = f32::from_bits(x.to_bits() - 1);
            }
            for _ in 0..8 {
                for a1 in [x, -x] {
                    assert_eq!(second_order_stable(a1, a2), exact(a1, a2), "a1 {a1:e} a2 {a2:e}");
                }
                x = f32::from_bits(x.to_bits() + 1);
            }
        }
        let mut seed = 12345u32;
        for _ in 0..200_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let a1 = (seed >> 8) as f32 / (1u32 << 23) as f32 - 1.0;
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let a2 = (seed >> 8) as f32 / (1u32 << 24) as f32 * 2.2 - 1.1;
            assert_eq!(second_order_stable(a1, a2), exact(a1, a2), "a1 {a1:e} a2 {a2:e}");
        }
        assert!(!second_order_stable(0.0, f32::NAN) && !second_order_stable(f32::NAN, 0.5));
    }

    fn stable(a: &[f32]) -> bool {
        Model::new(a, &[1.0], &[], 1).unwrap().a_is_stable()
    }

    #[test]
    fn stability_of_known_polynomials() {
        assert!(stable(&[-0.9]));
        assert!(!stable(&[-1.0]));
        assert!(stable(&[-1.8, 0.81])); // double pole at 0.9
        assert!(!stable(&[-2.1, 1.1])); // poles 1.0 and 1.1
        assert!(stable(&[-1.995, 0.99501])); // poles ≈ 0.9975 ± small
                                             // (1 − 0.5 q⁻¹)(1 − 1.2 q⁻¹) = 1 − 1.7 q⁻¹ + 0.6 q⁻²
        assert!(!stable(&[-1.7, 0.6]));
        // 4th order: (1 − 0.9 q⁻¹)² (1 − 0.5 q⁻¹)² = 1 − 2.8 q⁻¹ + 2.86 q⁻² − 1.26 q⁻³ + 0.2025 q⁻⁴
        assert!(stable(&[-2.8, 2.86, -1.26, 0.2025]));
        // 3rd order: (1 − 0.9 q⁻¹)(1 − 1.1 q⁻¹)(1 − 0.5 q⁻¹) = 1 − 2.5 q⁻¹ + 1.99 q⁻² − 0.495 q⁻³
        assert!(!stable(&[-2.5, 1.99, -0.495]));
        // The general recursion agrees with Jury's conditions where both apply.
        for a in [[-1.8f32, 0.81], [-2.1, 1.1], [-1.7, 0.6], [0.3, -0.2]] {
            assert_eq!(schur_stable(&[a[0], a[1], 0.0, 0.0], 2), second_order_stable(a[0], a[1]), "{a:?}");
        }
    }

    #[test]
    fn rejects_bad_orders_and_values() {
        assert_eq!(Model::new(&[], &[1.0], &[], 1), Err(ModelError::Order));
        assert_eq!(Model::new(&[-0.9], &[1.0], &[], 0), Err(ModelError::Order));
        assert_eq!(Model::new(&[-0.9], &[1.0], &[], MAX_K + 1), Err(ModelError::Order));
        assert_eq!(Model::new(&[-0.9], &[], &[], 1), Err(ModelError::Order));
        assert_eq!(Model::new(&[-0.9], &[1.0], &[0.1, 0.1, 0.1], 1), Err(ModelError::Order));
        assert_eq!(Model::new(&[f32::NAN], &[1.0], &[], 1), Err(ModelError::NonFinite));
        assert_eq!(Model::second_order([-1.8, 0.81], [f32::INFINITY, 0.0], 1), Err(ModelError::NonFinite));
        assert_eq!(Model::second_order([-1.8, 0.81], [-0.02, -0.01], 0), Err(ModelError::Order));
        let m = Model::new(&[-1.8, 0.81], &[-0.02, -0.01], &[], 1).unwrap();
        assert_eq!(Model::second_order([-1.8, 0.81], [-0.02, -0.01], 1), Ok(m));
        assert!((m.static_gain().unwrap() - (-0.03 / 0.01)).abs() < 1e-3);
        assert_eq!(m.with_delay(0), Err(ModelError::Order));
        assert_eq!(m.with_delay(4).unwrap().k(), 4);
        assert_eq!(m.with_b_scaled(f32::NAN), Err(ModelError::NonFinite));
        // B = 2 scaled by the largest f32 overflows.
        let big_b = Model::new(&[-0.9], &[2.0], &[], 1).unwrap();
        assert_eq!(big_b.with_b_scaled(f32::MAX), Err(ModelError::NonFinite));
    }

    /// An A of order 7 once reached the stability test through public fields and indexed past
    /// the coefficients (a panic). No constructor builds one now, and the largest order there
    /// is runs the general recursion.
    #[test]
    fn an_order_beyond_the_bound_cannot_be_built() {
        let seven = [0.1f32; 7];
        assert_eq!(Model::new(&seven, &[1.0], &[], 1), Err(ModelError::Order));
        assert_eq!(Model::from_theta(&[0.1; 8], 7, 1, 0, 1), Err(ModelError::Order));
        assert_eq!(Model::from_theta(&[0.1; 2], usize::MAX, 3, 0, 1), Err(ModelError::Order));
        let m = Model::new(&[0.1; MAX_NA], &[1.0], &[], 1).unwrap();
        assert!(m.a_is_stable());
        assert!(!Model::new(&[-4.0, 6.0, -4.0, 1.0], &[1.0], &[], 1).unwrap().a_is_stable());
        // (1 − q⁻¹)⁴
    }

    #[test]
    fn theta_layout_and_simulation() {
        let m = Model::from_theta(&[-1.5, 0.56, 0.5, 0.25, 0.3], 2, 2, 1, 1).unwrap();
        assert_eq!((m.na(), m.nb(), m.nc(), m.k()), (2, 2, 1, 1));
        assert_eq!((&m.a()[..2], &m.b()[..2], m.c()[0]), (&[-1.5, 0.56][..], &[0.5, 0.25][..], 0.3));
        assert_eq!(Model::from_theta(&[-1.5, 0.56, 0.5], 2, 2, 0, 1), Err(ModelError::Order));
        // y(t) = 1.5 y(t−1) − 0.56 y(t−2) + 0.5 u(t−1) + 0.25 u(t−2)
        let u: std::vec::Vec<f32> = (0..40).map(|t| if (t / 5) % 2 == 0 { 1.0 } else { 0.0 }).collect();
        let mut y = std::vec![0.0f32; 40];
        y[0] = 0.3;
        y[1] = 0.2;
        for t in 2..40 {
            y[t] = 1.5 * y[t - 1] - 0.56 * y[t - 2] + 0.5 * u[t - 1] + 0.25 * u[t - 2];
        }
        let mut ys = std::vec![0.0f32; 40];
        assert_eq!(m.simulate(&u, &y[..2], &mut ys), 40);
        for t in 0..40 {
            assert!((ys[t] - y[t]).abs() < 1e-5, "t = {t}");
        }
        // Steady state: y = (0.75 / 0.06) u; an integrator has none.
        assert!((m.static_gain().unwrap() - 12.5).abs() < 1e-3);
        assert_eq!(Model::new(&[-1.0], &[1.0], &[], 1).unwrap().static_gain(), None);
        assert_eq!(m.with_b_scaled(20.0).unwrap().b()[..2], [10.0, 5.0]);
    }
}
