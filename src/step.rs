//! The per-sample application step: raw ADC counts (and time) in → temperature, duty, events out.
//!
//! [`Carrier`] is the whole application minus the peripherals. The firmware calls
//! [`Carrier::step`] once per sample period with the oversampled RTD counts and writes the
//! returned duty to the SSR timer and the supply-enable output; `hal-sim` does the same with its
//! simulated ADC and SSR. A trace of counts therefore reproduces a board's behaviour on the host.
//!
//! Pipeline per sample:
//! 1. **convert**: counts → ohms (ratiometric front end, [`crate::adc`]); ohms → °C
//!    (Callendar–Van Dusen, [`crate::rtd`]); two-point calibration ([`crate::calib`]); the
//!    faults the counts reveal (open, short, out of range, stuck:
//!    [`crate::supervisor::sensor`]);
//! 2. **check**: the [`crate::supervisor`]'s sensor checks (fault state, offset, spikes)
//!    decide what the first-order filter F_a ([`crate::filter`]) takes; the supply and the
//!    supply switch are checked;
//! 3. **control**: the setpoint clamped to the vaccine band 2…8 °C (a controller may never aim
//!    below +2 °C), then the controller ([`crate::control`]), with a trusted reading only;
//! 4. **guard**: the supervisor's freeze guard, SSR monitor, limp home and lid detector decide
//!    the duty and the supply-enable level, independent of what the controller wanted;
//! 5. **actuate**: the applied duty is fed back to the controller (anti-windup, bumpless
//!    transfer) and returned.
//!
//! ## Sampling period
//! Default Ts = 10 s. The carrier's dominant time constant is tens of minutes and its apparent
//! dead time tens of seconds, so 10 s gives 6+ samples per dead time and ~100–300 per time
//! constant (Åström & Wittenmark's rule of 4–10 samples per rise time is met many times over),
//! while keeping the identified poles away from 1 far enough for f32 RLS (at Ts = 1 s,
//! `1 + a1 + a2` would shrink another 100-fold). It also matches a GPC horizon of N2 = 30
//! samples = 5 minutes, the scale of the closed-loop settling time, and lets open/short faults be
//! confirmed within two samples = 20 s.

use crate::control::{AdaptiveMode, ControlInput, Controller, ControllerStatus};
use crate::event::{Event, EventKind, Events};
use crate::filter::FirstOrder;
#[cfg(feature = "holdover")]
use crate::holdover::Holdover;
use crate::supervisor::{sensor, Supervisor};
use crate::units::{Celsius, Duty};

pub use config::{CarrierConfig, ConfigError, ValidConfig};

mod config;

/// One sample's input.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepInput {
    /// Sample time, ms, on a monotonic clock (integer: every duration the step and the
    /// cold-chain rules measure stays exact to the millisecond for the whole mission, where f32
    /// seconds step by 0.5 s at day 89).
    pub t_ms: u64,
    /// Oversampled RTD conversion, counts of the front end's full scale.
    pub counts: u32,
    /// Requested setpoint, °C.
    pub setpoint_c: f32,
}

/// What a board measures besides the RTD for one sample, handed to the step before it
/// ([`Carrier::observe`]): each `None` where the board has no such sense or took no reading.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BoardReadings {
    /// The modules' supply ahead of the supply-enable switch, V ([`Carrier::observe_supply_v`]).
    pub supply_v: Option<f32>,
    /// The switched rail after the switch, V ([`Carrier::observe_switched_rail_v`]).
    pub switched_v: Option<f32>,
    /// The switched rail at the end of the test pulse the previous output asked for, V
    /// ([`Carrier::observe_switch_test_v`]).
    pub switch_test_v: Option<f32>,
    /// The modules' voltage in the conversion window, V, on a board with the module-side sense
    /// ([`Carrier::observe_module_v`]).
    #[cfg(feature = "module-sense")]
    pub module_v: Option<f32>,
}

/// What the step is doing about safety.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// The controller drives the SSR.
    Normal,
    /// The sensor is faulty: cooling off until it reads plausibly again.
    SensorFault,
    /// The freeze guard holds cooling off.
    FreezeGuard,
    /// The SSR was found shorted: cooling is switched On-Off through the supply-enable switch
    /// (full cooling above setpoint + 1 °C until 0.5 °C below it), the controller is idle.
    LimpHome,
}

