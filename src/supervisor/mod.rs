//! The safety supervisor: what the step does about safety, independent of what the controller
//! wants.
//!
//! Cooling vaccines is safe when it stops: a load that warms a little is an alarm, one that
//! freezes is lost. So every detector here, when in doubt, takes cooling away — the duty and,
//! through the supply-enable switch, the modules' supply — and the controller only drives when
//! nothing holds the outputs.
//!
//! ## Modes
//! The supervisor's mode, [`State`], has two parts that change independently, each a
//! state-carrying enum whose variants hold what that state needs, and each edge one named
//! transition (a method of [`State`]): [`Hold`], what holds cooling off, and [`Drive`], who
//! drives it when nothing does.
//!
//! ```text
//!   Hold:                guard_tripped
//!   +-------------+ --------------------> +-------------+
//!   |    Free     |                       | FreezeGuard |
//!   +-------------+ <-------------------- +-------------+
//!      |      ^          guard_released      |      ^
//!      |      | sensor_recovered             |      | sensor_recovered
//!      |      | (guard: false)               |      | (guard: true)
//!      | sensor_failed                       | sensor_failed
//!      v      |                              v      |
//!   +------------------------------------------------+   sensor_failed
//!   | SensorFault { kind, guard }                    | <-----------------+
//!   +------------------------------------------------+ ------------------+
//!                                                        (another kind)
//!
//!   Drive:
//!   Controller { probe: None } --probe_started--> Controller { probe: Some(t0) }
//!              ^                                              |
//!              +------------------- probe_ended --------------+
//!
//!   Controller { .. } --ssr_shorted--> LimpHome { supply_on }   (latched until reset)
//!                                        |    ^
//!                                        +----+ limp_switched
//! ```
//!
//! `sensor_failed` also comes from a plausible reading that jumped by more than the load can
//! move and stays there (the spike filter's real jump, reported as `sensor_offset`): that
//! fault ends with the first plausible reading [`sensor::SensorConfig::stuck_s`] after the
//! jump, not before, so that a front end stuck at the new level is found before it cools.
//!
//! The summary the step reports, [`Mode`], is `SensorFault` or `FreezeGuard` while those hold
//! cooling off, and otherwise `Normal` or `LimpHome` by who drives. During a sensor fault
//! nothing that needs a reading runs, so the freeze guard's verdict (`guard`), the probe and
//! limp home's supply state wait for the reading to come back.
//!
//! ## Order of the checks in one sample
//! The order is fixed here, in `Supervisor::check` (before the controller) and
//! `Supervisor::guard` (after it), and it is also the order of the sample's events:
//! 1. the sensor: fault diagnosis and recovery (`sensor::diagnose`; the stuck-converter check
//!    has run on the raw counts during the conversion), then the offset watch and the spike
//!    filter, which decide what the measurement filter takes ([`sensor`]);
//! 2. the supply sag ([`supply`]), then the supply switch on its rail ([`switch`], which needs
//!    the supply measured);
//! 3. — the controller runs, with a trusted reading only —
//! 4. with a trusted reading: the freeze guard's trend ([`freeze`]), its trip and the two SSR
//!    stuck-on verdicts that come with a trip ([`ssr`], paths 1 and 2), its release; then the
//!    SSR checks on the temperature history (stuck on after the off-run, stuck off, the supply
//!    probe);
//! 5. the mode's outputs: no duty unless the controller drives, limp home's On-Off (on the
//!    freeze guard's look-ahead, [`ssr::LimpConfig`]), the supply
//!    switch open below the floor with nothing asked and the load still
//!    ([`freeze::FreezeConfig::idle_open_c`]);
//! 6. the supply switch's test pulse, the lid detector ([`lid`]) on the applied duty;
//! 7. last, the SSR monitor counts this sample's duty: every check above saw the runs up to the
//!    previous sample.
//!
//! ## Units
//! Every setting is in seconds, °C, V or duty. The sample counts they mean are derived from the
//! sample period once, when the supervisor is built (rounded to the nearest sample).

pub mod freeze;
pub mod lid;
#[cfg(feature = "module-sense")]
pub mod module;
pub mod sensor;
pub mod ssr;
pub mod supply;
pub mod switch;

use crate::control::ControlInput;
use crate::event::EventKind;
use crate::filter::FirstOrder;
use crate::step::{CarrierConfig, Mode};
use crate::units::{Celsius, Duty};

use freeze::{FreezeConfig, FreezeGuard};
use lid::{LidConfig, LidDetector, LidInput};
use sensor::{Diagnosis, Reading, SensorChecks, SensorConfig};
use ssr::{Probe, SsrConfig, SsrMonitor};
use supply::{SupplyConfig, SupplyMonitor};
use switch::{SwitchCheck, SwitchConfig};

