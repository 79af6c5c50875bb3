//! The VFD side: a Modbus RTU master, written sans-IO (it makes request frames and takes the
//! bytes and times it is given), so the same code runs on the MCU and in host tests.
//!
//! Each cycle writes the torque reference (FC 06) and reads a block of holding registers
//! (FC 03) holding actual speed, torque and status; the register map and scaling are
//! configuration ([`VfdMap`]), since vendors differ (16384 or 10000 counts = 100 % torque).
//! An exchange is a request and up to [`VfdMap::retries`] repeats, each with
//! [`VfdMap::timeout_ms`]. Failures are counted per kind of exchange as well as in all, since
//! a drive may fail one kind only (reject or ignore every write, yet answer every read):
//!
//! - **link alarm** ([`VfdMaster::alarm`]): [`VfdMap::fail_limit`] failed *writes* in a row
//!   (the torque reference cannot be delivered), or that many failed exchanges of any kind in
//!   a row (a silent drive: write, read, write). While it stands the reference written is the
//!   safe value, 0 %, and so is the analog one ([`VfdMaster::applied_torque_pct`]). Only a
//!   delivered reference (a write echoed exactly) clears it; a good read does not.
//! - **blind** ([`VfdMaster::blind`]): [`VfdMap::fail_limit`] failed *reads* in a row, or
//!   that many failed exchanges in all, or no read answered yet. The drive's readings are then
//!   invalid ([`VfdMaster::readings`] is `None`); the next good read makes them valid again.
//!   A drive that takes writes but fails reads leaves the link up and the controller blind.
//!
//! Requests come from `rmodbus`'s client; responses pass the crate's RTU gate
//! ([`crate::modbus::gate`]: length, unit, CRC) and are then checked here, strictly (function,
//! exact length, byte count, the write's echo): rmodbus's client parser is not used, for its
//! defects 5 to 7 listed in [`crate::modbus`].

use crate::modbus::{gate, Frame};
use rmodbus::client::ModbusRequest;
use rmodbus::ModbusProto;

/// Largest read block, registers.
pub const MAX_READ: u16 = 8;

/// Register map and link settings of one VFD.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VfdMap {
    /// Modbus unit (1..=247).
    pub unit: u8,
    /// Holding register of the torque reference (FC 06).
    pub torque_ref_register: u16,
    /// Counts for 100 % torque (e.g. 16384 or 10000), > 0.
    pub counts_per_100_pct: u16,
    /// First holding register of the read block (FC 03).
    pub read_start: u16,
    /// Registers in the read block (1..=8).
    pub read_count: u16,
    /// Offset of actual speed in the block.
    pub speed_offset: u16,
    /// rpm per count of actual speed (signed register), finite.
    pub rpm_per_count: f32,
    /// Offset of actual torque in the block (signed, same scaling as the reference).
    pub torque_offset: u16,
    /// Offset of the status word in the block.
    pub status_offset: u16,
    /// Time to wait for an answer, ms (> 0).
    pub timeout_ms: u32,
    /// Repeats of a request before the exchange fails.
    pub retries: u8,
    /// Failed exchanges in a row that raise the link alarm (≥ 1).
    pub fail_limit: u8,
    /// Shortest time from the start of one exchange to the start of the next, ms: the
    /// master's cycle. At 19 200 baud a write and its answer take ≈ 9 ms on the line, a read
    /// of three registers ≈ 10 ms, so 10 ms asks no more than a real link carries; 0 starts
    /// each exchange as soon as the last one ends.
    pub cycle_ms: u32,
}

impl VfdMap {
    /// A drive with 16384 counts = 100 % torque: reference at 0x2000, speed (1 rpm/count),
    /// torque and status at 0x2100..0x2102; 100 ms timeout, 2 retries, alarm after 3 failures,
    /// an exchange every 10 ms at most.
    pub const fn example_16384() -> Self {
        Self {
            unit: 1,
            torque_ref_register: 0x2000,
            counts_per_100_pct: 16384,
            read_start: 0x2100,
            read_count: 3,
            speed_offset: 0,
            rpm_per_count: 1.0,
            torque_offset: 1,
            status_offset: 2,
            timeout_ms: 100,
            retries: 2,
            fail_limit: 3,
            cycle_ms: 10,
        }
    }

