//! The per-sample application step: raw ADC counts (and time) in → temperature, duty, events out.
//!
//! [`Carrier`] is the whole application minus the peripherals. The firmware calls
//! [`Carrier::step`] once per sample period with the oversampled RTD counts and writes the
//! returned duty to the SSR timer and the supply-enable output; `hal-sim` does the same with its
//! simulated ADC and SSR. A trace of counts therefore reproduces a board's behaviour on the host.
//!
//! Pipeline per sample:
//! 1. counts → ohms (ratiometric front end, [`crate::adc`]); open/short detection;
//! 2. ohms → °C (Callendar–Van Dusen, [`crate::rtd`]); plausibility range check;
//! 3. two-point calibration ([`crate::calib`]) and first-order filter F_a ([`crate::filter`]);
//! 4. setpoint clamped to the vaccine band 2…8 °C (a controller may never aim below +2 °C);
//! 5. controller ([`crate::control`]);
//! 6. safety: on a sensor fault cooling stops (the safe state for vaccines that freeze); the
//!    freeze guard cuts cooling — duty and the supply-enable switch — when the measured load,
//!    extrapolated along its slope, falls to `freeze_cut_c`, and holds it off until it is back
//!    above `freeze_release_c`; stuck and spiking sensors and a shorted or open SSR are
//!    detected (a shorted SSR opens the supply switch for good);
//! 7. the applied duty is fed back to the controller (anti-windup, bumpless transfer).
//!
//! ## Sampling period
//! Default Ts = 10 s. The carrier's dominant time constant is tens of minutes and its apparent
//! dead time tens of seconds, so 10 s gives 6+ samples per dead time and ~100–300 per time
//! constant (Åström & Wittenmark's rule of 4–10 samples per rise time is met many times over),
//! while keeping the identified poles away from 1 far enough for f32 RLS (at Ts = 1 s,
//! `1 + a1 + a2` would shrink another 100-fold). It also matches a GPC horizon of N2 = 30
//! samples = 5 minutes, the scale of the closed-loop settling time, and lets open/short faults be
//! confirmed within two samples = 20 s.

use crate::adc::{AdcError, AdcFrontEnd};
use crate::calib::TwoPoint;
use crate::control::{AdaptiveMode, ControlInput, Controller, ControllerStatus};
use crate::event::{Event, EventKind, Events};
use crate::filter::{FirstOrder, FirstOrderConfig};
use crate::rtd::Rtd;
use crate::units::{max_f32, min_f32, secs_f32, Celsius, Duty};

/// Everything the step needs to know that does not change while it runs.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarrierConfig {
    /// Sample period, s (see the module docs for the choice of 10 s).
    pub ts_s: f32,
    /// ADC front end of the RTD channel.
    pub adc: AdcFrontEnd,
    /// The RTD (Pt100 on the reference board).
    pub rtd: Rtd,
    /// Two-point calibration of the channel.
    pub cal: TwoPoint,
    /// Measurement filter.
    pub filter: FirstOrderConfig,
    /// Readings below this are implausible for a vaccine carrier (sensor fault), °C.
    pub plausible_min_c: f32,
    /// Readings above this are implausible for a vaccine carrier (sensor fault), °C.
    pub plausible_max_c: f32,
    /// Lowest setpoint accepted, °C (vaccines freeze below; SPEC §6).
    pub setpoint_min_c: f32,
    /// Highest setpoint accepted, °C.
    pub setpoint_max_c: f32,
    /// Freeze guard: cooling is cut when the measured load is at or below this, °C.
    /// 1.5 °C leaves 0.5 °C of margin to the +1 °C limit of SPEC §6 for the sensor lag.
    pub freeze_cut_c: f32,
    /// Freeze guard: cooling may resume once the measured load is at or above this, °C.
    pub freeze_release_c: f32,
    /// Freeze guard look-ahead, s: the guard acts on the measured temperature extrapolated
    /// this far along its current downward slope. Cut at full cooling, the cold side (≈ −10 °C)
    /// keeps pulling the load down for minutes and the sensor lags the load by ≈ 50 s, so a
    /// guard on the present reading alone lets the load coast ≈ 1 °C past it (measured on the
    /// hal-sim plant with On-Off at a 3 °C setpoint).
    pub freeze_lookahead_s: f32,
    /// Identical conversions in a row that mean a stuck converter. 18 samples = 3 min: with the
    /// front end's ≈ 1.5 counts of noise, 18 equal 16-bit results in a row happen by chance
    /// about once in 10¹² samples.
    pub stuck_samples: u16,
    /// A reading further than this from the filtered temperature is a spike, °C. The load
    /// cannot move more than ≈ 0.2 °C in one 10 s sample; 2 °C leaves a wide margin.
    pub spike_c: f32,
    /// SSR stuck on: the duty was 0 for this many samples (3 min: the coast after full cooling
    /// stops has slowed down by then)…
    pub stuck_on_samples: u16,
    /// …and the load still fell by more than this over the last minute, °C, at least 80 % as
    /// fast as the minute before (the coast after full cooling stops slows down; a shorted SSR
    /// keeps cooling at full rate).
    pub stuck_on_drop_c: f32,
    /// SSR stuck off: the duty was ≥ 0.9 for this many samples (5 min: longer than the
    /// warming the sensor lag shows right after cooling starts)…
    pub stuck_off_samples: u16,
    /// …and the load rose by more than this over that time, °C.
    pub stuck_off_rise_c: f32,
    /// SSR stuck off, slow warming (a cool day, when a dead SSR lets the load rise only
    /// ≈ 0.3 °C in 5 min): full duty for this many samples (15 min, three times the longest
    /// lag between cooling starting and the load turning down)…
    pub stuck_off_slow_samples: u16,
    /// …the load higher than when full duty began by more than this, °C, and still rising
    /// over the last 5 min. A working SSR has turned the load around long before.
    pub stuck_off_slow_rise_c: f32,
    /// Sensor offset: a step of the calibrated reading larger than this between two samples,
    /// °C… The sensed load moves at most ≈ 0.46 °C per 10 s sample (pull-down from 43 °C, half
    /// load, measured on the hal-sim plant), so 0.7 °C is more than physics allows.
    pub offset_step_c: f32,
    /// …that stays at its new level (within a quarter of the step) for this many samples.
    pub offset_confirm_samples: u8,
    /// Largest upward offset that is measured and subtracted, °C (larger ones, and any step
    /// down, are reported only).
    pub offset_max_comp_c: f32,
    /// Supply sag: the measured module supply below this, V (12 V nominal − 10 %)…
    pub supply_min_v: f32,
    /// …for this many samples in a row.
    pub supply_sag_samples: u8,
    /// Lid open: time constants of the fast and slow averages of the applied duty, s…
    pub lid_fast_s: f32,
    /// (slow average)
    pub lid_slow_s: f32,
    /// …whose difference above this, duty, while holding within 1 °C of the setpoint, means a
    /// sudden heat load. A 15 W lid opening raises the holding duty by ≈ 0.35 and the difference
    /// peaks at ≈ 0.13 after 50 min; a 3 W warm item (≈ +0.09) and a 12 → 9 V supply sag
    /// (≈ +0.07) stay below 0.04; On-Off's own duty cycle ripples the difference by < 0.08.
    pub lid_duty_rise: f32,
    // ---- supply-switch check (switched-rail sense) ----
    /// Shorted supply switch: with the switch commanded open, the switched rail reading above
    /// this fraction of the measured supply is a short (a working, open switch leaves the rail
    /// at the bleeder's few millivolts; a shorted one at the supply minus its ≈ 0.1 V drop)…
    pub switch_open_max_fraction: f32,
    /// …but never below this, V (a dead or missing supply reads noise, not a short)…
    pub switch_open_floor_v: f32,
    /// …or, without a supply measurement, above this, V (half the 12 V nominal).
    pub switch_open_max_v: f32,
    /// Samples the switch must have been commanded open before the rail is judged: 2, so the
    /// first reading after opening (the rail's capacitance still bleeding down) never counts.
    pub switch_open_samples: u8,
    /// Samples between test openings of the switch when nothing else opened it: 720 = 2 h. A
    /// test costs `switch_open_samples` samples (20 s) without cooling, and an unpowered module
    /// lets its hot side's heat flow back: the load warms by up to ≈ 0.25 °C (half-loaded
    /// H-TER I in hal-sim) before the controller has it back. So a test waits until the load is
    /// at or below its setpoint (it then ends at most that much above it, deep inside 2–8 °C);
    /// a load held above its setpoint at full capacity is never opened on. Every 2 h finds a
    /// latent short well within the day, and within any 24 h `hter campaign` mission whose
    /// load reaches its setpoint after the fault. 0: no test openings (an identification run,
    /// whose record a 20 s gap in the input would spoil); the switch is then only judged when
    /// the supervisor opens it.
    pub switch_test_interval_samples: u32,
}

