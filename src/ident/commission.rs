//! On-board commissioning: rest, PRBS, an output-error fit of the second-order model on the
//! board, in bounded work per sample, and the checks the model must pass before anyone uses it
//! (issue 16 item 4; SPEC §8). f32, no heap, no panicking paths: it runs inside the firmware's
//! control step as any law does.
//!
//! [`Commissioning`] is a [`Controller`], so the per-sample step ([`crate::step::Carrier`])
//! runs it with its sensor checks and freeze guard on, exactly as it runs a control law. The
//! glue calls [`Commissioning::abort`] (or [`Commissioning::abort_on_mode`]) when the step's
//! mode leaves normal: the record is spoiled then.
//!
//! # Phases
//!
//! ```text
//!   Rest ──rest_samples──▶ Excite ──(2ⁿ−1)·hold──▶ Fit ──passes──▶ Done(model)
//!    │                       │  └─output did not move─────────────▶ Failed(no excitation)
//!    │                       │                      └─check fails─▶ Failed(reason)
//!    └───────────────────────┴──── abort(reason) at any time ─────▶ Failed(reason)
//!    └─── the load outside 2…8 °C in any phase (coldchain::IN_RANGE_C) ─▶ Failed(out of band)
//! ```
//!
//! - **Rest**: holds `u0` (the duty the board applied when commissioning began) for
//!   `rest_samples`; y0 = the mean temperature of the rest's last `rest_tail_samples`. (y0, u0)
//!   is the operating point of the deviation variables, as `hter identify`'s "initial rest".
//! - **Excite**: one period of a PRBS (the firmware `identify` build's: 7-bit register, bits held
//!   12 samples, levels u0 ± 0.1 clipped to [0, 1]).
//! - **Fit**: holds u0 while it fits, **one pass over the stored record per `update`** (below).
//! - **Done** / **Failed**: holds u0; the glue takes the model (or the reason) and switches
//!   to the law it continues with.
//!
//! # The fit: output error through separable least squares
//!
//! `hter identify` minimises the output error V = Σ (y − x)², x the model simulated from the
//! input and the measured start, by Levenberg–Marquardt in f64 ([`super::oe`]); equation-error
//! least squares is no substitute (63–85 % fit against ≈ 95 % on the H-TER I PRBS run). The
//! board minimises the same V with the poles as the only nonlinear parameters:
//!
//! ```text
//! A(q⁻¹) = (1 − p1 q⁻¹)(1 − p2 q⁻¹),  p_i = exp(−1/τ_i),  τ_i = e^{s_i} samples,  τ1 ≥ 3 τ2
//! m_i(t) = p_i m_i(t−1) + (1 − p_i) ũ(t)             each lag at unit DC gain
//! x(t)   = f_k(t) + K1 m1(t−k) + K2 m2(t−k)          B = K1(1−p1)(1 − p2 q⁻¹) + K2(1−p2)(1 − p1 q⁻¹)
//! f_k(t) = (p1 + p2) f_k(t−1) − p1 p2 f_k(t−2),  f_k(t) = ỹ(t) for t ≤ k
//! V_k(s) = min_{K in the sign cone} Σ_{t ≥ 11} (ỹ(t) − x(t))²
//! ```
//!
//! f_k is the free response from the measured start, as the host's simulation
//! ([`super::validate::simulate_fit`]) begins with x(t) = y(t) for t ≤ k: with two slow poles a
//! few millikelvin of noise in those two samples grow into a slow transient the host's fit
//! counts, so the board must count it too (without it the board's best H-TER I model scored
//! 89.8 % on the host's metric for 96.4 % on its own). With the poles fixed, x is linear in K,
//! so the best K is a 2×2 least-squares problem (separable least squares: Golub & Pereyra, *SIAM
//! J. Numer. Anal.* 10(2), 1973) — and one pass over the record gives it, with V, **for every
//! delay k = 1…10 at once**. The sign rule ([`SignRule`]) is a cone of two linear inequalities
//! on K, enforced exactly (the minimum of a convex 2-variable QP over a cone is the
//! unconstrained one, the best point on a boundary ray, or the origin). The poles are searched
//! in s = ln τ (poles near 1 need a log scale): a grid of the [`GRID_PASSES`] pairs τ1 > τ2 of
//! [`TAU_GRID`], then a compass search (Kolda, Lewis & Torczon, "Optimization by direct search",
//! *SIAM Review* 45(3), 2003, §3: axes and diagonals, the step doubled after a move and halved
//! after a poll without one) on V_k for each of the [`SEARCHED_DELAYS`] delays the grid found
//! best, down to a step of [`MIN_STEP`] or [`MAX_SEARCH_EVALS`] passes; every pass updates the
//! best of every delay. The delay with the
//! least V wins, as `hter identify --nk auto` keeps the delay with the best simulated fit. A
//! last pass simulates the stored `Model` (f32 A, B) from the measured start, for the fit on its
//! own record and the response check.
//!
//! # Two models from one run
//!
//! The sign rule enters only where each delay's 2×2 problem is solved: the sums of a pass are
//! the rule's. So one run fits two models of the same record ([`CommissionConfig::cabinet`]):
//! the **control model** of `cfg.sign` ([`SignRule::EveryCoefficient`] by default: what the
//! self-tuner starts from and trusts) and the **cabinet model**, the best fit of the
//! [`SignRule::Monotone`] cone (what a carrier's holdover estimate runs on: the best-fitting
//! model a monotone cooling allows, [`Commissioning::cabinet`]). The grid's passes give both
//! rules' candidates at once; the two compass searches run one after the other (each keeps only
//! its own rule's candidates, so each model is exactly what a run of its rule alone gives), each
//! ending with its final simulation and checks. The run is done only when both pass (the
//! cabinet model by [`cabinet_plausible`] and its fit on the record); a failure of either keeps
//! neither. The cabinet search costs its own passes: on the simulated carriers the fit phase
//! takes 597–683 samples instead of 286–333 (+50–58 min at Ts = 10 s).
//!
//! Real poles only: the carriers' output-error models have two real lags (H-TER I 0.9968 and
//! 0.943, H-TER II 0.997 and 0.924), as a chain of heat capacities must. The lags are kept a
//! factor [`MIN_LN_TAU_RATIO`] apart: two nearly equal slow poles lose A(1) to f32 rounding.
//!
//! Numerics (f32): the lags have unit DC gain, so every regressor has the input's scale;
//! V = Σe² − Kᵀc cancels most of Σe² at a good fit, so every sum is accumulated in blocks of
//! [`BLOCK`] samples before it joins its total (error ≈ (BLOCK + N/BLOCK)·ε instead of N·ε).
//!
//! Measured (`tests/commission.rs`, the host's fit of the board's model on the same log, vs
//! `hter identify`'s): with [`SignRule::Monotone`] H-TER I full load 96.37 vs 96.39 %, half load
//! 95.10 vs 95.12 %, H-TER II 95.93 vs 95.94 %; with the default [`SignRule::EveryCoefficient`]
//! 86.13, 77.88 and 95.65 % (the host's models all have b1 > 0, which that rule refuses).
//!
//! # Cost
//!
//! - RAM: the record is ỹ as i16 milli-°C (2 bytes/sample) and the PRBS level as one bit per
//!   sample; samples where the step applied something else (the freeze guard) go to a table of
//!   [`MAX_OVERRIDES`]. [`CAPACITY`] = 1600 samples covers the default 60 + 1524.
//!   `size_of::<Commissioning>()` is 4 232 bytes on the Cortex-M4F (4 296 on a 64-bit host, which
//!   a test checks; the cabinet model's candidates added 248); a pass keeps ≈ 0.6 KiB of sums on
//!   the stack.
//! - Per sample in Rest and Excite: at most 303 instructions.
//! - Per sample in Fit: **one pass** over the N stored samples: per sample the two lags (4
//!   flops), then for each of the 10 delays the free response (3), the error (1) and six
//!   multiply-adds (12): ≈ 165 flops, ≈ 2.6·10⁵ flops per pass for N = 1584. Measured on the
//!   emulated Cortex-M4F (`pil/src/bin/commission.rs`, QEMU mps2-an386 `-icount`, the firmware's
//!   build profile): 632 088 instructions per pass at most (mean 629 733) with both cones (ten
//!   more 2×2 solutions per pass; 633 293 / 631 375 measured with one), ≈ 8 ms at 80 MHz,
//!   against Ts = 10 s (the GPC step is ≈ 4 800). The fit takes at most [`MAX_FIT_PASSES`]
//!   samples (28 grid + 2 × (3 × 120 + 1) = 750, 125 min at Ts = 10 s; 389 for one model); on
//!   the simulated carriers 597–683 for both models (286–333 for the control model alone).
//! - Whole run, default settings: 60 + 1524 + (595…683) ≈ 2179–2267 samples (≈ 6.1–6.3 h at
//!   Ts = 10 s), at most 1584 + 750 = 2334.
//!
//! # Glossary
//!
//! - ỹ, ũ — deviations from (y0, u0); x — the model's simulated output; V — Σ(ỹ − x)².
//! - p, τ, s — a pole, its time constant in samples, ln τ; k — delay, samples.
//! - pass — one sweep over the stored record (the unit of bounded work per `update`).

use core::fmt;

use crate::control::adaptive::{plausible_model, AdaptiveConfig};
use crate::control::{ControlError, ControlInput, Controller};
use crate::ident::prbs::{Prbs, PrbsConfig};
use crate::model::Model;
use crate::numerics::sqrtf;
use crate::step::Mode;

/// Most samples the record holds (rest + one PRBS period): the default 60 + 127·12 = 1584 fit.
pub const CAPACITY: usize = 1600;

/// Delays scanned, samples (as `hter identify --nk auto`: 1…10).
pub const MAX_DELAY: usize = 10;

/// Samples where the applied duty differed from the requested level that the record can keep.
pub const MAX_OVERRIDES: usize = 16;

/// Time constants of the pole grid, samples (10 s … 8.3 h at Ts = 10 s, ×√10 apart): every pair
/// τ1 ≥ τ2 is one start of the search.
pub const TAU_GRID: [f32; 8] = [1.0, 3.16, 10.0, 31.6, 100.0, 316.0, 1000.0, 3160.0];

