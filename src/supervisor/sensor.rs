//! Sensor checks: is the reading the load, or the sensor?
//!
//! - **Diagnosis and recovery** (`measure`, `diagnose`): the conversion chain's open,
//!   short, out-of-range and reference faults, and readings outside the plausible range; a
//!   fault is reported once per kind and ends with the first plausible reading
//!   ([`crate::event::EventKind::SensorRecovered`]).
//! - **Stuck converter** (`StuckConverter`): a real reading always carries some noise, so the
//!   same 16-bit result [`SensorConfig::stuck_s`] in a row is a frozen front end.
//! - **Spikes** (`SpikeFilter`): a reading further than [`SpikeConfig::c`] from the filtered
//!   value is ignored; a run of them that agree with each other is a real jump (a re-seated
//!   probe, or a front end stuck at a new level) and restarts the filter, is reported as a
//!   [`EventKind::SensorOffset`], and is a sensor fault for [`SensorConfig::stuck_s`] (in the
//!   supervisor's `check`): nothing cools on it until the stuck check has had its time.
//!   Several spikes within [`SpikeConfig::window_s`] are reported. A filter that holds one
//!   reading (the first after a boot or a sensor fault) is outvoted by the next two readings
//!   when they agree with each other, below it: that first reading was a spike, too warm.
//! - **Offset** (`OffsetWatch`): a step larger than physics allows that stays at its new level
//!   is a sensor offset; it is reported, and an upward one is measured and subtracted, up to
//!   [`OffsetConfig::max_comp_c`] in total (the history keeps it across restarts). A step down
//!   by the offset subtracted, within [`OffsetConfig::hold_fraction`] of it, is its fault going
//!   away (a lead repaired): the subtraction ends.
//!
//! A change of the channel's calibration (`set cal_ice`, `set cal_warm`) is not a step of the
//! sensor: `SensorChecks::recalibrated` carries every reading the checks hold over to the new
//! line ([`crate::calib::Recalibration`]), so that the next reading continues them.
//!
//! `SensorChecks::reading` runs the last three in their order and feeds the measurement
//! filter F_a.

use super::{ms, samples_u16, samples_u8, since};
use crate::adc::AdcError;
use crate::calib::Recalibration;
use crate::event::EventKind;
use crate::filter::FirstOrder;
use crate::step::CarrierConfig;
use crate::units::{min_f32, Celsius};

/// Settings of the sensor checks.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorConfig {
    /// Identical conversions in a row for this long mean a stuck converter, s. 180 s = 18
    /// samples at 10 s: with the front end's ≈ 1.5 counts of noise, 18 equal 16-bit results in
    /// a row happen by chance about once in 10¹² samples. A real jump
    /// ([`SpikeConfig::jump_s`]) is a sensor fault for as long: a front end that stuck at the
    /// level it jumped to is found before the reading drives anything.
    pub stuck_s: f32,
    /// The spike filter.
    pub spike: SpikeConfig,
    /// The offset watch.
    pub offset: OffsetConfig,
}

impl SensorConfig {
    /// The reference board's settings.
    pub const DEFAULT: SensorConfig =
        SensorConfig { stuck_s: 180.0, spike: SpikeConfig::DEFAULT, offset: OffsetConfig::DEFAULT };
}

/// Settings of the spike filter.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpikeConfig {
    /// A reading further than this from the filtered temperature is a spike, °C. The load
    /// cannot move more than ≈ 0.2 °C in one 10 s sample; 2 °C leaves a wide margin.
    pub c: f32,
    /// Spikes agree with each other when they are within this fraction of [`Self::c`] of the
    /// previous one (a real jump reads the same level again; noise does not).
    pub agree_fraction: f32,
    /// Agreeing spikes in a row for this long are a real jump, s (60 s = 6 samples: a probe
    /// re-seated in another load reads its new level from then on). Not 30 s: three spikes in
    /// a row that agree come by chance. With spikes on 2 % of the samples, each +30…55 or
    /// −5…−30 °C off (hal-sim), three in a row within 0.5 °C of the first come once in 3·10⁸
    /// samples, ≈ 0.1 times in 30 000 missions (≈ 12 h of spikes in 30 % of them); it came
    /// once, `hter campaign --missions 10000 --seed 20001`, mission 26762: 49.9, 50.1 and
    /// 49.5 °C taken for a real level, reported as a sensor offset, the filter restarted at
    /// 49.5 °C, 30 s of full cooling. Six agree once in 10¹⁹ samples. An offset step larger
    /// than [`OffsetConfig::max_comp_c`] is confirmed as slowly.
    pub jump_s: f32,
    /// Three spikes within this window are reported, and reported at most once per window, s
    /// (several within an hour are a loose contact or EMI, not the load).
    pub window_s: f32,
}

impl SpikeConfig {
    /// The reference board's settings.
    pub const DEFAULT: SpikeConfig = SpikeConfig { c: 2.0, agree_fraction: 0.5, jump_s: 60.0, window_s: 3600.0 };
}

/// Settings of the offset watch.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OffsetConfig {
    /// A step of the calibrated reading larger than this between two samples, °C… The sensed
    /// load moves at most ≈ 0.46 °C per 10 s sample (pull-down from 43 °C, half load, measured
    /// on the hal-sim plant), so 0.7 °C is more than physics allows.
    pub step_c: f32,
    /// …that stays at its new level, within this fraction of the step…
    pub hold_fraction: f32,
    /// …and never looser than this, °C (a burst of spikes tens of degrees off must not pass for
    /// a level that holds)…
    pub hold_max_c: f32,
    /// …for this long, counting the sample of the step, s (30 s = 3 samples); twice as long for
    /// a step larger than [`Self::max_comp_c`], which is not compensated, only reported, and
    /// which three agreeing spikes in a row make by chance ([`SpikeConfig::jump_s`]).
    pub confirm_s: f32,
    /// Largest offset subtracted, in total, °C: an upward step is measured and subtracted only
    /// while the offsets subtracted so far and it come to no more than this (a larger step, one
    /// that would take the total beyond it, and any step down, are reported only). One
    /// connector or lead fault is within 3 °C; the total is bounded because every compensation
    /// is a correction the reading cannot verify, and an unbounded sum hides a warm load for
    /// good: `hter virtual-board`, before a calibration change was carried over to the checks
    /// (`Carrier::set_calibration`), took each `set cal_ice 0.0,1.4` for a 1.2 °C offset, and
    /// alternating it with `set cal_ice 0,0` added one every other change until the board read
    /// 4.00 °C for ≈ 9 h with the load at ≈ 9 °C, no alarm and a clean record.
    pub max_comp_c: f32,
}

impl OffsetConfig {
    /// The reference board's settings.
    pub const DEFAULT: OffsetConfig =
        OffsetConfig { step_c: 0.7, hold_fraction: 0.25, hold_max_c: 0.5, confirm_s: 30.0, max_comp_c: 3.0 };
}

