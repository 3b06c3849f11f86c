//! The `hter` command line: the clap top level and the dispatch to one `*_cmd` module per
//! command. `hter` alone runs a short demo.

use std::io::Write;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use hal_sim::{
    board_cmd, campaign_cmd, compare_cmd, demo_cmd, identify_cmd, log2csv_cmd, monitor_cmd, report_cmd, rtd_cmd,
    sim_cmd, virtual_board_cmd,
};

/// Adaptive control of a thermoelectric (Peltier) vaccine carrier: simulate, identify, convert.
#[derive(Parser, Debug)]
#[command(name = "hter", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

// Parsed once per process: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand, Debug)]
enum Command {
    /// Run a closed-loop scenario: the firmware's per-sample step against the plant model.
    Sim(sim_cmd::SimArgs),
    /// Identify an ARX/ARMAX model of the carrier from a logged run (CSV).
    Identify(identify_cmd::IdentifyArgs),
    /// Convert between RTD resistance and temperature (IEC 60751).
    Rtd(rtd_cmd::RtdArgs),
    /// Cold-chain record of a CSV log: WHO-style alarms, mean kinetic temperature, excursions.
    Monitor(monitor_cmd::MonitorArgs),
    /// Cold-chain report of a CSV log as one HTML page (or PDF): verdict, per-day table, alarms,
    /// MKT, plots.
    Report(report_cmd::ReportArgs),
    /// Run one scenario with several controllers and print a markdown comparison table.
    Compare(compare_cmd::CompareArgs),
    /// Turn the firmware's defmt telemetry log into the CSV `identify` and `monitor` read.
    Log2csv(log2csv_cmd::Log2CsvArgs),
    /// Run many randomized 24 h missions (plant ±50 %, ambient 0–43 °C, lid openings, supply
    /// sags, sensor spikes, random hardware faults) in parallel and judge them.
    Campaign(campaign_cmd::CampaignArgs),
    /// Talk to a carrier (or `hter virtual-board`) over its serial port: status, settings,
    /// the cold-chain record, on-board commissioning.
    Board(board_cmd::BoardArgs),
    /// A simulated carrier on a pseudo-terminal: the board's step, record and interface in front
    /// of the plant model, N× faster than real time, for `hter board` to talk to.
    VirtualBoard(virtual_board_cmd::VirtualBoardArgs),
}

fn main() -> ExitCode {
    restore_sigpipe();
    report_a_full_stdout();
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {} (see 'hter --help')", one_line(&e.to_string()));
            return ExitCode::from(2);
        }
    };
    let result = match cli.command {
        None => demo_cmd::run(),
        Some(Command::Sim(a)) => sim_cmd::run(&a),
        Some(Command::Identify(a)) => identify_cmd::run(&a),
        Some(Command::Rtd(a)) => rtd_cmd::run(&a),
        Some(Command::Monitor(a)) => monitor_cmd::run(&a),
        Some(Command::Report(a)) => report_cmd::run(&a),
        Some(Command::Compare(a)) => compare_cmd::run(&a),
        Some(Command::Log2csv(a)) => log2csv_cmd::run(&a),
        Some(Command::Campaign(a)) => campaign_cmd::run(&a),
        Some(Command::Board(a)) => board_cmd::run(&a),
        Some(Command::VirtualBoard(a)) => virtual_board_cmd::run(&a),
    };
    // What is still buffered (a last line without its line end) goes out now, where a failed
    // write can be reported; at exit it would be lost without a word.
    let flushed = std::io::stdout().flush();
    match (result, flushed) {
        (Ok(()), Ok(())) => ExitCode::SUCCESS,
        (Ok(()), Err(e)) => {
            eprintln!("error: {STDOUT_UNWRITABLE}: {e}");
            ExitCode::FAILURE
        }
        (Err(e), _) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            ExitCode::FAILURE
        }
    }
}

/// The one-line error of output that cannot be written (a full disk, `> /dev/full`).
const STDOUT_UNWRITABLE: &str = "cannot write to stdout";

/// `println!` panics when stdout cannot be written ("failed printing to stdout: No space left
/// on device"): exit 101 with a backtrace hint, as for a bug, though the user's disk is full.
/// That panic, whichever command and thread printed, becomes the one-line error and exit 1;
/// every other panic is still reported as the bug it is. (A closed pipe never gets here: the
/// default SIGPIPE action of [`restore_sigpipe`] ends the process at the write.)
fn report_a_full_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg =
            payload.downcast_ref::<String>().map(String::as_str).or_else(|| payload.downcast_ref::<&str>().copied());
        if let Some(why) = msg.and_then(|m| m.strip_prefix("failed printing to stdout: ")) {
            // stderr may be full too: nothing more can be said then.
            let _ = writeln!(std::io::stderr(), "error: {STDOUT_UNWRITABLE}: {why}");
            std::process::exit(1);
        }
        default(info);
    }));
}

/// clap's message on one line. clap spreads it over paragraphs: the problem, whose later lines
/// carry what it is about (the missing arguments, the possible values), then tips, the usage
/// and a pointer to `--help`. The first line alone said "the following required arguments were
/// not provided:" without naming them; this keeps the whole first paragraph and the tips.
fn one_line(msg: &str) -> String {
    let mut parts: Vec<String> = Vec::new();
    for (i, para) in msg.split("\n\n").enumerate() {
        let text = para.lines().map(str::trim).filter(|l| !l.is_empty()).collect::<Vec<_>>().join(" ");
        if i == 0 || text.starts_with("tip:") {
            parts.push(text);
        }
    }
    let text = parts.join("; ");
    let text = text.trim_start_matches("error: ");
    if text.is_empty() {
        "invalid arguments".into()
    } else {
        text.into()
    }
}

/// A closed stdout (`hter sim | head -3`) ends the program quietly, as it ends `cat` or `ls`:
/// Rust ignores SIGPIPE, so `println!` got EPIPE and panicked with exit code 101 and a
/// backtrace hint on stderr. With the default action the kernel ends the process at the first
/// write into the closed pipe, and the shell sees the usual "killed by SIGPIPE" status.
fn restore_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any other thread exists; setting a signal's
    // disposition to its default has no other effect on the process.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
