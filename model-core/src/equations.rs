//! The paper's equations (4)-(8), one function each. Units as in [`crate::params`].

use crate::scalar::Real;

/// A cubic in flow, `c3 Q³ + c2 Q² + c1 Q + c0`, whose coefficients depend on speed.
///
/// Both static maps of the paper, eqs. (5) and (6), are full cubics in (ω, Q); at a fixed
/// speed they become cubics in Q. This is the form the flow solver and the integrator use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CubicInFlow<T> {
    /// Coefficient of Q³.
    pub c3: T,
    /// Coefficient of Q².
    pub c2: T,
    /// Coefficient of Q.
    pub c1: T,
    /// Constant term.
    pub c0: T,
}

impl<T: Real> CubicInFlow<T> {
    /// Eq. (5)/(6) form `p1 Q³ + p2 ω³ + p3 Q²ω + p4 Qω² + p5 Q² + p6 ω² + p7 Qω + p8 Q + p9 ω + p10`
    /// at the speed `speed_rpm`, as a cubic in Q.
    #[inline]
    pub fn from_poly(p: &[T; 10], speed_rpm: T) -> Self {
        let w = speed_rpm;
        Self {
            c3: p[0],
            c2: p[2] * w + p[4],
            c1: (p[3] * w + p[6]) * w + p[7],
            c0: ((p[1] * w + p[5]) * w + p[8]) * w + p[9],
        }
    }

    /// Value at `q` (Horner).
    #[inline]
    pub fn eval(&self, q: T) -> T {
        ((self.c3 * q + self.c2) * q + self.c1) * q + self.c0
    }

    /// Derivative with respect to Q at `q`.
    #[inline]
    pub fn slope(&self, q: T) -> T {
        let three = T::from_f64(3.0);
        let two = T::from_f64(2.0);
        (three * self.c3 * q + two * self.c2) * q + self.c1
    }

    /// Sum of the magnitudes of the terms at `q`: the scale of the rounding error of
    /// [`Self::eval`] (which is at most a few ulps of this).
    #[inline]
    pub fn magnitude(&self, q: T) -> T {
        let a = q.abs();
        ((self.c3.abs() * a + self.c2.abs()) * a + self.c1.abs()) * a + self.c0.abs()
    }
}

/// Eq. (4): electromagnetic torque produced by the drive for a torque reference,
/// `Te(u) = γ1 u⁵ + γ2 u⁴ + γ3 u³ + γ4 u² + γ5 u + γ6`.
///
/// `torque_ref_pct` and the result in % of nominal torque (39.9 N·m); the fit holds for
/// 5..85 %; with the paper's γ, Te(0) = 2.24 % and Te(100) = 101.0 %.
#[inline]
pub fn electromagnetic_torque_pct<T: Real>(gamma: &[T; 6], torque_ref_pct: T) -> T {
    let u = torque_ref_pct;
    ((((gamma[0] * u + gamma[1]) * u + gamma[2]) * u + gamma[3]) * u + gamma[4]) * u + gamma[5]
}

/// Eq. (5): pump head `F_H(ω, Q) = α1 Q³ + α2 ω³ + α3 Q²ω + α4 Qω² + α5 Q² + α6 ω² + α7 Qω
/// + α8 Q + α9 ω + α10`, in mca, with ω in rpm and Q in l/s.
///
/// Fitted (17 % MAPE) on 351..1749 rpm and 0..27.8 l/s.
#[inline]
pub fn pump_head_mca<T: Real>(alpha: &[T; 10], speed_rpm: T, flow_lps: T) -> T {
    CubicInFlow::from_poly(alpha, speed_rpm).eval(flow_lps)
}

/// Eq. (6): load torque `F_T(ω, Q) = β1 Q³ + β2 ω³ + β3 Q²ω + β4 Qω² + β5 Q² + β6 ω² + β7 Qω
/// + β8 Q + β9 ω + β10`, in % of nominal torque, with ω in rpm and Q in l/s.
///
/// It is `b ω + Tc + F_load(ω, Q)` of eq. (3): friction is inside. Fitted (2.3 % MAPE) on
/// 351..1749 rpm and 0..27.8 l/s.
#[inline]
pub fn load_torque_pct<T: Real>(beta: &[T; 10], speed_rpm: T, flow_lps: T) -> T {
    CubicInFlow::from_poly(beta, speed_rpm).eval(flow_lps)
}

