//! On-board commissioning ([`hter::ident::commission`]) against the hal-sim plant, through the
//! per-sample step and the simulated ADC and SSR as `hter sim` drives them, judged by the host's
//! own tool: the log of each run goes through `hter identify`'s pipeline (its `load` and
//! `compare`, i.e. `hter identify --input LOG --na 2 --nb 2` with the defaults `--method oe --nk
//! auto --operating-point auto`), and the board's model is scored on that same log with the
//! host's fit metric and operating point. The board must come within 3 fit points.
//!
//! Also: every way a commissioning fails, and how self-tuning GPC does on `piecewise` from the
//! commissioned model against the profile's start model (printed; run with `--nocapture`).

use std::path::PathBuf;

use hal_sim::identify_cmd::{compare, load, Delay, Method, OperatingPointChoice};
use hal_sim::periph::{SensorFault, SimAdc, SimSsr};
use hal_sim::plant::{Load, Plant, PlantParams};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{self, ControllerChoice, ControllerSpec, SimOptions, PWM_PERIOD_S};
use hter::hal::{apply_duty, RtdSampler};
use hter::ident::commission::{
    CommissionConfig, CommissionError, Commissioning, ConfigProblem, FaultKind, Phase, SignRule,
};
use hter::ident::model::Structure;
use hter::ident::oe_search::OeMemo;
use hter::ident::validate;
use hter::model::Model;
use hter::step::{Carrier, CarrierConfig, Mode, StepInput};

const TS_S: f64 = 10.0;

/// The simulated board: plant, ADC, SSR and the step running `Commissioning`.
struct Bench {
    plant: Plant,
    adc: SimAdc,
    ssr: SimSsr,
    carrier: Carrier<Commissioning>,
    t: u64,
}

/// One logged sample: time, the duty the step applied, the filtered temperature it saw.
type Row = (f64, f64, f64);

impl Bench {
    /// The plant at steady state holding `load_c` (settled 2 h at that duty, as `hter sim
    /// --scenario prbs` does), commissioning from the duty that holds it.
    fn holding(params: PlantParams, ambient_c: f64, load_c: f64, cfg: CommissionConfig) -> Bench {
        let (mut plant, u0) = Plant::at_load_temperature(params, ambient_c, load_c).expect("holdable");
        for _ in 0..(7200.0 / PWM_PERIOD_S) as usize {
            plant.advance_pwm_period(PWM_PERIOD_S, u0);
        }
        Bench::new(plant, u0, cfg)
    }

    fn new(plant: Plant, u0: f64, cfg: CommissionConfig) -> Bench {
        let mut ccfg = CarrierConfig::DEFAULT;
        // As the identify build and `hter sim --scenario prbs`: no supply-switch test pulse in
        // the record (the glue must suspend it while commissioning).
        ccfg.supervisor.switch.test_interval_s = 0.0;
        let valid = ccfg.validated().expect("carrier configuration");
        let c = Commissioning::new(cfg, ccfg.ts_s, u0 as f32).expect("commissioning configuration");
        Bench { plant, adc: SimAdc::new(1), ssr: SimSsr::new(), carrier: Carrier::new(valid, c), t: 0 }
    }

    /// One sample: sense, step (with the glue's abort on a mode change), actuate, advance.
    fn sample(&mut self) -> (Row, Mode) {
        let t_s = self.t as f64 * TS_S;
        self.adc.set_temperature_c(self.plant.sensed_temp_c());
        self.carrier.observe_supply_v(self.plant.supply_v() as f32);
        self.carrier.observe_switched_rail_v(self.ssr.switched_rail_v(self.plant.supply_v()) as f32);
        let counts = match self.adc.sample() {
            Ok(c) => c,
            Err(never) => match never {},
        };
        let out = self.carrier.step(&StepInput { t_ms: self.t * 10_000, counts, setpoint_c: 4.0 });
        self.carrier.controller_mut().abort_on_mode(out.mode);
        let duty = self.adc.window.clear_duty(out.duty);
        let _ = apply_duty(&mut self.ssr, duty);
        self.ssr.set_supply_enabled(out.supply_enable);
        let d = self.ssr.effective_duty();
        for _ in 0..(TS_S / PWM_PERIOD_S).round() as usize {
            self.plant.advance_pwm_period(PWM_PERIOD_S, d);
            self.adc.set_ssr_duty(d);
        }
        self.t += 1;
        ((t_s, f64::from(out.duty.get()), f64::from(out.temp_c.0)), out.mode)
    }

