//! The records of [`crate::persist`] in NOR flash, through `sequential-storage`'s map (one key
//! per record kind; a store appends, the newest item of a key wins, full pages are erased in
//! turn, so wear spreads over the region). Generic over
//! `embedded_storage_async::nor_flash::NorFlash`: the firmware passes the STM32's flash, the host
//! tests a mock that loses power mid-write, and both run this code.
//!
//! Loading never fails: a record that is missing, torn, corrupt or implausible yields the
//! default and a [`LoadStatus`] saying which, for the firmware to log.
//!
//! # Torn words and ECC
//!
//! The STM32L4 programs flash by 64-bit double word with 8 ECC bits; a power cut inside a
//! double-word program, or inside a page erase, can leave words whose data and ECC disagree in
//! two or more bits. Reading one sets ECCD and raises an NMI; the firmware's NMI handler notes
//! the address and returns, and [`EccFlash`] turns the note ([`EccErrors`]) into a read error.
//! `sequential-storage` propagates a read error as `Error::Storage` without repairing anything
//! (its own repair runs only on `Error::Corrupted`), so every load and store would fail for
//! good. The [`Store`] therefore repairs the flash at the reported address and retries, at most
//! [`MAX_REPAIRS`] times per operation:
//!
//! - one torn word in a page whose start marker reads: a cut double-word program (a power cut
//!   stops the flash, so one program leaves one torn word, at the end of what was written). The
//!   word is programmed to all zeros, which the L4 allows over a programmed word (RM0351
//!   §3.3.7: programming a non-erased double word is refused "except if the data to write is
//!   full zero") and whose ECC is all zeros, so it reads again. To the storage layer a zeroed
//!   word is a marker (the page markers are zero words, so a torn marker reads as completed), an
//!   item header whose length CRC fails (skipped word by word), or item data whose CRC fails
//!   (the item is skipped): it loses the record being written, which was never complete, and
//!   nothing else. Erasing that page instead would lose the newest complete record of every
//!   other kind written to it (the page being written holds them, and after a page turn it holds
//!   the only copy of the records moved out of the page erased next).
//! - a torn start marker, or more than one torn word: a cut page erase (it touches every
//!   programmed word of the page at once) or a cut start-marker program (written only on an
//!   erased page). The storage layer erases a page only after moving its live items elsewhere
//!   (or to retry an erase), and a page being opened held nothing, so the page is erased again:
//!   nothing that was still needed is lost.
//!
//! Each repair is counted ([`Store::repairs`]) for the boot to report and the cold-chain history
//! to keep.

use core::ops::Range;

use embedded_storage_async::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};
use sequential_storage::queue::{QueueConfig, QueueStorage};

use super::log::{LogEntry, ENTRY_LEN};
use super::{CalibrationRecord, DecodeError, HistoryRecord, ModelRecord, SettingsRecord};
use crate::calib::TwoPoint;
use crate::control::adaptive::AdaptiveConfig;

/// Map keys, one per record kind ([`crate::persist::Record`]'s discriminants). Never reuse a key
/// for a different layout: bump the record's version instead.
pub mod key {
    use crate::persist::Record;
    /// [`super::ModelRecord`].
    pub const MODEL: u8 = Record::Model as u8;
    /// [`super::CalibrationRecord`].
    pub const CALIBRATION: u8 = Record::Calibration as u8;
    /// [`super::HistoryRecord`].
    pub const HISTORY: u8 = Record::History as u8;
    /// [`super::SettingsRecord`].
    pub const SETTINGS: u8 = Record::Settings as u8;
    /// [`crate::persist::CabinetRecord`].
    pub const CABINET: u8 = Record::Cabinet as u8;
}

/// Repairs one load or store may make before it gives up with [`StoreError::Flash`]: one power
/// cut leaves at most one torn word or one torn page, and a boot repairs what it reads, so more
/// than a few in one operation means a flash that keeps failing, which must not stall the boot
/// (each repair costs at most one page scan and one page erase, ≈ 22 ms on the L4).
pub const MAX_REPAIRS: usize = 8;

/// Where a flash reports reads that failed their ECC check.
pub trait EccErrors {
    /// The flash offset (as the `NorFlash` addresses it) of a word whose read failed its ECC
    /// check since the last call, if any; clears it.
    fn take(&mut self) -> Option<u32>;
}

/// For a flash without ECC (or whose driver reports ECC errors itself): never reports one.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoEcc;

impl EccErrors for NoEcc {
    fn take(&mut self) -> Option<u32> {
        None
    }
}

/// An error of [`EccFlash`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EccFlashError<E> {
    /// The flash driver's own error (or power lost).
    Flash(E),
    /// A read covered a word that failed its ECC check, at this flash offset.
    Ecc {
        /// Offset of the word.
        offset: u32,
    },
}

impl<E: NorFlashError> NorFlashError for EccFlashError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            EccFlashError::Flash(e) => e.kind(),
            EccFlashError::Ecc { .. } => NorFlashErrorKind::Other,
        }
    }
}

