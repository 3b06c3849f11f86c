//! `cargo xtask audit` — what the release firmware image itself must show for the board's own
//! failures to leave it safe and loud:
//!
//! - the NMI, HardFault and every other vector entry (the runtime's `DefaultHandler` serves
//!   every exception and interrupt nobody handles) lead somewhere other than a bare spin loop
//!   (`b .` after at most a frame-pointer prologue, or a `wfi`/`nop` loop): a spin there hangs
//!   the board with its outputs as they were;
//! - defmt-rtt cannot block: its `disable-blocking-mode` feature is on. The ELF does not show it
//!   (the up channel starts with the same non-blocking flags either way, and the host switches
//!   it to blocking at attach; the feature only removes the blocking branch from the code), so
//!   the feature is read from `cargo tree -e features` for the firmware's target;
//! - the programmed image (every loaded segment with file bytes in flash) ends in bank 1, and
//!   so does the linker's FLASH region in `memory.x` (it bounds what a larger build may use):
//!   bank 2 holds the persisted records, and read-while-write only holds between the banks.
//!
//! - the stack guard is in the image: `.stack_guard` (memory.x) is one MPU region (a power of two
//!   of at least 32 bytes, aligned to its size), above the statics (`.bss`, `.uninit` with the
//!   stop record and the RTT buffer) and below the lowest address the stack may use, so a stack
//!   that overflows faults in it before it reaches them (`hter::failsafe::arm_stack_guard`);
//! - the code reader those checks rest on (`crate::code`) reads every function of the image as
//!   llvm-objdump does: frame, calls, indirect calls;
//! - every stop path reaches the safe outputs: from the NMI, the HardFault, `DefaultHandler`, the
//!   panic handler and TIM7's vector (which must be the bound `TIM7` stall check, not the default
//!   handler), the image's direct calls and jumps lead to `BoardOutputs::force_safe`
//!   (`crate::code` decodes them); the HardFault path's deepest chain of frames fits the room its
//!   entry leaves above the guard, and the NMI's with its exception frame fits the guard (the MPU
//!   is off in both, so a deeper path would run through the guard into the statics);
//! - the whole stack is bounded: the thread's deepest chain from Reset through the executor and
//!   its deepest task, plus every handler's with its exception frame as if all nested, is
//!   within the stack, so the guard is never reached and a frame larger than the guard cannot
//!   step over it. Indirect calls go to any function whose address the image holds, a task poll
//!   only from the executor (embassy's run loop polls tasks; their own indirect calls are
//!   wakers); recursion, a frame of run-time size, a target with no symbol or a task poll the
//!   thread's walk never reaches (its call moved out of the executor's code) fail it. Every
//!   build is asked, the interface build too: its text protocol is written through
//!   `hter::iface::sink`, not `core::fmt`, whose `core::fmt::write` calls each argument's
//!   formatter through a pointer and can nest (a `Display` that formats again), a recursion the
//!   image cannot bound; an unbounded image that links `core::fmt::write` says so in its line.
//!
//! It prints one line per check and a final JSON line, and exits non-zero if any check fails.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};

/// STM32L476 flash: bank 1 is 0x0800_0000..0x0808_0000 (512 KiB), bank 2 follows (RM0351 §3.3.1).
const FLASH_START: u64 = 0x0800_0000;
const BANK2_START: u64 = 0x0808_0000;
const FLASH_END: u64 = 0x0810_0000;
/// Prologue and body instructions followed when deciding whether a handler only spins.
const MAX_INSNS: usize = 8;
const TARGET: &str = "thumbv7em-none-eabihf";

/// One audit line.
#[derive(Debug)]
pub struct Finding {
    pub key: &'static str,
    pub ok: bool,
    pub line: String,
}

/// USART2's entry in the STM32L476's vector table: the 16 core exceptions, then IRQ 38
/// (RM0351 table 58; stm32-metapac's `Interrupt::USART2 = 38`).
pub const USART2_VECTOR: usize = 16 + 38;

/// Audits the release firmware built with `features` (cargo's `--features` list, empty for the
/// default build). A build with `interface` must also have USART2's handler bound.
pub fn audit(features: &str) -> Result<()> {
    let root = super::root();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(&cargo);
    cmd.current_dir(&root).args(["build", "--release", "-p", "firmware", "--target", TARGET]);
    if !features.is_empty() {
        cmd.args(["--features", features]);
    }
    let status = cmd.status().context("running cargo")?;
    if !status.success() {
        bail!("building the release firmware failed");
    }
    let path = super::target_dir().join(TARGET).join("release").join("firmware");
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let elf = Elf::parse(&bytes).with_context(|| format!("parsing {}", path.display()))?;
    let mut findings = handler_findings(&elf)?;
    findings.push(rtt_finding(&elf, &cargo, &root)?);
    findings.push(image_finding(&elf));
    findings.push(region_finding(&root.join("memory.x"))?);
    findings.push(stack_guard_finding(&elf));
    findings.push(decoder_finding(&elf, &path));
    findings.extend(stop_path_findings(&elf)?);
    findings.push(stack_bound_finding(&elf));
    if features.split([',', ' ']).any(|f| f == "interface" || f == "serial") {
        findings.push(usart2_finding(&elf)?);
    }
    if features.split([',', ' ']).any(|f| f == "buck") {
        findings.push(buck_safe_finding(&elf));
    }
    println!("audit of {}", path.display());
    for f in &findings {
        println!("  {:<22} {:<4} {}", f.key, if f.ok { "ok" } else { "FAIL" }, f.line);
    }
    let json: Vec<String> = findings.iter().map(|f| format!("\"{}\": {}", f.key, f.ok)).collect();
    println!("{{\"audit\": {{{}}}}}", json.join(", "));
    if let Some(bad) = findings.iter().find(|f| !f.ok) {
        bail!("audit failed: {}: {}", bad.key, bad.line);
    }
    Ok(())
}

/// The parts of a little-endian ELF32 image the audit reads.
#[derive(Debug, Default)]
pub struct Elf<'a> {
    bytes: &'a [u8],
    sections: Vec<Section>,
    segments: Vec<Segment>,
    /// (name, value, size).
    symbols: Vec<(String, u64, u64)>,
}

#[derive(Debug, Clone)]
pub struct Section {
    pub name: String,
    pub ty: u64,
    pub flags: u64,
    pub addr: u64,
    pub offset: u64,
    pub size: u64,
}

#[derive(Debug, Clone, Copy)]
pub struct Segment {
    pub ty: u64,
    pub paddr: u64,
    pub filesz: u64,
}

const SHT_PROGBITS: u64 = 1;
const SHT_SYMTAB: u64 = 2;
const PT_LOAD: u64 = 1;

impl<'a> Elf<'a> {
    pub fn parse(bytes: &'a [u8]) -> Result<Self> {
        if bytes.get(..6) != Some(&[0x7f, b'E', b'L', b'F', 1, 1][..]) {
            bail!("not a little-endian ELF32 file");
        }
        let u16_at = |o: u64| -> Result<u64> { Ok(u64::from(u16::from_le_bytes(get(bytes, o, 2)?.try_into()?))) };
        let u32_at = |o: u64| -> Result<u64> { Ok(u64::from(u32::from_le_bytes(get(bytes, o, 4)?.try_into()?))) };
        let (phoff, shoff) = (u32_at(0x1c)?, u32_at(0x20)?);
        let (phentsize, phnum) = (u16_at(0x2a)?, u16_at(0x2c)?);
        let (shentsize, shnum, shstrndx) = (u16_at(0x2e)?, u16_at(0x30)?, u16_at(0x32)?);
        let mut segments = Vec::new();
        for i in 0..phnum {
            let ph = phoff + i * phentsize;
            segments.push(Segment { ty: u32_at(ph)?, paddr: u32_at(ph + 12)?, filesz: u32_at(ph + 16)? });
        }
        let mut raw = Vec::new();
        for i in 0..shnum {
            let sh = shoff + i * shentsize;
            raw.push((
                u32_at(sh)?,
                u32_at(sh + 4)?,
                u32_at(sh + 8)?,
                u32_at(sh + 12)?,
                u32_at(sh + 16)?,
                u32_at(sh + 20)?,
                u32_at(sh + 24)?,
            ));
        }
        let name_at = |table: u64, at: u64| -> Result<String> {
            let (_, _, _, _, off, size, _) = *raw.get(table as usize).context("string table index out of range")?;
            let s = get(bytes, off, size)?;
            let tail = s.get(at as usize..).context("name offset out of range")?;
            let end = tail.iter().position(|b| *b == 0).context("unterminated name")?;
            Ok(String::from_utf8_lossy(&tail[..end]).into_owned())
        };
        let mut sections = Vec::new();
        let mut symbols = Vec::new();
        for &(name, ty, flags, addr, offset, size, link) in &raw {
            sections.push(Section { name: name_at(shstrndx, name)?, ty, flags, addr, offset, size });
            if ty == SHT_SYMTAB {
                for k in 0..size / 16 {
                    let sym = offset + 16 * k;
                    let (st_name, value, size) = (u32_at(sym)?, u32_at(sym + 4)?, u32_at(sym + 8)?);
                    if st_name != 0 {
                        symbols.push((name_at(link, st_name)?, value, size));
                    }
                }
            }
        }
        Ok(Elf { bytes, sections, segments, symbols })
    }

