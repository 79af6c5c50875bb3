//! Cross-crate checks of `model-core`: an independently written f64 reference of the paper's
//! white-box bench ([`reference`]) and error statistics for comparisons ([`stats`]).
//!
//! The reference shares no code with `model-core`: it types the coefficients again from the
//! paper, keeps the speed in rad/s (converting to rpm only inside the polynomials), finds the
//! flow from the closed-form roots of the cubic polished by bisection, and integrates with an
//! adaptive Dormand-Prince 5(4) at a tight tolerance.
#![forbid(unsafe_code)]
// `!(x > 0.0)` is deliberate throughout: unlike `x <= 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod narmax_ref;
pub mod reference;
pub mod stats;
