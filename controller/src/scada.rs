//! The SCADA side: a Modbus RTU slave with the controller's register map.
//!
//! | input register (FC 04) | meaning | unit |
//! |---|---|---|
//! | 0 | status bits: 0 running, 1 any alarm, 2 model extrapolating, 3 VFD link ok (the torque reference is delivered), 4 pressure transmitter fault, 5 flow transmitter fault, 6 VFD readings invalid (reads fail: registers 14-16 read 0) | |
//! | 1 | applied torque reference | 0.01 % |
//! | 2 | measured pressure | 0.001 mca, signed |
//! | 3 | measured flow | 0.01 l/s |
//! | 4 | white-box predicted pressure | 0.001 mca, signed |
//! | 5 | white-box predicted flow | 0.01 l/s |
//! | 6 | white-box speed | 0.1 rpm |
//! | 7 | NARMAX predicted pressure | 0.001 mca, signed |
//! | 8 | NARMAX predicted flow | 0.01 l/s |
//! | 9 | sample counter (wraps) | |
//! | 10 | white-box pressure residual (measured − predicted) | 0.001 mca, signed |
//! | 11 | white-box flow residual | 0.01 l/s, signed |
//! | 12 | NARMAX pressure residual | 0.001 mca, signed |
//! | 13 | NARMAX flow residual | 0.01 l/s, signed |
//! | 14 | VFD actual speed (read over the VFD link; 0 while status bit 6 is set) | 0.1 rpm, signed |
//! | 15 | VFD actual torque (0 while bit 6 is set) | 0.01 %, signed |
//! | 16 | VFD status word, the vendor's bits (0 while bit 6 is set) | |
//! | 17 | uptime (wraps) | s |
//! | 18 | observer speed | 0.1 rpm |
//! | 19 | observer flow | 0.01 l/s |
//! | 20 | observer valve coefficient k2 (0.1082 → 10820) | 1e-5 |
//! | 21 | alarm bits ([`model_core::monitor`]): 0 pressure transmitter, 1 flow transmitter, 2 VFD link, 3 dry run, 4 no flow, 5 end of curve, 6 load changed, 7 model residual | |
//! | 22 | observer flow standard deviation | 0.01 l/s |
//!
//! | holding register (FC 03, 06, 16) | meaning | range |
//! |---|---|---|
//! | 0 | torque setpoint, 0.01 % | 0..=10000 |
//! | 1 | mode: 0 stop, 1 manual setpoint, 2 built-in excitation profile; writing 0 also acknowledges the latched alarms whose cause has gone | 0..=2 |
//! | 2 | NARMAX arithmetic: 0 f32, 1 fixed point | 0..=1 |
//! | 3 | virtual bench only: its valve, k2 in 0.1 % of nominal (1000 = nominal) | 500..=2000 |
//! | 4 | virtual bench only: fault injection bits: 0 dry run, 1 pressure transmitter at 2 mA, 2 flow transmitter at 2 mA, 3 VFD link cut | 0..=15 |
//!
//! Holding registers 3 and 4 exist only with a virtual bench ([`ScadaSlave::with_virtual_bench`]):
//! on a board without one they answer exception 02 like any address outside the map.
//!
//! Exceptions as the Modbus spec says: 01 illegal function (anything but 03, 04, 06, 16, whatever
//! its fields),
//! 02 illegal data address (a range outside the map), 03 illegal data value (a quantity of 0 or
//! above the limit, a byte count that does not match, a setpoint above 10000, an unknown mode).
//! A write with any bad value changes nothing. Frames with a bad CRC, for another unit
//! (broadcasts included), too short or too long get no answer and leave no state behind.
//!
//! `rmodbus` is the codec (parsing, responses, CRC); this module checks the RTU frame's exact
//! length and CRC first, because rmodbus answers an unknown function without checking the CRC
//! and ignores bytes after a valid frame, and it drops function codes 128..=255 (the exception
//! space), on which rmodbus 0.13 overflows.

use rmodbus::server::{ModbusFrame, Read, Write};
use rmodbus::{ErrorKind, ModbusProto};

