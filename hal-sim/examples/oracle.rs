//! How close to the physical bound can *any* controller get? An oracle that knows the plant
//! exactly — its true state at every sample (no sensor dead time, lag, filter or noise) and its
//! equations (it predicts by running a copy of the plant itself) — against the bound
//! (`hal_sim::bound`, SPEC §9) of `piecewise`'s three steps (issue 15).
//!
//! ```text
//! cargo run --release -p hal-sim --example oracle -- [hter1|hter2] [full|half] [ambient °C]
//! ```
//!
//! Each step starts, as the bound's transients do, from the steady state holding the previous
//! setpoint (4 → 6 °C for 112 samples, 6 → 3 °C for 112, 3 → 4 °C for 116: `piecewise` at
//! Ts = 10 s). The plant is deterministic and the oracle knows it, so the best closed loop is
//! the best open-loop duty sequence: it searches one duty per sample in [0, 1] for the least
//! IAE of the segment, by coordinate descent (each duty ±δ in turn, δ from 0.25 down to 0.002,
//! until no move helps), from the bound's own move (all or nothing until the load crosses,
//! then the duty that holds the new setpoint). The IAE is summed as `hal_sim::metrics` and the
//! bound sum it: Σ |T(t_k) − w|·Ts over the samples, T the true load temperature before the
//! sample's duty acts.
//!
//! What it shows: no controller can beat the bound, and none can beat this oracle by more than
//! the search leaves on the table (a local optimum of a 112-dimensional search), since no
//! controller knows more than the oracle does. The oracle's IAE is therefore what is achievable
//! at best; the gap between a controller and the oracle is the controller's, the gap between
//! the oracle and the bound is the plant's (the bound's "zero error after the crossing" cannot
//! be had: the load keeps moving after it crosses). It takes ≈ 1 min per carrier on one core.
use hal_sim::bound::bound;
use hal_sim::plant::{Load, Plant, PlantParams};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{ControllerChoice, ControllerSpec, PlantChoice, SimOptions, PWM_PERIOD_S};

const TS_S: f64 = 10.0;

fn run_sample(p: &mut Plant, duty: f64) {
    for _ in 0..(TS_S / PWM_PERIOD_S).round() as usize {
        p.advance_pwm_period(PWM_PERIOD_S, duty);
    }
}

/// The best duty sequence found for one transient: its IAE, °C·s, and the sequence.
///
/// `states[i]` is the plant before sample i of the current best sequence, so a change of
/// `u[i]` is simulated from there only.
fn optimise(start: &Plant, w: f64, mut u: Vec<f64>) -> (f64, Vec<f64>) {
    let n = u.len();
    let simulate = |from: &Plant, u: &[f64], states: &mut [Plant], first: usize| {
        let mut p = from.clone();
        let mut tail = 0.0;
        for (i, &d) in u.iter().enumerate().skip(first) {
            states[i] = p.clone();
            tail += (p.load_temp_c() - w).abs() * TS_S;
            run_sample(&mut p, d);
        }
        tail
    };
    let mut states = vec![start.clone(); n];
    let mut prefix = vec![0.0; n + 1]; // prefix[i]: IAE of samples 0..i
    let fill_prefix = |states: &[Plant], prefix: &mut [f64]| {
        for i in 0..n {
            prefix[i + 1] = prefix[i] + (states[i].load_temp_c() - w).abs() * TS_S;
        }
    };
    let mut best = simulate(start, &u, &mut states, 0);
    fill_prefix(&states, &mut prefix);
    let mut scratch = states.clone();
    for delta in [0.25, 0.1, 0.04, 0.015, 0.005, 0.002] {
        loop {
            let mut improved = false;
            for i in 0..n {
                for sign in [1.0, -1.0] {
                    let old = u[i];
                    let new = (old + sign * delta).clamp(0.0, 1.0);
                    if new == old {
                        continue;
                    }
                    u[i] = new;
                    let cost = prefix[i] + simulate(&states[i].clone(), &u, &mut scratch, i);
                    if cost < best - 1e-9 {
                        best = cost;
                        states[i..].clone_from_slice(&scratch[i..]);
                        fill_prefix(&states, &mut prefix);
                        improved = true;
                    } else {
                        u[i] = old;
                    }
                }
            }
            if !improved {
                break;
            }
        }
    }
    (best, u)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let plant = args.first().map_or("hter1", String::as_str);
    let load = match args.get(1).map_or("full", String::as_str) {
        "half" => Load::Half,
        "full" => Load::Full,
        other => {
            eprintln!("error: load must be full or half, not {other:?}");
            std::process::exit(2);
        }
    };
    let ambient: f64 = match args.get(2).map(|s| s.parse::<f64>()) {
        None => 28.0,
        Some(Ok(a)) if a.is_finite() => a,
        Some(_) => {
            eprintln!("error: the ambient must be a number of °C");
            std::process::exit(2);
        }
    };
    let (params, choice) = match plant {
        "hter1" => (PlantParams::hter1(load), PlantChoice::Hter1),
        "hter2" => (PlantParams::hter2(load), PlantChoice::Hter2),
        other => {
            eprintln!("error: plant must be hter1 or hter2, not {other:?}");
            std::process::exit(2);
        }
    };
    let scenario = Scenario::built_in("piecewise").expect("piecewise is built in");
    let mut opts = SimOptions::new(scenario, ControllerSpec::new(ControllerChoice::Gpc));
    (opts.plant, opts.load, opts.ambient_c) = (choice, load, ambient);
    let the_bound = match bound(&opts) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    println!("oracle on {plant} {load:?} at {ambient} °C (piecewise's steps, each from steady state)");
    let mut total = 0.0;
    for (from, to, samples) in [(4.0, 6.0, 112usize), (6.0, 3.0, 112), (3.0, 4.0, 116)] {
        let segment_bound =
            the_bound.segments.iter().find(|g| g.from_c == from && g.to_c == to).map_or(f64::NAN, |g| g.iae);
        let (Some((mut p, _)), Some((_, u_w))) =
            (Plant::at_load_temperature(params, ambient, from), Plant::at_load_temperature(params, ambient, to))
        else {
            eprintln!("error: the carrier cannot hold {from} or {to} °C at {ambient} °C ambient");
            std::process::exit(1);
        };
        // Start: the bound's move (all or nothing) until the load crosses, then the holding duty.
        let mut u = Vec::with_capacity(samples);
        let mut q = p.clone();
        let down = to < from;
        let mut crossed = false;
        for _ in 0..samples {
            crossed |= if down { q.load_temp_c() <= to } else { q.load_temp_c() >= to };
            let d = if crossed {
                u_w
            } else if down {
                1.0
            } else {
                0.0
            };
            u.push(d);
            run_sample(&mut q, d);
        }
        let (iae, u) = optimise(&p, to, u);
        let mut iae_after_300s = 0.0;
        for (s, &d) in u.iter().enumerate() {
            if s >= 30 {
                iae_after_300s += (p.load_temp_c() - to).abs() * TS_S;
            }
            run_sample(&mut p, d);
        }
        let head: Vec<String> = u.iter().take(40).map(|d| format!("{d:.2}")).collect();
        println!("  duty, first 40 samples: {}", head.join(" "));
        println!(
            "{from} → {to} °C: IAE {iae:.1} °C·s ({iae_after_300s:.1} after the first 300 s); bound {segment_bound:.1}, ratio {:.3}",
            iae / segment_bound
        );
        total += iae;
    }
    println!("total IAE {total:.1} °C·s; bound {:.1}, ratio {:.3}", the_bound.iae, total / the_bound.iae);
}
