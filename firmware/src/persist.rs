//! Glue between the carrier and `hter::persist::flash::Store` over the STM32L4's flash: what is
//! restored at boot (calibration, cold-chain history, the self-tuner's model) and a task that
//! stores what the control task hands it.
//!
//! Writes wait for [`hter::persist::WriteGate`]: the supply (the control task's [`note_supply`]
//! every sample) good for 60 s since boot and good now, or good now for an alarm record. Until
//! then requests wait in [`hter::persist::PendingSaves`], the newest of each kind, so a board in
//! a power-bounce loop never writes (and never tears a word). Reads go through the store's ECC
//! repair: the NMI handler notes a double ECC error in the region ([`crate::ecc`]), the reader
//! fails, the store clears the torn word or erases the torn page and retries; the boot reports
//! how many pages it repaired ([`Restored::pages_lost`]).
//!
//! The flash driver is blocking (embassy's `Flash` in blocking mode behind `BlockingAsync`): a
//! store stalls the executor for at most one page erase (≈ 22 ms on the L4, RM0351 table 50
//! "tERASE") plus a few double-word writes, about once an hour; the 10 s control loop and the
//! 30 s watchdog do not notice.

use core::cell::RefCell;
use defmt::{info, warn};
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::signal::Signal;
use embassy_time::Instant;
use hter::calib::TwoPoint;
use hter::control::adaptive::AdaptiveConfig;
use hter::persist::flash::{key, EccErrors, LoadStatus, Store, StoreError};
pub use hter::persist::Save;
use hter::persist::{CalibrationRecord, HistoryRecord, PendingSaves, WriteGate};

use crate::config;

/// ECC errors of the STM32L4's flash, as the NMI handler notes them ([`crate::ecc`], absolute
/// addresses), as offsets from the flash base (what embassy's `Flash` and the store address).
pub struct L4Ecc;

impl EccErrors for L4Ecc {
    fn take(&mut self) -> Option<u32> {
        crate::ecc::take().map(|addr| addr.wrapping_sub(crate::board::FLASH_BASE))
    }
}

/// The record store over the `PERSIST` region.
pub type FlashStore = Store<BlockingAsync<Flash<'static, Blocking>>, L4Ecc>;

/// The records waiting for the write gate, and the gate.
static PENDING: Mutex<CriticalSectionRawMutex, RefCell<(PendingSaves, WriteGate)>> =
    Mutex::new(RefCell::new((PendingSaves::EMPTY, WriteGate::firmware())));

/// Wakes the `persist` task: a new request, or a supply sample that may open the gate.
static WAKE: Signal<CriticalSectionRawMutex, ()> = Signal::new();

fn now_ms() -> u64 {
    Instant::now().as_millis()
}

/// One supply sample for the write gate: `ok` when the supply is above what a flash write needs
/// (the control task calls this every sample).
pub fn note_supply(ok: bool) {
    let now = now_ms();
    PENDING.lock(|p| p.borrow_mut().1.note_supply(now, ok));
    WAKE.signal(());
}

/// What the boot restored.
pub struct Restored {
    /// The calibration to run with.
    pub cal: TwoPoint,
    /// The history carried in from earlier boots.
    pub history: HistoryRecord,
    /// The self-tuner's configuration, restarted from the stored model if a good one is stored.
    pub adaptive: Option<AdaptiveConfig>,
    /// Flash pages the boot found torn by a power cut (ECC errors) and repaired: one
    /// `FlashPageLost` event and one count in the history each.
    pub pages_lost: u8,
}

/// Opens the store; `None` (and says so) if the configured region is unusable.
pub fn open(flash: Peri<'static, FLASH>) -> Option<FlashStore> {
    match Store::new(BlockingAsync::new(Flash::new_blocking(flash)), L4Ecc, config::PERSIST_RANGE) {
        Ok(store) => Some(store),
        Err(e) => {
            warn!("persist: flash region unusable ({}): nothing is restored or saved", e);
            None
        }
    }
}

fn log_status(what: &str, status: LoadStatus) {
    match status {
        LoadStatus::Restored => info!("persist: {} restored", what),
        LoadStatus::Missing => info!("persist: no stored {}, using the default", what),
        LoadStatus::Invalid(e) => warn!("persist: stored {} rejected ({}), using the default", what, e),
        LoadStatus::Flash(e) => warn!("persist: reading the {} failed ({}), using the default", what, e),
    }
}

