//! Independent f64 NARMAX forward pass: straightforward loops and `f64::tanh`, regressors
//! built by indexing the whole input/output/error sequences (no shift registers), NNSYSID
//! weight layout (W1 hidden × (inputs + 1) and W2 hidden + 1, biases last).

/// A NARMAX network in physical units at the edges.
#[derive(Debug, Clone)]
pub struct RefNarmax {
    /// na, nb, nc, nk.
    pub lags: [usize; 4],
    /// W1 rows, bias last.
    pub w1: Vec<Vec<f64>>,
    /// W2, bias last.
    pub w2: Vec<f64>,
    /// u mean and std.
    pub u_scale: (f64, f64),
    /// y mean and std.
    pub y_scale: (f64, f64),
}

impl RefNarmax {
    /// max(na, nb + nk − 1, nc).
    pub fn max_lag(&self) -> usize {
        let [na, nb, nc, nk] = self.lags;
        na.max(nc).max(nb + nk - 1)
    }

    /// ŷ(t) (scaled) from scaled sequences: z_y[t−1..], z_u[t−nk..], e[t−1..]; values before
    /// index 0 are `before` = (u, y) scaled, and 0 for errors.
    fn predict(&self, zu: &[f64], zy: &[f64], e: &[f64], t: usize, before: (f64, f64)) -> f64 {
        let [na, nb, nc, nk] = self.lags;
        let at = |s: &[f64], back: usize, before: f64| if t >= back { s[t - back] } else { before };
        let mut phi = Vec::new();
        for i in 1..=na {
            phi.push(at(zy, i, before.1));
        }
        for i in 0..nb {
            phi.push(at(zu, nk + i, before.0));
        }
        for i in 1..=nc {
            phi.push(at(e, i, 0.0));
        }
        let mut out = self.w2[self.w2.len() - 1];
        for (row, w2) in self.w1.iter().zip(&self.w2) {
            let mut a = row[row.len() - 1];
            for (w, x) in row.iter().zip(&phi) {
                a += w * x;
            }
            out += w2 * a.tanh();
        }
        out
    }

    /// One-step-ahead predictions for measured `u`, `y` (physical), errors fed back; the
    /// history before the first sample is (u[0], `y_init`).
    pub fn one_step(&self, u: &[f64], y: &[f64], y_init: f64) -> Vec<f64> {
        let zu: Vec<f64> = u
            .iter()
            .map(|v| (v - self.u_scale.0) / self.u_scale.1)
            .collect();
        let zy: Vec<f64> = y
            .iter()
            .map(|v| (v - self.y_scale.0) / self.y_scale.1)
            .collect();
        let before = (zu[0], (y_init - self.y_scale.0) / self.y_scale.1);
        let mut e = vec![0.0; u.len()];
        let mut out = vec![0.0; u.len()];
        for t in 0..u.len() {
            let z = self.predict(&zu, &zy, &e, t, before);
            e[t] = zy[t] - z;
            out[t] = z * self.y_scale.1 + self.y_scale.0;
        }
        out
    }

    /// Free run with the history before the first sample at (u[0], `y0`): past outputs fed
    /// back, errors 0.
    pub fn free_run(&self, u: &[f64], y0: f64) -> Vec<f64> {
        let zu: Vec<f64> = u
            .iter()
            .map(|v| (v - self.u_scale.0) / self.u_scale.1)
            .collect();
        let before = (zu[0], (y0 - self.y_scale.0) / self.y_scale.1);
        let mut zy = vec![0.0; u.len()];
        let e = vec![0.0; u.len()];
        let mut out = vec![0.0; u.len()];
        for t in 0..u.len() {
            let z = self.predict(&zu, &zy, &e, t, before);
            zy[t] = z;
            out[t] = z * self.y_scale.1 + self.y_scale.0;
        }
        out
    }
}
