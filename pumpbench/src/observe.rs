//! `pumpbench observe`: model-core's observer (the EKF of `model_core::observer`) and monitor
//! (`model_core::monitor`) run over a logged record, as the controller would run them, one
//! output row per input row.
//!
//! # Semantics
//!
//! The observer starts with `Observer::new(ObserverConfig::paper(), u₀)`, at the model's
//! steady state for the first row's torque, and keeps that configuration (the controller
//! also widens the pressure lag's uncertainty to the lag its pressure loop measures, which a
//! record does not carry: `controller::control::observer_pressure_lag_sd_s`). Row 0 is one step of a sample period with torque
//! u₀ and row 0's measurements; row k ≥ 1 is `step(t_k − t_{k−1}, u_{k−1}, m_k)`: the torque
//! of the previous row is what acted over the interval (as in `simulate`), the measurements
//! are those logged at the end of it. After each step the monitor is updated with that step's
//! estimate (see [`monitor_inputs`]). The row written is the filtered estimate after the row's
//! measurements.
//!
//! # Cells
//!
//! `t_s` and `torque_ref_pct` are in every row, finite. In `pressure_mca` (a required column),
//! `flow_lps` and `speed_rpm` (optional columns) an empty cell is a missing measurement; `NaN`,
//! `inf` or a number beyond f64 (`1e999`) is passed to the observer as it is, which refuses it
//! as implausible (and the monitor raises that transmitter's fault bit).

use crate::error::Failure;
use crate::input::{read_gappy_series, InputError};
use crate::num::{Float, Short};
use crate::output::{check_outputs, write_csv, Named};
use crate::plots::{self, ObservePanel};
use indicatif::{ProgressBar, ProgressStyle};
use model_core::monitor::{Monitor, MonitorConfig, MonitorInputs};
use model_core::observer::{Estimate, Measurements, Observer, ObserverConfig, Use, MAX_DT_S};
use model_core::Real;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Arithmetic of the observer and the monitor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Precision {
    /// Double precision (the host's reference arithmetic).
    F64,
    /// Single precision, as on the MCU.
    F32,
}

/// The output's header.
pub const COLUMNS: &str = "t_s,speed_rpm,flow_lps,pressure_mca,valve_k2,head_scale,\
speed_sd_rpm,flow_sd_lps,pressure_sd_mca,valve_k2_sd,head_scale_sd,\
torque_scale,torque_scale_sd,pump_head_mca,pipe_loss_mca,hydraulic_power_w,\
pressure_innovation_mca,pressure_nis,flow_innovation_lps,flow_nis,speed_innovation_rpm,speed_nis,\
alarm_bits";

/// Optional columns of the record: the measurements, then the truth (plotted only).
const OPTIONAL: [&str; 6] = [
    "flow_lps",
    "speed_rpm",
    "k2_true",
    "flow_true",
    "speed_true",
    "pressure_true",
];

/// Records longer than this (rows) show a progress bar on stderr (when it is a terminal).
pub const PROGRESS_ROWS: usize = 100_000;

/// Most points of one plotted series: longer records are drawn from every n-th row.
const PLOT_POINTS: usize = 20_000;

/// A record as `observe` reads it.
#[derive(Debug, Clone)]
pub struct Record {
    /// The file, for messages.
    pub path: PathBuf,
    /// Times, s.
    pub t_s: Vec<f64>,
    /// Torque references, %.
    pub torque_ref_pct: Vec<f64>,
    /// Pressure cells, mca (`None`: empty).
    pub pressure: Vec<Option<f64>>,
    /// Flow cells, l/s, if the column is there.
    pub flow: Option<Vec<Option<f64>>>,
    /// VFD speed cells, rpm, if the column is there.
    pub speed: Option<Vec<Option<f64>>>,
    /// The truth, for the plot: k2, flow, speed, pressure (each if its column is there).
    pub truth: [Option<Vec<Option<f64>>>; 4],
    /// Sample period (mean step), s: the length of row 0's step.
    pub period_s: f64,
}

