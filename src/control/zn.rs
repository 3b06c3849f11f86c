//! Ziegler–Nichols tuning from a measured open-loop step response (process reaction curve;
//! Ziegler & Nichols 1942).
//!
//! The step response is reduced to a first-order-plus-dead-time model by the tangent at its
//! steepest point: with the tangent `y = y_i + s·(t − t_i)`,
//!
//! ```text
//! K = (y_∞ − y_0)/Δu        process gain, °C per unit duty (negative for a cooler)
//! L = t_i − (y_i − y_0)/s   apparent dead time, s
//! T = (y_∞ − y_0)/s         apparent time constant, s
//! ```
//!
//! and the table gives P: `Kp = T/(|K|·L)`; PI: `Kp = 0.9·T/(|K|·L)`, `Ti = L/0.3`.

/// Why a step response could not be reduced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ZnError {
    /// Fewer than 5 samples, a zero input step, or a non-positive sample period.
    TooLittleData,
    /// A sample was NaN or infinite.
    NonFinite,
    /// The response does not move, or the tangent gives a non-positive dead time or time constant.
    NoUsableResponse,
}

/// The first-order-plus-dead-time reduction of a step response.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReactionCurve {
    /// Gain K, °C per unit duty.
    pub gain_c_per_duty: f32,
    /// Apparent dead time L, s.
    pub dead_time_s: f32,
    /// Apparent time constant T, s.
    pub time_constant_s: f32,
}

impl ReactionCurve {
    /// Reduces the response `y` (°C, sampled every `ts_s` from the instant of the step) to a
    /// step of size `du` in duty. The last sample is taken as the final value, so the record
    /// must reach steady state.
    pub fn from_step(y: &[f32], ts_s: f32, du: f32) -> Result<Self, ZnError> {
        if y.len() < 5 || du == 0.0 || !(ts_s > 0.0) || !du.is_finite() {
            return Err(ZnError::TooLittleData);
        }
        if y.iter().any(|v| !v.is_finite()) {
            return Err(ZnError::NonFinite);
        }
        let (y0, yinf) = (y[0], y[y.len() - 1]);
        let sign = if yinf >= y0 { 1.0 } else { -1.0 };
        // Steepest point of the response in its own direction (central differences).
        let (mut best_k, mut best_s) = (0usize, 0.0f32);
        for (k, w) in y.windows(3).enumerate() {
            let s = sign * (w[2] - w[0]) / (2.0 * ts_s);
            if s > best_s {
                best_s = s;
                best_k = k + 1;
            }
        }
        if best_s <= 0.0 {
            return Err(ZnError::NoUsableResponse);
        }
        let s = sign * best_s;
        let ti = best_k as f32 * ts_s;
        let l = ti - (y[best_k] - y0) / s;
        let t = (yinf - y0) / s;
        if !(l > 0.0 && t > 0.0) {
            return Err(ZnError::NoUsableResponse);
        }
        Ok(Self { gain_c_per_duty: (yinf - y0) / du, dead_time_s: l, time_constant_s: t })
    }

    /// Ziegler–Nichols P gain, duty per °C.
    pub fn p_gain(&self) -> f32 {
        self.time_constant_s / (self.gain_c_per_duty.abs() * self.dead_time_s)
    }

    /// Ziegler–Nichols PI gains: (Kp in duty per °C, Ti in s).
    pub fn pi_gains(&self) -> (f32, f32) {
        (0.9 * self.p_gain(), self.dead_time_s / 0.3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_first_order_plus_dead_time_step() {
        // y = K·(1 − e^{−(t−L)/T}) for t ≥ L, K = −30 °C, L = 60 s, T = 1800 s, Ts = 10 s.
        let (k, l, t, ts) = (-30.0f32, 60.0f32, 1800.0f32, 10.0f32);
        let y: std::vec::Vec<f32> = (0..2000)
            .map(|i| {
                let tt = i as f32 * ts;
                if tt < l {
                    28.0
                } else {
                    28.0 + k * (1.0 - libm::expf(-(tt - l) / t))
                }
            })
            .collect();
        let rc = ReactionCurve::from_step(&y, ts, 1.0).unwrap();
        assert!((rc.gain_c_per_duty - k).abs() < 0.01, "{rc:?}");
        // For a pure FOPDT the steepest point is at t = L, so the tangent recovers L and T
        // up to the one-sample discretisation of the derivative.
        assert!((rc.dead_time_s - l).abs() < ts, "{rc:?}");
        assert!((rc.time_constant_s - t).abs() / t < 0.01, "{rc:?}");
        let (kp, ti) = rc.pi_gains();
        assert!((kp - 0.9 * 1800.0 / (30.0 * 60.0)).abs() / kp < 0.2, "{kp}");
        assert!((ti - 200.0).abs() < 35.0, "{ti}");
    }

    #[test]
    fn refuses_flat_and_bad_records() {
        assert_eq!(ReactionCurve::from_step(&[1.0; 10], 10.0, 1.0), Err(ZnError::NoUsableResponse));
        assert_eq!(ReactionCurve::from_step(&[1.0; 3], 10.0, 1.0), Err(ZnError::TooLittleData));
        assert_eq!(ReactionCurve::from_step(&[1.0, f32::NAN, 0.0, 0.0, 0.0], 10.0, 1.0), Err(ZnError::NonFinite));
    }
}
