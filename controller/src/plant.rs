//! A plant in the loop: the controller run in lockstep with a plant simulator, one frame per
//! control period, on the host (`pumpbench control --plant-stdio`) and on the QEMU board
//! (`cargo xtask qemu --plant PTY`), through this one path so that both give the same torques
//! for the same frames.
//!
//! Each [`PlantFrame`] carries what the plant shows the controller for one
//! [`FRAME_PERIOD_MS`] period: the two transmitters' raw ADC codes (12-bit, as the board's ADC
//! reads them, so a NAMUR NE 43 fault is sent as its current's code) and the drive's speed and
//! torque as its Modbus link would read them (`None`: the link is cut). [`Lockstep::period`]
//! runs the controller's [`FRAME_PERIOD_MS`] 1 ms steps on it and answers a [`PlantReply`]:
//! the torque reference the controller applies at the period's end (the plant applies it
//! over the next period) and the status word. Between frames, [`Lockstep::write`] applies a
//! holding-register write (the SCADA map's, [`crate::scada::ScadaSlave::write_words`]) at a
//! frame boundary, so a scenario is as deterministic as the plant.
//!
//! # The plant protocol, version 1
//!
//! The lockstep over a byte stream (a serial line, a pipe: stdin/stdout): text lines of
//! printable ASCII ended by `\n` (a `\r` before it is ignored), fields separated by spaces
//! (runs of spaces or tabs count as one). The plant sends one request line, the controller
//! answers exactly one reply line, and sends nothing else: a plant always knows which reply
//! is whose. A plant waits for each reply before its next line (lockstep): the QEMU board
//! queues at most 3 replies and 1 KiB of received bytes, so a plant that runs ahead of it
//! loses replies there (the host does not). [`PlantSession`] is the controller's side, byte in, reply out, the same code on
//! the host and the MCU; [`Request`] and [`Reply`] format and parse both directions for a
//! plant written in Rust.
//!
//! | request | meaning | reply |
//! |---|---|---|
//! | `H <version>` | hello: the plant speaks `version` (decimal; this is 1). Optional, but a plant should start with it | `H 1 <period_ms>`: the version spoken and the frame period, ms ([`FRAME_PERIOD_MS`], 5); `E version` for another version |
//! | `S <pressure_code> <flow_code> <speed_rpm> <torque_pct>` | one frame: the transmitters' ADC codes (integers 0..=4095) and the drive's actual speed (rpm, −32 768..=32 767) and torque (% of nominal, −200..=200), decimal numbers in the syntax of Rust's `f32::from_str` (`1500`, `-3.25`, `1.5e3`, `.5`; no hexadecimal), rounded to the nearest `f32` | `T <t_ms> <torque_ref_pct> <status>` |
//! | `S <pressure_code> <flow_code> -` | one frame with the VFD link cut (no readings: the controller applies 0 % and freezes its loop, as with its Modbus link down) | `T …` |
//! | `W <register> <value>` | a holding-register write (the SCADA map, [`crate::scada`]; decimal 0..=65535 both), applied before the next frame | `K`, or `E <code>`: the Modbus exception a SCADA write would get (2 no such register, 3 value refused), nothing changed |
//! | `Q` | the end of the session | `B` (bye); the controller side then stops reading |
//! | anything else | | `E <reason>`, the session goes on |
//!
//! In a `T` reply, `t_ms` is the controller's time at the period's last 1 ms step (decimal,
//! wrapping at 2³²; the first frame answers 4), `torque_ref_pct` the torque reference it
//! applies from now on (0..=100 %), which the plant applies to its drive over the next period,
//! written by Rust's `{}` for an `f32`: the shortest decimal that reads back as the same
//! `f32` (no exponent, e.g. `37.51953`; in Python, `struct.unpack('f', struct.pack('f',
//! float(s)))[0]` is the exact value), and `status` SCADA input register 0's core bits
//! (decimal; its bits in [`crate::scada`]: 0 running, 1 any alarm, 9 in control, …; not bit 8,
//! saturated, which only the register map sets).
//!
//! The reasons of `E <reason>`: `long` (more than [`MAX_LINE`] bytes before the `\n`),
//! `ascii` (a byte outside printable ASCII), `empty` (a blank line), `command` (an unknown
//! first field), `fields` (too few or too many fields), `number` (a field that is not a
//! number of its kind: codes, registers and values are decimal digits only), `range` (a
//! number outside its range), `finite` (NaN or an infinity, and a decimal beyond `f32`'s
//! range, ±3.4e38, which rounds to one), `version` (a version this side does not speak). A
//! line with several errors answers one of them (the order is not part of the protocol). An
//! `E` reply to an `S` line runs no step: the controller's time stands still. After `Q` the
//! QEMU board exits 250 ms after its `B` (the serial line closes with QEMU: a plant that
//! reads the `B` later than that finds the line's end instead).
//!
//! The ADC codes: a 4-20 mA loop through the board's 150 Ω shunt into its 12-bit, 3.3 V ADC
//! ([`crate::analog::LoopConfig::typical`]): `code = round(mA × 0.150 / 3.3 × 4095)` =
//! `round(mA / 22 × 4095)` (4 mA: 745, 20 mA: 3723); the pressure transmitter spans 0..10 mca
//! over 4..20 mA, the flow transmitter 0..30 l/s. A code under 3.6 mA (670) or over 21 mA
//! (3909) is a NAMUR NE 43 fault (e.g. 2 mA, a broken wire: 372). The controller samples
//! the codes on its own ticks (its models' periods and the control period); a frame's codes
//! stand for the whole period. The drive's status word is not carried (the controller does
//! not use it; SCADA input register 16 reads 0).
//!
//! The plant starts the controller in mode 0 (stop), as the board starts; a `W 1 3` (mode 3,
//! pressure control) with `W 8 3000` (its setpoint, 3.000 mca) closes a loop. Writes before
//! the first frame set the state the controller starts in: in manual (`W 1 1`, its torque in
//! register 0) or the profile its first step applies that torque at once, so a plant that
//! starts settled starts the controller there (`pumpbench control`'s settled start does);
//! the loops start from 0 % at the rate. An exchange
//! (`>` from the plant, `<` from the controller):
//!
//! ```text
//! > H 1
//! < H 1 5
//! > W 8 3000
//! < K
//! > W 1 3
//! < K
//! > S 745 745 0 0
//! < T 4 0.6 1549
//! > S 745 745 12.5 0.8
//! < T 9 1.6000001 1549
//! > W 3 1000
//! < E 2
//! > S 4095 745 -
//! < T 14 0 1095
//! > S 1 2 3
//! < E fields
//! > Q
//! < B
//! ```
//!
//! (`cargo xtask plant-stdio` answered these; a test, `the_docs_exchange_is_answered_so`,
//! checks them. Status 1549: bits 0 running, 2 model extrapolating, 3 VFD link ok, 9 in
//! control, 10 limited (the torque comes up at the rate limit); 1095: bits 0, 1 any alarm,
//! 2, 6 VFD readings invalid, 10, and not 3: the link is down. Bit 4, the pressure
//! transmitter's fault, is not yet set: a fault latches on the models' samples, every 50 ms,
//! not on one 5 ms frame.) Lockstep makes a run deterministic: the same frames and writes give
//! the same replies, bit for bit, on the host and on the QEMU board, whatever either
//! machine's speed. On the board a SCADA master may still read and write over Modbus; its
//! writes land between two frames, when they arrive, so only the in-band `W` lines are
//! deterministic.

