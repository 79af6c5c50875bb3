//! Neural NARMAX forward pass (paper section 3.1; Nørgaard's NNSYSID `nnarmax2` layout).
//!
//! A one-hidden-layer tanh network with a linear output predicts `y(t)` from the regressors
//!
//! ```text
//! φ(t) = [y(t−1) … y(t−na), u(t−nk) … u(t−nk−nb+1), ε(t−1) … ε(t−nc)]
//! ŷ(t) = W2 · [tanh(W1 · [φ(t); 1]); 1]
//! ```
//!
//! all in scaled units (`(x − mean) / std` for u and y, ε = y − ŷ scaled by y's std). `W1` is
//! hidden × (inputs + 1) with the bias last, `W2` is 1 × (hidden + 1) with the bias last, as
//! NNSYSID stores them.
//!
//! Shapes: `N` (regressors) and `H` (hidden units) are const generics that bound the model; the
//! model's own lags are checked against them when it is built. History is kept in fixed-size
//! shift registers: no allocation. This is the generic pass (the host's, any lags); the
//! firmware runs the MCU passes of [`mcu`], built at compile time.
//!
//! Two ways to run it: **free-run simulation** ([`Narmax::simulate_step`]: past model outputs
//! fed back, error inputs zero), and **one-step-ahead prediction** ([`Narmax::predict_step`]:
//! measured past outputs, and past prediction errors when nc > 0). Regressors outside the
//! training range are clamped to it and the result is flagged.

use crate::scalar::Real;

pub mod adapt;
pub mod mcu;

/// Largest input delay `nk` supported.
pub const MAX_NK: usize = 8;

/// Lag structure of a NARMAX model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lags {
    /// Past outputs y(t−1..t−na).
    pub na: usize,
    /// Past inputs u(t−nk..t−nk−nb+1).
    pub nb: usize,
    /// Past prediction errors ε(t−1..t−nc) (0 for NARX).
    pub nc: usize,
    /// Input delay, samples (0..=[`MAX_NK`]; 1 in the paper).
    pub nk: usize,
}

impl Lags {
    /// Number of regressors, na + nb + nc.
    pub const fn inputs(&self) -> usize {
        self.na + self.nb + self.nc
    }

    /// The NNSYSID weight counts of a network with these lags and `hidden` tanh units:
    /// `(W1, W2) = (hidden·(inputs + 1), hidden + 1)` (each row and the output with its bias).
    pub const fn weight_counts(&self, hidden: usize) -> (usize, usize) {
        (hidden * (self.inputs() + 1), hidden + 1)
    }

    /// Samples of history a prediction needs: max(na, nk + nb − 1, nc).
    pub fn max_lag(&self) -> usize {
        self.na
            .max(self.nc)
            .max((self.nk + self.nb).saturating_sub(1))
    }
}

/// Affine scaling `scaled = (x − mean) / std` (NNSYSID `dscale`: zero mean, unit variance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scaling<T> {
    /// Mean, physical units.
    pub mean: T,
    /// Standard deviation, physical units, > 0.
    pub std: T,
}

impl<T: Real> Scaling<T> {
    /// Physical to scaled.
    #[inline]
    pub fn scale(&self, x: T) -> T {
        (x - self.mean) / self.std
    }
    /// Scaled to physical.
    #[inline]
    pub fn unscale(&self, z: T) -> T {
        z * self.std + self.mean
    }
}

/// Why a NARMAX model was refused when built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NarmaxError {
    /// More regressors or hidden units than this build's capacity (`N`, `H`).
    TooLarge,
    /// `W1` or `W2` has the wrong number of values for the lags and hidden width.
    WrongShape,
    /// A weight, scaling or range value is NaN or infinite, a std is ≤ 0, or a range is empty.
    BadValue,
    /// nk > [`MAX_NK`], or no regressor and no hidden unit.
    BadLags,
    /// The MCU passes ([`mcu`]) take NARX models only: nc = 0 and nk ≥ 1.
    NotNarx,
    /// A hidden pre-activation can reach 2^14, or the output layer needs more than 16-bit
    /// mantissas: the model does not fit the Q15 pass ([`mcu::NarxQ15`]).
    FixedRange,
    /// The sample period is not a whole number of milliseconds from 1 to
    /// [`mcu::MAX_PERIOD_MS`] ([`mcu::firmware_period_ms`]).
    Period,
}

