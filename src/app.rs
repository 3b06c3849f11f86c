//! The board application minus the peripherals: the per-sample step, the cold-chain record and
//! log, the alarm indicator, the settings and the interface's commands, in one object that the
//! firmware's control task and `hter virtual-board` both own and feed.
//!
//! ```text
//!  sample (counts, supply V) ──► App::sample ──► duty, supply enable, alarm indication
//!  request line ──────────────► App::handle ──► reply lines (docs/interface.md)
//!                                    └──► App::next_save ──► the glue's flash writer
//! ```
//!
//! The glue moves data only: it reads the ADC, calls [`App::sample`], drives the outputs, passes
//! request lines to [`App::handle`] and writes what [`App::next_save`] hands it (the settings,
//! the model, the history record and the log entries) to flash behind its write gate. For
//! `history` ([`Handled::History`]) the glue streams the log it owns
//! ([`crate::persist::log::write_csv_row`]), since only it can read flash.
//!
//! Every setting is validated before it is used and before it is stored: [`Command::parse`]
//! checks what needs no state (a plain decimal, a range), [`App::handle`] the rest (a law this
//! build links, a calibration pair, a plausible model); a refused request changes nothing and
//! is not logged, an accepted one is a [`LogEntry::Setting`].

use crate::alarm::{Annunciator, Indication};
use crate::calib::TwoPoint;
use crate::coldchain::Raised;
use crate::control::adaptive::{plausible_model, AdaptiveConfig, SelfTuning};
use crate::control::{ControlError, ControlInput, Controller, ControllerStatus, OnOff, OnOffConfig, Pi};
use crate::event::EventKind;
use crate::failsafe::Stops;
use crate::ident::commission::{
    cabinet_plausible, CommissionConfig, CommissionError, Commissioning, Implausibility, Phase,
};
use crate::iface::num::Fixed;
use crate::iface::sink::{put, Sink, Written};
use crate::iface::{Command, Law, Refusal, SetRequest, Why, HELP};
use crate::model::Model;
use crate::persist::log::{record_secs, IntervalLog, LogEntry, SettingKey};
use crate::persist::{
    HistoryRecord, ModelCadence, ModelRecord, Recorder, ResetCause, Save, SensorOffset, SettingsRecord,
};
use crate::profile::SelfTuningOrPi;
use crate::step::{Carrier, StepInput, StepOutput, ValidConfig};

/// What a build is: its step configuration, its self-tuner and the laws it links.
#[derive(Clone, Copy, Debug)]
pub struct AppConfig {
    /// The step's configuration (its calibration is replaced by the settings').
    pub carrier: ValidConfig,
    /// The self-tuner's built-in configuration (a stored model replaces its start model).
    pub adaptive: AdaptiveConfig,
    /// The laws this build links, the first the default: the self-tuner's law (`gpc` or
    /// `igmvc`), `pi` and `onoff`.
    pub laws: &'static [Law],
    /// The setpoint before any setting is stored, °C.
    pub setpoint_c: f32,
    /// `status`'s `firmware` field.
    pub firmware: &'static str,
    /// Samples between stores of the history record.
    pub history_save_samples: u32,
    /// Samples of trusted learning between stores of the model.
    pub model_save_samples: u32,
}

/// What the boot found in flash and in the reset flags.
#[derive(Clone, Copy, Debug)]
pub struct Boot {
    /// The stored settings, if a valid record was found.
    pub settings: Option<SettingsRecord>,
    /// The calibration to use when no settings are stored (a calibration record of an older
    /// firmware, or identity).
    pub calibration: TwoPoint,
    /// The self-tuner's configuration restarted from the stored model, if one was stored.
    pub adaptive: Option<AdaptiveConfig>,
    /// The stored cabinet model (the holdover's), if a valid record was found. Only builds with
    /// the holdover estimate keep one.
    #[cfg(feature = "holdover")]
    pub cabinet: Option<Model>,
    /// The history carried in.
    pub history: HistoryRecord,
    /// The newest log entry's record time, s (0 for an empty log).
    pub log_last_s: u32,
    /// Why the MCU started.
    pub reset: ResetCause,
    /// The fail-safe stops the stored history does not have yet
    /// ([`crate::failsafe::ResetRecords::boot`]): the stop that ended the previous boot
    /// ([`Stops::fresh`]), or one an earlier boot reported and did not store, and one before it.
    /// Each is counted and reported as a `BoardFault` event until a history that counts it is
    /// in flash.
    pub stops: Stops,
    /// Flash pages the boot found torn and repaired.
    pub pages_lost: u8,
    /// The stored records the boot refused ([`crate::persist::flash::Restored::refused`]), as
    /// [`crate::persist::Record::bit`]s: each runs the build's default instead.
    pub refused: u8,
    /// The acknowledge button was held through the reset: a technician's service reset if the
    /// reset was the reset button's ([`Self::service_reset`]), chance otherwise.
    pub button_held: bool,
}

impl Boot {
    /// A new board's first boot: nothing in flash, a plain reset, no stop, no button (what the
    /// tests and the host's tools start from, field by field overridden).
    pub const NEW: Boot = Boot {
        settings: None,
        calibration: TwoPoint::IDENTITY,
        adaptive: None,
        #[cfg(feature = "holdover")]
        cabinet: None,
        history: HistoryRecord::EMPTY,
        log_last_s: 0,
        reset: ResetCause::Other,
        stops: Stops { earlier: None, latest: None, fresh: false },
        pages_lost: 0,
        refused: 0,
        button_held: false,
    };

    /// How the boot's `history` (the stored one with this boot's reset, stop and repaired pages
    /// counted) is stored: at once on a good supply, past the write gate's hold-off, when it
    /// carries a fail-safe stop the stored history does not already have as its newest, or
    /// forgets what a service reset cleared ([`Self::service_reset`]); behind the hold-off
    /// otherwise. A board that faults within the hold-off of every boot (a panic in
    /// the first steps, a stall) restarts before its boot's store: behind the hold-off, the
    /// stop never reached the cold-chain record however often it repeated, though the next boot
    /// found it in RAM each time (SPEC §7). The same stop again (a fault loop) waits as before,
    /// so a loop does not write at every boot; a stop kept beside it ([`Stops::earlier`]) that
    /// the stored history lacks goes at once, as a new newest does; a power bounce has no stop
    /// (RAM does not keep the reason through a power loss).
    pub fn history_save(&self, history: HistoryRecord) -> Save {
        // Each stop, not the newest alone: a new stop kept as the earlier behind a repeat of the
        // stored newest (a boot that took it on a bad supply, then the loop's panic) waited for a
        // boot that outlasts the hold-off, in RAM, where a power cut loses it. Once stored it is
        // let go, and the repeat alone waits again.
        let new_stop = self.stops.iter().any(|s| Some(crate::persist::LastStop::from(s)) != self.history.last_stop);
        // A service reset's forgetting is stored at once too: behind the hold-off, a power cut
        // in the first minute brought back a short or an offset the technician had cleared.
        let forgot =
            history.ssr_shorted() != self.history.ssr_shorted() || history.sensor_offset != self.history.sensor_offset;
        if forgot || new_stop {
            Save::AlarmHistory(history)
        } else {
            Save::History(history)
        }
    }