/// Input registers.
pub const INPUT_REGISTERS: usize = 23;
/// Holding registers with a virtual bench (3 without).
pub const HOLDING_REGISTERS: usize = 5;
/// Holding registers on a board without a virtual bench.
pub const BOARD_HOLDING_REGISTERS: usize = 3;
/// Virtual bench valve, 0.1 % of nominal k2: nominal.
pub const VALVE_NOMINAL_PERMILLE: u16 = 1000;
/// Virtual bench valve: the range, 0.1 % of nominal k2.
pub const VALVE_RANGE_PERMILLE: core::ops::RangeInclusive<u16> = 500..=2000;
/// Fault injection bit: the virtual pump runs dry.
pub const FAULT_DRY_RUN: u16 = 1 << 0;
/// Fault injection bit: the pressure transmitter at 2 mA.
pub const FAULT_PRESSURE_2MA: u16 = 1 << 1;
/// Fault injection bit: the flow transmitter at 2 mA.
pub const FAULT_FLOW_2MA: u16 = 1 << 2;
/// Fault injection bit: the virtual VFD link cut.
pub const FAULT_VFD_LINK: u16 = 1 << 3;
/// Largest torque setpoint, 0.01 %.
pub const SETPOINT_MAX: u16 = 10_000;
/// Longest RTU frame (Modbus: 256 bytes).
pub const MAX_FRAME: usize = 256;
/// A response buffer.
pub type Response = heapless::Vec<u8, MAX_FRAME>;

/// Operating mode (holding register 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Torque reference 0.
    #[default]
    Stop = 0,
    /// Torque reference = the setpoint.
    Manual = 1,
    /// The built-in excitation profile (the paper's pulses).
    Profile = 2,
}

/// Arithmetic of the NARMAX pass (holding register 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Arithmetic {
    /// f32 forward pass.
    #[default]
    F32 = 0,
    /// Fixed point (the Q15 pass, `NarxQ15`).
    Fixed = 1,
}

impl Arithmetic {
    /// The name used in logs and options: `f32` or `q15`.
    pub fn name(self) -> &'static str {
        match self {
            Arithmetic::F32 => "f32",
            Arithmetic::Fixed => "q15",
        }
    }

    /// The arithmetic of a [`Self::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "f32" => Some(Arithmetic::F32),
            "q15" => Some(Arithmetic::Fixed),
            _ => None,
        }
    }
}

impl Mode {
    /// The name used in logs: `stop`, `manual` or `profile`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Stop => "stop",
            Mode::Manual => "manual",
            Mode::Profile => "profile",
        }
    }

    fn from_register(v: u16) -> Option<Self> {
        match v {
            0 => Some(Mode::Stop),
            1 => Some(Mode::Manual),
            2 => Some(Mode::Profile),
            _ => None,
        }
    }
}

/// Status bits of input register 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Status {
    /// Bit 0: the drive is commanded to run.
    pub running: bool,
    /// Bit 1: any alarm.
    pub any_alarm: bool,
    /// Bit 2: a model runs outside its fitted/training range.
    pub extrapolating: bool,
    /// Bit 3: the VFD link delivers the torque reference (no link alarm).
    pub vfd_link_ok: bool,
    /// Bit 4: pressure transmitter fault (NAMUR NE 43).
    pub pressure_fault: bool,
    /// Bit 5: flow transmitter fault.
    pub flow_fault: bool,
    /// Bit 6: the drive's readings are invalid (its reads fail, or the link is down): the
    /// controller is blind to the drive, and input registers 14-16 read 0.
    pub vfd_readings_invalid: bool,
}

impl Status {
    /// The register value.
    pub fn bits(&self) -> u16 {
        [
            self.running,
            self.any_alarm,
            self.extrapolating,
            self.vfd_link_ok,
            self.pressure_fault,
            self.flow_fault,
            self.vfd_readings_invalid,
        ]
        .iter()
        .enumerate()
        .fold(0, |acc, (i, &b)| acc | (u16::from(b) << i))
    }
}

