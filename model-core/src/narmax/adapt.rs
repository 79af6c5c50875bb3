//! A NARMAX model that follows the load: the identified network runs free, its weights
//! untouched, and an affine map of its output is estimated on line from the measurements.
//!
//! ```text
//! z = (ŷ − mean) / std                (ŷ: the network's free-run output; its training scaling)
//! y = mean + std · (a·z + b)          (the model's output, adapted)
//! ```
//!
//! `(a, b)` is the exponentially weighted least-squares fit of the measurements on `(z, 1)`,
//! regularised toward the identity `(1, 0)`:
//!
//! ```text
//! R ← λR + (1 − λ)(x xᵀ + δ I),   v ← λv + (1 − λ)(x z_m + δ (1, 0)),   (a, b) = R⁻¹ v,   x = (z, 1)
//! ```
//!
//! with `λ = exp(−Ts / τ)` (a memory of τ seconds) and `z_m` the measurement in the same
//! scaling.
//!
//! Why this form, measured on `bench-data` records with valve steps (docs/narmax.md): a valve
//! moved ±30 % changes the pressure the torque gives by −50..+60 %, and the best static affine
//! map of the unadapted free run onto the truth brings every valve segment back to the
//! fixed-valve error. Recursive least squares on the network's output layer, fed back through
//! its own predictions, diverged on the pressure model (a free run is a recurrent system: a
//! small change of its output weights moves its poles); fitted on measured regressors it was
//! worse. Here the network's free run is the identified one, stable as identified, and the map
//! is static: it cannot make the model unstable.
//!
//! Numerical safety (the MCU runs it in f32 beside either NARMAX pass, f32 or Q15):
//! - `R` is a sum of positive semi-definite terms and `δ(1 − λ) I` per update: positive
//!   definite, its determinant at least δ² once it has forgotten its start (`δ I`), so the
//!   2 × 2 solve never divides by zero; `z` and `z_m` are clamped to ±[`Z_MAX`], so `R` and
//!   `v` are bounded; a pump at rest (constant `z`) fits `a·z + b` along that direction and
//!   keeps the identity across it: no covariance wind-up.
//! - `a` and `b` are kept within [`A_RANGE`] and ±[`B_MAX`]; a non-finite input is no
//!   sample.
//! - **Fallback**: if the adapted model's residual (exponentially weighted RMS, scaled) passes
//!   [`DIVERGED_RMS`] or the fit leaves its bounds, the map returns to the identity (the
//!   shipped model as it is) and [`Update::diverged`] says so (the controller raises the
//!   model-residual alarm). [`OutputMap::reset`] is the same return on demand.

use super::Scaling;
use crate::scalar::Real;

/// Largest |z| taken, in training standard deviations.
pub const Z_MAX: f64 = 8.0;
/// The map's gain range.
pub const A_RANGE: (f64, f64) = (0.2, 5.0);
/// The map's largest |offset|, in training standard deviations.
pub const B_MAX: f64 = 8.0;
/// Regularisation toward the identity, δ (in the units of `x xᵀ`: scaled², per sample).
pub const DELTA: f64 = 1e-3;
/// The adapted residual's RMS (scaled, over the map's memory) beyond which the map is reset.
pub const DIVERGED_RMS: f64 = 1.0;
/// The memory's range, s.
pub const TAU_RANGE_S: (f64, f64) = (0.1, 3600.0);

/// What the map cannot be built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdaptError {
    /// The memory τ is outside [`TAU_RANGE_S`], the sample period not > 0, or the
    /// scaling's std not > 0 (or a value not finite).
    Invalid,
}

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Update {
    /// The sample was taken (finite model output and measurement).
    pub taken: bool,
    /// The map left its bounds or the residual its limit: it is back at the identity.
    pub diverged: bool,
}

/// The adaptive output map (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputMap<T> {
    scaling: Scaling<T>,
    lambda: T,
    /// `R`'s entries r11, r12, r22.
    r: [T; 3],
    v: [T; 2],
    theta: [T; 2],
    /// Exponentially weighted mean square of the adapted residual, scaled.
    ms: T,
}

