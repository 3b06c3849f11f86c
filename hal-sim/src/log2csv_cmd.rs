//! `hter log2csv`: turns the firmware's defmt telemetry (as printed by probe-rs or defmt-print)
//! into the CSV that `hter identify` and `hter monitor` read.
//!
//! The firmware prints one line per sample, `t=… temp=… sp=… duty=… mode=… counts=… supply=…
//! alarm=…` (the `interface` build adds `rail=…` and `holdover=…`), possibly behind a timestamp,
//! a level and a location; a `t_ms=` field (a millisecond clock) is preferred over `t=` when both
//! are there. `counts` (the RTD conversion), `supply` (V, NaN when not measured), `alarm` (the
//! indicator's state) and `holdover` (the step's holdover estimate, s, NaN when it has none:
//! [`hter::holdover`]; the column `holdover_s`, as in `hter sim --csv`) are kept when present;
//! logs of older firmware, or of a build without the field, leave those cells empty.
//!
//! The firmware prints the step's mode and the alarm indicator as their variant names
//! (`mode=LimpHome alarm=OutOfRange`, defmt's `{}` of the enum); the CSV carries the library's
//! names instead ([`Mode::name`], [`Indication::name`]: `limp_home`, `out_of_range`), as
//! `hter sim --csv` does, so a simulated and a logged trace spell every mode the same way. A
//! word that is neither spelling of a known value is an error naming the line.
//!
//! Field logs are not clean, and one bad sample must not cost the whole record:
//! - a sample whose temperature is not finite (`temp=NaN`: a sensor fault before the first
//!   good reading, when the filter has nothing to hold) is kept as a *fault row*: `temp_c`
//!   empty, every other cell (the mode, e.g. `sensor_fault`) as for any sample;
//! - a log that spans resets is split into *boots*. A boot starts at the firmware's
//!   boot line (`hter firmware …: reset cause Watchdog|BrownOut|Other; …`; earlier firmware
//!   printed `reset cause: …` on a line of its own), or, when that line was lost, where `t` stops
//!   increasing. The board's clock restarts at 0 on every boot and the log has no wall clock,
//!   so the length of the reset gap is unknown: each later boot's `t = 0` is placed one sample
//!   period after the previous boot's last sample (the period from the boot line
//!   `Ts = … s`, else the median sample interval of the log), and the command says so. When a
//!   boot's first `t` is later than the previous boot's last one (a clock that survived the
//!   reset), the times are kept as they are.
//!
//! The CSV's `boot` column numbers the boots from 0; `reset_cause` is filled on the first row
//! of each boot with the library's event name: `restarted_watchdog`, `restarted_brownout`,
//! `restarted`, or `board_fault_panic` (…`_hard_fault`, `_nmi`, `_unexpected_interrupt`,
//! `_control_stall`) when the boot reported a fail-safe stop (`board fault: Panic pc=…`);
//! `unknown` for a boot found only by its time going back; empty on the first boot when the
//! log began while the board was already running. `events` holds the step's events (`event
//! t=… SsrStuckOn` lines, which the firmware logs after the sample's telemetry line) on the
//! sample they came with, by their library names (`ssr_stuck_on`), `;`-separated: what `hter
//! report` lists with the resets and faults.

use std::io::BufRead;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use hter::alarm::Indication;
use hter::event::EventKind;
use hter::failsafe::StopKind;
use hter::persist::ResetCause;
use hter::rtd::{T_MAX_C, T_MIN_C};
use hter::step::Mode;

/// Arguments of `hter log2csv`.
#[derive(clap::Args, Debug, Clone)]
pub struct Log2CsvArgs {
    /// The saved log (e.g. `cargo fw-run | tee carrier.log`).
    #[arg(long)]
    pub input: PathBuf,
    /// Where to write the CSV (columns t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm,
    /// boot,reset_cause,holdover_s,events).
    #[arg(long)]
    pub output: PathBuf,
}

/// The CSV header `hter log2csv` writes.
pub const HEADER: &str = "t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm,boot,reset_cause,holdover_s,events";

/// One telemetry sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Time since the boot, s (from `t_ms=` when present, else `t=`).
    pub t_s: f64,
    /// Setpoint, °C.
    pub setpoint_c: f64,
    /// Filtered temperature, °C; `None` when the firmware printed a non-finite one (a sensor
    /// fault with no earlier good reading).
    pub temp_c: Option<f64>,
    /// Duty applied.
    pub duty: f64,
    /// Safety mode (`None`: the line had no `mode=`).
    pub mode: Option<Mode>,
    /// RTD conversion, counts (newer firmware).
    pub counts: Option<u32>,
    /// The modules' supply, V (newer firmware; `None` also when the board could not measure it).
    pub supply_v: Option<f64>,
    /// The alarm indicator's state (newer firmware).
    pub alarm: Option<Indication>,
    /// The step's holdover estimate, s (the `interface` build; `None` also when the step had
    /// none: the firmware prints NaN).
    pub holdover_s: Option<f64>,
}

/// One row of the CSV: a sample on the log's continuous time axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The sample, its `t_s` moved onto the continuous axis.
    pub sample: Sample,
    /// Boot number, from 0.
    pub boot: u32,
    /// Why this boot started (first row of a boot only; see the module doc).
    pub reset_cause: Option<String>,
    /// The step's events the firmware logged with this sample (`event t=… SsrStuckOn` lines after
    /// its telemetry line), by their library names (`ssr_stuck_on`); the restart and the
    /// fail-safe stop are the boot's `reset_cause`.
    pub events: Vec<&'static str>,
}

