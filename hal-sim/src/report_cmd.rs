//! `hter report`: the cold-chain record of a CSV log as one self-contained HTML page a
//! supervisor reads at a glance, in the spirit of the download of a WHO PQS E006 30-day
//! temperature recorder: a verdict line, a header (source, carrier and firmware when the file
//! names them, period, resets and faults), a per-day table (min, max, time-weighted mean, time
//! below +2 °C and above +8 °C, alarms), the alarms by kind with start, trigger and duration,
//! the mean kinetic temperature (MKT) against 2–8 °C, and plots (SVG inline) of the whole
//! period and of each day with an alarm.
//!
//! The numbers are `hter monitor`'s: the same reader ([`monitor_cmd::read_input`]) and the
//! same library monitor ([`monitor_cmd::report`], `hter::coldchain`), so the two commands agree
//! on every alarm and on MKT. The per-day figures use the monitor's rule: a sample holds over
//! the interval to the next one (a board history's row over the interval that ends at its
//! `t_s`), and the interval after a sample with no reading counts neither in nor out of range.
//!
//! Days are 24 h blocks of the record's own time axis from its first sample: the logs carry
//! no calendar date (the board has no real-time clock), and the report says so.
//!
//! `--output FILE.pdf` prints the HTML with headless Chromium (`chromium --headless
//! --print-to-pdf`); no PDF crate is needed for a page a browser already lays out.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use hter::coldchain::AlarmKind;

use crate::monitor_cmd::{self, AlarmOut, Event, Input};
use crate::{log, plot};

/// Length of a report day, s.
const DAY_S: f64 = 86_400.0;
/// Most points drawn per line: longer records are drawn as a min/max envelope per bucket, which
/// keeps every extreme visible and the page small (a 30-day record at 10 s has 259 200 samples).
const MAX_PLOT_POINTS: usize = 4_000;

/// Arguments of `hter report`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReportArgs {
    /// CSV log with columns t_s and temp_c: `hter sim --csv`, `hter log2csv` or a board
    /// history (`hter board … history`).
    #[arg(long)]
    pub input: PathBuf,
    /// The report to write: FILE.html, or FILE.pdf (printed from the HTML by headless Chromium).
    #[arg(long)]
    pub output: PathBuf,
}

/// One report day.
#[derive(Debug, Clone, PartialEq)]
pub struct Day {
    /// Day number from 1.
    pub number: usize,
    /// Start on the log's axis, s.
    pub start_s: f64,
    /// Lowest reading, °C (`None`: no reading that day).
    pub min_c: Option<f64>,
    /// Highest reading, °C.
    pub max_c: Option<f64>,
    /// Time-weighted mean, °C.
    pub mean_c: Option<f64>,
    /// Time below +2 °C, s.
    pub below_2_s: f64,
    /// Time above +8 °C, s.
    pub above_8_s: f64,
    /// Kinds of the alarms under way that day.
    pub alarms: Vec<&'static str>,
}

/// An alarm with how long its condition held.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmSpan {
    /// The alarm as `hter monitor` reports it.
    pub alarm: AlarmOut,
    /// Until when the condition held, s (the first reading that no longer met it, or the end of
    /// the record); for the cumulative `ship_30c_10h`, the last interval that met it.
    pub end_s: f64,
    /// Time with a reading that met the condition, s (for a continuous alarm, within its run;
    /// for the cumulative one, over the record).
    pub duration_s: f64,
    /// Whether the condition still held at the end of the record.
    pub ongoing: bool,
    /// Recorded by the carrier (an alarm event of a board history) and not shown by the file's
    /// readings: its end and duration are not known here.
    pub carrier: bool,
}

/// The sample-and-hold intervals of a log with a reading: (from, to, °C).
fn intervals(t: &[f64], temp: &[Option<f64>]) -> Vec<(f64, f64, f64)> {
    t.windows(2).zip(temp).filter_map(|(w, c)| c.map(|c| (w[0], w[1], c))).collect()
}

/// How long each alarm's condition held, with the library's thresholds.
pub fn alarm_spans(t: &[f64], temp: &[Option<f64>], alarms: Vec<AlarmOut>) -> Vec<AlarmSpan> {
    let iv = intervals(t, temp);
    let end_of_record = t.last().copied().unwrap_or(0.0);
    alarms
        .into_iter()
        .map(|alarm| {
            let kind = AlarmKind::ALL.into_iter().find(|k| k.name() == alarm.kind);
            let meets = |c: f64| kind.is_some_and(|k| k.meets(c as f32));
            if kind.is_some_and(AlarmKind::cumulative) {
                let hits: Vec<_> = iv.iter().filter(|x| meets(x.2)).collect();
                let duration_s = hits.iter().map(|x| x.1 - x.0).sum();
                let end_s = hits.last().map_or(alarm.trigger_s, |x| x.1);
                let ongoing = temp.iter().rev().flatten().next().is_some_and(|&c| meets(c));
                return AlarmSpan { alarm, end_s, duration_s, ongoing, carrier: false };
            }
            let mut duration_s = 0.0;
            let mut end = None;
            for x in iv.iter().filter(|x| x.0 >= alarm.start_s) {
                if !meets(x.2) {
                    end = Some(x.0);
                    break;
                }
                duration_s += x.1 - x.0;
            }
            // A last reading after the run's intervals that no longer meets ends it there.
            let last_reading = t.iter().zip(temp).rev().find_map(|(&t, c)| c.map(|c| (t, c)));
            if end.is_none() {
                end = last_reading.filter(|&(lt, c)| lt >= alarm.start_s && !meets(c)).map(|x| x.0);
            }
            AlarmSpan { alarm, end_s: end.unwrap_or(end_of_record), duration_s, ongoing: end.is_none(), carrier: false }
        })
        .collect()
}