    /// Flash (allocated sections with contents: what is programmed) and static RAM (allocated
    /// sections in SRAM at 0x2000_0000 and up: .data, .bss, .uninit), bytes.
    pub fn sizes(&self) -> (u64, u64) {
        const SHF_ALLOC: u64 = 2;
        const SHT_NOBITS: u64 = 8;
        let alloc = || self.sections.iter().filter(|s| s.flags & SHF_ALLOC != 0);
        let flash = alloc().filter(|s| s.ty != SHT_NOBITS).map(|s| s.size).sum();
        let ram = alloc().filter(|s| s.addr >= 0x2000_0000).map(|s| s.size).sum();
        (flash, ram)
    }

    /// `len` bytes at address `addr` of a section with contents.
    pub fn read(&self, addr: u64, len: u64) -> Option<&'a [u8]> {
        let s = self
            .sections
            .iter()
            .find(|s| s.ty == SHT_PROGBITS && s.addr != 0 && addr >= s.addr && addr + len <= s.addr + s.size)?;
        get(self.bytes, s.offset + (addr - s.addr), len).ok()
    }

    /// The section headers.
    pub fn sections(&self) -> &[Section] {
        &self.sections
    }

    /// Every named symbol: (name, value, size).
    pub fn symbols(&self) -> &[(String, u64, u64)] {
        &self.symbols
    }

    pub fn symbol(&self, name: &str) -> Option<u64> {
        self.symbols.iter().find(|(n, _, _)| n == name).map(|s| s.1)
    }

    /// Address and size of the first symbol whose name contains every one of `parts`.
    pub fn symbol_containing(&self, parts: &[&str]) -> Option<(u64, u64)> {
        self.symbols.iter().find(|(n, _, _)| parts.iter().all(|p| n.contains(p))).map(|s| (s.1, s.2))
    }

    /// The vector table: the initial SP then one handler address per exception number.
    pub fn vectors(&self) -> Result<Vec<u64>> {
        let s = self.sections.iter().find(|s| s.name == ".vector_table").context("no .vector_table section")?;
        let b = get(self.bytes, s.offset, s.size)?;
        Ok(b.chunks_exact(4).map(|c| u64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]]))).collect())
    }
}

fn get(bytes: &[u8], off: u64, len: u64) -> Result<&[u8]> {
    let (off, len) = (usize::try_from(off)?, usize::try_from(len)?);
    bytes.get(off..off.checked_add(len).context("ELF offset overflow")?).context("ELF truncated")
}

/// Whether the Thumb code at `entry` (a vector value, bit 0 set) does nothing but spin: up to a
/// frame-pointer prologue (`push`, `mov r7, sp`, `add r7, sp, #n`, `sub sp, #n`), then a body of
/// hint instructions (`nop`, `wfi`, `wfe`, `yield`) closed by an unconditional branch back into
/// it. A lone unconditional branch elsewhere (a trampoline) is followed.
pub fn is_spin(elf: &Elf, entry: u64) -> bool {
    let mut pc = entry & !1;
    let mut body = None;
    let mut hops = 0;
    for _ in 0..MAX_INSNS {
        let Some(h) = elf.read(pc, 2).map(|b| u16::from_le_bytes([b[0], b[1]])) else {
            return false;
        };
        let h2 = elf.read(pc + 2, 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
        match decode(h, h2) {
            Insn::Prologue if body.is_none() => pc += 2,
            Insn::PrologueWide if body.is_none() => pc += 4,
            Insn::Hint => {
                body.get_or_insert(pc);
                pc += 2;
            }
            Insn::Branch { offset, .. } => {
                let target = (pc as i64 + 4 + offset) as u64;
                let start = body.unwrap_or(pc);
                if target >= start && target <= pc {
                    return true;
                }
                // A tail jump into another handler: follow it (at most twice).
                hops += 1;
                if hops > 2 || body.is_some() {
                    return false;
                }
                pc = target;
            }
            _ => return false,
        }
    }
    false
}

#[derive(Debug, PartialEq, Eq)]
enum Insn {
    Prologue,
    PrologueWide,
    Hint,
    /// Unconditional branch, offset from PC + 4, instruction length in bytes.
    Branch {
        offset: i64,
        len: u64,
    },
    Other,
}

/// Decodes the few Thumb-2 encodings [`is_spin`] cares about (ARMv7-M ARM A7.7).
fn decode(h: u16, h2: Option<u16>) -> Insn {
    match h {
        // PUSH T1 (with or without LR), MOV r7, sp, ADD r7, sp, #imm8, SUB sp, sp, #imm7.
        0xb400..=0xb5ff | 0x466f | 0xaf00..=0xafff | 0xb080..=0xb0ff => Insn::Prologue,
        // PUSH.W T2 (STMDB sp!, {...}).
        0xe92d => Insn::PrologueWide,
        // NOP, YIELD, WFE, WFI.
        0xbf00 | 0xbf10 | 0xbf20 | 0xbf30 => Insn::Hint,
        // B T2 (unconditional, 16-bit).
        0xe000..=0xe7ff => Insn::Branch { offset: crate::code::b_t2_offset(h), len: 2 },
        // B.W T4 (unconditional, 32-bit; not BL).
        _ if h & 0xf800 == 0xf000 => match h2 {
            Some(l) if l & 0xd000 == 0x9000 => Insn::Branch { offset: crate::code::t4_offset(h, l), len: 4 },
            _ => Insn::Other,
        },
        _ => Insn::Other,
    }
}

/// The NMI, HardFault and default-handler checks.
pub fn handler_findings(elf: &Elf) -> Result<Vec<Finding>> {
    let v = elf.vectors()?;
    if v.len() < 16 {
        bail!("vector table has {} entries, fewer than the 16 of the core exceptions", v.len());
    }
    let one = |key: &'static str, what: &str, n: usize| {
        let spin = is_spin(elf, v[n]);
        Finding {
            key,
            ok: !spin,
            line: if spin {
                format!(
                    "vector {n} ({what}) at {:#010x} is a bare spin loop: the board hangs with its outputs as they are",
                    v[n] & !1
                )
            } else {
                format!("vector {n} ({what}) at {:#010x} does more than spin", v[n] & !1)
            },
        }
    };
    let mut out = vec![one("nmi_handler", "NMI", 2), one("hard_fault_handler", "HardFault", 3)];
    // Every other entry that is set: the runtime points each unclaimed one at `DefaultHandler`.
    let spinning: Vec<usize> = (4..v.len()).filter(|&n| v[n] != 0 && is_spin(elf, v[n])).collect();
    let default = elf.symbol("DefaultHandler");
    let default_spins = default.is_some_and(|a| is_spin(elf, a | 1));
    let ok = spinning.is_empty() && !default_spins;
    let line = if ok {
        format!(
            "no other vector entry (of {}) is a bare spin loop{}",
            v.len() - 4,
            default.map(|a| format!("; DefaultHandler at {a:#010x} does more than spin")).unwrap_or_default()
        )
    } else {
        let first = spinning.first().map(|&n| format!("first vector {n} at {:#010x}", v[n] & !1)).unwrap_or_default();
        format!(
            "{} vector entries lead to a bare spin loop ({first}){}",
            spinning.len(),
            if default_spins { "; DefaultHandler is one" } else { "" }
        )
    };
    out.push(Finding { key: "default_handler", ok, line });
    Ok(out)
}

/// The most an exception entry takes off the stack: the frame with the FPU's state (26 words)
/// and the word of padding that aligns it to 8 bytes (CCR.STKALIGN; ARMv7-M ARM B1.5.7).
pub const EXCEPTION_FRAME: u64 = 108;

/// TIM7's entry in the STM32L476's vector table: the control-stall check (RM0351 table 58;
/// stm32-metapac's `Interrupt::TIM7 = 55`).
pub const TIM7_VECTOR: usize = 16 + 55;

/// A symbol's name for a finding's line: the last two path components of a legacy-mangled
/// Rust name without its hash (`failsafe::halt`), else the name as it is.
pub fn short_name(name: &str) -> String {
    // A v0-mangled name (`_RNv…17rust_begin_unwind`): its last identifier.
    if name.starts_with("_R") {
        let b = name.as_bytes();
        for i in 1..b.len() {
            if b[i].is_ascii_digit() && !b[i - 1].is_ascii_digit() {
                let digits = b[i..].iter().take_while(|c| c.is_ascii_digit()).count();
                if name[i..i + digits].parse::<usize>().ok() == Some(b.len() - i - digits) {
                    return name[i + digits..].to_owned();
                }
            }
        }
        return name.to_owned();
    }
    let Some(mut rest) = name.strip_prefix("_ZN") else { return name.to_owned() };
    let mut parts = Vec::new();
    while let Some(digits) = rest.find(|c: char| !c.is_ascii_digit()).filter(|&d| d > 0) {
        let Ok(n) = rest[..digits].parse::<usize>() else { break };
        let Some(part) = rest.get(digits..digits + n) else { break };
        parts.push(part);
        rest = &rest[digits + n..];
    }
    if parts.last().is_some_and(|p| p.len() == 17 && p.starts_with('h')) {
        parts.pop();
    }
    let keep = parts.len().saturating_sub(2);
    parts[keep..]
        .join("::")
        .trim_start_matches('_')
        .replace("$LT$", "<")
        .replace("$GT$", ">")
        .replace("$u20$", " ")
        .replace("_$u7b$", "{")
        .replace("$u7b$", "{")
        .replace("$u7d$", "}")
        .replace("..", "::")
}

