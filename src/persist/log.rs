//! The cold-chain log: what a 30-day temperature recorder keeps, as fixed 16-byte entries in a
//! `sequential-storage` queue (`persist::flash::LogStore`, feature `persist-flash`) — an interval summary every
//! [`INTERVAL_S`] seconds, and every event, alarm and accepted setting.
//!
//! Time is **record time**, seconds: the board's clock counts from boot, so at boot the record
//! continues from its newest entry ([`LogEntry::t_s`]); an outage shows as a `restarted` event,
//! its length is not known (the board has no battery-backed clock: the NUCLEO ties VBAT to VDD).
//!
//! Layout (little endian), 16 bytes:
//!
//! ```text
//! 0      1 … 4     5 … 15
//! tag    t_s u32   payload (zero padded)
//! 'I'  interval  mean, min, max: i16 centi-°C; duty: u16 /10 000; mode u8
//! 'E'  event     EventKind::code u32; for log_entries_lost, the entries lost u16 after it
//! 'A'  alarm     AlarmKind index u8; start_s u32
//! 'S'  setting   SettingKey u8; two f32 values
//! ```
//!
//! `sequential-storage` checks each item with its own CRC; an entry this firmware cannot read
//! (an unknown tag, a value out of range) decodes to an error and is skipped, never shown as data.
//!
//! Entries wait in RAM while flash writes are held off (the minute after a boot, a bad supply:
//! [`crate::persist::WriteGate`]). When more than [`crate::persist::PENDING_LOG`] wait, the
//! oldest are dropped, and the log gets one `log_entries_lost` event
//! ([`EventKind::LogEntriesLost`], stored as [`LogEntry::Lost`] with how many were dropped) at
//! the newest lost entry's time, ahead of the entries kept ([`crate::persist::PendingSaves`]):
//! a hole in the record is marked and sized, never silent. What is missing lies between the
//! entry before that event and the event's time. A count of 0 is a record written before the
//! count was kept (the bytes after the code were zero then): entries were lost, how many is not
//! known.

use crate::coldchain::AlarmKind;
use crate::event::EventKind;
use crate::iface::sink::{put, Sink, Written};
use crate::step::Mode;
use crate::units::{max_f32, min_f32};

/// Interval length, s: the 5 minutes WHO PQS E006 30-day recorders log at.
pub const INTERVAL_S: u32 = 300;

/// Encoded size of every entry, bytes.
pub const ENTRY_LEN: usize = 16;

/// Record time `ms` in the entries' whole seconds, stopping at the end of their clock (u32 s):
/// truncated, a log whose newest entry lay near it (another clock's, or a corrupt one) made the
/// next boot's entries wrap to 0 s and the record run back in time. Out of line: inlined into
/// its four callers it was 312 B more of the interface build's flash; out of line, one 64-bit
/// division for all of them, 80 B less than the truncations it replaced.
#[inline(never)]
pub(crate) fn record_secs(ms: u64) -> u32 {
    u32::try_from(ms / 1000).unwrap_or(u32::MAX)
}

/// One interval's summary.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Interval {
    /// Mean load temperature the controller saw, °C.
    pub mean_c: f32,
    /// Lowest, °C.
    pub min_c: f32,
    /// Highest, °C.
    pub max_c: f32,
    /// Mean applied duty.
    pub duty: f32,
    /// The worst mode of the interval: `sensor_fault` if any sample had no reading, else the last
    /// in [`Mode::ALL`] order that occurred.
    pub mode: Mode,
}

/// Which setting an accepted change set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingKey {
    /// `setpoint_c` (value 0).
    Setpoint,
    /// `controller` (value 0: the law's index in [`crate::iface::Law::ALL`]).
    Controller,
    /// `cal_ice` (channel reading, reference).
    CalIce,
    /// `cal_warm` (channel reading, reference).
    CalWarm,
    /// `model` (static gain, delay).
    Model,
    /// `ack`.
    Ack,
    /// `identify` started (values 0).
    Identify,
    /// Commissioning finished: value 0 = 1 done, 0 failed; value 1 = the failure's code.
    IdentifyEnd,
    /// `sensor_offset_c 0`: the sensor offset cleared (value 0: the offset it had, °C).
    SensorOffset,
    /// A service reset ([`crate::app::Boot::service_reset`]) forgot what the history carried
    /// (value 0: the sensor offset it forgot, in the channel's terms, °C, 0 if none; value 1: 1
    /// if it forgot the SSR's short; [`crate::persist::Recorder::note_service`]: one of them).
    Service,
}

