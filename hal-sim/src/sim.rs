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
//! sample; the heartbeat pulses once per completed step (the firmware's `board::heartbeat_pulse`)
//! into the board's [`crate::periph::Monostable`], whose expiry opens the supply switch and sounds the
//! alarm hardware (`alarm_hw`): the only thing that stops cooling when the step stops being
//! called (`--fault firmware-hang@T`).
//!
//! Rooms: this file holds the run's options and the loop; `rig` the simulated hardware and
//! the board glue around the step; `row` the CSV row; [`crate::fault`] the fault table.

use anyhow::{anyhow, bail, Result};
use hter::alarm::{Annunciator, Indication};
use hter::app::Boot;
use hter::control::adaptive::{AdaptiveConfig, SelfTuning};
use hter::control::excite::PrbsExcitation;
use hter::control::gpc::GpcConfig;
use hter::control::mv::{GmvcConfig, IgmvcConfig};
use hter::control::Controller;
use hter::control::{AnyController, FixedModel, Law, Pi, PiConfig};
use hter::event::EventKind;
use hter::failsafe::{StopKind, Stops};
use hter::ident::prbs::PrbsConfig;
use hter::model::Model;
use hter::persist::{HistoryRecord, ModelCadence, ModelRecord, Recorder, ResetCause, Save};
use hter::profile::{self, Kind};
use hter::step::{Carrier, CarrierConfig, StepOutput};

use crate::arx;
use crate::fault;
pub use crate::fault::Fault;
use crate::metrics::{self, Detected, Holdover, Sample, SimMetrics, Stamped};
pub use crate::periph::SamplePhase;
pub use crate::plant::Drive;
use crate::plant::{Load, PlantParams};
use crate::scenario::{PowerCut, Scenario, Start, PREROLL_S};

mod rig;
mod row;
pub mod virtual_board;

