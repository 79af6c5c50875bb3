//! `pumpbench control`: the controller's pressure and flow loops (modes 3 and 4) judged with a
//! plant in the loop.
//!
//! The controller is the MCU's own ([`board_common::build_controller`] with
//! [`Config::bench`], the compiled-in NARMAX models), run through the lockstep every board
//! runs a plant through ([`controller::plant::Lockstep`]): every
//! [`FRAME_PERIOD_MS`] the plant shows a [`PlantFrame`] (the two transmitters' ADC codes and
//! the drive's readings), the controller runs its 1 ms steps on it and answers a torque
//! reference, and the plant advances one period with that torque in 1 ms steps. The scenario
//! reaches the controller only as SCADA holding-register writes at frame boundaries
//! ([`Lockstep::write`]: mode register 1, setpoints 0, 8 and 9, law 14), as an operator's
//! would.
//!
//! The plant is behind [`PlantSide`]: the built-in one ([`BuiltInPlant`], the physics of
//! [`crate::plant`]: `bench-data`'s bench) or any other that speaks frames.
//!
//! # Scenario
//! A CSV with the header `t_s,mode,setpoint,valve` and the optional columns `flow_meter`,
//! `pressure_meter` (1 works, 0 failed: its loop reads 2 mA, an NE 43 fault), `link` (1
//! up, 0 cut: no drive readings, the controller applies 0 %) and `speed_reading` (1 the
//! drive reports its speed, 0 its speed reading stuck at 0 rpm, the torque still read). Each row applies from its time
//! on (at the first frame at or after it, a multiple of 5 ms); times strictly increasing, the
//! first 0. `mode`: 0 stop, 1 manual torque, 2 excitation profile, 3 pressure, 4 flow;
//! `setpoint`: mca in mode 3 (0..=65.535, holding register 8 in 0.001 mca), l/s in mode 4
//! (0..=655.35, register 9 in 0.01 l/s), % torque in mode 1 (0..=100, register 0), ignored in
//! modes 0 and 2 (may be empty there); `valve`: the valve's k2 as a factor of the paper's
//! (0.2..=5); the optional `static_head`: holding register 20 written at the row, the static
//! head the models take, mca (−10..=10, 0.001 mca; empty: no write), as commissioning would
//! correct it. The last row holds for `--hold-s` seconds.
//!
//! # A settled start
//! Every run starts at t = −6 s with the plant at the steady state that holds the first row
//! (in mode 3 or 4 the torque the TRUE plant needs for its setpoint, from
//! [`model_core::inverse::steady_torque`]; in mode 1 its torque), the controller in mode 1 at
//! that torque for 3 s (its observer finds the load), then in the first row's mode, setpoint,
//! valve and sensors from t = −3 s. The figures start at t = 0; the CSV has the whole run.
//!
//! # Figures
//! On the plant's TRUE pressure or flow (not the transmitters' readings), for the controlled
//! value of each row's mode (pressure in mode 3, flow in mode 4), from the row's frame to the
//! next row's ([`figures`]):
//! - a setpoint step: 10-90 % rise time, overshoot (% of the step), 2 % settling time (the
//!   last exit from ±2 % of the new setpoint), IAE (∫|setpoint − true| dt, mca·s or l/s·s);
//! - any other change (valve, a sensor, the link): the peak deviation (% of the setpoint), the
//!   time back within 2 % (the last exit from the band), the IAE;
//! - every row: the steady error, the mean of (true − setpoint) / setpoint over the last
//!   second before the next row, %.

use crate::cli::{ControlArgs, ControllerChoice};
use crate::commands::plant_options;
use crate::error::Failure;
use crate::input::InputError;
use crate::num::Short;
use crate::output::{self, Named};
use crate::plant::{
    Plant, PlantError, PlantOptions, SensorState, Truth, VALVE_FACTOR_MAX, VALVE_FACTOR_MIN,
};
use controller::control::{Config, Outputs};
use controller::plant::{Lockstep, PlantFrame, PlantReply, FRAME_PERIOD_MS};
use controller::scada::ScadaSlave;
use controller::types::Status;
use model_core::inverse::{steady_torque, Load, Target};
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

mod plot;

/// How long the controller runs in mode 1 at the start torque before the first row, s.
pub const PRE_MANUAL_S: f64 = 3.0;
/// How long the first row acts before the figures start (t = 0), s.
pub const PRE_ROW_S: f64 = 3.0;
/// The window of the steady error before each next row, s.
pub const STEADY_WINDOW_S: f64 = 1.0;
/// The settling band, fraction of the setpoint.
pub const BAND: f64 = 0.02;
/// Longest scenario, s.
pub const MAX_SCENARIO_S: f64 = 3600.0;
/// Holding register: the torque setpoint of mode 1, 0.01 %.
const REG_TORQUE: u16 = 0;
/// Holding register: the mode.
const REG_MODE: u16 = 1;
/// Holding register: the pressure setpoint, 0.001 mca.
const REG_PRESSURE: u16 = 8;
/// Holding register: the flow setpoint, 0.01 l/s.
const REG_FLOW: u16 = 9;
/// Holding register: the law (0 model-based, 1 PI alone).
const REG_LAW: u16 = 14;
/// Holding register: the static head, 0.001 mca, signed (`controller::scada::STATIC_HEAD_RANGE`).
const REG_STATIC_HEAD: u16 = 20;

/// The plant's side of the lockstep: a frame per period, the controller's reply applied over
/// the next period. The built-in plant is [`BuiltInPlant`]; an external one (frames on a
/// serial line or stdin/stdout) implements the same.
pub trait PlantSide {
    /// What the controller sees for the coming period.
    fn frame(&mut self) -> Result<PlantFrame, Failure>;
    /// The controller's reply: the plant advances one period ([`FRAME_PERIOD_MS`]) with it.
    fn apply(&mut self, reply: &PlantReply) -> Result<(), Failure>;
    /// The scenario's plant-side conditions from now on: the valve factor (k2 over the
    /// paper's) and which sensors work. A plant that cannot take them (an external plant runs
    /// its own scenario) refuses anything but a nominal valve with every sensor working.
    fn set_conditions(&mut self, valve_factor: f64, sensors: SensorState) -> Result<(), Failure>;
    /// The plant's true state now, if it tells it (the figures use it; without it they use the
    /// controller's measurement and say so).
    fn truth(&self) -> Option<Truth>;
}

/// The built-in plant ([`Plant`]): one period is [`FRAME_PERIOD_MS`] steps of 1 ms.
#[derive(Debug, Clone)]
pub struct BuiltInPlant {
    plant: Plant,
}

impl BuiltInPlant {
    /// The plant `plant`.
    pub fn new(plant: Plant) -> Self {
        Self { plant }
    }
}

/// A plant failure as a command's failure.
fn plant_failure(e: PlantError) -> Failure {
    match e {
        PlantError::Options(message) => Failure { code: 2, message },
        e => Failure {
            code: 1,
            message: e.to_string(),
        },
    }
}

impl PlantSide for BuiltInPlant {
    fn frame(&mut self) -> Result<PlantFrame, Failure> {
        Ok(self.plant.frame())
    }

    fn apply(&mut self, reply: &PlantReply) -> Result<(), Failure> {
        let u = f64::from(reply.torque_ref_pct);
        if !(0.0..=100.0).contains(&u) {
            return Err(Failure {
                code: 1,
                message: format!("the controller answered a torque of {} %", Short(u)),
            });
        }
        for _ in 0..FRAME_PERIOD_MS {
            self.plant.advance(u, 1e-3).map_err(plant_failure)?;
        }
        Ok(())
    }

    fn set_conditions(&mut self, valve_factor: f64, sensors: SensorState) -> Result<(), Failure> {
        self.plant
            .set_valve_factor(valve_factor)
            .map_err(plant_failure)?;
        self.plant.set_sensors(sensors);
        Ok(())
    }

    fn truth(&self) -> Option<Truth> {
        Some(self.plant.truth())
    }
}

