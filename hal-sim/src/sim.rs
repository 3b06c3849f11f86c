//! The closed-loop simulation: the library's per-sample step against the plant model, through
//! the simulated ADC and SSR — exactly the data path of the firmware.
//!
//! Each control sample (every Ts):
//! 1. the simulated ADC converts the plant's sensed (lagged, delayed) temperature to counts;
//! 2. [`hter::step::Carrier::step`] turns counts into a duty and events;
//! 3. the duty goes to the simulated SSR through [`hter::hal::apply_duty`];
//! 4. the plant integrates Ts / PWM-period SSR periods, each switched on then off for real.
//!
//! The board around the step is simulated too: the duty is cleared of the ADC's conversion
//! window ([`hter::adc::SampleWindow::clear_duty`]) and the RTD is converted at that fixed
//! phase ([`SamplePhase`]); the supply divider and the switched-rail sense are read every
//! sample; the heartbeat ([`hter::failsafe::Heartbeat`]) toggles once per step into the
//! board's [`Monostable`], whose expiry opens the supply switch and sounds the alarm hardware
//! (`alarm_hw`): the only thing that stops cooling when the step stops being called
//! (`--fault firmware-hang@T`).

use anyhow::{anyhow, bail, Result};
use hter::alarm::{Annunciator, Indication};
use hter::control::adaptive::{AdaptiveConfig, SelfTuning};
use hter::control::excite::PrbsExcitation;
use hter::control::gpc::GpcConfig;
use hter::control::mv::{GmvcConfig, IgmvcConfig};
use hter::control::AdaptiveMode;
use hter::control::Controller;
use hter::control::{AnyController, FixedModel, Law};
use hter::event::EventKind;
use hter::hal::{apply_duty, RtdSampler};
use hter::ident::prbs::PrbsConfig;
use hter::model::Model;
use hter::persist::{HistoryRecord, ModelCadence, ModelRecord, Recorder, ResetCause, Save};
use hter::profile::{self, Kind};
use hter::step::{Carrier, CarrierConfig, Mode, StepInput, StepOutput};
use hter::units::Celsius;

use crate::arx::{self, ArxPlant};
use crate::metrics::{self, Sample, SimMetrics, Stamped};
pub use crate::periph::SamplePhase;
use crate::periph::{Monostable, SensorFault, SimAdc, SimSsr, SsrFault};
use crate::plant::{Load, Plant, PlantParams};
use crate::scenario::{Change, Scenario, Start, PREROLL_S};
use hter::failsafe::Heartbeat;

/// SSR PWM period, s. The seed drove its SSR from a DAQ with a slow software PWM; 1 s gives 1 %
/// duty resolution against Ts = 10 s and is far faster than the modules' thermal response.
pub const PWM_PERIOD_S: f64 = 1.0;

/// Rest at the holding duty at the start of an excitation scenario's log (`prbs`), s, before
/// the PRBS begins: after the 2 h settling, so the record starts at steady state and `hter
/// identify --operating-point auto` finds the initial rest (180 samples at Ts = 10 s, far more
/// than the 5 it needs, and under the 10 % of the record it averages at most).
pub const PRBS_REST_S: f64 = 1800.0;

/// Which controller runs in the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerChoice {
    /// On-Off with ±0.3 °C hysteresis.
    Onoff,
    /// Proportional only (Ziegler–Nichols P gain).
    P,
    /// PI with anti-windup (Ziegler–Nichols, detuned).
    Pi,
    /// Generalized minimum variance (weights P, R, S).
    Gmvc,
    /// Incremental GMVC (weight λ on Δu).
    Igmvc,
    /// Generalized predictive control (N1, N2, Nu, λ).
    Gpc,
}

/// A controller with its tuning and, for the model-based ones, an optional fixed model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerSpec {
    /// Which controller.
    pub choice: ControllerChoice,
    /// Fixed model (`--model arx:...`); `None` = self-tuning for gmvc/igmvc/gpc.
    pub model: Option<Model>,
    /// GPC tuning.
    pub gpc: GpcConfig,
    /// GMVC weights.
    pub gmvc: GmvcConfig,
    /// IGMVC weight.
    pub igmvc: IgmvcConfig,
    /// Self-tuning GPC: T-filter pole (`AdaptiveConfig::t_filter`).
    pub gpc_t_filter: f32,
    /// Model the self-tuning laws start from; `None`: the one identified on the simulated
    /// carrier (`profile::START_MODEL_HTER1`, `START_MODEL_HTER2`), as a board starts from the
    /// model persisted from its own identification run.
    pub initial: Option<Model>,
}

