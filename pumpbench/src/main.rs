//! `pumpbench`: the host tool for the pump bench models.
//!
//! Exit codes: 0 success; 2 bad command line or bad input file (one-line error on stderr,
//! no output file left behind), including an output that is one of the inputs or that cannot
//! be written (checked before any input is read); 1 any other failure (e.g. writing the output
//! fails part way).

// `!(x > 0.0)` is deliberate: unlike `x <= 0.0` it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod benchdata;
mod excite;
mod export;
mod input;
mod modelfile;
mod narmaxcmd;
mod num;
mod observe;
mod output;
mod plots;
mod simulate;
mod study;
mod train;
mod vfdsim;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
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
    /// A neural NARMAX model from `identify` (needs --weights).
    Narmax,
}

/// Arithmetic of the model.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Precision {
    /// Double precision (the host's reference arithmetic).
    F64,
    /// Single precision, as on the MCU.
    F32,
    /// Fixed point: the firmware's Q15 pass, bit for bit (NARX models only: nc = 0).
    Q15,
}

#[derive(Subcommand)]
enum Command {
    /// A simulated VFD on a serial port: a Modbus RTU slave with the controller's VFD register
    /// map (torque reference written with FC 06; speed, torque and status read with FC 03)
    /// that drives a virtual bench in real time. For host tests over a pseudo-terminal pair
    /// and for the firmware in QEMU (`cargo xtask qemu --vfd PTY`). Logs a line a second.
    VfdSim {
        /// The serial device (e.g. /dev/pts/3, /dev/ttyUSB0), set to 19200 8N1 raw.
        #[arg(long)]
        port: PathBuf,
        /// Modbus unit address (1..247).
        #[arg(long, default_value_t = 1)]
        unit: u8,
        /// Counts of the torque registers for 100 % torque (vendors: 16384 or 10000).
        #[arg(long, default_value_t = 16384)]
        counts_per_100: u16,
        /// rpm per count of the speed register.
        #[arg(long, default_value_t = 1.0)]
        rpm_per_count: f32,
        /// Silence that ends a request, ms.
        #[arg(long, default_value_t = 5)]
        idle_ms: u32,
        /// Stop after this many seconds (default: run until killed).
        #[arg(long)]
        seconds: Option<f64>,
        /// Noise seed of the virtual bench.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
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
        /// NARMAX model file (with --model narmax).
        #[arg(long)]
        weights: Option<PathBuf>,
        /// Largest internal RK4 step, ms (0.001..=100). Each interval between input
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
        /// NARMAX model file (with --model narmax).
        #[arg(long)]
        weights: Option<PathBuf>,
        /// Torque references, % (0..100): a list `5,10,15` or a range `5:85:5`
        /// (start:stop:step, stop included).
        #[arg(long, allow_hyphen_values = true)]
        torque_pct: String,
        /// Output CSV (stdout if omitted).
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// The paper's excitation: pulses of uncorrelated amplitudes, uniform in a range, held
    /// for random whole numbers of samples. CSV `t_s,torque_ref_pct`, one row per sample;
    /// the input's normalised auto-covariance at lags 1..10 goes to stderr.
    Excite {
        /// Seed of the generator (same seed, same signal, on every machine).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Length, s.
        #[arg(long, value_parser = parse_positive)]
        seconds: f64,
        /// Sample period, ms.
        #[arg(long, default_value_t = 50.0, value_parser = parse_positive)]
        ts_ms: f64,
        /// Lowest amplitude, % (0..100).
        #[arg(long, default_value_t = 5.0)]
        min_pct: f64,
        /// Highest amplitude, % (0..100).
        #[arg(long, default_value_t = 85.0)]
        max_pct: f64,
        /// Shortest hold, s (rounded to whole samples, at least one).
        #[arg(long, default_value_t = 0.1, value_parser = parse_positive)]
        min_hold_s: f64,
        /// Longest hold, s.
        #[arg(long, default_value_t = 2.0, value_parser = parse_positive)]
        max_hold_s: f64,
        /// Output CSV (stdout if omitted).
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// Identify a neural NARX/NARMAX model (NNSYSID nnarx/nnarmax2 semantics, LM) from a
    /// uniformly sampled record; writes a model file (JSON).
    Identify {
        /// Training data: header with t_s, torque_ref_pct and the target's column.
        #[arg(long)]
        data: PathBuf,
        /// Output to model.
        #[arg(long, value_enum)]
        target: modelfile::Target,
        /// Output lags y(t-1..t-na).
        #[arg(long)]
        na: usize,
        /// Input lags u(t-nk..t-nk-nb+1).
        #[arg(long)]
        nb: usize,
        /// Error lags e(t-1..t-nc) (0: NARX).
        #[arg(long, default_value_t = 0)]
        nc: usize,
        /// Input delay, samples.
        #[arg(long, default_value_t = 1)]
        nk: usize,
        /// Hidden tanh units.
        #[arg(long)]
        hidden: usize,
        /// Accepted Levenberg-Marquardt steps.
        #[arg(long, default_value_t = 40)]
        epochs: usize,
        /// Seed of the initial weights.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Seeded random starts (seed, seed+1, …): up to 4 are each trained to --epochs in
        /// parallel and the lowest final training criterion wins (more: all train 10 epochs
        /// first and the best 4 continue). 1 = NNSYSID's single random start.
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=64))]
        starts: u64,
        /// Model file to write.
        #[arg(long)]
        output: PathBuf,
    },
    /// Free-run MAPE_d of a NARMAX model on a record (seed rows skipped, paper eq. 1) and,
    /// with --static, MAPE_s on steady-state points (eq. 2).
    Validate {
        /// Model file.
        #[arg(long)]
        weights: PathBuf,
        /// Validation record: t_s, torque_ref_pct and the target's column.
        #[arg(long)]
        data: PathBuf,
        /// Steady-state points: torque_ref_pct and the target's column.
        #[arg(long = "static")]
        statics: Option<PathBuf>,
        /// Arithmetic.
        #[arg(long, value_enum, default_value = "f64")]
        precision: Precision,
    },
    /// Run the observer (an extended Kalman filter on the white-box bench) and the alarm
    /// monitor over a record, as the controller runs them; one output row per input row.
    ///
    /// The record (uniformly sampled, as for `identify`) has t_s (s) and torque_ref_pct (%,
    /// 0..100) in every row, the column pressure_mca (mca) and optionally flow_lps (l/s) and
    /// speed_rpm (rpm, the VFD's); other columns are ignored, except k2_true, flow_true,
    /// speed_true and pressure_true, which are plotted. An empty measurement cell is a
    /// missing measurement; NaN or inf (or 1e999) in one is passed on and refused by the
    /// observer as implausible, which raises that transmitter's fault bit.
    ///
    /// The observer starts at the steady state of row 0's torque and takes row 0 as a step of
    /// one sample period; row k is a step from t(k-1) to t(k) with the torque of row k-1 held
    /// (as in `simulate`), then row k's measurements. Each output row is the estimate after
    /// that row's measurements (standard deviations 1 sigma; innovations and their normalised
    /// squares 0 when the measurement is missing or implausible):
    ///
    /// t_s (s, echoed), speed_rpm (rpm), flow_lps (l/s), pressure_mca (mca, outlet pressure
    /// without the transmitter's lag), valve_k2 (mca^0.5 s/l), head_scale (1: the paper's
    /// pump-head curve), speed_sd_rpm (rpm), flow_sd_lps (l/s), pressure_sd_mca (mca),
    /// valve_k2_sd (mca^0.5 s/l), head_scale_sd (1), torque_scale (1: the paper's load-torque
    /// curve), torque_scale_sd (1), pump_head_mca (mca), pipe_loss_mca (mca),
    /// hydraulic_power_w (W), pressure_innovation_mca (mca, measured - predicted),
    /// pressure_nis (1), flow_innovation_lps (l/s), flow_nis (1), speed_innovation_rpm (rpm),
    /// speed_nis (1), alarm_bits (integer: 1 pressure transmitter, 2 flow transmitter, 4 VFD
    /// link, 8 dry run, 16 no flow, 32 end of curve, 64 load changed, 128 model residual).
    ///
    /// With --output OUT.csv, a figure OUT.png beside it: speed, flow, pressure and k2
    /// estimated against the measurements and the truth columns, alarms shaded.
    Observe {
        /// The record (CSV).
        #[arg(long)]
        data: PathBuf,
        /// Arithmetic of the observer and the monitor (f32: the MCU's).
        #[arg(long, value_enum, default_value = "f64")]
        precision: observe::Precision,
        /// Output CSV (stdout if omitted, and no figure). Written to a temporary file and
        /// renamed when complete, as is the figure OUT.png (same stem; none when the output
        /// is a device such as /dev/null).
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// A model file as Rust source for the firmware (f32 constants and a `model()`
    /// constructor); e.g. `--output models/src/pressure.rs`, then build the firmware.
    Export {
        /// Model file.
        #[arg(long)]
        weights: PathBuf,
        /// Rust file to write (stdout if omitted).
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// The paper's study end to end: identify the pressure (na=6 nb=6, 7 hidden) and flow
    /// (na=7 nb=7, 6 hidden) NARMAX models, validate them and the white-box model, and write
    /// the models, table1.md (MAPE_s / MAPE_d as the paper's Table 1, beside the paper's own
    /// numbers) and figures 4, 5, 7 and 8 (PNG) into --out. Prints the table.
    Study {
        /// Pressure training record: t_s, torque_ref_pct, pressure_mca (uniformly sampled).
        #[arg(long, required_unless_present = "demo")]
        train_pressure: Option<PathBuf>,
        /// Flow training record: t_s, torque_ref_pct, flow_lps (uniformly sampled).
        #[arg(long, required_unless_present = "demo")]
        train_flow: Option<PathBuf>,
        /// Pressure validation record (same sample period as its training record).
        #[arg(long, required_unless_present = "demo")]
        val_pressure: Option<PathBuf>,
        /// Flow validation record (same sample period as its training record).
        #[arg(long, required_unless_present = "demo")]
        val_flow: Option<PathBuf>,
        /// Steady-state points: torque_ref_pct, pressure_mca, flow_lps.
        #[arg(long = "static", required_unless_present = "demo")]
        statics: Option<PathBuf>,
        /// Make SYNTHETIC data instead (excite + bench-data, fixed seeds) and write it into
        /// --out too; the five files are then not given.
        #[arg(long, conflicts_with_all = ["train_pressure", "train_flow", "val_pressure", "val_flow", "statics"])]
        demo: bool,
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// A SYNTHETIC bench record for a torque input: the white-box bench plus transmitter lags,
    /// noise and 12-bit quantisation. Demo data, not a measurement. CSV
    /// `t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca`, one row per input row.
    ///
    /// The bench can differ from the paper's model (valve steps, curve error) to test an
    /// observer against a known truth, which `--truth` writes beside the readings. Without
    /// these options the record is the paper's bench, as always.
    BenchData {
        /// Input CSV `t_s,torque_ref_pct` (as for `simulate`).
        #[arg(long)]
        input: PathBuf,
        /// Seed of the noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output CSV (stdout if omitted).
        #[arg(long)]
        output: Option<PathBuf>,
        /// Valve steps `T:FACTOR,...`, times increasing: from T (s, on the input's t_s) the
        /// valve coefficient k2 is FACTOR (0.2..5) times the paper's 0.1082 √mca/(l/s), the
        /// static head c unchanged; FACTOR > 1 closes the valve (less flow, more pressure).
        /// Applied at the first 1 ms integration step at or after T (so from the first row
        /// with t_s >= T); steps at or before the first row set the valve the bench starts
        /// with. E.g. `20:1.3,40:0.7,60:1`.
        #[arg(long, value_name = "T:FACTOR,...", allow_hyphen_values = true)]
        valve_steps: Option<String>,
        /// Curve error PCT, % (-20..20): the TRUE bench's pump-head curve F_H is the paper's
        /// times (1 + PCT/100) (all ten alpha) and its load-torque curve F_T the paper's times
        /// (1 - PCT/100) (all ten beta). PCT > 0: a stronger pump and a lighter load than the
        /// paper's fits; PCT < 0: a weaker pump and a heavier load. HEAD_PCT,TORQUE_PCT sets
        /// them apart: F_H times (1 + HEAD_PCT/100), F_T times (1 + TORQUE_PCT/100).
        #[arg(
            long,
            value_name = "PCT|HEAD_PCT,TORQUE_PCT",
            default_value = "0",
            allow_hyphen_values = true
        )]
        curve_error: String,
        /// Water-column inertia L, mca·s²/l (0, or 0.001..10): the flow becomes a state,
        /// L dQ/dt = F_H(ω, Q) − (k1 + k2²) Q² + c. 0 keeps the paper's algebraic flow (and
        /// the record's bytes).
        #[arg(
            long,
            value_name = "L",
            default_value = "0",
            allow_hyphen_values = true
        )]
        water_inertia: String,
        /// First-order lag of the drive's torque loop, ms (0..2000; 0: none): the
        /// electromagnetic torque follows Te(u) through it.
        #[arg(
            long,
            value_name = "MS",
            default_value = "0",
            allow_hyphen_values = true
        )]
        drive_lag_ms: String,
        /// Add the columns speed_true (rpm), flow_true (l/s), pressure_true (mca) and k2_true
        /// (√mca/(l/s)) after the readings: the bench's true state at the row's time, before
        /// transmitter lag, noise and quantisation (shortest round-trip form).
        #[arg(long)]
        truth: bool,
        /// First-order lag of the flow transmitter, ms (0..2000; 0: none).
        #[arg(
            long,
            value_name = "MS",
            default_value = "40",
            allow_hyphen_values = true
        )]
        flow_lag_ms: String,
        /// First-order lag of the pressure transmitter, ms (0..2000; 0: none).
        #[arg(
            long,
            value_name = "MS",
            default_value = "20",
            allow_hyphen_values = true
        )]
        pressure_lag_ms: String,
    },
}