/// The name of the function holding `addr` (Thumb bit ignored), shortened, or the address.
fn name_at(elf: &Elf, addr: u64) -> String {
    let a = addr & !1;
    elf.symbols()
        .iter()
        .find(|(n, v, s)| (*v & !1..(*v & !1) + *s).contains(&a) && !n.starts_with('$') && crate::code::in_code(elf, a))
        .map(|(n, _, _)| short_name(n))
        .unwrap_or_else(|| format!("{:#010x}", addr & !1))
}

fn chain(elf: &Elf, addrs: &[u64]) -> String {
    addrs.iter().map(|&a| name_at(elf, a)).collect::<Vec<_>>().join(" → ")
}

/// The room the HardFault entry (`hter::hard_fault_entry!`) leaves above the guard before it
/// moves the stack to its top: the literal `__stack_guard_end + room` it compares the stack
/// pointer with, read from its literal pool (the `$d` range, not its instructions).
pub fn hard_fault_room(elf: &Elf, entry: u64) -> Option<u64> {
    let guard_end = elf.symbol("__stack_guard_end")?;
    let top = elf.symbol("_stack_start")?;
    let b = crate::code::body(elf, entry)?;
    // Its literal pool only: an instruction pair could read as such a word too.
    crate::code::literal_words(elf, b.start, b.size)
        .into_iter()
        .find(|&w| w > guard_end && w < top && w - guard_end <= 0x1_0000)
        .map(|w| w - guard_end)
}

/// The stop paths, followed through the image's direct calls and jumps: from the NMI, the
/// HardFault, the default handler (every interrupt nobody handles), the panic handler and the
/// control-stall check (TIM7's vector, which must be the bound `TIM7` handler), each reaches
/// the routine that drives the outputs safe (`BoardOutputs::force_safe`). A path that lost
/// that call, or a stall check left unbound, would stop the board with its outputs as they
/// were. The HardFault path's stack, summed over its deepest chain of calls, must fit the room
/// its entry leaves above the guard: the MPU is off in HardFault, so a deeper path would run
/// through the guard into the statics it may still need to record the stop. The NMI's, with
/// its exception frame, must fit the guard: the MPU is off in it too, and it may come with the
/// stack pointer anywhere down to the guard's top.
pub fn stop_path_findings(elf: &Elf) -> Result<Vec<Finding>> {
    let v = elf.vectors()?;
    let goal = elf.symbol_containing(&["BoardOutputs", "force_safe"]).map(|(a, _)| a & !1);
    let default = elf.symbol("DefaultHandler");
    let panic = elf.symbol_containing(&["rust_begin_unwind"]).map(|(a, _)| a);
    let tim7 = v.get(TIM7_VECTOR).copied().filter(|&e| e != 0);
    let paths: [(&'static str, &str, Option<u64>); 5] = [
        ("stop_path_nmi", "NMI", v.get(2).copied()),
        ("stop_path_hard_fault", "HardFault", v.get(3).copied()),
        ("stop_path_default", "DefaultHandler", default),
        ("stop_path_panic", "the panic handler", panic),
        ("stop_path_stall", "TIM7's stall check", tim7),
    ];
    let mut out = Vec::new();
    for (key, what, entry) in paths {
        let Some(goal) = goal else {
            out.push(Finding { key, ok: false, line: "no BoardOutputs::force_safe symbol in the image".into() });
            continue;
        };
        let Some(entry) = entry else {
            out.push(Finding { key, ok: false, line: format!("{what}: no entry in the image") });
            continue;
        };
        if key == "stop_path_stall" {
            let bound = elf.symbol("TIM7");
            if bound.map(|a| a & !1) != Some(entry & !1) || default.map(|a| a & !1) == Some(entry & !1) {
                out.push(Finding {
                    key,
                    ok: false,
                    line: format!(
                        "vector {TIM7_VECTOR} (TIM7) at {:#010x} is not the bound TIM7 handler: a stalled control loop is never stopped",
                        entry & !1
                    ),
                });
                continue;
            }
        }
        let w = crate::code::walk(elf, entry, goal, &crate::code::no_indirect);
        let depth = match (w.depth, w.unbounded_at) {
            (Some(d), _) => format!("{d} B of stack at most"),
            (None, Some(at)) => format!("stack not bounded from the code (at {at:#010x}, in {})", name_at(elf, at)),
            (None, None) => "stack not bounded from the code".into(),
        };
        if !w.reaches_goal {
            out.push(Finding {
                key,
                ok: false,
                line: format!(
                    "{what} at {:#010x} does NOT reach force_safe through direct calls: a stop there leaves the outputs as they are; {depth}",
                    entry & !1
                ),
            });
            continue;
        }
        let mut ok = true;
        let mut line = format!("{what}: {}; {depth}", chain(elf, &w.to_goal));
        let room = match key {
            // The NMI runs with the MPU off (HFNMIENA clear), on whatever stack it came in on:
            // from a stack pointer at the guard's top, its frames and its own exception frame
            // must end inside the guard, not in the statics below it.
            "stop_path_nmi" => Some((
                elf.symbol("__stack_guard_end").zip(elf.symbol("__stack_guard_start")).map(|(e, s)| e - s),
                EXCEPTION_FRAME,
                "the {} B guard with its exception frame",
                "no __stack_guard_start/__stack_guard_end in the image",
            )),
            "stop_path_hard_fault" => Some((
                hard_fault_room(elf, entry),
                0,
                "the {} B the entry leaves above the guard",
                "no `__stack_guard_end + room` literal in the HardFault entry (hter::hard_fault_entry!)",
            )),
            _ => None,
        };
        if let Some((room, extra, within, missing)) = room {
            let within = |r: u64| within.replace("{}", &r.to_string());
            match (room, w.depth) {
                (Some(r), Some(d)) if d + extra <= r => {
                    let _ = write!(line, ", within {}", within(r));
                }
                (Some(r), _) => {
                    ok = false;
                    let _ = write!(line, ": NOT within {} (deepest: {})", within(r), chain(elf, &w.deepest));
                }
                (None, _) => {
                    ok = false;
                    let _ = write!(line, ": {missing}");
                }
            }
        }
        out.push(Finding { key, ok, line });
    }
    Ok(out)
}

/// llvm-objdump from the toolchain's `llvm-tools` component.
fn llvm_objdump() -> Option<std::path::PathBuf> {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = Command::new(rustc).args(["--print", "sysroot"]).output().ok()?;
    let sysroot = std::path::PathBuf::from(String::from_utf8(out.stdout).ok()?.trim());
    std::fs::read_dir(sysroot.join("lib").join("rustlib"))
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("bin").join("llvm-objdump"))
        .find(|p| p.is_file())
}

/// The code reader the stop-path and stack checks rest on (`crate::code`) against an
/// independent one: for every function of the image, the frame, the targets outside it and
/// whether it calls through a register, as decoded from the bytes and as read from
/// llvm-objdump's disassembly (`crate::code::listed`), must agree. A prologue or branch form
/// the decoder does not know shows here, not as a wrong bound.
pub fn decoder_finding(elf: &Elf, path: &Path) -> Finding {
    let key = "code_decoder";
    let Some(objdump) = llvm_objdump() else {
        return Finding {
            key,
            ok: false,
            line: "no llvm-objdump in the toolchain (rustup component add llvm-tools)".into(),
        };
    };
    let text = match Command::new(&objdump).args(["-d", "--no-show-raw-insn"]).arg(path).output() {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        Ok(o) => {
            return Finding {
                key,
                ok: false,
                line: format!("llvm-objdump failed: {}", String::from_utf8_lossy(&o.stderr).trim()),
            }
        }
        Err(e) => return Finding { key, ok: false, line: format!("running {}: {e}", objdump.display()) },
    };
    let bodies: Vec<crate::code::Body> =
        crate::code::functions(elf).into_iter().filter_map(|f| crate::code::body(elf, f)).collect();
    let funcs: Vec<(u64, u64)> = bodies.iter().map(|b| (b.start, b.size)).collect();
    let listed = crate::code::listed(&text, &funcs);
    let mut differ = Vec::new();
    for b in &bodies {
        let f = b.start;
        let mut mine = b.out.clone();
        mine.sort();
        let theirs = listed.get(&f).map(|l| {
            let mut out = l.out.clone();
            out.sort();
            (l.frame, out, l.indirect, l.dynamic_frame)
        });
        if theirs != Some((b.frame, mine, b.indirect.is_some(), b.dynamic_frame.is_some())) {
            differ.push(f);
        }
    }
    match differ.first() {
        None => Finding {
            key,
            ok: true,
            line: format!("frames, calls and indirect calls agree with llvm-objdump's for all {} functions", funcs.len()),
        },
        Some(&f) => Finding {
            key,
            ok: false,
            line: format!(
                "{} of {} functions read differently from llvm-objdump, first {} at {f:#010x}: the decoder misses a form the compiler emits",
                differ.len(),
                funcs.len(),
                name_at(elf, f)
            ),
        },
    }
}

/// Whether a function is one of embassy-executor's task polls (`TaskStorage<F>::poll`): only
/// the executor calls them, through the task header's pointer.
fn is_task_poll(name: &str) -> bool {
    name.contains("TaskStorage") && name.contains("poll")
}

/// Whether a function is embassy-executor's own (its run loop polls the tasks).
fn is_executor(name: &str) -> bool {
    name.contains("embassy_executor") && !is_task_poll(name)
}