/// A NOR flash whose reads fail when [`EccErrors`] reports an ECC error during them (on the L4
/// the read itself returns whatever the word holds).
pub struct EccFlash<F, E> {
    flash: F,
    ecc: E,
}

impl<F: NorFlash, E: EccErrors> EccFlash<F, E> {
    /// `flash` with its ECC reports from `ecc`. Any stale report is dropped.
    pub fn new(flash: F, mut ecc: E) -> Self {
        let _ = ecc.take();
        EccFlash { flash, ecc }
    }

    /// The flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    /// The flash underneath (a test's mock, to arm a power cut).
    pub fn inner_mut(&mut self) -> &mut F {
        &mut self.flash
    }
}

impl<F: NorFlash, E> ErrorType for EccFlash<F, E> {
    type Error = EccFlashError<F::Error>;
}

impl<F: NorFlash, E: EccErrors> ReadNorFlash for EccFlash<F, E> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let result = self.flash.read(offset, bytes).await;
        // The report wins over the driver's result: on the L4 the read "succeeds" with bad data.
        if let Some(offset) = self.ecc.take() {
            return Err(EccFlashError::Ecc { offset });
        }
        result.map_err(EccFlashError::Flash)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash, E: EccErrors> NorFlash for EccFlash<F, E> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.flash.erase(from, to).await.map_err(EccFlashError::Flash)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash.write(offset, bytes).await.map_err(EccFlashError::Flash)
    }
}

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash range is not page-aligned or spans fewer than two pages.
    Config,
    /// The flash driver reported an error (or power was lost), or ECC errors outlasted
    /// [`MAX_REPAIRS`] repairs.
    Flash,
    /// No space left even after erasing stale pages (cannot happen with three keys in ≥ 2 pages
    /// unless the region is far too small).
    Full,
    /// `sequential-storage` found corruption it could not repair; [`Store::erase_all`] recovers.
    Corrupted,
    /// Any other storage-layer error (buffer sizing, a bug in the layer).
    Other,
}

impl<E> From<sequential_storage::Error<E>> for StoreError {
    fn from(e: sequential_storage::Error<E>) -> Self {
        match e {
            sequential_storage::Error::Storage { .. } => StoreError::Flash,
            sequential_storage::Error::FullStorage => StoreError::Full,
            sequential_storage::Error::Corrupted { .. } => StoreError::Corrupted,
            _ => StoreError::Other,
        }
    }
}

/// The flash offset of the ECC error behind `e`, if that is what it is.
fn ecc_offset<E>(e: &sequential_storage::Error<EccFlashError<E>>) -> Option<u32> {
    match e {
        sequential_storage::Error::Storage { value: EccFlashError::Ecc { offset }, .. } => Some(*offset),
        _ => None,
    }
}

/// Where a loaded value came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadStatus {
    /// The stored record passed every check.
    Restored,
    /// Nothing stored under the key: defaults.
    Missing,
    /// A record was stored but rejected: defaults.
    Invalid(DecodeError),
    /// The flash could not be read: defaults.
    Flash(StoreError),
}

/// A loaded value and how it was obtained.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Loaded<T> {
    /// The restored value, or the default.
    pub value: T,
    /// Why it is what it is.
    pub status: LoadStatus,
}

/// ECC damage the [`Store`] repaired since it was opened.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Repairs {
    /// Torn words programmed to zero (each lost at most the record being written when the
    /// power went).
    pub words_cleared: u16,
    /// Torn pages erased again (each was being erased or opened: nothing still needed was in it).
    pub pages_erased: u16,
}

impl Repairs {
    /// Pages found damaged, either way.
    pub fn total(&self) -> u16 {
        self.words_cleared.saturating_add(self.pages_erased)
    }
}

/// Reads every word of the page at `start`: how many fail their ECC check, the first of
/// them, and whether the page's start marker is one.
/// A flash word the scratch buffer cannot hold is [`StoreError::Flash`].
async fn scan_page<F: NorFlash, E: EccErrors>(
    flash: &mut EccFlash<F, E>,
    start: u32,
) -> Result<(usize, Option<u32>, bool), StoreError> {
    let (page, word) = (F::ERASE_SIZE as u32, F::WRITE_SIZE);
    if word == 0 || word > MAX_WORD {
        return Err(StoreError::Flash);
    }
    let mut scratch = [0u8; MAX_WORD];
    let (mut torn, mut first_torn, mut marker_torn) = (0usize, None, false);
    for at in (start..start + page).step_by(word) {
        match flash.read(at, scratch.get_mut(..word).unwrap_or(&mut [])).await {
            Ok(()) => {}
            Err(EccFlashError::Ecc { .. }) => {
                torn += 1;
                first_torn = first_torn.or(Some(at));
                marker_torn |= at == start;
            }
            Err(EccFlashError::Flash(_)) => return Err(StoreError::Flash),
        }
    }
    Ok((torn, first_torn, marker_torn))
}

