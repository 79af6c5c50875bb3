//! The Modbus RTU layer shared by every slave and master of the controller: the frame buffer,
//! the CRC, the register scalings, the one gate every received frame passes (length, unit,
//! CRC), the framing of requests by their content, and the one slave engine that serves a
//! register map ([`RegisterMap`], [`serve`]).
//!
//! The SCADA slave ([`crate::scada`]) and the simulated drive ([`crate::vfdsim`]) are register
//! maps served by [`serve`]; the VFD master ([`crate::vfd`]) checks the drive's answers through
//! [`gate`].
//!
//! # The engine's answers
//!
//! [`serve`] answers one RTU request frame (the bytes between two silences) as the Modbus spec
//! says (Modbus Application Protocol V1.1b3, §6 and §7):
//!
//! - **silence** for a frame shorter than 4 or longer than [`MAX_FRAME`] bytes, for another
//!   unit (broadcasts, unit 0, included: no map here takes them), with a bad CRC, with a
//!   function code of 0x80 or above (the exception space, never a request), or whose length
//!   differs from the one its function fixes ([`request_len`]);
//! - **01** illegal function: any function but 03, 04, 06 and 16, or one of these the map does
//!   not serve ([`RegisterMap::serves`]), whatever its fields;
//! - **03** illegal data value: a read quantity outside 1..=125, a write quantity outside
//!   1..=123 or a byte count other than twice the quantity (FC 16);
//! - otherwise the map's answer: the registers, the write echoed, or the exception it returns
//!   (02 for an address outside the map, 03 for a value it refuses; a write is all or nothing).
//!
//! # rmodbus
//!
//! `rmodbus` makes the master's requests in [`crate::vfd`] and gives [`request_len`] the
//! length of a fixed-length request. The slave's requests are read and its answers built here,
//! by [`serve`] itself: a request's fields are two words and FC 16's byte count, an answer is
//! the registers or the request's first six bytes; rmodbus's server took 1 648 B of the QEMU
//! image for it (its parser, its response builder and the bounds checks they pull in; `cargo
//! xtask bench`), and defects 1..=4 below are in it. Every rmodbus defect this crate meets is
//! listed here, with a comment where it is worked around.
//!
//! ## rmodbus 0.13 defects found (1..=4 in its server, no longer used; 5..=8 worked around)
//!
//! Each as found in rmodbus 0.13.0's source, with a reproduction (RTU frames in hex, CRC
//! included where it matters, unit 1, a `ModbusFrame` with `ModbusProto::Rtu`):
//!
//! 1. **The server answers an unknown function without checking the CRC.**
//!    `ModbusFrame::parse` (src/server/mod.rs:593-604) sets `response_required` and
//!    `IllegalFunction` for a function code it does not know and returns before
//!    `check_frame_crc!`. Reproduce: parse `01 2B 0E 01 00 DE AD` (bad CRC), then
//!    `finalize_response`: the answer is `01 AB 01 9E F0`. Expected: `FrameCRCError` and no
//!    answer, as for a known function (a frame with a bad CRC is noise, spec serial line
//!    V1.02 §2.5.1.2). Here: [`gate`] checks the CRC of every frame first.
//! 2. **Function codes 128..=255 overflow.** `finalize_response` writes
//!    `self.responding_to_fn + 0x80` in u8 (src/server/mod.rs:153, and :148 for TCP). Reproduce:
//!    parse `01 85 00 00` (no CRC needed, see 1) and `finalize_response`: with overflow checks
//!    (debug) it panics, "attempt to add with overflow"; without (release) it answers
//!    `01 05 01 E2 90`, an exception that reads as function 05. Expected: no answer (0x80 and
//!    above are exception responses, never requests), or at least no panic. Here: [`serve`]
//!    drops such frames.
//! 3. **A write-multiple byte count of 249 or more overflows.** `parse` checks the CRC of FC 15
//!    and 16 with `check_frame_crc!(7 + bytes)` where `bytes` is the u8 byte count
//!    (src/server/mod.rs:712-713). Reproduce: parse `01 10 00 00 00 01 F9` followed by any ten
//!    bytes: debug panics, "attempt to add with overflow"; in release the sum wraps and the CRC
//!    is read at the wrong place: the 8-byte frame `01 10 30 13 00 01 FF 0C` passes as
//!    CRC-valid and is answered exception 03. Expected: `FrameBroken` (the frame cannot hold
//!    its byte count). Here: [`serve`] takes only frames exactly as long as
//!    [`request_len`] says, with their CRC checked by [`gate`], so a byte count is at most 247.
//! 4. **Quantity 0 and a byte count that does not match the quantity are accepted.** `parse`
//!    refuses only quantities above the maximum: FC 03/04 above 125 (src/server/mod.rs:674),
//!    FC 16 above 123 and byte counts above 246 (:728, :732), FC 01/02 above 2000 (:646); it
//!    never refuses 0, and never compares FC 15/16's byte count with the quantity.
//!    Reproduce: `01 03 00 00 00 00 45 CA` is answered `01 03 00 20 F0` (a read of nothing);
//!    `01 10 00 00 00 01 04 00 05 00 06 63 9F` through `process_write` writes two registers
//!    (5 and 6) and answers that it wrote one (`01 10 00 00 00 01 01 C9`); through
//!    `get_external_write` it hands on `count: 1` with four data bytes. Expected (Modbus
//!    Application Protocol V1.1b3 §6.3, §6.4, §6.12): exception 03 unless
//!    1 ≤ quantity ≤ 125 (reads) or 123 (FC 16) and byte count = 2 × quantity. Here: [`serve`]
//!    answers 03 for these.
//! 5. **The client parser accepts responses of the wrong length.** `ModbusRequest`'s
//!    `parse_response` (src/client.rs:355-361) refuses a read response only if
//!    `byte count × 2 < data bytes` (its comment takes the byte count for a count of words),
//!    so a response with fewer data bytes than its byte count, or up to twice as many, passes;
//!    write responses are not length-checked at all. Reproduce: after
//!    `generate_get_holdings(0, 3, ..)`, `parse_u16` on `01 03 06 00 09 39 83` returns Ok with
//!    one value (9); after `generate_set_holding(0, 7, ..)`, `parse_ok` on `01 06 00 23 A0`
//!    returns Ok. Expected: `FrameBroken` unless byte count = data bytes = 2 × the registers
//!    asked for, and a write answer is the 8-byte echo. Worked around: the master checks
//!    answers itself after [`gate`] (exact length, byte count, echo) and never calls rmodbus's
//!    parser.
//! 6. **`parse_u16` underflows on a read response without data.** `parse_reg!` loops
//!    `while pos < data.len() - 1` (src/client.rs:26; `data.len() - 3` at :42 and :59 for the
//!    32-bit parsers). Reproduce: after `generate_get_holdings(0, 3, ..)`, `parse_u16` on
//!    `01 03 00 20 F0` (byte count 0, CRC valid; defect 5 lets it through): debug panics,
//!    "attempt to subtract with overflow"; release panics, "index out of bounds". Expected:
//!    `FrameBroken`. Worked around as 5.
//! 7. **The client parser reports any other function as an exception.** `parse_response`
//!    returns `ErrorKind::from_modbus_error(buf[2])` whenever the function differs from the
//!    request's (src/client.rs:349-353), whether or not it is `function | 0x80`, and does not
//!    check an exception's length. Reproduce: after `generate_get_holdings(0, 3, ..)`,
//!    `parse_u16` on `01 04 02 00 01 78 F0` (an FC 04 answer) returns
//!    `Err(IllegalDataAddress)` (its byte count, 2, read as an exception code), and so does
//!    `01 83 02 09 09 57 D2` (an exception with two bytes too many). Expected: `FrameBroken`
//!    for a function other than the request's and its exception form, and for an exception
//!    that is not 5 bytes. Worked around as 5: the master takes an exception only as
//!    `function | 0x80` with exactly one code byte, and ignores anything else.
//! 8. **`guess_request_frame_len` gives 8 bytes for every function but 15 and 16.**
//!    (src/lib.rs:262-270; its docs say two bytes suffice for all other functions.) Reproduce:
//!    `guess_request_frame_len(&[1, 0x11], ModbusProto::Rtu)` is `Ok(8)`, but an FC 11 (report
//!    server id) request is 4 bytes long; so are 07, 0B and 0C; FC 16 (0x16, mask write) is 10,
//!    FC 17 is 13 + its byte count, FC 2B/0E is 7, FC 14 and 15 carry their byte count at
//!    offset 2, and codes 0x80 and above are no requests at all. Expected: the length where
//!    the function fixes it, an error otherwise. Worked around: [`request_len`] uses it for
//!    01..=06, 15 and 16 only and leaves the length of any other function open.
//!
//! ## rmodbus 0.13 server behaviours that are not defects, which [`serve`] does otherwise
//!
//! - `parse` ignores bytes after a valid frame (src/server/mod.rs:610-617 checks only that the
//!   buffer is long enough): by design, its examples hand it a whole 256-byte buffer. An RTU
//!   frame is the bytes between two silences, so a longer one is not this request:
//!   [`serve`] checks the exact length first.
//! - A coil function's quantity is checked before a server that has no coils can answer 01:
//!   rmodbus serves coils, and answers 03 for FC 01/02 above 2000 and FC 15 above 1968 bits in
//!   `parse` (src/server/mod.rs:646, :728), before the application sees the frame; it has no
//!   way to say that a server does not serve a function. [`serve`] answers 01 itself for any
//!   function it or the map does not serve.
//! - `guess_request_frame_len` returns a u8 (src/lib.rs:271-276), so it cannot say 256, the
//!   length of an FC 15/16 request with byte count 247, the longest RTU frame; that byte count
//!   is invalid anyway (at most 246), and [`request_len`] computes the length itself there, so
//!   that such a frame is answered 03 rather than dropped.

