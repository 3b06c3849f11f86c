//! The settings and data interface: one line in, a reply out (docs/interface.md is the wire
//! contract). Transport-agnostic: the firmware feeds it lines from USART2, `hter virtual-board`
//! from a pseudo-terminal, a future USB CDC port from its endpoint; [`crate::app::App::handle`]
//! runs the command against the board's state.
//!
//! Why a text protocol and not postcard/COBS frames or miniconf's settings tree: a person at a
//! plain serial terminal must be able to use it (`help`, `status`, `set setpoint_c 5`, readable
//! refusals), and the host tool reads the same lines, because every reply ends with one final
//! line, `ok` or `err <key>: <why>`. A settings tree library would bring serde and a JSON or
//! postcard codec (several KiB) for five keys; the grammar below is a few hundred bytes.

pub mod line;
pub mod num;
pub mod sink;

use crate::model::{Model, MAX_K};
use num::{parse_decimal, parse_list, parse_whole, Decimal, Fixed, MAX_DIGITS};
use sink::{put, Sink, Text, Written};

/// Longest request line, bytes (docs/interface.md).
pub const MAX_LINE: usize = 96;

/// The laws a board can run, by their wire names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Law {
    /// Self-tuning GPC.
    Gpc,
    /// Self-tuning IGMVC.
    Igmvc,
    /// PI.
    Pi,
    /// On-Off.
    OnOff,
}

impl Law {
    /// Every law, in the order of their codes.
    pub const ALL: [Law; 4] = [Law::Gpc, Law::Igmvc, Law::Pi, Law::OnOff];

    /// Wire name.
    pub fn name(self) -> &'static str {
        match self {
            Law::Gpc => "gpc",
            Law::Igmvc => "igmvc",
            Law::Pi => "pi",
            Law::OnOff => "onoff",
        }
    }

    /// The law of a wire name.
    pub fn from_name(s: &str) -> Option<Law> {
        Law::ALL.into_iter().find(|l| l.name() == s)
    }
}

/// A setting as requested, parsed but not yet checked against the board (range checks that
/// need no state are done here).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SetRequest {
    /// `setpoint_c`, °C.
    Setpoint(f32),
    /// `controller`.
    Controller(Law),
    /// `cal_ice`: (channel reading, reference), °C.
    CalIce([f32; 2]),
    /// `cal_warm`: (channel reading, reference), °C.
    CalWarm([f32; 2]),
    /// `model`: a second-order model to start the self-tuner from.
    Model(Model),
    /// `ack`.
    Ack,
    /// `sensor_offset_c 0`: the sensor offset the board subtracts is cleared (after the lead
    /// fault it compensated was repaired).
    ClearSensorOffset,
}

/// One request line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `help`.
    Help,
    /// `status`.
    Status,
    /// `get`.
    Get,
    /// `set KEY VALUE` (or `ack`).
    Set(SetRequest),
    /// `history [SINCE_S]`.
    History {
        /// Only rows at or after this record time, s.
        since_s: u32,
    },
    /// `identify`.
    Identify,
    /// `identify abort`.
    IdentifyAbort,
}

/// Why a request was refused: the key (or `line`, or the command) and the reason, printed as
/// the final line `err <what>: <why>`. A value it quotes is the request's own text (`'a`), as
/// the user typed it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refusal<'a> {
    /// What was refused.
    pub what: &'static str,
    /// Why.
    pub why: Why<'a>,
}

