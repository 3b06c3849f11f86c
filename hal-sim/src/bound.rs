//! The physical bound of a setpoint schedule: the IAE no causal controller can beat on that
//! plant.
//!
//! For each segment of constant setpoint w the plant starts from the steady state holding the
//! previous setpoint (the scenario's start for the first segment: the holding steady state of
//! [`Start::Holding`], or everything at ambient for [`Start::Ambient`]). It then gets the most
//! the actuator can give in the direction of w — the SSR fully on to go down, fully off to go
//! up — until the true load temperature reaches or crosses w; from then on the error counts as
//! zero. A segment that ends before the crossing is truncated there. The bound is the sum of
//! these transients' IAE.
//!
//! Why nothing beats it: the thermal network is cooperative (every node is heated only by its
//! neighbours, through positive conductances), so for the same start state a colder input
//! trajectory gives a colder load at every instant (the comparison theorem for monotone
//! systems; Smith, *Monotone Dynamical Systems*, AMS 1995, ch. 3). Full cooling is therefore
//! the coldest the load can be at each sample before it reaches w, no cooling the warmest, and
//! after the crossing no error is better than zero. A controller also only learns of a
//! setpoint change at the first sample at or after it (no preview), which is where each
//! transient starts here. The bound is only as tight as the steady-state start: a controller
//! that is still settling from the previous step starts closer to or further from w.
//!
//! **Same rule as the metrics.** The IAE is summed as [`crate::metrics::tracking`] sums it:
//! Σ |T(t_k) − w(t_k)| · Ts over the control samples t_k = k·Ts of the run, T the true load
//! temperature at the instant the sample is taken (before the duty chosen there acts), w the
//! setpoint in force then. The sample at which a change is first seen therefore carries the
//! whole step |w − w_prev| · Ts for every controller and for the bound alike, so a ratio of
//! IAEs compares like with like.
//!
//! **Same plant.** The physical carrier is driven as `hter sim` drives it: Ts / PWM-period SSR
//! periods per sample, each fully on or fully off ([`Plant::advance_pwm_period`]), from
//! [`Plant::at_load_temperature`]. An ideal ARX plant (`--plant arx:...`) gets u = 1 or u = 0
//! for one sample at a time, from [`ArxPlant::at_steady_state`]; its direction of cooling is
//! the sign of its static gain. For an ARX model the bound is a bound only if the model's step
//! response is monotone (an oscillating model can overshoot its way to the setpoint faster);
//! every model `hter identify` gives for this carrier is.
//!
//! **Setpoint schedules only.** Timed changes of the surroundings (ambient, extra heat,
//! supply) are not in the bound: it is computed at the run's initial ambient, nominal supply
//! and no extra heat. A scenario whose only events are such changes (`disturbance`) has a
//! bound of 0, which bounds nothing useful: [`Bound::changes_ignored`] says how many changes
//! were left out, and `hter compare` prints its ratios as "n/a" when the bound is 0.

use anyhow::{bail, Result};
use hter::step::CarrierConfig;

use crate::arx::ArxPlant;
use crate::plant::{Plant, PlantParams};
use crate::scenario::Start;
use crate::sim::{PlantChoice, SimOptions, PWM_PERIOD_S};

/// One setpoint segment's share of the bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentBound {
    /// The sample time at which the segment starts, s.
    pub start_s: f64,
    /// The temperature the transient starts from (the previous setpoint, the holding
    /// temperature or the ambient the run starts at), °C.
    pub from_c: f64,
    /// The segment's setpoint, °C.
    pub to_c: f64,
    /// The transient's IAE, °C·s.
    pub iae: f64,
    /// The first sample time at which the load had reached the setpoint, s (`None` if the
    /// segment ended first, or if it started there).
    pub crossed_s: Option<f64>,
}

/// The bound of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Bound {
    /// Σ of the segments' IAE, °C·s.
    pub iae: f64,
    /// Each segment of constant setpoint.
    pub segments: Vec<SegmentBound>,
    /// How many timed changes of the surroundings the scenario has that the bound leaves out.
    pub changes_ignored: usize,
}

/// The plant the bound drives, in the state a transient starts from.
enum BoundPlant {
    Physical(Box<Plant>),
    Arx(ArxPlant, f64),
}

impl BoundPlant {
    fn temp_c(&self) -> f64 {
        match self {
            BoundPlant::Physical(p) => p.load_temp_c(),
            BoundPlant::Arx(p, _) => p.temp_c(),
        }
    }

    /// One control sample with the actuator fully towards `down` (cooling) or away from it.
    fn advance(&mut self, ts_s: f64, down: bool) {
        match self {
            BoundPlant::Physical(p) => {
                let d = if down { 1.0 } else { 0.0 };
                for _ in 0..(ts_s / PWM_PERIOD_S).round() as usize {
                    p.advance_pwm_period(PWM_PERIOD_S, d);
                }
            }
            BoundPlant::Arx(p, gain) => {
                // Cooling is u = 1 on a negative-gain model, u = 0 on a positive one.
                let cool = if *gain < 0.0 { 1.0 } else { 0.0 };
                p.advance(if down { cool } else { 1.0 - cool });
            }
        }
    }
}

