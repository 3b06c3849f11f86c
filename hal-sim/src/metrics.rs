//! Performance metrics of a simulated run: the `hter sim --json` object.
//!
//! All temperatures here are the plant's true load temperature, not the sensor reading.
//!
//! **Segments and settling.** The run is cut into segments of constant setpoint (a segment
//! ends at the next setpoint change or at the end of the run). In each segment the load has
//! *settled* at the first sample after which its true temperature stays within
//! ±[`SETTLE_BAND_C`] of the setpoint until the segment ends: the sample after the *last exit*
//! from the band, not the first entry into it, so an overshoot out of the band or a limit
//! cycle that leaves it again moves the settling instant past it. `settle_time_s` is that
//! instant minus the segment start (0 if the segment never leaves the band); a segment whose
//! last sample is outside the band has not settled and makes `settle_time_s` null.
//! `max_abs_error_after_settle_c` is the largest |T − w| from the settling instant to the end
//! of the segment, which for a settled segment is within the band by construction; like
//! `settle_time_s` it is null if any segment has not settled (there is no "after settle" to
//! measure: a 600 s pull-down from 28 °C reported 24 °C "after settle"). The same rule applies
//! to every controller; the overall figures are the worst over the segments. `steady_state_error_c` is the largest |T − w| over the last quarter of each
//! segment (a steady-state figure that excludes the transient).
//!
//! **Overshoot** is how far the load goes past the setpoint in the direction of travel, in °C,
//! ≥ 0. The direction of a segment is from the load's true temperature at its first sample
//! towards its setpoint, not from the previous setpoint: a load still pulling down from 28 °C
//! when the setpoint steps 4 → 6 °C travels down to 6 °C, and only going below 6 °C after
//! arriving from above is overshoot (counting from the previous setpoint called the whole
//! 20 °C it was still above 6 °C an "overshoot"). The load starts on the near side of the
//! setpoint, so it can only go past it after reaching it. A segment that starts within
//! ±[`TRAVEL_MIN_C`] of its setpoint has no direction and no overshoot.
//!
//! **IAE** is ∫|T − w| dt over the whole run in °C·s (rectangle rule at the sample period).
//!
//! **SSR switches** counts turn-ons of the SSR output (a PWM period at a duty strictly between
//! 0 and 1 is one turn-on; consecutive periods at full duty are not).

use hter::coldchain::AlarmKind;
use hter::event::EventKind;
use serde::ser::SerializeStruct;
use serde::Serialize;

/// The band that defines "settled", °C: ±0.2 °C, tight enough to separate controllers that
/// hold the setpoint (the measurement noise moves the true load by a few hundredths) from
/// one that limit-cycles or creeps, and well inside the carrier's ±0.5 °C holding
/// requirement.
pub const SETTLE_BAND_C: f64 = 0.2;

/// The least move, °C, from the load's temperature at the start of a segment to its setpoint
/// that gives the segment a direction of travel for the overshoot: a run that starts holding
/// its setpoint, even in a ±0.3 °C On-Off limit cycle, has none.
pub const TRAVEL_MIN_C: f64 = 0.5;

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
    /// Electrical energy of the modules, Wh (with the buck drive, what the drive takes from
    /// the supply: the modules and the drive's own losses).
    pub energy_wh: f64,
    /// Mean electrical power over the run, W: `energy_wh` over the run's duration.
    pub mean_power_w: f64,
    /// SSR turn-ons.
    pub ssr_switches: u64,
    /// Cold-chain alarms raised.
    pub alarms: Vec<Stamped<AlarmKind>>,
    /// Faults the step detected.
    pub faults_detected: Vec<Stamped<Detected>>,
    /// Times the safety supervisor's freeze guard took the output from the controller
    /// (`freeze_guard_tripped` events after the pre-roll): 0 in a run the controller kept
    /// above the guard on its own.
    pub freeze_guard_trips: u32,
    /// Time the board's alarm indicator was on (`hter::alarm`: out of range, not in control,
    /// or a fault or alarm nobody acknowledged — the simulation never presses the button), s.
    pub alarm_indicator_s: f64,
    /// When the alarm indicator first came on, s (null if never).
    pub alarm_indicator_first_s: Option<f64>,
    /// When the board's alarm hardware first sounded (the heartbeat monostable expired: the
    /// control loop stopped), s (null if never).
    pub alarm_hw_first_s: Option<f64>,
    /// A power-cut run's holdover (`holdover_predicted_s`, `holdover_actual_s`); absent from
    /// the JSON of other scenarios.
    #[serde(flatten)]
    pub holdover: Option<Holdover>,
}

