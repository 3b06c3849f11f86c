//! The `hter` command line (SPEC §3). `hter` alone runs a short demo.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{self, ControllerChoice, ControllerSpec, PlantChoice, SimOptions, SimOutput};
use hal_sim::{campaign_cmd, identify_cmd, log2csv_cmd, monitor_cmd, plot};
use hter::rtd::Rtd;
use hter::units::{Celsius, Ohms};

/// Adaptive control of a thermoelectric (Peltier) vaccine carrier: simulate, identify, convert.
#[derive(Parser, Debug)]
#[command(name = "hter", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

// Parsed once per process: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
enum Command {
    /// Run a closed-loop scenario: the firmware's per-sample step against the plant model.
    Sim(SimArgs),
    /// Identify an ARX/ARMAX model of the carrier from a logged run (CSV).
    Identify(identify_cmd::IdentifyArgs),
    /// Convert between RTD resistance and temperature (IEC 60751).
    Rtd(RtdArgs),
    /// Cold-chain record of a CSV log: WHO-style alarms, mean kinetic temperature, excursions.
    Monitor(monitor_cmd::MonitorArgs),
    /// Run one scenario with several controllers and print a markdown comparison table.
    Compare(CompareArgs),
    /// Turn the firmware's defmt telemetry log into the CSV `identify` and `monitor` read.
    Log2csv(log2csv_cmd::Log2CsvArgs),
    /// Run many randomized 24 h missions (plant ±50 %, ambient 0–43 °C, lid openings, supply
    /// sags, sensor spikes, random hardware faults) in parallel and judge them.
    Campaign(campaign_cmd::CampaignArgs),
}

#[derive(clap::Args, Debug)]
struct SimArgs {
    /// Scenario name (step, piecewise, half-load, disturbance, prbs, hot-zone, mission) or a
    /// JSON scenario file.
    #[arg(long, default_value = "step")]
    scenario: String,
    /// Controller.
    #[arg(long, value_enum, default_value = "pi")]
    controller: ControllerChoice,
    /// Plant: hter1 (aluminium container), hter2 (stainless steel), or an ideal ARX model
    /// arx:A;B;K (y = temperature − ambient, u = duty).
    #[arg(long, default_value = "hter1")]
    plant: String,
    /// Fixed model for gmvc/igmvc/gpc, arx:A;B;K[;C] (without it they are self-tuning).
    #[arg(long)]
    model: Option<String>,
    /// GPC: first predicted sample in the cost.
    #[arg(long)]
    n1: Option<usize>,
    /// GPC: last predicted sample in the cost (≤ 30).
    #[arg(long)]
    n2: Option<usize>,
    /// GPC: control horizon (≤ 5).
    #[arg(long)]
    nu: Option<usize>,
    /// GPC and IGMVC: weight on the control increment (≥ 0).
    #[arg(long, allow_negative_numbers = true)]
    lambda: Option<f64>,
    /// GMVC: output weight P.
    #[arg(long, allow_negative_numbers = true)]
    p_weight: Option<f64>,
    /// GMVC: reference weight R.
    #[arg(long, allow_negative_numbers = true)]
    r_weight: Option<f64>,
    /// GMVC: control weight S (≥ 0).
    #[arg(long, allow_negative_numbers = true)]
    s_weight: Option<f64>,
    /// GMVC and IGMVC: pole α of the output weight P = (1 − α q⁻¹)/(1 − α), 0 ≤ α < 1
    /// (default 0.95; 0 gives the classical P = 1).
    #[arg(long, allow_negative_numbers = true)]
    p_pole: Option<f64>,
    /// IGMVC and self-tuning GPC: pole τ of the T-filter T = 1 − τ q⁻¹, 0 ≤ τ < 1 (0: none).
    #[arg(long, allow_negative_numbers = true)]
    t_pole: Option<f64>,
    /// Water load: full (100 ml) or half (50 ml).
    #[arg(long, value_enum, default_value = "full")]
    load: LoadArg,
    /// Ambient temperature, °C.
    #[arg(long, default_value_t = 28.0, allow_negative_numbers = true)]
    ambient: f64,
    /// Duration, s (default: the scenario's own).
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Inject a hardware fault at a time, KIND@T_S (repeatable): sensor-open, sensor-short,
    /// sensor-stuck, sensor-spikes, sensor-offset, ssr-stuck-on, ssr-stuck-off, supply-sag,
    /// lid-open, brownout.
    #[arg(long = "fault")]
    faults: Vec<String>,
    /// Write the trace as CSV (one row per control sample).
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Plot temperature, setpoint and duty to a .png or .svg file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Print the metrics as one JSON object instead of the summary.
    #[arg(long)]
    json: bool,
    /// Replay the randomized mission of this seed from `hter campaign` (its carrier, ambient,
    /// lid openings, supply sag, faults and noise seed); the controller flags still apply.
    #[arg(long, conflicts_with_all = ["scenario", "plant", "load", "ambient", "duration", "seed", "faults"])]
    mission_seed: Option<u64>,
}

