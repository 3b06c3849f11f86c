//! Freeze guard: cut cooling before the load reaches 0 °C.
//!
//! The guard acts on the filtered temperature extrapolated along its smoothed downward slope:
//!
//! ```text
//! s(k) = m·s(k−1) + (1 − m)·(y(k) − y(k−1))/Ts        (m = slope_smoothing)
//! ŷ(k) = y(k) + min(s(k), 0)·T_la                     (T_la = lookahead_s)
//! trip:    ŷ(k) ≤ cut_c
//! release: y(k) ≥ release_c and ŷ(k) > cut_c
//! ```
//!
//! Cut at full cooling, the cold side (≈ −10 °C) keeps pulling the load down for minutes and the
//! sensor lags the load by ≈ 50 s, so a guard on the present reading alone lets the load coast
//! ≈ 1 °C past it. Whether the guard holds is the supervisor's mode
//! ([`super::Hold::FreezeGuard`]); this type keeps the slope and answers the two questions.

/// Settings of the freeze guard.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FreezeConfig {
    /// Cooling is cut when the predicted load is at or below this, °C. 1.5 °C leaves 0.5 °C of
    /// margin to the +1 °C freezing limit of the vaccines for the sensor lag.
    pub cut_c: f32,
    /// Cooling may resume once the measured load is at or above this, °C.
    pub release_c: f32,
    /// Look-ahead, s: how far along its current downward slope the load is extrapolated. 120 s
    /// covers the coast after full cooling stops seen through the ≈ 50 s sensor lag (measured
    /// on the hal-sim plant with On-Off at a 3 °C setpoint).
    pub lookahead_s: f32,
    /// Weight of the previous slope in the smoothed one (0.7: smoothed over ≈ 3 samples, so one
    /// noisy reading cannot trip the guard).
    pub slope_smoothing: f32,
    /// In normal control with the load below this, °C, nothing asked of the drive and the load
    /// standing still ([`Self::idle_slope_c_per_s`]), the supply switch opens as well: nothing
    /// may cool a load a cold ambient holds below the 2 °C floor, and an SSR that shorts then
    /// cannot take it down before the guard has seen the fall. A light load at 1.7 °C in a
    /// 1.6 °C ambient fell 1.8 °C in the 50 s the guard needed to trip on a short (`hter
    /// campaign` mission 41783: −0.09 °C). It costs nothing: no cooling was asked. 2.5 °C, the
    /// guard's release level, not the 2 °C floor: a light load a 1.2 °C ambient held at 2.05 °C
    /// fell 1.5 °C in the 60 s before the guard tripped on a short, and coasted to −0.2 °C
    /// (mission 110774, `--seed 110001`).
    pub idle_open_c: f32,
    /// …with the freeze guard's smoothed slope at or above this, °C/s (−0.06 °C/min, a third
    /// of the SSR checks' "falling fast"). A load falling with nothing asked is left to the guard
    /// and the SSR checks, which need to see it fall: opening on a heavy load that a short took
    /// down at −0.12 °C/min hid the short for the rest of the day (mission 47432: the switch
    /// cycling it around 2 °C, never reported).
    pub idle_slope_c_per_s: f32,
}

impl FreezeConfig {
    /// The reference board's settings.
    pub const DEFAULT: FreezeConfig = FreezeConfig {
        cut_c: 1.5,
        release_c: 2.5,
        lookahead_s: 120.0,
        slope_smoothing: 0.7,
        idle_open_c: 2.5,
        idle_slope_c_per_s: -0.001,
    };
}

/// This sample's movement of the filtered temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Trend {
    /// The fall over the last sample, °C (positive falling; 0 without a previous sample).
    pub(crate) drop_c: f32,
    /// The smoothed slope, °C/s.
    pub(crate) slope_c_per_s: f32,
    /// The temperature extrapolated `lookahead_s` along a falling slope, °C.
    pub(crate) predicted_c: f32,
}

/// The freeze guard's slope estimate.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FreezeGuard {
    /// 1 − `slope_smoothing`: the weight of this sample's slope.
    gain: f32,
    last_temp_c: Option<f32>,
    slope_c_per_s: f32,
}

impl FreezeGuard {
    pub(crate) fn new(cfg: &FreezeConfig) -> Self {
        FreezeGuard { gain: 1.0 - cfg.slope_smoothing, last_temp_c: None, slope_c_per_s: 0.0 }
    }

    /// The smoothed slope, °C/s.
    pub(crate) fn slope_c_per_s(&self) -> f32 {
        self.slope_c_per_s
    }

