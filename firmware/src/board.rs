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
//! | SSR input (SSR build) | PA6 (TIM3_CH1) | D12 (CN5-5) | Crydom CMX60D10 (or any DC SSR) input, 3–32 V, through 330 Ω; the SSR switches the Peltier modules' 12 V |
//! | buck high-side gate (`buck` build) | PA8 (TIM1_CH1, AF1) | D7 (CN9-8) | HI input of a half-bridge gate driver (UCC27211-class, independent HI/LI inputs, bootstrap high side), 10 kΩ pull-down; the driver switches the synchronous buck's high-side N-MOSFET (README, "The buck drive") |
//! | buck low-side gate (`buck` build) | PA7 (TIM1_CH1N, AF1) | D11 (CN5-4) | LI input of the same driver, 10 kΩ pull-down; PB13 (TIM1_CH1N, CN10-30) is the other pin TIM1_CH1N reaches |
//! | supply enable | PB0 | A3 (CN8-4) | gate driver of a high-side P-MOSFET switch in series with the SSR and the modules; high = power allowed; pulled down, so a reset or a dead MCU removes power |
//! | status LED | PA5 | LD2 (on board) | on while cooling is enabled |
//! | switched rail | PC0 (ADC1_IN1) | A5 (CN8-6) | 47 kΩ from the modules' side of the supply-enable switch (after the P-MOSFET) to PC0, 10 kΩ to AGND, 100 nF across the 10 kΩ: reads the rail the modules really see, so a shorted switch shows as voltage while the switch is open |
//! | modules' side of the SSR (`module-sense` build) | PC1 (ADC1_IN2) | A4 (CN8-5) | 47 kΩ from the SSR's load terminal (the modules' supply side) to PC1, 10 kΩ to AGND, 100 nF across the 10 kΩ (τ 0.8 ms: settled ≥ 20 ms before it is read), and a BAT54 Schottky from AGND (anode) to PC1: the modules' Seebeck voltage reverses when the load is warmer than the room (up to −0.56 V at the pin, past the −0.3 V the pin allows). Read in the conversion window after the RTD, where the SSR is off at every duty below full: a shorted SSR reads the supply (`hter::supervisor::module`, README "The module-side sense") |
//! | alarm output | PC7 | D9 (CN5-2) | a buzzer or red lamp through a low-side NPN/N-MOSFET driver; high = alarm (`hter::alarm`); the second path to the buzzer beside the heartbeat |
//! | heartbeat | PB5 | D4 (CN9-5) | one 10 µs high pulse per healthy control step ([`heartbeat_pulse`]; a rising edge every Ts, where a toggled level gave the 74HC123's one trigger edge every 2·Ts, past its 15 s) into a retriggerable monostable (74HC123, timeout ≈ 15 s = 1.5·Ts): its output silences the buzzer only while edges arrive, and is ANDed into the supply-enable gate drive, so a reset, hung or dead MCU (pins Hi-Z) sounds the buzzer and opens the supply within 2·Ts without software (README, wiring) |
//! | acknowledge button | PC13 | B1 (on board, blue) | pressed pulls low (the Nucleo's pull-up); clears a latched alarm; held through a reset, a service reset ([`button_held`]) |
//! | settings interface TX | PA2 (USART2_TX, AF7) | ST-LINK VCP (on board) | the ST-LINK's virtual COM port (UM1724: SB13/SB14 closed and SB62/SB63 open, as shipped; then PA2/PA3 are not on CN9 D1/D0); 115200 8N1 ([`serial_config`]) |
//! | settings interface RX | PA3 (USART2_RX, AF7) | ST-LINK VCP (on board) | as TX |
//!
//! The supply-enable switch is the independent second cut-off: SSRs usually fail shorted, and
//! the supervisor must be able to stop cooling regardless.
//!
//! Clocks: MSI at 4 MHz, locked to the Nucleo's 32.768 kHz LSE crystal (X2 on PC14/PC15) by the
//! MSI PLL mode (MSIPLLEN; ± the crystal's 20 ppm instead of the ±1 % of HSI16), → PLL → 80 MHz.
//! TIM2 (embassy's time driver) and so the millisecond clock run from it. A board without
//! the crystal hangs in the LSE start-up until the watchdog resets it: fit one.
//!
//! Interrupts: USART2 (the settings interface, `crate::serial`, feature `serial`) is bound to embassy's buffered
//! UART handler ([`SerialIrqs`]) at a lower urgency than TIM7's stall check.
//!
//! Timers: TIM2 is the time driver, TIM3 the SSR PWM, TIM7 the control-stall check (its
//! interrupt at the highest priority, so it preempts the executor). The `buck` build drives the
//! modules through a synchronous buck from TIM1, the advanced timer (CH1 and CH1N, complementary,
//! `config::BUCK_PWM_HZ` with `config::BUCK_DEAD_TIME_TICKS` of dead time, `Buck`), and
//! keeps TIM3 running at 1 Hz without a pin as the sample clock: the RTD is still converted at
//! a fixed phase of TIM3's period ([`Analog::sample`]), so both builds sample alike.
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

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime, VrefInt};
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals::{OversamplingRatio, OversamplingShift, Rovsm, Trovs};
use embassy_stm32::peripherals::ADC1;
#[cfg(feature = "buck")]
use embassy_stm32::peripherals::TIM1;
#[cfg(not(feature = "buck"))]
use embassy_stm32::peripherals::TIM3;
#[cfg(feature = "interface")]
use embassy_stm32::peripherals::{PA2, PA3, USART2};
use embassy_stm32::time::Hertz;
#[cfg(feature = "buck")]
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin, Ossi, Ossr};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
#[cfg(not(feature = "buck"))]
use embassy_stm32::timer::simple_pwm::SimplePwm;
use embassy_stm32::Peri;
use embassy_time::Timer;
use hter::adc::SupplySense;