impl CarrierConfig {
    /// Defaults for the reference board: Pt100 on the default front end, Ts = 10 s, F_a = 0.5.
    pub const DEFAULT: CarrierConfig = CarrierConfig {
        ts_s: 10.0,
        adc: AdcFrontEnd::DEFAULT,
        rtd: Rtd::PT100,
        cal: TwoPoint::IDENTITY,
        filter: FirstOrderConfig { fa: 0.5 },
        // The carrier lives between a freezer pack (−25 °C) and a car in the sun (+70 °C).
        plausible_min_c: -30.0,
        plausible_max_c: 75.0,
        setpoint_min_c: 2.0,
        setpoint_max_c: 8.0,
        freeze_cut_c: 1.5,
        freeze_release_c: 2.5,
        freeze_lookahead_s: 120.0,
        stuck_samples: 18,
        spike_c: 2.0,
        stuck_on_samples: 18,
        stuck_on_drop_c: 0.15,
        stuck_off_samples: 30,
        stuck_off_rise_c: 0.5,
        stuck_off_slow_samples: 90,
        stuck_off_slow_rise_c: 0.3,
        offset_step_c: 0.7,
        offset_confirm_samples: 3,
        offset_max_comp_c: 3.0,
        supply_min_v: 10.8,
        supply_sag_samples: 3,
        lid_fast_s: 1800.0,
        lid_slow_s: 5400.0,
        lid_duty_rise: 0.1,
        switch_open_max_fraction: 0.5,
        switch_open_floor_v: 2.0,
        switch_open_max_v: 6.0,
        switch_open_samples: 2,
        switch_test_interval_samples: 720,
    };
}

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
    /// Safety mode after this sample.
    pub mode: Mode,
    /// What happened this sample.
    pub events: Events,
    /// Estimator and mode of an adaptive controller (θ, trace P, prediction error).
    pub status: Option<ControllerStatus>,
}

/// The per-sample application step.
#[derive(Clone, Debug)]
pub struct Carrier<C: Controller> {
    cfg: CarrierConfig,
    controller: C,
    filter: FirstOrder,
    sensor_fault: Option<EventKind>,
    freeze_guard: bool,
    setpoint_clamped: bool,
    adaptive_mode: Option<AdaptiveMode>,
    last_temp_c: Option<f32>,
    slope_c_per_s: f32,
    last_counts: Option<u32>,
    same_counts: u16,
    spike_run: u8,
    spike_times: [Option<u64>; 3],
    spikes_reported_ms: Option<u64>,
    history: [f32; HISTORY],
    history_len: usize,
    history_head: usize,
    off_run: u16,
    on_run: u16,
    /// The fall of the filtered temperature over the last sample, °C (positive falling).
    last_drop_c: f32,
    /// Limp home: whether the supply is switched on now.
    limp_on: bool,
    /// A restart to report with the next sample.
    pending_reset: Option<crate::persist::ResetCause>,
    /// A fail-safe stop of the previous boot to report with the next sample.
    pending_stop: Option<crate::failsafe::StopKind>,
    /// When the supply probe under way began, ms.
    probe: Option<u64>,
    /// When the last supply probe began, ms.
    probe_ms: Option<u64>,
    /// When the freeze guard last tripped, ms.
    trip_ms: Option<u64>,
    /// When the freeze guard last tripped with cooling not requested, ms.
    unrequested_trip_ms: Option<u64>,
    /// Filtered temperature when the current run of full duty began.
    on_start_c: f32,
    req_off_run: u16,
    supply_cut: bool,
    ssr_off_reported: bool,
    /// Sensor offset measured and subtracted, °C.
    offset_c: f32,
    /// The last offset-corrected reading that was not a spike.
    last_raw_c: Option<f32>,
    /// The last spike's reading.
    spike_last_c: f32,
    /// A step under watch: (level before, step, samples it has held).
    pending_step: Option<(f32, f32, u8)>,
    /// Last measured module supply, V, and samples in a row below the minimum.
    supply_v: Option<f32>,
    supply_low_run: u8,
    supply_sag_reported: bool,
    /// Fast and slow averages of the applied duty (lid-open check).
    duty_fast: Option<f32>,
    duty_slow: f32,
    /// Samples the duty averages have run since the load reached its setpoint (they mean
    /// nothing before one slow time constant).
    duty_n: u32,
    /// Samples since the applied duty was last strictly between 0 and 1.
    since_modulated: u32,
    lid_reported: bool,
    /// The setpoint of the last sample and when the load first came within 0.3 °C of it, ms.
    last_w: f32,
    reached_ms: Option<u64>,
    switch: SwitchCheck,
}

