//! The NARMAX passes the MCU runs: NARX models (nc = 0, nk ≥ 1) with their shapes fixed at
//! compile time, built by `const fn` from the NNSYSID weights, in f32 ([`NarxF32`]) and in
//! Q15 fixed point ([`NarxQ15`]).
//!
//! # Built at compile time
//!
//! [`NarxF32::new`] and [`NarxQ15::new`] are `const fn`: the firmware's models are `static`s
//! evaluated by the compiler (checked, re-laid-out and quantised on the host), so a bad model
//! is a build error and the image holds neither the quantiser nor the f64 arithmetic it uses.
//! The host (pumpbench, tests) calls the same functions at run time and gets the same bits.
//!
//! # History without shifting
//!
//! All regressor segments move by one sample per step, so the history is one ring of
//! **frames** `(y(t−1−k), u(t−1−k))`, `k = 0..F`, kept twice in a double-length buffer: the
//! window `F` frames long is contiguous at a moving index and no value is moved, only written
//! twice. The weights are laid out frame by frame to match; the input delay nk is folded into
//! that layout (u(t−nk−i) is frame nk − 1 + i), and frames a segment does not use carry zero
//! weights. Each value is scaled and clamped to its training range **once**, when it enters
//! the history; the `clamped` flag of a step says whether a value the weights use was clamped,
//! as the generic pass's does.
//!
//! # The f32 pass
//!
//! One multiply-accumulate per weight in frame order, then [`tanh_f32`], a rational
//! approximation (odd degree-13 over even degree-6 polynomial on [−7.905, 7.905], ±1 beyond;
//! the coefficients of Eigen's `ptanh_float`) within [`TANH_F32_MAX_ERROR`] = 4e-7 of tanh (measured 3.95e-7)
//! (every f32 input checked in the tests).
//!
//! # The Q15 pass
//!
//! - **Regressors**: each segment in Q15 over its own training range, `q = 32768·(z − c)/h`
//!   with `c`, `h` the centre and half-width of the scaled range: saturating to the range is
//!   the clamp, and every regressor uses all 16 bits whatever its range. A frame is one word,
//!   `y` in the low half and `u` in the high half.
//! - **Hidden layer**: the ranges are folded into the weights (`w·h`) and biases
//!   (`b + Σ w·c`); each row is i16 mantissas with one power-of-two exponent, packed in pairs
//!   to match the frames, accumulated with `SMLAD` (two 16×16 products per instruction,
//!   [`crate::dsp`]) in 32 bits onto the bias. The exponent is the smallest with every
//!   mantissa ≤ 32767 **and** `|bias| + 32768·Σ|mantissa| ≤ 2³¹ − 1`, so the accumulator
//!   cannot overflow for any input.
//! - **tanh**: the pre-activation rounded to Q16, then the 1 025-entry Q15 table on [−8, 8]
//!   with linear interpolation, [`tanh_q15`], within [`TANH_Q15_MAX_ERROR`] of tanh.
//! - **Output**: i16 mantissas with one exponent, folded so that the accumulator is the
//!   output's Q15 code over y's range (fed back after rounding and saturation) and the
//!   physical output is `a + b·acc` in f32, unsaturated.
//!
//! [`NarxQ15::one_step_error_bound`] bounds the one-step difference to the f64 network.
//!
//! # Q formats as types
//!
//! The Q15 codes (regressors, the table, tanh's result) are `fixed`'s [`I1F15`] and the
//! pre-activation fed to the table is [`I16F16`] (Q16): the format is in the type, not only in
//! a name. Both are `repr(transparent)` over i16/i32 and their `from_bits`/`to_bits` are
//! free, so the pass costs what it did with bare integers (`cargo xtask bench`: 373 and 345
//! instructions per step for the pressure and flow models, the same before and after). Two
//! codes packed in a word for `SMLAD` and the weights' block-exponent mantissas stay plain
//! `u32`/`i16`: they are not one Q format. The crate is chosen over a local newtype because
//! it is well kept, no_std, and gives the conversions (`to_num::<f64>()`) the tests use.
//!
//! # Layout
//!
//! This module holds the model as NNSYSID stores it ([`NnsysidModel`], checked), the periods
//! the firmware runs, and the history ring; `float` the f32 pass, `q15` the Q15 pass and its
//! quantiser, `tanh` both tanh approximations and their error bounds.