/// Eq. (7): pressure loss in the fixed pipe, `F_pipeline(Q) = k1 Q²`, in mca (Q in l/s).
#[inline]
pub fn pipe_loss_mca<T: Real>(pipe_k1: T, flow_lps: T) -> T {
    pipe_k1 * flow_lps * flow_lps
}

/// Eq. (8): flow through the valve, `Q = √(Hs + c) / k2`, in l/s, for an outlet pressure
/// `Hs` in mca. 0 when `Hs + c ≤ 0` (nothing to push water out) or `k2 = 0` is not
/// meaningful (returns +∞ for k2 = 0 and Hs + c > 0: a fully open valve).
#[inline]
pub fn valve_flow_lps<T: Real>(valve_k2: T, static_head_c_mca: T, pressure_mca: T) -> T {
    let head = pressure_mca + static_head_c_mca;
    if head > T::ZERO {
        head.sqrt() / valve_k2
    } else {
        T::ZERO
    }
}

/// Eq. (8) inverted: outlet pressure `Hs = k2² Q² − c` in mca for a flow in l/s.
///
/// With no flow this gives `−c`: the transmitter sits `c` above the tank level.
#[inline]
pub fn valve_pressure_mca<T: Real>(valve_k2: T, static_head_c_mca: T, flow_lps: T) -> T {
    valve_k2 * valve_k2 * flow_lps * flow_lps - static_head_c_mca
}

/// Eq. (3) with (6): `J dω/dt = Te(u) − F_T(ω, Q)`, as the rate of change of speed in rpm/s.
///
/// Torques in % of nominal; `accel_rpm_per_s_per_pct = (T_nom / 100) / J · 30/π` converts a
/// torque surplus in % into rpm/s (≈ 42.95 rpm/s per % with the paper's J and T_nom).
#[inline]
pub fn speed_derivative_rpm_per_s<T: Real>(
    electromagnetic_torque_pct: T,
    load_torque_pct: T,
    accel_rpm_per_s_per_pct: T,
) -> T {
    (electromagnetic_torque_pct - load_torque_pct) * accel_rpm_per_s_per_pct
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::*;

    #[test]
    fn te_is_almost_the_reference() {
        assert_eq!(electromagnetic_torque_pct(&PAPER_GAMMA, 0.0), 2.244);
        let te100 = electromagnetic_torque_pct(&PAPER_GAMMA, 100.0);
        assert!((te100 - 101.044).abs() < 1e-3, "{te100}");
        // "The nonlinearity is very small": within 3.5 points over the excitation range.
        let worst = (5..=85)
            .map(|u| (electromagnetic_torque_pct(&PAPER_GAMMA, u as f64) - u as f64).abs())
            .fold(0.0, f64::max);
        assert!(worst > 2.5 && worst < 3.5, "max |Te(u) - u| = {worst}");
    }

    #[test]
    fn polynomial_matches_its_printed_form() {
        let (w, q) = (1234.5, 17.25);
        let a = PAPER_ALPHA;
        let printed = a[0] * q * q * q
            + a[1] * w * w * w
            + a[2] * q * q * w
            + a[3] * q * w * w
            + a[4] * q * q
            + a[5] * w * w
            + a[6] * q * w
            + a[7] * q
            + a[8] * w
            + a[9];
        assert!((pump_head_mca(&a, w, q) - printed).abs() < 1e-12);
        let c = CubicInFlow::from_poly(&PAPER_BETA, w);
        let h = 1e-6;
        let numeric = (c.eval(q + h) - c.eval(q - h)) / (2.0 * h);
        assert!((c.slope(q) - numeric).abs() < 1e-6);
    }

    #[test]
    fn valve_relation_inverts() {
        for q in [0.5, 5.0, 19.2, 27.8] {
            let hs = valve_pressure_mca(PAPER_K2, PAPER_C_MCA, q);
            assert!((valve_flow_lps(PAPER_K2, PAPER_C_MCA, hs) - q).abs() < 1e-12);
        }
        assert_eq!(valve_flow_lps(PAPER_K2, PAPER_C_MCA, -1.0), 0.0);
        assert_eq!(pipe_loss_mca(PAPER_K1, 10.0), 2.5);
    }
}
