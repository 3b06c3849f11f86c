//! Request framing of the settings and data interface (docs/interface.md, "Framing"): bytes in,
//! complete lines out.
//!
//! A request is at most [`MAX_LINE`] bytes of printable ASCII (0x20–0x7E) ended by `\n`, `\r\n`
//! or a bare `\r` (a terminal's Enter). A line with a byte outside printable ASCII, or longer
//! than [`MAX_LINE`] bytes, is refused as a whole when its end arrives ([`LineError`], one reply
//! per line, in order), and its bytes are dropped. Fixed 96-byte buffer, no heap, `core` only:
//! the firmware's serial task feeds it from the UART, and `cargo test -p xtask` tests it on the
//! host (it includes this file as a module, as it does `pil/src/proto.rs`).

/// Longest request, bytes (the terminator not counted).
pub const MAX_LINE: usize = 96;

/// Why a line was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineError {
    /// More than [`MAX_LINE`] bytes before the terminator.
    TooLong,
    /// A byte outside printable ASCII (0x20–0x7E) other than the terminators.
    NotPrintable,
}

impl LineError {
    /// The reply's final line for this refusal (docs/interface.md: `err line: …`).
    pub fn reply(self) -> &'static str {
        match self {
            LineError::TooLong => "err line: too long",
            LineError::NotPrintable => "err line: not printable ASCII",
        }
    }
}

/// Assembles received bytes into lines.
pub struct LineAssembler {
    buf: [u8; MAX_LINE],
    len: usize,
    /// The line so far is refused (its bytes are dropped until its end).
    refused: Option<LineError>,
    /// The last byte was `\r`: a `\n` right after it ends nothing (`\r\n` is one terminator).
    after_cr: bool,
}

impl Default for LineAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl LineAssembler {
    /// An empty assembler.
    pub const fn new() -> Self {
        LineAssembler { buf: [0; MAX_LINE], len: 0, refused: None, after_cr: false }
    }

    /// Takes one received byte. `Some(Ok(line))` when it ended a line (without its terminator;
    /// possibly empty), `Some(Err(..))` when it ended a refused line, `None` otherwise.
    pub fn push(&mut self, byte: u8) -> Option<Result<&str, LineError>> {
        let after_cr = core::mem::replace(&mut self.after_cr, byte == b'\r');
        match byte {
            b'\n' if after_cr => None,
            b'\n' | b'\r' => {
                let len = core::mem::replace(&mut self.len, 0);
                if let Some(e) = self.refused.take() {
                    return Some(Err(e));
                }
                let bytes = self.buf.get(..len).unwrap_or(&[]);
                // SAFETY: the only write to `buf` (below) stores bytes 0x20–0x7E, which are
                // ASCII and so UTF-8. (`from_utf8` would cost 0.6 KiB of flash for a check
                // that cannot fail.)
                Some(Ok(unsafe { core::str::from_utf8_unchecked(bytes) }))
            }
            _ if self.refused.is_some() => None,
            0x20..=0x7E => {
                match self.buf.get_mut(self.len) {
                    Some(slot) => {
                        *slot = byte;
                        self.len += 1;
                    }
                    None => self.refused = Some(LineError::TooLong),
                }
                None
            }
            _ => {
                self.refused = Some(LineError::NotPrintable);
                None
            }
        }
    }
}
