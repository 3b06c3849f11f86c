//! Simulated peripherals behind the firmware's seams, with fault injection (the way
//! sequential-storage's mock flash injects power loss).
//!
//! - [`SimAdc`] implements [`hter::hal::RtdSampler`]: the RTD in °C → ohms with its *own* f64
//!   Callendar–Van Dusen (the simulator never shares code paths with the controller) → the
//!   ratiometric front end → Gaussian noise → quantisation to 16-bit counts.
//!   Each conversion also picks up the SSR's switching disturbance when it starts within a few
//!   ms of an edge ([`SsrKick`]), and happens at the phase of the PWM period [`SamplePhase`]
//!   says.
//! - [`SimSsr`] implements `embedded_hal::pwm::SetDutyCycle` for the SSR, with stuck-on/off
//!   faults, behind the supply-enable switch (which can be shorted), with the switched rail
//!   after it.
//! - [`Monostable`]: the board's heartbeat watchdog, a retriggerable monostable whose expiry
//!   opens the supply switch and sounds the alarm hardware.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Faults the RTD channel can have.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SensorFault {
    /// Working.
    None,
    /// Broken lead: the amplifier saturates at full scale.
    Open,
    /// Shorted leads: only the lead resistance (≈ 1 Ω) is seen.
    Short,
    /// The converter repeats the last value.
    Stuck,
    /// About 2 % of the samples are large spikes (EMI from the SSR, a loose connector).
    Spikes,
    /// A constant offset, °C (drifted calibration).
    Offset(f64),
}

/// Where in the SSR's PWM period the RTD conversion happens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SamplePhase {
    /// At the board's fixed phase ([`hter::adc::SampleWindow`]: the RTD conversion after the
    /// first reference conversion, 974 ms into the period), with the duty cleared so no edge
    /// comes near it. The default.
    Synchronised,
    /// On the SSR's falling edge of the last period before the sample (the rising edge at
    /// duty 1 after a period off): what a free-running sample clock slides onto for ≈ 20 min
    /// at a time. For tests.
    EdgeAligned,
}

/// The SSR switching disturbance on the RTD front end: each SSR edge adds `peak_counts`
/// decaying with `tau_ms`; a conversion of `conv_ms` averages it over its length.
///
/// A model, not a measurement: the SSR switches ≈ 4 A in the module leads, a ground bounce of
/// a few mV on a front end whose 16-bit count is 50 µV at the ADC makes tens of counts per mV;
/// 400 counts (≈ 0.8 Ω, 2 °C at the peak) decaying with 1 ms (the RC of the front end's
/// anti-alias filter and the ground return) is the order of magnitude, and a board must measure
/// it. Edges more than 10 τ before the conversion contribute nothing (e⁻¹⁰ · 400 = 0.02
/// counts, far under the noise), so a synchronised sample is exactly unbiased.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SsrKick {
    /// Disturbance right after an edge, counts (both edges alike, the worst case for the mean).
    pub peak_counts: f64,
    /// Its decay time constant, ms.
    pub tau_ms: f64,
    /// Length of the RTD conversion (×256 oversampling), ms.
    pub conv_ms: f64,
}

impl SsrKick {
    /// The model above.
    pub const DEFAULT: SsrKick = SsrKick { peak_counts: 400.0, tau_ms: 1.0, conv_ms: 4.0 };

    /// Mean disturbance over a conversion starting `after_ms` after an edge (negative: the edge
    /// comes during or after the conversion's start).
    pub fn bias_counts(&self, after_ms: f64) -> f64 {
        let (tau, d) = (self.tau_ms.max(1e-9), self.conv_ms.max(1e-9));
        // The kick integrated over the part of the conversion after the edge, divided by its length.
        let (from, to) = (after_ms.max(0.0), after_ms + d);
        if to <= 0.0 || from > 10.0 * tau {
            return 0.0;
        }
        self.peak_counts * tau / d * ((-from / tau).exp() - (-to / tau).exp())
    }
}

