//! When the firmware may write flash, and what waits until then.
//!
//! A flash write cut by a power loss tears a word (see [`super::flash`]); the board recovers, but
//! each torn word costs the record being written, and a supply that bounces (a loose connector,
//! a vehicle cranking, a solar panel at dusk) reboots the board again and again. So the firmware
//! writes only on a supply that has been good, without a bad sample, for [`SUPPLY_HOLD_OFF_MS`]
//! and whose latest sample is fresh and good. An alarm record skips the hold-off (it must be on
//! record even if the board dies a minute later) but still needs the supply good now: a write
//! begun on a failing supply is the one most likely to be torn.
//!
//! Requests wait in [`PendingSaves`], one slot per record kind, the newest replacing the older
//! (every record is a whole state, not a delta: the newest history includes everything the
//! older one had), so a long closed gate costs no memory and a reopened one writes each kind
//! once. A power-bounce loop therefore writes nothing, and the resets of a loop whose boots
//! never stay up for the hold-off are not counted in the history.
//!
//! Cold-chain log entries (the builds with the log, feature `cold-chain-log`) wait for the gate
//! too, except in the hold-off after an alarm history went: the rows of what made it urgent go
//! with it ([`PendingSaves::next`]). They are not whole states: each waits, in order, up to [`PENDING_LOG`] of
//! them. Beyond that the oldest waiting entry is dropped (a pop at the queue's front: the
//! cheapest in flash), and the record says so. The first log entry written when the gate opens
//! is then one `log_entries_lost` event ([`EventKind::LogEntriesLost`](crate::event::EventKind::LogEntriesLost), [`LogEntry::Lost`])
//! stamped with the record time of the newest entry dropped and carrying how many were, before
//! the entries kept: the record stays in time order, and what it misses lies after the entry
//! before that event, up to the event's time. Forty settings accepted in the minute after a
//! boot, say, leave `log_entries_lost:25` at the 24th one's time, then the last sixteen (the
//! boot's `restarted` event was among the lost).

use super::log::LogEntry;
use super::{HistoryRecord, ModelRecord};
use crate::calib::TwoPoint;

/// How long the supply must have been good since boot (or since its last bad sample) before a
/// write, ms: 60 s, six samples at Ts = 10 s, several times the seconds a brown-out or a plug
/// bounce lasts, and short against the hourly history store.
pub const SUPPLY_HOLD_OFF_MS: u64 = 60_000;

/// Age of the latest supply sample beyond which the supply does not count as good now, ms: 25 s,
/// two and a half samples at Ts = 10 s (a control loop that stopped sampling must not write).
pub const SUPPLY_FRESH_MS: u64 = 25_000;

/// Whether a flash write may start now, from the supply samples seen since boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteGate {
    hold_off_ms: u64,
    fresh_ms: u64,
    /// Start of the current run of good samples.
    good_since_ms: Option<u64>,
    /// Time of the latest sample (good or bad).
    last_ms: Option<u64>,
}

impl WriteGate {
    /// Closed until a good supply has lasted `hold_off_ms`; a sample older than `fresh_ms` does
    /// not count as now.
    pub const fn new(hold_off_ms: u64, fresh_ms: u64) -> Self {
        WriteGate { hold_off_ms, fresh_ms, good_since_ms: None, last_ms: None }
    }

    /// The firmware's gate: [`SUPPLY_HOLD_OFF_MS`], [`SUPPLY_FRESH_MS`].
    pub const fn firmware() -> Self {
        Self::new(SUPPLY_HOLD_OFF_MS, SUPPLY_FRESH_MS)
    }

    /// One supply sample at `now_ms` (monotonic, since boot): `ok` if the supply is above the
    /// threshold flash writes need.
    pub fn note_supply(&mut self, now_ms: u64, ok: bool) {
        self.last_ms = Some(now_ms);
        if !ok {
            self.good_since_ms = None;
        } else if self.good_since_ms.is_none() {
            self.good_since_ms = Some(now_ms);
        }
    }