/// The carrier's own alarms ([`monitor_cmd::Report::carrier_alarms`]) as table rows.
pub fn carrier_spans(alarms: &[AlarmOut]) -> Vec<AlarmSpan> {
    alarms
        .iter()
        .map(|a| AlarmSpan { alarm: a.clone(), end_s: a.trigger_s, duration_s: 0.0, ongoing: false, carrier: true })
        .collect()
}

/// The 24 h blocks of the record from its first sample, with the alarms under way in each. A
/// board history's interval extremes (`extremes`, one per sample or empty) widen each day's
/// min and max.
pub fn days(t: &[f64], temp: &[Option<f64>], extremes: &[Option<(f64, f64)>], alarms: &[AlarmSpan]) -> Vec<Day> {
    let (Some(&t0), Some(&t1)) = (t.first(), t.last()) else {
        return Vec::new();
    };
    let n = (((t1 - t0) / DAY_S).ceil() as usize).max(1);
    let mut days: Vec<Day> = (0..n)
        .map(|i| Day {
            number: i + 1,
            start_s: t0 + i as f64 * DAY_S,
            min_c: None,
            max_c: None,
            mean_c: None,
            below_2_s: 0.0,
            above_8_s: 0.0,
            alarms: Vec::new(),
        })
        .collect();
    let index = |ts: f64| (((ts - t0) / DAY_S).floor().max(0.0) as usize).min(n - 1);
    for (i, (&ts, c)) in t.iter().zip(temp).enumerate() {
        if let (Some(c), Some(d)) = (c, days.get_mut(index(ts))) {
            let (lo, hi) = extremes.get(i).copied().flatten().unwrap_or((*c, *c));
            d.min_c = Some(d.min_c.map_or(lo, |m| m.min(lo)));
            d.max_c = Some(d.max_c.map_or(hi, |m| m.max(hi)));
        }
    }
    let mut weighted = vec![(0.0, 0.0); n];
    for (a, b, c) in intervals(t, temp) {
        // Split the interval at day boundaries.
        let mut from = a;
        while from < b {
            let i = index(from);
            let to = b.min(t0 + (i + 1) as f64 * DAY_S);
            let to = if i + 1 == n { b } else { to };
            let dt = to - from;
            if let (Some(d), Some(w)) = (days.get_mut(i), weighted.get_mut(i)) {
                w.0 += c * dt;
                w.1 += dt;
                if c < 2.0 {
                    d.below_2_s += dt;
                }
                if c > 8.0 {
                    d.above_8_s += dt;
                }
            }
            from = to;
        }
    }
    for (d, (sum, dt)) in days.iter_mut().zip(weighted) {
        d.mean_c = (dt > 0.0).then(|| sum / dt).or(d.min_c);
        let (lo, hi) = (d.start_s, d.start_s + DAY_S);
        for a in alarms {
            let in_day = a.alarm.start_s < hi && a.end_s.max(a.alarm.trigger_s) >= lo;
            if in_day && !d.alarms.contains(&a.alarm.kind) {
                d.alarms.push(a.alarm.kind);
            }
        }
    }
    days
}

/// The one-line verdict: freeze risk (a freeze alarm, the file's or the carrier's, or a reading
/// at or below −0.5 °C, an interval's lowest included), excursions (any alarm, any time outside
/// 2–8 °C, any interval whose extremes left it, or MKT outside 2–8 °C), not fully recorded
/// (no reading for a while, so "in range" cannot be claimed: the probe's fault, or entries the
/// record lost, the input's `holes`, each said as what it is), or in range.
pub fn verdict(r: &monitor_cmd::Report, holes: usize) -> (&'static str, &'static str) {
    if r.alarms.iter().chain(&r.carrier_alarms).any(|a| a.kind == "freeze_60min") || r.min_c <= -0.5 {
        ("freeze", "FREEZE RISK — the vaccines may have frozen: check them (shake test) before use")
    } else if !r.alarms.is_empty()
        || !r.carrier_alarms.is_empty()
        || r.time_below_2_s > 0.0
        || r.time_above_8_s > 0.0
        || r.intervals_outside_2_8 > 0
        || !(2.0..=8.0).contains(&r.mkt_c)
    {
        ("excursion", "EXCURSIONS — the load left 2–8 °C: see the alarms and the days below")
    } else if r.fault_samples > 0 {
        let line = match monitor_cmd::NoReading::of(r.fault_samples, holes) {
            monitor_cmd::NoReading::LostEntries => {
                "NOT FULLY RECORDED — part of the record was lost (log entries the board could not store, below): \
                 the record cannot show the load stayed within 2–8 °C then"
            }
            monitor_cmd::NoReading::SensorFault => {
                "NOT FULLY RECORDED — the probe gave no reading for part of the period (below): the record \
                 cannot show the load stayed within 2–8 °C then"
            }
            monitor_cmd::NoReading::Both => {
                "NOT FULLY RECORDED — the probe gave no reading for part of the period and part of the record \
                 was lost (below): the record cannot show the load stayed within 2–8 °C then"
            }
        };
        ("unknown", line)
    } else {
        ("ok", "IN RANGE — the load stayed within 2–8 °C for the whole period")
    }
}

