//! The observer: an extended Kalman filter on the white-box bench that estimates what the
//! controller does not measure (speed without an encoder, flow without a flow meter) and what
//! changes under it (the valve, the pump's and the load's curves), each with its standard
//! deviation. One code path for f32 (the MCU) and f64 (the host).
//!
//! # Model
//!
//! State (6): speed ω (rpm), valve coefficient k2 (mca^½·s/l), pump-head scale `s_H`, load-torque
//! scale `s_T` (both 1 for the paper's fits), and the two transmitters' lagged readings
//! `p_f` (mca) and `q_f` (l/s). The flow Q follows the largest non-negative root Q* of the
//! flow balance `g(Q) = s_H F_H(ω, Q) − (k1 + k2²) Q² + c` through the water column's inertia
//! (`L dQ/dt = g(Q)`, linearised: a first-order lag of `L / |∂g/∂Q|`, carried beside the
//! state, its uncertainty in the variances); the outlet pressure is `Hs = k2² Q² − c`. The
//! drive delivers Te(u) through its torque loop's first-order lag.
//!
//! ```text
//! dω/dt   = K (Te_d − s_T F_T(ω, Q))         K = T_nom/100/J · 30/π ≈ 42.95 rpm/s per %
//! dTe_d/dt = (Te(u) − Te_d) / τ_d             the drive's torque loop
//! dQ/dt   = (Q* − Q) / (L / |∂g/∂Q|)           the water column
//! dk2/dt, ds_H/dt, ds_T/dt = white noise      (random walks: the valve moves, curves drift)
//! dp_f/dt = (Hs − p_f) / τ_p                  pressure transmitter lag
//! dq_f/dt = (Q − q_f) / τ_q                   flow transmitter lag
//! ```
//!
//! Measurements are the lagged readings and the drive's speed, so each is one state:
//! pressure `y = p_f`, flow `y = q_f`, VFD speed `y = ω`. They are applied one at a time
//! (sequential scalar updates, Joseph form), each only when it arrives: any of them may be
//! missing for any length of time, and the filter runs on the others and on the model. A
//! channel missing for [`ObserverConfig::lost_after_s`] is lost, and the curve scales it made
//! observable are held (see [`Observer::held`]).
//!
//! # Discretisation
//!
//! [`Observer::step`] advances by `dt` with the torque reference held: the mean by Heun's
//! method in sub-steps of at most [`MAX_SUBSTEP_S`] (the drive's lag exactly, the water column
//! and the transmitters exactly for a target held over a sub-step), the covariance once per
//! call by the transition matrix linearised at the start (second order in speed, exact in the
//! lags), plus process noise. Then the measurements.
//!
//! # Robustness
//!
//! A measurement that is not finite or is physically implausible (pressure below −c − 0.5
//! mca or above 60 mca, flow below −0.5 l/s or above 60 l/s, speed below −50 or above 4000
//! rpm: a transmitter at 2 mA, a NaN) is not used. An innovation whose normalised square
//! exceeds [`ObserverConfig::gate_sigma`]² is rejected as an outlier, unless the channel has
//! been rejected [`ObserverConfig::max_rejections`] times in a row: then the change is taken
//! as real (the valve moved) and, for pressure and flow, k2's variance is raised by
//! [`ObserverConfig::k2_jump_sigma`]² before the update, so the filter re-converges in a few
//! samples instead of tens of seconds; one update moves k2 by at most [`MAX_K2_MOVE`] of
//! itself. The covariance is kept symmetric, its diagonal positive; k2 and the scales stay within
//! their configured ranges; a non-finite result restores the last good estimate. No output
//! is ever NaN.

use crate::equations::{
    electromagnetic_torque_pct, flow_balance, flow_balance_dq, flow_root_sensitivities,
    load_torque_partials, pipe_loss_dq, pipe_loss_mca, pump_head_partials, scaled_load_torque_pct,
    speed_derivative_rpm_per_s, system_k, valve_pressure_mca, valve_pressure_partials, CubicInFlow,
    Partials,
};
use crate::flow::solve_flow;
use crate::params::BenchParams;
use crate::scalar::Real;
use crate::units::applied_torque_pct;
use crate::BenchError;

/// Number of states.
pub const STATES: usize = 6;
// The states a prediction moves through Φ are SPEED, PRESSURE_LAGGED and FLOW_LAGGED (rows
// 0, 1, 2 of `phi` in `predict`); the others are random walks.
const _: () = assert!(SPEED == 0 && PRESSURE_LAGGED == 4 && FLOW_LAGGED == 5);
/// Index of speed, rpm.
pub const SPEED: usize = 0;
/// Index of the valve coefficient k2.
pub const K2: usize = 1;
/// Index of the pump-head scale.
pub const HEAD_SCALE: usize = 2;
/// Index of the load-torque scale.
pub const TORQUE_SCALE: usize = 3;
/// Index of the pressure transmitter's lagged reading, mca.
pub const PRESSURE_LAGGED: usize = 4;
/// Index of the flow transmitter's lagged reading, l/s.
pub const FLOW_LAGGED: usize = 5;

/// Largest relative move of k2 in one measurement update (see [`Observer::step`]'s
/// updates: a trust region for the linearisation).
pub const MAX_K2_MOVE: f64 = 0.15;
/// Longest sub-step of the mean's integration, s.
pub const MAX_SUBSTEP_S: f64 = 0.05;
/// Longest `dt` of one [`Observer::step`], s (the error message repeats it).
pub const MAX_DT_S: f64 = 10.0;
/// Water density × g, W per (l/s · m): hydraulic power P = 9.81 · Q (l/s) · H (m).
pub const RHO_G_W_PER_LPS_M: f64 = 9.806_65;

