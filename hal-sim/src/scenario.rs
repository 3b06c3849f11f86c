//! Scenarios: what happens to the carrier during a simulated run.
//!
//! A scenario is a setpoint schedule, an initial condition, a default duration and timed
//! changes of the surroundings (ambient, extra heat, supply voltage). Built-in scenarios are
//! named; a JSON file with the same fields defines a custom one (see [`ScenarioFile`]).

use anyhow::{bail, Context, Result};
use serde::Deserialize;

use crate::plant::Load;

/// How a run starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Start {
    /// Everything at ambient, cooling off: the carrier has just been switched on.
    Ambient,
    /// Holding the load at this temperature, °C: the run's first sample is at it, whatever the
    /// first setpoint. At the first setpoint, on a physical plant, with the controller already
    /// running (the closed loop is pre-rolled for [`PREROLL_S`] before t = 0); at any other
    /// temperature, as on an ARX plant, from the plant's steady state at the duty that holds
    /// it, the controller starting at that duty, which is where the bound starts too
    /// (`crate::sim::prerolled`). A temperature no duty in [0, 1] holds (above the ambient) is
    /// refused when the run starts.
    Holding(f64),
}

/// Closed-loop pre-roll before t = 0 for [`Start::Holding`], s. Long enough for every
/// controller (including the integral of PI and the estimator of the adaptive ones) to reach
/// its own steady state, so the comparison starts fair.
pub const PREROLL_S: f64 = 3600.0;

/// A timed change of the surroundings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Change {
    /// Ambient temperature, °C.
    Ambient(f64),
    /// Extra heat into the cabinet (lid open, warm item), W.
    ExtraHeat(f64),
    /// Supply voltage of the modules, V.
    Supply(f64),
}

/// A complete scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    /// Name (built-in name or file name).
    pub name: String,
    /// One-line description.
    pub description: String,
    /// Initial condition.
    pub start: Start,
    /// Setpoint schedule: (from time s, setpoint °C), sorted, first entry at t = 0.
    pub setpoints: Vec<(f64, f64)>,
    /// Timed changes: (at time s, change), sorted.
    pub changes: Vec<(f64, Change)>,
    /// Default duration, s.
    pub duration_s: f64,
    /// Load forced by the scenario (`half-load`), overriding `--load`.
    pub load: Option<Load>,
    /// Open-loop identification run: the plant settles 2 h at the holding duty, the log starts
    /// with [`crate::sim::PRBS_REST_S`] more of that rest, then a PRBS on the SSR around the
    /// holding duty instead of the controller (`prbs`).
    pub excitation: bool,
    /// A power cut (`power-cut`): the run ends at the first sample after it whose true load
    /// temperature is above the limit, and reports the holdover.
    pub cut: Option<PowerCut>,
}

/// A power cut that ends the run once the load has warmed past a limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowerCut {
    /// When the supply goes to 0 V, s.
    pub at_s: f64,
    /// The run ends at the first sample after the cut with the true load temperature above
    /// this, °C.
    pub limit_c: f64,
}

impl PowerCut {
    /// Whether a sample at `t_s` with the true load at `true_temp_c` is past the cut and the
    /// limit: the run's last sample, and the end of the holdover.
    pub fn passed(&self, t_s: f64, true_temp_c: f64) -> bool {
        t_s >= self.at_s && true_temp_c > self.limit_c
    }
}

/// When `power-cut` cuts the supply, s.
pub const POWER_CUT_AT_S: f64 = 7200.0;

/// Names of the built-in scenarios.
pub const BUILT_IN: &[&str] =
    &["step", "piecewise", "half-load", "disturbance", "prbs", "hot-zone", "mission", "power-cut"];

/// One day, s.
pub const DAY_S: f64 = 86400.0;

/// A day/night ambient cycle as a staircase: from `t0_s` to `t1_s`, every `step_s`, the ambient
/// `mean_c + amplitude_c · cos(2π (t − t_peak_s) / 24 h)` at the middle of the step (so the
/// staircase follows the sine without lagging it). Peak at `t_peak_s` (and every 24 h from it).
pub fn day_night(
    t0_s: f64,
    t1_s: f64,
    step_s: f64,
    mean_c: f64,
    amplitude_c: f64,
    t_peak_s: f64,
) -> Vec<(f64, Change)> {
    let mut out = Vec::new();
    let mut t = t0_s;
    while t < t1_s {
        let mid = t + 0.5 * step_s.min(t1_s - t);
        let phase = 2.0 * std::f64::consts::PI * (mid - t_peak_s) / DAY_S;
        out.push((t, Change::Ambient(mean_c + amplitude_c * phase.cos())));
        t += step_s;
    }
    out
}

