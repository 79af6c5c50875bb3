//! NARMAX commands: `identify`, and the narmax forms of `simulate`, `steady`, `validate`.

use crate::error::Failure;
use crate::input::{read_series, Series};
use crate::modelfile::{
    in_firmware_range, HostNarxQ15, LagsFile, ModelFile, ScalingFile, Target, Training,
    TransmitterFile, FORMAT, MAX_ABS_VALUE,
};
use crate::num::Short;
use crate::train::{identify, Data, Structure};
use indicatif::{ProgressBar, ProgressStyle};
use model_core::narmax::Predictor;
use model_core::Real;
use std::io::Write;
use std::path::Path;

fn usage(m: String) -> Failure {
    Failure {
        code: 2,
        message: m,
    }
}

fn io(e: std::io::Error) -> Failure {
    Failure {
        code: 1,
        message: format!("cannot write the output: {e}"),
    }
}

/// Mean and standard deviation (N − 1, as MATLAB's `std`).
pub fn mean_std(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

fn range(x: &[f64]) -> [f64; 2] {
    x.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |r, &v| {
        [r[0].min(v), r[1].max(v)]
    })
}

/// Options of `identify`.
pub struct Identify<'a> {
    /// Training data.
    pub data: &'a Path,
    /// Output to model.
    pub target: Target,
    /// Structure.
    pub structure: Structure,
    /// Accepted LM steps.
    pub epochs: usize,
    /// Seed of the initial weights.
    pub seed: u64,
    /// Seeded starts (the lowest final training criterion wins).
    pub starts: usize,
}

