//! The bench's steady state run backwards: the torque reference that holds an outlet pressure
//! or a flow at a given load, the feedforward of a pressure or flow controller.
//!
//! The load is what the observer estimates: the valve's k2 and the scales of the pump-head and
//! load-torque curves (1 for the paper's). At a steady state, eqs. (5)-(8) give, in turn:
//!
//! 1. the flow through the valve for the pressure asked, eq. (8): `Q = √(Hs + c) / k2` (or the
//!    flow asked, and its pressure `Hs = k2² Q² − c`);
//! 2. the speed at which the scaled pump head meets the system: `s_H F_H(ω, Q) = (k1 + k2²) Q²
//!    − c` (eqs. 5, 7, 8), the lowest such speed, as [`crate::WhiteBox::steady_state`] finds
//!    the bench settles from rest;
//! 3. the load torque there, `s_T F_T(ω, Q)` (eq. 6), which the drive must deliver;
//! 4. the torque reference whose electromagnetic torque is that, `Te(u) = s_T F_T` (eq. 4),
//!    within 0..=100 %.
//!
//! Steps 2 and 4 bracket by a scan and refine by bisection (to a few ulps), as the white-box's
//! steady state does; [`steady_torque`] is its inverse to within those ulps (tested both ways).
//! A target the bench cannot reach inside 0..=100 % gives the nearest limit, flagged.

use crate::equations::{
    electromagnetic_torque_pct, electromagnetic_torque_slope, flow_root_sensitivities,
    load_torque_partials, pump_head_mca, pump_head_partials, scaled_load_torque_pct, system_k,
    valve_flow_lps, valve_pressure_mca,
};
use crate::error::BenchError;
use crate::params::BenchParams;
use crate::scalar::Real;
use crate::units::MAX_TORQUE_PCT;
use crate::whitebox::{STEADY_SCAN_STEP_RPM, STEADY_SEARCH_MAX_RPM};

/// What a controller holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target<T> {
    /// Outlet pressure, mca (the transmitter's reading, `c` above the tank level).
    PressureMca(T),
    /// Flow, l/s (≥ 0).
    FlowLps(T),
}

/// The load the bench works against, as the observer estimates it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load<T> {
    /// The valve's k2 of eq. (8), √mca/(l/s), > 0.
    pub valve_k2: T,
    /// Scale of the pump-head curve F_H (eq. 5), > 0; 1: the paper's.
    pub head_scale: T,
    /// Scale of the load-torque curve F_T (eq. 6), > 0; 1: the paper's.
    pub torque_scale: T,
}

/// A steady state found backwards from its target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyInverse<T> {
    /// The torque reference that holds the target, % of nominal torque, 0..=100.
    pub torque_ref_pct: T,
    /// The speed there, rpm.
    pub speed_rpm: T,
    /// The flow there, l/s.
    pub flow_lps: T,
    /// The outlet pressure there, mca.
    pub pressure_mca: T,
    /// The target is outside what 0..=100 % holds: `torque_ref_pct` is the nearest limit and
    /// the speed, flow and pressure are the target's, not what that torque gives.
    pub limited: bool,
}

/// The torque reference that holds `target` on the bench `p` (its k1, c, curves and
/// `Te(u)`) against `load` at steady state (see the module docs).
///
/// Errors: a NaN or infinite target, a negative flow, a load that is not finite and > 0
/// ([`BenchError::InvalidParameter`]); no speed below [`STEADY_SEARCH_MAX_RPM`] that gives
/// the head ([`BenchError::NoSteadyState`]: the target is beyond the pump).
pub fn steady_torque<T: Real>(
    p: &BenchParams<T>,
    load: Load<T>,
    target: Target<T>,
) -> Result<SteadyInverse<T>, BenchError> {
    // Steps 1 and 2: the flow, the pressure, the head the pump must give; then the lowest
    // speed that gives it.
    let (flow, pressure, head) = operating_point(p, load, target)?;
    let speed = match lowest_root(T::ZERO, T::from_f64(STEADY_SEARCH_MAX_RPM), |w| {
        pump_head_mca(&p.alpha, w, flow) - head
    }) {
        Root::Below => T::ZERO,
        Root::At(w) => w,
        Root::Above => return Err(BenchError::NoSteadyState),
    };
    // Steps 3 and 4: the load torque, and the reference that delivers it.
    let torque = scaled_load_torque_pct(&p.beta, load.torque_scale, speed, flow);
    let full = T::from_f64(MAX_TORQUE_PCT);
    let (torque_ref_pct, limited) = match lowest_root(T::ZERO, full, |u| {
        electromagnetic_torque_pct(&p.gamma, u) - torque
    }) {
        // At rest the target needs no speed: the least the drive can give.
        Root::Below => (T::ZERO, speed > T::ZERO || torque < p.gamma[5]),
        Root::At(u) => (u, false),
        Root::Above => (full, true),
    };
    Ok(SteadyInverse {
        torque_ref_pct,
        speed_rpm: speed,
        flow_lps: flow,
        pressure_mca: pressure,
        limited,
    })
}

