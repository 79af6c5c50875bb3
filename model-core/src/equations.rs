//! The paper's equations (3)-(8), their combinations (the flow balance, eqs. 5 + 7 + 8) and
//! the partial derivatives the observer needs: each written once, here, and called from
//! every model (the white-box bench, the flow solver, the observer, the alarm monitor, the
//! controller's virtual bench). Units as in [`crate::params`]: speed in rpm, flow in l/s,
//! heads in mca, torques in % of the nominal torque.
//!
//! Where a model scales a curve (the observer's head and load-torque scales `s_H`, `s_T`)
//! the scale is a parameter; 1 is the paper's curve.
//!
//! # Two evaluation orders of the flow balance
//!
//! The balance `g(ω, Q) = s_H F_H(ω, Q) − (k1 + k2²) Q² + c` is evaluated in two orders,
//! each kept because a hot path's results are defined by it to the last bit:
//! [`flow_balance_poly`] folds the load into α once, for a model whose load is a parameter
//! (the white-box bench: no scale, k2 and c change rarely), and [`flow_balance`] applies the
//! scale and the load at each evaluation, for a model whose scale and k2 are states (the
//! observer). They agree to a few ulps (tested below). Likewise ∂F_H/∂Q comes in Horner form
//! from [`CubicInFlow::slope`] (the solver's and the observer's water column) and expanded
//! with ∂F_H/∂ω from [`pump_head_partials`] (the observer's linearisation).
//!
//! # In `const fn`s
//!
//! The compile-time constructors of f32 and f64 (`WhiteBox::<f32>::new_const`,
//! `BenchParams::<f32>::accel_const`) need three of these expressions as well, and generic
//! `const fn` arithmetic is not possible on stable: [`system_k`], [`flow_balance_poly`] and
//! [`accel_rpm_per_s_per_pct`] are each written once as a crate-internal macro, which both
//! the generic function and the `const fn`s expand (same operations, same order, same bits).

use crate::scalar::Real;

/// `k1 + k2²` (eqs. 7 + 8) as an expression; see the module docs (`const fn`s).
macro_rules! system_k_expr {
    ($pipe_k1:expr, $valve_k2:expr) => {
        $pipe_k1 + $valve_k2 * $valve_k2
    };
}

/// α with the load folded in (eqs. 5 + 7 + 8) as an expression: `α5 − (k1 + k2²)`,
/// `α10 + c`; see the module docs (`const fn`s). `$alpha` is an array value (copied).
macro_rules! flow_balance_poly_expr {
    ($alpha:expr, $system_k:expr, $static_head_c_mca:expr) => {{
        let mut p = $alpha;
        p[4] = p[4] - $system_k;
        p[9] += $static_head_c_mca;
        p
    }};
}

/// `(T_nom / 100) / J · 30/π` (eq. 3's constant) as an expression, with `100` and `30/π`
/// given in the caller's type; see the module docs (`const fn`s).
macro_rules! accel_expr {
    ($nominal_torque_nm:expr, $inertia_kg_m2:expr, $hundred:expr, $rpm_per_rad_s:expr) => {
        $nominal_torque_nm / $hundred / $inertia_kg_m2 * $rpm_per_rad_s
    };
}

pub(crate) use {accel_expr, flow_balance_poly_expr, system_k_expr};

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

/// The indices (0-based) of eq. (5)/(6)'s ten coefficients whose terms hold the flow Q
/// (`p1 Q³`, `p3 Q²ω`, `p4 Qω²`, `p5 Q²`, `p7 Qω`, `p8 Q`): those
/// [`CubicInFlow::from_poly`] puts in `c3`, `c2` and `c1`; the other four make the value at
/// no flow. (What a curve's shape error scales on the host's test benches.)
pub const FLOW_TERMS: [usize; 6] = [0, 2, 3, 4, 6, 7];

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

