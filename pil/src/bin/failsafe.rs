//! The fail-safe paths on the emulated Cortex-M4F: a panic, a HardFault, an NMI and an
//! unexpected interrupt, each through the firmware's own library code
//! ([`hter::failsafe::stop`] and the `*_info` constructors), each followed by a real system
//! reset (`SCB::sys_reset`, SYSRESETREQ), and each reported by the next boot; then a boot that
//! read a stop, hangs before it "stores" it and is reset by a real watchdog: the next boot makes
//! a stop of the hang and still has the first beside it ([`hter::failsafe::ResetRecords`]); then
//! a boot that read a stop and, before it "stores" it, stops on a real stop path: the next boot
//! has the new stop and the first beside it, and once that boot lets them go, none.
//!
//! QEMU's mps2-an386 resets the whole machine on SYSRESETREQ and starts again at the reset
//! vector; its RAM keeps its contents, so the `.uninit` statics below cross the reset (their ELF
//! segment has no file bytes, and QEMU's loader neither writes nor zeroes such a segment, at
//! load or at a reset: xtask's `failsafe` module says where). A boot counter with its own magic
//! sequences the boots:
//!
//! 1. reports nothing, panics (an out-of-bounds index);
//! 2. reports the panic, reads an unmapped address (a precise BusFault, escalated to HardFault);
//! 3. reports the HardFault, pends the NMI (ICSR.NMIPENDSET);
//! 4. reports the NMI, pends an enabled interrupt that has no handler (`DefaultHandler`);
//! 5. reports it, fills a canary below the stack guard and recurses until the stack overflows
//!    into the guard (MPU region 0, armed at every boot as the firmware arms it);
//! 6. reports the overflow (a HardFault whose text is "stack overflow", the faulting address in
//!    the guard, the canary intact: nothing below the guard was written), marks its phase as
//!    the firmware's flash restore ([`BootPhase::Restore`], the word the firmware's `note_boot`
//!    writes), arms the board's CMSDK watchdog with a short timeout and hangs. The watchdog's
//!    first timeout raises its interrupt, which on this board is the NMI: the NMI handler tells
//!    it from a genuine NMI by WDOGMIS and returns (the board's IWDG has no early interrupt),
//!    and the second timeout resets the machine. It has not let the overflow go (every other
//!    boot but 8 does once it has reported, as the board does once its history is in flash);
//! 7. reports the watchdog's reset: the phase marker found, what the firmware's rule makes of
//!    it after a watchdog reset (a `control_stall` of phase 2, with the overflow kept beside it
//!    as the earlier stop) and after any other (the overflow alone, no stall), lets them go and
//!    panics (as boot 1);
//! 8. reports the panic (alone: boot 7 let the hang's two go) and does not let it go (as a
//!    board's boot that stops before its history is stored), then reads the unmapped address
//!    (as boot 2): the HardFault's stop path ([`ResetRecords::record`]) finds the panic reported
//!    and not stored in the newest record and keeps it as the earlier one before writing its own;
//! 9. reports both: the HardFault as the newest stop, fresh (the reason it started), and the
//!    panic beside it, each whole with its own fields (a second line, `failsafe-earlier`, has the
//!    earlier stop's fields as the first line has the newest's); lets them go and resets with a
//!    bare SYSRESETREQ, no stop path;
//! 10. reports no stop, newest or earlier (what boot 9 let go does not come back), then exits.
//!
//! The HardFault vector is the firmware's (`hter::hard_fault_entry!`): on an overflow the handler
//! runs from the top of the stack.
//!
//! Each report is one semihosting stdout line `failsafe boot=<n> ...` that xtask parses. The
//! safe-outputs hook stamps a sequence number and notes whether the reason record was already
//! written when it ran; the handler stamps another after `stop` returns, and checks the record.
//! `reason`, `fresh` and `earlier` are what the firmware's `boot_stops` returns
//! ([`ResetRecords::boot`]): the newest stop (a stop path's record, or the stop made of a phase
//! marker after a watchdog reset), whether no boot reported it before, and one before it not yet
//! let go, whose fields follow on a line of their own. The hook's check that it ran first
//! compares the records with what the boot left in them (a stop it had not let go, at boot 8),
//! not with no stop.
//!
//! The PIL machine has no reset-cause register (the board's RCC_CSR), so each boot derives the
//! cause from what it sees ([`reset_cause`]): the previous boot armed the watchdog and its
//! interrupt came, no stop path ran (the boot log's stamps), and the watchdog reads back its
//! reset state.
//! Once armed, boot 6 runs only its hang loop, and every way out of it but one (the watchdog's
//! interrupt, which returns) is a stop path that records before it resets; a semihosting exit
//! ends QEMU and leaves no next boot; and only a machine reset puts the watchdog's control
//! register back to 0 (a jump to the reset vector would leave it armed). So a boot that sees
//! all of that was reset by the watchdog.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};

