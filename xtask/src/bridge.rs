//! The SCADA port as a Modbus client sees it: a pseudo-terminal of xtask's own, bridged to
//! QEMU's, that behaves like an RS-485 line.
//!
//! QEMU's `-serial pty` alone is no line:
//! - when the last client closes it, QEMU stops reading it and looks again only once a second
//!   (a client that opens the port per request, as mbpoll does, can time out);
//! - held open between clients (as xtask once did), an answer nobody read stays queued, and
//!   the next client reads it as the answer to its own request;
//! - QEMU's USART model writes each byte with a blocking write: a client that stops reading
//!   fills the pty and stops the whole emulated controller.
//!
//! So xtask holds QEMU's pty alone, always reading it, and offers clients a pty of its own:
//! bytes from a client go to QEMU; bytes from QEMU go to the client if one is connected and
//! has room, and are otherwise dropped and counted, as a line drops what nobody listens to.
//! When a client closes its port, what it left unread is flushed, and until QEMU has been
//! silent for [`QUIET_MS`] after that (answers still on their way to the client that left are
//! dropped), the next client's bytes wait; so a client sees only answers to its own requests,
//! unless the controller took longer than [`QUIET_MS`] to answer the one that left, or the
//! one that left opened, wrote and closed unread, and the next opened, all within one pass
//! of the bridge's loop (2 ms; longer when the host is busy): a pty shows no close that is
//! followed by an open before the bridge looks, and both requests then go through (a
//! review saw it in 811 of 3 000 such pairs made 0..4 ms apart; clients that read their
//! answers, as `mbpoll` does, are not concerned).