impl ControllerSpec {
    /// The controller with its default tuning.
    pub fn new(choice: ControllerChoice) -> Self {
        Self {
            choice,
            model: None,
            gpc: GpcConfig::DEFAULT,
            gmvc: GmvcConfig::DEFAULT,
            igmvc: IgmvcConfig::DEFAULT,
            gpc_t_filter: profile::GPC_T_FILTER,
            initial: None,
        }
    }

    /// The law of a model-based controller.
    pub fn law(&self) -> Option<Law> {
        match self.choice {
            ControllerChoice::Gmvc => Some(Law::Gmvc(self.gmvc)),
            ControllerChoice::Igmvc => Some(Law::Igmvc(self.igmvc)),
            ControllerChoice::Gpc => Some(Law::Gpc(self.gpc)),
            _ => None,
        }
    }

    /// Builds the controller for a loop sampled every `ts_s`, starting from duty `u0`: the
    /// board profile's ([`profile::controller`]), with this spec's tuning of the laws.
    pub fn build(&self, ts_s: f32, u0: f32) -> Result<AnyController> {
        let kind = self.choice.kind();
        let refused = |e| anyhow!("{:?}: configuration refused ({e:?})", self.choice);
        let (Some(profile_cfg), Some(law)) = (kind.adaptive(), self.law()) else {
            return profile::controller(kind, ts_s, u0).map_err(refused);
        };
        Ok(match self.model {
            Some(m) => AnyController::Fixed(FixedModel::new(law, m, u0)),
            None => {
                let initial = self.initial.or(profile_cfg.initial);
                let cfg = AdaptiveConfig {
                    law,
                    t_filter: self.gpc_t_filter,
                    initial,
                    // The estimator uses the start model's delay.
                    k: initial.map_or(profile_cfg.k, |m| m.k()),
                    ..profile_cfg
                };
                AnyController::SelfTuning(SelfTuning::new(cfg, ts_s, u0).map_err(refused)?)
            }
        })
    }
}

impl ControllerChoice {
    /// The board profile's kind.
    pub fn kind(self) -> Kind {
        match self {
            ControllerChoice::Onoff => Kind::OnOff,
            ControllerChoice::P => Kind::P,
            ControllerChoice::Pi => Kind::Pi,
            ControllerChoice::Gmvc => Kind::Gmvc,
            ControllerChoice::Igmvc => Kind::Igmvc,
            ControllerChoice::Gpc => Kind::Gpc,
        }
    }

    /// Builds the controller with default tuning (baselines only; model-based ones need a model).
    pub fn build(self, ts_s: f32) -> AnyController {
        match ControllerSpec::new(self).build(ts_s, 0.0) {
            Ok(c) => c,
            Err(_) => AnyController::Pi(profile::pi(ts_s)),
        }
    }
}

/// Which plant the controller drives.
// Chosen once per run: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlantChoice {
    /// H-TER I: aluminium container.
    Hter1,
    /// H-TER II: stainless-steel container.
    Hter2,
    /// An ideal ARX plant at the controller's sampling period (`--plant arx:A;B;K`).
    Arx(Model),
    /// The physical carrier with these parameters (a randomized `campaign` mission); the
    /// scenario's load override does not apply, the parameters carry their own water load.
    Custom(PlantParams),
}

impl PlantChoice {
    /// Parses `hter1`, `hter2` or `arx:A;B;K`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "hter1" => Ok(PlantChoice::Hter1),
            "hter2" => Ok(PlantChoice::Hter2),
            _ if s.starts_with("arx:") => Ok(PlantChoice::Arx(arx::parse(s)?)),
            _ => bail!("unknown plant '{s}' (expected hter1, hter2 or arx:A;B;K)"),
        }
    }

    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            PlantChoice::Hter1 => "H-TER I",
            PlantChoice::Hter2 => "H-TER II",
            PlantChoice::Arx(_) => "ARX model",
            PlantChoice::Custom(_) => "randomized carrier",
        }
    }
}

/// Everything a run needs.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// The scenario.
    pub scenario: Scenario,
    /// Controller.
    pub controller: ControllerSpec,
    /// Plant.
    pub plant: PlantChoice,
    /// Load (overridden by a scenario that fixes it).
    pub load: Load,
    /// Initial ambient temperature, °C.
    pub ambient_c: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Seed of the ADC noise.
    pub seed: u64,
    /// Injected hardware faults (time s, kind), any order.
    pub faults: Vec<(f64, Fault)>,
}

