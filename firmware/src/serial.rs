//! The settings and data interface's transport: USART2 on the ST-LINK's virtual COM port
//! (115200 8N1, `board::serial_config`), one request line in, one reply out
//! (docs/interface.md).
//!
//! The [`serial`] task owns the UART: an interrupt-driven driver (embassy's `BufferedUart`)
//! moves bytes between the pins and two ring buffers ([`RX_BUF`], [`TX_BUF`] bytes); the task
//! assembles received bytes into lines ([`crate::line`]), hands each complete request to
//! [`handle`], which writes its reply into a [`REPLY_CAP`]-byte buffer, and sends the reply.
//!
//! It never holds up the control loop: it is its own task, awaiting while it waits for bytes or
//! for room in the transmit ring, and [`handle`] runs to completion between two awaits. The
//! UART has no flow control, so the transmit ring drains at the line rate (≈ 11.5 kB/s) whether
//! or not a host reads the port (the ST-LINK drops what its USB host does not take); should it
//! still not drain (a clock or driver fault), a reply gets at most [`TX_TIMEOUT_MS`] and the rest
//! of it is dropped, with a warning in the defmt log. A reply longer than [`REPLY_CAP`] is not
//! sent: the host gets `err reply: too long` instead, so the final line stays true.
//!
//! Costs (feature `serial` on the default build, `llvm-size -A`): +4 016 B of flash (the
//! driver and its interrupt handler ≈ 1.6 KB, this task ≈ 1.2 KB, framing, waits) and +1 824 B
//! of static RAM (the rings, the reply buffer and the line buffer live in the task's future).

use core::fmt::Write;

use defmt::warn;
use embassy_stm32::usart::{BufferedUart, BufferedUartTx};
use embassy_time::{with_timeout, Duration, Instant};
use embedded_io_async::{Read, Write as _};

use crate::board;
use crate::line::LineAssembler;

/// Receive ring, bytes: more than a request, so one line typed or pasted at 115200 waits whole
/// while the task handles the one before.
pub const RX_BUF: usize = 128;
/// Transmit ring, bytes (≈ 22 ms at 115200).
pub const TX_BUF: usize = 256;
/// Longest reply, bytes (with its `\r\n` line ends): `help` and `status` fit.
pub const REPLY_CAP: usize = 1024;
/// Longest a reply may wait for room in the transmit ring before the rest is dropped, ms (a
/// [`REPLY_CAP`] reply drains in ≈ 90 ms).
pub const TX_TIMEOUT_MS: u64 = 250;
/// How often a write that found the ring full looks again, ms (embassy 0.6's buffered write
/// does not always register for the wake-up when the ring lacks room: poll it).
const TX_RETRY_MS: u64 = 2;

/// Answers one request line (printable ASCII, ≤ 96 bytes, terminator removed, not empty after
/// trimming spaces): zero or more data lines, then exactly one final line, `ok` or
/// `err <what>: <why>`. Lines end in `\n` (the transport sends `\r\n`).
///
/// Placeholder until the library's handler is wired in (issue 16).
pub fn handle(line: &str, reply: &mut impl Write) {
    let _ = line;
    let _ = writeln!(reply, "err line: interface not wired yet");
}

/// A reply being written: at most [`REPLY_CAP`] bytes, `\n` sent as `\r\n`. A reply that does not
/// fit is marked too long (the writer returns `fmt::Error` from then on).
pub struct Reply {
    buf: [u8; REPLY_CAP],
    len: usize,
    overflow: bool,
}

impl Reply {
    const fn new() -> Self {
        Reply { buf: [0; REPLY_CAP], len: 0, overflow: false }
    }