use crate::config;

/// The persistence regions (the log, then the records: `config::LOG_RANGE` and
/// `config::PERSIST_RANGE`, relative to the flash base) as absolute addresses, for the NMI
/// handler's ECC check.
pub const PERSIST_ADDRESSES: core::ops::Range<u32> =
    FLASH_BASE + config::LOG_RANGE.start..FLASH_BASE + config::PERSIST_RANGE.end;
const _: () = assert!(config::LOG_RANGE.end <= config::PERSIST_RANGE.start);

/// The flash's base address (0x0800_0000): `config::PERSIST_RANGE` and embassy's `Flash` count
/// from it, the NMI's FLASH_ECCR address and the ECC note are absolute.
pub const FLASH_BASE: u32 = embassy_stm32::flash::FLASH_BASE as u32;

/// The board's peripherals, initialised.
pub struct Board {
    /// The analog inputs: RTD, reference resistor, supply, switched rail, VREFINT.
    pub analog: Analog,
    /// SSR PWM timer.
    #[cfg(not(feature = "buck"))]
    pub ssr: SimplePwm<'static, TIM3>,
    /// The buck's half bridge (TIM1; TIM3 stays the sample clock, owned by [`Analog`]).
    #[cfg(feature = "buck")]
    pub buck: Buck,
    /// Supply-enable output.
    pub supply_enable: Output<'static>,
    /// Status LED.
    pub led: Output<'static>,
    /// Alarm indicator output (buzzer or lamp driver).
    pub alarm: Output<'static>,
    /// Heartbeat into the alarm's monostable.
    pub heartbeat: Output<'static>,
    /// The user button (acknowledges the alarm).
    pub button: Input<'static>,
    /// Flash controller (persisted records, `config::PERSIST_RANGE`).
    pub flash: Peri<'static, embassy_stm32::peripherals::FLASH>,
    /// The settings interface's UART and pins (`crate::serial` configures them).
    #[cfg(feature = "interface")]
    pub serial: SerialPins,
}

/// USART2 and its pins on the ST-LINK's virtual COM port.
#[cfg(feature = "interface")]
pub struct SerialPins {
    /// The UART.
    pub usart: Peri<'static, USART2>,
    /// PA2, USART2_TX (AF7).
    pub tx: Peri<'static, PA2>,
    /// PA3, USART2_RX (AF7).
    pub rx: Peri<'static, PA3>,
}

// Binding puts the handler in the vector table: only in builds that serve the interface.
#[cfg(feature = "interface")]
embassy_stm32::bind_interrupts!(
    /// USART2's interrupt drives the settings interface's ring buffers.
    pub struct SerialIrqs {
        USART2 => embassy_stm32::usart::BufferedInterruptHandler<USART2>;
    }
);

/// The settings interface's line: 115200 baud, 8 data bits, no parity, 1 stop bit, no flow
/// control (docs/interface.md).
#[cfg(feature = "interface")]
pub fn serial_config() -> embassy_stm32::usart::Config {
    let mut c = embassy_stm32::usart::Config::default();
    c.baudrate = 115_200;
    c.data_bits = embassy_stm32::usart::DataBits::DataBits8;
    c.parity = embassy_stm32::usart::Parity::ParityNone;
    c.stop_bits = embassy_stm32::usart::StopBits::STOP1;
    c
}

/// USART2's interrupt below TIM7's (P0): a burst of received bytes never delays the stall check.
/// Call before the UART is created (embassy enables the interrupt and keeps its priority).
#[cfg(feature = "interface")]
pub fn serial_interrupt_priority() {
    interrupt::USART2.set_priority(interrupt::Priority::P2);
}

/// Starts the independent watchdog at [`config::IWDG_RELOAD`]: the first thing `main` does,
/// before the clocks and before flash is read, so no boot path runs without it. Registers only
/// (embassy's `IndependentWatchdog` would reconfigure it and is not used).
pub fn start_watchdog() {
    use pac::iwdg::vals::{Key, Pr};
    let iwdg = pac::IWDG;
    // Starting first (which also starts the LSI) means a hardware-started watchdog and a stopped
    // one take the same path; the reload below replaces the reset value's 0.5 s.
    iwdg.kr().write(|w| w.set_key(Key::START));
    iwdg.kr().write(|w| w.set_key(Key::ENABLE));
    iwdg.pr().write(|w| w.set_pr(Pr::from_bits(config::IWDG_PR)));
    iwdg.rlr().write(|w| w.set_rl(config::IWDG_RELOAD));
    // PVU/RVU: the values cross into the LSI domain within a few LSI cycles. A dead LSI would
    // hold this loop for good, and the watchdog with it (it counts the LSI): the pins stay as the
    // reset left them (Hi-Z, the supply switch pulled open) and the monostable sounds the buzzer.
    while iwdg.sr().read().0 != 0 {}
    iwdg.kr().write(|w| w.set_key(Key::RESET));
    // Halted under a debugger, the watchdog would reset the chip between two steps; only debug
    // builds freeze it, so a release board with a probe attached behaves as in the field. Written
    // both ways: DBGMCU_APB1FZR1 is reset only by a power-on reset (RM0351, "Debug MCU APB1
    // freeze register 1"), so a debug build or a tool that set DBG_IWDG_STOP (st-flash does when
    // it flashes an L4, stlink's `stop_wdg_in_debug`; ST's OpenOCD board files, `STOP_WATCHDOG
    // 1`) leaves it set through the flashing of a release image and every reset after it: a core
    // halted then (a probe left halted, a laptop asleep on the debug port) would hold the
    // watchdog too, with the SSR and the supply switch as they were.
    pac::DBGMCU.apb1fzr1().modify(|w| w.set_iwdg(cfg!(debug_assertions)));
}

