//! The settings and data interface under noise (docs/interface.md): what a loose cable, a laptop
//! waking from sleep or a person at a terminal can send to USART2, through the framer
//! (`hter::iface::line::LineFramer`) and the handler (`hter::app::App::handle`), between the
//! board's samples. A panic there is a fail-safe stop (outputs safe, reset, a `board fault` on the
//! record), so for any input:
//!
//! - framing: no panic; a line is 1…[`MAX_LINE`] bytes of printable ASCII without surrounding
//!   spaces, and the frames are what the framing rules give (an independent model of them below);
//!   a request begun with Ctrl-U comes through whatever came before it;
//! - replies: no panic; a request gets its data lines and exactly one final line, `ok` or `err
//!   <what>: <why>` (a refusal alone), with `\r\n` line ends, within the firmware's reply buffer;
//!   an empty line gets nothing, `history` leaves its rows to the glue;
//! - a refused line changes nothing: a twin board that never saw it replies, samples, stores and
//!   reports exactly as the board that refused it, then and later;
//! - an accepted `set` changes its setting only, to the value typed (the standard library's
//!   reading of the decimal), inside its range and step, and the records queued for flash decode
//!   back to it; a value the contract takes is not refused.
//!
//! The quick proptests run on every `cargo test` (a few seconds in debug); the `#[ignore]`d long
//! variants run in CI: `cargo test --release --test iface_fuzz -- --ignored`.

use std::collections::VecDeque;

use hter::app::{App, AppConfig, Boot, Handled, SampleIn};
use hter::failsafe::{StopInfo, StopKind, Stops};
use hter::iface::line::{Frame, LineFramer, LINE_KILL};
use hter::iface::{Law, SetRequest, MAX_LINE, SETPOINT_RANGE_C};
use hter::model::{Model, MAX_K};
use hter::persist::log::{LogEntry, SettingKey};
use hter::persist::{ModelRecord, Save, SettingsRecord};
use hter::step::{CarrierConfig, ValidConfig};
use hter::units::Celsius;
use proptest::prelude::*;
use proptest::sample::select;

/// The firmware's reply buffer, bytes (`firmware/src/serial.rs`, `REPLY_CAP`): a longer reply is
/// not sent, `err reply: too long` is.
const REPLY_CAP: usize = 1024;

/// The laws of the bench's build, the first its default.
const LAWS: &[Law] = &[Law::Gpc, Law::Pi, Law::OnOff];

/// What a refusal may name (docs/interface.md: the key, `line`, or the command).
const WHATS: &[&str] = &[
    "line",
    "set",
    "setpoint_c",
    "controller",
    "cal_ice",
    "cal_warm",
    "model",
    "ack",
    "sensor_offset_c",
    "history",
    "identify",
];

/// `status`'s keys, in the contract's order: the first column of docs/interface.md's table.
fn status_keys() -> &'static [&'static str] {
    static KEYS: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    KEYS.get_or_init(|| {
        let doc = include_str!("../docs/interface.md");
        let table = doc.split("## `status` fields").nth(1).and_then(|s| s.split("\n#").next()).unwrap_or("");
        let keys: Vec<&str> = table.lines().filter_map(|l| l.strip_prefix("| `")?.split('`').next()).collect();
        assert_eq!(keys.first(), Some(&"t_s"), "docs/interface.md's status table");
        keys
    })
}

fn config() -> AppConfig {
    AppConfig {
        carrier: ValidConfig::DEFAULT,
        adaptive: hter::profile::ADAPTIVE_GPC,
        laws: LAWS,
        setpoint_c: 4.0,
        firmware: "hter fuzz",
        history_save_samples: 360,
        model_save_samples: 1440,
    }
}

/// How a board starts: what its flash and reset flags held.
#[derive(Clone, Copy, Debug)]
enum Start {
    /// A new board.
    New,
    /// Stored settings with this law.
    Law(Law),
    /// After a fail-safe stop: the indicator latched, an `ack` has something to acknowledge.
    AfterStop,
    /// With a stored cabinet model.
    #[cfg(feature = "holdover")]
    Cabinet,
    /// A new board that has held its setpoint for this many samples (190 and more: `identify` is
    /// accepted).
    Held(u16),
    /// A commissioning under way, this many samples into its rest.
    Commissioning(u8),
}

fn boot(start: Start) -> Boot {
    let base = Boot::NEW;
    match start {
        Start::New | Start::Held(_) | Start::Commissioning(_) => base,
        Start::Law(law) => {
            Boot { settings: Some(SettingsRecord { law, ..*App::new(config(), &base).settings() }), ..base }
        }
        Start::AfterStop => {
            let stall = StopInfo::new(StopKind::ControlStall, 0, 0, 25_000);
            Boot { stops: Stops { earlier: None, latest: Some(stall), fresh: true }, ..base }
        }
        #[cfg(feature = "holdover")]
        Start::Cabinet => {
            Boot { cabinet: Some(Model::second_order([-1.9, 0.905], [-0.05, -0.05], 2).unwrap()), ..base }
        }
    }
}

/// The counts the default front end reads at `t` °C.
fn counts_at(t: f32) -> u32 {
    let cfg = CarrierConfig::DEFAULT;
    cfg.rtd.resistance(Celsius(t)).map_or(0, |r| cfg.adc.counts(r))
}

/// Samples a new board holding its setpoint takes before `identify` is accepted.
const COMMISSION_AFTER: usize = 190;

/// One sample's input.
#[derive(Clone, Copy, Debug)]
enum Sample {
    /// The plant's temperature, read with a count of dither.
    Plant,
    /// Whatever the ADC gave: a broken front end, a pulled probe.
    Counts(u32),
    /// The plant's reading with the reference conversions out of their window.
    ReferenceFault,
}

/// The app in front of a first-order plant holding 4 °C (τ = 30 min, −43 °C per unit duty from
/// 28 °C, 60 s dead time: `src/app/tests.rs`'s bench), and what it handed over for flash.
struct Board {
    app: App,
    t_ms: u64,
    load_c: f32,
    pipe: VecDeque<f32>,
    /// The RTD lead's own error, °C: the sensor reads the load this much warm (a lead or
    /// connector fault, which the offset watch measures and subtracts).
    lead_c: f32,
    /// Everything queued for flash, oldest first.
    saves: Vec<Save>,
}

impl Board {
    fn new(start: Start) -> Board {
        let mut b = Board {
            app: App::new(config(), &boot(start)),
            t_ms: 0,
            load_c: 4.0,
            pipe: [24.0 / 43.0; 6].into(),
            lead_c: 0.0,
            saves: Vec::new(),
        };
        b.drain();
        match start {
            Start::Held(n) => {
                b.run(usize::from(n), Sample::Plant);
            }
            Start::Commissioning(n) => {
                b.run(COMMISSION_AFTER, Sample::Plant);
                assert_eq!(b.send("identify").1, "ok\r\n");
                b.run(usize::from(n), Sample::Plant);
            }
            _ => {}
        }
        b.drain();
        b
    }