/// Ratiometric RTD front end with noise.
#[derive(Clone, Debug)]
pub struct SimAdc {
    /// Nominal RTD resistance at 0 °C, Ω.
    pub r0_ohm: f64,
    /// Reference resistor, Ω.
    pub r_ref_ohm: f64,
    /// Amplifier gain.
    pub gain: f64,
    /// Counts at full scale.
    pub full_scale: u32,
    /// Noise standard deviation, counts (after oversampling).
    pub noise_counts: f64,
    /// Injected fault.
    pub fault: SensorFault,
    /// When in the PWM period the RTD conversion happens.
    pub phase: SamplePhase,
    /// The board's conversion window in the PWM period.
    pub window: hter::adc::SampleWindow,
    /// The SSR switching disturbance.
    pub kick: SsrKick,
    temp_c: f64,
    last: u32,
    /// Duty the modules really got in the last PWM period (its edges disturb the conversion).
    ssr_duty: f64,
    /// The last conversion without noise or disturbance, counts (not rounded).
    ideal: f64,
    rng: ChaCha8Rng,
}

impl SimAdc {
    /// The board's front end (Pt100, 2 kΩ, gain 15, 16-bit) with 1.5 counts of noise
    /// (≈ 0.008 °C: the L4's 12-bit converter with ~2 LSB noise, averaged over 256 samples).
    pub fn new(seed: u64) -> Self {
        SimAdc {
            r0_ohm: 100.0,
            r_ref_ohm: 2000.0,
            gain: 15.0,
            full_scale: 65_535,
            noise_counts: 1.5,
            fault: SensorFault::None,
            phase: SamplePhase::Synchronised,
            window: hter::adc::SampleWindow::DEFAULT,
            kick: SsrKick::DEFAULT,
            temp_c: 25.0,
            last: 0,
            ssr_duty: 0.0,
            ideal: 0.0,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Sets the temperature the RTD is at, °C.
    pub fn set_temperature_c(&mut self, t: f64) {
        self.temp_c = t;
    }

    /// Tells the ADC the duty the modules got in the PWM period before the next conversion
    /// (0 with the supply open or the SSR stuck: no current, no edges).
    pub fn set_ssr_duty(&mut self, d: f64) {
        self.ssr_duty = d;
    }

    /// The last conversion as an ideal converter would have made it (no noise, no switching
    /// disturbance, not rounded), counts; the sensor fault, if any, included (a stuck converter
    /// repeats its value).
    pub fn ideal_counts_last(&self) -> f64 {
        self.ideal
    }

    /// Mean switching disturbance of a conversion now, counts: the edges of the last PWM
    /// period (rising at its start, falling at `duty · period`; none at duty 0 or 1).
    pub fn ssr_bias_counts(&self) -> f64 {
        let d = self.ssr_duty;
        if !(d > 0.0 && d < 1.0) {
            return 0.0;
        }
        let period = f64::from(self.window.period_ms);
        let fall = d * period;
        let start = match self.phase {
            // After the first reference conversion.
            SamplePhase::Synchronised => f64::from(self.window.start_ms) + self.kick.conv_ms,
            SamplePhase::EdgeAligned => fall,
        };
        self.kick.bias_counts(start) + self.kick.bias_counts(start - fall)
    }

    /// IEC 60751 resistance at `t` °C, independently of the library.
    pub fn ohms_at(&self, t: f64) -> f64 {
        const A: f64 = 3.9083e-3;
        const B: f64 = -5.775e-7;
        const C: f64 = -4.183e-12;
        let c = if t < 0.0 { C * (t - 100.0) * t * t * t } else { 0.0 };
        self.r0_ohm * (1.0 + A * t + B * t * t + c)
    }

    fn ideal_counts(&self, ohms: f64) -> f64 {
        ohms * self.gain / self.r_ref_ohm * f64::from(self.full_scale)
    }

    fn convert(&mut self) -> u32 {
        let fs = f64::from(self.full_scale);
        let noise = Normal::new(0.0, self.noise_counts.max(1e-12)).map_or(0.0, |n| n.sample(&mut self.rng));
        let bias = self.ssr_bias_counts();
        let ideal = match self.fault {
            SensorFault::Offset(d) => self.ideal_counts(self.ohms_at(self.temp_c + d)),
            SensorFault::Open => fs,
            SensorFault::Short => self.ideal_counts(1.0),
            SensorFault::None | SensorFault::Stuck | SensorFault::Spikes => {
                self.ideal_counts(self.ohms_at(self.temp_c))
            }
        };
        self.ideal = ideal;
        let x = match self.fault {
            // The amplifier sits at its rail: nothing moves it.
            SensorFault::Open => fs,
            SensorFault::Spikes => {
                let base = ideal + noise + bias;
                let u: f64 = rand::Rng::gen(&mut self.rng);
                if u < 0.02 {
                    // A spike of ±(5…30) °C worth of counts.
                    let v: f64 = rand::Rng::gen(&mut self.rng);
                    let sign = if v < 0.5 { -1.0 } else { 1.0 };
                    base + sign * (5.0 + 50.0 * v) * 0.385 * self.gain / self.r_ref_ohm * fs
                } else {
                    base
                }
            }
            SensorFault::None | SensorFault::Stuck | SensorFault::Offset(_) | SensorFault::Short => {
                ideal + noise + bias
            }
        };
        x.round().clamp(0.0, fs) as u32
    }
}

impl hter::hal::RtdSampler for SimAdc {
    type Error = core::convert::Infallible;

    fn sample(&mut self) -> Result<u32, Self::Error> {
        if self.fault != SensorFault::Stuck {
            self.last = self.convert();
        }
        Ok(self.last)
    }
}

/// Faults of the SSR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SsrFault {
    /// Working.
    None,
    /// Shorted output (the usual failure of a MOSFET SSR): always on.
    StuckOn,
    /// Open output: never on.
    StuckOff,
}

/// The SSR PWM channel behind the supply-enable switch.
#[derive(Clone, Debug)]
pub struct SimSsr {
    ticks: u16,
    /// Injected fault.
    pub fault: SsrFault,
    /// The supply-enable switch is shorted (a failed MOSFET): it conducts whatever it is told.
    pub switch_shorted: bool,
    supply_enabled: bool,
}

impl Default for SimSsr {
    fn default() -> Self {
        Self::new()
    }
}

impl SimSsr {
    /// Timer resolution: 1000 ticks per period (0.1 % duty steps).
    pub const MAX_TICKS: u16 = 1000;