    /// `true` if usable: unit 1..=247, counts > 0, block 1..=8 registers with every offset
    /// inside it, finite rpm scale, timeout > 0, fail limit ≥ 1.
    pub fn is_valid(&self) -> bool {
        (1..=247).contains(&self.unit)
            && self.counts_per_100_pct > 0
            && (1..=MAX_READ).contains(&self.read_count)
            && self.speed_offset < self.read_count
            && self.torque_offset < self.read_count
            && self.status_offset < self.read_count
            && self.rpm_per_count.is_finite()
            && self.timeout_ms > 0
            && self.fail_limit >= 1
    }

    /// Torque reference counts for `pct` (applied by the torque rule,
    /// [`model_core::units::applied_torque_pct`]: clamped to 0..=100 %, NaN → 0).
    pub fn torque_counts(&self, pct: f32) -> u16 {
        let pct = model_core::units::applied_torque_pct(pct);
        (pct / 100.0 * f32::from(self.counts_per_100_pct) + 0.5) as u16
    }
}

/// The torque reference applied for a requested one, %: the safe value 0 during the link
/// alarm, else the workspace's torque rule ([`model_core::units::applied_torque_pct`]:
/// clamped to 0..=100, +∞ → 100, −∞ and NaN → 0). The one rule for the master and the core
/// ([`crate::control::VfdStatus::applied_torque_pct`]).
pub fn applied_torque_pct(link_alarm: bool, requested_pct: f32) -> f32 {
    if link_alarm {
        0.0
    } else {
        model_core::units::applied_torque_pct(requested_pct)
    }
}

/// What the drive last reported.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VfdReadings {
    /// Actual speed, rpm.
    pub speed_rpm: f32,
    /// Actual torque, % of nominal.
    pub torque_pct: f32,
    /// Status word, as the vendor defines it.
    pub status: u16,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    WriteTorque(u16),
    Read,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Pending {
    kind: Kind,
    sent_ms: u32,
    attempt: u8,
    /// The write carries the requested reference (not the safe value instead of it).
    delivers_request: bool,
}

/// The master's state.
#[derive(Debug, Clone, PartialEq)]
pub struct VfdMaster {
    map: VfdMap,
    pending: Option<Pending>,
    /// When the last exchange started, ms (`None` before the first).
    last_start_ms: Option<u32>,
    next_is_write: bool,
    /// Failed exchanges in a row, of any kind (a success of either kind resets it).
    failures_in_row: u8,
    /// Failed torque writes in a row (only a delivered write resets it).
    write_failures_in_row: u8,
    /// Failed reads in a row (only a good read resets it).
    read_failures_in_row: u8,
    alarm: bool,
    /// During the alarm, a safe (0 %) write has been delivered: the next writes carry the
    /// requested reference, whose delivery clears the alarm.
    link_proven: bool,
    blind: bool,
    readings: VfdReadings,
    exchanges_ok: u32,
    reads_ok: u32,
}

impl VfdMaster {
    /// A master for `map`; `None` if the map is not valid. The link starts in alarm (nothing
    /// has answered yet), so the first reference written is 0 %.
    pub fn new(map: VfdMap) -> Option<Self> {
        map.is_valid().then_some(Self {
            map,
            pending: None,
            last_start_ms: None,
            next_is_write: true,
            failures_in_row: 0,
            write_failures_in_row: 0,
            read_failures_in_row: 0,
            alarm: true,
            link_proven: false,
            blind: true,
            readings: VfdReadings::default(),
            exchanges_ok: 0,
            reads_ok: 0,
        })
    }

    /// `true` while the link alarm stands: the torque reference cannot be delivered (see the
    /// module docs); the safe value, 0 %, is applied.
    pub fn alarm(&self) -> bool {
        self.alarm
    }

