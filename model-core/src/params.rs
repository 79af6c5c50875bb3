//! Parameters of the white-box bench, with the paper's values as defaults.
//!
//! Units (the paper does not state them; these are the ones its coefficients were fitted in,
//! see the crate docs): speed in **rpm** inside the polynomials, flow in **l/s**, heads in
//! **metres of water column (mca)**, torques in **percent of the nominal torque** (39.9 Nm).

use crate::error::BenchError;
use crate::scalar::{PerScalar, Real};

/// Nominal motor torque, N·m: 100 % torque reference.
pub const NOMINAL_TORQUE_NM: f64 = 39.9;
/// Lowest speed of the data the paper's polynomials were fitted on: 11.7π rad/s = 351 rpm.
pub const FITTED_SPEED_MIN_RPM: f64 = 351.0;
/// Highest speed of the fitting data: 58.3π rad/s = 1749 rpm (the pump's nominal speed).
pub const FITTED_SPEED_MAX_RPM: f64 = 1749.0;
/// Highest flow of the fitting data, l/s (the lowest is 0 l/s).
pub const FITTED_FLOW_MAX_LPS: f64 = 27.8;
/// rpm per rad/s (30/π).
pub const RPM_PER_RAD_S: f64 = 30.0 / core::f64::consts::PI;

/// Eq. (4), γ1..γ6: `Te(u) = γ1 u^5 + … + γ5 u + γ6`, u and Te in % of nominal torque.
pub const PAPER_GAMMA: [f64; 6] = [-1.506e-8, 3.843e-6, -3.319e-4, 1.263e-2, 0.707, 2.244];
/// Eq. (5), α1..α10 of the pump head `F_H(ω, Q)` in mca (ω in rpm, Q in l/s).
pub const PAPER_ALPHA: [f64; 10] = [
    -1.3631e-3, 1.3620e-9, 1.7304e-5, -7.3548e-8, -2.5497e-2, 5.7314e-6, 1.0691e-4, -9.6703e-2,
    4.4057e-3, -2.5259e-1,
];
/// Eq. (6), β1..β10 of the load torque `F_T(ω, Q)` in % of nominal torque (ω in rpm, Q in l/s).
/// It already holds the viscous (b·ω) and Coulomb (Tc) friction.
pub const PAPER_BETA: [f64; 10] = [
    -2.5186e-3,
    -9.1168e-10,
    6.9103e-5,
    2.5492e-7,
    -5.6126e-2,
    1.0972e-5,
    6.8286e-4,
    6.5038e-1,
    3.6776e-3,
    4.3067e-1,
];
/// Eq. (7): fixed pipe loss coefficient k1, mca/(l/s)².
pub const PAPER_K1: f64 = 2.5e-2;
/// Eq. (8): valve coefficient k2 of the half-open valve, √mca/(l/s).
pub const PAPER_K2: f64 = 1.082e-1;
/// Eq. (8): static head c (level difference transmitter to tank), mca.
pub const PAPER_C_MCA: f64 = 0.252;
/// Motor plus pump inertia J, kg·m².
pub const PAPER_INERTIA_KG_M2: f64 = 0.08872;

/// Coefficients and constants of the white-box bench (immutable configuration).
///
/// Build with [`BenchParams::paper`], change fields if needed, then hand it to
/// [`crate::WhiteBox::new`], which validates it. For f32 and f64 the paper's set is also a
/// `const` (`BenchParams::<f32>::PAPER`), and `validate_const` / `WhiteBox::new_const` do
/// the same at compile time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchParams<T> {
    /// γ1..γ6 of eq. (4), % of nominal torque per %^(5..0).
    pub gamma: [T; 6],
    /// α1..α10 of eq. (5): pump head in mca, speed in rpm, flow in l/s. α1 must be < 0.
    pub alpha: [T; 10],
    /// β1..β10 of eq. (6): load torque in % of nominal, speed in rpm, flow in l/s.
    pub beta: [T; 10],
    /// k1 of eq. (7), mca/(l/s)², ≥ 0.
    pub pipe_k1: T,
    /// k2 of eq. (8), √mca/(l/s), ≥ 0: the load (valve opening); changeable at run time.
    pub valve_k2: T,
    /// c of eq. (8), mca: static head; changeable at run time.
    pub static_head_c_mca: T,
    /// J, kg·m², > 0.
    pub inertia_kg_m2: T,
    /// Nominal torque, N·m (100 %), > 0.
    pub nominal_torque_nm: T,
}

