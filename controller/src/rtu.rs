//! Modbus RTU on a serial line: frames ended by silence ([`RtuFramer`]) and an RS-485 port on
//! the embedded-hal serial and pin traits, driven from interrupts ([`Rs485`]).
//!
//! The spec's silence between frames is 3.5 character times ([`gap_us`]). A board either
//! stamps each received byte with a microsecond clock and polls the framer
//! ([`RtuFramer::poll`]), or lets a hardware timer mark the silence (a USART's receiver
//! timeout) and ends the frame there ([`RtuFramer::end_frame`]). QEMU marks no silence on its
//! serial ports (bytes arrive as the guest reads them), so the virtual bench also finds whole
//! requests by their content ([`RtuFramer::take_if`] with [`crate::modbus::request_at_end`]).
//! A frame longer than [`MAX_FRAME`] bytes is dropped whole: its end is still waited for, and
//! no part of it is handed on.

use crate::modbus::{Frame, MAX_FRAME};
use embedded_hal::digital::OutputPin;
use embedded_hal_nb::nb;
use embedded_hal_nb::serial::{self, Error as _};

/// Bytes an [`RtuFramer`] holds: the longest frame.
const HOLD: usize = MAX_FRAME;

/// The silence that ends an RTU frame at `baud` bits/s, µs: 3.5 characters of 11 bits
/// (the spec's RTU character: start, 8 data, parity or a second stop bit, stop), rounded up;
/// 1 750 µs at any rate above 19 200 baud (Modbus over serial line V1.02 §2.5.1.1). At
/// 19 200 baud that is 2 006 µs; a line run 8N1 (10-bit characters, outside the spec) has
/// 3.5 characters in 1 823 µs, and a board may set that instead ([`RtuFramer::new`] takes any
/// gap). `baud` 0 gives `u32::MAX` (no silence ends a frame; no panic).
pub const fn gap_us(baud: u32) -> u32 {
    /// 3.5 characters of 11 bits, in bit times × 10⁶.
    const GAP_BITS_E6: u32 = 38_500_000;
    match baud {
        0 => u32::MAX,
        1..=19_200 => GAP_BITS_E6.div_ceil(baud),
        _ => 1_750,
    }
}

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
    /// Where the bytes after a start kept past the gap by [`Self::poll_patient`] begin among
    /// those held (0: none): [`Self::take_if`] looks there too, so that a start that never
    /// grows whole does not hide the frames sent after it.
    resumed: usize,
    last_us: u32,
    gap_us: u32,
}

impl RtuFramer {
    /// A framer that ends a frame after `gap_us` µs (1..=u32::MAX; 0 is taken as 1) without a
    /// byte, e.g. [`gap_us`]`(baud)`.
    pub const fn new(gap_us: u32) -> Self {
        Self {
            ring: [0; 2 * HOLD],
            start: 0,
            len: 0,
            overflow: false,
            resumed: 0,
            last_us: 0,
            gap_us: if gap_us == 0 { 1 } else { gap_us },
        }
    }

    /// The silence that ends a frame, µs (≥ 1).
    pub fn gap_us(&self) -> u32 {
        self.gap_us
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
        self.resumed = 0;
    }

    /// Takes one received byte at time `now_us` (µs, any origin, wrapping). Past
    /// [`MAX_FRAME`] bytes the frame is too long (it will be dropped at the silence); the last
    /// bytes are kept, so that [`Self::take_if`] can still find a whole frame at their end.
    pub fn push(&mut self, byte: u8, now_us: u32) {
        if self.len == HOLD {
            self.overflow = true;
            self.start = (self.start + 1) % HOLD;
            self.len -= 1;
            self.resumed = self.resumed.saturating_sub(1);
        }
        let at = (self.start + self.len) % HOLD;
        self.ring[at] = byte;
        self.ring[at + HOLD] = byte;
        self.len += 1;
        self.last_us = now_us;
    }

    /// `true` while bytes of an unfinished frame are held.
    pub fn busy(&self) -> bool {
        self.len > 0 || self.overflow
    }