impl Mode {
    /// Every mode, in declaration order.
    pub const ALL: [Mode; 4] = [Mode::Normal, Mode::SensorFault, Mode::FreezeGuard, Mode::LimpHome];

    /// Stable snake_case name: the `mode` column of `hter sim --csv` and `hter log2csv` (the
    /// board's telemetry prints the variant name, which `hter log2csv` maps to this).
    pub fn name(self) -> &'static str {
        match self {
            Mode::Normal => "normal",
            Mode::SensorFault => "sensor_fault",
            Mode::FreezeGuard => "freeze_guard",
            Mode::LimpHome => "limp_home",
        }
    }

    /// The step, not the law, decides the outputs for as long as this mode lasts: a sensor
    /// fault (cooling held off, the law not run) or limp home (the supply switch's On-Off). The
    /// alarm indicator shows `not_in_control` ([`crate::alarm`]) and `status` names no law.
    pub fn not_in_control(self) -> bool {
        matches!(self, Mode::SensorFault | Mode::LimpHome)
    }
}

/// One sample's output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutput {
    /// Calibrated temperature of this sample, °C (`None` on a sensor fault).
    pub raw_c: Option<Celsius>,
    /// Filtered temperature the controller saw, °C (the last good value on a sensor fault).
    pub temp_c: Celsius,
    /// Setpoint after clamping, °C.
    pub setpoint_c: Celsius,
    /// What the controller asked for (before saturation and safety), duty.
    pub requested: f32,
    /// Duty to apply to the SSR.
    pub duty: Duty,
    /// Level of the supply-enable output (false opens the modules' supply switch).
    pub supply_enable: bool,
    /// A supply-switch test is due: before the next sample's step, open the switch for
    /// [`crate::supervisor::switch::TEST_PULSE_MS`] with the drive running, read the switched
    /// rail, close the switch again (unless an output since has opened it) and give the reading
    /// to [`Carrier::observe_switch_test_v`]. A board that ignores it only goes untested.
    pub switch_test: bool,
    /// Safety mode after this sample.
    pub mode: Mode,
    /// What happened this sample.
    pub events: Events,
    /// Estimator and mode of an adaptive controller (θ, trace P, prediction error).
    pub status: Option<ControllerStatus>,
    /// How long the load would stay at or below 8 °C if cooling stopped now, s
    /// ([`crate::holdover`]); `None` without a model or before the first estimate.
    pub holdover_s: Option<f32>,
}

impl StepOutput {
    /// The temperature the cold-chain record takes ([`crate::persist::Recorder::push`]): the
    /// controller's `temp_c`, or NaN on a sensor fault, whose `temp_c` is the last good value
    /// held, no measurement.
    pub fn recorded_c(&self) -> f32 {
        if self.mode == Mode::SensorFault {
            f32::NAN
        } else {
            self.temp_c.0
        }
    }
}

/// The per-sample application step.
#[derive(Clone, Debug)]
pub struct Carrier<C: Controller> {
    cfg: CarrierConfig,
    controller: C,
    filter: FirstOrder,
    supervisor: Supervisor,
    setpoint_clamped: bool,
    adaptive_mode: Option<AdaptiveMode>,
    /// A restart to report with the next sample.
    pending_reset: Option<crate::persist::ResetCause>,
    /// The fail-safe stops the boot found ([`crate::failsafe::Stops`]) to report with the next
    /// sample: their [`crate::failsafe::StopKind`] codes, a nibble each, the oldest lowest
    /// (two `Option`s and an emit each cost 224 B of the default firmware).
    pending_stops: u8,
    /// Only in builds with the estimate: the default firmware carries neither its state nor
    /// its initialisation (≈ 350 B of its flash once the settling count was added).
    #[cfg(feature = "holdover")]
    holdover: Holdover,
    /// The model the holdover runs on (the commissioned one); without it, no estimate.
    holdover_model: Option<crate::model::Model>,
}

