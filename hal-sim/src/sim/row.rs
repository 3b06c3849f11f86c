//! One control sample of a run: a row of `hter sim --csv`. The mode, adaptive-mode and alarm
//! cells are the library's names ([`Mode::name`], [`AdaptiveMode::name`],
//! [`Indication::name`]), the spelling `hter log2csv` writes for the board's telemetry too.

use hter::alarm::Indication;
use hter::control::AdaptiveMode;
use hter::event::Events;
use hter::step::{BoardReadings, Mode, StepOutput};
use serde::Serialize;

/// The `mode` cell: the step's safety mode, or the step not being called at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowMode {
    /// The step ran in this mode.
    Step(Mode),
    /// The control loop hangs (`--fault firmware-hang`): no step ran, so no mode of the
    /// step applies; the board's pins hold what the last step set.
    Hung,
}

impl RowMode {
    /// The cell: [`Mode::name`], or `hung`.
    pub fn name(self) -> &'static str {
        match self {
            RowMode::Step(m) => m.name(),
            RowMode::Hung => "hung",
        }
    }
}

impl Serialize for RowMode {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

fn indication_name<S: serde::Serializer>(i: &Indication, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(i.name())
}

/// The `events` cell: the step's events of the sample by [`hter::event::EventKind::name`],
/// `;`-separated, as `hter log2csv` writes the board's (so that `hter monitor` and `hter report`
/// read a simulated run's restarts and faults as a board's).
fn event_names<S: serde::Serializer>(e: &Events, s: S) -> Result<S::Ok, S::Error> {
    let names: Vec<&str> = e.iter().map(|e| e.kind.name()).collect();
    s.serialize_str(&names.join(";"))
}

fn adaptive_name<S: serde::Serializer>(m: &Option<AdaptiveMode>, s: S) -> Result<S::Ok, S::Error> {
    match m {
        Some(m) => s.serialize_some(m.name()),
        None => s.serialize_none(),
    }
}

/// One control sample of a run (one CSV row).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Row {
    /// Sample time, s.
    pub t_s: f64,
    /// Setpoint in force, °C.
    pub setpoint_c: f64,
    /// Temperature the controller saw (filtered, calibrated), °C.
    pub temp_c: f64,
    /// Duty applied, [0, 1].
    pub duty: f64,
    /// Calibrated reading before the filter, °C (empty on a sensor fault).
    pub raw_temp_c: Option<f64>,
    /// True load temperature, °C.
    pub true_temp_c: f64,
    /// Ambient, °C.
    pub ambient_c: f64,
    /// Safety mode of the step.
    pub mode: RowMode,
    /// Raw RTD conversion the step received, counts (replayable through the step).
    pub counts: u32,
    /// Self-tuning estimate a1 (empty for other controllers).
    pub a1: Option<f32>,
    /// Self-tuning estimate a2.
    pub a2: Option<f32>,
    /// Self-tuning estimate b0.
    pub b0: Option<f32>,
    /// Self-tuning estimate b1.
    pub b1: Option<f32>,
    /// Self-tuning estimate b2.
    pub b2: Option<f32>,
    /// Self-tuning estimate b3.
    pub b3: Option<f32>,
    /// trace(P) of the estimator.
    pub trace_p: Option<f32>,
    /// Self-tuning mode (empty for other controllers).
    #[serde(serialize_with = "adaptive_name")]
    pub adaptive_mode: Option<AdaptiveMode>,
    /// The board's alarm indicator.
    #[serde(serialize_with = "indication_name")]
    pub alarm: Indication,
    /// The step's supply-enable output (the MCU's pin; the board's monostable gates it too).
    pub supply_enable: bool,
    /// The step asked for a supply-switch test pulse, taken before the next sample; not in the
    /// CSV.
    #[serde(skip)]
    pub switch_test: bool,
    /// The board's alarm hardware: true while the heartbeat monostable has expired (the MCU
    /// stopped stepping), whatever the MCU's own alarm pin says.
    pub alarm_hw: bool,
    /// The step's holdover estimate: how long the load would stay at or below 8 °C if cooling
    /// stopped now, s (empty without a model or before the first estimate; [`hter::holdover`]).
    pub holdover_s: Option<f64>,
    /// The self-tuner's reset at rest, °C: what it adds to the setpoint the law aims at
    /// (empty for other controllers; [`hter::control::adaptive`], "Reset at rest").
    pub reset_c: Option<f32>,
    /// The step's events of this sample (empty while the loop hangs): the `events` cell.
    #[serde(serialize_with = "event_names")]
    pub events: Events,
    /// The conversion an ideal ADC would have made of this sample, counts (no noise, no SSR
    /// switching disturbance, not rounded); not in the CSV.
    #[serde(skip)]
    pub ideal_counts: f64,
    /// What the board measured besides the RTD, as handed to the step ([`BoardReadings`]:
    /// `cargo xtask pil` replays them on the emulated Cortex-M4F); not in the CSV.
    #[serde(skip)]
    pub board_in: BoardReadings,
}