/// Feeds the watchdog.
pub fn pet_watchdog() {
    pac::IWDG.kr().write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// The IWDG_SW option byte is 0: the chip starts the watchdog itself at every reset.
pub fn watchdog_is_hardware() -> bool {
    !pac::FLASH.optr().read().idwg_sw()
}

/// Drives the outputs safe from any context, through the registers alone: the SSR pin to a
/// plain output at low with TIM3's channel 1 disabled (the `buck` build: both gate pins to plain
/// outputs at low, TIM1's main output and both channel-1 outputs disabled), the supply enable
/// low, the alarm on. Works before `init` too (it turns the GPIO clocks on).
pub fn force_safe() {
    use pac::gpio::vals::Moder;
    pac::RCC.ahb2enr().modify(|w| {
        w.set_gpioaen(true);
        w.set_gpioben(true);
        w.set_gpiocen(true);
    });
    // Low first, then output mode: the pin never drives the old level as a plain output.
    #[cfg(not(feature = "buck"))]
    {
        pac::GPIOA.bsrr().write(|w| w.set_br(6, true));
        pac::GPIOA.moder().modify(|w| w.set_moder(6, Moder::OUTPUT));
        // A write to a timer whose clock is off is ignored: harmless before `init`.
        pac::TIM3.ccer().modify(|w| w.set_cce(0, false));
    }
    // Both gates low: the high side off cuts the module's supply, the low side off leaves no
    // path for the module's Seebeck voltage to drive a reverse current (the inductor's current
    // decays through the low side's body diode). Gates first, timer after: the pins stop
    // following TIM1 at once, whatever state the timer is in.
    #[cfg(feature = "buck")]
    {
        pac::GPIOA.bsrr().write(|w| {
            w.set_br(BUCK_HIGH_PIN, true);
            w.set_br(BUCK_LOW_PIN, true);
        });
        pac::GPIOA.moder().modify(|w| {
            w.set_moder(BUCK_HIGH_PIN, Moder::OUTPUT);
            w.set_moder(BUCK_LOW_PIN, Moder::OUTPUT);
        });
        // MOE off sends both outputs to their idle level (OSSI = 1, OIS1 = OIS1N = 0: low); the
        // channel enables off as well, so a later MOE (the timer's automatic output enable is
        // off) changes nothing. Ignored while TIM1's clock is off: harmless before `init`.
        pac::TIM1.bdtr().modify(|w| w.set_moe(false));
        pac::TIM1.ccer().modify(|w| {
            w.set_cce(0, false);
            w.set_ccne(0, false);
        });
    }
    set_supply_switch(false);
    pac::GPIOB.moder().modify(|w| w.set_moder(0, Moder::OUTPUT));
    pac::GPIOC.bsrr().write(|w| w.set_bs(7, true));
    pac::GPIOC.moder().modify(|w| w.set_moder(7, Moder::OUTPUT));
}

/// Clocks: MSI 4 MHz locked to the LSE (embassy sets MSIPLLEN when the LSE is 32.768 kHz) →
/// PLL → 80 MHz system clock; the ADC runs from SYSCLK.
fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.ls = LsConfig::default_lse();
    c.rcc.hsi = false;
    c.rcc.msi = Some(MSIRange::RANGE4M);
    c.rcc.pll = Some(Pll {
        source: PllSource::MSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL40,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2), // 4 MHz × 40 / 2 = 80 MHz (VCO 160 MHz)
    });
    c.rcc.sys = Sysclk::PLL1_R;
    c.rcc.mux.adcsel = mux::Adcsel::SYS;
    c
}

