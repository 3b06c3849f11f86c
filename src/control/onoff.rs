//! On-Off control with hysteresis: full cooling above `w + h`, none below `w − h`,
//! unchanged in between. The hysteresis keeps the SSR and the Peltier modules from chattering
//! on sensor noise.

use super::{ControlError, ControlInput, Controller};

/// On-Off configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OnOffConfig {
    /// Half-width of the hysteresis band, °C. Default 0.3 °C: far wider than the filtered
    /// noise (≈ 0.01 °C), and narrow enough that the ≈ 1 °C the load coasts on after full
    /// cooling stops still stays above 2 °C at a 3 °C setpoint (±0.5 °C went to 1.8 °C on the
    /// hal-sim plant).
    pub hysteresis_c: f32,
}

impl OnOffConfig {
    /// Default band ±0.5 °C.
    pub const DEFAULT: OnOffConfig = OnOffConfig { hysteresis_c: 0.3 };
}

/// On-Off state.
#[derive(Clone, Debug)]
pub struct OnOff {
    cfg: OnOffConfig,
    on: bool,
}

impl OnOff {
    /// A controller that starts with cooling off.
    pub fn new(cfg: OnOffConfig) -> Self {
        Self { cfg, on: false }
    }
}

impl Controller for OnOff {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        let e = input.y_c - input.w_c;
        if e > self.cfg.hysteresis_c {
            self.on = true;
        } else if e < -self.cfg.hysteresis_c {
            self.on = false;
        }
        Ok(if self.on { 1.0 } else { 0.0 })
    }

    fn track(&mut self, _input: &ControlInput, applied: f32) {
        // If the supervisor forced cooling off, start from "off" when it lets go.
        if applied < 0.5 {
            self.on = false;
        }
    }

    fn name(&self) -> &'static str {
        "onoff"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_only_outside_the_band() {
        let mut c = OnOff::new(OnOffConfig::DEFAULT);
        let at = |y| ControlInput { y_c: y, w_c: 4.0 };
        assert_eq!(c.update(&at(4.29)), Ok(0.0));
        assert_eq!(c.update(&at(4.31)), Ok(1.0));
        assert_eq!(c.update(&at(4.0)), Ok(1.0));
        assert_eq!(c.update(&at(3.71)), Ok(1.0));
        assert_eq!(c.update(&at(3.69)), Ok(0.0));
        assert_eq!(c.update(&at(4.29)), Ok(0.0));
    }
}