/// Whether an event is a reset or a fault (what the header lists), by the library's event names
/// (`hter::event::EventKind::name`; a board history may add `:detail`): restarts, board faults,
/// sensor, SSR, supply, reference and flash faults, a lid left open (each of the supervisor's
/// detections sounds the alarm indicator), and the record's own holes (a flash page lost, log
/// entries lost while flash writes were held off, a flash that refused its writes). Settings, alarms (listed on their own) and
/// recoveries are not.
fn is_reset_or_fault(e: &Event) -> bool {
    let n = e.name.to_ascii_lowercase();
    const PREFIXES: [&str; 13] = [
        "restart",
        "board_fault",
        "sensor_",
        "ssr_stuck",
        "supply_",
        "reference_out_of_range",
        "flash_page_lost",
        "log_entries_lost",
        "record_refused",
        "store_failed",
        "controller_non_finite",
        "freeze_guard_tripped",
        "lid_open",
    ];
    PREFIXES.iter().any(|p| n.starts_with(p)) && !n.starts_with("sensor_recovered")
}

/// HTML-escapes text.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A duration as `12 h 05 min` (or `45 s` below a minute).
fn dur(s: f64) -> String {
    if s < 60.0 {
        return format!("{s:.0} s");
    }
    let m = (s / 60.0).round() as u64;
    if m < 60 {
        format!("{m} min")
    } else {
        format!("{} h {:02} min", m / 60, m % 60)
    }
}

/// A time on the log's axis as `day 2, 14:05` from the first sample (and the raw seconds).
fn when(t: f64, t0: f64) -> String {
    let rel = (t - t0).max(0.0);
    let day = (rel / DAY_S).floor() as u64 + 1;
    let m = ((rel % DAY_S) / 60.0).floor() as u64;
    format!("day {day}, {:02}:{:02} <span class=\"raw\">(t = {t:.0} s)</span>", m / 60, m % 60)
}

fn opt_c(c: Option<f64>) -> String {
    c.map_or_else(|| "—".to_owned(), |c| format!("{c:.1}"))
}

/// At most `max` points (at least 2): the min and max of each bucket, in time order.
fn envelope_to(points: Vec<(f64, f64)>, max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max {
        return points;
    }
    let per = points.len().div_ceil((max / 2).max(1));
    points
        .chunks(per)
        .flat_map(|c| {
            let lo = c.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1));
            let hi = c.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1));
            let mut v: Vec<_> = lo.into_iter().chain(hi).collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            v
        })
        .collect()
}

/// The points with a value, in runs between those without one (a sample or interval with no
/// reading), each run enveloped to its share of [`MAX_PLOT_POINTS`] and the runs joined by a
/// NaN, where the plot breaks its line: a sensor fault is a gap, not a line from the last
/// reading to the next, which showed a temperature nobody measured.
fn broken(points: &[(f64, Option<f64>)]) -> Vec<(f64, f64)> {
    let runs: Vec<Vec<(f64, f64)>> = points
        .split(|p| p.1.is_none())
        .filter(|r| !r.is_empty())
        .map(|r| r.iter().filter_map(|&(x, y)| y.map(|y| (x, y))).collect())
        .collect();
    let total: usize = runs.iter().map(Vec::len).sum();
    let mut line = Vec::new();
    for run in runs {
        if let Some(&(x, _)) = run.first().filter(|_| !line.is_empty()) {
            line.push((x, f64::NAN));
        }
        // The run's share of the plot's points, at least two.
        let share = (MAX_PLOT_POINTS * run.len()).div_ceil(total.max(1)).max(2);
        line.extend(envelope_to(run, share));
    }
    line
}