/// The start of a transient: the plant of `opts` holding `from_c`, or (`None`) at ambient.
fn start_plant(opts: &SimOptions, from_c: Option<f64>) -> Result<BoundPlant> {
    let ambient = opts.ambient_c;
    let params = match opts.plant {
        PlantChoice::Hter1 => PlantParams::hter1(opts.scenario.load.unwrap_or(opts.load)),
        PlantChoice::Hter2 => PlantParams::hter2(opts.scenario.load.unwrap_or(opts.load)),
        PlantChoice::Custom(p) => p,
        PlantChoice::Arx(m) => {
            let a1 = 1.0 + m.a()[..m.na()].iter().map(|&x| f64::from(x)).sum::<f64>();
            let b1: f64 = m.b()[..m.nb()].iter().map(|&x| f64::from(x)).sum();
            let gain = if a1.abs() > 1e-12 { b1 / a1 } else { b1 };
            return Ok(BoundPlant::Arx(ArxPlant::at_steady_state(m, ambient, from_c.unwrap_or(ambient))?, gain));
        }
    };
    Ok(BoundPlant::Physical(Box::new(match from_c {
        None => Plant::at_ambient(params, ambient),
        Some(t) => match Plant::at_load_temperature(params, ambient, t) {
            Some((p, _)) => p,
            None => bail!("the bound needs the plant holding {t} °C, which it cannot at {ambient} °C ambient"),
        },
    })))
}

/// The bound of the run `opts` describes (its scenario, plant, load, ambient and duration),
/// sampled at the step's Ts.
pub fn bound(opts: &SimOptions) -> Result<Bound> {
    bound_at(opts, f64::from(CarrierConfig::DEFAULT.ts_s))
}