use super::{Lags, NarmaxError, Scaling, MAX_NK};

/// Largest frame count (history length) of the MCU passes: the clamp flags are 32-bit masks.
pub const MAX_FRAMES: usize = 32;

/// A NARMAX model as NNSYSID stores it, in f64 and physical units: what the `const`
/// builders take (see [`super::Narmax::new`] for the layout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NnsysidModel<'a> {
    /// Lags; the MCU passes take nc = 0 and 1 ≤ nk ≤ [`MAX_NK`].
    pub lags: Lags,
    /// Hidden tanh units.
    pub hidden: usize,
    /// Hidden × (na + nb + 1), row-major, bias last.
    pub w1: &'a [f64],
    /// Hidden + 1, bias last.
    pub w2: &'a [f64],
    /// Input scaling, % of nominal torque.
    pub u_scale: Scaling<f64>,
    /// Output scaling, the output's unit.
    pub y_scale: Scaling<f64>,
    /// Training range of u, `[min, max]`, %.
    pub u_range: [f64; 2],
    /// Training range of y, `[min, max]`, the output's unit.
    pub y_range: [f64; 2],
}

/// Longest model period the firmware runs, ms: the controller steps the observer once per
/// pressure period and refuses steps longer than 1 s.
pub const MAX_PERIOD_MS: u32 = 1000;

/// How far a model's period may be from a whole number of milliseconds, ms (1 µs: an f32
/// period of up to 1 s is stored within 0.06 µs of its decimal value).
pub const PERIOD_TOLERANCE_MS: f64 = 1e-3;

/// The firmware's step count for a model sampled every `period_s` seconds: the controller
/// ticks every 1 ms, so the period must be a whole number of milliseconds (within
/// [`PERIOD_TOLERANCE_MS`]) from 1 to [`MAX_PERIOD_MS`]; anything else is
/// [`NarmaxError::Period`] (never rounded to a period the model was not trained at).
///
/// `const fn`: the firmware derives its periods from the exported models with it, so a model
/// written by hand with a period it cannot run is a build error; `pumpbench export` calls it
/// before writing anything.
pub const fn firmware_period_ms(period_s: f64) -> Result<u32, NarmaxError> {
    let ms = period_s * 1000.0;
    // NaN fails both comparisons.
    if !(ms >= 1.0 - PERIOD_TOLERANCE_MS && ms <= MAX_PERIOD_MS as f64 + PERIOD_TOLERANCE_MS) {
        return Err(NarmaxError::Period);
    }
    let whole = round(ms);
    if abs(ms - whole as f64) > PERIOD_TOLERANCE_MS {
        return Err(NarmaxError::Period);
    }
    Ok(whole as u32)
}

const fn all_finite(xs: &[f64]) -> bool {
    let mut i = 0;
    while i < xs.len() {
        if !xs[i].is_finite() {
            return false;
        }
        i += 1;
    }
    true
}