impl core::fmt::Display for NarmaxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            NarmaxError::TooLarge => "more regressors or hidden units than this build supports",
            NarmaxError::WrongShape => {
                "weight matrix shapes do not match the lags and hidden width"
            }
            NarmaxError::BadValue => "non-finite weight or scaling, std <= 0, or empty range",
            NarmaxError::BadLags => "lags out of range (nk <= 8, at least one regressor)",
            NarmaxError::NotNarx => "the firmware's passes take NARX models only (nc = 0, nk >= 1)",
            NarmaxError::FixedRange => {
                "a pre-activation or the output is too large for the Q15 pass"
            }
            NarmaxError::Period => {
                "the sample period must be a whole number of milliseconds from 1 to 1000 \
                 (the controller steps every 1 ms)"
            }
        })
    }
}

impl core::error::Error for NarmaxError {}

/// A NARMAX model: weights, scaling and training ranges (immutable configuration).
#[derive(Debug, Clone, PartialEq)]
pub struct Narmax<T, const N: usize, const H: usize> {
    lags: Lags,
    hidden: usize,
    w1: [[T; N]; H],
    b1: [T; H],
    w2: [T; H],
    b2: T,
    u_scale: Scaling<T>,
    y_scale: Scaling<T>,
    /// Training range of u, scaled units.
    u_range: [T; 2],
    /// Training range of y, scaled units.
    y_range: [T; 2],
}

/// The history of a running model (small, `Copy`, owned by the caller).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarmaxState<T, const N: usize> {
    /// y(t−1), y(t−2), … scaled.
    y: [T; N],
    /// u(t−nk), u(t−nk−1), … scaled.
    u: [T; N],
    /// ε(t−1), ε(t−2), … scaled.
    e: [T; N],
    /// u(t), u(t−1), … u(t−nk+1) scaled, waiting for their delay.
    delay: [T; MAX_NK],
}

impl<V: Copy + PartialOrd, const N: usize> NarmaxState<V, N> {
    /// Every past input at `zu`, every past output at `zy`, errors at `zero` (scaled values).
    fn filled(zu: V, zy: V, zero: V) -> Self {
        Self {
            y: [zy; N],
            u: [zu; N],
            e: [zero; N],
            delay: [zu; MAX_NK],
        }
    }

    /// Takes the scaled input u(t): through the nk-sample delay line into the u register.
    fn push_u(&mut self, lags: Lags, z: V) {
        let nk = lags.nk;
        let delayed = if nk == 0 {
            z
        } else {
            let out = self.delay[nk - 1];
            shift_in(&mut self.delay[..nk], z);
            out
        };
        shift_in(&mut self.u[..lags.nb], delayed);
    }

    /// Takes the scaled output y(t) and error ε(t) (after a prediction or a seed).
    fn push_y_e(&mut self, lags: Lags, y: V, e: V) {
        shift_in(&mut self.y[..lags.na], y);
        shift_in(&mut self.e[..lags.nc], e);
    }

    /// The regressor vector, y and u clamped to their training ranges; `true` if any was.
    fn regressors(&self, lags: Lags, u_range: &[V; 2], y_range: &[V; 2], phi: &mut [V; N]) -> bool {
        let Lags { na, nb, nc, .. } = lags;
        let mut clamped = false;
        let mut clamp = |x: V, r: &[V; 2]| {
            if x < r[0] {
                clamped = true;
                r[0]
            } else if x > r[1] {
                clamped = true;
                r[1]
            } else {
                x
            }
        };
        for (p, &y) in phi[..na].iter_mut().zip(&self.y[..na]) {
            *p = clamp(y, y_range);
        }
        for (p, &u) in phi[na..na + nb].iter_mut().zip(&self.u[..nb]) {
            *p = clamp(u, u_range);
        }
        phi[na + nb..na + nb + nc].copy_from_slice(&self.e[..nc]);
        clamped
    }
}

/// One model output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarmaxOutput<T> {
    /// Predicted output, physical units.
    pub y: T,
    /// A regressor was outside the training range and was clamped.
    pub clamped: bool,
}

/// A NARMAX predictor in physical units: the generic pass ([`Narmax`]) and the MCU passes
/// ([`mcu::NarxF32`], [`mcu::NarxQ15`]) implement it, and every user (the controller, pumpbench,
/// the MCU bench, the tests) runs a model through it.
///
/// An implementation gives the one body [`Predictor::step`] (predict ŷ(t) from the past, then
/// store y(t)); the one-step-ahead and free-run steps are that body with and without a
/// measurement, so a caller that does both holds one copy of the network.
pub trait Predictor {
    /// The number type of u (torque reference, %) and y (the output's unit).
    type Value: Real;
    /// A running model's history.
    type State: Clone;