#[derive(clap::Args, Debug)]
struct CompareArgs {
    /// The scenario and plant, exactly as for `hter sim` (its --controller is ignored).
    #[command(flatten)]
    sim: SimArgs,
    /// Controllers to compare, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "onoff,pi,gmvc,igmvc,gpc")]
    controllers: Vec<ControllerChoice>,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum LoadArg {
    Full,
    Half,
}

#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["ohms", "celsius", "counts"])))]
struct RtdArgs {
    /// Resistance to convert, Ω.
    #[arg(long, allow_negative_numbers = true)]
    ohms: Option<f64>,
    /// Temperature to convert, °C.
    #[arg(long, allow_negative_numbers = true)]
    celsius: Option<f64>,
    /// A conversion of the board's RTD channel (the `counts=` of its telemetry) to convert
    /// through the default front end, uncalibrated: the "measured" reading of a calibration.
    #[arg(long)]
    counts: Option<u32>,
    /// Nominal resistance at 0 °C: 100 (Pt100) or 1000 (Pt1000).
    #[arg(long, default_value_t = 100)]
    r0: u32,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            // clap's own message can span lines; keep the first, which names the problem.
            let msg = e.to_string();
            let first = msg.lines().next().unwrap_or("invalid arguments").trim_start_matches("error: ");
            eprintln!("error: {first} (see 'hter --help')");
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        None => demo(),
        Some(Command::Sim(a)) => sim_cmd(&a),
        Some(Command::Identify(a)) => identify_cmd::run(&a),
        Some(Command::Rtd(a)) => rtd_cmd(&a),
        Some(Command::Monitor(a)) => monitor_cmd::run(&a),
        Some(Command::Compare(a)) => compare_cmd(&a),
        Some(Command::Log2csv(a)) => log2csv_cmd::run(&a),
        Some(Command::Campaign(a)) => campaign_cmd::run(&a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}

fn finite(name: &str, x: f64) -> Result<f64> {
    if x.is_finite() {
        Ok(x)
    } else {
        bail!("--{name} must be a finite number, got {x}")
    }
}

fn sim_options(a: &SimArgs) -> Result<SimOptions> {
    let scenario = Scenario::resolve(&a.scenario)?;
    let duration_s = match a.duration {
        Some(d) => finite("duration", d)?,
        None => scenario.duration_s,
    };
    let mut controller = ControllerSpec::new(a.controller);
    if let Some(m) = &a.model {
        controller.model = Some(hal_sim::arx::parse(m)?);
    }
    if let Some(n) = a.n1 {
        controller.gpc.n1 = n;
    }
    if let Some(n) = a.n2 {
        controller.gpc.n2 = n;
    }
    if let Some(n) = a.nu {
        controller.gpc.nu = n;
    }
    if let Some(l) = a.lambda {
        let l = finite("lambda", l)?;
        if l < 0.0 {
            bail!("--lambda must be ≥ 0, got {l}");
        }
        controller.gpc.lambda = l as f32;
        controller.igmvc.lambda = l as f32;
    }
    let g = &controller.gpc;
    if g.n1 < 1 || g.n2 < g.n1 || g.n2 > hter::control::gpc::MAX_N2 {
        bail!("GPC horizons need 1 ≤ N1 ≤ N2 ≤ {}, got N1 = {}, N2 = {}", hter::control::gpc::MAX_N2, g.n1, g.n2);
    }
    if g.nu < 1 || g.nu > hter::control::gpc::MAX_NU || g.nu > g.n2 {
        bail!("GPC control horizon needs 1 ≤ Nu ≤ min(N2, {}), got Nu = {}", hter::control::gpc::MAX_NU, g.nu);
    }
    if let Some(p) = a.p_weight {
        controller.gmvc.p = finite("p-weight", p)? as f32;
        if p == 0.0 {
            bail!("--p-weight must not be 0");
        }
    }
    if let Some(r) = a.r_weight {
        controller.gmvc.r = finite("r-weight", r)? as f32;
    }
    if let Some(sw) = a.s_weight {
        let sw = finite("s-weight", sw)?;
        if sw < 0.0 {
            bail!("--s-weight must be ≥ 0, got {sw}");
        }
        controller.gmvc.s = sw as f32;
    }
    if let Some(al) = a.p_pole {
        let al = finite("p-pole", al)?;
        if !(0.0..1.0).contains(&al) {
            bail!("--p-pole must be in [0, 1), got {al}");
        }
        controller.gmvc.p_pole = al as f32;
        controller.igmvc.p_pole = al as f32;
    }
    if let Some(tp) = a.t_pole {
        let tp = finite("t-pole", tp)?;
        if !(0.0..1.0).contains(&tp) {
            bail!("--t-pole must be in [0, 1), got {tp}");
        }
        controller.igmvc.t_pole = tp as f32;
        controller.gpc_t_filter = tp as f32;
    }
    if let Some(seed) = a.mission_seed {
        return Ok(hal_sim::mission::Mission::generate(seed).options(controller));
    }
    Ok(SimOptions {
        scenario,
        controller,
        plant: PlantChoice::parse(&a.plant)?,
        load: match a.load {
            LoadArg::Full => Load::Full,
            LoadArg::Half => Load::Half,
        },
        ambient_c: finite("ambient", a.ambient)?,
        duration_s,
        seed: a.seed,
        faults: a.faults.iter().map(|f| sim::Fault::parse(f)).collect::<Result<_>>()?,
    })
}

fn sim_cmd(a: &SimArgs) -> Result<()> {
    let opts = sim_options(a)?;
    let out = sim::run(&opts)?;
    if let Some(path) = &a.csv {
        write_csv(path, &out)?;
    }
    if let Some(path) = &a.plot {
        plot_run(path, &opts, &out)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&out.metrics)?);
    } else {
        print_summary(&opts, &out);
        if let Some(p) = &a.csv {
            println!("trace written to {}", p.display());
        }
        if let Some(p) = &a.plot {
            println!("plot written to {}", p.display());
        }
    }
    Ok(())
}

