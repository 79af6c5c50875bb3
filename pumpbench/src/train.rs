//! Levenberg-Marquardt training of a one-hidden-layer tanh network as a NARX/NARMAX
//! predictor, following NNSYSID 2.0 (`nnarx`/`marq.m`, `nnarmax2.m`) step for step:
//!
//! - criterion `PI = SSE / (2N)` over the N = Ndat − max-lag targets;
//! - search direction `h = (R + λI)⁻¹ G` with `R = ΨΨᵀ`, `G = ΨE` (Ψ = ∂ŷ/∂θ, E = y − ŷ);
//! - predicted decrease `L = hᵀG + λ hᵀh`; λ halves when the actual decrease `2N(PI − PI_new)`
//!   exceeds 0.75 L and doubles when it is at most 0.25 L (every trial); a trial is accepted
//!   when `PI_new < PI`, and only accepted trials count as epochs;
//! - stop after `epochs` accepted steps, at λ ≥ 1e7, or when the criterion, gradient and
//!   parameter changes are all below NNSYSID's defaults (1e-7, 1e-4, 1e-3);
//! - initial weights uniform in [−0.5, 0.5), λ = 1;
//! - with nc > 0 (NARMAX), the ε regressors are the model's own past residuals, computed
//!   sample by sample, and Ψ is the recurrent gradient: `ψ(t) = ρ(t) − Σ_d ∂ŷ(t)/∂ε(t−d) ψ(t−d)`;
//!   the network first trains as NARX (≤ 100 epochs) and the ε weights start uniform in
//!   [−0.025, 0.025), as `nnarmax2` does.
//!
//! The LM loop is written here rather than taken from the `levenberg-marquardt` crate: that
//! crate's trust-region updates differ from NNSYSID's λ rules, which the paper's results rest
//! on. Its Jacobian is checked against finite differences in the tests.

// Index loops over several parallel arrays (φ, W1 rows, y1, Ψ) read like the equations.
#![allow(clippy::needless_range_loop)]

use model_core::excitation::SplitMix64;
use model_core::narmax::Lags;
use nalgebra::{DMatrix, DVector};

/// Network and lag structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Structure {
    /// Output lags.
    pub na: usize,
    /// Input lags.
    pub nb: usize,
    /// Error lags (0: NARX).
    pub nc: usize,
    /// Input delay.
    pub nk: usize,
    /// Hidden tanh units.
    pub hidden: usize,
}

impl Structure {
    /// The lags, as the models take them.
    pub fn lags(&self) -> Lags {
        Lags {
            na: self.na,
            nb: self.nb,
            nc: self.nc,
            nk: self.nk,
        }
    }
    /// Regressors per sample ([`Lags::inputs`]).
    pub fn inputs(&self) -> usize {
        self.lags().inputs()
    }
    /// Samples of history needed ([`Lags::max_lag`]).
    pub fn max_lag(&self) -> usize {
        self.lags().max_lag()
    }
    /// Weights: hidden·(inputs + 1) + hidden + 1 ([`Lags::weight_counts`]).
    pub fn params(&self) -> usize {
        let (w1, w2) = self.lags().weight_counts(self.hidden);
        w1 + w2
    }
}

/// Weights in NNSYSID layout: `w1` hidden × (inputs + 1) row-major, bias last; `w2` hidden + 1,
/// bias last. θ = [w2; w1] as in NNSYSID.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    /// Hidden layer, row-major, bias last in each row.
    pub w1: Vec<f64>,
    /// Output layer, bias last.
    pub w2: Vec<f64>,
}