    /// The lags.
    fn lags(&self) -> Lags;

    /// The output's training scaling (mean and standard deviation), physical units.
    fn output_scaling(&self) -> Scaling<Self::Value>;

    /// The output's training mean, physical units (where a history may start).
    #[inline]
    fn output_mean(&self) -> Self::Value {
        self.output_scaling().mean
    }

    /// A history with every past sample at (u, y), physical units (no past errors).
    fn state_at(&self, u: Self::Value, y: Self::Value) -> Self::State;

    /// Puts the measured sample (u(t), y(t)) into the history without predicting: to seed the
    /// first `lags().max_lag()` samples of a run from data.
    fn seed(&self, st: &mut Self::State, u: Self::Value, y: Self::Value);

    /// One step: takes u(t), returns ŷ(t) predicted from the past, then stores y(t): the
    /// measurement if there is one (one-step-ahead; with nc > 0 also the error y − ŷ), ŷ(t)
    /// if not (free run, errors zero).
    fn step(
        &self,
        st: &mut Self::State,
        u: Self::Value,
        y_measured: Option<Self::Value>,
    ) -> NarmaxOutput<Self::Value>;

    /// Free-run step: takes u(t), returns ŷ(t) and feeds it back as the next y(t−1).
    #[inline(always)]
    fn simulate_step(&self, st: &mut Self::State, u: Self::Value) -> NarmaxOutput<Self::Value> {
        self.step(st, u, None)
    }

    /// One-step-ahead step: takes u(t) and the measured y(t), returns ŷ(t) from the past only.
    #[inline(always)]
    fn predict_step(
        &self,
        st: &mut Self::State,
        u: Self::Value,
        y_measured: Self::Value,
    ) -> NarmaxOutput<Self::Value> {
        self.step(st, u, Some(y_measured))
    }

    /// The free-run output settled under a constant input `u`: runs the model from the output
    /// mean until two successive outputs differ by less than `tol` (physical units) for
    /// `max_lag` steps in a row, at most `max_steps` steps. `None` if it does not settle
    /// (oscillating or diverging model). Fixed-point passes may settle more coarsely (see
    /// theirs).
    fn steady_output(
        &self,
        u: Self::Value,
        tol: Self::Value,
        max_steps: usize,
    ) -> Option<Self::Value> {
        let mut st = self.state_at(u, self.output_mean());
        let need = self.lags().max_lag().max(1);
        settle(self.output_mean(), tol, need, max_steps, || {
            self.simulate_step(&mut st, u).y
        })
    }
}

/// Runs `next` until two successive outputs differ by less than `tol` for `need` steps in a
/// row (from `start`), at most `max_steps` times: the settled output, `None` if it does not
/// settle or leaves the finite numbers.
fn settle<T: Real>(
    start: T,
    tol: T,
    need: usize,
    max_steps: usize,
    mut next: impl FnMut() -> T,
) -> Option<T> {
    let (mut last, mut calm) = (start, 0);
    for _ in 0..max_steps {
        let y = next();
        if !y.is_finite() {
            return None;
        }
        if (y - last).abs() < tol {
            calm += 1;
            if calm >= need {
                return Some(y);
            }
        } else {
            calm = 0;
        }
        last = y;
    }
    None
}

fn shift_in<T: Copy>(reg: &mut [T], x: T) {
    if reg.is_empty() {
        return;
    }
    reg.copy_within(0..reg.len() - 1, 1);
    reg[0] = x;
}