/// What the controller publishes, in engineering units (converted and clamped here).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Published {
    /// Status bits.
    pub status: Status,
    /// Applied torque reference, %.
    pub torque_pct: f32,
    /// Measured pressure, mca.
    pub pressure_mca: f32,
    /// Measured flow, l/s.
    pub flow_lps: f32,
    /// White-box predicted pressure, mca.
    pub whitebox_pressure_mca: f32,
    /// White-box predicted flow, l/s.
    pub whitebox_flow_lps: f32,
    /// White-box speed, rpm.
    pub whitebox_speed_rpm: f32,
    /// NARMAX predicted pressure, mca.
    pub narmax_pressure_mca: f32,
    /// NARMAX predicted flow, l/s.
    pub narmax_flow_lps: f32,
    /// Sample counter.
    pub sample: u16,
    /// White-box pressure residual, mca.
    pub whitebox_pressure_residual_mca: f32,
    /// White-box flow residual, l/s.
    pub whitebox_flow_residual_lps: f32,
    /// NARMAX pressure residual, mca.
    pub narmax_pressure_residual_mca: f32,
    /// NARMAX flow residual, l/s.
    pub narmax_flow_residual_lps: f32,
    /// VFD actual speed, rpm.
    pub vfd_speed_rpm: f32,
    /// VFD actual torque, %.
    pub vfd_torque_pct: f32,
    /// VFD status word.
    pub vfd_status: u16,
    /// Uptime, s.
    pub uptime_s: u16,
    /// Observer speed, rpm.
    pub observer_speed_rpm: f32,
    /// Observer flow, l/s.
    pub observer_flow_lps: f32,
    /// Observer valve coefficient k2.
    pub observer_valve_k2: f32,
    /// Alarm bits (see the module table).
    pub alarms: u16,
    /// Observer flow standard deviation, l/s.
    pub observer_flow_sd_lps: f32,
}

/// `x · scale` rounded and clamped to 0..=u16::MAX; NaN gives 0.
pub fn unsigned_register(x: f32, scale: f32) -> u16 {
    let v = x * scale;
    if v.is_nan() {
        0
    } else {
        (v + 0.5).clamp(0.0, f32::from(u16::MAX)) as u16
    }
}

/// `x · scale` rounded and clamped to i16, as the register's two's-complement bits; NaN
/// gives 0.
pub fn signed_register(x: f32, scale: f32) -> u16 {
    let v = x * scale;
    if v.is_nan() {
        0
    } else {
        let r = if v < 0.0 { v - 0.5 } else { v + 0.5 };
        r.clamp(f32::from(i16::MIN), f32::from(i16::MAX)) as i16 as u16
    }
}

impl Published {
    /// The input registers.
    pub fn registers(&self) -> [u16; INPUT_REGISTERS] {
        [
            self.status.bits(),
            unsigned_register(self.torque_pct, 100.0).min(SETPOINT_MAX),
            signed_register(self.pressure_mca, 1000.0),
            unsigned_register(self.flow_lps, 100.0),
            signed_register(self.whitebox_pressure_mca, 1000.0),
            unsigned_register(self.whitebox_flow_lps, 100.0),
            unsigned_register(self.whitebox_speed_rpm, 10.0),
            signed_register(self.narmax_pressure_mca, 1000.0),
            unsigned_register(self.narmax_flow_lps, 100.0),
            self.sample,
            signed_register(self.whitebox_pressure_residual_mca, 1000.0),
            signed_register(self.whitebox_flow_residual_lps, 100.0),
            signed_register(self.narmax_pressure_residual_mca, 1000.0),
            signed_register(self.narmax_flow_residual_lps, 100.0),
            signed_register(self.vfd_speed_rpm, 10.0),
            signed_register(self.vfd_torque_pct, 100.0),
            self.vfd_status,
            self.uptime_s,
            unsigned_register(self.observer_speed_rpm, 10.0),
            unsigned_register(self.observer_flow_lps, 100.0),
            unsigned_register(self.observer_valve_k2, 1e5),
            self.alarms,
            unsigned_register(self.observer_flow_sd_lps, 100.0),
        ]
    }
}

/// CRC-16/MODBUS of `data`.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc = 0xFFFFu16;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// The exact RTU length of a request (unit, function, body, CRC), or `None` when the frame
/// does not say (too short to tell). Unknown functions have no fixed length: any CRC-valid
/// frame of ≥ 4 bytes is taken as one.
fn expected_len(frame: &[u8]) -> Option<usize> {
    match *frame.get(1)? {
        1..=6 => Some(8),
        15 | 16 => frame.get(6).map(|&n| 9 + usize::from(n)),
        _ => Some(frame.len()),
    }
}