/// Settings of every detector.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SupervisorConfig {
    /// Sensor checks: stuck converter, spikes, offset.
    pub sensor: SensorConfig,
    /// Freeze guard.
    pub freeze: FreezeConfig,
    /// SSR monitor: stuck on, stuck off, the supply probe, limp home.
    pub ssr: SsrConfig,
    /// Supply sag.
    pub supply: SupplyConfig,
    /// Supply-switch check.
    pub switch: SwitchConfig,
    /// Lid detector.
    pub lid: LidConfig,
}

impl SupervisorConfig {
    /// The reference board's settings.
    pub const DEFAULT: SupervisorConfig = SupervisorConfig {
        sensor: SensorConfig::DEFAULT,
        freeze: FreezeConfig::DEFAULT,
        ssr: SsrConfig::DEFAULT,
        supply: SupplyConfig::DEFAULT,
        switch: SwitchConfig::DEFAULT,
        lid: LidConfig::DEFAULT,
    };

    /// A board whose modules are on a buck drive (the firmware's `buck` build, `hter sim --drive
    /// buck`): the lid check in the SSR's units of cooling ([`LidConfig::BUCK`]) and the
    /// shorted drive's 45 min trip window ([`ssr::StuckOnConfig::BUCK`]); the rest as
    /// [`Self::DEFAULT`].
    #[cfg(feature = "buck-drive")]
    pub const BUCK: SupervisorConfig = SupervisorConfig {
        ssr: SsrConfig { stuck_on: ssr::StuckOnConfig::BUCK, ..SsrConfig::DEFAULT },
        lid: LidConfig::BUCK,
        ..Self::DEFAULT
    };
}

/// A supervisor setting its detectors cannot honour at the sample period: the field, as its
/// path in [`SupervisorConfig`] spells it (`"ssr.stuck_on.window_s"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WindowError(pub &'static str);

