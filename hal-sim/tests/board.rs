//! `hter board` as a user runs it, against a [`PtyLink`] served in-process by a small scripted
//! stand-in that answers per docs/interface.md. The stand-in is a test double of this file
//! only (fixed replies, no plant, no handler); the end-to-end test against `hter
//! virtual-board` is separate.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use hal_sim::link::PtyLink;

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("hter-board-test-{}-{name}", std::process::id()))
}

/// The history the stand-in sends: an event at the same time as an interval's end, and a
/// model event whose value has commas (quoted, as a CSV field must be).
const HISTORY: &str = "t_s,temp_c,min_c,max_c,duty,mode,event\n\
                       0,7.80,7.80,7.80,,,restarted:power_on\n\
                       300,6.10,4.90,7.80,0.800,normal,\n\
                       300,6.10,6.10,6.10,,,set:setpoint_c=5.00\n\
                       600,5.05,4.85,5.30,0.420,normal,\n\
                       750,5.05,5.05,5.05,,,\"set:model=-1.79,0.80;-0.015,-0.008;1\"\n\
                       900,4.98,4.80,5.20,0.400,normal,\n";

/// Scripted answers: `status`, `get`, `set setpoint_c V` (accepted 2.5…7.5 as a plain
/// decimal, refused otherwise), `history`, `identify` with a fixed run of commissioning states.
struct Script {
    setpoint_c: f64,
    commissioning: Vec<&'static str>,
}

impl Script {
    fn status(&mut self) -> String {
        let c = if self.commissioning.len() > 1 { self.commissioning.remove(0) } else { self.commissioning[0] };
        format!(
            "t_s=86400\ntemp_c=4.93\nsetpoint_c={:.2}\nduty=0.412\nmode=normal\nalarm=off\ncontroller=gpc\n\
             adaptive=adaptive\ncontrollers=gpc,pi,onoff\nmodel_a=-1.7900,0.8000\nmodel_b=-0.0150,-0.0080\n\
             model_k=1\ncabinet_a=-1.9390,0.9392\ncabinet_b=-0.2798,0.2717\ncabinet_k=9\nholdover_s=-\nresets=2\nfirmware=hter 0.1.0\ncommissioning={c}\nsettings_version=7\nok",
            self.setpoint_c
        )
    }

    fn answer(&mut self, line: &str) -> String {
        let words: Vec<&str> = line.split(' ').collect();
        match words.as_slice() {
            ["status"] => self.status(),
            ["get"] => format!("setpoint_c={:.2}\ncontroller=gpc\nok", self.setpoint_c),
            ["set", "setpoint_c", v] => {
                let decimal = !v.is_empty() && v.chars().all(|c| c.is_ascii_digit() || c == '.' || c == '-');
                match v.parse::<f64>() {
                    Ok(x) if decimal && (2.5..=7.5).contains(&x) => {
                        self.setpoint_c = x;
                        "ok".into()
                    }
                    Ok(_) if decimal => format!("err setpoint_c: {v} is outside 2.5…7.5 °C"),
                    _ => "err setpoint_c: not a decimal number".into(),
                }
            }
            ["history"] => format!("{HISTORY}ok"),
            ["history", "0"] => format!("{}ok", month()),
            ["identify"] => "ok".into(),
            _ => format!("err {}: unknown command", words[0]),
        }
    }
}

/// 30 days of 5-minute intervals and an event a day: the record's full size, about 0.4 MB.
fn month() -> String {
    let mut csv = String::from("t_s,temp_c,min_c,max_c,duty,mode,event\n");
    for i in 1..=30 * 288 {
        let t = 300 * i;
        let c = 5.0 + 0.5 * (f64::from(i) / 40.0).sin();
        csv += &format!("{t},{c:.2},{:.2},{:.2},0.412,normal,\n", c - 0.3, c + 0.3);
        if i % 288 == 0 {
            csv += &format!("{t},{c:.2},{c:.2},{c:.2},,,alarm:heat_10h\n");
        }
    }
    csv
}

struct Fake {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    /// The requests it heard, in order.
    heard: Arc<Mutex<Vec<String>>>,
    thread: Option<JoinHandle<()>>,
}

