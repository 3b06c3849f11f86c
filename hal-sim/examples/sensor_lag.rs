//! How much of GPC's distance from the bound is the sensor chain's? `piecewise` on H-TER I
//! (full and half load, 28 °C) with the carrier's RTD dead time and lag as built (20 s + 20 s)
//! and shortened, for two controllers (experiment for issue 15):
//! - self-tuning GPC as the board runs it (from the carrier's start model);
//! - GPC on a fixed model fitted to that sensor's own step response: the cooling ARX model
//!   (na 2, nb 2–4, delay 1–6) of least rms error over the first 30 samples of the filtered
//!   step (`examples/common/stepfit.rs`, as the `step_fit` example), fitted over the first 30
//!   samples, with the best of λ 0.3/1/3, Nu 2/3 and T-filter 0/0.5 on seed 1. This is the
//!   ceiling of a law that knows its plant's input-output response over the horizon.
//!
//! IAE / bound on seeds 1–3. `cargo run --release -p hal-sim --example sensor_lag`.
use hal_sim::bound::bound;
use hal_sim::plant::{Load, PlantParams};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};
use hter::ident::model::Structure;
use hter::model::Model;

#[path = "common/stepfit.rs"]
mod stepfit;
use stepfit::{cools, filtered_step, fit, model, rms, step_response};

/// Samples of the step the fixed model is fitted to and judged on.
const N_FIT: usize = 30;

/// The cooling ARX model that best matches the first [`N_FIT`] samples of `params`' step.
fn best_fit(params: PlantParams) -> Option<(Structure, Vec<f64>)> {
    let (f, _) = filtered_step(params, 28.0)?;
    let mut best: Option<(f64, Structure, Vec<f64>)> = None;
    for nb in 2..=4 {
        for nk in 1..=6 {
            let Ok(s) = Structure::new(2, nb, 0, nk) else { continue };
            let Some(theta) = fit(&s, &f, N_FIT).filter(|th| cools(&s, th)) else { continue };
            let e = rms(&step_response(&s, &theta, N_FIT)[1..], &f[1..=N_FIT]);
            if best.as_ref().is_none_or(|b| e < b.0) {
                best = Some((e, s, theta));
            }
        }
    }
    best.map(|(_, s, th)| (s, th))
}

fn ratios(opts: &mut SimOptions, b: f64) -> anyhow::Result<Vec<f64>> {
    (1..=3)
        .map(|seed| {
            opts.seed = seed;
            Ok(run(opts)?.metrics.tracking.iae / b)
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    let show = |r: &[f64]| r.iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>().join(" ");
    for (name, params) in
        [("hter1 full", PlantParams::hter1(Load::Full)), ("hter1 half", PlantParams::hter1(Load::Half))]
    {
        for (dead, tau) in [(20.0, 20.0), (10.0, 10.0), (0.0, 1.0)] {
            let mut p = params;
            p.dead_time_s = dead;
            p.rtd_tau_s = tau;
            let mut opts =
                SimOptions::new(Scenario::built_in("piecewise").unwrap(), ControllerSpec::new(ControllerChoice::Gpc));
            opts.plant = PlantChoice::Custom(p);
            let b = bound(&opts)?.iae;
            let tuned = ratios(&mut opts, b)?;
            let Some((s, theta)) = best_fit(p) else {
                println!("{name}: dead time {dead} s, RTD lag {tau} s: no cooling ARX model fits its step");
                continue;
            };
            // The fixed model's tuning: the best on seed 1.
            let mut best: Option<(f64, Model, f32, usize)> = None;
            for tpole in [0.0f32, 0.5] {
                let Some(m) = model(&s, &theta, tpole) else { continue };
                for lambda in [0.3f32, 1.0, 3.0] {
                    for nu in [2usize, 3] {
                        opts.controller.model = Some(m);
                        opts.controller.gpc.lambda = lambda;
                        opts.controller.gpc.nu = nu;
                        opts.seed = 1;
                        let r = run(&opts)?.metrics.tracking.iae / b;
                        if best.as_ref().is_none_or(|x| r < x.0) {
                            best = Some((r, m, lambda, nu));
                        }
                    }
                }
            }
            let Some((_, m, lambda, nu)) = best else { continue };
            opts.controller.model = Some(m);
            opts.controller.gpc.lambda = lambda;
            opts.controller.gpc.nu = nu;
            let fixed = ratios(&mut opts, b)?;
            println!(
                "{name}: dead time {dead} s, RTD lag {tau} s: bound {b:.0}; GPC / bound: self-tuning {}, \
                 fixed fitted model (nb {} k {}, λ {lambda}, Nu {nu}, T-filter {}) {}",
                show(&tuned),
                s.nb,
                s.nk,
                m.c().first().map_or(0.0, |c| -c),
                show(&fixed),
            );
        }
    }
    Ok(())
}