use crate::control::{Config, Controller, Error, Inputs, Outputs, VfdStatus};
use crate::link::ScadaLink;
use crate::modbus::Exception;
use crate::regulate::CONTROL_PERIOD_MS;
use crate::scada::ScadaSlave;
use crate::types::Published;
use crate::vfd::VfdReadings;

/// One frame per this many 1 ms steps: the control period.
pub const FRAME_PERIOD_MS: u32 = CONTROL_PERIOD_MS;

/// The controller's configuration in a plant session, on the host and the QEMU board alike
/// (`board_common::plant_session` builds both sides from it): the bench's ([`Config::bench`]:
/// its transmitters and drive map, SCADA unit 1, stopped, NARMAX in f32), no virtual bench
/// (holding registers 3 and 4 do not exist: `W 3 …` answers `E 2`).
pub const PLANT_CONFIG: Config = Config::bench();

/// What the plant shows the controller for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantFrame {
    /// Pressure transmitter's ADC code (0..=4095; the board's 150 Ω shunt, 12-bit 3.3 V ADC).
    pub pressure_code: u16,
    /// Flow transmitter's ADC code (as the pressure's).
    pub flow_code: u16,
    /// The drive's readings (speed rpm, torque %, status word); `None`: the VFD link is cut
    /// (the controller applies 0 % and freezes its loop, as with its Modbus link down).
    pub drive: Option<VfdReadings>,
}

/// What the controller answers for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantReply {
    /// The torque reference applied at the period's end, % (0..=100), exact f32.
    pub torque_ref_pct: f32,
    /// SCADA input register 0's core bits ([`crate::types::Status::bits`]).
    pub status: u16,
}

/// The controller's side of the lockstep: its SCADA holding registers (the scenario's
/// writes land there) and the drive link's state as the frames give it.
#[derive(Debug, Clone)]
pub struct Lockstep {
    scada: ScadaSlave,
    vfd: VfdStatus,
}

impl Lockstep {
    /// A lockstep with the holding registers of `scada` (as the board starts them).
    pub fn new(scada: ScadaSlave) -> Self {
        Self {
            scada,
            vfd: VfdStatus::START,
        }
    }

    /// A lockstep with the holding registers as a board starts them with `config`
    /// ([`ScadaLink::new`]: its start-up mode, setpoint and arithmetic, its protections).
    pub fn for_config(config: &Config) -> Result<Self, Error> {
        Ok(Self::new(*ScadaLink::new(config)?.slave()))
    }

    /// The holding registers now.
    pub fn scada(&self) -> &ScadaSlave {
        &self.scada
    }

    /// The holding registers, for a SCADA server that serves them between frames (the QEMU
    /// board's Modbus link in plant mode: its writes land when they arrive, not in lockstep).
    pub fn scada_mut(&mut self) -> &mut ScadaSlave {
        &mut self.scada
    }

    /// A write of `values` to the holding registers from `address` on, all or nothing (the
    /// Modbus exception a SCADA write would get on refusal).
    pub fn write(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        self.scada.write_words(address, values)
    }

