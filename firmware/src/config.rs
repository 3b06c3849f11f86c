//! Build-time configuration: every tunable of the firmware, with its unit and source.
//! Changing the carrier's behaviour means changing this file (or a cargo feature) and reflashing.
//!
//! Controller, chosen by cargo feature (at most one; none is the default, self-tuning GPC):
//!
//! | feature | controller | host equivalent |
//! | --- | --- | --- |
//! | (none) | self-tuning GPC, `hter::profile::ADAPTIVE_GPC`, restarted from the model stored in flash | `hter sim --controller gpc` |
//! | `igmvc` | self-tuning IGMVC, `hter::profile::ADAPTIVE_IGMVC`, restarted from the model stored in flash | `hter sim --controller igmvc` |
//! | `pi` | PI, `hter::profile::PI` (Ziegler–Nichols, detuned 2×) | `hter sim --controller pi` |
//! | `onoff` | On-Off, ±0.3 °C (`OnOffConfig::DEFAULT`) | `hter sim --controller onoff` |
//! | `identify` | open-loop PRBS on the SSR (sensor checks and freeze guard stay on) | `hter sim --scenario prbs` |
//!
//! (`adaptive` is accepted and changes nothing: self-tuning GPC used to need it.)
//!
//! The controllers' tuning and the save cadences are the library's board profile
//! (`hter::profile`), which the simulator and the processor-in-the-loop runner build from too;
//! this file picks from it. Every build keeps the calibration, the cold-chain history and, for
//! the self-tuning controllers, the learned model in flash ([`PERSIST_RANGE`], `hter::persist`).

#[cfg(any(
    all(feature = "pi", any(feature = "onoff", feature = "igmvc", feature = "identify")),
    all(feature = "onoff", any(feature = "igmvc", feature = "identify")),
    all(feature = "igmvc", feature = "identify"),
))]
compile_error!("features `pi`, `onoff`, `igmvc` and `identify` each select a controller: enable at most one");
#[cfg(all(feature = "module-sense", feature = "buck"))]
compile_error!("feature `module-sense` reads the modules in the SSR's off time: the `buck` drive has none");

use hter::adc::SupplySense;
use hter::calib::TwoPoint;
use hter::control::adaptive::AdaptiveConfig;
#[allow(unused_imports)]
use hter::control::{OnOff, OnOffConfig, Pi};
use hter::profile;
use hter::step::{CarrierConfig, ValidConfig};
use hter::supervisor::switch::SwitchConfig;
use hter::supervisor::SupervisorConfig;
#[allow(unused_imports)]
use hter::units::Celsius;

/// Setpoint of the vaccine load, °C: the middle of the lower half of 2–8 °C, where the seed ran
/// its experiments (4 °C) and as far from freezing as from the 8 °C limit allows with margin.
pub const SETPOINT_C: f32 = 4.0;

/// The step's configuration (Ts = 10 s, Pt100 on the default front end, F_a = 0.5, freeze
/// guard at 1.5 °C with a 120 s look-ahead): see `hter::step::CarrierConfig::DEFAULT`. Its
/// calibration is replaced at boot by [`CALIBRATION`] or the one stored in flash.
/// The identification build turns off the supply-switch test pulses (its record holds its
/// excitation and nothing else; the 20 s openings the test once was spoiled the fit, as the
/// simulator's `prbs` runs showed); its switch is still checked whenever the freeze guard or a
/// sensor fault opens it. The buck build's supervisor is the buck's
/// (`hter::supervisor::SupervisorConfig::BUCK`: the lid check takes the cooling the duty pumps,
/// not the duty, and the shorted-drive check waits 45 min for a second trip).
pub const CARRIER: CarrierConfig = CarrierConfig {
    supervisor: SupervisorConfig {
        switch: if cfg!(feature = "identify") {
            SwitchConfig { test_interval_s: 0.0, ..SwitchConfig::DEFAULT }
        } else {
            SwitchConfig::DEFAULT
        },
        ..SUPERVISOR
    },
    ..CarrierConfig::DEFAULT
};

