//! Simulated peripherals behind the firmware's seams, with fault injection (the way
//! sequential-storage's mock flash injects power loss).
//!
//! - [`SimAdc`] implements [`hter::hal::RtdSampler`]: the RTD in °C → ohms with its *own* f64
//!   Callendar–Van Dusen (the simulator never shares code paths with the controller) → the
//!   ratiometric front end → Gaussian noise → quantisation to 16-bit counts.
//! - [`SimSsr`] implements `embedded_hal::pwm::SetDutyCycle` for the SSR, with stuck-on/off
//!   faults, behind the supply-enable switch.

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
    temp_c: f64,
    last: u32,
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
            temp_c: 25.0,
            last: 0,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Sets the temperature the RTD is at, °C.
    pub fn set_temperature_c(&mut self, t: f64) {
        self.temp_c = t;
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
        let x = match self.fault {
            SensorFault::None | SensorFault::Stuck => self.ideal_counts(self.ohms_at(self.temp_c)) + noise,
            SensorFault::Offset(d) => self.ideal_counts(self.ohms_at(self.temp_c + d)) + noise,
            SensorFault::Open => fs,
            SensorFault::Short => self.ideal_counts(1.0) + noise,
            SensorFault::Spikes => {
                let base = self.ideal_counts(self.ohms_at(self.temp_c)) + noise;
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
        SimSsr { ticks: 0, fault: SsrFault::None, supply_enabled: true }
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
        if !self.supply_enabled {
            return 0.0;
        }
        match self.fault {
            SsrFault::None => self.commanded_duty(),
            SsrFault::StuckOn => 1.0,
            SsrFault::StuckOff => 0.0,
        }
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
}