impl SettingKey {
    const ALL: [SettingKey; 10] = [
        SettingKey::Setpoint,
        SettingKey::Controller,
        SettingKey::CalIce,
        SettingKey::CalWarm,
        SettingKey::Model,
        SettingKey::Ack,
        SettingKey::Identify,
        SettingKey::IdentifyEnd,
        SettingKey::SensorOffset,
        SettingKey::Service,
    ];

    /// The key's wire name.
    pub fn name(self) -> &'static str {
        match self {
            SettingKey::Setpoint => "setpoint_c",
            SettingKey::Controller => "controller",
            SettingKey::CalIce => "cal_ice",
            SettingKey::CalWarm => "cal_warm",
            SettingKey::Model => "model",
            SettingKey::Ack => "ack",
            SettingKey::Identify => "identify",
            SettingKey::IdentifyEnd => "identify_end",
            SettingKey::SensorOffset => "sensor_offset_c",
            SettingKey::Service => "service_reset",
        }
    }
}

/// One entry of the log.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LogEntry {
    /// The interval ending at `t_s`.
    Interval {
        /// End of the interval, record s.
        t_s: u32,
        /// Its summary.
        interval: Interval,
    },
    /// An event of the step.
    Event {
        /// Record s.
        t_s: u32,
        /// What happened.
        kind: EventKind,
    },
    /// Log entries lost before they reached flash ([`EventKind::LogEntriesLost`]): stored as
    /// that event with the count after its code.
    Lost {
        /// The newest lost entry's record time, s.
        t_s: u32,
        /// How many entries were dropped (saturating; 0: a record from before the count).
        entries: u16,
    },
    /// A cold-chain alarm.
    Alarm {
        /// When it was raised, record s.
        t_s: u32,
        /// Which.
        kind: AlarmKind,
        /// When its condition began, record s.
        start_s: u32,
    },
    /// An accepted setting, from the serial interface.
    Setting {
        /// Record s.
        t_s: u32,
        /// Which setting.
        key: SettingKey,
        /// Its value(s) (see [`SettingKey`]).
        value: [f32; 2],
    },
}

/// Why 16 bytes are not an entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EntryError {
    /// Not [`ENTRY_LEN`] bytes.
    Length,
    /// A tag, mode, kind or key this firmware does not know, or a value out of its range (an
    /// interval's duty above 1).
    Unknown,
}

fn centi(x: f32) -> i16 {
    // Saturating: a reading beyond ±327 °C is a fault the events already carry.
    let c = x * 100.0;
    let c = if c.is_finite() { min_f32(max_f32(c, -32_767.0), 32_767.0) } else { -32_768.0 };
    if c < 0.0 {
        (c - 0.5) as i16
    } else {
        (c + 0.5) as i16
    }
}

fn from_centi(c: i16) -> f32 {
    if c == i16::MIN {
        f32::NAN
    } else {
        f32::from(c) / 100.0
    }
}

impl LogEntry {
    /// Record time of the entry, s.
    pub fn t_s(&self) -> u32 {
        match *self {
            LogEntry::Interval { t_s, .. }
            | LogEntry::Event { t_s, .. }
            | LogEntry::Lost { t_s, .. }
            | LogEntry::Alarm { t_s, .. }
            | LogEntry::Setting { t_s, .. } => t_s,
        }
    }