/// The holdover of a power-cut run (`hter sim --scenario power-cut`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Holdover {
    /// The step's estimate at the last sample before the cut, s (null if it had none).
    #[serde(rename = "holdover_predicted_s")]
    pub predicted_s: Option<f64>,
    /// From the cut to the first sample with the true load temperature above 8 °C, s (null if
    /// the run ended first).
    #[serde(rename = "holdover_actual_s")]
    pub actual_s: Option<f64>,
}

/// Figures computed from the samples alone (flattened into [`SimMetrics`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TrackingFigures {
    /// Integral of absolute error, °C·s.
    pub iae: f64,
    /// Worst |T − w| after settling, °C; null if a segment never settled (see the module docs).
    pub max_abs_error_after_settle_c: Option<f64>,
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

/// Mean power, W, of `energy_wh` spent over `duration_s` (0 for an empty run).
pub fn mean_power_w(energy_wh: f64, duration_s: f64) -> f64 {
    if duration_s > 0.0 {
        energy_wh * 3600.0 / duration_s
    } else {
        0.0
    }
}

/// Computes the tracking figures of a run sampled every `ts_s`.
pub fn tracking(samples: &[Sample], ts_s: f64) -> TrackingFigures {
    let mut f = TrackingFigures {
        iae: 0.0,
        max_abs_error_after_settle_c: Some(0.0),
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
        // Direction of travel: from where the load is when the segment starts (module docs).
        let from = seg[0].true_temp_c;
        let dir = if (w - from).abs() <= TRAVEL_MIN_C { 0.0 } else { (w - from).signum() };
        if dir != 0.0 {
            let past = seg.iter().map(|s| dir * (s.true_temp_c - w)).fold(0.0f64, f64::max);
            f.overshoot_c = f.overshoot_c.max(past);
        }
        let err = |s: &Sample| (s.true_temp_c - w).abs();
        let max_from = |k: usize| seg[k..].iter().map(err).fold(0.0, f64::max);
        // The first sample of the final stretch inside the band.
        let settled = match seg.iter().rposition(|s| err(s) > SETTLE_BAND_C) {
            None => Some(0),
            Some(j) if j + 1 < seg.len() => Some(j + 1),
            Some(_) => None,
        };
        match settled {
            Some(k) => {
                let settle = seg[k].t_s - seg[0].t_s;
                f.settle_time_s = f.settle_time_s.map(|x| x.max(settle));
                f.max_abs_error_after_settle_c = f.max_abs_error_after_settle_c.map(|x| x.max(max_from(k)));
            }
            None => {
                f.settle_time_s = None;
                f.max_abs_error_after_settle_c = None;
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
        // From 10 °C to a 4 °C setpoint, undershooting to 3.2 °C, then back to 4.1 °C. The last
        // sample outside ±0.2 °C is 3.2 °C at t = 30 s, so the load has settled at t = 40 s
        // (3.9 °C), and the worst error from there is 0.1 °C.
        let f = run(&[(4.0, 10.0), (4.0, 7.0), (4.0, 4.4), (4.0, 3.2), (4.0, 3.9), (4.0, 4.1), (4.0, 4.0), (4.0, 4.0)]);
        assert_eq!(f.settle_time_s, Some(40.0));
        assert!((f.overshoot_c - 0.8).abs() < 1e-9);
        assert!((f.max_abs_error_after_settle_c.unwrap() - 0.1).abs() < 1e-9);
        assert!((f.steady_state_error_c - 0.0).abs() < 1e-9);
        assert!((f.iae - 10.0 * (6.0 + 3.0 + 0.4 + 0.8 + 0.1 + 0.1)).abs() < 1e-9);
        assert_eq!(f.min_temp_c, 3.2);
        assert!((f.time_outside_2_8_s - 10.0).abs() < 1e-9);
    }

    #[test]
    fn settling_is_the_last_exit_from_the_band_not_the_first_entry() {
        // Setpoint 6 °C from 4 °C: enters the band at t = 20 s (5.9), leaves it at t = 40 s
        // (6.3), re-enters at t = 50 s (6.1) and stays. First entry would say 20 s; the load
        // has settled at 50 s, and after that the worst error is 0.1 °C, not the 0.3 °C of the
        // excursion.
        let f = run(&[(6.0, 4.0), (6.0, 5.0), (6.0, 5.9), (6.0, 6.1), (6.0, 6.3), (6.0, 6.1), (6.0, 6.0), (6.0, 5.95)]);
        assert_eq!(f.settle_time_s, Some(50.0));
        assert!((f.max_abs_error_after_settle_c.unwrap() - 0.1).abs() < 1e-9);
        assert!((f.overshoot_c - 0.3).abs() < 1e-9);
        // Each segment is timed from its own start: 4 °C held (settled at once), then a step to
        // 3 °C at t = 30 s reached at t = 50 s (3.15 after 3.4): 20 s, the worst of the two.
        let f =
            run(&[(4.0, 4.0), (4.0, 4.1), (4.0, 3.9), (3.0, 3.9), (3.0, 3.4), (3.0, 3.15), (3.0, 3.0), (3.0, 3.05)]);
        assert_eq!(f.settle_time_s, Some(20.0));
        assert!((f.max_abs_error_after_settle_c.unwrap() - 0.15).abs() < 1e-9);
    }

    #[test]
    fn a_segment_that_ends_outside_the_band_has_not_settled() {
        // Never arrives: no settling, so nothing "after settle" (it reported the 2 °C of the
        // whole segment, and 24 °C for a 600 s pull-down).
        let f = run(&[(4.0, 4.0), (4.0, 4.0), (6.0, 4.0), (6.0, 4.5), (6.0, 5.0), (6.0, 5.2)]);
        assert_eq!(f.settle_time_s, None);
        assert_eq!(f.max_abs_error_after_settle_c, None);
        assert_eq!(f.overshoot_c, 0.0);
        // Arrives at t = 20 s, then drifts out at the end (a limit cycle cut by the end of the
        // run): not settled either.
        let f = run(&[(4.0, 5.0), (4.0, 4.5), (4.0, 4.1), (4.0, 3.9), (4.0, 4.15), (4.0, 3.65)]);
        assert_eq!(f.settle_time_s, None);
        assert_eq!(f.max_abs_error_after_settle_c, None);
        // One settled segment and one not: both figures null, not the settled one's.
        let f = run(&[(4.0, 4.0), (4.0, 4.0), (4.0, 4.0), (6.0, 4.0), (6.0, 5.0)]);
        assert_eq!((f.settle_time_s, f.max_abs_error_after_settle_c), (None, None));
    }

    #[test]
    fn overshoot_is_past_the_setpoint_from_where_the_load_was() {
        // Still pulling down from 28 °C when the setpoint steps 4 → 6 °C: the load travels
        // down to 6 °C, and the 14 °C it is still above it is not overshoot (it reported the
        // distance above the new setpoint, 20.95 °C in `hter sim` of such a file).
        let f = run(&[(4.0, 28.0), (4.0, 24.0), (6.0, 20.0), (6.0, 14.0), (6.0, 9.0), (6.0, 7.0), (6.0, 6.3)]);
        assert_eq!(f.overshoot_c, 0.0);
        // The same, then it does go past 6 °C from above: that is overshoot, 0.4 °C.
        let f = run(&[(4.0, 28.0), (4.0, 24.0), (6.0, 20.0), (6.0, 9.0), (6.0, 5.6), (6.0, 5.9), (6.0, 6.0)]);
        assert!((f.overshoot_c - 0.4).abs() < 1e-9, "{f:?}");
        // A step up from a held 4 °C: past 6 °C upwards counts (0.3 °C), as before.
        let f = run(&[(4.0, 4.0), (4.0, 4.0), (6.0, 4.0), (6.0, 5.5), (6.0, 6.3), (6.0, 6.1)]);
        assert!((f.overshoot_c - 0.3).abs() < 1e-9, "{f:?}");
        // A step that finds the load already within TRAVEL_MIN_C of it has no direction.
        let f = run(&[(4.0, 5.8), (4.0, 5.9), (6.0, 5.9), (6.0, 6.3), (6.0, 5.7)]);
        assert_eq!(f.overshoot_c, 0.0);
    }
}
