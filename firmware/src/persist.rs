//! Glue between the carrier and `hter::persist::flash::Store` over the STM32L4's flash: what is
//! restored at boot (calibration, cold-chain history, the self-tuner's model) and a task that
//! stores what the control task hands it.
//!
//! The flash driver is blocking (embassy's `Flash` in blocking mode behind `BlockingAsync`): a
//! store stalls the executor for at most one page erase (≈ 22 ms on the L4, RM0351 table 50
//! "tERASE") plus a few double-word writes, about once an hour; the 10 s control loop and the
//! 30 s watchdog do not notice.

use defmt::{info, warn};
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use hter::calib::TwoPoint;
use hter::control::adaptive::AdaptiveConfig;
use hter::control::AnyController;
use hter::persist::flash::{key, LoadStatus, Store, StoreError};
use hter::persist::{CalibrationRecord, HistoryRecord, ModelRecord};

use crate::config;

/// The record store over the `PERSIST` region.
pub type FlashStore = Store<BlockingAsync<Flash<'static, Blocking>>>;

/// A record to store.
#[derive(Clone, Copy)]
pub enum Save {
    /// The self-tuner's trusted model.
    Model(ModelRecord),
    /// The cold-chain history.
    History(HistoryRecord),
    /// The calibration.
    Calibration(TwoPoint),
}

/// Records waiting for the `persist` task. A full queue drops the request (and says so): the
/// next hourly history or 4-hourly model carries the same information.
static SAVES: Channel<CriticalSectionRawMutex, Save, 3> = Channel::new();

/// What the boot restored.
pub struct Restored {
    /// The calibration to run with.
    pub cal: TwoPoint,
    /// The history carried in from earlier boots.
    pub history: HistoryRecord,
    /// The self-tuner's configuration, restarted from the stored model if a good one is stored.
    pub adaptive: Option<AdaptiveConfig>,
}

/// Opens the store; `None` (and says so) if the configured region is unusable.
pub fn open(flash: Peri<'static, FLASH>) -> Option<FlashStore> {
    match Store::new(BlockingAsync::new(Flash::new_blocking(flash)), config::PERSIST_RANGE) {
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
        };
    };
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
                (LoadStatus::Restored, Some(m)) => info!("persist: model restored: a={} b={} k={}", m.a, m.b, m.k),
                (status, _) => log_status("model", status),
            }
            Some(loaded.value)
        }
        None => None,
    };
    Restored { cal, history: history.value, adaptive }
}

/// Queues a record for the `persist` task.
pub fn request(save: Save) {
    if SAVES.try_send(save).is_err() {
        warn!("persist: store queue full, a record waits for its next turn");
    }
}

/// Asks for the controller's trusted model to be stored, if it has one.
pub fn request_model(controller: &AnyController) {
    if let AnyController::SelfTuning(st) = controller {
        if let Some(rec) = st.trusted_model().as_ref().and_then(ModelRecord::from_model) {
            request(Save::Model(rec));
        }
    }
}

/// Stores each requested record. A region the storage layer finds corrupt is erased once and
/// written again (what it held is lost either way; the next requests rewrite the rest).
#[embassy_executor::task]
pub async fn persist(mut store: FlashStore) {
    loop {
        let save = SAVES.receive().await;
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
        Save::History(h) => (key::HISTORY, put(&mut buf, &h.encode())),
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
