//! The bench's process model inside the observer: the flow balance's root and how it moves
//! (the paper's equations, [`crate::equations`], with the head and load-torque scales and
//! the valve as states), the speed's rate, the transition matrix Φ linearised at a state,
//! and the mean's integration over a step (Heun's method in sub-steps, the drive's, the
//! water column's and the transmitters' lags exact).

use super::config::ObserverConfig;
use super::{
    Observer, Vector, FLOW_LAGGED, HEAD_SCALE, K2, MAX_SUBSTEP_S, PRESSURE_LAGGED, SPEED, STATES,
    TORQUE_SCALE,
};
use crate::equations::{
    flow_balance, flow_balance_dq, flow_root_sensitivities, load_torque_partials,
    pump_head_partials, scaled_load_torque_pct, speed_derivative_rpm_per_s, system_k,
    valve_pressure_mca, valve_pressure_partials, CubicInFlow, Partials,
};
use crate::flow::solve_flow;
use crate::scalar::Real;
use crate::transmitter::{decay, lag_to};

/// Flow and its sensitivities at one state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Hydraulics<T> {
    pub(super) flow: T,
    /// dQ/d(ω, k2, s_H).
    pub(super) dq: [T; 3],
    /// F_H(ω, Q) (unscaled) and its partials in ω and Q.
    pub(super) head: Partials<T>,
    /// F_T(ω, Q) (unscaled) and its partials in ω and Q.
    pub(super) torque: Partials<T>,
}

impl<T: Real> Observer<T> {
    /// Flow at `x` (warm-started from the last solve).
    #[inline(never)]
    pub(super) fn flow(&mut self, x: &Vector<T>) -> T {
        let par = &self.cfg.params;
        let (w, k2, s_h) = (x[SPEED], x[K2], x[HEAD_SCALE]);
        let k = system_k(par.pipe_k1, k2);
        let g = flow_balance(&par.alpha, s_h, k, par.static_head_c_mca, w);
        let q = solve_flow(&g, self.flow_warm).flow_lps;
        self.flow_warm = q;
        q
    }

    /// dω/dt at `x` with electromagnetic torque `te` and flow `q` (l/s).
    pub(super) fn speed_rate(&self, x: &Vector<T>, te: T, q: T) -> T {
        let load = scaled_load_torque_pct(&self.cfg.params.beta, x[TORQUE_SCALE], x[SPEED], q);
        speed_derivative_rpm_per_s(te, load, self.accel)
    }

    /// The water column's time constant per unit of inertia at `x` for the flow balance's
    /// root `q`, s per mca·s²/l: `1 / |∂g/∂Q|` (times L, the time constant).
    pub(super) fn flow_tau_per_inertia(&self, x: &Vector<T>, q: T) -> T {
        let par = &self.cfg.params;
        let (w, k2, s_h) = (x[SPEED], x[K2], x[HEAD_SCALE]);
        let head_dq = CubicInFlow::from_poly(&par.alpha, w).slope(q);
        let slope = flow_balance_dq(head_dq, s_h, system_k(par.pipe_k1, k2), q);
        // |∂g/∂Q| ≥ 0.05 mca per l/s: a flat balance (no flow) must not freeze the flow.
        T::ONE / slope.abs().max(T::from_f64(0.05))
    }

    /// Flow at `x` with the partials the linearisation and the standard deviations need.
    #[inline(never)]
    pub(super) fn hydraulics(&mut self, x: &Vector<T>) -> Hydraulics<T> {
        let q = self.flow(x);
        let par = &self.cfg.params;
        let (w, k2, s_h) = (x[SPEED], x[K2], x[HEAD_SCALE]);
        let head = pump_head_partials(&par.alpha, w, q);
        let torque = load_torque_partials(&par.beta, w, q);
        let dq = flow_root_sensitivities(&head, s_h, par.pipe_k1, k2, q);
        Hydraulics {
            flow: q,
            dq,
            head,
            torque,
        }
    }

    pub(super) fn outlet_pressure(&self, x: &Vector<T>, q: T) -> T {
        valve_pressure_mca(x[K2], self.cfg.params.static_head_c_mca, q)
    }

