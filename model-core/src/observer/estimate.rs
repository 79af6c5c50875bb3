//! The observer's outputs: the [`Estimate`] after each step (states, the quantities derived
//! from them and every standard deviation, by the linearised covariance) and each channel's
//! [`Innovation`].

use super::process::Hydraulics;
use super::{
    nan_unless_finite, Observer, Vector, HEAD_SCALE, K2, RHO_G_W_PER_LPS_M, SPEED, TORQUE_SCALE,
};
use crate::equations::{pipe_loss_dq, pipe_loss_mca, valve_pressure_partials};
use crate::scalar::Real;

/// What happened to one measurement channel in a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Use {
    /// Nothing arrived.
    #[default]
    Missing,
    /// Not finite, or outside what the bench can show: not used.
    Implausible,
    /// Innovation outside the gate: not used.
    Rejected,
    /// Used.
    Used,
}

/// One channel's innovation (measured − predicted) in a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation<T> {
    /// What was done with it.
    pub used: Use,
    /// Measured − predicted, in the channel's unit (0 if missing or implausible).
    pub value: T,
    /// Normalised square `value² / S` (0 if missing or implausible).
    pub nis: T,
}

/// The observer's estimate after a step. Standard deviations are 1 σ, from the linearised
/// covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate<T> {
    /// Speed, rpm.
    pub speed_rpm: T,
    /// Flow, l/s.
    pub flow_lps: T,
    /// Outlet pressure Hs, mca (what a pressure transmitter would read with no lag).
    pub pressure_mca: T,
    /// Valve coefficient k2.
    pub valve_k2: T,
    /// Pump-head curve scale (1: the paper's fit).
    pub head_scale: T,
    /// Load-torque curve scale (1: the paper's fit).
    pub torque_scale: T,
    /// Pump head `s_H F_H(ω, Q)`, mca.
    pub pump_head_mca: T,
    /// Pipe loss `k1 Q²`, mca.
    pub pipe_loss_mca: T,
    /// Hydraulic power `ρ g Q H`, W.
    pub hydraulic_power_w: T,
    /// Load torque `s_T F_T(ω, Q)`, % of nominal: what the pump needs at this speed and flow.
    pub load_torque_pct: T,
    /// Standard deviation of speed, rpm.
    pub speed_sd_rpm: T,
    /// Standard deviation of flow, l/s.
    pub flow_sd_lps: T,
    /// Standard deviation of pressure, mca.
    pub pressure_sd_mca: T,
    /// Standard deviation of k2.
    pub valve_k2_sd: T,
    /// Standard deviation of the head scale.
    pub head_scale_sd: T,
    /// Standard deviation of the load-torque scale.
    pub torque_scale_sd: T,
    /// Standard deviation of the pump head, mca.
    pub pump_head_sd_mca: T,
    /// Standard deviation of the pipe loss, mca.
    pub pipe_loss_sd_mca: T,
    /// Standard deviation of the hydraulic power, W.
    pub hydraulic_power_sd_w: T,
    /// Pressure innovation.
    pub pressure: Innovation<T>,
    /// Flow innovation.
    pub flow: Innovation<T>,
    /// VFD speed innovation.
    pub speed: Innovation<T>,
}

impl<T: Real> Innovation<T> {
    pub(super) fn none(used: Use) -> Self {
        Self {
            used,
            value: T::ZERO,
            nis: T::ZERO,
        }
    }
}

impl<T: Real> Observer<T> {
    /// Standard deviation of `jᵀ (ω, k2, s_H)` (linearised): what every derived quantity
    /// depends on. The 3×3 block of P is symmetric: six products.
    pub(super) fn sd3(&self, j: &[T; 3]) -> T {
        let p = &self.p;
        let (a, b, c) = (j[SPEED], j[K2], j[HEAD_SCALE]);
        let two = T::from_f64(2.0);
        let v = a * a * p[SPEED][SPEED]
            + b * b * p[K2][K2]
            + c * c * p[HEAD_SCALE][HEAD_SCALE]
            + two
                * (a * b * p[SPEED][K2] + a * c * p[SPEED][HEAD_SCALE] + b * c * p[K2][HEAD_SCALE]);
        v.max(T::ZERO).sqrt()
    }

    /// Standard deviation of state `i`.
    pub(super) fn sd_state(&self, i: usize) -> T {
        self.p[i][i].max(T::ZERO).sqrt()
    }