impl Weights {
    fn theta(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.w2.len() + self.w1.len(),
            self.w2.iter().chain(&self.w1).copied(),
        )
    }
    fn from_theta(s: &Structure, theta: &DVector<f64>) -> Self {
        let n2 = s.lags().weight_counts(s.hidden).1;
        Weights {
            w2: theta.as_slice()[..n2].to_vec(),
            w1: theta.as_slice()[n2..].to_vec(),
        }
    }
    /// Uniform in [−0.5, 0.5) (NNSYSID's `rand − 0.5`).
    pub fn random(s: &Structure, rng: &mut SplitMix64) -> Self {
        Weights {
            w1: (0..s.lags().weight_counts(s.hidden).0)
                .map(|_| rng.next_f64() - 0.5)
                .collect(),
            w2: (0..s.lags().weight_counts(s.hidden).1)
                .map(|_| rng.next_f64() - 0.5)
                .collect(),
        }
    }
}

/// Scaled training data: u and y, same length.
pub struct Data<'a> {
    /// Input, scaled.
    pub u: &'a [f64],
    /// Output, scaled.
    pub y: &'a [f64],
}

/// Result of a forward pass over the data.
struct Pass {
    /// Residuals E(t) = y − ŷ for t = max_lag..Ndat.
    e: Vec<f64>,
    /// Ψ (N × params), if asked for.
    psi: Option<DMatrix<f64>>,
}

/// Runs the one-step-ahead predictor over the data (ε regressors from the model's own
/// residuals, as in training); returns residuals and, if `jacobian`, Ψ = ∂ŷ/∂θ (recurrent).
fn pass(s: &Structure, w: &Weights, d: &Data, jacobian: bool) -> Pass {
    let (na, nb, nc, nk, hd) = (s.na, s.nb, s.nc, s.nk, s.hidden);
    let n_in = s.inputs();
    let m = s.max_lag();
    let n = d.y.len() - m;
    let p = s.params();
    let mut e = vec![0.0; n];
    let mut psi = jacobian.then(|| DMatrix::<f64>::zeros(n, p));
    let mut phi = vec![0.0; n_in];
    let mut y1 = vec![0.0; hd];
    let mut dyde = vec![0.0; nc];
    let mut row = vec![0.0; p];
    for k in 0..n {
        let t = k + m;
        for i in 0..na {
            phi[i] = d.y[t - 1 - i];
        }
        for i in 0..nb {
            phi[na + i] = d.u[t - nk - i];
        }
        for i in 0..nc {
            // ε(t−1−i): residuals before the first target are 0.
            phi[na + nb + i] = if k > i { e[k - 1 - i] } else { 0.0 };
        }
        let mut yhat = w.w2[hd];
        for j in 0..hd {
            let r = &w.w1[j * (n_in + 1)..(j + 1) * (n_in + 1)];
            let a = r[n_in] + r[..n_in].iter().zip(&phi).map(|(a, b)| a * b).sum::<f64>();
            y1[j] = a.tanh();
            yhat += w.w2[j] * y1[j];
        }
        e[k] = d.y[t] - yhat;
        if let Some(psi) = psi.as_mut() {
            // ρ(t): ∂ŷ/∂W2 = [y1; 1]; ∂ŷ/∂W1[j, i] = W2[j](1 − y1[j]²)[φ; 1][i].
            row[..hd].copy_from_slice(&y1);
            row[hd] = 1.0;
            for j in 0..hd {
                let g = w.w2[j] * (1.0 - y1[j] * y1[j]);
                let base = hd + 1 + j * (n_in + 1);
                for i in 0..n_in {
                    row[base + i] = g * phi[i];
                }
                row[base + n_in] = g;
            }
            // Recurrent correction: ψ(t) = ρ(t) − Σ_d ∂ŷ(t)/∂ε(t−d) · ψ(t−d).
            for (dd, v) in dyde.iter_mut().enumerate() {
                *v = (0..hd)
                    .map(|j| w.w2[j] * (1.0 - y1[j] * y1[j]) * w.w1[j * (n_in + 1) + na + nb + dd])
                    .sum();
            }
            for (dd, &v) in dyde.iter().enumerate() {
                if k > dd {
                    for c in 0..p {
                        row[c] -= v * psi[(k - 1 - dd, c)];
                    }
                }
            }
            for c in 0..p {
                psi[(k, c)] = row[c];
            }
        }
    }
    Pass { e, psi }
}

