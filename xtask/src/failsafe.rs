//! The fail-safe part of `cargo xtask pil`: boots `pil`'s `failsafe` binary on QEMU mps2-an386
//! and checks, for each stop path, what its boots report on semihosting stdout. The last path is
//! a stack overflow into the MPU stack guard (QEMU models the ARMv7-M MPU): it must end in the
//! HardFault's stop path, recorded as a stack overflow, with nothing below the guard written.
//!
//! QEMU turns the guest's SYSRESETREQ (`SCB::sys_reset`) into a machine reset
//! (`qemu_system_reset_request`; with `-no-reboot` the same request makes QEMU exit instead, which
//! is how this was verified): the CPU restarts from the reset vector, the fault status and NVIC
//! state are cleared, and RAM outside the ELF's loaded segments keeps its contents. The ELF's
//! `.uninit` statics are in a segment with no file bytes, which QEMU's loader does not re-zero
//! at reset; the checks below fail if that ever changes (the record would not survive).

use std::collections::HashMap;
use std::path::Path;
use std::time::Duration;

use anyhow::Result;

/// Each stop path, the reason its record names and the boot that reports it (the boot after the
/// one that triggered it). A stack overflow is a HardFault record with its own text.
pub const FAILSAFE_KINDS: [(&str, &str, u32); 5] = [
    ("panic", "panic", 2),
    ("hard_fault", "hard_fault", 3),
    ("nmi", "nmi", 4),
    ("unexpected_interrupt", "unexpected_interrupt", 5),
    ("stack_overflow", "hard_fault", 6),
];
/// The address the HardFault boot reads (the runner's `UNMAPPED`).
const FAULT_ADDR: u64 = 0xF000_0000;
/// ICSR.VECTACTIVE of the NMI (exception number 2), the NMI record's `detail` on the PIL.
const NMI_EXCEPTION: u64 = 2;
/// Six boots take well under a second; a broken boot counter loops forever.
const FAILSAFE_TIMEOUT: Duration = Duration::from_secs(60);

/// The three checks of one stop path.
#[derive(Debug)]
pub struct Check {
    pub kind: &'static str,
    /// The safe-outputs hook ran first: stamp 1, before the record was valid, record stamp 2.
    pub first: bool,
    /// The record crossed a real reset intact (magic + CRC, kind, kind-specific fields).
    pub survived: bool,
    /// The next boot (the boot counter advanced by one) reported it.
    pub reported: bool,
    /// Why a check failed, one line each.
    pub why: Vec<String>,
}

impl Check {
    pub fn ok(&self) -> bool {
        self.first && self.survived && self.reported
    }
}

/// Boots the runner until it exits; returns the checks.
pub fn run(elf: &Path, work: &Path) -> Result<Vec<Check>> {
    let dir = work.join("failsafe");
    std::fs::create_dir_all(&dir)?;
    let run = crate::qemu(elf, &dir, &[], FAILSAFE_TIMEOUT)?;
    let (exited_ok, out) = (run.status.is_some_and(|s| s.success()), run.stdout);
    std::fs::write(dir.join("stdout.txt"), &out)?;
    Ok(checks(&out, exited_ok))
}

/// One boot's report: `failsafe boot=<n> key=value ... text=<the rest of the line>`.
fn parse_line(line: &str) -> Option<HashMap<&str, &str>> {
    let rest = line.strip_prefix("failsafe ")?;
    let (words, text) = match rest.split_once(" text=") {
        Some((words, text)) => (words, Some(text)),
        None => (rest, None),
    };
    let mut map: HashMap<&str, &str> = words.split_whitespace().filter_map(|kv| kv.split_once('=')).collect();
    if let Some(text) = text {
        map.insert("text", text);
    }
    map.contains_key("boot").then_some(map)
}

fn num(map: &HashMap<&str, &str>, key: &str) -> Option<u64> {
    let v = map.get(key)?;
    match v.strip_prefix("0x") {
        Some(hex) => u64::from_str_radix(hex, 16).ok(),
        None => v.parse().ok(),
    }
}

