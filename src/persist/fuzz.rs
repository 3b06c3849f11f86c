//! Fuzz tests of every decoder of the records the board reads back from flash after a reset or a
//! power cut, which it did not just write itself: a record of an older or newer firmware, a
//! half-written one, one whose CRC passes by chance. Every decoder gets two kinds of input:
//!
//! 1. arbitrary bytes, of any length up to twice the record's and of exactly its length;
//! 2. a valid record with arbitrary edits in its body (bytes, f32 and u32 words, the tag and the
//!    version byte too) and its CRC written again, so that the case reaches the checks behind it.
//!
//! Whatever comes in, a decoder must not panic, and a value it accepts must be valid by its
//! type's own rules (what its encoder writes and what the boot relies on) and read back the same
//! once encoded again. A history the board accepted is also continued as a boot continues it
//! ([`Recorder`]): every history that boot stores must be one the next boot accepts, or one odd
//! record would cost every record after it.
//!
//! The quick properties run with every `cargo test`; their `_long` twins, ignored, with
//! [`LONG`] cases each in CI (`cargo test --release -p hter --features persist-flash --lib
//! --test persist -- --ignored`).

use super::log::{write_csv_row, LogEntry, ENTRY_LEN};
use super::tests::reframe;
use super::*;
use crate::coldchain::EXCURSION_LOG;
use crate::control::adaptive::SelfTuning;
use crate::failsafe::Stops;
use crate::profile::{ADAPTIVE_GPC, ADAPTIVE_IGMVC, START_MODEL_HTER1, START_MODEL_HTER2};
use proptest::array::{uniform3, uniform4, uniform5};
use proptest::collection::vec;
use proptest::prelude::*;
use proptest::sample::select;
use std::string::String;
use std::vec::Vec;

/// Cases of each quick property (every `cargo test`, debug: well under a second each).
const QUICK: u32 = 400;
/// Cases of each ignored `_long` property (CI, release).
const LONG: u32 = 200_000;

/// Values at and around the edges of every range a decoder checks, and the special ones.
const EDGES: [f32; 31] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    MIN_GAIN,
    1.1,
    MAX_CORRECTION_C,
    -MAX_CORRECTION_C,
    2.0,
    2.5,
    7.5,
    8.0,
    10.0,
    -10.0,
    25.0,
    -50.0,
    -60.0,
    100.0,
    3.0,
    SensorOffset::MAX_C,
    1e-45,
    f32::MIN_POSITIVE,
    f32::EPSILON,
    f32::MAX,
    f32::MIN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::NAN,
    16_777_216.0,
    4_294_967_296.0,
    -1.7,
];

/// Any f32, an edge, an edge a few ulps off, or an ordinary value.
fn edge_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        any::<f32>(),
        select(EDGES.to_vec()),
        (select(EDGES.to_vec()), -3i32..=3).prop_map(|(x, d)| f32::from_bits(x.to_bits().wrapping_add_signed(d))),
        -200.0f32..200.0,
    ]
}

/// Any u32, or one at an edge (0, 1, a stop kind's code, a sign bit, all ones).
fn edge_u32() -> impl Strategy<Value = u32> {
    prop_oneof![any::<u32>(), 0u32..8, select(std::vec![0x7FFF_FFFF, 0x8000_0000, 0x8000_0001, u32::MAX])]
}

/// One edit of a frame's body.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Edit {
    /// Byte `at` (modulo the body's length) set.
    Byte(usize, u8),
    /// An f32 written from byte `at` (clipped at the body's end).
    F32(usize, f32),
    /// A u32 written from byte `at`.
    U32(usize, u32),
}