impl SupervisorConfig {
    /// Checks that every duration is a finite, non-negative number of seconds whose sample count
    /// fits its counter at the sample period `ts_s` (a count that saturated would silently
    /// shorten the check), and that every window the SSR monitor looks back over is at least one
    /// sample and shorter than the history it keeps ([`ssr::HISTORY`] samples): a longer window
    /// never has its sample, and its check would never fire. And that the supply probe's
    /// [`ssr::ProbeConfig::yield_within_c`] is a finite, non-negative temperature and
    /// [`ssr::StuckOnConfig::unrequested_duty`] a duty in [0, 1), and that the most the offset
    /// watch subtracts, [`sensor::OffsetConfig::max_comp_c`], is one the history can restore.
    pub const fn validate(&self, ts_s: f32) -> Result<(), WindowError> {
        if !(ts_s.is_finite() && ts_s > 0.0) {
            return Err(WindowError("ts_s"));
        }
        let (s, on, off, p) = (&self.sensor, &self.ssr.stuck_on, &self.ssr.stuck_off, &self.ssr.probe);
        // (seconds, largest count its counter holds, field)
        let counted: [(f32, u32, &'static str); 13] = [
            (s.stuck_s, u16::MAX as u32, "sensor.stuck_s"),
            (s.spike.jump_s, u8::MAX as u32, "sensor.spike.jump_s"),
            (s.offset.confirm_s, u8::MAX as u32, "sensor.offset.confirm_s"),
            (on.unrequested_s, u16::MAX as u32, "ssr.stuck_on.unrequested_s"),
            (on.off_s, u16::MAX as u32, "ssr.stuck_on.off_s"),
            (off.on_s, u16::MAX as u32, "ssr.stuck_off.on_s"),
            (off.slow_on_s, u16::MAX as u32, "ssr.stuck_off.slow_on_s"),
            (off.stalled_on_s, u16::MAX as u32, "ssr.stuck_off.stalled_on_s"),
            (p.unrequested_s, u16::MAX as u32, "ssr.probe.unrequested_s"),
            (self.lid.overwhelmed_s, u16::MAX as u32, "lid.overwhelmed_s"),
            (self.supply.sag_s, u8::MAX as u32, "supply.sag_s"),
            (self.switch.settle_s, u8::MAX as u32, "switch.settle_s"),
            (self.switch.test_interval_s, u32::MAX, "switch.test_interval_s"),
        ];
        let mut i = 0;
        while i < counted.len() {
            let (secs, max, field) = counted[i];
            if !counts_within(secs, ts_s, max) {
                return Err(WindowError(field));
            }
            i += 1;
        }
        // The millisecond timers ([`ms`]: u32, 49 days).
        let timed: [(f32, &'static str); 4] = [
            (s.spike.window_s, "sensor.spike.window_s"),
            (on.trip_window_s, "ssr.stuck_on.trip_window_s"),
            (p.open_s, "ssr.probe.open_s"),
            (p.interval_s, "ssr.probe.interval_s"),
        ];
        let mut i = 0;
        while i < timed.len() {
            let (secs, field) = timed[i];
            if !counts_within(secs, 0.001, u32::MAX) {
                return Err(WindowError(field));
            }
            i += 1;
        }
        // (seconds, how many of it the ring must hold, field): the stuck-on check compares the
        // fall over the last window with the window before, so it reads two windows back.
        let looked_back: [(f32, u32, &'static str); 4] = [
            (on.window_s, 2, "ssr.stuck_on.window_s"),
            (off.on_s, 1, "ssr.stuck_off.on_s"),
            (p.fall_window_s, 1, "ssr.probe.fall_window_s"),
            (p.turn_up_window_s, 1, "ssr.probe.turn_up_window_s"),
        ];
        let mut i = 0;
        while i < looked_back.len() {
            let (secs, times, field) = looked_back[i];
            if !counts_within(secs, ts_s, u16::MAX as u32) {
                return Err(WindowError(field));
            }
            let n = samples_u32(secs, ts_s);
            if n == 0 || n * times >= ssr::HISTORY as u32 {
                return Err(WindowError(field));
            }
            i += 1;
        }
        // The probe's margin is a distance below the setpoint (a NaN would compare false and
        // leave the probe deaf to every request).
        let y = p.yield_within_c;
        if !(y.is_finite() && y >= 0.0) {
            return Err(WindowError("ssr.probe.yield_within_c"));
        }
        // No cooling requested is a duty below full (a NaN would compare false: no run of it
        // would ever start, and stuck-on paths 1 and 2 and the probe would be off).
        let u = on.unrequested_duty;
        if !(u >= 0.0 && u < 1.0) {
            return Err(WindowError("ssr.stuck_on.unrequested_duty"));
        }
        // The history keeps the offset subtracted in the channel's terms, up to
        // `SensorOffset::MAX_C`: the most the watch subtracts must fit it through the lowest
        // calibration gain, or a restart would restore less than was subtracted (the freezing
        // side; a NaN would compare false and subtract nothing).
        let m = s.offset.max_comp_c;
        if !(m >= 0.0 && m <= crate::calib::MIN_GAIN * crate::persist::SensorOffset::MAX_C) {
            return Err(WindowError("sensor.offset.max_comp_c"));
        }
        Ok(())
    }
}

/// Whether `s` seconds is a finite, non-negative duration of at most `max` samples of `ts_s`
/// (rounded to the nearest, as [`samples_u32`] counts them).
const fn counts_within(s: f32, ts_s: f32, max: u32) -> bool {
    s.is_finite() && s >= 0.0 && s / ts_s + 0.5 < max as f32 + 1.0
}

/// The samples in `s` seconds at the sample period `ts_s`, rounded to the nearest (saturating;
/// 0 for a negative or NaN duration).
pub(crate) const fn samples_u32(s: f32, ts_s: f32) -> u32 {
    (s / ts_s + 0.5) as u32
}

/// [`samples_u32`] for a u16 count.
pub(crate) const fn samples_u16(s: f32, ts_s: f32) -> u16 {
    (s / ts_s + 0.5) as u16
}

/// [`samples_u32`] for a u8 count.
pub(crate) const fn samples_u8(s: f32, ts_s: f32) -> u8 {
    (s / ts_s + 0.5) as u8
}

/// `s` seconds in whole milliseconds (u32: f32 → u64 is a library call on the M4F; 49 days at
/// most).
pub(crate) const fn ms(s: f32) -> u32 {
    (s * 1000.0 + 0.5) as u32
}

/// Time from `t0` to `t_ms`, ms (0 if the clock went back: "just now").
pub(crate) fn since(t_ms: u64, t0: u64) -> u64 {
    t_ms.saturating_sub(t0)
}

/// Who drives cooling when no safety action holds it off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive {
    /// The controller, through the SSR (the supply switch is open while a supply probe is under
    /// way).
    Controller {
        /// When the probe under way began, ms.
        probe: Option<u64>,
    },
    /// The SSR was found shorted: cooling is switched On-Off through the supply-enable switch
    /// ([`ssr::LimpConfig`]), the controller is idle. Latched until reset.
    LimpHome {
        /// The supply is switched on.
        supply_on: bool,
    },
}

/// What holds cooling off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hold {
    /// Nothing: the [`Drive`] drives.
    Free,
    /// The freeze guard, until the load is warm again.
    FreezeGuard,
    /// A faulty sensor, until it reads plausibly again.
    SensorFault {
        /// The fault reported.
        kind: EventKind,
        /// The freeze guard held when the fault began, and holds again when it ends.
        guard: bool,
    },
}

/// The supervisor's mode (see the state diagram in the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct State {
    /// What holds cooling off.
    pub hold: Hold,
    /// Who drives it otherwise.
    pub drive: Drive,
}

impl State {
    /// Power-up: nothing holds, the controller drives, no probe.
    pub const START: State = State { hold: Hold::Free, drive: Drive::Controller { probe: None } };

    /// The sensor reads a fault `kind` (a first fault, or another kind than the one in force).
    pub fn sensor_failed(&mut self, kind: EventKind) {
        let guard = match self.hold {
            Hold::Free => false,
            Hold::FreezeGuard => true,
            Hold::SensorFault { guard, .. } => guard,
        };
        self.hold = Hold::SensorFault { kind, guard };
    }

