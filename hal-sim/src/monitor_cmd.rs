//! `hter monitor`: the cold-chain record of any CSV log, computed by the same
//! library monitor the firmware runs.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use hter::coldchain::{AlarmKind, ColdChainMonitor};
use hter::event::EventKind;
use hter::persist::log::INTERVAL_S as INTERVAL_S_U32;
use hter::step::Mode;

/// A board history's interval, s.
const INTERVAL_S: f64 = INTERVAL_S_U32 as f64;
use serde::Serialize;

use crate::log;

/// Arguments of `hter monitor`.
#[derive(clap::Args, Debug, Clone)]
pub struct MonitorArgs {
    /// CSV log with columns t_s and temp_c (an empty temp_c is a sample with no reading); rows
    /// with a non-empty `event` column (the board's history) are events, not samples. A board
    /// history's interval row (a file with min_c and max_c) covers the 5 min ending at its t_s.
    #[arg(long)]
    pub input: PathBuf,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// One alarm of the report.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AlarmOut {
    /// Kind (`heat_10h`, `freeze_60min`, `ship_45c_1h`, `ship_30c_10h`).
    pub kind: &'static str,
    /// Start of the qualifying run, s.
    pub start_s: f64,
    /// Trigger time, s.
    pub trigger_s: f64,
}

/// The `--json` report.
#[derive(Debug, Serialize)]
pub struct Report {
    /// Alarms raised.
    pub alarms: Vec<AlarmOut>,
    /// Mean kinetic temperature over the time with a reading, °C.
    pub mkt_c: f64,
    /// Lowest temperature, °C.
    pub min_c: f64,
    /// Highest temperature, °C.
    pub max_c: f64,
    /// Time below +2 °C, s.
    pub time_below_2_s: f64,
    /// Time above +8 °C, s.
    pub time_above_8_s: f64,
    /// Time within 2–8 °C, s.
    pub time_in_range_s: f64,
    /// Time with no reading (after a sample with an empty `temp_c`), s.
    pub time_no_reading_s: f64,
    /// Samples with no reading; for a board history, its interval rows with no reading (each up
    /// to 5 min), and one for each hole after a `log_entries_lost` event.
    pub fault_samples: u32,
    /// Number of excursions outside 2–8 °C.
    pub excursions: u32,
    /// Intervals of a board history whose lowest or highest reading (`min_c`, `max_c`) left
    /// 2–8 °C (0 for a log of samples). The times above are the interval means': a dip between
    /// two readings of a mean is counted here, not there.
    pub intervals_outside_2_8: u32,
    /// Alarms the carrier recorded in a board history (`alarm:KIND@START` events, raised by the
    /// firmware's monitor on every 10 s sample) that the readings of the file do not show in
    /// [`Self::alarms`]: the file's 5-minute means can miss what the samples met.
    pub carrier_alarms: Vec<AlarmOut>,
}