impl Fake {
    fn start(name: &str, commissioning: Vec<&'static str>) -> Self {
        let path = tmp(name);
        let mut link = PtyLink::open(&path).expect("open the pty");
        let stop = Arc::new(AtomicBool::new(false));
        let (halt, heard) = (stop.clone(), Arc::new(Mutex::new(Vec::new())));
        let log = heard.clone();
        let thread = std::thread::spawn(move || {
            let mut script = Script { setpoint_c: 5.0, commissioning };
            while !halt.load(Ordering::Relaxed) {
                if let Some(line) = link.poll_line(Duration::from_millis(20)).expect("poll") {
                    link.send(&script.answer(&line)).expect("send");
                    log.lock().unwrap().push(line);
                }
            }
        });
        Self { path, stop, heard, thread: Some(thread) }
    }

    fn port(&self) -> &str {
        self.path.to_str().unwrap()
    }

    /// Stops the stand-in; the requests it heard, in order.
    fn finish(mut self) -> Vec<String> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().unwrap().join().unwrap();
        assert!(!self.path.exists(), "the link's symlink outlived it");
        std::mem::take(&mut *self.heard.lock().unwrap())
    }
}

fn assert_one_line_error(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "should fail: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
    assert!(err.starts_with("error: ") && err.contains(needle), "'{needle}' not in: {err}");
}

