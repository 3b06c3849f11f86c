//! Glue between the carrier and the library's flash stores over the STM32L4's flash: the boot's
//! restore, a task that stores what the control task hands it, and the `history` stream.
//!
//! Bank 2 holds two regions (`memory.x`): the records (`PERSIST`: settings, model, calibration,
//! history; `hter::persist::flash::Store`) and the cold-chain log (`LOG`: intervals and events;
//! `hter::persist::flash::LogStore`). One flash driver serves both, through embassy's flash
//! [`Partition`]s, all inside the [`persist`] task: it restores at boot
//! (`hter::persist::flash::restore`, then [`BOOTED`]), writes every save
//! (`hter::persist::flash::write`) and streams the log for `history` ([`HISTORY`] →
//! [`HISTORY_PIPE`]).
//!
//! Writes wait for [`hter::persist::WriteGate`]: the supply (the control task's [`note_supply`]
//! every sample, and PVDO read again before each record) good for 60 s since boot and good
//! now, or good now for an alarm record. Until
//! then requests wait in [`hter::persist::PendingSaves`] (the newest record of each kind, every
//! log entry), so a board in a power-bounce loop never writes (and never tears a word). Reads
//! go through the stores' ECC repair: the NMI handler notes a double ECC error in either region
//! ([`crate::ecc`]), the reader fails, the store clears the torn word or erases the torn page
//! and retries; the boot reports how many pages it repaired.
//!
//! The flash driver is blocking (embassy's `Flash` in blocking mode behind `BlockingAsync`): a
//! store stalls the executor for at most one page erase (≈ 22 ms on the L4, RM0351 table 50
//! "tERASE") plus a few double-word writes; the log appends one 32-byte item every 5 minutes
//! and erases a page every ≈ 5 h; the 10 s control loop and the 30 s watchdog do not notice.

use core::cell::RefCell;
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};

use defmt::{info, warn};
#[cfg(feature = "interface")]
use embassy_futures::select::{select, Either};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
#[cfg(feature = "interface")]
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_time::Instant;
#[cfg(feature = "interface")]
use embassy_time::{with_timeout, Duration};
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
#[cfg(feature = "interface")]
use hter::persist::flash::LogStore;
use hter::persist::flash::{self, EccErrors, LoadStatus, Restored, Store};
#[cfg(feature = "interface")]
use hter::persist::log::{write_csv_row, LogEntry, CSV_HEADER};
pub use hter::persist::Save;
use hter::persist::{PendingSaves, WriteGate};

use crate::config;

/// One region of the flash, for one store: the blocking driver shared by both regions (only the
/// persist task uses it, one operation at a time). Not embassy's async `Partition`: its mutex
/// gives every flash operation a real suspension point, and sequential-storage's state
/// machines grow with each (measured: several KiB); a blocking operation completes when its
/// method is called and hands back a ready future ([`Done`]; every caller awaits it at once, so
/// it runs where an `async fn` body would; the `async fn`s' own state machines cost 68 B of
/// flash).
pub struct Region<'a> {
    flash: &'a RefCell<Flash<'static, Blocking>>,
    offset: u32,
    size: u32,
}

impl ErrorType for Region<'_> {
    type Error = embassy_stm32::flash::Error;
}

impl ReadNorFlash for Region<'_> {
    const READ_SIZE: usize = <Flash<'static, Blocking> as embedded_storage::nor_flash::ReadNorFlash>::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> impl Future<Output = Result<(), Self::Error>> {
        Done(self.flash.borrow_mut().blocking_read(self.offset + offset, bytes))
    }

    fn capacity(&self) -> usize {
        self.size as usize
    }
}

impl NorFlash for Region<'_> {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as embedded_storage::nor_flash::NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Flash<'static, Blocking> as embedded_storage::nor_flash::NorFlash>::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> impl Future<Output = Result<(), Self::Error>> {
        Done(self.flash.borrow_mut().blocking_erase(self.offset + from, self.offset + to))
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> impl Future<Output = Result<(), Self::Error>> {
        Done(self.flash.borrow_mut().blocking_write(self.offset + offset, bytes))
    }
}

/// A blocking operation's result as a future that is ready at once. Not `core::future::ready`:
/// its poll after completion panics, and that path linked its message and its source file's
/// 81-byte path into flash (−120 B in all); each of these is awaited once, where a result that
/// is `Copy` can simply be handed out again.
struct Done<T>(T);