/// The drive's supervisor settings, before this build's own (above).
#[cfg(feature = "buck")]
const SUPERVISOR: SupervisorConfig = SupervisorConfig::BUCK;
#[cfg(not(feature = "buck"))]
const SUPERVISOR: SupervisorConfig = SupervisorConfig::DEFAULT;

/// [`CARRIER`], checked when the firmware is compiled: a setting the step cannot honour (a
/// supervisor window longer than its detector's history, say) fails the build, not the board.
pub const VALID_CARRIER: ValidConfig = match CARRIER.validated() {
    Ok(v) => v,
    Err(_) => panic!("the board's CarrierConfig is refused by CarrierConfig::validate"),
};

/// Two-point calibration of this board's RTD channel, or `None` to keep the one stored in flash
/// (identity if none is stored). Measure it as the seed did (ice bath and a second bath against
/// a reference thermometer; README "Calibrating a board"), fill in the four readings, e.g.
///
/// ```ignore
/// pub const CALIBRATION: Option<TwoPoint> = Some(calibration(0.12, 0.00, 25.31, 25.02));
/// ```
///
/// and flash once: the boot stores it (`Restored::calibration_to_store`, through the write
/// gate), and later images with `None` keep using it. In the interface build it runs only while
/// no settings are stored: once a `set` has stored them, their calibration runs (`set cal_ice`
/// and `set cal_warm` change it, and store the calibration record too), and the boot log says
/// the constant was not run. A pair of points the library refuses
/// (closer than 1 °C, gain outside 0.9–1.1, a correction beyond ±1.5 °C between 0 and 10 °C,
/// not finite) stops the build. The `calibrated` feature builds with the example above, so that
/// `cargo xtask size` holds a calibrated board to the budget too (the constant's store costs
/// ≈ 0.1 KiB of flash).
#[cfg(not(feature = "calibrated"))]
pub const CALIBRATION: Option<TwoPoint> = None;
#[cfg(feature = "calibrated")]
pub const CALIBRATION: Option<TwoPoint> = Some(calibration(0.12, 0.00, 25.31, 25.02));

/// A calibration from (channel reading, reference reading) in the ice bath and in the second
/// bath, °C, checked when the firmware compiles.
#[allow(dead_code)]
pub const fn calibration(
    measured_ice_c: f32,
    reference_ice_c: f32,
    measured_warm_c: f32,
    reference_warm_c: f32,
) -> TwoPoint {
    match TwoPoint::from_points(
        Celsius(measured_ice_c),
        Celsius(reference_ice_c),
        Celsius(measured_warm_c),
        Celsius(reference_warm_c),
    ) {
        Ok(cal) => cal,
        Err(_) => panic!("CALIBRATION refused: the points must be ≥ 1 °C apart, give a gain within 0.9–1.1 and correct 0–10 °C by at most 1.5 °C"),
    }
}

/// Sample period, ms: `CARRIER.ts_s` (10 s) in the time driver's unit.
pub const SAMPLE_PERIOD_MS: u64 = (CARRIER.ts_s * 1000.0) as u64;

/// SSR PWM frequency, Hz: a 1 s period, as the simulator models it (the seed's DAQ drove the
/// SSR with a slow PWM; at 1 Hz the DC SSR's 100 µs switching time costs < 0.02 % of duty).
/// TIM3 at 80 MHz reaches it with prescaler 1221 and ARR 65520 (`board::init`).
pub const SSR_PWM_HZ: u32 = 1;

/// The `buck` build's switching frequency, Hz: ≥ 20 kHz (SPEC §10: above hearing, and a
/// small inductor for ≤ 10 % ripple, README "The buck drive"); TIM1 at 80 MHz gives ARR = 1999,
/// 2000 duty ticks (0.05 % of duty, 6 mV of module voltage at 12 V). At 40 kHz the gate charge
/// and the edges cost ≈ 0.04 W (`hal-sim`'s `plant::buck::SWITCHING_W` budgets 0.1 W in all).
#[cfg(feature = "buck")]
pub const BUCK_PWM_HZ: u32 = 40_000;

