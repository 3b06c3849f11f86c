//! The fail-safe part of `cargo xtask pil`: boots `pil`'s `failsafe` binary on QEMU mps2-an386
//! and checks, for each stop path, what its boots report on semihosting stdout. The fifth path is
//! a stack overflow into the MPU stack guard (QEMU models the ARMv7-M MPU): it must end in the
//! HardFault's stop path, recorded as a stack overflow, with nothing below the guard written.
//! The sixth is no stop path: a boot that reads the overflow's stop, marks its phase as the
//! firmware does ([`hter::failsafe::BootPhase::Restore`]), arms the board's watchdog and hangs
//! before it lets the stop go (as a board's boot can hang before its history is stored); the
//! next boot must see a watchdog reset, the marker, [`hter::failsafe::ResetRecords::boot`]'s
//! stop of it (a `control_stall` of that phase) with the overflow kept beside it as the earlier
//! stop, field for field as the boot before reported it, and after any other reset the overflow
//! alone, no stop from the marker. That boot lets both go and panics.
//!
//! The last is a stop path that finds a stop reported and not let go
//! ([`hter::failsafe::ResetRecords::record`]): the boot after the panic reports it (alone, as
//! the newest stop and fresh) and, before it lets it go, reads the unmapped address. The next
//! boot must find the HardFault as the newest stop, fresh and with its own fields, and the panic
//! kept beside it as the earlier stop, whole (a record that fails its magic or CRC is none) and
//! field for field as the boot before reported it; that boot lets both go and resets with no
//! stop path, and the boot after it must find no stop at all. Every other boot must find no
//! earlier stop: each lets its stop go once reported.
//!
//! QEMU turns the guest's SYSRESETREQ (`SCB::sys_reset`) into a machine reset
//! (`qemu_system_reset_request`; with `-no-reboot` the same request makes QEMU exit instead, which
//! is how this was verified): the CPU restarts from the reset vector, the fault status and NVIC
//! state are cleared, and RAM outside the ELF's loaded segments keeps its contents. The ELF's
//! `.uninit` statics are in a segment with no file bytes, which QEMU's loader does not re-zero
//! at reset; the checks below fail if that ever changes (the record would not survive).
//!
//! The watchdog is the CMSDK APB watchdog QEMU puts at 0x4000_8000 on mps2-an386, clocked at the
//! 25 MHz SYSCLK, its interrupt wired to the NMI (QEMU 7.2 `hw/arm/mps2.c`, lines 377–383). Its
//! first timeout raises the interrupt, its second, with the interrupt not cleared and RESEN set,
//! calls `watchdog_perform_action` (`hw/watchdog/cmsdk-apb-watchdog.c`, lines 280–292 and 113–116),
//! whose default action is the same `qemu_system_reset_request(SHUTDOWN_CAUSE_GUEST_RESET)` as
//! SYSRESETREQ's (`hw/watchdog/watchdog.c` line 49, `hw/intc/armv7m_nvic.c` line 77): the same
//! machine reset, so `.uninit` crosses it as it crosses SYSRESETREQ (the loader's reset handler
//! skips a segment without file bytes: `include/hw/elf_ops.h` line 580, `hw/core/loader.c` lines
//! 1177–1179), and with `-no-reboot` it would make QEMU exit as well: the run must not pass it
//! (nor `-action watchdog=` other than `reset`). The run uses `-icount shift=6,sleep=off`, as
//! the PIL cases do: the watchdog counts QEMU's virtual clock, which without `-icount` follows the
//! host's, and a loaded host that stalled the guest for its 10 ms period between arming it and
//! noting so would fail the check by chance; with it, the 20 ms to the reset are 312 500 guest
//! instructions, the same on every run.

use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

use anyhow::Result;