/// Counts → calibrated °C through the channel of `cfg`, or the fault the counts reveal: open
/// and short from the front end, a resistance outside the RTD's range, a reading outside the
/// plausible range.
pub(crate) fn measure(cfg: &CarrierConfig, counts: u32) -> Result<Celsius, EventKind> {
    let ohms = cfg.adc.ohms(counts).map_err(|e| match e {
        AdcError::Open => EventKind::SensorOpen,
        AdcError::Short => EventKind::SensorShort,
        AdcError::ReferenceOutOfRange => EventKind::ReferenceOutOfRange,
    })?;
    let t = cfg.rtd.temperature(ohms).map_err(|_| EventKind::SensorOutOfRange)?;
    plausible(cfg, cfg.cal.apply(t))
}

/// The plausibility range check of a calibrated temperature.
pub(crate) fn plausible(cfg: &CarrierConfig, t: Celsius) -> Result<Celsius, EventKind> {
    if t.0.is_finite() && (cfg.plausible_min_c..=cfg.plausible_max_c).contains(&t.0) {
        Ok(t)
    } else {
        Err(EventKind::SensorOutOfRange)
    }
}

/// What the conversion result of this sample does to the sensor-fault state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Diagnosis {
    /// A fault begins, or a fault of another kind replaces the one in force: report it.
    Failed(EventKind),
    /// A plausible reading ends the fault.
    Recovered,
}

/// The sensor-fault transition of a sample whose conversion gave `raw`, with `fault` in force.
/// A fault that persists is reported once.
pub(crate) fn diagnose(raw: &Result<Celsius, EventKind>, fault: Option<EventKind>) -> Option<Diagnosis> {
    match (raw, fault) {
        (Err(kind), None) => Some(Diagnosis::Failed(*kind)),
        (Err(kind), Some(prev)) if *kind != prev => Some(Diagnosis::Failed(*kind)),
        (Ok(_), Some(_)) => Some(Diagnosis::Recovered),
        _ => None,
    }
}

/// The stuck-converter check, on the raw counts.
#[derive(Clone, Copy, Debug)]
pub(crate) struct StuckConverter {
    /// Identical conversions in a row that are stuck.
    limit: u16,
    last: Option<u32>,
    /// Conversions in a row equal to the one before.
    repeats: u16,
}

impl StuckConverter {
    pub(crate) fn new(cfg: &SensorConfig, ts_s: f32) -> Self {
        StuckConverter { limit: samples_u16(cfg.stuck_s, ts_s), last: None, repeats: 0 }
    }

    /// Identical conversions in a row that are stuck: the check's window in samples.
    pub(crate) fn window(&self) -> u16 {
        self.limit
    }

    /// Takes this sample's conversion; whether it makes `limit` identical ones in a row.
    pub(crate) fn run(&mut self, counts: u32) -> bool {
        self.repeats = if self.last == Some(counts) { self.repeats.saturating_add(1) } else { 0 };
        self.last = Some(counts);
        self.repeats.saturating_add(1) >= self.limit
    }
}

/// What the spike filter makes of a reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Spike {
    /// Not a spike.
    No,
    /// A spike: the filter keeps its value.
    Ignored,
    /// The last of a run of agreeing spikes: a real jump, the filter restarts from it.
    Jump,
}

/// Spikes in a burst that is reported ([`EventKind::SensorSpikes`]).
const BURST: usize = 3;

/// The spike filter and its burst report.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpikeFilter {
    /// Agreeing spikes in a row that are a jump.
    jump_n: u8,
    window_ms: u32,
    /// Agreeing spikes in a row so far.
    run: u8,
    /// The measurement filter holds a single reading (the first after a boot, a sensor fault's
    /// end or a restart), which no other has confirmed yet.
    unconfirmed: bool,
    /// The last spike's reading, °C.
    last_c: f32,
    /// When the last [`BURST`] spikes came, a ring (`None` until that many have come): a new
    /// spike overwrites the oldest, at `next`. Shifting the times along instead is a
    /// `copy_within`, which is a `memmove` call.
    times: [Option<u64>; BURST],
    /// The oldest spike's slot in `times`, always less than [`BURST`].
    next: usize,
    /// When a burst was last reported.
    reported_ms: Option<u64>,
}

impl SpikeFilter {
    pub(crate) fn new(cfg: &SpikeConfig, ts_s: f32) -> Self {
        SpikeFilter {
            jump_n: samples_u8(cfg.jump_s, ts_s),
            window_ms: ms(cfg.window_s),
            run: 0,
            unconfirmed: false,
            last_c: f32::NAN,
            times: [None; BURST],
            next: 0,
            reported_ms: None,
        }
    }

    /// The channel's calibration changed by `r`: the last spike's reading, which the next must
    /// agree with to make a run, as the new line reads it.
    pub(crate) fn recalibrated(&mut self, r: &Recalibration) {
        self.last_c = r.level(self.last_c);
    }

    /// Whether the reading `t` is a spike against the filtered value `filtered` (no spike
    /// without both).
    pub(crate) fn is_spike(cfg: &SpikeConfig, t: Option<Celsius>, filtered: Option<f32>) -> bool {
        match (t, filtered) {
            (Some(t), Some(prev)) => (t.0 - prev).abs() > cfg.c,
            _ => false,
        }
    }

    /// Takes the reading `t` at `t_ms` and whether it is a spike ([`Self::is_spike`]).
    pub(crate) fn run(
        &mut self,
        cfg: &SpikeConfig,
        t_ms: u64,
        t: Option<Celsius>,
        spike: bool,
        emit: &mut impl FnMut(EventKind),
    ) -> Spike {
        // Spikes that agree with each other are a real jump; ones that do not are noise, and
        // the filter keeps its value.
        let consistent = t.is_some_and(|t| (t.0 - self.last_c).abs() < cfg.agree_fraction * cfg.c);
        let Some(t) = t.filter(|_| spike) else {
            self.run = 0;
            return Spike::No;
        };
        self.last_c = t.0;
        if self.run > 0 && !consistent {
            self.run = 0;
        }
        self.run = self.run.saturating_add(1);
        if let Some(slot) = self.times.get_mut(self.next) {
            *slot = Some(t_ms);
        }
        self.next = if self.next + 1 < BURST { self.next + 1 } else { 0 };
        // Now the oldest of the last BURST spikes, this one included.
        let oldest = self.times.get(self.next).copied().flatten();
        let burst = oldest.is_some_and(|t0| since(t_ms, t0) <= u64::from(self.window_ms));
        let quiet = self.reported_ms.is_none_or(|r| since(t_ms, r) > u64::from(self.window_ms));
        if burst && quiet {
            emit(EventKind::SensorSpikes);
            self.reported_ms = Some(t_ms);
        }
        if self.run >= self.jump_n {
            Spike::Jump
        } else {
            Spike::Ignored
        }
    }
}

