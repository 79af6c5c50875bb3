//! The f32 pass: one multiply-accumulate per weight in frame order, then [`tanh_f32`].

use super::tanh::tanh_f32;
use super::{build_error, NnsysidModel, Ring};
use crate::narmax::{Lags, NarmaxError, NarmaxOutput, Predictor, Scaling};

/// The f32 MCU pass (see the module docs): `F` frames of history, `H` hidden units.
#[derive(Debug, Clone, PartialEq)]
pub struct NarxF32<const F: usize, const H: usize> {
    lags: Lags,
    /// Row j, frame k: weights of (y, u).
    w1: [[[f32; 2]; F]; H],
    b1: [f32; H],
    w2: [f32; H],
    b2: f32,
    /// Scaled = physical · gain + offset, for u and y.
    u_gain: f32,
    u_offset: f32,
    y_gain: f32,
    y_offset: f32,
    /// Physical = scaled · std + mean, for y.
    y_scale: Scaling<f32>,
    /// Scaled training ranges.
    u_range: [f32; 2],
    y_range: [f32; 2],
    used_y: u32,
    used_u: u32,
}

/// History of a running [`NarxF32`] (scaled, clamped frames `[y, u]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarxF32State<const F: usize>(Ring<[f32; 2], F>);

/// Scales and clamps one value: `(clamped value, was clamped)`; NaN enters as the range's low
/// end and counts as clamped.
#[inline(always)]
fn enter_f32(x: f32, gain: f32, offset: f32, range: [f32; 2]) -> (f32, bool) {
    clamp_f32(x * gain + offset, range)
}

/// [`enter_f32`] for a value already scaled.
#[inline(always)]
fn clamp_f32(z: f32, range: [f32; 2]) -> (f32, bool) {
    if z > range[1] {
        (range[1], true)
    } else if z >= range[0] {
        (z, false)
    } else {
        (range[0], true)
    }
}

impl<const F: usize, const H: usize> NarxF32<F, H> {
    /// Builds the pass from NNSYSID weights, checked ([`NnsysidModel::check`]) and re-laid-out
    /// into frames; `const`, for `static` models.
    pub const fn new(m: &NnsysidModel) -> Result<Self, NarmaxError> {
        if let Err(e) = m.check(F, H) {
            return Err(e);
        }
        let mut w1 = [[[0.0f32; 2]; F]; H];
        let mut b1 = [0.0f32; H];
        let mut w2 = [0.0f32; H];
        let mut j = 0;
        while j < m.hidden {
            let mut seg = 0;
            while seg < 2 {
                let len = if seg == 0 { m.lags.na } else { m.lags.nb };
                let mut i = 0;
                while i < len {
                    w1[j][m.frame_of(seg, i)][seg] = m.w(j, seg, i) as f32;
                    i += 1;
                }
                seg += 1;
            }
            b1[j] = m.bias(j) as f32;
            w2[j] = m.w2[j] as f32;
            j += 1;
        }
        let (u, y) = (m.scaled_range(1), m.scaled_range(0));
        Ok(Self {
            lags: m.lags,
            w1,
            b1,
            w2,
            b2: m.w2[m.hidden] as f32,
            u_gain: (1.0 / m.u_scale.std) as f32,
            u_offset: (-m.u_scale.mean / m.u_scale.std) as f32,
            y_gain: (1.0 / m.y_scale.std) as f32,
            y_offset: (-m.y_scale.mean / m.y_scale.std) as f32,
            y_scale: Scaling {
                mean: m.y_scale.mean as f32,
                std: m.y_scale.std as f32,
            },
            u_range: [u[0] as f32, u[1] as f32],
            y_range: [y[0] as f32, y[1] as f32],
            used_y: m.used(0),
            used_u: m.used(1),
        })
    }

    /// [`Self::new`] for a `static`: a bad model stops the build with the rule it broke.
    pub const fn build(m: &NnsysidModel) -> Self {
        match Self::new(m) {
            Ok(x) => x,
            Err(e) => build_error(e),
        }
    }

    /// The frame `[y, u]` of a measured sample (u(t), y(t)), each scaled and clamped to its
    /// training range, with y's and u's clamp flags.
    #[inline(always)]
    fn frame(&self, u: f32, y: f32) -> ([f32; 2], bool, bool) {
        let (zu, cu) = enter_f32(u, self.u_gain, self.u_offset, self.u_range);
        let (zy, cy) = enter_f32(y, self.y_gain, self.y_offset, self.y_range);
        ([zy, zu], cy, cu)
    }

    /// The network's scaled output for the current window.
    #[inline(always)]
    fn network(&self, st: &NarxF32State<F>) -> f32 {
        let x = st.0.window();
        let mut out = self.b2;
        for j in 0..H {
            let w = &self.w1[j];
            let mut a = self.b1[j];
            unrolled!(F, |k| {
                a += w[k][0] * x[k][0];
                a += w[k][1] * x[k][1];
            });
            out += self.w2[j] * tanh_f32(a);
        }
        out
    }

    #[inline(always)]
    fn clamped(&self, st: &NarxF32State<F>) -> bool {
        (st.0.y_clamped & self.used_y) | (st.0.u_clamped & self.used_u) != 0
    }
}

impl<const F: usize, const H: usize> Predictor for NarxF32<F, H> {
    type Value = f32;
    type State = NarxF32State<F>;

    fn lags(&self) -> Lags {
        self.lags
    }

    fn output_scaling(&self) -> Scaling<f32> {
        self.y_scale
    }

    fn state_at(&self, u: f32, y: f32) -> NarxF32State<F> {
        let (v, cy, cu) = self.frame(u, y);
        NarxF32State(Ring::filled(v, cy, cu))
    }

    fn seed(&self, st: &mut NarxF32State<F>, u: f32, y: f32) {
        let (v, cy, cu) = self.frame(u, y);
        st.0.push(v, cy, cu);
    }

    /// The measurement enters the history scaled and clamped; in free run ŷ(t) clamped to
    /// the training range.
    #[inline(always)]
    fn step(&self, st: &mut NarxF32State<F>, u: f32, y_measured: Option<f32>) -> NarmaxOutput<f32> {
        let z = self.network(st);
        let clamped = self.clamped(st);
        let (zu, cu) = enter_f32(u, self.u_gain, self.u_offset, self.u_range);
        let (zy, cy) = match y_measured {
            Some(y) => enter_f32(y, self.y_gain, self.y_offset, self.y_range),
            None => clamp_f32(z, self.y_range),
        };
        st.0.push([zy, zu], cy, cu);
        NarmaxOutput {
            y: z * self.y_scale.std + self.y_scale.mean,
            clamped,
        }
    }
}
