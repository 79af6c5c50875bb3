//! A USART's interrupt side: its [`Rs485`] port, the receive queue it fills and the transmit
//! queue of whole frames it empties. The board's priority-4 handler calls
//! [`PortIsr::on_interrupt`] and keeps nothing else in it.
use super::{Margin, Ordering};
use controller::control::Commands;
use controller::link::{ScadaLink, VfdPort};
use controller::modbus::Frame;
use controller::rtu::Rs485;
use controller::rtu::RtuFramer;
use controller::types::Published;
use core::sync::atomic::{AtomicU16, AtomicUsize};
use embedded_hal::digital::OutputPin;
use embedded_hal_nb::serial::{Read, Write};
use heapless::spsc::{Consumer, Producer};

/// The receive queue's mark for "the line went silent" (3.5 characters), put there by a
/// board's gap timer ([`PortIsr::mark_gap`]); every other entry is a byte.
pub const GAP: u16 = 0x100;

/// A receive queue's size: it holds one entry less (1 023), more than four longest RTU
/// frames, so a task at the lowest priority may fall ≈ 500 ms behind a 19 200-baud line
/// before a byte is lost. A power of two ([`RxQueue`]).
pub const RX_QUEUE: usize = 1024;

/// A receive queue: single producer (the USART's interrupt, [`RxProducer`]), single consumer
/// (the task, [`RxConsumer`]), lock-free, of `N` slots holding `N − 1` entries (as
/// `heapless::spsc::Queue<u16, N>`, which it replaces). `N` is a power of two the compiler
/// sees: an index wraps with a mask, where heapless 0.9's producer and consumer, views of a
/// queue of any size, divided by the size read at run time (a `UDIV` and a divide-by-zero
/// panic's path in each USART interrupt). The slots are atomics: no `unsafe`.
pub struct RxQueue<const N: usize> {
    /// Where the consumer takes the next entry (0..N).
    head: AtomicUsize,
    /// Where the producer puts the next entry (0..N).
    tail: AtomicUsize,
    slots: [AtomicU16; N],
}

impl<const N: usize> RxQueue<N> {
    /// `N − 1`: an index's wrap (`N` a power of two, at least 2: a build error otherwise).
    const MASK: usize = {
        assert!(
            N >= 2 && N.is_power_of_two(),
            "a receive queue's size is a power of two"
        );
        N - 1
    };

    /// An empty queue.
    #[allow(clippy::new_without_default)]
    pub const fn new() -> Self {
        let _ = Self::MASK;
        Self {
            head: AtomicUsize::new(0),
            tail: AtomicUsize::new(0),
            slots: [const { AtomicU16::new(0) }; N],
        }
    }

    /// The queue's two ends (once: they borrow it for as long as they live).
    pub fn split(&mut self) -> (RxProducer<'_, N>, RxConsumer<'_, N>) {
        (RxProducer { q: self }, RxConsumer { q: self })
    }
}

/// The producer end of an [`RxQueue`].
pub struct RxProducer<'a, const N: usize> {
    q: &'a RxQueue<N>,
}

impl<const N: usize> RxProducer<'_, N> {
    /// Adds `e` at the back; `Err(e)` if the queue is full.
    #[inline]
    pub fn enqueue(&mut self, e: u16) -> Result<(), u16> {
        let q = self.q;
        let tail = q.tail.load(Ordering::Relaxed);
        let next = (tail + 1) & RxQueue::<N>::MASK;
        if next == q.head.load(Ordering::Acquire) {
            return Err(e);
        }
        q.slots[tail & RxQueue::<N>::MASK].store(e, Ordering::Relaxed);
        q.tail.store(next, Ordering::Release);
        Ok(())
    }
}

/// The consumer end of an [`RxQueue`].
pub struct RxConsumer<'a, const N: usize> {
    q: &'a RxQueue<N>,
}

