//! What the carrier keeps across power cycles: the learned plant model, the two-point
//! calibration and a cold-chain history summary, each as a small versioned record with a fixed
//! little-endian byte layout and a CRC.
//!
//! Every record is framed the same way:
//!
//! ```text
//! offset 0        1          2 … n−5    n−4 … n−1
//!        kind tag version    payload    CRC-32 (IEEE 802.3, reflected, LE) of bytes 0 … n−5
//! ```
//!
//! The flash layer below (`persist::flash`, feature `persist-flash`, over `sequential-storage`) has its
//! own CRCs against torn writes; this CRC and the range checks on decode guard what that layer
//! cannot know: a record written by another firmware version, a bit flip inside a stored value,
//! or a model that was plausible under different limits. A record that fails any check is
//! rejected with a [`DecodeError`] and the caller starts from defaults.
//!
//! Glossary: θ = [a1 a2 b0 b1 b2 b3] the self-tuner's ARX estimate (see
//! [`crate::control::adaptive`]; its offset d is not kept: it tracks the operating point, which
//! has changed by the next boot, and the estimator starts it at 0 anyway); k the model delay in
//! samples.

use crate::calib::{TwoPoint, MAX_CORRECTION_C, MAX_GAIN, MIN_GAIN};
use crate::coldchain::{AlarmKind, ColdChainMonitor, Excursion, Raised, Runs, Side};
use crate::control::adaptive::{model_from_theta, plausible_model_cold, AdaptiveConfig, ESTIMATED_NB};
use crate::control::{AdaptiveMode, Controller};
use crate::failsafe::{StopInfo, StopKind};
use crate::ident::commission::cabinet_plausible;
use crate::model::{Model, MAX_K};

#[cfg(feature = "persist-flash")]
pub mod flash;
#[cfg(test)]
pub(crate) mod fuzz;
mod gate;
pub mod log;

pub use gate::{
    PendingSaves, Save, StoreFailures, StoreWatch, WriteGate, PENDING_LOG, STORE_FAILURES, SUPPLY_FRESH_MS,
    SUPPLY_HOLD_OFF_MS,
};

/// Why stored bytes were not accepted as a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// The byte count is not the record's length.
    Length,
    /// The CRC does not match the bytes.
    Crc,
    /// The kind tag belongs to another record.
    Kind,
    /// A layout version this firmware does not read.
    Version,
    /// A value is NaN or infinite where a finite one is required.
    NonFinite,
    /// A value is outside the range the record allows.
    OutOfRange,
    /// The model decodes but the self-tuner would not trust it (unstable A, a heating b_i, or a
    /// static gain outside the configured range).
    Implausible,
}

/// CRC-32 (IEEE 802.3: polynomial 0x04C11DB7 reflected, init and final XOR 0xFFFF_FFFF), bit
/// by bit: no 1 KiB table in flash for a few hundred bytes every few hours. Out of line: LLVM
/// inlined its unrolled loop into every record's encode and decode, ≈ 1.2 KiB of the default
/// firmware build (`cargo xtask size`), for a function that runs a few times an hour. The bit
/// count hidden from the optimiser (as [`crate::coldchain`]'s `kinds()`): the inner loop stays
/// a loop, where unrolled eightfold it was 72 B more of the firmware's flash.
#[inline(never)]
pub fn crc32(bytes: &[u8]) -> u32 {
    let bits = core::hint::black_box(8u32);
    let mut crc = 0xFFFF_FFFFu32;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..bits {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// Sequential little-endian writer into a record buffer sized by its `LEN`.
struct Writer<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl<'a> Writer<'a> {
    fn new(buf: &'a mut [u8], tag: u8, version: u8) -> Self {
        let mut w = Writer { buf, at: 0 };
        w.put(&[tag, version]);
        w
    }

    fn put(&mut self, bytes: &[u8]) {
        if let Some(dst) = self.buf.get_mut(self.at..self.at + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
        self.at += bytes.len();
    }

    fn f32(&mut self, x: f32) {
        self.put(&x.to_le_bytes());
    }

    fn u16(&mut self, x: u16) {
        self.put(&x.to_le_bytes());
    }

    fn u32(&mut self, x: u32) {
        self.put(&x.to_le_bytes());
    }

    /// Appends the CRC of everything written so far.
    fn finish(mut self) {
        let crc = crc32(self.buf.get(..self.at).unwrap_or(&[]));
        self.u32(crc);
    }
}

/// Sequential little-endian reader over a frame already checked by [`open_frame`].
struct Reader<'a> {
    rest: &'a [u8],
}

impl Reader<'_> {
    /// The next `n` (≤ 4) bytes as a little-endian word; 0, consuming nothing, if fewer are
    /// left. Out of line, one copy for every width: inlined, each of the decoders' ≈ 60 reads
    /// carried its own slice split and copy (≈ 300 B of the firmware's flash, for code that
    /// runs at boot).
    #[inline(never)]
    fn word(&mut self, n: usize) -> u32 {
        let Some((head, tail)) = self.rest.split_at_checked(n) else { return 0 };
        self.rest = tail;
        head.iter().rev().fold(0, |w, &b| w << 8 | u32::from(b))
    }

    /// Skips `n` bytes (none if fewer are left, as a read would).
    fn skip(&mut self, n: usize) {
        if let Some(tail) = self.rest.get(n..) {
            self.rest = tail;
        }
    }

    fn u8(&mut self) -> u8 {
        self.word(1) as u8
    }

    fn u16(&mut self) -> u16 {
        self.word(2) as u16
    }

    fn u32(&mut self) -> u32 {
        self.word(4)
    }

    fn f32(&mut self) -> f32 {
        f32::from_bits(self.word(4))
    }

    /// A finite f32 within `lo..=hi`. Out of line: inlined, each of the decoders' range checks
    /// carried its own copy of the tests (−8 B of flash; out of line with a `RangeInclusive`
    /// argument, which goes by reference, 28 B more than inlined).
    #[inline(never)]
    fn f32_in(&mut self, lo: f32, hi: f32) -> Result<f32, DecodeError> {
        let x = self.f32();
        if !x.is_finite() {
            Err(DecodeError::NonFinite)
        } else if !(lo..=hi).contains(&x) {
            Err(DecodeError::OutOfRange)
        } else {
            Ok(x)
        }
    }
}

/// Checks length, CRC, tag and version; returns a reader over the payload. Out of line: every
/// record's decoder inlined it (−8 B of the default firmware's flash, −232 B of the interface
/// build's, which decodes the settings and the cabinet model too).
#[inline(never)]
fn open_frame(bytes: &[u8], len: usize, tag: u8, version: u8) -> Result<Reader<'_>, DecodeError> {
    if bytes.len() != len {
        return Err(DecodeError::Length);
    }
    let (body, crc) = bytes.split_at_checked(len - 4).ok_or(DecodeError::Length)?;
    let mut crc_reader = Reader { rest: crc };
    if crc32(body) != crc_reader.u32() {
        return Err(DecodeError::Crc);
    }
    let mut r = Reader { rest: body };
    if r.u8() != tag {
        return Err(DecodeError::Kind);
    }
    if r.u8() != version {
        return Err(DecodeError::Version);
    }
    Ok(r)
}

/// The self-tuner's learned model: θ = [a1 a2 b0 b1 b2 b3] and the delay k.
///
/// Layout v2, 31 bytes: `'M'`, 2, a1 a2 b0 b1 b2 b3 (f32 LE), k (u8), CRC-32. A model with
/// fewer than [`ModelRecord::NB`] B terms is stored with the rest zero.
///
/// v1 (23 bytes: `'M'`, 1, a1 a2 b0 b1, k, CRC-32; the self-tuner estimated two B terms) is
/// still read, as b2 = b3 = 0: a board updated in the field restarts from the model it had
/// learnt, not from the build's start model.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModelRecord {
    /// θ = [a1 a2 b0 b1 b2 b3] (zero beyond the model's B order).
    pub theta: [f32; 2 + ModelRecord::NB],
    /// Delay, samples (1 … [`MAX_K`]).
    pub k: u8,
}

// The record must hold every B term the self-tuner estimates.
const _: () = assert!(ESTIMATED_NB <= ModelRecord::NB);

impl ModelRecord {
    /// Kind tag.
    pub const TAG: u8 = b'M';
    /// Layout version written by this firmware.
    pub const VERSION: u8 = 2;
    /// B terms the record holds (the layout's, fixed: not [`ESTIMATED_NB`], which may change
    /// without the bytes on a board changing with it).
    pub const NB: usize = 4;
    /// Encoded length, bytes.
    pub const LEN: usize = theta_k_len(2 + Self::NB);
    /// Length of a v1 record (θ = [a1 a2 b0 b1]; still read), bytes.
    pub const LEN_V1: usize = theta_k_len(4);

    /// The record of a model of the self-tuner's structure: na = 2 and 1 ≤ nb ≤
    /// [`ModelRecord::NB`] (what [`crate::control::adaptive::SelfTuning`] estimates, or a
    /// commissioned second-order model); `None` for other orders.
    pub fn from_model(m: &Model) -> Option<Self> {
        if m.na() != 2 || m.nb() > Self::NB {
            return None;
        }
        // B is zero beyond nb (a `Model` invariant), so the padding is already there.
        let (a, b) = (m.a(), m.b());
        // A model's delay is 1 … MAX_K, which fits a byte.
        Some(ModelRecord { theta: [a[0], a[1], b[0], b[1], b[2], b[3]], k: m.k() as u8 })
    }

    /// The bytes to store (layout v2).
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut buf = [0u8; Self::LEN];
        encode_theta_k(&mut buf, Self::TAG, Self::VERSION, &self.theta, self.k);
        buf
    }

    /// Parses stored bytes, v2 or v1: frame, finite θ, 1 ≤ k ≤ [`MAX_K`]. Plausibility needs
    /// the controller's limits: see [`ModelRecord::to_model`].
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let mut theta = [0.0f32; 2 + Self::NB];
        // Told apart as the history's versions are: by length and version byte together; the
        // frame check then refuses a v1 byte on a v2 length (CRC) and the converse (length).
        let v1 = bytes.len() == Self::LEN_V1 && bytes.get(1) == Some(&1);
        let (version, n) = if v1 { (1, 4) } else { (Self::VERSION, theta.len()) };
        let k = decode_theta_k(bytes, Self::TAG, version, theta.get_mut(..n).unwrap_or_default())?;
        Ok(ModelRecord { theta, k })
    }

    /// The model the self-tuner configured by `cfg` would design on, if it passes the same
    /// plausibility test the self-tuner applies to its own estimates
    /// ([`plausible_model`](crate::control::adaptive::plausible_model)). Its
    /// B has [`ModelRecord::NB`] terms, the trailing ones zero for a model of lower order (the
    /// same polynomial).
    pub fn to_model(&self, cfg: &AdaptiveConfig) -> Result<Model, DecodeError> {
        let cfg = AdaptiveConfig { k: usize::from(self.k), ..*cfg };
        let m = model_from_theta(&cfg, &self.theta).ok_or(DecodeError::OutOfRange)?;
        if plausible_model_cold(&cfg, &m) {
            Ok(m)
        } else {
            Err(DecodeError::Implausible)
        }
    }

    /// `cfg` resumed from this record ([`AdaptiveConfig::resumed_from`]), or why not.
    pub fn restore(&self, cfg: &AdaptiveConfig) -> Result<AdaptiveConfig, DecodeError> {
        self.to_model(cfg).map(|m| cfg.resumed_from(m))
    }
}

/// Length of a record of the layout [`ModelRecord`] and [`CabinetRecord`] share, with `n` θ
/// entries, bytes.
const fn theta_k_len(n: usize) -> usize {
    2 + 4 * n + 1 + 4
}

/// That layout into `buf` (of [`theta_k_len`]`(theta.len())` bytes): `tag`, `version`, θ (f32
/// LE), k (u8), CRC-32.
fn encode_theta_k(buf: &mut [u8], tag: u8, version: u8, theta: &[f32], k: u8) {
    let mut w = Writer::new(buf, tag, version);
    for &x in theta {
        w.f32(x);
    }
    w.put(&[k]);
    w.finish();
}

/// θ (as many entries as `theta` has) and k from that layout: the frame, every θ finite,
/// 1 ≤ k ≤ [`MAX_K`].
fn decode_theta_k(bytes: &[u8], tag: u8, version: u8, theta: &mut [f32]) -> Result<u8, DecodeError> {
    let mut r = open_frame(bytes, theta_k_len(theta.len()), tag, version)?;
    for x in theta.iter_mut() {
        *x = r.f32();
        if !x.is_finite() {
            return Err(DecodeError::NonFinite);
        }
    }
    let k = r.u8();
    if k == 0 || usize::from(k) > MAX_K {
        return Err(DecodeError::OutOfRange);
    }
    Ok(k)
}

/// The carrier's cabinet model: the best-fitting model of its own commissioning run (the
/// monotone-step rule), or one uploaded with `set model`; what the holdover estimate runs on
/// (README "Holdover"). A record of its own: the self-tuner's periodic save
/// ([`ModelCadence`], [`ModelRecord`]) never overwrites it.
///
/// Layout v1, 23 bytes: `'K'`, 1, a1 a2 b0 b1 (f32 LE), k (u8), CRC-32 (the model is second
/// order: [`cabinet_plausible`] accepts nothing else). On decode the model must pass exactly
/// what it passed when accepted: finite, 1 ≤ k ≤ [`MAX_K`] and [`cabinet_plausible`] (two real
/// stable lags, a monotone cooling step response, a static gain in the configured range).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CabinetRecord {
    /// θ = [a1 a2 b0 b1].
    pub theta: [f32; 4],
    /// Delay, samples (1 … [`MAX_K`]).
    pub k: u8,
}