    /// Runs `n` samples; each one's output and saves in `trace` (as text: NaN is no reading).
    fn run(&mut self, n: usize, kind: Sample) -> String {
        let mut trace = String::new();
        for _ in 0..n {
            let dither = u32::from(!self.t_ms.is_multiple_of(20_000));
            let counts = match kind {
                Sample::Plant | Sample::ReferenceFault => counts_at(self.load_c + self.lead_c) + dither,
                Sample::Counts(c) => c,
            };
            let input = SampleIn {
                t_ms: self.t_ms,
                counts,
                reference_ok: !matches!(kind, Sample::ReferenceFault),
                board: Default::default(),
            };
            let out = self.app.sample(&input);
            self.pipe.push_back(out.step.duty.get());
            let duty = self.pipe.pop_front().unwrap_or(0.0);
            self.load_c += (28.0 - 43.0 * duty - self.load_c) * (10.0 / 1800.0);
            self.t_ms += 10_000;
            trace += &format!("{out:?}\n");
            for s in self.drain() {
                trace += &format!("{s:?}\n");
            }
        }
        trace
    }

    /// What the app queued since the last drain.
    fn drain(&mut self) -> Vec<Save> {
        let new: Vec<Save> = std::iter::from_fn(|| self.app.next_save()).collect();
        self.saves.extend(&new);
        new
    }

    fn send(&mut self, line: &str) -> (Handled, String) {
        let mut out = String::new();
        let handled = self.app.handle(line, &mut out);
        (handled, out)
    }

    /// Everything a host can read of the board's state: `status` and `get`.
    fn observe(&mut self) -> String {
        let (_, status) = self.send("status");
        let (_, get) = self.send("get");
        status + &get
    }
}

/// How a reply ended.
#[derive(Clone, Debug, PartialEq)]
enum Ended {
    /// No reply (an empty line).
    Nothing,
    /// `history`: the glue streams the rows.
    History(u32),
    /// `ok`, after these data lines.
    Ok(Vec<String>),
    /// `err <what>: <why>`.
    Err(String, String),
}

/// The words of a line as the contract splits them (spaces; a tab too, which the handler takes
/// though the framer never passes one).
fn words(line: &str) -> Vec<&str> {
    line.split_ascii_whitespace().collect()
}

/// Checks a reply against the contract's reply grammar and returns how it ended.
fn check_reply(line: &str, handled: Handled, reply: &str) -> Result<Ended, TestCaseError> {
    let blank = line.bytes().all(|b| b == b' ' || b == b'\t');
    if let Handled::History { since_s } = handled {
        prop_assert_eq!(reply, "", "history's rows are the glue's to send");
        prop_assert_eq!(words(line).first().copied(), Some("history"));
        prop_assert!(since_s <= 4_000_000_000, "{since_s}");
        return Ok(Ended::History(since_s));
    }
    if blank && line.len() <= MAX_LINE {
        prop_assert_eq!(reply, "", "an empty line gets no reply");
        return Ok(Ended::Nothing);
    }
    prop_assert!(reply.len() <= REPLY_CAP, "{} bytes, more than the board's reply buffer", reply.len());
    let Some(body) = reply.strip_suffix("\r\n") else {
        return Err(TestCaseError::fail(format!("{reply:?} does not end with a line end")));
    };
    let lines: Vec<&str> = body.split("\r\n").collect();
    for l in &lines {
        prop_assert!(!l.contains(['\r', '\n']), "a bare line end in {reply:?}");
        prop_assert!(!l.is_empty(), "an empty reply line in {reply:?}");
    }
    let (last, data) = lines.split_last().expect("split gives one piece at least");
    for d in data {
        prop_assert!(*d != "ok" && !d.starts_with("err "), "a second final line in {reply:?}");
    }
    if *last == "ok" {
        return Ok(Ended::Ok(data.iter().map(|d| d.to_string()).collect()));
    }
    let Some(refusal) = last.strip_prefix("err ") else {
        return Err(TestCaseError::fail(format!("{reply:?} has no final line")));
    };
    prop_assert!(data.is_empty(), "a refusal is one line: {reply:?}");
    let Some((what, why)) = refusal.split_once(": ") else {
        return Err(TestCaseError::fail(format!("{last:?} is not `err <what>: <why>`")));
    };
    prop_assert!(WHATS.contains(&what), "{last:?} names {what:?}");
    prop_assert!(!why.trim().is_empty() && why.trim() == why, "{last:?}: the reason is empty or padded");
    Ok(Ended::Err(what.to_string(), why.to_string()))
}

/// Data lines of `status` and `get`: `key=value`, the value without spaces, the keys in order.
fn check_data(line: &str, data: &[String], settings: &SettingsRecord) -> Result<(), TestCaseError> {
    let keys: Vec<&str> = data.iter().filter_map(|d| d.split_once('=').map(|(k, _)| k)).collect();
    let want: &[&str] = match words(line).as_slice() {
        ["status"] => status_keys(),
        ["get"] => &["setpoint_c", "controller", "cal_ice", "cal_warm"],
        ["help"] => {
            prop_assert_eq!(data.len(), hter::iface::HELP.len());
            return Ok(());
        }
        ["ack"] | ["set", "ack"] | ["set", "ack", "1"] => {
            prop_assert!(data.len() <= 1, "{data:?}");
            return Ok(());
        }
        ["set", "controller", "onoff"] => {
            prop_assert!(data.len() <= 1 && data.iter().all(|d| d.starts_with("warning: ")), "{data:?}");
            return Ok(());
        }
        _ => {
            prop_assert!(data.is_empty(), "{line:?} got data lines {data:?}");
            return Ok(());
        }
    };
    prop_assert_eq!(keys.as_slice(), want);
    for d in data {
        let (k, v) = d.split_once('=').unwrap_or_default();
        // `firmware` is `hter <version>` (the contract's table; `hter board` splits at the `=`).
        prop_assert!(!v.is_empty() && (!v.contains(' ') || k == "firmware"), "{d:?}");
        prop_assert!(value_as_documented(k, v, settings, want == status_keys()), "{d:?} ({settings:?})");
    }
    Ok(())
}

/// A decimal of exactly `decimals` decimals (`-` for none where `none`).
fn fixed(v: &str, decimals: usize) -> Option<f32> {
    let (int, frac) = v.split_once('.').unwrap_or((v, ""));
    let int = int.strip_prefix('-').unwrap_or(int);
    let ok = !int.is_empty() && int.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) && frac.len() == decimals;
    ok.then(|| v.parse::<f32>().ok()).flatten()
}

fn whole(v: &str) -> Option<u64> {
    v.bytes().all(|b| b.is_ascii_digit()).then(|| v.parse().ok()).flatten()
}