fn compare_cmd(a: &CompareArgs) -> Result<()> {
    if a.controllers.is_empty() {
        bail!("--controllers is empty");
    }
    let base = sim_options(&a.sim)?;
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

fn write_csv(path: &std::path::Path, out: &SimOutput) -> Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("cannot write '{}'", path.display()))?;
    for r in &out.rows {
        w.serialize(r)?;
    }
    w.flush().with_context(|| format!("cannot write '{}'", path.display()))?;
    Ok(())
}

fn plot_run(path: &std::path::Path, opts: &SimOptions, out: &SimOutput) -> Result<()> {
    let minutes = |t: f64| t / 60.0;
    let pts = |f: &dyn Fn(&sim::Row) -> f64| out.rows.iter().map(|r| (minutes(r.t_s), f(r))).collect();
    let temp = plot::Panel {
        title: "Load temperature".into(),
        y_label: "°C".into(),
        series: vec![
            plot::Series { name: "setpoint".into(), points: pts(&|r| r.setpoint_c) },
            plot::Series { name: "true load".into(), points: pts(&|r| r.true_temp_c) },
            plot::Series { name: "measured (filtered)".into(), points: pts(&|r| r.temp_c) },
            plot::Series { name: "2 °C limit".into(), points: pts(&|_| 2.0) },
        ],
        y_range: None,
    };
    let duty = plot::Panel {
        title: "SSR duty".into(),
        y_label: "duty".into(),
        series: vec![plot::Series { name: "duty".into(), points: pts(&|r| r.duty) }],
        y_range: Some((-0.02, 1.02)),
    };
    let title = format!(
        "{} — {} on {}, {:?} load, {} °C ambient",
        opts.scenario.name,
        out.metrics.controller,
        opts.plant.name(),
        opts.scenario.load.unwrap_or(opts.load),
        opts.ambient_c
    );
    let mut panels = vec![temp, duty];
    // Self-tuning runs: the estimate over time, as the seed's Figs 5.21 and 6.9.
    let est = |f: &dyn Fn(&sim::Row) -> Option<f32>| -> Vec<(f64, f64)> {
        out.rows.iter().filter_map(|r| f(r).map(|v| (minutes(r.t_s), f64::from(v)))).collect()
    };
    if out.rows.iter().any(|r| r.a1.is_some()) {
        panels.push(plot::Panel {
            title: "Estimated A(q⁻¹) = 1 + a1 q⁻¹ + a2 q⁻²".into(),
            y_label: "coefficient".into(),
            series: vec![
                plot::Series { name: "a1".into(), points: est(&|r| r.a1) },
                plot::Series { name: "a2".into(), points: est(&|r| r.a2) },
            ],
            y_range: None,
        });
        panels.push(plot::Panel {
            title: "Estimated B(q⁻¹) = b0 + b1 q⁻¹ (°C per unit duty)".into(),
            y_label: "coefficient".into(),
            series: vec![
                plot::Series { name: "b0".into(), points: est(&|r| r.b0) },
                plot::Series { name: "b1".into(), points: est(&|r| r.b1) },
            ],
            y_range: None,
        });
    }
    plot::panels(path, &title, "time (min)", &panels)
}

