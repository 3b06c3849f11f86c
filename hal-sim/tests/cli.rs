//! The `hter` binary as a user runs it: bad input gives one line on stderr and a non-zero exit.

use std::process::{Command, Output};

use hter::event::EventKind;

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

/// The cells of the column `name` of a `hter sim --csv` text, one per row after the header.
fn column(text: &str, name: &str) -> Vec<String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let i = header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name} column: {header:?}"));
    lines.map(|l| l.split(',').nth(i).unwrap_or_else(|| panic!("short row {l}")).to_string()).collect()
}

fn assert_one_line_error(args: &[&str], needle: &str) {
    let out = hter(args);
    assert!(!out.status.success(), "{args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: not one line: {err}");
    assert!(err.starts_with("error: "), "{args:?}: {err}");
    assert!(err.contains(needle), "{args:?}: '{needle}' not in: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
}

#[test]
fn bad_input_is_a_one_line_error() {
    assert_one_line_error(&["sim", "--scenario", "nope"], "unknown scenario 'nope'");
    assert_one_line_error(&["sim", "--controller", "magic"], "magic");
    assert_one_line_error(&["sim", "--ambient", "NaN"], "finite");
    assert_one_line_error(&["sim", "--duration", "-5"], "duration");
    assert_one_line_error(&["sim", "--scenario", "/no/such/file.json"], "cannot read scenario file");
    assert_one_line_error(&["rtd", "--ohms", "-3"], "positive");
    assert_one_line_error(&["rtd", "--ohms", "nan"], "finite");
    assert_one_line_error(&["rtd", "--celsius", "inf"], "finite");
    assert_one_line_error(&["rtd", "--celsius", "2000"], "outside");
    assert_one_line_error(&["rtd", "--ohms", "100", "--r0", "500"], "--r0");
    assert_one_line_error(&["rtd"], "required");
    assert_one_line_error(&["identify", "--input", "/no/such/log.csv"], "/no/such/log.csv");
    assert_one_line_error(&["sim", "--controller", "gpc", "--lambda", "-1"], "--lambda");
    assert_one_line_error(&["sim", "--controller", "gpc", "--n2", "0"], "N2");
    assert_one_line_error(&["sim", "--controller", "gpc", "--n1", "5", "--n2", "4"], "N1");
    assert_one_line_error(&["sim", "--controller", "gpc", "--nu", "9"], "Nu");
    assert_one_line_error(&["sim", "--controller", "gpc", "--lambda", "inf"], "finite");
    assert_one_line_error(&["sim", "--controller", "igmvc", "--p-pole", "1"], "--p-pole");
    assert_one_line_error(&["sim", "--controller", "igmvc", "--t-pole", "-0.1"], "--t-pole");
    assert_one_line_error(&["sim", "--controller", "gmvc", "--p-pole", "nan"], "finite");
    assert_one_line_error(&["sim", "--plant", "arx:1;x;1"], "not a number");
    assert_one_line_error(&["sim", "--model", "arx:-0.9;0.1;0"], "delay");
    assert_one_line_error(&["sim", "--plant", "hter3"], "unknown plant");
    assert_one_line_error(&["sim", "--model", "arx:1,-1.936,0.936;-0.28,0.27;9"], "without the leading 1");
    assert_one_line_error(
        &["sim", "--plant", "arx:-0.99;-0.5;1", "--commission", "monotone"],
        "--commission needs a physical plant",
    );
    assert_one_line_error(&["sim", "--model", "arx:-0.9;0.1;2"], "does not cool");
    assert_one_line_error(&["sim", "--plant", "arx:1;2;3"], "without the leading 1");
    assert_one_line_error(&["sim", "--plant", "arx:-1.5;-0.1;3"], "not stable");
    assert_one_line_error(&["compare", "--plant", "arx:-0.9;0.1;2"], "does not cool");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--forgetting", "0"], "--forgetting");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--nk", "x"], "'x' is not a delay");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--nk", "11"], "orders out of range");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--method", "oe", "--nc", "1"], "--method rels");
    assert_one_line_error(&["monitor", "--input", "/no/such/log.csv"], "/no/such/log.csv");
}