const fn max_usize(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

const fn abs(x: f64) -> f64 {
    if x < 0.0 {
        -x
    } else {
        x
    }
}

/// 2^e, exactly, for |e| < 1000.
const fn pow2(e: i32) -> f64 {
    let mut r = 1.0;
    let mut k = 0;
    while k < e {
        r *= 2.0;
        k += 1;
    }
    while k > e {
        r *= 0.5;
        k -= 1;
    }
    r
}

/// Nearest integer, halves away from zero, saturated to i64.
const fn round(x: f64) -> i64 {
    if x >= 0.0 {
        (x + 0.5) as i64
    } else {
        -((-x + 0.5) as i64)
    }
}

/// Runs `$body` for `$k` = 0..F in straight-line code for F ≤ 16 (the branches fold at
/// compile time: F is a constant), a loop beyond: the MCU's loops are short and `opt-level =
/// "s"` does not unroll them, which costs ≈ 3 instructions per multiply-accumulate.
macro_rules! unrolled {
    ($F:expr, |$k:ident| $body:block) => {{
        unrolled!(@ $F, $k, $body, 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15);
        let mut $k = 16;
        while $k < $F {
            $body
            $k += 1;
        }
    }};
    (@ $F:expr, $k:ident, $body:block, $($n:literal)*) => {
        $(
            if $n < $F {
                let $k: usize = $n;
                $body
            }
        )*
    };
}

impl NnsysidModel<'_> {
    /// Frames of history the model needs: max(na, nk − 1 + nb).
    pub const fn frames(&self) -> usize {
        max_usize(
            self.lags.na,
            (self.lags.nk + self.lags.nb).saturating_sub(1),
        )
    }

    /// Weight of y(t−1−i) (`seg` 0, i < na) or u(t−nk−i) (`seg` 1, i < nb) in row `j`.
    const fn w(&self, j: usize, seg: usize, i: usize) -> f64 {
        let n = self.lags.na + self.lags.nb;
        self.w1[j * (n + 1) + seg * self.lags.na + i]
    }

    const fn bias(&self, j: usize) -> f64 {
        let n = self.lags.na + self.lags.nb;
        self.w1[j * (n + 1) + n]
    }

    /// The rules every MCU model keeps, for `frames` frames and `hidden` units of capacity.
    pub const fn check(&self, frames: usize, hidden: usize) -> Result<(), NarmaxError> {
        let l = self.lags;
        if l.nk > MAX_NK || self.hidden == 0 || l.na + l.nb == 0 {
            return Err(NarmaxError::BadLags);
        }
        if l.nc != 0 || l.nk == 0 {
            return Err(NarmaxError::NotNarx);
        }
        if self.frames() > frames || self.hidden > hidden || frames > MAX_FRAMES {
            return Err(NarmaxError::TooLarge);
        }
        let (w1n, w2n) = l.weight_counts(self.hidden);
        if self.w1.len() != w1n || self.w2.len() != w2n {
            return Err(NarmaxError::WrongShape);
        }
        let s = [
            self.u_scale.mean,
            self.u_scale.std,
            self.y_scale.mean,
            self.y_scale.std,
            self.u_range[0],
            self.u_range[1],
            self.y_range[0],
            self.y_range[1],
        ];
        if !all_finite(self.w1)
            || !all_finite(self.w2)
            || !all_finite(&s)
            || !(self.u_scale.std > 0.0)
            || !(self.y_scale.std > 0.0)
            || !(self.u_range[0] < self.u_range[1])
            || !(self.y_range[0] < self.y_range[1])
        {
            return Err(NarmaxError::BadValue);
        }
        // Everything the f32 pass holds must be a finite f32 (checked in f64: 3.4e38).
        let big = 1e37;
        let mut i = 0;
        while i < s.len() {
            if abs(s[i]) > big {
                return Err(NarmaxError::BadValue);
            }
            i += 1;
        }
        Ok(())
    }

    /// Scaled range `[lo, hi]` of segment `seg` (0: y, 1: u).
    const fn scaled_range(&self, seg: usize) -> [f64; 2] {
        let (s, r) = if seg == 0 {
            (self.y_scale, self.y_range)
        } else {
            (self.u_scale, self.u_range)
        };
        [(r[0] - s.mean) / s.std, (r[1] - s.mean) / s.std]
    }

    /// Bit k set: frame k's value of segment `seg` has a weight.
    const fn used(&self, seg: usize) -> u32 {
        let (first, len) = if seg == 0 {
            (0, self.lags.na)
        } else {
            (self.lags.nk - 1, self.lags.nb)
        };
        if len == 0 {
            0
        } else {
            (u32::MAX >> (32 - len)) << first
        }
    }

    /// Frame index and segment of regressor `i` of segment `seg`.
    const fn frame_of(&self, seg: usize, i: usize) -> usize {
        if seg == 0 {
            i
        } else {
            self.lags.nk - 1 + i
        }
    }
}

pub use crate::scalar::to_f32;