    /// `true` while the drive's readings are invalid: reads fail (or none has been answered
    /// yet), whether or not writes still get through.
    pub fn blind(&self) -> bool {
        self.blind
    }

    /// What the drive last reported; `None` while [`Self::blind`] (the last good values are
    /// stale and are not handed out).
    pub fn readings(&self) -> Option<VfdReadings> {
        (!self.blind).then_some(self.readings)
    }

    /// Successful exchanges so far.
    pub fn exchanges_ok(&self) -> u32 {
        self.exchanges_ok
    }

    /// Successful reads so far (wraps): a change means fresh readings.
    pub fn reads_ok(&self) -> u32 {
        self.reads_ok
    }

    /// The torque reference that is written for a requested one: 0 % during the link alarm
    /// (see [`applied_torque_pct`]).
    pub fn applied_torque_pct(&self, requested_pct: f32) -> f32 {
        applied_torque_pct(self.alarm, requested_pct)
    }

    /// Handles time: an unanswered request past its timeout is repeated (the frame to send is
    /// written to `out`) or, after the retries, the exchange fails. Call it every tick.
    pub fn poll(&mut self, now_ms: u32, out: &mut Frame) -> Option<usize> {
        out.clear();
        let p = self.pending?;
        if now_ms.wrapping_sub(p.sent_ms) < self.map.timeout_ms {
            return None;
        }
        if p.attempt < self.map.retries {
            self.pending = Some(Pending {
                attempt: p.attempt + 1,
                sent_ms: now_ms,
                ..p
            });
            self.request(p.kind, out)
        } else {
            self.pending = None;
            self.failed(p.kind);
            None
        }
    }

    /// Starts the next exchange if none is under way and [`VfdMap::cycle_ms`] has passed since
    /// the last one started: alternately the torque reference and the
    /// read block. During the alarm the reference written is 0 % until one such write is
    /// delivered, then `requested_pct` again: the alarm clears only when the requested
    /// reference itself is delivered, so a drive that takes 0 % but refuses the reference
    /// keeps the alarm (and the analog output at 0 %) instead of toggling it. The frame to
    /// send is written to `out`.
    pub fn start(&mut self, now_ms: u32, requested_pct: f32, out: &mut Frame) -> Option<usize> {
        out.clear();
        if self.pending.is_some() {
            return None;
        }
        if let Some(t) = self.last_start_ms {
            if now_ms.wrapping_sub(t) < self.map.cycle_ms {
                return None;
            }
        }
        self.last_start_ms = Some(now_ms);
        let requested = self.map.torque_counts(requested_pct);
        let (kind, delivers_request) = if self.next_is_write {
            // In the alarm: the safe value until the link takes a write, then the request.
            let counts = if self.alarm && !self.link_proven {
                0
            } else {
                requested
            };
            (Kind::WriteTorque(counts), counts == requested)
        } else {
            (Kind::Read, false)
        };
        self.next_is_write = !self.next_is_write;
        self.pending = Some(Pending {
            kind,
            sent_ms: now_ms,
            attempt: 0,
            delivers_request,
        });
        self.request(kind, out)
    }

    fn request(&self, kind: Kind, out: &mut Frame) -> Option<usize> {
        let mut req = ModbusRequest::new(self.map.unit, ModbusProto::Rtu);
        let made = match kind {
            Kind::WriteTorque(counts) => {
                req.generate_set_holding(self.map.torque_ref_register, counts, out)
            }
            Kind::Read => req.generate_get_holdings(self.map.read_start, self.map.read_count, out),
        };
        made.ok().map(|()| out.len())
    }

    fn failed(&mut self, kind: Kind) {
        let limit = self.map.fail_limit;
        if matches!(kind, Kind::WriteTorque(_)) {
            self.link_proven = false;
        }
        self.failures_in_row = self.failures_in_row.saturating_add(1);
        let of_kind = match kind {
            Kind::WriteTorque(_) => &mut self.write_failures_in_row,
            Kind::Read => &mut self.read_failures_in_row,
        };
        *of_kind = of_kind.saturating_add(1);
        let all = self.failures_in_row >= limit;
        self.alarm |= all || self.write_failures_in_row >= limit;
        self.blind |= all || self.read_failures_in_row >= limit;
    }

