//! The firmware's Thumb-2 code as `cargo xtask audit` reads it: each function's stack frame
//! and the calls and jumps that leave it, decoded from the release ELF (ARMv7-M ARM A7.7), so
//! that the audit can follow a stop path from its vector to the routine that drives the outputs
//! safe and bound the stack it needs.
//!
//! Only what the compiler emits for these is decoded:
//! - the stack pointer's decrements: `push`, `push.w` (STMDB sp!), `str rX, [sp, #-n]!`,
//!   `vpush`, `sub sp, #n`, `sub.w sp, sp, #n` and `subw sp, sp, #n`; a frame is their sum over
//!   the whole body, an upper bound when a body holds more than one prologue;
//! - the direct calls and jumps: `bl`, `b`, `b.w`, `b<c>`, `b<c>.w`; a target outside the body
//!   is a call (or a tail call), and so is one to the body's own first byte (a recursion);
//! - what cannot be followed: `blx rN`, `bx rN` other than `bx lr`, `mov pc, rN`, a load into
//!   pc other than a pop, and `sub sp, sp, rN` and `mov sp, rN` (a frame of unknown size: an
//!   alloca, a frame realigned for an over-aligned local);
//! - the addresses a function forms in code (`movw`/`movt` pairs, `adr`), which an indirect
//!   call may later use.
//!
//! Literal pools and other data inside `.text` are skipped by the ELF's mapping symbols (`$d`
//! starts data, `$t` starts Thumb code again; ARM ELF ABI §4.5.5).

use std::collections::HashMap;

use crate::audit::Elf;

/// One function's code, as far as the stop-path checks need it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Body {
    /// First byte (the symbol's value without the Thumb bit) and size.
    pub start: u64,
    pub size: u64,
    /// Bytes its prologue(s) take off the stack pointer.
    pub frame: u64,
    /// Addresses it calls or jumps to outside itself, in code order, without repeats.
    pub out: Vec<u64>,
    /// Its first call or jump through a register or a loaded address, if any.
    pub indirect: Option<u64>,
    /// Its first frame of run-time size, if any.
    pub dynamic_frame: Option<u64>,
    /// The 32-bit constants it builds with a `movw` then a `movt` into one register, and the
    /// code addresses it forms with `adr` (with the Thumb bit set, as a function pointer has it).
    pub constants: Vec<u64>,
}

/// Sign-extends the low `bits` of `v`.
fn sext(v: u64, bits: u32) -> i64 {
    let s = 64 - bits;
    ((v << s) as i64) >> s
}

/// ThumbExpandImm (A5.3.2) of a 12-bit `i:imm3:imm8`.
fn thumb_expand_imm(imm12: u64) -> u64 {
    let imm8 = imm12 & 0xff;
    if imm12 >> 10 == 0 {
        match (imm12 >> 8) & 3 {
            0 => imm8,
            1 => (imm8 << 16) | imm8,
            2 => (imm8 << 24) | (imm8 << 8),
            _ => (imm8 << 24) | (imm8 << 16) | (imm8 << 8) | imm8,
        }
    } else {
        let unrotated = 0x80 | (imm12 & 0x7f);
        let rot = (imm12 >> 7) & 0x1f;
        u64::from((unrotated as u32).rotate_right(rot as u32))
    }
}

/// What one instruction does to the stack and the flow of control.
#[derive(Debug, PartialEq, Eq)]
pub enum Effect {
    /// Takes this many bytes off the stack pointer.
    Frame(u64),
    /// A direct call or jump to this offset from the instruction's address + 4.
    Branch(i64),
    /// A call or jump through a register or a loaded address.
    Indirect,
    /// A frame of run-time size (`sub sp, sp, rN`, `mov sp, rN`).
    DynamicFrame,
    /// `movw rd, #imm16` (`top` false) or `movt rd, #imm16` (`top` true): half an address.
    Move {
        rd: u16,
        imm: u64,
        top: bool,
    },
    /// `adr rd, label`: an address this offset from the instruction's address + 4, rounded
    /// down to a word.
    Adr(i64),
    Other,
}

/// B T2's offset from the instruction's address + 4: SignExtend(imm11:0).
pub fn b_t2_offset(h: u16) -> i64 {
    sext(u64::from(h & 0x7ff) << 1, 12)
}