impl<T: Copy + Unpin> Future for Done<T> {
    type Output = T;

    fn poll(self: Pin<&mut Self>, _: &mut Context<'_>) -> Poll<T> {
        Poll::Ready(self.0)
    }
}

/// ECC errors of the STM32L4's flash, as the NMI handler notes them ([`crate::ecc`], absolute
/// addresses), as offsets within the partition that starts `base` bytes past the flash base.
pub struct L4Ecc {
    base: u32,
}

impl EccErrors for L4Ecc {
    fn take(&mut self) -> Option<u32> {
        crate::ecc::take().map(|addr| addr.wrapping_sub(crate::board::FLASH_BASE + self.base))
    }
}

/// The records waiting for the write gate, and the gate; set up on first use.
static PENDING: Mutex<CriticalSectionRawMutex, RefCell<Pending>> = Mutex::new(RefCell::new(Pending::Unset));

/// [`PENDING`]'s contents. Not the queue and gate themselves: their empty states hold niche
/// values and the gate's constants, which put all 672 bytes in `.data` (flash); `Unset` is a
/// zero tag (`repr(u8)`, no niche), so the static is `.bss` and the first use builds them
/// field by field (`PendingSaves::default()` is `EMPTY`; −536 B of flash in all).
// (One static of it: the empty variant's unused room is the point.)
#[allow(clippy::large_enum_variant)]
#[repr(u8)]
enum Pending {
    Unset = 0,
    Set(PendingSaves, WriteGate) = 1,
}

/// Runs `f` on the waiting records and the write gate (on the first use, on new ones, which
/// it then keeps).
fn with_pending<R>(f: impl FnOnce(&mut PendingSaves, &mut WriteGate) -> R) -> R {
    PENDING.lock(|p| {
        let mut p = p.borrow_mut();
        let (pending, gate) = set_up(&mut p);
        f(pending, gate)
    })
}

/// The waiting records and the write gate, set up on the first use. Out of line, and built in
/// place: inlined into each of the three callers of [`with_pending`], the setup built the
/// 640-byte pair on the stack and copied it into the static (−184 B of flash, −232 B with the
/// interface).
#[inline(never)]
fn set_up(p: &mut Pending) -> (&mut PendingSaves, &mut WriteGate) {
    if matches!(p, Pending::Unset) {
        *p = Pending::Set(PendingSaves::default(), WriteGate::firmware());
    }
    match p {
        Pending::Set(pending, gate) => (pending, gate),
        Pending::Unset => unreachable!(),
    }
}

static WAKE: Signal<CriticalSectionRawMutex, ()> = Signal::new();

/// The records region was erased after the storage layer found it corrupt: the control task
/// hands the records over again (the interface build: [`hter::app::App::records_erased`]; the
/// others: the history and the calibration in force, at the next sample).
pub static RECORDS_ERASED: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);

/// The persist task's `hter::persist::StoreFailures::in_a_row` after its latest store, which the
/// control task's `hter::persist::StoreWatch` reads ([`failed_in_a_row`]).
static FAILED_IN_A_ROW: core::sync::atomic::AtomicU8 = core::sync::atomic::AtomicU8::new(0);

/// Stores failed in a row in the region that has failed longest.
pub fn failed_in_a_row() -> u8 {
    FAILED_IN_A_ROW.load(core::sync::atomic::Ordering::Relaxed)
}

/// What the boot restored: the persist task sends it once, `main` waits for it. A one-slot
/// channel, not a `Signal`: a signal's empty state is a niche value inside `Restored`, which
/// puts all 324 bytes of it in `.data` (flash); the channel's empty state is all zeros (`.bss`):
/// −292 B of flash.
pub static BOOTED: Channel<CriticalSectionRawMutex, Restored, 1> = Channel::new();

/// A `history` request: stream the log from this record time, s.
#[cfg(feature = "interface")]
pub static HISTORY: Signal<CriticalSectionRawMutex, u32> = Signal::new();

/// The `history` reply on its way to the serial task: the CSV header, a row per entry, then
/// the final line (`ok` or `err history: …`).
#[cfg(feature = "interface")]
pub static HISTORY_PIPE: Pipe<CriticalSectionRawMutex, 256> = Pipe::new();

/// A row that waits this long for the serial task is dropped with the rest of the stream (a
/// host that stopped reading must not hold the flash writes back).
#[cfg(feature = "interface")]
const HISTORY_STALL_MS: u64 = 2_000;

