//! The SCADA line under hostile clients (regressions of a hostile run): traffic must not slow
//! the loop, a client that stops reading must not stop the controller, an answer nobody read
//! must not reach the next client, and noise or back-to-back requests must be taken at the
//! rate QEMU allows. Also the raw client port the flood uses.

use crate::bridge::Bridge;
use crate::util::Result;
use controller::modbus::crc16;
use nix::fcntl::{open, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::stat::Mode;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use nix::unistd::{read, write};
use std::os::fd::{AsFd, OwnedFd};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// A raw client port.
pub struct Port(OwnedFd);

/// An RTU frame: `body` (unit, function, data) and its CRC.
pub fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

impl Port {
    /// The client side of the line at `path`, raw and non-blocking.
    pub fn open(path: &str) -> Result<Self> {
        let fd = open(
            path,
            OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK,
            Mode::empty(),
        )
        .map_err(|e| format!("{path}: {e}"))?;
        let mut t = tcgetattr(&fd).map_err(|e| e.to_string())?;
        cfmakeraw(&mut t);
        tcsetattr(&fd, SetArg::TCSANOW, &t).map_err(|e| e.to_string())?;
        Ok(Self(fd))
    }

    /// Writes all of `bytes` (the port is non-blocking: waits while it is full).
    pub fn send(&self, mut bytes: &[u8]) -> Result {
        let end = Instant::now() + Duration::from_secs(5);
        while !bytes.is_empty() {
            match write(&self.0, bytes) {
                Ok(n) => bytes = &bytes[n..],
                Err(nix::errno::Errno::EAGAIN) if Instant::now() < end => {
                    std::thread::sleep(Duration::from_millis(1))
                }
                Err(e) => return Err(format!("client write: {e}")),
            }
        }
        Ok(())
    }

    /// Up to `n` bytes received within `timeout`.
    pub fn recv(&self, n: usize, timeout: Duration) -> Vec<u8> {
        let end = Instant::now() + timeout;
        let mut got = Vec::new();
        let mut buf = [0u8; 512];
        while got.len() < n {
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            let ms = left.as_millis().clamp(1, 1000) as u16;
            let mut fds = [PollFd::new(self.0.as_fd(), PollFlags::POLLIN)];
            if poll(&mut fds, PollTimeout::from(ms)).unwrap_or(0) > 0 {
                if let Ok(k) = read(&self.0, &mut buf) {
                    got.extend_from_slice(&buf[..k]);
                }
            }
        }
        got
    }

    /// Input registers `start..start + count` (FC 04), or `None` without a valid answer
    /// within `timeout`.
    pub fn inputs(&self, start: u16, count: u16, timeout: Duration) -> Result<Option<Vec<u16>>> {
        let n = 5 + 2 * usize::from(count);
        let ans = self.inputs_raw(start, count, timeout)?;
        Ok(inputs_answer(&ans, count).then(|| {
            ans[3..n - 2]
                .chunks(2)
                .map(|w| u16::from_be_bytes([w[0], w[1]]))
                .collect()
        }))
    }

    /// A read of input registers `start..start + count` (FC 04) sent, and the bytes back
    /// within `timeout` (up to the answer's length), as they came.
    pub fn inputs_raw(&self, start: u16, count: u16, timeout: Duration) -> Result<Vec<u8>> {
        let [a, b] = start.to_be_bytes();
        self.send(&frame(&[1, 4, a, b, 0, count as u8]))?;
        Ok(self.recv(5 + 2 * usize::from(count), timeout))
    }

    /// The sample counter (input 9: +1 per 50 ms pressure sample).
    pub fn samples(&self, when: &str) -> Result<u16> {
        self.inputs(9, 1, Duration::from_secs(1))?
            .map(|r| r[0])
            .ok_or_else(|| format!("no answer to a read of the sample counter ({when})"))
    }
}

/// `true` if `ans` is exactly a valid answer of unit 1 to a read of `count` input registers.
pub fn inputs_answer(ans: &[u8], count: u16) -> bool {
    let n = 5 + 2 * usize::from(count);
    ans.len() == n
        && ans[..3] == [1, 4, 2 * count as u8]
        && crc16(&ans[..n - 2]).to_le_bytes() == ans[n - 2..]
}

/// The loop's rate against the wall clock, a fraction (0: on time): the sample counter went
/// from `s0` to `s1` (+1 per 50 ms sample, wrapping) in `wall` s.
pub fn loop_rate(s0: u16, s1: u16, wall: f64) -> f64 {
    f64::from(s1.wrapping_sub(s0)) / (wall * 20.0) - 1.0
}

/// Whether `both` is the two answers to a read of `inputs` input registers (FC 04) then of 3
/// holding registers (FC 03), sent in one write: both whole, in order, their CRCs right.
pub fn two_answers(both: &[u8], inputs: u8) -> bool {
    let n = 5 + 2 * usize::from(inputs);
    both.len() == n + 11 && inputs_answer(&both[..n], inputs.into()) && three_holding(&both[n..])
}

/// Whether `answer` is exactly the answer to a read of 3 holding registers (FC 03) of unit
/// 1: 11 bytes, its CRC right.
fn three_holding(answer: &[u8]) -> bool {
    answer.len() == 11
        && answer[..3] == [1, 3, 6]
        && crc16(&answer[..9]).to_le_bytes() == answer[9..]
}

/// The line's checks on the SCADA pty `pty` (through `bridge`), the controller running:
/// appended to `report`.
pub fn checks(pty: &str, bridge: &Bridge, report: &mut String) -> Result {
    // 1. Traffic does not slow the loop: 50 reads a second for 10 s, sample counter
    //    (20 per second) against wall time.
    let port = Port::open(pty)?;
    let (s0, t0) = (port.samples("before 10 s of reads")?, Instant::now());
    let mut reads = 0;
    while t0.elapsed() < Duration::from_secs(10) {
        let t = Instant::now();
        port.inputs(0, 18, Duration::from_secs(1))?
            .ok_or("a read under traffic got no answer")?;
        reads += 1;
        std::thread::sleep(Duration::from_millis(20).saturating_sub(t.elapsed()));
    }
    let (s1, wall) = (
        port.samples("after 10 s of reads")?,
        t0.elapsed().as_secs_f64(),
    );
    let rate = loop_rate(s0, s1, wall);
    report.push_str(&format!(
        "{reads} reads in {wall:.1} s ({:.0}/s): loop at {:+.2} % of wall time (sample counter)\n",
        f64::from(reads) / wall,
        rate * 100.0
    ));
    if rate.abs() > 0.01 {
        return Err(format!(
            "the loop's rate depends on traffic: {:+.2} % of wall time (limit ±1 %)\n{report}",
            rate * 100.0
        ));
    }
    // 2. Noise is taken fast: 2000 bytes, then a read is answered within 1 s.
    port.send(&[0x55; 2000])?;
    let t = Instant::now();
    std::thread::sleep(Duration::from_millis(20));
    port.inputs(17, 1, Duration::from_secs(1))?
        .ok_or("no answer within 1 s to a read after 2000 bytes of noise")?;
    report.push_str(&format!(
        "2000 bytes of noise, then a read: answered {} ms after the noise\n",
        t.elapsed().as_millis()
    ));
    // 3. Back-to-back writes, one every 10 ms (no 10 ms silence ever): all answered.
    let mut answered = 0;
    let t = Instant::now();
    for i in 0..100u16 {
        let next = t + Duration::from_millis(10 * u64::from(i));
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        let [a, b] = (i * 50).to_be_bytes();
        let w = frame(&[1, 6, 0, 0, a, b]);
        port.send(&w)?;
        answered += usize::from(port.recv(8, Duration::from_millis(500)) == w);
    }
    report.push_str(&format!(
        "100 setpoint writes, one every 10 ms: {answered} answered in {:.2} s\n",
        t.elapsed().as_secs_f64()
    ));
    if answered != 100 {
        return Err(format!(
            "only {answered} of 100 back-to-back writes answered"
        ));
    }
    // Two requests in one write (no gap at all): both answered, in order.
    let (a, b) = (frame(&[1, 4, 0, 17, 0, 1]), frame(&[1, 3, 0, 0, 0, 3]));
    port.send(&[a, b].concat())?;
    let both = port.recv(7 + 11, Duration::from_secs(1));
    let ok = two_answers(&both, 1);
    if !ok {
        return Err(format!("two requests in one write: got {both:02x?}"));
    }
    report.push_str("two requests in one write: both answered, in order\n");
    // A request torn by a 100 ms pause (a busy host holds QEMU's bytes up so; 10 × the
    // silence that drops noise): answered.
    let torn = frame(&[1, 3, 0, 0, 0, 3]);
    port.send(&torn[..3])?;
    std::thread::sleep(Duration::from_millis(100));
    port.send(&torn[3..])?;
    let back = port.recv(11, Duration::from_secs(1));
    if !three_holding(&back) {
        return Err(format!("a request torn by a 100 ms pause: got {back:02x?}"));
    }
    report.push_str("a request torn by a 100 ms pause: answered\n");
    // The start of a long write that never comes whole (a write's first 7 bytes claiming
    // 209), a pause, then a read: the read is answered, not taken for the write's data.
    port.send(&[1, 16, 0, 0, 0, 100, 200])?;
    std::thread::sleep(Duration::from_millis(100));
    port.inputs(17, 1, Duration::from_secs(1))?
        .ok_or("no answer within 1 s to a read after the start of a write that never came whole")?;
    report.push_str("the start of a write that never came whole, 100 ms, a read: answered\n");
    drop(port);
    // 4. A client that sends and never reads (answers pile up: 25 KB in 12 s) does not
    //    stop the controller.
    let s0 = Port::open(pty)?.samples("before a client that reads nothing")?;
    let t = Instant::now();
    let flood = Port::open(pty)?;
    let mut sent = 0;
    while t.elapsed() < Duration::from_secs(12) {
        flood.send(&frame(&[1, 4, 0, 0, 0, 18]))?;
        sent += 1;
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(flood);
    std::thread::sleep(Duration::from_millis(100));
    let after = Port::open(pty)?;
    let s1 = after.samples("after a client that read nothing")?;
    let wall = t.elapsed().as_secs_f64();
    let rate = loop_rate(s0, s1, wall);
    report.push_str(&format!(
        "a client sent {sent} reads in 12 s and read none: the loop ran on at {:+.2} % of wall time; {}\n",
        rate * 100.0,
        bridge.stats.summary()
    ));
    if rate.abs() > 0.02 {
        return Err(format!(
            "the controller stalled under a client that does not read:\n{report}"
        ));
    }
    drop(after);
    // 5. An answer nobody read does not reach the next client: a read of input 17 sent,
    //    its client closes unread, then a read of another shape gets its own answer. Each
    //    client closes once the bridge's counters show its request sent on to the
    //    controller (its answer comes before the bridge sees the close, then flushed, or
    //    after: dropped, the bridge holding the line for QUIET_MS; the controller answers
    //    in ≈ 1 ms, so mostly before), or once its answer is in the client's queue
    //    (flushed at the close); a request held back by the last close's quarantine waits
    //    in the bridge meanwhile. The bridge keeps its promise for a close it has seen (a
    //    close and an open within one pass of its loop look like one client to a pty: see
    //    `bridge`), so the next client opens once the bridge has begun two passes since
    //    the close, and 20 ms later.
    let counted = |c: &AtomicU64| c.load(Ordering::Relaxed);
    let st = &bridge.stats;
    let wait_for = |what: &str, done: &dyn Fn() -> bool| -> Result {
        let t = Instant::now();
        while !done() {
            if t.elapsed() > Duration::from_secs(2) {
                return Err(format!("{what}: not within 2 s\n{}", st.summary()));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    };
    let unread = || counted(&st.flushed_on_close) + st.dropped_from_qemu();
    let (flushed0, dropped0) = (counted(&st.flushed_on_close), st.dropped_from_qemu());
    for i in 0..4 {
        let gone = Port::open(pty)?;
        let (q0, c0, unread0) = (counted(&st.to_qemu), counted(&st.to_client), unread());
        gone.send(&frame(&[1, 4, 0, 17, 0, 1]))?;
        if i % 2 == 0 {
            wait_for("a request sent on to the controller", &|| {
                counted(&st.to_qemu) >= q0 + 8
            })?;
        } else {
            wait_for("an answer in the client's queue", &|| {
                counted(&st.to_client) >= c0 + 7
            })?;
        }
        drop(gone);
        let p0 = counted(&st.passes);
        wait_for("the bridge's loop seeing a close", &|| {
            counted(&st.passes) >= p0 + 2
        })?;
        std::thread::sleep(Duration::from_millis(20));
        let next = Port::open(pty)?;
        let got = next.inputs_raw(0, 18, Duration::from_secs(1))?;
        if !inputs_answer(&got, 18) {
            // The stale answer (7 bytes: 01 04 02 ..) ahead of this one spoils its header
            // and CRC; no bytes at all is another failure: both are told apart here.
            return Err(format!(
                "after an unread answer, the next client's read of 18 inputs got {} B, {}: {got:02x?}\n{}",
                got.len(),
                if got.starts_with(&[1, 4, 2]) {
                    "starting with the stale answer's header"
                } else {
                    "not its own answer"
                },
                st.summary()
            ));
        }
        // The stale answer came before this one (the controller answers in order): it was
        // flushed or dropped, or the check above saw it.
        if unread() < unread0 + 7 {
            return Err(format!(
                "an answer left unread: the bridge counted {} B flushed or dropped, not its 7\n{}",
                unread() - unread0,
                st.summary()
            ));
        }
    }
    report.push_str(&format!(
        "an answer left unread by a client that closed: not seen by the next client (4 of 4; \
         the bridge flushed {} B left in the clients' queues and dropped {} B that came after \
         their close)\n",
        counted(&st.flushed_on_close) - flushed0,
        st.dropped_from_qemu() - dropped0,
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames() {
        // Unit 1, FC 04, start 0, count 1: CRC-16/MODBUS 0xCA31, sent low byte first.
        assert_eq!(frame(&[1, 4, 0, 0, 0, 1]), [1, 4, 0, 0, 0, 1, 0x31, 0xCA]);
        let f = frame(&[1, 6, 0, 0, 0x13, 0x88]);
        assert_eq!(f.len(), 8);
        assert_eq!(crc16(&f[..6]).to_le_bytes(), [f[6], f[7]]);
        // A frame with its CRC checks to 0 (the CRC's residue).
        assert_eq!(crc16(&f), 0);
    }

    #[test]
    fn rates() {
        assert_eq!(loop_rate(100, 300, 10.0), 0.0);
        assert!((loop_rate(0, 202, 10.0) - 0.01).abs() < 1e-12);
        assert!((loop_rate(0, 198, 10.0) + 0.01).abs() < 1e-12);
        // The counter wraps.
        assert_eq!(loop_rate(u16::MAX - 99, 100, 10.0), 0.0);
    }

    #[test]
    fn two_answers_in_one() {
        let answer = |mut body: Vec<u8>| {
            body.extend_from_slice(&crc16(&body).to_le_bytes());
            body
        };
        let a = answer(vec![1, 4, 2, 0x12, 0x34]);
        let b = answer(vec![1, 3, 6, 0, 1, 0, 2, 0, 3]);
        let both = [a.clone(), b.clone()].concat();
        assert!(two_answers(&both, 1));
        assert!(!two_answers(&both, 18));
        assert!(!two_answers(&[b.clone(), a.clone()].concat(), 1));
        assert!(!two_answers(&both[..both.len() - 1], 1));
        let mut bad = both.clone();
        bad[3] ^= 1;
        assert!(!two_answers(&bad, 1));
        let mut bad = both.clone();
        bad[12] ^= 0x80;
        assert!(!two_answers(&bad, 1));
        let long = answer([vec![1, 4, 36], vec![7; 36]].concat());
        assert!(two_answers(&[long, b].concat(), 18));
    }
}
