//! Board facts: every chip and pin choice of the reference carrier controller, in one place, so
//! another STM32 is a change to this file only (hubris keeps its `bsp/*.rs` the same way).
//!
//! NUCLEO-L476RG (STM32L476RG, Cortex-M4F at 80 MHz, 1 MiB flash, 128 KiB RAM).
//!
//! | signal | MCU pin | Nucleo header | wiring |
//! | --- | --- | --- | --- |
//! | RTD amplifier output | PA0 (ADC1_IN5) | A0 (CN8-1) | Pt100, 4-wire, in series with a 2 kΩ 0.1 % reference resistor, both carrying a 1 mA excitation (a current source from VDDA, e.g. an op-amp Howland or a REF200 pair); an instrumentation amplifier (gain 15) across the RTD's sense leads drives PA0 |
//! | reference-resistor voltage | PA1 (ADC1_IN6) | A1 (CN8-2) | the top of the 2 kΩ reference resistor (its bottom at AGND), through a 1 kΩ / 100 nF RC; ≈ 2.0 V at 1 mA |
//! | modules' supply | PA4 (ADC1_IN9) | A2 (CN8-3) | 47 kΩ from the 12 V input (ahead of the supply-enable switch, so an open switch does not read as a sag) to PA4, 10 kΩ to AGND, 100 nF across the 10 kΩ: 12 V reads 2.1 V |
//! | SSR input | PA6 (TIM3_CH1) | D12 (CN5-5) | Crydom CMX60D10 (or any DC SSR) input, 3–32 V, through 330 Ω; the SSR switches the Peltier modules' 12 V |
//! | supply enable | PB0 | A3 (CN8-4) | gate driver of a high-side P-MOSFET switch in series with the SSR and the modules; high = power allowed; pulled down, so a reset or a dead MCU removes power |
//! | status LED | PA5 | LD2 (on board) | on while cooling is enabled |
//! | alarm output | PC7 | D9 (CN5-2) | a buzzer or red lamp through a low-side NPN/N-MOSFET driver; high = alarm (`hter::alarm`) |
//! | acknowledge button | PC13 | B1 (on board, blue) | pressed pulls low (the Nucleo's pull-up); clears a latched alarm |
//!
//! The supply-enable switch is the independent second cut-off of SPEC §6: SSRs usually fail
//! shorted, and the supervisor must be able to stop cooling regardless.
//!
//! **Measurement.** In the LQFP64 package VREF+ is bonded to VDDA (3.3 V on the Nucleo), so the
//! reference resistor cannot be the converter's reference: both the amplified RTD voltage and
//! the reference-resistor voltage are converted against VDDA and their ratio is formed by
//! `hter::adc::ratiometric_counts` — VDDA and the excitation current cancel as in a
//! ratiometric converter. Each conversion is 256 × 12-bit conversions averaged by the L4's
//! hardware oversampler and shifted to 16 bits; one count of the RTD conversion is 50 µV at the
//! ADC, 3.4 µV at the RTD, 3.4 mΩ at 1 mA: **≈ 0.009 °C**, within the 0.02 °C target (16 × the
//! 0.14 °C of a bare 12-bit conversion: the ADC's ≈ 1–2 LSB of noise dithers the average).
//! Averaging 256 conversions also cuts white noise 16-fold; the step's first-order filter
//! (F_a = 0.5) halves its variance again. The supply divider is converted the same way, and
//! the internal reference VREFINT with it, so the supply reading is corrected for VDDA's
//! tolerance (RM0351 §16.4.34).

use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime, VrefInt};
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::pac::adc::vals::{OversamplingRatio, OversamplingShift, Rovsm, Trovs};
use embassy_stm32::peripherals::{ADC1, IWDG, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::Peri;

use crate::config;

/// The board's peripherals, initialised.
pub struct Board {
    /// The analog inputs: RTD, reference resistor, supply, VREFINT.
    pub analog: Analog,
    /// SSR PWM timer.
    pub ssr: SimplePwm<'static, TIM3>,
    /// Supply-enable output.
    pub supply_enable: Output<'static>,
    /// Status LED.
    pub led: Output<'static>,
    /// Alarm indicator output (buzzer or lamp driver).
    pub alarm: Output<'static>,
    /// The user button (acknowledges the alarm).
    pub button: Input<'static>,
    /// Independent watchdog.
    pub iwdg: Peri<'static, IWDG>,
    /// Flash controller (persisted records, `config::PERSIST_RANGE`).
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
    let vrefint = adc.enable_vrefint();
    let analog =
        Analog { adc, rtd: p.PA0.degrade_adc(), reference: p.PA1.degrade_adc(), supply: p.PA4.degrade_adc(), vrefint };

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
        analog,
        ssr,
        // Low until the first good control step: no cooling before the loop runs.
        supply_enable: Output::new(p.PB0, Level::Low, Speed::Low),
        led: Output::new(p.PA5, Level::Low, Speed::Low),
        alarm: Output::new(p.PC7, Level::Low, Speed::Low),
        button: Input::new(p.PC13, Pull::None),
        iwdg: p.IWDG,
        flash: p.FLASH,
    }
}

/// Address of VREFINT_CAL on the STM32L4: the 12-bit conversion of the internal reference at
/// VDDA = 3.0 V and 30 °C, written at the factory (datasheet DS10198, "Internal voltage reference calibration values"; ST's LL headers call it `VREFINT_CAL_ADDR`).
const VREFINT_CAL: *const u16 = 0x1FFF_75AA as *const u16;

/// The analog inputs, oversampled as configured in [`init`].
pub struct Analog {
    adc: Adc<'static, ADC1>,
    rtd: AnyAdcChannel<'static, ADC1>,
    reference: AnyAdcChannel<'static, ADC1>,
    supply: AnyAdcChannel<'static, ADC1>,
    vrefint: VrefInt,
}

/// 640.5 ADC cycles of sampling per conversion (the longest: the amplifier's output impedance
/// and the sampling capacitor settle fully, and VREFINT needs ≥ 4 µs) + 12.5 of conversion; 256
/// of them take 2.1 ms at 80 MHz. embassy converts twice on the L4 and keeps the second (an L4
/// ADC erratum: the first conversion after a pause longer than 1 ms may be corrupted), so the
/// four inputs block the executor ≈ 17 ms every Ts — nothing else in it is that time-critical.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES640_5;

impl Analog {
    /// The modules' supply, V (`None` if the reference reads 0 or the calibration word is blank).
    pub fn supply_v(&mut self) -> Option<f32> {
        let supply = u32::from(self.adc.blocking_read(&mut self.supply, SAMPLE_TIME));
        let vrefint = u32::from(self.adc.blocking_read(&mut self.vrefint, SAMPLE_TIME));
        // SAFETY: a 16-bit read of the factory calibration word in system memory, which is
        // always mapped and read-only.
        let cal = unsafe { core::ptr::read_volatile(VREFINT_CAL) };
        crate::config::SUPPLY.volts(supply, vrefint, cal)
    }
}

impl hter::hal::RtdSampler for Analog {
    type Error = core::convert::Infallible;

    /// The ratio of the RTD and reference-resistor conversions, in counts of
    /// `AdcFrontEnd::DEFAULT.full_scale_counts`.
    fn sample(&mut self) -> Result<u32, Self::Error> {
        let signal = u32::from(self.adc.blocking_read(&mut self.rtd, SAMPLE_TIME));
        let reference = u32::from(self.adc.blocking_read(&mut self.reference, SAMPLE_TIME));
        Ok(hter::adc::ratiometric_counts(signal, reference, crate::config::CARRIER.adc.full_scale_counts))
    }
}