/// BL T1's and B.W T4's offset from the instruction's address + 4: S:I1:I2:imm10:imm11:0,
/// I1 = NOT(J1 XOR S), I2 = NOT(J2 XOR S).
pub fn t4_offset(h: u16, l: u16) -> i64 {
    let (hw, lw) = (u64::from(h), u64::from(l));
    let s = (hw >> 10) & 1;
    let (j1, j2) = ((lw >> 13) & 1, (lw >> 11) & 1);
    let (i1, i2) = (1 ^ (j1 ^ s), 1 ^ (j2 ^ s));
    sext((s << 24) | (i1 << 23) | (i2 << 22) | ((hw & 0x3ff) << 12) | ((lw & 0x7ff) << 1), 25)
}

/// Length in bytes of the Thumb instruction whose first halfword is `h`.
pub fn insn_len(h: u16) -> u64 {
    if h >> 11 >= 0b11101 {
        4
    } else {
        2
    }
}

/// Decodes the instruction `h` (+ `l`, its second halfword when 32-bit).
pub fn effect(h: u16, l: u16) -> Effect {
    let (hw, lw) = (u64::from(h), u64::from(l));
    if insn_len(h) == 2 {
        return match h {
            // PUSH T1: r0–r7 and LR.
            0xb400..=0xb5ff => Effect::Frame(4 * u64::from((h & 0x1ff).count_ones())),
            // SUB SP, SP, #imm7 × 4 (T1).
            0xb080..=0xb0ff => Effect::Frame(4 * (hw & 0x7f)),
            // ADR T1: imm8 words forward.
            0xa000..=0xa7ff => Effect::Adr(4 * i64::from(h & 0xff)),
            // B T2: imm11.
            0xe000..=0xe7ff => Effect::Branch(b_t2_offset(h)),
            // B<c> T1: imm8 (cond 1110 is UDF, 1111 SVC).
            0xd000..=0xddff => Effect::Branch(sext((hw & 0xff) << 1, 9)),
            // BLX Rm; BX Rm other than LR; MOV PC, Rm (T1, Rd = 15).
            _ if h & 0xff87 == 0x4780 => Effect::Indirect,
            _ if h & 0xff87 == 0x4700 && (h >> 3) & 0xf != 14 => Effect::Indirect,
            _ if h & 0xff87 == 0x4687 => Effect::Indirect,
            // MOV SP, Rm (T1, Rd = 13): SP set from a register, as a realigned frame's
            // `sub.w rX, sp, #n; bfc rX, …; mov sp, rX` does: of a size the image does not show.
            _ if h & 0xff87 == 0x4685 => Effect::DynamicFrame,
            _ => Effect::Other,
        };
    }
    // PUSH.W (STMDB SP!, {…}).
    if h == 0xe92d {
        return Effect::Frame(4 * u64::from(l.count_ones()));
    }
    // STR.W Rt, [SP, #-imm8]! (T4, P = 1, U = 0, W = 1).
    if h == 0xf84d && l & 0x0f00 == 0x0d00 {
        return Effect::Frame(lw & 0xff);
    }
    // STRD Rt, Rt2, [SP, #-imm8×4]! (T1, P = 1, U = 0, W = 1).
    if h == 0xe96d {
        return Effect::Frame(4 * (lw & 0xff));
    }
    // VPUSH T1 (doubles) / T2 (singles): imm8 words.
    if h & 0xffbf == 0xed2d && matches!(l & 0x0e00, 0x0a00) {
        return Effect::Frame(4 * (lw & 0xff));
    }
    // SUB.W SP, SP, #const (T2, S = 0 or 1) and SUBW SP, SP, #imm12 (T3).
    if h & 0xfbef == 0xf1ad && l & 0x8f00 == 0x0d00 {
        let imm12 = ((hw >> 10) & 1) << 11 | ((lw >> 12) & 7) << 8 | (lw & 0xff);
        return Effect::Frame(thumb_expand_imm(imm12));
    }
    if h & 0xfbff == 0xf2ad && l & 0x8f00 == 0x0d00 {
        return Effect::Frame(((hw >> 10) & 1) << 11 | ((lw >> 12) & 7) << 8 | (lw & 0xff));
    }
    // SUB SP, SP, Rm: a frame of run-time size.
    if h & 0xffef == 0xebad && l & 0x0f00 == 0x0d00 {
        return Effect::DynamicFrame;
    }
    // ADR.W T3 (add) / T2 (subtract): i:imm3:imm8.
    if h & 0xfbff == 0xf20f || h & 0xfbff == 0xf2af {
        let imm = (((hw >> 10) & 1) << 11 | ((lw >> 12) & 7) << 8 | (lw & 0xff)) as i64;
        return Effect::Adr(if h & 0xfbff == 0xf2af { -imm } else { imm });
    }
    // MOVW T3 / MOVT T1: imm4:i:imm3:imm8 into Rd.
    if h & 0xfbf0 == 0xf240 || h & 0xfbf0 == 0xf2c0 {
        let imm = (hw & 0xf) << 12 | ((hw >> 10) & 1) << 11 | ((lw >> 12) & 7) << 8 | (lw & 0xff);
        return Effect::Move { rd: (l >> 8) & 0xf, imm, top: h & 0xfbf0 == 0xf2c0 };
    }
    if h & 0xf800 == 0xf000 {
        // BL T1 and B.W T4.
        if l & 0xd000 == 0xd000 || l & 0xd000 == 0x9000 {
            return Effect::Branch(t4_offset(h, l));
        }
        // B<c>.W T3: S:J2:J1:imm6:imm11:0 (cond 111x are other instructions).
        if l & 0xd000 == 0x8000 && (h >> 6) & 0xe != 0xe {
            let s = (hw >> 10) & 1;
            let (j1, j2) = ((lw >> 13) & 1, (lw >> 11) & 1);
            let imm = (s << 20) | (j2 << 19) | (j1 << 18) | ((hw & 0x3f) << 12) | ((lw & 0x7ff) << 1);
            return Effect::Branch(sext(imm, 21));
        }
    }
    // LDR.W PC, [Rn, …] other than a pop (LDR PC, [SP], #4) and LDM … {…, PC} are returns.
    if h & 0xfff0 == 0xf8d0 && l >> 12 == 0xf && h & 0xf != 0xd {
        return Effect::Indirect;
    }
    if h & 0xfff0 == 0xf850 && l >> 12 == 0xf && h & 0xf != 0xd {
        return Effect::Indirect;
    }
    Effect::Other
}

