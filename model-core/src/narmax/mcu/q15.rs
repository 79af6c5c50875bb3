//! The Q15 pass: regressors as Q15 codes over their training ranges, block-exponent weights
//! accumulated two at a time with `SMLAD`, the tanh table, the output as an affine map of the
//! accumulator (see the parent module's docs).

use super::tanh::{tanh_q15, TANH_Q15_MAX_ERROR};
use super::{abs, build_error, pow2, round, NnsysidModel, Ring, MAX_FRAMES};
use crate::dsp::{pack, smlad};
use crate::narmax::{Lags, NarmaxError, NarmaxOutput, Predictor, Scaling};
use fixed::types::{I16F16, I1F15};

/// The Q15 MCU pass (see the module docs): `F` frames of history, `H` hidden units.
#[derive(Debug, Clone, PartialEq)]
pub struct NarxQ15<const F: usize, const H: usize> {
    lags: Lags,
    /// Row j, frame k: mantissas of (y, u), packed low/high.
    /// Per hidden unit, everything its step reads, side by side (one base address).
    pub(super) rows: [QRow<F>; H],
    b2: i32,
    /// Right shift from the output accumulator to y's Q15 code, minus 1.
    shift2: u32,
    /// Physical output = `out_offset + out_gain · accumulator`.
    out_gain: f32,
    out_offset: f32,
    /// Q15 code = physical · gain + offset, for u and y.
    u_gain: f32,
    u_offset: f32,
    y_gain: f32,
    y_offset: f32,
    /// Settled output: 1 LSB of y's code, physical units.
    y_lsb: f32,
    /// The output's training mean and standard deviation, physical units.
    y_scale: Scaling<f32>,
    used_y: u32,
    used_u: u32,
}

/// What the one-step error bound needs of a quantisation (host-side: kept out of the pass, so
/// the firmware's statics carry none of it).
#[derive(Debug, Clone, Copy)]
struct BoundTerms<const H: usize> {
    /// Output exponent.
    e2: i32,
    /// Half-width of y's scaled range.
    h_y: f64,
    /// |w2| and row L1 norms of the folded weights, real units.
    w2_abs: [f64; H],
    w1_l1: [f64; H],
    /// Largest |physical output| / y's std the ranges allow.
    z_max: f64,
    /// Exact rounding of each hidden row (Σ|Δw| + |Δb|, pre-activation units) and of the
    /// output layer (Σ|Δw2| per tanh LSB + |Δb2|, code units).
    qerr1: [f64; H],
    qerr2: f64,
    hidden: usize,
}

/// One hidden unit of [`NarxQ15`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct QRow<const F: usize> {
    /// Frame k: mantissas of (y, u), packed low/high.
    pub(super) w: [u32; F],
    /// Bias in accumulator units.
    pub(super) bias: i32,
    /// Right shift from the accumulator to Q16, minus 1 (see [`round_shift`]).
    pub(super) shift: u32,
    /// Output-layer mantissa.
    pub(super) w2: i32,
}

/// History of a running [`NarxQ15`]: frames of Q15 codes, y low, u high.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarxQ15State<const F: usize>(Ring<u32, F>);

/// Q15 code of a physical value: `(code, was clamped)`. Rounds to nearest (to within 1/128 of
/// an LSB: the f32 sum below has 2^-7 steps); NaN enters as the range's low end and counts as
/// clamped. Branch-free: one convert, a saturating subtract and one `SSAT`.
#[inline(always)]
fn enter_q15(x: f32, gain: f32, offset: f32) -> (I1F15, bool) {
    // r = floor(z + 0.5) + 98304 for z ≥ −98304 (truncation is floor there); smaller z, −∞
    // and NaN give r < 65536, so they count as clamped and enter as the low end.
    let r = (x * gain + offset + 98_304.5) as i32;
    let clamped = (r.wrapping_sub(65_536) as u32) > 65_535;
    let code = r.saturating_sub(98_304).clamp(-32_768, 32_767);
    (I1F15::from_bits(code as i16), clamped)
}

/// One frame of the history: y's and u's Q15 codes in one word (y low, u high), the operand
/// of `SMLAD`.
#[inline(always)]
fn frame(y: I1F15, u: I1F15) -> u32 {
    pack(y.to_bits(), u.to_bits())
}