/// Turns a failed `const` build into a compile error naming the rule.
pub const fn build_error(e: NarmaxError) -> ! {
    match e {
        NarmaxError::TooLarge => {
            panic!("NARMAX model larger than the pass's frames or hidden units")
        }
        NarmaxError::WrongShape => panic!("NARMAX weights do not match the lags and hidden width"),
        NarmaxError::BadValue => panic!("NARMAX model has a non-finite or out-of-range value"),
        NarmaxError::BadLags => panic!("NARMAX lags out of range"),
        NarmaxError::NotNarx => panic!("the MCU passes take NARX models: nc = 0, nk >= 1"),
        NarmaxError::FixedRange => {
            panic!("NARMAX pre-activation or output too large for the Q15 pass")
        }
        NarmaxError::Period => {
            panic!("NARMAX sample period is not a whole number of ms from 1 to 1000")
        }
    }
}

/// [`firmware_period_ms`] of an exported model's `SAMPLE_PERIOD_S` (an f32, s), for a `const`:
/// a period the firmware cannot run is a build error naming the rule.
pub const fn build_period_ms(period_s: f32) -> u32 {
    match firmware_period_ms(period_s as f64) {
        Ok(ms) => ms,
        Err(e) => build_error(e),
    }
}

/// Ring of `F` frames kept twice (see the module docs), and the clamp masks.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ring<V, const F: usize> {
    /// `frames[0]` and `frames[1]` hold the same frames; the window starts at `pos` of the
    /// flattened pair.
    frames: [[V; F]; 2],
    pos: usize,
    /// Bit k: frame k's y (resp. u) was clamped when it entered.
    y_clamped: u32,
    u_clamped: u32,
}

impl<V: Copy, const F: usize> Ring<V, F> {
    const fn filled(v: V, y_clamped: bool, u_clamped: bool) -> Self {
        let all = if F >= 32 { u32::MAX } else { (1u32 << F) - 1 };
        Self {
            frames: [[v; F]; 2],
            pos: 0,
            y_clamped: if y_clamped { all } else { 0 },
            u_clamped: if u_clamped { all } else { 0 },
        }
    }

    /// The F frames, newest first.
    #[inline(always)]
    fn window(&self) -> &[V; F] {
        // (`get`, not indexing: `pos` < F always, but a bounds check's panic would link its
        // formatting into the image.)
        let flat = self.frames.as_flattened();
        match flat.get(self.pos..).and_then(<[V]>::first_chunk::<F>) {
            Some(w) => w,
            None => &self.frames[0],
        }
    }

    /// Makes `v` frame 0 (the oldest frame leaves).
    #[inline(always)]
    fn push(&mut self, v: V, y_clamped: bool, u_clamped: bool) {
        // (`pos` ≤ F − 1 for the compiler too: no bounds check below.)
        let pos = if self.pos == 0 || self.pos > F {
            F - 1
        } else {
            self.pos - 1
        };
        self.pos = pos;
        self.frames[0][pos] = v;
        self.frames[1][pos] = v;
        self.y_clamped = (self.y_clamped << 1) | u32::from(y_clamped);
        self.u_clamped = (self.u_clamped << 1) | u32::from(u_clamped);
    }
}

mod float;
mod q15;
mod tanh;

