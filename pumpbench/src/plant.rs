//! The physical bench that `bench-data` records and `pumpbench control` closes its loop around:
//! the paper's white-box model in f64 (RK4 at ≤ 1 ms) plus what a real bench adds between the
//! physics and the controller's inputs, as a stepping API ([`Plant`]).
//!
//! What is added (constants below, per signal):
//! - a first-order transmitter lag (pressure 20 ms; flow 40 ms, a transmitter that settles in
//!   about 100 ms as the paper's does; speed none), settable per plant ([`PlantOptions`]);
//! - noise (pressure 0.003 mca, flow 0.02 l/s, speed 0.5 rpm, 1 σ), the controller's
//!   transmitter noise ([`controller::analog::noise`]: a sum of four uniform draws, bounded
//!   at ±3.46 σ);
//! - the 4-20 mA loop and its ADC, the model the controller and its virtual bench use
//!   ([`controller::analog`]): a transmitter span of 0..10 mca (pressure) and 0..30 l/s
//!   (flow), saturated at NAMUR NE 43's measuring range 3.8..20.5 mA (−0.125..10.3125 mca,
//!   −0.375..30.9375 l/s), read through a 150 Ω shunt by a 12-bit 3.3 V ADC (0..22 mA in 4096
//!   codes): one code is 3.4 mm of water and 0.010 l/s.
//!
//! Two dynamics the paper's model lacks can be added ([`Dynamics`]; both 0 by default):
//! - water-column inertia (mca·s²/l): the flow is a state,
//!   `L dQ/dt = F_H(ω, Q) − (k1 + k2²) Q² + c`, the head the pump makes beyond what the pipe,
//!   the valve and the static head take accelerating the water column (for a pipe of length
//!   ℓ m and section A m², L = ℓ / (g A) / 1000: 10 m of 50 mm pipe is 0.52);
//! - the drive's torque loop: the electromagnetic torque follows Te(u) (eq. 4) through a
//!   first-order lag;
//! - the drive's own torque ramp: the reference it acts on follows the one it is sent no
//!   faster than a rate (%/s), as a drive's ramp setting limits it.
//!
//! And a transport delay ahead of both transmitters' lags
//! ([`PlantOptions::transmitter_delay_s`]): a pressure tap or a meter down the pipe, a
//! transmitter that samples and filters digitally, a reading that crosses a fieldbus.
//!
//! Its rotor's inertia (J of eq. 3) can be the paper's times a factor
//! ([`PlantOptions::rotor_inertia`]; another motor and impeller).
//!
//! The bench can differ from the paper's model: its valve coefficient k2 set to a factor of
//! the paper's 0.1082 √mca/(l/s) at any time ([`Plant::set_valve_factor`]), and a curve error
//! ([`CurveError`], [`true_bench`]): the true pump-head curve F_H (eq. 5, all ten α) and the
//! true load-torque curve F_T (eq. 6, all ten β) are the paper's times their own factors, and
//! each curve's shape can differ: its six terms in the flow ([`FLOW_TERMS`]) times a factor of
//! their own (a head that falls faster or slower with the flow than the paper's fit, a torque
//! that rises faster or slower), which no single scale absorbs.
//!
//! For a controller in the loop ([`Plant::frame`]) the plant shows the two transmitters' ADC
//! codes (a failed transmitter reads [`FAULT_MA`], an NE 43 fault) and the drive's readings
//! (speed through the speed channel's noise, the electromagnetic torque it delivers, status
//! word 0), or no drive readings while the VFD link is cut ([`SensorState`]).
//!
//! Not modelled: transmitter drift and offsets, VFD torque ripple.

use crate::input::shown;
use crate::num::Short;
use controller::analog::{self, LoopConfig, FLOW_LOOP, PRESSURE_LOOP};
use controller::plant::PlantFrame;
use controller::vfd::VfdReadings;
use model_core::equations::{
    electromagnetic_torque_pct, load_torque_pct, speed_derivative_rpm_per_s, valve_pressure_mca,
    FLOW_TERMS,
};
use model_core::excitation::SplitMix64;
use model_core::params::PAPER_C_MCA;
use model_core::transmitter::lag_to;
use model_core::{BenchParams, BenchState, Scheme, WhiteBox, MAX_STEP_S};
use std::collections::VecDeque;

/// Transmitter model of one signal.
#[derive(Debug, Clone, Copy)]
pub struct Transmitter {
    /// First-order time constant, s (0: none).
    pub tau_s: f64,
    /// Noise standard deviation, signal units.
    pub noise: f64,
    /// The 4-20 mA loop (span, shunt, ADC) that carries the reading; `None`: not quantised.
    pub adc: Option<LoopConfig>,
}

/// Pressure transmitter: 20 ms lag, 3 mm water noise, 0..10 mca ([`PRESSURE_LOOP`]).
pub const PRESSURE: Transmitter = Transmitter {
    tau_s: 0.020,
    noise: 0.003,
    adc: Some(PRESSURE_LOOP),
};
/// Flow transmitter: 40 ms lag, 0.02 l/s noise, 0..30 l/s ([`FLOW_LOOP`]).
pub const FLOW: Transmitter = Transmitter {
    tau_s: 0.040,
    noise: 0.02,
    adc: Some(FLOW_LOOP),
};
/// Speed (encoder used during identification only): no lag, 0.5 rpm noise, not quantised.
pub const SPEED: Transmitter = Transmitter {
    tau_s: 0.0,
    noise: 0.5,
    adc: None,
};

impl Transmitter {
    /// The lagged value with this transmitter's noise (one draw of `rng`).
    fn noisy(&self, lagged: f64, rng: &mut SplitMix64) -> f64 {
        lagged + self.noise * f64::from(analog::noise(rng))
    }

    /// Reading: noise added to the lagged value, then the 4-20 mA transmitter and the ADC
    /// ([`controller::analog`], in f32 as on the board), the code's current read back on the
    /// span's line.
    pub(crate) fn read(&self, lagged: f64, rng: &mut SplitMix64) -> f64 {
        let noisy = self.noisy(lagged, rng);
        match &self.adc {
            None => noisy,
            Some(l) => f64::from(l.value_unclamped(l.current_ma(adc_code(l, noisy)))),
        }
    }

    /// Advances the lag state `x` toward `target` over `h` seconds (the transmitter's lag,
    /// [`analog::lag_exact`]: exact for a held target).
    fn lag(&self, x: &mut f64, target: f64, h: f64) {
        analog::lag_exact(x, target, h, self.tau_s);
    }
}

/// The ADC code of a transmitter on loop `l` showing `value` (its span's unit): the 4-20 mA
/// current saturated at NE 43's measuring range, then the shunt and the ADC, in f32 as on the
/// board.
fn adc_code(l: &LoopConfig, value: f64) -> u16 {
    l.code(l.transmitter_ma(value as f32))
}

/// The loop current of a failed transmitter, mA (NE 43: below 3.6 mA, a broken wire).
pub const FAULT_MA: f32 = 2.0;

/// Largest RK4 step of the bench, ms (each interval between input rows is split into equal
/// steps no longer than this; a shorter interval is one step of its length).
pub const STEP_MS: f64 = 1.0;

