//! The H-TER I carrier's step response as its RTD sees it (before the step's F_a filter, which the
//! models were identified through, so they lag it by about a sample more),
//! against the start model's and the output-error model's (issue 15: why GPC chatters on the
//! better-fitting model). Per unit duty, from the steady state holding 4 °C at 28 °C ambient:
//! `cargo run --release -p hal-sim --example step_compare`.
use hal_sim::plant::{Load, Plant, PlantParams};
use hter::model::Model;
use hter::profile::START_MODEL_HTER1;

/// Step response of `q^−k B/A` at samples 0…n.
fn model_step(m: &Model, n: usize) -> Vec<f64> {
    let mut y = vec![0.0; n + 1];
    for t in 1..=n {
        let mut v = 0.0;
        for (i, ai) in m.a().iter().enumerate() {
            if t > i {
                v -= f64::from(*ai) * y[t - i - 1];
            }
        }
        for (i, bi) in m.b().iter().enumerate() {
            if t >= m.k() + i {
                v += f64::from(*bi);
            }
        }
        y[t] = v;
    }
    y
}

fn main() {
    // `hter identify --input prbs1.csv` (output error, best delay; `START_MODEL_HTER1`'s docs).
    let Ok(oe) = Model::second_order([-1.936_244, 0.936_443], [-0.286_523, 0.277_79], 9) else {
        unreachable!("the output-error model is a model")
    };
    let n = 120;
    let start = model_step(&START_MODEL_HTER1, n);
    let oe9 = model_step(&oe, n);
    for load in [Load::Full, Load::Half] {
        let Some((y, duty0)) = Plant::sensed_step(PlantParams::hter1(load), 28.0, 4.0, 0.1, 10.0, n) else {
            unreachable!("H-TER I holds 4 °C at 28 °C")
        };
        println!("H-TER I {load:?} load (holding duty {duty0:.3}), °C per unit duty after j samples of 10 s:");
        println!("| j | plant (RTD) | start model (k 5) | output-error model (k 9) |");
        println!("| --- | --- | --- | --- |");
        for j in [2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 30, 60, 120] {
            println!("| {j} | {:.3} | {:.3} | {:.3} |", (y[j] - y[0]) / 0.1, start[j], oe9[j]);
        }
    }
}