/// The whole program's stack, bounded from the image ([`crate::code::stack_bound`]): the
/// thread's deepest chain from Reset through the executor and the deepest task, and every
/// handler's with its exception frame, each once. Within the stack (`_stack_end` to
/// `_stack_start`), the stack cannot reach the guard whatever the size of one frame; a frame
/// larger than the guard could otherwise step over it. Recursion, an indirect call the image
/// gives no targets for, or a frame of run-time size leave it unbounded, which fails.
pub fn stack_bound_finding(elf: &Elf) -> Finding {
    let key = "stack_bound";
    let (Some(end), Some(start)) = (elf.symbol("_stack_end"), elf.symbol("_stack_start")) else {
        return Finding { key, ok: false, line: "no _stack_end/_stack_start in the image".into() };
    };
    let size = start.saturating_sub(end);
    let b = match crate::code::stack_bound(elf, EXCEPTION_FRAME, &is_task_poll, &is_executor) {
        Ok(b) => b,
        Err(e) => return Finding { key, ok: false, line: format!("{e:#}") },
    };
    let largest = crate::code::functions(elf)
        .into_iter()
        .filter_map(|f| crate::code::body(elf, f))
        .max_by_key(|b| b.frame)
        .map(|b| format!("; the largest frame {} B ({})", b.frame, name_at(elf, b.start)))
        .unwrap_or_default();
    match b.total {
        Some(total) => {
            let handlers: u64 = b.handlers.iter().filter_map(|(_, w)| w.depth).map(|d| d + EXCEPTION_FRAME).sum();
            let thread = b.thread.depth.unwrap_or(0);
            // The thread's deepest chain, by its frames of 256 B and more.
            let big: Vec<String> = b
                .thread
                .deepest
                .iter()
                .filter_map(|&f| crate::code::body(elf, f))
                .filter(|f| f.frame >= 256)
                .map(|f| format!("{} {} B", name_at(elf, f.start), f.frame))
                .collect();
            let ok = total <= size;
            Finding {
                key,
                ok,
                line: format!(
                    "at most {total} B of the {size} B stack{}: the thread {thread} B (its deepest chain's large frames: {}), {} handlers {handlers} B with their exception frames{largest}",
                    if ok { ", so no frame, however large, reaches the guard below it" } else { ": MORE than the stack" },
                    if big.is_empty() { "none".to_owned() } else { big.join(", ") },
                    b.handlers.len(),
                ),
            }
        }
        None if !b.unreached_tasks.is_empty() => Finding {
            key,
            ok: false,
            line: format!(
                "the stack is not bounded from the code: {} task poll(s), first {}, not reached from Reset: the executor's call of them is in a function not taken for the executor's, so their stack is in no chain{largest}",
                b.unreached_tasks.len(),
                name_at(elf, b.unreached_tasks[0])
            ),
        },
        None => {
            let lost = std::iter::once(&b.thread)
                .chain(b.handlers.iter().map(|(_, w)| w))
                .find_map(|w| w.unbounded_at)
                .map(|at| format!(" (at {at:#010x}, in {})", name_at(elf, at)))
                .unwrap_or_default();
            // `core::fmt::write` calls each argument's formatter through a pointer, and a
            // `Display` that formats again nests: the interface writes its text without it.
            let fmt = if elf.symbol_containing(&["core", "fmt", "5write"]).is_some() {
                "; the image links core::fmt::write, whose calls through a formatting argument can nest (write text through hter::iface::sink instead)"
            } else {
                ""
            };
            Finding {
                key,
                ok: false,
                line: format!("the stack is not bounded from the code{lost}: recursion, or an indirect call or a frame the image does not show{largest}{fmt}"),
            }
        }
    }
}

/// The settings interface's UART interrupt: USART2's vector entry is the bound handler (the
/// `USART2` symbol `bind_interrupts!` defines), not `DefaultHandler`, and does more than spin.
pub fn usart2_finding(elf: &Elf) -> Result<Finding> {
    let v = elf.vectors()?;
    let entry = *v.get(USART2_VECTOR).context("the vector table has no USART2 entry")?;
    let at = entry & !1;
    let handler = elf.symbol("USART2").map(|a| a & !1);
    let default = elf.symbol("DefaultHandler").map(|a| a & !1);
    let (ok, line) = if entry == 0 || Some(at) == default {
        (false, format!("vector {USART2_VECTOR} (USART2) is DefaultHandler: received bytes are never read"))
    } else if handler != Some(at) {
        (false, format!("vector {USART2_VECTOR} (USART2) at {at:#010x} is not the bound USART2 handler"))
    } else if is_spin(elf, entry) {
        (false, format!("vector {USART2_VECTOR} (USART2) at {at:#010x} is a bare spin loop"))
    } else {
        (true, format!("vector {USART2_VECTOR} (USART2) at {at:#010x} is the bound buffered-UART handler"))
    };
    Ok(Finding { key: "usart2_handler", ok, line })
}

/// TIM1's register block on the STM32L476 (RM0351 memory map): the buck's half bridge.
pub const TIM1_BLOCK: std::ops::Range<u64> = 0x4001_2C00..0x4001_3000;

/// The `buck` build's safe outputs reach its gates: the routine every stop path calls first
/// (`BoardOutputs::force_safe`, behind the library's `SafeOutputs`) holds an address inside
/// TIM1's register block in its literal pool (the firmware clears TIM1's MOE and CC1E/CC1NE
/// there, beside driving PA8/PA7 low). A build whose stop path forgot the half bridge would leave
/// it switching at its last duty through a panic, a HardFault or a stall, with only the supply
/// switch to stop the modules.
pub fn buck_safe_finding(elf: &Elf) -> Finding {
    let key = "buck_safe_outputs";
    let Some((addr, size)) = elf.symbol_containing(&["BoardOutputs", "force_safe"]) else {
        return Finding { key, ok: false, line: "no BoardOutputs::force_safe symbol in the image".into() };
    };
    let start = addr & !1;
    let hit = elf.read(start, size).and_then(|code| {
        // Literal-pool words are 4-byte aligned.
        let skip = ((4 - start % 4) % 4) as usize;
        code.get(skip..)?
            .chunks_exact(4)
            .map(|w| u64::from(u32::from_le_bytes([w[0], w[1], w[2], w[3]])))
            .find(|w| TIM1_BLOCK.contains(w))
    });
    match hit {
        Some(w) => Finding {
            key,
            ok: true,
            line: format!("force_safe at {start:#010x} addresses TIM1 ({w:#010x}): the stop paths turn both gates off"),
        },
        None => Finding {
            key,
            ok: false,
            line: format!(
                "force_safe at {start:#010x} ({size} B) has no TIM1 address: a stop leaves the buck's half bridge switching"
            ),
        },
    }
}

/// Whether `cargo tree -e features -i defmt-rtt` output shows the non-blocking feature.
pub fn rtt_nonblocking(tree: &str) -> bool {
    tree.lines().any(|l| l.contains("defmt-rtt feature \"disable-blocking-mode\""))
}

fn rtt_finding(elf: &Elf, cargo: &str, root: &Path) -> Result<Finding> {
    if elf.symbol("_SEGGER_RTT").is_none() {
        return Ok(Finding { key: "rtt_nonblocking", ok: true, line: "no RTT control block in the image".into() });
    }
    let out = Command::new(cargo)
        .current_dir(root)
        .args(["tree", "-p", "firmware", "--target", TARGET, "-e", "features", "-i", "defmt-rtt"])
        .output()
        .context("running cargo tree")?;
    if !out.status.success() {
        bail!("cargo tree -i defmt-rtt failed: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    let ok = rtt_nonblocking(&String::from_utf8_lossy(&out.stdout));
    Ok(Finding {
        key: "rtt_nonblocking",
        ok,
        line: if ok {
            "defmt-rtt is built with disable-blocking-mode (cargo tree -e features)".into()
        } else {
            "defmt-rtt lacks disable-blocking-mode (cargo tree -e features): a host that stops reading stalls every log call, and the control loop with it".into()
        },
    })
}

/// The programmed image ends in bank 1.
pub fn image_finding(elf: &Elf) -> Finding {
    let end = elf
        .segments
        .iter()
        .filter(|s| s.ty == PT_LOAD && s.filesz > 0 && (FLASH_START..FLASH_END).contains(&s.paddr))
        .map(|s| s.paddr + s.filesz)
        .chain(
            elf.sections
                .iter()
                .filter(|s| s.ty == SHT_PROGBITS && (FLASH_START..FLASH_END).contains(&s.addr))
                .map(|s| s.addr + s.size),
        )
        .max()
        .unwrap_or(FLASH_START);
    let ok = end <= BANK2_START;
    Finding {
        key: "image_in_bank1",
        ok,
        line: format!(
            "programmed image ends at {end:#010x} ({} bank 2 at {BANK2_START:#010x})",
            if ok { "below" } else { "INSIDE" }
        ),
    }
}

/// The stack guard lies between the statics and the stack, and is one MPU region.
pub fn stack_guard_finding(elf: &Elf) -> Finding {
    let key = "stack_guard";
    let sym = |n: &str| elf.symbol(n);
    let (Some(start), Some(end), Some(stack_end), Some(stack_start)) =
        (sym("__stack_guard_start"), sym("__stack_guard_end"), sym("_stack_end"), sym("_stack_start"))
    else {
        return Finding {
            key,
            ok: false,
            line: "no __stack_guard_start/__stack_guard_end (memory.x's .stack_guard) or stack symbols".into(),
        };
    };
    let statics_end = ["__ebss", "__euninit"].iter().filter_map(|n| sym(n)).max().unwrap_or(u64::MAX);
    let region = u32::try_from(start)
        .ok()
        .zip(u32::try_from(end).ok())
        .and_then(|(s, e)| hter::failsafe::stack_guard_region(s, e));
    let ok = region.is_some() && statics_end <= start && end <= stack_end && stack_end < stack_start;
    Finding {
        key,
        ok,
        line: format!(
            "guard {start:#010x}..{end:#010x} ({} one MPU region); statics end at {statics_end:#010x}, stack {stack_end:#010x}..{stack_start:#010x}{}",
            if region.is_some() { "is" } else { "NOT" },
            if ok { "" } else { ": NOT between them" }
        ),
    }
}

/// The `FLASH` region's end from a linker `MEMORY` block, if it parses.
pub fn flash_region_end(memory_x: &str) -> Option<u64> {
    let line = memory_x.lines().find(|l| l.trim_start().starts_with("FLASH") && l.contains("ORIGIN"))?;
    let field = |name: &str| -> Option<u64> {
        let rest = line.split(name).nth(1)?.trim_start().strip_prefix('=')?.trim_start();
        let tok: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric()).collect();
        let (digits, mult) = match tok.chars().last()? {
            'K' | 'k' => (&tok[..tok.len() - 1], 1024),
            'M' | 'm' => (&tok[..tok.len() - 1], 1024 * 1024),
            _ => (tok.as_str(), 1),
        };
        let v = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
            Some(h) => u64::from_str_radix(h, 16).ok()?,
            None => digits.parse().ok()?,
        };
        v.checked_mul(mult)
    };
    Some(field("ORIGIN")? + field("LENGTH")?)
}