/// Where the sample period used to join boots came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PeriodSource {
    /// The firmware's boot line `Ts = … s`.
    BootLine,
    /// The median interval between samples of one boot.
    Median,
}

/// A converted log.
#[derive(Clone, Debug)]
pub struct Converted {
    /// Every sample, in log order.
    pub rows: Vec<Row>,
    /// Boots joined by placing their `t = 0` one sample period after the previous boot's last
    /// sample (the gap's real length is unknown), and the period used, s.
    pub joined: Option<(u32, f64, PeriodSource)>,
    /// Boot lines that were not understood (recorded as [`UNKNOWN_CAUSE`]), one sentence each.
    pub warnings: Vec<String>,
}

fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let start = line.split_whitespace().find_map(|w| w.strip_prefix(key))?;
    Some(start.trim_end_matches(','))
}

/// The word after `marker` in `line`, if the line has the marker.
fn word_after<'a>(line: &'a str, marker: &str) -> Option<&'a str> {
    let at = line.find(marker)? + marker.len();
    Some(line.get(at..)?.split_whitespace().next().unwrap_or(""))
}

/// The value `word` names, in the firmware's spelling (the variant name, as `{:?}` prints it
/// on the host and defmt's `{}` on the board) or the library's (`name`).
fn named<T: Copy + std::fmt::Debug>(all: &[T], name: fn(T) -> &'static str, word: &str) -> Option<T> {
    all.iter().copied().find(|v| format!("{v:?}") == word || name(*v) == word)
}

/// The value of a `mode=`/`alarm=` field, if the line has one.
fn named_field<T: Copy + std::fmt::Debug>(
    line: &str,
    key: &str,
    all: &[T],
    name: fn(T) -> &'static str,
) -> Result<Option<T>> {
    let Some(word) = field(line, key) else { return Ok(None) };
    named(all, name, word).map(Some).ok_or_else(|| {
        let known: Vec<String> = all.iter().map(|v| format!("{v:?}")).collect();
        anyhow!("{} '{word}' is none of {}", key.trim_end_matches('='), known.join(", "))
    })
}

/// The event name of a line with the reset cause (the defmt of [`ResetCause`]): the firmware's
/// boot line `hter firmware …: reset cause BrownOut; watchdog …; Ts = 10 s, …`, or the
/// `reset cause: BrownOut` line of earlier firmware; `Err` with the word when it names no
/// known cause.
fn reset_line(line: &str) -> Option<Result<&'static str, String>> {
    let word =
        word_after(line, "reset cause:").or_else(|| word_after(line, "reset cause"))?.trim_end_matches([';', ',']);
    let cause =
        [ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other].into_iter().find(|c| format!("{c:?}") == word);
    Some(cause.map(|c| EventKind::Restarted(c).name()).ok_or_else(|| word.to_string()))
}

/// The event name of a `board fault: Panic pc=…` line (the defmt of the stop's record); `Err`
/// with the word when it names no known stop.
fn fault_line(line: &str) -> Option<Result<&'static str, String>> {
    let word = word_after(line, "board fault:")?;
    let kind = StopKind::ALL.into_iter().find(|k| format!("{k:?}") == word);
    Some(kind.map(|k| EventKind::BoardFault(k).name()).ok_or_else(|| word.to_string()))
}

/// The step's event of an `event t=… SsrStuckOn` line (the defmt of [`EventKind`]): its time
/// since the boot, s (`None` if unreadable), and its library name; `Err` with the word when it
/// names no event. `None` for another line, and for the restart and the fail-safe stop, which
/// the boot's `reset_cause` already carries.
fn event_line(line: &str) -> Option<(Option<f64>, Result<&'static str, String>)> {
    let rest = line.get(line.find("event t=")? + "event t=".len()..)?;
    let mut words = rest.split_whitespace();
    let t = words.next()?.parse::<f64>().ok().filter(|t| t.is_finite());
    let word = words.next().unwrap_or("");
    if word.starts_with("Restarted") || word.starts_with("BoardFault") {
        return None;
    }
    let kind = named(&EventKind::ALL, EventKind::name, word);
    Some((t, kind.map(EventKind::name).ok_or_else(|| word.to_string())))
}

/// The cause recorded for a boot whose reset line was lost or not understood.
pub const UNKNOWN_CAUSE: &str = "unknown";

/// The sample period of the firmware's boot line (`hter firmware …: Ts = 10 s, …`), s.
fn period_line(line: &str) -> Option<f64> {
    word_after(line, "Ts = ")?.parse::<f64>().ok().filter(|ts| ts.is_finite() && *ts > 0.0 && *ts <= MAX_CLOCK_S)
}

/// The largest time the board's clock can show, s: a monotonic 64-bit millisecond counter
/// (SPEC §7). A `t=` beyond it is not a board's: `t=1e303` became `inf` once rounded to the
/// microsecond, and the CSV carried it.
pub const MAX_CLOCK_S: f64 = u64::MAX as f64 / 1000.0;

/// The keys of a telemetry line; each at most once.
const KEYS: [&str; 10] = ["t_ms=", "t=", "temp=", "sp=", "duty=", "counts=", "supply=", "holdover=", "mode=", "alarm="];

