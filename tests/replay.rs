//! Golden replay: a recorded sequence of RTD counts through the library's step gives exactly
//! the recorded duties and events, on every run and every machine (PX4 change-indication idea).
//!
//! `tests/golden/step_pi.csv` and `tests/golden/step_gpc.csv` hold
//! `t_s,counts,setpoint_c,duty_bits[,events]` from `hter sim --scenario step` runs with the PI
//! and with self-tuning GPC — the firmware's default controller, built exactly as the board
//! builds it (`pil/src/proto.rs`, shared with the processor-in-the-loop runner). `events` is
//! the step's event codes of that sample joined by `+`. If a change moves any duty or event,
//! this test fails; when the change is intended, regenerate with
//! `HTER_BLESS=1 cargo test --test replay` and commit the new files with an explanation.

#[path = "../pil/src/proto.rs"]
#[allow(dead_code)]
mod proto;

use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};
use hter::step::StepInput;

struct Golden {
    file: &'static str,
    kind: u32,
    choice: ControllerChoice,
    /// The step's events this trace must contain (it pins them, so it must have some).
    min_events: usize,
}

const GOLDENS: [Golden; 2] = [
    Golden {
        file: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/step_pi.csv"),
        kind: proto::KIND_PI,
        choice: ControllerChoice::Pi,
        min_events: 0,
    },
    Golden {
        file: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/step_gpc.csv"),
        kind: proto::KIND_GPC,
        choice: ControllerChoice::Gpc,
        min_events: 1,
    },
];

/// Duty bits and event codes of each sample, from a fresh carrier built as the firmware does.
fn replay(kind: u32, rows: &[(f32, u32, f32)]) -> Vec<(u32, String)> {
    let (mut c, _) = proto::carrier(kind).expect("known controller kind");
    rows.iter()
        .map(|&(t_s, counts, setpoint_c)| {
            let out = c.step(&StepInput { t_ms: (f64::from(t_s) * 1000.0).round() as u64, counts, setpoint_c });
            let events: Vec<String> = out.events.iter().map(|e| e.kind.code().to_string()).collect();
            (out.duty.get().to_bits(), events.join("+"))
        })
        .collect()
}

fn bless(g: &Golden) {
    let scenario = Scenario::resolve("step").unwrap();
    let opts = SimOptions {
        duration_s: scenario.duration_s,
        scenario,
        controller: ControllerSpec::new(g.choice),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 1,
        faults: vec![],
    };
    let out = run(&opts).unwrap();
    let rows: Vec<(f32, u32, f32)> = out.rows.iter().map(|r| (r.t_s as f32, r.counts, r.setpoint_c as f32)).collect();
    let mut text = String::from("t_s,counts,setpoint_c,duty_bits,events\n");
    for ((t, c, w), (d, e)) in rows.iter().zip(replay(g.kind, &rows)) {
        text.push_str(&format!("{t},{c},{w},{d},{e}\n"));
    }
    std::fs::write(g.file, text).unwrap();
}

#[test]
fn recorded_counts_replay_to_the_recorded_duties_and_events() {
    for g in &GOLDENS {
        if std::env::var_os("HTER_BLESS").is_some() {
            bless(g);
        }
        let text = std::fs::read_to_string(g.file).expect("golden file missing: run with HTER_BLESS=1");
        let mut rows = Vec::new();
        let mut golden = Vec::new();
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            rows.push((f[0].parse().unwrap(), f[1].parse().unwrap(), f[2].parse().unwrap()));
            golden.push((f[3].parse::<u32>().unwrap(), f.get(4).copied().unwrap_or("").to_string()));
        }
        assert!(rows.len() > 500, "{}: golden trace too short", g.file);
        // The trace must exercise the controller, not sit at one duty.
        let distinct: std::collections::BTreeSet<_> = golden.iter().map(|(d, _)| d).collect();
        assert!(distinct.len() > 20, "{}: only {} distinct duties", g.file, distinct.len());
        let with_events = golden.iter().filter(|(_, e)| !e.is_empty()).count();
        assert!(with_events >= g.min_events, "{}: {with_events} samples with events", g.file);
        for run in 0..3 {
            let got = replay(g.kind, &rows);
            for (k, (g_k, want)) in got.iter().zip(&golden).enumerate() {
                assert_eq!(g_k, want, "{} run {run}: sample {k} (t = {} s) differs", g.file, rows[k].0);
            }
        }
    }
}