use cortex_m::peripheral::SCB;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hprint, hprintln};
use hter::failsafe::{
    arm_stack_guard, hard_fault_record, nmi_info, panic_info, stack_guard, stop, unexpected_interrupt_info, BootPhase,
    ResetRecords, SafeOutputs, StopInfo, Stops,
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
const LAST_BOOT: u32 = 10;
/// The boots that report a stop and do not let it go before they stop: 6 hangs, 8 faults.
const UNSTORED: [u32; 2] = [6, 8];
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
    /// Whether the records already held other stops than the boot left in them ([`LEFT`]) when
    /// the hook ran (the stop path wrote before the outputs were safe: it must not).
    record_before_safe: u32,
    /// Whether the record read back valid, of the expected kind, right after `stop`.
    record_ok_after: u32,
    /// The "outputs": 1 once driven safe.
    outputs_safe: u32,
    /// Whether every word of [`CANARY_WORDS`] still held [`CANARY`] when the stop path ran.
    canary_ok: u32,
    /// 1 once boot 6 armed the watchdog, just before its hang.
    wdog_armed: u32,
    /// How many times the NMI handler passed over the watchdog's interrupt.
    wdog_nmi: u32,
}

/// The stops not yet "stored" and the boot's phase word, as the firmware's `RECORDS`.
#[link_section = ".uninit.hter_records"]
static mut RECORDS: MaybeUninit<ResetRecords> = MaybeUninit::uninit();
#[link_section = ".uninit.hter_bootlog"]
static mut LOG: MaybeUninit<BootLog> = MaybeUninit::uninit();
/// The stops this boot left in the records, for the safe-outputs hook: written by `main` before
/// any trigger, read by the hook only (a plain static: the runtime sets it at every boot).
static mut LEFT: Stops = Stops { earlier: None, latest: None, fresh: false };
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
    addr_of_mut!(RECORDS).cast()
}

fn log() -> *mut BootLog {
    addr_of_mut!(LOG).cast()
}

/// The records as the last boot left them (the stops not yet "stored" and the phase word).
fn last_records() -> ResetRecords {
    // SAFETY: the records' memory is ours; nothing else runs at boot. Any bit pattern is valid.
    unsafe { read_volatile(reason()) }
}

/// Writes the records back for the next boot.
fn keep_records(r: ResetRecords) {
    // SAFETY: as in `last_records`.
    unsafe { write_volatile(reason(), r) }
}

