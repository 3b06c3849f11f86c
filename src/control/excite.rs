//! Open-loop excitation for identification: a PRBS on the SSR, behind the same [`Controller`]
//! trait, so an identification run goes through the per-sample step like any other and keeps
//! its sensor checks and freeze guard (the firmware's identification mode, `hter sim
//! --scenario prbs`).

use super::{ControlInput, Controller};
use crate::ident::prbs::{Prbs, PrbsConfig, PrbsError};

/// A PRBS "controller": ignores the measurement and plays the sequence.
#[derive(Clone, Debug)]
pub struct PrbsExcitation {
    prbs: Prbs,
}

impl PrbsExcitation {
    /// Levels `cfg.low`/`cfg.high` must be duties in [0, 1].
    pub fn new(cfg: PrbsConfig) -> Result<Self, PrbsError> {
        if !(0.0..=1.0).contains(&cfg.low) || !(0.0..=1.0).contains(&cfg.high) {
            return Err(PrbsError::Levels);
        }
        Ok(Self { prbs: Prbs::new(cfg)? })
    }
}

impl Controller for PrbsExcitation {
    fn update(&mut self, _input: &ControlInput) -> f32 {
        self.prbs.next_duty()
    }

    fn track(&mut self, _input: &ControlInput, _applied: f32) {}

    fn name(&self) -> &'static str {
        "prbs"
    }
}