impl CabinetRecord {
    /// Kind tag.
    pub const TAG: u8 = b'K';
    /// Layout version written by this firmware.
    pub const VERSION: u8 = 1;
    /// Encoded length, bytes.
    pub const LEN: usize = theta_k_len(4);

    /// The record of a second-order model (na = nb = 2); `None` for other orders.
    pub fn from_model(m: &Model) -> Option<Self> {
        if m.na() != 2 || m.nb() != 2 {
            return None;
        }
        let (a, b) = (m.a(), m.b());
        Some(CabinetRecord { theta: [a[0], a[1], b[0], b[1]], k: m.k() as u8 })
    }

    /// The bytes to store.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut buf = [0u8; Self::LEN];
        encode_theta_k(&mut buf, Self::TAG, Self::VERSION, &self.theta, self.k);
        buf
    }

    /// Parses stored bytes and checks the model as an upload is checked, with the gain range of
    /// `cfg` (the build's self-tuner configuration).
    pub fn decode(bytes: &[u8], cfg: &AdaptiveConfig) -> Result<Model, DecodeError> {
        let mut theta = [0.0f32; 4];
        let k = decode_theta_k(bytes, Self::TAG, Self::VERSION, &mut theta)?;
        let m = Model::second_order([theta[0], theta[1]], [theta[2], theta[3]], usize::from(k))
            .map_err(|_| DecodeError::OutOfRange)?;
        cabinet_plausible(cfg, &m).map_err(|_| DecodeError::Implausible)?;
        Ok(m)
    }
}

/// The two-point calibration ([`TwoPoint`]).
///
/// Layout v1, 14 bytes: `'C'`, 1, gain (f32 LE), offset_c (f32 LE), CRC-32. On decode the line
/// must be one [`TwoPoint::from_points`] gives: a gain within 0.9 … 1.1 and a correction of a
/// reading between 0 and 10 °C of at most [`MAX_CORRECTION_C`] (|offset| up to 10 °C with any
/// such gain was read before, a line that moved the freeze guard's readings by up to 11 °C).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalibrationRecord {
    /// The calibration.
    pub cal: TwoPoint,
}

impl CalibrationRecord {
    /// Kind tag.
    pub const TAG: u8 = b'C';
    /// Layout version written by this firmware.
    pub const VERSION: u8 = 1;
    /// Encoded length, bytes.
    pub const LEN: usize = 2 + 4 + 4 + 4;

    /// The bytes to store.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut buf = [0u8; Self::LEN];
        let mut w = Writer::new(&mut buf, Self::TAG, Self::VERSION);
        w.f32(self.cal.gain);
        w.f32(self.cal.offset_c);
        w.finish();
        buf
    }

    /// Parses and range-checks stored bytes.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let mut r = open_frame(bytes, Self::LEN, Self::TAG, Self::VERSION)?;
        let gain = r.f32_in(MIN_GAIN, MAX_GAIN)?;
        let offset_c = r.f32_in(-MAX_CORRECTION_C, MAX_CORRECTION_C)?;
        // The rest of `from_points`' checks: the correction at 10 °C.
        let cal = TwoPoint::checked(gain, offset_c).map_err(|_| DecodeError::OutOfRange)?;
        Ok(CalibrationRecord { cal })
    }
}

/// The settings a person changes over the interface (docs/interface.md): the setpoint, the
/// law, the two calibration points, and a counter of accepted changes.
///
/// Layout v1, 31 bytes: `'S'`, 1, seq (u32), setpoint_c (f32), law (u8, index in
/// [`crate::iface::Law::ALL`]), ice point (measured, reference) and warm point (f32 each),
/// CRC-32. On decode every value is range-checked as the interface checks it, and the points
/// must pass [`TwoPoint::from_points`]: a record that would be refused as a request for its range
/// or its calibration is refused as a record. Not for its step: a value finer than the interface
/// takes now (`5.001`, which it took before it refused values finer than a setting's step) is
/// read and runs as stored, where refused it would cost the whole record, the calibration too.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SettingsRecord {
    /// Accepted changes since the record began.
    pub seq: u32,
    /// Setpoint, °C.
    pub setpoint_c: f32,
    /// The law.
    pub law: crate::iface::Law,
    /// Ice-bath point (channel reading, reference), °C.
    pub cal_ice: [f32; 2],
    /// Second point (channel reading, reference), °C.
    pub cal_warm: [f32; 2],
}

impl SettingsRecord {
    /// Kind tag.
    pub const TAG: u8 = b'S';
    /// Layout version written by this firmware.
    pub const VERSION: u8 = 1;
    /// Encoded length, bytes.
    pub const LEN: usize = 2 + 4 + 4 + 1 + 4 * 4 + 4;

    /// The calibration of the two points.
    pub fn calibration(&self) -> Result<TwoPoint, crate::calib::CalError> {
        use crate::units::Celsius;
        let ([mi, ri], [mw, rw]) = (self.cal_ice, self.cal_warm);
        TwoPoint::from_points(Celsius(mi), Celsius(ri), Celsius(mw), Celsius(rw))
    }

    /// The bytes to store.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut buf = [0u8; Self::LEN];
        let mut w = Writer::new(&mut buf, Self::TAG, Self::VERSION);
        w.u32(self.seq);
        w.f32(self.setpoint_c);
        w.put(&[self.law as u8]);
        for x in self.cal_ice.into_iter().chain(self.cal_warm) {
            w.f32(x);
        }
        w.finish();
        buf
    }

    /// Parses and checks stored bytes.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let mut r = open_frame(bytes, Self::LEN, Self::TAG, Self::VERSION)?;
        let seq = r.u32();
        let (lo, hi) = crate::iface::SETPOINT_RANGE_C;
        let setpoint_c = r.f32_in(lo, hi)?;
        let law = *crate::iface::Law::ALL.get(usize::from(r.u8())).ok_or(DecodeError::OutOfRange)?;
        let mut p = [0.0f32; 4];
        for x in p.iter_mut() {
            *x = r.f32_in(-50.0, 100.0)?;
        }
        let rec = SettingsRecord { seq, setpoint_c, law, cal_ice: [p[0], p[1]], cal_warm: [p[2], p[3]] };
        rec.calibration().map_err(|_| DecodeError::OutOfRange)?;
        Ok(rec)
    }
}

/// Why the MCU last reset (from the RCC reset flags on the STM32L4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Independent or window watchdog.
    Watchdog,
    /// The supply fell below the brown-out threshold: a brown-out or a power cycle. The
    /// STM32L4 sets the same flag for both (its BOR is the power-on reset), and for the
    /// vaccines they are the same event: RAM, and the record of those minutes, are lost.
    BrownOut,
    /// Pin (NRST, the debugger), software or anything else.
    Other,
}

impl ResetCause {
    /// The cause from the STM32L4's `RCC_CSR` (RM0351 §6.4.29), read at boot before the
    /// firmware clears the flags. Several flags can be set at once (a power-on sets BORRSTF and
    /// PINRSTF); the watchdog wins over the supply, the supply over the pin.
    pub fn from_stm32l4_csr(csr: u32) -> ResetCause {
        const IWDGRSTF: u32 = 1 << 29;
        const WWDGRSTF: u32 = 1 << 30;
        const BORRSTF: u32 = 1 << 27;
        if csr & (IWDGRSTF | WWDGRSTF) != 0 {
            ResetCause::Watchdog
        } else if csr & BORRSTF != 0 {
            ResetCause::BrownOut
        } else {
            ResetCause::Other
        }
    }
}

/// The records the board keeps in flash, each under its own key (its discriminant,
/// [`crate::persist::flash::key`]). What a boot refused of them is on the record
/// ([`HistoryRecord::refused`], [`crate::event::EventKind::RecordRefused`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Record {
    /// The self-tuner's model ([`ModelRecord`]).
    Model = 1,
    /// The calibration of an older firmware or of the build ([`CalibrationRecord`]).
    Calibration = 2,
    /// The cold-chain history ([`HistoryRecord`]).
    History = 3,
    /// The interface's settings ([`SettingsRecord`]).
    Settings = 4,
    /// The holdover's cabinet model ([`CabinetRecord`]).
    Cabinet = 5,
}

impl Record {
    /// Every record, in key order.
    pub const ALL: [Record; 5] =
        [Record::Model, Record::Calibration, Record::History, Record::Settings, Record::Cabinet];

    /// Its bit in a set of records ([`HistoryRecord::refused`], [`crate::app::Boot::refused`]).
    pub const fn bit(self) -> u8 {
        1 << (self as u8 - 1)
    }

    /// Stable snake_case name (the event's suffix).
    pub fn name(self) -> &'static str {
        match self {
            Record::Model => "model",
            Record::Calibration => "calibration",
            Record::History => "history",
            Record::Settings => "settings",
            Record::Cabinet => "cabinet",
        }
    }
}

/// Excursions kept in a [`HistoryRecord`] (the newest).
pub const HISTORY_EXCURSIONS: usize = 4;

/// Temperatures a stored extreme may have, °C: the RTD chain's measurable span with margin.
const TEMP_RANGE_C: core::ops::RangeInclusive<f32> = -60.0..=100.0;

/// The newest fail-safe stop a [`HistoryRecord`] keeps: the [`StopInfo`] without its text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LastStop {
    /// The path that stopped the board.
    pub kind: StopKind,
    /// Program counter of the faulting instruction (0 when there is none).
    pub pc: u32,
    /// Faulting data address (0 when none was latched).
    pub addr: u32,
    /// Kind-specific word ([`StopInfo::detail`]).
    pub detail: u32,
}

impl From<&StopInfo> for LastStop {
    fn from(info: &StopInfo) -> Self {
        LastStop { kind: info.kind, pc: info.pc, addr: info.addr, detail: info.detail }
    }
}

/// The sensor offset the step subtracts from every reading ([`crate::step::Carrier::sensor_offset`]:
/// a lead or connector fault the offset watch measured), as the history keeps it: in the channel's
/// own terms (the calibration's gain divided out, so that a calibration stored after it, and a
/// power cut before the next history, still restore it right), in whole steps of
/// [`Self::STEP_C`], up to [`Self::MAX_C`]. Forgotten at a restart, the fault it compensated read
/// up to 3 °C warm again, and the controller held the load that much colder (the freezing side).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorOffset(u8);

impl SensorOffset {
    /// No offset.
    pub const NONE: SensorOffset = SensorOffset(0);
    /// One step, °C: a restored offset is within half of it of the one subtracted.
    pub const STEP_C: f32 = 0.03;
    /// Steps the record's 7 bits hold.
    const MAX_STEPS: u8 = 127;
    /// Largest offset kept, °C (3.81 °C: [`crate::supervisor::sensor::OffsetConfig::max_comp_c`]
    /// through the lowest calibration gain a fit accepts, 3.0 °C / 0.9, fits).
    pub const MAX_C: f32 = Self::MAX_STEPS as f32 * Self::STEP_C;

    /// `offset_c` to the nearest step, within 0 … [`Self::MAX_C`] (NaN is none).
    pub fn from_c(offset_c: f32) -> Self {
        // `as` saturates: a negative or NaN offset is 0 steps (through u32, which the FPU's
        // conversion saturates to by itself: through u8 it took two compares more).
        SensorOffset(((offset_c * (1.0 / Self::STEP_C) + 0.5) as u32).min(Self::MAX_STEPS as u32) as u8)
    }

    /// The offset, °C.
    pub fn c(self) -> f32 {
        f32::from(self.0) * Self::STEP_C
    }
}

/// Cold-chain history summary, reset counts and board faults, accumulated over power cycles.
///
/// Layout v6, 139 bytes: `'H'`, 6; alarm counts (4 × u16, in [`AlarmKind`] order heat_10h,
/// freeze_60min, ship_45c_1h, ship_30c_10h); reset counts (3 × u16: watchdog, brown-out, other);
/// min_c, max_c (f32, NaN = no sample yet); time below 2 °C, time above 8 °C, excursion count,
/// recorded time (4 × u32, seconds and count); [`HISTORY_EXCURSIONS`] × (side u8: 0 none,
/// 1 cold, 2 warm; start_s, end_s, extreme_c f32); fail-safe stops (5 × u16, in
/// [`StopKind::ALL`] order); flash pages lost (u16); last stop (kind code u8, 0 = none; pc, addr,
/// detail u32); the carried byte (bit 0 the indicator's latch, bits 1–7 the
/// [`SensorOffset`]'s steps); the alarms' runs (4 × u32, [`Runs`]); the faults byte (bit 0 the
/// SSR found shorted, [`HistoryRecord::ssr_shorted`]; bit 1 the newest excursion under way at
/// the last sample, [`HistoryRecord::open_excursion`]; bits 2–6 the records the boot refused,
/// [`HistoryRecord::refused`]; v6 records written before these bits leave them at 0); CRC-32. Excursion times are
/// on the record's own clock: seconds of recorded time since the first boot (each boot's samples
/// start where the previous boot's record ended), so they stay in order across power cycles.
///
/// v5 (138 bytes: v6 without the faults byte) is still read with no short known; v4 (122
/// bytes: v5 without the runs) with no run under way either; v3 (121 bytes: v4 without the
/// carried byte) with nothing unacknowledged and no offset either; and v2 (96
/// bytes: v3 without the board-fault fields) with no faults counted either: it is the carrier's
/// cold-chain record, and a firmware update must not erase the alarms and excursions the
/// vaccines have been through. (v1 had no recorded time and stamped excursions
/// with seconds since their own boot; it is not read.)
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HistoryRecord {
    /// Alarms raised, per kind, in [`AlarmKind`] declaration order.
    pub alarms: [u16; 4],
    /// Boots seen, by the reset that started them: watchdog, brown-out, other. The boot that
    /// began the record is counted too (`status` shows the restarts: these less that one).
    pub resets: [u16; 3],
    /// Coldest sample, °C.
    pub min_c: Option<f32>,
    /// Warmest sample, °C.
    pub max_c: Option<f32>,
    /// Time below +2 °C, s.
    pub below_2_s: u32,
    /// Time above +8 °C, s.
    pub above_8_s: u32,
    /// Excursions outside 2 … 8 °C.
    pub excursions: u32,
    /// Time covered by the record over every boot, s (the excursions' clock).
    pub recorded_s: u32,
    /// The newest excursions, oldest first (`None` entries first while fewer were seen).
    pub last: [Option<Excursion>; HISTORY_EXCURSIONS],
    /// Fail-safe stops, per kind in [`StopKind::ALL`] order.
    pub stops: [u16; StopKind::ALL.len()],
    /// Flash pages found damaged by a power cut (an ECC error) and repaired at boot.
    pub flash_pages_lost: u16,
    /// The newest fail-safe stop.
    pub last_stop: Option<LastStop>,
    /// The alarm indicator's latch ([`Self::unacknowledged`]), the SSR's short
    /// ([`Self::ssr_shorted`]) and the newest excursion under way ([`Self::open_excursion`]) as
    /// bits 0, 1 and 2 of one byte, the records refused ([`Self::refused`]) in bits 3–7: a `bool`
    /// more made the record 4 bytes longer in RAM, and the copies of it 312 B more of the
    /// firmware's flash.
    flags: u8,
    /// The sensor offset the step subtracted ([`Recorder::note_carried`] stores every change at
    /// once; the next boot subtracts it again from its first sample,
    /// [`crate::step::Carrier::resume`]).
    pub sensor_offset: SensorOffset,
    /// The cold-chain alarms' runs under way at the last sample, which the next boot continues
    /// ([`ColdChainMonitor::resumed`]): without them the board started every run over at each
    /// boot, and 6 h of heat and a brown-out raised `heat_10h` 10 h after the restart instead of
    /// 4 h, as `hter monitor` does from the same record.
    pub runs: Runs,
}