/// One accepted epoch, as reported to the progress callback.
#[derive(Debug, Clone, Copy)]
pub struct Epoch {
    /// Accepted steps so far.
    pub epoch: usize,
    /// Criterion SSE/(2N) after it, scaled units.
    pub criterion: f64,
    /// λ after it.
    pub lambda: f64,
}

/// Outcome of training.
pub struct Trained {
    /// Final weights (scaled units).
    pub weights: Weights,
    /// Criterion before training and after each accepted epoch.
    pub criterion: Vec<f64>,
    /// Final λ.
    pub lambda: f64,
    /// Why it stopped.
    pub stop: &'static str,
}

/// NNSYSID's LM loop from `w0` for at most `epochs` accepted steps, starting at `lambda0`
/// (NNSYSID: 1).
pub fn marquardt(
    s: &Structure,
    w0: Weights,
    d: &Data,
    epochs: usize,
    lambda0: f64,
    mut progress: impl FnMut(Epoch),
) -> Trained {
    const CRITTERM: f64 = 1e-7;
    const GRADTERM: f64 = 1e-4;
    const PARAMTERM: f64 = 1e-3;
    let mut theta = w0.theta();
    let p = theta.len();
    let mut w = w0;
    let mut lambda = lambda0;
    let mut first = pass(s, &w, d, true);
    let n = first.e.len() as f64;
    let mut pi = first.e.iter().map(|x| x * x).sum::<f64>() / (2.0 * n);
    let mut history = vec![pi];
    let mut epoch = 0;
    let (mut critdif, mut gradmax, mut paramdif) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut rg: Option<(DMatrix<f64>, DVector<f64>)> = None;
    let stop = loop {
        if epoch >= epochs {
            break "epochs";
        }
        if lambda >= 1e7 {
            break "lambda >= 1e7";
        }
        if critdif <= CRITTERM && gradmax <= GRADTERM && paramdif <= PARAMTERM {
            break "converged";
        }
        if rg.is_none() {
            let psi = first
                .psi
                .take()
                .unwrap_or_else(|| pass(s, &w, d, true).psi.unwrap_or_default());
            let e = DVector::from_column_slice(&first.e);
            let g = psi.tr_mul(&e);
            let r = psi.transpose() * &psi;
            rg = Some((r, g));
        }
        let Some((r, g)) = rg.as_ref() else {
            break "internal";
        };
        let mut a = r.clone();
        for i in 0..p {
            a[(i, i)] += lambda;
        }
        let Some(chol) = a.cholesky() else {
            lambda *= 2.0;
            continue;
        };
        let h = chol.solve(g);
        let theta_new = &theta + &h;
        let w_new = Weights::from_theta(s, &theta_new);
        let trial = pass(s, &w_new, d, false);
        let pi_new = trial.e.iter().map(|x| x * x).sum::<f64>() / (2.0 * n);
        let l = h.dot(g) + lambda * h.dot(&h);
        let actual = 2.0 * n * (pi - pi_new);
        if actual > 0.75 * l {
            lambda /= 2.0;
        } else if actual <= 0.25 * l {
            lambda *= 2.0;
        }
        if pi_new < pi {
            critdif = pi - pi_new;
            gradmax = g.amax() / n;
            paramdif = h.amax();
            theta = theta_new;
            w = w_new;
            pi = pi_new;
            first = trial;
            rg = None;
            epoch += 1;
            history.push(pi);
            progress(Epoch {
                epoch,
                criterion: pi,
                lambda,
            });
        }
    };
    Trained {
        weights: w,
        criterion: history,
        lambda,
        stop,
    }
}

