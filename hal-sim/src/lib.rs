//! Host side of hter: a physical plant model in f64, simulated peripherals with fault
//! injection, scenarios, metrics, plots and the `hter` command line.
#![warn(missing_docs)]

pub mod arx;
pub mod board_cmd;
pub mod bound;
pub mod campaign_cmd;
pub mod commission;
pub mod compare_cmd;
pub mod demo_cmd;
pub mod fault;
pub mod flash;
pub mod identify_cmd;
pub mod link;
pub mod log;
pub mod log2csv_cmd;
pub mod metrics;
pub mod mission;
pub mod monitor_cmd;
pub mod output;
pub mod periph;
pub mod plant;
pub mod plot;
pub mod report_cmd;
pub mod rtd_cmd;
pub mod scenario;
pub mod sim;
pub mod sim_cmd;
pub mod virtual_board_cmd;