    fn succeeded(&mut self, p: Pending) {
        self.failures_in_row = 0;
        match p.kind {
            Kind::WriteTorque(_) => {
                self.write_failures_in_row = 0;
                if p.delivers_request {
                    self.alarm = false;
                    self.link_proven = false;
                } else {
                    self.link_proven = true;
                }
            }
            Kind::Read => {
                self.read_failures_in_row = 0;
                self.blind = false;
                self.reads_ok = self.reads_ok.wrapping_add(1);
            }
        }
        self.exchanges_ok = self.exchanges_ok.wrapping_add(1);
    }

    /// Takes a received frame. A valid answer to the pending request completes the exchange
    /// (a write clears the alarm, a read the blindness); an exception answer fails it;
    /// anything else (noise, another unit, bad CRC, wrong length, a write echoed with another
    /// value) is ignored and the request runs into its timeout.
    pub fn receive(&mut self, frame: &[u8]) {
        let Some(p) = self.pending else { return };
        match self.check(p.kind, frame) {
            Answer::Ignore => {}
            Answer::Exception => {
                self.pending = None;
                self.failed(p.kind);
            }
            Answer::Ok => {
                self.pending = None;
                self.succeeded(p);
            }
        }
    }

    fn check(&mut self, kind: Kind, f: &[u8]) -> Answer {
        let Some(pdu) = gate(f, self.map.unit) else {
            return Answer::Ignore;
        };
        let func = match kind {
            Kind::WriteTorque(_) => 6,
            Kind::Read => 3,
        };
        if pdu.function == func | 0x80 {
            return if pdu.data.len() == 1 {
                Answer::Exception
            } else {
                Answer::Ignore
            };
        }
        if pdu.function != func {
            return Answer::Ignore;
        }
        match kind {
            Kind::WriteTorque(counts) => {
                // The echo: register and value as written (the frame is then 8 bytes).
                let mut echo = [0u8; 4];
                echo[..2].copy_from_slice(&self.map.torque_ref_register.to_be_bytes());
                echo[2..].copy_from_slice(&counts.to_be_bytes());
                if pdu.data == echo {
                    Answer::Ok
                } else {
                    Answer::Ignore
                }
            }
            Kind::Read => {
                // Byte count, then exactly that many bytes: the block asked for.
                let bytes = 2 * usize::from(self.map.read_count);
                let Some((&count, words)) = pdu.data.split_first() else {
                    return Answer::Ignore;
                };
                if usize::from(count) != bytes || words.len() != bytes {
                    return Answer::Ignore;
                }
                let word = |i: u16| {
                    let at = 2 * usize::from(i);
                    words
                        .get(at..at + 2)
                        .map_or(0, |w| u16::from_be_bytes([w[0], w[1]]))
                };
                let m = &self.map;
                self.readings = VfdReadings {
                    speed_rpm: f32::from(word(m.speed_offset) as i16) * m.rpm_per_count,
                    torque_pct: f32::from(word(m.torque_offset) as i16) * 100.0
                        / f32::from(m.counts_per_100_pct),
                    status: word(m.status_offset),
                };
                Answer::Ok
            }
        }
    }
}

enum Answer {
    Ok,
    Exception,
    Ignore,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::crc16;