/// Dead time between one MOSFET turning off and the other turning on, TIM1 clock ticks of
/// 12.5 ns: 20 = 250 ns, inserted by TIM1's dead-time generator on both edges. It covers a
/// UCC27211-class driver's delay mismatch (≤ 10 ns) and the turn-off of a ≈ 20 nC MOSFET at a
/// few amperes of gate current (≈ 50 ns) several times over; the body diode carries the 2 ×
/// 250 ns per period (2 % at 40 kHz, ≈ 0.7 V × 1.5 A × 2 % ≈ 0.02 W).
#[cfg(feature = "buck")]
pub const BUCK_DEAD_TIME_TICKS: u16 = 20;

/// Below this duty the buck runs without its low side (diode emulation): the module's Seebeck
/// voltage αΔT reaches 0.053 V/K × 55 K ≈ 2.9 V at 43 °C ambient, 24 % of 12 V and 29 % of a
/// 10 V sag, and with the low side on, a duty × supply below it would drive the current
/// backwards (the module then heats the load). 0.30 covers both; the hold duties at 25–43 °C
/// are 0.32–0.72 (hal-sim, buck), synchronous.
#[cfg(feature = "buck")]
pub const BUCK_SYNC_MIN_DUTY: f32 = 0.30;

/// Highest high-side duty: the bootstrap capacitor of the high-side gate driver recharges only
/// while the low side (or its body diode) conducts, so at least 2 % of each period (0.5 µs at
/// 40 kHz, ≫ the capacitor's recharge time constant of ≈ 20 ns) stays with it; full cooling is
/// then 0.98 × supply, a 2 % loss of top speed in a pull-down.
#[cfg(feature = "buck")]
pub const BUCK_MAX_DUTY: f32 = 0.98;

/// Independent watchdog prescaler: LSI ÷ 256 (IWDG_PR = 6), the slowest, so the 12-bit reload
/// reaches tens of seconds.
pub const IWDG_PR: u8 = 6;
/// Independent watchdog reload, LSI ÷ 256 ticks: 3750 ticks = 30.0 s at the LSI's nominal
/// 32 kHz, 28.2–32.5 s over its 29.5–34 kHz spread (datasheet DS10198, "LSI oscillator"):
/// three sample periods, always more than the 2·Ts stall check that acts first. The control
/// task feeds it when its loop starts (`failsafe::boot_done`, with the stall check's start),
/// then only after a completed step. Its longest timeout is 4096 · 256 / 32 kHz = 32.8 s.
pub const IWDG_RELOAD: u16 = 3750 - 1;

// The watchdog's option byte. The board starts the IWDG in software as the first thing `main`
// does, but a reset between the chip's reset and that line (none today; a future boot loader,
// a fault in the runtime's RAM init) would leave it stopped. Programming IWDG_SW = 0 (FLASH_OPTR
// bit 16, "hardware watchdog") makes the chip start the IWDG itself at every reset, before the
// first instruction, with the reset-value reload (4095 at ÷ 4, 0.5 s) until `main` sets 30 s;
// nothing can then stop it. Program it once per board, e.g.
//
//     STM32_Programmer_CLI -c port=SWD -ob IWDG_SW=0
//
// (STM32CubeProgrammer; in its GUI: Option bytes → User configuration → untick IWDG_SW), or
// with OpenOCD (`stm32l4x option_write 0 0x20 0 0x10000`, then `stm32l4x option_load 0`).
// The boot log says which the board has (`watchdog hardware (option byte)` / `watchdog software`).

/// Brown-out reset level the board needs (FLASH_OPTR BOR_LEV): 3, reset below ≈ 2.47 V falling
/// / 2.56 V rising (DS10198, "BOR thresholds"). The default level 0 (≈ 1.7 V) lets the CPU run
/// where the 1 mA excitation source from VDDA and the amplifier have no headroom; level 3 keeps
/// the core in reset there, and sits below the PVD level ([`PVD_LEVEL`]) so writes stop first.
/// A board below this level is reprogrammed once at boot (`board::power_check`).
pub const BOR_LEVEL: u8 = 3;

