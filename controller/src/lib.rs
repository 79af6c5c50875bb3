//! Board-independent logic of the bench controller: what runs on the MCU between the
//! hardware and the models, written as plain `no_std` code and tested on the host.
//!
//! Only the analog inputs are here so far ([`analog`]); the Modbus maps, alarms and the model
//! loop follow.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod analog;
