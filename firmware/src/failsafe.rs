//! The board's stop paths: the panic handler, HardFault, NMI, the default handler of every
//! interrupt without one, and the control-stall check. Each drives the outputs safe first
//! ([`board::force_safe`], registers only), then records why in [`RECORDS`] (RAM the runtime
//! leaves alone, so it survives the reset) and resets; the next boot reads it ([`boot_stops`]) and
//! the persist task lets it go once the history that counts it is in flash ([`stops_stored`]).
//!
//! A stack overflow is a HardFault: [`arm_stack_guard`] makes memory.x's `.stack_guard`, between
//! the statics and the stack, an MPU region no code may touch, and the HardFault entry
//! (`hter::hard_fault_entry!`) runs the stop path from the top of the stack when the fault left
//! the stack pointer near the guard.
//!
//! One exception returns: an NMI raised by an uncorrectable flash ECC error inside the
//! persistence region (a double-word whose programming a power cut interrupted). Its address
//! goes to [`crate::ecc`], the error is cleared, and the read that hit it carries on with garbage
//! the flash reader then discards, so the boot goes on with that page treated as lost.

use core::mem::MaybeUninit;
use core::panic::PanicInfo;
use core::ptr::addr_of_mut;

use cortex_m_rt::exception;
use embassy_stm32::pac::FLASH;
use hter::failsafe::{self, ResetRecords, SafeOutputs, StopInfo, StopKind, Stops};

use crate::board;

/// The stops the flash does not have yet and the boot's phase, across a reset. `.uninit` is
/// neither zeroed nor initialised by cortex-m-rt, so after a power-up it holds noise, which the
/// records' magic and CRC reject.
#[link_section = ".uninit.RECORDS"]
static mut RECORDS: MaybeUninit<ResetRecords> = MaybeUninit::uninit();

/// The records in [`RECORDS`].
///
/// # Safety
/// One context at a time uses the reference: the boot's thread (main, then the control task
/// until its loop runs), the persist task in a critical section ([`stops_stored`]), or a stop
/// path. A stop path can preempt one of the others (an NMI or a HardFault, which no critical
/// section holds off) while it holds its reference; two then exist by the letter, but the
/// preempted one is never used again: a stop path does not return, it resets. (The same holds
/// of the stop record before it, 2026-12-06.)
unsafe fn records() -> &'static mut ResetRecords {
    // SAFETY: ResetRecords is `repr(C)` words and bytes, so any bit pattern is a valid value;
    // exclusivity is the caller's promise.
    unsafe { (*addr_of_mut!(RECORDS)).assume_init_mut() }
}

/// The board's outputs behind the library's seam.
struct BoardOutputs;

impl SafeOutputs for BoardOutputs {
    /// Out of line: `cargo xtask audit --features buck` finds it by name and checks that it
    /// reaches TIM1's gates (inlined into the one `halt`, it was no symbol of its own).
    #[inline(never)]
    fn force_safe(&mut self) {
        board::force_safe();
    }
}

