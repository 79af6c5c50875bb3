//! pumpbench's command line: the commands and their options (clap), the options' value
//! parsers, and the checks shared by the commands (`--weights`, `--output`).

use crate::error::Failure;
use crate::{modelfile, observe, output};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

/// Models of the UFMG pump test bench: simulate them, find their steady states.
#[derive(Parser)]
#[command(name = "pumpbench", version, about)]
pub struct Cli {
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// Which model to run.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Model {
    /// The paper's white-box bench (eqs. 3-8).
    Whitebox,
    /// A neural NARMAX model from `identify` (needs --weights).
    Narmax,
}

/// Arithmetic of the model.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Precision {
    /// Double precision (the host's reference arithmetic).
    F64,
    /// Single precision, as on the MCU.
    F32,
    /// Fixed point: the firmware's Q15 pass, bit for bit (NARX models only: nc = 0).
    Q15,
}

/// pumpbench's commands (each variant's documentation is its help text).
#[derive(Subcommand)]
pub enum Command {
    /// A simulated VFD on a serial port: a Modbus RTU slave with the controller's VFD register
    /// map (torque reference written with FC 06; speed, torque and status read with FC 03)
    /// that drives a virtual bench in real time. For host tests over a pseudo-terminal pair
    /// and for the firmware in QEMU (`cargo xtask qemu --vfd PTY`). Logs a line a second.
    VfdSim(VfdSimArgs),
    /// Simulate a torque-reference input; one output row per input row (NARMAX: per row
    /// whose target cell, if the column is there, is filled).
    ///
    /// The bench starts at the steady state of the first row's torque; each row's torque is
    /// held until the next row's time. Output columns: t_s, torque_ref_pct, speed_rpm,
    /// flow_lps, pressure_mca, then speed_rad_s, pump_head_mca, pipe_loss_mca,
    /// electromagnetic_torque_pct, load_torque_pct, extrapolated (0/1): the state AT the
    /// row's time, before that row's torque acts.
    Simulate(SimulateArgs),
    /// Steady states for constant torque references.
    ///
    /// Output columns: torque_ref_pct, speed_rpm, flow_lps, pressure_mca.
    Steady(SteadyArgs),
    /// The paper's excitation: pulses of uncorrelated amplitudes, uniform in a range, held
    /// for random whole numbers of samples. CSV `t_s,torque_ref_pct`, one row per sample;
    /// the input's normalised auto-covariance at lags 1..10 goes to stderr.
    Excite(ExciteArgs),
    /// Identify a neural NARX/NARMAX model (NNSYSID nnarx/nnarmax2 semantics, LM) from a
    /// uniformly sampled record; writes a model file (JSON). With a `speed_rpm` column (the
    /// drive's speed; the valve fixed), it also finds the transmitter's lag behind the speed,
    /// a water column's part taken out, and writes it to the file: `simulate` takes the
    /// model's prediction back through it (docs/narmax.md).
    Identify(IdentifyArgs),
    /// Free-run MAPE_d of a NARMAX model on a record (seed rows skipped, paper eq. 1) and,
    /// with --static, MAPE_s on steady-state points (eq. 2).
    Validate(ValidateArgs),
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
    Observe(ObserveArgs),
    /// A model file as Rust source for the firmware (f32 constants and a `model()`
    /// constructor); e.g. `--output models/src/pressure.rs`, then build the firmware.
    Export(ExportArgs),
    /// The paper's study end to end: identify the pressure (na=6 nb=6, 7 hidden) and flow
    /// (na=7 nb=7, 6 hidden) NARMAX models, validate them and the white-box model, and write
    /// the models, table1.md (MAPE_s / MAPE_d as the paper's Table 1, beside the paper's own
    /// numbers) and figures 4, 5, 7 and 8 (PNG) into --out. Prints the table.
    Study(StudyArgs),
    /// A SYNTHETIC bench record for a torque input: the white-box bench plus transmitter lags,
    /// noise and 12-bit quantisation. Demo data, not a measurement. CSV
    /// `t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca`, one row per input row.
    ///
    /// The bench can differ from the paper's model (valve steps, curve error) to test an
    /// observer against a known truth, which `--truth` writes beside the readings. Without
    /// these options the record is the paper's bench, as always.
    BenchData(BenchDataArgs),
    /// Close the controller's pressure and flow loops (modes 3 and 4) around a built-in plant
    /// and measure them: the MCU's own controller, in lockstep with `bench-data`'s bench (5 ms
    /// frames of 12-bit transmitter codes and drive readings), the scenario applied as SCADA
    /// holding-register writes. Prints, per scenario row, on the plant's TRUE pressure or
    /// flow: 10-90 % rise, overshoot, 2 % settling time and IAE after a setpoint step; peak
    /// deviation and time back within 2 % after any other change; the steady error over the
    /// row's last second. Every run starts settled (3 s in mode 1 at the torque that holds the
    /// first row, then 3 s of the first row); figures from t = 0.
    ///
    /// Built-in scenarios: pressure-steps (mode 3: 2, then 4, 1, 3 mca at 2, 8, 14 s),
    /// valve-steps (3 mca; valve x1.3, x1, x0.7, x1 at 2, 7, 12, 17 s), flow-steps (mode 4:
    /// 10, then 15, 8, 12 l/s at 2, 8, 14 s, then valve x1.3, x1, x0.7, x1 at 20, 25, 30,
    /// 35 s; flow transmitter 150 ms unless --flow-lag-ms), flow-meter-lost (12 l/s, the flow
    /// meter fails at 2 s, then the valve steps at 7, 12, 17, 22 s), link-cut (3 mca, the VFD
    /// link cut from 2 to 4 s). Or a CSV file: `t_s,mode,setpoint,valve` and optionally
    /// `flow_meter`, `pressure_meter`, `link` (1 ok, 0 failed / cut), `speed_reading` (1 ok,
    /// 0 the drive's speed reading stuck at 0 rpm), `static_head`; each row from its time
    /// on (the first at 0); setpoint in mca (mode 3), l/s (mode 4), % torque (mode 1); valve
    /// = k2 over the paper's (0.2..5).
    Control(ControlArgs),
}

