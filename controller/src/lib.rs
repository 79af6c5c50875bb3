//! Board-independent logic of the bench controller: what runs on the MCU between the
//! hardware and the models, written as plain `no_std` code and tested on the host.
//!
//! - [`analog`]: the 4-20 mA inputs with NAMUR NE 43 faults;
//! - [`scada`]: the SCADA Modbus RTU slave and its register map;
//! - [`vfd`]: the VFD Modbus RTU master; [`vfdsim`]: a simulated drive (its slave side);
//! - [`rtu`]: RTU framing and the RS-485 port;
//! - [`control`]: the real-time core, stepped every 1 ms, that ties the inputs to the
//!   white-box and NARMAX models, the observer and the alarms;
//! - [`link`]: the SCADA server and the VFD master that run apart from the core;
//! - [`mod@bench`]: the virtual bench that stands in for the real one (QEMU, host tests).
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod analog;
pub mod bench;
pub mod control;
pub mod link;
pub mod rtu;
pub mod scada;
pub mod vfd;
pub mod vfdsim;
