//! Controllers behind one small trait.
//!
//! Sign convention: the actuator cools, so more duty means a colder load. Every controller
//! works on the error `e = y − w` (measured minus setpoint, °C): positive when the load is too
//! warm, which asks for more duty.
//!
//! The per-sample step ([`crate::step::Carrier`]) calls [`Controller::update`] with the filtered
//! measurement, then tells the controller what was really applied with [`Controller::track`]
//! (after saturation and any supervisor override), so every controller can stay bumpless and
//! free of integrator wind-up. A controller that cannot compute a duty says why
//! ([`ControlError`]); the step then applies the safe state and reports it.

pub mod adaptive;
pub mod diophantine;
pub mod excite;
pub mod fixed;
pub mod gpc;
pub mod mv;
pub mod onoff;
pub mod pi;
pub mod zn;

pub use fixed::{FixedModel, Law};
pub use onoff::{OnOff, OnOffConfig};
pub use pi::{Pi, PiConfig};

use crate::model::Model;

/// What a controller sees each sample.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlInput {
    /// Filtered, calibrated load temperature, °C.
    pub y_c: f32,
    /// Setpoint, °C (already clamped to the safe band by the step).
    pub w_c: f32,
}

/// Why a controller produced no duty this sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlError {
    /// The law's tuning is out of range (GPC horizons, minimum-variance weights).
    Config,
    /// The law has no solution on this model: singular normal equations, no Diophantine
    /// solution, or no gain at the delay.
    Singular,
    /// A NaN or an infinity appeared in the measurement, the model or the result.
    NonFinite,
    /// No model to design on.
    NoModel,
    /// The law is not built into this image (the library's `mv-laws` / `igmvc-only` features), or
    /// GPC on a model beyond na 2, nb 4 without `gpc-any-order`.
    NotBuilt,
}

impl From<gpc::GpcError> for ControlError {
    fn from(e: gpc::GpcError) -> Self {
        match e {
            gpc::GpcError::Config => ControlError::Config,
            gpc::GpcError::Singular => ControlError::Singular,
            gpc::GpcError::NonFinite => ControlError::NonFinite,
            gpc::GpcError::NotBuilt => ControlError::NotBuilt,
        }
    }
}

impl From<mv::MvError> for ControlError {
    fn from(e: mv::MvError) -> Self {
        match e {
            mv::MvError::Config => ControlError::Config,
            mv::MvError::Diophantine | mv::MvError::Singular => ControlError::Singular,
            mv::MvError::NonFinite => ControlError::NonFinite,
        }
    }
}

/// A feedback controller for the cooler.
pub trait Controller {
    /// Computes the duty request for this sample, or why there is none. The value need not be
    /// clipped; the step saturates it to [0, 1], and on an error (or a non-finite request)
    /// applies the safe state and raises an event.
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError>;

    /// Informs the controller of the duty actually applied this sample, in [0, 1].
    fn track(&mut self, input: &ControlInput, applied: f32);

    /// The step ran a sample without the controller (no trusted reading: a sensor fault, or a
    /// first reading outvoted as a spike) and applied `applied`. Nothing by default: a law
    /// resumes where it left off. The self-tuner's estimator must not regress across the gap
    /// ([`adaptive::SelfTuning`], "Across a sensor fault"), and a model-based law, self-tuning or
    /// on a fixed model, forgets the measurements before it ([`fixed::LawState::reprime`]).
    fn skip(&mut self, _applied: f32) {}

    /// Short name for logs ("onoff", "pi", …).
    fn name(&self) -> &'static str;

    /// State of an adaptive controller, for telemetry and mode-change events.
    fn status(&self) -> Option<ControllerStatus> {
        None
    }

    /// The model a self-tuning controller last trusted (what a board persists); `None` for the
    /// controllers that learn none.
    fn trusted_model(&self) -> Option<Model> {
        None
    }
}

/// Which controller drives the SSR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdaptiveMode {
    /// The law runs on the current RLS estimate.
    Adaptive,
    /// The estimate is not trustworthy: the law runs on the last trusted model (self-tuning:
    /// or on the one its last rest confirmed).
    Frozen,
    /// No trusted model at all: the fallback PI drives.
    Fallback,
}

impl AdaptiveMode {
    /// Every mode, in declaration order.
    pub const ALL: [AdaptiveMode; 3] = [AdaptiveMode::Adaptive, AdaptiveMode::Frozen, AdaptiveMode::Fallback];

    /// Stable snake_case name: the `adaptive_mode` column of `hter sim --csv`.
    pub fn name(self) -> &'static str {
        match self {
            AdaptiveMode::Adaptive => "adaptive",
            AdaptiveMode::Frozen => "frozen",
            AdaptiveMode::Fallback => "fallback",
        }
    }
}

/// What an adaptive controller exposes for logging.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControllerStatus {
    /// Which controller drives the SSR.
    pub mode: AdaptiveMode,
    /// Estimated θ = [a1 a2 b0 b1 b2 b3] (the self-tuner's model without its offset).
    pub theta: [f32; 6],
    /// trace(P) of the estimator.
    pub trace_p: f32,
    /// Last a-priori prediction error, °C.
    pub prediction_error: f32,
    /// The reset at rest the law adds to the setpoint it aims at, °C (0 outside a rest, and
    /// always for laws without one; [`crate::control::adaptive`], "Reset at rest").
    pub reset_c: f32,
}

/// Selects a controller at run time without a heap: the host CLI and the firmware config pick
/// one of these.
// No heap to box into: the enum is as large as its largest controller, which is the one the
// firmware runs by default anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum AnyController {
    /// On-Off with hysteresis.
    OnOff(OnOff),
    /// PI (or P when the integral time is infinite).
    Pi(Pi),
    /// GMVC, IGMVC or GPC on a fixed model.
    Fixed(FixedModel),
    /// Open-loop PRBS for identification.
    Prbs(excite::PrbsExcitation),
    /// Self-tuning GMVC, IGMVC or GPC.
    SelfTuning(adaptive::SelfTuning),
}

impl Controller for AnyController {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        match self {
            AnyController::OnOff(c) => c.update(input),
            AnyController::Pi(c) => c.update(input),
            AnyController::Fixed(c) => c.update(input),
            AnyController::Prbs(c) => c.update(input),
            AnyController::SelfTuning(c) => c.update(input),
        }
    }

    fn track(&mut self, input: &ControlInput, applied: f32) {
        match self {
            AnyController::OnOff(c) => c.track(input, applied),
            AnyController::Pi(c) => c.track(input, applied),
            AnyController::Fixed(c) => c.track(input, applied),
            AnyController::Prbs(c) => c.track(input, applied),
            AnyController::SelfTuning(c) => c.track(input, applied),
        }
    }

    fn skip(&mut self, applied: f32) {
        match self {
            AnyController::SelfTuning(c) => c.skip(applied),
            AnyController::Fixed(c) => c.skip(applied),
            _ => {}
        }
    }

    fn status(&self) -> Option<ControllerStatus> {
        match self {
            AnyController::SelfTuning(c) => c.status(),
            _ => None,
        }
    }

    fn trusted_model(&self) -> Option<Model> {
        match self {
            AnyController::SelfTuning(c) => c.trusted_model(),
            _ => None,
        }
    }

    fn name(&self) -> &'static str {
        match self {
            AnyController::OnOff(c) => c.name(),
            AnyController::Pi(c) => c.name(),
            AnyController::Fixed(c) => c.name(),
            AnyController::Prbs(c) => c.name(),
            AnyController::SelfTuning(c) => c.name(),
        }
    }
}