/// State of the supply-switch check (see [`Carrier::observe_switched_rail_v`]), counted in
/// samples.
#[derive(Clone, Copy, Debug)]
struct SwitchCheck {
    /// The switched rail measured for this sample, V (`None`: the board has no sense).
    rail_v: Option<f32>,
    /// The supply-enable level of the previous output (what the rail now shows).
    last_enable: bool,
    /// Samples in a row the switch has been commanded open, up to the previous output.
    open_run: u8,
    reported: bool,
    /// Samples since the rail was last seen with the switch open long enough to judge it.
    since_check: u32,
    /// Samples of the test opening still to go.
    test_left: u8,
}

impl SwitchCheck {
    const NEW: SwitchCheck =
        SwitchCheck { rail_v: None, last_enable: true, open_run: 0, reported: false, since_check: 0, test_left: 0 };
}

/// Samples of filtered temperature kept for the SSR checks.
const HISTORY: usize = 32;

impl<C: Controller> Carrier<C> {
    /// A carrier that has not seen a sample yet.
    pub fn new(cfg: CarrierConfig, controller: C) -> Self {
        Self {
            cfg,
            controller,
            filter: FirstOrder::default(),
            sensor_fault: None,
            freeze_guard: false,
            setpoint_clamped: false,
            adaptive_mode: None,
            last_temp_c: None,
            slope_c_per_s: 0.0,
            last_counts: None,
            same_counts: 0,
            spike_run: 0,
            spike_times: [None; 3],
            spikes_reported_ms: None,
            history: [0.0; HISTORY],
            history_len: 0,
            history_head: 0,
            off_run: 0,
            on_run: 0,
            on_start_c: 0.0,
            unrequested_trip_ms: None,
            trip_ms: None,
            probe: None,
            probe_ms: None,
            pending_reset: None,
            pending_stop: None,
            limp_on: false,
            last_drop_c: 0.0,
            req_off_run: 0,
            supply_cut: false,
            ssr_off_reported: false,
            offset_c: 0.0,
            last_raw_c: None,
            spike_last_c: f32::NAN,
            pending_step: None,
            supply_v: None,
            supply_low_run: 0,
            supply_sag_reported: false,
            duty_fast: None,
            duty_slow: 0.0,
            duty_n: 0,
            since_modulated: u32::MAX,
            lid_reported: false,
            last_w: f32::NAN,
            reached_ms: None,
            switch: SwitchCheck::NEW,
        }
    }

    /// Tells the step why the MCU (re)started; the next sample reports it as
    /// [`EventKind::Restarted`], so the log and the cold-chain record show the gap.
    pub fn note_reset(&mut self, cause: crate::persist::ResetCause) {
        self.pending_reset = Some(cause);
    }

    /// Tells the step that the previous boot ended in a fail-safe stop (the reason record the
    /// glue found at boot, [`crate::failsafe::ReasonRecord::take`]); the next sample reports it
    /// as [`EventKind::BoardFault`].
    pub fn note_board_fault(&mut self, kind: crate::failsafe::StopKind) {
        self.pending_stop = Some(kind);
    }

    /// Gives the step the measured supply voltage of the Peltier modules, V, for the next
    /// sample (boards with a divider on the supply rail call it every sample; without it the
    /// supply-sag check is off).
    pub fn observe_supply_v(&mut self, v: f32) {
        self.supply_v = Some(v);
    }

    /// Gives the step the switched supply rail — the modules' supply measured *after* the
    /// supply-enable switch — V, for the next sample. With it the step checks the switch: the
    /// rail reading powered while the switch has been commanded open for
    /// `switch_open_samples` samples is [`EventKind::SupplySwitchShorted`] (reported once; the
    /// alarm latches on it). The switch is opened for that whenever the supervisor opens it
    /// anyway (sensor fault, freeze guard, supply probe, limp home), and otherwise for a test
    /// every `switch_test_interval_samples` in normal control, once the load is at or below
    /// its setpoint. Without this call (a board
    /// without the sense, a replayed trace) there is no check and no test opening.
    pub fn observe_switched_rail_v(&mut self, v: f32) {
        self.switch.rail_v = Some(v);
    }

    /// Runs one sample whose RTD conversion is not valid because the reference conversions
    /// around it failed [`crate::adc::ReferenceWindow::check`]: a sensor fault
    /// ([`EventKind::ReferenceOutOfRange`]) with cooling off, exactly as an open sensor would
    /// be, until a valid sample comes. `input.counts` is ignored (and does not feed the stuck
    /// check).
    pub fn step_with_reference_fault(&mut self, input: &StepInput) -> StepOutput {
        self.run(input.t_ms, Err(EventKind::ReferenceOutOfRange), input.setpoint_c, true)
    }

    // ---- supply-switch check ----

    /// The shorted-switch detector, run every sample on the rail measured with the switch in
    /// the state of the previous output.
    fn check_switch(&mut self, emit: &mut impl FnMut(EventKind)) {
        let sw = &mut self.switch;
        let Some(rail) = sw.rail_v else { return };
        sw.open_run = if sw.last_enable { 0 } else { sw.open_run.saturating_add(1) };
        if sw.open_run < self.cfg.switch_open_samples {
            return;
        }
        sw.since_check = 0;
        let limit = match self.supply_v {
            Some(v) if v.is_finite() => max_f32(self.cfg.switch_open_max_fraction * v, self.cfg.switch_open_floor_v),
            _ => self.cfg.switch_open_max_v,
        };
        // NaN (a broken sense) is not a short: it fails `>`.
        if rail > limit && !sw.reported {
            sw.reported = true;
            emit(EventKind::SupplySwitchShorted);
        }
    }

    /// Whether this sample opens the switch for the periodic test: only in normal control
    /// (every other mode opens it itself, or needs it closed to limp home), only with the
    /// sense present, never once a short has been found (the test can tell nothing more), and
    /// only starting with the filtered load `temp_c` at or below the setpoint `w`.
    fn switch_test_due(&mut self, mode: Mode, temp_c: f32, w: f32) -> bool {
        let cfg = &self.cfg;
        let sw = &mut self.switch;
        let off = cfg.switch_test_interval_samples == 0;
        if off || sw.rail_v.is_none() || sw.reported || mode != Mode::Normal || self.supply_cut {
            sw.test_left = 0;
            return false;
        }
        sw.since_check = sw.since_check.saturating_add(1);
        if sw.test_left == 0 && sw.since_check >= cfg.switch_test_interval_samples && temp_c <= w {
            sw.test_left = cfg.switch_open_samples;
        }
        if sw.test_left > 0 {
            sw.test_left -= 1;
            true
        } else {
            false
        }
    }

    /// Remembers the supply-enable level this sample outputs (the next rail reading shows it).
    fn note_supply_enable(&mut self, enable: bool) -> bool {
        self.switch.last_enable = enable;
        enable
    }

    // ---- end of the supply-switch check ----

    /// The configuration.
    pub fn config(&self) -> &CarrierConfig {
        &self.cfg
    }

    /// The controller, for logging its state.
    pub fn controller(&self) -> &C {
        &self.controller
    }

