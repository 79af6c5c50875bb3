//! The transmitter's lag, found by `identify` from the record it trains on.
//!
//! A NARMAX model is fitted to a transmitter's readings, so it predicts the reading: the
//! process value passed through the transmitter's first-order lag (its damping). To give the
//! process value back, `simulate` needs that lag's time constant ([`crate::narmaxcmd::unlagged`]).
//! A record with the drive's speed (`speed_rpm`, read from the VFD: no transmitter in between)
//! tells it: with the valve fixed the process value is a static function of the speed (the
//! pump's curves at one system curve), so the reading is that function lagged,
//!
//! ```text
//! y = lag_τ(c0 + c1·s + c2·s² + c3·s³),   s = (speed − mean) / std
//! ```
//!
//! and τ is the one whose least-squares fit leaves the least residual (a scan of 0..2 s by
//! 5 ms, then by 0.5 ms around the best). The lag of each basis column is the continuous
//! first-order lag of the column taken as linear between samples (first-order hold), exact
//! for a piecewise-linear speed: the fit finds the transmitter's own time constant, not one
//! of its discretisation.
//!
//! **What can fool it, and how it says so.** Anything else that lags the process value
//! behind the speed is lumped into τ. A water column of its own (the flow a state of its own,
//! `bench-data --water-inertia`) does: its lag is part of the plant, the model must keep it,
//! and a τ that took it out would make the estimate worse, not better. A water column's lag
//! changes with the operating point, a transmitter's does not, so the lagged static fit then
//! leaves a residual with structure. The residual's covariance at one sample (white noise has
//! none) measures that structure: its root, as a share of the reading's standard deviation,
//! is the fit's *mismatch*. The estimate is trusted only when the mismatch is at most
//! [`MISMATCH_MAX_PCT`] and τ is inside the scan. Measured on `bench-data` records (600 s
//! at 50 ms, 1 200 s at 100 ms): transmitters of 0..300 ms, curve errors and drive lags,
//! no water column: τ within 5 ms of the stated lag, mismatch 0.0..0.4 %; a water column of
//! 0.1..0.5 mca·s²/l: mismatch 1.6..5.0 %, not trusted.

use crate::num::Short;

/// Largest mismatch (% of the reading's standard deviation) at which the estimate is trusted.
pub const MISMATCH_MAX_PCT: f64 = 0.5;

/// Longest lag scanned, s (`simulate --sensor-lag-ms` accepts the same range).
pub const LAG_MAX_S: f64 = 2.0;

/// The coarse scan's step, s.
const COARSE_S: f64 = 0.005;
/// The fine scan's step around the coarse best, s.
const FINE_S: f64 = 0.0005;

/// Fewest samples fitted (four coefficients, and enough for the residual's covariance).
pub const MIN_SAMPLES: usize = 100;

/// What the scan found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LagEstimate {
    /// The lag's time constant, s (0..=[`LAG_MAX_S`]).
    pub lag_s: f64,
    /// The fit's mismatch at that lag, % of the reading's standard deviation (0..).
    pub mismatch_pct: f64,
    /// The residual's RMS at that lag, the reading's unit.
    pub residual_rms: f64,
    /// Whether `simulate` may use it: mismatch ≤ [`MISMATCH_MAX_PCT`], τ inside the scan.
    pub trusted: bool,
}

impl LagEstimate {
    /// One line for a person: the lag, the mismatch, and whether it is used.
    pub fn describe(&self, column: &str) -> String {
        let ms = Short(self.lag_s * 1e3);
        if self.trusted {
            format!(
                "the {column} transmitter lags the speed by {ms} ms (fit mismatch {:.2} % of \
                 its spread): simulate takes the model's prediction back through it \
                 (--sensor-lag-ms overrides, 0 gives the reading)",
                self.mismatch_pct
            )
        } else {
            format!(
                "the {column} reading lags the speed by {ms} ms, but a first-order lag explains \
                 it badly (fit mismatch {:.2} % of its spread, over {} %, or at the scan's end): \
                 something else lags it too, e.g. a water column, so it is not taken for the \
                 transmitter's; simulate gives the reading unless --sensor-lag-ms is given",
                self.mismatch_pct,
                Short(MISMATCH_MAX_PCT)
            )
        }
    }
}

/// Why no lag could be estimated.
#[derive(Debug, Clone, PartialEq)]
pub enum NoEstimate {
    /// Fewer than [`MIN_SAMPLES`] rows with both the reading and the speed.
    TooFew(usize),
    /// The speed or the reading does not vary, or is not finite.
    Flat,
}

impl core::fmt::Display for NoEstimate {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            NoEstimate::TooFew(n) => write!(
                f,
                "{n} rows have both the reading and speed_rpm: at least {MIN_SAMPLES} are needed"
            ),
            NoEstimate::Flat => write!(
                f,
                "the speed or the reading does not vary (or is not finite): no lag can be seen"
            ),
        }
    }
}

