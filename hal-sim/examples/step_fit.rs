//! Which model structure matches the plant's step response as the controller sees it (issue 15).
//!
//! The H-TER I or II carrier's response to a duty step from the steady state holding 4 °C at
//! 28 °C ambient, as the RTD reads it through the step's F_a = 0.5 measurement filter, per unit
//! duty; then, for each ARX structure (na 1–2, nb 1–4, delay 3–6), the batch least-squares fit
//! of that response over its first `N` samples (the library's `ident::batch::least_squares`),
//! the rms error of the fitted model's step response over the first 30 and 120 samples, whether
//! every b_i cools (the self-tuner's plausibility rule), and the model as `hter --model`
//! takes it. `cargo run --release -p hal-sim --example step_fit -- [full|half] [hter1|hter2]
//! [N = 60]`.
use hal_sim::plant::{Load, Plant, PlantParams};
use hter::ident::batch::least_squares;
use hter::ident::model::Structure;

/// Step response of the ARX model `theta` = [a…, b…] of structure `s`, samples 0…n.
fn step_response(s: &Structure, theta: &[f64], n: usize) -> Vec<f64> {
    let (a, b) = theta.split_at(s.na);
    let mut y = vec![0.0; n + 1];
    for t in 1..=n {
        let mut v = 0.0;
        for (i, ai) in a.iter().enumerate() {
            if t > i {
                v -= ai * y[t - i - 1];
            }
        }
        for (i, bi) in b.iter().enumerate() {
            if t >= s.nk + i {
                v += bi;
            }
        }
        y[t] = v;
    }
    y
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let load = if args.first().map(String::as_str) == Some("half") { Load::Half } else { Load::Full };
    let hter2 = args.get(1).map(String::as_str) == Some("hter2");
    let n_fit: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60);
    let params = if hter2 { PlantParams::hter2(load) } else { PlantParams::hter1(load) };
    let (n, delta, fa) = (240, 0.1, 0.5);
    let Some((sensed, duty0)) = Plant::sensed_step(params, 28.0, 4.0, delta, 10.0, n) else {
        eprintln!("the carrier cannot hold 4 °C at 28 °C");
        std::process::exit(1);
    };
    // Through the measurement filter, per unit duty, from 0.
    let mut f = vec![0.0; n + 1];
    for t in 1..=n {
        f[t] = fa * f[t - 1] + (1.0 - fa) * (sensed[t] - sensed[0]) / delta;
    }
    let carrier = if hter2 { "H-TER II" } else { "H-TER I" };
    println!("{carrier} {load:?} load, holding duty {duty0:.3}; filtered step response, °C per unit duty:");
    for j in [3, 4, 5, 6, 8, 10, 15, 20, 30, 60, 120, 240] {
        print!(" {j}: {:.3}", f[j]);
    }
    println!("\nfits over the first {n_fit} samples:");
    // The record: 10 samples at rest before the step, so every regressor has its history.
    let pad = 10;
    let y: Vec<f64> = std::iter::repeat_n(0.0, pad).chain(f[..=n_fit].iter().copied()).collect();
    let u: Vec<f64> = (0..y.len()).map(|t| if t >= pad { 1.0 } else { 0.0 }).collect();
    for na in 1..=2 {
        for nb in 1..=4 {
            for nk in 3..=6 {
                let Ok(s) = Structure::new(na, nb, 0, nk) else { continue };
                let mut theta = vec![0.0; s.n_params()];
                if least_squares(&s, &y, &u, &mut theta).is_err() {
                    println!("na {na} nb {nb} k {nk}: singular");
                    continue;
                }
                let model = step_response(&s, &theta, n);
                let cools = theta[na..].iter().all(|&b| b <= 0.0);
                let list = |v: &[f64]| v.iter().map(|x| format!("{x:.6}")).collect::<Vec<_>>().join(",");
                println!(
                    "na {na} nb {nb} k {nk}: rms error 1–30 {:.3}, 1–120 {:.3}, b_i {} arx:{};{};{nk}",
                    rms(&model[1..=30], &f[1..=30]),
                    rms(&model[1..=120], &f[1..=120]),
                    if cools { "cool" } else { "HEAT" },
                    list(&theta[..na]),
                    list(&theta[na..]),
                );
            }
        }
    }
}