/// Which law(s) `control` runs.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ControllerChoice {
    /// The model-based loop (holding register 14 = 0): feedforward and scheduled PI.
    Model,
    /// The PI alone with one gain set (register 14 = 1), as a drive ships it.
    Pi,
    /// Both, the same scenario and noise seed, side by side.
    Both,
}

/// Options of `pumpbench control` (their documentation is their help text).
#[derive(Args)]
pub struct ControlArgs {
    /// A built-in scenario (pressure-steps, valve-steps, flow-steps, flow-meter-lost,
    /// link-cut) or a scenario CSV file.
    #[arg(long, required_unless_present = "plant_stdio")]
    pub scenario: Option<String>,
    /// Instead of the built-in plant, serve the plant protocol (`controller::plant`, version 1)
    /// on standard input and output: an external plant closes the loop in lockstep, its
    /// scenario in its own `W` lines (docs/control.md); the controller is the boards'. With
    /// it, `--controller model` (the default) or `pi` chooses the law (holding register 14,
    /// written before the first frame; `both` needs a plant run twice: run the session once
    /// with each) and `--set` writes holding registers before the first frame. The built-in
    /// plant's options (its curves, lags, inertias, seed), the scenario's and the figures'
    /// are refused with it: the external plant is the plant, and it measures.
    #[arg(long, conflicts_with_all = [
        "scenario", "targets", "output", "plot", "seed", "hold_s",
        "flow_lag_ms", "curve_error", "curve_shape", "water_inertia", "drive_lag_ms", "rotor_inertia",
        "pressure_lag_ms", "speed_lag_ms", "static_head", "flow_update_ms",
        "drive_slew_pct_s", "transmitter_delay_ms", "pressure_noise",
    ])]
    pub plant_stdio: bool,
    /// The law(s) to run. Default: `both` on the built-in plant, `model` with
    /// `--plant-stdio`.
    #[arg(long, value_enum)]
    pub controller: Option<ControllerChoice>,
    /// Print the targets beside each figure, with PASS or MISS (a miss is not an
    /// error: the exit code stays 0).
    #[arg(long)]
    pub targets: bool,
    /// CSV of every control period (5 ms) of every run (stdout is the tables).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// PNG figure: true pressure and flow against the setpoint, torque reference.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Seed of the plant's noise (the same for every law).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How long a scenario file's last row holds, s (0 exclusive..3600).
    #[arg(long, default_value = "6")]
    pub hold_s: String,
    /// The plant: curve error, rotor inertia, water inertia, drive lag, pressure transmitter
    /// lag.
    #[command(flatten)]
    pub plant: PlantArgs,
    /// A holding-register write before the run, as commissioning sets it (repeatable), e.g.
    /// `--set 15=110` (the pressure transmitter's time constant, ms) or `--set 11=8000` (the
    /// torque high limit, 0.01 %); a signed register takes a negative value (`--set 20=-252`,
    /// the static head, 0.001 mca); a value the map refuses is an error.
    #[arg(long, value_name = "REGISTER=VALUE", allow_hyphen_values = true)]
    pub set: Vec<String>,
    /// First-order lag of the flow transmitter, ms (0..2000; 0: none). Default: the
    /// scenario's (flow-steps: 150), else 40.
    #[arg(long, value_name = "MS", allow_hyphen_values = true)]
    pub flow_lag_ms: Option<String>,
}

