//! `hter board`: the host side of the carrier's settings and data interface (SPEC §8), over a
//! serial port: the NUCLEO's ST-LINK virtual COM port (`/dev/ttyACM0`) or the pseudo-terminal
//! of `hter virtual-board` (the symlink it makes). The wire protocol is docs/interface.md: one
//! request line, then data lines and one final line, `ok` or `err <what>: <why>`.
//!
//! [`Board`] speaks the protocol over anything `Read + Write` (tested on scripted bytes);
//! [`status_json`] maps `status`'s `key=value` lines to typed JSON; [`run`] is the command.
//!
//! Sharing the port. A client has the port to itself (serialport's `TIOCEXCL` and `flock`) while
//! it has it open, so each command holds it only for its request: one that finds it held waits
//! up to `--timeout` for it. `identify` follows a commissioning for hours (≈ 6 h on a board)
//! with [`follow`]: it opens the port for each look at `status` ([`POLL`] apart) and closes it in
//! between, so an engineer can check the status, acknowledge an alarm or save the record
//! meanwhile; a look that finds the port held is skipped, and the watch gives up only when the
//! board has not answered for [`LOST_TIMEOUTS`] × `--timeout` (unplugged, stopped).

use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use serde_json::{Map, Number, Value};

use crate::link::MAX_LINE_BYTES;

/// The interface's line speed, baud (8N1, no flow control).
pub const BAUD: u32 = 115_200;

/// Largest reply accepted, bytes: a 30-day history is about 0.4 MB; anything far beyond is a
/// device that is not the board.
const MAX_REPLY_BYTES: usize = 64 << 20;

/// Silence that ends the drain of stale input after opening the port.
const QUIET: Duration = Duration::from_millis(50);
/// Longest drain of stale input. The board answers requests in the order they come
/// (docs/interface.md): one that is still streaming an old reply (a `history` whose client was
/// stopped: a 30-day history, ≈ 0.4 MB, takes ≈ 35 s at 115 200 baud) goes on until its final
/// line, and a request sent before then is answered after it. So the drain waits the stream out:
/// with 2 s, the rest of the history and its final `ok` were read as the reply to the next
/// request (`hter board set …` said nothing and exited 0, its own reply, maybe a refusal, unread).
const MAX_DRAIN: Duration = Duration::from_secs(60);
/// Wait between attempts to open a port another client holds: its request takes tens of ms.
const BUSY_RETRY: Duration = Duration::from_millis(50);

/// How often `identify` looks at the commissioning's progress (each look holds the port for
/// ≈ 60 ms: the drain's quiet time and the `status` reply).
pub const POLL: Duration = Duration::from_secs(1);
/// `identify` stops following when the board has not answered for this many `--timeout` (30 s
/// by default): a USB cable reseated or the ST-LINK's port re-enumerated is back within seconds;
/// a board unplugged or switched off is reported instead of waited for in silence.
pub const LOST_TIMEOUTS: f64 = 6.0;

/// Arguments of `hter board`.
#[derive(clap::Args, Debug)]
pub struct BoardArgs {
    /// Serial device: the board's port (e.g. /dev/ttyACM0) or the path of `hter virtual-board --link`.
    #[arg(long)]
    pub port: String,
    /// Longest wait for the board's next byte, and for the port while another client has it,
    /// s; `identify` stops following after six times this without an answer.
    #[arg(long, default_value_t = 5.0, allow_hyphen_values = true)]
    pub timeout: f64,
    /// The request.
    #[command(subcommand)]
    pub command: BoardCommand,
}

/// What to ask the board.
#[derive(clap::Subcommand, Debug)]
pub enum BoardCommand {
    /// Print the board's status (SPEC §8), one key=value per line.
    Status {
        /// Print one JSON object: numbers as numbers, `model` as {a, b, k}, `-` as null.
        #[arg(long)]
        json: bool,
    },
    /// Print every setting, one key=value per line.
    Get,
    /// Change a setting (setpoint_c, controller, cal_ice, cal_warm, model, sensor_offset_c, ack); the board
    /// validates it and refuses a bad value with one line, changing nothing.
    Set {
        /// Setting name.
        key: String,
        /// New value (e.g. 5, gpc, 0.12,0.00, or a model -1.7493,0.7514;-0.02708,-0.02987;5).
        #[arg(allow_hyphen_values = true)]
        value: String,
    },
    /// Acknowledge the alarm.
    Ack,
    /// Save the cold-chain record as a CSV that `hter monitor --input` reads.
    History {
        /// CSV file to write, FILE.csv (the board's rows verbatim, header included).
        #[arg(long)]
        output: PathBuf,
        /// Only rows from this board time on, s.
        #[arg(long, allow_negative_numbers = true)]
        since: Option<f64>,
    },
    /// Start on-board commissioning (rest, PRBS, fit, check, store) and follow its progress
    /// until it ends (Ctrl-C stops watching; the board carries on). The port is opened for each
    /// look only: other commands get through meanwhile.
    Identify {
        /// Start it and return at once.
        #[arg(long)]
        no_wait: bool,
        /// Abort a commissioning that is running (the previous model stays).
        #[arg(long, conflicts_with = "no_wait")]
        abort: bool,
    },
}

