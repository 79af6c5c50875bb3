//! The white-box bench: one ODE in speed with the flow loop solved at every evaluation.

use crate::equations::{
    dry_friction_torque_pct, electromagnetic_torque_pct, flow_balance_poly, flow_balance_poly_expr,
    load_torque_pct, pipe_loss_mca, pump_head_mca, speed_derivative_rpm_per_s, system_k,
    system_k_expr, valve_pressure_mca, CubicInFlow,
};
use crate::error::BenchError;
use crate::flow::solve_flow;
use crate::params::{
    BenchParams, FITTED_FLOW_MAX_LPS, FITTED_SPEED_MAX_RPM, FITTED_SPEED_MIN_RPM, RPM_PER_RAD_S,
};
use crate::scalar::{PerScalar, Real};
use crate::units::checked_torque_pct;

/// Largest integration step accepted, s. RK4 is stable up to ≈ 0.6 s at the bench's fastest
/// time constant (≈ 0.22 s) and Euler up to ≈ 0.44 s; 0.1 s keeps every scheme well inside.
pub const MAX_STEP_S: f64 = 0.1;
/// Smallest integration step accepted, s (1 µs: a thousandth of the default step; smaller
/// steps only add rounding and time).
pub const MIN_STEP_S: f64 = 1e-6;
/// Upper end of the steady-state search, rpm.
pub const STEADY_SEARCH_MAX_RPM: f64 = 6000.0;
/// Speed increment of the steady-state scan, rpm (the scan finds the lowest equilibrium, the
/// one the bench settles at from rest).
pub const STEADY_SCAN_STEP_RPM: f64 = 25.0;

/// Fixed-step integration scheme; the torque reference is held over a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scheme {
    /// Classic 4th-order Runge-Kutta: 3 flow solves per step plus 1 for the new state, each
    /// warm-started from the previous one (stage 4 from a linear extrapolation).
    #[default]
    Rk4,
    /// Heun (explicit trapezoid, 2nd order): 1 + 1 flow solves per step.
    Heun,
    /// Forward Euler (1st order): 1 flow solve per step.
    Euler,
}

/// The integrator's state: small, `Copy`, owned by the caller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchState<T> {
    /// Motor/pump speed, rpm, ≥ 0.
    pub speed_rpm: T,
    /// Flow at `speed_rpm`, l/s (the solution of the flow loop, kept for the next warm start).
    pub flow_lps: T,
    /// Torque reference that acted over the last step, % of nominal.
    pub torque_ref_pct: T,
    /// Kahan compensation of `speed_rpm`: keeps tiny f32 increments (small steps near
    /// equilibrium) from being rounded away.
    speed_carry_rpm: T,
    /// The model's load generation `flow_lps` was solved for (see [`WhiteBox::set_load`]).
    load_generation: u32,
}

impl<T: Real> BenchState<T> {
    /// The bench at rest: zero speed, zero flow, zero torque reference.
    pub fn at_rest() -> Self {
        Self {
            speed_rpm: T::ZERO,
            flow_lps: T::ZERO,
            torque_ref_pct: T::ZERO,
            speed_carry_rpm: T::ZERO,
            load_generation: 0,
        }
    }
}

/// Which fitted range a signal is outside of (the result is still computed: extrapolated).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Extrapolation {
    /// Speed below 351 rpm (11.7π rad/s).
    pub speed_below: bool,
    /// Speed above 1749 rpm (58.3π rad/s).
    pub speed_above: bool,
    /// Flow above 27.8 l/s.
    pub flow_above: bool,
}

impl Extrapolation {
    /// `true` if any signal is outside the range the polynomials were fitted on.
    pub fn any(&self) -> bool {
        self.speed_below || self.speed_above || self.flow_above
    }
}

/// Every signal of the bench at one state: the paper's "other signals for free".
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Signals<T> {
    /// Speed, rpm.
    pub speed_rpm: T,
    /// Speed, rad/s.
    pub speed_rad_s: T,
    /// Flow, l/s.
    pub flow_lps: T,
    /// Outlet pressure `Hs`, mca (−c with no flow).
    pub pressure_mca: T,
    /// Pump head `F_H(ω, Q)`, eq. (5), mca. Equals pipe loss + `Hs` while there is flow.
    pub pump_head_mca: T,
    /// Pipe loss `k1 Q²`, eq. (7), mca.
    pub pipe_loss_mca: T,
    /// Electromagnetic torque `Te(u)`, eq. (4), % of nominal.
    pub electromagnetic_torque_pct: T,
    /// Load torque `F_T(ω, Q)`, eq. (6), % of nominal.
    pub load_torque_pct: T,
    /// Outside the fitted range?
    pub extrapolation: Extrapolation,
}

