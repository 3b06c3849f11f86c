//! The simulated hardware a run drives: the physical carrier behind the simulated ADC, SSR
//! and supply switch, with the board's fail-safe hardware around the MCU (the heartbeat and
//! its monostable), or an ideal ARX plant read and driven directly.

use anyhow::{bail, Result};
use hter::control::Controller;
use hter::hal::{apply_duty, RtdSampler};
use hter::step::{BoardReadings, Carrier, StepInput, StepOutput};
use hter::units::Celsius;

use super::row::RigView;
use super::{PlantChoice, SimOptions, PWM_PERIOD_S};
use crate::arx::ArxPlant;
use crate::fault::Fault;
use crate::periph::{Monostable, SamplePhase, SensorFault, SimAdc, SimSsr, SsrFault};
use crate::plant::{Drive, Plant};
use crate::scenario::{Change, Start, PREROLL_S};

/// The step's clock for sim time `t_s`, ms: the board's monotonic millisecond clock, which
/// counts from boot and so cannot go negative; the pre-roll starts at sim time −[`PREROLL_S`],
/// so the clock is sim time + [`PREROLL_S`] (converted once per sample, rounded to the ms).
pub(super) fn step_clock_ms(t_s: f64) -> u64 {
    ((t_s + PREROLL_S) * 1000.0).round() as u64
}

/// The simulated hardware: the physical carrier behind a simulated ADC and SSR, or an ideal
/// ARX plant read and driven directly.
// One Rig per run: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
pub(super) enum Rig {
    Physical { plant: Box<Plant>, adc: SimAdc, ssr: SimSsr, board: Board },
    Arx(ArxPlant),
}

impl Rig {
    pub(super) fn new(opts: &SimOptions) -> Result<(Rig, f64)> {
        let sc = &opts.scenario;
        let params = match (opts.plant_params(), opts.plant) {
            (Some(p), _) => p,
            (None, PlantChoice::Arx(m)) => {
                let t0 = match sc.start {
                    Start::Ambient => opts.ambient_c,
                    Start::Holding(t) => t,
                };
                let p = ArxPlant::at_steady_state(m, opts.ambient_c, t0)?;
                // The controller starts where the plant is: at the duty that holds it.
                let u0 = p.last_duty();
                return Ok((Rig::Arx(p), u0));
            }
            (None, _) => unreachable!("only an ARX plant has no physical parameters"),
        };
        let (plant, u0) = match sc.start {
            Start::Ambient => (Plant::at_ambient(params, opts.ambient_c), 0.0),
            Start::Holding(t) => match Plant::at_load_temperature(params, opts.ambient_c, t) {
                Some(p) => p,
                None => bail!("the plant cannot hold {} °C at {} °C ambient", crate::sim_cmd::shown(t), opts.ambient_c),
            },
        };
        let adc = SimAdc::new(opts.seed);
        // The sense reads the SSR's off time in the conversion window: the buck has neither.
        let board = Board { module_sense: opts.module_sense && params.drive == Drive::Ssr, ..Board::new() };
        Ok((Rig::Physical { plant: Box::new(plant), adc, ssr: SimSsr::new(), board }, u0))
    }

    /// Samples the sensor and runs the step; returns its output, the counts it got and the
    /// board's other readings it was handed. The step runs on the board's clock, [`step_clock_ms`].
    pub(super) fn step<C: Controller>(
        &mut self,
        carrier: &mut Carrier<C>,
        t_s: f64,
        w: f64,
    ) -> (StepOutput, (u32, BoardReadings)) {
        let t_ms = step_clock_ms(t_s);
        match self {
            Rig::Physical { plant, adc, ssr, board } => {
                let (counts, readings) = board.sample(plant, adc, ssr);
                carrier.observe(&readings);
                (carrier.step(&StepInput { t_ms, counts, setpoint_c: w as f32 }), (counts, readings))
            }
            Rig::Arx(p) => {
                (carrier.step_celsius(t_ms, Celsius(p.temp_c() as f32), w as f32), (0, BoardReadings::default()))
            }
        }
    }

    /// The board's inputs at board time `t_ms` for [`hter::app::App::sample`] (what
    /// [`Rig::step`] hands the step, for the glue that owns an `App`); `None` on an ideal
    /// plant, which has no ADC: its temperature is [`Rig::true_temp_c`].
    pub(super) fn sample_in(&mut self, t_ms: u64) -> Option<hter::app::SampleIn> {
        match self {
            Rig::Physical { plant, adc, ssr, board } => {
                let (counts, board) = board.sample(plant, adc, ssr);
                Some(hter::app::SampleIn { t_ms, counts, reference_ok: true, board })
            }
            Rig::Arx(_) => None,
        }
    }