/// Repairs the page at `start` given its scan (see the module documentation for the choice
/// between clearing the word and erasing the page).
async fn repair_page<F: NorFlash, E: EccErrors>(
    flash: &mut EccFlash<F, E>,
    start: u32,
    scan: (usize, Option<u32>, bool),
    repairs: &mut Repairs,
) -> Result<(), StoreError> {
    let (page, word) = (F::ERASE_SIZE as u32, F::WRITE_SIZE);
    match scan {
        // Not torn (any more): nothing to repair, the retry reads it.
        (_, None, _) => return Ok(()),
        (1, Some(at), false) => {
            let zeros = [0u8; MAX_WORD];
            if flash.write(at, zeros.get(..word).unwrap_or(&[])).await.is_ok() {
                repairs.words_cleared = repairs.words_cleared.saturating_add(1);
                return Ok(());
            }
            // The flash refused the zeros: the page has to go.
        }
        _ => {}
    }
    flash.erase(start, start + page).await.map_err(|_| StoreError::Flash)?;
    repairs.pages_erased = repairs.pages_erased.saturating_add(1);
    Ok(())
}

/// Repairs the page of `range` holding the word at `offset` that failed its ECC check.
async fn repair<F: NorFlash, E: EccErrors>(
    flash: &mut EccFlash<F, E>,
    range: &Range<u32>,
    offset: u32,
    repairs: &mut Repairs,
) -> Result<(), StoreError> {
    let page = F::ERASE_SIZE as u32;
    if !range.contains(&offset) {
        return Err(StoreError::Flash);
    }
    let start = offset - (offset - range.start) % page;
    let scan = scan_page(flash, start).await?;
    repair_page(flash, start, scan, repairs).await
}

/// Scans every page of `range` and repairs the damaged ones.
async fn scrub<F: NorFlash, E: EccErrors>(
    flash: &mut EccFlash<F, E>,
    range: &Range<u32>,
    repairs: &mut Repairs,
) -> Result<(), StoreError> {
    let page = F::ERASE_SIZE as u32;
    for start in range.clone().step_by(F::ERASE_SIZE) {
        if start + page > range.end {
            break;
        }
        let scan = scan_page(flash, start).await?;
        repair_page(flash, start, scan, repairs).await?;
    }
    Ok(())
}

/// Largest word `sequential-storage` supports (its `MAX_WORD_SIZE`), bytes.
const MAX_WORD: usize = 32;

/// Working buffer: the largest item (1 key byte + [`HistoryRecord::LEN`]) rounded up to the
/// largest flash word `sequential-storage` supports; aligned for flash drivers that want it.
const BUF_LEN: usize = (1 + HistoryRecord::LEN).next_multiple_of(MAX_WORD);

#[repr(C, align(8))]
struct Buffer([u8; BUF_LEN]);

/// [`Store`]'s copy of the newest fetched record, word-aligned: after the storage layer's
/// state its bytes began three past a word, and [`Store::new`] zeroed them through the
/// unaligned `__aeabi_memclr` (−8 B of flash aligned).
#[repr(C, align(4))]
struct Fetched([u8; HistoryRecord::LEN]);

type Map<F, E> = MapStorage<u8, EccFlash<F, E>, Cache<Uncached, Uncached, Uncached, u8>>;

/// The persisted records over a flash region.
pub struct Store<F: NorFlash, E: EccErrors> {
    map: Map<F, E>,
    range: Range<u32>,
    buf: Buffer,
    /// The newest fetched record's bytes, copied out of `buf` so a retry can reuse `buf`.
    rec: Fetched,
    repairs: Repairs,
}

impl<F: NorFlash, E: EccErrors> Store<F, E> {
    /// A store over `range` (flash offsets, page-aligned, at least two pages) of `flash`, whose
    /// ECC errors `ecc` reports.
    pub fn new(flash: F, ecc: E, range: Range<u32>) -> Result<Self, StoreError> {
        let config = MapConfig::try_new(range.clone()).map_err(|_| StoreError::Config)?;
        Ok(Store {
            map: MapStorage::new(EccFlash::new(flash, ecc), config, Cache::new_uncached()),
            range,
            buf: Buffer([0; BUF_LEN]),
            rec: Fetched([0; HistoryRecord::LEN]),
            repairs: Repairs::default(),
        })
    }

    /// The flash back (e.g. to reopen it after a simulated reset).
    pub fn release(self) -> F {
        self.map.destroy().0.into_inner()
    }

    /// ECC damage repaired since the store was opened.
    pub fn repairs(&self) -> Repairs {
        self.repairs
    }

    /// The flash underneath (a test's mock, to arm a power cut).
    pub fn flash_mut(&mut self) -> &mut F {
        self.map.flash().inner_mut()
    }