/// A `status` (or `get`) value as its table in docs/interface.md describes it; the setpoint,
/// law, calibration and settings version as the board keeps them.
fn value_as_documented(k: &str, v: &str, s: &SettingsRecord, status: bool) -> bool {
    let list = |v: &str, n: std::ops::RangeInclusive<usize>, decimals| {
        let parts: Vec<&str> = v.split(',').collect();
        n.contains(&parts.len()) && parts.iter().all(|p| fixed(p, decimals).is_some())
    };
    let pair_is = |v: &str, p: [f32; 2]| {
        let parts: Vec<Option<f32>> = v.split(',').map(|x| fixed(x, 2)).collect();
        parts == [Some(p[0]), Some(p[1])]
    };
    let shown = |v: &str, x: f32| fixed(v, 2) == Some(x);
    match k {
        "t_s" => v.split_once('.').is_some_and(|(s, t)| whole(s).is_some() && t.len() == 1 && whole(t).is_some()),
        "temp_c" | "sensor_offset_c" => v == "-" || fixed(v, 2).is_some(),
        // What `status` shows is the setpoint in force; `get` the one set: the same here.
        "setpoint_c" => shown(v, s.setpoint_c),
        "duty" => v == "-" || fixed(v, 3).is_some_and(|d| (0.0..=1.0).contains(&d)),
        "mode" => ["normal", "sensor_fault", "freeze_guard", "limp_home", "-"].contains(&v),
        "alarm" => ["off", "not_in_control", "out_of_range", "unacknowledged", "-"].contains(&v),
        "controller" if status => ["gpc", "igmvc", "pi", "onoff", "commission", "-"].contains(&v),
        "controller" => v == s.law.name(),
        "adaptive" => ["adaptive", "frozen", "fallback", "-"].contains(&v),
        "controllers" => v == "gpc,pi,onoff",
        "model_a" | "cabinet_a" => v == "-" || list(v, 2..=2, 6),
        "model_b" => v == "-" || list(v, 1..=4, 6),
        "cabinet_b" => v == "-" || list(v, 2..=2, 6),
        "model_k" | "cabinet_k" => v == "-" || whole(v).is_some_and(|k| (1..=MAX_K as u64).contains(&k)),
        "holdover_s" => v == "-" || whole(v).is_some_and(|h| h <= 172_800),
        "resets" => whole(v).is_some(),
        "firmware" => v == "hter fuzz",
        "commissioning" => match v.split_once(':') {
            None => ["idle", "done"].contains(&v),
            Some(("failed", why)) => !why.is_empty() && why.bytes().all(|b| b.is_ascii_lowercase() || b == b'_'),
            Some((phase, p)) => ["rest", "excite", "fit"].contains(&phase) && whole(p).is_some_and(|p| p <= 100),
        },
        "settings_version" => whole(v) == Some(u64::from(s.seq)),
        // The fuzz's board has no flash: nothing reports a failed store.
        "flash" => v == "ok",
        "cal_ice" => pair_is(v, s.cal_ice),
        "cal_warm" => pair_is(v, s.cal_warm),
        _ => false,
    }
}

/// A plain decimal as docs/interface.md defines it (`-`? digits, `.`? digits, a digit at least),
/// read without `hter::iface::num`: its f32 from the standard library's parser (the nearest), its
/// decimals up to the last non-zero one, its significant digits.
#[derive(Clone, Copy, Debug)]
struct Plain {
    value: f32,
    decimals: usize,
    digits: usize,
    zero: bool,
}

fn plain(s: &str) -> Option<Plain> {
    let (sign, body) = match s.strip_prefix('-') {
        Some(b) => ("-", b),
        None => ("", s),
    };
    let (int, frac) = body.split_once('.').unwrap_or((body, ""));
    let digits_only = |t: &str| t.bytes().all(|b| b.is_ascii_digit());
    if int.len() + frac.len() == 0 || !digits_only(int) || !digits_only(frac) {
        return None;
    }
    let frac = frac.trim_end_matches('0');
    let significant = format!("{int}{frac}");
    let significant = significant.trim_start_matches('0');
    let value = format!("{sign}0{int}.{frac}0").parse::<f32>().ok()?;
    Some(Plain { value, decimals: frac.len(), digits: significant.len(), zero: significant.is_empty() })
}

/// A value the contract takes for a setting of `decimals` decimals in `lo…hi`: a plain decimal
/// of at most 7 significant digits and that many decimals, in the range.
fn takes(s: &str, decimals: usize, lo: f32, hi: f32) -> Option<f32> {
    plain(s).filter(|p| p.decimals <= decimals && p.digits <= 7 && (lo..=hi).contains(&p.value)).map(|p| p.value)
}

/// `history`'s SINCE_S as the contract takes it: a plain decimal (`.5` and `3600.` too, not `.`
/// alone) of up to 10 whole digits and 6 decimals, below 4 000 000 000, rounded up to whole
/// seconds.
fn since(s: &str) -> Option<u32> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
    let ok = |t: &str, n: usize| t.len() <= n && t.bytes().all(|b| b.is_ascii_digit());
    if whole.len() + frac.len() == 0 || !ok(whole, 10) || !ok(frac, 6) {
        return None;
    }
    let whole: u64 = if whole.is_empty() { 0 } else { whole.parse().ok()? };
    (whole < 4_000_000_000).then(|| (whole + u64::from(frac.bytes().any(|b| b != b'0'))) as u32)
}

/// What `set KEY VALUE` with a valid value (the contract's reading, without `hter::iface`)
/// requests, if the value is valid: `None` when the line must be refused whatever the board's
/// state.
fn contract_set(key: &str, value: &str) -> Option<SetRequest> {
    let pair = |v: &str, decimals, lo, hi| -> Option<[f32; 2]> {
        let (a, b) = v.split_once(',')?;
        Some([takes(a, decimals, lo, hi)?, takes(b, decimals, lo, hi)?])
    };
    match key {
        "setpoint_c" => takes(value, 2, SETPOINT_RANGE_C.0, SETPOINT_RANGE_C.1).map(SetRequest::Setpoint),
        "controller" => Law::ALL.into_iter().find(|l| l.name() == value).map(SetRequest::Controller),
        "cal_ice" => pair(value, 2, -50.0, 100.0).map(SetRequest::CalIce),
        "cal_warm" => pair(value, 2, -50.0, 100.0).map(SetRequest::CalWarm),
        "ack" => (value == "1").then_some(SetRequest::Ack),
        "sensor_offset_c" => plain(value).filter(|p| p.zero).map(|_| SetRequest::ClearSensorOffset),
        "model" => {
            let mut parts = value.split(';');
            let (a, b, k) = (parts.next()?, parts.next()?, parts.next()?);
            if parts.next().is_some() {
                return None;
            }
            let a = pair(a, 6, f32::MIN, f32::MAX)?;
            let b = pair(b, 6, f32::MIN, f32::MAX)?;
            let k = plain(k).filter(|p| p.decimals == 0 && (1.0..=MAX_K as f32).contains(&p.value))?;
            Model::second_order(a, b, k.value as usize).ok().map(SetRequest::Model)
        }
        _ => None,
    }
}

fn same_model(m: &Model, want: &Model) -> bool {
    m.a()[..2] == want.a()[..2] && m.b()[..2] == want.b()[..2] && m.k() == want.k()
}

/// The state a host cannot see but a `set` must leave alone or change: the settings, the cabinet
/// model.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Kept {
    settings: SettingsRecord,
    cabinet: Option<Model>,
    saves_dropped: u16,
}

fn kept(app: &App) -> Kept {
    Kept { settings: *app.settings(), cabinet: app.cabinet(), saves_dropped: app.saves_dropped }
}