    /// Drives the actuator at `t_s`; returns the duty the plant really gets.
    pub(super) fn actuate(&mut self, out: &StepOutput, t_s: f64) -> f64 {
        match self {
            Rig::Physical { plant, ssr, adc, board } => {
                // The SSR's edges must keep off the conversion window; the buck's output is
                // filtered and has none to keep off (the firmware's buck build does not clear).
                let duty = match (plant.params().drive, adc.phase) {
                    (Drive::Ssr, SamplePhase::Synchronised) => adc.window.clear_duty(out.duty),
                    _ => out.duty,
                };
                // SimSsr's error type is Infallible.
                let _ = apply_duty(ssr, duty);
                board.supply_pin = out.supply_enable;
                board.pulse_asked = out.switch_test && out.supply_enable;
                // A completed step: the heartbeat pulses, the monostable restarts.
                board.beat(t_s);
                ssr.set_supply_enabled(board.supply_on(t_s));
                ssr.effective_duty()
            }
            Rig::Arx(_) => {
                if out.supply_enable {
                    f64::from(out.duty.get())
                } else {
                    0.0
                }
            }
        }
    }

    /// Advances one sample period from `t_s` at duty `d` (on the physical rig: the SSR's duty
    /// behind the supply switch, whose gate the monostable may open in any PWM period) in PWM
    /// periods; returns SSR turn-ons.
    pub(super) fn advance(&mut self, t_s: f64, d: f64, ts: f64, last_on: &mut bool, count: bool) -> u64 {
        let periods = match self {
            Rig::Physical { .. } => (ts / PWM_PERIOD_S).round() as usize,
            Rig::Arx(_) => 1,
        };
        let mut switches = 0;
        for i in 0..periods {
            let d = match self {
                Rig::Physical { ssr, board, .. } => {
                    let t = t_s + i as f64 * PWM_PERIOD_S;
                    ssr.set_supply_enabled(board.supply_on(t));
                    // A test pulse (taken at the sample, so in this sample's first period)
                    // cuts the drive for its length, unless the switch is shorted.
                    let pulse = i == 0 && std::mem::take(&mut board.pulse_taken) && !ssr.switch_shorted;
                    ssr.effective_duty() * if pulse { 1.0 - TEST_PULSE_S / PWM_PERIOD_S } else { 1.0 }
                }
                Rig::Arx(_) => d,
            };
            if count && d > 0.0 && !*last_on {
                switches += 1;
            }
            // The SSR turns on again every period below full duty; the buck's output stays
            // on while the duty is above 0.
            *last_on = match self {
                Rig::Physical { plant, .. } if plant.params().drive == Drive::Buck => d > 0.0,
                _ => d >= 1.0,
            };
            if let Rig::Physical { plant, adc, .. } = self {
                plant.advance_pwm_period(PWM_PERIOD_S, d);
                // The buck switches in its own LC-filtered loop: no edge in the module leads.
                adc.set_ssr_duty(match plant.params().drive {
                    Drive::Ssr => d,
                    Drive::Buck => 0.0,
                });
            }
        }
        if let Rig::Arx(p) = self {
            p.advance(d);
        }
        switches
    }

    pub(super) fn true_temp_c(&self) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.load_temp_c(),
            Rig::Arx(p) => p.temp_c(),
        }
    }

    pub(super) fn ambient_c(&self, default: f64) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.ambient_c(),
            Rig::Arx(_) => default,
        }
    }

    pub(super) fn energy_wh(&self) -> f64 {
        match self {
            Rig::Physical { plant, .. } => plant.energy_wh(),
            Rig::Arx(_) => 0.0,
        }
    }

    pub(super) fn inject(&mut self, f: Fault) {
        if let Rig::Physical { plant, adc, ssr, .. } = self {
            match f {
                Fault::SensorOpen => adc.fault = SensorFault::Open,
                Fault::SensorShort => adc.fault = SensorFault::Short,
                Fault::SensorStuck => adc.fault = SensorFault::Stuck,
                Fault::SensorSpikes => adc.fault = SensorFault::Spikes,
                Fault::SensorOffset => adc.fault = SensorFault::Offset(1.5),
                Fault::SsrStuckOn => ssr.fault = SsrFault::StuckOn,
                Fault::SsrStuckOff => ssr.fault = SsrFault::StuckOff,
                Fault::SupplySag => plant.set_supply_v(9.0),
                Fault::LidOpen => plant.set_extra_heat_w(15.0),
                Fault::SupplySwitchShort => ssr.switch_shorted = true,
                // The run loop handles these: they stop or restart the step.
                Fault::Brownout | Fault::FirmwareHang | Fault::BoardFault(_) => {}
            }
        }
    }

    pub(super) fn change(&mut self, c: Change) {
        if let Rig::Physical { plant, .. } = self {
            match c {
                Change::Ambient(a) => plant.set_ambient_c(a),
                Change::ExtraHeat(w) => plant.set_extra_heat_w(w),
                Change::Supply(v) => plant.set_supply_v(v),
            }
        }
    }

    /// When the alarm hardware sounds at `t_s` (the monostable has expired), the time it
    /// began; `None` while the board is healthy or on an ideal plant without a board.
    pub(super) fn alarm_hw_since(&self, t_s: f64) -> Option<f64> {
        match self {
            Rig::Physical { board, .. } if !board.mono.is_running(t_s) => board.mono.expiry_s().or(Some(t_s)),
            _ => None,
        }
    }

    /// The ideal conversion of the last sample, counts (0 on an ideal plant).
    pub(super) fn ideal_counts(&self) -> f64 {
        match self {
            Rig::Physical { adc, .. } => adc.ideal_counts_last(),
            Rig::Arx(_) => 0.0,
        }
    }

    /// Advances one sample period at duty `d` before the run (the board not yet involved).
    pub(super) fn settle(&mut self, d: f64, ts: f64) {
        match self {
            Rig::Physical { plant, .. } => {
                for _ in 0..(ts / PWM_PERIOD_S).round() as usize {
                    plant.advance_pwm_period(PWM_PERIOD_S, d);
                }
            }
            Rig::Arx(p) => p.advance(d),
        }
    }

    /// The duty the modules get at `t_s` with the SSR and the pins as they are (the monostable
    /// gating the supply switch); 0 on an ideal plant, which has no board to hang.
    pub(super) fn gated_duty(&mut self, t_s: f64) -> f64 {
        match self {
            Rig::Physical { ssr, board, .. } => {
                ssr.set_supply_enabled(board.supply_on(t_s));
                ssr.effective_duty()
            }
            Rig::Arx(_) => 0.0,
        }
    }

    /// What the rig shows at `t_s` for a CSV row (`default_ambient_c` on an ideal plant).
    pub(super) fn view(&self, t_s: f64, default_ambient_c: f64) -> RigView {
        RigView {
            true_temp_c: self.true_temp_c(),
            ambient_c: self.ambient_c(default_ambient_c),
            alarm_hw: self.alarm_hw_since(t_s).is_some(),
            ideal_counts: self.ideal_counts(),
        }
    }

    pub(super) fn set_sample_phase(&mut self, phase: SamplePhase) {
        if let Rig::Physical { adc, .. } = self {
            adc.phase = phase;
        }
    }
}

