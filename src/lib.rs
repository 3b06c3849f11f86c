//! # hter — adaptive firmware core for a thermoelectric vaccine carrier
//!
//! Everything that is math and no hardware: the RTD measurement chain, filtering,
//! black-box identification, the controllers, and the one per-sample step object
//! ([`step::Carrier`]) that the firmware and the host simulator both drive.
//!
//! The crate is `no_std`, allocation-free and works in `f32` with fixed sizes, so
//! exactly the same code runs on the STM32L476 and in `hal-sim`.
//!
//! Layout:
//! - [`units`]: `Celsius`, `Ohms`, `Duty` newtypes for values that cross modules.
//! - [`rtd`], [`adc`], [`calib`], [`filter`]: counts → ohms → °C → calibrated → filtered.
//! - [`model`]: the one ARX/CARIMA [`model::Model`] that identification estimates and the
//!   model-based laws are designed from.
//! - [`control`]: the [`control::Controller`] trait, the baseline controllers, the model-based
//!   laws and the self-tuner.
//! - [`profile`]: the board's tuning of those controllers and its save cadences, written once
//!   for the firmware, the processor-in-the-loop runner and the simulator.
//! - [`ident`]: ARX/ARMAX structures, LS/RLS/RELS estimators, PRBS, validation.
//! - [`event`]: timestamped events the step reports (sensor faults, guard actions, mode changes).
//! - [`failsafe`]: the safe-outputs seam and the reset-surviving stop records (the fail-loud
//!   alarm's heartbeat is the firmware's `board::heartbeat_pulse`, simulated by `hal-sim`).
//! - [`hal`]: the small hardware seams the firmware and `hal-sim` implement.
//! - [`step`]: the per-sample application step: convert, check, control, guard, actuate.
//! - [`supervisor`]: the safety supervisor the step runs: its mode, and one detector per file
//!   (sensor checks, freeze guard, SSR monitor and limp home, supply sag, supply switch, lid).
//! - [`coldchain`]: WHO-style alarms, mean kinetic temperature, excursions; [`alarm`]: the
//!   board's alarm indicator.
//! - [`persist`]: versioned, CRC-checked records of what survives a power cycle (model, calibration,
//!   history); with feature `persist-flash`, their storage in flash.
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it is also true for NaN, which is
// exactly the case a numerical guard must catch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Index loops mirror the textbook sums (Σ_i a_i y(t−i)) they implement.
#![allow(clippy::needless_range_loop)]

// A `String` is an interface sink on the host (`iface::sink`).
#[cfg(any(test, feature = "alloc"))]
extern crate alloc;

pub mod adc;
pub mod alarm;
pub mod app;
pub mod calib;
pub mod coldchain;
pub mod control;
pub mod event;
pub mod failsafe;
pub mod filter;
pub mod hal;
pub mod holdover;
pub mod ident;
pub mod iface;
pub mod model;
pub(crate) mod numerics;
pub mod persist;
pub mod profile;
pub mod rtd;
pub mod step;
pub mod supervisor;
pub mod units;