/// Power voltage detector level (PWR_CR2 PLS): 6, PVDO set below ≈ 2.84 V falling / 2.96 V
/// rising (DS10198, "PVD thresholds"). Flash writes wait while VDD is under it: a page erase or a
/// double-word program cut by a brown-out leaves an ECC error behind.
pub const PVD_LEVEL: u8 = 6;

/// VDDA window in which an RTD sample is trusted, V: the Nucleo's 3.3 V ± 10 % rail is 3.0–3.6 V
/// (the L4's analog supply range is 1.62–3.6 V; below 3.0 V the excitation source and the
/// amplifier, designed for 3.3 V, lose headroom). Outside it the step gets a sensor fault.
pub const VDDA_MIN_V: f32 = 3.0;
/// Upper end of the VDDA window, V (the L4's absolute VDDA maximum of operation, DS10198).
pub const VDDA_MAX_V: f32 = 3.6;

/// Control stall limit, ms: two sample periods without a completed step stop cooling and reset
/// (checked once a second by TIM7's interrupt, which preempts the executor).
pub const STALL_LIMIT_MS: u32 = hter::failsafe::STALL_SAMPLES * SAMPLE_PERIOD_MS as u32;

/// Where in the SSR PWM period the reference, RTD, reference conversions happen: the last 30 ms
/// of the 1 s period, with the duty quantised so the SSR's falling edge stays 10 ms clear of it
/// (`hter::adc::SampleWindow::DEFAULT`, the simulator's too). The three conversions take
/// 3 × 2 × 2.1 ms = 12.6 ms (`board::SAMPLE_TIME`); one that ends in the next period is retaken.
pub const SAMPLE_WINDOW: hter::adc::SampleWindow = hter::adc::SampleWindow::DEFAULT;

/// The modules' supply measurement: 47 kΩ over 10 kΩ into PA4, VDDA from VREFINT
/// (`hter::adc::SupplySense::DEFAULT`). The step reports a sag below 10.8 V
/// (`hter::supervisor::supply::SupplyConfig::min_v`).
pub const SUPPLY: SupplySense = SupplySense::DEFAULT;

/// The self-tuner this build runs, if any (its model is restored from and saved to flash):
/// the board profile's self-tuning GPC (N2 = 30, Nu = 3, λ = 3, T-filter τ = 0.8; RLS
/// λ_f = 0.995), or IGMVC (λ = 0.5, P pole 0.93, T pole 0.9) in the `igmvc` build, from the
/// H-TER I start model with the profile's PI as the bumpless fallback.
pub const ADAPTIVE: Option<AdaptiveConfig> = if cfg!(any(feature = "pi", feature = "onoff", feature = "identify")) {
    None
} else if cfg!(feature = "igmvc") {
    Some(profile::ADAPTIVE_IGMVC)
} else {
    Some(profile::ADAPTIVE_GPC)
};

/// Identification excitation, as `hter sim --scenario prbs` plays it: a 7-bit PRBS (period 127
/// bits), each bit held 12 samples = 120 s, so one period is 4.2 h; levels 0.45 ± 0.1 duty (the
/// README's holding duty; ±0.1 kept the simulated H-TER I load within 2.6–5.6 °C where ±0.2 took
/// it below 2 °C, commit d1a13d1).
#[cfg(feature = "identify")]
pub const PRBS: hter::ident::prbs::PrbsConfig =
    hter::ident::prbs::PrbsConfig { bits: 7, hold: 12, low: 0.35, high: 0.55 };

/// The identification run first holds the PRBS's middle duty for this many samples (2 h, about
/// two of the carrier's slow time constants): the rest `hter identify` takes as the operating
/// point. Precool the load to ≈ 4 °C with a normal build before flashing the identification
/// build, so the rest starts near its equilibrium.
#[cfg(feature = "identify")]
pub const IDENTIFY_REST_SAMPLES: u32 = 2 * 3600 / (CARRIER.ts_s as u32);

