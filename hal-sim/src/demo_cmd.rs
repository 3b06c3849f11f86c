//! `hter` alone: a short demo of the firmware's control step on the simulated carrier.

use anyhow::Result;

use crate::bound;
use crate::sim::{self, ControllerChoice};
use crate::sim_cmd::{self, LoadArg, SimArgs};

/// `hter` without a command: a short pull-down by the board's default controller (self-tuning
/// GPC), how far it is from the physical bound and from PI, and what to try next.
pub fn run() -> Result<()> {
    println!("hter demo: the firmware's control step (self-tuning GPC, Ts = 10 s, the board's default)");
    println!("pulls a full-load H-TER I vaccine carrier (100 ml water, aluminium container) from 28 °C");
    println!("ambient down to 4 °C and holds it, against a physical model of the Peltier modules, SSR");
    println!("PWM, RTD and ADC. The vaccines must stay within +2…+8 °C and never freeze.\n");
    let args = SimArgs {
        scenario: "step".into(),
        controller: Some(ControllerChoice::Gpc),
        plant: "hter1".into(),
        model: None,
        n1: None,
        n2: None,
        nu: None,
        lambda: None,
        kp: None,
        ti: None,
        p_weight: None,
        r_weight: None,
        s_weight: None,
        p_pole: None,
        t_pole: None,
        no_approach_lead: false,
        load: LoadArg::Full,
        ambient: 28.0,
        duration: None,
        seed: 1,
        drive: crate::sim::Drive::Ssr,
        module_sense: false,
        faults: Vec::new(),
        csv: None,
        plot: None,
        json: false,
        commission: None,
        commission_ambient: None,
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
    // The same pull-down with the PI, and the physical bound of the schedule.
    let pi = sim::run(&sim::SimOptions {
        controller: sim::ControllerSpec { choice: ControllerChoice::Pi, ..opts.controller },
        ..opts.clone()
    })?;
    let b = bound::bound(&opts)?.iae;
    let (gpc_iae, pi_iae) = (out.metrics.tracking.iae, pi.metrics.tracking.iae);
    println!("\nHow good is that? No controller can beat the bound: the SSR fully on from 28 °C until the");
    println!("load reaches 4 °C, zero error after (`hter compare` prints it for any scenario).");
    println!("  bound         IAE {b:8.0} °C·s");
    println!("  GPC           IAE {gpc_iae:8.0} °C·s  = {:.3} × bound, {:5.0} °C·s above it", gpc_iae / b, gpc_iae - b);
    println!("  PI            IAE {pi_iae:8.0} °C·s  = {:.3} × bound, {:5.0} °C·s above it", pi_iae / b, pi_iae - b);
    println!("Most of a pull-down's IAE is the pull-down itself; the setpoint steps of `piecewise` tell");
    println!("the controllers apart: hter compare --scenario piecewise");
    println!("\nTry next:");
    println!("  hter sim --scenario piecewise --controller onoff --plot piecewise.png");
    println!("  hter sim --scenario step --controller pi --kp 0.4 --ti 500 --plot step.png --json");
    println!("  hter rtd --celsius 4");
    println!("  hter --help");
    Ok(())
}