/// The sensor-offset watch.
#[derive(Clone, Copy, Debug)]
pub(crate) struct OffsetWatch {
    /// Samples a step must hold, counting its own (twice as many for one larger than
    /// [`OffsetConfig::max_comp_c`]).
    confirm_n: u8,
    /// Offset measured and subtracted, °C.
    offset_c: f32,
    /// The last offset-corrected reading that was not a spike: the reference for a step.
    /// After a spike the good reading that follows must not look like a step from the spike,
    /// and the filtered value lags a fast pull-down too much to serve.
    last_good_c: Option<f32>,
    /// How far the reference moved a sample from the good reading before it, °C (the mean over
    /// the spikes between them; 0 when there was none): the load's own motion, to carry the
    /// reference across spikes.
    trend_c: f32,
    /// Readings watched since the reference was taken (1 on the sample right after it; more
    /// when spikes came between).
    age: u8,
    /// A step under watch: (level before, step, samples it has held).
    pending: Option<(f32, f32, u8)>,
}

impl OffsetWatch {
    pub(crate) fn new(cfg: &OffsetConfig, ts_s: f32) -> Self {
        OffsetWatch {
            confirm_n: samples_u8(cfg.confirm_s, ts_s),
            offset_c: 0.0,
            last_good_c: None,
            trend_c: 0.0,
            age: 0,
            pending: None,
        }
    }

    /// Whether a step is under watch.
    pub(crate) fn watching(&self) -> bool {
        self.pending.is_some()
    }

    /// The offset subtracted from every reading, °C.
    pub(crate) fn offset_c(&self) -> f32 {
        self.offset_c
    }

    /// Watches the offset-corrected reading `raw`; returns whether the filter must hold this
    /// sample (a step is under watch). Once a step has held its level for `confirm_n` samples
    /// (twice that for a step too large to compensate) it is measured, subtracted from every
    /// later reading and reported.
    ///
    /// A step whose own sample was a spike (not kept as the reference) ends with the first
    /// reading that does not hold the spike's level. That reading is the first good one since
    /// the reference, so it is itself checked for a step, against the reference carried on by
    /// the load's trend over the samples between (mission 49578, `--seed 40001`: an offset that
    /// began on the sample after a spike became the reference unseen; the trend keeps a fast
    /// fall in limp home from reading as a step across the spike).
    pub(crate) fn watch(&mut self, cfg: &OffsetConfig, raw: f32, emit: &mut impl FnMut(EventKind)) -> bool {
        self.age = self.age.saturating_add(1);
        // A reference from before a run of spikes longer than the slowest confirmation is gone,
        // as after a missing reading: carried that far, the trend is the front end's noise
        // (±0.01 °C a sample: 2.4 °C over a 200-sample burst, measured and subtracted as an
        // offset), not the load's motion.
        if u16::from(self.age) > u16::from(self.confirm_n) << 1 {
            self.last_good_c = None;
        }
        match (self.pending, self.last_good_c) {
            (Some((before, step, n)), reference) => {
                if (raw - (before + step)).abs() <= min_f32(cfg.hold_fraction * step.abs(), cfg.hold_max_c) {
                    let n = n.saturating_add(1);
                    if n >= self.confirm_n << u8::from(step.abs() > cfg.max_comp_c) {
                        // Measured on this sample: the load itself has not moved measurably.
                        // Only a step *up* of at most `max_comp_c` is subtracted: a reading too
                        // warm makes the controller overcool — the freezing side — while one
                        // too cold only under-cools, which the warm alarms catch, and which is
                        // also what a probe re-seated in a colder load looks like.
                        // The total, not each step, is bounded: offsets that add up hide a warm
                        // load as surely as one large one ([`OffsetConfig::max_comp_c`]).
                        let measured = raw - before;
                        if measured > 0.0 && self.offset_c + measured <= cfg.max_comp_c {
                            self.offset_c += measured;
                        } else if (measured + self.offset_c).abs() <= cfg.hold_fraction * self.offset_c {
                            // A step down by the offset subtracted: the fault it compensated went
                            // away (a lead re-seated or repaired). Kept across restarts, the
                            // offset would otherwise read the load that much cold for good.
                            self.offset_c = 0.0;
                        }
                        self.pending = None;
                        emit(EventKind::SensorOffset);
                    } else {
                        self.pending = Some((before, step, n));
                    }
                    true
                } else {
                    // Back (a transient, which the spike filter handles) or somewhere else,
                    // which after a spike may be a step of its own.
                    self.pending = None;
                    match reference {
                        Some(p) if self.age >= 2 => self.step_from(cfg, p + f32::from(self.age) * self.trend_c, raw),
                        _ => false,
                    }
                }
            }
            (None, Some(p)) => self.step_from(cfg, p, raw),
            _ => false,
        }
    }

    /// Starts watching `raw` as a step from `level` if it is one.
    fn step_from(&mut self, cfg: &OffsetConfig, level: f32, raw: f32) -> bool {
        let step = (raw - level).abs() > cfg.step_c;
        if step {
            self.pending = Some((level, raw - level, 1));
        }
        step
    }

    /// The spike filter took the reading `t` for a real jump: the step under watch is over,
    /// and `t` is the reference for the next one.
    pub(crate) fn rebase(&mut self, t: f32) {
        self.pending = None;
        self.last_good_c = Some(t);
        self.trend_c = 0.0;
        self.age = 0;
    }

    /// The channel's calibration changed by `r`: the reference, the trend and a step under
    /// watch are carried over to the new line, so the next reading is compared with what the
    /// new line reads and a step the sensor really made is still confirmed or dropped on its
    /// merits. The offset in force stays: it was measured as a step of the sensor (a connector
    /// or lead fault), which a new line through the channel does not mend, so it is carried over
    /// as the same fault seen through the new gain (at most [`OffsetConfig::max_comp_c`]).
    /// Clearing it would be the freezing side if the fault is still there (the reading too warm
    /// by up to 3 °C, the controller and the freeze guard overcooling); keeping it is at worst
    /// the warm side, if the new points were taken with the fault in the channel (the
    /// uncalibrated counts of the log, README "Calibrating a board"), as the watch's own rule
    /// for which steps it subtracts has it. Returns the change of the offset-corrected reading:
    /// `r`, plus the part of the offset the bound did not carry over.
    pub(crate) fn recalibrated(&mut self, cfg: &OffsetConfig, r: &Recalibration) -> Recalibration {
        // corrected = T − offset through either line, so corrected_new = gain · corrected_old
        // + shift_c + (gain · offset_old − offset_new).
        let carried = r.difference(self.offset_c);
        let offset_c = min_f32(carried, cfg.max_comp_c);
        let r = Recalibration { gain: r.gain, shift_c: r.shift_c + (carried - offset_c) };
        self.last_good_c = self.last_good_c.map(|t| r.level(t));
        self.trend_c = r.difference(self.trend_c);
        self.pending = self.pending.map(|(before, step, n)| (r.level(before), r.difference(step), n));
        self.offset_c = offset_c;
        r
    }

    /// The offset a previous boot subtracted (restored from the history, before the first
    /// sample; not negative), at most `max_comp_c`: the fault it measured is still in the
    /// channel.
    pub(crate) fn restore(&mut self, cfg: &OffsetConfig, offset_c: f32) {
        self.offset_c = min_f32(offset_c, cfg.max_comp_c);
    }