/// The law of modes 3 and 4 (holding register 14).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Law {
    /// 0: the model-based loop (feedforward from the steady-state inverse, scheduled PI).
    Model,
    /// 1: the PI alone, one gain set, as a drive ships it.
    Pi,
}

impl Law {
    /// Holding register 14's value.
    pub fn register(self) -> u16 {
        match self {
            Law::Model => 0,
            Law::Pi => 1,
        }
    }

    /// Its name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Law::Model => "model",
            Law::Pi => "pi",
        }
    }
}

/// One scenario row: from `t_s` on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Time, s (≥ 0; the first row's is 0).
    pub t_s: f64,
    /// Mode (holding register 1): 0..=4.
    pub mode: u16,
    /// Setpoint in the mode's unit (mca, l/s, %); 0 in modes 0 and 2.
    pub setpoint: f64,
    /// Valve k2 over the paper's.
    pub valve: f64,
    /// Which sensors work.
    pub sensors: SensorState,
    /// The static head written to register 20 at this row, mca (−10..=10); `None`: no write.
    pub static_head_mca: Option<f64>,
}

impl Row {
    /// The holding-register writes that set this row's setpoint: (register, value).
    fn setpoint_write(&self) -> Option<(u16, u16)> {
        match self.mode {
            1 => Some((REG_TORQUE, (self.setpoint * 100.0).round() as u16)),
            3 => Some((REG_PRESSURE, (self.setpoint * 1000.0).round() as u16)),
            4 => Some((REG_FLOW, (self.setpoint * 100.0).round() as u16)),
            _ => None,
        }
    }
}

/// A scenario: its rows, how long it runs, and the flow transmitter's lag it asks for.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Its name (a built-in name or the file's path).
    pub name: String,
    /// Rows, times strictly increasing, the first at 0.
    pub rows: Vec<Row>,
    /// End of the run, s (after the last row).
    pub end_s: f64,
    /// The flow transmitter lag the scenario is meant for, ms (`--flow-lag-ms` overrides it).
    pub flow_lag_ms: Option<f64>,
}

/// The built-in scenarios' names.
pub const BUILT_IN: [&str; 5] = [
    "pressure-steps",
    "valve-steps",
    "flow-steps",
    "flow-meter-lost",
    "link-cut",
];

/// The built-in scenario `name` (see [`BUILT_IN`]):
/// - `pressure-steps`: mode 3, 2 mca, then 4, 1 and 3 mca at 2, 8 and 14 s; ends at 20 s;
/// - `valve-steps`: mode 3 at 3 mca, the valve ×1.3, ×1, ×0.7, ×1 at 2, 7, 12, 17 s; 22 s;
/// - `flow-steps` (flow transmitter 150 ms): mode 4, 10 l/s, then 15, 8 and 12 l/s at 2, 8
///   and 14 s, then at 12 l/s the valve ×1.3, ×1, ×0.7, ×1 at 20, 25, 30, 35 s; 40 s;
/// - `flow-meter-lost`: mode 4 at 12 l/s, the flow meter fails at 2 s, then the valve ×1.3,
///   ×1, ×0.7, ×1 at 7, 12, 17, 22 s; 27 s;
/// - `link-cut`: mode 3 at 3 mca, the VFD link cut at 2 s and restored at 4 s; 10 s.
pub fn built_in(name: &str) -> Option<Scenario> {
    let row = |t_s: f64, mode: u16, setpoint: f64, valve: f64, sensors: SensorState| Row {
        t_s,
        mode,
        setpoint,
        valve,
        sensors,
        static_head_mca: None,
    };
    let ok = SensorState::OK;
    let no_meter = SensorState {
        flow_meter: false,
        ..ok
    };
    let cut = SensorState { link: false, ..ok };
    let (rows, end_s, flow_lag_ms) = match name {
        "pressure-steps" => (
            vec![
                row(0.0, 3, 2.0, 1.0, ok),
                row(2.0, 3, 4.0, 1.0, ok),
                row(8.0, 3, 1.0, 1.0, ok),
                row(14.0, 3, 3.0, 1.0, ok),
            ],
            20.0,
            None,
        ),
        "valve-steps" => (
            vec![
                row(0.0, 3, 3.0, 1.0, ok),
                row(2.0, 3, 3.0, 1.3, ok),
                row(7.0, 3, 3.0, 1.0, ok),
                row(12.0, 3, 3.0, 0.7, ok),
                row(17.0, 3, 3.0, 1.0, ok),
            ],
            22.0,
            None,
        ),
        "flow-steps" => (
            vec![
                row(0.0, 4, 10.0, 1.0, ok),
                row(2.0, 4, 15.0, 1.0, ok),
                row(8.0, 4, 8.0, 1.0, ok),
                row(14.0, 4, 12.0, 1.0, ok),
                row(20.0, 4, 12.0, 1.3, ok),
                row(25.0, 4, 12.0, 1.0, ok),
                row(30.0, 4, 12.0, 0.7, ok),
                row(35.0, 4, 12.0, 1.0, ok),
            ],
            40.0,
            Some(150.0),
        ),
        "flow-meter-lost" => (
            vec![
                row(0.0, 4, 12.0, 1.0, ok),
                row(2.0, 4, 12.0, 1.0, no_meter),
                row(7.0, 4, 12.0, 1.3, no_meter),
                row(12.0, 4, 12.0, 1.0, no_meter),
                row(17.0, 4, 12.0, 0.7, no_meter),
                row(22.0, 4, 12.0, 1.0, no_meter),
            ],
            27.0,
            None,
        ),
        "link-cut" => (
            vec![
                row(0.0, 3, 3.0, 1.0, ok),
                row(2.0, 3, 3.0, 1.0, cut),
                row(4.0, 3, 3.0, 1.0, ok),
            ],
            10.0,
            None,
        ),
        _ => return None,
    };
    Some(Scenario {
        name: name.to_string(),
        rows,
        end_s,
        flow_lag_ms,
    })
}

/// The setpoint's range in `mode` (its holding register's), and its unit; `None` for modes
/// without one.
fn setpoint_range(mode: u16) -> Option<(f64, &'static str)> {
    match mode {
        1 => Some((100.0, "%")),
        3 => Some((65.535, "mca")),
        4 => Some((655.35, "l/s")),
        _ => None,
    }
}