impl SimOptions {
    /// `scenario` with `controller` as `hter sim` runs it without other flags: H-TER I, full
    /// load, 28 °C ambient, the scenario's own duration, noise seed 1, no faults.
    pub fn new(scenario: Scenario, controller: ControllerSpec) -> Self {
        Self {
            duration_s: scenario.duration_s,
            scenario,
            controller,
            plant: PlantChoice::Hter1,
            load: Load::Full,
            ambient_c: 28.0,
            seed: 1,
            faults: Vec::new(),
        }
    }
}

/// One control sample of a run (one CSV row).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Row {
    /// Sample time, s.
    pub t_s: f64,
    /// Setpoint in force, °C.
    pub setpoint_c: f64,
    /// Temperature the controller saw (filtered, calibrated), °C.
    pub temp_c: f64,
    /// Duty applied, [0, 1].
    pub duty: f64,
    /// Calibrated reading before the filter, °C (empty on a sensor fault).
    pub raw_temp_c: Option<f64>,
    /// True load temperature, °C.
    pub true_temp_c: f64,
    /// Ambient, °C.
    pub ambient_c: f64,
    /// Safety mode of the step.
    pub mode: &'static str,
    /// Raw RTD conversion the step received, counts (replayable through the step).
    pub counts: u32,
    /// Self-tuning estimate a1 (empty for other controllers).
    pub a1: Option<f32>,
    /// Self-tuning estimate a2.
    pub a2: Option<f32>,
    /// Self-tuning estimate b0.
    pub b0: Option<f32>,
    /// Self-tuning estimate b1.
    pub b1: Option<f32>,
    /// trace(P) of the estimator.
    pub trace_p: Option<f32>,
    /// Self-tuning mode (adaptive, frozen, fallback).
    pub adaptive_mode: Option<&'static str>,
    /// The board's alarm indicator (`hter::alarm::Indication`): off, not_in_control,
    /// out_of_range, unacknowledged.
    pub alarm: &'static str,
    /// The step's supply-enable output (the MCU's pin; the board's monostable gates it too).
    pub supply_enable: bool,
    /// The board's alarm hardware: true while the heartbeat monostable has expired (the MCU
    /// stopped stepping), whatever the MCU's own alarm pin says.
    pub alarm_hw: bool,
    /// The conversion an ideal ADC would have made of this sample, counts (no noise, no SSR
    /// switching disturbance, not rounded); not in the CSV.
    #[serde(skip)]
    pub ideal_counts: f64,
}

/// How the simulated board around the step is built (what `run` uses by default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoardOptions {
    /// Where in the SSR period the RTD is converted; [`SamplePhase::Synchronised`] also clears
    /// the duty of the conversion window, as the firmware does.
    pub sample_phase: SamplePhase,
}

impl BoardOptions {
    /// The reference board: synchronised conversions with cleared duties.
    pub const DEFAULT: BoardOptions = BoardOptions { sample_phase: SamplePhase::Synchronised };
}

/// A finished run.
pub struct SimOutput {
    /// The samples.
    pub rows: Vec<Row>,
    /// The metrics of the `--json` contract.
    pub metrics: SimMetrics,
    /// Sample period, s.
    pub ts_s: f64,
    /// What the simulated board stored in flash, in order, with the sample time (s) of each
    /// store: the history when the board's [`Recorder`] asks (hourly, at an alarm, after a
    /// reset) and the model at the board profile's [`ModelCadence`].
    pub stores: Vec<(f64, Save)>,
}

fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Normal => "normal",
        Mode::SensorFault => "sensor_fault",
        Mode::FreezeGuard => "freeze_guard",
        Mode::LimpHome => "limp_home",
    }
}

/// snake_case name of an event kind, as it appears in JSON and CSV ([`EventKind::name`]).
pub fn event_name(k: EventKind) -> &'static str {
    k.name()
}

fn is_fault(k: EventKind) -> bool {
    k.is_hardware_fault() || matches!(k, EventKind::Restarted(ResetCause::BrownOut | ResetCause::Watchdog))
}

/// Hardware faults `--fault KIND@T_S` injects (SPEC §3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// RTD lead broken.
    SensorOpen,
    /// RTD leads shorted.
    SensorShort,
    /// Converter repeats its last value.
    SensorStuck,
    /// Occasional large spikes.
    SensorSpikes,
    /// +1.5 °C calibration drift.
    SensorOffset,
    /// SSR output shorted.
    SsrStuckOn,
    /// SSR output open.
    SsrStuckOff,
    /// Supply drops from 12 to 9 V.
    SupplySag,
    /// Lid left open: 15 W extra heat.
    LidOpen,
    /// The MCU resets: all controller state is lost and the step restarts.
    Brownout,
    /// The supply-enable switch shorts: it conducts whatever it is told.
    SupplySwitchShort,
    /// The control loop hangs: the step is no longer called, the SSR timer keeps its last duty,
    /// the MCU's pins hold their levels; only the board's heartbeat monostable can stop cooling.
    FirmwareHang,
}

