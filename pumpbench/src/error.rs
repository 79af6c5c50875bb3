//! pumpbench's failures: a one-line message and the exit code (2: bad command line or bad
//! input, 1: anything else).

use crate::input;

/// A failure: its message (one line) and exit code.
#[derive(Debug)]
pub struct Failure {
    /// Exit code: 2 for bad input, 1 otherwise.
    pub code: u8,
    /// One-line message.
    pub message: String,
}

impl From<input::InputError> for Failure {
    fn from(e: input::InputError) -> Self {
        Failure {
            code: 2,
            message: e.to_string(),
        }
    }
}

impl Failure {
    /// A bad command line or input: exit code 2.
    pub fn usage(message: String) -> Self {
        Failure { code: 2, message }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_and_messages() {
        let f = Failure::usage("--min-hold-s must be <= --max-hold-s".into());
        assert_eq!(
            (f.code, f.message.as_str()),
            (2, "--min-hold-s must be <= --max-hold-s")
        );
        // A bad input file: exit code 2, the message as the input error prints it.
        let e = input::InputError {
            path: "in.csv".into(),
            line: Some(3),
            column: Some((2, "torque_ref_pct".into())),
            message: "not a number".into(),
        };
        let f = Failure::from(e.clone());
        assert_eq!(f.code, 2);
        assert_eq!(f.message, e.to_string());
        assert_eq!(f.message, "in.csv:3:2 (torque_ref_pct): not a number");
    }
}