/// The mapping symbols in `range`, in address order: (address, true where data starts, false
/// where Thumb code starts again).
fn mapping_symbols(elf: &Elf, range: std::ops::Range<u64>) -> Vec<(u64, bool)> {
    let mut maps: Vec<(u64, bool)> = elf
        .symbols()
        .iter()
        .filter(|(_, v, _)| range.contains(v))
        .filter_map(|(n, v, _)| match n.split('.').next() {
            Some("$d") => Some((*v, true)),
            Some("$t") => Some((*v, false)),
            _ => None,
        })
        .collect();
    maps.sort();
    maps
}

/// The sized symbol (a function, not a mapping symbol) that starts at `addr` (Thumb bit
/// ignored): (name, value, size).
pub fn function_symbol<'e>(elf: &'e Elf, addr: u64) -> Option<&'e (String, u64, u64)> {
    let start = addr & !1;
    elf.symbols().iter().find(|(n, v, s)| *v & !1 == start && *s > 0 && !n.starts_with('$'))
}

/// The function whose symbol starts at `addr` (Thumb bit ignored), decoded.
pub fn body(elf: &Elf, addr: u64) -> Option<Body> {
    let start = addr & !1;
    if !in_code(elf, start) {
        return None;
    }
    let size = function_symbol(elf, start)?.2;
    let code = elf.read(start, size)?;
    // Mapping symbols inside the body, in address order: true where data starts.
    let maps = mapping_symbols(elf, start..start + size);
    let data_at = |pc: u64| maps.iter().rev().find(|(a, _)| *a <= pc).is_some_and(|(_, d)| *d);
    let half = |off: u64| code.get(off as usize..off as usize + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let mut b =
        Body { start, size, frame: 0, out: Vec::new(), indirect: None, dynamic_frame: None, constants: Vec::new() };
    let mut low = [None::<u64>; 16];
    let mut off = 0;
    while off + 2 <= size {
        let pc = start + off;
        if data_at(pc) {
            // On to the next code mapping, or the end.
            off = maps.iter().find(|(a, d)| *a > pc && !d).map_or(size, |(a, _)| a - start);
            continue;
        }
        let h = half(off)?;
        let len = insn_len(h);
        let l = if len == 4 { half(off + 2).unwrap_or(0) } else { 0 };
        match effect(h, l) {
            Effect::Frame(n) => b.frame += n,
            Effect::Branch(rel) => {
                // A branch within the body is its own flow, except to its first byte: that runs
                // the prologue again, a recursion.
                let target = (pc as i64 + 4 + rel) as u64;
                if (target == start || !(start..start + size).contains(&target)) && !b.out.contains(&target) {
                    b.out.push(target);
                }
            }
            Effect::Indirect => {
                b.indirect.get_or_insert(pc);
            }
            Effect::DynamicFrame => {
                b.dynamic_frame.get_or_insert(pc);
            }
            Effect::Move { rd, imm, top: false } => low[usize::from(rd)] = Some(imm),
            Effect::Move { rd, imm, top: true } => {
                if let Some(lo) = low[usize::from(rd)].take() {
                    b.constants.push(imm << 16 | lo);
                }
            }
            // A code address formed from the pc: taken as a function's with its Thumb bit.
            Effect::Adr(rel) => b.constants.push((((pc + 4) & !3) as i64 + rel) as u64 | 1),
            Effect::Other => {}
        }
        off += len;
    }
    Some(b)
}

/// Where a body's indirect calls may go: `None` where the code cannot say (the walk then has
/// no bound).
pub type Resolve<'r> = &'r dyn Fn(&Body) -> Option<Vec<u64>>;

/// No indirect call is followed.
pub fn no_indirect(_: &Body) -> Option<Vec<u64>> {
    None
}

/// A walk of the call graph from one entry.
#[derive(Debug)]
pub struct Walk {
    /// The deepest stack any chain of calls from the entry takes (frames summed along it), or
    /// `None` if it cannot be bounded: an indirect call the resolver cannot place, a frame of
    /// run-time size, a target the image has no sized symbol for, or a cycle (recursion).
    pub depth: Option<u64>,
    /// The chain that needs `depth`, entry first.
    pub deepest: Vec<u64>,
    /// Why `depth` is `None`: the address where the walk lost the bound.
    pub unbounded_at: Option<u64>,
    /// Whether `goal` is reached (called or jumped to) from the entry.
    pub reaches_goal: bool,
    /// The chain from the entry to `goal`, when reached.
    pub to_goal: Vec<u64>,
    /// Every function the walk entered, sorted.
    pub reached: Vec<u64>,
}

/// Walks every call and jump from `entry` (the indirect ones where `resolve` places them),
/// summing frames along each chain, and looks for `goal` on the way.
pub fn walk(elf: &Elf, entry: u64, goal: u64, resolve: Resolve) -> Walk {
    struct State<'e, 'a, 'r> {
        elf: &'e Elf<'a>,
        goal: u64,
        resolve: Resolve<'r>,
        /// Per function: Some(depth and its chain), or None for unbounded.
        memo: HashMap<u64, Option<(u64, Vec<u64>)>>,
        on_path: Vec<u64>,
        unbounded_at: Option<u64>,
        to_goal: Option<Vec<u64>>,
    }
    fn visit(st: &mut State, f: u64) -> Option<(u64, Vec<u64>)> {
        if f == st.goal && st.to_goal.is_none() {
            let mut chain = st.on_path.clone();
            chain.push(f);
            st.to_goal = Some(chain);
        }
        if let Some(m) = st.memo.get(&f) {
            return m.clone();
        }
        if st.on_path.contains(&f) {
            st.unbounded_at.get_or_insert(f);
            return None;
        }
        let Some(b) = body(st.elf, f) else {
            st.unbounded_at.get_or_insert(f);
            st.memo.insert(f, None);
            return None;
        };
        st.on_path.push(f);
        let mut result = Some((b.frame, vec![f]));
        if let Some(at) = b.dynamic_frame {
            st.unbounded_at.get_or_insert(at);
            result = None;
        }
        let mut out = b.out.clone();
        if let Some(at) = b.indirect {
            match (st.resolve)(&b) {
                Some(targets) => out.extend(targets.into_iter().filter(|t| !b.out.contains(t))),
                None => {
                    st.unbounded_at.get_or_insert(at);
                    result = None;
                }
            }
        }
        for callee in out {
            let sub = visit(st, callee);
            result = match (result, sub) {
                (Some((d, c)), Some((sd, sc))) => {
                    if b.frame + sd > d {
                        let mut chain = vec![f];
                        chain.extend(sc);
                        Some((b.frame + sd, chain))
                    } else {
                        Some((d, c))
                    }
                }
                _ => None,
            };
        }
        st.on_path.pop();
        st.memo.insert(f, result.clone());
        result
    }
    let mut st = State {
        elf,
        goal: goal & !1,
        resolve,
        memo: HashMap::new(),
        on_path: Vec::new(),
        unbounded_at: None,
        to_goal: None,
    };
    let r = visit(&mut st, entry & !1);
    let mut reached: Vec<u64> = st.memo.keys().copied().collect();
    reached.sort();
    Walk {
        depth: r.as_ref().map(|(d, _)| *d),
        deepest: r.map(|(_, c)| c).unwrap_or_default(),
        unbounded_at: st.unbounded_at,
        reaches_goal: st.to_goal.is_some(),
        to_goal: st.to_goal.unwrap_or_default(),
        reached,
    }
}

