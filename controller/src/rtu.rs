//! Modbus RTU framing by silence: bytes that arrive without a gap of
//! [`RtuFramer::idle_ms`] form one frame.
//!
//! The spec's gap is 3.5 character times (1.82 ms at 19 200 baud); the framer counts whole
//! milliseconds, so a board sets `idle_ms` to the next millisecond above that, plus one for the
//! tick's resolution. QEMU marks no silence on its serial ports (bytes arrive as the guest reads
//! them), so the virtual bench uses a longer gap (see the firmware). A frame longer than
//! [`MAX_FRAME`](crate::modbus::MAX_FRAME) bytes is dropped whole: its end is still waited for, and no part of it is
//! handed on.

use crate::modbus::Frame;

/// Bytes an [`RtuFramer`] holds: the longest frame.
const HOLD: usize = crate::modbus::MAX_FRAME;

/// Collects bytes into frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtuFramer {
    /// The last bytes received, a ring kept twice (byte k at `k` and `k + HOLD`), so that
    /// they are one slice wherever the ring starts and dropping the oldest byte moves nothing
    /// (no `memmove`, which cost 1.5 KB of flash for this one use).
    ring: [u8; 2 * HOLD],
    start: usize,
    len: usize,
    overflow: bool,
    last_ms: u32,
    idle_ms: u32,
}

impl RtuFramer {
    /// A framer that ends a frame after `idle_ms` (≥ 1) ms without a byte.
    pub const fn new(idle_ms: u32) -> Self {
        Self {
            ring: [0; 2 * HOLD],
            start: 0,
            len: 0,
            overflow: false,
            last_ms: 0,
            idle_ms: if idle_ms == 0 { 1 } else { idle_ms },
        }
    }

    /// The silence that ends a frame, ms.
    pub fn idle_ms(&self) -> u32 {
        self.idle_ms
    }

    /// The bytes held, oldest first.
    fn held(&self) -> &[u8] {
        self.ring
            .get(self.start..self.start + self.len)
            .unwrap_or_default()
    }

    /// Forgets the bytes held.
    fn clear(&mut self) {
        self.start = 0;
        self.len = 0;
    }

    /// Takes one received byte at time `now_ms`. Past [`MAX_FRAME`](crate::modbus::MAX_FRAME)
    /// bytes the frame is too long (it will be dropped at the silence); the last bytes are
    /// kept, so that [`Self::take_if`] can still find a whole frame at their end.
    pub fn push(&mut self, byte: u8, now_ms: u32) {
        if self.len == HOLD {
            self.overflow = true;
            self.start = (self.start + 1) % HOLD;
            self.len -= 1;
        }
        let at = (self.start + self.len) % HOLD;
        self.ring[at] = byte;
        self.ring[at + HOLD] = byte;
        self.len += 1;
        self.last_ms = now_ms;
    }

    /// `true` while bytes of an unfinished frame are held.
    pub fn busy(&self) -> bool {
        self.len > 0 || self.overflow
    }

    /// A whole frame at the end of the bytes held, found by its content: `find` gives where
    /// it starts (e.g. [`crate::modbus::request_at_end`]: a request whose length its function
    /// fixes, with a valid CRC). It is moved into `out` and whatever came before it (noise) is
    /// dropped, without waiting for the silence. `false` otherwise (bytes kept).
    pub fn take_if(&mut self, out: &mut Frame, find: impl Fn(&[u8]) -> Option<usize>) -> bool {
        let held = self.held();
        let Some(frame) = find(held).and_then(|start| held.get(start..)) else {
            return false;
        };
        out.clear();
        // Cannot fail: `out` holds HOLD bytes.
        let _ = out.extend_from_slice(frame);
        self.clear();
        self.overflow = false;
        true
    }

    /// Once the line has been silent for `idle_ms`, the complete frame (moved into `out`);
    /// `false` if no frame is complete, or the frame was too long (dropped).
    pub fn poll(&mut self, now_ms: u32, out: &mut Frame) -> bool {
        if !self.busy() || now_ms.wrapping_sub(self.last_ms) < self.idle_ms {
            return false;
        }
        let complete = !self.overflow;
        self.overflow = false;
        if complete {
            out.clear();
            // Cannot fail: `out` holds HOLD bytes.
            let _ = out.extend_from_slice(self.held());
        }
        self.clear();
        complete
    }
}

/// A byte-wide serial port, polled (a board's USART, RS-485 transceiver included).
pub trait Uart {
    /// A received byte, if one is waiting.
    fn try_read(&mut self) -> Option<u8>;
    /// Queues `byte` for sending; `false` if the transmitter is busy (try again).
    fn try_write(&mut self, byte: u8) -> bool;
    /// `true` once the last byte has left the shift register (USART TC).
    fn tx_complete(&mut self) -> bool;
    /// Drives the RS-485 transceiver (`true` while sending); nothing for a plain UART.
    fn set_driver(&mut self, _on: bool) {}
    /// `true` if the port hears its own transmission (a half-duplex RS-485 transceiver with
    /// its receiver on): bytes received while sending are then dropped as the echo. `false`
    /// for a full-duplex port (QEMU's), where they are the peer's next request.
    fn echoes(&self) -> bool {
        true
    }
}