/// Each stop path, the reason its record names and the boot that reports it (the boot after the
/// one that triggered it). A stack overflow is a HardFault record with its own text; the hang
/// ([`HANG`]) has no record: its reason is the stop the next boot makes of its phase marker;
/// [`KEPT`]'s is the HardFault of a boot that had not let its panic go.
pub const FAILSAFE_KINDS: [(&str, &str, u32); 7] = [
    ("panic", "panic", 2),
    ("hard_fault", "hard_fault", 3),
    ("nmi", "nmi", 4),
    ("unexpected_interrupt", "unexpected_interrupt", 5),
    ("stack_overflow", "hard_fault", 6),
    (HANG, "control_stall", 7),
    (KEPT, "hard_fault", 9),
];
/// The boot that hangs until the watchdog resets it (and the next boot reports).
pub const HANG: &str = "watchdog_hang";
/// The stop path that finds a stop reported and not let go: the next boot has both.
pub const KEPT: &str = "stop_beside_unstored";
/// The boots of a run: the last reports what the one that let [`KEPT`]'s two stops go left
/// (nothing), then exits.
pub const BOOTS: u64 = 10;
/// The line after a boot's report with the fields of the earlier stop it found, if any.
const EARLIER: &str = "failsafe-earlier ";
/// The address the HardFault boot reads (the runner's `UNMAPPED`).
const FAULT_ADDR: u64 = 0xF000_0000;
/// ICSR.VECTACTIVE of the NMI (exception number 2), the NMI record's `detail` on the PIL.
const NMI_EXCEPTION: u64 = 2;
/// Ten boots take well under a second of host time (the hang's two watchdog periods are
/// 20 ms of guest time); a broken boot counter, or a watchdog that never resets, loops forever.
const FAILSAFE_TIMEOUT: Duration = Duration::from_secs(60);

/// The three checks of one stop path (of the hang and of [`KEPT`]: [`Check::labels`]).
#[derive(Debug)]
pub struct Check {
    pub kind: &'static str,
    /// The safe-outputs hook ran first: stamp 1, before the records changed, record stamp 2.
    /// The hang: the reset was the watchdog's (armed, its interrupt passed over by the NMI
    /// handler, no stop path recorded, the machine reset).
    pub first: bool,
    /// The record crossed a real reset intact (magic + CRC, kind, kind-specific fields). The
    /// hang: its phase marker did. [`KEPT`]: both records did, the earlier as it was reported.
    pub survived: bool,
    /// The next boot (the boot counter advanced by one) reported it. The hang: as the boot's
    /// stop of its phase, and as no stop after another reset. [`KEPT`]: as the fresh stop, the
    /// one before it having been the only one, and no stop once both were let go.
    pub reported: bool,
    /// Why a check failed, one line each.
    pub why: Vec<String>,
}

impl Check {
    pub fn ok(&self) -> bool {
        self.first && self.survived && self.reported
    }

    /// What [`Self::first`], [`Self::survived`] and [`Self::reported`] say for this kind.
    pub fn labels(&self) -> [&'static str; 3] {
        match self.kind {
            HANG => ["watchdog reset", "marker survived the reset", "next boot made the stop of it"],
            KEPT => ["safe outputs first", "both records survived the reset", "reported fresh, let go"],
            _ => ["safe outputs first", "record survived the reset", "next boot reported it"],
        }
    }
}

/// Boots the runner until it exits; returns the checks.
pub fn run(elf: &Path, work: &Path) -> Result<Vec<Check>> {
    let dir = work.join("failsafe");
    std::fs::create_dir_all(&dir)?;
    let run = crate::qemu(elf, &dir, &["-icount", "shift=6,sleep=off"], FAILSAFE_TIMEOUT)?;
    let (exited_ok, out) = (run.status.is_some_and(|s| s.success()), run.stdout);
    std::fs::write(dir.join("stdout.txt"), &out)?;
    Ok(checks(&out, exited_ok))
}

/// A line of the boots' reports: its fields by name.
type Report<'a> = HashMap<&'a str, &'a str>;

/// One boot's report: `failsafe boot=<n> key=value ... text=<the rest of the line>` (`prefix`
/// `"failsafe "`), or the earlier stop it found ([`EARLIER`], the same form).
fn parse_line<'a>(prefix: &str, line: &'a str) -> Option<Report<'a>> {
    let rest = line.strip_prefix(prefix)?;
    let (words, text) = match rest.split_once(" text=") {
        Some((words, text)) => (words, Some(text)),
        None => (rest, None),
    };
    let mut map: Report = words.split_whitespace().filter_map(|kv| kv.split_once('=')).collect();
    if let Some(text) = text {
        map.insert("text", text);
    }
    map.contains_key("boot").then_some(map)
}

