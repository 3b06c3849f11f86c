//! Request framing: bytes from a serial port into request lines (docs/interface.md), the same
//! for the board's USART2, the virtual board's pty and a future USB CDC port. No heap.
//!
//! `\n`, `\r\n` or a bare `\r` end a line (a terminal's Enter sends `\r`); backspace (0x08) and
//! DEL (0x7f, what most terminals send for Backspace) erase the last byte, so a person can
//! correct a typo; Ctrl-U (0x15, a terminal's line kill) drops the whole line so far, which is
//! how `hter board` begins every request: a client that went away in the middle of a line (the
//! board's UART sees no hang-up) leaves its bytes behind, and the next request was read glued to
//! them (`set setpoint_c 6` + `status` came to `set setpoint_c 6status`, refused; a glued
//! remainder could as well have made a valid, unintended request). An empty or all-space line
//! is nothing. A line longer than [`MAX_LINE`] or with another byte outside printable ASCII is
//! answered by its [`Frame`] error and dropped whole.
//!
//! A transport that can lose bytes says so with [`LineFramer::lost`]: the board's receive ring
//! (embassy's `BufferedUart`) drops, without a word, every byte that arrives while it is full,
//! and a person who pastes a script faster than the replies go out fills it. Whatever was lost,
//! the line the gap falls in is refused ([`Frame::Lost`]): it is the front of one line glued to
//! the back of another, and `set setpoint_c 2.5` that lost `2.` is `set setpoint_c 5`, a valid
//! request nobody typed.

use super::MAX_LINE;

/// What one line of input came to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame<'a> {
    /// A request, without its line end and surrounding spaces; never empty.
    Line(&'a str),
    /// Longer than [`MAX_LINE`] bytes (the rest was dropped).
    TooLong,
    /// A byte outside printable ASCII (other than the line ends and the erase keys).
    NotPrintable,
    /// Input may have been lost inside this line ([`LineFramer::lost`]); whole lines before it
    /// may have gone too.
    Lost,
}

impl Frame<'_> {
    /// The reply to a framing error (`None` for a line, which the handler answers).
    pub fn error(&self) -> Option<&'static str> {
        match self {
            Frame::Line(_) => None,
            Frame::TooLong => Some("err line: too long (at most 96 bytes)"),
            Frame::NotPrintable => Some("err line: a byte outside printable ASCII"),
            Frame::Lost => {
                Some("err line: input lost (typed ahead of the replies); this line and any before it may not have run")
            }
        }
    }
}

/// Ctrl-U: drops the line so far ([`LineFramer::push`]).
pub const LINE_KILL: u8 = 0x15;

/// Splits a byte stream into [`Frame`]s.
#[derive(Clone, Debug, Default)]
pub struct LineFramer {
    buf: heapless::Vec<u8, MAX_LINE>,
    too_long: bool,
    not_printable: bool,
    after_cr: bool,
    /// `buf` holds the line last returned: cleared by the next byte.
    returned: bool,
    /// Bytes may be missing after those pushed so far ([`Self::lost`]).
    lost: bool,
}

impl LineFramer {
    /// A framer at the start of a line.
    pub const fn new() -> Self {
        LineFramer {
            buf: heapless::Vec::new(),
            too_long: false,
            not_printable: false,
            after_cr: false,
            returned: false,
            lost: false,
        }
    }

    /// Forgets a partial line (a client went away in the middle of one).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Bytes may be missing after those pushed so far (the transport dropped some): the line
    /// they fall in, which ends at the next line end, is refused as [`Frame::Lost`], even when
    /// nothing of it has arrived yet (the gap may end at a line end). Ctrl-U clears it: what
    /// follows a line kill is a new line whatever was lost before it.
    pub fn lost(&mut self) {
        self.lost = true;
    }