    /// Runs one sample from raw ADC counts (the firmware's and the simulator's entry).
    pub fn step(&mut self, input: &StepInput) -> StepOutput {
        self.same_counts = if self.last_counts == Some(input.counts) { self.same_counts.saturating_add(1) } else { 0 };
        self.last_counts = Some(input.counts);
        // Only a plausible reading can be "stuck": open and short keep their own diagnosis.
        let measured = match self.measure(input.counts) {
            Ok(_) if self.same_counts.saturating_add(1) >= self.cfg.stuck_samples => Err(EventKind::SensorStuck),
            m => m,
        };
        self.run(input.t_ms, measured, input.setpoint_c, true)
    }

    /// Runs one sample from an already converted temperature, skipping the ADC and RTD
    /// conversion (ideal-measurement plants, replay of temperature logs). The plausibility
    /// check, filter, controller and safety still apply.
    pub fn step_celsius(&mut self, t_ms: u64, temp: Celsius, setpoint_c: f32) -> StepOutput {
        let measured = self.plausible(temp);
        self.run(t_ms, measured, setpoint_c, false)
    }

    /// Sensor offset: a reading that steps by more than physics allows and stays there is a
    /// sensor fault, not the load. While a step is under watch the filter is held; once it has
    /// held its level for `offset_confirm_samples` it is measured, subtracted from every later
    /// reading and reported. `raw` is the offset-corrected reading; returns whether the filter
    /// must hold this sample.
    fn watch_offset(&mut self, raw: f32, emit: &mut impl FnMut(EventKind)) -> bool {
        // The reference is the last reading that was not a spike (`run` keeps it): after a
        // spike the good reading that follows must not look like a step from the spike, and
        // the filtered value lags a fast pull-down too much to serve (both seen in
        // `hter campaign` before this).
        let prev = self.last_raw_c;
        match (self.pending_step, prev) {
            (Some((before, step, n)), _) => {
                // Within a quarter of the step, and never looser than 0.5 °C: a burst of
                // spikes tens of degrees off must not pass for a level that holds.
                if (raw - (before + step)).abs() <= min_f32(0.25 * step.abs(), 0.5) {
                    let n = n.saturating_add(1);
                    if n >= self.cfg.offset_confirm_samples {
                        // Measured on this sample: the load itself has not moved measurably.
                        // Only a step *up* of at most `offset_max_comp_c` is subtracted: a
                        // reading too warm makes the controller overcool — the freezing side —
                        // while one too cold only under-cools, which the warm alarms catch, and
                        // which is also what a probe re-seated in a colder load looks like.
                        let measured = raw - before;
                        if measured > 0.0 && measured <= self.cfg.offset_max_comp_c {
                            self.offset_c += measured;
                        }
                        self.pending_step = None;
                        emit(EventKind::SensorOffset);
                    } else {
                        self.pending_step = Some((before, step, n));
                    }
                    true
                } else {
                    // Back (a transient, which the spike filter handles) or somewhere else.
                    self.pending_step = None;
                    false
                }
            }
            (None, Some(p)) if (raw - p).abs() > self.cfg.offset_step_c => {
                self.pending_step = Some((p, raw - p, 1));
                true
            }
            _ => false,
        }
    }

