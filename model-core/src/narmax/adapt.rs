//! A NARMAX model that follows the load: the identified network runs free, its weights
//! untouched, and an affine map of its output is estimated on line from the measurements.
//!
//! ```text
//! z = (ŷ − mean) / std                (ŷ: the network's free-run output; its training scaling)
//! y = mean + std · (a·z + b)          (the model's output, adapted)
//! ```
//!
//! `(a, b)` is the exponentially weighted least-squares fit of the measurements on `(z, 1)`,
//! regularised toward the identity `(1, 0)`, the gain more than the offset:
//!
//! ```text
//! R ← λR + (1 − λ) x xᵀ,   v ← λv + (1 − λ) x z_m,   x = (z, 1)
//! (a, b) = (R + D)⁻¹ (v + D (1, 0)),   D = diag(δ_a, δ_b)
//! ```
//!
//! with `λ = exp(−Ts / τ)` (a memory of τ seconds), `z_m` the measurement in the same scaling,
//! and the fit kept within its bounds ([`A_RANGE`], ±[`B_MAX`]). With the torque held (a pump
//! under pressure control), the samples say only what `a·z + b` is at one `z`: the
//! regularisation then puts the change in the offset, the gain staying near 1, and the fit
//! follows the load there too.
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
//! Numerical safety (meant to run in f32 beside either MCU pass, f32 or Q15):
//! - `R` is kept without `D`, which is added at the solve: `R + D` is positive definite with a
//!   determinant of at least δ_a·δ_b whatever rounding does to the sums (their increments are
//!   exact to f32's precision down to a memory of 60 s at 50 ms, [`TAU_RANGE_S`]), so the
//!   2 × 2 solve never divides by zero; `z` and `z_m` are clamped to ±[`Z_MAX`] for the fit,
//!   so `R` and `v` are bounded; a non-finite input is no sample.
//! - **Fallback**: the map follows two exponentially weighted mean squares over a quarter of
//!   its memory, of its own residual and of the model's alone (`z_m − z`). If the map does
//!   worse than no map (its mean square over twice the model's and over ([`WORSE_FLOOR`])²:
//!   e.g. a valve back at the one the model was identified at while a long memory still
//!   holds the other), or a solve is not finite, it returns to the identity (the model as
//!   identified) and [`Update::diverged`] says so (a controller would raise its
//!   model-residual alarm).
//!   [`OutputMap::reset`] is the same return on demand.

use super::Scaling;
use crate::scalar::Real;

/// Largest |z| the fit takes, in training standard deviations.
pub const Z_MAX: f64 = 8.0;
/// The map's gain range.
pub const A_RANGE: (f64, f64) = (0.2, 5.0);
/// The map's largest |offset|, in training standard deviations.
pub const B_MAX: f64 = 8.0;
/// Regularisation of the gain toward 1, δ_a (scaled², as `R`'s entries).
pub const DELTA_GAIN: f64 = 1e-3;
/// Regularisation of the offset toward 0, δ_b: a hundredth of the gain's, so that what one
/// operating point cannot tell apart goes to the offset.
pub const DELTA_OFFSET: f64 = 1e-5;
/// The fallback's floor: the map's residual RMS (scaled) under which it is never judged worse
/// than no map.
pub const WORSE_FLOOR: f64 = 0.05;
/// The memory's range, s: below, the map would follow the noise; above, f32 sums stop
/// resolving the updates (1 − λ below 1e-3 at 50 ms).
pub const TAU_RANGE_S: (f64, f64) = (0.1, 60.0);

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
    /// The map did worse than no map, or its solve failed: it is back at the identity.
    pub diverged: bool,
}

/// The adaptive output map (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputMap<T> {
    scaling: Scaling<T>,
    lambda: T,
    /// The fallback's forgetting factor, over a quarter of the memory.
    lambda_check: T,
    /// `R`'s entries r11, r12, r22 (without `D`).
    r: [T; 3],
    /// `v` (without `D (1, 0)`).
    v: [T; 2],
    theta: [T; 2],
    /// Exponentially weighted mean squares (over a quarter of the memory) of the map's
    /// residual and of the model's alone, scaled.
    ms: [T; 2],
}