/// The Q formats of the Q15 pass: Q15 codes ([`I1F15`], i16 over 2^15) and the Q16
/// pre-activation ([`I16F16`], i32 over 2^16), from the `fixed` crate.
pub use fixed::types::{I16F16, I1F15};
pub use float::{NarxF32, NarxF32State};
pub use q15::{NarxQ15, NarxQ15State};
pub use tanh::{tanh_f32, tanh_q15, TANH_F32_MAX_ERROR, TANH_Q15_MAX_ERROR};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::narmax::Predictor;

    #[test]
    fn firmware_period_whole_milliseconds_only() {
        // What export writes is an f32: check the periods as the firmware sees them.
        let f = |s: f32| firmware_period_ms(f64::from(s));
        assert_eq!(f(0.05), Ok(50));
        assert_eq!(f(0.001), Ok(1));
        assert_eq!(f(1.0), Ok(1000));
        assert_eq!(f(0.15), Ok(150));
        for bad in [
            1e-300_f64,
            0.0,
            -0.05,
            0.0504,
            0.0005,
            1.001,
            20.0,
            f64::NAN,
            f64::INFINITY,
        ] {
            assert_eq!(firmware_period_ms(bad), Err(NarmaxError::Period), "{bad}");
        }
        // 1 µs off a whole ms is still that ms; 2 µs is not.
        assert_eq!(firmware_period_ms(0.050_000_9), Ok(50));
        assert_eq!(firmware_period_ms(0.050_002), Err(NarmaxError::Period));
        let message = NarmaxError::Period.to_string();
        assert!(message.contains(&MAX_PERIOD_MS.to_string()), "{message}");
    }

    const fn model<'a>(lags: Lags, w1: &'a [f64], w2: &'a [f64]) -> NnsysidModel<'a> {
        NnsysidModel {
            lags,
            hidden: w2.len() - 1,
            w1,
            w2,
            u_scale: Scaling {
                mean: 40.0,
                std: 20.0,
            },
            y_scale: Scaling {
                mean: 2.0,
                std: 1.0,
            },
            u_range: [5.0, 85.0],
            y_range: [0.0, 5.0],
        }
    }

    const LAGS: Lags = Lags {
        na: 2,
        nb: 3,
        nc: 0,
        nk: 2,
    };

    #[test]
    fn frames_hold_the_nnsysid_regressors() {
        // Hidden unit j sees regressor j only (weight 1e-3): the output reveals it.
        for pick in 0..5 {
            let mut w1 = [0.0; 6];
            w1[pick] = 1e-3;
            let m = model(LAGS, &w1, &[1.0, 0.0]);
            assert_eq!(m.frames(), 4);
            let f: NarxF32<4, 1> = NarxF32::new(&m).unwrap();
            let mut st = f.state_at(40.0, 2.0);
            let mut seen = 0.0;
            for t in 0..10 {
                let u = 10.0 + 5.0 * t as f32;
                let y = 0.5 + 0.25 * t as f32;
                let z = f.predict_step(&mut st, u, y).y - 2.0;
                seen = libm::atanhf(z) / 1e-3;
            }
            // At t = 9: y(t−1−i) scaled = 0.5 + 0.25·(8 − i) − 2; u(t−2−i) scaled.
            let want = if pick < 2 {
                0.5 + 0.25 * (8 - pick) as f32 - 2.0
            } else {
                (10.0 + 5.0 * (9 - 2 - (pick - 2)) as f32 - 40.0) / 20.0
            };
            assert!(
                (seen - want).abs() < 2e-3,
                "regressor {pick}: {seen} vs {want}"
            );
        }
    }

    #[test]
    fn clamp_flag_follows_the_used_frames() {
        let w1 = [0.1; 6];
        let m = model(LAGS, &w1, &[0.5, 0.0]);
        let f: NarxF32<4, 1> = NarxF32::new(&m).unwrap();
        let q: NarxQ15<4, 1> = NarxQ15::new(&m).unwrap();
        let (mut sf, mut sq) = (f.state_at(40.0, 2.0), q.state_at(40.0, 2.0));
        // u = 99 % (outside 5..85) at t = 0: used from t = 2 (nk = 2) to t = 4 (nb = 3).
        let mut flags = vec![];
        for t in 0..7 {
            let u = if t == 0 { 99.0 } else { 40.0 };
            let a = f.predict_step(&mut sf, u, 2.0).clamped;
            let b = q.predict_step(&mut sq, u, 2.0).clamped;
            assert_eq!(a, b, "t = {t}");
            flags.push(a);
        }
        assert_eq!(flags, [false, false, true, true, true, false, false]);
        // A NaN measurement enters at the low end, flagged, for na = 2 steps.
        let mut flags = vec![];
        for t in 0..4 {
            let y = if t == 0 { f32::NAN } else { 2.0 };
            flags.push(f.predict_step(&mut sf, 40.0, y).clamped);
            assert!(q.predict_step(&mut sq, 40.0, y).y.is_finite());
        }
        assert_eq!(flags, [false, true, true, false]);
    }

    #[test]
    fn bad_models_are_refused_and_capacity_is_checked() {
        let w1 = [0.1; 6];
        let ok = model(LAGS, &w1, &[0.5, 0.0]);
        assert!(NarxF32::<4, 1>::new(&ok).is_ok());
        assert!(NarxF32::<8, 4>::new(&ok).is_ok(), "padding is allowed");
        assert_eq!(
            NarxF32::<3, 1>::new(&ok).map(|_| ()),
            Err(NarmaxError::TooLarge)
        );
        let narmax = Lags { nc: 1, ..LAGS };
        let w1c = [0.1; 7];
        assert_eq!(
            NarxQ15::<4, 1>::new(&model(narmax, &w1c, &[0.5, 0.0])).map(|_| ()),
            Err(NarmaxError::NotNarx)
        );
        let nk0 = Lags { nk: 0, ..LAGS };
        assert_eq!(
            NarxQ15::<4, 1>::new(&model(nk0, &w1, &[0.5, 0.0])).map(|_| ()),
            Err(NarmaxError::NotNarx)
        );
        assert_eq!(
            NarxF32::<4, 1>::new(&model(LAGS, &w1[..5], &[0.5, 0.0])).map(|_| ()),
            Err(NarmaxError::WrongShape)
        );
        let mut nan = w1;
        nan[2] = f64::NAN;
        assert_eq!(
            NarxF32::<4, 1>::new(&model(LAGS, &nan, &[0.5, 0.0])).map(|_| ()),
            Err(NarmaxError::BadValue)
        );
        let huge = [1e6; 6];
        assert_eq!(
            NarxQ15::<4, 1>::new(&model(LAGS, &huge, &[0.5, 0.0])).map(|_| ()),
            Err(NarmaxError::FixedRange)
        );
    }

    #[test]
    fn accumulators_cannot_overflow() {
        // Weights at the edge of the mantissa range: the L1 rule raises the exponent.
        let w1 = [3.0, -3.0, 3.0, -3.0, 3.0, 10.0];
        let m = model(LAGS, &w1, &[0.9, 0.1]);
        let q: NarxQ15<4, 1> = NarxQ15::new(&m).unwrap();
        let l1: i64 = q.rows[0]
            .w
            .iter()
            .map(|&p| {
                i64::from((p as i16).unsigned_abs()) + i64::from(((p >> 16) as i16).unsigned_abs())
            })
            .sum();
        assert!(i64::from(q.rows[0].bias).abs() + 32768 * l1 <= i64::from(i32::MAX));
        // Inputs at both ends: finite and within tanh's range.
        let mut st = q.state_at(85.0, 5.0);
        for k in 0..20 {
            let u = if k % 2 == 0 { 1e9 } else { -1e9 };
            assert!(q.simulate_step(&mut st, u).y.is_finite());
        }
    }

    #[test]
    fn f32_and_q15_agree_with_the_generic_pass() {
        use crate::narmax::Narmax;
        let lags = Lags {
            na: 3,
            nb: 2,
            nc: 0,
            nk: 1,
        };
        let w1: Vec<f64> = (0..4 * 6)
            .map(|i| ((i * 7919) % 23) as f64 / 23.0 - 0.5)
            .collect();
        let w2 = [0.4, -0.3, 0.2, 0.5, 0.1];
        let m = model(lags, &w1, &w2);
        let g: Narmax<f64, 5, 4> = Narmax::new(
            lags, 4, &w1, &w2, m.u_scale, m.y_scale, m.u_range, m.y_range,
        )
        .unwrap();
        let f: NarxF32<3, 4> = NarxF32::new(&m).unwrap();
        let q: NarxQ15<3, 4> = NarxQ15::new(&m).unwrap();
        let (mut sg, mut sf, mut sq) = (
            g.state_at(30.0, 2.0),
            f.state_at(30.0, 2.0),
            q.state_at(30.0, 2.0),
        );
        let bound = NarxQ15::<3, 4>::one_step_error_bound(&m).unwrap();
        for t in 0..300 {
            let u = 10.0 + (t * 37 % 71) as f64;
            let y = 1.0 + (t * 13 % 29) as f64 / 10.0;
            let a = g.predict_step(&mut sg, u, y).y;
            let b = f64::from(f.predict_step(&mut sf, u as f32, y as f32).y);
            let c = f64::from(q.predict_step(&mut sq, u as f32, y as f32).y);
            assert!(
                (a - b).abs() <= 1e-5 * a.abs().max(1.0),
                "t {t}: f32 {b} vs {a}"
            );
            assert!(
                (a - c).abs() <= bound,
                "t {t}: q15 {c} vs {a}, bound {bound:e}"
            );
        }
        assert!(bound < 1e-2, "bound {bound}");
    }
}