    fn clear(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    fn push(&mut self, b: u8) -> core::fmt::Result {
        let slot = self.buf.get_mut(self.len).ok_or(core::fmt::Error)?;
        *slot = b;
        self.len += 1;
        Ok(())
    }

    /// What to send: the reply, ending in a line end; or the refusal of a reply too long.
    fn finish(&mut self) -> &[u8] {
        if !self.overflow && self.len > 0 && self.buf.get(self.len - 1) != Some(&b'\n') {
            self.overflow = self.write_str("\n").is_err();
        }
        if self.overflow {
            return b"err reply: too long\r\n";
        }
        self.buf.get(..self.len).unwrap_or(&[])
    }
}

impl Write for Reply {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        if self.overflow {
            return Err(core::fmt::Error);
        }
        for &b in s.as_bytes() {
            let r = if b == b'\n' && self.len.checked_sub(1).and_then(|i| self.buf.get(i)) != Some(&b'\r') {
                self.push(b'\r').and_then(|()| self.push(b'\n'))
            } else {
                self.push(b)
            };
            if r.is_err() {
                self.overflow = true;
                return r;
            }
        }
        Ok(())
    }
}

/// `line` without its leading and trailing spaces. By hand, on bytes (the line is printable
/// ASCII): `str::trim` brings a Unicode table and `trim_matches` a pattern matcher, 0.25–0.6
/// KiB of flash each.
fn trim_spaces(line: &str) -> &str {
    let b = line.as_bytes();
    let start = b.iter().position(|&c| c != b' ').unwrap_or(b.len());
    let end = b.iter().rposition(|&c| c != b' ').map_or(start, |i| i + 1);
    line.get(start..end).unwrap_or("")
}

/// Sends `bytes` within [`TX_TIMEOUT_MS`]; false (and the rest dropped) when the ring did not take
/// them in time.
async fn send(tx: &mut BufferedUartTx<'_>, bytes: &[u8]) -> bool {
    let deadline = Instant::now() + Duration::from_millis(TX_TIMEOUT_MS);
    // Each write must fit the ring (embassy refuses a longer one outright).
    for chunk in bytes.chunks(TX_BUF / 2) {
        let mut rest = chunk;
        while !rest.is_empty() {
            if Instant::now() >= deadline {
                return false;
            }
            match with_timeout(Duration::from_millis(TX_RETRY_MS), tx.write(rest)).await {
                Ok(Ok(n)) => rest = rest.get(n..).unwrap_or(&[]),
                Ok(Err(e)) => {
                    warn!("serial: write failed ({})", e);
                    return false;
                }
                Err(_) => {}
            }
        }
    }
    true
}

/// Serves the interface on USART2 (see the module docs). Returns only if the UART cannot be
/// configured (the board then runs without the interface, and the log says so).
#[embassy_executor::task]
pub async fn serial(pins: board::SerialPins) {
    // Before the driver enables the interrupt: never a moment at TIM7's urgency.
    board::serial_interrupt_priority();
    let mut tx_buf = [0u8; TX_BUF];
    let mut rx_buf = [0u8; RX_BUF];
    let uart = match BufferedUart::new(
        pins.usart,
        pins.rx,
        pins.tx,
        &mut tx_buf,
        &mut rx_buf,
        board::SerialIrqs,
        board::serial_config(),
    ) {
        Ok(uart) => uart,
        Err(e) => {
            warn!("serial: USART2 not configured ({}): no settings interface", e);
            return;
        }
    };
    let (mut tx, mut rx) = uart.split();
    let mut lines = LineAssembler::new();
    let mut reply = Reply::new();
    let mut chunk = [0u8; 32];
    loop {
        let n = match rx.read(&mut chunk).await {
            Ok(n) => n,
            Err(e) => {
                warn!("serial: receive error ({})", e);
                continue;
            }
        };
        for &b in chunk.get(..n).unwrap_or(&[]) {
            reply.clear();
            match lines.push(b) {
                None => continue,
                Some(Ok(line)) => match trim_spaces(line) {
                    "" => continue,
                    line => handle(line, &mut reply),
                },
                Some(Err(e)) => {
                    let _ = reply.write_str(e.reply());
                }
            }
            if !send(&mut tx, reply.finish()).await {
                warn!("serial: transmit ring full for {} ms, reply dropped", TX_TIMEOUT_MS);
            }
        }
    }
}
