//! Independent f64 reference of the white-box bench (paper eqs. 3-8).
//!
//! Written apart from `model-core` on purpose: different state unit (rad/s), polynomials
//! evaluated term by term as printed, flow from the closed-form cubic roots polished by
//! bisection, steady state by scan and bisection on its own code, and an adaptive
//! Dormand-Prince 5(4) integrator. Units of the coefficients: rpm, l/s, mca, % of nominal
//! torque (docs/bench.md, "Units (the paper prints none)").

use std::f64::consts::PI;

/// The bench's coefficients, typed again from the paper.
#[derive(Debug, Clone, Copy)]
pub struct Reference {
    /// γ1..γ6.
    pub gamma: [f64; 6],
    /// α1..α10.
    pub alpha: [f64; 10],
    /// β1..β10.
    pub beta: [f64; 10],
    /// k1, mca/(l/s)².
    pub k1: f64,
    /// k2, √mca/(l/s).
    pub k2: f64,
    /// c, mca.
    pub c: f64,
    /// J, kg m².
    pub j: f64,
    /// Nominal torque, N m.
    pub t_nom: f64,
    /// Relative tolerance of the integrator.
    pub rtol: f64,
}

/// State and outputs of the reference at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefSample {
    /// Time, s.
    pub t_s: f64,
    /// Torque reference that acts from this instant, %.
    pub u_pct: f64,
    /// Speed, rpm.
    pub speed_rpm: f64,
    /// Flow, l/s.
    pub flow_lps: f64,
    /// Outlet pressure, mca.
    pub pressure_mca: f64,
}

fn rad_to_rpm(w: f64) -> f64 {
    w * 60.0 / (2.0 * PI)
}

impl Reference {
    /// The paper's bench, tolerance 1e-12.
    pub fn paper() -> Self {
        Reference {
            gamma: [-1.506e-8, 3.843e-6, -3.319e-4, 1.263e-2, 0.707, 2.244],
            alpha: [
                -1.3631e-3, 1.3620e-9, 1.7304e-5, -7.3548e-8, -2.5497e-2, 5.7314e-6, 1.0691e-4,
                -9.6703e-2, 4.4057e-3, -2.5259e-1,
            ],
            beta: [
                -2.5186e-3,
                -9.1168e-10,
                6.9103e-5,
                2.5492e-7,
                -5.6126e-2,
                1.0972e-5,
                6.8286e-4,
                6.5038e-1,
                3.6776e-3,
                4.3067e-1,
            ],
            k1: 2.5e-2,
            k2: 1.082e-1,
            c: 0.252,
            j: 0.08872,
            t_nom: 39.9,
            rtol: 1e-12,
        }
    }

    /// Te(u), % (eq. 4), term by term.
    pub fn te(&self, u: f64) -> f64 {
        (0..6).map(|i| self.gamma[i] * u.powi(5 - i as i32)).sum()
    }

    fn poly(p: &[f64; 10], w: f64, q: f64) -> f64 {
        p[0] * q.powi(3)
            + p[1] * w.powi(3)
            + p[2] * q.powi(2) * w
            + p[3] * q * w.powi(2)
            + p[4] * q.powi(2)
            + p[5] * w.powi(2)
            + p[6] * q * w
            + p[7] * q
            + p[8] * w
            + p[9]
    }

    /// Pump head F_H(ω, Q), mca (eq. 5); ω in rpm.
    pub fn fh(&self, w_rpm: f64, q: f64) -> f64 {
        Self::poly(&self.alpha, w_rpm, q)
    }

    /// Load torque F_T(ω, Q), % (eq. 6); ω in rpm.
    pub fn ft(&self, w_rpm: f64, q: f64) -> f64 {
        Self::poly(&self.beta, w_rpm, q)
    }

    /// The flow balance F_H − k1 Q² − Hs(Q), with Hs = k2² Q² − c.
    pub fn balance(&self, w_rpm: f64, q: f64) -> f64 {
        self.fh(w_rpm, q) - self.k1 * q * q - (self.k2 * self.k2 * q * q - self.c)
    }