fn read_log() -> BootLog {
    // SAFETY: `LOG` is ours alone (single core; the one handler that returns, the watchdog's
    // NMI, comes only once boot 6 hangs, past its last whole-log access); any bit pattern is a
    // valid `BootLog` (plain words).
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
        // hook, the records would already hold another stop than the boot left there (none, or
        // a stop it had not let go).
        // SAFETY: a volatile read of the record's memory while `stop` holds no write to it yet;
        // `LEFT` is written once by `main`, before any trigger.
        let (rec, left) = unsafe { (read_volatile(reason()), read_volatile(addr_of!(LEFT))) };
        l.record_before_safe = u32::from(rec.stops() != left);
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
    let before = last_records();
    // A system reset clears the sticky fault status, the interrupt enables and the watchdog's
    // control register; a jump back to the reset vector would not.
    // SAFETY: reads of system control block, NVIC and watchdog registers.
    let (cfsr, iser0, wdog_control) =
        unsafe { (read_volatile(CFSR), read_volatile(NVIC_ISER0), read_volatile(WDOGCONTROL)) };
    let reset = reset_cause(&prev, wdog_control);
    // What the firmware's `boot_stops` returns, and what the same records would give after a
    // reset that is not the watchdog's (a marker alone must be no stop then).
    let (mut records, mut other, mut brown_out) = (before, before, before);
    let last = LastBoot {
        reset,
        marker: before.marker(),
        wdog_control,
        stops: records.boot(reset),
        if_other: other.boot(ResetCause::Other).latest,
        if_brown_out: brown_out.boot(ResetCause::BrownOut).latest,
    };
    // This runner has no flash: the report stands for the board's stored history, so the stops
    // are let go once reported, except by boot 6, which reports the stack overflow and then hangs
    // in its "restore", before its store, as a board's boot can: its stop must reach boot 7
    // beside the hang; and by boot 8, which reports boot 7's panic and then faults before its
    // store: the panic must reach boot 9 beside the fault.
    if !UNSTORED.contains(&boot) {
        records.stored();
    }
    // This boot reached its "control loop": the marker is cleared, as the firmware's `boot_done`
    // clears it (the last boot leaves the word as a power-up would find it before it exits).
    records.running();
    keep_records(records);
    // SAFETY: no stop path has run in this boot yet: nothing else reads or writes `LEFT`.
    unsafe { write_volatile(addr_of_mut!(LEFT), records.stops()) };
    report(boot, cfsr, iser0, armed, &prev, &last);
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
        wdog_armed: 0,
        wdog_nmi: 0,
    });
    match boot {
        1 | 7 => {
            let v = [1u32, 2, 3];
            let i = black_box(7usize);
            black_box(v[i]);
        }
        2 | 8 => {
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
        6 => {
            // The firmware's boot in its flash restore, hung: the marker first, as `note_boot`
            // writes it before the phase's work, then the watchdog, then no more feeding.
            // SAFETY: the records are ours; nothing else holds them here.
            unsafe { (*reason()).enter(BootPhase::Restore) };
            arm_watchdog();
            // SAFETY: one word of the log, a single store: the watchdog's NMI, which writes
            // another word of it, cannot tear it.
            unsafe { addr_of_mut!((*log()).wdog_armed).write_volatile(1) };
            loop {
                core::hint::spin_loop();
            }
        }
        // Both stops reported and let go: a reset that is no stop path, so that boot 10 shows
        // what the records hold after a store.
        9 => SCB::sys_reset(),
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

/// What a boot made of the last one: the stops, as the firmware's `boot_stops` finds them, and
/// what they were found from.
struct LastBoot {
    /// The reset's cause as [`reset_cause`] derives it.
    reset: ResetCause,
    /// The phase word as the last boot left it.
    marker: u32,
    /// WDOGCONTROL at boot (0: the watchdog was reset with the machine).
    wdog_control: u32,
    /// [`ResetRecords::boot`] after `reset`.
    stops: Stops,
    /// The newest stop of the same records after a reset that is not the watchdog's: a marker
    /// alone must be no stop then.
    if_other: Option<StopInfo>,
    if_brown_out: Option<StopInfo>,
}

/// The reset's cause as far as this machine shows it (it has no RCC_CSR; the module docs say
/// why this is sound): the watchdog's if the previous boot armed it and its interrupt came, no
/// stop path ran (the safe-outputs hook and the record left no stamp: the records themselves
/// may hold a stop that boot read and had not let go), and the watchdog is back in its reset
/// state; otherwise [`ResetCause::Other`] (SYSRESETREQ, or QEMU's start).
fn reset_cause(prev: &BootLog, wdog_control: u32) -> ResetCause {
    let watched = prev.magic == BOOT_MAGIC && prev.wdog_armed == 1 && prev.wdog_nmi > 0;
    let stopped = prev.safe_seq != 0 || prev.record_seq != 0;
    if watched && !stopped && wdog_control == 0 {
        ResetCause::Watchdog
    } else {
        ResetCause::Other
    }
}

fn reset_name(r: ResetCause) -> &'static str {
    match r {
        ResetCause::Watchdog => "watchdog",
        ResetCause::BrownOut => "brown_out",
        ResetCause::Other => "other",
    }
}

fn stop_name(s: Option<&StopInfo>) -> &'static str {
    s.map_or("none", |s| s.kind.name())
}