    /// A whole frame at the end of the bytes held, found by its content: `find` gives where
    /// it starts (e.g. [`crate::modbus::request_at_end`]: a request whose length its function
    /// fixes, with a valid CRC). It is moved into `out` and whatever came before it (noise) is
    /// dropped, without waiting for the silence. If none is found in all the bytes held, the
    /// bytes after a start that [`Self::poll_patient`] kept past the gap are looked at alone
    /// (the start may claim more bytes than follow it). `false` otherwise (bytes kept).
    pub fn take_if(&mut self, out: &mut Frame, find: impl Fn(&[u8]) -> Option<usize>) -> bool {
        let held = self.held();
        let since = self.resumed;
        let at = find(held).or_else(|| {
            let after = held.get(since..).filter(|_| since > 0)?;
            find(after).map(|start| start + since)
        });
        let Some(frame) = at.and_then(|start| held.get(start..)) else {
            return false;
        };
        out.clear();
        // Cannot fail: `out` holds HOLD bytes.
        let _ = out.extend_from_slice(frame);
        self.clear();
        self.overflow = false;
        true
    }

    /// Once the line has been silent for [`Self::gap_us`] since the last byte (at `now_us`,
    /// the clock of [`Self::push`]), the complete frame (moved into `out`); `false` if no
    /// frame is complete, or the frame was too long (dropped). Call it at least once every
    /// 2³² µs (71 minutes) while a frame is held, or the clock's wrap hides the silence.
    pub fn poll(&mut self, now_us: u32, out: &mut Frame) -> bool {
        if !self.busy() || now_us.wrapping_sub(self.last_us) < self.gap_us {
            return false;
        }
        self.end_frame(out)
    }

    /// As [`Self::poll`], except that bytes held which `may_grow` takes for the start of a
    /// frame not yet whole (e.g. [`crate::modbus::request_may_grow`]) are kept until
    /// `patience_us` µs of silence (taken as at least [`Self::gap_us`]): on a line whose bytes
    /// can be held up longer than the silence inside a frame (QEMU's, behind a busy host), a
    /// torn request is still answered, while bytes that cannot become one are dropped as
    /// soon as by [`Self::poll`]. A start kept so that never grows whole does not hide the
    /// frames sent after the pause: [`Self::take_if`] looks at the bytes since it alone too.
    pub fn poll_patient(
        &mut self,
        now_us: u32,
        out: &mut Frame,
        may_grow: impl Fn(&[u8]) -> bool,
        patience_us: u32,
    ) -> bool {
        let quiet = now_us.wrapping_sub(self.last_us);
        if !self.overflow && quiet < patience_us && may_grow(self.held()) {
            if quiet >= self.gap_us {
                // Kept past the gap: what comes next is looked at alone too.
                self.resumed = self.len;
            }
            return false;
        }
        self.poll(now_us, out)
    }