impl Fault {
    /// Every kind, with its CLI name.
    pub const ALL: [(&'static str, Fault); 12] = [
        ("sensor-open", Fault::SensorOpen),
        ("sensor-short", Fault::SensorShort),
        ("sensor-stuck", Fault::SensorStuck),
        ("sensor-spikes", Fault::SensorSpikes),
        ("sensor-offset", Fault::SensorOffset),
        ("ssr-stuck-on", Fault::SsrStuckOn),
        ("ssr-stuck-off", Fault::SsrStuckOff),
        ("supply-sag", Fault::SupplySag),
        ("lid-open", Fault::LidOpen),
        ("brownout", Fault::Brownout),
        ("supply-switch-short", Fault::SupplySwitchShort),
        ("firmware-hang", Fault::FirmwareHang),
    ];

    /// Parses `KIND@T_S`.
    pub fn parse(s: &str) -> Result<(f64, Fault)> {
        let (kind, t) =
            s.split_once('@').ok_or_else(|| anyhow::anyhow!("fault '{s}' must be KIND@T_S, e.g. sensor-open@1800"))?;
        let fault = Self::ALL.iter().find(|(n, _)| *n == kind).map(|(_, f)| *f).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|(n, _)| *n).collect();
            anyhow::anyhow!("unknown fault '{kind}' (expected one of {})", names.join(", "))
        })?;
        let t: f64 = t.parse().map_err(|_| anyhow::anyhow!("fault '{s}': time '{t}' is not a number"))?;
        if !(t.is_finite() && t >= 0.0) {
            bail!("fault '{s}': time must be a finite number of seconds ≥ 0");
        }
        Ok((t, fault))
    }
}

/// The step's clock for sim time `t_s`, ms: the board's monotonic millisecond clock, which
/// counts from boot and so cannot go negative; the pre-roll starts at sim time −[`PREROLL_S`],
/// so the clock is sim time + [`PREROLL_S`] (converted once per sample, rounded to the ms).
fn step_clock_ms(t_s: f64) -> u64 {
    ((t_s + PREROLL_S) * 1000.0).round() as u64
}

/// The simulated hardware: the physical carrier behind a simulated ADC and SSR, or an ideal
/// ARX plant read and driven directly.
// One Rig per run: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
enum Rig {
    Physical { plant: Box<Plant>, adc: SimAdc, ssr: SimSsr, board: Board },
    Arx(ArxPlant),
}

impl Rig {
    fn new(opts: &SimOptions) -> Result<(Rig, f64)> {
        let sc = &opts.scenario;
        let load = sc.load.unwrap_or(opts.load);
        let params = match opts.plant {
            PlantChoice::Hter1 => PlantParams::hter1(load),
            PlantChoice::Hter2 => PlantParams::hter2(load),
            PlantChoice::Custom(p) => p,
            PlantChoice::Arx(m) => {
                let t0 = match sc.start {
                    Start::Ambient => opts.ambient_c,
                    Start::Holding(t) => t,
                };
                let p = ArxPlant::at_steady_state(m, opts.ambient_c, t0)?;
                return Ok((Rig::Arx(p), 0.0));
            }
        };
        let (plant, u0) = match sc.start {
            Start::Ambient => (Plant::at_ambient(params, opts.ambient_c), 0.0),
            Start::Holding(t) => match Plant::at_load_temperature(params, opts.ambient_c, t) {
                Some(p) => p,
                None => bail!("the plant cannot hold {t} °C at {} °C ambient", opts.ambient_c),
            },
        };
        let adc = SimAdc::new(opts.seed);
        Ok((Rig::Physical { plant: Box::new(plant), adc, ssr: SimSsr::new(), board: Board::new() }, u0))
    }

    /// Samples the sensor and runs the step; returns its output and the counts it got.
    /// The step runs on the board's clock, [`step_clock_ms`].
    fn step<C: Controller>(&mut self, carrier: &mut Carrier<C>, t_s: f64, w: f64) -> (StepOutput, u32) {
        match self {
            Rig::Physical { plant, adc, ssr, .. } => {
                adc.set_temperature_c(plant.sensed_temp_c());
                // The board's divider on the module supply rail, and the sense after the switch.
                carrier.observe_supply_v(plant.supply_v() as f32);
                carrier.observe_switched_rail_v(ssr.switched_rail_v(plant.supply_v()) as f32);
                let counts = match adc.sample() {
                    Ok(c) => c,
                    Err(never) => match never {},
                };
                (carrier.step(&StepInput { t_ms: step_clock_ms(t_s), counts, setpoint_c: w as f32 }), counts)
            }
            Rig::Arx(p) => (carrier.step_celsius(step_clock_ms(t_s), Celsius(p.temp_c() as f32), w as f32), 0),
        }
    }