    /// Off, supply enabled, no fault.
    pub fn new() -> Self {
        SimSsr { ticks: 0, fault: SsrFault::None, switch_shorted: false, supply_enabled: true }
    }

    /// Whether the supply switch conducts (commanded closed, or shorted).
    pub fn switch_conducts(&self) -> bool {
        self.supply_enabled || self.switch_shorted
    }

    /// The switched rail (after the supply switch, before the SSR) with the supply at
    /// `supply_v`, V: the supply when the switch conducts, else 0 (the board's bleeder empties
    /// the rail's capacitance well within a sample; the step ignores the first reading after
    /// an opening anyway).
    pub fn switched_rail_v(&self, supply_v: f64) -> f64 {
        if self.switch_conducts() {
            supply_v
        } else {
            0.0
        }
    }

    /// The voltage across the modules in the conversion window at the end of a PWM period, with
    /// the supply at `supply_v` and the modules' own Seebeck voltage `seebeck_v`, V: the supply
    /// when the SSR conducts there (shorted, or commanded to full duty, whose period has no off
    /// time) behind a conducting switch; else what the modules give back.
    pub fn module_window_v(&self, supply_v: f64, seebeck_v: f64) -> f64 {
        if self.effective_duty() >= 1.0 {
            supply_v
        } else {
            seebeck_v.max(0.0)
        }
    }

    /// Opens or closes the supply-enable switch in series with the modules.
    pub fn set_supply_enabled(&mut self, on: bool) {
        self.supply_enabled = on;
    }

    /// Commanded duty, [0, 1].
    pub fn commanded_duty(&self) -> f64 {
        f64::from(self.ticks) / f64::from(Self::MAX_TICKS)
    }