/// The functions whose address the image holds as data, as an indirect call would find them:
/// the words of `.rodata` and `.data` and of the literal pools in code ([`literal_words`])
/// that are a function's address with the Thumb bit, and the `movw`/`movt` and `adr`
/// constants of every function's code. The vector table is left out: its handlers are not
/// called by code.
pub fn address_taken(elf: &Elf) -> Vec<u64> {
    let funcs: Vec<u64> = functions(elf);
    let is_func = |w: u64| w & 1 == 1 && funcs.binary_search(&(w & !1)).is_ok();
    let mut taken: Vec<u64> = Vec::new();
    for sec in elf.sections() {
        let loaded = sec.ty == 1 && sec.flags & 2 != 0 && sec.addr != 0;
        let words = if loaded && (sec.name == ".rodata" || sec.name == ".data") {
            elf.read(sec.addr, sec.size).map_or_else(Vec::new, |bytes| aligned_words(bytes, sec.addr))
        } else if loaded && in_code(elf, sec.addr) {
            // The data ranges in code: the literal pools.
            literal_words(elf, sec.addr, sec.size)
        } else {
            continue;
        };
        taken.extend(words.into_iter().filter(|&w| is_func(w)).map(|w| w & !1));
    }
    for &f in &funcs {
        if let Some(b) = body(elf, f) {
            taken.extend(b.constants.iter().filter(|&&w| is_func(w)).map(|w| w & !1));
        }
    }
    taken.sort();
    taken.dedup();
    taken
}

