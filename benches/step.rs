//! Host benchmarks (criterion): the whole per-sample step (PI and self-tuning GPC) over
//! recorded counts, and its parts — RLS update, GPC design, Diophantine solution, the counts →
//! °C conversion — and a 24 h closed-loop simulation. `cargo bench --bench step`; the figures
//! and the machine are in BENCHMARKS.md. The instruction counts on the Cortex-M4F come from
//! `cargo xtask pil`, which runs the same step on the emulated target.

#[path = "../pil/src/proto.rs"]
#[allow(dead_code)]
mod proto;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, SimOptions};
use hter::control::adaptive::AdaptiveConfig;
use hter::control::diophantine;
use hter::control::gpc::{GpcConfig, GpcState};
use hter::ident::rls::Rls;
use hter::step::StepInput;
use hter::units::Ohms;
use nalgebra::SVector;

fn sim_options(scenario: &str, duration_s: Option<f64>, choice: ControllerChoice) -> SimOptions {
    let scenario = Scenario::resolve(scenario).expect("built-in scenario");
    let mut opts = SimOptions::new(scenario, ControllerSpec::new(choice));
    if let Some(d) = duration_s {
        opts.duration_s = d;
    }
    opts
}

/// The counts the step saw in a closed-loop `piecewise` run (360 samples).
fn recorded(choice: ControllerChoice) -> Vec<StepInput> {
    let out = run(&sim_options("piecewise", None, choice)).expect("simulation runs");
    out.rows
        .iter()
        .map(|r| StepInput { t_ms: (r.t_s * 1000.0).round() as u64, counts: r.counts, setpoint_c: r.setpoint_c as f32 })
        .collect()
}

fn step(c: &mut Criterion) {
    let mut g = c.benchmark_group("step");
    for (name, kind, choice) in
        [("pi", proto::KIND_PI, ControllerChoice::Pi), ("self_tuning_gpc", proto::KIND_GPC, ControllerChoice::Gpc)]
    {
        let inputs = recorded(choice);
        g.throughput(Throughput::Elements(inputs.len() as u64));
        // One iteration = the whole recorded sequence from a fresh carrier (step + monitor).
        g.bench_function(name, |b| {
            b.iter(|| {
                let (mut carrier, mut monitor) = proto::carrier(kind).expect("known kind");
                let mut acc = 0.0f32;
                for inp in &inputs {
                    let o = carrier.step(black_box(inp));
                    let raised = proto::monitor_push(&mut monitor, inp, &o);
                    acc += o.duty.get() + raised.iter().flatten().count() as f32;
                }
                acc
            })
        });
    }
    g.finish();
}

fn parts(c: &mut Criterion) {
    let acfg: AdaptiveConfig = proto::ADAPTIVE;
    let m = hter::profile::START_MODEL_HTER1;

    // RLS: 5 parameters (the self-tuning controller's) and 4, on a fixed regressor cycle.
    let phis: Vec<[f32; 5]> = (0..64)
        .map(|k| {
            let y = 4.0 + 0.5 * (k as f32 * 0.3).sin();
            [-y, -(y - 0.01), 0.45 + 0.1 * (k as f32 * 0.7).cos(), 0.45, 1.0]
        })
        .collect();
    let mut rls5 = Rls::new(&acfg.rls, SVector::<f32, 5>::from([m.a()[0], m.a()[1], m.b()[0], m.b()[1], 0.0]));
    let mut k = 0;
    c.bench_function("rls_update_5", |b| {
        b.iter(|| {
            k = (k + 1) % phis.len();
            let p = SVector::<f32, 5>::from(phis[k]);
            rls5.update(&acfg.rls, black_box(&p), black_box(4.0 + 0.001 * k as f32))
        })
    });
    let mut rls4 = Rls::new(&acfg.rls, SVector::<f32, 4>::from([m.a()[0], m.a()[1], m.b()[0], m.b()[1]]));
    c.bench_function("rls_update_4", |b| {
        b.iter(|| {
            k = (k + 1) % phis.len();
            let p = SVector::<f32, 4>::from([phis[k][0], phis[k][1], phis[k][2], phis[k][3]]);
            rls4.update(&acfg.rls, black_box(&p), black_box(4.0 + 0.001 * k as f32))
        })
    });

    // GPC design (N2 = 30, Nu = 3) on the H-TER I model, as every self-tuning sample runs it.
    let mut gpc = GpcState::new(0.45);
    for y in [4.3f32, 4.2, 4.1, 4.0] {
        gpc.push_y(y, &m).expect("finite");
        gpc.track(0.5);
    }
    let cfg = GpcConfig::DEFAULT;
    c.bench_function("gpc_design_n2_30_nu_3", |b| b.iter(|| gpc.design(black_box(&m), &cfg, black_box(4.0))));

    // Diophantine identity for Ã of the same model and k = 5 (GMVC/IGMVC; GPC does not need it).
    let at = m.atilde();
    c.bench_function("diophantine_k5", |b| b.iter(|| diophantine::solve(black_box(&at[..m.na() + 2]), &[1.0], 5)));

    // Callendar–Van Dusen inversion, ohms → °C (Pt100 near 4 °C).
    let rtd = proto::CARRIER.get().rtd;
    c.bench_function("cvd_ohms_to_celsius", |b| b.iter(|| rtd.temperature(black_box(Ohms(101.56)))));
}

fn mission(c: &mut Criterion) {
    // The `mission` scenario: 24 h, day/night ambient, lid openings, a supply sag; 8 640
    // control samples and ≈ 10⁶ plant steps. The target is under a second, so that a
    // 1000-mission campaign stays a coffee break.
    let mut g = c.benchmark_group("sim");
    g.sample_size(10);
    for (name, controller) in
        [("mission_24h_pi", ControllerChoice::Pi), ("mission_24h_self_tuning_gpc", ControllerChoice::Gpc)]
    {
        let opts = sim_options("mission", None, controller);
        g.bench_function(name, |b| b.iter(|| run(black_box(&opts)).expect("simulation runs").rows.len()));
    }
    g.finish();
}

criterion_group!(benches, step, parts, mission);
criterion_main!(benches);
