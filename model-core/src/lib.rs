//! Models of the UFMG hydraulic test bench (Cavazzana, Barbosa, Tôrres, Martinez) for a
//! controller MCU: `no_std`, no allocation, `f32` on the target and `f64` on the host through
//! one code path ([`Real`]); no `unsafe` but in [`dsp`], one audited `asm!` for the M4's `SMLAD`.
//!
//! # The white-box bench (paper eqs. 3-8)
//!
//! A VFD in torque mode drives a centrifugal pump through a fixed pipe and a half-open
//! valve. One ODE in speed, with an algebraic loop for flow:
//!
//! ```text
//! J dω/dt = Te(u) − F_T(ω, Q)                   eq. (3) with F_T = bω + Tc + F_load
//! Te(u)   = γ1 u⁵ + … + γ6                      eq. (4)
//! F_H(ω, Q) = k1 Q² + Hs                          eqs. (5), (7)
//! Q = √(Hs + c) / k2                              eq. (8)
//! ```
//!
//! # Units: why rpm, l/s, mca and percent
//!
//! The paper prints its coefficients without units. Read literally (ω in rad/s), the bench
//! would settle at 3.4 l/s at nominal speed and its load torque would be negative at the
//! operating flow. The coefficients only make sense with **ω in rpm** inside `F_H` and `F_T`
//! (nominal 58.3π rad/s = 1749 rpm), **Q in l/s**, every **head in metres of water column**
//! and both **torques in percent of the nominal 39.9 N·m**: then `Te(u) ≈ u` ("the
//! nonlinearity is very small"), `β10 = 0.43` is the Coulomb friction as the paper says, and
//! the bench reaches 320 rpm at 5 % and 1629 rpm at 85 % (paper: 351 and 1749 rpm, within the
//! 17 % MAPE of the `F_H` fit). The ODE therefore reads
//!
//! ```text
//! dω_rpm/dt = (Te(u) − F_T(ω_rpm, Q)) · (39.9 N·m / 100 %) / J · 30/π      [rpm/s]
//! ```
//!
//! and this crate keeps the state in rpm, with the unit in every name (`speed_rpm`,
//! `flow_lps`, `pressure_mca`, `torque_ref_pct`); rad/s is given at the output.
//!
//! # The observer and the alarms
//!
//! [`observer`] is an extended Kalman filter on this bench: speed, flow, the valve k2 and the
//! curves' scales from whatever measurements arrive (pressure, flow, the VFD's speed), each
//! with its standard deviation; [`monitor`] turns it and the measurements into alarms (dry
//! run, no flow, end of curve, load changed, model residual, transmitter and link faults) and
//! hands its drive readings on to [`inertia`], which measures the rotor's inertia for the
//! controller's loops and the dry-run rule; [`drive_lag`] measures the drive's torque lag from
//! its torque readings, for the loops' braking.
//!
//! # Use
//!
//! ```
//! use model_core::{BenchState, Scheme, WhiteBox};
//! let bench = WhiteBox::<f32>::paper();
//! let mut state = bench.steady_state(20.0).unwrap();
//! bench.step(&mut state, 60.0, 0.001, Scheme::Rk4).unwrap();
//! let s = bench.signals(&state);
//! assert!(s.flow_lps > 0.0 && s.pressure_mca > 0.0);
//! ```
#![cfg_attr(not(test), no_std)]
// `unsafe` is denied everywhere but in `dsp`, the one audited module (an `asm!` for SMLAD).
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod drive_lag;
pub mod dsp;
pub mod equations;
pub mod error;
pub mod excitation;
pub mod flow;
pub mod inertia;
pub mod inverse;
pub mod monitor;
pub mod narmax;
pub mod observer;
pub mod params;
pub mod scalar;
pub mod transmitter;
pub mod units;
pub mod whitebox;

pub use error::BenchError;
pub use params::BenchParams;
pub use scalar::Real;
pub use whitebox::{
    BenchState, Extrapolation, Scheme, Signals, WhiteBox, MAX_STEP_S, MIN_STEP_S,
    STEADY_SCAN_STEP_RPM, STEADY_SEARCH_MAX_RPM,
};