fn parse_positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("'{s}' is not a positive number")),
    }
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
    fn usage(message: String) -> Self {
        Failure { code: 2, message }
    }
}

fn need_weights(w: Option<PathBuf>) -> Result<modelfile::ModelFile, Failure> {
    let path =
        w.ok_or_else(|| Failure::usage("--model narmax needs --weights MODEL.json".into()))?;
    modelfile::ModelFile::read(&path)
}

/// Runs `$body` with `$model` bound to the NARMAX model of file `$m` in precision `$p`.
macro_rules! with_narmax {
    ($m:expr, $p:expr, |$model:ident| $body:expr) => {
        match $p {
            Precision::F64 => {
                let $model = $m.build::<f64>().map_err(Failure::usage)?;
                $body
            }
            Precision::F32 => {
                let $model = $m.build::<f32>().map_err(Failure::usage)?;
                $body
            }
            Precision::Q15 => {
                let $model = narmaxcmd::quantized(&$m)?;
                $body
            }
        }
    };
}

/// The `--weights` file, if given, as the inputs an output must not be.
fn weights_input(weights: Option<&std::path::Path>) -> Vec<output::Named<'_>> {
    weights.map(|w| ("--weights", w)).into_iter().collect()
}

/// [`output::check_outputs`] for an optional `--output` (stdout if `None`: nothing to check).
fn check_optional_output(inputs: &[output::Named], out: Option<&Path>) -> Result<(), Failure> {
    match out {
        Some(out) => output::check_outputs(inputs, &[("--output", out)]),
        None => Ok(()),
    }
}

fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Identify {
            data,
            target,
            na,
            nb,
            nc,
            nk,
            hidden,
            epochs,
            seed,
            starts,
            output,
        } => {
            output::check_outputs(&[("--data", &data)], &[("--output", &output)])?;
            let o = narmaxcmd::Identify {
                starts: starts as usize,
                data: &data,
                target,
                structure: train::Structure {
                    na,
                    nb,
                    nc,
                    nk,
                    hidden,
                },
                epochs,
                seed,
            };
            let model = narmaxcmd::run_identify(&o)?;
            narmaxcmd::write_model(&output, &model)
        }
        Command::Validate {
            weights,
            data,
            statics,
            precision,
        } => {
            let m = modelfile::ModelFile::read(&weights)?;
            let series = narmaxcmd::read_for_model(&m, &data, true)?;
            let points = match &statics {
                None => None,
                Some(p) => {
                    let cols = input::read_columns(p, &["torque_ref_pct", m.target.column()])?;
                    Some(cols.rows().map(|r| (r[0], r[1])).collect::<Vec<_>>())
                }
            };
            let v = with_narmax!(m, precision, |model| narmaxcmd::validate(
                &model,
                &m,
                &series,
                points.as_deref()
            )?);
            println!("target={}", m.target.column());
            println!(
                "mape_d_pct={:.4} (free run, {} samples after the seed rows)",
                v.mape_d_pct, v.samples
            );
            if let Some((n, s)) = v.mape_s {
                println!("mape_s_pct={s:.4} ({n} steady-state points)");
            }
            Ok(())
        }
        Command::Observe {
            data,
            precision,
            output,
        } => observe::command(&data, precision, output.as_deref()),
        Command::Excite {
            seed,
            seconds,
            ts_ms,
            min_pct,
            max_pct,
            min_hold_s,
            max_hold_s,
            output,
        } => {
            if !(0.0..=100.0).contains(&min_pct)
                || !(0.0..=100.0).contains(&max_pct)
                || min_pct > max_pct
            {
                return Err(Failure::usage(format!(
                    "--min-pct {} and --max-pct {} must satisfy 0 <= min <= max <= 100",
                    num::Short(min_pct),
                    num::Short(max_pct)
                )));
            }
            if min_hold_s > max_hold_s {
                return Err(Failure::usage(
                    "--min-hold-s must be <= --max-hold-s".into(),
                ));
            }
            if let Some(out) = &output {
                output::check_outputs(&[], &[("--output", out)])?;
            }
            if seconds / (ts_ms * 1e-3) > 1e8 {
                return Err(Failure::usage(
                    "more than 1e8 samples: shorten --seconds".into(),
                ));
            }
            let o = excite::Excite {
                seed,
                seconds,
                ts_s: ts_ms * 1e-3,
                min_pct,
                max_pct,
                min_hold_s,
                max_hold_s,
            };
            output::write_csv(output.as_deref(), |w| excite::run(&o, w))
        }
        Command::VfdSim {
            port,
            unit,
            counts_per_100,
            rpm_per_count,
            idle_ms,
            seconds,
            seed,
        } => vfdsim::run(
            &port,
            &vfdsim::Options {
                unit,
                counts_per_100_pct: counts_per_100,
                rpm_per_count,
                idle_ms,
                seconds,
                seed,
            },
        ),
        Command::Export { weights, output } => {
            check_optional_output(&[("--weights", &weights)], output.as_deref())?;
            let m = modelfile::ModelFile::read(&weights)?;
            let source = weights.display().to_string();
            output::write_csv(output.as_deref(), |w| export::run(&m, &source, w))
        }
        Command::BenchData {
            input,
            seed,
            output,
            valve_steps,
            curve_error,
            water_inertia,
            drive_lag_ms,
            truth,
            flow_lag_ms,
            pressure_lag_ms,
        } => {
            // The options first (no file touched), then the output, then the input.
            let options = benchdata::Options {
                seed,
                valve_steps: match valve_steps.as_deref() {
                    Some(text) => benchdata::parse_valve_steps(text).map_err(Failure::usage)?,
                    None => Vec::new(),
                },
                curve_error: benchdata::parse_curve_error(&curve_error).map_err(Failure::usage)?,
                dynamics: benchdata::Dynamics {
                    water_inertia: benchdata::parse_water_inertia(&water_inertia)
                        .map_err(Failure::usage)?,
                    drive_lag_s: benchdata::parse_lag_ms("--drive-lag-ms", &drive_lag_ms)
                        .map_err(Failure::usage)?,
                },
                truth,
                flow_lag_s: benchdata::parse_lag_ms("--flow-lag-ms", &flow_lag_ms)
                    .map_err(Failure::usage)?,
                pressure_lag_s: benchdata::parse_lag_ms("--pressure-lag-ms", &pressure_lag_ms)
                    .map_err(Failure::usage)?,
            };
            benchdata::true_bench(options.curve_error).map_err(Failure::usage)?;
            check_optional_output(&[("--input", &input)], output.as_deref())?;
            let data = input::read_input_to_integrate(
                &input,
                benchdata::STEP_MS,
                benchdata::TOO_MANY_STEPS,
            )?;
            output::write_csv(output.as_deref(), |w| benchdata::run(&data, &options, w))
        }
        Command::Study {
            train_pressure,
            train_flow,
            val_pressure,
            val_flow,
            statics,
            demo,
            out,
        } => {
            let files = match (
                demo,
                train_pressure,
                train_flow,
                val_pressure,
                val_flow,
                statics,
            ) {
                (false, Some(tp), Some(tf), Some(vp), Some(vf), Some(st)) => Some(study::Files {
                    train_pressure: tp,
                    train_flow: tf,
                    val_pressure: vp,
                    val_flow: vf,
                    statics: st,
                }),
                (true, ..) => None,
                _ => {
                    return Err(Failure::usage(
                        "study needs --demo or all of --train-pressure, --train-flow, \
                         --val-pressure, --val-flow, --static"
                            .into(),
                    ))
                }
            };
            study::run(&study::Study { files, out })
        }
        Command::Simulate {
            model: Model::Whitebox,
            precision,
            step_ms,
            input,
            output,
            weights,
        } => {
            let mut inputs = vec![("--input", input.as_path())];
            inputs.extend(weights.as_deref().map(|w| ("--weights", w)));
            check_optional_output(&inputs, output.as_deref())?;
            let data = input::read_input_to_integrate(&input, step_ms, simulate::TOO_MANY_STEPS)?;
            let step_s = step_ms * 1e-3;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::whitebox::<f64, _>(&data, step_s, w),
                Precision::F32 => simulate::whitebox::<f32, _>(&data, step_s, w),
                Precision::Q15 => Err(Failure::usage(
                    "--precision q15 is for NARMAX models".into(),
                )),
            })
        }
        Command::Simulate {
            model: Model::Narmax,
            precision,
            weights,
            input,
            output,
            ..
        } => {
            let mut inputs = vec![("--input", input.as_path())];
            inputs.extend(weights.as_deref().map(|w| ("--weights", w)));
            check_optional_output(&inputs, output.as_deref())?;
            let m = need_weights(weights)?;
            let series = narmaxcmd::read_for_model(&m, &input, false)?;
            with_narmax!(m, precision, |model| output::write_csv(
                output.as_deref(),
                |w| { narmaxcmd::simulate(&model, &m, &series, w) }
            ))
        }
        Command::Steady {
            model: Model::Whitebox,
            precision,
            torque_pct,
            output,
            weights,
        } => {
            let inputs = weights_input(weights.as_deref());
            check_optional_output(&inputs, output.as_deref())?;
            let torques = simulate::parse_torque_list(&torque_pct).map_err(Failure::usage)?;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::steady::<f64, _>(&torques, w),
                Precision::F32 => simulate::steady::<f32, _>(&torques, w),
                Precision::Q15 => Err(Failure::usage(
                    "--precision q15 is for NARMAX models".into(),
                )),
            })
        }
        Command::Steady {
            model: Model::Narmax,
            precision,
            weights,
            torque_pct,
            output,
        } => {
            let inputs = weights_input(weights.as_deref());
            check_optional_output(&inputs, output.as_deref())?;
            let m = need_weights(weights)?;
            let torques = simulate::parse_torque_list(&torque_pct).map_err(Failure::usage)?;
            with_narmax!(m, precision, |model| output::write_csv(
                output.as_deref(),
                |w| { narmaxcmd::steady(&model, &m, &torques, w) }
            ))
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