use rmodbus::ModbusProto;

/// Longest RTU frame, bytes (Modbus serial line V1.02 §2.5.1: 256).
pub const MAX_FRAME: usize = 256;

/// Shortest RTU frame, bytes: unit, function, CRC.
const MIN_FRAME: usize = 4;

/// A frame buffer (0..=[`MAX_FRAME`] bytes): the one type for requests and responses.
pub type Frame = heapless::Vec<u8, MAX_FRAME>;

/// Longest read, registers (FC 03, 04).
const MAX_READ: u16 = 125;

/// Longest write, registers (FC 16).
const MAX_WRITE: u16 = 123;

/// CRC-16/MODBUS of `data` (any length), as sent: low byte first (`to_le_bytes`).
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

/// `x · scale` rounded to the nearest integer and clamped to 0..=65535; NaN gives 0.
pub fn unsigned_register(x: f32, scale: f32) -> u16 {
    let v = x * scale;
    if v.is_nan() {
        0
    } else {
        (v + 0.5).clamp(0.0, f32::from(u16::MAX)) as u16
    }
}

/// `x · scale` rounded to the nearest integer (halves away from 0) and clamped to
/// -32768..=32767, as the register's two's-complement bits; NaN gives 0.
pub fn signed_register(x: f32, scale: f32) -> u16 {
    let v = x * scale;
    if v.is_nan() {
        0
    } else {
        let r = if v < 0.0 { v - 0.5 } else { v + 0.5 };
        r.clamp(f32::from(i16::MIN), f32::from(i16::MAX)) as i16 as u16
    }
}

