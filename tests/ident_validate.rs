//! Acceptance tests of the PRBS generator and the validation measures.

use hter::ident::batch::BatchLs;
use hter::ident::model::Structure;
use hter::ident::prbs::{Prbs, PrbsConfig, PrbsError};
use hter::ident::validate::{self, OrderCandidate};

fn bits_of(p: &mut Prbs, n: usize) -> Vec<bool> {
    (0..n).map(|_| p.next_duty() > 0.5).collect()
}

#[test]
fn prbs_is_maximum_length_and_balanced_for_every_register_length() {
    for bits in 3..=16u8 {
        let mut p = Prbs::new(PrbsConfig { bits, hold: 1, low: 0.0, high: 1.0 }).unwrap();
        let period = (1usize << bits) - 1;
        assert_eq!(p.period_bits() as usize, period);
        let seq = bits_of(&mut p, 2 * period);
        assert_eq!(seq[..period], seq[period..], "{bits} bits: does not repeat after 2^n − 1");
        // 2^n − 1 is the smallest period: no proper divisor d repeats the sequence.
        for d in (1..period).filter(|d| period.is_multiple_of(*d)) {
            assert_ne!(seq[..period - d], seq[d..period], "{bits} bits: period {d}");
        }
        let ones = seq[..period].iter().filter(|b| **b).count() as i64;
        let zeros = period as i64 - ones;
        assert_eq!(ones - zeros, 1, "{bits} bits: ones − zeros");
    }
}

#[test]
fn prbs_hold_levels_and_length() {
    let cfg = PrbsConfig { bits: 6, hold: 4, low: 0.25, high: 0.75 };
    let mut held = Prbs::new(cfg).unwrap();
    let mut plain = Prbs::new(PrbsConfig { hold: 1, ..cfg }).unwrap();
    assert_eq!(held.period_samples(), 63 * 4);
    for _ in 0..3 * 63 {
        let bit = plain.next_duty();
        for _ in 0..4 {
            assert_eq!(held.next_duty(), bit, "each bit is held for 4 samples");
        }
    }
    let limited: Vec<f32> = Prbs::with_length(cfg, 10).unwrap().collect();
    assert_eq!(limited.len(), 10);
    assert!(limited.iter().all(|v| *v == 0.25 || *v == 0.75));
    let mut p = Prbs::with_length(cfg, 1).unwrap();
    assert_eq!(p.remaining(), Some(1));
    assert!(p.next_sample().is_some());
    assert_eq!(p.next_sample(), None);
    assert_eq!(Prbs::new(PrbsConfig { bits: 17, ..cfg }).err(), Some(PrbsError::Bits));
    assert_eq!(Prbs::new(PrbsConfig { hold: 0, ..cfg }).err(), Some(PrbsError::Levels));
}

/// Noiseless data from a 2nd-order ARX with nk = 2, identified by batch LS and simulated from
/// the input alone: fit 100 %, MSE 0.
#[test]
fn exact_model_fits_100_percent() {
    let n = 500;
    let s = Structure::new(2, 2, 0, 2).unwrap();
    let mut prbs = Prbs::new(PrbsConfig { bits: 7, hold: 5, low: -1.0, high: 1.0 }).unwrap();
    let u: Vec<f64> = (0..n).map(|_| f64::from(prbs.next_duty())).collect();
    let mut y = vec![0.0; n];
    y[0] = 0.5;
    y[1] = 0.4;
    for t in 3..n {
        y[t] = 1.8 * y[t - 1] - 0.81 * y[t - 2] + 0.02 * u[t - 2] + 0.01 * u[t - 3];
    }
    let mut ls = BatchLs::new(4).unwrap();
    let mut phi = [0.0; 4];
    for t in s.first_index()..n {
        assert!(s.regressor(&y, &u, &[], t, &mut phi));
        ls.add(&phi, y[t]).unwrap();
    }
    let mut th = [0.0; 4];
    ls.solve(&mut th).unwrap();
    let mut ysim = vec![0.0; n];
    let fit = validate::simulate_fit(&s, &th, &y, &u, &mut ysim);
    assert!((fit - 100.0).abs() < 1e-6, "fit {fit}");
    let mut eps = vec![0.0; n];
    assert!(validate::one_step(&s, &th, &y, &u, &mut eps) < 1e-20);
    // The f32 per-sample model simulates the same trajectory.
    let m = s.model(&[th[0] as f32, th[1] as f32, th[2] as f32, th[3] as f32]).unwrap();
    let uf: Vec<f32> = u.iter().map(|v| *v as f32).collect();
    let yf: Vec<f32> = y.iter().map(|v| *v as f32).collect();
    let mut ys32 = vec![0.0f32; n];
    m.simulate(&uf, &yf, &mut ys32);
    let ys64: Vec<f64> = ys32.iter().map(|v| f64::from(*v)).collect();
    assert!(validate::fit_percent(&y, &ys64) > 99.9);
}