/// Reads a scenario file (see the module docs); the last row holds for `hold_s` seconds.
/// Errors name the file, the line and the column.
pub fn read_scenario(path: &Path, hold_s: f64) -> Result<Scenario, InputError> {
    let names = ["t_s", "mode", "setpoint", "valve"];
    let optional = [
        "flow_meter",
        "pressure_meter",
        "link",
        "static_head",
        "speed_reading",
    ];
    let mut rows: Vec<Row> = Vec::new();
    let err = |line: u64, c: usize, name: &str, message: String| InputError {
        path: path.to_path_buf(),
        line: Some(line),
        column: Some((c + 1, name.to_string())),
        message,
    };
    crate::input::scan_csv(path, &names, &optional, |line, cols, record| {
        let cell = |k: usize| -> Option<(usize, &str)> {
            cols[k].map(|c| (c, record.get(c).unwrap_or("")))
        };
        // A cell's value and its text, which a refusal echoes as typed (`Short` would print
        // 100000 as "1e5").
        let number = |k: usize, name: &str| -> Result<Option<(f64, &str)>, InputError> {
            match cell(k) {
                None => Ok(None),
                Some((_, "")) => Ok(None),
                Some((c, text)) => {
                    crate::input::finite_cell(path, line, c, name, text).map(|v| Some((v, text)))
                }
            }
        };
        let shown = |text: &str| crate::input::shown(text.trim());
        let col = |k: usize| cols[k].unwrap_or(0);
        let (t_s, t_text) = number(0, "t_s")?
            .ok_or_else(|| err(line, col(0), "t_s", "empty: a time is needed".into()))?;
        match rows.last() {
            None if t_s != 0.0 => {
                return Err(err(
                    line,
                    col(0),
                    "t_s",
                    format!(
                        "the first row's time is {} s: it must be 0 (the settled start)",
                        shown(t_text)
                    ),
                ))
            }
            Some(prev) if !(t_s > prev.t_s) => {
                return Err(err(
                    line,
                    col(0),
                    "t_s",
                    format!(
                        "time {} s is not after the previous row's {} s",
                        shown(t_text),
                        Short(prev.t_s)
                    ),
                ))
            }
            _ => {}
        }
        if t_s > MAX_SCENARIO_S {
            return Err(err(
                line,
                col(0),
                "t_s",
                format!(
                    "time {} s is beyond the longest scenario, {MAX_SCENARIO_S} s",
                    shown(t_text)
                ),
            ));
        }
        let (mode_v, mode_text) = number(1, "mode")?
            .ok_or_else(|| err(line, col(1), "mode", "empty: a mode is needed".into()))?;
        if !(mode_v.fract() == 0.0 && (0.0..=4.0).contains(&mode_v)) {
            return Err(err(
                line,
                col(1),
                "mode",
                format!(
                    "unknown mode {}: 0 stop, 1 manual torque, 2 profile, 3 pressure, 4 flow",
                    shown(mode_text)
                ),
            ));
        }
        let mode = mode_v as u16;
        let setpoint = match (setpoint_range(mode), number(2, "setpoint")?) {
            (None, v) => v.map_or(0.0, |(v, _)| v),
            (Some(_), None) => {
                return Err(err(
                    line,
                    col(2),
                    "setpoint",
                    format!("empty: mode {mode} needs a setpoint"),
                ))
            }
            (Some((max, unit)), Some((v, text))) => {
                if !(0.0..=max).contains(&v) {
                    return Err(err(
                        line,
                        col(2),
                        "setpoint",
                        format!(
                            "setpoint {} {unit} is outside mode {mode}'s register range 0..{}",
                            shown(text),
                            Short(max)
                        ),
                    ));
                }
                v
            }
        };
        let (valve, valve_text) = number(3, "valve")?.ok_or_else(|| {
            err(
                line,
                col(3),
                "valve",
                "empty: a valve factor is needed".into(),
            )
        })?;
        if !(VALVE_FACTOR_MIN..=VALVE_FACTOR_MAX).contains(&valve) {
            return Err(err(
                line,
                col(3),
                "valve",
                format!(
                    "valve factor {} is outside {}..{}",
                    shown(valve_text),
                    Short(VALVE_FACTOR_MIN),
                    Short(VALVE_FACTOR_MAX)
                ),
            ));
        }
        let flag = |k: usize, name: &str| -> Result<bool, InputError> {
            match number(k, name)? {
                None => Ok(true),
                Some((1.0, _)) => Ok(true),
                Some((0.0, _)) => Ok(false),
                Some((_, text)) => Err(err(
                    line,
                    col(k),
                    name,
                    format!("{} is not 0 or 1", shown(text)),
                )),
            }
        };
        let sensors = SensorState {
            flow_meter: flag(4, "flow_meter")?,
            pressure_meter: flag(5, "pressure_meter")?,
            link: flag(6, "link")?,
            speed_reading: flag(8, "speed_reading")?,
        };
        let max = f64::from(controller::control::STATIC_HEAD_MAX_MCA);
        let static_head_mca = match number(7, "static_head")? {
            Some((v, text)) if !(-max..=max).contains(&v) => {
                return Err(err(
                    line,
                    col(7),
                    "static_head",
                    format!(
                        "static head {} mca is outside register 20's range -{}..{}",
                        shown(text),
                        Short(max),
                        Short(max)
                    ),
                ))
            }
            // (As register 20 takes it: to 0.001 mca, and so the row says; + 0 makes a −0 0.)
            v => v.map(|(v, _)| (v * 1000.0).round() / 1000.0 + 0.0),
        };
        rows.push(Row {
            t_s,
            mode,
            setpoint,
            valve,
            sensors,
            static_head_mca,
        });
        Ok(())
    })?;
    let last = rows.last().map_or(0.0, |r| r.t_s);
    Ok(Scenario {
        name: path.display().to_string(),
        rows,
        end_s: last + hold_s,
        flow_lag_ms: None,
    })
}

/// One control period of a run: the plant at the frame's time and the controller's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time of the frame, s (negative before the figures start).
    pub t_s: f64,
    /// The scenario row acting (index into [`Scenario::rows`]; the first row's also before
    /// it acts, in the pre-roll).
    pub row: usize,
    /// The controller's mode (holding register 1).
    pub mode: u16,
    /// The plant's truth at the frame's time, if the plant tells it.
    pub truth: Option<Truth>,
    /// What the controller published at the period's end.
    pub published: controller::types::Published,
    /// The torque reference the plant applies over the period, %.
    pub torque_ref_pct: f32,
}

/// A run's result: its samples and its torque checks.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// The law.
    pub law: Law,
    /// Every period's sample.
    pub samples: Vec<Sample>,
    /// Steps whose torque or loop outputs were NaN or infinite.
    pub nan_steps: u64,
    /// Steps whose torque was outside 0..=100 % or, in modes 3 and 4, the limits of
    /// holding registers 10 and 11 (under the low limit only while the torque is neither 0 %,
    /// a stop's, a cut link's or a trip's, nor coming up to the limit after a switch or the
    /// link's return, as the controller brings it at the switch rate).
    pub out_of_limits: u64,
    /// The largest torque change between two periods, the second with the link up and no
    /// trip (a cut link's or a trip's 0 % excepted, the way back included), counted from the
    /// high limit where the torque before was above it (the drop onto it applies at once), %/s.
    pub max_rate_pct_per_s: f64,
    /// The torque rate limit of holding register 12 (the loops), or the switch rate where it
    /// is faster (a mode switch moves the torque at least at
    /// [`controller::control::SWITCH_RATE_MIN_PCT_PER_S`]), %/s.
    pub rate_limit_pct_per_s: f64,
    /// The plant's lag beyond the model the pressure and flow loops took by the run's end, s
    /// (`Controller::measured_lag_s`: measured on setpoint steps or raised by the ring watch;
    /// 0 if neither: the PI alone never does).
    pub measured_lag_s: [f32; 2],
    /// The rotor's inertia the controller measured by the run's end, × the paper's
    /// (`Controller::inertia_factor`; 1 until measured).
    pub inertia_factor: f32,
    /// The drive's torque lag the controller measured by the run's end, s
    /// (`Controller::drive_lag_s`; 0 until measured).
    pub drive_lag_s: f32,
    /// The static head the models took at the run's end, mca (`Controller::static_head_mca`:
    /// register 20's, or learnt while it holds its default).
    pub static_head_mca: f32,
    /// The drive's speed reading's lag the controller measured by the run's end, s
    /// (`Controller::speed_lag_s`; 0 until measured).
    pub speed_lag_s: f32,
    /// The time a protection held the torque at 0 % (status bit 7), s.
    pub tripped_s: f64,
}

/// A `--set REGISTER=VALUE`: the register a decimal u16, the value a decimal u16 or, for
/// the signed register 20, an i16 (−32768..=−1 written as its two's complement, as a Modbus
/// master sends it).
fn parse_setting(text: &str) -> Result<(u16, u16), Failure> {
    let bad = || {
        Failure::usage(format!(
            "--set {text}: must be REGISTER=VALUE, the register 0..=65535, the value \
             0..=65535 (register 20, signed: -32768..=32767)"
        ))
    };
    let (r, v) = text.split_once('=').ok_or_else(bad)?;
    let (register, v) = (r.trim().parse::<u16>().map_err(|_| bad())?, v.trim());
    let value = match v.parse::<u16>() {
        Ok(u) => u,
        // Only a signed register takes a negative value (elsewhere −1 would land as 65 535).
        Err(_) if register == 20 => v.parse::<i16>().map_err(|_| bad())? as u16,
        Err(_) => return Err(bad()),
    };
    Ok((register, value))
}