    /// Forgets the history (the filter restarted after a sensor fault).
    pub(crate) fn restart(&mut self) {
        self.last_temp_c = None;
        self.slope_c_per_s = 0.0;
    }

    /// The channel's calibration changed by `r`: the last temperature and the slope as the new
    /// line reads them, so that the next sample's is no fall or rise of the load.
    pub(crate) fn recalibrated(&mut self, r: &crate::calib::Recalibration) {
        self.last_temp_c = self.last_temp_c.map(|t| r.level(t));
        self.slope_c_per_s = r.difference(self.slope_c_per_s);
    }

    /// Takes this sample's filtered temperature (`ts_s`: the sample period, s).
    pub(crate) fn observe(&mut self, cfg: &FreezeConfig, ts_s: f32, temp_c: f32) -> Trend {
        let mut drop_c = 0.0;
        if let Some(prev) = self.last_temp_c.filter(|p| p.is_finite()) {
            drop_c = prev - temp_c;
            let raw_slope = (temp_c - prev) / ts_s;
            if raw_slope.is_finite() {
                self.slope_c_per_s = cfg.slope_smoothing * self.slope_c_per_s + self.gain * raw_slope;
            }
        }
        self.last_temp_c = Some(temp_c);
        Trend { drop_c, slope_c_per_s: self.slope_c_per_s, predicted_c: self.predicted_c(cfg, temp_c) }
    }

    /// `temp_c` extrapolated `lookahead_s` along the smoothed slope when it falls, °C: what the
    /// guard judges, and limp home's thermostat reads ([`super::ssr::LimpConfig`]).
    pub(crate) fn predicted_c(&self, cfg: &FreezeConfig, temp_c: f32) -> f32 {
        temp_c + crate::units::min_f32(self.slope_c_per_s, 0.0) * cfg.lookahead_s
    }

    /// Whether the guard trips on `trend`.
    pub(crate) fn trips(cfg: &FreezeConfig, trend: &Trend) -> bool {
        trend.predicted_c <= cfg.cut_c
    }

    /// Whether a tripped guard releases at `temp_c` on `trend` (never on a sample that trips).
    pub(crate) fn releases(cfg: &FreezeConfig, temp_c: f32, trend: &Trend) -> bool {
        temp_c >= cfg.release_c && trend.predicted_c > cfg.cut_c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CFG: FreezeConfig = FreezeConfig::DEFAULT;

    fn guard() -> FreezeGuard {
        FreezeGuard::new(&CFG)
    }

    #[test]
    fn the_smoothing_gain_is_the_literal_it_replaces() {
        // `1 − 0.7` in f32 is bit for bit the 0.3 the slope was smoothed with.
        assert_eq!(guard().gain.to_bits(), 0.3f32.to_bits());
    }

    #[test]
    fn a_steady_load_trips_at_the_cut_and_releases_at_the_release() {
        let mut g = guard();
        let t = g.observe(&CFG, 10.0, 1.51);
        assert!(!FreezeGuard::trips(&CFG, &t));
        let t = g.observe(&CFG, 10.0, 1.51);
        assert_eq!((t.drop_c, t.slope_c_per_s), (0.0, 0.0));
        assert!(!FreezeGuard::trips(&CFG, &t));
        let mut g = guard();
        let t = g.observe(&CFG, 10.0, 1.5);
        assert!(FreezeGuard::trips(&CFG, &t), "at the cut");
        let mut g = guard();
        let t = g.observe(&CFG, 10.0, 2.49);
        assert!(!FreezeGuard::releases(&CFG, 2.49, &t));
        let mut g = guard();
        let t = g.observe(&CFG, 10.0, 2.5);
        assert!(FreezeGuard::releases(&CFG, 2.5, &t));
    }

    #[test]
    fn it_trips_on_the_look_ahead_of_a_falling_load() {
        // Falling 0.6 °C/min: the smoothed slope approaches −0.01 °C/s, so the prediction runs
        // ≈ 1.2 °C below the reading.
        let mut g = guard();
        let mut temp = 5.0f32;
        let mut tripped = None;
        for _ in 0..40 {
            let t = g.observe(&CFG, 10.0, temp);
            if FreezeGuard::trips(&CFG, &t) {
                tripped = Some((temp, t.predicted_c));
                break;
            }
            temp -= 0.1;
        }
        let (temp, predicted) = tripped.expect("never tripped");
        assert!(temp > 2.5 && temp < 2.8, "tripped at {temp} °C");
        assert!(predicted <= 1.5);
        // Not released at 2.5 °C or more while the fall still predicts the cut.
        let t = g.observe(&CFG, 10.0, temp - 0.1);
        assert!(temp - 0.1 >= 2.5 && !FreezeGuard::releases(&CFG, temp - 0.1, &t));
    }

    #[test]
    fn a_rising_load_is_not_extrapolated() {
        let mut g = guard();
        g.observe(&CFG, 10.0, 1.0);
        let t = g.observe(&CFG, 10.0, 1.6);
        assert!(t.slope_c_per_s > 0.0);
        assert_eq!(t.predicted_c, 1.6);
        assert!((t.drop_c + 0.6).abs() < 1e-6);
    }

    #[test]
    fn restart_forgets_the_slope() {
        let mut g = guard();
        g.observe(&CFG, 10.0, 5.0);
        g.observe(&CFG, 10.0, 4.0);
        assert!(g.slope_c_per_s() < 0.0);
        g.restart();
        let t = g.observe(&CFG, 10.0, 1.6);
        assert_eq!((t.drop_c, t.slope_c_per_s, t.predicted_c), (0.0, 0.0, 1.6));
    }

    #[test]
    fn a_non_finite_reading_leaves_the_slope_alone() {
        let mut g = guard();
        g.observe(&CFG, 10.0, 5.0);
        g.observe(&CFG, 10.0, 4.9);
        let s = g.slope_c_per_s();
        g.observe(&CFG, 10.0, f32::NAN);
        assert_eq!(g.slope_c_per_s(), s);
        // And the sample after it has no previous reading to take a slope from.
        let t = g.observe(&CFG, 10.0, 4.8);
        assert_eq!((t.drop_c, t.slope_c_per_s), (0.0, s));
    }
}

/// The freeze guard as the step runs it.
#[cfg(test)]
mod carrier {
    use crate::control::{AnyController, OnOff, OnOffConfig};
    use crate::event::EventKind;
    use crate::step::tests::counts_at;
    use crate::step::{Carrier, Mode, StepInput};
    use crate::units::Duty;

