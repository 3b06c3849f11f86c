//! The README's workflow end to end: `hter virtual-board --link PATH --speed 600` in one process,
//! `hter board --port PATH …` in others, as a user runs them from two shells.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("hter-vb-{}-{name}", std::process::id()))
}

/// A running `hter virtual-board`, stopped on drop.
struct Board {
    child: Child,
    link: PathBuf,
}

impl Board {
    fn start(name: &str, extra: &[&str]) -> Board {
        let link = tmp(name);
        let mut args = vec!["virtual-board", "--link", link.to_str().unwrap()];
        if !extra.contains(&"--speed") {
            args.extend(["--speed", "600"]);
        }
        args.extend_from_slice(extra);
        let child = Command::new(env!("CARGO_BIN_EXE_hter")).args(&args).stderr(Stdio::null()).spawn().unwrap();
        let t0 = Instant::now();
        while !link.exists() {
            assert!(t0.elapsed() < Duration::from_secs(20), "the link did not appear");
            std::thread::sleep(Duration::from_millis(50));
        }
        Board { child, link }
    }

    fn port(&self) -> &str {
        self.link.to_str().unwrap()
    }

    fn board(&self, args: &[&str]) -> Output {
        let mut a = vec!["board", "--port", self.port()];
        a.extend_from_slice(args);
        hter(&a)
    }

