//! Host tests of the firmware's request framing (`firmware/src/line.rs`, included as `line`).

use crate::line::{LineAssembler, LineError, MAX_LINE};

/// Feeds `bytes` and collects what each completed line gave.
fn lines(bytes: &[u8]) -> Vec<Result<String, LineError>> {
    let mut a = LineAssembler::new();
    bytes.iter().filter_map(|&b| a.push(b).map(|r| r.map(str::to_owned))).collect()
}

fn ok(s: &str) -> Result<String, LineError> {
    Ok(s.to_owned())
}

#[test]
fn each_terminator_ends_one_line() {
    assert_eq!(lines(b"help\n"), [ok("help")]);
    assert_eq!(lines(b"status\r\nget\r\n"), [ok("status"), ok("get")]);
    assert_eq!(lines(b"status\rget\r"), [ok("status"), ok("get")]);
    // A bare \r then \n of the next line's end: \r\n is one terminator, \n\n two.
    assert_eq!(lines(b"a\r\r\nb\n\n"), [ok("a"), ok(""), ok("b"), ok("")]);
    // Nothing comes out before the terminator.
    assert_eq!(lines(b"set setpoint_c 5"), []);
}

#[test]
fn a_line_of_max_length_passes_and_one_byte_more_is_refused_whole() {
    let full = "x".repeat(MAX_LINE);
    let mut input = format!("{full}\n").into_bytes();
    input.extend_from_slice(format!("{full}y tail\nnext\n").as_bytes());
    assert_eq!(lines(&input), [ok(&full), Err(LineError::TooLong), ok("next")]);
}

#[test]
fn a_byte_outside_printable_ascii_refuses_its_line_and_only_its_line() {
    for bad in [0x00u8, 0x07, b'\t', 0x1b, 0x7f, 0x80, 0xc3, 0xff] {
        let input = [b"se".as_slice(), &[bad], b"t ack 1\nack\n"].concat();
        assert_eq!(lines(&input), [Err(LineError::NotPrintable), ok("ack")], "byte {bad:#04x}");
    }
    // Space and tilde are the ends of the printable range.
    assert_eq!(lines(b" ~\n"), [ok(" ~")]);
}

#[test]
fn the_first_fault_of_a_line_is_the_one_reported() {
    let long_then_bad = [vec![b'x'; MAX_LINE + 1], vec![0x01, b'\n']].concat();
    assert_eq!(lines(&long_then_bad), [Err(LineError::TooLong)]);
    let bad_then_long = [vec![0x01], vec![b'x'; MAX_LINE + 5], vec![b'\n']].concat();
    assert_eq!(lines(&bad_then_long), [Err(LineError::NotPrintable)]);
}

#[test]
fn refusals_are_the_protocols_lines() {
    // docs/interface.md, Framing: `err line: …`.
    assert_eq!(LineError::TooLong.reply(), "err line: too long");
    assert_eq!(LineError::NotPrintable.reply(), "err line: not printable ASCII");
}