/// [`steady_torque`] warm-started from a nearby solution `near` (the last control period's,
/// or any operating point: a speed ≤ 0 starts from the nominal 1 750 rpm): Newton's method on
/// the speed (step 2) and on the reference (step 4), a few iterations where the scan takes a
/// few hundred evaluations, so a loop can run it every period on the MCU. A torque beyond
/// what 0..=100 % gives is answered at the limit, flagged, as [`steady_torque`] does.
///
/// Where Newton cannot settle on the rising branch inside the ranges (a slope ≤ 0, a speed
/// beyond [`STEADY_SEARCH_MAX_RPM`], no convergence in [`NEWTON_ITERATIONS`]) it answers
/// [`BenchError::NoSteadyState`] rather than scan: the scan costs ten times a control period's
/// budget on the M4 (and its code would not fit the QEMU image's), and a loop has its PI for
/// such a period. Where the scan finds a steady state from a start a control period away,
/// Newton finds it too (tested over the range), to within its tolerance.
pub fn steady_torque_near<T: Real>(
    p: &BenchParams<T>,
    load: Load<T>,
    target: Target<T>,
    near: &SteadyInverse<T>,
) -> Result<SteadyInverse<T>, BenchError> {
    newton(p, load, target, near).ok_or(BenchError::NoSteadyState)
}

/// Step 1 and the head of step 2 (module docs): the flow and the pressure of `target` against
/// `load`, and the head the pump must give there, mca. The errors of [`steady_torque`].
fn operating_point<T: Real>(
    p: &BenchParams<T>,
    load: Load<T>,
    target: Target<T>,
) -> Result<(T, T, T), BenchError> {
    let positive = |x: T| x.is_finite() && x > T::ZERO;
    if !(positive(load.valve_k2) && positive(load.head_scale) && positive(load.torque_scale)) {
        return Err(BenchError::InvalidParameter(
            "the load's k2 and curve scales must be finite and > 0",
        ));
    }
    let c = p.static_head_c_mca;
    let (flow, pressure) = match target {
        Target::PressureMca(h) if h.is_finite() => (valve_flow_lps(load.valve_k2, c, h), h),
        Target::FlowLps(q) if q.is_finite() && q >= T::ZERO => {
            (q, valve_pressure_mca(load.valve_k2, c, q))
        }
        _ => {
            return Err(BenchError::InvalidParameter(
                "the target must be finite (a flow >= 0)",
            ))
        }
    };
    let head = (system_k(p.pipe_k1, load.valve_k2) * flow * flow - c) / load.head_scale;
    Ok((flow, pressure, head))
}

/// Most Newton iterations of [`steady_torque_near`] per unknown.
pub const NEWTON_ITERATIONS: usize = 12;

/// Where [`steady_torque_near`] starts without a solution to start from, rpm (the paper's
/// nominal speed).
const NEWTON_START_RPM: f64 = 1750.0;