/// The checks of every stop path from the runner's stdout and whether it exited with success.
pub fn checks(stdout: &str, exited_ok: bool) -> Vec<Check> {
    let boots: Vec<HashMap<&str, &str>> = stdout.lines().filter_map(parse_line).collect();
    let order: Vec<Option<u64>> = boots.iter().map(|b| num(b, "boot")).collect();
    let expected: Vec<Option<u64>> = (1..=FAILSAFE_KINDS.len() as u64 + 1).map(Some).collect();
    let sequence_ok = order == expected;
    FAILSAFE_KINDS
        .iter()
        .map(|&(kind, reason, boot)| {
            let mut c = Check { kind, first: true, survived: true, reported: true, why: Vec::new() };
            if !sequence_ok {
                c.why.push(format!(
                    "boots reported {order:?}, not 1..={}: the boot counter or a reset failed",
                    expected.len()
                ));
            }
            if !exited_ok {
                c.why.push("the runner did not exit with success after its last boot".into());
            }
            let Some(b) = boots.iter().find(|b| num(b, "boot") == Some(u64::from(boot))) else {
                c.why.push(format!("boot {boot} never reported"));
                c.first = false;
                c.survived = false;
                c.reported = false;
                return c;
            };
            let mut need = |flag: &mut bool, ok: bool, what: String| {
                if !ok {
                    *flag = false;
                    c.why.push(what);
                }
            };
            let (mut first, mut survived, mut reported) = (true, true, true);
            need(
                &mut reported,
                b.get("reason") == Some(&reason) && sequence_ok && exited_ok,
                format!("boot {boot} reported reason={}", b.get("reason").unwrap_or(&"?")),
            );
            let stamps =
                (num(b, "safe_seq"), num(b, "record_seq"), num(b, "record_before_safe"), num(b, "outputs_safe"));
            need(
                &mut first,
                stamps == (Some(1), Some(2), Some(0), Some(1)),
                format!("safe_seq, record_seq, record_before_safe, outputs_safe = {stamps:?}, not (1, 2, 0, 1)"),
            );
            need(
                &mut survived,
                b.get("reason") == Some(&reason),
                "no intact record of this kind after the reset".into(),
            );
            need(&mut survived, num(b, "record_ok_after") == Some(1), "the record did not read back after stop".into());
            need(
                &mut survived,
                num(b, "cfsr") == Some(0) && num(b, "iser0") == Some(0),
                "fault status or interrupt enables survived: not a system reset".into(),
            );
            let detail = num(b, "detail").unwrap_or(u64::MAX);
            let specific = match kind {
                "panic" => detail > 0 && b.get("text").is_some_and(|t| t.ends_with("failsafe.rs")),
                "hard_fault" => {
                    num(b, "addr") == Some(FAULT_ADDR) && detail & u64::from(hter::failsafe::CFSR_BFARVALID) != 0
                }
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
            };
            need(&mut survived, specific, format!("{kind} record fields wrong: {b:?}"));
            c.first = first;
            c.survived = survived;
            c.reported = reported;
            c
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "\
failsafe boot=1 cfsr=0x0 iser0=0x0 reason=none
failsafe boot=2 cfsr=0x0 iser0=0x0 reason=panic pc=0x00000000 addr=0x00000000 detail=0x99 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=src/bin/failsafe.rs
failsafe boot=3 cfsr=0x0 iser0=0x0 reason=hard_fault pc=0x00000dac addr=0xf0000000 detail=0x8200 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=4 cfsr=0x0 iser0=0x0 reason=nmi pc=0x00000000 addr=0x00000000 detail=0x802 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=5 cfsr=0x0 iser0=0x0 reason=unexpected_interrupt pc=0x00000000 addr=0x00000000 detail=0x0 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 text=
failsafe boot=6 cfsr=0x0 iser0=0x0 guard=0x20000400-0x20000800 armed=1 reason=hard_fault pc=0x00000000 addr=0x200007fc detail=0x92 safe_seq=1 record_seq=2 record_before_safe=0 record_ok_after=1 outputs_safe=1 canary_ok=1 text=stack overflow
";

    fn oks(out: &str, exited: bool) -> Vec<(bool, bool, bool)> {
        checks(out, exited).iter().map(|c| (c.first, c.survived, c.reported)).collect()
    }

    #[test]
    fn a_good_run_passes_every_check() {
        let c = checks(GOOD, true);
        assert!(c.iter().all(Check::ok), "{c:?}");
        assert_eq!(c.len(), 5);
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
        // The record lost across the reset: the next boot finds none.
        let lost = GOOD.replace("reason=panic", "reason=none");
        assert_eq!(oks(&lost, true)[0], (true, false, false));
        // The overflow ran past the guard (the canary below it overwritten), faulted outside it,
        // was not told from another HardFault, or the guard was never armed.
        for broken in [
            GOOD.replace("canary_ok=1", "canary_ok=0"),
            GOOD.replace("addr=0x200007fc", "addr=0x200003fc"),
            GOOD.replace("text=stack overflow", "text="),
            GOOD.replace("armed=1", "armed=0"),
        ] {
            assert_eq!(oks(&broken, true)[4], (true, false, true), "{broken}");
        }
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