/// Initialises the chip and returns the board.
pub fn init() -> Board {
    // The flash's data cache off for good (it is on from reset, FLASH_ACR = 0x600): the program
    // runs from bank 1 while the persist task erases and writes bank 2, and the L4's data cache
    // can be corrupted by such a read-while-write (errata ES0335, "Data cache might be corrupted
    // during flash memory read-while-write operation"); a cached line of an erased page would
    // also still read as before. embassy-stm32 0.6's L4 flash driver does neither (embassy fixed
    // it later, commit 1b9e614). Never enabled again, so its stale lines need no DCRST.
    pac::FLASH.acr().modify(|w| w.set_dcen(false));
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
    #[cfg(feature = "buck")]
    let buck = Buck::new(p.TIM1, p.PA8, p.PA7);

    #[cfg(not(feature = "buck"))]
    let ssr_pin = PwmPin::new(p.PA6, OutputType::PushPull);
    // TIM3 is 16-bit and clocked at 80 MHz (APB1 ÷ 1): embassy picks the smallest prescaler that
    // fits, PSC + 1 = 1221, ARR = 65520, a period of 1.000014 s and 65521 duty ticks.
    #[cfg(not(feature = "buck"))]
    let ssr =
        SimplePwm::new(p.TIM3, Some(ssr_pin), None, None, None, Hertz(config::SSR_PWM_HZ), CountingMode::EdgeAlignedUp);
    // embedded-hal's `SetDutyCycle` (behind `hter::hal::apply_duty`) counts duty in u16 and
    // embassy unwraps ARR + 1 into it on every write: a clock change that gave ARR = 65535 would
    // panic in the control path, so refuse it here, at boot.
    #[cfg(not(feature = "buck"))]
    defmt::assert!(ssr.max_duty_cycle() <= u32::from(u16::MAX), "SSR PWM: ARR + 1 must fit in u16");
    // The buck build has no SSR: TIM3 counts the same 1 s period without a pin, as the sample
    // clock.
    #[cfg(feature = "buck")]
    start_sample_clock();

    let analog = Analog {
        adc,
        rtd: p.PA0.degrade_adc(),
        reference: p.PA1.degrade_adc(),
        supply: p.PA4.degrade_adc(),
        switched: p.PC0.degrade_adc(),
        #[cfg(feature = "module-sense")]
        module: p.PC1.degrade_adc(),
        vrefint,
    };

    Board {
        analog,
        #[cfg(not(feature = "buck"))]
        ssr,
        #[cfg(feature = "buck")]
        buck,
        // Low until the first good control step: no cooling before the loop runs.
        supply_enable: Output::new(p.PB0, Level::Low, Speed::Low),
        led: Output::new(p.PA5, Level::Low, Speed::Low),
        alarm: Output::new(p.PC7, Level::Low, Speed::Low),
        heartbeat: Output::new(p.PB5, Level::Low, Speed::Low),
        button: Input::new(p.PC13, Pull::None),
        flash: p.FLASH,
        #[cfg(feature = "interface")]
        serial: SerialPins { usart: p.USART2, tx: p.PA2, rx: p.PA3 },
    }
}

/// What the boot found of the supply supervision.
#[derive(Clone, Copy, defmt::Format)]
pub struct PowerCheck {
    /// FLASH_OPTR BOR_LEV as found.
    pub bor_level: u8,
    /// VDD was above the PVD level.
    pub supply_ok: bool,
}

/// Enables the PVD at [`config::PVD_LEVEL`] and checks the brown-out level; a board below
/// [`config::BOR_LEVEL`] has its option bytes reprogrammed, which reloads them and resets (so
/// this returns only when the level is right, when the supply is too low to program now, when
/// the programming failed, or on the reset of a load that did not take:
/// `hter::failsafe::bor_needs_programming`, `csr` is RCC_CSR as read at boot). Call after `init`
/// (PWR's clock) and before the flash store is opened.
pub fn power_check(csr: u32) -> PowerCheck {
    pac::RCC.apb1enr1().modify(|w| w.set_pwren(true));
    pac::PWR.cr2().modify(|w| {
        w.set_pls(pac::pwr::vals::Pls::from_bits(config::PVD_LEVEL));
        w.set_pvde(true);
    });
    // The PVD output settles within its start-up time (≤ a few µs, DS10198); a millisecond of
    // spinning before the first read covers it.
    cortex_m::asm::delay(80_000);
    let bor_level = pac::FLASH.optr().read().bor_lev();
    let supply_ok = supply_ok();
    if hter::failsafe::bor_needs_programming(bor_level, config::BOR_LEVEL, supply_ok, csr) {
        defmt::warn!(
            "brown-out level {} below {}: programming the option bytes (resets)",
            bor_level,
            config::BOR_LEVEL
        );
        program_bor_level(config::BOR_LEVEL);
    }
    PowerCheck { bor_level, supply_ok }
}

/// Whether the acknowledge button is held at boot: a technician's service reset (held while the
/// reset button is pressed and released; `hter::app::Boot::service_reset`).
/// Read twice 50 ms apart: a bounce or a glitch on the line is no service reset.
pub fn button_held(button: &Input<'static>) -> bool {
    if button.is_high() {
        return false;
    }
    embassy_time::block_for(embassy_time::Duration::from_millis(50));
    button.is_low()
}

/// VDD is above the PVD level (PVDO clear): flash may be written.
pub fn supply_ok() -> bool {
    !pac::PWR.sr2().read().pvdo()
}

/// FLASH_SR's error flags (OPERR, PROGERR, WRPERR, PGAERR, SIZERR, PGSERR, MISERR, FASTERR, RDERR,
/// OPTVERR; RM0351 FLASH_SR), each write-1-to-clear.
const FLASH_SR_ERRORS: u32 = 0x0000_C3FA;