impl<C: Controller> Carrier<C> {
    /// A carrier that has not seen a sample yet, on a configuration that passed
    /// [`CarrierConfig::validate`] (a board's constant one is checked when it is compiled).
    pub fn new(cfg: ValidConfig, controller: C) -> Self {
        let cfg = *cfg.get();
        Self {
            cfg,
            controller,
            filter: FirstOrder::default(),
            supervisor: Supervisor::new(&cfg.supervisor, cfg.ts_s),
            setpoint_clamped: false,
            adaptive_mode: None,
            pending_reset: None,
            pending_stops: 0,
            #[cfg(feature = "holdover")]
            // The mean duty starts at full duty: until it settles it errs on the short side
            // ([`crate::holdover`]).
            holdover: Holdover::new(1.0),
            holdover_model: None,
        }
    }

    /// Tells the step why the MCU (re)started; the next sample reports it as
    /// [`EventKind::Restarted`], so the log and the cold-chain record show the gap.
    pub fn note_reset(&mut self, cause: crate::persist::ResetCause) {
        self.pending_reset = Some(cause);
    }

    /// Tells the step of a fail-safe stop the boot found ([`crate::failsafe::ResetRecords::boot`]:
    /// the previous boot's, and one before it that boot had not stored), oldest first; the next
    /// sample reports each as [`EventKind::BoardFault`].
    pub fn note_board_fault(&mut self, kind: crate::failsafe::StopKind) {
        // Two are all a boot finds: the newest goes above the oldest (a third would replace it).
        self.pending_stops =
            if self.pending_stops == 0 { kind as u8 } else { self.pending_stops & 0xF | (kind as u8) << 4 };
    }

    /// Gives the step every reading the board took besides the RTD, for the next sample: what
    /// the glue calls before [`Self::step`] (the firmware's control task, the board application
    /// [`crate::app::App::sample`], the simulator and the processor-in-the-loop runner alike).
    ///
    /// A supply or switched-rail reading missing from `r` is missing for this sample: its check
    /// waits for the next reading rather than judging an older one (a rail read with the switch
    /// closed and judged as if read with it open is a false "supply switch shorted").
    pub fn observe(&mut self, r: &BoardReadings) {
        self.supervisor.observe_supply_v(r.supply_v);
        self.supervisor.observe_switched_rail_v(r.switched_v);
        #[cfg(feature = "module-sense")]
        if let Some(v) = r.module_v {
            self.observe_module_v(v);
        }
        if let Some(v) = r.switch_test_v {
            self.observe_switch_test_v(v);
        }
    }

    /// Gives the step the measured supply voltage of the Peltier modules, V, for the next
    /// sample (boards with a divider on the supply rail call it every sample; without it the
    /// supply-sag check is off).
    pub fn observe_supply_v(&mut self, v: f32) {
        self.supervisor.observe_supply_v(Some(v));
    }

    /// Gives the step the switched supply rail — the modules' supply measured *after* the
    /// supply-enable switch — V, for the next sample. With it the step checks the switch
    /// ([`crate::supervisor::switch`]): the rail reading powered while the switch has been
    /// commanded open is [`EventKind::SupplySwitchShorted`]. Without this call (a board without
    /// the sense, a replayed trace) there is no check and no test pulse.
    pub fn observe_switched_rail_v(&mut self, v: f32) {
        self.supervisor.observe_switched_rail_v(Some(v));
    }

    /// Gives the step the voltage across the modules — the SSR's load side, read in the
    /// conversion window at the end of the PWM period, where the SSR is commanded off below full
    /// duty — V, for the next sample. With it the step finds a shorted SSR within two samples,
    /// whatever the load does ([`crate::supervisor::module`]). Without this call (the reference
    /// board has no such sense; the buck drive has no window) there is no such check. Built
    /// with the `module-sense` feature (the host's default; the firmware's `module-sense`
    /// build, which reads it on PC1).
    #[cfg(feature = "module-sense")]
    pub fn observe_module_v(&mut self, v: f32) {
        self.supervisor.observe_module_v(v);
    }

    /// Gives the step the switched rail read at the end of the test pulse the previous output
    /// asked for ([`StepOutput::switch_test`]), V, for the next sample: reading powered, the
    /// switch is shorted.
    pub fn observe_switch_test_v(&mut self, v: f32) {
        self.supervisor.observe_switch_test_v(v);
    }

    /// Holds the supply switch's periodic test pulses off (`true`) while an identification run
    /// records the plant: its record should hold its own excitation and nothing else (the
    /// identify build turns them off for the same reason). The switch is
    /// still checked whenever the freeze guard or a sensor fault opens it.
    pub fn hold_switch_tests(&mut self, held: bool) {
        self.supervisor.hold_switch_tests(held);
    }