    /// The silence has been seen (a hardware receiver timeout fired): the frame held, moved
    /// into `out`, whatever the clock says; `false` if no bytes are held or the frame was too
    /// long (dropped).
    pub fn end_frame(&mut self, out: &mut Frame) -> bool {
        if !self.busy() {
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

/// Error counts of an [`Rs485`] port since it was made, each wrapping at 2³².
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Errors {
    /// Receive overruns (bytes lost: the receiver was not read in time).
    pub overrun: u32,
    /// Receive framing errors (no stop bit where one was due).
    pub framing: u32,
    /// Receive parity errors.
    pub parity: u32,
    /// Receive noise errors.
    pub noise: u32,
    /// Other receive errors.
    pub other: u32,
    /// Transmit errors (each ends the frame being sent: see [`Rs485::on_transmit`]).
    pub transmit: u32,
    /// Failed settings of the driver-enable pin.
    pub driver_enable: u32,
}

impl Errors {
    fn count_receive(&mut self, kind: serial::ErrorKind) {
        let n = match kind {
            serial::ErrorKind::Overrun => &mut self.overrun,
            serial::ErrorKind::FrameFormat => &mut self.framing,
            serial::ErrorKind::Parity => &mut self.parity,
            serial::ErrorKind::Noise => &mut self.noise,
            _ => &mut self.other,
        };
        *n = n.wrapping_add(1);
    }
}

/// A driver-enable "pin" for a port without one (a full-duplex line, QEMU's UART): setting it
/// does nothing and never fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoDe;

impl embedded_hal::digital::ErrorType for NoDe {
    type Error = core::convert::Infallible;
}

impl OutputPin for NoDe {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// Reads per [`Rs485::on_receive`] call at most: a receiver that never runs dry (or keeps
/// reporting an error) cannot hold an interrupt handler forever; bytes left are read by the
/// next call (the receive interrupt is still pending).
const READS_PER_CALL: usize = MAX_FRAME;

/// An RTU port on a UART's transmitter `TX` and receiver `RX` and an RS-485 transceiver's
/// driver-enable pin `DE` (high while sending), driven from interrupts: [`Self::on_receive`]
/// from the receive interrupt, [`Self::on_transmit`] from the transmit-empty / transmission
/// complete interrupt (or both from a poll loop). One frame goes out at a time.
///
/// A half-duplex transceiver hears its own transmission: built with [`Self::half_duplex`],
/// the port drops what it receives while sending (the echo). A full-duplex port
/// ([`Self::full_duplex`]: QEMU's UART, RS-422) keeps it: it is the peer's next request.
#[derive(Debug)]
pub struct Rs485<TX, RX, DE> {
    tx: TX,
    rx: RX,
    de: DE,
    echo: bool,
    out: Frame,
    sent: usize,
    sending: bool,
    errors: Errors,
}

impl<TX, RX, DE> Rs485<TX, RX, DE>
where
    TX: serial::Write<u8>,
    RX: serial::Read<u8>,
    DE: OutputPin,
{
    /// A port whose receiver hears its own transmission (a half-duplex RS-485 transceiver
    /// with its receiver always on): bytes received while sending are dropped. DE is set low.
    pub fn half_duplex(tx: TX, rx: RX, de: DE) -> Self {
        Self::new(tx, rx, de, true)
    }

    /// A port that does not hear itself (full duplex): bytes received while sending are kept.
    /// DE is set low (use [`NoDe`] for a line without one).
    pub fn full_duplex(tx: TX, rx: RX, de: DE) -> Self {
        Self::new(tx, rx, de, false)
    }

    fn new(tx: TX, rx: RX, de: DE, echo: bool) -> Self {
        let mut port = Self {
            tx,
            rx,
            de,
            echo,
            out: Frame::new(),
            sent: 0,
            sending: false,
            errors: Errors::default(),
        };
        port.drive(false);
        port
    }

    /// Sets DE. A pin that fails is counted ([`Errors::driver_enable`]) and otherwise
    /// ignored: nothing here can mend it, and the frame still goes out (if DE stays low the
    /// peer hears nothing and its timeout handles it; if it stays high the bus is blocked,
    /// which the board sees in the count).
    fn drive(&mut self, on: bool) {
        let set = if on {
            self.de.set_high()
        } else {
            self.de.set_low()
        };
        if set.is_err() {
            self.errors.driver_enable = self.errors.driver_enable.wrapping_add(1);
        }
    }

    /// Reads every byte waiting in the receiver (up to 256 per call) and hands each to `sink`
    /// (e.g. `|b| framer.push(b, now_us)`), except the echo of a half-duplex port while it
    /// sends. Receive errors are counted by kind ([`Self::errors`]); the byte in error is not
    /// handed on (the frame's CRC then fails).
    pub fn on_receive(&mut self, mut sink: impl FnMut(u8)) {
        let drop_echo = self.sending && self.echo;
        for _ in 0..READS_PER_CALL {
            match self.rx.read() {
                Ok(b) if !drop_echo => sink(b),
                Ok(_) => {}
                Err(nb::Error::WouldBlock) => return,
                Err(nb::Error::Other(e)) => self.errors.count_receive(e.kind()),
            }
        }
    }

    /// Starts sending `frame` (1..=[`MAX_FRAME`] bytes): raises DE and writes the first byte;
    /// [`Self::on_transmit`] writes the rest. `false` (nothing sent, DE untouched) if a frame
    /// is still going out, `frame` is empty or too long, or the first byte could not be
    /// written (a transmit error, counted).
    pub fn send(&mut self, frame: &[u8]) -> bool {
        if self.sending || frame.is_empty() {
            return false;
        }
        self.out.clear();
        if self.out.extend_from_slice(frame).is_err() {
            return false;
        }
        self.sent = 0;
        self.sending = true;
        self.drive(true);
        match self.tx.write(self.out[0]) {
            Ok(()) => self.sent = 1,
            // The transmitter is still busy (its last byte of a previous frame): the first
            // byte goes out from `on_transmit`.
            Err(nb::Error::WouldBlock) => {}
            Err(nb::Error::Other(_)) => {
                self.errors.transmit = self.errors.transmit.wrapping_add(1);
                self.finish();
                return false;
            }
        }
        true
    }

    /// Moves the frame being sent on: writes bytes while the transmitter takes them; once all
    /// are written and the transmitter has flushed (the last stop bit is out), drops the echo
    /// still waiting (half duplex), lowers DE and returns `true` ("done"), once per frame.
    /// A transmit error ends the frame there (counted; DE lowered; `true`). `false` while the
    /// frame is still going out or when nothing is being sent. In a handler serving both
    /// interrupts, call [`Self::on_receive`] first.
    pub fn on_transmit(&mut self) -> bool {
        if !self.sending {
            return false;
        }
        while let Some(&b) = self.out.get(self.sent) {
            match self.tx.write(b) {
                Ok(()) => self.sent += 1,
                Err(nb::Error::WouldBlock) => return false,
                Err(nb::Error::Other(_)) => {
                    self.errors.transmit = self.errors.transmit.wrapping_add(1);
                    self.finish();
                    return true;
                }
            }
        }
        match self.tx.flush() {
            Ok(()) => {}
            Err(nb::Error::WouldBlock) => return false,
            Err(nb::Error::Other(_)) => {
                self.errors.transmit = self.errors.transmit.wrapping_add(1);
            }
        }
        self.finish();
        true
    }

    /// Ends the frame being sent: the echo dropped (half duplex), DE low.
    fn finish(&mut self) {
        if self.echo {
            self.on_receive(|_| {});
        }
        self.sending = false;
        self.drive(false);
    }

    /// `true` from a successful [`Self::send`] until [`Self::on_transmit`] reports it done.
    pub fn sending(&self) -> bool {
        self.sending
    }

    /// The error counts so far.
    pub fn errors(&self) -> Errors {
        self.errors
    }

    /// The transmitter, receiver and DE pin back (DE as last set: low unless a frame was
    /// still going out).
    pub fn release(self) -> (TX, RX, DE) {
        (self.tx, self.rx, self.de)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::collections::VecDeque;
    use std::rc::Rc;

    /// What happened on the line, in order.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Event {
        /// A byte left the shift register, DE as it was then.
        Byte(u8, bool),
        /// DE set.
        De(bool),
    }

    /// A UART with a holding and a shift register (one byte each) moved by [`Line::tick`],
    /// a receive queue and a DE pin, shared by the three fakes.
    #[derive(Default)]
    struct Line {
        events: Vec<Event>,
        rx: VecDeque<Result<u8, serial::ErrorKind>>,
        holding: Option<u8>,
        shift: Option<u8>,
        de: bool,
        echo: bool,
        de_fails: bool,
        tx_fails: bool,
    }

    impl Line {
        /// One character time: the byte in the shift register leaves (and is heard back by
        /// a half-duplex transceiver), the holding register's moves on.
        fn tick(&mut self) {
            if let Some(b) = self.shift.take() {
                self.events.push(Event::Byte(b, self.de));
                if self.echo {
                    self.rx.push_back(Ok(b));
                }
            }
            self.shift = self.holding.take();
        }
        fn sent(&self) -> Vec<u8> {
            self.events
                .iter()
                .filter_map(|e| match *e {
                    Event::Byte(b, _) => Some(b),
                    Event::De(_) => None,
                })
                .collect()
        }
    }

    type Shared = Rc<RefCell<Line>>;
    struct Tx(Shared);
    struct Rx(Shared);
    struct De(Shared);

    impl serial::ErrorType for Tx {
        type Error = serial::ErrorKind;
    }
    impl serial::Write<u8> for Tx {
        fn write(&mut self, b: u8) -> nb::Result<(), serial::ErrorKind> {
            let mut l = self.0.borrow_mut();
            if l.tx_fails {
                return Err(nb::Error::Other(serial::ErrorKind::Other));
            }
            if l.holding.is_some() {
                return Err(nb::Error::WouldBlock);
            }
            l.holding = Some(b);
            Ok(())
        }
        fn flush(&mut self) -> nb::Result<(), serial::ErrorKind> {
            let l = self.0.borrow();
            if l.holding.is_some() || l.shift.is_some() {
                Err(nb::Error::WouldBlock)
            } else {
                Ok(())
            }
        }
    }
    impl serial::ErrorType for Rx {
        type Error = serial::ErrorKind;
    }
    impl serial::Read<u8> for Rx {
        fn read(&mut self) -> nb::Result<u8, serial::ErrorKind> {
            match self.0.borrow_mut().rx.pop_front() {
                Some(Ok(b)) => Ok(b),
                Some(Err(e)) => Err(nb::Error::Other(e)),
                None => Err(nb::Error::WouldBlock),
            }
        }
    }
    impl embedded_hal::digital::ErrorType for De {
        type Error = embedded_hal::digital::ErrorKind;
    }
    impl OutputPin for De {
        fn set_low(&mut self) -> Result<(), Self::Error> {
            self.set(false)
        }
        fn set_high(&mut self) -> Result<(), Self::Error> {
            self.set(true)
        }
    }
    impl De {
        fn set(&mut self, on: bool) -> Result<(), embedded_hal::digital::ErrorKind> {
            let mut l = self.0.borrow_mut();
            if l.de_fails {
                return Err(embedded_hal::digital::ErrorKind::Other);
            }
            l.de = on;
            l.events.push(Event::De(on));
            Ok(())
        }
    }

    fn port(echo: bool) -> (Rs485<Tx, Rx, De>, Shared) {
        let line = Rc::new(RefCell::new(Line {
            echo,
            ..Line::default()
        }));
        let (tx, rx, de) = (Tx(line.clone()), Rx(line.clone()), De(line.clone()));
        let p = if echo {
            Rs485::half_duplex(tx, rx, de)
        } else {
            Rs485::full_duplex(tx, rx, de)
        };
        line.borrow_mut().events.clear();
        (p, line)
    }

    /// Runs the line until the port reports the frame done, serving both interrupts each
    /// character time (receive first); returns the bytes received meanwhile and the ticks.
    fn run(p: &mut Rs485<Tx, Rx, De>, line: &Shared) -> (Vec<u8>, usize) {
        let mut got = Vec::new();
        for ticks in 1..1000 {
            line.borrow_mut().tick();
            p.on_receive(|b| got.push(b));
            if p.on_transmit() {
                return (got, ticks);
            }
        }
        panic!("never done");
    }

    #[test]
    fn gaps_follow_the_spec() {
        assert_eq!(gap_us(19_200), 2_006, "3.5 × 11 bits, rounded up");
        assert_eq!(gap_us(9_600), 4_011);
        assert_eq!(gap_us(1_200), 32_084);
        for baud in [19_201, 38_400, 115_200, u32::MAX] {
            assert_eq!(gap_us(baud), 1_750, "{baud}");
        }
        assert_eq!(gap_us(0), u32::MAX);
        assert_eq!(gap_us(1), 38_500_000);
        assert_eq!(RtuFramer::new(0).gap_us(), 1);
    }

    #[test]
    fn half_duplex_drops_its_echo_and_frames_what_comes_back() {
        let (mut p, line) = port(true);
        assert!(p.send(&[1, 2, 3]));
        assert!(!p.send(&[9]), "one frame at a time");
        let (heard, _) = run(&mut p, &line);
        assert!(heard.is_empty(), "its own echo is dropped: {heard:?}");
        assert!(!p.sending() && !p.on_transmit(), "done once");
        assert_eq!(line.borrow().sent(), [1, 2, 3]);
        assert!(line.borrow().rx.is_empty(), "the last echo byte drained");
        // A handler that serves the transmit interrupt first: the last byte's echo, waiting
        // when the flush completes, is dropped by `on_transmit` itself.
        assert!(p.send(&[6, 7]));
        let mut heard = Vec::new();
        loop {
            line.borrow_mut().tick();
            if p.on_transmit() {
                break;
            }
            p.on_receive(|b| heard.push(b));
        }
        p.on_receive(|b| heard.push(b));
        assert!(heard.is_empty(), "{heard:?}");
        // The peer answers: framed by the silence.
        let mut framer = RtuFramer::new(2_000);
        let mut out = Frame::new();
        line.borrow_mut().rx.extend([Ok(4), Ok(5)]);
        p.on_receive(|b| framer.push(b, 10_000));
        assert!(!framer.poll(11_999, &mut out));
        assert!(framer.poll(12_000, &mut out));
        assert_eq!(&out[..], &[4, 5]);
        assert_eq!(p.errors(), Errors::default());
    }

    #[test]
    fn de_is_high_from_the_first_byte_until_the_flush_completes() {
        let (mut p, line) = port(true);
        let frame: Vec<u8> = (10..20).collect();
        assert!(p.send(&frame));
        assert_eq!(line.borrow().events, [Event::De(true)], "DE raised first");
        assert_eq!(
            line.borrow().holding,
            Some(10),
            "the first byte written by send"
        );
        let (_, ticks) = run(&mut p, &line);
        let events = line.borrow().events.clone();
        let mut want: Vec<Event> = vec![Event::De(true)];
        want.extend(frame.iter().map(|&b| Event::Byte(b, true)));
        want.push(Event::De(false));
        assert_eq!(
            events, want,
            "every byte left with DE high; DE low after the last"
        );
        assert_eq!(
            ticks,
            frame.len() + 1,
            "done once the shift register is empty"
        );
        let (_, _, de) = p.release();
        assert!(!de.0.borrow().de);
    }

    /// A full-duplex port (no echo) keeps what arrives while it sends: the peer's next request.
    #[test]
    fn full_duplex_keeps_bytes_received_while_sending() {
        let (mut p, line) = port(false);
        assert!(p.send(&[1, 2, 3]));
        line.borrow_mut().rx.extend([Ok(7), Ok(8), Ok(9)]);
        let mut got = Vec::new();
        p.on_receive(|b| got.push(b));
        assert!(p.sending(), "still sending");
        assert_eq!(got, [7, 8, 9]);
        line.borrow_mut().rx.push_back(Ok(10));
        let (more, _) = run(&mut p, &line);
        assert_eq!(more, [10]);
        assert_eq!(line.borrow().sent(), [1, 2, 3]);
    }

    #[test]
    fn receive_errors_are_counted_by_kind_and_their_bytes_dropped() {
        let (mut p, line) = port(true);
        use serial::ErrorKind::*;
        line.borrow_mut().rx.extend([
            Ok(1),
            Err(Overrun),
            Ok(2),
            Err(FrameFormat),
            Err(Parity),
            Err(Parity),
            Err(Noise),
            Err(Other),
            Ok(3),
        ]);
        let mut got = Vec::new();
        p.on_receive(|b| got.push(b));
        assert_eq!(got, [1, 2, 3]);
        assert_eq!(
            p.errors(),
            Errors {
                overrun: 1,
                framing: 1,
                parity: 2,
                noise: 1,
                other: 1,
                ..Errors::default()
            }
        );
    }

    #[test]
    fn a_receiver_that_never_runs_dry_does_not_hold_the_handler() {
        let (mut p, line) = port(true);
        line.borrow_mut()
            .rx
            .extend(std::iter::repeat_n(Err(serial::ErrorKind::Noise), 1000));
        p.on_receive(|_| {});
        assert_eq!(p.errors().noise, READS_PER_CALL as u32);
    }

    #[test]
    fn frames_that_cannot_be_sent_are_refused() {
        let (mut p, line) = port(true);
        assert!(!p.send(&[0; MAX_FRAME + 1]), "longer than MAX_FRAME");
        assert!(!p.send(&[]), "empty");
        assert!(!p.sending());
        assert!(
            line.borrow().events.is_empty(),
            "DE untouched, nothing written"
        );
        assert!(line.borrow().holding.is_none());
        assert!(p.send(&[0x5A; MAX_FRAME]), "MAX_FRAME bytes are fine");
        let _ = run(&mut p, &line);
        assert_eq!(line.borrow().sent(), [0x5A; MAX_FRAME]);
    }

    #[test]
    fn pin_and_transmit_errors_are_counted_not_panics() {
        let (mut p, line) = port(true);
        line.borrow_mut().de_fails = true;
        assert!(p.send(&[1, 2]));
        let _ = run(&mut p, &line);
        assert_eq!(line.borrow().sent(), [1, 2], "the frame still went out");
        assert_eq!(p.errors().driver_enable, 2, "raise and lower");
        line.borrow_mut().de_fails = false;
        // A transmitter that fails: the first byte → refused; later → the frame ends.
        line.borrow_mut().tx_fails = true;
        assert!(!p.send(&[3, 4]));
        assert!(!p.sending() && !line.borrow().de, "DE low again");
        line.borrow_mut().tx_fails = false;
        assert!(p.send(&[5, 6, 7]));
        line.borrow_mut().tx_fails = true;
        assert!(p.on_transmit(), "ended");
        assert!(!p.sending() && !line.borrow().de);
        assert_eq!(p.errors().transmit, 2);
    }

    #[test]
    fn a_gap_ends_a_frame() {
        let mut f = RtuFramer::new(3_000);
        let mut out = Frame::new();
        for (t, b) in [(0, 1u8), (1_000, 2), (2_000, 3)] {
            f.push(b, t);
            assert!(!f.poll(t, &mut out));
        }
        assert!(
            !f.poll(4_999, &mut out),
            "2.999 ms of silence is not enough"
        );
        assert!(f.poll(5_000, &mut out));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.poll(9_000, &mut out), "one frame once");
        f.push(9, 10_000);
        assert!(f.poll(13_000, &mut out));
        assert_eq!(&out[..], &[9]);
    }

    #[test]
    fn a_hardware_timeout_ends_a_frame() {
        let mut f = RtuFramer::new(u32::MAX);
        let mut out = Frame::new();
        assert!(!f.end_frame(&mut out), "nothing held");
        f.push(1, 0);
        f.push(2, 0);
        assert!(!f.poll(1_000_000, &mut out), "the clock is not watched");
        assert!(f.end_frame(&mut out));
        assert_eq!(&out[..], &[1, 2]);
        assert!(!f.busy() && !f.end_frame(&mut out));
        for i in 0..300u32 {
            f.push(i as u8, 0);
        }
        assert!(!f.end_frame(&mut out), "too long: dropped");
        assert!(!f.busy());
    }

    #[test]
    fn too_long_frames_are_dropped_and_the_next_one_is_whole() {
        let mut f = RtuFramer::new(2_000);
        let mut out = Frame::new();
        for i in 0..300u32 {
            f.push(i as u8, 100_000);
        }
        assert!(!f.poll(102_000, &mut out));
        assert!(!f.busy());
        f.push(7, 103_000);
        f.push(8, 103_000);
        assert!(f.poll(105_000, &mut out));
        assert_eq!(&out[..], &[7, 8]);
    }

    #[test]
    fn a_frame_complete_by_its_content_needs_no_silence() {
        let mut f = RtuFramer::new(10_000);
        let mut out = Frame::new();
        // "Whole" here: the last three bytes are 1, 2, 3.
        let find = |b: &[u8]| b.ends_with(&[1, 2, 3]).then(|| b.len() - 3);
        f.push(1, 0);
        f.push(2, 0);
        assert!(!f.take_if(&mut out, find), "not yet whole");
        f.push(3, 0);
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.busy() && !f.poll(100_000, &mut out), "handed on once");
        // Noise is not whole: it waits for the silence and is handed on there as before.
        for b in [9, 1, 2] {
            f.push(b, 200_000);
        }
        assert!(!f.take_if(&mut out, find));
        assert!(f.poll(210_000, &mut out));
        assert_eq!(&out[..], &[9, 1, 2]);
        // A whole frame right after more noise than a frame holds: found, noise dropped.
        for i in 0..1000u32 {
            f.push(0x55 ^ i as u8, 300_000);
        }
        for b in [1, 2, 3] {
            f.push(b, 300_000);
        }
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &[1, 2, 3]);
        assert!(!f.busy());
    }

    #[test]
    fn a_frame_as_long_as_the_framer_holds_is_found_after_overflowing_noise() {
        let mut f = RtuFramer::new(3_000);
        let mut out = Frame::new();
        let frame: Vec<u8> = (0..HOLD as u32).map(|i| (i * 7 + 1) as u8).collect();
        let find = |held: &[u8]| held.ends_with(&frame).then(|| held.len() - frame.len());
        for i in 0..777u32 {
            f.push((i * 13) as u8, 5_000);
        }
        for &b in &frame {
            assert!(!f.take_if(&mut out, find) || out[..] == frame[..]);
            f.push(b, 5_000);
        }
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &frame[..]);
        assert!(!f.busy());
    }

