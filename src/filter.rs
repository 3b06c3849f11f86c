//! First-order low-pass filter with parameter F_a:
//!
//! ```text
//! y_f(t) = F_a · y_f(t − 1) + (1 − F_a) · y(t),     0 ≤ F_a < 1
//! ```
//!
//! F_a = 0 passes the signal unchanged. The equivalent time constant is
//! τ = −Ts / ln(F_a); with the default Ts = 10 s and F_a = 0.5 that is 14.4 s, short against the
//! plant's tens of minutes but enough to take the ADC noise out of the controller's input.
//! The first sample initialises the state, so there is no start-up transient from zero.

/// Filter configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FirstOrderConfig {
    /// Pole F_a of the filter, in [0, 1).
    pub fa: f32,
}

impl FirstOrderConfig {
    /// Checked constructor: `None` unless `fa` is finite and in [0, 1).
    pub fn new(fa: f32) -> Option<Self> {
        (fa.is_finite() && (0.0..1.0).contains(&fa)).then_some(Self { fa })
    }
}

/// Filter state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FirstOrder {
    y: Option<f32>,
}

impl FirstOrder {
    /// Filters one sample. Non-finite samples are not absorbed into the state: the previous
    /// output is returned (or the sample itself if there is none), so one bad reading cannot
    /// poison the filter forever.
    pub fn step(&mut self, cfg: &FirstOrderConfig, x: f32) -> f32 {
        if !x.is_finite() {
            return self.y.unwrap_or(x);
        }
        let y = match self.y {
            Some(prev) => cfg.fa * prev + (1.0 - cfg.fa) * x,
            None => x,
        };
        self.y = Some(y);
        y
    }

    /// The last output, if any.
    pub fn output(&self) -> Option<f32> {
        self.y
    }

    /// Carries the state onto another scale of the input, `f` a straight line (a new
    /// calibration of the channel, [`crate::calib::Recalibration`]): a straight line commutes
    /// with the filter, whose weights sum to one, so the output is what the filter would hold
    /// had the input always been on the new scale — no transient, where restarting would lose
    /// the smoothing and slewing into the new value would read as motion.
    pub fn remap(&mut self, f: impl FnOnce(f32) -> f32) {
        self.y = self.y.map(f);
    }

    /// Forgets the state; the next sample re-initialises it.
    pub fn reset(&mut self) {
        self.y = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_response_is_geometric() {
        let cfg = FirstOrderConfig::new(0.5).unwrap();
        let mut f = FirstOrder::default();
        assert_eq!(f.step(&cfg, 0.0), 0.0);
        assert_eq!(f.step(&cfg, 1.0), 0.5);
        assert_eq!(f.step(&cfg, 1.0), 0.75);
        assert_eq!(f.step(&cfg, 1.0), 0.875);
    }

    #[test]
    fn zero_fa_passes_through_and_nan_is_not_absorbed() {
        let cfg = FirstOrderConfig::new(0.0).unwrap();
        let mut f = FirstOrder::default();
        assert_eq!(f.step(&cfg, 3.0), 3.0);
        assert_eq!(f.step(&cfg, f32::NAN), 3.0);
        assert_eq!(f.step(&cfg, 4.0), 4.0);
        assert!(FirstOrderConfig::new(1.0).is_none());
        assert!(FirstOrderConfig::new(-0.1).is_none());
    }
}