#[test]
fn rtd_json_matches_iec_60751() {
    let out = hter(&["rtd", "--celsius", "4", "--json"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["ohms"].as_f64().unwrap() - 101.56).abs() < 0.005, "{v}");
    let out = hter(&["rtd", "--ohms", "1385.1", "--r0", "1000", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // 1385.1 Ω is the table value rounded to 0.1 Ω, i.e. ±0.013 °C.
    assert!((v["celsius"].as_f64().unwrap() - 100.0).abs() < 0.02, "{v}");
    // A board conversion through the default front end: 49 918 counts · 2 kΩ / (15 · 65 535)
    // = 101.5600 Ω; Callendar–Van Dusen above 0 °C inverted in f64 gives the reference.
    let out = hter(&["rtd", "--counts", "49918", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = 49_918.0 * 2000.0 / (15.0 * 65_535.0);
    let (a, b) = (3.9083e-3f64, -5.775e-7f64);
    let t = (-a + (a * a - 4.0 * b * (1.0 - r / 100.0)).sqrt()) / (2.0 * b);
    assert!((v["ohms"].as_f64().unwrap() - r).abs() < 1e-4, "{v} vs {r} Ω");
    assert!((v["celsius"].as_f64().unwrap() - t).abs() < 1e-3, "{v} vs {t} °C");
    assert_one_line_error(&["rtd", "--counts", "65535"], "not a working RTD");
    assert_one_line_error(&["rtd", "--counts", "20", "--ohms", "100"], "--counts");
}

#[test]
fn sim_json_has_every_contract_field_and_writes_csv_and_plot() {
    let dir = std::env::temp_dir().join(format!("hter-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("run.csv");
    let png = dir.join("run.png");
    let out = hter(&[
        "sim",
        "--scenario",
        "piecewise",
        "--controller",
        "pi",
        "--json",
        "--csv",
        csv.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "controller",
        "iae",
        "max_abs_error_after_settle_c",
        "overshoot_c",
        "settle_time_s",
        "min_temp_c",
        "max_temp_c",
        "time_outside_2_8_s",
        "energy_wh",
        "ssr_switches",
        "alarms",
        "faults_detected",
        "freeze_guard_trips",
    ] {
        assert!(v.get(key).is_some(), "missing {key} in {v}");
    }
    assert_eq!(v["controller"], "pi");
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap();
    assert!(header.starts_with("t_s,setpoint_c,temp_c,duty"), "{header}");
    assert_eq!(text.lines().count(), 1 + 360, "one row per 10 s sample over 3600 s");
    let png_bytes = std::fs::read(&png).unwrap();
    assert_eq!(&png_bytes[1..4], b"PNG");
    assert!(png_bytes.len() > 10_000);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The method's order conclusion on the simulator's PRBS runs, from the default command a
/// new user types (`hter identify --input prbs.csv`: output error, each order at its best delay
/// 1–10, deviations from the initial rest the log starts with): a 2nd-order model simulates
/// the carrier within a few points of the 4th-order one on both carriers, clearly better than
/// 1st order, and the tool chooses order 2 and says why. Measured (default seed): H-TER I
/// orders 1/2/4 fit 84.8/94.8/95.9 % (nk 6/9/7), H-TER II 89.6/93.1/93.4 % (nk 10/4/9);
/// static gains −43.7 and −45.2 °C per unit duty.
#[test]
fn second_order_model_is_enough_on_both_carriers() {
    for plant in ["hter1", "hter2"] {
        let csv = std::env::temp_dir().join(format!("hter-cli-prbs-{plant}-{}.csv", std::process::id()));
        let csv_s = csv.to_str().unwrap();
        let out = hter(&["sim", "--scenario", "prbs", "--plant", plant, "--csv", csv_s, "--json"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let out = hter(&["identify", "--input", csv_s, "--json"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let _ = std::fs::remove_file(&csv);
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!((&v["method"], &v["nk_choice"]), (&"oe".into(), &"auto".into()), "{plant}: the defaults");
        assert_eq!(v["operating_point"]["kind"], "initial", "{plant}: the log starts at rest");
        let row = |order: u64| {
            v["order_comparison"].as_array().unwrap().iter().find(|r| r["order"] == order).unwrap().clone()
        };
        let (first, second, fourth) = (row(1), row(2), row(4));
        let fit = |r: &serde_json::Value| r["fit_percent"].as_f64().unwrap();
        let (f1, f2, f4) = (fit(&first), fit(&second), fit(&fourth));
        assert!([&first, &second, &fourth].iter().all(|r| r["stable"] == true), "{plant}: {v}");
        assert!(f2 > 90.0, "{plant}: 2nd-order fit {f2} %");
        assert!(f2 >= f4 - 3.0, "{plant}: 2nd order {f2} % vs 4th {f4} %");
        assert!(f1 < f2 - 3.0, "{plant}: 1st order {f1} % vs 2nd {f2} %");
        assert_eq!(v["chosen_order"], 2, "{plant}: {}", v["reason"]);
        let reason = v["reason"].as_str().unwrap();
        assert!(reason.contains("order 4") && reason.contains("order 1"), "{plant}: the reason compares: {reason}");
        // The reported model is the 2nd-order row, at its own delay.
        assert_eq!((&v["na"], &v["nb"]), (&2.into(), &2.into()));
        assert_eq!(v["nk"], second["nk"], "{plant}");
        assert_eq!(v["fit_percent"].as_f64(), Some(f2));
        let scan = v["delay_scan"].as_array().unwrap();
        assert_eq!(scan.len(), 10, "{plant}");
        assert!(scan.iter().all(|r| r["fit_percent"].as_f64().unwrap() <= f2), "{plant}: {scan:?}");
        let gain = v["static_gain_c_per_duty"].as_f64().unwrap();
        assert!((-50.0..-40.0).contains(&gain), "{plant}: gain {gain} °C/duty");
    }
}

#[test]
fn campaign_bad_input_is_a_one_line_error() {
    assert_one_line_error(&["campaign", "--missions", "0"], "--missions");
    assert_one_line_error(&["campaign", "--missions", "abc"], "abc");
    assert_one_line_error(&["campaign", "--missions", "-3"], "-3");
    assert_one_line_error(&["campaign"], "required");
    assert_one_line_error(&["campaign", "--missions", "2", "--controller", "magic"], "magic");
    assert_one_line_error(&["campaign", "--missions", "2", "--seed", "18446744073709551615"], "overflows");
    assert_one_line_error(&["sim", "--mission-seed", "3", "--scenario", "step"], "--scenario");
    assert_one_line_error(&["sim", "--mission-seed", "x"], "x");
}

fn json(args: &[&str]) -> serde_json::Value {
    let out = hter(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{args:?}: {e}"))
}

#[test]
fn small_campaign_reports_the_spec_fields() {
    let v = json(&["campaign", "--missions", "8", "--seed", "100", "--json"]);
    assert_eq!(v["missions"], 8);
    for f in ["freeze_minutes", "fraction_outside_2_8", "worst_min_c", "worst_max_c", "cold_ambient_minutes"] {
        assert!(v[f].as_f64().is_some_and(f64::is_finite), "{f}: {v}");
    }
    let frac = v["fraction_outside_2_8"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&frac), "{v}");
    assert!(v["faults_detected"].as_u64().unwrap() <= v["faults_injected"].as_u64().unwrap(), "{v}");
    // Every fault kind a mission can carry (each `--fault` kind but the spikes, a nuisance the
    // step rides through), each with a detector, whether or not this campaign drew it.
    let kinds = v["faults_by_kind"].as_object().unwrap();
    let expected = [
        "board-fault-control-stall",
        "board-fault-hard-fault",
        "board-fault-nmi",
        "board-fault-panic",
        "board-fault-unexpected-interrupt",
        "brownout",
        "firmware-hang",
        "lid-open",
        "sensor-offset",
        "sensor-open",
        "sensor-short",
        "sensor-stuck",
        "ssr-stuck-off",
        "ssr-stuck-on",
        "supply-sag",
        "supply-switch-short",
    ];
    assert_eq!(kinds.keys().map(String::as_str).collect::<Vec<_>>(), expected, "{v}");
    assert!(kinds.values().all(|k| k["detector"] == true), "{v}");
    let injected: u64 = kinds.values().map(|k| k["injected"].as_u64().unwrap()).sum();
    assert_eq!(injected, v["faults_injected"].as_u64().unwrap());
    // Every failure is one of the campaign's seeds and comes with its replay command.
    let failures = v["failures"].as_array().unwrap();
    assert!(failures.iter().all(|s| (100..108).contains(&s.as_u64().unwrap())), "{v}");
    assert_eq!(v["failure_details"].as_array().unwrap().len(), failures.len());
    assert!(v["worst_min_c"].as_f64().unwrap() > -20.0 && v["worst_max_c"].as_f64().unwrap() < 50.0, "{v}");
}

#[test]
fn a_campaign_mission_replays_with_hter_sim() {
    // Mission 681 with PI fails (it leaves 2–8 °C for ≈ 19 min); mission 115 carries a dead SSR
    // at 61 071 s that the step reports. A replay must show what the campaign judged.
    for (seed, controller) in [("681", "pi"), ("115", "gpc")] {
        let c = json(&["campaign", "--missions", "1", "--seed", seed, "--controller", controller, "--json"]);
        let s = json(&["sim", "--mission-seed", seed, "--controller", controller, "--json"]);
        assert_eq!(c["worst_min_c"].as_f64(), s["min_temp_c"].as_f64(), "{c}\n{s}");
        if seed == "681" {
            assert_eq!(c["failures"], serde_json::json!([681]), "{c}");
            let replay = c["failure_details"][0]["replay"].as_str().unwrap();
            assert_eq!(replay, "hter sim --mission-seed 681 --controller pi --json");
            assert!(s["time_outside_2_8_s"].as_f64().unwrap() > 600.0, "{s}");
        } else {
            assert_eq!(c["failures"], serde_json::json!([]), "{c}");
            assert_eq!(c["faults_by_kind"]["ssr-stuck-off"]["detected"], 1, "{c}");
            let found = s["faults_detected"]
                .as_array()
                .unwrap()
                .iter()
                .any(|f| f["kind"] == EventKind::SsrStuckOff.name() && f["t_s"].as_f64().unwrap() >= 61071.0);
            assert!(found, "{s}");
        }
    }
}

#[test]
fn a_buck_campaign_mission_replays_with_its_drive() {
    // Mission 681 with PI fails on the buck drive too (≈ 20 min outside 2–8 °C); its replay line
    // must name the drive, and running that line must show what the campaign judged.
    let c = json(&["campaign", "--missions", "1", "--seed", "681", "--controller", "pi", "--drive", "buck", "--json"]);
    assert_eq!(c["drive"], "buck", "{c}");
    assert_eq!(c["failures"], serde_json::json!([681]), "{c}");
    let replay = c["failure_details"][0]["replay"].as_str().unwrap();
    assert_eq!(replay, "hter sim --mission-seed 681 --controller pi --drive buck --json");
    let args: Vec<&str> = replay.split_whitespace().skip(1).collect();
    let s = json(&args);
    assert_eq!(c["worst_min_c"].as_f64(), s["min_temp_c"].as_f64(), "{c}\n{s}");
    let ssr = json(&["sim", "--mission-seed", "681", "--controller", "pi", "--json"]);
    assert_ne!(s["energy_wh"], ssr["energy_wh"], "the replay ran on the SSR: {s}\n{ssr}");
}

/// `freeze_guard_trips` counts the supervisor's trips, read here from the CSV's `mode` column
/// instead of its events: every entry into `freeze_guard`. A shorted SSR at 5 400 s cools the
/// load into the guard again and again; a clean run never meets it.
#[test]
fn freeze_guard_trips_count_the_entries_into_the_guard() {
    let csv = std::env::temp_dir().join(format!("hter-cli-freeze-{}.csv", std::process::id()));
    let path = csv.to_str().unwrap();
    for (fault, tripped) in [(Some("ssr-stuck-on@5400"), true), (None, false)] {
        let mut args = vec!["sim", "--scenario", "step", "--json", "--csv", path];
        if let Some(f) = fault {
            args.extend(["--fault", f]);
        }
        let v = json(&args);
        let modes = column(&std::fs::read_to_string(&csv).unwrap(), "mode");
        let entries = modes.windows(2).filter(|m| m[0] != "freeze_guard" && m[1] == "freeze_guard").count()
            + usize::from(modes.first().is_some_and(|m| m == "freeze_guard"));
        assert_eq!(v["freeze_guard_trips"].as_u64(), Some(entries as u64), "{fault:?}: {v}");
        assert_eq!(entries > 0, tripped, "{fault:?}: {entries} entries");
    }
    let _ = std::fs::remove_file(&csv);
}

#[test]
fn mission_and_hot_zone_scenarios_hold_2_to_8_after_pull_down() {
    let v = json(&["sim", "--scenario", "mission", "--controller", "gpc", "--json"]);
    assert!(v["min_temp_c"].as_f64().unwrap() >= 2.0, "{v}");
    // Outside 2–8 °C only during the pull-down from 28 °C (≈ 24 min).
    assert!(v["time_outside_2_8_s"].as_f64().unwrap() < 1800.0, "{v}");
    let v = json(&["sim", "--scenario", "hot-zone", "--controller", "pi", "--json"]);
    assert!(v["min_temp_c"].as_f64().unwrap() >= 2.0 && v["max_temp_c"].as_f64().unwrap() <= 8.0, "{v}");
    assert_eq!(v["time_outside_2_8_s"].as_f64(), Some(0.0), "{v}");
}

/// The engineer's identification workflow on a board (README, "Identifying a new cabinet"):
/// the identification build's defmt log, as probe-rs prints it, through `hter log2csv` and
/// `hter identify`. The log is made from a simulated `prbs` run in the firmware's line format,
/// with the boot, estimate, event and location lines a real log interleaves.
#[test]
fn a_board_identification_log_goes_through_log2csv_and_identify() {
    let dir = std::env::temp_dir().join(format!("hter-cli-board-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (sim_csv, log, csv) = (dir.join("sim.csv"), dir.join("cabinet.log"), dir.join("cabinet.csv"));
    let out = hter(&["sim", "--scenario", "prbs", "--csv", sim_csv.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&sim_csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t, sp, temp, duty, counts) = (col("t_s"), col("setpoint_c"), col("temp_c"), col("duty"), col("counts"));
    let mut board = String::from(
        "0.000000 INFO  reset cause: BrownOut\n└─ firmware::__main_task @ src/main.rs:97\n0.001 INFO  controller: prbs\n",
    );
    for (i, row) in lines.enumerate() {
        let f: Vec<&str> = row.split(',').collect();
        board.push_str(&format!(
            "{}.000000 INFO  t={} temp={} sp={} duty={} mode=Normal counts={} supply=12.02 alarm=Off\n└─ firmware::__telemetry_task @ src/main.rs:290\n",
            i * 10,
            f[t],
            f[temp],
            f[sp],
            f[duty],
            f[counts]
        ));
        if i == 100 {
            board.push_str("1000.000000 WARN  event t=1000 SensorSpikes\n");
        }
    }
    std::fs::write(&log, board).unwrap();
    let out = hter(&["log2csv", "--input", log.to_str().unwrap(), "--output", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let converted = std::fs::read_to_string(&csv).unwrap();
    assert!(converted
        .starts_with("t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm,boot,reset_cause,holdover_s,events\n"));
    assert_eq!(converted.lines().count(), text.lines().count(), "one row per sample line");
    let v = json(&["identify", "--input", csv.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(v["chosen_order"], 2, "{}", v["reason"]);
    assert!(v["fit_percent"].as_f64().unwrap() > 90.0, "{v}");
    let gain = v["static_gain_c_per_duty"].as_f64().unwrap();
    assert!((-50.0..=-40.0).contains(&gain), "{gain}");
}

/// `hter compare --json` is `{"bound_iae": X, "controllers": [sim JSON, ...]}`: each controller
/// object is exactly what `hter sim --json` prints for it, and none beats the bound.
#[test]
fn compare_json_has_the_bound_and_the_sim_objects() {
    let v = json(&["compare", "--scenario", "piecewise", "--controllers", "pi,gpc", "--json"]);
    let bound = v["bound_iae"].as_f64().unwrap();
    // The plant's bound on the seed's piecewise schedule at 28 °C (`hal-sim/src/bound.rs`):
    // three transients of a few minutes each, 2, 3 and 1 °C deep.
    assert!((600.0..900.0).contains(&bound), "{v}");
    let runs = v["controllers"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    // Each controller's ratio to the bound, in the same order.
    let ratios = v["iae_over_bound"].as_array().unwrap();
    assert_eq!(ratios.len(), 2, "{v}");
    for (run, r) in runs.iter().zip(ratios) {
        let want = run["iae"].as_f64().unwrap() / bound;
        assert!((r.as_f64().unwrap() - want).abs() < 1e-12, "{r} against {want}");
    }
    for (run, name) in runs.iter().zip(["pi", "gpc"]) {
        assert_eq!(run["controller"], name);
        let sim = json(&["sim", "--scenario", "piecewise", "--controller", name, "--json"]);
        assert_eq!(run, &sim, "{name}: the compare object is the sim object");
        assert!(run["iae"].as_f64().unwrap() >= bound, "{name}: {run}");
    }
    // A heat step at a constant setpoint has no setpoint transient: the bound is 0.
    let v = json(&["compare", "--scenario", "disturbance", "--controllers", "pi", "--json"]);
    assert_eq!(v["bound_iae"].as_f64(), Some(0.0), "{v}");
    assert_eq!(v["iae_over_bound"], serde_json::json!([null]), "no ratio to a bound of 0");
    // The table has the bound as its first row and the ratio column.
    let out = hter(&["compare", "--scenario", "piecewise", "--controllers", "pi"]);
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| ---")).collect();
    assert!(
        rows[0].contains("IAE / bound") && rows[1].starts_with("| bound |") && rows[2].starts_with("| pi |"),
        "{text}"
    );
    let ratio: f64 = rows[2].split('|').nth(3).unwrap().trim().parse().unwrap();
    let pi_iae: f64 = rows[2].split('|').nth(2).unwrap().trim().parse().unwrap();
    assert!((ratio - pi_iae / bound).abs() < 0.01, "{text}");
}

#[test]
fn pi_tuning_flags_are_checked_and_used() {
    assert_one_line_error(&["sim", "--controller", "pi", "--kp", "0"], "--kp must be > 0");
    assert_one_line_error(&["sim", "--controller", "pi", "--kp", "-0.3"], "--kp must be > 0");
    assert_one_line_error(&["sim", "--controller", "pi", "--kp", "nan"], "--kp must be a finite");
    assert_one_line_error(&["sim", "--controller", "pi", "--ti", "0"], "--ti must be > 0");
    assert_one_line_error(&["sim", "--controller", "pi", "--ti", "inf"], "--ti must be a finite");
    assert_one_line_error(&["compare", "--controllers", "pi", "--kp", "x"], "x");
    let run = |extra: &[&str]| {
        let mut args = vec!["sim", "--scenario", "piecewise", "--controller", "pi", "--json"];
        args.extend_from_slice(extra);
        json(&args)["iae"].as_f64().unwrap()
    };
    // The profile's H-TER I PI spelled out is the default; other gains give another run.
    let (kp, ti) = (hter::profile::PI.kp_per_c.to_string(), hter::profile::PI.ti_s.to_string());
    assert_eq!(run(&[]), run(&["--kp", &kp, "--ti", &ti]));
    assert_ne!(run(&[]), run(&["--kp", "0.6"]));
}

#[test]
fn the_default_controller_is_self_tuning_gpc() {
    let v = json(&["sim", "--scenario", "piecewise", "--json"]);
    assert_eq!(v["controller"], "gpc", "{v}");
}

/// `hter sim --csv` carries the step's holdover estimate as a number in `holdover_s`, and the
/// `--json` prediction of a power cut is that column's last value before the cut.
#[test]
fn the_sim_csv_has_holdover_s_as_numbers_and_json_predicts_from_it() {
    let csv = std::env::temp_dir().join(format!("hter-cli-power-cut-{}.csv", std::process::id()));
    let out = hter(&["sim", "--scenario", "power-cut", "--json", "--csv", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let text = std::fs::read_to_string(&csv).unwrap();
    let _ = std::fs::remove_file(&csv);
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name} column"));
    let (t_col, h_col) = (col("t_s"), col("holdover_s"));
    let rows: Vec<(f64, f64)> = lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            let h = cells[h_col].parse::<f64>().unwrap_or_else(|_| panic!("holdover_s '{}' in: {l}", cells[h_col]));
            (cells[t_col].parse().unwrap(), h)
        })
        .collect();
    // Holding 4 °C: minutes of holdover on every sample before the cut at 2 h.
    let before: Vec<f64> = rows.iter().filter(|(t, _)| *t < 7200.0).map(|&(_, h)| h).collect();
    assert_eq!(before.len(), 720);
    assert!(before.iter().all(|h| (60.0..3600.0).contains(h)), "{before:?}");
    let predicted = v["holdover_predicted_s"].as_f64().expect("a prediction");
    assert!((predicted - before[before.len() - 1]).abs() < 1e-3, "{predicted} vs {:?}", before.last());
}

#[test]
fn a_campaign_reports_the_freeze_margin_apart_from_the_faults() {
    // Mission 665 has no hardware fault: its lowest load after pull-down (the freeze margin)
    // is reported, never below the mission's lowest, and nothing after a fault.
    let c = json(&["campaign", "--missions", "1", "--seed", "665", "--json"]);
    let (margin, lowest) = (c["fault_free_min_c"].as_f64().unwrap(), c["worst_min_c"].as_f64().unwrap());
    assert!((2.0..=8.0).contains(&margin) && margin >= lowest, "{c}");
    assert_eq!(c["fault_free_min_seed"], 665, "{c}");
    assert!(c["fault_min_c"].is_null() && c["fault_below_2_minutes"] == 0.0, "{c}");
    // Mission 41783's SSR shorts on a light load: what the fault did is reported apart, and the
    // mission is not in the freeze margin.
    let c = json(&["campaign", "--missions", "1", "--seed", "41783", "--json"]);
    assert!(c["fault_free_min_c"].is_null(), "{c}");
    assert!(c["fault_min_c"].as_f64().unwrap() >= c["worst_min_c"].as_f64().unwrap(), "{c}");
    assert_eq!(c["fault_min_seed"], 41783, "{c}");
}

/// `hter sim --csv` logs the self-tuner's reset at rest in `reset_c`: 0 on every sample of a
/// setpoint change, within ±`RESET_MAX_C`, and from one sample to the next it moves by
/// −`RESET_GAIN` × the error the law saw (`hter::control::adaptive`, "Reset at rest"); empty for
/// a controller without one.
#[test]
fn the_sim_csv_logs_the_reset_at_rest_the_law_aims_at() {
    use hter::control::adaptive::{RESET_GAIN, RESET_MAX_C};
    let run = |controller: &str| {
        let csv = std::env::temp_dir().join(format!("hter-cli-reset-{controller}-{}.csv", std::process::id()));
        let out = hter(&["sim", "--scenario", "half-load", "--controller", controller, "--csv", csv.to_str().unwrap()]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = std::fs::read_to_string(&csv).unwrap();
        let _ = std::fs::remove_file(&csv);
        text
    };
    let pi = run("pi");
    assert!(column(&pi, "reset_c").iter().all(String::is_empty), "PI has no reset");

    let gpc = run("gpc");
    let num = |name: &str| -> Vec<f32> {
        column(&gpc, name).iter().map(|c| c.parse().unwrap_or_else(|_| panic!("{name} '{c}'"))).collect()
    };
    let (w, y, r) = (num("setpoint_c"), num("temp_c"), num("reset_c"));
    assert!(r.iter().all(|r| r.abs() <= RESET_MAX_C), "every reset within ±{RESET_MAX_C}");
    let (mut moved, mut resting) = (0, 0);
    for t in 1..r.len() {
        if w[t] != w[t - 1] {
            assert_eq!(r[t], 0.0, "a setpoint change ends the rest (sample {t})");
        }
        if r[t] != 0.0 {
            resting += 1;
        }
        if r[t] != 0.0 && r[t - 1] != 0.0 && r[t] != r[t - 1] {
            moved += 1;
            let step = r[t] - r[t - 1];
            let want = -RESET_GAIN * (y[t] - w[t]);
            assert!((step - want).abs() < 1e-6, "sample {t}: reset moved {step}, the rule says {want}");
        }
    }
    // The run's holds are long: the reset runs on a large part of it.
    assert!(resting > r.len() / 3 && moved > r.len() / 4, "{resting} resting, {moved} moved of {}", r.len());
}

/// A temporary file with `text`, named for the test and the process.
fn temp_file(name: &str, text: &str) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("hter-cli-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

/// `monitor` and `report` refuse a temperature no Pt100 can report (IEC 60751: −200…850 °C)
/// with its line and column. 1e39 °C was infinite in the monitor's f32 and dropped: `report`
/// said "IN RANGE"; −500 °C left no mean kinetic temperature.
#[test]
fn a_temperature_no_rtd_can_report_is_refused_with_its_line() {
    for (name, cell) in [("huge", "1e39"), ("below", "-500"), ("above", "850.5")] {
        let csv = temp_file(&format!("temp-{name}.csv"), &format!("t_s,temp_c\n0,4\n10,{cell}\n20,4\n30,4\n"));
        let path = csv.to_str().unwrap();
        let html = std::env::temp_dir().join(format!("hter-cli-{}-temp-{name}.html", std::process::id()));
        assert_one_line_error(&["monitor", "--input", path], "line 3, column 'temp_c'");
        assert_one_line_error(&["monitor", "--input", path, "--json"], "IEC 60751");
        assert_one_line_error(&["report", "--input", path, "--output", html.to_str().unwrap()], "line 3");
        assert!(!html.exists(), "{name}: no report is written");
        let _ = std::fs::remove_file(&csv);
    }
    // The range's ends are readings.
    let csv = temp_file("temp-ends.csv", "t_s,temp_c\n0,-200\n10,850\n20,4\n");
    let v = json(&["monitor", "--input", csv.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_file(&csv);
    assert_eq!((v["min_c"].as_f64(), v["max_c"].as_f64()), (Some(-200.0), Some(850.0)), "{v}");
}

/// A closed stdout ends `hter` quietly, as it ends other Unix tools: before, every printing
/// command panicked ("failed printing to stdout: Broken pipe") with exit code 101. The read end
/// of the pipe is closed before the child starts, so its first write meets a closed pipe.
#[cfg(unix)]
#[test]
fn a_closed_stdout_is_not_a_panic() {
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::os::unix::process::ExitStatusExt;
    for args in [&["sim", "--duration", "600"][..], &["rtd", "--celsius", "4"], &["compare", "--duration", "600"]] {
        let mut fds = [0; 2];
        // SAFETY: `pipe` fills both descriptors on success, each then owned exactly once.
        assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
        let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
        drop(read);
        let out = Command::new(env!("CARGO_BIN_EXE_hter"))
            .args(args)
            .stdout(std::process::Stdio::from(write))
            .stderr(std::process::Stdio::piped())
            .output()
            .expect("run hter");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
        assert_ne!(out.status.code(), Some(101), "{args:?}: {err}");
        assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{args:?}: {:?} {err}", out.status);
    }
}

/// A run shorter than one control sample (Ts = 10 s) has no sample: it reported IAE 0, settled
/// at 0 s and min/max of inf/−inf.
#[test]
fn a_run_shorter_than_one_sample_is_refused() {
    assert_one_line_error(&["sim", "--duration", "1"], "shorter than one control sample");
    assert_one_line_error(&["compare", "--controllers", "pi", "--duration", "9.9"], "shorter than one control sample");
    let file = temp_file("tiny.json", r#"{"setpoints": [[0, 4]], "duration_s": 1e-9}"#);
    assert_one_line_error(&["sim", "--scenario", file.to_str().unwrap()], "duration 1e-9 s is shorter");
    let _ = std::fs::remove_file(&file);
    // One sample is a run.
    let v = json(&["sim", "--duration", "10", "--controller", "pi", "--json"]);
    assert!(v["min_temp_c"].as_f64().is_some_and(f64::is_finite), "{v}");
}

/// A scenario file is held to the ranges of the flags and of the board: ambient as `--ambient`
/// (−10…50 °C), setpoints as the board's `set setpoint_c` (2.5…7.5 °C), supply 0…16 V with the
/// same time checks as the other schedules, extra heat within ±100 W.
#[test]
fn scenario_files_are_held_to_physical_ranges() {
    let cases = [
        ("amb-hot", r#""ambient": [[0, 1e6]]"#, "'ambient' at 0 s is 1000000 °C, outside -10…50 °C"),
        ("amb-cold", r#""ambient": [[0, 28], [600, -273]]"#, "'ambient' at 600 s is -273 °C"),
        ("sup-neg", r#""supply_v": [[0, -12]]"#, "'supply_v' at 0 s is -12 V, outside 0…16 V"),
        ("sup-huge", r#""supply_v": [[0, 1e6]]"#, "'supply_v' at 0 s is 1000000 V"),
        ("sup-neg-t", r#""supply_v": [[-100, 12]]"#, "'supply_v' has a negative time"),
        ("sup-dec", r#""supply_v": [[300, 12], [100, 0]]"#, "'supply_v' times are not increasing"),
        ("heat-huge", r#""extra_heat_w": [[0, 1e6]]"#, "'extra_heat_w' at 0 s is 1000000 W, outside -100…100 W"),
        ("heat-neg", r#""extra_heat_w": [[0, -1e6]]"#, "'extra_heat_w' at 0 s is -1000000 W"),
    ];
    for (name, field, needle) in cases {
        let text = format!(r#"{{"setpoints": [[0, 4]], {field}, "duration_s": 600}}"#);
        let file = temp_file(&format!("{name}.json"), &text);
        assert_one_line_error(&["sim", "--scenario", file.to_str().unwrap()], needle);
        let _ = std::fs::remove_file(&file);
    }
    for (name, sp, needle) in [("sp-neg", "-40", "-40 °C, outside 2.5…7.5 °C"), ("sp-huge", "1e300", "is 1e300 °C")]
    {
        let file = temp_file(
            &format!("{name}.json"),
            &format!(r#"{{"setpoints": [[0, 4], [300, {sp}]], "duration_s": 600}}"#),
        );
        assert_one_line_error(&["sim", "--scenario", file.to_str().unwrap()], needle);
        let _ = std::fs::remove_file(&file);
    }
    // The ends of every range run.
    let text = r#"{"setpoints": [[0, 2.5], [300, 7.5]], "ambient": [[0, -10], [300, 50]],
        "supply_v": [[0, 16], [300, 0]], "extra_heat_w": [[0, -100], [300, 100]], "duration_s": 600}"#;
    let file = temp_file("ends.json", text);
    let v = json(&["sim", "--scenario", file.to_str().unwrap(), "--controller", "pi", "--json"]);
    let _ = std::fs::remove_file(&file);
    assert!(v["iae"].as_f64().is_some_and(f64::is_finite), "{v}");
}

/// Identification from a record whose duty or temperature never changes is refused, naming
/// which, by every method: output error and RLS returned gains of 1e12 °C per unit duty or a
/// "stable" model with no fit, with exit 0.
#[test]
fn identify_refuses_a_record_without_excitation() {
    let rows = |duty: &dyn Fn(usize) -> f64, temp: &dyn Fn(usize) -> f64| {
        let mut s = String::from("t_s,duty,temp_c\n");
        for i in 0..200 {
            s.push_str(&format!("{},{},{}\n", 10 * i, duty(i), temp(i)));
        }
        s
    };
    let prbs = |i: usize| if (i / 7 + i / 3).is_multiple_of(2) { 0.3 } else { 0.6 };
    let drift = |i: usize| 4.0 + 0.01 * i as f64;
    let const_duty = temp_file("const-duty.csv", &rows(&|_| 0.459, &drift));
    let const_temp = temp_file("const-temp.csv", &rows(&prbs, &|_| 4.0));
    for method in ["oe", "rls", "rels", "ls", "iv"] {
        let args =
            |p: &std::path::Path| ["identify", "--input", p.to_str().unwrap(), "--method", method].map(String::from);
        let a = args(&const_duty);
        assert_one_line_error(&a.iter().map(String::as_str).collect::<Vec<_>>(), "duty is 0.459 in every row");
        let a = args(&const_temp);
        assert_one_line_error(&a.iter().map(String::as_str).collect::<Vec<_>>(), "temp_c is 4 in every row");
    }
    let _ = (std::fs::remove_file(&const_duty), std::fs::remove_file(&const_temp));
}

/// Numeric flags the library takes as f32 are checked as the library will see them, and
/// within a range the carrier makes sense of: `--ti 1e39` and `--ti 1e-300` silently turned
/// PI into P, `--kp 1e-300` into nothing, `--kp 1e39` never cooled, `--forgetting 1e-50` became
/// 0 then 1, and `--filter 0.99999999999` was refused as if it were below 1.
#[test]
fn f32_flags_are_checked_as_the_library_sees_them() {
    assert_one_line_error(&["sim", "--controller", "pi", "--ti", "1e39"], "--ti must be within 1…1e6 s, got 1e39");
    assert_one_line_error(&["sim", "--controller", "pi", "--ti", "1e-300"], "--ti must be within");
    assert_one_line_error(&["sim", "--controller", "pi", "--ti", "0.5"], "--ti must be within");
    assert_one_line_error(&["sim", "--controller", "pi", "--kp", "1e-300"], "--kp must be within 0.001…100");
    assert_one_line_error(&["sim", "--controller", "pi", "--kp", "1e39"], "--kp must be within");
    assert_one_line_error(&["sim", "--controller", "gpc", "--lambda", "1e39"], "--lambda = 1e39 is too large");
    assert_one_line_error(
        &["sim", "--controller", "gmvc", "--p-weight", "1e-300"],
        "--p-weight must be within 0.01…100",
    );
    assert_one_line_error(&["identify", "--input", "/dev/null", "--forgetting", "1e-50"], "--forgetting");
    assert_one_line_error(
        &["identify", "--input", "/dev/null", "--forgetting", "0.1"],
        "--forgetting must be in [0.5, 1]",
    );
    assert_one_line_error(
        &["identify", "--input", "/dev/null", "--filter", "0.99999999999"],
        "which is 1 in the filter's f32 arithmetic",
    );
    // The ends of the PI ranges run.
    for (kp, ti) in [("0.001", "1e6"), ("100", "1")] {
        let v = json(&["sim", "--scenario", "piecewise", "--controller", "pi", "--kp", kp, "--ti", ti, "--json"]);
        assert!(v["iae"].as_f64().is_some_and(f64::is_finite), "{kp} {ti}: {v}");
    }
}

/// What a run would silently ignore is refused: a fault, the buck drive or the module-side sense
/// on an ideal ARX plant (as `--commission` already was), the sense on the buck drive (no off
/// time to read the modules in), a fault after the run's last sample.
#[test]
fn flags_a_run_would_ignore_are_refused() {
    let arx = "arx:-0.99;-0.5;1";
    assert_one_line_error(
        &["sim", "--plant", arx, "--fault", "sensor-open@100"],
        "--fault sensor-open@100 needs a physical plant",
    );
    assert_one_line_error(&["sim", "--plant", arx, "--drive", "buck"], "--drive buck needs a physical plant");
    assert_one_line_error(&["sim", "--plant", arx, "--module-sense"], "--module-sense needs a physical plant");
    assert_one_line_error(&["sim", "--drive", "buck", "--module-sense"], "--module-sense needs --drive ssr");
    assert_one_line_error(
        &["campaign", "--missions", "2", "--drive", "buck", "--module-sense"],
        "--module-sense needs --drive ssr",
    );
    assert_one_line_error(&["compare", "--plant", arx, "--fault", "lid-open@60"], "needs a physical plant");
    // `step` lasts 10 800 s, its last sample at 10 790 s.
    assert_one_line_error(&["sim", "--fault", "lid-open@10800"], "the run lasts 10800 s");
    assert_one_line_error(&["sim", "--duration", "600", "--fault", "ssr-stuck-off@595"], "the run lasts 600 s");
    let v = json(&["sim", "--duration", "600", "--controller", "pi", "--fault", "sensor-open@590", "--json"]);
    assert!(!v["faults_detected"].as_array().unwrap().is_empty(), "a fault at the last sample happens: {v}");
}

/// clap's errors on one line that still says what is wrong: the missing arguments by name, and
/// a negative number as the flag's value with its valid range instead of "unexpected argument
/// '-1' found".
#[test]
fn argument_errors_name_the_argument_and_its_range() {
    assert_one_line_error(&["rtd"], "--ohms");
    assert_one_line_error(&["campaign"], "--missions <MISSIONS>");
    assert_one_line_error(&["identify"], "--input <INPUT>");
    assert_one_line_error(
        &["campaign", "--missions", "-1"],
        "'--missions <MISSIONS>': the number of missions must be a whole number in 1…1000000",
    );
    assert_one_line_error(&["campaign", "--missions", "1", "--seed", "-1"], "'--seed <SEED>'");
    assert_one_line_error(&["sim", "--seed", "-1"], "the noise seed must be a whole number in 0…");
    assert_one_line_error(&["sim", "--n1", "-1"], "N1 must be a whole number in 1…30");
    assert_one_line_error(&["sim", "--n2", "-1"], "'--n2 <N2>'");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--nk", "-1"], "'-1' is not a delay: give 1–10");
    assert_one_line_error(&["identify", "--input", "/dev/null", "--na", "-1"], "na, must be a whole number in 1…4");
    assert_one_line_error(&["rtd", "--ohms", "100", "--r0", "-100"], "must be 100 (Pt100) or 1000 (Pt1000)");
    assert_one_line_error(&["sim", "--controller", "magic"], "possible values: onoff");
}

/// `virtual-board --duration nan` ran for ever; its messages named "----speed".
#[test]
fn virtual_board_flags_are_checked_before_it_serves() {
    let link = std::env::temp_dir().join(format!("hter-cli-vb-{}", std::process::id()));
    let link = link.to_str().unwrap();
    assert_one_line_error(&["virtual-board", "--link", link, "--duration", "nan"], "--duration must be a finite");
    assert_one_line_error(&["virtual-board", "--link", link, "--duration", "0"], "--duration must be > 0");
    assert_one_line_error(&["virtual-board", "--link", link, "--duration", "-5"], "--duration must be > 0");
    for (flag, v) in [("--speed", "nan"), ("--ambient", "inf")] {
        let out = hter(&["virtual-board", "--link", link, flag, v]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(&format!("error: {flag} must")) && !err.contains("----"),
            "{err}"
        );
    }
    assert_one_line_error(&["virtual-board", "--link", link, "--ambient", "80"], "--ambient must be within -10…50 °C");
}

/// `log2csv` refuses a time the board's 64-bit millisecond clock cannot show, with its line:
/// `t=1e303` was written as `inf`.
#[test]
fn log2csv_refuses_a_time_beyond_the_boards_clock() {
    let log =
        temp_file("huge-t.log", "t=0 temp=4 sp=4 duty=0.5 mode=Normal\nt=1e303 temp=4 sp=4 duty=0.5 mode=Normal\n");
    let csv = std::env::temp_dir().join(format!("hter-cli-{}-huge-t.csv", std::process::id()));
    assert_one_line_error(
        &["log2csv", "--input", log.to_str().unwrap(), "--output", csv.to_str().unwrap()],
        "line 2: t = 1e303 s is beyond the board's 64-bit millisecond clock",
    );
    let _ = (std::fs::remove_file(&log), std::fs::remove_file(&csv));
}

/// An ideal plant with a gain no carrier can have (−6e38 °C per unit duty) ran the load to
/// −1e33 °C; the bound is the self-tuner's plausible range.
#[test]
fn an_arx_plant_beyond_any_carrier_is_refused() {
    assert_one_line_error(&["sim", "--plant", "arx:-0.5;-3e38;1"], "beyond what a carrier can have");
    assert_one_line_error(&["sim", "--model", "arx:-0.9;-101;1"], "beyond what a carrier can have");
}

/// A scratch directory for one test, removed by the caller.
fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("hter-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `hter compare` refuses what it would ignore: `--csv` (one run's trace: it exited 0 and wrote
/// nothing, even into a missing directory) and `--controller` beside `--controllers`.
#[test]
fn compare_refuses_per_run_options_it_would_ignore() {
    assert_one_line_error(&["compare", "--duration", "300", "--csv", "/nonexistent/dir/x.csv"], "--csv");
    assert_one_line_error(&["compare", "--duration", "300", "--csv", "x.csv", "--controllers", "pi"], "hter sim");
    assert_one_line_error(&["compare", "--controllers", "gpc", "--controller", "pi"], "--controller");
    assert_one_line_error(&["compare", "--controller", "pi", "--duration", "300"], "--controllers");
}

/// The T-filter C must be stable, a plant takes no C, and no field may be empty.
#[test]
fn arx_fields_are_checked_on_the_command_line() {
    assert_one_line_error(
        &[
            "sim",
            "--json",
            "--scenario",
            "piecewise",
            "--duration",
            "1500",
            "--model",
            "arx:-1.8,0.81;-0.02,-0.01;1;5,6",
        ],
        "inside the unit circle",
    );
    assert_one_line_error(&["sim", "--plant", "arx:-0.9;-0.1;1;0.5"], "no fourth (C) field");
    assert_one_line_error(&["sim", "--model", "arx:-1.8,0.81;-0.02,-0.01;1;"], "field 4 (C) is empty");
    // The message states the rule it enforces.
    assert_one_line_error(&["sim", "--model", "arx:-0.5;-3e38;1"], "[-1000, 0)");
}

/// `--p-weight=-1` froze the load, `1e-30` cooled nothing; R and S are held the same way.
#[test]
fn gmvc_weights_are_checked() {
    for (flag, bad) in [
        ("--p-weight", "-1"),
        ("--p-weight", "1e-30"),
        ("--p-weight", "1e9"),
        ("--p-weight", "nan"),
        ("--r-weight", "0"),
        ("--r-weight", "-1"),
        ("--r-weight", "inf"),
        ("--s-weight", "-0.1"),
        ("--s-weight", "1e6"),
    ] {
        let arg = format!("{flag}={bad}");
        assert_one_line_error(&["sim", "--controller", "gmvc", "--duration", "300", &arg], flag);
    }
    // In range they run, and change the run.
    let run = |extra: &[&str]| {
        let mut args = vec!["sim", "--scenario", "piecewise", "--duration", "600", "--controller", "gmvc", "--json"];
        args.extend_from_slice(extra);
        json(&args)["iae"].as_f64().unwrap()
    };
    assert_ne!(run(&[]), run(&["--s-weight", "0.02", "--p-weight", "1.5", "--r-weight", "1.5"]));
}

/// A tuning flag the chosen controller does not take is refused, naming the flag and who takes
/// it; `compare` needs at least one of its controllers to take each flag.
#[test]
fn tuning_flags_for_another_controller_are_refused() {
    let m = "arx:-1.7493,0.7514;-0.02708,-0.02987;5";
    for (args, needle) in [
        (vec!["sim", "--controller", "pi", "--model", m], "--model does not apply to the controller pi"),
        (vec!["sim", "--controller", "onoff", "--model", m], "--model"),
        (vec!["sim", "--controller", "pi", "--lambda", "1"], "--lambda"),
        (vec!["sim", "--controller", "pi", "--n1", "2"], "--n1"),
        (vec!["sim", "--controller", "gpc", "--s-weight", "0.1"], "it applies to gmvc"),
        (vec!["sim", "--controller", "gpc", "--p-pole", "0.5"], "--p-pole"),
        (vec!["sim", "--p-pole", "0.5"], "--p-pole"),
        (vec!["sim", "--controller", "gmvc", "--kp", "0.5"], "it applies to pi"),
        (vec!["sim", "--controller", "gpc", "--model", m, "--t-pole", "0.5"], "--t-pole"),
        (vec!["sim", "--controller", "gpc", "--model", m, "--no-approach-lead"], "--no-approach-lead"),
        (vec!["compare", "--controllers", "onoff,pi", "--lambda", "1"], "any of the controllers onoff, pi"),
        (vec!["compare", "--controllers", "gpc,pi", "--s-weight", "0.1"], "--s-weight"),
    ] {
        assert_one_line_error(&args, needle);
    }
    // Where it applies to some of compare's controllers it is taken (PI's grid: pi-grid.sh).
    let v =
        json(&["compare", "--controllers", "pi,onoff", "--kp", "0.4", "--ti", "550", "--duration", "600", "--json"]);
    assert_eq!(v["controllers"].as_array().unwrap().len(), 2, "{v}");
}

/// "After settle" is null where a segment never settled, as settle_time_s is: a 600 s pull-down
/// reported 24 °C after settling.
#[test]
fn a_run_that_never_settles_has_no_error_after_settle() {
    let v = json(&["sim", "--duration", "600", "--json"]);
    assert!(v["settle_time_s"].is_null() && v["max_abs_error_after_settle_c"].is_null(), "{v}");
    let out = hter(&["sim", "--duration", "600"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("max |error| after settling   not settled"), "{text}");
    // A step to 6 °C at 100 s while the load still pulls down from 28 °C: no overshoot (the
    // load never reached 6 °C), not the 20.95 °C it is above it.
    let dir = scratch("overshoot");
    let up = dir.join("up.json");
    std::fs::write(&up, r#"{"setpoints":[[0,4],[100,6]],"duration_s":600}"#).unwrap();
    let v = json(&["sim", "--scenario", up.to_str().unwrap(), "--json"]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(v["overshoot_c"].as_f64(), Some(0.0), "{v}");
}

/// A power-cut run that ends before the cut reported a holdover for a cut that never happened.
#[test]
fn a_power_cut_run_must_reach_the_cut() {
    assert_one_line_error(
        &["sim", "--scenario", "power-cut", "--duration", "600", "--json"],
        "cuts the supply at 7200 s",
    );
    assert_one_line_error(&["sim", "--scenario", "power-cut", "--duration", "7200"], "at least 7210 s");
    assert_one_line_error(&["compare", "--scenario", "power-cut", "--duration", "600"], "7200");
}

/// A plot into a missing directory reads as the `--csv` error does, in `sim` and `compare`.
#[test]
fn a_plot_into_a_missing_directory_is_the_os_error() {
    for cmd in ["sim", "compare"] {
        let args = [cmd, "--duration", "300", "--controllers", "pi", "--plot", "/tmp/hter-no-such-dir/x.png"];
        let args = if cmd == "sim" { vec![cmd, "--duration", "300", "--plot", args[6]] } else { args.to_vec() };
        assert_one_line_error(
            &args,
            "cannot write '/tmp/hter-no-such-dir/x.png': No such file or directory (os error 2)",
        );
        let out = hter(&args);
        assert!(!String::from_utf8_lossy(&out.stderr).contains("backend"));
        // Checked before the run: compare prints no table it then fails to plot.
        assert!(out.stdout.is_empty(), "{}", String::from_utf8_lossy(&out.stdout));
    }
}

/// Outputs never overwrite an input or each other.
#[test]
fn outputs_that_overwrite_inputs_or_each_other_are_refused() {
    let dir = scratch("same-path");
    let sc = dir.join("ok.json");
    let text = r#"{"setpoints":[[0,4]],"duration_s":100}"#;
    std::fs::write(&sc, text).unwrap();
    let sc_s = sc.to_str().unwrap();
    assert_one_line_error(&["sim", "--scenario", sc_s, "--csv", sc_s], "same file as --scenario");
    // The same file by another spelling.
    let other = format!("{}/./ok.json", dir.display());
    assert_one_line_error(&["sim", "--scenario", sc_s, "--plot", &other], "same file as --scenario");
    assert_eq!(std::fs::read_to_string(&sc).unwrap(), text, "the scenario is untouched");
    let svg = dir.join("same.svg");
    let svg_s = svg.to_str().unwrap();
    assert_one_line_error(&["sim", "--duration", "100", "--csv", svg_s, "--plot", svg_s], "same file as --csv");
    assert!(!svg.exists());
    assert_one_line_error(&["compare", "--scenario", sc_s, "--plot", sc_s], "same file as --scenario");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A description with a newline or an escape sequence was printed raw in the summary.
#[test]
fn a_scenario_description_must_be_one_line_of_text() {
    let dir = scratch("description");
    let sc = dir.join("esc.json");
    std::fs::write(&sc, r#"{"description":"a\nb \u001b[2J","setpoints":[[0,4]],"duration_s":100}"#).unwrap();
    assert_one_line_error(&["sim", "--scenario", sc.to_str().unwrap()], "control character");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `start_c` on the command line: the run's first sample is there (it started at 4.0 °C).
#[test]
fn a_scenario_files_start_c_is_honoured_by_sim() {
    let dir = scratch("start-c");
    let sc = dir.join("st.json");
    std::fs::write(&sc, r#"{"setpoints":[[0,4]],"duration_s":100,"start_c":20}"#).unwrap();
    let csv = dir.join("st.csv");
    let out = hter(&["sim", "--scenario", sc.to_str().unwrap(), "--csv", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let first: f64 = column(&text, "true_temp_c")[0].parse().unwrap();
    assert!((first - 20.0).abs() < 0.05, "first sample at {first} °C");
    std::fs::write(&sc, r#"{"setpoints":[[0,4]],"duration_s":100,"start_c":30}"#).unwrap();
    assert_one_line_error(&["sim", "--scenario", sc.to_str().unwrap()], "cannot hold 30 °C");
    let _ = std::fs::remove_dir_all(&dir);
}