/// `acc · 2^−(s + 1)` rounded to nearest (`s` = shift − 1), without overflow.
#[inline(always)]
fn round_shift(acc: i32, s: u32) -> i32 {
    ((acc >> s) + 1) >> 1
}

/// The exponent and i16 mantissas (`v ≈ m · 2^(e − 15)`) of a block of `len` values of `v`,
/// with the bias `b` as `round(b · 2^(30 − e))`: the smallest e ≥ `e_min` such that every
/// mantissa is ≤ 32767 and `|bias| + 32768 · Σ|m| ≤ 2³¹ − 1` (inputs are i16), if one
/// ≤ `e_max` exists.
/// Also returns Σ|v − m·2^(e−15)| + |b − bias·2^(e − bias_exp)|, the block's exact rounding.
const fn block<const L: usize>(
    v: &[f64; L],
    b: f64,
    bias_exp: i32,
    e_min: i32,
    e_max: i32,
) -> Option<(i32, [i32; L], i64, f64)> {
    let mut e = e_min;
    while e <= e_max {
        let mut m = [0i32; L];
        let mut ok = true;
        let mut l1: i64 = 0;
        let mut k = 0;
        while k < L {
            let x = round(v[k] * pow2(15 - e));
            if x > 32767 || x < -32767 {
                ok = false;
            }
            m[k] = x as i32;
            l1 += if x < 0 { -x } else { x };
            k += 1;
        }
        let bias = round(b * pow2(bias_exp - e));
        let mag = if bias < 0 { -bias } else { bias };
        if ok && mag + 32768 * l1 <= i32::MAX as i64 {
            let mut err = abs(b - bias as f64 * pow2(e - bias_exp));
            let mut k = 0;
            while k < L {
                err += abs(v[k] - m[k] as f64 * pow2(e - 15));
                k += 1;
            }
            return Some((e, m, bias, err));
        }
        e += 1;
    }
    None
}

impl<const F: usize, const H: usize> NarxQ15<F, H> {
    /// Builds the pass from NNSYSID weights: checked, re-laid-out, ranges folded in and
    /// quantised (module docs); `const`, for `static` models. [`NarmaxError::FixedRange`] if a
    /// row's bias plus the largest weighted input reaches 2^14 (tanh is flat long before) or
    /// the output layer cannot be put in 16-bit mantissas.
    pub const fn new(m: &NnsysidModel) -> Result<Self, NarmaxError> {
        match Self::quantise(m) {
            Ok((pass, _)) => Ok(pass),
            Err(e) => Err(e),
        }
    }