/// A frame that passed the [`gate`]: what lies between its unit and its CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pdu<'a> {
    /// Function code, 0..=255 (0x80 and above: an exception response).
    pub function: u8,
    /// The bytes after the function code, before the CRC (0..=252 bytes).
    pub data: &'a [u8],
}

/// The RTU gate every received frame passes, requests and responses alike: `frame` is
/// 4..=[`MAX_FRAME`] bytes long, addressed to `unit` and its CRC is valid. `None` otherwise
/// (the frame is ignored: noise, another slave's traffic, a frame cut short or run together).
/// Whether its length suits its function is the caller's to check (a request's by
/// [`request_len`], a response's by what was asked).
pub fn gate(frame: &[u8], unit: u8) -> Option<Pdu<'_>> {
    if !(MIN_FRAME..=MAX_FRAME).contains(&frame.len()) || frame.first() != Some(&unit) {
        return None;
    }
    let (body, crc) = frame.split_at(frame.len() - 2);
    if crc16(body).to_le_bytes() != crc {
        return None;
    }
    let (&function, data) = body.get(1..)?.split_first()?;
    Some(Pdu { function, data })
}

/// The exact RTU length of a request (unit, function, fields, CRC), bytes: 8 for 01..=06,
/// 9 + its byte count (9..=264) for 15 and 16; `None` when the frame is too short to tell (a
/// 15 or 16 shorter than 7 bytes, anything shorter than 2). Any other function has no length
/// known here: the frame's own length is given back (it is ended by the silence).
pub fn request_len(frame: &[u8]) -> Option<usize> {
    match *frame.get(1)? {
        // rmodbus is right for the functions whose fields fix the length; but its u8 cannot
        // say 256 (byte count 247), which this crate still answers (03), hence the fallback.
        1..=6 | 15 | 16 => rmodbus::guess_request_frame_len(frame, ModbusProto::Rtu)
            .ok()
            .map(usize::from)
            .or_else(|| frame.get(6).map(|&n| 9 + usize::from(n))),
        // rmodbus 0.13 defect 8 (module docs): it says 8 for every other function.
        _ => Some(frame.len()),
    }
}