    fn commissioning(&self) -> &Commissioning {
        self.carrier.controller()
    }

    /// Runs until the commissioning finishes (at most `limit` samples); returns the log of the
    /// rest and the excitation (the record the board fits) and the samples it took in all.
    fn run(&mut self, limit: usize) -> (Vec<Row>, usize) {
        let mut rows = Vec::new();
        for n in 0..limit {
            let recording = matches!(self.commissioning().phase(), Phase::Rest { .. } | Phase::Excite { .. });
            let (row, _) = self.sample();
            if recording {
                rows.push(row);
            }
            if self.commissioning().outcome().is_some() {
                return (rows, n + 1);
            }
        }
        (rows, limit)
    }
}

/// The host's verdict on a log and the board model's score on it.
struct Judged {
    host_fit: f64,
    host_nk: usize,
    host_theta: Vec<f64>,
    board_fit: f64,
}

fn write_log(name: &str, rows: &[Row]) -> PathBuf {
    let path = std::env::temp_dir().join(format!("hter-commission-{}-{name}.csv", std::process::id()));
    let mut s = String::from("t_s,duty,temp_c\n");
    for (t, u, y) in rows {
        s.push_str(&format!("{t},{u},{y}\n"));
    }
    std::fs::write(&path, s).expect("write log");
    path
}

/// `hter identify --input LOG --na 2 --nb 2` (defaults: OE, nk auto, operating point auto) on
/// the log, and the board's model simulated on the same deviation data with the host's metric.
fn judge(name: &str, rows: &[Row], board: &Model) -> Judged {
    let path = write_log(name, rows);
    let d = load(&path, "temp_c", None, None, 1, OperatingPointChoice::Auto).expect("host load");
    let _ = std::fs::remove_file(&path);
    assert_eq!(d.op.kind, OperatingPointChoice::Initial, "{}", d.op.why);
    let cmp = compare(&d, Delay::Auto, 0, Method::Oe, 1.0, &mut OeMemo::default());
    let (_, host, _) = cmp.fits.iter().find(|(order, _, _)| *order == 2).expect("host 2nd-order fit");
    let s = Structure::new(2, 2, 0, board.k()).expect("structure");
    let theta: Vec<f64> = board.a()[..2].iter().chain(&board.b()[..2]).map(|v| f64::from(*v)).collect();
    let mut ysim = vec![0.0; d.y.len()];
    let board_fit = validate::simulate_fit(&s, &theta, &d.y, &d.u, &mut ysim);
    Judged {
        host_fit: host.fit_percent,
        host_nk: host.nk,
        host_theta: host.a.iter().chain(&host.b).copied().collect(),
        board_fit,
    }
}

/// Commissions the carrier as the board does (one run, both models: the control model of the
/// rule every b_i ≤ 0 and the cabinet model of the monotone rule) and compares each with the
/// host on the run's log; returns both models and their verdicts.
fn commission_and_judge(name: &str, params: PlantParams) -> ((Model, Judged), (Model, Judged)) {
    let cfg = CommissionConfig::DEFAULT;
    assert!(cfg.two_models());
    let mut bench = Bench::holding(params, 28.0, 4.0, cfg);
    let (rows, samples) = bench.run(cfg.max_total_samples() + 10);
    let c = bench.commissioning();
    let (control, cabinet) = match (c.outcome(), c.cabinet()) {
        (Some(Ok(m)), Some(cab)) => (m, cab),
        other => panic!(
            "{name}: commissioning did not succeed: {other:?} (fit {:?}, cabinet fit {:?}, {} passes)",
            c.fit_percent(),
            c.cabinet_fit_percent(),
            c.fit_passes()
        ),
    };
    assert_eq!(rows.len(), cfg.record_samples());
    assert!(samples <= cfg.max_total_samples(), "{samples}");
    assert!(usize::from(c.fit_passes()) <= cfg.max_fit_passes());
    let mut out = Vec::new();
    for (what, model, own) in [("control", control, c.fit_percent()), ("cabinet", cabinet, c.cabinet_fit_percent())] {
        let j = judge(name, &rows, &model);
        println!(
            "{name} {what}: board fit {:.2} % (own record {:.2} %, nk {}, a {:?}, b {:?}, gain {:.1} °C/duty) vs host {:.2} % (nk {}, θ {:?})",
            j.board_fit,
            own.unwrap_or(f32::NAN),
            model.k(),
            &model.a()[..2],
            &model.b()[..2],
            model.static_gain().unwrap_or(f32::NAN),
            j.host_fit,
            j.host_nk,
            j.host_theta,
        );
        assert!(f64::from(own.unwrap_or(0.0)) >= f64::from(cfg.min_fit_percent));
        out.push((model, j));
    }
    println!(
        "{name}: fit phase {} samples (both models), commissioning {} samples in all ({:.2} h at Ts = 10 s)",
        c.fit_passes(),
        samples,
        samples as f64 * TS_S / 3600.0
    );
    let cabinet = out.pop().unwrap();
    (out.pop().unwrap(), cabinet)
}

