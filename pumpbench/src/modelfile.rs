//! The NARMAX model file (JSON): weights in NNSYSID layout, scaling, lags, sample period,
//! target, and training metadata. Checked when read: a bad file is refused before any run.

use crate::error::Failure;
use crate::num::Short;
use model_core::narmax::mcu::{NarxQ15, NnsysidModel};
use model_core::narmax::{Lags, Narmax, NarmaxError, Scaling};
use model_core::Real;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag written in every model file.
pub const FORMAT: &str = "pumpbench-narmax-1";

/// Largest model file read, bytes (16 MiB; the shipped models are under 5 KB, and even a
/// model with the most weights the host allows and a long training history is far smaller).
/// A larger file, or a device or pipe that gives more, is refused once this much has been
/// read.
pub const MAX_MODEL_BYTES: u64 = 16 << 20;

/// Largest magnitude of a value in a model file (weights, scaling, ranges): f32::MAX / 1e6,
/// so that the firmware's f32 arithmetic has room above every value.
pub const MAX_ABS_VALUE: f64 = f32::MAX as f64 / 1e6;

/// Whether `x` is finite and within ±[`MAX_ABS_VALUE`].
pub fn in_firmware_range(x: f64) -> bool {
    x.abs() <= MAX_ABS_VALUE
}

/// Capacity of the host's NARMAX models: regressors.
pub const HOST_MAX_INPUTS: usize = 64;
/// Capacity of the host's NARMAX models: hidden units.
pub const HOST_MAX_HIDDEN: usize = 32;
/// A NARMAX model as the host runs it (model-core, generous capacity).
pub type HostNarmax<T> = Narmax<T, HOST_MAX_INPUTS, HOST_MAX_HIDDEN>;
/// Capacity of the host's MCU passes: frames of history (model-core's limit).
pub const HOST_MAX_FRAMES: usize = model_core::narmax::mcu::MAX_FRAMES;
/// The firmware's Q15 pass of a host model (NARX models only), padded to the host's capacity:
/// the same arithmetic and bits as the firmware's exact-size pass (zero weights add nothing).
pub type HostNarxQ15 = NarxQ15<HOST_MAX_FRAMES, HOST_MAX_HIDDEN>;

/// What the model predicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Target {
    /// Outlet pressure, mca (column `pressure_mca`).
    Pressure,
    /// Flow, l/s (column `flow_lps`).
    Flow,
}

impl Target {
    /// The CSV column of this target.
    pub fn column(self) -> &'static str {
        match self {
            Target::Pressure => "pressure_mca",
            Target::Flow => "flow_lps",
        }
    }
}

/// Mean and standard deviation (N − 1), physical units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScalingFile {
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
}

/// Lags as stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LagsFile {
    /// Output lags.
    pub na: usize,
    /// Input lags.
    pub nb: usize,
    /// Error lags.
    pub nc: usize,
    /// Input delay.
    pub nk: usize,
}

/// How the model was trained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Training {
    /// Training data file, as given.
    pub data: String,
    /// Samples in it.
    pub samples: usize,
    /// Accepted LM epochs asked for.
    pub epochs: usize,
    /// Accepted LM epochs done.
    pub epochs_done: usize,
    /// Seed of the initial weights.
    pub seed: u64,
    /// Seeded starts trained; the lowest final training criterion was kept.
    pub starts: usize,
    /// Criterion SSE/(2N), scaled units, before training and after each epoch.
    pub criterion: Vec<f64>,
    /// Final λ.
    pub lambda: f64,
    /// Why training stopped.
    pub stop: String,
    /// Wall time, s.
    pub seconds: f64,
    /// pumpbench version.
    pub tool: String,
}

/// The transmitter's lag as `identify` found it from the record's speed
/// ([`crate::sensorlag`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TransmitterFile {
    /// The transmitter's lag, s (0..=2): the one `simulate` uses.
    pub lag_s: f64,
    /// The lag of the reading behind the speed over the whole record, s (0..=2).
    pub found_lag_s: f64,
    /// The lag found at the lower half of the record's speeds alone, s.
    pub low_speed_lag_s: f64,
    /// The lag found at the upper half of the record's speeds alone, s.
    pub high_speed_lag_s: f64,
    /// The lagged static fit's mismatch, % of the reading's standard deviation.
    pub mismatch_pct: f64,
    /// The share of the reading's variance the lagged static fit explains, % (≤ 100).
    /// Absent in files written before it existed.
    #[serde(default)]
    pub explained_pct: f64,
    /// Whether `simulate` takes the prediction back through the lag by default.
    pub trusted: bool,
}

/// A model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// [`FORMAT`].
    pub format: String,
    /// Predicted output.
    pub target: Target,
    /// Sample period, s.
    pub sample_period_s: f64,
    /// Lags.
    pub lags: LagsFile,
    /// Hidden tanh units.
    pub hidden: usize,
    /// Hidden layer, hidden rows of (na + nb + nc + 1), bias last (NNSYSID W1).
    pub w1: Vec<Vec<f64>>,
    /// Output layer, hidden + 1, bias last (NNSYSID W2).
    pub w2: Vec<f64>,
    /// Input scaling.
    pub u_scaling: ScalingFile,
    /// Output scaling.
    pub y_scaling: ScalingFile,
    /// Training range of the torque reference, %.
    pub u_range: [f64; 2],
    /// Training range of the output.
    pub y_range: [f64; 2],
    /// Training metadata.
    pub training: Training,
    /// The transmitter's lag behind the speed, when the training record had `speed_rpm`
    /// (absent in files written before it existed, and in the shipped models).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transmitter: Option<TransmitterFile>,
}