/// An accepted `set` (or `ack`) of `line`: it changed its own setting only, to the value typed,
/// and what it queued for flash decodes back to the state it left.
fn check_accepted_set(
    line: &str,
    data: &[String],
    before: Kept,
    after: Kept,
    new: &[Save],
) -> Result<(), TestCaseError> {
    let w = words(line);
    let (key, value) = match w.as_slice() {
        ["ack"] => ("ack", "1"),
        ["set", key, value] => (*key, *value),
        ["set", "ack"] => ("ack", "1"),
        _ => return Ok(()),
    };
    let want = contract_set(key, value);
    prop_assert!(want.is_some(), "{line:?} was accepted, the contract refuses it");
    let (b, a) = (before.settings, after.settings);
    let changed = a != b;
    // The settings record: queued exactly when the settings changed, as they now are, and back
    // from its bytes unchanged.
    let stored: Vec<&SettingsRecord> =
        new.iter().filter_map(|s| if let Save::Settings(r) = s { Some(r) } else { None }).collect();
    if changed {
        prop_assert_eq!(a.seq, b.seq.wrapping_add(1), "one accepted change counts one");
        prop_assert_eq!(stored.as_slice(), &[&a]);
        prop_assert_eq!(SettingsRecord::decode(&a.encode()), Ok(a));
    } else {
        prop_assert!(stored.is_empty(), "unchanged settings stored again: {line:?}");
    }
    // The record's event: one for a changed setting, named by its key.
    let logged: Vec<SettingKey> = new
        .iter()
        .filter_map(|s| if let Save::Log(LogEntry::Setting { key, .. }) = s { Some(*key) } else { None })
        .collect();
    let key_of = match want {
        Some(SetRequest::Setpoint(_)) => Some(SettingKey::Setpoint),
        Some(SetRequest::Controller(_)) => Some(SettingKey::Controller),
        Some(SetRequest::CalIce(_)) => Some(SettingKey::CalIce),
        Some(SetRequest::CalWarm(_)) => Some(SettingKey::CalWarm),
        _ => None,
    };
    if let Some(k) = key_of {
        prop_assert_eq!(logged.as_slice(), if changed { &[k][..] } else { &[][..] }, "{:?}", line);
    }
    let unchanged = |x: SettingsRecord| SettingsRecord { seq: b.seq, ..x };
    match want {
        Some(SetRequest::Setpoint(x)) => {
            prop_assert_eq!(a.setpoint_c.to_bits(), x.to_bits(), "{:?}", line);
            prop_assert_eq!(unchanged(SettingsRecord { setpoint_c: b.setpoint_c, ..a }), b);
        }
        Some(SetRequest::Controller(l)) => {
            prop_assert!(LAWS.contains(&l));
            prop_assert_eq!(a.law, l);
            prop_assert_eq!(unchanged(SettingsRecord { law: b.law, ..a }), b);
        }
        Some(SetRequest::CalIce(p)) => {
            prop_assert_eq!(a.cal_ice, p);
            prop_assert!(a.calibration().is_ok());
            prop_assert_eq!(unchanged(SettingsRecord { cal_ice: b.cal_ice, ..a }), b);
        }
        Some(SetRequest::CalWarm(p)) => {
            prop_assert_eq!(a.cal_warm, p);
            prop_assert!(a.calibration().is_ok());
            prop_assert_eq!(unchanged(SettingsRecord { cal_warm: b.cal_warm, ..a }), b);
        }
        Some(SetRequest::Model(m)) => {
            prop_assert_eq!(a, b, "a model is no setting of the settings record");
            prop_assert!(after.cabinet.is_some_and(|c| same_model(&c, &m)), "{line:?}: cabinet {:?}", after.cabinet);
            let adaptive = config().adaptive;
            prop_assert!(hter::ident::commission::cabinet_plausible(&adaptive, &m).is_ok());
            // The cabinet model it already has, and none for the self-tuner: nothing changed,
            // nothing to store or record (a script repeating it would push the record's oldest
            // days out).
            let control = hter::control::adaptive::plausible_model(&adaptive, &m);
            if before.cabinet == Some(m) && !control {
                prop_assert!(new.is_empty(), "{line:?}: the model it has, stored and logged again: {new:?}");
                return Ok(());
            }
            prop_assert_eq!(logged.as_slice(), &[SettingKey::Model]);
            #[cfg(feature = "holdover")]
            {
                let cab: Vec<_> =
                    new.iter().filter_map(|s| if let Save::Cabinet(r) = s { Some(r) } else { None }).collect();
                prop_assert_eq!(cab.len(), 1, "{:?}: the cabinet record once", line);
                let back = hter::persist::CabinetRecord::decode(&cab[0].encode(), &adaptive);
                prop_assert!(back.is_ok_and(|c| same_model(&c, &m)), "{line:?}: {back:?}");
            }
            // The model record: only for a model the self-tuner trusts, back as it was typed.
            let rec: Vec<_> = new.iter().filter_map(|s| if let Save::Model(r) = s { Some(r) } else { None }).collect();
            prop_assert_eq!(rec.len(), usize::from(control), "{:?}", line);
            for r in rec {
                let back = ModelRecord::decode(&r.encode()).and_then(|r| r.to_model(&adaptive));
                prop_assert!(back.is_ok_and(|c| same_model(&c, &m)), "{line:?}: {back:?}");
            }
        }
        Some(SetRequest::Ack) => {
            prop_assert_eq!(a, b);
            // Nothing to acknowledge is said in a data line, and recorded nowhere.
            let said = if data.is_empty() { &[SettingKey::Ack][..] } else { &[][..] };
            prop_assert_eq!(logged.as_slice(), said, "{:?}: {:?}", line, new);
        }
        Some(SetRequest::ClearSensorOffset) => {
            prop_assert_eq!(a, b);
            prop_assert!(new.is_empty() || logged == [SettingKey::SensorOffset], "{line:?}: {new:?}");
        }
        None => {}
    }
    if !matches!(want, Some(SetRequest::Model(_))) {
        prop_assert_eq!(after.cabinet, before.cabinet);
    }
    Ok(())
}

/// A refused line: nothing the board keeps changed and nothing was queued for flash.
fn check_refused(line: &str, before: Kept, after: Kept, new: &[Save]) -> Result<(), TestCaseError> {
    prop_assert_eq!(after, before, "{:?} was refused and changed the board", line);
    prop_assert!(new.is_empty(), "{line:?} was refused and queued {new:?}");
    Ok(())
}

/// A `set` the contract takes, on a board that has no reason to refuse it (no commissioning),
/// must not be refused; its refusal must be one the contract gives.
fn check_refusal_reason(line: &str, what: &str, why: &str, commissioning: bool) -> Result<(), TestCaseError> {
    // A line the framer would not pass is refused as a line, whatever it says.
    if line.len() > MAX_LINE || !line.bytes().all(|b| (0x20..0x7f).contains(&b) || b == b'\t') {
        prop_assert_eq!(what, "line", "{:?}", line);
        return Ok(());
    }
    let w = words(line);
    if let ["set", key, value] = w.as_slice() {
        if let Some(req) = contract_set(key, value) {
            let may = match req {
                SetRequest::Controller(l) => !LAWS.contains(&l) || commissioning,
                SetRequest::CalIce(_) | SetRequest::CalWarm(_) => {
                    commissioning || why.starts_with("the points") || why.starts_with("the two points")
                }
                SetRequest::Model(_) => true,
                SetRequest::ClearSensorOffset => commissioning,
                SetRequest::Setpoint(_) | SetRequest::Ack => false,
            };
            prop_assert!(may, "{line:?} is valid and was refused: err {what}: {why}");
        } else if !why.contains("unknown setting") && !matches!(*key, "ack" | "sensor_offset_c" | "model") {
            // A value quoted in the reason is quoted as typed.
            if why.contains(" is outside ") || why.contains(" is finer ") || why.contains(" significant digits") {
                let quoted = why.split(' ').next().unwrap_or_default();
                let pieces = value.split([',', ';']);
                prop_assert!(
                    quoted == *value || pieces.into_iter().any(|p| p == quoted),
                    "{line:?}: {why:?} does not quote {value:?}"
                );
            }
        }
    }
    if let ["history", s] = w.as_slice() {
        prop_assert!(since(s).is_none(), "{line:?} is valid and was refused: err {what}: {why}");
    }
    Ok(())
}