    /// Whether the supply is good now: the latest sample was good and is fresh.
    pub fn good_now(&self, now_ms: u64) -> bool {
        match (self.good_since_ms, self.last_ms) {
            (Some(_), Some(last)) => now_ms.saturating_sub(last) <= self.fresh_ms,
            _ => false,
        }
    }

    /// Whether a write may start at `now_ms`: the supply is good now and, unless an alarm record
    /// is due, has been for the hold-off.
    pub fn allows(&self, now_ms: u64, alarm_due: bool) -> bool {
        self.good_since(now_ms).is_some_and(|since| alarm_due || self.held(now_ms, since))
    }

    /// The start of the run of good samples, if the supply is good now.
    fn good_since(&self, now_ms: u64) -> Option<u64> {
        self.good_since_ms.filter(|_| self.good_now(now_ms))
    }

    /// Whether a supply good since `since` has been for the hold-off at `now_ms`.
    fn held(&self, now_ms: u64, since: u64) -> bool {
        now_ms.saturating_sub(since) >= self.hold_off_ms
    }
}

/// A record to store.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Save {
    /// The self-tuner's trusted model.
    Model(ModelRecord),
    /// The cold-chain history (hourly, or at boot).
    History(HistoryRecord),
    /// The cold-chain history with an alarm this boot raised that is not yet stored: it skips
    /// the hold-off.
    AlarmHistory(HistoryRecord),
    /// The calibration.
    Calibration(TwoPoint),
    /// The settings (an accepted change over the interface).
    Settings(super::SettingsRecord),
    /// The cabinet model (commissioned or uploaded): the holdover's, in a record of its own.
    /// Only builds with the holdover estimate keep it (the default firmware build has no room).
    #[cfg(feature = "holdover")]
    Cabinet(super::CabinetRecord),
    /// An entry of the cold-chain log: kept in order, up to [`PENDING_LOG`] waiting (beyond
    /// them a `log_entries_lost` event stands for the oldest, [`PendingSaves`]).
    Log(LogEntry),
}

/// Stores in a row that fail before the board calls its flash failed
/// ([`EventKind::StoreFailed`](crate::event::EventKind::StoreFailed)): three, so that one
/// failure the storage layer recovers from at the next write (noise in a region another
/// firmware left) is no alarm, and a region that refuses every write is one within three
/// stores (the history's hourly one, the 5-minute log rows of the interface build).
pub const STORE_FAILURES: u8 = 3;

/// Stores failed in a row in each flash region, the records' and the log's (the persist task's
/// side of [`StoreWatch`]): a store that succeeds ends its region's run. Counted apart: the log's
/// 5-minute rows would otherwise end every run of the records region's hourly failures.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoreFailures {
    in_a_row: [u8; 2],
}

impl StoreFailures {
    /// No store failed.
    pub const NEW: StoreFailures = StoreFailures { in_a_row: [0; 2] };

    /// One store of `save` and whether it succeeded.
    pub fn note(&mut self, save: &Save, ok: bool) {
        let n = &mut self.in_a_row[usize::from(matches!(save, Save::Log(_)))];
        *n = if ok { 0 } else { n.saturating_add(1) };
    }

    /// The longer run of the two regions (saturating): what [`StoreWatch::observe`] takes.
    pub fn in_a_row(&self) -> u8 {
        self.in_a_row[0].max(self.in_a_row[1])
    }
}

/// Whether the board's flash keeps failing, from the persist task's [`StoreFailures::in_a_row`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoreWatch {
    failing: bool,
}

impl StoreWatch {
    /// Flash working.
    pub const NEW: StoreWatch = StoreWatch { failing: false };

    /// The persist task's count of stores failed in a row: true when it reaches
    /// [`STORE_FAILURES`] (once per run of failures; a store that succeeds ends the run).
    pub fn observe(&mut self, failed_in_a_row: u8) -> bool {
        let failing = failed_in_a_row >= STORE_FAILURES;
        let new = failing && !self.failing;
        self.failing = failing;
        new
    }

