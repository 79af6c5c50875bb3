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
//! A measurement that is not finite or is physically implausible (pressure below
//! min(−c, 0) − 0.5 mca or above 60 mca, flow below −0.5 l/s or above 60 l/s, speed below −50 or above 4000
//! rpm: a transmitter at 2 mA, a NaN) is not used, nor is a drive's speed of exactly 0 rpm
//! while the observer's is not and the pump cannot make the pressure read at rest (its head
//! at no flow at 0 rpm, at the largest head scale, [`SPEED_HEAD_MARGIN_MCA`] under the
//! reading: a speed register stuck at 0). An innovation whose normalised square
//! exceeds [`ObserverConfig::gate_sigma`]² is rejected as an outlier, unless the channel has
//! been rejected [`ObserverConfig::max_rejections`] times in a row: then the change is taken
//! as real (the valve moved) and, for pressure and flow, k2's variance is raised by
//! [`ObserverConfig::k2_jump_sigma`]² before the update, so the filter re-converges in a few
//! samples instead of tens of seconds; one update moves k2 by at most [`MAX_K2_MOVE`] of
//! itself. The covariance is kept symmetric, its diagonal positive; k2 and the scales stay within
//! their configured ranges; a non-finite result restores the last good estimate. No output
//! is ever NaN.
//!
//! # Layout
//!
//! The filter itself is here (prediction of the covariance, the measurement updates, the
//! holds, the guards); `config` holds the tuning, `process` the bench's process model
//! (the flow, the speed's rate, the transition matrix, the mean's integration) and
//! `estimate` the derived outputs and their standard deviations.

use crate::equations::{electromagnetic_torque_pct, valve_pressure_partials, CubicInFlow};
use crate::scalar::Real;
use crate::units::applied_torque_pct;

mod config;
mod estimate;
mod process;
#[cfg(test)]
mod robustness;
#[cfg(test)]
pub(crate) mod tests;

pub use config::{ObserverConfig, ObserverError, PAPER_PRESSURE_LAG_SD_S};
use estimate::{estimate_finite, unreachable_estimate};
pub use estimate::{Estimate, Innovation, Use};
use process::{Hydraulics, StepConsts};

/// Number of states.
pub const STATES: usize = 6;
// The states a prediction moves through Φ are SPEED, PRESSURE_LAGGED and FLOW_LAGGED (rows
// 0, 1, 2 of `phi` in `process::transition`); the others are random walks.
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
/// How far over the most the pump can give at rest a pressure reading must be for a drive's
/// speed of 0 rpm to be taken as wrong, mca ([`Observer::step`]: the speed is then not used):
/// the pressure channel's own margin under its plausible range.
pub const SPEED_HEAD_MARGIN_MCA: f64 = 0.5;
/// The highest pressure reading the observer takes, mca (module docs, Robustness).
const PRESSURE_MAX_MCA: f64 = 60.0;
/// Longest sub-step of the mean's integration, s.
pub const MAX_SUBSTEP_S: f64 = 0.05;
/// Longest `dt` of one [`Observer::step`], s (the error message repeats it).
pub const MAX_DT_S: f64 = 10.0;
/// Water density × g, W per (l/s · m): hydraulic power P = 9.81 · Q (l/s) · H (m).
pub const RHO_G_W_PER_LPS_M: f64 = 9.806_65;

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