/// One line through one board, every check that needs no twin; how it ended.
fn one_line(b: &mut Board, line: &str) -> Result<(Ended, Vec<Save>), TestCaseError> {
    b.drain();
    let commissioning = b.observe().contains("controller=commission");
    let before = kept(&b.app);
    let (handled, reply) = b.send(line);
    let after = kept(&b.app);
    let new = b.drain();
    let ended = check_reply(line, handled, &reply)?;
    match &ended {
        Ended::Nothing => check_refused(line, before, after, &new)?,
        Ended::History(s) => {
            check_refused(line, before, after, &new)?;
            match words(line).as_slice() {
                ["history"] => prop_assert_eq!(*s, 0),
                ["history", n] => prop_assert_eq!(Some(*s), since(n), "{:?}", line),
                w => return Err(TestCaseError::fail(format!("{w:?} streamed history"))),
            }
        }
        Ended::Ok(data) => {
            check_data(line, data, &after.settings)?;
            check_accepted_set(line, data, before, after, &new)?;
        }
        Ended::Err(what, why) => {
            check_refused(line, before, after, &new)?;
            check_refusal_reason(line, what, why, commissioning)?;
        }
    }
    Ok((ended, new))
}

/// What reaches the board: lines and samples.
#[derive(Clone, Debug)]
enum Op {
    Line(String),
    /// One of the last lines sent, again (a script repeating its requests).
    Again(usize),
    Run(u8, Sample),
    /// The RTD lead's error steps to this, °C (then 10 samples: the offset watch measures it).
    Lead(f32),
}

/// Runs `ops` on a board and on its twin, which gets every op but the refused lines: the two
/// must reply, sample, store and report alike, through the ops and after them.
fn twins(start: Start, ops: &[Op]) -> Result<(), TestCaseError> {
    let (mut a, mut b) = (Board::new(start), Board::new(start));
    let mut sent: Vec<&str> = Vec::new();
    for op in ops {
        let again = match op {
            // Mostly one of the last three, as a script repeats what it just sent.
            Op::Again(i) if !sent.is_empty() => Op::Line(sent[sent.len() - 1 - i % sent.len().min(3)].to_string()),
            op => op.clone(),
        };
        if let Op::Line(line) = op {
            sent.push(line);
        }
        match &again {
            Op::Run(n, kind) => {
                let (ta, tb) = (a.run(usize::from(*n), *kind), b.run(usize::from(*n), *kind));
                prop_assert!(ta == tb, "the twins' samples differ:\n{ta}\n{tb}");
            }
            Op::Lead(c) => {
                (a.lead_c, b.lead_c) = (*c, *c);
                let (ta, tb) = (a.run(10, Sample::Plant), b.run(10, Sample::Plant));
                prop_assert!(ta == tb, "the twins' samples differ:\n{ta}\n{tb}");
            }
            Op::Again(_) => {}
            Op::Line(line) => {
                let (ended, new) = one_line(&mut a, line)?;
                if !matches!(ended, Ended::Err(..)) {
                    let (_, ra) = a.send("status");
                    let (_, reply_b) = b.send(line);
                    let new_b = b.drain();
                    let (_, rb) = b.send("status");
                    prop_assert_eq!(format!("{new:?}"), format!("{new_b:?}"), "{:?}", line);
                    if let Ended::Ok(data) = &ended {
                        let lines_b: Vec<&str> = reply_b.trim_end().split("\r\n").collect();
                        prop_assert_eq!(lines_b.len(), data.len() + 1, "{:?}", line);
                    }
                    prop_assert_eq!(ra, rb, "{:?}", line);
                }
                let (oa, ob) = (a.observe(), b.observe());
                prop_assert!(oa == ob, "after {line:?} the twins differ:\n{oa}\n{ob}");
            }
        }
    }
    // What a refusal could have changed out of sight shows in the next samples, in an `ack` or
    // in whether a commissioning may start (the settling of the duty's mean).
    for probe in ["ack", "identify"] {
        let (ta, tb) = (a.run(3, Sample::Plant), b.run(3, Sample::Plant));
        prop_assert!(ta == tb, "the twins' samples differ:\n{ta}\n{tb}");
        let (ra, rb) = (a.send(probe), b.send(probe));
        prop_assert_eq!(ra, rb, "{}", probe);
    }
    let (oa, ob) = (a.observe(), b.observe());
    prop_assert!(oa == ob, "the twins differ at the end:\n{oa}\n{ob}");
    Ok(())
}

// ---- Strategies ----

/// Spaces between words: what a person types, what a script writes, a tab the framer refuses.
fn gap() -> impl Strategy<Value = &'static str> {
    select(vec![" ", " ", " ", "  ", "   ", "\t", " \t"])
}

/// Something that looks like a number, or tries to.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        6 => "-?[0-9]{0,3}(\\.[0-9]{0,4})?",
        3 => "-?0{0,6}[0-9]{1,2}\\.?[0-9]{0,3}0{0,8}",
        2 => "-?[0-9]{8,80}(\\.[0-9]{0,12})?",
        2 => "-?0?\\.0{6,75}[0-9]?",
        2 => "[-+]?[0-9]{1,3}(\\.[0-9]{1,3})?[eE][-+]?[0-9]{1,4}",
        2 => select(vec![
            "nan", "NaN", "-nan", "inf", "-inf", "+inf", "infinity", "-Infinity", "+5", "0x1F", "1_0", "\u{663}",
            "\u{ff15}", "5\u{b0}C", "--5", "5-", "-+5", "1.2.3", "..5", ".", "-.", "-", "", "1e38", "3.4e38",
            "1e-46", "5.", ".5", "-.5", "0", "-0", "-0.00", "00", "0.", ".0",
        ])
        .prop_map(String::from),
        2 => select(vec![
            "2.5", "7.5", "2.49", "7.51", "2.4999999999", "7.5000000001", "7.50", "2.50000", "-50", "100", "-50.01",
            "100.01", "-50.00", "100.000", "1", "10", "11", "0.5", "3999999999", "3999999999.5", "3999999999.000001",
            "4000000000", "4294967295", "4294967296", "1234567", "12345678", "0.000001", "0.0000001", "9999999",
        ])
        .prop_map(String::from),
        2 => any::<f32>().prop_map(|x| x.to_string()),
        2 => (any::<f32>(), 0usize..10).prop_map(|(x, d)| format!("{x:.d$}")),
        2 => (-100.0f32..100.0, 0usize..8).prop_map(|(x, d)| format!("{x:.d$}")),
    ]
}

/// A word of the grammar, or not quite.
fn word() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => select(vec![
            "help", "status", "get", "set", "ack", "history", "identify", "abort", "setpoint_c", "controller",
            "cal_ice", "cal_warm", "model", "sensor_offset_c", "gpc", "igmvc", "pi", "onoff", "1", "0",
        ])
        .prop_map(String::from),
        1 => select(vec!["STATUS", "Set", "sta tus", "set_point", "setpoint", "GPC", "ack1", "identify-abort", "help!"])
            .prop_map(String::from),
        1 => "[!-~]{1,12}",
        1 => "\\PC{1,6}",
    ]
}

