//! PROTOTYPE (issue 18 groundwork, not wired into `Controller::step`): a pressure or flow loop
//! that knows the pump. Feedforward from the white-box's steady state run backwards at the
//! estimated load ([`model_core::inverse::steady_torque`]), a PI scheduled on the bench
//! linearised there ([`model_core::inverse::linearise`]: IMC tuning of a first-order plant,
//! `Kc = τ / (K λ)`, `Ti = τ`), acting on the error to a first-order reference model of the
//! setpoint; torque limits and a rate limit, the integrator frozen while limited.

use model_core::inverse::{linearise, steady_torque, Load, Target};
use model_core::BenchParams;

/// What the loop holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Controlled {
    /// Outlet pressure, mca.
    Pressure,
    /// Flow, l/s.
    Flow,
}

/// The loop's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegulatorConfig {
    /// What is held.
    pub controlled: Controlled,
    /// Control period, s (> 0).
    pub period_s: f32,
    /// Closed-loop time constant asked of the PI (IMC λ), s (> 0).
    pub closed_loop_s: f32,
    /// Time constant of the setpoint's reference model, s (≥ 0; 0: steps go straight in).
    pub reference_s: f32,
    /// Torque limits, % (0 ≤ min < max ≤ 100).
    pub torque_min_pct: f32,
    /// See `torque_min_pct`.
    pub torque_max_pct: f32,
    /// Torque rate limit, %/s (> 0).
    pub rate_pct_per_s: f32,
    /// Use the feedforward (false: PI alone around the last torque, gains still scheduled).
    pub feedforward: bool,
    /// The feedforward leads by the plant's time constant (the steady torque of
    /// `r + τ dr/dt`, r the reference model's output).
    pub dynamic_feedforward: bool,
}

/// One step's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegulatorOutput {
    /// Torque reference, %.
    pub torque_pct: f32,
    /// The feedforward part, %.
    pub feedforward_pct: f32,
    /// The integral part, %.
    pub integral_pct: f32,
    /// The torque was limited (range or rate).
    pub limited: bool,
}

/// The loop's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Regulator {
    config: RegulatorConfig,
    reference: f32,
    integral_pct: f32,
    last_pct: f32,
    fresh: bool,
}

impl Regulator {
    /// Starts bumplessly from the torque applied now and the value measured now.
    pub fn new(config: RegulatorConfig, measured: f32, torque_pct: f32) -> Self {
        Self {
            config,
            reference: measured,
            integral_pct: 0.0,
            last_pct: torque_pct,
            fresh: true,
        }
    }