/// Passes of the grid: the pairs τ1 > τ2 of [`TAU_GRID`].
pub const GRID_PASSES: usize = TAU_GRID.len() * (TAU_GRID.len() - 1) / 2;

/// Least ratio τ1/τ2 of the two lags, as ln: 3. Two lags closer than that are one lag to the
/// data, and their A = 1 + a1 q⁻¹ + a2 q⁻² loses the static gain in f32 (A(1) = (1 − p1)(1 − p2)
/// ≈ 6·10⁻⁶ for two poles near 0.997, below the rounding of a1 and a2): on H-TER II such a pair
/// fitted its record at 23 % once stored as a `Model`.
pub const MIN_LN_TAU_RATIO: f32 = 1.0986;

/// Relative RMS error within which a longer delay is preferred to the best-fitting one
/// (the delay choice at the end of the fit): 4 %, about 0.55 fit points at the carriers' 86 %
/// and 0.2 at 95 %. It was 7 %, chosen for the 2-term self-tuner; under the 4-term one that let
/// H-TER I's full load keep k 8 (its RMS error 6.7 % above the best delay's, k 7's 1.8 %), and
/// self-tuning GPC from it limit-cycled 0.17 °C about the setpoint at 28 and 36 °C (1.31–1.46 ×
/// the bound). 3 % and 5 % choose as 4 % does (k 7 full, k 6 half, k 6–8 on H-TER II; issue 15),
/// before the bound on the delay ([`MAX_CONTROL_DELAY_S`]), which now keeps k 6 on all of them.
pub const DELAY_TOLERANCE: f32 = 0.04;

/// Longest delay the control model (the [`SignRule::EveryCoefficient`] rule's) may have, s:
/// 60 s, 6 samples at Ts = 10 s. The delay choice (`preferred`) looks only at the delays up to
/// it; the cabinet model (the monotone rule's) is not bounded, nor is a delay the configuration
/// asks for ([`CommissionConfig::delay`]).
///
/// Why: the RTD reads the water 20 s late through a 20 s lag, and every simulated carrier's
/// step response as the RTD sees it has started within 60 s (at 50 s it is 0.5–2.3 % of its
/// value at 300 s, at 60 s 1.2–5 %). A longer delay fits the record as well only by trading the
/// carrier's fast lag for dead time, and the self-tuner, whose B starts at the model's delay,
/// then misses the response the RTD already shows. The half-loaded H-TER II's fit is flat over
/// the delay (93.4–94.1 % for k 5–10 at 28 °C) and the tolerance kept k 10, the scan's end,
/// with a fast lag of 0.3 samples (3.5 at k 6): self-tuning GPC from it limit-cycled at rest
/// (±0.09 °C, 25 °C) and reached 1.20–1.55 × the bound with a 0.19–0.46 °C steady-state error
/// on `piecewise` (seeds 1–3 at 20, 28 and 36 °C), worse than from the profile's start model;
/// from k 6, 1.03–1.07 × and 0.02–0.04 °C. On the other carriers the tolerance kept k 6 already
/// (H-TER I's half load, H-TER II's full) or k 7 (H-TER I's full load: 1.12–1.14 × from either,
/// the bound keeps k 6). The price: a carrier whose response starts later than 60 s gets a
/// control model of delay 6 whose poles stand in for the rest
/// (`tests::the_control_models_delay_is_bounded`), and its self-tuner's 4-term B spans lags 6–9.
pub const MAX_CONTROL_DELAY_S: f32 = 60.0;

/// Delays the compass search refines: the delay the fit would keep after the grid, then the
/// best of the grid in order of its V.
pub const SEARCHED_DELAYS: usize = 3;

/// First step of the compass search in s = ln τ: half the grid's spacing.
pub const FIRST_STEP: f32 = 0.58;

/// The compass search's directions in s: the axes and the diagonals (the criterion's valleys
/// run along the diagonals: a slower slow lag trades against a faster fast one).
const DIRECTIONS: [[f32; 2]; 8] = [
    [1.0, 0.0],
    [-1.0, 0.0],
    [0.0, 1.0],
    [0.0, -1.0],
    [0.707, 0.707],
    [-0.707, -0.707],
    [0.707, -0.707],
    [-0.707, 0.707],
];

/// A compass step counts as a move when it lowers V by this fraction: smaller decreases are
/// within the f32 rounding of V (≈ 10⁻⁵ of Σỹ², which is 10⁻³–10⁻² of V at a 95 % fit) and
/// would keep the search walking on rounding noise.
pub const MIN_IMPROVEMENT: f32 = 1e-3;

/// The search stops when its step in s falls below this (0.4 % of τ: the fit moves in its
/// third decimal then).
pub const MIN_STEP: f32 = 0.004;

/// Most passes of the compass search of one delay.
pub const MAX_SEARCH_EVALS: usize = 120;

/// Most passes of one model's search and final simulation after the shared grid.
pub const MODEL_PASSES: usize = SEARCHED_DELAYS * MAX_SEARCH_EVALS + 1;

/// Most samples of the fit phase: the grid (shared), then the search and final simulation of
/// the control model and of the cabinet model ([`CommissionConfig::max_fit_passes`]).
pub const MAX_FIT_PASSES: usize = GRID_PASSES + 2 * MODEL_PASSES;

/// Samples per block of the two-level sums (module docs, numerics).
pub const BLOCK: usize = 64;

/// The fit's window starts here, for every delay (the host's starts at k + 1; the record starts
/// at rest, where the samples in between add nothing).
const T0: usize = MAX_DELAY + 1;

/// Bounds of s = ln τ (τ from 0.3 to 10⁴ samples).
const S_MIN: f32 = -1.2;
const S_MAX: f32 = 9.2;

/// What is wrong with a [`CommissionConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigProblem {
    /// The rest is shorter than 20 samples (the fit's window starts at 11 with the input at
    /// rest before it), or its tail is empty or longer than the rest.
    Rest,
    /// The PRBS register length is outside 3…16 bits or the hold is 0.
    Prbs,
    /// The PRBS amplitude is not in (0, 0.5].
    Amplitude,
    /// Rest + one PRBS period do not fit in [`CAPACITY`] samples.
    Capacity,
    /// The rest duty u0 is not a duty in [0, 1].
    RestDuty,
    /// `min_response_c` is not positive, or `min_fit_percent` not in [0, 100).
    Threshold,
    /// The plausibility rule's gain range is not finite, negative and non-empty.
    Plausibility,
    /// The sample period is not positive and finite.
    SamplePeriod,
    /// A given delay is outside 1…[`MAX_DELAY`] samples.
    Delay,
}

/// Why a model fails the plausibility rule ([`plausible_model`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Implausibility {
    /// A root of A on or outside the unit circle.
    Unstable,
    /// No model with every b_i ≤ 0 explains the record: the input heats.
    Heating,
    /// The static gain is outside the plausible range of the profile.
    Gain,
    /// The cabinet model's step response is not a monotone cooling: A's roots are not two real
    /// lags in [0, 1), or b0 > 0, or the slow lag heats ([`cabinet_plausible`]).
    NotMonotone,
}

/// What stopped a run from outside.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FaultKind {
    /// The step reported a sensor fault.
    SensorFault,
    /// The freeze guard took over.
    FreezeGuard,
    /// The SSR was found shorted: limp home.
    LimpHome,
    /// More than [`MAX_OVERRIDES`] samples were applied other than the PRBS asked.
    Overridden,
    /// The temperature left the record's range (±32 °C around its first sample) or was not finite.
    OutputRange,
    /// The load left the vaccine band [`crate::coldchain::IN_RANGE_C`]: the run drives the duty
    /// open loop (the rest, the PRBS, the fit's hold), so a load it takes out of the band (a
    /// start near an edge, an ambient change, a lid opening) is handed back to the law at once.
    OutOfBand,
}

/// Why commissioning gave no model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommissionError {
    /// The configuration is refused.
    Config(ConfigProblem),
    /// The output did not move with the input (RMS below `min_response_c`).
    NoExcitation,
    /// The best model fails the plausibility rule.
    Implausible(Implausibility),
    /// The model simulates its own record below `min_fit_percent`.
    PoorFit,
    /// A fault during the run spoiled the record.
    Fault(FaultKind),
    /// Stopped on request.
    Aborted,
}

impl CommissionError {
    /// Every failure, in the order of their codes ([`CommissionError::code`]).
    pub const ALL: [CommissionError; 22] = [
        CommissionError::Config(ConfigProblem::Rest),
        CommissionError::Config(ConfigProblem::Prbs),
        CommissionError::Config(ConfigProblem::Amplitude),
        CommissionError::Config(ConfigProblem::Capacity),
        CommissionError::Config(ConfigProblem::RestDuty),
        CommissionError::Config(ConfigProblem::Threshold),
        CommissionError::Config(ConfigProblem::Plausibility),
        CommissionError::Config(ConfigProblem::SamplePeriod),
        CommissionError::Config(ConfigProblem::Delay),
        CommissionError::NoExcitation,
        CommissionError::Implausible(Implausibility::Unstable),
        CommissionError::Implausible(Implausibility::Heating),
        CommissionError::Implausible(Implausibility::Gain),
        CommissionError::PoorFit,
        CommissionError::Fault(FaultKind::SensorFault),
        CommissionError::Fault(FaultKind::FreezeGuard),
        CommissionError::Fault(FaultKind::LimpHome),
        CommissionError::Fault(FaultKind::Overridden),
        CommissionError::Fault(FaultKind::OutputRange),
        CommissionError::Aborted,
        // Appended: the codes above are in logs already written.
        CommissionError::Implausible(Implausibility::NotMonotone),
        CommissionError::Fault(FaultKind::OutOfBand),
    ];

    /// A stable number for the failure (the cold-chain log's entry): its index in [`Self::ALL`].
    pub fn code(self) -> u8 {
        Self::ALL.iter().position(|&e| e == self).unwrap_or(0) as u8
    }

