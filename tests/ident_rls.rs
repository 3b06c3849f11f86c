//! Acceptance tests of the f32 recursive estimators against independent references.

use hter::ident::batch::BatchLs;
use hter::ident::model::Structure;
use hter::ident::prbs::{Prbs, PrbsConfig};
use hter::ident::recursive;
use hter::ident::rls::{Rls, RlsConfig};
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;

/// A small deterministic PRNG (no dependency on the estimator's code).
struct Lcg(u64);
impl Lcg {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// Near-integrating plant: poles 0.999 and 0.95, so 1 + a1 + a2 = (1 − 0.999)(1 − 0.95) = 5e-5.
const A1: f64 = -(0.999 + 0.95);
const A2: f64 = 0.999 * 0.95;
const B0: f64 = 0.02;
const B1: f64 = 0.01;

fn plant_data(n: usize, noise: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut prbs = Prbs::new(PrbsConfig { bits: 11, hold: 3, low: -0.5, high: 0.5 }).unwrap();
    let mut rng = Lcg(seed);
    let u: Vec<f64> = (0..n).map(|_| f64::from(prbs.next_duty())).collect();
    let mut y = vec![0.0; n];
    for t in 2..n {
        y[t] = -A1 * y[t - 1] - A2 * y[t - 2] + B0 * u[t - 1] + B1 * u[t - 2] + noise * rng.uniform();
    }
    (y, u)
}

/// f64 batch least squares of the 2nd-order ARX (nk = 1): the independent reference.
fn batch_arx2(y: &[f64], u: &[f64]) -> [f64; 4] {
    let s = Structure::new(2, 2, 0, 1).unwrap();
    let mut ls = BatchLs::new(4).unwrap();
    let mut phi = [0.0f64; 4];
    for t in s.first_index()..y.len() {
        assert!(s.regressor(y, u, &[], t, &mut phi));
        ls.add(&phi, y[t]).unwrap();
    }
    let mut th = [0.0f64; 4];
    ls.solve(&mut th).unwrap();
    th
}

/// The f32 recursive estimator (RLS for nc = 0, RELS otherwise) over the record, λ_f = 1.
fn recursive_f32<const N: usize>(s: &Structure, p0: f32, y: &[f64], u: &[f64]) -> (Vec<f64>, u32) {
    let yf: Vec<f32> = y.iter().map(|&v| v as f32).collect();
    let uf: Vec<f32> = u.iter().map(|&v| v as f32).collect();
    let cfg = RlsConfig { forgetting: 1.0, p0, trace_max: 1e6 };
    let (r, skipped) = recursive::run::<N>(s, &cfg, SVector::zeros(), &yf, &uf, |_, _, _| {}).unwrap();
    (r.theta().iter().map(|&v| f64::from(v)).collect(), skipped)
}

#[test]
fn f32_rls_matches_f64_batch_least_squares_on_a_near_integrating_plant() {
    let n = 100_000;
    let (y, u) = plant_data(n, 0.002, 7);
    let s = Structure::new(2, 2, 0, 1).unwrap();
    let th_ls = batch_arx2(&y, &u);
    // f32 RLS, λ_f = 1, large P(0) so the prior's weight is negligible.
    let (th, skipped) = recursive_f32::<4>(&s, 1e4, &y, &u);
    assert_eq!(skipped, 0);
    let diff: f64 = th.iter().zip(&th_ls).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
    let norm: f64 = th_ls.iter().map(|v| v * v).sum::<f64>().sqrt();
    println!("LS {th_ls:?}\nRLS {th:?}\nrelative difference {:.2e}", diff / norm);
    assert!(diff / norm <= 1e-3, "relative difference {}", diff / norm);
    // And both are close to the truth (the data are informative).
    assert!((th_ls[0] - A1).abs() < 1e-3 && (th_ls[1] - A2).abs() < 1e-3);
}

/// P rebuilt in f64 from its f32 factors (forming it in f32 would lose the tiny eigenvalues of
/// the excited directions next to the 1e4 of the unexcited ones).
fn assert_spd(rls: &Rls<4>) {
    let (u, d) = rls.factors();
    assert!(d.iter().all(|v| *v > 0.0 && v.is_finite()), "D = {d}");
    let u64: SMatrix<f64, 4, 4> = u.map(f64::from);
    let d64 = SMatrix::<f64, 4, 4>::from_diagonal(&d.map(f64::from));
    let p64 = u64 * d64 * u64.transpose();
    for i in 0..4 {
        for j in 0..4 {
            let (a, b) = (p64[(i, j)], p64[(j, i)]);
            assert!((a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1e-12), "P not symmetric at {i},{j}");
        }
    }
    assert!(p64.cholesky().is_some(), "P not positive definite: {p64}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4, .. ProptestConfig::default() })]

    /// λ_f = 0.98 and 10⁶ samples of constant input: the classic windup case. trace(P) stays
    /// bounded, P symmetric positive definite, θ finite.
    #[test]
    fn no_windup_under_constant_input(level in 0.1f32..1.0, y0 in -5.0f32..5.0) {
        let cfg = RlsConfig { forgetting: 0.98, p0: 100.0, trace_max: 1e4 };
        let mut rls = Rls::<4>::new(&cfg, SVector::zeros());
        let mut y = [y0; 3];
        for t in 0..1_000_000u32 {
            let phi = SVector::<f32, 4>::new(-y[0], -y[1], level, level);
            let yt = y0 + 1e-3 * ((t % 7) as f32 - 3.0);
            rls.update(&cfg, &phi, yt).unwrap();
            y = [yt, y[0], y[1]];
            if t % 100_000 == 0 {
                prop_assert!(rls.trace_p() <= cfg.trace_max * 1.0001);
            }
        }
        prop_assert!(rls.theta().iter().all(|v| v.is_finite()));
        prop_assert!(rls.trace_p().is_finite() && rls.trace_p() <= cfg.trace_max * 1.0001);
        assert_spd(&rls);
    }
}

/// ARMAX plant with coloured noise: A = 1 − 1.5 q⁻¹ + 0.7 q⁻², B = q⁻¹ (1 + 0.5 q⁻¹),
/// C = 1 + 0.8 q⁻¹ (Ljung's classic example system, 1999, §11.3 with a stronger C).
#[test]
fn rels_recovers_c_where_least_squares_is_biased() {
    let n = 20_000;
    let mut prbs = Prbs::new(PrbsConfig { bits: 10, hold: 1, low: -1.0, high: 1.0 }).unwrap();
    let mut rng = Lcg(3);
    let u: Vec<f64> = (0..n).map(|_| f64::from(prbs.next_duty())).collect();
    let e: Vec<f64> = (0..n).map(|_| 1.5 * rng.uniform()).collect();
    let mut y = vec![0.0; n];
    for t in 2..n {
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + u[t - 1] + 0.5 * u[t - 2] + e[t] + 0.8 * e[t - 1];
    }
    let truth = [-1.5, 0.7, 1.0, 0.5];
    let err = |th: &[f64]| truth.iter().zip(th).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();

    let th_ls = batch_arx2(&y, &u);
    let armax = Structure::new(2, 2, 1, 1).unwrap();
    let (th_rels, _) = recursive_f32::<5>(&armax, 100.0, &y, &u);
    println!("LS   {th_ls:?} error {:.4}\nRELS {th_rels:?} error {:.4}", err(&th_ls), err(&th_rels[..4]));
    assert!((th_rels[4] - 0.8).abs() < 0.05, "c1 = {}", th_rels[4]);
    assert!(err(&th_rels[..4]) < 0.03, "RELS error {}", err(&th_rels[..4]));
    assert!(err(&th_ls) > 3.0 * err(&th_rels[..4]), "LS should be clearly biased: {}", err(&th_ls));
}
