//! Hardware seams: the only places where the library meets a peripheral.
//!
//! embedded-hal 1.0 has no trait for "give me one (oversampled) ADC conversion", so the RTD
//! channel gets its own small trait here. The SSR is driven through
//! [`embedded_hal::pwm::SetDutyCycle`]; [`apply_duty`] converts a [`Duty`] to its ticks.
//!
//! The firmware implements [`RtdSampler`] on top of the STM32 ADC (hardware oversampler);
//! `hal-sim` implements it on a simulated front end with noise, quantisation and injected
//! faults. Both hand the counts to [`crate::step::Carrier::step`].

use crate::units::Duty;
use embedded_hal::pwm::SetDutyCycle;

/// A source of RTD conversions, already oversampled/averaged to the configured resolution.
pub trait RtdSampler {
    /// Error of the underlying peripheral.
    type Error;
    /// Take one conversion. The result is in counts of
    /// [`crate::adc::AdcFrontEnd::full_scale_counts`].
    fn sample(&mut self) -> Result<u32, Self::Error>;
}

/// Sets a PWM channel (the SSR) to `duty`, rounding to the nearest timer tick.
pub fn apply_duty<P: SetDutyCycle>(pwm: &mut P, duty: Duty) -> Result<(), P::Error> {
    let max = pwm.max_duty_cycle();
    // Duty is guaranteed finite and in [0, 1], so the product fits in u16 after rounding.
    let ticks = libm::roundf(duty.get() * f32::from(max)) as u16;
    pwm.set_duty_cycle(ticks.min(max))
}