/// The temperature against the 2 and 8 °C limits over `[from, to)` of the log, x in hours
/// from `x0`; a board history's interval extremes as two more lines. Every line breaks where
/// there is no reading ([`broken`]).
fn temp_plot(title: &str, input: &Input, from: f64, to: f64, x0: f64) -> Result<String> {
    let h = |ts: f64| (ts - x0) / 3600.0;
    let within = || input.t_s.iter().enumerate().filter(|(_, &ts)| ts >= from && ts <= to);
    let temps: Vec<(f64, Option<f64>)> = within().map(|(i, &ts)| (h(ts), input.temp_c[i])).collect();
    let (a, b) = (
        temps.iter().find(|p| p.1.is_some()).map_or(h(from), |p| p.0),
        temps.iter().rev().find(|p| p.1.is_some()).map_or(h(to), |p| p.0),
    );
    let ext: Vec<(f64, Option<(f64, f64)>)> =
        within().map(|(i, &ts)| (h(ts), input.extremes.get(i).copied().flatten())).collect();
    let limit = |v: f64| vec![(a, v), (b, v)];
    let mut series = vec![plot::Series { name: "temperature".into(), points: broken(&temps) }];
    if ext.iter().any(|e| e.1.is_some()) {
        let side =
            |pick: fn((f64, f64)) -> f64| broken(&ext.iter().map(|&(x, e)| (x, e.map(pick))).collect::<Vec<_>>());
        series.push(plot::Series { name: "interval lowest".into(), points: side(|e| e.0) });
        series.push(plot::Series { name: "interval highest".into(), points: side(|e| e.1) });
    }
    series.push(plot::Series { name: "8 °C limit".into(), points: limit(8.0) });
    series.push(plot::Series { name: "2 °C limit".into(), points: limit(2.0) });
    let panel = plot::Panel { title: "Load temperature".into(), y_label: "°C".into(), series, y_range: None };
    plot::panels_svg(1000, title, "hours from the first sample", &[panel])
}

/// The first non-empty cell of an optional text column.
fn first_text(path: &Path, name: &str) -> Result<Option<String>> {
    Ok(log::read_text(path, name)?.and_then(|c| c.into_iter().find(|s| !s.is_empty())))
}