    /// Runs one sample whose RTD conversion is not valid because the reference conversions
    /// around it failed [`crate::adc::ReferenceWindow::check`]: a sensor fault
    /// ([`EventKind::ReferenceOutOfRange`]) with cooling off, exactly as an open sensor would
    /// be, until a valid sample comes. `input.counts` is ignored (and does not feed the stuck
    /// check).
    pub fn step_with_reference_fault(&mut self, input: &StepInput) -> StepOutput {
        self.run(input.t_ms, Err(EventKind::ReferenceOutOfRange), input.setpoint_c, true)
    }

    /// The model the holdover estimate runs on from the next sweep ([`crate::holdover`]): the
    /// model commissioning measured and the board stored, whatever law drives (`None`: no
    /// estimate). Not the self-tuner's running estimate:  holding a constant setpoint with little excitation, it drifts in its
    /// fast mode, which is the one a power cut's first minutes follow (EXPERIMENTS.md, issue 17).
    pub fn set_holdover_model(&mut self, model: Option<crate::model::Model>) {
        self.holdover_model = model;
    }

    /// The model the holdover estimate runs on.
    pub fn holdover_model(&self) -> Option<crate::model::Model> {
        self.holdover_model
    }

    /// The configuration.
    pub fn config(&self) -> &CarrierConfig {
        &self.cfg
    }

    /// The controller, for logging its state.
    pub fn controller(&self) -> &C {
        &self.controller
    }

    /// The controller, to switch or reconfigure it at run time (the board's settings
    /// interface, [`crate::app::App`]; an on-board commissioning aborted when the mode leaves
    /// normal, [`crate::ident::commission`]); the next sample runs the new one.
    pub fn controller_mut(&mut self) -> &mut C {
        &mut self.controller
    }

    /// Replaces the two-point calibration from the next sample on. A [`TwoPoint`] is checked
    /// when it is made ([`TwoPoint::from_points`]); nothing else in the configuration changes.
    ///
    /// The reading steps by the calibration's change, which is neither the load moving nor the
    /// sensor failing: the measurement filter and the supervisor's references (the sensor
    /// checks, the freeze guard's slope, the SSR monitor's history) are carried over to the new
    /// line ([`crate::calib::Recalibration`]), so that the reported temperature moves by the
    /// change at once and no check takes it for a sensor offset, a fall or a warming (a bug
    /// hunt against `hter virtual-board` found each `set cal_ice 0.0,1.4` measured as a sensor
    /// offset and subtracted, undoing it, and alternating changes adding offsets up). An
    /// offset subtracted for a real sensor step before stays ([`OffsetWatch`]'s
    /// `recalibrated`). The controller is not told: the new reading is what it should now
    /// drive to the setpoint. Reached from the board's interface only ([`crate::app::App`]),
    /// so a build without it carries none of this.
    ///
    /// [`TwoPoint`]: crate::calib::TwoPoint
    /// [`TwoPoint::from_points`]: crate::calib::TwoPoint::from_points
    /// [`OffsetWatch`]: crate::supervisor::sensor
    pub fn set_calibration(&mut self, cal: crate::calib::TwoPoint) {
        let old = self.cfg.cal;
        self.supervisor.recalibrated(&self.cfg.supervisor, &old, &cal, &mut self.filter);
        self.cfg.cal = cal;
    }

    /// The sensor offset the step subtracts from every reading (a lead or connector fault the
    /// offset watch measured, `sensor_offset` in the event log), as the history keeps it: in
    /// the channel's own terms, the calibration's gain divided out
    /// ([`crate::persist::SensorOffset`]). The glue hands it to the cold-chain record after every
    /// sample ([`crate::persist::Recorder::note_carried`]), which stores each change at once.
    pub fn sensor_offset(&self) -> crate::persist::SensorOffset {
        crate::persist::SensorOffset::from_c(self.supervisor.sensor_offset_c() / self.cfg.cal.gain)
    }

    /// The sensor offset the step subtracts from every reading, °C, through the calibration in
    /// force (`status`'s `sensor_offset_c`; 0 for none).
    pub fn sensor_offset_c(&self) -> f32 {
        self.supervisor.sensor_offset_c()
    }

