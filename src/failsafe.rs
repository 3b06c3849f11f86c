//! What every path that stops the control loop does first, and what survives the reset after it.
//!
//! A panic, a HardFault, an NMI or any unexpected interrupt must leave the carrier in its *safe
//! outputs* — SSR drive low and its timer channel off, the supply-enable switch open, the alarm
//! on — before anything else can go wrong, then record why, then reset. The board-specific part
//! (which pins, how to reset) is behind [`SafeOutputs`]; the order and the record are here, so
//! the very same code runs in the firmware's handlers and on the processor-in-the-loop machine
//! (`cargo xtask pil` triggers a panic, a HardFault, an NMI, an unexpected interrupt and a
//! stack overflow into the stack guard (`arm_stack_guard`) there and checks each step, then
//! hangs a boot that read a stop until the emulated watchdog resets it, and checks that the next
//! boot has both: [`ResetRecords`]).
//!
//! The reason lives in a [`ReasonRecord`] of the [`ResetRecords`] that the glue places in RAM the
//! runtime neither zeroes nor initialises (`.uninit`): it survives a system reset (not a power
//! cycle). The next boot reads it ([`ResetRecords::boot`]) — a record whose magic or CRC is wrong
//! is noise from a power-up and is ignored — reports it as
//! [`crate::event::EventKind::BoardFault`] and counts it in the history, and it stays in RAM
//! until that history is in flash ([`ResetRecords::stored`]).
//!
//! Glossary: *stop* = any path that leaves the control loop for good (until reset); *PC* = the
//! program counter stacked by the exception entry; *CFSR/HFSR* = the Cortex-M fault status
//! registers (ARMv7-M ARM B3.2.15–16); *BFAR/MMFAR* = the faulting data address when valid.

use crate::persist::crc32;

/// The board's outputs driven to their safe state from any context (an exception handler, a
/// panic, the first instructions of `main`): SSR drive low with its timer channel off, the
/// supply-enable switch open, the alarm on.
///
/// Implementations write registers directly (no locks, no allocation, nothing that can block
/// or fault) and are idempotent: a second fault inside the first handler calls it again.
pub trait SafeOutputs {
    /// Drive every output to its safe level now.
    fn force_safe(&mut self);
}

/// Which path stopped the control loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum StopKind {
    /// A Rust panic (`detail` = source line, `text` = file and message as far as they fit).
    Panic = 1,
    /// A HardFault (or an escalated MemManage/BusFault/UsageFault): `pc` stacked, `addr` the
    /// faulting data address when the CPU latched one (else 0), `detail` = CFSR.
    HardFault = 2,
    /// An NMI not caused by the persistence region's flash ECC (clock security system, a
    /// double ECC error elsewhere in flash): `detail` = the source's status word.
    Nmi = 3,
    /// An interrupt without a handler fired (`detail` = its IRQ number as CMSIS counts it: the
    /// exception number − 16, so TIM7 on the L476 is 55, and a core exception such as SysTick
    /// is negative, −1, stored as a two's-complement word).
    UnexpectedInterrupt = 4,
    /// The control loop stopped making progress and the glue noticed before the watchdog did
    /// (`detail` = milliseconds since the last completed step); or a boot the watchdog reset
    /// before its control loop started ([`boot_stall`]: `detail` 0, `addr` the [`BootPhase`]).
    ControlStall = 5,
}

impl StopKind {
    /// Every kind, in code order.
    pub const ALL: [StopKind; 5] =
        [StopKind::Panic, StopKind::HardFault, StopKind::Nmi, StopKind::UnexpectedInterrupt, StopKind::ControlStall];

    /// The kind stored as `code`, if any.
    pub fn from_code(code: u8) -> Option<StopKind> {
        StopKind::ALL.into_iter().find(|k| *k as u8 == code)
    }

    /// Stable lower-case name for logs and CSV.
    pub fn name(self) -> &'static str {
        match self {
            StopKind::Panic => "panic",
            StopKind::HardFault => "hard_fault",
            StopKind::Nmi => "nmi",
            StopKind::UnexpectedInterrupt => "unexpected_interrupt",
            StopKind::ControlStall => "control_stall",
        }
    }
}

/// Sample periods without a completed step after which the glue's stall check stops cooling
/// and resets the board ([`StopKind::ControlStall`]): the firmware's `config::STALL_LIMIT_MS`,
/// and when the simulator's `board-fault-control-stall` stops its hung loop.
pub const STALL_SAMPLES: u32 = 2;

/// Bytes of text a [`StopInfo`] keeps (a panic's file and message, truncated).
pub const STOP_TEXT: usize = 48;

/// Why the board stopped: what a handler records and the next boot reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StopInfo {
    /// The path.
    pub kind: StopKind,
    /// Program counter of the faulting instruction (0 for a panic, which has no single one).
    pub pc: u32,
    /// Faulting data address, or 0 when none was latched.
    pub addr: u32,
    /// Kind-specific word: the panic's line, CFSR, the NMI source's status, the IRQ number.
    pub detail: u32,
    text: [u8; STOP_TEXT],
    text_len: u8,
}

impl StopInfo {
    /// A reason without text.
    pub const fn new(kind: StopKind, pc: u32, addr: u32, detail: u32) -> Self {
        StopInfo { kind, pc, addr, detail, text: [0; STOP_TEXT], text_len: 0 }
    }

    /// Appends `s` to the text, truncating at [`STOP_TEXT`] bytes. The text is ASCII: each byte
    /// of `s` outside it is kept as `?` (a panic's file and message are ASCII in this code; an
    /// ASCII check at the next boot is a few bytes of flash, where `core::str::from_utf8` linked
    /// ≈ 500 B for it).
    pub fn push_text(&mut self, s: &str) {
        self.push_bytes(s.as_bytes());
    }

    /// [`Self::push_text`] of bytes (a cut anywhere in a multi-byte character is fine).
    fn push_bytes(&mut self, s: &[u8]) {
        let at = usize::from(self.text_len);
        let room = self.text.get_mut(at..).unwrap_or(&mut []);
        let n = s.len().min(room.len());
        for (dst, src) in room.iter_mut().zip(s) {
            *dst = if src.is_ascii() { *src } else { b'?' };
        }
        self.text_len += n as u8;
    }

    /// The recorded text's bytes (ASCII; the board logs them without decoding).
    pub fn text_bytes(&self) -> &[u8] {
        self.text.get(..usize::from(self.text_len)).unwrap_or(&[])
    }

    /// The recorded text (empty if none).
    pub fn text(&self) -> &str {
        let bytes = self.text.get(..usize::from(self.text_len)).unwrap_or(&[]);
        core::str::from_utf8(bytes).unwrap_or("")
    }
}

/// For the host and the tests: the firmware's stop paths push their text with
/// [`StopInfo::push_text`] and link no `core::fmt`.
impl core::fmt::Write for StopInfo {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.push_text(s);
        Ok(())
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for StopInfo {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "{} pc={=u32:#010x} addr={=u32:#010x} detail={=u32:#x} {=[u8]:a}",
            self.kind,
            self.pc,
            self.addr,
            self.detail,
            self.text_bytes()
        )
    }
}

