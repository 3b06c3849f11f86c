//! Performance metrics of a simulated run: the `hter sim --json` object.
//!
//! All temperatures here are the plant's true load temperature, not the sensor reading.
//!
//! **Segments and settling.** The run is cut into segments of constant setpoint. In each
//! segment the load has *settled* at the first sample whose true temperature is within
//! ±[`SETTLE_BAND_C`] of the setpoint; `settle_time_s` is that instant minus the segment
//! start. `max_abs_error_after_settle_c` is the largest |T − w| from the settling instant to
//! the end of the segment, so overshoot and limit cycles after the first arrival count against
//! it. A segment that never settles contributes its whole-segment error and makes
//! `settle_time_s` null. The same rule applies to every controller. `steady_state_error_c` is
//! the largest |T − w| over the last quarter of each segment (a steady-state figure that
//! excludes the transient). Overall figures are the worst over all segments.
//!
//! **Overshoot** is how far the load goes past the setpoint in the direction of travel of a
//! setpoint change (or, for a run starting at ambient, of the pull-down), in °C, ≥ 0.
//!
//! **IAE** is ∫|T − w| dt over the whole run in °C·s (rectangle rule at the sample period).
//!
//! **SSR switches** counts turn-ons of the SSR output (a PWM period at a duty strictly between
//! 0 and 1 is one turn-on; consecutive periods at full duty are not).

use hter::coldchain::AlarmKind;
use hter::event::EventKind;
use serde::ser::SerializeStruct;
use serde::Serialize;

/// The band that defines "settled", °C (the carrier must hold its setpoint within ±0.5 °C).
pub const SETTLE_BAND_C: f64 = 0.5;

/// One sample of a run, as the metrics see it.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Setpoint, °C.
    pub setpoint_c: f64,
    /// True load temperature, °C.
    pub true_temp_c: f64,
}

/// What a `faults_detected` item reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detected {
    /// An event of the step (a hardware fault or a restart that lost minutes of control).
    Event(EventKind),
    /// The board's heartbeat monostable expired: the step stopped being called, and the
    /// board's alarm hardware sounds (the step cannot report its own hang).
    FirmwareHang,
}

impl Detected {
    /// Stable snake_case name, as `faults_detected` spells it: the event's name, or
    /// `firmware_hang`.
    pub fn name(self) -> &'static str {
        match self {
            Detected::Event(k) => k.name(),
            Detected::FirmwareHang => "firmware_hang",
        }
    }
}

impl std::fmt::Display for Detected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Detected {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// A kind with a stable name: what a [`Stamped`] item serialises as its `kind`.
pub trait Named: Copy {
    /// The name.
    fn name(self) -> &'static str;
}

impl Named for Detected {
    fn name(self) -> &'static str {
        Detected::name(self)
    }
}

impl Named for AlarmKind {
    fn name(self) -> &'static str {
        AlarmKind::name(self)
    }
}

/// A timestamped item of the `alarms` / `faults_detected` lists: `{"kind": name, "t_s": t}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stamped<K> {
    /// What was raised.
    pub kind: K,
    /// Time, s.
    pub t_s: f64,
}

impl<K: Named> Serialize for Stamped<K> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Stamped", 2)?;
        st.serialize_field("kind", self.kind.name())?;
        st.serialize_field("t_s", &self.t_s)?;
        st.end()
    }
}

/// The `hter sim --json` object.
#[derive(Clone, Debug, Serialize)]
pub struct SimMetrics {
    /// Controller name.
    pub controller: String,
    /// The figures computed from the samples alone.
    #[serde(flatten)]
    pub tracking: TrackingFigures,
    /// Electrical energy of the modules, Wh.
    pub energy_wh: f64,
    /// SSR turn-ons.
    pub ssr_switches: u64,
    /// Cold-chain alarms raised.
    pub alarms: Vec<Stamped<AlarmKind>>,
    /// Faults the step detected.
    pub faults_detected: Vec<Stamped<Detected>>,
    /// Time the board's alarm indicator was on (`hter::alarm`: out of range, not in control,
    /// or a fault or alarm nobody acknowledged — the simulation never presses the button), s.
    pub alarm_indicator_s: f64,
    /// When the alarm indicator first came on, s (null if never).
    pub alarm_indicator_first_s: Option<f64>,
    /// When the board's alarm hardware first sounded (the heartbeat monostable expired: the
    /// control loop stopped), s (null if never).
    pub alarm_hw_first_s: Option<f64>,
}

/// Figures computed from the samples alone (flattened into [`SimMetrics`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TrackingFigures {
    /// Integral of absolute error, °C·s.
    pub iae: f64,
    /// Worst |T − w| after settling, °C (see the module docs).
    pub max_abs_error_after_settle_c: f64,
    /// Worst |T − w| over the last quarter of each setpoint segment, °C.
    pub steady_state_error_c: f64,
    /// Worst overshoot, °C.
    pub overshoot_c: f64,
    /// Worst settling time over the segments, s (null if a segment never settled).
    pub settle_time_s: Option<f64>,
    /// Lowest true load temperature, °C.
    pub min_temp_c: f64,
    /// Highest true load temperature, °C.
    pub max_temp_c: f64,
    /// Time with the load outside 2…8 °C, s.
    pub time_outside_2_8_s: f64,
}