/// Accepted epochs of the first selection round.
pub const ROUND_EPOCHS: usize = 10;

/// Continues `t` to `target` accepted epochs in all (no-op if it has them or has stopped).
fn continue_to(
    s: &Structure,
    d: &Data,
    t: Trained,
    target: usize,
    progress: impl FnMut(Epoch),
) -> Trained {
    let done = t.criterion.len() - 1;
    if done >= target || t.stop != "epochs" && done > 0 {
        return t;
    }
    let mut progress = progress;
    let more = marquardt(s, t.weights, d, target - done, t.lambda, |e| {
        progress(Epoch {
            epoch: e.epoch + done,
            ..e
        })
    });
    let mut criterion = t.criterion;
    criterion.extend_from_slice(&more.criterion[1..]);
    Trained { criterion, ..more }
}

fn final_criterion(t: &Trained) -> f64 {
    t.criterion.last().copied().unwrap_or(f64::INFINITY)
}

/// Candidates trained to the full epochs (in parallel); with more starts than this, a first
/// round of [`ROUND_EPOCHS`] picks them.
pub const FINALISTS: usize = 4;

/// Trains `pool` in parallel, each to `target` accepted epochs.
fn train_all(s: &Structure, d: &Data, pool: Vec<Trained>, target: usize) -> Vec<Trained> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = pool
            .into_iter()
            .map(|t| scope.spawn(move || continue_to(s, d, fresh(s, d, t), target, |_| {})))
            .collect();
        handles.into_iter().filter_map(|h| h.join().ok()).collect()
    })
}

/// Trains from `starts` seeded random weight sets (seeds `seed`, `seed + 1`, …), choosing on
/// the **training** criterion only: all train [`ROUND_EPOCHS`] accepted epochs (in parallel),
/// the best [`FINALISTS`] continue to `epochs` (in parallel), and the lowest final criterion
/// wins. λ carries over between rounds, so each network's LM run is one continuous NNSYSID
/// run; `starts = 1` is NNSYSID's single random start. The progress of the winner is reported
/// when it is known.
fn select_and_train(
    s: &Structure,
    d: &Data,
    seed: u64,
    starts: usize,
    epochs: usize,
    mut progress: impl FnMut(Epoch),
) -> Trained {
    let pool: Vec<Trained> = (0..starts.max(1) as u64)
        .map(|k| Trained {
            weights: Weights::random(s, &mut SplitMix64::new(seed.wrapping_add(k))),
            criterion: vec![f64::INFINITY],
            lambda: 1.0,
            stop: "epochs",
        })
        .collect();
    let mut pool = if pool.len() > FINALISTS {
        let mut first = train_all(s, d, pool, ROUND_EPOCHS.min(epochs));
        first.sort_by(|a, b| final_criterion(a).total_cmp(&final_criterion(b)));
        first.truncate(FINALISTS);
        first
    } else {
        pool
    };
    pool = train_all(s, d, pool, epochs);
    pool.sort_by(|a, b| final_criterion(a).total_cmp(&final_criterion(b)));
    let Some(best) = pool.into_iter().next() else {
        return marquardt(
            s,
            Weights::random(s, &mut SplitMix64::new(seed)),
            d,
            epochs,
            1.0,
            progress,
        );
    };
    for (i, &c) in best.criterion.iter().enumerate().skip(1) {
        progress(Epoch {
            epoch: i,
            criterion: c,
            lambda: best.lambda,
        });
    }
    best
}

/// A start that has not trained yet gets its initial criterion (one LM call with 0 epochs).
fn fresh(s: &Structure, d: &Data, t: Trained) -> Trained {
    if t.criterion.len() == 1 && t.criterion[0].is_infinite() {
        marquardt(s, t.weights, d, 0, t.lambda, |_| {})
    } else {
        t
    }
}

