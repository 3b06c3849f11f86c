//! Host automation for hter (`cargo xtask <command>`).
//!
//! `cargo xtask pil` — processor-in-the-loop: records ADC counts from closed-loop `hal-sim` runs
//! (and one made-up sequence that meets GPC's soft floor, which no closed-loop run at the board's
//! tuning does: it reports those samples' instructions apart, and fails when no sample meets the
//! floor), builds the bare-metal runner `pil/` for the Cortex-M4F (thumbv7em-none-eabihf), runs it
//! under QEMU (`-M mps2-an386`, `-icount shift=6,sleep=off`: deterministic virtual time, one
//! instruction = 64 ns), and checks that every duty (bit for bit) and every event and alarm the
//! target computes equals what the same library code computes here on the host from the same
//! counts. It reports the instructions per sample (the step plus the cold-chain monitor), a profile
//! by part, the runner's flash and RAM, and ends with one JSON line. It runs the cases twice: on
//! the runner built with `pil/Cargo.toml`'s release profile (the runner's own crate at opt-level
//! 3), held to [`BUDGET_INSN`], and on the runner built as the firmware is (`[profile.board]`, the
//! root crate at "z", which under fat LTO sets how the step is compiled), reported and not held to
//! it. It exits non-zero when a bit differs in either or when a self-tuning GPC sample of the first
//! takes more than [`BUDGET_INSN`] instructions. Once, from the first build, it boots `pil`'s
//! `failsafe` binary, which takes a panic, a HardFault, an NMI, an unexpected interrupt and a stack
//! overflow into the MPU stack guard through the firmware's stop path, each across a real system
//! reset, then hangs a boot in its flash-restore phase until the emulated board's watchdog resets
//! it, then stops a boot on a real stop path before it let its stop go, and checks each path,
//! that the next boot makes the firmware's boot stall of the hang, and that the stop path kept
//! the stop not yet let go beside its own ([`failsafe`]); the JSON line's `failsafe` object says
//! which passed, and any `false` fails the command.
//!
//! `cargo xtask size` — the firmware's footprint: builds the release firmware once per
//! controller (the default self-tuning GPC, the same on the buck drive, then each controller
//! feature), prints flash
//! (allocated sections with contents: what is programmed) and static RAM (allocated sections
//! in SRAM: .data, .bss, .uninit) for each, and ends with one JSON line. It exits non-zero when
//! a build exceeds [`FLASH_BUDGET`] or [`RAM_BUDGET`].
//!
//! `cargo xtask audit` — the release firmware image's fail-safe properties ([`audit`]): fault
//! handlers that do more than spin, defmt-rtt that cannot block, the program in flash bank 1;
//! `cargo xtask audit --features interface` audits that build and checks USART2's handler is bound;
//! `cargo xtask audit --features buck` audits the buck build and checks that its safe-output
//! routine writes TIM1's main-output and channel-enable registers.

#[path = "../../pil/src/proto.rs"]
#[allow(dead_code)]
mod proto;

mod audit;
mod code;
mod failsafe;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, Fault, SimOptions};
use hter::step::{BoardReadings, StepInput};

/// Worst-case instructions allowed for one sample (step + monitor) with self-tuning GPC, on the
/// first pass (the runner's own crate at opt-level 3); the board-like pass is not held to it.
const BUDGET_INSN: f64 = 5000.0;
/// Release firmware flash budget, bytes: the product's 64 KiB, so that the firmware also fits
/// parts much smaller than the NUCLEO's 1 MiB STM32L476RG.
const FLASH_BUDGET: u64 = 64 * 1024;
/// Release firmware static RAM budget, bytes: the product's 16 KiB (the L476RG's SRAM1 has 96).
const RAM_BUDGET: u64 = 16 * 1024;
/// The firmware builds `size` reports: (cargo features, what they run, flash budget, static RAM
/// budget).
const FIRMWARE_BUILDS: [(&str, &str, u64, u64); 10] = [
    ("", "self-tuning GPC (default)", FLASH_BUDGET, RAM_BUDGET),
    ("module-sense", "GPC, module-side sense", FLASH_BUDGET, RAM_BUDGET),
    // The largest 64 KiB build as a calibrated board flashes it (`config::CALIBRATION` filled in).
    ("module-sense,calibrated", "GPC, module-side sense, calibrated", FLASH_BUDGET, RAM_BUDGET),
    ("buck", "self-tuning GPC, buck drive", FLASH_BUDGET, RAM_BUDGET),
    ("igmvc", "self-tuning IGMVC", FLASH_BUDGET, RAM_BUDGET),
    ("pi", "PI", FLASH_BUDGET, RAM_BUDGET),
    ("onoff", "On-Off", FLASH_BUDGET, RAM_BUDGET),
    ("identify", "identification PRBS", FLASH_BUDGET, RAM_BUDGET),
    ("interface", "GPC + interface (issue 16)", INTERFACE_FLASH_BUDGET, INTERFACE_RAM_BUDGET),
    ("interface,module-sense", "interface, module-side sense", INTERFACE_FLASH_BUDGET, INTERFACE_RAM_BUDGET),
];
/// The interface build's flash budget, bytes: it does not fit the product's 64 KiB (README,
/// "Flash budget": the board application, the log, commissioning and USART2 cost ≈ 55 KiB), so
/// it is held to the next STM32L4 part size, 128 KiB (e.g. the L412/L422).
const INTERFACE_FLASH_BUDGET: u64 = 128 * 1024;
/// The interface build's static RAM budget, bytes: 32 KiB (those parts have 40 KiB).
const INTERFACE_RAM_BUDGET: u64 = 32 * 1024;
/// SysTick counts per instruction expected under `-icount shift=6` at 25 MHz (64 ns / 40 ns).
const TICKS_PER_INSN: f64 = 1.6;
/// Longest a QEMU run may take before it is killed.
const QEMU_TIMEOUT: Duration = Duration::from_secs(300);
const TARGET: &str = "thumbv7em-none-eabihf";

