//! The linear discrete-time model the model-based controllers are designed from.
//!
//! ```text
//! A(q⁻¹) y(t) = q^−k B(q⁻¹) u(t) + C(q⁻¹) e(t) / Δ         (CARIMA, Clarke et al. 1987)
//! A = 1 + a1 q⁻¹ + … + a_na q⁻na,   B = b0 + b1 q⁻¹ + … + b_{nb−1} q^−(nb−1),   C = 1 + c1 q⁻¹ + …
//! ```
//!
//! Orders are bounded at compile time ([`MAX_NA`], [`MAX_NB`], [`MAX_NC`], [`MAX_K`]) so the
//! model is `Copy` and lives on the stack; unused coefficients are zero.

/// Largest A order.
pub const MAX_NA: usize = 4;
/// Most B coefficients.
pub const MAX_NB: usize = 4;
/// Largest C order.
pub const MAX_NC: usize = 2;
/// Largest delay, samples.
pub const MAX_K: usize = 10;

/// Why a model was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// An order or the delay is outside the supported range (k ≥ 1, na ≥ 1, nb ≥ 1).
    Order,
    /// A coefficient is NaN or infinite.
    NonFinite,
}

/// A CARIMA/ARX model with bounded orders.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Model {
    /// a1 … a_na (without the leading 1), zero-padded.
    pub a: [f32; MAX_NA],
    /// b0 … b_{nb−1}, zero-padded.
    pub b: [f32; MAX_NB],
    /// c1 … c_nc (without the leading 1), zero-padded.
    pub c: [f32; MAX_NC],
    /// A order.
    pub na: usize,
    /// Number of B coefficients.
    pub nb: usize,
    /// C order.
    pub nc: usize,
    /// Delay in samples, ≥ 1.
    pub k: usize,
}

impl Model {
    /// y(t) = y(t−1) + u(t−1)·0: a placeholder that lets histories advance when no model is known.
    pub const NEUTRAL: Model =
        Model { a: [-1.0, 0.0, 0.0, 0.0], b: [0.0; MAX_NB], c: [0.0; MAX_NC], na: 1, nb: 1, nc: 0, k: 1 };

    /// Builds a model from coefficient slices (a without the leading 1, c likewise).
    pub fn new(a: &[f32], b: &[f32], c: &[f32], k: usize) -> Result<Model, ModelError> {
        if a.is_empty() || a.len() > MAX_NA || b.is_empty() || b.len() > MAX_NB || c.len() > MAX_NC {
            return Err(ModelError::Order);
        }
        if k == 0 || k > MAX_K {
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

    /// Steady-state gain B(1)/A(1), output units per input unit (`None` if A(1) ≈ 0).
    pub fn static_gain(&self) -> Option<f32> {
        let a1 = 1.0 + self.a.iter().sum::<f32>();
        let b1: f32 = self.b.iter().sum();
        (a1.abs() > 1e-9).then(|| b1 / a1)
    }

    /// Ã = Δ·A = (1 − q⁻¹) A: coefficients ã_0 = 1, ã_1 … ã_{na+1}.
    pub fn atilde(&self) -> [f32; MAX_NA + 2] {
        let mut at = [0.0f32; MAX_NA + 2];
        at[0] = 1.0;
        for i in 1..=self.na + 1 {
            let ai = if i <= self.na { self.a[i - 1] } else { 0.0 };
            let aim1 = if i == 1 { 1.0 } else { self.a[i - 2] };
            at[i] = ai - aim1;
        }
        at
    }

    /// True if all roots of A lie strictly inside the unit circle (Jury's criterion for
    /// orders 1 and 2; for higher orders, Schur–Cohn reduction).
    pub fn a_is_stable(&self) -> bool {
        schur_stable(&self.a[..self.na])
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

/// Schur–Cohn test: are all roots of 1 + a1 z⁻¹ + … + an z⁻ⁿ inside the unit circle?
pub fn schur_stable(a: &[f32]) -> bool {
    // Orders 1 and 2: the conditions the recursion below reduces to, without its f64
    // divisions (software on the M4F, ≈ 1 000 instructions).
    match *a {
        [a1] => return a1.abs() < 1.0,
        [a1, a2] => return second_order_stable(a1, a2),
        _ => {}
    }
    // Step-down (Levinson) recursion on the coefficients, in f64 for margin near |z| = 1.
    let n = a.len();
    let mut p = [0.0f64; MAX_NA + 1];
    p[0] = 1.0;
    for (dst, src) in p[1..=n].iter_mut().zip(a) {
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
    #[test]
    fn second_order_check_is_exact_against_f64() {
        use super::second_order_stable;
        let exact = |a1: f32, a2: f32| a2.abs() < 1.0 && f64::from(a1.abs()) < 1.0 + f64::from(a2);
        // (f64 is exact for these: |a2| ≥ 2⁻³⁰.) The carrier's poles sit within 1e-4 of 1: probe the boundary |a1| = 1 + a2 ulp by ulp.
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

    use super::*;

    #[test]
    fn stability_of_known_polynomials() {
        assert!(schur_stable(&[-0.9]));
        assert!(!schur_stable(&[-1.0]));
        assert!(schur_stable(&[-1.8, 0.81])); // double pole at 0.9
        assert!(!schur_stable(&[-2.1, 1.1])); // poles 1.0 and 1.1
        assert!(schur_stable(&[-1.995, 0.99501])); // poles ≈ 0.9975 ± small
                                                   // (1 − 0.5 q⁻¹)(1 − 1.2 q⁻¹) = 1 − 1.7 q⁻¹ + 0.6 q⁻²
        assert!(!schur_stable(&[-1.7, 0.6]));
        // 4th order: (1 − 0.9 q⁻¹)² (1 − 0.5 q⁻¹)² = 1 − 2.8 q⁻¹ + 2.86 q⁻² − 1.26 q⁻³ + 0.2025 q⁻⁴
        assert!(schur_stable(&[-2.8, 2.86, -1.26, 0.2025]));
    }

    #[test]
    fn rejects_bad_orders_and_values() {
        assert_eq!(Model::new(&[], &[1.0], &[], 1), Err(ModelError::Order));
        assert_eq!(Model::new(&[-0.9], &[1.0], &[], 0), Err(ModelError::Order));
        assert_eq!(Model::new(&[f32::NAN], &[1.0], &[], 1), Err(ModelError::NonFinite));
        let m = Model::new(&[-1.8, 0.81], &[-0.02, -0.01], &[], 1).unwrap();
        assert!((m.static_gain().unwrap() - (-0.03 / 0.01)).abs() < 1e-3);
    }
}