    /// Whether this boot is a technician's service reset, which forgets what the history
    /// carries ([`Recorder::note_service`]: the SSR's short if one is stored, else the sensor
    /// offset, after the repair): the acknowledge button held through a reset ([`Self::button_held`]), and the reset
    /// a pin reset (the reset button) without a fail-safe stop of its own ([`Stops::fresh`]: a
    /// stop an earlier boot reported and did not store yet does not refuse it). Not after a
    /// watchdog bite, a fail-safe stop or a power cut, which the button held by chance (someone
    /// acknowledging an alarm) must not turn into a repair. A reset alone no longer clears the
    /// short: an NRST glitch or a debugger attaching under reset gives one too.
    pub fn service_reset(&self) -> bool {
        self.button_held && !self.stops.fresh && self.reset == ResetCause::Other
    }

    /// Runs the build's calibration constant (firmware `config.rs`'s `CALIBRATION`, which the glue
    /// applies when no settings are stored) instead of the calibration record: the record's
    /// refusal, if it was refused, changes nothing and is not reported.
    pub fn run_calibration_constant(&mut self, cal: TwoPoint) {
        self.calibration = cal;
        self.refused &= !crate::persist::Record::Calibration.bit();
    }

    /// The records this boot refused that the stored history does not have as refused
    /// ([`HistoryRecord::refused`]), as [`crate::persist::Record::bit`]s: each one is reported,
    /// as [`EventKind::RecordRefused`] on the log and with the alarm indicator's latch, once. A
    /// record still refused at the next boot is not reported again (the boot does not remove it:
    /// removed, a settings, calibration or cabinet record was gone for good should the firmware
    /// that wrote it come back; a history or a model is replaced by the next store anyway); one
    /// that loads again and is refused later is.
    pub fn newly_refused(&self) -> u8 {
        self.refused & !self.history.refused()
    }

    /// Starts the step and the record from what this boot found: counts the boot in the record
    /// ([`Recorder::note_boot`]) and the pages it repaired, tells the step why the MCU started
    /// and how the previous boot stopped (its first sample reports both), and resumes what the
    /// history keeps ([`Carrier::resume`]: the sensor offset, a shorted SSR), and keeps the
    /// records it refused in the history, the latch set for a new refusal
    /// ([`Recorder::note_refused`], [`Self::newly_refused`]). Returns the history to store
    /// ([`Self::history_save`]; the indicator starts from its latch). What the firmware's
    /// control task and [`App::new`] both call, before the first sample.
    pub fn resume<C: crate::control::Controller>(
        &self,
        carrier: &mut Carrier<C>,
        recorder: &mut Recorder,
    ) -> HistoryRecord {
        carrier.note_reset(self.reset);
        recorder.note_refused(self.refused);
        let mut history = recorder.note_boot(self.reset, &self.stops);
        if self.service_reset() {
            history = recorder.note_service();
        }
        for f in self.stops.iter() {
            carrier.note_board_fault(f.kind);
        }
        carrier.resume(&history);
        for _ in 0..self.pages_lost {
            history = recorder.note_flash_page_lost();
        }
        history
    }
}

/// One sample of the board's inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleIn {
    /// Board time, ms since boot.
    pub t_ms: u64,
    /// RTD conversion, counts.
    pub counts: u32,
    /// The reference conversions around it were in their windows.
    pub reference_ok: bool,
    /// The board's other readings ([`crate::step::BoardReadings`]).
    pub board: crate::step::BoardReadings,
}

/// What one sample decided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleOut {
    /// The step's output (duty, supply enable, mode, events).
    pub step: StepOutput,
    /// The alarm indicator.
    pub alarm: Indication,
    /// Cold-chain alarms this sample raised.
    pub raised: Raised,
}

/// How [`App::handle`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handled {
    /// The reply is complete (its final line written), or the line was empty.
    Done,
    /// `history`: the glue streams the log from record time `since_s` (the CSV header, a row
    /// per entry, then `ok`).
    History {
        /// First record time to send, s.
        since_s: u32,
    },
}

/// The laws a board switches between at run time, without a heap: the variant in use.
// No heap to box into; the enum is as large as the self-tuner, which the board runs anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum BoardController {
    /// The self-tuner (or its PI, if its configuration was refused).
    Adaptive(SelfTuningOrPi),
    /// PI.
    Pi(Pi),
    /// On-Off.
    OnOff(OnOff),
    /// On-board commissioning (rest, PRBS, fit), under the step's supervisor like any law.
    Commission(Commissioning),
}

impl Controller for BoardController {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        match self {
            BoardController::Adaptive(c) => c.update(input),
            BoardController::Pi(c) => c.update(input),
            BoardController::OnOff(c) => c.update(input),
            BoardController::Commission(c) => c.update(input),
        }
    }

    fn track(&mut self, input: &ControlInput, applied: f32) {
        match self {
            BoardController::Adaptive(c) => c.track(input, applied),
            BoardController::Pi(c) => c.track(input, applied),
            BoardController::OnOff(c) => c.track(input, applied),
            BoardController::Commission(c) => c.track(input, applied),
        }
    }

    fn skip(&mut self, applied: f32) {
        if let BoardController::Adaptive(c) = self {
            c.skip(applied);
        }
    }

    fn name(&self) -> &'static str {
        match self {
            BoardController::Adaptive(c) => c.name(),
            BoardController::Pi(c) => c.name(),
            BoardController::OnOff(c) => c.name(),
            BoardController::Commission(c) => c.name(),
        }
    }

    fn status(&self) -> Option<ControllerStatus> {
        match self {
            BoardController::Adaptive(c) => c.status(),
            _ => None,
        }
    }

    fn trusted_model(&self) -> Option<Model> {
        match self {
            BoardController::Adaptive(c) => c.trusted_model(),
            _ => None,
        }
    }
}

