//! `hter` alone: a short demo of the firmware's control step on the simulated carrier.

use anyhow::Result;

use crate::sim::{self, ControllerChoice};
use crate::sim_cmd::{self, LoadArg, SimArgs};

/// `hter` without a command: a short PI pull-down and what to try next.
pub fn run() -> Result<()> {
    println!("hter demo: the firmware's control step (PI, Ts = 10 s) pulls a full-load H-TER I vaccine");
    println!("carrier (100 ml water, aluminium container) from 28 °C ambient down to 4 °C and holds it,");
    println!("against a physical model of the Peltier modules, SSR PWM, RTD and ADC. The vaccines must");
    println!("stay within +2…+8 °C and never freeze.\n");
    let args = SimArgs {
        scenario: "step".into(),
        controller: ControllerChoice::Pi,
        plant: "hter1".into(),
        model: None,
        n1: None,
        n2: None,
        nu: None,
        lambda: None,
        p_weight: None,
        r_weight: None,
        s_weight: None,
        p_pole: None,
        t_pole: None,
        load: LoadArg::Full,
        ambient: 28.0,
        duration: None,
        seed: 1,
        faults: Vec::new(),
        csv: None,
        plot: None,
        json: false,
        mission_seed: None,
    };
    let opts = sim_cmd::options(&args)?;
    let out = sim::run(&opts)?;
    for r in out.rows.iter().filter(|r| (r.t_s as u64).is_multiple_of(900)) {
        let bar = "#".repeat((r.duty * 20.0).round() as usize);
        println!(
            "  t = {:5.0} min   load {:6.2} °C   measured {:6.2} °C   duty {:4.2} {bar}",
            r.t_s / 60.0,
            r.true_temp_c,
            r.temp_c,
            r.duty
        );
    }
    println!();
    sim_cmd::print_summary(&opts, &out);
    println!("\nTry next:");
    println!("  hter sim --scenario piecewise --controller onoff --plot piecewise.png");
    println!("  hter sim --scenario step --controller pi --plot step.png --json");
    println!("  hter rtd --celsius 4");
    println!("  hter --help");
    Ok(())
}