/// Parses one telemetry line; `None` for any other line.
pub fn parse_line(line: &str) -> Option<Result<Sample>> {
    let (temp, sp, duty) = (field(line, "temp=")?, field(line, "sp=")?, field(line, "duty=")?);
    let t_ms = field(line, "t_ms=");
    let t = field(line, "t=");
    if t_ms.is_none() && t.is_none() {
        return None;
    }
    let counts = field(line, "counts=");
    let supply = field(line, "supply=");
    let holdover = field(line, "holdover=");
    let any =
        |name: &str, v: &str| -> Result<f64> { v.parse().with_context(|| format!("{name} '{v}' is not a number")) };
    let num = |name: &str, v: &str| -> Result<f64> {
        let x = any(name, v)?;
        if x.is_finite() {
            Ok(x)
        } else {
            bail!("{name} is not finite")
        }
    };
    Some((|| {
        for key in KEYS {
            if line.split_whitespace().filter(|w| w.starts_with(key)).count() > 1 {
                bail!("'{}' appears twice", key.trim_end_matches('='));
            }
        }
        // A temperature the firmware printed: a number a Pt100 can report, or NaN / inf for no
        // reading; a number too long for an f64 is a corrupt line, not a fault.
        let temp_c = match any("temp", temp)? {
            c if c.is_finite() => {
                if let Some(why) = crate::log::outside_pt100(c) {
                    bail!("temp = {why}");
                }
                Some(c)
            }
            c if c.is_infinite() && !temp.trim_start_matches(['+', '-']).to_ascii_lowercase().starts_with("inf") => {
                bail!("temp '{}' is too large a number", crate::log::clip(temp))
            }
            _ => None,
        };
        let duty = num("duty", duty)?;
        if !(0.0..=1.0).contains(&duty) {
            bail!("duty = {} is outside 0…1", crate::sim_cmd::shown(duty));
        }
        let setpoint_c = num("sp", sp)?;
        if !(f64::from(T_MIN_C)..=f64::from(T_MAX_C)).contains(&setpoint_c) {
            bail!("sp = {} °C is not a temperature a carrier can be set to", crate::sim_cmd::shown(setpoint_c));
        }
        let t_s = match (t_ms, t) {
            (Some(ms), _) => {
                ms.parse::<u64>().with_context(|| format!("t_ms '{ms}' is not a whole number of milliseconds"))? as f64
                    / 1000.0
            }
            (None, Some(t)) => num("t", t)?,
            (None, None) => bail!("no time"),
        };
        if t_s > MAX_CLOCK_S {
            let t = crate::sim_cmd::shown(t_s);
            bail!("t = {t} s is beyond the board's 64-bit millisecond clock (at most {MAX_CLOCK_S:e} s)");
        }
        // The board's clock counts from 0 at its boot: `t=-1e300` was written to the CSV as
        // 301 digits, and `monitor` then counted 1.8e16 s in range.
        if t_s < 0.0 {
            let t = crate::sim_cmd::shown(t_s);
            bail!("t = {t} s is before the board's clock starts (0 s at its boot)");
        }
        Ok(Sample {
            mode: named_field(line, "mode=", &Mode::ALL, Mode::name)?,
            alarm: named_field(line, "alarm=", &Indication::ALL, Indication::name)?,
            t_s,
            // NaN or inf: no reading (the firmware holds the last good value once it has one).
            temp_c,
            setpoint_c,
            duty,
            counts: counts
                .map(|c| c.parse::<u32>().with_context(|| format!("counts '{c}' is not a whole number")))
                .transpose()?,
            // NaN is how the firmware says "not measured".
            supply_v: supply.map(|v| measured("supply", v, "V")).transpose()?.flatten(),
            // NaN: no estimate (no model, or none finished yet).
            holdover_s: holdover.map(|v| measured("holdover", v, "s")).transpose()?.flatten(),
        })
    })())
}

/// A measurement the firmware prints as a number ≥ 0, or NaN for none (`None`). Anything else is
/// a corrupt line: `supply=1e400` (inf once parsed) was read as "not measured", and a negative
/// voltage or holdover went into the CSV as if the board had measured it.
fn measured(name: &str, v: &str, unit: &str) -> Result<Option<f64>> {
    let x: f64 = v.parse().with_context(|| format!("{name} '{}' is not a number", crate::log::clip(v)))?;
    if x.is_nan() {
        return Ok(None);
    }
    if !(x.is_finite() && x >= 0.0) {
        bail!("{name} = {} {unit} is not what the board prints (a number ≥ 0, or NaN for none)", crate::log::clip(v));
    }
    Ok(Some(x))
}