fn newton<T: Real>(
    p: &BenchParams<T>,
    load: Load<T>,
    target: Target<T>,
    near: &SteadyInverse<T>,
) -> Option<SteadyInverse<T>> {
    let (flow, pressure, head) = operating_point(p, load, target).ok()?;
    if !(flow.is_finite() && flow > T::ZERO) {
        return None;
    }
    // Tolerances: 1e-5 of the value's scale, well under what a transmitter resolves (one
    // ADC code is 3.4 mm of water) and above f32's rounding of the sums.
    let tol = T::from_f64(1e-5);
    let max_rpm = T::from_f64(STEADY_SEARCH_MAX_RPM);
    let mut w =
        if near.speed_rpm.is_finite() && near.speed_rpm > T::ZERO && near.speed_rpm < max_rpm {
            near.speed_rpm
        } else {
            T::from_f64(NEWTON_START_RPM)
        };
    // Safeguarded Newton: a step that leaves the bracket the signs have shown bisects it.
    let (mut lo, mut hi) = (T::ZERO, max_rpm);
    let mut done = false;
    for _ in 0..NEWTON_ITERATIONS {
        let h = pump_head_partials(&p.alpha, w, flow);
        let g = h.value - head;
        if !g.is_finite() {
            return None;
        }
        if g.abs() <= tol * (T::ONE + head.abs()) {
            done = true;
            break;
        }
        if g < T::ZERO {
            lo = w;
        } else {
            hi = w;
        }
        let next = w - g / h.d_speed;
        w = if h.d_speed > T::ZERO && next > lo && next < hi {
            next
        } else {
            (lo + hi) / T::from_f64(2.0)
        };
    }
    if !done {
        return None;
    }
    let torque = scaled_load_torque_pct(&p.beta, load.torque_scale, w, flow);
    let full = T::from_f64(MAX_TORQUE_PCT);
    let gm = &p.gamma;
    let at = |u: T, limited: bool| SteadyInverse {
        torque_ref_pct: u,
        speed_rpm: w,
        flow_lps: flow,
        pressure_mca: pressure,
        limited,
    };
    // Te(u) rises over 0..=100 % (eq. 4 on the paper's bench): the ends answer a torque
    // beyond them, as the scan's `Root::Above` does.
    if electromagnetic_torque_pct(gm, full) < torque {
        return Some(at(full, true));
    }
    if !(electromagnetic_torque_pct(gm, T::ZERO) < torque) {
        // The least the drive gives already holds it (the scan's `Root::Below`).
        return Some(at(T::ZERO, w > T::ZERO || torque < gm[5]));
    }
    let two = T::from_f64(2.0);
    let mut u = if near.torque_ref_pct > T::ZERO && near.torque_ref_pct < full {
        near.torque_ref_pct
    } else {
        full / two
    };
    let (mut lo, mut hi) = (T::ZERO, full);
    for _ in 0..NEWTON_ITERATIONS {
        let g = electromagnetic_torque_pct(gm, u) - torque;
        if !g.is_finite() {
            return None;
        }
        if g.abs() <= tol * (T::ONE + torque.abs()) {
            return Some(at(u, false));
        }
        if g < T::ZERO {
            lo = u;
        } else {
            hi = u;
        }
        let slope = electromagnetic_torque_slope(gm, u);
        let next = u - g / slope;
        u = if slope > T::ZERO && next > lo && next < hi {
            next
        } else {
            (lo + hi) / two
        };
    }
    None
}

/// The bench linearised about a steady state: what a controller's gains are scheduled on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linearisation<T> {
    /// Time constant of the speed about the point, s: `1 / (K · dT_L/dω)`, with `dT_L/dω`
    /// the load torque's slope along the flow balance (eq. 6 through Q*(ω)) and K eq. (3)'s
    /// rpm/s per %. The one pole of the bench's model (the water column and the drive's lag
    /// are not in the paper's model).
    pub time_constant_s: T,
    /// Static gain of the outlet pressure to the torque reference, mca per %.
    pub pressure_gain_mca_per_pct: T,
    /// Static gain of the flow to the torque reference, l/s per %.
    pub flow_gain_lps_per_pct: T,
}

