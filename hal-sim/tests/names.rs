//! `hter sim --csv` and `hter log2csv` spell every mode, indication and event the same way: as
//! the library names them (`Mode::name`, `Indication::name`, `AdaptiveMode::name`,
//! `EventKind::name`), whatever spelling the firmware's telemetry prints.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::{Command, Output};

use hter::alarm::Indication;
use hter::control::AdaptiveMode;
use hter::event::EventKind;
use hter::step::Mode;

fn hter(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hter")).args(args).output().expect("run hter")
}

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("hter-names-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The cells of `column` in a CSV text (with its header line).
fn column(text: &str, name: &str) -> Vec<String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let i = header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}: {header:?}"));
    lines.map(|l| l.split(',').nth(i).unwrap_or_else(|| panic!("short row {l}")).to_string()).collect()
}

fn names<T: Copy>(all: &[T], name: fn(T) -> &'static str) -> BTreeSet<String> {
    all.iter().map(|v| name(*v).to_string()).collect()
}

/// Every list's names are distinct snake_case words, so a cell names one value.
#[test]
fn the_library_names_are_distinct_snake_case() {
    let lists = [
        (Mode::ALL.len(), names(&Mode::ALL, Mode::name)),
        (Indication::ALL.len(), names(&Indication::ALL, Indication::name)),
        (AdaptiveMode::ALL.len(), names(&AdaptiveMode::ALL, AdaptiveMode::name)),
        (EventKind::ALL.len(), names(&EventKind::ALL, EventKind::name)),
    ];
    for (n, set) in lists {
        assert_eq!(set.len(), n, "a name is used twice: {set:?}");
        for s in &set {
            assert!(s.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'), "{s}");
        }
    }
}

/// The board's telemetry: one sample per mode as the firmware prints it (`defmt` `{}` of the
/// enum: the variant name), with every indication, and the boot lines of a brown-out and a
/// fail-safe stop.
fn firmware_log(modes: &[&str], indications: &[&str]) -> String {
    let mut log = String::from("0.000000 INFO  reset cause: BrownOut\n0.000000 INFO  hter firmware 0.1.0: Ts = 10 s\n");
    let mut t = 0;
    for m in modes {
        for a in indications {
            let temp = if *m == "SensorFault" { "NaN" } else { "4.5" };
            log += &format!(
                "{t}.000000 INFO  t={t} temp={temp} sp=4 duty=0.4 mode={m} counts=49918 supply=12.02 rail=12.01 alarm={a}\n\
                 └─ firmware::__telemetry_task @ src/main.rs:366\n"
            );
            if *m == "SensorFault" && t % 20 == 0 {
                log += &format!("{t}.000000 WARN  event t={t} SensorOpen\n");
            }
            t += 10;
        }
    }
    log += "0.000000 INFO  reset cause: Other\n";
    log += "0.000100 ERROR board fault: HardFault pc=0x08001234 addr=0x20018000 detail=0x8200\n";
    log += "0.000000 INFO  t=0 temp=4.5 sp=4 duty=0.4 mode=Normal counts=49918 supply=12.02 rail=12.01 alarm=Off\n";
    log
}

#[test]
fn sim_and_log2csv_spell_every_mode_and_event_as_the_library() {
    let d = dir();
    // A supply sag (a fault that latches while the step stays in control), a shorted SSR
    // (freeze guard, then limp home), then an open sensor: all four modes of the step and all
    // four indications in one run. (Without the sag, `unacknowledged` came only from limp
    // home's freeze-guard holds, which an acknowledgement silenced: `hter::alarm`.)
    let sim_csv = d.join("sim.csv");
    let out = hter(&[
        "sim",
        "--scenario",
        "step",
        "--controller",
        "gpc",
        "--fault",
        "supply-sag@1800",
        "--fault",
        "ssr-stuck-on@3600",
        "--fault",
        "sensor-open@9000",
        "--json",
        "--csv",
        sim_csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let sim = std::fs::read_to_string(&sim_csv).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();

    let (mode_names, alarm_names) = (names(&Mode::ALL, Mode::name), names(&Indication::ALL, Indication::name));
    let event_names = names(&EventKind::ALL, EventKind::name);
    let sim_modes: BTreeSet<String> = column(&sim, "mode").into_iter().collect();
    let sim_alarms: BTreeSet<String> = column(&sim, "alarm").into_iter().collect();
    let sim_adaptive: BTreeSet<String> = column(&sim, "adaptive_mode").into_iter().collect();
    assert_eq!(sim_modes, mode_names, "the run should go through every mode");
    assert_eq!(sim_alarms, alarm_names, "the run should show every indication");
    let adaptive_names = names(&AdaptiveMode::ALL, AdaptiveMode::name);
    assert!(sim_adaptive.is_subset(&adaptive_names) && sim_adaptive.len() >= 2, "{sim_adaptive:?}");
    let kinds: Vec<&str> =
        json["faults_detected"].as_array().unwrap().iter().map(|f| f["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["supply_sag", "ssr_stuck_on", "sensor_open"]);
    assert!(kinds.iter().all(|k| event_names.contains(*k)), "{kinds:?}");

    // The firmware's spelling of each mode and indication, in `Mode::ALL` / `Indication::ALL`
    // order: what its `defmt::Format` derive prints.
    let fw_modes = ["Normal", "SensorFault", "FreezeGuard", "LimpHome"];
    let fw_alarms = ["Off", "NotInControl", "OutOfRange", "Unacknowledged"];
    assert_eq!((fw_modes.len(), fw_alarms.len()), (Mode::ALL.len(), Indication::ALL.len()));
    let (log, csv) = (d.join("carrier.log"), d.join("carrier.csv"));
    std::fs::write(&log, firmware_log(&fw_modes, &fw_alarms)).unwrap();
    let out = hter(&["log2csv", "--input", log.to_str().unwrap(), "--output", csv.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let logged = std::fs::read_to_string(&csv).unwrap();
    let (modes, alarms) = (column(&logged, "mode"), column(&logged, "alarm"));
    // Sample i is mode i / 4 with indication i % 4; the last is the boot after the stop.
    for (i, (m, a)) in modes.iter().zip(&alarms).take(16).enumerate() {
        assert_eq!(m, Mode::ALL[i / 4].name(), "row {i}");
        assert_eq!(a, Indication::ALL[i % 4].name(), "row {i}");
    }
    let log_modes: BTreeSet<String> = modes.into_iter().collect();
    let log_alarms: BTreeSet<String> = alarms.into_iter().collect();
    // Both tools write the same word for each mode and indication.
    assert_eq!(log_modes, sim_modes);
    assert_eq!(log_alarms, sim_alarms);
    let causes: Vec<String> = column(&logged, "reset_cause").into_iter().filter(|c| !c.is_empty()).collect();
    assert_eq!(causes, ["restarted_brownout", "board_fault_hard_fault"]);
    assert!(causes.iter().all(|c| event_names.contains(c)), "{causes:?}");
    let _ = std::fs::remove_dir_all(&d);
}