    /// Duty the modules really get, [0, 1].
    pub fn effective_duty(&self) -> f64 {
        if !self.switch_conducts() {
            return 0.0;
        }
        match self.fault {
            SsrFault::None => self.commanded_duty(),
            SsrFault::StuckOn => 1.0,
            SsrFault::StuckOff => 0.0,
        }
    }
}

/// The board's heartbeat watchdog: a retriggerable monostable (a 74HC123 on its B input) fed
/// by the heartbeat output, which a healthy control loop pulses once per step (the firmware's
/// `board::heartbeat_pulse`). Only a rising edge retriggers it, as the 74HC123's function table
/// has it (B rising with A low): a level toggled once per step gave it a trigger every 2·Ts,
/// past its timeout, where a pulse gives one every Ts ([`Monostable::input`]). While it runs its
/// output closes
/// the supply-enable switch's gate (in series with the MCU's supply-enable pin) and keeps the
/// alarm hardware silent. When the edges stop it expires: the switch opens (cooling stops
/// whatever duty the hung MCU's timer still drives) and the alarm sounds (powered and driven
/// by the board, not the MCU). At power-up it has not been triggered: the switch stays open and
/// the alarm sounds until the first step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Monostable {
    /// Pulse length, s.
    pub timeout_s: f64,
    last_trigger_s: Option<f64>,
    /// The trigger input's level (low at power-up: the pull-down).
    level: bool,
}

impl Monostable {
    /// 15 s = 1.5 Ts: longer than the 10 s between beats with the RC's tolerance (±20 %: 12 s
    /// at worst) and the step's jitter, and short enough that cooling stops within 2 Ts of the
    /// last beat (18 s at worst, before the switch's own turn-off time of microseconds).
    pub const TIMEOUT_S: f64 = 15.0;

    /// Not yet triggered.
    pub fn new(timeout_s: f64) -> Self {
        Monostable { timeout_s, last_trigger_s: None, level: false }
    }

    /// The trigger input goes to `level` at `t_s`: a rising edge retriggers the pulse, a falling
    /// one does nothing.
    pub fn input(&mut self, level: bool, t_s: f64) {
        if level && !self.level {
            self.last_trigger_s = Some(t_s);
        }
        self.level = level;
    }

    /// One heartbeat pulse at `t_s` (the firmware's ≈ 10 µs high, then low): one rising edge.
    pub fn pulse(&mut self, t_s: f64) {
        self.input(true, t_s);
        self.input(false, t_s);
    }

    /// Whether the pulse is still running at `t_s` (supply gate closed, alarm silent).
    pub fn is_running(&self, t_s: f64) -> bool {
        self.expiry_s().is_some_and(|e| t_s < e)
    }

    /// When the pulse ends (or ended), s; `None` before the first trigger.
    pub fn expiry_s(&self) -> Option<f64> {
        self.last_trigger_s.map(|t| t + self.timeout_s)
    }
}