/// Builds `law`'s controller starting bumplessly from the applied duty `u0`.
fn build(law: Law, adaptive: &AdaptiveConfig, ts_s: f32, u0: f32) -> BoardController {
    // The build's PI (the self-tuner's fallback), from the applied duty.
    let pi = || Pi::new(crate::control::PiConfig { bias: u0, ..adaptive.fallback }, ts_s);
    match law {
        Law::Gpc | Law::Igmvc => BoardController::Adaptive(match SelfTuning::new(*adaptive, ts_s, u0) {
            Ok(st) => SelfTuningOrPi::SelfTuning(st),
            Err(_) => SelfTuningOrPi::Pi(pi()),
        }),
        Law::Pi => BoardController::Pi(pi()),
        Law::OnOff => BoardController::OnOff(OnOff::new(OnOffConfig::DEFAULT)),
    }
}

/// Log entries one sample may add beyond its events: an interval and up to four alarms.
const OUTBOX: usize = 16;

/// Events that are not written to the flash log: the self-tuner's trust toggling between
/// adaptive and frozen can happen every few samples for hours (EXPERIMENTS.md, issue 15) and
/// would push 30 days of intervals out of the log; `status` shows the mode, telemetry logs every
/// change. Every other event is kept.
fn logged(kind: EventKind) -> bool {
    !matches!(kind, EventKind::AdaptiveEngaged | EventKind::AdaptiveFrozen)
}

/// The board application (see the module documentation).
pub struct App {
    cfg: AppConfig,
    carrier: Carrier<BoardController>,
    settings: SettingsRecord,
    adaptive: AdaptiveConfig,
    recorder: Recorder,
    annunciator: Annunciator,
    cadence: ModelCadence,
    intervals: IntervalLog,
    /// Record time at board time 0, ms.
    base_ms: u64,
    outbox: heapless::Deque<Save, OUTBOX>,
    /// Saves dropped because the glue did not drain the outbox (16 saves) in time.
    pub saves_dropped: u16,
    last: Option<SampleOut>,
    last_t_ms: u64,
    ack_pending: bool,
    /// The applied duty's mean over the last 30–60 minutes: where a commissioning rests.
    duty_mean: DutyMean,
    /// The last commissioning's end, for `status` until the next one starts.
    commissioned: Option<Result<(), CommissionError>>,
    /// The cabinet model (commissioned or uploaded; the holdover's), if the carrier has one.
    cabinet: Option<Model>,
    /// Whether the flash keeps failing ([`Self::note_store_failures`]).
    store: crate::persist::StoreWatch,
}

/// Samples in one block of [`DutyMean`]: 30 minutes at Ts = 10 s.
const DUTY_BLOCK: u16 = 180;

/// The mean applied duty over the last complete block of [`DUTY_BLOCK`] samples and the block
/// under way (30–60 minutes at Ts = 10 s): the duty a commissioning rests at and excites
/// around.
///
/// The commissioning's record must not drift: 0.01 of duty off the carrier's steady duty is
/// ≈ 0.4 °C of drift over the 4-hour PRBS on H-TER I (−43 °C/duty), which the output-error fit
/// takes for a pole at 1. The self-tuning GPC moves the duty at rest in a slow cycle, and the
/// 5-minute exponential average this replaces was up to 0.007 off the longer mean: started at
/// samples 550–558 of the virtual board (H-TER I, 28 °C, seed 1), the cabinet model came out
/// with A ≈ [−1.99, 0.99] and delay 6, or `poor_fit`. From this mean the same starts, and
/// starts at 360–800, give A ≈ [−1.92…−1.95, 0.92…0.95] and delays 8–10.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DutyMean {
    /// Sum and count of the last complete block.
    last: (f32, u16),
    /// Sum and count of the block under way.
    cur: (f32, u16),
    /// Samples since a setting moved the load ([`DutyMean::moved`]), up to [`SETTLE_SAMPLES`].
    since_moved: u16,
}

/// Samples after a setting that moves the load (setpoint, law, calibration, a cleared sensor
/// offset) before a commissioning may start: the mean's whole window (two blocks) after a
/// 10-minute transient, 70 minutes at Ts = 10 s. Started within it, the commissioning rests
/// and excites around a mean of the old operating point and the transient: `set setpoint_c 5`
/// on a carrier holding 4 °C, then `identify` (the README's sequence) 0–50 minutes later ran
/// its 6 h and ended `poor_fit` or `implausible_gain` in 13 of 21 starts on the virtual board;
/// 70 minutes later and on, in none
/// (`hal-sim/tests/virtual_board.rs::identify_waits_until_the_carrier_has_held_a_new_setpoint`).
const SETTLE_SAMPLES: u16 = 2 * DUTY_BLOCK + 60;

/// A reading further than this from the setpoint moves the operating point as a setting does
/// ([`DutyMean::moved`]), °C: a pull-down after the carrier is switched on, a recovery from a
/// disturbance, a sensor fault (no reading). Commissioning a new cabinet is naturally asked for
/// right after power-up: started when the pull-down first reached 4 °C (35 min at 28 °C on the
/// virtual board), the commissioning rested at the pull-down's mean duty, ≈ 0.9, and the load
/// fell into the freeze guard within 31 samples (`failed:fault_freeze_guard`;
/// `hal-sim/tests/virtual_board.rs::identify_waits_until_a_pulled_down_carrier_has_held_its_setpoint`).
/// Wide enough for the closed-loop laws' hold (On-Off's cycle is no hold: `identify` refuses it,
/// [`App::start_commissioning`]).
const HELD_BAND_C: f32 = 1.5;

impl DutyMean {
    /// After a boot the mean is empty, and a commissioning started at once rested at the
    /// fallback PI's bias: right only where the bias is the carrier's holding duty. One block
    /// (30 min) of a boot that holds its setpoint is the mean's shortest window; a boot into a
    /// pull-down waits [`SETTLE_SAMPLES`] from its last reading out of [`HELD_BAND_C`]. Started
    /// 1–60 samples after a boot holding 4 °C on the virtual board (H-TER I full and half, 20, 36,
    /// 43 °C), commissioning ended `fault_out_of_band` or `poor_fit` in every case; 180 or 420
    /// samples after, `done` in every case.
    const NEW: DutyMean = DutyMean { last: (0.0, 0), cur: (0.0, 0), since_moved: SETTLE_SAMPLES - DUTY_BLOCK };

    /// A setting moved the load: its operating point is settling.
    fn moved(&mut self) {
        self.since_moved = 0;
    }