/// ARX(1, 1), nk = 1, θ = [a1, b0] = [−0.8, 0.5]:
/// ε(1) = 1.0 − (0.8·0 + 0.5·2) = 0;  ε(2) = 1.3 − (0.8·1.0 + 0.5·0) = 0.5;
/// ε(3) = 0.4 − (0.8·1.3 + 0.5·(−1)) = −0.14.  MSE = (0 + 0.25 + 0.0196)/3 = 0.0898667.
#[test]
fn mse_equals_the_hand_computed_value() {
    let s = Structure::new(1, 1, 0, 1).unwrap();
    let y = [0.0, 1.0, 1.3, 0.4];
    let u = [2.0, 0.0, -1.0, 0.0];
    let mut eps = [0.0; 4];
    let mse = validate::one_step(&s, &[-0.8, 0.5], &y, &u, &mut eps);
    assert!((mse - 0.269_6 / 3.0).abs() < 1e-12, "MSE {mse}");
    assert!((eps[2] - 0.5).abs() < 1e-12 && (eps[3] + 0.14).abs() < 1e-12);
}

#[test]
fn poles_of_known_polynomials_and_stability() {
    let mut r = [(0.0, 0.0); 4];
    // 1 − 0.95 q⁻¹ → z = 0.95, a time constant of −Ts/ln 0.95 ≈ 19.5 Ts.
    assert_eq!(validate::roots_monic(&[-0.95], &mut r), 1);
    assert!((r[0].0 - 0.95).abs() < 1e-15 && r[0].1 == 0.0);
    // z² − 1.6 z + 0.8 → 0.8 ± 0.4 i, |z| = √0.8 (stable, oscillatory).
    assert_eq!(validate::roots_monic(&[-1.6, 0.8], &mut r), 2);
    assert!((r[0].0 - 0.8).abs() < 1e-12 && (r[0].1.abs() - 0.4).abs() < 1e-12);
    assert!((validate::abs(r[0]) - 0.8f64.sqrt()).abs() < 1e-12);
    // (z − 1.1)(z − 0.5) = z² − 1.6 z + 0.55: unstable.
    validate::roots_monic(&[-1.6, 0.55], &mut r);
    assert!(r[..2].iter().any(|p| validate::abs(*p) > 1.0));
    // (z − 0.99)(z − 0.9)(z² − z + 0.5) = z⁴ − 2.89 z³ + 3.281 z² − 1.836 z + 0.4455
    assert_eq!(validate::roots_monic(&[-2.89, 3.281, -1.836, 0.4455], &mut r), 4);
    let mut found = [false; 4];
    let want = [(0.99, 0.0), (0.9, 0.0), (0.5, 0.5), (0.5, -0.5)];
    for p in &r {
        for (i, w) in want.iter().enumerate() {
            if (p.0 - w.0).abs() < 1e-8 && (p.1 - w.1).abs() < 1e-8 {
                found[i] = true;
            }
        }
    }
    assert_eq!(found, [true; 4], "{r:?}");
}

#[test]
fn residual_whiteness_band_and_order_choice() {
    // MA(1) residuals e(t) + 0.8 e(t−1) are not white: lag 1 ≈ 0.8/1.64 ≈ 0.49.
    let mut seed = 5u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let e: Vec<f64> = (0..2000).map(|_| rnd()).collect();
    let ma: Vec<f64> = (1..2000).map(|t| e[t] + 0.8 * e[t - 1]).collect();
    let band = validate::whiteness_band(ma.len());
    let mut r = [0.0; 20];
    validate::autocorrelation(&ma, &mut r);
    assert!((r[0] - 0.49).abs() < 0.05 && r[0] > band, "{r:?}");
    validate::autocorrelation(&e, &mut r);
    assert!(r.iter().filter(|v| v.abs() > validate::whiteness_band(e.len())).count() <= 3);

    let c = |order, fit_percent, stable| OrderCandidate { order, fit_percent, stable };
    let rows = [c(1, 90.5, true), c(2, 92.0, true), c(4, 93.0, true)];
    assert_eq!(validate::choose_order(&rows, validate::ORDER_TOLERANCE_POINTS), Some(0));
    let rows = [c(1, 70.0, true), c(2, 92.0, true), c(4, 93.0, true)];
    assert_eq!(validate::choose_order(&rows, validate::ORDER_TOLERANCE_POINTS), Some(1));
}
