//! `pumpbench excite`: the paper's excitation — pulses of uncorrelated amplitudes, uniform in a
//! torque range, held for random whole numbers of samples.

use crate::error::Failure;
use model_core::excitation::PulseTrain;
use std::io::Write;

/// Options of `excite`.
pub struct Excite {
    /// Seed of the generator.
    pub seed: u64,
    /// Length, s.
    pub seconds: f64,
    /// Sample period, s.
    pub ts_s: f64,
    /// Amplitude range, %.
    pub min_pct: f64,
    /// Amplitude range, %.
    pub max_pct: f64,
    /// Hold range, s.
    pub min_hold_s: f64,
    /// Hold range, s.
    pub max_hold_s: f64,
}

/// The samples of the excitation: `(t_s, torque_ref_pct)` every `ts_s` from 0 to `seconds`.
pub fn samples(o: &Excite) -> Vec<(f64, f64)> {
    let mut train = PulseTrain::paper(o.seed);
    train.min_pct = o.min_pct;
    train.max_pct = o.max_pct;
    train.min_hold_s = o.min_hold_s;
    train.max_hold_s = o.max_hold_s;
    train.period_s = o.ts_s;
    let n = (o.seconds / o.ts_s + 1e-9).floor() as usize + 1;
    let mut out = Vec::with_capacity(n);
    let mut left = 0usize;
    let mut u = 0.0;
    for k in 0..n {
        if left == 0 {
            let p = train.next_pulse();
            u = p.torque_ref_pct;
            left = (p.hold_s / o.ts_s).round().max(1.0) as usize;
        }
        left -= 1;
        // Times as k·Ts, printed in their shortest form (0.05, 0.1, …).
        out.push((round_time(k as f64 * o.ts_s), u));
    }
    out
}

/// Rounds a time to 1 ns so that k·Ts prints as the decimal the user expects.
pub fn round_time(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

/// Normalised auto-covariance of `x` at lags 1..=max_lag (lag 0 = 1).
pub fn autocovariance(x: &[f64], max_lag: usize) -> Vec<f64> {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let c0: f64 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (1..=max_lag)
        .map(|k| {
            if k >= x.len() || c0 == 0.0 {
                return 0.0;
            }
            x.iter()
                .zip(&x[k..])
                .map(|(a, b)| (a - mean) * (b - mean))
                .sum::<f64>()
                / n
                / c0
        })
        .collect()
}

/// Writes the excitation CSV and prints its auto-covariance to stderr.
pub fn run(o: &Excite, w: &mut dyn Write) -> Result<(), Failure> {
    let rows = samples(o);
    let io = |e: std::io::Error| Failure {
        code: 1,
        message: format!("cannot write the output: {e}"),
    };
    writeln!(w, "t_s,torque_ref_pct").map_err(io)?;
    for (t, u) in &rows {
        writeln!(w, "{t},{u}").map_err(io)?;
    }
    let u: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let acov = autocovariance(&u, 10);
    let text: Vec<String> = acov.iter().map(|c| format!("{c:.3}")).collect();
    eprintln!(
        "excite: {} samples; input auto-covariance (normalised) at lags 1..10: {}",
        rows.len(),
        text.join(" ")
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(min_hold_s: f64, max_hold_s: f64) -> Excite {
        Excite {
            seed: 9,
            seconds: 600.0,
            ts_s: 0.05,
            min_pct: 5.0,
            max_pct: 85.0,
            min_hold_s,
            max_hold_s,
        }
    }

    #[test]
    fn uniform_amplitudes_on_the_sample_grid() {
        let rows = samples(&opts(0.05, 2.0));
        assert_eq!(rows.len(), 12_001);
        assert_eq!(rows[3].0, 0.15);
        assert!(rows.iter().all(|r| (5.0..85.0).contains(&r.1)));
        let mean = rows.iter().map(|r| r.1).sum::<f64>() / rows.len() as f64;
        assert!((mean - 45.0).abs() < 3.0, "{mean}");
    }

    #[test]
    fn one_sample_holds_give_white_input() {
        let acov = autocovariance(
            &samples(&opts(0.05, 0.05))
                .iter()
                .map(|r| r.1)
                .collect::<Vec<_>>(),
            10,
        );
        assert!(acov.iter().all(|c| c.abs() < 0.05), "{acov:?}");
        let slow = autocovariance(
            &samples(&opts(1.0, 1.0))
                .iter()
                .map(|r| r.1)
                .collect::<Vec<_>>(),
            10,
        );
        assert!(slow[0] > 0.9, "{slow:?}");
    }
}
