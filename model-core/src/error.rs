//! Errors of the models: typed, never a panic.

use core::fmt;

/// What a model refused. When a call returns one of these, the model's state is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchError {
    /// The torque reference is NaN or infinite.
    NonFiniteTorque,
    /// The torque reference is outside 0..=100 % of nominal torque.
    TorqueOutOfRange,
    /// The step or duration is NaN, infinite, negative, or the step is outside
    /// [`crate::MIN_STEP_S`]..=[`crate::MAX_STEP_S`].
    InvalidStep,
    /// A parameter is invalid; the text says which rule it breaks.
    InvalidParameter(&'static str),
    /// No steady state below [`crate::STEADY_SEARCH_MAX_RPM`] (possible only with
    /// non-physical parameters).
    NoSteadyState,
    /// The integration produced a non-finite value (possible only with non-physical
    /// parameters); the state was not updated.
    Diverged,
}

impl fmt::Display for BenchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BenchError::NonFiniteTorque => f.write_str("torque reference is NaN or infinite"),
            BenchError::TorqueOutOfRange => {
                f.write_str("torque reference outside 0..=100 % of nominal torque")
            }
            BenchError::InvalidStep => f.write_str("step must be finite, within 1e-6..=0.1 s"),
            BenchError::InvalidParameter(why) => write!(f, "invalid parameter: {why}"),
            BenchError::NoSteadyState => f.write_str("no steady state below the search limit"),
            BenchError::Diverged => f.write_str("integration produced a non-finite value"),
        }
    }
}

impl core::error::Error for BenchError {}