/// Whether `addr` lies in a section of executable code.
pub fn in_code(elf: &Elf, addr: u64) -> bool {
    const SHF_EXECINSTR: u64 = 4;
    elf.sections().iter().any(|s| s.flags & SHF_EXECINSTR != 0 && (s.addr..s.addr + s.size).contains(&addr))
}

/// The little-endian 32-bit words of `bytes`, which start at address `base`, that lie on word
/// boundaries.
fn aligned_words(bytes: &[u8], base: u64) -> Vec<u64> {
    let skip = ((4 - base % 4) % 4) as usize;
    bytes
        .get(skip..)
        .unwrap_or(&[])
        .chunks_exact(4)
        .map(|w| u64::from(u32::from_le_bytes([w[0], w[1], w[2], w[3]])))
        .collect()
}

/// The aligned 32-bit words of the data (`$d`) ranges in `size` bytes of code from `start` (a
/// function, or a whole section): the literal pools, not the instructions. A range ends at the
/// next mapping symbol, or at `start + size`.
pub fn literal_words(elf: &Elf, start: u64, size: u64) -> Vec<u64> {
    let end = start + size;
    let marks = mapping_symbols(elf, start..end);
    let mut out = Vec::new();
    for (k, &(at, data)) in marks.iter().enumerate() {
        if !data {
            continue;
        }
        let to = marks[k + 1..].iter().map(|m| m.0).find(|&e| e > at).unwrap_or(end);
        if let Some(bytes) = elf.read(at, to - at) {
            out.extend(aligned_words(bytes, at));
        }
    }
    out
}

/// Every sized symbol in executable code (a function), its first byte, sorted.
pub fn functions(elf: &Elf) -> Vec<u64> {
    let mut f: Vec<u64> = elf
        .symbols()
        .iter()
        .filter(|(n, v, s)| *s > 0 && !n.starts_with('$') && in_code(elf, v & !1))
        .map(|(_, v, _)| v & !1)
        .collect();
    f.sort();
    f.dedup();
    f
}

/// The most stack the program can take: the thread's deepest chain from the reset handler,
/// plus every interrupt and exception handler's deepest chain and exception frame, each once,
/// as if all of them nested at that moment (a handler cannot preempt itself).
#[derive(Debug)]
pub struct StackBound {
    pub thread: Walk,
    /// (entry, its walk), one per distinct handler in the vector table.
    pub handlers: Vec<(u64, Walk)>,
    /// The task polls the thread's walk never entered: their frames are in no chain, so the
    /// bound is not one (`total` is `None`).
    pub unreached_tasks: Vec<u64>,
    /// The sum, if every walk is bounded and every task poll is reached.
    pub total: Option<u64>,
}