/// The white-box bench model (coefficients only; the state is a separate [`BenchState`]).
///
/// [`WhiteBox::new`] validates a parameter set at run time; for f32 and f64 the paper's bench
/// is also a `const` (`WhiteBox::<f32>::PAPER`, what [`WhiteBox::paper`] returns) and
/// `WhiteBox::<f32>::new_const` builds one at compile time, where a parameter set that fails
/// validation is a build error:
///
/// ```
/// use model_core::{BenchParams, WhiteBox};
/// const HEAVIER: BenchParams<f32> = {
///     let mut p = BenchParams::<f32>::PAPER;
///     p.inertia_kg_m2 = 0.1; // kg·m²
///     p
/// };
/// const BENCH: WhiteBox<f32> = match WhiteBox::<f32>::new_const(HEAVIER) {
///     Ok(bench) => bench,
///     Err(_) => panic!("invalid bench parameters"),
/// };
/// assert!(BENCH.accel_rpm_per_s_per_pct() < WhiteBox::<f32>::PAPER.accel_rpm_per_s_per_pct());
/// ```
///
/// The same with a zero inertia does not build:
///
/// ```compile_fail
/// use model_core::{BenchParams, WhiteBox};
/// const HEAVIER: BenchParams<f32> = {
///     let mut p = BenchParams::<f32>::PAPER;
///     p.inertia_kg_m2 = 0.0; // kg·m²
///     p
/// };
/// const BENCH: WhiteBox<f32> = match WhiteBox::<f32>::new_const(HEAVIER) {
///     Ok(bench) => bench,
///     Err(_) => panic!("invalid bench parameters"),
/// };
/// assert!(BENCH.accel_rpm_per_s_per_pct() < WhiteBox::<f32>::PAPER.accel_rpm_per_s_per_pct());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WhiteBox<T> {
    params: BenchParams<T>,
    /// k1 + k2², mca/(l/s)².
    system_k: T,
    /// rpm/s per % of torque surplus.
    accel: T,
    /// α1..α10 with the load folded in (α5 − k1 − k2², α10 + c): the flow-balance cubic
    /// `g(ω, Q)` in the layout of eq. (5), mca.
    balance_poly: [T; 10],
    /// Incremented by every load change, so a state's flow is re-solved after one.
    load_generation: u32,
}

/// `const fn` constructors for one concrete scalar type (generic `const fn` arithmetic is not
/// possible on stable): the same operations in the same order as [`WhiteBox::new`], so the
/// same bench (a test holds them equal).
macro_rules! const_white_box {
    ($t:ty) => {
        impl WhiteBox<$t> {
            /// The paper's bench ([`BenchParams::paper`] in this type), built at compile time:
            /// no arithmetic at run time, and a build error if its parameters failed
            /// validation.
            pub const PAPER: Self = match Self::new_const(BenchParams::<$t>::PAPER) {
                Ok(bench) => bench,
                Err(BenchError::InvalidParameter(why)) => panic!("{}", why),
                Err(_) => panic!("invalid parameters"),
            };

            /// [`WhiteBox::new`] as a `const fn`: validates `params`
            /// (`BenchParams::validate_const`) and builds the model. In a `const` item, match
            /// the result and `panic!` on an error to make a bad parameter set a build error.
            pub const fn new_const(params: BenchParams<$t>) -> Result<Self, BenchError> {
                if let Err(e) = params.validate_const() {
                    return Err(e);
                }
                // The expressions of `equations::{system_k, flow_balance_poly}`.
                let system_k = system_k_expr!(params.pipe_k1, params.valve_k2);
                let balance_poly =
                    flow_balance_poly_expr!(params.alpha, system_k, params.static_head_c_mca);
                Ok(Self {
                    system_k,
                    accel: params.accel_const(),
                    balance_poly,
                    params,
                    load_generation: 0,
                })
            }
        }
    };
}

const_white_box!(f32);
const_white_box!(f64);