impl<const N: usize> RxConsumer<'_, N> {
    /// Takes the entry at the front; `None` if the queue is empty.
    #[inline]
    pub fn dequeue(&mut self) -> Option<u16> {
        let q = self.q;
        let head = q.head.load(Ordering::Relaxed);
        if head == q.tail.load(Ordering::Acquire) {
            return None;
        }
        let e = q.slots[head & RxQueue::<N>::MASK].load(Ordering::Relaxed);
        q.head
            .store((head + 1) & RxQueue::<N>::MASK, Ordering::Release);
        Some(e)
    }
}
/// Frames a transmit queue holds (a slave answers one request at a time; a master waits
/// for its answer): two, one going out and one waiting.
pub const TX_QUEUE: usize = 3;

/// What one [`PortIsr::on_interrupt`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Activity {
    /// Bytes received (count).
    pub received: u32,
    /// A frame is still going out.
    pub sending: bool,
}

/// The interrupt side of one port (the board's priority-4 handler calls it), with a receive
/// queue of `N` slots.
pub struct PortIsr<TX, RX, DE, const N: usize = RX_QUEUE> {
    rs485: Rs485<TX, RX, DE>,
    rx: RxProducer<'static, N>,
    tx: Consumer<'static, Frame>,
}

impl<TX: Write<u8>, RX: Read<u8>, DE: OutputPin, const N: usize> PortIsr<TX, RX, DE, N> {
    /// The port with its queues' ends.
    pub fn new(
        rs485: Rs485<TX, RX, DE>,
        rx: RxProducer<'static, N>,
        tx: Consumer<'static, Frame>,
    ) -> Self {
        Self { rs485, rx, tx }
    }

