//! The torque reference's range and the one rule that maps any requested value into it.
//!
//! The drive takes a torque reference in **0..=100 % of the nominal torque** (39.9 N·m,
//! [`crate::params::NOMINAL_TORQUE_NM`]). Every part of the workspace that turns a requested
//! torque into the one the bench, the drive or a model sees uses [`applied_torque_pct`]; a
//! model that refuses what is outside the range instead of clamping it (the white-box bench)
//! uses its checked twin, [`checked_torque_pct`]. The rule, for any `f32`/`f64`:
//!
//! | requested | applied | checked |
//! |---|---|---|
//! | finite, in 0..=100 | itself | `Ok(itself)` |
//! | finite, below 0 | 0 | [`BenchError::TorqueOutOfRange`] |
//! | finite, above 100 | 100 | [`BenchError::TorqueOutOfRange`] |
//! | +∞ | 100 (the clamp's limit) | [`BenchError::NonFiniteTorque`] |
//! | −∞ | 0 | [`BenchError::NonFiniteTorque`] |
//! | NaN | 0: no valid request, the safe value (no torque) | [`BenchError::NonFiniteTorque`] |
//!
//! A zero result may carry either sign (−0.0 in, −0.0 or +0.0 out): both are 0 %.

use crate::error::BenchError;
use crate::scalar::Real;

/// The largest torque reference, % of nominal torque (the smallest is 0 %).
pub const MAX_TORQUE_PCT: f64 = 100.0;

/// The torque applied for a requested one, % of nominal torque: clamped to
/// 0..=[`MAX_TORQUE_PCT`], +∞ → 100, −∞ → 0, NaN → 0 (the safe value; see the module table).
///
/// Two comparisons and no branch on the MCU: NaN → 0 comes from [`Real::max`], which
/// returns its non-NaN operand (IEEE 754 maxNum).
#[inline]
pub fn applied_torque_pct<T: Real>(requested_pct: T) -> T {
    requested_pct.max(T::ZERO).min(T::from_f64(MAX_TORQUE_PCT))
}

/// A torque reference checked against the same range, % of nominal torque: `Ok` with the
/// value itself within 0..=[`MAX_TORQUE_PCT`], else [`BenchError::NonFiniteTorque`] (NaN,
/// ±∞) or [`BenchError::TorqueOutOfRange`] (finite, outside the range). Where it is `Ok`,
/// [`applied_torque_pct`] gives the same value.
#[inline]
pub fn checked_torque_pct<T: Real>(requested_pct: T) -> Result<T, BenchError> {
    if !requested_pct.is_finite() {
        Err(BenchError::NonFiniteTorque)
    } else if requested_pct < T::ZERO || requested_pct > T::from_f64(MAX_TORQUE_PCT) {
        Err(BenchError::TorqueOutOfRange)
    } else {
        Ok(requested_pct)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rule<T: Real>() {
        let f = T::from_f64;
        let cases = [
            (0.0, 0.0, Ok(0.0)),
            (42.5, 42.5, Ok(42.5)),
            (100.0, 100.0, Ok(100.0)),
            (-0.01, 0.0, Err(BenchError::TorqueOutOfRange)),
            (-1e30, 0.0, Err(BenchError::TorqueOutOfRange)),
            (100.01, 100.0, Err(BenchError::TorqueOutOfRange)),
            (1e30, 100.0, Err(BenchError::TorqueOutOfRange)),
            (f64::INFINITY, 100.0, Err(BenchError::NonFiniteTorque)),
            (f64::NEG_INFINITY, 0.0, Err(BenchError::NonFiniteTorque)),
            (f64::NAN, 0.0, Err(BenchError::NonFiniteTorque)),
        ];
        for (requested, applied, checked) in cases {
            let u = f(requested);
            let a = applied_torque_pct(u);
            assert!(a == f(applied), "{requested}: {a:?}");
            assert_eq!(checked_torque_pct(u), checked.map(f), "{requested}");
            if let Ok(c) = checked_torque_pct(u) {
                assert!(c == a, "{requested}");
            }
        }
        assert!(applied_torque_pct(f(-0.0)) == T::ZERO);
        // Finite values: the clamp itself, bit for bit (the observer's former rule).
        for i in -300..=1300 {
            let u = f(i as f64 * 0.0999);
            assert!(applied_torque_pct(u) == u.max(T::ZERO).min(f(100.0)), "{i}");
        }
    }

    #[test]
    fn one_rule_for_f32_and_f64() {
        rule::<f32>();
        rule::<f64>();
    }
}