/// Hands `main` what the boot restored (once: the slot is free).
fn send_booted(r: Restored) {
    let _ = BOOTED.try_send(r);
}

fn now_ms() -> u64 {
    Instant::now().as_millis()
}

/// Tells the write gate how the supply is (every sample).
pub fn note_supply(ok: bool) {
    let now = now_ms();
    with_pending(|_, gate| gate.note_supply(now, ok));
    WAKE.signal(());
}

/// Queues a record for the [`persist`] task (a waiting one of its kind is replaced; log entries
/// queue in order); it is written once the write gate opens.
pub fn request(save: Save) {
    with_pending(|pending, _| pending.put(save));
    WAKE.signal(());
}

fn log_status(what: &str, status: LoadStatus) {
    match status {
        LoadStatus::Restored => info!("persist: {} restored", what),
        LoadStatus::Missing => info!("persist: no stored {}, using the default", what),
        LoadStatus::Invalid(e) => warn!("persist: stored {} rejected ({}), using the default", what, e),
        LoadStatus::Flash(e) => warn!("persist: reading the {} failed ({}), using the default", what, e),
    }
}

/// The boot log of what was restored.
fn report(r: &Restored) {
    log_status("settings", r.settings.err().unwrap_or(LoadStatus::Restored));
    #[cfg(feature = "interface")]
    log_status("cabinet model", r.cabinet.err().unwrap_or(LoadStatus::Restored));
    log_status("calibration", r.calibration.status);
    log_status("cold-chain history", r.history.status);
    if let Some(a) = r.adaptive {
        log_status("model", a.status);
    }
    match r.log_last_s {
        Ok(t) => info!("persist: the log continues at record time {} s", t),
        Err(e) => warn!("persist: the log could not be read ({})", e),
    }
    if r.repairs.total() > 0 {
        warn!(
            "persist: power-cut damage repaired: {} torn words cleared, {} torn pages erased",
            r.repairs.words_cleared, r.repairs.pages_erased
        );
    }
}