impl<T: Real> OutputMap<T> {
    /// The identity map for a model whose output has the training `scaling`, sampled every
    /// `sample_period_s`, with a memory of `tau_s` seconds. (Not inlined: its `exp` would be
    /// copied into every caller, ≈ 0.5 KB of flash each on the MCU.)
    #[inline(never)]
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
        let lambda = (-(sample_period_s / tau_s)).exp();
        let mut m = Self {
            scaling,
            lambda,
            // exp(−4 Ts/τ): a quarter of the memory.
            lambda_check: (lambda * lambda) * (lambda * lambda),
            r: [T::ZERO; 3],
            v: [T::ZERO; 2],
            theta: [T::ONE, T::ZERO],
            ms: [T::ZERO; 2],
        };
        m.reset();
        Ok(m)
    }

    /// Back to the identity: the model's output as it is, the fit forgotten.
    pub fn reset(&mut self) {
        self.r = [T::ZERO; 3];
        self.v = [T::ZERO; 2];
        self.theta = [T::ONE, T::ZERO];
        self.ms = [T::ZERO; 2];
    }

    /// The forgetting factor per sample, λ = exp(−Ts/τ).
    pub fn lambda(&self) -> T {
        self.lambda
    }

    /// The map now: gain `a` and offset `b` (scaled units).
    pub fn gain_offset(&self) -> (T, T) {
        (self.theta[0], self.theta[1])
    }

    /// The network's output `y` in the training scaling, clamped to ±[`Z_MAX`] (for the fit).
    fn z(&self, y: T) -> T {
        let zmax = T::from_f64(Z_MAX);
        self.scaling.scale(y).max(-zmax).min(zmax)
    }

    /// The adapted output for the network's output `y_model` (physical units): `y_model`
    /// itself at the identity, if it is not finite, and where the map's would not be (a
    /// `y_model` near the type's largest values).
    pub fn output(&self, y_model: T) -> T {
        let [a, b] = self.theta;
        if !y_model.is_finite() || (a == T::ONE && b == T::ZERO) {
            return y_model;
        }
        let y = self.scaling.unscale(a * self.scaling.scale(y_model) + b);
        if y.is_finite() {
            y
        } else {
            y_model
        }
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
        let (e, e0) = (zm - (a * z + b), zm - z);
        let lc = self.lambda_check;
        self.ms = [
            lc * self.ms[0] + (T::ONE - lc) * e * e,
            lc * self.ms[1] + (T::ONE - lc) * e0 * e0,
        ];
        let [r11, r12, r22] = self.r;
        self.r = [
            lam * r11 + one_m * z * z,
            lam * r12 + one_m * z,
            lam * r22 + one_m,
        ];
        self.v = [
            lam * self.v[0] + one_m * z * zm,
            lam * self.v[1] + one_m * zm,
        ];
        let (da, db) = (f(DELTA_GAIN), f(DELTA_OFFSET));
        let [r11, r12, r22] = self.r;
        let (r11, r22) = (r11 + da, r22 + db);
        let (v1, v2) = (self.v[0] + da, self.v[1]);
        let det = r11 * r22 - r12 * r12;
        let a = (r22 * v1 - r12 * v2) / det;
        let b = (r11 * v2 - r12 * v1) / det;
        let worse = self.ms[0] > f(2.0) * self.ms[1] && self.ms[0] > f(WORSE_FLOOR * WORSE_FLOOR);
        // `!(x > 0)` also catches NaN.
        if !(det > T::ZERO && a.is_finite() && b.is_finite()) || worse {
            self.reset();
            return Update {
                taken: true,
                diverged: true,
            };
        }
        let bmax = f(B_MAX);
        self.theta = [
            a.max(f(A_RANGE.0)).min(f(A_RANGE.1)),
            b.max(-bmax).min(bmax),
        ];
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

    /// A map learnt on one plant, the plant back to the model: the stale map does worse than
    /// no map and returns to the identity within its memory, saying so.
    #[test]
    fn a_map_worse_than_none_falls_back_to_the_identity() {
        let model = |k: u32| 2.0 + 1.5 * (0.37 * f64::from(k)).sin();
        for tau in [2.0, 20.0] {
            let mut m = map(tau);
            for k in 0..4000 {
                assert!(!m.update(model(k), 0.5 * model(k) + 0.3).diverged);
            }
            let memory = (tau / 0.05) as u32;
            let fell_back = (4000..4000 + memory).find(|&k| m.update(model(k), model(k)).diverged);
            let k = fell_back.expect("a fallback within the memory");
            println!(
                "memory {tau} s: fell back {} samples after the plant changed back",
                k - 4000
            );
            assert_eq!(m.gain_offset(), (1.0, 0.0));
            assert_eq!(m.output(2.7), 2.7);
        }
        // A plant beyond the map's reach: the fit stays within its bounds and keeps helping.
        let mut m = map(2.0);
        for k in 0..200 {
            let y = 2.0 + f64::from(k % 7) * 0.1;
            assert!(!m.update(y, 50.0).diverged);
        }
        let (a, b) = m.gain_offset();
        assert!(
            (A_RANGE.0..=A_RANGE.1).contains(&a) && b <= B_MAX,
            "{a} {b}"
        );
        assert!(m.output(2.3) > 9.0);
        // Non-finite inputs are no samples.
        let before = m;
        assert_eq!(m.update(f64::NAN, 1.0), Update::default());
        assert_eq!(m.update(1.0, f64::INFINITY), Update::default());
        assert_eq!(m, before);
    }

    /// An hour at rest in f32 with the longest memory: the sums keep resolving their updates,
    /// and the map still follows a change as the f64 one does.
    #[test]
    fn an_hour_at_rest_in_f32_with_the_longest_memory() {
        let s32 = Scaling {
            mean: 2.0f32,
            std: 1.0,
        };
        let mut m32 = OutputMap::new(s32, 0.05, TAU_RANGE_S.1 as f32).unwrap();
        let mut m64 = map(TAU_RANGE_S.1);
        for _ in 0..72_000 {
            m32.update(0.0, 0.1);
            m64.update(0.0, 0.1);
        }
        let model = |k: u32| 2.0 + 1.5 * (0.37 * f64::from(k)).sin();
        for k in 0..6_000 {
            let y = model(k);
            m32.update(y as f32, (1.2 * y - 0.3) as f32);
            m64.update(y, 1.2 * y - 0.3);
        }
        for y in [0.5, 2.0, 4.0] {
            let (a, b) = (m32.output(y as f32), m64.output(y));
            assert!((f64::from(a) - b).abs() < 2e-3, "{y}: f32 {a}, f64 {b}");
            assert!((b - (1.2 * y - 0.3)).abs() < 0.05, "{y}: {b}");
        }
    }

    proptest! {
        /// Any sequence of finite samples, any memory: the map stays within its bounds and
        /// finite, in f32 as in f64.
        #[test]
        fn bounded_and_finite(
            tau in 0.1f64..60.0,
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

        /// Whatever f32 gives it, finite or not (found by the controller's property test:
        /// a learnt map took −2.9e38 to −∞), the output is finite whenever the model's is.
        #[test]
        fn finite_output_for_any_finite_model_output(
            samples in proptest::collection::vec(
                (proptest::num::f32::ANY, proptest::num::f32::ANY), 1..200),
        ) {
            let mut m = OutputMap::<f32>::new(
                Scaling { mean: 2.0, std: 0.5 }, 0.05, 2.0).unwrap();
            for (y, meas) in samples {
                let out = m.output(y);
                prop_assert!(!y.is_finite() || out.is_finite(), "{} -> {}", y, out);
                m.update(y, meas);
                let (a, b) = m.gain_offset();
                prop_assert!(a.is_finite() && b.is_finite());
            }
            for y in [f32::MAX, -f32::MAX, 1e30, -1e30] {
                prop_assert!(m.output(y).is_finite());
            }
        }
    }
}