fn num(map: &Report, key: &str) -> Option<u64> {
    let v = map.get(key)?;
    match v.strip_prefix("0x") {
        Some(hex) => u64::from_str_radix(hex, 16).ok(),
        None => v.parse().ok(),
    }
}

/// Every boot's report and the earlier stops they found, by boot.
struct Run<'a> {
    boots: Vec<Report<'a>>,
    earlier: Vec<Report<'a>>,
}

impl<'a> Run<'a> {
    fn parse(stdout: &'a str) -> Self {
        let of = |prefix: &str| stdout.lines().filter_map(|l| parse_line(prefix, l)).collect();
        Run { boots: of("failsafe "), earlier: of(EARLIER) }
    }

    fn find<'r>(list: &'r [Report<'a>], boot: u32) -> Option<&'r Report<'a>> {
        list.iter().find(|b| num(b, "boot") == Some(u64::from(boot)))
    }

    /// Boot `boot`'s report.
    fn boot(&self, boot: u32) -> Option<&Report<'a>> {
        Self::find(&self.boots, boot)
    }

    /// The earlier stop boot `boot` found, if it found one.
    fn earlier(&self, boot: u32) -> Option<&Report<'a>> {
        Self::find(&self.earlier, boot)
    }
}

/// The checks of every stop path (the hang's and [`KEPT`]'s too) from the runner's stdout and
/// whether it exited with success.
pub fn checks(stdout: &str, exited_ok: bool) -> Vec<Check> {
    let run = Run::parse(stdout);
    let boots = &run.boots;
    let order: Vec<Option<u64>> = boots.iter().map(|b| num(b, "boot")).collect();
    let expected: Vec<Option<u64>> = (1..=BOOTS).map(Some).collect();
    let sequence_ok = order == expected;
    FAILSAFE_KINDS
        .iter()
        .map(|&(kind, reason, boot)| {
            let mut why = Vec::new();
            if !sequence_ok {
                why.push(format!(
                    "boots reported {order:?}, not 1..={}: the boot counter or a reset failed",
                    expected.len()
                ));
            }
            if !exited_ok {
                why.push("the runner did not exit with success after its last boot".into());
            }
            let Some(b) = run.boot(boot) else {
                why.push(format!("boot {boot} never reported"));
                return Check { kind, first: false, survived: false, reported: false, why };
            };
            let (mut first, mut survived, mut reported) = (true, true, true);
            let mut need = |flag: &mut bool, ok: bool, what: String| {
                if !ok {
                    *flag = false;
                    why.push(what);
                }
            };
            need(
                &mut reported,
                b.get("reason") == Some(&reason) && sequence_ok && exited_ok,
                format!("boot {boot} reported reason={}", b.get("reason").unwrap_or(&"?")),
            );
            need(
                &mut survived,
                num(b, "cfsr") == Some(0) && num(b, "iser0") == Some(0),
                "fault status or interrupt enables survived: not a system reset".into(),
            );
            let flags = [&mut first, &mut survived, &mut reported];
            match kind {
                HANG => hang_checks(b, &run, boot, flags, &mut need),
                KEPT => kept_checks(b, &run, boot, flags, &mut need),
                _ => stop_checks(b, kind, reason, flags, &mut need),
            }
            Check { kind, first, survived, reported, why }
        })
        .collect()
}

/// What a stop path's report must hold beyond its reason: the order of its stamps and the
/// record's kind-specific fields. `need(flag, ok, why)` clears `flag` and notes `why` unless `ok`.
fn stop_checks(
    b: &Report,
    kind: &str,
    reason: &str,
    [first, survived, reported]: [&mut bool; 3],
    need: &mut impl FnMut(&mut bool, bool, String),
) {
    stamp_checks(b, first, need);
    need(survived, b.get("reason") == Some(&reason), "no intact record of this kind after the reset".into());
    need(survived, num(b, "record_ok_after") == Some(1), "the record did not read back after stop".into());
    need(
        reported,
        b.get("earlier") == Some(&"none"),
        format!("earlier={}, not none: a stop reported and let go came back", b.get("earlier").unwrap_or(&"?")),
    );
    need(survived, fields_ok(kind, b), format!("{kind} record fields wrong: {b:?}"));
}