/// Trains a network (see [`select_and_train`]); with nc > 0 as `nnarmax2`: NARX first (at
/// most 100 epochs), then the ε columns added with small random weights and LM from λ = 1.
pub fn identify(
    s: &Structure,
    d: &Data,
    epochs: usize,
    seed: u64,
    starts: usize,
    progress: impl FnMut(Epoch),
) -> Trained {
    if s.nc == 0 {
        return select_and_train(s, d, seed, starts, epochs, progress);
    }
    let mut rng = SplitMix64::new(seed.wrapping_add(starts as u64));
    let narx = Structure { nc: 0, ..*s };
    let start = select_and_train(&narx, d, seed, starts, 100, |_| {});
    let nab = s.na + s.nb;
    let mut w1 = Vec::with_capacity(s.lags().weight_counts(s.hidden).0);
    for j in 0..s.hidden {
        let r = &start.weights.w1[j * (nab + 1)..(j + 1) * (nab + 1)];
        w1.extend_from_slice(&r[..nab]);
        w1.extend((0..s.nc).map(|_| 0.05 * rng.next_f64() - 0.025));
        w1.push(r[nab]);
    }
    let w0 = Weights {
        w1,
        w2: start.weights.w2,
    };
    marquardt(s, w0, d, epochs, 1.0, progress)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy(s: &Structure, n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = SplitMix64::new(seed);
        let u: Vec<f64> = (0..n).map(|_| 2.0 * rng.next_f64() - 1.0).collect();
        let mut y = vec![0.0; n];
        for t in 1..n {
            y[t] = 0.6 * y[t - 1] + (0.8 * u[t - 1]).tanh() + 0.05 * (rng.next_f64() - 0.5);
        }
        let _ = s;
        (u, y)
    }

    /// Ψ from `pass` equals the finite-difference derivative of ŷ = y − E, for NARX and for
    /// NARMAX (where ŷ depends on θ through the fed-back residuals too).
    #[test]
    fn jacobian_matches_finite_differences() {
        for s in [
            Structure {
                na: 2,
                nb: 2,
                nc: 0,
                nk: 1,
                hidden: 3,
            },
            Structure {
                na: 2,
                nb: 2,
                nc: 2,
                nk: 1,
                hidden: 3,
            },
        ] {
            let (u, y) = toy(&s, 60, 3);
            let d = Data { u: &u, y: &y };
            let w = Weights::random(&s, &mut SplitMix64::new(5));
            let psi = pass(&s, &w, &d, true).psi.unwrap();
            let theta = w.theta();
            let mut worst: f64 = 0.0;
            for c in 0..theta.len() {
                let step = 1e-6;
                let mut tp = theta.clone();
                tp[c] += step;
                let mut tm = theta.clone();
                tm[c] -= step;
                let ep = pass(&s, &Weights::from_theta(&s, &tp), &d, false).e;
                let em = pass(&s, &Weights::from_theta(&s, &tm), &d, false).e;
                for k in 0..ep.len() {
                    let numeric = -(ep[k] - em[k]) / (2.0 * step);
                    worst = worst.max((numeric - psi[(k, c)]).abs());
                }
            }
            assert!(
                worst < 1e-7,
                "{s:?}: max |Ψ − finite difference| = {worst:e}"
            );
        }
    }

    #[test]
    fn lm_decreases_the_criterion_and_counts_accepted_steps() {
        let s = Structure {
            na: 1,
            nb: 1,
            nc: 0,
            nk: 1,
            hidden: 3,
        };
        let (u, y) = toy(&s, 400, 1);
        let d = Data { u: &u, y: &y };
        let mut seen = vec![];
        let t = identify(&s, &d, 15, 2, 3, |e| seen.push(e.epoch));
        assert!(t.criterion.windows(2).all(|w| w[1] < w[0]));
        assert_eq!(seen, (1..t.criterion.len()).collect::<Vec<_>>());
        assert!(t.criterion.last().unwrap() < &(0.2 * t.criterion[0]));
    }
}