    /// Drives the actuator at `t_s`; returns the duty the plant really gets.
    fn actuate(&mut self, out: &StepOutput, t_s: f64) -> f64 {
        match self {
            Rig::Physical { ssr, adc, board, .. } => {
                let duty = match adc.phase {
                    SamplePhase::Synchronised => adc.window.clear_duty(out.duty),
                    SamplePhase::EdgeAligned => out.duty,
                };
                // SimSsr's error type is Infallible.
                let _ = apply_duty(ssr, duty);
                board.supply_pin = out.supply_enable;
                // A completed step: the heartbeat toggles, the monostable restarts.
                board.beat(t_s);
                ssr.set_supply_enabled(board.supply_on(t_s));
                ssr.effective_duty()
            }
            Rig::Arx(_) => {
                if out.supply_enable {
                    f64::from(out.duty.get())
                } else {
                    0.0
                }
            }
        }
    }

    /// Advances one sample period from `t_s` at duty `d` (on the physical rig: the SSR's duty
    /// behind the supply switch, whose gate the monostable may open in any PWM period) in PWM
    /// periods; returns SSR turn-ons.
    fn advance(&mut self, t_s: f64, d: f64, ts: f64, last_on: &mut bool, count: bool) -> u64 {
        let periods = match self {
            Rig::Physical { .. } => (ts / PWM_PERIOD_S).round() as usize,
            Rig::Arx(_) => 1,
        };
        let mut switches = 0;
        for i in 0..periods {
            let d = match self {
                Rig::Physical { ssr, board, .. } => {
                    let t = t_s + i as f64 * PWM_PERIOD_S;
                    ssr.set_supply_enabled(board.supply_on(t));
                    ssr.effective_duty()
                }
                Rig::Arx(_) => d,
            };
            if count && d > 0.0 && !*last_on {
                switches += 1;
            }
            *last_on = d >= 1.0;
            if let Rig::Physical { plant, adc, .. } = self {
                plant.advance_pwm_period(PWM_PERIOD_S, d);
                adc.set_ssr_duty(d);
            }
        }
        if let Rig::Arx(p) = self {
            p.advance(d);
        }
        switches
    }

    fn true_temp_c(&self) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.load_temp_c(),
            Rig::Arx(p) => p.temp_c(),
        }
    }

    fn ambient_c(&self, default: f64) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.ambient_c(),
            Rig::Arx(_) => default,
        }
    }

    fn energy_wh(&self) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.energy_wh(),
            Rig::Arx(_) => 0.0,
        }
    }

    fn inject(&mut self, f: Fault) {
        if let Rig::Physical { plant, adc, ssr, .. } = self {
            match f {
                Fault::SensorOpen => adc.fault = SensorFault::Open,
                Fault::SensorShort => adc.fault = SensorFault::Short,
                Fault::SensorStuck => adc.fault = SensorFault::Stuck,
                Fault::SensorSpikes => adc.fault = SensorFault::Spikes,
                Fault::SensorOffset => adc.fault = SensorFault::Offset(1.5),
                Fault::SsrStuckOn => ssr.fault = SsrFault::StuckOn,
                Fault::SsrStuckOff => ssr.fault = SsrFault::StuckOff,
                Fault::SupplySag => plant.set_supply_v(9.0),
                Fault::LidOpen => plant.set_extra_heat_w(15.0),
                Fault::SupplySwitchShort => ssr.switch_shorted = true,
                // The run loop handles these: they stop or restart the step.
                Fault::Brownout | Fault::FirmwareHang => {}
            }
        }
    }

    fn change(&mut self, c: Change) {
        if let Rig::Physical { plant, .. } = self {
            match c {
                Change::Ambient(a) => plant.set_ambient_c(a),
                Change::ExtraHeat(w) => plant.set_extra_heat_w(w),
                Change::Supply(v) => plant.set_supply_v(v),
            }
        }
    }

    /// When the alarm hardware sounds at `t_s` (the monostable has expired), the time it
    /// began; `None` while the board is healthy or on an ideal plant without a board.
    fn alarm_hw_since(&self, t_s: f64) -> Option<f64> {
        match self {
            Rig::Physical { board, .. } if !board.mono.is_running(t_s) => board.mono.expiry_s().or(Some(t_s)),
            _ => None,
        }
    }

    /// The ideal conversion of the last sample, counts (0 on an ideal plant).
    fn ideal_counts(&self) -> f64 {
        match self {
            Rig::Physical { adc, .. } => adc.ideal_counts_last(),
            Rig::Arx(_) => 0.0,
        }
    }

    /// Advances one sample period at duty `d` before the run (the board not yet involved).
    fn settle(&mut self, d: f64, ts: f64) {
        match self {
            Rig::Physical { plant, .. } => {
                for _ in 0..(ts / PWM_PERIOD_S).round() as usize {
                    plant.advance_pwm_period(PWM_PERIOD_S, d);
                }
            }
            Rig::Arx(p) => p.advance(d),
        }
    }

    /// The duty the modules get at `t_s` with the SSR and the pins as they are (the monostable
    /// gating the supply switch); 0 on an ideal plant, which has no board to hang.
    fn gated_duty(&mut self, t_s: f64) -> f64 {
        match self {
            Rig::Physical { ssr, board, .. } => {
                ssr.set_supply_enabled(board.supply_on(t_s));
                ssr.effective_duty()
            }
            Rig::Arx(_) => 0.0,
        }
    }

    fn set_sample_phase(&mut self, phase: SamplePhase) {
        if let Rig::Physical { adc, .. } = self {
            adc.phase = phase;
        }
    }
}