/// A token: a word, a number, or a list of numbers (a calibration point, a model).
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        3 => word(),
        4 => number(),
        2 => prop::collection::vec(number(), 1..4).prop_map(|v| v.join(",")),
        2 => prop::collection::vec(prop::collection::vec(number(), 1..3).prop_map(|v| v.join(",")), 1..4)
            .prop_map(|v| v.join(";")),
    ]
}

/// A setpoint near the range, with 0–4 decimals and zeros around.
fn setpoint() -> impl Strategy<Value = String> {
    (2.0f32..8.0, 0usize..5, "0{0,2}", any::<bool>()).prop_map(|(x, d, z, tail)| {
        let s = format!("{z}{x:.d$}");
        if tail && d > 0 {
            s + "00"
        } else {
            s
        }
    })
}

/// A calibration point near the identity's line, at reading `m` ± 2 °C, 2 decimals (3 now and
/// then).
fn cal_point(m: std::ops::Range<f32>) -> impl Strategy<Value = String> {
    (m, -1.6f32..1.6, 0.97f32..1.03, select(vec![2usize, 2, 2, 1, 3])).prop_map(|(m, off, g, d)| {
        let r = m * g + off;
        format!("{m:.d$},{r:.d$}")
    })
}

/// A model near the plausible ones: two real lags, a cooling gain, B split between two terms
/// (b1 > 0 now and then), printed with 4–7 decimals, a delay of 0–11 (or any number, or none).
fn model() -> impl Strategy<Value = String> {
    let k = prop_oneof![8 => (0u8..12).prop_map(|k| k.to_string()), 1 => number(), 1 => Just(String::new())];
    (0.5f64..0.9999, 0.0f64..1.0, -1100.0f64..0.0, -0.1f64..1.4, 4usize..8, k).prop_map(|(p1, f2, gain, w, d, k)| {
        let p2 = p1 * f2;
        let (a1, a2) = (-(p1 + p2), p1 * p2);
        let sum = gain * (1.0 - p1) * (1.0 - p2);
        let (b0, b1) = (sum * w, sum * (1.0 - w));
        format!("{a1:.d$},{a2:.d$};{b0:.d$},{b1:.d$};{k}")
    })
}

/// A line the handler is most likely to misread: a command word, then random tokens; or a
/// `set` of a real key with a value near or in its range.
fn near_valid() -> impl Strategy<Value = String> {
    let set = |key: &'static str, value: BoxedStrategy<String>| {
        (gap(), gap(), value).prop_map(move |(g1, g2, v)| format!("set{g1}{key}{g2}{v}"))
    };
    prop_oneof![
        4 => (word(), prop::collection::vec((gap(), token()), 0..4)).prop_map(|(w, rest)| {
            rest.into_iter().fold(w, |acc, (g, t)| acc + g + &t)
        }),
        2 => (select(vec!["setpoint_c", "cal_ice", "cal_warm", "model", "sensor_offset_c", "ack", "controller"]), token())
            .prop_map(|(k, v)| format!("set {k} {v}")),
        2 => number().prop_map(|n| format!("history {n}")),
        3 => set("setpoint_c", setpoint().boxed()),
        1 => set("setpoint_c", number().boxed()),
        2 => set("cal_ice", cal_point(-1.5..1.5).boxed()),
        2 => set("cal_warm", cal_point(15.0..40.0).boxed()),
        3 => set("model", model().boxed()),
        1 => set("controller", select(vec!["gpc", "igmvc", "pi", "onoff", "PI", "on-off", ""]).prop_map(String::from).boxed()),
        1 => set("sensor_offset_c", number().boxed()),
        1 => select(vec!["identify", "identify abort", "ack", "set ack 1", "set ack", "status", "get", "help"])
            .prop_map(String::from),
    ]
}

/// Any line: arbitrary text, printable ASCII, near-valid requests; with spaces around now and
/// then.
fn any_line() -> impl Strategy<Value = String> {
    prop_oneof![
        1 => "\\PC{0,100}",
        1 => ".{0,40}",
        2 => "[ -~]{0,110}",
        8 => (near_valid(), "[ ]{0,2}", "[ ]{0,2}").prop_map(|(l, a, b)| format!("{a}{l}{b}")),
    ]
}

fn sample_kind() -> impl Strategy<Value = Sample> {
    prop_oneof![
        8 => Just(Sample::Plant),
        1 => Just(Sample::ReferenceFault),
        1 => any::<u32>().prop_map(Sample::Counts),
        1 => select(vec![0u32, 1, 65_535, u32::MAX]).prop_map(Sample::Counts),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        8 => any_line().prop_map(Op::Line),
        2 => any::<usize>().prop_map(Op::Again),
        2 => (1u8..20, sample_kind()).prop_map(|(n, k)| Op::Run(n, k)),
        1 => select(vec![0.0f32, 1.0, 1.5, 2.5, -1.0]).prop_map(Op::Lead),
    ]
}

fn start() -> impl Strategy<Value = Start> {
    let mut starts = vec![
        Just(Start::New).boxed(),
        Just(Start::AfterStop).boxed(),
        select(LAWS.to_vec()).prop_map(Start::Law).boxed(),
        (0u16..40).prop_map(Start::Held).boxed(),
    ];
    #[cfg(feature = "holdover")]
    starts.push(Just(Start::Cabinet).boxed());
    // Long enough for `identify` to start a commissioning; one under way.
    starts.push((190u16..200).prop_map(Start::Held).boxed());
    starts.push((0u8..30).prop_map(Start::Commissioning).boxed());
    proptest::strategy::Union::new(starts)
}

/// Bytes off a serial line: anything, the bytes the framer acts on, long runs of one byte, valid
/// requests.
fn bytes() -> impl Strategy<Value = Vec<u8>> {
    let piece = prop_oneof![
        3 => prop::collection::vec(any::<u8>(), 0..20),
        3 => prop::collection::vec(select(vec![0u8, b'\r', b'\n', 0x08, 0x7f, LINE_KILL, 0xff, b' ', b'\t', b'a', 0x1b]), 0..10),
        1 => (any::<u8>(), 0usize..300).prop_map(|(b, n)| vec![b; n]),
        1 => (0usize..200).prop_map(|n| vec![b'x'; n]),
        3 => (any_line(), select(vec!["\n", "\r\n", "\r", ""])).prop_map(|(l, end)| (l + end).into_bytes()),
    ];
    prop::collection::vec(piece, 0..12).prop_map(|v| v.concat())
}

// ---- Framing ----

/// A frame owned, for comparing.
#[derive(Clone, Debug, PartialEq)]
enum Owned {
    Line(String),
    TooLong,
    NotPrintable,
    Lost,
}