/// Writes BOR_LEV into FLASH_OPTR and launches the option-byte load, which resets the chip
/// (RM0351 "Option bytes programming"). Unverified on silicon. Only called with the supply above
/// the PVD level: a write cut by a brown-out can leave the option bytes inconsistent.
fn program_bor_level(level: u8) {
    let flash = pac::FLASH;
    if flash.cr().read().lock() {
        flash.keyr().write_value(0x4567_0123);
        flash.keyr().write_value(0xCDEF_89AB);
    }
    if flash.cr().read().optlock() {
        flash.optkeyr().write_value(0x0819_2A3B);
        flash.optkeyr().write_value(0x4C5D_6E7F);
    }
    while flash.sr().read().bsy() {}
    // Clear every error flag (write 1): a stale one would refuse the start.
    flash.sr().write_value(pac::flash::regs::Sr(FLASH_SR_ERRORS));
    flash.optr().modify(|w| w.set_bor_lev(level));
    flash.cr().modify(|w| w.set_optstrt(true));
    while flash.sr().read().bsy() {}
    // A refused or failed write (write protection, a programming error): no load, which would
    // reset into the same state; lock again and boot at the level there is (`power_check`'s
    // caller logs it).
    if flash.sr().read().0 & FLASH_SR_ERRORS != 0 {
        flash.sr().write_value(pac::flash::regs::Sr(FLASH_SR_ERRORS));
        flash.cr().modify(|w| {
            w.set_optlock(true);
            w.set_lock(true);
        });
        defmt::warn!("brown-out level: the option bytes were not programmed; running at the old level");
        return;
    }
    flash.cr().modify(|w| w.set_obl_launch(true));
    // OBL_LAUNCH resets the chip; should it not, the watchdog does.
    loop {
        cortex_m::asm::nop();
    }
}

/// Whole seconds since the last completed control step, counted by TIM7's interrupt.
static SINCE_STEP_S: AtomicU32 = AtomicU32::new(0);

/// Starts the control-stall check: TIM7 interrupts once a second at the highest priority and,
/// once [`config::STALL_LIMIT_MS`] pass without [`note_step`], stops cooling, records the stall
/// and resets (`failsafe::stall`). A hang inside a critical section masks it; the watchdog
/// covers that.
pub fn start_stall_check() {
    pac::RCC.apb1enr1().modify(|w| w.set_tim7en(true));
    let tim = pac::TIM7;
    // 80 MHz / 8000 = 10 kHz, / 10000 = 1 Hz.
    tim.psc().write_value(8000 - 1);
    tim.arr().write(|w| w.set_arr(10_000 - 1));
    tim.egr().write(|w| w.set_ug(true));
    tim.sr().write_value(pac::timer::regs::SrCore(0));
    tim.dier().write(|w| w.set_uie(true));
    tim.cr1().write(|w| w.set_cen(true));
    SINCE_STEP_S.store(0, Ordering::Relaxed);
    interrupt::TIM7.set_priority(interrupt::Priority::P0);
    // SAFETY: the handler below touches only TIM7 and an atomic; no critical section relies on
    // TIM7 being masked.
    unsafe { interrupt::TIM7.enable() };
}

/// One heartbeat: PB5 high for ≈ 10 µs (800 cycles at 80 MHz, ≫ the 74HC123's minimum trigger
/// width of tens of ns), then low again. A 74HC123 retriggers on one edge polarity only (B
/// rising with A low, or A falling with B high; its function table): a level toggled once per
/// step would give it one trigger every 2·Ts = 20 s against its 15 s timeout, and the healthy
/// board's supply would open and its buzzer sound 5 s in every 20. A pulse gives a rising edge
/// every step; a hung or reset MCU (PB5 stuck, or Hi-Z and pulled down) gives none.
pub fn heartbeat_pulse(pin: &mut Output<'static>) {
    pin.set_high();
    cortex_m::asm::delay(800);
    pin.set_low();
}

/// A control step completed.
pub fn note_step() {
    SINCE_STEP_S.store(0, Ordering::Relaxed);
}

#[interrupt]
fn TIM7() {
    pac::TIM7.sr().write_value(pac::timer::regs::SrCore(0));
    let s = SINCE_STEP_S.fetch_add(1, Ordering::Relaxed) + 1;
    let ms = s.saturating_mul(1000);
    if ms >= config::STALL_LIMIT_MS {
        crate::failsafe::stall(ms);
    }
}

/// Address of VREFINT_CAL on the STM32L4: the 12-bit conversion of the internal reference at
/// VDDA = 3.0 V and 30 °C, written at the factory (datasheet DS10198, "Internal voltage reference calibration values"; ST's LL headers call it `VREFINT_CAL_ADDR`).
const VREFINT_CAL: *const u16 = 0x1FFF_75AA as *const u16;

/// Full scale of one oversampled conversion, counts: 256 × 4095 shifted right by 4.
const CONVERSION_FULL_SCALE: u32 = (256 * 4095) >> 4;

/// How many PWM periods the sampler tries to land a conversion inside the window before taking
/// one unsynchronised (a page erase can block the executor for ≈ 22 ms).
const SYNC_ATTEMPTS: u32 = 3;

/// The analog inputs, oversampled as configured in [`init`].
pub struct Analog {
    adc: Adc<'static, ADC1>,
    rtd: AnyAdcChannel<'static, ADC1>,
    reference: AnyAdcChannel<'static, ADC1>,
    supply: AnyAdcChannel<'static, ADC1>,
    switched: AnyAdcChannel<'static, ADC1>,
    /// The modules' side of the SSR (`module-sense` build).
    #[cfg(feature = "module-sense")]
    module: AnyAdcChannel<'static, ADC1>,
    vrefint: VrefInt,
}

