//! Fixed-point NARMAX forward pass (Q15-class), built from a float model by code.
//!
//! Number formats (the `fixed` crate's types):
//! - regressors, history, hidden pre-activations, biases and the output: [`I16F16`]
//!   (range ±32768, step 1.5e-5 in scaled units);
//! - weights: [`I1F15`] mantissas with one power-of-two exponent per hidden row and one for
//!   the output layer (block floating point, as CMSIS-NN's per-channel shifts): every row
//!   uses the full 16 bits whatever its magnitude, and weights need no range assumption;
//! - tanh outputs: [`I1F15`];
//! - accumulators: i64 on the raw bits (Q15 × Q16 → Q31 products, as the Cortex-M4's
//!   `SMLAL` accumulates), rounded once per row and saturated into [`I16F16`]; bias adds and
//!   the output sum saturate.
//!
//! tanh: a 513-entry Q15 table of tanh on [0, 8] in steps of 1/64, generated from f64 `tanh`
//! by the build script, linearly interpolated, odd symmetry for negative inputs, ±(1 − 2⁻¹⁵)
//! beyond 8. Its maximum error against f64 `tanh` over every I16F16 input is [`TANH_MAX_ERROR`]
//! = 4.7e-5 (measured: 4.70e-5, checked exhaustively in the tests): the interpolation error
//! h²/8·max|tanh''| = 2.3e-5, plus the table's and the result's rounding, and 3.1e-5 where
//! the table saturates at 1 − 2⁻¹⁵.
//!
//! [`NarmaxQ::one_step_error_bound`] bounds the one-step difference to the exact (real
//! arithmetic) network from these formats; host-tests checks it against an f64 network.

use super::{Lags, Narmax, NarmaxError, NarmaxOutput, NarmaxState, Scaling};
use crate::scalar::Real;
use fixed::types::{I16F16, I1F15};

include!(concat!(env!("OUT_DIR"), "/tanh_table.rs"));

/// Largest |tanh_q15(x) − tanh(x)| over all I16F16 inputs (exhaustive test `tanh_table_error`).
pub const TANH_MAX_ERROR: f64 = 4.7e-5;

/// tanh of an I16F16 by table and linear interpolation (see the module docs).
#[inline]
pub fn tanh_q15(x: I16F16) -> I1F15 {
    let bits = x.to_bits();
    let a = bits.unsigned_abs();
    let shift = 16 - TANH_STEP_LOG2;
    let i = (a >> shift) as usize;
    let y = if i + 1 >= TANH_Q15.len() {
        i32::from(i16::MAX)
    } else {
        let frac = (a & ((1 << shift) - 1)) as i32;
        let (y0, y1) = (i32::from(TANH_Q15[i]), i32::from(TANH_Q15[i + 1]));
        y0 + (((y1 - y0) * frac + (1 << (shift - 1))) >> shift)
    };
    let y = y.min(i32::from(i16::MAX)) as i16;
    I1F15::from_bits(if bits < 0 { -y } else { y })
}

/// A scaled value in I16F16, saturating; NaN (which `fixed` would panic on) reads as 0, the
/// scaled mean.
#[inline]
fn to_fixed(x: f32) -> I16F16 {
    if x.is_nan() {
        I16F16::ZERO
    } else {
        I16F16::saturating_from_num(x)
    }
}