    /// [`Self::new`] and what the error bound needs of it.
    const fn quantise(m: &NnsysidModel) -> Result<(Self, BoundTerms<H>), NarmaxError> {
        if let Err(e) = m.check(F, H) {
            return Err(e);
        }
        let r = [m.scaled_range(0), m.scaled_range(1)];
        let c = [(r[0][0] + r[0][1]) / 2.0, (r[1][0] + r[1][1]) / 2.0];
        let h = [(r[0][1] - r[0][0]) / 2.0, (r[1][1] - r[1][0]) / 2.0];
        let mut w1 = [[0u32; F]; H];
        let mut b1 = [0i32; H];
        let mut shift1 = [0u32; H];
        let mut w1_l1 = [0.0f64; H];
        let mut qerr1 = [0.0f64; H];
        let mut j = 0;
        while j < m.hidden {
            // Folded weights: [frame][seg], and the folded bias.
            let mut v = [0.0f64; MAX_FRAMES * 2];
            let mut bias = m.bias(j);
            let mut seg = 0;
            while seg < 2 {
                let len = if seg == 0 { m.lags.na } else { m.lags.nb };
                let mut i = 0;
                while i < len {
                    let w = m.w(j, seg, i);
                    v[m.frame_of(seg, i) * 2 + seg] = w * h[seg];
                    w1_l1[j] += abs(w * h[seg]);
                    bias += w * c[seg];
                    i += 1;
                }
                seg += 1;
            }
            // Q16 = acc · 2^(e − 14): shift 14 − e in 1..=31.
            let Some((e, mant, bias_q, err)) = block(&v, bias, 30, -17, 13) else {
                return Err(NarmaxError::FixedRange);
            };
            let mut k = 0;
            while k < F {
                w1[j][k] = pack(mant[2 * k] as i16, mant[2 * k + 1] as i16);
                k += 1;
            }
            b1[j] = bias_q as i32;
            shift1[j] = (13 - e) as u32;
            // In pre-activation units: weights act on |q/32768| ≤ 1, the bias as is.
            qerr1[j] = err;
            j += 1;
        }
        // Output: code = 32768·(z − c_y)/h_y = Σ (w2/h_y)·T + 32768·(b2 − c_y)/h_y, T = tanh
        // in Q15; acc = code · 2^(15 − e2).
        let mut v2 = [0.0f64; H];
        let mut w2_abs = [0.0f64; H];
        let mut j = 0;
        while j < m.hidden {
            v2[j] = m.w2[j] / h[0];
            w2_abs[j] = abs(m.w2[j]);
            j += 1;
        }
        let b2 = 32768.0 * (m.w2[m.hidden] - c[0]) / h[0];
        // Shift to the code 15 − e2 in 1..=31.
        let Some((e2, w2, b2q, qerr2)) = block(&v2, b2, 15, -16, 14) else {
            return Err(NarmaxError::FixedRange);
        };
        let (us, ys) = (m.u_scale, m.y_scale);
        let mut rows = [QRow {
            w: [0; F],
            bias: 0,
            shift: 0,
            w2: 0,
        }; H];
        let mut j = 0;
        while j < H {
            rows[j] = QRow {
                w: w1[j],
                bias: b1[j],
                shift: shift1[j],
                w2: w2[j],
            };
            j += 1;
        }
        let pass = Self {
            lags: m.lags,
            rows,
            b2: b2q as i32,
            shift2: (14 - e2) as u32,
            out_gain: (ys.std * h[0] * pow2(e2 - 30)) as f32,
            out_offset: (ys.mean + ys.std * c[0]) as f32,
            u_gain: (32768.0 / (us.std * h[1])) as f32,
            u_offset: (-32768.0 * (us.mean / us.std + c[1]) / h[1]) as f32,
            y_gain: (32768.0 / (ys.std * h[0])) as f32,
            y_offset: (-32768.0 * (ys.mean / ys.std + c[0]) / h[0]) as f32,
            y_lsb: (ys.std * h[0] / 32768.0) as f32,
            y_scale: Scaling {
                mean: ys.mean as f32,
                std: ys.std as f32,
            },
            used_y: m.used(0),
            used_u: m.used(1),
        };
        let bound = BoundTerms {
            e2,
            h_y: h[0],
            w2_abs,
            w1_l1,
            z_max: abs(ys.mean / ys.std) + abs(c[0]) + h[0],
            qerr1,
            qerr2,
            hidden: m.hidden,
        };
        Ok((pass, bound))
    }

    /// [`Self::new`] for a `static`: a bad model stops the build with the rule it broke.
    pub const fn build(m: &NnsysidModel) -> Self {
        match Self::new(m) {
            Ok(x) => x,
            Err(e) => build_error(e),
        }
    }

    /// The frame word of a measured sample (u(t), y(t)): y's and u's Q15 codes, and their
    /// clamp flags.
    #[inline(always)]
    fn codes(&self, u: f32, y: f32) -> (u32, bool, bool) {
        let (qu, cu) = enter_q15(u, self.u_gain, self.u_offset);
        let (qy, cy) = enter_q15(y, self.y_gain, self.y_offset);
        (frame(qy, qu), cy, cu)
    }

    /// The output accumulator for the current window (y's Q15 code · 2^(shift2)).
    #[inline(always)]
    fn network(&self, st: &NarxQ15State<F>) -> i32 {
        let x = st.0.window();
        let mut out = self.b2;
        for j in 0..H {
            let row = &self.rows[j];
            let w = &row.w;
            let mut acc = row.bias;
            unrolled!(F, |k| {
                acc = smlad(w[k], x[k], acc);
            });
            let t = tanh_q15(I16F16::from_bits(round_shift(acc, row.shift)));
            out = out.wrapping_add(row.w2 * i32::from(t.to_bits()));
        }
        out
    }

    #[inline(always)]
    fn clamped(&self, st: &NarxQ15State<F>) -> bool {
        (st.0.y_clamped & self.used_y) | (st.0.u_clamped & self.used_u) != 0
    }

    #[inline(always)]
    fn output(&self, acc: i32, clamped: bool) -> NarmaxOutput<f32> {
        NarmaxOutput {
            y: self.out_offset + self.out_gain * acc as f32,
            clamped,
        }
    }