    /// The sensor reads plausibly again: back to what the fault interrupted.
    pub fn sensor_recovered(&mut self) {
        if let Hold::SensorFault { guard, .. } = self.hold {
            self.hold = if guard { Hold::FreezeGuard } else { Hold::Free };
        }
    }

    /// The freeze guard trips.
    pub fn guard_tripped(&mut self) {
        if self.hold == Hold::Free {
            self.hold = Hold::FreezeGuard;
        }
    }

    /// The freeze guard releases.
    pub fn guard_released(&mut self) {
        if self.hold == Hold::FreezeGuard {
            self.hold = Hold::Free;
        }
    }

    /// The SSR is found shorted: limp home from now on, supply off until limp home switches it.
    pub fn ssr_shorted(&mut self) {
        if let Drive::Controller { .. } = self.drive {
            self.drive = Drive::LimpHome { supply_on: false };
        }
    }

    /// A supply probe begins at `t_ms`.
    pub fn probe_started(&mut self, t_ms: u64) {
        if let Drive::Controller { probe } = &mut self.drive {
            *probe = Some(t_ms);
        }
    }

    /// The supply probe ends.
    pub fn probe_ended(&mut self) {
        if let Drive::Controller { probe } = &mut self.drive {
            *probe = None;
        }
    }

    /// Limp home switches the supply on or off.
    pub fn limp_switched(&mut self, on: bool) {
        if let Drive::LimpHome { supply_on } = &mut self.drive {
            *supply_on = on;
        }
    }

    /// The fault in force, if the sensor is faulty.
    pub fn sensor_fault(self) -> Option<EventKind> {
        match self.hold {
            Hold::SensorFault { kind, .. } => Some(kind),
            _ => None,
        }
    }

    /// Whether a short was found (limp home drives).
    pub fn shorted(self) -> bool {
        matches!(self.drive, Drive::LimpHome { .. })
    }

    /// The summary the step reports.
    pub fn mode(self) -> Mode {
        match (self.hold, self.drive) {
            (Hold::Free, Drive::Controller { .. }) => Mode::Normal,
            (Hold::Free, Drive::LimpHome { .. }) => Mode::LimpHome,
            (Hold::FreezeGuard, _) => Mode::FreezeGuard,
            (Hold::SensorFault { .. }, _) => Mode::SensorFault,
        }
    }

    /// The level of the supply-enable output in this mode (before the idle opening below the
    /// floor): closed while the controller drives without a probe, and while limp home has it on. It also opens
    /// whenever the freeze guard holds cooling off: that costs nothing, and it is the only thing
    /// that stops a shorted SSR before the SSR checks have seen enough to be sure. No cooling
    /// at all without a trustworthy reading either: a shorted SSR must not cool blind.
    pub fn supply_enable(self) -> bool {
        match (self.hold, self.drive) {
            (Hold::Free, Drive::Controller { probe }) => probe.is_none(),
            (Hold::Free, Drive::LimpHome { supply_on }) => supply_on,
            (Hold::FreezeGuard | Hold::SensorFault { .. }, _) => false,
        }
    }
}

/// What the supervisor decided for this sample's outputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Verdict {
    /// Duty to apply to the SSR.
    pub(crate) duty: Duty,
    /// Level of the supply-enable output.
    pub(crate) supply_enable: bool,
    /// Ask the board for a supply-switch test pulse ([`switch`]).
    pub(crate) switch_test: bool,
    /// The mode after this sample.
    pub(crate) mode: Mode,
}

/// The supervisor: its mode and every detector's state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Supervisor {
    /// The sample period, s.
    ts_s: f32,
    state: State,
    sensor: SensorChecks,
    /// Samples left before a jump's sensor fault may end on a plausible reading (0 outside
    /// one); it lasts the stuck-converter check's window ([`SensorConfig::stuck_s`]).
    distrust_left: u16,
    freeze: FreezeGuard,
    ssr: SsrMonitor,
    /// The module-side sense's check (a board with the sense only).
    #[cfg(feature = "module-sense")]
    module: module::ModuleSense,
    supply: SupplyMonitor,
    switch: SwitchCheck,
    lid: LidDetector,
}

impl Supervisor {
    /// A supervisor that has not seen a sample, for the sample period `ts_s`. Inline, so that
    /// where the configuration is a constant its sample counts fold into constants too.
    #[inline]
    pub(crate) fn new(cfg: &SupervisorConfig, ts_s: f32) -> Self {
        Supervisor {
            ts_s,
            state: State::START,
            sensor: SensorChecks::new(&cfg.sensor, ts_s),
            distrust_left: 0,
            freeze: FreezeGuard::new(&cfg.freeze),
            ssr: SsrMonitor::new(&cfg.ssr, ts_s),
            #[cfg(feature = "module-sense")]
            module: module::ModuleSense::default(),
            supply: SupplyMonitor::new(&cfg.supply, ts_s),
            switch: SwitchCheck::new(&cfg.switch, ts_s),
            lid: LidDetector::new(&cfg.lid, ts_s),
        }
    }

