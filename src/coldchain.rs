//! Cold-chain monitoring: WHO PQS E006-style temperature-recorder alarms, shipping
//! indicator alarms, mean kinetic temperature, extremes, time out of range and an excursion log.
//!
//! Alarm rules (durations from sample times, integer milliseconds: exact for the whole mission,
//! where f32 seconds would step by 0.5 s at day 89 and move a trigger across a sample):
//! - *continuous*: a run starts at the first sample t0 that meets the condition; the alarm
//!   triggers at the first sample t with t − t0 ≥ duration while every sample since t0 met it;
//!   it triggers once per run (a new run after the condition cleared can trigger again);
//! - *cumulative*: each interval (t_i, t_{i+1}) whose start sample meets the condition adds
//!   t_{i+1} − t_i; the alarm triggers at the first sample at which the sum reaches the
//!   duration, once per record.
//!
//! | kind | condition | duration |
//! | --- | --- | --- |
//! | `heat_10h` | T > +8.0 °C | 10 h continuous |
//! | `freeze_60min` | T ≤ −0.5 °C | 60 min continuous |
//! | `ship_45c_1h` | T ≥ +45 °C | 1 h continuous |
//! | `ship_30c_10h` | T ≥ +30 °C | 10 h cumulative |
//!
//! Mean kinetic temperature (Haynes 1971; USP <1079.2>), time-weighted over the intervals:
//!
//! ```text
//! T_mk = (ΔH/R) / −ln( Σ Δt_i · exp(−ΔH/(R·T_i)) / Σ Δt_i ),   ΔH = 83.144 kJ/mol, R = 8.314 J/(mol·K)
//! ```
//!
//! evaluated as an offset from a 5 °C reference so the exponentials stay near 1 in f32, with a
//! compensated running mean (no growing sum to lose precision over a 30-day record, and no
//! step dropped for being below half an ulp of the mean late in it).
//!
//! The per-sample exponential is libm's correctly rounded `expf`. micromath's fast `exp` was
//! measured in its place and rejected: on the Cortex-M4F it costs more, not less (the
//! monitor's push 196 → 224 instructions median, `cargo xtask pil`: its series divides four
//! times, its range reduction branches), and it is 15 times less accurate (relative error up
//! to 2.5e-3, the MKT off by up to 0.017 °C at −0.2 °C).
//!
//! The excursion log is a ring that holds the excursion under way in its own slot, so closing
//! one only moves an index. A `heapless::HistoryBuf` of closed excursions beside an
//! `Option<Excursion>` was measured in its place: moving the closed excursion from the one into
//! the other is a copy within the monitor that LLVM makes a `memmove` call, and that call was
//! what linked `compiler_builtins`' 1.5 KB `memmove` into the firmware.

use crate::units::{max_f32, min_f32};

/// The vaccine band, °C: in range when 2 ≤ T ≤ 8 (the alarm indicator's out-of-range test,
/// commissioning's end of a run that leaves it).
pub const IN_RANGE_C: core::ops::RangeInclusive<f32> = 2.0..=8.0;

/// ΔH/R of the mean kinetic temperature, K (83 144 / 8.314).
pub const MKT_DH_OVER_R_K: f32 = 83_144.0 / 8.314;
const T_REF_K: f32 = 278.15;

/// Alarm kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AlarmKind {
    /// Above +8 °C for 10 h continuously.
    Heat10h,
    /// At or below −0.5 °C for 60 min continuously.
    Freeze60min,
    /// At or above +45 °C for 1 h continuously.
    Ship45c1h,
    /// At or above +30 °C for 10 h in total.
    Ship30c10h,
}

impl AlarmKind {
    /// The contract name (`heat_10h`, …).
    pub fn name(self) -> &'static str {
        match self {
            AlarmKind::Heat10h => "heat_10h",
            AlarmKind::Freeze60min => "freeze_60min",
            AlarmKind::Ship45c1h => "ship_45c_1h",
            AlarmKind::Ship30c10h => "ship_30c_10h",
        }
    }

    /// Every kind, in the order [`Raised`] reports them.
    pub const ALL: [AlarmKind; 4] =
        [AlarmKind::Heat10h, AlarmKind::Freeze60min, AlarmKind::Ship45c1h, AlarmKind::Ship30c10h];

    /// Whether a sample at `t_c`, °C, meets this kind's condition (`hter report` reads it to
    /// give each alarm's duration with the same thresholds the monitor uses).
    pub fn meets(self, t_c: f32) -> bool {
        match self {
            AlarmKind::Heat10h => t_c > 8.0,
            AlarmKind::Freeze60min => t_c <= -0.5,
            AlarmKind::Ship45c1h => t_c >= 45.0,
            AlarmKind::Ship30c10h => t_c >= 30.0,
        }
    }

    fn duration_ms(self) -> u64 {
        match self {
            AlarmKind::Heat10h => 10 * 3_600_000,
            AlarmKind::Freeze60min => 3_600_000,
            AlarmKind::Ship45c1h => 3_600_000,
            AlarmKind::Ship30c10h => 10 * 3_600_000,
        }
    }

    /// Whether the duration is a total over the record (`ship_30c_10h`) rather than one run.
    pub fn cumulative(self) -> bool {
        matches!(self, AlarmKind::Ship30c10h)
    }
}