/// Median of the positive intervals between consecutive samples of one boot (times since the
/// boot, before the boots are joined), s.
fn median_interval(rows: &[Row]) -> Option<f64> {
    let mut d: Vec<f64> = rows
        .windows(2)
        .filter(|w| w[0].boot == w[1].boot)
        .map(|w| w[1].sample.t_s - w[0].sample.t_s)
        .filter(|d| *d > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied()
}

/// A time rounded to the microsecond, so that a shifted `12.345` prints as `122.345`, not as
/// the sum's binary neighbour (the firmware's clocks resolve 1 ms at best).
fn micros(t: f64) -> f64 {
    (t * 1e6).round() / 1e6
}

/// Converts a whole log (its lines, in order); errors name the 1-based line.
pub fn convert<I: IntoIterator<Item = std::io::Result<String>>>(lines: I) -> Result<Converted> {
    // Each row's `t_s` is its time since its boot until the boots are joined below.
    let mut rows: Vec<Row> = Vec::new();
    // Each boot after the first: its first row, and whether its clock went on from the last.
    let mut starts: Vec<(usize, bool)> = Vec::new();
    let mut boot_period: Option<f64> = None;
    let mut pending_reset: Option<&'static str> = None;
    let mut pending_fault: Option<&'static str> = None;
    let mut pending_events: Vec<&'static str> = Vec::new();
    let mut warnings: Vec<String> = Vec::new();
    let understood = |warnings: &mut Vec<String>, found: Result<&'static str, String>, what: &str, n: usize| {
        found.unwrap_or_else(|word| {
            warnings.push(format!("line {n}: unknown {what} '{word}', recorded as '{UNKNOWN_CAUSE}'"));
            UNKNOWN_CAUSE
        })
    };
    for (i, line) in lines.into_iter().enumerate() {
        let n = i + 1;
        let line = line.with_context(|| format!("line {n}: not text"))?;
        // A fail-safe stop's text is anything, "reset cause" included: its line first.
        if let Some(kind) = fault_line(&line) {
            pending_fault = Some(understood(&mut warnings, kind, "board fault", n));
            continue;
        }
        if let Some(cause) = reset_line(&line) {
            pending_reset = Some(understood(&mut warnings, cause, "reset cause", n));
            // The firmware's one boot line carries the sample period too.
            if let Some(ts) = period_line(&line) {
                boot_period.get_or_insert(ts);
            }
            continue;
        }
        if let Some(ts) = period_line(&line) {
            boot_period.get_or_insert(ts);
            continue;
        }
        if let Some((t, found)) = event_line(&line) {
            match found {
                // The firmware logs a sample's events after its telemetry line: with the last
                // sample of its boot at or after the event's time, else with the next sample.
                Ok(name) => match rows.last_mut().filter(|r| {
                    pending_reset.is_none() && pending_fault.is_none() && t.is_none_or(|t| t <= r.sample.t_s)
                }) {
                    Some(r) => r.events.push(name),
                    None => pending_events.push(name),
                },
                Err(word) => warnings.push(format!("line {n}: unknown event '{word}', left out")),
            }
            continue;
        }
        let Some(s) = parse_line(&line) else { continue };
        let s = s.with_context(|| format!("line {n}"))?;
        let prev = rows.last().map(|r| (r.sample.t_s, r.boot));
        let backwards = prev.is_some_and(|(t, _)| s.t_s <= t);
        let new_boot = prev.is_some() && (pending_reset.is_some() || backwards);
        let boot = prev.map_or(0, |(_, b)| b + u32::from(new_boot));
        let cause = if new_boot {
            starts.push((rows.len(), !backwards));
            Some(pending_fault.or(pending_reset).unwrap_or(UNKNOWN_CAUSE))
        } else if prev.is_none() {
            pending_fault.or(pending_reset)
        } else {
            // A fail-safe report after the boot's first sample still belongs to that boot.
            if let Some(kind) = pending_fault {
                let first = starts.last().map_or(0, |&(r, _)| r);
                if let Some(r) = rows.get_mut(first) {
                    r.reset_cause = Some(kind.to_string());
                }
            }
            None
        };
        pending_reset = None;
        pending_fault = None;
        rows.push(Row {
            sample: s,
            boot,
            reset_cause: cause.map(str::to_string),
            events: std::mem::take(&mut pending_events),
        });
    }
    if rows.is_empty() {
        bail!("no telemetry lines (t=… temp=… sp=… duty=…)");
    }
    let period = boot_period
        .map(|ts| (ts, PeriodSource::BootLine))
        .or_else(|| median_interval(&rows).map(|ts| (ts, PeriodSource::Median)));
    let mut joined = 0;
    let mut offset = 0.0;
    let mut last_out = 0.0;
    let mut next_start = starts.iter().peekable();
    for (i, r) in rows.iter_mut().enumerate() {
        let t = r.sample.t_s;
        if let Some(&&(_, clock_went_on)) = next_start.peek().filter(|(first, _)| *first == i) {
            next_start.next();
            if !clock_went_on {
                let (ts, _) = period.ok_or_else(|| {
                    anyhow!(
                        "{} boots but no sample period to join them: no 'Ts = … s' boot line and no boot with two \
                         samples",
                        starts.len() + 1
                    )
                })?;
                offset = last_out + ts;
                joined += 1;
            }
        }
        r.sample.t_s = micros(t + offset);
        last_out = r.sample.t_s;
    }
    let joined = period.filter(|_| joined > 0).map(|(ts, src)| (joined, ts, src));
    Ok(Converted { rows, joined, warnings })
}

/// The CSV text of converted rows, with [`HEADER`].
pub fn csv_text(rows: &[Row]) -> String {
    let mut text = format!("{HEADER}\n");
    let opt = |v: Option<String>| v.unwrap_or_default();
    for r in rows {
        let s = &r.sample;
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{}\n",
            s.t_s,
            s.setpoint_c,
            opt(s.temp_c.map(|c| c.to_string())),
            s.duty,
            s.mode.map_or("", Mode::name),
            opt(s.counts.map(|c| c.to_string())),
            opt(s.supply_v.map(|v| v.to_string())),
            s.alarm.map_or("", Indication::name),
            r.boot,
            r.reset_cause.as_deref().unwrap_or(""),
            opt(s.holdover_s.map(|v| v.to_string())),
            r.events.join(";"),
        ));
    }
    text
}