/// `true` if `frame` is a whole request by its content alone: a function whose request length
/// is fixed by its fields (01..=06, 15, 16), exactly that long, with a valid CRC; for any
/// unit, so that traffic to other slaves on the bus is framed too. A frame of another
/// function, or one that is not yet (or no longer) whole, gives `false`: it is ended by the
/// silence.
pub fn request_complete(frame: &[u8]) -> bool {
    let n = frame.len();
    n >= 8
        && matches!(frame[1], 1..=6 | 15 | 16)
        && request_len(frame) == Some(n)
        && crc16(&frame[..n - 2]) == u16::from_le_bytes([frame[n - 2], frame[n - 1]])
}

/// `true` while `bytes` may still become a whole request as more bytes come: a function whose
/// request length its fields fix (01..=06, 15, 16) and that length not reached yet (a 15 or
/// 16 whose byte count has not come counts). A single byte may still be a unit address:
/// `true` too. An empty slice gives `false`.
pub fn request_may_grow(bytes: &[u8]) -> bool {
    match bytes.get(1) {
        None => bytes.len() == 1,
        Some(1..=6 | 15 | 16) => request_len(bytes).is_none_or(|want| want > bytes.len()),
        Some(_) => false,
    }
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
    if request_may_grow(bytes) {
        return None;
    }
    if request_complete(bytes) {
        return Some(0);
    }
    // Fixed-length requests (01..06) are 8 bytes; 15 and 16 carry their byte count at 6.
    if n >= 8 && request_complete(&bytes[n - 8..]) {
        return Some(n - 8);
    }
    (0..n.saturating_sub(10)).rev().find(|&start| {
        matches!(bytes.get(start + 1), Some(15 | 16))
            && bytes.get(start..).is_some_and(request_complete)
    })
}

/// A Modbus exception code a register map answers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exception {
    /// 01: the function is not served.
    IllegalFunction = 1,
    /// 02: an address of the range is not in the map (or not writable).
    IllegalDataAddress = 2,
    /// 03: a value (or quantity) is refused.
    IllegalDataValue = 3,
    /// 04: the server failed while serving the request.
    ServerDeviceFailure = 4,
}

impl Exception {
    /// The exception code, 1..=4.
    pub fn code(self) -> u8 {
        self as u8
    }
}

/// A slave's registers, as [`serve`] sees them. Addresses are the PDU's (0..=65535, the first
/// register is 0); ranges are 1..=125 registers long for reads, 1..=123 for writes, and may run
/// past 65535 (`address + len` overflows u16): the map answers 02 for those.
pub trait RegisterMap {
    /// `true` if the map serves `function` (called for 03, 04, 06 and 16 only, the engine's;
    /// the others are never served). A function not served is answered 01 whatever its fields.
    /// All four by default.
    fn serves(&self, function: u8) -> bool {
        let _ = function;
        true
    }

    /// FC 04: fills `out` with the input registers from `address` on; `Err` answers that
    /// exception. 01 (none) by default.
    fn read_input_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
        let _ = (address, out);
        Err(Exception::IllegalFunction)
    }

    /// FC 03: fills `out` with the holding registers from `address` on; `Err` answers that
    /// exception.
    fn read_holding_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception>;

    /// FC 06 (one value) and FC 16: writes `values` to the holding registers from `address`
    /// on, all or nothing: on `Err` (answered as that exception) nothing has changed.
    fn write_holding_registers(&mut self, address: u16, values: &[u16]) -> Result<(), Exception>;
}