/// Options of `pumpbench vfd-sim` (their documentation is their help text).
#[derive(Args)]
pub struct VfdSimArgs {
    /// The serial device (e.g. /dev/pts/3, /dev/ttyUSB0), set to 19200 8N1 raw.
    #[arg(long)]
    pub port: PathBuf,
    /// Modbus unit address (1..247).
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Counts of the torque registers for 100 % torque (vendors: 16384 or 10000).
    #[arg(long, default_value_t = 16384)]
    pub counts_per_100: u16,
    /// rpm per count of the speed register.
    #[arg(long, default_value_t = 1.0)]
    pub rpm_per_count: f32,
    /// Silence that ends a request, ms.
    #[arg(long, default_value_t = 5)]
    pub idle_ms: u32,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Noise seed of the virtual bench.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Which model runs, in which arithmetic (`simulate`, `steady`).
#[derive(Args)]
pub struct ModelChoice {
    /// Model to run.
    #[arg(long, value_enum)]
    pub model: Model,
    /// Arithmetic.
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: Precision,
    /// NARMAX model file (with --model narmax).
    #[arg(long)]
    pub weights: Option<PathBuf>,
}

/// Options of `pumpbench simulate` (their documentation is their help text).
#[derive(Args)]
pub struct SimulateArgs {
    /// The model and its arithmetic.
    #[command(flatten)]
    pub choice: ModelChoice,
    /// Largest internal RK4 step, ms (0.001..=100). Each interval between input
    /// rows is split into equal steps no longer than this, so every input time is hit.
    #[arg(long, default_value_t = 1.0, value_parser = parse_step_ms)]
    pub step_ms: f64,
    /// Input CSV with a header and at least `t_s,torque_ref_pct` (s, % of nominal
    /// torque 0..100); t_s strictly increasing.
    #[arg(long)]
    pub input: PathBuf,
    /// Output CSV (stdout if omitted). Written to a temporary file and renamed when
    /// complete: a failed run leaves nothing behind.
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// NARMAX only: how the free run follows the plant. `off`: the identified model alone.
    /// `output-map`: the model runs free, its weights untouched, and an affine map of its
    /// output is fitted on line to the input's measurements (the target column)
    /// (model_core::narmax::adapt); each row's prediction is made before its measurement is
    /// taken. Readings at or beyond the spans of the controller's transmitters (0..10 mca,
    /// 0..30 l/s), which the controller clamps and does not take, are not taken.
    #[arg(long, value_enum, default_value = "off")]
    pub adapt: Adapt,
    /// The output map's memory τ, s (0.1..60; default 2): the forgetting factor is
    /// exp(−Ts/τ). Only with `--adapt output-map`.
    #[arg(long, value_parser = parse_positive)]
    pub adapt_tau_s: Option<f64>,
    /// NARMAX only: the transmitter's time constant (its damping), ms (0..2000): the output
    /// becomes the model's estimate of the process value before the transmitter, its
    /// prediction of the reading taken back through that first-order lag, x = y + τ·dy/dt
    /// (model_core::transmitter::unlag; the seed rows echoed as they are). The model is
    /// identified on, and its map follows, the readings: this is for comparing it with the
    /// process value (a bench's truth). Default: the lag `identify` found from the training
    /// record's speed, when the model file holds a trusted one (`transmitter`), else none:
    /// the prediction of the reading. 0: the prediction of the reading.
    #[arg(long, value_name = "MS", allow_hyphen_values = true)]
    pub sensor_lag_ms: Option<String>,
}

/// How `simulate --model narmax` follows the plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Adapt {
    /// The identified model alone.
    Off,
    /// An affine map of the model's output fitted on line to the measurements.
    OutputMap,
}