/// One recorded sequence: a closed-loop `hal-sim` run, or (`synthetic`) inputs made up to reach
/// a path no such run reaches.
struct Case {
    name: &'static str,
    scenario: &'static str,
    duration_s: Option<f64>,
    kind: u32,
    faults: &'static [&'static str],
    /// The board has the module-side sense (the firmware's `module-sense` build).
    module_sense: bool,
    synthetic: Option<fn() -> Vec<StepInput>>,
}

const CASES: [Case; 7] = [
    Case {
        name: "piecewise, self-tuning GPC",
        scenario: "piecewise",
        duration_s: None,
        kind: proto::KIND_GPC,
        faults: &[],
        module_sense: false,
        synthetic: None,
    },
    Case {
        name: "piecewise, self-tuning GPC, sensor open at 1500 s",
        scenario: "piecewise",
        duration_s: None,
        kind: proto::KIND_GPC,
        faults: &["sensor-open@1500"],
        module_sense: false,
        synthetic: None,
    },
    Case {
        name: "step, self-tuning GPC, SSR stuck on at 5400 s",
        scenario: "step",
        duration_s: None,
        kind: proto::KIND_GPC,
        faults: &["ssr-stuck-on@5400"],
        module_sense: false,
        synthetic: None,
    },
    Case {
        name: "step, self-tuning GPC, module-side sense, SSR stuck on at 5400 s",
        scenario: "step",
        duration_s: None,
        kind: proto::KIND_GPC,
        faults: &["ssr-stuck-on@5400"],
        module_sense: true,
        synthetic: None,
    },
    Case {
        name: "step 24 h, self-tuning GPC",
        scenario: "step",
        duration_s: Some(86_400.0),
        kind: proto::KIND_GPC,
        faults: &[],
        module_sense: false,
        synthetic: None,
    },
    Case {
        name: "step, PI",
        scenario: "step",
        duration_s: None,
        kind: proto::KIND_PI,
        faults: &[],
        module_sense: false,
        synthetic: None,
    },
    Case {
        name: "load falling through 3 °C, GPC at λ 200",
        scenario: "",
        duration_s: None,
        kind: proto::KIND_GPC_DAMPED,
        faults: &[],
        module_sense: false,
        synthetic: Some(falling_through_3c),
    },
];

/// The soft floor's case ([`proto::KIND_GPC_DAMPED`]): 4 °C held for 4 000 s, the setpoint to
/// 3 °C, and 120 s later the reading falls 0.2 °C a sample to 1.5 °C, the duty's effect or not
/// (the replay is open loop). The damped plan cuts the duty slowly and still dips below the
/// floor, so the floor moves it (three samples; the board's λ 0.5 on one, through the floor's
/// guard row, the plan meeting the no-cooling bound soon after). A little deterministic noise
/// keeps the estimator fed.
fn falling_through_3c() -> Vec<StepInput> {
    let counts = |t: f64| {
        let r = hter::rtd::Rtd::PT100.resistance(hter::units::Celsius(t as f32)).expect("an RTD temperature");
        hter::adc::AdcFrontEnd::DEFAULT.counts(r)
    };
    let mut t = 4.0;
    (0..512u64)
        .map(|i| {
            if i >= 412 && t > 1.5 {
                t -= 0.2;
            }
            let noise = ((i * 7919) % 13) as f64 * 0.0004;
            StepInput { t_ms: i * 10_000, counts: counts(t + noise), setpoint_c: if i < 400 { 4.0 } else { 3.0 } }
        })
        .collect()
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("pil") => pil(),
        Some("size") => size(),
        Some("audit") => match (args.get(1).map(String::as_str), args.get(2)) {
            (None, _) => audit::audit(""),
            (Some("--features"), Some(f)) => audit::audit(f),
            _ => {
                eprintln!("usage: cargo xtask audit [--features FEATURES]");
                std::process::exit(2)
            }
        },
        _ => {
            eprintln!("usage: cargo xtask pil | cargo xtask size | cargo xtask audit [--features FEATURES]");
            std::process::exit(2)
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root().join("target"))
}

