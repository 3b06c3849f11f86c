//! The settings and data interface's transport: USART2 on the ST-LINK's virtual COM port
//! (115200 8N1, `board::serial_config`), one request line in, one reply out
//! (docs/interface.md).
//!
//! The [`serial`] task owns the UART: an interrupt-driven driver (embassy's `BufferedUart`)
//! moves bytes between the pins and two ring buffers ([`RX_BUF`], [`TX_BUF`] bytes); the task
//! frames received bytes into lines (`hter::iface::line::LineFramer`, the virtual board's too),
//! hands each request to the control task ([`REQUESTS`]), whose `hter::app::App::handle`
//! writes the reply into [`REPLY`] and signals [`REPLIED`], and sends the reply; for `history`
//! it then relays the rows the persist task streams ([`crate::persist::HISTORY_PIPE`]).
//!
//! It never holds up the control loop: it is its own task, awaiting while it waits for bytes or
//! for room in the transmit ring; the control task handles a request between two samples in
//! microseconds and never waits for this task. The
//! UART has no flow control, so the transmit ring drains at the line rate (≈ 11.5 kB/s) whether
//! or not a host reads the port (the ST-LINK drops what its USB host does not take); should it
//! still not drain (a clock or driver fault), a reply gets at most [`TX_TIMEOUT_MS`] and the rest
//! of it is dropped, with a warning in the defmt log. A reply longer than [`REPLY_CAP`] is not
//! sent: the host gets `err reply: too long` instead, so the final line stays true.
//!
//! Costs (feature `serial` on the default build, `llvm-size -A`): +4 016 B of flash (the
//! driver and its interrupt handler ≈ 1.6 KB, this task ≈ 1.2 KB, framing, waits) and +1 824 B
//! of static RAM (the rings, the reply buffer and the line buffer live in the task's future).

use defmt::warn;
use embassy_stm32::usart::{BufferedUart, BufferedUartTx};
use embassy_time::{with_timeout, Duration, Instant};
use embedded_io_async::{Read, Write as _};

use core::cell::RefCell;

use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use hter::app::Handled;
use hter::iface::line::{Frame, LineFramer};
use hter::iface::sink::{Full, Sink, Written};
use hter::iface::MAX_LINE;

use crate::board;

/// Request lines for the control task (one at a time: the next waits for its reply).
pub static REQUESTS: Channel<CriticalSectionRawMutex, heapless::String<MAX_LINE>, 1> = Channel::new();
/// The reply the control task wrote (thread mode only: no critical section while it formats).
pub static REPLY: Mutex<ThreadModeRawMutex, RefCell<Reply>> = Mutex::new(RefCell::new(Reply::new()));
/// The control task handled the request in [`REQUESTS`]: how ([`Handled::History`]: the rows
/// follow through the persist task's pipe).
pub static REPLIED: Signal<CriticalSectionRawMutex, Handled> = Signal::new();
/// A `history` stream that sends nothing for this long is ended (the persist task gave up).
const HISTORY_QUIET_MS: u64 = 3_000;

/// Receive ring, bytes: more than a request, so one line typed or pasted at 115200 waits whole
/// while the task handles the one before. Beyond it, typed-ahead bytes are lost, and the line
/// the loss falls in is refused (`rx_ring_was_full`).
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

/// A reply being written: at most [`REPLY_CAP`] bytes, `\n` sent as `\r\n`. A reply that does not
/// fit is marked too long (the sink returns [`Full`] from then on).
pub struct Reply {
    buf: [u8; REPLY_CAP],
    len: usize,
    overflow: bool,
}

impl Reply {
    const fn new() -> Self {
        Reply { buf: [0; REPLY_CAP], len: 0, overflow: false }
    }

    /// Empty, for the next reply.
    pub fn clear(&mut self) {
        self.len = 0;
        self.overflow = false;
    }

    fn push(&mut self, b: u8) -> Written {
        let slot = self.buf.get_mut(self.len).ok_or(Full)?;
        *slot = b;
        self.len += 1;
        Ok(())
    }

    /// What to send: the reply, ending in a line end; or the refusal of a reply too long.
    fn finish(&mut self) -> &[u8] {
        if !self.overflow && self.len > 0 && self.buf.get(self.len - 1) != Some(&b'\n') {
            self.overflow = self.str("\n").is_err();
        }
        if self.overflow {
            return b"err reply: too long\r\n";
        }
        self.buf.get(..self.len).unwrap_or(&[])
    }
}

