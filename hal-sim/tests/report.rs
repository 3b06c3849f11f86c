//! `hter report` as a user runs it: from a simulator run and from a board history to one HTML
//! page that agrees with `hter monitor` on every alarm and on MKT, that a real headless browser
//! renders, and bad input as a one-line error.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hter-report-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn ok(out: &Output) {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `(kind, start_s, trigger_s)` of each alarm row of the report, in page order.
fn page_alarms(html: &str) -> Vec<(String, f64, f64)> {
    let attr = |row: &str, name: &str| -> String {
        let from = row.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        row[from..].split('"').next().unwrap().to_owned()
    };
    html.split("<tr class=\"alarm\"")
        .skip(1)
        .map(|row| {
            (
                attr(row, "data-kind"),
                attr(row, "data-start-s").parse().unwrap(),
                attr(row, "data-trigger-s").parse().unwrap(),
            )
        })
        .collect()
}

/// The monitor's alarms in the same form, sorted like the page (by kind, library order).
fn monitor_alarms(v: &serde_json::Value) -> Vec<(String, f64, f64)> {
    let order = ["heat_10h", "freeze_60min", "ship_45c_1h", "ship_30c_10h"];
    let mut a: Vec<(String, f64, f64)> = v["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (a["kind"].as_str().unwrap().to_owned(), a["start_s"].as_f64().unwrap(), a["trigger_s"].as_f64().unwrap())
        })
        .collect();
    a.sort_by_key(|x| order.iter().position(|k| *k == x.0));
    a
}

/// Runs `hter report` and `hter monitor --json` on `csv`; checks they agree on the alarms and
/// MKT; returns the page.
fn report_agreeing_with_monitor(csv: &Path, html: &Path) -> String {
    ok(&hter(&["report", "--input", s(csv), "--output", s(html)]));
    let page = std::fs::read_to_string(html).unwrap();
    let out = hter(&["monitor", "--input", s(csv), "--json"]);
    ok(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(page_alarms(&page), monitor_alarms(&v));
    let mkt = format!("id=\"mkt\">{:.2} °C<", v["mkt_c"].as_f64().unwrap());
    assert!(page.contains(&mkt), "{mkt} not in the page");
    assert!(page.contains("<svg"), "no inline SVG");
    page
}

fn day_rows(page: &str) -> usize {
    page.matches("<tr class=\"day").count()
}

/// A screenshot of the page in headless Chromium, when it is installed (CI installs it).
fn render_check(html: &Path, png: &Path) {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.exists() {
        println!("note: /usr/bin/chromium is absent, the render check is skipped");
        return;
    }
    let out = Command::new(chromium)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--window-size=1200,1600"])
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!("file://{}", std::fs::canonicalize(html).unwrap().display()))
        .output()
        .expect("run chromium");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let size = std::fs::metadata(png).unwrap().len();
    assert!(size > 30_000, "screenshot only {size} bytes");
    let img = image::open(png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1200, 1600));
    // The page drew: the verdict banner's colour, dark text and the white page all appear.
    let (mut white, mut dark, mut banner) = (0u32, 0u32, 0u32);
    for p in img.pixels() {
        let [r, g, b] = p.0;
        if r > 245 && g > 245 && b > 245 {
            white += 1;
        } else if r < 80 && g < 80 && b < 80 {
            dark += 1;
        } else if (r, g, b) == (0x2e, 0x7d, 0x32) || (r, g, b) == (0xe6, 0x51, 0x00) {
            banner += 1;
        }
    }
    let n = 1200 * 1600;
    assert!(white > n / 4 && dark > 2_000 && banner > 10_000, "white {white}, dark {dark}, banner {banner}");
}