/// Checks a request before it goes out: one line of printable ASCII within the board's limit
/// (a value with a line end in it would be a second command).
pub fn check_request(line: &str) -> Result<()> {
    if let Some(c) = line.chars().find(|c| !(' '..='~').contains(c)) {
        bail!("{:?} is not allowed in a request (printable ASCII only)", c);
    }
    if line.len() > MAX_LINE_BYTES {
        bail!("the request is {} bytes, the board takes at most {MAX_LINE_BYTES}", line.len());
    }
    Ok(())
}

/// The connection failed (a write, a read, no reply in time), as opposed to the board refusing
/// a request: the watch of `identify` looks again at its next poll.
#[derive(Debug)]
pub struct LinkError(pub String);

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LinkError {}

/// One conversation with a board over `port`.
pub struct Board<P> {
    port: P,
    name: String,
    timeout_s: f64,
    buf: Vec<u8>,
}

impl<P: Read + Write> Board<P> {
    /// `name` and `timeout_s` only go into error messages; the port's own timeout applies.
    pub fn new(port: P, name: &str, timeout_s: f64) -> Self {
        Self { port, name: name.to_string(), timeout_s, buf: Vec::new() }
    }

    /// Sends `line` and reads the reply: its data lines if it ends in `ok`; an error whose
    /// message is the board's `err …` line, verbatim, if it ends in `err`; a [`LinkError`] if
    /// the connection failed.
    pub fn request(&mut self, line: &str) -> Result<Vec<String>> {
        check_request(line)?;
        // Ctrl-U first: it drops whatever a client that went away mid-line left in the board's
        // line (docs/interface.md, "Framing"), which the request would otherwise be glued to.
        self.port
            .write_all(format!("{}{line}\n", char::from(hter::iface::line::LINE_KILL)).as_bytes())
            .and_then(|()| self.port.flush())
            .map_err(|e| LinkError(format!("cannot write to '{}': {e}", self.name)))?;
        let mut data = Vec::new();
        let mut bytes = 0usize;
        loop {
            let l = self.next_line(line)?;
            bytes += l.len();
            if bytes > MAX_REPLY_BYTES {
                bail!(
                    "'{}': reply to '{line}' longer than {} MiB; is this the board?",
                    self.name,
                    MAX_REPLY_BYTES >> 20
                );
            }
            match l.as_str() {
                "" => {}
                "ok" => return Ok(data),
                _ if l == "err" || l.starts_with("err ") => bail!("{l}"),
                _ => data.push(l),
            }
        }
    }

    /// The next line the board sends, without its line end and trailing spaces.
    fn next_line(&mut self, request: &str) -> Result<String> {
        loop {
            if let Some(i) = self.buf.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.buf.drain(..=i).collect();
                let text = String::from_utf8_lossy(raw.get(..i).unwrap_or_default());
                return Ok(text.trim_end().to_string());
            }
            let mut chunk = [0u8; 4096];
            let failed = match self.port.read(&mut chunk) {
                Ok(0) => format!("'{}' closed the connection in the middle of the reply to '{request}'", self.name),
                Ok(n) => {
                    self.buf.extend_from_slice(chunk.get(..n).unwrap_or_default());
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => format!(
                    "no reply from '{}' to '{request}' within {} s (is it the board, and is nothing else using the port?)",
                    self.name, self.timeout_s
                ),
                Err(e) => format!("cannot read '{}': {e}", self.name),
            };
            return Err(LinkError(failed).into());
        }
    }
}

/// Splits `key=value` lines, in order; a line without `=` or a repeated key is an error.
pub fn parse_kv(lines: &[String]) -> Result<Vec<(String, String)>> {
    let mut out: Vec<(String, String)> = Vec::with_capacity(lines.len());
    for l in lines {
        let (k, v) = l.split_once('=').ok_or_else(|| anyhow!("the board sent '{l}', not key=value"))?;
        if out.iter().any(|(seen, _)| seen == k) {
            bail!("the board sent '{k}' twice");
        }
        out.push((k.to_string(), v.to_string()));
    }
    Ok(out)
}

/// `status` keys whose values are numbers (docs/interface.md § status fields).
const NUMERIC: [&str; 8] =
    ["t_s", "temp_c", "sensor_offset_c", "setpoint_c", "duty", "holdover_s", "resets", "settings_version"];

/// The SPEC §8 fields `status --json` must have.
const REQUIRED: [&str; 13] = [
    "t_s",
    "temp_c",
    "setpoint_c",
    "duty",
    "mode",
    "alarm",
    "controller",
    "model_a",
    "model_b",
    "model_k",
    "holdover_s",
    "resets",
    "firmware",
];

/// A number as the board wrote it: an integer stays an integer in JSON; `-` is null.
fn number(key: &str, v: &str) -> Result<Value> {
    if v == "-" {
        return Ok(Value::Null);
    }
    if let Ok(i) = v.parse::<i64>() {
        return Ok(Value::Number(i.into()));
    }
    v.parse::<f64>()
        .ok()
        .and_then(Number::from_f64)
        .map(Value::Number)
        .ok_or_else(|| anyhow!("the board sent {key}={v}, not a finite number"))
}

fn numbers(key: &str, v: &str) -> Result<Value> {
    v.split(',').map(|x| number(key, x)).collect::<Result<Vec<_>>>().map(Value::Array)
}

