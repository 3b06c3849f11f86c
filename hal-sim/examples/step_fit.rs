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
use hal_sim::plant::{Load, PlantParams};
use hter::ident::model::Structure;

#[path = "common/stepfit.rs"]
mod stepfit;
use stepfit::{cools, filtered_step, fit, rms, step_response, N};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let load = if args.first().map(String::as_str) == Some("half") { Load::Half } else { Load::Full };
    let hter2 = args.get(1).map(String::as_str) == Some("hter2");
    let n_fit: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60).clamp(10, N);
    let params = if hter2 { PlantParams::hter2(load) } else { PlantParams::hter1(load) };
    let Some((f, duty0)) = filtered_step(params, 28.0) else {
        eprintln!("the carrier cannot hold 4 °C at 28 °C");
        std::process::exit(1);
    };
    let carrier = if hter2 { "H-TER II" } else { "H-TER I" };
    println!("{carrier} {load:?} load, holding duty {duty0:.3}; filtered step response, °C per unit duty:");
    for j in [3, 4, 5, 6, 8, 10, 15, 20, 30, 60, 120, 240] {
        print!(" {j}: {:.3}", f[j]);
    }
    println!("\nfits over the first {n_fit} samples:");
    for na in 1..=2 {
        for nb in 1..=4 {
            for nk in 3..=6 {
                let Ok(s) = Structure::new(na, nb, 0, nk) else { continue };
                let Some(theta) = fit(&s, &f, n_fit) else {
                    println!("na {na} nb {nb} k {nk}: singular");
                    continue;
                };
                let model = step_response(&s, &theta, N);
                let list = |v: &[f64]| v.iter().map(|x| format!("{x:.6}")).collect::<Vec<_>>().join(",");
                println!(
                    "na {na} nb {nb} k {nk}: rms error 1–30 {:.3}, 1–120 {:.3}, b_i {} arx:{};{};{nk}",
                    rms(&model[1..=30], &f[1..=30]),
                    rms(&model[1..=120], &f[1..=120]),
                    if cools(&s, &theta) { "cool" } else { "HEAT" },
                    list(&theta[..na]),
                    list(&theta[na..]),
                );
            }
        }
    }
}