    /// Stable snake_case name (the interface's `reason` field).
    pub fn name(self) -> &'static str {
        match self {
            CommissionError::Config(p) => match p {
                ConfigProblem::Rest => "config_rest",
                ConfigProblem::Prbs => "config_prbs",
                ConfigProblem::Amplitude => "config_amplitude",
                ConfigProblem::Capacity => "config_capacity",
                ConfigProblem::RestDuty => "config_rest_duty",
                ConfigProblem::Threshold => "config_threshold",
                ConfigProblem::Plausibility => "config_plausibility",
                ConfigProblem::SamplePeriod => "config_sample_period",
                ConfigProblem::Delay => "config_delay",
            },
            CommissionError::NoExcitation => "no_excitation",
            CommissionError::Implausible(i) => match i {
                Implausibility::Unstable => "implausible_unstable",
                Implausibility::Heating => "implausible_heating",
                Implausibility::Gain => "implausible_gain",
                Implausibility::NotMonotone => "implausible_not_monotone",
            },
            CommissionError::PoorFit => "poor_fit",
            CommissionError::Fault(f) => match f {
                FaultKind::SensorFault => "fault_sensor",
                FaultKind::FreezeGuard => "fault_freeze_guard",
                FaultKind::LimpHome => "fault_limp_home",
                FaultKind::Overridden => "fault_overridden",
                FaultKind::OutputRange => "fault_output_range",
                FaultKind::OutOfBand => "fault_out_of_band",
            },
            CommissionError::Aborted => "aborted",
        }
    }

    /// One line for a person: what went wrong.
    pub fn reason(self) -> &'static str {
        match self {
            CommissionError::Config(p) => match p {
                ConfigProblem::Rest => "configuration refused: rest under 20 samples or its tail not in 1..=rest",
                ConfigProblem::Prbs => "configuration refused: PRBS register not 3-16 bits or hold 0",
                ConfigProblem::Amplitude => "configuration refused: PRBS amplitude not in (0, 0.5]",
                ConfigProblem::Capacity => "configuration refused: rest + PRBS period exceed the record (1600 samples)",
                ConfigProblem::RestDuty => "configuration refused: rest duty not in [0, 1]",
                ConfigProblem::Threshold => {
                    "configuration refused: min_response_c <= 0 or min_fit_percent not in [0, 100)"
                }
                ConfigProblem::Plausibility => {
                    "configuration refused: plausible gain range not finite, negative, non-empty"
                }
                ConfigProblem::SamplePeriod => "configuration refused: sample period not positive",
                ConfigProblem::Delay => "configuration refused: delay not in 1..=10 samples",
            },
            CommissionError::NoExcitation => "no excitation: the temperature did not follow the PRBS",
            CommissionError::Implausible(i) => match i {
                Implausibility::Unstable => "implausible fit: A is not stable",
                Implausibility::Heating => "implausible fit: only a heating B explains the record",
                Implausibility::Gain => "implausible fit: static gain outside the plausible range",
                Implausibility::NotMonotone => {
                    "implausible fit: the cabinet model's step response is not a monotone cooling"
                }
            },
            CommissionError::PoorFit => "poor fit: the model does not simulate its own record well enough",
            CommissionError::Fault(f) => match f {
                FaultKind::SensorFault => "fault during the run: sensor fault",
                FaultKind::FreezeGuard => "fault during the run: the freeze guard took over",
                FaultKind::LimpHome => "fault during the run: SSR shorted, limp home",
                FaultKind::Overridden => "fault during the run: the excitation was overridden too often",
                FaultKind::OutputRange => "fault during the run: temperature out of the record's range",
                FaultKind::OutOfBand => "fault during the run: the load left 2-8 °C",
            },
            CommissionError::Aborted => "aborted on request",
        }
    }
}

impl fmt::Display for CommissionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.reason())
    }
}

/// Commissioning settings (a `Copy` constant; checked by [`CommissionConfig::validate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommissionConfig {
    /// Samples the rest holds u0 (≥ 20).
    pub rest_samples: u16,
    /// The last samples of the rest whose mean temperature is y0 (1 … `rest_samples`).
    pub rest_tail_samples: u16,
    /// PRBS register length, bits (3…16): one period is (2ⁿ − 1)·hold samples.
    pub prbs_bits: u8,
    /// Samples each PRBS bit is held.
    pub prbs_hold: u16,
    /// PRBS levels u0 ± this, duty (clipped to [0, 1]).
    pub amplitude: f32,
    /// The output counts as moved when the RMS of ỹ over the excitation, and of the model's
    /// simulated output, reach this, °C.
    pub min_response_c: f32,
    /// Least simulated fit of the model on its own record, %.
    pub min_fit_percent: f32,
    /// The plausibility rule's settings ([`plausible_model`]: the gain range).
    pub plausible: AdaptiveConfig,
    /// The sign the fit imposes on B (and the final check).
    pub sign: SignRule,
    /// Fit this delay only, samples (1…[`MAX_DELAY`], as `hter identify --nk N`); `None`: the
    /// delay with the least V (`--nk auto`).
    pub delay: Option<u8>,
    /// Also fit the cabinet model from the same record: the best-fitting model of the
    /// [`SignRule::Monotone`] cone ([`Commissioning::cabinet`]; the module docs' "Two models").
    /// Without effect when `sign` is already [`SignRule::Monotone`] (the one model is both).
    pub cabinet: bool,
}

/// Which models with a cooling sign the fit may choose from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SignRule {
    /// Every b_i ≤ 0, as [`plausible_model`] requires of any model the self-tuner trusts or a
    /// board restores ([`crate::persist::ModelRecord::to_model`]). The default.
    EveryCoefficient,
    /// A monotone step response: the impulse response h(j) = K1 (1−p1) p1^j + K2 (1−p2) p2^j
    /// (modal form of the module docs, p1 ≥ p2) is ≤ 0 at every j, which for two real poles is
    /// h(0) = b0 ≤ 0 and K1 ≤ 0 (the slow mode cools; a heating fast mode is allowed as long
    /// as b0 stays cooling). This is the property [`plausible_model`]'s docs give as its reason
    /// ("the step response of a Peltier cooler seen through the RTD is monotone"); every b_i ≤ 0
    /// implies it but is stricter: two cooling lags in parallel have b1 > 0, and so have the
    /// output-error models of both carriers. A model of this rule passes the final check by
    /// [`cabinet_plausible`] (two real stable lags, b0 ≤ 0, slow mode cooling, gain in range),
    /// not by [`plausible_model`], which refuses it while b1 > 0: the self-tuner would not
    /// trust it; a board keeps it as its cabinet model (the holdover's, its own record).
    Monotone,
}

impl CommissionConfig {
    /// 60 samples of rest (10 min at Ts = 10 s; y0 from the last 30), the firmware identify
    /// build's PRBS (7 bits, hold 12, ±0.1: 1524 samples, 4.2 h), 0.05 °C of response (6× the
    /// sensor's 0.008 °C noise; the carriers answer ±0.1 with ≈ 1 °C RMS), 80 % fit (the
    /// carriers' output-error models reach 92–95 %, equation error 63–85 %), and the default
    /// build's plausibility rule ([`crate::profile::ADAPTIVE_GPC`]).
    pub const DEFAULT: CommissionConfig = CommissionConfig {
        rest_samples: 60,
        rest_tail_samples: 30,
        prbs_bits: 7,
        prbs_hold: 12,
        amplitude: 0.1,
        min_response_c: 0.05,
        min_fit_percent: 70.0,
        plausible: crate::profile::ADAPTIVE_GPC,
        sign: SignRule::EveryCoefficient,
        delay: None,
        cabinet: true,
    };

    /// One PRBS period, samples.
    pub const fn prbs_samples(&self) -> usize {
        let bits = if self.prbs_bits >= 3 && self.prbs_bits <= 16 { self.prbs_bits } else { 3 };
        ((1usize << bits) - 1) * self.prbs_hold as usize
    }

    /// Rest + excitation, samples: the record the fit runs on.
    pub const fn record_samples(&self) -> usize {
        self.rest_samples as usize + self.prbs_samples()
    }

    /// Whether the run fits two models: the control model of `sign` and the cabinet model.
    pub const fn two_models(&self) -> bool {
        self.cabinet && !matches!(self.sign, SignRule::Monotone)
    }

    /// Most samples of the fit phase: the grid and one model's search, or two.
    pub const fn max_fit_passes(&self) -> usize {
        GRID_PASSES + if self.two_models() { 2 * MODEL_PASSES } else { MODEL_PASSES }
    }

    /// Most samples the whole commissioning takes: the record and the longest fit.
    pub const fn max_total_samples(&self) -> usize {
        self.record_samples() + self.max_fit_passes()
    }

    /// Checks every range [`Commissioning::new`] relies on.
    pub fn validate(&self) -> Result<(), CommissionError> {
        let bad = |p| Err(CommissionError::Config(p));
        if self.rest_samples < 20 || self.rest_tail_samples == 0 || self.rest_tail_samples > self.rest_samples {
            return bad(ConfigProblem::Rest);
        }
        if !(3..=16).contains(&self.prbs_bits) || self.prbs_hold == 0 {
            return bad(ConfigProblem::Prbs);
        }
        if !(self.amplitude > 0.0 && self.amplitude <= 0.5) {
            return bad(ConfigProblem::Amplitude);
        }
        if self.record_samples() > CAPACITY || self.record_samples() <= T0 + 40 {
            return bad(ConfigProblem::Capacity);
        }
        let fit_ok = self.min_fit_percent >= 0.0 && self.min_fit_percent < 100.0;
        if !(self.min_response_c > 0.0 && self.min_response_c.is_finite() && fit_ok) {
            return bad(ConfigProblem::Threshold);
        }
        let (lo, hi) = (self.plausible.gain_min_c_per_duty, self.plausible.gain_max_c_per_duty);
        if !(lo.is_finite() && lo < hi && hi < 0.0) {
            return bad(ConfigProblem::Plausibility);
        }
        if self.delay.is_some_and(|k| !(1..=MAX_DELAY as u8).contains(&k)) {
            return bad(ConfigProblem::Delay);
        }
        Ok(())
    }
}

impl Default for CommissionConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Where a run is, with its progress.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// Holding u0; percent of the rest done.
    Rest {
        /// 0…100.
        percent: u8,
    },
    /// Playing the PRBS; percent of its period done.
    Excite {
        /// 0…100.
        percent: u8,
    },
    /// Fitting, holding u0; percent of the most passes the fit can take.
    Fit {
        /// 0…100.
        percent: u8,
    },
    /// Finished with a model that passed every check.
    Done(Model),
    /// Finished without a model.
    Failed(CommissionError),
}