    /// Whether the mean is of the operating point in force (no setting moved it within
    /// [`SETTLE_SAMPLES`]).
    fn settled(&self) -> bool {
        self.since_moved >= SETTLE_SAMPLES
    }

    fn push(&mut self, duty: f32) {
        self.since_moved = self.since_moved.saturating_add(1).min(SETTLE_SAMPLES);
        self.cur = (self.cur.0 + duty, self.cur.1 + 1);
        if self.cur.1 >= DUTY_BLOCK {
            self.last = self.cur;
            self.cur = (0.0, 0);
        }
    }

    /// The mean, or `none` before the first sample.
    fn get(&self, none: f32) -> f32 {
        let n = self.last.1 + self.cur.1;
        if n == 0 {
            none
        } else {
            (self.last.0 + self.cur.0) / f32::from(n)
        }
    }
}

impl App {
    /// The application after a boot: settings, model, history and record time from flash.
    pub fn new(cfg: AppConfig, boot: &Boot) -> App {
        let default_law = cfg.laws.first().copied().unwrap_or(Law::Gpc);
        let settings = match boot.settings {
            // A law this build does not link (a record of another build) is refused as `set
            // controller` refuses it: the build's default runs, the setpoint and calibration stay.
            Some(s) if s.calibration().is_ok() => {
                SettingsRecord { law: if cfg.laws.contains(&s.law) { s.law } else { default_law }, ..s }
            }
            _ => {
                // No settings yet: the points of the line the board booted with (the build's
                // constant, an older firmware's record; identity: 0,0 and 25,25), so that `get`
                // shows it and a setting stored later keeps it. With identity points instead, the
                // first accepted setting replaced it and its record brought identity back at
                // every boot.
                let c = boot.calibration;
                let from_boot = SettingsRecord {
                    seq: 0,
                    setpoint_c: cfg.setpoint_c,
                    law: default_law,
                    cal_ice: [0.0, c.offset_c],
                    cal_warm: [25.0, c.gain * 25.0 + c.offset_c],
                };
                match from_boot.calibration() {
                    Ok(_) => from_boot,
                    Err(_) => SettingsRecord { cal_ice: [0.0, 0.0], cal_warm: [25.0, 25.0], ..from_boot },
                }
            }
        };
        let cal =
            if boot.settings.is_some() { settings.calibration().unwrap_or(boot.calibration) } else { boot.calibration };
        let adaptive = boot.adaptive.unwrap_or(cfg.adaptive);
        let ts_s = cfg.carrier.get().ts_s;
        let controller = build(settings.law, &adaptive, ts_s, cfg.adaptive.fallback.bias);
        let mut carrier = Carrier::new(cfg.carrier.with_calibration(cal), controller);
        #[cfg(feature = "holdover")]
        let cabinet = boot.cabinet;
        #[cfg(not(feature = "holdover"))]
        let cabinet = None;
        // The holdover runs on the cabinet model, whatever law drives; without one on the build's
        // start model, never on the self-tuner's saved estimate (README "Holdover": its slow
        // mode drifts while it holds a constant setpoint).
        carrier.set_holdover_model(cabinet.or(cfg.adaptive.initial));
        let mut recorder = Recorder::new(boot.history, cfg.history_save_samples);
        let mut app_saves = heapless::Deque::new();
        let history = boot.resume(&mut carrier, &mut recorder);
        let base_ms = (u64::from(boot.log_last_s) + 1) * 1000;
        // The history before the events: more pages lost than the outbox holds drop events (the
        // history counts them all), never the boot's history.
        let _ = app_saves.push_back(boot.history_save(history));
        // What the service reset forgot ([`Recorder::note_service`]: the short, or the offset).
        let short = boot.history.ssr_shorted() && !history.ssr_shorted();
        let offset = if history.sensor_offset != boot.history.sensor_offset {
            boot.history.sensor_offset
        } else {
            SensorOffset::NONE
        };
        if boot.service_reset() && (short || offset != SensorOffset::NONE) {
            let value = [offset.c(), f32::from(u8::from(short))];
            let _ = app_saves.push_back(Save::Log(LogEntry::Setting {
                t_s: record_secs(base_ms),
                key: SettingKey::Service,
                value,
            }));
        }
        // The refusals before the pages lost, which the history counts if the outbox drops them
        // (the refusals it keeps as a set: dropped, one would go unreported).
        let new = boot.newly_refused();
        for r in crate::persist::Record::ALL {
            if new & r.bit() != 0 {
                let _ = app_saves.push_back(Save::Log(LogEntry::Event {
                    t_s: record_secs(base_ms),
                    kind: EventKind::RecordRefused(r),
                }));
            }
        }
        for _ in 0..boot.pages_lost {
            let _ = app_saves
                .push_back(Save::Log(LogEntry::Event { t_s: record_secs(base_ms), kind: EventKind::FlashPageLost }));
        }
        App {
            cfg,
            carrier,
            settings,
            adaptive,
            recorder,
            annunciator: Annunciator::restored(&history),
            cadence: ModelCadence::new(cfg.model_save_samples),
            intervals: IntervalLog::new(),
            base_ms,
            outbox: app_saves,
            saves_dropped: 0,
            last: None,
            last_t_ms: 0,
            ack_pending: false,
            duty_mean: DutyMean::NEW,
            commissioned: None,
            cabinet,
            store: crate::persist::StoreWatch::NEW,
        }
    }

    /// The cold-chain record (this boot's monitor: MKT, extremes, excursions).
    pub fn recorder(&self) -> &Recorder {
        &self.recorder
    }

    /// The step (for logging the controller's state).
    pub fn carrier(&self) -> &Carrier<BoardController> {
        &self.carrier
    }

    /// The settings in use.
    pub fn settings(&self) -> &SettingsRecord {
        &self.settings
    }

    /// The next record to write to flash, oldest first; the glue drains it after every
    /// [`App::sample`] and [`App::handle`].
    pub fn next_save(&mut self) -> Option<Save> {
        self.outbox.pop_front()
    }

    /// `m` (checked by the caller with [`plausible_model`]) becomes the model the self-tuner
    /// starts from (the caller stores it in the model record), with the start's P(0): a board
    /// booted from its record runs `resumed_from` it (P(0) = `RESUMED_P0`), which a
    /// commissioned or uploaded model must not inherit.
    fn adopt_control(&mut self, m: Model) {
        self.adaptive = AdaptiveConfig { rls: self.cfg.adaptive.rls, ..self.adaptive }.restored_from(m);
    }