/// Where each record's fields begin (the layouts in their docs), bytes: an edit there replaces
/// a whole field, which reaches the field's check far more often than an edit anywhere.
pub(crate) const MODEL_FIELDS: &[usize] = &[0, 1, 2, 6, 10, 14, 18, 22, 26];
pub(crate) const CABINET_FIELDS: &[usize] = &[0, 1, 2, 6, 10, 14, 18];
pub(crate) const CALIBRATION_FIELDS: &[usize] = &[0, 1, 2, 6];
pub(crate) const SETTINGS_FIELDS: &[usize] = &[0, 1, 2, 6, 10, 11, 15, 19, 23];
/// The history's (v6; an older version's body is shorter, and an offset past it wraps).
#[rustfmt::skip]
pub(crate) const HISTORY_FIELDS: &[usize] = &[
    0, 1, 2, 4, 6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 36,
    40, 41, 45, 49, 53, 54, 58, 62, 66, 67, 71, 75, 79, 80, 84, 88,
    92, 94, 96, 98, 100, 102, 104, 105, 109, 113, 117, 118, 122, 126, 130, 134,
];
const LOG_FIELDS: &[usize] = &[0, 1, 5, 6, 7, 9, 10, 11, 13];

fn edit(fields: &'static [usize]) -> impl Strategy<Value = Edit> {
    let at = prop_oneof![any::<usize>(), select(fields)];
    prop_oneof![
        (at.clone(), any::<u8>()).prop_map(|(at, x)| Edit::Byte(at, x)),
        (at.clone(), edge_f32()).prop_map(|(at, x)| Edit::F32(at, x)),
        (at, edge_u32()).prop_map(|(at, x)| Edit::U32(at, x)),
    ]
}

/// One to four edits of a record whose fields begin at `fields`, there or anywhere (a single
/// one reaches a check behind valid fields more often).
pub(crate) fn edits(fields: &'static [usize]) -> impl Strategy<Value = Vec<Edit>> {
    vec(edit(fields), 1..=4)
}

/// `frame` with `edits` in its body (everything before the CRC) and its CRC written again.
pub(crate) fn edited(frame: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut b = frame.to_vec();
    let body = b.len() - 4;
    for e in edits {
        let (at, word) = match *e {
            Edit::Byte(at, x) => {
                b[at % body] = x;
                continue;
            }
            Edit::F32(at, x) => (at, x.to_le_bytes()),
            Edit::U32(at, x) => (at, x.to_le_bytes()),
        };
        for (d, s) in b[at % body..body].iter_mut().zip(word) {
            *d = s;
        }
    }
    reframe(&mut b);
    b
}

/// Arbitrary bytes of any length up to twice `len`, or of exactly `len`.
pub(crate) fn any_bytes(len: usize) -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![vec(any::<u8>(), 0..=2 * len), vec(any::<u8>(), len)]
}

/// Arbitrary bytes of `len` behind the record's tag and `version`, framed with a valid CRC: the
/// field checks of a version see noise.
pub(crate) fn noise_frame(tag: u8, version: u8, len: usize) -> impl Strategy<Value = Vec<u8>> {
    vec(any::<u8>(), len).prop_map(move |mut b| {
        b[0] = tag;
        b[1] = version;
        reframe(&mut b);
        b
    })
}

/// The self-tuner configurations a record is restored under (the board builds').
fn configs() -> [AdaptiveConfig; 2] {
    [ADAPTIVE_GPC, ADAPTIVE_IGMVC]
}

// ---------------------------------------------------------------------------------------------
// The model records.

/// A delay, mostly in range.
fn delay() -> impl Strategy<Value = u8> {
    prop_oneof![4 => 1..=MAX_K as u8, 1 => any::<u8>()]
}

/// Moves a model's θ (a1, a2, b…) by the fractions `d` in −1…1: A by up to 0.01 % (its poles
/// are near 1), B by up to 30 %.
fn jitter(theta: &mut [f32], d: Vec<f32>) {
    for (i, (x, d)) in theta.iter_mut().zip(d).enumerate() {
        *x += d * x.abs() * if i < 2 { 1e-4 } else { 0.3 };
    }
}

/// A model record near a carrier's model, mostly with a delay in range.
fn model_record() -> impl Strategy<Value = ModelRecord> {
    (select(std::vec![START_MODEL_HTER1, START_MODEL_HTER2]), vec(-1f32..1.0, 6), delay()).prop_map(|(m, d, k)| {
        let mut r = ModelRecord::from_model(&m).expect("a second-order start model");
        jitter(&mut r.theta, d);
        ModelRecord { k, ..r }
    })
}

