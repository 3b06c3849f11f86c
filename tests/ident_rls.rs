//! Acceptance tests of the f32 recursive estimators against independent references.

use hter::ident::batch::BatchLs;
use hter::ident::model::{OperatingPoint, Regressor, Structure};
use hter::ident::prbs::{Prbs, PrbsConfig};
use hter::ident::recursive;
use hter::ident::rls::{EstError, Rls, RlsConfig};
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

/// Second-order plant with real poles p1, p2 and B = b0 + b1 q⁻¹ (nk = 1):
/// 1 + a1 + a2 = (1 − p1)(1 − p2).
#[derive(Clone, Copy)]
struct Plant {
    p1: f64,
    p2: f64,
    b0: f64,
    b1: f64,
}

impl Plant {
    fn a(&self) -> [f64; 2] {
        [-(self.p1 + self.p2), self.p1 * self.p2]
    }
}

/// 1 + a1 + a2 = 5e-5: harder than the carrier.
const VERY_SLOW: Plant = Plant { p1: 0.999, p2: 0.95, b0: 0.02, b1: 0.01 };
/// 1 + a1 + a2 = 1e-3: the carrier at its sampling period.
const CARRIER_LIKE: Plant = Plant { p1: 0.99, p2: 0.9, b0: 0.02, b1: 0.01 };

/// PRBS input ±0.5 (11-bit register, 3 samples per bit) through the plant, uniform noise.
fn plant_data(plant: Plant, n: usize, noise: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut prbs = Prbs::new(PrbsConfig { bits: 11, hold: 3, low: -0.5, high: 0.5 }).unwrap();
    let mut rng = Lcg(seed);
    let [a1, a2] = plant.a();
    let u: Vec<f64> = (0..n).map(|_| f64::from(prbs.next_duty())).collect();
    let mut y = vec![0.0; n];
    for t in 2..n {
        y[t] = -a1 * y[t - 1] - a2 * y[t - 2] + plant.b0 * u[t - 1] + plant.b1 * u[t - 2] + noise * rng.uniform();
    }
    (y, u)
}

fn relative_difference(th: &[f64], reference: &[f64]) -> f64 {
    let diff: f64 = th.iter().zip(reference).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
    diff / reference.iter().map(|v| v * v).sum::<f64>().sqrt()
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
    for (name, plant) in [("1 + a1 + a2 = 1e-3", CARRIER_LIKE), ("1 + a1 + a2 = 5e-5", VERY_SLOW)] {
        let n = 100_000;
        let (y, u) = plant_data(plant, n, 0.002, 7);
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let th_ls = batch_arx2(&y, &u);
        // f32 RLS, λ_f = 1, large P(0) so the prior's weight is negligible.
        let (th, skipped) = recursive_f32::<4>(&s, 1e4, &y, &u);
        assert_eq!(skipped, 0);
        let rel = relative_difference(&th, &th_ls);
        println!("{name}:\n  LS  {th_ls:?}\n  RLS {th:?}\n  relative difference {rel:.2e}");
        assert!(rel <= 1e-3, "{name}: relative difference {rel}");
        // And both are close to the truth (the data are informative).
        let [a1, a2] = plant.a();
        assert!((th_ls[0] - a1).abs() < 1e-3 && (th_ls[1] - a2).abs() < 1e-3, "{name}: {th_ls:?}");
    }
}