/// What the simulated hardware shows at a sample, besides the step's output.
#[derive(Clone, Copy, Debug)]
pub(super) struct RigView {
    /// True load temperature, °C.
    pub true_temp_c: f64,
    /// Ambient, °C.
    pub ambient_c: f64,
    /// The board's alarm hardware sounds.
    pub alarm_hw: bool,
    /// The ideal conversion, counts.
    pub ideal_counts: f64,
}

impl Row {
    /// A sample the step ran: its output `out` for `counts` and the board's other readings, the
    /// duty the modules got, the indicator it drove.
    pub(super) fn stepped(
        t_s: f64,
        setpoint_c: f64,
        out: &StepOutput,
        (counts, board_in): (u32, BoardReadings),
        duty: f64,
        alarm: Indication,
        rig: RigView,
    ) -> Row {
        Row {
            t_s,
            setpoint_c,
            temp_c: f64::from(out.temp_c.0),
            duty,
            raw_temp_c: out.raw_c.map(|c| f64::from(c.0)),
            true_temp_c: rig.true_temp_c,
            ambient_c: rig.ambient_c,
            mode: RowMode::Step(out.mode),
            counts,
            a1: out.status.map(|st| st.theta[0]),
            a2: out.status.map(|st| st.theta[1]),
            b0: out.status.map(|st| st.theta[2]),
            b1: out.status.map(|st| st.theta[3]),
            b2: out.status.map(|st| st.theta[4]),
            b3: out.status.map(|st| st.theta[5]),
            trace_p: out.status.map(|st| st.trace_p),
            adaptive_mode: out.status.map(|st| st.mode),
            alarm,
            supply_enable: out.supply_enable,
            switch_test: out.switch_test,
            alarm_hw: rig.alarm_hw,
            holdover_s: out.holdover_s.map(f64::from),
            reset_c: out.status.map(|st| st.reset_c),
            events: out.events,
            ideal_counts: rig.ideal_counts,
            board_in,
        }
    }

    /// A sample while the control loop hangs: what the last step left on the pins (`held`: its
    /// output, counts and indication, if there was one), the duty the modules still get.
    pub(super) fn hung(
        t_s: f64,
        setpoint_c: f64,
        held: Option<&(StepOutput, u32, Indication)>,
        duty: f64,
        rig: RigView,
    ) -> Row {
        let (out, counts, alarm) = held.map_or((None, 0, Indication::Off), |(o, c, i)| (Some(o), *c, *i));
        Row {
            t_s,
            setpoint_c,
            temp_c: out.map_or(f64::NAN, |o| f64::from(o.temp_c.0)),
            duty,
            raw_temp_c: None,
            true_temp_c: rig.true_temp_c,
            ambient_c: rig.ambient_c,
            mode: RowMode::Hung,
            counts,
            a1: None,
            a2: None,
            b0: None,
            b1: None,
            b2: None,
            b3: None,
            trace_p: None,
            adaptive_mode: None,
            alarm,
            supply_enable: out.is_some_and(|o| o.supply_enable),
            // A hung loop takes no sample, so no pulse.
            switch_test: false,
            alarm_hw: rig.alarm_hw,
            holdover_s: None,
            reset_c: None,
            events: Events::default(),
            ideal_counts: rig.ideal_counts,
            board_in: BoardReadings::default(),
        }
    }
}
