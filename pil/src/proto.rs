//! What the host (`cargo xtask pil`) and the target runner agree on: the controllers both build
//! (the board profile's, `hter::profile`),
//! the per-sample work both run, the file formats, and the encoding of events. The runner
//! compiles this file as its module and xtask includes it with `#[path]`, so the two sides
//! cannot drift apart.
//!
//! Input file ([`INPUT_FILE`], little-endian u32 words):
//! `MAGIC_IN, controller kind, n`, then n × [`INPUT_WORDS`] words from [`input_words`]:
//! `t_ms low word, t_ms high word, counts, setpoint_c (f32 bits)`, then the board's other
//! readings as the firmware hands them to the step ([`BoardReadings`], [`Carrier::observe`]:
//! supply, switched rail, test pulse, modules; f32 bits, [`NO_READING`] for none), so that the
//! supply, switch and module checks run as on the board.
//!
//! Output file ([`OUTPUT_FILE`]): `MAGIC_OUT`, the calibration (3 words, [`CAL_LOOP`]), n, then
//! per sample: `duty (f32 bits)`, one SysTick count per entry of [`PARTS`], the number of event
//! word pairs m, and m × `(code, value)` from [`event_words`]; then the runner's peak stack and the size of the carrier + monitor state, bytes.

use hter::coldchain::{ColdChainMonitor, Raised};
use hter::control::adaptive::{AdaptiveConfig, SelfTuning};
use hter::control::fixed::Law;
use hter::control::gpc::GpcConfig;
use hter::control::AnyController;
use hter::profile::{self, Kind};
use hter::step::{BoardReadings, Carrier, StepInput, StepOutput, ValidConfig};

/// Input file name in QEMU's working directory (NUL-terminated for semihosting `SYS_OPEN`).
pub const INPUT_FILE: &str = "pil-in.bin\0";
/// Output file name in QEMU's working directory (NUL-terminated).
pub const OUTPUT_FILE: &str = "pil-out.bin\0";
/// First word of the input file.
pub const MAGIC_IN: u32 = 0x4e49_4c50; // "PLIN"
/// First word of the output file.
pub const MAGIC_OUT: u32 = 0x544f_4c50; // "PLOT"

/// The step's configuration on both sides: the firmware's (`firmware/src/config.rs`).
pub const CARRIER: ValidConfig = ValidConfig::DEFAULT;

/// Controller kind 0: the PI baseline (the firmware's `pi` feature, and the self-tuners'
/// fallback).
pub const KIND_PI: u32 = 0;
/// Controller kind 1: the firmware's default, self-tuning GPC (N2 = 30, Nu = 3).
pub const KIND_GPC: u32 = 1;

/// Controller kind 2: the default self-tuning GPC with λ 200, a heavily damped tuning: the only
/// kind here whose plans meet GPC's soft floor (`hter::control::gpc::GpcStaged`, "Soft floor"),
/// so that `cargo xtask pil` times such a sample (the default's λ 0.5 meets it on one sample of
/// the same case, through the floor's guard row).
pub const KIND_GPC_DAMPED: u32 = 2;

/// The self-tuning GPC configuration the firmware runs by default.
pub const ADAPTIVE: AdaptiveConfig = profile::ADAPTIVE_GPC;

/// [`KIND_GPC_DAMPED`]'s configuration: [`ADAPTIVE`] with λ 200.
pub const DAMPED: AdaptiveConfig =
    AdaptiveConfig { law: Law::Gpc(GpcConfig { lambda: 200.0, ..GpcConfig::DEFAULT }), ..ADAPTIVE };

/// The board-profile controller of a kind code.
fn kind(code: u32) -> Option<Kind> {
    match code {
        KIND_PI => Some(Kind::Pi),
        KIND_GPC => Some(Kind::Gpc),
        _ => None,
    }
}

/// The controller of kind `code`, from the board profile as the firmware builds it: at the
/// step's sample period, a self-tuner starting from the board's boot duty.
pub fn controller(code: u32) -> Option<AnyController> {
    let ts_s = CARRIER.get().ts_s;
    if code == KIND_GPC_DAMPED {
        return SelfTuning::new(DAMPED, ts_s, profile::BOOT_DUTY).ok().map(AnyController::SelfTuning);
    }
    profile::controller(kind(code)?, ts_s, profile::BOOT_DUTY).ok()
}

/// How many samples GPC's soft floor has moved the plan on, modulo 256, for a self-tuning
/// carrier (the host's check that [`KIND_GPC_DAMPED`]'s case meets the floor).
#[allow(dead_code)] // the host reads it, the runner does not
pub fn floor_samples(carrier: &Carrier<AnyController>) -> Option<u8> {
    match carrier.controller() {
        AnyController::SelfTuning(s) => Some(s.law_state().gpc().floor_samples()),
        _ => None,
    }
}

/// A fresh carrier and cold-chain record for `kind`.
pub fn carrier(kind: u32) -> Option<(Carrier<AnyController>, ColdChainMonitor)> {
    let mut carrier = Carrier::new(CARRIER, controller(kind)?);
    // The holdover estimate on the built-in model, as the board's (its per-sample sweep is
    // part of the step's budget).
    carrier.set_holdover_model(Some(profile::START_MODEL_HTER1));
    Some((carrier, ColdChainMonitor::new()))
}