/// Raw logs (temperature around 28 °C, duty around 0.4) through the per-sample path: the
/// regressor takes the operating point and scales, the estimate converted back to physical
/// units matches f64 batch LS on the deviation data.
#[test]
fn streaming_rls_with_an_operating_point_matches_batch_ls_on_raw_logs() {
    let n = 100_000;
    let (dy, du) = plant_data(CARRIER_LIKE, n, 0.002, 11);
    let (y0, u0) = (28.0f64, 0.4f64);
    // Duty swings ±0.5 · 0.4 around 0.4, temperature ±a few °C around 28.
    let raw_u: Vec<f64> = du.iter().map(|v| u0 + 0.4 * v).collect();
    let raw_y: Vec<f64> = dy.iter().map(|v| y0 + 0.4 * v).collect();
    let dev_y: Vec<f64> = raw_y.iter().map(|v| v - y0).collect();
    let dev_u: Vec<f64> = raw_u.iter().map(|v| v - u0).collect();
    let th_ls = batch_arx2(&dev_y, &dev_u);

    let cfg = RlsConfig { forgetting: 1.0, p0: 1e4, trace_max: 1e6 };
    let run = |op: OperatingPoint| {
        let mut reg = Regressor::<2, 2, 0>::new(1, op).unwrap();
        let mut rls = Rls::<4>::new(&cfg, SVector::zeros());
        for t in 0..n {
            let (y, u) = (raw_y[t] as f32, raw_u[t] as f32);
            if let Some(phi) = reg.phi::<4>() {
                rls.update(&cfg, &phi, reg.y_dev(y)).unwrap();
            }
            reg.push(y, u);
        }
        // b back to physical units: b = b_scaled · y_scale / u_scale.
        let m = op.unscale(&Structure::new(2, 2, 0, 1).unwrap().model(rls.theta().as_slice()).unwrap()).unwrap();
        vec![m.a()[0], m.a()[1], m.b()[0], m.b()[1]].into_iter().map(f64::from).collect::<Vec<f64>>()
    };
    let scaled = run(OperatingPoint::new(y0 as f32, u0 as f32, 2.0, 0.2).unwrap());
    let rel = relative_difference(&scaled, &th_ls);
    // For the record: fed the raw values (no operating point), the offset-free model also has
    // to explain the 28 °C level with a duty of 0.4, which biases it.
    let raw = run(OperatingPoint::IDENTITY);
    println!(
        "LS {th_ls:?}\nscaled deviations {scaled:?} ({rel:.2e})\nraw values {raw:?} ({:.2e})",
        relative_difference(&raw, &th_ls)
    );
    assert!(rel <= 1e-3, "relative difference {rel}");
}

/// A NaN reading is refused (state kept) for as long as it sits in φ, then estimation resumes.
#[test]
fn non_finite_samples_are_refused_and_estimation_resumes() {
    let n = 20_000;
    let (y, u) = plant_data(CARRIER_LIKE, n, 0.002, 5);
    let cfg = RlsConfig { forgetting: 0.999, p0: 1e3, trace_max: 1e5 };
    let mut reg = Regressor::<2, 2, 0>::new(1, OperatingPoint::IDENTITY).unwrap();
    let mut rls = Rls::<4>::new(&cfg, SVector::zeros());
    let mut refused = 0;
    for t in 0..n {
        let yt = if t == 10_000 { f32::NAN } else { y[t] as f32 };
        if let Some(phi) = reg.phi::<4>() {
            let before = rls.clone();
            match rls.update(&cfg, &phi, reg.y_dev(yt)) {
                Ok(_) => {}
                Err(e) => {
                    assert_eq!(e, EstError::NonFinite);
                    assert_eq!(rls, before, "state changed on a refused update");
                    refused += 1;
                }
            }
        }
        reg.push(yt, u[t] as f32);
    }
    // y(10000) is the target once and sits in φ for the next two samples.
    assert_eq!(refused, 3);
    let th: Vec<f64> = rls.theta().iter().map(|v| f64::from(*v)).collect();
    let [a1, a2] = CARRIER_LIKE.a();
    assert!((th[0] - a1).abs() < 0.01 && (th[1] - a2).abs() < 0.01, "{th:?}");
    assert_spd(&rls);
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

/// Why the estimator is U-D factorised: the textbook covariance form
/// `P ← (P − K φᵀ P) / λ_f` in f32 on the 5e-5 plant loses positive definiteness, while the U-D
/// factors of the same data stay positive.
#[test]
fn textbook_covariance_form_in_f32_loses_positive_definiteness_where_u_d_does_not() {
    let n = 100_000;
    let (y, u) = plant_data(VERY_SLOW, n, 0.002, 7);
    let cfg = RlsConfig { forgetting: 1.0, p0: 1e4, trace_max: 1e6 };
    let mut p = SMatrix::<f32, 4, 4>::identity() * cfg.p0;
    let mut th = SVector::<f32, 4>::zeros();
    let mut ud = Rls::<4>::new(&cfg, SVector::zeros());
    let mut first_indefinite = None;
    for t in 2..n {
        let phi = SVector::<f32, 4>::new(-y[t - 1] as f32, -y[t - 2] as f32, u[t - 1] as f32, u[t - 2] as f32);
        let pphi = p * phi;
        let k = pphi / (1.0 + phi.dot(&pphi));
        th += k * (y[t] as f32 - phi.dot(&th));
        p -= k * pphi.transpose();
        ud.update(&cfg, &phi, y[t] as f32).unwrap();
        if first_indefinite.is_none() && t % 50 == 0 {
            let sym = (p.map(f64::from) + p.map(f64::from).transpose()) * 0.5;
            if sym.cholesky().is_none() {
                first_indefinite = Some(t);
            }
        }
    }
    println!("covariance form: P indefinite from sample {first_indefinite:?}; θ = {}", th.transpose());
    assert!(first_indefinite.is_some(), "the f32 covariance form stayed positive definite");
    assert_spd(&ud);
}
