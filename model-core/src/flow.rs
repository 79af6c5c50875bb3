//! The algebraic loop: flow for a given speed.
//!
//! Pump head equals pipe loss plus outlet pressure, and the valve fixes the outlet pressure
//! from the flow (eqs. 5, 7, 8). Eliminating `Hs = k2² Q² − c` leaves one cubic in Q:
//!
//! ```text
//! g(Q) = F_H(ω, Q) − (k1 + k2²) Q² + c = 0
//! ```
//!
//! The flow is the **largest non-negative root** of `g`, where the pump curve crosses the
//! system curve from above (the stable operating point), and 0 when `g(Q) ≤ 0` for all
//! `Q ≥ 0` (the pump cannot lift the static head). Since α1 < 0, `g → −∞` as Q grows, so that
//! root is bounded. With the paper's coefficients, `g` is strictly decreasing on `Q ≥ 0` for
//! every speed below ≈ 3600 rpm, so the root is unique there.
//!
//! Method, usual case: when `c2 ≤ 0`, `c1 ≤ 0` and `g(0) = c0 > 0`, `g` is falling and
//! concave on `Q > 0` (`g' < 0`, `g'' < 0`), so it has exactly one positive root and Newton's
//! method converges to it from any start `Q ≥ 0`: the first step lands on or above the root
//! (a concave function lies below its tangents), every later one moves down towards it, and
//! each iterate is an upper bound, so no bracket is kept. With the paper's coefficients this
//! holds at every speed below ≈ 3600 rpm. Warm-started from the last flow (the RK4 stages
//! start from the previous stage's flow), one update is usually enough. Each update is one
//! cubic, its slope and one division, and one convergence test: for a cubic the error of the
//! new iterate is exactly `e² (g''(q)/2 − c3 e) / g'(q)`, `e` the error of `q`, which the test
//! bounds with the step for `e` and accepts when it is below one `ε` of the flow (so the
//! result is as close as the evaluation of `g` in `T` allows, a few ulps). No square root, no
//! `max`/`min` call (`f32::max` is a library call on a Cortex-M4F).
//!
//! Otherwise (a non-monotone cubic, no flow, non-finite coefficients, or a fast-path iterate
//! that is not finite and positive) the general method runs: the branch on which `g` falls for
//! good starts at `max(0, q₊)`, `q₊` the larger critical point of the cubic (one square root).
//! Newton's method, warm-started from the given flow, runs inside a bracket that every
//! evaluation tightens; a step that would leave the bracket is replaced by bisection (or by
//! doubling while no upper bound is known). It stops when the step is within a few ulps of the
//! flow or `|g|` is within its own rounding error, and after [`MAX_FLOW_ITERATIONS`] at most.
//!
//! Either way the solver never panics and returns a finite flow `≥ 0`, never NaN, for any
//! coefficients and any warm start (NaN and infinities included; non-finite coefficients give
//! 0).

use crate::equations::CubicInFlow;
use crate::scalar::Real;

/// Upper bound on the iterations of one flow solve (each: one cubic and its slope).
pub const MAX_FLOW_ITERATIONS: u32 = 80;

/// Result of one flow solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowSolution<T> {
    /// Flow in l/s, ≥ 0, finite.
    pub flow_lps: T,
    /// Iterations used (0 when there is no flow).
    pub iterations: u32,
    /// `false` only if the iteration bound was hit; the flow is then the best bracketed
    /// estimate, still finite.
    pub converged: bool,
}

/// The flow-balance cubic `g(Q) = F_H(ω, Q) − (k1 + k2²) Q² + c` at one speed: the paper's
/// pump curve, [`crate::equations::flow_balance`] with head scale 1.
#[inline]
pub fn balance_cubic<T: Real>(
    alpha: &[T; 10],
    system_k_mca_per_lps2: T,
    static_head_c_mca: T,
    speed_rpm: T,
) -> CubicInFlow<T> {
    crate::equations::flow_balance(
        alpha,
        T::ONE,
        system_k_mca_per_lps2,
        static_head_c_mca,
        speed_rpm,
    )
}