    fn run(&mut self, t_ms: u64, raw: Result<Celsius, EventKind>, setpoint_c: f32, sensor: bool) -> StepOutput {
        let mut events = Events::default();
        let mut emit = |kind| events.push(Event { t_ms, kind });
        // Time since an earlier instant, ms (0 if the clock went back: "just now").
        let since = move |t0: u64| t_ms.saturating_sub(t0);
        if let Some(cause) = self.pending_reset.take() {
            emit(EventKind::Restarted(cause));
        }
        if let Some(kind) = self.pending_stop.take() {
            emit(EventKind::BoardFault(kind));
        }

        // 1–3: measurement chain.
        match (raw, self.sensor_fault) {
            (Err(kind), None) => {
                emit(kind);
                self.sensor_fault = Some(kind);
            }
            (Err(kind), Some(prev)) if kind != prev => {
                emit(kind);
                self.sensor_fault = Some(kind);
            }
            (Ok(_), Some(_)) => {
                emit(EventKind::SensorRecovered);
                self.sensor_fault = None;
                // The filter state predates the fault; start afresh from the first good reading.
                self.filter.reset();
                self.last_temp_c = None;
                self.slope_c_per_s = 0.0;
            }
            _ => {}
        }
        // Offset check on the raw sensor path only (an ideal-measurement plant has no sensor).
        let mut hold = false;
        let offset_before = self.offset_c;
        let raw_c = match raw.ok() {
            Some(t) if sensor => {
                let corrected = t.0 - self.offset_c;
                hold = self.watch_offset(corrected, &mut emit);
                Some(Celsius(corrected))
            }
            other => other,
        };
        if raw_c.is_none() {
            self.last_raw_c = None;
            self.pending_step = None;
        }
        // Spikes: a reading far from the filtered value is ignored; three in a row are a real
        // jump (a re-seated probe) and restart the filter.
        let spike = match (raw_c, self.filter.output()) {
            (Some(t), Some(prev)) => (t.0 - prev).abs() > self.cfg.spike_c,
            _ => false,
        };
        if let (Some(t), false) = (raw_c, spike) {
            // In the frame of the offset now in force (it may have changed this sample).
            self.last_raw_c = Some(t.0 - (self.offset_c - offset_before));
        }
        // Three spikes in a row that agree with each other are a real jump (a re-seated probe);
        // three that do not are noise, and the filter keeps its value.
        let consistent = raw_c.is_some_and(|t| (t.0 - self.spike_last_c).abs() < 0.5 * self.cfg.spike_c);
        if let Some(t) = raw_c {
            if spike {
                self.spike_last_c = t.0;
            }
        }
        if spike && self.spike_run > 0 && !consistent {
            self.spike_run = 0;
        }
        if spike {
            self.spike_run = self.spike_run.saturating_add(1);
            self.spike_times.copy_within(0..2, 1);
            self.spike_times[0] = Some(t_ms);
            let burst = self.spike_times[2].is_some_and(|t0| since(t0) <= 3_600_000);
            let quiet = self.spikes_reported_ms.is_none_or(|r| since(r) > 3_600_000);
            if burst && quiet {
                emit(EventKind::SensorSpikes);
                self.spikes_reported_ms = Some(t_ms);
            }
            if self.spike_run >= 3 {
                self.filter.reset();
            }
        } else {
            self.spike_run = 0;
        }
        let temp_c = match raw_c {
            Some(t) if !hold && (!spike || self.spike_run >= 3) => self.filter.step(&self.cfg.filter, t.0),
            // An empty filter (just reset) starts from the reading rather than report nothing.
            Some(t) if self.filter.output().is_none() => self.filter.step(&self.cfg.filter, t.0),
            _ => self.filter.output().unwrap_or(f32::NAN),
        };

        // Supply sag, on the measured module supply.
        if let Some(v) = self.supply_v {
            if v < self.cfg.supply_min_v {
                self.supply_low_run = self.supply_low_run.saturating_add(1);
                if self.supply_low_run >= self.cfg.supply_sag_samples && !self.supply_sag_reported {
                    self.supply_sag_reported = true;
                    emit(EventKind::SupplySag);
                }
            } else {
                self.supply_low_run = 0;
                if v >= self.cfg.supply_min_v + 0.5 {
                    self.supply_sag_reported = false;
                }
            }
        }

        // Shorted supply switch, on the switched rail.
        self.check_switch(&mut emit);

        // 4: setpoint.
        let w = if setpoint_c.is_finite() {
            // Not `f32::clamp`: it panics when min > max, and a panic path costs the firmware
            // ~15 KiB of formatting code. Not `f32::max`/`min` either: calls on the M4F.
            min_f32(max_f32(setpoint_c, self.cfg.setpoint_min_c), self.cfg.setpoint_max_c)
        } else {
            min_f32(max_f32(self.cfg.setpoint_min_c, 4.0), self.cfg.setpoint_max_c)
        };
        let clamped = w != setpoint_c;
        if clamped && !self.setpoint_clamped {
            emit(EventKind::SetpointClamped);
        }
        self.setpoint_clamped = clamped;

        // 5: controller (only with a trustworthy measurement).
        let ci = ControlInput { y_c: temp_c, w_c: w };
        let requested = if self.sensor_fault.is_none() { self.controller.update(&ci) } else { Ok(0.0) };
        // A failed controller's request is NaN: the check below applies the safe state and says so.
        let requested = requested.unwrap_or(f32::NAN);
        let mut duty = if requested.is_finite() {
            Duty::saturating(requested)
        } else {
            emit(EventKind::ControllerNonFinite);
            Duty::OFF
        };

        let status = self.controller.status();
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

        // 6: safety, independent of what the controller wanted.
        if self.sensor_fault.is_none() {
            let mut drop_c = 0.0;
            if let Some(prev) = self.last_temp_c.filter(|p| p.is_finite()) {
                drop_c = prev - temp_c;
                let raw_slope = (temp_c - prev) / self.cfg.ts_s;
                if raw_slope.is_finite() {
                    // Smoothed over ≈ 3 samples so one noisy reading cannot trip the guard.
                    self.slope_c_per_s = 0.7 * self.slope_c_per_s + 0.3 * raw_slope;
                }
            }
            self.last_temp_c = Some(temp_c);
            let predicted = temp_c + min_f32(self.slope_c_per_s, 0.0) * self.cfg.freeze_lookahead_s;
            if !self.freeze_guard && predicted <= self.cfg.freeze_cut_c {
                self.freeze_guard = true;
                self.trip_ms = Some(t_ms);
                emit(EventKind::FreezeGuardTripped);
                // No cooling asked for a minute, and either falling fast without slowing down
                // or tripping for the second time in half an hour: only a shorted SSR does
                // that. A light carrier pulled down from a cool ambient coasts fast after
                // cooling stops, seen through the ≈ 50 s sensor lag, but its fall slows down; a
                // very light one fed by a shorted SSR falls faster every sample (`hter
                // campaign` missions 11338 and 28631). In a hot ambient a shorted SSR only
                // holds the load near its full-cooling floor (≈ 1.5 °C), and the guard trips,
                // opens the supply, releases and trips again every ≈ 15 min (mission 27640); a
                // cold ambient pulls the load down once, and needs hours to warm it past the
                // release and back.
                if !self.supply_cut && self.req_off_run >= 6 {
                    let again = self.unrequested_trip_ms.is_some_and(|t0| since(t0) <= 1_800_000);
                    if again || (self.slope_c_per_s < -0.003 && drop_c >= self.last_drop_c) {
                        self.supply_cut = true;
                        emit(EventKind::SsrStuckOn);
                    } else {
                        self.unrequested_trip_ms = Some(t_ms);
                    }
                }
            }
            // The same fall between trips: within half an hour of a trip, nothing asked for a
            // minute, yet falling more than 0.6 °C a minute and faster every sample. Catches a
            // very light carrier on a shorted SSR after the guard has released, before the next
            // trip comes too late (mission 28631). Not outside that window: the coast after a
            // pull-down does the same for a minute or two on light carriers.
            if !self.supply_cut
                && self.trip_ms.is_some_and(|t0| since(t0) <= 1_800_000)
                && self.req_off_run >= 6
                && drop_c > 0.1
                && drop_c >= self.last_drop_c
                && self.slope_c_per_s < -0.003
            {
                self.supply_cut = true;
                emit(EventKind::SsrStuckOn);
            }
            self.last_drop_c = drop_c;
            // (Exclusive with a trip this sample: that needs `predicted` at or below the cut.)
            if self.freeze_guard && temp_c >= self.cfg.freeze_release_c && predicted > self.cfg.freeze_cut_c {
                self.freeze_guard = false;
                emit(EventKind::FreezeGuardReleased);
            }
        }
        // SSR checks on the duty applied over the last samples (`off_run`/`on_run` count up to
        // the previous sample) and the filtered temperature history.
        if self.sensor_fault.is_none() {
            // A ring (not a shifted array: the shift cost ≈ 100 instructions a sample on the M4F,
            // `cargo xtask pil`). `history_len` counts samples up to HISTORY; `history_head` is
            // where the next one goes.
            self.history[self.history_head] = temp_c;
            self.history_head = if self.history_head + 1 == HISTORY { 0 } else { self.history_head + 1 };
            self.history_len = (self.history_len + 1).min(HISTORY);
            let (head, len) = (self.history_head, self.history_len);
            let ago =
                |n: usize| (n < len).then(|| self.history.get((head + HISTORY - 1 - n) % HISTORY).copied()).flatten();
            // Stuck on: still falling after the SSR has been off for a while, and not slowing
            // down — the coast after full cooling stops decelerates, a shorted SSR does not.
            if !self.supply_cut && self.off_run >= self.cfg.stuck_on_samples {
                if let (Some(t6), Some(t12)) = (ago(6), ago(12)) {
                    let (last, before) = (t6 - temp_c, t12 - t6);
                    if last > self.cfg.stuck_on_drop_c && last >= 0.95 * before {
                        self.supply_cut = true;
                        emit(EventKind::SsrStuckOn);
                    }
                }
            }
            if !self.ssr_off_reported && self.on_run >= self.cfg.stuck_off_samples {
                if let Some(past) = ago(self.cfg.stuck_off_samples as usize) {
                    let fast = temp_c - past > self.cfg.stuck_off_rise_c;
                    let slow = self.on_run >= self.cfg.stuck_off_slow_samples
                        && temp_c - self.on_start_c > self.cfg.stuck_off_slow_rise_c
                        && temp_c > past;
                    if fast || slow {
                        self.ssr_off_reported = true;
                        emit(EventKind::SsrStuckOff);
                    }
                }
            }
            if self.on_run == 0 {
                self.ssr_off_reported = false;
            }
            // Supply probe: a shorted SSR that holds the load below its setpoint at a cooling
            // floor above the freeze guard (a hot day: full cooling barely wins) never trips
            // the guard. Nothing asked for 10 min, 1 °C below the setpoint and still falling:
            // open the supply switch for 5 min (harmless, no cooling is wanted). A shorted SSR
            // stops cooling and the load turns up; a load falling toward a cold ambient does
            // not notice. One probe an hour at most.
            match self.probe {
                Some(t0) => {
                    // Turned up fast with the supply open: it was the supply cooling. A shorted
                    // SSR's cold side warms the load by 0.2–0.4 °C in 30 s once it stops (the
                    // hot side's heat flows back); a lid opening or a warmer ambient that
                    // happens to coincide warms it by ≤ 0.1 °C in 30 s (`hter campaign`
                    // missions 20217, 22550, 25800, 26642).
                    if ago(3).is_some_and(|p| temp_c - p > 0.15) {
                        self.probe = None;
                        if !self.supply_cut {
                            self.supply_cut = true;
                            emit(EventKind::SsrStuckOn);
                        }
                    } else if self.req_off_run == 0 || since(t0) >= 300_000 {
                        self.probe = None; // no verdict: cooling wanted again, or time is up
                    }
                }
                None => {
                    let idle = self.probe_ms.is_none_or(|p| since(p) >= 3_600_000);
                    if idle && !self.supply_cut && self.req_off_run >= 60 && temp_c < w - 1.0 {
                        if let Some(past) = ago(30) {
                            if past - temp_c > 0.05 {
                                self.probe = Some(t_ms);
                                self.probe_ms = Some(t_ms);
                            }
                        }
                    }
                }
            }
        }

        let mode = if self.sensor_fault.is_some() {
            Mode::SensorFault
        } else if self.freeze_guard {
            Mode::FreezeGuard
        } else if self.supply_cut {
            Mode::LimpHome
        } else {
            Mode::Normal
        };
        if mode != Mode::Normal {
            duty = Duty::OFF;
        }
        if mode == Mode::LimpHome {
            // Limp home after a shorted SSR: On-Off through the supply switch (with the SSR
            // commanded alike, in case the short was a false alarm), on 1 °C above the setpoint
            // and off 0.5 °C below it (the coast after full cooling stops carries the load
            // ≈ 1 °C further; the freeze guard still cuts). Cooling that cannot be modulated
            // still keeps vaccines in 2–8 °C, where a latched-off supply would let them warm
            // to the ambient.
            if temp_c >= w + 1.0 {
                self.limp_on = true;
            } else if temp_c <= w - 0.5 {
                self.limp_on = false;
            }
            if self.limp_on {
                duty = Duty::FULL;
            }
        }

        // Supply-switch test opening. The duty stays what the controller asked: told that none
        // was applied, a PI's anti-windup tracking would unwind its integral and let the load
        // warm by 0.6 °C over the next 10 min; the 20 s without supply are a small disturbance
        // it rejects.
        let switch_test = self.switch_test_due(mode, temp_c, w);

        // Lid open: the duty it takes to hold the setpoint jumps. Two averages of the applied
        // duty; the fast one running well above the slow one while the load is held near its
        // setpoint means a sudden heat load (a slow ambient swing moves both together, a
        // setpoint change or pull-down is not "holding").
        let (d, ts) = (duty.get(), self.cfg.ts_s);
        // "Holding": the load reached this setpoint (no pull-down, no setpoint transient) at
        // least one fast time constant ago. The averages start afresh when a pull-down reaches
        // the setpoint, so they never carry its full duty (which a 90 min average would still
        // show at 23 % two hours later and hide a lid opening behind). A load that warms up to
        // the setpoint (a cold ambient) keeps them: its zero duty is the holding duty until then.
        if (w - self.last_w).abs() > 0.01 || !self.last_w.is_finite() {
            self.reached_ms = None;
        }
        self.last_w = w;
        if self.reached_ms.is_none() && (temp_c - w).abs() < 0.3 {
            self.reached_ms = Some(t_ms);
            if self.slope_c_per_s < 0.0 {
                self.duty_n = 0;
                self.duty_fast = None;
            }
        }
        // Exponential averages that begin as the running mean of the samples so far (a weight
        // of at least 1/n), so a fresh start is not biased toward its first sample.
        self.duty_n = self.duty_n.saturating_add(1);
        let first = 1.0 / self.duty_n as f32;
        let fast = self.duty_fast.map_or(d, |f| f + (d - f) * max_f32(ts / self.cfg.lid_fast_s, first));
        self.duty_slow = if self.duty_fast.is_some() {
            self.duty_slow + (d - self.duty_slow) * max_f32(ts / self.cfg.lid_slow_s, first)
        } else {
            d
        };
        self.duty_fast = Some(fast);
        self.since_modulated = if d > 0.0 && d < 1.0 { 0 } else { self.since_modulated.saturating_add(1) };
        let averaged = self.duty_n as f32 * ts >= self.cfg.lid_slow_s;
        // A relay controller (On-Off: only 0 and 1 for the last hour) has a limit cycle whose
        // averages swing as much as a lid opening moves them: no lid check for it (a known gap).
        let modulated = (self.since_modulated as f32) * ts < 3600.0;
        let settled = averaged
            && modulated
            && mode == Mode::Normal
            && self.reached_ms.is_some_and(|r| secs_f32(since(r)) >= self.cfg.lid_fast_s);
        // Either the holding duty jumped (a controller that keeps the load on target), or full
        // cooling for 10 min no longer holds the load within 1 °C (one that cannot, On-Off).
        let duty_jump = (temp_c - w).abs() < 1.0 && fast - self.duty_slow > self.cfg.lid_duty_rise;
        let overwhelmed = self.on_run >= 60 && temp_c > w + 1.0;
        if settled && !self.lid_reported && (duty_jump || overwhelmed) {
            self.lid_reported = true;
            emit(EventKind::LidOpen);
        } else if self.lid_reported && fast - self.duty_slow < 0.25 * self.cfg.lid_duty_rise {
            self.lid_reported = false;
        }
        self.off_run = if duty.get() == 0.0 { self.off_run.saturating_add(1) } else { 0 };
        if self.on_run == 0 && duty.get() >= 0.9 {
            self.on_start_c = temp_c;
        }
        self.on_run = if duty.get() >= 0.9 { self.on_run.saturating_add(1) } else { 0 };
        self.req_off_run = if requested <= 0.0 { self.req_off_run.saturating_add(1) } else { 0 };

        // 7: tell the controller what was really applied.
        if self.sensor_fault.is_none() {
            self.controller.track(&ci, duty.get());
        }

        StepOutput {
            raw_c,
            temp_c: Celsius(temp_c),
            setpoint_c: Celsius(w),
            requested,
            duty,
            // The supply switch also opens whenever the freeze guard holds cooling off: it costs
            // nothing then, and it is the only thing that stops a shorted SSR before the SSR
            // check has seen enough to be sure.
            supply_enable: self.note_supply_enable(
                !switch_test
                    && if self.supply_cut {
                        mode == Mode::LimpHome && self.limp_on
                    } else {
                        // No cooling at all without a trustworthy reading either: a shorted SSR
                        // must not cool blind.
                        !(self.freeze_guard || self.probe.is_some() || mode == Mode::SensorFault)
                    },
            ),
            mode,
            events,
            status,
        }
    }