impl Scenario {
    /// A built-in scenario by name, or a JSON scenario file.
    pub fn resolve(name_or_file: &str) -> Result<Scenario> {
        if let Some(s) = Self::built_in(name_or_file) {
            return Ok(s);
        }
        let path = std::path::Path::new(name_or_file);
        if path.extension().is_some_and(|e| e == "json") || path.exists() {
            let text =
                std::fs::read_to_string(path).with_context(|| format!("cannot read scenario file '{name_or_file}'"))?;
            let file: ScenarioFile =
                serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("scenario file '{name_or_file}': {e}"))?;
            return file.into_scenario(name_or_file);
        }
        bail!("unknown scenario '{name_or_file}' (expected one of {} or a .json file)", BUILT_IN.join(", "))
    }

    /// A built-in scenario.
    pub fn built_in(name: &str) -> Option<Scenario> {
        let piecewise = vec![(0.0, 4.0), (200.0, 6.0), (1320.0, 3.0), (2440.0, 4.0)];
        let s = match name {
            "step" => Scenario {
                name: name.into(),
                description: "carrier at ambient, setpoint 4 °C from t = 0 (pull-down and hold)".into(),
                start: Start::Ambient,
                setpoints: vec![(0.0, 4.0)],
                changes: vec![],
                duration_s: 3.0 * 3600.0,
                load: None,
                excitation: false,
                cut: None,
            },
            "piecewise" => Scenario {
                name: name.into(),
                description: "holding 4 °C; setpoint → 6 °C at 200 s, → 3 °C at 1320 s, → 4 °C at 2440 s".into(),
                start: Start::Holding(4.0),
                setpoints: piecewise,
                changes: vec![],
                duration_s: 3600.0,
                load: None,
                excitation: false,
                cut: None,
            },
            "half-load" => Scenario {
                name: name.into(),
                description: "piecewise with half the load (50 ml water)".into(),
                start: Start::Holding(4.0),
                setpoints: piecewise,
                changes: vec![],
                duration_s: 3600.0,
                load: Some(Load::Half),
                excitation: false,
                cut: None,
            },
            "disturbance" => Scenario {
                name: name.into(),
                description: "holding 4 °C; a 3 W step heat load (lid ajar / warm item) from t = 1800 s".into(),
                start: Start::Holding(4.0),
                setpoints: vec![(0.0, 4.0)],
                changes: vec![(1800.0, Change::ExtraHeat(3.0))],
                duration_s: 3.0 * 3600.0,
                load: None,
                excitation: false,
                cut: None,
            },
            "prbs" => Scenario {
                name: name.into(),
                description: "open loop: 30 min at rest at the holding duty, then a PRBS (7-bit register, 120 s bits, period 4.2 h) on the SSR, holding duty ± 0.1, for 6 h, from 4 °C".into(),
                start: Start::Holding(4.0),
                setpoints: vec![(0.0, 4.0)],
                changes: vec![],
                duration_s: 6.5 * 3600.0,
                load: None,
                excitation: true,
                cut: None,
            },
            "hot-zone" => {
                // 24 h at 43 °C, then two days of 43/25 °C day/night (peak at 14:00, the
                // hot zone is entered at 14:00 of day 1), in 30-min steps.
                let mut changes = vec![(0.0, Change::Ambient(43.0))];
                changes.extend(day_night(DAY_S, 3.0 * DAY_S, 1800.0, 34.0, 9.0, DAY_S));
                Scenario {
                    name: name.into(),
                    description: "holding 4 °C, carried into 43 °C ambient for 24 h, then a 43/25 °C day/night cycle (30-min steps) for 48 h".into(),
                    start: Start::Holding(4.0),
                    setpoints: vec![(0.0, 4.0)],
                    changes,
                    duration_s: 3.0 * DAY_S,
                    load: None,
                    excitation: false,
                    cut: None,
                }
            }
            "mission" => {
                // A day in the field, starting 08:00: ambient 20…34 °C (peak 14:00) in 30-min
                // steps, the lid opened for 2 min four times (15 W each), and the supply
                // sagging to 10 V for an hour in the hot afternoon.
                let mut changes = day_night(0.0, DAY_S, 1800.0, 27.0, 7.0, 6.0 * 3600.0);
                for h in [2.0, 5.5, 9.0, 20.0] {
                    changes.push((h * 3600.0, Change::ExtraHeat(15.0)));
                    changes.push((h * 3600.0 + 120.0, Change::ExtraHeat(0.0)));
                }
                changes.push((6.0 * 3600.0, Change::Supply(10.0)));
                changes.push((7.0 * 3600.0, Change::Supply(12.0)));
                changes.sort_by(|a, b| a.0.total_cmp(&b.0));
                Scenario {
                    name: name.into(),
                    description: "24 h in the field: pull-down from ambient, day/night 20…34 °C, lid opened 2 min (15 W) four times, supply 12 → 10 V for an hour".into(),
                    start: Start::Ambient,
                    setpoints: vec![(0.0, 4.0)],
                    changes,
                    duration_s: DAY_S,
                    load: None,
                    excitation: false,
                    cut: None,
                }
            }
            "power-cut" => Scenario {
                name: name.into(),
                description: "holding 4 °C; the supply goes to 0 V at 2 h; ends when the load passes 8 °C (at most 48 h after the cut)".into(),
                start: Start::Holding(4.0),
                setpoints: vec![(0.0, 4.0)],
                changes: vec![(POWER_CUT_AT_S, Change::Supply(0.0))],
                duration_s: POWER_CUT_AT_S + 2.0 * DAY_S,
                load: None,
                excitation: false,
                cut: Some(PowerCut { at_s: POWER_CUT_AT_S, limit_c: hter::holdover::LIMIT_C as f64 }),
            },
            _ => return None,
        };
        Some(s)
    }

    /// Setpoint in force at time `t_s`.
    pub fn setpoint_at(&self, t_s: f64) -> f64 {
        self.setpoints.iter().take_while(|(t, _)| *t <= t_s).last().map_or(self.setpoints[0].1, |(_, w)| *w)
    }
}

