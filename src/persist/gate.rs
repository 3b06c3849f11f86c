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
        match self.good_since_ms {
            Some(since) if self.good_now(now_ms) => alarm_due || now_ms.saturating_sub(since) >= self.hold_off_ms,
            _ => false,
        }
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
    /// An entry of the cold-chain log: every one is kept, in order.
    Log(super::log::LogEntry),
}

/// Log entries that may wait for the [`WriteGate`]: a little over an hour of intervals and
/// events at a typical rate; beyond it the oldest waiting entry is dropped and counted.
pub const PENDING_LOG: usize = 16;

/// The newest record of each kind waiting for the [`WriteGate`], and every log entry (in order).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PendingSaves {
    model: Option<ModelRecord>,
    calibration: Option<TwoPoint>,
    settings: Option<super::SettingsRecord>,
    #[cfg(feature = "holdover")]
    cabinet: Option<super::CabinetRecord>,
    history: Option<HistoryRecord>,
    log: heapless::Deque<super::log::LogEntry, PENDING_LOG>,
    /// Log entries dropped because [`PENDING_LOG`] were waiting.
    pub log_dropped: u16,
    /// The waiting history holds an alarm not yet stored (stays set when a newer history
    /// replaces it: the newer one counts the alarm too).
    alarm: bool,
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
        log: heapless::Deque::new(),
        log_dropped: 0,
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
            Save::Log(e) => {
                if self.log.is_full() {
                    self.log.pop_front();
                    self.log_dropped = self.log_dropped.saturating_add(1);
                }
                let _ = self.log.push_back(e);
            }
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
        self.model.is_none()
            && self.calibration.is_none()
            && self.settings.is_none()
            && self.history.is_none()
            && self.log.is_empty()
    }

    /// The next record `gate` lets through at `now_ms`, removed from the queue: an alarm history
    /// first, then settings (a person waits for them), the cabinet model, history, log entries,
    /// calibration, model.
    pub fn next(&mut self, gate: &WriteGate, now_ms: u64) -> Option<Save> {
        if self.alarm && gate.allows(now_ms, true) {
            self.alarm = false;
            if let Some(h) = self.history.take() {
                return Some(Save::AlarmHistory(h));
            }
        }
        if !gate.allows(now_ms, false) {
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
        if let Some(e) = self.log.pop_front() {
            return Some(Save::Log(e));
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
}