    /// Real roots of a q³ + b q² + c q + d (a ≠ 0), closed form.
    fn cubic_roots(a: f64, b: f64, c: f64, d: f64) -> Vec<f64> {
        let (b, c, d) = (b / a, c / a, d / a);
        let p = c - b * b / 3.0;
        let q = 2.0 * b.powi(3) / 27.0 - b * c / 3.0 + d;
        let shift = -b / 3.0;
        let disc = (q / 2.0).powi(2) + (p / 3.0).powi(3);
        if disc > 0.0 {
            let s = disc.sqrt();
            vec![(-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt() + shift]
        } else if p == 0.0 {
            vec![shift]
        } else {
            let r = 2.0 * (-p / 3.0).sqrt();
            let phi = ((3.0 * q / (p * r)).clamp(-1.0, 1.0)).acos() / 3.0;
            (0..3)
                .map(|k| r * (phi - 2.0 * PI * k as f64 / 3.0).cos() + shift)
                .collect()
        }
    }

    /// Flow at a speed (rpm): the largest non-negative root of the balance, 0 if none.
    pub fn flow(&self, w_rpm: f64) -> f64 {
        let a = &self.alpha;
        let w = w_rpm;
        let c3 = a[0];
        let c2 = a[2] * w + a[4] - self.k1 - self.k2 * self.k2;
        let c1 = a[3] * w * w + a[6] * w + a[7];
        let c0 = a[1] * w.powi(3) + a[5] * w * w + a[8] * w + a[9] + self.c;
        let root = Self::cubic_roots(c3, c2, c1, c0)
            .into_iter()
            .fold(f64::NEG_INFINITY, f64::max);
        if !(root > 0.0) {
            return 0.0;
        }
        // Polish by bisection on a bracket around the closed-form root.
        let g = |q: f64| self.balance(w, q);
        let mut delta = 1e-9 * root.max(1.0);
        let (mut lo, mut hi) = ((root - delta).max(0.0), root + delta);
        while !(g(lo) > 0.0 && g(hi) < 0.0) && delta < root.max(1.0) {
            delta *= 4.0;
            lo = (root - delta).max(0.0);
            hi = root + delta;
        }
        if !(g(lo) > 0.0 && g(hi) < 0.0) {
            return if g(0.0) > 0.0 { root } else { 0.0 };
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if g(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// dω/dt in rad/s² (eq. 3).
    pub fn dwdt(&self, u: f64, w_rad: f64) -> f64 {
        let w_rpm = rad_to_rpm(w_rad);
        let q = self.flow(w_rpm);
        (self.te(u) - self.ft(w_rpm, q)) * self.t_nom / 100.0 / self.j
    }

    /// Outlet pressure at a flow, mca (eq. 8).
    pub fn pressure(&self, q: f64) -> f64 {
        self.k2 * self.k2 * q * q - self.c
    }

    /// Steady state for u: (speed rpm, flow l/s, pressure mca) — the lowest equilibrium
    /// above rest, found by a 10 rpm scan and bisection.
    pub fn steady(&self, u: f64) -> (f64, f64, f64) {
        let te = self.te(u);
        let surplus = |w: f64| te - self.ft(w, self.flow(w));
        let mut lo = 0.0;
        let mut hi = 10.0;
        while surplus(hi) > 0.0 {
            lo = hi;
            hi += 10.0;
            assert!(hi < 1e4, "no steady state for u = {u}");
        }
        while hi - lo > 1e-13 * hi {
            let mid = 0.5 * (lo + hi);
            if surplus(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let w = 0.5 * (lo + hi);
        let q = self.flow(w);
        (w, q, self.pressure(q))
    }

    /// Integrates dω/dt with u held from `w_rad` over `duration` s (Dormand-Prince 5(4),
    /// adaptive, relative tolerance `self.rtol`); returns the speed in rad/s.
    pub fn hold(&self, u: f64, w_rad: f64, duration: f64) -> f64 {
        const C: [f64; 7] = [0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0];
        const A: [[f64; 6]; 7] = [
            [0.0; 6],
            [0.2, 0.0, 0.0, 0.0, 0.0, 0.0],
            [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
            [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
            [
                19372.0 / 6561.0,
                -25360.0 / 2187.0,
                64448.0 / 6561.0,
                -212.0 / 729.0,
                0.0,
                0.0,
            ],
            [
                9017.0 / 3168.0,
                -355.0 / 33.0,
                46732.0 / 5247.0,
                49.0 / 176.0,
                -5103.0 / 18656.0,
                0.0,
            ],
            [
                35.0 / 384.0,
                0.0,
                500.0 / 1113.0,
                125.0 / 192.0,
                -2187.0 / 6784.0,
                11.0 / 84.0,
            ],
        ];
        const B5: [f64; 7] = [
            35.0 / 384.0,
            0.0,
            500.0 / 1113.0,
            125.0 / 192.0,
            -2187.0 / 6784.0,
            11.0 / 84.0,
            0.0,
        ];
        const B4: [f64; 7] = [
            5179.0 / 57600.0,
            0.0,
            7571.0 / 16695.0,
            393.0 / 640.0,
            -92097.0 / 339200.0,
            187.0 / 2100.0,
            1.0 / 40.0,
        ];
        let _ = C; // stage times: the ODE is autonomous over a hold
        let mut t = 0.0;
        let mut w = w_rad;
        let mut h = (duration / 10.0).min(1e-3);
        while t < duration {
            if t + h > duration {
                h = duration - t;
            }
            let mut k = [0.0f64; 7];
            for s in 0..7 {
                let ws = w + h * (0..s).map(|i| A[s][i] * k[i]).sum::<f64>();
                k[s] = self.dwdt(u, ws);
            }
            let w5 = w + h * (0..7).map(|i| B5[i] * k[i]).sum::<f64>();
            let w4 = w + h * (0..7).map(|i| B4[i] * k[i]).sum::<f64>();
            let scale = self.rtol * w.abs().max(w5.abs()).max(1.0);
            let err = (w5 - w4).abs() / scale;
            if err <= 1.0 {
                t += h;
                w = w5;
            }
            let factor = if err == 0.0 {
                5.0
            } else {
                (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
            };
            h = (h * factor).max(1e-12);
        }
        w
    }

    /// Simulates a piecewise-constant input `(t_s, u_pct)` (times increasing) from the steady
    /// state of the first torque; returns the state at every input time, before its torque acts.
    pub fn simulate(&self, input: &[(f64, f64)]) -> Vec<RefSample> {
        let mut out = Vec::with_capacity(input.len());
        let (w0_rpm, _, _) = self.steady(input[0].1);
        let mut w = w0_rpm * 2.0 * PI / 60.0;
        for (i, &(t, u)) in input.iter().enumerate() {
            if i > 0 {
                let (t_prev, u_prev) = input[i - 1];
                w = self.hold(u_prev, w, t - t_prev);
            }
            let w_rpm = rad_to_rpm(w);
            let q = self.flow(w_rpm);
            out.push(RefSample {
                t_s: t,
                u_pct: u,
                speed_rpm: w_rpm,
                flow_lps: q,
                pressure_mca: self.pressure(q),
            });
        }
        out
    }
}