/// A scenario file (JSON): `{"description": "...", "start_c": 4.0 | null, "setpoints": [[0, 4.0], ...],
/// "ambient": [[0, 28.0], ...], "extra_heat_w": [[1800, 3.0]], "supply_v": [[...]], "duration_s": 3600}`.
/// `start_c` null (or absent) starts at ambient.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// One-line description.
    #[serde(default)]
    pub description: String,
    /// Holding temperature at t = 0, °C; absent = start at ambient.
    pub start_c: Option<f64>,
    /// Setpoint schedule (time s, °C).
    pub setpoints: Vec<(f64, f64)>,
    /// Ambient schedule (time s, °C).
    #[serde(default)]
    pub ambient: Vec<(f64, f64)>,
    /// Extra heat schedule (time s, W).
    #[serde(default)]
    pub extra_heat_w: Vec<(f64, f64)>,
    /// Supply voltage schedule (time s, V).
    #[serde(default)]
    pub supply_v: Vec<(f64, f64)>,
    /// Duration, s.
    pub duration_s: f64,
}

/// Ambient range a run supports, °C (`--ambient`, and every `ambient` entry of a scenario file):
/// the plant table's parameters (fan-cooled hot sink, foam leak) are for a carrier in use, from
/// a cold store to the 43 °C of the WHO hot zone with margin.
pub const AMBIENT_RANGE_C: (f64, f64) = (-10.0, 50.0);

/// Supply range of a scenario file's `supply_v`, V. 0 V is a power cut (`power-cut`); the
/// plant's module is TEC1-12706 class (plant table), rated at most ≈ 15.4 V, and the carrier
/// runs from a 12 V supply or battery: above 16 V the module would be driven beyond its
/// datasheet, where the lumped model's numbers mean nothing. The plant itself only clips
/// negative volts to 0, so a sign error in a file would pass as a power cut.
pub const SUPPLY_RANGE_V: (f64, f64) = (0.0, 16.0);

/// Largest extra heat of a scenario file's `extra_heat_w`, W, either sign (negative: a cold
/// pack). The lid-open fault is 15 W and the module pumps at most Q_max ≈ 50 W (plant table):
/// twice that already swamps the cabinet and tests no controller, and without a bound ±1e6 W
/// drove the simulated load far below absolute zero.
pub const EXTRA_HEAT_MAX_W: f64 = 100.0;

