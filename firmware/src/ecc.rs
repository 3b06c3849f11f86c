//! The one word the NMI handler and the flash reader share: the address of the last flash
//! double-word whose read raised an uncorrectable ECC error (ECCD in FLASH_ECCR, which the L4
//! signals through the NMI, RM0351 §3.3.8 "Error code correction").
//!
//! The NMI handler (`failsafe.rs`) stores the address here and clears ECCD when it lies in the
//! persistence region, so the read returns (with garbage data) instead of hanging the boot; the
//! flash reader (`persist.rs`) takes it after every read and turns it into a read error, and the
//! store treats that page as lost.

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::pac::FLASH;

/// No ECC error pending.
const NONE: u32 = u32::MAX;

static ECC_ADDR: AtomicU32 = AtomicU32::new(NONE);

/// Records an ECC error at absolute flash address `addr` (called from the NMI handler).
pub fn note(addr: u32) {
    ECC_ADDR.store(addr, Ordering::SeqCst);
}

/// The pending ECC error's absolute flash address, if any, clearing it. Also clears a corrected
/// single error (ECCC) the read left behind: while it stands, FLASH_ECCR keeps its address and
/// latches none for a later double error (RM0351 "Error code correction"), so the NMI handler
/// would name the corrected word instead of the torn one (a torn write leaves single errors too).
pub fn take() -> Option<u32> {
    let eccr = FLASH.eccr().read();
    if eccr.eccc() {
        // Write-1-to-clear; ECCD written 0 (the NMI handler owns it), ECCIE kept.
        FLASH.eccr().write(|w| {
            w.set_eccc(true);
            w.set_eccie(eccr.eccie());
        });
    }
    match ECC_ADDR.swap(NONE, Ordering::SeqCst) {
        NONE => None,
        addr => Some(addr),
    }
}