    /// The last count observed had reached [`STORE_FAILURES`].
    pub fn failing(&self) -> bool {
        self.failing
    }
}

/// Log entries that may wait for the [`WriteGate`]: a little over an hour of intervals and
/// events at a typical rate; beyond it the oldest waiting entry is dropped, and the record gets
/// a `log_entries_lost` event in its place ([`EventKind::LogEntriesLost`](crate::event::EventKind::LogEntriesLost)).
pub const PENDING_LOG: usize = 16;

/// The newest record of each kind waiting for the [`WriteGate`], and the log entries (in order;
/// the newest [`PENDING_LOG`], after a `log_entries_lost` event when older ones were dropped).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PendingSaves {
    model: Option<ModelRecord>,
    calibration: Option<TwoPoint>,
    settings: Option<super::SettingsRecord>,
    #[cfg(feature = "holdover")]
    cabinet: Option<super::CabinetRecord>,
    history: Option<HistoryRecord>,
    /// The log entries (the builds with the cold-chain log).
    #[cfg(feature = "cold-chain-log")]
    rows: Rows,
    /// The waiting history holds an alarm not yet stored (stays set when a newer history
    /// replaces it: the newer one counts the alarm too).
    alarm: bool,
}

/// The log entries waiting in [`PendingSaves`], in order: the newest [`PENDING_LOG`], after a
/// `log_entries_lost` event when older ones were dropped.
#[cfg(feature = "cold-chain-log")]
#[derive(Clone, Debug, PartialEq, Default)]
struct Rows {
    entries: heapless::Deque<LogEntry, PENDING_LOG>,
    /// Record time of the newest log entry dropped (because [`PENDING_LOG`] were waiting) since
    /// the last `log_entries_lost` event went out, s, and how many were (saturating); `None`
    /// when none was.
    lost: Option<(u32, u16)>,
    /// When the last alarm history went, ms: the entries of the hold-off after it go as they
    /// come, not behind it ([`PendingSaves::next`]).
    alarm_sent_ms: Option<u64>,
}

#[cfg(feature = "cold-chain-log")]
impl Rows {
    const EMPTY: Rows = Rows { entries: heapless::Deque::new(), lost: None, alarm_sent_ms: None };

    fn put(&mut self, e: LogEntry) {
        if self.entries.is_full() {
            if let Some(lost) = self.entries.pop_front() {
                let before = self.lost.map_or(0, |(_, n)| n);
                self.lost = Some((lost.t_s(), before.saturating_add(1)));
            }
        }
        let _ = self.entries.push_back(e);
    }

    fn is_empty(&self) -> bool {
        self.entries.is_empty() && self.lost.is_none()
    }

    /// The next entry, removed from the queue: a `log_entries_lost` event first if some were
    /// dropped (every dropped entry is older than every waiting one).
    fn next(&mut self) -> Option<Save> {
        if let Some((t_s, entries)) = self.lost.take() {
            return Some(Save::Log(LogEntry::Lost { t_s, entries }));
        }
        self.entries.pop_front().map(Save::Log)
    }
}

impl PendingSaves {
    /// Nothing waiting.
    pub const EMPTY: PendingSaves = PendingSaves {
        model: None,
        calibration: None,
        settings: None,
        #[cfg(feature = "holdover")]
        cabinet: None,
        history: None,
        #[cfg(feature = "cold-chain-log")]
        rows: Rows::EMPTY,
        alarm: false,
    };

    /// Queues `save`, replacing any waiting record of its kind.
    pub fn put(&mut self, save: Save) {
        match save {
            Save::Model(m) => self.model = Some(m),
            Save::Calibration(c) => self.calibration = Some(c),
            Save::Settings(s) => self.settings = Some(s),
            #[cfg(feature = "holdover")]
            Save::Cabinet(c) => self.cabinet = Some(c),
            #[cfg(feature = "cold-chain-log")]
            Save::Log(e) => self.rows.put(e),
            // No log in this build (the default firmware's): nothing logs.
            #[cfg(not(feature = "cold-chain-log"))]
            Save::Log(_) => {}
            Save::History(h) => self.history = Some(h),
            Save::AlarmHistory(h) => {
                self.history = Some(h);
                self.alarm = true;
            }
        }
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        #[cfg(feature = "holdover")]
        if self.cabinet.is_some() {
            return false;
        }
        #[cfg(feature = "cold-chain-log")]
        if !self.rows.is_empty() {
            return false;
        }
        self.model.is_none() && self.calibration.is_none() && self.settings.is_none() && self.history.is_none()
    }