/// [`HistoryRecord`]'s flag bits.
const UNACKNOWLEDGED: u8 = 1;
const SSR_SHORTED: u8 = 2;
/// The newest excursion was under way at the last sample ([`HistoryRecord::open_excursion`]).
const EXCURSION_OPEN: u8 = 4;
/// The records the last boot refused ([`HistoryRecord::refused`]), one bit each
/// ([`Record::bit`]) from bit 3 up.
const REFUSED: u8 = 0xF8;
const REFUSED_SHIFT: u8 = 3;

/// [`HistoryRecord`]'s flags for the latch and the short.
fn flags(unacknowledged: bool, ssr_shorted: bool) -> u8 {
    (u8::from(unacknowledged) * UNACKNOWLEDGED) | (u8::from(ssr_shorted) * SSR_SHORTED)
}

impl Default for HistoryRecord {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// `kind`'s slot in [`HistoryRecord::alarms`].
pub const fn alarm_index(kind: AlarmKind) -> usize {
    match kind {
        AlarmKind::Heat10h => 0,
        AlarmKind::Freeze60min => 1,
        AlarmKind::Ship45c1h => 2,
        AlarmKind::Ship30c10h => 3,
    }
}

/// `kind`'s slot in [`HistoryRecord::stops`], its place in [`StopKind::ALL`] (a test holds the
/// two together).
pub const fn stop_index(kind: StopKind) -> usize {
    match kind {
        StopKind::Panic => 0,
        StopKind::HardFault => 1,
        StopKind::Nmi => 2,
        StopKind::UnexpectedInterrupt => 3,
        StopKind::ControlStall => 4,
    }
}

/// `cause`'s slot in [`HistoryRecord::resets`].
pub const fn reset_index(cause: ResetCause) -> usize {
    match cause {
        ResetCause::Watchdog => 0,
        ResetCause::BrownOut => 1,
        ResetCause::Other => 2,
    }
}

/// Seconds as a saturating u32 (NaN and negatives give 0).
fn secs(x_s: f32) -> u32 {
    x_s as u32
}

impl HistoryRecord {
    /// Kind tag.
    pub const TAG: u8 = b'H';
    /// Layout version written by this firmware.
    pub const VERSION: u8 = 6;
    /// Length of a v2 record (still read), bytes.
    pub const LEN_V2: usize = 2 + 4 * 2 + 3 * 2 + 2 * 4 + 4 * 4 + HISTORY_EXCURSIONS * 13 + 4;
    /// Length of a v3 record (still read: the v4 one without the indicator's latch), bytes.
    pub const LEN_V3: usize = Self::LEN_V2 + StopKind::ALL.len() * 2 + 2 + 1 + 3 * 4;
    /// Length of a v4 record (still read: the v5 one without the alarms' runs), bytes.
    pub const LEN_V4: usize = Self::LEN_V3 + 1;
    /// Length of a v5 record (still read: the v6 one without the faults byte), bytes.
    pub const LEN_V5: usize = Self::LEN_V4 + 4 * 4;
    /// Encoded length, bytes.
    pub const LEN: usize = Self::LEN_V5 + 1;
    /// Nothing seen yet.
    pub const EMPTY: HistoryRecord = HistoryRecord::empty();

    /// [`HistoryRecord::EMPTY`], built in place where it is called: a use of the constant copies
    /// its 176 bytes (nearly all zero) from flash, where they sat once per use.
    #[inline(never)]
    pub const fn empty() -> Self {
        HistoryRecord {
            alarms: [0; 4],
            resets: [0; 3],
            min_c: None,
            max_c: None,
            below_2_s: 0,
            above_8_s: 0,
            excursions: 0,
            recorded_s: 0,
            last: [None; HISTORY_EXCURSIONS],
            stops: [0; StopKind::ALL.len()],
            flash_pages_lost: 0,
            last_stop: None,
            flags: 0,
            sensor_offset: SensorOffset::NONE,
            runs: [0; 4],
        }
    }

    /// The alarm indicator's latch ([`crate::alarm::Annunciator`]): a cold-chain alarm or a
    /// fault not yet acknowledged. The next boot starts from it: RAM alone lost it at every
    /// restart, and a brown-out silenced an alarm nobody had seen
    /// ([`Recorder::note_carried`] stores every change).
    pub fn unacknowledged(&self) -> bool {
        self.flags & UNACKNOWLEDGED != 0
    }

    /// The SSR was found shorted ([`crate::step::Carrier::ssr_shorted`]; [`Recorder::note_carried`]
    /// stores it at once): the next boot limps home from its first sample
    /// ([`crate::step::Carrier::resume`]). A short does not heal in a restart, and forgotten, a
    /// brown-out in limp home handed the modules back to the controller with the short still
    /// there: full cooling until the checks found it again, the load at 1.88 °C first (`hter sim
    /// --scenario disturbance --fault ssr-stuck-on@3000 --fault brownout@10000`). Only a
    /// technician's service reset clears it ([`Recorder::note_service`]): not a reset alone, which
    /// an NRST glitch or a debugger gives as well.
    pub fn ssr_shorted(&self) -> bool {
        self.flags & SSR_SHORTED != 0
    }

    /// The newest excursion if it was under way at the record's last sample: the next boot
    /// goes on with it ([`Recorder::new`], [`ColdChainMonitor::resumed`]), and if that boot's
    /// first reading is on its side it goes on across the restart, as `hter monitor` reads one
    /// excursion across a restart in a log, rather than count a new one. Before, each restart in
    /// an excursion counted one more: a supply that dropped every 50 minutes through a day of
    /// heat put 13 excursions on the record for one, and its four newest were all pieces of it
    /// (`hal-sim/tests/virtual_board.rs`). Stored in the faults byte's bit 1, which v6 readers before it ignore.
    pub fn open_excursion(&self) -> Option<Excursion> {
        match self.last {
            [.., e] if self.flags & EXCURSION_OPEN != 0 => e,
            _ => None,
        }
    }

    /// This record with the sensor offset `offset`.
    pub fn with_sensor_offset(mut self, offset: SensorOffset) -> Self {
        self.sensor_offset = offset;
        self
    }

    /// The stored records the boot that wrote this history refused, as [`Record::bit`]s: a record
    /// it could not use (a firmware that checks more than the one that wrote it, a corruption
    /// its CRC missed), for which it ran the build's default. The next boot reports only a record
    /// refused that this set does not have ([`crate::app::Boot::newly_refused`]): one refusal is
    /// one event and one alarm, not one at every boot. Stored in the faults byte's bits 2–6,
    /// which v6 readers before it ignore.
    pub fn refused(&self) -> u8 {
        self.flags >> REFUSED_SHIFT
    }

    /// This record with the latch and the short as given (the open excursion's bit and the
    /// refused records kept).
    pub fn with_carried(mut self, unacknowledged: bool, ssr_shorted: bool) -> Self {
        self.flags = flags(unacknowledged, ssr_shorted) | self.flags & (EXCURSION_OPEN | REFUSED);
        self
    }

    /// Counts an alarm.
    pub fn note_alarm(&mut self, kind: AlarmKind) {
        if let Some(n) = self.alarms.get_mut(alarm_index(kind)) {
            *n = n.saturating_add(1);
        }
    }

    /// Counts a reset.
    pub fn note_reset(&mut self, cause: ResetCause) {
        if let Some(n) = self.resets.get_mut(reset_index(cause)) {
            *n = n.saturating_add(1);
        }
    }

    /// Counts a fail-safe stop and keeps it as the newest.
    pub fn note_stop(&mut self, info: &StopInfo) {
        if let Some(n) = self.stops.get_mut(stop_index(info.kind)) {
            *n = n.saturating_add(1);
        }
        self.last_stop = Some(LastStop::from(info));
    }

    /// Fail-safe stops of `kind` seen.
    pub fn stops_of(&self, kind: StopKind) -> u16 {
        self.stops.get(stop_index(kind)).copied().unwrap_or(0)
    }

    /// Resets seen with `cause`.
    pub fn resets_by(&self, cause: ResetCause) -> u16 {
        self.resets.get(reset_index(cause)).copied().unwrap_or(0)
    }

    /// Alarms of `kind` raised.
    pub fn alarms_of(&self, kind: AlarmKind) -> u16 {
        self.alarms.get(alarm_index(kind)).copied().unwrap_or(0)
    }

    /// This record (what was carried in at boot) plus what `monitor` saw since boot. Always
    /// merge into the boot-time record, not into a previous merge, or this session counts twice,
    /// and `monitor` must have been resumed from it ([`Recorder::new`]: the alarms' runs and the
    /// excursion under way go on from the record's).
    pub(crate) fn merged(&self, monitor: &ColdChainMonitor) -> HistoryRecord {
        let pick = |a: Option<f32>, b: Option<f32>, f: fn(f32, f32) -> f32| match (a, b) {
            (Some(a), Some(b)) => Some(f(a, b)),
            (a, b) => a.or(b),
        };
        // This boot's excursions (on the record's clock) overwrite the oldest of the record's
        // in a ring, unrolled oldest first at the end: rotating the array once per excursion
        // instead is a `memmove` call each.
        let base = self.recorded_s as f32;
        let mut ring = self.last;
        // The monitor's first excursion is the record's newest if that one was under way: it
        // was handed on to the monitor ([`Recorder::new`]) and goes back in its own slot.
        let mut oldest = if self.open_excursion().is_some() { HISTORY_EXCURSIONS - 1 } else { 0 };
        for e in monitor.excursions() {
            ring[oldest] = Some(Excursion { start_s: base + e.start_s, end_s: base + e.end_s, ..*e });
            oldest = (oldest + 1) % HISTORY_EXCURSIONS;
        }
        // Set field by field on one copy: a struct literal with `..*self` built the record beside
        // the copy and moved it (≈ 90 B more flash for the same values).
        let mut rec = *self;
        // A loop over slots whose count is hidden from the optimiser (as `coldchain`'s
        // `kinds()`): unrolled fourfold, the copy out of the ring was 60 B more of the firmware's
        // flash (a count hidden alone was not enough: the array's length still bounded it).
        for (i, slot) in core::hint::black_box(&mut rec.last[..]).iter_mut().enumerate() {
            if let Some(e) = ring.get((oldest + i) % HISTORY_EXCURSIONS) {
                *slot = *e;
            }
        }
        rec.min_c = pick(self.min_c, monitor.min_c(), f32::min);
        rec.max_c = pick(self.max_c, monitor.max_c(), f32::max);
        rec.below_2_s = self.below_2_s.saturating_add(secs(monitor.time_below_2_s()));
        rec.above_8_s = self.above_8_s.saturating_add(secs(monitor.time_above_8_s()));
        rec.excursions = self.excursions.saturating_add(monitor.excursion_count());
        rec.recorded_s = self.recorded_s.saturating_add(secs(monitor.recorded_s()));
        rec.runs = monitor.runs();
        rec.flags = self.flags & !EXCURSION_OPEN | (u8::from(monitor.in_excursion()) * EXCURSION_OPEN);
        rec
    }