/// The stamps of the stop path a boot reports: the safe-outputs hook first (stamp 1), while the
/// records still held what the boot had left in them, then the record (stamp 2), the outputs
/// safe.
fn stamp_checks(b: &Report, first: &mut bool, need: &mut impl FnMut(&mut bool, bool, String)) {
    let stamps = (num(b, "safe_seq"), num(b, "record_seq"), num(b, "record_before_safe"), num(b, "outputs_safe"));
    need(
        first,
        stamps == (Some(1), Some(2), Some(0), Some(1)),
        format!("safe_seq, record_seq, record_before_safe, outputs_safe = {stamps:?}, not (1, 2, 0, 1)"),
    );
}

/// Whether a stop's fields are those its path (`kind`, as [`FAILSAFE_KINDS`] names it) records
/// on the PIL; `b` is a boot's report of it or an [`EARLIER`] line.
fn fields_ok(kind: &str, b: &Report) -> bool {
    let detail = num(b, "detail").unwrap_or(u64::MAX);
    match kind {
        "panic" => detail > 0 && b.get("text").is_some_and(|t| t.ends_with("failsafe.rs")),
        "hard_fault" => num(b, "addr") == Some(FAULT_ADDR) && detail & u64::from(hter::failsafe::CFSR_BFARVALID) != 0,
        "nmi" => detail & 0x1ff == NMI_EXCEPTION,
        // The guard was armed, the fault's address is in it, the frame went into it, and
        // the canary below it is whole: the overflow stopped at the guard.
        "stack_overflow" => {
            let guard = b.get("guard").and_then(|g| g.split_once('-')).and_then(|(lo, hi)| {
                let hex = |v: &str| u64::from_str_radix(v.strip_prefix("0x")?, 16).ok();
                Some(hex(lo)?..hex(hi)?)
            });
            num(b, "armed") == Some(1)
                && num(b, "canary_ok") == Some(1)
                && b.get("text") == Some(&"stack overflow")
                && detail & u64::from(hter::failsafe::CFSR_MSTKERR) != 0
                && guard.zip(num(b, "addr")).is_some_and(|(g, a)| g.contains(&a))
        }
        _ => detail == 0,
    }
}

/// Whether two lines name the same stop, field for field (a `None` or a line without a reason is
/// none).
fn same_stop(a: Option<&Report>, b: Option<&Report>) -> bool {
    const FIELDS: [&str; 5] = ["reason", "pc", "addr", "detail", "text"];
    a.zip(b).is_some_and(|(a, b)| a.contains_key("reason") && FIELDS.iter().all(|k| a.get(k) == b.get(k)))
}

/// A stop's fields as one line of a reason (`none` if there is no stop).
fn describe(s: Option<&Report>) -> String {
    let Some(s) = s.filter(|s| s.contains_key("reason") && s.get("reason") != Some(&"none")) else {
        return "none".into();
    };
    let f = |k: &str| s.get(k).copied().unwrap_or("?");
    format!("{} pc={} addr={} detail={} text={}", f("reason"), f("pc"), f("addr"), f("detail"), f("text"))
}