/// The `status` reply as one JSON object: `NUMERIC` keys as numbers, `model_a`/`model_b`/
/// `model_k` as `model: {a: [a1, a2], b: [b0, …], k}` with every B term the board sends (four,
/// b0 … b3, for the self-tuner's own estimate; two for a commissioned or uploaded model; null
/// when the board trusts no model), `cabinet_a`/`cabinet_b`/`cabinet_k` likewise as `cabinet`
/// (second order: b = [b0, b1]; null without one, or from a board that does not send them),
/// every other key as a string, `-` as null anywhere.
pub fn status_json(kv: &[(String, String)]) -> Result<Value> {
    if let Some(missing) = REQUIRED.iter().find(|r| !kv.iter().any(|(k, _)| k == *r)) {
        bail!("the board's status has no '{missing}'");
    }
    let get = |key: &str| kv.iter().find(|(k, _)| k == key).map_or("-", |(_, v)| v.as_str());
    let mut obj = Map::new();
    for (k, v) in kv {
        let value = match k.as_str() {
            "model_a" | "model_b" | "model_k" | "cabinet_a" | "cabinet_b" | "cabinet_k" => continue,
            _ if NUMERIC.contains(&k.as_str()) => number(k, v)?,
            _ if v == "-" => Value::Null,
            _ => Value::String(v.clone()),
        };
        obj.insert(k.clone(), value);
    }
    for name in ["model", "cabinet"] {
        let key = |part: &str| format!("{name}_{part}");
        let (a, b, k) = (get(&key("a")), get(&key("b")), get(&key("k")));
        let model = if [a, b, k].contains(&"-") {
            Value::Null
        } else {
            let k = k.parse::<u32>().map_err(|_| anyhow!("the board sent {name}_k={k}, not a delay in samples"))?;
            serde_json::json!({ "a": numbers(&key("a"), a)?, "b": numbers(&key("b"), b)?, "k": k })
        };
        obj.insert(name.into(), model);
    }
    Ok(Value::Object(obj))
}

/// Where a commissioning is (the `commissioning=` field of `status`).
#[derive(Debug, Clone, PartialEq)]
pub enum Commissioning {
    /// None ran since boot, or one was aborted.
    Idle,
    /// Running: the phase (`rest`, `excite`, `fit`) and its percent.
    Running(String, u8),
    /// Finished; the new model is in use.
    Done,
    /// Failed; the previous model stays. The board's reason.
    Failed(String),
}

impl Commissioning {
    /// Reads the field's value.
    pub fn parse(v: &str) -> Result<Self> {
        Ok(match v {
            "idle" => Self::Idle,
            "done" => Self::Done,
            _ if v.starts_with("failed") => {
                Self::Failed(v.strip_prefix("failed").unwrap_or_default().trim_start_matches(':').to_string())
            }
            _ => {
                let (phase, pct) = v
                    .split_once(':')
                    .and_then(|(ph, p)| Some((ph, p.parse::<u8>().ok().filter(|&p| p <= 100)?)))
                    .ok_or_else(|| anyhow!("the board sent commissioning={v}, not a known state"))?;
                Self::Running(phase.to_string(), pct)
            }
        })
    }
}

/// Polls of `status` showing `idle` after `identify` was accepted before the watch gives up.
const IDLE_POLLS: u32 = 5;

fn status_kv<P: Read + Write>(b: &mut Board<P>) -> Result<Vec<(String, String)>> {
    parse_kv(&b.request("status")?)
}

fn field<'a>(kv: &'a [(String, String)], key: &str) -> Result<&'a str> {
    kv.iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
        .ok_or_else(|| anyhow!("the board's status has no '{key}'"))
}

/// What one look at the board during `identify`'s watch came to.
#[derive(Debug)]
pub enum Poll {
    /// The board's status, `key=value` pairs in order.
    Status(Vec<(String, String)>),
    /// Another client has the port now: look again at the next poll.
    Busy,
    /// No answer (the port is gone, or nothing answers on it): why, in one line.
    NoAnswer(String),
}

/// How [`follow`] paces itself.
#[derive(Clone, Copy, Debug)]
pub struct Watch {
    /// Between two looks.
    pub every: Duration,
    /// Without an answer for this long (looks at a busy port count as reaching it), it gives up.
    pub lost_after: Duration,
}

/// One look at `status` for the watch, on a connection of its own, closed before it returns. A
/// port held by another client is waited for until the next look is due (commands run back
/// to back from another shell would otherwise have it at most looks).
fn poll_status(port: &str, timeout_s: f64) -> Result<Poll> {
    let p = match open_waiting(port, timeout_s, POLL) {
        Ok(p) => p,
        Err(e) if busy(&e) => return Ok(Poll::Busy),
        Err(e) => return Ok(Poll::NoAnswer(format!("cannot open '{port}': {}", e.description))),
    };
    match Board::new(p, port, timeout_s).request("status") {
        Ok(lines) => Ok(Poll::Status(parse_kv(&lines)?)),
        Err(e) if e.is::<LinkError>() => Ok(Poll::NoAnswer(e.to_string())),
        Err(e) => Err(e),
    }
}

/// Seconds as a person reads them: to a tenth, without a trailing `.0`.
fn secs(d: Duration) -> String {
    format!("{}", (d.as_secs_f64() * 10.0).round() / 10.0)
}