use crate::util::Result;
use nix::fcntl::{open, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::{grantpt, posix_openpt, ptsname_r, unlockpt, PtyMaster};
use nix::sys::stat::Mode;
use nix::sys::termios::{cfmakeraw, tcflush, tcgetattr, tcsetattr, FlushArg, SetArg};
use nix::unistd::{read, write};
use std::os::fd::{AsFd, OwnedFd};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Bytes from clients waiting for QEMU to take them; beyond this they are dropped (QEMU takes
/// ≈ 14 bytes per ms, so this is seconds of input).
const TO_QEMU_MAX: usize = 64 * 1024;

/// Silence from QEMU, after a client left, before the next client's bytes go through, ms. The
/// controller answers within a few ms in real time; this covers a busy host.
pub const QUIET_MS: u64 = 100;

/// What the bridge counted, shared with its owner.
#[derive(Debug, Default)]
pub struct Stats {
    /// Bytes from clients handed to QEMU.
    pub to_qemu: AtomicU64,
    /// Bytes from QEMU handed to a client.
    pub to_client: AtomicU64,
    /// Bytes from QEMU dropped: no client connected.
    pub dropped_no_client: AtomicU64,
    /// Bytes from QEMU dropped: the client does not read (its port is full).
    pub dropped_not_read: AtomicU64,
    /// Bytes from clients dropped: QEMU did not take them in time.
    pub dropped_to_qemu: AtomicU64,
    /// Bytes from clients dropped: the client closed its port before they were forwarded.
    pub dropped_from_gone: AtomicU64,
    /// Unread bytes flushed when a client closed its port.
    pub flushed_on_close: AtomicU64,
    /// Bytes from QEMU dropped after a client left: answers meant for it.
    pub dropped_after_close: AtomicU64,
    /// Clients that connected and left.
    pub sessions: AtomicU64,
    /// Passes of the bridge's loop begun (each looks once whether a client is connected, at
    /// its start): a close followed by two more passes has been seen.
    pub passes: AtomicU64,
}

impl Stats {
    /// The counters, one line.
    pub fn summary(&self) -> String {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        format!(
            "SCADA line: {} B to the controller, {} B to clients; dropped: {} B with no client connected, {} B answering a client that had left, {} B the client did not read, {} B QEMU did not take, {} B a client sent and closed before they went through; {} B left unread and flushed at {} client closes",
            get(&self.to_qemu),
            get(&self.to_client),
            get(&self.dropped_no_client),
            get(&self.dropped_after_close),
            get(&self.dropped_not_read),
            get(&self.dropped_to_qemu),
            get(&self.dropped_from_gone),
            get(&self.flushed_on_close),
            get(&self.sessions),
        )
    }

    /// Bytes dropped in all (never delivered).
    pub fn dropped(&self) -> u64 {
        self.dropped_from_qemu()
            + self.dropped_to_qemu.load(Ordering::Relaxed)
            + self.dropped_from_gone.load(Ordering::Relaxed)
    }

    /// Bytes from QEMU dropped, reaching no client (after a close, on a port full or gone,
    /// with no client connected): [`Stats::dropped`]'s share of the controller's answers.
    pub fn dropped_from_qemu(&self) -> u64 {
        self.dropped_after_close.load(Ordering::Relaxed)
            + self.dropped_not_read.load(Ordering::Relaxed)
            + self.dropped_no_client.load(Ordering::Relaxed)
    }
}

/// A running bridge: the clients' port and the counters. The thread ends when QEMU's pty
/// closes or `stop` is set.
pub struct Bridge {
    /// The clients' serial device (`/dev/pts/N`).
    pub path: String,
    /// Counters.
    pub stats: Arc<Stats>,
    /// Set to end the bridge.
    pub stop: Arc<AtomicBool>,
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn make_raw(fd: impl AsFd, what: &str) -> Result {
    let mut t = tcgetattr(&fd).map_err(|e| format!("{what}: tcgetattr: {e}"))?;
    cfmakeraw(&mut t);
    tcsetattr(&fd, SetArg::TCSANOW, &t).map_err(|e| format!("{what}: tcsetattr: {e}"))
}

fn open_tty(path: &str) -> Result<OwnedFd> {
    open(
        path,
        OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK,
        Mode::empty(),
    )
    .map_err(|e| format!("{path}: {e}"))
}

/// Bridges QEMU's pty at `qemu_pty` to a new pty for clients.
pub fn start(qemu_pty: &str) -> Result<Bridge> {
    start_quiet(qemu_pty, Duration::from_millis(QUIET_MS))
}

/// [`start`] with `quiet` in place of [`QUIET_MS`] (the tests' device answers at once).
fn start_quiet(qemu_pty: &str, quiet: Duration) -> Result<Bridge> {
    let qemu = open_tty(qemu_pty)?;
    make_raw(&qemu, qemu_pty)?;
    let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK)
        .map_err(|e| format!("posix_openpt: {e}"))?;
    grantpt(&master).map_err(|e| format!("grantpt: {e}"))?;
    unlockpt(&master).map_err(|e| format!("unlockpt: {e}"))?;
    let path = ptsname_r(&master).map_err(|e| format!("ptsname: {e}"))?;
    {
        // Raw from the start, for clients that do not set it; kept while the master is open.
        let slave = open_tty(&path)?;
        make_raw(&slave, &path)?;
    }
    let stats = Arc::new(Stats::default());
    let stop = Arc::new(AtomicBool::new(false));
    let (s, st, p) = (stats.clone(), stop.clone(), path.clone());
    std::thread::spawn(move || run(qemu, master, &p, &s, &st, quiet));
    Ok(Bridge { path, stats, stop })
}

/// `true` if a client has the pty's far end open (the master shows no hang-up).
fn client_connected(master: &PtyMaster) -> bool {
    let mut fds = [PollFd::new(master.as_fd(), PollFlags::empty())];
    match poll(&mut fds, PollTimeout::ZERO) {
        Ok(_) => !fds[0]
            .revents()
            .is_some_and(|r| r.contains(PollFlags::POLLHUP)),
        Err(_) => false,
    }
}

/// Drops what the last client left unread in its port's input queue.
fn flush_unread(path: &str) -> u64 {
    let Ok(slave) = open_tty(path) else { return 0 };
    let mut n = 0u64;
    let mut buf = [0u8; 4096];
    while let Ok(k) = read(&slave, &mut buf) {
        if k == 0 {
            break;
        }
        n += k as u64;
    }
    // The input queue only: flushing the output too would drop what a next client, already
    // open, has written (on a pty, the slave's output queue is the master's input).
    let _ = tcflush(&slave, FlushArg::TCIFLUSH);
    n
}

fn run(
    qemu: OwnedFd,
    master: PtyMaster,
    path: &str,
    stats: &Stats,
    stop: &AtomicBool,
    quiet: Duration,
) {
    let add = |c: &AtomicU64, n: usize| {
        c.fetch_add(n as u64, Ordering::Relaxed);
    };
    let mut to_qemu: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    let mut connected = false;
    // Set when a client leaves: the last time QEMU was heard since (or the leaving).
    let mut quarantine: Option<Instant> = None;
    while !stop.load(Ordering::Relaxed) {
        stats.passes.fetch_add(1, Ordering::Relaxed);
        let now_connected = client_connected(&master);
        if connected && !now_connected {
            stats.sessions.fetch_add(1, Ordering::Relaxed);
            stats
                .flushed_on_close
                .fetch_add(flush_unread(path), Ordering::Relaxed);
            // A request left half-sent (or held back, see below) by the client that left is
            // not the next one's.
            add(&stats.dropped_from_gone, to_qemu.len());
            to_qemu.clear();
            quarantine = Some(Instant::now());
        }
        connected = now_connected;
        if !connected {
            // Bytes a client wrote and closed on before they were read (open, write and close
            // can all fall between two polls): its request, not the next client's. Unless a
            // client is there once they are read: then the next client opened and wrote since
            // the poll above, and they are its request (dropping them lost one request in a
            // few hundred of back-to-back clients).
            while let Ok(n) = read(&master, &mut buf) {
                if n == 0 {
                    break;
                }
                if client_connected(&master) {
                    let room = TO_QEMU_MAX.saturating_sub(to_qemu.len()).min(n);
                    to_qemu.extend_from_slice(&buf[..room]);
                    add(&stats.dropped_to_qemu, n - room);
                } else {
                    add(&stats.dropped_from_gone, n);
                }
            }
        }
        if quarantine.is_some_and(|heard| heard.elapsed() >= quiet) {
            quarantine = None;
        }
        // Wait for QEMU's bytes (and the client's, if one is connected), at most 2 ms.
        let mut fds = vec![PollFd::new(qemu.as_fd(), PollFlags::POLLIN)];
        if connected {
            fds.push(PollFd::new(master.as_fd(), PollFlags::POLLIN));
        }
        let timeout = PollTimeout::from(2u8);
        if poll(&mut fds, timeout).is_err() {
            std::thread::sleep(Duration::from_millis(2));
            continue;
        }
        let ready = |i: usize| {
            fds.get(i)
                .and_then(PollFd::revents)
                .is_some_and(|r| r.intersects(PollFlags::POLLIN | PollFlags::POLLHUP))
        };
        let (qemu_ready, client_ready) = (ready(0), ready(1));
        drop(fds);
        if client_ready {
            if let Ok(n) = read(&master, &mut buf) {
                let room = TO_QEMU_MAX.saturating_sub(to_qemu.len()).min(n);
                to_qemu.extend_from_slice(&buf[..room]);
                add(&stats.dropped_to_qemu, n - room);
            }
        }
        if !to_qemu.is_empty() && quarantine.is_none() {
            if let Ok(n) = write(&qemu, &to_qemu) {
                add(&stats.to_qemu, n);
                to_qemu.drain(..n);
            }
        }
        if qemu_ready {
            match read(&qemu, &mut buf) {
                Ok(0) => return,
                Ok(n) if quarantine.is_some() => {
                    add(&stats.dropped_after_close, n);
                    quarantine = Some(Instant::now());
                }
                Ok(n) if connected => {
                    let sent = write(&master, &buf[..n]).unwrap_or(0);
                    add(&stats.to_client, sent);
                    add(&stats.dropped_not_read, n - sent);
                }
                Ok(n) => add(&stats.dropped_no_client, n),
                Err(nix::errno::Errno::EAGAIN | nix::errno::Errno::EINTR) => {}
                Err(e) => {
                    // QEMU closed its side (it exited): nothing left to bridge.
                    eprintln!("SCADA line: QEMU's pty: {e}; the bridge stops");
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::line::Port;

    /// A stand-in for QEMU's pty: a pty of the test's own whose far end the bridge opens, and
    /// a thread that echoes every byte back, as a controller answers a request.
    fn echo_device() -> (String, Arc<AtomicBool>) {
        let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY).unwrap();
        grantpt(&master).unwrap();
        unlockpt(&master).unwrap();
        let path = ptsname_r(&master).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 512];
            while !s.load(Ordering::Relaxed) {
                let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
                if poll(&mut fds, PollTimeout::from(10u8)).unwrap_or(0) > 0 {
                    if let Ok(n) = read(&master, &mut buf) {
                        let _ = write(&master, &buf[..n]);
                    }
                }
            }
        });
        (path, stop)
    }

    /// Clients that open the port, send, read their answer and close, one right after the
    /// other (as mbpoll does, and as `cargo xtask test`'s line checks do): every request
    /// reaches the device and every answer its client. A regression: a client that opened
    /// and wrote while the bridge was noticing the last one's close had its request dropped
    /// as the leaver's, or flushed with its port's queues (the line checks then saw "no
    /// answer to a read of the sample counter", twice in CI).
    #[test]
    fn back_to_back_clients_each_get_their_answer() {
        let (device, stop) = echo_device();
        let bridge = start_quiet(&device, Duration::from_millis(2)).unwrap();
        // A busy host, as in CI (the misses come when the bridge is preempted).
        for _ in 0..2 {
            let s = stop.clone();
            std::thread::spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    std::hint::spin_loop();
                }
            });
        }
        let mut lost = Vec::new();
        // Before the fix, 8 000 such clients lost 48 requests once (2 cores, both busy); runs
        // of 3 000 lost 0 to 4 (the test failed two runs of three, and a review's run lost 1).
        const N: u16 = 3000;
        for i in 0..N {
            // The next client comes 0 to 96 µs after the last one left: the close seen by the
            // bridge before, during or after the next one's open and write.
            std::thread::sleep(Duration::from_micros(u64::from(i % 97)));
            let port = Port::open(&bridge.path).unwrap();
            let [a, b] = i.to_be_bytes();
            let request = [1, 4, 0, a, b, 1, 0, 0xA5];
            port.send(&request).unwrap();
            let answer = port.recv(request.len(), Duration::from_secs(1));
            if answer != request {
                lost.push((i, answer));
            }
        }
        stop.store(true, Ordering::Relaxed);
        assert!(
            lost.is_empty(),
            "{} of {N} clients got no echo: {lost:02x?}; {}",
            lost.len(),
            bridge.stats.summary()
        );
    }
}