/// Tuning of the observer. Noise densities are per second of the random walk (variance grows
/// by `psd · dt`); standard deviations in the state's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverConfig<T> {
    /// The model: the paper's white-box bench by default.
    pub params: BenchParams<T>,
    /// Pressure transmitter's first-order lag, s (≥ 0).
    pub pressure_lag_s: T,
    /// Flow transmitter's first-order lag, s (≥ 0).
    pub flow_lag_s: T,
    /// How far the pressure transmitter's lag may be from `pressure_lag_s`, s (1 σ): while
    /// pressure moves at r mca/s its reading's variance grows by (this · r)².
    pub pressure_lag_sd_s: T,
    /// How far the flow transmitter's lag may be from `flow_lag_s`, s (1 σ), likewise.
    pub flow_lag_sd_s: T,
    /// The drive's torque loop: the electromagnetic torque follows Te(u) through a
    /// first-order lag of this time constant, s (≥ 0).
    pub drive_lag_s: T,
    /// How far the drive's lag may be from `drive_lag_s`, s (1 σ): a torque that changes by
    /// ΔTe over a step adds (K · this · ΔTe)² to the speed's variance (K in rpm/s per %).
    pub drive_lag_sd_s: T,
    /// Water-column inertia L, mca·s²/l (≥ 0): the flow follows the flow balance's root Q*
    /// with the time constant `L / |∂g/∂Q|` (g the flow balance, in mca).
    pub water_inertia: T,
    /// How far the inertia may be from `water_inertia`, mca·s²/l (1 σ): adds the flow's
    /// rate times the time constant it makes to the flow's and the readings' variances.
    pub water_inertia_sd: T,
    /// Process noise of speed, rpm²/s (model error of the torque balance).
    pub speed_psd: T,
    /// Random walk of k2, (mca^½·s/l)²/s.
    pub k2_psd: T,
    /// Random walk of the head scale, 1/s.
    pub head_scale_psd: T,
    /// Random walk of the load-torque scale, 1/s.
    pub torque_scale_psd: T,
    /// Process noise of the lagged readings, (unit)²/s (transmitter model error).
    pub lag_psd: T,
    /// Pressure measurement noise, mca (1 σ).
    pub pressure_sigma_mca: T,
    /// Flow measurement noise, l/s (1 σ).
    pub flow_sigma_lps: T,
    /// VFD speed reading noise, rpm (1 σ).
    pub speed_sigma_rpm: T,
    /// Initial standard deviations: speed rpm, k2, head scale, torque scale, p_f mca, q_f l/s.
    pub initial_sigma: [T; STATES],
    /// Innovation gate, in standard deviations of the innovation (> 0).
    pub gate_sigma: T,
    /// Rejections in a row after which a channel's innovation is taken as real (≥ 1).
    pub max_rejections: u8,
    /// Standard deviation added to k2 when a rejected change is taken as real.
    pub k2_jump_sigma: T,
    /// Range of k2 (min, max), > 0.
    pub k2_range: (T, T),
    /// Range of both curve scales (min, max), > 0.
    pub scale_range: (T, T),
    /// A measurement channel missing (or implausible) for longer than this, s, is lost: the
    /// curve scales it made observable are held until it returns (> 0; longer than the
    /// slowest channel's period, the flow's 100 ms).
    pub lost_after_s: T,
}

impl<T: Real> ObserverConfig<T> {
    /// Defaults for the paper's bench and this project's transmitters (pressure lag 20 ms,
    /// flow lag 40 ms, the noise of a 12-bit 4-20 mA reading), tuned on synthetic records
    /// whose valve steps ±30 % and whose curves are off by a few percent (see the tests).
    pub fn paper() -> Self {
        let f = T::from_f64;
        Self {
            params: BenchParams::paper(),
            pressure_lag_s: f(0.020),
            flow_lag_s: f(0.120),
            pressure_lag_sd_s: f(0.040),
            flow_lag_sd_s: f(0.100),
            drive_lag_s: f(0.025),
            drive_lag_sd_s: f(0.025),
            water_inertia: f(0.05),
            water_inertia_sd: f(0.075),
            speed_psd: f(400.0),
            k2_psd: f(1e-6),
            head_scale_psd: f(1e-7),
            torque_scale_psd: f(1e-7),
            lag_psd: f(1e-6),
            pressure_sigma_mca: f(0.006),
            flow_sigma_lps: f(0.04),
            speed_sigma_rpm: f(2.0),
            initial_sigma: [f(100.0), f(0.02), f(0.1), f(0.1), f(0.2), f(2.0)],
            gate_sigma: f(6.0),
            max_rejections: 5,
            k2_jump_sigma: f(0.02),
            k2_range: (f(0.02), f(1.0)),
            scale_range: (f(0.5), f(1.5)),
            lost_after_s: f(1.0),
        }
    }

    /// `Ok` if usable: valid model parameters, finite non-negative lags and noise densities,
    /// positive measurement noises, initial sigmas and gate, ordered positive ranges that hold
    /// the paper's values.
    pub fn validate(&self) -> Result<(), ObserverError> {
        self.params.validate().map_err(ObserverError::Model)?;
        let nonneg = |x: T| x.is_finite() && x >= T::ZERO;
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        let ok = nonneg(self.pressure_lag_s)
            && nonneg(self.flow_lag_s)
            && nonneg(self.pressure_lag_sd_s)
            && nonneg(self.flow_lag_sd_s)
            && nonneg(self.drive_lag_s)
            && nonneg(self.drive_lag_sd_s)
            && nonneg(self.water_inertia)
            && nonneg(self.water_inertia_sd)
            && nonneg(self.speed_psd)
            && nonneg(self.k2_psd)
            && nonneg(self.head_scale_psd)
            && nonneg(self.torque_scale_psd)
            && nonneg(self.lag_psd)
            && pos(self.pressure_sigma_mca)
            && pos(self.flow_sigma_lps)
            && pos(self.speed_sigma_rpm)
            && self.initial_sigma.iter().all(|&s| pos(s))
            && pos(self.gate_sigma)
            && self.max_rejections >= 1
            && nonneg(self.k2_jump_sigma)
            && pos(self.k2_range.0)
            && self.k2_range.1.is_finite()
            && self.k2_range.0 < self.k2_range.1
            && pos(self.scale_range.0)
            && self.scale_range.1.is_finite()
            && self.scale_range.0 < T::ONE
            && T::ONE < self.scale_range.1
            && pos(self.lost_after_s)
            && self.k2_range.0 <= self.params.valve_k2
            && self.params.valve_k2 <= self.k2_range.1;
        if ok {
            Ok(())
        } else {
            Err(ObserverError::Config)
        }
    }
}

/// Why an observer could not be built or stepped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObserverError {
    /// The model's parameters are not valid.
    Model(BenchError),
    /// A configuration value is out of range (see [`ObserverConfig::validate`]).
    Config,
    /// `dt` is not finite or not in (0, [`MAX_DT_S`]] s.
    Step,
}

impl core::fmt::Display for ObserverError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ObserverError::Model(e) => write!(f, "observer model: {e}"),
            ObserverError::Config => f.write_str("observer configuration out of range"),
            // A literal, not `{MAX_DT_S}`: float formatting would cost the MCU ≈ 10 KB.
            ObserverError::Step => f.write_str("observer step must be in (0, 10] s"),
        }
    }
}

/// What arrived since the last step (`None`: not measured this time).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measurements<T> {
    /// Pressure transmitter, mca.
    pub pressure_mca: Option<T>,
    /// Flow transmitter, l/s.
    pub flow_lps: Option<T>,
    /// Speed reported by the VFD, rpm.
    pub speed_rpm: Option<T>,
}

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

type Vector<T> = [T; STATES];
type Matrix<T> = [[T; STATES]; STATES];

/// Flow and its sensitivities at one state.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Hydraulics<T> {
    flow: T,
    /// dQ/d(ω, k2, s_H).
    dq: [T; 3],
    /// F_H(ω, Q) (unscaled) and its partials in ω and Q.
    head: Partials<T>,
    /// F_T(ω, Q) (unscaled) and its partials in ω and Q.
    torque: Partials<T>,
}