/// Builds the report page of a log.
pub fn html(path: &Path) -> Result<String> {
    let shown = path.display().to_string();
    let input = monitor_cmd::read_input(path)?;
    let r = monitor_cmd::record(&input).with_context(|| format!("'{shown}'"))?;
    let Input { t_s: t, temp_c: temp, events, .. } = &input;
    let carrier = first_text(path, "carrier")?;
    let firmware = first_text(path, "firmware")?;
    let (t0, t1) = (t.first().copied().unwrap_or(0.0), t.last().copied().unwrap_or(0.0));
    let mut spans = alarm_spans(t, temp, r.alarms.clone());
    spans.extend(carrier_spans(&r.carrier_alarms));
    let days = days(t, temp, &input.extremes, &spans);
    let (class, line) = verdict(&r, input.holes);

    let mut h = String::new();
    let w = &mut h;
    writeln!(w, "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">")?;
    writeln!(w, "<title>Cold-chain report — {}</title>", esc(&shown))?;
    w.push_str(STYLE);
    writeln!(w, "</head><body>")?;
    writeln!(w, "<div class=\"verdict {class}\" id=\"verdict\">{}</div>", esc(line))?;
    // Loud beside the verdict: the load may be in range while the carrier needs a technician.
    // The resets and faults, each with what it means and whether it needs a technician.
    let faults: Vec<(&Event, Option<(String, bool)>)> =
        events.iter().filter(|e| is_reset_or_fault(e)).map(|e| (e, fault_meaning(&e.name))).collect();
    let service: Vec<&Event> =
        faults.iter().filter(|(_, m)| m.as_ref().is_some_and(|(_, s)| *s)).map(|(e, _)| *e).collect();
    if let Some(first) = service.first() {
        writeln!(
            w,
            "<div class=\"verdict service\" id=\"service\">SERVICE NEEDED — {} fault{} that need{} \
                a service check, the first {} at {} (below)</div>",
            service.len(),
            if service.len() == 1 { "" } else { "s" },
            if service.len() == 1 { "s" } else { "" },
            esc(&first.name),
            when(first.t_s, t0)
        )?;
    }
    writeln!(w, "<h1>Cold-chain report</h1>")?;
    writeln!(w, "<table class=\"head\">")?;
    let row = |w: &mut String, k: &str, v: &str| writeln!(w, "<tr><th>{k}</th><td>{v}</td></tr>");
    row(w, "Source file", &esc(&shown))?;
    row(w, "Carrier", &carrier.as_deref().map_or("not stated in the file".into(), esc))?;
    row(w, "Firmware", &firmware.as_deref().map_or("not stated in the file".into(), esc))?;
    row(
        w,
        "Period covered",
        &format!(
            "{} ({}, t = {t0:.0} … {t1:.0} s). The file has no calendar date: days are 24 h blocks \
             from the first sample.",
            dur(t1 - t0),
            input.count_text()
        ),
    )?;
    let mkt_ok = (2.0..=8.0).contains(&r.mkt_c);
    row(
        w,
        "Mean kinetic temperature",
        &format!(
            "<b id=\"mkt\">{:.2} °C</b> — {} the WHO limits of 2–8 °C",
            r.mkt_c,
            if mkt_ok { "within" } else { "<b>outside</b>" }
        ),
    )?;
    row(w, "Min / max", &format!("{:.2} / {:.2} °C", r.min_c, r.max_c))?;
    row(
        w,
        "Time below 2 °C / above 8 °C",
        &format!(
            "{} / {} ({} excursion{} outside 2–8 °C)",
            dur(r.time_below_2_s),
            dur(r.time_above_8_s),
            r.excursions,
            if r.excursions == 1 { "" } else { "s" }
        ),
    )?;
    if r.intervals_outside_2_8 > 0 {
        row(
            w,
            "Intervals that left 2–8 °C",
            &format!(
                "<b id=\"intervals-outside\">{}</b> of the record's 5-minute intervals had a lowest reading below 2 °C \
                 or a highest above 8 °C (the times above are from the intervals' means)",
                r.intervals_outside_2_8
            ),
        )?;
    }
    if r.fault_samples > 0 {
        row(
            w,
            &format!("No reading ({})", input.no_reading_cause(r.fault_samples).label()),
            &format!(
                "{} ({}; counted neither in nor out of range)",
                dur(r.time_no_reading_s),
                input.no_reading_text(r.fault_samples)
            ),
        )?;
    }
    let listed = if faults.is_empty() {
        if !input.has_event_column {
            "none recorded (the file has no event column)".to_owned()
        } else {
            "none".to_owned()
        }
    } else {
        let mut s = format!("{}:<ul class=\"events\">", faults.len());
        for (e, meaning) in &faults {
            let _ = write!(s, "<li>{} — {}", esc(&e.name), when(e.t_s, t0));
            if let Some((m, _)) = meaning {
                let _ = write!(s, ": {}", esc(m));
            }
            s.push_str("</li>");
        }
        s.push_str("</ul>");
        s
    };
    row(w, "Resets and faults", &listed)?;
    writeln!(w, "</table>")?;

    writeln!(w, "<h2>Alarms</h2>")?;
    if spans.is_empty() {
        writeln!(w, "<p id=\"alarms\">No alarm was raised.</p>")?;
    } else {
        writeln!(w, "<table id=\"alarms\"><tr><th>Alarm</th><th>Meaning</th><th>Started</th><th>Triggered</th><th>Duration</th></tr>")?;
        let mut sorted: Vec<&AlarmSpan> = spans.iter().collect();
        sorted.sort_by_key(|a| AlarmKind::ALL.iter().position(|k| k.name() == a.alarm.kind));
        for a in sorted {
            let (class, lasted) = if a.carrier {
                (
                    "alarm-carrier",
                    "recorded by the carrier, which checks every 10 s reading; the 5-minute means in this file \
                     do not show it"
                        .to_owned(),
                )
            } else if a.ongoing {
                ("alarm", format!("{} (still on at the end)", dur(a.duration_s)))
            } else {
                ("alarm", format!("{} (until {})", dur(a.duration_s), when(a.end_s, t0)))
            };
            writeln!(
                w,
                "<tr class=\"{class}\" data-kind=\"{}\" data-start-s=\"{}\" data-trigger-s=\"{}\"><td><b>{}</b></td><td>{}</td><td>{}</td><td>{}</td><td>{lasted}</td></tr>",
                a.alarm.kind,
                a.alarm.start_s,
                a.alarm.trigger_s,
                a.alarm.kind,
                meaning(a.alarm.kind),
                when(a.alarm.start_s, t0),
                when(a.alarm.trigger_s, t0),
            )?;
        }
        writeln!(w, "</table>")?;
    }

    writeln!(w, "<h2>Day by day</h2>")?;
    writeln!(w, "<table id=\"days\"><tr><th>Day</th><th>Min °C</th><th>Max °C</th><th>Mean °C</th><th>Below 2 °C</th><th>Above 8 °C</th><th>Alarms</th></tr>")?;
    for d in &days {
        let left = d.min_c.is_some_and(|c| c < 2.0) || d.max_c.is_some_and(|c| c > 8.0);
        let bad = !d.alarms.is_empty() || d.below_2_s > 0.0 || d.above_8_s > 0.0 || left;
        writeln!(
            w,
            "<tr class=\"day{}\"><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            if bad { " bad" } else { "" },
            d.number,
            opt_c(d.min_c),
            opt_c(d.max_c),
            opt_c(d.mean_c),
            dur(d.below_2_s),
            dur(d.above_8_s),
            if d.alarms.is_empty() { "—".to_owned() } else { d.alarms.join(", ") },
        )?;
    }
    writeln!(w, "</table>")?;

    writeln!(w, "<h2>Plots</h2>")?;
    writeln!(w, "<div class=\"plot\">{}</div>", temp_plot("The whole period", &input, t0, t1, t0)?)?;
    for d in days.iter().filter(|d| !d.alarms.is_empty()) {
        let title = format!("Day {} (alarms: {})", d.number, d.alarms.join(", "));
        writeln!(w, "<div class=\"plot\">{}</div>", temp_plot(&title, &input, d.start_s, d.start_s + DAY_S, t0)?)?;
    }
    writeln!(
        w,
        "<p class=\"foot\">Made by <code>hter report</code> (hter {}) with the cold-chain monitor the firmware runs; \
         alarms after WHO PQS E006 (heat: above 8 °C for 10 h; freeze: at or below −0.5 °C for 60 min; \
         shipping: 45 °C for 1 h, 30 °C for 10 h in total).</p>",
        env!("CARGO_PKG_VERSION")
    )?;
    writeln!(w, "</body></html>")?;
    Ok(h)
}

/// What an alarm kind means, for the table.
/// What a reset or fault ([`is_reset_or_fault`]) means to the person reading the record, and
/// whether the carrier needs a service check for it, by the library's event name
/// (`hter::event::EventKind::name`; a board history's `restarted:brownout` spelling and
/// `log_entries_lost:N` count too). `None` for a name the library does not have.
fn fault_meaning(name: &str) -> Option<(String, bool)> {
    let n = name.to_ascii_lowercase();
    let (base, detail) = n.split_once(':').unwrap_or((n.as_str(), ""));
    let base = match (base, detail) {
        ("restarted", "brownout") => "restarted_brownout",
        ("restarted", "watchdog") => "restarted_watchdog",
        _ => base,
    };
    let (text, service) = match base {
        "restarted" => (
            "the controller restarted (power switched on or reset); the record goes on from here, \
                the time it was off is not known"
                .to_owned(),
            false,
        ),
        "restarted_brownout" => (
            "the controller restarted after its supply dropped too low (a weak battery or a loose \
                supply lead); the time it was off is not known"
                .to_owned(),
            false,
        ),
        "restarted_watchdog" => (
            "the controller stopped responding and its watchdog restarted it; cooling was off \
                meanwhile"
                .to_owned(),
            true,
        ),
        b if b.starts_with("board_fault") => (
            "the controller stopped itself after an internal error, switched cooling off and \
                restarted"
                .to_owned(),
            true,
        ),
        "sensor_open" | "sensor_short" | "sensor_out_of_range" | "sensor_stuck" | "reference_out_of_range" => {
            ("the temperature probe or its circuit failed; cooling stays off until it reads again".to_owned(), true)
        }
        "sensor_spikes" => ("the temperature probe gave erratic readings (a loose contact)".to_owned(), true),
        "sensor_offset" => ("the temperature probe's reading jumped and stayed (a damaged lead)".to_owned(), true),
        "ssr_stuck_on" => (
            "the cooling relay is stuck on; the controller now switches cooling on and off with its \
                safety switch (coarser control; the freeze guard still protects the load)"
                .to_owned(),
            true,
        ),
        "ssr_stuck_off" => (
            "cooling at full power did not cool: the relay or the cooling modules failed, or the \
                lid is open"
                .to_owned(),
            true,
        ),
        "supply_sag" => (
            "the supply voltage is low (a weak battery, car socket or solar panel): cooling power \
                is reduced"
                .to_owned(),
            false,
        ),
        "supply_switch_shorted" => (
            "the safety switch that cuts cooling is stuck closed: the second way to stop cooling \
                is gone"
                .to_owned(),
            true,
        ),
        "lid_open" => ("the cooling needed rose suddenly: the lid left open or a warm load put in".to_owned(), false),
        "freeze_guard_tripped" => {
            ("cooling was cut because the load came close to freezing (the vaccines were protected)".to_owned(), false)
        }
        "controller_non_finite" => {
            ("the control law gave an invalid output and the controller went to its safe state".to_owned(), true)
        }
        "flash_page_lost" => {
            ("a record being written when power was cut was lost; the rest of the record is intact".to_owned(), false)
        }
        "log_entries_lost" => {
            let waited = "while the controller waited to write them (just after a start, or on a bad supply)";
            let what = match detail.parse::<u32>() {
                Ok(1) => format!("1 record entry was lost {waited}"),
                Ok(count) => format!("{count} record entries were lost {waited}"),
                Err(_) => "record entries were lost, how many is not known (the controller found its \
                    log corrupt and erased it, or entries waiting to be written were dropped)"
                    .to_owned(),
            };
            (format!("{what}: the record has a gap before this time"), false)
        }
        "store_failed" => (
            "the controller's memory refused to store the record (several writes in a row \
                failed): what happened from here may not have been kept, and a restart loses it"
                .to_owned(),
            true,
        ),
        r if r.starts_with("record_refused_") => {
            let what = match &r["record_refused_".len()..] {
                "calibration" => {
                    "the stored calibration of the temperature probe, so the controller reads without \
                        it (up to 1.5 °C off) until it is calibrated again"
                }
                "settings" => {
                    "the stored settings (setpoint, controller, calibration), so the controller runs \
                        its defaults until they are set again"
                }
                "history" => {
                    "the stored cold-chain summary, so its counts start again here (the entries of \
                        this record are intact)"
                }
                "model" => "the cooling model learnt on this carrier, so the controller learns it again",
                "cabinet" => {
                    "the cabinet model from commissioning, so the holdover estimate uses the built-in \
                        one until the carrier is commissioned again"
                }
                _ => return None,
            };
            (format!("the controller could not use {what} (most often after a firmware change)"), true)
        }
        _ => return None,
    };
    Some(if service { (format!("{text}; the carrier needs a service check"), true) } else { (text, false) })
}

fn meaning(kind: &str) -> &'static str {
    match kind {
        "heat_10h" => "above +8 °C for 10 h without a break",
        "freeze_60min" => "at or below −0.5 °C for 60 min without a break",
        "ship_45c_1h" => "at or above +45 °C for 1 h without a break",
        "ship_30c_10h" => "at or above +30 °C for 10 h in total",
        _ => "",
    }
}