/// The board's fail-safe hardware around the MCU: the supply-enable pin's last level and the
/// monostable the heartbeat pulses feed, which gates the supply switch.
#[derive(Clone, Debug)]
pub(super) struct Board {
    supply_pin: bool,
    mono: Monostable,
    /// The last output asked for a supply-switch test pulse (with the switch closed).
    pulse_asked: bool,
    /// A pulse was taken at this sample: its drive cut is still to come.
    pulse_taken: bool,
    /// The board has the module-side sense (`--module-sense`; not the reference board).
    module_sense: bool,
}

/// A supply-switch test pulse's length, s.
const TEST_PULSE_S: f64 = hter::supervisor::switch::TEST_PULSE_MS as f64 / 1000.0;

impl Board {
    fn new() -> Self {
        Board {
            supply_pin: true,
            mono: Monostable::new(Monostable::TIMEOUT_S),
            pulse_asked: false,
            pulse_taken: false,
            module_sense: false,
        }
    }

    /// The firmware's test pulse, if the last output asked for one: the switch opened for
    /// [`TEST_PULSE_S`] with the drive running, the rail read at its end, V (the supply if the
    /// switch is shorted, else emptied: the firmware drives the buck at its ceiling for the
    /// pulse, and nothing holds the SSR board's rail up).
    fn test_pulse(&mut self, ssr: &SimSsr, supply_v: f64) -> Option<f32> {
        std::mem::take(&mut self.pulse_asked).then(|| {
            self.pulse_taken = true;
            (if ssr.switch_shorted { supply_v } else { 0.0 }) as f32
        })
    }

    /// The board's sample for the next step: its other readings ([`Self::readings`]) and the
    /// RTD's conversion of the sensed temperature.
    fn sample(&mut self, plant: &Plant, adc: &mut SimAdc, ssr: &SimSsr) -> (u32, BoardReadings) {
        let readings = self.readings(plant, ssr);
        adc.set_temperature_c(plant.sensed_temp_c());
        let counts = match adc.sample() {
            Ok(c) => c,
            Err(never) => match never {},
        };
        (counts, readings)
    }

    /// What the board reads besides the RTD for the next sample: the supply divider, the
    /// switched rail after the supply switch, the test pulse's rail if the last output asked
    /// for one, and the modules in the conversion window on a board with that sense.
    fn readings(&mut self, plant: &Plant, ssr: &SimSsr) -> BoardReadings {
        BoardReadings {
            supply_v: Some(plant.supply_v() as f32),
            switched_v: Some(ssr.switched_rail_v(plant.supply_v()) as f32),
            switch_test_v: self.test_pulse(ssr, plant.supply_v()),
            module_v: self.module_sense.then(|| ssr.module_window_v(plant.supply_v(), plant.seebeck_v()) as f32),
        }
    }

    /// Whether the supply switch conducts at `t_s`: the MCU's pin, ANDed with the monostable.
    fn supply_on(&self, t_s: f64) -> bool {
        self.supply_pin && self.mono.is_running(t_s)
    }

    /// One healthy step at `t_s`: the heartbeat's pulse retriggers the monostable.
    fn beat(&mut self, t_s: f64) {
        self.mono.pulse(t_s);
    }
}