fn bad(path: &Path, message: String) -> Failure {
    Failure {
        code: 2,
        message: format!("{}: {message}", path.display()),
    }
}

impl ModelFile {
    /// Lags for model-core.
    pub fn lags(&self) -> Lags {
        Lags {
            na: self.lags.na,
            nb: self.lags.nb,
            nc: self.lags.nc,
            nk: self.lags.nk,
        }
    }

    /// Reads and checks a model file.
    pub fn read(path: &Path) -> Result<Self, Failure> {
        let bytes = crate::input::read_bounded(path, MAX_MODEL_BYTES).map_err(|e| bad(path, e))?;
        let m: ModelFile = serde_json::from_slice(&bytes).map_err(|e| {
            bad(
                path,
                format!(
                    "not a pumpbench model file (line {}, column {}): {e}",
                    e.line(),
                    e.column()
                ),
            )
        })?;
        if m.format != FORMAT {
            return Err(bad(
                path,
                format!("format '{}', expected '{FORMAT}'", m.format),
            ));
        }
        let n = m.lags().inputs();
        if m.w1.len() != m.hidden
            || m.w1.iter().any(|r| r.len() != n + 1)
            || m.w2.len() != m.hidden + 1
        {
            return Err(bad(
                path,
                format!(
                    "weights do not match the lags and hidden width: expected w1 {}×{} and w2 {}",
                    m.hidden,
                    n + 1,
                    m.hidden + 1
                ),
            ));
        }
        if !(m.sample_period_s.is_finite() && m.sample_period_s > 0.0) {
            return Err(bad(path, "sample_period_s must be > 0".into()));
        }
        if let Some(t) = m.transmitter {
            let lag = 0.0..=crate::sensorlag::LAG_MAX_S;
            if ![
                t.lag_s,
                t.found_lag_s,
                t.low_speed_lag_s,
                t.high_speed_lag_s,
            ]
            .iter()
            .all(|l| lag.contains(l))
                || !(t.mismatch_pct >= 0.0)
            {
                return Err(bad(
                    path,
                    format!(
                        "transmitter: the lags must be within 0..={} s and mismatch_pct >= 0",
                        Short(crate::sensorlag::LAG_MAX_S)
                    ),
                ));
            }
        }
        // Every value must survive the firmware's arithmetic: f32, and the fixed-point form.
        let scalars = [
            m.u_scaling.mean,
            m.u_scaling.std,
            m.y_scaling.mean,
            m.y_scaling.std,
            m.u_range[0],
            m.u_range[1],
            m.y_range[0],
            m.y_range[1],
        ];
        if let Some(x) =
            m.w1.iter()
                .flatten()
                .chain(&m.w2)
                .chain(&scalars)
                .find(|&&x| !in_firmware_range(x))
        {
            return Err(bad(
                path,
                format!(
                    "value {} is out of range for the firmware's f32 arithmetic",
                    Short(*x)
                ),
            ));
        }
        m.build::<f32>().map_err(|e| bad(path, e))?;
        m.build::<f64>().map_err(|e| bad(path, e))?;
        if m.lags.nc == 0 {
            m.q15().map_err(|e| {
                bad(
                    path,
                    format!("cannot be put in the firmware's fixed point: {e}"),
                )
            })?;
        }
        Ok(m)
    }

    /// Runs `f` on the model in NNSYSID form (what model-core's MCU passes are built from).
    pub fn with_spec<R>(&self, f: impl FnOnce(&NnsysidModel) -> R) -> R {
        let w1: Vec<f64> = self.w1.iter().flatten().copied().collect();
        let scaling = |s: ScalingFile| Scaling {
            mean: s.mean,
            std: s.std,
        };
        f(&NnsysidModel {
            lags: self.lags(),
            hidden: self.hidden,
            w1: &w1,
            w2: &self.w2,
            u_scale: scaling(self.u_scaling),
            y_scale: scaling(self.y_scaling),
            u_range: self.u_range,
            y_range: self.y_range,
        })
    }

    /// The firmware's Q15 pass of this model.
    pub fn q15(&self) -> Result<HostNarxQ15, NarmaxError> {
        self.with_spec(HostNarxQ15::new)
    }

    /// The model-core model in `T` arithmetic.
    pub fn build<T: Real>(&self) -> Result<HostNarmax<T>, String> {
        let c = |x: f64| T::from_f64(x);
        let w1: Vec<T> = self.w1.iter().flatten().map(|&x| c(x)).collect();
        let w2: Vec<T> = self.w2.iter().map(|&x| c(x)).collect();
        let sc = |s: ScalingFile| Scaling {
            mean: c(s.mean),
            std: c(s.std),
        };
        Narmax::new(
            self.lags(),
            self.hidden,
            &w1,
            &w2,
            sc(self.u_scaling),
            sc(self.y_scaling),
            [c(self.u_range[0]), c(self.u_range[1])],
            [c(self.y_range[0]), c(self.y_range[1])],
        )
        .map_err(|e| e.to_string())
    }
}
