//! Input and output checks of the `hter` binary beyond the basics of `cli.rs`: a stdout that
//! cannot be written, seeds at the end of the 64-bit range, `hter virtual-board`'s stop and
//! run-length checks, `hter board set`'s format explanations, `hter rtd`'s wording and
//! `hter identify`'s physical checks. Each runs the built binary as a user does.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("hter-cli-input-{}-{name}", std::process::id()))
}

/// The one stderr line of a failed run.
fn one_line_error(args: &[&str]) -> String {
    let out = hter(args);
    let err = String::from_utf8_lossy(&out.stderr).trim_end().to_string();
    assert!(!out.status.success(), "{args:?} should fail: {}", stdout(&out));
    assert_eq!(err.lines().count(), 1, "{args:?}: not one line: {err}");
    assert!(err.starts_with("error: ") && !err.contains("panicked"), "{args:?}: {err}");
    err
}

fn assert_error(args: &[&str], needle: &str) {
    let err = one_line_error(args);
    assert!(err.contains(needle), "{args:?}: '{needle}' not in: {err}");
}

/// A `hter sim --scenario prbs` log (open loop, PRBS on the duty), made once per test.
fn prbs_log(name: &str) -> PathBuf {
    let csv = tmp(name);
    let out = hter(&["sim", "--scenario", "prbs", "--csv", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    csv
}

/// `log` with the cell of `column` on 1-based `line` replaced by `cell`.
fn with_cell(log: &Path, name: &str, line: usize, column: &str, cell: &str) -> PathBuf {
    let text = std::fs::read_to_string(log).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let j = header.iter().position(|h| *h == column).unwrap();
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i + 1 != line {
                return l.to_string();
            }
            let mut cells: Vec<&str> = l.split(',').collect();
            cells[j] = cell;
            cells.join(",")
        })
        .collect();
    let p = tmp(name);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    p
}

/// A full disk (`> /dev/full`) is one line, `error: cannot write to stdout: …`, and exit 1 for
/// every printing command: `println!` panicked with exit 101, and `identify` exited 0 with its
/// report lost.
#[test]
fn a_stdout_that_cannot_be_written_is_a_one_line_error() {
    if !Path::new("/dev/full").exists() {
        eprintln!("no /dev/full here: skipped");
        return;
    }
    let log = prbs_log("full.csv");
    let log_s = log.to_str().unwrap();
    let fast_fit = ["--method", "ls", "--na", "1", "--nb", "1", "--nk", "3"];
    let identify: Vec<&str> = ["identify", "--input", log_s].iter().copied().chain(fast_fit).collect();
    let identify_json: Vec<&str> = identify.iter().copied().chain(["--json"]).collect();
    let cases: [&[&str]; 8] = [
        &["rtd", "--ohms", "100"],
        &["rtd", "--celsius", "4", "--json"],
        &identify,
        &identify_json,
        &["monitor", "--input", log_s],
        &["sim", "--duration", "600"],
        &["compare", "--controllers", "pi", "--duration", "600"],
        &["campaign", "--missions", "1", "--json"],
    ];
    for args in cases {
        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_hter"))
            .args(args)
            .stdout(Stdio::from(full))
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("error: cannot write to stdout: No space left on device"), "{args:?}: {err}");
    }
    // The same commands to a writable stdout succeed: the error is the disk's, not theirs.
    assert!(hter(&identify).status.success());
    let _ = std::fs::remove_file(&log);
}