    /// Whether the reading is trusted (no sensor fault): the controller runs only then.
    pub(crate) fn trusts_reading(&self) -> bool {
        self.state.sensor_fault().is_none()
    }

    /// The measured module supply for the next sample, V (`None`: not read).
    pub(crate) fn observe_supply_v(&mut self, v: Option<f32>) {
        self.supply.observe(v);
    }

    /// The switched supply rail for the next sample, V (`None`: not read).
    pub(crate) fn observe_switched_rail_v(&mut self, v: Option<f32>) {
        self.switch.observe(v);
    }

    /// The modules' voltage read in the conversion window, V, for the next sample ([`module`]).
    #[cfg(feature = "module-sense")]
    pub(crate) fn observe_module_v(&mut self, v: f32) {
        self.module.observe(v);
    }

    /// The switched supply rail read at the end of a test pulse, V, for the next sample.
    pub(crate) fn observe_switch_test_v(&mut self, v: f32) {
        self.switch.observe_pulse(v);
    }

    /// Holds the supply switch's periodic test pulses off, or lets them resume.
    pub(crate) fn hold_switch_tests(&mut self, held: bool) {
        self.switch.hold_tests(held);
    }

    /// The sensor offset subtracted from every reading, °C (calibrated).
    pub(crate) fn sensor_offset_c(&self) -> f32 {
        self.sensor.offset_c()
    }

    /// Restores the sensor offset a previous boot subtracted, °C (calibrated).
    pub(crate) fn restore_sensor_offset(&mut self, cfg: &SupervisorConfig, offset_c: f32) {
        self.sensor.restore_offset(&cfg.sensor, offset_c);
    }

    /// Whether the SSR was found shorted (limp home drives, latched).
    pub(crate) fn shorted(&self) -> bool {
        self.state.shorted()
    }

    /// Limps home from the next sample on, as on a short found now but without its event: a
    /// previous boot found it ([`crate::persist::HistoryRecord::ssr_shorted`]).
    pub(crate) fn restore_short(&mut self) {
        self.state.ssr_shorted();
    }

    /// Clears the sensor offset: the offset-corrected reading moves up by it, which every check
    /// and the filter take over as a new line through the channel (the checks carry what they
    /// hold over to it, as for [`Self::recalibrated`]).
    pub(crate) fn clear_sensor_offset(&mut self, cfg: &SupervisorConfig, filter: &mut FirstOrder) {
        let shift = crate::calib::Recalibration { gain: 1.0, shift_c: self.sensor.offset_c() };
        self.carry_over(cfg, &shift, filter);
        self.sensor.restore_offset(&cfg.sensor, 0.0);
    }

    /// The reading moves by `r` and is neither the load moving nor the sensor stepping: the
    /// sensor checks, the measurement filter, the freeze guard's slope and the SSR monitor's
    /// history are carried over to it (a new calibration, a cleared offset).
    fn carry_over(&mut self, cfg: &SupervisorConfig, r: &crate::calib::Recalibration, filter: &mut FirstOrder) {
        let r = self.sensor.recalibrated(&cfg.sensor, r, filter);
        self.freeze.recalibrated(&r);
        self.ssr.recalibrated(&r);
    }

    /// The stuck-converter check on this sample's raw counts: whether they are stuck.
    pub(crate) fn counts_stuck(&mut self, counts: u32) -> bool {
        self.sensor.stuck.run(counts)
    }

    /// The channel's calibration changed from `old` to `new` (`Carrier::set_calibration`, the
    /// board interface's `set cal_ice`/`cal_warm`; the next sample reads through `new`). A new
    /// line is not a move of the load nor a step of the sensor: the sensor checks, the
    /// measurement filter, the freeze guard's slope and the SSR monitor's history are carried
    /// over to it ([`crate::calib::Recalibration`]), so that the next reading continues them.
    /// The reported temperature moves by the calibration's change at once, and nothing takes
    /// the change for a sensor offset, a spike, a fall or a warming. If `old` cannot be
    /// inverted they restart instead, as after a sensor fault.
    pub(crate) fn recalibrated(
        &mut self,
        cfg: &SupervisorConfig,
        old: &crate::calib::TwoPoint,
        new: &crate::calib::TwoPoint,
        filter: &mut FirstOrder,
    ) {
        match crate::calib::Recalibration::between(old, new) {
            Some(r) => self.carry_over(cfg, &r, filter),
            None => {
                self.sensor.restart(filter);
                self.freeze.restart();
                self.ssr.restart();
            }
        }
    }