    /// One period: [`FRAME_PERIOD_MS`] steps of `controller` on `frame`; `each` sees every
    /// step's outputs and what it published (a CSV row, the log); returns the reply.
    pub fn period<const NP: usize, const HP: usize, const NF: usize, const HF: usize>(
        &mut self,
        controller: &mut Controller<NP, HP, NF, HF>,
        frame: &PlantFrame,
        mut each: impl FnMut(&Outputs, &Published),
    ) -> PlantReply {
        self.vfd.link_alarm = frame.drive.is_none();
        self.vfd.readings = frame.drive;
        if frame.drive.is_some() {
            self.vfd.reads_ok = self.vfd.reads_ok.wrapping_add(1);
        }
        let inputs = Inputs {
            pressure_code: frame.pressure_code,
            flow_code: frame.flow_code,
            commands: self.scada.commands(),
            vfd: self.vfd,
        };
        let mut reply = PlantReply {
            torque_ref_pct: 0.0,
            status: 0,
        };
        for _ in 0..FRAME_PERIOD_MS {
            let out = controller.step(&inputs);
            reply = PlantReply {
                torque_ref_pct: out.torque_ref_pct,
                status: controller.published().status,
            };
            each(&out, controller.published());
        }
        reply
    }
}

/// The plant protocol's version this side speaks.
pub const PROTOCOL_VERSION: u16 = 1;
/// Longest request line, bytes (the `\n` not counted): a frame with long decimals fits
/// several times over.
pub const MAX_LINE: usize = 96;
/// Largest ADC code (12 bits).
pub const CODE_MAX: u16 = 4095;
/// The drive's speed a frame may carry, rpm (a 16-bit signed register at 1 rpm per count).
pub const SPEED_RANGE_RPM: core::ops::RangeInclusive<f32> = -32768.0..=32767.0;
/// The drive's torque a frame may carry, % of nominal (a 16-bit signed register at 16 384
/// counts per 100 %).
pub const TORQUE_RANGE_PCT: core::ops::RangeInclusive<f32> = -200.0..=200.0;

/// Why a request line is refused (the reply `E <reason>`; see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineError {
    /// More than [`MAX_LINE`] bytes before the `\n`: `long`.
    TooLong,
    /// A byte outside printable ASCII (space, tab, `!`..=`~`): `ascii`.
    NotAscii,
    /// A blank line: `empty`.
    Empty,
    /// An unknown first field: `command`.
    Command,
    /// Too few or too many fields: `fields`.
    Fields,
    /// A field that is not a number of its kind: `number`.
    Number,
    /// A number outside its range: `range`.
    Range,
    /// NaN or an infinity: `finite`.
    NotFinite,
    /// A protocol version this side does not speak: `version`.
    Version,
}

impl LineError {
    /// The reason's word in an `E` reply.
    pub fn word(self) -> &'static str {
        match self {
            LineError::TooLong => "long",
            LineError::NotAscii => "ascii",
            LineError::Empty => "empty",
            LineError::Command => "command",
            LineError::Fields => "fields",
            LineError::Number => "number",
            LineError::Range => "range",
            LineError::NotFinite => "finite",
            LineError::Version => "version",
        }
    }

    /// The reason of a word ([`Self::word`]'s inverse).
    pub fn from_word(word: &str) -> Option<Self> {
        [
            LineError::TooLong,
            LineError::NotAscii,
            LineError::Empty,
            LineError::Command,
            LineError::Fields,
            LineError::Number,
            LineError::Range,
            LineError::NotFinite,
            LineError::Version,
        ]
        .into_iter()
        .find(|e| e.word() == word)
    }
}

/// One request line of the plant protocol, parsed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Request {
    /// `H <version>`: hello.
    Hello {
        /// The plant's protocol version.
        version: u16,
    },
    /// `S …`: one frame.
    Frame(PlantFrame),
    /// `W <register> <value>`: a holding-register write.
    Write {
        /// Holding register address (0..=65535; the map has 0..=20).
        register: u16,
        /// The value (0..=65535).
        value: u16,
    },
    /// `Q`: the end of the session.
    Quit,
}

/// One reply line of the plant protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reply {
    /// `H <version> <period_ms>`: the version spoken, the frame period.
    Hello {
        /// The protocol version ([`PROTOCOL_VERSION`]).
        version: u16,
        /// The frame period, ms ([`FRAME_PERIOD_MS`]).
        period_ms: u32,
    },
    /// `T <t_ms> <torque_ref_pct> <status>`: a frame's answer.
    Torque {
        /// The controller's time at the period's last step, ms (wrapping).
        t_ms: u32,
        /// The torque reference and the status word.
        reply: PlantReply,
    },
    /// `K`: the write was applied.
    Written,
    /// `E <code>`: the write was refused with this Modbus exception code (1..=4).
    Refused(u8),
    /// `E <reason>`: the request line was refused.
    Error(LineError),
    /// `B`: the session ended.
    Bye,
}

/// A decimal `u16` of digits only (`number` otherwise, `range` above 65535).
fn parse_u16(field: &[u8]) -> Result<u16, LineError> {
    if field.is_empty() || !field.iter().all(u8::is_ascii_digit) {
        return Err(LineError::Number);
    }
    field.iter().try_fold(0u16, |n, &d| {
        n.checked_mul(10)
            .and_then(|n| n.checked_add(u16::from(d - b'0')))
            .ok_or(LineError::Range)
    })
}

/// An ADC code: [`parse_u16`], 0..=[`CODE_MAX`].
fn parse_code(field: &[u8]) -> Result<u16, LineError> {
    let code = parse_u16(field)?;
    if code > CODE_MAX {
        return Err(LineError::Range);
    }
    Ok(code)
}

