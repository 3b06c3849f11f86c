//! Model-based controllers on a fixed, known model (certainty-equivalence design for a model
//! identified offline or taken from the literature): GMVC, IGMVC and GPC behind the
//! [`Controller`] trait. The self-tuning versions redesign the same laws from the RLS estimate
//! every sample.

use super::gpc::{GpcConfig, GpcStaged, GpcState};
use super::mv::{GmvcConfig, IgmvcConfig, MvState};
use super::{ControlError, ControlInput, Controller};
use crate::model::Model;

/// Which law, with its tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Law {
    /// Generalized minimum variance (weights P, R, S).
    Gmvc(GmvcConfig),
    /// Incremental GMVC (weight λ on Δu).
    Igmvc(IgmvcConfig),
    /// Generalized predictive control (N1, N2, Nu, λ).
    Gpc(GpcConfig),
}

impl Law {
    /// Short name for logs.
    pub fn name(&self) -> &'static str {
        match self {
            Law::Gmvc(_) => "gmvc",
            Law::Igmvc(_) => "igmvc",
            Law::Gpc(_) => "gpc",
        }
    }

    /// Is the tuning in range and the law built into this image? The range checks are the ones
    /// every design repeats; a law left out by the library's features (`mv-laws`,
    /// `igmvc-only`) is [`ControlError::NotBuilt`].
    pub const fn validate(&self) -> Result<(), ControlError> {
        let valid = match self {
            #[cfg(feature = "mv-laws")]
            Law::Gmvc(c) => c.valid(),
            #[cfg(feature = "mv-laws")]
            Law::Igmvc(c) => c.valid(),
            #[cfg(not(feature = "igmvc-only"))]
            Law::Gpc(c) => c.validate().is_ok(),
            #[allow(unreachable_patterns)]
            _ => return Err(ControlError::NotBuilt),
        };
        if valid {
            Ok(())
        } else {
            Err(ControlError::Config)
        }
    }
}

/// The histories of every law, so a law can be evaluated on any model at any sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawState {
    mv: MvState,
    gpc: GpcState,
    /// GPC's design, spread over samples ([`GpcStaged`]).
    gpc_design: GpcStaged,
}

impl LawState {
    /// Empty histories holding the duty `u0`.
    pub fn new(u0: f32) -> Self {
        Self { mv: MvState::new(u0), gpc: GpcState::new(u0), gpc_design: GpcStaged::NEW }
    }

    /// Computes the unclipped u(t) for measurement `y`, setpoint `w`, model `m`, or why not
    /// (a numerical failure, or no model: the caller falls back to its safe behaviour). The
    /// histories advance either way. Without the library feature `mv-laws` (a board that runs
    /// GPC only) GMVC and IGMVC are not linked and give [`ControlError::NotBuilt`]; with
    /// `igmvc-only` (a board that runs IGMVC only) GPC is not linked and gives it.
    pub fn update(&mut self, law: &Law, m: Option<&Model>, y: f32, w: f32) -> Result<f32, ControlError> {
        // A reference to the constant (promoted to a static): no 60-byte copy per sample.
        let (m, have_model) = match m {
            Some(m) => (m, true),
            None => (&Model::NEUTRAL, false),
        };
        #[cfg(feature = "mv-laws")]
        let pushed_mv = self.mv.push_y(y, m);
        #[cfg(not(feature = "igmvc-only"))]
        let pushed_gpc = self.gpc.push_y(y, self.gpc_design.model().unwrap_or(m));
        if !have_model {
            return Err(ControlError::NoModel);
        }
        let u = match law {
            #[cfg(feature = "mv-laws")]
            Law::Gmvc(c) => {
                pushed_mv?;
                self.mv.gmvc(m, c, w)?
            }
            #[cfg(feature = "mv-laws")]
            Law::Igmvc(c) => {
                pushed_mv?;
                self.mv.igmvc(m, c, w)?
            }
            #[cfg(not(feature = "igmvc-only"))]
            Law::Gpc(c) => {
                pushed_gpc?;
                self.gpc.u_prev() + self.gpc_design.update(&self.gpc, m, c, w)?
            }
            #[allow(unreachable_patterns)]
            _ => return Err(ControlError::NotBuilt),
        };
        if u.is_finite() {
            Ok(u)
        } else {
            Err(ControlError::NonFinite)
        }
    }

    /// GPC's staged design (its soft-floor count, [`GpcStaged::floor_samples`]).
    pub fn gpc(&self) -> &GpcStaged {
        &self.gpc_design
    }

    /// Records the applied u.
    pub fn track(&mut self, applied: f32) {
        self.mv.track(applied);
        self.gpc.track(applied);
    }

    /// Forgets the measured past ([`GpcState::reprime`], [`MvState::reprime`]).
    pub fn reprime(&mut self) {
        self.mv.reprime();
        self.gpc.reprime();
    }
}

/// A law on a fixed model.
#[derive(Clone, Debug)]
pub struct FixedModel {
    law: Law,
    model: Model,
    state: LawState,
}

impl FixedModel {
    /// A controller starting from duty `u0`.
    pub fn new(law: Law, model: Model, u0: f32) -> Self {
        Self { law, model, state: LawState::new(u0) }
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }
}

impl Controller for FixedModel {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        self.state.update(&self.law, Some(&self.model), input.y_c, input.w_c)
    }

    fn track(&mut self, _input: &ControlInput, applied: f32) {
        self.state.track(applied);
    }

    /// As the self-tuner's law: the measurements before the gap are forgotten (a spike the step
    /// outvoted may be among them).
    fn skip(&mut self, _applied: f32) {
        self.state.reprime();
    }

    fn name(&self) -> &'static str {
        self.law.name()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::gpc::GpcConfig;
    use crate::control::mv::IgmvcConfig;

    /// After a skipped sample a fixed-model law asks the same whatever it measured before: six
    /// readings (GPC's staged design has run) of a 54 °C spike or of the load at 4 °C, with the
    /// same duties applied.
    #[test]
    fn a_skipped_sample_forgets_the_readings_before_it() {
        let m = Model::new(&[-1.75, 0.75], &[-0.027, -0.03], &[], 5).unwrap();
        for law in [Law::Gpc(GpcConfig::DEFAULT), Law::Igmvc(IgmvcConfig::DEFAULT)] {
            let after = |before: f32| {
                let mut c = FixedModel::new(law, m, 0.3);
                for _ in 0..6 {
                    let input = ControlInput { y_c: before, w_c: 4.0 };
                    c.update(&input).unwrap();
                    // The same duty applied either way (a freeze guard holding it, say), so that
                    // only the readings differ.
                    c.track(&input, 0.3);
                }
                c.skip(0.0);
                c.update(&ControlInput { y_c: 4.05, w_c: 4.0 }).unwrap()
            };
            assert_eq!(after(54.0).to_bits(), after(4.0).to_bits(), "{}", law.name());
        }
    }
}