    /// Counts → calibrated °C, or the fault the counts reveal.
    fn measure(&self, counts: u32) -> Result<Celsius, EventKind> {
        let ohms = self.cfg.adc.ohms(counts).map_err(|e| match e {
            AdcError::Open => EventKind::SensorOpen,
            AdcError::Short => EventKind::SensorShort,
            AdcError::ReferenceOutOfRange => EventKind::ReferenceOutOfRange,
        })?;
        let t = self.cfg.rtd.temperature(ohms).map_err(|_| EventKind::SensorOutOfRange)?;
        self.plausible(self.cfg.cal.apply(t))
    }

    /// The plausibility range check of a calibrated temperature.
    fn plausible(&self, t: Celsius) -> Result<Celsius, EventKind> {
        if t.0.is_finite() && (self.cfg.plausible_min_c..=self.cfg.plausible_max_c).contains(&t.0) {
            Ok(t)
        } else {
            Err(EventKind::SensorOutOfRange)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{AnyController, OnOff, OnOffConfig};
    use crate::units::Ohms;

    pub(super) fn counts_at(t: f32) -> u32 {
        let cfg = CarrierConfig::DEFAULT;
        cfg.adc.counts(cfg.rtd.resistance(Celsius(t)).unwrap())
    }

    pub(super) fn pi_carrier() -> Carrier<AnyController> {
        Carrier::new(CarrierConfig::DEFAULT, AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)))
    }