    /// Stops subtracting the sensor offset, from the next sample (`set sensor_offset_c 0`, after
    /// the lead fault it compensated was repaired). The reading moves up by it at once, which is
    /// neither the load moving nor the sensor stepping: the checks, the filter, the freeze
    /// guard's slope and the SSR monitor's history are carried over, as for a new calibration
    /// ([`Self::set_calibration`]). If the fault is still there, the reading is that much warm
    /// and the load is held that much colder: the engineer clears it after the repair only.
    pub fn clear_sensor_offset(&mut self) {
        self.supervisor.clear_sensor_offset(&self.cfg.supervisor, &mut self.filter);
    }

    /// Whether the step found the SSR shorted: limp home drives, for the rest of this boot and,
    /// through the cold-chain history ([`crate::persist::HistoryRecord::ssr_shorted`], which the
    /// glue hands it with [`crate::persist::Recorder::note_carried`] after every sample), the
    /// next ones ([`Self::resume`]).
    pub fn ssr_shorted(&self) -> bool {
        self.supervisor.shorted()
    }

    /// Resumes, from the first sample on, what the previous boots found and the history keeps
    /// (`history`: the boot's, after [`crate::persist::Recorder::note_boot`]): the sensor offset
    /// (through the calibration in force) and a shorted SSR, which limps home at once instead of
    /// handing the modules back to the controller until the checks find the short again (at
    /// full cooling, the load to 1.88 °C first). What the glue calls at boot, after the
    /// calibration is set and before the first sample.
    pub fn resume(&mut self, history: &crate::persist::HistoryRecord) {
        self.restore_sensor_offset(history.sensor_offset);
        if history.ssr_shorted() {
            self.supervisor.restore_short();
        }
    }

    /// Subtracts again, from the first sample on, the sensor offset a previous boot subtracted
    /// (the stored history's [`crate::persist::HistoryRecord::sensor_offset`], through the
    /// calibration in force; at most [`crate::supervisor::sensor::OffsetConfig::max_comp_c`]).
    /// What the glue calls at boot, after the calibration is set and before the first sample:
    /// the fault the offset compensated does not go away with a restart, and forgotten, it read
    /// warm again and the controller held the load that much colder (the freezing side).
    fn restore_sensor_offset(&mut self, offset: crate::persist::SensorOffset) {
        self.supervisor.restore_sensor_offset(&self.cfg.supervisor, offset.c() * self.cfg.cal.gain);
    }

    /// Runs one sample from raw ADC counts (the firmware's and the simulator's entry).
    pub fn step(&mut self, input: &StepInput) -> StepOutput {
        let stuck = self.supervisor.counts_stuck(input.counts);
        // Only a plausible reading can be "stuck": open and short keep their own diagnosis.
        let measured = match sensor::measure(&self.cfg, input.counts) {
            Ok(_) if stuck => Err(EventKind::SensorStuck),
            m => m,
        };
        self.run(input.t_ms, measured, input.setpoint_c, true)
    }

    /// Runs one sample from an already converted temperature, skipping the ADC and RTD
    /// conversion (ideal-measurement plants, replay of temperature logs). The plausibility
    /// check, filter, controller and safety still apply.
    pub fn step_celsius(&mut self, t_ms: u64, temp: Celsius, setpoint_c: f32) -> StepOutput {
        let measured = sensor::plausible(&self.cfg, temp);
        self.run(t_ms, measured, setpoint_c, false)
    }