impl Phase {
    /// Stable snake_case name.
    pub fn name(&self) -> &'static str {
        match self {
            Phase::Rest { .. } => "rest",
            Phase::Excite { .. } => "excite",
            Phase::Fit { .. } => "fit",
            Phase::Done(_) => "done",
            Phase::Failed(_) => "failed",
        }
    }

    /// Percent of this phase done (100 once finished).
    pub fn percent(&self) -> u8 {
        match self {
            Phase::Rest { percent } | Phase::Excite { percent } | Phase::Fit { percent } => *percent,
            Phase::Done(_) | Phase::Failed(_) => 100,
        }
    }
}

/// One evaluation of the poles s = (ln τ1, ln τ2): the best delay and its B.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Candidate {
    s: [f32; 2],
    /// min over k of V_k, °C².
    v: f32,
    k: u8,
    /// B in physical units (°C per unit duty), b0 and b1.
    b: [f32; 2],
}

impl Candidate {
    const NONE: Candidate = Candidate { s: [0.0; 2], v: f32::INFINITY, k: 1, b: [0.0; 2] };
}

/// Where the fit is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum FitStage {
    /// Evaluating grid pair `i`.
    Grid(u8),
    /// Compass search of the `round`-th delay of `order` around its best point: next
    /// direction `dir` (of [`DIRECTIONS`]) at `step`; of the cabinet model's candidates if
    /// `cabinet`, else of the control model's.
    Compass { cabinet: bool, round: u8, order: [u8; SEARCHED_DELAYS], step: f32, dir: u8, evals: u8 },
    /// The final simulation of the control model.
    Final,
    /// The final simulation of the cabinet model.
    FinalCabinet,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum State {
    Rest,
    Excite,
    Fit(FitStage),
    Done(Model),
    Failed(CommissionError),
}

/// On-board commissioning as a [`Controller`] (module docs).
#[derive(Clone, Debug)]
pub struct Commissioning {
    cfg: CommissionConfig,
    state: State,
    prbs: Prbs,
    u0: f32,
    low: f32,
    high: f32,
    /// The level `update` asked for this sample (true: high), checked against the applied duty.
    asked_high: bool,
    /// Output of the first sample, °C: the record keeps y − y_ref.
    y_ref: f32,
    /// y0 − y_ref, milli-°C (known after the rest).
    y0_mk: f32,
    /// Σ ỹ² over the excitation so far, °C².
    excite_ss: f32,
    len: u16,
    y_mk: [i16; CAPACITY],
    high_bits: [u8; CAPACITY / 8],
    overrides: [(u16, u16); MAX_OVERRIDES],
    n_overrides: u8,
    /// Longest delay of the `cfg.sign` rule's candidates, samples: [`MAX_CONTROL_DELAY_S`] at
    /// this Ts (at least 1) for the every-b_i ≤ 0 rule's model, [`MAX_DELAY`] otherwise.
    max_control_k: u8,
    /// The best candidate of each delay k = 1…[`MAX_DELAY`] so far (the rule `cfg.sign`).
    best: [Candidate; MAX_DELAY],
    /// The same of the cabinet model (the monotone rule), when the run fits two models.
    best_cabinet: [Candidate; MAX_DELAY],
    passes: u16,
    fit_percent: Option<f32>,
    /// The cabinet model passed its checks (it is `preferred(best_cabinet)`'s model).
    cabinet_ok: bool,
    cabinet_fit_percent: Option<f32>,
}

/// exp(−1/τ) for τ = e^s.
fn pole(s: f32) -> f32 {
    libm::expf(-libm::expf(-s))
}

/// s within its bounds, ordered s1 ≥ s2, with the lags at least [`MIN_LN_TAU_RATIO`] apart.
fn separated(s: [f32; 2]) -> [f32; 2] {
    let clamp = |v: f32| crate::units::min_f32(crate::units::max_f32(v, S_MIN), S_MAX);
    let (hi, lo) = if s[0] >= s[1] { (s[0], s[1]) } else { (s[1], s[0]) };
    let hi = clamp(crate::units::max_f32(hi, S_MIN + MIN_LN_TAU_RATIO));
    [hi, clamp(crate::units::min_f32(lo, hi - MIN_LN_TAU_RATIO))]
}

fn percent(done: usize, of: usize) -> u8 {
    if of == 0 {
        return 100;
    }
    (done.saturating_mul(100) / of).min(100) as u8
}

/// Two-level sum: `block` collects up to [`BLOCK`] terms, then joins `total`.
#[derive(Clone, Copy, Default)]
struct Sum {
    block: f32,
    total: f32,
}

impl Sum {
    fn add(&mut self, v: f32) {
        self.block += v;
    }
    fn flush(&mut self) {
        self.total += self.block;
        self.block = 0.0;
    }
    fn get(&self) -> f32 {
        self.total + self.block
    }
}

/// The normal-equation sums of one delay over the modal regressors z1 = m1(t−k), z2 = m2(t−k).
#[derive(Clone, Copy, Default)]
struct Normal {
    yy: Sum,
    s11: Sum,
    s12: Sum,
    s22: Sum,
    c1: Sum,
    c2: Sum,
}

/// The K = (K1, K2) minimising V = Σỹ² − 2Kᵀc + KᵀSK subject to r1·K ≤ 0 and r2·K ≤ 0, and its
/// V. A convex QP in two variables over a cone: its minimum is the unconstrained one, the best
/// point on one of the two boundary rays, or the origin; the feasible candidate of least V is it.
fn constrained_k(n: &Normal, r: [[f32; 2]; 2]) -> ([f32; 2], f32) {
    let (s11, s12, s22, c1, c2) = (n.s11.get(), n.s12.get(), n.s22.get(), n.c1.get(), n.c2.get());
    let yy = n.yy.get();
    let feasible = |k: [f32; 2]| r.iter().all(|ri| ri[0] * k[0] + ri[1] * k[1] <= 1e-12);
    let mut best = ([0.0f32; 2], yy);
    let mut consider = |k: [f32; 2], v: f32| {
        if feasible(k) && v.is_finite() && v < best.1 {
            best = (k, v);
        }
    };
    let det = s11 * s22 - s12 * s12;
    if det > 1e-3 * s11 * s22 && det.is_finite() {
        let k = [(s22 * c1 - s12 * c2) / det, (s11 * c2 - s12 * c1) / det];
        consider(k, yy - (k[0] * c1 + k[1] * c2));
    }
    for ri in r {
        // The boundary ri·K = 0 is the line along d ⊥ ri; both rays are tried (feasibility
        // decides), the least-squares point on each: t = dᵀc / dᵀSd, t > 0.
        for d in [[-ri[1], ri[0]], [ri[1], -ri[0]]] {
            let sdd = d[0] * d[0] * s11 + 2.0 * d[0] * d[1] * s12 + d[1] * d[1] * s22;
            let dc = d[0] * c1 + d[1] * c2;
            if sdd > 0.0 && dc > 0.0 {
                let t = dc / sdd;
                consider([t * d[0], t * d[1]], yy - t * dc);
            }
        }
    }
    best
}

/// B of the modal form: x = K1 (1−p1)/(1−p1 q⁻¹) u(t−k) + K2 (1−p2)/(1−p2 q⁻¹) u(t−k)
/// ⇒ B = K1 (1−p1)(1 − p2 q⁻¹) + K2 (1−p2)(1 − p1 q⁻¹).
fn b_of_modes(k: [f32; 2], p1: f32, p2: f32) -> [f32; 2] {
    let (g1, g2) = (k[0] * (1.0 - p1), k[1] * (1.0 - p2));
    [g1 + g2, -(g1 * p2 + g2 * p1)]
}

/// The sign constraints r·K ≤ 0 of `rule` on the modal gains K for poles p1, p2.
fn sign_rows(rule: SignRule, p1: f32, p2: f32) -> [[f32; 2]; 2] {
    let (g1, g2) = (1.0 - p1, 1.0 - p2);
    match rule {
        // b0 ≤ 0 and b1 ≤ 0, through b_of_modes.
        SignRule::EveryCoefficient => [[g1, g2], [-g1 * p2, -g2 * p1]],
        // K1 ≤ 0 and b0 = K1 (1 − p1) + K2 (1 − p2) ≤ 0.
        SignRule::Monotone => [[1.0, 0.0], [g1, g2]],
    }
}

/// The candidate of delay `k` for the poles p1, p2 (at s) from its sums, under `rule`.
fn candidate(n: &Normal, s: [f32; 2], k: usize, p1: f32, p2: f32, rule: SignRule) -> Candidate {
    let (gains, v) = constrained_k(n, sign_rows(rule, p1, p2));
    // On a boundary ray the constrained coefficient is 0 up to rounding, which may leave it at
    // +1e-9: the rule holds it at 0 exactly (plausible_model refuses b > 0).
    let [b0, b1] = b_of_modes(gains, p1, p2);
    let b = match rule {
        SignRule::EveryCoefficient => [crate::units::min_f32(b0, 0.0), crate::units::min_f32(b1, 0.0)],
        SignRule::Monotone => [crate::units::min_f32(b0, 0.0), b1],
    };
    Candidate { s, v, k: k as u8, b }
}

/// Keeps every delay's better candidate.
fn adopt(best: &mut [Candidate; MAX_DELAY], cands: &[Candidate; MAX_DELAY]) {
    for (b, c) in best.iter_mut().zip(cands) {
        if c.v < b.v {
            *b = *c;
        }
    }
}

/// The best candidate over every delay.
fn overall_best(best: &[Candidate; MAX_DELAY]) -> Candidate {
    best.iter().fold(Candidate::NONE, |acc, c| if c.v < acc.v { *c } else { acc })
}

