//! The records of [`crate::persist`] in NOR flash, through `sequential-storage`'s map (one key
//! per record kind; a store appends, the newest item of a key wins, full pages are erased in
//! turn, so wear spreads over the region). Generic over
//! `embedded_storage_async::nor_flash::NorFlash`: the firmware passes the STM32's flash, the host
//! tests a mock that loses power mid-write, and both run this code.
//!
//! Loading never fails: a record that is missing, torn, corrupt or implausible yields the
//! default and a [`LoadStatus`] saying which, for the firmware to log.

use core::ops::Range;

use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use super::{CalibrationRecord, DecodeError, HistoryRecord, ModelRecord};
use crate::calib::TwoPoint;
use crate::control::adaptive::AdaptiveConfig;

/// Map keys, one per record kind. Never reuse a key for a different layout: bump the record's
/// version instead.
pub mod key {
    /// [`super::ModelRecord`].
    pub const MODEL: u8 = 1;
    /// [`super::CalibrationRecord`].
    pub const CALIBRATION: u8 = 2;
    /// [`super::HistoryRecord`].
    pub const HISTORY: u8 = 3;
}

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash range is not page-aligned or spans fewer than two pages.
    Config,
    /// The flash driver reported an error (or power was lost).
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

/// Working buffer: the largest item (1 key byte + [`HistoryRecord::LEN`]) rounded up to the
/// flash word, with room for 16-byte words; aligned for flash drivers that want it.
#[repr(C, align(8))]
struct Buffer([u8; 128]);

/// The persisted records over a flash region.
pub struct Store<S: NorFlash> {
    map: MapStorage<u8, S, Cache<Uncached, Uncached, Uncached, u8>>,
    buf: Buffer,
}

impl<S: NorFlash> Store<S> {
    /// A store over `range` (absolute flash offsets, page-aligned, at least two pages) of `flash`.
    pub fn new(flash: S, range: Range<u32>) -> Result<Self, StoreError> {
        let config = MapConfig::try_new(range).map_err(|_| StoreError::Config)?;
        Ok(Store { map: MapStorage::new(flash, config, Cache::new_uncached()), buf: Buffer([0; 128]) })
    }

    /// The flash back (e.g. to reopen it after a simulated reset).
    pub fn release(self) -> S {
        self.map.destroy().0
    }

    /// Erases the whole region.
    pub async fn erase_all(&mut self) -> Result<(), StoreError> {
        Ok(self.map.erase_all().await?)
    }

    /// Stores already encoded record bytes under `key` (one call site for every record kind
    /// keeps one copy of the storage layer's write path in the firmware's flash).
    pub async fn store(&mut self, key: u8, bytes: &[u8]) -> Result<(), StoreError> {
        Ok(self.map.store_item(&mut self.buf.0, &key, &bytes).await?)
    }

    /// The bytes of the newest item under `key` (not generic: one copy of the storage layer's
    /// read path for every record kind).
    async fn fetch(&mut self, key: u8) -> Result<&[u8], LoadStatus> {
        match self.map.fetch_item::<&[u8]>(&mut self.buf.0, &key).await {
            Ok(Some(bytes)) => Ok(bytes),
            Ok(None) => Err(LoadStatus::Missing),
            Err(e) => Err(LoadStatus::Flash(e.into())),
        }
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
        self.load(key::MODEL, ModelRecord::decode).await
    }

    /// `cfg` restarted from the stored model ([`AdaptiveConfig::restored_from`]) if one is stored
    /// and plausible under `cfg`'s limits; otherwise `cfg` unchanged.
    pub async fn load_adaptive(&mut self, cfg: AdaptiveConfig) -> Loaded<AdaptiveConfig> {
        match self.load_model_record().await.and_then(|rec| rec.restore(&cfg).map_err(LoadStatus::Invalid)) {
            Ok(value) => Loaded { value, status: LoadStatus::Restored },
            Err(status) => Loaded { value: cfg, status },
        }
    }

    /// Stores the calibration.
    pub async fn save_calibration(&mut self, cal: TwoPoint) -> Result<(), StoreError> {
        self.store(key::CALIBRATION, &CalibrationRecord { cal }.encode()).await
    }

    /// The stored calibration, or [`TwoPoint::IDENTITY`].
    pub async fn load_calibration(&mut self) -> Loaded<TwoPoint> {
        match self.load(key::CALIBRATION, CalibrationRecord::decode).await {
            Ok(rec) => Loaded { value: rec.cal, status: LoadStatus::Restored },
            Err(status) => Loaded { value: TwoPoint::IDENTITY, status },
        }
    }

    /// Stores the history.
    pub async fn save_history(&mut self, rec: &HistoryRecord) -> Result<(), StoreError> {
        self.store(key::HISTORY, &rec.encode()).await
    }

    /// The stored history, or [`HistoryRecord::EMPTY`].
    pub async fn load_history(&mut self) -> Loaded<HistoryRecord> {
        match self.load(key::HISTORY, HistoryRecord::decode).await {
            Ok(value) => Loaded { value, status: LoadStatus::Restored },
            Err(status) => Loaded { value: HistoryRecord::EMPTY, status },
        }
    }
}