/// The observer.
#[derive(Debug, Clone, PartialEq)]
pub struct Observer<T> {
    cfg: ObserverConfig<T>,
    /// rpm/s per % of torque surplus.
    accel: T,
    x: Vector<T>,
    p: Matrix<T>,
    flow_warm: T,
    /// Electromagnetic torque the drive delivers now, % (Te(u) through the drive's lag).
    te_applied: T,
    /// Flow now, l/s: the flow balance's root Q* through the water column's lag.
    flow_now: T,
    /// The flow balance's root Q* at the state, l/s (where `flow_now` is heading).
    flow_star: T,
    /// How far the water column's time constant may be off at the last step, s (1 σ), and
    /// dQ*/dt over that step, l/s²: the flow is off by about their product.
    flow_tau_sd_s: T,
    flow_rate: T,
    rejections: [u8; 3],
    /// Time since each channel (pressure, flow, speed) last brought a plausible value, s.
    silent_s: [T; 3],
    /// Channels lost (see [`Observer::decide_holds`]).
    lost: [bool; 3],
    /// States held this step (their process noise off, their gain zero): see [`Observer::held`].
    held: [bool; STATES],
    step_consts: StepConsts<T>,
    /// Outlet pressure and flow at the end of the last prediction (what the lagged readings
    /// move toward).
    predicted: (T, T),
    /// The hydraulics at the state now (the last step's end, where the next one starts).
    h_now: Option<Hydraulics<T>>,
    /// Set by every reset; `Option` only to build the observer before its first estimate.
    last: Option<Estimate<T>>,
}

impl<T: Real> Innovation<T> {
    fn none(used: Use) -> Self {
        Self {
            used,
            value: T::ZERO,
            nis: T::ZERO,
        }
    }
}

impl<T: Real> Observer<T> {
    /// An observer with `config`, started at the model's steady state for the torque
    /// reference `torque_ref_pct` (0..=100 %) with the nominal valve and curves.
    pub fn new(config: ObserverConfig<T>, torque_ref_pct: T) -> Result<Self, ObserverError> {
        config.validate()?;
        let par = &config.params;
        let accel = par.accel_rpm_per_s_per_pct();
        let mut o = Self {
            cfg: config,
            accel,
            x: [T::ZERO; STATES],
            p: [[T::ZERO; STATES]; STATES],
            flow_warm: T::ZERO,
            te_applied: T::ZERO,
            flow_now: T::ZERO,
            flow_star: T::ZERO,
            flow_tau_sd_s: T::ZERO,
            flow_rate: T::ZERO,
            rejections: [0; 3],
            silent_s: [T::ZERO; 3],
            lost: [false; 3],
            held: [false; STATES],
            step_consts: StepConsts::new(&config, T::from_f64(0.05)),
            predicted: (T::ZERO, T::ZERO),
            h_now: None,
            last: None,
        };
        o.reset(torque_ref_pct);
        Ok(o)
    }

    /// The configuration.
    pub fn config(&self) -> &ObserverConfig<T> {
        &self.cfg
    }