/// Smallest valve factor accepted.
pub const VALVE_FACTOR_MIN: f64 = 0.2;
/// Largest valve factor accepted.
pub const VALVE_FACTOR_MAX: f64 = 5.0;
/// Largest |curve error| accepted, %.
pub const CURVE_ERROR_MAX_PCT: f64 = 20.0;
/// Largest |curve shape error| accepted, % (the head curve's terms in Q at +50 % lower the head by
/// 4..10 % from 8 to 15 l/s at 1 400..1 800 rpm: a curve of another slope).
pub const CURVE_SHAPE_MAX_PCT: f64 = 50.0;
/// Longest transmitter lag accepted, ms.
pub const LAG_MAX_MS: f64 = 2000.0;
/// Smallest non-zero water inertia accepted, mca·s²/l (below it the flow's time constant is
/// under 0.1 ms at the steepest flow balance, and 1 ms steps would need too many sub-steps).
pub const INERTIA_MIN: f64 = 1e-3;
/// Largest water inertia accepted, mca·s²/l.
pub const INERTIA_MAX: f64 = 10.0;
/// The rotor inertias accepted, × the paper's.
pub const ROTOR_INERTIA_RANGE: (f64, f64) = (0.25, 4.0);

/// A curve error: the true curves are the paper's times `1 + pct/100`, each on its own
/// (scale), and their terms in the flow times `1 + shape_pct/100` (shape).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveError {
    /// Pump head F_H (eq. 5, all ten α), %.
    pub head_pct: f64,
    /// Load torque F_T (eq. 6, all ten β), %.
    pub torque_pct: f64,
    /// Pump head F_H's shape: its six terms in Q ([`FLOW_TERMS`]) times `1 + head_shape_pct/100`
    /// on top of the scale, %; the shut-off head F_H(ω, 0) stays the scaled paper's.
    pub head_shape_pct: f64,
    /// Load torque F_T's shape: its six terms in Q times `1 + torque_shape_pct/100`, %; the
    /// torque at no flow F_T(ω, 0) stays the scaled paper's.
    pub torque_shape_pct: f64,
}

impl CurveError {
    /// The paper's curves.
    pub const NONE: Self = Self {
        head_pct: 0.0,
        torque_pct: 0.0,
        head_shape_pct: 0.0,
        torque_shape_pct: 0.0,
    };
}

/// Dynamics the paper's model lacks (0: not there).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dynamics {
    /// Water-column inertia L, mca·s²/l: `L dQ/dt` is the head left over from the flow
    /// balance (0, or [`INERTIA_MIN`]..=[`INERTIA_MAX`]).
    pub water_inertia: f64,
    /// First-order lag of the drive's torque loop, s (0..=2 s).
    pub drive_lag_s: f64,
    /// The drive's own torque ramp, % of nominal torque per s (0: none, else
    /// [`DRIVE_SLEW_RANGE_PCT_S`]): the reference the drive acts on moves toward the one it
    /// is sent by at most this rate × the step at each step's start (steps of ≤ 1 ms).
    pub drive_slew_pct_s: f64,
}

/// `--drive-slew-pct-s`' range when not 0, % of nominal torque per s: from a drive ramping
/// 0..100 % in 10 s to one far faster than the controller's own rate limit (200 %/s by
/// default, holding register 12).
pub const DRIVE_SLEW_RANGE_PCT_S: (f64, f64) = (10.0, 100_000.0);

/// Parses `--drive-slew-pct-s R` (% of nominal torque per s): 0 (none), or finite within
/// [`DRIVE_SLEW_RANGE_PCT_S`].
pub fn parse_drive_slew(text: &str) -> Result<f64, String> {
    zero_or_in_range("--drive-slew-pct-s", text, DRIVE_SLEW_RANGE_PCT_S, " %/s")
}

/// Longest transport delay accepted ahead of the transmitters, ms.
pub const DELAY_MAX_MS: f64 = 1000.0;

/// Parses `--transmitter-delay-ms MS`: finite, within 0..=[`DELAY_MAX_MS`]. Returns seconds.
pub fn parse_delay_ms(text: &str) -> Result<f64, String> {
    Ok(in_range("--transmitter-delay-ms", text, (0.0, DELAY_MAX_MS), " ms")? / 1000.0)
}

/// The range of `--pressure-noise`, mca (1 σ): up to 5 % of the transmitter's 10 mca span.
pub const PRESSURE_NOISE_RANGE_MCA: (f64, f64) = (0.0, 0.5);

/// `--pressure-noise MCA`: the pressure transmitter's noise, mca (1 σ), within
/// [`PRESSURE_NOISE_RANGE_MCA`].
pub fn parse_pressure_noise(text: &str) -> Result<f64, String> {
    in_range("--pressure-noise", text, PRESSURE_NOISE_RANGE_MCA, " mca")
}

impl Dynamics {
    /// The paper's model: flow algebraic, torque at once.
    pub const NONE: Self = Self {
        water_inertia: 0.0,
        drive_lag_s: 0.0,
        drive_slew_pct_s: 0.0,
    };
}

/// `text` as a finite number within `lo..=hi`, or a one-line message naming `option` that
/// shows the value as it was typed (3000, not 3e3) and the range in `unit` (" ms").
fn in_range(option: &str, text: &str, range: (f64, f64), unit: &str) -> Result<f64, String> {
    within(option, text, range, unit, false)
}

/// As [`in_range`], but 0 (off) is accepted too, and given back as +0 (for "-0").
fn zero_or_in_range(
    option: &str,
    text: &str,
    range: (f64, f64),
    unit: &str,
) -> Result<f64, String> {
    within(option, text, range, unit, true)
}

/// The rule of [`in_range`] and [`zero_or_in_range`] (`zero`: 0 accepted too).
fn within(
    option: &str,
    text: &str,
    (lo, hi): (f64, f64),
    unit: &str,
    zero: bool,
) -> Result<f64, String> {
    let v = finite(option, text)?;
    if zero && v == 0.0 {
        Ok(0.0)
    } else if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        // The limits in plain notation (`Short` would write 2e3).
        let or_zero = if zero { "0 or " } else { "" };
        Err(format!(
            "{option} {}: must be {or_zero}within {lo}..{hi}{unit}",
            shown(text.trim())
        ))
    }
}

/// `text` as a finite number, or a one-line message naming `option`.
pub(crate) fn finite(option: &str, text: &str) -> Result<f64, String> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{option} '{}': not a finite number", shown(t))),
        Err(_) => Err(format!("{option} '{}': not a number", shown(t))),
    }
}

/// Parses `--curve-error PCT` (head +PCT, load torque −PCT) or `--curve-error H,T` (head H,
/// load torque T): each finite, |·| ≤ [`CURVE_ERROR_MAX_PCT`]. The shapes are the paper's.
pub fn parse_curve_error(text: &str) -> Result<CurveError, String> {
    let (head_pct, torque_pct) = parse_pct_pair("--curve-error", text, CURVE_ERROR_MAX_PCT)?;
    Ok(CurveError {
        head_pct,
        torque_pct,
        ..CurveError::NONE
    })
}

/// Parses `--curve-shape PCT` (the head curve's flow terms +PCT, the load torque's −PCT) or
/// `--curve-shape H,T`: each finite, |·| ≤ [`CURVE_SHAPE_MAX_PCT`]. Returns
/// `(head_shape_pct, torque_shape_pct)` ([`CurveError`]).
pub fn parse_curve_shape(text: &str) -> Result<(f64, f64), String> {
    parse_pct_pair("--curve-shape", text, CURVE_SHAPE_MAX_PCT)
}