    /// No reading this sample: a step under watch, and the reference, are gone.
    pub(crate) fn forget(&mut self) {
        self.last_good_c = None;
        self.pending = None;
    }

    /// `t`, which was not a spike, is the reference for the next step, in the frame of the
    /// offset in force after this sample (`offset_before` was in force before it).
    pub(crate) fn keep_reference(&mut self, t: f32, offset_before: f32) {
        // Both in the frame of `offset_before`: a change of the offset is no motion. Across
        // spikes (`age` > 1) the load's mean motion a sample since the reference: a fall that
        // goes on across a second spike is carried on as across the first.
        self.trend_c = match self.last_good_c {
            Some(p) if self.age > 0 => (t - p) / f32::from(self.age),
            _ => 0.0,
        };
        self.last_good_c = Some(t - (self.offset_c - offset_before));
        self.age = 0;
    }
}

/// A first reading (after a boot or a sensor fault) below this, °C, is outvoted by two readings
/// above it that agree, as one above them is by two below: a load below freezing is not what a
/// carrier that only cools makes of vaccines held at 2–8 °C, and a frozen load keeps reading
/// frozen. Above it a first reading is trusted over readings above it (module docs, mission
/// 70549).
pub const OUTVOTE_UP_BELOW_C: f32 = 0.0;

/// This sample's reading after the sensor checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Reading {
    /// The calibrated, offset-corrected reading (`None` on a sensor fault).
    pub(crate) raw_c: Option<Celsius>,
    /// The filtered temperature, °C (the last good value on a fault or a spike; NaN before the
    /// first good reading).
    pub(crate) temp_c: f32,
    /// The spike filter took a run of agreeing spikes for a real jump this sample, and
    /// restarted from it (reported as [`EventKind::SensorOffset`]).
    pub(crate) jump: bool,
    /// The filter's first reading was outvoted this sample, and the filter restarted from this
    /// one: what was derived from the filtered value (the freeze guard's slope, the SSR checks'
    /// history) restarts too.
    pub(crate) outvoted: bool,
}

/// The stuck, spike and offset checks of the sensor.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SensorChecks {
    pub(crate) stuck: StuckConverter,
    spikes: SpikeFilter,
    offset: OffsetWatch,
}

impl SensorChecks {
    pub(crate) fn new(cfg: &SensorConfig, ts_s: f32) -> Self {
        SensorChecks {
            stuck: StuckConverter::new(cfg, ts_s),
            spikes: SpikeFilter::new(&cfg.spike, ts_s),
            offset: OffsetWatch::new(&cfg.offset, ts_s),
        }
    }

    /// The channel's calibration changed by `r` (the next sample reads through the new line):
    /// carries the offset watch's and the spike filter's readings, and the measurement filter's
    /// value, over to it (the stuck check reads counts, which no calibration changes). Returns
    /// the change of the offset-corrected reading, which the filter's value and every
    /// detector's history of it take ([`OffsetWatch::recalibrated`]).
    pub(crate) fn recalibrated(
        &mut self,
        cfg: &SensorConfig,
        r: &Recalibration,
        filter: &mut FirstOrder,
    ) -> Recalibration {
        let r = self.offset.recalibrated(&cfg.offset, r);
        self.spikes.recalibrated(&r);
        filter.remap(|y| r.level(y));
        r
    }

    /// The offset the watch subtracts from every reading, °C.
    pub(crate) fn offset_c(&self) -> f32 {
        self.offset.offset_c()
    }

    /// Restores the offset a previous boot subtracted ([`OffsetWatch::restore`]).
    pub(crate) fn restore_offset(&mut self, cfg: &SensorConfig, offset_c: f32) {
        self.offset.restore(&cfg.offset, offset_c);
    }

    /// A calibration change that cannot be carried over ([`Recalibration::between`] found the
    /// old line not invertible): the references are dropped, as after a sensor fault, and the
    /// next reading starts them again.
    pub(crate) fn restart(&mut self, filter: &mut FirstOrder) {
        self.offset.forget();
        filter.reset();
    }