    /// The gap timer's interrupt: the line has been silent for 3.5 characters since the
    /// last byte; the frame before it is complete.
    pub fn mark_gap(&mut self, margin: &Margin) {
        if self.rx.enqueue(GAP).is_err() {
            margin.bytes_lost.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The interrupt's work: every received byte into the receive queue (a byte the full
    /// queue cannot take, and a USART overrun, count in [`Margin::bytes_lost`]); the next
    /// queued frame started once the last one is out, and the bytes the transmitter takes.
    /// Returns what happened: bytes received (a board with a gap timer restarts it) and
    /// whether a frame is still going out (the board keeps its transmit interrupt on, or,
    /// under QEMU where it never fires, calls again at once).
    pub fn on_interrupt(&mut self, margin: &Margin) -> Activity {
        let overruns = self.rs485.errors().overrun;
        let (mut got, mut lost) = (0u32, 0u32);
        let rx = &mut self.rx;
        self.rs485.on_receive(|b| {
            got += 1;
            if rx.enqueue(u16::from(b)).is_err() {
                lost += 1;
            }
        });
        lost += self.rs485.errors().overrun.wrapping_sub(overruns);
        if got > 0 {
            margin.bytes_received.fetch_add(got, Ordering::Relaxed);
        }
        if lost > 0 {
            margin.bytes_lost.fetch_add(lost, Ordering::Relaxed);
        }
        if !self.rs485.sending() {
            // The frame is sent from its slot, then the slot freed (`dequeue` first copied
            // the 260-byte frame out twice: two `memcpy`s and 36 B of flash per port).
            if let Some(frame) = self.tx.peek() {
                self.rs485.send(frame);
                let _ = self.tx.dequeue();
            }
        }
        if self.rs485.sending() {
            self.rs485.on_transmit();
        }
        Activity {
            received: got,
            sending: self.rs485.sending(),
        }
    }

    /// The port's line-error counts.
    pub fn errors(&self) -> controller::rtu::Errors {
        self.rs485.errors()
    }
}

/// How a port on a line that marks no silence (QEMU's) finds its frames by their content.
#[derive(Debug, Clone, Copy)]
pub struct ByContent {
    /// Where a whole frame starts at the end of the bytes held ([`RtuFramer::take_if`]).
    pub find: fn(&[u8]) -> Option<usize>,
    /// `true` while the bytes held may still become a whole frame.
    pub may_grow: fn(&[u8]) -> bool,
    /// Silence after which bytes that may still grow are given up, µs: longer than the
    /// port's silence, which drops any other bytes ([`RtuFramer::poll_patient`]).
    pub patience_us: u32,
}

impl ByContent {
    /// Modbus RTU requests ([`controller::modbus::request_at_end`]); one torn by a pause
    /// (a busy host holding QEMU's bytes up) is waited for up to `patience_us`
    /// ([`controller::modbus::request_may_grow`]).
    pub const fn requests(patience_us: u32) -> Self {
        Self {
            find: controller::modbus::request_at_end,
            may_grow: controller::modbus::request_may_grow,
            patience_us,
        }
    }
}

/// A port's task side: frames out of the receive queue (of `N` slots), frames into the
/// transmit queue.
pub struct PortTask<const N: usize = RX_QUEUE> {
    rx: RxConsumer<'static, N>,
    tx: Producer<'static, Frame>,
    framer: RtuFramer,
    by_content: Option<ByContent>,
    pend: fn(),
    /// Time stamp for the bytes taken next, µs (wrapping).
    pub now_us: u32,
}

impl<const N: usize> PortTask<N> {
    /// The task side of a port whose frames end at a [`GAP`] mark or after `silence_us`
    /// without a byte (timed from when this side takes them); with `by_content`, also by
    /// their content (e.g. [`ByContent::requests`], for a line that marks no silence), and
    /// a start of a frame is kept for its patience. `pend` pends the port's interrupt,
    /// which starts a queued frame.
    pub fn new(
        rx: RxConsumer<'static, N>,
        tx: Producer<'static, Frame>,
        silence_us: u32,
        by_content: Option<ByContent>,
        pend: fn(),
    ) -> Self {
        Self {
            rx,
            tx,
            framer: RtuFramer::new(silence_us),
            by_content,
            pend,
            now_us: 0,
        }
    }

    /// Stamps the bytes taken next with `now_us` ([`Self::now_us`]); returns the port, e.g.
    /// for [`crate::tasks::vfd_pass`].
    pub fn at(&mut self, now_us: u32) -> &mut Self {
        self.now_us = now_us;
        self
    }

    /// The next complete frame into `out`; `false` if none (call again while `true`).
    pub fn receive_frame(&mut self, out: &mut Frame) -> bool {
        while let Some(e) = self.rx.dequeue() {
            if e == GAP {
                if self.framer.end_frame(out) {
                    return true;
                }
                continue;
            }
            self.framer.push(e as u8, self.now_us);
            if let Some(c) = self.by_content {
                if self.framer.take_if(out, c.find) {
                    return true;
                }
            }
        }
        match self.by_content {
            Some(c) => self
                .framer
                .poll_patient(self.now_us, out, c.may_grow, c.patience_us),
            None => self.framer.poll(self.now_us, out),
        }
    }

    /// The next received byte, for a port that carries text lines instead of RTU frames
    /// (the QEMU board's plant line): gap marks are skipped; `None` if none is waiting.
    pub fn take_byte(&mut self) -> Option<u8> {
        while let Some(e) = self.rx.dequeue() {
            if e != GAP {
                return Some(e as u8);
            }
        }
        None
    }

    /// Queues `frame` for sending and pends the port's interrupt; `false` if the queue is
    /// full (the frame is dropped).
    pub fn send_frame(&mut self, frame: &[u8]) -> bool {
        let mut f = Frame::new();
        if f.extend_from_slice(frame).is_err() || self.tx.enqueue(f).is_err() {
            return false;
        }
        (self.pend)();
        true
    }
}

/// The SCADA server's work on a wake-up at `now_us`: every complete request from `port`
/// answered by `link` from the values `published` gives, its answer queued, and the
/// holding registers handed to `commands` after each. Returns the answers dropped because
/// the transmit queue was full (0 unless the line is stuck; with the `defmt` feature, a
/// warning says how many).
pub fn serve_scada<const N: usize>(
    port: &mut PortTask<N>,
    link: &mut ScadaLink,
    now_us: u32,
    mut published: impl FnMut() -> Published,
    mut commands: impl FnMut(Commands),
) -> u32 {
    let (mut frame, mut answer) = (Frame::new(), Frame::new());
    let mut dropped = 0;
    port.now_us = now_us;
    while port.receive_frame(&mut frame) {
        link.publish(&published());
        if let Some(n) = link.handle(&frame, &mut answer) {
            // (`get`: `n` is within the frame; no slice check's panic in EXTI1.)
            if !answer.get(..n).is_some_and(|a| port.send_frame(a)) {
                dropped += 1;
            }
        }
        commands(link.commands());
    }
    #[cfg(feature = "defmt")]
    if dropped > 0 {
        defmt::warn!(
            "{=u32} SCADA answers dropped (transmit queue full)",
            dropped
        );
    }
    dropped
}

/// The VFD master's frames over a serial port.
impl<const N: usize> VfdPort for PortTask<N> {
    fn send(&mut self, frame: &[u8]) {
        // A full queue means the drive's line is stuck: the request runs into its timeout.
        let _ = self.send_frame(frame);
    }
    fn receive(&mut self, frame: &mut Frame) -> bool {
        self.receive_frame(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller::control::Config;
    use controller::modbus::crc16;
    use controller::rtu::NoDe;
    use embedded_hal_nb::nb;
    use embedded_hal_nb::serial::{self, ErrorKind};
    use heapless::spsc::Queue;
    use std::boxed::Box;
    use std::cell::{Cell, RefCell};
    use std::collections::VecDeque;
    use std::rc::Rc;
    use std::vec::Vec;

    /// A UART's receiver: what the line delivers, bytes or errors, in order.
    #[derive(Clone, Default)]
    struct Rx(Rc<RefCell<VecDeque<Result<u8, ErrorKind>>>>);
    /// A UART's transmitter: takes every byte (recorded) unless `busy`.
    #[derive(Clone, Default)]
    struct Tx(Rc<RefCell<Vec<u8>>>, Rc<Cell<bool>>);

    impl serial::ErrorType for Rx {
        type Error = ErrorKind;
    }
    impl serial::Read<u8> for Rx {
        fn read(&mut self) -> nb::Result<u8, ErrorKind> {
            match self.0.borrow_mut().pop_front() {
                Some(Ok(b)) => Ok(b),
                Some(Err(e)) => Err(nb::Error::Other(e)),
                None => Err(nb::Error::WouldBlock),
            }
        }
    }
    impl serial::ErrorType for Tx {
        type Error = ErrorKind;
    }
    impl serial::Write<u8> for Tx {
        fn write(&mut self, b: u8) -> nb::Result<(), ErrorKind> {
            if self.1.get() {
                return Err(nb::Error::WouldBlock);
            }
            self.0.borrow_mut().push(b);
            Ok(())
        }
        fn flush(&mut self) -> nb::Result<(), ErrorKind> {
            if self.1.get() {
                Err(nb::Error::WouldBlock)
            } else {
                Ok(())
            }
        }
    }

    impl Rx {
        fn deliver(&self, items: impl IntoIterator<Item = Result<u8, ErrorKind>>) {
            self.0.borrow_mut().extend(items);
        }
        fn bytes(&self, bytes: &[u8]) {
            self.deliver(bytes.iter().map(|&b| Ok(b)));
        }
    }

    /// The queues of one port, leaked to `'static` as a board's `init` locals are.
    fn queues<const R: usize, const T: usize>() -> (
        RxProducer<'static, R>,
        RxConsumer<'static, R>,
        Producer<'static, Frame>,
        Consumer<'static, Frame>,
    ) {
        let (p, c) = Box::leak(Box::new(RxQueue::<R>::new())).split();
        let (pt, ct) = Box::leak(Box::new(Queue::<Frame, T>::new())).split();
        (p, c, pt, ct)
    }

    std::thread_local! {
        static PENDS: Cell<u32> = const { Cell::new(0) };
    }
    fn pend() {
        PENDS.with(|p| p.set(p.get() + 1));
    }
    fn pends() -> u32 {
        PENDS.with(Cell::get)
    }

    type Isr<const R: usize> = PortIsr<Tx, Rx, NoDe, R>;

    /// A full-duplex port with queues of `R` entries and `T` frames, both sides.
    fn port<const R: usize, const T: usize>(
        silence_us: u32,
        by_content: Option<ByContent>,
    ) -> (Isr<R>, PortTask<R>, Rx, Tx) {
        let (rx_q, rx_c, tx_p, tx_c) = queues::<R, T>();
        let (rx, tx) = (Rx::default(), Tx::default());
        let isr = PortIsr::new(Rs485::full_duplex(tx.clone(), rx.clone(), NoDe), rx_q, tx_c);
        let task = PortTask::new(rx_c, tx_p, silence_us, by_content, pend);
        (isr, task, rx, tx)
    }

    fn with_crc(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    /// The receive queue holds `N − 1` entries (as heapless's did), first in first out,
    /// across many wraps of its indices.
    #[test]
    fn the_receive_queue_holds_n_minus_one_in_order_across_wraps() {
        let (mut p, mut c) = Box::leak(Box::new(RxQueue::<4>::new())).split();
        assert_eq!(c.dequeue(), None);
        let (mut next_in, mut next_out) = (0u16, 0u16);
        for round in 0..50 {
            let n = round % 4;
            for _ in 0..n {
                if p.enqueue(next_in).is_ok() {
                    next_in += 1;
                }
            }
            assert!(next_in - next_out <= 3);
            while let Some(e) = c.dequeue() {
                assert_eq!(e, next_out);
                next_out += 1;
            }
            assert_eq!(next_in, next_out);
        }
        for k in 0..3 {
            assert_eq!(p.enqueue(k), Ok(()));
        }
        assert_eq!(p.enqueue(9), Err(9), "full at N - 1");
        assert_eq!(c.dequeue(), Some(0));
        assert_eq!(p.enqueue(9), Ok(()));
        let rest: Vec<u16> = core::iter::from_fn(|| c.dequeue()).collect();
        assert_eq!(rest, [1, 2, 9]);
    }

    #[test]
    fn received_bytes_reach_the_task_and_are_counted() {
        let (mut isr, mut task, rx, _) = port::<64, 3>(1000, None);
        let margin = Margin::new();
        rx.bytes(&[1, 2, 3]);
        let a = isr.on_interrupt(&margin);
        assert_eq!(
            a,
            Activity {
                received: 3,
                sending: false
            }
        );
        rx.bytes(&[4]);
        assert_eq!(isr.on_interrupt(&margin).received, 1);
        assert_eq!(isr.on_interrupt(&margin).received, 0);
        let m = margin.snapshot();
        assert_eq!((m.bytes_received, m.bytes_lost), (4, 0));
        isr.mark_gap(&margin);
        let mut out = Frame::new();
        assert!(task.receive_frame(&mut out));
        assert_eq!(out[..], [1, 2, 3, 4]);
        assert!(!task.receive_frame(&mut out));
    }

    /// A byte the full queue cannot take is lost and counted; the ones before it arrive.
    #[test]
    fn a_full_receive_queue_counts_each_byte_lost() {
        let (mut isr, mut task, rx, _) = port::<8, 3>(1000, None);
        let margin = Margin::new();
        let bytes: Vec<u8> = (0..20).collect();
        rx.bytes(&bytes);
        assert_eq!(isr.on_interrupt(&margin).received, 20);
        let m = margin.snapshot();
        let held = m.bytes_received - m.bytes_lost;
        assert_eq!(m.bytes_received, 20);
        assert!(m.bytes_lost > 0 && held >= 7, "{m:?}");
        // The gap mark cannot go in either: one more entry lost.
        isr.mark_gap(&margin);
        assert_eq!(margin.snapshot().bytes_lost, m.bytes_lost + 1);
        let mut out = Frame::new();
        assert!(
            !task.at(5000).receive_frame(&mut out),
            "bytes taken at 5 000 µs"
        );
        assert!(
            task.at(6000).receive_frame(&mut out),
            "ended by the silence"
        );
        assert_eq!(out[..], bytes[..held as usize]);
    }

    /// An overrun is a byte the USART lost: counted as lost. Other line errors are not lost
    /// bytes (the byte came, damaged: the frame's CRC rejects it).
    #[test]
    fn an_overrun_counts_as_a_lost_byte() {
        let (mut isr, _, rx, _) = port::<64, 3>(1000, None);
        let margin = Margin::new();
        rx.deliver([
            Ok(1),
            Err(ErrorKind::Overrun),
            Ok(2),
            Err(ErrorKind::FrameFormat),
            Err(ErrorKind::Overrun),
            Err(ErrorKind::Parity),
        ]);
        assert_eq!(isr.on_interrupt(&margin).received, 2);
        let m = margin.snapshot();
        assert_eq!((m.bytes_received, m.bytes_lost), (2, 2));
        assert_eq!(isr.errors().overrun, 2);
        assert_eq!(isr.errors().framing, 1);
        // Counted once: the next interrupt adds only new overruns.
        rx.deliver([Ok(3)]);
        isr.on_interrupt(&margin);
        assert_eq!(margin.snapshot().bytes_lost, 2);
    }

    #[test]
    fn a_queued_frame_goes_out_from_the_interrupt() {
        let (mut isr, mut task, _, tx) = port::<64, 3>(1000, None);
        let margin = Margin::new();
        let before = pends();
        assert!(task.send_frame(&[9, 8, 7]));
        assert_eq!(pends(), before + 1, "the interrupt pended");
        assert!(!isr.on_interrupt(&margin).sending);
        assert_eq!(tx.0.borrow()[..], [9, 8, 7]);
        // A transmitter that is still busy: the frame stays on, and goes out later.
        tx.1.set(true);
        assert!(task.send_frame(&[1, 2]));
        assert!(isr.on_interrupt(&margin).sending);
        assert!(isr.on_interrupt(&margin).sending);
        tx.1.set(false);
        assert!(!isr.on_interrupt(&margin).sending);
        assert_eq!(tx.0.borrow()[..], [9, 8, 7, 1, 2]);
    }

    #[test]
    fn bytes_are_taken_one_by_one_without_the_gap_marks() {
        let (mut isr, mut task, rx, _) = port::<64, 3>(1000, None);
        let margin = Margin::new();
        assert_eq!(task.take_byte(), None);
        rx.bytes(b"S 1");
        isr.on_interrupt(&margin);
        isr.mark_gap(&margin);
        rx.bytes(b"\n");
        isr.on_interrupt(&margin);
        let got: Vec<u8> = core::iter::from_fn(|| task.take_byte()).collect();
        assert_eq!(got, b"S 1\n");
        assert_eq!(task.take_byte(), None);
    }

    #[test]
    fn a_full_transmit_queue_or_a_long_frame_is_refused() {
        let (_, mut task, _, _) = port::<64, 3>(1000, None);
        let before = pends();
        let mut sent = 0;
        while task.send_frame(&[1]) {
            sent += 1;
            assert!(sent < 100);
        }
        assert!(sent >= 2, "two frames, one going out and one waiting");
        assert_eq!(pends(), before + sent);
        let (_, mut task, _, _) = port::<64, 3>(1000, None);
        assert!(!task.send_frame(&[0; controller::modbus::MAX_FRAME + 1]));
        assert!(task.send_frame(&[0; controller::modbus::MAX_FRAME]));
    }

    #[test]
    fn frames_end_at_the_gap_mark_or_the_silence() {
        let (mut isr, mut task, rx, _) = port::<64, 3>(2000, None);
        let margin = Margin::new();
        let mut out = Frame::new();
        // A mark with no bytes before it is no frame.
        isr.mark_gap(&margin);
        assert!(!task.receive_frame(&mut out));
        // Two frames queued: one each call.
        rx.bytes(&[1, 2]);
        isr.on_interrupt(&margin);
        isr.mark_gap(&margin);
        rx.bytes(&[3]);
        isr.on_interrupt(&margin);
        isr.mark_gap(&margin);
        assert!(task.receive_frame(&mut out));
        assert_eq!(out[..], [1, 2]);
        assert!(task.receive_frame(&mut out));
        assert_eq!(out[..], [3]);
        assert!(!task.receive_frame(&mut out));
        // No mark: the silence, timed from when the task takes the bytes, across the wrap.
        task.now_us = u32::MAX - 500;
        rx.bytes(&[4, 5]);
        isr.on_interrupt(&margin);
        assert!(!task.receive_frame(&mut out));
        assert!(!task
            .at((u32::MAX - 500).wrapping_add(1999))
            .receive_frame(&mut out));
        assert!(task
            .at((u32::MAX - 500).wrapping_add(2000))
            .receive_frame(&mut out));
        assert_eq!(out[..], [4, 5]);
    }

    #[test]
    fn a_request_is_found_by_its_content_without_silence() {
        let (mut isr, mut task, rx, _) = port::<64, 3>(10_000, Some(ByContent::requests(500_000)));
        let margin = Margin::new();
        let req = with_crc(&[1, 4, 0, 0, 0, 18]);
        rx.bytes(&[0x55]);
        rx.bytes(&req);
        isr.on_interrupt(&margin);
        let mut out = Frame::new();
        assert!(task.receive_frame(&mut out));
        assert_eq!(out[..], req[..]);
        // Half a request: nothing yet.
        rx.bytes(&req[..4]);
        isr.on_interrupt(&margin);
        assert!(!task.receive_frame(&mut out));
        rx.bytes(&req[4..]);
        isr.on_interrupt(&margin);
        assert!(task.receive_frame(&mut out));
        assert_eq!(out[..], req[..]);
    }

    #[test]
    fn a_request_torn_by_a_pause_is_kept_for_its_patience() {
        let (mut isr, mut task, rx, _) = port::<64, 3>(10_000, Some(ByContent::requests(500_000)));
        let margin = Margin::new();
        let req = with_crc(&[1, 4, 0, 0, 0, 18]);
        let mut out = Frame::new();
        // Half a request, then 0.4 s of silence (40 of the port's): kept, then whole.
        rx.bytes(&req[..3]);
        isr.on_interrupt(&margin);
        assert!(!task.at(0).receive_frame(&mut out));
        assert!(!task.at(400_000).receive_frame(&mut out));
        rx.bytes(&req[3..]);
        isr.on_interrupt(&margin);
        assert!(task.at(400_000).receive_frame(&mut out));
        assert_eq!(out[..], req[..]);
        // Half a request never finished: given up at the patience, and the next is whole.
        rx.bytes(&req[..5]);
        isr.on_interrupt(&margin);
        assert!(!task.at(1_000_000).receive_frame(&mut out));
        assert!(!task.at(1_499_999).receive_frame(&mut out));
        assert!(
            task.at(1_500_000).receive_frame(&mut out),
            "handed on, as by the silence"
        );
        assert_eq!(out[..], req[..5]);
        rx.bytes(&req);
        isr.on_interrupt(&margin);
        assert!(task.at(1_500_001).receive_frame(&mut out));
        assert_eq!(out[..], req[..]);
        // The start of a long write that never grows whole, then a read after a pause: the
        // read is answered at once, not hidden in the bytes the write claims.
        rx.bytes(&[1, 16, 0, 0, 0, 100, 200]);
        isr.on_interrupt(&margin);
        assert!(!task.at(1_600_000).receive_frame(&mut out));
        assert!(!task.at(1_700_000).receive_frame(&mut out), "kept");
        rx.bytes(&req);
        isr.on_interrupt(&margin);
        assert!(task.at(1_700_000).receive_frame(&mut out));
        assert_eq!(out[..], req[..]);
        // Noise that cannot start a request: dropped at the port's silence.
        rx.bytes(&[0x55, 0x99, 0x01]);
        isr.on_interrupt(&margin);
        assert!(!task.at(2_000_000).receive_frame(&mut out));
        assert!(task.at(2_010_000).receive_frame(&mut out));
        assert_eq!(out[..], [0x55, 0x99, 0x01]);
    }

    /// A SCADA link of the bench configuration on a port that finds requests by their
    /// content, with a receive queue of `R` entries; `requests` requests for `registers`
    /// input registers received.
    fn scada<const R: usize>(
        requests: usize,
        registers: u8,
    ) -> (Config, ScadaLink, Isr<R>, PortTask<R>, Tx, Margin) {
        let config = Config::bench();
        let link = ScadaLink::new(&config).unwrap();
        let (mut isr, task, rx, tx) = port::<R, 3>(10_000, Some(ByContent::requests(500_000)));
        let margin = Margin::new();
        let req = with_crc(&[config.scada_unit, 4, 0, 0, 0, registers]);
        for _ in 0..requests {
            rx.bytes(&req);
        }
        isr.on_interrupt(&margin);
        (config, link, isr, task, tx, margin)
    }

    #[test]
    fn the_scada_server_answers_and_hands_on_the_commands() {
        // Two requests for 4 input registers at once: two answers, the commands after each.
        let (config, mut link, mut isr, mut task, tx, margin) = scada::<64>(2, 4);
        let published = Published {
            pressure_mca: 3.5,
            ..Published::default()
        };
        let (mut reads, mut handed) = (0, 0);
        let dropped = serve_scada(
            &mut task,
            &mut link,
            123,
            || {
                reads += 1;
                published
            },
            |c| {
                handed += 1;
                assert_eq!(c, link_commands(&config));
            },
        );
        assert_eq!((dropped, reads, handed, task.now_us), (0, 2, 2, 123));
        // One frame per interrupt (the task pends it again for the next).
        for _ in 0..2 {
            while isr.on_interrupt(&margin).sending {}
        }
        let sent = tx.0.borrow().clone();
        // Each answer: unit, function, byte count, 4 registers, CRC.
        let n = 3 + 8 + 2;
        assert_eq!(sent.len(), 2 * n, "{sent:?}");
        assert_eq!(sent[..3], [config.scada_unit, 4, 8]);
        assert_eq!(crc16(&sent[..n - 2]).to_le_bytes(), sent[n - 2..n]);
        assert_eq!(sent[..n], sent[n..]);
    }

    #[test]
    fn answers_the_transmit_queue_cannot_take_are_counted() {
        let (_, mut link, _, mut task, _, _) = scada::<1024>(10, 1);
        // Nothing goes out meanwhile (the interrupt does not run): the queue fills.
        let dropped = serve_scada(&mut task, &mut link, 0, Published::default, |_| {});
        assert!((7..10).contains(&dropped), "{dropped}");
    }

    fn link_commands(config: &Config) -> Commands {
        ScadaLink::new(config).unwrap().commands()
    }
}