/// A finite `f32` in `range` (`core::str::parse`, the same on the host and the MCU).
fn parse_f32(field: &[u8], range: &core::ops::RangeInclusive<f32>) -> Result<f32, LineError> {
    let text = core::str::from_utf8(field).map_err(|_| LineError::NotAscii)?;
    let x: f32 = text.parse().map_err(|_| LineError::Number)?;
    if !x.is_finite() {
        return Err(LineError::NotFinite);
    }
    if !range.contains(&x) {
        return Err(LineError::Range);
    }
    Ok(x)
}

/// The fields of a line: separated by runs of spaces or tabs.
fn fields(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|&b| b == b' ' || b == b'\t')
        .filter(|f| !f.is_empty())
}

/// The line without a final `\n` and the `\r` before it; refused if longer than
/// [`MAX_LINE`] or not printable ASCII.
fn checked_line(line: &[u8]) -> Result<&[u8], LineError> {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.len() > MAX_LINE {
        return Err(LineError::TooLong);
    }
    if !line
        .iter()
        .all(|&b| b == b'\t' || (b' '..=b'~').contains(&b))
    {
        return Err(LineError::NotAscii);
    }
    Ok(line)
}

impl Request {
    /// Parses one request line (a final `\n`, and `\r\n`, allowed).
    pub fn parse(line: &[u8]) -> Result<Self, LineError> {
        let line = checked_line(line)?;
        let mut f = fields(line);
        let command = f.next().ok_or(LineError::Empty)?;
        let mut take = |n: usize| -> Result<[&[u8]; 4], LineError> {
            let mut out = [&b""[..]; 4];
            for slot in out.iter_mut().take(n) {
                *slot = f.next().ok_or(LineError::Fields)?;
            }
            Ok(out)
        };
        let request = match command {
            b"H" => {
                let [v, ..] = take(1)?;
                Request::Hello {
                    version: parse_u16(v)?,
                }
            }
            b"W" => {
                let [r, v, ..] = take(2)?;
                Request::Write {
                    register: parse_u16(r)?,
                    value: parse_u16(v)?,
                }
            }
            b"Q" => Request::Quit,
            b"S" => {
                let [p, q, speed, ..] = take(3)?;
                let drive = if speed == b"-" {
                    None
                } else {
                    let [torque, ..] = take(1)?;
                    Some(VfdReadings {
                        speed_rpm: parse_f32(speed, &SPEED_RANGE_RPM)?,
                        torque_pct: parse_f32(torque, &TORQUE_RANGE_PCT)?,
                        status: 0,
                    })
                };
                Request::Frame(PlantFrame {
                    pressure_code: parse_code(p)?,
                    flow_code: parse_code(q)?,
                    drive,
                })
            }
            _ => return Err(LineError::Command),
        };
        if f.next().is_some() {
            return Err(LineError::Fields);
        }
        Ok(request)
    }
}

/// The request line, without its `\n` (the drive's status word is not carried).
impl core::fmt::Display for Request {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Request::Hello { version } => write!(f, "H {version}"),
            Request::Frame(fr) => {
                write!(f, "S {} {}", fr.pressure_code, fr.flow_code)?;
                match fr.drive {
                    Some(d) => write!(f, " {} {}", d.speed_rpm, d.torque_pct),
                    None => write!(f, " -"),
                }
            }
            Request::Write { register, value } => write!(f, "W {register} {value}"),
            Request::Quit => write!(f, "Q"),
        }
    }
}

/// The reply line, without its `\n`.
impl core::fmt::Display for Reply {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Reply::Hello { version, period_ms } => write!(f, "H {version} {period_ms}"),
            Reply::Torque { t_ms, reply } => {
                write!(f, "T {t_ms} {} {}", reply.torque_ref_pct, reply.status)
            }
            Reply::Written => write!(f, "K"),
            Reply::Refused(code) => write!(f, "E {code}"),
            Reply::Error(e) => write!(f, "E {}", e.word()),
            Reply::Bye => write!(f, "B"),
        }
    }
}

impl Reply {
    /// Parses one reply line (for a plant written in Rust; a final `\n` allowed): the
    /// grammar of the module docs, `E` with a code 1..=4 or a known reason.
    pub fn parse(line: &[u8]) -> Result<Self, LineError> {
        let line = checked_line(line)?;
        let mut f = fields(line);
        let command = f.next().ok_or(LineError::Empty)?;
        let mut next = || f.next().ok_or(LineError::Fields);
        let reply = match command {
            b"H" => Reply::Hello {
                version: parse_u16(next()?)?,
                period_ms: parse_u32(next()?)?,
            },
            b"T" => Reply::Torque {
                t_ms: parse_u32(next()?)?,
                reply: PlantReply {
                    torque_ref_pct: parse_f32(next()?, &(f32::MIN..=f32::MAX))?,
                    status: parse_u16(next()?)?,
                },
            },
            b"K" => Reply::Written,
            b"B" => Reply::Bye,
            b"E" => {
                let what = next()?;
                match parse_u16(what) {
                    Ok(code @ 1..=4) => Reply::Refused(code as u8),
                    Ok(_) => return Err(LineError::Range),
                    Err(_) => Reply::Error(
                        core::str::from_utf8(what)
                            .ok()
                            .and_then(LineError::from_word)
                            .ok_or(LineError::Command)?,
                    ),
                }
            }
            _ => return Err(LineError::Command),
        };
        if f.next().is_some() {
            return Err(LineError::Fields);
        }
        Ok(reply)
    }
}