/// `true` if `frame` is a whole request by its content alone: a function whose request length
/// is fixed by its fields (01..06, 15, 16), exactly that long, with a valid CRC; for any unit,
/// so that traffic to other slaves on the bus is framed too. A frame of another function, or
/// one that is not yet (or no longer) whole, gives `false`: it is ended by the silence.
pub fn request_complete(frame: &[u8]) -> bool {
    let n = frame.len();
    n >= 8
        && matches!(frame[1], 1..=6 | 15 | 16)
        && expected_len(frame) == Some(n)
        && crc16(&frame[..n - 2]) == u16::from_le_bytes([frame[n - 2], frame[n - 1]])
}

/// Where a whole request ([`request_complete`]) ends `bytes`, if one does: its start. On a
/// line that marks no silence (QEMU's serial ports), a valid request that follows noise with
/// no gap is still found this way. The odds that noise passes for a request are those of a
/// valid CRC with a known function and length: about 2⁻²¹ per byte. While the bytes from
/// the start may still become a whole request (a known function whose length is not reached
/// yet), nothing inside them is taken for one, so a long write is never cut short by a
/// request-like run of bytes in its data.
pub fn request_at_end(bytes: &[u8]) -> Option<usize> {
    let n = bytes.len();
    let growing = matches!(bytes.get(1), Some(1..=6 | 15 | 16))
        && expected_len(bytes).is_none_or(|want| want > n);
    if growing {
        return None;
    }
    if request_complete(bytes) {
        return Some(0);
    }
    // Fixed-length requests (01..06) are 8 bytes; 15 and 16 carry their byte count at 6.
    if n >= 8 && request_complete(&bytes[n - 8..]) {
        return Some(n - 8);
    }
    (0..n.saturating_sub(10))
        .rev()
        .find(|&start| matches!(bytes[start + 1], 15 | 16) && request_complete(&bytes[start..]))
}

/// The slave: its unit address and holding registers; the input registers are handed in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScadaSlave {
    unit: u8,
    /// Torque setpoint, 0.01 % (0..=10000).
    pub setpoint: u16,
    /// Mode.
    pub mode: Mode,
    /// NARMAX arithmetic.
    pub arithmetic: Arithmetic,
    /// Holding registers 3 and 4 exist (a virtual bench).
    virtual_bench: bool,
    /// Virtual bench valve, 0.1 % of nominal k2 (500..=2000).
    pub valve_permille: u16,
    /// Virtual bench fault injection bits (0..=15).
    pub faults: u16,
    /// Writes of mode 0 (stop) so far (wraps): each acknowledges the latched alarms.
    pub stop_writes: u16,
}

impl ScadaSlave {
    /// A slave at `unit` (1..=247), stopped, setpoint 0; `None` for another address.
    pub fn new(unit: u8) -> Option<Self> {
        (1..=247).contains(&unit).then_some(Self {
            unit,
            setpoint: 0,
            mode: Mode::Stop,
            arithmetic: Arithmetic::F32,
            virtual_bench: false,
            valve_permille: VALVE_NOMINAL_PERMILLE,
            faults: 0,
            stop_writes: 0,
        })
    }

    /// The slave with holding registers 3 and 4 (the virtual bench's valve and faults).
    pub fn with_virtual_bench(mut self) -> Self {
        self.virtual_bench = true;
        self
    }

    /// The holding registers (the last two exist only with a virtual bench).
    pub fn holding(&self) -> [u16; HOLDING_REGISTERS] {
        [
            self.setpoint,
            self.mode as u16,
            self.arithmetic as u16,
            self.valve_permille,
            self.faults,
        ]
    }

    fn holding_count(&self) -> usize {
        if self.virtual_bench {
            HOLDING_REGISTERS
        } else {
            BOARD_HOLDING_REGISTERS
        }
    }

