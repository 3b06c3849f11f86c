//! Build-time configuration: every tunable of the firmware, with its unit and source.
//! Changing the carrier's behaviour means changing this file and reflashing.

use hter::control::{AnyController, Pi, PiConfig};
use hter::step::CarrierConfig;

/// Setpoint of the vaccine load, °C: the middle of the lower half of 2–8 °C, where the seed ran
/// its experiments (4 °C) and as far from freezing as from the 8 °C limit allows with margin.
pub const SETPOINT_C: f32 = 4.0;

/// The step's configuration (Ts = 10 s, Pt100 on the default front end, F_a = 0.5, freeze
/// guard at 1.5 °C with a 120 s look-ahead): see `hter::step::CarrierConfig::DEFAULT`.
pub const CARRIER: CarrierConfig = CarrierConfig::DEFAULT;

/// SSR PWM frequency, Hz: a 1 s period, as the simulator models it (the seed's DAQ drove the
/// SSR with a slow PWM; at 1 Hz the DC SSR's 100 µs switching time costs < 0.02 % of duty).
pub const SSR_PWM_HZ: u32 = 1;

/// Independent watchdog timeout, µs: three sample periods. The control task feeds it only after
/// a completed step, so a hung loop resets the MCU (and the pull-down on the supply-enable line
/// removes power from the modules meanwhile).
pub const WATCHDOG_TIMEOUT_US: u32 = 30_000_000;

/// The controller: PI (Ziegler–Nichols, detuned; `PiConfig::HTER1_DEFAULT`).
pub fn controller() -> AnyController {
    AnyController::Pi(Pi::new(PiConfig { ts_s: CARRIER.ts_s, ..PiConfig::HTER1_DEFAULT }))
}