/// The cold-chain record's share of a sample: it is fed what the controller saw.
pub fn monitor_push(monitor: &mut ColdChainMonitor, input: &StepInput, out: &StepOutput) -> Raised {
    monitor.push(input.t_ms, out.temp_c.0)
}

/// Words per sample in the input file.
pub const INPUT_WORDS: usize = 8;

/// The word of a missing reading: a NaN with a payload no conversion gives (a measured NaN is
/// a reading, and goes to the step as one).
pub const NO_READING: u32 = 0x7fc0_dead;

/// One sample's words in the input file (the u64 clock as low word, high word).
#[allow(dead_code)] // the host writes the file, the runner only reads it
pub fn input_words(i: &StepInput, board: &BoardReadings) -> [u32; INPUT_WORDS] {
    let r = |v: Option<f32>| v.map_or(NO_READING, f32::to_bits);
    [
        i.t_ms as u32,
        (i.t_ms >> 32) as u32,
        i.counts,
        i.setpoint_c.to_bits(),
        r(board.supply_v),
        r(board.switched_v),
        r(board.switch_test_v),
        r(board.module_v),
    ]
}

/// The sample of [`input_words`].
pub fn input_of(w: [u32; INPUT_WORDS]) -> (StepInput, BoardReadings) {
    let r = |x: u32| (x != NO_READING).then(|| f32::from_bits(x));
    let input =
        StepInput { t_ms: u64::from(w[0]) | u64::from(w[1]) << 32, counts: w[2], setpoint_c: f32::from_bits(w[3]) };
    (input, BoardReadings { supply_v: r(w[4]), switched_v: r(w[5]), switch_test_v: r(w[6]), module_v: r(w[7]) })
}

/// Most `(code, value)` pairs [`event_words`] gives for one sample: two per step event, the
/// dropped count, four per alarm kind.
pub const MAX_EVENT_WORDS: usize = 2 * hter::event::MAX_EVENTS_PER_STEP + 1 + 4 * 4;

/// A time, ms, as the two pairs `(code, low word)`, `(code, high word)`.
fn push_time(code: u32, t_ms: u64, push: &mut impl FnMut(u32, u32)) {
    push(code, t_ms as u32);
    push(code, (t_ms >> 32) as u32);
}

/// Timed parts of a sample, one SysTick count each (0 where a part did not run).
/// `step` and `monitor` are the per-sample work; the others are the same computations run
/// again on shadow copies, to split the figure.
pub const PARTS: [&str; 10] = [
    "step (board readings + Carrier::step)",
    "cold-chain monitor push",
    "controller update alone",
    "counts → °C (ratio + CVD)",
    "RLS update, 7 parameters",
    "RLS update, 5 parameters",
    "GPC push_y + staged design",
    "estimate + projection",
    "Diophantine (Ã, k = 5)",
    "board: recorder + alarm indicator",
];
/// Index of the step in [`PARTS`].
pub const PART_STEP: usize = 0;
/// Index of the monitor in [`PARTS`].
pub const PART_MONITOR: usize = 1;
/// Index of the firmware's per-sample bookkeeping beside the step (`hter::persist::Recorder`
/// with the monitor inside it, on a copy, and `hter::alarm::Annunciator`), outside the
/// budgeted figure.
pub const PART_BOARD: usize = 9;
/// The firmware's history store cadence in samples: the board profile's, 1 h.
pub const HISTORY_SAVE_SAMPLES: u32 = profile::samples(profile::HISTORY_SAVE_S, CARRIER.get().ts_s);

/// Iterations of the short calibration loop (the long one runs twice as many). The output's
/// calibration words are the SysTick counts of an empty window and of the two loops of two
/// instructions per iteration (`subs`, `bne`): the last two differ by exactly 2 · CAL_LOOP
/// instructions.
pub const CAL_LOOP: u32 = 1000;

/// Event code of an alarm of the cold-chain monitor (`+ AlarmKind as u32`).
pub const CODE_ALARM: u32 = 0x100;
/// Event code of the step's dropped-event counter (value = the count, not a time).
pub const CODE_DROPPED: u32 = 0x200;

/// The events and alarms of one sample as `(code, value)` pairs: step events as
/// `(EventKind as u32, t_ms)`, alarms as `(CODE_ALARM + kind, trigger_ms)` then
/// `(CODE_ALARM + kind, start_ms)`, each time (u64) as two pairs, low word first.
pub fn event_words(out: &StepOutput, raised: &Raised, mut push: impl FnMut(u32, u32)) {
    for e in out.events.iter() {
        push_time(e.kind.code(), e.t_ms, &mut push);
    }
    if out.events.dropped() > 0 {
        push(CODE_DROPPED, u32::from(out.events.dropped()));
    }
    for a in raised.iter().flatten() {
        push_time(CODE_ALARM + a.kind as u32, a.trigger_ms, &mut push);
        push_time(CODE_ALARM + a.kind as u32, a.start_ms, &mut push);
    }
}