impl<T: Real> BenchParams<T> {
    /// The paper's coefficients (as printed), rounded to `T`: a copy of compile-time data
    /// (`BenchParams::<f64>::PAPER` or `BenchParams::<f32>::PAPER`), no arithmetic at run
    /// time. (Written here, beside [`WhiteBox::paper`], so that the target holds the set
    /// once, inside the paper's bench.)
    #[inline]
    pub fn paper() -> Self {
        *WhiteBox::<T>::paper().params()
    }
}

/// `WhiteBox::<f32>::PAPER` and `WhiteBox::<f64>::PAPER`, for [`WhiteBox::paper`].
struct PaperBench;

impl PerScalar for PaperBench {
    type Of<R: Real> = WhiteBox<R>;
    const F32: WhiteBox<f32> = WhiteBox::<f32>::PAPER;
    const F64: WhiteBox<f64> = WhiteBox::<f64>::PAPER;
}

/// Each type's `new_const`, for [`WhiteBox::new`]: one construction.
struct NewConst;

impl PerScalar for NewConst {
    type Of<R: Real> = fn(BenchParams<R>) -> Result<WhiteBox<R>, BenchError>;
    const F32: fn(BenchParams<f32>) -> Result<WhiteBox<f32>, BenchError> =
        WhiteBox::<f32>::new_const;
    const F64: fn(BenchParams<f64>) -> Result<WhiteBox<f64>, BenchError> =
        WhiteBox::<f64>::new_const;
}

impl<T: Real> WhiteBox<T> {
    /// Validates `params` and builds the model (the `const fn` [`WhiteBox::new_const`] of
    /// `T`: one construction for run time and compile time).
    pub fn new(params: BenchParams<T>) -> Result<Self, BenchError> {
        (T::per_scalar::<NewConst>())(params)
    }

    /// The paper's bench: a copy of compile-time data (`WhiteBox::<f32>::PAPER` or
    /// `WhiteBox::<f64>::PAPER`), nothing computed at run time.
    #[inline]
    pub fn paper() -> Self {
        T::per_scalar::<PaperBench>()
    }

    /// rpm/s of speed change per % of torque surplus
    /// ([`BenchParams::accel_rpm_per_s_per_pct`]).
    pub fn accel_rpm_per_s_per_pct(&self) -> T {
        self.accel
    }

    /// One forward-Euler step of `dt_s` seconds of the pump running dry (no water: eq. (3) with
    /// the friction alone, [`crate::equations::dry_friction_torque_pct`]) under the torque
    /// reference `torque_ref_pct` (%, as delivered): the speed kept within
    /// 0..=[`STEADY_SEARCH_MAX_RPM`], the flow 0. Euler at 1 ms is ample for this first-order
    /// run-up (the virtual bench's dry run and the observer's dry-run test records).
    pub fn dry_run_step(&self, state: &mut BenchState<T>, torque_ref_pct: T, dt_s: T) {
        let te = electromagnetic_torque_pct(&self.params.gamma, torque_ref_pct);
        let w = state.speed_rpm;
        let friction = dry_friction_torque_pct(&self.params.beta, w);
        let rate = speed_derivative_rpm_per_s(te, friction, self.accel);
        state.speed_rpm = (w + dt_s * rate)
            .max(T::ZERO)
            .min(T::from_f64(STEADY_SEARCH_MAX_RPM));
        state.flow_lps = T::ZERO;
    }

    /// The parameters in use.
    pub fn params(&self) -> &BenchParams<T> {
        &self.params
    }

    /// Changes the load: valve coefficient `k2` (√mca/(l/s), finite, ≥ 0) and static head `c`
    /// (mca, finite). On error nothing changes. A state's flow, solved for the old load, is
    /// re-solved by the next [`Self::step`] and [`Self::signals`] (a load generation is kept
    /// in both).
    pub fn set_load(&mut self, valve_k2: T, static_head_c_mca: T) -> Result<(), BenchError> {
        if !valve_k2.is_finite() || !static_head_c_mca.is_finite() {
            return Err(BenchError::InvalidParameter("non-finite load"));
        }
        if valve_k2 < T::ZERO {
            return Err(BenchError::InvalidParameter("k2 must be >= 0"));
        }
        self.params.valve_k2 = valve_k2;
        self.params.static_head_c_mca = static_head_c_mca;
        self.system_k = system_k(self.params.pipe_k1, valve_k2);
        self.balance_poly = flow_balance_poly(&self.params.alpha, self.system_k, static_head_c_mca);
        self.load_generation = self.load_generation.wrapping_add(1);
        Ok(())
    }

