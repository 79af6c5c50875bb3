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

use super::{Lags, NarmaxError, NarmaxOutput, Predictor, Scaling, MAX_NK};
use crate::dsp::{pack, smlad};

include!(concat!(env!("OUT_DIR"), "/tanh_table.rs"));

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
        let n = l.na + l.nb;
        if self.w1.len() != self.hidden * (n + 1) || self.w2.len() != self.hidden + 1 {
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
        let flat = self.frames.as_flattened();
        match flat[self.pos..].first_chunk::<F>() {
            Some(w) => w,
            None => &self.frames[0],
        }
    }

    /// Makes `v` frame 0 (the oldest frame leaves).
    #[inline(always)]
    fn push(&mut self, v: V, y_clamped: bool, u_clamped: bool) {
        let pos = if self.pos == 0 { F - 1 } else { self.pos - 1 };
        self.pos = pos;
        self.frames[0][pos] = v;
        self.frames[1][pos] = v;
        self.y_clamped = (self.y_clamped << 1) | u32::from(y_clamped);
        self.u_clamped = (self.u_clamped << 1) | u32::from(u_clamped);
    }
}

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
    y_std: f32,
    y_mean: f32,
    /// Scaled training ranges.
    u_range: [f32; 2],
    y_range: [f32; 2],
    used_y: u32,
    used_u: u32,
}

/// History of a running [`NarxF32`] (scaled, clamped frames `[y, u]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarxF32State<const F: usize>(Ring<[f32; 2], F>);

/// Largest |[`tanh_f32`]`(x)` − tanh(x)| over every f32 x (exhaustive test `tanh_f32_error`).
pub const TANH_F32_MAX_ERROR: f32 = 4e-7;

/// tanh by a rational approximation (see the module docs): within [`TANH_F32_MAX_ERROR`],
/// odd, ±1 beyond ±7.905, NaN for NaN. About 25 instructions on a Cortex-M4F, one divide.
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const A1: f32 = 4.893_524_6e-3;
    const A3: f32 = 6.372_619e-4;
    const A5: f32 = 1.485_722_4e-5;
    const A7: f32 = 5.122_297e-8;
    const A9: f32 = -8.604_672e-11;
    const A11: f32 = 2.000_188e-13;
    const A13: f32 = -2.760_768_5e-16;
    const B0: f32 = 4.893_525e-3;
    const B2: f32 = 2.268_434_7e-3;
    const B4: f32 = 1.185_347_1e-4;
    const B6: f32 = 1.198_258_4e-6;
    // Comparisons, not f32::min/max/clamp: those are library calls on FPv4 (and `clamp`
    // panics on NaN bounds checks it cannot see through).
    #[allow(clippy::manual_clamp)]
    let x = if x > CLAMP {
        CLAMP
    } else if x < -CLAMP {
        -CLAMP
    } else {
        x
    };
    let x2 = x * x;
    let p = x * (A1 + x2 * (A3 + x2 * (A5 + x2 * (A7 + x2 * (A9 + x2 * (A11 + x2 * A13))))));
    let q = B0 + x2 * (B2 + x2 * (B4 + x2 * B6));
    p / q
}

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
            y_std: m.y_scale.std as f32,
            y_mean: m.y_scale.mean as f32,
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
        Scaling {
            mean: self.y_mean,
            std: self.y_std,
        }
    }

    fn state_at(&self, u: f32, y: f32) -> NarxF32State<F> {
        let (zu, cu) = enter_f32(u, self.u_gain, self.u_offset, self.u_range);
        let (zy, cy) = enter_f32(y, self.y_gain, self.y_offset, self.y_range);
        NarxF32State(Ring::filled([zy, zu], cy, cu))
    }

    fn seed(&self, st: &mut NarxF32State<F>, u: f32, y: f32) {
        let (zu, cu) = enter_f32(u, self.u_gain, self.u_offset, self.u_range);
        let (zy, cy) = enter_f32(y, self.y_gain, self.y_offset, self.y_range);
        st.0.push([zy, zu], cy, cu);
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
            y: z * self.y_std + self.y_mean,
            clamped,
        }
    }
}

/// Largest |[`tanh_q15`] − tanh| over all Q16 inputs, in real units (exhaustive test
/// `tanh_q15_error`): the interpolation error h²/8·max|tanh''| = 2.3e-5, plus the table's
/// and the result's rounding, and 3.1e-5 where the table saturates at 1 − 2⁻¹⁵.
pub const TANH_Q15_MAX_ERROR: f64 = 4.72e-5;

/// tanh of a Q16 value (`x / 65536`) as Q15 (`/ 32768`), by the table (module docs): the
/// input saturated to [−8, 8) (one `SSAT`), an index and a fraction, one interpolation; no
/// branch, no sign handling (the table covers both signs).
#[inline(always)]
pub fn tanh_q15(x_q16: i32) -> i16 {
    const END: i32 = TANH_TABLE_MAX << 16;
    let shift = 16 - TANH_STEP_LOG2;
    let c = x_q16.clamp(-END, END - 1);
    // 0 ≤ u < 2·END, so i + 1 ≤ 2·END >> shift, the table's last index.
    let u = (c + END) as u32;
    let i = (u >> shift) as usize;
    let frac = (u & ((1 << shift) - 1)) as i32;
    let (y0, y1) = (i32::from(TANH_Q15[i]), i32::from(TANH_Q15[i + 1]));
    // Between y0 and y1, both within ±32767: no saturation needed.
    (y0 + (((y1 - y0) * frac + (1 << (shift - 1))) >> shift)) as i16
}