/// A half-duplex RTU port: frames in by silence ([`RtuFramer`]), one frame out at a time,
/// the RS-485 driver enabled from the first byte to the end of the last. Bytes received while
/// sending (the transceiver's echo) are dropped. Call [`RtuPort::poll`] as often as the loop
/// can (at least once per character time on a real line).
#[derive(Debug)]
pub struct RtuPort<U> {
    uart: U,
    framer: RtuFramer,
    tx: Frame,
    sent: usize,
    sending: bool,
}

impl<U: Uart> RtuPort<U> {
    /// A port on `uart`, frames ended by `idle_ms` of silence.
    pub fn new(uart: U, idle_ms: u32) -> Self {
        Self {
            uart,
            framer: RtuFramer::new(idle_ms),
            tx: Frame::new(),
            sent: 0,
            sending: false,
        }
    }

    /// The UART.
    pub fn uart(&mut self) -> &mut U {
        &mut self.uart
    }

    /// `true` while a frame is being sent.
    pub fn sending(&self) -> bool {
        self.sending
    }

    /// Starts sending `frame` (dropped if one is still going out; a master waits for its
    /// answer, a slave answers one request at a time, so that does not happen in use).
    pub fn send(&mut self, frame: &[u8]) -> bool {
        if self.sending || frame.is_empty() {
            return false;
        }
        self.tx.clear();
        if self.tx.extend_from_slice(frame).is_err() {
            return false;
        }
        self.sent = 0;
        self.sending = true;
        self.uart.set_driver(true);
        true
    }

    /// Moves bytes: received ones into the framer (stamped `now_ms`), queued ones out; drops
    /// the driver once the last byte is out.
    pub fn poll(&mut self, now_ms: u32) {
        let echo = self.sending && self.uart.echoes();
        while let Some(b) = self.uart.try_read() {
            if !echo {
                self.framer.push(b, now_ms);
            }
        }
        if self.sending {
            while self.sent < self.tx.len() && self.uart.try_write(self.tx[self.sent]) {
                self.sent += 1;
            }
            if self.sent == self.tx.len() && self.uart.tx_complete() {
                self.sending = false;
                self.uart.set_driver(false);
            }
        }
    }

    /// A complete received frame, if the line has been silent long enough.
    pub fn receive(&mut self, now_ms: u32, out: &mut Frame) -> bool {
        self.poll(now_ms);
        self.framer.poll(now_ms, out)
    }