    /// Erases the whole region.
    pub async fn erase_all(&mut self) -> Result<(), StoreError> {
        Ok(self.map.erase_all().await?)
    }

    /// Reads the whole region and repairs every page with a word failing its ECC check. The
    /// loads repair what they read, but a load stops at the page it needs (a page torn while
    /// being erased lies past the page being written, which is found first); the boot calls
    /// this before loading, so no damage waits for a later store (≈ 8 KiB read, well under a
    /// millisecond on the L4, plus a repair per damaged page).
    pub async fn scrub(&mut self) -> Result<(), StoreError> {
        scrub(self.map.flash(), &self.range, &mut self.repairs).await
    }

    async fn repair(&mut self, offset: u32) -> Result<(), StoreError> {
        repair(self.map.flash(), &self.range, offset, &mut self.repairs).await
    }

    /// Stores already encoded record bytes under `key` (one call site for every record kind
    /// keeps one copy of the storage layer's write path in the firmware's flash).
    pub async fn store(&mut self, key: u8, bytes: &[u8]) -> Result<(), StoreError> {
        let mut repairs_left = MAX_REPAIRS;
        loop {
            let err = match self.map.store_item(&mut self.buf.0, &key, &bytes).await {
                Ok(()) => return Ok(()),
                Err(e) => e,
            };
            match ecc_offset(&err) {
                Some(offset) if repairs_left > 0 => {
                    repairs_left -= 1;
                    self.repair(offset).await?;
                }
                _ => return Err(err.into()),
            }
        }
    }

    /// The bytes of the newest item under `key` (not generic: one copy of the storage layer's
    /// read path for every record kind).
    async fn fetch(&mut self, key: u8) -> Result<&[u8], LoadStatus> {
        let mut repairs_left = MAX_REPAIRS;
        let len = loop {
            let err = match self.map.fetch_item::<&[u8]>(&mut self.buf.0, &key).await {
                Ok(Some(bytes)) => match self.rec.0.get_mut(..bytes.len()) {
                    Some(dst) => {
                        dst.copy_from_slice(bytes);
                        break bytes.len();
                    }
                    None => return Err(LoadStatus::Invalid(DecodeError::Length)),
                },
                Ok(None) => return Err(LoadStatus::Missing),
                Err(e) => e,
            };
            match ecc_offset(&err) {
                Some(offset) if repairs_left > 0 => {
                    repairs_left -= 1;
                    self.repair(offset).await.map_err(LoadStatus::Flash)?;
                }
                _ => return Err(LoadStatus::Flash(err.into())),
            }
        };
        Ok(self.rec.0.get(..len).unwrap_or(&[]))
    }

    /// Fetches the newest item under `key` and decodes it.
    async fn load<T>(
        &mut self,
        key: u8,
        decode: impl FnOnce(&[u8]) -> Result<T, DecodeError>,
    ) -> Result<T, LoadStatus> {
        let bytes = self.fetch(key).await?;
        decode(bytes).map_err(LoadStatus::Invalid)
    }

    /// Stores the model record.
    pub async fn save_model(&mut self, rec: &ModelRecord) -> Result<(), StoreError> {
        self.store(key::MODEL, &rec.encode()).await
    }

    /// The stored model record as the self-tuner would take it, not yet checked for plausibility.
    pub async fn load_model_record(&mut self) -> Result<ModelRecord, LoadStatus> {
        model_from(self.fetch(key::MODEL).await)
    }

    /// `cfg` resumed from the stored model ([`AdaptiveConfig::resumed_from`]) if one is stored
    /// and plausible under `cfg`'s limits; otherwise `cfg` unchanged. `cfg` is borrowed: taken by
    /// value, it is moved into this future inside the caller's, a copy within one future that
    /// LLVM makes a `memmove` call, and one such call links `compiler_builtins`' 1.5 KB
    /// `memmove` into the firmware.
    pub async fn load_adaptive(&mut self, cfg: &AdaptiveConfig) -> Loaded<AdaptiveConfig> {
        adaptive_from(model_from(self.fetch(key::MODEL).await), cfg)
    }

    /// Stores the calibration.
    pub async fn save_calibration(&mut self, cal: TwoPoint) -> Result<(), StoreError> {
        self.store(key::CALIBRATION, &CalibrationRecord { cal }.encode()).await
    }

    /// The stored calibration, or [`TwoPoint::IDENTITY`].
    pub async fn load_calibration(&mut self) -> Loaded<TwoPoint> {
        calibration_from(self.fetch(key::CALIBRATION).await)
    }

    /// Stores the history.
    pub async fn save_history(&mut self, rec: &HistoryRecord) -> Result<(), StoreError> {
        self.store(key::HISTORY, &rec.encode()).await
    }

    /// The stored history, or [`HistoryRecord::EMPTY`].
    pub async fn load_history(&mut self) -> Loaded<HistoryRecord> {
        history_from(self.fetch(key::HISTORY).await)
    }