/// Follows a commissioning the board has accepted until it ends, looking with `poll` every
/// `watch.every`: progress on stderr as a bar on a terminal, else one line per new state on
/// stdout. Gives the final status when it is done; an error in one line when it failed, is not
/// running, or the board did not answer for `watch.lost_after`. A look at a port another client
/// holds is skipped; one without an answer is tried again until then.
pub fn follow(watch: &Watch, port: &str, mut poll: impl FnMut() -> Result<Poll>) -> Result<Vec<(String, String)>> {
    let bar = if std::io::stderr().is_terminal() {
        let pb = indicatif::ProgressBar::new(100);
        pb.set_style(
            indicatif::ProgressStyle::with_template("commissioning {msg:7} [{bar:30}] {pos:>3} %")
                .map_err(|e| anyhow!("{e}"))?,
        );
        Some(pb)
    } else {
        None
    };
    let give_up = |why: String| {
        bar.as_ref().map(indicatif::ProgressBar::abandon);
        anyhow!("{why}")
    };
    let (mut last, mut idle) = (String::new(), 0u32);
    // The last look that reached the port, and since when it has been held by another client.
    let (mut reached, mut held_since, mut held_said) = (Instant::now(), None::<Instant>, false);
    loop {
        std::thread::sleep(watch.every);
        let kv = match poll().map_err(|e| give_up(e.to_string()))? {
            Poll::Status(kv) => kv,
            Poll::Busy => {
                reached = Instant::now();
                let since = *held_since.get_or_insert(reached);
                if !held_said && since.elapsed() >= watch.lost_after {
                    let note = format!(
                        "'{port}' has been held by another program for {} s; following again when it is free",
                        secs(since.elapsed())
                    );
                    match &bar {
                        Some(pb) => pb.println(note),
                        None => eprintln!("{note}"),
                    }
                    held_said = true;
                }
                continue;
            }
            Poll::NoAnswer(why) => {
                held_since = None;
                if reached.elapsed() >= watch.lost_after {
                    return Err(give_up(format!(
                        "no answer from the board for {} s ({why}); stopped following the commissioning, which \
                         goes on on the board while it has power: 'hter board --port {port} status' shows it",
                        secs(watch.lost_after)
                    )));
                }
                continue;
            }
        };
        (reached, held_since, held_said) = (Instant::now(), None, false);
        let value = field(&kv, "commissioning").map_err(|e| give_up(e.to_string()))?.to_string();
        let state = Commissioning::parse(&value).map_err(|e| give_up(e.to_string()))?;
        match (&state, &bar) {
            (Commissioning::Running(phase, pct), Some(pb)) => {
                pb.set_message(phase.clone());
                pb.set_position(u64::from(*pct));
            }
            (Commissioning::Running(..), None) if value != last => println!("commissioning={value}"),
            _ => {}
        }
        last = value;
        match state {
            Commissioning::Running(..) => idle = 0,
            Commissioning::Idle => {
                idle += 1;
                if idle >= IDLE_POLLS {
                    return Err(give_up("commissioning is not running (the board says idle)".into()));
                }
            }
            Commissioning::Done => {
                bar.as_ref().map(indicatif::ProgressBar::finish_and_clear);
                return Ok(kv);
            }
            Commissioning::Failed(why) => {
                return Err(give_up(format!("commissioning failed: {why} (the previous model stays)")));
            }
        }
    }
}

/// The models and the law a finished commissioning left, in one line.
fn print_done(kv: &[(String, String)]) {
    let show = |k: &str| field(kv, k).unwrap_or("?").to_string();
    println!(
        "commissioning done: control model a={} b={} k={}; cabinet model a={} b={} k={}; controller {} ({})",
        show("model_a"),
        show("model_b"),
        show("model_k"),
        show("cabinet_a"),
        show("cabinet_b"),
        show("cabinet_k"),
        show("controller"),
        show("adaptive")
    );
}

/// Checks the history CSV (what `hter monitor` needs of it) and counts interval and event rows.
pub fn check_history(text: &str) -> Result<(usize, usize)> {
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).flexible(false).from_reader(text.as_bytes());
    let headers = rdr.headers().map_err(|e| anyhow!("line 1: {e}"))?.clone();
    for need in ["t_s", "temp_c"] {
        if !headers.iter().any(|h| h == need) {
            bail!("line 1: no '{need}' column (header: {})", headers.iter().collect::<Vec<_>>().join(","));
        }
    }
    let event = headers.iter().position(|h| h == "event");
    let (mut intervals, mut events) = (0, 0);
    for (i, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| anyhow!("line {}: {}", i + 2, e.to_string().lines().next().unwrap_or("bad row")))?;
        if event.and_then(|j| rec.get(j)).is_some_and(|e| !e.is_empty()) {
            events += 1;
        } else {
            intervals += 1;
        }
    }
    Ok((intervals, events))
}

fn history<P: Read + Write>(b: &mut Board<P>, output: &Path, since: Option<f64>) -> Result<()> {
    // Rows are stamped in whole record seconds: the next whole second is the same request.
    let request = since.map_or_else(|| "history".to_string(), |s| format!("history {}", s.ceil() as u64));
    let rows = b.request(&request)?;
    if rows.is_empty() {
        bail!("the board sent no CSV header for '{request}'");
    }
    let mut text = rows.join("\n");
    text.push('\n');
    crate::output::write(output, text.as_bytes())?;
    let (intervals, events) = check_history(&text)
        .with_context(|| format!("wrote '{}' as the board sent it, but it is not the history CSV", output.display()))?;
    println!("wrote {} rows ({intervals} intervals, {events} events) to {}", rows.len() - 1, output.display());
    Ok(())
}