/// `"HTSR"`: a record written by [`ReasonRecord::write`].
const MAGIC: u32 = 0x5253_5448;
/// In a record's kind word, above the kind's code: a boot has reported it ([`Stops::fresh`]).
const SEEN: u32 = 1 << 8;

/// The reset-surviving record of a stop, laid out as plain words so that uninitialised RAM can
/// hold it: the glue declares one `static mut` in `.uninit` and never lets the runtime touch it.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct ReasonRecord {
    magic: u32,
    kind: u32,
    pc: u32,
    addr: u32,
    detail: u32,
    text_len: u32,
    text: [u8; STOP_TEXT],
    crc: u32,
}

impl ReasonRecord {
    /// An empty record.
    pub const EMPTY: ReasonRecord =
        ReasonRecord { magic: 0, kind: 0, pc: 0, addr: 0, detail: 0, text_len: 0, text: [0; STOP_TEXT], crc: 0 };

    /// The CRC of the record's bytes before `crc`, as they lie in memory: the six words
    /// little-endian (every target of this crate is), then the text. Read in place, not copied
    /// word by word into a buffer first (−112 B of the default firmware).
    fn crc(&self) -> u32 {
        const COVERED: usize = core::mem::offset_of!(ReasonRecord, crc);
        const _: () = assert!(COVERED == 24 + STOP_TEXT && cfg!(target_endian = "little"));
        // SAFETY: `repr(C)` words and bytes with no padding (the assertion above): the first
        // COVERED bytes of `self` are initialised and inside it.
        crc32(unsafe { core::slice::from_raw_parts((self as *const Self).cast::<u8>(), COVERED) })
    }

    /// Records `info` (replacing whatever was there).
    pub fn write(&mut self, info: &StopInfo) {
        *self = ReasonRecord {
            magic: MAGIC,
            kind: u32::from(info.kind as u8),
            pc: info.pc,
            addr: info.addr,
            detail: info.detail,
            text_len: u32::from(info.text_len),
            text: info.text,
            crc: 0,
        };
        self.crc = self.crc();
    }

    /// Marks a whole record as reported by a boot: [`SEEN`] in its kind word, the CRC written
    /// again. Whether it was whole and not yet marked ([`Stops::fresh`]).
    fn mark_seen(&mut self) -> bool {
        let fresh = self.intact() && self.kind & SEEN == 0;
        if fresh {
            self.kind |= SEEN;
            self.crc = self.crc();
        }
        fresh
    }

    /// Whether the record is whole: its magic and its CRC ([`Self::peek`] checks the fields
    /// too).
    #[inline(never)]
    fn intact(&self) -> bool {
        self.magic == MAGIC && self.crc == self.crc()
    }

    /// The recorded stop, if the record is intact (magic, CRC, kind and text length valid).
    #[inline(never)]
    pub fn peek(&self) -> Option<StopInfo> {
        if !self.intact() {
            return None;
        }
        let kind = StopKind::from_code(u8::try_from(self.kind & !SEEN).ok()?)?;
        let text_len = u8::try_from(self.text_len).ok().filter(|n| usize::from(*n) <= STOP_TEXT)?;
        // The text checked first and the reason built in the result: built first, it went through
        // a copy on the stack (−24 B of flash; out of line, as inlined into the boot's two calls
        // it cost 168 B more).
        if !self.text.get(..usize::from(text_len))?.is_ascii() {
            return None;
        }
        Some(StopInfo { kind, pc: self.pc, addr: self.addr, detail: self.detail, text: self.text, text_len })
    }
}

/// The first thing every stop path does: safe outputs, then the reason, then the record. The
/// caller resets afterwards (`SCB::sys_reset` on the board and the PIL machine).
///
/// The reason is built by `info` only once the outputs are safe: reading fault registers or
/// cutting a file name down costs little, but a fault in it must not find the SSR still driven.
/// The record (a CRC over 72 bytes) comes last and is written whole before the reset, so the
/// next boot can trust it ([`ResetRecords::record`]: a stop the flash does not have yet is kept
/// beside it). Returns what was recorded.
pub fn stop<O: SafeOutputs + ?Sized>(
    outputs: &mut O,
    records: &mut ResetRecords,
    info: impl FnOnce() -> StopInfo,
) -> StopInfo {
    outputs.force_safe();
    // Neither the reason's register reads nor the record's stores may be moved ahead of the
    // outputs' writes.
    core::sync::atomic::compiler_fence(core::sync::atomic::Ordering::SeqCst);
    let info = info();
    records.record(&info);
    info
}

/// The record of a panic at `file:line`: the line in `detail`, the file's last bytes in the
/// text (the end of a path names the module; its start is the same for every file).
pub fn panic_info(file: &str, line: u32) -> StopInfo {
    let mut info = StopInfo::new(StopKind::Panic, 0, 0, line);
    let from = file.len().saturating_sub(STOP_TEXT);
    info.push_bytes(file.as_bytes().get(from..).unwrap_or(&[]));
    info
}

/// How far a boot got on its way to the control loop. The glue keeps the phase in a
/// reset-surviving word ([`Self::marker`]) from right after it read the last reset's stops up
/// to the control-stall check's start: a boot that hangs there (in the clocks, in a flash
/// restore) before any stop path can notice is reset by the watchdog, and the next boot makes a
/// stop of it ([`ResetRecords::boot`]). Before, the bite was a watchdog reset and nothing more, and a
/// loop of them that hung before the history's store at every boot left nothing in the
/// cold-chain record, however long it lasted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum BootPhase {
    /// The board's set-up: the clocks and the peripherals.
    Board = 1,
    /// Restoring the flash records (scrub, repair, load).
    Restore = 2,
    /// Building the step from them, up to the control-stall check's start.
    Start = 3,
}

/// [`BootPhase::marker`]'s upper half: RAM's noise after a power-up is a marker by chance
/// once in 2³⁰, and then only a watchdog reset takes it for one.
const BOOT_MARK: u32 = 0xB007_0000;

impl BootPhase {
    /// Every phase, in order.
    pub const ALL: [BootPhase; 3] = [BootPhase::Board, BootPhase::Restore, BootPhase::Start];

    /// The word the glue keeps while the boot is in this phase (0 once the control loop runs).
    pub const fn marker(self) -> u32 {
        BOOT_MARK | self as u32
    }
}

/// The stop a boot that never reached its control loop leaves: a [`StopKind::ControlStall`]
/// (the persisted per-kind counts keep their layout) with `pc` 0, `addr` the phase and
/// `detail` 0 (a stall the glue notices is at least two sample periods: never 0 ms).
pub fn boot_stall(phase: BootPhase) -> StopInfo {
    StopInfo::new(StopKind::ControlStall, 0, phase as u32, 0)
}

/// The stops a boot found that the flash does not have yet ([`ResetRecords::boot`]), oldest
/// first: at most two, so that a stop and the hang or stop of the boot that took it are both
/// counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stops {
    /// A stop before [`Self::latest`] that an earlier boot took but did not store.
    pub earlier: Option<StopInfo>,
    /// The newest stop.
    pub latest: Option<StopInfo>,
    /// `latest` is the last reset's own (a stop path's record, or the hang a watchdog reset
    /// ended): no boot reported it before. False for a stop an earlier boot already reported and
    /// did not get into flash (a person's reset in its first minute, a supply under the PVD
    /// level, a failed store): counted again, since the flash does not have it, but not the
    /// reason this boot started.
    pub fresh: bool,
}

