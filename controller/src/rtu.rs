//! Modbus RTU framing by silence: bytes that arrive without a gap of
//! [`RtuFramer::idle_ms`] form one frame.
//!
//! The spec's gap is 3.5 character times (1.82 ms at 19 200 baud); the framer counts whole
//! milliseconds, so a board sets `idle_ms` to the next millisecond above that, plus one for the
//! tick's resolution. QEMU marks no silence on its serial ports (bytes arrive as the guest reads
//! them), so the virtual bench uses a longer gap (see the firmware). A frame longer than
//! [`MAX_FRAME`] bytes is dropped whole: its end is still waited for, and no part of it is
//! handed on.

pub use crate::vfd::Frame;

/// Collects bytes into frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtuFramer {
    buf: Frame,
    overflow: bool,
    last_ms: u32,
    idle_ms: u32,
}

impl RtuFramer {
    /// A framer that ends a frame after `idle_ms` (≥ 1) ms without a byte.
    pub const fn new(idle_ms: u32) -> Self {
        Self {
            buf: Frame::new(),
            overflow: false,
            last_ms: 0,
            idle_ms: if idle_ms == 0 { 1 } else { idle_ms },
        }
    }

    /// The silence that ends a frame, ms.
    pub fn idle_ms(&self) -> u32 {
        self.idle_ms
    }

    /// Takes one received byte at time `now_ms`.
    pub fn push(&mut self, byte: u8, now_ms: u32) {
        if self.buf.push(byte).is_err() {
            self.overflow = true;
        }
        self.last_ms = now_ms;
    }

    /// `true` while bytes of an unfinished frame are held.
    pub fn busy(&self) -> bool {
        !self.buf.is_empty() || self.overflow
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
            core::mem::swap(out, &mut self.buf);
        }
        self.buf.clear();
        complete
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn time_wraps() {
        let mut f = RtuFramer::new(2);
        let mut out = Frame::new();
        f.push(1, u32::MAX);
        assert!(!f.poll(0, &mut out));
        assert!(f.poll(1, &mut out));
    }
}