/// The candidate the fit keeps: of the delays whose RMS error is within [`DELAY_TOLERANCE`] of
/// the best delay's, the longest (for the control model, of the delays up to
/// [`MAX_CONTROL_DELAY_S`]: the others have no candidate). On the carriers the fit is nearly
/// flat over the delay (H-TER I: 85.0–86.1 % for k = 1…8) because the two poles can mimic dead
/// time; the longest delay that fits as well leaves the poles to the thermal lags, which is
/// what a predictive law needs (self-tuning GPC from H-TER I's k = 6 or 7 model: 1.12–1.14 × the
/// bound on `piecewise`; from the k = 5 the best fit picks: 2.38–2.50 ×; from k 8, which a 7 %
/// tolerance kept: 1.40–1.45 ×, `tests/commission.rs::gpc_by_delay`).
fn preferred(best: &[Candidate; MAX_DELAY]) -> Candidate {
    let top = overall_best(best);
    let limit = sqrtf(top.v) * (1.0 + DELAY_TOLERANCE);
    best.iter().rev().find(|c| c.v.is_finite() && sqrtf(c.v) <= limit).copied().unwrap_or(top)
}

/// The best candidate of delay `k`.
fn best_of(best: &[Candidate; MAX_DELAY], k: u8) -> Candidate {
    best.get(usize::from(k).wrapping_sub(1)).copied().unwrap_or(Candidate::NONE)
}

/// The delay the fit would keep after the grid ([`preferred`]), then the others with the lowest
/// V, best first.
fn delay_order(best: &[Candidate; MAX_DELAY]) -> [u8; SEARCHED_DELAYS] {
    let mut order = [0u8; SEARCHED_DELAYS];
    let mut taken = [false; MAX_DELAY];
    let keep = preferred(best).k;
    if let (Some(o), Some(t)) = (order.first_mut(), taken.get_mut(usize::from(keep).wrapping_sub(1))) {
        *o = keep;
        *t = true;
    }
    for o in order.iter_mut().skip(1) {
        let mut pick: Option<(usize, f32)> = None;
        for (i, c) in best.iter().enumerate() {
            let free = !taken.get(i).copied().unwrap_or(true);
            if free && pick.is_none_or(|(_, v)| c.v < v) {
                pick = Some((i, c.v));
            }
        }
        if let Some((i, _)) = pick {
            if let Some(t) = taken.get_mut(i) {
                *t = true;
            }
            *o = (i + 1) as u8;
        }
    }
    order
}

/// Whether `m` may be a carrier's cabinet model (the holdover's; what commissioning's
/// monotone rule fits, what `set model` uploads and a board restores): a second-order model
/// whose A has two real lags 0 ≤ p2 ≤ p1 < 1, whose step response is a monotone cooling
/// (b0 ≤ 0 and the slow lag cooling, b0·p1 + b1 ≤ 0: with the impulse response
/// h(j) = r1 p1^j + r2 p2^j, r1 = (b1 + b0 p1)/(p1 − p2) and r1 + r2 = b0, every h(j) ≤ 0 iff
/// r1 ≤ 0 and b0 ≤ 0; the same holds for a repeated pole), and whose static gain is in `cfg`'s
/// plausible range. Every model with every b_i ≤ 0 and real lags passes; two cooling lags in
/// parallel (b1 > 0) pass too, which [`plausible_model`] refuses.
pub fn cabinet_plausible(cfg: &AdaptiveConfig, m: &Model) -> Result<(), Implausibility> {
    if m.na() != 2 || m.nb() != 2 || !m.a_is_stable() {
        return Err(Implausibility::Unstable);
    }
    let (a1, a2, b0, b1) = (m.a()[0], m.a()[1], m.b()[0], m.b()[1]);
    // Two real roots of z² + a1 z + a2 in [0, 1): a sum −a1 ≥ 0, a product a2 ≥ 0 and a
    // discriminant ≥ 0 up to its f32 rounding (two lags 3× apart in τ near 1 differ by 10⁻³).
    let disc = a1 * a1 - 4.0 * a2;
    if !(a1 <= 0.0 && a2 >= 0.0 && disc >= -1e-6 * a1 * a1) {
        return Err(Implausibility::NotMonotone);
    }
    let p1 = 0.5 * (-a1 + sqrtf(crate::units::max_f32(disc, 0.0)));
    // The fit holds r1 ≤ 0 exactly in its modal form; in (b0, b1) that is 0 up to rounding.
    let slack = 1e-4 * (b0.abs() * p1 + b1.abs());
    if !(b0 <= 0.0 && b0 * p1 + b1 <= slack) {
        return Err(Implausibility::NotMonotone);
    }
    let (lo, hi) = (cfg.gain_min_c_per_duty, cfg.gain_max_c_per_duty);
    if !m.static_gain().is_some_and(|g| (lo..=hi).contains(&g)) {
        return Err(Implausibility::Gain);
    }
    Ok(())
}

