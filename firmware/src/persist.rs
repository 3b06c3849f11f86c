//! Glue between the self-tuner and `hter::persist::flash::Store` over the STM32L4's flash: the
//! boot-time restore and a task that saves the trusted model when the control task asks.
//!
//! The flash driver is blocking (embassy's `Flash` in blocking mode behind `BlockingAsync`): a
//! save stalls the executor for at most one page erase (≈ 22 ms on the L4, RM0351 table 50
//! "tERASE") plus a few double-word writes, once every 4 h; the 10 s control loop and the 30 s
//! watchdog do not notice.

use defmt::{info, warn};
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use hter::control::adaptive::AdaptiveConfig;
use hter::control::AnyController;
use hter::persist::flash::{LoadStatus, Store, StoreError};
use hter::persist::ModelRecord;

use crate::config;

/// The record store over the `PERSIST` region.
pub type FlashStore = Store<BlockingAsync<Flash<'static, Blocking>>>;

/// The newest model to save.
static SAVE_MODEL: Signal<CriticalSectionRawMutex, ModelRecord> = Signal::new();

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

/// The self-tuner's configuration, restarted from the stored model when there is a good one.
pub async fn restore(store: &mut FlashStore) -> AdaptiveConfig {
    let loaded = store.load_adaptive(config::ADAPTIVE).await;
    match loaded.status {
        LoadStatus::Restored => match loaded.value.initial {
            Some(m) => info!("persist: model restored: a={} b={} k={}", m.a, m.b, m.k),
            None => info!("persist: model restored"),
        },
        LoadStatus::Missing => info!("persist: no stored model, starting from the built-in one"),
        LoadStatus::Invalid(e) => warn!("persist: stored model rejected ({}), starting from the built-in one", e),
        LoadStatus::Flash(e) => warn!("persist: flash read failed ({}), starting from the built-in one", e),
    }
    loaded.value
}

/// Asks the `persist` task to save the controller's trusted model, if it has one.
pub fn request_save(controller: &AnyController) {
    if let AnyController::SelfTuning(st) = controller {
        if let Some(rec) = st.trusted_model().as_ref().and_then(ModelRecord::from_model) {
            SAVE_MODEL.signal(rec);
        }
    }
}

/// Saves each requested model. A region the storage layer finds corrupt is erased once and
/// written again (the record it held is lost either way).
#[embassy_executor::task]
pub async fn persist(mut store: FlashStore) {
    loop {
        let rec = SAVE_MODEL.wait().await;
        let mut result = store.save_model(&rec).await;
        if result == Err(StoreError::Corrupted) {
            warn!("persist: region corrupt, erasing it");
            result = match store.erase_all().await {
                Ok(()) => store.save_model(&rec).await,
                Err(e) => Err(e),
            };
        }
        match result {
            Ok(()) => info!("persist: model saved: theta={} k={}", rec.theta, rec.k),
            Err(e) => warn!("persist: model save failed ({})", e),
        }
    }
}
