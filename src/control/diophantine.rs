//! The Diophantine identity of minimum-variance and predictive control
//! (Åström & Wittenmark, *Computer-Controlled Systems*, 3rd ed., §12.3; Clarke & Gawthrop,
//! "Self-tuning controller", Proc. IEE 122(9), 1975):
//!
//! ```text
//! P(q⁻¹) C(q⁻¹) = A'(q⁻¹) E(q⁻¹) + q^−k F(q⁻¹),     deg E = k − 1
//! ```
//!
//! where A' is A for GMVC and Ã = ΔA for IGMVC. E is the first k terms of the power series of
//! PC/A' (long division) and F what remains, shifted by k. Solved by k steps of synthetic
//! division on fixed-size arrays; the leading coefficient of A' is 1, so no division at all.

use crate::model::{MAX_K, MAX_NA, MAX_NC};

/// Longest A' handled (Ã of a 4th-order A has 6 coefficients).
pub const MAX_A: usize = MAX_NA + 2;
/// Most F coefficients.
pub const MAX_F: usize = MAX_A + MAX_NC;

/// E and F of one solution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    /// e0 … e_{k−1}.
    pub e: [f32; MAX_K],
    /// f0 … f_{nf−1}.
    pub f: [f32; MAX_F],
    /// Number of E coefficients (= k).
    pub ne: usize,
    /// Number of F coefficients.
    pub nf: usize,
}

/// Solves `PC = A' E + q^−k F` for polynomials given with their leading coefficient:
/// `a_prime[0]` must be 1. Returns `None` if k is 0 or too large, or sizes overflow.
pub fn solve(a_prime: &[f32], pc: &[f32], k: usize) -> Option<Solution> {
    if k == 0 || k > MAX_K || a_prime.is_empty() || a_prime[0] != 1.0 {
        return None;
    }
    let na = a_prime.len() - 1;
    let len = (k + na).max(pc.len());
    const R: usize = MAX_K + MAX_F;
    if len > R || pc.len() > R {
        return None;
    }
    let mut r = [0.0f32; R];
    r[..pc.len()].copy_from_slice(pc);
    let mut s = Solution { e: [0.0; MAX_K], f: [0.0; MAX_F], ne: k, nf: 0 };
    for i in 0..k {
        let ei = r[i];
        s.e[i] = ei;
        for (j, aj) in a_prime.iter().enumerate() {
            r[i + j] -= ei * aj;
        }
    }
    s.nf = len - k;
    if s.nf > MAX_F {
        return None;
    }
    s.f[..s.nf].copy_from_slice(&r[k..len]);
    Some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_first_order() {
        // A = 1 − 0.9 q⁻¹, k = 2, C = 1: E = 1 + 0.9 q⁻¹, F = 0.81.
        let s = solve(&[1.0, -0.9], &[1.0], 2).unwrap();
        assert_eq!(s.ne, 2);
        assert!((s.e[0] - 1.0).abs() < 1e-6 && (s.e[1] - 0.9).abs() < 1e-6);
        assert_eq!(s.nf, 1);
        assert!((s.f[0] - 0.81).abs() < 1e-6);
    }

    #[test]
    fn hand_computed_incremental() {
        // Ã = (1 − q⁻¹)(1 − 0.9 q⁻¹) = 1 − 1.9 q⁻¹ + 0.9 q⁻², k = 2:
        // E = 1 + 1.9 q⁻¹, F = 2.71 − 1.71 q⁻¹ (check: ÃE + q⁻²F = 1).
        let s = solve(&[1.0, -1.9, 0.9], &[1.0], 2).unwrap();
        assert!((s.e[0] - 1.0).abs() < 1e-6 && (s.e[1] - 1.9).abs() < 1e-6);
        assert_eq!(s.nf, 2);
        assert!((s.f[0] - 2.71).abs() < 1e-5 && (s.f[1] + 1.71).abs() < 1e-5);
    }

    #[test]
    fn identity_holds_with_a_c_polynomial() {
        // A' = 1 − 1.5 q⁻¹ + 0.56 q⁻², PC = 1 + 0.5 q⁻¹, k = 3: verify A'E + q⁻³F = PC.
        let a = [1.0f32, -1.5, 0.56];
        let pc = [1.0f32, 0.5];
        let s = solve(&a, &pc, 3).unwrap();
        let mut lhs = [0.0f32; 8];
        for i in 0..s.ne {
            for (j, aj) in a.iter().enumerate() {
                lhs[i + j] += s.e[i] * aj;
            }
        }
        for i in 0..s.nf {
            lhs[3 + i] += s.f[i];
        }
        let mut want = [0.0f32; 8];
        want[..2].copy_from_slice(&pc);
        for (l, w) in lhs.iter().zip(&want) {
            assert!((l - w).abs() < 1e-5, "{lhs:?}");
        }
    }
}