/// Everything the boot restores, each record falling back to its default on its own (a torn
/// history does not cost the calibration). `None` store: the defaults.
pub async fn restore(store: Option<&mut FlashStore>) -> Restored {
    let Some(store) = store else {
        return Restored {
            cal: config::CALIBRATION.unwrap_or(TwoPoint::IDENTITY),
            history: HistoryRecord::EMPTY,
            adaptive: config::ADAPTIVE,
            pages_lost: 0,
        };
    };
    if let Err(e) = store.scrub().await {
        warn!("persist: scrubbing the region failed ({})", e);
    }
    let stored_cal = store.load_calibration().await;
    let cal = match config::CALIBRATION {
        Some(cal) => {
            if stored_cal.status != LoadStatus::Restored || stored_cal.value != cal {
                info!("persist: calibration from config.rs (gain {} offset {} °C), storing it", cal.gain, cal.offset_c);
                request(Save::Calibration(cal));
            }
            cal
        }
        None => {
            log_status("calibration", stored_cal.status);
            if stored_cal.status != LoadStatus::Restored {
                warn!("uncalibrated: readings use the nominal Pt100 and front end (README, Calibrating a board)");
            }
            stored_cal.value
        }
    };
    info!("calibration: gain {} offset {} °C", cal.gain, cal.offset_c);
    let history = store.load_history().await;
    log_status("cold-chain history", history.status);
    let h = history.value;
    info!(
        "history: {} h recorded, alarms heat_10h {} freeze_60min {} ship_45c_1h {} ship_30c_10h {}, {} excursions, resets watchdog {} brown-out {} other {}",
        h.recorded_s / 3600,
        h.alarms[0],
        h.alarms[1],
        h.alarms[2],
        h.alarms[3],
        h.excursions,
        h.resets[0],
        h.resets[1],
        h.resets[2]
    );
    let adaptive = match config::ADAPTIVE {
        Some(cfg) => {
            let loaded = store.load_adaptive(cfg).await;
            match (loaded.status, loaded.value.initial) {
                (LoadStatus::Restored, Some(m)) => {
                    info!("persist: model restored: a={} b={} k={}", m.a(), m.b(), m.k())
                }
                (status, _) => log_status("model", status),
            }
            Some(loaded.value)
        }
        None => None,
    };
    let repairs = store.repairs();
    if repairs.total() > 0 {
        warn!(
            "persist: power-cut damage repaired: {} torn words cleared, {} torn pages erased",
            repairs.words_cleared, repairs.pages_erased
        );
    }
    let pages_lost = u8::try_from(repairs.total()).unwrap_or(u8::MAX);
    Restored { cal, history: history.value, adaptive, pages_lost }
}

/// Queues a record for the `persist` task (replacing a waiting one of its kind); it is written
/// once the write gate opens.
pub fn request(save: Save) {
    PENDING.lock(|p| p.borrow_mut().0.put(save));
    WAKE.signal(());
}

/// Stores each requested record the write gate lets through. A region the storage layer finds
/// corrupt is erased once and written again (what it held is lost either way; the next requests
/// rewrite the rest).
#[embassy_executor::task]
pub async fn persist(mut store: FlashStore) {
    loop {
        let next = PENDING.lock(|p| {
            let (pending, gate) = &mut *p.borrow_mut();
            pending.next(gate, now_ms())
        });
        let Some(save) = next else {
            WAKE.wait().await;
            continue;
        };
        let mut result = write(&mut store, &save).await;
        if result == Err(StoreError::Corrupted) {
            warn!("persist: region corrupt, erasing it");
            result = match store.erase_all().await {
                Ok(()) => write(&mut store, &save).await,
                Err(e) => Err(e),
            };
        }
        match (result, save) {
            (Ok(()), Save::Model(rec)) => info!("persist: model stored: theta={} k={}", rec.theta, rec.k),
            (Ok(()), Save::History(h)) => info!("persist: history stored ({} h recorded)", h.recorded_s / 3600),
            (Ok(()), Save::AlarmHistory(h)) => {
                info!("persist: history stored at an alarm ({} h recorded)", h.recorded_s / 3600)
            }
            (Ok(()), Save::Calibration(_)) => info!("persist: calibration stored"),
            (Err(e), _) => warn!("persist: store failed ({})", e),
        }
    }
}

async fn write(store: &mut FlashStore, save: &Save) -> Result<(), StoreError> {
    // Encoded here, stored through one call: one copy of the storage layer's write path.
    let mut buf = [0u8; HistoryRecord::LEN];
    let (key, len) = match save {
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