impl Commissioning {
    /// A run at sample period `ts_s` (s) that rests at duty `u0`, the duty the board applied
    /// when it began.
    pub fn new(cfg: CommissionConfig, ts_s: f32, u0: f32) -> Result<Self, CommissionError> {
        cfg.validate()?;
        if !(ts_s.is_finite() && ts_s > 0.0) {
            return Err(CommissionError::Config(ConfigProblem::SamplePeriod));
        }
        if !(0.0..=1.0).contains(&u0) {
            return Err(CommissionError::Config(ConfigProblem::RestDuty));
        }
        let low = crate::units::max_f32(u0 - cfg.amplitude, 0.0);
        let high = crate::units::min_f32(u0 + cfg.amplitude, 1.0);
        let prbs = Prbs::new(PrbsConfig { bits: cfg.prbs_bits, hold: cfg.prbs_hold, low, high })
            .map_err(|_| CommissionError::Config(ConfigProblem::Prbs))?;
        Ok(Self {
            cfg,
            state: State::Rest,
            prbs,
            u0,
            low,
            high,
            asked_high: false,
            y_ref: 0.0,
            y0_mk: 0.0,
            excite_ss: 0.0,
            len: 0,
            y_mk: [0; CAPACITY],
            high_bits: [0; CAPACITY / 8],
            overrides: [(0, 0); MAX_OVERRIDES],
            n_overrides: 0,
            // Whole samples within the bound, at least one (a Ts above 60 s); the whole scan for
            // the monotone rule's model and for a delay asked for.
            max_control_k: if cfg.sign == SignRule::EveryCoefficient && cfg.delay.is_none() {
                (MAX_CONTROL_DELAY_S / ts_s).clamp(1.0, MAX_DELAY as f32) as u8
            } else {
                MAX_DELAY as u8
            },
            best: [Candidate::NONE; MAX_DELAY],
            best_cabinet: [Candidate::NONE; MAX_DELAY],
            passes: 0,
            fit_percent: None,
            cabinet_ok: false,
            cabinet_fit_percent: None,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &CommissionConfig {
        &self.cfg
    }

    /// Where the run is, with its progress.
    pub fn phase(&self) -> Phase {
        let len = usize::from(self.len);
        let rest = usize::from(self.cfg.rest_samples);
        match self.state {
            State::Rest => Phase::Rest { percent: percent(len, rest) },
            State::Excite => Phase::Excite { percent: percent(len.saturating_sub(rest), self.cfg.prbs_samples()) },
            State::Fit(_) => Phase::Fit { percent: percent(usize::from(self.passes), self.cfg.max_fit_passes()) },
            State::Done(m) => Phase::Done(m),
            State::Failed(e) => Phase::Failed(e),
        }
    }

    /// The model or the reason, once finished; `None` while running.
    pub fn outcome(&self) -> Option<Result<Model, CommissionError>> {
        match self.state {
            State::Done(m) => Some(Ok(m)),
            State::Failed(e) => Some(Err(e)),
            _ => None,
        }
    }

    /// The fit of the model on its own record, %, once the fit has run (also when the model
    /// then failed a check).
    pub fn fit_percent(&self) -> Option<f32> {
        self.fit_percent
    }

    /// The cabinet model (the best fit of the monotone rule, checked by
    /// [`cabinet_plausible`] and on its own record) once the run is done: the second model of a
    /// two-model run, or the one model of a [`SignRule::Monotone`] run; `None` before, after a
    /// failure, or for a run with `cabinet` off.
    pub fn cabinet(&self) -> Option<Model> {
        match self.state {
            State::Done(m) if self.cfg.sign == SignRule::Monotone => self.cfg.cabinet.then_some(m),
            State::Done(_) if self.cabinet_ok => Self::model_of(&preferred(&self.best_cabinet)),
            _ => None,
        }
    }

    /// The cabinet model's fit on its own record, %, once fitted (a two-model run; the one
    /// model's for a [`SignRule::Monotone`] run).
    pub fn cabinet_fit_percent(&self) -> Option<f32> {
        if self.cfg.sign == SignRule::Monotone {
            self.fit_percent
        } else {
            self.cabinet_fit_percent
        }
    }

    /// The operating point (y0 °C, u0 duty) of the model's deviation variables; y0 is known
    /// once the rest is over.
    pub fn operating_point(&self) -> (f32, f32) {
        (self.y_ref + self.y0_mk / 1000.0, self.u0)
    }

    /// Samples of the fit phase so far (each one pass over the record).
    pub fn fit_passes(&self) -> u16 {
        self.passes
    }

    /// Stops a running commissioning with `reason` (a fault: the record is spoiled; or
    /// [`CommissionError::Aborted`] on request). A finished one keeps its outcome.
    pub fn abort(&mut self, reason: CommissionError) {
        if !matches!(self.state, State::Done(_) | State::Failed(_)) {
            self.state = State::Failed(reason);
        }
    }

    /// [`Self::abort`] with the matching fault when the step's mode is not normal (the glue
    /// calls it after every step).
    pub fn abort_on_mode(&mut self, mode: Mode) {
        let kind = match mode {
            Mode::Normal => return,
            Mode::SensorFault => FaultKind::SensorFault,
            Mode::FreezeGuard => FaultKind::FreezeGuard,
            Mode::LimpHome => FaultKind::LimpHome,
        };
        self.abort(CommissionError::Fault(kind));
    }

    fn fail(&mut self, e: CommissionError) {
        self.state = State::Failed(e);
    }

    /// Appends one sample (Rest and Excite).
    fn record(&mut self, y_c: f32, applied: f32) {
        let i = usize::from(self.len);
        if i == 0 {
            self.y_ref = y_c;
        }
        let mk = (y_c - self.y_ref) * 1000.0;
        if !(mk.is_finite() && mk.abs() < 32_000.0) {
            return self.fail(CommissionError::Fault(FaultKind::OutputRange));
        }
        let rest = i < usize::from(self.cfg.rest_samples);
        let asked = if rest {
            self.u0
        } else if self.asked_high {
            self.high
        } else {
            self.low
        };
        if (applied - asked).abs() > 1e-6 {
            let Some(slot) = self.overrides.get_mut(usize::from(self.n_overrides)) else {
                return self.fail(CommissionError::Fault(FaultKind::Overridden));
            };
            let applied = crate::units::min_f32(crate::units::max_f32(applied, 0.0), 1.0);
            *slot = (i as u16, (applied * 65535.0 + 0.5) as u16);
            self.n_overrides += 1;
        }
        let (Some(y), Some(bits)) = (self.y_mk.get_mut(i), self.high_bits.get_mut(i / 8)) else {
            return self.fail(CommissionError::Fault(FaultKind::Overridden));
        };
        *y = (mk + if mk >= 0.0 { 0.5 } else { -0.5 }) as i16;
        if !rest && self.asked_high {
            *bits |= 1 << (i % 8);
        }
        self.len += 1;
        let len = usize::from(self.len);
        if !rest {
            let d = (mk - self.y0_mk) / 1000.0;
            self.excite_ss += d * d;
        }
        if len == usize::from(self.cfg.rest_samples) {
            let tail = usize::from(self.cfg.rest_tail_samples);
            let sum: f32 = self.y_mk.get(len - tail..len).unwrap_or(&[]).iter().map(|v| f32::from(*v)).sum();
            self.y0_mk = sum / tail as f32;
            self.state = State::Excite;
        } else if len == self.cfg.record_samples() {
            let n = self.cfg.prbs_samples() as f32;
            if sqrtf(self.excite_ss / n) < self.cfg.min_response_c {
                return self.fail(CommissionError::NoExcitation);
            }
            self.state = State::Fit(FitStage::Grid(0));
        }
    }

    /// ũ of every stored sample, in order, through `f(t, ỹ, ũ)`.
    fn for_each(&self, mut f: impl FnMut(usize, f32, f32)) {
        let rest = usize::from(self.cfg.rest_samples);
        let (du_low, du_high) = (self.low - self.u0, self.high - self.u0);
        let mut next = 0usize;
        let overrides = self.overrides.get(..usize::from(self.n_overrides)).unwrap_or(&[]);
        let len = usize::from(self.len);
        for (t, y) in self.y_mk.iter().take(len).enumerate() {
            let mut du = if t < rest {
                0.0
            } else if self.high_bits.get(t / 8).is_some_and(|b| b & (1 << (t % 8)) != 0) {
                du_high
            } else {
                du_low
            };
            if let Some(&(at, d)) = overrides.get(next) {
                if usize::from(at) == t {
                    du = f32::from(d) / 65535.0 - self.u0;
                    next += 1;
                }
            }
            f(t, (f32::from(*y) - self.y0_mk) / 1000.0, du);
        }
    }

    /// One pass: every delay's B for the poles at s (module docs), under the rule `cfg.sign`
    /// and (a two-model run) the monotone rule: the sums are the same, only the cone differs.
    fn evaluate(&self, s: [f32; 2]) -> [[Candidate; MAX_DELAY]; 2] {
        let (p1, p2) = (pole(s[0]), pole(s[1]));
        let (g1, g2) = (1.0 - p1, 1.0 - p2);
        // m_i(t) = p_i m_i(t−1) + (1 − p_i) ũ(t): each mode at unit DC gain.
        let mut ring = [[0.0f32; 2]; 16];
        let mut m = [0.0f32; 2];
        let mut normal = [Normal::default(); MAX_DELAY];
        // The free response of A from the measured start of each delay's simulation: x(t) = y(t)
        // for t ≤ k, then x(t) = (p1 + p2) x(t−1) − p1 p2 x(t−2) without input: [x(t−1), x(t−2)].
        let mut free = [[0.0f32; 2]; MAX_DELAY];
        let (f1, f2) = (p1 + p2, p1 * p2);
        let mut counted = 0usize;
        self.for_each(|t, y, u| {
            m = [p1 * m[0] + g1 * u, p2 * m[1] + g2 * u];
            if let Some(r) = ring.get_mut(t & 15) {
                *r = m;
            }
            for (k, (n, fr)) in normal.iter_mut().zip(free.iter_mut()).enumerate() {
                // Delay k + 1: the host's simulation starts at t0 = k + 2.
                let f = if t <= k + 1 { y } else { f1 * fr[0] - f2 * fr[1] };
                *fr = [f, fr[0]];
                if t < T0 {
                    continue;
                }
                let e = y - f;
                let [z1, z2] = ring.get(t.wrapping_sub(k + 1) & 15).copied().unwrap_or([0.0; 2]);
                n.yy.add(e * e);
                n.s11.add(z1 * z1);
                n.s12.add(z1 * z2);
                n.s22.add(z2 * z2);
                n.c1.add(e * z1);
                n.c2.add(e * z2);
            }
            if t < T0 {
                return;
            }
            counted += 1;
            if counted.is_multiple_of(BLOCK) {
                for n in normal.iter_mut() {
                    for s in [&mut n.yy, &mut n.s11, &mut n.s12, &mut n.s22, &mut n.c1, &mut n.c2] {
                        s.flush();
                    }
                }
            }
        });
        let mut out = [[Candidate { s, ..Candidate::NONE }; MAX_DELAY]; 2];
        let [control, cabinet] = &mut out;
        let two = self.cfg.two_models();
        for (k, ((n, c), cab)) in normal.iter().zip(control.iter_mut()).zip(cabinet.iter_mut()).enumerate() {
            if self.cfg.delay.is_some_and(|d| usize::from(d) != k + 1) {
                continue;
            }
            if k < usize::from(self.max_control_k) {
                *c = candidate(n, s, k + 1, p1, p2, self.cfg.sign);
            }
            if two {
                *cab = candidate(n, s, k + 1, p1, p2, SignRule::Monotone);
            }
        }
        out
    }

    /// The candidate the fit keeps of the control model ([`preferred`]).
    fn preferred(&self) -> Candidate {
        preferred(&self.best)
    }

    /// The model of a candidate.
    fn model_of(c: &Candidate) -> Option<Model> {
        let (p1, p2) = (pole(c.s[0]), pole(c.s[1]));
        Model::second_order([-(p1 + p2), p1 * p2], c.b, usize::from(c.k)).ok()
    }

    /// The final pass: simulated fit of `m` on the record (the host's `simulate_fit`: the
    /// measured output before the first simulated sample) and the RMS of the simulation, °C.
    fn simulate(&self, m: &Model) -> (f32, f32) {
        let (a1, a2, b0, b1) = (m.a()[0], m.a()[1], m.b()[0], m.b()[1]);
        let k = m.k();
        let start = k + 1;
        let mut xr = [0.0f32; 2];
        let mut ur = [0.0f32; 16];
        let (mut sy, mut n) = (0.0f32, 0usize);
        self.for_each(|_, y, _| {
            sy += y;
            n += 1;
        });
        let mean = sy / n.max(1) as f32;
        let (mut num, mut den, mut xx) = (Sum::default(), Sum::default(), Sum::default());
        self.for_each(|t, y, u| {
            if let Some(r) = ur.get_mut(t & 15) {
                *r = u;
            }
            let x = if t < start {
                y
            } else {
                let uk = ur.get(t.wrapping_sub(k) & 15).copied().unwrap_or(0.0);
                let uk1 = ur.get(t.wrapping_sub(k + 1) & 15).copied().unwrap_or(0.0);
                -a1 * xr[0] - a2 * xr[1] + b0 * uk + b1 * uk1
            };
            xr = [x, xr[0]];
            num.add((y - x) * (y - x));
            den.add((y - mean) * (y - mean));
            xx.add(x * x);
            if (t + 1).is_multiple_of(BLOCK) {
                num.flush();
                den.flush();
                xx.flush();
            }
        });
        let fit = 100.0 * (1.0 - sqrtf(num.get() / den.get()));
        (fit, sqrtf(xx.get() / n.max(1) as f32))
    }

    /// One sample of the fit phase: exactly one pass over the record.
    fn fit_step(&mut self, stage: FitStage) {
        self.passes = self.passes.saturating_add(1);
        match stage {
            FitStage::Grid(i) => {
                // The i-th pair τ1 > τ2 of the grid, in order.
                let (mut j, mut idx) = (1usize, usize::from(i));
                while idx >= j {
                    idx -= j;
                    j += 1;
                }
                let (t1, t2) = (TAU_GRID.get(j).copied().unwrap_or(1.0), TAU_GRID.get(idx).copied().unwrap_or(1.0));
                let [control, cabinet] = self.evaluate([libm::logf(t1), libm::logf(t2)]);
                // The grid serves both models: one pass gives both cones' candidates.
                adopt(&mut self.best, &control);
                adopt(&mut self.best_cabinet, &cabinet);
                let next = usize::from(i) + 1;
                self.state = State::Fit(if next < GRID_PASSES {
                    FitStage::Grid(next as u8)
                } else {
                    Self::first_compass(false, &self.best)
                });
            }
            FitStage::Compass { cabinet, round, order, step, dir, evals } => {
                let k = order.get(usize::from(round)).copied().unwrap_or(1);
                let here = best_of(self.searched(cabinet), k);
                let d = DIRECTIONS.get(usize::from(dir)).copied().unwrap_or([0.0; 2]);
                let [control, cab] = self.evaluate(separated([here.s[0] + step * d[0], here.s[1] + step * d[1]]));
                // Each search keeps its own model's candidates only: the two searches, one after
                // the other, give exactly what a run of either rule alone gives.
                if cabinet {
                    adopt(&mut self.best_cabinet, &cab);
                } else {
                    adopt(&mut self.best, &control);
                }
                let moved = best_of(self.searched(cabinet), k).v < here.v * (1.0 - MIN_IMPROVEMENT);
                let evals = evals.saturating_add(1);
                let next = if moved {
                    // Moved: try further the same way with a longer step (expansion: the valleys
                    // are long).
                    Some((crate::units::min_f32(2.0 * step, 2.0 * FIRST_STEP), dir))
                } else if usize::from(dir) + 1 < DIRECTIONS.len() {
                    Some((step, dir + 1))
                } else if step * 0.5 >= MIN_STEP {
                    Some((step * 0.5, 0))
                } else {
                    None
                };
                let next = next.filter(|_| usize::from(evals) < MAX_SEARCH_EVALS);
                self.state = State::Fit(match next {
                    Some((step, dir)) => FitStage::Compass { cabinet, round, order, step, dir, evals },
                    None if usize::from(round) + 1 < SEARCHED_DELAYS => {
                        FitStage::Compass { cabinet, round: round + 1, order, step: FIRST_STEP, dir: 0, evals: 0 }
                    }
                    None if cabinet => FitStage::FinalCabinet,
                    None => FitStage::Final,
                });
            }
            FitStage::Final => self.finish(),
            FitStage::FinalCabinet => self.finish_cabinet(),
        }
    }

    /// The candidates a search refines.
    fn searched(&self, cabinet: bool) -> &[Candidate; MAX_DELAY] {
        if cabinet {
            &self.best_cabinet
        } else {
            &self.best
        }
    }

    fn first_compass(cabinet: bool, best: &[Candidate; MAX_DELAY]) -> FitStage {
        FitStage::Compass { cabinet, round: 0, order: delay_order(best), step: FIRST_STEP, dir: 0, evals: 0 }
    }

    /// The model of candidate `c`, its fit on the record, and whether it passes `rule`'s
    /// checks (the record moved, plausible, fit ≥ `min_fit_percent`).
    fn checked(&self, c: &Candidate, rule: SignRule) -> (Option<f32>, Result<Model, CommissionError>) {
        if c.b == [0.0, 0.0] || !c.v.is_finite() {
            return (None, Err(CommissionError::Implausible(Implausibility::Heating)));
        }
        let Some(m) = Self::model_of(c) else {
            return (None, Err(CommissionError::Implausible(Implausibility::Unstable)));
        };
        let (fit, rms) = self.simulate(&m);
        if rms < self.cfg.min_response_c {
            return (Some(fit), Err(CommissionError::NoExcitation));
        }
        let plausible = match rule {
            SignRule::EveryCoefficient if plausible_model(&self.cfg.plausible, &m) => Ok(()),
            SignRule::EveryCoefficient => Err(if !m.a_is_stable() {
                Implausibility::Unstable
            } else if m.b().iter().any(|b| *b > 0.0) {
                Implausibility::Heating
            } else {
                Implausibility::Gain
            }),
            // The slow mode cools by construction (the fit's constraint); A is stable since
            // both poles are in (0, 1); the check is the one an upload and a restore pass.
            SignRule::Monotone => cabinet_plausible(&self.cfg.plausible, &m).map_err(|e| match e {
                Implausibility::NotMonotone if m.b()[0] > 0.0 => Implausibility::Heating,
                e => e,
            }),
        };
        if let Err(why) = plausible {
            return (Some(fit), Err(CommissionError::Implausible(why)));
        }
        if !(fit >= self.cfg.min_fit_percent) {
            return (Some(fit), Err(CommissionError::PoorFit));
        }
        (Some(fit), Ok(m))
    }

    /// The control model's checks; a two-model run goes on to the cabinet model's search.
    fn finish(&mut self) {
        let (fit, m) = self.checked(&self.preferred(), self.cfg.sign);
        self.fit_percent = fit;
        match m {
            Err(e) => self.fail(e),
            // The control model is the preferred candidate's: the cabinet search leaves `best`.
            Ok(_) if self.cfg.two_models() => self.state = State::Fit(Self::first_compass(true, &self.best_cabinet)),
            Ok(m) => self.state = State::Done(m),
        }
    }

    /// The cabinet model's checks: done with both models, or failed (neither is kept).
    fn finish_cabinet(&mut self) {
        let (fit, m) = self.checked(&preferred(&self.best_cabinet), SignRule::Monotone);
        self.cabinet_fit_percent = fit;
        match (m, Self::model_of(&self.preferred())) {
            (Ok(_), Some(control)) => {
                self.cabinet_ok = true;
                self.state = State::Done(control);
            }
            (Err(e), _) => self.fail(e),
            (Ok(_), None) => self.fail(CommissionError::Implausible(Implausibility::Unstable)),
        }
    }
}

impl Controller for Commissioning {
    fn update(&mut self, _input: &ControlInput) -> Result<f32, ControlError> {
        Ok(match self.state {
            State::Excite => {
                let d = self.prbs.next_duty();
                self.asked_high = d >= self.high;
                d
            }
            State::Fit(stage) => {
                self.fit_step(stage);
                self.u0
            }
            State::Rest | State::Done(_) | State::Failed(_) => self.u0,
        })
    }

    fn track(&mut self, input: &ControlInput, applied: f32) {
        // Open loop in every phase: a load outside the band goes back to the law now (a
        // non-finite reading is the record's `OutputRange`).
        let running = matches!(self.state, State::Rest | State::Excite | State::Fit(_));
        if running && input.y_c.is_finite() && !crate::coldchain::IN_RANGE_C.contains(&input.y_c) {
            return self.fail(CommissionError::Fault(FaultKind::OutOfBand));
        }
        if matches!(self.state, State::Rest | State::Excite) {
            self.record(input.y_c, applied);
        }
    }

    fn name(&self) -> &'static str {
        "commission"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const INPUT: ControlInput = ControlInput { y_c: 4.0, w_c: 4.0 };

    /// Runs `c` on the ideal plant `m` (deviation y around 4 °C, u around u0), applying the
    /// duty as asked, until it finishes; returns the samples it took.
    fn run_on(c: &mut Commissioning, m: &Model, u0: f32) -> usize {
        run_from(c, m, u0, 4.0, |_| 0.0)
    }

    /// [`run_on`] around `base_c`, with `drift(t)` °C added to the output at sample t (an
    /// ambient change the model does not explain).
    fn run_from(c: &mut Commissioning, m: &Model, u0: f32, base_c: f32, drift: impl Fn(usize) -> f32) -> usize {
        let mut y = [0.0f32; 2];
        let mut u = [0.0f32; 16];
        for t in 0..5000usize {
            let yt = base_c + y[0] + drift(t);
            let input = ControlInput { y_c: yt, ..INPUT };
            let d = c.update(&input).unwrap();
            c.track(&input, d);
            if c.outcome().is_some() {
                return t + 1;
            }
            u[t & 15] = d - u0;
            let k = m.k();
            let uk = u[(t + 1).wrapping_sub(k) & 15];
            let uk1 = u[(t + 1).wrapping_sub(k + 1) & 15];
            let next = -m.a()[0] * y[0] - m.a()[1] * y[1] + m.b()[0] * uk + m.b()[1] * uk1;
            y = [next, y[0]];
        }
        5000
    }

    /// Poles 0.997 and 0.94, delay `k`, gain −40 °C/duty, every b ≤ 0.
    fn two_lags(k: usize) -> Model {
        let (p1, p2) = (0.997f32, 0.94f32);
        let g = (1.0 - p1) * (1.0 - p2);
        Model::second_order([-(p1 + p2), p1 * p2], [-30.0 * g, -10.0 * g], k).unwrap()
    }

    #[test]
    fn recovers_an_exact_second_order_plant() {
        // k = 5: within the control model's bound of 6 at Ts = 10 s.
        let truth = two_lags(5);
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.45).unwrap();
        let n = run_on(&mut c, &truth, 0.45);
        let m = c.outcome().unwrap().unwrap();
        assert_eq!(m.k(), 5);
        // The poles and the static gain are found; the split of B between b0 and b1 is poorly
        // determined by a PRBS held 12 samples (the host's OE tests say the same), its sum is not.
        let roots = |m: &Model| {
            let (s, p) = (-m.a()[0], m.a()[1]);
            let r = sqrtf(s * s - 4.0 * p);
            [(s + r) / 2.0, (s - r) / 2.0]
        };
        let (got, want) = (roots(&m), roots(&truth));
        assert!(
            (got[0] - want[0]).abs() < 1e-4 && (got[1] - want[1]).abs() < 2e-3,
            "{got:?} vs {want:?}, fit {:?}",
            c.fit_percent()
        );
        let (g, w) = (m.static_gain().unwrap(), truth.static_gain().unwrap());
        assert!((g - w).abs() < 0.01 * w.abs(), "gain {g} vs {w}");
        assert!(c.fit_percent().unwrap() > 99.5, "{:?}", c.fit_percent());
        let record = CommissionConfig::DEFAULT.record_samples();
        assert!(n > record && n <= record + MAX_FIT_PASSES, "{n}");
    }

    /// A plant whose delay is longer than [`MAX_CONTROL_DELAY_S`]: the control model takes the
    /// bound's delay (its poles take up the rest and it still fits), the cabinet model the
    /// plant's; asked for (`delay`), the control model has the plant's delay too; the bound is
    /// in seconds, so at Ts = 5 s it no longer binds.
    #[test]
    fn the_control_models_delay_is_bounded() {
        let truth = two_lags(9);
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.45).unwrap();
        run_on(&mut c, &truth, 0.45);
        let m = c.outcome().unwrap().unwrap();
        assert_eq!(m.k(), 6, "{m:?}");
        assert!(plausible_model(&CommissionConfig::DEFAULT.plausible, &m), "{m:?}");
        assert!(c.fit_percent().unwrap() > 95.0, "{:?}", c.fit_percent());
        assert_eq!(c.cabinet().map(|m| m.k()), Some(9));
        let asked = CommissionConfig { delay: Some(9), cabinet: false, ..CommissionConfig::DEFAULT };
        let mut c = Commissioning::new(asked, 10.0, 0.45).unwrap();
        run_on(&mut c, &truth, 0.45);
        assert_eq!(c.outcome().unwrap().unwrap().k(), 9);
        // Ts = 5 s: the bound is 12 samples, all the scan (the delay the fit keeps there is its
        // own choice, 8 or 9 as its search goes).
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 5.0, 0.45).unwrap();
        run_on(&mut c, &truth, 0.45);
        assert!(c.outcome().unwrap().unwrap().k() > 6, "{:?}", c.outcome());
    }

