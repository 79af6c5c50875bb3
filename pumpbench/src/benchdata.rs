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
//! The bench itself is the paper's white-box model in f64, integrated with RK4 at ≤ 1 ms.
//!
//! Two dynamics the paper's model lacks can be added ([`Dynamics`]; both 0 by default, and
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
//! - `--truth` adds the bench's true state at each row's time (before lag, noise and
//!   quantisation): `speed_true` (rpm), `flow_true` (l/s), `pressure_true` (mca) and
//!   `k2_true` (√mca/(l/s)).
//!
//! With none of these (or all at their defaults) the record is byte for byte what it was
//! before they existed.

use crate::error::Failure;
use crate::input::{shown, TorqueInput};
use crate::num::Short;
use controller::analog::{self, LoopConfig, FLOW_LOOP, PRESSURE_LOOP};
use model_core::equations::{
    electromagnetic_torque_pct, load_torque_pct, speed_derivative_rpm_per_s, valve_pressure_mca,
};
use model_core::excitation::SplitMix64;
use model_core::transmitter::lag_to;
use model_core::{BenchParams, BenchState, Scheme, WhiteBox, MAX_STEP_S};
use std::io::Write;

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
    /// Reading: noise added to the lagged value, then the 4-20 mA transmitter and the ADC
    /// ([`controller::analog`], in f32 as on the board), the code's current read back on the
    /// span's line.
    fn read(&self, lagged: f64, rng: &mut SplitMix64) -> f64 {
        let noisy = lagged + self.noise * f64::from(analog::noise(rng));
        match &self.adc {
            None => noisy,
            Some(l) => {
                let code = l.code(l.transmitter_ma(noisy as f32));
                f64::from(l.value_unclamped(l.current_ma(code)))
            }
        }
    }

    /// Advances the lag state `x` toward `target` over `h` seconds (the transmitter's lag,
    /// [`analog::lag_exact`]: exact for a held target).
    fn lag(&self, x: &mut f64, target: f64, h: f64) {
        analog::lag_exact(x, target, h, self.tau_s);
    }
}

/// Largest RK4 step of the bench, ms (each interval between input rows is split into equal
/// steps no longer than this; a shorter interval is one step of its length).
pub const STEP_MS: f64 = 1.0;

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

/// Smallest valve factor accepted.
pub const VALVE_FACTOR_MIN: f64 = 0.2;
/// Largest valve factor accepted.
pub const VALVE_FACTOR_MAX: f64 = 5.0;
/// Largest |curve error| accepted, %.
pub const CURVE_ERROR_MAX_PCT: f64 = 20.0;
/// Longest transmitter lag accepted, ms.
pub const LAG_MAX_MS: f64 = 2000.0;
/// Smallest non-zero water inertia accepted, mca·s²/l (below it the flow's time constant is
/// under 0.1 ms at the steepest flow balance, and 1 ms steps would need too many sub-steps).
pub const INERTIA_MIN: f64 = 1e-3;
/// Largest water inertia accepted, mca·s²/l.
pub const INERTIA_MAX: f64 = 10.0;

/// A curve error: the true curves are the paper's times `1 + pct/100`, each on its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveError {
    /// Pump head F_H (eq. 5, all ten α), %.
    pub head_pct: f64,
    /// Load torque F_T (eq. 6, all ten β), %.
    pub torque_pct: f64,
}

impl CurveError {
    /// The paper's curves.
    pub const NONE: Self = Self {
        head_pct: 0.0,
        torque_pct: 0.0,
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
}

impl Dynamics {
    /// The paper's model: flow algebraic, torque at once.
    pub const NONE: Self = Self {
        water_inertia: 0.0,
        drive_lag_s: 0.0,
    };
}

/// How the bench of a record differs from the paper's model, and what is written.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Seed of the noise.
    pub seed: u64,
    /// Valve steps, times strictly increasing (see [`parse_valve_steps`]).
    pub valve_steps: Vec<ValveStep>,
    /// Curve error (see [`true_bench`]).
    pub curve_error: CurveError,
    /// Water inertia and drive lag.
    pub dynamics: Dynamics,
    /// Write the true state columns too.
    pub truth: bool,
    /// Flow transmitter lag, s.
    pub flow_lag_s: f64,
    /// Pressure transmitter lag, s.
    pub pressure_lag_s: f64,
}

