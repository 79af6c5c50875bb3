//! Board-independent logic of the bench controller: what runs on the MCU between the
//! hardware and the models, written as plain `no_std` code and tested on the host.
//!
//! So far: the 4-20 mA inputs ([`analog`]), the SCADA Modbus RTU slave ([`scada`]) and the VFD
//! Modbus RTU master ([`vfd`]); the alarms and the model loop follow.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod analog;
pub mod scada;
pub mod vfd;