/// Trains a model; returns the model file.
pub fn run_identify(o: &Identify) -> Result<ModelFile, Failure> {
    let s = o.structure;
    if s.hidden == 0 || s.inputs() == 0 || s.nk > model_core::narmax::MAX_NK {
        return Err(usage(
            "need --hidden >= 1, at least one lag, and --nk <= 8".into(),
        ));
    }
    if s.inputs() > crate::modelfile::HOST_MAX_INPUTS
        || s.hidden > crate::modelfile::HOST_MAX_HIDDEN
    {
        return Err(usage(format!(
            "at most {} regressors and {} hidden units",
            crate::modelfile::HOST_MAX_INPUTS,
            crate::modelfile::HOST_MAX_HIDDEN
        )));
    }
    let series = read_series(o.data, o.target.column(), true)?;
    let y = series.y.clone().unwrap_or_default();
    let n = y.len();
    if n < s.max_lag() + s.params() + 1 {
        return Err(usage(format!(
            "{}: {n} samples is too few for {} weights after {} lags",
            o.data.display(),
            s.params(),
            s.max_lag()
        )));
    }
    let (um, us) = mean_std(&series.torque_ref_pct);
    let (ym, ys) = mean_std(&y);
    let (u_range, y_range) = (range(&series.torque_ref_pct), range(&y));
    for (column, mean, std, r) in [
        ("torque_ref_pct", um, us, u_range),
        (o.target.column(), ym, ys, y_range),
    ] {
        let what = format!(
            "{}: {column} (from {} to {})",
            o.data.display(),
            Short(r[0]),
            Short(r[1])
        );
        if !mean.is_finite() || !std.is_finite() {
            return Err(usage(format!(
                "{what}: its mean or spread overflows f64 (standard deviation not finite): \
                 nothing can be scaled"
            )));
        }
        if let Some(x) = [mean, std, r[0], r[1]]
            .into_iter()
            .find(|&x| !in_firmware_range(x))
        {
            return Err(usage(format!(
                "{what}: {} is out of range for a model file (|value| <= {}, the firmware's \
                 f32 arithmetic)",
                Short(x),
                Short(MAX_ABS_VALUE)
            )));
        }
        if !(std > 0.0) {
            return Err(usage(format!("{what} is constant: nothing to identify")));
        }
    }
    let u_scaled: Vec<f64> = series
        .torque_ref_pct
        .iter()
        .map(|u| (u - um) / us)
        .collect();
    let y_scaled: Vec<f64> = y.iter().map(|v| (v - ym) / ys).collect();
    let bar = ProgressBar::new(o.epochs as u64);
    bar.set_style(
        ProgressStyle::with_template("identify {bar:30} epoch {pos}/{len} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = std::time::Instant::now();
    let d = Data {
        u: &u_scaled,
        y: &y_scaled,
    };
    let trained = identify(&s, &d, o.epochs, o.seed, o.starts, |e| {
        bar.set_position(e.epoch as u64);
        bar.set_message(format!(
            "criterion {:.4e} lambda {:.1e}",
            e.criterion, e.lambda
        ));
    });
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let n_in = s.inputs();
    let file = ModelFile {
        format: FORMAT.into(),
        target: o.target,
        sample_period_s: series.sample_period_s,
        lags: LagsFile {
            na: s.na,
            nb: s.nb,
            nc: s.nc,
            nk: s.nk,
        },
        hidden: s.hidden,
        w1: trained
            .weights
            .w1
            .chunks(n_in + 1)
            .map(|r| r.to_vec())
            .collect(),
        w2: trained.weights.w2.clone(),
        u_scaling: ScalingFile { mean: um, std: us },
        y_scaling: ScalingFile { mean: ym, std: ys },
        u_range,
        y_range,
        training: Training {
            data: o.data.display().to_string(),
            samples: n,
            epochs: o.epochs,
            epochs_done: trained.criterion.len() - 1,
            seed: o.seed,
            starts: o.starts,
            criterion: trained.criterion.clone(),
            lambda: trained.lambda,
            stop: trained.stop.into(),
            seconds,
            tool: format!("pumpbench {}", env!("CARGO_PKG_VERSION")),
        },
        transmitter: transmitter_lag(o.data, o.target),
    };
    eprintln!(
        "identify: {} epochs in {seconds:.2} s, criterion {:.4e} -> {:.4e} ({})",
        file.training.epochs_done,
        trained.criterion[0],
        trained.criterion.last().copied().unwrap_or(f64::NAN),
        trained.stop
    );
    Ok(file)
}

/// The transmitter's lag behind the speed in the training record ([`crate::sensorlag`]),
/// said on stderr; `None` (and why, on stderr) when the record has no `speed_rpm` or the lag
/// cannot be seen. Never fails identify: the model is the same with or without it.
fn transmitter_lag(data: &Path, target: Target) -> Option<TransmitterFile> {
    let column = target.column();
    let say = |m: String| eprintln!("identify: {m}");
    let rec = match crate::input::read_gappy_series(data, &[], &[column, "speed_rpm"]) {
        Ok(r) => r,
        Err(e) => {
            say(format!("no transmitter lag estimated: {e}"));
            return None;
        }
    };
    let (Some(y), Some(w)) = (&rec.columns[0], &rec.columns[1]) else {
        say(format!(
            "no speed_rpm column: the {column} transmitter's lag is not estimated (simulate gives the reading unless --sensor-lag-ms is given)"
        ));
        return None;
    };
    // The rows with both a reading and a finite speed; a few without a speed (a VFD read
    // that failed: an empty cell in the controller's record) are left out, the lag taken
    // across them.
    let (mut t, mut speed, mut reading) = (Vec::new(), Vec::new(), Vec::new());
    let mut without = 0usize;
    for k in 0..rec.input.t_s.len() {
        match (y[k], w[k]) {
            (Some(yk), Some(wk)) if yk.is_finite() && wk.is_finite() => {
                t.push(rec.input.t_s[k]);
                speed.push(wk);
                reading.push(yk);
            }
            (Some(_), _) => without += 1,
            (None, _) => {}
        }
    }
    let with = reading.len();
    if without * 100 > with + without {
        say(format!(
            "{without} of {} {column} samples have no finite speed_rpm, or are not finite themselves (over 1 %): the transmitter's lag is not estimated",
            with + without
        ));
        return None;
    }
    match crate::sensorlag::estimate(&t, &speed, &reading) {
        Ok(e) => {
            say(e.describe(column));
            Some(TransmitterFile {
                lag_s: e.lag_s,
                found_lag_s: e.found_lag_s,
                low_speed_lag_s: e.low_speed_lag_s,
                high_speed_lag_s: e.high_speed_lag_s,
                mismatch_pct: e.mismatch_pct,
                explained_pct: e.explained_pct,
                trusted: e.trusted,
            })
        }
        Err(e) => {
            say(format!("no transmitter lag estimated: {e}"));
            None
        }
    }
}

/// Writes a model file (pretty JSON and a final newline), complete or not at all.
pub fn write_model(path: &Path, model: &ModelFile) -> Result<(), Failure> {
    crate::output::write_csv(Some(path), |w| {
        serde_json::to_writer_pretty(&mut *w, model).map_err(|e| Failure {
            code: 1,
            message: format!("cannot write the model: {e}"),
        })?;
        writeln!(w).map_err(|e| Failure {
            code: 1,
            message: e.to_string(),
        })
    })
}

/// Reads a data file for a model and checks its sample period against the model's.
pub fn read_for_model(m: &ModelFile, path: &Path, need_y: bool) -> Result<Series, Failure> {
    let s = read_series(path, m.target.column(), need_y)?;
    if s.t_s.len() > 1 && (s.sample_period_s / m.sample_period_s - 1.0).abs() > 1e-2 {
        return Err(usage(format!(
            "{}: sampled every {} s but the model was identified at {} s",
            path.display(),
            Short(s.sample_period_s),
            Short(m.sample_period_s)
        )));
    }
    Ok(s)
}

/// The settled output of `m` under a constant torque `u` (%), physical f64: successive outputs
/// within 1e-7 of the output's spread, or 64 ulps of its scale in the model's arithmetic
/// (the Q15 pass settles no finer than 4 LSBs of its code); `None` if it does not settle in
/// 200 000 steps.
fn settled<P: Predictor>(m: &P, u: f64) -> Option<f64> {
    let ys = m.output_scaling();
    let v = P::Value::from_f64;
    let ulps = (ys.mean.abs() + v(4.0) * ys.std) * P::Value::EPSILON * v(64.0);
    let tol = (ys.std * v(1e-7)).max(ulps);
    m.steady_output(v(u), tol, 200_000).map(Real::to_f64)
}

/// Free-run simulation of `series`: one output per row. If the series has the target column,
/// its first max-lag rows seed the history and are returned as measured; otherwise the history
/// starts at the model's own steady state for the first torque.
pub fn free_run<M: Predictor>(m: &M, series: &Series) -> Result<Vec<f64>, Failure> {
    free_run_with(m, series, |_, y| y)
}

/// [`free_run`], each row `k`'s free-run output `y` given as `output(k, y)`.
fn free_run_with<M: Predictor>(
    m: &M,
    series: &Series,
    mut output: impl FnMut(usize, M::Value) -> M::Value,
) -> Result<Vec<f64>, Failure> {
    let u = &series.torque_ref_pct;
    let v = M::Value::from_f64;
    let mut out = Vec::with_capacity(u.len());
    let mut st;
    let mut start = 0;
    match &series.y {
        Some(y) => {
            st = m.state_at(v(u[0]), v(y[0]));
            start = m.lags().max_lag().min(u.len());
            for k in 0..start {
                m.seed(&mut st, v(u[k]), v(y[k]));
                out.push(y[k]);
            }
        }
        None => {
            let y0 = steady_of(m, u[0])?;
            st = m.state_at(v(u[0]), v(y0));
        }
    }
    let mut clamped = 0usize;
    for (k, &uk) in u.iter().enumerate().skip(start) {
        let o = m.simulate_step(&mut st, v(uk));
        out.push(output(k, o.y).to_f64());
        clamped += usize::from(o.clamped);
    }
    if clamped > 0 {
        eprintln!(
            "pumpbench: {clamped} of {} free-run samples had regressors outside the training range (clamped)",
            u.len() - start
        );
    }
    Ok(out)
}

/// The transmitter span of a target, physical units: readings at or beyond it are the
/// controller's clamped values, not measurements (`model_core::transmitter`).
pub fn span(target: Target) -> (f64, f64) {
    let l = match target {
        Target::Pressure => model_core::transmitter::PRESSURE_LOOP,
        Target::Flow => model_core::transmitter::FLOW_LOOP,
    };
    (f64::from(l.value_at_4ma), f64::from(l.value_at_20ma))
}

/// [`free_run`] followed by the output map (`model_core::narmax::adapt`, memory `tau_s`): each
/// row's output is the map of the network's free-run output, then the row's measurement
/// (inside [`span`]) updates the map. The seed rows are as in [`free_run`]. Reports on stderr
/// how many rows the map took and how often it fell back to the identity.
pub fn free_run_adapted<M: Predictor>(
    model: &M,
    m: &ModelFile,
    series: &Series,
    tau_s: f64,
) -> Result<Vec<f64>, Failure> {
    use model_core::narmax::adapt::{OutputMap, TAU_RANGE_S};
    let v = M::Value::from_f64;
    let y = series
        .y
        .as_ref()
        .ok_or_else(|| usage(format!("--adapt needs the {} column", m.target.column())))?;
    let mut map =
        OutputMap::new(model.output_scaling(), v(m.sample_period_s), v(tau_s)).map_err(|_| {
            usage(format!(
                "--adapt-tau-s {}: must be within {}..={} s",
                Short(tau_s),
                TAU_RANGE_S.0,
                TAU_RANGE_S.1
            ))
        })?;
    let (lo, hi) = span(m.target);
    let (mut taken, mut resets) = (0usize, 0usize);
    let out = free_run_with(model, series, |k, network| {
        let adapted = map.output(network);
        if y[k] > lo && y[k] < hi {
            let r = map.update(network, v(y[k]));
            taken += usize::from(r.taken);
            resets += usize::from(r.diverged);
        }
        adapted
    })?;
    let rows = series.torque_ref_pct.len() - model.lags().max_lag().min(y.len());
    eprintln!(
        "pumpbench: output map (memory {} s): {taken} of {rows} rows taken, {resets} fallbacks to the identity",
        Short(tau_s)
    );
    Ok(out)
}

/// The model's steady output under a constant torque `u` (%); a model that does not settle is
/// an error (code 1).
pub fn steady_of<M: Predictor>(m: &M, u: f64) -> Result<f64, Failure> {
    settled(m, u).ok_or_else(|| Failure {
        code: 1,
        message: format!(
            "the model does not settle under a constant torque of {} %",
            Short(u)
        ),
    })
}

/// The firmware's Q15 pass of a model file (NARX models only: nc = 0).
pub fn quantized(m: &ModelFile) -> Result<HostNarxQ15, Failure> {
    m.q15().map_err(|e| usage(e.to_string()))
}

/// `simulate --model narmax`: the free run, alone or (`adapt_tau_s`) with the output map
/// fitted on line to the series' measurements; taken back through the transmitter's lag
/// ([`unlagged`]) of `sensor_lag_s` if given, else of the model file's trusted estimate
/// (`identify`'s, [`crate::sensorlag`]), else left as the prediction of the reading.
pub fn simulate<M: Predictor>(
    model: &M,
    m: &ModelFile,
    series: &Series,
    adapt_tau_s: Option<f64>,
    sensor_lag_s: Option<f64>,
    w: &mut dyn Write,
) -> Result<(), Failure> {
    let mut y = match adapt_tau_s {
        None => free_run(model, series)?,
        Some(tau) => free_run_adapted(model, m, series, tau)?,
    };
    // A trusted lag of 0 is the reading itself: nothing to take back, nothing to say.
    let from_file = m
        .transmitter
        .filter(|t| t.trusted && t.lag_s > 0.0)
        .map(|t| t.lag_s);
    let sensor_lag_s = match (sensor_lag_s, from_file) {
        (Some(given), _) => Some(given),
        (None, Some(lag)) => {
            eprintln!(
                "pumpbench: the output is the process value: the prediction taken back through the {} transmitter's lag of {} ms that identify found (--sensor-lag-ms 0 gives the reading)",
                m.target.column(),
                Short((lag * 1e6).round() / 1e3)
            );
            Some(lag)
        }
        (None, None) => {
            if adapt_tau_s.is_some() {
                eprintln!(
                    "pumpbench: the output predicts the transmitter's reading; --sensor-lag-ms (its time constant) gives the process value before it"
                );
            }
            None
        }
    };
    if let Some(tau) = sensor_lag_s {
        let seeded = if series.y.is_some() {
            model.lags().max_lag().min(y.len())
        } else {
            0
        };
        y = unlagged(&y, &series.t_s, seeded, tau);
    }
    writeln!(w, "t_s,torque_ref_pct,{}", m.target.column()).map_err(io)?;
    for ((t, u), v) in series.t_s.iter().zip(&series.torque_ref_pct).zip(&y) {
        writeln!(w, "{},{},{}", Short(*t), Short(*u), Short(*v)).map_err(io)?;
    }
    Ok(())
}

/// A prediction of a transmitter's readings `y` (at the times `t_s`, s) taken back through
/// its first-order lag of `tau_s` s: the estimate of the process value before the transmitter
/// (`model_core::transmitter::unlag`, each row from the row before, over the time between
/// them). The first `seeded` rows are readings echoed as they are (the history's seed), and so
/// is the first prediction: a reading's noise is not taken through the inverse.
pub fn unlagged(y: &[f64], t_s: &[f64], seeded: usize, tau_s: f64) -> Vec<f64> {
    use model_core::transmitter::unlag;
    (0..y.len())
        .map(|k| match k.checked_sub(1) {
            Some(j) if k > seeded => unlag(y[k], y[j], t_s[k] - t_s[j], tau_s),
            _ => y[k],
        })
        .collect()
}

/// `steady --model narmax`.
pub fn steady<M: Predictor>(
    model: &M,
    m: &ModelFile,
    torques: &[f64],
    w: &mut dyn Write,
) -> Result<(), Failure> {
    writeln!(w, "torque_ref_pct,{}", m.target.column()).map_err(io)?;
    let outside: Vec<String> = torques
        .iter()
        .filter(|&&u| u < m.u_range[0] || u > m.u_range[1])
        .map(|&u| Short(u).to_string())
        .collect();
    if !outside.is_empty() {
        eprintln!(
            "pumpbench: torque {} % outside the training range {}..{} %: the input is clamped to it",
            outside.join(", "),
            Short(m.u_range[0]),
            Short(m.u_range[1])
        );
    }
    for &u in torques {
        let y = steady_of(model, u)?;
        writeln!(w, "{},{}", Short(u), Short(y)).map_err(io)?;
    }
    Ok(())
}

/// Mean absolute percentage error, %, of `model` against `measured` (paper eqs. 1-2).
///
/// Samples whose measurement is exactly 0 (the relative error is undefined there) are left
/// out; [`zero_measurements`] counts them so callers can say so.
pub fn mape_pct(measured: &[f64], model: &[f64]) -> f64 {
    let n = measured.len().min(model.len());
    let (sum, count) = (0..n)
        .filter(|&k| measured[k] != 0.0)
        .fold((0.0, 0usize), |(s, c), k| {
            (s + ((measured[k] - model[k]) / measured[k]).abs(), c + 1)
        });
    100.0 * sum / count.max(1) as f64
}

/// How many measurements [`mape_pct`] leaves out (exactly 0).
pub fn zero_measurements(measured: &[f64]) -> usize {
    measured.iter().filter(|&&v| v == 0.0).count()
}

/// MAPE_d of the free-run simulation (seed rows skipped) and, with static data, MAPE_s.
pub struct Validation {
    /// Free-run samples compared.
    pub samples: usize,
    /// MAPE_d, %.
    pub mape_d_pct: f64,
    /// Static points and MAPE_s, %.
    pub mape_s: Option<(usize, f64)>,
}

/// `validate`.
///
/// `statics` holds `(torque_ref_pct, measured steady output)` pairs.
pub fn validate<M: Predictor>(
    model: &M,
    m: &ModelFile,
    series: &Series,
    statics: Option<&[(f64, f64)]>,
) -> Result<Validation, Failure> {
    let y = series
        .y
        .as_ref()
        .ok_or_else(|| usage("validation data needs the target column".into()))?;
    let skip = m.lags().max_lag();
    if y.len() <= skip {
        return Err(usage(format!(
            "the validation record has {} rows; the model needs more than its {skip} seed rows",
            y.len()
        )));
    }
    if y[skip..].iter().all(|&v| v == 0.0) {
        return Err(usage(
            "every measurement after the seed rows is 0: MAPE is undefined".into(),
        ));
    }
    let sim = free_run(model, series)?;
    let mape_d_pct = mape_pct(&y[skip..], &sim[skip..]);
    let zeros = zero_measurements(&y[skip..]);
    if zeros > 0 {
        eprintln!("validate: {zeros} samples with a measurement of exactly 0 left out of MAPE_d");
    }
    let mape_s = match statics {
        None => None,
        Some(points) => {
            let ys: Vec<f64> = points.iter().map(|p| p.1).collect();
            let zeros = zero_measurements(&ys);
            if zeros == ys.len() {
                return Err(usage(
                    "every steady-state measurement is 0: MAPE_s is undefined".into(),
                ));
            }
            if zeros > 0 {
                eprintln!("validate: {zeros} steady-state points with a measurement of 0 left out of MAPE_s");
            }
            let mut model_ys = Vec::with_capacity(ys.len());
            for &(u, _) in points {
                model_ys.push(steady_of(model, u)?);
            }
            Some((ys.len() - zeros, mape_pct(&ys, &model_ys)))
        }
    };
    Ok(Validation {
        samples: y.len() - skip,
        mape_d_pct,
        mape_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mape_leaves_zero_measurements_out() {
        assert!((mape_pct(&[2.0, 4.0], &[2.2, 4.0]) - 5.0).abs() < 1e-12);
        assert!((mape_pct(&[2.0, 0.0, 4.0], &[2.2, 1.0, 4.0]) - 5.0).abs() < 1e-12);
        assert_eq!(zero_measurements(&[2.0, 0.0, -0.0]), 2);
        assert_eq!(mape_pct(&[0.0], &[1.0]), 0.0);
    }

    #[test]
    fn sampling_jitter_is_accepted_up_to_ten_percent() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("jitter.csv");
        std::fs::write(
            &ok,
            "t_s,torque_ref_pct,flow_lps\n0,10,1\n0.052,10,1\n0.1,10,1\n0.149,10,1\n",
        )
        .unwrap();
        let s = crate::input::read_series(&ok, "flow_lps", true).unwrap();
        assert!((s.sample_period_s - 0.149 / 3.0).abs() < 1e-12, "mean step");
        let bad = dir.path().join("missing.csv");
        std::fs::write(
            &bad,
            "t_s,torque_ref_pct,flow_lps\n0,10,1\n0.05,10,1\n0.15,10,1\n0.2,10,1\n",
        )
        .unwrap();
        let e = crate::input::read_series(&bad, "flow_lps", true).unwrap_err();
        assert_eq!(e.line, Some(4));
    }

    #[test]
    fn times_wider_than_an_f64_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let wide = dir.path().join("wide.csv");
        std::fs::write(
            &wide,
            "t_s,torque_ref_pct,flow_lps\n-1e308,10,1\n0,10,1\n1e308,10,1\n",
        )
        .unwrap();
        let e = crate::input::read_series(&wide, "flow_lps", true).unwrap_err();
        assert_eq!(e.line, Some(4));
        assert_eq!(
            e.message,
            "the times span -1e308 s to 1e308 s: more than an f64 holds"
        );
        let inf_step = dir.path().join("inf_step.csv");
        std::fs::write(
            &inf_step,
            "t_s,torque_ref_pct,flow_lps\n-1.7e308,10,1\n1.7e308,10,1\n",
        )
        .unwrap();
        let e = crate::input::read_series(&inf_step, "flow_lps", true).unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.message.contains("step inf s"), "{}", e.message);
    }
}