/// [`StackBound`] of the image. An indirect call goes to any function whose address the image
/// holds ([`address_taken`]); `task(name)` marks the ones only a call from `executor(name)`
/// can reach (an async executor's task polls, which the tasks' own indirect calls — wakers —
/// never make), so the tasks and the executor do not form a false cycle.
pub fn stack_bound(
    elf: &Elf,
    exception_frame: u64,
    task: &dyn Fn(&str) -> bool,
    executor: &dyn Fn(&str) -> bool,
) -> anyhow::Result<StackBound> {
    let v = elf.vectors()?;
    let name = |addr: u64| function_symbol(elf, addr).map_or("", |(n, _, _)| n.as_str());
    let taken = address_taken(elf);
    let (tasks, others): (Vec<u64>, Vec<u64>) = taken.iter().partition(|&&f| task(name(f)));
    let resolve = |b: &Body| -> Option<Vec<u64>> {
        if executor(name(b.start)) {
            Some(tasks.iter().chain(&others).copied().collect())
        } else {
            Some(others.clone())
        }
    };
    let thread = walk(elf, *v.get(1).ok_or_else(|| anyhow::anyhow!("no reset vector"))?, u64::MAX, &resolve);
    let mut entries: Vec<u64> = v.iter().skip(2).filter(|&&e| e != 0).map(|e| e & !1).collect();
    entries.sort();
    entries.dedup();
    let handlers: Vec<(u64, Walk)> = entries.into_iter().map(|e| (e, walk(elf, e, u64::MAX, &resolve))).collect();
    // A task poll is followed only from a function named as the executor's: one the executor's
    // call of it has moved out of (an outlined sequence, the run loop inlined into `main`) would
    // leave the tasks' frames out of the bound without a word.
    let unreached_tasks: Vec<u64> =
        tasks.iter().copied().filter(|t| thread.reached.binary_search(t).is_err()).collect();
    let total = thread
        .depth
        .filter(|_| unreached_tasks.is_empty())
        .and_then(|d| handlers.iter().try_fold(d, |t, (_, w)| Some(t + w.depth? + exception_frame)));
    Ok(StackBound { thread, handlers, unreached_tasks, total })
}

/// What llvm-objdump's text shows of one function, read as [`body`] reads the bytes.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Listed {
    pub frame: u64,
    pub out: Vec<u64>,
    pub indirect: bool,
    pub dynamic_frame: bool,
}

/// Condition suffixes of an IT block's instructions, as llvm-objdump prints them.
const CONDS: [&str; 15] = ["", "eq", "ne", "hs", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le"];

fn cond_of<'s>(op: &'s str, stem: &str) -> Option<&'s str> {
    let rest = op.strip_prefix(stem)?;
    let rest = rest.strip_suffix(".w").unwrap_or(rest);
    (CONDS.contains(&rest) || rest == "cs" || rest == "cc").then_some(rest)
}