/// What the report of the boot after the hang must hold beyond its reason (`control_stall`):
/// a watchdog reset and the evidence the runner drew it from (the watchdog armed, its first
/// timeout's interrupt passed over, the watchdog back in its reset state), the phase marker the
/// hang wrote, the stop of that phase (`hter::failsafe::boot_stall`) with the stop the hung boot
/// had read and not let go beside it (the stack overflow's `hard_fault`, as the hung boot
/// reported it), and after another reset that stop alone, none from the marker.
fn hang_checks(
    b: &Report,
    run: &Run,
    boot: u32,
    [first, survived, reported]: [&mut bool; 3],
    need: &mut impl FnMut(&mut bool, bool, String),
) {
    use hter::failsafe::BootPhase;
    let field = |k: &str| b.get(k).copied().unwrap_or("?");
    let evidence = (num(b, "wdog_armed"), num(b, "wdog_nmi").is_some_and(|n| n >= 1), num(b, "wdog_control"));
    need(
        first,
        b.get("reset") == Some(&"watchdog") && evidence == (Some(1), true, Some(0)),
        format!(
            "no watchdog reset: reset={} wdog_armed={} wdog_nmi={} wdog_control={}",
            field("reset"),
            field("wdog_armed"),
            field("wdog_nmi"),
            field("wdog_control")
        ),
    );
    let phase = BootPhase::Restore;
    need(
        survived,
        num(b, "marker") == Some(u64::from(phase.marker())),
        format!("marker={}, not {phase:?}'s {:#010x}", field("marker"), phase.marker()),
    );
    // The boot stall's contract (`StopKind::ControlStall`'s docs): no PC, the phase's number as
    // the address, 0 ms (a stall the control loop's check notices is never 0 ms).
    let stop = (num(b, "pc"), num(b, "addr"), num(b, "detail"));
    let want = (Some(0), Some(phase as u64), Some(0));
    need(reported, stop == want, format!("the stop's pc, addr, detail = {stop:?}, not {want:?}"));
    let (kept, was) = (run.earlier(boot), run.boot(boot - 1));
    need(
        reported,
        b.get("earlier") == Some(&"hard_fault") && same_stop(kept, was),
        format!(
            "earlier={} ({}), not the overflow's hard_fault the hung boot had not let go ({})",
            field("earlier"),
            describe(kept),
            describe(was)
        ),
    );
    need(
        reported,
        b.get("if_other") == Some(&"hard_fault") && b.get("if_brown_out") == Some(&"hard_fault"),
        format!(
            "after another reset the rule gives if_other={} if_brown_out={}, not the kept hard_fault alone",
            field("if_other"),
            field("if_brown_out")
        ),
    );
}