    /// The rows of the transition matrix Φ over `dt` that are not the identity's (for
    /// [`SPEED`], [`PRESSURE_LAGGED`] and [`FLOW_LAGGED`]; k2 and the scales are random
    /// walks), linearised at the hydraulics `h0` where the step starts: second order in
    /// speed, exact in the transmitters' lags.
    #[inline(always)]
    pub(super) fn transition(
        &self,
        h0: &Hydraulics<T>,
        k: &StepConsts<T>,
        dt: T,
    ) -> [Vector<T>; 3] {
        let two = T::from_f64(2.0);
        let s_t = self.x[TORQUE_SCALE];
        let a = self.accel;
        let (torque, torque_w, torque_q) = (h0.torque.value, h0.torque.d_speed, h0.torque.d_flow);
        let a_ww = -a * s_t * (torque_w + torque_q * h0.dq[0]);
        let a_w = [
            a_ww,
            -a * s_t * torque_q * h0.dq[1],
            -a * s_t * torque_q * h0.dq[2],
            -a * torque,
        ];
        let adt = a_ww * dt;
        let mut phi = [[T::ZERO; STATES]; 3];
        let through = dt * (T::ONE + adt / two);
        phi[0][SPEED] = T::ONE + adt + adt * adt / two;
        phi[0][1] = a_w[1] * through;
        phi[0][2] = a_w[2] * through;
        phi[0][3] = a_w[3] * through;
        // Outlet pressure sensitivities at the start: Hs = k2² Q² − c.
        let (hs_q, hs_k2) = valve_pressure_partials(self.x[K2], h0.flow);
        let hs = [hs_q * h0.dq[0], hs_q * h0.dq[1] + hs_k2, hs_q * h0.dq[2]];
        let (ap, aq) = (k.pressure_decay, k.flow_decay);
        phi[1][PRESSURE_LAGGED] = ap;
        phi[2][FLOW_LAGGED] = aq;
        // Through the speed at the end of the step, and directly for k2, s_H (written out).
        let (bp, bq) = (T::ONE - ap, T::ONE - aq);
        let (w0, w1, w2, w3) = (phi[0][0], phi[0][1], phi[0][2], phi[0][3]);
        phi[1][0] = bp * hs[0] * w0;
        phi[1][1] = bp * (hs[0] * w1 + hs[1]);
        phi[1][2] = bp * (hs[0] * w2 + hs[2]);
        phi[1][3] = bp * hs[0] * w3;
        phi[2][0] = bq * h0.dq[0] * w0;
        phi[2][1] = bq * (h0.dq[0] * w1 + h0.dq[1]);
        phi[2][2] = bq * (h0.dq[0] * w2 + h0.dq[2]);
        phi[2][3] = bq * h0.dq[0] * w3;
        phi
    }

    /// Advances the mean over `dt` by Heun's method in the sub-steps of `k`, from the
    /// hydraulics `h0` at the start, with the drive heading for `te` (% of nominal): speed,
    /// the lagged readings, the applied torque, the flow and its root, and what the
    /// uncertain water inertia makes of them.
    #[inline(always)]
    pub(super) fn advance_mean(&mut self, h0: &Hydraulics<T>, k: &StepConsts<T>, te: T, dt: T) {
        let two = T::from_f64(2.0);
        // The mean: Heun in sub-steps. The drive's torque is exact for Te(u) held over the
        // step; the flow follows the balance's root through the water column's lag (exact for
        // a root held over a sub-step), the transmitters follow the flow (ramp-exact).
        let h = k.substep_s;
        let te_start = self.te_applied;
        let te_at = |j: u32| te + (te_start - te) * k.drive_decay_pow(j);
        let inertia = self.cfg.water_inertia;
        let q_star0 = h0.flow;
        let mut q = self.flow_now;
        let (mut hs_start, mut q_start) = (self.outlet_pressure(&self.x, q), q);
        let mut q_star = q_star0;
        let mut tau = inertia * self.flow_tau_per_inertia(&self.x, q_star);
        // dω/dt at the start of a sub-step: the end of the last one's.
        let mut rate = self.speed_rate(&self.x, te_at(0), q);
        let mut per_inertia = T::ZERO;
        for j in 0..k.substeps {
            let x = self.x;
            let mut xe = x;
            xe[SPEED] = x[SPEED] + h * rate;
            let q_e_star = self.flow(&xe);
            let q_e = lag_to(q, q_e_star, h, tau);
            let rate_e = self.speed_rate(&xe, te_at(j + 1), q_e);
            self.x[SPEED] = x[SPEED] + h * (rate + rate_e) / two;
            q_star = self.flow(&self.x.clone());
            per_inertia = self.flow_tau_per_inertia(&self.x, q_star);
            tau = inertia * per_inertia;
            q = lag_to(q, q_star, h, tau);
            rate = self.speed_rate(&self.x, te_at(j + 1), q);
            let hs_end = self.outlet_pressure(&self.x, q);
            self.x[PRESSURE_LAGGED] = k.lag_p.advance(self.x[PRESSURE_LAGGED], hs_start, hs_end);
            self.x[FLOW_LAGGED] = k.lag_q.advance(self.x[FLOW_LAGGED], q_start, q);
            (hs_start, q_start) = (hs_end, q);
        }
        self.predicted = (hs_start, q_start);
        self.te_applied = te_at(k.substeps);
        self.flow_now = q;
        self.flow_star = q_star;
        self.flow_tau_sd_s = self.cfg.water_inertia_sd * per_inertia;
        self.flow_rate = (q_star - q_star0) / dt;
    }
}