fn refused(what: &str, e: controller::modbus::Exception) -> Failure {
    Failure {
        code: 1,
        message: format!("the controller refused {what}: {e:?}"),
    }
}

/// The torque that holds `row` on the plant (its true curves and valve) at steady state.
fn start_torque(plant: &Plant, row: &Row) -> Result<f64, Failure> {
    let p = plant.params();
    let load = Load {
        valve_k2: p.valve_k2,
        head_scale: 1.0,
        torque_scale: 1.0,
    };
    let target = match row.mode {
        1 => return Ok(row.setpoint),
        3 => Target::PressureMca(row.setpoint),
        4 => Target::FlowLps(row.setpoint),
        _ => return Ok(0.0),
    };
    let no_start = |why: String| Failure {
        code: 2,
        message: format!(
            "the first row's setpoint {} {} cannot be held on this plant: {why}",
            Short(row.setpoint),
            unit(row.mode)
        ),
    };
    let s =
        steady_torque(p, load, target).map_err(|e| no_start(format!("no steady state ({e})")))?;
    if s.limited && s.torque_ref_pct > 0.0 {
        return Err(no_start("it needs more than 100 % torque".into()));
    }
    Ok(s.torque_ref_pct)
}

/// The built-in plant for `scenario`, settled where its first row holds, and the torque that
/// holds it there, %.
pub fn built_in_plant(
    o: &PlantOptions,
    scenario: &Scenario,
) -> Result<(BuiltInPlant, f64), Failure> {
    let first = scenario.rows[0];
    let probe = Plant::new(o, first.valve, 0.0).map_err(plant_failure)?;
    let u0 = start_torque(&probe, &first)?;
    let plant = Plant::new(o, first.valve, u0).map_err(plant_failure)?;
    Ok((BuiltInPlant::new(plant), u0))
}

/// Runs `scenario` with `law` on `plant` (settled at its first row: [`built_in_plant`]),
/// starting the controller in mode 1 at `start_torque_pct` (see the module docs), after the
/// holding-register writes `settings` (the commissioning: limits, rate, transmitters' time
/// constants). `progress` is called after every period.
pub fn run(
    plant: &mut dyn PlantSide,
    scenario: &Scenario,
    law: Law,
    start_torque_pct: f64,
    settings: &[(u16, u16)],
    mut progress: impl FnMut(),
) -> Result<Trace, Failure> {
    let first = scenario.rows[0];
    let build = |e: controller::control::Error| Failure {
        code: 1,
        message: format!("cannot build the controller: {e}"),
    };
    let mut c = board_common::build_controller(&Config {
        virtual_bench: false,
        ..Config::bench()
    })
    .map_err(build)?;
    let scada = ScadaSlave::new(1).ok_or_else(|| Failure {
        code: 1,
        message: "SCADA unit 1 refused".into(),
    })?;
    let mut lock = Lockstep::new(scada);
    lock.write(REG_LAW, &[law.register()])
        .map_err(|e| refused("the law", e))?;
    for &(reg, v) in settings {
        lock.write(reg, &[v]).map_err(|e| Failure {
            code: 2,
            message: format!("--set {reg}={v}: the controller refused it ({e:?})"),
        })?;
    }
    let u0 = (start_torque_pct.clamp(0.0, 100.0) * 100.0).round() as u16;
    lock.write(REG_TORQUE, &[u0])
        .map_err(|e| refused("the start torque", e))?;
    lock.write(REG_MODE, &[1])
        .map_err(|e| refused("mode 1", e))?;
    plant.set_conditions(first.valve, SensorState::OK)?;
    let period = i64::from(FRAME_PERIOD_MS);
    let start_ms = -((PRE_MANUAL_S + PRE_ROW_S) * 1000.0).round() as i64;
    let first_ms = -(PRE_ROW_S * 1000.0).round() as i64;
    let end_ms = (scenario.end_s * 1000.0).round() as i64;
    // Each row from the first frame at or after its time.
    let row_ms: Vec<i64> = scenario
        .rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            if i == 0 {
                first_ms
            } else {
                ((r.t_s * 1000.0 / period as f64) - 1e-9).ceil() as i64 * period
            }
        })
        .collect();
    let mut next = 0usize;
    let mut mode = 1u16;
    let mut row = 0usize;
    let mut trace = Trace {
        law,
        samples: Vec::with_capacity(((end_ms - start_ms) / period) as usize + 1),
        nan_steps: 0,
        out_of_limits: 0,
        max_rate_pct_per_s: 0.0,
        rate_limit_pct_per_s: f64::from(
            lock.scada()
                .commands()
                .control
                .rate_pct_per_s
                .max(controller::control::SWITCH_RATE_MIN_PCT_PER_S),
        ),
        measured_lag_s: [0.0; 2],
        inertia_factor: 1.0,
        drive_lag_s: 0.0,
        static_head_mca: controller::control::STATIC_HEAD_DEFAULT_MCA,
        speed_lag_s: 0.0,
        tripped_s: 0.0,
    };
    let mut last_torque: Option<f32> = None;
    let mut t = start_ms;
    while t < end_ms {
        while next < row_ms.len() && row_ms[next] <= t {
            let r = scenario.rows[next];
            plant.set_conditions(r.valve, r.sensors)?;
            if let Some((reg, v)) = r.setpoint_write() {
                lock.write(reg, &[v])
                    .map_err(|e| refused(&format!("setpoint register {reg} = {v}"), e))?;
            }
            if let Some(h) = r.static_head_mca {
                let v = (h * 1000.0).round() as i16 as u16;
                lock.write(REG_STATIC_HEAD, &[v])
                    .map_err(|e| refused(&format!("static head {} mca", Short(h)), e))?;
            }
            if r.mode != mode {
                lock.write(REG_MODE, &[r.mode])
                    .map_err(|e| refused(&format!("mode {}", r.mode), e))?;
                mode = r.mode;
            }
            row = next;
            next += 1;
        }
        let frame = plant.frame()?;
        let truth = plant.truth();
        let settings = lock.scada().commands().control;
        let (lo, hi) = if matches!(mode, 3 | 4) {
            (settings.torque_min_pct, settings.torque_max_pct)
        } else {
            (0.0, 100.0)
        };
        let mut last: Option<Outputs> = None;
        let (mut nan, mut outside) = (0u64, 0u64);
        let reply = lock.period(&mut c, &frame, |o, p| {
            if ![
                o.torque_ref_pct,
                p.active_setpoint,
                p.feedforward_pct,
                p.integral_pct,
            ]
            .iter()
            .all(|v| v.is_finite())
            {
                nan += 1;
            }
            let u = o.torque_ref_pct;
            let rising = last
                .map_or(last_torque, |l| Some(l.torque_ref_pct))
                .is_some_and(|b| u > b);
            if !(u <= hi && (u >= lo || u == 0.0 || rising)) {
                outside += 1;
            }
            last = Some(*o);
        });
        trace.nan_steps += nan;
        trace.out_of_limits += outside;
        last.ok_or_else(|| Failure {
            code: 1,
            message: "a period without a controller step".into(),
        })?;
        // The rate into every period with the link up and no trip (the drop to 0 % of a cut
        // link or a trip is allowed; the way back up is not a step), counted from the high
        // limit where the last torque was above it (the drop onto it applies at once: it
        // protects the drive; the loop may go on down from it in the same period).
        let status = Status::from_bits(reply.status);
        if let (Some(prev), true) = (last_torque, status.vfd_link_ok && !status.tripped) {
            let from = if matches!(mode, 3 | 4) && prev > settings.torque_max_pct {
                settings.torque_max_pct
            } else {
                prev
            };
            let rate = f64::from((reply.torque_ref_pct - from).abs()) / (period as f64 * 1e-3);
            trace.max_rate_pct_per_s = trace.max_rate_pct_per_s.max(rate);
        }
        if status.tripped {
            trace.tripped_s += period as f64 * 1e-3;
        }
        last_torque = Some(reply.torque_ref_pct);
        trace.measured_lag_s = c.measured_lag_s();
        trace.inertia_factor = c.inertia_factor();
        trace.drive_lag_s = c.drive_lag_s();
        trace.static_head_mca = c.static_head_mca();
        trace.speed_lag_s = c.speed_lag_s();
        plant.apply(&reply)?;
        trace.samples.push(Sample {
            t_s: t as f64 * 1e-3,
            row,
            mode,
            truth,
            published: *c.published(),
            torque_ref_pct: reply.torque_ref_pct,
        });
        progress();
        t += period;
    }
    Ok(trace)
}