/// The library monitor fed on the record's time (the log's time less the gaps so far), on its
/// integer millisecond clock from `t0_s` (0, or the first sample if that is earlier).
struct Record {
    m: ColdChainMonitor,
    t0_s: f64,
    alarms: Vec<(&'static str, u64, u64)>,
    /// Each sample given to the monitor: its record time (ms) and its time in the log, to give
    /// the alarms back on the log's axis.
    pushed: Vec<(u64, f64)>,
}

impl Record {
    /// Gives the monitor one sample. Its clock counts whole milliseconds: a sample that does not
    /// fall on a later millisecond than the one before would be dropped by it, so it is refused.
    fn push(&mut self, record_t: f64, log_t: f64, c: f64) -> Result<()> {
        let record_ms = ((record_t - self.t0_s) * 1000.0).round().max(0.0) as u64;
        if let Some(&(ms, prev)) = self.pushed.last().filter(|p| p.0 >= record_ms) {
            bail!(
                "t_s = {log_t} falls on the same millisecond as the sample at t_s = {prev} ({ms} ms of the record): \
                 samples must be at least 1 ms apart"
            );
        }
        self.pushed.push((record_ms, log_t));
        for a in self.m.push(record_ms, c as f32).into_iter().flatten() {
            self.alarms.push((a.kind.name(), a.start_ms, a.trigger_ms));
        }
        Ok(())
    }
}

/// Runs the monitor over a log; `None` is a sample with no reading (a sensor fault).
///
/// Samples hold over the interval to the next one (the library monitor's rule). The interval
/// after a sample with no reading is *unknown*: it is cut out of the record before the library
/// monitor sees it, so it counts neither as in range nor as out of range, adds nothing to any
/// alarm's duration and nothing to the mean kinetic temperature, and is reported on its own
/// (`time_no_reading_s`). A run that meets an alarm's condition on both sides of the gap goes
/// on (a failed sensor must not reset the clock of a heat or freeze excursion); only the time
/// with a reading counts toward its duration, so the alarm triggers later by the gap's length.
/// That is what a 30-day recorder can defend: it never claims a temperature it did not
/// measure, and it never forgets an excursion it did. Alarm times are given on the log's own
/// time axis.
pub fn report(t: &[f64], temp: &[Option<f64>]) -> Result<Report> {
    report_closed(t, temp, false)
}

/// [`report`] of a log whose last sample, when `closing`, is no sample of its own but the end of
/// the interval of the one before it ([`Input::closing`]: a board history's last row holds to
/// its `t_s`): with no reading there it is not one more fault sample.
pub fn report_closed(t: &[f64], temp: &[Option<f64>], closing: bool) -> Result<Report> {
    let readings = temp.iter().filter(|c| c.is_some()).count();
    if readings < 2 {
        bail!("the log needs at least 2 samples with a temperature, it has {readings}");
    }
    let t0_s = t.first().copied().unwrap_or(0.0).min(0.0);
    let mut rec = Record { m: ColdChainMonitor::new(), t0_s, alarms: Vec::new(), pushed: Vec::new() };
    let mut gaps_s = 0.0;
    let mut no_reading_s = 0.0;
    let mut fault_samples = 0u32;
    let last_reading = temp.iter().rposition(Option::is_some);
    let mut held = None;
    for (i, (&ts, &c)) in t.iter().zip(temp).enumerate() {
        if closing && c.is_none() && i + 1 == t.len() {
            break;
        }
        if let Some(c) = c {
            rec.push(ts - gaps_s, ts, c)?;
            held = Some(c);
            continue;
        }
        // A log that ends in faults: the last reading holds until the first of them (a gap
        // inside the log is closed by the reading after it).
        if let Some(c) = held.filter(|_| last_reading.is_some_and(|r| r + 1 == i)) {
            rec.push(ts - gaps_s, ts, c)?;
        }
        fault_samples += 1;
        // The last sample has no interval after it.
        let unknown = t.get(i + 1).map_or(0.0, |&next| next - ts);
        no_reading_s += unknown;
        gaps_s += unknown;
    }
    let Record { m, alarms, pushed, .. } = rec;
    let on_log = |x: u64| {
        let k = pushed.partition_point(|p| p.0 < x);
        pushed.get(k).filter(|p| p.0 == x).map_or(x as f64 / 1000.0 + t0_s, |p| p.1)
    };
    let alarms =
        alarms.into_iter().map(|(kind, s, tr)| AlarmOut { kind, start_s: on_log(s), trigger_s: on_log(tr) }).collect();
    let f = |x: Option<f32>| x.map_or(f64::NAN, f64::from);
    let (below, above) = (m.time_below_2_ms() as f64 / 1000.0, m.time_above_8_ms() as f64 / 1000.0);
    Ok(Report {
        alarms,
        mkt_c: f(m.mkt_c()),
        min_c: f(m.min_c()),
        max_c: f(m.max_c()),
        time_below_2_s: below,
        time_above_8_s: above,
        time_in_range_s: m.recorded_ms() as f64 / 1000.0 - below - above,
        time_no_reading_s: no_reading_s,
        fault_samples,
        excursions: m.excursion_count(),
        intervals_outside_2_8: 0,
        carrier_alarms: Vec::new(),
    })
}

/// The cold-chain record of a log as read by [`read_input`]: [`report`] of its readings, then
/// what a board history adds. The extremes of its intervals (`min_c`, `max_c`) widen `min_c`
/// and `max_c` and count in [`Report::intervals_outside_2_8`]; its alarm events that the
/// readings do not show are [`Report::carrier_alarms`]. A history's rows are 5-minute means:
/// recomputed from them alone, a dip to −5 °C between two readings of a mean of 4 °C, or the
/// carrier's own freeze alarm, would not be in the record a supervisor reads.
pub fn record(input: &Input) -> Result<Report> {
    let mut r = report_closed(&input.t_s, &input.temp_c, input.closing)?;
    for &(lo, hi) in input.extremes.iter().flatten() {
        r.min_c = r.min_c.min(lo);
        r.max_c = r.max_c.max(hi);
        if lo < 2.0 || hi > 8.0 {
            r.intervals_outside_2_8 += 1;
        }
    }
    r.carrier_alarms =
        carrier_alarms(&input.events)?.into_iter().filter(|b| !r.alarms.iter().any(|a| same_alarm(a, b))).collect();
    Ok(r)
}

/// How far apart, s, the carrier's trigger time and the one recomputed from a history's means
/// may be for the two to be one alarm: a run of means meets a threshold up to an interval
/// later or earlier than the samples did, and an interval after a restart is a short one.
pub const SAME_ALARM_S: f64 = 2.0 * INTERVAL_S;

/// Whether a recomputed alarm and one the carrier recorded are the same.
fn same_alarm(recomputed: &AlarmOut, carrier: &AlarmOut) -> bool {
    recomputed.kind == carrier.kind && (recomputed.trigger_s - carrier.trigger_s).abs() <= SAME_ALARM_S
}

/// The alarm events of a board history: `alarm:KIND@START` (the firmware's spelling: raised at
/// the row's `t_s`, its condition from record second START) or `alarm:KIND`. Names the library
/// does not know are left with the other events. A START that is no record second at or before
/// the row's `t_s` (not a number, negative, later than the alarm) is a corrupt row and refused:
/// `alarm:heat_10h@-1e300` was reported as an alarm that started 1e300 s before the record,
/// `@nan` as one that started when it triggered.
pub fn carrier_alarms(events: &[Event]) -> Result<Vec<AlarmOut>> {
    let mut out = Vec::new();
    for e in events {
        let Some(rest) = e.name.strip_prefix("alarm:") else { continue };
        let (name, start) = rest.split_once('@').map_or((rest, None), |(n, s)| (n, Some(s)));
        let Some(kind) = AlarmKind::ALL.into_iter().find(|k| k.name() == name).map(AlarmKind::name) else {
            continue;
        };
        let start_s = match start {
            None => e.t_s,
            Some(s) => match s.parse::<f64>() {
                Ok(v) if (0.0..=e.t_s).contains(&v) => v,
                _ => bail!(
                    "event '{}' at t_s = {}: its start '{}' is not a record second in 0…{} (the alarm's own time)",
                    log::clip(&e.name),
                    crate::sim_cmd::shown(e.t_s),
                    log::clip(s),
                    crate::sim_cmd::shown(e.t_s)
                ),
            },
        };
        out.push(AlarmOut { kind, start_s, trigger_s: e.t_s });
    }
    Ok(out)
}

/// One event of a board history (`event` column), or a reset or an event of a `hter log2csv`
/// output (`reset_cause` and `events` columns).
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Time on the log's axis, s.
    pub t_s: f64,
    /// The event's name as the file spells it (`restarted:brownout`, `alarm:heat_10h`, …).
    pub name: String,
}