/// The controller type of this build: only the selected law is linked (a run-time choice
/// through `AnyController` links all five: the PI build was 64.3 KB with it, 49.6 KB without).
/// The self-tuner, or the PI if its configuration is refused.
#[cfg(not(any(feature = "pi", feature = "onoff", feature = "identify")))]
pub type Ctl = profile::SelfTuningOrPi;
/// The controller type of this build: only the selected law is linked.
#[cfg(feature = "pi")]
pub type Ctl = Pi;
/// The controller type of this build: only the selected law is linked.
#[cfg(feature = "onoff")]
pub type Ctl = OnOff;
/// The controller type of this build: the PRBS, or the PI if the PRBS configuration is refused.
#[cfg(feature = "identify")]
pub type Ctl = Identify;

/// The controller of this build. `adaptive` is the self-tuner's configuration as restored from
/// flash (the built-in one when nothing good is stored); the others ignore it.
#[cfg(not(any(feature = "pi", feature = "onoff", feature = "identify")))]
// Out of line: inlined into the step's constructor, the self-tuner's folded constants were
// stored into the control task's future and copied on from there (−232 B of flash).
#[inline(never)]
pub fn controller(adaptive: Option<AdaptiveConfig>) -> Ctl {
    // Only the start model, its delay and the estimator's P(0) come from flash
    // (`AdaptiveConfig::with_restored`: P(0) is `RESUMED_P0` for the model this self-tuner
    // stored); taking the rest from the constant lets the compiler fold its checks, which
    // `ADAPTIVE_DEFAULT` passed when the firmware compiled.
    let cfg = match adaptive {
        Some(a) => ADAPTIVE_DEFAULT.with_restored(&a),
        None => ADAPTIVE_DEFAULT,
    };
    // Starts from the profile's boot duty (`profile::BOOT_DUTY`), the fallback PI's bias.
    let (ctl, refused) = profile::SelfTuningOrPi::new(cfg, CARRIER.ts_s);
    if let Some(e) = refused {
        // The controller's name is logged at start, so the log shows the PI.
        defmt::error!("self-tuner configuration refused ({}): running PI", e);
    }
    ctl
}

/// The self-tuner's configuration when the boot hands none (no store): this build's built-in.
#[cfg(not(any(feature = "pi", feature = "onoff", feature = "identify")))]
const ADAPTIVE_DEFAULT: AdaptiveConfig = match ADAPTIVE {
    Some(cfg) => cfg,
    None => profile::ADAPTIVE_GPC,
};

// The built-in configuration is valid for this build's law: a profile change that breaks it
// stops the build instead of running the PI on every board.
#[cfg(not(any(feature = "pi", feature = "onoff", feature = "identify")))]
const _: () = assert!(ADAPTIVE_DEFAULT.validate().is_ok(), "the self-tuner's configuration is refused");

/// The controller of this build (the restored self-tuner configuration does not apply).
#[cfg(feature = "pi")]
pub fn controller(_adaptive: Option<AdaptiveConfig>) -> Ctl {
    profile::pi(CARRIER.ts_s)
}

/// The controller of this build (the restored self-tuner configuration does not apply).
#[cfg(feature = "onoff")]
pub fn controller(_adaptive: Option<AdaptiveConfig>) -> Ctl {
    OnOff::new(OnOffConfig::DEFAULT)
}

/// The controller of this build (the restored self-tuner configuration does not apply).
#[cfg(feature = "identify")]
pub fn controller(_adaptive: Option<AdaptiveConfig>) -> Ctl {
    let rest_duty = 0.5 * (PRBS.low + PRBS.high);
    match hter::control::excite::PrbsExcitation::after_rest(PRBS, rest_duty, IDENTIFY_REST_SAMPLES) {
        Ok(p) => Identify::Prbs(p),
        Err(e) => {
            // The controller's name is logged at start, so the log shows the PI.
            defmt::error!("PRBS configuration refused ({}): running PI", e);
            Identify::Pi(profile::pi(CARRIER.ts_s))
        }
    }
}

/// The identification build's controller: the PRBS, or the PI when its configuration is
/// refused (two laws, not the five of `AnyController`).
#[cfg(feature = "identify")]
pub enum Identify {
    /// The excitation.
    Prbs(hter::control::excite::PrbsExcitation),
    /// The fallback.
    Pi(Pi),
}