/// One line per boot: what the previous boot's stop path, or its hang, left behind; a second
/// when the boot found an earlier stop beside the newest.
fn report(boot: u32, cfsr: u32, iser0: u32, armed: bool, prev: &BootLog, last: &LastBoot) {
    let g = stack_guard();
    hprint!(
        "failsafe boot={} cfsr={:#x} iser0={:#x} guard={:#010x}-{:#010x} armed={} reset={} marker={:#010x} wdog_armed={} wdog_nmi={} wdog_control={:#x} if_other={} if_brown_out={} fresh={} earlier={} ",
        boot,
        cfsr,
        iser0,
        g.start,
        g.end,
        u32::from(armed),
        reset_name(last.reset),
        last.marker,
        prev.wdog_armed,
        prev.wdog_nmi,
        last.wdog_control,
        stop_name(last.if_other.as_ref()),
        stop_name(last.if_brown_out.as_ref()),
        u32::from(last.stops.fresh),
        stop_name(last.stops.earlier.as_ref())
    );
    match &last.stops.latest {
        None => hprintln!("reason=none"),
        Some(r) => hprintln!(
            "reason={} pc={:#010x} addr={:#010x} detail={:#x} safe_seq={} record_seq={} record_before_safe={} record_ok_after={} outputs_safe={} canary_ok={} text={}",
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
    // The earlier stop's own fields, on a line of their own: its text, like the newest's, is
    // the rest of its line.
    if let Some(e) = &last.stops.earlier {
        hprintln!(
            "failsafe-earlier boot={} reason={} pc={:#010x} addr={:#010x} detail={:#x} text={}",
            boot,
            e.kind.name(),
            e.pc,
            e.addr,
            e.detail,
            e.text()
        );
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

/// mps2-an386's CMSDK APB watchdog (ARM DDI0479, "APB watchdog"): QEMU maps it at 0x4000_8000,
/// clocks it from the 25 MHz SYSCLK and wires its interrupt to the NMI (hw/arm/mps2.c). Its
/// counter runs down from WDOGLOAD; at zero it raises its interrupt and reloads, and at zero
/// again with the interrupt still raised it resets the machine, if RESEN is set.
const WDOGLOAD: *mut u32 = 0x4000_8000 as *mut u32;
/// INTEN (bit 0) runs the counter and enables the interrupt; RESEN (bit 1) enables the reset.
const WDOGCONTROL: *mut u32 = 0x4000_8008 as *mut u32;
/// The interrupt, raised and enabled (bit 0).
const WDOGMIS: *const u32 = 0x4000_8014 as *const u32;
/// Writes to the other registers are ignored unless this one was last written [`WDOG_UNLOCK`].
const WDOGLOCK: *mut u32 = 0x4000_8C00 as *mut u32;
const WDOG_UNLOCK: u32 = 0x1ACC_E551;
const WDOG_INTEN: u32 = 1 << 0;
const WDOG_RESEN: u32 = 1 << 1;
/// The watchdog's period, WDOGCLK ticks: 10 ms at 25 MHz, so the reset comes 20 ms of guest
/// time after boot 6 arms it (the first period raises the interrupt, the second resets). Short,
/// so the run stays well under a second; long against the few instructions boot 6 runs between
/// arming it and noting so in the log.
const WDOG_PERIOD_TICKS: u32 = 250_000;

/// Arms the watchdog for a reset two periods from now and locks it. INTEN too: the CMSDK
/// watchdog's counter runs only with it (QEMU 7.2 counts from the WDOGLOAD write whatever INTEN
/// says; QEMU's current source, like the part, only with INTEN), and its interrupt is what the
/// NMI handler must pass over.
fn arm_watchdog() {
    // SAFETY: writes to the watchdog's registers, which nothing else in this image programs.
    unsafe {
        write_volatile(WDOGLOCK, WDOG_UNLOCK);
        write_volatile(WDOGLOAD, WDOG_PERIOD_TICKS);
        write_volatile(WDOGCONTROL, WDOG_INTEN | WDOG_RESEN);
        write_volatile(WDOGLOCK, 0);
    }
}

/// Whether the NMI is the watchdog's first timeout (its interrupt raised and enabled).
fn watchdog_interrupt() -> bool {
    // SAFETY: a read of a watchdog status register, with no side effect.
    unsafe { read_volatile(WDOGMIS) & 1 != 0 }
}

/// Counts a watchdog interrupt the NMI handler passed over.
fn note_watchdog_interrupt() {
    // SAFETY: one word of the log; the NMI preempts everything else, and `main`, hung by then,
    // touches no word of it.
    unsafe {
        let n = addr_of_mut!((*log()).wdog_nmi);
        n.write_volatile(n.read_volatile().wrapping_add(1));
    }
}

// The firmware's HardFault entry: from the top of the stack when the fault left it near the guard.
hter::hard_fault_entry!(hard_fault, 1024);

extern "C" fn hard_fault(sp: u32) -> ! {
    // SAFETY: the HardFault handler's `sp`, as its entry passed it.
    fail(|| unsafe { hard_fault_record(sp) })
}

#[exception]
unsafe fn NonMaskableInt() {
    // The watchdog's first timeout is passed over, uncleared, so that its second one resets the
    // machine as the board's IWDG resets a hung boot (the IWDG has no early interrupt: the
    // firmware never sees one). A genuine NMI (boot 3's) finds WDOGMIS clear and stops.
    if watchdog_interrupt() {
        note_watchdog_interrupt();
        return;
    }
    // ICSR: its VECTACTIVE field (2 in the NMI) says which exception this is; the board passes
    // the NMI source's status word here instead.
    // SAFETY: a read of a system control block register.
    fail(|| nmi_info(0, unsafe { read_volatile(ICSR) }))
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    fail(|| unexpected_interrupt_info(irqn))
}