/// The Q15 MCU pass (see the module docs): `F` frames of history, `H` hidden units.
#[derive(Debug, Clone, PartialEq)]
pub struct NarxQ15<const F: usize, const H: usize> {
    lags: Lags,
    /// Row j, frame k: mantissas of (y, u), packed low/high.
    /// Per hidden unit, everything its step reads, side by side (one base address).
    rows: [QRow<F>; H],
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
    y_mean: f32,
    y_std: f32,
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
struct QRow<const F: usize> {
    /// Frame k: mantissas of (y, u), packed low/high.
    w: [u32; F],
    /// Bias in accumulator units.
    bias: i32,
    /// Right shift from the accumulator to Q16, minus 1 (see [`round_shift`]).
    shift: u32,
    /// Output-layer mantissa.
    w2: i32,
}

/// History of a running [`NarxQ15`]: frames of Q15 codes, y low, u high.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarxQ15State<const F: usize>(Ring<u32, F>);

/// Q15 code of a physical value: `(code, was clamped)`. Rounds to nearest (to within 1/128 of
/// an LSB: the f32 sum below has 2^-7 steps); NaN enters as the range's low end and counts as
/// clamped. Branch-free: one convert, a saturating subtract and one `SSAT`.
#[inline(always)]
fn enter_q15(x: f32, gain: f32, offset: f32) -> (i16, bool) {
    // r = floor(z + 0.5) + 98304 for z ≥ −98304 (truncation is floor there); smaller z, −∞
    // and NaN give r < 65536, so they count as clamped and enter as the low end.
    let r = (x * gain + offset + 98_304.5) as i32;
    let clamped = (r.wrapping_sub(65_536) as u32) > 65_535;
    let code = r.saturating_sub(98_304).clamp(-32_768, 32_767);
    (code as i16, clamped)
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
            y_mean: ys.mean as f32,
            y_std: ys.std as f32,
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
            let t = tanh_q15(round_shift(acc, row.shift));
            out = out.wrapping_add(row.w2 * i32::from(t));
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
        Scaling {
            mean: self.y_mean,
            std: self.y_std,
        }
    }

    fn state_at(&self, u: f32, y: f32) -> NarxQ15State<F> {
        let (qu, cu) = enter_q15(u, self.u_gain, self.u_offset);
        let (qy, cy) = enter_q15(y, self.y_gain, self.y_offset);
        NarxQ15State(Ring::filled(pack(qy, qu), cy, cu))
    }

    fn seed(&self, st: &mut NarxQ15State<F>, u: f32, y: f32) {
        let (qu, cu) = enter_q15(u, self.u_gain, self.u_offset);
        let (qy, cy) = enter_q15(y, self.y_gain, self.y_offset);
        st.0.push(pack(qy, qu), cy, cu);
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
                (sat as i16, sat != code)
            }
        };
        st.0.push(pack(qy, qu), cy, cu);
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

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn tanh_q15_error() {
        // Every non-negative Q16 input up to 10 (odd symmetry covers the rest), then a sparse
        // sweep to the end of the range.
        let mut worst: f64 = 0.0;
        let mut check = |bits: i32| {
            let x = f64::from(bits) / 65536.0;
            let err = (f64::from(tanh_q15(bits)) / 32768.0 - x.tanh()).abs();
            worst = worst.max(err);
        };
        for bits in 0..(10 << 16) {
            check(bits);
            check(-bits);
        }
        for bits in (10 << 16..i32::MAX).step_by(65_537) {
            check(bits);
        }
        check(i32::MIN);
        check(i32::MAX);
        assert!(worst <= TANH_Q15_MAX_ERROR, "max tanh error {worst:e}");
        assert!(
            worst > 0.5 * TANH_Q15_MAX_ERROR,
            "documented bound is loose: {worst:e}"
        );
    }

    /// Every f32 from 0 to +∞ (odd symmetry covers the rest: checked on a sweep), two threads.
    #[test]
    fn tanh_f32_error() {
        let worst = std::thread::scope(|s| {
            let halves: Vec<_> = [(0u32, 0x3F80_0000u32), (0x3F80_0000, 0x7F80_0001)]
                .into_iter()
                .map(|(a, b)| {
                    s.spawn(move || {
                        let mut worst = 0.0f64;
                        for bits in a..b {
                            let x = f32::from_bits(bits);
                            let e = (f64::from(tanh_f32(x)) - f64::from(x).tanh()).abs();
                            worst = worst.max(e);
                        }
                        worst
                    })
                })
                .collect();
            halves
                .into_iter()
                .map(|h| h.join().unwrap())
                .fold(0.0, f64::max)
        });
        for bits in (0..0x7F80_0000u32).step_by(9973) {
            let x = f32::from_bits(bits);
            assert_eq!(tanh_f32(-x), -tanh_f32(x), "odd at {x:e}");
        }
        assert!(tanh_f32(f32::NAN).is_nan());
        assert!(
            worst <= f64::from(TANH_F32_MAX_ERROR),
            "max error {worst:e}"
        );
        assert!(
            worst > 0.5 * f64::from(TANH_F32_MAX_ERROR),
            "bound loose: {worst:e}"
        );
        eprintln!("tanh_f32: max |error| over every f32 ≥ 0: {worst:.3e}");
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