    /// `m` (checked by the caller with [`cabinet_plausible`]) becomes the cabinet model: the
    /// holdover estimate's, stored in its own record.
    fn adopt_cabinet(&mut self, m: Model) {
        self.cabinet = Some(m);
        self.carrier.set_holdover_model(Some(m));
        #[cfg(feature = "holdover")]
        if let Some(rec) = crate::persist::CabinetRecord::from_model(&m) {
            self.save(Save::Cabinet(rec));
        }
    }

    /// The cabinet model, if the carrier has one.
    pub fn cabinet(&self) -> Option<Model> {
        self.cabinet
    }

    /// The records region was erased (the storage layer found it corrupt and the persist task
    /// wiped it to write again): queues once more what nothing stores on a cadence — the
    /// settings when any were stored, the calibration that runs, the cabinet model — and the
    /// history now rather than at its next hourly store. Without it a corrupt region lost the setpoint, the calibration
    /// and the cabinet model for good (they are written only when they change). The model
    /// record comes back with the self-tuner's next store.
    #[inline(never)] // called once, from the firmware's loop: −24 B inlined there
    pub fn records_erased(&mut self) {
        if self.settings.seq != 0 {
            self.save(Save::Settings(self.settings));
        }
        // The calibration that runs, for an image without the interface (which reads the
        // calibration record alone) and for one without a constant.
        self.save(Save::Calibration(self.carrier.config().cal));
        #[cfg(feature = "holdover")]
        if let Some(rec) = self.cabinet.as_ref().and_then(crate::persist::CabinetRecord::from_model) {
            self.save(Save::Cabinet(rec));
        }
        self.save(Save::History(self.recorder.history()));
    }

    /// The persist task's count of stores failed in a row (0 after one that succeeded), before
    /// each sample: when it reaches [`crate::persist::STORE_FAILURES`] the flash is failing,
    /// which latches the indicator and logs `store_failed` (kept if the log region still
    /// writes), once per run of failures; `status` shows `flash=failing` until a store succeeds.
    /// Before, a board whose flash refused every write kept no record and said so only in its
    /// RTT log, which nobody reads in the field.
    pub fn note_store_failures(&mut self, failed_in_a_row: u8) {
        if self.store.observe(failed_in_a_row) {
            self.annunciator.note(EventKind::StoreFailed);
            let t_s = self.record_s(self.last_t_ms);
            self.save(Save::Log(LogEntry::Event { t_s, kind: EventKind::StoreFailed }));
        }
    }

    /// Out of line: inlined, each of its dozen call sites moved a whole `Save` (a history record
    /// is ≈ 180 bytes) through a copy of the queue's code (−1 512 B of the interface build).
    #[inline(never)]
    fn save(&mut self, save: Save) {
        if self.outbox.is_full() {
            self.outbox.pop_front();
            self.saves_dropped = self.saves_dropped.saturating_add(1);
        }
        let _ = self.outbox.push_back(save);
    }

    fn record_s(&self, t_ms: u64) -> u32 {
        record_secs(self.base_ms + t_ms)
    }

    /// The user button (or `ack`): the alarm has been seen; applied with the next sample.
    pub fn acknowledge(&mut self) {
        self.ack_pending = true;
    }

    /// Runs one sample.
    pub fn sample(&mut self, s: &SampleIn) -> SampleOut {
        self.carrier.observe(&s.board);
        let input = StepInput { t_ms: s.t_ms, counts: s.counts, setpoint_c: self.settings.setpoint_c };
        let out =
            if s.reference_ok { self.carrier.step(&input) } else { self.carrier.step_with_reference_fault(&input) };
        self.finish_sample(s.t_ms, out)
    }

    /// Runs one sample from an already converted temperature (an ideal-measurement plant).
    pub fn sample_celsius(&mut self, t_ms: u64, temp_c: f32) -> SampleOut {
        let out = self.carrier.step_celsius(t_ms, crate::units::Celsius(temp_c), self.settings.setpoint_c);
        self.finish_sample(t_ms, out)
    }

    fn finish_sample(&mut self, t_ms: u64, out: StepOutput) -> SampleOut {
        self.duty_mean.push(out.duty.get());
        let recorded = out.recorded_c();
        // NaN (no reading) compares false: a sensor fault moves it too.
        if !((recorded - out.setpoint_c.0).abs() <= HELD_BAND_C) {
            self.duty_mean.moved();
        }
        self.last_t_ms = t_ms;
        self.commission_step(out.mode);
        let mut rec = self.recorder.push(t_ms, recorded);
        if core::mem::take(&mut self.ack_pending) {
            self.annunciator.acknowledge();
        }
        let alarm = self.annunciator.update(&out, &rec.raised);
        self.recorder.note_carried(
            &mut rec,
            self.annunciator.latched(),
            self.carrier.sensor_offset(),
            self.carrier.ssr_shorted(),
        );
        let t_s = self.record_s(t_ms);
        // The interval this sample closes ended at or before it, so it is logged before the
        // sample's events and alarms: the record stays in time order (a fault found on the
        // sample that closed an interval was logged a second after the interval's end and
        // before it, and `hter monitor` refused the history).
        if let Some(e) = self.intervals.push(self.base_ms + t_ms, out.temp_c.0, out.duty.get(), out.mode) {
            self.save(Save::Log(e));
        }
        for e in out.events.iter() {
            if logged(e.kind) {
                self.save(Save::Log(LogEntry::Event { t_s: self.record_s(e.t_ms), kind: e.kind }));
            }
        }
        for a in rec.raised.iter().flatten() {
            // A run carried through a restart began that much recorded time before this boot's
            // part of it.
            let start_s = self.record_s(a.start_ms).saturating_sub(a.carried_s);
            self.save(Save::Log(LogEntry::Alarm { t_s, kind: a.kind, start_s }));
        }
        if let Some(save) = self.recorder.due_save(&rec) {
            self.save(save);
        }
        if let Some(m) = self.cadence.push(out.status.map(|st| st.mode), self.carrier.controller()) {
            self.save(Save::Model(m));
        }
        let done = SampleOut { step: out, alarm, raised: rec.raised };
        self.last = Some(done);
        done
    }

    /// Runs one request line and writes its reply (lines ended by `\r\n`, the last one `ok` or
    /// `err …`), except for `history`, whose rows the glue streams ([`Handled::History`]).
    pub fn handle(&mut self, line: &str, out: &mut impl Sink) -> Handled {
        let result = match Command::parse(line) {
            Ok(None) => return Handled::Done,
            Ok(Some(Command::History { since_s })) => return Handled::History { since_s },
            Ok(Some(cmd)) => self.run(cmd, out),
            Err(r) => Err(r),
        };
        let _ = match result {
            Ok(()) => out.str("ok\r\n"),
            Err(r) => put!(out, r, "\r\n"),
        };
        Handled::Done
    }

