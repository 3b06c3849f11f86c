//! ARX fits to the plant's step response as the controller sees it, shared by the `step_fit`
//! and `sensor_lag` examples (issue 15).
// Each example uses a part of this module.
#![allow(dead_code)]
use hal_sim::plant::{Plant, PlantParams};
use hter::ident::batch::least_squares;
use hter::ident::model::Structure;
use hter::ident::validate::simulate_fit;
use hter::model::Model;

/// Samples of the recorded step response.
pub const N: usize = 240;

/// The carrier's response to a duty step of 0.1 from the steady state holding 4 °C at
/// `ambient_c`, as the RTD reads it through the step's F_a = 0.5 measurement filter, per unit
/// duty and from 0: `N + 1` samples of 10 s, the first before the step; with the duty it
/// started from. `None` if no duty holds 4 °C.
pub fn filtered_step(params: PlantParams, ambient_c: f64) -> Option<(Vec<f64>, f64)> {
    let (delta, fa) = (0.1, 0.5);
    let (sensed, duty0) = Plant::sensed_step(params, ambient_c, 4.0, delta, 10.0, N)?;
    let mut f = vec![0.0; N + 1];
    for t in 1..=N {
        f[t] = fa * f[t - 1] + (1.0 - fa) * (sensed[t] - sensed[0]) / delta;
    }
    Some((f, duty0))
}

/// Samples at rest before the step in the records [`fit`] and [`step_response`] build, so every
/// regressor has its history (≥ the largest `Structure::first_index` the examples use).
const PAD: usize = 10;

/// The record of a unit duty step from rest: `y` (`PAD` zeros, then `f[..=n]`) and `u` (0
/// before the step, 1 from it).
fn step_record(f: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    let y: Vec<f64> = std::iter::repeat_n(0.0, PAD).chain(f[..=n].iter().copied()).collect();
    let u: Vec<f64> = (0..y.len()).map(|t| if t >= PAD { 1.0 } else { 0.0 }).collect();
    (y, u)
}

/// Batch least-squares ARX fit of structure `s` to the first `n_fit` samples of the step
/// response `f` (the library's `ident::batch::least_squares`): θ = [a…, b…], or `None` if the
/// normal equations are singular.
pub fn fit(s: &Structure, f: &[f64], n_fit: usize) -> Option<Vec<f64>> {
    let (y, u) = step_record(f, n_fit);
    let mut theta = vec![0.0; s.n_params()];
    least_squares(s, &y, &u, &mut theta).ok()?;
    Some(theta)
}

/// Step response of the ARX model `theta` = [a…, b…] of structure `s`, samples 0…n: the
/// library's simulation from rest (`ident::validate::simulate_fit`).
pub fn step_response(s: &Structure, theta: &[f64], n: usize) -> Vec<f64> {
    let (y, u) = step_record(&vec![0.0; n + 1], n);
    let mut ysim = vec![0.0; y.len()];
    simulate_fit(s, theta, &y, &u, &mut ysim);
    ysim.split_off(PAD)
}

/// Root-mean-square difference of two equally long records.
pub fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

/// Whether every b_i cools (≤ 0), the self-tuner's plausibility rule.
pub fn cools(s: &Structure, theta: &[f64]) -> bool {
    theta[s.na..].iter().all(|&b| b <= 0.0)
}

/// `theta` of structure `s` as a law's model, with the T-filter C = 1 − τ q⁻¹ (`tau` = 0: none).
pub fn model(s: &Structure, theta: &[f64], tau: f32) -> Option<Model> {
    let mut th: Vec<f32> = theta.iter().map(|&x| x as f32).collect();
    let nc = if tau > 0.0 {
        th.push(-tau);
        1
    } else {
        0
    };
    Structure { nc, ..*s }.model(&th).ok()
}