impl<T: Real> OutputMap<T> {
    /// The identity map for a model whose output has the training `scaling`, sampled every
    /// `sample_period_s`, with a memory of `tau_s` seconds.
    pub fn new(scaling: Scaling<T>, sample_period_s: T, tau_s: T) -> Result<Self, AdaptError> {
        let f = T::from_f64;
        let ok = scaling.mean.is_finite()
            && scaling.std.is_finite()
            && scaling.std > T::ZERO
            && sample_period_s.is_finite()
            && sample_period_s > T::ZERO
            && tau_s >= f(TAU_RANGE_S.0)
            && tau_s <= f(TAU_RANGE_S.1);
        if !ok {
            return Err(AdaptError::Invalid);
        }
        let mut m = Self {
            scaling,
            lambda: (-(sample_period_s / tau_s)).exp(),
            r: [T::ZERO; 3],
            v: [T::ZERO; 2],
            theta: [T::ONE, T::ZERO],
            ms: T::ZERO,
        };
        m.reset();
        Ok(m)
    }

    /// Back to the identity: the model's output as it is, the fit forgotten.
    pub fn reset(&mut self) {
        let d = T::from_f64(DELTA);
        self.r = [d, T::ZERO, d];
        self.v = [d, T::ZERO];
        self.theta = [T::ONE, T::ZERO];
        self.ms = T::ZERO;
    }

    /// The forgetting factor per sample, λ = exp(−Ts/τ).
    pub fn lambda(&self) -> T {
        self.lambda
    }

    /// The map now: gain `a` and offset `b` (scaled units).
    pub fn gain_offset(&self) -> (T, T) {
        (self.theta[0], self.theta[1])
    }

    /// The network's output `y_model` in the training scaling, clamped to ±[`Z_MAX`].
    fn z(&self, y: T) -> T {
        let zmax = T::from_f64(Z_MAX);
        self.scaling.scale(y).max(-zmax).min(zmax)
    }

    /// The adapted output for the network's output `y_model` (physical units); `y_model`
    /// itself if it is not finite.
    pub fn output(&self, y_model: T) -> T {
        if !y_model.is_finite() {
            return y_model;
        }
        let [a, b] = self.theta;
        self.scaling.unscale(a * self.z(y_model) + b)
    }

