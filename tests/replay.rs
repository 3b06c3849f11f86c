//! Golden replay: a change detector for the step. A recorded sequence of RTD counts through
//! the library's step gives exactly the recorded duties and events, on every run and every
//! machine (PX4 change-indication idea).
//!
//! What it proves and what it does not: the duties and events in the golden files were written
//! by this same step (`HTER_BLESS=1` regenerates them from the code under test), so the test
//! says nothing about whether they are *right*; the closed-loop, fault and PIL tests do that.
//! It says that a change moved a duty or an event somewhere, bit for bit, which a refactor
//! must not do. What it pins independently of the code: each trace contains the events its
//! scenario must cause (the self-tuner's mode changes for GPC; the injected spikes and offset
//! for the PI).
//!
//! `tests/golden/step_pi.csv` and `tests/golden/step_gpc.csv` hold
//! `t_s,counts,setpoint_c,duty_bits,events` from `hter sim --scenario step` runs with the PI
//! (with sensor spikes from 2 400 s and a +1.5 °C offset at 5 400 s) and with self-tuning GPC
//! (the firmware's default controller, built as the board builds it: `pil/src/proto.rs`, shared
//! with the processor-in-the-loop runner). `events` is the step's event codes of that sample
//! joined by `+`. When a change is meant to move a duty or event, regenerate with
//! `HTER_BLESS=1 cargo test --test replay` (or `HTER_BLESS=step_pi` for one trace) and say in
//! the commit why the trace moved. Blessing re-runs the simulator, so the counts move too
//! whenever the simulated board or plant has changed since the trace was recorded.

#[path = "../pil/src/proto.rs"]
#[allow(dead_code)]
mod proto;

use hal_sim::plant::Load;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, Fault, PlantChoice, SimOptions};
use hter::event::EventKind;
use hter::step::StepInput;

struct Golden {
    file: &'static str,
    kind: u32,
    choice: ControllerChoice,
    /// Faults injected into the recorded run, (time s, kind).
    faults: &'static [(f64, Fault)],
    /// Events the scenario must cause: each appears in the trace.
    expected: &'static [EventKind],
}

const GOLDENS: [Golden; 2] = [
    Golden {
        file: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/step_pi.csv"),
        kind: proto::KIND_PI,
        choice: ControllerChoice::Pi,
        faults: &[(2400.0, Fault::SensorSpikes), (5400.0, Fault::SensorOffset)],
        expected: &[EventKind::SensorSpikes, EventKind::SensorOffset],
    },
    Golden {
        file: concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/step_gpc.csv"),
        kind: proto::KIND_GPC,
        choice: ControllerChoice::Gpc,
        faults: &[],
        expected: &[EventKind::AdaptiveFrozen, EventKind::AdaptiveEngaged],
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
        drive: Default::default(),
        duration_s: scenario.duration_s,
        scenario,
        controller: ControllerSpec::new(g.choice),
        plant: PlantChoice::Hter1,
        load: Load::Full,
        ambient_c: 28.0,
        seed: 1,
        faults: g.faults.to_vec(),
        module_sense: false,
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
        // `HTER_BLESS=1` regenerates every trace, `HTER_BLESS=step_pi` that one only.
        let stem = g.file.rsplit('/').next().unwrap_or("").trim_end_matches(".csv");
        if std::env::var("HTER_BLESS").is_ok_and(|b| b == "1" || b == stem) {
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
        for kind in g.expected {
            let code = kind.code().to_string();
            assert!(
                golden.iter().any(|(_, e)| e.split('+').any(|c| c == code)),
                "{}: no {} event in the trace",
                g.file,
                kind.name()
            );
        }
        // The step is deterministic and starts from a fresh carrier: one replay is the proof.
        let got = replay(g.kind, &rows);
        assert_eq!(got.len(), golden.len());
        for (k, (g_k, want)) in got.iter().zip(&golden).enumerate() {
            assert_eq!(g_k, want, "{}: sample {k} (t = {} s) differs", g.file, rows[k].0);
        }
    }
}