/// `PCT` as `(PCT, −PCT)` or `H,T` as `(H, T)`, each finite and within ±`max_pct`; the
/// message names `option`.
fn parse_pct_pair(option: &str, text: &str, max_pct: f64) -> Result<(f64, f64), String> {
    let one = |t: &str| in_range(option, t, (-max_pct, max_pct), " %");
    match text.split_once(',') {
        None => {
            let pct = one(text)?;
            Ok((pct, -pct))
        }
        Some((h, t)) if !t.contains(',') => Ok((one(h)?, one(t)?)),
        Some(_) => Err(format!(
            "{option} '{}': expected PCT or HEAD_PCT,TORQUE_PCT",
            shown(text)
        )),
    }
}

/// Parses `--water-inertia L` (mca·s²/l): 0, or finite within
/// [`INERTIA_MIN`]..=[`INERTIA_MAX`].
pub fn parse_water_inertia(text: &str) -> Result<f64, String> {
    zero_or_in_range(
        "--water-inertia",
        text,
        (INERTIA_MIN, INERTIA_MAX),
        " mca·s²/l",
    )
}

/// Parses `--rotor-inertia F` (× the paper's J): finite, within [`ROTOR_INERTIA_RANGE`].
pub fn parse_rotor_inertia(text: &str) -> Result<f64, String> {
    in_range(
        "--rotor-inertia",
        text,
        ROTOR_INERTIA_RANGE,
        " × the paper's",
    )
}

/// Parses a transmitter lag in ms (`option` names it in the message): finite, within
/// 0..=[`LAG_MAX_MS`]. Returns seconds.
pub fn parse_lag_ms(option: &str, text: &str) -> Result<f64, String> {
    // A division, so 40 ms is exactly the 0.040 s of the default.
    Ok(in_range(option, text, (0.0, LAG_MAX_MS), " ms")? / 1000.0)
}

/// The true bench for a curve error: the paper's parameters with every α (pump head F_H,
/// eq. 5) times (1 + head_pct/100) and every β (load torque F_T, eq. 6) times
/// (1 + torque_pct/100), then the α and β of the terms in Q ([`FLOW_TERMS`]) times
/// (1 + head_shape_pct/100) and (1 + torque_shape_pct/100), and its rotor's inertia J the
/// paper's times `rotor_inertia`. [`CurveError::NONE`] and 1 give the paper's bench exactly.
/// The message (one line) says why the parameters are refused.
pub fn true_bench(e: CurveError, rotor_inertia: f64) -> Result<WhiteBox<f64>, String> {
    let mut p = BenchParams::<f64>::paper();
    let head = 1.0 + e.head_pct / 100.0;
    let load = 1.0 + e.torque_pct / 100.0;
    p.alpha.iter_mut().for_each(|a| *a *= head);
    p.beta.iter_mut().for_each(|b| *b *= load);
    let (head_shape, load_shape) = (
        1.0 + e.head_shape_pct / 100.0,
        1.0 + e.torque_shape_pct / 100.0,
    );
    for i in FLOW_TERMS {
        p.alpha[i] *= head_shape;
        p.beta[i] *= load_shape;
    }
    p.inertia_kg_m2 *= rotor_inertia;
    WhiteBox::new(p).map_err(|err| {
        format!(
            "--curve-error {},{} --curve-shape {},{}: the pump-head and load-torque curves are \
             refused: {err}",
            Short(e.head_pct),
            Short(e.torque_pct),
            Short(e.head_shape_pct),
            Short(e.torque_shape_pct)
        )
    })
}

/// The bench with the dynamics the paper's model lacks ([`Dynamics`]): speed, flow (a state
/// when there is water inertia, else the flow balance's root) and the electromagnetic torque
/// the drive delivers (lagged when the drive has a lag), and the reference the drive acts on
/// (its ramp's output: the reference sent, without a ramp).
#[derive(Debug, Clone, Copy)]
struct Rich {
    speed_rpm: f64,
    flow_lps: f64,
    te_pct: f64,
    ramped_pct: f64,
}

/// Most RK4 sub-steps in one step of the rich bench (the flow's time constant sets them).
const RICH_MAX_SUBSTEPS: f64 = 1000.0;

impl Rich {
    /// At the white-box bench's (steady) `state` under the torque reference `u`, the drive
    /// delivering Te(u).
    fn at(bench: &WhiteBox<f64>, state: &BenchState<f64>, u: f64) -> Self {
        let s = bench.signals(state);
        Rich {
            speed_rpm: s.speed_rpm,
            flow_lps: s.flow_lps,
            te_pct: s.electromagnetic_torque_pct,
            ramped_pct: u,
        }
    }

    /// dω/dt (rpm/s) and dQ/dt (l/s², 0 without inertia) at speed `w`, flow `q`, delivered
    /// torque `te`.
    fn rates(bench: &WhiteBox<f64>, d: &Dynamics, w: f64, q: f64, te: f64) -> (f64, f64) {
        let p = bench.params();
        let dw = speed_derivative_rpm_per_s(
            te,
            load_torque_pct(&p.beta, w, q),
            bench.accel_rpm_per_s_per_pct(),
        );
        let dq = if d.water_inertia > 0.0 {
            bench.balance(w).eval(q) / d.water_inertia
        } else {
            0.0
        };
        (dw, dq)
    }

    /// Advances by `h` seconds with the torque reference `u` held: the drive's ramp (above),
    /// its lag exactly
    /// (its target Te(u) is constant over the step), speed and flow by RK4 in equal sub-steps,
    /// as many as keep a sub-step under half the flow's time constant `L / |∂g/∂Q|`. Without
    /// inertia the flow is the flow balance's root at each stage (as in the white-box bench).
    /// Its own RK4, not `WhiteBox::step`: the state here is speed *and* flow (the water
    /// column) with a drive torque that moves within the step, which the white-box's one-state
    /// step with the torque held does not integrate; it calls the same equations.
    fn advance(&mut self, bench: &WhiteBox<f64>, d: &Dynamics, u: f64, h: f64) {
        // The drive's ramp: a step of at most the rate × h toward the reference sent, at
        // the step's start (none: the reference itself, to the bit).
        let u = if d.drive_slew_pct_s > 0.0 {
            let most = d.drive_slew_pct_s * h;
            self.ramped_pct + (u - self.ramped_pct).clamp(-most, most)
        } else {
            u
        };
        self.ramped_pct = u;
        let target = electromagnetic_torque_pct(&bench.params().gamma, u);
        let te0 = self.te_pct;
        let te_at = |t: f64| lag_to(te0, target, t, d.drive_lag_s);
        let n = if d.water_inertia > 0.0 {
            let slope = bench.balance(self.speed_rpm).slope(self.flow_lps).abs();
            (h * slope / d.water_inertia / 0.5)
                .ceil()
                .clamp(1.0, RICH_MAX_SUBSTEPS)
        } else {
            1.0
        };
        let hs = h / n;
        let inertial = d.water_inertia > 0.0;
        let flow = |w: f64, q: f64| if inertial { q } else { bench.flow_at(w, q) };
        for k in 0..n as u32 {
            let t0 = f64::from(k) * hs;
            let (w, q) = (self.speed_rpm, self.flow_lps);
            let f = |w: f64, q: f64, t: f64| {
                let q = flow(w.max(0.0), q);
                let (dw, dq) = Self::rates(bench, d, w.max(0.0), q, te_at(t));
                (dw, dq, q)
            };
            let (k1w, k1q, q1) = f(w, q, t0);
            let (k2w, k2q, q2) = f(w + hs / 2.0 * k1w, q1 + hs / 2.0 * k1q, t0 + hs / 2.0);
            let (k3w, k3q, q3) = f(w + hs / 2.0 * k2w, q2 + hs / 2.0 * k2q, t0 + hs / 2.0);
            let (k4w, k4q, _) = f(w + hs * k3w, q3 + hs * k3q, t0 + hs);
            self.speed_rpm = (w + hs / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)).max(0.0);
            let q_end = q1 + hs / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q);
            // No backflow: the pump's check valve.
            self.flow_lps = flow(self.speed_rpm, q_end).max(0.0);
        }
        self.te_pct = te_at(h);
    }
}