/// What the target reported for one sample.
struct TargetSample {
    duty: u32,
    ticks: [u32; proto::PARTS.len()],
    events: Vec<(u32, u32)>,
}

/// Builds the release firmware for every entry of [`FIRMWARE_BUILDS`] and checks the budgets.
fn size() -> Result<()> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let elf = target_dir().join(TARGET).join("release").join("firmware");
    let mut rows = Vec::new();
    println!("firmware release builds for {TARGET} (budget: flash {FLASH_BUDGET} B, static RAM {RAM_BUDGET} B)");
    for (features, what, flash_budget, ram_budget) in FIRMWARE_BUILDS {
        let mut cmd = Command::new(&cargo);
        cmd.current_dir(root()).args(["build", "--release", "-p", "firmware", "--target", TARGET]);
        if !features.is_empty() {
            cmd.args(["--features", features]);
        }
        if !cmd.status().context("running cargo")?.success() {
            bail!("building the firmware ({what}) failed");
        }
        let (flash, ram) = elf_sizes(&std::fs::read(&elf).with_context(|| format!("reading {}", elf.display()))?)?;
        let ok = flash <= flash_budget && ram <= ram_budget;
        println!(
            "  {what:<28} features {:<22} flash {flash:>6} B ({:>5.1} % of {flash_budget})  static RAM {ram:>6} B ({:>5.1} % of {ram_budget}){}",
            if features.is_empty() { "(none)" } else { features },
            100.0 * flash as f64 / flash_budget as f64,
            100.0 * ram as f64 / ram_budget as f64,
            if ok { "" } else { "  OVER BUDGET" }
        );
        rows.push((features, flash, ram, ok, flash_budget, ram_budget));
    }
    let within = rows.iter().all(|r| r.3);
    let builds: Vec<String> = rows
        .iter()
        .map(|(f, flash, ram, _, fb, rb)| {
            format!("{{\"features\": \"{f}\", \"flash_bytes\": {flash}, \"ram_bytes\": {ram}, \"flash_budget\": {fb}, \"ram_budget\": {rb}}}")
        })
        .collect();
    println!(
        "{{\"builds\": [{}], \"flash_budget\": {FLASH_BUDGET}, \"ram_budget\": {RAM_BUDGET}, \"within_budget\": {within}}}",
        builds.join(", ")
    );
    if !within {
        bail!("a firmware build exceeds the budget");
    }
    Ok(())
}

/// What the target reported for one run.
struct TargetRun {
    cal: [u32; 3],
    samples: Vec<TargetSample>,
    stack_bytes: u32,
    state_bytes: u32,
}

/// One case recorded and run on the host once, for every pass on the target.
struct Prepared<'a> {
    case: &'a Case,
    inputs: Vec<Sample>,
    host: Vec<HostSample>,
    /// The samples on which GPC's soft floor moved the plan.
    floors: Vec<usize>,
}

/// What one build of the runner did on every case.
struct Pass {
    all_equal: bool,
    steps: usize,
    /// Instructions per sample (step + monitor) of the GPC cases.
    gpc_insn: Vec<f64>,
    pi_insn: Vec<f64>,
    /// Instructions of the samples the soft floor moved.
    floor_insn: Vec<f64>,
    /// Instructions per part ([`proto::PARTS`]) of the GPC cases' samples.
    parts: Vec<Vec<f64>>,
    cal: [u32; 3],
    ticks_per_insn: f64,
    stack: u32,
    state: u32,
}

