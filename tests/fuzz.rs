//! 10⁷ arbitrary ADC samples through the whole step: no panic, a finite duty in
//! [0, 1] every sample, a finite filtered temperature whenever the step says the sensor is fine,
//! and the supply switch open whenever cooling is held off for safety.
//!
//! Ignored by default (≈ 5 s in release, minutes in debug); CI runs it:
//! `cargo test --release --test fuzz -- --ignored`. The quick proptest in `src/step.rs` covers
//! the same invariants on every `cargo test`.

use hal_sim::sim::{ControllerChoice, ControllerSpec};
use hter::control::AnyController;
use hter::step::{Carrier, Mode, StepInput, ValidConfig};

/// xorshift64*: a fixed, seedable stream.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

/// Counts in blocks of a random kind: anything a broken front end could send (uniform u32,
/// rail to rail, stuck, a plausible random walk with jumps, bursts of spikes).
fn counts(rng: &mut Rng, n: usize, out: &mut Vec<u32>) {
    let plausible = 49_846i64; // ≈ 4 °C on the default front end
    let mut walk = plausible;
    while out.len() < n {
        let len = 1 + (rng.next() % 2000) as usize;
        let kind = rng.next() % 6;
        let stuck = rng.next() as u32;
        for _ in 0..len.min(n - out.len()) {
            let r = rng.next();
            let c = match kind {
                0 => r as u32,
                1 => [0, 65_535, u32::MAX, 1][(r % 4) as usize],
                2 => stuck,
                3 | 4 => {
                    walk += (r % 41) as i64 - 20;
                    if r.is_multiple_of(997) {
                        walk += (r % 4001) as i64 - 2000; // a jump (offset, re-seated probe)
                    }
                    walk = walk.clamp(30_000, 70_000);
                    walk as u32
                }
                _ => {
                    if r.is_multiple_of(7) {
                        (r >> 16) as u32 % 70_000
                    } else {
                        plausible as u32 + (r % 30) as u32
                    }
                }
            };
            out.push(c);
        }
    }
}

#[test]
#[ignore = "10⁷ samples: run in release, `cargo test --release --test fuzz -- --ignored`"]
fn ten_million_arbitrary_samples_through_every_controller() {
    let controllers = [
        ControllerChoice::Onoff,
        ControllerChoice::Pi,
        ControllerChoice::Gmvc,
        ControllerChoice::Igmvc,
        ControllerChoice::Gpc,
    ];
    let per = 10_000_000 / controllers.len();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut stream = Vec::with_capacity(per);
    let mut total = 0usize;
    for choice in controllers {
        stream.clear();
        counts(&mut rng, per, &mut stream);
        let ctl: AnyController = ControllerSpec::new(choice).build(10.0, 0.45).unwrap();
        let mut carrier = Carrier::new(ValidConfig::DEFAULT, ctl);
        for (i, &c) in stream.iter().enumerate() {
            // Setpoints too: mostly 4 °C, sometimes anything (NaN, ±∞, out of band).
            let r = rng.next();
            let setpoint_c = match r % 64 {
                0 => f32::NAN,
                1 => f32::INFINITY,
                2 => -40.0,
                3 => f32::from_bits(r as u32),
                _ => 4.0,
            };
            let out = carrier.step(&StepInput { t_ms: i as u64 * 10_000, counts: c, setpoint_c });
            let d = out.duty.get();
            assert!(d.is_finite() && (0.0..=1.0).contains(&d), "{choice:?} sample {i}: duty {d}");
            assert!((2.0..=8.0).contains(&out.setpoint_c.0), "{choice:?} sample {i}: setpoint {:?}", out.setpoint_c);
            match out.mode {
                Mode::Normal => {
                    assert!(out.temp_c.0.is_finite(), "{choice:?} sample {i}: temperature {:?}", out.temp_c);
                }
                // After a (fuzzed) shorted-SSR verdict: On-Off through the supply switch, the
                // SSR commanded alike, on a finite temperature.
                Mode::LimpHome => {
                    assert!(out.temp_c.0.is_finite(), "{choice:?} sample {i}: temperature {:?}", out.temp_c);
                    assert!(d == 0.0 || d == 1.0, "{choice:?} sample {i}: duty {d} in limp-home");
                    assert_eq!(out.supply_enable, d == 1.0, "{choice:?} sample {i}");
                }
                // Sensor fault, freeze guard: no cooling at all, the supply switch open too.
                _ => {
                    assert_eq!(d, 0.0, "{choice:?} sample {i}: cooling in {:?}", out.mode);
                    assert!(!out.supply_enable, "{choice:?} sample {i}: supply on in {:?}", out.mode);
                }
            }
            total += 1;
        }
    }
    assert_eq!(total, 10_000_000);
}