    /// The 16 bytes of the entry.
    pub fn encode(&self) -> [u8; ENTRY_LEN] {
        let mut b = [0u8; ENTRY_LEN];
        let (tag, t_s) = match self {
            LogEntry::Interval { t_s, .. } => (b'I', *t_s),
            LogEntry::Event { t_s, .. } | LogEntry::Lost { t_s, .. } => (b'E', *t_s),
            LogEntry::Alarm { t_s, .. } => (b'A', *t_s),
            LogEntry::Setting { t_s, .. } => (b'S', *t_s),
        };
        b[0] = tag;
        b[1..5].copy_from_slice(&t_s.to_le_bytes());
        match self {
            LogEntry::Interval { interval: i, .. } => {
                b[5..7].copy_from_slice(&centi(i.mean_c).to_le_bytes());
                b[7..9].copy_from_slice(&centi(i.min_c).to_le_bytes());
                b[9..11].copy_from_slice(&centi(i.max_c).to_le_bytes());
                let duty = min_f32(max_f32(i.duty, 0.0), 1.0) * 10_000.0 + 0.5;
                b[11..13].copy_from_slice(&(duty as u16).to_le_bytes());
                b[13] = i.mode as u8;
            }
            LogEntry::Event { kind, .. } => b[5..9].copy_from_slice(&kind.code().to_le_bytes()),
            LogEntry::Lost { entries, .. } => {
                b[5..9].copy_from_slice(&EventKind::LogEntriesLost.code().to_le_bytes());
                b[9..11].copy_from_slice(&entries.to_le_bytes());
            }
            LogEntry::Alarm { kind, start_s, .. } => {
                b[5] = *kind as u8;
                b[6..10].copy_from_slice(&start_s.to_le_bytes());
            }
            LogEntry::Setting { key, value, .. } => {
                b[5] = *key as u8;
                b[6..10].copy_from_slice(&value[0].to_le_bytes());
                b[10..14].copy_from_slice(&value[1].to_le_bytes());
            }
        }
        b
    }

    /// The entry of 16 stored bytes.
    pub fn decode(bytes: &[u8]) -> Result<LogEntry, EntryError> {
        let b: &[u8; ENTRY_LEN] = bytes.try_into().map_err(|_| EntryError::Length)?;
        let t_s = u32::from_le_bytes([b[1], b[2], b[3], b[4]]);
        let i16_at = |i: usize| i16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Ok(match b[0] {
            b'I' => LogEntry::Interval {
                t_s,
                interval: Interval {
                    mean_c: from_centi(i16_at(5)),
                    min_c: from_centi(i16_at(7)),
                    max_c: from_centi(i16_at(9)),
                    // The encoder's clamp: a code above 1 is no duty it wrote.
                    duty: match u16::from_le_bytes([b[11], b[12]]) {
                        d @ 0..=10_000 => f32::from(d) / 10_000.0,
                        _ => return Err(EntryError::Unknown),
                    },
                    mode: *Mode::ALL.get(usize::from(b[13])).ok_or(EntryError::Unknown)?,
                },
            },
            b'E' => {
                let code = u32_at(5);
                let kind = EventKind::ALL.into_iter().find(|k| k.code() == code).ok_or(EntryError::Unknown)?;
                if kind == EventKind::LogEntriesLost {
                    LogEntry::Lost { t_s, entries: u16::from_le_bytes([b[9], b[10]]) }
                } else {
                    LogEntry::Event { t_s, kind }
                }
            }
            b'A' => LogEntry::Alarm {
                t_s,
                kind: *AlarmKind::ALL.get(usize::from(b[5])).ok_or(EntryError::Unknown)?,
                start_s: u32_at(6),
            },
            b'S' => LogEntry::Setting {
                t_s,
                key: *SettingKey::ALL.get(usize::from(b[5])).ok_or(EntryError::Unknown)?,
                value: [f32::from_bits(u32_at(6)), f32::from_bits(u32_at(10))],
            },
            _ => return Err(EntryError::Unknown),
        })
    }
}

/// Builds the interval summaries from the samples: one [`Interval`] every [`INTERVAL_S`] of
/// record time, aligned to multiples of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntervalLog {
    /// End of the interval being filled, record ms.
    end_ms: u64,
    n: u32,
    sum_c: f32,
    min_c: f32,
    max_c: f32,
    sum_duty: f32,
    worst: Mode,
}

impl Default for IntervalLog {
    fn default() -> Self {
        Self::new()
    }
}

impl IntervalLog {
    /// Nothing recorded yet.
    pub const fn new() -> Self {
        IntervalLog {
            end_ms: 0,
            n: 0,
            sum_c: 0.0,
            min_c: f32::INFINITY,
            max_c: f32::NEG_INFINITY,
            sum_duty: 0.0,
            worst: Mode::Normal,
        }
    }