/// A raised alarm.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Alarm {
    /// Kind.
    pub kind: AlarmKind,
    /// Start of the run (continuous) or first qualifying sample (cumulative), ms.
    pub start_ms: u64,
    /// Sample at which it triggered, ms.
    pub trigger_ms: u64,
    /// A continuous run carried in from before this boot ([`ColdChainMonitor::resumed`]): its
    /// time before `start_ms`, whole seconds of recorded time (0 for a run of this boot alone,
    /// and for the cumulative kind, whose `start_ms` is this boot's first qualifying sample).
    pub carried_s: u32,
}

impl Alarm {
    /// Start, s, for display.
    pub fn start_s(&self) -> f64 {
        crate::units::secs_f64(self.start_ms)
    }

    /// Trigger, s, for display.
    pub fn trigger_s(&self) -> f64 {
        crate::units::secs_f64(self.trigger_ms)
    }
}

/// Which side of 2…8 °C an excursion is on. The discriminants are the history record's codes
/// ([`crate::persist::HistoryRecord`]), and leave 0 for `None` in an `Option<Excursion>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Side {
    /// Below +2 °C.
    Cold = 1,
    /// Above +8 °C.
    Warm = 2,
}

/// One excursion outside 2…8 °C. Its times are f32 seconds, the form the history record
/// stores them in ([`crate::persist::HistoryRecord`]), rounded from the millisecond clock (0.5 s
/// steps at day 89, far below the sample period; no alarm rule reads them).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Excursion {
    /// Which side.
    pub side: Side,
    /// First sample outside, s.
    pub start_s: f32,
    /// Last sample outside so far, s.
    pub end_s: f32,
    /// Coldest or warmest temperature reached, °C.
    pub extreme_c: f32,
}

/// Closed excursions kept (the newest; older ones are overwritten and counted), besides the one
/// under way.
pub const EXCURSION_LOG: usize = 16;

#[derive(Clone, Copy, Debug, Default)]
struct Tracker {
    start: Option<u64>,
    /// The cumulative kind's sum; a continuous kind's time carried in from before this boot
    /// ([`ColdChainMonitor::resumed`]), which its run adds to.
    acc_ms: u64,
    fired: bool,
}

/// Each kind's run, in [`AlarmKind::ALL`] order, as one boot hands it to the next through the
/// stored history ([`crate::persist::HistoryRecord::runs`]): 0 when none is under way;
/// otherwise bits 0–30 its time toward the alarm's duration in ms plus one (at most
/// [`RUN_MAX_MS`]: every duration is far shorter) and bit 31 set when it has raised its alarm.
/// A continuous kind's run is the one under way at the last sample, the cumulative kind's the
/// sum over the record.
pub type Runs = [u32; 4];

/// The longest time a [`Runs`] entry keeps, ms (24.8 days).
pub const RUN_MAX_MS: u64 = 0x7FFF_FFFE;

/// A [`Runs`] entry's raised flag.
const RUN_FIRED: u32 = 1 << 31;

/// The number of alarm kinds, hidden from the optimiser: [`ColdChainMonitor::runs`]'s loop stays
/// a loop (the library's opt-level unrolled it fourfold: 418 B of flash against 232 B).
fn kinds() -> usize {
    core::hint::black_box(AlarmKind::ALL.len())
}

/// The monitor's state and results.
#[derive(Clone, Debug)]
pub struct ColdChainMonitor {
    trackers: [Tracker; 4],
    last: Option<(u64, f32)>,
    elapsed_ms: u64,
    mkt_mean: f32,
    /// The rounding error of `mkt_mean`'s last step, taken off the next one.
    mkt_lost: f32,
    min_c: f32,
    max_c: f32,
    below_2_ms: u64,
    above_8_ms: u64,
    /// The excursion log, a ring: the slot at `head` holds the excursion under way (`None`
    /// between excursions), the [`EXCURSION_LOG`] slots after it (wrapping) the closed ones,
    /// oldest first (`None` until that many have closed).
    log: [Option<Excursion>; EXCURSION_LOG + 1],
    /// The open excursion's slot in `log`, always less than its length.
    head: usize,
    excursions: u32,
    /// The time without a reading so far, ms: the clock given less it is the record's.
    gap_ms: u64,
    /// The first sample of the gap under way if the last sample had no reading, else u64::MAX.
    gap_from: u64,
}

impl Default for ColdChainMonitor {
    fn default() -> Self {
        Self::new()
    }
}

/// Alarms raised by one sample (at most one per kind).
pub type Raised = [Option<Alarm>; 4];