use rig::{step_clock_ms, Rig};
pub use row::{Row, RowMode};

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
    /// PI with anti-windup, tuned for each carrier (H-TER I: Ziegler–Nichols detuned ×2;
    /// H-TER II: SIMC; `--kp`, `--ti`).
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
    /// Self-tuning laws: the first approach's lead (`hter::control::adaptive`, "The first
    /// approach"); false only to measure without it (`hter sim --no-approach-lead`).
    pub approach_lead: bool,
    /// Model the self-tuning laws start from; `None`: the one identified on the simulated
    /// carrier (`profile::START_MODEL_HTER1`, `START_MODEL_HTER2`), as a board starts from the
    /// model persisted from its own identification run.
    pub initial: Option<Model>,
    /// PI tuning (`--kp`, `--ti`); `None`: the carrier's own ([`PlantChoice::default_pi`]).
    /// Its bias is replaced by the plant's steady duty when the run starts holding a
    /// temperature, and by the board's boot duty (`profile::BOOT_DUTY`) from ambient and after
    /// a restart.
    pub pi: Option<PiConfig>,
    /// Model the holdover estimate runs on ([`hter::holdover`]); `None`: [`Self::initial`], or
    /// the carrier's start model. Set apart from `initial` for a model the self-tuner would not
    /// trust (`hter sim --commission monotone`).
    pub holdover: Option<Model>,
    /// `initial` is the model this self-tuner stored before a reset: the estimator resumes
    /// from it ([`AdaptiveConfig::resumed_from`]), as the board's boot does.
    pub resumed: bool,
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
            approach_lead: true,
            initial: None,
            pi: None,
            holdover: None,
            resumed: false,
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
        if let (ControllerChoice::Pi, Some(pi)) = (self.choice, self.pi) {
            return Ok(AnyController::Pi(Pi::new(pi, ts_s)));
        }
        let (Some(profile_cfg), Some(law)) = (kind.adaptive(), self.law()) else {
            return profile::controller(kind, ts_s, u0).map_err(refused);
        };
        // Before the delay the step response is zero: a GPC horizon that ends there has no duty
        // act on any predicted sample and holds its first duty for good (the self-tuner's
        // configuration refuses it too, as `Law(Config)`: said here by name).
        let reaches = |k: usize| match law {
            Law::Gpc(g) if g.n2 < k => Err(anyhow!(
                "GPC's horizon N2 = {} ends before the model's delay k = {k}: no duty would act on \
                 any predicted sample (--n2 {k} or more)",
                g.n2
            )),
            _ => Ok(()),
        };
        Ok(match self.model {
            Some(m) => {
                reaches(m.k())?;
                AnyController::Fixed(FixedModel::new(law, m, u0))
            }
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
                let cfg = match initial {
                    Some(m) if self.resumed => cfg.resumed_from(m),
                    _ => cfg,
                };
                reaches(cfg.k)?;
                let mut c = SelfTuning::new(cfg, ts_s, u0).map_err(refused)?;
                if !self.approach_lead {
                    c.end_approach();
                }
                AnyController::SelfTuning(c)
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
    /// Parses `hter1`, `hter2` or `arx:A;B;K` (a stable, cooling model without C: [`arx::plant_model`]).
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "hter1" => Ok(PlantChoice::Hter1),
            "hter2" => Ok(PlantChoice::Hter2),
            _ if s.starts_with("arx:") => Ok(PlantChoice::Arx(arx::plant_model(s)?)),
            _ => bail!("unknown plant '{s}' (expected hter1, hter2 or arx:A;B;K)"),
        }
    }

    /// The PI tuned for this carrier ([`profile::PI`], Ziegler–Nichols detuned;
    /// [`profile::PI_HTER2`], SIMC): the stainless-steel carrier's for H-TER II and a stainless
    /// custom carrier, H-TER I's otherwise (an ARX plant has no carrier of its own).
    pub fn default_pi(&self) -> PiConfig {
        match self {
            PlantChoice::Hter2 => profile::PI_HTER2,
            PlantChoice::Custom(p) if p.container == crate::plant::Container::StainlessSteel => profile::PI_HTER2,
            _ => profile::PI,
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
    /// How the modules are driven (`--drive`; the SSR by default); ignored by an ideal ARX
    /// plant, which takes the duty as is.
    pub drive: Drive,
    /// The board reads the modules' voltage in the conversion window (`--module-sense`), a
    /// board change the reference board does not have ([`hter::supervisor::module`]); SSR
    /// drive only.
    pub module_sense: bool,
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
            drive: Drive::Ssr,
            module_sense: false,
        }
    }
}