fn print_summary(opts: &SimOptions, out: &SimOutput) {
    let m = &out.metrics;
    println!("scenario    {} — {}", opts.scenario.name, opts.scenario.description);
    println!(
        "plant       {}, {:?} load, ambient {} °C; controller {}; Ts = {} s",
        opts.plant.name(),
        opts.scenario.load.unwrap_or(opts.load),
        opts.ambient_c,
        m.controller,
        out.ts_s
    );
    println!("IAE                         {:10.1} °C·s", m.tracking.iae);
    match m.tracking.settle_time_s {
        Some(s) => println!("settle time (±0.5 °C)       {:10.0} s", s),
        None => println!("settle time (±0.5 °C)          never"),
    }
    println!("max |error| after settling  {:10.2} °C", m.tracking.max_abs_error_after_settle_c);
    println!("steady-state |error|        {:10.2} °C", m.tracking.steady_state_error_c);
    println!("overshoot                   {:10.2} °C", m.tracking.overshoot_c);
    println!("min / max load temperature  {:6.2} / {:.2} °C", m.tracking.min_temp_c, m.tracking.max_temp_c);
    println!("time outside 2–8 °C         {:10.0} s", m.tracking.time_outside_2_8_s);
    println!("energy                      {:10.2} Wh", m.energy_wh);
    println!("SSR switches                {:10}", m.ssr_switches);
    if !m.faults_detected.is_empty() {
        let list: Vec<String> = m.faults_detected.iter().map(|f| format!("{}@{}s", f.kind, f.t_s)).collect();
        println!("faults detected             {}", list.join(", "));
    }
}

fn demo() -> Result<()> {
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
    let opts = sim_options(&args)?;
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
    print_summary(&opts, &out);
    println!("\nTry next:");
    println!("  hter sim --scenario piecewise --controller onoff --plot piecewise.png");
    println!("  hter sim --scenario step --controller pi --plot step.png --json");
    println!("  hter rtd --celsius 4");
    println!("  hter --help");
    Ok(())
}

fn rtd_cmd(a: &RtdArgs) -> Result<()> {
    let rtd = match a.r0 {
        100 => Rtd::PT100,
        1000 => Rtd::PT1000,
        other => bail!("--r0 must be 100 or 1000, got {other}"),
    };
    let from_counts = match a.counts {
        Some(c) => {
            let fe = hter::adc::AdcFrontEnd::DEFAULT;
            let r = fe.ohms(c).map_err(|e| {
                anyhow::anyhow!(
                    "{c} counts is not a working RTD on the default front end ({e:?}: open at ≥ {}, short below {} Ω)",
                    fe.full_scale_counts - fe.open_margin_counts,
                    fe.short_below_ohm
                )
            })?;
            Some(f64::from(r.0))
        }
        None => None,
    };
    let (ohms, celsius) = match (from_counts.or(a.ohms), a.celsius) {
        (Some(r), _) => {
            let r = finite("ohms", r)?;
            if r <= 0.0 {
                bail!("--ohms must be positive, got {r}");
            }
            let t = rtd.temperature(Ohms(r as f32)).map_err(|e| {
                anyhow::anyhow!("{r} Ω is outside the Pt{} range of IEC 60751 (−200…850 °C): {e:?}", a.r0)
            })?;
            (r, f64::from(t.0))
        }
        (None, Some(t)) => {
            let t = finite("celsius", t)?;
            let r = rtd
                .resistance(Celsius(t as f32))
                .map_err(|e| anyhow::anyhow!("{t} °C is outside the IEC 60751 range −200…850 °C: {e:?}"))?;
            (f64::from(r.0), t)
        }
        (None, None) => bail!("give --ohms, --celsius or --counts"),
    };
    if a.json {
        let mut v = serde_json::json!({ "ohms": ohms, "celsius": celsius });
        if let Some(c) = a.counts {
            v["counts"] = c.into();
        }
        println!("{v}");
    } else if let Some(c) = a.counts {
        println!("{c} counts: Pt{}: {:.4} Ω  ⇔  {:.3} °C (uncalibrated, default front end)", a.r0, ohms, celsius);
    } else {
        println!("Pt{}: {:.3} Ω  ⇔  {:.3} °C", a.r0, ohms, celsius);
    }
    Ok(())
}