/// Computes the tracking figures of a run sampled every `ts_s`.
pub fn tracking(samples: &[Sample], ts_s: f64) -> TrackingFigures {
    let mut f = TrackingFigures {
        iae: 0.0,
        max_abs_error_after_settle_c: 0.0,
        steady_state_error_c: 0.0,
        overshoot_c: 0.0,
        settle_time_s: Some(0.0),
        min_temp_c: f64::INFINITY,
        max_temp_c: f64::NEG_INFINITY,
        time_outside_2_8_s: 0.0,
    };
    for s in samples {
        f.iae += (s.true_temp_c - s.setpoint_c).abs() * ts_s;
        f.min_temp_c = f.min_temp_c.min(s.true_temp_c);
        f.max_temp_c = f.max_temp_c.max(s.true_temp_c);
        if !(2.0..=8.0).contains(&s.true_temp_c) {
            f.time_outside_2_8_s += ts_s;
        }
    }
    // Segments of constant setpoint.
    let mut start = 0;
    while start < samples.len() {
        let w = samples[start].setpoint_c;
        let end = samples[start..].iter().position(|s| s.setpoint_c != w).map_or(samples.len(), |n| start + n);
        let seg = &samples[start..end];
        // Direction of travel: from the previous setpoint, or from the initial temperature.
        let from = if start > 0 { samples[start - 1].setpoint_c } else { seg[0].true_temp_c };
        let dir = if (w - from).abs() <= SETTLE_BAND_C { 0.0 } else { (w - from).signum() };
        if dir != 0.0 {
            let past = seg.iter().map(|s| dir * (s.true_temp_c - w)).fold(0.0f64, f64::max);
            f.overshoot_c = f.overshoot_c.max(past);
        }
        let err = |s: &Sample| (s.true_temp_c - w).abs();
        match seg.iter().position(|s| err(s) <= SETTLE_BAND_C) {
            Some(k) => {
                let settle = seg[k].t_s - seg[0].t_s;
                f.settle_time_s = f.settle_time_s.map(|x| x.max(settle));
                let after = seg[k..].iter().map(err).fold(0.0, f64::max);
                f.max_abs_error_after_settle_c = f.max_abs_error_after_settle_c.max(after);
            }
            None => {
                f.settle_time_s = None;
                let all = seg.iter().map(err).fold(0.0, f64::max);
                f.max_abs_error_after_settle_c = f.max_abs_error_after_settle_c.max(all);
            }
        }
        let tail = &seg[seg.len() * 3 / 4..];
        f.steady_state_error_c = f.steady_state_error_c.max(tail.iter().map(err).fold(0.0, f64::max));
        start = end;
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(temps: &[(f64, f64)]) -> TrackingFigures {
        let s: Vec<Sample> = temps
            .iter()
            .enumerate()
            .map(|(i, &(w, t))| Sample { t_s: i as f64 * 10.0, setpoint_c: w, true_temp_c: t })
            .collect();
        tracking(&s, 10.0)
    }

    #[test]
    fn pull_down_with_undershoot() {
        // From 10 °C to a 4 °C setpoint, undershooting to 3.2 °C, then back to 4.1 °C.
        let f = run(&[(4.0, 10.0), (4.0, 7.0), (4.0, 4.4), (4.0, 3.2), (4.0, 3.9), (4.0, 4.1), (4.0, 4.0), (4.0, 4.0)]);
        assert!((f.settle_time_s.unwrap() - 20.0).abs() < 1e-9);
        assert!((f.overshoot_c - 0.8).abs() < 1e-9);
        assert!((f.max_abs_error_after_settle_c - 0.8).abs() < 1e-9);
        assert!((f.steady_state_error_c - 0.0).abs() < 1e-9);
        assert!((f.iae - 10.0 * (6.0 + 3.0 + 0.4 + 0.8 + 0.1 + 0.1)).abs() < 1e-9);
        assert_eq!(f.min_temp_c, 3.2);
        assert!((f.time_outside_2_8_s - 10.0).abs() < 1e-9);
    }

    #[test]
    fn a_segment_that_never_settles_has_no_settle_time() {
        let f = run(&[(4.0, 4.0), (4.0, 4.0), (6.0, 4.0), (6.0, 4.5), (6.0, 5.0), (6.0, 5.2)]);
        assert_eq!(f.settle_time_s, None);
        assert!((f.max_abs_error_after_settle_c - 2.0).abs() < 1e-9);
        assert_eq!(f.overshoot_c, 0.0);
    }
}