/// A cold-chain log as `hter monitor` and `hter report` read it.
#[derive(Debug, Clone)]
pub struct Input {
    /// Sample times, s, strictly increasing; a sample holds to the next one. A board history's
    /// interval row is a sample at the start of its interval (its `t_s` less the interval, 300 s, or
    /// the row before's `t_s` if that is later), and the last row's `t_s` closes the record
    /// ([`Self::closing`]).
    pub t_s: Vec<f64>,
    /// Sample temperatures, °C (`None`: no reading).
    pub temp_c: Vec<Option<f64>>,
    /// Each sample's interval extremes (`min_c`, `max_c`) when the file is a board history
    /// (`None` for a sample without them, and for every sample of a file without the columns).
    pub extremes: Vec<Option<(f64, f64)>>,
    /// Events, in time order (empty when the file has neither column).
    pub events: Vec<Event>,
    /// Whether the file has an `event`, `reset_cause` or `events` column (a file without one cannot say
    /// that nothing happened).
    pub has_event_column: bool,
    /// Whether the last entry of `t_s` is no row but the end of the last row's interval (a board
    /// history), where that row's temperature is repeated.
    pub closing: bool,
    /// Whether the file is a board history (its `min_c` and `max_c` columns): its rows are
    /// intervals of up to 5 min, not samples.
    pub history: bool,
    /// Entries of `t_s` that are no row of the file but the start of a hole after a
    /// `log_entries_lost` event (no reading).
    pub holes: usize,
}

impl Input {
    /// The samples of the file: `t_s`'s entries less the closing one.
    pub fn samples(&self) -> usize {
        self.t_s.len() - usize::from(self.closing)
    }

    /// `n` of the file's rows as people read them: `12 samples` for a log of samples, `12
    /// intervals` for a board history, whose rows each summarise up to 5 min of the board's
    /// 10 s samples (a history's row count said "samples" where a row is 30 of them).
    pub fn rows_text(&self, n: usize) -> String {
        let unit = if self.history { "interval" } else { "sample" };
        format!("{n} {unit}{}", if n == 1 { "" } else { "s" })
    }

    /// The rows of the file read as samples, as [`Self::rows_text`] says them.
    pub fn count_text(&self) -> String {
        let text = self.rows_text(self.samples() - self.holes);
        if self.history {
            format!("{text} of up to 5 min")
        } else {
            text
        }
    }

    /// Why there was no reading, by [`Report::fault_samples`]: the probe (the file's rows with
    /// no reading), the record (holes after a `log_entries_lost` event), or both.
    pub fn no_reading_cause(&self, fault_samples: u32) -> NoReading {
        NoReading::of(fault_samples, self.holes)
    }

    /// What had no reading, by [`Report::fault_samples`]: the file's rows with no reading and
    /// the holes after a `log_entries_lost` event, each said as what it is.
    pub fn no_reading_text(&self, fault_samples: u32) -> String {
        let rows = (fault_samples as usize).saturating_sub(self.holes);
        let mut parts = Vec::new();
        if rows > 0 {
            parts.push(self.rows_text(rows));
        }
        if self.holes > 0 {
            parts.push(format!("{} hole{} of lost log entries", self.holes, if self.holes == 1 { "" } else { "s" }));
        }
        parts.join(" and ")
    }
}

/// Why a log had no reading for a while.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoReading {
    /// The probe: rows with no reading.
    SensorFault,
    /// The record: holes after a `log_entries_lost` event.
    LostEntries,
    /// Both.
    Both,
}

impl NoReading {
    /// The cause when `holes` of `fault_samples` are holes after a `log_entries_lost` event.
    pub fn of(fault_samples: u32, holes: usize) -> NoReading {
        match ((fault_samples as usize) > holes, holes > 0) {
            (true, true) => NoReading::Both,
            (false, true) => NoReading::LostEntries,
            _ => NoReading::SensorFault,
        }
    }

    /// As the no-reading line and the report's row name it.
    pub fn label(self) -> &'static str {
        match self {
            NoReading::SensorFault => "sensor fault",
            NoReading::LostEntries => "lost log entries",
            NoReading::Both => "sensor fault; lost log entries",
        }
    }
}