    /// Stores the cabinet model's record.
    #[cfg(feature = "holdover")]
    pub async fn save_cabinet(&mut self, rec: &super::CabinetRecord) -> Result<(), StoreError> {
        self.store(key::CABINET, &rec.encode()).await
    }

    /// The stored cabinet model, checked with `cfg`'s gain range as an upload is.
    #[cfg(feature = "holdover")]
    pub async fn load_cabinet(&mut self, cfg: &AdaptiveConfig) -> Result<crate::model::Model, LoadStatus> {
        self.load(key::CABINET, |b| super::CabinetRecord::decode(b, cfg)).await
    }

    /// Stores the settings.
    pub async fn save_settings(&mut self, rec: &SettingsRecord) -> Result<(), StoreError> {
        self.store(key::SETTINGS, &rec.encode()).await
    }

    /// The stored settings, if a valid record is stored.
    pub async fn load_settings(&mut self) -> Result<SettingsRecord, LoadStatus> {
        self.load(key::SETTINGS, SettingsRecord::decode).await
    }
}

/// The calibration from a fetch of its key, or [`TwoPoint::IDENTITY`] and why not.
fn calibration_from(fetched: Result<&[u8], LoadStatus>) -> Loaded<TwoPoint> {
    match fetched.and_then(|b| CalibrationRecord::decode(b).map_err(LoadStatus::Invalid)) {
        Ok(rec) => Loaded { value: rec.cal, status: LoadStatus::Restored },
        Err(status) => Loaded { value: TwoPoint::IDENTITY, status },
    }
}

/// The history from a fetch of its key, or [`HistoryRecord::EMPTY`] and why not.
fn history_from(fetched: Result<&[u8], LoadStatus>) -> Loaded<HistoryRecord> {
    match fetched.and_then(|b| HistoryRecord::decode(b).map_err(LoadStatus::Invalid)) {
        Ok(value) => Loaded { value, status: LoadStatus::Restored },
        Err(status) => Loaded { value: HistoryRecord::empty(), status },
    }
}

/// The model record from a fetch of its key, not yet checked for plausibility.
fn model_from(fetched: Result<&[u8], LoadStatus>) -> Result<ModelRecord, LoadStatus> {
    fetched.and_then(|b| ModelRecord::decode(b).map_err(LoadStatus::Invalid))
}

/// `cfg` resumed from the loaded model record if it is plausible under `cfg`'s limits
/// ([`Store::load_adaptive`]); otherwise `cfg` and why not. Out of line: inlined into the
/// restore, the configuration (≈ 100 bytes) went field by field through the caller's registers
/// and stack into its result (−240 B of the firmware's flash).
#[inline(never)]
fn adaptive_from(rec: Result<ModelRecord, LoadStatus>, cfg: &AdaptiveConfig) -> Loaded<AdaptiveConfig> {
    // `ModelRecord::restore`'s steps on the result itself: `cfg` copied into it once, then
    // resumed there; building `restore`'s value and moving it in cost 60 B more flash.
    let mut out = Loaded { value: *cfg, status: LoadStatus::Restored };
    match rec.and_then(|rec| rec.to_model(cfg).map_err(LoadStatus::Invalid)) {
        Ok(m) => out.value = out.value.resumed_from(m),
        Err(status) => out.status = status,
    }
    out
}

/// The cold-chain log ([`crate::persist::log`]) in its own flash region, as a
/// `sequential-storage` queue that overwrites its oldest entries when full: 16-byte entries,
/// 24 bytes each in flash with sequential-storage 8's 8-byte item header (a multiple of the L4's
/// 8-byte words already), so a 2 KiB page (less its two 8-byte state markers) holds 84 and 30
/// days of 5-minute intervals (8 640) fill 103 pages; the firmware gives it 248 (496 KiB),
/// ≈ 70 days of intervals, less the room its events take. The same ECC repair as [`Store`]'s.
pub struct LogStore<F: NorFlash, E: EccErrors> {
    queue: QueueStorage<EccFlash<F, E>, Cache<Uncached, Uncached, Uncached, ()>>,
    range: Range<u32>,
    buf: Buffer,
    repairs: Repairs,
}

impl<F: NorFlash, E: EccErrors> LogStore<F, E> {
    /// A log over `range` (flash offsets, page-aligned) of `flash`, whose ECC errors `ecc`
    /// reports.
    pub fn new(flash: F, ecc: E, range: Range<u32>) -> Result<Self, StoreError> {
        let config = QueueConfig::try_new(range.clone()).map_err(|_| StoreError::Config)?;
        Ok(LogStore {
            queue: QueueStorage::new(EccFlash::new(flash, ecc), config, Cache::new_uncached()),
            range,
            buf: Buffer([0; BUF_LEN]),
            repairs: Repairs::default(),
        })
    }

    /// The flash back.
    pub fn release(self) -> F {
        self.queue.destroy().0.into_inner()
    }

    /// The flash underneath (a test's mock).
    pub fn flash_mut(&mut self) -> &mut F {
        self.queue.flash().inner_mut()
    }

