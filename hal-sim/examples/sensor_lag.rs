//! How much of self-tuning GPC's distance from the bound is the sensor chain's? `piecewise`
//! with the carrier's RTD dead time and lag as built (20 s + 20 s) and shortened (experiment
//! for issue 15): `cargo run --release -p hal-sim --example sensor_lag`.
use hal_sim::bound::bound;
use hal_sim::plant::{Load, PlantParams};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};

fn main() -> anyhow::Result<()> {
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
            let mut ratios = Vec::new();
            for seed in 1..=3 {
                opts.seed = seed;
                ratios.push(format!("{:.3}", run(&opts)?.metrics.tracking.iae / b));
            }
            println!("{name}: dead time {dead} s, RTD lag {tau} s: bound {b:.0}, GPC / bound {}", ratios.join(" "));
        }
    }
    Ok(())
}