/// Reads a simulator CSV, a `hter log2csv` output or a board history (docs/interface.md): the
/// `t_s` and `temp_c` columns; when an `event` column exists, a row with a non-empty `event` is
/// an event, not a sample (its temperature cells only repeat the last interval's mean, or are
/// empty); a non-empty `reset_cause` is a reset event at that (sample) row, and each name in a
/// non-empty `events` cell (`hter log2csv`: `ssr_stuck_on;lid_open`) an event there. Sample times must
/// strictly increase and no row may go back in time.
///
/// A board history (a file with the `min_c` and `max_c` columns) is told from a log of samples
/// (`hter sim --csv`, `hter log2csv`) by those columns. Its interval row's `t_s` is the end of
/// the interval it summarises (`hter::persist::log::IntervalLog`): the row holds over the
/// interval that ends at its `t_s`, i.e. it is read as a sample at `t_s` − `INTERVAL_S` (at the
/// row before's `t_s` if that is later), and the last row's `t_s` closes the record. A log of
/// samples keeps its meaning: a sample holds until the next one. Read as samples at their
/// `t_s`, a history's alarms started and triggered an interval late, its first interval was cut
/// from the period and its last interval from every time in and out of range. After a
/// `log_entries_lost` event, the time from the end of the sample row before it to the start of
/// the next sample row is no reading (a sample with no temperature is added there; one interval
/// past the row before, for a file that is no history): those rows never reached flash.
///
/// A sample's temperature must lie in the range the carrier's Pt100 can report (IEC 60751,
/// [`crate::log::outside_pt100`]): anything else is a corrupt log, not a reading. Unchecked, 1e39 °C
/// became infinite in the library monitor's f32 and was dropped, so `report` said "IN RANGE"
/// over a day table showing hours above 8 °C, and −500 °C gave no mean kinetic temperature.
pub fn read_input(path: &std::path::Path) -> Result<Input> {
    let shown = path.display();
    let mut cols = log::read_cells(path, &["t_s", "temp_c"])?.into_iter();
    let (t_all, temp_all) = (cols.next().unwrap_or_default(), cols.next().unwrap_or_default());
    let event_col = log::read_text(path, "event")?;
    let reset_col = log::read_text(path, "reset_cause")?;
    let events_col = log::read_text(path, "events")?;
    let mode_col = log::read_text(path, "mode")?;
    // A board history's interval extremes; a file with one of the two columns is not one.
    let extremes = match (log::has_column(path, "min_c")?, log::has_column(path, "max_c")?) {
        (true, true) => {
            let mut c = log::read_cells(path, &["min_c", "max_c"])?.into_iter();
            Some((c.next().unwrap_or_default(), c.next().unwrap_or_default()))
        }
        (false, false) => None,
        (lo, _) => bail!(
            "'{shown}': a column '{}' without '{}'",
            if lo { "min_c" } else { "max_c" },
            if lo { "max_c" } else { "min_c" }
        ),
    };
    let cell =
        |col: &Option<Vec<String>>, i: usize| col.as_ref().and_then(|c| c.get(i)).filter(|s| !s.is_empty()).cloned();
    let mut input = Input {
        t_s: Vec::new(),
        temp_c: Vec::new(),
        extremes: Vec::new(),
        events: Vec::new(),
        has_event_column: event_col.is_some() || reset_col.is_some() || events_col.is_some(),
        closing: false,
        history: extremes.is_some(),
        holes: 0,
    };
    // A board history (its interval extremes' columns): a row's `t_s` is the end of its interval.
    let history = extremes.is_some();
    // The newest sample row's time and the newest row's of any kind.
    let (mut last_sample, mut last): (Option<f64>, Option<f64>) = (None, None);
    // A `log_entries_lost` event since the last sample row: the rows after that one, up to the
    // event, were dropped before they reached flash.
    let mut lost = false;
    for (i, (t, c)) in t_all.into_iter().zip(temp_all).enumerate() {
        let line = i + 2;
        let t = t.ok_or_else(|| anyhow!("'{shown}' line {line}, column 't_s': empty"))?;
        if let Some(name) = cell(&event_col, i) {
            if let Some(p) = last.filter(|&p| t < p) {
                bail!("'{shown}' line {line}: t_s = {t} goes back in time (previous {p})");
            }
            lost |= name.starts_with(EventKind::LogEntriesLost.name());
            input.events.push(Event { t_s: t, name });
            last = Some(t);
            continue;
        }
        if let Some(p) = last_sample.filter(|&p| t <= p) {
            bail!("'{shown}' line {line}: t_s = {t} does not increase (previous {p})");
        }
        // Boards before the fix logged an event found on the sample that closed an interval
        // (a second after its end) before the interval's row: a row up to one interval older
        // than the event before it is that, not a clock that went back.
        if let Some(p) = last.filter(|&p| t < p - INTERVAL_S) {
            bail!("'{shown}' line {line}: t_s = {t} goes back in time (previous {p})");
        }
        // On a sensor fault the board holds its last good reading: the row's temperature is
        // not a measurement, and the time is not known to be in range.
        let c = c.filter(|_| cell(&mode_col, i).as_deref() != Some(Mode::SensorFault.name()));
        if let Some(why) = c.and_then(log::outside_pt100) {
            bail!("'{shown}' line {line}, column 'temp_c': {why}");
        }
        let span = extremes.as_ref().filter(|_| c.is_some()).map_or(Ok(None), |(lo, hi)| {
            extremes_of(lo.get(i).copied().flatten(), hi.get(i).copied().flatten(), c)
                .map_err(|e| anyhow!("'{shown}' line {line}: {e}"))
        })?;
        // A history's row holds over the interval that ends at its `t_s`: from an interval
        // before it, or from the row before it if that ended later (rows less than an interval
        // apart, which the board's aligned intervals never are).
        let at = if history { last_sample.map_or(t - INTERVAL_S, |p| p.max(t - INTERVAL_S)) } else { t };
        // Entries lost before this row: the last row before them holds its own interval, and
        // what follows it up to this row's interval was not recorded (no reading, as on a sensor
        // fault).
        let after_loss = std::mem::take(&mut lost);
        let hole = last_sample.map(|p| if history { p } else { p + INTERVAL_S });
        if let Some(hole) = hole.filter(|&h| after_loss && h < at) {
            input.t_s.push(hole);
            input.temp_c.push(None);
            input.extremes.push(None);
            input.holes += 1;
        }
        if let Some(cause) = cell(&reset_col, i) {
            // `hter log2csv` names the cause (`restarted_brownout`, …, or `unknown`).
            let name = if cause.starts_with("restarted") { cause } else { format!("restarted: {cause}") };
            input.events.push(Event { t_s: t, name });
        }
        // `hter log2csv`'s: the step's events logged with this sample, `;`-separated.
        for name in cell(&events_col, i).iter().flat_map(|c| c.split(';')).filter(|n| !n.is_empty()) {
            input.events.push(Event { t_s: t, name: name.to_owned() });
        }
        input.t_s.push(at);
        input.temp_c.push(c);
        input.extremes.push(span);
        last_sample = Some(t);
        last = Some(last.map_or(t, |p: f64| p.max(t)));
    }
    // The last row of a history holds to its `t_s`, which closes the record.
    if let (true, Some(end), Some(&c)) = (history, last_sample, input.temp_c.last()) {
        input.t_s.push(end);
        input.temp_c.push(c);
        input.extremes.push(None);
        input.closing = true;
    }
    // In time order (a stable sort: the file's order among events of one second).
    input.events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    if last.is_some_and(|t| t > 16_000_000.0) {
        bail!("'{shown}': t_s beyond 16e6 s (185 days) is not supported");
    }
    // The record's clock counts from the first sample, or from 0 if that is earlier
    // ([`report`]): a first sample at t_s = −1e300 made a record of 1e300 s (1.8e16 s in range
    // once in the monitor's milliseconds), and `report` laid it out day by day until it ran
    // out of memory.
    if let (Some(&first), Some(&end)) = (input.t_s.first(), input.t_s.last()) {
        if end - first.min(0.0) > 16_000_000.0 {
            bail!(
                "'{shown}': the record runs from t_s = {} to {} s, more than 16e6 s (185 days), which is not supported",
                crate::sim_cmd::shown(first.min(0.0)),
                crate::sim_cmd::shown(end)
            );
        }
    }
    Ok(input)
}