/// 640.5 ADC cycles of sampling per conversion (the longest: the amplifier's output impedance
/// and the sampling capacitor settle fully, and VREFINT needs ≥ 4 µs) + 12.5 of conversion; 256
/// of them take 2.1 ms at 80 MHz. embassy converts twice on the L4 and keeps the second (an L4
/// ADC erratum: the first conversion after a pause longer than 1 ms may be corrupted), so each
/// input takes ≈ 4.2 ms and the six conversions of a sample block the executor ≈ 25 ms every Ts
/// (seven, ≈ 29 ms, in the `module-sense` build).
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES640_5;

/// One sample of the analog inputs.
#[derive(Clone, Copy)]
pub struct Conversion {
    /// RTD ratio to the mean of the two reference conversions, counts of
    /// `AdcFrontEnd::DEFAULT.full_scale_counts`.
    pub counts: u32,
    /// Both reference conversions inside `hter::adc::ReferenceWindow::DEFAULT` and agreeing, and
    /// VDDA within `config::VDDA_MIN_V..=VDDA_MAX_V`: otherwise the step treats the sample as a
    /// sensor fault (`Carrier::step_with_reference_fault`).
    pub reference_ok: bool,
    /// The modules' supply ahead of the switch, V (`None` if it could not be measured).
    pub supply_v: Option<f32>,
    /// The switched rail after the switch, V (`None` if it could not be measured).
    pub switched_v: Option<f32>,
    /// The switched rail at the end of a supply-switch test pulse, V (`None`: none was asked
    /// for, or it could not be measured).
    pub switch_test_v: Option<f32>,
    /// The modules' side of the SSR read in the conversion window, V (`None`: it could not be
    /// measured, or the conversion did not end inside the window; `module-sense` build).
    #[cfg(feature = "module-sense")]
    pub module_v: Option<f32>,
    /// VDDA from VREFINT, V (`None` if it could not be measured).
    pub vdda_v: Option<f32>,
    /// The RTD conversion landed inside the sampling window of the SSR PWM period.
    pub in_window: bool,
}

/// A supply-switch test pulse is wanted with the next sample: set by the actuator when the step
/// asks for one with the switch closed (`hter::step::StepOutput::switch_test`), cleared by the
/// actuator whenever it opens the switch, and by the pulse.
pub static SWITCH_TEST: AtomicBool = AtomicBool::new(false);

/// The supply-enable pin (PB0) through its set/reset register: for [`force_safe`], and for the
/// test pulse inside [`Analog::sample`], where the actuator owns the pin's `Output` and the two
/// never interleave (the pulse runs before the sample is handed over, so no new actuation can
/// come in between).
fn set_supply_switch(closed: bool) {
    pac::GPIOB.bsrr().write(|w| if closed { w.set_bs(0, true) } else { w.set_br(0, true) });
}

/// The buck's compare and output enables, as the actuator left them, while a test pulse drives
/// the buck at its ceiling.
#[cfg(feature = "buck")]
struct BuckHeld {
    ccr: u16,
    ccer: pac::timer::regs::CcerAdv,
}

/// Drives the buck at [`config::BUCK_MAX_DUTY`], both gates switching, for a test pulse: the
/// input capacitor empties into the module within ≈ 0.2 ms, where at a low duty a synchronous
/// buck would hold it at the module's Seebeck voltage ÷ D (`hter::supervisor::switch`). Called
/// with the switch already open, so the module never sees the ceiling from the supply.
#[cfg(feature = "buck")]
fn buck_at_ceiling() -> BuckHeld {
    let tim = pac::TIM1;
    let held = BuckHeld { ccr: tim.ccr(0).read().ccr(), ccer: tim.ccer().read() };
    buck_write(buck_ticks(config::BUCK_MAX_DUTY), true, true);
    held
}

/// Full duty in TIM1 compare ticks, ARR + 1 (2000 at 40 kHz); the duty's u16 (embedded-hal)
/// holds it for any frequency above the 1.2 kHz where ARR would reach 65535.
#[cfg(feature = "buck")]
fn buck_full_ticks() -> u16 {
    (u32::from(pac::TIM1.arr().read().arr()) + 1).min(u32::from(u16::MAX)) as u16
}

/// The duty `d` in TIM1 compare ticks.
#[cfg(feature = "buck")]
fn buck_ticks(d: f32) -> u16 {
    (d * f32::from(buck_full_ticks())) as u16
}

/// CCR1 and the enables of the high side (CH1) and the low side (CH1N) through the registers:
/// embassy's `set_duty` would re-read the period and assert on every write, and its `enable`
/// sets CC1E and CC1NE only together.
#[cfg(feature = "buck")]
fn buck_write(ccr: u16, high: bool, low: bool) {
    pac::TIM1.ccr(0).write(|w| w.set_ccr(ccr));
    pac::TIM1.ccer().modify(|w| {
        w.set_cce(0, high);
        w.set_ccne(0, low);
    });
}

#[cfg(feature = "buck")]
impl BuckHeld {
    /// Puts the actuator's duty back (before the switch closes again).
    fn restore(self) {
        pac::TIM1.ccr(0).write(|w| w.set_ccr(self.ccr));
        pac::TIM1.ccer().write_value(self.ccer);
    }
}

fn tim3_update_pending() -> bool {
    pac::TIM3.sr().read().uif()
}

fn tim3_clear_update() {
    // rc_w0: writing 0 clears UIF, the 1s leave the other flags alone.
    pac::TIM3.sr().write_value(pac::timer::regs::SrGp16(!1));
}