#[test]
fn status_and_settings_over_successive_connections() {
    let fake = Fake::start("status", vec!["idle"]);
    let port = fake.port();
    let o = hter(&["board", "--port", port, "status", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("one JSON object");
    assert_eq!(v["t_s"], 86400);
    assert_eq!(v["temp_c"], 4.93);
    assert_eq!(v["setpoint_c"], 5.0);
    assert_eq!(v["model"], serde_json::json!({"a": [-1.79, 0.8], "b": [-0.015, -0.008], "k": 1}));
    assert_eq!(v["holdover_s"], serde_json::Value::Null);
    assert_eq!((v["resets"].as_u64(), v["firmware"].as_str()), (Some(2), Some("hter 0.1.0")));
    assert_eq!(v["mode"], "normal");

    let o = hter(&["board", "--port", port, "set", "setpoint_c", "12"]);
    assert_one_line_error(&o, "err setpoint_c: 12 is outside 2.5…7.5 °C");
    // A value the board's parser calls "not a decimal number" is explained by the client, which
    // parses it as the board does, and not sent.
    let o = hter(&["board", "--port", port, "set", "setpoint_c", "nan"]);
    assert_one_line_error(&o, "setpoint_c takes a plain decimal number");
    let o = hter(&["board", "--port", port, "set", "setpoint_c", "4"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = hter(&["board", "--port", port, "status"]);
    assert!(stdout(&o).lines().any(|l| l == "setpoint_c=4.00"), "{}", stdout(&o));
    // The client refuses a value that would smuggle in a second line, before sending.
    let o = hter(&["board", "--port", port, "set", "setpoint_c", "5\nset controller pi"]);
    assert_one_line_error(&o, "not allowed in a request");

    let heard = fake.finish();
    assert_eq!(heard, ["status", "set setpoint_c 12", "set setpoint_c 4", "status"]);
}

#[test]
fn history_goes_verbatim_into_a_csv_monitor_reads() {
    let fake = Fake::start("history", vec!["idle"]);
    let csv = tmp("history.csv");
    let o = hter(&["board", "--port", fake.port(), "history", "--output", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stdout(&o).trim(), format!("wrote 6 rows (3 intervals, 3 events) to {}", csv.display()));
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), HISTORY);
    fake.finish();

    let o = hter(&["monitor", "--input", csv.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    // The times are the interval rows' means' (the library monitor keeps f32; each covers the
    // 300 s that end at its `t_s`: 0 … 900 s); the lowest and highest are the intervals'
    // extremes (4.80 in the last interval, 7.80 in the first), not the means' (4.98, 6.10).
    let close = |key: &str, want: f64| assert!((v[key].as_f64().unwrap() - want).abs() < 1e-5, "{key}: {v}");
    close("min_c", 4.8);
    close("max_c", 7.8);
    assert_eq!(v["time_below_2_s"], 0.0);
    assert_eq!(v["time_in_range_s"], 900.0);
    assert_eq!(v["intervals_outside_2_8"], 0);
    let _ = std::fs::remove_file(&csv);
}

/// The history is CSV whatever the file is called: `--output x.html` wrote CSV into a file
/// named .html. A name that is not FILE.csv (SPEC §8) is refused before the board is asked.
#[test]
fn history_refuses_an_output_that_is_not_csv() {
    let fake = Fake::start("history-ext", vec!["idle"]);
    // Names of this test's own: another test's stand-in board sits at `tmp("history")`.
    for name in ["refused.html", "refused.pdf", "refused"] {
        let out = tmp(name);
        let o = hter(&["board", "--port", fake.port(), "history", "--output", out.to_str().unwrap()]);
        assert_one_line_error(&o, &format!("--output '{}' must end in .csv", out.display()));
        assert!(!out.exists(), "{} written", out.display());
    }
    // A directory that does not exist: refused before the download, not after it.
    let lost = tmp("no-such-dir").join("history.csv");
    let o = hter(&["board", "--port", fake.port(), "history", "--output", lost.to_str().unwrap()]);
    assert_one_line_error(&o, &format!("cannot write '{}'", lost.display()));
    let csv = tmp("history-ext.CSV");
    let o = hter(&["board", "--port", fake.port(), "history", "--output", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), HISTORY);
    let _ = std::fs::remove_file(&csv);
    assert_eq!(fake.finish(), ["history"], "only the .CSV name in a directory that exists reached the board");
}

#[test]
fn a_full_30_day_history_arrives_whole() {
    let fake = Fake::start("month", vec!["idle"]);
    let csv = tmp("month.csv");
    let start = std::time::Instant::now();
    let o = hter(&["board", "--port", fake.port(), "history", "--output", csv.to_str().unwrap(), "--since", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    eprintln!("30-day history over the pty: {:.2} s", start.elapsed().as_secs_f64());
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), month());
    assert!(stdout(&o).starts_with("wrote 8670 rows (8640 intervals, 30 events)"), "{}", stdout(&o));
    fake.finish();
    let o = hter(&["monitor", "--input", csv.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let _ = std::fs::remove_file(&csv);
}

#[test]
fn identify_follows_commissioning_to_its_end() {
    let fake = Fake::start("identify", vec!["rest:0", "excite:50", "fit:90", "done"]);
    let o = hter(&["board", "--port", fake.port(), "identify"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    // Not a terminal: one plain line per state, then the model.
    assert!(out.contains("commissioning=rest:0\ncommissioning=excite:50\ncommissioning=fit:90\n"), "{out}");
    assert!(
        out.trim_end().ends_with(
            "commissioning done: control model a=-1.7900,0.8000 b=-0.0150,-0.0080 k=1; \
                 cabinet model a=-1.9390,0.9392 b=-0.2798,0.2717 k=9; controller gpc (adaptive)"
        ),
        "{out}"
    );
    assert_eq!(fake.finish(), ["identify", "status", "status", "status", "status"]);

    let fake = Fake::start("identify-fail", vec!["excite:10", "failed:no_excitation"]);
    let o = hter(&["board", "--port", fake.port(), "identify"]);
    assert_one_line_error(&o, "commissioning failed: no_excitation");
    fake.finish();
}

#[test]
fn a_killed_clients_unread_reply_does_not_reach_the_next_client() {
    let fake = Fake::start("stale", vec!["idle"]);
    {
        // Asks for the whole record and goes away without reading it.
        let mut port = serialport::new(fake.port(), 115_200).open_native().unwrap();
        std::io::Write::write_all(&mut port, b"history 0\n").unwrap();
    }
    while !fake.heard.lock().unwrap().iter().any(|l| l == "history 0") {
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = hter(&["board", "--port", fake.port(), "status", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["t_s"], 86400);
    fake.finish();
}

#[test]
fn no_device_or_no_answer_is_a_one_line_error() {
    assert_one_line_error(&hter(&["board", "--port", "/nonexistent/tty", "status"]), "cannot open '/nonexistent/tty'");
    // A link nobody serves: the client gives up after its timeout.
    let path = tmp("silent");
    let _link = PtyLink::open(&path).unwrap();
    let o = hter(&["board", "--port", path.to_str().unwrap(), "--timeout", "0.3", "get"]);
    assert_one_line_error(&o, "no reply from");
    assert_one_line_error(&hter(&["board", "--port", "/dev/null", "--timeout", "0", "get"]), "--timeout");
    assert_one_line_error(
        &hter(&["board", "--port", "/dev/null", "history", "--output", "x.csv", "--since", "-1"]),
        "--since",
    );
}