/// The framing rules of docs/interface.md and `hter::iface::line`, written plainly: `\n`, `\r\n`
/// or `\r` end a line; backspace and DEL erase a byte; Ctrl-U drops the line so far; a line of
/// more than [`MAX_LINE`] bytes, or with another byte outside printable ASCII, is refused whole
/// (too long first); an empty or all-space line is nothing; a line is trimmed of its spaces.
fn framing_rules(bytes: &[u8]) -> Vec<Owned> {
    let (mut buf, mut long, mut bad, mut after_cr) = (Vec::new(), false, false, false);
    let mut frames = Vec::new();
    for &b in bytes {
        let cr = std::mem::replace(&mut after_cr, b == b'\r');
        match b {
            b'\n' if cr => {}
            b'\r' | b'\n' => {
                if long {
                    frames.push(Owned::TooLong);
                } else if bad {
                    frames.push(Owned::NotPrintable);
                } else {
                    let line = String::from_utf8(buf.clone()).expect("printable ASCII");
                    let line = line.trim_matches(' ');
                    if !line.is_empty() {
                        frames.push(Owned::Line(line.to_string()));
                    }
                }
                (buf, long, bad) = (Vec::new(), false, false);
            }
            0x08 | 0x7f => {
                buf.pop();
            }
            LINE_KILL => (buf, long, bad) = (Vec::new(), false, false),
            0x20..=0x7e => {
                buf.push(b);
                long |= buf.len() > MAX_LINE;
            }
            _ => bad = true,
        }
    }
    frames
}

/// The framer's frames, each checked against what a frame may be.
fn framed(bytes: &[u8]) -> Result<Vec<Owned>, TestCaseError> {
    let mut f = LineFramer::new();
    let mut frames = Vec::new();
    for &b in bytes {
        match f.push(b) {
            None => {}
            Some(Frame::Line(l)) => {
                prop_assert!(!l.is_empty() && l.len() <= MAX_LINE, "{l:?}");
                prop_assert!(l.bytes().all(|c| (0x20..0x7f).contains(&c)), "{l:?}");
                prop_assert!(!l.starts_with(' ') && !l.ends_with(' '), "{l:?}");
                prop_assert_eq!(Frame::Line(l).error(), None);
                frames.push(Owned::Line(l.to_string()));
            }
            Some(fr) => {
                let e = fr.error().unwrap_or_default();
                prop_assert!(e.starts_with("err line: ") && e.len() < REPLY_CAP, "{e:?}");
                prop_assert_ne!(fr, Frame::Lost, "no byte was lost");
                frames.push(refusal(fr));
            }
        }
    }
    Ok(frames)
}

fn framing(bytes: &[u8], request: &str) -> Result<(), TestCaseError> {
    prop_assert_eq!(framed(bytes)?, framing_rules(bytes));
    // Whatever came before, a request begun with Ctrl-U (as `hter board` sends every one) comes
    // through as typed; one after a line end as well.
    let request = request.trim_matches(' ');
    if !request.is_empty() && request.len() <= MAX_LINE && request.bytes().all(|b| (0x20..0x7f).contains(&b)) {
        for (lead, end) in [(&[LINE_KILL][..], "\n"), (&[LINE_KILL][..], "\r\n"), (&b"\n"[..], "\r")] {
            let stream = [bytes, lead, request.as_bytes(), end.as_bytes()].concat();
            let frames = framed(&stream)?;
            prop_assert_eq!(frames.last(), Some(&Owned::Line(request.to_string())), "{:?}", lead);
        }
    }
    Ok(())
}

/// Bytes through the framer into the handler, as the firmware's serial task passes them.
fn bytes_to_board(start: Start, bytes: &[u8]) -> Result<(), TestCaseError> {
    let mut b = Board::new(start);
    let mut f = LineFramer::new();
    for (i, &byte) in bytes.iter().enumerate() {
        if let Some(Frame::Line(line)) = f.push(byte) {
            let line = line.to_string();
            one_line(&mut b, &line)?;
        }
        if i % 64 == 63 {
            b.run(1, Sample::Plant);
        }
    }
    Ok(())
}

// ---- Typed ahead beyond the board's receive ring ----

/// The firmware's receive ring, bytes (`firmware/src/serial.rs`, `RX_BUF`).
const RX_BUF: usize = 128;

/// Embassy 0.6's `BufferedUart` receive side as the serial task sees it: a ring of [`RX_BUF`]
/// bytes whose interrupt handler drops, without a word, a byte that arrives while it is full.
struct RxRing {
    bytes: VecDeque<u8>,
    dropped: usize,
}

impl RxRing {
    fn arrive(&mut self, b: u8) {
        if self.bytes.len() < RX_BUF {
            self.bytes.push_back(b);
        } else {
            self.dropped += 1;
        }
    }
}

/// What came of a script pasted into the board.
struct TypedAhead {
    frames: Vec<Owned>,
    dropped: usize,
    full_reads: usize,
}

impl TypedAhead {
    /// The lines the board ran, in order.
    fn lines(&self) -> Vec<String> {
        self.frames.iter().filter_map(|f| if let Owned::Line(l) = f { Some(l.clone()) } else { None }).collect()
    }
}

/// `script` sent as one paste at the line rate (one byte a tick; `pause[i]` ticks before line
/// `i`, a person's pause), then, long after, an Enter on an empty line, through the ring into
/// the serial task's loop: a read takes all the ring holds into a buffer of [`RX_BUF`], the
/// framer takes it byte by byte, each request holds the task for `reply[i % len]` ticks (the
/// control task's answer, then the reply drained at the same line rate: `help` ≈ 1 000 byte
/// times), and a read that found the ring full ends with [`LineFramer::lost`] (`mark_lost`:
/// off, the task before the fix).
fn type_ahead(script: &[String], pause: &[u64], reply: &[u64], mark_lost: bool) -> TypedAhead {
    let mut sent: Vec<(u64, u8)> = Vec::new();
    let mut t = 0u64;
    for (i, line) in script.iter().enumerate() {
        t += pause.get(i).copied().unwrap_or(0);
        for &b in line.as_bytes().iter().chain(b"\r\n") {
            sent.push((t, b));
            t += 1;
        }
    }
    let mut ring = RxRing { bytes: VecDeque::new(), dropped: 0 };
    let mut next = 0;
    // The bytes sent up to `now` reach the ring.
    let deliver = |ring: &mut RxRing, next: &mut usize, now: u64| {
        while let Some(&(_, b)) = sent.get(*next).filter(|(at, _)| *at <= now) {
            ring.arrive(b);
            *next += 1;
        }
    };
    let mut out = TypedAhead { frames: Vec::new(), dropped: 0, full_reads: 0 };
    let mut framer = LineFramer::new();
    let mut now = 0u64;
    let mut served = 0usize;
    loop {
        deliver(&mut ring, &mut next, now);
        if ring.bytes.is_empty() {
            match sent.get(next) {
                Some(&(at, _)) => {
                    now = at;
                    continue;
                }
                None => break,
            }
        }
        let chunk: Vec<u8> = ring.bytes.drain(..).collect();
        let full = chunk.len() >= RX_BUF;
        for b in chunk {
            match framer.push(b) {
                None => {}
                Some(Frame::Line(l)) => {
                    out.frames.push(Owned::Line(l.to_string()));
                    now += reply.get(served % reply.len().max(1)).copied().unwrap_or(0);
                    served += 1;
                    deliver(&mut ring, &mut next, now);
                }
                Some(fr) => {
                    out.frames.push(refusal(fr));
                    now += 40;
                    deliver(&mut ring, &mut next, now);
                }
            }
        }
        if full {
            out.full_reads += 1;
            if mark_lost {
                framer.lost();
            }
        }
    }
    // Later, Enter on an empty line: what the paste left pending is answered.
    for &b in b"\r\n" {
        match framer.push(b) {
            None => {}
            Some(Frame::Line(l)) => {
                out.frames.push(Owned::Line(l.to_string()));
            }
            Some(fr) => out.frames.push(refusal(fr)),
        }
    }
    out.dropped = ring.dropped;
    out
}