/// Why a stop path stops: what its reason is built from once the outputs are safe.
enum Why<'a> {
    /// The control loop stalled for this many ms.
    Stall(u32),
    /// A panic at this file and line (`None`: no location). Not the `PanicInfo` itself: handed
    /// out of line, its message would keep `core::fmt` linked (several KiB of flash).
    Panic(Option<(&'a str, u32)>),
    /// A HardFault and the stack pointer it left, the stacked frame's address (the frame and
    /// the fault registers are read in [`halt`]).
    HardFault(u32),
    /// An NMI with FLASH_ECCR's value (0: another source).
    Nmi(u32),
    /// An interrupt without a handler.
    Interrupt(i16),
}

/// Outputs safe, then the reason built from `why`, recorded, then reset. One copy for every stop
/// path (one `failsafe::stop` with the reasons in one match; a closure per path instantiated it
/// five times).
#[inline(never)]
fn halt(why: Why) -> ! {
    // SAFETY: this path does not return, and a fault inside it escalates to a lockup, which the
    // watchdog resets: no second holder of the record runs after this one.
    failsafe::stop(&mut BoardOutputs, unsafe { records() }, || match why {
        Why::Stall(since_ms) => StopInfo::new(StopKind::ControlStall, 0, 0, since_ms),
        // Records the location only: formatting the message would link `core::fmt` (several KiB
        // of flash, and calls through formatting arguments that leave the audit's stack bound
        // unproven) into a binary at its budget. defmt's own panics (`unwrap!`,
        // `defmt::assert!`) have already logged their message over RTT when they get here.
        Why::Panic(at) => match at {
            Some((file, line)) => failsafe::panic_info(file, line),
            None => StopInfo::new(StopKind::Panic, 0, 0, 0),
        },
        // SAFETY: the HardFault handler's `sp`, as its entry passed it.
        Why::HardFault(sp) => unsafe { failsafe::hard_fault_record(sp) },
        // cortex-m-rt hands the NMI no exception frame: the PC is not recorded (0); FLASH_ECCR
        // (or 0 for another source such as the clock security system) names the cause.
        Why::Nmi(eccr) => failsafe::nmi_info(0, eccr),
        Why::Interrupt(irqn) => failsafe::unexpected_interrupt_info(irqn),
    });
    cortex_m::peripheral::SCB::sys_reset()
}

/// The stops the last reset came from that the flash does not have yet: the record a stop path
/// left, one before it the boot before did not store, or a boot the watchdog reset before its
/// control loop ([`ResetRecords::boot`]). They stay in RAM until [`stops_stored`].
pub fn boot_stops(reset: hter::persist::ResetCause) -> Stops {
    // SAFETY: called once at boot, before the stall check is armed and before the persist task
    // runs; a fault meanwhile resets without returning here.
    unsafe { records() }.boot(reset)
}

/// Marks the boot as at `phase` until [`boot_done`]: a watchdog reset before then is the next
/// boot's stop.
pub fn note_boot(phase: failsafe::BootPhase) {
    // SAFETY: the boot's thread (main, then the control task before its stall check starts);
    // the phase word is written volatile by the library, and nothing else writes it.
    unsafe { records() }.enter(phase);
}

/// The control loop starts: the stall check and the watchdog watch it from now on. Feeds the
/// watchdog: unfed since `main` started it, its window ran from the boot's first instructions,
/// so after a slow boot (an LSE that starts late in the cold, a flash repair) it bit before the
/// stall check's 2·Ts and a hang in the first steps, with the marker already cleared, was a
/// bare watchdog reset: no stop on record. From here it has its whole window, more than the
/// stall check's (`config::IWDG_RELOAD`).
pub fn boot_done() {
    // SAFETY: as `note_boot`'s.
    unsafe { records() }.running();
    board::pet_watchdog();
}

/// A history that counts this boot's stops is in flash: RAM no longer keeps them (the persist
/// task, after each history it stores). In a critical section: the stall check's interrupt
/// runs a stop path, which must not find the records half cleared.
pub fn stops_stored() {
    // SAFETY: the stop paths that could also hold the records run in interrupts, which the
    // critical section holds off (a HardFault cannot be, but one here is a fault in two word
    // stores, and it resets without returning).
    cortex_m::interrupt::free(|_| unsafe { records() }.stored());
}

/// The control loop stalled for `since_ms` (called from the stall check's interrupt).
pub fn stall(since_ms: u32) -> ! {
    halt(Why::Stall(since_ms))
}

/// The reason records the location only ([`halt`]).
#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    halt(Why::Panic(info.location().map(|at| (at.file(), at.line()))))
}

/// Turns the stack guard on (`hter::failsafe::arm_stack_guard`): from here a stack overflow
/// faults into [`hard_fault`] instead of writing over the statics. The first thing `main` does.
pub fn arm_stack_guard() {
    let g = failsafe::stack_guard();
    // SAFETY: the guard is the linker's `.stack_guard` section, which holds nothing; nothing else
    // programs the MPU. A guard that is not one MPU region fails the audit.
    let armed = unsafe { failsafe::arm_stack_guard(g.start, g.end) };
    debug_assert!(armed);
}

// The HardFault vector: runs `hard_fault` from the top of the stack when the fault left the stack
// pointer within 1 KiB of the guard (the stop path's frames need well under that).
hter::hard_fault_entry!(hard_fault, 1024);

/// HardFault, after `hter::hard_fault_entry!`'s stack switch; `sp` is where the frame was stacked.
extern "C" fn hard_fault(sp: u32) -> ! {
    halt(Why::HardFault(sp))
}

/// Flash bank size of the STM32L476RG, bytes: FLASH_ECCR's ADDR_ECC is the offset within the
/// bank BK_ECC names (RM0351 "Flash ECC register"), with the banks not swapped (BFB2 = 0).
const BANK_SIZE: u32 = 0x8_0000;

#[exception]
unsafe fn NonMaskableInt() {
    let eccr = FLASH.eccr().read();
    if eccr.eccd() {
        let addr = board::FLASH_BASE + if eccr.bk_ecc() { BANK_SIZE } else { 0 } + eccr.addr_ecc();
        if board::PERSIST_ADDRESSES.contains(&addr) {
            // ECCD and ECCC are write-1-to-clear, and both are cleared (ECCIE kept): while
            // either is set the flash latches no new address (RM0351 "Error code correction":
            // "When ECCC or ECCD is set, ADDR_ECC and BK_ECC are not updated if a new ECC error
            // occurs"), so a corrected error left standing would name its own address for the
            // next double error, and the store would repair the wrong word.
            FLASH.eccr().write(|w| {
                w.set_eccd(true);
                w.set_eccc(true);
                w.set_eccie(eccr.eccie());
            });
            crate::ecc::note(addr);
            return;
        }
    }
    halt(Why::Nmi(if eccr.eccd() { eccr.0 } else { 0 }))
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) -> ! {
    halt(Why::Interrupt(irqn))
}