/// A decimal `u32` of digits only.
fn parse_u32(field: &[u8]) -> Result<u32, LineError> {
    if field.is_empty() || !field.iter().all(u8::is_ascii_digit) {
        return Err(LineError::Number);
    }
    field.iter().try_fold(0u32, |n, &d| {
        n.checked_mul(10)
            .and_then(|n| n.checked_add(u32::from(d - b'0')))
            .ok_or(LineError::Range)
    })
}

/// What a served line asks of the caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Served {
    /// Go on reading lines.
    Continue,
    /// The plant ended the session (`Q`, answered `B`): stop reading.
    Quit,
}

/// The controller's side of one request line (a final `\n` allowed): the line parsed, the
/// frame run ([`Lockstep::period`], `each` seeing every step's outputs) or the write applied
/// ([`Lockstep::write`]), and the one reply line, `\n` included, written to `out`. Never
/// panics: a bad line is answered `E <reason>` and changes nothing. An error only if `out`
/// refuses the text.
pub fn serve_line<const NP: usize, const HP: usize, const NF: usize, const HF: usize>(
    lockstep: &mut Lockstep,
    controller: &mut Controller<NP, HP, NF, HF>,
    line: &[u8],
    out: &mut impl core::fmt::Write,
    each: impl FnMut(&Outputs, &Published),
) -> Result<Served, core::fmt::Error> {
    let (reply, served) = match Request::parse(line) {
        Ok(request) => answer(lockstep, controller, request, each),
        Err(e) => (Reply::Error(e), Served::Continue),
    };
    writeln!(out, "{reply}")?;
    Ok(served)
}

/// The reply to a parsed request, its work done.
fn answer<const NP: usize, const HP: usize, const NF: usize, const HF: usize>(
    lockstep: &mut Lockstep,
    controller: &mut Controller<NP, HP, NF, HF>,
    request: Request,
    mut each: impl FnMut(&Outputs, &Published),
) -> (Reply, Served) {
    let reply = match request {
        Request::Hello { version } if version == PROTOCOL_VERSION => Reply::Hello {
            version: PROTOCOL_VERSION,
            period_ms: FRAME_PERIOD_MS,
        },
        Request::Hello { .. } => Reply::Error(LineError::Version),
        Request::Frame(frame) => {
            let mut t_ms = controller.now_ms();
            let reply = lockstep.period(controller, &frame, |o, p| {
                t_ms = o.t_ms;
                each(o, p)
            });
            Reply::Torque { t_ms, reply }
        }
        Request::Write { register, value } => match lockstep.write(register, &[value]) {
            Ok(()) => Reply::Written,
            Err(e) => Reply::Refused(e.code()),
        },
        Request::Quit => return (Reply::Bye, Served::Quit),
    };
    (reply, Served::Continue)
}

/// The controller's side of a session over a byte stream: bytes in ([`Self::feed`]), one
/// reply line out per request line, with a fixed line buffer (no allocation). The host's
/// `pumpbench control --plant-stdio` and the QEMU board run this same code.
#[derive(Debug, Clone)]
pub struct PlantSession {
    lockstep: Lockstep,
    /// The line so far: [`MAX_LINE`] bytes and a `\r`.
    line: [u8; MAX_LINE + 1],
    len: usize,
    /// The line being read is longer than the buffer.
    overflow: bool,
    ended: bool,
}

impl PlantSession {
    /// A session on `lockstep` (its holding registers as the controller starts).
    pub fn new(lockstep: Lockstep) -> Self {
        Self {
            lockstep,
            line: [0; MAX_LINE + 1],
            len: 0,
            overflow: false,
            ended: false,
        }
    }

    /// The lockstep (the holding registers).
    pub fn lockstep(&self) -> &Lockstep {
        &self.lockstep
    }

    /// The lockstep, e.g. for a SCADA write that lands between frames.
    pub fn lockstep_mut(&mut self) -> &mut Lockstep {
        &mut self.lockstep
    }

