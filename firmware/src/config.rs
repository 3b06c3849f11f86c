//! Build-time configuration: every tunable of the firmware, with its unit and source.
//! Changing the carrier's behaviour means changing this file (or a cargo feature) and reflashing.
//!
//! Controller, chosen by cargo feature (at most one):
//!
//! | feature | controller | host equivalent |
//! | --- | --- | --- |
//! | (none) | PI, `PiConfig::HTER1_DEFAULT` | `hter sim --controller pi` |
//! | `adaptive` | self-tuning GPC, `AdaptiveConfig::default_for(Law::Gpc(GpcConfig::DEFAULT))`, restarted from the model stored in flash | `hter sim --controller gpc` |
//! | `identify` | open-loop PRBS on the SSR (sensor checks and freeze guard stay on) | `hter sim --scenario prbs` |

#[cfg(all(feature = "adaptive", feature = "identify"))]
compile_error!("features `adaptive` and `identify` select different controllers: enable at most one");

#[cfg(not(feature = "adaptive"))]
use hter::control::Pi;
use hter::control::{AnyController, PiConfig};
use hter::step::CarrierConfig;

/// Setpoint of the vaccine load, °C: the middle of the lower half of 2–8 °C, where the seed ran
/// its experiments (4 °C) and as far from freezing as from the 8 °C limit allows with margin.
pub const SETPOINT_C: f32 = 4.0;

/// The step's configuration (Ts = 10 s, Pt100 on the default front end, F_a = 0.5, freeze
/// guard at 1.5 °C with a 120 s look-ahead): see `hter::step::CarrierConfig::DEFAULT`.
pub const CARRIER: CarrierConfig = CarrierConfig::DEFAULT;

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

/// PI tuning at the carrier's sample period (Ziegler–Nichols, detuned 2×;
/// `PiConfig::HTER1_DEFAULT`), also the fallback of the self-tuning controller.
const PI: PiConfig = PiConfig { ts_s: CARRIER.ts_s, ..PiConfig::HTER1_DEFAULT };

/// What `main` hands the control task to build its controller from (inside the task, so the
/// controller lives once in the task's state): the self-tuner's configuration, possibly
/// restored from flash, with `adaptive`; nothing otherwise.
#[cfg(feature = "adaptive")]
pub type ControllerSeed = hter::control::adaptive::AdaptiveConfig;

/// What `main` hands the control task to build its controller from: nothing without `adaptive`.
#[cfg(not(feature = "adaptive"))]
#[derive(Clone, Copy)]
pub struct ControllerSeed;

/// The controller: PI (Ziegler–Nichols, detuned; `PiConfig::HTER1_DEFAULT`).
#[cfg(not(any(feature = "adaptive", feature = "identify")))]
pub fn controller(_: ControllerSeed) -> AnyController {
    AnyController::Pi(Pi::new(PI))
}

/// Self-tuning GPC (N2 = 30, Nu = 3, λ = 3, T-filter τ = 0.8; RLS λ_f = 0.995) starting from the
/// H-TER I model, with the PI as its bumpless fallback — the host's `--controller gpc`. A model
/// restored from flash replaces the starting model (`hter::persist`).
#[cfg(feature = "adaptive")]
pub const ADAPTIVE: hter::control::adaptive::AdaptiveConfig = hter::control::adaptive::AdaptiveConfig {
    fallback: PI,
    ..hter::control::adaptive::AdaptiveConfig::default_for(hter::control::Law::Gpc(
        hter::control::gpc::GpcConfig::DEFAULT,
    ))
};

/// The controller: the self-tuner configured by `cfg` ([`ADAPTIVE`], or it restarted from the
/// stored model).
#[cfg(feature = "adaptive")]
pub fn controller(cfg: ControllerSeed) -> AnyController {
    // Start from the PI's bias: the duty that holds the load near 4 °C (PiConfig::HTER1_DEFAULT).
    AnyController::SelfTuning(hter::control::adaptive::SelfTuning::new(cfg, PI.bias))
}

/// Flash region of the persisted records, as offsets from the flash base 0x0800_0000 (what
/// embassy's `Flash` takes): the last 4 pages of 2 KiB, `PERSIST` in `memory.x`.
#[cfg(feature = "adaptive")]
pub const PERSIST_RANGE: core::ops::Range<u32> = 0x000F_E000..0x0010_0000;

/// Samples with a trusted, freshly updated estimate (mode `Adaptive`) between model saves:
/// 4 h at Ts = 10 s. Wear: a model item takes ≈ 32 bytes of flash (1 key + 23 record bytes
/// and sequential-storage's item header, in 8-byte words), so a 2 KiB page holds ≈ 62 and the
/// 4 pages are erased in turn: each page once per ≈ 250 saves (`wear_per_save` in
/// `tests/persist.rs` measures ≥ 60 saves per erase). At 6 saves a day a page is erased every
/// ≈ 41 days, and the L4's 10 000 cycles (datasheet DS10198, "NEND") last ≈ 1 100 years.
/// Power lost within 4 h of learning loses at most those 4 h.
#[cfg(feature = "adaptive")]
pub const MODEL_SAVE_SAMPLES: u32 = 4 * 3600 / (CARRIER.ts_s as u32);

/// Identification excitation, as `hter sim --scenario prbs` plays it: a 7-bit PRBS (period 127
/// bits), each bit held 12 samples = 120 s, so one period is 4.2 h; levels 0.45 ± 0.1 duty (the
/// README's holding duty; ±0.1 kept the simulated H-TER I load within 2.6–5.6 °C where ±0.2 took
/// it below 2 °C, commit d1a13d1). The board does not settle at the holding duty first as the
/// simulator does: precool to ≈ 4 °C, or let `hter identify` discard the initial drift.
#[cfg(feature = "identify")]
pub const PRBS: hter::ident::prbs::PrbsConfig =
    hter::ident::prbs::PrbsConfig { bits: 7, hold: 12, low: 0.35, high: 0.55 };

/// The controller: the identification PRBS. Should the configuration ever be refused, the PI
/// runs instead and the boot log says so (the controller name is logged at start).
#[cfg(feature = "identify")]
pub fn controller(_: ControllerSeed) -> AnyController {
    match hter::control::excite::PrbsExcitation::new(PRBS) {
        Ok(p) => AnyController::Prbs(p),
        Err(e) => {
            defmt::error!("PRBS configuration refused ({}): running PI", e);
            AnyController::Pi(Pi::new(PI))
        }
    }
}