impl ColdChainMonitor {
    /// An empty record.
    pub const fn new() -> Self {
        Self {
            trackers: [Tracker { start: None, acc_ms: 0, fired: false }; 4],
            last: None,
            elapsed_ms: 0,
            mkt_mean: 0.0,
            mkt_lost: 0.0,
            min_c: f32::INFINITY,
            max_c: f32::NEG_INFINITY,
            below_2_ms: 0,
            above_8_ms: 0,
            log: [None; EXCURSION_LOG + 1],
            head: 0,
            excursions: 0,
            gap_ms: 0,
            gap_from: u64::MAX,
        }
    }

    /// Adds a sample at `t_ms`, ms. Times must increase; a sample that is not later than the
    /// previous one is ignored (returns no alarm) so a glitch cannot corrupt the record. A
    /// sample that is not finite has no reading (a sensor fault): the time from the first such
    /// sample to the next reading is cut out of the record (its clock stops), as `hter
    /// monitor` cuts it from a log, so it counts neither in nor out of range and adds nothing to
    /// the mean kinetic temperature or to an alarm's run, which goes on across it.
    pub fn push(&mut self, t_ms: u64, temp_c: f32) -> Raised {
        let mut raised: Raised = [None; 4];
        let Some(t_ms) = self.record_ms(t_ms, temp_c) else { return raised };
        if let Some((t_prev, c_prev)) = self.last {
            if t_ms <= t_prev {
                return raised;
            }
            // The interval (t_prev, t_ms) belongs to the previous sample. The sums cannot
            // overflow: each is at most the last time minus the first.
            let dt = t_ms - t_prev;
            self.elapsed_ms += dt;
            let x = libm::expf(-MKT_DH_OVER_R_K * (1.0 / (c_prev + 273.15) - 1.0 / T_REF_K));
            // The weight in seconds, as f32: the ratio is all that matters, and whole seconds
            // stay exact this way.
            let (dt_s, elapsed_s) = (crate::units::secs_f32(dt), crate::units::secs_f32(self.elapsed_ms));
            // Compensated (Kahan): late in a long record the step is below half an ulp of the
            // mean, and a plain f32 sum dropped it (90 days at 10 s: MKT off by 0.05 °C).
            let step = (x - self.mkt_mean) * dt_s / elapsed_s - self.mkt_lost;
            let sum = self.mkt_mean + step;
            self.mkt_lost = (sum - self.mkt_mean) - step;
            self.mkt_mean = sum;
            if c_prev < 2.0 {
                self.below_2_ms += dt;
            }
            if c_prev > 8.0 {
                self.above_8_ms += dt;
            }
            for (tr, kind) in self.trackers.iter_mut().zip(AlarmKind::ALL) {
                if kind.cumulative() && kind.meets(c_prev) {
                    tr.acc_ms += dt;
                }
            }
        }
        self.last = Some((t_ms, temp_c));
        self.min_c = min_f32(self.min_c, temp_c);
        self.max_c = max_f32(self.max_c, temp_c);

        for (i, (tr, kind)) in self.trackers.iter_mut().zip(AlarmKind::ALL).enumerate() {
            let meets = kind.meets(temp_c);
            if kind.cumulative() {
                if meets && tr.start.is_none() {
                    tr.start = Some(t_ms);
                }
                if !tr.fired && tr.acc_ms >= kind.duration_ms() {
                    tr.fired = true;
                    let start_ms = tr.start.unwrap_or(t_ms);
                    raised[i] = Some(Alarm { kind, start_ms, trigger_ms: t_ms, carried_s: 0 });
                }
            } else if meets {
                let t0 = *tr.start.get_or_insert(t_ms);
                // t0 ≤ t_ms: times only increase past the guard above. `acc_ms`: the part of the
                // run before this boot.
                if !tr.fired && t_ms - t0 + tr.acc_ms >= kind.duration_ms() {
                    tr.fired = true;
                    let carried_s = (tr.acc_ms / 1000) as u32;
                    raised[i] = Some(Alarm { kind, start_ms: t0, trigger_ms: t_ms, carried_s });
                }
            } else {
                *tr = Tracker::default();
            }
        }
        self.log_excursion(t_ms, temp_c);
        raised
    }

    /// `t_ms` on the record's clock, which does not run while there is no reading: `None` for a
    /// sample without one (`temp_c` not finite), whose gap begins at the first such sample and
    /// ends at the next reading.
    fn record_ms(&mut self, t_ms: u64, temp_c: f32) -> Option<u64> {
        if !temp_c.is_finite() {
            self.gap_from = self.gap_from.min(t_ms);
            return None;
        }
        // `gap_from` is u64::MAX outside a gap.
        self.gap_ms += t_ms.saturating_sub(self.gap_from);
        self.gap_from = u64::MAX;
        Some(t_ms.saturating_sub(self.gap_ms))
    }