/// Serves one RTU request `frame` (the bytes between two silences) for the slave at `unit`
/// (1..=247) against `map`: the answer goes to `response` (cleared first) and its length is
/// returned; `None` is silence (nothing is sent, `response` is empty). The answers are the
/// module docs'; no input makes it panic.
///
/// One engine for every map, called through `dyn`: generic, the QEMU image held two copies
/// (the SCADA slave's and the simulated drive's), 1 888 B more flash (`cargo xtask bench`),
/// against a virtual call per register access. (The NUCLEO image serves SCADA alone: 112 B
/// more there.)
pub fn serve(
    unit: u8,
    map: &mut dyn RegisterMap,
    frame: &[u8],
    response: &mut Frame,
) -> Option<usize> {
    response.clear();
    if !(1..=247).contains(&unit) {
        return None;
    }
    let pdu = gate(frame, unit)?;
    let func = pdu.function;
    // 0x80 and above are exception responses, never requests (rmodbus 0.13's server
    // overflowed on them: defect 2, module docs).
    if func >= 0x80 {
        return None;
    }
    // Only a frame of exactly its function's length goes on (an RTU frame is the bytes between
    // two silences; rmodbus 0.13's server ignored trailing bytes, and overflowed on FC 16's byte
    // counts of 249 and more: defect 3, module docs).
    if request_len(frame)? != frame.len() {
        return None;
    }
    if !(matches!(func, 3 | 4 | 6 | 16) && map.serves(func)) {
        // Whatever its fields (rmodbus 0.13's server checked a coil function's quantity
        // first: module docs, behaviours that are not defects).
        return exception(unit, func, Exception::IllegalFunction, response);
    }
    // 03, 04, 06 and 16 all begin with an address and a second word (the quantity, or 06's
    // value); their length, checked above, holds both.
    let [a0, a1, w0, w1, rest @ ..] = pdu.data else {
        return None;
    };
    let address = u16::from_be_bytes([*a0, *a1]);
    let word = u16::from_be_bytes([*w0, *w1]);
    let answered = match func {
        3 | 4 => read(map, unit, func, address, word, response),
        6 => write(map, address, 1, &[*w0, *w1]),
        // Quantity 0 (in `write`) and a byte count other than twice the quantity are refused
        // (03), as the spec says (rmodbus 0.13's server took both: defect 4, module docs).
        _ => match rest {
            [n, values @ ..] if u32::from(*n) == 2 * u32::from(word) => {
                write(map, address, word, values)
            }
            _ => Err(Exception::IllegalDataValue),
        },
    };
    if let Err(e) = answered {
        return exception(unit, func, e, response);
    }
    if func == 6 || func == 16 {
        // A write is answered with its request's first six bytes: unit, function, address
        // and 06's value or 16's quantity.
        response.extend_from_slice(frame.get(..6)?).ok()?;
    }
    let crc = crc16(response);
    response.extend_from_slice(&crc.to_le_bytes()).ok()?;
    Some(response.len())
}

/// An exception answer (5 bytes) in `response`.
fn exception(unit: u8, func: u8, e: Exception, response: &mut Frame) -> Option<usize> {
    let body = [unit, func | 0x80, e.code()];
    response.clear();
    response.extend_from_slice(&body).ok()?;
    response
        .extend_from_slice(&crc16(&body).to_le_bytes())
        .ok()?;
    Some(response.len())
}

/// Reads `count` registers (1..=125, else 03) from `map` and appends the answer to
/// `response`: unit, function, byte count, the registers big-endian.
fn read(
    map: &dyn RegisterMap,
    unit: u8,
    func: u8,
    address: u16,
    count: u16,
    response: &mut Frame,
) -> Result<(), Exception> {
    let mut words = [0u16; MAX_READ as usize];
    let words = words
        .get_mut(..usize::from(count))
        .filter(|w| !w.is_empty())
        .ok_or(Exception::IllegalDataValue)?;
    if func == 4 {
        map.read_input_registers(address, words)?;
    } else {
        map.read_holding_registers(address, words)?;
    }
    // At most 3 + 250 bytes: the frame holds them.
    let full = |_| Exception::ServerDeviceFailure;
    response
        .extend_from_slice(&[unit, func, (2 * count) as u8])
        .map_err(full)?;
    for w in words.iter() {
        response.extend_from_slice(&w.to_be_bytes()).map_err(full)?;
    }
    Ok(())
}