/// The plant's options: how it differs from the paper's model, its transmitters, its noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantOptions {
    /// Seed of the noise.
    pub seed: u64,
    /// Curve error (see [`true_bench`]).
    pub curve_error: CurveError,
    /// Water inertia and drive lag.
    pub dynamics: Dynamics,
    /// The rotor's inertia (motor, coupling, impeller: J of eq. 3), × the paper's
    /// ([`ROTOR_INERTIA_RANGE`]; 1: the paper's); the white-box bench carries it.
    pub rotor_inertia: f64,
    /// Flow transmitter lag, s.
    pub flow_lag_s: f64,
    /// Pressure transmitter lag, s.
    pub pressure_lag_s: f64,
    /// The pressure transmitter's noise, mca (1 σ; [`PRESSURE`]'s 0.003 by default).
    pub pressure_noise_mca: f64,
    /// The drive's speed reading's first-order lag, s (0: the rotor's speed as it is; a
    /// drive's filtered speed estimate lags it).
    pub speed_lag_s: f64,
    /// The flow meter's update period, s (0: every step): between updates its output holds
    /// the last (lagged) value, as a meter that computes its flow over a window, or is read
    /// over a bus, does.
    pub flow_update_s: f64,
    /// The system curve's pressure at no flow, mca ([`STATIC_HEAD_RANGE_MCA`]): `−c` of eq.
    /// (8), the paper's −0.252; a lift (the outlet above the suction's level) is positive.
    /// Under it the pump moves no water and the transmitter reads it (a check valve holds
    /// the column).
    pub static_head_mca: f64,
    /// A transport delay ahead of the pressure and flow transmitters' lags, s (0: none; at
    /// most [`DELAY_MAX_MS`]): each transmitter's lag follows the true value of this long
    /// ago, at the plant's steps' resolution (≤ 1 ms). The drive's readings are not delayed.
    pub transmitter_delay_s: f64,
}

/// `--static-head`'s range, mca: from the paper's bench's side (the transmitter above the
/// tank's level) to a lift of 5 mca (the pump gives ≈ 11 mca of head at no flow at
/// 1 000 rpm, 32 at its nominal 1 749).
pub const STATIC_HEAD_RANGE_MCA: (f64, f64) = (-1.0, 5.0);

/// Parses `--static-head MCA`: finite, within [`STATIC_HEAD_RANGE_MCA`].
pub fn parse_static_head(text: &str) -> Result<f64, String> {
    in_range("--static-head", text, STATIC_HEAD_RANGE_MCA, " mca")
}

impl PlantOptions {
    /// The paper's bench, the default transmitter lags ([`PRESSURE`], [`FLOW`]), noise seed
    /// `seed`.
    pub fn with_seed(seed: u64) -> Self {
        PlantOptions {
            seed,
            curve_error: CurveError::NONE,
            dynamics: Dynamics::NONE,
            rotor_inertia: 1.0,
            flow_lag_s: FLOW.tau_s,
            pressure_lag_s: PRESSURE.tau_s,
            pressure_noise_mca: PRESSURE.noise,
            speed_lag_s: SPEED.tau_s,
            flow_update_s: 0.0,
            static_head_mca: -PAPER_C_MCA,
            transmitter_delay_s: 0.0,
        }
    }
}

/// Why the plant cannot go on.
#[derive(Debug, Clone, PartialEq)]
pub enum PlantError {
    /// Its options are refused (a bad command line: the message names the option).
    Options(String),
    /// The white-box model refused a step or a state (its message).
    Model(String),
    /// Speed or flow became NaN or infinite.
    Diverged,
}

impl std::fmt::Display for PlantError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlantError::Options(m) => write!(f, "{m}"),
            PlantError::Model(m) => write!(f, "model: {m}"),
            PlantError::Diverged => write!(f, "model: the bench diverged"),
        }
    }
}

/// The plant's true state now (no lag, no noise, no quantisation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Speed, rpm.
    pub speed_rpm: f64,
    /// Flow, l/s.
    pub flow_lps: f64,
    /// Outlet pressure, mca.
    pub pressure_mca: f64,
    /// Valve coefficient k2, √mca/(l/s).
    pub valve_k2: f64,
    /// Electromagnetic torque the drive delivers, % of nominal.
    pub torque_pct: f64,
}

/// Which of the plant's signals reach the controller ([`Plant::frame`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorState {
    /// The pressure transmitter works (else its loop reads [`FAULT_MA`]).
    pub pressure_meter: bool,
    /// The flow transmitter works (else its loop reads [`FAULT_MA`]).
    pub flow_meter: bool,
    /// The VFD link is up (else the frame has no drive readings).
    pub link: bool,
    /// The drive reports its speed (else its speed reading is stuck at 0 rpm: a drive whose
    /// speed register is not mapped, or a plant that sends none; its torque still read).
    pub speed_reading: bool,
}

impl SensorState {
    /// Everything works.
    pub const OK: Self = Self {
        pressure_meter: true,
        flow_meter: true,
        link: true,
        speed_reading: true,
    };
}

/// The physical bench, stepped by its caller: the white-box bench (with the [`Dynamics`] when
/// there are any), the transmitters' lags, their noise and ADCs.
#[derive(Debug, Clone)]
pub struct Plant {
    bench: WhiteBox<f64>,
    nominal_k2: f64,
    static_head_c_mca: f64,
    state: BenchState<f64>,
    /// With inertia or a drive lag the rich bench carries the state; without, the white-box
    /// bench alone.
    rich: Option<Rich>,
    dynamics: Dynamics,
    pressure: Transmitter,
    flow: Transmitter,
    speed: Transmitter,
    /// The transmitters' lagged values: speed, flow, pressure.
    seen: (f64, f64, f64),
    /// The flow meter's update period, s (0: every step), the value it shows and the time
    /// since it last updated it, s.
    flow_update_s: f64,
    flow_shown: f64,
    flow_age_s: f64,
    /// The transport delay ahead of the pressure and flow transmitters, s (0: none), the
    /// plant's time, s, and the true (time, flow, pressure) since the delay's start: the
    /// first entry is the latest at least the delay old (the start's at −∞).
    delay_s: f64,
    t_s: f64,
    history: VecDeque<(f64, f64, f64)>,
    rng: SplitMix64,
    sensors: SensorState,
}