const STYLE: &str = "<style>
body{font-family:'DejaVu Sans',Arial,sans-serif;margin:24px;max-width:1040px;color:#222}
h1{margin:.3em 0}h2{margin-top:1.2em;border-bottom:1px solid #ccc}
.verdict{font-size:1.5em;font-weight:bold;padding:12px 16px;border-radius:6px;color:#fff}
.verdict.ok{background:#2e7d32}.verdict.excursion{background:#e65100}.verdict.freeze{background:#1565c0}.verdict.unknown{background:#6a1b9a}
.verdict.service{background:#b71c1c;margin-top:8px}.verdict .raw{color:#ffcdd2}
table{border-collapse:collapse;margin:8px 0}th,td{border:1px solid #bbb;padding:4px 8px;text-align:left;vertical-align:top}
table.head th{background:#f3f3f3;width:220px}tr.bad td{background:#fff3e0}.raw{color:#888;font-size:.85em}
ul.events{margin:4px 0;padding-left:20px}.plot svg{max-width:100%;height:auto}.foot{color:#666;font-size:.85em}
</style>
";

/// Prints an HTML file to PDF with headless Chromium.
fn print_pdf(html_path: &Path, pdf: &Path) -> Result<()> {
    let browser = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| std::process::Command::new(b).arg("--version").output().is_ok_and(|o| o.status.success()));
    let Some(browser) = browser else {
        bail!("a PDF needs headless Chromium ('chromium' not found); write --output FILE.html instead");
    };
    let abs = std::fs::canonicalize(html_path)?;
    let out = std::process::Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--no-pdf-header-footer"])
        .arg(format!("--print-to-pdf={}", pdf.display()))
        .arg(format!("file://{}", abs.display()))
        .output()
        .with_context(|| format!("cannot run {browser}"))?;
    if !out.status.success() || !pdf.exists() {
        bail!("{browser} could not print '{}' to PDF", pdf.display());
    }
    Ok(())
}

/// `hter report`.
pub fn run(args: &ReportArgs) -> Result<()> {
    // The page replaced the log it was made from.
    crate::sim_cmd::check_paths(&[("--input", &args.input)], &[("--output", &args.output)])?;
    let ext = args.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let page = html(&args.input)?;
    let out = args.output.display();
    match ext.as_deref() {
        Some("html" | "htm") => {
            crate::output::write(&args.output, page.as_bytes())?;
            println!("report written to {out}");
        }
        Some("pdf") => {
            let tmp = args.output.with_extension("pdf.html");
            std::fs::write(&tmp, page).with_context(|| format!("cannot write '{}'", tmp.display()))?;
            let printed = print_pdf(&tmp, &args.output);
            let _ = std::fs::remove_file(&tmp);
            printed?;
            println!("report written to {out} (the HTML report printed by headless Chromium)");
        }
        _ => bail!("--output '{out}' must end in .html (or .pdf, printed by headless Chromium)"),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hourly samples for 48 h at 4 °C, 10 °C from hour 20 to hour 31 (the sample at 31 is back
    /// at 4 °C), the sensor out at hour 40.
    fn log() -> (Vec<f64>, Vec<Option<f64>>) {
        let t: Vec<f64> = (0..=48).map(|h| 3600.0 * f64::from(h)).collect();
        let temp = (0..=48).map(|h| if h == 40 { None } else { Some(if (20..31).contains(&h) { 10.0 } else { 4.0 }) });
        (t, temp.collect())
    }

    #[test]
    fn days_split_intervals_at_midnight_of_the_record() {
        let (t, temp) = log();
        let r = monitor_cmd::report(&t, &temp).unwrap();
        assert_eq!(r.alarms, vec![AlarmOut { kind: "heat_10h", start_s: 72_000.0, trigger_s: 108_000.0 }]);
        let spans = alarm_spans(&t, &temp, r.alarms.clone());
        // Eleven hourly intervals at 10 °C; the reading at hour 31 ends the run.
        assert_eq!((spans[0].end_s, spans[0].duration_s, spans[0].ongoing), (111_600.0, 39_600.0, false));
        let d = days(&t, &temp, &[], &spans);
        assert_eq!(d.len(), 2);
        // Hours 20–24 on day 1, 24–31 on day 2: the split adds up to the monitor's total.
        assert_eq!((d[0].above_8_s, d[1].above_8_s), (4.0 * 3600.0, 7.0 * 3600.0));
        assert_eq!(d[0].above_8_s + d[1].above_8_s, r.time_above_8_s);
        assert_eq!((d[0].min_c, d[0].max_c, d[1].max_c), (Some(4.0), Some(10.0), Some(10.0)));
        // Day 1: 20 h at 4, 4 h at 10; day 2: 7 h at 10, 16 h at 4 (hour 40–41 has no reading).
        assert!((d[0].mean_c.unwrap() - (20.0 * 4.0 + 4.0 * 10.0) / 24.0).abs() < 1e-12);
        assert!((d[1].mean_c.unwrap() - (7.0 * 10.0 + 16.0 * 4.0) / 23.0).abs() < 1e-12);
        assert_eq!((d[0].alarms.clone(), d[1].alarms.clone()), (vec!["heat_10h"], vec!["heat_10h"]));
        assert_eq!(verdict(&r, 0).0, "excursion");
    }

    #[test]
    fn a_freeze_reading_is_a_freeze_risk_and_a_clean_log_is_in_range() {
        let t = [0.0, 60.0, 120.0];
        let r = monitor_cmd::report(&t, &[Some(4.0), Some(-0.6), Some(4.0)]).unwrap();
        assert_eq!(verdict(&r, 0).0, "freeze");
        let r = monitor_cmd::report(&t, &[Some(4.0), Some(5.0), Some(4.0)]).unwrap();
        assert_eq!(verdict(&r, 0).0, "ok");
    }

    /// Every reset and fault the library can record reads in plain words in the header.
    #[test]
    fn every_reset_and_fault_the_library_records_has_a_meaning() {
        for k in hter::event::EventKind::ALL {
            let e = Event { t_s: 0.0, name: k.name().to_owned() };
            assert_eq!(is_reset_or_fault(&e), fault_meaning(k.name()).is_some(), "{}", k.name());
            // Every hardware fault the supervisor detects but a weak supply and a lid left open
            // asks for a technician.
            if k.is_hardware_fault() {
                let service = fault_meaning(k.name()).unwrap().1;
                let expected = !matches!(k, hter::event::EventKind::SupplySag | hter::event::EventKind::LidOpen);
                assert_eq!(service, expected, "{}", k.name());
            }
        }
        let text = |n: &str| fault_meaning(n).unwrap().0;
        assert!(text("restarted:brownout").contains("supply dropped"));
        assert!(text("log_entries_lost:25").starts_with("25 record entries were lost"));
        assert!(text("log_entries_lost:1").starts_with("1 record entry was lost"));
        assert!(text("log_entries_lost").starts_with("record entries were lost"));
        assert!(text("ssr_stuck_on").ends_with("; the carrier needs a service check"));
        assert!(text("record_refused_calibration").contains("reads without it (up to 1.5 °C off)"));
        assert!(text("record_refused_calibration").ends_with("; the carrier needs a service check"));
        assert_eq!(fault_meaning("record_refused_nothing"), None);
        assert_eq!(fault_meaning("no_such_event"), None);
    }

    #[test]
    fn the_envelope_keeps_the_extremes() {
        let pts: Vec<(f64, f64)> = (0..100_000).map(|i| (f64::from(i), if i == 54_321 { 99.0 } else { 4.0 })).collect();
        let e = envelope_to(pts, MAX_PLOT_POINTS);
        assert!(e.len() <= MAX_PLOT_POINTS + 2, "{}", e.len());
        assert!(e.contains(&(54_321.0, 99.0)));
        assert!(e.windows(2).all(|w| w[0].0 < w[1].0));
    }

    /// The plot's line breaks where there is no reading: one NaN between two runs, none at the
    /// ends or for a gap at the start; the runs share the points' budget and keep their extremes.
    #[test]
    fn the_plots_line_breaks_where_there_is_no_reading() {
        let pts: Vec<(f64, Option<f64>)> = (0..100_000)
            .map(|i| {
                let c = match i {
                    0..10 | 40_000..60_000 => None,
                    12_345 => Some(-3.0),
                    77_777 => Some(11.0),
                    _ => Some(4.0),
                };
                (f64::from(i), c)
            })
            .collect();
        let line = broken(&pts);
        let nans: Vec<usize> = line.iter().enumerate().filter(|(_, p)| p.1.is_nan()).map(|(i, _)| i).collect();
        assert_eq!(nans.len(), 1, "one break");
        let k = nans[0];
        // The break sits between the last reading before the gap and the first after it.
        assert!(
            line[k - 1].0 < 40_000.0 && line[k].0 == 60_000.0 && line[k + 1].0 == 60_000.0,
            "{:?}",
            &line[k - 1..=k + 1]
        );
        assert!(line.first().is_some_and(|p| p.0 >= 10.0 && !p.1.is_nan()));
        assert!(line.len() <= MAX_PLOT_POINTS + 6, "{}", line.len());
        assert!(line.contains(&(12_345.0, -3.0)) && line.contains(&(77_777.0, 11.0)));
        assert!(line.windows(2).all(|w| w[0].0 <= w[1].0));
        // No gap, no break.
        assert!(broken(&[(0.0, Some(4.0)), (1.0, Some(5.0))]).iter().all(|p| !p.1.is_nan()));
    }
}