impl ScenarioFile {
    fn into_scenario(self, name: &str) -> Result<Scenario> {
        let finite = |v: &[(f64, f64)]| v.iter().all(|(a, b)| a.is_finite() && b.is_finite() && *a >= 0.0);
        // The description is printed on one line of the summary: a newline or an escape
        // sequence (`\x1b[2J`) in it would break the line or drive the terminal.
        if let Some(c) = self.description.chars().find(|c| c.is_control()) {
            bail!("scenario file '{name}': 'description' contains a control character ({c:?}); it must be one line of text");
        }
        if self.setpoints.is_empty() {
            bail!("scenario file '{name}': 'setpoints' is empty");
        }
        // The board's own range: `set setpoint_c` refuses anything else (SPEC §8), and the step
        // clamps it, so a file asking for −40 °C ran at 2 °C and reported its error from −40.
        let (sp_lo, sp_hi) = hter::iface::SETPOINT_RANGE_C;
        let ranges = [
            ("setpoints", &self.setpoints, f64::from(sp_lo), f64::from(sp_hi), "°C"),
            ("ambient", &self.ambient, AMBIENT_RANGE_C.0, AMBIENT_RANGE_C.1, "°C"),
            ("extra_heat_w", &self.extra_heat_w, -EXTRA_HEAT_MAX_W, EXTRA_HEAT_MAX_W, "W"),
            ("supply_v", &self.supply_v, SUPPLY_RANGE_V.0, SUPPLY_RANGE_V.1, "V"),
        ];
        for (field, v, lo, hi, unit) in ranges {
            if !finite(v) {
                bail!("scenario file '{name}': '{field}' has a negative time or a non-finite number");
            }
            if v.windows(2).any(|w| w[1].0 < w[0].0) {
                bail!("scenario file '{name}': '{field}' times are not increasing");
            }
            // The schedule is piecewise constant: of two entries at one time the later replaced
            // the earlier at once, so `[[0, 4], [0, 5]]` ran at 5 °C and the 4 was never seen.
            if let Some(w) = v.windows(2).find(|w| w[1].0 == w[0].0) {
                let t = crate::sim_cmd::shown(w[0].0);
                bail!("scenario file '{name}': '{field}' has two entries at {t} s; give each time once");
            }
            if let Some((t, x)) = v.iter().find(|(_, x)| !(lo..=hi).contains(x)) {
                let (t, x) = (crate::sim_cmd::shown(*t), crate::sim_cmd::shown(*x));
                bail!("scenario file '{name}': '{field}' at {t} s is {x} {unit}, outside {lo}…{hi} {unit}");
            }
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            bail!("scenario file '{name}': duration_s must be positive");
        }
        let mut setpoints = self.setpoints;
        if setpoints[0].0 > 0.0 {
            setpoints.insert(0, (0.0, setpoints[0].1));
        }
        let mut changes: Vec<(f64, Change)> = self
            .ambient
            .iter()
            .map(|&(t, v)| (t, Change::Ambient(v)))
            .chain(self.extra_heat_w.iter().map(|&(t, v)| (t, Change::ExtraHeat(v))))
            .chain(self.supply_v.iter().map(|&(t, v)| (t, Change::Supply(v))))
            .collect();
        changes.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Scenario {
            name: name.into(),
            description: if self.description.is_empty() { "custom scenario".into() } else { self.description },
            start: self.start_c.map_or(Start::Ambient, Start::Holding),
            setpoints,
            changes,
            duration_s: self.duration_s,
            load: None,
            excitation: false,
            cut: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_schedule_matches_the_seed() {
        let s = Scenario::resolve("piecewise").unwrap();
        assert_eq!(s.setpoint_at(0.0), 4.0);
        assert_eq!(s.setpoint_at(199.0), 4.0);
        assert_eq!(s.setpoint_at(200.0), 6.0);
        assert_eq!(s.setpoint_at(1320.0), 3.0);
        assert_eq!(s.setpoint_at(3599.0), 4.0);
    }

    fn file(json: &str) -> Result<Scenario> {
        serde_json::from_str::<ScenarioFile>(json).unwrap().into_scenario("t.json")
    }

    #[test]
    fn a_description_with_control_characters_is_refused() {
        for d in [r"two\nlines", r"clear \u001b[2J screen", r"cr\r", r"tab\tbed"] {
            let e = file(&format!(r#"{{"description":"{d}","setpoints":[[0,4]],"duration_s":100}}"#))
                .unwrap_err()
                .to_string();
            assert!(e.contains("'description' contains a control character") && !e.contains('\n'), "{e}");
        }
        let s = file(r#"{"description":"holding 4 °C — one line","setpoints":[[0,4]],"duration_s":100}"#).unwrap();
        assert_eq!(s.description, "holding 4 °C — one line");
    }

    #[test]
    fn two_entries_at_one_time_are_refused() {
        for field in ["setpoints", "ambient", "extra_heat_w", "supply_v"] {
            let (a, b) = if field == "setpoints" { (4, 5) } else { (5, 6) };
            let json = if field == "setpoints" {
                format!(r#"{{"setpoints":[[0,4],[300,{a}],[300,{b}]],"duration_s":600}}"#)
            } else {
                format!(r#"{{"setpoints":[[0,4]],"{field}":[[0,{a}],[300,{a}],[300,{b}]],"duration_s":600}}"#)
            };
            let e = file(&json).unwrap_err().to_string();
            assert!(e.contains(&format!("'{field}' has two entries at 300 s")), "{e}");
        }
    }

    #[test]
    fn unknown_scenario_is_a_one_line_error() {
        let e = Scenario::resolve("nope").unwrap_err().to_string();
        assert!(e.contains("unknown scenario 'nope'") && !e.contains('\n'), "{e}");
    }
}