impl SimOptions {
    /// The physical carrier this run drives, with the scenario's load and the run's drive;
    /// `None` for an ideal ARX plant.
    pub fn plant_params(&self) -> Option<PlantParams> {
        let load = self.scenario.load.unwrap_or(self.load);
        match self.plant {
            PlantChoice::Hter1 => Some(PlantParams { drive: self.drive, ..PlantParams::hter1(load) }),
            PlantChoice::Hter2 => Some(PlantParams { drive: self.drive, ..PlantParams::hter2(load) }),
            PlantChoice::Custom(p) => Some(PlantParams { drive: self.drive, ..p }),
            PlantChoice::Arx(_) => None,
        }
    }
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

/// The history the board's flash holds after `stores`: the last one stored (an alarm's
/// or a periodic store), or none yet.
fn last_history(stores: &[(f64, Save)]) -> HistoryRecord {
    stores
        .iter()
        .rev()
        .find_map(|(_, s)| match s {
            Save::History(h) | Save::AlarmHistory(h) => Some(*h),
            _ => None,
        })
        .unwrap_or(HistoryRecord::EMPTY)
}

/// What a boot finds after the fail-safe stop of an injected board fault: a pin or software
/// reset, and that stop, new.
fn fresh_stop(kind: StopKind) -> (ResetCause, Stops) {
    (ResetCause::Other, Stops { earlier: None, latest: Some(fault::stop_info(kind)), fresh: true })
}

/// The one-line error of a refused carrier configuration.
fn config_refused(e: hter::step::ConfigError) -> anyhow::Error {
    anyhow!("the carrier configuration is refused: {e}")
}

/// Runs a scenario on the reference board ([`BoardOptions::DEFAULT`]).
pub fn run(opts: &SimOptions) -> Result<SimOutput> {
    run_with(opts, &BoardOptions::DEFAULT)
}

/// Runs a scenario on a board built as `board` says.
pub fn run_with(opts: &SimOptions, board: &BoardOptions) -> Result<SimOutput> {
    let (amb_lo, amb_hi) = crate::scenario::AMBIENT_RANGE_C;
    if !(opts.ambient_c.is_finite() && (amb_lo..=amb_hi).contains(&opts.ambient_c)) {
        bail!("ambient {} °C is outside the supported {amb_lo}..{amb_hi} °C", crate::sim_cmd::shown(opts.ambient_c));
    }
    if !(opts.duration_s.is_finite() && opts.duration_s > 0.0 && opts.duration_s <= 90.0 * 86400.0) {
        bail!("duration {} s must be positive and at most 90 days", crate::sim_cmd::shown(opts.duration_s));
    }
    let sc = &opts.scenario;
    let mut cfg = CarrierConfig::DEFAULT;
    if opts.drive == Drive::Buck {
        // As the firmware's `buck` build.
        cfg.supervisor = hter::supervisor::SupervisorConfig::BUCK;
    }
    if let PlantChoice::Arx(_) = opts.plant {
        // Ideal measurement: no filter between the model's output and the controller.
        cfg.filter.fa = 0.0;
    }
    if sc.excitation {
        // As the identification build: no supply-switch test pulse in the record.
        cfg.supervisor.switch.test_interval_s = 0.0;
    }
    let valid = cfg.validated().map_err(config_refused)?;
    let ts = f64::from(cfg.ts_s);
    // Shorter than one sample, the run has no sample: it reported IAE 0, settled at 0 s and a
    // temperature range of inf…−inf.
    if opts.duration_s < ts {
        bail!("duration {} s is shorter than one control sample (Ts = {ts} s)", crate::sim_cmd::shown(opts.duration_s));
    }
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
    let stainless = match opts.plant {
        PlantChoice::Hter2 => true,
        PlantChoice::Custom(p) => p.container == crate::plant::Container::StainlessSteel,
        _ => false,
    };
    // `boot`: built by a restart's boot, which starts the law from the board's boot duty
    // (`profile::BOOT_DUTY`, the fallback PI's bias: `profile::SelfTuningOrPi::new`, `App::new`),
    // not from the run's start duty. A run from ambient starts as a board's power-up does, from
    // the boot duty too; one holding a temperature starts bumplessly from the duty that holds it.
    let make_controller = |persisted: Option<&[u8; ModelRecord::LEN]>, boot: bool| -> Result<AnyController> {
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
            if spec.initial.is_none() && stainless {
                spec.initial = Some(profile::START_MODEL_HTER2);
            }
            let pi = spec.pi.unwrap_or_else(|| opts.plant.default_pi());
            let bias = match sc.start {
                Start::Holding(_) if !boot => u0 as f32,
                _ => profile::BOOT_DUTY,
            };
            spec.pi = Some(PiConfig { bias, ..pi });
            // After a reset: the stored model, if it decodes and is still plausible for this law
            // (else the built-in start model, as on the board).
            if let (Some(bytes), Some(check)) = (persisted, spec.choice.kind().adaptive()) {
                if let Ok(m) = ModelRecord::decode(bytes).and_then(|r| r.to_model(&check)) {
                    spec.initial = Some(m);
                    spec.resumed = true;
                }
            }
            spec.build(cfg.ts_s, bias)?
        })
    };
    // The holdover runs on the model the carrier was commissioned with: the start model of its
    // container, as the board's stored model.
    let holdover_model = Some(match opts.controller.holdover.or(opts.controller.initial) {
        Some(m) => m,
        None if stainless => profile::START_MODEL_HTER2,
        None => profile::START_MODEL_HTER1,
    });
    let new_carrier = |c: AnyController| {
        let mut carrier = Carrier::new(valid, c);
        carrier.set_holdover_model(holdover_model);
        carrier
    };
    let mut carrier = new_carrier(make_controller(None, false)?);
    let faults_pending = &opts.faults;
    let name = carrier.controller().name().to_string();

    // Pre-roll: the loop has been holding the initial temperature, its first setpoint, for an
    // hour. A start at another temperature is the plant's steady state there, as the bound's
    // ([`prerolled`]).
    let preroll = match (sc.start, opts.plant) {
        _ if sc.excitation => 0,
        (Start::Holding(_), PlantChoice::Hter1 | PlantChoice::Hter2 | PlantChoice::Custom(_)) if prerolled(sc) => {
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
    // The time the energy is counted over: the whole run, or up to the sample a power cut's
    // run ends at (`power-cut` ends hours before its 50 h duration, once the load passes 8 °C).
    let mut energy_s = n as f64 * ts;
    // The carrier's own record and alarm indicator, fed as the firmware feeds them: the
    // monitor sees what the sensor saw. A brown-out restarts the record from the history last
    // stored, as the board's boot does (what came after that store is lost with the RAM; an
    // alarm's run goes on from where the store left it), then counts the reset and stores it.
    let history_every = profile::samples(profile::HISTORY_SAVE_S, cfg.ts_s);
    let mut recorder = Recorder::new(HistoryRecord::EMPTY, history_every);
    let mut alarms = Vec::new();
    let mut annunciator = Annunciator::new();
    let (mut alarm_on_s, mut alarm_first_s) = (0.0, None);
    // The step has stopped being called (`firmware-hang`); what the hung MCU's pins still show.
    let mut hung = false;
    // A control stall (`board-fault-control-stall`): the sample at which the glue's stall check
    // has stopped the hung loop and reset the board ([`hter::failsafe::STALL_SAMPLES`] sample
    // periods after the last completed step, the one before the stall: the loop misses one
    // sample fewer than that).
    let mut stall_stop: Option<i64> = None;
    let mut alarm_hw_first_s: Option<f64> = None;
    let mut freeze_guard_trips = 0u32;
    let mut held: Option<(StepOutput, u32, Indication)> = None;
    for k in -preroll..n {
        let t_s = k as f64 * ts;
        while k >= 0 && next_change < sc.changes.len() && sc.changes[next_change].0 <= t_s {
            rig.change(sc.changes[next_change].1);
            next_change += 1;
        }
        // Whether the loop was hung up to this sample (a reset below may end it).
        let was_hung = hung;
        if k >= 0 {
            let mut restart = None;
            for &(_, f) in faults_pending.iter().filter(|(ft, _)| *ft <= t_s && *ft > t_s - ts) {
                match f {
                    Fault::FirmwareHang => hung = true,
                    // What the firmware reads from RCC_CSR at boot after a brown-out; RAM lost,
                    // so no stop record crosses it.
                    Fault::Brownout => restart = Some((ResetCause::BrownOut, Stops::default())),
                    Fault::BoardFault(StopKind::ControlStall) => {
                        hung = true;
                        stall_stop = Some(k + i64::from(hter::failsafe::STALL_SAMPLES) - 1);
                    }
                    // The stop path's record crosses the reset (a pin or software reset).
                    Fault::BoardFault(kind) => restart = Some(fresh_stop(kind)),
                    f => rig.inject(f),
                }
            }
            if stall_stop == Some(k) {
                restart = Some(fresh_stop(StopKind::ControlStall));
            }
            if let Some((reset, stops)) = restart {
                // The reset ends a hang too.
                hung = false;
                stall_stop = None;
                // RAM lost: a fresh step, restarted from what flash holds, as the board's boot
                // restarts it (`Boot::resume`: the reset and the stops reported with the first
                // sample and counted in the history; the indicator's latch, the sensor offset and
                // a shorted SSR from the stored history).
                carrier = new_carrier(make_controller(persisted.as_ref(), true)?);
                cadence = model_cadence();
                let history = last_history(&stores);
                recorder = Recorder::new(history, history_every);
                let boot = Boot { history, reset, stops, ..Boot::NEW };
                let stored = boot.resume(&mut carrier, &mut recorder);
                stores.push((t_s, boot.history_save(stored)));
                annunciator = Annunciator::restored(&stored);
            }
        }
        let w = if k >= 0 { sc.setpoint_at(t_s) } else { sc.setpoint_at(0.0) };
        // The monostable lapsed since the last beat: a hung loop, or a stall that a stop and a
        // reset ended after the lapse (the boot's first step beats again).
        if let (true, Some(at), None) = (was_hung || hung, rig.alarm_hw_since(t_s), alarm_hw_first_s) {
            alarm_hw_first_s = Some(at);
            faults.push(Stamped { kind: Detected::FirmwareHang, t_s: at });
        }
        if hung {
            // ---- hung control loop: no step, no actuation, no beat ----
            let duty = rig.gated_duty(t_s);
            switches += rig.advance(t_s, 0.0, ts, &mut last_on, true);
            let last = held.as_ref();
            if last.is_some_and(|(_, _, i)| i.is_on()) {
                alarm_on_s += ts;
            }
            let view = row::RigView { ideal_counts: f64::NAN, ..rig.view(t_s, opts.ambient_c) };
            rows.push(Row::hung(t_s, w, last, duty, view));
            continue;
        }
        let (out, sensed) = rig.step(&mut carrier, t_s, w);
        if let Some(rec) = cadence.push(out.status.map(|st| st.mode), carrier.controller()) {
            persisted = Some(rec.encode());
            stores.push((t_s, Save::Model(rec)));
        }
        let d = rig.actuate(&out, t_s);
        if k >= 0 {
            for e in out.events.iter().filter(|e| fault::is_reported(e.kind)) {
                faults.push(Stamped { kind: Detected::Event(e.kind), t_s: e.t_s() - PREROLL_S });
            }
            let trips = out.events.iter().filter(|e| e.kind == EventKind::FreezeGuardTripped).count();
            freeze_guard_trips = freeze_guard_trips.saturating_add(trips as u32);
            let mut recorded = recorder.push(step_clock_ms(t_s), out.recorded_c());
            let raised = recorded.raised;
            for a in raised.iter().flatten() {
                alarms.push(Stamped { kind: a.kind, t_s: a.trigger_s() - PREROLL_S });
            }
            let indication = annunciator.update(&out, &raised);
            recorder.note_carried(&mut recorded, annunciator.latched(), carrier.sensor_offset(), carrier.ssr_shorted());
            if let Some(save) = recorder.due_save(&recorded) {
                stores.push((t_s, save));
            }
            if indication.is_on() {
                alarm_on_s += ts;
                alarm_first_s.get_or_insert(t_s);
            }
            rows.push(Row::stepped(t_s, w, &out, sensed, d, indication, rig.view(t_s, opts.ambient_c)));
            held = Some((out, sensed.0, indication));
            if sc.cut.is_some_and(|c| c.passed(t_s, rig.true_temp_c())) {
                energy_s = t_s;
                break;
            }
        }
        if k == 0 {
            energy0_wh = rig.energy_wh();
        }
        switches += rig.advance(t_s, d, ts, &mut last_on, k >= 0);
    }
    let samples: Vec<Sample> =
        rows.iter().map(|r| Sample { t_s: r.t_s, setpoint_c: r.setpoint_c, true_temp_c: r.true_temp_c }).collect();
    let metrics = SimMetrics {
        controller: name,
        tracking: metrics::tracking(&samples, ts),
        energy_wh: rig.energy_wh() - energy0_wh,
        mean_power_w: metrics::mean_power_w(rig.energy_wh() - energy0_wh, energy_s),
        ssr_switches: switches,
        alarms,
        faults_detected: faults,
        freeze_guard_trips,
        alarm_indicator_s: alarm_on_s,
        alarm_indicator_first_s: alarm_first_s,
        alarm_hw_first_s,
        holdover: sc.cut.map(|c| holdover(&rows, c)),
    };
    Ok(SimOutput { rows, metrics, ts_s: ts, stores })
}

/// Whether a run of `sc` on a physical plant starts from a closed-loop pre-roll: it starts
/// holding its first setpoint ([`Start::Holding`] at `setpoint_at(0)`, every built-in that
/// holds), so each controller starts from its own steady state. A start at another temperature
/// (a scenario file's `start_c`) is the plant's steady state at the duty that holds it, the
/// controller starting at that duty, as on an ARX plant: the pre-roll held the first setpoint,
/// so `start_c` 20 with a 4 °C setpoint started at 4 °C, while the bound ([`crate::bound`])
/// started from 20 °C and On-Off "beat" it. From that state the bound and the run start alike.
pub fn prerolled(sc: &Scenario) -> bool {
    matches!(sc.start, Start::Holding(t) if t == sc.setpoint_at(0.0))
}

/// The holdover of a power-cut run: the step's estimate at the last sample before the cut, and
/// the time from the cut to the first sample whose true load temperature is above the limit
/// (`None` if the run ended first).
fn holdover(rows: &[Row], cut: PowerCut) -> Holdover {
    let predicted_s = rows.iter().take_while(|r| r.t_s < cut.at_s).last().and_then(|r| r.holdover_s);
    let actual_s = rows.iter().find(|r| cut.passed(r.t_s, r.true_temp_c)).map(|r| r.t_s - cut.at_s);
    Holdover { predicted_s, actual_s }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `power-cut` ends once the load passes 8 °C, ≈ 2 h 8 min in, not at its 50 h duration: its
    /// mean power is its energy over those 2 h 8 min. Over 50 h it read 1.13 W for a carrier
    /// that drew 56.6 Wh holding 4 °C for 2 h (26.5 W; H-TER I holds 4 °C at 28 °C on ≈ 28 W,
    /// `piecewise`'s 27.8 Wh in 1 h).
    #[test]
    fn a_power_cuts_mean_power_is_over_the_run_it_made() {
        let sc = Scenario::resolve("power-cut").unwrap();
        let full_s = sc.duration_s;
        let out = run(&SimOptions::new(sc, ControllerSpec::new(ControllerChoice::Gpc))).unwrap();
        let end_s = out.rows.last().unwrap().t_s;
        assert!(end_s < 3.0 * 3600.0 && end_s < full_s, "{end_s}");
        let m = &out.metrics;
        assert!(
            (m.mean_power_w - m.energy_wh * 3600.0 / end_s).abs() < 1e-9,
            "{} W, {} Wh",
            m.mean_power_w,
            m.energy_wh
        );
        assert!((20.0..35.0).contains(&m.mean_power_w), "{} W", m.mean_power_w);
        // A run without a cut: over its whole duration, as before.
        let out =
            run(&SimOptions::new(Scenario::resolve("piecewise").unwrap(), ControllerSpec::new(ControllerChoice::Gpc)))
                .unwrap();
        assert!((out.metrics.mean_power_w - out.metrics.energy_wh).abs() < 1e-9, "1 h: W = Wh");
    }
}
