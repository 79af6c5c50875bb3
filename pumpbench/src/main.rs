//! `pumpbench`: the host tool for the pump bench models.
//!
//! Exit codes: 0 success; 2 bad command line or bad input file (one-line error on stderr,
//! no output file left behind); 1 any other failure (e.g. the output cannot be written).

// `!(x > 0.0)` is deliberate: unlike `x <= 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod input;
mod output;
mod simulate;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;

/// Models of the UFMG pump test bench: simulate them, find their steady states.
#[derive(Parser)]
#[command(name = "pumpbench", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Which model to run.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Model {
    /// The paper's white-box bench (eqs. 3-8).
    Whitebox,
}

/// Arithmetic of the model.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Precision {
    /// Double precision (the host's reference arithmetic).
    F64,
    /// Single precision, as on the MCU.
    F32,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a torque-reference input; one output row per input row.
    ///
    /// The bench starts at the steady state of the first row's torque; each row's torque is
    /// held until the next row's time. Output columns: t_s, torque_ref_pct, speed_rpm,
    /// flow_lps, pressure_mca, then speed_rad_s, pump_head_mca, pipe_loss_mca,
    /// electromagnetic_torque_pct, load_torque_pct, extrapolated (0/1): the state AT the
    /// row's time, before that row's torque acts.
    Simulate {
        /// Model to run.
        #[arg(long, value_enum)]
        model: Model,
        /// Arithmetic.
        #[arg(long, value_enum, default_value = "f64")]
        precision: Precision,
        /// Largest internal RK4 step, ms (0 < step <= 100). Each interval between input
        /// rows is split into equal steps no longer than this, so every input time is hit.
        #[arg(long, default_value_t = 1.0, value_parser = parse_step_ms)]
        step_ms: f64,
        /// Input CSV with a header and at least `t_s,torque_ref_pct` (s, % of nominal
        /// torque 0..100); t_s strictly increasing.
        #[arg(long)]
        input: PathBuf,
        /// Output CSV (stdout if omitted). Written to a temporary file and renamed when
        /// complete: a failed run leaves nothing behind.
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// Steady states for constant torque references.
    ///
    /// Output columns: torque_ref_pct, speed_rpm, flow_lps, pressure_mca.
    Steady {
        /// Model to run.
        #[arg(long, value_enum)]
        model: Model,
        /// Arithmetic.
        #[arg(long, value_enum, default_value = "f64")]
        precision: Precision,
        /// Torque references, % (0..100): a list `5,10,15` or a range `5:85:5`
        /// (start:stop:step, stop included).
        #[arg(long, allow_hyphen_values = true)]
        torque_pct: String,
        /// Output CSV (stdout if omitted).
        #[arg(long)]
        output: Option<PathBuf>,
    },
}

fn parse_step_ms(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() && v > 0.0 && v <= model_core::MAX_STEP_S * 1e3 {
        Ok(v)
    } else {
        Err(format!(
            "step must be > 0 and <= {} ms",
            model_core::MAX_STEP_S * 1e3
        ))
    }
}

/// A failure: its message (one line) and exit code.
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
    fn usage(message: String) -> Self {
        Failure { code: 2, message }
    }
}

fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Simulate {
            model: Model::Whitebox,
            precision,
            step_ms,
            input,
            output,
        } => {
            let data = input::read_torque_input(&input)?;
            let step_s = step_ms * 1e-3;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::whitebox::<f64, _>(&data, step_s, w),
                Precision::F32 => simulate::whitebox::<f32, _>(&data, step_s, w),
            })
        }
        Command::Steady {
            model: Model::Whitebox,
            precision,
            torque_pct,
            output,
        } => {
            let torques = simulate::parse_torque_list(&torque_pct).map_err(Failure::usage)?;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::steady::<f64, _>(&torques, w),
                Precision::F32 => simulate::steady::<f32, _>(&torques, w),
            })
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("pumpbench: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}