/// Reads `path` and checks that the observer can take every step in `precision`.
pub fn read(path: &Path, precision: Precision) -> Result<Record, Failure> {
    let rec = read_gappy_series(path, &["pressure_mca"], &OPTIONAL)?;
    let at = |row: usize, message: String| InputError {
        path: path.to_path_buf(),
        line: Some(rec.lines[row]),
        column: Some((rec.t_column, "t_s".into())),
        message,
    };
    let t = &rec.input.t_s;
    if t.len() < 2 {
        return Err(at(
            0,
            "one data row: observe needs two at least (the sample period)".into(),
        )
        .into());
    }
    // The steps the observer takes, in its arithmetic: in (0, MAX_DT_S].
    let fits = |dt: f64| match precision {
        Precision::F64 => dt > 0.0 && dt <= MAX_DT_S,
        Precision::F32 => (dt as f32) > 0.0 && f64::from(dt as f32) <= MAX_DT_S,
    };
    for k in 1..t.len() {
        let dt = t[k] - t[k - 1];
        if !fits(dt) {
            return Err(at(
                k,
                format!(
                    "step {} s from the previous row: the observer's steps are in (0, {}] s{}",
                    Short(dt),
                    Short(MAX_DT_S),
                    if precision == Precision::F32 {
                        " in f32"
                    } else {
                        ""
                    }
                ),
            )
            .into());
        }
    }
    let mut columns = rec.columns.into_iter();
    let mut next = || columns.next().flatten();
    let pressure = next().unwrap_or_default();
    let (flow, speed) = (next(), next());
    let truth = [next(), next(), next(), next()];
    Ok(Record {
        path: path.to_path_buf(),
        t_s: rec.input.t_s,
        torque_ref_pct: rec.input.torque_ref_pct,
        pressure,
        flow,
        speed,
        truth,
        period_s: rec.sample_period_s,
    })
}

/// What the monitor is given after a step with torque `torque_ref_pct` over `dt_s` and the
/// measurements `m`: no VFD torque and no link alarm (the record has neither); the VFD speed
/// if the row has one; the measured flow if the row has one that is finite and the observer
/// did not refuse as implausible (a transmitter in fault gives no flow); a transmitter in
/// fault where the row has a measurement that the observer refused as implausible.
pub fn monitor_inputs<T: Real>(
    dt_s: T,
    torque_ref_pct: T,
    m: &Measurements<T>,
    estimate: Estimate<T>,
) -> MonitorInputs<T> {
    let refused = |cell: Option<T>, used: Use| cell.is_some() && used == Use::Implausible;
    MonitorInputs {
        dt_s,
        estimate,
        torque_ref_pct,
        vfd_torque_pct: None,
        vfd_speed_rpm: m.speed_rpm,
        measured_flow_lps: m
            .flow_lps
            .filter(|q| q.is_finite() && estimate.flow.used != Use::Implausible),
        pressure_fault: refused(m.pressure_mca, estimate.pressure.used),
        flow_fault: refused(m.flow_lps, estimate.flow.used),
        vfd_link_alarm: false,
    }
}

/// The plotted series, every `stride`-th row (the measurements: the first plausible one among
/// those rows), and the alarm intervals, exact.
#[derive(Debug, Default)]
struct PlotData {
    stride: usize,
    t: Vec<f64>,
    /// Estimates: speed, flow, pressure, k2.
    estimate: [Vec<f64>; 4],
    /// Measurements the observer did not refuse as implausible: speed, flow, pressure.
    measured: [Vec<Option<f64>>; 3],
    /// Times where any alarm bit is set: (from, to), s.
    alarms: Vec<(f64, f64)>,
}

impl PlotData {
    fn new(rows: usize) -> Self {
        let stride = rows.div_ceil(PLOT_POINTS).max(1);
        let n = rows.div_ceil(stride);
        PlotData {
            stride,
            t: Vec::with_capacity(n),
            estimate: std::array::from_fn(|_| Vec::with_capacity(n)),
            measured: std::array::from_fn(|_| Vec::with_capacity(n)),
            alarms: Vec::new(),
        }
    }

