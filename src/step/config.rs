//! The step's configuration and the checks it must pass before a [`Carrier`](super::Carrier)
//! runs on it.

use crate::adc::AdcFrontEnd;
use crate::calib::TwoPoint;
use crate::filter::FirstOrderConfig;
use crate::rtd::Rtd;
use crate::supervisor::{SupervisorConfig, WindowError};
use crate::units::{max_f32, min_f32};

/// Setpoint used when the requested one is not a number, °C (before clamping): the middle of
/// the lower half of 2–8 °C.
const FALLBACK_SETPOINT_C: f32 = 4.0;

/// Everything the step needs to know that does not change while it runs.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarrierConfig {
    /// Sample period, s (see the module docs for the choice of 10 s).
    pub ts_s: f32,
    /// ADC front end of the RTD channel.
    pub adc: AdcFrontEnd,
    /// The RTD (Pt100 on the reference board).
    pub rtd: Rtd,
    /// Two-point calibration of the channel.
    pub cal: TwoPoint,
    /// Measurement filter.
    pub filter: FirstOrderConfig,
    /// Readings below this are implausible for a vaccine carrier (sensor fault), °C.
    pub plausible_min_c: f32,
    /// Readings above this are implausible for a vaccine carrier (sensor fault), °C.
    pub plausible_max_c: f32,
    /// Lowest setpoint accepted, °C (vaccines freeze below).
    pub setpoint_min_c: f32,
    /// Highest setpoint accepted, °C.
    pub setpoint_max_c: f32,
    /// The safety supervisor's detectors.
    pub supervisor: SupervisorConfig,
}

impl CarrierConfig {
    /// Defaults for the reference board: Pt100 on the default front end, Ts = 10 s, F_a = 0.5.
    pub const DEFAULT: CarrierConfig = CarrierConfig {
        ts_s: 10.0,
        adc: AdcFrontEnd::DEFAULT,
        rtd: Rtd::PT100,
        cal: TwoPoint::IDENTITY,
        filter: FirstOrderConfig { fa: 0.5 },
        // The carrier lives between a freezer pack (−25 °C) and a car in the sun (+70 °C).
        plausible_min_c: -30.0,
        plausible_max_c: 75.0,
        setpoint_min_c: 2.0,
        setpoint_max_c: 8.0,
        supervisor: SupervisorConfig::DEFAULT,
    };
}

/// Why a [`CarrierConfig`] is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The sample period is not a finite number of seconds in (0, 3600].
    SamplePeriod,
    /// The measurement filter's pole is outside [0, 1).
    Filter,
    /// The setpoint range is not an ordered range of finite temperatures inside the plausible
    /// readings.
    Setpoints,
    /// A supervisor duration or window its detector cannot honour at the sample period (the
    /// field's path in [`SupervisorConfig`]).
    Window(&'static str),
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::SamplePeriod => f.write_str("the sample period must be a finite number of seconds in (0, 3600]"),
            ConfigError::Filter => f.write_str("the measurement filter's pole must be in [0, 1)"),
            ConfigError::Setpoints => {
                f.write_str("the setpoint range must be ordered and lie inside the plausible readings")
            }
            ConfigError::Window(field) => write!(
                f,
                "supervisor.{field} does not fit its detector at this sample period (a window the SSR monitor looks back over must be 1 to {} samples)",
                crate::supervisor::ssr::HISTORY - 1
            ),
        }
    }
}

impl CarrierConfig {
    /// The setpoint the step runs on when `setpoint_c` is asked for: clamped to the accepted
    /// range, 4 °C (clamped) for one that is not a number. The step and the board's `status`
    /// both use it, so `status` shows what the next sample will run on.
    pub fn setpoint_in_force(&self, setpoint_c: f32) -> f32 {
        let (lo, hi) = (self.setpoint_min_c, self.setpoint_max_c);
        // Not `f32::clamp`: it panics when min > max, and a panic path costs the firmware
        // ~15 KiB of formatting code. Not `f32::max`/`min` either: calls on the M4F.
        if setpoint_c.is_finite() {
            min_f32(max_f32(setpoint_c, lo), hi)
        } else {
            min_f32(max_f32(lo, FALLBACK_SETPOINT_C), hi)
        }
    }

    /// Checks what the step relies on: a sample period, a stable filter, a setpoint range the
    /// plausibility check does not cut into, and supervisor windows that fit their counters
    /// ([`SupervisorConfig::validate`]).
    pub const fn validate(&self) -> Result<(), ConfigError> {
        if !(self.ts_s.is_finite() && self.ts_s > 0.0 && self.ts_s <= 3600.0) {
            return Err(ConfigError::SamplePeriod);
        }
        let fa = self.filter.fa;
        if !(fa.is_finite() && fa >= 0.0 && fa < 1.0) {
            return Err(ConfigError::Filter);
        }
        let ordered = self.plausible_min_c < self.setpoint_min_c
            && self.setpoint_min_c < self.setpoint_max_c
            && self.setpoint_max_c < self.plausible_max_c;
        // NaN compares false: an ordered range is a finite one.
        if !ordered || !self.plausible_min_c.is_finite() || !self.plausible_max_c.is_finite() {
            return Err(ConfigError::Setpoints);
        }
        match self.supervisor.validate(self.ts_s) {
            Ok(()) => Ok(()),
            Err(WindowError(field)) => Err(ConfigError::Window(field)),
        }
    }

    /// This configuration, checked ([`Self::validate`]): what [`Carrier::new`](super::Carrier::new)
    /// takes.
    pub const fn validated(self) -> Result<ValidConfig, ConfigError> {
        match self.validate() {
            Ok(()) => Ok(ValidConfig(self)),
            Err(e) => Err(e),
        }
    }
}

/// A [`CarrierConfig`] that passed [`CarrierConfig::validate`]: the only kind a
/// [`Carrier`](super::Carrier) runs on. A constant one is checked by the compiler
/// (`match CFG.validated() { Ok(v) => v, Err(_) => panic!(..) }` in a `const`), so the board
/// carries no check and no error path for it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ValidConfig(CarrierConfig);

impl ValidConfig {
    /// The reference board's defaults, [`CarrierConfig::DEFAULT`].
    pub const DEFAULT: ValidConfig = match CarrierConfig::DEFAULT.validated() {
        Ok(v) => v,
        Err(_) => panic!("CarrierConfig::DEFAULT is refused by its own validation"),
    };

    /// The configuration.
    pub const fn get(&self) -> &CarrierConfig {
        &self.0
    }

    /// The same configuration with the channel's calibration `cal` (validation does not read
    /// the calibration: a [`TwoPoint`] is checked when it is built or loaded).
    pub const fn with_calibration(self, cal: TwoPoint) -> ValidConfig {
        ValidConfig(CarrierConfig { cal, ..self.0 })
    }
}