/// The bench `p` against `load`, linearised about the steady state `at` (from
/// [`steady_torque`]): `None` where there is no stable operating point to follow (no flow,
/// the pump at rest, or a load torque that does not rise with speed).
pub fn linearise<T: Real>(
    p: &BenchParams<T>,
    load: Load<T>,
    at: &SteadyInverse<T>,
) -> Option<Linearisation<T>> {
    let (w, q) = (at.speed_rpm, at.flow_lps);
    if !(w > T::ZERO && q > T::ZERO) {
        return None;
    }
    let head = pump_head_partials(&p.alpha, w, q);
    let dq_dw = flow_root_sensitivities(&head, load.head_scale, p.pipe_k1, load.valve_k2, q)[0];
    let torque = load_torque_partials(&p.beta, w, q);
    let dtl_dw = load.torque_scale * (torque.d_speed + torque.d_flow * dq_dw);
    if !(dtl_dw > T::ZERO) {
        return None;
    }
    let u = at.torque_ref_pct;
    let dte_du = electromagnetic_torque_slope(&p.gamma, u);
    let dw_du = dte_du / dtl_dw;
    let flow_gain = dq_dw * dw_du;
    Some(Linearisation {
        time_constant_s: T::ONE / (p.accel_rpm_per_s_per_pct() * dtl_dw),
        pressure_gain_mca_per_pct: T::from_f64(2.0) * load.valve_k2 * load.valve_k2 * q * flow_gain,
        flow_gain_lps_per_pct: flow_gain,
    })
}

/// Where `f` first reaches 0 from below on `[lo, hi]`.
enum Root<T> {
    /// `f(lo) ≥ 0`: already there at `lo`.
    Below,
    /// Crosses at this point (bisection to the last representable bracket).
    At(T),
    /// Still below 0 at `hi`.
    Above,
}