    /// As [`Self::receive`], and also a frame that `find` sees whole at the end of the bytes
    /// before the silence (see [`RtuFramer::take_if`]; the SCADA slave uses
    /// [`crate::modbus::request_at_end`]). On a line that marks no silence (QEMU), this is
    /// what lets back-to-back requests, and a request right after noise, be answered. Bytes
    /// are checked one at a time, so a whole request is found as its last byte arrives.
    pub fn receive_complete(
        &mut self,
        now_ms: u32,
        out: &mut Frame,
        find: impl Fn(&[u8]) -> Option<usize>,
    ) -> bool {
        while !self.sending || !self.uart.echoes() {
            let Some(b) = self.uart.try_read() else { break };
            self.framer.push(b, now_ms);
            if self.framer.take_if(out, &find) {
                return true;
            }
        }
        // Bytes [`Self::poll`] took since the last call have not been looked at yet.
        self.poll(now_ms);
        self.framer.take_if(out, &find) || self.framer.poll(now_ms, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UART whose transmitter takes one byte per poll and echoes it (RS-485).
    #[derive(Default)]
    struct Loopback {
        rx: std::collections::VecDeque<u8>,
        wire: Vec<u8>,
        busy: bool,
        driver: Vec<bool>,
    }

    impl Uart for Loopback {
        fn try_read(&mut self) -> Option<u8> {
            self.rx.pop_front()
        }
        fn try_write(&mut self, b: u8) -> bool {
            if std::mem::take(&mut self.busy) {
                return false;
            }
            self.busy = true;
            self.wire.push(b);
            self.rx.push_back(b);
            true
        }
        fn tx_complete(&mut self) -> bool {
            !std::mem::take(&mut self.busy)
        }
        fn set_driver(&mut self, on: bool) {
            self.driver.push(on);
        }
    }

    #[test]
    fn port_sends_half_duplex_and_frames_what_comes_back() {
        let mut p = RtuPort::new(Loopback::default(), 2);
        let mut out = Frame::new();
        assert!(p.send(&[1, 2, 3]));
        assert!(!p.send(&[9]), "one frame at a time");
        let mut t = 0;
        while p.sending() {
            p.poll(t);
            t += 1;
            assert!(t < 20);
        }
        assert_eq!(p.uart().wire, [1, 2, 3]);
        assert_eq!(p.uart().driver, [true, false]);
        assert!(!p.receive(t + 5, &mut out), "its own echo is not a frame");
        p.uart().rx.extend([4, 5]);
        assert!(!p.receive(t + 6, &mut out));
        assert!(p.receive(t + 8, &mut out));
        assert_eq!(&out[..], &[4, 5]);
    }

    /// A full-duplex port (no echo) keeps what arrives while it sends: the peer's next request.
    #[test]
    fn a_port_without_echo_keeps_bytes_received_while_sending() {
        struct Duplex(Loopback);
        impl Uart for Duplex {
            fn try_read(&mut self) -> Option<u8> {
                self.0.rx.pop_front()
            }
            fn try_write(&mut self, b: u8) -> bool {
                self.0.wire.push(b);
                true
            }
            fn tx_complete(&mut self) -> bool {
                false
            }
            fn echoes(&self) -> bool {
                false
            }
        }
        let mut p = RtuPort::new(Duplex(Loopback::default()), 2);
        let mut out = Frame::new();
        assert!(p.send(&[1, 2, 3]));
        p.uart().0.rx.extend([7, 8, 9]);
        p.poll(0);
        assert!(p.sending(), "still sending");
        let whole = |b: &[u8]| b.ends_with(&[7, 8, 9]).then(|| b.len() - 3);
        assert!(p.receive_complete(0, &mut out, whole));
        assert_eq!(&out[..], &[7, 8, 9]);
    }

    #[test]
    fn a_gap_ends_a_frame() {
        let mut f = RtuFramer::new(3);
        let mut out = Frame::new();
        for (t, b) in [(0, 1u8), (1, 2), (2, 3)] {
            f.push(b, t);
            assert!(!f.poll(t, &mut out));
        }
        assert!(!f.poll(4, &mut out), "2 ms of silence is not enough");
        assert!(f.poll(5, &mut out));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.poll(9, &mut out), "one frame once");
        f.push(9, 10);
        assert!(f.poll(13, &mut out));
        assert_eq!(&out[..], &[9]);
    }

    #[test]
    fn too_long_frames_are_dropped_and_the_next_one_is_whole() {
        let mut f = RtuFramer::new(2);
        let mut out = Frame::new();
        for i in 0..300u32 {
            f.push(i as u8, 100);
        }
        assert!(!f.poll(102, &mut out));
        assert!(!f.busy());
        f.push(7, 103);
        f.push(8, 103);
        assert!(f.poll(105, &mut out));
        assert_eq!(&out[..], &[7, 8]);
    }

    #[test]
    fn a_frame_complete_by_its_content_needs_no_silence() {
        let mut f = RtuFramer::new(10);
        let mut out = Frame::new();
        // "Whole" here: the last three bytes are 1, 2, 3.
        let find = |b: &[u8]| b.ends_with(&[1, 2, 3]).then(|| b.len() - 3);
        f.push(1, 0);
        f.push(2, 0);
        assert!(!f.take_if(&mut out, find), "not yet whole");
        f.push(3, 0);
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.busy() && !f.poll(100, &mut out), "handed on once");
        // Noise is not whole: it waits for the silence and is handed on there as before.
        for b in [9, 1, 2] {
            f.push(b, 200);
        }
        assert!(!f.take_if(&mut out, find));
        assert!(f.poll(210, &mut out));
        assert_eq!(&out[..], &[9, 1, 2]);
        // A whole frame right after more noise than a frame holds: found, noise dropped.
        for i in 0..1000u32 {
            f.push(0x55 ^ i as u8, 300);
        }
        for b in [1, 2, 3] {
            f.push(b, 300);
        }
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.busy());
    }

    #[test]
    fn a_frame_as_long_as_the_framer_holds_is_found_after_overflowing_noise() {
        let mut f = RtuFramer::new(3);
        let mut out = Frame::new();
        let frame: Vec<u8> = (0..HOLD as u32).map(|i| (i * 7 + 1) as u8).collect();
        let find = |held: &[u8]| held.ends_with(&frame).then(|| held.len() - frame.len());
        for i in 0..777u32 {
            f.push((i * 13) as u8, 5);
        }
        for &b in &frame {
            assert!(!f.take_if(&mut out, find) || out[..] == frame[..]);
            f.push(b, 5);
        }
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &frame[..]);
        assert!(!f.busy());
    }

    #[test]
    fn time_wraps() {
        let mut f = RtuFramer::new(2);
        let mut out = Frame::new();
        f.push(1, u32::MAX);
        assert!(!f.poll(0, &mut out));
        assert!(f.poll(1, &mut out));
    }
}