    /// ECC damage repaired since the log was opened.
    pub fn repairs(&self) -> Repairs {
        self.repairs
    }

    /// Scans the region and repairs damaged pages (the boot calls it before reading).
    pub async fn scrub(&mut self) -> Result<(), StoreError> {
        scrub(self.queue.flash(), &self.range, &mut self.repairs).await
    }

    /// Erases the whole log.
    pub async fn erase_all(&mut self) -> Result<(), StoreError> {
        Ok(self.queue.erase_all().await?)
    }

    /// Appends `entry`, overwriting the oldest entries when the region is full.
    pub async fn push(&mut self, entry: &LogEntry) -> Result<(), StoreError> {
        let bytes = entry.encode();
        let mut repairs_left = MAX_REPAIRS;
        loop {
            let err = match self.queue.push(&bytes, true).await {
                Ok(()) => return Ok(()),
                Err(e) => e,
            };
            match ecc_offset(&err) {
                Some(offset) if repairs_left > 0 => {
                    repairs_left -= 1;
                    repair(self.queue.flash(), &self.range, offset, &mut self.repairs).await?;
                }
                _ => return Err(err.into()),
            }
        }
    }

    /// Calls `each` with every readable entry, oldest first, from record time `since_s` on;
    /// returns how many entries could not be decoded (skipped). `each` may await (the firmware
    /// streams each row to the UART); returning `false` stops the walk (a host that went away).
    pub async fn for_each(
        &mut self,
        since_s: u32,
        mut each: impl AsyncFnMut(&LogEntry) -> bool,
    ) -> Result<u32, StoreError> {
        let mut skipped = 0u32;
        let mut iter = match self.queue.iter().await {
            Ok(it) => it,
            Err(e) => return Err(e.into()),
        };
        loop {
            match iter.next(&mut self.buf.0).await {
                Ok(Some(item)) => match LogEntry::decode(&item[..]) {
                    Ok(e) if e.t_s() >= since_s => {
                        if !each(&e).await {
                            return Ok(skipped);
                        }
                    }
                    Ok(_) => {}
                    Err(_) => skipped += 1,
                },
                Ok(None) => return Ok(skipped),
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// The newest entry's record time, s (0 for an empty log): where this boot's record time
    /// continues.
    pub async fn last_t_s(&mut self) -> Result<u32, StoreError> {
        let mut last = 0u32;
        self.for_each(0, async |e: &LogEntry| {
            last = last.max(e.t_s());
            true
        })
        .await?;
        Ok(last)
    }
}

const _: () = assert!(ENTRY_LEN <= BUF_LEN);
// Every record fits `write_record`'s buffer and `Store::rec`, both sized by the history (the
// largest): a record that did not would be stored as nothing.
const _: () = assert!(
    ModelRecord::LEN <= HistoryRecord::LEN
        && super::CabinetRecord::LEN <= HistoryRecord::LEN
        && CalibrationRecord::LEN <= HistoryRecord::LEN
        && SettingsRecord::LEN <= HistoryRecord::LEN
);

/// Writes one [`Save`](super::Save) where it belongs: the log entries to the log, every other
/// record to the store under its key (encoded here, stored through one call: one copy of the
/// storage layer's write path in the firmware).
pub async fn write<F: NorFlash, E: EccErrors, G: NorFlash, H: EccErrors>(
    store: &mut Store<F, E>,
    log: &mut LogStore<G, H>,
    save: &super::Save,
) -> Result<(), StoreError> {
    match save {
        super::Save::Log(entry) => log.push(entry).await,
        super::Save::Settings(s) => store.store(key::SETTINGS, &s.encode()).await,
        #[cfg(feature = "holdover")]
        super::Save::Cabinet(c) => store.store(key::CABINET, &c.encode()).await,
        _ => write_record(store, save).await,
    }
}

/// Which region [`write_or_erase`] erased.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Erased {
    /// None: the write went as [`write()`] alone.
    Nothing,
    /// The records region: the caller hands over again what nothing stores on a cadence (the
    /// history now, the calibration; the interface build's settings and cabinet model,
    /// [`crate::app::App::records_erased`]).
    Records,
    /// The log: every entry before this one is gone, and it begins with a plain
    /// [`LogEntry::Lost`] (no count) at this entry's time, so that the record shows where its
    /// hole ends (before, `history` began there as if the carrier were new).
    Log,
}

/// [`write()`], and a region the storage layer finds corrupt ([`StoreError::Corrupted`], which its
/// own repair could not mend) erased once and the record written again: what the region held is
/// lost either way, and without the erase no record of its kind would be stored again.
pub async fn write_or_erase<F: NorFlash, E: EccErrors, G: NorFlash, H: EccErrors>(
    store: &mut Store<F, E>,
    log: &mut LogStore<G, H>,
    save: &super::Save,
) -> (Result<(), StoreError>, Erased) {
    let result = write(store, log, save).await;
    if result != Err(StoreError::Corrupted) {
        return (result, Erased::Nothing);
    }
    match save {
        super::Save::Log(entry) => {
            if let Err(e) = log.erase_all().await {
                return (Err(e), Erased::Nothing);
            }
            let _ = log.push(&LogEntry::Lost { t_s: entry.t_s(), entries: 0 }).await;
            (log.push(entry).await, Erased::Log)
        }
        _ => match store.erase_all().await {
            Ok(()) => (write(store, log, save).await, Erased::Records),
            Err(e) => (Err(e), Erased::Nothing),
        },
    }
}

/// Writes a record of a board without the interface to the store: the model, the history, the
/// calibration. What that board never writes is [`StoreError::Other`]: a log entry, settings, a
/// cabinet model ([`write()`] writes them), whose encoders it then leaves out of its flash.
pub async fn write_record<F: NorFlash, E: EccErrors>(
    store: &mut Store<F, E>,
    save: &super::Save,
) -> Result<(), StoreError> {
    use super::Save;
    let mut buf = [0u8; HistoryRecord::LEN];
    let (key, len) = match save {
        Save::Log(_) | Save::Settings(_) => return Err(StoreError::Other),
        #[cfg(feature = "holdover")]
        Save::Cabinet(_) => return Err(StoreError::Other),
        Save::Model(rec) => (key::MODEL, put(&mut buf, &rec.encode())),
        Save::History(h) | Save::AlarmHistory(h) => (key::HISTORY, put(&mut buf, &h.encode())),
        Save::Calibration(cal) => (key::CALIBRATION, put(&mut buf, &CalibrationRecord { cal: *cal }.encode())),
    };
    store.store(key, buf.get(..len).unwrap_or(&[])).await
}

/// Copies `bytes` to the front of `buf`; their length (0 if they do not fit).
fn put(buf: &mut [u8], bytes: &[u8]) -> usize {
    match buf.get_mut(..bytes.len()) {
        Some(dst) => {
            dst.copy_from_slice(bytes);
            bytes.len()
        }
        None => 0,
    }
}

/// What a boot restored from both regions, each record on its own (a torn history does not cost
/// the settings), with how each was obtained for the boot log.
#[derive(Clone, Copy, Debug)]
pub struct Restored {
    /// The settings, if a valid record is stored.
    pub settings: Result<SettingsRecord, LoadStatus>,
    /// The cabinet model, if a valid record is stored (loaded with the settings, by [`restore`]).
    #[cfg(feature = "holdover")]
    pub cabinet: Result<crate::model::Model, LoadStatus>,
    /// The calibration record (an older firmware's, or the build's constant stored at boot).
    pub calibration: Loaded<TwoPoint>,
    /// The cold-chain history.
    pub history: Loaded<HistoryRecord>,
    /// The self-tuner's configuration restarted from the stored model (`None`: no self-tuner).
    pub adaptive: Option<Loaded<AdaptiveConfig>>,
    /// The newest log entry's record time, s.
    pub log_last_s: Result<u32, StoreError>,
    /// Power-cut damage repaired in both regions.
    pub repairs: Repairs,
}

impl Restored {
    /// Nothing restored (no usable flash): every record its default.
    pub const NOTHING: Restored = Restored::nothing();

    /// [`Restored::NOTHING`], built in place where it is called: a use of the constant copies
    /// its 340 bytes (nearly all zero) from flash ([`HistoryRecord::empty`]).
    pub const fn nothing() -> Restored {
        Restored {
            settings: Err(LoadStatus::Missing),
            #[cfg(feature = "holdover")]
            cabinet: Err(LoadStatus::Missing),
            calibration: Loaded { value: TwoPoint::IDENTITY, status: LoadStatus::Missing },
            history: Loaded { value: HistoryRecord::empty(), status: LoadStatus::Missing },
            adaptive: None,
            log_last_s: Ok(0),
            repairs: Repairs { words_cleared: 0, pages_erased: 0 },
        }
    }

    /// The records this boot refused ([`LoadStatus::Invalid`]: stored, intact for the storage
    /// layer, their frame or content failing this firmware's checks), as [`crate::persist::Record::bit`]s. A record the
    /// flash could not give ([`LoadStatus::Flash`]) is not one: the storage layer's repair and the
    /// boot's warning deal with it. Nor is the calibration record when settings were restored:
    /// the settings' calibration runs ([`crate::app::App::new`]), so its refusal changes nothing
    /// (nor where the build's constant replaces the record,
    /// [`crate::app::Boot::run_calibration_constant`]).
    pub fn refused(&self) -> u8 {
        use crate::persist::Record;
        // By reference: the model's configuration copied out to read its status cost flash.
        let refused =
            |r: Record, s: Option<&LoadStatus>| if matches!(s, Some(LoadStatus::Invalid(_))) { r.bit() } else { 0 };
        #[cfg(feature = "holdover")]
        let cabinet = refused(Record::Cabinet, self.cabinet.as_ref().err());
        #[cfg(not(feature = "holdover"))]
        let cabinet = 0;
        refused(Record::Model, self.adaptive.as_ref().map(|a| &a.status))
            | refused(Record::Calibration, self.settings.is_err().then_some(&self.calibration.status))
            | refused(Record::History, Some(&self.history.status))
            | refused(Record::Settings, self.settings.as_ref().err())
            | cabinet
    }

    /// What a boot stores of the build's calibration constant `constant` (firmware `config.rs`'s
    /// `CALIBRATION`), which it runs when no settings are stored: the constant, unless the
    /// calibration record already holds it. Stored, a later image built without the constant
    /// keeps it (README "Calibrating a board"); unstored, that image read up to 1.5 °C off with
    /// nothing on record. Once: the next boot finds the record.
    pub fn calibration_to_store(&self, constant: TwoPoint) -> Option<TwoPoint> {
        let stored = self.calibration.status == LoadStatus::Restored && self.calibration.value == constant;
        (!stored).then_some(constant)
    }

    /// The application's boot from what was restored. Out of line: inlined into the firmware's
    /// `main`, it cost 312 B of code there, against 264 B here (−56 B of flash in all).
    #[inline(never)]
    pub fn boot(&self, reset: super::ResetCause, stops: crate::failsafe::Stops) -> crate::app::Boot {
        crate::app::Boot {
            refused: self.refused(),
            settings: self.settings.ok(),
            #[cfg(feature = "holdover")]
            cabinet: self.cabinet.ok(),
            calibration: self.calibration.value,
            adaptive: self.adaptive.map(|a| a.value),
            history: self.history.value,
            log_last_s: self.log_last_s.unwrap_or(0),
            reset,
            stops,
            pages_lost: u8::try_from(self.repairs.total()).unwrap_or(u8::MAX),
            button_held: false,
        }
    }
}

/// Scrubs both regions, then loads every record (the boot's sequence, shared by the firmware and
/// `hter virtual-board`). `adaptive`: the build's self-tuner configuration, if it has one.
pub async fn restore<F: NorFlash, E: EccErrors, G: NorFlash, H: EccErrors>(
    store: &mut Store<F, E>,
    log: &mut LogStore<G, H>,
    adaptive: Option<AdaptiveConfig>,
) -> Restored {
    let _ = log.scrub().await;
    let mut r = restore_records(store, adaptive.as_ref()).await;
    r.settings = store.load_settings().await;
    #[cfg(feature = "holdover")]
    if let Some(cfg) = adaptive {
        r.cabinet = store.load_cabinet(&cfg).await;
    }
    r.log_last_s = log.last_t_s().await;
    let b = log.repairs();
    r.repairs = Repairs {
        words_cleared: r.repairs.words_cleared.saturating_add(b.words_cleared),
        pages_erased: r.repairs.pages_erased.saturating_add(b.pages_erased),
    };
    r
}

/// [`restore`] of the store alone, for a board without the interface: no log (`log_last_s` is
/// 0) and no settings (`settings` is [`LoadStatus::Missing`]; the build's constants apply).
/// `adaptive` is borrowed for the reason [`Store::load_adaptive`]'s `cfg` is.
pub async fn restore_records<F: NorFlash, E: EccErrors>(
    store: &mut Store<F, E>,
    adaptive: Option<&AdaptiveConfig>,
) -> Restored {
    // A scrub that fails leaves the loads to repair what they read.
    let _ = store.scrub().await;
    // [`Restored::nothing`]'s two fields, built alone (taking them from the whole value: +48 B).
    let mut calibration = Loaded { value: TwoPoint::IDENTITY, status: LoadStatus::Missing };
    let mut history = Loaded { value: HistoryRecord::empty(), status: LoadStatus::Missing };
    let mut model = Err(LoadStatus::Missing);
    // The loads of `load_calibration`, `load_history` and `load_adaptive`, in that order, through
    // one fetch: each awaited load was a future of its own inside the caller's (≈ 0.3 KiB of the
    // firmware's flash). The model's plausibility is checked after the loop, so that only its
    // record, not the configuration, is kept across the fetches.
    for key in [key::CALIBRATION, key::HISTORY, key::MODEL] {
        if key == key::MODEL && adaptive.is_none() {
            break;
        }
        let fetched = store.fetch(key).await;
        match key {
            key::CALIBRATION => calibration = calibration_from(fetched),
            key::HISTORY => history = history_from(fetched),
            _ => model = model_from(fetched),
        }
    }
    Restored {
        settings: Err(LoadStatus::Missing),
        #[cfg(feature = "holdover")]
        cabinet: Err(LoadStatus::Missing),
        calibration,
        history,
        adaptive: adaptive.map(|cfg| adaptive_from(model, cfg)),
        log_last_s: Ok(0),
        repairs: store.repairs(),
    }
}