    /// Flow (l/s) at `speed_rpm`, solving the flow loop with a warm start (any guess).
    #[inline]
    pub fn flow_at(&self, speed_rpm: T, warm_start_lps: T) -> T {
        solve_flow(&self.balance(speed_rpm), warm_start_lps).flow_lps
    }

    /// The flow-balance cubic at `speed_rpm` (see [`crate::flow`]): the load folded into α
    /// beforehand ([`crate::equations::flow_balance_poly`]; the same as
    /// [`crate::equations::flow_balance`] with scale 1 up to rounding).
    #[inline]
    pub fn balance(&self, speed_rpm: T) -> CubicInFlow<T> {
        CubicInFlow::from_poly(&self.balance_poly, speed_rpm)
    }

    /// Checks a torque reference: finite and within 0..=100 %
    /// ([`crate::units::checked_torque_pct`]: the white-box refuses what the torque rule
    /// would clamp).
    pub fn check_torque(torque_ref_pct: T) -> Result<(), BenchError> {
        checked_torque_pct(torque_ref_pct).map(|_| ())
    }

    /// dω/dt in rpm/s at `speed_rpm` with flow `flow_lps` and electromagnetic torque `te_pct`.
    #[inline]
    fn derivative(&self, te_pct: T, speed_rpm: T, flow_lps: T) -> T {
        speed_derivative_rpm_per_s(
            te_pct,
            load_torque_pct(&self.params.beta, speed_rpm, flow_lps),
            self.accel,
        )
    }

    /// Flow and dω/dt at `speed_rpm`, the flow warm-started from `warm_lps`.
    #[inline]
    fn stage(&self, te_pct: T, speed_rpm: T, warm_lps: T) -> (T, T) {
        let q = self.flow_at(speed_rpm, warm_lps);
        (q, self.derivative(te_pct, speed_rpm, q))
    }

    /// Advances `state` by one step of `dt_s` seconds (finite, 0 < dt ≤ [`MAX_STEP_S`]) with the
    /// torque reference `torque_ref_pct` (0..=100 %) held over the step.
    ///
    /// The new speed and flow are in `state`; every other signal comes from
    /// [`Self::signals`], computed only when asked for (it costs two polynomial evaluations,
    /// which a loop that samples every 50 ms need not pay every 1 ms step).
    /// On error the state is unchanged.
    pub fn step(
        &self,
        state: &mut BenchState<T>,
        torque_ref_pct: T,
        dt_s: T,
        scheme: Scheme,
    ) -> Result<(), BenchError> {
        Self::check_torque(torque_ref_pct)?;
        if !dt_s.is_finite() || !(dt_s >= T::from_f64(MIN_STEP_S)) || dt_s > T::from_f64(MAX_STEP_S)
        {
            return Err(BenchError::InvalidStep);
        }
        self.step_unchecked(state, torque_ref_pct, dt_s, scheme)
    }

    /// [`Self::step`] without the input checks (the caller has done them).
    fn step_unchecked(
        &self,
        state: &mut BenchState<T>,
        torque_ref_pct: T,
        h: T,
        scheme: Scheme,
    ) -> Result<(), BenchError> {
        let te = electromagnetic_torque_pct(&self.params.gamma, torque_ref_pct);
        let w0 = state.speed_rpm;
        let q0 = self.current_flow(state);
        let k1 = self.derivative(te, w0, q0);
        let half = T::from_f64(0.5);
        // Each flow solve is warm-started from the flow at the nearest speed solved so far;
        // `near` is the one closest to the new speed.
        let (increment, near) = match scheme {
            Scheme::Euler => (h * k1, q0),
            Scheme::Heun => {
                let (q2, k2) = self.stage(te, w0 + h * k1, q0);
                (h * half * (k1 + k2), q2)
            }
            Scheme::Rk4 => {
                let (q2, k2) = self.stage(te, w0 + half * h * k1, q0);
                let (q3, k3) = self.stage(te, w0 + half * h * k2, q2);
                // Stage 4's speed is about twice as far from w0 as stage 3's (h k3 against
                // h k2 / 2): extrapolate the flow linearly (a non-positive guess is ignored).
                let (q4, k4) = self.stage(te, w0 + h * k3, q3 + (q3 - q0));
                let two = T::from_f64(2.0);
                (h / T::from_f64(6.0) * (k1 + two * (k2 + k3) + k4), q4)
            }
        };
        // Kahan-compensated update of the speed.
        let y = increment - state.speed_carry_rpm;
        let w1 = w0 + y;
        let carry = (w1 - w0) - y;
        let q1 = self.flow_at(w1, near);
        if !w1.is_finite() || !q1.is_finite() || !carry.is_finite() {
            return Err(BenchError::Diverged);
        }
        state.speed_rpm = w1;
        state.speed_carry_rpm = carry;
        state.flow_lps = q1;
        state.torque_ref_pct = torque_ref_pct;
        state.load_generation = self.load_generation;
        Ok(())
    }