/// Options of `pumpbench steady` (their documentation is their help text).
#[derive(Args)]
pub struct SteadyArgs {
    /// The model and its arithmetic.
    #[command(flatten)]
    pub choice: ModelChoice,
    /// Torque references, % (0..100): a list `5,10,15` or a range `5:85:5`
    /// (start:stop:step, stop included).
    #[arg(long, allow_hyphen_values = true)]
    pub torque_pct: String,
    /// Output CSV (stdout if omitted).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// Options of `pumpbench excite` (their documentation is their help text).
#[derive(Args)]
pub struct ExciteArgs {
    /// Seed of the generator (same seed, same signal, on every machine).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Length, s.
    #[arg(long, value_parser = parse_positive)]
    pub seconds: f64,
    /// Sample period, ms.
    #[arg(long, default_value_t = 50.0, value_parser = parse_positive)]
    pub ts_ms: f64,
    /// Lowest amplitude, % (0..100).
    #[arg(long, default_value_t = 5.0)]
    pub min_pct: f64,
    /// Highest amplitude, % (0..100).
    #[arg(long, default_value_t = 85.0)]
    pub max_pct: f64,
    /// Shortest hold, s (rounded to whole samples, at least one).
    #[arg(long, default_value_t = 0.1, value_parser = parse_positive)]
    pub min_hold_s: f64,
    /// Longest hold, s.
    #[arg(long, default_value_t = 2.0, value_parser = parse_positive)]
    pub max_hold_s: f64,
    /// Output CSV (stdout if omitted).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// Options of `pumpbench identify` (their documentation is their help text).
#[derive(Args)]
pub struct IdentifyArgs {
    /// Training data: header with t_s, torque_ref_pct and the target's column; optionally
    /// speed_rpm (the transmitter's lag).
    #[arg(long)]
    pub data: PathBuf,
    /// Output to model.
    #[arg(long, value_enum)]
    pub target: modelfile::Target,
    /// Output lags y(t-1..t-na).
    #[arg(long)]
    pub na: usize,
    /// Input lags u(t-nk..t-nk-nb+1).
    #[arg(long)]
    pub nb: usize,
    /// Error lags e(t-1..t-nc) (0: NARX).
    #[arg(long, default_value_t = 0)]
    pub nc: usize,
    /// Input delay, samples.
    #[arg(long, default_value_t = 1)]
    pub nk: usize,
    /// Hidden tanh units.
    #[arg(long)]
    pub hidden: usize,
    /// Accepted Levenberg-Marquardt steps.
    #[arg(long, default_value_t = 40)]
    pub epochs: usize,
    /// Seed of the initial weights.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seeded random starts (seed, seed+1, …): up to 4 are each trained to --epochs in
    /// parallel and the lowest final training criterion wins (more: all train 10 epochs
    /// first and the best 4 continue). 1 = NNSYSID's single random start.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub starts: u64,
    /// Model file to write.
    #[arg(long)]
    pub output: PathBuf,
}

/// Options of `pumpbench validate` (their documentation is their help text).
#[derive(Args)]
pub struct ValidateArgs {
    /// Model file.
    #[arg(long)]
    pub weights: PathBuf,
    /// Validation record: t_s, torque_ref_pct and the target's column.
    #[arg(long)]
    pub data: PathBuf,
    /// Steady-state points: torque_ref_pct and the target's column.
    #[arg(long = "static")]
    pub statics: Option<PathBuf>,
    /// Arithmetic.
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: Precision,
}

/// Options of `pumpbench observe` (their documentation is their help text).
#[derive(Args)]
pub struct ObserveArgs {
    /// The record (CSV).
    #[arg(long)]
    pub data: PathBuf,
    /// Arithmetic of the observer and the monitor (f32: the MCU's).
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: observe::Precision,
    /// Output CSV (stdout if omitted, and no figure). Written to a temporary file and
    /// renamed when complete, as is the figure OUT.png (same stem; none when the output
    /// is a device such as /dev/null).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// Options of `pumpbench export` (their documentation is their help text).
#[derive(Args)]
pub struct ExportArgs {
    /// Model file.
    #[arg(long)]
    pub weights: PathBuf,
    /// Rust file to write (stdout if omitted).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// Options of `pumpbench study` (their documentation is their help text).
#[derive(Args)]
pub struct StudyArgs {
    /// Pressure training record: t_s, torque_ref_pct, pressure_mca (uniformly sampled).
    #[arg(long, required_unless_present = "demo")]
    pub train_pressure: Option<PathBuf>,
    /// Flow training record: t_s, torque_ref_pct, flow_lps (uniformly sampled).
    #[arg(long, required_unless_present = "demo")]
    pub train_flow: Option<PathBuf>,
    /// Pressure validation record (same sample period as its training record).
    #[arg(long, required_unless_present = "demo")]
    pub val_pressure: Option<PathBuf>,
    /// Flow validation record (same sample period as its training record).
    #[arg(long, required_unless_present = "demo")]
    pub val_flow: Option<PathBuf>,
    /// Steady-state points: torque_ref_pct, pressure_mca, flow_lps.
    #[arg(long = "static", required_unless_present = "demo")]
    pub statics: Option<PathBuf>,
    /// Make SYNTHETIC data instead (excite + bench-data, fixed seeds) and write it into
    /// --out too; the five files are then not given.
    #[arg(long, conflicts_with_all = ["train_pressure", "train_flow", "val_pressure", "val_flow", "statics"])]
    pub demo: bool,
    /// Output folder (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// Options of `pumpbench bench-data` (their documentation is their help text).
#[derive(Args)]
pub struct BenchDataArgs {
    /// Input CSV `t_s,torque_ref_pct` (as for `simulate`).
    #[arg(long)]
    pub input: PathBuf,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output CSV (stdout if omitted).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Valve steps `T:FACTOR,...`, times increasing: from T (s, on the input's t_s) the
    /// valve coefficient k2 is FACTOR (0.2..5) times the paper's 0.1082 √mca/(l/s), the
    /// static head c unchanged; FACTOR > 1 closes the valve (less flow, more pressure).
    /// Applied at the first 1 ms integration step at or after T (so from the first row
    /// with t_s >= T); steps at or before the first row set the valve the bench starts
    /// with. E.g. `20:1.3,40:0.7,60:1`.
    #[arg(long, value_name = "T:FACTOR,...", allow_hyphen_values = true)]
    pub valve_steps: Option<String>,
    /// The plant: curve error, rotor inertia, water inertia, drive lag, pressure transmitter
    /// lag.
    #[command(flatten)]
    pub plant: PlantArgs,
    /// Add the columns speed_true (rpm), flow_true (l/s), pressure_true (mca) and k2_true
    /// (√mca/(l/s)) after the readings: the bench's true state at the row's time, before
    /// transmitter lag, noise and quantisation (shortest round-trip form).
    #[arg(long)]
    pub truth: bool,
    /// First-order lag of the flow transmitter, ms (0..2000; 0: none).
    #[arg(
        long,
        value_name = "MS",
        default_value = "40",
        allow_hyphen_values = true
    )]
    pub flow_lag_ms: String,
}

/// The plant's options shared by `bench-data` and `control` (their documentation is their
/// help text; the flow transmitter's lag is each command's own, its default differs).
#[derive(Args)]
pub struct PlantArgs {
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
    pub curve_error: String,
    /// Curve shape error PCT, % (-50..50), on top of --curve-error: the TRUE pump-head
    /// curve's six terms in the flow Q (alpha 1, 3, 4, 5, 7, 8) times (1 + PCT/100), the
    /// load-torque curve's (the same beta) times (1 - PCT/100); the values at no flow stay.
    /// PCT > 0: a head that falls more steeply with the flow than the paper's fit (its
    /// terms in Q pull it down) and a torque that rises less; a shape no curve scale
    /// absorbs. HEAD_PCT,TORQUE_PCT sets them apart.
    #[arg(
        long,
        value_name = "PCT|HEAD_PCT,TORQUE_PCT",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub curve_shape: String,
    /// Water-column inertia L, mca·s²/l (0, or 0.001..10): the flow becomes a state,
    /// L dQ/dt = F_H(ω, Q) − (k1 + k2²) Q² + c. 0 keeps the paper's algebraic flow (and
    /// the record's bytes).
    #[arg(
        long,
        value_name = "L",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub water_inertia: String,
    /// First-order lag of the drive's torque loop, ms (0..2000; 0: none): the
    /// electromagnetic torque follows Te(u) through it.
    #[arg(
        long,
        value_name = "MS",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub drive_lag_ms: String,
    /// The drive's own torque ramp, % of nominal torque per s (0, or 10..100000; 0: none):
    /// the reference the drive acts on follows the one it is sent no faster (a drive's ramp
    /// setting), then its lag (--drive-lag-ms). The controller's own rate limit is 200 %/s
    /// by default.
    #[arg(
        long,
        value_name = "PCT_PER_S",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub drive_slew_pct_s: String,
    /// The rotor's inertia (motor, coupling and impeller: J of the speed equation), × the
    /// paper's (0.25..4; 1: the paper's bench, and the record's bytes).
    #[arg(
        long,
        value_name = "F",
        default_value = "1",
        allow_hyphen_values = true
    )]
    pub rotor_inertia: String,
    /// First-order lag of the pressure transmitter, ms (0..2000; 0: none).
    #[arg(
        long,
        value_name = "MS",
        default_value = "20",
        allow_hyphen_values = true
    )]
    pub pressure_lag_ms: String,
    /// The pressure transmitter's noise, mca, 1 σ (0..0.5; 0.003: 3 mm of water, the
    /// default): every reading's, a sum of four uniform draws scaled to it, before the 4-20 mA
    /// loop and the 12-bit ADC. A low setpoint's readings then move by this much around it
    /// (0.01 mca is 1 % of 1 mca).
    #[arg(
        long,
        value_name = "MCA",
        default_value = "0.003",
        allow_hyphen_values = true
    )]
    pub pressure_noise: String,
    /// A transport delay ahead of the pressure and flow transmitters' lags, ms (0..1000; 0:
    /// none): a tap or a meter down the pipe, a transmitter that samples and filters
    /// digitally, a reading over a fieldbus. The drive's readings are not delayed.
    #[arg(
        long,
        value_name = "MS",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub transmitter_delay_ms: String,
    /// First-order lag of the drive's speed reading, ms (0..2000; 0: none): a drive's
    /// filtered speed estimate, read over its link, lags the rotor.
    #[arg(
        long,
        value_name = "MS",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub speed_lag_ms: String,
    /// The flow meter's update period, ms (0..2000; 0: every step): between updates it
    /// holds its last reading, as a meter that computes its flow over a window, or is read
    /// over a bus, does.
    #[arg(
        long,
        value_name = "MS",
        default_value = "0",
        allow_hyphen_values = true
    )]
    pub flow_update_ms: String,
    /// The TRUE system's static head, mca (-1..5): its pressure at no flow, -c of the
    /// valve's equation (the paper's bench -0.252, its transmitter above the tank's level;
    /// a lift, the outlet above the suction's level, is positive). Under it the pump moves
    /// no water. The controller's models take theirs from holding register 20.
    #[arg(
        long,
        value_name = "MCA",
        default_value = "-0.252",
        allow_hyphen_values = true
    )]
    pub static_head: String,
}