    /// Takes this sample's conversion result `raw` (calibrated, `Err` on a fault) and feeds the
    /// measurement filter with what passes. The offset watch runs on the raw sensor path only
    /// (`sensor`; an ideal-measurement plant has no sensor); then the spike filter, whose
    /// verdict needs the filter's value before this sample.
    pub(crate) fn reading(
        &mut self,
        cfg: &CarrierConfig,
        t_ms: u64,
        raw: Result<Celsius, EventKind>,
        sensor: bool,
        filter: &mut FirstOrder,
        emit: &mut impl FnMut(EventKind),
    ) -> Reading {
        let (sc, filter_cfg) = (&cfg.supervisor.sensor, &cfg.filter);
        let mut hold = false;
        // Reset by the supervisor (a sensor fault's end) or before the first reading; not by a
        // jump or an outvote below, whose readings are confirmed.
        let empty = filter.output().is_none();
        let offset_before = self.offset.offset_c();
        let mut offset_reported = false;
        let raw_c = match raw.ok() {
            Some(t) if sensor => {
                let corrected = t.0 - self.offset.offset_c();
                let watching = self.offset.watching();
                hold = self.offset.watch(&sc.offset, corrected, emit);
                // A step under watch that ended held: it was confirmed, and reported.
                offset_reported = watching && hold && !self.offset.watching();
                Some(Celsius(corrected))
            }
            other => other,
        };
        if raw_c.is_none() {
            self.offset.forget();
        }
        let spike = SpikeFilter::is_spike(&sc.spike, raw_c, filter.output());
        if let (Some(t), false) = (raw_c, spike) {
            self.offset.keep_reference(t.0, offset_before);
        }
        let verdict = self.spikes.run(&sc.spike, t_ms, raw_c, spike, emit);
        // A filter started on one reading cannot tell a spike: two readings in a row that agree
        // with each other and not with it outvote it, and it restarts from them. Without this a
        // spike on the first reading after a boot or a sensor fault was the filter's value, and
        // the good readings after it spikes, until six of them made a jump: 60 s of full cooling
        // on a load read at 50 °C, the freeze guard blind, then 3 min of a sensor fault.
        // Readings below it outvote it (it read warm, which cools blind). Readings above it may
        // be an offset that began on the second reading, which the offset watch subtracts, or
        // a front end stuck high right after a boot over a cold load (mission 70549, a load at
        // 0.6 °C): they outvote only a first reading below freezing ([`OUTVOTE_UP_BELOW_C`]), a
        // load the carrier cannot have made. A first reading too cold held cooling off until
        // six readings made a jump, and the jump's sensor fault 3 min more: a light carrier at
        // 40 °C went from 4.0 to 9.0 °C (mission 65944, `--seed 60001`: −18.6 °C on the first
        // reading after a brown-out), and the offset it reported sent a technician to the probe.
        let first = filter.output().unwrap_or(f32::NAN);
        let outvoted = self.spikes.unconfirmed
            && verdict == Spike::Ignored
            && self.spikes.run >= 2
            // This reading, the spike's (`last_c`), below the filter's, or the filter's frozen.
            && (self.spikes.last_c < first || first < OUTVOTE_UP_BELOW_C);
        let jump = verdict == Spike::Jump;
        if jump || outvoted {
            filter.reset();
            // The jump is the step the offset watch was watching: its new level is the
            // reference from now on, and it is reported once, here if the watch has not yet.
            if let Some(t) = raw_c {
                self.offset.rebase(t.0);
            }
            if jump && !offset_reported {
                emit(EventKind::SensorOffset);
            }
        }
        let temp_c = match raw_c {
            // An empty filter (just reset) starts from the reading rather than report nothing.
            Some(t) if (!hold && verdict != Spike::Ignored) || filter.output().is_none() => {
                // Unconfirmed if it starts the filter on this reading alone.
                self.spikes.unconfirmed = empty;
                filter.step(filter_cfg, t.0)
            }
            _ => filter.output().unwrap_or(f32::NAN),
        };
        Reading { raw_c, temp_c, jump, outvoted }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TS: f32 = 10.0;
    const SPIKE: SpikeConfig = SpikeConfig::DEFAULT;
    const OFFSET: OffsetConfig = OffsetConfig::DEFAULT;

    fn kinds(f: impl FnOnce(&mut dyn FnMut(EventKind))) -> Vec<EventKind> {
        let mut v = Vec::new();
        f(&mut |k| v.push(k));
        v
    }

    #[test]
    fn a_fault_is_reported_once_per_kind_and_ends_with_a_good_reading() {
        let open = Err(EventKind::SensorOpen);
        assert_eq!(diagnose(&open, None), Some(Diagnosis::Failed(EventKind::SensorOpen)));
        assert_eq!(diagnose(&open, Some(EventKind::SensorOpen)), None);
        assert_eq!(
            diagnose(&Err(EventKind::SensorShort), Some(EventKind::SensorOpen)),
            Some(Diagnosis::Failed(EventKind::SensorShort))
        );
        assert_eq!(diagnose(&Ok(Celsius(4.0)), Some(EventKind::SensorShort)), Some(Diagnosis::Recovered));
        assert_eq!(diagnose(&Ok(Celsius(4.0)), None), None);
    }

    #[test]
    fn a_stuck_converter_is_eighteen_identical_counts_not_seventeen() {
        let mut s = StuckConverter::new(&SensorConfig::DEFAULT, TS);
        assert_eq!(s.limit, 18);
        let verdicts: Vec<bool> = (0..18).map(|_| s.run(49_900)).collect();
        assert!(verdicts[..17].iter().all(|v| !v), "fired before 18: {verdicts:?}");
        assert!(verdicts[17]);
        // One different count starts the run again.
        assert!(!s.run(49_901));
        assert!((1..17).all(|_| !s.run(49_901)));
        assert!(s.run(49_901));
    }

    #[test]
    fn spikes_are_ignored_and_six_agreeing_ones_are_a_jump() {
        let mut f = SpikeFilter::new(&SpikeConfig::DEFAULT, TS);
        assert!(!SpikeFilter::is_spike(&SPIKE, Some(Celsius(6.0)), Some(4.0)), "2 °C off is not yet a spike");
        assert!(SpikeFilter::is_spike(&SPIKE, Some(Celsius(6.01)), Some(4.0)));
        assert!(!SpikeFilter::is_spike(&SPIKE, Some(Celsius(10.0)), None), "no spike without a filtered value");
        let mut e = |_: EventKind| {};
        assert_eq!(f.run(&SPIKE, 0, Some(Celsius(10.0)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 10_000, Some(Celsius(10.4)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 20_000, Some(Celsius(10.2)), true, &mut e), Spike::Ignored, "three agree by chance");
        assert_eq!(f.run(&SPIKE, 30_000, Some(Celsius(10.1)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 40_000, Some(Celsius(10.3)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 50_000, Some(Celsius(10.2)), true, &mut e), Spike::Jump);
        // Spikes that disagree (more than 1 °C apart) start the run again.
        let mut f = SpikeFilter::new(&SpikeConfig::DEFAULT, TS);
        assert_eq!(f.run(&SPIKE, 0, Some(Celsius(10.0)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 10_000, Some(Celsius(20.0)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 20_000, Some(Celsius(30.0)), true, &mut e), Spike::Ignored);
        // A good reading between them too.
        assert_eq!(f.run(&SPIKE, 30_000, Some(Celsius(30.0)), true, &mut e), Spike::Ignored);
        assert_eq!(f.run(&SPIKE, 40_000, Some(Celsius(4.0)), false, &mut e), Spike::No);
        assert_eq!(f.run(&SPIKE, 50_000, Some(Celsius(30.0)), true, &mut e), Spike::Ignored);
    }

    #[test]
    fn three_spikes_within_an_hour_are_reported_once_an_hour() {
        let mut f = SpikeFilter::new(&SpikeConfig::DEFAULT, TS);
        let spike_at = |f: &mut SpikeFilter, t_s: u64| {
            kinds(|e| {
                f.run(&SPIKE, t_s * 1000, Some(Celsius(30.0 + t_s as f32)), true, &mut |k| e(k));
            })
        };
        assert!(spike_at(&mut f, 0).is_empty());
        assert!(spike_at(&mut f, 1800).is_empty());
        // The third within 3600 s of the first: reported.
        assert_eq!(spike_at(&mut f, 3600), [EventKind::SensorSpikes]);
        // Not again within the hour after the report…
        assert!(spike_at(&mut f, 4000).is_empty());
        assert!(spike_at(&mut f, 7200).is_empty());
        // …and again after it, once three fall within an hour.
        assert_eq!(spike_at(&mut f, 7201), [EventKind::SensorSpikes]);
        // Three spread over more than an hour are not a burst.
        let mut f = SpikeFilter::new(&SpikeConfig::DEFAULT, TS);
        assert!(spike_at(&mut f, 0).is_empty());
        assert!(spike_at(&mut f, 1801).is_empty());
        assert!(spike_at(&mut f, 3601).is_empty());
    }

    #[test]
    fn an_offset_that_holds_three_samples_is_measured_and_subtracted() {
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        assert_eq!(w.confirm_n, 3);
        let mut e = |_: EventKind| {};
        assert!(!w.watch(&OFFSET, 4.0, &mut e));
        w.keep_reference(4.0, 0.0);
        // A 0.6 °C step is still physics; 1.5 °C is not.
        assert!(!w.watch(&OFFSET, 4.6, &mut e));
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 5.5, &mut e), "held while under watch");
        assert!(w.watch(&OFFSET, 5.6, &mut e));
        let ev = kinds(|k| assert!(w.watch(&OFFSET, 5.45, &mut |x| k(x))));
        assert_eq!(ev, [EventKind::SensorOffset]);
        assert!((w.offset_c() - 1.45).abs() < 1e-6, "{}", w.offset_c());
        // A step down is reported but not subtracted.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.keep_reference(6.0, 0.0);
        assert!(w.watch(&OFFSET, 4.0, &mut e) && w.watch(&OFFSET, 4.0, &mut e));
        assert_eq!(kinds(|k| assert!(w.watch(&OFFSET, 4.0, &mut |x| k(x)))), [EventKind::SensorOffset]);
        assert_eq!(w.offset_c(), 0.0);
    }

    #[test]
    fn a_step_that_does_not_hold_its_level_is_no_offset() {
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        let mut e = |k: EventKind| panic!("reported {k:?}");
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 6.0, &mut e));
        // 2 °C off the filtered value is not a spike: the step's reading is the reference.
        w.keep_reference(6.0, 0.0);
        // Within a quarter of the 2 °C step is 0.5 °C; 0.51 °C off is not holding.
        assert!(!w.watch(&OFFSET, 6.51, &mut e), "released");
        // A 10 °C step (a spike: not the reference) must hold within 0.5 °C, not within a
        // quarter of it. The reading that does not hold it is the first since the reference
        // and is watched as a step of its own from there. Two references at 4 °C: a load at
        // rest (no trend to carry the reference on by).
        w.keep_reference(4.0, 0.0);
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 14.0, &mut e));
        assert!(w.watch(&OFFSET, 14.6, &mut e));
        assert_eq!(w.pending, Some((4.0, 10.6, 1)));
        assert!(!w.watch(&OFFSET, 4.05, &mut e), "back at the reference: no step");
        assert_eq!(w.pending, None);
    }

    #[test]
    fn an_upward_offset_above_the_limit_is_reported_only() {
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        let mut e = |_: EventKind| {};
        w.keep_reference(4.0, 0.0);
        let ev = kinds(|k| (0..6).for_each(|_| assert!(w.watch(&OFFSET, 7.5, &mut |x| k(x)))));
        assert_eq!(ev, [EventKind::SensorOffset]);
        assert_eq!(w.offset_c(), 0.0, "3.5 °C is more than the 3 °C compensated");
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 7.0, &mut e) && w.watch(&OFFSET, 7.0, &mut e) && w.watch(&OFFSET, 7.0, &mut e));
        assert_eq!(w.offset_c(), 3.0);
    }

    #[test]
    fn the_offsets_subtracted_never_add_up_to_more_than_max_comp_c() {
        // Two upward steps of 2 °C, each within the 3 °C compensated: the first is subtracted,
        // the second would take the total to 4 °C and is reported only.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        let mut events = Vec::new();
        let mut read = |w: &mut OffsetWatch, t: f32| {
            let offset = w.offset_c();
            let corrected = t - offset;
            w.watch(&OFFSET, corrected, &mut |k| events.push(k));
            w.keep_reference(corrected, offset);
        };
        read(&mut w, 4.0);
        (0..4).for_each(|_| read(&mut w, 6.0));
        assert_eq!(w.offset_c(), 2.0);
        (0..4).for_each(|_| read(&mut w, 8.0));
        assert_eq!(w.offset_c(), 2.0, "4 °C in total is more than the 3 °C compensated");
        // A third of 1 °C fits: 3 °C in total.
        (0..4).for_each(|_| read(&mut w, 9.0));
        assert_eq!(w.offset_c(), 3.0);
        // And nothing more, however small and however many.
        for k in 0..20 {
            (0..4).for_each(|_| read(&mut w, 9.0 + 0.8 * (k + 1) as f32));
        }
        assert_eq!(w.offset_c(), 3.0);
        assert_eq!(events.len(), 23, "every step reported: {events:?}");
        assert!(events.iter().all(|k| *k == EventKind::SensorOffset));
    }

    #[test]
    fn a_recalibration_carries_the_references_and_the_offset_over_to_the_new_line() {
        let r = Recalibration { gain: 0.944, shift_c: 1.4 };
        // At rest at 4 °C, with 1 °C subtracted: the reading through the new line continues the
        // reference, no step.
        let mut s = SensorChecks::new(&SensorConfig::DEFAULT, TS);
        s.offset.offset_c = 1.0;
        let mut f = FirstOrder::default();
        let cfg = CarrierConfig::DEFAULT;
        let mut none = |k: EventKind| panic!("reported {k:?}");
        for k in 0..5 {
            s.reading(&cfg, k * 10_000, Ok(Celsius(5.0)), true, &mut f, &mut none);
        }
        let rc = s.recalibrated(&SensorConfig::DEFAULT, &r, &mut f);
        assert!((s.offset.offset_c() - 0.944).abs() < 1e-6, "the same fault through the new gain");
        let new = r.level(5.0) - s.offset.offset_c();
        assert!((rc.level(4.0) - new).abs() < 1e-5);
        assert!((f.output().unwrap() - new).abs() < 1e-5, "the filter moved with the line");
        for k in 5..15 {
            let read = s.reading(&cfg, k * 10_000, Ok(Celsius(r.level(5.0))), true, &mut f, &mut none);
            assert!((read.temp_c - new).abs() < 1e-5, "sample {k}: {}", read.temp_c);
        }
        // The offset carried over stays within the bound.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.offset_c = 2.9;
        let rc = w.recalibrated(&OFFSET, &Recalibration { gain: 1.2, shift_c: 0.0 });
        assert_eq!(w.offset_c(), 3.0);
        assert!((rc.shift_c - 0.48).abs() < 1e-5, "{rc:?}");
        // A step under watch is carried over and still confirmed.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 5.5, &mut none));
        w.recalibrated(&OFFSET, &Recalibration { gain: 1.0, shift_c: 1.0 });
        assert!(w.watch(&OFFSET, 6.5, &mut none));
        assert_eq!(kinds(|k| assert!(w.watch(&OFFSET, 6.5, &mut |x| k(x)))), [EventKind::SensorOffset]);
        assert!((w.offset_c() - 1.5).abs() < 1e-6, "{}", w.offset_c());
    }

    #[test]
    fn a_step_too_large_to_compensate_holds_twice_as_long() {
        // Mission 26762 (`--seed 20001`): three spikes in a row at 49.9, 50.1 and 49.5 °C.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        let mut none = |k: EventKind| panic!("reported {k:?}");
        w.keep_reference(4.09, 0.0);
        assert!(w.watch(&OFFSET, 49.87, &mut none) && w.watch(&OFFSET, 50.06, &mut none));
        assert!(w.watch(&OFFSET, 49.50, &mut none), "three that agree are not yet a level");
        assert!(!w.watch(&OFFSET, 3.94, &mut none), "back: no offset");
        // 3 °C is compensated: three samples.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.keep_reference(4.0, 0.0);
        assert!(w.watch(&OFFSET, 7.0, &mut none) && w.watch(&OFFSET, 7.0, &mut none));
        assert_eq!(kinds(|k| assert!(w.watch(&OFFSET, 7.0, &mut |x| k(x)))), [EventKind::SensorOffset]);
        // 3.1 °C is not: six.
        let mut w = OffsetWatch::new(&OffsetConfig::DEFAULT, TS);
        w.keep_reference(4.0, 0.0);
        assert!((0..5).all(|_| w.watch(&OFFSET, 7.1, &mut none)));
        assert_eq!(kinds(|k| assert!(w.watch(&OFFSET, 7.1, &mut |x| k(x)))), [EventKind::SensorOffset]);
    }

    /// Feeds `readings` through the sensor checks (raw path) from time 0; the events and the
    /// offset at the end.
    fn through_checks(readings: &[f32]) -> (Vec<(usize, EventKind)>, f32) {
        let mut s = SensorChecks::new(&SensorConfig::DEFAULT, TS);
        let cfg = CarrierConfig::DEFAULT;
        let mut f = FirstOrder::default();
        let mut ev = Vec::new();
        for (k, &t) in readings.iter().enumerate() {
            s.reading(&cfg, k as u64 * 10_000, Ok(Celsius(t)), true, &mut f, &mut |e| ev.push((k, e)));
        }
        (ev, s.offset.offset_c())
    }

    #[test]
    fn an_offset_that_starts_on_the_sample_after_a_spike_is_found() {
        // Mission 49578 (`--seed 40001`), 72 000–72 060 s: the +1.5 °C offset began on the
        // reading after a spike; it used to become the reference unseen.
        let (ev, offset) = through_checks(&[4.046, 4.056, 4.082, -23.717, 5.568, 5.521, 5.500, 5.459]);
        assert_eq!(ev, [(6, EventKind::SensorOffset)]);
        assert!((1.3..=1.5).contains(&offset), "measured {offset}");
        // The same without the offset: the reading after the spike is the load, no step.
        let (ev, offset) = through_checks(&[4.046, 4.056, 4.082, -23.717, 4.090, 4.101, 4.095, 4.099]);
        assert!(ev.is_empty(), "{ev:?}");
        assert_eq!(offset, 0.0);
    }

    #[test]
    fn a_fast_fall_across_a_spike_is_no_step() {
        // A light load in limp home falls 0.4 °C a sample; across a spike the reading is 0.8 °C
        // below the one before it, more than the 0.7 °C step, and its trend explains it. The
        // fall then slows to a level that holds.
        let (ev, offset) = through_checks(&[6.4, 6.0, 5.6, 5.2, 45.0, 4.4, 4.3, 4.25, 4.22, 4.2]);
        assert!(ev.is_empty(), "{ev:?}");
        assert_eq!(offset, 0.0);
    }

    #[test]
    fn a_fast_fall_across_two_spikes_one_reading_apart_is_no_step() {
        // The same fall, 0.37 °C a sample, with a good reading between two spikes: the trend
        // carried over the first spike is the load's too. It used to be forgotten there, the
        // reading after the second spike taken for a 0.74 °C step, the filter held while the
        // steps were watched and the load falling past it, until the readings, 2 °C under the
        // held value, were six agreeing spikes: a jump, reported as a sensor offset, and 3 min
        // of a sensor fault (found by a fuzz of the checks: 7.3 °C held while the load fell to
        // 3.1 °C).
        let mut readings: Vec<f32> = (0..8).map(|k| 9.0 - 0.37 * k as f32).collect();
        let fall = |k: usize| 9.0 - 0.37 * k as f32;
        readings.extend([-16.5, fall(9), 45.0, fall(11), 35.8]);
        readings.extend((13..30).map(fall));
        let (ev, offset) = through_checks(&readings);
        assert!(ev.iter().all(|(_, e)| *e == EventKind::SensorSpikes), "{ev:?}");
        assert_eq!(offset, 0.0);
    }

    #[test]
    fn a_long_burst_of_spikes_makes_no_offset_of_the_noise() {
        // A load at rest at 4 °C, its last two readings 0.012 °C apart (the front end's noise),
        // then a failing contact: 200 readings in a row each far off and none agreeing with the
        // one before (33 minutes), then the load again, where it was. The noise's "trend"
        // carried over 200 samples is no level the load left.
        let mut readings = vec![4.0, 4.012, 4.0, 3.988];
        readings.extend((0..200).map(|k| if k % 2 == 0 { 30.0 } else { 10.0 }));
        readings.extend([4.0; 10]);
        let (ev, offset) = through_checks(&readings);
        assert!(ev.iter().all(|(_, e)| *e == EventKind::SensorSpikes), "{ev:?}");
        assert_eq!(offset, 0.0);
    }

    #[test]
    fn the_filter_holds_on_spikes_and_restarts_on_a_jump() {
        let mut s = SensorChecks::new(&SensorConfig::DEFAULT, TS);
        let cfg = CarrierConfig::DEFAULT;
        let mut f = FirstOrder::default();
        let read = |s: &mut SensorChecks, f: &mut FirstOrder, k: u64, t: f32| {
            s.reading(&cfg, k * 10_000, Ok(Celsius(t)), false, f, &mut |_| {}).temp_c
        };
        assert_eq!(read(&mut s, &mut f, 0, 4.0), 4.0);
        assert_eq!(read(&mut s, &mut f, 1, 4.2), 4.1);
        assert_eq!(read(&mut s, &mut f, 2, 9.0), 4.1, "a spike is ignored");
        for k in 3..7 {
            assert_eq!(read(&mut s, &mut f, k, 9.0), 4.1, "sample {k}");
        }
        // The sixth in a row restarts the filter, and is reported (here with no offset watch,
        // `sensor` false, to have reported it).
        let jump = kinds(|e| {
            let r = s.reading(&cfg, 70_000, Ok(Celsius(9.0)), false, &mut f, &mut |k| e(k));
            assert_eq!((r.temp_c, r.jump), (9.0, true));
        });
        assert_eq!(jump, [EventKind::SensorOffset]);
        assert!(!s.reading(&cfg, 75_000, Ok(Celsius(9.0)), false, &mut f, &mut |_| {}).jump);
        let none = s.reading(&cfg, 80_000, Err(EventKind::SensorOpen), false, &mut f, &mut |_| {});
        assert_eq!((none.raw_c, none.temp_c), (None, 9.0));
    }
}

