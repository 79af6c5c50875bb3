//! `pumpbench bench-data`: a **synthetic** bench record, made from the white-box bench plus what
//! a real bench adds between the physics and the logged numbers. It is the project's demo data
//! until real bench logs are used; nothing in it was measured.
//!
//! What is added (constants below, per signal):
//! - a first-order transmitter lag (pressure 20 ms; flow 40 ms, a transmitter that settles in
//!   about 100 ms as the paper's does; speed none); the pressure and flow lags can be set
//!   (`--pressure-lag-ms`, `--flow-lag-ms`, 0..2000 ms);
//! - noise (pressure 0.003 mca, flow 0.02 l/s, speed 0.5 rpm, 1 σ), the controller's
//!   transmitter noise ([`controller::analog::noise`]: a sum of four uniform draws, bounded
//!   at ±3.46 σ);
//! - the 4-20 mA loop and its ADC, the model the controller and its virtual bench use
//!   ([`controller::analog`]): a transmitter span of 0..10 mca (pressure) and 0..30 l/s
//!   (flow), saturated at NAMUR NE 43's measuring range 3.8..20.5 mA (−0.125..10.3125 mca,
//!   −0.375..30.9375 l/s), read through a 150 Ω shunt by a 12-bit 3.3 V ADC (0..22 mA in 4096
//!   codes): one code is 3.4 mm of water and 0.010 l/s. The logged value is the code's
//!   current on the span's line (not clamped to the span, as a logger records it).
//!
//! Not modelled: transmitter drift and offsets, VFD torque ripple.
//! The bench itself is the paper's white-box model in f64, integrated with RK4 at ≤ 1 ms: the
//! physics is [`crate::plant`]'s [`Plant`], which `pumpbench control` closes its loop around.
//!
//! Two dynamics the paper's model lacks can be added ([`crate::plant::Dynamics`]; both 0 by default, and
//! then the record is byte for byte what it was before they existed):
//! - water-column inertia (`--water-inertia L`, mca·s²/l): the flow is a state,
//!   `L dQ/dt = F_H(ω, Q) − (k1 + k2²) Q² + c`, the head the pump makes beyond what the pipe,
//!   the valve and the static head take accelerating the water column (for a pipe of length
//!   ℓ m and section A m², L = ℓ / (g A) / 1000: 10 m of 50 mm pipe is 0.52);
//! - the drive's torque loop (`--drive-lag-ms`): the electromagnetic torque follows Te(u)
//!   (eq. 4) through a first-order lag.
//!
//! The bench can be made to differ from the paper's model, so that an observer built on that
//! model can be tested against a known truth ([`Options`]):
//! - valve steps (`--valve-steps T:FACTOR,...`): from time T the valve coefficient k2 is FACTOR
//!   times the paper's 0.1082 √mca/(l/s) (c unchanged); FACTOR > 1 closes the valve (less flow,
//!   more pressure);
//! - a curve error (`--curve-error PCT`): the true pump-head curve is the paper's F_H (eq. 5,
//!   all ten α) times (1 + PCT/100), the true load-torque curve the paper's F_T (eq. 6, all ten
//!   β) times (1 − PCT/100): PCT > 0 is a stronger pump and a lighter load than the paper's
//!   fits, PCT < 0 a weaker pump and a heavier load; `--curve-error H,T` sets the two apart:
//!   F_H times (1 + H/100), F_T times (1 + T/100) (so `5` is `5,-5`);
//! - a curve shape (`--curve-shape PCT` or `H,T`, ±50 %): on top of that, the six terms in the
//!   flow of F_H times (1 + H/100) and of F_T times (1 + T/100), the values at no flow
//!   unchanged (`model_core::equations::FLOW_TERMS`);
//! - `--truth` adds the bench's true state at each row's time (before lag, noise and
//!   quantisation): `speed_true` (rpm), `flow_true` (l/s), `pressure_true` (mca) and
//!   `k2_true` (√mca/(l/s)).
//!
//! With none of these (or all at their defaults) the record is byte for byte what it was
//! before they existed.

use crate::error::Failure;
use crate::input::{shown, TorqueInput};
use crate::num::Short;
use crate::plant::{Plant, PlantError, PlantOptions, VALVE_FACTOR_MAX, VALVE_FACTOR_MIN};
use std::io::Write;

