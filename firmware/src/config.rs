//! Build-time configuration: every tunable of the firmware, with its unit and source.
//! Changing the carrier's behaviour means changing this file (or a cargo feature) and reflashing.
//!
//! Controller, chosen by cargo feature (at most one; none is the default, self-tuning GPC):
//!
//! | feature | controller | host equivalent |
//! | --- | --- | --- |
//! | (none) | self-tuning GPC, [`ADAPTIVE_GPC`], restarted from the model stored in flash | `hter sim --controller gpc` |
//! | `igmvc` | self-tuning IGMVC, [`ADAPTIVE_IGMVC`], restarted from the model stored in flash | `hter sim --controller igmvc` |
//! | `pi` | PI, `PiConfig::HTER1_DEFAULT` (Ziegler–Nichols, detuned 2×) | `hter sim --controller pi` |
//! | `onoff` | On-Off, ±0.3 °C (`OnOffConfig::DEFAULT`) | `hter sim --controller onoff` |
//! | `identify` | open-loop PRBS on the SSR (sensor checks and freeze guard stay on) | `hter sim --scenario prbs` |
//!
//! (`adaptive` is accepted and changes nothing: self-tuning GPC used to need it.)
//!
//! Every build keeps the calibration, the cold-chain history and, for the self-tuning
//! controllers, the learned model in flash ([`PERSIST_RANGE`], `hter::persist`).

#[cfg(any(
    all(feature = "pi", any(feature = "onoff", feature = "igmvc", feature = "identify")),
    all(feature = "onoff", any(feature = "igmvc", feature = "identify")),
    all(feature = "igmvc", feature = "identify"),
))]
compile_error!("features `pi`, `onoff`, `igmvc` and `identify` each select a controller: enable at most one");

use hter::adc::SupplySense;
use hter::calib::TwoPoint;
use hter::control::adaptive::{AdaptiveConfig, SelfTuning};
use hter::control::gpc::GpcConfig;
use hter::control::mv::IgmvcConfig;
use hter::control::{AnyController, Law, OnOff, OnOffConfig, Pi, PiConfig};
use hter::step::CarrierConfig;
#[allow(unused_imports)]
use hter::units::Celsius;

/// Setpoint of the vaccine load, °C: the middle of the lower half of 2–8 °C, where the seed ran
/// its experiments (4 °C) and as far from freezing as from the 8 °C limit allows with margin.
pub const SETPOINT_C: f32 = 4.0;

/// The step's configuration (Ts = 10 s, Pt100 on the default front end, F_a = 0.5, freeze
/// guard at 1.5 °C with a 120 s look-ahead): see `hter::step::CarrierConfig::DEFAULT`. Its
/// calibration is replaced at boot by [`CALIBRATION`] or the one stored in flash.
pub const CARRIER: CarrierConfig = CarrierConfig::DEFAULT;

/// Two-point calibration of this board's RTD channel, or `None` to keep the one stored in flash
/// (identity if none is stored). Measure it as the seed did (ice bath and a second bath against
/// a reference thermometer; README "Calibrating a board"), fill in the four readings, e.g.
///
/// ```ignore
/// pub const CALIBRATION: Option<TwoPoint> = Some(calibration(0.12, 0.00, 25.31, 25.02));
/// ```
///
/// and flash once: the boot stores it, and later images with `None` keep using it. A pair of
/// points the library refuses (closer than 1 °C, gain outside 0.9–1.1, not finite) stops the
/// build.
pub const CALIBRATION: Option<TwoPoint> = None;

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
        Err(_) => panic!("CALIBRATION refused: the points must be ≥ 1 °C apart and give a gain within 0.9–1.1"),
    }
}

/// Sample period, ms: `CARRIER.ts_s` (10 s) in the time driver's unit.
pub const SAMPLE_PERIOD_MS: u64 = (CARRIER.ts_s * 1000.0) as u64;

/// SSR PWM frequency, Hz: a 1 s period, as the simulator models it (the seed's DAQ drove the
/// SSR with a slow PWM; at 1 Hz the DC SSR's 100 µs switching time costs < 0.02 % of duty).
/// TIM3 at 80 MHz reaches it with prescaler 1221 and ARR 65520 (`board::init`).
pub const SSR_PWM_HZ: u32 = 1;

/// Independent watchdog timeout, µs: three sample periods. The control task feeds it only after
/// a completed step, so a hung loop resets the MCU (and the pull-down on the supply-enable line
/// removes power from the modules meanwhile). The IWDG's longest timeout on the L4 is
/// 4096 · 256 / 32 kHz = 32.8 s.
pub const WATCHDOG_TIMEOUT_US: u32 = 30_000_000;

/// The modules' supply measurement: 47 kΩ over 10 kΩ into PA4, VDDA from VREFINT
/// (`hter::adc::SupplySense::DEFAULT`). The step reports a sag below 10.8 V
/// (`CarrierConfig::supply_min_v`).
pub const SUPPLY: SupplySense = SupplySense::DEFAULT;

/// PI tuning at the carrier's sample period (Ziegler–Nichols, detuned 2×;
/// `PiConfig::HTER1_DEFAULT`): the `pi` build's controller and the self-tuners' fallback.
const PI: PiConfig = PiConfig { ts_s: CARRIER.ts_s, ..PiConfig::HTER1_DEFAULT };