/// `hter log2csv`.
pub fn run(args: &Log2CsvArgs) -> Result<()> {
    // `--output carrier.log` replaced the log with its CSV.
    crate::sim_cmd::check_paths(&[("--input", &args.input)], &[("--output", &args.output)])?;
    let shown = args.input.display();
    // Opened, a directory failed only at the first read, as "line 1: not text: Is a directory".
    if args.input.is_dir() {
        bail!("cannot read '{shown}': it is a directory");
    }
    let f = std::fs::File::open(&args.input).with_context(|| format!("cannot read '{shown}'"))?;
    let c = convert(std::io::BufReader::new(f).lines()).with_context(|| format!("'{shown}'"))?;
    crate::output::write(&args.output, csv_text(&c.rows).as_bytes())?;
    for w in &c.warnings {
        eprintln!("warning: '{shown}' {w}");
    }
    let faults = c.rows.iter().filter(|r| r.sample.temp_c.is_none()).count();
    let boots = c.rows.last().map_or(0, |r| r.boot + 1);
    eprintln!(
        "{} samples ({faults} with no temperature: sensor fault) from {boots} boot(s) written to {}",
        c.rows.len(),
        args.output.display()
    );
    if let Some((n, ts, src)) = c.joined {
        let from = match src {
            PeriodSource::BootLine => "the boot line",
            PeriodSource::Median => "the median sample interval",
        };
        eprintln!(
            "the log has no wall clock: {n} reset gap(s) of unknown length; each boot's t = 0 is placed one sample \
             period ({ts} s, from {from}) after the previous boot's last sample"
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(text: &str) -> Vec<std::io::Result<String>> {
        text.lines().map(|l| Ok(l.to_string())).collect()
    }

    #[test]
    fn parses_probe_rs_lines_and_skips_others() {
        let l = "12.345678 INFO  t=10 temp=4.0123 sp=4 duty=0.456 mode=Normal\n└─ firmware::__telemetry_task @ src/main.rs:160";
        let s = parse_line(l.lines().next().unwrap()).unwrap().unwrap();
        assert_eq!(
            s,
            Sample {
                t_s: 10.0,
                setpoint_c: 4.0,
                temp_c: Some(4.0123),
                duty: 0.456,
                mode: Some(Mode::Normal),
                counts: None,
                supply_v: None,
                alarm: None,
                holdover_s: None,
            }
        );
        // Today's firmware line: the conversion, the supply (NaN: not measured) and the alarm.
        let l = "0.000 INFO  t=20 temp=4.01 sp=4 duty=0.45 mode=Normal counts=49918 supply=12.04 alarm=Off";
        let s = parse_line(l).unwrap().unwrap();
        assert_eq!((s.counts, s.supply_v, s.alarm), (Some(49_918), Some(12.04), Some(Indication::Off)));
        let l = "t=30 temp=4.01 sp=4 duty=0.45 mode=Normal counts=49920 supply=NaN alarm=OutOfRange";
        assert_eq!(parse_line(l).unwrap().unwrap().supply_v, None);
        let bad = parse_line("t=30 temp=4.01 sp=4 duty=0.45 mode=Normal counts=4.5 supply=12 alarm=Off").unwrap();
        assert!(bad.unwrap_err().to_string().contains("counts"));
        assert!(parse_line("WARN  event t=10 SensorOpen").is_none());
        assert!(parse_line("INFO  hter firmware 0.1.0: Ts = 10 s").is_none());
        assert!(parse_line("INFO  est t=10 ctl=Adaptive theta=[-1.7] trace_p=0.8 pe=0.1").is_none());
        let bad = parse_line("INFO t=10 temp=warm sp=4 duty=0.5 mode=Normal").unwrap();
        assert!(bad.unwrap_err().to_string().contains("temp"));
        let bad = parse_line("INFO t=NaN temp=4 sp=4 duty=0.5 mode=Normal").unwrap();
        assert!(bad.unwrap_err().to_string().contains("t is not finite"));
    }

    #[test]
    fn the_interface_builds_holdover_is_a_number_or_empty() {
        // The interface build's line (firmware/src/main.rs, `telemetry`).
        let l = "1.0 INFO  t=30 temp=4.01 sp=4 duty=0.45 mode=Normal counts=49920 supply=12.01 rail=11.9 \
                 alarm=Off holdover=412.5";
        let s = parse_line(l).unwrap().unwrap();
        assert_eq!((s.supply_v, s.holdover_s), (Some(12.01), Some(412.5)));
        // NaN: the step has no estimate yet.
        let nan = l.replace("holdover=412.5", "holdover=NaN");
        assert_eq!(parse_line(&nan).unwrap().unwrap().holdover_s, None);
        let bad = parse_line(&l.replace("holdover=412.5", "holdover=long")).unwrap();
        assert!(bad.unwrap_err().to_string().contains("holdover 'long' is not a number"));
        // In the CSV: its column, empty without an estimate.
        let c = convert(lines(&format!("{l}\n{}", nan.replace("t=30 ", "t=40 ")))).unwrap();
        let text = csv_text(&c.rows);
        let cells: Vec<Vec<&str>> = text.lines().map(|r| r.split(',').collect()).collect();
        let col = cells[0].iter().position(|h| *h == "holdover_s").unwrap();
        assert_eq!((cells[1][col], cells[2][col]), ("412.5", ""));
    }

    #[test]
    fn modes_and_alarms_take_the_library_names() {
        let line =
            |mode: &str, alarm: &str| format!("t=0 temp=4 sp=4 duty=0 mode={mode} counts=1 supply=12 alarm={alarm}");
        for (m, i) in Mode::ALL.into_iter().zip(Indication::ALL.into_iter().cycle()) {
            // The firmware's spelling and the library's both read as the value.
            for (mw, iw) in [(format!("{m:?}"), format!("{i:?}")), (m.name().to_string(), i.name().to_string())] {
                let s = parse_line(&line(&mw, &iw)).unwrap().unwrap();
                assert_eq!((s.mode, s.alarm), (Some(m), Some(i)), "{mw} {iw}");
            }
        }
        let c = convert(lines(&line("LimpHome", "OutOfRange"))).unwrap();
        assert_eq!(csv_text(&c.rows).lines().nth(1), Some("0,4,4,0,limp_home,1,12,out_of_range,0,,,"));
        let e = parse_line(&line("Limping", "Off")).unwrap().unwrap_err();
        assert!(e.to_string().contains("mode 'Limping' is none of Normal, SensorFault"), "{e}");
        let e = parse_line(&line("Normal", "On")).unwrap().unwrap_err();
        assert!(e.to_string().contains("alarm 'On'"), "{e}");
    }

    #[test]
    fn a_line_the_firmware_cannot_have_printed_is_an_error() {
        let l = "t=0 temp=4 sp=4 duty=0.5 mode=Normal counts=1 supply=12 alarm=Off";
        let err = |from: &str, to: &str| parse_line(&l.replace(from, to)).unwrap().unwrap_err().to_string();
        assert!(err("duty=0.5", "duty=7").contains("duty = 7 is outside 0…1"));
        assert!(err("duty=0.5", "duty=-1").contains("duty = -1 is outside 0…1"));
        assert!(err("temp=4", "temp=1e30").contains("outside what a Pt100 can report"));
        assert!(err("temp=4", "temp=-300").contains("outside what a Pt100 can report"));
        assert!(err("temp=4", &format!("temp=4{}", "0".repeat(400))).contains("is too large a number"));
        assert!(err("sp=4", "sp=1e30").contains("sp = 1e30"));
        assert!(err("temp=4", "temp=4 temp=5").contains("'temp' appears twice"));
        assert!(err("alarm=Off", "alarm=Off alarm=Off").contains("'alarm' appears twice"));
        assert!(parse_line(l).unwrap().is_ok());
    }

    #[test]
    fn a_non_finite_temperature_is_a_fault_row_and_t_ms_wins() {
        for nan in ["NaN", "inf", "-inf"] {
            let l = format!(
                "0.1 INFO  t=0 temp={nan} sp=4 duty=0 mode=SensorFault counts=65535 supply=12 alarm=NotInControl"
            );
            let s = parse_line(&l).unwrap().unwrap();
            assert_eq!((s.temp_c, s.mode, s.counts), (None, Some(Mode::SensorFault), Some(65_535)), "{nan}");
        }
        let s = parse_line("t_ms=7776000123 t=7776000 temp=4 sp=4 duty=0.5 mode=Normal").unwrap().unwrap();
        assert_eq!(s.t_s, 7_776_000.123);
        let s = parse_line("t_ms=2500 temp=4 sp=4 duty=0.5 mode=Normal").unwrap().unwrap();
        assert_eq!(s.t_s, 2.5);
        let bad = parse_line("t_ms=2.5 t=2 temp=4 sp=4 duty=0.5 mode=Normal").unwrap();
        assert!(bad.unwrap_err().to_string().contains("t_ms"));
    }

    #[test]
    fn boots_are_joined_and_keep_their_causes() {
        let log = "\
0.0 INFO  reset cause: BrownOut
0.0 INFO  hter firmware 0.1.0: Ts = 10 s, setpoint 4 °C, SSR PWM 1 Hz (1000 ticks)
t=0 temp=NaN sp=4 duty=0 mode=SensorFault
t=10 temp=5 sp=4 duty=0.5 mode=Normal
WARN  event t=10 SensorRecovered
INFO  reset cause: Watchdog
t=0 temp=6 sp=4 duty=0.5 mode=Normal
t=10 temp=6 sp=4 duty=0.5 mode=Normal
INFO  reset cause: Other
INFO  board fault: HardFault pc=0x08001234 addr=0x20018000 detail=0x8200
t=0 temp=7 sp=4 duty=0.5 mode=Normal
t=5 temp=7 sp=4 duty=0.5 mode=Normal
t=0 temp=8 sp=4 duty=0.5 mode=Normal
INFO  board fault: Panic pc=0x00000000 addr=0x00000000 detail=0x2a src/step.rs
t=10 temp=8 sp=4 duty=0.5 mode=Normal
";
        let c = convert(lines(log)).unwrap();
        let got: Vec<(f64, Option<f64>, u32, Option<&str>)> =
            c.rows.iter().map(|r| (r.sample.t_s, r.sample.temp_c, r.boot, r.reset_cause.as_deref())).collect();
        assert_eq!(
            got,
            vec![
                (0.0, None, 0, Some("restarted_brownout")),
                (10.0, Some(5.0), 0, None),
                (20.0, Some(6.0), 1, Some("restarted_watchdog")),
                (30.0, Some(6.0), 1, None),
                (40.0, Some(7.0), 2, Some("board_fault_hard_fault")),
                (45.0, Some(7.0), 2, None),
                // t went back with no reset line: a boot whose cause was lost, until the late
                // fail-safe report names it.
                (55.0, Some(8.0), 3, Some("board_fault_panic")),
                (65.0, Some(8.0), 3, None),
            ]
        );
        assert_eq!(c.joined, Some((3, 10.0, PeriodSource::BootLine)));
        let text = csv_text(&c.rows);
        assert_eq!(text.lines().next(), Some(HEADER));
        assert_eq!(text.lines().nth(1), Some("0,4,,0,sensor_fault,,,,0,restarted_brownout,,"));
        assert_eq!(text.lines().nth(2), Some("10,4,5,0.5,normal,,,,0,,,sensor_recovered"));
        // An event logged ahead of its sample (t later than the last one) goes with the next.
        let c = convert(lines(
            "t=0 temp=4 sp=4 duty=0 mode=Normal\nevent t=10 LidOpen\nt=10 temp=4 sp=4 duty=0 mode=Normal\n",
        ))
        .unwrap();
        assert_eq!((c.rows[0].events.clone(), c.rows[1].events.clone()), (vec![], vec!["lid_open"]));
    }

    /// The firmware logs each of the step's events after the sample's telemetry line (`WARN  event
    /// t=10.000 SsrStuckOn`, firmware/src/main.rs). They were left out of the CSV, so `hter report`
    /// of a firmware log listed its restarts and no fault: no "SERVICE NEEDED" for a shorted SSR
    /// or an open probe, where the README says a `hter log2csv` output lists them.
    #[test]
    fn the_steps_events_reach_the_csv_and_the_report() {
        let log = "\
0.000000 INFO  hter firmware 0.1.0: reset cause BrownOut; watchdog software; Ts = 10 s, setpoint 4 °C
WARN  event t=0.000 Restarted(BrownOut)
t=0.000 temp=4.0 sp=4 duty=0.45 mode=Normal
t=10.000 temp=4.1 sp=4 duty=0.45 mode=Normal
WARN  event t=10.000 SsrStuckOn
WARN  event t=10.000 FreezeGuardTripped
t=20.000 temp=4.2 sp=4 duty=0.45 mode=LimpHome
WARN  event t=20.000 Gremlin
0.000000 INFO  hter firmware 0.1.0: reset cause Watchdog; watchdog software; Ts = 10 s, setpoint 4 °C
WARN  event t=0.000 SensorOpen
t=0.000 temp=NaN sp=4 duty=0 mode=SensorFault
t=10.000 temp=NaN sp=4 duty=0 mode=SensorFault
";
        let c = convert(lines(log)).unwrap();
        let got: Vec<(f64, Vec<&str>)> = c.rows.iter().map(|r| (r.sample.t_s, r.events.clone())).collect();
        assert_eq!(
            got,
            [
                (0.0, vec![]),
                (10.0, vec!["ssr_stuck_on", "freeze_guard_tripped"]),
                (20.0, vec![]),
                (30.0, vec!["sensor_open"]),
                (40.0, vec![]),
            ]
        );
        assert_eq!(c.warnings, ["line 8: unknown event 'Gremlin', left out".to_string()]);
        let text = csv_text(&c.rows);
        assert_eq!(text.lines().nth(2), Some("10,4,4.1,0.45,normal,,,,0,,,ssr_stuck_on;freeze_guard_tripped"));
        // What `hter monitor` and `hter report` read from it.
        let p = std::env::temp_dir().join(format!("hter-log2csv-{}-events.csv", std::process::id()));
        std::fs::write(&p, text).unwrap();
        let input = crate::monitor_cmd::read_input(&p);
        let page = crate::report_cmd::html(&p);
        std::fs::remove_file(&p).unwrap();
        let names: Vec<(f64, String)> = input.unwrap().events.into_iter().map(|e| (e.t_s, e.name)).collect();
        let want = [
            (0.0, "restarted_brownout"),
            (10.0, "ssr_stuck_on"),
            (10.0, "freeze_guard_tripped"),
            (30.0, "restarted_watchdog"),
            (30.0, "sensor_open"),
        ];
        assert_eq!(names, want.map(|(t, n)| (t, n.to_string())));
        let page = page.unwrap();
        assert!(page.contains("SERVICE NEEDED — 3 faults that need a service check, the first ssr_stuck_on"), "{page}");
    }

    /// The boot line as the firmware prints it (every build's format string in
    /// firmware/src/main.rs, its `{}` filled in): one line with the reset cause and the period.
    /// Read only for a `reset cause:` line of its own, a real log's boots all came out `unknown`
    /// (the first one with no cause) and a `hter report` of it named no watchdog restart.
    #[test]
    fn the_firmwares_boot_line_gives_each_boot_its_cause_and_the_period() {
        let main = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../firmware/src/main.rs")).unwrap();
        let formats: Vec<&str> =
            main.split('"').filter(|s| s.starts_with("hter firmware {}: reset cause {};")).collect();
        assert!(formats.len() >= 2, "the SSR and buck builds' boot lines: {formats:?}");
        for format in formats {
            let boot = |cause: &str| {
                let values = ["0.1.0", cause, "software", "4", "4", "true", "10", "4", "1", "1000"];
                let parts: Vec<&str> = format.split("{}").collect();
                assert!(parts.len() <= values.len() + 1, "{format}");
                let mut line = parts[0].to_owned();
                for (v, p) in values.iter().zip(&parts[1..]) {
                    line.push_str(v);
                    line.push_str(p);
                }
                format!("0.000000 INFO  {line}\n")
            };
            let sample = |t: u32| format!("t={t} temp=4 sp=4 duty=0.5 mode=Normal\n");
            let log = [boot("Other"), sample(0), sample(10), boot("BrownOut"), sample(0), boot("Watchdog"), sample(0)]
                .concat();
            assert!(log.contains("reset cause BrownOut; watchdog software;"), "{log}");
            let c = convert(lines(&log)).unwrap();
            let got: Vec<(f64, Option<&str>)> =
                c.rows.iter().map(|r| (r.sample.t_s, r.reset_cause.as_deref())).collect();
            assert_eq!(
                got,
                [
                    (0.0, Some("restarted")),
                    (10.0, None),
                    (20.0, Some("restarted_brownout")),
                    (30.0, Some("restarted_watchdog"))
                ],
                "{log}"
            );
            assert_eq!(c.joined, Some((2, 10.0, PeriodSource::BootLine)));
            assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        }
    }

    #[test]
    fn joins_use_the_median_interval_and_keep_a_clock_that_went_on() {
        // No boot line: the period is the median interval (10 s); a lost reset line is `unknown`.
        let log = "t=0 temp=4 sp=4 duty=0 mode=Normal\nt=10 temp=4 sp=4 duty=0 mode=Normal\n\
                   t=20 temp=4 sp=4 duty=0 mode=Normal\nt=3 temp=4 sp=4 duty=0 mode=Normal\n";
        let c = convert(lines(log)).unwrap();
        let t: Vec<f64> = c.rows.iter().map(|r| r.sample.t_s).collect();
        assert_eq!(t, vec![0.0, 10.0, 20.0, 33.0]);
        assert_eq!(c.rows[3].reset_cause.as_deref(), Some("unknown"));
        assert_eq!(c.rows[0].reset_cause, None, "the log began on a running board");
        assert_eq!(c.joined, Some((1, 10.0, PeriodSource::Median)));
        // A clock that survived the reset (later than the last sample) is kept as it is.
        let log = "t_ms=1000 temp=4 sp=4 duty=0 mode=Normal\nreset cause: Watchdog\n\
                   t_ms=40123 temp=4 sp=4 duty=0 mode=Normal\n";
        let c = convert(lines(log)).unwrap();
        assert_eq!((c.rows[1].sample.t_s, c.rows[1].boot, c.joined), (40.123, 1, None));
        // Fractional times stay decimal after the shift.
        let log = "Ts = 0.1 s\nt=0 temp=4 sp=4 duty=0 mode=Normal\nt_ms=12345 temp=4 sp=4 duty=0 mode=Normal\n\
                   reset cause: Other\nt_ms=0 temp=4 sp=4 duty=0 mode=Normal\n";
        let c = convert(lines(log)).unwrap();
        assert_eq!(csv_text(&c.rows).lines().nth(3).unwrap().split(',').next(), Some("12.445"));
    }

    #[test]
    fn bad_logs_are_errors_with_the_line() {
        let e = convert(lines("hello\nt=0 temp=4 sp=x duty=0 mode=Normal\n")).unwrap_err();
        assert!(format!("{e:#}").contains("line 2: sp 'x'"), "{e:#}");
        // A garbled boot line costs its cause, not the log.
        let c = convert(lines("reset cause: Cosmic\nboard fault: Gremlin pc=0\nt=0 temp=4 sp=4 duty=0 mode=Normal\n"))
            .unwrap();
        assert_eq!(c.rows[0].reset_cause.as_deref(), Some(UNKNOWN_CAUSE));
        assert_eq!(
            c.warnings,
            vec![
                "line 1: unknown reset cause 'Cosmic', recorded as 'unknown'".to_string(),
                "line 2: unknown board fault 'Gremlin', recorded as 'unknown'".to_string()
            ]
        );
        let e = convert(lines("INFO boot\n")).unwrap_err();
        assert!(e.to_string().contains("no telemetry lines"), "{e}");
        // Two one-sample boots and no boot line: nothing says how far apart the samples are.
        let e = convert(lines("t=5 temp=4 sp=4 duty=0 mode=Normal\nt=5 temp=4 sp=4 duty=0 mode=Normal\n")).unwrap_err();
        assert!(e.to_string().contains("no sample period"), "{e}");
    }

    /// A supply voltage or holdover the board cannot print (negative, or too large for a number)
    /// is a corrupt line, named; NaN is "none", as the firmware prints it.
    #[test]
    fn a_measurement_the_board_cannot_print_is_refused() {
        let line = |supply: &str, holdover: &str| {
            format!("t=0 temp=4 sp=4 duty=0.5 mode=Normal counts=1 supply={supply} alarm=Off holdover={holdover}")
        };
        for (supply, holdover, what) in
            [("1e400", "10", "supply"), ("-12", "10", "supply"), ("12", "-5", "holdover"), ("12", "inf", "holdover")]
        {
            let e = format!("{:#}", parse_line(&line(supply, holdover)).unwrap().unwrap_err());
            assert!(e.contains(what) && e.contains("not what the board prints"), "{supply} {holdover}: {e}");
        }
        let ok = parse_line(&line("NaN", "NaN")).unwrap().unwrap();
        assert_eq!((ok.supply_v, ok.holdover_s), (None, None));
        let ok = parse_line(&line("12.04", "0")).unwrap().unwrap();
        assert_eq!((ok.supply_v, ok.holdover_s), (Some(12.04), Some(0.0)));
    }

    /// The board's clock starts at 0: a negative `t=` is a corrupt line, named, not a sample
    /// (`t=-1e300` was written as 301 digits). `t=-0` and `t=0` are the boot's first sample.
    #[test]
    fn a_time_before_the_boot_is_refused() {
        for t in ["-5", "-1e300", "-0.001"] {
            let log = format!("t=0 temp=4 sp=4 duty=0\nt={t} temp=4 sp=4 duty=0\n");
            let e = format!("{:#}", convert(lines(&log)).unwrap_err());
            assert!(e.contains("line 2") && e.contains("before the board's clock starts"), "{t}: {e}");
            assert!(e.len() < 150, "{e}");
        }
        assert!(convert(lines("t=-0 temp=4 sp=4 duty=0\nt=10 temp=4 sp=4 duty=0\n")).is_ok());
    }
}