/// A value the board's parser (the same `hter::iface`) would refuse as "not a decimal number"
/// is refused here, saying what the setting takes: the board's one reason covers a missing
/// pair (`cal_ice 0.1`), a model with one A coefficient, an exponent and a `nan` alike.
/// Range, step, digits and plausibility stay the board's to check, with its own words.
fn explain_format(key: &str, value: &str) -> Result<()> {
    use hter::iface::{Command, Why};
    let request = format!("set {key} {value}");
    let Err(refusal) = Command::parse(&request) else { return Ok(()) };
    if refusal.why != Why::NotDecimal {
        return Ok(());
    }
    let plain = "plain decimals (no exponent, nan or inf)";
    match key {
        "setpoint_c" => bail!("setpoint_c takes a plain decimal number (no exponent, nan or inf) in °C, e.g. 4.5; got '{value}'"),
        "cal_ice" | "cal_warm" => bail!(
            "{key} takes MEASURED,TRUE in °C (the channel's reading, the reference thermometer's), two {plain}, e.g. {}; got '{value}'",
            if key == "cal_ice" { "0.12,0.00" } else { "37.30,37.00" }
        ),
        "model" => bail!(
            "model takes A1,A2;B0,B1;K: two A and two B coefficients, {plain}, and the delay K in samples, e.g. -1.7493,0.7514;-0.02708,-0.02987;5; got '{value}'"
        ),
        _ => Ok(()),
    }
}

/// Checks what can be checked before the port is opened.
pub fn check_command(cmd: &BoardCommand) -> Result<()> {
    match cmd {
        BoardCommand::Set { key, value } => {
            check_request(&format!("set {key} {value}"))?;
            if key.is_empty() || value.is_empty() || key.contains(' ') || value.contains(' ') {
                bail!("set takes a KEY and a VALUE without spaces, got '{key}' '{value}'");
            }
            explain_format(key, value)
        }
        // The board sends CSV whatever the name says: `--output x.html` wrote CSV into a
        // file named .html (SPEC §8: `--output FILE.csv`), found out only when opened.
        BoardCommand::History { output, .. }
            if !output.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("csv")) =>
        {
            bail!("--output '{}' must end in .csv (the board's history is a CSV)", output.display())
        }
        BoardCommand::History { since: Some(s), .. }
            if !(s.is_finite() && *s >= 0.0 && *s < f64::from(hter::iface::HISTORY_SINCE_LIMIT_S)) =>
        {
            bail!(
                "--since must be a time ≥ 0 s and below 4e9 s (the record's clock), got {}",
                crate::sim_cmd::shown(*s)
            )
        }
        // Before the download (≈ 35 s for 30 days on a board), not after it.
        BoardCommand::History { output, .. } => crate::plot::check_dir(output),
        _ => Ok(()),
    }
}

/// Runs one `hter board` command on an open connection; for `identify` (without `--abort`),
/// starts the commissioning, which [`run`] then follows on connections of its own.
pub fn run_on<P: Read + Write>(b: &mut Board<P>, cmd: &BoardCommand) -> Result<()> {
    match cmd {
        BoardCommand::Status { json: true } => {
            println!("{}", status_json(&status_kv(b)?)?);
        }
        BoardCommand::Status { json: false } | BoardCommand::Get => {
            let request = if matches!(cmd, BoardCommand::Get) { "get" } else { "status" };
            for l in b.request(request)? {
                println!("{l}");
            }
        }
        BoardCommand::Set { key, value } => {
            let data = b.request(&format!("set {key} {value}"))?;
            // The board's warnings on an accepted value (`set controller onoff`) go where
            // warnings go; the acceptance is still said on stdout.
            let (warnings, data): (Vec<_>, Vec<_>) = data.iter().partition(|l| l.starts_with("warning:"));
            warnings.iter().for_each(|l| eprintln!("{l}"));
            data.iter().for_each(|l| println!("{l}"));
            if data.is_empty() {
                println!("ok: {key} = {value}");
            }
        }
        BoardCommand::Ack => {
            let data = b.request("ack")?;
            data.iter().for_each(|l| println!("{l}"));
            if data.is_empty() {
                println!("ok: alarm acknowledged");
            }
        }
        BoardCommand::History { output, since } => history(b, output, *since)?,
        BoardCommand::Identify { abort: true, .. } => {
            b.request("identify abort")?.iter().for_each(|l| println!("{l}"));
            println!("ok: commissioning aborted; the previous model stays");
        }
        BoardCommand::Identify { no_wait, .. } => {
            b.request("identify")?.iter().for_each(|l| println!("{l}"));
            if *no_wait {
                println!("commissioning started; follow it with 'hter board --port {} status'", b.name);
            }
        }
    }
    Ok(())
}

/// Another client has the port. serialport reports both of its locks as `NoDevice`: the tty's
/// `TIOCEXCL` (EBUSY at open, what a non-root user meets) and its `flock` ("Unable to acquire
/// exclusive lock", what root meets, and anyone on a pty whose flag the virtual board cleared).
fn busy(e: &serialport::Error) -> bool {
    e.kind() == serialport::ErrorKind::NoDevice
}

/// Why the port could not be opened, in one line; `waited_s` is how long a held port was waited
/// for. No `hter board` command holds it for long (`identify` only for each look at the
/// commissioning), except a history download over a real board's line (≈ 35 s for 30 days).
fn open_error(port: &str, e: &serialport::Error, waited_s: f64) -> String {
    if busy(e) {
        format!(
            "cannot open '{port}': another program has held it for {waited_s} s (a terminal such as picocom or \
             screen, or another 'hter board' command such as a history download); close it or try again, or \
             wait longer with --timeout"
        )
    } else {
        format!("cannot open '{port}': {}", e.description)
    }
}