/// The continuous first-order lag of `x` (linear between the samples at times `t_s`), started
/// at rest at `x[0]`; `tau_s` = 0 is `x` itself.
fn lag_foh(x: &[f64], t_s: &[f64], tau_s: f64, out: &mut [f64]) {
    out[0] = x[0];
    for k in 1..x.len() {
        if tau_s <= 0.0 {
            out[k] = x[k];
            continue;
        }
        let r = (t_s[k] - t_s[k - 1]) / tau_s;
        let a = (-r).exp();
        // 1 − a over r, the share of the ramp: for tiny r, 1 − r/2 (no cancellation).
        let g = if r < 1e-6 {
            1.0 - r / 2.0
        } else {
            -(-r).exp_m1() / r
        };
        out[k] = a * out[k - 1] + (1.0 - g) * x[k] + (g - a) * x[k - 1];
    }
}

/// The residual's sum of squares after the least-squares fit of `y` on the lagged basis
/// (`cols`), with the residual written to `e`; `None` if the normal equations are singular.
fn fit(cols: &[Vec<f64>; 4], y: &[f64], e: &mut [f64]) -> Option<f64> {
    use nalgebra::{Matrix4, Vector4};
    let mut a = Matrix4::<f64>::zeros();
    let mut b = Vector4::<f64>::zeros();
    for k in 0..y.len() {
        let r = Vector4::new(cols[0][k], cols[1][k], cols[2][k], cols[3][k]);
        a += r * r.transpose();
        b += r * y[k];
    }
    let c = a.cholesky()?.solve(&b);
    let mut sse = 0.0;
    for k in 0..y.len() {
        let v =
            y[k] - (c[0] * cols[0][k] + c[1] * cols[1][k] + c[2] * cols[2][k] + c[3] * cols[3][k]);
        e[k] = v;
        sse += v * v;
    }
    Some(sse)
}