/// The slope of eq. (4), `dTe/du`, % per % (what the reference's inverse and the bench's
/// linearisation divide by).
#[inline]
pub fn electromagnetic_torque_slope<T: Real>(gamma: &[T; 6], torque_ref_pct: T) -> T {
    let u = torque_ref_pct;
    let (five, four, three, two) = (
        T::from_f64(5.0),
        T::from_f64(4.0),
        T::from_f64(3.0),
        T::from_f64(2.0),
    );
    (((five * gamma[0] * u + four * gamma[1]) * u + three * gamma[2]) * u + two * gamma[3]) * u
        + gamma[4]
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

/// The part of eq. (6) a dry pump meets: the friction terms `β9 ω + β10` (b ω + Tc of eq. 3),
/// % of nominal torque, with no water to move (the virtual bench's dry run).
#[inline]
pub fn dry_friction_torque_pct<T: Real>(beta: &[T; 10], speed_rpm: T) -> T {
    beta[8] * speed_rpm + beta[9]
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

/// Eq. (6) with the observer's load-torque scale: `s_T F_T(ω, Q)`, % of nominal torque
/// (`torque_scale` 1: the paper's curve, [`load_torque_pct`] to the bit).
#[inline]
pub fn scaled_load_torque_pct<T: Real>(
    beta: &[T; 10],
    torque_scale: T,
    speed_rpm: T,
    flow_lps: T,
) -> T {
    torque_scale * load_torque_pct(beta, speed_rpm, flow_lps)
}

/// Eq. (3)'s constant: rpm/s of speed change per % of torque surplus,
/// `(T_nom / 100) / J · 30/π` (≈ 42.95 with the paper's J = 0.08872 kg·m² and
/// T_nom = 39.9 N·m; both > 0).
#[inline]
pub fn accel_rpm_per_s_per_pct<T: Real>(nominal_torque_nm: T, inertia_kg_m2: T) -> T {
    accel_expr!(
        nominal_torque_nm,
        inertia_kg_m2,
        T::from_f64(100.0),
        T::from_f64(crate::params::RPM_PER_RAD_S)
    )
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

/// Eq. (3) solved for the load: the load torque a motion shows, `Te − (dω/dt) / K`, % of
/// nominal torque, from the delivered torque in %, the acceleration in rpm/s and
/// `accel_rpm_per_s_per_pct` K (> 0, rpm/s per %).
#[inline]
pub fn load_torque_from_motion_pct<T: Real>(
    electromagnetic_torque_pct: T,
    speed_rate_rpm_per_s: T,
    accel_rpm_per_s_per_pct: T,
) -> T {
    electromagnetic_torque_pct - speed_rate_rpm_per_s / accel_rpm_per_s_per_pct
}

/// Eqs. (7) + (8): the system curve's coefficient `k1 + k2²`, mca/(l/s)² (pipe plus valve:
/// the head they take is this times Q², less c).
#[inline]
pub fn system_k<T: Real>(pipe_k1: T, valve_k2: T) -> T {
    system_k_expr!(pipe_k1, valve_k2)
}

/// The flow balance (eqs. 5 + 7 + 8) `g(ω, Q) = F_H(ω, Q) − (k1 + k2²) Q² + c` as one
/// polynomial in the layout of eq. (5) (α5 − `system_k`, α10 + c), mca, for a model whose
/// load is a parameter: fold once, then [`CubicInFlow::from_poly`] at each speed. See the
/// module docs for its order against [`flow_balance`].
#[inline]
pub fn flow_balance_poly<T: Real>(alpha: &[T; 10], system_k: T, static_head_c_mca: T) -> [T; 10] {
    flow_balance_poly_expr!(*alpha, system_k, static_head_c_mca)
}

/// The flow balance (eqs. 5 + 7 + 8) with a scaled pump head at the speed `speed_rpm`, as a
/// cubic in Q: `g(Q) = s_H F_H(ω, Q) − (k1 + k2²) Q² + c`, mca (`head_scale` s_H, 1 for the
/// paper's curve; `system_k` from [`system_k`]; `static_head_c_mca` c). Its largest
/// non-negative root is the flow ([`crate::flow::solve_flow`]).
#[inline]
pub fn flow_balance<T: Real>(
    alpha: &[T; 10],
    head_scale: T,
    system_k: T,
    static_head_c_mca: T,
    speed_rpm: T,
) -> CubicInFlow<T> {
    let mut g = CubicInFlow::from_poly(alpha, speed_rpm);
    g.c3 = g.c3 * head_scale;
    g.c2 = g.c2 * head_scale - system_k;
    g.c1 = g.c1 * head_scale;
    g.c0 = g.c0 * head_scale + static_head_c_mca;
    g
}

/// ∂g/∂Q of the flow balance, mca per l/s: `s_H ∂F_H/∂Q − 2 (k1 + k2²) Q`, from the pump
/// head's slope `head_dq` (either form, see the module docs), the head scale, `system_k`
/// and the flow.
#[inline]
pub fn flow_balance_dq<T: Real>(head_dq: T, head_scale: T, system_k: T, flow_lps: T) -> T {
    head_scale * head_dq - T::from_f64(2.0) * system_k * flow_lps
}

/// A curve's value and its partial derivatives at one (ω, Q).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Partials<T> {
    /// The value (mca for the pump head, % for the load torque).
    pub value: T,
    /// ∂/∂ω, per rpm.
    pub d_speed: T,
    /// ∂/∂Q, per l/s.
    pub d_flow: T,
}

/// `p1 Q³ + p2 ω³ + p3 Q²ω + p4 Qω² + p5 Q² + p6 ω² + p7 Qω + p8 Q + p9 ω + p10` (eqs. 5, 6)
/// and its partials in ω and Q (expanded).
#[inline]
fn poly_partials<T: Real>(p: &[T; 10], w: T, q: T) -> Partials<T> {
    let two = T::from_f64(2.0);
    let three = T::from_f64(3.0);
    let value = CubicInFlow::from_poly(p, w).eval(q);
    let d_w =
        three * p[1] * w * w + p[2] * q * q + two * p[3] * q * w + two * p[5] * w + p[6] * q + p[8];
    let d_q =
        three * p[0] * q * q + two * p[2] * q * w + p[3] * w * w + two * p[4] * q + p[6] * w + p[7];
    Partials {
        value,
        d_speed: d_w,
        d_flow: d_q,
    }
}

/// Eq. (5) and its partials: `F_H(ω, Q)` in mca ([`pump_head_mca`] to the bit), ∂F_H/∂ω in
/// mca/rpm, ∂F_H/∂Q in mca/(l/s).
#[inline]
pub fn pump_head_partials<T: Real>(alpha: &[T; 10], speed_rpm: T, flow_lps: T) -> Partials<T> {
    poly_partials(alpha, speed_rpm, flow_lps)
}

/// Eq. (6) and its partials: `F_T(ω, Q)` in % ([`load_torque_pct`] to the bit), ∂F_T/∂ω in
/// %/rpm, ∂F_T/∂Q in %/(l/s).
#[inline]
pub fn load_torque_partials<T: Real>(beta: &[T; 10], speed_rpm: T, flow_lps: T) -> Partials<T> {
    poly_partials(beta, speed_rpm, flow_lps)
}

/// Eq. (8) inverted, its partials: `(∂Hs/∂Q, ∂Hs/∂k2) = (2 k2² Q, 2 k2 Q²)`, mca/(l/s) and
/// mca per unit of k2.
#[inline]
pub fn valve_pressure_partials<T: Real>(valve_k2: T, flow_lps: T) -> (T, T) {
    let two = T::from_f64(2.0);
    (
        two * valve_k2 * valve_k2 * flow_lps,
        two * valve_k2 * flow_lps * flow_lps,
    )
}

/// Eq. (7)'s derivative: `∂(k1 Q²)/∂Q = 2 k1 Q`, mca/(l/s).
#[inline]
pub fn pipe_loss_dq<T: Real>(pipe_k1: T, flow_lps: T) -> T {
    T::from_f64(2.0) * pipe_k1 * flow_lps
}

/// How the flow balance's root Q* (l/s) moves with speed, valve and head scale:
/// `(∂Q*/∂ω, ∂Q*/∂k2, ∂Q*/∂s_H)` by the implicit function theorem on `g(Q*; ω, k2, s_H) = 0`,
/// `∂Q*/∂θ = −(∂g/∂θ) / (∂g/∂Q)`, in l/s per rpm, per unit of k2 and per unit of scale.
///
/// `head` holds F_H and its partials at (ω, Q*) ([`pump_head_partials`]). Zero where there is
/// no flow (Q* ≤ 0) or the balance does not fall through its root (∂g/∂Q ≥ 0: no stable
/// operating point to follow).
#[inline]
pub fn flow_root_sensitivities<T: Real>(
    head: &Partials<T>,
    head_scale: T,
    pipe_k1: T,
    valve_k2: T,
    flow_lps: T,
) -> [T; 3] {
    let q = flow_lps;
    if q > T::ZERO {
        let g_q = flow_balance_dq(head.d_flow, head_scale, system_k(pipe_k1, valve_k2), q);
        if g_q < T::ZERO {
            let (_, hs_k2) = valve_pressure_partials(valve_k2, q);
            [
                -(head_scale * head.d_speed) / g_q,
                hs_k2 / g_q,
                -head.value / g_q,
            ]
        } else {
            [T::ZERO; 3]
        }
    } else {
        [T::ZERO; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::*;
    use crate::BenchParams;

    #[test]
    fn flow_terms_are_those_that_vanish_at_no_flow() {
        for i in 0..10 {
            let mut p = [0.0f64; 10];
            p[i] = 1.0;
            let g = CubicInFlow::from_poly(&p, 1500.0);
            assert_eq!(g.c0 == 0.0, FLOW_TERMS.contains(&i), "coefficient {i}");
        }
    }

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

    /// Speeds, flows, head scales and valves over and beyond the fitted range.
    fn grid() -> impl Iterator<Item = (f64, f64, f64, f64)> {
        let speeds = [0.0, 37.5, 351.0, 902.25, 1749.0, 2600.0];
        let flows = [0.0, 0.75, 9.5, 19.2, 27.8, 33.0];
        let scales = [0.5, 0.97, 1.0, 1.04, 1.5];
        let valves = [0.02, PAPER_K2, 0.3];
        speeds.into_iter().flat_map(move |w| {
            flows.into_iter().flat_map(move |q| {
                scales
                    .into_iter()
                    .flat_map(move |s| valves.into_iter().map(move |k2| (w, q, s, k2)))
            })
        })
    }

    /// The expressions these functions replaced, written out as they stood (the observer's,
    /// the white-box's, the flow solver's and the virtual bench's): the same bits.
    fn same_bits_as_the_former_inline_code<T: Real>() {
        let p = BenchParams::<T>::paper();
        let (k1, c) = (p.pipe_k1, p.static_head_c_mca);
        let two = T::from_f64(2.0);
        for (w, q, s_h, k2) in grid() {
            let (w, q, s_h, k2) = (
                T::from_f64(w),
                T::from_f64(q),
                T::from_f64(s_h),
                T::from_f64(k2),
            );
            let k = system_k(k1, k2);
            assert!(k == k1 + k2 * k2);
            // The observer's balance, with its scale.
            let mut old = CubicInFlow::from_poly(&p.alpha, w);
            old.c3 = old.c3 * s_h;
            old.c2 = old.c2 * s_h - (k1 + k2 * k2);
            old.c1 = old.c1 * s_h;
            old.c0 = old.c0 * s_h + c;
            assert_eq!(flow_balance(&p.alpha, s_h, k, c, w), old);
            // The flow solver's, unscaled.
            let mut old = CubicInFlow::from_poly(&p.alpha, w);
            old.c2 = old.c2 - k;
            old.c0 += c;
            assert_eq!(flow_balance(&p.alpha, T::ONE, k, c, w), old);
            // The white-box's, folded.
            let mut folded = p.alpha;
            folded[4] = folded[4] - k;
            folded[9] += c;
            assert_eq!(flow_balance_poly(&p.alpha, k, c), folded);
            // The two orders agree to a few ulps of the terms' magnitude.
            let g = flow_balance(&p.alpha, T::ONE, k, c, w);
            let f = CubicInFlow::from_poly(&flow_balance_poly(&p.alpha, k, c), w);
            let scale = g.magnitude(q).to_f64().max(1.0);
            assert!((g.eval(q) - f.eval(q)).to_f64().abs() <= 16.0 * T::EPSILON.to_f64() * scale);
            // The observer's slope of the balance, both forms of ∂F_H/∂Q.
            let head_dq = CubicInFlow::from_poly(&p.alpha, w).slope(q);
            let old = s_h * head_dq - T::from_f64(2.0) * (k1 + k2 * k2) * q;
            assert!(flow_balance_dq(head_dq, s_h, k, q) == old);
            // Its partials (the observer's `poly_with_partials`, expanded).
            let a = &p.alpha;
            let three = T::from_f64(3.0);
            let d_w = three * a[1] * w * w
                + a[2] * q * q
                + two * a[3] * q * w
                + two * a[5] * w
                + a[6] * q
                + a[8];
            let d_q = three * a[0] * q * q
                + two * a[2] * q * w
                + a[3] * w * w
                + two * a[4] * q
                + a[6] * w
                + a[7];
            let h = pump_head_partials(&p.alpha, w, q);
            assert!(
                h.value == pump_head_mca(&p.alpha, w, q) && h.d_speed == d_w && h.d_flow == d_q
            );
            let t = load_torque_partials(&p.beta, w, q);
            assert!(t.value == load_torque_pct(&p.beta, w, q));
            // Eq. (8) inverted: the observer's and the virtual bench's `k2 k2 Q Q − c`.
            assert!(valve_pressure_mca(k2, c, q) == k2 * k2 * q * q - c);
            let (hs_q, hs_k2) = valve_pressure_partials(k2, q);
            assert!(hs_q == two * k2 * k2 * q && hs_k2 == two * k2 * q * q);
            assert!(pipe_loss_mca(k1, q) == k1 * q * q);
            assert!(pipe_loss_dq(k1, q) == two * k1 * q);
            // Eq. (3): the observer's `accel (te − s_T F_T)` and the monitor's `te − rate / K`.
            let accel = p.accel_rpm_per_s_per_pct();
            let te = T::from_f64(37.25);
            let load = load_torque_pct(&p.beta, w, q);
            assert!(scaled_load_torque_pct(&p.beta, T::ONE, w, q) == load);
            let scaled = scaled_load_torque_pct(&p.beta, s_h, w, q);
            assert!(speed_derivative_rpm_per_s(te, scaled, accel) == accel * (te - s_h * load));
            let rate = T::from_f64(123.5);
            assert!(load_torque_from_motion_pct(te, rate, accel) == te - rate / accel);
        }
        let j = p.inertia_kg_m2;
        let old = p.nominal_torque_nm / T::from_f64(100.0) / j * T::from_f64(RPM_PER_RAD_S);
        assert!(accel_rpm_per_s_per_pct(p.nominal_torque_nm, j) == old);
    }

    #[test]
    fn same_bits_as_the_former_inline_code_f32_and_f64() {
        same_bits_as_the_former_inline_code::<f32>();
        same_bits_as_the_former_inline_code::<f64>();
    }

    /// Central difference of `f` at `x`, step `h`.
    fn numeric(f: impl Fn(f64) -> f64, x: f64, h: f64) -> f64 {
        (f(x + h) - f(x - h)) / (2.0 * h)
    }

    fn close(analytic: f64, numeric: f64, what: &str) {
        assert!(
            (analytic - numeric).abs() <= 1e-6 * analytic.abs().max(1.0),
            "{what}: {analytic} against {numeric}"
        );
    }

    #[test]
    fn the_torque_slope_is_eq_4s_derivative() {
        let p = BenchParams::<f64>::PAPER;
        for u in (0..=20).map(|k| f64::from(k) * 5.0) {
            close(
                electromagnetic_torque_slope(&p.gamma, u),
                numeric(|u| electromagnetic_torque_pct(&p.gamma, u), u, 1e-4),
                "dTe/du",
            );
        }
    }

    #[test]
    fn partials_match_finite_differences() {
        let p = BenchParams::<f64>::PAPER;
        for (w, q, s_h, k2) in grid() {
            let k = system_k(p.pipe_k1, k2);
            for (curve, c) in [("F_H", &p.alpha), ("F_T", &p.beta)] {
                let d = poly_partials(c, w, q);
                let at = |w: f64, q: f64| CubicInFlow::from_poly(c, w).eval(q);
                close(d.d_speed, numeric(|w| at(w, q), w, 1e-3), curve);
                close(d.d_flow, numeric(|q| at(w, q), q, 1e-5), curve);
            }
            let head = pump_head_partials(&p.alpha, w, q);
            let g = |q: f64| flow_balance(&p.alpha, s_h, k, p.static_head_c_mca, w).eval(q);
            let slope = numeric(g, q, 1e-5);
            close(
                flow_balance_dq(head.d_flow, s_h, k, q),
                slope,
                "∂g/∂Q expanded",
            );
            let horner = CubicInFlow::from_poly(&p.alpha, w).slope(q);
            close(flow_balance_dq(horner, s_h, k, q), slope, "∂g/∂Q Horner");
            let (hs_q, hs_k2) = valve_pressure_partials(k2, q);
            let c = p.static_head_c_mca;
            close(
                hs_q,
                numeric(|q| valve_pressure_mca(k2, c, q), q, 1e-5),
                "∂Hs/∂Q",
            );
            close(
                hs_k2,
                numeric(|k2| valve_pressure_mca(k2, c, q), k2, 1e-7),
                "∂Hs/∂k2",
            );
            let pipe = numeric(|q| pipe_loss_mca(p.pipe_k1, q), q, 1e-5);
            close(pipe_loss_dq(p.pipe_k1, q), pipe, "∂(k1 Q²)/∂Q");
        }
    }

    #[test]
    fn flow_root_sensitivities_match_finite_differences_of_the_solved_root() {
        use crate::flow::solve_flow;
        let p = BenchParams::<f64>::PAPER;
        let (k1, c) = (p.pipe_k1, p.static_head_c_mca);
        let root = |w: f64, k2: f64, s_h: f64| {
            let g = flow_balance(&p.alpha, s_h, system_k(k1, k2), c, w);
            solve_flow(&g, 10.0).flow_lps
        };
        let mut checked = 0;
        for w in [400.0, 900.0, 1500.0, 1749.0] {
            for s_h in [0.9, 1.0, 1.1] {
                for k2 in [0.06, PAPER_K2, 0.2] {
                    let q = root(w, k2, s_h);
                    assert!(q > 0.0);
                    let head = pump_head_partials(&p.alpha, w, q);
                    let d = flow_root_sensitivities(&head, s_h, k1, k2, q);
                    let fd = [
                        numeric(|w| root(w, k2, s_h), w, 1e-2),
                        numeric(|k2| root(w, k2, s_h), k2, 1e-6),
                        numeric(|s_h| root(w, k2, s_h), s_h, 1e-6),
                    ];
                    for (a, n) in d.into_iter().zip(fd) {
                        assert!(
                            (a - n).abs() <= 1e-5 * a.abs().max(1e-3),
                            "{d:?} against {fd:?}"
                        );
                    }
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 36);
        // No flow, or a balance that rises through its root: nothing to follow.
        let head = pump_head_partials(&p.alpha, 0.0, 0.0);
        assert_eq!(
            flow_root_sensitivities(&head, 1.0, k1, PAPER_K2, 0.0),
            [0.0; 3]
        );
        let rising = Partials {
            value: 10.0,
            d_speed: 0.01,
            d_flow: 50.0,
        };
        assert_eq!(
            flow_root_sensitivities(&rising, 1.0, k1, PAPER_K2, 5.0),
            [0.0; 3]
        );
    }

    #[test]
    fn load_from_motion_inverts_the_speed_derivative() {
        let accel = BenchParams::<f64>::PAPER.accel_rpm_per_s_per_pct();
        for (te, load) in [(20.0, 12.5), (85.0, 90.0), (2.244, 0.43)] {
            let rate = speed_derivative_rpm_per_s(te, load, accel);
            assert!((load_torque_from_motion_pct(te, rate, accel) - load).abs() < 1e-12);
        }
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
