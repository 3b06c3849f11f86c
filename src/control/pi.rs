//! PI control with anti-windup, and P control as its special case.
//!
//! Positional form, forward-Euler integral, sample period Ts:
//!
//! ```text
//! e(t) = y(t) − w(t)
//! I(t) = I(t−1) + Kp·Ts/Ti · e(t)
//! u(t) = Kp · e(t) + I(t)
//! ```
//!
//! Anti-windup (Åström & Hägglund, "Advanced PID Control", 2006, §3.5):
//! - conditional integration: while the request is saturated and the error pushes further into
//!   saturation, the integral is frozen;
//! - the integral is bounded to the actuator range [0, 1] (it is the steady-state duty);
//! - tracking: when the applied duty differs from the saturated request (the supervisor forced
//!   cooling off, or a mode switch), the integral is reset to `applied − Kp·e`, so the controller
//!   resumes from exactly what was applied (bumpless).
//!
//! With `ti_s = ∞` the integral never moves and the controller is P with the manual reset
//! `bias` (the steady duty it assumes at zero error).

use super::{ControlError, ControlInput, Controller};

/// PI configuration (the board's: [`crate::profile::PI`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PiConfig {
    /// Proportional gain, duty per °C (positive: warmer → more cooling).
    pub kp_per_c: f32,
    /// Integral time, s. `f32::INFINITY` gives P control.
    pub ti_s: f32,
    /// Initial integral (= assumed steady duty), in [0, 1].
    pub bias: f32,
}

impl PiConfig {
    /// Integral gain per sample at sample period `ts_s`, duty per °C per sample (0 for P).
    fn ki(&self, ts_s: f32) -> f32 {
        if self.ti_s.is_finite() && self.ti_s > 0.0 {
            self.kp_per_c * ts_s / self.ti_s
        } else {
            0.0
        }
    }
}

/// PI state.
#[derive(Clone, Debug)]
pub struct Pi {
    cfg: PiConfig,
    /// Kp·Ts/Ti, duty per °C per sample.
    ki: f32,
    integral: f32,
    pending: Pending,
}

#[derive(Clone, Copy, Debug, Default)]
struct Pending {
    e: f32,
    integral: f32,
    u: f32,
}

impl Pi {
    /// A controller sampled every `ts_s` (the step's period, `CarrierConfig::ts_s`) whose
    /// integral starts at `cfg.bias`.
    pub fn new(cfg: PiConfig, ts_s: f32) -> Self {
        let integral = if cfg.bias.is_finite() { cfg.bias.clamp(0.0, 1.0) } else { 0.0 };
        Self { cfg, ki: cfg.ki(ts_s), integral, pending: Pending::default() }
    }

    /// The configuration.
    pub fn config(&self) -> &PiConfig {
        &self.cfg
    }

    /// The integral term (the duty the controller holds at zero error).
    pub fn integral(&self) -> f32 {
        self.integral
    }
}

impl Controller for Pi {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        let e = input.y_c - input.w_c;
        let integral = self.integral + self.ki * e;
        let u = self.cfg.kp_per_c * e + integral;
        self.pending = Pending { e, integral, u };
        Ok(u)
    }

    fn track(&mut self, _input: &ControlInput, applied: f32) {
        let Pending { e, integral, u } = self.pending;
        let saturated = u.clamp(0.0, 1.0);
        let candidate = if !applied.is_finite() {
            self.integral
        } else if (applied - saturated).abs() > 1e-6 {
            applied - self.cfg.kp_per_c * e
        } else if (u > 1.0 && e > 0.0) || (u < 0.0 && e < 0.0) {
            self.integral
        } else {
            integral
        };
        if candidate.is_finite() {
            self.integral = candidate.clamp(0.0, 1.0);
        }
    }

    fn name(&self) -> &'static str {
        if self.ki == 0.0 {
            "p"
        } else {
            "pi"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(y: f32) -> ControlInput {
        ControlInput { y_c: y, w_c: 4.0 }
    }

    fn run(c: &mut Pi, y: f32) -> f32 {
        let u = c.update(&input(y)).unwrap();
        let applied = u.clamp(0.0, 1.0);
        c.track(&input(y), applied);
        applied
    }

    #[test]
    fn integral_action_removes_offset_direction() {
        let mut c = Pi::new(PiConfig { kp_per_c: 0.5, ti_s: 100.0, bias: 0.3 }, 10.0);
        let u1 = run(&mut c, 4.2);
        let u2 = run(&mut c, 4.2);
        assert!((u1 - (0.5 * 0.2 + 0.3 + 0.05 * 0.2)).abs() < 1e-6);
        assert!(u2 > u1, "a persistent warm error must increase cooling");
    }

    #[test]
    fn anti_windup_freezes_integral_in_saturation() {
        let cfg = PiConfig { kp_per_c: 0.5, ti_s: 100.0, bias: 0.4 };
        let mut c = Pi::new(cfg, 10.0);
        // An hour at 24 °C above the setpoint: the request is saturated the whole time.
        for _ in 0..360 {
            assert_eq!(run(&mut c, 28.0), 1.0);
        }
        assert!((c.integral() - 0.4).abs() < 1e-6, "integral wound up to {}", c.integral());
        // Once the load is at the setpoint, the controller asks for its pre-saturation duty,
        // not for full cooling as a wound-up integral would.
        assert!((run(&mut c, 4.0) - 0.4).abs() < 1e-6);
        // A naive PI would have accumulated 360 · 0.05 · 24 ≈ 432 and kept cooling far below 2 °C.
    }

    #[test]
    fn override_is_bumpless() {
        let mut c = Pi::new(PiConfig { kp_per_c: 0.5, ti_s: 100.0, bias: 0.4 }, 10.0);
        c.update(&input(4.5)).unwrap();
        // The supervisor forced cooling off.
        c.track(&input(4.5), 0.0);
        // The integral restarts from max(0, applied − Kp·e) = 0 instead of the 0.425 it had, so
        // the next request is Kp·e + Ki·e, not the 0.7 a controller unaware of the override
        // would jump to.
        let u = c.update(&input(4.5)).unwrap();
        assert!((u - (0.5 * 0.5 + 0.05 * 0.5)).abs() < 1e-6, "{u}");
        assert_eq!(c.integral(), 0.0);
    }

    #[test]
    fn p_only_holds_bias_at_zero_error() {
        let mut c = Pi::new(PiConfig { kp_per_c: 0.5, ti_s: f32::INFINITY, bias: 0.35 }, 10.0);
        assert_eq!(c.name(), "p");
        for _ in 0..10 {
            assert!((run(&mut c, 4.0) - 0.35).abs() < 1e-6);
        }
    }
}