/// The last mission's seed is seed + missions − 1: the last two seeds of the 64-bit range were
/// refused as "overflows".
#[test]
fn a_campaign_may_end_at_the_last_seed() {
    for (missions, seed) in [("2", "18446744073709551614"), ("1", "18446744073709551615")] {
        let out = hter(&["campaign", "--missions", missions, "--seed", seed, "--json"]);
        assert!(out.status.success() || out.status.code() == Some(1), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the campaign's JSON");
        assert_eq!(v["missions"].as_u64(), missions.parse().ok(), "{v}");
    }
    assert_error(&["campaign", "--missions", "3", "--seed", "18446744073709551614"], "overflows a 64-bit seed");
}

/// A `hter virtual-board` on a fresh link, stopped (SIGKILL) on drop if still running.
struct Board {
    child: std::process::Child,
    link: PathBuf,
}

impl Board {
    fn start(name: &str) -> Board {
        let link = tmp(name);
        let child = Command::new(env!("CARGO_BIN_EXE_hter"))
            .args(["virtual-board", "--link", link.to_str().unwrap(), "--speed", "600"])
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let t0 = Instant::now();
        while !link.exists() {
            assert!(t0.elapsed() < Duration::from_secs(20), "the link did not appear");
            std::thread::sleep(Duration::from_millis(50));
        }
        Board { child, link }
    }

    fn board(&self, args: &[&str]) -> Output {
        let mut a = vec!["board", "--port", self.link.to_str().unwrap()];
        a.extend_from_slice(args);
        hter(&a)
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Ctrl-C (SIGINT) or `kill` (SIGTERM) remove the `--link` symlink, which was left behind
/// pointing to a pty that no longer existed, and the board ends by that signal.
#[cfg(unix)]
#[test]
fn a_stopped_virtual_board_removes_its_link() {
    use std::os::unix::process::ExitStatusExt;
    for (name, sig) in [("int", libc::SIGINT), ("term", libc::SIGTERM)] {
        let mut b = Board::start(&format!("stop-{name}"));
        // It serves before it is stopped.
        assert!(b.board(&["status"]).status.success());
        // SAFETY: a signal to our own child, which has not been waited for.
        assert_eq!(unsafe { libc::kill(b.child.id() as libc::pid_t, sig) }, 0);
        let status = b.child.wait().unwrap();
        assert_eq!(status.signal(), Some(sig), "{name}: {status:?}");
        assert!(std::fs::symlink_metadata(&b.link).is_err(), "{name}: the link is left behind");
    }
}

/// `--duration` shorter than one sample stopped at once with exit 0; a fault after the last
/// sample of `--duration` was accepted and never happened (`hter sim` refuses both).
#[test]
fn a_virtual_board_run_that_would_not_happen_is_refused() {
    let link = tmp("vb-refused");
    let link = link.to_str().unwrap();
    assert_error(&["virtual-board", "--link", link, "--duration", "5"], "shorter than one control sample");
    assert_error(
        &["virtual-board", "--link", link, "--duration", "100", "--fault", "sensor-open@1e30"],
        "--fault sensor-open@1e30: the board stops at 100 s (last sample at 90 s)",
    );
    assert_error(&["virtual-board", "--link", link, "--duration", "100", "--fault", "sensor-open@95"], "never happen");
    assert!(std::fs::symlink_metadata(link).is_err(), "no link for a refused run");
    // The last sample's time is a time a fault can have: the run starts and ends by itself.
    let out =
        hter(&["virtual-board", "--link", link, "--duration", "100", "--speed", "1000", "--fault", "sensor-open@90"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(std::fs::symlink_metadata(link).is_err(), "the link is removed at the end");
}

/// `hter board set` says what a setting takes where the board says "not a decimal number"; the
/// board's own refusals (range, plausibility) still come through verbatim, and valid values are
/// still set.
#[test]
fn board_set_explains_the_format_of_a_value() {
    let b = Board::start("set-format");
    let port = b.link.to_str().unwrap();
    let check = |key: &str, value: &str, needle: &str| {
        let err = one_line_error(&["board", "--port", port, "set", key, value]);
        assert!(err.contains(needle), "{key} {value}: {err}");
        assert!(!err.contains("not a decimal number"), "{key} {value}: {err}");
    };
    check("cal_ice", "0.1", "cal_ice takes MEASURED,TRUE in °C");
    check("cal_ice", "1e3", "cal_ice takes MEASURED,TRUE in °C");
    check("cal_warm", "20", "cal_warm takes MEASURED,TRUE in °C");
    check("model", "-0.9;-0.1;1", "model takes A1,A2;B0,B1;K");
    check("setpoint_c", "1e0", "setpoint_c takes a plain decimal number");
    // The board's words for what it checks itself: range, step and digits.
    let out = b.board(&["set", "setpoint_c", "12"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("setpoint_c: 12 is outside 2.5…7.5"), "{out:?}");
    let out = b.board(&["set", "setpoint_c", "4.00000000001"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("setpoint_c: 4.00000000001 is finer than the 0.01 °C step (at most 2 decimals)"), "{out:?}");
    let out = b.board(&["set", "model", "-1.8,0.81;-0.02,-0.01;1;2"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("usage: model A1,A2;B0,B1;K"), "{out:?}");
    // Valid values go through.
    let out = b.board(&["set", "setpoint_c", "4.5"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = b.board(&["set", "cal_ice", "0.12,0.00"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let get = stdout(&b.board(&["get"]));
    assert!(get.contains("setpoint_c=4.50"), "{get}");
}

/// `hter rtd`'s messages and output: plain words, compact numbers, no −0, the JSON at the
/// conversion's precision, hyphen values reaching the value checks.
#[test]
fn rtd_says_plainly_what_it_converted_or_refused() {
    let err = one_line_error(&["rtd", "--ohms", "1e30"]);
    assert_eq!(err, "error: 1e30 Ω is outside the Pt100 range of IEC 60751 (−200…850 °C)");
    assert_error(&["rtd", "--celsius", "2000"], "outside the IEC 60751 range −200…850 °C");
    assert!(!one_line_error(&["rtd", "--celsius", "2000"]).contains("OutOfRange"));
    assert_error(&["rtd", "--counts", "65535"], "(an open circuit: open at");
    assert_error(&["rtd", "--counts", "30000", "--r0", "1000"], "--r0 1000 does not apply");
    assert_error(&["rtd", "--ohms", "-inf"], "--ohms must be a finite number, got -inf");
    assert_error(&["rtd", "--celsius", "-inf"], "--celsius must be a finite number");
    assert_error(&["board", "--port", "/no/such/port", "--timeout", "-1", "status"], "--timeout must be within");
    let out = hter(&["rtd", "--celsius", "-0"]);
    assert_eq!(stdout(&out), "Pt100: 100.000 Ω  ⇔  0.000 °C\n");
    let out = hter(&["rtd", "--ohms", "99.99999"]);
    assert!(stdout(&out).ends_with("⇔  0.000 °C\n"), "{}", stdout(&out));
    let out = hter(&["rtd", "--celsius", "-0", "--json"]);
    assert_eq!(stdout(&out).trim(), r#"{"celsius":0.0,"ohms":100.0}"#);
    // 390 Ω: the f32 conversion's 848.35663 °C, not its f64 image 848.3566284179688.
    let out = hter(&["rtd", "--ohms", "390", "--json"]);
    let text = stdout(&out);
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let c = v["celsius"].as_f64().unwrap();
    assert!((c - 848.3566).abs() < 1e-3, "{text}");
    assert!(text.trim().len() < r#"{"celsius":848.35663,"ohms":390.0}"#.len() + 1, "{text}");
    // The text output of an ordinary value is as it was.
    assert_eq!(stdout(&hter(&["rtd", "--celsius", "4"])), "Pt100: 101.562 Ω  ⇔  4.000 °C\n");
}

/// `hter identify` refuses a duty outside [0, 1] and a temperature no Pt100 reports, with the
/// line; says "is a directory"; calls a pole at |p| = 1 − 1e-14 not stable; formats a tiny Ts
/// compactly; names `nk=auto` in the too-few-rows error.
#[test]
fn identify_refuses_impossible_data_and_reports_plainly() {
    let log = prbs_log("id.csv");
    let bad = |name: &str, column: &str, cell: &str| with_cell(&log, name, 50, column, cell);
    for (name, column, cell, needle) in [
        ("huge-duty.csv", "duty", "1e30", "line 50, column 'duty': 1e30 is outside 0…1"),
        ("neg-duty.csv", "duty", "-3", "line 50, column 'duty': -3 is outside 0…1"),
        ("two-duty.csv", "duty", "2", "line 50, column 'duty': 2 is outside 0…1"),
        ("huge-temp.csv", "temp_c", "1e30", "line 50, column 'temp_c': 1e30 °C is outside the Pt100 range"),
        ("cold-temp.csv", "temp_c", "-300", "line 50, column 'temp_c': -300 °C is outside the Pt100 range"),
    ] {
        let p = bad(name, column, cell);
        assert_error(&["identify", "--input", p.to_str().unwrap()], needle);
        let _ = std::fs::remove_file(&p);
    }
    // The ends of the ranges are data.
    let p = bad("ends.csv", "duty", "1");
    let out = hter(&["identify", "--input", p.to_str().unwrap(), "--method", "ls", "--nk", "3"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let _ = std::fs::remove_file(&p);
    let dir = std::env::temp_dir();
    assert_error(&["identify", "--input", dir.to_str().unwrap()], "is a directory");
    assert!(!one_line_error(&["identify", "--input", dir.to_str().unwrap()]).contains("line 1"));
    assert_error(
        &["identify", "--input", log.to_str().unwrap(), "--decimate", "1000"],
        "too few rows (2) for na=2 nb=2 nc=0 nk=auto",
    );
    // t_s against the duty: a ramp, fitted with a double pole at 1 − 1.6e-14.
    let out = hter(&["identify", "--input", log.to_str().unwrap(), "--y-column", "t_s", "--method", "ls", "--nk", "1"]);
    let text = stdout(&out);
    assert!(text.contains("UNSTABLE") && !text.contains("stable (all poles inside"), "{text}");
    // Ts = 1 µs from microsecond timestamps.
    let text = std::fs::read_to_string(&log).unwrap();
    let micro: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let (t, rest) = l.split_once(',').unwrap();
            format!("{:.6},{rest}\n", t.parse::<f64>().unwrap() * 1e-7)
        })
        .collect();
    let p = tmp("micro.csv");
    std::fs::write(&p, micro).unwrap();
    let out = hter(&["identify", "--input", p.to_str().unwrap(), "--method", "ls", "--nk", "2"]);
    let text = stdout(&out);
    assert!(text.contains("Ts = 0.000001 s)"), "{text}");
    assert!(text.contains("nk = 2 × Ts = 0.000002 s)"), "{text}");
    let _ = (std::fs::remove_file(&p), std::fs::remove_file(&log));
}

/// A record whose first sample lies far before 0 is as long as one that ends far after it:
/// `t_s = -1e300` then `0` gave `monitor` 1.8e16 s in range with exit 0, and `report` a panic
/// (capacity overflow), `-1e12` a report that never finished. A record of 10e6 s that starts
/// before 0 is still read.
#[test]
fn a_record_that_starts_long_before_zero_is_refused() {
    for (name, first) in [("neg-huge.csv", "-1e300"), ("neg-long.csv", "-1e12"), ("neg-span.csv", "-15000000")] {
        let p = tmp(name);
        std::fs::write(&p, format!("t_s,temp_c\n{first},4\n1000001,4\n")).unwrap();
        let html = tmp(&format!("{name}.html"));
        for args in [
            vec!["monitor", "--input", p.to_str().unwrap(), "--json"],
            vec!["report", "--input", p.to_str().unwrap(), "--output", html.to_str().unwrap()],
        ] {
            assert_error(&args, "more than 16e6 s (185 days)");
        }
        assert!(!html.exists());
        let _ = std::fs::remove_file(&p);
    }
    let p = tmp("neg-ok.csv");
    std::fs::write(&p, "t_s,temp_c\n-20000000,4\n-10000000,4\n").unwrap();
    let out = hter(&["monitor", "--input", p.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout(&out).contains("\"time_in_range_s\":10000000.0"), "{}", stdout(&out));
    let _ = std::fs::remove_file(&p);
}

/// The `prbs` scenario drives the SSR open loop: `compare --scenario prbs` printed five
/// identical rows named "prbs" for the five controllers asked for, and `sim --scenario prbs
/// --controller pi --kp 1` ran the PRBS, silently ignoring both flags.
#[test]
fn the_open_loop_scenario_refuses_controllers() {
    assert_error(&["compare", "--scenario", "prbs", "--duration", "100"], "runs no controller");
    assert_error(&["compare", "--scenario", "prbs", "--controllers", "pi", "--duration", "100"], "nothing to compare");
    assert_error(
        &["sim", "--scenario", "prbs", "--controller", "pi", "--duration", "100"],
        "--controller pi does not apply to the prbs scenario",
    );
    assert_error(&["sim", "--scenario", "prbs", "--n2", "5", "--duration", "100"], "--n2 does not apply to the prbs");
    let out = hter(&["sim", "--scenario", "prbs", "--duration", "100", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout(&out).contains("\"controller\":\"prbs\""), "{}", stdout(&out));
}

/// A GPC horizon that ends before the model's delay: no duty acts on any predicted sample, and
/// `hter sim --n2 4` (the self-tuner, delay 5) kept the carrier at 28 °C for 3 h with no word;
/// `--model` with a longer delay likewise. Refused by name; N2 = k runs.
#[test]
fn a_gpc_horizon_shorter_than_the_delay_is_refused() {
    let said = "ends before the model's delay k = ";
    assert_error(&["sim", "--n2", "4", "--nu", "1", "--duration", "100"], &format!("N2 = 4 {said}5"));
    assert_error(&["sim", "--n2", "5", "--nu", "1", "--plant", "hter2", "--duration", "100"], &format!("{said}6"));
    let model = ["--model", "arx:-0.99;-0.3;10"];
    assert_error(&[&["sim", "--n2", "9"][..], &model, &["--duration", "100"]].concat(), &format!("{said}10"));
    for args in [
        &["sim", "--n2", "5", "--nu", "1", "--duration", "100"][..],
        &[&["sim", "--n2", "10"][..], &model, &["--duration", "100"]].concat(),
    ] {
        let out = hter(args);
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    }
}

/// A pole in [0, 1) as typed that is 1 in the library's f32 is refused as what it becomes:
/// `--p-pole 0.999999999` said "Gmvc: configuration refused (Law(Config))", `--t-pole` "…
/// (TFilter)". The largest f32 below 1 still runs.
#[test]
fn a_pole_that_rounds_to_one_is_refused_by_name() {
    for (controller, flag) in [("gmvc", "--p-pole"), ("igmvc", "--p-pole"), ("igmvc", "--t-pole"), ("gpc", "--t-pole")]
    {
        let args = ["sim", "--controller", controller, flag, "0.999999999", "--duration", "100"];
        let err = one_line_error(&args);
        assert!(err.contains(&format!("{flag} must be in [0, 1), got 0.999999999, which is 1 in")), "{err}");
        let out = hter(&["sim", "--controller", controller, flag, "0.99999994", "--duration", "100"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    assert_error(&["sim", "--controller", "gmvc", "--p-pole", "1", "--duration", "100"], "got 1");
}

/// An output that is the input is refused, the input left as it was: `log2csv --input
/// carrier.log --output carrier.log` replaced the log with its CSV, and `report` a log with
/// the page made from it.
#[test]
fn log2csv_and_report_refuse_to_overwrite_their_input() {
    for (command, name, text) in [
        ("log2csv", "same.log", "t=0 temp=4 sp=4 duty=0.5\nt=10 temp=4 sp=4 duty=0.5\n"),
        ("report", "same.html", "t_s,temp_c\n0,4\n10,4\n"),
    ] {
        let path = tmp(name);
        std::fs::write(&path, text).unwrap();
        let s = path.to_str().unwrap();
        assert_error(&[command, "--input", s, "--output", s], "is the same file as --input");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text, "{command}");
        let _ = std::fs::remove_file(&path);
    }
}

/// Every "line N" names the line a user opens the file at. The CSV reader skips blank lines, so a
/// blank line inside the data shifted them by one (the bad row on line 4 was "line 3"): a blank
/// line inside the data is refused by its line. Blank lines at the end are still read.
#[test]
fn a_blank_line_inside_the_data_is_refused_at_its_real_line() {
    let p = tmp("blank.csv");
    std::fs::write(&p, "t_s,temp_c\n0,4\n\n10,warm\n").unwrap();
    let e = one_line_error(&["monitor", "--input", p.to_str().unwrap(), "--json"]);
    assert!(e.contains("line 3") && e.contains("blank line"), "{e}");
    std::fs::write(&p, "t_s,temp_c\n0,4\n10,4\n\n\n").unwrap();
    let out = hter(&["monitor", "--input", p.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let _ = std::fs::remove_file(&p);
}

/// A huge number in a one-line error is shown in the short exponent form, not as 301 digits.
#[test]
fn a_huge_number_in_an_error_is_shown_short() {
    let sc = tmp("huge-start.json");
    std::fs::write(&sc, r#"{"start_c": 1e300, "setpoints": [[0, 4]], "duration_s": 100}"#).unwrap();
    let cases: [Vec<&str>; 4] = [
        vec!["board", "--port", "/dev/null", "--timeout", "1e300", "status"],
        vec!["virtual-board", "--link", "/tmp/x", "--speed", "1e300"],
        vec!["sim", "--scenario", sc.to_str().unwrap()],
        vec!["sim", "--controller", "pi", "--kp", "-1e300"],
    ];
    for args in cases {
        let e = one_line_error(&args);
        assert!(e.contains("1e300") && e.len() < 200, "{args:?}: {e}");
    }
    let _ = std::fs::remove_file(&sc);
}

/// A column the header names twice is refused by every command that reads it: `monitor`,
/// `report` and `identify` silently read the first `temp_c` of `t_s,temp_c,…,temp_c`, so a
/// second column of −30 °C (or the same probe in °F) left no trace, and `report` said the record
/// was clean.
#[test]
fn a_column_named_twice_is_refused() {
    let log = prbs_log("dup-src.csv");
    let text = std::fs::read_to_string(&log).unwrap();
    let doubled: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| if i == 0 { format!("{l},temp_c\n") } else { format!("{l},-30\n") })
        .collect();
    let p = tmp("dup-col.csv");
    std::fs::write(&p, doubled).unwrap();
    let html = tmp("dup-col.html");
    let s = p.to_str().unwrap();
    for args in [
        vec!["monitor", "--input", s, "--json"],
        vec!["report", "--input", s, "--output", html.to_str().unwrap()],
        vec!["identify", "--input", s, "--json"],
    ] {
        assert_error(&args, "column 'temp_c' appears twice in the header");
    }
    assert!(!html.exists());
    let _ = (std::fs::remove_file(&p), std::fs::remove_file(&log));
}

/// RELS with a short memory can estimate a noise model C whose root lies outside the unit
/// circle: its one-step predictor (filtered by 1/C) diverges, and `identify` printed an MSE of
/// 1.5e161 °C² (or "inf", null in the JSON) as the model's. Such an estimate is refused with
/// why; with the delay scan, the delays that gave one are left out and the best of the others
/// is reported, with a finite MSE.
#[test]
fn a_rels_noise_model_with_an_unstable_predictor_is_refused() {
    let log = prbs_log("rels-c.csv");
    let s = log.to_str().unwrap();
    assert_error(
        &["identify", "--input", s, "--method", "rels", "--forgetting", "0.5", "--nk", "3", "--json"],
        "C(q⁻¹) has a root of modulus 1.142, on or outside the unit circle",
    );
    let out = hter(&["identify", "--input", s, "--method", "rels", "--forgetting", "0.5", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    let mses = std::iter::once(&v["mse"]).chain(v["order_comparison"].as_array().unwrap().iter().map(|r| &r["mse"]));
    for mse in mses {
        assert!(mse.as_f64().is_some_and(|m| m < 1.0), "{mse} in {v}");
    }
    let _ = std::fs::remove_file(&log);
}

/// `identify --auto-order --na 3` reported the comparison's order (na = nb = 1, 2 or 4) and
/// silently ignored `--na 3`: the two ask for different orders, and are refused together.
#[test]
fn auto_order_with_a_given_order_is_refused() {
    for flag in ["--na", "--nb"] {
        let e = one_line_error(&["identify", "--input", "/dev/null", "--auto-order", flag, "3"]);
        assert!(e.contains("'--auto-order' cannot be used with") && e.contains(flag), "{e}");
    }
}

/// `compare --controllers pi,pi` ran one controller twice and printed two identical rows as a
/// comparison: a controller named twice is refused.
#[test]
fn compare_refuses_a_controller_named_twice() {
    assert_error(
        &["compare", "--controllers", "gpc,pi,pi", "--duration", "100"],
        "--controllers names pi twice (entries 2 and 3)",
    );
}

/// `log2csv --input DIR` said "'DIR': line 1: not text: Is a directory (os error 21)", as if
/// the directory were a log with a bad first line; it is refused as what it is, as `monitor`,
/// `report` and `identify` refuse it, and no output is written.
#[test]
fn log2csv_refuses_a_directory_by_name() {
    let dir = std::env::temp_dir();
    let out = tmp("from-dir.csv");
    let e = one_line_error(&["log2csv", "--input", dir.to_str().unwrap(), "--output", out.to_str().unwrap()]);
    assert!(e.ends_with("': it is a directory") && !e.contains("line 1"), "{e}");
    assert!(!out.exists());
}

/// A scenario file whose schedule gives one time twice (`[[0, 4], [0, 5]]`) ran at the later
/// value and never showed the earlier one, with exit 0: it is refused, naming the field and the
/// time.
#[test]
fn a_scenario_time_given_twice_is_refused() {
    let sc = tmp("twice.json");
    std::fs::write(&sc, r#"{"start_c": 4, "setpoints": [[0, 4], [0, 5]], "duration_s": 600}"#).unwrap();
    assert_error(&["sim", "--scenario", sc.to_str().unwrap(), "--json"], "'setpoints' has two entries at 0 s");
    let _ = std::fs::remove_file(&sc);
}

/// A board history's `alarm:KIND@START` whose START is no record second at or before the alarm
/// was taken as it came (`@-1e300`: an alarm that started 1e300 s before the record, in
/// `monitor --json` and the report) or silently replaced by the alarm's time (`@nan`): both
/// are refused as the corrupt rows they are, and no report is written.
#[test]
fn a_carrier_alarm_with_an_impossible_start_is_refused() {
    for (name, start) in [("alarm-neg.csv", "-1e300"), ("alarm-nan.csv", "nan"), ("alarm-late.csv", "900")] {
        let p = tmp(name);
        let rows = "300,4,3.9,4.1,0.5,normal,\n600,4,3.9,4.1,0.5,normal,\n";
        std::fs::write(&p, format!("t_s,temp_c,min_c,max_c,duty,mode,event\n{rows}700,,,,,,alarm:heat_10h@{start}\n"))
            .unwrap();
        let html = tmp(&format!("{name}.html"));
        for args in [
            vec!["monitor", "--input", p.to_str().unwrap(), "--json"],
            vec!["report", "--input", p.to_str().unwrap(), "--output", html.to_str().unwrap()],
        ] {
            assert_error(&args, &format!("event 'alarm:heat_10h@{start}' at t_s = 700: its start '{start}'"));
        }
        assert!(!html.exists());
        let _ = std::fs::remove_file(&p);
    }
}