    /// Restarts at the model's steady state for `torque_ref_pct`, nominal valve and curves,
    /// the initial covariance.
    pub fn reset(&mut self, torque_ref_pct: T) {
        let u = applied_torque_pct(torque_ref_pct);
        let par = &self.cfg.params;
        let mut x = [T::ZERO; STATES];
        x[K2] = par.valve_k2;
        x[HEAD_SCALE] = T::ONE;
        x[TORQUE_SCALE] = T::ONE;
        // Steady speed: bisection on the torque balance over 0..4000 rpm.
        let te = electromagnetic_torque_pct(&par.gamma, u);
        let (mut lo, mut hi) = (T::ZERO, T::from_f64(4000.0));
        self.flow_warm = T::ZERO;
        for _ in 0..40 {
            let mid = (lo + hi) * T::from_f64(0.5);
            x[SPEED] = mid;
            let h = self.hydraulics(&x);
            if te - h.torque.value > T::ZERO {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        x[SPEED] = lo;
        let h = self.hydraulics(&x);
        self.h_now = Some(h);
        self.te_applied = te;
        (self.flow_now, self.flow_star) = (h.flow, h.flow);
        (self.flow_tau_sd_s, self.flow_rate) = (T::ZERO, T::ZERO);
        x[PRESSURE_LAGGED] = self.outlet_pressure(&x, h.flow);
        x[FLOW_LAGGED] = h.flow;
        self.predicted = (x[PRESSURE_LAGGED], h.flow);
        self.x = x;
        self.p = [[T::ZERO; STATES]; STATES];
        for (i, s) in self.cfg.initial_sigma.iter().enumerate() {
            self.p[i][i] = *s * *s;
        }
        self.rejections = [0; 3];
        self.silent_s = [T::ZERO; 3];
        self.lost = [false; 3];
        self.held = [false; STATES];
        let none = Innovation::none(Use::Missing);
        self.last = Some(self.estimate(&h, none, none, none));
    }

    /// The state vector (see the indices: [`SPEED`], [`K2`], …).
    pub fn state(&self) -> &[T; STATES] {
        &self.x
    }

    /// The covariance.
    pub fn covariance(&self) -> &[[T; STATES]; STATES] {
        &self.p
    }

    /// The last estimate.
    pub fn estimate_now(&self) -> Estimate<T> {
        self.last.unwrap_or_else(|| unreachable_estimate(&self.x))
    }

    /// Flow at `x` (warm-started from the last solve).
    #[inline(never)]
    fn flow(&mut self, x: &Vector<T>) -> T {
        let par = &self.cfg.params;
        let (w, k2, s_h) = (x[SPEED], x[K2], x[HEAD_SCALE]);
        let k = system_k(par.pipe_k1, k2);
        let g = flow_balance(&par.alpha, s_h, k, par.static_head_c_mca, w);
        let q = solve_flow(&g, self.flow_warm).flow_lps;
        self.flow_warm = q;
        q
    }

    /// dω/dt at `x` with electromagnetic torque `te` and flow `q` (l/s).
    fn speed_rate(&self, x: &Vector<T>, te: T, q: T) -> T {
        let load = scaled_load_torque_pct(&self.cfg.params.beta, x[TORQUE_SCALE], x[SPEED], q);
        speed_derivative_rpm_per_s(te, load, self.accel)
    }

    /// The water column's time constant per unit of inertia at `x` for the flow balance's
    /// root `q`, s per mca·s²/l: `1 / |∂g/∂Q|` (times L, the time constant).
    fn flow_tau_per_inertia(&self, x: &Vector<T>, q: T) -> T {
        let par = &self.cfg.params;
        let (w, k2, s_h) = (x[SPEED], x[K2], x[HEAD_SCALE]);
        let head_dq = CubicInFlow::from_poly(&par.alpha, w).slope(q);
        let slope = flow_balance_dq(head_dq, s_h, system_k(par.pipe_k1, k2), q);
        // |∂g/∂Q| ≥ 0.05 mca per l/s: a flat balance (no flow) must not freeze the flow.
        T::ONE / slope.abs().max(T::from_f64(0.05))
    }

    /// Flow at `x` with the partials the linearisation and the standard deviations need.
    #[inline(never)]
    fn hydraulics(&mut self, x: &Vector<T>) -> Hydraulics<T> {
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

    fn outlet_pressure(&self, x: &Vector<T>, q: T) -> T {
        valve_pressure_mca(x[K2], self.cfg.params.static_head_c_mca, q)
    }

    /// Advances by `dt_s` seconds with the torque reference `torque_ref_pct` held (applied by
    /// [`crate::units::applied_torque_pct`]: clamped to 0..=100 %, NaN → 0), then takes the measurements that arrived. Returns the estimate.
    pub fn step(
        &mut self,
        dt_s: T,
        torque_ref_pct: T,
        m: &Measurements<T>,
    ) -> Result<Estimate<T>, ObserverError> {
        if !dt_s.is_finite() || !(dt_s > T::ZERO) || dt_s > T::from_f64(MAX_DT_S) {
            return Err(ObserverError::Step);
        }
        let (x0, p0, warm0) = (self.x, self.p, self.flow_warm);
        let aux0 = (
            self.te_applied,
            self.flow_now,
            self.flow_star,
            self.flow_tau_sd_s,
            self.flow_rate,
        );
        self.decide_holds(dt_s, m);
        self.predict(dt_s, applied_torque_pct(torque_ref_pct));
        let pressure = self.update_pressure(m.pressure_mca);
        let flow = self.update_flow(m.flow_lps);
        let speed = self.update_speed(m.speed_rpm);
        self.bound();
        let h = self.hydraulics(&self.x.clone());
        // The updates moved the state, so the balance's root: the flow through the water
        // column's lag moves with it (its lag behind the root kept), never below 0.
        self.flow_now = (self.flow_now + h.flow - self.flow_star).max(T::ZERO);
        self.flow_star = h.flow;
        let h_before = self.h_now;
        self.h_now = Some(h);
        let e = self.estimate(&h, pressure, flow, speed);
        if self.healthy() && estimate_finite(&e) {
            self.last = Some(e);
        } else {
            // Keep the last good state: a diverged step is undone, never published.
            (self.x, self.p, self.flow_warm) = (x0, p0, warm0);
            self.h_now = h_before;
            (
                self.te_applied,
                self.flow_now,
                self.flow_star,
                self.flow_tau_sd_s,
                self.flow_rate,
            ) = aux0;
        }
        Ok(self.estimate_now())
    }

    /// Which states are held this step. A channel is lost once it has brought no plausible
    /// value for longer than [`ObserverConfig::lost_after_s`], and found again once it has
    /// brought them for that long (up to twice that after a long loss). With pressure, speed and flow
    /// all there, the valve and both curve scales are observable; take one away and they are
    /// not, all at once: at one operating point a change of the valve and a change of a
    /// curve look alike. They differ in time: a valve moves in seconds, a curve drifts over
    /// months. So while flow or speed is lost both scales are held at what the full set
    /// taught, and while pressure is lost the head scale is; k2 stays free and tracks the
    /// valve from what remains. Released as soon as the channel is back.
    fn decide_holds(&mut self, dt: T, m: &Measurements<T>) {
        let plausible = |ch: usize, y: Option<T>| {
            let (lo, hi) = self.plausible_range(ch);
            y.is_some_and(|v| v.is_finite() && v >= lo && v <= hi)
        };
        let present = [
            plausible(0, m.pressure_mca),
            plausible(1, m.flow_lps),
            plausible(2, m.speed_rpm),
        ];
        // silent_s counts up while a channel is away and, once it is lost, down while it is
        // back: the scales stay held until it has been back as long as it takes to be lost,
        // so the first readings after a loss re-converge k2 and speed, not the curves.
        let limit = self.cfg.lost_after_s;
        for (ch, p) in present.into_iter().enumerate() {
            let s = &mut self.silent_s[ch];
            *s = match (p, self.lost[ch]) {
                (false, _) => (*s + dt).min(T::from_f64(1e6)),
                (true, false) => T::ZERO,
                (true, true) => (s.min(limit + limit) - dt).max(T::ZERO),
            };
            if *s > limit {
                self.lost[ch] = true;
            } else if *s <= T::ZERO {
                self.lost[ch] = false;
            }
        }
        let (p_lost, q_lost, w_lost) = (self.lost[0], self.lost[1], self.lost[2]);
        self.held = [false; STATES];
        self.held[HEAD_SCALE] = p_lost || q_lost || w_lost;
        self.held[TORQUE_SCALE] = q_lost || w_lost;
    }

    /// What channel `ch` (pressure mca, flow l/s, speed rpm) can plausibly read (see the
    /// module docs): outside it a value is not used.
    fn plausible_range(&self, ch: usize) -> (T, T) {
        match ch {
            0 => (
                -self.cfg.params.static_head_c_mca - T::from_f64(0.5),
                T::from_f64(60.0),
            ),
            1 => (T::from_f64(-0.5), T::from_f64(60.0)),
            _ => (T::from_f64(-50.0), T::from_f64(4000.0)),
        }
    }

    /// States held in the last step, indices as [`SPEED`], [`K2`], …: both curve scales while
    /// flow or speed is lost, the head scale while pressure is (a channel is lost after
    /// [`ObserverConfig::lost_after_s`] without a plausible value, and found again once it has
    /// been back as long). A held state is "considered", not estimated: zero gain, no random
    /// walk, its variance and correlations kept.
    pub fn held(&self) -> &[bool; STATES] {
        &self.held
    }

    fn predict(&mut self, dt: T, u: T) {
        let te = electromagnetic_torque_pct(&self.cfg.params.gamma, u);
        // Transition matrix, linearised at the start.
        // The hydraulics where the last step ended (the state has not moved since).
        let h0 = match self.h_now {
            Some(h) => h,
            None => self.hydraulics(&self.x.clone()),
        };
        if dt != self.step_consts.dt {
            self.step_consts = StepConsts::new(&self.cfg, dt);
        }
        let k = self.step_consts;
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
        // The rows of Φ that are not the identity's, for SPEED, PRESSURE_LAGGED and
        // FLOW_LAGGED (k2 and the scales are random walks).
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

        // P = Φ P Φᵀ + Q, with rows K2, HEAD_SCALE, TORQUE_SCALE of Φ the identity: only
        // the rows and columns of the three moved states change. M = (those rows of Φ) P;
        // then P[i][c] = M[i][c] for c not moved (P symmetric), and the moved block is
        // M Φᵀ. Written symmetric.
        // Column c of P is row c (symmetric): each entry one unrolled dot product.
        let m: [[T; STATES]; 3] =
            core::array::from_fn(|r| core::array::from_fn(|c| dot6(&phi[r], &self.p[c])));
        // Written out with constant indices (MOVED = 0, 4, 5; the rest 1, 2, 3): a loop
        // over MOVED costs twice as many instructions on the M4 at opt-level "s".
        let p = &mut self.p;
        macro_rules! plain {
            ($r:literal, $i:literal, $c:literal) => {{
                p[$i][$c] = m[$r][$c];
                p[$c][$i] = m[$r][$c];
            }};
        }
        macro_rules! block {
            ($r:literal, $i:literal, $r2:literal, $k:literal) => {{
                let v = dot6(&m[$r], &phi[$r2]);
                p[$i][$k] = v;
                p[$k][$i] = v;
            }};
        }
        plain!(0, 0, 1);
        plain!(0, 0, 2);
        plain!(0, 0, 3);
        plain!(1, 4, 1);
        plain!(1, 4, 2);
        plain!(1, 4, 3);
        plain!(2, 5, 1);
        plain!(2, 5, 2);
        plain!(2, 5, 3);
        block!(0, 0, 0, 0);
        block!(0, 0, 1, 4);
        block!(0, 0, 2, 5);
        block!(1, 4, 1, 4);
        block!(1, 4, 2, 5);
        block!(2, 5, 2, 5);
        let out = &mut self.p;
        let c = &self.cfg;
        let held = self.held;
        let walk = |i: usize, psd: T| if held[i] { T::ZERO } else { psd * dt };
        out[0][0] += walk(0, c.speed_psd);
        out[1][1] += walk(1, c.k2_psd);
        out[2][2] += walk(2, c.head_scale_psd);
        out[3][3] += walk(3, c.torque_scale_psd);
        out[4][4] += walk(4, c.lag_psd);
        out[5][5] += walk(5, c.lag_psd);
        // A drive lag off by its σ moves the torque-time by σ · ΔTe over a change of torque.
        let dw = self.accel * self.cfg.drive_lag_sd_s * (self.te_applied - te_start);
        out[SPEED][SPEED] += dw * dw;
        self.cap_variances();
    }

    /// A transmitter's noise variance plus what its uncertain lag adds while the signal
    /// moves: a lag off by `lag_sd` misreads a signal changing at `rate` by ≈ `lag_sd · rate`.
    fn lag_variance(sigma: T, lag_sd: T, target: T, lagged: T, lag: T) -> T {
        let rate = if lag > T::ZERO {
            (target - lagged) / lag
        } else {
            T::ZERO
        };
        let e = lag_sd * rate;
        sigma * sigma + e * e
    }

    /// The flow's error from an uncertain water inertia now, l/s (1 σ).
    fn inertia_flow_sd(&self) -> T {
        self.flow_tau_sd_s * self.flow_rate
    }

    fn update_pressure(&mut self, y: Option<T>) -> Innovation<T> {
        let c = &self.cfg;
        let (lo, hi) = self.plausible_range(0);
        let (hs_q, _) = valve_pressure_partials(self.x[K2], self.flow_now);
        let e = hs_q * self.inertia_flow_sd();
        let r = Self::lag_variance(
            c.pressure_sigma_mca,
            c.pressure_lag_sd_s,
            self.predicted.0,
            self.x[PRESSURE_LAGGED],
            c.pressure_lag_s,
        ) + e * e;
        self.update(0, PRESSURE_LAGGED, y, lo, hi, r)
    }

    fn update_flow(&mut self, y: Option<T>) -> Innovation<T> {
        let c = &self.cfg;
        let e = self.inertia_flow_sd();
        let r = Self::lag_variance(
            c.flow_sigma_lps,
            c.flow_lag_sd_s,
            self.predicted.1,
            self.x[FLOW_LAGGED],
            c.flow_lag_s,
        ) + e * e;
        let (lo, hi) = self.plausible_range(1);
        self.update(1, FLOW_LAGGED, y, lo, hi, r)
    }

    fn update_speed(&mut self, y: Option<T>) -> Innovation<T> {
        let r = self.cfg.speed_sigma_rpm;
        let (lo, hi) = self.plausible_range(2);
        self.update(2, SPEED, y, lo, hi, r * r)
    }

    /// One scalar update of state `i` measured directly, Joseph form.
    fn update(&mut self, ch: usize, i: usize, y: Option<T>, lo: T, hi: T, r: T) -> Innovation<T> {
        let Some(y) = y else {
            return Innovation::none(Use::Missing);
        };
        if !y.is_finite() || y < lo || y > hi {
            return Innovation::none(Use::Implausible);
        }
        let nu = y - self.x[i];
        let s = self.p[i][i] + r;
        let nis = nu * nu / s;
        let gate = self.cfg.gate_sigma * self.cfg.gate_sigma;
        if nis > gate {
            self.rejections[ch] = self.rejections[ch].saturating_add(1);
            if self.rejections[ch] < self.cfg.max_rejections {
                return Innovation {
                    used: Use::Rejected,
                    value: nu,
                    nis,
                };
            }
            // A lasting change, not an outlier: let the valve move (pressure and flow only:
            // a lasting speed offset says nothing about the valve).
            if ch < 2 {
                let j = self.cfg.k2_jump_sigma;
                self.p[K2][K2] += j * j;
            }
        }
        self.rejections[ch] = 0;
        let s = self.p[i][i] + r;
        // Held states are "considered", not estimated (Schmidt): zero gain, their variance
        // and correlations kept, so the estimate's σ still carries their uncertainty. The
        // Joseph form below is right for any gain.
        // Column i of P is row i (symmetric). The six-element loops below are written out: a
        // loop costs twice as many instructions on the M4 at opt-level "s".
        let pi: Vector<T> = self.p[i];
        let held = self.held;
        let gain = |a: usize| if held[a] { T::ZERO } else { pi[a] / s };
        let mut k: Vector<T> = [gain(0), gain(1), gain(2), gain(3), gain(4), gain(5)];
        // A trust region on k2: the linearisation holds for a small move only, and a large
        // one in a step overshoots (after a valve step, the model is far from linear in k2),
        // so one update moves k2 by at most MAX_K2_MOVE of itself; the whole correction is
        // scaled alike (its direction kept) and the Joseph form below stays right for the
        // smaller gain. A large change is followed over a few steps.
        let step = (k[K2] * nu).abs();
        let allowed = T::from_f64(MAX_K2_MOVE) * self.x[K2];
        if step > allowed {
            let f = allowed / step;
            k = [k[0] * f, k[1] * f, k[2] * f, k[3] * f, k[4] * f, k[5] * f];
        }
        let x = &mut self.x;
        *x = [
            x[0] + k[0] * nu,
            x[1] + k[1] * nu,
            x[2] + k[2] * nu,
            x[3] + k[3] * nu,
            x[4] + k[4] * nu,
            x[5] + k[5] * nu,
        ];
        // Joseph, P = (I − k eᵢᵀ) P (I − k eᵢᵀ)ᵀ + k r kᵀ, expanded: with p = P eᵢ and
        // s = pᵢᵢ + r it is P − k pᵀ − p kᵀ + s k kᵀ = P − k gᵀ − p kᵀ, g = p − s k (0 where
        // the gain is optimal, p where it is held). Symmetric by construction: the upper
        // triangle, mirrored.
        let g: Vector<T> = [
            pi[0] - s * k[0],
            pi[1] - s * k[1],
            pi[2] - s * k[2],
            pi[3] - s * k[3],
            pi[4] - s * k[4],
            pi[5] - s * k[5],
        ];
        let floor = T::from_f64(1e-12);
        let p = &mut self.p;
        // Written out, entry by entry (a loop costs twice as many instructions on the M4 at
        // opt-level "s").
        macro_rules! entry {
            ($a:literal, $b:literal) => {{
                let v = p[$a][$b] - k[$a] * g[$b] - pi[$a] * k[$b];
                p[$a][$b] = v;
                p[$b][$a] = v;
            }};
        }
        macro_rules! diagonal {
            ($a:literal) => {{
                p[$a][$a] = (p[$a][$a] - k[$a] * g[$a] - pi[$a] * k[$a]).max(floor);
            }};
        }
        diagonal!(0);
        entry!(0, 1);
        entry!(0, 2);
        entry!(0, 3);
        entry!(0, 4);
        entry!(0, 5);
        diagonal!(1);
        entry!(1, 2);
        entry!(1, 3);
        entry!(1, 4);
        entry!(1, 5);
        diagonal!(2);
        entry!(2, 3);
        entry!(2, 4);
        entry!(2, 5);
        diagonal!(3);
        entry!(3, 4);
        entry!(3, 5);
        diagonal!(4);
        entry!(4, 5);
        diagonal!(5);
        Innovation {
            used: Use::Used,
            value: nu,
            nis,
        }
    }

    /// Keeps each variance at most its initial one: with nothing to observe (at rest, no
    /// flow) the random walks would otherwise grow it without bound, and the first readings
    /// after hours would throw k2 and the scales to their limits. Row and column are scaled
    /// together (D P D), which keeps P positive definite (and symmetric); every variance at
    /// least 1e-12.
    fn cap_variances(&mut self) {
        let floor = T::from_f64(1e-12);
        let sigma = self.cfg.initial_sigma;
        // The check written out per state (a loop costs twice as many instructions on the
        // M4 at opt-level "s"); the scaling, rare, as a loop.
        let mut cap = |i: usize| {
            let v = self.p[i][i].max(floor);
            self.p[i][i] = v;
            let cap = sigma[i] * sigma[i];
            if v > cap {
                let f = (cap / v).sqrt();
                for j in 0..STATES {
                    self.p[i][j] = self.p[i][j] * f;
                    self.p[j][i] = self.p[j][i] * f;
                }
            }
        };
        cap(0);
        cap(1);
        cap(2);
        cap(3);
        cap(4);
        cap(5);
    }

    /// Keeps k2 and the scales in range, speed and flow non-negative.
    fn bound(&mut self) {
        let c = &self.cfg;
        self.x[K2] = self.x[K2].max(c.k2_range.0).min(c.k2_range.1);
        for i in [HEAD_SCALE, TORQUE_SCALE] {
            self.x[i] = self.x[i].max(c.scale_range.0).min(c.scale_range.1);
        }
        self.x[SPEED] = self.x[SPEED].max(T::ZERO);
        self.x[FLOW_LAGGED] = self.x[FLOW_LAGGED].max(T::ZERO);
    }

    fn healthy(&self) -> bool {
        // P is symmetric by construction: its upper triangle says it all. `v − v` is 0 for a
        // finite v and NaN otherwise, so one sum tells (written out: a loop costs twice as
        // many instructions on the M4 at opt-level "s").
        let (x, p) = (&self.x, &self.p);
        let z = nan_unless_finite::<T>;
        let sum = z(x[0])
            + z(x[1])
            + z(x[2])
            + z(x[3])
            + z(x[4])
            + z(x[5])
            + (z(p[0][0]) + z(p[0][1]) + z(p[0][2]) + z(p[0][3]) + z(p[0][4]) + z(p[0][5]))
            + (z(p[1][1]) + z(p[1][2]) + z(p[1][3]) + z(p[1][4]) + z(p[1][5]))
            + (z(p[2][2]) + z(p[2][3]) + z(p[2][4]) + z(p[2][5]))
            + (z(p[3][3]) + z(p[3][4]) + z(p[3][5]))
            + (z(p[4][4]) + z(p[4][5]) + z(p[5][5]));
        sum == T::ZERO
            && p[0][0] > T::ZERO
            && p[1][1] > T::ZERO
            && p[2][2] > T::ZERO
            && p[3][3] > T::ZERO
            && p[4][4] > T::ZERO
            && p[5][5] > T::ZERO
    }

    /// Standard deviation of `jᵀ (ω, k2, s_H)` (linearised): what every derived quantity
    /// depends on. The 3×3 block of P is symmetric: six products.
    fn sd3(&self, j: &[T; 3]) -> T {
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
    fn sd_state(&self, i: usize) -> T {
        self.p[i][i].max(T::ZERO).sqrt()
    }

    fn estimate(
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
fn unreachable_estimate<T: Real>(x: &Vector<T>) -> Estimate<T> {
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

/// What a step's `dt` fixes, computed again only when `dt` changes (the loop's is constant):
/// the sub-steps, the lags' decays over `dt` and their ramp-exact updates over a sub-step.
#[derive(Debug, Clone, Copy, PartialEq)]
struct StepConsts<T> {
    dt: T,
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

    fn new(cfg: &ObserverConfig<T>, dt: T) -> Self {
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
        let decay = |tau: T| {
            if tau > T::ZERO {
                (-dt / tau).exp()
            } else {
                T::ZERO
            }
        };
        Self {
            dt,
            substeps,
            substep_s,
            pressure_decay: decay(cfg.pressure_lag_s),
            flow_decay: decay(cfg.flow_lag_s),
            lag_p: Lag::new(cfg.pressure_lag_s, substep_s),
            lag_q: Lag::new(cfg.flow_lag_s, substep_s),
            drive_decay: if cfg.drive_lag_s > T::ZERO {
                (-substep_s / cfg.drive_lag_s).exp()
            } else {
                T::ZERO
            },
        }
    }
}

/// `a · b` over the six states, written out (the loop costs twice as many instructions on the
/// M4 at opt-level "s").
#[inline(always)]
fn dot6<T: Real>(a: &[T; STATES], b: &[T; STATES]) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

/// 0 for a finite `v`, NaN for ±∞ and NaN: summed over many values, one comparison says
/// whether all are finite.
#[inline(always)]
#[allow(clippy::eq_op)] // deliberate: v − v is NaN exactly when v is not finite
fn nan_unless_finite<T: Real>(v: T) -> T {
    v - v
}

/// √(a² + b²).
fn hypot<T: Real>(a: T, b: T) -> T {
    (a * a + b * b).sqrt()
}

/// `x` after `h` seconds of a first-order lag `tau` toward a held `target` (`tau` = 0: the
/// target).
fn lag_to<T: Real>(x: T, target: T, h: T, tau: T) -> T {
    if tau > T::ZERO {
        target + (x - target) * (-h / tau).exp()
    } else {
        target
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
            let a = (-h / tau).exp();
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

fn estimate_finite<T: Real>(e: &Estimate<T>) -> bool {
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::excitation::{PulseTrain, SplitMix64, SteppedPulses};

    fn gaussian(rng: &mut SplitMix64) -> f64 {
        let u1 = rng.next_f64().max(1e-300);
        let u2 = rng.next_f64();
        (-2.0 * u1.ln()).sqrt() * (2.0 * core::f64::consts::PI * u2).cos()
    }
    use crate::{Scheme, WhiteBox};

    /// The transmitters of the synthetic bench: lagged readings and the noise generator.
    struct Lags {
        lag_p: f64,
        lag_q: f64,
        rng: SplitMix64,
    }

    /// One 50 ms row: time, mean torque over the interval, truth at its end, readings.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Row {
        pub t_s: f64,
        pub torque_pct: f64,
        pub speed: f64,
        pub flow: f64,
        pub k2: f64,
        pub p_meas: f64,
        pub q_meas: f64,
        pub w_meas: f64,
    }

    /// `seconds` of the paper's pulses (seed) on a synthetic bench whose truth differs from
    /// the model: curves scaled (head × (1 + e), load torque × (1 − e)), valve factors
    /// `steps` (time s, × nominal k2), transmitter lags (20 / 40 ms) and noise (3 mm, 0.02
    /// l/s, 0.5 rpm).
    pub(crate) fn record(seed: u64, seconds: f64, e: f64, steps: &[(f64, f64)]) -> Vec<Row> {
        record_with(seed, seconds, e, steps, None, 1.0)
    }

    /// As [`record`], and from `dry_from_s` on the pump runs dry: no flow, the outlet at its
    /// static level (−c), the load torque only the friction part of the curve (β9 ω + β10);
    /// with each valve step the pipe's k1 becomes `k1_factor` × the paper's (a broken pipe).
    pub(crate) fn record_with(
        seed: u64,
        seconds: f64,
        e: f64,
        steps: &[(f64, f64)],
        dry_from_s: Option<f64>,
        k1_factor: f64,
    ) -> Vec<Row> {
        let mut par = BenchParams::<f64>::paper();
        for a in par.alpha.iter_mut() {
            *a *= 1.0 + e;
        }
        for b in par.beta.iter_mut() {
            *b *= 1.0 - e;
        }
        let k2_nom = par.valve_k2;
        let mut bench = WhiteBox::new(par).unwrap();
        let pulses = SteppedPulses::new(PulseTrain::paper(seed), 1);
        let mut state = bench.steady_state(20.0).unwrap();
        let s0 = bench.signals(&state);
        let mut t = Lags {
            lag_p: s0.pressure_mca,
            lag_q: s0.flow_lps,
            rng: SplitMix64::new(seed ^ 0x5eed),
        };
        let mut rows = vec![];
        let mut acc = 0.0;
        let mut k2 = k2_nom;
        for (ms, u) in pulses.take((seconds * 1000.0) as usize) {
            let now = ms as f64 * 1e-3;
            for &(ts, f) in steps {
                if (now - ts).abs() < 0.5e-3 {
                    k2 = k2_nom * f;
                    if k1_factor != 1.0 {
                        let mut q = *bench.params();
                        q.pipe_k1 = par.pipe_k1 * k1_factor;
                        bench = WhiteBox::new(q).unwrap();
                    }
                    bench.set_load(k2, par.static_head_c_mca).unwrap();
                }
            }
            acc += u;
            let mut s = if dry_from_s.is_some_and(|t| now >= t) {
                let p = bench.params();
                let te = crate::equations::electromagnetic_torque_pct(&p.gamma, u);
                let w = state.speed_rpm;
                let friction = p.beta[8] * w + p.beta[9];
                let k = bench.accel_rpm_per_s_per_pct();
                state.speed_rpm = (w + 1e-3 * k * (te - friction)).max(0.0);
                let mut s = bench.signals(&state);
                s.flow_lps = 0.0;
                s.pressure_mca = -p.static_head_c_mca;
                s
            } else {
                bench.step(&mut state, u, 1e-3, Scheme::Rk4).unwrap();
                bench.signals(&state)
            };
            s.speed_rpm = state.speed_rpm;
            t.lag_p += (1.0 - (-1e-3f64 / 0.020).exp()) * (s.pressure_mca - t.lag_p);
            t.lag_q += (1.0 - (-1e-3f64 / 0.040).exp()) * (s.flow_lps - t.lag_q);
            if (ms + 1) % 50 == 0 {
                rows.push(Row {
                    t_s: (ms + 1) as f64 * 1e-3,
                    torque_pct: acc / 50.0,
                    speed: s.speed_rpm,
                    flow: s.flow_lps,
                    k2,
                    p_meas: t.lag_p + 0.003 * gaussian(&mut t.rng),
                    q_meas: t.lag_q + 0.02 * gaussian(&mut t.rng),
                    w_meas: s.speed_rpm + 0.5 * gaussian(&mut t.rng),
                });
                acc = 0.0;
            }
        }
        rows
    }

    /// Runs the observer on `rows` (flow every other row), with the flow and/or speed
    /// columns dropped from `drop_from_s`. Returns the estimates.
    pub(crate) fn run<T: Real>(
        rows: &[Row],
        drop_flow_from_s: f64,
        drop_speed_from_s: f64,
    ) -> Vec<Estimate<T>> {
        let f = T::from_f64;
        let mut o = Observer::<T>::new(ObserverConfig::paper(), f(20.0)).unwrap();
        rows.iter()
            .enumerate()
            .map(|(i, r)| {
                let m = Measurements {
                    pressure_mca: Some(f(r.p_meas)),
                    flow_lps: (i % 2 == 1 && r.t_s < drop_flow_from_s).then(|| f(r.q_meas)),
                    speed_rpm: (r.t_s < drop_speed_from_s).then(|| f(r.w_meas)),
                };
                o.step(f(0.05), f(r.torque_pct), &m).unwrap()
            })
            .collect()
    }

    fn mape(pairs: impl Iterator<Item = (f64, f64)>) -> f64 {
        let (mut s, mut n) = (0.0, 0.0);
        for (est, truth) in pairs {
            s += ((est - truth) / truth).abs();
            n += 1.0;
        }
        100.0 * s / n
    }

    #[test]
    fn tracks_valve_steps_and_curve_errors() {
        for (seed, e) in [(1u64, 0.03), (2, -0.04), (3, 0.05)] {
            let steps = [(30.0, 1.3), (60.0, 0.7), (90.0, 1.0)];
            let rows = record(seed, 120.0, e, &steps);
            let est = run::<f64>(&rows, 1e9, 1e9);
            // k2 within 3 % from 2 s after each step (and after the first 10 s).
            let mut worst: f64 = 0.0;
            for (r, x) in rows.iter().zip(&est) {
                let settled = r.t_s > 10.0
                    && steps
                        .iter()
                        .all(|&(ts, _)| !(ts..ts + 2.0).contains(&r.t_s));
                if settled {
                    let err = (x.valve_k2 / r.k2 - 1.0).abs();
                    worst = worst.max(err);
                }
            }
            let flow = mape(
                rows.iter()
                    .zip(&est)
                    .skip(200)
                    .map(|(r, x)| (x.flow_lps, r.flow)),
            );
            let speed = mape(
                rows.iter()
                    .zip(&est)
                    .skip(200)
                    .map(|(r, x)| (x.speed_rpm, r.speed)),
            );
            println!("seed {seed} e {e}: k2 worst {:.2} %, flow MAPE {flow:.3} %, speed MAPE {speed:.3} %", worst * 100.0);
            assert!(worst < 0.03, "k2 off by {:.2} %", worst * 100.0);
        }
    }

    #[test]
    fn flow_and_speed_without_their_sensors() {
        let steps = [(30.0, 1.3), (75.0, 0.7)];
        for e in [0.03, -0.04] {
            let rows = record(4, 120.0, e, &steps);
            let half = 60.0;
            let no_flow = run::<f64>(&rows, half, 1e9);
            let no_speed = run::<f64>(&rows, 1e9, half);
            let after = |est: &[Estimate<f64>], f: fn(&Row, &Estimate<f64>) -> (f64, f64)| {
                mape(
                    rows.iter()
                        .zip(est)
                        .filter(|(r, _)| r.t_s >= half)
                        .map(|(r, x)| f(r, x)),
                )
            };
            let flow = after(&no_flow, |r, x| (x.flow_lps, r.flow));
            let speed = after(&no_speed, |r, x| (x.speed_rpm, r.speed));
            println!("e {e}: flow MAPE without flow meter {flow:.3} %, speed MAPE without VFD speed {speed:.3} %");
            assert!(flow < 1.0 && speed < 1.0);
        }
    }
}

#[cfg(test)]
mod robustness {
    use super::tests::{record, run, Row};
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn f32_follows_f64_within_1e_3() {
        let rows = record(5, 60.0, 0.03, &[(20.0, 1.3), (40.0, 0.8)]);
        let a = run::<f64>(&rows, 1e9, 1e9);
        let b = run::<f32>(&rows, 1e9, 1e9);
        let mut worst: f64 = 0.0;
        for (x, y) in a.iter().zip(&b) {
            for (u, v) in [
                (x.speed_rpm, y.speed_rpm),
                (x.flow_lps, y.flow_lps),
                (x.valve_k2, y.valve_k2),
                (x.pressure_mca, y.pressure_mca),
            ] {
                worst = worst.max((f64::from(v) / u - 1.0).abs());
            }
        }
        println!("f32 vs f64: worst relative difference {worst:.2e}");
        assert!(worst < 1e-3, "{worst}");
    }

    /// Eight hours at rest (nothing to observe: no pressure in span, little flow), then the
    /// pulses: the variances stay at most their initial ones, and the estimates are right
    /// within seconds instead of slamming k2 to its limits.
    #[test]
    fn hours_at_rest_do_not_inflate_the_covariance() {
        let mut o = Observer::<f32>::new(ObserverConfig::paper(), 0.0).unwrap();
        let c = ObserverConfig::<f32>::paper();
        for _ in 0..(8 * 3600 * 20) {
            o.step(0.05, 0.0, &Measurements::default()).unwrap();
        }
        for i in 0..STATES {
            let cap = c.initial_sigma[i] * c.initial_sigma[i];
            assert!(o.covariance()[i][i] <= cap * 1.0001, "variance {i}");
        }
        let rows = super::tests::record(8, 40.0, 0.03, &[]);
        let mut worst: f64 = 0.0;
        for (i, r) in rows.iter().enumerate() {
            let m = Measurements {
                pressure_mca: Some(r.p_meas as f32),
                flow_lps: (i % 2 == 1).then_some(r.q_meas as f32),
                speed_rpm: Some(r.w_meas as f32),
            };
            let e = o.step(0.05, r.torque_pct as f32, &m).unwrap();
            if r.t_s > 5.0 {
                worst = worst.max((f64::from(e.valve_k2) / r.k2 - 1.0).abs());
            }
        }
        println!(
            "after 8 h at rest: k2 worst {:.2} % from 5 s of pulses",
            worst * 100.0
        );
        assert!(worst < 0.03);
    }

    /// A pressure transmitter at 2 mA (−1.25 mca on a 0..10 mca span) for 20 s: not used;
    /// the estimates stay within 5 % and recover after.
    #[test]
    fn a_transmitter_at_2_ma_is_not_used() {
        // Not used means: the estimate is exactly what it is with the cells empty, and the
        // flow and k2 stay right through the 20 s from what remains.
        let rows = record(6, 80.0, 0.03, &[]);
        let run = |faulted: bool| {
            let mut o = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
            let mut out = vec![];
            for (i, r) in rows.iter().enumerate() {
                let fault = (30.0..50.0).contains(&r.t_s);
                let pressure = match (fault, faulted) {
                    (false, _) => Some(r.p_meas),
                    (true, true) => Some(-1.25),
                    (true, false) => None,
                };
                let m = Measurements {
                    pressure_mca: pressure,
                    flow_lps: (i % 2 == 1).then_some(r.q_meas),
                    speed_rpm: Some(r.w_meas),
                };
                let e = o.step(0.05, r.torque_pct, &m).unwrap();
                if fault && faulted {
                    assert_eq!(e.pressure.used, Use::Implausible);
                }
                out.push((r, e));
            }
            out
        };
        let (faulted, missing) = (run(true), run(false));
        for ((r, a), (_, b)) in faulted.iter().zip(&missing) {
            assert_eq!(
                (a.flow_lps, a.valve_k2, a.speed_rpm),
                (b.flow_lps, b.valve_k2, b.speed_rpm),
                "{} s",
                r.t_s
            );
        }
        let window: Vec<_> = faulted
            .iter()
            .filter(|(r, _)| (30.0..50.0).contains(&r.t_s))
            .collect();
        let mape = |f: &dyn Fn(&Row, &Estimate<f64>) -> f64| {
            100.0 * window.iter().map(|(r, e)| f(r, e).abs()).sum::<f64>() / window.len() as f64
        };
        let (flow, k2) = (
            mape(&|r, e| e.flow_lps / r.flow - 1.0),
            mape(&|r, e| e.valve_k2 / r.k2 - 1.0),
        );
        println!("pressure at 2 mA for 20 s: flow MAPE {flow:.2} %, k2 {k2:.2} %");
        assert!(flow < 1.0 && k2 < 1.0);
    }

    fn channel() -> impl Strategy<Value = Option<f64>> {
        prop_oneof![
            3 => Just(None),
            6 => (-10.0..2000.0f64).prop_map(Some),
            1 => prop_oneof![
                Just(f64::NAN),
                Just(f64::INFINITY),
                Just(f64::NEG_INFINITY),
                Just(1e30),
                Just(-1e30)
            ]
            .prop_map(Some),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Random torques (NaN and ±∞ among them), steps, dropped and wild measurements: no
        /// NaN out, the covariance symmetric with a positive diagonal and positive 2×2 minors,
        /// k2 in range.
        #[test]
        fn never_nan_and_covariance_stays_positive(
            steps in proptest::collection::vec(
                (prop_oneof![8 => -20.0..120.0f64, 1 => Just(f64::NAN), 1 => Just(f64::INFINITY)],
                 prop_oneof![8 => 0.001..0.3f64, 1 => Just(0.05)],
                 channel(), channel(), channel()),
                1..120)
        ) {
            for f32_too in [false, true] {
                let mut o64 = Observer::<f64>::new(ObserverConfig::paper(), 30.0).unwrap();
                let mut o32 = Observer::<f32>::new(ObserverConfig::paper(), 30.0).unwrap();
                for &(u, dt, p, q, w) in &steps {
                    let m = Measurements { pressure_mca: p, flow_lps: q, speed_rpm: w };
                    let e = o64.step(dt, u, &m).unwrap();
                    prop_assert!(estimate_finite(&e));
                    check(o64.covariance(), o64.state(), o64.config())?;
                    if f32_too {
                        let m32 = Measurements {
                            pressure_mca: p.map(|v| v as f32),
                            flow_lps: q.map(|v| v as f32),
                            speed_rpm: w.map(|v| v as f32),
                        };
                        let e = o32.step(dt as f32, u as f32, &m32).unwrap();
                        prop_assert!(estimate_finite(&e));
                        check(o32.covariance(), o32.state(), o32.config())?;
                    }
                }
            }
        }
    }

    fn check<T: Real>(
        p: &[[T; STATES]; STATES],
        x: &[T; STATES],
        c: &ObserverConfig<T>,
    ) -> Result<(), TestCaseError> {
        for i in 0..STATES {
            prop_assert!(p[i][i] > T::ZERO, "variance {i}: {:?}", p[i][i]);
            for j in 0..STATES {
                prop_assert!(p[i][j] == p[j][i]);
                // Every 2×2 principal minor of a positive definite matrix is positive.
                if i != j {
                    let minor =
                        p[i][i].to_f64() * p[j][j].to_f64() - p[i][j].to_f64() * p[j][i].to_f64();
                    prop_assert!(
                        minor > -1e-9 * p[i][i].to_f64() * p[j][j].to_f64(),
                        "minor {i},{j}"
                    );
                }
            }
        }
        prop_assert!(c.k2_range.0 <= x[K2] && x[K2] <= c.k2_range.1);
        Ok(())
    }
}