/// The reasons a request is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Why<'a> {
    /// Not a command this board knows.
    UnknownCommand,
    /// `set` of a key this board does not have.
    UnknownKey,
    /// Arguments missing or extra.
    Usage(&'static str),
    /// The value is not a plain decimal number (or list of them).
    NotDecimal,
    /// A number outside its range: the value as typed and the bounds.
    OutOfRange(&'a str, f32, f32),
    /// A number with more decimals than its setting keeps: the value as typed, the step (with
    /// its unit) and the decimals kept. Rounded, it would be used as typed but shown, recorded
    /// and stored as another value.
    Finer(&'a str, &'static str, u8),
    /// A number with more than [`MAX_DIGITS`] significant digits (an f32 holds no more): the
    /// value as typed.
    Digits(&'a str),
    /// A model's delay that is not a whole number of samples in 1…[`MAX_K`]: as typed.
    Delay(&'a str),
    /// A law this build does not link.
    NotInBuild,
    /// The calibration points fail [`crate::calib::TwoPoint::from_points`].
    Calibration(crate::calib::CalError),
    /// The model is refused: why.
    Model(&'static str),
    /// The request is not possible now: why.
    NotNow(&'static str),
    /// The line itself: too long, or not printable ASCII.
    Line(&'static str),
}

impl Refusal<'_> {
    /// Writes the refusal's line, without its line end.
    pub fn write<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
        put!(out, "err ", self.what, ": ")?;
        match self.why {
            Why::UnknownCommand => out.str("unknown command (try help)"),
            Why::UnknownKey => {
                out.str("unknown setting (setpoint_c, controller, cal_ice, cal_warm, model, sensor_offset_c, ack)")
            }
            Why::Usage(u) => put!(out, "usage: ", u),
            Why::NotDecimal => out.str("not a decimal number"),
            Why::OutOfRange(x, lo, hi) => put!(out, x, " is outside ", Fixed(lo, 1), "…", Fixed(hi, 1)),
            Why::Finer(x, step, n) => put!(out, x, " is finer than the ", step, " step (at most ", n, " decimals)"),
            Why::Digits(x) => put!(out, x, " has more than ", MAX_DIGITS, " significant digits"),
            Why::Delay(k) => put!(out, "K must be a whole number of samples in 1…", MAX_K, ", not ", k),
            Why::NotInBuild => out.str("not a law this build links (see status: controllers)"),
            Why::Calibration(e) => out.str(match e {
                crate::calib::CalError::NonFinite => "a point is not finite",
                crate::calib::CalError::PointsTooClose => "the two points are less than 1 °C apart",
                crate::calib::CalError::ImplausibleGain => "the points give a gain outside 0.9…1.1",
                crate::calib::CalError::ImplausibleCorrection => {
                    "the points move a reading between 0 and 10 °C by more than 1.5 °C"
                }
            }),
            Why::Model(w) | Why::NotNow(w) | Why::Line(w) => out.str(w),
        }
    }
}

impl Text for Refusal<'_> {
    fn put<S: Sink + ?Sized>(&self, out: &mut S) -> Written {
        self.write(out)
    }
}

/// For the host and the tests (`to_string()`): the line [`Refusal::write`] writes.
impl core::fmt::Display for Refusal<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        self.write(f).map_err(|_| core::fmt::Error)
    }
}

/// The accepted setpoint range of the interface, °C (SPEC §8): inside the vaccine band with
/// 0.5 °C to either limit.
pub const SETPOINT_RANGE_C: (f32, f32) = (2.5, 7.5);

fn refuse<'a, T>(what: &'static str, why: Why<'a>) -> Result<T, Refusal<'a>> {
    Err(Refusal { what, why })
}

impl Command {
    /// Parses one line (without its line end). `Ok(None)` for an empty line, which gets no
    /// reply.
    // Out of line: inlined, it was copied into the board's control task (with the step and digit
    // checks the interface build was 1.2 KB larger).
    #[inline(never)]
    pub fn parse(line: &str) -> Result<Option<Command>, Refusal<'_>> {
        if line.len() > MAX_LINE {
            return refuse("line", Why::Line("longer than 96 bytes"));
        }
        if !line.bytes().all(|b| (0x20..0x7f).contains(&b) || b == b'\t') {
            return refuse("line", Why::Line("not printable ASCII"));
        }
        let mut words = line.split_ascii_whitespace();
        let Some(cmd) = words.next() else { return Ok(None) };
        let (a, b, extra) = (words.next(), words.next(), words.next().is_some());
        let cmd = match (cmd, a, b) {
            _ if extra => return refuse("line", Why::Usage("too many words")),
            ("help", None, None) => Command::Help,
            ("status", None, None) => Command::Status,
            ("get", None, None) => Command::Get,
            ("ack", None, None) => Command::Set(SetRequest::Ack),
            ("identify", None, None) => Command::Identify,
            ("identify", Some("abort"), None) => Command::IdentifyAbort,
            ("history", since, None) => Command::History {
                since_s: match since {
                    None => 0,
                    // The limit is on the value typed, the rounding up after it: `3999999999.5`.
                    Some(s) => match since_seconds(s) {
                        Some((whole, part)) if whole < HISTORY_SINCE_LIMIT_S => whole + u32::from(part),
                        Some(_) => {
                            return refuse(
                                "history",
                                Why::Usage("history [SINCE_S], SINCE_S below 4000000000, at most 6 decimals"),
                            )
                        }
                        None => return refuse("history", Why::NotDecimal),
                    },
                },
            },
            ("set", Some(key), Some(value)) => Command::Set(parse_set(key, value)?),
            ("set", Some("ack"), None) => Command::Set(SetRequest::Ack),
            ("set", _, _) => return refuse("set", Why::Usage("set KEY VALUE")),
            ("help" | "status" | "get" | "ack" | "identify" | "history", _, _) => {
                return refuse("line", Why::Usage("too many words"))
            }
            _ => return refuse("line", Why::UnknownCommand),
        };
        Ok(Some(cmd))
    }
}

