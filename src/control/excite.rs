//! Open-loop excitation for identification: a PRBS on the SSR, behind the same [`Controller`]
//! trait, so an identification run goes through the per-sample step like any other and keeps
//! its sensor checks and freeze guard (the firmware's identification mode, `hter sim
//! --scenario prbs`).

use super::{ControlError, ControlInput, Controller};
use crate::ident::prbs::{Prbs, PrbsConfig, PrbsError};

/// A PRBS "controller": ignores the measurement and plays the sequence, optionally after a
/// rest at a constant duty.
#[derive(Clone, Debug)]
pub struct PrbsExcitation {
    prbs: Prbs,
    rest_duty: f32,
    rest_left: u32,
}

impl PrbsExcitation {
    /// Levels `cfg.low`/`cfg.high` must be duties in [0, 1].
    pub fn new(cfg: PrbsConfig) -> Result<Self, PrbsError> {
        if !(0.0..=1.0).contains(&cfg.low) || !(0.0..=1.0).contains(&cfg.high) {
            return Err(PrbsError::Levels);
        }
        Ok(Self { prbs: Prbs::new(cfg)?, rest_duty: 0.0, rest_left: 0 })
    }

    /// Holds `rest_duty` (in [0, 1]) for `rest_samples` samples, then plays the PRBS. An
    /// identification log should begin at rest: the rest is the operating point the model's
    /// deviation variables are taken from (`hter identify --operating-point auto`), and without
    /// it the tool has to fall back to the record means, which are no equilibrium.
    pub fn after_rest(cfg: PrbsConfig, rest_duty: f32, rest_samples: u32) -> Result<Self, PrbsError> {
        if !(0.0..=1.0).contains(&rest_duty) {
            return Err(PrbsError::Levels);
        }
        Ok(Self { rest_duty, rest_left: rest_samples, ..Self::new(cfg)? })
    }
}

impl Controller for PrbsExcitation {
    fn update(&mut self, _input: &ControlInput) -> Result<f32, ControlError> {
        if self.rest_left > 0 {
            self.rest_left -= 1;
            return Ok(self.rest_duty);
        }
        Ok(self.prbs.next_duty())
    }

    fn track(&mut self, _input: &ControlInput, _applied: f32) {}

    fn name(&self) -> &'static str {
        "prbs"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_comes_first_then_the_same_sequence() {
        let cfg = PrbsConfig { bits: 5, hold: 3, low: 0.35, high: 0.55 };
        let input = ControlInput { y_c: 4.0, w_c: 4.0 };
        let mut plain = PrbsExcitation::new(cfg).unwrap();
        let mut rested = PrbsExcitation::after_rest(cfg, 0.45, 4).unwrap();
        let head: std::vec::Vec<f32> = (0..4).map(|_| rested.update(&input).unwrap()).collect();
        assert_eq!(head, [0.45; 4]);
        for _ in 0..200 {
            assert_eq!(rested.update(&input), plain.update(&input));
        }
        assert_eq!(PrbsExcitation::after_rest(cfg, 1.5, 4).err(), Some(PrbsError::Levels));
    }
}