impl Stops {
    /// Each stop, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &StopInfo> {
        self.earlier.iter().chain(self.latest.iter())
    }
}

/// What crosses a reset for the fail-safe (not a power cut): the stops the stored history does
/// not have yet, and how far the boot got ([`BootPhase`]). The glue keeps one in RAM the
/// runtime neither zeroes nor initialises (`.uninit`; after a power-up it is noise, which each
/// record's magic and CRC reject, and which a marker matches once in 2³⁰).
///
/// A stop stays here until the flash has it ([`Self::stored`]), not only until the next boot
/// reads it. Before, the boot cleared the record as it took it: a boot that then hung or
/// stopped before its history was stored (a hang in the flash restore, a fault in the first
/// steps, behind the write gate's minute) left the next boot only its own stop or hang, and the
/// first stop was in no record. Now the stop path that finds a stop not yet stored keeps it as
/// [`Stops::earlier`]'s before writing its own ([`Self::record`]), and a boot the watchdog reset
/// before its control loop is recorded the same way ([`Self::boot`]). A loop that stops faster
/// than it stores keeps the first and the newest stop.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct ResetRecords {
    /// The newest stop not yet stored (what the stop paths write).
    latest: ReasonRecord,
    /// The stop before it, when the stop path that wrote `latest` found it not yet stored.
    earlier: ReasonRecord,
    /// [`BootPhase::marker`] while the boot is on its way to the control loop, 0 once it runs.
    phase: u32,
}

impl ResetRecords {
    /// No stop, no boot under way.
    pub const EMPTY: ResetRecords =
        ResetRecords { latest: ReasonRecord::EMPTY, earlier: ReasonRecord::EMPTY, phase: 0 };

    /// Records `info` as the newest stop. A stop already there and not yet stored moves to
    /// [`Stops::earlier`] if that is free; if it is not, the oldest stays and `info` replaces the
    /// one between.
    pub fn record(&mut self, info: &StopInfo) {
        // Whole records, by their CRC, not their magic alone: a copy into `earlier` that a reset
        // or a nested stop path cut (an NMI preempting this one: the outer never resumes) has
        // the magic and not the CRC. Taken by its magic for a kept stop, it held the slot, and
        // the stop still whole in `latest` was written over: lost. The CRC is `write`'s own,
        // already on every stop path.
        if !self.earlier.intact() && self.latest.intact() {
            self.earlier = self.latest;
        }
        self.latest.write(info);
    }

    /// At boot, with the reset's cause: the stops the flash does not have yet, oldest first.
    /// After a watchdog reset, a boot left in one of its phases ([`Self::enter`]) had hung on
    /// its way to the control loop, where no stop path watches: it is recorded as a stop of its
    /// phase ([`boot_stall`]). After any other reset a phase left over is a boot a person reset
    /// (the reset button in its first second) or a power cut, not a hang. The stops stay until
    /// [`Self::stored`].
    pub fn boot(&mut self, reset: crate::persist::ResetCause) -> Stops {
        let marker = self.marker();
        if reset == crate::persist::ResetCause::Watchdog {
            if let Some(phase) = BootPhase::ALL.into_iter().find(|p| p.marker() == marker) {
                self.record(&boot_stall(phase));
            }
        }
        // `earlier` was a `latest` a boot reported, or the stop before a nested one: its mark
        // tells nothing, so it is not written.
        let fresh = self.latest.mark_seen();
        let stops = self.stops();
        // A whole record this firmware cannot read (another firmware's kind code) is no stop,
        // and so not the reset's own either (`&`, not `&&`: 8 B less flash).
        Stops { fresh: fresh & stops.latest.is_some(), ..stops }
    }

    /// The phase word as it is: a [`BootPhase::marker`] while a boot is on its way to its control
    /// loop (or was, when it was reset), 0 once the loop runs, noise after a power-up.
    pub fn marker(&self) -> u32 {
        // SAFETY: a read of this struct's own field; volatile because the word was written by
        // the boot before the reset, which the compiler cannot know about.
        unsafe { core::ptr::read_volatile(&self.phase) }
    }

    /// The stops held, oldest first, as they are (no phase read, nothing recorded or marked;
    /// [`Stops::fresh`] false).
    pub fn stops(&self) -> Stops {
        Stops { earlier: self.earlier.peek(), latest: self.latest.peek(), fresh: false }
    }

    /// The boot is now at `phase`, until [`Self::running`]: a watchdog reset before then is the
    /// next boot's stop. Volatile: the word is read only after the next reset, and the writes
    /// of two phases with nothing between them that reads it could otherwise be merged.
    pub fn enter(&mut self, phase: BootPhase) {
        // SAFETY: a write of this struct's own field.
        unsafe { core::ptr::write_volatile(&mut self.phase, phase.marker()) };
    }

    /// The control loop runs: from here the stall check and the watchdog watch it.
    pub fn running(&mut self) {
        // SAFETY: as `enter`'s.
        unsafe { core::ptr::write_volatile(&mut self.phase, 0) };
    }

    /// The history with this boot's stops is in flash: they are no longer kept. A reset between
    /// the store and this call counts them again at the next boot (once more rather than never),
    /// and so does a stop path that runs between its two stores (an NMI, which no critical
    /// section holds off: it keeps the stored `latest` as its `earlier`).
    pub fn stored(&mut self) {
        // The magic alone: a record without it is none ([`ReasonRecord::peek`]).
        self.earlier.magic = 0;
        self.latest.magic = 0;
    }
}

/// CFSR bit: BFAR holds a valid fault address (ARMv7-M ARM B3.2.15, BusFault status).
pub const CFSR_BFARVALID: u32 = 1 << 15;
/// CFSR bit: MMFAR holds a valid fault address (MemManage status).
pub const CFSR_MMARVALID: u32 = 1 << 7;

/// The record of a HardFault from the stacked PC and the fault status and address registers:
/// the data address is BFAR or MMFAR only when CFSR says the CPU latched it, else 0.
pub fn hard_fault_info(pc: u32, cfsr: u32, bfar: u32, mmfar: u32) -> StopInfo {
    let addr = if cfsr & CFSR_BFARVALID != 0 {
        bfar
    } else if cfsr & CFSR_MMARVALID != 0 {
        mmfar
    } else {
        0
    };
    StopInfo::new(StopKind::HardFault, pc, addr, cfsr)
}

/// CFSR bit: a MemManage fault on exception entry, while stacking the frame (ARMv7-M ARM
/// B3.2.15, MMFSR.MSTKERR). With the stack guard (`arm_stack_guard`) the guard is the only
/// region no code may touch, so this bit says the stack reached it.
pub const CFSR_MSTKERR: u32 = 1 << 4;

/// The text of a HardFault record that a stack overflow caused.
pub const STACK_OVERFLOW_TEXT: &str = "stack overflow";