/// Solves `g(Q) = 0` for the largest non-negative root (see the module docs).
///
/// `g.c3` must be negative (checked by [`crate::BenchParams::validate`]; otherwise the flow is
/// 0); `warm_start_lps` is any guess (the last flow, l/s); a non-finite or non-positive guess
/// is ignored.
#[inline]
pub fn solve_flow<T: Real>(g: &CubicInFlow<T>, warm_start_lps: T) -> FlowSolution<T> {
    match newton_on_falling_concave(g, warm_start_lps) {
        Some(s) => s,
        None => solve_flow_general(g, warm_start_lps),
    }
}

/// The usual case (module docs): `c3 < 0`, `c2 ≤ 0`, `c1 ≤ 0`, `c0 > 0`. `None` when the
/// cubic is not of that form (NaN fails every comparison) or an iterate is not finite and
/// positive, or the iteration bound is hit: the general method then decides.
#[inline]
fn newton_on_falling_concave<T: Real>(
    g: &CubicInFlow<T>,
    warm_start_lps: T,
) -> Option<FlowSolution<T>> {
    let CubicInFlow { c3, c2, c1, c0 } = *g;
    if !(c3 < T::ZERO && c2 <= T::ZERO && c1 <= T::ZERO && c0 > T::ZERO) {
        return None;
    }
    // Any finite start Q ≥ 0 converges; 0 when the guess is not positive (or NaN). A zero
    // slope at 0 (c1 = 0), an infinite guess or one so large that g overflows makes an
    // iterate infinite or NaN, which hands over to the general method.
    let mut q = if warm_start_lps > T::ZERO {
        warm_start_lps
    } else {
        T::ZERO
    };
    let three_c3 = T::from_f64(3.0) * c3;
    let mut iterations = 0;
    while iterations < MAX_FLOW_ITERATIONS {
        iterations += 1;
        let half_curvature = three_c3 * q + c2; // g''(q)/2 ≤ 0
        let slope = (half_curvature + c2) * q + c1; // g'(q) < 0 for q > 0: no cancellation
        let step = g.eval(q) / slope;
        let next = q - step;
        if !(next > T::ZERO) {
            // Only by rounding with a root at ≈ 0, or from a NaN.
            return None;
        }
        // The new iterate's error is e² (g''(q)/2 − c3 e) / g'(q), e = q − root ≈ step:
        // accept when its bound, with the step for e, is within ε of the flow. Both sides
        // are ≤ 0 (c3, g'' and g' are negative), NaN fails.
        let s = step.abs();
        if (c3 * s + half_curvature) * s * s >= T::EPSILON * slope * next {
            return next.is_finite().then_some(FlowSolution {
                flow_lps: next,
                iterations,
                converged: true,
            });
        }
        q = next;
    }
    None
}