    /// The next record `gate` lets through at `now_ms`, removed from the queue: an alarm history
    /// first, then settings (a person waits for them), the cabinet model, history, log entries
    /// (a `log_entries_lost` event first if some were dropped), calibration, model. Out of
    /// line: inlined into the firmware's persist task, each kind's record went into the task's
    /// state through a copy of its own (−244 B of flash).
    ///
    /// Log entries skip the hold-off, as the alarm history does, for the hold-off after an alarm
    /// history went: the rows of what made it urgent, which come with the sample that raised it
    /// or, for a new fail-safe stop, with the boot's first sample (its `board_fault` row), after
    /// the boot's history went. Behind the hold-off, a board whose every boot stops within it
    /// stored the new stop in its history and never its row on the log, which `history` and
    /// `hter report` read. A repeated stop's history waits ([`crate::app::Boot::history_save`]),
    /// and so do its rows: a fault loop does not write at every boot.
    #[inline(never)]
    pub fn next(&mut self, gate: &WriteGate, now_ms: u64) -> Option<Save> {
        // [`WriteGate::allows`] taken apart: the supply good now (both kinds of record), then the
        // hold-off (all but an alarm's); asked whole twice, the test of now was made twice
        // (−44 B of flash).
        let since = gate.good_since(now_ms)?;
        if self.alarm {
            self.alarm = false;
            if let Some(h) = self.history.take() {
                #[cfg(feature = "cold-chain-log")]
                {
                    self.rows.alarm_sent_ms = Some(now_ms);
                }
                return Some(Save::AlarmHistory(h));
            }
        }
        if !gate.held(now_ms, since) {
            #[cfg(feature = "cold-chain-log")]
            if self.rows.alarm_sent_ms.is_some_and(|t| !gate.held(now_ms, t)) {
                return self.rows.next();
            }
            return None;
        }
        if let Some(s) = self.settings.take() {
            return Some(Save::Settings(s));
        }
        #[cfg(feature = "holdover")]
        if let Some(c) = self.cabinet.take() {
            return Some(Save::Cabinet(c));
        }
        if let Some(h) = self.history.take() {
            self.alarm = false;
            return Some(Save::History(h));
        }
        #[cfg(feature = "cold-chain-log")]
        if let Some(row) = self.rows.next() {
            return Some(row);
        }
        if let Some(c) = self.calibration.take() {
            return Some(Save::Calibration(c));
        }
        self.model.take().map(Save::Model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::EventKind;

    const TS_MS: u64 = 10_000;

    fn history(recorded_s: u32) -> HistoryRecord {
        HistoryRecord { recorded_s, ..HistoryRecord::EMPTY }
    }

    /// Runs one boot of `up_ms` with a sample every Ts, `supply(t)` deciding each sample, the
    /// boot history queued at boot and `alarm_at` (if any) queuing an alarm history; returns the
    /// times of the writes.
    fn boot(up_ms: u64, supply: impl Fn(u64) -> bool, alarm_at: Option<u64>) -> Vec<(u64, Save)> {
        let mut gate = WriteGate::firmware();
        let mut pending = PendingSaves::EMPTY;
        pending.put(Save::History(history(0)));
        let mut writes = Vec::new();
        let mut t = 0;
        while t < up_ms {
            gate.note_supply(t, supply(t));
            if alarm_at == Some(t) {
                pending.put(Save::AlarmHistory(history(t as u32 / 1000)));
            }
            while let Some(s) = pending.next(&gate, t) {
                writes.push((t, s));
            }
            t += TS_MS;
        }
        writes
    }

    #[test]
    fn a_power_bounce_every_20_s_for_an_hour_writes_nothing() {
        let boots = 3600 / 20;
        let writes: usize = (0..boots).map(|_| boot(20_000, |_| true, None).len()).sum();
        assert_eq!(writes, 0);
        // The same loop with boots that last 70 s writes each boot's history once.
        let writes: usize = (0..3600 / 70).map(|_| boot(70_000, |_| true, None).len()).sum();
        assert_eq!(writes, 3600 / 70);
    }

    #[test]
    fn a_boot_on_a_good_supply_writes_once_after_the_hold_off() {
        let writes = boot(600_000, |_| true, None);
        assert_eq!(writes, vec![(SUPPLY_HOLD_OFF_MS, Save::History(history(0)))]);
        // A bad sample restarts the hold-off.
        let writes = boot(600_000, |t| t != 40_000, None);
        assert_eq!(writes.iter().map(|w| w.0).collect::<Vec<_>>(), vec![50_000 + SUPPLY_HOLD_OFF_MS]);
    }

    #[test]
    fn an_alarm_writes_at_once_on_a_good_supply_and_never_on_a_bad_one() {
        let writes = boot(40_000, |_| true, Some(20_000));
        assert_eq!(writes, vec![(20_000, Save::AlarmHistory(history(20)))]);
        // An hour of bad supply: nothing, not even the alarm.
        assert!(boot(3_600_000, |_| false, Some(20_000)).is_empty());
        // Supply back at 100 s: the alarm goes at once, before the hold-off.
        let writes = boot(120_000, |t| t >= 100_000, Some(20_000));
        assert_eq!(writes, vec![(100_000, Save::AlarmHistory(history(20)))]);
    }

    #[test]
    fn each_region_counts_its_own_failures_in_a_row() {
        let mut f = StoreFailures::NEW;
        let row = Save::Log(LogEntry::Event { t_s: 1, kind: EventKind::SensorOpen });
        // The records region fails hourly; the log's rows between succeed: the run goes on.
        for hour in 1..=3u8 {
            f.note(&Save::History(history(0)), false);
            for _ in 0..12 {
                f.note(&row, true);
            }
            assert_eq!(f.in_a_row(), hour);
        }
        f.note(&row, false);
        assert_eq!(f.in_a_row(), 3, "the longer run");
        f.note(&Save::Calibration(TwoPoint::IDENTITY), true);
        assert_eq!(f.in_a_row(), 1, "a records store that succeeds ends the records' run");
        for _ in 0..300 {
            f.note(&row, false);
        }
        assert_eq!(f.in_a_row(), u8::MAX, "saturating");
    }

    #[test]
    fn the_flash_is_failing_from_the_third_store_in_a_row_that_fails_once_per_run() {
        let mut w = StoreWatch::NEW;
        let seen: Vec<bool> = [0, 1, 2, 3, 4, 5, 0, 1, 0, 1, 2, 3, 255].into_iter().map(|n| w.observe(n)).collect();
        assert_eq!(seen, [false, false, false, true, false, false, false, false, false, false, false, true, false]);
        assert!(w.failing());
        w.observe(0);
        assert!(!w.failing());
    }

    #[test]
    fn a_stale_sample_closes_the_gate() {
        let mut gate = WriteGate::firmware();
        gate.note_supply(0, true);
        gate.note_supply(60_000, true);
        assert!(gate.allows(60_000, false));
        assert!(gate.allows(60_000 + SUPPLY_FRESH_MS, false));
        assert!(!gate.allows(60_001 + SUPPLY_FRESH_MS, false));
        assert!(!gate.allows(60_001 + SUPPLY_FRESH_MS, true));
        assert!(!WriteGate::firmware().allows(0, true), "no sample yet");
    }

    #[test]
    fn pending_keeps_the_newest_of_each_kind() {
        let mut p = PendingSaves::EMPTY;
        p.put(Save::AlarmHistory(history(1)));
        p.put(Save::History(history(2)));
        p.put(Save::Calibration(TwoPoint::IDENTITY));
        p.put(Save::Calibration(TwoPoint { gain: 1.01, offset_c: 0.1 }));
        let mut gate = WriteGate::firmware();
        gate.note_supply(0, true);
        // Only the alarm may go before the hold-off, and it carries the newest history.
        assert_eq!(p.next(&gate, 0), Some(Save::AlarmHistory(history(2))));
        assert_eq!(p.next(&gate, 0), None);
        gate.note_supply(SUPPLY_HOLD_OFF_MS, true);
        assert_eq!(p.next(&gate, SUPPLY_HOLD_OFF_MS), Some(Save::Calibration(TwoPoint { gain: 1.01, offset_c: 0.1 })));
        assert_eq!(p.next(&gate, SUPPLY_HOLD_OFF_MS), None);
        assert!(p.is_empty());
    }

    /// The boot's `restarted` event at record time `t0_s`, then `n` accepted setpoints one
    /// second apart.
    #[cfg(feature = "cold-chain-log")]
    fn boot_then_settings(t0_s: u32, n: u32) -> Vec<LogEntry> {
        let restarted = LogEntry::Event { t_s: t0_s, kind: EventKind::Restarted(crate::persist::ResetCause::Other) };
        let set = |i: u32| LogEntry::Setting {
            t_s: t0_s + i,
            key: crate::persist::log::SettingKey::Setpoint,
            value: [2.5 + 0.1 * i as f32, 0.0],
        };
        core::iter::once(restarted).chain((1..=n).map(set)).collect()
    }

    /// Everything `gate` lets through at `now_ms`.
    #[cfg(feature = "cold-chain-log")]
    fn drain(p: &mut PendingSaves, gate: &WriteGate, now_ms: u64) -> Vec<Save> {
        core::iter::from_fn(|| p.next(gate, now_ms)).collect()
    }

    #[cfg(feature = "cold-chain-log")]
    fn lost(t_s: u32, entries: u16) -> Save {
        Save::Log(LogEntry::Lost { t_s, entries })
    }

    #[cfg(feature = "cold-chain-log")]
    #[test]
    fn a_flooded_log_queue_leaves_one_lost_event_before_the_entries_it_kept() {
        let mut gate = WriteGate::firmware();
        let mut p = PendingSaves::EMPTY;
        // 40 settings in the minute after a boot: 41 entries for 16 places.
        let entries = boot_then_settings(1, 40);
        let mut t = 0;
        for chunk in entries.chunks(7) {
            gate.note_supply(t, true);
            for e in chunk {
                p.put(Save::Log(*e));
            }
            assert_eq!(p.next(&gate, t), None, "held off at {t} ms");
            t += TS_MS;
        }
        gate.note_supply(SUPPLY_HOLD_OFF_MS, true);
        let writes = drain(&mut p, &gate, SUPPLY_HOLD_OFF_MS);
        // The boot's event and settings 1…24 were dropped: the event carries setting 24's time
        // and their number.
        let kept = &entries[entries.len() - PENDING_LOG..];
        assert_eq!(kept[0].t_s(), 26);
        let want: Vec<Save> = core::iter::once(lost(25, 25)).chain(kept.iter().map(|e| Save::Log(*e))).collect();
        assert_eq!(writes, want);
        assert!(p.is_empty());
        let t_s: Vec<u32> =
            writes.iter().map(|w| if let Save::Log(e) = w { e.t_s() } else { unreachable!() }).collect();
        assert!(t_s.windows(2).all(|w| w[0] <= w[1]), "time order: {t_s:?}");

        // Handed out once: a queue that fills without overflowing later has no event.
        let more = boot_then_settings(100, PENDING_LOG as u32 - 1);
        for e in &more {
            p.put(Save::Log(*e));
        }
        let writes = drain(&mut p, &gate, SUPPLY_HOLD_OFF_MS);
        assert_eq!(writes, more.iter().map(|e| Save::Log(*e)).collect::<Vec<_>>());

        // A bad supply closes the gate again: a second flood gets its own event.
        gate.note_supply(70_000, false);
        let again = boot_then_settings(200, 20);
        for e in &again {
            p.put(Save::Log(*e));
        }
        assert_eq!(p.next(&gate, 70_000), None);
        gate.note_supply(80_000, true);
        gate.note_supply(80_000 + SUPPLY_HOLD_OFF_MS, true);
        let writes = drain(&mut p, &gate, 80_000 + SUPPLY_HOLD_OFF_MS);
        assert_eq!(writes.first(), Some(&lost(204, 5)), "21 entries, 5 dropped: the newest at 204 s");
        assert_eq!(writes[1..], again[5..].iter().map(|e| Save::Log(*e)).collect::<Vec<_>>());
    }

    /// The rows that come with an alarm history (the boot's first sample logs a new stop's
    /// `board_fault` row after the boot's history went) skip the hold-off for the hold-off after
    /// it, as it did: a board that stops again within the minute has them on its log. Later
    /// ones wait for the gate's hold-off, as every row without an alarm does.
    #[cfg(feature = "cold-chain-log")]
    #[test]
    fn the_log_rows_in_the_hold_off_after_an_alarm_history_go_as_they_come() {
        let mut gate = WriteGate::firmware();
        let mut p = PendingSaves::EMPTY;
        let row = |t_s: u32, kind: EventKind| Save::Log(LogEntry::Event { t_s, kind });
        gate.note_supply(0, true);
        p.put(Save::AlarmHistory(history(0)));
        assert_eq!(drain(&mut p, &gate, 0), [Save::AlarmHistory(history(0))]);
        // A bad sample at 20 s: the gate's hold-off runs from 30 s to 90 s.
        gate.note_supply(20_000, false);
        gate.note_supply(30_000, true);
        let first = [
            row(1, EventKind::Restarted(crate::persist::ResetCause::Other)),
            row(1, EventKind::BoardFault(crate::failsafe::StopKind::Panic)),
        ];
        p.put(Save::History(history(30)));
        p.put(Save::Calibration(TwoPoint::IDENTITY));
        for r in first {
            p.put(r);
        }
        assert_eq!(drain(&mut p, &gate, 30_000), first, "the rows only, at once");
        // Past the alarm's hold-off and before the gate's: a row waits, with the others.
        gate.note_supply(70_000, true);
        p.put(row(71, EventKind::SensorOpen));
        assert_eq!(drain(&mut p, &gate, 70_000), []);
        gate.note_supply(90_000, true);
        assert_eq!(
            drain(&mut p, &gate, 90_000),
            [Save::History(history(30)), row(71, EventKind::SensorOpen), Save::Calibration(TwoPoint::IDENTITY)]
        );
        // Without an alarm history the rows wait for the hold-off (the fault loop's repeats).
        let (mut gate, mut p) = (WriteGate::firmware(), PendingSaves::EMPTY);
        gate.note_supply(0, true);
        p.put(Save::History(history(0)));
        p.put(first[1]);
        gate.note_supply(10_000, true);
        assert_eq!(drain(&mut p, &gate, 10_000), []);
    }

    #[cfg(feature = "cold-chain-log")]
    #[test]
    fn a_full_log_queue_that_did_not_overflow_has_no_lost_event() {
        let mut gate = WriteGate::firmware();
        let mut p = PendingSaves::EMPTY;
        gate.note_supply(0, true);
        let entries = boot_then_settings(1, PENDING_LOG as u32 - 1);
        p.put(Save::History(history(1)));
        for e in &entries {
            p.put(Save::Log(*e));
        }
        gate.note_supply(SUPPLY_HOLD_OFF_MS, true);
        let writes = drain(&mut p, &gate, SUPPLY_HOLD_OFF_MS);
        let want: Vec<Save> =
            core::iter::once(Save::History(history(1))).chain(entries.iter().map(|e| Save::Log(*e))).collect();
        assert_eq!(writes, want);
    }
}