impl<T: Real, const N: usize, const H: usize> Narmax<T, N, H> {
    /// Builds a model from NNSYSID-layout weights.
    ///
    /// - `w1`: hidden × (na + nb + nc + 1), row-major, bias last in each row;
    /// - `w2`: hidden + 1, bias last;
    /// - `u_scale`, `u_range`: input (torque reference) scaling and training range, %;
    /// - `y_scale`, `y_range`: output scaling and training range in the output's unit
    ///   (regressors are clamped to the ranges), `[min, max]` with min < max.
    ///
    /// Every value must be finite and both stds > 0.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        lags: Lags,
        hidden: usize,
        w1: &[T],
        w2: &[T],
        u_scale: Scaling<T>,
        y_scale: Scaling<T>,
        u_range: [T; 2],
        y_range: [T; 2],
    ) -> Result<Self, NarmaxError> {
        let shape = (w1.len(), w2.len());
        Self::from_parts(
            lags,
            hidden,
            shape,
            |i| w1[i],
            |i| w2[i],
            [u_scale, y_scale],
            [u_range, y_range],
        )
    }

    /// The generic pass of a model in NNSYSID form (the f64 data `pumpbench export` writes),
    /// every value rounded to `T` once (for f32: the bits the MCU passes start from). The
    /// host's reference and baseline for the MCU passes built from the same data.
    pub fn from_nnsysid(m: &mcu::NnsysidModel) -> Result<Self, NarmaxError> {
        let t = T::from_f64;
        let s = |s: Scaling<f64>| Scaling {
            mean: t(s.mean),
            std: t(s.std),
        };
        let r = |r: [f64; 2]| [t(r[0]), t(r[1])];
        Self::from_parts(
            m.lags,
            m.hidden,
            (m.w1.len(), m.w2.len()),
            |i| t(m.w1[i]),
            |i| t(m.w2[i]),
            [s(m.u_scale), s(m.y_scale)],
            [r(m.u_range), r(m.y_range)],
        )
    }

    /// [`Self::new`] with the weights read through `w1(i)`, `w2(i)` (`shape`: their lengths).
    fn from_parts(
        lags: Lags,
        hidden: usize,
        shape: (usize, usize),
        w1: impl Fn(usize) -> T,
        w2: impl Fn(usize) -> T,
        [u_scale, y_scale]: [Scaling<T>; 2],
        [u_range, y_range]: [[T; 2]; 2],
    ) -> Result<Self, NarmaxError> {
        let n = lags.inputs();
        if lags.nk > MAX_NK || n == 0 || hidden == 0 {
            return Err(NarmaxError::BadLags);
        }
        if n > N || hidden > H || lags.na > N || lags.nb > N || lags.nc > N {
            return Err(NarmaxError::TooLarge);
        }
        if shape != lags.weight_counts(hidden) {
            return Err(NarmaxError::WrongShape);
        }
        let finite = (0..shape.0)
            .map(&w1)
            .chain((0..shape.1).map(&w2))
            .chain([u_scale.mean, u_scale.std, y_scale.mean, y_scale.std])
            .chain(u_range)
            .chain(y_range)
            .all(|x| x.is_finite());
        if !finite
            || !(u_scale.std > T::ZERO)
            || !(y_scale.std > T::ZERO)
            || !(u_range[0] < u_range[1])
            || !(y_range[0] < y_range[1])
        {
            return Err(NarmaxError::BadValue);
        }
        let mut m = Self {
            lags,
            hidden,
            w1: [[T::ZERO; N]; H],
            b1: [T::ZERO; H],
            w2: [T::ZERO; H],
            b2: w2(hidden),
            u_scale,
            y_scale,
            u_range: [u_scale.scale(u_range[0]), u_scale.scale(u_range[1])],
            y_range: [y_scale.scale(y_range[0]), y_scale.scale(y_range[1])],
        };
        for j in 0..hidden {
            let row = j * (n + 1);
            for i in 0..n {
                m.w1[j][i] = w1(row + i);
            }
            m.b1[j] = w1(row + n);
            m.w2[j] = w2(j);
        }
        Ok(m)
    }

    /// Hidden units.
    pub fn hidden(&self) -> usize {
        self.hidden
    }

    /// Network output (scaled) for a regressor vector φ (scaled, `lags().inputs()` long).
    #[inline]
    pub fn network(&self, phi: &[T]) -> T {
        let n = self.lags.inputs().min(phi.len());
        let mut out = self.b2;
        for j in 0..self.hidden {
            let mut acc = self.b1[j];
            for (w, x) in self.w1[j][..n].iter().zip(&phi[..n]) {
                acc += *w * *x;
            }
            out += self.w2[j] * acc.tanh();
        }
        out
    }

    /// Takes u(t), returns the network's scaled ŷ(t) and the clamp flag.
    fn predict_scaled(&self, st: &mut NarmaxState<T, N>, u: T) -> (T, bool) {
        st.push_u(self.lags, self.u_scale.scale(u));
        let mut phi = [T::ZERO; N];
        let clamped = st.regressors(self.lags, &self.u_range, &self.y_range, &mut phi);
        (self.network(&phi), clamped)
    }
}

impl<T: Real, const N: usize, const H: usize> Predictor for Narmax<T, N, H> {
    type Value = T;
    type State = NarmaxState<T, N>;

    fn lags(&self) -> Lags {
        self.lags
    }

    fn output_scaling(&self) -> Scaling<T> {
        self.y_scale
    }