fn pil() -> Result<()> {
    which("qemu-system-arm").context("qemu-system-arm not found (Debian: apt-get install qemu-system-arm)")?;
    let elf = build_runner("release")?;
    let (flash, ram) = elf_sizes(&std::fs::read(&elf)?)?;
    let work = target_dir().join("pil-runs");

    let mut prepared = Vec::with_capacity(CASES.len());
    for case in &CASES {
        let inputs = record(case)?;
        let (host, floors) = run_host(case.kind, &inputs)?;
        prepared.push(Prepared { case, inputs, host, floors });
    }

    println!("processor-in-the-loop: {} on qemu-system-arm -M mps2-an386 (Cortex-M4F), -icount shift=6", elf.display());
    let first = run_pass(&elf, &work, &prepared)?;
    let tpi = first.ticks_per_insn;
    println!(
        "calibration: empty window {} ticks; {} and {} loop instructions: {} and {} ticks → {:.4} ticks per instruction (expected {})",
        first.cal[0],
        2 * proto::CAL_LOOP,
        4 * proto::CAL_LOOP,
        first.cal[1],
        first.cal[2],
        tpi,
        TICKS_PER_INSN
    );
    print_profile(&first.parts);
    println!(
        "PI: insn/sample median {:.0}, max {:.0}; carrier + monitor state {} B (on the runner's stack); peak stack of the runner {} B; runner image: flash {} B, static RAM {} B",
        median(&first.pi_insn),
        max(&first.pi_insn),
        first.state,
        first.stack,
        flash,
        ram
    );
    let t0 = Instant::now();
    let fs = failsafe::run(&elf.with_file_name("failsafe"), &work)?;
    let yes = |b: bool| if b { "yes" } else { "NO" };
    println!(
        "fail-safe paths: {} boots of {} across SYSRESETREQ and watchdog resets ({:.1} s)",
        failsafe::BOOTS,
        elf.with_file_name("failsafe").display(),
        t0.elapsed().as_secs_f64()
    );
    for c in &fs {
        let [first, survived, reported] = c.labels();
        println!(
            "  {:<21} {first}: {:<3}  {survived}: {:<3}  {reported}: {}",
            c.kind,
            yes(c.first),
            yes(c.survived),
            yes(c.reported)
        );
        for line in &c.why {
            println!("    {line}");
        }
    }
    let failsafe_ok = fs.iter().all(failsafe::Check::ok);
    let failsafe_json: Vec<String> = fs.iter().map(|c| format!("\"{}\": {}", c.kind, c.ok())).collect();

    // The same cases on the runner built as the firmware is: under fat LTO the root crate's
    // opt-level ("z" in the firmware) drives the link-time pipeline and the generic step's
    // instantiation, so the first pass (root at 3) counts fewer instructions than the board runs.
    let board_elf = build_runner("board")?;
    println!(
        "as the firmware compiles it (pil/Cargo.toml's [profile.board]: the root crate at \"z\"): {}",
        board_elf.display()
    );
    let board = run_pass(&board_elf, &target_dir().join("pil-runs-board"), &prepared)?;
    print_profile(&board.parts);
    let board_worst = max(&board.gpc_insn);
    println!(
        "as the firmware compiles it (root crate at \"z\"): self-tuning GPC worst {:.0}, median {:.0} instructions per sample ({} the {} target, which only the first pass is held to); PI median {:.0}, max {:.0}; bit-equal: {}",
        board_worst,
        median(&board.gpc_insn),
        if board_worst <= BUDGET_INSN { "within" } else { "ABOVE" },
        BUDGET_INSN,
        median(&board.pi_insn),
        max(&board.pi_insn),
        yes(board.all_equal)
    );

    if first.floor_insn.is_empty() {
        bail!("no case met GPC's soft floor: its samples went untimed");
    }
    let worst = max(&first.gpc_insn);
    let within = worst <= BUDGET_INSN;
    println!(
        "budget: self-tuning GPC worst case {:.0} instructions per sample ({} the {} budget; samples the soft floor moved: max {:.0}); host and target {}",
        worst,
        if within { "within" } else { "OVER" },
        BUDGET_INSN,
        max(&first.floor_insn),
        if first.all_equal { "bit-equal on every sample" } else { "DIFFER" }
    );
    println!(
        "{{\"steps\": {}, \"bit_equal\": {}, \"insn_per_step_median\": {:.0}, \"insn_per_step_max\": {:.0}, \"board_bit_equal\": {}, \"board_insn_per_step_median\": {:.0}, \"board_insn_per_step_max\": {:.0}, \"flash_bytes\": {}, \"ram_bytes\": {}, \"state_bytes\": {}, \"stack_bytes\": {}, \"ticks_per_insn\": {:.4}, \"failsafe\": {{{}}}}}",
        first.steps,
        first.all_equal,
        median(&first.gpc_insn),
        worst,
        board.all_equal,
        median(&board.gpc_insn),
        board_worst,
        flash,
        ram,
        first.state,
        first.stack,
        tpi,
        failsafe_json.join(", ")
    );
    if !first.all_equal || !board.all_equal {
        bail!("host and target results differ");
    }
    if !within {
        bail!("instruction budget exceeded: {worst:.0} > {BUDGET_INSN}");
    }
    if !failsafe_ok {
        bail!("a fail-safe check failed");
    }
    Ok(())
}

