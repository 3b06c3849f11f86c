//! The one word the NMI handler and the flash reader share: the address of the last flash
//! double-word whose read raised an uncorrectable ECC error (ECCD in FLASH_ECCR, which the L4
//! signals through the NMI, RM0351 §3.3.8 "Error code correction").
//!
//! The NMI handler (`failsafe.rs`) stores the address here and clears ECCD when it lies in the
//! persistence region, so the read returns (with garbage data) instead of hanging the boot; the
//! flash reader (`persist.rs`) takes it after every read and turns it into a read error, and the
//! store treats that page as lost.

use core::sync::atomic::{AtomicU32, Ordering};

/// No ECC error pending.
const NONE: u32 = u32::MAX;

static ECC_ADDR: AtomicU32 = AtomicU32::new(NONE);

/// Records an ECC error at absolute flash address `addr` (called from the NMI handler).
pub fn note(addr: u32) {
    ECC_ADDR.store(addr, Ordering::SeqCst);
}

/// The pending ECC error's absolute flash address, if any, clearing it.
pub fn take() -> Option<u32> {
    match ECC_ADDR.swap(NONE, Ordering::SeqCst) {
        NONE => None,
        addr => Some(addr),
    }
}
