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
//!   that overflows faults in it before it reaches them (`hter::failsafe::arm_stack_guard`).
//!
//! It prints one line per check and a final JSON line, and exits non-zero if any check fails.

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
        // B T2: imm11, offset = SignExtend(imm11:0).
        0xe000..=0xe7ff => {
            let imm = i64::from(h & 0x7ff);
            Insn::Branch { offset: ((imm << 53) >> 52), len: 2 }
        }
        // B.W T4: S:I1:I2:imm10:imm11:0, I1 = NOT(J1 XOR S), I2 = NOT(J2 XOR S).
        _ if h & 0xf800 == 0xf000 => match h2 {
            Some(l) if l & 0xd000 == 0x9000 => {
                let s = i64::from((h >> 10) & 1);
                let j1 = i64::from((l >> 13) & 1);
                let j2 = i64::from((l >> 11) & 1);
                let i1 = 1 ^ (j1 ^ s);
                let i2 = 1 ^ (j2 ^ s);
                let imm =
                    (s << 24) | (i1 << 23) | (i2 << 22) | (i64::from(h & 0x3ff) << 12) | (i64::from(l & 0x7ff) << 1);
                Insn::Branch { offset: (imm << 39) >> 39, len: 4 }
            }
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
            for (i, w) in [name, ty, 0, addr, off, size, link].iter().enumerate() {
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