    /// Takes one byte; gives a frame when it ends a non-empty line.
    pub fn push(&mut self, b: u8) -> Option<Frame<'_>> {
        if core::mem::take(&mut self.returned) {
            self.buf.clear();
        }
        let after_cr = core::mem::replace(&mut self.after_cr, b == b'\r');
        match b {
            // The `\n` of a `\r\n`.
            b'\n' if after_cr => None,
            b'\r' | b'\n' => self.end_line(),
            0x08 | 0x7f => {
                self.buf.pop();
                None
            }
            LINE_KILL => {
                self.reset();
                None
            }
            0x20..=0x7e => {
                if self.buf.push(b).is_err() {
                    self.too_long = true;
                }
                None
            }
            _ => {
                self.not_printable = true;
                None
            }
        }
    }

    fn end_line(&mut self) -> Option<Frame<'_>> {
        let (too_long, not_printable) = (self.too_long, self.not_printable);
        (self.too_long, self.not_printable) = (false, false);
        self.returned = true;
        if core::mem::take(&mut self.lost) {
            return Some(Frame::Lost);
        }
        if too_long {
            return Some(Frame::TooLong);
        }
        if not_printable {
            return Some(Frame::NotPrintable);
        }
        // Printable ASCII is UTF-8.
        let line = core::str::from_utf8(&self.buf).unwrap_or("").trim_matches(' ');
        (!line.is_empty()).then_some(Frame::Line(line))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::{String, ToString};
    use std::vec::Vec;

    #[derive(Debug, PartialEq)]
    enum Owned {
        Line(String),
        TooLong,
        NotPrintable,
        Lost,
    }

    fn owned(fr: Frame<'_>) -> Owned {
        match fr {
            Frame::Line(l) => Owned::Line(l.to_string()),
            Frame::TooLong => Owned::TooLong,
            Frame::NotPrintable => Owned::NotPrintable,
            Frame::Lost => Owned::Lost,
        }
    }

    fn frames(bytes: &[u8]) -> Vec<Owned> {
        let mut f = LineFramer::new();
        bytes.iter().filter_map(|&b| f.push(b).map(owned)).collect()
    }

    /// `before`, then bytes lost, then `after`.
    fn frames_across_a_gap(before: &[u8], after: &[u8]) -> Vec<Owned> {
        let mut f = LineFramer::new();
        let mut out: Vec<Owned> = before.iter().filter_map(|&b| f.push(b).map(owned)).collect();
        f.lost();
        out.extend(after.iter().filter_map(|&b| f.push(b).map(owned)));
        out
    }

    /// `set setpoint_c 2.5` that lost `2.` would be `set setpoint_c 5`.
    #[test]
    fn the_line_a_gap_falls_in_is_refused_and_the_next_one_runs() {
        let (before, after) = (&b"status\nset setpoint_c "[..], &b"5\nget\n"[..]);
        assert_eq!(frames(&[before, after].concat()), [line("status"), line("set setpoint_c 5"), line("get")]);
        assert_eq!(frames_across_a_gap(before, after), [line("status"), Owned::Lost, line("get")]);
        // A gap at a line end: the next line may be the tail of a lost one.
        assert_eq!(frames_across_a_gap(b"status\n", b"5\nget\n"), [line("status"), Owned::Lost, line("get")]);
        // Between the `\r` and the `\n` of one line end.
        assert_eq!(frames_across_a_gap(b"status\r", b"\n5\r\nget\r\n"), [line("status"), Owned::Lost, line("get")]);
        // An empty line after the gap says so at once (whole lines may have gone).
        assert_eq!(frames_across_a_gap(b"status\n", b"\nget\n"), [line("status"), Owned::Lost, line("get")]);
        // A line too long or unprintable across the gap is reported as lost.
        assert_eq!(frames_across_a_gap(b"set\tx", b"y\nget\n"), [Owned::Lost, line("get")]);
        // Ctrl-U begins a new line whatever was lost before it.
        assert_eq!(frames_across_a_gap(b"set setpoint_c ", b"5\x15get\n"), [line("get")]);
        assert!(Frame::Lost.error().is_some_and(|e| e.starts_with("err line: ") && !e.contains('\n')));
    }

    fn line(s: &str) -> Owned {
        Owned::Line(s.into())
    }

    #[test]
    fn every_line_end_a_terminal_sends_ends_a_line() {
        assert_eq!(frames(b"status\nget\r\nhelp\rack\r\n"), [line("status"), line("get"), line("help"), line("ack")]);
        assert_eq!(frames(b"\r\n\r\n  \n"), []);
        assert_eq!(frames(b"  set setpoint_c 5  \n"), [line("set setpoint_c 5")]);
    }

    #[test]
    fn backspace_and_del_erase_so_a_typo_can_be_fixed() {
        assert_eq!(frames(b"statsu\x08\x08us\n"), [line("status")]);
        assert_eq!(frames(b"st\x7f\x7f\x7fstatus\n"), [line("status")]);
    }

    /// What a client that went away mid-line leaves, and how the next request drops it.
    #[test]
    fn line_kill_drops_a_partial_line_left_behind() {
        assert_eq!(frames(b"set setpoint_c 6status\n"), [line("set setpoint_c 6status")]);
        assert_eq!(frames(b"set setpoint_c 6\x15status\n"), [line("status")]);
        // Also after a line already too long or unprintable, and at the start of a line.
        let over = "y".repeat(MAX_LINE + 1);
        assert_eq!(frames(format!("{over}\x15get\n").as_bytes()), [line("get")]);
        assert_eq!(frames(b"a\tb\x15\x15get\n"), [line("get")]);
    }

    #[test]
    fn over_long_or_unprintable_lines_are_dropped_whole_and_the_next_one_works() {
        let max = "x".repeat(MAX_LINE);
        assert_eq!(frames(format!("{max}\n").as_bytes()), [line(&max)]);
        let over = "y".repeat(MAX_LINE + 1);
        assert_eq!(frames(format!("{over}{over}\nget\n").as_bytes()), [Owned::TooLong, line("get")]);
        assert_eq!(frames(b"set\tsetpoint_c 5\nget\n"), [Owned::NotPrintable, line("get")]);
        assert_eq!(frames("set setpoint_c 5 °C\n".as_bytes()), [Owned::NotPrintable]);
    }
}