    #[test]
    fn measures_within_the_resolution() {
        let mut c = pi_carrier();
        let out = c.step(&StepInput { t_ms: 0, counts: counts_at(4.0), setpoint_c: 4.0 });
        assert!((out.temp_c.0 - 4.0).abs() < 0.01, "{:?}", out.temp_c);
        assert_eq!(out.mode, Mode::Normal);
        assert!(out.supply_enable);
    }

    #[test]
    fn open_sensor_stops_cooling_on_the_first_sample_and_recovers() {
        let mut c = pi_carrier();
        let warm = c.step(&StepInput { t_ms: 0, counts: counts_at(10.0), setpoint_c: 4.0 });
        assert!(warm.duty.get() > 0.5);
        let open = c.step(&StepInput { t_ms: 10_000, counts: 65_535, setpoint_c: 4.0 });
        assert_eq!(open.duty, Duty::OFF);
        assert_eq!(open.mode, Mode::SensorFault);
        assert_eq!(open.events.iter().next().map(|e| (e.kind, e.t_ms)), Some((EventKind::SensorOpen, 10_000)));
        // No repeated event while the fault persists.
        let still = c.step(&StepInput { t_ms: 20_000, counts: 65_535, setpoint_c: 4.0 });
        assert!(still.events.is_empty());
        let back = c.step(&StepInput { t_ms: 30_000, counts: counts_at(5.0), setpoint_c: 4.0 });
        assert_eq!(back.mode, Mode::Normal);
        assert_eq!(back.events.iter().next().map(|e| e.kind), Some(EventKind::SensorRecovered));
    }

    #[test]
    fn short_and_implausible_readings_are_faults() {
        let mut c = pi_carrier();
        let short = c.step(&StepInput { t_ms: 0, counts: 10, setpoint_c: 4.0 });
        assert_eq!(short.events.iter().next().map(|e| e.kind), Some(EventKind::SensorShort));
        let cold = CarrierConfig::DEFAULT.adc.counts(Ohms(80.0)); // ≈ −50 °C
        let out = c.step(&StepInput { t_ms: 10_000, counts: cold, setpoint_c: 4.0 });
        assert_eq!(out.events.iter().next().map(|e| e.kind), Some(EventKind::SensorOutOfRange));
        assert_eq!(out.duty, Duty::OFF);
    }

    #[test]
    fn setpoint_below_two_degrees_is_clamped() {
        let mut c = pi_carrier();
        let out = c.step(&StepInput { t_ms: 0, counts: counts_at(4.0), setpoint_c: -5.0 });
        assert_eq!(out.setpoint_c.0, 2.0);
        assert_eq!(out.events.iter().next().map(|e| e.kind), Some(EventKind::SetpointClamped));
        let nan = c.step(&StepInput { t_ms: 10_000, counts: counts_at(4.0), setpoint_c: f32::NAN });
        assert!((2.0..=8.0).contains(&nan.setpoint_c.0));
    }

    /// Feeds a load falling at `rate_c_per_s` from 9 °C under an On-Off controller that keeps
    /// asking for cooling; returns the measured temperature at which the guard cut it.
    fn guard_trip(rate_c_per_s: f32) -> f32 {
        let onoff = OnOff::new(OnOffConfig { hysteresis_c: 0.1 });
        let mut c = Carrier::new(CarrierConfig::DEFAULT, AnyController::OnOff(onoff));
        let mut temp = 9.0f32;
        let mut t = 0u64;
        while temp > 0.0 {
            let out = c.step(&StepInput { t_ms: t, counts: counts_at(temp), setpoint_c: 2.0 });
            if out.mode == Mode::FreezeGuard {
                assert_eq!(out.duty, Duty::OFF);
                assert!(out.events.iter().any(|e| e.kind == EventKind::FreezeGuardTripped));
                // It holds until the load is back above the release threshold.
                for k in 1..20 {
                    let back = c.step(&StepInput { t_ms: t + 10_000 * k, counts: counts_at(2.2), setpoint_c: 2.0 });
                    assert_eq!(back.duty, Duty::OFF);
                }
                // Back above 2.5 °C (through the filter): cooling may resume.
                let released = (0..3).any(|k| {
                    let warm =
                        c.step(&StepInput { t_ms: t + 200_000 + 10_000 * k, counts: counts_at(2.8), setpoint_c: 2.0 });
                    warm.mode == Mode::Normal && warm.events.iter().any(|e| e.kind == EventKind::FreezeGuardReleased)
                });
                assert!(released);
                return out.temp_c.0;
            }
            temp -= rate_c_per_s * 10.0;
            t += 10_000;
        }
        panic!("guard never tripped");
    }