/// Opens `port` as the interface wants it (115200 8N1, no flow control, reads waiting up to
/// `timeout_s`) and drops the input from before this connection; one attempt.
fn open_port(port: &str, timeout_s: f64) -> serialport::Result<Box<dyn serialport::SerialPort>> {
    let timeout = Duration::from_secs_f64(timeout_s);
    let mut p = serialport::new(port, BAUD)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(timeout)
        .open()?;
    // Bytes from before this connection (the rest of a reply a killed client never read, a
    // person's typing) are not ours: drop what is buffered, then what still arrives until the
    // line is quiet (a board still streaming an old reply finishes it first: [`MAX_DRAIN`]).
    p.clear(serialport::ClearBuffer::Input)?;
    p.set_timeout(QUIET)?;
    if !drain(&mut p, MAX_DRAIN) {
        return Err(serialport::Error::new(
            serialport::ErrorKind::Unknown,
            format!("it is still sending after {} s (a reply nobody read, or not the board)", MAX_DRAIN.as_secs()),
        ));
    }
    p.set_timeout(timeout)?;
    Ok(p)
}

/// Reads and drops what `p` sends until a read finds the line quiet (the port's timeout); `false`
/// if it was still sending after `max`.
fn drain<P: Read + ?Sized>(p: &mut P, max: Duration) -> bool {
    let start = Instant::now();
    let mut stale = [0u8; 4096];
    loop {
        if !p.read(&mut stale).is_ok_and(|n| n > 0) {
            return true;
        }
        if start.elapsed() >= max {
            return false;
        }
    }
}

/// [`open_port`], waiting up to `wait` while another client holds the port.
fn open_waiting(port: &str, timeout_s: f64, wait: Duration) -> serialport::Result<Box<dyn serialport::SerialPort>> {
    let start = Instant::now();
    loop {
        match open_port(port, timeout_s) {
            Err(e) if busy(&e) && start.elapsed() < wait => std::thread::sleep(BUSY_RETRY),
            opened => return opened,
        }
    }
}

/// A connection to the board at `port`; a port another client holds is waited for up to
/// `timeout_s` (its request takes tens of milliseconds; `identify`'s watch holds it that long
/// once a second).
fn connect(port: &str, timeout_s: f64) -> Result<Board<Box<dyn serialport::SerialPort>>> {
    open_waiting(port, timeout_s, Duration::from_secs_f64(timeout_s))
        .map(|p| Board::new(p, port, timeout_s))
        .map_err(|e| anyhow!("{}", open_error(port, &e, timeout_s)))
}