/// What changed at a row.
#[derive(Debug, Clone, PartialEq)]
pub enum EventKind {
    /// A setpoint step in mode 3 or 4 (from, to, in the mode's unit).
    Step {
        /// The setpoint before.
        from: f64,
        /// The setpoint after.
        to: f64,
    },
    /// Something else changed (valve, sensors, link) in mode 3 or 4: its description.
    Disturbance(String),
    /// A mode switch, or a row in a mode without a controlled value: no figures.
    Other(String),
}

/// The figures of one row (see the module docs); `None`: not reached within the row.
#[derive(Debug, Clone, PartialEq)]
pub struct EventFigures {
    /// The row's time, s.
    pub t_s: f64,
    /// The row's mode.
    pub mode: u16,
    /// The setpoint after the row, in the mode's unit.
    pub setpoint: f64,
    /// What changed.
    pub kind: EventKind,
    /// The plant's valve and sensors after the row.
    pub sensors: SensorState,
    /// 10-90 % rise time, s (steps).
    pub rise_s: Option<f64>,
    /// Overshoot, % of the step (steps; ≥ 0).
    pub overshoot_pct: Option<f64>,
    /// Peak deviation from the setpoint, % of the setpoint (disturbances).
    pub peak_pct: Option<f64>,
    /// 2 % settling time (steps) or time back within 2 % (disturbances), s.
    pub settle_s: Option<f64>,
    /// ∫|setpoint − value| dt over the row, mca·s or l/s·s.
    pub iae: Option<f64>,
    /// Mean (value − setpoint) / setpoint over the last [`STEADY_WINDOW_S`] of the row, %.
    pub steady_error_pct: Option<f64>,
}

impl EventFigures {
    /// An event's figures, none measured yet.
    pub fn new(t_s: f64, mode: u16, setpoint: f64, kind: EventKind, sensors: SensorState) -> Self {
        Self {
            t_s,
            mode,
            setpoint,
            kind,
            sensors,
            rise_s: None,
            overshoot_pct: None,
            peak_pct: None,
            settle_s: None,
            iae: None,
            steady_error_pct: None,
        }
    }
}

/// First time at or after `t[0]` that `f(y)` reaches `level` (rising), linearly
/// interpolated between samples; `None` if never.
fn first_reach(t: &[f64], y: &[f64], level: f64, f: impl Fn(f64) -> f64) -> Option<f64> {
    let mut prev: Option<(f64, f64)> = None;
    for (&ti, &yi) in t.iter().zip(y) {
        let v = f(yi);
        if v >= level {
            return Some(match prev {
                Some((tp, vp)) if v > vp => tp + (ti - tp) * (level - vp) / (v - vp),
                _ => ti,
            });
        }
        prev = Some((ti, v));
    }
    None
}

/// The time from `t0` to the last exit of `y` from `target ± band` (linearly interpolated),
/// `y` sampled at `t` until `t_end`: 0 if it never leaves, `None` if it is outside at the end.
pub fn band_entry(t: &[f64], y: &[f64], target: f64, band: f64, t0: f64) -> Option<f64> {
    let e: Vec<f64> = y.iter().map(|v| (v - target).abs()).collect();
    let last_out = e.iter().rposition(|&v| !(v <= band));
    match last_out {
        None => Some(0.0),
        Some(i) if i + 1 == e.len() => None,
        Some(i) => {
            let (a, b) = (e[i], e[i + 1]);
            let frac = if a > b { (a - band) / (a - b) } else { 0.0 };
            Some((t[i] + (t[i + 1] - t[i]) * frac - t0).max(0.0))
        }
    }
}

/// ∫|target − y| dt by trapezoids over the samples, the last one held to `t_end`.
pub fn iae(t: &[f64], y: &[f64], target: f64, t_end: f64) -> f64 {
    let e: Vec<f64> = y.iter().map(|v| (target - v).abs()).collect();
    let mut s = 0.0;
    for k in 1..t.len() {
        s += (t[k] - t[k - 1]) * (e[k] + e[k - 1]) / 2.0;
    }
    if let (Some(&tl), Some(&el)) = (t.last(), e.last()) {
        s += (t_end - tl).max(0.0) * el;
    }
    s
}

/// The figures of a setpoint step from `from` to `to` at `t0`, `y` sampled at `t` (from
/// `t0` on) until `t_end`: (10-90 % rise, overshoot %, 2 % settling, IAE).
pub fn step_figures(
    t: &[f64],
    y: &[f64],
    t0: f64,
    from: f64,
    to: f64,
    t_end: f64,
) -> (Option<f64>, Option<f64>, Option<f64>, f64) {
    let span = to - from;
    let frac = |v: f64| (v - from) / span;
    let rise = if span != 0.0 {
        match (first_reach(t, y, 0.1, frac), first_reach(t, y, 0.9, frac)) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        }
    } else {
        None
    };
    let over = (span != 0.0).then(|| {
        y.iter()
            .map(|&v| (frac(v) - 1.0) * 100.0)
            .fold(0.0f64, f64::max)
    });
    let settle = band_entry(t, y, to, BAND * to.abs(), t0);
    (rise, over, settle, iae(t, y, to, t_end))
}

/// The figures of every row of `scenario` in `trace` from t = 0 on, on the plant's truth (or
/// on the controller's measurement where the plant tells no truth).
pub fn figures(trace: &Trace, scenario: &Scenario) -> Vec<EventFigures> {
    let rows = &scenario.rows;
    let mut out = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        let t0 = if i == 0 { 0.0 } else { r.t_s };
        let t_end = rows.get(i + 1).map_or(scenario.end_s, |n| n.t_s);
        let own: Vec<&Sample> = trace
            .samples
            .iter()
            .filter(|s| s.row == i && s.t_s >= 0.0)
            .collect();
        let value = |s: &Sample| -> f64 {
            match (r.mode, s.truth) {
                (4, Some(t)) => t.flow_lps,
                (4, None) => f64::from(s.published.flow_lps),
                (_, Some(t)) => t.pressure_mca,
                (_, None) => f64::from(s.published.pressure_mca),
            }
        };
        let t: Vec<f64> = own.iter().map(|s| s.t_s).collect();
        let y: Vec<f64> = own.iter().map(|s| value(s)).collect();
        let prev = (i > 0).then(|| rows[i - 1]);
        let controlled = matches!(r.mode, 3 | 4);
        let kind = match prev {
            _ if !controlled => EventKind::Other(format!("mode {}", r.mode)),
            None => EventKind::Other("start".into()),
            Some(p) if p.mode != r.mode => {
                EventKind::Other(format!("mode {} → {}", p.mode, r.mode))
            }
            Some(p) if p.setpoint != r.setpoint => EventKind::Step {
                from: p.setpoint,
                to: r.setpoint,
            },
            Some(p) => EventKind::Disturbance(describe_change(&p, r)),
        };
        let mut f = EventFigures::new(t0, r.mode, r.setpoint, kind.clone(), r.sensors);
        if controlled && !t.is_empty() {
            let sp = r.setpoint;
            let tail: Vec<f64> = t
                .iter()
                .zip(&y)
                .filter(|(&ti, _)| ti >= t_end - STEADY_WINDOW_S)
                .map(|(_, &v)| v)
                .collect();
            if !tail.is_empty() && sp != 0.0 {
                let mean = tail.iter().sum::<f64>() / tail.len() as f64;
                f.steady_error_pct = Some((mean - sp) / sp.abs() * 100.0);
            }
            match &kind {
                EventKind::Step { from, to } => {
                    let (rise, over, settle, iae) = step_figures(&t, &y, t0, *from, *to, t_end);
                    (f.rise_s, f.overshoot_pct, f.settle_s, f.iae) =
                        (rise, over, settle, Some(iae));
                }
                EventKind::Disturbance(_) => {
                    if sp != 0.0 {
                        f.peak_pct = Some(
                            y.iter()
                                .map(|v| (v - sp).abs() / sp.abs() * 100.0)
                                .fold(0.0, f64::max),
                        );
                    }
                    f.settle_s = band_entry(&t, &y, sp, BAND * sp.abs(), t0);
                    f.iae = Some(iae(&t, &y, sp, t_end));
                }
                EventKind::Other(_) => {}
            }
        }
        out.push(f);
    }
    out
}