/// Writes `count` (1..=123, else 03) big-endian registers of `data` (exactly `2 count` bytes,
/// else 03) to `map`.
fn write(
    map: &mut dyn RegisterMap,
    address: u16,
    count: u16,
    data: &[u8],
) -> Result<(), Exception> {
    let mut words = [0u16; MAX_WRITE as usize];
    let words = words
        .get_mut(..usize::from(count))
        .filter(|w| !w.is_empty() && data.len() == 2 * w.len())
        .ok_or(Exception::IllegalDataValue)?;
    for (w, b) in words.iter_mut().zip(data.chunks_exact(2)) {
        *w = u16::from_be_bytes([b[0], b[1]]);
    }
    map.write_holding_registers(address, words)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    /// Four holding registers (0..=3, values 0..=999) and two input registers; counts the
    /// writes it takes.
    #[derive(Default)]
    struct Toy {
        holding: [u16; 4],
        writes: u32,
        no_inputs: bool,
    }

    impl RegisterMap for Toy {
        fn serves(&self, function: u8) -> bool {
            !(self.no_inputs && function == 4)
        }
        fn read_input_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
            let inputs = [0xBEEF, 0x1234];
            let start = usize::from(address);
            let src = inputs
                .get(start..start + out.len())
                .ok_or(Exception::IllegalDataAddress)?;
            out.copy_from_slice(src);
            Ok(())
        }
        fn read_holding_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
            let start = usize::from(address);
            let src = self
                .holding
                .get(start..start + out.len())
                .ok_or(Exception::IllegalDataAddress)?;
            out.copy_from_slice(src);
            Ok(())
        }
        fn write_holding_registers(
            &mut self,
            address: u16,
            values: &[u16],
        ) -> Result<(), Exception> {
            let start = usize::from(address);
            let mut next = self.holding;
            let dst = next
                .get_mut(start..start + values.len())
                .ok_or(Exception::IllegalDataAddress)?;
            if values.iter().any(|&v| v > 999) {
                return Err(Exception::IllegalDataValue);
            }
            dst.copy_from_slice(values);
            self.holding = next;
            self.writes += 1;
            Ok(())
        }
    }

    fn ask(map: &mut Toy, f: &[u8]) -> Option<Vec<u8>> {
        let mut r = Frame::new();
        let n = serve(1, map, f, &mut r);
        assert_eq!(n.is_none(), r.is_empty(), "{f:02x?}");
        n.map(|n| r[..n].to_vec())
    }

    fn exception_code(map: &mut Toy, body: &[u8]) -> u8 {
        let r = ask(map, &frame(body)).expect("an answer");
        assert_eq!(r.len(), 5, "{r:02x?}");
        assert_eq!((r[0], r[1]), (body[0], body[1] | 0x80));
        assert_eq!(crc16(&r[..3]).to_le_bytes(), [r[3], r[4]]);
        r[2]
    }

    #[test]
    fn crc_matches_the_spec_example() {
        // Read holding registers 0x006B..0x006D of unit 0x11: CRC 0x8776 (bytes 76 87).
        assert_eq!(crc16(&[0x11, 0x03, 0x00, 0x6B, 0x00, 0x03]), 0x8776);
    }

    #[test]
    fn register_scalings_round_clamp_and_zero_nan() {
        assert_eq!(unsigned_register(1.234, 100.0), 123);
        assert_eq!(unsigned_register(-1.0, 1.0), 0);
        assert_eq!(unsigned_register(1e9, 1.0), u16::MAX);
        assert_eq!(unsigned_register(f32::NAN, 1.0), 0);
        assert_eq!(signed_register(-0.0125, 1000.0) as i16, -13);
        assert_eq!(signed_register(-1e9, 1.0) as i16, i16::MIN);
        assert_eq!(signed_register(1e9, 1.0) as i16, i16::MAX);
        assert_eq!(signed_register(f32::NAN, 1.0), 0);
    }

    #[test]
    fn the_gate_takes_length_unit_and_crc() {
        let read = frame(&[1, 3, 0, 0, 0, 2]);
        assert_eq!(
            gate(&read, 1),
            Some(Pdu {
                function: 3,
                data: &[0, 0, 0, 2]
            })
        );
        assert_eq!(gate(&read, 2), None, "another unit");
        let mut bad = read.clone();
        bad[3] ^= 1;
        assert_eq!(gate(&bad, 1), None, "bad CRC");
        assert_eq!(gate(&frame(&[1, 7]), 1).map(|p| p.function), Some(7));
        assert_eq!(gate(&[1, 7, 0], 1), None, "too short");
        assert_eq!(gate(&[], 1), None);
        let longest = frame(&[1; MAX_FRAME - 2]);
        assert!(gate(&longest, 1).is_some());
        assert_eq!(gate(&frame(&[1; MAX_FRAME - 1]), 1), None, "too long");
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
    fn request_lengths_by_function() {
        assert_eq!(request_len(&[1]), None);
        for func in 1..=6 {
            assert_eq!(request_len(&[1, func]), Some(8), "{func}");
        }
        assert_eq!(
            request_len(&[1, 16, 0, 0, 0, 1]),
            None,
            "byte count not yet"
        );
        assert_eq!(request_len(&[1, 15, 0, 0, 0, 1, 2]), Some(11));
        assert_eq!(request_len(&[1, 16, 0, 0, 0, 123, 246]), Some(255));
        assert_eq!(request_len(&[1, 16, 0, 0, 0, 123, 247]), Some(256));
        assert_eq!(request_len(&[1, 16, 0, 0, 0, 123, 255]), Some(264));
        assert_eq!(request_len(&[1, 0x11, 1, 2]), Some(4), "open length");
        assert_eq!(request_len(&[1, 0x85, 1, 2, 3]), Some(5), "open length");
    }

    #[test]
    fn a_request_may_grow_until_its_length_is_reached() {
        let read = frame(&[1, 4, 0, 0, 0, 18]);
        let fc16 = frame(&[1, 16, 0, 0, 0, 2, 4, 0x13, 0x88, 0, 1]);
        for req in [&read, &fc16] {
            for k in 1..req.len() {
                assert!(request_may_grow(&req[..k]), "{k} bytes of {req:02x?}");
            }
            assert!(!request_may_grow(req), "whole");
        }
        assert!(!request_may_grow(&[]));
        assert!(!request_may_grow(&[1, 0x11]), "a function of open length");
        assert!(!request_may_grow(&[1, 0x83, 2]), "an exception's code");
        assert!(
            !request_may_grow(&[1, 3, 0, 0, 0, 3, 5, 6, 7]),
            "past its length"
        );
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
    fn the_engine_reads_and_writes_a_map() {
        let mut m = Toy::default();
        let r = ask(&mut m, &frame(&[1, 4, 0, 0, 0, 2])).unwrap();
        assert_eq!(r, frame(&[1, 4, 4, 0xBE, 0xEF, 0x12, 0x34]));
        let w = frame(&[1, 6, 0, 2, 0x03, 0xE7]);
        assert_eq!(ask(&mut m, &w).unwrap(), w, "FC 06 echoes the request");
        let r = ask(&mut m, &frame(&[1, 16, 0, 0, 0, 2, 4, 0, 7, 0, 8])).unwrap();
        assert_eq!(r, frame(&[1, 16, 0, 0, 0, 2]));
        let r = ask(&mut m, &frame(&[1, 3, 0, 0, 0, 4])).unwrap();
        assert_eq!(r, frame(&[1, 3, 8, 0, 7, 0, 8, 0x03, 0xE7, 0, 0]));
        assert_eq!(m.writes, 2);
    }

    #[test]
    fn the_engine_answers_the_spec_exceptions() {
        let mut m = Toy::default();
        for (body, code) in [
            (&[1, 1, 0, 0, 0, 1][..], 1),
            (&[1, 0x2B, 0x0E, 1, 0], 1),
            (&[1, 0x11], 1),
            (&[1, 4, 0, 1, 0, 2], 2),
            (&[1, 3, 0, 3, 0, 2], 2),
            (&[1, 3, 0xFF, 0xFF, 0, 2], 2),
            (&[1, 6, 0, 4, 0, 1], 2),
            (&[1, 16, 0xFF, 0xFF, 0, 2, 4, 0, 1, 0, 1], 2),
            (&[1, 3, 0, 0, 0, 0], 3),
            (&[1, 4, 0, 0, 0, 126], 3),
            (&[1, 6, 0, 0, 0x03, 0xE8], 3),
            (&[1, 16, 0, 0, 0, 0, 0], 3),
            (&[1, 16, 0, 0, 0, 124, 2, 0, 1], 3),
            (&[1, 16, 0, 0, 0, 2, 2, 0, 1], 3),
            (&[1, 16, 0, 0, 0, 1, 4, 0, 5, 0, 6], 3),
            (&[1, 16, 0, 0, 0, 2, 4, 0, 1, 0x03, 0xE8], 3),
            // Twice 0x8000 is 0 in 16 bits: the byte count 0 must not pass for it.
            (&[1, 16, 0, 0, 0x80, 0, 0], 3),
            (&[1, 3, 0, 0, 0x80, 0], 3),
        ] {
            assert_eq!(exception_code(&mut m, body), code, "{body:02x?}");
        }
        assert_eq!((m.holding, m.writes), ([0; 4], 0), "nothing written");
        m.no_inputs = true;
        assert_eq!(exception_code(&mut m, &[1, 4, 0, 0, 0, 1]), 1);
        assert_eq!(
            exception_code(&mut m, &[1, 4, 0, 0, 0, 0]),
            1,
            "a function not served is 01 whatever its fields"
        );
    }

    /// The frames of the rmodbus server defects of the module docs: the engine's answer is the
    /// spec's, and nothing panics.
    #[test]
    fn rmodbus_defects_do_not_reach_the_wire() {
        let mut m = Toy::default();
        // 1: an unknown function with a bad CRC.
        assert_eq!(ask(&mut m, &[1, 0x2B, 0x0E, 1, 0, 0xDE, 0xAD]), None);
        // 2: function codes 128..=255, with or without a valid CRC.
        for func in 0x80..=0xFF {
            assert_eq!(ask(&mut m, &[1, func, 0, 0]), None);
            assert_eq!(ask(&mut m, &frame(&[1, func, 0, 0, 0, 1])), None);
        }
        // 3: byte counts of 249 and more, CRC-valid at the wrong place or not at all.
        assert_eq!(ask(&mut m, &[1, 0x10, 0x30, 0x13, 0, 1, 0xFF, 0x0C]), None);
        let mut body = vec![1, 16, 0, 0, 0, 1, 0xF9];
        body.extend_from_slice(&[0; 10]);
        assert_eq!(ask(&mut m, &frame(&body)), None);
        // 4: quantity 0, byte count ≠ 2 × quantity (03, nothing written).
        assert_eq!(exception_code(&mut m, &[1, 3, 0, 0, 0, 0]), 3);
        assert_eq!(
            exception_code(&mut m, &[1, 16, 0, 0, 0, 1, 4, 0, 5, 0, 6]),
            3
        );
        assert_eq!(m.holding, [0; 4]);
        // Not defects: trailing bytes (silence), a coil quantity above 2000 (01).
        let mut long = frame(&[1, 3, 0, 0, 0, 2]);
        long.extend_from_slice(&[0xAA, 0xBB, 0xCC]);
        assert_eq!(ask(&mut m, &long), None);
        assert_eq!(exception_code(&mut m, &[1, 1, 0, 0, 0x07, 0xD1]), 1);
        assert_eq!(exception_code(&mut m, &[1, 15, 0, 0, 0x07, 0xB1, 1, 0]), 1);
    }

    #[test]
    fn silence_for_frames_that_are_no_request_for_this_unit() {
        let mut m = Toy::default();
        let good = frame(&[1, 6, 0, 0, 0, 7]);
        let mut bad_crc = good.clone();
        bad_crc[7] ^= 0xFF;
        for f in [
            vec![],
            vec![1],
            vec![1, 6, 0],
            good[..7].to_vec(),
            bad_crc,
            frame(&[2, 6, 0, 0, 0, 7]),
            frame(&[0, 6, 0, 0, 0, 7]),
            frame(&[1, 6, 0, 0, 0, 7, 0]),
            frame(&[1, 4, 0, 0, 0]),
            frame(&[1, 16, 0, 0, 0, 1, 2, 0]),
            vec![0xFF; 300],
        ] {
            assert_eq!(ask(&mut m, &f), None, "{f:02x?}");
        }
        assert_eq!(m.writes, 0);
        assert_eq!(ask(&mut m, &good), Some(good.clone()));
        let mut r = Frame::new();
        for unit in [0, 248, 255] {
            let f = frame(&[unit, 3, 0, 0, 0, 1]);
            assert_eq!(serve(unit, &mut m, &f, &mut r), None, "unit {unit}");
        }
    }
}