/// Estimates the lag of `reading` behind the static function of `speed_rpm` (rows at times
/// `t_s`, s, strictly increasing; the three of one length). The valve must be fixed over the
/// record (identify's record is).
pub fn estimate(
    t_s: &[f64],
    speed_rpm: &[f64],
    reading: &[f64],
) -> Result<LagEstimate, NoEstimate> {
    let n = reading.len();
    if n < MIN_SAMPLES {
        return Err(NoEstimate::TooFew(n));
    }
    let (sm, ss) = crate::narmaxcmd::mean_std(speed_rpm);
    let (_, ys) = crate::narmaxcmd::mean_std(reading);
    if !(ss > 0.0 && ys > 0.0 && ss.is_finite() && ys.is_finite()) {
        return Err(NoEstimate::Flat);
    }
    let s: Vec<f64> = speed_rpm.iter().map(|w| (w - sm) / ss).collect();
    let basis: [Vec<f64>; 4] =
        core::array::from_fn(|p| s.iter().map(|v| v.powi(p as i32)).collect());
    let mut cols: [Vec<f64>; 4] = core::array::from_fn(|_| vec![0.0; n]);
    let mut e = vec![0.0; n];
    let mut sse_at = |tau: f64, e: &mut [f64]| -> f64 {
        for (col, x) in cols.iter_mut().zip(&basis) {
            lag_foh(x, t_s, tau, col);
        }
        fit(&cols, reading, e).unwrap_or(f64::INFINITY)
    };
    let best = |lo: f64,
                hi: f64,
                step: f64,
                sse_at: &mut dyn FnMut(f64, &mut [f64]) -> f64,
                e: &mut [f64]| {
        let steps = ((hi - lo) / step).round() as usize;
        (0..=steps)
            .map(|i| (lo + i as f64 * step).clamp(0.0, LAG_MAX_S))
            .map(|tau| (tau, sse_at(tau, e)))
            .fold((0.0, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b })
    };
    let (coarse, _) = best(0.0, LAG_MAX_S, COARSE_S, &mut sse_at, &mut e);
    let (lo, hi) = (
        (coarse - COARSE_S).max(0.0),
        (coarse + COARSE_S).min(LAG_MAX_S),
    );
    let (lag_s, sse) = best(lo, hi, FINE_S, &mut sse_at, &mut e);
    if !sse.is_finite() {
        return Err(NoEstimate::Flat);
    }
    // The residual at the best lag, for its covariance at one sample.
    sse_at(lag_s, &mut e);
    let cov1 = e.windows(2).map(|p| p[0] * p[1]).sum::<f64>() / (n - 1) as f64;
    let mismatch_pct = 100.0 * cov1.max(0.0).sqrt() / ys;
    let at_edge = lag_s >= LAG_MAX_S - COARSE_S;
    Ok(LagEstimate {
        lag_s,
        mismatch_pct,
        residual_rms: (sse / n as f64).sqrt(),
        trusted: mismatch_pct <= MISMATCH_MAX_PCT && !at_edge,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A speed that moves like a pump's under a random torque: a first-order response
    /// (0.4 s) to a held level that changes every 0.5..2 s, at 1 ms.
    fn speed_1ms(seconds: f64, seed: u64) -> Vec<f64> {
        let mut rng = model_core::excitation::SplitMix64::new(seed);
        let n = (seconds * 1e3) as usize;
        let (mut w, mut target, mut left) = (1500.0, 1500.0, 0usize);
        (0..n)
            .map(|_| {
                if left == 0 {
                    target = 900.0 + 1800.0 * rng.next_f64();
                    left = 500 + (1500.0 * rng.next_f64()) as usize;
                }
                left -= 1;
                w += (target - w) * (1e-3 / 0.4);
                w
            })
            .collect()
    }

    /// A lag of `tau_s` at 1 ms (exact for a held input), then every `every`-th sample.
    fn lagged_sampled(x: &[f64], tau_s: f64, every: usize) -> Vec<f64> {
        let a = if tau_s > 0.0 {
            (-1e-3 / tau_s).exp()
        } else {
            0.0
        };
        let mut z = x[0];
        let mut out = Vec::new();
        for (k, v) in x.iter().enumerate() {
            z = a * z + (1.0 - a) * v;
            if k % every == 0 {
                out.push(z);
            }
        }
        out
    }

    fn record(tau_s: f64, every: usize, noise: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let w = speed_1ms(300.0, 7);
        // A pump's pressure at a fixed valve: about quadratic in speed, with a static head.
        let p: Vec<f64> = w.iter().map(|w| 0.3 + 1.1e-6 * w * w + 2e-4 * w).collect();
        let y = lagged_sampled(&p, tau_s, every);
        let mut rng = model_core::excitation::SplitMix64::new(3);
        let y = y
            .iter()
            .map(|v| v + noise * (rng.next_f64() - 0.5) * 3.46)
            .collect();
        let speed: Vec<f64> = w.iter().step_by(every).copied().collect();
        let t: Vec<f64> = (0..speed.len())
            .map(|k| (k * every) as f64 * 1e-3)
            .collect();
        (t, speed, y)
    }

    #[test]
    fn finds_the_lag_of_a_transmitter_behind_a_static_function_of_speed() {
        for (tau, every) in [
            (0.0, 50),
            (0.02, 50),
            (0.06, 50),
            (0.15, 100),
            (0.3, 100),
            (0.8, 50),
        ] {
            let (t, w, y) = record(tau, every, 0.003);
            let e = estimate(&t, &w, &y).unwrap();
            assert!((e.lag_s - tau).abs() <= 0.003 + 0.02 * tau, "{tau}: {e:?}");
            assert!(e.trusted, "{tau}: {e:?}");
        }
    }

    #[test]
    fn a_second_lag_of_the_plant_is_not_taken_for_the_transmitter() {
        // The process value itself lags the speed by 0.25 s at low speed and 0.08 s at high
        // (a water column's lag falls with the flow): not a transmitter.
        let w = speed_1ms(300.0, 9);
        let mut q = w[0];
        let p: Vec<f64> = w
            .iter()
            .map(|&w| {
                let tau = 0.08 + 0.17 * ((2700.0 - w) / 1800.0).clamp(0.0, 1.0);
                q += (w - q) * (1e-3 / tau);
                0.3 + 1.1e-6 * q * q
            })
            .collect();
        let y = lagged_sampled(&p, 0.02, 50);
        let speed: Vec<f64> = w.iter().step_by(50).copied().collect();
        let t: Vec<f64> = (0..speed.len()).map(|k| k as f64 * 0.05).collect();
        let e = estimate(&t, &speed, &y).unwrap();
        assert!(!e.trusted, "{e:?}");
        assert!(e.mismatch_pct > MISMATCH_MAX_PCT, "{e:?}");
    }

    #[test]
    fn flat_or_short_records_give_no_estimate() {
        let t: Vec<f64> = (0..500).map(|k| k as f64 * 0.05).collect();
        let flat = vec![1500.0; 500];
        let y: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        assert_eq!(estimate(&t, &flat, &y), Err(NoEstimate::Flat));
        assert_eq!(estimate(&t, &y, &vec![2.0; 500]), Err(NoEstimate::Flat));
        assert_eq!(
            estimate(&t[..10], &y[..10], &y[..10]),
            Err(NoEstimate::TooFew(10))
        );
        let mut nan = y.clone();
        nan[3] = f64::NAN;
        assert_eq!(estimate(&t, &nan, &y), Err(NoEstimate::Flat));
    }
}
