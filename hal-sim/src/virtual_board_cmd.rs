//! `hter virtual-board`: a simulated carrier on a pseudo-terminal. The library's
//! [`hter::app::App`] — the step, the record and the interface handler the firmware runs — in
//! front of the plant model, its flash the mock L4 flash ([`crate::sim::virtual_board`]),
//! served on a pty whose slave `--link PATH` names, N× faster than real time, until stopped
//! (Ctrl-C). `hter board --port PATH …` cannot tell it from a board.

use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::fault::Fault;
use crate::link::PtyLink;
use crate::sim::virtual_board::{VirtualBoard, VirtualOptions, HANG_REFUSED};
use crate::sim::PlantChoice;
use crate::sim_cmd::{at_least, finite, shown, whole, LoadArg};

/// `hter virtual-board` arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct VirtualBoardArgs {
    /// Where the pseudo-terminal appears (a symlink to its device), e.g. /tmp/carrier.
    #[arg(long)]
    pub link: PathBuf,
    /// The carrier: hter1 (aluminium) or hter2 (stainless steel).
    #[arg(long, default_value = "hter1")]
    pub plant: String,
    /// Load: full or half.
    #[arg(long, value_enum, default_value = "full")]
    pub load: LoadArg,
    /// Ambient, °C.
    #[arg(long, default_value_t = 28.0, allow_negative_numbers = true)]
    pub ambient: f64,
    /// Simulated seconds per real second (1 = real time; at 600 a 10 s sample takes 17 ms).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub speed: f64,
    /// Seed of the ADC noise.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = whole("the noise seed", 0, u64::MAX))]
    pub seed: u64,
    /// Test hook: the first settings write loses power after this many flash operations (word
    /// programs, page erases); the board restarts as after a brown-out and restores its flash.
    #[arg(long, allow_negative_numbers = true, value_parser = at_least("the number of flash operations", 0usize))]
    pub cut_settings_write: Option<usize>,
    /// Stop after this many simulated seconds (default: run until stopped).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// The board of the `interface,module-sense` firmware build: the modules' voltage in the
    /// conversion window goes to the step with each sample (README, "Fail-loud alarm, switch
    /// sense and what is unverified").
    #[arg(long)]
    pub module_sense: bool,
    /// Inject a fault at a simulated time, KIND@T_S (repeatable; the names of `hter sim
    /// --fault` but firmware-hang, the board's own fail-safe stops board-fault-panic,
    /// board-fault-hard-fault, board-fault-nmi, board-fault-unexpected-interrupt and
    /// board-fault-control-stall included: the stop path's record, a reset, the boot that
    /// reports it; a stall stops at once, without the loop's hung sample): to rehearse what
    /// `status`, the alarm and `history` show when a probe, the relay, the supply or the board
    /// itself fails.
    #[arg(long = "fault")]
    pub faults: Vec<String>,
}

