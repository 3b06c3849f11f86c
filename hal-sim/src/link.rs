//! The virtual board's serial line: a pseudo-terminal whose slave side a host tool opens like
//! a real serial port (`hter board --port PATH`, `picocom`, `screen`), and whose master side
//! the virtual board's loop polls between simulated samples.
//!
//! [`PtyLink::open`] creates the pty pair (raw mode, so no echo and no line editing: the
//! board's framing applies, as on the NUCLEO's UART) and makes `PATH` a symlink to the slave
//! device (`/dev/pts/N`). The link does the framing of docs/interface.md (§ Framing) and
//! nothing else: [`PtyLink::poll_line`] gives complete request lines, answers malformed lines
//! itself with `err line: …`, and [`PtyLink::send`] queues a reply with `\r\n` line ends.
//!
//! In order. The board frames and answers one line at a time, so its replies come in the order
//! of the lines, however many came in one write. The link keeps what it read in that order, the
//! requests and the refusals of malformed lines alike, and sends a refusal only once the lines
//! before it have been handed out (and answered: the caller sends each reply before it polls
//! again).
//!
//! Between clients. The link keeps its own descriptor of the slave open for its whole life.
//! Without it, the master would read EIO and poll as hung up whenever no client has the port
//! open. With it, two facts about Linux ptys need handling:
//! - A client that sets `TIOCEXCL` (serialport does, for exclusive access) and dies without
//!   closing cleanly (killed, Ctrl-C) leaves the flag on the slave, because a pty's slave tty
//!   lives as long as its master: every later open by a non-root user would fail with EBUSY.
//!   The link clears the flag on its own descriptor at every poll. Exclusive access between
//!   clients is still enforced by serialport's `flock`, which the kernel drops with the process.
//! - Output written while no client reads stays in the pty's buffer. `hter board` discards its
//!   input buffer after opening the port (as it must on a real board too); the link's own
//!   queue of unsent output is dropped when the next request line arrives (one reply at a time:
//!   a new request supersedes the rest of an unread reply).
//!
//! Output never blocks the caller: the master is non-blocking, what the pty does not take now
//! waits in a queue (at most [`MAX_PENDING_BYTES`]) that every `poll_line`/`send` call
//! advances; beyond that bound output is dropped and counted, as the board's transmit side
//! drops output nobody reads.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, FromRawFd, IntoRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

/// Longest request line, bytes without its line end (docs/interface.md § Framing).
pub const MAX_LINE_BYTES: usize = hter::iface::MAX_LINE;

/// Unsent output the link keeps, bytes: ten times a 30-day history (8 640 five-minute
/// interval rows of about 45 bytes, plus events), so only a client that stopped reading loses
/// output.
pub const MAX_PENDING_BYTES: usize = 4 << 20;

pub use hter::iface::line::{Frame, LineFramer};

/// A pseudo-terminal serving the board's interface at a path (see the module docs).
pub struct PtyLink {
    /// Master side, non-blocking.
    master: File,
    /// The link's own descriptor of the slave (see the module docs).
    slave: File,
    device: PathBuf,
    path: PathBuf,
    framer: LineFramer,
    received: VecDeque<Received>,
    out: VecDeque<u8>,
    dropped_bytes: u64,
}

impl std::fmt::Debug for PtyLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PtyLink").field("path", &self.path).field("device", &self.device).finish_non_exhaustive()
    }
}