fn region_finding(path: &Path) -> Result<Finding> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let end = flash_region_end(&text)
        .with_context(|| format!("{}: no FLASH : ORIGIN = …, LENGTH = … line", path.display()))?;
    let ok = end <= BANK2_START;
    Ok(Finding {
        key: "region_in_bank1",
        ok,
        line: format!(
            "memory.x FLASH region ends at {end:#010x} ({} bank 2 at {BANK2_START:#010x})",
            if ok { "within bank 1, below" } else { "reaching into" }
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A minimal ELF32: a `.vector_table` and a `.text` section at the given addresses, one
    /// loaded segment per section, and a symbol table.
    fn elf(vectors: &[u32], text_addr: u32, text: &[u8], symbols: &[(&str, u32)]) -> Vec<u8> {
        let sized: Vec<(&str, u32, u32)> = symbols.iter().map(|&(n, v)| (n, v, 0)).collect();
        elf_sized(vectors, text_addr, text, &sized)
    }

    fn elf_sized(vectors: &[u32], text_addr: u32, text: &[u8], symbols: &[(&str, u32, u32)]) -> Vec<u8> {
        let vt: Vec<u8> = vectors.iter().flat_map(|w| w.to_le_bytes()).collect();
        let mut shstr = b"\0.vector_table\0.text\0.symtab\0.strtab\0.shstrtab\0".to_vec();
        shstr.push(0);
        let mut strtab = vec![0u8];
        let mut symtab = vec![0u8; 16];
        for (name, value, size) in symbols {
            let at = strtab.len() as u32;
            strtab.extend_from_slice(name.as_bytes());
            strtab.push(0);
            let mut s = [0u8; 16];
            s[..4].copy_from_slice(&at.to_le_bytes());
            s[4..8].copy_from_slice(&value.to_le_bytes());
            s[8..12].copy_from_slice(&size.to_le_bytes());
            symtab.extend_from_slice(&s);
        }
        let mut out = vec![0u8; 52];
        let phoff = out.len();
        out.resize(phoff + 2 * 32, 0);
        let place = |out: &mut Vec<u8>, data: &[u8]| {
            let at = out.len();
            out.extend_from_slice(data);
            at as u32
        };
        let vt_off = place(&mut out, &vt);
        let text_off = place(&mut out, text);
        let sym_off = place(&mut out, &symtab);
        let str_off = place(&mut out, &strtab);
        let shstr_off = place(&mut out, &shstr);
        let shoff = out.len();
        // (name, type, addr, offset, size, link)
        let sh: [(u32, u32, u32, u32, u32, u32); 6] = [
            (0, 0, 0, 0, 0, 0),
            (1, 1, 0x0800_0000, vt_off, vt.len() as u32, 0),
            (15, 1, text_addr, text_off, text.len() as u32, 0),
            (21, 2, 0, sym_off, symtab.len() as u32, 4),
            (29, 3, 0, str_off, strtab.len() as u32, 0),
            (37, 3, 0, shstr_off, shstr.len() as u32, 0),
        ];
        for (name, ty, addr, off, size, link) in sh {
            let mut s = [0u8; 40];
            // .text: SHF_ALLOC | SHF_EXECINSTR.
            let flags = if name == 15 { 6 } else { 0 };
            for (i, w) in [name, ty, flags, addr, off, size, link].iter().enumerate() {
                s[4 * i..4 * i + 4].copy_from_slice(&w.to_le_bytes());
            }
            out.extend_from_slice(&s);
        }
        for (i, (paddr, off, size)) in
            [(0x0800_0000, vt_off, vt.len() as u32), (text_addr, text_off, text.len() as u32)].iter().enumerate()
        {
            let p = phoff + 32 * i;
            for (k, w) in [1u32, *off, *paddr, *paddr, *size, *size].iter().enumerate() {
                out[p + 4 * k..p + 4 * k + 4].copy_from_slice(&w.to_le_bytes());
            }
        }
        out[..6].copy_from_slice(&[0x7f, b'E', b'L', b'F', 1, 1]);
        out[0x1c..0x20].copy_from_slice(&(phoff as u32).to_le_bytes());
        out[0x20..0x24].copy_from_slice(&(shoff as u32).to_le_bytes());
        out[0x2a..0x2c].copy_from_slice(&32u16.to_le_bytes());
        out[0x2c..0x2e].copy_from_slice(&2u16.to_le_bytes());
        out[0x2e..0x30].copy_from_slice(&40u16.to_le_bytes());
        out[0x30..0x32].copy_from_slice(&6u16.to_le_bytes());
        out[0x32..0x34].copy_from_slice(&5u16.to_le_bytes());
        out
    }

    fn halfwords(h: &[u16]) -> Vec<u8> {
        h.iter().flat_map(|w| w.to_le_bytes()).collect()
    }

    const T: u32 = 0x0800_0100;

    /// 16 vectors: SP, Reset, then `nmi`, `hf`, and `rest` for every other entry.
    fn table(nmi: u32, hf: u32, rest: u32) -> Vec<u32> {
        let mut v = vec![0x2001_8000, T | 1, nmi | 1, hf | 1];
        v.extend([rest | 1; 12]);
        v
    }

    /// `bl` (`link`) or `b.w` from `from` to `to`, as two halfwords (T1 / T4).
    fn branch(from: u32, to: u32, link: bool) -> [u16; 2] {
        let off = i64::from(to) - i64::from(from) - 4;
        let imm = (off as u32) >> 1;
        let s = (off < 0) as u16;
        let (i1, i2) = (((imm >> 23) & 1) as u16, ((imm >> 22) & 1) as u16);
        let (j1, j2) = (1 ^ i1 ^ s, 1 ^ i2 ^ s);
        let h = 0xf000 | (s << 10) | ((imm >> 11) & 0x3ff) as u16;
        let l = if link { 0xd000 } else { 0x9000 } | (j1 << 13) | (j2 << 11) | (imm & 0x7ff) as u16;
        [h, l]
    }

    const STOP_T: u32 = 0x0800_0400;

    /// An image with the five stop paths: force_safe, halt (its frame from `halt_frame`, then
    /// `bl force_safe`, then `halt_extra`), a HardFault trampoline with its literal, and NMI,
    /// default, panic and TIM7 handlers that each `bl halt` unless named in `cut`.
    fn stop_image(halt_frame: &[u16], halt_extra: &[u16], cut: &[&str], tim7_default: bool) -> Vec<u8> {
        stop_image_marked(halt_frame, halt_extra, cut, tim7_default, true)
    }

    /// [`stop_image`], with the HardFault entry's literal marked as data (`$d`) or not.
    fn stop_image_marked(
        halt_frame: &[u16],
        halt_extra: &[u16],
        cut: &[&str],
        tim7_default: bool,
        mark_literal: bool,
    ) -> Vec<u8> {
        const GUARD_END: u32 = 0x2000_3000;
        let mut code: Vec<u16> = Vec::new();
        let mut syms: Vec<(String, u32, u32)> = Vec::new();
        // Past the vector table, which TIM7's entry makes 288 bytes long.
        let at = |code: &Vec<u16>| STOP_T + 2 * code.len() as u32;
        // force_safe: push {r7, lr}; pop {r7, pc}.
        let fs = at(&code);
        code.extend([0xb580, 0xbd80]);
        syms.push(("_ZN80_$LT$firmware..failsafe..BoardOutputs$u20$as$u20$hter..failsafe..SafeOutputs$GT$10force_safe17h0123456789abcdefE".into(), fs | 1, 4));
        let halt = at(&code);
        code.extend([0xb580]);
        code.extend(halt_frame);
        code.extend(branch(at(&code), fs, true));
        code.extend(halt_extra);
        code.push(0xe7fe);
        syms.push(("_ZN8firmware8failsafe4halt17h0123456789abcdefE".into(), halt | 1, at(&code) - halt));
        let handler = |name: &str, code: &mut Vec<u16>, syms: &mut Vec<(String, u32, u32)>| {
            let h = at(code);
            code.push(0xb580);
            if cut.contains(&name) {
                code.push(0xe7fe);
            } else {
                code.extend(branch(at(code), halt, true));
            }
            syms.push((name.into(), h | 1, at(code) - h));
            h
        };
        let nmi = handler("NonMaskableInt", &mut code, &mut syms);
        let default = handler("DefaultHandler", &mut code, &mut syms);
        handler("_RNvCs1234_7___rustc17rust_begin_unwind", &mut code, &mut syms);
        let tim7 = handler("TIM7", &mut code, &mut syms);
        // HardFault: b.w halt; nop; then (aligned) the literal, marked as data.
        if code.len() % 2 == 1 {
            code.push(0xbf00);
        }
        let hf = at(&code);
        if cut.contains(&"HardFault") {
            code.extend([0xe7fe, 0xbf00]);
        } else {
            code.extend(branch(hf, halt, false));
        }
        let lit = at(&code);
        let word = GUARD_END + 1024;
        code.extend([word as u16, (word >> 16) as u16]);
        syms.push(("HardFault".into(), hf | 1, 8));
        if mark_literal {
            syms.push(("$d".into(), lit, 0));
        }
        syms.push(("__stack_guard_start".into(), GUARD_END - 1024, 0));
        syms.push(("__stack_guard_end".into(), GUARD_END, 0));
        syms.push(("_stack_start".into(), 0x2001_8000, 0));
        let mut v = table(nmi, hf, default);
        v.resize(TIM7_VECTOR + 1, default | 1);
        v[TIM7_VECTOR] = if tim7_default { default } else { tim7 } | 1;
        let sized: Vec<(&str, u32, u32)> = syms.iter().map(|(n, a, s)| (n.as_str(), *a, *s)).collect();
        elf_sized(&v, STOP_T, &halfwords(&code), &sized)
    }

    fn stop_findings(bytes: Vec<u8>) -> Vec<Finding> {
        stop_path_findings(&Elf::parse(&bytes).unwrap()).unwrap()
    }

    #[test]
    fn every_stop_path_must_reach_force_safe() {
        // halt: sub sp, #0x40: 8 + 64 + 8 (force_safe) = 80 B on the deepest chain.
        let all = stop_findings(stop_image(&[0xb090], &[], &[], false));
        let keys: Vec<_> = all.iter().map(|f| f.key).collect();
        assert_eq!(
            keys,
            ["stop_path_nmi", "stop_path_hard_fault", "stop_path_default", "stop_path_panic", "stop_path_stall"]
        );
        for f in &all {
            assert!(f.ok, "{}: {}", f.key, f.line);
            assert!(f.line.contains("failsafe::halt → ") && f.line.contains("force_safe"), "{}", f.line);
        }
        let hf = &all[1];
        assert!(hf.line.contains("80 B of stack at most") && hf.line.contains("within the 1024 B"), "{}", hf.line);
        assert!(
            all[0].line.contains("88 B") && all[0].line.contains("within the 1024 B guard"),
            "the NMI handler's own push counts: {}",
            all[0].line
        );
        // Each path cut on its own fails on its own.
        for (name, key) in [
            ("NonMaskableInt", "stop_path_nmi"),
            ("HardFault", "stop_path_hard_fault"),
            ("DefaultHandler", "stop_path_default"),
            ("_RNvCs1234_7___rustc17rust_begin_unwind", "stop_path_panic"),
            ("TIM7", "stop_path_stall"),
        ] {
            let f = stop_findings(stop_image(&[0xb090], &[], &[name], false));
            for g in &f {
                assert_eq!(g.ok, g.key != key, "{name} cut: {}: {}", g.key, g.line);
            }
            let bad = f.iter().find(|g| g.key == key).unwrap();
            assert!(bad.line.contains("does NOT reach force_safe"), "{}", bad.line);
        }
    }

    #[test]
    fn the_stall_check_must_be_bound_to_tim7() {
        let f = stop_findings(stop_image(&[0xb090], &[], &[], true));
        let stall = f.iter().find(|g| g.key == "stop_path_stall").unwrap();
        assert!(!stall.ok && stall.line.contains("not the bound TIM7 handler"), "{}", stall.line);
        // DefaultHandler reaches force_safe too: it is the binding that is wrong.
        assert!(f.iter().filter(|g| g.key != "stop_path_stall").all(|g| g.ok));
    }

    #[test]
    fn the_hard_fault_path_must_fit_the_room_its_entry_leaves() {
        // subw sp, sp, #0x400: 8 + 1024 + 8 > 1024.
        let deep = stop_findings(stop_image(&[0xf2ad, 0x4d00], &[], &[], false));
        let hf = deep.iter().find(|g| g.key == "stop_path_hard_fault").unwrap();
        assert!(!hf.ok && hf.line.contains("1040 B") && hf.line.contains("NOT within the 1024 B"), "{}", hf.line);
        // Nor the NMI's the guard; the other paths run on the stack they were on, and reaching
        // force_safe is their check.
        for g in &deep {
            assert_eq!(g.ok, !matches!(g.key, "stop_path_hard_fault" | "stop_path_nmi"), "{}: {}", g.key, g.line);
        }
        // sub sp, #0x3f0 (T1's largest is 508: two of them): 8 + 1008 + 8 = 1024 fits.
        let edge = stop_findings(stop_image(&[0xb0ff, 0xb0fd], &[], &[], false));
        let hf = edge.iter().find(|g| g.key == "stop_path_hard_fault").unwrap();
        assert!(!edge[0].ok, "the NMI's 1032 B do not fit: {}", edge[0].line);
        assert!(hf.ok && hf.line.contains("1024 B of stack at most"), "{}", hf.line);
        // sub sp, #0x1f0, twice: 8 + 992 + 8 = 1008 B fits the HardFault's room, but the NMI's
        // 1016 B and its 108 B exception frame do not fit the 1 KiB guard.
        let nmi = stop_findings(stop_image(&[0xb0fc, 0xb0fc], &[], &[], false));
        for g in &nmi {
            assert_eq!(g.ok, g.key != "stop_path_nmi", "{}: {}", g.key, g.line);
        }
        let bad = nmi.iter().find(|g| g.key == "stop_path_nmi").unwrap();
        assert!(bad.line.contains("1016 B") && bad.line.contains("NOT within the 1024 B guard"), "{}", bad.line);
        // The room is read from the entry's literal pool only: the same word among its
        // instructions (no `$d` before it) is no room.
        let unmarked = stop_findings(stop_image_marked(&[0xb090], &[], &[], false, false));
        let hf = unmarked.iter().find(|g| g.key == "stop_path_hard_fault").unwrap();
        assert!(!hf.ok && hf.line.contains("no `__stack_guard_end + room` literal"), "{}", hf.line);
        // An indirect call on the path (blx r3 after force_safe): the stack cannot be bounded.
        let blind = stop_findings(stop_image(&[0xb090], &[0x4798], &[], false));
        let hf = blind.iter().find(|g| g.key == "stop_path_hard_fault").unwrap();
        assert!(!hf.ok && hf.line.contains("not bounded"), "{}", hf.line);
    }

    /// One function of [`program`]: its name, the instructions of its frame after
    /// `push {r7, lr}`, the functions it calls (`bl`), and whether it calls through r3.
    type Func<'a> = (&'a str, &'a [u16], &'a [&'a str], bool);

    /// An image of `funcs` laid out in order (each `push {r7, lr}`, its frame, its calls, its
    /// `blx r3`, `pop {r7, pc}`), then a literal pool holding the addresses of `pointers` (as
    /// `$d`), with Reset at `funcs[0]` and the handlers named in `handlers` in the vector table.
    fn program(funcs: &[Func], pointers: &[&str], handlers: &[&str], stack: u32) -> Vec<u8> {
        // Laid out twice: the first pass finds where each function starts.
        let mut at = std::collections::HashMap::new();
        let mut code: Vec<u16> = Vec::new();
        let mut syms: Vec<(String, u32, u32)> = Vec::new();
        for pass in 0..2 {
            code.clear();
            syms.clear();
            for f in funcs {
                let start = STOP_T + 2 * code.len() as u32;
                if pass == 0 {
                    at.insert(f.0, start);
                }
                code.push(0xb580);
                code.extend(f.1);
                for callee in f.2 {
                    let to = at.get(callee).copied().unwrap_or(STOP_T);
                    code.extend(branch(STOP_T + 2 * code.len() as u32, to, true));
                }
                if f.3 {
                    code.push(0x4798);
                }
                code.extend([0xbd80, 0xbf00]);
                if code.len() % 2 == 1 {
                    code.push(0xbf00);
                }
                syms.push((f.0.into(), start | 1, STOP_T + 2 * code.len() as u32 - start));
            }
        }
        syms.push(("$d".into(), STOP_T + 2 * code.len() as u32, 0));
        for p in pointers {
            let w = at[p] | 1;
            code.extend([w as u16, (w >> 16) as u16]);
        }
        // A last function after the pool ends its data.
        let tail = STOP_T + 2 * code.len() as u32;
        code.extend([0xe7fe, 0xbf00]);
        syms.push(("$t".into(), tail, 0));
        syms.push(("tail".into(), tail | 1, 4));
        syms.push(("_stack_end".into(), 0x2000_3000, 0));
        syms.push(("_stack_start".into(), 0x2000_3000 + stack, 0));
        let mut v = vec![0x2000_3000 + stack, at[funcs[0].0] | 1];
        v.extend(handlers.iter().map(|h| at[h] | 1));
        let sized: Vec<(&str, u32, u32)> = syms.iter().map(|(n, a, s)| (n.as_str(), *a, *s)).collect();
        elf_sized(&v, STOP_T, &halfwords(&code), &sized)
    }

    fn bound(bytes: Vec<u8>) -> Finding {
        stack_bound_finding(&Elf::parse(&bytes).unwrap())
    }

    const EXECUTOR: &str = "_ZN16embassy_executor8platform6thread8Executor3run17h0123456789abcdefE";
    const TASK_A: &str = "_ZN16embassy_executor3raw20TaskStorage$LT$F$GT$4poll17h0123456789abcde0E";
    const TASK_B: &str = "_ZN16embassy_executor3raw20TaskStorage$LT$F$GT$4poll17h0123456789abcde1E";
    const WAKE: &str = "_ZN16embassy_executor3raw5waker4wake17h0123456789abcdefE";

    #[test]
    fn the_stack_is_bounded_through_the_executor_and_its_tasks() {
        // Reset (8) → main (8 + 16) → the executor (8), which polls a task through r3: task A
        // (8 + 1024, calls build: 8 + 2032) or task B (8 + 64); each task wakes through r3
        // (wake: 8). The deepest: 8 + 24 + 8 + 1032 + 2040 = 3112; or through wake: task A's
        // 1032 + 8 < its call to build. The handler: 8 + 64 + its 108 B exception frame.
        let funcs: [Func; 8] = [
            ("Reset", &[], &["main"], false),
            ("main", &[0xb084], &[EXECUTOR], false),
            (EXECUTOR, &[], &[], true),
            (TASK_A, &[0xf5ad, 0x6d80], &["build"], true),
            (TASK_B, &[0xb090], &[], true),
            ("build", &[0xf2ad, 0x7df0], &[], false),
            (WAKE, &[], &[], false),
            ("TIM7", &[0xb090], &[], false),
        ];
        let ok = bound(program(&funcs, &[TASK_A, TASK_B, WAKE], &["TIM7"], 0x1_0000));
        assert!(ok.ok, "{}", ok.line);
        assert!(ok.line.starts_with("at most 3292 B of the 65536 B stack"), "{}", ok.line);
        assert!(ok.line.contains("the thread 3112 B") && ok.line.contains("1 handlers 180 B"), "{}", ok.line);
        assert!(
            ok.line.contains("build 2040 B") && ok.line.contains("the largest frame 2040 B (build)"),
            "{}",
            ok.line
        );
        // A stack smaller than the bound fails.
        let small = bound(program(&funcs, &[TASK_A, TASK_B, WAKE], &["TIM7"], 0x800));
        assert!(!small.ok && small.line.contains("MORE than the stack"), "{}", small.line);
        // A task's indirect call is a waker's, never a poll: had it been taken for any address
        // the image holds, the task would call itself. Through a function the executor does not
        // own, the same call is resolved the same way: no false cycle.
        let mut wakes = funcs;
        wakes[6] = (WAKE, &[], &[], true);
        let cyc = bound(program(&wakes, &[TASK_A, TASK_B, WAKE], &["TIM7"], 0x1_0000));
        assert!(
            !cyc.ok && cyc.line.contains("not bounded"),
            "a waker that calls through a pointer calls itself: {}",
            cyc.line
        );
    }

    #[test]
    fn a_task_poll_the_executor_is_not_seen_to_call_leaves_the_stack_unbounded() {
        // The executor's call of the task poll through its pointer sits in a function not named
        // as the executor's (the outliner's, as `OUTLINED_FUNCTION_10` holds `bx r5` in the
        // firmware; or the run loop inlined into main): resolved as any other indirect call, it
        // never reached task A's 1032 B, and the bound, 32 B, passed a 512 B stack.
        let funcs: [Func; 5] = [
            ("Reset", &[], &["main"], false),
            ("main", &[], &[EXECUTOR], false),
            (EXECUTOR, &[], &["OUTLINED_FUNCTION_0"], false),
            ("OUTLINED_FUNCTION_0", &[], &[], true),
            (TASK_A, &[0xf5ad, 0x6d80], &[], false),
        ];
        let f = bound(program(&funcs, &[TASK_A], &[], 0x200));
        assert!(!f.ok && f.line.contains("not reached"), "{}", f.line);
        // Called from the executor itself, the same poll is counted, and does not fit.
        let direct: [Func; 4] = [
            ("Reset", &[], &["main"], false),
            ("main", &[], &[EXECUTOR], false),
            (EXECUTOR, &[], &[], true),
            (TASK_A, &[0xf5ad, 0x6d80], &[], false),
        ];
        let f = bound(program(&direct, &[TASK_A], &[], 0x200));
        assert!(!f.ok && f.line.contains("MORE than the stack"), "{}", f.line);
        let f = bound(program(&direct, &[TASK_A], &[], 0x1_0000));
        assert!(f.ok && f.line.contains("the thread 1056 B"), "{}", f.line);
    }

    #[test]
    fn recursion_an_unknown_call_or_a_run_time_frame_leave_the_stack_unbounded() {
        let rec: [Func; 3] =
            [("Reset", &[], &["main"], false), ("main", &[], &["walk"], false), ("walk", &[0xb082], &["walk"], false)];
        let f = bound(program(&rec, &[], &[], 0x1_0000));
        assert!(!f.ok && f.line.contains("not bounded") && f.line.contains("walk"), "{}", f.line);
        // An indirect call outside the executor with no address in the image: it can only go
        // to a function whose address the image holds, and it holds none: bounded by main.
        let none: [Func; 2] = [("Reset", &[], &["main"], false), ("main", &[0xb082], &[], true)];
        let f = bound(program(&none, &[], &[], 0x1_0000));
        assert!(f.ok && f.line.contains("at most 24 B"), "{}", f.line);
        // sub sp, sp, r0: a frame of run-time size.
        let dynamic: [Func; 2] = [("Reset", &[], &["main"], false), ("main", &[0xebad, 0x0d00], &[], false)];
        let f = bound(program(&dynamic, &[], &[], 0x1_0000));
        assert!(!f.ok && f.line.contains("not bounded"), "{}", f.line);
        // A frame realigned for an over-aligned local (LLVM's `sub.w r4, sp, #0x800; bfc r4, #0,
        // #6; mov sp, r4`): SP set from a register takes 2 KiB the decoder did not count, and the
        // bound, 16 B, passed a 1 KiB stack.
        let realigned: [Func; 2] =
            [("Reset", &[], &["main"], false), ("main", &[0xf5ad, 0x6400, 0xf36f, 0x0405, 0x46a5], &[], false)];
        let f = bound(program(&realigned, &[], &[], 0x400));
        assert!(!f.ok && f.line.contains("not bounded"), "{}", f.line);
    }

    #[test]
    fn names_are_shortened_for_the_lines() {
        assert_eq!(short_name("_ZN8firmware8failsafe4halt17h3e694ca0ef75b51eE"), "failsafe::halt");
        assert_eq!(short_name("_RNvCsfLfy6EI15iL_7___rustc17rust_begin_unwind"), "rust_begin_unwind");
        assert_eq!(short_name("TIM7"), "TIM7");
        assert_eq!(
            short_name("_ZN4hter7persist5flash12write_record28_$u7b$$u7b$closure$u7d$$u7d$17h53612bc673850ba5E"),
            "write_record::{{closure}}"
        );
    }

    #[test]
    fn decodes_the_branches_a_spin_is_made_of() {
        assert_eq!(decode(0xe7fe, None), Insn::Branch { offset: -4, len: 2 }, "b .");
        assert_eq!(decode(0xe7fd, None), Insn::Branch { offset: -6, len: 2 });
        assert_eq!(decode(0xe001, None), Insn::Branch { offset: 2, len: 2 });
        assert_eq!(decode(0xf7ff, Some(0xbffe)), Insn::Branch { offset: -4, len: 4 }, "b.w .");
        assert_eq!(decode(0xf000, Some(0xb800)), Insn::Branch { offset: 0, len: 4 });
        assert_eq!(decode(0xf000, Some(0xf800)), Insn::Other, "bl is a call, not a branch");
        assert_eq!(decode(0xd0fe, None), Insn::Other, "a conditional branch can exit");
        assert_eq!(decode(0xb580, None), Insn::Prologue);
        assert_eq!(decode(0xdefe, None), Insn::Other, "udf");
    }

    #[test]
    fn spin_loops_are_found_and_real_handlers_are_not() {
        // 0x100: cortex-m-rt's DefaultHandler_ as the firmware links it: push {r7, lr};
        // mov r7, sp; b .   0x106: `loop { wfi }`.   0x10a: a handler that stores and calls.
        // 0x112: a trampoline `b.w` to the spin at 0x100.  0x116: `b.w .`.
        let code = halfwords(&[
            0xb580, 0x466f, 0xe7fe, // 0x100
            0xbf30, 0xe7fd, // 0x106
            0xb580, 0x466f, 0x6001, 0xf000, // 0x10a: str r1, [r0]; then a bl (first half)
            0xf7ff, 0xbff5, // 0x112: b.w 0x100
            0xf7ff, 0xbffe, // 0x116
        ]);
        let e = elf(&table(T, T, T), T, &code, &[]);
        let e = Elf::parse(&e).unwrap();
        assert!(is_spin(&e, u64::from(T | 1)));
        assert!(is_spin(&e, u64::from(T + 6) | 1));
        assert!(!is_spin(&e, u64::from(T + 0xa) | 1));
        assert!(is_spin(&e, u64::from(T + 0x12) | 1), "followed into the spin");
        assert!(is_spin(&e, u64::from(T + 0x16) | 1));
        assert!(!is_spin(&e, 0x0900_0001), "outside the image: not provably a spin");
    }

    #[test]
    fn the_handler_findings_name_each_spinning_vector() {
        let code = halfwords(&[0xb580, 0x466f, 0xe7fe, 0xb580, 0x466f, 0x6001, 0xdefe]);
        let (spin, real) = (T, T + 6);
        let bad = elf(&table(spin, spin, spin), T, &code, &[("DefaultHandler", spin)]);
        let f = handler_findings(&Elf::parse(&bad).unwrap()).unwrap();
        assert_eq!(
            f.iter().map(|f| (f.key, f.ok)).collect::<Vec<_>>(),
            [("nmi_handler", false), ("hard_fault_handler", false), ("default_handler", false)]
        );
        assert!(f[0].line.contains("vector 2 (NMI)"), "{}", f[0].line);
        let good = elf(&table(real, real, real), T, &code, &[("DefaultHandler", real)]);
        assert!(handler_findings(&Elf::parse(&good).unwrap()).unwrap().iter().all(|f| f.ok));
        // Only the HardFault left as the runtime's spin.
        let hf = elf(&table(real, spin, real), T, &code, &[("DefaultHandler", real)]);
        let f = handler_findings(&Elf::parse(&hf).unwrap()).unwrap();
        assert_eq!(f.iter().map(|f| f.ok).collect::<Vec<_>>(), [true, false, true]);
        // One interrupt vector still on a spin, whatever DefaultHandler is.
        let mut v = table(real, real, real);
        v[15] = spin | 1;
        let one = elf(&v, T, &code, &[("DefaultHandler", real)]);
        assert!(!handler_findings(&Elf::parse(&one).unwrap()).unwrap()[2].ok);
        assert!(Elf::parse(b"\x7fELF\x02\x01").is_err(), "ELF64 refused");
        assert!(Elf::parse(&bad[..60]).is_err(), "truncated");
    }

    #[test]
    fn the_stack_guard_lies_between_the_statics_and_the_stack() {
        let f =
            |syms: &[(&str, u32)]| stack_guard_finding(&Elf::parse(&elf(&table(T, T, T), T, &[0, 0], syms)).unwrap());
        let base = [("__ebss", 0x2000_2590), ("__euninit", 0x2000_29dc), ("_stack_start", 0x2001_8000)];
        let with = |start: u32, end: u32, stack_end: u32| {
            let mut s = base.to_vec();
            s.extend([("__stack_guard_start", start), ("__stack_guard_end", end), ("_stack_end", stack_end)]);
            f(&s)
        };
        // The firmware's layout (llvm-nm of the default build).
        assert!(with(0x2000_2c00, 0x2000_3000, 0x2000_3000).ok);
        assert!(!with(0x2000_2800, 0x2000_2c00, 0x2000_3000).ok, "over .uninit");
        assert!(!with(0x2000_2c00, 0x2000_3000, 0x2000_2c00).ok, "the stack may run into it");
        assert!(!with(0x2000_2e00, 0x2000_3200, 0x2000_3200).ok, "not aligned to its size: no MPU region");
        assert!(!f(&base).ok, "no guard at all");
    }

    #[test]
    fn usart2_must_be_the_bound_handler() {
        // T: a spin; T + 6: DefaultHandler (real); T + 14: the bound USART2 handler (real).
        let code = halfwords(&[0xb580, 0x466f, 0xe7fe, 0xb580, 0x466f, 0x6001, 0xdefe, 0xb580, 0x466f, 0x6001, 0xdefe]);
        let (spin, default, usart2) = (T, T + 6, T + 14);
        let image = |entry: u32, symbols: &[(&str, u32)]| {
            let mut v = table(default, default, default);
            v.resize(USART2_VECTOR + 1, default | 1);
            v[USART2_VECTOR] = entry;
            elf(&v, T, &code, symbols)
        };
        let both = [("DefaultHandler", default | 1), ("USART2", usart2 | 1)];
        let f = |bytes: Vec<u8>| usart2_finding(&Elf::parse(&bytes).unwrap()).unwrap();
        let bound = f(image(usart2 | 1, &both));
        assert!(bound.ok, "{}", bound.line);
        assert_eq!(bound.key, "usart2_handler");
        let unbound = f(image(default | 1, &both[..1]));
        assert!(!unbound.ok && unbound.line.contains("DefaultHandler"), "{}", unbound.line);
        let other = f(image(default | 1, &[("DefaultHandler", usart2 | 1), ("USART2", usart2 | 1)]));
        assert!(!other.ok, "an entry that is not the USART2 symbol: {}", other.line);
        let spins = f(image(spin | 1, &[("DefaultHandler", default | 1), ("USART2", spin | 1)]));
        assert!(!spins.ok && spins.line.contains("spin"), "{}", spins.line);
        assert!(!f(image(0, &both)).ok, "an empty entry");
        // A table too short for USART2 is an error, not a pass.
        let short = elf(&table(default, default, default), T, &code, &both);
        assert!(usart2_finding(&Elf::parse(&short).unwrap()).is_err());
    }

    #[test]
    fn the_buck_stop_path_must_reach_tim1() {
        // force_safe as the buck build links it, shortened: push; ldr r1, [pc, #4]; bic …; pop;
        // then its literal pool (aligned), which holds TIM1_CCER (0x4001_2C20).
        let mut code = halfwords(&[0xb580, 0x4901, 0xbd80, 0xbf00]);
        code.extend_from_slice(&0x4001_2c20u32.to_le_bytes());
        let name = "_ZN80_$LT$firmware..failsafe..BoardOutputs$u20$as$u20$hter..failsafe..SafeOutputs$GT$10force_safe17h0c63d009b50055fdE";
        let f = |code: &[u8], symbols: &[(&str, u32, u32)]| {
            buck_safe_finding(&Elf::parse(&elf_sized(&table(T, T, T), T, code, symbols)).unwrap())
        };
        let ok = f(&code, &[(name, T | 1, code.len() as u32)]);
        assert!(ok.ok && ok.line.contains("0x40012c20"), "{}", ok.line);
        // The SSR build's routine: TIM3 (0x4000_0400) only.
        let mut ssr = halfwords(&[0xb580, 0x4901, 0xbd80, 0xbf00]);
        ssr.extend_from_slice(&0x4000_0420u32.to_le_bytes());
        let bad = f(&ssr, &[(name, T | 1, ssr.len() as u32)]);
        assert!(!bad.ok && bad.line.contains("no TIM1 address"), "{}", bad.line);
        // The literal past the symbol's end is not the routine's.
        let short = f(&code, &[(name, T | 1, 8)]);
        assert!(!short.ok, "{}", short.line);
        assert!(!f(&code, &[("DefaultHandler", T | 1, 8)]).ok, "no force_safe symbol");
    }

    #[test]
    fn the_image_end_is_checked_against_bank_2() {
        let code = halfwords(&[0xe7fe]);
        let low = elf(&table(T, T, T), T, &code, &[]);
        assert!(image_finding(&Elf::parse(&low).unwrap()).ok);
        let high = elf(&table(T, T, T), 0x0807_fffe, &halfwords(&[0xe7fe, 0xe7fe]), &[]);
        let f = image_finding(&Elf::parse(&high).unwrap());
        assert!(!f.ok, "{}", f.line);
        let edge = elf(&table(T, T, T), 0x0807_fffe, &code, &[]);
        assert!(image_finding(&Elf::parse(&edge).unwrap()).ok, "ending exactly at bank 2 is in bank 1");
    }

    #[test]
    fn memory_x_flash_region() {
        let today =
            "MEMORY\n{\n  FLASH   : ORIGIN = 0x08000000, LENGTH = 1016K\n  RAM : ORIGIN = 0x20000000, LENGTH = 96K\n}";
        assert_eq!(flash_region_end(today), Some(0x0800_0000 + 1016 * 1024));
        let bank1 = "  FLASH : ORIGIN = 0x08000000, LENGTH = 512K /* bank 1 */";
        assert_eq!(flash_region_end(bank1), Some(BANK2_START));
        assert_eq!(flash_region_end("  FLASH : ORIGIN = 0x08000000, LENGTH = 1M"), Some(FLASH_END));
        assert_eq!(flash_region_end("  FLASH : ORIGIN = 134217728, LENGTH = 4096"), Some(0x0800_1000));
        assert_eq!(flash_region_end("RAM : ORIGIN = 0x20000000, LENGTH = 96K"), None);
        assert_eq!(flash_region_end("  FLASH : ORIGIN = 0x08000000, LENGTH = lots"), None);
    }

    #[test]
    fn rtt_feature_from_cargo_tree() {
        let without = "defmt-rtt v1.3.1\n└── defmt-rtt feature \"default\"\n    └── firmware v0.1.0\n";
        assert!(!rtt_nonblocking(without));
        let with = "defmt-rtt v1.3.1\n├── defmt-rtt feature \"default\"\n└── defmt-rtt feature \"disable-blocking-mode\"\n    └── firmware v0.1.0\n";
        assert!(rtt_nonblocking(with));
    }
}