    /// Handles one received RTU frame (the bytes between two silences). Returns the response
    /// to send, or `None` for silence.
    pub fn handle(
        &mut self,
        frame: &[u8],
        inputs: &[u16; INPUT_REGISTERS],
        response: &mut Response,
    ) -> Option<usize> {
        response.clear();
        // Function codes 128..=255 are the exception space, never a request; rmodbus 0.13 would
        // overflow on them (`responding_to_fn + 0x80`, found by tests/frames.rs).
        if frame.len() < 4 || frame.len() > MAX_FRAME || frame[0] != self.unit || frame[1] >= 0x80 {
            return None;
        }
        if expected_len(frame)? != frame.len() {
            return None;
        }
        let n = frame.len();
        if crc16(&frame[..n - 2]) != u16::from_le_bytes([frame[n - 2], frame[n - 1]]) {
            return None;
        }
        let func = frame[1];
        if !matches!(func, 3 | 4 | 6 | 16) {
            // Illegal function, whatever the fields: rmodbus would check a coil function's
            // quantity first and answer 03.
            let body = [self.unit, func | 0x80, 1];
            response.extend_from_slice(&body).ok()?;
            response
                .extend_from_slice(&crc16(&body).to_le_bytes())
                .ok()?;
            return Some(response.len());
        }
        let mut mf = ModbusFrame::new(self.unit, frame, ModbusProto::Rtu, response)
            .with_broadcast_units(&[]);
        mf.parse().ok()?;
        if !mf.response_required {
            return None;
        }
        if mf.processing_required {
            let result = match func {
                3 | 4 if mf.count == 0 => Err(ErrorKind::IllegalDataValue),
                16 if mf.count == 0 || usize::from(frame[6]) != 2 * usize::from(mf.count) => {
                    Err(ErrorKind::IllegalDataValue)
                }
                3 | 4 => {
                    let holding = self.holding();
                    let table: &[u16] = if func == 4 {
                        inputs
                    } else {
                        &holding[..self.holding_count()]
                    };
                    match mf.get_external_read() {
                        Ok(Read::Words(r)) => read_words(table, r.address, r.count, r.buf),
                        Ok(Read::Bits(_)) | Err(_) => Err(ErrorKind::IllegalFunction),
                    }
                }
                6 | 16 => match mf.get_external_write() {
                    Ok(Write::Words(w)) => self.write_words(w.address, w.count, w.data),
                    Ok(Write::Bits(_)) | Err(_) => Err(ErrorKind::IllegalFunction),
                },
                _ => Err(ErrorKind::IllegalFunction),
            };
            let done = if func == 3 || func == 4 {
                if result.is_err() {
                    // Drop the partial read response: only the exception goes out.
                    mf.response.clear();
                }
                mf.process_external_read(result)
            } else {
                mf.process_external_write(result)
            };
            done.ok()?;
        }
        mf.finalize_response().ok()?;
        Some(response.len())
    }

    /// Applies a write of `count` registers at `address` (big-endian `data`), all or nothing.
    fn write_words(&mut self, address: u16, count: u16, data: &[u8]) -> Result<(), ErrorKind> {
        let end = usize::from(address) + usize::from(count);
        if end > self.holding_count() {
            return Err(ErrorKind::IllegalDataAddress);
        }
        let mut next = *self;
        for (k, word) in data.chunks_exact(2).take(usize::from(count)).enumerate() {
            let v = u16::from_be_bytes([word[0], word[1]]);
            match usize::from(address) + k {
                0 if v <= SETPOINT_MAX => next.setpoint = v,
                1 => {
                    next.mode = Mode::from_register(v).ok_or(ErrorKind::IllegalDataValue)?;
                    if next.mode == Mode::Stop {
                        next.stop_writes = next.stop_writes.wrapping_add(1);
                    }
                }
                2 => {
                    next.arithmetic = match v {
                        0 => Arithmetic::F32,
                        1 => Arithmetic::Fixed,
                        _ => return Err(ErrorKind::IllegalDataValue),
                    }
                }
                3 if VALVE_RANGE_PERMILLE.contains(&v) => next.valve_permille = v,
                4 if v <= 15 => next.faults = v,
                _ => return Err(ErrorKind::IllegalDataValue),
            }
        }
        *self = next;
        Ok(())
    }
}