    /// Holds `torque_ref_pct` for `duration_s` seconds (finite, ≥ 0), in the smallest number
    /// of equal steps no longer than `max_step_s` (so that the end time is hit exactly).
    ///
    /// Returns the number of steps taken. On error the state is unchanged.
    pub fn advance(
        &self,
        state: &mut BenchState<T>,
        torque_ref_pct: T,
        duration_s: f64,
        max_step_s: f64,
        scheme: Scheme,
    ) -> Result<u64, BenchError> {
        Self::check_torque(torque_ref_pct)?;
        if !duration_s.is_finite()
            || duration_s < 0.0
            || !max_step_s.is_finite()
            || !(max_step_s >= MIN_STEP_S)
            || max_step_s > MAX_STEP_S
        {
            return Err(BenchError::InvalidStep);
        }
        if duration_s == 0.0 {
            return Ok(0);
        }
        // Smallest n with duration/n ≤ max_step (with a relative slack of 1e-9 so that
        // 0.05 s at 1 ms gives 50 steps, not 51, despite rounding).
        let ratio = duration_s / max_step_s;
        let mut n = libm::ceil(ratio) as u64;
        if n > 1 && (n - 1) as f64 >= ratio * (1.0 - 1e-9) {
            n -= 1;
        }
        let n = n.max(1);
        let h = T::from_f64(duration_s / n as f64);
        let mut next = *state;
        for _ in 0..n {
            self.step_unchecked(&mut next, torque_ref_pct, h, scheme)?;
        }
        *state = next;
        Ok(n)
    }

    /// The state's flow, re-solved if the load changed since it was computed.
    #[inline]
    fn current_flow(&self, state: &BenchState<T>) -> T {
        if state.load_generation == self.load_generation {
            state.flow_lps
        } else {
            self.flow_at(state.speed_rpm, state.flow_lps)
        }
    }

    /// Every signal at `state` (pump head, pipe loss, torques, pressure, extrapolation flags).
    pub fn signals(&self, state: &BenchState<T>) -> Signals<T> {
        let w = state.speed_rpm;
        let q = self.current_flow(state);
        let p = &self.params;
        Signals {
            speed_rpm: w,
            speed_rad_s: w / T::from_f64(RPM_PER_RAD_S),
            flow_lps: q,
            pressure_mca: valve_pressure_mca(p.valve_k2, p.static_head_c_mca, q),
            pump_head_mca: pump_head_mca(&p.alpha, w, q),
            pipe_loss_mca: pipe_loss_mca(p.pipe_k1, q),
            electromagnetic_torque_pct: electromagnetic_torque_pct(&p.gamma, state.torque_ref_pct),
            load_torque_pct: load_torque_pct(&p.beta, w, q),
            extrapolation: Extrapolation {
                speed_below: w < T::from_f64(FITTED_SPEED_MIN_RPM),
                speed_above: w > T::from_f64(FITTED_SPEED_MAX_RPM),
                flow_above: q > T::from_f64(FITTED_FLOW_MAX_LPS),
            },
        }
    }

    /// Torque surplus `Te(u) − F_T(ω, Q(ω))`, % of nominal, and the flow at `speed_rpm`.
    fn surplus(&self, te_pct: T, speed_rpm: T, warm_lps: T) -> (T, T) {
        let q = self.flow_at(speed_rpm, warm_lps);
        (te_pct - load_torque_pct(&self.params.beta, speed_rpm, q), q)
    }