/// A value parser: a finite number > 0.
pub fn parse_positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("'{s}' is not a positive number")),
    }
}

/// A value parser: an RK4 step, ms, in (0, [`model_core::MAX_STEP_S`] × 1000].
pub fn parse_step_ms(s: &str) -> Result<f64, String> {
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

/// The model file of `--weights` for `--model narmax` (a usage error without it).
pub fn need_weights(w: Option<PathBuf>) -> Result<modelfile::ModelFile, Failure> {
    let path =
        w.ok_or_else(|| Failure::usage("--model narmax needs --weights MODEL.json".into()))?;
    modelfile::ModelFile::read(&path)
}

/// The `--weights` file, if given, as the inputs an output must not be.
pub fn weights_input(weights: Option<&Path>) -> Vec<output::Named<'_>> {
    weights.map(|w| ("--weights", w)).into_iter().collect()
}

/// [`output::check_outputs`] for an optional `--output` (stdout if `None`: nothing to check).
pub fn check_optional_output(inputs: &[output::Named], out: Option<&Path>) -> Result<(), Failure> {
    match out {
        Some(out) => output::check_outputs(inputs, &[("--output", out)]),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        // clap's own checks of the definitions (ids, conflicts, defaults against parsers).
        Cli::command().debug_assert();
    }

    #[test]
    fn value_parsers() {
        assert_eq!(parse_positive("2.5"), Ok(2.5));
        assert_eq!(parse_positive("1e-9"), Ok(1e-9));
        for bad in ["0", "-1", "inf", "NaN", "x", ""] {
            assert_eq!(
                parse_positive(bad),
                Err(format!("'{bad}' is not a positive number")),
                "{bad}"
            );
        }
        let max_ms = model_core::MAX_STEP_S * 1e3;
        assert_eq!(parse_step_ms("1"), Ok(1.0));
        assert_eq!(parse_step_ms(&max_ms.to_string()), Ok(max_ms));
        let out_of_range = Err(format!("step must be > 0 and <= {max_ms} ms"));
        for bad in ["0", "-0.5", "inf", "NaN"] {
            assert_eq!(parse_step_ms(bad), out_of_range, "{bad}");
        }
        assert_eq!(parse_step_ms(&(max_ms * 1.001).to_string()), out_of_range);
        assert_eq!(parse_step_ms("1 ms"), Err("'1 ms' is not a number".into()));
    }

    #[test]
    fn shared_checks() {
        let e = need_weights(None).unwrap_err();
        assert_eq!(
            (e.code, e.message.as_str()),
            (2, "--model narmax needs --weights MODEL.json")
        );
        assert_eq!(
            need_weights(Some("/nonexistent/m.json".into()))
                .unwrap_err()
                .code,
            2
        );
        let w = Path::new("m.json");
        assert_eq!(weights_input(Some(w)), [("--weights", w)]);
        assert!(weights_input(None).is_empty());
        // No --output: stdout, nothing to check; an output that is an input: refused.
        assert!(check_optional_output(&[("--input", w)], None).is_ok());
        let file = tempfile::NamedTempFile::new().unwrap();
        let e =
            check_optional_output(&[("--weights", file.path())], Some(file.path())).unwrap_err();
        assert_eq!(e.code, 2);
        assert!(e.message.contains("--output"), "{}", e.message);
    }
}