    fn push<T: Real>(
        &mut self,
        k: usize,
        t: &[f64],
        e: &Estimate<T>,
        m: &Measurements<T>,
        bits: u16,
    ) {
        let f = |x: T| Real::to_f64(x);
        if k.is_multiple_of(self.stride) {
            self.t.push(t[k]);
            for (v, x) in
                self.estimate
                    .iter_mut()
                    .zip([e.speed_rpm, e.flow_lps, e.pressure_mca, e.valve_k2])
            {
                v.push(f(x));
            }
            for v in &mut self.measured {
                v.push(None);
            }
        }
        let plausible = |cell: Option<T>, used: Use| cell.filter(|_| used != Use::Implausible);
        for (v, cell) in self.measured.iter_mut().zip([
            plausible(m.speed_rpm, e.speed.used),
            plausible(m.flow_lps, e.flow.used),
            plausible(m.pressure_mca, e.pressure.used),
        ]) {
            if let (Some(last @ None), Some(x)) = (v.last_mut(), cell) {
                *last = Some(f(x));
            }
        }
        let end = t[(k + 1).min(t.len() - 1)];
        match self.alarms.last_mut() {
            Some(a) if bits != 0 && a.1 == t[k] => a.1 = end,
            _ if bits != 0 => self.alarms.push((t[k], end)),
            _ => {}
        }
    }
}

fn write_fail(e: std::io::Error) -> Failure {
    Failure {
        code: 1,
        message: format!("cannot write the output: {e}"),
    }
}