/// One commissioning gives both models: the cabinet model (monotone-step rule) comes within 3
/// points of the host (measured: within 0.03) and passes the cabinet check; the control model
/// (every b_i ≤ 0, what `plausible_model` accepts) is one the self-tuner trusts, at the fit that
/// rule allows (measured: H-TER I full 86.1 % vs the host's 96.4 %, half load 77.9 % vs 95.1 %,
/// H-TER II 95.7 % vs 95.9 %: the host's models have b1 > 0, two cooling lags in parallel,
/// which that rule refuses).
fn both_rules(name: &str, params: PlantParams, control_within_3: bool) {
    let ((m, j), (cab, jc)) = commission_and_judge(name, params);
    assert!(jc.board_fit >= jc.host_fit - 3.0, "{name}: board {:.2} % vs host {:.2} %", jc.board_fit, jc.host_fit);
    let gains = hter::profile::ADAPTIVE_GPC;
    assert_eq!(hter::ident::commission::cabinet_plausible(&gains, &cab), Ok(()), "{cab:?}");
    assert!(hter::control::adaptive::plausible_model(&gains, &m), "{m:?}");
    assert_eq!(j.board_fit >= j.host_fit - 3.0, control_within_3, "{name}: {:.2} vs {:.2}", j.board_fit, j.host_fit);
}

#[test]
fn hter1_full_load_within_three_points_of_the_host() {
    both_rules("hter1-full", PlantParams::hter1(Load::Full), false);
}

#[test]
fn hter1_half_load_within_three_points_of_the_host() {
    both_rules("hter1-half", PlantParams::hter1(Load::Half), false);
}

#[test]
fn hter2_within_three_points_of_the_host() {
    both_rules("hter2-full", PlantParams::hter2(Load::Full), true);
}

/// The two-model run's models are exactly what a run of each rule alone gives on the same
/// carrier (the grid is shared, each search keeps its own candidates): the control model is the
/// one GPC's measurements below were made from, the cabinet model the monotone rule's.
#[test]
fn each_model_of_the_board_run_is_what_its_rule_alone_gives() {
    let run = |cfg: CommissionConfig| {
        let mut bench = Bench::holding(PlantParams::hter1(Load::Full), 28.0, 4.0, cfg);
        let (_, samples) = bench.run(cfg.max_total_samples() + 10);
        let c = bench.commissioning();
        (c.outcome().unwrap().unwrap(), c.cabinet(), samples)
    };
    let (control, cabinet, both) = run(CommissionConfig::DEFAULT);
    let alone = |sign| CommissionConfig { sign, cabinet: false, ..CommissionConfig::DEFAULT };
    let (every, none, n_every) = run(alone(SignRule::EveryCoefficient));
    let (mono, _, n_mono) = run(alone(SignRule::Monotone));
    assert_eq!(none, None);
    assert_eq!(control, every);
    assert_eq!(cabinet, Some(mono));
    let record = CommissionConfig::DEFAULT.record_samples();
    println!(
        "H-TER I full: fit phase {} samples for both models, {} + {} alone",
        both - record,
        n_every - record,
        n_mono - record
    );
    assert_eq!(both - record, (n_every - record) + (n_mono - record) - hter::ident::commission::GRID_PASSES);
}