/// TIM3 ticks in `ms` of the PWM period (ARR + 1 ticks per 1 / SSR_PWM_HZ s).
fn tim3_ticks(ms: u32) -> u32 {
    let per_period = u32::from(pac::TIM3.arr().read().arr()) + 1;
    per_period * config::SSR_PWM_HZ * ms / 1000
}

impl Analog {
    fn read(&mut self, which: Ain) -> u32 {
        let ch = match which {
            Ain::Rtd => &mut self.rtd,
            Ain::Reference => &mut self.reference,
            Ain::Supply => &mut self.supply,
            Ain::Switched => &mut self.switched,
            #[cfg(feature = "module-sense")]
            Ain::Module => &mut self.module,
        };
        u32::from(self.adc.blocking_read(ch, SAMPLE_TIME))
    }

    /// Waits for the start of an SSR PWM period (TIM3's update, where the SSR drive rises),
    /// then for the start of [`config::SAMPLE_WINDOW`], and converts reference, RTD, reference;
    /// a sample that ends in the next period is retaken. Then the supplies and VREFINT, whose
    /// readings do not care about the phase.
    pub async fn sample(&mut self) -> Conversion {
        let window = config::SAMPLE_WINDOW;
        let mut attempt = 0;
        let (signal, before, after, in_window) = loop {
            attempt += 1;
            tim3_clear_update();
            while !tim3_update_pending() {
                Timer::after_millis(1).await;
            }
            tim3_clear_update();
            Timer::after_millis(u64::from(window.start_ms)).await;
            let started = u32::from(pac::TIM3.cnt().read().cnt()) >= tim3_ticks(window.start_ms);
            let before = self.read(Ain::Reference);
            let signal = self.read(Ain::Rtd);
            let after = self.read(Ain::Reference);
            let in_window = started && !tim3_update_pending();
            if in_window || attempt >= SYNC_ATTEMPTS {
                break (signal, before, after, in_window);
            }
        };
        // The modules, right after the RTD and still in the window (≈ 17 ms of its 30 with the
        // four conversions), where the SSR has been off ≥ 10 ms at any duty below full. A
        // conversion that ended in the next period may have seen the SSR's rising edge: none.
        #[cfg(feature = "module-sense")]
        let module = {
            let counts = self.read(Ain::Module);
            (in_window && !tim3_update_pending()).then_some(counts)
        };
        // Both references in their window and agreeing; their mean is the reference at the RTD
        // conversion's midpoint.
        let reference = hter::adc::ReferenceWindow::DEFAULT.check(before, after);
        let supply = self.read(Ain::Supply);
        let switched = self.read(Ain::Switched);
        let vrefint = u32::from(self.adc.blocking_read(&mut self.vrefint, SAMPLE_TIME));
        // SAFETY: a 16-bit read of the factory calibration word in system memory, which is
        // always mapped and read-only.
        let cal = unsafe { core::ptr::read_volatile(VREFINT_CAL) };
        // VDDA is a supply reading through a 1:1 "divider" of VREFINT.
        let vdda_v = SupplySense { divider: 1.0, ..config::SUPPLY }.volts(CONVERSION_FULL_SCALE, vrefint, cal);
        // The test pulse the last output asked for (`hter::supervisor::switch`): the switch
        // opened with the drive running, the rail read at its end, the switch closed again
        // unless the actuator opened it meanwhile. After the RTD's window, so the rail's step
        // never lands in a conversion that counts.
        let switch_test_v = if SWITCH_TEST.load(Ordering::Relaxed) {
            set_supply_switch(false);
            #[cfg(feature = "buck")]
            let held = buck_at_ceiling();
            Timer::after_millis(u64::from(hter::supervisor::switch::TEST_PULSE_MS)).await;
            let rail = self.read(Ain::Switched);
            #[cfg(feature = "buck")]
            held.restore();
            if SWITCH_TEST.swap(false, Ordering::Relaxed) {
                set_supply_switch(true);
            }
            config::SUPPLY.volts(rail, vrefint, cal)
        } else {
            None
        };
        let vdda_ok = vdda_v.is_some_and(|v| (config::VDDA_MIN_V..=config::VDDA_MAX_V).contains(&v));
        let counts = match reference {
            Ok(r) => hter::adc::ratiometric_counts(signal, r, config::CARRIER.adc.full_scale_counts),
            Err(_) => 0,
        };
        Conversion {
            counts,
            reference_ok: reference.is_ok() && vdda_ok,
            supply_v: config::SUPPLY.volts(supply, vrefint, cal),
            switched_v: config::SUPPLY.volts(switched, vrefint, cal),
            switch_test_v,
            #[cfg(feature = "module-sense")]
            module_v: module.and_then(|m| config::SUPPLY.volts(m, vrefint, cal)),
            vdda_v,
            in_window,
        }
    }
}

/// Which analog input to convert.
#[derive(Clone, Copy)]
enum Ain {
    Rtd,
    Reference,
    Supply,
    Switched,
    /// The modules' side of the SSR (`module-sense` build).
    #[cfg(feature = "module-sense")]
    Module,
}

