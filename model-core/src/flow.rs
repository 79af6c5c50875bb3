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
//! Method: the branch on which `g` falls for good starts at `max(0, q₊)`, `q₊` the larger
//! critical point of the cubic (none to compute when `c2 ≤ 0` and `c1 ≤ 0`: the usual case,
//! which costs no square root). Newton's method, warm-started from the last flow, runs
//! inside a bracket that every evaluation tightens; a step that would leave the bracket is
//! replaced by bisection (or by doubling while no upper bound is known). It stops when the
//! step is within a few ulps of the flow or `|g|` is within its own rounding error, and
//! after [`MAX_FLOW_ITERATIONS`] at most. It never returns NaN and never panics for finite
//! coefficients.

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

/// The flow-balance cubic `g(Q) = F_H(ω, Q) − (k1 + k2²) Q² + c` at one speed.
#[inline]
pub fn balance_cubic<T: Real>(
    alpha: &[T; 10],
    system_k_mca_per_lps2: T,
    static_head_c_mca: T,
    speed_rpm: T,
) -> CubicInFlow<T> {
    let mut g = CubicInFlow::from_poly(alpha, speed_rpm);
    g.c2 = g.c2 - system_k_mca_per_lps2;
    g.c0 += static_head_c_mca;
    g
}

/// Solves `g(Q) = 0` for the largest non-negative root (see the module docs).
///
/// `g.c3` must be negative (checked by [`crate::BenchParams::validate`]); `warm_start_lps` is
/// any guess (the last flow); a non-finite or negative guess is ignored.
pub fn solve_flow<T: Real>(g: &CubicInFlow<T>, warm_start_lps: T) -> FlowSolution<T> {
    let none = FlowSolution {
        flow_lps: T::ZERO,
        iterations: 0,
        converged: true,
    };
    if !(g.c3 < T::ZERO) || !g.c2.is_finite() || !g.c1.is_finite() || !g.c0.is_finite() {
        return none;
    }
    // Start of the branch on which g decreases for good, and the bracket on it.
    let (mut lo, mut hi) = if g.c2 <= T::ZERO && g.c1 <= T::ZERO {
        // g'(Q) = 3 c3 Q² + 2 c2 Q + c1 < 0 for all Q > 0.
        (T::ZERO, None)
    } else {
        let three = T::from_f64(3.0);
        let disc = g.c2 * g.c2 - three * g.c3 * g.c1;
        if disc <= T::ZERO {
            (T::ZERO, None)
        } else {
            let root_disc = disc.sqrt();
            let denom = three * (-g.c3); // > 0
            let q_plus = (g.c2 + root_disc) / denom; // larger critical point (local max)
            let q_minus = (g.c2 - root_disc) / denom; // smaller one (local min)
            let start = q_plus.max(T::ZERO);
            if g.eval(start) > T::ZERO {
                (start, None)
            } else if g.c0 > T::ZERO && q_minus > T::ZERO {
                // g falls from g(0) > 0 to its local min: the only root is in (0, q₋).
                (T::ZERO, Some(q_minus))
            } else {
                return none;
            }
        }
    };
    if g.eval(lo) <= T::ZERO {
        // Only reachable with lo = 0: g(0) ≤ 0 on a decreasing branch, so no flow.
        return none;
    }

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
            None => lo.max(T::ONE),
        }
    };
    let mut iterations = 0;
    while iterations < MAX_FLOW_ITERATIONS {
        iterations += 1;
        let value = g.eval(q);
        if value.abs() <= T::from_f64(8.0) * T::EPSILON * g.magnitude(q) {
            // As good as the evaluation of g allows.
            return FlowSolution {
                flow_lps: q,
                iterations,
                converged: true,
            };
        }
        if value > T::ZERO {
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
                None => newton <= two * q.max(T::ONE),
            };
        let next = if inside {
            newton
        } else {
            match hi {
                Some(h) => (lo + h) / two,
                None => two * lo.max(T::ONE),
            }
        };
        let scale = next.abs().max(T::ONE);
        if (next - q).abs() <= tol * scale {
            return FlowSolution {
                flow_lps: next.max(T::ZERO),
                iterations,
                converged: true,
            };
        }
        q = next;
    }
    FlowSolution {
        flow_lps: q.max(T::ZERO),
        iterations,
        converged: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let k = p.pipe_k1 + p.valve_k2 * p.valve_k2;
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
        // 1 rpm apart, the warm start is close: Newton needs a handful of iterations.
        assert!(worst <= 5, "worst {worst} iterations");
    }

    #[test]
    fn f32_flow_close_to_f64() {
        let p64 = crate::BenchParams::<f64>::paper();
        let p32 = crate::BenchParams::<f32>::paper();
        for i in 0..=40 {
            let w = 50.0 * i as f64;
            let g64 = balance_cubic(&p64.alpha, 0.025 + 0.1082 * 0.1082, 0.252, w);
            let g32 = balance_cubic(&p32.alpha, 0.025 + 0.1082f32 * 0.1082, 0.252, w as f32);
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