/// Largest RK4 step of the bench, ms (each interval between input rows is split into equal
/// steps no longer than this; a shorter interval is one step of its length).
pub use crate::plant::STEP_MS;

/// What to do about an input that needs too many steps (see
/// [`crate::input::read_input_to_integrate`]).
pub const TOO_MANY_STEPS: &str = "bench-data integrates in steps of 1 ms: use a shorter input";

/// A valve step: from `t_s` on (s, of the input's times), the valve coefficient k2 is
/// `factor` times its nominal value (the paper's k2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValveStep {
    /// Time of the step, s.
    pub t_s: f64,
    /// k2 over the nominal k2 (> 1: the valve closes).
    pub factor: f64,
}

/// How the bench of a record differs from the paper's model, and what is written.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// The plant: noise seed, curve error, dynamics, transmitter lags.
    pub plant: PlantOptions,
    /// Valve steps, times strictly increasing (see [`parse_valve_steps`]).
    pub valve_steps: Vec<ValveStep>,
    /// Write the true state columns too.
    pub truth: bool,
}

impl Options {
    /// The record as it always was: the paper's bench, the default lags, no truth columns.
    pub fn with_seed(seed: u64) -> Self {
        Options {
            plant: PlantOptions::with_seed(seed),
            valve_steps: Vec::new(),
            truth: false,
        }
    }
}

/// Parses `--valve-steps T:FACTOR,...`: times (s) finite and strictly increasing, factors
/// within [`VALVE_FACTOR_MIN`]..=[`VALVE_FACTOR_MAX`]. The message names the bad item.
pub fn parse_valve_steps(text: &str) -> Result<Vec<ValveStep>, String> {
    if text.trim().is_empty() {
        return Err(
            "--valve-steps: no steps given: expected T:FACTOR,... (e.g. 20:1.3,40:0.7)".into(),
        );
    }
    let mut steps: Vec<ValveStep> = Vec::new();
    for (k, item) in text.split(',').enumerate() {
        let bad = |why: String| format!("--valve-steps: item {} '{}': {why}", k + 1, shown(item));
        let Some((t, f)) = item.split_once(':') else {
            return Err(bad(
                "expected T:FACTOR (time in s, factor of the nominal k2)".into(),
            ));
        };
        let number = |what: &str, text: &str| -> Result<f64, String> {
            let text = text.trim();
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(bad(format!(
                    "{what} '{}' is not a finite number",
                    shown(text)
                ))),
                Err(_) => Err(bad(format!("{what} '{}' is not a number", shown(text)))),
            }
        };
        let t_s = number("time", t)?;
        let factor = number("factor", f)?;
        if !(VALVE_FACTOR_MIN..=VALVE_FACTOR_MAX).contains(&factor) {
            return Err(bad(format!(
                "factor {} is outside {}..{}",
                Short(factor),
                Short(VALVE_FACTOR_MIN),
                Short(VALVE_FACTOR_MAX)
            )));
        }
        if let Some(prev) = steps.last() {
            if !(t_s > prev.t_s) {
                return Err(bad(format!(
                    "time {} s is not after the previous step's {} s",
                    Short(t_s),
                    Short(prev.t_s)
                )));
            }
        }
        steps.push(ValveStep { t_s, factor });
    }
    Ok(steps)
}