/// The modules' supply is cut: the duty reaches nothing, the load (at ambient, a 5 °C room)
/// does not move. In a 28 °C room the same load is out of 2–8 °C, and the run ends at once.
#[test]
fn no_excitation_when_the_load_does_not_respond() {
    let cfg = CommissionConfig::DEFAULT;
    let mut plant = Plant::at_ambient(PlantParams::hter1(Load::Full), 5.0);
    plant.set_supply_v(0.0);
    let mut bench = Bench::new(plant, 0.4, cfg);
    let (_, samples) = bench.run(cfg.max_total_samples() + 10);
    assert_eq!(bench.commissioning().outcome(), Some(Err(CommissionError::NoExcitation)));
    // Found at the end of the excitation, before any fit.
    assert_eq!(samples, cfg.record_samples());
    assert_eq!(CommissionError::NoExcitation.name(), "no_excitation");
    let mut warm = Plant::at_ambient(PlantParams::hter1(Load::Full), 28.0);
    warm.set_supply_v(0.0);
    let mut bench = Bench::new(warm, 0.4, cfg);
    let (_, samples) = bench.run(cfg.max_total_samples() + 10);
    assert_eq!(bench.commissioning().outcome(), Some(Err(CommissionError::Fault(FaultKind::OutOfBand))));
    assert!(samples < 10, "{samples}");
}

/// The supply is cut at the start from 4 °C: the load warms by itself toward ambient, which no
/// cooling model explains. No model comes out.
#[test]
fn no_model_when_the_supply_is_cut_at_4c() {
    let cfg = CommissionConfig::DEFAULT;
    let (mut plant, u0) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
    plant.set_supply_v(0.0);
    let mut bench = Bench::new(plant, u0, cfg);
    bench.run(cfg.max_total_samples() + 10);
    let out = bench.commissioning().outcome();
    println!("supply cut at 4 °C: {out:?} (fit on own record {:?})", bench.commissioning().fit_percent());
    assert!(matches!(out, Some(Err(_))), "{out:?}");
}

/// An open sensor in the middle of the excitation: the step goes to its sensor-fault mode, the
/// glue aborts, no model.
#[test]
fn a_sensor_fault_mid_run_fails_the_run() {
    let cfg = CommissionConfig::DEFAULT;
    let mut bench = Bench::holding(PlantParams::hter1(Load::Full), 28.0, 4.0, cfg);
    for _ in 0..600 {
        bench.sample();
    }
    assert_eq!(bench.commissioning().phase().name(), "excite");
    bench.adc.fault = SensorFault::Open;
    let mut modes = Vec::new();
    for _ in 0..5 {
        modes.push(bench.sample().1);
    }
    assert!(modes.contains(&Mode::SensorFault), "{modes:?}");
    let want = CommissionError::Fault(FaultKind::SensorFault);
    assert_eq!(bench.commissioning().outcome(), Some(Err(want)));
    assert_eq!(want.name(), "fault_sensor");
    // The sensor comes back: the run stays failed, holding the rest duty.
    bench.adc.fault = SensorFault::None;
    for _ in 0..20 {
        bench.sample();
    }
    assert_eq!(bench.commissioning().phase(), Phase::Failed(want));
}

#[test]
fn a_refused_configuration_starts_nothing() {
    let cfg = CommissionConfig { prbs_bits: 9, ..CommissionConfig::DEFAULT };
    let e = Commissioning::new(cfg, 10.0, 0.4).err();
    assert_eq!(e, Some(CommissionError::Config(ConfigProblem::Capacity)));
    let e = e.unwrap();
    assert!(e.to_string().starts_with("configuration refused"), "{e}");
    assert_eq!(
        Commissioning::new(CommissionConfig::DEFAULT, 10.0, -0.1).err().map(|e| e.name()),
        Some("config_rest_duty")
    );
}

/// IAE of self-tuning GPC on `piecewise` (H-TER I, full load, seed `seed`) from `initial`
/// (`None`: the profile's START_MODEL_HTER1), and the physical bound's.
fn gpc_piecewise(initial: Option<Model>, seed: u64) -> (f64, f64, f64) {
    let spec = ControllerSpec { initial, ..ControllerSpec::new(ControllerChoice::Gpc) };
    let mut opts = SimOptions::new(Scenario::built_in("piecewise").unwrap(), spec);
    opts.seed = seed;
    let out = sim::run(&opts).unwrap();
    let b = hal_sim::bound::bound(&opts).unwrap();
    (out.metrics.tracking.iae, b.iae, out.metrics.tracking.steady_state_error_c)
}