    fn run(&mut self, cmd: Command, out: &mut impl Sink) -> Result<(), Refusal<'static>> {
        match cmd {
            Command::Help => {
                for l in HELP {
                    let _ = put!(out, *l, "\r\n");
                }
                Ok(())
            }
            Command::Status => {
                let _ = self.write_status(out);
                Ok(())
            }
            Command::Get => {
                let s = &self.settings;
                let _ = put!(
                    out,
                    "setpoint_c=",
                    Fixed(s.setpoint_c, 2),
                    "\r\ncontroller=",
                    s.law.name(),
                    "\r\ncal_ice=",
                    Fixed(s.cal_ice[0], 2),
                    ",",
                    Fixed(s.cal_ice[1], 2),
                    "\r\ncal_warm=",
                    Fixed(s.cal_warm[0], 2),
                    ",",
                    Fixed(s.cal_warm[1], 2),
                    "\r\n"
                );
                Ok(())
            }
            // Nothing to acknowledge (or an `ack` already waiting for the next sample): said,
            // and neither applied nor recorded, so that a repeated `ack` (a script in a loop, a
            // key held down) cannot fill the record's ring with events and push out its days.
            // With the indicator on for what is true now (the load outside 2…8 °C, the step not in
            // control), it says so: `no alarm` under a sounding buzzer told the health worker the
            // carrier was fine.
            Command::Set(SetRequest::Ack) if !self.annunciator.latched() || self.ack_pending => {
                let _ = match self.last.map(|o| o.alarm) {
                    Some(a @ (Indication::OutOfRange | Indication::NotInControl)) => {
                        put!(out, "alarm=", a.name(), " stays on while it lasts\r\n")
                    }
                    _ => out.str("no alarm\r\n"),
                };
                Ok(())
            }
            Command::Set(req) => {
                self.set(req)?;
                if req == SetRequest::Controller(Law::OnOff) {
                    self.warn_on_off(out);
                }
                Ok(())
            }
            Command::Identify => self.start_commissioning(),
            Command::IdentifyAbort => match self.carrier.controller_mut() {
                BoardController::Commission(c) => {
                    c.abort(CommissionError::Aborted);
                    self.commission_step(crate::step::Mode::Normal);
                    Ok(())
                }
                _ => Err(Refusal { what: "identify", why: Why::NotNow("no commissioning is running") }),
            },
            Command::History { .. } => Ok(()),
        }
    }

    /// The data line before `ok` that accepts On-Off (SPEC §8 has it settable): it is the
    /// comparison baseline, not a law for the field. Its limit cycle leaves 2–8 °C: `hter sim
    /// --controller onoff`, 12 h holding a setpoint, the water's swing after the first 3 h: H-TER I
    /// full 2.3–2.4 °C peak to peak (down to 1.71 °C at setpoint 3.5 °C and 15 °C ambient, up to
    /// 8.16 °C at 6.5 °C and 43 °C), half loaded 3.0 °C (1.09 °C, 8.77 °C); H-TER II 1.7–2.2 °C. A
    /// data line, not a second final line: `hter board` and any client reading to `ok`/`err` see
    /// an accepted setting with a line to show.
    fn warn_on_off(&self, out: &mut impl Sink) {
        let field = self.cfg.laws.iter().copied().find(|l| matches!(l, Law::Gpc | Law::Igmvc)).unwrap_or(Law::Gpc);
        let _ = put!(
            out,
            "warning: onoff is a comparison baseline: it swings up to 3 °C peak to peak and can leave 2-8 °C; ",
            field.name(),
            " is the field controller\r\n"
        );
    }

    /// The applied duty of the last sample (a switched law starts from it).
    fn applied(&self) -> f32 {
        self.last.map_or(self.cfg.adaptive.fallback.bias, |o| o.step.duty.get())
    }

    fn set(&mut self, req: SetRequest) -> Result<(), Refusal<'static>> {
        let t_s = self.record_s(self.last_t_ms);
        let mut next = self.settings;
        // Only a new calibration point changes the line in force.
        let mut recalibrated = None;
        let (key, value) = match req {
            SetRequest::Setpoint(x) => {
                next.setpoint_c = x;
                (SettingKey::Setpoint, [x, 0.0])
            }
            SetRequest::Controller(law) => {
                if !self.cfg.laws.contains(&law) {
                    return Err(Refusal { what: "controller", why: Why::NotInBuild });
                }
                self.not_while_commissioning("controller")?;
                next.law = law;
                (SettingKey::Controller, [law as u8 as f32, 0.0])
            }
            SetRequest::CalIce(p) | SetRequest::CalWarm(p) => {
                let ice = matches!(req, SetRequest::CalIce(_));
                let (what, key) = if ice { ("cal_ice", SettingKey::CalIce) } else { ("cal_warm", SettingKey::CalWarm) };
                // The commissioning's record is of readings through today's calibration: a new
                // one mid-run is a step in the record the fit would take for the carrier's.
                self.not_while_commissioning(what)?;
                if ice {
                    next.cal_ice = p;
                } else {
                    next.cal_warm = p;
                }
                recalibrated = Some(next.calibration().map_err(|e| Refusal { what, why: Why::Calibration(e) })?);
                (key, p)
            }
            SetRequest::Model(m) => return self.set_model(m, t_s),
            SetRequest::Ack => {
                self.acknowledge();
                self.save(Save::Log(LogEntry::Setting { t_s, key: SettingKey::Ack, value: [0.0; 2] }));
                return Ok(());
            }
            SetRequest::ClearSensorOffset => {
                // The commissioning's record is of readings with the offset subtracted: clearing
                // it mid-run is a step the fit would take for the carrier's.
                self.not_while_commissioning("sensor_offset_c")?;
                let was = self.carrier.sensor_offset_c();
                if was != 0.0 {
                    // The next sample stores the history without it (`Recorder::note_carried`).
                    self.carrier.clear_sensor_offset();
                    self.duty_mean.moved();
                    let value = [was, 0.0];
                    self.save(Save::Log(LogEntry::Setting { t_s, key: SettingKey::SensorOffset, value }));
                }
                return Ok(());
            }
        };
        // The value it already has: nothing to use, store or record (a script repeating a
        // `set` would otherwise fill the record's ring with events).
        if next == self.settings {
            return Ok(());
        }
        // Accepted: used from the next sample, stored, logged.
        next.seq = next.seq.wrapping_add(1);
        self.duty_mean.moved();
        if next.law != self.settings.law {
            let ctl = build(next.law, &self.adaptive, self.cfg.carrier.get().ts_s, self.applied());
            *self.carrier.controller_mut() = ctl;
        }
        if let Some(cal) = recalibrated {
            self.carrier.set_calibration(cal);
            // The calibration record too: an image without the interface reads that one, not
            // the settings, and would have run this carrier uncalibrated after a reflash.
            self.save(Save::Calibration(cal));
        }
        self.settings = next;
        self.save(Save::Settings(next));
        self.save(Save::Log(LogEntry::Setting { t_s, key, value }));
        Ok(())
    }

    /// `set model`: the carrier's cabinet model (the holdover's, its own record), checked as a
    /// commissioned one is ([`cabinet_plausible`]); if the self-tuner would trust it too (every
    /// b_i ≤ 0, [`plausible_model`]) the self-tuner restarts from it and it is stored as the
    /// model record as well.
    fn set_model(&mut self, m: Model, t_s: u32) -> Result<(), Refusal<'static>> {
        let refuse = |why| Err(Refusal { what: "model", why: Why::Model(why) });
        if !m.a_is_stable() {
            return refuse("A is not stable (a root on or outside the unit circle)");
        }
        match cabinet_plausible(&self.adaptive, &m) {
            Ok(()) => {}
            Err(Implausibility::Gain) => return refuse("static gain outside the self-tuner's plausible range"),
            Err(Implausibility::Unstable) => return refuse("not a second-order model with a stable A"),
            Err(_) => {
                return refuse(
                    "not a monotone cooling (A two real lags, b0 <= 0, the slow lag cooling: b0*p1 + b1 <= 0)",
                )
            }
        }
        let Some(rec) = ModelRecord::from_model(&m) else { return refuse("not a second-order model") };
        let control = crate::control::adaptive::plausible_model_cold(&self.adaptive, &m);
        // The cabinet model it already has, and none for the self-tuner: nothing to use, store or
        // record (a script repeating it logged it each time, pushing the record's oldest days out).
        // Compared as records, the check out of line: +120 B of the interface build, where
        // comparing the `Model`s with the check inlined cost 528 B.
        if !control && self.cabinet.as_ref().and_then(ModelRecord::from_model) == Some(rec) {
            return Ok(());
        }
        self.adopt_cabinet(m);
        if control {
            self.adopt_control(m);
            if matches!(self.settings.law, Law::Gpc | Law::Igmvc) && !self.commissioning() {
                let ctl = build(self.settings.law, &self.adaptive, self.cfg.carrier.get().ts_s, self.applied());
                *self.carrier.controller_mut() = ctl;
            }
            self.save(Save::Model(rec));
        }
        let gain = m.static_gain().unwrap_or(f32::NAN);
        self.save(Save::Log(LogEntry::Setting { t_s, key: SettingKey::Model, value: [gain, m.k() as f32] }));
        Ok(())
    }

    fn commissioning(&self) -> bool {
        matches!(self.carrier.controller(), BoardController::Commission(_))
    }

    /// The refusal of setting `what` while a commissioning runs.
    fn not_while_commissioning(&self, what: &'static str) -> Result<(), Refusal<'static>> {
        if self.commissioning() {
            return Err(Refusal { what, why: Why::NotNow("commissioning is running (identify abort)") });
        }
        Ok(())
    }

    /// The applied duty's recent mean ([`DutyMean`]), or the fallback PI's bias before the first
    /// sample: where a commissioning rests, and where the law after it starts.
    fn rest_duty(&self) -> f32 {
        self.duty_mean.get(self.cfg.adaptive.fallback.bias)
    }

    /// `identify`: the law hands over to a commissioning that rests at the recent mean duty.
    fn start_commissioning(&mut self) -> Result<(), Refusal<'static>> {
        let refuse = |why| Err(Refusal { what: "identify", why: Why::NotNow(why) });
        if self.commissioning() {
            return refuse("a commissioning is already running (identify abort stops it)");
        }
        // On-Off's limit cycle swings the load up to 3 °C about a point off the setpoint: the
        // run rests at its mean duty from wherever the cycle left the load, and on the virtual
        // board (H-TER I, full and half load, 20, 28, 36, 43 °C, seeds 1–2) 13 of 16 runs failed,
        // 12 of them after 3–5 h (`fault_out_of_band`, `poor_fit`); from GPC or PI all 32 ended
        // `done`.
        if matches!(self.carrier.controller(), BoardController::OnOff(_)) {
            return refuse(
                "the carrier runs onoff, whose limit cycle is no operating point to commission from: set controller gpc (or pi), then identify 70 min later",
            );
        }
        match self.last {
            Some(o) if o.step.mode == crate::step::Mode::Normal => {}
            Some(_) => {
                return refuse("the carrier is not in normal mode (a sensor fault, the freeze guard, limp home)")
            }
            None => return refuse("no sample yet"),
        }
        if !self.duty_mean.settled() {
            return refuse(
                "the carrier has not held its setpoint long enough: commissioning rests at the last hour's mean duty, so wait 30 min after a boot, 70 min after a setting or a reading more than 1.5 °C from the setpoint (a pull-down, a disturbance, a sensor fault)",
            );
        }
        let cfg = CommissionConfig { plausible: self.adaptive, ..CommissionConfig::DEFAULT };
        let u0 = self.rest_duty();
        let c = Commissioning::new(cfg, self.cfg.carrier.get().ts_s, u0)
            .map_err(|e| Refusal { what: "identify", why: Why::NotNow(e.reason()) })?;
        *self.carrier.controller_mut() = BoardController::Commission(c);
        self.carrier.hold_switch_tests(true);
        self.commissioned = None;
        let t_s = self.record_s(self.last_t_ms);
        self.save(Save::Log(LogEntry::Setting { t_s, key: SettingKey::Identify, value: [u0, 0.0] }));
        Ok(())
    }

    /// After each sample: a commissioning is aborted when the mode leaves normal; a finished
    /// one stores its model and hands over to the self-tuner from it, or (failed) back to the
    /// law that ran before, keeping the previous model.
    fn commission_step(&mut self, mode: crate::step::Mode) {
        let BoardController::Commission(c) = self.carrier.controller_mut() else { return };
        c.abort_on_mode(mode);
        let Some(outcome) = c.outcome() else { return };
        let cabinet = c.cabinet();
        let t_s = self.record_s(self.last_t_ms);
        let ts_s = self.cfg.carrier.get().ts_s;
        let law = match outcome {
            Ok(m) => match ModelRecord::from_model(&m) {
                Some(rec) if plausible_model(&self.adaptive, &m) => {
                    // The control model for the self-tuner, the cabinet model for the holdover.
                    self.adopt_control(m);
                    self.save(Save::Model(rec));
                    if let Some(cab) = cabinet {
                        self.adopt_cabinet(cab);
                    }
                    self.commissioned = Some(Ok(()));
                    // The build's self-tuner continues from the new model.
                    self.cfg
                        .laws
                        .iter()
                        .copied()
                        .find(|l| matches!(l, Law::Gpc | Law::Igmvc))
                        .unwrap_or(self.settings.law)
                }
                _ => {
                    self.commissioned =
                        Some(Err(CommissionError::Implausible(crate::ident::commission::Implausibility::Gain)));
                    self.settings.law
                }
            },
            Err(e) => {
                self.commissioned = Some(Err(e));
                self.settings.law
            }
        };
        let code = match self.commissioned {
            Some(Err(e)) => [0.0, f32::from(e.code())],
            _ => [1.0, 0.0],
        };
        self.save(Save::Log(LogEntry::Setting { t_s, key: SettingKey::IdentifyEnd, value: code }));
        *self.carrier.controller_mut() = build(law, &self.adaptive, ts_s, self.rest_duty());
        self.carrier.hold_switch_tests(false);
        if law != self.settings.law {
            self.settings.law = law;
            self.settings.seq = self.settings.seq.wrapping_add(1);
            let s = self.settings;
            self.save(Save::Settings(s));
        }
    }

    fn write_status(&self, out: &mut impl Sink) -> Written {
        let last = self.last;
        // From the integer clock: through f32 the tenths went wrong after 48 days (8025510.4 on a
        // 10 s grid) and the whole value became `-` after 6 years.
        put!(out, "t_s=", self.last_t_ms / 1000, ".", self.last_t_ms % 1000 / 100, "\r\n")?;
        let (temp, duty, mode, alarm) = match last {
            Some(o) => (o.step.temp_c.0, o.step.duty.get(), o.step.mode.name(), o.alarm.name()),
            None => (f32::NAN, f32::NAN, "-", "-"),
        };
        // The setpoint in force: an accepted `set` at once, not the last sample's (up to Ts
        // old), clamped as the step clamps it.
        let sp = self.cfg.carrier.get().setpoint_in_force(self.settings.setpoint_c);
        // What is subtracted from the reading: a lead fault the offset watch measured (kept
        // across restarts), which an engineer must see to service it.
        let offset = self.carrier.sensor_offset_c();
        put!(out, "temp_c=", Fixed(temp, 2), "\r\nsensor_offset_c=", Fixed(offset, 2), "\r\n")?;
        put!(out, "setpoint_c=", Fixed(sp, 2), "\r\nduty=", Fixed(duty, 3), "\r\n")?;
        // No law while the step holds the outputs (a sensor fault: cooling off, the law not run;
        // limp home: the supply switch's On-Off): `get` says which law resumes.
        let law = match last {
            Some(o) if o.step.mode.not_in_control() => None,
            _ => Some(self.carrier.controller()),
        };
        put!(out, "mode=", mode, "\r\nalarm=", alarm, "\r\ncontroller=", law.map_or("-", |l| l.name()), "\r\n")?;
        let status = law.and_then(|l| l.status());
        put!(out, "adaptive=", status.map_or("-", |s| s.mode.name()), "\r\ncontrollers=")?;
        for (i, l) in self.cfg.laws.iter().enumerate() {
            put!(out, if i == 0 { "" } else { "," }, l.name())?;
        }
        out.str("\r\n")?;
        let model = self.carrier.controller().trusted_model().or(match self.settings.law {
            Law::Gpc | Law::Igmvc => self.adaptive.initial,
            _ => None,
        });
        write_model(out, "model", model)?;
        write_model(out, "cabinet", self.cabinet)?;
        // The record counts every boot by its cause, the one that began it too (a power-on, or
        // the pin reset after flashing): the restarts are the boots after that one.
        let h = self.recorder.history();
        let boots: u32 = [ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other]
            .into_iter()
            .map(|c| u32::from(h.resets_by(c)))
            .sum();
        let resets = boots.saturating_sub(1);
        let holdover = last.and_then(|o| o.step.holdover_s).unwrap_or(f32::NAN);
        put!(
            out,
            "holdover_s=",
            Fixed(holdover, 0),
            "\r\nresets=",
            resets,
            "\r\nfirmware=",
            self.cfg.firmware,
            "\r\ncommissioning="
        )?;
        match (self.carrier.controller(), self.commissioned) {
            (BoardController::Commission(c), _) => match c.phase() {
                Phase::Done(_) => out.str("done")?,
                Phase::Failed(e) => put!(out, "failed:", e.name())?,
                p => put!(out, p.name(), ":", p.percent())?,
            },
            (_, Some(Ok(()))) => out.str("done")?,
            (_, Some(Err(e))) => put!(out, "failed:", e.name())?,
            (_, None) => out.str("idle")?,
        }
        put!(out, "\r\nsettings_version=", self.settings.seq, "\r\n")?;
        put!(out, "flash=", if self.store.failing() { "failing" } else { "ok" }, "\r\n")
    }
}

/// The name of a commissioning failure code ([`CommissionError::code`]), for the log's CSV.
pub fn commission_failure_name(code: u8) -> &'static str {
    CommissionError::ALL.get(usize::from(code)).map_or("unknown", |e| e.name())
}

/// A model's status lines `{key}_a=a1,a2`, `{key}_b=b0,…` (its nb B terms: up to four for the
/// self-tuner's estimate, two for a commissioned or uploaded model), `{key}_k=k`, or `-` for each
/// when there is none (or its A is not second order).
fn write_model(out: &mut impl Sink, key: &str, m: Option<Model>) -> Written {
    match m {
        Some(m) if m.na() == 2 => {
            let a = m.a();
            put!(out, key, "_a=", Fixed(a[0], 6), ",", Fixed(a[1], 6), "\r\n", key, "_b=")?;
            for (i, b) in m.b().iter().take(m.nb()).enumerate() {
                put!(out, if i == 0 { "" } else { "," }, Fixed(*b, 6))?;
            }
            put!(out, "\r\n", key, "_k=", m.k(), "\r\n")
        }
        _ => put!(out, key, "_a=-\r\n", key, "_b=-\r\n", key, "_k=-\r\n"),
    }
}

#[cfg(test)]
mod tests;