    #[test]
    fn a_torn_frame_start_waits_for_its_patience_and_nothing_else_does() {
        let mut f = RtuFramer::new(10_000);
        let mut out = Frame::new();
        // "May grow": starts with 1 and holds fewer than 4 bytes.
        let may_grow = |b: &[u8]| b.first() == Some(&1) && b.len() < 4;
        f.push(1, 0);
        f.push(2, 0);
        assert!(
            !f.poll_patient(10_000, &mut out, may_grow, 500_000),
            "past the gap"
        );
        assert!(!f.poll_patient(499_999, &mut out, may_grow, 500_000));
        // The rest arrives: the silence ends it as usual.
        f.push(3, 499_999);
        f.push(4, 499_999);
        assert!(!f.poll_patient(509_998, &mut out, may_grow, 500_000));
        assert!(f.poll_patient(509_999, &mut out, may_grow, 500_000));
        assert_eq!(&out[..], &[1, 2, 3, 4]);
        // Given up at the patience, as by the silence (handed on).
        f.push(1, 600_000);
        assert!(f.poll_patient(1_100_000, &mut out, may_grow, 500_000));
        assert_eq!(&out[..], &[1]);
        // Bytes that cannot grow: the gap alone.
        f.push(9, 2_000_000);
        assert!(f.poll_patient(2_010_000, &mut out, may_grow, 500_000));
        assert_eq!(&out[..], &[9]);
        // A patience shorter than the gap: the gap.
        f.push(1, 3_000_000);
        assert!(!f.poll_patient(3_009_999, &mut out, may_grow, 0));
        assert!(f.poll_patient(3_010_000, &mut out, may_grow, 0));
        // Too long a frame is dropped at the gap, whatever its bytes.
        for _ in 0..300 {
            f.push(1, 4_000_000);
        }
        assert!(!f.poll_patient(4_010_000, &mut out, |_| true, 500_000));
        assert!(!f.busy());
    }