/// What a step's `dt` fixes, computed again only when `dt` changes (the loop's is constant):
/// the sub-steps, the lags' decays over `dt` and their ramp-exact updates over a sub-step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct StepConsts<T> {
    pub(super) dt: T,
    substeps: u32,
    substep_s: T,
    pressure_decay: T,
    flow_decay: T,
    lag_p: Lag<T>,
    lag_q: Lag<T>,
    /// e^{−h/τ_d} of the drive's lag over one sub-step (0 without a lag).
    drive_decay: T,
}

impl<T: Real> StepConsts<T> {
    /// The drive lag's decay over `j` sub-steps.
    fn drive_decay_pow(&self, j: u32) -> T {
        let mut a = T::ONE;
        for _ in 0..j {
            a = a * self.drive_decay;
        }
        a
    }

    pub(super) fn new(cfg: &ObserverConfig<T>, dt: T) -> Self {
        // The fewest substeps of at most MAX_SUBSTEP_S, ≥ 1 (dt ≤ MAX_DT_S keeps it ≤ 400),
        // counted in T: no conversion through f64 (software on the MCU).
        // A step a few ulps over a multiple of the sub-step (times read from a file: 31.85 −
        // 31.8 is 0.05000000000000071 in f64, 0.05 in f32) takes no extra sub-step, so f32
        // and f64 integrate alike.
        let max_sub = T::from_f64(MAX_SUBSTEP_S * (1.0 + 1e-6));
        let (mut substeps, mut n) = (1u32, T::ONE);
        while n * max_sub < dt && substeps < 400 {
            substeps += 1;
            n += T::ONE;
        }
        let substep_s = dt / n;
        Self {
            dt,
            substeps,
            substep_s,
            pressure_decay: decay(dt, cfg.pressure_lag_s),
            flow_decay: decay(dt, cfg.flow_lag_s),
            lag_p: Lag::new(cfg.pressure_lag_s, substep_s),
            lag_q: Lag::new(cfg.flow_lag_s, substep_s),
            drive_decay: decay(substep_s, cfg.drive_lag_s),
        }
    }
}

/// A first-order lag `τ` over a step `h`, exact for a target that moves linearly across the
/// step: `x₁ = a x₀ + y₁ − a y₀ − (y₁ − y₀)(τ/h)(1 − a)`, `a = e^{−h/τ}` (τ = 0: `x₁ = y₁`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Lag<T> {
    a: T,
    /// (τ/h)(1 − a).
    ramp: T,
}

impl<T: Real> Lag<T> {
    fn new(tau: T, h: T) -> Self {
        if tau > T::ZERO {
            let a = decay(h, tau);
            Self {
                a,
                ramp: tau / h * (T::ONE - a),
            }
        } else {
            Self {
                a: T::ZERO,
                ramp: T::ZERO,
            }
        }
    }

    fn advance(&self, x0: T, y0: T, y1: T) -> T {
        self.a * x0 + y1 - self.a * y0 - (y1 - y0) * self.ramp
    }
}