/// What changed from `p` to `r` besides the setpoint and the mode.
fn describe_change(p: &Row, r: &Row) -> String {
    let mut parts = Vec::new();
    if p.valve != r.valve {
        parts.push(format!("valve ×{}", Short(r.valve)));
    }
    let s = |b: bool, what: &str| format!("{what} {}", if b { "restored" } else { "failed" });
    if p.sensors.flow_meter != r.sensors.flow_meter {
        parts.push(s(r.sensors.flow_meter, "flow meter"));
    }
    if p.sensors.pressure_meter != r.sensors.pressure_meter {
        parts.push(s(r.sensors.pressure_meter, "pressure meter"));
    }
    if p.sensors.speed_reading != r.sensors.speed_reading {
        parts.push(
            if r.sensors.speed_reading {
                "drive's speed reading restored"
            } else {
                "drive's speed reading stuck at 0 rpm"
            }
            .into(),
        );
    }
    if p.sensors.link != r.sensors.link {
        parts.push(format!(
            "VFD link {}",
            if r.sensors.link { "restored" } else { "cut" }
        ));
    }
    if let Some(h) = r.static_head_mca {
        parts.push(format!("static head {} mca written", Short(h)));
    }
    if parts.is_empty() {
        "no change".into()
    } else {
        parts.join(", ")
    }
}

/// A target of the issue for one figure: `value ≤ limit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limit {
    /// The figure's name in the tables.
    pub figure: &'static str,
    /// The largest value that passes.
    pub limit: f64,
}

/// The targets for the figures of `f` (issue 18's table): pressure steps rise
/// ≤ 0.5 / 0.8 s (up / down), overshoot ≤ 5 %, settling ≤ 1.0 / 2.5 s, IAE ≤ 1.0 / 1.8 mca·s;
/// back within 2 % ≤ 1.0 s after a valve step while holding a pressure; flow steps rise
/// ≤ 0.7 / 1.0 s, overshoot ≤ 10 %, settling ≤ 1.5 / 3 s; valve steps while holding a flow
/// with its meter: peak ≤ 7 %, back ≤ 1 s; with the flow meter failed, |steady error| ≤ 2 %.
pub fn targets(f: &EventFigures) -> Vec<Limit> {
    let l = |figure, limit| Limit { figure, limit };
    match (&f.kind, f.mode) {
        (EventKind::Step { from, to }, 3) => {
            if to > from {
                vec![
                    l("rise", 0.5),
                    l("overshoot", 5.0),
                    l("settle", 1.0),
                    l("iae", 1.0),
                ]
            } else {
                vec![
                    l("rise", 0.8),
                    l("overshoot", 5.0),
                    l("settle", 2.5),
                    l("iae", 1.8),
                ]
            }
        }
        (EventKind::Step { from, to }, 4) => {
            let mut v = if to > from {
                vec![l("rise", 0.7), l("overshoot", 10.0), l("settle", 1.5)]
            } else {
                vec![l("rise", 1.0), l("overshoot", 10.0), l("settle", 3.0)]
            };
            if !f.sensors.flow_meter {
                v.push(l("steady", 2.0));
            }
            v
        }
        (EventKind::Disturbance(what), 3) if what.starts_with("valve") => vec![l("settle", 1.0)],
        (EventKind::Disturbance(what), 4) => {
            if !f.sensors.flow_meter {
                vec![l("steady", 2.0)]
            } else if what.starts_with("valve") {
                vec![l("peak", 7.0), l("settle", 1.0)]
            } else {
                vec![]
            }
        }
        _ => vec![],
    }
}

/// The value of figure `name` in `f` (|·| for the steady error).
fn figure_value(f: &EventFigures, name: &str) -> Option<f64> {
    match name {
        "rise" => f.rise_s,
        "overshoot" => f.overshoot_pct,
        "peak" => f.peak_pct,
        "settle" => f.settle_s,
        "iae" => f.iae,
        "steady" => f.steady_error_pct.map(f64::abs),
        _ => None,
    }
}

/// A figure in a table: 3 significant decimals, `-` for none.
fn cell(v: Option<f64>) -> String {
    match v {
        Some(v) => format!("{v:.3}"),
        None => "-".into(),
    }
}

/// The unit of the controlled value in `mode`.
fn unit(mode: u16) -> &'static str {
    match mode {
        4 => "l/s",
        1 => "%",
        _ => "mca",
    }
}