    /// The bytes to store.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut buf = [0u8; Self::LEN];
        let mut w = Writer::new(&mut buf, Self::TAG, Self::VERSION);
        for n in self.alarms.iter().chain(self.resets.iter()) {
            w.u16(*n);
        }
        w.f32(self.min_c.unwrap_or(f32::NAN));
        w.f32(self.max_c.unwrap_or(f32::NAN));
        w.u32(self.below_2_s);
        w.u32(self.above_8_s);
        w.u32(self.excursions);
        w.u32(self.recorded_s);
        for e in &self.last {
            match e {
                Some(e) => {
                    // The stored codes are the discriminants: 1 cold, 2 warm.
                    w.put(&[e.side as u8]);
                    w.f32(e.start_s);
                    w.f32(e.end_s);
                    w.f32(e.extreme_c);
                }
                None => w.put(&[0; 13]),
            }
        }
        for n in self.stops {
            w.u16(n);
        }
        w.u16(self.flash_pages_lost);
        match &self.last_stop {
            Some(s) => {
                w.put(&[s.kind as u8]);
                w.u32(s.pc);
                w.u32(s.addr);
                w.u32(s.detail);
            }
            None => w.put(&[0; 13]),
        }
        w.put(&[self.flags & UNACKNOWLEDGED | self.sensor_offset.0 << 1]);
        for r in self.runs {
            w.u32(r);
        }
        w.put(&[(self.flags & !UNACKNOWLEDGED) >> 1]);
        w.finish();
        buf
    }

    /// Parses and range-checks stored bytes: extremes within −60 … 100 °C (or absent) and
    /// min ≤ max; excursions with a known side, 0 ≤ start ≤ end and a finite extreme in range;
    /// a known stop kind. A v2 record decodes with no board faults, v2 and v3 with nothing
    /// unacknowledged and no sensor offset, v2 to v4 with no alarm run under way.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let (len, version) = match (bytes.len(), bytes.get(1)) {
            (Self::LEN_V2, Some(2)) => (Self::LEN_V2, 2),
            (Self::LEN_V3, Some(3)) => (Self::LEN_V3, 3),
            (Self::LEN_V4, Some(4)) => (Self::LEN_V4, 4),
            (Self::LEN_V5, Some(5)) => (Self::LEN_V5, 5),
            _ => (Self::LEN, Self::VERSION),
        };
        let v2 = version == 2;
        let mut r = open_frame(bytes, len, Self::TAG, version)?;
        let mut rec = HistoryRecord::empty();
        for n in rec.alarms.iter_mut().chain(rec.resets.iter_mut()) {
            *n = r.u16();
        }
        let mut extreme = || {
            let x = r.f32();
            if x.is_nan() {
                Ok(None)
            } else if !x.is_finite() {
                Err(DecodeError::NonFinite)
            } else if TEMP_RANGE_C.contains(&x) {
                Ok(Some(x))
            } else {
                Err(DecodeError::OutOfRange)
            }
        };
        rec.min_c = extreme()?;
        rec.max_c = extreme()?;
        if let (Some(lo), Some(hi)) = (rec.min_c, rec.max_c) {
            if lo > hi {
                return Err(DecodeError::OutOfRange);
            }
        }
        rec.below_2_s = r.u32();
        rec.above_8_s = r.u32();
        rec.excursions = r.u32();
        rec.recorded_s = r.u32();
        for slot in rec.last.iter_mut() {
            let side = match r.u8() {
                0 => {
                    r.skip(12);
                    continue;
                }
                1 => Side::Cold,
                2 => Side::Warm,
                _ => return Err(DecodeError::OutOfRange),
            };
            let start_s = r.f32_in(0.0, f32::MAX)?;
            let end_s = r.f32_in(start_s, f32::MAX)?;
            let extreme_c = r.f32_in(*TEMP_RANGE_C.start(), *TEMP_RANGE_C.end())?;
            *slot = Some(Excursion { side, start_s, end_s, extreme_c });
        }
        if v2 {
            return Ok(rec);
        }
        for n in rec.stops.iter_mut() {
            *n = r.u16();
        }
        rec.flash_pages_lost = r.u16();
        let code = r.u8();
        let (pc, addr, detail) = (r.u32(), r.u32(), r.u32());
        rec.last_stop = match code {
            0 => None,
            code => {
                Some(LastStop { kind: StopKind::from_code(code).ok_or(DecodeError::OutOfRange)?, pc, addr, detail })
            }
        };
        // A v3 frame ends here: its reader reads 0, nothing unacknowledged and no offset (as the
        // v4 records written before the offset was kept, whose byte is 0 or 1).
        let carried = r.u8();
        rec.flags = carried & UNACKNOWLEDGED;
        rec.sensor_offset = SensorOffset(carried >> 1);
        // A v4 frame ends here: no run under way. Every value of a run is one.
        for run in rec.runs.iter_mut() {
            *run = r.u32();
        }
        // A v5 frame ends here: no short known. Bit 0 the SSR's short, bit 1 the newest
        // excursion under way, bits 2–6 the records refused; bit 7 is free.
        rec.flags |= (r.u8() & 0x7F) << 1;
        Ok(rec)
    }
}

/// What one sample did to the cold-chain record: the alarms it raised and whether the history
/// is due to be stored ([`Recorder::history`] gives it; not carried here, so the samples that
/// store nothing do not move a hundred bytes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recorded {
    /// Alarms this sample raised (at most one per kind).
    pub raised: Raised,
    /// Store the history now: after an alarm, after a change of the indicator's latch or the sensor
    /// offset ([`Recorder::note_carried`]), when an alarm's run the last store handed on ended
    /// (the next boot would carry it on), and every `save_every_samples` samples
    /// ([`EXCURSION_SAVES`] times as often during an excursion).
    pub save_due: bool,
    /// …and past the write gate's hold-off: an alarm was raised or the latch was set.
    pub urgent: bool,
}

/// How many times as often the [`Recorder`] stores the history while an excursion is under way:
/// every 10 minutes at the board's hourly period.
pub const EXCURSION_SAVES: u32 = 6;

/// The carrier's cold-chain record across power cycles: the history carried in at boot, this
/// boot's [`ColdChainMonitor`], and when to store their merge. The firmware feeds it every
/// step's output and stores what it hands back; a power cut loses at most the samples since
/// the last store (an hour by default, 10 minutes while the load is outside 2…8 °C), never an
/// alarm.
#[derive(Clone, Debug)]
pub struct Recorder {
    boot: HistoryRecord,
    monitor: ColdChainMonitor,
    save_every_samples: u32,
    since_save: u32,
    /// The kinds whose alarm run was under way in the history last handed over (bit i:
    /// [`AlarmKind::ALL`]`[i]`): when one of them ends, the history is due, or the next boot
    /// would carry on a run that had ended (and raise its alarm early).
    runs_stored: u8,
}

/// The kinds with a run under way in `runs`, as bits in [`AlarmKind::ALL`] order. Out of line:
/// three callers.
#[inline(never)]
fn run_bits(runs: &Runs) -> u8 {
    runs.iter().enumerate().fold(0, |b, (i, r)| b | u8::from(*r != 0) << i)
}

impl Recorder {
    /// A record that continues `boot` (the stored history, or [`HistoryRecord::EMPTY`]) and
    /// asks for a store every `save_every_samples` samples (at least 1).
    pub fn new(boot: HistoryRecord, save_every_samples: u32) -> Self {
        Recorder {
            boot,
            // The alarms' runs and the excursion under way go on where the stored history left
            // them (the history's merge puts that excursion back in its slot).
            monitor: ColdChainMonitor::resumed(&boot.runs, boot.open_excursion(), boot.recorded_s as f32),
            save_every_samples: save_every_samples.max(1),
            since_save: 0,
            runs_stored: run_bits(&boot.runs),
        }
    }

    /// Counts the reset that started this boot; returns the history to store (a brown-out must
    /// be on record even if the next one follows within the hour). The firmware holds it until
    /// its [`WriteGate`] opens, so a boot that does not stay up on a good supply writes nothing.
    pub fn note_reset(&mut self, cause: ResetCause) -> HistoryRecord {
        self.boot.note_reset(cause);
        self.since_save = 0;
        self.history()
    }

    /// Counts a fail-safe stop (one the boot found in [`crate::failsafe::ResetRecords`]); returns
    /// the history to store.
    pub fn note_board_fault(&mut self, info: &StopInfo) -> HistoryRecord {
        self.boot.note_stop(info);
        self.since_save = 0;
        self.history()
    }

    /// Counts the boot: its reset ([`Self::note_reset`]) and the fail-safe stops the stored
    /// history lacks, the previous boot's and one before it if the boot found them
    /// ([`crate::failsafe::ResetRecords::boot`]), oldest first, so the newest is the history's
    /// [`HistoryRecord::last_stop`]; returns the history to store and to resume from
    /// ([`crate::step::Carrier::resume`]). What the history carries (the SSR's short, the sensor
    /// offset) stays, whatever the reset: only a service reset ([`Self::note_service`]) forgets
    /// it.
    pub fn note_boot(&mut self, reset: ResetCause, stops: &crate::failsafe::Stops) -> HistoryRecord {
        self.boot.note_reset(reset);
        for f in stops.iter() {
            self.boot.note_stop(f);
        }
        self.since_save = 0;
        self.history()
    }

    /// A technician's service reset ([`crate::app::Boot::service_reset`]: the acknowledge button
    /// held through a reset, after replacing the SSR or repairing the probe's lead): forgets one
    /// repair, the SSR's short ([`HistoryRecord::ssr_shorted`]) if the history carries one, else
    /// the sensor offset ([`HistoryRecord::sensor_offset`]); returns the history to store and to
    /// resume from. A short still there is found again as on a first boot (full cooling until
    /// the checks do, the load to ≈ 1.9 °C first). An offset still there is not: the offset
    /// watch sees steps, and after a restart the first reading already carries it, so the load
    /// would be held that much colder for good (up to 3 °C, the freeze guard blind to it).
    /// Forgetting both at once forgot a damaged lead's offset at the service reset that followed
    /// an SSR's replacement; both repaired take two service resets. Before, any pin or software
    /// reset without a fail-safe stop cleared the short: the reset button, but also an NRST
    /// glitch or a debugger attaching under reset.
    pub fn note_service(&mut self) -> HistoryRecord {
        if self.boot.ssr_shorted() {
            self.boot.flags &= !SSR_SHORTED;
        } else {
            self.boot.sensor_offset = SensorOffset::NONE;
        }
        self.since_save = 0;
        self.history()
    }

    /// Keeps the stored records this boot refused (`refused`, [`Record::bit`]s) as the history's
    /// [`HistoryRecord::refused`], and sets the alarm indicator's latch if one of them is not
    /// among those the stored history had (a refusal nobody has seen yet). What a boot calls
    /// first ([`crate::app::Boot::resume`]): the history [`Self::note_boot`] returns has them. A
    /// refusal is not stored at once: lost to a power cut before the next store, the next boot
    /// finds it new again and reports it then.
    pub fn note_refused(&mut self, refused: u8) {
        if refused & !self.boot.refused() != 0 {
            self.boot.flags |= UNACKNOWLEDGED;
        }
        self.boot.flags = self.boot.flags & !REFUSED | refused << REFUSED_SHIFT;
    }

    /// Counts a flash page the boot found damaged and repaired; returns the history to store.
    pub fn note_flash_page_lost(&mut self) -> HistoryRecord {
        self.boot.flash_pages_lost = self.boot.flash_pages_lost.saturating_add(1);
        self.since_save = 0;
        self.history()
    }

    /// Records one sample: the temperature the controller saw
    /// ([`crate::step::StepOutput::recorded_c`], as `hter sim` and the processor-in-the-loop
    /// runner record it), NaN for a sample without a reading (a sensor fault), whose time the
    /// record leaves out ([`ColdChainMonitor::push`]'s rule). Before, the step's last good reading,
    /// held through the fault, went on the record as a measurement: 12 h of an open sensor on a
    /// load above 8 °C were 12 h in range at the held 4 °C, and no `heat_10h`.
    pub fn push(&mut self, t_ms: u64, temp_c: f32) -> Recorded {
        let raised = self.monitor.push(t_ms, temp_c);
        let mut alarm = false;
        for a in raised.iter().flatten() {
            self.boot.note_alarm(a.kind);
            alarm = true;
        }
        self.since_save = self.since_save.saturating_add(1);
        // A run the stored history has under way ended: stored behind the hold-off (at most
        // one store a kind between two periodic ones). The runs are packed only when the last
        // store had one under way, not on every sample in range.
        let ended = self.runs_stored != 0 && self.runs_stored & !run_bits(&self.monitor.runs()) != 0;
        // During an excursion (every alarm's run is part of one) the history is stored
        // [`EXCURSION_SAVES`] times as often: a supply that drops more often than the periodic
        // store would lose every excursion it cut short, and a carried run would be up to the
        // whole period short.
        let every = if self.monitor.in_excursion() {
            self.save_every_samples / EXCURSION_SAVES
        } else {
            self.save_every_samples
        };
        let save_due = alarm || ended || self.since_save >= every;
        if save_due {
            self.since_save = 0;
        }
        Recorded { raised, save_due, urgent: alarm }
    }

    /// Takes what the next boot carries on from this one, after the sample `r` recorded and
    /// before [`Self::due_save`]: the alarm indicator's latch
    /// ([`crate::alarm::Annunciator::latched`]), the sensor offset the step subtracts
    /// ([`crate::step::Carrier::sensor_offset`]) and whether it found the SSR shorted
    /// ([`crate::step::Carrier::ssr_shorted`]). A change is stored with the history: at once
    /// when the latch was set (a fault or alarm nobody has seen yet must survive a power cut
    /// that follows it), the offset changed (forgotten, the load is held colder by it) or a
    /// short was found (forgotten, the modules cool flat out after the restart);
    /// behind the write gate's hold-off when an acknowledgement cleared the latch (lost to a
    /// cut, the indicator comes back on: the safe side).
    #[inline(never)]
    pub fn note_carried(&mut self, r: &mut Recorded, latched: bool, offset: SensorOffset, shorted: bool) {
        let moved = self.boot.sensor_offset != offset;
        let found = shorted && !self.boot.ssr_shorted();
        if self.boot.unacknowledged() != latched || moved || found {
            self.boot.flags = flags(latched, shorted) | self.boot.flags & (EXCURSION_OPEN | REFUSED);
            self.boot.sensor_offset = offset;
            self.since_save = 0;
            r.save_due = true;
            r.urgent |= latched | moved | found;
        }
    }