impl embedded_hal::pwm::ErrorType for SimSsr {
    type Error = core::convert::Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for SimSsr {
    fn max_duty_cycle(&self) -> u16 {
        Self::MAX_TICKS
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        self.ticks = duty.min(Self::MAX_TICKS);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::pwm::SetDutyCycle;
    use hter::hal::RtdSampler;

    #[test]
    fn counts_match_the_front_end_equation() {
        let mut adc = SimAdc::new(1);
        adc.noise_counts = 0.0;
        for (t, r) in [(0.0, 100.0), (50.0, 119.3971), (-20.0, 92.1603)] {
            adc.set_temperature_c(t);
            let want = r * 15.0 / 2000.0 * 65535.0;
            let got = f64::from(adc.sample().unwrap());
            assert!((got - want).abs() <= 1.0, "{t} °C: {got} vs {want}");
        }
    }

    #[test]
    fn faults_behave() {
        let mut adc = SimAdc::new(1);
        adc.set_temperature_c(4.0);
        let normal = adc.sample().unwrap();
        adc.fault = SensorFault::Open;
        assert_eq!(adc.sample().unwrap(), 65_535);
        adc.fault = SensorFault::Short;
        assert!(adc.sample().unwrap() < 600);
        adc.fault = SensorFault::Stuck;
        let stuck = adc.sample().unwrap();
        adc.set_temperature_c(20.0);
        assert_eq!(adc.sample().unwrap(), stuck);
        adc.fault = SensorFault::Offset(1.0);
        adc.set_temperature_c(4.0);
        let off = adc.sample().unwrap();
        assert!((f64::from(off) - f64::from(normal) - 0.39 * 15.0 / 2000.0 * 65535.0).abs() < 10.0);
        adc.fault = SensorFault::Spikes;
        let spikes = (0..1000).filter(|_| (f64::from(adc.sample().unwrap()) - f64::from(normal)).abs() > 500.0).count();
        assert!((5..=50).contains(&spikes), "{spikes}");
    }

    #[test]
    fn ssr_round_trip_faults_and_supply_switch() {
        let mut ssr = SimSsr::new();
        ssr.set_duty_cycle_fraction(1, 4).unwrap();
        assert_eq!(ssr.effective_duty(), 0.25);
        ssr.fault = SsrFault::StuckOn;
        assert_eq!(ssr.effective_duty(), 1.0);
        ssr.set_supply_enabled(false);
        assert_eq!(ssr.effective_duty(), 0.0);
        ssr.set_supply_enabled(true);
        ssr.fault = SsrFault::StuckOff;
        assert_eq!(ssr.effective_duty(), 0.0);
    }

    #[test]
    fn a_shorted_switch_keeps_the_rail_and_the_cooling() {
        let mut ssr = SimSsr::new();
        ssr.set_duty_cycle_fraction(1, 2).unwrap();
        ssr.set_supply_enabled(false);
        assert_eq!((ssr.effective_duty(), ssr.switched_rail_v(12.0)), (0.0, 0.0));
        ssr.switch_shorted = true;
        assert_eq!((ssr.effective_duty(), ssr.switched_rail_v(12.0)), (0.5, 12.0));
    }

    #[test]
    fn the_monostable_runs_while_it_is_retriggered() {
        let mut m = Monostable::new(Monostable::TIMEOUT_S);
        assert!(!m.is_running(0.0), "not triggered at power-up");
        for k in 0..10 {
            m.pulse(k as f64 * 10.0);
            assert!(m.is_running(k as f64 * 10.0 + 9.99));
        }
        assert!(m.is_running(104.9) && !m.is_running(105.0));
        assert_eq!(m.expiry_s(), Some(105.0));
    }

    /// A 74HC123 triggers on one edge polarity: a level toggled once per 10 s step (the old
    /// heartbeat) rises every 20 s, and the 15 s pulse lapses for 5 s of every 20 (the healthy
    /// board's supply opened and its buzzer sounded); a pin stuck high gives no edge at all.
    #[test]
    fn a_toggled_level_lets_the_monostable_lapse() {
        let mut m = Monostable::new(Monostable::TIMEOUT_S);
        let mut level = false;
        let mut lapsed_s = 0;
        for k in 0..100u32 {
            level = !level;
            m.input(level, f64::from(k) * 10.0);
            lapsed_s += (0..10).filter(|s| !m.is_running(f64::from(k * 10 + s))).count();
        }
        assert_eq!(lapsed_s, 50 * 5, "5 s of every 20");
        m.input(true, 1000.0);
        assert!(!m.is_running(1020.0), "a pin stuck high gives no edge");
    }

    #[test]
    fn the_switching_disturbance_model() {
        let k = SsrKick::DEFAULT;
        // On the edge: the mean of 400·e^(−t/1 ms) over 4 ms, 400/4·(1 − e⁻⁴) ≈ 98 counts.
        assert!((k.bias_counts(0.0) - 100.0 * (1.0 - (-4.0f64).exp())).abs() < 1e-9);
        assert!(k.bias_counts(2.0) < k.bias_counts(0.0) * 0.14);
        assert_eq!(k.bias_counts(10.5), 0.0);
        assert_eq!(k.bias_counts(-4.0), 0.0, "edge after the conversion");
        assert!(k.bias_counts(-2.0) > 0.0 && k.bias_counts(-2.0) < k.bias_counts(0.0));
        // The ADC: edge-aligned conversions carry it, synchronised ones none.
        let mut adc = SimAdc::new(3);
        adc.noise_counts = 0.0;
        adc.set_temperature_c(4.0);
        adc.set_ssr_duty(0.4);
        let sync = f64::from(adc.sample().unwrap());
        assert!((sync - adc.ideal_counts_last()).abs() <= 0.5, "{sync} vs {}", adc.ideal_counts_last());
        adc.phase = SamplePhase::EdgeAligned;
        let edge = f64::from(adc.sample().unwrap());
        assert!((edge - adc.ideal_counts_last() - 98.2).abs() < 1.0, "{edge} vs {}", adc.ideal_counts_last());
        adc.set_ssr_duty(1.0);
        assert!((f64::from(adc.sample().unwrap()) - adc.ideal_counts_last()).abs() <= 0.5, "no edge at duty 1");
    }
}
