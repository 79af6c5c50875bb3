//! The controller's two communication owners, apart from the real-time core
//! ([`crate::control::Controller`]):
//!
//! - [`ScadaLink`]: the SCADA Modbus server. It holds the holding registers (the
//!   [`Commands`] the core reads) and the last [`Published`] values (the input registers the
//!   core writes), and answers requests against them.
//! - [`VfdLink`]: the VFD Modbus master. It writes the requested torque and reads the drive
//!   over a [`VfdPort`], and reports a [`VfdStatus`] to the core.
//!
//! On the MCU each runs in its own task below the 1 ms control task: a flood of SCADA
//! requests or a slow drive delays neither the core nor the other link's bytes.

use crate::control::{Commands, Config, Error, VfdStatus};
use crate::modbus::Frame;
use crate::scada::{input_registers, setpoint_register, ScadaSlave, INPUT_REGISTERS};
use crate::types::Published;
use crate::vfd::{VfdMap, VfdMaster};

/// The SCADA server's state: holding registers in, input registers out.
#[derive(Debug, Clone)]
pub struct ScadaLink {
    slave: ScadaSlave,
    inputs: [u16; INPUT_REGISTERS],
}

impl ScadaLink {
    /// The server at `config.scada_unit`, holding the start-up mode, setpoint (rounded to the
    /// register's 0.01 %; refused outside 0..=100 %), arithmetic and adaptation; with holding registers 3
    /// and 4 if `config.virtual_bench`.
    pub fn new(config: &Config) -> Result<Self, Error> {
        let mut slave = ScadaSlave::new(config.scada_unit).ok_or(Error::Config("SCADA unit"))?;
        slave.setpoint = setpoint_register(config.initial_setpoint_pct)
            .ok_or(Error::Config("initial setpoint outside 0..=100 %"))?;
        slave.mode = config.initial_mode;
        slave.arithmetic = config.initial_arithmetic;
        slave.narmax_adapt = config.initial_narmax_adapt;
        if !config.protection.is_valid() {
            return Err(Error::Config("protection settings out of range"));
        }
        slave.protection = config.protection;
        if config.virtual_bench {
            slave = slave.with_virtual_bench();
        }
        Ok(Self {
            slave,
            inputs: input_registers(&Published::default()),
        })
    }

    /// Takes the values the core published (the input registers from now on).
    pub fn publish(&mut self, values: &Published) {
        self.inputs = input_registers(values);
    }

    /// What the holding registers ask of the core ([`ScadaSlave::commands`]).
    pub fn commands(&self) -> Commands {
        self.slave.commands()
    }

    /// The slave (holding registers).
    pub fn slave(&self) -> &ScadaSlave {
        &self.slave
    }

    /// Answers one RTU request frame; the response (if any) is in `response`.
    pub fn handle(&mut self, frame: &[u8], response: &mut Frame) -> Option<usize> {
        self.slave.handle(frame, &self.inputs, response)
    }
}

/// Where the VFD master's frames go: an RS-485 port, or a simulated drive in-process.
pub trait VfdPort {
    /// Sends one RTU request frame.
    fn send(&mut self, frame: &[u8]);
    /// Moves a complete received frame into `frame`; `false` if none is waiting.
    fn receive(&mut self, frame: &mut Frame) -> bool;
}

/// The VFD master and its buffers.
#[derive(Debug, Clone)]
pub struct VfdLink {
    master: VfdMaster,
    tx: Frame,
    rx: Frame,
}

impl VfdLink {
    /// A master for `map`; `Error::Config` if the map is not valid.
    pub fn new(map: VfdMap) -> Result<Self, Error> {
        Ok(Self {
            master: VfdMaster::new(map).ok_or(Error::Config("VFD map"))?,
            tx: Frame::new(),
            rx: Frame::new(),
        })
    }

    /// One pass at `now_ms`: answers taken from `port`, timeouts and repeats, and the next
    /// exchange started (paced by [`VfdMap::cycle_ms`]) with `requested_pct`, the torque the
    /// core asks for (the master writes 0 % instead during the link alarm).
    pub fn poll(&mut self, now_ms: u32, requested_pct: f32, port: &mut impl VfdPort) {
        while port.receive(&mut self.rx) {
            self.master.receive(&self.rx);
        }
        if self.master.poll(now_ms, &mut self.tx).is_some() {
            port.send(&self.tx);
        }
        if self
            .master
            .start(now_ms, requested_pct, &mut self.tx)
            .is_some()
        {
            port.send(&self.tx);
        }
    }

    /// What the core needs to know of the link.
    pub fn status(&self) -> VfdStatus {
        VfdStatus {
            link_alarm: self.master.alarm(),
            readings: self.master.readings(),
            reads_ok: self.master.reads_ok(),
        }
    }

    /// The master (counters, state).
    pub fn master(&self) -> &VfdMaster {
        &self.master
    }
}