impl PtyLink {
    /// Creates a pty pair in raw mode and makes `path` a symlink to its slave device. An
    /// existing symlink at `path` is replaced (a virtual board that was not stopped cleanly
    /// leaves one); any other file there is refused.
    pub fn open(path: &Path) -> io::Result<Self> {
        match std::fs::symlink_metadata(path) {
            Ok(m) if !m.file_type().is_symlink() => {
                return Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    format!("'{}' exists and is not a symlink; not replacing it", path.display()),
                ));
            }
            Ok(_) | Err(_) => {}
        }
        let (master, slave) = TTYPort::pair().map_err(io::Error::from)?;
        let device =
            slave.name().map(PathBuf::from).ok_or_else(|| io::Error::other("the pty's slave device has no name"))?;
        let (master, slave) = (into_file(master), into_file(slave));
        set_nonblocking(&master)?;
        // Create the symlink beside `path` and rename it over: a client never sees the path
        // missing or half made.
        let file_name = path.file_name().ok_or_else(|| {
            io::Error::new(io::ErrorKind::InvalidInput, format!("'{}' is not a file path", path.display()))
        })?;
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(".{}.tmp", std::process::id()));
        let tmp = path.with_file_name(tmp_name);
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&device, &tmp)?;
        if let Err(e) = std::fs::rename(&tmp, path) {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        Ok(Self {
            master,
            slave,
            device,
            path: path.to_path_buf(),
            framer: LineFramer::new(),
            received: VecDeque::new(),
            out: VecDeque::new(),
            dropped_bytes: 0,
        })
    }

    /// The symlink clients open.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The slave device the symlink points to (`/dev/pts/N`).
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// Output queued but not yet taken by the pty, bytes.
    pub fn pending_bytes(&self) -> usize {
        self.out.len()
    }

    /// Output dropped since the link opened (queue full, or superseded by a new request), bytes.
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }

    /// Waits up to `timeout` for a complete request line and returns it (trimmed, never
    /// empty), or `None` if none came (or a signal arrived first). Meanwhile it sends queued
    /// output and answers malformed lines (`err line: …`) itself, each in its turn: after the
    /// lines received before it were returned. `Duration::ZERO` only looks.
    pub fn poll_line(&mut self, timeout: Duration) -> io::Result<Option<String>> {
        // A crashed client's TIOCEXCL (module docs); harmless when not set. Not serialport's
        // `set_exclusive(false)`: that also takes a shared flock, which would lock clients out.
        // SAFETY: TIOCNXCL takes no argument; the descriptor is this link's own.
        let _ = unsafe { libc::ioctl(self.slave.as_raw_fd(), libc::TIOCNXCL) };
        self.flush_out()?;
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(r) = self.received.pop_front() {
                match r {
                    Received::Line(line) => return Ok(Some(line)),
                    Received::Refused(why) => self.send(why)?,
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let ready = wait(&self.master, !self.out.is_empty(), left)?;
            if ready.interrupted {
                // The caller may have a stop request to look at (`hter virtual-board`'s Ctrl-C).
                return Ok(None);
            }
            if ready.hangup && !ready.readable {
                // Nobody on the slave side (cannot happen while the link holds it): do not spin.
                std::thread::sleep(left);
                return Ok(None);
            }
            if ready.writable {
                self.flush_out()?;
            }
            if ready.readable {
                self.read_in()?;
            }
            if self.received.is_empty() && Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// Queues a reply and sends what the pty takes now. `reply` is one or more lines ended by
    /// `\n` or `\r\n` (the last line end may be left out); each goes out ended by `\r\n`.
    pub fn send(&mut self, reply: &str) -> io::Result<()> {
        for line in reply.lines() {
            self.queue(line.as_bytes());
            self.queue(b"\r\n");
        }
        self.flush_out()
    }

    fn queue(&mut self, bytes: &[u8]) {
        let room = MAX_PENDING_BYTES.saturating_sub(self.out.len());
        let take = bytes.len().min(room);
        self.out.extend(bytes.iter().take(take));
        self.dropped_bytes += (bytes.len() - take) as u64;
    }

    fn flush_out(&mut self) -> io::Result<()> {
        while !self.out.is_empty() {
            let (front, _) = self.out.as_slices();
            match self.master.write(front) {
                Ok(0) => break,
                Ok(n) => drop(self.out.drain(..n)),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                // EIO: no slave open (cannot happen while the link holds it); the output has
                // nobody to go to.
                Err(e) if e.raw_os_error() == Some(libc::EIO) => {
                    self.dropped_bytes += self.out.len() as u64;
                    self.out.clear();
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    fn read_in(&mut self) -> io::Result<()> {
        let mut buf = [0u8; 512];
        loop {
            let n = match self.master.read(&mut buf) {
                Ok(0) => return Ok(()),
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) if e.raw_os_error() == Some(libc::EIO) => {
                    self.framer.reset();
                    return Ok(());
                }
                Err(e) => return Err(e),
            };
            for &b in buf.iter().take(n) {
                let received = match self.framer.push(b) {
                    None => continue,
                    Some(Frame::Line(l)) => {
                        // A new request supersedes what is left of the previous reply.
                        self.dropped_bytes += self.out.len() as u64;
                        self.out.clear();
                        Received::Line(l.to_string())
                    }
                    Some(f) => match f.error() {
                        Some(why) => Received::Refused(why),
                        None => continue,
                    },
                };
                self.received.push_back(received);
            }
        }
    }
}

/// What a line of input came to, kept in the order received.
enum Received {
    /// A request, for the caller.
    Line(String),
    /// A malformed line's refusal, which the link sends itself.
    Refused(&'static str),
}

impl Drop for PtyLink {
    /// Removes the symlink if it still points to this link's device (another virtual board
    /// may have taken the path since).
    fn drop(&mut self) {
        if std::fs::read_link(&self.path).is_ok_and(|t| t == self.device) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

fn into_file(port: TTYPort) -> File {
    // SAFETY: `into_raw_fd` hands over the descriptor without closing it; nothing else owns it.
    File::from(unsafe { OwnedFd::from_raw_fd(port.into_raw_fd()) })
}

fn set_nonblocking(f: &File) -> io::Result<()> {
    let fd = f.as_raw_fd();
    // SAFETY: fcntl on a descriptor this function borrows; no memory is passed.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    // SAFETY: as above.
    if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

struct Ready {
    readable: bool,
    writable: bool,
    hangup: bool,
    /// A signal ended the wait.
    interrupted: bool,
}

/// poll(2) on one descriptor: readable, and writable if `want_write`, for up to `timeout`.
fn wait(f: &File, want_write: bool, timeout: Duration) -> io::Result<Ready> {
    let mut events = libc::POLLIN;
    if want_write {
        events |= libc::POLLOUT;
    }
    let mut pfd = libc::pollfd { fd: f.as_raw_fd(), events, revents: 0 };
    // Round up: a 0.3 ms timeout must not become a busy 0 ms loop.
    let ms = timeout.as_micros().div_ceil(1000).min(i32::MAX as u128) as i32;
    // SAFETY: one valid pollfd, count 1.
    let r = unsafe { libc::poll(&mut pfd, 1, ms) };
    if r < 0 {
        let e = io::Error::last_os_error();
        if e.kind() == io::ErrorKind::Interrupted {
            return Ok(Ready { readable: false, writable: false, hangup: false, interrupted: true });
        }
        return Err(e);
    }
    Ok(Ready {
        readable: pfd.revents & libc::POLLIN != 0,
        writable: pfd.revents & libc::POLLOUT != 0,
        hangup: pfd.revents & (libc::POLLHUP | libc::POLLERR) != 0,
        interrupted: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp_path(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("hter-link-{}-{name}", std::process::id()))
    }

    /// A client on the link's port, as `hter board` opens it.
    fn client(path: &Path) -> serialport::TTYPort {
        serialport::new(path.to_string_lossy(), 115_200)
            .timeout(Duration::from_secs(5))
            .open_native()
            .expect("open the link")
    }

    /// The next request line the link hands out, waiting for it.
    fn next_line(link: &mut PtyLink) -> String {
        loop {
            if let Some(l) = link.poll_line(Duration::from_millis(50)).unwrap() {
                break l;
            }
        }
    }

    /// What the client reads until `done` says the text is complete.
    fn read_until(port: &mut serialport::TTYPort, done: impl Fn(&str) -> bool) -> String {
        let mut text = String::new();
        let mut buf = [0u8; 256];
        while !done(&text) {
            let n = port.read(&mut buf).expect("reply");
            text.push_str(std::str::from_utf8(&buf[..n]).unwrap());
        }
        text
    }

    /// A client as `hter board` opens the port: send `request`, the board answers `reply`, the
    /// client reads until `ok`; gives the line the board got and the text the client got.
    fn client_request(path: &Path, link: &mut PtyLink, request: &str, reply: &str) -> (String, String) {
        let mut port = client(path);
        port.write_all(request.as_bytes()).unwrap();
        let got = next_line(link);
        link.send(reply).unwrap();
        let text = read_until(&mut port, |t| t.ends_with("ok\r\n"));
        (got, text)
    }

    #[test]
    fn serves_successive_clients_and_cleans_up() {
        let path = tmp_path("clients");
        std::fs::write(&path, "precious").unwrap();
        let e = PtyLink::open(&path).unwrap_err();
        assert!(e.to_string().contains("not a symlink"), "{e}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
        std::fs::remove_file(&path).unwrap();
        // A stale symlink (a board killed earlier) is replaced.
        std::os::unix::fs::symlink("/dev/pts/no-such", &path).unwrap();
        let mut link = PtyLink::open(&path).unwrap();
        assert_eq!(std::fs::read_link(&path).unwrap(), link.device());
        assert_eq!(link.poll_line(Duration::ZERO).unwrap(), None);
        let got = |l: &str, t: &str| (l.to_string(), t.to_string());
        assert_eq!(client_request(&path, &mut link, "status\r\n", "t_s=1\nok"), got("status", "t_s=1\r\nok\r\n"));
        assert_eq!(
            client_request(&path, &mut link, "get\n", "setpoint_c=5.00\r\nok\r\n"),
            got("get", "setpoint_c=5.00\r\nok\r\n")
        );
        assert_eq!(
            client_request(&path, &mut link, "x\x01\nack\r", "ok"),
            got("ack", &format!("{}\r\nok\r\n", Frame::NotPrintable.error().unwrap()))
        );
        drop(link);
        assert!(std::fs::symlink_metadata(&path).is_err(), "symlink left behind");
    }

    #[test]
    fn answers_framing_errors_itself() {
        let path = tmp_path("framing");
        let mut link = PtyLink::open(&path).unwrap();
        let mut port = client(&path);
        port.write_all(format!("{}\nget\n", "z".repeat(200)).as_bytes()).unwrap();
        let got = next_line(&mut link);
        assert_eq!(got, "get");
        let text = read_until(&mut port, |t| t.ends_with("\r\n"));
        assert_eq!(text, format!("{}\r\n", Frame::TooLong.error().unwrap()));
    }

    /// Lines in one write, malformed ones among them: each is answered in its turn, as the
    /// board does (it frames and answers one line at a time); the refusal of a malformed line
    /// went out as soon as it was read, ahead of the replies to the lines before it.
    #[test]
    fn malformed_lines_are_refused_in_their_turn() {
        let path = tmp_path("order");
        let mut link = PtyLink::open(&path).unwrap();
        let mut port = client(&path);
        port.write_all(b"get\n\x01\nhelp\nx\ty\n").unwrap();
        let mut heard = Vec::new();
        while heard.len() < 2 {
            if let Some(l) = link.poll_line(Duration::from_millis(50)).unwrap() {
                link.send(&format!("{l}=1\nok")).unwrap();
                heard.push(l);
            }
        }
        // The refusal after the last line goes out at the next poll.
        assert_eq!(link.poll_line(Duration::ZERO).unwrap(), None);
        let refused = Frame::NotPrintable.error().unwrap();
        let want = format!("get=1\r\nok\r\n{refused}\r\nhelp=1\r\nok\r\n{refused}\r\n");
        let text = read_until(&mut port, |t| t.len() >= want.len());
        assert_eq!((heard, text), (vec!["get".to_string(), "help".to_string()], want));
    }

    #[test]
    fn a_crashed_clients_exclusive_flag_is_cleared() {
        let path = tmp_path("excl");
        let mut link = PtyLink::open(&path).unwrap();
        let excl = |f: &File| {
            let mut on: libc::c_int = 0;
            // SAFETY: TIOCGEXCL writes one c_int.
            assert_eq!(unsafe { libc::ioctl(f.as_raw_fd(), libc::TIOCGEXCL, &mut on) }, 0);
            on != 0
        };
        let f = File::options().read(true).write(true).open(&path).unwrap();
        // SAFETY: TIOCEXCL takes no argument.
        assert_eq!(unsafe { libc::ioctl(f.as_raw_fd(), libc::TIOCEXCL) }, 0);
        drop(f); // closed without TIOCNXCL, as a killed process's descriptor is
        let probe = File::options().read(true).write(true).open(&path).unwrap(); // root may
        assert!(excl(&probe), "the flag outlives the client on a pty");
        link.poll_line(Duration::ZERO).unwrap();
        assert!(!excl(&probe));
    }

    #[test]
    fn output_nobody_reads_is_queued_then_superseded() {
        let path = tmp_path("queue");
        let mut link = PtyLink::open(&path).unwrap();
        let row = format!("{}\n", "1,4.00,3.90,4.10,0.500,normal,".repeat(2));
        let big: String = row.repeat(20_000); // ~1.2 MB, more than a pty holds
        link.send(&big).unwrap();
        assert!(link.pending_bytes() > 0, "the pty took everything");
        let mut port = client(&path);
        port.write_all(b"status\n").unwrap();
        let got = next_line(&mut link);
        assert_eq!((got.as_str(), link.pending_bytes()), ("status", 0));
        assert!(link.dropped_bytes() > 0);
    }
}