    /// Steps 1–2, before the controller: the sensor (its fault state, offset and spikes, then
    /// the measurement filter), the supply and the supply switch. `raw` is this sample's
    /// calibrated reading or its fault; `sensor`: it came from the sensor (not an ideal plant).
    pub(crate) fn check(
        &mut self,
        cfg: &CarrierConfig,
        t_ms: u64,
        raw: Result<Celsius, EventKind>,
        sensor: bool,
        filter: &mut FirstOrder,
        emit: &mut impl FnMut(EventKind),
    ) -> Reading {
        match sensor::diagnose(&raw, self.state.sensor_fault()) {
            Some(Diagnosis::Failed(kind)) => {
                emit(kind);
                self.state.sensor_failed(kind);
                self.distrust_left = 0;
            }
            // A jump's fault outlasts the plausible readings that follow it.
            Some(Diagnosis::Recovered) if self.distrust_left > 0 => self.distrust_left -= 1,
            Some(Diagnosis::Recovered) => {
                emit(EventKind::SensorRecovered);
                self.state.sensor_recovered();
                // The filter, the slope and the SSR checks' history predate the fault; start
                // afresh from the first good reading.
                filter.reset();
                self.freeze.restart();
                self.ssr.restart();
            }
            None => {}
        }
        let reading = self.sensor.reading(cfg, t_ms, raw, sensor, filter, emit);
        if reading.outvoted {
            // The filtered value that the slope and the history hold was a spike.
            self.freeze.restart();
            self.ssr.restart();
        }
        if reading.jump {
            // The reading left the load's level by more than physics allows and stays there.
            // It may be a probe re-seated in another load, or a front end stuck at a new
            // level: it cools nothing, nor releases the freeze guard, until the stuck-converter
            // check has had `stuck_s` to tell (mission 70549, `--seed 70001`: a reading stuck
            // at 55 °C released the guard over a load at 0.6 °C, and 12 samples of full cooling
            // took it to −2.3 °C before the check fired).
            self.state.sensor_failed(EventKind::SensorOffset);
            self.distrust_left = self.sensor.stuck.window().saturating_sub(1);
        }
        self.supply.run(&cfg.supervisor.supply, emit);
        self.switch.check(&cfg.supervisor.switch, self.supply.v(), emit);
        // Before the controller and whatever the reading: the modules' voltage needs no RTD.
        #[cfg(feature = "module-sense")]
        if self.module.shorted(&cfg.supervisor.switch, self.supply.v()) && !self.state.shorted() {
            self.ssr_shorted(emit);
        }
        reading
    }

    /// Steps 4–7, after the controller asked for `requested` (saturated to `duty`): the freeze
    /// guard and the SSR checks on the filtered load `temp_c` at setpoint `w`, then the outputs.
    pub(crate) fn guard(
        &mut self,
        cfg: &SupervisorConfig,
        t_ms: u64,
        ci: &ControlInput,
        requested: f32,
        duty: Duty,
        emit: &mut impl FnMut(EventKind),
    ) -> Verdict {
        let (temp_c, w) = (ci.y_c, ci.w_c);
        if self.trusts_reading() {
            self.freeze_guard(cfg, t_ms, temp_c, emit);
            self.ssr_checks(&cfg.ssr, t_ms, temp_c, w, emit);
        }
        let mode = self.state.mode();
        let mut duty = if mode == Mode::Normal { duty } else { Duty::OFF };
        if let State { hold: Hold::Free, drive: Drive::LimpHome { supply_on } } = self.state {
            // On the freeze guard's look-ahead ([`ssr::LimpConfig`]): the RTD reads the water
            // ≈ 50 s late, and a light load at full cooling falls 2–3 °C in that time.
            let on = cfg.ssr.limp.supply_on(supply_on, self.freeze.predicted_c(&cfg.freeze, temp_c), w);
            self.state.limp_switched(on);
            if on {
                duty = Duty::FULL;
            }
        }
        // Below the floor with nothing asked, the switch opens too ([`FreezeConfig::idle_open_c`]),
        // while the load stands still: a fall nobody asked for is the SSR checks' to judge.
        let idle_cold = mode == Mode::Normal
            && duty.get() <= 0.0
            && temp_c < cfg.freeze.idle_open_c
            && self.freeze.slope_c_per_s() >= cfg.freeze.idle_slope_c_per_s;
        let closed = self.state.supply_enable() && !idle_cold;
        let switch_test = self.switch.test_due(mode == Mode::Normal && closed);
        let lid = LidInput {
            t_ms,
            duty: duty.get(),
            temp_c,
            w,
            slope_c_per_s: self.freeze.slope_c_per_s(),
            normal: mode == Mode::Normal,
            full_duty_run: self.ssr.full_duty_run(),
            #[cfg(feature = "buck-drive")]
            supply_v: self.supply.v(),
        };
        self.lid.run(&cfg.lid, self.ts_s, &lid, emit);
        self.ssr.applied(&cfg.ssr, duty, requested, temp_c);
        let supply_enable = self.switch.note_enable(closed);
        #[cfg(feature = "module-sense")]
        self.module.note_output(closed, duty.get(), cfg.ssr.full_duty);
        Verdict { duty, supply_enable, switch_test, mode }
    }

