//! One code path for `f32` (the MCU) and `f64` (the host) through a small scalar trait.
//!
//! Only `sqrt`, `abs` and `tanh` need a maths library; all come from `libm` (pure Rust, no_std, the
//! same routines on the host and the target, correctly rounded `sqrt`). `micromath` was not
//! chosen: its `sqrt` is an approximation (~5 % error bound documented), far outside the
//! 1e-4 budget of the f32 model. `sqrt` is not on the hot path: the flow solver only needs
//! it when the flow-balance cubic is not monotone, which never happens with the paper's
//! coefficients inside the fitted range (see [`crate::flow`]).

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// A real scalar: implemented for `f32` and `f64`.
pub trait Real:
    Copy
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// Machine epsilon (distance from 1 to the next representable value).
    const EPSILON: Self;
    /// Conversion from `f64`, rounding to nearest.
    fn from_f64(x: f64) -> Self;
    /// Exact conversion to `f64`.
    fn to_f64(self) -> f64;
    /// Square root (correctly rounded, `libm`); NaN for negative input.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// `true` unless NaN or infinite.
    fn is_finite(self) -> bool;
    /// The larger of two values (the non-NaN one if one is NaN).
    fn max(self, other: Self) -> Self;
    /// The smaller of two values (the non-NaN one if one is NaN).
    fn min(self, other: Self) -> Self;
    /// Hyperbolic tangent (`libm`).
    fn tanh(self) -> Self;
    /// Exponential (`libm`).
    fn exp(self) -> Self;
    /// `P`'s value for this type ([`PerScalar::F32`] or [`PerScalar::F64`]): how generic code
    /// reaches a model's compile-time data and `const fn`s of one concrete type.
    fn per_scalar<P: PerScalar>() -> P::Of<Self>;
}

/// A value given once per scalar type, known at compile time: what a model written for
/// f32 and f64 as `const` data and `const fn`s (generic `const fn` arithmetic is not possible
/// on stable) hands to its generic, run-time API through [`Real::per_scalar`]. The trait
/// knows nothing of the models: they implement it (e.g. the paper's bench, the `const fn`
/// that validates a parameter set), and the layers point from the models to the scalar.
///
/// ```
/// use model_core::scalar::{PerScalar, Real};
/// struct Bits;
/// impl PerScalar for Bits {
///     type Of<R: Real> = u32;
///     const F32: u32 = 32;
///     const F64: u32 = 64;
/// }
/// fn bits<T: Real>() -> u32 {
///     T::per_scalar::<Bits>()
/// }
/// assert_eq!((bits::<f32>(), bits::<f64>()), (32, 64));
/// ```
pub trait PerScalar {
    /// The value's type for the scalar `R`.
    type Of<R: Real>;
    /// The value for `f32`.
    const F32: Self::Of<f32>;
    /// The value for `f64`.
    const F64: Self::Of<f64>;
}

impl Real for f32 {
    #[inline(always)]
    fn per_scalar<P: PerScalar>() -> P::Of<Self> {
        P::F32
    }
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f32::EPSILON;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn sqrt(self) -> Self {
        crate::dsp::sqrt_f32(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    // IEEE maxNum/minNum (a NaN operand gives the other) by comparisons: `f32::max`/`min`
    // are library calls (`fmaxf`, `fminf`) on a Cortex-M4F, whose FPU has no VMAXNM.
    #[inline]
    fn max(self, other: Self) -> Self {
        if other.is_nan() || self > other {
            self
        } else {
            other
        }
    }
    #[inline]
    fn min(self, other: Self) -> Self {
        if other.is_nan() || self < other {
            self
        } else {
            other
        }
    }
    #[inline]
    fn tanh(self) -> Self {
        libm::tanhf(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::expf(self)
    }
}

impl Real for f64 {
    #[inline(always)]
    fn per_scalar<P: PerScalar>() -> P::Of<Self> {
        P::F64
    }
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const EPSILON: Self = f64::EPSILON;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn max(self, other: Self) -> Self {
        f64::max(self, other)
    }
    #[inline]
    fn min(self, other: Self) -> Self {
        f64::min(self, other)
    }
    #[inline]
    fn tanh(self) -> Self {
        libm::tanh(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
}

/// `a` with each element rounded to the nearest f32; `const`, for compile-time data.
pub const fn to_f32<const N: usize>(a: &[f64; N]) -> [f32; N] {
    let mut out = [0.0f32; N];
    let mut i = 0;
    while i < N {
        out[i] = a[i] as f32;
        i += 1;
    }
    out
}