/// A framing refusal as [`Owned`].
fn refusal(fr: Frame<'_>) -> Owned {
    match fr {
        Frame::Lost => Owned::Lost,
        Frame::TooLong => Owned::TooLong,
        _ => Owned::NotPrintable,
    }
}

/// Requests a person might paste, many of them `set`s whose values a lost stretch could turn
/// into other valid values.
fn pasted_line() -> impl Strategy<Value = String> {
    prop_oneof![
        select(&["status", "help", "get", "ack", "set controller pi", "set controller gpc", "history 86400"][..])
            .prop_map(str::to_string),
        (25u32..=75, 0u32..100).prop_map(|(a, b)| format!("set setpoint_c {}.{b:02}", a / 10)),
        (-5i32..=5, 0u32..100).prop_map(|(a, b)| format!("set cal_ice {a}.{b:02},0.00")),
    ]
}

/// Every line the board ran is one that was sent, whole, in order; if any byte was lost, the
/// board said so; if no read found the ring full, every line ran.
fn typed_ahead(script: &[String], pause: &[u64], reply: &[u64]) -> Result<(), TestCaseError> {
    let r = type_ahead(script, pause, reply, true);
    let mut rest = script.iter();
    for line in &r.lines() {
        prop_assert!(rest.any(|s| s == line), "ran {line:?}, which was not sent as such (or out of order)");
    }
    if r.dropped > 0 {
        prop_assert!(r.frames.contains(&Owned::Lost), "{} bytes lost without a word", r.dropped);
    }
    if r.full_reads == 0 {
        prop_assert_eq!(r.dropped, 0);
        prop_assert_eq!(&r.lines(), &script.to_vec());
    }
    Ok(())
}

/// The case that made the fix: a paste behind `help`'s reply whose third line loses its
/// middle. Before it, the board ran `set setpoint_c 5`, a line nobody typed.
#[test]
fn a_paste_beyond_the_receive_ring_never_runs_a_line_glued_from_two() {
    // `help`'s reply holds the task while the next 128 bytes fill the ring, up to the `2` of
    // `set setpoint_c 2.5`, and the `2.` arrives while it is full.
    let script: Vec<String> = [
        "help",
        "set controller pi",
        "set cal_ice 0.00,0.00",
        "set cal_warm 25.0,25.00",
        "get",
        "set controller gpc",
        "set setpoint_c 4.0",
        "set setpoint_c 2.5",
        "status",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let (pause, reply) = ([0; 9], [130, 4, 4, 4, 400, 4, 4, 4, 600]);
    let before = type_ahead(&script, &pause, &reply, false);
    assert_eq!(before.dropped, 2, "the paste must overrun the ring");
    assert!(before.lines().iter().any(|l| l == "set setpoint_c 5"), "without the fix: {:?}", before.lines());
    let after = type_ahead(&script, &pause, &reply, true);
    assert_eq!(after.dropped, before.dropped);
    assert!(after.lines().iter().all(|l| script.contains(l)), "{:?}", after.lines());
    assert!(after.frames.contains(&Owned::Lost));
    assert_eq!(after.lines().first().map(String::as_str), Some("help"));
    // Typed at a person's pace, all of it runs.
    let slow = type_ahead(&script, &[2_000; 9], &reply, true);
    assert_eq!((slow.dropped, slow.full_reads), (0, 0));
    assert_eq!(slow.lines(), script);
}

/// `cases` cases; a failure's seed is kept beside this file (`iface_fuzz.proptest-regressions`)
/// and run first from then on.
fn cases(cases: u32) -> ProptestConfig {
    let keep = proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions");
    ProptestConfig { cases, failure_persistence: Some(Box::new(keep)), ..ProptestConfig::default() }
}

// ---- The quick tests, on every `cargo test` ----

proptest! {
    #![proptest_config(cases(512))]

    #[test]
    fn any_byte_stream_frames_by_the_rules(bytes in bytes(), request in any_line()) {
        framing(&bytes, &request)?;
    }

    #[test]
    fn any_line_gets_one_final_line_and_a_refusal_changes_nothing(line in any_line()) {
        one_line(&mut Board::new(Start::New), &line)?;
    }

    #[test]
    fn a_paste_typed_ahead_runs_whole_lines_only_and_says_when_it_lost_some(
        script in prop::collection::vec(pasted_line(), 1..16),
        pause in prop::collection::vec(prop_oneof![3 => Just(0u64), 1 => 0u64..3_000], 16),
        reply in prop::collection::vec(prop_oneof![0u64..50, 300u64..1_100, 2_000u64..20_000], 1..6),
    ) {
        typed_ahead(&script, &pause, &reply)?;
    }
}

proptest! {
    #![proptest_config(cases(64))]

    #[test]
    fn any_byte_stream_through_the_framer_into_the_board(start in start(), bytes in bytes()) {
        bytes_to_board(start, &bytes)?;
    }

    #[test]
    fn lines_between_samples_a_refused_one_changes_nothing_now_or_later(
        start in start(),
        ops in prop::collection::vec(op(), 1..30),
    ) {
        twins(start, &ops)?;
    }
}

// ---- The long variants, in CI: `cargo test --release --test iface_fuzz -- --ignored` ----

proptest! {
    #![proptest_config(cases(200_000))]

    #[test]
    #[ignore = "long: run in release, `cargo test --release --test iface_fuzz -- --ignored`"]
    fn long_any_byte_stream_frames_by_the_rules(bytes in bytes(), request in any_line()) {
        framing(&bytes, &request)?;
    }

    #[test]
    #[ignore = "long: run in release, `cargo test --release --test iface_fuzz -- --ignored`"]
    fn long_any_line_gets_one_final_line_and_a_refusal_changes_nothing(line in any_line()) {
        one_line(&mut Board::new(Start::New), &line)?;
    }

    #[test]
    #[ignore = "long: run in release, `cargo test --release --test iface_fuzz -- --ignored`"]
    fn long_a_paste_typed_ahead_runs_whole_lines_only_and_says_when_it_lost_some(
        script in prop::collection::vec(pasted_line(), 1..40),
        pause in prop::collection::vec(prop_oneof![3 => Just(0u64), 1 => 0u64..3_000], 40),
        reply in prop::collection::vec(prop_oneof![0u64..50, 300u64..1_100, 2_000u64..20_000], 1..10),
    ) {
        typed_ahead(&script, &pause, &reply)?;
    }
}

proptest! {
    #![proptest_config(cases(5_000))]

    #[test]
    #[ignore = "long: run in release, `cargo test --release --test iface_fuzz -- --ignored`"]
    fn long_any_byte_stream_through_the_framer_into_the_board(start in start(), bytes in bytes()) {
        bytes_to_board(start, &bytes)?;
    }

    #[test]
    #[ignore = "long: run in release, `cargo test --release --test iface_fuzz -- --ignored`"]
    fn long_lines_between_samples_a_refused_one_changes_nothing_now_or_later(
        start in start(),
        ops in prop::collection::vec(op(), 1..60),
    ) {
        twins(start, &ops)?;
    }
}
