//! Host side of hter: a physical plant model in f64, simulated peripherals with fault
//! injection, scenarios, metrics, plots and the `hter` command line.
#![warn(missing_docs)]

pub mod arx;
pub mod metrics;
pub mod plant;
pub mod plot;