    /// Bound on |ŷ_Q15 − ŷ| in scaled output units (multiply by y's std for physical units)
    /// for one step from the same history, ŷ the exact network on the unquantised history,
    /// every history value within its training range. Terms: each regressor's rounding to its
    /// code (½ LSB, plus the f32 scaling's rounding), the weights' (½ mantissa LSB) and
    /// biases', the accumulator's to Q16, [`TANH_Q15_MAX_ERROR`], propagated through |w2|; the
    /// output layer's mantissas and bias; the f32 conversion of the accumulator and of the
    /// physical output.
    ///
    /// A function of the model (it quantises it again, as [`Self::new`] does): the pass
    /// itself carries nothing of it.
    pub fn one_step_error_bound(m: &NnsysidModel) -> Result<f64, NarmaxError> {
        let b = Self::quantise(m)?.1;
        let half = 0.51 / 32768.0;
        let (h, e2) = (b.h_y, f64::from(b.e2));
        let mut total = 0.0;
        for j in 0..b.hidden {
            // Weights and bias: their exact rounding (weights act on |q/32768| ≤ 1);
            // regressors: ½ LSB each through the folded weights; Q16: ½ of 2^-16.
            let da = b.qerr1[j] + b.w1_l1[j] * half + libm::exp2(-17.0);
            total += b.w2_abs[j] * (da + TANH_Q15_MAX_ERROR);
        }
        // Output layer: its exact rounding in code units (mantissas act on |T| ≤ 32767, the
        // bias in code units), to scaled units; the f32 conversion of the accumulator
        // (≤ 2^31 · 2^-24 accumulator units) and of the physical output.
        Ok(total + b.qerr2 * h + h * libm::exp2(e2 - 30.0) * 128.0 + b.z_max * libm::exp2(-22.0))
    }
}

impl<const F: usize, const H: usize> Predictor for NarxQ15<F, H> {
    type Value = f32;
    type State = NarxQ15State<F>;

    fn lags(&self) -> Lags {
        self.lags
    }

    fn output_scaling(&self) -> Scaling<f32> {
        self.y_scale
    }

    fn state_at(&self, u: f32, y: f32) -> NarxQ15State<F> {
        let (word, cy, cu) = self.codes(u, y);
        NarxQ15State(Ring::filled(word, cy, cu))
    }

    fn seed(&self, st: &mut NarxQ15State<F>, u: f32, y: f32) {
        let (word, cy, cu) = self.codes(u, y);
        st.0.push(word, cy, cu);
    }

    /// The measurement's code enters the history; in free run ŷ(t)'s code, saturated.
    #[inline(always)]
    fn step(&self, st: &mut NarxQ15State<F>, u: f32, y_measured: Option<f32>) -> NarmaxOutput<f32> {
        let acc = self.network(st);
        let clamped = self.clamped(st);
        let (qu, cu) = enter_q15(u, self.u_gain, self.u_offset);
        let (qy, cy) = match y_measured {
            Some(y) => enter_q15(y, self.y_gain, self.y_offset),
            None => {
                // Saturated to i16 (one `SSAT`); clamped if that changed it.
                let code = round_shift(acc, self.shift2);
                let sat = code.clamp(-32768, 32767);
                (I1F15::from_bits(sat as i16), sat != code)
            }
        };
        st.0.push(frame(qy, qu), cy, cu);
        self.output(acc, clamped)
    }

    /// Free-run output settled under constant `u`: successive outputs within `tol` and at
    /// least 4 LSBs of y's code (fixed-point feedback may end in a limit cycle of a few LSBs)
    /// for 4·max-lag steps in a row; the mean over those steps. Starts from the centre of y's
    /// code range. `None` if it does not settle in `max_steps`.
    fn steady_output(&self, u: f32, tol: f32, max_steps: usize) -> Option<f32> {
        let mut st = self.state_at(u, self.out_offset);
        let need = 4 * self.lags.max_lag().max(1);
        let tol = tol.max(4.0 * self.y_lsb);
        let (mut calm, mut last, mut sum) = (0usize, f32::NAN, 0.0f64);
        for _ in 0..max_steps {
            let y = self.simulate_step(&mut st, u).y;
            if (y - last).abs() <= tol {
                calm += 1;
                sum += f64::from(y);
            } else {
                calm = 0;
                sum = 0.0;
            }
            if calm >= need {
                return Some((sum / need as f64) as f32);
            }
            last = y;
        }
        None
    }
}
