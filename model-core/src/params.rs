//! Parameters of the white-box bench, with the paper's values as defaults.
//!
//! Units (the paper does not state them; these are the ones its coefficients were fitted in,
//! see the crate docs): speed in **rpm** inside the polynomials, flow in **l/s**, heads in
//! **metres of water column (mca)**, torques in **percent of the nominal torque** (39.9 Nm).

use crate::error::BenchError;
use crate::scalar::Real;

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
/// [`crate::WhiteBox::new`], which validates it.
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

fn conv<T: Real, const N: usize>(a: &[f64; N]) -> [T; N] {
    let mut out = [T::ZERO; N];
    for (o, &x) in out.iter_mut().zip(a.iter()) {
        *o = T::from_f64(x);
    }
    out
}

impl<T: Real> BenchParams<T> {
    /// The paper's coefficients (as printed), rounded to `T`.
    pub fn paper() -> Self {
        Self {
            gamma: conv(&PAPER_GAMMA),
            alpha: conv(&PAPER_ALPHA),
            beta: conv(&PAPER_BETA),
            pipe_k1: T::from_f64(PAPER_K1),
            valve_k2: T::from_f64(PAPER_K2),
            static_head_c_mca: T::from_f64(PAPER_C_MCA),
            inertia_kg_m2: T::from_f64(PAPER_INERTIA_KG_M2),
            nominal_torque_nm: T::from_f64(NOMINAL_TORQUE_NM),
        }
    }

    /// rpm/s of speed change per % of torque surplus: `(T_nom / 100) / J · 30/π` (≈ 42.95
    /// with the paper's J and T_nom), computed in f64 and rounded once.
    pub fn accel_rpm_per_s_per_pct(&self) -> T {
        T::from_f64(
            self.nominal_torque_nm.to_f64() / 100.0 / self.inertia_kg_m2.to_f64() * RPM_PER_RAD_S,
        )
    }

    /// Checks every value: all finite, α1 < 0 (the pump head falls at high flow, so the flow
    /// balance always has a bounded largest root), k1 ≥ 0, k2 ≥ 0, J > 0, nominal torque > 0.
    pub fn validate(&self) -> Result<(), BenchError> {
        let scalars = [
            self.pipe_k1,
            self.valve_k2,
            self.static_head_c_mca,
            self.inertia_kg_m2,
            self.nominal_torque_nm,
        ];
        let all = self
            .gamma
            .iter()
            .chain(self.alpha.iter())
            .chain(self.beta.iter())
            .chain(scalars.iter());
        for &x in all {
            if !x.is_finite() {
                return Err(BenchError::InvalidParameter("non-finite coefficient"));
            }
        }
        if !(self.alpha[0] < T::ZERO) {
            return Err(BenchError::InvalidParameter("alpha1 must be negative"));
        }
        if self.pipe_k1 < T::ZERO || self.valve_k2 < T::ZERO {
            return Err(BenchError::InvalidParameter("k1 and k2 must be >= 0"));
        }
        if !(self.inertia_kg_m2 > T::ZERO) || !(self.nominal_torque_nm > T::ZERO) {
            return Err(BenchError::InvalidParameter(
                "inertia and nominal torque must be > 0",
            ));
        }
        Ok(())
    }
}

impl<T: Real> Default for BenchParams<T> {
    fn default() -> Self {
        Self::paper()
    }
}