    /// Check, control, guard, actuate. `raw` is the converted reading or the fault the
    /// conversion found; `sensor`: it came from the sensor (the offset watch runs on it).
    fn run(&mut self, t_ms: u64, raw: Result<Celsius, EventKind>, setpoint_c: f32, sensor: bool) -> StepOutput {
        let mut events = Events::default();
        let mut emit = |kind| events.push(Event { t_ms, kind });
        if let Some(cause) = self.pending_reset.take() {
            emit(EventKind::Restarted(cause));
        }
        let mut stops = core::mem::take(&mut self.pending_stops);
        while let Some(kind) = crate::failsafe::StopKind::from_code(stops & 0xF) {
            emit(EventKind::BoardFault(kind));
            stops >>= 4;
        }

        let reading = self.supervisor.check(&self.cfg, t_ms, raw, sensor, &mut self.filter, &mut emit);
        let temp_c = reading.temp_c;
        // The filter's first reading (after a boot or a sensor fault) was a spike, outvoted this
        // sample: the samples before fed the controller a temperature nobody measured. This one
        // runs without the controller, as a sensor fault's do, so that the self-tuner's estimator
        // waits out a gap (`Controller::skip`). Without it a warm spike on a restart's first
        // reading (54 °C over a load at 4 °C, mission 42047) took b to −0.74 at the next update,
        // and the law swung the load 2.1–5.7 °C for two hours.
        let trusted = self.supervisor.trusts_reading() && !reading.outvoted;

        let w = self.setpoint(setpoint_c, &mut emit);
        let ci = ControlInput { y_c: temp_c, w_c: w };
        let requested = if trusted { self.controller.update(&ci) } else { Ok(0.0) };
        // A failed controller's request is NaN: the check below applies the safe state and says so.
        let requested = requested.unwrap_or(f32::NAN);
        let duty = if requested.is_finite() {
            Duty::saturating(requested)
        } else {
            emit(EventKind::ControllerNonFinite);
            Duty::OFF
        };
        let status = self.controller.status();
        self.note_adaptive_mode(status, &mut emit);

        let verdict = self.supervisor.guard(&self.cfg.supervisor, t_ms, &ci, requested, duty, &mut emit);

        // Tell the controller what was really applied.
        if trusted {
            self.controller.track(&ci, verdict.duty.get());
        } else {
            self.controller.skip(verdict.duty.get());
        }
        let holdover_s = self.holdover(verdict.duty.get(), verdict.supply_enable, verdict.mode, trusted, temp_c);
        StepOutput {
            raw_c: reading.raw_c,
            temp_c: Celsius(temp_c),
            setpoint_c: Celsius(w),
            requested,
            duty: verdict.duty,
            supply_enable: verdict.supply_enable,
            switch_test: verdict.switch_test,
            mode: verdict.mode,
            events,
            status,
            holdover_s,
        }
    }

    /// The holdover estimate after this sample's actuation ([`crate::holdover`]).
    #[cfg(feature = "holdover")]
    fn holdover(&mut self, duty: f32, supply_enable: bool, mode: Mode, trusted: bool, temp_c: f32) -> Option<f32> {
        // What the modules got: nothing with the supply switch open.
        let applied = if supply_enable { duty } else { 0.0 };
        // Every sample, a sweep under way too: one started on another T₀ and ū is stale once
        // they move ([`crate::holdover`]).
        let start = if trusted { self.holdover_model.as_ref().map(|m| (m, temp_c)) } else { None };
        // Only a controller holding the load gives the mean duty a meaning: a sensor fault or
        // the freeze guard stops cooling, limp home's thermostat cycles full cooling on a
        // cycle longer than the mean's memory (`hter sim --scenario power-cut --fault
        // ssr-stuck-on@1800 --ambient 15`: the horizon for 12 minutes after limp home began,
        // then 826–1539 s with the cycle against the 1360 s the load took).
        self.holdover.update(applied, mode == Mode::Normal, start, self.cfg.ts_s)
    }

    /// Without the `holdover` feature: no estimate.
    #[cfg(not(feature = "holdover"))]
    fn holdover(&mut self, _duty: f32, _supply_enable: bool, _mode: Mode, _trusted: bool, _temp_c: f32) -> Option<f32> {
        None
    }

    /// The setpoint clamped to the accepted range; a clamp is reported when it begins.
    fn setpoint(&mut self, setpoint_c: f32, emit: &mut impl FnMut(EventKind)) -> f32 {
        let w = self.cfg.setpoint_in_force(setpoint_c);
        let clamped = w != setpoint_c;
        if clamped && !self.setpoint_clamped {
            emit(EventKind::SetpointClamped);
        }
        self.setpoint_clamped = clamped;
        w
    }

    /// Reports a change of the self-tuner's mode.
    fn note_adaptive_mode(&mut self, status: Option<ControllerStatus>, emit: &mut impl FnMut(EventKind)) {
        if let Some(st) = status {
            if self.adaptive_mode != Some(st.mode) {
                emit(match st.mode {
                    AdaptiveMode::Adaptive => EventKind::AdaptiveEngaged,
                    AdaptiveMode::Frozen => EventKind::AdaptiveFrozen,
                    AdaptiveMode::Fallback => EventKind::FallbackEngaged,
                });
                self.adaptive_mode = Some(st.mode);
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