/// [`bound`] at sample period `ts_s`.
pub fn bound_at(opts: &SimOptions, ts_s: f64) -> Result<Bound> {
    let sc = &opts.scenario;
    // The control samples of the run and the setpoint each sees, as `sim::run` produces them.
    let n = (opts.duration_s / ts_s).round() as usize;
    let w: Vec<f64> = (0..n).map(|k| sc.setpoint_at(k as f64 * ts_s)).collect();
    let mut segments = Vec::new();
    let mut start = 0;
    while start < n {
        let to = w[start];
        let end = w[start..].iter().position(|&x| x != to).map_or(n, |m| start + m);
        let from = if start > 0 {
            Some(w[start - 1])
        } else {
            match sc.start {
                Start::Holding(t) => Some(t),
                Start::Ambient => None,
            }
        };
        // The direction and "already there" go by the nominal start: the steady state found
        // for a holding temperature matches it only to the search's tolerance.
        let from_c = from.unwrap_or(opts.ambient_c);
        let down = to < from_c;
        let mut seg = SegmentBound { start_s: start as f64 * ts_s, from_c, to_c: to, iae: 0.0, crossed_s: None };
        if from_c != to {
            let mut plant = start_plant(opts, from)?;
            for k in start..end {
                let t = plant.temp_c();
                if (down && t <= to) || (!down && t >= to) {
                    seg.crossed_s = Some(k as f64 * ts_s);
                    break;
                }
                seg.iae += (t - to).abs() * ts_s;
                plant.advance(ts_s, down);
            }
        }
        segments.push(seg);
        start = end;
    }
    Ok(Bound { iae: segments.iter().map(|s| s.iae).sum(), segments, changes_ignored: sc.changes.len() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use crate::sim::{ControllerChoice, ControllerSpec};

    fn opts(scenario: Scenario, plant: PlantChoice) -> SimOptions {
        SimOptions { plant, ..SimOptions::new(scenario, ControllerSpec::new(ControllerChoice::Pi)) }
    }

    fn schedule(start: Start, setpoints: Vec<(f64, f64)>, duration_s: f64) -> Scenario {
        Scenario { start, setpoints, duration_s, changes: vec![], ..Scenario::resolve("piecewise").unwrap() }
    }

    /// First-order ARX y(t+1) = a·y(t) + b·u(t): from the steady state y0 at duty u0, full
    /// cooling gives y(j) = y∞ + (y0 − y∞)·aʲ with y∞ = b/(1 − a). The bound's IAE is
    /// Ts·Σ_{j<n} (y(j) − yw), n the first j with y(j) ≤ yw, which in closed form is
    /// Ts·[n·(y∞ − yw) + (y0 − y∞)·(1 − aⁿ)/(1 − a)] with n = ⌈ln((yw − y∞)/(y0 − y∞))/ln a⌉.
    #[test]
    fn first_order_arx_crossing_has_the_closed_form() {
        let (a, b) = (0.95f64, -2.0f64);
        let m = crate::arx::parse(&format!("arx:{};{};1", -a, b)).unwrap();
        let ambient = 28.0;
        // Holding 6 °C (y0 = −22, u0 = 0.55), setpoint 3 °C from t = 100 s; 1 h at Ts = 10 s.
        let sc = schedule(Start::Holding(6.0), vec![(0.0, 6.0), (100.0, 3.0)], 3600.0);
        let bd = bound_at(&SimOptions { ambient_c: ambient, ..opts(sc, PlantChoice::Arx(m)) }, 10.0).unwrap();
        let (y0, yw, yinf) = (6.0 - ambient, 3.0 - ambient, b / (1.0 - a));
        let n = (((yw - yinf) / (y0 - yinf)).ln() / a.ln()).ceil();
        let want = 10.0 * (n * (yinf - yw) + (y0 - yinf) * (1.0 - a.powf(n)) / (1.0 - a));
        assert_eq!(bd.segments.len(), 2);
        assert_eq!(bd.segments[0].iae, 0.0, "the first segment starts at its setpoint");
        // f32 coefficients in the model: 1e-4 relative.
        assert!((bd.iae - want).abs() < 1e-4 * want, "bound {} vs closed form {want} (n = {n})", bd.iae);
        assert_eq!(bd.segments[1].crossed_s, Some(100.0 + 10.0 * n));
        // The warming way: from 3 °C back to 6 °C with u = 0, y(j) = y0·aʲ.
        let sc = schedule(Start::Holding(3.0), vec![(0.0, 6.0)], 3600.0);
        let bd = bound_at(&SimOptions { ambient_c: ambient, ..opts(sc, PlantChoice::Arx(m)) }, 10.0).unwrap();
        let (y0, yw) = (3.0 - ambient, 6.0 - ambient);
        let n = ((yw / y0).ln() / a.ln()).ceil();
        let want = 10.0 * (n * yw - y0 * (1.0 - a.powf(n)) / (1.0 - a));
        assert!((bd.iae - want).abs() < 1e-4 * want, "bound {} vs closed form {want}", bd.iae);
    }

    #[test]
    fn a_segment_that_ends_before_the_crossing_is_truncated() {
        // 1 − 0.999 q⁻¹, gain −0.02/(0.001) = −20 °C: from 6 °C it creeps; 30 s is 3 samples.
        let m = crate::arx::parse("arx:-0.999;-0.02;1").unwrap();
        let sc = schedule(Start::Holding(6.0), vec![(0.0, 3.0)], 30.0);
        let bd = bound_at(&SimOptions { ambient_c: 20.0, ..opts(sc, PlantChoice::Arx(m)) }, 10.0).unwrap();
        // y: −14, then −14·0.999 − 0.02, …: three samples of error ≈ 3 °C.
        let mut y = -14.0f64;
        let mut want = 0.0;
        for _ in 0..3 {
            want += (y - (3.0 - 20.0)).abs() * 10.0;
            y = 0.999 * y - 0.02;
        }
        assert!((bd.iae - want).abs() < 1e-3, "{} vs {want}", bd.iae);
        assert_eq!(bd.segments[0].crossed_s, None);
    }

    #[test]
    fn the_physical_bound_crosses_once_per_step_and_counts_the_first_sample_whole() {
        let sc = Scenario::resolve("piecewise").unwrap();
        let bd = bound(&opts(sc, PlantChoice::Hter1)).unwrap();
        assert_eq!(bd.segments.len(), 4);
        assert_eq!(bd.segments[0].iae, 0.0);
        for (s, from) in bd.segments[1..].iter().zip([4.0, 6.0, 3.0]) {
            // Each transient starts from the steady state at the previous setpoint.
            assert!((s.from_c - from).abs() < 1e-6, "{s:?}");
            // The first sample of a step sees the whole step before anything has moved, and
            // the load then moves towards the setpoint: more than one sample's worth, less
            // than the whole segment at the full step.
            let step = (s.to_c - from).abs();
            assert!(s.iae > step * 10.0, "{s:?}");
            let crossed = s.crossed_s.expect("the carrier crosses each setpoint within its segment");
            assert!(s.iae < step * (crossed - s.start_s), "{s:?}");
        }
    }

    #[test]
    fn an_unholdable_previous_setpoint_is_an_error_not_a_panic() {
        // Nothing holds the load at −40 °C.
        let sc = schedule(Start::Holding(-40.0), vec![(0.0, -40.0), (100.0, 4.0)], 600.0);
        let e = bound(&opts(sc, PlantChoice::Hter1)).unwrap_err().to_string();
        assert!(e.contains("cannot") && !e.contains('\n'), "{e}");
    }
}