/// The general method (module docs): any cubic, any warm start. Out of line: the usual case
/// never comes here, and keeping it apart keeps the fast path small.
#[inline(never)]
fn solve_flow_general<T: Real>(g: &CubicInFlow<T>, warm_start_lps: T) -> FlowSolution<T> {
    let none = FlowSolution {
        flow_lps: T::ZERO,
        iterations: 0,
        converged: true,
    };
    if !(g.c3 < T::ZERO)
        || !g.c3.is_finite()
        || !g.c2.is_finite()
        || !g.c1.is_finite()
        || !g.c0.is_finite()
    {
        return none;
    }
    let (zero, one) = (T::ZERO, T::ONE);
    // Every root lies below Cauchy's bound 1 + max(|c2|, |c1|, |c0|) / |c3| (above it the
    // cubic term outweighs the others, so g < 0): an upper end for the bracket, which also
    // keeps a huge warm start from costing many iterations. `None` if it overflows.
    let largest = |a: T, b: T| if a > b { a } else { b };
    let cauchy = one + largest(largest(g.c2.abs(), g.c1.abs()), g.c0.abs()) / (-g.c3);
    let cap = if cauchy.is_finite() {
        Some(cauchy)
    } else {
        None
    };
    // Start of the branch on which g decreases for good, and the bracket on it.
    let (mut lo, mut hi) = if g.c2 <= zero && g.c1 <= zero {
        // g'(Q) = 3 c3 Q² + 2 c2 Q + c1 < 0 for all Q > 0.
        (zero, cap)
    } else {
        let three = T::from_f64(3.0);
        let disc = g.c2 * g.c2 - three * g.c3 * g.c1;
        if disc <= zero {
            (zero, cap)
        } else {
            let root_disc = disc.sqrt();
            let denom = three * (-g.c3); // > 0
            let q_plus = (g.c2 + root_disc) / denom; // larger critical point (local max)
            let q_minus = (g.c2 - root_disc) / denom; // smaller one (local min)
            let start = if q_plus > zero { q_plus } else { zero };
            if g.eval(start) > zero {
                (start, cap)
            } else if g.c0 > zero && q_minus > zero {
                // g falls from g(0) > 0 to its local min: the only root is in (0, q₋).
                (zero, Some(q_minus))
            } else {
                return none;
            }
        }
    };
    if !(g.eval(lo) > zero) {
        // Only reachable with lo = 0: g(0) ≤ 0 on a decreasing branch, so no flow.
        return none;
    }

    // The larger of x ≥ 0 (or NaN) and 1.
    let at_least_one = |x: T| largest(x, one);
    let tol = T::from_f64(4.0) * T::EPSILON;
    let two = T::from_f64(2.0);
    let mut q = if warm_start_lps.is_finite() && warm_start_lps > lo {
        match hi {
            Some(h) if warm_start_lps >= h => (lo + h) / two,
            _ => warm_start_lps,
        }
    } else {
        match hi {
            Some(h) => (lo + h) / two,
            None => at_least_one(lo),
        }
    };
    let mut iterations = 0;
    while iterations < MAX_FLOW_ITERATIONS {
        iterations += 1;
        let value = g.eval(q);
        let magnitude = g.magnitude(q);
        if value.abs() <= T::from_f64(8.0) * T::EPSILON * magnitude && magnitude.is_finite() {
            // As good as the evaluation of g allows (an overflowing g, at a huge warm start,
            // is not: ∞ ≤ ∞).
            return FlowSolution {
                flow_lps: q,
                iterations,
                converged: true,
            };
        }
        if value > zero {
            lo = q;
        } else {
            hi = Some(q);
        }
        let slope = g.slope(q);
        let newton = q - value / slope;
        // Without an upper bound, grow at most geometrically (a slope near zero, e.g. at the
        // local maximum that starts the branch, would otherwise throw Newton far out).
        let inside = newton.is_finite()
            && newton > lo
            && match hi {
                Some(h) => newton < h,
                None => newton <= two * at_least_one(q),
            };
        let next = if inside {
            newton
        } else {
            match hi {
                Some(h) => (lo + h) / two,
                None => two * at_least_one(lo),
            }
        };
        if (next - q).abs() <= tol * at_least_one(next.abs()) {
            return FlowSolution {
                flow_lps: if next > zero { next } else { zero },
                iterations,
                converged: true,
            };
        }
        q = next;
    }
    FlowSolution {
        flow_lps: if q > zero { q } else { zero },
        iterations,
        converged: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::equations::system_k;

    /// −s (Q − r1)(Q − r2)(Q − r3) expanded.
    fn from_roots(s: f64, r: [f64; 3]) -> CubicInFlow<f64> {
        CubicInFlow {
            c3: -s,
            c2: s * (r[0] + r[1] + r[2]),
            c1: -s * (r[0] * r[1] + r[0] * r[2] + r[1] * r[2]),
            c0: s * r[0] * r[1] * r[2],
        }
    }

    const WARM: [f64; 7] = [0.0, 1.0, 3.0, 7.5, 100.0, -5.0, f64::NAN];

    #[test]
    fn largest_of_three_positive_roots() {
        let g = from_roots(1e-3, [2.0, 5.0, 9.0]);
        for w in WARM {
            let s = solve_flow(&g, w);
            assert!(
                (s.flow_lps - 9.0).abs() < 1e-12 && s.converged,
                "warm {w}: {s:?}"
            );
        }
    }

    #[test]
    fn root_pair_above_a_negative_start() {
        // g(0) < 0 but the pump curve rises above the system curve between 2 and 5 l/s.
        let g = from_roots(1.0, [2.0, 5.0, -1.0]);
        assert!(g.c0 < 0.0);
        for w in WARM {
            assert!((solve_flow(&g, w).flow_lps - 5.0).abs() < 1e-12, "warm {w}");
        }
    }

    #[test]
    fn single_root_with_a_hump_below_zero() {
        // −(Q − 1)((Q − 5)² + 0.5): one real root at 1, local max below zero.
        let g = CubicInFlow {
            c3: -1.0,
            c2: 11.0,
            c1: -35.5,
            c0: 25.5,
        };
        assert!(g.eval(1.0).abs() < 1e-12);
        for w in WARM {
            assert!((solve_flow(&g, w).flow_lps - 1.0).abs() < 1e-12, "warm {w}");
        }
    }

    #[test]
    fn no_positive_root_gives_zero() {
        let g = from_roots(2.0, [-1.0, -2.0, -3.0]);
        for w in WARM {
            let s = solve_flow(&g, w);
            assert_eq!((s.flow_lps, s.iterations), (0.0, 0));
        }
        // Non-finite or non-physical coefficients: zero, no panic.
        for bad in [f64::NAN, f64::INFINITY] {
            let mut g = from_roots(1.0, [1.0, 2.0, 3.0]);
            g.c1 = bad;
            assert_eq!(solve_flow(&g, 1.0).flow_lps, 0.0);
        }
        let mut g = from_roots(1.0, [1.0, 2.0, 3.0]);
        g.c3 = 0.0;
        assert_eq!(solve_flow(&g, 1.0).flow_lps, 0.0);
    }

    #[test]
    fn paper_balance_warm_started_converges_in_few_iterations() {
        let p = crate::BenchParams::<f64>::paper();
        let k = crate::equations::system_k(p.pipe_k1, p.valve_k2);
        let mut q = 0.0;
        let mut worst = 0;
        for i in 0..=2000 {
            let w = i as f64;
            let g = balance_cubic(&p.alpha, k, p.static_head_c_mca, w);
            let s = solve_flow(&g, q);
            assert!(s.converged && s.flow_lps >= 0.0);
            if s.flow_lps > 0.0 {
                assert!(g.eval(s.flow_lps).abs() < 1e-12 * g.magnitude(s.flow_lps));
            }
            if q > 0.0 {
                worst = worst.max(s.iterations);
            }
            q = s.flow_lps;
        }
        // 1 rpm apart, the warm start is close: Newton needs three or four updates in f64.
        assert!(worst <= 4, "worst {worst} iterations");
    }

    /// The paper's flow-balance cubic at `speed_rpm`, in `T`.
    fn paper_balance<T: Real>(speed_rpm: f64) -> CubicInFlow<T> {
        let p = crate::BenchParams::<T>::paper();
        let k = crate::equations::system_k(p.pipe_k1, p.valve_k2);
        balance_cubic(&p.alpha, k, p.static_head_c_mca, T::from_f64(speed_rpm))
    }

    /// The exact largest root of `g` (its coefficients taken exactly into f64), in f64.
    fn exact_root<T: Real>(g: &CubicInFlow<T>) -> f64 {
        let g64 = CubicInFlow {
            c3: g.c3.to_f64(),
            c2: g.c2.to_f64(),
            c1: g.c1.to_f64(),
            c0: g.c0.to_f64(),
        };
        solve_flow_general(&g64, 0.0).flow_lps
    }

    fn fast_path_agrees_with_the_general_method<T: Real>() {
        let odd = [0.0, -1.0, f64::NAN, f64::INFINITY, 1e30, 100.0];
        for i in 0..=500 {
            let w = 7.0 * i as f64;
            let g = paper_balance::<T>(w);
            let q_general = solve_flow_general(&g, T::ZERO).flow_lps;
            let general = q_general.to_f64();
            // The general method may stop where |g| ≤ 8 ε magnitude: that far from the root.
            let loose = 8.0 * (g.magnitude(q_general) / g.slope(q_general)).to_f64().abs();
            let tol = T::EPSILON.to_f64() * (4.0 * general.max(1.0) + loose);
            let near = [0.9, 0.999, 1.001, 1.1].map(|f| general * f);
            for warm in near.iter().chain(odd.iter()) {
                let s = solve_flow(&g, T::from_f64(*warm));
                let q = s.flow_lps.to_f64();
                assert!(
                    q.is_finite() && q >= 0.0 && s.converged,
                    "w={w} warm={warm}: {s:?}"
                );
                assert!(
                    (q - general).abs() <= tol,
                    "w={w} warm={warm}: {q} vs {general}"
                );
            }
            // Every speed here with flow is the usual case (only at rest, g(0) = α10 + c < 0,
            // is there none).
            let fast = newton_on_falling_concave(&g, T::from_f64(near[2]));
            assert_eq!(fast.is_some(), general > 0.0, "w={w}");
        }
    }

    #[test]
    fn fast_path_agrees_with_the_general_method_f32_and_f64() {
        fast_path_agrees_with_the_general_method::<f32>();
        fast_path_agrees_with_the_general_method::<f64>();
    }

    #[test]
    fn fast_path_in_f32_is_within_two_eps_of_the_exact_root() {
        // The root of the same (rounded) cubic, so this is the solver's own error: the
        // convergence test's ε plus the rounding of g near its root.
        fn check<T: Real>() -> f64 {
            let mut worst = 0.0f64;
            for i in 1..=3590 {
                let w = i as f64;
                let g = paper_balance::<T>(w);
                let warm = T::from_f64(exact_root(&paper_balance::<f64>(w - 0.5)));
                let q = solve_flow(&g, warm).flow_lps.to_f64();
                let r = exact_root(&g);
                worst = worst.max((q / r - 1.0).abs() / T::EPSILON.to_f64());
            }
            worst
        }
        // f32 only: in f64 the reference would have the same precision as what it checks.
        let worst = check::<f32>();
        eprintln!("fast path: worst error {worst:.2} ε (f32)");
        assert!(worst <= 2.0, "{worst} ε");
    }

    #[test]
    fn warm_starts_a_stage_apart_need_one_or_two_updates() {
        // At 1 ms RK4 steps the stages are a fraction of an rpm apart (≤ 0.53 rpm in the
        // firmware's timing run): one update in f32, two from 1 rpm on.
        for (d, most) in [(0.25, 1), (2.0, 2)] {
            for i in 0..=100 {
                let w = 600.0 + 10.0 * i as f64;
                let g = paper_balance::<f32>(w);
                let warm = solve_flow(&paper_balance::<f32>(w - d), 0.0).flow_lps;
                let s = solve_flow(&g, warm);
                assert!(s.iterations <= most, "w={w} d={d}: {s:?}");
            }
        }
    }

    #[test]
    fn non_finite_coefficients_of_the_usual_form_give_zero() {
        let good = CubicInFlow {
            c3: -1e-3,
            c2: -0.04,
            c1: -0.06,
            c0: 10.0,
        };
        let inf = f64::INFINITY;
        for (i, bad) in [-inf, -inf, -inf, inf].into_iter().enumerate() {
            let mut g = good;
            match i {
                0 => g.c3 = bad,
                1 => g.c2 = bad,
                2 => g.c1 = bad,
                _ => g.c0 = bad,
            }
            for w in WARM.iter().chain([inf, 1e300].iter()) {
                let s = solve_flow(&g, *w);
                assert_eq!(s.flow_lps, 0.0, "coefficient {i}, warm {w}: {s:?}");
            }
        }
        // A zero slope at Q = 0 (c1 = c2 = 0) with no warm start: handed over, still right.
        let g = CubicInFlow {
            c3: -1.0,
            c2: 0.0,
            c1: 0.0,
            c0: 8.0,
        };
        for w in WARM {
            assert!((solve_flow(&g, w).flow_lps - 2.0).abs() < 1e-12, "warm {w}");
        }
    }

    #[test]
    fn f32_flow_close_to_f64() {
        let p64 = crate::BenchParams::<f64>::paper();
        let p32 = crate::BenchParams::<f32>::paper();
        for i in 0..=40 {
            let w = 50.0 * i as f64;
            let (k64, k32) = (system_k(0.025, 0.1082), system_k(0.025f32, 0.1082));
            let g64 = balance_cubic(&p64.alpha, k64, 0.252, w);
            let g32 = balance_cubic(&p32.alpha, k32, 0.252, w as f32);
            let (a, b) = (
                solve_flow(&g64, 0.0).flow_lps,
                solve_flow(&g32, 0.0).flow_lps,
            );
            assert!(
                (a - b as f64).abs() <= 2e-6 * a.max(1.0),
                "w={w}: {a} vs {b}"
            );
        }
    }
}