/// Runs the observer and the monitor over `rec` in `T` arithmetic, writing the CSV to `w`.
fn run<T: Real + Float>(
    rec: &Record,
    w: &mut dyn Write,
    mut plot: Option<&mut PlotData>,
) -> Result<(), Failure> {
    let f = T::from_f64;
    let observer_fail = |k: usize, e: model_core::observer::ObserverError| Failure {
        code: 1,
        message: format!("{}: row {}: observer: {e}", rec.path.display(), k + 1),
    };
    let n = rec.t_s.len();
    let mut observer = Observer::<T>::new(ObserverConfig::paper(), f(rec.torque_ref_pct[0]))
        .map_err(|e| observer_fail(0, e))?;
    let mut monitor = Monitor::<T>::new(MonitorConfig::paper());
    let bar = if n > PROGRESS_ROWS {
        ProgressBar::new(n as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("observe {bar:40} {pos}/{len} rows, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    writeln!(w, "{COLUMNS}").map_err(write_fail)?;
    let cell = |col: &Option<Vec<Option<f64>>>, k: usize| col.as_ref().and_then(|c| c[k]).map(f);
    for k in 0..n {
        let (dt, u) = if k == 0 {
            (rec.period_s, rec.torque_ref_pct[0])
        } else {
            (rec.t_s[k] - rec.t_s[k - 1], rec.torque_ref_pct[k - 1])
        };
        let m = Measurements {
            pressure_mca: rec.pressure[k].map(f),
            flow_lps: cell(&rec.flow, k),
            speed_rpm: cell(&rec.speed, k),
        };
        let e = observer
            .step(f(dt), f(u), &m)
            .map_err(|e| observer_fail(k, e))?;
        // Overspeed as the controller checks it: the row's speed cell (the drive's), else
        // the estimate's; once per row here.
        let speed = m.speed_rpm.filter(|w| w.is_finite()).unwrap_or(e.speed_rpm);
        monitor.check_speed(f(dt), speed);
        let bits = monitor.update(&monitor_inputs(f(dt), f(u), &m, e));
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            Short(rec.t_s[k]),
            Short(e.speed_rpm),
            Short(e.flow_lps),
            Short(e.pressure_mca),
            Short(e.valve_k2),
            Short(e.head_scale),
            Short(e.speed_sd_rpm),
            Short(e.flow_sd_lps),
            Short(e.pressure_sd_mca),
            Short(e.valve_k2_sd),
            Short(e.head_scale_sd),
            Short(e.torque_scale),
            Short(e.torque_scale_sd),
            Short(e.pump_head_mca),
            Short(e.pipe_loss_mca),
            Short(e.hydraulic_power_w),
            Short(e.pressure.value),
            Short(e.pressure.nis),
            Short(e.flow.value),
            Short(e.flow.nis),
            Short(e.speed.value),
            Short(e.speed.nis),
            bits
        )
        .map_err(write_fail)?;
        if let Some(p) = plot.as_deref_mut() {
            p.push(k, &rec.t_s, &e, &m, bits);
        }
        if k.is_multiple_of(4096) {
            bar.set_position(k as u64);
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// The figure's path for the CSV `out`: the same stem, `.png`; `None` for an output that is
/// not a file (a device such as /dev/null, a FIFO).
pub fn figure_path(out: &Path) -> Option<PathBuf> {
    match std::fs::metadata(out) {
        Ok(meta) if !meta.is_file() => None,
        _ => Some(out.with_extension("png")),
    }
}

/// `pumpbench observe`: checks the outputs, reads `data`, writes the CSV (to `output` or
/// stdout) and, with `output`, the figure beside it.
pub fn command(data: &Path, precision: Precision, output: Option<&Path>) -> Result<(), Failure> {
    let figure = output.and_then(figure_path);
    if let (Some(out), Some(png)) = (output, &figure) {
        if png == out {
            return Err(Failure {
                code: 2,
                message: format!(
                    "--output {}: the figure would be written over the CSV: give the CSV \
                     another extension (e.g. .csv)",
                    out.display()
                ),
            });
        }
    }
    let mut outputs: Vec<Named> = output.map(|o| ("--output", o)).into_iter().collect();
    if let Some(png) = &figure {
        outputs.push(("the figure", png.as_path()));
    }
    check_outputs(&[("--data", data)], &outputs)?;
    let rec = read(data, precision)?;
    let mut plot = figure.as_ref().map(|_| PlotData::new(rec.t_s.len()));
    write_csv(output, |w| match precision {
        Precision::F64 => run::<f64>(&rec, w, plot.as_mut()),
        Precision::F32 => run::<f32>(&rec, w, plot.as_mut()),
    })?;
    if let (Some(png), Some(p)) = (figure, plot) {
        draw(&png, &rec, &p, precision)?;
    }
    Ok(())
}

/// Draws the figure into a temporary file beside `png` and renames it into place.
fn draw(png: &Path, rec: &Record, p: &PlotData, precision: Precision) -> Result<(), Failure> {
    // Truth rows follow the plotted rows.
    let truth = |i: usize| -> Option<Vec<Option<f64>>> {
        rec.truth[i]
            .as_ref()
            .map(|v| v.iter().step_by(p.stride).copied().collect())
    };
    let [k2_true, flow_true, speed_true, pressure_true] = [0, 1, 2, 3].map(truth);
    let panels = [
        ObservePanel {
            title: "Speed",
            y_desc: "speed (rpm)",
            estimate: &p.estimate[0],
            measured: rec.speed.as_ref().map(|_| p.measured[0].as_slice()),
            truth: speed_true.as_deref(),
        },
        ObservePanel {
            title: "Flow",
            y_desc: "flow (l/s)",
            estimate: &p.estimate[1],
            measured: rec.flow.as_ref().map(|_| p.measured[1].as_slice()),
            truth: flow_true.as_deref(),
        },
        ObservePanel {
            title: "Outlet pressure (estimate: no transmitter lag)",
            y_desc: "pressure (mca)",
            estimate: &p.estimate[2],
            measured: Some(p.measured[2].as_slice()),
            truth: pressure_true.as_deref(),
        },
        ObservePanel {
            title: "Valve coefficient k2",
            y_desc: "k2 (mca^0.5 s/l)",
            estimate: &p.estimate[3],
            measured: None,
            truth: k2_true.as_deref(),
        },
    ];
    let title = format!(
        "pumpbench observe {} ({}), shaded: any alarm bit set",
        rec.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        match precision {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    );
    plots::write_png(png, |tmp| {
        plots::observe_figure(tmp, &title, &p.t, &panels, &p.alarms)
    })
}