    /// The link alarm gives the safe value; otherwise the workspace's torque rule, the
    /// non-finite requests included (+∞ → 100 %, −∞ and NaN → 0 %), and the counts follow.
    #[test]
    fn applied_torque_is_the_safe_value_in_alarm_else_the_torque_rule() {
        let inf = f32::INFINITY;
        let cases = [
            (-5.0, 0.0),
            (0.0, 0.0),
            (42.5, 42.5),
            (100.0, 100.0),
            (150.0, 100.0),
            (inf, 100.0),
            (-inf, 0.0),
            (f32::NAN, 0.0),
        ];
        let map = VfdMap::example_16384();
        for (requested, applied) in cases {
            assert_eq!(applied_torque_pct(true, requested), 0.0, "{requested}");
            assert_eq!(applied_torque_pct(false, requested), applied, "{requested}");
            let counts = (applied / 100.0 * f32::from(map.counts_per_100_pct) + 0.5) as u16;
            assert_eq!(map.torque_counts(requested), counts, "{requested}");
        }
    }

    /// The example map without the cycle: each exchange starts as soon as the last one ends,
    /// so the tests step the link exchange by exchange.
    fn unpaced() -> VfdMap {
        VfdMap {
            cycle_ms: 0,
            ..VfdMap::example_16384()
        }
    }

    #[test]
    fn exchanges_start_no_more_often_than_the_cycle() {
        let mut m = VfdMaster::new(VfdMap::example_16384()).unwrap();
        let mut out = Frame::new();
        let mut started = vec![];
        for t in 0..100u32 {
            if m.start(t, 50.0, &mut out).is_some() {
                started.push(t);
                // The drive answers the write at once (echo) or the read with 3 registers.
                let mut answer = Frame::new();
                if out[1] == 6 {
                    answer.extend_from_slice(&out).unwrap();
                } else {
                    let body = [1u8, 3, 6, 0, 100, 0, 50, 0, 1];
                    answer.extend_from_slice(&body).unwrap();
                    let crc = crate::modbus::crc16(&body);
                    answer.extend_from_slice(&crc.to_le_bytes()).unwrap();
                }
                m.receive(&answer);
            }
        }
        assert_eq!(started, (0..100).step_by(10).collect::<Vec<u32>>());
        assert!(!m.alarm() && m.readings().is_some());
    }