impl<T: Real> BenchParams<T> {
    /// rpm/s of speed change per % of torque surplus: `(T_nom / 100) / J · 30/π` (≈ 42.95
    /// with the paper's J and T_nom), computed in `T` (in f32 within 2 ulps of the exact
    /// value; no f64 arithmetic on an f32 target). Gives what [`Self::accel_const`] gives.
    pub fn accel_rpm_per_s_per_pct(&self) -> T {
        crate::equations::accel_rpm_per_s_per_pct(self.nominal_torque_nm, self.inertia_kg_m2)
    }

    /// Checks every value: all finite, α1 < 0 (the pump head falls at high flow, so the flow
    /// balance always has a bounded largest root), k1 ≥ 0, k2 ≥ 0, J > 0, nominal torque > 0.
    pub fn validate(&self) -> Result<(), BenchError> {
        (T::per_scalar::<ValidateConst>())(self)
    }
}

impl BenchParams<f64> {
    /// The paper's coefficients as printed ([`PAPER_GAMMA`], [`PAPER_ALPHA`], [`PAPER_BETA`],
    /// [`PAPER_K1`], [`PAPER_K2`], [`PAPER_C_MCA`], [`PAPER_INERTIA_KG_M2`],
    /// [`NOMINAL_TORQUE_NM`]; units as in the fields): compile-time data.
    pub const PAPER: Self = Self {
        gamma: PAPER_GAMMA,
        alpha: PAPER_ALPHA,
        beta: PAPER_BETA,
        pipe_k1: PAPER_K1,
        valve_k2: PAPER_K2,
        static_head_c_mca: PAPER_C_MCA,
        inertia_kg_m2: PAPER_INERTIA_KG_M2,
        nominal_torque_nm: NOMINAL_TORQUE_NM,
    };

    /// Every value rounded to the nearest f32 (units unchanged); a `const fn`, so a `const`
    /// built with it holds f32 data and the target does no f64 arithmetic for it.
    pub const fn to_f32(&self) -> BenchParams<f32> {
        BenchParams {
            gamma: crate::scalar::to_f32(&self.gamma),
            alpha: crate::scalar::to_f32(&self.alpha),
            beta: crate::scalar::to_f32(&self.beta),
            pipe_k1: self.pipe_k1 as f32,
            valve_k2: self.valve_k2 as f32,
            static_head_c_mca: self.static_head_c_mca as f32,
            inertia_kg_m2: self.inertia_kg_m2 as f32,
            nominal_torque_nm: self.nominal_torque_nm as f32,
        }
    }
}

impl BenchParams<f32> {
    /// The paper's coefficients rounded to f32 (`BenchParams::<f64>::PAPER.to_f32()`, units
    /// as in the fields): compile-time data.
    pub const PAPER: Self = BenchParams::<f64>::PAPER.to_f32();
}

/// `const fn` twins of [`BenchParams::validate`] and [`BenchParams::accel_rpm_per_s_per_pct`]
/// for one concrete scalar type (generic `const fn` arithmetic is not possible on stable).
macro_rules! const_bench_params {
    ($t:ty) => {
        impl BenchParams<$t> {
            /// [`Self::validate`] as a `const fn`: the same rules, the same errors (a test
            /// holds them equal). A `const` item that turns an error into a `panic!` makes a
            /// bad parameter set a build error (see [`crate::WhiteBox`]).
            pub const fn validate_const(&self) -> Result<(), BenchError> {
                const fn all_finite<const N: usize>(a: &[$t; N]) -> bool {
                    let mut i = 0;
                    while i < N {
                        if !a[i].is_finite() {
                            return false;
                        }
                        i += 1;
                    }
                    true
                }
                let scalars = [
                    self.pipe_k1,
                    self.valve_k2,
                    self.static_head_c_mca,
                    self.inertia_kg_m2,
                    self.nominal_torque_nm,
                ];
                if !all_finite(&self.gamma)
                    || !all_finite(&self.alpha)
                    || !all_finite(&self.beta)
                    || !all_finite(&scalars)
                {
                    return Err(BenchError::InvalidParameter("non-finite coefficient"));
                }
                if !(self.alpha[0] < 0.0) {
                    return Err(BenchError::InvalidParameter("alpha1 must be negative"));
                }
                if self.pipe_k1 < 0.0 || self.valve_k2 < 0.0 {
                    return Err(BenchError::InvalidParameter("k1 and k2 must be >= 0"));
                }
                if !(self.inertia_kg_m2 > 0.0) || !(self.nominal_torque_nm > 0.0) {
                    return Err(BenchError::InvalidParameter(
                        "inertia and nominal torque must be > 0",
                    ));
                }
                Ok(())
            }

            /// [`Self::accel_rpm_per_s_per_pct`] as a `const fn` (rpm/s per %): the same
            /// operations in the same order, so the same value.
            pub const fn accel_const(&self) -> $t {
                crate::equations::accel_expr!(
                    self.nominal_torque_nm,
                    self.inertia_kg_m2,
                    100.0,
                    RPM_PER_RAD_S as $t
                )
            }
        }
    };
}