fn number(s: &str) -> Option<u64> {
    let s = s.trim().trim_start_matches('#');
    match s.strip_prefix("0x") {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

/// Reads `llvm-objdump -d --no-show-raw-insn` output: per function of `functions` (start and
/// size), its frame, its targets outside itself (or at its start) and whether it calls
/// through a register, an independent reading of what [`body`] decodes.
pub fn listed(text: &str, functions: &[(u64, u64)]) -> HashMap<u64, Listed> {
    let mut out: HashMap<u64, Listed> = HashMap::new();
    let mut cur: Option<(u64, u64)> = None;
    for line in text.lines() {
        if let Some(head) = line.strip_suffix(">:") {
            let addr = head.split(' ').next().and_then(|a| u64::from_str_radix(a, 16).ok());
            cur = addr.and_then(|a| functions.iter().find(|f| f.0 == a).copied()).filter(|f| !out.contains_key(&f.0));
            if let Some(f) = cur {
                out.insert(f.0, Listed::default());
            }
            continue;
        }
        let Some((start, size)) = cur else { continue };
        let Some((pc, insn)) = line.split_once(':') else { continue };
        let Some(pc) = u64::from_str_radix(pc.trim(), 16).ok() else { continue };
        if !(start..start + size).contains(&pc) {
            continue;
        }
        let insn = insn.trim();
        let (op, args) = insn.split_once(char::is_whitespace).map_or((insn, ""), |(o, a)| (o, a.trim()));
        let l = out.get_mut(&start).expect("inserted at the header");
        let regs = || args.trim_start_matches('{').split('}').next().map_or(0, |r| r.split(',').count() as u64);
        match op {
            "push" | "push.w" => l.frame += 4 * regs(),
            "vpush" => l.frame += if args.starts_with("{d") { 8 } else { 4 } * regs(),
            // SP's own decrement (`sub sp, #n`, `sub.w sp, sp, …`), not `sub sp, r7, #n`, which
            // sets it back up from the frame pointer.
            "sub" | "sub.w" | "subw" if args.starts_with("sp, #") || args.starts_with("sp, sp,") => {
                let last = args.rsplit(',').next().unwrap_or("").trim();
                match last.starts_with('#').then(|| number(last)).flatten() {
                    Some(n) => l.frame += n,
                    None if last.starts_with('r') => l.dynamic_frame = true,
                    None => {}
                }
            }
            // SP set from a register (a realigned frame, an alloca): no size to read.
            "mov" | "mov.w" if args.starts_with("sp, r") => l.dynamic_frame = true,
            _ if op.starts_with("str") && args.contains("[sp, #-") && args.ends_with("]!") => {
                let n = args.rsplit("#-").next().and_then(|n| number(n.trim_end_matches("]!")));
                l.frame += n.unwrap_or(0);
            }
            _ => {}
        }
        let reg = |a: &str| {
            let r = a.trim();
            r.strip_prefix('r').and_then(|n| n.parse::<u8>().ok()).is_some_and(|n| n <= 12)
        };
        if cond_of(op, "blx").is_some() || cond_of(op, "bx").is_some() {
            if reg(args) {
                l.indirect = true;
            }
        } else if cond_of(op, "bl").is_some() || cond_of(op, "b").is_some() {
            if let Some(t) = args.split_whitespace().next().and_then(number) {
                if (t == start || !(start..start + size).contains(&t)) && !l.out.contains(&t) {
                    l.out.push(t);
                }
            }
        } else if (op == "mov" && args.starts_with("pc,"))
            || (op.starts_with("ldr") && args.starts_with("pc, [") && !args.starts_with("pc, [sp]"))
        {
            l.indirect = true;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_the_frames_the_compiler_emits() {
        // Each against llvm-objdump's reading of the firmware.
        assert_eq!(effect(0xb5f0, 0), Effect::Frame(20), "push {{r4, r5, r6, r7, lr}}");
        assert_eq!(effect(0xb580, 0), Effect::Frame(8), "push {{r7, lr}}");
        assert_eq!(effect(0xe92d, 0x0f00), Effect::Frame(16), "push.w {{r8, r9, r10, r11}}");
        assert_eq!(effect(0xf84d, 0xbd04), Effect::Frame(4), "str r11, [sp, #-4]!");
        assert_eq!(effect(0xed2d, 0x8b04), Effect::Frame(16), "vpush {{d8, d9}}");
        assert_eq!(effect(0xed2d, 0x8b10), Effect::Frame(64), "vpush {{d8-d15}}");
        assert_eq!(effect(0xb090, 0), Effect::Frame(0x40), "sub sp, #0x40");
        assert_eq!(effect(0xf5ad, 0x7d74), Effect::Frame(0x3d0), "sub.w sp, sp, #0x3d0");
        assert_eq!(effect(0xf5ad, 0x5d9b), Effect::Frame(0x1360), "sub.w sp, sp, #0x1360");
        assert_eq!(effect(0xf6ad, 0x4dd8), Effect::Frame(0xcd8), "subw sp, sp, #0xcd8");
        assert_eq!(effect(0xebad, 0x0d00), Effect::DynamicFrame, "sub.w sp, sp, r0");
        assert_eq!(effect(0x46a5, 0), Effect::DynamicFrame, "mov sp, r4 (a realigned frame)");
        assert_eq!(effect(0x466c, 0), Effect::Other, "mov r4, sp");
        assert_eq!(effect(0xe96d, 0x4502), Effect::Frame(8), "strd r4, r5, [sp, #-8]!");
        // Not frames: add sp, pop, sub into another register.
        assert_eq!(effect(0xb010, 0), Effect::Other, "add sp, #0x40");
        assert_eq!(effect(0xbdf0, 0), Effect::Other, "pop {{r4-r7, pc}}");
        assert_eq!(effect(0xf5a0, 0x7d74), Effect::Other, "sub.w sp, r0, … is not SP's own decrement");
    }

    #[test]
    fn decodes_calls_jumps_and_what_cannot_be_followed() {
        // bl 0x800b7da at 0x80002ac (imm = #0xb52a), b.w 0x800b7bc at 0x800eb9e (#-0x33e6).
        assert_eq!(effect(0xf00b, 0xfa95), Effect::Branch(0xb52a));
        assert_eq!(effect(0xf7fc, 0xbe0d), Effect::Branch(-0x33e6));
        assert_eq!(effect(0xe7fe, 0), Effect::Branch(-4), "b .");
        assert_eq!(effect(0xd1f8, 0), Effect::Branch(-0x10), "bne #-0x10");
        // beq.w +0x100 (T3).
        assert_eq!(effect(0xf000, 0x8080), Effect::Branch(0x100));
        assert_eq!(effect(0x4798, 0), Effect::Indirect, "blx r3");
        assert_eq!(effect(0x4718, 0), Effect::Indirect, "bx r3");
        assert_eq!(effect(0x4770, 0), Effect::Other, "bx lr is a return");
        assert_eq!(effect(0xf85d, 0xfb04), Effect::Other, "ldr pc, [sp], #4 is a return");
        assert_eq!(effect(0xf8d0, 0xf000), Effect::Indirect, "ldr.w pc, [r0]");
        // movw r0, #0xf8a8; movt r0, #0x800 (the firmware's, at 0x800c85e).
        assert_eq!(effect(0xf64f, 0x00a8), Effect::Move { rd: 0, imm: 0xf8a8, top: false });
        assert_eq!(effect(0xf6c0, 0x0000), Effect::Move { rd: 0, imm: 0x0800, top: true });
        // adr r1, #968 (the runner's, at 0x700a); adr.w r1, #4 (the firmware's, at 0x800afec).
        assert_eq!(effect(0xa1f2, 0), Effect::Adr(968));
        assert_eq!(effect(0xf20f, 0x0104), Effect::Adr(4));
        assert_eq!(effect(0xf2af, 0x0108), Effect::Adr(-8), "adr.w r1, #-8");
        assert_eq!(insn_len(0xf000), 4);
        assert_eq!(insn_len(0xe92d), 4);
        assert_eq!(insn_len(0xb580), 2);
        assert_eq!(insn_len(0xe7fe), 2);
    }

    #[test]
    fn reads_llvm_objdumps_listing_as_the_decoder_reads_the_bytes() {
        // Lines as `llvm-objdump -d --no-show-raw-insn` prints the firmware (some shortened).
        let text = "\
08000294 <__rustc::rust_begin_unwind>:
 8000294:      \tpush\t{r3, r4, r5, r6, r7, lr}
 8000296:      \tadd\tr7, sp, #0x10
 80002ac:      \tbl\t0x800b7da <halt> @ imm = #0xb52a

080002b0 <next>:
 80002b0:      \tpush\t{r7, lr}

0800060c <signal>:
 800060c:      \tpush\t{r4, r5, r7, lr}
 8000610:      \tpush.w\t{r8, r9, r10, r11}
 8000614:      \tvpush\t{d8, d9}
 8000618:      \tsub.w\tsp, sp, #0x3d0
 800061c:      \tsub\tsp, #0x18
 800061e:      \tstr\tr11, [sp, #-4]!
 8000622:      \tbic\tr0, r0, #0x1
 8000626:      \tbls\t0x800060c <signal>
 8000628:      \tblxeq\tr1
 800062a:      \tbne\t0x8000622 <signal+0x16>
 800062c:      \tblne\t0x800bbac <next_period> @ imm = #0x58
 8000630:      \tbx\tlr
 8000632:      \tadd\tsp, #0x18
";
        let funcs = [(0x0800_0294, 0x1c), (0x0800_02b0, 0x26), (0x0800_060c, 0x28)];
        let l = listed(text, &funcs);
        assert_eq!(
            l[&0x0800_0294],
            Listed { frame: 24, out: vec![0x0800_b7da], indirect: false, dynamic_frame: false }
        );
        // 16 + 16 + 16 + 0x3d0 + 0x18 + 4; a branch to its own start is a recursion; `bic` is
        // no branch, `bne` within is none, `bx lr` a return.
        assert_eq!(
            l[&0x0800_060c],
            Listed { frame: 1052, out: vec![0x0800_060c, 0x0800_bbac], indirect: true, dynamic_frame: false }
        );
        assert_eq!(l[&0x0800_02b0].frame, 8);
        let dynamic = listed("0800060c <f>:\n 800060c:      \tsub.w\tsp, sp, r0\n", &funcs);
        assert!(dynamic[&0x0800_060c].dynamic_frame);
        let realign = listed("0800060c <f>:\n 800060c:      \tmov\tsp, r4\n", &funcs);
        assert!(realign[&0x0800_060c].dynamic_frame, "SP set from a register");
        let restore = listed("0800060c <f>:\n 800060c:      \tsub.w\tsp, r7, #0x18\n", &funcs);
        assert_eq!(restore[&0x0800_060c], Listed::default(), "the frame pointer's restore is no frame");
    }

    #[test]
    fn expands_modified_immediates() {
        assert_eq!(thumb_expand_imm(0x0ab), 0xab);
        assert_eq!(thumb_expand_imm(0x1ab), 0x00ab_00ab);
        assert_eq!(thumb_expand_imm(0x2ab), 0xab00_ab00);
        assert_eq!(thumb_expand_imm(0x3ab), 0xabab_abab);
        // 0x3d0 = 0xf4 rotated right by 30: i:imm3 = 0b1_111, imm8 = 0x74.
        assert_eq!(thumb_expand_imm(0xf74), 0x3d0);
    }
}