/// The frame of a model record as v2 writes it, or as v1 wrote it (its first four θ).
pub(crate) fn model_frame() -> impl Strategy<Value = Vec<u8>> {
    (model_record(), any::<bool>()).prop_map(|(r, v1)| {
        if v1 {
            let mut b = std::vec![0u8; ModelRecord::LEN_V1];
            encode_theta_k(&mut b, ModelRecord::TAG, 1, &r.theta[..4], r.k);
            b
        } else {
            r.encode().to_vec()
        }
    })
}

/// A decoded model record is finite with a delay in range, reads back the same, and restores
/// (when plausible) a model of its own θ that the self-tuner starts from.
fn check_model(bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(rec) = ModelRecord::decode(bytes) else { return Ok(()) };
    prop_assert!(rec.theta.iter().all(|x| x.is_finite()), "{rec:?}");
    prop_assert!((1..=MAX_K).contains(&usize::from(rec.k)), "{rec:?}");
    if bytes.len() == ModelRecord::LEN_V1 {
        prop_assert_eq!(&rec.theta[4..], &[0.0, 0.0]);
    }
    prop_assert_eq!(ModelRecord::decode(&rec.encode()), Ok(rec));
    for cfg in configs() {
        let Ok(m) = rec.to_model(&cfg) else { continue };
        prop_assert!(plausible_model_cold(&AdaptiveConfig { k: usize::from(rec.k), ..cfg }, &m), "{rec:?}");
        prop_assert_eq!(ModelRecord::from_model(&m), Some(rec));
        let resumed = rec.restore(&cfg);
        prop_assert!(resumed.is_ok(), "{rec:?}: {resumed:?}");
        let _ = SelfTuning::new(resumed.unwrap(), 10.0, 0.45);
    }
    Ok(())
}

/// A cabinet record near a carrier's model, mostly with a delay in range.
pub(crate) fn cabinet_frame() -> impl Strategy<Value = Vec<u8>> {
    (vec(-1f32..1.0, 4), delay()).prop_map(|(d, k)| {
        let mut r = CabinetRecord::from_model(&START_MODEL_HTER1).expect("second order");
        jitter(&mut r.theta, d);
        CabinetRecord { k, ..r }.encode().to_vec()
    })
}