/// How far, °C, an interval's mean may lie outside its extremes: the board writes all three
/// rounded to 0.01 °C, and its f32 mean of equal readings can differ from them by an ulp.
const MEAN_SLACK_C: f64 = 0.01;

/// The extremes of a history's interval row with mean `mean`: both or neither (an interval
/// with no reading), each a temperature a Pt100 can report, `min_c ≤ max_c`, the mean between
/// them.
fn extremes_of(lo: Option<f64>, hi: Option<f64>, mean: Option<f64>) -> Result<Option<(f64, f64)>> {
    let (lo, hi) = match (lo, hi) {
        (None, None) => return Ok(None),
        (Some(lo), Some(hi)) => (lo, hi),
        (Some(_), None) => bail!("'min_c' without 'max_c'"),
        (None, Some(_)) => bail!("'max_c' without 'min_c'"),
    };
    for (name, v) in [("min_c", lo), ("max_c", hi)] {
        if let Some(why) = log::outside_pt100(v) {
            bail!("column '{name}': {why}");
        }
    }
    if lo > hi {
        bail!("min_c {lo} °C is above max_c {hi} °C");
    }
    if let Some(m) = mean.filter(|&m| m < lo - MEAN_SLACK_C || m > hi + MEAN_SLACK_C) {
        bail!("the mean temp_c {m} °C lies outside its interval's min_c … max_c ({lo} … {hi} °C)");
    }
    Ok(Some((lo, hi)))
}

