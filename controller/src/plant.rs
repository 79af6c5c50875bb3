//! A plant in the loop: the controller run in lockstep with a plant simulator, one frame per
//! control period, on the host (`pumpbench control`) and on the QEMU board (`cargo xtask qemu
//! --plant`), through this one path so that both give the same torques for the same frames.
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

use crate::control::{Controller, Inputs, Outputs, VfdStatus};
use crate::modbus::Exception;
use crate::regulate::CONTROL_PERIOD_MS;
use crate::scada::ScadaSlave;
use crate::vfd::VfdReadings;

/// One frame per this many 1 ms steps: the control period.
pub const FRAME_PERIOD_MS: u32 = CONTROL_PERIOD_MS;

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

    /// The holding registers now.
    pub fn scada(&self) -> &ScadaSlave {
        &self.scada
    }

    /// A write of `values` to the holding registers from `address` on, all or nothing (the
    /// Modbus exception a SCADA write would get on refusal).
    pub fn write(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        self.scada.write_words(address, values)
    }

    /// One period: [`FRAME_PERIOD_MS`] steps of `controller` on `frame`; `each` sees every
    /// step's outputs (a CSV row, the log); returns the reply.
    pub fn period<const NP: usize, const HP: usize, const NF: usize, const HF: usize>(
        &mut self,
        controller: &mut Controller<NP, HP, NF, HF>,
        frame: &PlantFrame,
        mut each: impl FnMut(&Outputs),
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
                status: out.published.status,
            };
            each(&out);
        }
        reply
    }
}