    /// Continues the runs a previous boot handed over ([`Self::runs`] of its last sample, from
    /// the stored history), before the first sample. A continuous kind's run goes on if the
    /// first sample meets its condition and ends otherwise; the time the board was off is not
    /// on the record's clock, as in `hter monitor`, which reads the record as one clock across
    /// restarts. The cumulative kind's sum goes on. A run that has raised its alarm does not
    /// raise it again. Out of line: it runs once a boot.
    ///
    /// `open` is the excursion under way at the previous boot's last stored sample
    /// ([`crate::persist::HistoryRecord::open_excursion`]), on the record's clock, whose time
    /// was `base_s` at that store: it is the log's excursion under way, not counted again. A
    /// first reading on its side extends it, as `hter monitor` reads one excursion across a
    /// restart in a log; one in range or on the other side ends it.
    #[inline(never)]
    pub fn resumed(runs: &Runs, open: Option<Excursion>, base_s: f32) -> Self {
        let mut m = Self::new();
        m.resume(runs);
        // The log's slot at `head` (0) holds the excursion under way; its times on this boot's
        // clock, where the history's merge adds `base_s` back, and not after this boot's start:
        // the board times excursions from its reset and `base_s` counts whole seconds from
        // the first sample, so a stored excursion can lie up to that sample's time and a second
        // after `base_s`, and a first reading before that on its side made an end before the
        // start, a record the next boot rejects whole (found in review: 10.703 s against 10.7).
        m.log[0] = open.map(|e| Excursion {
            start_s: min_f32(e.start_s - base_s, 0.0),
            end_s: min_f32(e.end_s - base_s, 0.0),
            ..e
        });
        m
    }

    /// [`Self::resumed`]'s continuation, on a monitor with no sample yet.
    fn resume(&mut self, runs: &Runs) {
        for (tr, &r) in self.trackers.iter_mut().zip(runs) {
            if r != 0 {
                tr.acc_ms = u64::from((r & !RUN_FIRED).saturating_sub(1));
                tr.fired = r & RUN_FIRED != 0;
            }
        }
    }

    /// Each kind's run at the last sample, for the next boot ([`Self::resumed`]); before this
    /// boot's first sample, the runs it was resumed with. Out of line: the history's merge and
    /// the recorder's check of ended runs both call it.
    #[inline(never)]
    pub fn runs(&self) -> Runs {
        let last_ms = self.last.map_or(0, |(t, _)| t);
        let mut runs = [0; 4];
        for i in 0..kinds() {
            if let (Some(r), Some(tr), Some(kind)) = (runs.get_mut(i), self.trackers.get(i), AlarmKind::ALL.get(i)) {
                let open = match tr.start {
                    Some(t0) if !kind.cumulative() => last_ms - t0,
                    _ => 0,
                };
                let ms = tr.acc_ms + open;
                if tr.fired || tr.start.is_some() || ms > 0 {
                    *r = (ms.min(RUN_MAX_MS) as u32 + 1) | if tr.fired { RUN_FIRED } else { 0 };
                }
            }
        }
        runs
    }

    fn log_excursion(&mut self, t_ms: u64, temp_c: f32) {
        let side = if temp_c < 2.0 {
            Some(Side::Cold)
        } else if temp_c > 8.0 {
            Some(Side::Warm)
        } else {
            None
        };
        match (side, self.log.get_mut(self.head)) {
            (Some(s), Some(Some(e))) if e.side == s => {
                e.end_s = crate::units::secs_f32(t_ms);
                e.extreme_c = if s == Side::Cold { min_f32(e.extreme_c, temp_c) } else { max_f32(e.extreme_c, temp_c) };
                return;
            }
            (_, Some(Some(_))) => {
                // Closed where it lies: the next slot, the oldest closed one, makes room.
                self.head = if self.head + 1 < self.log.len() { self.head + 1 } else { 0 };
                if let Some(next) = self.log.get_mut(self.head) {
                    *next = None;
                }
            }
            _ => {}
        }
        if let (Some(s), Some(slot)) = (side, self.log.get_mut(self.head)) {
            let t_s = crate::units::secs_f32(t_ms);
            *slot = Some(Excursion { side: s, start_s: t_s, end_s: t_s, extreme_c: temp_c });
            self.excursions = self.excursions.saturating_add(1);
        }
    }

    /// Mean kinetic temperature so far, °C (`None` before two samples).
    pub fn mkt_c(&self) -> Option<f32> {
        (self.elapsed_ms > 0 && self.mkt_mean > 0.0)
            .then(|| 1.0 / (1.0 / T_REF_K - libm::logf(self.mkt_mean) / MKT_DH_OVER_R_K) - 273.15)
    }

    /// Lowest temperature, °C.
    pub fn min_c(&self) -> Option<f32> {
        self.last.map(|_| self.min_c)
    }

    /// Highest temperature, °C.
    pub fn max_c(&self) -> Option<f32> {
        self.last.map(|_| self.max_c)
    }

    /// Time covered by the record (first to last sample), ms: the excursions' clock.
    pub fn recorded_ms(&self) -> u64 {
        self.elapsed_ms
    }