    /// Adds the sample at record time `t_ms`; returns the summary of the interval it closed, if
    /// it closed one (an interval with no sample, e.g. during an outage, is not logged).
    pub fn push(&mut self, t_ms: u64, temp_c: f32, duty: f32, mode: Mode) -> Option<LogEntry> {
        let period_ms = u64::from(INTERVAL_S) * 1000;
        let mut closed = None;
        if t_ms >= self.end_ms {
            if self.n > 0 {
                let n = self.n as f32;
                closed = Some(LogEntry::Interval {
                    t_s: record_secs(self.end_ms),
                    interval: Interval {
                        mean_c: self.sum_c / n,
                        min_c: self.min_c,
                        max_c: self.max_c,
                        duty: self.sum_duty / n,
                        mode: self.worst,
                    },
                });
            }
            *self = IntervalLog { end_ms: (t_ms / period_ms + 1) * period_ms, ..IntervalLog::new() };
        }
        if temp_c.is_finite() {
            self.n += 1;
            self.sum_c += temp_c;
            self.min_c = min_f32(self.min_c, temp_c);
            self.max_c = max_f32(self.max_c, temp_c);
            self.sum_duty += duty;
        }
        // A sensor fault labels the interval whatever else it had: its mean, min and max then hold
        // the step's last reading through the fault, which a reader must not take as measured
        // (`hter monitor` drops a `sensor_fault` interval). Ranked below the freeze guard and
        // limp home, a fault that began or ended in an interval with either was labelled by
        // them, and the held value read as the load's. Their trips are in the events.
        if self.worst != Mode::SensorFault && (mode == Mode::SensorFault || (mode as u8) > (self.worst as u8)) {
            self.worst = mode;
        }
        closed
    }
}

/// The header of `history`'s CSV (docs/interface.md).
pub const CSV_HEADER: &str = "t_s,temp_c,min_c,max_c,duty,mode,event";