/// Runs every prepared case on `elf` (QEMU in a directory per case under `work`), compares it
/// with the host bit for bit and prints a line per case.
fn run_pass(elf: &Path, work: &Path, prepared: &[Prepared]) -> Result<Pass> {
    let mut pass = Pass {
        all_equal: true,
        steps: 0,
        gpc_insn: Vec::new(),
        pi_insn: Vec::new(),
        floor_insn: Vec::new(),
        parts: vec![Vec::new(); proto::PARTS.len()],
        cal: [0; 3],
        ticks_per_insn: 0.0,
        stack: 0,
        state: 0,
    };
    for Prepared { case, inputs, host, floors } in prepared {
        let dir = work.join(case.name.replace([',', ' '], "_"));
        std::fs::create_dir_all(&dir)?;
        let t0 = Instant::now();
        let tr = run_target(elf, &dir, case.kind, inputs)?;
        let qemu_s = t0.elapsed().as_secs_f64();
        let (empty, tpi) = calibration(&tr.cal)?;
        (pass.cal, pass.ticks_per_insn) = (tr.cal, tpi);
        pass.stack = pass.stack.max(tr.stack_bytes);
        pass.state = pass.state.max(tr.state_bytes);
        let mismatches = compare(host, &tr.samples);
        pass.steps += inputs.len();
        let insn = |t: u32| (f64::from(t) - f64::from(empty)).max(0.0) / TICKS_PER_INSN;
        let per_step: Vec<f64> =
            tr.samples.iter().map(|s| insn(s.ticks[proto::PART_STEP]) + insn(s.ticks[proto::PART_MONITOR])).collect();
        if case.kind != proto::KIND_PI {
            pass.gpc_insn.extend(&per_step);
            for s in &tr.samples {
                for (p, t) in s.ticks.iter().enumerate() {
                    if *t > 0 {
                        pass.parts[p].push(insn(*t));
                    }
                }
            }
        } else {
            pass.pi_insn.extend(&per_step);
        }
        let events: usize = host.iter().map(|h| h.1.len()).sum();
        println!(
            "  {:<52} {:>5} samples, {:>3} event words, bit-equal: {:<3}  insn/sample median {:>5.0} max {:>5.0}  ({:.1} s)",
            case.name,
            inputs.len(),
            events,
            if mismatches.is_empty() { "yes" } else { "NO" },
            median(&per_step),
            max(&per_step),
            qemu_s
        );
        if !floors.is_empty() {
            let at: Vec<f64> = floors.iter().filter_map(|&i| per_step.get(i).copied()).collect();
            println!(
                "    soft floor at work on {} samples ({:?}): insn/sample max {:.0}",
                floors.len(),
                floors,
                max(&at)
            );
            pass.floor_insn.extend(at);
        }
        for m in mismatches.iter().take(5) {
            println!("    mismatch: {m}");
        }
        pass.all_equal &= mismatches.is_empty();
    }
    if pass.steps == 0 {
        bail!("no case ran");
    }
    Ok(pass)
}

/// The profile by part of the GPC cases' samples.
fn print_profile(parts: &[Vec<f64>]) {
    println!("profile, self-tuning GPC samples (instructions; shadow copies re-run each part):");
    println!("  {:<32} {:>8} {:>8} {:>8}", "part", "median", "max", "n");
    for (name, v) in proto::PARTS.iter().zip(parts) {
        if !v.is_empty() {
            println!("  {:<32} {:>8.0} {:>8.0} {:>8}", name, median(v), max(v), v.len());
        }
    }
}

fn which(cmd: &str) -> Result<()> {
    let ok = Command::new(cmd).arg("--version").stdout(Stdio::null()).stderr(Stdio::null()).status()?.success();
    if !ok {
        bail!("{cmd} --version failed");
    }
    Ok(())
}

/// Builds `pil/` (its own workspace) for the target with cargo profile `profile` ("release":
/// every binary; any other, a custom profile of `pil/Cargo.toml`: the `pil` binary alone);
/// returns the `pil` ELF's path.
fn build_runner(profile: &str) -> Result<PathBuf> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let pil = root().join("pil");
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&pil).args(["build", "--profile", profile, "--locked", "--target", TARGET, "--target-dir"]);
    cmd.arg(target_dir());
    if profile != "release" {
        cmd.args(["--bin", "pil"]);
    }
    if !cmd.status().context("running cargo")?.success() {
        bail!("building the PIL runner (profile {profile}) failed");
    }
    // Cargo puts a profile's output in a directory of its name ("dev" in "debug").
    let dir = if profile == "dev" { "debug" } else { profile };
    Ok(target_dir().join(TARGET).join(dir).join("pil"))
}