    /// Time below +2 °C, ms.
    pub fn time_below_2_ms(&self) -> u64 {
        self.below_2_ms
    }

    /// Time above +8 °C, ms.
    pub fn time_above_8_ms(&self) -> u64 {
        self.above_8_ms
    }

    /// [`Self::recorded_ms`] as f32 seconds (the history record's form). This and the next two
    /// are out of line: read by the hourly merge and summary only, inlined each carried its own
    /// copy of the conversion (−64 B of firmware flash); the per-sample `push` keeps its own.
    #[inline(never)]
    pub fn recorded_s(&self) -> f32 {
        crate::units::secs_f32(self.elapsed_ms)
    }

    /// [`Self::time_below_2_ms`] as f32 seconds.
    #[inline(never)]
    pub fn time_below_2_s(&self) -> f32 {
        crate::units::secs_f32(self.below_2_ms)
    }

    /// [`Self::time_above_8_ms`] as f32 seconds.
    #[inline(never)]
    pub fn time_above_8_s(&self) -> f32 {
        crate::units::secs_f32(self.above_8_ms)
    }

    /// The newest closed excursions and the one under way, oldest first.
    pub fn excursions(&self) -> impl Iterator<Item = &Excursion> {
        // `head` is always less than the log's length: the bound is for the optimiser, which
        // otherwise kept a panic path for the split in the history's merge, and with it this
        // file's name (−44 B of flash).
        let (to_open, closed) = self.log.split_at(self.head.min(EXCURSION_LOG) + 1);
        closed.iter().chain(to_open).flatten()
    }

    /// Excursions since start (including those overwritten in the log).
    pub fn excursion_count(&self) -> u32 {
        self.excursions
    }