/// The record of a HardFault, told apart from a stack overflow: `sp` is the stack pointer the
/// handler found (where the hardware stacked, or tried to stack, the frame), `guard` the stack
/// guard's addresses (`__stack_guard_start..__stack_guard_end`).
///
/// The stack overflowed when the frame could not be stacked (CFSR.MSTKERR), when the data
/// access that faulted was in the guard (MMARVALID and MMFAR in it) or when `sp` is below the
/// guard's end. Its record is a [`StopKind::HardFault`] (the persisted per-kind counts keep
/// their layout) with the text [`STACK_OVERFLOW_TEXT`], `pc` 0 when the frame was not stacked
/// (the stacked words are then the guard's old contents, not the fault's), `addr` MMFAR when
/// latched, else `sp`, and `detail` = CFSR. Any other fault is [`hard_fault_info`]'s.
pub fn fault_info(pc: u32, sp: u32, cfsr: u32, bfar: u32, mmfar: u32, guard: core::ops::Range<u32>) -> StopInfo {
    let latched = cfsr & CFSR_MMARVALID != 0;
    if cfsr & CFSR_MSTKERR == 0 && sp >= guard.end && !(latched && guard.contains(&mmfar)) {
        return hard_fault_info(pc, cfsr, bfar, mmfar);
    }
    let pc = if cfsr & CFSR_MSTKERR != 0 { 0 } else { pc };
    let mut info = StopInfo::new(StopKind::HardFault, pc, if latched { mmfar } else { sp }, cfsr);
    info.push_text(STACK_OVERFLOW_TEXT);
    info
}

/// MPU_RBAR and MPU_RASR (ARMv7-M ARM B3.5.9–10) of the stack guard `start..end`, MPU region 0:
/// no access at any privilege (AP = 0b000), execute-never, enabled. `None` unless the guard is
/// one MPU region: a power of two of at least 32 bytes, aligned to its size.
pub fn stack_guard_region(start: u32, end: u32) -> Option<(u32, u32)> {
    let size = end.checked_sub(start)?;
    if size < 32 || !size.is_power_of_two() || !start.is_multiple_of(size) {
        return None;
    }
    // RBAR: the base, VALID (bit 4) with REGION = 0 in bits 3:0.
    let rbar = start | 1 << 4;
    // RASR: XN (bit 28), AP = 0 (bits 26:24), SIZE = log2(size) − 1 (bits 5:1), ENABLE (bit 0).
    let rasr = 1 << 28 | (size.trailing_zeros() - 1) << 1 | 1;
    Some((rbar, rasr))
}

/// The stack guard's addresses: the linker's `.stack_guard` section (`__stack_guard_start` ..
/// `__stack_guard_end`, memory.x and pil/memory.x), which [`arm_stack_guard`] protects and
/// [`hard_fault_record`] tells an overflow by.
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub fn stack_guard() -> core::ops::Range<u32> {
    extern "C" {
        static __stack_guard_start: u8;
        static __stack_guard_end: u8;
    }
    // Only the symbols' addresses are taken.
    core::ptr::addr_of!(__stack_guard_start) as u32..core::ptr::addr_of!(__stack_guard_end) as u32
}

/// The record of the HardFault whose frame [`crate::hard_fault_entry!`] handed over at `sp`: CFSR, BFAR
/// and MMFAR from the System Control Block, the stacked PC (`sp` + 24), told apart from a stack
/// overflow against [`stack_guard`] ([`fault_info`]).
///
/// # Safety
/// Only from the HardFault handler, with the `sp` its entry passed (the MPU is off there, so the
/// frame reads even when it went into the guard).
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub unsafe fn hard_fault_record(sp: u32) -> StopInfo {
    const CFSR: *const u32 = 0xE000_ED28 as *const u32;
    const MMFAR: *const u32 = 0xE000_ED34 as *const u32;
    const BFAR: *const u32 = 0xE000_ED38 as *const u32;
    // SAFETY: the System Control Block's fault status and address registers (ARMv7-M ARM
    // B3.2.2), and the stacked frame's PC word, which the caller vouches for.
    let (cfsr, bfar, mmfar, pc) = unsafe {
        (
            core::ptr::read_volatile(CFSR),
            core::ptr::read_volatile(BFAR),
            core::ptr::read_volatile(MMFAR),
            core::ptr::read_volatile((sp + 24) as *const u32),
        )
    };
    fault_info(pc, sp, cfsr, bfar, mmfar, stack_guard())
}

/// MPU_CTRL of the stack guard: ENABLE and PRIVDEFENA (the default memory map everywhere but
/// the guard); HFNMIENA = 0, so the MPU is off in the HardFault and NMI handlers and in a
/// HardFault entered from an overflow the handler can still use the stack.
pub const MPU_CTRL_GUARD: u32 = 1 | 1 << 2;

/// Turns the stack guard on: MPU region 0 over `start..end` ([`stack_guard_region`]), the MPU on
/// with [`MPU_CTRL_GUARD`]. From then on a push into the guard faults (MemManage, escalated to
/// HardFault while MemManage is disabled, as on the board) instead of writing over the statics
/// below it. Returns `false` (and changes nothing) if the guard is not one MPU region.
///
/// # Safety
/// `start..end` must hold nothing the program uses (the linker's `.stack_guard` section), and
/// no other code may program the MPU.
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub unsafe fn arm_stack_guard(start: u32, end: u32) -> bool {
    let Some((rbar, rasr)) = stack_guard_region(start, end) else {
        return false;
    };
    const MPU_CTRL: *mut u32 = 0xE000_ED94 as *mut u32;
    const MPU_RBAR: *mut u32 = 0xE000_ED9C as *mut u32;
    const MPU_RASR: *mut u32 = 0xE000_EDA0 as *mut u32;
    // SAFETY: the MPU's registers (ARMv7-M ARM B3.5); RBAR's VALID bit selects region 0.
    unsafe {
        core::ptr::write_volatile(MPU_RBAR, rbar);
        core::ptr::write_volatile(MPU_RASR, rasr);
        core::ptr::write_volatile(MPU_CTRL, MPU_CTRL_GUARD);
        // The new map applies to the next access and instruction (B3.5.7).
        core::arch::asm!("dsb", "isb", options(nostack, preserves_flags));
    }
    true
}

/// Defines the `HardFault` vector (in place of cortex-m-rt's trampoline) for a program with the
/// stack guard: `$handler` is an `extern "C" fn(sp: u32) -> !` called with the stack pointer
/// the fault left (the stacked frame's address; the process stack's if the fault came from it).
///
/// If the main stack pointer is within `$room` bytes above `__stack_guard_end` (or below it: the
/// stack overflowed), the handler runs from the top of the stack (`_stack_start`) instead: the
/// overflowed stack is abandoned (the handler never returns) and the handler's frames do not
/// run down through the guard into the statics (the MPU is off in HardFault). No memory is read
/// here: the outputs are driven safe before the frame is.
#[macro_export]
macro_rules! hard_fault_entry {
    ($handler:path, $room:literal) => {
        core::arch::global_asm!(
            ".section .HardFault.user, \"ax\"",
            ".global HardFault",
            ".type HardFault,%function",
            ".thumb_func",
            "HardFault:",
            "tst lr, #4",
            "ite eq",
            "mrseq r0, MSP",
            "mrsne r0, PSP",
            "mrs r1, MSP",
            "ldr r2, =__stack_guard_end + {room}",
            "cmp r1, r2",
            "bhs 1f",
            "ldr r2, =_stack_start",
            "msr MSP, r2",
            "1:",
            "b {handler}",
            ".ltorg",
            ".size HardFault, . - HardFault",
            handler = sym $handler,
            room = const $room,
        );
    };
}