/// Restores, then stores each requested record the write gate lets through (and, with the
/// interface, streams the log for `history`). A region the storage layer finds corrupt is
/// erased once and written again (what it held is lost either way): the model and the history
/// come back with their next stores, and the calibration (and in the interface build the
/// settings and the cabinet model), which are stored only when they change, are handed over
/// again ([`RECORDS_ERASED`]).
#[embassy_executor::task]
pub async fn persist(flash: Peri<'static, FLASH>) {
    let flash = RefCell::new(Flash::new_blocking(flash));
    let region = |r: core::ops::Range<u32>| Region { flash: &flash, offset: r.start, size: r.end - r.start };
    let p = config::PERSIST_RANGE;
    let store = Store::new(region(p.clone()), L4Ecc { base: p.start }, 0..p.end - p.start);
    #[cfg(feature = "interface")]
    let log = {
        let l = config::LOG_RANGE;
        LogStore::new(region(l.clone()), L4Ecc { base: l.start }, 0..l.end - l.start)
    };
    #[cfg(feature = "interface")]
    let (Ok(mut store), Ok(mut log)) = (store, log) else {
        warn!("persist: flash regions unusable: nothing is restored or saved");
        send_booted(Restored::nothing());
        loop {
            HISTORY.wait().await;
            HISTORY_PIPE.write_all(b"err history: no flash\r\n").await;
        }
    };
    #[cfg(not(feature = "interface"))]
    let Ok(mut store) = store
    else {
        warn!("persist: flash region unusable: nothing is restored or saved");
        send_booted(Restored::nothing());
        return;
    };
    // The interface build links the self-tuning laws whatever its default law (`set controller
    // gpc` on the `interface,pi` build): its models are restored with the self-tuner it would run,
    // `config::APP`'s (with `config::ADAPTIVE`, `None` there, they were lost at every restart).
    #[cfg(feature = "interface")]
    let restored = flash::restore(&mut store, &mut log, Some(config::APP.adaptive)).await;
    #[cfg(not(feature = "interface"))]
    let restored = flash::restore_records(&mut store, config::ADAPTIVE.as_ref()).await;
    report(&restored);
    send_booted(restored);
    let mut failures = hter::persist::StoreFailures::NEW;
    loop {
        #[cfg(feature = "interface")]
        if let Either::Second(since_s) = select(WAKE.wait(), HISTORY.wait()).await {
            stream_history(&mut log, since_s).await;
        }
        #[cfg(not(feature = "interface"))]
        WAKE.wait().await;
        loop {
            // VDD now, not only at the last sample (up to 10 s old): a supply that has just
            // fallen under the PVD level closes the gate before this record, not after it. It is
            // not a sample for the gate's freshness (a stalled control loop still stops writes).
            let supply_ok = crate::board::supply_ok();
            let next = with_pending(|pending, gate| {
                let now = now_ms();
                if !supply_ok {
                    gate.note_supply(now, false);
                }
                pending.next(gate, now)
            });
            let Some(save) = next else { break };
            // A region the storage layer finds corrupt is erased once and the record written
            // again (what it held is lost either way): the control task then hands over again
            // what went with the records region and nothing stores on a cadence
            // ([`RECORDS_ERASED`]: the history and the calibration; the interface build's
            // settings and cabinet model). The interface build through the library's
            // `flash::write_or_erase`, which the virtual board runs too; the build without the
            // log in line (the library's form cost it 104 B of the 64 KiB, which the calibrated
            // module-sense build lacks).
            #[cfg(feature = "interface")]
            let result = {
                let (result, erased) = flash::write_or_erase(&mut store, &mut log, &save).await;
                match erased {
                    flash::Erased::Nothing => {}
                    flash::Erased::Log => warn!("persist: log corrupt, erased: the record begins again here"),
                    flash::Erased::Records => {
                        warn!("persist: records region corrupt, erased");
                        RECORDS_ERASED.store(true, core::sync::atomic::Ordering::Relaxed);
                    }
                }
                result
            };
            #[cfg(not(feature = "interface"))]
            let result = {
                let mut result = flash::write_record(&mut store, &save).await;
                if result == Err(flash::StoreError::Corrupted) {
                    warn!("persist: region corrupt, erasing it");
                    result = store.erase_all().await;
                    if result.is_ok() {
                        RECORDS_ERASED.store(true, core::sync::atomic::Ordering::Relaxed);
                        result = flash::write_record(&mut store, &save).await;
                    }
                }
                result
            };
            failures.note(&save, result.is_ok());
            FAILED_IN_A_ROW.store(failures.in_a_row(), core::sync::atomic::Ordering::Relaxed);
            match (result, save) {
                #[cfg(feature = "interface")]
                (Ok(()), Save::Log(LogEntry::Lost { t_s, entries })) => {
                    warn!(
                        "persist: {} log entries lost while writes waited, the newest at record time {} s",
                        entries, t_s
                    )
                }
                (Ok(()), Save::Log(_)) => {}
                (Ok(()), Save::Model(rec)) => info!("persist: model stored: theta={} k={}", rec.theta, rec.k),
                (Ok(()), Save::History(_) | Save::AlarmHistory(_)) => {
                    // It counts the boot's stops: RAM need not keep them for the next boot.
                    crate::failsafe::stops_stored();
                    info!("persist: history stored")
                }
                (Ok(()), Save::Settings(s)) => info!("persist: settings v{} stored", s.seq),
                (Ok(()), Save::Calibration(_)) => info!("persist: calibration stored"),
                #[cfg(feature = "interface")]
                (Ok(()), Save::Cabinet(rec)) => info!("persist: cabinet model stored: theta={} k={}", rec.theta, rec.k),
                (Err(e), _) => warn!("persist: store failed ({})", e),
            }
        }
    }
}

#[cfg(feature = "interface")]
/// Streams the log from record time `since_s` into [`HISTORY_PIPE`], then the final line.
async fn stream_history<F: NorFlash>(log: &mut LogStore<F, L4Ecc>, since_s: u32) {
    let send = async |bytes: &[u8]| {
        with_timeout(Duration::from_millis(HISTORY_STALL_MS), HISTORY_PIPE.write_all(bytes)).await.is_ok()
    };
    if !send(CSV_HEADER.as_bytes()).await || !send(b"\r\n").await {
        return;
    }
    let mut row = heapless::String::<80>::new();
    let mut stalled = false;
    let walked = log
        .for_each(since_s, async |e: &LogEntry| {
            row.clear();
            let _ = write_csv_row(e, &mut row);
            let _ = row.push_str("\r\n");
            stalled = !send(row.as_bytes()).await;
            !stalled
        })
        .await;
    if stalled {
        warn!("history: the host stopped reading; stream dropped");
        return;
    }
    let end: &[u8] = match walked {
        Ok(_) => b"ok\r\n",
        Err(_) => b"err history: the log could not be read\r\n",
    };
    send(end).await;
}