    #[test]
    fn freeze_guard_cuts_cooling_ahead_of_a_falling_load() {
        // Slow fall (0.06 °C/min): the guard acts close to its 1.5 °C threshold.
        let slow = guard_trip(0.001);
        assert!(slow <= 1.7 && slow > 1.0, "slow fall tripped at {slow}");
        // Fast fall (0.6 °C/min, full cooling): it acts ≈ 120 s ahead, above 2 °C.
        let fast = guard_trip(0.01);
        assert!(fast > 2.0 && fast <= 2.8, "fast fall tripped at {fast}");
    }
}

#[cfg(test)]
mod robustness {
    use super::*;
    use crate::control::AnyController;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

        /// Arbitrary conversions (including stuck runs, rails and noise) never panic, never give
        /// a non-finite or out-of-range duty.
        #[test]
        fn arbitrary_counts_give_a_valid_duty(counts in proptest::collection::vec(prop_oneof![any::<u32>(), 0u32..70_000, Just(49_900u32)], 1..400)) {
            let mut c = Carrier::new(CarrierConfig::DEFAULT, AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)));
            for (k, n) in counts.iter().enumerate() {
                let out = c.step(&StepInput { t_ms: k as u64 * 10_000, counts: *n, setpoint_c: 4.0 });
                prop_assert!(out.duty.get().is_finite() && (0.0..=1.0).contains(&out.duty.get()));
            }
        }
    }

    #[test]
    fn a_week_of_identical_counts_does_not_overflow() {
        let mut c =
            Carrier::new(CarrierConfig::DEFAULT, AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)));
        for k in 0..70_000u32 {
            let out = c.step(&StepInput { t_ms: k as u64 * 10_000, counts: 49_900, setpoint_c: 4.0 });
            if k > 20 {
                assert_eq!(out.mode, Mode::SensorFault);
            }
        }
    }
}

#[cfg(test)]
mod switch_and_reference {
    use super::tests::{counts_at, pi_carrier as carrier};
    use super::*;
    use crate::control::AnyController;

    /// Runs `n` samples holding 5 °C at setpoint `w` with the rail reading what a switch that is
    /// `shorted` (or not) shows; returns the samples that opened the switch and when the short
    /// was reported.
    fn run(n: u32, shorted: bool, w: f32) -> (Vec<u32>, Option<u32>) {
        let mut c = carrier();
        let (mut opened, mut found, mut enabled) = (Vec::new(), None, true);
        for k in 0..n {
            c.observe_supply_v(12.0);
            c.observe_switched_rail_v(if enabled || shorted { 11.9 } else { 0.01 });
            let out = c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: w });
            if out.events.iter().any(|e| e.kind == EventKind::SupplySwitchShorted) {
                assert!(found.is_none(), "reported twice");
                found = Some(k);
            }
            enabled = out.supply_enable;
            if !enabled {
                // The controller's duty stays (the switch alone opens).
                assert_eq!(out.duty, Duty::saturating(out.requested), "sample {k}");
                assert_eq!(out.mode, Mode::Normal);
                opened.push(k);
            }
        }
        (opened, found)
    }

    #[test]
    fn a_shorted_switch_is_found_by_the_test_opening() {
        let (opened, found) = run(1600, true, 5.1);
        assert_eq!(opened[..2], [719, 720], "first test after two hours, two samples");
        assert_eq!(found, Some(721), "judged on the second reading with the switch open");
        // Found: no more test openings.
        assert_eq!(opened.len(), 2, "{opened:?}");
        let (opened, found) = run(1600, false, 5.1);
        assert_eq!(found, None);
        assert_eq!(opened, [719, 720, 1440, 1441], "one test every two hours");
        // A load above its setpoint is never opened on (the test would warm it further).
        assert_eq!(run(1600, true, 4.9), (vec![], None));
    }

    #[test]
    fn no_sense_no_test_and_no_check() {
        let mut c = carrier();
        for k in 0..1600u32 {
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.supply_enable && out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted));
        }
        // Test openings off (an identification run): the sense alone opens nothing.
        let cfg = CarrierConfig { switch_test_interval_samples: 0, ..CarrierConfig::DEFAULT };
        let mut c = Carrier::new(cfg, AnyController::Pi(crate::profile::pi(CarrierConfig::DEFAULT.ts_s)));
        for k in 0..1600u32 {
            c.observe_switched_rail_v(11.9);
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.supply_enable, "sample {k}");
        }
    }

    #[test]
    fn a_rail_that_bleeds_down_slowly_is_no_short() {
        // The first reading after opening still shows the rail's charge: not judged.
        let mut c = carrier();
        let (mut enabled, mut open_for, mut opened) = (true, 0, 0);
        for k in 0..1600u32 {
            c.observe_supply_v(12.0);
            open_for = if enabled { 0 } else { open_for + 1 };
            c.observe_switched_rail_v(if enabled || open_for == 1 { 11.9 } else { 0.05 });
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted), "sample {k}");
            enabled = out.supply_enable;
            opened += u32::from(!enabled);
        }
        assert_eq!(opened, 4, "two test openings were judged");
        // The floor: a dead supply (0 V) whose rail reads a little noise is not a short.
        let mut c = carrier();
        for k in 0..1600u32 {
            c.observe_supply_v(0.0);
            c.observe_switched_rail_v(0.3);
            let out =
                c.step(&StepInput { t_ms: u64::from(k) * 10_000, counts: counts_at(5.0) + k % 3, setpoint_c: 5.1 });
            assert!(out.events.iter().all(|e| e.kind != EventKind::SupplySwitchShorted), "sample {k}");
            opened += u32::from(!out.supply_enable);
        }
        assert_eq!(opened, 8, "and judged twice more");
    }

    #[test]
    fn a_reference_fault_is_a_sensor_fault_until_a_valid_sample() {
        let mut c = carrier();
        let warm = c.step(&StepInput { t_ms: 0, counts: counts_at(9.0), setpoint_c: 4.0 });
        assert!(warm.duty.get() > 0.0);
        let bad = StepInput { t_ms: 10_000, counts: counts_at(9.0), setpoint_c: 4.0 };
        let out = c.step_with_reference_fault(&bad);
        assert_eq!((out.mode, out.duty, out.supply_enable), (Mode::SensorFault, Duty::OFF, false));
        assert_eq!(out.events.iter().map(|e| e.kind).collect::<Vec<_>>(), [EventKind::ReferenceOutOfRange]);
        assert!(crate::alarm::needs_attention(EventKind::ReferenceOutOfRange));
        let again = c.step_with_reference_fault(&StepInput { t_ms: 20_000, ..bad });
        assert!(again.events.is_empty(), "reported once while it lasts");
        let back = c.step(&StepInput { t_ms: 30_000, ..bad });
        assert_eq!(back.mode, Mode::Normal);
        assert_eq!(back.events.iter().map(|e| e.kind).collect::<Vec<_>>(), [EventKind::SensorRecovered]);
    }
}