/// `history`'s SINCE_S must be below this, record s.
pub const HISTORY_SINCE_LIMIT_S: u32 = 4_000_000_000;

/// `history`'s SINCE_S: a plain decimal ≥ 0 as every number is (`3600`, `3600.5`, `.5`,
/// `3600.`), as its whole seconds and whether a fraction is left (the caller rounds up to the
/// record's whole seconds, which rows are stamped in, once it has checked the value: rounded
/// first, `3999999999.5`, below the limit, was refused). One beyond 10 whole digits or 6 decimals
/// is `u32::MAX`, which the caller refuses with the limits; `None`: not a decimal. Not
/// [`parse_decimal`]: the record's time passes its 7 digits after 116 days of service, and
/// `history 10000000` was "not a decimal number".
fn since_seconds(s: &str) -> Option<(u32, bool)> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
    if whole.len() + frac.len() == 0 || !whole.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) {
        return None;
    }
    if frac.len() > 6 {
        return Some((u32::MAX, false));
    }
    let whole = if whole.is_empty() { 0 } else { parse_whole(whole).unwrap_or(u32::MAX) };
    Some((whole, frac.bytes().any(|b| b != b'0')))
}

/// How a numeric setting is kept: the range it takes and its step, the decimals it is stored,
/// shown (`status`, `get`) and recorded (`history`) with. A value finer than the step is
/// refused rather than rounded: rounded, the board would show and record one value and run
/// another (`5.001` ran as 5.001 °C and read 5.00 everywhere).
#[derive(Clone, Copy)]
struct Kept {
    /// Lowest and highest value taken, if the key has a range of its own.
    range: Option<(f32, f32)>,
    /// Decimals kept.
    decimals: u8,
    /// The step, as the refusal names it.
    step: &'static str,
}

/// `setpoint_c`: SPEC §8's range; `status`, `get` and the record show 2 decimals.
const SETPOINT: Kept = Kept { range: Some(SETPOINT_RANGE_C), decimals: 2, step: "0.01 °C" };
/// Either value of a calibration point: `get` and the record show 2 decimals.
const CAL_POINT: Kept = Kept { range: Some((-50.0, 100.0)), decimals: 2, step: "0.01 °C" };
/// A model coefficient: `status` shows 6 decimals; its range is the model's plausibility,
/// checked by the board.
const COEFFICIENT: Kept = Kept { range: None, decimals: 6, step: "0.000001" };