    /// Takes the measurement `measured` of the sample whose network output was `y_model`
    /// (after [`Self::output`] gave the prediction: the prediction never sees its own
    /// measurement).
    pub fn update(&mut self, y_model: T, measured: T) -> Update {
        if !(y_model.is_finite() && measured.is_finite()) {
            return Update::default();
        }
        let f = T::from_f64;
        let (lam, one_m) = (self.lambda, T::ONE - self.lambda);
        let (z, zm) = (self.z(y_model), self.z(measured));
        let [a, b] = self.theta;
        let e = zm - (a * z + b);
        self.ms = lam * self.ms + one_m * e * e;
        let d = f(DELTA);
        let [r11, r12, r22] = self.r;
        let r11 = lam * r11 + one_m * (z * z + d);
        let r12 = lam * r12 + one_m * z;
        let r22 = lam * r22 + one_m * (T::ONE + d);
        let v1 = lam * self.v[0] + one_m * (z * zm + d);
        let v2 = lam * self.v[1] + one_m * zm;
        self.r = [r11, r12, r22];
        self.v = [v1, v2];
        let det = r11 * r22 - r12 * r12;
        let a = (r22 * v1 - r12 * v2) / det;
        let b = (r11 * v2 - r12 * v1) / det;
        let inside = det > T::ZERO
            && a >= f(A_RANGE.0)
            && a <= f(A_RANGE.1)
            && b.abs() <= f(B_MAX)
            && self.ms <= f(DIVERGED_RMS * DIVERGED_RMS);
        if !inside {
            // Also catches NaN: every comparison with it is false.
            self.reset();
            return Update {
                taken: true,
                diverged: true,
            };
        }
        self.theta = [a, b];
        Update {
            taken: true,
            diverged: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const S: Scaling<f64> = Scaling {
        mean: 2.0,
        std: 1.0,
    };

    fn map(tau: f64) -> OutputMap<f64> {
        OutputMap::new(S, 0.05, tau).unwrap()
    }

    #[test]
    fn starts_as_the_identity_and_refuses_bad_settings() {
        let m = map(2.0);
        for y in [-3.0, 0.0, 2.0, 4.5] {
            assert!((m.output(y) - y).abs() < 1e-12);
        }
        assert!((m.lambda() - (-0.025f64).exp()).abs() < 1e-15);
        assert_eq!(OutputMap::new(S, 0.05, 0.05), Err(AdaptError::Invalid));
        assert_eq!(OutputMap::new(S, 0.0, 2.0), Err(AdaptError::Invalid));
        assert_eq!(OutputMap::new(S, 0.05, f64::NAN), Err(AdaptError::Invalid));
        let flat = Scaling {
            mean: 1.0,
            std: 0.0,
        };
        assert_eq!(OutputMap::new(flat, 0.05, 2.0), Err(AdaptError::Invalid));
        assert!(map(2.0).output(f64::NAN).is_nan());
    }

    /// The model's output `y`, the plant's `0.5 y + 0.3` (physical): the map finds it within
    /// a few memories, and its output follows.
    #[test]
    fn finds_an_affine_change_of_the_plant() {
        let mut m = map(2.0);
        let mut k = 0u32;
        let model = |k: u32| 2.0 + 1.5 * (0.37 * f64::from(k)).sin();
        while k < 400 {
            let y = model(k);
            let u = m.update(y, 0.5 * y + 0.3);
            assert!(u.taken && !u.diverged);
            k += 1;
        }
        let y = model(k);
        assert!(
            (m.output(y) - (0.5 * y + 0.3)).abs() < 1e-3,
            "{:?}",
            m.gain_offset()
        );
        // Back to the identity on demand.
        m.reset();
        assert!((m.output(y) - y).abs() < 1e-12);
    }

    /// A pump at rest: the same model output for minutes. The fit along that one point holds,
    /// nothing winds up, and a later change is followed as fast as from the start.
    #[test]
    fn no_wind_up_at_rest() {
        let mut m = map(2.0);
        for _ in 0..20_000 {
            assert!(!m.update(1.2, 1.5).diverged);
        }
        // The ridge toward the identity leaves δ / (|x|² + δ) of the step: 0.3 · 6e-4.
        assert!((m.output(1.2) - 1.5).abs() < 2e-4);
        let (a, b) = m.gain_offset();
        assert!(
            a.is_finite() && b.is_finite() && (a - 1.0).abs() < 0.5,
            "{a} {b}"
        );
        let mut fresh = map(2.0);
        let model = |k: u32| 2.0 + 1.5 * (0.37 * f64::from(k)).sin();
        for k in 0..400 {
            let y = model(k);
            m.update(y, 1.3 * y - 0.4);
            fresh.update(y, 1.3 * y - 0.4);
        }
        let y = model(400);
        for x in [&m, &fresh] {
            assert!((x.output(y) - (1.3 * y - 0.4)).abs() < 1e-3);
        }
    }

    #[test]
    fn a_wild_plant_resets_to_the_identity_and_says_so() {
        let mut m = map(2.0);
        let mut diverged = false;
        for k in 0..200 {
            let y = 2.0 + f64::from(k % 7) * 0.1;
            diverged |= m.update(y, 50.0).diverged;
        }
        assert!(diverged);
        // Non-finite inputs are no samples.
        let before = m;
        assert_eq!(m.update(f64::NAN, 1.0), Update::default());
        assert_eq!(m.update(1.0, f64::INFINITY), Update::default());
        assert_eq!(m, before);
    }

    proptest! {
        /// Any sequence of finite samples, any memory: the map stays within its bounds and
        /// finite, in f32 as in f64.
        #[test]
        fn bounded_and_finite(
            tau in 0.1f64..100.0,
            samples in proptest::collection::vec((-1e6f64..1e6, -1e6f64..1e6), 1..300),
        ) {
            let mut m = OutputMap::new(S, 0.05, tau).unwrap();
            let mut m32 = OutputMap::<f32>::new(
                Scaling { mean: 2.0, std: 1.0 }, 0.05, tau as f32).unwrap();
            for (y, meas) in samples {
                m.update(y, meas);
                m32.update(y as f32, meas as f32);
                let (a, b) = m.gain_offset();
                prop_assert!((A_RANGE.0..=A_RANGE.1).contains(&a) && b.abs() <= B_MAX);
                let (a, b) = m32.gain_offset();
                prop_assert!((A_RANGE.0 as f32..=A_RANGE.1 as f32).contains(&a));
                prop_assert!(b.abs() <= B_MAX as f32);
                prop_assert!(m.output(y).is_finite() && m32.output(y as f32).is_finite());
            }
        }
    }
}
