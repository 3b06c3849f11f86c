//! A field log as a carrier's debug port records it, through `hter log2csv` and `hter monitor`:
//! sensor-fault samples before the first good reading, a watchdog reset and a fail-safe stop
//! (a panic) in the middle of a warm excursion.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hter-field-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// One telemetry line as probe-rs prints it (host timestamp, level, message, location line).
fn sample(t: u32, temp: &str, mode: &str, alarm: &str) -> String {
    let duty = if mode == "Normal" { "0.45" } else { "0" };
    format!(
        "{t}.000000 INFO  t={t} temp={temp} sp=4 duty={duty} mode={mode} counts=49918 supply=12.02 alarm={alarm}\n\
         └─ firmware::__telemetry_task @ src/main.rs:289\n"
    )
}

fn boot(cause: &str) -> String {
    format!(
        "0.000000 INFO  reset cause: {cause}\n└─ firmware::__main_task @ src/main.rs:107\n\
         0.000000 INFO  hter firmware 0.1.0: Ts = 10 s, setpoint 4 °C, SSR PWM 1 Hz (10000 ticks)\n\
         └─ firmware::__main_task @ src/main.rs:108\n0.001000 INFO  controller: gpc\n"
    )
}

/// Boot 0 (power-on): no reading for 3 samples, 5 °C, then 9 °C from t = 100. A watchdog reset
/// after t = 110; boot 1 at 9.5 °C for 3 samples, then 5 °C. A panic after its t = 60; boot 2
/// has no reading at t = 0, then 4 °C.
fn field_log() -> String {
    let mut log = boot("BrownOut");
    for t in [0, 10, 20] {
        log += &sample(t, "NaN", "SensorFault", "NotInControl");
        if t == 0 {
            log += "0.000000 WARN  event t=0 SensorOpen\n";
        }
    }
    log += "30.000000 WARN  event t=30 SensorRecovered\n";
    for t in (30..=90).step_by(10) {
        log += &sample(t, "5", "Normal", "Off");
    }
    for t in [100, 110] {
        log += &sample(t, "9", "Normal", "OutOfRange");
    }
    log += &boot("Watchdog");
    for t in [0, 10, 20] {
        log += &sample(t, "9.5", "Normal", "OutOfRange");
    }
    for t in (30..=60).step_by(10) {
        log += &sample(t, "5", "Normal", "Off");
    }
    log += &boot("Other");
    log += "0.000100 ERROR board fault: Panic pc=0x00000000 addr=0x00000000 detail=0x2a src/step.rs\n\
            └─ firmware::__main_task @ src/main.rs:104\n";
    log += &sample(0, "NaN", "SensorFault", "NotInControl");
    for t in (10..=40).step_by(10) {
        log += &sample(t, "4", "Normal", "Off");
    }
    log
}

