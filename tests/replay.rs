//! Golden replay: a recorded sequence of RTD counts through the library's step gives exactly
//! the recorded duties, on every run and every machine (PX4 change-indication idea).
//!
//! `tests/golden/step_pi.csv` holds `t_s,counts,setpoint_c,duty_bits` from an `hter sim
//! --scenario step --controller pi` run. If a change moves any duty, this test fails; when the
//! change is intended, regenerate with `HTER_BLESS=1 cargo test --test replay` and commit the
//! new file with an explanation.

use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};
use hter::step::{Carrier, CarrierConfig, StepInput};

const GOLDEN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/step_pi.csv");

fn replay(rows: &[(f32, u32, f32)]) -> Vec<u32> {
    let cfg = CarrierConfig::DEFAULT;
    let mut c = Carrier::new(cfg, ControllerChoice::Pi.build(cfg.ts_s));
    rows.iter()
        .map(|&(t_s, counts, setpoint_c)| c.step(&StepInput { t_s, counts, setpoint_c }).duty.get().to_bits())
        .collect()
}

fn bless() {
    let scenario = Scenario::resolve("step").unwrap();
    let opts = SimOptions {
        duration_s: scenario.duration_s,
        scenario,
        controller: ControllerSpec::new(ControllerChoice::Pi),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 1,
        faults: vec![],
    };
    let out = run(&opts).unwrap();
    let rows: Vec<(f32, u32, f32)> = out.rows.iter().map(|r| (r.t_s as f32, r.counts, r.setpoint_c as f32)).collect();
    let duties = replay(&rows);
    let mut text = String::from("t_s,counts,setpoint_c,duty_bits\n");
    for ((t, c, w), d) in rows.iter().zip(&duties) {
        text.push_str(&format!("{t},{c},{w},{d}\n"));
    }
    std::fs::write(GOLDEN, text).unwrap();
}

#[test]
fn recorded_counts_replay_to_the_recorded_duties() {
    if std::env::var_os("HTER_BLESS").is_some() {
        bless();
    }
    let text = std::fs::read_to_string(GOLDEN).expect("golden file missing: run with HTER_BLESS=1");
    let mut rows = Vec::new();
    let mut golden = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        rows.push((f[0].parse().unwrap(), f[1].parse().unwrap(), f[2].parse().unwrap()));
        golden.push(f[3].parse::<u32>().unwrap());
    }
    assert!(rows.len() > 500, "golden trace too short");
    // The trace must exercise the controller, not sit at one duty.
    let distinct: std::collections::BTreeSet<_> = golden.iter().collect();
    assert!(distinct.len() > 20, "golden trace has only {} distinct duties", distinct.len());
    for run in 0..3 {
        let got = replay(&rows);
        for (k, (g, want)) in got.iter().zip(&golden).enumerate() {
            assert_eq!(g, want, "run {run}: duty differs at sample {k} (t = {} s)", rows[k].0);
        }
    }
}
