//! The plain NARMAX free-run step in f32 with `libm::tanhf`: the baseline row of the bench.
//!
//! A frozen copy of what model-core's generic `Narmax<f32, N, H>::simulate_step` computes
//! today (scale u, delay line, regressors clamped to the training range, one hidden tanh
//! layer, linear output, output fed back), written out plainly and kept here, so that the
//! bench compares every faster kernel with the same plain pass whatever model-core becomes.
//! The bench checks that it agrees with model-core's f32 step on its inputs.

use model_core::narmax::{Lags, Scaling, MAX_NK};

/// A NARMAX model in plain f32 arrays (`N` regressor slots, exactly `H` hidden units).
#[derive(Debug, Clone)]
pub struct PlainNarmax<const N: usize, const H: usize> {
    lags: Lags,
    w1: [[f32; N]; H],
    b1: [f32; H],
    w2: [f32; H],
    b2: f32,
    u_scale: Scaling<f32>,
    y_scale: Scaling<f32>,
    /// Training ranges, scaled.
    u_range: [f32; 2],
    y_range: [f32; 2],
}

/// The history of a running [`PlainNarmax`] (scaled values).
#[derive(Debug, Clone, Copy)]
pub struct PlainState<const N: usize> {
    y: [f32; N],
    u: [f32; N],
    delay: [f32; MAX_NK],
}

fn shift_in(reg: &mut [f32], x: f32) {
    if let Some(last) = reg.len().checked_sub(1) {
        reg.copy_within(0..last, 1);
        reg[0] = x;
    }
}

fn clamp(x: f32, r: &[f32; 2], clamped: &mut bool) -> f32 {
    if x < r[0] {
        *clamped = true;
        r[0]
    } else if x > r[1] {
        *clamped = true;
        r[1]
    } else {
        x
    }
}

impl<const N: usize, const H: usize> PlainNarmax<N, H> {
    /// From the exported model's constants (`W1`: H rows of na + nb + nc + 1, bias last;
    /// `W2`: H + 1, bias last; ranges in physical units). `None` if the shapes do not fit.
    pub fn new(
        lags: Lags,
        w1: &[f32],
        w2: &[f32],
        u_scale: Scaling<f32>,
        y_scale: Scaling<f32>,
        u_range: [f32; 2],
        y_range: [f32; 2],
    ) -> Option<Self> {
        let n = lags.inputs();
        if n > N || lags.nk > MAX_NK || w1.len() != H * (n + 1) || w2.len() != H + 1 {
            return None;
        }
        let scale = |s: &Scaling<f32>, x: f32| (x - s.mean) / s.std;
        let mut m = Self {
            lags,
            w1: [[0.0; N]; H],
            b1: [0.0; H],
            w2: [0.0; H],
            b2: w2[H],
            u_scale,
            y_scale,
            u_range: [scale(&u_scale, u_range[0]), scale(&u_scale, u_range[1])],
            y_range: [scale(&y_scale, y_range[0]), scale(&y_scale, y_range[1])],
        };
        for j in 0..H {
            let row = &w1[j * (n + 1)..(j + 1) * (n + 1)];
            m.w1[j][..n].copy_from_slice(&row[..n]);
            m.b1[j] = row[n];
            m.w2[j] = w2[j];
        }
        Some(m)
    }

    /// Every past input at `u`, every past output at `y` (physical units).
    pub fn state_at(&self, u: f32, y: f32) -> PlainState<N> {
        let zu = (u - self.u_scale.mean) / self.u_scale.std;
        let zy = (y - self.y_scale.mean) / self.y_scale.std;
        PlainState {
            y: [zy; N],
            u: [zu; N],
            delay: [zu; MAX_NK],
        }
    }

    /// Free-run step: takes u(t) (physical), returns ŷ(t) (physical) and whether a regressor
    /// was clamped, and feeds ŷ(t) back as the next y(t−1); error regressors are zero.
    // Indexed loops on purpose: the baseline is the plain pass.
    #[allow(clippy::needless_range_loop)]
    pub fn simulate_step(&self, st: &mut PlainState<N>, u: f32) -> (f32, bool) {
        let Lags { na, nb, nc, nk } = self.lags;
        let z = (u - self.u_scale.mean) / self.u_scale.std;
        let delayed = if nk == 0 {
            z
        } else {
            let out = st.delay[nk - 1];
            shift_in(&mut st.delay[..nk], z);
            out
        };
        shift_in(&mut st.u[..nb], delayed);
        let mut clamped = false;
        let mut phi = [0.0f32; N];
        for i in 0..na {
            phi[i] = clamp(st.y[i], &self.y_range, &mut clamped);
        }
        for i in 0..nb {
            phi[na + i] = clamp(st.u[i], &self.u_range, &mut clamped);
        }
        let n = na + nb + nc;
        let mut out = self.b2;
        for j in 0..H {
            let mut acc = self.b1[j];
            for i in 0..n {
                acc += self.w1[j][i] * phi[i];
            }
            out += self.w2[j] * libm::tanhf(acc);
        }
        shift_in(&mut st.y[..na], out);
        (out * self.y_scale.std + self.y_scale.mean, clamped)
    }
}

/// The plain pass of one of [`crate::models`] (`plain_model!(pressure)`), `None` if its
/// shapes do not fit.
#[macro_export]
macro_rules! plain_model {
    ($m:ident) => {{
        use model_core::narmax::{mcu::to_f32, Scaling};
        use $crate::models::$m as m;
        let s = |s: Scaling<f64>| Scaling {
            mean: s.mean as f32,
            std: s.std as f32,
        };
        let r = |r: [f64; 2]| [r[0] as f32, r[1] as f32];
        $crate::plain::PlainNarmax::<{ m::INPUTS }, { m::HIDDEN }>::new(
            m::LAGS,
            &to_f32(&m::W1),
            &to_f32(&m::W2),
            s(m::U_SCALING),
            s(m::Y_SCALING),
            r(m::U_RANGE),
            r(m::Y_RANGE),
        )
    }};
}