/// What the report of the boot after [`KEPT`]'s stop path must hold beyond its reason
/// (`hard_fault`), with the reports of the boot before it and of the boot after it: the stop
/// path's stamps (the hook ran while the records still held the unstored panic as its boot left
/// them), the HardFault's own fields, the panic kept beside it as the earlier stop with a panic's
/// fields, the very ones the boot before reported, the HardFault fresh; the boot before found the
/// panic fresh and alone (the boot before it let the hang's two go); and the boot after this one
/// finds no stop at all, this one having let both go.
fn kept_checks(
    b: &Report,
    run: &Run,
    boot: u32,
    [first, survived, reported]: [&mut bool; 3],
    need: &mut impl FnMut(&mut bool, bool, String),
) {
    let field = |s: Option<&Report>, k: &str| s.and_then(|s| s.get(k)).map_or("?".to_string(), |v| v.to_string());
    stamp_checks(b, first, need);
    need(survived, num(b, "record_ok_after") == Some(1), "the record did not read back after stop".into());
    need(survived, fields_ok("hard_fault", b), format!("hard_fault record fields wrong: {b:?}"));
    let (kept, was) = (run.earlier(boot), run.boot(boot - 1));
    need(
        survived,
        kept.is_some_and(|k| k.get("reason") == Some(&"panic") && fields_ok("panic", k)) && same_stop(kept, was),
        format!(
            "boot {boot} kept {} as the earlier stop, not the panic boot {} reported and did not let go ({})",
            describe(kept),
            boot - 1,
            describe(was)
        ),
    );
    need(
        reported,
        num(b, "fresh") == Some(1),
        format!("boot {boot} fresh={}, not 1: the HardFault is the reason it started", field(Some(b), "fresh")),
    );
    need(
        reported,
        was.is_some_and(|w| w.get("reason") == Some(&"panic") && w.get("earlier") == Some(&"none"))
            && was.and_then(|w| num(w, "fresh")) == Some(1),
        format!(
            "boot {} reported reason={} fresh={} earlier={}, not a fresh panic alone",
            boot - 1,
            field(was, "reason"),
            field(was, "fresh"),
            field(was, "earlier")
        ),
    );
    let after = run.boot(boot + 1);
    need(
        reported,
        after.is_some_and(|a| a.get("reason") == Some(&"none") && a.get("earlier") == Some(&"none")),
        format!(
            "boot {} found reason={} earlier={}, not none: the stops boot {boot} let go came back",
            boot + 1,
            field(after, "reason"),
            field(after, "earlier")
        ),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "\
failsafe boot=1 cfsr=0x0 iser0=0x0 reason=none
failsafe boot=2 cfsr=0x0 iser0=0x0 fresh=1 earlier=none reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=src/bin/failsafe.rs
failsafe boot=3 cfsr=0x0 iser0=0x0 fresh=1 earlier=none reason=hard_fault pc=0x00000dac addr=0xf0000000 detail=0x8200 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=4 cfsr=0x0 iser0=0x0 fresh=1 earlier=none reason=nmi pc=0x00000000 addr=0x00000000 detail=0x802 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=5 cfsr=0x0 iser0=0x0 fresh=1 earlier=none reason=unexpected_interrupt pc=0x00000000 addr=0x00000000 detail=0x0 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=6 cfsr=0x0 iser0=0x0 guard=0x20000400-0x20000800 armed=1 fresh=1 earlier=none reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 canary_ok=1 text=stack overflow
failsafe boot=7 cfsr=0x0 iser0=0x0 guard=0x20000400-0x20000800 armed=1 reset=watchdog marker=0xb0070002 wdog_armed=1 wdog_nmi=1 wdog_control=0x0 if_other=hard_fault if_brown_out=hard_fault fresh=1 earlier=hard_fault reason=control_stall pc=0x00000000 addr=0x00000002 detail=0x0 safe_seq=0 record_seq=0 record_before_safe=0 record_ok_after=0 outputs_safe=0 canary_ok=0 text=
failsafe-earlier boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 text=stack overflow
failsafe boot=8 cfsr=0x0 iser0=0x0 reset=other marker=0x00000000 if_other=panic if_brown_out=panic fresh=1 earlier=none reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=src/bin/failsafe.rs
failsafe boot=9 cfsr=0x0 iser0=0x0 reset=other marker=0x00000000 if_other=hard_fault if_brown_out=hard_fault fresh=1 earlier=panic reason=hard_fault pc=0x00000dac addr=0xf0000000 detail=0x8200 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe-earlier boot=9 reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 text=src/bin/failsafe.rs
failsafe boot=10 cfsr=0x0 iser0=0x0 reset=other marker=0x00000000 if_other=none if_brown_out=none fresh=0 earlier=none reason=none
";

    fn oks(out: &str, exited: bool) -> Vec<(bool, bool, bool)> {
        checks(out, exited).iter().map(|c| (c.first, c.survived, c.reported)).collect()
    }

    /// The check of `kind`.
    fn of(kind: &str, out: &str, exited: bool) -> Check {
        checks(out, exited).into_iter().find(|c| c.kind == kind).expect("a check of that kind")
    }

    #[test]
    fn a_good_run_passes_every_check() {
        let c = checks(GOOD, true);
        assert!(c.iter().all(Check::ok), "{c:?}");
        assert!(c.iter().all(|c| c.why.is_empty()), "{c:?}");
        assert_eq!(c.len(), 7);
    }

    #[test]
    fn each_broken_step_fails_its_own_check() {
        // The record written before the outputs were driven safe.
        let late = GOOD.replacen("record_before_safe=0", "record_before_safe=1", 1);
        assert_eq!(oks(&late, true)[0], (false, true, true));
        // The hook stamped second.
        let second = GOOD.replace(
            "reason=nmi pc=0x00000000 addr=0x00000000 detail=0x802 safe_seq=1 record_seq=2",
            "reason=nmi pc=0x00000000 addr=0x00000000 detail=0x802 safe_seq=2 record_seq=1",
        );
        assert_eq!(oks(&second, true)[2], (false, true, true));
        // The wrong fault address.
        let addr = GOOD.replace("addr=0xf0000000", "addr=0x00000000");
        assert_eq!(oks(&addr, true)[1], (true, false, true));
        // Fault status still set at the next boot: the CPU jumped to the reset vector.
        let no_reset = GOOD.replace("boot=4 cfsr=0x0", "boot=4 cfsr=0x8200");
        assert_eq!(oks(&no_reset, true)[2], (true, false, true));
        // A stop reported and let go found again by the next boot.
        let again = GOOD
            .replace("earlier=none reason=hard_fault pc=0x00000dac", "earlier=panic reason=hard_fault pc=0x00000dac");
        assert_eq!(oks(&again, true)[1], (true, true, false));
        // The record lost across the reset: the next boot finds none.
        let lost = GOOD.replace("reason=panic", "reason=none");
        assert_eq!(oks(&lost, true)[0], (true, false, false));
        // The overflow ran past the guard (the canary below it overwritten), faulted outside it,
        // was not told from another HardFault, or the guard was never armed.
        for broken in [
            GOOD.replace("canary_ok=1", "canary_ok=0"),
            GOOD.replace("addr=0x200007fc", "addr=0x200003fc"),
            GOOD.replace("text=stack overflow", "text="),
            GOOD.replace(" armed=1", " armed=0"),
        ] {
            assert_eq!(oks(&broken, true)[4], (true, false, true), "{broken}");
        }
    }

    /// Each way the hang's boot can go wrong fails its own check of the hang, with a reason.
    #[test]
    fn a_hang_without_a_watchdog_reset_or_its_marker_fails() {
        let hang = |out: &str| of(HANG, out, true);
        // Reset by something else (SYSRESETREQ: the watchdog's interrupt never came), the
        // watchdog never armed, or still armed after the "reset" (a jump to the reset vector).
        for broken in [
            GOOD.replace("reset=watchdog", "reset=other"),
            GOOD.replace("wdog_nmi=1", "wdog_nmi=0"),
            GOOD.replace("wdog_armed=1", "wdog_armed=0"),
            GOOD.replace("wdog_control=0x0", "wdog_control=0x3"),
        ] {
            let c = hang(&broken);
            assert_eq!((c.first, c.survived, c.reported), (false, true, true), "{broken}");
            assert!(c.why.iter().any(|w| w.starts_with("no watchdog reset")), "{:?}", c.why);
        }
        // The marker lost (or never written): no stop either.
        let lost = GOOD.replace("marker=0xb0070002", "marker=0x00000000").replace(
            "reason=control_stall pc=0x00000000 addr=0x00000002 detail=0x0 safe_seq=0 record_seq=0 record_before_safe=0 record_ok_after=0 outputs_safe=0 canary_ok=0 text=",
            "reason=none",
        );
        let c = hang(&lost);
        assert_eq!((c.first, c.survived, c.reported), (true, false, false), "{:?}", c.why);
        // Another phase's stop, a stop from the marker after another reset, or the overflow
        // not kept beside it, or kept other than the hung boot reported it.
        for broken in [
            GOOD.replace("addr=0x00000002", "addr=0x00000003"),
            GOOD.replace("if_other=hard_fault", "if_other=control_stall"),
            GOOD.replace("if_brown_out=hard_fault", "if_brown_out=control_stall"),
            GOOD.replace("earlier=hard_fault", "earlier=none").replace(
                "failsafe-earlier boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 text=stack overflow\n",
                "",
            ),
            GOOD.replace("boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92", "boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x82"),
            GOOD.replace("boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 text=stack overflow", "boot=7 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 text=stack"),
        ] {
            let c = hang(&broken);
            assert_eq!((c.first, c.survived, c.reported), (true, true, false), "{broken}");
            assert_eq!(c.why.len(), 1, "{:?}", c.why);
        }
        // The watchdog never reset the hung boot: QEMU was killed at the time limit.
        let six: String = GOOD.lines().take(6).map(|l| format!("{l}\n")).collect();
        let c = of(HANG, &six, false);
        assert!(!c.first && !c.survived && !c.reported);
        assert!(c.why.contains(&"boot 7 never reported".to_string()), "{:?}", c.why);
    }

    /// Each way the stop path after an unstored stop can go wrong fails its own check of
    /// [`KEPT`], with one reason.
    #[test]
    fn a_stop_path_that_loses_the_unstored_stop_fails() {
        let kept = |out: &str| of(KEPT, out, true);
        let line9 =
            "failsafe-earlier boot=9 reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 text=src/bin/failsafe.rs";
        // The panic let go before the HardFault's stop path (no earlier stop), a record of
        // another stop there, or the panic's fields not as boot 8 reported them (its line, its
        // text cut, its own fields lost).
        for broken in [
            GOOD.replace("earlier=panic", "earlier=none").replace(&format!("{line9}\n"), ""),
            GOOD.replace("earlier=panic", "earlier=nmi").replace(line9, &line9.replace("reason=panic", "reason=nmi")),
            GOOD.replace(line9, &line9.replace("detail=0x99", "detail=0x98")),
            GOOD.replace(line9, &line9.replace("text=src/bin/failsafe.rs", "text=src/bin/fail")),
            GOOD.replace(line9, &line9.replace("detail=0x99", "detail=0x0")).replace(
                "earlier=none reason=panic pc=0x00000000 addr=0x00000000 detail=0x99",
                "earlier=none reason=panic pc=0x00000000 addr=0x00000000 detail=0x0",
            ),
        ] {
            let c = kept(&broken);
            assert_eq!((c.first, c.survived, c.reported), (true, false, true), "{broken}");
            assert_eq!(c.why.len(), 1, "{:?}", c.why);
            assert!(c.why[0].starts_with("boot 9 kept "), "{:?}", c.why);
        }
        // The new stop written before the outputs were safe (the hook found the records other
        // than boot 8 left them), or its own fields wrong.
        let c = kept(&GOOD.replace(
            "record_before_safe=0 record_ok_after=1 outputs_safe=1 text=\nfailsafe-earlier boot=9",
            "record_before_safe=1 record_ok_after=1 outputs_safe=1 text=\nfailsafe-earlier boot=9",
        ));
        assert_eq!((c.first, c.survived, c.reported), (false, true, true), "{:?}", c.why);
        let c = kept(&GOOD.replace(
            "earlier=panic reason=hard_fault pc=0x00000dac addr=0xf0000000",
            "earlier=panic reason=hard_fault pc=0x00000dac addr=0x00000000",
        ));
        assert_eq!((c.first, c.survived, c.reported), (true, false, true), "{:?}", c.why);
        // The new stop not fresh, the panic not alone at boot 8 (the hang's stops not let go),
        // or a stop still there after boot 9 let both go.
        for broken in [
            GOOD.replace("fresh=1 earlier=panic", "fresh=0 earlier=panic"),
            GOOD.replace("fresh=1 earlier=none reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=src/bin/failsafe.rs\nfailsafe boot=9", "fresh=1 earlier=hard_fault reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=src/bin/failsafe.rs\nfailsafe boot=9"),
            GOOD.replace("fresh=0 earlier=none reason=none", "fresh=0 earlier=none reason=hard_fault pc=0x00000dac addr=0xf0000000 detail=0x8200 text="),
            GOOD.replace("fresh=0 earlier=none reason=none", "fresh=0 earlier=panic reason=none"),
        ] {
            let c = kept(&broken);
            assert_eq!((c.first, c.survived, c.reported), (true, true, false), "{broken}");
            assert_eq!(c.why.len(), 1, "{:?}", c.why);
        }
        // The run ended before the boot that shows what is left after the store.
        let nine: String =
            GOOD.lines().filter(|l| !l.starts_with("failsafe boot=10 ")).map(|l| format!("{l}\n")).collect();
        let c = of(KEPT, &nine, true);
        assert!(!c.reported, "{:?}", c.why);
        assert!(c.why.iter().any(|w| w.contains("not 1..=10")), "{:?}", c.why);
    }

    #[test]
    fn a_wiped_boot_counter_or_a_hang_fails_everything() {
        let looping = "failsafe boot=1 cfsr=0x0 iser0=0x0 reason=none\n".repeat(50);
        assert!(checks(&looping, false).iter().all(|c| !c.ok()));
        let first_two: String = GOOD.lines().take(2).map(|l| format!("{l}\n")).collect();
        let c = checks(&first_two, false);
        assert!(c.iter().all(|c| !c.ok()));
        assert!(!c[1].reported && !c[1].survived && !c[1].first, "boot 3 never ran");
        assert!(checks(GOOD, false).iter().all(|c| !c.reported), "a failed exit is not a report");
    }
}