    /// The freeze guard: trip (with SSR stuck-on paths 1 and 2) and release.
    fn freeze_guard(&mut self, cfg: &SupervisorConfig, t_ms: u64, temp_c: f32, emit: &mut impl FnMut(EventKind)) {
        let trend = self.freeze.observe(&cfg.freeze, self.ts_s, temp_c);
        if self.state.hold == Hold::Free && FreezeGuard::trips(&cfg.freeze, &trend) {
            self.state.guard_tripped();
            emit(EventKind::FreezeGuardTripped);
            if self.ssr.freeze_tripped(&cfg.ssr.stuck_on, t_ms, &trend, self.state.shorted()) {
                self.ssr_shorted(emit);
            }
        }
        if self.ssr.between_trips(&cfg.ssr.stuck_on, t_ms, &trend, self.state.shorted()) {
            self.ssr_shorted(emit);
        }
        if self.state.hold == Hold::FreezeGuard && FreezeGuard::releases(&cfg.freeze, temp_c, &trend) {
            self.state.guard_released();
            emit(EventKind::FreezeGuardReleased);
        }
    }

    /// The SSR checks on the temperature history: stuck on after the off-run (path 3), stuck
    /// off, the supply probe.
    fn ssr_checks(&mut self, cfg: &SsrConfig, t_ms: u64, temp_c: f32, w: f32, emit: &mut impl FnMut(EventKind)) {
        self.ssr.remember(temp_c);
        if !self.state.shorted() && self.ssr.still_falling(&cfg.stuck_on, temp_c) {
            self.ssr_shorted(emit);
        }
        if self.ssr.warms_at_full_duty(&cfg.stuck_off, temp_c) {
            emit(EventKind::SsrStuckOff);
        }
        if let Drive::Controller { probe } = self.state.drive {
            match self.ssr.probe(&cfg.probe, t_ms, probe, temp_c, w) {
                Probe::Keep => {}
                Probe::Start => self.state.probe_started(t_ms),
                Probe::End => self.state.probe_ended(),
                Probe::Shorted => {
                    self.state.probe_ended();
                    self.ssr_shorted(emit);
                }
            }
        }
    }