/// Rounds `acc · 2^-shift` (shift may be negative) and saturates to i32.
#[inline]
fn round_shift(acc: i64, shift: i32) -> i32 {
    let v = if shift > 0 {
        (acc + (1i64 << (shift - 1))) >> shift
    } else {
        acc.saturating_mul(1i64 << (-shift).min(62))
    };
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// Largest weight exponent: |w| < 2^30.
pub const MAX_WEIGHT_EXP: i32 = 30;

/// Mantissas in I1F15 and the exponent e with w = m · 2^e, for a block of weights; `None` if a
/// weight is 2^30 or larger (or not finite).
fn block<const L: usize>(w: &[f64], out: &mut [I1F15; L]) -> Option<i8> {
    if w.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let max = w.iter().fold(0.0f64, |m, &x| m.max(x.abs()));
    let full = 32767.0 / 32768.0;
    if !(max < libm::ldexp(full, MAX_WEIGHT_EXP)) {
        return None;
    }
    let mut e: i32 = 0;
    if max > 0.0 {
        while max > full * libm::ldexp(1.0, e) && e < MAX_WEIGHT_EXP {
            e += 1;
        }
        while max <= full * libm::ldexp(1.0, e - 1) && e > -30 {
            e -= 1;
        }
    }
    for (o, &x) in out.iter_mut().zip(w) {
        *o = I1F15::saturating_from_num(libm::ldexp(x, -e));
    }
    Some(e as i8)
}

/// Largest step between successive outputs, in I16F16 LSBs, that still counts as settled.
pub const STEADY_LSB: i32 = 4;

/// A quantised NARMAX model (immutable configuration); shapes as in [`Narmax`].
#[derive(Debug, Clone, PartialEq)]
pub struct NarmaxQ<const N: usize, const H: usize> {
    lags: Lags,
    hidden: usize,
    w1: [[I1F15; N]; H],
    w1_exp: [i8; H],
    b1: [I16F16; H],
    w2: [I1F15; H],
    w2_exp: i8,
    b2: I16F16,
    u_scale: Scaling<f32>,
    y_scale: Scaling<f32>,
    u_range: [I16F16; 2],
    y_range: [I16F16; 2],
}

/// History of a running quantised model.
pub type NarmaxQState<const N: usize> = NarmaxState<I16F16, N>;

impl<const N: usize, const H: usize> NarmaxQ<N, H> {
    /// Quantises a float model (the only way to build one).
    pub fn quantize<T: Real>(m: &Narmax<T, N, H>) -> Result<Self, NarmaxError> {
        let n = m.lags.inputs();
        let mut q = Self {
            lags: m.lags,
            hidden: m.hidden,
            w1: [[I1F15::ZERO; N]; H],
            w1_exp: [0; H],
            b1: [I16F16::ZERO; H],
            w2: [I1F15::ZERO; H],
            w2_exp: 0,
            b2: I16F16::ZERO,
            u_scale: Scaling {
                mean: m.u_scale.mean.to_f64() as f32,
                std: m.u_scale.std.to_f64() as f32,
            },
            y_scale: Scaling {
                mean: m.y_scale.mean.to_f64() as f32,
                std: m.y_scale.std.to_f64() as f32,
            },
            u_range: [0, 1].map(|i| I16F16::saturating_from_num(m.u_range[i].to_f64())),
            y_range: [0, 1].map(|i| I16F16::saturating_from_num(m.y_range[i].to_f64())),
        };
        let fits = |x: f64| x.abs() < 32767.0;
        let mut row = [0.0f64; N];
        for j in 0..m.hidden {
            for (r, w) in row[..n].iter_mut().zip(&m.w1[j][..n]) {
                *r = w.to_f64();
            }
            q.w1_exp[j] = block(&row[..n], &mut q.w1[j]).ok_or(NarmaxError::BadValue)?;
            let b = m.b1[j].to_f64();
            if !fits(b) {
                return Err(NarmaxError::BadValue);
            }
            q.b1[j] = I16F16::from_num(b);
        }
        let mut w2 = [0.0f64; H];
        for (o, w) in w2[..m.hidden].iter_mut().zip(&m.w2[..m.hidden]) {
            *o = w.to_f64();
        }
        q.w2_exp = block(&w2[..m.hidden], &mut q.w2).ok_or(NarmaxError::BadValue)?;
        if !fits(m.b2.to_f64()) {
            return Err(NarmaxError::BadValue);
        }
        q.b2 = I16F16::from_num(m.b2.to_f64());
        Ok(q)
    }

    /// The lags.
    pub fn lags(&self) -> Lags {
        self.lags
    }

    /// Output of the network for scaled regressors φ (I16F16).
    #[inline]
    pub fn network(&self, phi: &[I16F16]) -> I16F16 {
        let n = self.lags.inputs().min(phi.len());
        let mut out: i64 = 0;
        for j in 0..self.hidden {
            let mut acc: i64 = 0;
            for (w, x) in self.w1[j][..n].iter().zip(&phi[..n]) {
                acc += i64::from(w.to_bits()) * i64::from(x.to_bits());
            }
            // Q31 · 2^e → Q16.
            let a = I16F16::from_bits(round_shift(acc, 15 - i32::from(self.w1_exp[j])))
                .saturating_add(self.b1[j]);
            out += i64::from(self.w2[j].to_bits()) * i64::from(tanh_q15(a).to_bits());
        }
        // Q30 · 2^e → Q16.
        I16F16::from_bits(round_shift(out, 14 - i32::from(self.w2_exp))).saturating_add(self.b2)
    }

    /// Bound on |network_q(φ) − network(φ)| (scaled units) for regressors with |φᵢ| ≤ `phi_max`
    /// already on the I16F16 grid, `network` being the float model this was quantised from in
    /// exact arithmetic: weight rounding (half a mantissa step per row), bias and accumulator
    /// rounding, and [`TANH_MAX_ERROR`], propagated through |w2|.
    pub fn one_step_error_bound(&self, phi_max: f64) -> f64 {
        let n = self.lags.inputs() as f64;
        let half_lsb16 = 1.0 / 131072.0;
        let mut total = 0.0;
        for j in 0..self.hidden {
            let dw1 = libm::ldexp(1.0, i32::from(self.w1_exp[j]) - 16);
            let da = n * phi_max * dw1 + 2.0 * half_lsb16;
            let w2 =
                libm::ldexp(f64::from(self.w2[j].to_bits()), i32::from(self.w2_exp) - 15).abs();
            let dw2 = libm::ldexp(1.0, i32::from(self.w2_exp) - 16);
            total += (w2 + dw2) * (da + TANH_MAX_ERROR) + dw2;
        }
        total + 2.0 * half_lsb16
    }

    /// History with every past value at (u, y) (physical), no errors.
    pub fn state_at(&self, u: f32, y: f32) -> NarmaxQState<N> {
        NarmaxState::filled(self.scale_u(u), self.scale_y(y), I16F16::ZERO)
    }

    fn scale_u(&self, u: f32) -> I16F16 {
        to_fixed(self.u_scale.scale(u))
    }

    fn scale_y(&self, y: f32) -> I16F16 {
        to_fixed(self.y_scale.scale(y))
    }

    /// Puts one measured sample into the history without predicting.
    pub fn seed(&self, st: &mut NarmaxQState<N>, u: f32, y: f32) {
        st.push_u(self.lags, self.scale_u(u));
        st.push_y_e(self.lags, self.scale_y(y), I16F16::ZERO);
    }

    /// Takes u(t), returns the network's scaled ŷ(t) and the clamp flag.
    fn predict_scaled(&self, st: &mut NarmaxQState<N>, u: f32) -> (I16F16, bool) {
        st.push_u(self.lags, self.scale_u(u));
        let mut phi = [I16F16::ZERO; N];
        let clamped = st.regressors(self.lags, &self.u_range, &self.y_range, &mut phi);
        (self.network(&phi), clamped)
    }

    fn output(&self, z: I16F16, clamped: bool) -> NarmaxOutput<f32> {
        NarmaxOutput {
            y: self.y_scale.unscale(z.to_num::<f32>()),
            clamped,
        }
    }

    /// Free-run simulation step (see [`Narmax::simulate_step`]).
    pub fn simulate_step(&self, st: &mut NarmaxQState<N>, u: f32) -> NarmaxOutput<f32> {
        let (z, clamped) = self.predict_scaled(st, u);
        st.push_y_e(self.lags, z, I16F16::ZERO);
        self.output(z, clamped)
    }

    /// One-step-ahead prediction step (see [`Narmax::predict_step`]).
    pub fn predict_step(
        &self,
        st: &mut NarmaxQState<N>,
        u: f32,
        y_measured: f32,
    ) -> NarmaxOutput<f32> {
        let (z, clamped) = self.predict_scaled(st, u);
        let zy = self.scale_y(y_measured);
        st.push_y_e(self.lags, zy, zy.saturating_sub(z));
        self.output(z, clamped)
    }

    /// Free-run output settled under constant `u` (see [`Narmax::steady_output`]). Fixed-point
    /// feedback may end in a limit cycle of a few LSBs instead of a fixed point: settled means
    /// successive outputs within [`STEADY_LSB`] LSBs for 4·max-lag steps in a row, and the
    /// result is the mean over those steps.
    pub fn steady_output(&self, u: f32, max_steps: usize) -> Option<f32> {
        let mut st = self.state_at(u, self.y_scale.mean);
        let need = 4 * self.lags.max_lag().max(1);
        let (mut calm, mut last, mut sum) = (0usize, i32::MAX, 0i64);
        for _ in 0..max_steps {
            let z = self.simulate_step(&mut st, u);
            let bits = self.scale_y(z.y).to_bits();
            if (i64::from(bits) - i64::from(last)).abs() <= i64::from(STEADY_LSB) {
                calm += 1;
                sum += i64::from(bits);
            } else {
                calm = 0;
                sum = 0;
            }
            if calm >= need {
                let mean = I16F16::from_bits((sum / need as i64) as i32);
                return Some(self.y_scale.unscale(mean.to_num::<f32>()));
            }
            last = bits;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_table_error() {
        // Every non-negative I16F16 up to 10 (odd symmetry covers the rest), then a sparse
        // sweep to the end of the range.
        let mut worst: f64 = 0.0;
        let mut check = |bits: i32| {
            let x = I16F16::from_bits(bits);
            let err = (tanh_q15(x).to_num::<f64>() - x.to_num::<f64>().tanh()).abs();
            worst = worst.max(err);
        };
        for bits in 0..(10 << 16) {
            check(bits);
            check(-bits);
        }
        for bits in (10 << 16..i32::MAX).step_by(65_537) {
            check(bits);
        }
        check(i32::MIN + 1);
        assert!(worst <= TANH_MAX_ERROR, "max tanh error {worst:e}");
        assert!(
            worst > 0.5 * TANH_MAX_ERROR,
            "documented bound is loose: {worst:e}"
        );
    }

    #[test]
    fn non_finite_inputs_never_panic() {
        use crate::narmax::{Lags, Narmax, Scaling};
        let lags = Lags {
            na: 1,
            nb: 1,
            nc: 1,
            nk: 1,
        };
        let unit = Scaling {
            mean: 1.0f32,
            std: 2.0,
        };
        let m: Narmax<f32, 4, 2> = Narmax::new(
            lags,
            2,
            &[0.5; 8],
            &[0.3; 3],
            unit,
            unit,
            [0.0, 9.0],
            [0.0, 9.0],
        )
        .unwrap();
        let q: NarmaxQ<4, 2> = NarmaxQ::quantize(&m).unwrap();
        let mut st = q.state_at(f32::NAN, f32::INFINITY);
        for u in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, 3.0] {
            assert!(q.simulate_step(&mut st, u).y.is_finite());
            assert!(q.predict_step(&mut st, u, f32::NAN).y.is_finite());
        }
    }

    #[test]
    fn block_exponents_use_the_full_mantissa() {
        let mut out = [I1F15::ZERO; 3];
        let e = block(&[0.3, -5.0, 2.0], &mut out);
        assert_eq!(e, Some(3));
        assert!((out[1].to_num::<f64>() * 8.0 + 5.0).abs() < 1e-3);
        let e = block(&[0.01, 0.002], &mut out);
        assert_eq!(e, Some(-6));
        assert_eq!(block(&[0.0, 0.0], &mut out), Some(0));
        assert_eq!(block(&[1e10, 0.0], &mut out), None);
        assert_eq!(block(&[f64::NAN], &mut out), None);
        assert_eq!(to_fixed(f32::NAN), I16F16::ZERO);
        assert_eq!(to_fixed(f32::INFINITY), I16F16::MAX);
        assert_eq!(round_shift(3, 1), 2);
        assert_eq!(round_shift(-3, 1), -1);
        assert_eq!(round_shift(i64::MAX / 2, 0), i32::MAX);
    }
}