/// One sample as the firmware hands it to the library: the step's input and the board's other
/// readings.
type Sample = (StepInput, BoardReadings);

/// Runs the case's closed loop on the simulated plant; returns the step inputs and board
/// readings it recorded (a synthetic case has no readings).
fn record(case: &Case) -> Result<Vec<Sample>> {
    if let Some(make) = case.synthetic {
        return Ok(make().into_iter().map(|i| (i, BoardReadings::default())).collect());
    }
    let scenario = Scenario::resolve(case.scenario)?;
    let choice = if case.kind == proto::KIND_PI { ControllerChoice::Pi } else { ControllerChoice::Gpc };
    let mut opts = SimOptions::new(scenario, ControllerSpec::new(choice));
    opts.duration_s = case.duration_s.unwrap_or(opts.duration_s);
    opts.faults = case.faults.iter().map(|f| Fault::parse(f)).collect::<Result<_>>()?;
    opts.module_sense = case.module_sense;
    let out = run(&opts)?;
    Ok(out
        .rows
        .iter()
        .map(|r| {
            let input = StepInput { t_ms: sim_clock_ms(r.t_s), counts: r.counts, setpoint_c: r.setpoint_c as f32 };
            (input, r.board_in)
        })
        .collect())
}

/// The board's millisecond clock at sim time `t_s` (rows start at 0), converted once per sample.
fn sim_clock_ms(t_s: f64) -> u64 {
    (t_s * 1000.0).round() as u64
}

/// One host sample: the duty's bits and the event words.
type HostSample = (u32, Vec<(u32, u32)>);

/// The same samples through the same library code on the host, and the samples on which GPC's
/// soft floor moved the plan (the floor's count in [`proto::floor_samples`] changed; none for a
/// controller without it).
fn run_host(kind: u32, inputs: &[Sample]) -> Result<(Vec<HostSample>, Vec<usize>)> {
    let (mut carrier, mut monitor) = proto::carrier(kind).context("unknown controller kind")?;
    let mut seen = proto::floor_samples(&carrier);
    let mut floors = Vec::new();
    let samples = inputs
        .iter()
        .enumerate()
        .map(|(i, (inp, board))| {
            carrier.observe(board);
            let o = carrier.step(inp);
            let now = proto::floor_samples(&carrier);
            if now != seen {
                floors.push(i);
            }
            seen = now;
            let raised = proto::monitor_push(&mut monitor, inp, &o);
            let mut ev = Vec::new();
            proto::event_words(&o, &raised, |c, v| ev.push((c, v)));
            (o.duty.get().to_bits(), ev)
        })
        .collect();
    Ok((samples, floors))
}

fn compare(host: &[HostSample], target: &[TargetSample]) -> Vec<String> {
    let mut out = Vec::new();
    if host.len() != target.len() {
        out.push(format!("{} host samples, {} target samples", host.len(), target.len()));
    }
    for (k, ((hd, hev), t)) in host.iter().zip(target).enumerate() {
        if *hd != t.duty {
            out.push(format!(
                "sample {k}: duty host {:?} ({hd:#010x}) target {:?} ({:#010x})",
                f32::from_bits(*hd),
                f32::from_bits(t.duty),
                t.duty
            ));
        }
        if *hev != t.events {
            out.push(format!("sample {k}: events host {hev:?} target {:?}", t.events));
        }
    }
    out
}

/// What one QEMU run printed, and how it ended.
pub struct QemuRun {
    /// `None`: still running after the timeout, and killed.
    pub status: Option<std::process::ExitStatus>,
    pub stdout: String,
    pub stderr: String,
}