/// The tables of the runs (one per law), side by side, with the targets if asked.
pub fn report(
    scenario: &Scenario,
    plant_text: &str,
    runs: &[(Trace, Vec<EventFigures>)],
    with_targets: bool,
    truth: bool,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "pumpbench control: scenario {}, {plant_text}",
        scenario.name
    );
    let _ = writeln!(
        s,
        "figures on the plant's {} from t = 0 (settled start: 3 s in mode 1, then the first \
         row from t = -3 s); steps: 10-90 % rise, overshoot (% of the step), settle = last exit \
         from ±2 % of the new setpoint, IAE = ∫|setpoint − value| dt to the next row; other \
         changes: peak deviation (% of the setpoint), back = last exit from ±2 %; steady = mean \
         error over the last 1 s of the row (%)",
        if truth {
            "TRUE pressure / flow (not the transmitters' readings)"
        } else {
            "MEASURED values (the plant tells no truth)"
        }
    );
    for (trace, _) in runs {
        let _ = writeln!(
            s,
            "{}: torque NaN steps {}, outside its limits {}, largest change into a period with \
             the link up {:.1} %/s; measured plant lag: pressure {:.0} ms{}, flow {:.0} ms{}; \
             rotor inertia measured: {:.2} × the paper's; drive lag measured: {:.0} ms; speed \
             reading lag measured: {:.0} ms; static head: {:.3} mca; tripped \
             (a protection's 0 %) {:.3} s",
            trace.law.name(),
            trace.nan_steps,
            trace.out_of_limits,
            trace.max_rate_pct_per_s,
            trace.measured_lag_s[0] * 1000.0,
            none_shown(trace.law, trace.measured_lag_s[0]),
            trace.measured_lag_s[1] * 1000.0,
            none_shown(trace.law, trace.measured_lag_s[1]),
            trace.inertia_factor,
            trace.drive_lag_s * 1000.0,
            trace.speed_lag_s * 1000.0,
            trace.static_head_mca,
            trace.tripped_s
        );
    }
    let n = runs.first().map_or(0, |r| r.1.len());
    // Each run's figure targets: (met, all).
    let mut tally = vec![(0u32, 0u32); runs.len()];
    // The comparisons of the default with the PI alone (met, all), tallied apart.
    let mut compared = (0usize, 0usize);
    for i in 0..n {
        let f0 = &runs[0].1[i];
        let u = unit(f0.mode);
        let head = match &f0.kind {
            EventKind::Step { from, to } => format!(
                "setpoint {} → {} {u} ({})",
                Short(*from),
                Short(*to),
                if to > from { "up" } else { "down" }
            ),
            EventKind::Disturbance(d) => format!("{d} holding {} {u}", Short(f0.setpoint)),
            EventKind::Other(d) => format!("{d} ({} {u})", Short(f0.setpoint)),
        };
        let _ = writeln!(s, "\nt = {} s, mode {}: {head}", Short(f0.t_s), f0.mode);
        let names: [(&str, &str); 6] = match f0.kind {
            EventKind::Step { .. } => [
                ("rise", "rise 10-90 % (s)"),
                ("overshoot", "overshoot (%)"),
                ("settle", "settle 2 % (s)"),
                ("iae", "IAE"),
                ("steady", "steady error (%)"),
                ("", ""),
            ],
            EventKind::Other(_) => [
                ("steady", "steady error (%)"),
                ("", ""),
                ("", ""),
                ("", ""),
                ("", ""),
                ("", ""),
            ],
            EventKind::Disturbance(_) => [
                ("peak", "peak deviation (%)"),
                ("settle", "back within 2 % (s)"),
                ("iae", "IAE"),
                ("steady", "steady error (%)"),
                ("", ""),
                ("", ""),
            ],
        };
        let limits = targets(f0);
        let _ = write!(s, "  {:<22}", "figure");
        for (trace, _) in runs {
            let _ = write!(s, "{:>10}", trace.law.name());
        }
        if with_targets {
            let _ = write!(s, "   target");
        }
        let _ = writeln!(s);
        for (key, label) in names.iter().filter(|(k, _)| !k.is_empty()) {
            let label = if *key == "iae" {
                format!("IAE ({u}·s)")
            } else {
                label.to_string()
            };
            let _ = write!(s, "  {label:<22}");
            for (_, figs) in runs {
                let v = if *key == "steady" {
                    figs[i].steady_error_pct
                } else {
                    figure_value(&figs[i], key)
                };
                let _ = write!(s, "{:>10}", cell(v));
            }
            if with_targets {
                if let Some(l) = limits.iter().find(|l| l.figure == *key) {
                    let verdicts: Vec<&str> = runs
                        .iter()
                        .zip(tally.iter_mut())
                        .map(|((_, figs), (pass, all))| {
                            *all += 1;
                            match figure_value(&figs[i], key) {
                                Some(v) if v <= l.limit => {
                                    *pass += 1;
                                    "PASS"
                                }
                                _ => "MISS",
                            }
                        })
                        .collect();
                    let _ = write!(s, "   ≤ {} {}", Short(l.limit), verdicts.join(" / "));
                }
            }
            let _ = writeln!(s);
        }
        if let (EventKind::Step { from, to }, [(_, a), (_, b)]) = (&f0.kind, runs) {
            if to > from {
                let (sa, sb) = (a[i].settle_s, b[i].settle_s);
                let faster = match (sa, sb) {
                    (Some(x), Some(y)) if x < y => "model settles faster",
                    (Some(x), Some(y)) if y < x => "pi settles faster",
                    (Some(_), Some(_)) => "both settle together",
                    (Some(_), None) => "model settles faster (pi does not settle)",
                    (None, Some(_)) => "pi settles faster (model does not settle)",
                    (None, None) => "neither settles",
                };
                let _ = write!(s, "  {faster}");
                if with_targets {
                    let pass = matches!((sa, sb), (Some(x), Some(y)) if x < y)
                        || matches!((sa, sb), (Some(_), None));
                    compared.1 += 1;
                    compared.0 += usize::from(pass);
                    let _ = write!(
                        s,
                        "   target: default faster on every upward step {}",
                        if pass { "PASS" } else { "MISS" }
                    );
                }
                let _ = writeln!(s);
            }
        }
        if let ([(_, a), (_, b)], true) = (runs, with_targets) {
            if let (Some(x), Some(y)) = (a[i].iae, b[i].iae) {
                compared.1 += 1;
                compared.0 += usize::from(x <= y);
                // The difference beside the ratio: a ratio printed 1.000 can still miss (a
                // link cut's 0 % rows differ only by the noise before the cut).
                let _ = writeln!(
                    s,
                    "  IAE model / pi = {:.3} (model − pi {:+.1e})   target: no worse than pi {}",
                    if y > 0.0 { x / y } else { f64::NAN },
                    x - y,
                    if x <= y { "PASS" } else { "MISS" }
                );
            }
        }
    }
    if with_targets {
        let _ = writeln!(s);
        for ((trace, _), (pass, all)) in runs.iter().zip(&tally) {
            let _ = writeln!(
                s,
                "{}: {pass} of the {all} figure targets above met",
                trace.law.name()
            );
        }
        if compared.1 > 0 {
            let _ = writeln!(
                s,
                "model against pi: {} of the {} comparisons above met (default faster on every \
                 upward step, IAE no worse)",
                compared.0, compared.1
            );
        }
        for (trace, _) in runs {
            let ok = trace.nan_steps == 0 && trace.out_of_limits == 0;
            // A period's change at the rate limit, with f32 rounding.
            let smooth = trace.max_rate_pct_per_s <= trace.rate_limit_pct_per_s * (1.0 + 1e-4);
            let _ = writeln!(
                s,
                "{}: target: never a NaN, never a torque outside its limits {}; never a \
                 torque step (every change into a period with the link up within the rate limit, {} \
                 %/s) {}",
                trace.law.name(),
                if ok { "PASS" } else { "MISS" },
                Short(trace.rate_limit_pct_per_s),
                if smooth { "PASS" } else { "MISS" }
            );
        }
    }
    s
}

/// The CSV's header.
pub const COLUMNS: &str = "law,t_s,mode,setpoint,valve,flow_meter,pressure_meter,link,\
speed_reading,pressure_true,flow_true,speed_true,k2_true,pressure_measured,flow_measured,active_setpoint,\
control_error,torque_ref_pct,feedforward_pct,integral_pct,status,observer_k2";

/// Writes the runs' samples, one row per period: the law (0 model, 1 pi), the time, the
/// scenario's mode, setpoint (its unit), valve factor and sensors, the plant's truth (empty
/// when it tells none), what the controller published (measured pressure and flow, the
/// active setpoint, the error, feedforward and integral parts, status word, observer k2) and
/// the torque reference the plant applies over the period.
pub fn write_csv(
    scenario: &Scenario,
    runs: &[(Trace, Vec<EventFigures>)],
    w: &mut dyn Write,
) -> Result<(), Failure> {
    let fail = |e: std::io::Error| Failure {
        code: 1,
        message: format!("cannot write the output: {e}"),
    };
    writeln!(w, "{COLUMNS}").map_err(fail)?;
    for (trace, _) in runs {
        for s in &trace.samples {
            let r = &scenario.rows[s.row];
            let p = &s.published;
            let truth = match s.truth {
                Some(t) => format!(
                    "{:.5},{:.4},{:.2},{:.5}",
                    t.pressure_mca, t.flow_lps, t.speed_rpm, t.valve_k2
                ),
                None => ",,,".into(),
            };
            writeln!(
                w,
                "{},{:.3},{},{},{},{},{},{},{},{truth},{:.5},{:.4},{:.5},{:.5},{:.3},{:.3},{:.3},{},{:.5}",
                trace.law.register(),
                s.t_s,
                s.mode,
                Short(r.setpoint),
                Short(r.valve),
                u8::from(r.sensors.flow_meter),
                u8::from(r.sensors.pressure_meter),
                u8::from(r.sensors.link),
                u8::from(r.sensors.speed_reading),
                p.pressure_mca,
                p.flow_lps,
                p.active_setpoint,
                p.control_error,
                s.torque_ref_pct,
                p.feedforward_pct,
                p.integral_pct,
                p.status,
                p.observer_valve_k2,
            )
            .map_err(fail)?;
        }
    }
    Ok(())
}

/// `--hold-s`, s: finite, over 0, at most [`MAX_SCENARIO_S`]; a refusal echoes the value as
/// typed (parsed, `100000` printed as "1e5").
fn parse_hold_s(text: &str) -> Result<f64, String> {
    let v = crate::plant::finite("--hold-s", text)?;
    if v > 0.0 && v <= MAX_SCENARIO_S {
        Ok(v)
    } else {
        Err(format!(
            "--hold-s {}: must be within 0..{MAX_SCENARIO_S} s (exclusive of 0)",
            crate::input::shown(text.trim())
        ))
    }
}

