//! The fail-safe paths on the emulated Cortex-M4F: a panic, a HardFault, an NMI and an
//! unexpected interrupt, each through the firmware's own library code
//! ([`hter::failsafe::stop`] and the `*_info` constructors), each followed by a real system
//! reset (`SCB::sys_reset`, SYSRESETREQ), and each reported by the next boot.
//!
//! QEMU's mps2-an386 resets the whole machine on SYSRESETREQ and starts again at the reset
//! vector; its RAM keeps its contents, so the `.uninit` statics below (which no ELF segment
//! covers once `cargo xtask pil` boots the flash image as a raw binary) cross the reset. A boot
//! counter with its own magic sequences the boots:
//!
//! 1. reports nothing, panics (an out-of-bounds index);
//! 2. reports the panic, reads an unmapped address (a precise BusFault, escalated to HardFault);
//! 3. reports the HardFault, pends the NMI (ICSR.NMIPENDSET);
//! 4. reports the NMI, pends an enabled interrupt that has no handler (`DefaultHandler`);
//! 5. reports it, fills a canary below the stack guard and recurses until the stack overflows
//!    into the guard (MPU region 0, armed at every boot as the firmware arms it);
//! 6. reports the overflow (a HardFault whose text is "stack overflow", the faulting address in
//!    the guard, the canary intact: nothing below the guard was written) and exits.
//!
//! The HardFault vector is the firmware's (`hter::hard_fault_entry!`): on an overflow the handler
//! runs from the top of the stack.
//!
//! Each report is one semihosting stdout line `failsafe boot=<n> ...` that xtask parses. The
//! safe-outputs hook stamps a sequence number and notes whether the reason record was already
//! written when it ran; the handler stamps another after `stop` returns, and checks the record.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use cortex_m::peripheral::SCB;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hprintln};
use hter::failsafe::{
    arm_stack_guard, hard_fault_record, nmi_info, panic_info, stack_guard, stop, unexpected_interrupt_info,
    ResetRecords, SafeOutputs, StopInfo,
};
use hter::persist::ResetCause;

/// `"HTBC"`: the boot log below holds a count from an earlier boot of this image.
const BOOT_MAGIC: u32 = 0x4342_5448;
/// An address no device or memory of mps2-an386 decodes (the vendor system region above the
/// PPB): a load there is a precise bus error.
const UNMAPPED: u32 = 0xF000_0000;
/// The interrupt pended in boot 4: line 0 has no handler in this image.
const SPARE_IRQ: u32 = 0;
/// Boots after which the runner gives up instead of faulting again (a stuck sequence must end).
const LAST_BOOT: u32 = 6;
/// The canary's pattern (boot 5).
const CANARY: u32 = 0x5AFE_C0DE;

/// What each boot leaves for the next, beside the reason record.
#[derive(Clone, Copy)]
#[repr(C)]
struct BootLog {
    magic: u32,
    boot: u32,
    /// Sequence counter of the current stop path (0 at boot).
    seq: u32,
    /// Stamp of the safe-outputs hook, 0 if it did not run.
    safe_seq: u32,
    /// Stamp taken when `stop` returned (the record written), 0 if it did not.
    record_seq: u32,
    /// Whether the reason record was already valid when the hook ran (it must not be).
    record_before_safe: u32,
    /// Whether the record read back valid, of the expected kind, right after `stop`.
    record_ok_after: u32,
    /// The "outputs": 1 once driven safe.
    outputs_safe: u32,
    /// Whether every word of [`CANARY_WORDS`] still held [`CANARY`] when the stop path ran.
    canary_ok: u32,
}

#[link_section = ".uninit.hter_reason"]
static mut REASON: MaybeUninit<ResetRecords> = MaybeUninit::uninit();
#[link_section = ".uninit.hter_bootlog"]
static mut LOG: MaybeUninit<BootLog> = MaybeUninit::uninit();
/// Statics below the guard that an overflow past it would overwrite (with the two above).
#[link_section = ".uninit.hter_canary"]
static mut CANARY_WORDS: MaybeUninit<[u32; 64]> = MaybeUninit::uninit();