    fn status(&self) -> serde_json::Value {
        let o = self.board(&["status", "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    }

    /// Polls `status` until `ok` holds (wall time limit).
    fn wait_for(&self, what: &str, limit_s: u64, ok: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
        let t0 = Instant::now();
        loop {
            let s = self.status();
            if ok(&s) {
                return s;
            }
            assert!(t0.elapsed() < Duration::from_secs(limit_s), "{what}: {s}");
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn one_line_error(o: &Output) -> String {
    assert!(!o.status.success(), "must fail: {}", String::from_utf8_lossy(&o.stdout));
    let e = String::from_utf8_lossy(&o.stderr).trim_end().to_string();
    assert_eq!(e.lines().count(), 1, "one line: {e}");
    e
}

#[test]
fn status_settings_and_history_work_from_the_host_tool_as_the_readme_shows() {
    let b = Board::start("readme", &[]);
    let s = b.status();
    for key in [
        "t_s",
        "temp_c",
        "setpoint_c",
        "duty",
        "mode",
        "alarm",
        "controller",
        "model",
        "holdover_s",
        "resets",
        "firmware",
    ] {
        assert!(s.get(key).is_some(), "status --json has {key}: {s}");
    }
    assert_eq!(s["controller"], "gpc");
    assert_eq!(s["model"]["k"], 5);
    // Refused values: non-zero exit, one line, nothing changed.
    for v in ["12", "nan"] {
        let e = one_line_error(&b.board(&["set", "setpoint_c", v]));
        assert!(e.contains("setpoint_c"), "{e}");
    }
    let s = b.status();
    assert_eq!((s["setpoint_c"].as_f64(), s["settings_version"].as_u64()), (Some(4.0), Some(0)));
    // An accepted one: the load follows (≈ 2 h of carrier time at 600×).
    let o = b.board(&["set", "setpoint_c", "5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = b.wait_for("the load reaches 5 °C", 60, |s| s["temp_c"].as_f64().is_some_and(|t| (t - 5.0).abs() < 0.1));
    assert_eq!(s["settings_version"], 1);
    // Every law of the build, and one it does not link.
    assert!(b.board(&["set", "controller", "pi"]).status.success());
    assert_eq!(b.status()["controller"], "pi");
    one_line_error(&b.board(&["set", "controller", "igmvc"]));
    assert!(b.board(&["set", "controller", "gpc"]).status.success());
    one_line_error(&b.board(&["set", "cal_ice", "3.0,0.0"]));
    assert!(b.board(&["set", "cal_ice", "0.05,0.00"]).status.success());
    one_line_error(&b.board(&["set", "model", "1.2,0.1;-0.02,-0.01;5"]));
    assert!(b.board(&["ack"]).status.success());
    // The record into `hter monitor`.
    let csv = tmp("h.csv");
    let o = b.board(&["history", "--output", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.contains("set:setpoint_c=5.00") && text.contains("set:controller=pi"), "{text}");
    let m = hter(&["monitor", "--input", csv.to_str().unwrap(), "--json"]);
    assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
    let m: serde_json::Value = serde_json::from_slice(&m.stdout).unwrap();
    assert_eq!(m["alarms"], serde_json::json!([]));
    assert!(m["min_c"].as_f64().unwrap() > 3.0 && m["max_c"].as_f64().unwrap() < 6.0, "{m}");
    // And into the supervisor's report (issue 17).
    let html = tmp("r.html");
    let r = hter(&["report", "--input", csv.to_str().unwrap(), "--output", html.to_str().unwrap()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("<svg") && page.contains("IN RANGE"), "the report of the board's history");
    let _ = std::fs::remove_file(&html);
    let _ = std::fs::remove_file(&csv);
}

#[test]
fn a_power_cut_in_the_middle_of_a_settings_write_keeps_the_old_setting_and_the_board_comes_back() {
    let b = Board::start("cut", &["--cut-settings-write", "2"]);
    // Past the write gate's minute after boot, so the boot's own record is stored first (a cut
    // before it would lose that record too, as on the board).
    b.wait_for("the write gate opened", 30, |s| s["t_s"].as_f64().is_some_and(|t| t > 120.0));
    let o = b.board(&["set", "setpoint_c", "6"]);
    assert!(o.status.success());
    let s = b.wait_for("the board restarted", 30, |s| s["resets"] == 1);
    assert_eq!(s["setpoint_c"], 4.0, "the torn write is not used: {s}");
    assert_eq!(s["mode"], "normal");
    // It takes settings again, and they persist.
    assert!(b.board(&["set", "setpoint_c", "5"]).status.success());
    assert_eq!(b.status()["setpoint_c"], 5.0);
    let csv = tmp("cut.csv");
    assert!(b.board(&["history", "--output", csv.to_str().unwrap()]).status.success());
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.contains("restarted_brownout"), "the cut is on record: {text}");
    let _ = std::fs::remove_file(&csv);
}

/// The bug hunt's `set` answers, as `hter board` prints them: a refused value is quoted as typed
/// (`2.4999` was "2.50 is outside 2.5…7.5"), a value finer than its setting's step is refused
/// naming the step (`5.001` was accepted and read 5.00), a model's K must be a whole number,
/// zeros that change nothing are no digits, and On-Off is accepted with a warning on stderr.
#[test]
fn board_set_answers_say_exactly_what_is_wrong_and_warn_of_on_off() {
    let b = Board::start("refuse", &[]);
    let stderr = |o: &Output| String::from_utf8_lossy(&o.stderr).trim_end().to_string();
    for (args, want) in [
        (["setpoint_c", "2.4999"], "err setpoint_c: 2.4999 is outside 2.5…7.5"),
        (["setpoint_c", "5.001"], "err setpoint_c: 5.001 is finer than the 0.01 °C step (at most 2 decimals)"),
        (["cal_ice", "0.125,0.00"], "err cal_ice: 0.125 is finer than the 0.01 °C step (at most 2 decimals)"),
        (
            ["model", "-1.859405,0.859802;-0.014713,-0.003021;5.5"],
            "err model: K must be a whole number of samples in 1…10, not 5.5",
        ),
        (
            ["model", "-1.859405,0.859802;-0.0147131,-0.003021;8"],
            "err model: -0.0147131 is finer than the 0.000001 step (at most 6 decimals)",
        ),
    ] {
        let o = b.board(&["set", args[0], args[1]]);
        assert_eq!(one_line_error(&o), format!("error: {want}"), "{args:?}");
    }
    let s = b.status();
    assert_eq!((s["setpoint_c"].as_f64(), s["settings_version"].as_u64()), (Some(4.0), Some(0)), "nothing changed");
    // Eight digits, but only one that counts.
    let o = b.board(&["set", "setpoint_c", "5.00000000"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout), "ok: setpoint_c = 5.00000000\n");
    // On-Off: accepted (exit 0, `ok` on stdout), its warning one line on stderr.
    let o = b.board(&["set", "controller", "onoff"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout), "ok: controller = onoff\n");
    let warning = stderr(&o);
    assert_eq!(warning.lines().count(), 1, "{warning}");
    assert!(warning.starts_with("warning: onoff is a comparison baseline") && warning.contains("2-8 °C"), "{warning}");
    assert!(warning.contains("gpc is the field controller"), "{warning}");
    assert_eq!(b.status()["controller"], "onoff");
    // Back to the field controller: no warning.
    let o = b.board(&["set", "controller", "gpc"]);
    assert!(o.status.success() && o.stderr.is_empty(), "{}", stderr(&o));
}

#[test]
fn a_missing_port_is_one_line_and_non_zero() {
    let e = one_line_error(&hter(&["board", "--port", Path::new("/nonexistent/tty").to_str().unwrap(), "status"]));
    assert!(e.contains("/nonexistent/tty"), "{e}");
}

#[test]
fn identify_runs_to_completion_and_the_status_shows_the_new_model_and_adaptive_mode() {
    // 3000×: the ≈ 6.2 h commissioning (both models) in well under a minute.
    let b = Board::start("identify", &["--speed", "3000"]);
    b.wait_for("an hour at 4 °C", 30, |s| s["t_s"].as_f64().is_some_and(|t| t > 3600.0));
    let before = b.status()["model"].clone();
    let o = b.board(&["identify"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "identify: {out} / {}", String::from_utf8_lossy(&o.stderr));
    let s = b.status();
    assert_eq!(s["commissioning"], "done");
    assert_eq!(s["controller"], "gpc");
    assert_ne!(s["model"], before, "the new model is in use");
    // Two models from the one run: the self-tuner's (every b_i <= 0) and the cabinet model, the
    // best fit, with b1 > 0 on H-TER I (two cooling lags in parallel), which the holdover runs on.
    let (control, cabinet) = (&s["model"], &s["cabinet"]);
    assert!(control["b"].as_array().unwrap().iter().all(|b| b.as_f64().unwrap() <= 0.0), "{s}");
    assert!(cabinet["b"][1].as_f64().unwrap() > 0.0, "{s}");
    // Its delay covers the carrier's 20 s transport, 20 s RTD lag and the filter (90 s by `hter
    // identify`). Which of the neighbouring delays fits best depends on the noise this run draws:
    // the virtual board runs against the wall clock, so `identify` starts at a different sample
    // each run (seen: k 8 and 9). tests/commission.rs pins the fit itself on a fixed seed.
    let k = cabinet["k"].as_u64().unwrap();
    assert!((7..=10).contains(&k), "{s}");
    // The self-tuner runs from it: on its current estimate (`adaptive`) or, while the estimate
    // is not trusted, on the commissioned model (`frozen`); never on its fallback PI; and it
    // holds the setpoint.
    let s = b.wait_for("the self-tuner holds 4 °C", 30, |s| {
        s["t_s"].as_f64().unwrap() > 3600.0 * 8.0 && (s["temp_c"].as_f64().unwrap() - 4.0).abs() < 0.2
    });
    assert!(s["adaptive"] == "adaptive" || s["adaptive"] == "frozen", "{s}");
    assert_eq!(&s["cabinet"], cabinet, "the self-tuner's running leaves the cabinet model");
}

/// The virtual board driven directly: after `identify`, a power cut; the board restores both
/// models from their own records, the holdover runs on the cabinet model (not the start model,
/// not the self-tuner's estimate) and GPC holds 4 °C from the control model.
#[test]
fn after_a_reset_the_holdover_still_runs_on_the_cabinet_model() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Holding(4.0));
    for _ in 0..360 {
        b.step().unwrap();
    }
    assert_eq!(b.request("identify"), "ok\r\n");
    commissioning_ends_done(&mut b);
    let cabinet = b.app().cabinet().expect("a cabinet model");
    assert!(cabinet.b()[1] > 0.0, "{cabinet:?}");
    assert_eq!(b.app().carrier().holdover_model(), Some(cabinet));
    let control = (board_status(&mut b, "model_a"), board_status(&mut b, "model_k"));
    let shown =
        (board_status(&mut b, "cabinet_a"), board_status(&mut b, "cabinet_b"), board_status(&mut b, "cabinet_k"));
    // Both records are written at once (the supply has been good for an hour).
    for _ in 0..6 {
        b.step().unwrap();
    }
    b.power_cut();
    assert_eq!(b.restarts, 1);
    assert_eq!(b.app().cabinet(), Some(cabinet), "restored from its own record");
    assert_eq!(b.app().carrier().holdover_model(), Some(cabinet), "the holdover runs on it after the reset");
    assert_eq!(
        (board_status(&mut b, "cabinet_a"), board_status(&mut b, "cabinet_b"), board_status(&mut b, "cabinet_k")),
        shown
    );
    assert_eq!(
        (board_status(&mut b, "model_a"), board_status(&mut b, "model_k")),
        control,
        "the self-tuner restarts from its model"
    );
    // Two hours on: GPC holds 4 °C, the holdover gives an estimate from the cabinet model.
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..720 {
        b.step().unwrap();
        if i >= 360 {
            lo = lo.min(b.load_c());
            hi = hi.max(b.load_c());
        }
    }
    assert!(lo > 3.7 && hi < 4.3, "holds 4 °C after the reset: {lo:.2}…{hi:.2}");
    assert_eq!(board_status(&mut b, "controller"), "gpc");
    let holdover: f64 = board_status(&mut b, "holdover_s").parse().expect("a number");
    assert!((60.0..3600.0).contains(&holdover), "{holdover}");
    assert_eq!(b.app().carrier().holdover_model(), Some(cabinet));
}

/// A client that wrote half a request and went away: the serial port shows no hang-up, so the
/// board keeps the bytes, and the next `hter board` request was read glued to them
/// (`set setpoint_c 6` + `status` → `err setpoint_c: not a decimal number`). `hter board` begins
/// every request with Ctrl-U, which drops them; the half request is not run either.
#[test]
fn a_half_request_left_by_a_client_that_went_away_is_dropped() {
    use std::io::Write;
    let b = Board::start("half-line", &[]);
    assert_eq!(b.status()["setpoint_c"], 4.0);
    {
        let mut raw = std::fs::OpenOptions::new().write(true).open(b.port()).unwrap();
        raw.write_all(b"set setpoint_c 6").unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let s = b.status();
    assert_eq!(s["setpoint_c"], 4.0, "{s}");
}

/// The `interface,module-sense` build on the virtual board: the sample `App::sample` gets
/// carries the modules' voltage read in the conversion window (hal-sim's model: the modules'
/// Seebeck voltage behind a working SSR, the supply through a shorted one). An hour of holding
/// 4 °C reads no short; a shorted SSR is found at the second sample after it and the board
/// limps home. The reference board (no sense) has not found it after those two samples: it
/// waits for the load to fall.
#[test]
fn with_the_module_side_sense_the_interface_build_finds_a_shorted_ssr_at_the_second_sample() {
    use hal_sim::fault::Fault;
    use hal_sim::plant::Load;
    use hal_sim::sim::virtual_board::{VirtualBoard, VirtualOptions};
    use hal_sim::sim::PlantChoice;
    use hter::event::EventKind;
    let mut found = Vec::new();
    for module_sense in [true, false] {
        let opts =
            VirtualOptions { plant: PlantChoice::Hter1, load: Load::Full, ambient_c: 28.0, seed: 1, module_sense };
        let mut b = VirtualBoard::new(&opts).unwrap();
        for _ in 0..360 {
            let out = b.step().unwrap();
            assert!(
                out.step.events.iter().all(|e| e.kind != EventKind::SsrStuckOn),
                "{module_sense}: {:?}",
                out.step.events
            );
        }
        b.inject(Fault::SsrStuckOn).unwrap();
        let at = (1..=60).find(|_| b.step().unwrap().step.events.iter().any(|e| e.kind == EventKind::SsrStuckOn));
        if module_sense {
            let status = b.request("status");
            assert!(status.contains("mode=limp_home\r\n"), "{status}");
        }
        found.push((at, b.load_c()));
    }
    assert_eq!(found[0].0, Some(2), "with the sense");
    assert!(found[1].0.is_none_or(|n| n > 2), "without the sense: {:?}", found[1]);
    eprintln!("shorted SSR found at sample {:?} with the sense, {:?} without (sample, load °C)", found[0], found[1]);
}

/// A shorted SSR found on a board with the module-side sense, then the reset button: the board
/// limps home from its first sample (an NRST glitch or a debugger's reset is no repair). Then
/// a service reset (the acknowledge button held through the reset): the board forgets the
/// short and hands the modules back to the controller, the history says so, and since this
/// SSR is still shorted the sense finds it again within three samples. Before, the plain reset
/// already forgot it.
#[test]
fn the_reset_button_keeps_a_shorted_ssr_and_a_service_reset_forgets_it() {
    use hal_sim::fault::Fault;
    use hal_sim::plant::Load;
    use hal_sim::sim::virtual_board::{VirtualBoard, VirtualOptions};
    use hal_sim::sim::PlantChoice;
    use hter::event::EventKind;
    use hter::step::Mode;
    let opts =
        VirtualOptions { plant: PlantChoice::Hter1, load: Load::Full, ambient_c: 28.0, seed: 1, module_sense: true };
    let mut b = VirtualBoard::new(&opts).unwrap();
    for _ in 0..360 {
        b.step().unwrap();
    }
    b.inject(Fault::SsrStuckOn).unwrap();
    let found = |b: &mut VirtualBoard| {
        (1..=10).find(|_| b.step().unwrap().step.events.iter().any(|e| e.kind == EventKind::SsrStuckOn))
    };
    assert_eq!(found(&mut b), Some(2));
    // Past the write gate's hold-off: the short is in flash.
    for _ in 0..30 {
        b.step().unwrap();
    }
    b.reset(false);
    let first = b.step().unwrap();
    assert_eq!(first.step.mode, Mode::LimpHome, "the reset button alone");
    assert!(!first.step.supply_enable);
    for _ in 0..30 {
        assert_eq!(b.step().unwrap().step.mode, Mode::LimpHome);
    }
    b.reset(true);
    assert_eq!(b.restarts, 2);
    let first = b.step().unwrap();
    assert_ne!(first.step.mode, Mode::LimpHome, "a service reset forgets the short");
    assert!(first.step.supply_enable);
    let again = found(&mut b);
    assert!(again.is_some_and(|n| n <= 2), "found again within the boot's first three samples: {again:?}");
    for _ in 0..30 {
        b.step().unwrap();
    }
    let history = b.request("history");
    let cleared: Vec<&str> = history.lines().filter(|l| l.contains("service_reset")).collect();
    assert_eq!(cleared.len(), 1, "{history}");
    assert!(cleared[0].ends_with(",service_reset:cleared ssr_short"), "{}", cleared[0]);
    assert_eq!(history.lines().filter(|l| l.ends_with(",ssr_stuck_on")).count(), 2, "{history}");
}

/// A firmware update over a record it refuses: the calibration record an older firmware wrote
/// under its looser bound (gain 0.9, offset 7.5 °C; this firmware holds a calibration to 1.5 °C
/// of correction between 0 and 10 °C), CRC-valid. The board runs without it, `status` shows the
/// alarm and `history` the refusal once; acknowledged, a restart neither reports it again nor
/// lights the indicator. Calibrated again over the interface, the settings' calibration runs and
/// the old record's refusal is forgotten.
#[test]
fn a_record_the_new_firmware_refuses_is_on_the_record_once() {
    use hter::persist::{flash::key, CalibrationRecord};
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Holding(4.0));
    let old = CalibrationRecord { cal: hter::calib::TwoPoint { gain: 0.9, offset_c: 7.5 } }.encode();
    assert!(CalibrationRecord::decode(&old).is_err(), "this firmware refuses it");
    b.store_raw(key::CALIBRATION, &old).unwrap();
    let refusals = |b: &mut hal_sim::sim::virtual_board::VirtualBoard| {
        b.request("history").lines().filter(|l| l.ends_with(",record_refused_calibration")).count()
    };
    b.reset(false);
    b.step().unwrap();
    assert_eq!(board_status(&mut b, "alarm"), "unacknowledged");
    assert_eq!(b.app().carrier().config().cal, hter::calib::TwoPoint::IDENTITY, "not run");
    // Past the write gate's hold-off: the event and the history are in flash.
    for _ in 0..30 {
        b.step().unwrap();
    }
    assert_eq!(refusals(&mut b), 1);
    assert!(b.request("ack").ends_with("ok\r\n"));
    for _ in 0..30 {
        b.step().unwrap();
    }
    for _ in 0..2 {
        b.reset(false);
        for _ in 0..30 {
            b.step().unwrap();
        }
        assert_eq!(board_status(&mut b, "alarm"), "off", "refused again, reported once");
        assert_eq!(refusals(&mut b), 1);
    }
    // Calibrated again: the settings carry it, the old record no longer matters.
    assert!(b.request("set cal_ice 0.1,0").ends_with("ok\r\n"));
    for _ in 0..30 {
        b.step().unwrap();
    }
    b.reset(false);
    for _ in 0..30 {
        b.step().unwrap();
    }
    // (0.1 → 0, 25 → 25.)
    let cal = b.app().carrier().config().cal;
    assert!((cal.gain - 25.0 / 24.9).abs() < 1e-6 && (cal.offset_c + 0.1 * 25.0 / 24.9).abs() < 1e-6, "{cal:?}");
    assert_eq!(board_status(&mut b, "alarm"), "off");
    assert_eq!(refusals(&mut b), 1);
}

/// A fault loop faster than the write gate's minute, end to end through the fail-safe's
/// reset-surviving record (`hter::failsafe::ResetRecords`) as the firmware keeps it: a panic 20 s
/// into each of five boots, then a HardFault. Each new stop is on the log before the next stop
/// (`board_fault_panic` from the loop's first boot; the HardFault's boot reports the last panic,
/// which no history had counted yet, and its own), the loop's repeats write nothing, and the
/// indicator is latched. Before, the rows waited for the minute: `history` had none.
#[test]
fn a_fault_loop_faster_than_the_write_gate_has_its_new_stops_on_the_log() {
    use hter::failsafe::{panic_info, StopInfo, StopKind};
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Holding(4.0));
    for _ in 0..40 {
        b.step().unwrap();
    }
    let panic = panic_info("src/step.rs", 417);
    let hard_fault = StopInfo::new(StopKind::HardFault, 0x0800_1234, 0, 0x8200);
    let rows = |b: &mut hal_sim::sim::virtual_board::VirtualBoard| -> Vec<String> {
        b.request("history")
            .lines()
            .filter_map(|l| l.rsplit(',').next().filter(|e| e.starts_with("board_fault")).map(str::to_string))
            .collect()
    };
    for (n, stop) in [panic; 5].into_iter().chain([hard_fault]).enumerate() {
        b.fail_safe_stop(stop);
        b.step().unwrap();
        b.step().unwrap();
        let seen = rows(&mut b);
        let want = if n < 5 { vec!["board_fault_panic"] } else { vec!["board_fault_panic"; 2] };
        let want: Vec<String> = want
            .into_iter()
            .map(str::to_string)
            .chain((n == 5).then(|| "board_fault_hard_fault".to_string()))
            .collect();
        assert_eq!(seen, want, "after the stop of boot {n}");
        assert_eq!(board_status(&mut b, "alarm"), "unacknowledged");
    }
}

/// A board whose records region refuses every write (an option byte's write protection over it,
/// a worn region) keeps no history, no settings and no model: after the third store in a row
/// that fails, `status` says `flash=failing`, the indicator latches, and the log (which still
/// writes) has one `store_failed` row. Before, only the RTT log said so, store by store. Lifted,
/// the next store that succeeds ends it; it is reported again only after a new run of failures.
#[test]
fn a_flash_that_refuses_every_write_sounds_the_alarm_and_says_so() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Holding(4.0));
    b.write_protect(false, true);
    let rows = |b: &mut hal_sim::sim::virtual_board::VirtualBoard| {
        b.request("history").lines().filter(|l| l.ends_with(",store_failed")).count()
    };
    let mut samples = 0;
    while board_status(&mut b, "flash") == "ok" {
        b.step().unwrap();
        samples += 1;
        // The boot's history after the write gate's minute, then the first hour's stores.
        assert!(samples < 420, "not failing after {samples} samples (70 minutes)");
        if b.write_errors < 3 {
            assert_eq!(board_status(&mut b, "alarm"), "off", "{} failed stores", b.write_errors);
        }
    }
    assert!(b.write_errors >= 3);
    b.step().unwrap();
    assert_eq!(board_status(&mut b, "alarm"), "unacknowledged");
    assert_eq!(rows(&mut b), 1);
    // Acknowledged, it stays quiet while the same run of failures goes on.
    assert!(b.request("ack").ends_with("ok\r\n"));
    for _ in 0..2 * 360 {
        b.step().unwrap();
    }
    assert_eq!((board_status(&mut b, "flash").as_str(), board_status(&mut b, "alarm").as_str()), ("failing", "off"));
    assert_eq!(rows(&mut b), 1);
    // Lifted: the next store ends it (the hourly history at the latest).
    b.write_protect(false, false);
    for _ in 0..361 {
        b.step().unwrap();
    }
    assert_eq!(board_status(&mut b, "flash"), "ok");
    // A new run of failures is a new report.
    b.write_protect(false, true);
    while board_status(&mut b, "flash") == "ok" {
        b.step().unwrap();
        samples += 1;
        assert!(samples < 20 * 360, "not failing again after {samples} samples");
    }
    b.step().unwrap();
    assert_eq!(board_status(&mut b, "alarm"), "unacknowledged");
    assert_eq!(rows(&mut b), 2);
}

/// `--fault` rehearses a failure over the interface, as an engineer would before the field: a
/// relay that shorts after an hour on a board with the module-side sense. `status` shows limp
/// home and the alarm, `history` the event within two samples of the short. A hung control loop is
/// refused in one line (the virtual board answers requests from its loop).
#[test]
fn a_fault_injected_on_the_virtual_board_shows_in_status_and_history() {
    let b = Board::start("fault", &["--module-sense", "--fault", "ssr-stuck-on@3600"]);
    let s = b.wait_for("limp home after the shorted relay", 60, |s| s["mode"] == "limp_home");
    assert_ne!(s["alarm"], "off", "{s}");
    let csv = tmp("fault.csv");
    assert!(b.board(&["history", "--output", csv.to_str().unwrap()]).status.success());
    let text = std::fs::read_to_string(&csv).unwrap();
    let found: Vec<f64> = text
        .lines()
        .filter(|l| l.ends_with(",ssr_stuck_on"))
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    // Record time runs 1 s ahead of the board's clock (the log starts at 1 s).
    assert_eq!(found.len(), 1, "{text}");
    assert!((3601.0..=3631.0).contains(&found[0]), "found at {} s", found[0]);
    let _ = std::fs::remove_file(&csv);

    let link = tmp("hang");
    let e = one_line_error(&hter(&["virtual-board", "--link", link.to_str().unwrap(), "--fault", "firmware-hang@10"]));
    assert!(e.contains("firmware-hang"), "{e}");
    assert!(!link.exists());
}

/// A board fault rehearsed over the interface: `--fault board-fault-hard-fault@600` takes the
/// virtual board through the fail-safe's stop and reset; `status` shows the latched alarm and a
/// restart, `history` the `board_fault_hard_fault` row. A board fault kind the library does not
/// have is refused in one line that lists the kinds.
#[test]
fn a_board_fault_rehearsed_on_the_virtual_board_shows_in_status_and_history() {
    let b = Board::start("boardfault", &["--fault", "board-fault-hard-fault@600"]);
    let s = b.wait_for("the restart after the stop", 60, |s| s["resets"] == 1);
    assert_eq!(s["alarm"], "unacknowledged", "{s}");
    let csv = tmp("boardfault.csv");
    assert!(b.board(&["history", "--output", csv.to_str().unwrap()]).status.success());
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().filter(|l| l.ends_with(",board_fault_hard_fault")).count(), 1, "{text}");
    let _ = std::fs::remove_file(&csv);

    let link = tmp("boardfault-bad");
    let e = one_line_error(&hter(&[
        "virtual-board",
        "--link",
        link.to_str().unwrap(),
        "--fault",
        "board-fault-gremlin@10",
    ]));
    assert!(e.contains("board-fault-gremlin") && e.contains("board-fault-control-stall"), "{e}");
    let e =
        one_line_error(&hter(&["virtual-board", "--link", link.to_str().unwrap(), "--fault", "board-fault-panic@-1"]));
    assert!(e.contains("≥ 0"), "{e}");
    assert!(!link.exists());
}

/// A supply that drops two hours after the board first started: the model the self-tuner learnt
/// on this half-loaded carrier was stored after its first trusted hour, so the board restarts
/// from it, not from the full-load start model (which swung the load 3.2–4.6 °C for a quarter
/// of an hour when the first store waited for 4 h). The boot starts every law from the board's
/// boot duty (`profile::BOOT_DUTY`, 0.2), under the 0.46 that holds this load: the load warms to
/// 4.53 °C in the first minutes (3.97–4.12 °C when the boot duty was 0.4).
#[test]
fn a_brown_out_two_hours_in_restarts_from_the_learnt_model() {
    use hal_sim::fault::Fault;
    use hal_sim::plant::Load;
    use hal_sim::sim::virtual_board::{VirtualBoard, VirtualOptions};
    use hal_sim::sim::PlantChoice;
    use hter::control::Controller;
    let opts =
        VirtualOptions { plant: PlantChoice::Hter1, load: Load::Half, ambient_c: 28.0, seed: 1, module_sense: false };
    let mut b = VirtualBoard::new(&opts).unwrap();
    for _ in 0..720 {
        b.step().unwrap();
    }
    b.inject(Fault::Brownout).unwrap();
    assert_eq!(b.restarts, 1);
    // The self-tuner restarts from a stored model: the half load's, not the full-load start.
    let restored = b.app().carrier().controller().status().expect("a self-tuner").theta;
    let start = hter::profile::START_MODEL_HTER1;
    let start_theta = [start.a()[0], start.a()[1], start.b()[0], start.b()[1]];
    assert!(restored[..4].iter().zip(&start_theta).any(|(r, s)| (r - s).abs() > 1e-3), "{restored:?}");
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for _ in 0..360 {
        b.step().unwrap();
        lo = lo.min(b.load_c());
        hi = hi.max(b.load_c());
    }
    assert!(lo > 3.85 && hi < 4.6, "the hour after the restart: {lo:.2}…{hi:.2} °C");
}

/// A full H-TER I whose SSR opens after its first sample (a cabinet that cannot cool), on the
/// virtual board until its history counts `heat_10h`, with a power cut before each sample that
/// `cut(simulated s, restarts so far)` asks for. Returns the board, the hours from the load
/// crossing 8 °C to the alarm, and the seconds the load spent above 8 °C.
fn warm_until_heat_10h(cut: impl Fn(f64, u32) -> bool) -> (hal_sim::sim::virtual_board::VirtualBoard, f64, f64) {
    use hal_sim::fault::Fault;
    use hal_sim::plant::Load;
    use hal_sim::sim::virtual_board::{VirtualBoard, VirtualOptions};
    use hal_sim::sim::PlantChoice;
    use hter::coldchain::AlarmKind;
    let opts =
        VirtualOptions { plant: PlantChoice::Hter1, load: Load::Full, ambient_c: 28.0, seed: 1, module_sense: false };
    let mut b = VirtualBoard::new(&opts).unwrap();
    b.step().unwrap();
    b.inject(Fault::SsrStuckOff).unwrap();
    let (mut warm_s, mut warm_since) = (0.0, None);
    while b.app().recorder().history().alarms_of(AlarmKind::Heat10h) == 0 {
        if cut(b.sim_s(), b.restarts) {
            b.inject(Fault::Brownout).unwrap();
        }
        b.step().unwrap();
        if b.load_c() > 8.0 {
            warm_s += 10.0;
            warm_since.get_or_insert(b.sim_s());
        }
        assert!(b.sim_s() < 24.0 * 3600.0, "no heat_10h in 24 h");
    }
    let run_h = (b.sim_s() - warm_since.expect("the load warmed past 8 °C")) / 3600.0;
    (b, run_h, warm_s)
}

/// A heat run goes on through a brown-out, on the board's whole path (the history stored to the
/// mock flash, the boot that restores it): a cabinet that cannot cool warms past 8 °C, the power
/// goes 6 h in, and `heat_10h` comes 10 h after the load crossed 8 °C, late by at most the
/// 10 minutes the last store missed (stores come every 10 minutes during an excursion). The
/// board started the run over at the restart and raised it 10 h after that, 15.9 h after the
/// crossing.
#[test]
fn a_heat_run_goes_on_through_a_brown_out() {
    let (_, run_h, _) = warm_until_heat_10h(|t_s, restarts| t_s >= 6.0 * 3600.0 && restarts == 0);
    assert!((10.0..=10.2).contains(&run_h), "heat_10h {run_h:.2} h after the load crossed 8 °C");
}

/// A supply that drops every 50 minutes, shorter than the hourly store: the history is stored
/// every 10 minutes while the load is outside 2…8 °C, so each boot's part of the excursion is
/// on record but for the minutes since its last store, and the heat run goes on from boot to
/// boot. With the hourly store alone no boot stored a sample: the record kept the resets and
/// nothing of a day of heat, and `heat_10h` never came.
#[test]
fn a_supply_that_drops_every_50_minutes_still_records_the_excursion() {
    let (mut b, run_h, warm_s) = warm_until_heat_10h(|t_s, restarts| t_s >= 3000.0 * f64::from(restarts + 1));
    // Each 50-minute boot loses at most the 10 minutes since its last store.
    assert!((10.0..=10.0 * 50.0 / 40.0 + 0.5).contains(&run_h), "heat_10h {run_h:.2} h after the crossing");
    let history = b.app().recorder().history();
    let recorded = f64::from(history.above_8_s);
    assert!(recorded > 0.75 * warm_s, "{recorded} s above 8 °C on record of {warm_s} s");
    // One excursion, whatever the restarts inside it (each had counted one more, and the
    // record's four newest were pieces of this one), from the crossing in the first boot.
    assert!(b.restarts >= 10, "{} restarts", b.restarts);
    let newest = history.last.iter().flatten().copied().collect::<Vec<_>>();
    assert_eq!(history.excursions, 1, "{newest:?}");
    assert_eq!(newest.len(), 1, "{newest:?}");
    assert!(newest[0].start_s < 3000.0, "{newest:?}");
    assert!(
        f64::from(newest[0].end_s - newest[0].start_s) >= 0.99 * recorded,
        "{newest:?} against {recorded} s above 8 °C"
    );
    assert!(history.open_excursion().is_some());
    // `hter monitor` on the board's own interval log across the restarts counts the same one.
    let reply = b.request("history");
    let csv: String = reply.lines().filter(|l| *l != "ok").map(|l| format!("{l}\n")).collect();
    let p = tmp("drops-history.csv");
    std::fs::write(&p, &csv).unwrap();
    let input = hal_sim::monitor_cmd::read_input(&p).unwrap();
    let _ = std::fs::remove_file(&p);
    let r = hal_sim::monitor_cmd::record(&input).unwrap();
    assert_eq!(r.excursions, history.excursions, "hter monitor on the board's history rows");
}

/// The history of a cabinet that cannot cool, as `hter monitor` and `hter report` read it: each
/// interval row covers the 5 minutes that end at its `t_s`, so the record starts at 0 s, and the
/// heat run recomputed from the rows' means starts and triggers within an interval of the
/// carrier's own `heat_10h` (raised on its 10 s samples), and its time above 8 °C is the
/// carrier's within an interval. Read as samples at their `t_s`, the record began at 300 s and
/// the recomputed run started and triggered an interval late.
#[test]
fn a_board_historys_heat_run_is_read_at_the_times_the_carrier_saw_it() {
    use hal_sim::monitor_cmd;
    let (mut b, _, _) = warm_until_heat_10h(|_, _| false);
    // An hour more, then the history up to the latest closed interval.
    for _ in 0..360 {
        b.step().unwrap();
    }
    let reply = b.request("history");
    let csv: String = reply.lines().filter(|l| *l != "ok").map(|l| format!("{l}\n")).collect();
    let p = tmp("heat-history.csv");
    std::fs::write(&p, &csv).unwrap();
    let input = monitor_cmd::read_input(&p).unwrap();
    let _ = std::fs::remove_file(&p);
    let r = monitor_cmd::record(&input).unwrap();
    let heat = |a: &[monitor_cmd::AlarmOut]| a.iter().find(|a| a.kind == "heat_10h").cloned().expect("heat_10h");
    let (ours, carrier) = (heat(&r.alarms), heat(&monitor_cmd::carrier_alarms(&input.events).unwrap()));
    let end = *input.t_s.last().unwrap();
    eprintln!("recomputed {ours:?}, the carrier's {carrier:?}; above 8 °C {} s to {end} s", r.time_above_8_s);
    assert_eq!(input.t_s[0], 0.0, "the first row covers 0 … 300 s");
    assert!((ours.start_s - carrier.start_s).abs() < 300.0, "{ours:?} {carrier:?}");
    assert!((ours.trigger_s - carrier.trigger_s).abs() < 300.0, "{ours:?} {carrier:?}");
    // The carrier's own count of time above 8 °C, up to its latest sample, less the part after
    // the last row's end.
    let recorded = f64::from(b.app().recorder().history().above_8_s) - (b.sim_s() - end);
    assert!((r.time_above_8_s - recorded).abs() < 300.0, "{} s above 8 °C, the carrier {recorded} s", r.time_above_8_s);
}

/// Several requests in one write, malformed ones among them: the board frames and answers one
/// line at a time, so each reply comes in the order of its line. The virtual board sent the
/// refusal of a line as soon as it read it, ahead of the replies to the lines before it.
#[test]
fn lines_sent_in_one_write_are_answered_in_order() {
    use std::io::{Read, Write};
    let b = Board::start("order", &[]);
    let mut port = serialport::new(b.port(), 115_200).timeout(Duration::from_secs(20)).open_native().unwrap();
    let long = "z".repeat(hter::iface::MAX_LINE + 1);
    port.write_all(format!("get\n\x01\nhelp\n{long}\nstatus\r\nx\ty\n").as_bytes()).unwrap();
    // Six lines, six final lines (`ok` or `err …`).
    let finals = |t: &str| t.lines().filter(|l| *l == "ok" || l.starts_with("err ")).count();
    let mut text = String::new();
    let mut buf = [0u8; 4096];
    while finals(&text) < 6 || !text.ends_with('\n') {
        let n = port.read(&mut buf).expect("the replies within 20 s");
        text.push_str(std::str::from_utf8(&buf[..n]).unwrap());
    }
    // Each reply as (the key or text of its first line, its final line).
    let mut replies = Vec::new();
    let mut first: Option<String> = None;
    for l in text.lines() {
        let head = first.get_or_insert_with(|| l.split('=').next().unwrap_or(l).to_string()).clone();
        if l == "ok" || l.starts_with("err ") {
            replies.push((head, l.to_string()));
            first = None;
        }
    }
    let not_printable = "err line: a byte outside printable ASCII";
    let too_long = "err line: too long (at most 96 bytes)";
    let got: Vec<(&str, &str)> = replies.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
    assert_eq!(got.len(), 6, "{text}");
    assert_eq!(got[0], ("setpoint_c", "ok"), "get first: {text}");
    assert_eq!(got[1], (not_printable, not_printable), "{text}");
    assert_eq!(got[2].1, "ok", "help: {text}");
    assert_eq!(got[3], (too_long, too_long), "{text}");
    assert_eq!(got[4], ("t_s", "ok"), "status: {text}");
    assert_eq!(got[5], (not_printable, not_printable), "{text}");
}

/// A `hter board … identify` following a commissioning in the background, stopped on drop.
struct Watcher(Child);

impl Watcher {
    fn start(args: &[&str]) -> Watcher {
        let child = Command::new(env!("CARGO_BIN_EXE_hter"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        Watcher(child)
    }

    fn running(&mut self) -> bool {
        self.0.try_wait().unwrap().is_none()
    }

    /// Waits for it to end (wall time limit): its exit status, stdout and stderr.
    fn finish(&mut self, limit_s: u64) -> (std::process::ExitStatus, String, String) {
        use std::io::Read;
        let t0 = Instant::now();
        let status = loop {
            if let Some(st) = self.0.try_wait().unwrap() {
                break st;
            }
            assert!(t0.elapsed() < Duration::from_secs(limit_s), "the watch did not end");
            std::thread::sleep(Duration::from_millis(200));
        };
        let (mut out, mut err) = (String::new(), String::new());
        self.0.stdout.take().unwrap().read_to_string(&mut out).unwrap();
        self.0.stderr.take().unwrap().read_to_string(&mut err).unwrap();
        (status, out, err)
    }
}

impl Drop for Watcher {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `identify` follows a commissioning for hours (≈ 6.2 h on a board, 37 s here): meanwhile an
/// engineer checks the status, acknowledges an alarm and saves the record from another shell.
/// The watch opens the port for each poll only; a poll that finds the port held by another
/// client tries again at the next one. The watch held the port for the whole commissioning,
/// and every other `hter board` command was refused.
#[test]
fn while_identify_follows_the_commissioning_other_commands_get_through() {
    let b = Board::start("follow", &[]);
    b.wait_for("an hour at 4 °C", 60, |s| s["t_s"].as_f64().is_some_and(|t| t > 3600.0));
    let mut watch = Watcher::start(&["board", "--port", b.port(), "identify"]);
    let running = |s: &serde_json::Value| s["commissioning"].as_str().is_some_and(|c| c != "idle" && c != "done");
    b.wait_for("the commissioning runs", 60, running);
    for _ in 0..3 {
        let s = b.status();
        assert!(running(&s), "{s}");
        assert!(watch.running(), "the watch still follows");
    }
    let o = b.board(&["ack"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = b.board(&["set", "ack", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = tmp("follow.csv");
    let o = b.board(&["history", "--output", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = std::fs::remove_file(&csv);
    // Another client holds the port for a few of the watch's polls (a terminal program left
    // open, a long history download): the watch tries again and carries on.
    let t0 = Instant::now();
    let held = loop {
        match serialport::new(b.port(), 115_200).open_native() {
            Ok(p) => break p,
            Err(e) => assert!(t0.elapsed() < Duration::from_secs(30), "the port stays held: {e}"),
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    std::thread::sleep(Duration::from_secs(3));
    drop(held);
    assert!(watch.running(), "a held port ended the watch");
    let (status, out, err) = watch.finish(180);
    assert!(status.success(), "{out} / {err}");
    assert!(out.contains("commissioning done: control model"), "{out}");
    assert_eq!(b.status()["commissioning"], "done");
}

/// A board that goes away while `identify` follows it (unplugged; here the virtual board
/// stopped, which removes its link): the watch gives up after six --timeout without an answer,
/// in one line that says the commissioning may go on and how to look; not at the first missed
/// poll (a cable reseated comes back), not never.
#[test]
fn a_board_that_goes_away_while_identify_follows_ends_the_watch_in_one_line() {
    let mut b = Board::start("gone", &[]);
    b.wait_for("an hour at 4 °C", 60, |s| s["t_s"].as_f64().is_some_and(|t| t > 3600.0));
    let mut watch = Watcher::start(&["board", "--port", b.port(), "--timeout", "1", "identify"]);
    b.wait_for("the commissioning runs", 60, |s| s["commissioning"].as_str().is_some_and(|c| c != "idle"));
    // SIGTERM: the virtual board removes its link as it stops.
    // SAFETY: a signal to the child this test started.
    assert_eq!(unsafe { libc::kill(b.child.id() as libc::pid_t, libc::SIGTERM) }, 0);
    b.child.wait().unwrap();
    assert!(!b.link.exists());
    let (status, _, err) = watch.finish(120);
    assert!(!status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(b.port()) && err.contains("no answer") && err.contains("6 s"), "{err}");
    assert!(err.contains("status"), "says how to look: {err}");
}

/// The README's sequence: `set setpoint_c 5` on a carrier holding 4 °C, then `identify`. The
/// commissioning rests and excites around the last hour's mean duty, which then still holds the
/// 4 °C duty and the transient. Without the wait, on this board (H-TER I full, 28 °C, seed 1),
/// a change 10 or 20 min after the boot and `identify` 0–31 min later ended `poor_fit` or
/// `implausible_gain` after its 6 h in 11 of 12 starts; after a change at 1 h, the starts 31
/// and 50 min later did (those 0–20 min later, on a mean still of the steady 4 °C, did not);
/// from 70 min after the change all 6 starts ran to `done` (without a change, every start from
/// 20 min after the boot did). Here: the change 20 min after the boot, `identify` refused 20 min
/// later (it would end `poor_fit`), accepted 70 min after the change and run to `done`.
/// A virtual H-TER I with `load`, seed 1, at `ambient_c`, booted as `start` says.
fn virtual_hter1(
    load: hal_sim::plant::Load,
    ambient_c: f64,
    start: hal_sim::scenario::Start,
) -> hal_sim::sim::virtual_board::VirtualBoard {
    use hal_sim::sim::virtual_board::{VirtualBoard, VirtualOptions};
    let opts =
        VirtualOptions { plant: hal_sim::sim::PlantChoice::Hter1, load, ambient_c, seed: 1, module_sense: false };
    VirtualBoard::starting(&opts, start).unwrap()
}

/// `key`'s value in the board's `status`.
fn board_status(b: &mut hal_sim::sim::virtual_board::VirtualBoard, key: &str) -> String {
    let reply = b.request("status");
    let prefix = format!("{key}=");
    reply.lines().find_map(|l| l.strip_prefix(prefix.as_str())).map(str::to_string).unwrap()
}

/// Runs the commissioning `identify` started to its end, which must be `done`.
fn commissioning_ends_done(b: &mut hal_sim::sim::virtual_board::VirtualBoard) {
    let mut m = 0;
    loop {
        b.step().unwrap();
        let c = board_status(b, "commissioning");
        if c == "done" {
            return;
        }
        assert!(!c.starts_with("failed"), "{c} after {m} samples");
        m += 1;
        assert!(m < 2500, "{c}");
    }
}

/// After a boot the duty mean is empty, and a commissioning started at once rested at the
/// fallback PI's bias, which is the carrier's holding duty only near 28 °C: at 36 °C it ended
/// `fault_out_of_band` 110 samples in (at 20 °C 368, at 43 °C 73; 60 samples after the boot,
/// `poor_fit`). It waits one block of the mean, 30 minutes, after a boot that holds its setpoint.
#[test]
fn identify_waits_half_an_hour_after_a_boot() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 36.0, hal_sim::scenario::Start::Holding(4.0));
    b.step().unwrap();
    let mut n = 1;
    loop {
        let r = b.request("identify");
        if r == "ok\r\n" {
            break;
        }
        assert!(r.starts_with("err identify: the carrier has not held its setpoint long enough"), "{r}");
        b.step().unwrap();
        n += 1;
        assert!(n <= 180, "still refused after {n} samples");
    }
    assert_eq!(n, 180, "one block of the duty mean, 30 min, after the boot");
    commissioning_ends_done(&mut b);
}

/// A carrier just switched on pulls its load down from the ambient at full duty. An engineer
/// commissioning a new cabinet powers it up and asks for `identify` once the load is at its
/// setpoint: the duty mean was then the pull-down's (≈ 0.9), the commissioning rested there and
/// drove the load into the freeze guard 31 samples later (`failed:fault_freeze_guard`). It is
/// refused until the load has held within 1.5 °C of the setpoint for 70 minutes, and then ends
/// `done`.
#[test]
fn identify_waits_until_a_pulled_down_carrier_has_held_its_setpoint() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Ambient);
    assert!(b.load_c() > 27.0, "switched on at the ambient: {}", b.load_c());
    // The sample whose reading was last more than 1.5 °C from the setpoint.
    let (mut n, mut last_out) = (0, 0);
    while (b.load_c() - 4.0).abs() > 0.3 {
        b.step().unwrap();
        n += 1;
        let reading: f64 = board_status(&mut b, "temp_c").parse().unwrap();
        if (reading - 4.0).abs() > 1.5 {
            last_out = n;
        }
        assert!(n < 1000, "{}", b.load_c());
    }
    // At its setpoint after the pull-down (211 samples): not yet.
    let r = b.request("identify");
    assert!(r.starts_with("err identify: the carrier has not held its setpoint long enough"), "{r}");
    assert_eq!(board_status(&mut b, "commissioning"), "idle");
    // Once it has held within 1.5 °C for 70 minutes, accepted, and it ends with a model.
    while b.request("identify") != "ok\r\n" {
        b.step().unwrap();
        n += 1;
        assert!(n < last_out + 500, "still refused {} samples after the last reading out", n - last_out);
    }
    assert_eq!(n - last_out, 420, "70 minutes (420 samples) after the last reading more than 1.5 °C out");
    commissioning_ends_done(&mut b);
}

#[test]
fn identify_waits_until_the_carrier_has_held_a_new_setpoint() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Full, 28.0, hal_sim::scenario::Start::Holding(4.0));
    for _ in 0..120 {
        b.step().unwrap();
    }
    assert_eq!(b.request("set setpoint_c 5"), "ok\r\n");
    // 20 min on: the load is at 5 °C, the mean duty is not yet its.
    for _ in 0..120 {
        b.step().unwrap();
    }
    assert!((b.load_c() - 5.0).abs() < 0.3, "{}", b.load_c());
    let r = b.request("identify");
    assert!(r.starts_with("err identify: the carrier has not held its setpoint long enough"), "{r}");
    assert_eq!(board_status(&mut b, "commissioning"), "idle");
    assert_eq!(board_status(&mut b, "controller"), "gpc");
    // An unchanged setpoint moves nothing and restarts no wait.
    assert_eq!(b.request("set setpoint_c 5.00"), "ok\r\n");
    for _ in 120..420 {
        b.step().unwrap();
    }
    assert_eq!(b.request("identify"), "ok\r\n");
    commissioning_ends_done(&mut b);
}

/// On-Off holds its setpoint with a limit cycle of up to 3 °C peak to peak about a point off it
/// (half a load at 20 °C: −2.3 … +0.8 °C): a commissioning started from it rests at its mean
/// duty from wherever the cycle left the load, and here it ended `fault_out_of_band` 3 h in
/// (13 of 16 such runs failed, 12 after 3–5 h). `identify` is refused under On-Off, saying what
/// to do; 70 minutes after `set controller gpc` (and the load back near the setpoint) it is
/// accepted and ends `done`.
#[test]
fn identify_is_refused_under_onoff_and_runs_70_min_after_gpc_is_set() {
    let mut b = virtual_hter1(hal_sim::plant::Load::Half, 20.0, hal_sim::scenario::Start::Holding(4.0));
    b.step().unwrap();
    assert!(b.request("set controller onoff").ends_with("ok\r\n"));
    for _ in 0..720 {
        b.step().unwrap();
    }
    let refused = b.request("identify");
    assert!(refused.starts_with("err identify: the carrier runs onoff"), "{refused}");
    assert!(refused.contains("set controller gpc"), "{refused}");
    assert_eq!(board_status(&mut b, "controller"), "onoff");
    assert!(b.request("set controller gpc").ends_with("ok\r\n"));
    let mut n = 0;
    while b.request("identify") != "ok\r\n" {
        b.step().unwrap();
        n += 1;
        assert!(n < 600, "still refused {n} samples after gpc was set");
    }
    // 70 minutes after the setting, or after GPC brought the cycle's low back within 1.5 °C.
    assert!((420..=450).contains(&n), "{n} samples after gpc was set");
    commissioning_ends_done(&mut b);
}