    /// One control period: the torque for `setpoint` given `measured`, on the bench `bench`
    /// against the estimated `load`.
    pub fn step(
        &mut self,
        bench: &BenchParams<f32>,
        load: Load<f32>,
        setpoint: f32,
        measured: f32,
    ) -> RegulatorOutput {
        let c = &self.config;
        let a = if c.reference_s > 0.0 {
            (c.period_s / c.reference_s).min(1.0)
        } else {
            1.0
        };
        self.reference += (setpoint - self.reference) * a;
        let at = |v: f32| match c.controlled {
            Controlled::Pressure => Target::PressureMca(v),
            Controlled::Flow => Target::FlowLps(v.max(0.0)),
        };
        // The reference's rate, for the feedforward's dynamic part (the plant's first-order
        // lag inverted: the steady torque of `r + τ dr/dt`).
        let rate = if c.reference_s > 0.0 {
            (setpoint - self.reference) / c.reference_s
        } else {
            0.0
        };
        let (ff, kc, ti) = match steady_torque(bench, load, at(self.reference)) {
            Ok(inv) => {
                let (gain, tau) = match linearise(bench, load, &inv) {
                    Some(l) => (
                        match c.controlled {
                            Controlled::Pressure => l.pressure_gain_mca_per_pct,
                            Controlled::Flow => l.flow_gain_lps_per_pct,
                        },
                        l.time_constant_s,
                    ),
                    None => (0.055, 0.4),
                };
                let ff = match steady_torque(bench, load, at(self.reference + tau * rate)) {
                    Ok(ahead) if c.dynamic_feedforward => ahead.torque_ref_pct,
                    _ => inv.torque_ref_pct,
                };
                (ff, tau / (gain * c.closed_loop_s), tau)
            }
            Err(_) => (self.last_pct, 0.0, 1.0),
        };
        let ff = if c.feedforward { ff } else { 0.0 };
        let e = self.reference - measured;
        if self.fresh {
            // Bumpless: the integral takes what the feedforward and the proportional part
            // leave of the torque applied now.
            self.integral_pct = self.last_pct - ff - kc * e;
            self.fresh = false;
        }
        let di = kc * c.period_s / ti * e;
        let wanted = ff + kc * e + self.integral_pct + di;
        let step = c.rate_pct_per_s * c.period_s;
        let lo = c.torque_min_pct.max(self.last_pct - step);
        let hi = c.torque_max_pct.min(self.last_pct + step);
        let torque = wanted.clamp(lo, hi);
        let limited = torque != wanted;
        // Conditional integration: not while the torque is held at a limit in the error's
        // direction.
        if !(limited && (wanted - torque) * di > 0.0) {
            self.integral_pct += di;
        }
        self.last_pct = torque;
        RegulatorOutput {
            torque_pct: torque,
            feedforward_pct: ff,
            integral_pct: self.integral_pct,
            limited,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analog::lag_1ms;
    use model_core::{Scheme, WhiteBox};

    /// Step response figures of `y` toward `to` from `from`, sampled every ms from the step.
    fn figures(y: &[f32], from: f32, to: f32) -> (f32, f32, f32) {
        let span = to - from;
        let frac = |v: f32| (v - from) / span;
        let t10 = y.iter().position(|&v| frac(v) >= 0.1).unwrap_or(y.len()) as f32;
        let t90 = y.iter().position(|&v| frac(v) >= 0.9).unwrap_or(y.len()) as f32;
        let over = y.iter().map(|&v| frac(v) - 1.0).fold(0.0f32, f32::max);
        let band = 0.02 * to.abs();
        let settle = y
            .iter()
            .rposition(|&v| (v - to).abs() > band)
            .map_or(0, |k| k + 1) as f32;
        ((t90 - t10) * 1e-3, over * 100.0, settle * 1e-3)
    }

    /// A closed loop on the white-box (RK4, 1 ms) with a 20 ms pressure transmitter,
    /// pressure steps 2 → 4 → 1 → 3 mca, the feedforward on the true load; prints the figures.
    fn run(feedforward: bool, dynamic: bool, period_s: f32) -> Vec<(f32, f32, f32)> {
        let p = BenchParams::<f32>::PAPER;
        let bench = WhiteBox::new(p).unwrap();
        let load = Load {
            valve_k2: p.valve_k2,
            head_scale: 1.0,
            torque_scale: 1.0,
        };
        let u0 = steady_torque(&p, load, Target::PressureMca(2.0))
            .unwrap()
            .torque_ref_pct;
        let mut st = bench.steady_state(u0).unwrap();
        let mut seen = bench.signals(&st).pressure_mca;
        let config = RegulatorConfig {
            controlled: Controlled::Pressure,
            period_s,
            closed_loop_s: 0.15,
            reference_s: 0.25,
            torque_min_pct: 0.0,
            torque_max_pct: 100.0,
            rate_pct_per_s: 200.0,
            feedforward,
            dynamic_feedforward: dynamic,
        };
        let mut reg = Regulator::new(config, seen, u0);
        let mut u = u0;
        let every = (period_s * 1000.0).round() as usize;
        let mut out = vec![];
        let mut from = 2.0;
        for (i, to) in [2.0f32, 4.0, 1.0, 3.0].into_iter().enumerate() {
            let mut y = vec![];
            for k in 0..6000 {
                if k % every == 0 {
                    u = reg.step(&p, load, to, seen).torque_pct;
                    assert!(u.is_finite() && (0.0..=100.0).contains(&u));
                }
                bench.step(&mut st, u, 1e-3, Scheme::Rk4).unwrap();
                let p_now = bench.signals(&st).pressure_mca;
                lag_1ms(&mut seen, p_now, 0.02);
                y.push(p_now);
            }
            if i > 0 {
                out.push(figures(&y, from, to));
            }
            from = to;
        }
        out
    }

    #[test]
    fn pressure_steps_on_the_white_box() {
        for (ff, dynamic, period) in [
            (true, false, 0.005),
            (true, true, 0.005),
            (false, false, 0.005),
        ] {
            let f = run(ff, dynamic, period);
            eprintln!("feedforward {ff} (dynamic {dynamic}), period {period} s: (rise s, overshoot %, settle s) {f:?}");
            for (rise, over, settle) in f {
                assert!(rise.is_finite() && over.is_finite() && settle < 6.0);
            }
        }
    }

    /// Valve steps ×1.3, ×1, ×0.7, ×1 while holding 3 mca: the time back within 2 % after
    /// each, with the feedforward at the true k2 (as a perfect observer would give) and at the
    /// paper's (no observer); prints them.
    #[test]
    fn valve_steps_on_the_white_box() {
        let p = BenchParams::<f32>::PAPER;
        for known in [true, false] {
            let mut bench = WhiteBox::new(p).unwrap();
            let mut load = Load {
                valve_k2: p.valve_k2,
                head_scale: 1.0,
                torque_scale: 1.0,
            };
            let u0 = steady_torque(&p, load, Target::PressureMca(3.0))
                .unwrap()
                .torque_ref_pct;
            let mut st = bench.steady_state(u0).unwrap();
            let mut seen = bench.signals(&st).pressure_mca;
            let config = RegulatorConfig {
                controlled: Controlled::Pressure,
                period_s: 0.005,
                closed_loop_s: 0.15,
                reference_s: 0.25,
                torque_min_pct: 0.0,
                torque_max_pct: 100.0,
                rate_pct_per_s: 200.0,
                feedforward: true,
                dynamic_feedforward: true,
            };
            let mut reg = Regulator::new(config, seen, u0);
            let mut u = u0;
            let mut back = vec![];
            for factor in [1.0f32, 1.3, 1.0, 0.7, 1.0] {
                let k2 = p.valve_k2 * factor;
                bench.set_load(k2, p.static_head_c_mca).unwrap();
                if known {
                    load.valve_k2 = k2;
                }
                let mut last_out = 0;
                for k in 0..5000 {
                    if k % 5 == 0 {
                        u = reg.step(&p, load, 3.0, seen).torque_pct;
                    }
                    bench.step(&mut st, u, 1e-3, Scheme::Rk4).unwrap();
                    let p_now = bench.signals(&st).pressure_mca;
                    lag_1ms(&mut seen, p_now, 0.02);
                    if (p_now - 3.0).abs() > 0.06 {
                        last_out = k + 1;
                    }
                }
                back.push(last_out as f32 * 1e-3);
            }
            eprintln!(
                "k2 known {known}: back within 2 % after valve x1.3, x1, x0.7, x1: {:?} s",
                &back[1..]
            );
            // 3 mca at valve ×0.7 needs more than 100 % torque on the paper's bench (the
            // inverse says so): never back; every other step is.
            let reach = |f: f32| {
                let l = Load {
                    valve_k2: p.valve_k2 * f,
                    ..load
                };
                !steady_torque(&p, l, Target::PressureMca(3.0))
                    .unwrap()
                    .limited
            };
            assert!(!reach(0.7) && reach(1.3) && reach(1.0));
            assert!(back[1] < 5.0 && back[2] < 5.0 && back[4] < 5.0, "{back:?}");
        }
    }
}