    #[test]
    fn a_kept_start_does_not_hide_a_whole_frame_after_a_pause() {
        let mut f = RtuFramer::new(10_000);
        let mut out = Frame::new();
        // "Whole": all the bytes looked at, if they end with 7, 8, 9 and do not start with 1
        // (a start that claims every byte after it).
        let find = |b: &[u8]| (b.first() != Some(&1) && b.ends_with(&[7, 8, 9])).then_some(0);
        for b in [1, 2] {
            f.push(b, 0);
        }
        assert!(
            !f.poll_patient(20_000, &mut out, |_| true, 1_000_000),
            "kept"
        );
        // A whole frame after the pause: found in the bytes since it, the start dropped.
        for b in [7, 8] {
            f.push(b, 30_000);
            assert!(!f.take_if(&mut out, find));
        }
        f.push(9, 30_000);
        assert!(f.take_if(&mut out, find));
        assert_eq!(&out[..], &[7, 8, 9]);
        assert!(!f.busy());
        // Without a pause, the start still claims what follows (as before).
        for b in [1, 2, 7, 8, 9] {
            f.push(b, 40_000);
        }
        assert!(!f.take_if(&mut out, find));
        assert!(f.poll(50_000, &mut out), "ended by the silence");
        // A long start kept, then more bytes than the ring has room for: the place where
        // they begin follows the ring as it drops its oldest bytes.
        for _ in 0..200 {
            f.push(1, 60_000);
        }
        assert!(
            !f.poll_patient(70_000, &mut out, |_| true, 1_000_000),
            "kept"
        );
        for _ in 0..100 {
            f.push(0x55, 80_000);
        }
        for b in [7, 8, 9] {
            f.push(b, 80_000);
        }
        assert!(f.take_if(&mut out, find));
        assert_eq!(out.len(), 103, "from the first byte after the pause");
        assert_eq!(&out[..2], &[0x55, 0x55]);
        assert!(!f.busy());
    }

    #[test]
    fn time_wraps() {
        let mut f = RtuFramer::new(2_000);
        let mut out = Frame::new();
        f.push(1, u32::MAX - 999);
        assert!(!f.poll(999, &mut out), "1.999 ms across the wrap");
        assert!(f.poll(1_000, &mut out));
        assert_eq!(&out[..], &[1]);
    }
}