    /// Whether the last sample was outside 2…8 °C: an excursion is under way.
    pub fn in_excursion(&self) -> bool {
        matches!(self.log.get(self.head), Some(Some(_)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(m: &mut ColdChainMonitor, samples: impl IntoIterator<Item = (u64, f32)>) -> std::vec::Vec<Alarm> {
        samples.into_iter().flat_map(|(t, c)| m.push(t, c)).flatten().collect()
    }

    /// One sample either side of every continuous threshold: with 60 s samples the run that
    /// lasts exactly `duration` triggers at that sample, one that is broken one sample
    /// before does not.
    #[test]
    fn continuous_alarms_trigger_exactly_at_the_duration() {
        for (kind, hot, cold, dur) in [
            (AlarmKind::Heat10h, 8.01f32, 8.0f32, 36_000u32),
            (AlarmKind::Freeze60min, -0.5, -0.49, 3_600),
            (AlarmKind::Ship45c1h, 45.0, 44.99, 3_600),
        ] {
            let step = 60u32;
            // Run from t0 = 600 s, exactly `dur` long: triggers at 600 + dur.
            let mut m = ColdChainMonitor::new();
            let s = (0..=(600 + dur) / step).map(|i| {
                let t = i * step;
                (u64::from(t) * 1000, if t >= 600 { hot } else { 5.0 })
            });
            let a = feed(&mut m, s);
            assert_eq!(a.len(), 1, "{kind:?}: {a:?}");
            assert_eq!((a[0].kind, a[0].start_ms, a[0].trigger_ms), (kind, 600_000, u64::from(600 + dur) * 1000));
            // One sample short: no alarm.
            let mut m = ColdChainMonitor::new();
            let s = (0..(600 + dur) / step).map(|i| {
                let t = i * step;
                (u64::from(t) * 1000, if t >= 600 { hot } else { 5.0 })
            });
            assert!(feed(&mut m, s).is_empty(), "{kind:?} fired early");
            // Interrupted by one sample just on the safe side of the threshold: no alarm.
            let mut m = ColdChainMonitor::new();
            let s = (0..=(600 + dur) / step).map(|i| {
                let t = i * step;
                (
                    u64::from(t) * 1000,
                    if t == 1200 {
                        cold
                    } else if t >= 600 {
                        hot
                    } else {
                        5.0
                    },
                )
            });
            assert!(feed(&mut m, s).is_empty(), "{kind:?} fired across a break");
        }
    }

    /// Day 89 on the board's clock, ms.
    const DAY_89_MS: u64 = 89 * 86_400_000;

    /// What a clock in f32 seconds would have read: even correctly rounded, f32 steps by 0.5 s
    /// between 48.5 and 97 days.
    fn f32_s(t_ms: u64) -> f32 {
        (t_ms as f64 / 1000.0) as f32
    }

    /// Samples every 10 s from day 89, 249 ms past the second (an f32 clock reads 0.249 s
    /// early there), with `temp(k)`; sample `short_k` comes `short_ms` early, as a busy
    /// executor's timestamp can.
    fn day_89(n: usize, temp: impl Fn(usize) -> f32, short_k: usize, short_ms: u64) -> std::vec::Vec<(u64, f32)> {
        (0..n)
            .map(|k| {
                let t = DAY_89_MS + 249 + 10_000 * k as u64;
                (if k == short_k { t - short_ms } else { t }, temp(k))
            })
            .collect()
    }

    /// A continuous alarm at day 89 triggers at the first sample whose distance from the run's
    /// start reaches the duration, to the millisecond: the sample exactly 10 h (60 min) after
    /// the start, and the next one if that sample is 1 ms short. f32 seconds could not tell
    /// the two apart and fire one sample early in the second case.
    #[test]
    fn continuous_alarms_at_day_89_are_exact_to_the_sample() {
        for (kind, hot, dur) in [(AlarmKind::Heat10h, 9.0f32, 3600usize), (AlarmKind::Freeze60min, -1.0, 360)] {
            let k0 = 30;
            let end = k0 + dur;
            for short_ms in [0u64, 1] {
                let s = day_89(end + 5, |k| if k >= k0 { hot } else { 5.0 }, end, short_ms);
                let mut m = ColdChainMonitor::new();
                let a: std::vec::Vec<Alarm> =
                    feed(&mut m, s.iter().copied()).into_iter().filter(|a| a.kind == kind).collect();
                let want = if short_ms == 0 { end } else { end + 1 };
                assert_eq!(a.len(), 1, "{kind:?}: {a:?}");
                assert_eq!((a[0].start_ms, a[0].trigger_ms), (s[k0].0, s[want].0), "{kind:?}, {short_ms} ms short");
                // The same rule on f32 seconds.
                let dur_s = kind.duration_ms() as f32 / 1000.0;
                let f32_at = (k0..s.len()).find(|&k| f32_s(s[k].0) - f32_s(s[k0].0) >= dur_s);
                assert_eq!(f32_at, Some(end), "{kind:?}: f32 seconds fire at the nominal sample");
                if short_ms > 0 {
                    assert_ne!(f32_at, Some(want), "{kind:?}: f32 seconds would have been exact too");
                }
            }
        }
    }

    /// `ship_30c_10h` at day 89, across a cool spell and a 30 min gap in the samples (the board
    /// was off while hot; the gap belongs to the hot sample before it): 4 h hot, 2 h at 20 °C,
    /// 40 hot samples, the gap, then hot again. It triggers at the sample where the sum reaches
    /// 10 h; with the gap 1 ms short, one sample later. f32 seconds round the gap's
    /// millisecond away and fire a sample early.
    #[test]
    fn cumulative_alarm_at_day_89_is_exact_to_the_sample_across_a_gap() {
        for short_ms in [0u64, 1] {
            let mut s = std::vec::Vec::new();
            let mut t = DAY_89_MS + 249;
            for (n, c) in [(1440, 31.0f32), (720, 20.0), (40, 31.0)] {
                for _ in 0..n {
                    s.push((t, c));
                    t += 10_000;
                }
            }
            // The last hot sample's interval is the gap: 30 min (minus `short_ms`).
            t += 1_800_000 - 10_000 - short_ms;
            let after_gap = s.len();
            for _ in 0..1950 {
                s.push((t, 31.0));
                t += 10_000;
            }
            // 1440 + 39 intervals of 10 s and the 30 min gap make 4 h 36 min 30 s; 1941 more
            // intervals make 10 h.
            let want = after_gap + 1941 + short_ms as usize;
            let mut m = ColdChainMonitor::new();
            let a: std::vec::Vec<Alarm> =
                feed(&mut m, s.iter().copied()).into_iter().filter(|a| a.kind == AlarmKind::Ship30c10h).collect();
            assert_eq!(a.len(), 1, "{a:?}");
            assert_eq!((a[0].start_ms, a[0].trigger_ms), (s[0].0, s[want].0), "gap {short_ms} ms short");
            // The same rule on f32 seconds.
            let mut acc = 0.0f32;
            let mut f32_at = None;
            for k in 1..s.len() {
                if s[k - 1].1 >= 30.0 {
                    acc += f32_s(s[k].0) - f32_s(s[k - 1].0);
                }
                if acc >= 36_000.0 {
                    f32_at = Some(k);
                    break;
                }
            }
            assert_eq!(f32_at, Some(after_gap + 1941), "f32 seconds fire at the nominal sample");
            if short_ms > 0 {
                assert_ne!(f32_at, Some(want), "f32 seconds would have been exact too");
            }
        }
    }

    #[test]
    fn cumulative_alarm_counts_intervals_by_their_start_sample() {
        // Alternate an hour at 31 °C with an hour at 20 °C, sampled every 600 s.
        let mut m = ColdChainMonitor::new();
        let mut alarms = std::vec::Vec::new();
        let mut t = 0u32;
        while t <= 20 * 3600 {
            let hot = (t / 3600).is_multiple_of(2);
            alarms.extend(m.push(u64::from(t) * 1000, if hot { 31.0 } else { 20.0 }).into_iter().flatten());
            t += 600;
        }
        // The 10th hot hour ends at 19 h: (0–1 h, 2–3 h, …, 18–19 h) — trigger at 19 h = 68 400 s.
        let a: std::vec::Vec<_> = alarms.iter().filter(|a| a.kind == AlarmKind::Ship30c10h).collect();
        assert_eq!(a.len(), 1);
        assert_eq!((a[0].start_ms, a[0].trigger_ms), (0, 68_400_000));
        // One sample earlier the sum is 9 h 50 min.
        let mut m = ColdChainMonitor::new();
        let mut n = 0;
        let mut t = 0u32;
        while t < 68_400 {
            let hot = (t / 3600).is_multiple_of(2);
            n += m
                .push(u64::from(t) * 1000, if hot { 31.0 } else { 20.0 })
                .iter()
                .flatten()
                .filter(|a| a.kind == AlarmKind::Ship30c10h)
                .count();
            t += 600;
        }
        assert_eq!(n, 0);
    }

    #[test]
    fn mkt_of_a_constant_is_that_constant_and_weights_heat() {
        let mut m = ColdChainMonitor::new();
        for i in 0..100 {
            m.push(i * 10_000, 5.0);
        }
        assert!((m.mkt_c().unwrap() - 5.0).abs() < 1e-3);
        // Half the time at 2 °C, half at 8 °C: MKT is above the 5 °C arithmetic mean.
        // Reference (f64): Tk = 10000/−ln((e^{−10000/275.15} + e^{−10000/281.15})/2) − 273.15 = 5.1277 °C.
        let mut m = ColdChainMonitor::new();
        for i in 0..=1000 {
            m.push(i * 10_000, if i % 2 == 0 { 2.0 } else { 8.0 });
        }
        let mkt = m.mkt_c().unwrap();
        let want = {
            let k = 83_144.0f64 / 8.314;
            let s = ((-k / 275.15).exp() + (-k / 281.15).exp()) / 2.0;
            k / -s.ln() - 273.15
        };
        assert!((f64::from(mkt) - want).abs() < 2e-3, "{mkt} vs {want}");
        assert!(mkt > 5.0);
    }

    /// The f32 record against an f64 MKT of the same samples, over the whole plausible range
    /// and over a day within 2…8 °C.
    #[test]
    fn mkt_matches_f64_within_the_documented_accuracy() {
        let mkt_f64 = |temps: &[f64]| {
            let k = 83_144.0f64 / 8.314;
            let n = (temps.len() - 1) as f64;
            // Each interval belongs to its start sample.
            let s: f64 = temps[..temps.len() - 1].iter().map(|c| (-k / (c + 273.15)).exp()).sum::<f64>() / n;
            k / -s.ln() - 273.15
        };
        let check = |temps: &[f64], tol: f64| {
            let mut m = ColdChainMonitor::new();
            for (i, c) in temps.iter().enumerate() {
                m.push(i as u64 * 10_000, *c as f32);
            }
            let got = f64::from(m.mkt_c().unwrap());
            let want = mkt_f64(temps);
            assert!((got - want).abs() <= tol, "MKT {got} vs f64 {want} (tolerance {tol})");
        };
        for c10 in 20..=80 {
            check(&[f64::from(c10) / 10.0; 50], 0.001);
        }
        for c10 in -300..=750 {
            check(&[f64::from(c10) / 10.0; 50], 0.002);
        }
        // A day within 2…8 °C: a slow sine with noise-like detail.
        let day: std::vec::Vec<f64> =
            (0..8640).map(|i| 5.0 + 2.9 * (f64::from(i) / 1375.0).sin() + 0.1 * (f64::from(i) * 1.7).sin()).collect();
        check(&day, 0.001);
    }

    /// A long record at the 10 s sample period: late in it, one interval's weight is ~4e-6 (30
    /// days) to ~1.3e-6 (90 days) of the whole, and an f32 running mean dropped each sample's
    /// small step whole (it is below half an ulp of the mean) or rounded it by tens of percent.
    /// References (Python, f64; equal time at each temperature, K = 83 144 / 8.314):
    /// `K / -ln((exp(-K/(a+273.15)) + exp(-K/(b+273.15))) / 2) - 273.15`
    /// - 15 days at 8.1 °C then 15 days at 7.9 °C: 8.0006 °C (outside 2–8 °C); the f32 running
    ///   mean gave 7.9959 (within);
    /// - 45 days at 7.95 °C then 45 days at 8.05 °C: 8.00015 °C; it gave 7.9500, the second
    ///   half of the record ignored;
    /// - 45 days at 1.8 °C then 45 days at 2.2 °C: 2.0025 °C (within); it gave 1.9836.
    #[test]
    fn mkt_of_a_long_record_keeps_every_samples_weight() {
        for (days, a, b, want) in
            [(30u64, 8.1f32, 7.9f32, 8.000597f64), (90, 7.95, 8.05, 8.000149), (90, 1.8, 2.2, 2.002496)]
        {
            let n = days * 8_640;
            let mut m = ColdChainMonitor::new();
            for i in 0..=n {
                m.push(i * 10_000, if i < n / 2 { a } else { b });
            }
            let got = f64::from(m.mkt_c().unwrap());
            assert!((got - want).abs() < 1e-3, "{days} days, {a} then {b} °C: MKT {got}, want {want}");
        }
    }

    #[test]
    fn the_log_keeps_the_newest_excursions_and_counts_all() {
        let mut m = ColdChainMonitor::new();
        // 20 warm excursions of 2 samples each, the last one still under way.
        let mut t = 0u64;
        for i in 0..20 {
            for c in [5.0, 9.0 + i as f32, 9.0] {
                m.push(t, c);
                t += 10_000;
            }
        }
        assert_eq!(m.excursion_count(), 20);
        let ex: std::vec::Vec<_> = m.excursions().copied().collect();
        assert_eq!(ex.len(), EXCURSION_LOG + 1);
        // Oldest first: excursions 3 … 19, the last one open.
        let extremes: std::vec::Vec<f32> = ex.iter().map(|e| e.extreme_c).collect();
        let want: std::vec::Vec<f32> = (3..20).map(|i| 9.0 + i as f32).collect();
        assert_eq!(extremes, want);
        assert_eq!(ex.last().map(|e| e.end_s), Some(((t - 10_000) / 1000) as f32));
        // Closing it overwrites the oldest: excursions 4 … 19, none open.
        m.push(t, 5.0);
        let extremes: std::vec::Vec<f32> = m.excursions().map(|e| e.extreme_c).collect();
        let want: std::vec::Vec<f32> = (4..20).map(|i| 9.0 + i as f32).collect();
        assert_eq!(extremes, want);
        assert_eq!(m.excursion_count(), 20);
    }

    #[test]
    fn extremes_time_out_of_range_and_excursions() {
        let mut m = ColdChainMonitor::new();
        let temps = [5.0, 1.5, 1.0, 5.0, 9.0, 10.0, 9.5, 5.0];
        for (i, c) in temps.iter().enumerate() {
            m.push(i as u64 * 10_000, *c);
        }
        assert_eq!(m.min_c(), Some(1.0));
        assert_eq!(m.max_c(), Some(10.0));
        assert_eq!(m.time_below_2_ms(), 20_000);
        assert_eq!(m.time_above_8_ms(), 30_000);
        let ex: std::vec::Vec<_> = m.excursions().copied().collect();
        assert_eq!(ex.len(), 2);
        assert_eq!((ex[0].side, ex[0].start_s, ex[0].end_s, ex[0].extreme_c), (Side::Cold, 10.0, 20.0, 1.0));
        assert_eq!((ex[1].side, ex[1].extreme_c), (Side::Warm, 10.0));
        // Glitches are ignored.
        m.push(80_000, f32::NAN);
        m.push(5_000, 5.0);
        m.push(70_000, 12.0);
        assert_eq!(m.max_c(), Some(10.0));
    }

    /// A monitor resumed with the stored history's excursion under way holds it in its log,
    /// uncounted, and reads as in an excursion before its first reading; a first reading on its
    /// side extends it (a sample without a reading waits), one in range or on the other side
    /// ends it where it was. Its times are this boot's clock, the record's less `base_s`.
    #[test]
    fn a_resumed_monitor_goes_on_with_the_excursion_under_way() {
        let stored = Excursion { side: Side::Warm, start_s: 100.0, end_s: 300.0, extreme_c: 10.0 };
        let on_boot_clock = Excursion { start_s: -200.0, end_s: 0.0, ..stored };
        let m = ColdChainMonitor::resumed(&[0; 4], Some(stored), 300.0);
        assert!(m.in_excursion());
        assert_eq!(m.excursions().copied().collect::<std::vec::Vec<_>>(), [on_boot_clock]);
        assert_eq!(m.excursion_count(), 0);

        let mut on = m.clone();
        on.push(0, f32::NAN);
        on.push(10_000, 9.0);
        on.push(20_000, 12.0);
        let ex: std::vec::Vec<_> = on.excursions().copied().collect();
        assert_eq!(ex, [Excursion { end_s: 10.0, extreme_c: 12.0, ..on_boot_clock }], "one excursion, extended");
        assert_eq!(on.excursion_count(), 0);

        for (first, new) in [(5.0, None), (1.0, Some(Side::Cold))] {
            let mut off = m.clone();
            off.push(0, first);
            let ex: std::vec::Vec<_> = off.excursions().copied().collect();
            assert_eq!(ex[0], on_boot_clock, "{first}: ended where it was");
            assert_eq!(ex.get(1).map(|e| e.side), new, "{first}");
            assert_eq!(off.excursion_count(), u32::from(new.is_some()), "{first}");
            assert_eq!(off.in_excursion(), new.is_some(), "{first}");
        }
        // Nothing under way: an empty log, as a new monitor's.
        let none = ColdChainMonitor::resumed(&[0; 4], None, 300.0);
        assert!(!none.in_excursion() && none.excursions().next().is_none());
    }
}