/// Scans `[lo, hi]` in [`STEADY_SCAN_STEP_RPM`]-wide steps scaled to the interval (240 steps)
/// for the first sign change of `f` from negative, then bisects it.
fn lowest_root<T: Real>(lo: T, hi: T, f: impl Fn(T) -> T) -> Root<T> {
    if f(lo) >= T::ZERO {
        return Root::Below;
    }
    let steps = STEADY_SEARCH_MAX_RPM / STEADY_SCAN_STEP_RPM;
    let step = (hi - lo) / T::from_f64(steps);
    let (mut a, mut b) = (lo, lo);
    let mut found = false;
    for k in 1..=steps as usize {
        a = b;
        b = lo + step * T::from_f64(k as f64);
        let v = f(b);
        if !v.is_finite() {
            return Root::Above;
        }
        if v >= T::ZERO {
            found = true;
            break;
        }
    }
    if !found {
        return Root::Above;
    }
    let two = T::from_f64(2.0);
    for _ in 0..200 {
        let mid = (a + b) / two;
        if mid <= a || mid >= b {
            break;
        }
        if f(mid) >= T::ZERO {
            b = mid;
        } else {
            a = mid;
        }
    }
    Root::At(b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::WhiteBox;

    fn paper_load() -> Load<f64> {
        Load {
            valve_k2: BenchParams::<f64>::PAPER.valve_k2,
            head_scale: 1.0,
            torque_scale: 1.0,
        }
    }

    /// Forward then backward: the white-box's steady state for a torque, then the torque for
    /// its pressure and for its flow, on the paper's bench and on benches with other curves.
    #[test]
    fn inverts_the_white_box_steady_state() {
        for (s_h, s_t) in [(1.0, 1.0), (0.95, 1.05), (1.08, 0.92)] {
            let mut p = BenchParams::<f64>::PAPER;
            p.alpha.iter_mut().for_each(|a| *a *= s_h);
            p.beta.iter_mut().for_each(|b| *b *= s_t);
            let bench = WhiteBox::new(p).unwrap();
            let load = Load {
                head_scale: s_h,
                torque_scale: s_t,
                ..paper_load()
            };
            let paper = BenchParams::<f64>::PAPER;
            for u in (10..=85).step_by(5).map(f64::from) {
                let s = bench.steady_state(u).unwrap();
                let sig = bench.signals(&s);
                for target in [
                    Target::PressureMca(sig.pressure_mca),
                    Target::FlowLps(s.flow_lps),
                ] {
                    let inv = steady_torque(&paper, load, target).unwrap();
                    assert!(!inv.limited, "{u} %: {inv:?}");
                    assert!(
                        (inv.torque_ref_pct - u).abs() < 1e-6,
                        "{u} %, {target:?}: {inv:?}"
                    );
                    assert!((inv.speed_rpm - s.speed_rpm).abs() < 1e-6, "{u}: {inv:?}");
                    assert!((inv.flow_lps - s.flow_lps).abs() < 1e-9, "{u}: {inv:?}");
                }
            }
        }
    }

    /// The same in f32, as the MCU would run it: within a few ulps of the torque.
    #[test]
    fn f32_follows_f64() {
        let p32 = BenchParams::<f32>::PAPER;
        let p64 = BenchParams::<f64>::PAPER;
        let l32 = Load {
            valve_k2: p32.valve_k2,
            head_scale: 1.0f32,
            torque_scale: 1.0,
        };
        for h in [0.5, 1.0, 2.0, 3.0, 4.0, 5.0] {
            let a = steady_torque(&p64, paper_load(), Target::PressureMca(h)).unwrap();
            let b = steady_torque(&p32, l32, Target::PressureMca(h as f32)).unwrap();
            let d = (f64::from(b.torque_ref_pct) - a.torque_ref_pct).abs();
            assert!(d < 1e-4 * a.torque_ref_pct.max(1.0), "{h} mca: {a:?} {b:?}");
        }
    }

    /// The static gains against finite differences of the forward steady state, the time
    /// constant against a small step simulated with the white-box (RK4, 1 ms): the time to
    /// 63 % of the speed's change.
    #[test]
    fn linearisation_matches_the_white_box() {
        let p = BenchParams::<f64>::PAPER;
        let bench = WhiteBox::new(p).unwrap();
        let mut taus = vec![];
        for u in [15.0, 30.0, 45.0, 60.0, 75.0] {
            let s = bench.steady_state(u).unwrap();
            let inv = steady_torque(&p, paper_load(), Target::FlowLps(s.flow_lps)).unwrap();
            let lin = linearise(&p, paper_load(), &inv).unwrap();
            let (lo, hi) = (
                bench.steady_state(u - 0.01).unwrap(),
                bench.steady_state(u + 0.01).unwrap(),
            );
            let dq = (hi.flow_lps - lo.flow_lps) / 0.02;
            let dp = (bench.signals(&hi).pressure_mca - bench.signals(&lo).pressure_mca) / 0.02;
            assert!(
                (lin.flow_gain_lps_per_pct / dq - 1.0).abs() < 1e-4,
                "{u}: {lin:?} {dq}"
            );
            assert!(
                (lin.pressure_gain_mca_per_pct / dp - 1.0).abs() < 1e-4,
                "{u}: {dp}"
            );
            // A 0.1 % step: the speed's first-order response reaches 63 % after τ.
            let end = bench.steady_state(u + 0.1).unwrap();
            let mut st = s;
            let mark = s.speed_rpm + (1.0 - (-1.0f64).exp()) * (end.speed_rpm - s.speed_rpm);
            let mut t = 0.0;
            while st.speed_rpm < mark {
                bench
                    .step(&mut st, u + 0.1, 1e-3, crate::Scheme::Rk4)
                    .unwrap();
                t += 1e-3;
            }
            let tau = lin.time_constant_s;
            eprintln!(
                "u {u} %: {:.0} rpm, {:.2} l/s, {:.3} mca; τ {tau:.3} s (step {t:.3} s), \
                 gain {:.4} mca/% {:.4} l/s/%",
                s.speed_rpm,
                s.flow_lps,
                bench.signals(&s).pressure_mca,
                lin.pressure_gain_mca_per_pct,
                lin.flow_gain_lps_per_pct
            );
            assert!(
                (t - tau).abs() <= 0.02 * tau + 1e-3,
                "{u} %: step {t} s, τ {tau} s"
            );
            taus.push(tau);
        }
        // The bench slows down toward low speeds: the scheduling the issue asks for is real.
        assert!(taus[0] > 2.0 * taus[4], "{taus:?}");
    }

    #[test]
    fn limits_and_bad_input() {
        let p = BenchParams::<f64>::PAPER;
        // Beyond the pump at full torque: the nearest limit, flagged.
        let high = steady_torque(&p, paper_load(), Target::PressureMca(9.0)).unwrap();
        assert_eq!(
            (high.torque_ref_pct, high.limited),
            (100.0, true),
            "{high:?}"
        );
        // At the level at rest (no flow): below what 0 % holds (Te(0) = 2.24 % turns the
        // pump faster than the few rpm this needs), so 0 %, flagged.
        let low = steady_torque(&p, paper_load(), Target::PressureMca(-p.static_head_c_mca));
        let low = low.unwrap();
        assert_eq!(
            (low.torque_ref_pct, low.flow_lps, low.limited),
            (0.0, 0.0, true)
        );
        assert!(low.speed_rpm < 1.0, "{low:?}");
        let at_zero = WhiteBox::new(p).unwrap().steady_state(0.0).unwrap();
        assert!(at_zero.speed_rpm > low.speed_rpm, "{at_zero:?}");
        for bad in [
            Target::PressureMca(f64::NAN),
            Target::PressureMca(f64::INFINITY),
            Target::FlowLps(-1.0),
            Target::FlowLps(f64::NAN),
        ] {
            assert!(
                matches!(
                    steady_torque(&p, paper_load(), bad),
                    Err(BenchError::InvalidParameter(_))
                ),
                "{bad:?}"
            );
        }
        for load in [
            Load {
                valve_k2: 0.0,
                ..paper_load()
            },
            Load {
                head_scale: f64::NAN,
                ..paper_load()
            },
            Load {
                torque_scale: -1.0,
                ..paper_load()
            },
        ] {
            assert!(
                steady_torque(&p, load, Target::PressureMca(2.0)).is_err(),
                "{load:?}"
            );
        }
    }

    /// Wherever the scan finds a steady state with flow, Newton finds the same from a start a
    /// control period's change away, from a far one and from rest (the nominal speed), on
    /// the paper's bench and on loads ±30 % and curves ±5 % off it.
    #[test]
    fn newton_finds_what_the_scan_finds_over_the_range() {
        let p = BenchParams::<f32>::PAPER;
        let rest = SteadyInverse {
            torque_ref_pct: 0.0,
            speed_rpm: 0.0,
            flow_lps: 0.0,
            pressure_mca: 0.0,
            limited: false,
        };
        let mut checked = 0;
        for (k2f, s_h, s_t) in [
            (1.0f32, 1.0f32, 1.0f32),
            (0.7, 1.05, 0.95),
            (1.3, 0.95, 1.05),
            (0.5, 1.0, 1.0),
            (2.0, 1.0, 1.0),
        ] {
            let load = Load {
                valve_k2: p.valve_k2 * k2f,
                head_scale: s_h,
                torque_scale: s_t,
            };
            let targets = (1..=28)
                .map(|k| Target::PressureMca(0.25 * k as f32))
                .chain((1..=30).map(|k| Target::FlowLps(k as f32)));
            for b in targets {
                let Ok(scan) = steady_torque(&p, load, b) else {
                    continue;
                };
                if !(scan.speed_rpm > 0.0 && scan.flow_lps > 0.0) {
                    continue;
                }
                let nudge = |t: Target<f32>, f: f32| match t {
                    Target::PressureMca(h) => Target::PressureMca(h * f),
                    Target::FlowLps(q) => Target::FlowLps(q * f),
                };
                let near = steady_torque(&p, load, nudge(b, 1.02)).unwrap();
                let far = steady_torque(&p, load, nudge(b, 0.4)).unwrap();
                for start in [near, far, rest] {
                    let fast = steady_torque_near(&p, load, b, &start)
                        .unwrap_or_else(|e| panic!("{b:?} valve x{k2f} from {start:?}: {e}"));
                    assert_eq!(fast.limited, scan.limited, "{b:?} valve x{k2f}");
                    let du = (fast.torque_ref_pct - scan.torque_ref_pct).abs();
                    let dw = (fast.speed_rpm - scan.speed_rpm).abs();
                    assert!(
                        du < 2e-3 && dw < 0.05,
                        "{b:?} valve x{k2f}: {fast:?} vs {scan:?}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 300, "{checked} cases");
        // No flow to hold, a NaN: no answer (the loop's PI alone), never a wrong one.
        let load = Load {
            valve_k2: p.valve_k2,
            head_scale: 1.0,
            torque_scale: 1.0,
        };
        assert!(steady_torque_near(&p, load, Target::FlowLps(0.0), &rest).is_err());
        assert!(steady_torque_near(&p, load, Target::FlowLps(f32::NAN), &rest).is_err());
        assert!(steady_torque_near(&p, load, Target::PressureMca(f32::INFINITY), &rest).is_err());
    }
}