    /// What to store after the sample `r` recorded: the history at once when it raised an alarm
    /// or set the indicator's latch ([`Save::AlarmHistory`], which skips the write gate's
    /// hold-off), or when the periodic store is due or a run the last store handed on ended
    /// ([`Save::History`]). It notes the runs the store hands on.
    pub fn due_save(&mut self, r: &Recorded) -> Option<Save> {
        if !r.save_due {
            return None;
        }
        let h = self.history();
        // The runs this store hands on: when one of them ends, the next store is due.
        self.runs_stored = run_bits(&h.runs);
        Some(if r.urgent { Save::AlarmHistory(h) } else { Save::History(h) })
    }

    /// This boot's monitor (MKT, extremes, excursions since boot).
    pub fn monitor(&self) -> &ColdChainMonitor {
        &self.monitor
    }

    /// The whole history: what was carried in at boot plus this boot's record.
    pub fn history(&self) -> HistoryRecord {
        self.boot.merged(&self.monitor)
    }
}

/// When to store the self-tuner's trusted model: once every `every_samples` samples in which
/// its estimate was trusted (mode [`AdaptiveMode::Adaptive`]), so a board that is not learning
/// (frozen, on its fallback, or not self-tuning) never rewrites the same model. The count
/// starts again at every boot, and a boot's first store comes after a quarter of that (1 h of
/// trusted samples on the board): a supply that drops every few hours would otherwise never
/// let a learnt model reach flash, and every boot would start again from the start model (a
/// half-loaded H-TER I on the full-load start model swings 3.2–4.7 °C for a quarter of an hour
/// after it; `hter virtual-board --load half --fault brownout@T`). A power cut loses at most the
/// learning since the last store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelCadence {
    every_samples: u32,
    trusted_samples: u32,
    /// The boot has stored its first model.
    stored: bool,
}

impl ModelCadence {
    /// A store every `every_samples` trusted samples (at least 1;
    /// [`crate::profile::MODEL_SAVE_S`] in samples on the board), the boot's first after a
    /// quarter of them.
    pub fn new(every_samples: u32) -> Self {
        ModelCadence { every_samples: every_samples.max(1), trusted_samples: 0, stored: false }
    }

