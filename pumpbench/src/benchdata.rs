//! `pumpbench bench-data`: a **synthetic** bench record, made from the white-box bench plus what
//! a real bench adds between the physics and the logged numbers. It is the project's demo data
//! until real bench logs are used; nothing in it was measured.
//!
//! What is added (constants below, per signal):
//! - a first-order transmitter lag (pressure 20 ms; flow 40 ms, a transmitter that settles in
//!   about 100 ms as the paper's does; speed none);
//! - Gaussian noise (pressure 0.003 mca, flow 0.02 l/s, speed 0.5 rpm, 1 σ);
//! - 12-bit quantisation of the 4-20 mA loop: an ADC reading 0..24 mA in 4096 codes, a
//!   transmitter span of 0..10 mca (pressure) and 0..30 l/s (flow): one code is 3.7 mm of
//!   water and 0.011 l/s.
//!
//! Not modelled: water-column inertia, transmitter drift and offsets, VFD torque ripple.
//! The bench itself is the paper's white-box model in f64, integrated with RK4 at ≤ 1 ms.

use crate::input::TorqueInput;
use crate::num::Short;
use crate::Failure;
use model_core::excitation::SplitMix64;
use model_core::{BenchState, Scheme, WhiteBox, MAX_STEP_S};
use std::io::Write;

/// Transmitter model of one signal.
#[derive(Debug, Clone, Copy)]
pub struct Transmitter {
    /// First-order time constant, s (0: none).
    pub tau_s: f64,
    /// Noise standard deviation, signal units.
    pub noise: f64,
    /// 4-20 mA span: the value at 20 mA (4 mA is 0); 0 for no quantisation.
    pub span: f64,
}

/// Pressure transmitter: 20 ms lag, 3 mm water noise, 0..10 mca.
pub const PRESSURE: Transmitter = Transmitter {
    tau_s: 0.020,
    noise: 0.003,
    span: 10.0,
};
/// Flow transmitter: 40 ms lag, 0.02 l/s noise, 0..30 l/s.
pub const FLOW: Transmitter = Transmitter {
    tau_s: 0.040,
    noise: 0.02,
    span: 30.0,
};
/// Speed (encoder used during identification only): no lag, 0.5 rpm noise, not quantised.
pub const SPEED: Transmitter = Transmitter {
    tau_s: 0.0,
    noise: 0.5,
    span: 0.0,
};
/// ADC: full scale in mA and number of codes.
const ADC_FULL_SCALE_MA: f64 = 24.0;
const ADC_CODES: f64 = 4096.0;

impl Transmitter {
    /// Reading: noise added to the lagged value, then the 4-20 mA loop quantised by the ADC.
    fn read(&self, lagged: f64, rng: &mut SplitMix64) -> f64 {
        let noisy = lagged + self.noise * gaussian(rng);
        if self.span <= 0.0 {
            return noisy;
        }
        let ma = 4.0 + 16.0 * noisy / self.span;
        let code = (ma / ADC_FULL_SCALE_MA * (ADC_CODES - 1.0))
            .round()
            .clamp(0.0, ADC_CODES - 1.0);
        let ma_q = code / (ADC_CODES - 1.0) * ADC_FULL_SCALE_MA;
        (ma_q - 4.0) / 16.0 * self.span
    }

    /// Advances the lag state `x` toward `target` over `h` seconds (exact for a held target).
    fn lag(&self, x: &mut f64, target: f64, h: f64) {
        if self.tau_s <= 0.0 {
            *x = target;
        } else {
            *x += (1.0 - (-h / self.tau_s).exp()) * (target - *x);
        }
    }
}

/// Standard normal draw (Box-Muller).
pub fn gaussian(rng: &mut SplitMix64) -> f64 {
    let u1 = rng.next_f64().max(1e-300);
    let u2 = rng.next_f64();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Largest RK4 step of the bench, ms (each interval between input rows is split into equal
/// steps no longer than this; a shorter interval is one step of its length).
pub const STEP_MS: f64 = 1.0;

/// What to do about an input that needs too many steps (see
/// [`crate::input::read_input_to_integrate`]).
pub const TOO_MANY_STEPS: &str = "bench-data integrates in steps of 1 ms: use a shorter input";

/// Writes the synthetic record of `input`: one row per input row, the readings at that time.
///
/// The input's times are checked by [`crate::input::read_input_to_integrate`] with
/// [`STEP_MS`], as `simulate` checks them.
pub fn run(input: &TorqueInput, seed: u64, w: &mut dyn Write) -> Result<(), Failure> {
    let fail = |m: String| Failure {
        code: 1,
        message: m,
    };
    let bench = WhiteBox::<f64>::paper();
    let mut state: BenchState<f64> = bench
        .steady_state(input.torque_ref_pct[0])
        .map_err(|e| fail(format!("model: {e}")))?;
    let mut rng = SplitMix64::new(seed);
    let s0 = bench.signals(&state);
    let (mut p, mut q, mut s) = (s0.pressure_mca, s0.flow_lps, s0.speed_rpm);
    writeln!(w, "t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca")
        .map_err(|e| fail(format!("cannot write the output: {e}")))?;
    for i in 0..input.t_s.len() {
        if i > 0 {
            let u = input.torque_ref_pct[i - 1];
            let dt = input.t_s[i] - input.t_s[i - 1];
            let n = (dt / (STEP_MS * 1e-3) - 1e-9).ceil().max(1.0) as u64;
            let h = dt / n as f64;
            for _ in 0..n {
                // One step of h (h <= 1 ms < MAX_STEP_S), also below model-core's 1 µs
                // smallest step, as `simulate` integrates a short interval.
                bench
                    .advance(&mut state, u, h, MAX_STEP_S, Scheme::Rk4)
                    .map_err(|e| fail(format!("model: {e}")))?;
                let sig = bench.signals(&state);
                PRESSURE.lag(&mut p, sig.pressure_mca, h);
                FLOW.lag(&mut q, sig.flow_lps, h);
                SPEED.lag(&mut s, sig.speed_rpm, h);
            }
        }
        // Times and torques as given (shortest round-trip form); the readings at the
        // resolution of a logger.
        writeln!(
            w,
            "{},{},{:.2},{:.4},{:.5}",
            Short(input.t_s[i]),
            Short(input.torque_ref_pct[i]),
            SPEED.read(s, &mut rng),
            FLOW.read(q, &mut rng),
            PRESSURE.read(p, &mut rng)
        )
        .map_err(|e| fail(format!("cannot write the output: {e}")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantisation_step_and_noise_level() {
        let mut rng = SplitMix64::new(1);
        let quiet = Transmitter {
            noise: 0.0,
            ..PRESSURE
        };
        let a = quiet.read(2.0, &mut rng);
        let lsb = 10.0 * ADC_FULL_SCALE_MA / 16.0 / (ADC_CODES - 1.0);
        assert!((a - 2.0).abs() <= lsb / 2.0 + 1e-12);
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| FLOW.read(15.0, &mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!(
            (mean - 15.0).abs() < 0.01 && (sd - 0.022).abs() < 0.004,
            "{mean} {sd}"
        );
    }

    #[test]
    fn lag_is_first_order() {
        let mut x = 0.0;
        for _ in 0..20 {
            PRESSURE.lag(&mut x, 1.0, 1e-3);
        }
        assert!((x - (1.0 - (-1.0f64).exp())).abs() < 1e-12);
    }
}
