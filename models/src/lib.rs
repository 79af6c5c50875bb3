//! The bench's NARMAX models as compile-time data, one module per output.
//!
//! Each module is written by `pumpbench export --weights models/<name>.json` (the script
//! `models/make.sh` remakes both from synthetic bench data) and holds only data: the NNSYSID
//! weights, scalings and training ranges in f64, and the `static` MCU passes
//! ([`model_core::narmax::mcu::NarxF32`], [`model_core::narmax::mcu::NarxQ15`]) that
//! model-core's `const fn`s build from them at compile time. The code that checks, lays out
//! and quantises a model lives in model-core; the generic pass of a module's model is
//! `model_core::narmax::Narmax::from_nnsysid(&MODEL)`.
//!
//! Every user (the firmware, the controller's tests, the host references, the MCU bench,
//! xtask's host replay) depends on this crate: the models the firmware compiles in are the
//! ones they test.
#![no_std]

pub mod flow;
pub mod pressure;