#[test]
fn a_hot_zone_run_gives_a_report_of_three_days_that_agrees_with_monitor_and_renders() {
    let d = dir("hot-zone");
    let csv = d.join("h.csv");
    ok(&hter(&["sim", "--scenario", "hot-zone", "--csv", s(&csv)]));
    let html = d.join("r.html");
    let page = report_agreeing_with_monitor(&csv, &html);
    // hot-zone runs 72 h: three days, no alarm (the controller holds 4 °C at 43 °C ambient).
    assert_eq!(day_rows(&page), 3);
    assert!(page.contains("No alarm was raised") && page.contains("IN RANGE"));
    assert!(!page.contains("id=\"service\""), "nothing for a technician on a clean run");
    assert!(page.contains("no calendar date"));
    render_check(&html, &d.join("r.png"));

    // The same run with the SSR failing open on day 2: the load warms to ambient.
    let csv = d.join("hf.csv");
    ok(&hter(&["sim", "--scenario", "hot-zone", "--fault", "ssr-stuck-off@100000", "--csv", s(&csv)]));
    let html = d.join("rf.html");
    let page = report_agreeing_with_monitor(&csv, &html);
    let kinds: Vec<String> = page_alarms(&page).into_iter().map(|a| a.0).collect();
    assert_eq!(kinds, ["heat_10h", "ship_30c_10h"]);
    assert_eq!(day_rows(&page), 3);
    assert!(page.contains("EXCURSIONS"));
    // The whole period and days 2 and 3 (alarms under way) are plotted.
    assert_eq!(page.matches("<svg").count(), 3);
    assert!(page.contains("Day 2 (alarms") && page.contains("Day 3 (alarms") && !page.contains("Day 1 (alarms"));
    render_check(&html, &d.join("rf.png"));
    if Path::new("/usr/bin/chromium").exists() {
        let pdf = d.join("rf.pdf");
        ok(&hter(&["report", "--input", s(&csv), "--output", s(&pdf)]));
        let bytes = std::fs::read(&pdf).unwrap();
        assert!(bytes.starts_with(b"%PDF") && bytes.len() > 10_000, "{} bytes", bytes.len());
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// A board history (docs/interface.md): 5-min interval rows for 26 h, 4 °C but 12 °C for 11 h
/// from hour 2, and event rows (the settings change, a brownout restart, log entries lost in the
/// minute after it, the alarm, a sensor fault), some at the same time as an interval row, with
/// the temperatures repeated or empty.
fn history() -> String {
    let mut s = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
    for i in 1..=(26 * 12) {
        let t = 300 * i;
        let c = if (2 * 3600..13 * 3600).contains(&t) { 12.0 } else { 4.0 };
        s.push_str(&format!("{t},{c:.2},{:.2},{:.2},0.40,normal,\n", c - 0.1, c + 0.1));
        match t {
            600 => s.push_str("600,4.00,3.90,4.10,,,set:setpoint_c=4.00\n"),
            7500 => s.push_str("7600,12.00,11.90,12.10,,,restarted:brownout\n7650,,,,,,log_entries_lost:12\n"),
            // 10 h above 8 °C from 7200 s.
            43200 => s.push_str("43200,,,,,,alarm:heat_10h\n"),
            60000 => s.push_str("60100,4.00,3.90,4.10,,,sensor_open\n"),
            _ => {}
        }
    }
    s
}

#[test]
fn a_board_history_gives_a_report_with_its_resets_and_faults() {
    let d = dir("history");
    let csv = d.join("history.csv");
    std::fs::write(&csv, history()).unwrap();
    let html = d.join("h.html");
    let page = report_agreeing_with_monitor(&csv, &html);
    // 0 … 93 600 s (each row covers the 5 min that end at its `t_s`): 26 h, two report days.
    assert_eq!(day_rows(&page), 2);
    let alarms = page_alarms(&page);
    // The 12 °C rows end at 7 200 … 46 500 s: above 8 °C from 6 900 s, 10 h of it at 42 900 s.
    assert_eq!(alarms, [("heat_10h".to_owned(), 6900.0, 42900.0)]);
    assert!(page.contains("restarted:brownout") && page.contains("sensor_open"), "resets and faults listed");
    assert!(page.contains("<li>log_entries_lost:12"), "a hole in the record is listed with the faults, with its size");
    // Each in plain words for the supervisor who reads it.
    assert!(page.contains("12 record entries were lost while the controller waited"), "the hole's size, in words");
    assert!(page.contains("the temperature probe or its circuit failed"), "what sensor_open means");
    assert!(page.contains("supply dropped too low"), "what a brown-out restart means");
    // The load's verdict says nothing of the carrier: a second banner does.
    assert!(
        page.contains("SERVICE NEEDED — 1 fault that needs a service check, the first sensor_open"),
        "the sensor fault asks for a technician; the restart and the lost entries do not"
    );
    assert!(!page.contains("<li>set:"), "a settings change is not a fault");
    // The event rows are not intervals: 312 interval rows, and the one with empty temperatures
    // is no sensor fault to the monitor either.
    assert!(page.contains("312 intervals of up to 5 min"), "event rows counted as intervals");
    let out = hter(&["monitor", "--input", s(&csv), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["fault_samples"].as_u64(), v["time_above_8_s"].as_f64()), (Some(0), Some(11.0 * 3600.0)), "{v}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A day of a board history at 4.0 ± 0.1 °C whose 5-minute means never leave 2–8 °C: in the
/// interval ending at 6 h the load dipped to `dip` °C between readings (the mean stays 4.0),
/// and, when `alarm` is given, the carrier recorded that alarm event at 8 h.
fn history_with_a_dip(dip: f64, alarm: Option<&str>) -> String {
    let mut s = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
    for i in 1..=288 {
        let t = 300 * i;
        let lo = if t == 6 * 3600 { dip } else { 3.9 };
        s.push_str(&format!("{t},4.00,{lo:.2},4.10,0.40,normal,\n"));
        if let (Some(a), 28_800) = (alarm, t) {
            s.push_str(&format!("{t},,,,,,{a}\n"));
        }
    }
    s
}

#[test]
fn a_history_reports_the_extremes_and_the_carriers_alarms_its_means_miss() {
    let d = dir("extremes");
    let html = d.join("r.html");
    let read = |name: &str, text: &str| {
        let csv = d.join(name);
        std::fs::write(&csv, text).unwrap();
        let page = report_agreeing_with_monitor(&csv, &html);
        let out = hter(&["monitor", "--input", s(&csv), "--json"]);
        (page, serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap())
    };
    let verdict = |page: &str| page.split("id=\"verdict\">").nth(1).unwrap().split('<').next().unwrap().to_owned();

    // In range: the extremes inside 2–8 °C.
    let (page, v) = read("clean.csv", &history_with_a_dip(3.0, None));
    assert!(verdict(&page).starts_with("IN RANGE"), "{}", verdict(&page));
    assert_eq!((v["min_c"].as_f64(), v["intervals_outside_2_8"].as_u64()), (Some(3.0), Some(0)));

    // A dip to 1.5 °C inside one interval: an excursion, though every mean is 4.0.
    let (page, v) = read("dip.csv", &history_with_a_dip(1.5, None));
    assert!(verdict(&page).starts_with("EXCURSIONS"), "{}", verdict(&page));
    assert_eq!((v["min_c"].as_f64(), v["intervals_outside_2_8"].as_u64()), (Some(1.5), Some(1)), "{v}");
    assert_eq!(v["time_below_2_s"], 0.0, "the times stay the means'");
    assert!(page.contains("id=\"intervals-outside\">1<"), "the interval is counted on the page");
    assert!(page.contains("<tr class=\"day bad\"><td>1</td><td>1.5</td>"), "the day's min is the dip");

    // A dip to −5 °C: the vaccines may have frozen.
    let (page, _) = read("freeze.csv", &history_with_a_dip(-5.0, None));
    assert!(verdict(&page).starts_with("FREEZE RISK"), "{}", verdict(&page));

    // The carrier's own freeze alarm (it checks every 10 s sample), which the means do not
    // show: listed, and the verdict is the alarm's.
    let (page, v) = read("alarm.csv", &history_with_a_dip(3.0, Some("alarm:freeze_60min@25200")));
    assert!(verdict(&page).starts_with("FREEZE RISK"), "{}", verdict(&page));
    assert_eq!(v["alarms"].as_array().map(Vec::len), Some(0), "the means meet no alarm: {v}");
    let carrier = &v["carrier_alarms"][0];
    assert_eq!(
        (carrier["kind"].as_str(), carrier["start_s"].as_f64(), carrier["trigger_s"].as_f64()),
        (Some("freeze_60min"), Some(25_200.0), Some(28_800.0)),
        "{v}"
    );
    assert!(page.contains("<tr class=\"alarm-carrier\" data-kind=\"freeze_60min\""), "listed on the page");

    // Intervals the board ran on a sensor fault hold its last good reading (4.00 / 4.00 /
    // 4.00): no reading, and no "in range" for the period.
    let faulted: String = history_with_a_dip(3.0, None)
        .lines()
        .map(|l| {
            let t: u32 = l.split(',').next().unwrap().parse().unwrap_or(0);
            if (36_000..=43_200).contains(&t) {
                format!("{t},4.00,4.00,4.00,0.00,sensor_fault,\n")
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let (page, v) = read("faulted.csv", &faulted);
    assert!(verdict(&page).starts_with("NOT FULLY RECORDED"), "{}", verdict(&page));
    assert_eq!(v["fault_samples"].as_u64(), Some(25), "{v}");
    assert!(v["time_no_reading_s"].as_f64().unwrap() >= 7_200.0, "{v}");

    // A board from before the fix logged an event found on the sample that closed an interval
    // a second after its end and before the interval's row: read, the event in its place.
    let early = history_with_a_dip(3.0, None).replace("\n3000,4.00", "\n3001,,,,,,sensor_offset\n3000,4.00");
    assert!(early.contains("\n3001,,,,,,sensor_offset\n3000,4.00"));
    let (page, v) = read("early.csv", &early);
    assert_eq!(v["fault_samples"].as_u64(), Some(0), "{v}");
    // 3 001 s from the start of the first interval, 0 s.
    assert!(page.contains("<li>sensor_offset — day 1, 00:50"), "the event is listed");

    // Extremes that contradict their mean are a corrupt record.
    let p = d.join("contradicts.csv");
    std::fs::write(&p, history_with_a_dip(3.0, None).replace("300,4.00,3.90,4.10", "300,4.00,4.50,4.10")).unwrap();
    assert_one_line_error(&["monitor", "--input", s(&p)], "line 2: min_c 4.5 °C is above max_c 4.1 °C");
    let _ = std::fs::remove_dir_all(&d);
}

/// A board history's rows are intervals of up to 5 min, each the summary of 30 samples: `hter
/// monitor` and `hter report` said "(288 samples)" of a day's history and "(25 samples; counted
/// neither in nor out of range)" of two hours without a reading, and counted a hole of lost log
/// entries (here 2 h) as one sample more.
#[test]
fn a_historys_rows_are_counted_as_intervals() {
    let d = dir("counts");
    let (csv, html) = (d.join("h.csv"), d.join("r.html"));
    let counts = |text: &str| {
        std::fs::write(&csv, text).unwrap();
        let out = hter(&["monitor", "--input", s(&csv)]);
        ok(&out);
        ok(&hter(&["report", "--input", s(&csv), "--output", s(&html)]));
        (String::from_utf8_lossy(&out.stdout).into_owned(), std::fs::read_to_string(&html).unwrap())
    };
    let rows: Vec<String> = history_with_a_dip(3.0, None).lines().map(str::to_owned).collect();
    let t_of = |l: &str| l.split(',').next().unwrap().parse::<u32>().unwrap_or(0);

    // Two hours on a sensor fault: 25 interval rows with no reading.
    let faulted: String = rows
        .iter()
        .map(|l| {
            let t = t_of(l);
            if (36_000..=43_200).contains(&t) {
                format!("{t},4.00,4.00,4.00,0.00,sensor_fault,\n")
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let (text, page) = counts(&faulted);
    assert!(text.contains(&format!("cold-chain record of {} (288 intervals of up to 5 min)", csv.display())), "{text}");
    assert!(text.contains("(25 intervals; counted neither in nor out of range)"), "{text}");
    assert!(page.contains("(288 intervals of up to 5 min, t = 0 … 86400 s)"), "the period");
    assert!(page.contains("(25 intervals; counted neither in nor out of range)"), "the rows with no reading");
    assert!(text.contains("no reading (sensor fault)") && page.contains("No reading (sensor fault)"), "{text}");
    assert!(!text.contains("samples") && !page.contains(" samples"), "{text}");

    // The rows from 36 300 to 43 200 s lost before they reached flash: 264 rows and a hole.
    let mut holed: String =
        rows.iter().filter(|l| !(36_300..=43_200).contains(&t_of(l))).map(|l| format!("{l}\n")).collect();
    holed = holed.replace("\n43500,", "\n43200,,,,,,log_entries_lost:24\n43500,");
    let (text, page) = counts(&holed);
    assert!(text.contains("(264 intervals of up to 5 min)"), "{text}");
    assert!(text.contains("(1 hole of lost log entries; counted neither in nor out of range)"), "{text}");
    assert!(page.contains("(264 intervals of up to 5 min, t = 0 … 86400 s)"), "the period");
    assert!(page.contains("(1 hole of lost log entries; counted neither"), "the hole");
    // The record lost them, not the probe: the row and the verdict say so.
    assert!(text.contains("no reading (lost log entries)") && !text.contains("sensor fault"), "{text}");
    assert!(page.contains("No reading (lost log entries)") && !page.contains("sensor fault"), "the row's label");
    assert!(page.contains("part of the record was lost") && !page.contains("the probe gave no reading"), "the verdict");
    // Both at once: each named.
    let both = holed.replace("\n3600,4.00,3.90,4.10,0.40,normal,", "\n3600,4.00,4.00,4.00,0.00,sensor_fault,");
    assert_ne!(both, holed);
    let (text, page) = counts(&both);
    // Wider than the label column: on its own line, the figure under the others' (it pushed the
    // figure 18 columns right).
    let under = format!("no reading (sensor fault; lost log entries)\n{}", " ".repeat(28));
    assert!(text.contains(&under), "{text}");
    assert!(
        page.contains("the probe gave no reading for part of the period and part of the record was lost"),
        "the verdict"
    );

    // A log of samples keeps its word.
    std::fs::write(&csv, "t_s,temp_c\n0,4\n10,\n20,4\n30,4\n").unwrap();
    let out = hter(&["monitor", "--input", s(&csv)]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("(4 samples)") && text.contains("(1 sample; counted neither"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}

fn assert_one_line_error(args: &[&str], needle: &str) {
    let out = hter(args);
    assert!(!out.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: not one line: {err}");
    assert!(err.starts_with("error: ") && err.contains(needle) && !err.contains("panicked"), "{args:?}: {err}");
}

#[test]
fn bad_input_is_a_one_line_error() {
    let d = dir("bad");
    let out = d.join("out.html");
    let o = s(&out);
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    assert_one_line_error(&["report", "--input", "/no/such/log.csv", "--output", o], "/no/such/log.csv");
    let p = write("empty.csv", "");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "missing column 't_s'");
    let p = write("header-only.csv", "t_s,temp_c\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "it has 0");
    let p = write("no-temp.csv", "t_s,duty\n0,0.5\n10,0.5\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "missing column 'temp_c'");
    let p = write("back.csv", "t_s,temp_c\n0,4\n10,4\n5,4\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "line 4");
    let p = write("event-back.csv", "t_s,temp_c,event\n0,4,\n10,4,\n5,,restarted:watchdog\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "goes back in time");
    let p = write("nan.csv", "t_s,temp_c\n0,4\n10,inf\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", o], "finite");
    let p = write("good.csv", "t_s,temp_c\n0,4\n10,4\n");
    assert_one_line_error(&["report", "--input", s(&p), "--output", s(&d.join("r.docx"))], ".html");
    assert!(!out.exists(), "no report written for bad input");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_log2csv_output_lists_its_resets() {
    let d = dir("log2csv");
    let csv = d.join("carrier.csv");
    let mut text = String::from("t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm,boot,reset_cause\n");
    for i in 0..=60 {
        let cause = match i {
            0 => "restarted",
            30 => "restarted_watchdog",
            45 => "unknown",
            _ => "",
        };
        let boot = u32::from(i >= 30) + u32::from(i >= 45);
        // The sensor is out for one sample in boot 1.
        let temp = if i == 40 { String::new() } else { "4.0".to_owned() };
        text.push_str(&format!("{},4.0,{temp},0.4,normal,,,off,{boot},{cause}\n", 10 * i));
    }
    std::fs::write(&csv, text).unwrap();
    let page = report_agreeing_with_monitor(&csv, &d.join("c.html"));
    assert!(page.contains("<li>restarted_watchdog") && page.contains("<li>restarted: unknown"), "resets listed");
    assert!(page.contains("Resets and faults</th><td>3:"), "three boots, three resets");
    assert!(page.contains("SERVICE NEEDED — 1 fault that needs a service check, the first restarted_watchdog"));
    assert!(page.contains("No reading (sensor fault)"));
    assert_eq!(day_rows(&page), 1);
    let _ = std::fs::remove_dir_all(&d);
}

/// `hter sim --csv` carries the step's events in its `events` cell, as `hter log2csv` writes a
/// board's: a simulated fail-safe stop reaches `hter report` and `hter monitor` as a board's
/// does, the reset and the stop that needs a service check; a run without a fault lists none.
#[test]
fn a_simulated_board_fault_reaches_the_report_as_a_service_check() {
    let d = dir("sim-board-fault");
    let (csv, clean) = (d.join("t.csv"), d.join("clean.csv"));
    let run = ["sim", "--scenario", "disturbance", "--csv"];
    ok(&hter(&[&run[..], &[s(&csv), "--fault", "board-fault-hard-fault@3000"]].concat()));
    let page = report_agreeing_with_monitor(&csv, &d.join("r.html"));
    let service = "SERVICE NEEDED — 1 fault that needs a service check, the first board_fault_hard_fault";
    assert!(page.contains(service), "the stop needs a service check");
    assert!(page.contains("Resets and faults</th><td>2:"), "the reset and the stop");
    assert!(page.contains("<li>restarted") && page.contains("<li>board_fault_hard_fault"), "both listed");
    ok(&hter(&[&run[..], &[s(&clean)]].concat()));
    let page = report_agreeing_with_monitor(&clean, &d.join("clean.html"));
    assert!(!page.contains("SERVICE NEEDED") && !page.contains("<li>restarted"), "a clean run lists no reset");
    let _ = std::fs::remove_dir_all(&d);
}

/// A simulated trace whose probe opens 2 h in: the carrier holds its last good reading in
/// `temp_c` (mode `sensor_fault`) while the load warms towards the ambient. `hter monitor`
/// counts the 2 h after as no reading: its record is the first 2 h's, to the figure (MKT,
/// extremes, time in and out of range, alarms), however warm the load truly got.
#[test]
fn a_sim_trace_through_a_sensor_fault_records_nothing_of_the_fault() {
    let d = dir("sim-fault");
    let (csv, head) = (d.join("t.csv"), d.join("head.csv"));
    ok(&hter(&["sim", "--fault", "sensor-open@7200", "--duration", "14400", "--csv", s(&csv)]));
    let text = std::fs::read_to_string(&csv).unwrap();
    // Up to the first fault sample, at 7 200 s.
    let t_of = |l: &str| l.split(',').next().unwrap().parse::<f64>().unwrap_or(0.0);
    let first: String = text.lines().filter(|l| t_of(l) <= 7200.0).map(|l| format!("{l}\n")).collect();
    std::fs::write(&head, first).unwrap();
    let truly_warm = text.lines().skip(1).filter(|l| t_of(l) > 7200.0).any(|l| {
        let true_c = l.split(',').nth(5).unwrap().parse::<f64>().unwrap();
        true_c > 8.0
    });
    assert!(truly_warm, "the load warms past 8 °C after the fault");
    let json = |p: &Path| -> serde_json::Value {
        let out = hter(&["monitor", "--input", s(p), "--json"]);
        ok(&out);
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let (all, before) = (json(&csv), json(&head));
    // From the first fault sample to the last sample, at 14 390 s.
    assert_eq!((all["time_no_reading_s"].as_f64(), all["fault_samples"].as_u64()), (Some(7190.0), Some(720)), "{all}");
    for key in
        ["mkt_c", "min_c", "max_c", "time_below_2_s", "time_above_8_s", "time_in_range_s", "alarms", "excursions"]
    {
        assert_eq!(all[key], before[key], "{key}: {all} vs {before}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// The report's plot breaks its lines where the history has no reading: two hours on a sensor
/// fault draw the temperature and the intervals' extremes as two lines each, not one line
/// across the gap, which showed a temperature nobody measured (the rows hold the step's last
/// reading, 4.00 °C). The SVG draws each line, and each legend entry, as a `<polyline>` in the
/// series' colour.
#[test]
fn the_reports_plot_breaks_its_lines_over_a_sensor_fault() {
    let d = dir("plot-gap");
    let (csv, html) = (d.join("h.csv"), d.join("r.html"));
    let lines = |fault: &str| {
        let mut text = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
        for t in (1..=288).map(|i| 300 * i) {
            let mode = if (36_000..=43_200).contains(&t) { fault } else { "normal" };
            text.push_str(&format!("{t},4.00,3.90,4.10,0.40,{mode},\n"));
        }
        std::fs::write(&csv, text).unwrap();
        ok(&hter(&["report", "--input", s(&csv), "--output", s(&html)]));
        let page = std::fs::read_to_string(&html).unwrap();
        // Temperature, interval lowest, interval highest: the plot's first three colours.
        ["#1F77B4", "#D62728", "#2CA02C"].map(|c| page.matches(&format!("stroke=\"{c}\"")).count())
    };
    assert_eq!(lines("normal"), [2, 2, 2], "one line each and its legend");
    assert_eq!(lines("sensor_fault"), [3, 3, 3], "two lines each and the legend");
    let _ = std::fs::remove_dir_all(&d);
}