/// The board's fail-safe hardware around the MCU: the supply-enable pin's last level, the
/// heartbeat output and the monostable it feeds, which gates the supply switch.
#[derive(Clone, Debug)]
struct Board {
    supply_pin: bool,
    heartbeat: Heartbeat,
    mono: Monostable,
}

impl Board {
    fn new() -> Self {
        Board { supply_pin: true, heartbeat: Heartbeat::new(), mono: Monostable::new(Monostable::TIMEOUT_S) }
    }

    /// Whether the supply switch conducts at `t_s`: the MCU's pin, ANDed with the monostable.
    fn supply_on(&self, t_s: f64) -> bool {
        self.supply_pin && self.mono.is_running(t_s)
    }

    /// One healthy step at `t_s`: the heartbeat toggles, and its edge retriggers the monostable.
    fn beat(&mut self, t_s: f64) {
        let before = self.heartbeat.level();
        if self.heartbeat.beat(true) != before {
            self.mono.trigger(t_s);
        }
    }
}

/// Runs a scenario on the reference board ([`BoardOptions::DEFAULT`]).
pub fn run(opts: &SimOptions) -> Result<SimOutput> {
    run_with(opts, &BoardOptions::DEFAULT)
}

/// Runs a scenario on a board built as `board` says.
pub fn run_with(opts: &SimOptions, board: &BoardOptions) -> Result<SimOutput> {
    if !(opts.ambient_c.is_finite() && (-10.0..=50.0).contains(&opts.ambient_c)) {
        bail!("ambient {} °C is outside the supported -10..50 °C", opts.ambient_c);
    }
    if !(opts.duration_s.is_finite() && opts.duration_s > 0.0 && opts.duration_s <= 90.0 * 86400.0) {
        bail!("duration {} s must be positive and at most 90 days", opts.duration_s);
    }
    let sc = &opts.scenario;
    let mut cfg = CarrierConfig::DEFAULT;
    if let PlantChoice::Arx(_) = opts.plant {
        // Ideal measurement: no filter between the model's output and the controller.
        cfg.filter.fa = 0.0;
    }
    if sc.excitation {
        // As the identification build: no supply-switch test opening in the record.
        cfg.switch_test_interval_samples = 0;
    }
    let ts = f64::from(cfg.ts_s);
    let (mut rig, u0) = Rig::new(opts)?;
    rig.set_sample_phase(board.sample_phase);
    if sc.excitation {
        // The averaged steady state is not exactly the switched one: let the plant settle at
        // the holding duty for two hours (the slowest mode is ≈ 30 min) so the identification
        // record starts without a drift the input does not explain.
        for _ in 0..(7200.0 / ts) as usize {
            rig.settle(u0, ts);
        }
    }
    // What the board keeps in flash, stored when the firmware stores it: the trusted model at
    // the profile's cadence (as the same record bytes), the cold-chain history when the
    // board's record asks.
    let model_cadence = || ModelCadence::new(profile::samples(profile::MODEL_SAVE_S, cfg.ts_s));
    let mut cadence = model_cadence();
    let mut persisted: Option<[u8; ModelRecord::LEN]> = None;
    let mut stores = Vec::new();
    let make_controller = |persisted: Option<&[u8; ModelRecord::LEN]>| -> Result<AnyController> {
        Ok(if sc.excitation {
            let prbs =
                PrbsConfig { bits: 7, hold: 12, low: (u0 - 0.1).max(0.0) as f32, high: (u0 + 0.1).min(1.0) as f32 };
            // The log begins with the last of the settling at the holding duty, as an engineer
            // logs the rest before starting the PRBS: the identification's operating point.
            let rest = (PRBS_REST_S / ts).round() as u32;
            AnyController::Prbs(
                PrbsExcitation::after_rest(prbs, u0 as f32, rest).map_err(|e| anyhow::anyhow!("PRBS: {e:?}"))?,
            )
        } else {
            let mut spec = opts.controller;
            let stainless = match opts.plant {
                PlantChoice::Hter2 => true,
                PlantChoice::Custom(p) => p.container == crate::plant::Container::StainlessSteel,
                _ => false,
            };
            if spec.initial.is_none() && stainless {
                spec.initial = Some(profile::START_MODEL_HTER2);
            }
            // After a reset: the stored model, if it decodes and is still plausible for this law
            // (else the built-in start model, as on the board).
            if let (Some(bytes), Some(check)) = (persisted, spec.choice.kind().adaptive()) {
                if let Ok(m) = ModelRecord::decode(bytes).and_then(|r| r.to_model(&check)) {
                    spec.initial = Some(m);
                }
            }
            spec.build(cfg.ts_s, u0 as f32)?
        })
    };
    let mut carrier = Carrier::new(cfg, make_controller(None)?);
    let faults_pending = &opts.faults;
    let name = carrier.controller().name().to_string();

    // Pre-roll: the loop has been holding the initial temperature for an hour.
    let preroll = match (sc.start, opts.plant) {
        _ if sc.excitation => 0,
        (Start::Holding(_), PlantChoice::Hter1 | PlantChoice::Hter2 | PlantChoice::Custom(_)) => {
            (PREROLL_S / ts).round() as i64
        }
        _ => 0,
    };
    let n = (opts.duration_s / ts).round() as i64;
    let mut rows = Vec::with_capacity(n as usize);
    let mut faults = Vec::new();
    let mut switches = 0u64;
    let mut last_on = false;
    let mut next_change = 0;
    let mut energy0_wh = 0.0;
    // The carrier's own record and alarm indicator, fed as the firmware feeds them: the
    // monitor sees what the sensor saw. A brown-out counts the reset in the record and stores
    // it, as the board's boot does; the simulated monitor runs on through it, where the board's
    // restarts from the stored history.
    let mut recorder = Recorder::new(HistoryRecord::EMPTY, profile::samples(profile::HISTORY_SAVE_S, cfg.ts_s));
    let mut alarms = Vec::new();
    let mut annunciator = Annunciator::new();
    let (mut alarm_on_s, mut alarm_first_s) = (0.0, None);
    // The step has stopped being called (`firmware-hang`); what the hung MCU's pins still show.
    let mut hung = false;
    let mut alarm_hw_first_s: Option<f64> = None;
    let mut held: Option<(StepOutput, u32, Indication)> = None;
    for k in -preroll..n {
        let t_s = k as f64 * ts;
        while k >= 0 && next_change < sc.changes.len() && sc.changes[next_change].0 <= t_s {
            rig.change(sc.changes[next_change].1);
            next_change += 1;
        }
        if k >= 0 {
            for &(_, f) in faults_pending.iter().filter(|(ft, _)| *ft <= t_s && *ft > t_s - ts) {
                if f == Fault::FirmwareHang {
                    hung = true;
                } else if f == Fault::Brownout {
                    // The reset ends a hang too.
                    hung = false;
                    // RAM lost: a fresh step, restarted from what flash holds.
                    carrier = Carrier::new(cfg, make_controller(persisted.as_ref())?);
                    // What the firmware reads from RCC_CSR at boot after a brown-out.
                    carrier.note_reset(ResetCause::BrownOut);
                    cadence = model_cadence();
                    stores.push((t_s, Save::History(recorder.note_reset(ResetCause::BrownOut))));
                    // The indicator's latch is RAM too.
                    annunciator = Annunciator::new();
                } else {
                    rig.inject(f);
                }
            }
        }
        let w = if k >= 0 { sc.setpoint_at(t_s) } else { sc.setpoint_at(0.0) };
        if hung {
            // ---- hung control loop: no step, no actuation, no beat ----
            let duty = rig.gated_duty(t_s);
            switches += rig.advance(t_s, 0.0, ts, &mut last_on, true);
            let alarm_hw = rig.alarm_hw_since(t_s);
            if let (Some(at), None) = (alarm_hw, alarm_hw_first_s) {
                alarm_hw_first_s = Some(at);
                faults.push(Stamped { kind: "firmware_hang".into(), t_s: at });
            }
            let (out, counts, indication) =
                held.as_ref().map_or((None, 0, Indication::Off), |(o, c, i)| (Some(o), *c, *i));
            if indication.is_on() {
                alarm_on_s += ts;
            }
            rows.push(Row {
                t_s,
                setpoint_c: w,
                temp_c: out.map_or(f64::NAN, |o| f64::from(o.temp_c.0)),
                duty,
                raw_temp_c: None,
                true_temp_c: rig.true_temp_c(),
                ambient_c: rig.ambient_c(opts.ambient_c),
                mode: "hung",
                counts,
                a1: None,
                a2: None,
                b0: None,
                b1: None,
                trace_p: None,
                adaptive_mode: None,
                alarm: indication.name(),
                supply_enable: out.is_some_and(|o| o.supply_enable),
                alarm_hw: alarm_hw.is_some(),
                ideal_counts: f64::NAN,
            });
            continue;
        }
        let (out, counts) = rig.step(&mut carrier, t_s, w);
        if let Some(rec) = cadence.push(out.status.map(|st| st.mode), carrier.controller()) {
            persisted = Some(rec.encode());
            stores.push((t_s, Save::Model(rec)));
        }
        let d = rig.actuate(&out, t_s);
        if k >= 0 {
            for e in out.events.iter().filter(|e| is_fault(e.kind)) {
                faults.push(Stamped { kind: event_name(e.kind).into(), t_s: e.t_s() - PREROLL_S });
            }
            let recorded = recorder.push(step_clock_ms(t_s), out.temp_c.0);
            if let Some(save) = recorder.due_save(&recorded) {
                stores.push((t_s, save));
            }
            let raised = recorded.raised;
            for a in raised.iter().flatten() {
                alarms.push(Stamped { kind: a.kind.name().into(), t_s: a.trigger_s() - PREROLL_S });
            }
            let indication = annunciator.update(&out, &raised);
            if indication.is_on() {
                alarm_on_s += ts;
                alarm_first_s.get_or_insert(t_s);
            }
            rows.push(Row {
                t_s,
                setpoint_c: w,
                temp_c: f64::from(out.temp_c.0),
                duty: d,
                raw_temp_c: out.raw_c.map(|c| f64::from(c.0)),
                true_temp_c: rig.true_temp_c(),
                ambient_c: rig.ambient_c(opts.ambient_c),
                mode: mode_name(out.mode),
                counts,
                a1: out.status.map(|st| st.theta[0]),
                a2: out.status.map(|st| st.theta[1]),
                b0: out.status.map(|st| st.theta[2]),
                b1: out.status.map(|st| st.theta[3]),
                trace_p: out.status.map(|st| st.trace_p),
                adaptive_mode: out.status.map(|st| match st.mode {
                    AdaptiveMode::Adaptive => "adaptive",
                    AdaptiveMode::Frozen => "frozen",
                    AdaptiveMode::Fallback => "fallback",
                }),
                alarm: indication.name(),
                supply_enable: out.supply_enable,
                alarm_hw: rig.alarm_hw_since(t_s).is_some(),
                ideal_counts: rig.ideal_counts(),
            });
            held = Some((out, counts, indication));
        }
        if k == 0 {
            energy0_wh = rig.energy_wh();
        }
        switches += rig.advance(t_s, d, ts, &mut last_on, k >= 0);
    }
    let samples: Vec<Sample> =
        rows.iter().map(|r| Sample { t_s: r.t_s, setpoint_c: r.setpoint_c, true_temp_c: r.true_temp_c }).collect();
    let f = metrics::tracking(&samples, ts);
    let metrics = SimMetrics {
        controller: name,
        iae: f.iae,
        max_abs_error_after_settle_c: f.max_abs_error_after_settle_c,
        steady_state_error_c: f.steady_state_error_c,
        overshoot_c: f.overshoot_c,
        settle_time_s: f.settle_time_s,
        min_temp_c: f.min_temp_c,
        max_temp_c: f.max_temp_c,
        time_outside_2_8_s: f.time_outside_2_8_s,
        energy_wh: rig.energy_wh() - energy0_wh,
        ssr_switches: switches,
        alarms,
        faults_detected: faults,
        alarm_indicator_s: alarm_on_s,
        alarm_indicator_first_s: alarm_first_s,
        alarm_hw_first_s,
    };
    Ok(SimOutput { rows, metrics, ts_s: ts, stores })
}