    #[test]
    fn recovers_two_parallel_lags_under_the_monotone_rule() {
        // H-TER I's output-error model: two cooling lags in parallel, b1 > 0.
        let truth = Model::second_order([-1.939_966, 0.940_146], [-0.279_127, 0.271_187], 9).unwrap();
        let cfg = CommissionConfig { sign: SignRule::Monotone, ..CommissionConfig::DEFAULT };
        let mut c = Commissioning::new(cfg, 10.0, 0.45).unwrap();
        run_on(&mut c, &truth, 0.45);
        let m = c.outcome().unwrap().unwrap();
        assert_eq!(m.k(), 9);
        assert!(c.fit_percent().unwrap() > 99.0, "{:?}", c.fit_percent());
    }

    #[test]
    fn phases_progress_and_abort() {
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.4).unwrap();
        assert_eq!(c.phase(), Phase::Rest { percent: 0 });
        for _ in 0..30 {
            let d = c.update(&INPUT).unwrap();
            assert_eq!(d, 0.4);
            c.track(&INPUT, d);
        }
        assert_eq!(c.phase(), Phase::Rest { percent: 50 });
        for _ in 0..30 {
            let d = c.update(&INPUT).unwrap();
            c.track(&INPUT, d);
        }
        assert_eq!(c.phase().name(), "excite");
        let d = c.update(&INPUT).unwrap();
        assert!(d == 0.5 || (d - 0.3).abs() < 1e-6, "{d}");
        c.abort_on_mode(Mode::Normal);
        assert!(c.outcome().is_none());
        c.abort_on_mode(Mode::FreezeGuard);
        assert_eq!(c.outcome(), Some(Err(CommissionError::Fault(FaultKind::FreezeGuard))));
        c.abort(CommissionError::Aborted);
        assert_eq!(c.phase(), Phase::Failed(CommissionError::Fault(FaultKind::FreezeGuard)));
        assert_eq!(c.update(&INPUT), Ok(0.4));
    }

    /// The run drives the duty open loop: a load it takes out of 2…8 °C ends it on that
    /// sample, in the excitation (a start near an edge: from 2.5 °C the PRBS took H-TER I's
    /// full load to 1.64 °C, 19 minutes below 2 °C until the freeze guard tripped; from 7.5 °C to
    /// 9.2 °C for 1.5 h, and the run ended `done`) and in the fit's hold (an ambient rise).
    #[test]
    fn a_load_leaving_the_band_ends_the_run_in_any_phase() {
        let truth = two_lags(5);
        let out_of_band = Some(Err(CommissionError::Fault(FaultKind::OutOfBand)));
        for base in [2.5f32, 7.5] {
            let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.45).unwrap();
            let n = run_from(&mut c, &truth, 0.45, base, |_| 0.0);
            assert_eq!(c.outcome(), out_of_band, "from {base} °C");
            assert!(n < CommissionConfig::DEFAULT.record_samples(), "{n}");
        }
        // The record is fine; the load warms past 8 °C while the fit holds u0.
        let record = CommissionConfig::DEFAULT.record_samples();
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.45).unwrap();
        let n = run_from(&mut c, &truth, 0.45, 4.0, |t| if t > record + 20 { 5.0 } else { 0.0 });
        assert_eq!(c.outcome(), out_of_band);
        assert_eq!(n, record + 22);
    }

    #[test]
    fn a_flat_output_is_no_excitation() {
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.4).unwrap();
        for _ in 0..CommissionConfig::DEFAULT.record_samples() {
            let d = c.update(&INPUT).unwrap();
            c.track(&INPUT, d);
        }
        assert_eq!(c.outcome(), Some(Err(CommissionError::NoExcitation)));
    }

    #[test]
    fn too_many_overrides_spoil_the_record() {
        let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.4).unwrap();
        for _ in 0..=MAX_OVERRIDES {
            let _ = c.update(&INPUT);
            c.track(&INPUT, 0.0);
        }
        assert_eq!(c.outcome(), Some(Err(CommissionError::Fault(FaultKind::Overridden))));
    }

    #[test]
    fn configurations_are_checked() {
        let d = CommissionConfig::DEFAULT;
        assert_eq!(d.validate(), Ok(()));
        assert_eq!(d.record_samples(), 1584);
        let cases = [
            (CommissionConfig { rest_samples: 5, ..d }, ConfigProblem::Rest),
            (CommissionConfig { rest_tail_samples: 0, ..d }, ConfigProblem::Rest),
            (CommissionConfig { rest_tail_samples: 61, ..d }, ConfigProblem::Rest),
            (CommissionConfig { prbs_bits: 2, ..d }, ConfigProblem::Prbs),
            (CommissionConfig { prbs_hold: 0, ..d }, ConfigProblem::Prbs),
            (CommissionConfig { amplitude: f32::NAN, ..d }, ConfigProblem::Amplitude),
            (CommissionConfig { amplitude: 0.0, ..d }, ConfigProblem::Amplitude),
            (CommissionConfig { prbs_bits: 8, ..d }, ConfigProblem::Capacity),
            (CommissionConfig { min_fit_percent: 100.0, ..d }, ConfigProblem::Threshold),
            (CommissionConfig { min_response_c: 0.0, ..d }, ConfigProblem::Threshold),
            (CommissionConfig { delay: Some(0), ..d }, ConfigProblem::Delay),
            (CommissionConfig { delay: Some(11), ..d }, ConfigProblem::Delay),
        ];
        for (cfg, want) in cases {
            assert_eq!(cfg.validate(), Err(CommissionError::Config(want)), "{cfg:?}");
            assert!(Commissioning::new(cfg, 10.0, 0.4).is_err());
        }
        let mut bad_gain = d;
        bad_gain.plausible.gain_max_c_per_duty = 5.0;
        assert_eq!(bad_gain.validate(), Err(CommissionError::Config(ConfigProblem::Plausibility)));
        assert_eq!(Commissioning::new(d, 10.0, 1.5).err(), Some(CommissionError::Config(ConfigProblem::RestDuty)));
        assert_eq!(
            Commissioning::new(d, f32::NAN, 0.5).err(),
            Some(CommissionError::Config(ConfigProblem::SamplePeriod))
        );
        let e = CommissionError::Config(ConfigProblem::Capacity);
        assert_eq!(e.name(), "config_capacity");
        assert!(!std::format!("{e}").contains('\n'));
    }

    #[test]
    fn size_is_as_documented() {
        assert_eq!(core::mem::size_of::<Commissioning>(), 4296);
    }

    #[test]
    fn one_run_gives_the_control_and_the_cabinet_model() {
        // H-TER I's output-error model (b1 > 0) as the plant: the cabinet model recovers it, the
        // control model is the best every-b_i ≤ 0 model of the same record, as a run of that
        // rule alone gives it.
        let truth = Model::second_order([-1.939_966, 0.940_146], [-0.279_127, 0.271_187], 9).unwrap();
        let mut both = Commissioning::new(CommissionConfig::DEFAULT, 10.0, 0.45).unwrap();
        let n_both = run_on(&mut both, &truth, 0.45);
        let control = both.outcome().unwrap().unwrap();
        let cabinet = both.cabinet().unwrap();
        assert!(plausible_model(&CommissionConfig::DEFAULT.plausible, &control), "{control:?}");
        assert!(cabinet.b()[1] > 0.0 && cabinet.k() == 9, "{cabinet:?}");
        assert!(both.cabinet_fit_percent().unwrap() > 99.0, "{:?}", both.cabinet_fit_percent());
        assert_eq!(cabinet_plausible(&CommissionConfig::DEFAULT.plausible, &cabinet), Ok(()));
        let alone_cfg = CommissionConfig { cabinet: false, ..CommissionConfig::DEFAULT };
        let mut alone = Commissioning::new(alone_cfg, 10.0, 0.45).unwrap();
        let n_alone = run_on(&mut alone, &truth, 0.45);
        assert_eq!(alone.outcome(), both.outcome());
        assert_eq!(alone.cabinet(), None);
        let mono_cfg = CommissionConfig { sign: SignRule::Monotone, cabinet: false, ..CommissionConfig::DEFAULT };
        let mut mono = Commissioning::new(mono_cfg, 10.0, 0.45).unwrap();
        let n_mono = run_on(&mut mono, &truth, 0.45);
        assert_eq!(mono.outcome(), Some(Ok(cabinet)));
        // The grid is shared: the two-model run costs the cabinet search and its simulation.
        let record = CommissionConfig::DEFAULT.record_samples();
        assert_eq!(
            n_both - record,
            (n_alone - record) + (n_mono - record) - GRID_PASSES,
            "{n_both} {n_alone} {n_mono}"
        );
        assert!(n_both - record <= CommissionConfig::DEFAULT.max_fit_passes());
    }

    #[test]
    fn the_cabinet_check_wants_two_real_lags_and_a_monotone_cooling() {
        let cfg = CommissionConfig::DEFAULT.plausible;
        let m = |a: [f32; 2], b: [f32; 2]| Model::second_order(a, b, 5).unwrap();
        // Two lags 0.997 and 0.94 with a gain of −40 °C/duty, every b ≤ 0 or b1 > 0.
        let (p1, p2) = (0.997f32, 0.94f32);
        let (a, g) = ([-(p1 + p2), p1 * p2], (1.0 - p1) * (1.0 - p2));
        assert_eq!(cabinet_plausible(&cfg, &m(a, [-30.0 * g, -10.0 * g])), Ok(()));
        assert_eq!(cabinet_plausible(&cfg, &m([-1.939_966, 0.940_146], [-0.279_127, 0.271_187])), Ok(()));
        // A heating slow lag: b0·p1 + b1 > 0 (the step response turns back up).
        assert_eq!(cabinet_plausible(&cfg, &m(a, [-0.02, 0.0201])), Err(Implausibility::NotMonotone), "slow lag heats");
        assert_eq!(cabinet_plausible(&cfg, &m(a, [0.001, -0.0024])), Err(Implausibility::NotMonotone));
        // Complex poles (an oscillating step response) and an unstable A.
        assert_eq!(cabinet_plausible(&cfg, &m([-1.8, 0.95], [-0.01, -0.01])), Err(Implausibility::NotMonotone));
        assert_eq!(cabinet_plausible(&cfg, &m([1.2, 0.1], [-0.02, -0.01])), Err(Implausibility::Unstable));
        // The gain range.
        assert_eq!(cabinet_plausible(&cfg, &m(a, [-0.000_001, 0.0])), Err(Implausibility::Gain));
    }
}