    /// Every past value at the scaled point of `u`, `y`, no errors.
    fn state_at(&self, u: T, y: T) -> NarmaxState<T, N> {
        NarmaxState::filled(self.u_scale.scale(u), self.y_scale.scale(y), T::ZERO)
    }

    fn seed(&self, st: &mut NarmaxState<T, N>, u: T, y: T) {
        st.push_u(self.lags, self.u_scale.scale(u));
        st.push_y_e(self.lags, self.y_scale.scale(y), T::ZERO);
    }

    /// Free run: ŷ(t) is fed back as the next y(t−1), error regressors zero; one-step-ahead:
    /// stores y(t) and ε(t) = y(t) − ŷ(t).
    fn step(&self, st: &mut NarmaxState<T, N>, u: T, y_measured: Option<T>) -> NarmaxOutput<T> {
        let (z, clamped) = self.predict_scaled(st, u);
        match y_measured {
            Some(y) => {
                let zy = self.y_scale.scale(y);
                st.push_y_e(self.lags, zy, zy - z);
            }
            None => st.push_y_e(self.lags, z, T::ZERO),
        }
        NarmaxOutput {
            y: self.y_scale.unscale(z),
            clamped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_nnsysid_is_new_with_every_value_rounded_once() {
        let lags = Lags {
            na: 2,
            nb: 2,
            nc: 0,
            nk: 1,
        };
        let w1: Vec<f64> = (0..3 * 5).map(|i| 0.8 * (0.37 * i as f64).sin()).collect();
        let w2 = [0.3, -0.2, 0.5, 0.1];
        let m = mcu::NnsysidModel {
            lags,
            hidden: 3,
            w1: &w1,
            w2: &w2,
            u_scale: Scaling {
                mean: 45.1,
                std: 23.3,
            },
            y_scale: Scaling {
                mean: 2.1,
                std: 0.51,
            },
            u_range: [5.2, 85.3],
            y_range: [0.55, 3.45],
        };
        let f = |x: &[f64]| x.iter().map(|&v| v as f32).collect::<Vec<f32>>();
        let s = |s: Scaling<f64>| Scaling {
            mean: s.mean as f32,
            std: s.std as f32,
        };
        let r = |r: [f64; 2]| [r[0] as f32, r[1] as f32];
        let by_new = Narmax::<f32, 8, 4>::new(
            lags,
            3,
            &f(&w1),
            &f(&w2),
            s(m.u_scale),
            s(m.y_scale),
            r(m.u_range),
            r(m.y_range),
        );
        assert_eq!(Narmax::<f32, 8, 4>::from_nnsysid(&m), by_new);
        assert!(by_new.is_ok());
        // The same checks as `new`.
        let short = mcu::NnsysidModel { w2: &w2[..3], ..m };
        assert_eq!(
            Narmax::<f32, 8, 4>::from_nnsysid(&short),
            Err(NarmaxError::WrongShape)
        );
        let nan = [f64::NAN, 0.0, 0.0, 0.0];
        let bad = mcu::NnsysidModel { w2: &nan, ..m };
        assert_eq!(
            Narmax::<f32, 8, 4>::from_nnsysid(&bad),
            Err(NarmaxError::BadValue)
        );
    }

    const UNIT: Scaling<f64> = Scaling {
        mean: 0.0,
        std: 1.0,
    };
    const WIDE: [f64; 2] = [-1e6, 1e6];

    /// A model whose hidden unit j sees regressor j only, with a small gain (tanh ≈ linear
    /// is not needed: we invert it), so the output reveals the regressor vector.
    fn probe(lags: Lags, pick: usize) -> Narmax<f64, 16, 4> {
        let n = lags.inputs();
        let mut w1 = vec![0.0; n + 1];
        w1[pick] = 1e-3;
        Narmax::new(lags, 1, &w1, &[1.0, 0.0], UNIT, UNIT, WIDE, WIDE).unwrap()
    }

    fn seen(_m: &Narmax<f64, 16, 4>, y: f64) -> f64 {
        libm::atanh(y) / 1e-3
    }

    #[test]
    fn regressors_follow_nnsysid_order_and_delay() {
        let lags = Lags {
            na: 2,
            nb: 3,
            nc: 1,
            nk: 2,
        };
        assert_eq!(lags.max_lag(), 4);
        // Input regressor i (0-based within u) at time t must be u(t − nk − i).
        for i in 0..3 {
            let m = probe(lags, 2 + i);
            let mut st = m.state_at(0.0, 0.0);
            let mut out = 0.0;
            for t in 0..10 {
                out = seen(&m, m.predict_step(&mut st, t as f64, 0.0).y);
            }
            assert!((out - (9 - 2 - i) as f64).abs() < 1e-6, "u lag {i}: {out}");
        }
        // Output regressor i at time t is y(t − 1 − i); error regressor is ε(t − 1).
        let m = probe(lags, 1);
        let mut st = m.state_at(0.0, 0.0);
        for t in 0..6 {
            m.predict_step(&mut st, 0.0, 100.0 + t as f64);
        }
        let y = seen(&m, m.predict_step(&mut st, 0.0, 0.0).y);
        assert!((y - 104.0).abs() < 1e-6, "y(t-2) = {y}");
        let m = probe(lags, 5);
        let mut st = m.state_at(0.0, 0.0);
        let first = m.predict_step(&mut st, 0.0, 7.0).y; // ε(t) = 7 − ŷ
        let e = seen(&m, m.predict_step(&mut st, 0.0, 0.0).y);
        assert!((e - (7.0 - first)).abs() < 1e-6, "ε(t-1) = {e}");
    }

    #[test]
    fn nk_zero_uses_the_current_input() {
        let m = probe(
            Lags {
                na: 0,
                nb: 1,
                nc: 0,
                nk: 0,
            },
            0,
        );
        let mut st = m.state_at(0.0, 0.0);
        assert!((seen(&m, m.simulate_step(&mut st, 3.0).y) - 3.0).abs() < 1e-6);
    }

    #[test]
    fn free_run_feeds_back_and_clamps() {
        // y(t) = 0.5 tanh(y(t−1)·1) + u-free bias: settles at the fixed point.
        let lags = Lags {
            na: 1,
            nb: 1,
            nc: 0,
            nk: 1,
        };
        let m: Narmax<f64, 4, 2> = Narmax::new(
            lags,
            1,
            &[1.0, 0.0, 0.0],
            &[0.5, 0.2],
            UNIT,
            UNIT,
            [-1.0, 1.0],
            [-1.0, 1.0],
        )
        .unwrap();
        let y = m.steady_output(0.0, 1e-12, 1000).unwrap();
        assert!((y - (0.5 * libm::tanh(y) + 0.2)).abs() < 1e-10);
        let mut st = m.state_at(5.0, 0.0);
        assert!(
            m.simulate_step(&mut st, 5.0).clamped,
            "u = 5 outside [-1, 1]"
        );
    }

    #[test]
    fn bad_models_are_refused_when_built() {
        let lags = Lags {
            na: 2,
            nb: 2,
            nc: 0,
            nk: 1,
        };
        let w1 = [0.1; 2 * 5];
        let w2 = [0.1; 3];
        let ok = |w1: &[f64], w2: &[f64], s: Scaling<f64>, r: [f64; 2]| {
            Narmax::<f64, 4, 2>::new(lags, 2, w1, w2, s, UNIT, r, WIDE).map(|_| ())
        };
        assert_eq!(ok(&w1, &w2, UNIT, WIDE), Ok(()));
        assert_eq!(ok(&w1[..9], &w2, UNIT, WIDE), Err(NarmaxError::WrongShape));
        assert_eq!(ok(&w1, &w2[..2], UNIT, WIDE), Err(NarmaxError::WrongShape));
        let mut nan = w1;
        nan[3] = f64::NAN;
        assert_eq!(ok(&nan, &w2, UNIT, WIDE), Err(NarmaxError::BadValue));
        assert_eq!(
            ok(
                &w1,
                &w2,
                Scaling {
                    mean: 0.0,
                    std: 0.0
                },
                WIDE
            ),
            Err(NarmaxError::BadValue)
        );
        assert_eq!(ok(&w1, &w2, UNIT, [1.0, 1.0]), Err(NarmaxError::BadValue));
        let big = Lags {
            na: 3,
            nb: 2,
            nc: 0,
            nk: 1,
        };
        assert_eq!(
            Narmax::<f64, 4, 2>::new(big, 2, &[0.0; 12], &w2, UNIT, UNIT, WIDE, WIDE).map(|_| ()),
            Err(NarmaxError::TooLarge)
        );
        let far = Lags { nk: 9, ..lags };
        assert_eq!(
            Narmax::<f64, 4, 2>::new(far, 2, &w1, &w2, UNIT, UNIT, WIDE, WIDE).map(|_| ()),
            Err(NarmaxError::BadLags)
        );
    }
}