    /// Counts one step of `controller` (after `Carrier::step`), `mode` the self-tuner's mode
    /// that step reported (`StepOutput::status`; `None` for a controller that learns nothing);
    /// the record to store when one is due. A due store of a model [`ModelRecord`] cannot hold
    /// (na ≠ 2, or more than [`ModelRecord::NB`] B terms) is skipped, and the count starts again.
    pub fn push(&mut self, mode: Option<AdaptiveMode>, controller: &impl Controller) -> Option<ModelRecord> {
        if mode != Some(AdaptiveMode::Adaptive) {
            return None;
        }
        self.trusted_samples = self.trusted_samples.saturating_add(1);
        let due = if self.stored { self.every_samples } else { (self.every_samples / 4).max(1) };
        if self.trusted_samples < due {
            return None;
        }
        self.trusted_samples = 0;
        self.stored = true;
        controller.trusted_model().as_ref().and_then(ModelRecord::from_model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::{ADAPTIVE_GPC, START_MODEL_HTER1, START_MODEL_HTER2};

    fn cfg() -> AdaptiveConfig {
        ADAPTIVE_GPC
    }

    #[test]
    fn each_kind_has_its_own_slot_in_the_history_and_the_stops_are_in_their_list_order() {
        for (i, k) in StopKind::ALL.into_iter().enumerate() {
            assert_eq!(stop_index(k), i, "{k:?}");
        }
        let alarms: Vec<usize> = AlarmKind::ALL.into_iter().map(alarm_index).collect();
        assert_eq!(alarms, [0, 1, 2, 3]);
        let resets: Vec<usize> =
            [ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other].into_iter().map(reset_index).collect();
        assert_eq!(resets, [0, 1, 2]);
    }

    /// RCC_CSR values as RM0351 documents them: the reset value after a power-on (BORRSTF and
    /// PINRSTF set, MSI range bits 0x600), a watchdog bite (IWDGRSTF and PINRSTF: the
    /// watchdog drives NRST low), NRST alone, a software reset (SFTRSTF and PINRSTF).
    #[test]
    fn reset_cause_from_the_rcc_flags() {
        assert_eq!(ResetCause::from_stm32l4_csr(0x0C00_0600), ResetCause::BrownOut);
        assert_eq!(ResetCause::from_stm32l4_csr(0x2400_0600), ResetCause::Watchdog);
        assert_eq!(ResetCause::from_stm32l4_csr(0x4400_0600), ResetCause::Watchdog);
        assert_eq!(ResetCause::from_stm32l4_csr(0x0400_0600), ResetCause::Other);
        assert_eq!(ResetCause::from_stm32l4_csr(0x1400_0600), ResetCause::Other);
        assert_eq!(ResetCause::from_stm32l4_csr(0), ResetCause::Other);
    }

    /// Writes the CRC of a frame's bytes before its last four into them: a frame edited by a
    /// test, framed again so that only the edit is checked (also `persist::fuzz`'s).
    pub(crate) fn reframe(frame: &mut [u8]) {
        let n = frame.len() - 4;
        let crc = crc32(&frame[..n]);
        frame[n..].copy_from_slice(&crc.to_le_bytes());
    }

    /// A history record as an older `version` of `N` bytes wrote it: the current encoding's
    /// first `N` − 4 bytes (each version appended its fields), that version's number, its CRC.
    fn older_history<const N: usize>(current: &[u8], version: u8) -> [u8; N] {
        let mut old = [0u8; N];
        old[..N - 4].copy_from_slice(&current[..N - 4]);
        old[1] = version;
        reframe(&mut old);
        old
    }

    #[test]
    fn crc32_check_value() {
        // The catalogue check value of CRC-32/ISO-HDLC.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    /// A θ-and-k record built byte by byte from the documented layout, independent of the
    /// encoder: `tag`, `version`, θ (f32 LE), k, CRC-32 (LE) of everything before it.
    fn frame_by_hand(tag: u8, version: u8, theta: &[f32], k: u8) -> std::vec::Vec<u8> {
        let mut b = std::vec![tag, version];
        for x in theta {
            b.extend_from_slice(&x.to_le_bytes());
        }
        b.push(k);
        let crc = crc32(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }

    #[test]
    fn model_round_trip_and_restore() {
        let rec = ModelRecord::from_model(&START_MODEL_HTER2).unwrap();
        assert_eq!(rec.k, 6);
        let (a, b) = (START_MODEL_HTER2.a(), START_MODEL_HTER2.b());
        assert_eq!(rec.theta, [a[0], a[1], b[0], b[1], 0.0, 0.0], "a second-order B padded with zeros");
        let bytes = rec.encode();
        assert_eq!(bytes.len(), ModelRecord::LEN);
        assert_eq!(ModelRecord::LEN, 31);
        assert_eq!(&bytes[..2], &[b'M', 2]);
        assert_eq!(bytes[..], frame_by_hand(b'M', 2, &rec.theta, 6)[..], "the documented layout v2");
        assert_eq!(ModelRecord::decode(&bytes), Ok(rec));
        let restored = rec.restore(&cfg()).unwrap();
        assert_eq!(restored.k, 6);
        let m = restored.initial.unwrap();
        assert_eq!(m.a()[..2], START_MODEL_HTER2.a()[..2]);
        // The record's four B terms, the last two zero: the same polynomial.
        assert_eq!(m.nb(), ModelRecord::NB);
        assert_eq!(m.b()[..], [b[0], b[1], 0.0, 0.0]);
        assert_eq!(m.static_gain(), START_MODEL_HTER2.static_gain());
        // GPC's T-filter is rebuilt from the configuration, as for a live estimate.
        assert_eq!(m.nc(), 1);
    }

    #[test]
    fn every_b_order_of_the_self_tuner_has_a_record_and_no_other_structure_does() {
        let a = [-1.7f32, 0.75];
        // Static gains −16 … −30 °C per duty: plausible for every nb.
        let b4 = [-0.8f32, -0.4, -0.2, -0.1];
        for nb in 1..=ModelRecord::NB {
            let m = Model::new(&a, &b4[..nb], &[], 5).unwrap();
            let rec = ModelRecord::from_model(&m).unwrap_or_else(|| panic!("nb {nb}"));
            let mut want = [0.0f32; 6];
            want[..2].copy_from_slice(&a);
            want[2..2 + nb].copy_from_slice(&b4[..nb]);
            assert_eq!(rec.theta, want, "nb {nb}");
            let back = ModelRecord::decode(&rec.encode()).unwrap();
            assert_eq!(back, rec, "nb {nb}");
            let m2 = back.to_model(&cfg()).unwrap();
            assert_eq!((&m2.a()[..2], &m2.b()[..nb], m2.k()), (&a[..], &b4[..nb], 5), "nb {nb}");
            assert!(m2.b()[nb..].iter().all(|&x| x == 0.0), "nb {nb}");
        }
        // The self-tuner's A is second order: first and third order have no record.
        let first_order = Model::new(&[-0.9], &[-0.5], &[], 3).unwrap();
        assert_eq!(ModelRecord::from_model(&first_order), None);
        let third_order = Model::new(&[-1.7, 0.75, -0.01], &b4, &[], 3).unwrap();
        assert_eq!(ModelRecord::from_model(&third_order), None);
        // The cabinet record keeps the commissioning's second-order model only.
        assert_eq!(CabinetRecord::from_model(&Model::new(&a, &b4, &[], 5).unwrap()), None);
        assert_eq!(CabinetRecord::from_model(&Model::new(&a, &b4[..1], &[], 5).unwrap()), None);
        let cab = CabinetRecord::from_model(&START_MODEL_HTER1).unwrap();
        let bytes = cab.encode();
        assert_eq!(bytes.len(), 23);
        assert_eq!(bytes[..], frame_by_hand(b'K', 1, &cab.theta, cab.k)[..], "the cabinet record stays v1");
    }

    /// A board updated in the field finds the v1 record its previous firmware wrote (two B
    /// terms, 23 bytes) and restarts from that model.
    #[test]
    fn a_v1_model_record_is_still_read() {
        let (a, b) = (START_MODEL_HTER1.a(), START_MODEL_HTER1.b());
        let k = START_MODEL_HTER1.k() as u8;
        let v1 = frame_by_hand(b'M', 1, &[a[0], a[1], b[0], b[1]], k);
        assert_eq!(v1.len(), ModelRecord::LEN_V1);
        assert_eq!(v1.len(), 23);
        let rec = ModelRecord::decode(&v1).expect("v1 is read");
        assert_eq!(rec, ModelRecord { theta: [a[0], a[1], b[0], b[1], 0.0, 0.0], k });
        let m = rec.restore(&cfg()).expect("the v1 model is restored").initial.unwrap();
        assert_eq!((&m.a()[..2], &m.b()[..], m.k()), (&a[..2], &[b[0], b[1], 0.0, 0.0][..], usize::from(k)));
        // Stored again, it is written as v2 with the same θ.
        assert_eq!(&rec.encode()[..2], &[b'M', 2]);
        assert_eq!(ModelRecord::decode(&rec.encode()), Ok(rec));

        // A v1 record is checked as a v2 one is.
        let mut torn = v1.clone();
        torn[5] ^= 0x10;
        assert_eq!(ModelRecord::decode(&torn), Err(DecodeError::Crc));
        let bad_k = frame_by_hand(b'M', 1, &[a[0], a[1], b[0], b[1]], 0);
        assert_eq!(ModelRecord::decode(&bad_k), Err(DecodeError::OutOfRange));
        let nan = frame_by_hand(b'M', 1, &[a[0], f32::NAN, b[0], b[1]], k);
        assert_eq!(ModelRecord::decode(&nan), Err(DecodeError::NonFinite));
        let heating = frame_by_hand(b'M', 1, &[a[0], a[1], 0.03, b[1]], k);
        assert_eq!(ModelRecord::decode(&heating).unwrap().to_model(&cfg()), Err(DecodeError::Implausible));
        // The version byte and the length go together: a v2 byte on a v1 length is not a v2
        // record (its length), a v1 byte on a v2 record breaks its CRC, and a v1 byte with a
        // valid CRC on a v2 length is a version this firmware does not read.
        let mut b2 = v1.clone();
        b2[1] = 2;
        assert_eq!(ModelRecord::decode(&b2), Err(DecodeError::Length));
        let mut b1 = rec.encode();
        b1[1] = 1;
        assert_eq!(ModelRecord::decode(&b1), Err(DecodeError::Crc));
        let v1_byte_31 = frame_by_hand(b'M', 1, &rec.theta, k);
        assert_eq!(ModelRecord::decode(&v1_byte_31), Err(DecodeError::Version));
        // A cabinet record (same length as v1, its own tag) is not a model record.
        let cab = CabinetRecord::from_model(&START_MODEL_HTER1).unwrap().encode();
        assert_eq!(ModelRecord::decode(&cab), Err(DecodeError::Kind));
    }

    #[test]
    fn every_single_bit_flip_is_caught() {
        let v2 = ModelRecord::from_model(&START_MODEL_HTER1).unwrap().encode();
        let (a, b) = (START_MODEL_HTER1.a(), START_MODEL_HTER1.b());
        let v1 = frame_by_hand(b'M', 1, &[a[0], a[1], b[0], b[1]], START_MODEL_HTER1.k() as u8);
        for bytes in [&v2[..], &v1[..]] {
            for i in 0..bytes.len() * 8 {
                let mut b = bytes.to_vec();
                b[i / 8] ^= 1 << (i % 8);
                assert!(ModelRecord::decode(&b).is_err(), "flip of bit {i} of {} bytes accepted", bytes.len());
            }
        }
    }

    #[test]
    fn frame_errors() {
        let bytes = ModelRecord { theta: [-1.7, 0.75, -0.03, -0.03, -0.01, 0.0], k: 5 }.encode();
        assert_eq!(ModelRecord::decode(&bytes[..30]), Err(DecodeError::Length));
        assert_eq!(ModelRecord::decode(&bytes[..22]), Err(DecodeError::Length));
        assert_eq!(ModelRecord::decode(&[0xFF; ModelRecord::LEN]), Err(DecodeError::Crc));
        assert_eq!(CalibrationRecord::decode(&bytes[..14]), Err(DecodeError::Crc));
        // Re-frame with a good CRC: wrong version, then wrong kind.
        let with_header = |tag: u8, ver: u8| {
            let mut b = bytes;
            b[0] = tag;
            b[1] = ver;
            reframe(&mut b);
            b
        };
        assert_eq!(ModelRecord::decode(&with_header(b'M', 3)), Err(DecodeError::Version));
        assert_eq!(ModelRecord::decode(&with_header(b'C', 2)), Err(DecodeError::Kind));
    }

    #[test]
    fn model_checks() {
        let bad_k = ModelRecord { theta: [-1.7, 0.75, -0.03, -0.03, 0.0, 0.0], k: 0 }.encode();
        assert_eq!(ModelRecord::decode(&bad_k), Err(DecodeError::OutOfRange));
        let nan = ModelRecord { theta: [f32::NAN, 0.75, -0.03, -0.03, 0.0, 0.0], k: 5 }.encode();
        assert_eq!(ModelRecord::decode(&nan), Err(DecodeError::NonFinite));
        let inf_b3 = ModelRecord { theta: [-1.7, 0.75, -0.03, -0.03, 0.0, f32::NEG_INFINITY], k: 5 }.encode();
        assert_eq!(ModelRecord::decode(&inf_b3), Err(DecodeError::NonFinite));
        // Decodes, but: unstable A (pole at 1.2), a heating b0, a heating b3, a gain of −1 °C per
        // duty.
        for theta in [
            [-2.2, 1.2, -0.03, -0.03, 0.0, 0.0],
            [-1.7, 0.75, 0.03, -0.03, 0.0, 0.0],
            [-1.7, 0.75, -0.03, -0.03, -0.01, 0.002],
            [-1.7, 0.75, -0.0005, -0.0005, 0.0, 0.0],
        ] {
            let rec = ModelRecord::decode(&ModelRecord { theta, k: 5 }.encode()).unwrap();
            assert_eq!(rec.to_model(&cfg()), Err(DecodeError::Implausible), "{theta:?}");
        }
    }

    #[test]
    fn calibration_round_trip_and_ranges() {
        let rec = CalibrationRecord { cal: TwoPoint { gain: 1.02, offset_c: -0.35 } };
        assert_eq!(CalibrationRecord::decode(&rec.encode()), Ok(rec));
        let gain = CalibrationRecord { cal: TwoPoint { gain: 1.2, offset_c: 0.0 } };
        assert_eq!(CalibrationRecord::decode(&gain.encode()), Err(DecodeError::OutOfRange));
        let offset = CalibrationRecord { cal: TwoPoint { gain: 1.0, offset_c: 12.0 } };
        assert_eq!(CalibrationRecord::decode(&offset.encode()), Err(DecodeError::OutOfRange));
        let inf = CalibrationRecord { cal: TwoPoint { gain: 1.0, offset_c: f32::INFINITY } };
        assert_eq!(CalibrationRecord::decode(&inf.encode()), Err(DecodeError::NonFinite));
    }

    /// Found by fuzzing (`fuzz::edited_calibration_and_settings_records`): the record took any
    /// offset up to 10 °C with any gain in 0.9 … 1.1, lines that move a reading between 0 and
    /// 10 °C by up to 11 °C, where a calibration ([`TwoPoint::from_points`], the interface's
    /// `set cal_ice`) stops at [`crate::calib::MAX_CORRECTION_C`]. A build without the interface
    /// runs the stored line as it is: gain 1.1 and offset 10 °C read a −5.5 °C load as 4 °C, the
    /// freeze guard blind to it.
    #[test]
    fn a_calibration_record_beyond_what_a_calibration_accepts_is_refused() {
        for (gain, offset_c) in [(1.1, 10.0), (0.9, -10.0), (1.093_570_1, 1.193_910_5), (1.0, 1.6), (1.1, 0.6)] {
            let rec = CalibrationRecord { cal: TwoPoint { gain, offset_c } };
            assert_eq!(CalibrationRecord::decode(&rec.encode()), Err(DecodeError::OutOfRange), "{gain} {offset_c}");
        }
        // Every line a calibration gives is read, at the limits too.
        use crate::units::Celsius;
        for (mi, ri, mw, rw) in
            [(0.12, 0.0, 25.31, 25.02), (0.0, 1.5, 10.0, 11.5), (0.0, -1.5, 10.0, 8.5), (0.0, 1.5, 10.0, 10.5)]
        {
            let cal = TwoPoint::from_points(Celsius(mi), Celsius(ri), Celsius(mw), Celsius(rw)).unwrap();
            assert_eq!(CalibrationRecord::decode(&CalibrationRecord { cal }.encode()), Ok(CalibrationRecord { cal }));
        }
    }

    fn monitor(samples: &[(f32, f32)]) -> ColdChainMonitor {
        monitor_after(&HistoryRecord::EMPTY, samples)
    }

    /// The monitor of the boot after the one that stored `rec`, as [`Recorder::new`] starts it.
    fn monitor_after(rec: &HistoryRecord, samples: &[(f32, f32)]) -> ColdChainMonitor {
        let mut m = ColdChainMonitor::resumed(&rec.runs, rec.open_excursion(), rec.recorded_s as f32);
        for &(t, c) in samples {
            m.push(t as u64 * 1000, c);
        }
        m
    }

    #[test]
    fn history_merge_and_round_trip() {
        let mut base = HistoryRecord::EMPTY;
        base.note_reset(ResetCause::BrownOut);
        base.note_reset(ResetCause::BrownOut);
        base.note_reset(ResetCause::Watchdog);
        base.note_alarm(AlarmKind::Freeze60min);
        assert_eq!(HistoryRecord::decode(&base.encode()), Ok(base));

        // Warm excursion 600 … 1200 s, cold one 1800 … 2400 s.
        let samples: std::vec::Vec<(f32, f32)> = (0..40)
            .map(|i| {
                let t = 60.0 * i as f32;
                (
                    t,
                    if (10..=20).contains(&i) {
                        9.5
                    } else if (30..=35).contains(&i) {
                        1.0
                    } else {
                        5.0
                    },
                )
            })
            .collect();
        let mon = monitor(&samples);
        let first = base.merged(&mon);
        assert_eq!(first.resets_by(ResetCause::BrownOut), 2);
        assert_eq!(first.alarms_of(AlarmKind::Freeze60min), 1);
        assert_eq!(first.min_c, Some(1.0));
        assert_eq!(first.max_c, Some(9.5));
        assert_eq!(first.excursions, 2);
        assert_eq!(first.above_8_s, mon.time_above_8_s() as u32);
        assert!(first.above_8_s >= 600);
        assert_eq!(first.last[..2], [None, None]);
        assert_eq!(first.last[2].unwrap().side, Side::Warm);
        assert_eq!(first.last[3].unwrap().side, Side::Cold);
        assert_eq!(HistoryRecord::decode(&first.encode()), Ok(first));

        // Next boot: carried totals plus a session with a colder minimum; the ring keeps the newest.
        let second = first.merged(&monitor_after(&first, &[(0.0, 0.5), (60.0, 5.0), (120.0, 9.0), (180.0, 5.0)]));
        assert_eq!(second.min_c, Some(0.5));
        assert_eq!(second.max_c, Some(9.5));
        assert_eq!(second.excursions, 4);
        let sides: std::vec::Vec<Side> = second.last.iter().flatten().map(|e| e.side).collect();
        assert_eq!(sides, [Side::Warm, Side::Cold, Side::Cold, Side::Warm]);
        // The second boot's excursions continue the first one's clock (2 340 s recorded).
        assert_eq!(first.recorded_s, 2340);
        assert_eq!(second.recorded_s, 2340 + 180);
        assert_eq!(second.last[2].map(|e| e.start_s), Some(2340.0));
        assert_eq!(second.last[3].map(|e| (e.start_s, e.end_s)), Some((2340.0 + 120.0, 2340.0 + 120.0)));
        assert!(second.last[1].unwrap().end_s < second.last[2].unwrap().start_s);
        assert_eq!(HistoryRecord::decode(&second.encode()), Ok(second));

        // A boot with more excursions than the record keeps: its newest four, oldest first.
        let third = second.merged(&monitor_after(
            &second,
            &[(0.0, 9.0), (60.0, 1.0), (120.0, 9.0), (180.0, 1.0), (240.0, 9.0), (300.0, 5.0)],
        ));
        assert_eq!(third.excursions, 9);
        let kept = third.last.map(|e| e.map(|e| (e.side, e.start_s)));
        let base = 2340.0 + 180.0;
        let want = [(Side::Cold, 60.0), (Side::Warm, 120.0), (Side::Cold, 180.0), (Side::Warm, 240.0)];
        assert_eq!(kept, want.map(|(side, t)| Some((side, base + t))));
    }

    #[test]
    fn recorder_stores_hourly_at_resets_and_at_every_alarm() {
        let mut carried = HistoryRecord::EMPTY;
        carried.note_alarm(AlarmKind::Heat10h);
        carried.recorded_s = 86_400;
        let mut rec = Recorder::new(carried, 360);
        let boot = rec.note_reset(ResetCause::BrownOut);
        assert_eq!(boot.resets_by(ResetCause::BrownOut), 1);
        assert_eq!(boot.alarms_of(AlarmKind::Heat10h), 1);
        // 359 samples at 5 °C: nothing to store; the 360th stores.
        for i in 0..359 {
            assert!(!rec.push(i * 10_000, 5.0).save_due, "sample {i}");
        }
        let due = rec.push(3_590_000, 5.0);
        assert!(due.save_due, "hourly store");
        let hourly = rec.history();
        assert_eq!(rec.due_save(&due), Some(Save::History(hourly)));
        assert_eq!(hourly.recorded_s, 86_400 + 3590);
        // Freezing: the freeze_60min alarm stores at once, counted once; the excursion is on
        // the record's clock.
        let mut stored_alarm = None;
        for i in 0..=360 {
            let out = rec.push(3_600_000 + i * 10_000, -1.0);
            if out.raised.iter().flatten().any(|a| a.kind == AlarmKind::Freeze60min) {
                assert!(out.save_due, "an alarm is stored at once");
                stored_alarm = Some(rec.history());
                assert_eq!(rec.due_save(&out), Some(Save::AlarmHistory(rec.history())));
                assert_eq!(i, 360, "triggers exactly 60 min after the run began");
            } else {
                let want = out.save_due.then(|| Save::History(rec.history()));
                assert_eq!(rec.due_save(&out), want, "sample {i}");
            }
        }
        let h = stored_alarm.expect("the alarm triggered");
        assert_eq!(h.alarms_of(AlarmKind::Freeze60min), 1);
        assert_eq!(h.alarms_of(AlarmKind::Heat10h), 1);
        assert_eq!(h.resets_by(ResetCause::BrownOut), 1);
        assert_eq!(h.last[3].map(|e| (e.side, e.start_s)), Some((Side::Cold, 86_400.0 + 3600.0)));
        assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
        assert_eq!(rec.history().alarms_of(AlarmKind::Freeze60min), 1);
    }

    /// A controller whose mode and trusted model the test sets.
    struct Scripted {
        mode: Option<AdaptiveMode>,
        trusted: Option<Model>,
    }

    impl Controller for Scripted {
        fn update(&mut self, _: &crate::control::ControlInput) -> Result<f32, crate::control::ControlError> {
            Ok(0.0)
        }
        fn track(&mut self, _: &crate::control::ControlInput, _: f32) {}
        fn name(&self) -> &'static str {
            "scripted"
        }
        fn status(&self) -> Option<crate::control::ControllerStatus> {
            self.mode.map(|mode| crate::control::ControllerStatus {
                mode,
                theta: [0.0; 6],
                trace_p: 0.0,
                prediction_error: 0.0,
                reset_c: 0.0,
            })
        }
        fn trusted_model(&self) -> Option<Model> {
            self.trusted
        }
    }

    #[test]
    fn the_model_is_stored_after_every_n_trusted_samples_only() {
        let mut cadence = ModelCadence::new(12);
        let mut c = Scripted { mode: Some(AdaptiveMode::Adaptive), trusted: Some(START_MODEL_HTER2) };
        let want = ModelRecord::from_model(&START_MODEL_HTER2);
        // The boot's first store after a quarter of the interval: the third trusted sample.
        assert_eq!([cadence.push(c.mode, &c), cadence.push(c.mode, &c)], [None, None]);
        // Frozen and fallback samples do not count: the third trusted sample stores.
        for mode in [Some(AdaptiveMode::Frozen), Some(AdaptiveMode::Fallback), None] {
            c.mode = mode;
            assert_eq!(cadence.push(c.mode, &c), None, "{mode:?}");
        }
        c.mode = Some(AdaptiveMode::Adaptive);
        assert_eq!(cadence.push(c.mode, &c), want);
        // Then every 12 trusted samples.
        let twelve = |cadence: &mut ModelCadence, c: &Scripted| -> Vec<Option<ModelRecord>> {
            (0..12).map(|_| cadence.push(c.mode, c)).collect()
        };
        let only_the_last = |v: &[Option<ModelRecord>]| v[..11].iter().all(Option::is_none) && v[11] == want;
        assert!(only_the_last(&twelve(&mut cadence, &c)));
        // A model without a record (A not second order) is skipped, and the count restarts.
        c.trusted = Some(Model::new(&[-0.9], &[-0.5], &[], 3).unwrap());
        assert!(twelve(&mut cadence, &c).iter().all(Option::is_none));
        c.trusted = Some(START_MODEL_HTER2);
        assert!(only_the_last(&twelve(&mut cadence, &c)));
        // A new boot stores its first after a quarter again; at least one sample between stores.
        let mut boot = ModelCadence::new(12);
        assert_eq!([boot.push(c.mode, &c), boot.push(c.mode, &c), boot.push(c.mode, &c)], [None, None, want]);
        assert_eq!(ModelCadence::new(0).push(c.mode, &c), want);
    }

    #[test]
    fn board_faults_round_trip_and_v2_records_migrate() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        let _ = rec.note_reset(ResetCause::Watchdog);
        let _ = rec.note_board_fault(&StopInfo::new(StopKind::HardFault, 0x0800_1234, 0x2001_8000, 0x0000_8200));
        let _ = rec.note_board_fault(&StopInfo::new(StopKind::Panic, 0, 0, 417));
        let h = rec.note_flash_page_lost();
        assert_eq!(h.stops_of(StopKind::HardFault), 1);
        assert_eq!(h.stops_of(StopKind::Panic), 1);
        assert_eq!(h.stops_of(StopKind::Nmi), 0);
        assert_eq!(h.flash_pages_lost, 1);
        assert_eq!(h.last_stop, Some(LastStop { kind: StopKind::Panic, pc: 0, addr: 0, detail: 417 }));
        let bytes = h.encode();
        assert_eq!(bytes.len(), HistoryRecord::LEN);
        assert_eq!(&bytes[..2], &[b'H', 6]);
        assert_eq!(HistoryRecord::decode(&bytes), Ok(h));

        // A v2 record: the v3 bytes before the board-fault fields, version 2, its own CRC.
        let mut carried = HistoryRecord { excursions: 3, recorded_s: 7200, ..HistoryRecord::EMPTY };
        carried.note_alarm(AlarmKind::Heat10h);
        carried.note_reset(ResetCause::BrownOut);
        carried.note_stop(&StopInfo::new(StopKind::Nmi, 1, 2, 3));
        let current = carried.encode();
        let v2: [u8; HistoryRecord::LEN_V2] = older_history(&current, 2);
        let migrated = HistoryRecord::decode(&v2).expect("v2 is read");
        assert_eq!(migrated, HistoryRecord { stops: [0; 5], last_stop: None, ..carried });
        // A v2 version byte on a current-length record, and a v3 byte on a v2-length one, are not.
        let mut b = current;
        b[1] = 2;
        assert_eq!(HistoryRecord::decode(&b), Err(DecodeError::Crc));
        let mut b = v2;
        b[1] = 3;
        assert_eq!(HistoryRecord::decode(&b), Err(DecodeError::Length));

        // An unknown stop kind code, re-framed with a valid CRC.
        let mut b = h.encode();
        // The stop's kind: before the last stop's three words, the carried byte and the runs.
        b[HistoryRecord::LEN_V4 - 4 - 14] = 9;
        reframe(&mut b);
        assert_eq!(HistoryRecord::decode(&b), Err(DecodeError::OutOfRange));
    }

    /// The indicator's latch is stored with the history (v4) and every change of it is handed
    /// over at once, a set one past the write gate's hold-off; a v3 record reads as nothing
    /// unacknowledged.
    #[test]
    fn the_indicators_latch_is_stored_and_v3_records_migrate() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        let _ = rec.note_reset(ResetCause::BrownOut);
        let mut quiet = rec.push(0, 4.0);
        rec.note_carried(&mut quiet, false, SensorOffset::NONE, false);
        assert_eq!(rec.due_save(&quiet), None);
        let mut set = rec.push(10_000, 4.0);
        rec.note_carried(&mut set, true, SensorOffset::NONE, false);
        let h = rec.history();
        assert!(h.unacknowledged());
        assert_eq!(rec.due_save(&set), Some(Save::AlarmHistory(h)));
        let mut again = rec.push(20_000, 4.0);
        rec.note_carried(&mut again, true, SensorOffset::NONE, false);
        assert_eq!(rec.due_save(&again), None, "stored once");
        assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
        let mut cleared = rec.push(30_000, 4.0);
        rec.note_carried(&mut cleared, false, SensorOffset::NONE, false);
        assert_eq!(rec.due_save(&cleared), Some(Save::History(rec.history())));
        assert!(!rec.history().unacknowledged());
        // Carried into the next boot's record.
        let mut next = Recorder::new(h, 360);
        assert!(next.note_reset(ResetCause::BrownOut).unacknowledged());

        // A v3 record: the v4 bytes before the latch, version 3, its own CRC.
        let v3: [u8; HistoryRecord::LEN_V3] = older_history(&h.encode(), 3);
        assert_eq!(HistoryRecord::decode(&v3), Ok(h.with_carried(false, false)));
    }

    /// The sensor offset the step subtracts is stored with the history in the carried byte's
    /// bits 1–7 (bit 0 the latch), each change at once; a v4 record written before the offset
    /// was kept (its byte 0 or 1) reads as no offset.
    #[test]
    fn the_sensor_offset_is_stored_with_the_history() {
        // Steps of 0.03 °C, to the nearest, within 0 … 3.81 °C; negative and NaN are none.
        for (c, steps) in [(0.0, 0), (0.014, 0), (0.016, 1), (1.5, 50), (3.0, 100), (3.81, 127)] {
            assert_eq!(SensorOffset::from_c(c), SensorOffset(steps), "{c} °C");
        }
        for c in [-1.0, f32::NAN] {
            assert_eq!(SensorOffset::from_c(c), SensorOffset::NONE, "{c} °C");
        }
        assert_eq!(SensorOffset::from_c(50.0).c(), SensorOffset::MAX_C);
        assert!((SensorOffset::from_c(1.5).c() - 1.5).abs() < 1e-6);

        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        let mut quiet = rec.push(0, 4.0);
        rec.note_carried(&mut quiet, false, SensorOffset::NONE, false);
        assert_eq!(rec.due_save(&quiet), None);
        // A new offset is stored at once, past the hold-off, with the latch as it stands.
        let offset = SensorOffset::from_c(1.47);
        let mut found = rec.push(10_000, 4.0);
        rec.note_carried(&mut found, false, offset, false);
        let h = rec.history();
        assert_eq!((h.sensor_offset, h.unacknowledged()), (offset, false));
        assert_eq!(rec.due_save(&found), Some(Save::AlarmHistory(h)));
        let mut same = rec.push(20_000, 4.0);
        rec.note_carried(&mut same, false, offset, false);
        assert_eq!(rec.due_save(&same), None, "stored once");
        // Offset and latch side by side in one byte, both read back.
        for latched in [false, true] {
            let both = HistoryRecord { sensor_offset: SensorOffset::from_c(3.81), ..h.with_carried(latched, false) };
            assert_eq!(HistoryRecord::decode(&both.encode()), Ok(both));
        }
        // An offset that goes is stored at once too (a recalibration can lower it).
        let mut gone = rec.push(30_000, 4.0);
        rec.note_carried(&mut gone, false, SensorOffset::NONE, false);
        assert!(matches!(rec.due_save(&gone), Some(Save::AlarmHistory(_))));
        // Carried into the next boot's record.
        let mut next = Recorder::new(h, 360);
        assert_eq!(next.note_reset(ResetCause::BrownOut).sensor_offset, offset);

        // The v4 bytes before the offset was kept: 0 or 1, the latch alone.
        let n = HistoryRecord::LEN_V4 - 4;
        for (byte, latched) in [(0u8, false), (1, true)] {
            let mut current = h.encode();
            current[n - 1] = byte;
            let b: [u8; HistoryRecord::LEN_V4] = older_history(&current, 4);
            let old = HistoryRecord { sensor_offset: SensorOffset::NONE, ..h.with_carried(latched, false) };
            assert_eq!(HistoryRecord::decode(&b), Ok(old));
        }
    }

    /// A [`Runs`] entry as its documented layout reads: (ms toward the duration, raised), `None`
    /// for no run.
    fn run_read(r: u32) -> Option<(u32, bool)> {
        (r != 0).then(|| ((r & 0x7FFF_FFFF) - 1, r >> 31 == 1))
    }

    /// The alarms' runs under way are stored with the history (v5) and the next boot's monitor
    /// continues them; a run the stored history has under way that ends makes the history due;
    /// a v4 record reads as no run.
    #[test]
    fn the_alarm_runs_are_stored_and_continued_and_v4_records_migrate() {
        // 5 h above 8 °C, a sample a minute.
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 60);
        for k in 0..=300 {
            rec.push(k * 60_000, 9.0);
        }
        let h = rec.history();
        assert_eq!(run_read(h.runs[0]), Some((5 * 3_600_000, false)), "heat_10h");
        assert_eq!(h.runs[1..3], [0, 0], "freeze_60min and ship_45c_1h");
        // ship_30c_10h: never above 30 °C, no sum.
        assert_eq!(run_read(h.runs[3]), None);
        assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
        // The next boot's run goes on: heat_10h 5 h later, not 10 h, and its alarm carries the
        // 5 h before the boot.
        let mut next = Recorder::new(h, 60);
        assert_eq!(next.history().runs, h.runs, "handed on before the first sample");
        let raised_at = (0..=400u64).find_map(|k| next.push(k * 60_000, 9.0).raised[0].map(|a| (k, a)));
        let (k, alarm) = raised_at.expect("heat_10h raised");
        assert_eq!((k, alarm.start_ms, alarm.carried_s), (300, 0, 5 * 3600));
        assert_eq!(run_read(next.history().runs[0]), Some((10 * 3_600_000, true)));
        // Raised, it is not raised again after another restart; a first sample in range ends it.
        let fired = next.history();
        let mut again = Recorder::new(fired, 60);
        assert!((0..100).all(|k| again.push(k * 60_000, 9.0).raised[0].is_none()));
        let mut cooled = Recorder::new(fired, 60);
        cooled.push(0, 5.0);
        assert_eq!(cooled.history().runs[0], 0);
        // The cumulative kind's sum goes on: 6 h above 30 °C, a restart, 4 h more raise it.
        let mut hot = Recorder::new(HistoryRecord::EMPTY, 60);
        for k in 0..=360 {
            hot.push(k * 60_000, 31.0);
        }
        let mut hot_next = Recorder::new(hot.history(), 60);
        let raised = (0..=300u64).find(|k| hot_next.push(k * 60_000, 31.0).raised[3].is_some());
        assert_eq!(raised, Some(240), "6 h carried, 4 h more");
        // A stored run that ends makes the history due at once, behind the hold-off, and once.
        let mut ends = Recorder::new(h, 3600);
        assert!(!ends.push(0, 9.0).save_due);
        let r = ends.push(60_000, 5.0);
        assert!(r.save_due && !r.urgent);
        assert!(matches!(ends.due_save(&r), Some(Save::History(s)) if s.runs[0] == 0));
        assert!(!ends.push(120_000, 5.0).save_due, "once");
        // A run the stored history does not have (a flicker above 8 °C between two stores) ends
        // without a store.
        for (k, c) in [(3, 9.0), (4, 5.0), (5, 9.0), (6, 5.0)] {
            assert!(!ends.push(k * 60_000, c).save_due, "minute {k}");
        }
        // v4: no run, and no excursion known to be under way (the faults byte came with v6).
        assert!(h.open_excursion().is_some());
        let v4: [u8; HistoryRecord::LEN_V4] = older_history(&h.encode(), 4);
        let v4_read = HistoryRecord { runs: [0; 4], flags: h.flags & !EXCURSION_OPEN, ..h };
        assert_eq!(HistoryRecord::decode(&v4), Ok(v4_read));
        assert_eq!(v4_read.open_excursion(), None);
    }