/// A decoded cabinet model passes what an upload passes, and its record reads back the same.
fn check_cabinet(bytes: &[u8]) -> Result<(), TestCaseError> {
    for cfg in configs() {
        let Ok(m) = CabinetRecord::decode(bytes, &cfg) else { continue };
        prop_assert!(m.na() == 2 && m.nb() == 2 && (1..=MAX_K).contains(&m.k()), "{m:?}");
        prop_assert!(cabinet_plausible(&cfg, &m).is_ok(), "{m:?}");
        let rec = CabinetRecord::from_model(&m);
        prop_assert!(rec.is_some(), "{m:?}");
        prop_assert_eq!(CabinetRecord::decode(&rec.unwrap().encode(), &cfg), Ok(m));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The calibration and the settings.

/// Whether `cal` is a line [`crate::calib::TwoPoint::from_points`] accepts: a gain within
/// 0.9 … 1.1 and a correction of a reading between 0 and 10 °C of at most
/// [`MAX_CORRECTION_C`] (what the interface refuses beyond: such a line read a −4.4 °C load as
/// 5.00 °C, the freeze guard blind to it).
pub(crate) fn plausible_line(cal: &TwoPoint) -> bool {
    let at_10 = (cal.gain - 1.0) * 10.0 + cal.offset_c;
    (MIN_GAIN..=1.1).contains(&cal.gain) && cal.offset_c.abs() <= MAX_CORRECTION_C && at_10.abs() <= MAX_CORRECTION_C
}

pub(crate) fn calibration_frame() -> impl Strategy<Value = Vec<u8>> {
    (MIN_GAIN..=1.1f32, -MAX_CORRECTION_C..=MAX_CORRECTION_C)
        .prop_map(|(gain, offset_c)| CalibrationRecord { cal: TwoPoint { gain, offset_c } }.encode().to_vec())
}

/// A decoded calibration is a line a calibration can give, and reads back the same.
fn check_calibration(bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(rec) = CalibrationRecord::decode(bytes) else { return Ok(()) };
    prop_assert!(plausible_line(&rec.cal), "{rec:?}");
    prop_assert_eq!(CalibrationRecord::decode(&rec.encode()), Ok(rec));
    Ok(())
}

pub(crate) fn settings_frame() -> impl Strategy<Value = Vec<u8>> {
    let (lo, hi) = crate::iface::SETPOINT_RANGE_C;
    (any::<u32>(), lo..=hi, select(crate::iface::Law::ALL.to_vec()), -1.0f32..1.0, -1.0f32..1.0).prop_map(
        |(seq, setpoint_c, law, ice, warm)| {
            let rec = SettingsRecord { seq, setpoint_c, law, cal_ice: [ice, 0.0], cal_warm: [25.0 + warm, 25.0] };
            rec.encode().to_vec()
        },
    )
}

/// A decoded settings record is what the interface accepts (a setpoint in its range, points in
/// theirs that make a plausible calibration), and reads back the same.
fn check_settings(bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(rec) = SettingsRecord::decode(bytes) else { return Ok(()) };
    let (lo, hi) = crate::iface::SETPOINT_RANGE_C;
    prop_assert!((lo..=hi).contains(&rec.setpoint_c), "{rec:?}");
    prop_assert!(rec.cal_ice.iter().chain(&rec.cal_warm).all(|x| (-50.0..=100.0).contains(x)), "{rec:?}");
    let cal = rec.calibration();
    prop_assert!(cal.as_ref().is_ok_and(plausible_line), "{rec:?}: {cal:?}");
    prop_assert_eq!(SettingsRecord::decode(&rec.encode()), Ok(rec));
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The history.

fn excursion() -> impl Strategy<Value = Excursion> {
    (select(std::vec![Side::Cold, Side::Warm]), 0.0f32..1e7, 0.0f32..1e5, -60.0f32..=100.0)
        .prop_map(|(side, start_s, d, extreme_c)| Excursion { side, start_s, end_s: start_s + d, extreme_c })
}

/// A count: any, small, or near its end (where the boot's additions saturate).
fn count_u16() -> impl Strategy<Value = u16> {
    prop_oneof![any::<u16>(), 0u16..10, (0u16..10).prop_map(|d| u16::MAX - d)]
}

/// A count or a time in seconds: any, small, or within 10⁷ of its end.
fn count_u32() -> impl Strategy<Value = u32> {
    prop_oneof![any::<u32>(), 0u32..1000, (0u32..10_000_000).prop_map(|d| u32::MAX - d)]
}

/// A history as the board stores it: any counts, extremes in order, the newest excursions
/// oldest first, any alarm runs, the flags, the offset and the last stop.
fn history() -> impl Strategy<Value = HistoryRecord> {
    let extremes = prop_oneof![
        Just((None, None)),
        (-60.0f32..=100.0, -60.0f32..=100.0).prop_map(|(a, b)| (Some(a.min(b)), Some(a.max(b)))),
    ];
    let stop = proptest::option::of((select(StopKind::ALL.to_vec()), any::<[u32; 3]>()));
    (
        (uniform4(count_u16()), uniform3(count_u16()), extremes, uniform4(count_u32())),
        (0usize..=HISTORY_EXCURSIONS, vec(excursion(), HISTORY_EXCURSIONS)),
        (uniform5(count_u16()), count_u16(), stop, any::<u8>(), 0u8..=127, uniform4(edge_u32())),
    )
        .prop_map(
            |((alarms, resets, (min_c, max_c), t), (n, mut ex), (stops, lost, stop, flags, offset, runs))| {
                ex.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
                let mut last = [None; HISTORY_EXCURSIONS];
                for (slot, e) in last.iter_mut().skip(HISTORY_EXCURSIONS - n).zip(ex) {
                    *slot = Some(e);
                }
                HistoryRecord {
                    alarms,
                    resets,
                    min_c,
                    max_c,
                    below_2_s: t[0],
                    above_8_s: t[1],
                    excursions: t[2],
                    recorded_s: t[3],
                    last,
                    stops,
                    flash_pages_lost: lost,
                    last_stop: stop.map(|(kind, [pc, addr, detail])| LastStop { kind, pc, addr, detail }),
                    flags,
                    sensor_offset: SensorOffset(offset),
                    runs,
                }
            },
        )
}

/// Length of a history frame of `version`.
fn history_len(version: u8) -> usize {
    match version {
        2 => HistoryRecord::LEN_V2,
        3 => HistoryRecord::LEN_V3,
        4 => HistoryRecord::LEN_V4,
        5 => HistoryRecord::LEN_V5,
        _ => HistoryRecord::LEN,
    }
}

/// A history frame as `version` (2 … 6) wrote it: the current encoding's first bytes (each
/// version appended its fields), that version's number, its CRC.
pub(crate) fn history_frame() -> impl Strategy<Value = Vec<u8>> {
    (history(), 2u8..=HistoryRecord::VERSION).prop_map(|(h, version)| {
        let n = history_len(version);
        let mut b = h.encode()[..n].to_vec();
        b[1] = version;
        reframe(&mut b);
        b
    })
}

/// A history valid by its own rules: extremes absent or within −60 … 100 °C and in order;
/// excursions with 0 ≤ start ≤ end and an extreme in range (every flag bit is one: three
/// flags and the five records' refusals).
pub(crate) fn history_valid(h: &HistoryRecord) -> Result<(), TestCaseError> {
    for x in [h.min_c, h.max_c].into_iter().flatten() {
        prop_assert!(TEMP_RANGE_C.contains(&x), "extreme {x}: {h:?}");
    }
    if let (Some(lo), Some(hi)) = (h.min_c, h.max_c) {
        prop_assert!(lo <= hi, "{h:?}");
    }
    for e in h.last.iter().flatten() {
        prop_assert!(e.start_s >= 0.0 && e.start_s <= e.end_s && e.end_s.is_finite(), "{e:?}: {h:?}");
        prop_assert!(TEMP_RANGE_C.contains(&e.extreme_c), "{e:?}: {h:?}");
    }
    prop_assert!(h.sensor_offset.0 <= SensorOffset::MAX_STEPS, "{h:?}");
    Ok(())
}

/// A decoded history is valid and reads back the same.
fn check_history(bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(h) = HistoryRecord::decode(bytes) else { return Ok(()) };
    history_valid(&h)?;
    prop_assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
    Ok(())
}

/// A boot that continues a history: how it started and what it sampled.
#[derive(Clone, Debug)]
struct Continued {
    reset: ResetCause,
    stops: Stops,
    service: bool,
    page_lost: bool,
    /// The records the boot refused ([`Recorder::note_refused`]), if any were or had been.
    refused: Option<u8>,
    every: u32,
    t0_ms: u64,
    /// (ms since the previous sample, the recorded °C or NaN, latched, offset steps, shorted).
    samples: Vec<(u64, f32, bool, u8, bool)>,
}

fn continued() -> impl Strategy<Value = Continued> {
    let stop = proptest::option::of(
        (select(StopKind::ALL.to_vec()), any::<u32>()).prop_map(|(k, d)| crate::failsafe::StopInfo::new(k, 0, 0, d)),
    );
    let temp = prop_oneof![Just(f32::NAN), -50.0f32..90.0, select(std::vec![2.0f32, 8.0, -0.5, 30.0, 45.0])];
    let sample = (
        prop_oneof![Just(10_000u64), 0u64..100_000, 0u64..100_000_000],
        temp,
        any::<bool>(),
        prop_oneof![Just(0u8), 0u8..=127],
        prop::bool::weighted(0.05),
    );
    (
        select(std::vec![ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other]),
        (stop.clone(), stop, any::<bool>()),
        any::<bool>(),
        (any::<bool>(), proptest::option::of(0u8..32)),
        1u32..400,
        0u64..20_000,
        vec(sample, 0..60),
    )
        .prop_map(|(reset, (earlier, latest, fresh), service, (page_lost, refused), every, t0_ms, samples)| {
            Continued {
                reset,
                stops: Stops { earlier, latest, fresh },
                service,
                page_lost,
                refused,
                every,
                t0_ms,
                samples,
            }
        })
}

/// Continues `rec` as a boot does ([`Recorder::note_boot`], a service reset, a page lost,
/// samples with the carried state changing): every history the boot hands over is valid, reads
/// back the same, and has lost none of the counts it carried in.
fn check_continued(rec: &HistoryRecord, boot: &Continued) -> Result<(), TestCaseError> {
    let mut r = Recorder::new(*rec, boot.every);
    if let Some(refused) = boot.refused {
        r.note_refused(refused);
    }
    let mut stored = std::vec![r.note_boot(boot.reset, &boot.stops)];
    let refused = boot.refused.unwrap_or(rec.refused());
    let h = stored[0];
    prop_assert_eq!(h.refused(), refused);
    prop_assert!(h.unacknowledged() || refused & !rec.refused() == 0, "a new refusal latches: {:?}", h);
    if boot.service {
        stored.push(r.note_service());
    }
    if boot.page_lost {
        stored.push(r.note_flash_page_lost());
    }
    let mut t_ms = boot.t0_ms;
    for &(dt, c, latched, steps, shorted) in &boot.samples {
        t_ms += dt;
        let mut out = r.push(t_ms, c);
        r.note_carried(&mut out, latched, SensorOffset(steps), shorted);
        if let Some(Save::History(h) | Save::AlarmHistory(h)) = r.due_save(&out) {
            stored.push(h);
        }
    }
    stored.push(r.history());
    prop_assert!(r.monitor().excursions().count() <= EXCURSION_LOG + 1);
    for h in stored {
        history_valid(&h)?;
        prop_assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h), "stored after {:?}", rec);
        let kept = h.alarms.iter().zip(&rec.alarms).chain(h.resets.iter().zip(&rec.resets));
        prop_assert!(kept.clone().all(|(now, was)| now >= was), "{h:?} after {rec:?}");
        prop_assert!(h.excursions >= rec.excursions && h.recorded_s >= rec.recorded_s, "{h:?} after {rec:?}");
        prop_assert_eq!(h.refused(), refused, "the refusals kept through the boot: {:?}", h);
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The log's entries (no CRC of their own: the storage layer's item CRC is all they have).

fn log_frame() -> impl Strategy<Value = Vec<u8>> {
    let tag = select(b"IEAS".to_vec());
    prop_oneof![
        (tag, vec(any::<u8>(), ENTRY_LEN - 1)).prop_map(|(t, rest)| [&[t][..], &rest].concat()),
        // A valid entry with edits anywhere (no CRC to write again: the last four bytes are data).
        (
            select(std::vec![
                LogEntry::Interval {
                    t_s: 300,
                    interval: super::log::Interval {
                        mean_c: 4.0,
                        min_c: 3.5,
                        max_c: 4.5,
                        duty: 0.45,
                        mode: crate::step::Mode::Normal
                    },
                },
                LogEntry::Event { t_s: 7, kind: crate::event::EventKind::Restarted(ResetCause::BrownOut) },
                LogEntry::Lost { t_s: 8, entries: 3 },
                LogEntry::Alarm { t_s: 36_000, kind: AlarmKind::Heat10h, start_s: 0 },
                LogEntry::Setting { t_s: 12, key: super::log::SettingKey::CalWarm, value: [25.31, 25.02] },
            ]),
            edits(LOG_FIELDS),
        )
            .prop_map(|(e, edits)| {
                let mut b = e.encode().to_vec();
                b.extend_from_slice(&[0; 4]);
                let mut b = edited(&b, &edits);
                b.truncate(ENTRY_LEN);
                b
            }),
    ]
}

/// A decoded entry is valid by the encoder's rules (temperatures as centi-°C or none, a duty in
/// 0 … 1, a known event), encodes to what decodes to itself, and prints as one CSV row.
fn check_log(bytes: &[u8]) -> Result<(), TestCaseError> {
    let Ok(e) = LogEntry::decode(bytes) else { return Ok(()) };
    match e {
        LogEntry::Interval { interval: i, .. } => {
            for x in [i.mean_c, i.min_c, i.max_c] {
                prop_assert!(x.is_nan() || x.abs() <= 327.67, "{e:?}");
            }
            prop_assert!((0.0..=1.0).contains(&i.duty), "{e:?}");
        }
        LogEntry::Event { kind, .. } => prop_assert!(kind != crate::event::EventKind::LogEntriesLost),
        _ => {}
    }
    // Compared as bytes: a NaN value is not equal to itself.
    let again = LogEntry::decode(&e.encode()).map(|x| x.encode());
    prop_assert_eq!(again, Ok(e.encode()), "{:?}", e);
    let mut row = String::new();
    prop_assert!(write_csv_row(&e, &mut row).is_ok());
    prop_assert!(!row.contains(['\r', '\n']), "{row:?}");
    Ok(())
}

// ---------------------------------------------------------------------------------------------

/// Declares each property twice: quick, and `_long` (ignored) with [`LONG`] cases.
macro_rules! properties {
    ($($name:ident, $long:ident ($($arg:ident in $strategy:expr),+) $body:block)*) => {
        proptest! {
            #![proptest_config(ProptestConfig { cases: QUICK, ..ProptestConfig::default() })]
            $(
                #[test]
                fn $name($($arg in $strategy),+) $body
            )*
        }
        proptest! {
            #![proptest_config(ProptestConfig { cases: LONG, ..ProptestConfig::default() })]
            $(
                #[test]
                #[ignore = "many cases: CI runs it in release with `-- --ignored`"]
                fn $long($($arg in $strategy),+) $body
            )*
        }
    };
}

properties! {
    arbitrary_bytes_into_every_record_decoder, arbitrary_bytes_into_every_record_decoder_long (
        model in any_bytes(ModelRecord::LEN),
        cabinet in any_bytes(CabinetRecord::LEN),
        cal in any_bytes(CalibrationRecord::LEN),
        settings in any_bytes(SettingsRecord::LEN),
        history in any_bytes(HistoryRecord::LEN),
        entry in any_bytes(ENTRY_LEN)
    ) {
        check_model(&model)?;
        check_cabinet(&cabinet)?;
        check_calibration(&cal)?;
        check_settings(&settings)?;
        check_history(&history)?;
        check_log(&entry)?;
    }

    edited_model_records, edited_model_records_long (
        frame in prop_oneof![
            model_frame(),
            noise_frame(ModelRecord::TAG, 2, ModelRecord::LEN),
            noise_frame(ModelRecord::TAG, 1, ModelRecord::LEN_V1)
        ],
        e in edits(MODEL_FIELDS),
        cab in cabinet_frame(),
        f in edits(CABINET_FIELDS)
    ) {
        check_model(&frame)?;
        check_model(&edited(&frame, &e))?;
        check_cabinet(&cab)?;
        check_cabinet(&edited(&cab, &f))?;
    }

    edited_calibration_and_settings_records, edited_calibration_and_settings_records_long (
        cal in prop_oneof![calibration_frame(), noise_frame(CalibrationRecord::TAG, 1, CalibrationRecord::LEN)],
        e in edits(CALIBRATION_FIELDS),
        settings in prop_oneof![settings_frame(), noise_frame(SettingsRecord::TAG, 1, SettingsRecord::LEN)],
        f in edits(SETTINGS_FIELDS)
    ) {
        check_calibration(&cal)?;
        check_calibration(&edited(&cal, &e))?;
        check_settings(&settings)?;
        check_settings(&edited(&settings, &f))?;
    }

    edited_history_records, edited_history_records_long (
        frame in prop_oneof![
            history_frame(),
            (2u8..=HistoryRecord::VERSION).prop_flat_map(|v| noise_frame(HistoryRecord::TAG, v, history_len(v)))
        ],
        e in edits(HISTORY_FIELDS)
    ) {
        check_history(&frame)?;
        check_history(&edited(&frame, &e))?;
    }

    a_history_the_board_accepted_continues_into_ones_the_next_boot_accepts,
    a_history_the_board_accepted_continues_into_ones_the_next_boot_accepts_long (
        frame in history_frame(),
        e in proptest::option::of(edits(HISTORY_FIELDS)),
        boot in continued()
    ) {
        let bytes = match e {
            Some(e) => edited(&frame, &e),
            None => frame,
        };
        if let Ok(rec) = HistoryRecord::decode(&bytes) {
            check_continued(&rec, &boot)?;
        }
    }

    edited_log_entries, edited_log_entries_long (entry in log_frame()) {
        check_log(&entry)?;
    }
}
