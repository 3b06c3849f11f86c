//! `hter compare`: one scenario run with several controllers, as a markdown table (the
//! physical bound of the schedule first, each controller's IAE also as a ratio to it) or as
//! JSON (`{"bound_iae": X, "iae_over_bound": [r, ...], "controllers": [sim JSON, ...]}`), and an optional plot of every run.

use anyhow::{bail, Result};

use crate::bound::{self, Bound};
use crate::plot;
use crate::sim::{self, ControllerChoice};
use crate::sim_cmd::{self, SimArgs};

/// Arguments of `hter compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// The scenario and plant, exactly as for `hter sim`; its --controller and --csv (one run's
    /// trace) are refused here (--controllers; `hter sim --csv` per controller).
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
    // `--controllers pi,pi` ran the same run twice and printed two identical rows, as if two
    // controllers had been compared.
    if let Some((i, c)) = a.controllers.iter().enumerate().find(|(i, c)| a.controllers[..*i].contains(c)) {
        use clap::ValueEnum;
        let name = c.to_possible_value().map_or_else(|| format!("{c:?}"), |v| v.get_name().to_string());
        bail!(
            "--controllers names {name} twice (entries {} and {}): each controller runs once",
            a.controllers.iter().position(|x| x == c).unwrap_or(0) + 1,
            i + 1
        );
    }
    // Per-run options compare has no single run for: refused, not silently ignored.
    if a.sim.controller.is_some() {
        bail!("--controller picks hter sim's one controller: compare runs --controllers (comma-separated)");
    }
    if let Some(p) = &a.sim.csv {
        bail!(
            "--csv '{}' is one run's trace and compare runs several: use hter sim --controller C --csv FILE for each",
            p.display()
        );
    }
    sim_cmd::check_tuning_applies(&a.sim, &a.controllers)?;
    if let Some(p) = &a.sim.plot {
        sim_cmd::check_paths(&sim_cmd::input_paths(&a.sim), &[("--plot", p)])?;
        plot::check_path(p)?;
    }
    let base = sim_cmd::options(&a.sim)?;
    // Every run of it is the same PRBS: five identical rows named "prbs", none of the
    // controllers asked for.
    if base.scenario.excitation {
        bail!(
            "the {} scenario runs no controller (open loop, a PRBS on the SSR): there is nothing to compare (hter sim --scenario {} runs it)",
            base.scenario.name,
            base.scenario.name
        );
    }
    let mut runs = Vec::new();
    for &c in &a.controllers {
        let mut opts = base.clone();
        opts.controller.choice = c;
        let out = sim::run(&opts)?;
        runs.push((c, out));
    }
    // A plant that cannot hold one of the setpoints has no steady state to start the bound
    // from: the table says why, the JSON has null.
    let bound = bound::bound(&base);
    if a.sim.json {
        // Each controller's IAE as a ratio to the bound, in the controllers' order (SPEC §9);
        // null where the bound is 0 or unknown. Beside the sim objects, which stay exactly what
        // `hter sim --json` prints.
        let b = bound.as_ref().ok().map(|b| b.iae);
        let ratios: Vec<Option<f64>> =
            runs.iter().map(|(_, out)| b.filter(|b| *b > 0.0).map(|b| out.metrics.tracking.iae / b)).collect();
        let v = serde_json::json!({
            "bound_iae": b,
            "iae_over_bound": ratios,
            "controllers": runs.iter().map(|(_, out)| &out.metrics).collect::<Vec<_>>(),
        });
        println!("{v}");
    } else {
        print_table(&base, &bound, &runs);
    }
    if let Some(path) = &a.sim.plot {
        plot_runs(path, &base, &runs)?;
        if !a.sim.json {
            println!("\nplot written to {}", path.display());
        }
    }
    Ok(())
}

/// `iae / bound` to two decimals, or "n/a" where the bound is 0 or unknown.
pub fn ratio(iae: f64, bound: Option<f64>) -> String {
    match bound {
        Some(b) if b > 0.0 => format!("{:.2}", iae / b),
        _ => "n/a".into(),
    }
}

/// The markdown table: the bound as the first row, then each controller.
fn print_table(base: &sim::SimOptions, bound: &Result<Bound>, runs: &[(ControllerChoice, sim::SimOutput)]) {
    println!(
        "{} on {}, {:?} load, {} °C ambient, seed {}",
        base.scenario.name,
        base.plant.name(),
        base.scenario.load.unwrap_or(base.load),
        base.ambient_c,
        base.seed
    );
    println!();
    println!("| controller | IAE (°C·s) | IAE / bound | steady-state error (°C) | overshoot (°C) | settle ±{} °C (s) | min / max (°C) | time outside 2–8 °C (s) | energy (Wh) | SSR switches |", crate::metrics::SETTLE_BAND_C);
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let b = bound.as_ref().ok().map(|b| b.iae);
    match bound {
        Ok(bd) => println!("| bound | {:.0} | {} | – | – | – | – | – | – | – |", bd.iae, ratio(bd.iae, b)),
        Err(e) => println!("| bound | n/a ({e}) | – | – | – | – | – | – | – | – |"),
    }
    for (_, out) in runs {
        let m = &out.metrics;
        let settle = m.tracking.settle_time_s.map_or("never".to_string(), |s| format!("{s:.0}"));
        println!(
            "| {} | {:.0} | {} | {:.3} | {:.2} | {} | {:.2} / {:.2} | {:.0} | {:.1} | {} |",
            m.controller,
            m.tracking.iae,
            ratio(m.tracking.iae, b),
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
    if let Ok(bd) = bound {
        if bd.changes_ignored > 0 {
            println!();
            println!(
                "The bound covers the setpoint changes only: the scenario's {} timed change(s) of ambient, heat or supply are not in it.",
                bd.changes_ignored
            );
        }
    }
}

/// Every run's true load temperature and duty in two panels.
fn plot_runs(
    path: &std::path::Path,
    base: &sim::SimOptions,
    runs: &[(ControllerChoice, sim::SimOutput)],
) -> Result<()> {
    {
        let minutes = |t: f64| t / 60.0;
        let first = &runs[0].1;
        let mut temp = Vec::new();
        let mut duty = Vec::new();
        for (_, out) in runs {
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
        plot::panels(path, &format!("{} — {}", base.scenario.name, base.plant.name()), "time (min)", &panels)
    }
}
