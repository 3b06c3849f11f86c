//! `hter compare`: one scenario run with several controllers, as a markdown table and an
//! optional plot of every run.

use anyhow::{bail, Result};

use crate::plot;
use crate::sim::{self, ControllerChoice};
use crate::sim_cmd::{self, SimArgs};

/// Arguments of `hter compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// The scenario and plant, exactly as for `hter sim` (its --controller is ignored).
    #[command(flatten)]
    pub sim: SimArgs,
    /// Controllers to compare, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "onoff,pi,gmvc,igmvc,gpc")]
    pub controllers: Vec<ControllerChoice>,
}

/// `hter compare`.
pub fn run(a: &CompareArgs) -> Result<()> {
    if a.controllers.is_empty() {
        bail!("--controllers is empty");
    }
    let base = sim_cmd::options(&a.sim)?;
    let mut runs = Vec::new();
    for &c in &a.controllers {
        let mut opts = base.clone();
        opts.controller.choice = c;
        let out = sim::run(&opts)?;
        runs.push((c, out));
    }
    println!(
        "{} on {}, {:?} load, {} °C ambient, seed {}",
        base.scenario.name,
        base.plant.name(),
        base.scenario.load.unwrap_or(base.load),
        base.ambient_c,
        base.seed
    );
    println!();
    println!("| controller | IAE (°C·s) | steady-state error (°C) | overshoot (°C) | settle (s) | min / max (°C) | time outside 2–8 °C (s) | energy (Wh) | SSR switches |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (_, out) in &runs {
        let m = &out.metrics;
        let settle = m.tracking.settle_time_s.map_or("never".to_string(), |s| format!("{s:.0}"));
        println!(
            "| {} | {:.0} | {:.3} | {:.2} | {} | {:.2} / {:.2} | {:.0} | {:.1} | {} |",
            m.controller,
            m.tracking.iae,
            m.tracking.steady_state_error_c,
            m.tracking.overshoot_c,
            settle,
            m.tracking.min_temp_c,
            m.tracking.max_temp_c,
            m.tracking.time_outside_2_8_s,
            m.energy_wh,
            m.ssr_switches
        );
    }
    if let Some(path) = &a.sim.plot {
        let minutes = |t: f64| t / 60.0;
        let first = &runs[0].1;
        let mut temp = Vec::new();
        let mut duty = Vec::new();
        for (_, out) in &runs {
            temp.push(plot::Series {
                name: out.metrics.controller.clone(),
                points: out.rows.iter().map(|r| (minutes(r.t_s), r.true_temp_c)).collect(),
            });
            duty.push(plot::Series {
                name: out.metrics.controller.clone(),
                points: out.rows.iter().map(|r| (minutes(r.t_s), r.duty)).collect(),
            });
        }
        // Setpoint last, so each controller has the same colour in both panels.
        temp.push(plot::Series {
            name: "setpoint".into(),
            points: first.rows.iter().map(|r| (minutes(r.t_s), r.setpoint_c)).collect(),
        });
        let panels = [
            plot::Panel { title: "True load temperature".into(), y_label: "°C".into(), series: temp, y_range: None },
            plot::Panel {
                title: "SSR duty".into(),
                y_label: "duty".into(),
                series: duty,
                y_range: Some((-0.02, 1.02)),
            },
        ];
        plot::panels(path, &format!("{} — {}", base.scenario.name, base.plant.name()), "time (min)", &panels)?;
        println!("\nplot written to {}", path.display());
    }
    Ok(())
}