/// How self-tuning GPC does from the commissioned model against the profile's start model
/// (measurement, printed): the ratio of IAE to the physical bound, seeds 1–3. Measured: from the
/// control model (every b_i ≤ 0, k 6: what the board's self-tuner starts from, the same model
/// in a two-model run, `each_model_of_the_board_run_is_what_its_rule_alone_gives`) 1.12–1.13×,
/// steady-state error 0.022–0.026 °C (k 7 before the bound on its delay: 1.12–1.14×; asserted:
/// the delay rule's 7 % tolerance kept k 8, 1.40–1.44× and 0.17 °C), from START_MODEL_HTER1
/// 1.09–1.14×, 0.026–0.051 °C (1.21× with the 2-term self-tuner before issue 15); from
/// the monotone-step model (k 9, b1 > 0: the cabinet model) 1.74–1.88× with a 0.44–0.45 °C
/// steady-state error: `plausible_model` refuses that model, so the self-tuner neither trusts
/// it nor starts its estimate from it; the fallback PI drives until an estimate learnt from the
/// neutral start is trusted, and that estimate is a poor one (as a fixed model, `--model
/// arx:…;9`, GPC reaches 3.5×). Hence two models.
#[test]
fn gpc_from_the_commissioned_model() {
    let commissioned = |sign| {
        let cfg = CommissionConfig { sign, cabinet: false, ..CommissionConfig::DEFAULT };
        let mut bench = Bench::holding(PlantParams::hter1(Load::Full), 28.0, 4.0, cfg);
        bench.run(cfg.max_total_samples() + 10);
        bench.commissioning().outcome().unwrap().unwrap()
    };
    let starts = [
        ("commissioned, every b_i <= 0", Some(commissioned(SignRule::EveryCoefficient))),
        ("commissioned, monotone step", Some(commissioned(SignRule::Monotone))),
        ("START_MODEL_HTER1", None),
    ];
    for (i, (name, initial)) in starts.into_iter().enumerate() {
        let mut ratios = Vec::new();
        for seed in 1..=3 {
            let (iae, bound, sse) = gpc_piecewise(initial, seed);
            println!(
                "GPC piecewise from {name} (k {}): seed {seed}: IAE {iae:.0} = {:.2}x bound, steady-state error {sse:.3} °C",
                initial.map_or(hter::profile::START_MODEL_HTER1.k(), |m| m.k()),
                iae / bound
            );
            assert!(iae.is_finite());
            // What a commissioned board runs: no worse than a quarter above the bound and
            // settled at the setpoint (the 7 % delay tolerance's k 8 gave 1.40–1.44× and a
            // 0.17 °C limit cycle, `DELAY_TOLERANCE`).
            if i == 0 {
                assert!(iae / bound <= 1.25 && sse <= 0.1, "{name}, seed {seed}: {:.3}x, {sse:.3} °C", iae / bound);
            }
            ratios.push(iae / bound);
        }
        ratios.sort_by(f64::total_cmp);
        println!("GPC piecewise from {name}: median {:.2}x bound", ratios[1]);
    }
}

/// Self-tuning GPC on `piecewise` from the model commissioned at each delay whose host-metric
/// fit is within 3 points of the best (measurement, printed): does one delay serve GPC better?
/// Measured (default rule, H-TER I full load, the 4-term self-tuner): k 1–5 (k 5 and 6 the best
/// fit, 86.1 %) 2.0–2.6× the bound, k 6 1.12–1.13×, k 7 (85.9 %) 1.12–1.14×, k 8 (85.2 %)
/// 1.40–1.45×, k 9 1.72–1.95× (k 8 was the best, 1.28–1.31×, under the 2-term self-tuner).
#[test]
fn gpc_by_delay() {
    for sign in [SignRule::EveryCoefficient, SignRule::Monotone] {
        let mut rows = Vec::new();
        for k in 1..=10u8 {
            let cfg = CommissionConfig { sign, delay: Some(k), cabinet: false, ..CommissionConfig::DEFAULT };
            let mut bench = Bench::holding(PlantParams::hter1(Load::Full), 28.0, 4.0, cfg);
            let (log, _) = bench.run(cfg.max_total_samples() + 10);
            match bench.commissioning().outcome() {
                Some(Ok(m)) => {
                    let j = judge("by-delay", &log, &m);
                    rows.push((k, j.board_fit, j.host_fit, m));
                }
                other => {
                    println!("{sign:?} k {k}: {other:?} (fit on its record {:?})", bench.commissioning().fit_percent())
                }
            }
        }
        let best = rows.iter().map(|r| r.1).fold(f64::NEG_INFINITY, f64::max);
        for (k, fit, host, m) in rows.iter().filter(|r| r.1 >= best - 3.0) {
            let ratios: Vec<f64> = (1..=3)
                .map(|seed| {
                    let (iae, b, _) = gpc_piecewise(Some(*m), seed);
                    iae / b
                })
                .collect();
            println!("{sign:?} k {k}: fit {fit:.2} % (host best {host:.2} %): GPC piecewise IAE/bound seeds 1-3 {ratios:.2?}");
        }
    }
}