/// `hter monitor`.
pub fn run(args: &MonitorArgs) -> Result<()> {
    let shown = args.input.display();
    let input = read_input(&args.input)?;
    let r = record(&input).with_context(|| format!("'{shown}'"))?;
    if args.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    let hours = |s: f64| s / 3600.0;
    println!("cold-chain record of {shown} ({})", input.count_text());
    println!("  mean kinetic temperature  {:7.2} °C  (WHO: must lie within 2–8 °C)", r.mkt_c);
    println!("  min / max                 {:7.2} / {:.2} °C", r.min_c, r.max_c);
    println!("  time below +2 °C          {:7.2} h", hours(r.time_below_2_s));
    println!("  time above +8 °C          {:7.2} h", hours(r.time_above_8_s));
    println!("  time within 2–8 °C        {:7.2} h", hours(r.time_in_range_s));
    if r.fault_samples > 0 {
        let mut label = format!("no reading ({})", input.no_reading_cause(r.fault_samples).label());
        // A label wider than the column gets its own line: the figure stays under the others.
        if label.chars().count() > 25 {
            println!("  {label}");
            label.clear();
        }
        println!(
            "  {label:<25} {:7.2} h  ({}; counted neither in nor out of range)",
            hours(r.time_no_reading_s),
            input.no_reading_text(r.fault_samples)
        );
    }
    println!("  excursions outside 2–8 °C {:7}", r.excursions);
    if r.intervals_outside_2_8 > 0 {
        println!(
            "  intervals leaving 2–8 °C  {:7}  (their lowest or highest reading; the times above are the means')",
            r.intervals_outside_2_8
        );
    }
    if r.alarms.is_empty() && r.carrier_alarms.is_empty() {
        println!("  alarms                    none");
    }
    for a in &r.alarms {
        println!("  ALARM {:<14} started at {:.0} s, triggered at {:.0} s", a.kind, a.start_s, a.trigger_s);
    }
    for a in &r.carrier_alarms {
        println!(
            "  ALARM {:<14} started at {:.0} s, triggered at {:.0} s (recorded by the carrier; the means here do not show it)",
            a.kind, a.start_s, a.trigger_s
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// −1 °C every minute for 2 h, the sensor out for three samples from minute 30.
    #[test]
    fn a_gap_holds_an_alarm_run_without_counting_toward_it() {
        let t: Vec<f64> = (0..=120).map(|i| 60.0 * f64::from(i)).collect();
        let temp: Vec<Option<f64>> = (0..=120).map(|i| (!(30..33).contains(&i)).then_some(-1.0)).collect();
        let r = report(&t, &temp).unwrap();
        // 60 min of readings at or below −0.5 °C: reached at minute 63 on the log's clock, the
        // run started at 0 (the gap did not reset it).
        assert_eq!(r.alarms, vec![AlarmOut { kind: "freeze_60min", start_s: 0.0, trigger_s: 3780.0 }]);
        assert_eq!((r.fault_samples, r.time_no_reading_s), (3, 180.0));
        assert_eq!((r.time_below_2_s, r.time_in_range_s, r.time_above_8_s), (7200.0 - 180.0, 0.0, 0.0));
        assert_eq!(r.excursions, 1);
        // Without the gap the same run triggers at minute 60.
        let full = report(&t, &vec![Some(-1.0); t.len()]).unwrap();
        assert_eq!(full.alarms[0].trigger_s, 3600.0);
    }

    /// The board's own record (the library monitor fed NaN for a sample without a reading, as
    /// the firmware feeds it `StepOutput::recorded_c`) and `hter monitor` of the same log agree:
    /// the gap is cut out of both, an alarm's run goes on across it, and the alarm triggers when
    /// the time with a reading reaches its duration (on the record's clock, which the gap does
    /// not advance).
    #[test]
    fn the_boards_record_cuts_a_sensor_fault_as_hter_monitor_does() {
        // Minutes: 1 h at 5 °C, 6 h at 10 °C, 3 h without a reading, 5 h at 10 °C, 1 h at 5 °C.
        let c = |m: u32| match m {
            0..60 | 900.. => Some(5.0),
            420..600 => None,
            _ => Some(10.0),
        };
        let t: Vec<f64> = (0..=960).map(|m| 60.0 * f64::from(m)).collect();
        let temp: Vec<Option<f64>> = (0..=960).map(c).collect();
        let host = report(&t, &temp).unwrap();
        let mut board = ColdChainMonitor::new();
        let mut raised = Vec::new();
        for (&ts, c) in t.iter().zip(&temp) {
            let r = board.push((ts * 1000.0) as u64, c.map_or(f32::NAN, |c| c as f32));
            raised.extend(r.into_iter().flatten().map(|a| (a.kind.name(), a.start_ms, a.trigger_ms)));
        }
        let gap_s = 3.0 * 3600.0;
        assert_eq!(host.time_no_reading_s, gap_s);
        assert_eq!(f64::from(board.recorded_s()), 960.0 * 60.0 - gap_s);
        assert_eq!(f64::from(board.time_above_8_s()), host.time_above_8_s);
        assert_eq!(host.time_above_8_s, 11.0 * 3600.0);
        assert_eq!(f64::from(board.time_below_2_s()), host.time_below_2_s);
        assert!((f64::from(board.mkt_c().unwrap()) - host.mkt_c).abs() < 1e-3, "{:?} {}", board.mkt_c(), host.mkt_c);
        // heat_10h: 10 h above 8 °C with a reading, from minute 60: at minute 60 + 600 + 180
        // on the log, 3 h earlier on the record's clock.
        assert_eq!(host.alarms, vec![AlarmOut { kind: "heat_10h", start_s: 3600.0, trigger_s: 840.0 * 60.0 }]);
        assert_eq!(raised, vec![("heat_10h", 3_600_000, (840 * 60 * 1000) - 3 * 3_600_000)]);
    }

    #[test]
    fn fault_samples_count_neither_in_nor_out_of_range() {
        // Faults first (no reading yet), a warm spell, a fault in the middle, the last sample a
        // fault (no interval after it).
        let t = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0];
        let temp = [None, None, Some(5.0), Some(9.0), None, Some(9.0), Some(5.0), None];
        let r = report(&t, &temp).unwrap();
        assert_eq!((r.fault_samples, r.time_no_reading_s), (4, 30.0));
        assert_eq!((r.time_above_8_s, r.time_in_range_s, r.time_below_2_s), (20.0, 20.0, 0.0));
        assert_eq!((r.min_c, r.max_c, r.excursions), (5.0, 9.0, 1));
        let e = report(&[0.0, 10.0, 20.0], &[None, Some(4.0), None]).unwrap_err();
        assert!(e.to_string().contains("2 samples with a temperature, it has 1"), "{e}");
    }

    /// The library monitor's clock counts milliseconds: a sample 0.4 ms after the one before
    /// would be dropped (a −3 °C reading vanished, and two samples 0.4 ms apart gave a NaN MKT).
    #[test]
    fn samples_on_the_same_millisecond_are_refused() {
        let e = report(&[0.0, 10.0, 10.0004, 20.0], &[Some(4.0), Some(4.0), Some(-3.0), Some(4.0)]).unwrap_err();
        assert!(e.to_string().contains("t_s = 10.0004 falls on the same millisecond as the sample at t_s = 10"), "{e}");
        assert!(report(&[0.0, 0.0004], &[Some(4.0), Some(9.0)]).is_err());
        // 1 ms apart is two samples.
        let r = report(&[0.0, 10.0, 10.001, 20.0], &[Some(4.0), Some(4.0), Some(-3.0), Some(4.0)]).unwrap();
        assert_eq!((r.min_c, r.excursions), (-3.0, 1));
    }

    /// A board history with a hole: 5.00 °C rows every 300 s to 3 600 s, then
    /// `log_entries_lost:72` at 25 200 s (the 72 oldest waiting entries, 6 h of rows, dropped
    /// while the write gate was held), then rows again from 25 500 s to 30 000 s. The 6 h were
    /// not measured in the file: like a sensor fault's rows, they are no reading. By hand, each
    /// row covering the interval that ends at its `t_s`: the rows to 3 600 s cover 0 … 3 600 s;
    /// from there to the start of the next row's interval, 25 200 s, there is no reading,
    /// 21 600 s; in range 3 600 + 30 000 − 25 200 = 8 400 s. Before, the 5.00 °C row held
    /// across the hole: 29 700 s in range, none unread, and `hter report` said "IN RANGE — the
    /// load stayed within 2–8 °C for the whole period".
    #[test]
    fn lost_log_entries_are_no_reading() {
        let mut csv = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
        let row = |t: u32| format!("{t},5.00,4.90,5.10,0.400,normal,\n");
        (300..=3600).step_by(300).for_each(|t| csv.push_str(&row(t)));
        csv.push_str("25200,,,,,,log_entries_lost:72\n");
        (25_500..=30_000).step_by(300).for_each(|t| csv.push_str(&row(t)));
        let p = std::env::temp_dir().join(format!("hter-monitor-{}-hole.csv", std::process::id()));
        std::fs::write(&p, csv).unwrap();
        let input = read_input(&p).unwrap();
        std::fs::remove_file(&p).unwrap();
        let r = record(&input).unwrap();
        assert_eq!((r.time_no_reading_s, r.time_in_range_s, r.fault_samples), (21_600.0, 8_400.0, 1));
        // The record lost them, not the probe: said as such.
        assert_eq!(input.no_reading_cause(r.fault_samples).label(), "lost log entries");
        let (class, line) = crate::report_cmd::verdict(&r, input.holes);
        assert_eq!(class, "unknown");
        assert!(line.contains("part of the record was lost") && !line.contains("probe"), "{line}");
    }

    fn read_history(name: &str, csv: &str) -> Input {
        let p = std::env::temp_dir().join(format!("hter-monitor-{}-{name}.csv", std::process::id()));
        std::fs::write(&p, csv).unwrap();
        let input = read_input(&p);
        std::fs::remove_file(&p).unwrap();
        input.unwrap()
    }

    /// A board history's row summarises the interval that ends at its `t_s`
    /// (`hter::persist::log::IntervalLog`, docs/interface.md). Rows at 300 and 600 s at 4 °C,
    /// thirteen at −1 °C (900 … 4 500 s), the carrier's freeze alarm (its first cold sample at
    /// 610 s, raised at 4 210 s) and a brown-out restart, then 9 °C at 4 800 s and 4 °C at 5 100
    /// and 5 400 s. By hand, each row covering (t_s − 300, t_s]: the record runs 0 … 5 400 s;
    /// below 2 °C 600 … 4 500 s = 3 900 s; above 8 °C 4 500 … 4 800 s = 300 s; in range 600 +
    /// 600 = 1 200 s. `freeze_60min` starts at 600 s (the first cold interval's start) and
    /// triggers at 4 200 s, when the cold intervals have lasted 60 min (the start of the 13th,
    /// still cold: SPEC §6's rule on the intervals' starts), 10 s before the carrier's own, so
    /// the two are one alarm. Read as samples at their `t_s` (before), the run started at 900 s
    /// and triggered at 4 500 s, the record began at 300 s, and 300 s in range were lost at each
    /// end.
    #[test]
    fn a_history_row_covers_the_interval_that_ends_at_its_time() {
        let mut csv = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
        let row = |t: u32, c: f64| format!("{t},{c:.2},{:.2},{:.2},0.40,normal,\n", c - 0.2, c + 0.2);
        csv += &row(300, 4.0);
        csv += &row(600, 4.0);
        (900..=4200).step_by(300).for_each(|t| csv += &row(t, -1.0));
        csv += "4210,,,,,,alarm:freeze_60min@610\n";
        csv += &row(4500, -1.0);
        csv += "4600,,,,,,restarted:brownout\n";
        csv += &row(4800, 9.0);
        csv += &row(5100, 4.0);
        csv += &row(5400, 4.0);
        let input = read_history("interval-end", &csv);
        assert_eq!(input.samples(), 18);
        assert_eq!((input.t_s.first(), input.t_s.last()), (Some(&0.0), Some(&5400.0)), "the period covered");
        let r = record(&input).unwrap();
        assert_eq!((r.time_below_2_s, r.time_above_8_s, r.time_in_range_s), (3900.0, 300.0, 1200.0), "{r:?}");
        assert_eq!(r.alarms, [AlarmOut { kind: "freeze_60min", start_s: 600.0, trigger_s: 4200.0 }]);
        assert_eq!(r.carrier_alarms, []);
        assert_eq!((r.min_c, r.max_c, r.intervals_outside_2_8, r.fault_samples), (-1.2, 9.2, 14, 0));
        // The events keep their own times.
        assert_eq!(input.events[1], Event { t_s: 4600.0, name: "restarted:brownout".into() });

        // The last row a sensor fault: its interval is no reading, and one fault sample.
        let fault = csv.replace("5400,4.00,3.80,4.20,0.40,normal,", "5400,4.00,3.80,4.20,0.40,sensor_fault,");
        let r = record(&read_history("interval-end-fault", &fault)).unwrap();
        assert_eq!((r.time_no_reading_s, r.fault_samples, r.time_in_range_s), (300.0, 1, 900.0));

        // A log of samples (no interval columns) keeps its meaning: a sample holds to the next.
        let samples = read_history("samples", "t_s,temp_c\n300,4\n600,9\n900,4\n");
        assert_eq!((samples.t_s, samples.closing), (vec![300.0, 600.0, 900.0], false));
    }

    #[test]
    fn an_intervals_extremes_must_hold_its_mean() {
        assert_eq!(extremes_of(None, None, Some(4.0)).unwrap(), None);
        assert_eq!(extremes_of(Some(3.9), Some(4.1), Some(4.0)).unwrap(), Some((3.9, 4.1)));
        // The board rounds all three to 0.01 °C.
        assert!(extremes_of(Some(4.0), Some(4.0), Some(3.99)).is_ok());
        let err = |lo, hi, m| extremes_of(lo, hi, m).unwrap_err().to_string();
        assert!(err(Some(4.0), Some(4.0), Some(3.98)).contains("outside its interval's min_c … max_c"));
        assert!(err(Some(4.2), Some(4.1), Some(4.15)).contains("min_c 4.2 °C is above max_c 4.1 °C"));
        assert!(err(Some(3.9), None, Some(4.0)).contains("'min_c' without 'max_c'"));
        assert!(err(Some(-300.0), Some(4.1), Some(4.0)).contains("Pt100"));
    }

    #[test]
    fn the_carriers_alarm_events_that_the_means_do_not_show_are_its_own() {
        let e = |t_s: f64, name: &str| Event { t_s, name: name.into() };
        let events = [
            e(28_800.0, "alarm:freeze_60min@25200"),
            e(40_000.0, "alarm:heat_10h"),
            e(50_000.0, "alarm:dancing@1"),
            e(60_000.0, "set:setpoint_c=4.00"),
        ];
        let a = carrier_alarms(&events).unwrap();
        assert_eq!(
            a,
            [
                AlarmOut { kind: "freeze_60min", start_s: 25_200.0, trigger_s: 28_800.0 },
                AlarmOut { kind: "heat_10h", start_s: 40_000.0, trigger_s: 40_000.0 },
            ]
        );
        // Recomputed from the means an interval later: the same alarm; hours later: another.
        let means = AlarmOut { kind: "heat_10h", start_s: 4_300.0, trigger_s: 40_300.0 };
        assert!(same_alarm(&means, &a[1]));
        assert!(!same_alarm(&AlarmOut { trigger_s: 47_200.0, ..means.clone() }, &a[1]));
        assert!(!same_alarm(&AlarmOut { kind: "freeze_60min", ..means }, &a[1]));
    }

    #[test]
    fn an_alarm_event_whose_start_is_no_record_second_is_refused() {
        for start in ["-1e300", "nan", "inf", "-5", "700.5", "soon"] {
            let events = [Event { t_s: 700.0, name: format!("alarm:heat_10h@{start}") }];
            let e = carrier_alarms(&events).unwrap_err().to_string();
            assert!(e.contains(&format!("its start '{start}' is not a record second in 0…700")), "{e}");
        }
        let ok = [Event { t_s: 700.0, name: "alarm:heat_10h@0".into() }];
        assert_eq!(carrier_alarms(&ok).unwrap()[0].start_s, 0.0);
    }
}