/// Starts TIM3 as the `buck` build's sample clock: the SSR build's period (PSC + 1 = 1221,
/// ARR + 1 = 65521 at 80 MHz: 1.000014 s, what embassy's `SimplePwm` picks for
/// `config::SSR_PWM_HZ`) with no channel and no pin, through the registers (a second embassy
/// timer driver beside TIM1's costs ≈ 0.5 KB the 64 KiB budget does not have). [`Analog::sample`]
/// waits on its update flag as in the SSR build.
#[cfg(feature = "buck")]
fn start_sample_clock() {
    pac::RCC.apb1enr1().modify(|w| w.set_tim3en(true));
    let tim = pac::TIM3;
    tim.psc().write_value(1221 - 1);
    tim.arr().write(|w| w.set_arr(65521 - 1));
    // Load PSC and ARR now, then count.
    tim.egr().write(|w| w.set_ug(true));
    tim.cr1().write(|w| w.set_cen(true));
}

/// GPIOA pin of the buck's high-side gate (TIM1_CH1, AF1): [`force_safe`] drives it low.
#[cfg(feature = "buck")]
const BUCK_HIGH_PIN: usize = 8;
/// GPIOA pin of the buck's low-side gate (TIM1_CH1N, AF1): [`force_safe`] drives it low.
#[cfg(feature = "buck")]
const BUCK_LOW_PIN: usize = 7;

/// The synchronous buck's half bridge on TIM1 channel 1: CH1 (PA8) gates the high-side MOSFET,
/// CH1N (PA7) the low-side one, complementary, with [`config::BUCK_DEAD_TIME_TICKS`] of dead time
/// on each edge. Duty = the high side's on-time fraction = module voltage / supply, the
/// controller's output as it is ([`hter::hal::apply_duty`] through `SetDutyCycle`).
///
/// Off states: duty 0 disables both outputs (driven at their inactive level, low: OSSR = 1);
/// below [`config::BUCK_SYNC_MIN_DUTY`] the low side stays off and the inductor freewheels
/// through its body diode (diode emulation: the module's Seebeck voltage can exceed duty ×
/// supply there, and a conducting low side would let it drive the current backwards, heating
/// the load); the high side is held below [`config::BUCK_MAX_DUTY`] so the bootstrap capacitor
/// of the high-side driver recharges every period. With the main output off (MOE = 0, what
/// [`force_safe`] sets) both gates sit at their idle level, low (OSSI = 1).
#[cfg(feature = "buck")]
pub struct Buck {
    /// Never dropped (its drop would stop TIM1's clock with the gates wherever they were; the
    /// actuation task owns it for good), so no drop code is linked.
    _pwm: core::mem::ManuallyDrop<ComplementaryPwm<'static, TIM1>>,
    /// The compare value of full duty (ARR + 1).
    max: u16,
    /// [`config::BUCK_MAX_DUTY`] in compare ticks.
    ceiling: u16,
    /// [`config::BUCK_SYNC_MIN_DUTY`] in compare ticks.
    sync_min: u16,
}

#[cfg(feature = "buck")]
impl Buck {
    fn new(
        tim: Peri<'static, TIM1>,
        high: Peri<'static, embassy_stm32::peripherals::PA8>,
        low: Peri<'static, embassy_stm32::peripherals::PA7>,
    ) -> Self {
        let high = PwmPin::new(high, OutputType::PushPull);
        let low = ComplementaryPwmPin::new(low, OutputType::PushPull);
        // TIM1 is clocked at 80 MHz (APB2 ÷ 1): 40 kHz is ARR = 1999, 2000 duty ticks of 12.5 ns.
        let pwm = ComplementaryPwm::new(
            tim,
            Some(high),
            Some(low),
            None,
            None,
            None,
            None,
            None,
            None,
            Hertz(config::BUCK_PWM_HZ),
            CountingMode::EdgeAlignedUp,
        );
        // Dead time and the off states in one BDTR write (embassy's `set_dead_time` and the two
        // `set_off_state_selection_*` are three read-modify-writes and a CKD/DTG search: flash the
        // buck build does not have). CKD stays at its reset value, t_DTS = t_CK_INT, and a DTG
        // below 128 is that many t_DTS ticks (RM0351, TIMx_BDTR.DTG[7:5] = 0xx), so DTG is the
        // dead time in timer ticks.
        const _: () = assert!(config::BUCK_DEAD_TIME_TICKS < 128, "DTG < 128 is the dead time in ticks");
        pac::TIM1.bdtr().modify(|w| {
            w.set_dtg(config::BUCK_DEAD_TIME_TICKS as u8);
            w.set_ossr(Ossr::IDLE_LEVEL);
            w.set_ossi(Ossi::IDLE_LEVEL);
        });
        // Both gates off until the first actuation: embassy leaves CCER at its reset value (both
        // outputs of every channel disabled, inactive level under OSSR = 1) and CCR1 at 0; the
        // automatic output enable (AOE) stays at its reset value, off.
        Buck {
            _pwm: core::mem::ManuallyDrop::new(pwm),
            max: buck_full_ticks(),
            ceiling: buck_ticks(config::BUCK_MAX_DUTY),
            sync_min: buck_ticks(config::BUCK_SYNC_MIN_DUTY),
        }
    }
}

#[cfg(feature = "buck")]
impl embedded_hal::pwm::ErrorType for Buck {
    type Error = core::convert::Infallible;
}

#[cfg(feature = "buck")]
impl embedded_hal::pwm::SetDutyCycle for Buck {
    fn max_duty_cycle(&self) -> u16 {
        self.max
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
        // The compare value is clamped here; the low side switches only from the sync minimum.
        buck_write(duty.min(self.ceiling), duty > 0, duty >= self.sync_min);
        Ok(())
    }
}