impl Options {
    /// The record as it always was: the paper's bench, the default lags, no truth columns.
    pub fn with_seed(seed: u64) -> Self {
        Options {
            seed,
            valve_steps: Vec::new(),
            curve_error: CurveError::NONE,
            dynamics: Dynamics::NONE,
            truth: false,
            flow_lag_s: FLOW.tau_s,
            pressure_lag_s: PRESSURE.tau_s,
        }
    }
}

/// `text` as a finite number, or a one-line message naming `option`.
fn finite(option: &str, text: &str) -> Result<f64, String> {
    let t = text.trim();
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{option} '{}': not a finite number", shown(t))),
        Err(_) => Err(format!("{option} '{}': not a number", shown(t))),
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

/// Parses `--curve-error PCT` (head +PCT, load torque −PCT) or `--curve-error H,T` (head H,
/// load torque T): each finite, |·| ≤ [`CURVE_ERROR_MAX_PCT`].
pub fn parse_curve_error(text: &str) -> Result<CurveError, String> {
    let one = |t: &str| -> Result<f64, String> {
        let pct = finite("--curve-error", t)?;
        if pct.abs() <= CURVE_ERROR_MAX_PCT {
            Ok(pct)
        } else {
            Err(format!(
                "--curve-error {}: must be within -{m}..{m} %",
                Short(pct),
                m = Short(CURVE_ERROR_MAX_PCT)
            ))
        }
    };
    match text.split_once(',') {
        None => {
            let pct = one(text)?;
            Ok(CurveError {
                head_pct: pct,
                torque_pct: -pct,
            })
        }
        Some((h, t)) if !t.contains(',') => Ok(CurveError {
            head_pct: one(h)?,
            torque_pct: one(t)?,
        }),
        Some(_) => Err(format!(
            "--curve-error '{}': expected PCT or HEAD_PCT,TORQUE_PCT",
            shown(text)
        )),
    }
}

/// Parses `--water-inertia L` (mca·s²/l): 0, or finite within
/// [`INERTIA_MIN`]..=[`INERTIA_MAX`].
pub fn parse_water_inertia(text: &str) -> Result<f64, String> {
    let l = finite("--water-inertia", text)?;
    if l == 0.0 || (INERTIA_MIN..=INERTIA_MAX).contains(&l) {
        Ok(l.abs())
    } else {
        Err(format!(
            "--water-inertia {}: must be 0 or within {}..{} mca·s²/l",
            Short(l),
            Short(INERTIA_MIN),
            Short(INERTIA_MAX)
        ))
    }
}

/// Parses a transmitter lag in ms (`option` names it in the message): finite, within
/// 0..=[`LAG_MAX_MS`]. Returns seconds.
pub fn parse_lag_ms(option: &str, text: &str) -> Result<f64, String> {
    let ms = finite(option, text)?;
    if (0.0..=LAG_MAX_MS).contains(&ms) {
        // A division, so 40 ms is exactly the 0.040 s of the default.
        Ok(ms / 1000.0)
    } else {
        // The limit in plain notation (Short would write 2e3).
        Err(format!(
            "{option} {}: must be within 0..{LAG_MAX_MS} ms",
            Short(ms)
        ))
    }
}

/// The true bench for a curve error: the paper's parameters with every α (pump head F_H,
/// eq. 5) times (1 + head_pct/100) and every β (load torque F_T, eq. 6) times
/// (1 + torque_pct/100). [`CurveError::NONE`] gives the paper's bench exactly. The message
/// (one line) says why the parameters are refused.
pub fn true_bench(e: CurveError) -> Result<WhiteBox<f64>, String> {
    let mut p = BenchParams::<f64>::paper();
    let head = 1.0 + e.head_pct / 100.0;
    let load = 1.0 + e.torque_pct / 100.0;
    p.alpha.iter_mut().for_each(|a| *a *= head);
    p.beta.iter_mut().for_each(|b| *b *= load);
    WhiteBox::new(p).map_err(|err| {
        format!(
            "--curve-error {},{}: the scaled pump-head and load-torque curves are refused: {err}",
            Short(e.head_pct),
            Short(e.torque_pct)
        )
    })
}

/// The bench with the dynamics the paper's model lacks ([`Dynamics`]): speed, flow (a state
/// when there is water inertia, else the flow balance's root) and the electromagnetic torque
/// the drive delivers (lagged when the drive has a lag).
#[derive(Debug, Clone, Copy)]
struct Rich {
    speed_rpm: f64,
    flow_lps: f64,
    te_pct: f64,
}

/// Most RK4 sub-steps in one step of the rich bench (the flow's time constant sets them).
const RICH_MAX_SUBSTEPS: f64 = 1000.0;

impl Rich {
    /// At the white-box bench's (steady) `state`, the drive delivering Te(u) for its torque.
    fn at(bench: &WhiteBox<f64>, state: &BenchState<f64>) -> Self {
        let s = bench.signals(state);
        Rich {
            speed_rpm: s.speed_rpm,
            flow_lps: s.flow_lps,
            te_pct: s.electromagnetic_torque_pct,
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

    /// Advances by `h` seconds with the torque reference `u` held: the drive's lag exactly
    /// (its target Te(u) is constant over the step), speed and flow by RK4 in equal sub-steps,
    /// as many as keep a sub-step under half the flow's time constant `L / |∂g/∂Q|`. Without
    /// inertia the flow is the flow balance's root at each stage (as in the white-box bench).
    /// Its own RK4, not `WhiteBox::step`: the state here is speed *and* flow (the water
    /// column) with a drive torque that moves within the step, which the white-box's one-state
    /// step with the torque held does not integrate; it calls the same equations.
    fn advance(&mut self, bench: &WhiteBox<f64>, d: &Dynamics, u: f64, h: f64) {
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
    let mut bench = true_bench(o.curve_error).map_err(|message| Failure { code: 2, message })?;
    let nominal_k2 = bench.params().valve_k2;
    let static_head_c_mca = bench.params().static_head_c_mca;
    let pressure = Transmitter {
        tau_s: o.pressure_lag_s,
        ..PRESSURE
    };
    let flow = Transmitter {
        tau_s: o.flow_lag_s,
        ..FLOW
    };
    let mut pending = o.valve_steps.iter().peekable();
    // Sets the valve of the last step due at time `t` (those before it lasted no time).
    let mut valve_at = |bench: &mut WhiteBox<f64>, t: f64| -> Result<(), Failure> {
        let mut factor = None;
        while let Some(step) = pending.next_if(|s| s.t_s <= t) {
            factor = Some(step.factor);
        }
        match factor {
            Some(f) => bench
                .set_load(nominal_k2 * f, static_head_c_mca)
                .map_err(|e| fail(format!("model: {e}"))),
            None => Ok(()),
        }
    };
    valve_at(&mut bench, input.t_s[0])?;
    let mut state: BenchState<f64> = bench
        .steady_state(input.torque_ref_pct[0])
        .map_err(|e| fail(format!("model: {e}")))?;
    // With inertia or a drive lag the rich bench carries the state (started at the same
    // steady state); without, the white-box bench alone, as before they existed.
    let mut rich = (o.dynamics != Dynamics::NONE).then(|| Rich::at(&bench, &state));
    // Speed, flow and pressure now.
    let now = |bench: &WhiteBox<f64>, state: &BenchState<f64>, rich: &Option<Rich>| match rich {
        Some(r) => {
            let par = bench.params();
            let q = r.flow_lps;
            (
                r.speed_rpm,
                q,
                valve_pressure_mca(par.valve_k2, par.static_head_c_mca, q),
            )
        }
        None => {
            let sig = bench.signals(state);
            (sig.speed_rpm, sig.flow_lps, sig.pressure_mca)
        }
    };
    let mut rng = SplitMix64::new(o.seed);
    let (mut s, mut q, mut p) = now(&bench, &state, &rich);
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
                    valve_at(&mut bench, t0 + k as f64 * h)?;
                }
                match rich.as_mut() {
                    Some(r) => r.advance(&bench, &o.dynamics, u, h),
                    // One step of h (h <= 1 ms < MAX_STEP_S), also below model-core's 1 µs
                    // smallest step, as `simulate` integrates a short interval.
                    None => {
                        bench
                            .advance(&mut state, u, h, MAX_STEP_S, Scheme::Rk4)
                            .map_err(|e| fail(format!("model: {e}")))?;
                    }
                }
                let (w_now, q_now, p_now) = now(&bench, &state, &rich);
                if !(w_now.is_finite() && q_now.is_finite()) {
                    return Err(fail(format!(
                        "model: the bench diverged at t = {} s",
                        Short(t0 + (k + 1) as f64 * h)
                    )));
                }
                pressure.lag(&mut p, p_now, h);
                flow.lag(&mut q, q_now, h);
                SPEED.lag(&mut s, w_now, h);
            }
        }
        valve_at(&mut bench, input.t_s[i])?;
        // Times and torques as given (shortest round-trip form); the readings at the
        // resolution of a logger.
        write!(
            w,
            "{},{},{:.2},{:.4},{:.5}",
            Short(input.t_s[i]),
            Short(input.torque_ref_pct[i]),
            SPEED.read(s, &mut rng),
            flow.read(q, &mut rng),
            pressure.read(p, &mut rng)
        )
        .map_err(write_fail)?;
        if o.truth {
            // The true state in shortest round-trip form (not a reading: no logger rounding).
            let (w_now, q_now, p_now) = now(&bench, &state, &rich);
            write!(
                w,
                ",{},{},{},{}",
                Short(w_now),
                Short(q_now),
                Short(p_now),
                Short(bench.params().valve_k2)
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
        let o = Options::with_seed(3);
        assert_eq!((o.flow_lag_s, o.pressure_lag_s), (flow, pressure));
        assert_eq!(o.dynamics, Dynamics::NONE);
        assert_eq!(parse_water_inertia("0").unwrap(), 0.0);
        assert_eq!(parse_lag_ms("--drive-lag-ms", "0").unwrap(), 0.0);
        assert_eq!(true_bench(zero).unwrap(), WhiteBox::<f64>::paper());
        assert_eq!(
            true_bench(parse_curve_error("-0").unwrap()).unwrap(),
            WhiteBox::<f64>::paper()
        );
    }

    #[test]
    fn curve_error_scales_every_alpha_up_and_every_beta_down() {
        let paper = BenchParams::<f64>::paper();
        let b = true_bench(parse_curve_error("5").unwrap()).unwrap();
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
        let p = true_bench(parse_curve_error("8,8").unwrap()).unwrap();
        assert_eq!(p.params().alpha[0], paper.alpha[0] * 1.08);
        assert_eq!(p.params().beta[0], paper.beta[0] * 1.08);
        for text in ["1,2,3", "x,1", "1,30", ""] {
            let e = parse_curve_error(text).unwrap_err();
            assert!(e.starts_with("--curve-error"), "{e}");
        }
        for pct in [f64::NAN, -100.0] {
            let e = true_bench(CurveError {
                head_pct: pct,
                torque_pct: -pct,
            })
            .unwrap_err();
            assert!(
                e.starts_with("--curve-error ") && e.contains("refused"),
                "{e}"
            );
            assert_eq!(e.lines().count(), 1);
        }
    }

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
    fn lag_is_first_order() {
        let mut x = 0.0;
        for _ in 0..20 {
            PRESSURE.lag(&mut x, 1.0, 1e-3);
        }
        assert!((x - (1.0 - (-1.0f64).exp())).abs() < 1e-12);
    }
}
