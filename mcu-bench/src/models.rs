//! The firmware's NARMAX models (`pumpbench export`), the very files it compiles in.

#[path = "../../firmware/src/models/flow.rs"]
pub mod flow;
#[path = "../../firmware/src/models/pressure.rs"]
pub mod pressure;