fn read_words(table: &[u16], address: u16, count: u16, buf: &mut [u8]) -> Result<(), ErrorKind> {
    let start = usize::from(address);
    let end = start + usize::from(count);
    let words = table.get(start..end).ok_or(ErrorKind::IllegalDataAddress)?;
    for (out, w) in buf.chunks_exact_mut(2).zip(words) {
        out.copy_from_slice(&w.to_be_bytes());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    fn ask(s: &mut ScadaSlave, f: &[u8]) -> Option<Vec<u8>> {
        let inputs: [u16; INPUT_REGISTERS] = core::array::from_fn(|i| 100 + i as u16);
        let mut r = Response::new();
        s.handle(f, &inputs, &mut r).map(|n| r[..n].to_vec())
    }

    fn exception(s: &mut ScadaSlave, body: &[u8]) -> u8 {
        let r = ask(s, &frame(body)).expect("an answer");
        assert_eq!(r.len(), 5, "{r:?}");
        assert_eq!(r[1], body[1] | 0x80);
        assert_eq!(crc16(&r[..3]).to_le_bytes(), [r[3], r[4]]);
        r[2]
    }

    #[test]
    fn crc_matches_the_spec_example() {
        // Read holding registers 0x006B..0x006D of unit 0x11: CRC 0x8776 (bytes 76 87).
        assert_eq!(crc16(&[0x11, 0x03, 0x00, 0x6B, 0x00, 0x03]), 0x8776);
    }

    #[test]
    fn reads_and_writes() {
        let mut s = ScadaSlave::new(1).unwrap();
        let r = ask(&mut s, &frame(&[1, 4, 0, 0, 0, 10])).unwrap();
        assert_eq!(&r[..3], &[1, 4, 20]);
        assert_eq!(u16::from_be_bytes([r[3], r[4]]), 100);
        assert_eq!(u16::from_be_bytes([r[21], r[22]]), 109);
        // FC 06 setpoint 5000, FC 16 setpoint + mode, read back with FC 03.
        let w = frame(&[1, 6, 0, 0, 0x13, 0x88]);
        assert_eq!(ask(&mut s, &w).unwrap(), w, "FC 06 echoes the request");
        assert_eq!(s.setpoint, 5000);
        let r = ask(&mut s, &frame(&[1, 16, 0, 0, 0, 2, 4, 0x0F, 0xA0, 0, 1])).unwrap();
        assert_eq!(&r[..6], &[1, 16, 0, 0, 0, 2]);
        assert_eq!((s.setpoint, s.mode), (4000, Mode::Manual));
        let r = ask(&mut s, &frame(&[1, 3, 0, 0, 0, 2])).unwrap();
        assert_eq!(&r[..7], &[1, 3, 4, 0x0F, 0xA0, 0, 1]);
        ask(&mut s, &frame(&[1, 6, 0, 2, 0, 1])).unwrap();
        assert_eq!(s.arithmetic, Arithmetic::Fixed);
        let r = ask(&mut s, &frame(&[1, 4, 0, 17, 0, 1])).unwrap();
        assert_eq!(&r[..5], &[1, 4, 2, 0, 117]);
        let r = ask(&mut s, &frame(&[1, 4, 0, 22, 0, 1])).unwrap();
        assert_eq!(&r[..5], &[1, 4, 2, 0, 122], "observer registers up to 22");
    }

    #[test]
    fn virtual_bench_registers_exist_only_with_one() {
        let mut board = ScadaSlave::new(1).unwrap();
        assert_eq!(
            exception(&mut board, &[1, 3, 0, 3, 0, 1]),
            2,
            "no bench: 02"
        );
        assert_eq!(exception(&mut board, &[1, 6, 0, 3, 0x05, 0x14]), 2);
        assert_eq!(exception(&mut board, &[1, 6, 0, 4, 0, 1]), 2);
        let mut s = ScadaSlave::new(1).unwrap().with_virtual_bench();
        let r = ask(&mut s, &frame(&[1, 3, 0, 0, 0, 5])).unwrap();
        assert_eq!(&r[..13], &[1, 3, 10, 0, 0, 0, 0, 0, 0, 0x03, 0xE8, 0, 0]);
        let w = frame(&[1, 6, 0, 3, 0x05, 0x14]);
        assert_eq!(ask(&mut s, &w).unwrap(), w);
        assert_eq!(s.valve_permille, 1300);
        assert_eq!(exception(&mut s, &[1, 6, 0, 3, 0x01, 0xF3]), 3, "499");
        assert_eq!(exception(&mut s, &[1, 6, 0, 3, 0x07, 0xD1]), 3, "2001");
        assert_eq!(exception(&mut s, &[1, 6, 0, 4, 0, 16]), 3, "fault bit 4");
        ask(&mut s, &frame(&[1, 6, 0, 4, 0, 0b1010])).unwrap();
        assert_eq!(s.faults, 0b1010);
        assert_eq!(exception(&mut s, &[1, 3, 0, 4, 0, 2]), 2, "past the map");
    }

    #[test]
    fn spec_exceptions() {
        let mut s = ScadaSlave::new(1).unwrap();
        assert_eq!(
            exception(&mut s, &[1, 1, 0, 0, 0, 1]),
            1,
            "coils: illegal function"
        );
        assert_eq!(
            exception(&mut s, &[1, 0x2B, 0x0E, 1, 0]),
            1,
            "unknown function"
        );
        assert_eq!(
            exception(&mut s, &[1, 4, 0, 22, 0, 2]),
            2,
            "past the input map"
        );
        assert_eq!(
            exception(&mut s, &[1, 3, 0, 3, 0, 1]),
            2,
            "past the holding map"
        );
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 5, 0, 1]),
            2,
            "write past the map"
        );
        assert_eq!(exception(&mut s, &[1, 4, 0, 0, 0, 0]), 3, "zero quantity");
        assert_eq!(
            exception(&mut s, &[1, 4, 0, 0, 0, 126]),
            3,
            "quantity above 125"
        );
        assert_eq!(
            exception(&mut s, &[1, 6, 0, 0, 0x27, 0x11]),
            3,
            "setpoint 10001"
        );
        assert_eq!(exception(&mut s, &[1, 6, 0, 1, 0, 3]), 3, "mode 3");
        assert_eq!(exception(&mut s, &[1, 6, 0, 2, 0, 2]), 3, "arithmetic 2");
        // Regression (hostile run): an unsupported function is 01 whatever its fields; an
        // oversized quantity in FC 01, 02 or 15 used to answer 03 (rmodbus's own check).
        for body in [
            &[1, 1, 0, 0, 0x07, 0xD1][..],
            &[1, 2, 0, 0, 0xFF, 0xFF],
            &[1, 0x0F, 0, 0, 0x07, 0xB1, 1, 0xFF],
            &[1, 5, 0, 0, 0x12, 0x34],
            &[1, 0x0F, 0, 0, 0, 0, 0],
        ] {
            assert_eq!(exception(&mut s, body), 1, "{body:02x?}");
        }
        assert_eq!(
            exception(&mut s, &[1, 16, 0, 0, 0, 2, 2, 0, 1]),
            3,
            "byte count"
        );
        // A write with one bad value changes nothing.
        assert_eq!(exception(&mut s, &[1, 16, 0, 0, 0, 2, 4, 0, 100, 0, 9]), 3);
        assert_eq!((s.setpoint, s.mode), (0, Mode::Stop));
    }

    /// Regression set of malformed frames: silence, no state change, and the next valid
    /// request is answered.
    #[test]
    fn malformed_frames_get_silence_and_do_not_disturb() {
        let mut s = ScadaSlave::new(1).unwrap();
        let good = frame(&[1, 6, 0, 0, 0, 7]);
        let mut bad_crc = good.clone();
        bad_crc[7] ^= 0xFF;
        let mut long = good.clone();
        long.push(0);
        let mut unknown_bad_crc = frame(&[1, 0x2B, 0x0E, 1, 0]);
        unknown_bad_crc[5] ^= 1;
        let cases: Vec<Vec<u8>> = vec![
            frame(&[1, 0x85, 0, 0, 0, 1]),
            vec![],
            vec![1],
            vec![1, 6, 0],
            good[..7].to_vec(),
            bad_crc,
            long,
            unknown_bad_crc,
            frame(&[2, 6, 0, 0, 0, 7]),
            frame(&[0, 6, 0, 0, 0, 7]),
            frame(&[1, 16, 0, 0, 0, 1, 2, 0]),
            vec![0xFF; 300],
        ];
        for f in &cases {
            assert_eq!(ask(&mut s, f), None, "{f:?}");
            assert_eq!((s.setpoint, s.mode), (0, Mode::Stop), "{f:?}");
        }
        assert_eq!(ask(&mut s, &good).unwrap(), good);
        assert_eq!(s.setpoint, 7);
    }

    #[test]
    fn requests_whole_by_their_length_and_crc() {
        let read = frame(&[1, 4, 0, 0, 0, 18]);
        assert!(request_complete(&read));
        assert!(request_complete(&frame(&[7, 3, 0, 0, 0, 1])), "any unit");
        let fc16 = frame(&[1, 16, 0, 0, 0, 2, 4, 0x13, 0x88, 0, 1]);
        assert!(request_complete(&fc16));
        for n in 0..fc16.len() {
            assert!(!request_complete(&fc16[..n]), "prefix of {n} bytes");
        }
        let mut bad = read.clone();
        bad[7] ^= 1;
        assert!(!request_complete(&bad), "bad CRC waits for the silence");
        assert!(
            !request_complete(&frame(&[1, 0x2B, 0x0E, 1, 0, 0])),
            "open length"
        );
        let mut long = read.clone();
        long.push(0);
        assert!(!request_complete(&long));
    }

    #[test]
    fn a_request_after_noise_is_found_at_the_end() {
        let read = frame(&[1, 4, 0, 0, 0, 18]);
        let fc16 = frame(&[1, 16, 0, 0, 0, 2, 4, 0x13, 0x88, 0, 1]);
        for req in [&read, &fc16] {
            assert_eq!(request_at_end(req), Some(0));
            let mut noisy = vec![0x55; 300];
            noisy.extend_from_slice(req);
            assert_eq!(request_at_end(&noisy), Some(300), "{req:02x?}");
            assert_eq!(request_at_end(&noisy[..noisy.len() - 1]), None);
        }
        assert_eq!(request_at_end(&[0x55; 300]), None);
        assert_eq!(request_at_end(&[]), None);
        // A long write whose data holds a valid read request is not cut at that request.
        let inner = frame(&[1, 3, 0, 0, 0, 1]);
        let mut body = vec![1, 16, 0, 0, 0, 8, 16];
        body.extend_from_slice(&inner);
        body.extend_from_slice(&[0; 8]);
        let long = frame(&body);
        for k in 1..long.len() {
            assert_eq!(request_at_end(&long[..k]), None, "{k} bytes");
        }
        assert_eq!(request_at_end(&long), Some(0));
        // A whole long write (a read request inside its data) is taken whole: the whole
        // buffer is checked before any tail of it.
        let mut body = vec![1, 16, 0, 0, 0, 4, 8];
        body.extend_from_slice(&frame(&[1, 4, 0, 0, 0, 1])[..6]);
        let tail = crc16(&[1, 4, 0, 0, 0, 1]).to_le_bytes();
        body.extend_from_slice(&tail);
        let whole = frame(&body);
        assert_eq!(
            request_at_end(&whole),
            Some(0),
            "the whole frame, not its tail"
        );
        // A truncated request and a whole one right after it: the whole one is found.
        let mut split = read[..5].to_vec();
        split.extend_from_slice(&read);
        assert_eq!(request_at_end(&split), Some(5));
    }

    #[test]
    fn registers_are_scaled_clamped_and_finite() {
        let p = Published {
            status: Status {
                running: true,
                flow_fault: true,
                ..Status::default()
            },
            torque_pct: 150.0,
            pressure_mca: -0.25,
            flow_lps: f32::NAN,
            whitebox_pressure_mca: 1e9,
            whitebox_flow_lps: -3.0,
            whitebox_speed_rpm: 1629.14,
            narmax_pressure_mca: 2.6604,
            narmax_flow_lps: 15.776,
            sample: 65535,
            whitebox_pressure_residual_mca: -0.0125,
            vfd_speed_rpm: -12.34,
            vfd_status: 0xBEEF,
            uptime_s: 7,
            ..Published::default()
        };
        let r = p.registers();
        assert_eq!(r[0], 0b10_0001);
        assert_eq!(r[1], 10_000);
        assert_eq!(r[2] as i16, -250);
        assert_eq!(r[3], 0);
        assert_eq!(r[4] as i16, i16::MAX);
        assert_eq!(r[5], 0);
        assert_eq!(r[6], 16291);
        assert_eq!(r[7], 2660);
        assert_eq!(r[8], 1578);
        assert_eq!(r[9], 65535);
        assert_eq!(r[10] as i16, -13);
        assert_eq!(r[11], 0);
        assert_eq!(r[14] as i16, -123);
        assert_eq!((r[16], r[17]), (0xBEEF, 7));
        assert!(ScadaSlave::new(0).is_none() && ScadaSlave::new(248).is_none());
    }
}