/// Writes `entry` as one CSV row of `history` (no line end). Event rows leave the measurement
/// columns empty (`hter monitor` and `hter report` take them as events, not samples).
pub fn write_csv_row(entry: &LogEntry, out: &mut impl Sink) -> Written {
    use crate::iface::num::Fixed;
    let t = entry.t_s();
    match entry {
        LogEntry::Interval { interval: i, .. } => put!(
            out,
            t,
            ",",
            Fixed(i.mean_c, 2),
            ",",
            Fixed(i.min_c, 2),
            ",",
            Fixed(i.max_c, 2),
            ",",
            Fixed(i.duty, 3),
            ",",
            i.mode.name(),
            ","
        ),
        _ => {
            put!(out, t, ",,,,,,")?;
            match entry {
                LogEntry::Event { kind, .. } => out.str(kind.name()),
                LogEntry::Lost { entries: 0, .. } => out.str(EventKind::LogEntriesLost.name()),
                LogEntry::Lost { entries, .. } => put!(out, EventKind::LogEntriesLost.name(), ":", *entries),
                LogEntry::Alarm { kind, start_s, .. } => put!(out, "alarm:", kind.name(), "@", *start_s),
                LogEntry::Setting { key, value, .. } => match key {
                    SettingKey::Setpoint => put!(out, "set:setpoint_c=", Fixed(value[0], 2)),
                    SettingKey::Controller => {
                        let name = crate::iface::Law::ALL.get(value[0] as usize).map_or("?", |l| l.name());
                        put!(out, "set:controller=", name)
                    }
                    SettingKey::CalIce | SettingKey::CalWarm => {
                        put!(out, "set:", key.name(), "=", Fixed(value[0], 2), ";", Fixed(value[1], 2))
                    }
                    SettingKey::Model => put!(out, "set:model=gain ", Fixed(value[0], 1), ";k ", Fixed(value[1], 0)),
                    SettingKey::Ack => out.str("ack"),
                    SettingKey::SensorOffset => put!(out, "set:sensor_offset_c=0.00;was ", Fixed(value[0], 2)),
                    SettingKey::Service => {
                        out.str("service_reset:cleared")?;
                        if value[1] > 0.5 {
                            out.str(" ssr_short")?;
                        }
                        if value[0] == 0.0 {
                            return Ok(());
                        }
                        put!(out, " sensor_offset_c ", Fixed(value[0], 2))
                    }
                    SettingKey::Identify => out.str("commissioning:started"),
                    SettingKey::IdentifyEnd if value[0] > 0.5 => out.str("commissioning:done"),
                    SettingKey::IdentifyEnd => {
                        put!(out, "commissioning:failed:", crate::app::commission_failure_name(value[1] as u8))
                    }
                },
                LogEntry::Interval { .. } => Ok(()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::persist::ResetCause;
    use std::string::String;

    #[test]
    fn every_entry_kind_survives_its_bytes() {
        let entries = [
            LogEntry::Interval {
                t_s: 300,
                interval: Interval { mean_c: 4.02, min_c: 3.87, max_c: -1.5, duty: 0.4567, mode: Mode::FreezeGuard },
            },
            LogEntry::Event { t_s: 7, kind: EventKind::Restarted(ResetCause::BrownOut) },
            LogEntry::Lost { t_s: 8, entries: 1 },
            LogEntry::Lost { t_s: 9, entries: u16::MAX },
            LogEntry::Alarm { t_s: 36_000, kind: AlarmKind::Heat10h, start_s: 0 },
            LogEntry::Setting { t_s: 12, key: SettingKey::CalWarm, value: [25.31, 25.02] },
            LogEntry::Setting { t_s: 13, key: SettingKey::Service, value: [1.5, 1.0] },
        ];
        for e in entries {
            let back = LogEntry::decode(&e.encode()).unwrap();
            match (e, back) {
                (LogEntry::Interval { interval: a, .. }, LogEntry::Interval { interval: b, .. }) => {
                    for (x, y) in [(a.mean_c, b.mean_c), (a.min_c, b.min_c), (a.max_c, b.max_c)] {
                        assert!((x - y).abs() <= 0.005, "{x} {y}");
                    }
                    assert!((a.duty - b.duty).abs() <= 0.5e-4);
                    assert_eq!(a.mode, b.mode);
                }
                _ => assert_eq!(e, back),
            }
        }
        for ev in EventKind::ALL.into_iter().filter(|&k| k != EventKind::LogEntriesLost) {
            assert_eq!(
                LogEntry::decode(&LogEntry::Event { t_s: 1, kind: ev }.encode()),
                Ok(LogEntry::Event { t_s: 1, kind: ev })
            );
        }
        let mut bad = entries[0].encode();
        bad[0] = b'X';
        assert_eq!(LogEntry::decode(&bad), Err(EntryError::Unknown));
        bad[0] = b'I';
        bad[13] = 9;
        assert_eq!(LogEntry::decode(&bad), Err(EntryError::Unknown));
        assert_eq!(LogEntry::decode(&bad[..15]), Err(EntryError::Length));
    }

    #[test]
    fn intervals_summarise_five_minutes_of_samples() {
        let mut log = IntervalLog::new();
        let mut closed = std::vec::Vec::new();
        // 10 s samples from t = 5 s for 20 minutes: temperature = minute of the run.
        for i in 0..120u64 {
            let t_ms = 5_000 + i * 10_000;
            let mode = if i == 40 { Mode::SensorFault } else { Mode::Normal };
            if let Some(e) = log.push(t_ms, (t_ms / 60_000) as f32, 0.5, mode) {
                closed.push(e);
            }
        }
        assert_eq!(closed.len(), 3, "the 4th interval is still open");
        let LogEntry::Interval { t_s, interval } = closed[0] else { panic!() };
        assert_eq!(t_s, 300);
        // Samples at 5, 15, … 295 s: 30 samples, minutes 0…4, six of each → mean 2.
        assert!((interval.mean_c - 2.0).abs() < 1e-6, "{}", interval.mean_c);
        assert_eq!((interval.min_c, interval.max_c), (0.0, 4.0));
        assert_eq!(interval.mode, Mode::Normal);
        let LogEntry::Interval { t_s, interval } = closed[1] else { panic!() };
        assert_eq!((t_s, interval.mode), (600, Mode::SensorFault), "sample 40 is at 405 s");
    }

    /// A sensor fault labels its interval even beside the freeze guard or limp home, which rank
    /// above it otherwise: the interval's temperatures hold the last reading through the fault.
    #[test]
    fn a_sensor_fault_labels_its_interval_beside_any_other_mode() {
        for modes in [
            [Mode::LimpHome, Mode::SensorFault, Mode::Normal],
            [Mode::SensorFault, Mode::FreezeGuard, Mode::LimpHome],
            [Mode::Normal, Mode::FreezeGuard, Mode::SensorFault],
        ] {
            let mut log = IntervalLog::new();
            for (i, mode) in modes.into_iter().enumerate() {
                assert_eq!(log.push(10_000 * (i as u64 + 1), 4.0, 0.5, mode), None);
            }
            let Some(LogEntry::Interval { interval, .. }) = log.push(300_000, 4.0, 0.5, Mode::Normal) else {
                panic!("{modes:?}: the interval closes")
            };
            assert_eq!(interval.mode, Mode::SensorFault, "{modes:?}");
        }
        // Without a fault the rank holds.
        let mut log = IntervalLog::new();
        for (i, mode) in [Mode::LimpHome, Mode::FreezeGuard, Mode::Normal].into_iter().enumerate() {
            let _ = log.push(10_000 * (i as u64 + 1), 4.0, 0.5, mode);
        }
        let Some(LogEntry::Interval { interval, .. }) = log.push(300_000, 4.0, 0.5, Mode::Normal) else { panic!() };
        assert_eq!(interval.mode, Mode::LimpHome);
    }

    /// Found by fuzzing (`persist::fuzz::edited_log_entries`): an interval's duty code above
    /// 10 000 (a duty above 1, which the encoder never writes: it clamps) was read as data and
    /// shown in `history` (up to 6.554), against this module's rule that a value out of range is
    /// an entry this firmware cannot read.
    #[test]
    fn an_interval_with_a_duty_above_one_is_not_read() {
        let i = Interval { mean_c: 4.0, min_c: 3.5, max_c: 4.5, duty: 1.0, mode: Mode::Normal };
        let mut b = LogEntry::Interval { t_s: 300, interval: i }.encode();
        assert_eq!(LogEntry::decode(&b), Ok(LogEntry::Interval { t_s: 300, interval: i }));
        for code in [10_001u16, 10_132, u16::MAX] {
            b[11..13].copy_from_slice(&code.to_le_bytes());
            assert_eq!(LogEntry::decode(&b), Err(EntryError::Unknown), "{code}");
        }
    }

    /// The lost-entry count sits after the event's code, where the bytes were zero before it was
    /// kept: a record written then still reads, as a hole of unknown size.
    #[test]
    fn a_lost_entries_event_keeps_its_count_and_older_records_read_as_unknown() {
        let bytes = LogEntry::Lost { t_s: 600, entries: 37 }.encode();
        assert_eq!(&bytes[5..9], &EventKind::LogEntriesLost.code().to_le_bytes());
        assert_eq!(&bytes[9..11], &37u16.to_le_bytes());
        let older = LogEntry::Event { t_s: 600, kind: EventKind::LogEntriesLost }.encode();
        assert_eq!(&older[9..], &[0u8; 7]);
        assert_eq!(LogEntry::decode(&older), Ok(LogEntry::Lost { t_s: 600, entries: 0 }));
        let mut s = String::new();
        write_csv_row(&LogEntry::Lost { t_s: 600, entries: 37 }, &mut s).unwrap();
        s.push('\n');
        write_csv_row(&LogEntry::Lost { t_s: 900, entries: 0 }, &mut s).unwrap();
        assert_eq!(s, "600,,,,,,log_entries_lost:37\n900,,,,,,log_entries_lost");
    }

    #[test]
    fn csv_rows_of_events_leave_the_measurements_empty() {
        let mut s = String::new();
        let i = Interval { mean_c: 4.0, min_c: 3.5, max_c: 4.5, duty: 0.45, mode: Mode::Normal };
        write_csv_row(&LogEntry::Interval { t_s: 300, interval: i }, &mut s).unwrap();
        s.push('\n');
        write_csv_row(&LogEntry::Setting { t_s: 310, key: SettingKey::Setpoint, value: [5.0, 0.0] }, &mut s).unwrap();
        for value in [[0.0, 1.0], [1.5, 0.0], [0.99, 1.0]] {
            s.push('\n');
            write_csv_row(&LogEntry::Setting { t_s: 320, key: SettingKey::Service, value }, &mut s).unwrap();
        }
        let service = "320,,,,,,service_reset:cleared ssr_short\n320,,,,,,service_reset:cleared sensor_offset_c 1.50\n\
                       320,,,,,,service_reset:cleared ssr_short sensor_offset_c 0.99";
        assert_eq!(s, format!("300,4.00,3.50,4.50,0.450,normal,\n310,,,,,,set:setpoint_c=5.00\n{service}"));
        assert_eq!(CSV_HEADER.split(',').count(), s.lines().next().unwrap().split(',').count());
    }
}