/// Serves the virtual board until stopped (or `--duration`).
pub fn run(a: &VirtualBoardArgs) -> Result<()> {
    let speed = finite("speed", a.speed)?;
    if !(0.01..=100_000.0).contains(&speed) {
        bail!("--speed must be within 0.01…100000, got {}", crate::sim_cmd::shown(speed));
    }
    let ambient_c = finite("ambient", a.ambient)?;
    let (lo, hi) = crate::scenario::AMBIENT_RANGE_C;
    if !(lo..=hi).contains(&ambient_c) {
        bail!("--ambient must be within {lo}…{hi} °C, got {}", crate::sim_cmd::shown(ambient_c));
    }
    // A NaN duration compared false with the simulated time for ever: the board never stopped.
    let ts = f64::from(hter::step::CarrierConfig::DEFAULT.ts_s);
    let duration_s = match a.duration {
        Some(d) if finite("duration", d)? <= 0.0 => bail!("--duration must be > 0 s, got {}", crate::sim_cmd::shown(d)),
        // It ran one sample and stopped at once with exit 0, as if it had served.
        Some(d) if d < ts => {
            bail!("--duration {} s is shorter than one control sample (Ts = {ts} s)", shown(d))
        }
        d => d,
    };
    let mut faults = a.faults.iter().map(|f| Fault::parse(f)).collect::<Result<Vec<_>>>()?;
    if faults.iter().any(|&(_, f)| f == Fault::FirmwareHang) {
        bail!("--fault firmware-hang: {HANG_REFUSED}");
    }
    // A fault goes in before the first sample at or after its time; samples start at 0, Ts,
    // 2 Ts, … while the simulated time is below the duration. One after the last never
    // happens, and the board would serve a clean carrier the user thinks has failed.
    if let Some(d) = duration_s {
        let last_sample_s = ((d / ts).ceil() - 1.0) * ts;
        if let Some((t, f)) = faults.iter().find(|(t, _)| *t > last_sample_s) {
            bail!(
                "--fault {}@{}: the board stops at {} s (last sample at {last_sample_s} s), the fault would never happen",
                f.name(),
                shown(*t),
                shown(d)
            );
        }
    }
    // Injected in time order, each at the first sample at or after its time.
    faults.sort_by(|a, b| a.0.total_cmp(&b.0));
    let plant = PlantChoice::parse(&a.plant)?;
    let mut board = VirtualBoard::new(&VirtualOptions {
        plant,
        load: a.load.into(),
        ambient_c,
        seed: a.seed,
        module_sense: a.module_sense,
    })?;
    if let Some(ops) = a.cut_settings_write {
        board.cut_next_settings_write(ops);
    }
    // Before the link exists: a Ctrl-C from then on is seen by the loop, which removes it.
    catch_stop_signals();
    let mut link = PtyLink::open(&a.link).with_context(|| format!("--link {}", a.link.display()))?;
    eprintln!(
        "virtual board: {} {:?} load at {ambient_c} °C ambient, {speed}× real time, on {} ({}); Ctrl-C stops it",
        plant.name(),
        a.load,
        a.link.display(),
        link.device().display()
    );
    let period = Duration::from_secs_f64(ts / speed);
    let served = serve(&mut board, &mut link, faults, period, duration_s);
    // The symlink goes with the link, however the board stopped.
    drop(link);
    let sig = STOP.load(Ordering::Relaxed);
    if sig != 0 {
        // Stopped by the signal: end as it ends other programs (the shell's 130 for Ctrl-C).
        // SAFETY: restoring a signal's default action and raising it; no handler runs.
        unsafe {
            libc::signal(sig, libc::SIG_DFL);
            libc::raise(sig);
        }
    }
    served
}

/// The signal that asked the board to stop (SIGINT, SIGTERM); 0 while none has.
static STOP: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_stop(sig: libc::c_int) {
    STOP.store(sig, Ordering::Relaxed);
}

/// Ctrl-C and `kill` (SIGTERM) stop the serving loop instead of the process, so the `--link`
/// symlink is removed: it was left behind, pointing to a pty that no longer exists.
fn catch_stop_signals() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe {
            libc::signal(sig, on_stop as extern "C" fn(libc::c_int) as libc::sighandler_t);
        }
    }
}

/// The serving loop: samples on time, requests in between, until `duration_s` or a stop signal.
fn serve(
    board: &mut VirtualBoard,
    link: &mut PtyLink,
    faults: Vec<(f64, Fault)>,
    period: Duration,
    duration_s: Option<f64>,
) -> Result<()> {
    let mut faults = faults.into_iter().peekable();
    let mut next = Instant::now();
    let mut restarts = board.restarts;
    loop {
        if STOP.load(Ordering::Relaxed) != 0 {
            return Ok(());
        }
        let now = Instant::now();
        if now >= next {
            while let Some((t, f)) = faults.next_if(|&(t, _)| board.sim_s() >= t) {
                board.inject(f)?;
                restarts = board.restarts;
                eprintln!("virtual board: fault {} injected at t = {} s (asked for {t} s)", f.name(), board.sim_s());
            }
            if board.step().is_none() {
                bail!("the virtual board's plant has no sensor to sample");
            }
            if board.restarts != restarts {
                restarts = board.restarts;
                eprintln!("virtual board: power cut in a settings write at t = {} s; restarted", board.sim_s());
            }
            // A slow host does not make the simulation catch up in a burst.
            next = (next + period).max(now);
            if duration_s.is_some_and(|d| board.sim_s() >= d) {
                return Ok(());
            }
            continue;
        }
        if let Some(line) = link.poll_line(next - now).context("reading the link")? {
            let reply = board.request(&line);
            link.send(&reply).context("writing the link")?;
        }
    }
}