/// `hter board`.
pub fn run(args: &BoardArgs) -> Result<()> {
    if !args.timeout.is_finite() || args.timeout <= 0.0 || args.timeout > 3600.0 {
        bail!("--timeout must be within (0, 3600] s, got {}", crate::sim_cmd::shown(args.timeout));
    }
    check_command(&args.command)?;
    let mut b = connect(&args.port, args.timeout)?;
    run_on(&mut b, &args.command)?;
    if let BoardCommand::Identify { no_wait: false, abort: false } = args.command {
        // The port is free between the watch's looks.
        drop(b);
        let watch = Watch { every: POLL, lost_after: Duration::from_secs_f64(LOST_TIMEOUTS * args.timeout) };
        print_done(&follow(&watch, &args.port, || poll_status(&args.port, args.timeout))?);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A port that plays back scripted chunks, then times out, and records what is written.
    struct Scripted {
        chunks: std::collections::VecDeque<Vec<u8>>,
        written: Vec<u8>,
    }

    impl Scripted {
        fn new(chunks: &[&[u8]]) -> Self {
            Self { chunks: chunks.iter().map(|c| c.to_vec()).collect(), written: Vec::new() }
        }
    }

    impl Read for Scripted {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let Some(mut c) = self.chunks.pop_front() else {
                return Err(std::io::ErrorKind::TimedOut.into());
            };
            let n = c.len().min(buf.len());
            buf[..n].copy_from_slice(&c[..n]);
            if n < c.len() {
                self.chunks.push_front(c.split_off(n));
            }
            Ok(n)
        }
    }

    impl Write for Scripted {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.written.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// The drain waits out a stream however long it lasts, up to its limit, and longer than a
    /// 30-day history takes at the line's speed (it gave up after 2 s, and the rest of an
    /// abandoned `history` was read as the next request's reply).
    #[test]
    fn the_drain_waits_out_a_stream_up_to_its_limit() {
        let mut quiet = Scripted::new(&[b"t_s,temp_c\r\n", b"0,4.00\r\n", b"ok\r\n"]);
        assert!(drain(&mut quiet, MAX_DRAIN));
        assert!(quiet.chunks.is_empty());
        /// A port that never stops sending.
        struct Endless;
        impl Read for Endless {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                std::thread::sleep(Duration::from_millis(1));
                buf[0] = b'x';
                Ok(1)
            }
        }
        assert!(!drain(&mut Endless, Duration::from_millis(20)));
        let history_s = 400_000.0 / (f64::from(BAUD) / 10.0);
        assert!(MAX_DRAIN.as_secs_f64() > 1.5 * history_s, "{history_s} s");
    }

    fn board(chunks: &[&[u8]]) -> Board<Scripted> {
        Board::new(Scripted::new(chunks), "/dev/test", 5.0)
    }

    #[test]
    fn a_reply_ends_at_its_final_line_however_it_is_split() {
        let mut b = board(&[b"t_s=1", b"2\r\nmode=nor", b"mal\r", b"\nok\r\nstray"]);
        assert_eq!(b.request("status").unwrap(), vec!["t_s=12", "mode=normal"]);
        assert_eq!(b.port.written, b"\x15status\n", "Ctrl-U, then the request");
        // The stray bytes after `ok` are the start of what comes next, not lost.
        b.port.chunks.push_back(b"=1\nok\n".to_vec());
        assert_eq!(b.request("get").unwrap(), vec!["stray=1"]);
        // Data only, no final line yet: a timeout that names the request.
        let e = board(&[b"t_s=1\r\n"]).request("status").unwrap_err().to_string();
        assert!(e.contains("no reply") && e.contains("'status'"), "{e}");
    }

    #[test]
    fn a_refusal_is_the_boards_line_verbatim() {
        let line = "err setpoint_c: 12 is outside 2.5…7.5 °C";
        let mut b = board(&[format!("{line}\r\n").as_bytes()]);
        let e = b.request("set setpoint_c 12").unwrap_err();
        assert_eq!(format!("{e:#}"), line);
        // A data line that merely starts with "ok" or "err" is data.
        let mut b = board(&[b"okay=1\r\nerrors=0\r\nok\r\n"]);
        assert_eq!(b.request("status").unwrap(), vec!["okay=1", "errors=0"]);
    }

    #[test]
    fn requests_are_one_printable_line_within_the_limit() {
        assert!(check_request("set setpoint_c 5").is_ok());
        assert!(check_request("set setpoint_c 5\nset controller pi").unwrap_err().to_string().contains("\\n"));
        assert!(check_request("set setpoint_c 5 °C").is_err());
        let e = check_request(&format!("set model {}", "1".repeat(90))).unwrap_err().to_string();
        assert!(e.contains("at most 96"), "{e}");
        // Refused before anything is written.
        let mut b = board(&[]);
        assert!(b.request("get\r").is_err());
        assert!(b.port.written.is_empty());
    }

    fn kv(lines: &[&str]) -> Vec<(String, String)> {
        parse_kv(&lines.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap()
    }

    const STATUS: [&str; 20] = [
        "t_s=86400",
        "temp_c=4.93",
        "setpoint_c=5.00",
        "duty=0.412",
        "mode=normal",
        "alarm=off",
        "controller=gpc",
        "adaptive=adaptive",
        "controllers=gpc,pi,onoff",
        "model_a=-1.7900,0.8000",
        "model_b=-0.0150,-0.0080",
        "model_k=1",
        "cabinet_a=-1.9390,0.9392",
        "cabinet_b=-0.2798,0.2717",
        "cabinet_k=9",
        "holdover_s=-",
        "resets=2",
        "firmware=hter 0.1.0",
        "commissioning=idle",
        "settings_version=7",
    ];

    #[test]
    fn status_json_types_the_spec_fields() {
        let v = status_json(&kv(&STATUS)).unwrap();
        let want = serde_json::json!({
            "t_s": 86400, "temp_c": 4.93, "setpoint_c": 5.0, "duty": 0.412, "mode": "normal",
            "alarm": "off", "controller": "gpc", "adaptive": "adaptive", "controllers": "gpc,pi,onoff",
            "model": {"a": [-1.79, 0.8], "b": [-0.015, -0.008], "k": 1},
            "cabinet": {"a": [-1.939, 0.9392], "b": [-0.2798, 0.2717], "k": 9},
            "holdover_s": null, "resets": 2, "firmware": "hter 0.1.0", "commissioning": "idle",
            "settings_version": 7
        });
        assert_eq!(v, want);
        assert!(v["resets"].is_u64() && v["temp_c"].is_f64());
        // The self-tuner's own estimate has four B terms: all of them are in the JSON.
        let mut s = STATUS.to_vec();
        s[10] = "model_b=-0.0150,-0.0080,-0.0040,0.0000";
        let v = status_json(&kv(&s)).unwrap();
        assert_eq!(v["model"]["b"], serde_json::json!([-0.015, -0.008, -0.004, 0.0]));
        assert_eq!(v["cabinet"]["b"], serde_json::json!([-0.2798, 0.2717]));
    }

    #[test]
    fn status_json_refuses_what_is_not_the_boards_status() {
        let mut s = STATUS.to_vec();
        s[1] = "temp_c=nan";
        assert!(status_json(&kv(&s)).unwrap_err().to_string().contains("temp_c=nan"));
        s[1] = "temp_c=-";
        assert_eq!(status_json(&kv(&s)).unwrap()["temp_c"], Value::Null);
        s[10] = "model_b=-";
        assert_eq!(status_json(&kv(&s)).unwrap()["model"], Value::Null);
        s[10] = "model_b=-0.01,x";
        assert!(status_json(&kv(&s)).unwrap_err().to_string().contains("model_b=x"));
        let e = status_json(&kv(&STATUS[1..])).unwrap_err().to_string();
        assert!(e.contains("no 't_s'"), "{e}");
        assert!(parse_kv(&["t_s=1".into(), "t_s=2".into()]).unwrap_err().to_string().contains("twice"));
        assert!(parse_kv(&["hello".into()]).unwrap_err().to_string().contains("not key=value"));
    }

    #[test]
    fn a_port_another_client_holds_says_who_may_hold_it_and_what_to_do() {
        use serialport::{Error, ErrorKind};
        for held in [
            Error::new(ErrorKind::NoDevice, "Unable to acquire exclusive lock on serial port"),
            Error::new(ErrorKind::NoDevice, "EBUSY: Device or resource busy"),
        ] {
            assert!(busy(&held));
            let e = open_error("/dev/ttyACM0", &held, 5.0);
            assert!(e.contains("another program has held it for 5 s") && e.contains("--timeout"), "{e}");
            assert!(!e.contains('\n') && !e.contains("identify"), "the watch no longer holds it: {e}");
        }
        let gone = Error::new(ErrorKind::Io(std::io::ErrorKind::NotFound), "No such file or directory");
        assert!(!busy(&gone));
        assert_eq!(open_error("/dev/x", &gone, 5.0), "cannot open '/dev/x': No such file or directory");
    }

    #[test]
    fn a_failed_connection_is_told_from_a_refusal() {
        let e = board(&[b"t_s=1\r\n"]).request("status").unwrap_err();
        assert!(e.is::<LinkError>() && e.to_string().contains("no reply"), "{e}");
        let e = board(&[b"err status: busy\r\n"]).request("status").unwrap_err();
        assert!(!e.is::<LinkError>(), "{e}");
    }

    /// Plays `polls` back, then `rest` for ever.
    fn scripted(polls: Vec<Poll>, rest: fn() -> Poll) -> impl FnMut() -> Result<Poll> {
        let mut polls = std::collections::VecDeque::from(polls);
        move || Ok(polls.pop_front().unwrap_or_else(rest))
    }

    fn at(state: &str) -> Poll {
        Poll::Status(kv(&["t_s=1", &format!("commissioning={state}")]))
    }

    #[test]
    fn the_watch_skips_a_held_port_and_rides_out_missed_answers() {
        let hour = Watch { every: Duration::ZERO, lost_after: Duration::from_secs(3600) };
        let gone = || Poll::NoAnswer("cannot open '/dev/x': No such file or directory".into());
        let polls = vec![Poll::Busy, at("excite:10"), gone(), Poll::Busy, gone(), at("fit:90"), at("done")];
        let kv = follow(&hour, "/dev/x", scripted(polls, || unreachable!())).unwrap();
        assert_eq!(field(&kv, "commissioning").unwrap(), "done");
        // A held port is never the board gone, however long it is held.
        let now = Watch { lost_after: Duration::ZERO, ..hour };
        let polls = (0..20).map(|_| Poll::Busy).chain([at("done")]).collect();
        assert!(follow(&now, "/dev/x", scripted(polls, || unreachable!())).is_ok());
    }

    #[test]
    fn the_watch_gives_up_on_a_board_that_does_not_answer_in_one_line() {
        let soon = Watch { every: Duration::from_millis(1), lost_after: Duration::from_millis(20) };
        let gone = || Poll::NoAnswer("cannot open '/dev/x': No such file or directory".into());
        let e = follow(&soon, "/dev/x", scripted(vec![at("excite:10")], gone)).unwrap_err().to_string();
        assert!(e.starts_with("no answer from the board for "), "{e}");
        assert!(e.contains("No such file") && e.contains("'hter board --port /dev/x status'"), "{e}");
        assert!(!e.contains('\n'));
        // What the board says ends the watch at once.
        let e = follow(&soon, "/dev/x", scripted(vec![at("failed:no_excitation")], || unreachable!()));
        assert!(e.unwrap_err().to_string().contains("commissioning failed: no_excitation"));
        let refused = || -> Result<Poll> { bail!("err status: nope") };
        assert_eq!(follow(&soon, "/dev/x", refused).unwrap_err().to_string(), "err status: nope");
    }

    #[test]
    fn commissioning_states() {
        assert_eq!(Commissioning::parse("idle").unwrap(), Commissioning::Idle);
        assert_eq!(Commissioning::parse("excite:42").unwrap(), Commissioning::Running("excite".into(), 42));
        assert_eq!(Commissioning::parse("done").unwrap(), Commissioning::Done);
        assert_eq!(
            Commissioning::parse("failed:no_excitation").unwrap(),
            Commissioning::Failed("no_excitation".into())
        );
        assert!(Commissioning::parse("fit:101").is_err());
        assert!(Commissioning::parse("dancing").is_err());
    }

    #[test]
    fn history_csv_counts_intervals_and_events() {
        let text = "t_s,temp_c,min_c,max_c,duty,mode,event\n\
                    300,5.10,4.90,5.30,0.400,normal,\n\
                    300,5.10,5.10,5.10,,,set:setpoint_c=4.00\n\
                    600,4.20,4.00,4.60,0.520,normal,\n";
        assert_eq!(check_history(text).unwrap(), (2, 1));
        // An unquoted model value has commas: the row has too many fields.
        let bad = format!("{text}900,4.0,4.0,4.0,,,set:model=-1.8,0.81;-0.02,-0.01;1\n");
        assert!(check_history(&bad).unwrap_err().to_string().contains("line 5"));
        assert!(check_history("time,temp\n1,2\n").unwrap_err().to_string().contains("no 't_s'"));
    }
}