type Vector<T> = [T; STATES];
type Matrix<T> = [[T; STATES]; STATES];

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

    /// Takes how far the pressure transmitter's lag may be from the one modelled, s (1 σ,
    /// finite, ≥ 0; [`ObserverConfig::pressure_lag_sd_s`]): while pressure moves, its
    /// reading weighs less, so a lag longer than the one modelled moves k2 less. A negative
    /// or non-finite value is refused; nothing changes then.
    pub fn set_pressure_lag_sd_s(&mut self, sd_s: T) -> Result<(), ObserverError> {
        if !(sd_s.is_finite() && sd_s >= T::ZERO) {
            return Err(ObserverError::Config);
        }
        self.cfg.pressure_lag_sd_s = sd_s;
        Ok(())
    }

    /// Takes the system curve's static head c (mca, eq. (8): `Hs = k2² Q² − c`; the paper's
    /// 0.252, a lift is c < 0), as commissioning writes it. The valve's k2 moves with it so
    /// that the system curve still passes through the operating point now (the same
    /// pressure at the same flow), within the configuration's `k2_range`; k2's row and
    /// column of the covariance are carried through the move (its slope `k2 / k2'`), the rest
    /// of the state and covariance stay, and the next steps find k2 from there. At no flow
    /// (or a curve that cannot pass there) k2 stays. A non-finite `c_mca` is refused;
    /// nothing changes then.
    pub fn set_static_head(&mut self, c_mca: T) -> Result<(), ObserverError> {
        if !c_mca.is_finite() {
            return Err(ObserverError::Model(crate::BenchError::InvalidParameter(
                "the static head must be finite",
            )));
        }
        let q = self.flow_now;
        if q > T::from_f64(0.1) {
            let k2 = self.x[K2];
            let k2_sq = k2 * k2 + (c_mca - self.cfg.params.static_head_c_mca) / (q * q);
            if k2_sq > T::ZERO {
                let r = &self.cfg.k2_range;
                let moved = k2_sq.sqrt().max(r.0).min(r.1);
                // k2' = √(k2² + Δc/Q²): dk2'/dk2 = k2/k2' (a clamped k2' takes the same
                // slope; the next updates find it). P' = J P Jᵀ, J = diag(1, …, k2/k2', …).
                let f = k2 / moved;
                for i in 0..STATES {
                    self.p[K2][i] = self.p[K2][i] * f;
                    self.p[i][K2] = self.p[i][K2] * f;
                }
                self.x[K2] = moved;
            }
        }
        self.cfg.params.static_head_c_mca = c_mca;
        self.h_now = None;
        Ok(())
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
        let speed_ok = !self.speed_contradicted(m);
        self.decide_holds(dt_s, m, speed_ok);
        self.predict(dt_s, applied_torque_pct(torque_ref_pct));
        let pressure = self.update_pressure(m.pressure_mca);
        let flow = self.update_flow(m.flow_lps);
        let speed = if speed_ok {
            self.update_speed(m.speed_rpm)
        } else {
            Innovation::none(Use::Implausible)
        };
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
    fn decide_holds(&mut self, dt: T, m: &Measurements<T>, speed_ok: bool) {
        let plausible = |ch: usize, y: Option<T>| {
            let (lo, hi) = self.plausible_range(ch);
            y.is_some_and(|v| v.is_finite() && v >= lo && v <= hi)
        };
        let present = [
            plausible(0, m.pressure_mca),
            plausible(1, m.flow_lps),
            speed_ok && plausible(2, m.speed_rpm),
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
            // Down to the system curve's head at no flow, and to 0 with a lift (c < 0): an
            // outlet transmitter before the check valve reads the pump's head under it.
            0 => (
                (-self.cfg.params.static_head_c_mca).min(T::ZERO) - T::from_f64(0.5),
                T::from_f64(PRESSURE_MAX_MCA),
            ),
            1 => (T::from_f64(-0.5), T::from_f64(60.0)),
            _ => (T::from_f64(-50.0), T::from_f64(4000.0)),
        }
    }

    /// Whether the drive's speed `m.speed_rpm` reads 0 rpm, to the bit, while the observer's
    /// is not 0, and the pump cannot make the pressure `m.pressure_mca` read at rest: over
    /// its head at no flow at 0 rpm at the largest head scale
    /// ([`ObserverConfig::scale_range`]), or over the static head a check valve holds, by
    /// more than [`SPEED_HEAD_MARGIN_MCA`]. Such a reading is not used: a drive's speed stuck
    /// at 0 (a speed register not mapped, a plant that sends none) under a pump holding
    /// 3 mca, taken as real after five rejections, set the model law swinging 1.3..3.8 mca
    /// where the PI alone held. Only an exact 0: judged at any speed under half the
    /// observer's, a moving reading of a light rotor coasting behind a slow transmitter or a
    /// water column that holds the pressure up was refused where it was right (a review: 7
    /// of 490 random runs on rotors 0.25 × the paper's). Not judged without a pressure.
    fn speed_contradicted(&self, m: &Measurements<T>) -> bool {
        let (Some(w), Some(p)) = (m.speed_rpm, m.pressure_mca) else {
            return false;
        };
        // (A NaN is not 0: the range check refuses it.) The check stays off the observer's
        // usual step: its cost is the 1 ms tick's worst case.
        if !(w == T::ZERO && self.x[SPEED] > T::ZERO) {
            return false;
        }
        let par = &self.cfg.params;
        // The head at no flow: the cubic's constant term alone (its other terms are not
        // computed). A NaN pressure fails the comparison; a pressure over its plausible range
        // is not judged (the transmitter's, not the speed's).
        let shutoff = CubicInFlow::from_poly(&par.alpha, w).c0;
        let most = (self.cfg.scale_range.1 * shutoff).max(-par.static_head_c_mca);
        p > most + T::from_f64(SPEED_HEAD_MARGIN_MCA) && p <= T::from_f64(PRESSURE_MAX_MCA)
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
        let phi = self.transition(&h0, &k, dt);
        let te_start = self.te_applied;
        self.advance_mean(&h0, &k, te, dt);

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
        // (Written out: the loop over the two indices kept a bounds check on the M4, and its
        // panic's formatting in the image.)
        self.x[HEAD_SCALE] = self.x[HEAD_SCALE].max(c.scale_range.0).min(c.scale_range.1);
        self.x[TORQUE_SCALE] = self.x[TORQUE_SCALE]
            .max(c.scale_range.0)
            .min(c.scale_range.1);
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