impl Sink for Reply {
    fn str(&mut self, s: &str) -> Written {
        if self.overflow {
            return Err(Full);
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
    let mut framer = LineFramer::new();
    // As long as the ring: one read takes all it holds (see `rx_ring_was_full`).
    let mut chunk = [0u8; RX_BUF];
    loop {
        let n = match rx.read(&mut chunk).await {
            Ok(n) => n,
            Err(e) => {
                warn!("serial: receive error ({})", e);
                continue;
            }
        };
        let full = rx_ring_was_full(n);
        for &b in chunk.get(..n).unwrap_or(&[]) {
            let request = match framer.push(b) {
                None => continue,
                Some(Frame::Line(line)) => heapless::String::try_from(line).ok(),
                Some(f) => {
                    let e = f.error().unwrap_or("err line");
                    let _ = send(&mut tx, e.as_bytes()).await && send(&mut tx, b"\r\n").await;
                    continue;
                }
            };
            let Some(request) = request else { continue };
            REQUESTS.send(request).await;
            let handled = REPLIED.wait().await;
            if !send_reply(&mut tx).await {
                warn!("serial: transmit ring full for {} ms, reply dropped", TX_TIMEOUT_MS);
            }
            if handled != Handled::Done {
                relay_history(&mut tx).await;
            }
        }
        if full {
            warn!("serial: receive ring full, bytes typed ahead may be lost");
            framer.lost();
        }
    }
}

/// A read of `n` bytes into a buffer of [`RX_BUF`] found the receive ring full, so bytes that
/// arrived after them may have been dropped. Embassy 0.6's `BufferedUart` interrupt handler
/// drops, without a flag or an error, every byte that arrives while its ring is full
/// (`usart/buffered.rs`, `on_interrupt`: an empty `push_slice`), and a person who pastes
/// several lines while a long reply (`help`, `status`: ≈ 90 ms) or a `history` goes out fills
/// its [`RX_BUF`] bytes. Only this task empties the ring, whose capacity is exactly its length
/// (embassy-hal-internal 0.5's `RingBuffer`), and a read takes all it holds into a buffer as
/// long: a byte dropped since the last read means the ring is still full at this one, so
/// `n == RX_BUF`. The converse is not true (a ring filled to its last byte and no more), and
/// then one good line is refused: the price of never running a line glued from two
/// (`hter::iface::line::LineFramer::lost`; `tests/iface_fuzz.rs` runs this loop against a model
/// of the ring).
fn rx_ring_was_full(n: usize) -> bool {
    n >= RX_BUF
}

/// Sends [`REPLY`] in chunks copied out of it (the control task may write the next one only
/// after the next request).
async fn send_reply(tx: &mut BufferedUartTx<'_>) -> bool {
    let mut at = 0;
    let mut part = [0u8; TX_BUF / 2];
    loop {
        let n = REPLY.lock(|r| {
            let mut r = r.borrow_mut();
            let bytes = r.finish();
            let rest = bytes.get(at..).unwrap_or(&[]);
            let n = rest.len().min(part.len());
            part[..n].copy_from_slice(&rest[..n]);
            n
        });
        if n == 0 {
            return true;
        }
        if !send(tx, &part[..n]).await {
            return false;
        }
        at += n;
    }
}

/// Relays the `history` rows from the persist task until their final line (`ok` or `err …`,
/// which no CSV row starts with), or until the stream goes quiet.
async fn relay_history(tx: &mut BufferedUartTx<'_>) {
    let mut buf = [0u8; 64];
    // The first bytes of the current line, to recognise the final one.
    let mut head = [0u8; 4];
    let mut col = 0usize;
    loop {
        let n = match with_timeout(Duration::from_millis(HISTORY_QUIET_MS), crate::persist::HISTORY_PIPE.read(&mut buf))
            .await
        {
            Ok(n) => n,
            Err(_) => {
                let _ = send(tx, b"err history: the log stream stopped\r\n").await;
                return;
            }
        };
        let bytes = buf.get(..n).unwrap_or(&[]);
        // A host that stopped reading loses the rest; the stream keeps draining the pipe.
        let _ = send(tx, bytes).await;
        for &b in bytes {
            if b == b'\n' {
                if head.starts_with(b"ok\r") || head.starts_with(b"err ") {
                    return;
                }
                (col, head) = (0, [0; 4]);
            } else {
                if let Some(h) = head.get_mut(col) {
                    *h = b;
                }
                col += 1;
            }
        }
    }
}