/// A value of a setting kept as `kept` says: in its range, no finer than its step, of at most
/// [`MAX_DIGITS`] significant digits; otherwise refused quoting `text`.
fn number<'a>(what: &'static str, text: &'a str, d: Decimal, kept: &Kept) -> Result<f32, Refusal<'a>> {
    let why = match kept.range {
        Some((lo, hi)) if !(lo..=hi).contains(&d.value) => Why::OutOfRange(text, lo, hi),
        _ if d.decimals > kept.decimals => Why::Finer(text, kept.step, kept.decimals),
        _ if d.digits > MAX_DIGITS => Why::Digits(text),
        _ => return Ok(d.value),
    };
    refuse(what, why)
}

/// Two comma-separated values of a setting kept as `kept` says ([`number`]): both plain decimals,
/// then each checked in turn.
fn pair<'a>(what: &'static str, text: &'a str, kept: &Kept) -> Result<[f32; 2], Refusal<'a>> {
    let [(t0, d0), (t1, d1)] = parse_list::<2>(text).ok_or(Refusal { what, why: Why::NotDecimal })?;
    Ok([number(what, t0, d0, kept)?, number(what, t1, d1, kept)?])
}

fn parse_set<'a>(key: &str, value: &'a str) -> Result<SetRequest, Refusal<'a>> {
    match key {
        "setpoint_c" => {
            let d = parse_decimal(value).ok_or(Refusal { what: "setpoint_c", why: Why::NotDecimal })?;
            number("setpoint_c", value, d, &SETPOINT).map(SetRequest::Setpoint)
        }
        "controller" => match Law::from_name(value) {
            Some(l) => Ok(SetRequest::Controller(l)),
            None => refuse("controller", Why::NotInBuild),
        },
        "cal_ice" => pair("cal_ice", value, &CAL_POINT).map(SetRequest::CalIce),
        "cal_warm" => pair("cal_warm", value, &CAL_POINT).map(SetRequest::CalWarm),
        "model" => parse_model(value).map(SetRequest::Model),
        // `set ack 0` must not read as "do not acknowledge" and acknowledge.
        "ack" if value == "1" => Ok(SetRequest::Ack),
        "ack" => refuse("ack", Why::Usage("set ack 1, or ack")),
        // The board measures the offset; a person can only clear it (`0`, `0.00`, …): zero by its
        // digits, not its f32, which a tiny value underflows to (`0.` and 45 zeros and a 1).
        "sensor_offset_c" => match parse_decimal(value) {
            Some(d) if d.digits == 0 => Ok(SetRequest::ClearSensorOffset),
            Some(_) => refuse(
                "sensor_offset_c",
                Why::Usage("set sensor_offset_c 0 (only 0: it clears the offset the board measured)"),
            ),
            None => refuse("sensor_offset_c", Why::NotDecimal),
        },
        _ => refuse("set", Why::UnknownKey),
    }
}

/// `A1,A2;B0,B1;K`: the structure of a model; its plausibility is the board's to check.
fn parse_model(value: &str) -> Result<Model, Refusal<'_>> {
    let bad = Refusal { what: "model", why: Why::Usage("model A1,A2;B0,B1;K") };
    let mut parts = value.split(';');
    let (Some(a), Some(b), Some(k), None) = (parts.next(), parts.next(), parts.next(), parts.next()) else {
        return Err(bad);
    };
    let a = pair("model", a, &COEFFICIENT)?;
    let b = pair("model", b, &COEFFICIENT)?;
    let k = match parse_decimal(k) {
        Some(d) if d.decimals == 0 && d.value >= 1.0 && d.value <= MAX_K as f32 => d.value as usize,
        // No K to quote (`A1,A2;B0,B1;`): "…, not " and nothing.
        None if k.is_empty() => return Err(bad),
        _ => return refuse("model", Why::Delay(k)),
    };
    Model::second_order(a, b, k).map_err(|_| Refusal { what: "model", why: Why::Model("not a second-order model") })
}