    /// The plant ended the session (`Q`): further bytes are ignored.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Takes one byte from the plant; at a `\n`, serves the line ([`serve_line`], `each`
    /// seeing every step's outputs) and writes its reply to `out`. Returns
    /// [`Served::Quit`] once the session has ended. A line longer than [`MAX_LINE`] is
    /// answered `E long` at its `\n`.
    pub fn feed<const NP: usize, const HP: usize, const NF: usize, const HF: usize>(
        &mut self,
        byte: u8,
        controller: &mut Controller<NP, HP, NF, HF>,
        out: &mut impl core::fmt::Write,
        each: impl FnMut(&Outputs, &Published),
    ) -> Result<Served, core::fmt::Error> {
        if self.ended {
            return Ok(Served::Quit);
        }
        if byte != b'\n' {
            match self.line.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return Ok(Served::Continue);
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        let served = if overflow {
            writeln!(out, "{}", Reply::Error(LineError::TooLong))?;
            Served::Continue
        } else {
            serve_line(&mut self.lockstep, controller, &self.line[..len], out, each)?
        };
        self.ended = served == Served::Quit;
        Ok(served)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::control::{Config, NarmaxModel};
    use proptest::prelude::*;
    use pump_models::{flow, pressure};
    use std::string::String;
    use std::vec::Vec;

    type Ctl =
        Controller<{ pressure::FRAMES }, { pressure::HIDDEN }, { flow::FRAMES }, { flow::HIDDEN }>;

    /// The bench's controller as a board builds it, stopped.
    fn controller() -> Ctl {
        let p = NarmaxModel::new(&pressure::F32, &pressure::Q15, 50).unwrap();
        let q = NarmaxModel::new(&flow::F32, &flow::Q15, 100).unwrap();
        Controller::new(&Config::bench(), p, q).unwrap()
    }

    fn session() -> PlantSession {
        PlantSession::new(Lockstep::new(ScadaSlave::new(1).unwrap()))
    }

    /// Every byte of `input` fed to `s`; the replies.
    fn feed(s: &mut PlantSession, c: &mut Ctl, input: &[u8]) -> String {
        let mut out = String::new();
        for &b in input {
            s.feed(b, c, &mut out, |_, _| {}).unwrap();
        }
        out
    }

    fn err(line: &str) -> Result<Request, LineError> {
        Request::parse(line.as_bytes())
    }

    #[test]
    fn requests_parse() {
        let frame = |p, q, drive| {
            Ok(Request::Frame(PlantFrame {
                pressure_code: p,
                flow_code: q,
                drive,
            }))
        };
        let drive = |speed_rpm, torque_pct| {
            Some(VfdReadings {
                speed_rpm,
                torque_pct,
                status: 0,
            })
        };
        assert_eq!(err("H 1"), Ok(Request::Hello { version: 1 }));
        assert_eq!(
            err("S 745 3723 1500 37.5\n"),
            frame(745, 3723, drive(1500.0, 37.5))
        );
        assert_eq!(err("S 0 4095 -"), frame(0, 4095, None));
        assert_eq!(
            err("  S\t1  2 -1.5e3 -200\r\n"),
            frame(1, 2, drive(-1500.0, -200.0))
        );
        assert_eq!(err("S 1 2 32767 200"), frame(1, 2, drive(32767.0, 200.0)));
        assert_eq!(
            err("S 1 2 -32768 0.000001"),
            frame(1, 2, drive(-32768.0, 1e-6))
        );
        assert_eq!(
            err("W 8 3000"),
            Ok(Request::Write {
                register: 8,
                value: 3000
            })
        );
        assert_eq!(
            err("W 65535 0065535"),
            Ok(Request::Write {
                register: 65535,
                value: 65535
            })
        );
        assert_eq!(err("Q"), Ok(Request::Quit));
        assert_eq!(err("Q\n"), Ok(Request::Quit));
    }

    /// Each reason of an `E` reply, from every kind of bad line.
    #[test]
    fn every_error_path() {
        use LineError::*;
        let cases: &[(&[u8], LineError)] = &[
            (&[b'S'; MAX_LINE + 1], TooLong),
            (b"S 1 2 3 \xff", NotAscii),
            (b"S 1 2 3 4\x00", NotAscii),
            (b"S 1 2\r3 4", NotAscii),
            (b"W 1 \xc3\xa9", NotAscii),
            (b"", Empty),
            (b"\n", Empty),
            (b" \t \r\n", Empty),
            (b"X 1", Command),
            (b"s 1 2 3 4", Command),
            (b"SS 1 2 3 4", Command),
            (b"T 1 2 3", Command),
            (b"S", Fields),
            (b"S 1 2", Fields),
            (b"S 1 2 3", Fields),
            (b"S 1 2 3 4 5", Fields),
            (b"S 1 2 - 4", Fields),
            (b"W 1", Fields),
            (b"W 1 2 3", Fields),
            (b"H", Fields),
            (b"H 1 5", Fields),
            (b"Q 1", Fields),
            (b"S 1a 2 3 4", Number),
            (b"S +1 2 3 4", Number),
            (b"S -1 2 3 4", Number),
            (b"S 1.0 2 3 4", Number),
            (b"S 1 2 x 4", Number),
            (b"S 1 2 3 1,5", Number),
            (b"S 1 2 0x10 4", Number),
            (b"S 1 2 - -", Fields),
            (b"S 1 2 -- 4", Number),
            (b"W -1 2", Number),
            (b"W 1 2.0", Number),
            (b"H v1", Number),
            (b"S 4096 2 3 4", Range),
            (b"S 1 99999999999999999999 3 4", Range),
            (b"S 1 2 32768 4", Range),
            (b"S 1 2 -32769 4", Range),
            (b"S 1 2 1e300 4", NotFinite),
            (b"S 1 2 3 200.01", Range),
            (b"S 1 2 3 -1e3", Range),
            (b"W 65536 1", Range),
            (b"W 1 70000", Range),
            (b"H 65536", Range),
            (b"S 1 2 NaN 4", NotFinite),
            (b"S 1 2 nan 4", NotFinite),
            (b"S 1 2 inf 4", NotFinite),
            (b"S 1 2 3 -inf", NotFinite),
            (b"S 1 2 3 infinity", NotFinite),
        ];
        for &(line, e) in cases {
            assert_eq!(
                Request::parse(line),
                Err(e),
                "{:?}",
                String::from_utf8_lossy(line)
            );
            assert_eq!(LineError::from_word(e.word()), Some(e));
        }
        // Exactly MAX_LINE bytes (and a `\r\n`) is no error of length.
        let mut line = Vec::from(&b"S 1 2 3 "[..]);
        line.resize(MAX_LINE, b'0');
        line.push(b'4');
        assert_eq!(Request::parse(&line), Err(LineError::TooLong));
        line.pop();
        assert!(matches!(Request::parse(&line), Ok(Request::Frame(_))));
        line.extend_from_slice(b"\r\n");
        assert!(matches!(Request::parse(&line), Ok(Request::Frame(_))));
        assert_eq!(LineError::from_word("nope"), None);
    }

    #[test]
    fn replies_format_and_parse() {
        let t = |t_ms, torque_ref_pct, status| Reply::Torque {
            t_ms,
            reply: PlantReply {
                torque_ref_pct,
                status,
            },
        };
        let cases = [
            (
                Reply::Hello {
                    version: 1,
                    period_ms: 5,
                },
                "H 1 5",
            ),
            (t(4, 0.0, 0), "T 4 0 0"),
            (t(u32::MAX, 37.51953, 513), "T 4294967295 37.51953 513"),
            (t(9, 0.1, 1), "T 9 0.1 1"),
            (t(9, 1e-7, 1), "T 9 0.0000001 1"),
            (t(9, 100.0, 65535), "T 9 100 65535"),
            (Reply::Written, "K"),
            (Reply::Refused(2), "E 2"),
            (Reply::Error(LineError::NotFinite), "E finite"),
            (Reply::Bye, "B"),
        ];
        for (reply, text) in cases {
            assert_eq!(std::format!("{reply}"), text);
            assert_eq!(Reply::parse(text.as_bytes()), Ok(reply), "{text}");
            assert_eq!(Reply::parse(std::format!("{text}\n").as_bytes()), Ok(reply));
        }
        for bad in [
            "E 0",
            "E 5",
            "E what",
            "T 1 2",
            "T 1 nan 0",
            "K 1",
            "Z",
            "",
            "H 1",
        ] {
            assert!(Reply::parse(bad.as_bytes()).is_err(), "{bad}");
        }
    }

    proptest! {
        /// A request formatted and parsed back is the same request, every f32 bit included.
        #[test]
        fn requests_round_trip(
            p in 0..=CODE_MAX,
            q in 0..=CODE_MAX,
            speed in -32768.0f32..=32767.0,
            torque in -200.0f32..=200.0,
            cut: bool,
            register: u16,
            value: u16,
        ) {
            let drive = (!cut).then_some(VfdReadings { speed_rpm: speed, torque_pct: torque, status: 0 });
            for r in [
                Request::Frame(PlantFrame { pressure_code: p, flow_code: q, drive }),
                Request::Write { register, value },
                Request::Hello { version: value },
                Request::Quit,
            ] {
                let line = std::format!("{r}\n");
                let back = Request::parse(line.as_bytes()).unwrap();
                prop_assert_eq!(back, r);
                if let (Request::Frame(a), Request::Frame(b)) = (back, r) {
                    let bits = |f: PlantFrame| f.drive.map(|d| (d.speed_rpm.to_bits(), d.torque_pct.to_bits()));
                    prop_assert_eq!(bits(a), bits(b));
                }
            }
        }

        /// Every finite f32 torque travels exactly.
        #[test]
        fn torques_round_trip(bits: u32, t_ms: u32, status: u16) {
            let x = f32::from_bits(bits);
            prop_assume!(x.is_finite());
            let reply = Reply::Torque { t_ms, reply: PlantReply { torque_ref_pct: x, status } };
            let text = std::format!("{reply}");
            prop_assert!(text.len() <= MAX_LINE || x.abs() > 1e30 || x.abs() < 1e-30);
            match Reply::parse(text.as_bytes()) {
                Ok(Reply::Torque { reply: r, t_ms: t }) => {
                    prop_assert_eq!(r.torque_ref_pct.to_bits(), bits);
                    prop_assert_eq!((t, r.status), (t_ms, status));
                }
                // The longest decimals (no exponent) are longer than a line may be.
                Err(LineError::TooLong) => prop_assert!(text.len() > MAX_LINE),
                other => prop_assert!(false, "{:?}", other),
            }
        }

        /// Hostile bytes: never a panic, one reply line per line, each a valid reply.
        #[test]
        fn random_bytes_never_panic(chunks in proptest::collection::vec(
            prop_oneof![
                proptest::collection::vec(any::<u8>(), 0..200),
                "[SWHQ]( [-+0-9.eEnaif]{0,12}){0,6}".prop_map(|s| s.into_bytes()),
            ],
            1..12,
        )) {
            let mut c = controller();
            let mut s = session();
            let mut input = Vec::new();
            for chunk in &chunks {
                input.extend_from_slice(chunk);
                input.push(b'\n');
            }
            let out = feed(&mut s, &mut c, &input);
            let lines: Vec<&str> = out.lines().collect();
            let quit = lines.iter().position(|l| *l == "B");
            let expected = match quit {
                Some(k) => k + 1,
                None => input.iter().filter(|&&b| b == b'\n').count(),
            };
            prop_assert_eq!(lines.len(), expected);
            for l in lines {
                prop_assert!(Reply::parse(l.as_bytes()).is_ok(), "{}", l);
            }
        }
    }

    #[test]
    fn a_session_answers_each_line_in_turn() {
        let mut c = controller();
        let mut s = session();
        let input = b"H 1\nH 2\nW 8 3000\nW 1 3\nW 3 1000\nW 1 9\nW 10 9000\r\nW 11 8000\nS 745 745 0 0\nS 745 745 12.5 0.8\nS 4095 745 -\nS 1 2 3\n\nQ\nS 745 745 0 0\n";
        let out = feed(&mut s, &mut c, input);
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(
            lines[..8],
            ["H 1 5", "E version", "K", "K", "E 2", "E 3", "K", "E 3"]
        );
        assert!(
            lines[8].starts_with("T 4 ")
                && lines[9].starts_with("T 9 ")
                && lines[10].starts_with("T 14 "),
            "{lines:?}"
        );
        assert_eq!(lines[11..], ["E fields", "E empty", "B"], "{lines:?}");
        assert!(s.ended());
        // The writes are in the holding registers; the refused ones changed nothing.
        let h = s.lockstep().scada().holding();
        assert_eq!((h[1], h[8], h[10], h[11]), (3, 3000, 9000, 10000));
        // The replies are the lockstep's own.
        let mut c2 = controller();
        let mut l2 = Lockstep::new(ScadaSlave::new(1).unwrap());
        l2.write(8, &[3000]).unwrap();
        l2.write(1, &[3]).unwrap();
        l2.write(10, &[9000]).unwrap();
        for (k, drive) in [Some((0.0, 0.0)), Some((12.5, 0.8)), None]
            .into_iter()
            .enumerate()
        {
            let frame = PlantFrame {
                pressure_code: if k == 2 { 4095 } else { 745 },
                flow_code: 745,
                drive: drive.map(|(speed_rpm, torque_pct)| VfdReadings {
                    speed_rpm,
                    torque_pct,
                    status: 0,
                }),
            };
            let r = l2.period(&mut c2, &frame, |_, _| {});
            let text = std::format!(
                "{}",
                Reply::Torque {
                    t_ms: c2.now_ms() - 1,
                    reply: r
                }
            );
            assert_eq!(lines[8 + k], text);
        }
    }

    #[test]
    fn a_refused_frame_runs_no_step_and_long_lines_are_refused_whole() {
        let mut c = controller();
        let mut s = session();
        let mut input = Vec::new();
        input.extend_from_slice(b"S 1 2 nan 4\n");
        input.extend(core::iter::repeat_n(b'S', 3 * MAX_LINE));
        input.extend_from_slice(b"\nS 745 745 0 0\n");
        let mut exact = Vec::from(&b"S 745 745 0 "[..]);
        exact.resize(MAX_LINE, b'0');
        input.extend_from_slice(&exact);
        input.extend_from_slice(b"\r\n");
        let out = feed(&mut s, &mut c, &input);
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines[..2], ["E finite", "E long"]);
        assert!(lines[2].starts_with("T 4 "), "{lines:?}");
        assert!(
            lines[3].starts_with("T 9 "),
            "a full-length line is served: {lines:?}"
        );
        assert_eq!(lines.len(), 4);
        assert_eq!(c.now_ms(), 10);
        // After the end, nothing more is read or answered.
        assert_eq!(feed(&mut s, &mut c, b"Q\nS 745 745 0 0\nQ\n"), "B\n");
        assert_eq!(c.now_ms(), 10);
    }

    /// The module docs' example exchange, as written there: the plant's lines (`> `) in, the
    /// controller's (`< `) out.
    #[test]
    fn the_docs_exchange_is_answered_so() {
        let docs = include_str!("plant.rs");
        let (mut sent, mut expected) = (String::new(), String::new());
        for line in docs.lines() {
            if let Some(l) = line.strip_prefix("//! > ") {
                sent.push_str(l);
                sent.push('\n');
            } else if let Some(l) = line.strip_prefix("//! < ") {
                expected.push_str(l);
                expected.push('\n');
            }
        }
        assert_eq!(
            expected.lines().count(),
            9,
            "the exchange found in the docs"
        );
        let (mut c, mut s) = (controller(), session());
        assert_eq!(feed(&mut s, &mut c, sent.as_bytes()), expected);
    }

    /// A review's session: the low limit at 50 % written before the loop's first frame, then
    /// the link cut and back. The torque comes up from 0 % at the rate (1 % a frame), on the
    /// loop's first frame and on the link's return (both were 50 % steps).
    #[test]
    fn a_low_limit_is_reached_at_the_rate_from_the_first_frame() {
        let (mut c, mut s) = (controller(), session());
        let mut input = String::from("H 1\nW 10 5000\nW 8 3000\nW 1 3\n");
        for k in 0..120 {
            input.push_str(if (60..70).contains(&k) {
                "S 745 745 -\n"
            } else {
                "S 745 745 0 0\n"
            });
        }
        let out = feed(&mut s, &mut c, input.as_bytes());
        let mut last = 0.0f32;
        for (k, line) in out.lines().skip(4).enumerate() {
            let Ok(Reply::Torque { reply: r, .. }) = Reply::parse(line.as_bytes()) else {
                panic!("frame {k}: {line}");
            };
            assert!(
                r.torque_ref_pct - last <= 1.0 + 1e-4,
                "frame {k}: {last} -> {}",
                r.torque_ref_pct
            );
            last = r.torque_ref_pct;
        }
        assert!(last >= 50.0, "within the limit at the end: {last}");
    }

    /// The same bytes, the same replies: the run is the frames' alone.
    #[test]
    fn sessions_are_deterministic() {
        let mut input = std::string::String::from("H 1\nW 8 3000\nW 1 3\n");
        let mut speed = 0.0f32;
        for k in 0..400 {
            speed += 3.7;
            let q = if (200..260).contains(&k) { 372 } else { 1500 };
            if k % 97 == 50 {
                input.push_str(&std::format!("S 2000 {q} -\n"));
            } else {
                input.push_str(&std::format!("S 2000 {q} {speed} 41.25\n"));
            }
        }
        let run = || {
            let (mut c, mut s) = (controller(), session());
            feed(&mut s, &mut c, input.as_bytes())
        };
        let a = run();
        assert_eq!(a, run());
        assert_eq!(a.lines().count(), 403);
        assert!(a.lines().skip(3).all(|l| l.starts_with("T ")), "{a}");
    }
}
