//! Board-independent logic of the bench controller: what runs on the MCU between the
//! hardware and the models, written as plain `no_std` code and tested on the host.
//!
//! - [`analog`]: the 4-20 mA inputs with NAMUR NE 43 faults;
//! - [`modbus`]: the Modbus RTU layer: frames, CRC, the RTU gate, content framing and the one
//!   slave engine that serves a register map;
//! - [`types`]: the core's own types (mode, arithmetic, status, published values);
//! - [`scada`]: the SCADA slave's register map, and its conversions to and from the core's
//!   types;
//! - [`vfd`]: the VFD Modbus RTU master; [`vfdsim`]: a simulated drive (its register map);
//! - [`rtu`]: RTU framing by silence and an RS-485 port on the embedded-hal traits;
//! - [`control`]: the real-time core, stepped every 1 ms, that ties the inputs to the
//!   white-box and NARMAX models, the observer and the alarms;
//! - [`protect`]: the protections that trip the torque to 0 % (dry run, overspeed, no flow);
//! - [`record`]: the commissioning record's rows, one per pressure sample;
//! - [`link`]: the SCADA server and the VFD master that run apart from the core;
//! - [`virtual_bench`]: the virtual bench that stands in for the real one (QEMU, host tests).
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod analog;
pub mod control;
pub mod link;
pub mod modbus;
pub mod plant;
pub mod protect;
pub mod record;
pub mod regulate;
pub mod rtu;
pub mod scada;
pub mod types;
pub mod vfd;
pub mod vfdsim;
pub mod virtual_bench;