/// The `help` text, one line per command.
pub const HELP: &[&str] = &[
    "status                   what the carrier is doing now",
    "get                      every setting",
    "set setpoint_c V         setpoint, 2.5...7.5 C, step 0.01",
    "set controller NAME      a law of this build (status: controllers)",
    "set cal_ice M,R          ice-bath point: channel reading, reference (C)",
    "set cal_warm M,R         second point: channel reading, reference (C)",
    "set model A1,A2;B0,B1;K  start model of the self-tuner (checked)",
    "set sensor_offset_c 0    clear the sensor offset, after the RTD lead's repair",
    "ack                      acknowledge the alarm",
    "history [SINCE_S]        the cold-chain record as CSV",
    "identify [abort]         commission the cabinet (rest, PRBS, fit, store)",
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::ToString;

    fn refusal(line: &str) -> std::string::String {
        Command::parse(line).unwrap_err().to_string()
    }

    #[test]
    fn a_person_can_type_every_command() {
        assert_eq!(Command::parse("status"), Ok(Some(Command::Status)));
        assert_eq!(Command::parse("  status  "), Ok(Some(Command::Status)));
        assert_eq!(Command::parse(""), Ok(None));
        assert_eq!(Command::parse("set setpoint_c 5"), Ok(Some(Command::Set(SetRequest::Setpoint(5.0)))));
        assert_eq!(Command::parse("set controller pi"), Ok(Some(Command::Set(SetRequest::Controller(Law::Pi)))));
        assert_eq!(Command::parse("set cal_ice 0.12,0.00"), Ok(Some(Command::Set(SetRequest::CalIce([0.12, 0.0])))));
        assert_eq!(Command::parse("ack"), Ok(Some(Command::Set(SetRequest::Ack))));
        assert_eq!(Command::parse("set ack 1"), Ok(Some(Command::Set(SetRequest::Ack))));
        assert_eq!(Command::parse("history"), Ok(Some(Command::History { since_s: 0 })));
        assert_eq!(Command::parse("history 3600"), Ok(Some(Command::History { since_s: 3600 })));
        // The record's time after 116 days and more, and a fraction rounded up to the next row.
        assert_eq!(Command::parse("history 10000000"), Ok(Some(Command::History { since_s: 10_000_000 })));
        assert_eq!(Command::parse("history 3999999999"), Ok(Some(Command::History { since_s: 3_999_999_999 })));
        assert_eq!(Command::parse("history 3600.5"), Ok(Some(Command::History { since_s: 3601 })));
        assert_eq!(Command::parse("history 3600.00"), Ok(Some(Command::History { since_s: 3600 })));
        // Plain decimals as every number is (docs/interface.md, "Numbers").
        assert_eq!(Command::parse("history .5"), Ok(Some(Command::History { since_s: 1 })));
        assert_eq!(Command::parse("history 3600."), Ok(Some(Command::History { since_s: 3600 })));
        for bad in ["history -1", "history 1e9", "history .", "history 1.2.3", "history 99999999999", "history x"] {
            assert!(Command::parse(bad).is_err(), "{bad}");
        }
        // Beyond its limits a number is refused with them, not as "not a decimal number".
        for beyond in ["99999999999", "0.0000001", "4294967296"] {
            let usage = "err history: usage: history [SINCE_S], SINCE_S below 4000000000, at most 6 decimals";
            assert_eq!(refusal(&format!("history {beyond}")), usage, "{beyond}");
        }
        assert_eq!(
            refusal("history 4000000000"),
            "err history: usage: history [SINCE_S], SINCE_S below 4000000000, at most 6 decimals"
        );
        assert_eq!(Command::parse("identify abort"), Ok(Some(Command::IdentifyAbort)));
        let Ok(Some(Command::Set(SetRequest::Model(m)))) = Command::parse("set model -1.8,0.81;-0.02,-0.01;9") else {
            panic!()
        };
        assert_eq!((&m.a()[..2], &m.b()[..2], m.k()), (&[-1.8f32, 0.81][..], &[-0.02f32, -0.01][..], 9));
    }

    #[test]
    fn a_bad_value_is_refused_in_one_line_that_names_the_key() {
        assert_eq!(refusal("set setpoint_c 12"), "err setpoint_c: 12 is outside 2.5…7.5");
        assert_eq!(refusal("set setpoint_c nan"), "err setpoint_c: not a decimal number");
        assert_eq!(refusal("set setpoint_c 1e1"), "err setpoint_c: not a decimal number");
        assert_eq!(refusal("set setpoint_c 2.4"), "err setpoint_c: 2.4 is outside 2.5…7.5");
        assert_eq!(
            refusal("set controller fuzzy"),
            "err controller: not a law this build links (see status: controllers)"
        );
        assert_eq!(
            refusal("set colour blue"),
            "err set: unknown setting (setpoint_c, controller, cal_ice, cal_warm, model, sensor_offset_c, ack)"
        );
        assert_eq!(refusal("set setpoint_c"), "err set: usage: set KEY VALUE");
        assert_eq!(refusal("frobnicate"), "err line: unknown command (try help)");
        assert_eq!(refusal("status now please"), "err line: usage: too many words");
        assert_eq!(refusal("set model -1.8,0.81;-0.02;9"), "err model: not a decimal number");
        assert_eq!(
            refusal("set model -1.8,0.81;-0.02,-0.01;0"),
            "err model: K must be a whole number of samples in 1…16, not 0".replace("16", &MAX_K.to_string())
        );
        assert_eq!(refusal("set cal_ice 0.1"), "err cal_ice: not a decimal number");
        assert_eq!(refusal("stat\u{7}us"), "err line: not printable ASCII");
        assert!(refusal(&"x".repeat(97)).starts_with("err line: longer than 96"));
        for line in ["set setpoint_c 12", "set setpoint_c nan", "frobnicate", "set model 1"] {
            assert!(!refusal(line).contains('\n'), "{line}");
        }
    }

    /// Found by `tests/iface_fuzz.rs`: `0.` and 45 zeros and a 1 is no 0, but its f32 underflows
    /// to 0.0, and it cleared the sensor offset.
    #[test]
    fn only_a_zero_clears_the_sensor_offset_however_small_the_value() {
        let usage =
            "err sensor_offset_c: usage: set sensor_offset_c 0 (only 0: it clears the offset the board measured)";
        for tiny in [format!("0.{}1", "0".repeat(45)), format!("-.{}7", "0".repeat(60)), "0.01".into()] {
            assert_eq!(refusal(&format!("set sensor_offset_c {tiny}")), usage, "{tiny}");
        }
        for zero in ["0", "-0", "0.00", ".0", "000", &format!("0.{}", "0".repeat(70))] {
            let line = format!("set sensor_offset_c {zero}");
            assert_eq!(Command::parse(&line), Ok(Some(Command::Set(SetRequest::ClearSensorOffset))), "{zero}");
        }
    }

    /// Found by `tests/iface_fuzz.rs`: SINCE_S below the limit with a fraction, rounded up to it
    /// first, was refused as not below it (`hter board history --since 3999999999.5` passes the
    /// host's check, which is on the value).
    #[test]
    fn history_since_is_checked_before_it_is_rounded_up() {
        for (s, since_s) in
            [("3999999999.5", 4_000_000_000), ("3999999999.000001", 4_000_000_000), ("3999999999.0", 3_999_999_999)]
        {
            assert_eq!(Command::parse(&format!("history {s}")), Ok(Some(Command::History { since_s })), "{s}");
        }
        for s in ["4000000000", "4000000000.5", "4294967295.5"] {
            assert_eq!(
                refusal(&format!("history {s}")),
                "err history: usage: history [SINCE_S], SINCE_S below 4000000000, at most 6 decimals",
                "{s}"
            );
        }
    }

    /// Found by `tests/iface_fuzz.rs`: a model without its K was refused quoting the K it lacks:
    /// `err model: K must be a whole number of samples in 1…10, not ` and nothing.
    #[test]
    fn a_model_without_its_delay_is_refused_with_the_usage() {
        for line in ["set model -1.8,0.81;-0.02,-0.01;", "set model -1.8,0.81;-0.02,-0.01; "] {
            assert_eq!(refusal(line), "err model: usage: model A1,A2;B0,B1;K", "{line:?}");
        }
    }
}
