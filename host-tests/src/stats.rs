//! Error statistics for model-vs-reference comparisons.

use std::fmt;

/// Relative error statistics of a series of (model, reference) pairs.
///
/// The relative error of a pair is `(model − reference) / max(|reference|, floor)`.
#[derive(Debug, Clone, Copy, Default)]
pub struct ErrorStats {
    /// Number of pairs.
    pub n: usize,
    /// Largest |relative error|.
    pub max_abs: f64,
    /// Index of the largest.
    pub argmax: usize,
    /// Root mean square of the relative error.
    pub rms: f64,
    /// Mean (signed) relative error.
    pub bias: f64,
    sum: f64,
    sum_sq: f64,
}

impl ErrorStats {
    /// Adds one pair; `floor` is the absolute floor of the denominator.
    pub fn push(&mut self, model: f64, reference: f64, floor: f64) {
        let e = (model - reference) / reference.abs().max(floor);
        let e = if e.is_nan() { f64::INFINITY } else { e };
        if e.abs() > self.max_abs || self.n == 0 {
            self.max_abs = e.abs();
            self.argmax = self.n;
        }
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.bias = self.sum / self.n as f64;
        self.rms = (self.sum_sq / self.n as f64).sqrt();
    }
}

impl fmt::Display for ErrorStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "n={} max={:.3e} (at #{}) rms={:.3e} bias={:+.3e}",
            self.n, self.max_abs, self.argmax, self.rms, self.bias
        )
    }
}