/// Writes the synthetic record of `input`: one row per input row, the readings at that time
/// (then, with [`Options::truth`], the true state at that time).
///
/// The input's times are checked by [`crate::input::read_input_to_integrate`] with
/// [`STEP_MS`], as `simulate` checks them.
///
/// A valve step at time T is applied before the first integration step that starts at or after
/// T, so the first row with a time ≥ T shows it in `k2_true`; the steps at or before the first
/// row's time set the valve the bench starts with (at its steady state). The new k2 changes the
/// flow and pressure at once (the flow loop has no inertia in the model); the readings follow
/// through their transmitter lags.
pub fn run(input: &TorqueInput, o: &Options, w: &mut dyn Write) -> Result<(), Failure> {
    let fail = |m: String| Failure {
        code: 1,
        message: m,
    };
    let plant_fail = |e: PlantError| match e {
        PlantError::Options(message) => Failure { code: 2, message },
        e => fail(e.to_string()),
    };
    let mut pending = o.valve_steps.iter().peekable();
    // The factor of the last step due at time `t` (those before it lasted no time).
    let mut valve_at = |t: f64| -> Option<f64> {
        let mut factor = None;
        while let Some(step) = pending.next_if(|s| s.t_s <= t) {
            factor = Some(step.factor);
        }
        factor
    };
    let start_valve = valve_at(input.t_s[0]).unwrap_or(1.0);
    let mut plant =
        Plant::new(&o.plant, start_valve, input.torque_ref_pct[0]).map_err(plant_fail)?;
    let write_fail = |e: std::io::Error| fail(format!("cannot write the output: {e}"));
    write!(w, "t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca").map_err(write_fail)?;
    if o.truth {
        write!(w, ",speed_true,flow_true,pressure_true,k2_true").map_err(write_fail)?;
    }
    writeln!(w).map_err(write_fail)?;
    for i in 0..input.t_s.len() {
        if i > 0 {
            let u = input.torque_ref_pct[i - 1];
            let t0 = input.t_s[i - 1];
            let dt = input.t_s[i] - t0;
            let n = (dt / (STEP_MS * 1e-3) - 1e-9).ceil().max(1.0) as u64;
            let h = dt / n as f64;
            for k in 0..n {
                if k > 0 {
                    // (k = 0 starts at the previous row's time: its steps are applied.)
                    if let Some(f) = valve_at(t0 + k as f64 * h) {
                        plant.set_valve_factor(f).map_err(plant_fail)?;
                    }
                }
                plant.advance(u, h).map_err(|e| match e {
                    PlantError::Diverged => fail(format!(
                        "model: the bench diverged at t = {} s",
                        Short(t0 + (k + 1) as f64 * h)
                    )),
                    e => plant_fail(e),
                })?;
            }
        }
        if let Some(f) = valve_at(input.t_s[i]) {
            plant.set_valve_factor(f).map_err(plant_fail)?;
        }
        // Times and torques as given (shortest round-trip form); the readings at the
        // resolution of a logger.
        let (speed, flow, pressure) = plant.readings();
        write!(
            w,
            "{},{},{:.2},{:.4},{:.5}",
            Short(input.t_s[i]),
            Short(input.torque_ref_pct[i]),
            speed,
            flow,
            pressure
        )
        .map_err(write_fail)?;
        if o.truth {
            // The true state in shortest round-trip form (not a reading: no logger rounding).
            let t = plant.truth();
            write!(
                w,
                ",{},{},{},{}",
                Short(t.speed_rpm),
                Short(t.flow_lps),
                Short(t.pressure_mca),
                Short(t.valve_k2)
            )
            .map_err(write_fail)?;
        }
        writeln!(w).map_err(write_fail)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valve_steps_parse_and_bad_items_are_named() {
        assert_eq!(
            parse_valve_steps("20:1.3, 40 : 0.7,60:1").unwrap(),
            [
                ValveStep {
                    t_s: 20.0,
                    factor: 1.3
                },
                ValveStep {
                    t_s: 40.0,
                    factor: 0.7
                },
                ValveStep {
                    t_s: 60.0,
                    factor: 1.0
                }
            ]
        );
        assert_eq!(parse_valve_steps("-1:0.2,0:5").unwrap().len(), 2);
        for (text, expected) in [
            ("20:1.3,40:x", "item 2 '40:x': factor 'x' is not a number"),
            ("20:0.19", "item 1 '20:0.19': factor 0.19 is outside 0.2..5"),
            ("20:1,20:2", "item 2 '20:2': time 20 s is not after"),
            ("inf:1", "item 1 'inf:1': time 'inf' is not a finite number"),
            ("20:1,", "item 2 '': expected T:FACTOR"),
            (" ", "no steps given"),
        ] {
            let e = parse_valve_steps(text).unwrap_err();
            assert!(
                e.starts_with("--valve-steps: ") && e.contains(expected),
                "{e}"
            );
        }
    }

    #[test]
    fn the_default_options_are_the_default_plant() {
        let o = Options::with_seed(3);
        assert_eq!(o.plant, PlantOptions::with_seed(3));
        assert!(o.valve_steps.is_empty() && !o.truth);
    }
}