    /// The steady state for a constant torque reference (0..=100 %): the lowest speed where
    /// `Te(u) = F_T(ω, Q(ω))` with a falling surplus, i.e. where the bench settles from rest.
    ///
    /// A scan in [`STEADY_SCAN_STEP_RPM`] steps brackets it, bisection refines it to a few ulps.
    pub fn steady_state(&self, torque_ref_pct: T) -> Result<BenchState<T>, BenchError> {
        Self::check_torque(torque_ref_pct)?;
        let te = electromagnetic_torque_pct(&self.params.gamma, torque_ref_pct);
        let step = T::from_f64(STEADY_SCAN_STEP_RPM);
        let limit = T::from_f64(STEADY_SEARCH_MAX_RPM);
        let (mut lo, mut hi) = (T::ZERO, T::ZERO);
        let (s0, mut q) = self.surplus(te, T::ZERO, T::ZERO);
        if s0 <= T::ZERO {
            // Cannot start from rest: the state at rest is the steady state.
            return Ok(self.state_with(T::ZERO, q, torque_ref_pct));
        }
        let mut found = false;
        while hi < limit {
            lo = hi;
            hi += step;
            let (s, q_hi) = self.surplus(te, hi, q);
            q = q_hi;
            if !s.is_finite() {
                return Err(BenchError::NoSteadyState);
            }
            if s <= T::ZERO {
                found = true;
                break;
            }
        }
        if !found {
            return Err(BenchError::NoSteadyState);
        }
        let two = T::from_f64(2.0);
        for _ in 0..200 {
            let mid = (lo + hi) / two;
            if !(mid > lo && mid < hi) {
                break;
            }
            let (s, q_mid) = self.surplus(te, mid, q);
            q = q_mid;
            if s > T::ZERO {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let w = (lo + hi) / two;
        let q = self.flow_at(w, q);
        Ok(self.state_with(w, q, torque_ref_pct))
    }

    fn state_with(&self, speed_rpm: T, flow_lps: T, torque_ref_pct: T) -> BenchState<T> {
        BenchState {
            speed_rpm,
            flow_lps,
            torque_ref_pct,
            speed_carry_rpm: T::ZERO,
            load_generation: self.load_generation,
        }
    }

    /// A state at `speed_rpm` (finite, ≥ 0) with its flow solved and the torque reference set,
    /// e.g. to start a simulation from a measured speed.
    pub fn state_at_speed(
        &self,
        speed_rpm: T,
        torque_ref_pct: T,
    ) -> Result<BenchState<T>, BenchError> {
        Self::check_torque(torque_ref_pct)?;
        if !speed_rpm.is_finite() || speed_rpm < T::ZERO {
            return Err(BenchError::InvalidParameter(
                "speed must be finite and >= 0",
            ));
        }
        let q = self.flow_at(speed_rpm, T::ZERO);
        Ok(self.state_with(speed_rpm, q, torque_ref_pct))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_parameters_validate() {
        assert!(BenchParams::<f32>::paper().validate().is_ok());
        assert!(BenchParams::<f64>::paper().validate().is_ok());
        let mut p = BenchParams::<f64>::paper();
        p.alpha[0] = 1e-3;
        assert!(WhiteBox::new(p).is_err());
        p = BenchParams::paper();
        p.inertia_kg_m2 = 0.0;
        assert!(WhiteBox::new(p).is_err());
        p = BenchParams::paper();
        p.beta[3] = f64::NAN;
        assert!(WhiteBox::new(p).is_err());
    }

    #[test]
    fn const_benches_equal_the_run_time_ones() {
        assert_eq!(
            WhiteBox::new(BenchParams::<f32>::PAPER),
            Ok(WhiteBox::<f32>::PAPER)
        );
        assert_eq!(
            WhiteBox::new(BenchParams::<f64>::PAPER),
            Ok(WhiteBox::<f64>::PAPER)
        );
        assert_eq!(WhiteBox::<f32>::paper(), WhiteBox::<f32>::PAPER);
        assert_eq!(WhiteBox::<f64>::paper(), WhiteBox::<f64>::PAPER);
        // Another set (the virtual bench's kind of change) and a load change after it.
        let mut p = BenchParams::<f32>::PAPER;
        p.inertia_kg_m2 *= 1.05;
        p.valve_k2 *= 1.02;
        let (mut at_build, mut at_run) = (
            WhiteBox::<f32>::new_const(p).unwrap(),
            WhiteBox::new(p).unwrap(),
        );
        assert_eq!(at_build, at_run);
        assert_ne!(at_build, WhiteBox::<f32>::PAPER);
        at_build.set_load(0.09, 0.3).unwrap();
        at_run.set_load(0.09, 0.3).unwrap();
        assert_eq!(at_build, at_run);
        p.alpha[0] = 0.0;
        assert_eq!(WhiteBox::<f32>::new_const(p), WhiteBox::new(p));
        assert!(WhiteBox::new(p).is_err());
    }

    #[test]
    fn advance_hits_the_end_time_with_few_equal_steps() {
        let b = WhiteBox::<f64>::paper();
        let mut s = b.steady_state(20.0).unwrap();
        assert_eq!(b.advance(&mut s, 30.0, 0.05, 1e-3, Scheme::Rk4), Ok(50));
        assert_eq!(b.advance(&mut s, 30.0, 0.0015, 1e-3, Scheme::Rk4), Ok(2));
        assert_eq!(b.advance(&mut s, 30.0, 0.0, 1e-3, Scheme::Rk4), Ok(0));
        assert_eq!(
            b.advance(&mut s, 30.0, 1.0, 0.3, Scheme::Rk4),
            Err(BenchError::InvalidStep)
        );
        assert_eq!(
            b.advance(&mut s, 30.0, -1.0, 1e-3, Scheme::Rk4),
            Err(BenchError::InvalidStep)
        );
    }

    #[test]
    fn a_load_change_mid_run_re_solves_the_flow() {
        let mut b = WhiteBox::<f64>::paper();
        let mut s = b.steady_state(50.0).unwrap();
        b.set_load(0.08, 0.3).unwrap();
        let sig = b.signals(&s);
        assert!((sig.pump_head_mca - sig.pipe_loss_mca - sig.pressure_mca).abs() < 1e-9);
        // One step after the change equals one step from a state solved for the new load.
        let mut fresh = b.state_at_speed(s.speed_rpm, 50.0).unwrap();
        b.step(&mut s, 50.0, 1e-3, Scheme::Rk4).unwrap();
        b.step(&mut fresh, 50.0, 1e-3, Scheme::Rk4).unwrap();
        assert!((s.speed_rpm - fresh.speed_rpm).abs() < 1e-12 * fresh.speed_rpm);
        assert!((s.flow_lps - fresh.flow_lps).abs() < 1e-12 * fresh.flow_lps);
    }

    #[test]
    fn opening_the_valve_raises_flow_and_lowers_pressure() {
        let mut b = WhiteBox::<f64>::paper();
        let half = b.signals(&b.steady_state(50.0).unwrap());
        b.set_load(0.08, 0.252).unwrap();
        let open = b.signals(&b.steady_state(50.0).unwrap());
        assert!(open.flow_lps > half.flow_lps && open.pressure_mca < half.pressure_mca);
    }

    #[test]
    fn kahan_keeps_small_f32_increments() {
        // 1e-5 s steps near equilibrium: the increments are below half an ulp of the speed,
        // which plain summation would drop. The compensated state still moves as f64 does.
        let b32 = WhiteBox::<f32>::paper();
        let b64 = WhiteBox::<f64>::paper();
        let mut s32 = b32.steady_state(50.0).unwrap();
        let mut s64 = b64.steady_state(50.0).unwrap();
        b32.advance(&mut s32, 50.2, 0.5, 1e-5, Scheme::Rk4).unwrap();
        b64.advance(&mut s64, 50.2, 0.5, 1e-5, Scheme::Rk4).unwrap();
        let rel = (s32.speed_rpm as f64 / s64.speed_rpm - 1.0).abs();
        assert!(rel < 1e-6, "{rel}");
    }

    #[test]
    fn signals_hold_the_head_balance_and_flags() {
        let b = WhiteBox::<f64>::paper();
        let s = b.signals(&b.steady_state(50.0).unwrap());
        assert!((s.pump_head_mca - s.pipe_loss_mca - s.pressure_mca).abs() < 1e-9);
        assert!((s.electromagnetic_torque_pct - s.load_torque_pct).abs() < 1e-9);
        assert!((s.speed_rad_s * 30.0 / core::f64::consts::PI - s.speed_rpm).abs() < 1e-9);
        assert!(!s.extrapolation.any());
        let low = b.signals(&b.steady_state(5.0).unwrap());
        assert!(low.extrapolation.speed_below && !low.extrapolation.speed_above);
    }
}