    /// Boots cut at random through excursions, each history stored as the firmware stores it
    /// (at the boot, then when [`Recorder::push`] says so, through [`Recorder::due_save`]), the
    /// samples after a boot's last store lost with the cut. The record's excursions must be
    /// those of the readings that reached it read as one series, as `hter monitor` reads a log
    /// across restarts: a run of readings on one side of 2…8 °C is one excursion whatever the
    /// restarts and sensor faults inside it. The reference counts runs in the readings and
    /// times them on the record's clock (each boot's reading j at the record's time when the
    /// boot began plus 10 s for each reading before it). Before, every restart inside an
    /// excursion counted another one.
    fn excursions_across_restarts(seed: u64, jitter: bool) -> Result<(), std::string::String> {
        let mut x = seed | 1;
        let mut next = move |n: u64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x % n
        };
        // (side, start_s, end_s, extreme_c) of the reference's runs.
        let mut runs: std::vec::Vec<(Side, f32, f32, f32)> = std::vec::Vec::new();
        let mut open = false;
        let mut stored = HistoryRecord::EMPTY;
        let mut level = 0u64;
        // Every record stored must read back whole: the next boot would otherwise start from an
        // empty history.
        let check = |h: &HistoryRecord| {
            if HistoryRecord::decode(&h.encode()) != Ok(*h) {
                return Err(std::format!("a stored history does not read back: {h:?}"));
            }
            Ok(())
        };
        for _boot in 0..1 + next(8) {
            // With jitter, as on the board: the first sample some seconds after the reset, the
            // samples a few ms off the period, stores at any sample (also a boot's first, when
            // the latch flips), and the period of the stores random.
            let every = if jitter { [1, 6, 36, 360][next(4) as usize] } else { 36 };
            let t0 = if jitter { next(9_000) } else { 0 };
            let mut rec = Recorder::new(stored, every);
            stored = rec.note_reset(ResetCause::BrownOut);
            check(&stored)?;
            let base = stored.recorded_s as f32;
            // This boot's reference runs, kept only up to the boot's last store.
            let (mut boot_runs, mut boot_open, mut readings) = (runs.clone(), open, 0u32);
            for j in 0..1 + next(60) {
                if next(10) == 0 {
                    level = next(3);
                }
                let c = match (next(12), level) {
                    (0, _) => f32::NAN,
                    (_, 0) => 4.0 + next(30) as f32 * 0.1,
                    (_, 1) => 8.5 + next(40) as f32 * 0.1,
                    _ => 1.9 - next(40) as f32 * 0.1,
                };
                let t_ms = if jitter { t0 + j * 10_000 + next(40) } else { j * 10_000 };
                let mut r = rec.push(t_ms, c);
                if jitter && next(4) == 0 {
                    rec.note_carried(&mut r, next(2) == 0, SensorOffset::NONE, false);
                }
                if !c.is_nan() {
                    let t = base + 10.0 * readings as f32;
                    readings += 1;
                    let side = if c > 8.0 {
                        Some(Side::Warm)
                    } else if c < 2.0 {
                        Some(Side::Cold)
                    } else {
                        None
                    };
                    match (side, boot_runs.last_mut()) {
                        (Some(s), Some(last)) if boot_open && last.0 == s => {
                            last.2 = t;
                            last.3 = if s == Side::Warm { last.3.max(c) } else { last.3.min(c) };
                        }
                        (Some(s), _) => boot_runs.push((s, t, t, c)),
                        (None, _) => {}
                    }
                    boot_open = side.is_some();
                }
                if let Some(Save::History(h) | Save::AlarmHistory(h)) = rec.due_save(&r) {
                    check(&h)?;
                    stored = h;
                    (runs, open) = (boot_runs.clone(), boot_open);
                }
            }
        }
        // With jitter the times are the board's (its clock from the reset, the record's whole
        // seconds from the first sample), not the reference's: compared without them.
        let times = |e: &(Side, f32, f32, f32)| if jitter { (e.0, 0.0, 0.0, e.3) } else { *e };
        let newest: std::vec::Vec<_> = runs.iter().rev().take(HISTORY_EXCURSIONS).rev().map(times).collect();
        let kept: std::vec::Vec<_> =
            stored.last.iter().flatten().map(|e| times(&(e.side, e.start_s, e.end_s, e.extreme_c))).collect();
        if stored.excursions as usize != runs.len() || kept != newest {
            return Err(std::format!(
                "{} excursions {kept:?}, the readings' {} {newest:?}",
                stored.excursions,
                runs.len()
            ));
        }
        if stored.open_excursion().map(|e| e.side) != open.then(|| newest.last().map(|e| e.0)).flatten() {
            return Err(std::format!("open {:?}, the readings' {open}", stored.open_excursion()));
        }
        check(&stored)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 2_000, ..Default::default() })]
        #[test]
        fn an_excursion_across_restarts_is_one_excursion(seed in proptest::prelude::any::<u64>()) {
            proptest::prop_assert_eq!(excursions_across_restarts(seed, false), Ok(()));
        }

        /// The same on the board's clock: found in review, a first reading before the time the
        /// stored excursion had reached on that clock gave an end before the start.
        #[test]
        fn an_excursion_across_restarts_on_the_boards_clock(seed in proptest::prelude::any::<u64>()) {
            proptest::prop_assert_eq!(excursions_across_restarts(seed, true), Ok(()));
        }
    }

    /// The review's case on the board's clock: the first sample 0.7 s after the reset, an
    /// excursion from 10.703 s with the record at 10 whole seconds, a watchdog restart whose
    /// first reading, at 0.7 s and on the same side, sets the latch and stores the history at
    /// once. It stored an excursion from 10.703 s to 10.7 s, which the next boot rejected with
    /// the whole history.
    #[test]
    fn a_first_reading_early_on_the_boards_clock_keeps_the_excursion_in_order() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        let _ = rec.note_reset(ResetCause::BrownOut);
        rec.push(700, 5.0);
        rec.push(10_703, 9.0);
        let stored = rec.history();
        assert_eq!((stored.recorded_s, stored.open_excursion().map(|e| e.start_s)), (10, Some(10.703)));
        let mut next = Recorder::new(stored, 360);
        let _ = next.note_reset(ResetCause::Watchdog);
        let mut r = next.push(700, 9.5);
        next.note_carried(&mut r, true, SensorOffset::NONE, false);
        let Some(Save::AlarmHistory(h)) = next.due_save(&r) else { panic!("the latch stores at once") };
        let e = h.last[3].expect("the excursion");
        assert!(e.start_s <= e.end_s, "{e:?}");
        assert_eq!((h.excursions, e.extreme_c), (1, 9.5));
        assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
    }

    /// A boot that continues the stored excursion and then has twenty more, more than its
    /// monitor's log keeps: the record counts them all once, and keeps the four newest in
    /// order (the continued one long gone from the log).
    #[test]
    fn a_continued_excursion_then_more_than_the_log_keeps() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        rec.push(0, 5.0);
        rec.push(10_000, 9.0);
        let stored = rec.history();
        let mut next = Recorder::new(stored, 360);
        next.push(0, 9.5);
        let mut t = 10_000;
        for k in 0..20 {
            next.push(t, 5.0);
            next.push(t + 10_000, if k % 2 == 0 { 1.0 } else { 9.0 });
            t += 20_000;
        }
        let h = next.history();
        assert_eq!(h.excursions, 21);
        let sides: std::vec::Vec<_> = h.last.iter().map(|e| e.map(|e| e.side)).collect();
        assert_eq!(sides, [Some(Side::Cold), Some(Side::Warm), Some(Side::Cold), Some(Side::Warm)]);
        let starts: std::vec::Vec<_> = h.last.iter().flatten().map(|e| e.start_s).collect();
        assert!(starts.windows(2).all(|w| w[0] < w[1]), "{starts:?}");
        assert_eq!(HistoryRecord::decode(&h.encode()), Ok(h));
    }

    /// The history is due six times as often while the load is outside 2…8 °C (a supply that
    /// drops more often than the periodic store would lose the excursion otherwise).
    #[test]
    fn an_excursion_stores_the_history_six_times_as_often() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 60);
        let mut k = 0;
        let mut hour = |rec: &mut Recorder, c: f32| {
            let due = (k..k + 60).filter(|i| rec.push(i * 60_000, c).save_due).count();
            k += 60;
            due
        };
        assert_eq!(hour(&mut rec, 5.0), 1, "in range: hourly");
        // 1 °C: below 2 °C, no alarm's run (freeze_60min is at −0.5 °C).
        assert_eq!(hour(&mut rec, 1.0), 6, "cold: every 10 minutes");
        assert_eq!(hour(&mut rec, 5.0), 1, "in range again");
    }

    /// The SSR's short is stored at once and once; a v5 record (before it was kept) decodes with
    /// no short; the bit reads back.
    #[test]
    fn a_shorted_ssr_is_stored_with_the_history_at_once() {
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        let _ = rec.note_reset(ResetCause::BrownOut);
        let mut quiet = rec.push(0, 4.0);
        rec.note_carried(&mut quiet, true, SensorOffset::NONE, false);
        let _ = rec.due_save(&quiet);
        let mut found = rec.push(10_000, 4.0);
        rec.note_carried(&mut found, true, SensorOffset::NONE, true);
        let h = rec.history();
        assert!(h.ssr_shorted());
        assert_eq!(rec.due_save(&found), Some(Save::AlarmHistory(h)), "at once, the latch already set");
        let mut again = rec.push(20_000, 4.0);
        rec.note_carried(&mut again, true, SensorOffset::NONE, true);
        assert_eq!(rec.due_save(&again), None, "stored once");
        let bytes = h.encode();
        assert_eq!(HistoryRecord::decode(&bytes), Ok(h));
        // The faults byte is the last before the CRC, bit 0.
        assert_eq!(bytes[HistoryRecord::LEN - 5], 1);
        let v5: [u8; HistoryRecord::LEN_V5] = older_history(&bytes, 5);
        assert_eq!(HistoryRecord::decode(&v5), Ok(h.with_carried(true, false)));
        // Every boot keeps it, whatever its reset (a pin reset is also an NRST glitch); a
        // service reset clears it and nothing else; the next one, with no short left, the sensor
        // offset (a damaged lead's offset outlives the SSR's replacement).
        let stall = StopInfo::new(StopKind::ControlStall, 0, 0, 12_000);
        let offset = SensorOffset::from_c(1.5);
        let h = h.with_sensor_offset(offset);
        for (reset, stop) in [
            (ResetCause::BrownOut, None),
            (ResetCause::Watchdog, None),
            (ResetCause::Other, Some(stall)),
            (ResetCause::Other, None),
        ] {
            let mut next = Recorder::new(h, 360);
            let booted =
                next.note_boot(reset, &crate::failsafe::Stops { earlier: None, latest: stop, fresh: stop.is_some() });
            assert!(booted.ssr_shorted(), "{reset:?} {stop:?}");
            assert_eq!(booted.sensor_offset, offset, "{reset:?} {stop:?}");
            let serviced = next.note_service();
            assert!(!serviced.ssr_shorted() && serviced.sensor_offset == offset);
            assert!(serviced.unacknowledged(), "the latch is the button's, not the service reset's");
            assert_eq!(serviced.with_carried(true, true), booted);
            let again = next.note_service();
            assert_eq!(again, serviced.with_sensor_offset(SensorOffset::NONE));
        }
    }

    /// The records a boot refused ride in the faults byte's bits 2–6, through every store of the
    /// boot (the latch, the short and the sensor offset changing around them) and a service
    /// reset; a v6 record written before them reads none, and a v5 one too.
    #[test]
    fn the_refused_records_are_stored_with_the_history() {
        let both = Record::Calibration.bit() | Record::Cabinet.bit();
        let mut rec = Recorder::new(HistoryRecord::EMPTY, 360);
        rec.note_refused(both);
        let h = rec.note_boot(ResetCause::BrownOut, &crate::failsafe::Stops::default());
        assert_eq!(h.refused(), both);
        assert!(h.unacknowledged(), "a refusal not stored before latches");
        let bytes = h.encode();
        assert_eq!(bytes[HistoryRecord::LEN - 5], both << 2, "bits 2–6 of the faults byte");
        assert_eq!(HistoryRecord::decode(&bytes), Ok(h));
        let mut before = bytes;
        before[HistoryRecord::LEN - 5] = 0;
        crate::persist::tests::reframe(&mut before);
        assert_eq!(HistoryRecord::decode(&before).map(|h| h.refused()), Ok(0), "a v6 record from before");
        let v5: [u8; HistoryRecord::LEN_V5] = older_history(&bytes, 5);
        assert_eq!(HistoryRecord::decode(&v5).map(|h| h.refused()), Ok(0));
        // Kept through the latch, the short and the offset as they change, and a service reset.
        let mut out = rec.push(0, 4.0);
        rec.note_carried(&mut out, false, SensorOffset::from_c(0.3), true);
        let mut out = rec.push(10_000, 4.0);
        rec.note_carried(&mut out, true, SensorOffset::NONE, true);
        assert_eq!(rec.history().refused(), both);
        assert_eq!(rec.note_service().refused(), both);
        assert_eq!(rec.history().with_carried(false, false).refused(), both);
        // The same refusals again: no latch; one fewer: none either, and it is forgotten.
        for refused in [both, Record::Calibration.bit()] {
            let mut next = Recorder::new(h.with_carried(false, false), 360);
            next.note_refused(refused);
            let again = next.history();
            assert_eq!((again.refused(), again.unacknowledged()), (refused, false));
        }
        let mut next = Recorder::new(h.with_carried(false, false), 360);
        next.note_refused(both | Record::Model.bit());
        assert!(next.history().unacknowledged(), "one more is new");
    }

    #[test]
    fn history_checks() {
        let mut rec = HistoryRecord { min_c: Some(9.0), max_c: Some(3.0), ..HistoryRecord::EMPTY };
        assert_eq!(HistoryRecord::decode(&rec.encode()), Err(DecodeError::OutOfRange));
        rec = HistoryRecord { min_c: Some(-80.0), ..HistoryRecord::EMPTY };
        assert_eq!(HistoryRecord::decode(&rec.encode()), Err(DecodeError::OutOfRange));
        rec = HistoryRecord::EMPTY;
        rec.last[0] = Some(Excursion { side: Side::Warm, start_s: 10.0, end_s: 5.0, extreme_c: 9.0 });
        assert_eq!(HistoryRecord::decode(&rec.encode()), Err(DecodeError::OutOfRange));
        rec.last[0] = Some(Excursion { side: Side::Warm, start_s: 10.0, end_s: 50.0, extreme_c: f32::NAN });
        assert_eq!(HistoryRecord::decode(&rec.encode()), Err(DecodeError::NonFinite));
        // An unknown side byte, re-framed with a valid CRC.
        let mut b = HistoryRecord::EMPTY.encode();
        b[2 + 14 + 8 + 16] = 3;
        reframe(&mut b);
        assert_eq!(HistoryRecord::decode(&b), Err(DecodeError::OutOfRange));
    }
}