    fn ssr_shorted(&mut self, emit: &mut impl FnMut(EventKind)) {
        self.state.ssr_shorted();
        emit(EventKind::SsrStuckOn);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONTROLLER: Drive = Drive::Controller { probe: None };

    fn state(hold: Hold, drive: Drive) -> State {
        State { hold, drive }
    }

    /// `s` after the transition `f`.
    fn after(mut s: State, f: impl FnOnce(&mut State)) -> State {
        f(&mut s);
        s
    }

    #[test]
    fn every_transition_of_the_diagram() {
        let run = State::START;
        assert_eq!(run.mode(), Mode::Normal);
        let guarded = after(run, State::guard_tripped);
        assert_eq!(guarded, state(Hold::FreezeGuard, CONTROLLER));
        assert_eq!(after(guarded, State::guard_released), run);
        assert_eq!(after(guarded, State::guard_tripped), guarded);
        assert_eq!(after(run, State::guard_released), run);
        // A sensor fault remembers whether the guard held, and who drives.
        let open = EventKind::SensorOpen;
        let fault = after(run, |s| s.sensor_failed(open));
        assert_eq!(fault, state(Hold::SensorFault { kind: open, guard: false }, CONTROLLER));
        assert_eq!(after(fault, State::sensor_recovered), run);
        assert_eq!(after(fault, State::guard_tripped), fault, "the guard waits for a reading");
        let guarded_fault = after(guarded, |s| s.sensor_failed(open));
        assert_eq!(after(guarded_fault, State::sensor_recovered), guarded);
        let short = after(guarded_fault, |s| s.sensor_failed(EventKind::SensorShort));
        assert_eq!(short, state(Hold::SensorFault { kind: EventKind::SensorShort, guard: true }, CONTROLLER));
        assert_eq!(after(run, State::sensor_recovered), run);
        // The probe and the short live in the drive, whatever holds the outputs.
        let probing = after(run, |s| s.probe_started(7));
        assert_eq!(probing.drive, Drive::Controller { probe: Some(7) });
        let round = after(probing, |s| {
            s.guard_tripped();
            s.guard_released();
            s.probe_ended();
        });
        assert_eq!(round, run);
        let limp = after(probing, State::ssr_shorted);
        assert_eq!(limp, state(Hold::Free, Drive::LimpHome { supply_on: false }));
        assert_eq!(limp.mode(), Mode::LimpHome);
        assert_eq!(after(limp, |s| s.probe_started(9)), limp, "no probe once shorted");
        let on = after(limp, |s| s.limp_switched(true));
        assert_eq!(on.drive, Drive::LimpHome { supply_on: true });
        assert_eq!(after(on, State::ssr_shorted), on, "latched");
        assert_eq!(after(guarded, State::ssr_shorted).mode(), Mode::FreezeGuard);
        assert_eq!(after(after(guarded, State::ssr_shorted), State::guard_released), limp);
        assert_eq!(after(run, |s| s.limp_switched(true)), run);
    }

    #[test]
    fn validation_names_the_setting_its_detector_cannot_honour() {
        let d = SupervisorConfig::DEFAULT;
        assert_eq!(d.validate(10.0), Ok(()));
        let refused = |f: fn(&mut SupervisorConfig), ts_s: f32| {
            let mut c = d;
            f(&mut c);
            c.validate(ts_s).err()
        };
        // Two stuck-on windows must fit the 32-sample ring: 15 samples, not 16.
        assert_eq!(refused(|c| c.ssr.stuck_on.window_s = 150.0, 10.0), None);
        assert_eq!(refused(|c| c.ssr.stuck_on.window_s = 160.0, 10.0), Some(WindowError("ssr.stuck_on.window_s")));
        assert_eq!(refused(|c| c.ssr.probe.fall_window_s = 0.0, 10.0), Some(WindowError("ssr.probe.fall_window_s")));
        assert_eq!(
            refused(|c| c.ssr.probe.turn_up_window_s = f32::NAN, 10.0),
            Some(WindowError("ssr.probe.turn_up_window_s"))
        );
        // A u8 count: 255 samples at most (2550 s at 10 s), rounded to the nearest.
        assert_eq!(refused(|c| c.supply.sag_s = 2554.0, 10.0), None);
        assert_eq!(refused(|c| c.supply.sag_s = 2556.0, 10.0), Some(WindowError("supply.sag_s")));
        assert_eq!(refused(|c| c.sensor.stuck_s = -1.0, 10.0), Some(WindowError("sensor.stuck_s")));
        assert_eq!(refused(|c| c.ssr.probe.interval_s = 5.0e6, 10.0), Some(WindowError("ssr.probe.interval_s")));
        assert_eq!(refused(|c| c.ssr.probe.yield_within_c = 0.0, 10.0), None);
        let yield_within = Some(WindowError("ssr.probe.yield_within_c"));
        assert_eq!(refused(|c| c.ssr.probe.yield_within_c = -0.1, 10.0), yield_within);
        assert_eq!(refused(|c| c.ssr.probe.yield_within_c = f32::NAN, 10.0), yield_within);
        assert_eq!(refused(|c| c.ssr.probe.yield_within_c = f32::INFINITY, 10.0), yield_within);
        assert_eq!(refused(|c| c.ssr.stuck_on.unrequested_duty = 0.0, 10.0), None);
        let unrequested = Some(WindowError("ssr.stuck_on.unrequested_duty"));
        assert_eq!(refused(|c| c.ssr.stuck_on.unrequested_duty = -0.01, 10.0), unrequested);
        assert_eq!(refused(|c| c.ssr.stuck_on.unrequested_duty = 1.0, 10.0), unrequested);
        assert_eq!(refused(|c| c.ssr.stuck_on.unrequested_duty = f32::NAN, 10.0), unrequested);
        // The same seconds at a faster sample period are more samples than the ring holds.
        assert_eq!(d.validate(1.0), Err(WindowError("ssr.stuck_on.window_s")));
        assert_eq!(d.validate(0.0), Err(WindowError("ts_s")));
        assert_eq!(d.validate(f32::NAN), Err(WindowError("ts_s")));
    }

    #[test]
    fn the_supply_opens_in_every_mode_but_running_unprobed_or_limping_on() {
        let limp = |supply_on| state(Hold::Free, Drive::LimpHome { supply_on });
        assert!(State::START.supply_enable());
        assert!(!after(State::START, |s| s.probe_started(0)).supply_enable());
        assert!(limp(true).supply_enable() && !limp(false).supply_enable());
        assert!(!state(Hold::FreezeGuard, CONTROLLER).supply_enable());
        assert!(!state(Hold::FreezeGuard, Drive::LimpHome { supply_on: true }).supply_enable());
        let fault = state(Hold::SensorFault { kind: EventKind::SensorOpen, guard: false }, CONTROLLER);
        assert!(!fault.supply_enable());
        assert_eq!(fault.mode(), Mode::SensorFault);
    }

    #[test]
    fn seconds_become_todays_sample_counts() {
        assert_eq!(samples_u16(180.0, 10.0), 18);
        assert_eq!(samples_u8(20.0, 10.0), 2);
        assert_eq!(samples_u32(7200.0, 10.0), 720);
        assert_eq!(samples_u32(0.0, 10.0), 0);
        assert_eq!(samples_u8(14.0, 10.0), 1, "rounded to the nearest");
        assert_eq!(samples_u8(15.0, 10.0), 2);
        assert_eq!(samples_u8(1e6, 10.0), 255, "saturating");
        assert_eq!(ms(1800.0), 1_800_000u32);
        assert_eq!(ms(3600.0), 3_600_000);
    }
}