/// Self-tuning GPC (N2 = 30, Nu = 3, λ = 3, T-filter τ = 0.8; RLS λ_f = 0.995) starting from the
/// H-TER I model, with the PI as its bumpless fallback — the host's `--controller gpc`.
pub const ADAPTIVE_GPC: AdaptiveConfig =
    AdaptiveConfig { fallback: PI, ..AdaptiveConfig::default_for(Law::Gpc(GpcConfig::DEFAULT)) };

/// Self-tuning IGMVC (λ = 0.5, P pole 0.93, T pole 0.9) on the same estimator and start model,
/// with the same fallback — the host's `--controller igmvc`.
pub const ADAPTIVE_IGMVC: AdaptiveConfig =
    AdaptiveConfig { fallback: PI, ..AdaptiveConfig::default_for(Law::Igmvc(IgmvcConfig::DEFAULT)) };

/// The self-tuner this build runs, if any (its model is restored from and saved to flash).
pub const ADAPTIVE: Option<AdaptiveConfig> = if cfg!(any(feature = "pi", feature = "onoff", feature = "identify")) {
    None
} else if cfg!(feature = "igmvc") {
    Some(ADAPTIVE_IGMVC)
} else {
    Some(ADAPTIVE_GPC)
};

/// Identification excitation, as `hter sim --scenario prbs` plays it: a 7-bit PRBS (period 127
/// bits), each bit held 12 samples = 120 s, so one period is 4.2 h; levels 0.45 ± 0.1 duty (the
/// README's holding duty; ±0.1 kept the simulated H-TER I load within 2.6–5.6 °C where ±0.2 took
/// it below 2 °C, commit d1a13d1).
pub const PRBS: hter::ident::prbs::PrbsConfig =
    hter::ident::prbs::PrbsConfig { bits: 7, hold: 12, low: 0.35, high: 0.55 };

/// The identification run first holds the PRBS's middle duty for this many samples (2 h, about
/// two of the carrier's slow time constants): the rest `hter identify` takes as the operating
/// point. Precool the load to ≈ 4 °C with a normal build before flashing the identification
/// build, so the rest starts near its equilibrium.
pub const IDENTIFY_REST_SAMPLES: u32 = 2 * 3600 / (CARRIER.ts_s as u32);

/// The controller of this build. `adaptive` is the self-tuner's configuration as restored from
/// flash (the built-in one when nothing good is stored); the others ignore it.
pub fn controller(adaptive: Option<AdaptiveConfig>) -> AnyController {
    if cfg!(feature = "identify") {
        let rest_duty = 0.5 * (PRBS.low + PRBS.high);
        return match hter::control::excite::PrbsExcitation::after_rest(PRBS, rest_duty, IDENTIFY_REST_SAMPLES) {
            Ok(p) => AnyController::Prbs(p),
            Err(e) => {
                // The controller's name is logged at start, so the log shows the PI.
                defmt::error!("PRBS configuration refused ({}): running PI", e);
                AnyController::Pi(Pi::new(PI))
            }
        };
    }
    if cfg!(feature = "onoff") {
        return AnyController::OnOff(OnOff::new(OnOffConfig::DEFAULT));
    }
    match adaptive {
        // Start from the PI's bias: the duty that holds the load near 4 °C.
        Some(cfg) => AnyController::SelfTuning(SelfTuning::new(cfg, PI.bias)),
        None => AnyController::Pi(Pi::new(PI)),
    }
}

/// Flash region of the persisted records, as offsets from the flash base 0x0800_0000 (what
/// embassy's `Flash` takes): the last 4 pages of 2 KiB, `PERSIST` in `memory.x`.
pub const PERSIST_RANGE: core::ops::Range<u32> = 0x000F_E000..0x0010_0000;

/// Samples with a trusted, freshly updated estimate (mode `Adaptive`) between model saves:
/// 4 h at Ts = 10 s. Power lost within 4 h of learning loses at most those 4 h.
pub const MODEL_SAVE_SAMPLES: u32 = 4 * 3600 / (CARRIER.ts_s as u32);

/// Samples between stores of the cold-chain history (an alarm stores at once): 1 h at
/// Ts = 10 s. A power cut loses at most that hour of statistics, never an alarm.
pub const HISTORY_SAVE_SAMPLES: u32 = 3600 / (CARRIER.ts_s as u32);

/// Samples between cold-chain summaries in the log (MKT, extremes, time out of range): 1 h.
pub const SUMMARY_SAMPLES: u32 = 3600 / (CARRIER.ts_s as u32);

// Flash wear (sequential-storage erases the four pages of `PERSIST` in turn): a model item takes
// ≈ 32 bytes (1 key + 23 record bytes and the item header, in 8-byte words), a history item
// ≈ 112 (1 + 96 and the header), a calibration item ≈ 24. At the hourly history and 4-hourly
// model cadence each page is erased every 2.9 days, so the L4's 10 000 cycles (datasheet
// DS10198, "NEND") last ≈ 79 years (`tests/persist.rs::wear_at_the_firmware_cadence`).