impl Plant {
    /// The plant of `o` with its valve at `valve_factor` times the paper's k2, at the steady
    /// state of the torque reference `torque_ref_pct` (0..=100 %), the transmitters settled
    /// there, all sensors working.
    pub fn new(
        o: &PlantOptions,
        valve_factor: f64,
        torque_ref_pct: f64,
    ) -> Result<Self, PlantError> {
        let bench = true_bench(o.curve_error, o.rotor_inertia).map_err(PlantError::Options)?;
        let nominal_k2 = bench.params().valve_k2;
        // (−(−c) is c to the bit: the paper's plant as before.)
        let static_head_c_mca = -o.static_head_mca;
        let mut plant = Plant {
            bench,
            nominal_k2,
            static_head_c_mca,
            state: BenchState::at_rest(),
            rich: None,
            dynamics: o.dynamics,
            pressure: Transmitter {
                tau_s: o.pressure_lag_s,
                noise: o.pressure_noise_mca,
                ..PRESSURE
            },
            flow: Transmitter {
                tau_s: o.flow_lag_s,
                ..FLOW
            },
            speed: Transmitter {
                tau_s: o.speed_lag_s,
                ..SPEED
            },
            seen: (0.0, 0.0, 0.0),
            flow_update_s: o.flow_update_s,
            flow_shown: 0.0,
            flow_age_s: 0.0,
            delay_s: o.transmitter_delay_s,
            t_s: 0.0,
            history: VecDeque::new(),
            rng: SplitMix64::new(o.seed),
            sensors: SensorState::OK,
        };
        plant.set_valve_factor(valve_factor)?;
        plant.state = plant
            .bench
            .steady_state(torque_ref_pct)
            .map_err(|e| PlantError::Model(e.to_string()))?;
        plant.rich = (o.dynamics != Dynamics::NONE)
            .then(|| Rich::at(&plant.bench, &plant.state, torque_ref_pct));
        plant.seen = plant.now();
        plant.flow_shown = plant.seen.1;
        plant
            .history
            .push_back((f64::NEG_INFINITY, plant.seen.1, plant.seen.2));
        Ok(plant)
    }

    /// Sets the valve: k2 is `factor` ([`VALVE_FACTOR_MIN`]..=[`VALVE_FACTOR_MAX`]) times the
    /// paper's, the static head unchanged. The flow and pressure change at once (with water
    /// inertia the flow follows through it); the readings through their lags.
    pub fn set_valve_factor(&mut self, factor: f64) -> Result<(), PlantError> {
        if !(VALVE_FACTOR_MIN..=VALVE_FACTOR_MAX).contains(&factor) {
            return Err(PlantError::Options(format!(
                "valve factor {} is outside {}..{}",
                Short(factor),
                Short(VALVE_FACTOR_MIN),
                Short(VALVE_FACTOR_MAX)
            )));
        }
        self.bench
            .set_load(self.nominal_k2 * factor, self.static_head_c_mca)
            .map_err(|e| PlantError::Model(e.to_string()))
    }

    /// Sets which signals reach the controller from now on.
    pub fn set_sensors(&mut self, s: SensorState) {
        self.sensors = s;
    }

    /// Speed, flow and pressure now.
    fn now(&self) -> (f64, f64, f64) {
        match &self.rich {
            Some(r) => {
                let par = self.bench.params();
                let q = r.flow_lps;
                (
                    r.speed_rpm,
                    q,
                    valve_pressure_mca(par.valve_k2, par.static_head_c_mca, q),
                )
            }
            None => {
                let sig = self.bench.signals(&self.state);
                (sig.speed_rpm, sig.flow_lps, sig.pressure_mca)
            }
        }
    }

    /// Advances by `h_s` seconds (at most [`STEP_MS`]) with the torque reference
    /// `torque_ref_pct` (0..=100 %) held: one RK4 step of the bench, then the transmitters'
    /// lags.
    pub fn advance(&mut self, torque_ref_pct: f64, h_s: f64) -> Result<(), PlantError> {
        match self.rich.as_mut() {
            Some(r) => r.advance(&self.bench, &self.dynamics, torque_ref_pct, h_s),
            // One step of h (h <= 1 ms < MAX_STEP_S), also below model-core's 1 µs
            // smallest step, as `simulate` integrates a short interval.
            None => {
                self.bench
                    .advance(
                        &mut self.state,
                        torque_ref_pct,
                        h_s,
                        MAX_STEP_S,
                        Scheme::Rk4,
                    )
                    .map_err(|e| PlantError::Model(e.to_string()))?;
            }
        }
        let (w_now, q_now, p_now) = self.now();
        if !(w_now.is_finite() && q_now.is_finite()) {
            return Err(PlantError::Diverged);
        }
        let (q_in, p_in) = self.delayed(q_now, p_now, h_s);
        let (s, q, p) = &mut self.seen;
        self.pressure.lag(p, p_in, h_s);
        self.flow.lag(q, q_in, h_s);
        self.speed.lag(s, w_now, h_s);
        // The meter's output: the lagged flow now, or at its last update (a step's rounding
        // of 1e-9 s: 200 steps of 1 ms are one 0.2 s period).
        self.flow_age_s += h_s;
        if self.flow_age_s + 1e-9 >= self.flow_update_s {
            self.flow_age_s = if self.flow_update_s > 0.0 {
                (self.flow_age_s - self.flow_update_s).max(0.0)
            } else {
                0.0
            };
            self.flow_shown = *q;
        }
        Ok(())
    }

    /// The flow and pressure the transmitters' lags follow after a step of `h_s` that ends at
    /// `q_now`, `p_now`: those values themselves without a delay, else the latest true
    /// values at least the delay old.
    fn delayed(&mut self, q_now: f64, p_now: f64, h_s: f64) -> (f64, f64) {
        if self.delay_s <= 0.0 {
            return (q_now, p_now);
        }
        self.t_s += h_s;
        self.history.push_back((self.t_s, q_now, p_now));
        // (1e-9 s: a step's rounding, as the flow meter's update.)
        let due = self.t_s - self.delay_s + 1e-9;
        while self.history.get(1).is_some_and(|&(t, _, _)| t <= due) {
            self.history.pop_front();
        }
        // (Never empty: the start's entry stays until a later one is due.)
        self.history
            .front()
            .map_or((q_now, p_now), |&(_, q, p)| (q, p))
    }

    /// The logged readings now (speed rpm, flow l/s, pressure mca): each transmitter's lagged
    /// value with its noise, through its ADC and read back on its span's line (not clamped to
    /// the span, as a logger records it). Three draws of the noise, in that order.
    pub fn readings(&mut self) -> (f64, f64, f64) {
        let (s, _, p) = self.seen;
        let q = self.flow_shown;
        (
            self.speed.read(s, &mut self.rng),
            self.flow.read(q, &mut self.rng),
            self.pressure.read(p, &mut self.rng),
        )
    }

    /// What the controller sees now: the pressure and flow transmitters' ADC codes (the
    /// lagged values with their noise; [`FAULT_MA`]'s code for a failed transmitter) and the
    /// drive's readings (speed with the speed channel's noise, the electromagnetic torque it
    /// delivers, status 0), `None` while the link is cut. The same three draws of the noise
    /// as [`Self::readings`], whatever the sensors' state.
    pub fn frame(&mut self) -> PlantFrame {
        let (s, _, p) = self.seen;
        let q = self.flow_shown;
        let speed = self.speed.noisy(s, &mut self.rng);
        let flow = self.flow.noisy(q, &mut self.rng);
        let pressure = self.pressure.noisy(p, &mut self.rng);
        let code = |l: &LoopConfig, ok: bool, v: f64| {
            if ok {
                adc_code(l, v)
            } else {
                l.code(FAULT_MA)
            }
        };
        let torque_pct = self.truth().torque_pct;
        PlantFrame {
            pressure_code: code(&PRESSURE_LOOP, self.sensors.pressure_meter, pressure),
            flow_code: code(&FLOW_LOOP, self.sensors.flow_meter, flow),
            drive: self.sensors.link.then_some(VfdReadings {
                speed_rpm: if self.sensors.speed_reading {
                    speed as f32
                } else {
                    0.0
                },
                torque_pct: torque_pct as f32,
                status: 0,
            }),
        }
    }