/// The record of an NMI the board could not recover from (`source` = the status word that
/// names it, e.g. FLASH_ECCR for an ECC error outside the persistence region).
pub fn nmi_info(pc: u32, source: u32) -> StopInfo {
    StopInfo::new(StopKind::Nmi, pc, 0, source)
}

/// The record of an interrupt that has no handler (`irqn` = its IRQ number as cortex-m-rt's
/// `DefaultHandler` receives it: the exception number − 16, negative for a core exception).
pub fn unexpected_interrupt_info(irqn: i16) -> StopInfo {
    StopInfo::new(StopKind::UnexpectedInterrupt, 0, 0, irqn as i32 as u32)
}

/// RCC_CSR's OBLRSTF (RM0351, RCC_CSR bit 25): the reset was the option-byte loader's.
pub const CSR_OBLRSTF: u32 = 1 << 25;

/// Whether the boot should program the brown-out level into the option bytes (which reloads them
/// and resets the chip): the level is below the one the board needs, the supply is above the
/// PVD level (a write cut by a brown-out can leave the option bytes inconsistent), and this boot
/// is not the reset that very load caused (`csr` is RCC_CSR as read at boot, [`CSR_OBLRSTF`]).
/// After a load that did not take (option bytes write-protected, a programming error), trying
/// again at every boot would be a boot loop that never cools and writes the option bytes each
/// time; the board runs at the level it has and the boot log says so.
pub fn bor_needs_programming(level: u8, needed: u8, supply_ok: bool, csr: u32) -> bool {
    level < needed && supply_ok && csr & CSR_OBLRSTF == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::persist::ResetCause;
    use core::fmt::Write;

    /// Flips bit `bit` of the record's words.
    fn flip(rec: &mut ReasonRecord, bit: usize) {
        // SAFETY: ReasonRecord is repr(C) plain words and bytes; any bit pattern is valid.
        let w = unsafe { &mut *(rec as *mut ReasonRecord as *mut [u32; 19]) };
        w[bit / 32] ^= 1 << (bit % 32);
    }

    /// A boot's marker is the next boot's stop after a watchdog reset only, named by its phase;
    /// the loop's start (0) and noise are no marker.
    #[test]
    fn a_boot_the_watchdog_reset_before_its_loop_is_a_stop_of_its_phase() {
        for phase in BootPhase::ALL {
            let mut r = ResetRecords::EMPTY;
            r.enter(phase);
            let stop = r.boot(ResetCause::Watchdog).latest.unwrap_or_else(|| panic!("{phase:?}"));
            assert_eq!((stop.kind, stop.pc, stop.addr, stop.detail), (StopKind::ControlStall, 0, phase as u32, 0));
            assert_eq!(stop, boot_stall(phase));
            for reset in [ResetCause::BrownOut, ResetCause::Other] {
                let mut r = ResetRecords::EMPTY;
                r.enter(phase);
                assert_eq!(r.boot(reset), Stops::default(), "{phase:?} {reset:?}");
            }
        }
        for word in [0, 0xB007_0000, 0xB007_0004, 0x0007_0002, 0xFFFF_FFFF] {
            let mut r = ResetRecords { phase: word, ..ResetRecords::EMPTY };
            assert_eq!(r.boot(ResetCause::Watchdog), Stops::default(), "{word:#x}");
        }
        let mut r = ResetRecords::EMPTY;
        r.enter(BootPhase::Start);
        r.running();
        assert_eq!(r.boot(ResetCause::Watchdog), Stops::default(), "a bite in the loop is the stall check's");
        // A stall the check noticed is another stop than a boot's.
        assert_ne!(boot_stall(BootPhase::Start), StopInfo::new(StopKind::ControlStall, 0, 0, 20_000));
    }

    /// A stop stays until the history has it: every boot before the store finds it again, and
    /// the hang or the stop of a boot that took it is kept beside it, not instead of it.
    #[test]
    fn a_stop_is_kept_until_stored_and_the_next_one_beside_it() {
        let panic = panic_info("src/persist.rs", 12);
        let fault = hard_fault_info(0x0800_1234, 0x8200, 0, 0);
        let mut r = ResetRecords::EMPTY;
        r.record(&panic);
        // The boot that took it is reset by a person before its store: the panic again, no
        // longer the reason the board started.
        for (reset, fresh) in [(ResetCause::Other, true), (ResetCause::Other, false), (ResetCause::BrownOut, false)] {
            r.enter(BootPhase::Restore);
            assert_eq!(r.boot(reset), Stops { earlier: None, latest: Some(panic), fresh }, "{reset:?}");
        }
        // That boot hangs in its restore: the panic and the hang.
        r.enter(BootPhase::Restore);
        let both = r.boot(ResetCause::Watchdog);
        assert_eq!(both, Stops { earlier: Some(panic), latest: Some(boot_stall(BootPhase::Restore)), fresh: true });
        assert_eq!(both.iter().copied().collect::<Vec<_>>(), [panic, boot_stall(BootPhase::Restore)]);
        // The next one faults in its first steps: the oldest stays, the newest replaces the hang.
        r.running();
        r.record(&fault);
        assert_eq!(r.boot(ResetCause::Other), Stops { earlier: Some(panic), latest: Some(fault), fresh: true });
        assert_eq!(r.boot(ResetCause::Other), Stops { earlier: Some(panic), latest: Some(fault), fresh: false });
        // Stored: gone, and the next stop is alone again.
        r.stored();
        assert_eq!(r.boot(ResetCause::Other), Stops::default());
        r.record(&fault);
        assert_eq!(r.boot(ResetCause::Other), Stops { earlier: None, latest: Some(fault), fresh: true });
        // A stop after a store is not kept beside a stored one.
        let mut r = ResetRecords::EMPTY;
        r.record(&panic);
        r.stored();
        r.record(&fault);
        assert_eq!(r.boot(ResetCause::Other), Stops { earlier: None, latest: Some(fault), fresh: true });
    }

    /// Power-up noise in the whole struct is neither a stop nor a boot under way; a torn
    /// `earlier` (a reset in the middle of the stop path's copy) is none, the newest kept.
    #[test]
    fn noise_in_the_reset_records_is_no_stop() {
        let mut seed = 0x1234_5678u32;
        for _ in 0..2000 {
            let mut r = ResetRecords::EMPTY;
            let words = core::mem::size_of::<ResetRecords>() / 4;
            // SAFETY: ResetRecords is repr(C) plain words and bytes; any bit pattern is valid.
            let w = unsafe { core::slice::from_raw_parts_mut(&mut r as *mut ResetRecords as *mut u32, words) };
            for x in w.iter_mut() {
                seed ^= seed << 13;
                seed ^= seed >> 17;
                seed ^= seed << 5;
                *x = seed;
            }
            assert_eq!(r.boot(ResetCause::Watchdog), Stops::default());
        }
        let mut r = ResetRecords::EMPTY;
        r.record(&panic_info("a.rs", 1));
        r.record(&panic_info("b.rs", 2));
        r.earlier.crc ^= 1;
        assert_eq!(
            r.boot(ResetCause::Other),
            Stops { earlier: None, latest: Some(panic_info("b.rs", 2)), fresh: true }
        );
    }

    /// Found by fuzzing (`fuzz::arbitrary_reset_records_give_whole_stops_or_none`): a whole
    /// record this firmware cannot read (a kind code it does not know, as a newer firmware's
    /// stop path leaves it across a reset into this one; a text length beyond the text; text
    /// outside ASCII) was the reset's own stop, [`Stops::fresh`], with no stop there, and a
    /// technician's service reset after it was refused ([`crate::app::Boot::service_reset`]).
    #[test]
    fn a_whole_record_this_firmware_cannot_read_is_not_the_resets_stop() {
        for (kind, text_len, text) in [(6, 0, 0), (0, 0, 0), (1, STOP_TEXT as u32 + 1, 0), (1, 1, 0xC3)] {
            let mut r = ResetRecords::EMPTY;
            r.latest.write(&StopInfo::new(StopKind::Panic, 0, 0, 7));
            (r.latest.kind, r.latest.text_len, r.latest.text[0]) = (kind, text_len, text);
            r.latest.crc = r.latest.crc();
            assert_eq!(r.boot(ResetCause::Other), Stops::default(), "{kind} {text_len} {text}");
        }
    }

    /// A copy into `earlier` that a reset or a nested stop path cut (an NMI preempting a stop
    /// path, a watchdog bite in it) leaves the magic without the CRC: the next stop path must
    /// take the slot as free and keep the stop still whole in `latest`, not write over it.
    #[test]
    fn a_cut_copy_into_earlier_does_not_cost_the_newest_stop() {
        let (a, b) = (panic_info("a.rs", 1), panic_info("b.rs", 2));
        for cut_after_words in [1, 5, 18] {
            let mut r = ResetRecords::EMPTY;
            r.record(&a);
            // The next stop path's `earlier = latest`, cut after its first words.
            let words = core::mem::size_of::<ReasonRecord>() / 4;
            // SAFETY: ReasonRecord is repr(C) plain words and bytes; any bit pattern is valid.
            let (src, dst) = unsafe {
                (
                    core::slice::from_raw_parts(&r.latest as *const ReasonRecord as *const u32, words).to_vec(),
                    core::slice::from_raw_parts_mut(&mut r.earlier as *mut ReasonRecord as *mut u32, words),
                )
            };
            dst[..cut_after_words].copy_from_slice(&src[..cut_after_words]);
            assert_eq!(
                r.boot(ResetCause::Other),
                Stops { earlier: None, latest: Some(a), fresh: true },
                "{cut_after_words}"
            );
            r.record(&b);
            let both = Stops { earlier: Some(a), latest: Some(b), fresh: true };
            assert_eq!(r.boot(ResetCause::Other), both, "{cut_after_words}");
        }
    }

    /// Stamps each step of a stop path with the next number of a shared counter.
    struct Pins<'a> {
        seq: &'a core::cell::Cell<u32>,
        safe_at: Option<u32>,
    }

    fn next(seq: &core::cell::Cell<u32>) -> u32 {
        seq.set(seq.get() + 1);
        seq.get()
    }

    impl SafeOutputs for Pins<'_> {
        fn force_safe(&mut self) {
            self.safe_at = Some(next(self.seq));
        }
    }

    #[test]
    fn stop_drives_the_outputs_then_builds_the_reason_then_records() {
        let seq = core::cell::Cell::new(0);
        let mut pins = Pins { seq: &seq, safe_at: None };
        let mut rec = ResetRecords::EMPTY;
        let mut built_at = None;
        let mut want = StopInfo::new(StopKind::Panic, 0, 0, 42);
        write!(want, "src/step.rs: index out of bounds").unwrap();
        let got = stop(&mut pins, &mut rec, || {
            built_at = Some(next(&seq));
            want
        });
        assert_eq!((pins.safe_at, built_at), (Some(1), Some(2)), "outputs safe before the reason is built");
        assert_eq!(got, want);
        let found = rec.boot(ResetCause::Other).latest.unwrap();
        assert_eq!(found, want);
        assert_eq!(found.text(), "src/step.rs: index out of bounds");
        rec.stored();
        assert_eq!(rec.boot(ResetCause::Other), Stops::default(), "a stop is counted until stored");
    }

    #[test]
    fn noise_is_not_a_record() {
        // Power-up RAM: anything. Every single-bit flip of a good record is rejected too.
        let mut rec = ReasonRecord::EMPTY;
        assert_eq!(rec.peek(), None);
        rec.write(&StopInfo::new(StopKind::HardFault, 0x0800_1234, 0x2001_8000, 0x0000_8200));
        let words = core::mem::size_of::<ReasonRecord>() / 4;
        for bit in 0..words * 32 {
            let mut r = rec;
            flip(&mut r, bit);
            assert_eq!(r.peek(), None, "flip of bit {bit} accepted");
        }
    }

    #[test]
    fn text_is_ascii_and_truncated() {
        let mut info = StopInfo::new(StopKind::Panic, 0, 0, 1);
        info.push_text("x = é");
        assert_eq!(info.text(), "x = ??", "each byte outside ASCII kept as ?");
        info.push_text(&"é".repeat(40)); // 80 bytes of 2-byte chars
        assert_eq!(info.text().len(), STOP_TEXT);
        assert_eq!(&info.text()[..8], "x = ????");
        info.push_text("more");
        assert_eq!(info.text().len(), STOP_TEXT);
        // A record whose text is not ASCII (one written by hand; the CRC is right) is no record.
        let mut r = ReasonRecord::EMPTY;
        r.write(&StopInfo::new(StopKind::Panic, 0, 0, 7));
        r.text[0] = 0xC3;
        r.text_len = 1;
        r.crc = r.crc();
        assert_eq!(r.peek(), None);
        r.text[0] = b'A';
        r.crc = r.crc();
        assert_eq!(r.peek().map(|i| i.detail), Some(7));
    }

    /// The brown-out level is programmed once: not below the PVD level, not when it is already
    /// high enough, and not again on the reset its own option-byte load caused (a load that did
    /// not take looped the boot for ever, never cooling).
    #[test]
    fn the_brown_out_level_is_programmed_once() {
        const PIN_RESET: u32 = 1 << 26;
        assert!(bor_needs_programming(0, 3, true, PIN_RESET));
        assert!(!bor_needs_programming(0, 3, false, PIN_RESET), "supply below the PVD level");
        assert!(!bor_needs_programming(3, 3, true, PIN_RESET) && !bor_needs_programming(4, 3, true, 0));
        assert!(!bor_needs_programming(0, 3, true, CSR_OBLRSTF | PIN_RESET), "after its own load");
    }

    #[test]
    fn fault_address_only_when_latched() {
        let bus = hard_fault_info(0x0800_0100, CFSR_BFARVALID | 0x200, 0x6000_0000, 0x1234);
        assert_eq!((bus.pc, bus.addr, bus.kind), (0x0800_0100, 0x6000_0000, StopKind::HardFault));
        assert_eq!(hard_fault_info(1, CFSR_MMARVALID, 2, 3).addr, 3);
        assert_eq!(hard_fault_info(1, 0x0001_0000, 2, 3).addr, 0, "UNDEFINSTR has no address");
        let p = panic_info("/home/builder/.cargo/registry/src/index.crates.io/nalgebra-0.35.0/src/base/matrix.rs", 77);
        assert_eq!(p.detail, 77);
        assert!(p.text().ends_with("src/base/matrix.rs") && p.text().len() <= STOP_TEXT, "{}", p.text());
        assert_eq!(panic_info("src/step.rs", 9).text(), "src/step.rs");
        // A path cut inside a character keeps the rest, its bytes outside ASCII as ?.
        let long = format!("é{}/x.rs", "d".repeat(STOP_TEXT - 6));
        assert_eq!(panic_info(&long, 1).text(), format!("?{}/x.rs", "d".repeat(STOP_TEXT - 6)));
        assert_eq!(unexpected_interrupt_info(-1).detail, u32::MAX);
    }

    /// A stack overflow is told apart from other HardFaults by CFSR.MSTKERR, by a faulting
    /// address in the guard or by the stack pointer below the guard's end; anything else keeps
    /// `hard_fault_info`'s record. CFSR values as QEMU's Cortex-M4 (mps2-an386) latched them.
    #[test]
    fn a_stack_overflow_is_a_hard_fault_with_its_own_text() {
        let guard = 0x2000_0400..0x2000_0800;
        // The PIL's overflow: DACCVIOL + MMARVALID at the guard's top word, then MSTKERR.
        let o = fault_info(0x1234, 0x2000_07e0, 0x92, 0, 0x2000_07fc, guard.clone());
        assert_eq!((o.kind, o.pc, o.addr, o.detail), (StopKind::HardFault, 0, 0x2000_07fc, 0x92));
        assert_eq!(o.text(), STACK_OVERFLOW_TEXT);
        // The frame stacked (no MSTKERR) but the access was in the guard: the PC is the fault's.
        let o = fault_info(0x1234, 0x2000_0900, 0x82, 0, 0x2000_0500, guard.clone());
        assert_eq!((o.pc, o.addr, o.text()), (0x1234, 0x2000_0500, STACK_OVERFLOW_TEXT));
        // The stack pointer below the guard's end, nothing latched: its address is the record's.
        let o = fault_info(0x1234, 0x2000_0300, 0x400, 0, 0, guard.clone());
        assert_eq!((o.pc, o.addr, o.text()), (0x1234, 0x2000_0300, STACK_OVERFLOW_TEXT));
        // A bus fault with the stack well above the guard is an ordinary HardFault.
        let b = fault_info(0x1234, 0x2001_7f00, CFSR_BFARVALID | 0x200, 0xF000_0000, 0, guard.clone());
        assert_eq!(b, hard_fault_info(0x1234, CFSR_BFARVALID | 0x200, 0xF000_0000, 0));
        assert_eq!(b.text(), "");
        // A MemManage at an address outside the guard (MMARVALID) is not an overflow either.
        assert_eq!(fault_info(1, 0x2001_7f00, 0x82, 0, 0x2000_0000, guard).text(), "");
    }

    /// The guard's MPU region against ARMv7-M ARM B3.5.9–10: 1 KiB at 0x2000_2c00 is misaligned,
    /// at 0x2000_2800 it is RBAR 0x2000_2810, RASR XN | SIZE 9 | ENABLE.
    #[test]
    fn the_guard_is_one_no_access_mpu_region() {
        assert_eq!(stack_guard_region(0x2000_2800, 0x2000_2c00), Some((0x2000_2810, 0x1000_0013)));
        assert_eq!(stack_guard_region(0x2000_0000, 0x2000_0020), Some((0x2000_0010, 0x1000_0009)));
        assert_eq!(stack_guard_region(0x2000_2c00, 0x2000_3000).map(|r| r.0), Some(0x2000_2c10));
        assert_eq!(stack_guard_region(0x2000_2a00, 0x2000_2e00), None, "not aligned to its size");
        assert_eq!(stack_guard_region(0x2000_0000, 0x2000_0010), None, "below the MPU's 32 bytes");
        assert_eq!(stack_guard_region(0x2000_0000, 0x2000_0060), None, "not a power of two");
        assert_eq!(stack_guard_region(0x2000_0400, 0x2000_0000), None);
        assert_eq!(MPU_CTRL_GUARD & 0b111, 0b101, "ENABLE, PRIVDEFENA, not HFNMIENA");
    }

    #[test]
    fn kinds_round_trip() {
        for k in StopKind::ALL {
            assert_eq!(StopKind::from_code(k as u8), Some(k));
        }
        assert_eq!(StopKind::from_code(0), None);
        assert_eq!(core::mem::size_of::<ReasonRecord>(), 19 * 4);
        // The CRC read in place covers the words little-endian, then the text, as a copy would.
        let mut r = ReasonRecord::EMPTY;
        r.write(&panic_info("src/step.rs", 417));
        let mut bytes = std::vec::Vec::new();
        for w in [r.magic, r.kind, r.pc, r.addr, r.detail, r.text_len] {
            bytes.extend_from_slice(&w.to_le_bytes());
        }
        bytes.extend_from_slice(&r.text);
        assert_eq!(r.crc, crc32(&bytes));
    }

    /// Fuzzing what a boot reads in `.uninit`: [`ResetRecords`] of arbitrary bytes (power-up
    /// noise), with whole records, records whose CRC is right over arbitrary fields, a lone magic
    /// or a boot phase's marker planted in them. Whatever the bytes, for every reset cause:
    /// nothing panics; every stop a boot or [`ResetRecords::stops`] returns is a whole record
    /// (its magic and CRC right) with a known kind and ASCII text within [`STOP_TEXT`]; a boot
    /// invents no stop but a watchdog-reset boot's phase; a stop reported as the reset's own is
    /// there; once [`ResetRecords::stored`], a boot finds none; after [`ResetRecords::record`] of
    /// `x`, the next boot finds `x` as its newest, the stop it kept before it as the earlier.
    mod fuzz {
        use super::*;
        use proptest::collection::vec;
        use proptest::prelude::*;
        use proptest::sample::select;

        const SIZE: usize = core::mem::size_of::<ResetRecords>();
        const CAUSES: [ResetCause; 3] = [ResetCause::Watchdog, ResetCause::BrownOut, ResetCause::Other];

        /// The struct as `bytes` lie in RAM.
        fn from_bytes(bytes: &[u8]) -> ResetRecords {
            assert_eq!(bytes.len(), SIZE);
            let mut r = core::mem::MaybeUninit::<ResetRecords>::uninit();
            // SAFETY: ResetRecords is repr(C) words and bytes without padding: any SIZE bytes are
            // one.
            unsafe {
                core::ptr::copy_nonoverlapping(bytes.as_ptr(), r.as_mut_ptr().cast::<u8>(), SIZE);
                r.assume_init()
            }
        }

        /// A stop a stop path records: any kind and words, text of arbitrary bytes (kept as
        /// `push_text` keeps them).
        fn stop_info() -> impl Strategy<Value = StopInfo> {
            (select(StopKind::ALL.to_vec()), any::<[u32; 3]>(), vec(any::<u8>(), 0..=60)).prop_map(
                |(kind, [pc, addr, detail], text)| {
                    let mut info = StopInfo::new(kind, pc, addr, detail);
                    info.push_bytes(&text);
                    info
                },
            )
        }

        /// What is planted in one record slot.
        #[derive(Clone, Debug)]
        enum Plant {
            /// Noise as it is.
            Noise,
            /// The magic alone.
            Magic,
            /// A record a stop path wrote, maybe seen by a boot.
            Whole(StopInfo, bool),
            /// A whole record with one bit flipped.
            Flipped(StopInfo, usize),
            /// The magic and the right CRC over arbitrary fields (a kind code this firmware
            /// does not know, a text length beyond the text, text outside ASCII).
            Framed { kind: u32, text_len: u32 },
        }

        fn plant() -> impl Strategy<Value = Plant> {
            let kind = prop_oneof![any::<u32>(), 0u32..8, (0u32..8).prop_map(|k| k | SEEN), Just(u32::MAX)];
            let text_len = prop_oneof![any::<u32>(), 0u32..=(STOP_TEXT as u32 + 2)];
            prop_oneof![
                Just(Plant::Noise),
                Just(Plant::Magic),
                (stop_info(), any::<bool>()).prop_map(|(i, seen)| Plant::Whole(i, seen)),
                (stop_info(), 0usize..19 * 32).prop_map(|(i, bit)| Plant::Flipped(i, bit)),
                (kind, text_len).prop_map(|(kind, text_len)| Plant::Framed { kind, text_len }),
            ]
        }

        fn apply(rec: &mut ReasonRecord, plant: &Plant) {
            match plant {
                Plant::Noise => {}
                Plant::Magic => rec.magic = MAGIC,
                Plant::Whole(info, seen) => {
                    rec.write(info);
                    if *seen {
                        rec.mark_seen();
                    }
                }
                Plant::Flipped(info, bit) => {
                    rec.write(info);
                    flip(rec, *bit);
                }
                Plant::Framed { kind, text_len } => {
                    rec.magic = MAGIC;
                    rec.kind = *kind;
                    rec.text_len = *text_len;
                    rec.crc = rec.crc();
                }
            }
        }

        /// Noise with plants in both slots and the phase word.
        fn records() -> impl Strategy<Value = ResetRecords> {
            let phase = prop_oneof![
                any::<u32>(),
                Just(0u32),
                select(BootPhase::ALL.to_vec()).prop_map(BootPhase::marker),
                (select(BootPhase::ALL.to_vec()), 0u32..32).prop_map(|(p, bit)| p.marker() ^ 1 << bit),
            ];
            (vec(any::<u8>(), SIZE), plant(), plant(), phase).prop_map(|(bytes, latest, earlier, phase)| {
                let mut r = from_bytes(&bytes);
                apply(&mut r.latest, &latest);
                apply(&mut r.earlier, &earlier);
                r.phase = phase;
                r
            })
        }

        /// `found` is the record `rec` holds, and a whole one with valid fields.
        fn whole(found: &Option<StopInfo>, rec: &ReasonRecord) -> Result<(), TestCaseError> {
            let Some(info) = found else { return Ok(()) };
            prop_assert!(rec.magic == MAGIC && rec.crc == rec.crc(), "{info:?} from a record not whole: {rec:?}");
            prop_assert_eq!(Some(*info), rec.peek());
            prop_assert!(StopKind::ALL.contains(&info.kind));
            prop_assert!(info.text_bytes().len() <= STOP_TEXT && info.text_bytes().is_ascii(), "{info:?}");
            prop_assert_eq!(info.text().len(), info.text_bytes().len());
            Ok(())
        }

        fn stops_whole(s: &Stops, r: &ResetRecords) -> Result<(), TestCaseError> {
            whole(&s.latest, &r.latest)?;
            whole(&s.earlier, &r.earlier)?;
            prop_assert!(!s.fresh || s.latest.is_some(), "the reset's own stop is not there: {s:?}");
            Ok(())
        }

        /// What `record` keeps as the earlier stop: the one there if whole, else the newest if
        /// whole (and peeked, as a boot reads it).
        fn kept_earlier(r: &ResetRecords) -> Option<StopInfo> {
            if r.earlier.intact() {
                r.earlier.peek()
            } else if r.latest.intact() {
                r.latest.peek()
            } else {
                None
            }
        }

        fn check(ram: &ResetRecords, x: &StopInfo) -> Result<(), TestCaseError> {
            stops_whole(&ram.stops(), ram)?;
            for cause in CAUSES {
                let mut r = *ram;
                let stall = BootPhase::ALL.into_iter().find(|p| p.marker() == ram.phase);
                let s = r.boot(cause);
                stops_whole(&s, &r)?;
                match stall {
                    Some(p) if cause == ResetCause::Watchdog => {
                        prop_assert_eq!(s.latest, Some(boot_stall(p)));
                        prop_assert!(s.fresh);
                        prop_assert_eq!(s.earlier, kept_earlier(ram));
                    }
                    // No stop but the ones held: noise is none unless its magic and CRC match.
                    _ => prop_assert_eq!((s.earlier, s.latest), (ram.earlier.peek(), ram.latest.peek()), "{:?}", cause),
                }
                // A boot the next reset interrupts: the same stops, no longer the reset's own.
                r.enter(BootPhase::Start);
                r.running();
                let again = r.boot(cause);
                prop_assert_eq!(again, Stops { fresh: false, ..s });
                // A stop path: its stop is the next boot's newest, the one it kept the earlier.
                let mut after = r;
                let earlier = kept_earlier(&after);
                after.record(x);
                let found = after.boot(cause);
                stops_whole(&found, &after)?;
                prop_assert_eq!(found, Stops { earlier, latest: Some(*x), fresh: true });
                // Stored: nothing is found again.
                for mut r in [r, after] {
                    r.stored();
                    prop_assert_eq!(r.boot(cause), Stops::default());
                    prop_assert_eq!(r.stops(), Stops::default());
                }
            }
            Ok(())
        }

        proptest! {
            #![proptest_config(ProptestConfig { cases: 1_000, ..ProptestConfig::default() })]
            #[test]
            fn arbitrary_reset_records_give_whole_stops_or_none(ram in records(), x in stop_info()) {
                check(&ram, &x)?;
            }

            /// Power-up noise alone: no stop after any reset, and no boot under way unless the
            /// phase word is one of the three markers (3 words in 2³², the documented "once in
            /// 2³⁰"), and then only after a watchdog reset.
            #[test]
            fn power_up_noise_is_no_stop(bytes in vec(any::<u8>(), SIZE)) {
                let ram = from_bytes(&bytes);
                for cause in CAUSES {
                    let mut r = ram;
                    let marker = BootPhase::ALL.iter().any(|p| p.marker() == ram.phase);
                    if !(marker && cause == ResetCause::Watchdog) {
                        prop_assert_eq!(r.boot(cause), Stops::default(), "{:?}", cause);
                    }
                }
            }
        }

        proptest! {
            #![proptest_config(ProptestConfig { cases: 1_000_000, ..ProptestConfig::default() })]
            #[test]
            #[ignore = "many cases: CI runs it in release with `-- --ignored`"]
            fn arbitrary_reset_records_give_whole_stops_or_none_long(ram in records(), x in stop_info()) {
                check(&ram, &x)?;
            }
        }
    }
}