#[test]
fn a_field_log_with_faults_and_resets_goes_through_log2csv_and_monitor() {
    let d = dir("resets");
    let (log, csv) = (d.join("carrier.log"), d.join("carrier.csv"));
    std::fs::write(&log, field_log()).unwrap();
    let out = hter(&["log2csv", "--input", s(&log), "--output", s(&csv)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("24 samples (4 with no temperature"), "{err}");
    assert!(err.contains("3 boot(s)") && err.contains("no wall clock") && err.contains("2 reset gap(s)"), "{err}");
    assert!(err.contains("10 s, from the boot line"), "{err}");

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm,boot,reset_cause,holdover_s,events")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == 12), "{text}");
    // The step's events, on the sample they were logged with.
    let events: Vec<(&str, &str)> = rows.iter().filter(|r| !r[11].is_empty()).map(|r| (r[0], r[11])).collect();
    assert_eq!(events, [("0", "sensor_open"), ("30", "sensor_recovered")]);
    // Each boot's t = 0 one sample period after the previous boot's last sample.
    let t: Vec<f64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    let expected: Vec<f64> =
        (0..=110).step_by(10).chain((120..=180).step_by(10)).chain((190..=230).step_by(10)).map(f64::from).collect();
    assert_eq!(t, expected);
    let faults: Vec<(f64, &str)> =
        rows.iter().filter(|r| r[2].is_empty()).map(|r| (r[0].parse().unwrap(), r[4])).collect();
    assert_eq!(
        faults,
        vec![(0.0, "sensor_fault"), (10.0, "sensor_fault"), (20.0, "sensor_fault"), (190.0, "sensor_fault")]
    );
    assert_eq!(rows[3][2..5], ["5", "0.45", "normal"]);
    // The indicator as the library spells it.
    let alarms: Vec<&str> = [0, 3, 10, 12].iter().map(|&i| rows[i][7]).collect();
    assert_eq!(alarms, ["not_in_control", "off", "out_of_range", "out_of_range"]);
    let boots: Vec<&str> = rows.iter().map(|r| r[8]).collect();
    assert_eq!(boots, [["0"; 12].as_slice(), &["1"; 7], &["2"; 5]].concat());
    let causes: Vec<(usize, &str)> =
        rows.iter().enumerate().filter(|(_, r)| !r[9].is_empty()).map(|(i, r)| (i, r[9])).collect();
    assert_eq!(causes, vec![(0, "restarted_brownout"), (12, "restarted_watchdog"), (19, "board_fault_panic")]);

    let out = hter(&["monitor", "--input", s(&csv), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Held samples: 9 °C over 100–120 (across the watchdog reset), 9.5 °C over 120–150.
    assert_eq!(v["time_above_8_s"].as_f64(), Some(50.0), "{v}");
    assert_eq!(v["time_below_2_s"].as_f64(), Some(0.0), "{v}");
    // 0–30 and 190–200 have no reading; 5 °C over 30–100 and 150–190, 4 °C over 200–230.
    assert_eq!(v["time_no_reading_s"].as_f64(), Some(40.0), "{v}");
    assert_eq!(v["fault_samples"], 4, "{v}");
    assert_eq!(v["time_in_range_s"].as_f64(), Some(140.0), "{v}");
    assert_eq!((v["min_c"].as_f64(), v["max_c"].as_f64()), (Some(4.0), Some(9.5)), "{v}");
    assert_eq!(v["excursions"], 1, "{v}");
    assert_eq!(v["alarms"], serde_json::json!([]), "{v}");
    // Mean kinetic temperature over the 190 s with a reading, in f64 from its definition.
    let dh_r = 83_144.0 / 8.314;
    let held = [(5.0, 110.0), (9.0, 20.0), (9.5, 30.0), (4.0, 30.0)];
    let total: f64 = held.iter().map(|(_, dt)| dt).sum();
    let mean = held.iter().map(|(c, dt)| dt * (-dh_r / (c + 273.15f64)).exp()).sum::<f64>() / total;
    let mkt = dh_r / -mean.ln() - 273.15;
    assert!((v["mkt_c"].as_f64().unwrap() - mkt).abs() < 0.01, "{v} vs {mkt} °C");

    let out = hter(&["monitor", "--input", s(&csv)]);
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && report.contains("no reading (sensor fault)"), "{report}");

    // Identification needs every sample: it refuses the fault rows on one line.
    let out = hter(&["identify", "--input", s(&csv)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.trim_end().lines().count() == 1, "{err}");
    assert!(err.contains("line 2, column 'temp_c'") && err.contains("sensor-fault"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_lost_reset_line_still_starts_a_boot() {
    let d = dir("lost");
    let (log, csv) = (d.join("carrier.log"), d.join("carrier.csv"));
    // The boot lines of the second boot were lost (the host attached late): only t going back
    // shows the reset.
    let mut text = boot("BrownOut");
    for t in (0..=50).step_by(10) {
        text += &sample(t, "4", "Normal", "Off");
    }
    for t in (0..=20).step_by(10) {
        text += &sample(t, "4.5", "Normal", "Off");
    }
    std::fs::write(&log, text).unwrap();
    let out = hter(&["log2csv", "--input", s(&log), "--output", s(&csv)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!((rows[6][0], rows[6][8], rows[6][9]), ("60", "1", "unknown"));
    assert_eq!(rows.last().map(|r| r[0]), Some("80"));
    let out = hter(&["monitor", "--input", s(&csv), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["time_in_range_s"].as_f64(), v["fault_samples"].as_u64()), (Some(80.0), Some(0)), "{v}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn monitor_still_refuses_time_going_back_on_one_line() {
    let d = dir("back");
    let csv = d.join("joined-by-hand.csv");
    std::fs::write(&csv, "t_s,temp_c\n0,4\n10,\n20,4\n0,4\n").unwrap();
    let out = hter(&["monitor", "--input", s(&csv), "--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("line 5") && err.contains("does not increase") && !err.contains("panicked"), "{err}");
    // A log with no reading at all is an error, not a report of nothing.
    std::fs::write(&csv, "t_s,temp_c\n0,\n10,\n").unwrap();
    let out = hter(&["monitor", "--input", s(&csv)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("it has 0"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}