    /// The true state now.
    pub fn truth(&self) -> Truth {
        let (speed_rpm, flow_lps, pressure_mca) = self.now();
        let torque_pct = match &self.rich {
            Some(r) => r.te_pct,
            None => self.bench.signals(&self.state).electromagnetic_torque_pct,
        };
        Truth {
            speed_rpm,
            flow_lps,
            pressure_mca,
            valve_k2: self.bench.params().valve_k2,
            torque_pct,
        }
    }

    /// The true bench's parameters now (its curves and its valve).
    pub fn params(&self) -> &BenchParams<f64> {
        self.bench.params()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model_core::equations::pump_head_mca;

    #[test]
    fn quantisation_step_and_noise_level() {
        let mut rng = SplitMix64::new(1);
        let quiet = Transmitter {
            noise: 0.0,
            ..PRESSURE
        };
        let a = quiet.read(2.0, &mut rng);
        // One code of the shared front end (22 mA over 4095 codes) on the 0..10 mca span.
        let l = PRESSURE_LOOP;
        let lsb = f64::from(l.current_ma(1)) * 10.0 / 16.0;
        assert!((lsb - 0.00336).abs() < 1e-5, "{lsb}");
        assert!((a - 2.0).abs() <= lsb / 2.0 + 1e-6, "{a}");
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| FLOW.read(15.0, &mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        // 0.02 l/s of noise and a code's 0.010 l/s of quantisation (uniform: 0.0029 l/s).
        assert!(
            (mean - 15.0).abs() < 0.01 && (sd - 0.0202).abs() < 0.004,
            "{mean} {sd}"
        );
        // Below and above the span the transmitter saturates at NE 43's measuring range.
        let below = quiet.read(-5.0, &mut rng);
        let above = quiet.read(50.0, &mut rng);
        assert!((below + 0.125).abs() <= lsb, "{below}");
        assert!((above - 10.3125).abs() <= lsb, "{above}");
    }

    #[test]
    fn default_options_are_the_paper_bench_and_the_old_lags_exactly() {
        // The defaults of the command line give the constants bit for bit.
        let flow = parse_lag_ms("--flow-lag-ms", "40").unwrap();
        let pressure = parse_lag_ms("--pressure-lag-ms", "20").unwrap();
        assert_eq!(flow.to_bits(), FLOW.tau_s.to_bits());
        assert_eq!(pressure.to_bits(), PRESSURE.tau_s.to_bits());
        let zero = parse_curve_error("0").unwrap();
        assert_eq!((zero.head_pct, zero.torque_pct), (0.0, 0.0));
        let o = PlantOptions::with_seed(3);
        assert_eq!((o.flow_lag_s, o.pressure_lag_s), (flow, pressure));
        assert_eq!(o.dynamics, Dynamics::NONE);
        assert_eq!(parse_water_inertia("0").unwrap(), 0.0);
        assert_eq!(parse_lag_ms("--drive-lag-ms", "0").unwrap(), 0.0);
        assert_eq!(true_bench(zero, 1.0).unwrap(), WhiteBox::<f64>::paper());
        assert_eq!(
            true_bench(parse_curve_error("-0").unwrap(), 1.0).unwrap(),
            WhiteBox::<f64>::paper()
        );
    }

    #[test]
    fn curve_shape_scales_the_terms_in_the_flow_only() {
        let paper = WhiteBox::<f64>::paper();
        let (h, t) = parse_curve_shape("30,-40").unwrap();
        let e = CurveError {
            head_shape_pct: h,
            torque_shape_pct: t,
            ..parse_curve_error("5").unwrap()
        };
        let b = true_bench(e, 1.0).unwrap();
        let (p, p0) = (b.params(), paper.params());
        for i in 0..10 {
            let flow_term = FLOW_TERMS.contains(&i);
            let (a, x) = if flow_term { (1.3, 0.6) } else { (1.0, 1.0) };
            assert_eq!(p.alpha[i], p0.alpha[i] * 1.05 * a, "alpha {i}");
            assert_eq!(p.beta[i], p0.beta[i] * 0.95 * x, "beta {i}");
        }
        // At no flow the curves are the scaled paper's; with flow, of another shape: the
        // head at 1 700 rpm falls faster from 8 to 15 l/s than the scaled paper's does.
        let head = |p: &BenchParams<f64>, q| pump_head_mca(&p.alpha, 1700.0, q);
        assert!((head(p, 0.0) / head(p0, 0.0) - 1.05).abs() < 1e-12);
        let ratio = |q| head(p, q) / head(p0, q) / 1.05;
        assert!(ratio(8.0) < 0.99 && ratio(15.0) < ratio(8.0) - 0.01);
        // The default is the paper's bench, bit for bit; the bounds and the form are checked.
        assert_eq!(parse_curve_shape("0").unwrap(), (0.0, -0.0));
        assert_eq!(parse_curve_shape("50,-50").unwrap(), (50.0, -50.0));
        for text in ["51", "1,-50.5", "x", "1,2,3", ""] {
            let e = parse_curve_shape(text).unwrap_err();
            assert!(e.starts_with("--curve-shape"), "{e}");
        }
        let zero = CurveError {
            head_shape_pct: 0.0,
            torque_shape_pct: -0.0,
            ..CurveError::NONE
        };
        assert_eq!(true_bench(zero, 1.0).unwrap(), paper);
    }

    #[test]
    fn curve_error_scales_every_alpha_up_and_every_beta_down() {
        let paper = BenchParams::<f64>::paper();
        let b = true_bench(parse_curve_error("5").unwrap(), 1.0).unwrap();
        let p = b.params();
        for (a, a0) in p.alpha.iter().zip(&paper.alpha) {
            assert_eq!(*a, a0 * 1.05);
        }
        for (x, x0) in p.beta.iter().zip(&paper.beta) {
            assert_eq!(*x, x0 * 0.95);
        }
        assert_eq!(
            (p.gamma, p.pipe_k1, p.valve_k2, p.static_head_c_mca),
            (
                paper.gamma,
                paper.pipe_k1,
                paper.valve_k2,
                paper.static_head_c_mca
            )
        );
        // Parameters the model refuses are a one-line message naming the option.
        // The two curves apart: 8 % more head and 8 % more load torque.
        let p = true_bench(parse_curve_error("8,8").unwrap(), 1.0).unwrap();
        assert_eq!(p.params().alpha[0], paper.alpha[0] * 1.08);
        assert_eq!(p.params().beta[0], paper.beta[0] * 1.08);
        for text in ["1,2,3", "x,1", "1,30", ""] {
            let e = parse_curve_error(text).unwrap_err();
            assert!(e.starts_with("--curve-error"), "{e}");
        }
        for pct in [f64::NAN, -100.0] {
            let e = true_bench(
                CurveError {
                    head_pct: pct,
                    torque_pct: -pct,
                    ..CurveError::NONE
                },
                1.0,
            )
            .unwrap_err();
            assert!(
                e.starts_with("--curve-error ") && e.contains("refused"),
                "{e}"
            );
            assert_eq!(e.lines().count(), 1);
        }
    }

    #[test]
    fn lag_is_first_order() {
        let mut x = 0.0;
        for _ in 0..20 {
            PRESSURE.lag(&mut x, 1.0, 1e-3);
        }
        assert!((x - (1.0 - (-1.0f64).exp())).abs() < 1e-12);
    }

    /// At its steady state the plant stays there; a frame's codes read back (with the
    /// controller's loop model) give the readings `bench-data` logs from the same noise draws.
    #[test]
    fn frames_carry_the_logged_readings_as_codes() {
        let o = PlantOptions::with_seed(4);
        let mut a = Plant::new(&o, 1.2, 55.0).unwrap();
        let mut b = a.clone();
        let start = a.truth();
        for _ in 0..500 {
            a.advance(55.0, 1e-3).unwrap();
            b.advance(55.0, 1e-3).unwrap();
        }
        let t = a.truth();
        assert!(
            (t.speed_rpm - start.speed_rpm).abs() < 1e-6,
            "{t:?} vs {start:?}"
        );
        assert!((t.valve_k2 - 1.2 * BenchParams::<f64>::paper().valve_k2).abs() < 1e-15);
        for _ in 0..20 {
            let (speed, flow, pressure) = a.readings();
            let f = b.frame();
            let back = |l: &LoopConfig, code: u16| f64::from(l.value_unclamped(l.current_ma(code)));
            assert_eq!(back(&PRESSURE_LOOP, f.pressure_code), pressure);
            assert_eq!(back(&FLOW_LOOP, f.flow_code), flow);
            let d = f.drive.unwrap();
            assert_eq!(f64::from(d.speed_rpm), speed as f32 as f64);
            assert_eq!(f64::from(d.torque_pct), t.torque_pct as f32 as f64);
            assert_eq!(d.status, 0);
            // Within the noise's bound (3.46 σ) and a code of the truth.
            assert!((pressure - t.pressure_mca).abs() < 3.5 * PRESSURE.noise + 0.0035);
            assert!((flow - t.flow_lps).abs() < 3.5 * FLOW.noise + 0.011);
        }
    }

    /// A failed transmitter reads 2 mA (an NE 43 fault for the controller's input), a cut link
    /// gives no drive readings; the noise draws go on as they would (the other signals are
    /// what they would have been).
    #[test]
    fn failed_sensors_and_a_cut_link_show_in_the_frame() {
        let o = PlantOptions::with_seed(9);
        let mut a = Plant::new(&o, 1.0, 40.0).unwrap();
        let mut b = a.clone();
        b.set_sensors(SensorState {
            flow_meter: false,
            link: false,
            ..SensorState::OK
        });
        let (fa, fb) = (a.frame(), b.frame());
        assert_eq!(fb.flow_code, FLOW_LOOP.code(FAULT_MA));
        assert!(FLOW_LOOP.current_ma(fb.flow_code) < model_core::transmitter::FAULT_LOW_MA);
        assert_eq!(fb.pressure_code, fa.pressure_code);
        assert!(fa.drive.is_some() && fb.drive.is_none());
        b.set_sensors(SensorState {
            pressure_meter: false,
            ..SensorState::OK
        });
        let (fa, fb) = (a.frame(), b.frame());
        assert_eq!(fb.pressure_code, PRESSURE_LOOP.code(FAULT_MA));
        assert_eq!((fb.flow_code, fb.drive), (fa.flow_code, fa.drive));
    }

    #[test]
    fn valve_factors_outside_the_range_are_refused() {
        let mut p = Plant::new(&PlantOptions::with_seed(1), 1.0, 30.0).unwrap();
        for bad in [0.1, 5.5, f64::NAN, f64::INFINITY] {
            assert!(
                matches!(p.set_valve_factor(bad), Err(PlantError::Options(_))),
                "{bad}"
            );
        }
        let k2 = p.truth().valve_k2;
        assert!(p.set_valve_factor(0.2).is_ok() && p.set_valve_factor(5.0).is_ok());
        assert_eq!(p.truth().valve_k2, 5.0 * k2);
        assert!(matches!(
            Plant::new(&PlantOptions::with_seed(1), 1.0, 120.0),
            Err(PlantError::Model(_))
        ));
    }

    /// With a drive lag the delivered torque (the drive's reading) follows a torque step
    /// through the lag: 63 % of the way after one time constant.
    #[test]
    fn the_drive_reading_follows_its_lag() {
        let o = PlantOptions {
            dynamics: Dynamics {
                water_inertia: 0.0,
                drive_lag_s: 0.05,
                drive_slew_pct_s: 0.0,
            },
            ..PlantOptions::with_seed(1)
        };
        let gamma = BenchParams::<f64>::paper().gamma;
        let (te0, te1) = (
            electromagnetic_torque_pct(&gamma, 30.0),
            electromagnetic_torque_pct(&gamma, 60.0),
        );
        let mut p = Plant::new(&o, 1.0, 30.0).unwrap();
        assert!((p.truth().torque_pct - te0).abs() < 1e-9);
        for _ in 0..50 {
            p.advance(60.0, 1e-3).unwrap();
        }
        let frac = (p.truth().torque_pct - te0) / (te1 - te0);
        assert!((frac - (1.0 - (-1.0f64).exp())).abs() < 1e-9, "{frac}");
        let d = p.frame().drive.unwrap();
        assert_eq!(d.torque_pct, p.truth().torque_pct as f32);
    }

    /// A flow meter updating every 20 ms shows the lagged flow of its last update: its
    /// readings change once in 20 steps of 1 ms while the flow moves, and at each update
    /// equal the continuous meter's of the same plant (same lag, same noise draws).
    #[test]
    fn a_flow_meter_updating_every_period_holds_its_reading_between() {
        let o = PlantOptions::with_seed(1);
        let held = PlantOptions {
            flow_update_s: 0.02,
            ..o
        };
        let (mut a, mut b) = (
            Plant::new(&o, 1.0, 30.0).unwrap(),
            Plant::new(&held, 1.0, 30.0).unwrap(),
        );
        let (mut changes, mut last) = (0, b.seen.1);
        for k in 1..=200 {
            a.advance(90.0, 1e-3).unwrap();
            b.advance(90.0, 1e-3).unwrap();
            assert_eq!(a.seen, b.seen, "the lagged values are the same");
            if b.flow_shown != last {
                changes += 1;
                last = b.flow_shown;
                assert_eq!(k % 20, 0, "an update at step {k}");
                assert_eq!(b.flow_shown, a.flow_shown);
            }
        }
        assert_eq!(changes, 10);
    }

    /// With a speed reading lag the drive's speed reading follows a speed step through it:
    /// 63 % of the way after one time constant (noise aside); without, the speed as it is.
    #[test]
    fn the_speed_reading_follows_its_lag() {
        for lag in [0.0, 0.05] {
            let o = PlantOptions {
                speed_lag_s: lag,
                ..PlantOptions::with_seed(1)
            };
            let mut p = Plant::new(&o, 1.0, 30.0).unwrap();
            let w0 = p.truth().speed_rpm;
            let mut seen = vec![];
            for _ in 0..50 {
                p.advance(90.0, 1e-3).unwrap();
                seen.push(p.truth().speed_rpm);
            }
            // The lag integrated over the true speed's path, as the plant steps it.
            let mut want = w0;
            for w in &seen {
                want += (w - want)
                    * if lag > 0.0 {
                        1.0 - (-1e-3 / lag).exp()
                    } else {
                        1.0
                    };
            }
            let got = f64::from(p.frame().drive.unwrap().speed_rpm);
            // Within the speed channel's noise (a sum of four uniform draws: ≤ 4 × 0.5 × √3).
            assert!((got - want).abs() < 3.5, "lag {lag}: {got} vs {want}");
            let rise = p.truth().speed_rpm - w0;
            assert!(rise > 100.0, "{rise}");
            if lag > 0.0 {
                assert!(want < p.truth().speed_rpm - 0.2 * rise, "{want}");
            }
        }
    }

    /// A rotor of `f` × the paper's inertia: the same steady state, and the speed's first
    /// response to a torque step `1 / f` of the paper's (the surplus is the same at the
    /// start); with a drive lag and a water column too. Out of its range, refused.
    #[test]
    fn the_rotor_inertia_scales_the_speed_response() {
        for (water, drive) in [(0.0, 0.0), (0.1, 0.03)] {
            let first_rise = |f: f64| {
                let o = PlantOptions {
                    dynamics: Dynamics {
                        water_inertia: water,
                        drive_lag_s: drive,
                        drive_slew_pct_s: 0.0,
                    },
                    rotor_inertia: f,
                    ..PlantOptions::with_seed(1)
                };
                let mut p = Plant::new(&o, 1.0, 40.0).unwrap();
                let w0 = p.truth().speed_rpm;
                p.advance(60.0, 1e-3).unwrap();
                (w0, p.truth().speed_rpm - w0)
            };
            let (w1, r1) = first_rise(1.0);
            for f in [0.5, 2.0, 4.0] {
                let (w, r) = first_rise(f);
                assert_eq!(w, w1, "{f}: the steady state");
                assert!((r * f / r1 - 1.0).abs() < 0.01, "{f}: {r} against {r1}");
            }
        }
        assert_eq!(parse_rotor_inertia("1").unwrap(), 1.0);
        for bad in ["0.2", "4.5", "nan", "-1", "x"] {
            let e = parse_rotor_inertia(bad).unwrap_err();
            assert!(e.starts_with("--rotor-inertia"), "{e}");
        }
    }

    /// A transport delay ahead of the transmitters: after a valve step the lagged pressure
    /// and flow the transmitters show are, step for step, those of the plant without the
    /// delay the delay earlier (the same noise draws); before the step's delay has passed
    /// they have not moved. The drive's readings are not delayed. 0 is no delay, to the bit.
    #[test]
    fn a_transport_delay_shifts_the_transmitters_by_it() {
        let o = PlantOptions {
            pressure_lag_s: 0.03,
            ..PlantOptions::with_seed(3)
        };
        let delayed = PlantOptions {
            transmitter_delay_s: 0.025,
            ..o
        };
        let (mut a, mut b) = (
            Plant::new(&o, 1.0, 40.0).unwrap(),
            Plant::new(&delayed, 1.0, 40.0).unwrap(),
        );
        let before = b.seen;
        a.set_valve_factor(1.3).unwrap();
        b.set_valve_factor(1.3).unwrap();
        let (mut sa, mut sb) = (vec![], vec![]);
        for _ in 0..100 {
            a.advance(40.0, 1e-3).unwrap();
            b.advance(40.0, 1e-3).unwrap();
            sa.push(a.seen);
            sb.push(b.seen);
            assert_eq!(a.truth(), b.truth(), "the plant itself is the same");
        }
        for (k, seen) in sb.iter().enumerate().take(25) {
            assert_eq!((seen.1, seen.2), (before.1, before.2), "step {k}");
        }
        // Step 25 + k follows the values of step k, through the same lags: with the torque
        // held the plant's pressure after the valve is steady, so the delayed lag is the
        // undelayed one 25 steps late (to rounding).
        for k in 0..75 {
            assert!(
                (sb[k + 25].2 - sa[k].2).abs() < 1e-9,
                "{k}: {:?} {:?}",
                sb[k + 25],
                sa[k]
            );
            assert!((sb[k + 25].1 - sa[k].1).abs() < 1e-9, "{k}");
        }
        assert!(
            (sa[10].2 - before.2).abs() > 0.1,
            "the valve moved the pressure"
        );
        assert_eq!(
            sa.last().unwrap().0,
            sb.last().unwrap().0,
            "the speed is not delayed"
        );
        // No delay: the plant as it was, to the bit.
        let zero = PlantOptions {
            transmitter_delay_s: 0.0,
            ..o
        };
        let mut c = Plant::new(&zero, 1.0, 40.0).unwrap();
        c.set_valve_factor(1.3).unwrap();
        for seen in &sa {
            c.advance(40.0, 1e-3).unwrap();
            assert_eq!(c.seen, *seen);
        }
    }

    /// A drive ramping at 100 %/s delivers Te of its ramped reference: after 0.1 s of a
    /// 30 → 60 % step the reference it acts on is 40 %, after 0.3 s 60 %; down alike. 0 is
    /// no ramp: the plant as it was, to the bit. Out of its range, refused.
    #[test]
    fn the_drives_ramp_limits_the_reference_it_acts_on() {
        let gamma = BenchParams::<f64>::paper().gamma;
        let ramp = |slew: f64| PlantOptions {
            dynamics: Dynamics {
                drive_slew_pct_s: slew,
                ..Dynamics::NONE
            },
            ..PlantOptions::with_seed(1)
        };
        let mut p = Plant::new(&ramp(100.0), 1.0, 30.0).unwrap();
        for _ in 0..100 {
            p.advance(60.0, 1e-3).unwrap();
        }
        let te = |u: f64| electromagnetic_torque_pct(&gamma, u);
        assert!(
            (p.truth().torque_pct - te(40.0)).abs() < 1e-6,
            "{:?}",
            p.truth()
        );
        for _ in 0..250 {
            p.advance(60.0, 1e-3).unwrap();
        }
        assert!((p.truth().torque_pct - te(60.0)).abs() < 1e-9);
        for _ in 0..50 {
            p.advance(0.0, 1e-3).unwrap();
        }
        assert!((p.truth().torque_pct - te(55.0)).abs() < 1e-6);
        // None: the same steps as the paper's dynamics, whose torque is Te(u) at once.
        let (mut a, mut b) = (
            Plant::new(&ramp(0.0), 1.0, 30.0).unwrap(),
            Plant::new(&PlantOptions::with_seed(1), 1.0, 30.0).unwrap(),
        );
        for _ in 0..50 {
            a.advance(60.0, 1e-3).unwrap();
            b.advance(60.0, 1e-3).unwrap();
        }
        assert_eq!(a.truth(), b.truth());
        assert_eq!(a.seen, b.seen);
        for bad in ["5", "-20", "1e6", "nan", "x"] {
            let e = parse_drive_slew(bad).unwrap_err();
            assert!(
                e.starts_with("--drive-slew-pct-s") && !e.contains('\n'),
                "{e}"
            );
        }
        assert_eq!(parse_drive_slew("0"), Ok(0.0));
        assert_eq!(parse_delay_ms("25"), Ok(0.025));
        assert!(parse_delay_ms("1001").is_err() && parse_delay_ms("-1").is_err());
    }
}