#[cfg(feature = "identify")]
impl hter::control::Controller for Identify {
    fn update(&mut self, input: &hter::control::ControlInput) -> Result<f32, hter::control::ControlError> {
        match self {
            Identify::Prbs(c) => c.update(input),
            Identify::Pi(c) => c.update(input),
        }
    }

    fn track(&mut self, input: &hter::control::ControlInput, applied: f32) {
        match self {
            Identify::Prbs(c) => c.track(input, applied),
            Identify::Pi(c) => c.track(input, applied),
        }
    }

    fn name(&self) -> &'static str {
        match self {
            Identify::Prbs(c) => c.name(),
            Identify::Pi(c) => c.name(),
        }
    }
}

/// Flash region of the persisted records, as offsets from the flash base 0x0800_0000 (what
/// embassy's `Flash` takes): the last 4 pages of 2 KiB, `PERSIST` in `memory.x`.
pub const PERSIST_RANGE: core::ops::Range<u32> = 0x000F_E000..0x0010_0000;

/// Flash region of the cold-chain log (`hter::persist::log`, a sequential-storage queue of
/// 16-byte entries), offsets from the flash base: bank 2 from its start, 248 pages of 2 KiB
/// (496 KiB, ≈ 50 days of 5-minute intervals and events), `LOG` in `memory.x`; two pages are
/// left free before [`PERSIST_RANGE`].
pub const LOG_RANGE: core::ops::Range<u32> = 0x0008_0000..0x000F_C000;

#[cfg(feature = "interface")]
/// The laws this build links, its default first (`set controller`, `status`'s `controllers`).
pub const LAWS: &[hter::iface::Law] = {
    use hter::iface::Law;
    if cfg!(feature = "igmvc") {
        &[Law::Igmvc, Law::Pi, Law::OnOff]
    } else if cfg!(feature = "pi") {
        &[Law::Pi, Law::Gpc, Law::OnOff]
    } else if cfg!(feature = "onoff") {
        &[Law::OnOff, Law::Gpc, Law::Pi]
    } else {
        &[Law::Gpc, Law::Pi, Law::OnOff]
    }
};

#[cfg(feature = "interface")]
/// The board application's build: this file's step configuration, self-tuner, laws, setpoint
/// and save cadences (`hter::app::App`, which the control task owns).
pub const APP: hter::app::AppConfig = hter::app::AppConfig {
    carrier: VALID_CARRIER,
    adaptive: match ADAPTIVE {
        Some(a) => a,
        None => profile::ADAPTIVE_GPC,
    },
    laws: LAWS,
    setpoint_c: SETPOINT_C,
    firmware: concat!("hter ", env!("CARGO_PKG_VERSION")),
    history_save_samples: HISTORY_SAVE_SAMPLES,
    model_save_samples: MODEL_SAVE_SAMPLES,
};

/// Samples with a trusted, freshly updated estimate (mode `Adaptive`) between model saves:
/// the board profile's `MODEL_SAVE_S` (4 h).
pub const MODEL_SAVE_SAMPLES: u32 = profile::samples(profile::MODEL_SAVE_S, CARRIER.ts_s);

/// Samples between stores of the cold-chain history (an alarm stores at once): the board
/// profile's `HISTORY_SAVE_S` (1 h).
pub const HISTORY_SAVE_SAMPLES: u32 = profile::samples(profile::HISTORY_SAVE_S, CARRIER.ts_s);

/// Samples between cold-chain summaries in the log (MKT, extremes, time out of range): 1 h.
pub const SUMMARY_SAMPLES: u32 = 3600 / (CARRIER.ts_s as u32);

// Flash wear (sequential-storage erases the four pages of `PERSIST` in turn): a model item takes
// 40 bytes (1 key + 31 record bytes in 8-byte words and the 8-byte item header), a history item
// 152 (1 + 138 and the header), a calibration item 24. At the profile's hourly history and
// 4-hourly model cadence each page is erased every 2.1 days, so the L4's 10 000 cycles
// (datasheet DS10198, "NEND") last ≈ 56 years; with the history every 10 minutes, as during an
// excursion, 10 years of excursion (`tests/persist.rs::wear_at_the_firmware_cadence`).