/// The sensor checks as the step runs them.
#[cfg(test)]
mod carrier {
    use crate::event::EventKind;
    use crate::step::tests::{counts_at, pi_carrier};
    use crate::step::{CarrierConfig, Mode, StepInput};
    use crate::units::{Duty, Ohms};

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
    fn a_reference_fault_is_a_sensor_fault_until_a_valid_sample() {
        let mut c = pi_carrier();
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

    /// Steps `c` at sample `k` on counts `counts`; the output.
    fn at(c: &mut crate::step::Carrier<crate::control::AnyController>, k: u64, counts: u32) -> crate::step::StepOutput {
        c.step(&StepInput { t_ms: k * 10_000, counts, setpoint_c: 4.0 })
    }

    /// A default carrier under PI whose freeze guard holds a load at 0.64 °C (counts with a
    /// count of noise, so that the stuck-converter check stays quiet), at sample 30.
    fn guarded_at_0_64() -> crate::step::Carrier<crate::control::AnyController> {
        let mut c = pi_carrier();
        for k in 0..30 {
            let out = at(&mut c, k, counts_at(0.64) + (k % 2) as u32);
            assert_eq!((out.mode, out.duty, out.supply_enable), (Mode::FreezeGuard, Duty::OFF, false), "sample {k}");
        }
        c
    }

    #[test]
    fn a_reading_stuck_high_over_a_cold_load_never_cools() {
        // Mission 70549 (`--seed 70001`): the front end stuck at 55.12 °C over a load the
        // freeze guard held at 0.64 °C. The spike filter took the sixth agreeing reading for a
        // real jump, the guard released, and 12 samples of full cooling took the load to
        // −2.3 °C before the stuck-converter check fired.
        let mut c = guarded_at_0_64();
        let stuck = counts_at(55.12);
        let mut events = Vec::new();
        for k in 30..60 {
            let out = at(&mut c, k, stuck);
            assert_eq!((out.duty, out.supply_enable), (Duty::OFF, false), "sample {k}");
            let expected = match k {
                30..35 => Mode::FreezeGuard,
                _ => Mode::SensorFault,
            };
            assert_eq!(out.mode, expected, "sample {k}");
            events.extend(out.events.iter().map(|e| (k, e.kind)));
        }
        // The jump on the sixth stuck reading, reported once; the stuck check twelve later.
        assert_eq!(
            events.iter().filter(|(_, e)| *e != EventKind::SensorSpikes).copied().collect::<Vec<_>>(),
            [(35, EventKind::SensorOffset), (47, EventKind::SensorStuck)]
        );
    }

    #[test]
    fn a_re_seated_probe_is_distrusted_for_the_stuck_window_then_controlled() {
        // A probe moved into a warm load reads 12 °C from one sample to the next. Nothing
        // cools for `stuck_s` after the jump; then the reading, alive, is the load.
        let mut c = guarded_at_0_64();
        let mut first_recovered = None;
        for k in 30..60 {
            let out = at(&mut c, k, counts_at(12.0) + (k % 3) as u32);
            let kinds: Vec<EventKind> = out.events.iter().map(|e| e.kind).collect();
            if k == 35 {
                assert!(kinds.contains(&EventKind::SensorOffset), "{kinds:?}");
            }
            if kinds.contains(&EventKind::SensorRecovered) {
                first_recovered.get_or_insert(k);
            }
            if k < 53 {
                assert_eq!((out.duty, out.supply_enable), (Duty::OFF, false), "sample {k}");
                assert_ne!(out.mode, Mode::Normal, "sample {k}");
            } else {
                assert_eq!(out.mode, Mode::Normal, "sample {k}");
                assert!(out.duty.get() > 0.5 && out.supply_enable, "sample {k}: {:?}", out.duty);
            }
        }
        // 180 s after the jump at sample 35.
        assert_eq!(first_recovered, Some(53));
    }

    /// Steps a fresh PI carrier through `readings` (°C, with a count of noise); for each
    /// sample the filtered temperature, the duty, the mode and the events.
    fn run_readings(readings: &[f32]) -> Vec<(f32, f32, Mode, Vec<EventKind>)> {
        let mut c = pi_carrier();
        let (mut k, mut v) = (0u64, Vec::new());
        for &t in readings {
            let counts = if t.is_nan() { 65_535 } else { counts_at(t) + (k % 2) as u32 };
            let out = at(&mut c, k, counts);
            v.push((out.temp_c.0, out.duty.get(), out.mode, out.events.iter().map(|e| e.kind).collect()));
            k += 1;
        }
        v
    }

    #[test]
    fn a_spike_on_the_first_reading_is_outvoted_by_the_two_after_it() {
        // After a boot, and after an open sensor's end (a loose contact: opens and spikes),
        // the first reading is a spike 46 °C high over a load at 4 °C. It used to be the
        // filter's value and every good reading after it a spike, until the sixth made a jump:
        // 60 s of full cooling on a load read at 50 °C, the freeze guard blind, then 3 min of
        // a sensor fault.
        let mut boot = vec![50.0];
        boot.extend([4.0; 12]);
        let mut recovery = vec![4.0, 4.0, f32::NAN, 50.0];
        recovery.extend([4.0; 12]);
        for (name, readings, first) in [("boot", boot, 0), ("recovery", recovery, 3)] {
            let out = run_readings(&readings);
            for (k, (temp, duty, mode, events)) in out.iter().enumerate().skip(first + 2) {
                assert!((temp - 4.0).abs() < 0.05, "{name} {k}: the filter reads {temp}");
                assert_eq!(*mode, Mode::Normal, "{name} {k}");
                assert!(*duty < 1.0, "{name} {k}: duty {duty}");
                assert!(!events.contains(&EventKind::SensorOffset), "{name} {k}: {events:?}");
            }
        }
        // A spike on the second reading is still ignored: the filter never reads it.
        let mut second = vec![4.0, 50.0];
        second.extend([4.0; 10]);
        for (k, (temp, ..)) in run_readings(&second).iter().enumerate() {
            assert!((temp - 4.0).abs() < 0.05, "{k}: the filter reads {temp}");
        }
        // Readings above the first are not its outvote: they may be an offset that began on
        // the second reading, too warm, which the offset watch measures and subtracts (an
        // outvote would hold the load 2.5 °C colder, the freezing side).
        let mut offset = vec![4.0];
        offset.extend([6.5; 12]);
        let out = run_readings(&offset);
        assert!(out[3].3.contains(&EventKind::SensorOffset), "{:?}", out[3]);
        for (k, (temp, ..)) in out.iter().enumerate().skip(4) {
            assert!((temp - 4.0).abs() < 0.05, "{k}: the filter reads {temp}");
        }
        // Nor a cold load's first reading with a front end stuck high after it (mission 70549):
        // a jump, and the sensor fault that distrusts it, cooling off.
        let mut stuck_high = vec![0.6];
        stuck_high.extend([55.0; 12]);
        let out = run_readings(&stuck_high);
        assert!(out.iter().any(|o| o.3.contains(&EventKind::SensorOffset)), "{out:?}");
        assert!(out.iter().skip(1).all(|o| o.1 == 0.0), "no cooling on the stuck reading: {out:?}");
        // But a first reading below freezing is a spike the two readings above it outvote
        // (mission 65944: −18.6 °C on a brown-out's first reading, over a load at 4.0 °C; it
        // held cooling off for 4 min, a false offset, and the light carrier at 40 °C warmed to
        // 9.0 °C): the filter reads the load from the third reading on, as for a warm spike.
        let mut frozen = vec![-18.6];
        frozen.extend([4.0; 12]);
        for (k, (temp, _, mode, events)) in run_readings(&frozen).iter().enumerate().skip(2) {
            assert!((temp - 4.0).abs() < 0.05, "{k}: the filter reads {temp}");
            assert_ne!(*mode, Mode::SensorFault, "{k}");
            assert!(!events.contains(&EventKind::SensorOffset), "{k}: {events:?}");
        }
    }

    #[test]
    fn a_week_of_identical_counts_does_not_overflow() {
        let mut c = pi_carrier();
        for k in 0..70_000u32 {
            let out = c.step(&StepInput { t_ms: k as u64 * 10_000, counts: 49_900, setpoint_c: 4.0 });
            if k > 20 {
                assert_eq!(out.mode, Mode::SensorFault);
            }
        }
    }
}