fn canary() -> *mut [u32; 64] {
    addr_of_mut!(CANARY_WORDS).cast()
}

/// Calls itself until the stack overflows (a frame of 32 bytes of locals each time).
#[inline(never)]
fn recurse(depth: u32) -> u32 {
    let local = black_box([depth; 8]);
    if black_box(depth) == u32::MAX {
        return local[0];
    }
    recurse(depth + 1).wrapping_add(local[(depth & 7) as usize])
}

fn reason() -> *mut ResetRecords {
    // Only the address is taken; every access is volatile, since the contents come from a
    // previous boot and the compiler must not assume the (absent) initialiser.
    addr_of_mut!(REASON).cast()
}

fn log() -> *mut BootLog {
    addr_of_mut!(LOG).cast()
}

fn read_log() -> BootLog {
    // SAFETY: `LOG` is ours alone (single core, handlers never nest with `main` here); any bit
    // pattern is a valid `BootLog` (plain words).
    unsafe { read_volatile(log()) }
}

fn write_log(l: BootLog) {
    // SAFETY: as in `read_log`.
    unsafe { write_volatile(log(), l) }
}

/// The PIL machine's outputs: a word of RAM stands for the SSR, switch and alarm pins.
struct PilOutputs;

impl SafeOutputs for PilOutputs {
    fn force_safe(&mut self) {
        let mut l = read_log();
        l.seq += 1;
        l.safe_seq = l.seq;
        // The record's magic is its first word: if `stop` wrote the record before calling the
        // hook, the record would already be valid here.
        // SAFETY: a volatile read of the record's memory while `stop` holds no write to it yet.
        let rec = unsafe { read_volatile(reason()) };
        l.record_before_safe = u32::from(rec.stops().latest.is_some());
        l.outputs_safe = 1;
        // SAFETY: a volatile read of the canary (noise outside boot 5, where it is not checked).
        let c = unsafe { read_volatile(canary()) };
        l.canary_ok = u32::from(c.iter().all(|w| *w == CANARY));
        write_log(l);
    }
}

/// The firmware's stop path with the PIL's outputs, then the checks of the order, then reset.
/// The boot cleared the stop's log fields, so the hook's stamp is the first of this path.
fn fail(info: impl FnOnce() -> StopInfo) -> ! {
    // SAFETY: the record's memory is ours; the hook reads it only through volatile loads.
    let info = stop(&mut PilOutputs, unsafe { &mut *reason() }, info);
    let mut l = read_log();
    l.seq += 1;
    l.record_seq = l.seq;
    // SAFETY: as above.
    let back = unsafe { read_volatile(reason()) }.stops().latest;
    l.record_ok_after = u32::from(back.is_some_and(|b| b.kind == info.kind));
    write_log(l);
    SCB::sys_reset()
}