    pub(super) fn estimate(
        &self,
        h: &Hydraulics<T>,
        pressure: Innovation<T>,
        flow: Innovation<T>,
        speed: Innovation<T>,
    ) -> Estimate<T> {
        let x = &self.x;
        let par = &self.cfg.params;
        // The flow through the water column's lag; the sensitivities are the root's.
        let (k2, q, s_h) = (x[K2], self.flow_now, x[HEAD_SCALE]);
        // Every derived quantity depends on (ω, k2, s_H) alone: sensitivities as 3-vectors.
        let j_q = h.dq;
        let e_q = self.inertia_flow_sd();
        let (a_p, hs_k2) = valve_pressure_partials(k2, q);
        let e_p = a_p * e_q;
        let j_p = [a_p * j_q[0], a_p * j_q[1] + hs_k2, a_p * j_q[2]];
        // Pump head s_H F_H(ω, Q(ω, k2, s_H)).
        let head = s_h * h.head.value;
        let a_h = s_h * h.head.d_flow;
        let j_h = [
            a_h * j_q[0] + s_h * h.head.d_speed,
            a_h * j_q[1],
            a_h * j_q[2] + h.head.value,
        ];
        let pipe = pipe_loss_mca(par.pipe_k1, q);
        let rho_g = T::from_f64(RHO_G_W_PER_LPS_M);
        let power = rho_g * q * head;
        let j_pow: [T; 3] = core::array::from_fn(|a| rho_g * (head * j_q[a] + q * j_h[a]));
        let sd_q = self.sd3(&j_q);
        Estimate {
            speed_rpm: x[SPEED],
            flow_lps: q,
            pressure_mca: self.outlet_pressure(x, q),
            valve_k2: k2,
            head_scale: s_h,
            torque_scale: x[TORQUE_SCALE],
            pump_head_mca: head,
            pipe_loss_mca: pipe,
            hydraulic_power_w: power,
            load_torque_pct: x[TORQUE_SCALE] * h.torque.value,
            speed_sd_rpm: self.sd_state(SPEED),
            flow_sd_lps: hypot(sd_q, e_q),
            pressure_sd_mca: hypot(self.sd3(&j_p), e_p),
            valve_k2_sd: self.sd_state(K2),
            head_scale_sd: self.sd_state(HEAD_SCALE),
            torque_scale_sd: self.sd_state(TORQUE_SCALE),
            pump_head_sd_mca: self.sd3(&j_h),
            pipe_loss_sd_mca: pipe_loss_dq(par.pipe_k1, q).abs() * sd_q,
            hydraulic_power_sd_w: self.sd3(&j_pow),
            pressure,
            flow,
            speed,
        }
    }
}

/// Never used: [`Observer::reset`] sets the estimate before any caller sees the observer.
/// Zero flow and the state's speed and k2, so that even a bug shows nothing wild.
pub(super) fn unreachable_estimate<T: Real>(x: &Vector<T>) -> Estimate<T> {
    let z = T::ZERO;
    let none = Innovation::none(Use::Missing);
    Estimate {
        speed_rpm: x[SPEED],
        flow_lps: z,
        pressure_mca: z,
        valve_k2: x[K2],
        head_scale: x[HEAD_SCALE],
        torque_scale: x[TORQUE_SCALE],
        pump_head_mca: z,
        pipe_loss_mca: z,
        hydraulic_power_w: z,
        load_torque_pct: z,
        speed_sd_rpm: z,
        flow_sd_lps: z,
        pressure_sd_mca: z,
        valve_k2_sd: z,
        head_scale_sd: z,
        torque_scale_sd: z,
        pump_head_sd_mca: z,
        pipe_loss_sd_mca: z,
        hydraulic_power_sd_w: z,
        pressure: none,
        flow: none,
        speed: none,
    }
}

/// √(a² + b²).
fn hypot<T: Real>(a: T, b: T) -> T {
    (a * a + b * b).sqrt()
}

pub(super) fn estimate_finite<T: Real>(e: &Estimate<T>) -> bool {
    // One sum of `v − v` (0 if finite, NaN if not), written out (see `healthy`).
    let z = nan_unless_finite::<T>;
    let sum = (z(e.speed_rpm) + z(e.flow_lps) + z(e.pressure_mca) + z(e.valve_k2))
        + (z(e.head_scale) + z(e.torque_scale) + z(e.pump_head_mca) + z(e.pipe_loss_mca))
        + (z(e.hydraulic_power_w) + z(e.load_torque_pct) + z(e.speed_sd_rpm))
        + (z(e.flow_sd_lps) + z(e.pressure_sd_mca) + z(e.valve_k2_sd) + z(e.head_scale_sd))
        + (z(e.torque_scale_sd) + z(e.pump_head_sd_mca) + z(e.pipe_loss_sd_mca))
        + (z(e.hydraulic_power_sd_w) + z(e.pressure.value) + z(e.pressure.nis))
        + (z(e.flow.value) + z(e.flow.nis) + z(e.speed.value) + z(e.speed.nis));
    sum == T::ZERO
}