/// The scenario of `--scenario`: a built-in name, else a file.
fn scenario_of(text: &str, hold_s: f64) -> Result<(Scenario, Option<PathBuf>), Failure> {
    if let Some(s) = built_in(text) {
        return Ok((s, None));
    }
    let path = PathBuf::from(text);
    if !path.exists() {
        return Err(Failure::usage(format!(
            "--scenario {}: neither a built-in scenario ({}) nor a file",
            crate::input::shown(text),
            BUILT_IN.join(", ")
        )));
    }
    Ok((read_scenario(&path, hold_s)?, Some(path)))
}

/// `pumpbench control`.
pub fn command(a: ControlArgs) -> Result<(), Failure> {
    let Some(name) = a.scenario.as_deref().filter(|_| !a.plant_stdio) else {
        // The external plant: the boards' controller and session, one code path with the
        // QEMU board's plant mode (board_common::serve_plant).
        let law = match a.controller {
            None | Some(ControllerChoice::Model) => Law::Model,
            Some(ControllerChoice::Pi) => Law::Pi,
            Some(ControllerChoice::Both) => {
                return Err(Failure::usage(
                    "--plant-stdio --controller both: an external plant is one session, one \
                     law; run it once with --controller model and once with --controller pi \
                     (or write holding register 14 in a W line)"
                        .into(),
                ))
            }
        };
        let mut writes = vec![(REG_LAW, law.register())];
        for w in &a.set {
            writes.push(parse_setting(w)?);
        }
        // Each write tried on a session of its own first: a refused `--set` is a usage error,
        // as with the built-in plant, before anything is served.
        let (_, mut tried) = board_common::plant_session().map_err(|e| Failure {
            code: 1,
            message: format!("plant session: {e}"),
        })?;
        for &(reg, v) in &writes {
            tried.lockstep_mut().write(reg, &[v]).map_err(|e| {
                Failure::usage(format!(
                    "--set {reg}={v}: the controller refused it ({e:?})"
                ))
            })?;
        }
        let mut steps = 0u64;
        let served = board_common::serve_plant(
            std::io::stdin().lock(),
            &mut std::io::stdout().lock(),
            &writes,
            |_, _| steps += 1,
        );
        eprintln!(
            "pumpbench control --plant-stdio: {steps} controller steps ({:.3} s of plant time)",
            steps as f64 * 1e-3
        );
        return served.map_err(|message| Failure { code: 1, message });
    };
    let hold_s = parse_hold_s(&a.hold_s).map_err(Failure::usage)?;
    let (scenario, path) = scenario_of(name, hold_s)?;
    let settings = a
        .set
        .iter()
        .map(|w| parse_setting(w))
        .collect::<Result<Vec<_>, _>>()?;
    let flow_lag = match (&a.flow_lag_ms, scenario.flow_lag_ms) {
        (Some(t), _) => t.clone(),
        (None, Some(ms)) => Short(ms).to_string(),
        (None, None) => "40".into(),
    };
    let o = plant_options(&a.plant, a.seed, &flow_lag)?;
    crate::plant::true_bench(o.curve_error, o.rotor_inertia).map_err(Failure::usage)?;
    let inputs: Vec<Named> = path
        .as_deref()
        .map(|p| ("--scenario", p))
        .into_iter()
        .collect();
    let mut outputs: Vec<Named> = Vec::new();
    if let Some(out) = &a.output {
        outputs.push(("--output", out));
    }
    if let Some(png) = &a.plot {
        if png.extension().is_none_or(|e| e != "png") {
            return Err(Failure::usage(format!(
                "--plot {}: must end in .png",
                png.display()
            )));
        }
        outputs.push(("--plot", png));
    }
    output::check_outputs(&inputs, &outputs)?;
    let laws: &[Law] = match a.controller.unwrap_or(ControllerChoice::Both) {
        ControllerChoice::Model => &[Law::Model],
        ControllerChoice::Pi => &[Law::Pi],
        ControllerChoice::Both => &[Law::Model, Law::Pi],
    };
    let periods =
        ((scenario.end_s + PRE_MANUAL_S + PRE_ROW_S) * 1000.0 / f64::from(FRAME_PERIOD_MS)) as u64;
    let bar = if periods * laws.len() as u64 > 4000 {
        indicatif::ProgressBar::new(periods * laws.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("control {bar:40} {pos}/{len} periods, eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut runs = Vec::new();
    for &law in laws {
        let (mut plant, u0) = built_in_plant(&o, &scenario)?;
        let trace = run(&mut plant, &scenario, law, u0, &settings, || bar.inc(1))?;
        let figs = figures(&trace, &scenario);
        runs.push((trace, figs));
    }
    bar.finish_and_clear();
    let plant_text = format!(
        "plant: curve error {},{} %, curve shape {},{} %, rotor inertia {} × the paper's, water inertia {} mca·s²/l, \
         drive lag {} ms, pressure lag {} ms, flow lag {} ms, speed reading lag {} ms{}, seed {}",
        // Every number as a person writes it (`plain`).
        plain(o.curve_error.head_pct),
        plain(o.curve_error.torque_pct),
        plain(o.curve_error.head_shape_pct),
        plain(o.curve_error.torque_shape_pct),
        plain(o.rotor_inertia),
        plain(o.dynamics.water_inertia),
        plain(o.dynamics.drive_lag_s * 1000.0),
        plain(o.pressure_lag_s * 1000.0),
        plain(o.flow_lag_s * 1000.0),
        plain(o.speed_lag_s * 1000.0),
        rarer_plant_text(&o),
        o.seed
    );
    if let Some(out) = &a.output {
        output::write_csv(Some(out), |w| write_csv(&scenario, &runs, w))?;
    }
    if let Some(png) = &a.plot {
        plot::draw(png, &scenario, &runs)?;
    }
    let truth = runs
        .iter()
        .all(|(t, _)| t.samples.iter().all(|s| s.truth.is_some()));
    print!(
        "{}",
        report(&scenario, &plant_text, &runs, a.targets, truth)
    );
    Ok(())
}

/// A number of the plant line as a person writes it: rounded to 1e-6 (a lag typed in ms is
/// kept in s: 1001 ms came back as 1000.9999999999999), +0 for -0 (a curve error of 0 is
/// written 0), and plain (`{}`, not `Short`'s exponent form: "1000 ms", not "1e3 ms";
/// "0.001 mca·s²/l", not "1e-3"; the options' ranges keep it short).
fn plain(x: f64) -> f64 {
    (x * 1e6).round() / 1e6 + 0.0
}

/// After a lag the probe reports as 0: what that 0 says. The model law's probe keeps 0 until
/// a setpoint step shows a lag (behind a transmitter slower than it can follow it never
/// does: docs/control.md, Limits), and the PI alone runs no probe: "0 ms" alone would read
/// as a plant without lag.
fn none_shown(law: Law, lag_s: f32) -> &'static str {
    match law {
        Law::Pi => " (the PI alone measures none)",
        Law::Model if lag_s == 0.0 => " (none shown by a setpoint step)",
        Law::Model => "",
    }
}

/// The plant options printed only when set (the plant line of the plants without them as it
/// was): the drive's ramp and the transmitters' transport delay.
fn rarer_plant_text(o: &PlantOptions) -> String {
    let mut t = String::new();
    if o.dynamics.drive_slew_pct_s > 0.0 {
        t += &format!(", drive ramp {} %/s", plain(o.dynamics.drive_slew_pct_s));
    }
    if o.pressure_noise_mca != crate::plant::PRESSURE.noise {
        t += &format!(", pressure noise {} mca", plain(o.pressure_noise_mca));
    }
    if o.transmitter_delay_s > 0.0 {
        t += &format!(
            ", transmitter delay {} ms",
            plain(o.transmitter_delay_s * 1000.0)
        );
    }
    t
}

#[cfg(test)]
mod tests;