/// The control model's delay is bounded by the sensor chain (`MAX_CONTROL_DELAY_S`, 60 s). On
/// the half-loaded H-TER II the fit is flat over the delay (93.4–94.1 % for k 5–10 at 28 °C)
/// and the tolerance kept k 10, the scan's end: self-tuning GPC from that model, whose B
/// starts 100 s after the duty moves while the RTD shows the response from 50 s, held the
/// `piecewise` setpoints 0.19–0.22 °C off at 1.20–1.28 × the bound (seeds 1–3, 28 °C; at 20 °C
/// 1.51–1.55 × and 0.40–0.46 °C), worse than from the profile's start model (1.12 ×, 0.05 °C).
/// From the bounded model (k 6): 1.04–1.07 ×, 0.02 °C.
#[test]
fn the_control_model_delay_is_bounded_by_the_sensor_chain() {
    let cfg = CommissionConfig { cabinet: false, ..CommissionConfig::DEFAULT };
    let mut bench = Bench::holding(PlantParams::hter2(Load::Half), 28.0, 4.0, cfg);
    bench.run(cfg.max_total_samples() + 10);
    let m = bench.commissioning().outcome().unwrap().unwrap();
    assert!(m.k() <= 6, "{m:?}");
    for seed in 1..=3 {
        let spec = ControllerSpec { initial: Some(m), ..ControllerSpec::new(ControllerChoice::Gpc) };
        let mut opts = SimOptions::new(Scenario::built_in("piecewise").unwrap(), spec);
        opts.plant = hal_sim::sim::PlantChoice::Hter2;
        opts.load = Load::Half;
        opts.seed = seed;
        let out = sim::run(&opts).unwrap();
        let b = hal_sim::bound::bound(&opts).unwrap();
        let t = &out.metrics.tracking;
        println!(
            "H-TER II half load, commissioned k {}: seed {seed}: {:.3}x bound, steady-state error {:.3} C",
            m.k(),
            t.iae / b.iae,
            t.steady_state_error_c
        );
        assert!(t.iae / b.iae < 1.10 && t.steady_state_error_c < 0.05, "seed {seed}: {t:?}");
        assert_eq!(out.metrics.freeze_guard_trips, 0);
    }
}

/// Commissioning drives the duty open loop for hours: started with the load at an edge of the
/// setpoint range (2.5 or 7.5 °C), the PRBS took H-TER I's full load to 1.64 °C (114 samples
/// below 2 °C until the freeze guard tripped) or to 9.2 °C (540 samples above 8 °C, and the run
/// ended `done`); an ambient rise of 10 °C 50 minutes in held the load above 8 °C for 3.9 h. The
/// run now ends on the first reading outside 2–8 °C, and the law takes over.
#[test]
fn a_run_that_takes_the_load_out_of_2_to_8_c_ends_there() {
    let cfg = CommissionConfig::DEFAULT;
    let want = Some(Err(CommissionError::Fault(FaultKind::OutOfBand)));
    for (load_c, ambient_step) in [(2.5, None), (7.5, None), (4.0, Some(38.0)), (4.0, Some(18.0))] {
        let mut bench = Bench::holding(PlantParams::hter1(Load::Full), 28.0, load_c, cfg);
        let mut seen = Vec::new();
        for n in 0..cfg.max_total_samples() {
            if n == 300 {
                if let Some(a) = ambient_step {
                    bench.plant.set_ambient_c(a);
                }
            }
            let ((_, _, y), mode) = bench.sample();
            seen.push((y, mode));
            if bench.commissioning().outcome().is_some() {
                break;
            }
        }
        let what = format!("held at {load_c} °C, ambient to {ambient_step:?}");
        assert_eq!(bench.commissioning().outcome(), want, "{what}");
        let (last, before) = seen.split_last().unwrap();
        assert!(before.iter().all(|(y, m)| (2.0..=8.0).contains(y) && *m == Mode::Normal), "{what}");
        assert!(!(2.0..=8.0).contains(&last.0) && last.1 == Mode::Normal, "{what}: {last:?}");
    }
}
