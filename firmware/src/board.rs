//! Board facts: every chip and pin choice of the reference carrier controller, in one place, so
//! another STM32 is a change to this file only (hubris keeps its `bsp/*.rs` the same way).
//!
//! NUCLEO-L476RG (STM32L476RG, Cortex-M4F at 80 MHz, 1 MiB flash, 128 KiB RAM).
//!
//! | signal | MCU pin | Nucleo header | wiring |
//! | --- | --- | --- | --- |
//! | RTD amplifier output | PA0 (ADC1_IN5) | A0 (CN8-1) | Pt100, 4-wire, in series with a 2 kΩ 0.1 % reference resistor and a ≈ 0.5 mA excitation; an instrumentation amplifier (gain 15) across the RTD's sense leads drives PA0; VREF+ is taken across the reference resistor, so the reading is ratiometric |
//! | SSR input | PA6 (TIM3_CH1) | D12 (CN5-5) | Crydom CMX60D10 (or any DC SSR) input, 3–32 V, through 330 Ω; the SSR switches the Peltier modules' 12 V |
//! | supply enable | PB0 | A3 (CN8-4) | gate driver of a high-side P-MOSFET switch in series with the SSR and the modules; high = power allowed; pulled down, so a reset or a dead MCU removes power |
//! | status LED | PA5 | LD2 (on board) | on while cooling is enabled |
//!
//! The supply-enable switch is the independent second cut-off of SPEC §6: SSRs usually fail
//! shorted, and the supervisor must be able to stop cooling regardless.

use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime};
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::pac::adc::vals::{OversamplingRatio, OversamplingShift, Rovsm, Trovs};
use embassy_stm32::peripherals::{ADC1, IWDG, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::Peri;

use crate::config;

/// The board's peripherals, initialised.
pub struct Board {
    /// RTD channel.
    pub rtd: RtdAdc,
    /// SSR PWM timer.
    pub ssr: SimplePwm<'static, TIM3>,
    /// Supply-enable output.
    pub supply_enable: Output<'static>,
    /// Status LED.
    pub led: Output<'static>,
    /// Independent watchdog.
    pub iwdg: Peri<'static, IWDG>,
    /// Flash controller (persisted records, `config::PERSIST_RANGE`).
    #[cfg(feature = "adaptive")]
    pub flash: Peri<'static, embassy_stm32::peripherals::FLASH>,
}

/// Clocks: HSI16 → PLL → 80 MHz system clock; the ADC runs from SYSCLK.
fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hsi = true;
    c.rcc.msi = None;
    c.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL10,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2), // 16 MHz × 10 / 2 = 80 MHz
    });
    c.rcc.sys = Sysclk::PLL1_R;
    c.rcc.mux.adcsel = mux::Adcsel::SYS;
    c
}

/// Initialises the chip and returns the board.
pub fn init() -> Board {
    let p = embassy_stm32::init(clocks());

    // 12-bit conversions, ×256 hardware oversampling, shifted right by 4: a 16-bit result
    // (full scale 65535, as `hter::adc::AdcFrontEnd::DEFAULT` expects). Averaging 256
    // conversions cuts white noise 16-fold.
    let adc_config = embassy_stm32::adc::AdcConfig {
        oversampling_ratio: Some(OversamplingRatio::RATIO256),
        oversampling_shift: Some(OversamplingShift::SHIFT4),
        oversampling_mode: Some((Rovsm::RESUMED, Trovs::AUTOMATIC, true)),
        ..Default::default()
    };
    let adc = Adc::new_with_config(p.ADC1, adc_config);
    let rtd = RtdAdc { adc, channel: p.PA0.degrade_adc() };

    let ssr_pin = PwmPin::new(p.PA6, OutputType::PushPull);
    // TIM3 is 16-bit and clocked at 80 MHz (APB1 ÷ 1): embassy picks the smallest prescaler that
    // fits, PSC + 1 = 1221, ARR = 65520, a period of 1.000014 s and 65521 duty ticks.
    let ssr =
        SimplePwm::new(p.TIM3, Some(ssr_pin), None, None, None, Hertz(config::SSR_PWM_HZ), CountingMode::EdgeAlignedUp);
    // embedded-hal's `SetDutyCycle` (behind `hter::hal::apply_duty`) counts duty in u16 and
    // embassy unwraps ARR + 1 into it on every write: a clock change that gave ARR = 65535 would
    // panic in the control path, so refuse it here, at boot.
    defmt::assert!(ssr.max_duty_cycle() <= u32::from(u16::MAX), "SSR PWM: ARR + 1 must fit in u16");

    Board {
        rtd,
        ssr,
        // Low until the first good control step: no cooling before the loop runs.
        supply_enable: Output::new(p.PB0, Level::Low, Speed::Low),
        led: Output::new(p.PA5, Level::Low, Speed::Low),
        iwdg: p.IWDG,
        #[cfg(feature = "adaptive")]
        flash: p.FLASH,
    }
}

/// The RTD channel behind the library's sampling seam.
pub struct RtdAdc {
    adc: Adc<'static, ADC1>,
    channel: AnyAdcChannel<'static, ADC1>,
}

impl hter::hal::RtdSampler for RtdAdc {
    type Error = core::convert::Infallible;

    fn sample(&mut self) -> Result<u32, Self::Error> {
        // 640.5 ADC cycles of sampling per conversion (the longest: the amplifier's output
        // impedance and the sampling capacitor settle fully) + 12.5 of conversion; 256 of them
        // take 2.1 ms at 80 MHz. embassy converts twice on the L4 and keeps the second (an L4 ADC
        // erratum: the first conversion after a pause longer than 1 ms may be corrupted), so this
        // blocks the executor ≈ 4.2 ms every Ts — nothing else in it is that time-critical.
        Ok(u32::from(self.adc.blocking_read(&mut self.channel, SampleTime::CYCLES640_5)))
    }
}