    fn with_crc(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    /// A fake drive: holding registers from 0x2000 (reference) and 0x2100 (speed, torque,
    /// status); answers FC 06 and FC 03 like a real one.
    struct Drive {
        reference: u16,
        block: [u16; 3],
    }

    impl Drive {
        fn answer(&mut self, req: &[u8]) -> Vec<u8> {
            match req[1] {
                6 => {
                    self.reference = u16::from_be_bytes([req[4], req[5]]);
                    req.to_vec()
                }
                3 => {
                    let mut body = vec![req[0], 3, 6];
                    for w in self.block {
                        body.extend_from_slice(&w.to_be_bytes());
                    }
                    with_crc(&body)
                }
                _ => with_crc(&[req[0], req[1] | 0x80, 1]),
            }
        }
    }

    /// One full exchange answered by `drive`; returns the request sent.
    fn exchange(m: &mut VfdMaster, d: &mut Drive, now: u32, pct: f32) -> Vec<u8> {
        let mut out = Frame::new();
        let n = m.start(now, pct, &mut out).expect("a request");
        let req = out[..n].to_vec();
        let ans = d.answer(&req);
        m.receive(&ans);
        req
    }

    #[test]
    fn cycles_write_then_read_and_scale() {
        let mut m = VfdMaster::new(unpaced()).unwrap();
        let mut d = Drive {
            reference: 999,
            block: [1500, (-4096i16) as u16, 0x0037],
        };
        assert!(m.alarm(), "nothing answered yet");
        exchange(&mut m, &mut d, 0, 50.0);
        assert_eq!(d.reference, 0, "the first write is the safe value");
        assert!(
            m.alarm(),
            "the link takes writes, but the request is not delivered yet"
        );
        exchange(&mut m, &mut d, 10, 50.0);
        assert_eq!(
            m.readings(),
            Some(VfdReadings {
                speed_rpm: 1500.0,
                torque_pct: -25.0,
                status: 0x37
            })
        );
        exchange(&mut m, &mut d, 20, 50.0);
        assert_eq!(d.reference, 8192);
        assert!(!m.alarm(), "the request delivered");
        let mut m10 = unpaced();
        m10.counts_per_100_pct = 10_000;
        assert_eq!(m10.torque_counts(50.0), 5000);
        assert_eq!(m10.torque_counts(f32::NAN), 0);
        assert_eq!(m10.torque_counts(150.0), 10_000);
        assert_eq!(m.exchanges_ok(), 3);
    }

    #[test]
    fn three_failed_exchanges_raise_the_alarm_and_force_zero() {
        let mut m = VfdMaster::new(unpaced()).unwrap();
        let mut d = Drive {
            reference: 0,
            block: [0; 3],
        };
        for _ in 0..3 {
            exchange(&mut m, &mut d, 0, 60.0);
        }
        assert!(!m.alarm());
        let mut out = Frame::new();
        let mut now = 1000;
        for failure in 1..=3 {
            let first = m.start(now, 60.0, &mut out).unwrap();
            let sent = out[..first].to_vec();
            // Two retries, each after the timeout, resend the same frame.
            for _ in 0..2 {
                assert_eq!(m.poll(now + 99, &mut out), None, "not yet");
                now += 100;
                let n = m.poll(now, &mut out).expect("a retry");
                assert_eq!(&out[..n], &sent[..]);
            }
            now += 100;
            assert_eq!(m.poll(now, &mut out), None, "exchange {failure} failed");
            assert_eq!(m.alarm(), failure >= 3);
        }
        assert_eq!(m.applied_torque_pct(60.0), 0.0);
        // The next write carries the safe value; its answer proves the link, and the write
        // after it, the request, brings the link back.
        let mut next_write = |m: &mut VfdMaster, now: &mut u32| loop {
            let n = m.start(*now, 60.0, &mut out).unwrap();
            if out[1] == 6 {
                break out[..n].to_vec();
            }
            for _ in 0..3 {
                *now += 100;
                m.poll(*now, &mut out);
            }
        };
        let write = next_write(&mut m, &mut now);
        assert_eq!(u16::from_be_bytes([write[4], write[5]]), 0);
        m.receive(&d.answer(&write));
        assert!(m.alarm(), "0 % delivered is not the request delivered");
        assert_eq!(m.applied_torque_pct(60.0), 0.0);
        let write = next_write(&mut m, &mut now);
        assert_eq!(u16::from_be_bytes([write[4], write[5]]), 9830, "60 %");
        m.receive(&d.answer(&write));
        assert!(!m.alarm());
        assert_eq!(m.applied_torque_pct(60.0), 60.0);
    }

    /// Regression (review): a drive that takes 0 % but refuses every other reference (its
    /// scaling differs from the map's) used to clear the alarm on each 0 % write and raise it
    /// again 0.9 s later, so the analog output pulsed to the request and back. The alarm now
    /// stands, and the output stays at 0 %, until the request itself is delivered.
    #[test]
    fn a_drive_that_refuses_all_but_zero_keeps_the_alarm() {
        let mut m = VfdMaster::new(unpaced()).unwrap();
        let mut d = Drive {
            reference: 0,
            block: [0; 3],
        };
        let mut out = Frame::new();
        let mut toggles = 0;
        let mut was = m.alarm();
        for now in 0..10_000u32 {
            let mut sent = m.poll(now, &mut out).map(|n| out[..n].to_vec());
            if sent.is_none() {
                sent = m.start(now, 70.0, &mut out).map(|n| out[..n].to_vec());
            }
            if let Some(req) = sent {
                let refuse = req[1] == 6 && u16::from_be_bytes([req[4], req[5]]) > 0;
                m.receive(&if refuse {
                    with_crc(&[req[0], 0x86, 3])
                } else {
                    d.answer(&req)
                });
            }
            assert_eq!(m.applied_torque_pct(70.0), 0.0, "at {now} ms");
            toggles += usize::from(m.alarm() != was);
            was = m.alarm();
        }
        assert!(m.alarm());
        assert_eq!(toggles, 0, "the alarm never cleared");
    }

    #[test]
    fn exceptions_fail_the_exchange_and_junk_is_ignored() {
        let mut m = VfdMaster::new(unpaced()).unwrap();
        let mut d = Drive {
            reference: 0,
            block: [0; 3],
        };
        exchange(&mut m, &mut d, 0, 10.0); // link up
        let mut out = Frame::new();
        m.start(0, 10.0, &mut out).unwrap(); // a read is pending
        let good = d.answer(&out);
        let mut bad_crc = good.clone();
        bad_crc[4] ^= 1;
        let mut long = good.clone();
        long.insert(5, 0);
        let junk: Vec<Vec<u8>> = vec![
            vec![],
            vec![1, 3],
            with_crc(&[1, 3, 0]), // empty payload: rmodbus's parser panics here
            with_crc(&[1, 3, 2, 0, 1]), // byte count short of the block
            with_crc(&[2, 3, 6, 0, 1, 0, 2, 0, 3]), // another unit
            with_crc(&[1, 4, 6, 0, 1, 0, 2, 0, 3]), // another function
            with_crc(&[1, 0x83, 2, 9]), // exception with extra bytes
            bad_crc,
            long,
            vec![0xFF; 256],
        ];
        for f in &junk {
            m.receive(f);
            assert_eq!(m.exchanges_ok(), 1, "{f:?}");
        }
        m.receive(&good);
        assert_eq!(m.exchanges_ok(), 2);
        // An exception answer fails the exchange at once (no retries).
        m.start(0, 10.0, &mut out).unwrap();
        m.receive(&with_crc(&[1, 0x86, 4]));
        assert_eq!(
            m.start(0, 10.0, &mut out).map(|_| out[1]),
            Some(3),
            "next exchange starts"
        );
    }

    /// How a faulty drive misbehaves (each seen in a hostile run against the firmware).
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Fault {
        /// Answers reads; rejects every write with exception 04.
        RejectWrites,
        /// Answers reads; never answers a write.
        SilentOnWrites,
        /// Answers reads; echoes another value (0x3FFF) to a write.
        EchoWrongValue,
        /// Answers writes; answers reads with a wrong byte count.
        BadReadByteCount,
        /// Answers writes; never answers a read.
        SilentOnReads,
    }

    impl Drive {
        fn faulty_answer(&mut self, req: &[u8], fault: Fault) -> Option<Vec<u8>> {
            let good = self.answer(req);
            match (fault, req[1]) {
                (Fault::RejectWrites, 6) => Some(with_crc(&[req[0], 0x86, 4])),
                (Fault::SilentOnWrites, 6) | (Fault::SilentOnReads, 3) => None,
                (Fault::EchoWrongValue, 6) => {
                    let mut body = req[..6].to_vec();
                    body[4..6].copy_from_slice(&0x3FFFu16.to_be_bytes());
                    Some(with_crc(&body))
                }
                (Fault::BadReadByteCount, 3) => {
                    let mut body = good[..good.len() - 2].to_vec();
                    body[2] = 4;
                    Some(with_crc(&body))
                }
                _ => Some(good),
            }
        }
    }

    /// Runs the master against `drive` for `ms` milliseconds from `*now`, answering each
    /// request at once (or never) as `fault` says; `pct` requested throughout.
    fn run_against(
        m: &mut VfdMaster,
        d: &mut Drive,
        fault: Option<Fault>,
        now: &mut u32,
        ms: u32,
        pct: f32,
    ) {
        let mut out = Frame::new();
        for _ in 0..ms {
            let mut sent = m.poll(*now, &mut out).map(|n| out[..n].to_vec());
            if sent.is_none() {
                sent = m.start(*now, pct, &mut out).map(|n| out[..n].to_vec());
            }
            if let Some(req) = sent {
                let ans = match fault {
                    Some(f) => d.faulty_answer(&req, f),
                    None => Some(d.answer(&req)),
                };
                if let Some(a) = ans {
                    m.receive(&a);
                }
            }
            *now += 1;
        }
    }

    /// Regression (hostile run): exchanges alternate write and read, and a good read used to
    /// reset the failure count, so a drive failing only writes kept the link "ok" and the
    /// torque applied. A reference that cannot be delivered must raise the alarm and force
    /// the safe value; a drive that takes writes but fails reads must leave the link up and
    /// flag its readings invalid (the controller is blind to it).
    #[test]
    fn a_drive_failing_one_kind_of_exchange_is_caught() {
        for fault in [
            Fault::RejectWrites,
            Fault::SilentOnWrites,
            Fault::EchoWrongValue,
            Fault::BadReadByteCount,
            Fault::SilentOnReads,
        ] {
            let mut m = VfdMaster::new(unpaced()).unwrap();
            let mut d = Drive {
                reference: 0,
                block: [1234, 8192, 7],
            };
            let mut now = 0;
            run_against(&mut m, &mut d, None, &mut now, 50, 50.0);
            assert!(!m.alarm() && !m.blind(), "{fault:?}: link up");
            assert_eq!(m.readings().map(|r| r.status), Some(7));
            assert_eq!(m.applied_torque_pct(50.0), 50.0);
            // Three failed exchanges of one kind, each 3 attempts of 100 ms, alternating with
            // the other kind: well within 3 s.
            run_against(&mut m, &mut d, Some(fault), &mut now, 3000, 50.0);
            let writes_fail = matches!(
                fault,
                Fault::RejectWrites | Fault::SilentOnWrites | Fault::EchoWrongValue
            );
            assert_eq!(m.alarm(), writes_fail, "{fault:?}: link alarm");
            assert_eq!(
                m.applied_torque_pct(50.0),
                if writes_fail { 0.0 } else { 50.0 },
                "{fault:?}: applied torque"
            );
            assert_eq!(m.blind(), !writes_fail, "{fault:?}: blind");
            assert_eq!(m.readings().is_none(), !writes_fail, "{fault:?}: readings");
            // The drive healed: the alarm clears on a delivered reference, the readings come
            // back on a good read.
            run_against(&mut m, &mut d, None, &mut now, 50, 50.0);
            assert!(!m.alarm() && !m.blind(), "{fault:?}: back");
            assert_eq!(d.reference, 8192, "{fault:?}: 50 % delivered again");
        }
    }

    /// A silent drive raises the alarm and invalidates the readings together, after the
    /// configured number of failed exchanges (3: write, read, write), not later.
    #[test]
    fn a_silent_drive_raises_the_alarm_after_fail_limit_exchanges() {
        let mut m = VfdMaster::new(unpaced()).unwrap();
        let mut d = Drive {
            reference: 0,
            block: [1234, 8192, 7],
        };
        let mut now = 0;
        run_against(&mut m, &mut d, None, &mut now, 10, 50.0);
        assert!(m.readings().is_some());
        let mut out = Frame::new();
        let mut t = 0;
        loop {
            if m.poll(now, &mut out).is_none() {
                m.start(now, 50.0, &mut out);
            }
            if m.alarm() {
                break;
            }
            now += 1;
            t += 1;
            assert!(t <= 900, "alarm later than 3 exchanges of 300 ms");
        }
        assert_eq!(t, 900, "alarm after 3 exchanges of 3 × 100 ms");
        assert!(
            m.blind() && m.readings().is_none(),
            "readings invalid with the alarm"
        );
    }

    #[test]
    fn bad_maps_are_refused() {
        let ok = VfdMap::example_16384();
        for bad in [
            VfdMap { unit: 0, ..ok },
            VfdMap {
                counts_per_100_pct: 0,
                ..ok
            },
            VfdMap {
                read_count: 9,
                ..ok
            },
            VfdMap {
                status_offset: 3,
                ..ok
            },
            VfdMap {
                rpm_per_count: f32::INFINITY,
                ..ok
            },
            VfdMap {
                timeout_ms: 0,
                ..ok
            },
            VfdMap {
                fail_limit: 0,
                cycle_ms: 10,
                ..ok
            },
        ] {
            assert!(VfdMaster::new(bad).is_none(), "{bad:?}");
        }
    }
}