    /// Feeds a load falling at `rate_c_per_s` from 9 °C under an On-Off controller that keeps
    /// asking for cooling; returns the measured temperature at which the guard cut it.
    fn guard_trip(rate_c_per_s: f32) -> f32 {
        let onoff = OnOff::new(OnOffConfig { hysteresis_c: 0.1 });
        let mut c = Carrier::new(crate::step::ValidConfig::DEFAULT, AnyController::OnOff(onoff));
        let mut temp = 9.0f32;
        let mut t = 0u64;
        while temp > 0.0 {
            let out = c.step(&StepInput { t_ms: t, counts: counts_at(temp), setpoint_c: 2.0 });
            if out.mode == Mode::FreezeGuard {
                assert_eq!(out.duty, Duty::OFF);
                assert!(out.events.iter().any(|e| e.kind == EventKind::FreezeGuardTripped));
                // It holds until the load is back above the release threshold.
                for k in 1..20 {
                    let back = c.step(&StepInput { t_ms: t + 10_000 * k, counts: counts_at(2.2), setpoint_c: 2.0 });
                    assert_eq!(back.duty, Duty::OFF);
                }
                // Back above 2.5 °C (through the filter): cooling may resume.
                let released = (0..3).any(|k| {
                    let warm =
                        c.step(&StepInput { t_ms: t + 200_000 + 10_000 * k, counts: counts_at(2.8), setpoint_c: 2.0 });
                    warm.mode == Mode::Normal && warm.events.iter().any(|e| e.kind == EventKind::FreezeGuardReleased)
                });
                assert!(released);
                return out.temp_c.0;
            }
            temp -= rate_c_per_s * 10.0;
            t += 10_000;
        }
        panic!("guard never tripped");
    }

    #[test]
    fn freeze_guard_cuts_cooling_ahead_of_a_falling_load() {
        // Slow fall (0.06 °C/min): the guard acts close to its 1.5 °C threshold.
        let slow = guard_trip(0.001);
        assert!(slow <= 1.7 && slow > 1.0, "slow fall tripped at {slow}");
        // Fast fall (0.6 °C/min, full cooling): it acts ≈ 120 s ahead, above 2 °C.
        let fast = guard_trip(0.01);
        assert!(fast > 2.0 && fast <= 2.8, "fast fall tripped at {fast}");
    }
}