/// Runs `elf` on `qemu-system-arm -M mps2-an386` in `dir`, with semihosting and the `extra`
/// arguments, killing it if it has not exited within `timeout`.
pub fn qemu(elf: &Path, dir: &Path, extra: &[&str], timeout: Duration) -> Result<QemuRun> {
    let mut child = Command::new("qemu-system-arm")
        .current_dir(dir)
        .args(["-M", "mps2-an386", "-display", "none", "-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(extra)
        .arg("-kernel")
        .arg(elf)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting qemu-system-arm")?;
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait()? {
            break Some(s);
        }
        if start.elapsed() > timeout {
            child.kill()?;
            child.wait()?;
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let (mut stdout, mut stderr) = (String::new(), String::new());
    if let Some(mut s) = child.stdout.take() {
        s.read_to_string(&mut stdout)?;
    }
    if let Some(mut s) = child.stderr.take() {
        s.read_to_string(&mut stderr)?;
    }
    Ok(QemuRun { status, stdout, stderr })
}

fn run_target(elf: &Path, dir: &Path, kind: u32, inputs: &[Sample]) -> Result<TargetRun> {
    let mut bytes = Vec::with_capacity(12 + 4 * proto::INPUT_WORDS * inputs.len());
    for w in [proto::MAGIC_IN, kind, inputs.len() as u32] {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    for (i, board) in inputs {
        for w in proto::input_words(i, board) {
            bytes.extend_from_slice(&w.to_le_bytes());
        }
    }
    let input = dir.join(proto::INPUT_FILE.trim_end_matches('\0'));
    let output = dir.join(proto::OUTPUT_FILE.trim_end_matches('\0'));
    std::fs::write(&input, bytes)?;
    let _ = std::fs::remove_file(&output);
    let run = qemu(elf, dir, &["-icount", "shift=6,sleep=off"], QEMU_TIMEOUT)?;
    let Some(status) = run.status else {
        bail!("QEMU did not finish within {} s", QEMU_TIMEOUT.as_secs());
    };
    let msg = run.stdout + &run.stderr;
    if !status.success() {
        bail!("the PIL runner failed ({status}): {}", msg.trim());
    }
    parse_output(&std::fs::read(&output).with_context(|| format!("reading {}", output.display()))?, inputs.len())
}

fn parse_output(bytes: &[u8], n: usize) -> Result<TargetRun> {
    let words: Vec<u32> =
        bytes.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().expect("chunks of 4"))).collect();
    let mut it = words.into_iter();
    let mut next = || it.next().context("PIL output truncated");
    if next()? != proto::MAGIC_OUT {
        bail!("PIL output has no header");
    }
    let cal = [next()?, next()?, next()?];
    let count = next()? as usize;
    if count != n {
        bail!("target ran {count} samples of {n}");
    }
    let mut samples = Vec::with_capacity(n);
    for _ in 0..n {
        let duty = next()?;
        let mut ticks = [0u32; proto::PARTS.len()];
        for t in ticks.iter_mut() {
            *t = next()?;
        }
        let m = next()? as usize;
        let mut events = Vec::with_capacity(m);
        for _ in 0..m {
            events.push((next()?, next()?));
        }
        samples.push(TargetSample { duty, ticks, events });
    }
    let stack_bytes = next()?;
    let state_bytes = next()?;
    Ok(TargetRun { cal, samples, stack_bytes, state_bytes })
}

/// Empty-window overhead in ticks and the measured ticks per instruction; fails if the
/// emulator does not count 1.6 ticks per instruction.
fn calibration(cal: &[u32; 3]) -> Result<(u32, f64)> {
    let tpi = f64::from(cal[2].saturating_sub(cal[1])) / f64::from(2 * proto::CAL_LOOP);
    if (tpi - TICKS_PER_INSN).abs() > 0.01 * TICKS_PER_INSN {
        bail!("SysTick counts {tpi:.4} ticks per instruction, not {TICKS_PER_INSN}: is -icount shift=6 in effect?");
    }
    Ok((cal[0], tpi))
}

/// Flash (allocated sections with contents) and static RAM (allocated sections at or above
/// 0x2000_0000) of a little-endian ELF32 image, as `size` counts text + data and data + bss
/// ([`audit::Elf::sizes`]).
fn elf_sizes(elf: &[u8]) -> Result<(u64, u64)> {
    Ok(audit::Elf::parse(elf)?.sizes())
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(ws: &[u32]) -> Vec<u8> {
        ws.iter().flat_map(|w| w.to_le_bytes()).collect()
    }

    /// A target output with two samples: the second has one event.
    fn output() -> Vec<u32> {
        let mut w = vec![proto::MAGIC_OUT, 2, 3216, 6416, 2];
        w.push(0.5f32.to_bits());
        w.extend([100u32; proto::PARTS.len()]);
        w.push(0);
        w.push(0.25f32.to_bits());
        w.extend([200u32; proto::PARTS.len()]);
        w.extend([1, 7, 10.0f32.to_bits()]);
        w.extend([4096, 1600]);
        w
    }

    #[test]
    fn parses_the_runner_output_and_refuses_a_truncated_one() {
        let run = parse_output(&words(&output()), 2).unwrap();
        assert_eq!(run.cal, [2, 3216, 6416]);
        assert_eq!(run.samples[1].duty, 0.25f32.to_bits());
        assert_eq!(run.samples[1].events, vec![(7, 10.0f32.to_bits())]);
        assert_eq!((run.stack_bytes, run.state_bytes), (4096, 1600));
        let w = output();
        assert!(parse_output(&words(&w[..w.len() - 3]), 2).is_err());
        assert!(parse_output(&words(&w), 3).is_err(), "sample count must match");
    }

    #[test]
    fn one_flipped_bit_or_event_is_a_mismatch() {
        let run = parse_output(&words(&output()), 2).unwrap();
        let host: Vec<HostSample> = vec![(0.5f32.to_bits(), vec![]), (0.25f32.to_bits(), vec![(7, 10.0f32.to_bits())])];
        assert!(compare(&host, &run.samples).is_empty());
        let mut flipped = host.clone();
        flipped[0].0 ^= 1;
        assert_eq!(compare(&flipped, &run.samples).len(), 1);
        let mut other_event = host.clone();
        other_event[1].1[0].0 = 8;
        assert_eq!(compare(&other_event, &run.samples).len(), 1);
        assert_eq!(compare(&host[..1], &run.samples).len(), 1, "length mismatch reported");
    }

    #[test]
    fn calibration_demands_1_6_ticks_per_instruction() {
        assert!((calibration(&[2, 3216, 6416]).unwrap().1 - 1.6).abs() < 1e-9);
        // Without -icount, or with another shift, the ratio is off: refuse.
        assert!(calibration(&[2, 2000, 4000]).is_err());
    }

    /// The board's readings cross the file exactly: a missing one stays missing, a measured NaN
    /// (a broken divider) stays a reading.
    #[test]
    fn the_input_words_carry_the_board_readings() {
        let input = StepInput { t_ms: (7 << 32) + 5, counts: 49_000, setpoint_c: 4.5 };
        let board = |s: Option<f32>, r: Option<f32>, t: Option<f32>, m: Option<f32>| BoardReadings {
            supply_v: s,
            switched_v: r,
            switch_test_v: t,
            module_v: m,
        };
        for b in [
            BoardReadings::default(),
            board(Some(12.1), Some(0.0), None, Some(f32::NAN)),
            board(Some(-0.3), None, Some(11.9), Some(2.5)),
        ] {
            let (i, back) = proto::input_of(proto::input_words(&input, &b));
            assert_eq!((i.t_ms, i.counts, i.setpoint_c), (input.t_ms, input.counts, input.setpoint_c));
            let bits = |b: &BoardReadings| {
                [b.supply_v, b.switched_v, b.switch_test_v, b.module_v].map(|v| v.map(f32::to_bits))
            };
            assert_eq!(bits(&back), bits(&b));
        }
    }

    #[test]
    fn host_replay_records_the_steps_duties_and_events() {
        // 20 samples at 9 °C (cooling wanted), then an open sensor at sample 20 (t = 200 s).
        let cfg = proto::CARRIER.get();
        let warm = cfg.adc.counts(cfg.rtd.resistance(hter::units::Celsius(9.0)).unwrap());
        let inputs: Vec<Sample> = (0..30u32)
            .map(|k| {
                let t_ms = 10_000 * u64::from(k);
                (
                    StepInput { t_ms, counts: if k < 20 { warm + k % 3 } else { 65_535 }, setpoint_c: 4.0 },
                    BoardReadings::default(),
                )
            })
            .collect();
        let (host, _) = run_host(proto::KIND_PI, &inputs).unwrap();
        assert_eq!(host.len(), inputs.len());
        assert!(host[..20].iter().all(|(d, _)| f32::from_bits(*d) > 0.0), "a warm load is cooled");
        assert!(host[20..].iter().all(|(d, _)| f32::from_bits(*d) == 0.0), "an open sensor stops cooling");
        // The open sensor is reported once, at its sample's time (low word, high word).
        let open = hter::event::EventKind::SensorOpen.code();
        assert_eq!(host[20].1, [(open, 200_000), (open, 0)]);
        assert!(host[21..].iter().all(|(_, e)| e.is_empty()), "{:?}", &host[21..]);
        assert!(run_host(7, &inputs).is_err(), "unknown controller kind");
    }

    #[test]
    fn the_floor_case_meets_the_soft_floor_at_both_tunings_after_the_fall_starts() {
        let inputs: Vec<Sample> = falling_through_3c().into_iter().map(|i| (i, BoardReadings::default())).collect();
        let floors = |kind| run_host(kind, &inputs).unwrap().1;
        let at = floors(proto::KIND_GPC_DAMPED);
        // The fall starts at sample 412; the floor can only act once the plan dips, after it.
        assert!(!at.is_empty() && at.iter().all(|&i| i >= 412), "{at:?}");
        // The board's λ 0.5 meets it too since the floor's guard row (on the box's plans), also
        // only after the fall starts; PI has no floor.
        let board = floors(proto::KIND_GPC);
        assert!(!board.is_empty() && board.iter().all(|&i| i >= 412), "{board:?}");
        assert!(floors(proto::KIND_PI).is_empty());
    }
}