/// Each type's `validate_const`, for [`BenchParams::validate`]: one set of rules.
struct ValidateConst;

impl PerScalar for ValidateConst {
    type Of<R: Real> = fn(&BenchParams<R>) -> Result<(), BenchError>;
    const F32: fn(&BenchParams<f32>) -> Result<(), BenchError> = BenchParams::<f32>::validate_const;
    const F64: fn(&BenchParams<f64>) -> Result<(), BenchError> = BenchParams::<f64>::validate_const;
}

impl<T: Real> Default for BenchParams<T> {
    fn default() -> Self {
        Self::paper()
    }
}

const_bench_params!(f32);
const_bench_params!(f64);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_paper_is_the_f64_one_rounded() {
        let p = BenchParams::<f32>::PAPER;
        assert_eq!(p.gamma, PAPER_GAMMA.map(|x| x as f32));
        assert_eq!(p.alpha, PAPER_ALPHA.map(|x| x as f32));
        assert_eq!(p.beta, PAPER_BETA.map(|x| x as f32));
        let scalars = [p.pipe_k1, p.valve_k2, p.static_head_c_mca, p.inertia_kg_m2];
        let printed = [PAPER_K1, PAPER_K2, PAPER_C_MCA, PAPER_INERTIA_KG_M2];
        assert_eq!(scalars, printed.map(|x| x as f32));
        assert_eq!(p.nominal_torque_nm, NOMINAL_TORQUE_NM as f32);
        assert_eq!(BenchParams::<f32>::paper(), p);
        assert_eq!(BenchParams::<f64>::paper(), BenchParams::<f64>::PAPER);
        assert_eq!(BenchParams::<f64>::PAPER.gamma, PAPER_GAMMA);
    }

    /// `validate_const` gives what `validate` gives, valid or not.
    fn const_validation_is_validate<T: Real>(
        validate_const: fn(&BenchParams<T>) -> Result<(), BenchError>,
    ) {
        let changes: [fn(&mut BenchParams<T>); 15] = [
            |_| {},
            |p| p.alpha[0] = T::from_f64(1e-3),
            |p| p.alpha[0] = T::ZERO,
            |p| p.alpha[0] = T::from_f64(f64::NAN),
            |p| p.inertia_kg_m2 = T::ZERO,
            |p| p.inertia_kg_m2 = T::from_f64(-1.0),
            |p| p.nominal_torque_nm = T::ZERO,
            |p| p.pipe_k1 = T::from_f64(-1.0),
            |p| p.valve_k2 = T::from_f64(-1e-9),
            |p| p.valve_k2 = T::ZERO,
            |p| p.beta[3] = T::from_f64(f64::NAN),
            |p| p.gamma[5] = T::from_f64(f64::INFINITY),
            |p| p.static_head_c_mca = T::from_f64(f64::NEG_INFINITY),
            |p| p.static_head_c_mca = T::from_f64(-3.0),
            |p| p.pipe_k1 = T::from_f64(f64::NAN),
        ];
        let mut errors = 0;
        for (i, change) in changes.iter().enumerate() {
            let mut p = BenchParams::<T>::paper();
            change(&mut p);
            assert_eq!(validate_const(&p), p.validate(), "change {i}");
            errors += usize::from(p.validate().is_err());
        }
        assert_eq!(errors, 12);
    }

    #[test]
    fn const_validation_is_validate_f32_and_f64() {
        const_validation_is_validate::<f32>(BenchParams::<f32>::validate_const);
        const_validation_is_validate::<f64>(BenchParams::<f64>::validate_const);
    }

    #[test]
    fn accel_in_f32_is_within_two_ulps_of_f64() {
        for factor in [1.0f32, 1.05, 0.9, 3.0] {
            let mut p = BenchParams::<f32>::PAPER;
            p.inertia_kg_m2 *= factor;
            let exact =
                f64::from(p.nominal_torque_nm) / 100.0 / f64::from(p.inertia_kg_m2) * RPM_PER_RAD_S;
            let a = p.accel_rpm_per_s_per_pct();
            assert_eq!(a, p.accel_const());
            let ulps = (f64::from(a) - exact).abs() / f64::from(f32::EPSILON * a);
            assert!(ulps <= 2.0, "J × {factor}: {ulps} ulps");
        }
        let p = BenchParams::<f64>::PAPER;
        assert_eq!(p.accel_rpm_per_s_per_pct(), p.accel_const());
        assert!((p.accel_const() - 42.946).abs() < 1e-3);
    }
}