#[entry]
fn main() -> ! {
    let g = stack_guard();
    // SAFETY: the guard is pil/memory.x's `.stack_guard`, which holds nothing.
    let armed = unsafe { arm_stack_guard(g.start, g.end) };
    let prev = read_log();
    let boot = if prev.magic == BOOT_MAGIC { prev.boot.saturating_add(1) } else { 1 };
    // SAFETY: the record's memory is ours. This runner has no flash: the report stands for the
    // board's stored history, so the stop is let go once read and each is reported once.
    let found = unsafe {
        let mut rec = read_volatile(reason());
        let found = rec.boot(ResetCause::Other).latest;
        rec.stored();
        write_volatile(reason(), rec);
        found
    };
    // A system reset clears the sticky fault status and the interrupt enables; a jump back to
    // the reset vector would not.
    // SAFETY: reads of system control block and NVIC registers.
    let (cfsr, iser0) = unsafe { (read_volatile(CFSR), read_volatile(NVIC_ISER0)) };
    report(boot, cfsr, iser0, armed, &prev, found.as_ref());
    write_log(BootLog {
        magic: BOOT_MAGIC,
        boot,
        seq: 0,
        safe_seq: 0,
        record_seq: 0,
        record_before_safe: 0,
        record_ok_after: 0,
        outputs_safe: 0,
        canary_ok: 0,
    });
    match boot {
        1 => {
            let v = [1u32, 2, 3];
            let i = black_box(7usize);
            black_box(v[i]);
        }
        2 => {
            // SAFETY: deliberately faults: nothing is mapped at `UNMAPPED`.
            black_box(unsafe { read_volatile(UNMAPPED as *const u32) });
        }
        3 => {
            // SAFETY: ICSR.NMIPENDSET (bit 31; ARMv7-M ARM B3.2.4) pends the NMI; other bits
            // written as 0 have no effect.
            unsafe { write_volatile(ICSR as *mut u32, 1 << 31) };
            cortex_m::asm::isb();
        }
        4 => {
            // SAFETY: enables one interrupt line whose vector is the runtime's default.
            unsafe {
                write_volatile(NVIC_ISER0 as *mut u32, 1 << SPARE_IRQ);
                write_volatile(NVIC_ISPR0, 1 << SPARE_IRQ);
            }
            cortex_m::asm::isb();
        }
        5 => {
            // SAFETY: the canary is this runner's alone.
            unsafe { write_volatile(canary(), [CANARY; 64]) };
            black_box(recurse(black_box(0)));
        }
        _ => {}
    }
    if boot < LAST_BOOT {
        hprintln!("failsafe boot={} error=the trigger did not stop the boot", boot);
        debug::exit(debug::EXIT_FAILURE);
    } else {
        debug::exit(debug::EXIT_SUCCESS);
    }
    #[allow(clippy::empty_loop)]
    loop {}
}

/// One line per boot: what the previous boot's stop path left behind.
fn report(boot: u32, cfsr: u32, iser0: u32, armed: bool, prev: &BootLog, found: Option<&StopInfo>) {
    let g = stack_guard();
    match found {
        None => hprintln!(
            "failsafe boot={} cfsr={:#x} iser0={:#x} guard={:#010x}-{:#010x} armed={} reason=none",
            boot,
            cfsr,
            iser0,
            g.start,
            g.end,
            u32::from(armed)
        ),
        Some(r) => hprintln!(
            "failsafe boot={} cfsr={:#x} iser0={:#x} guard={:#010x}-{:#010x} armed={} reason={} pc={:#010x} addr={:#010x} detail={:#x} safe_seq={} record_seq={} record_before_safe={} record_ok_after={} outputs_safe={} canary_ok={} text={}",
            boot,
            cfsr,
            iser0,
            g.start,
            g.end,
            u32::from(armed),
            r.kind.name(),
            r.pc,
            r.addr,
            r.detail,
            prev.safe_seq,
            prev.record_seq,
            prev.record_before_safe,
            prev.record_ok_after,
            prev.outputs_safe,
            prev.canary_ok,
            r.text()
        ),
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    let (file, line) = info.location().map(|l| (l.file(), l.line())).unwrap_or(("", 0));
    fail(|| panic_info(file, line))
}

/// SCB fault status register and interrupt control and state register (ARMv7-M ARM B3.2.4, B3.2.15).
const CFSR: *const u32 = 0xE000_ED28 as *const u32;
const ICSR: *const u32 = 0xE000_ED04 as *const u32;
/// NVIC set-enable and set-pending registers of lines 0–31 (ARMv7-M ARM B3.4.4, B3.4.6).
const NVIC_ISER0: *const u32 = 0xE000_E100 as *const u32;
const NVIC_ISPR0: *mut u32 = 0xE000_E200 as *mut u32;

// The firmware's HardFault entry: from the top of the stack when the fault left it near the guard.
hter::hard_fault_entry!(hard_fault, 1024);

extern "C" fn hard_fault(sp: u32) -> ! {
    // SAFETY: the HardFault handler's `sp`, as its entry passed it.
    fail(|| unsafe { hard_fault_record(sp) })
}

#[exception]
unsafe fn NonMaskableInt() {
    // ICSR: its VECTACTIVE field (2 in the NMI) says which exception this is; the board passes
    // the NMI source's status word here instead.
    // SAFETY: a read of a system control block register.
    fail(|| nmi_info(0, unsafe { read_volatile(ICSR) }))
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    fail(|| unexpected_interrupt_info(irqn))
}
