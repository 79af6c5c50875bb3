//! Alarms built on the observer and the measurements: each with a threshold, a delay to
//! raise, a hysteresis and a delay to clear, latched or not, all in one [`MonitorConfig`].
//!
//! | bit | alarm | raised when (for its raise delay) | latched by default |
//! |---|---|---|---|
//! | 0 | pressure transmitter | the caller says it is in fault (NAMUR NE 43) | no |
//! | 1 | flow transmitter | the caller says it is in fault | no |
//! | 2 | VFD link | the caller says the link alarm stands | no |
//! | 3 | dry run / loss of prime | the load torque the motion shows (delivered torque − inertia × acceleration; the inertia [`Monitor::set_inertia`] was told, else the paper's) is below `threshold` × what the paper's load curve needs at the speed and flow (measured when they are, else estimated), above `min_speed_rpm` | yes |
//! | 4 | no flow / closed valve | estimated flow below `threshold` l/s above `min_speed_rpm`, or k2 above `closed_valve_k2_ratio` × its reference | no |
//! | 5 | end of curve (run-out) | estimated or measured flow above `threshold` l/s (the fitted range ends at 27.8) | no |
//! | 6 | load changed | k2 more than `threshold` (a fraction) from its reference, above `min_speed_rpm` (k2 is poorly observed with little flow) | no (informational) |
//! | 7 | model residual | the innovations' normalised square (each capped at `residual_nis_cap`), averaged over `residual_tau_s`, above `threshold` | no |
//! | 8 | overspeed | the speed (the drive's reading, else the estimate's) above `threshold` rpm, checked by [`Monitor::check_speed`] on every call (the controller: every 1 ms) | yes |
//!
//! An unlatched alarm clears once its clearing condition (threshold moved by the hysteresis)
//! has held for its clear delay. A latched one stays after its cause has gone until
//! [`Monitor::acknowledge`], and then clears once its clearing condition has held for its
//! clear delay: at once if it already had when the acknowledge came, else as soon as it has
//! (an acknowledge given while the cause stands is kept until the cause has gone, not lost).
//! An alarm raised again after it cleared needs a new acknowledge.

use crate::equations::{electromagnetic_torque_pct, load_torque_from_motion_pct, load_torque_pct};
use crate::inertia::InertiaProbe;
use crate::observer::{Estimate, Use};
use crate::params::{BenchParams, FITTED_FLOW_MAX_LPS};
use crate::scalar::Real;
use crate::units::applied_torque_pct;

/// Bit of the pressure transmitter fault.
pub const PRESSURE_TRANSMITTER: u16 = 1 << 0;
/// Bit of the flow transmitter fault.
pub const FLOW_TRANSMITTER: u16 = 1 << 1;
/// Bit of the VFD link alarm.
pub const VFD_LINK: u16 = 1 << 2;
/// Bit of dry run / loss of prime.
pub const DRY_RUN: u16 = 1 << 3;
/// Bit of no flow / closed valve.
pub const NO_FLOW: u16 = 1 << 4;
/// Bit of end of curve (run-out).
pub const END_OF_CURVE: u16 = 1 << 5;
/// Bit of load changed.
pub const LOAD_CHANGED: u16 = 1 << 6;
/// Bit of model residual.
pub const MODEL_RESIDUAL: u16 = 1 << 7;
/// Bit of overspeed.
pub const OVERSPEED: u16 = 1 << 8;
/// Alarms in the bit set (bits 0..=8).
pub const ALARMS: usize = 9;
/// The motor's nominal speed, rpm: the paper's 58.3π rad/s, rounded to the drive's 1 750.
pub const NOMINAL_SPEED_RPM: f64 = 1750.0;

/// One alarm's rule. The threshold's unit is the alarm's (see the module table); the
/// hysteresis moves the threshold for clearing, away from the raising side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlarmConfig<T> {
    /// Threshold.
    pub threshold: T,
    /// Hysteresis (≥ 0), same unit.
    pub hysteresis: T,
    /// The condition must hold this long to raise, s (≥ 0).
    pub raise_s: T,
    /// The clearing condition must hold this long to clear, s (≥ 0).
    pub clear_s: T,
    /// Stays raised until acknowledged.
    pub latched: bool,
}

/// All the alarms' rules.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorConfig<T> {
    /// Load-torque ratio (motion / curve) below which the pump runs dry: 0.5, clear above
    /// 0.7; 2 s to raise and to clear; latched.
    pub dry_run: AlarmConfig<T>,
    /// Flow below which nothing flows, l/s: 1.0, clear above 1.5; 2 s; not latched.
    pub no_flow: AlarmConfig<T>,
    /// k2 above this multiple of its reference is a closed valve (no-flow alarm): 4.
    pub closed_valve_k2_ratio: T,
    /// Flow above which the pump runs out, l/s: 27.8, clear below 27.3; 2 s; not latched.
    pub end_of_curve: AlarmConfig<T>,
    /// Relative change of k2 from its reference: 0.15, clear below 0.10; 1 s; not latched.
    pub load_changed: AlarmConfig<T>,
    /// Averaged normalised innovation square: 12, clear below 6; 3 s to raise, 2 s to
    /// clear; not latched.
    pub residual: AlarmConfig<T>,
    /// Time constant of the innovation average, s: 2.
    pub residual_tau_s: T,
    /// Largest normalised square one sample adds to the average: 36 (the observer's 6 σ
    /// gate), so that the burst of a valve step (a few samples of thousands) does not raise
    /// the alarm, while a lasting inconsistency (a stuck transmitter) does.
    pub residual_nis_cap: T,
    /// Speeds below this do not judge dry run, no flow or load changed, rpm: 500.
    pub min_speed_rpm: T,
    /// Reference k2 (the commissioned valve): the paper's 0.1082.
    pub k2_reference: T,
    /// Raise and clear delays of the transmitter and link bits, s: 0 (their own checks
    /// already wait).
    pub pass_through_s: T,
    /// Speed above which the motor runs over speed, rpm: 110 % of the nominal 1 750 rpm
    /// (1 925), clear 100 rpm below it after 1 s; raised at once; latched.
    pub overspeed: AlarmConfig<T>,
}

impl<T: Real> MonitorConfig<T> {
    /// The defaults in the field docs.
    pub fn paper() -> Self {
        let f = T::from_f64;
        let rule = |threshold, hysteresis, raise_s, clear_s, latched| AlarmConfig {
            threshold: f(threshold),
            hysteresis: f(hysteresis),
            raise_s: f(raise_s),
            clear_s: f(clear_s),
            latched,
        };
        Self {
            dry_run: rule(0.5, 0.2, 2.0, 2.0, true),
            no_flow: rule(1.0, 0.5, 2.0, 2.0, false),
            closed_valve_k2_ratio: f(4.0),
            end_of_curve: rule(FITTED_FLOW_MAX_LPS, 0.5, 2.0, 2.0, false),
            load_changed: rule(0.15, 0.05, 1.0, 1.0, false),
            residual: rule(12.0, 6.0, 3.0, 2.0, false),
            residual_tau_s: f(2.0),
            residual_nis_cap: f(36.0),
            min_speed_rpm: f(500.0),
            k2_reference: BenchParams::<T>::paper().valve_k2,
            pass_through_s: T::ZERO,
            overspeed: rule(NOMINAL_SPEED_RPM * 11.0 / 10.0, 100.0, 0.0, 1.0, true),
        }
    }
}

/// What the monitor looks at in one update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorInputs<T> {
    /// Time since the last update, s (> 0; other values skip the timers).
    pub dt_s: T,
    /// The observer's estimate after this update.
    pub estimate: Estimate<T>,
    /// The applied torque reference over the step, %.
    pub torque_ref_pct: T,
    /// The torque the VFD reports, %, if read this time (else `Te(u)` of the reference).
    pub vfd_torque_pct: Option<T>,
    /// The speed the VFD reports, rpm, if read this time (else the estimate's).
    pub vfd_speed_rpm: Option<T>,
    /// The flow transmitter's reading, l/s, if one arrived (and is not in fault); the last
    /// one is used for up to 1 s, then the estimate's.
    pub measured_flow_lps: Option<T>,
    /// Pressure transmitter in fault.
    pub pressure_fault: bool,
    /// Flow transmitter in fault.
    pub flow_fault: bool,
    /// VFD link alarm.
    pub vfd_link_alarm: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Timer<T> {
    active: bool,
    held_s: T,
    /// The clearing condition held at the last update.
    clear_now: bool,
    /// The alarm is latched (as configured at the last update).
    latched: bool,
    /// The clear delay at the last update, s.
    clear_s: T,
    /// An acknowledge waits for the cause to go (latched alarms).
    ack: bool,
}

impl<T: Real> Timer<T> {
    const IDLE: Self = Self {
        active: false,
        held_s: T::ZERO,
        clear_now: true,
        latched: false,
        clear_s: T::ZERO,
        ack: false,
    };

    /// One update: `raise`/`clear` are the conditions (with the hysteresis applied). While
    /// raised, `held_s` is how long the clearing condition has held, latched or not; a
    /// latched alarm clears on it only once acknowledged. Not inlined: nine copies cost the
    /// MCU image ≈ 1 KB.
    #[inline(never)]
    fn update(&mut self, dt: T, raise: bool, clear: bool, raise_s: T, clear_s: T, latched: bool) {
        self.clear_now = clear;
        self.latched = latched;
        self.clear_s = clear_s;
        let want = if self.active { clear } else { raise };
        if want {
            self.held_s += dt;
        } else {
            self.held_s = T::ZERO;
        }
        self.settle(raise_s, raise);
    }

    /// Toggles the alarm if its condition has held long enough (and, to clear a latched
    /// alarm, it is acknowledged).
    fn settle(&mut self, raise_s: T, raise: bool) {
        let (needed, allowed) = if self.active {
            (self.clear_s, self.clear_now && (!self.latched || self.ack))
        } else {
            (raise_s, raise)
        };
        if allowed && self.held_s >= needed {
            self.active = !self.active;
            self.held_s = T::ZERO;
            self.ack = false;
        }
    }
}

/// One fresh drive reading as the alarms saw it, for the inertia probe
/// ([`crate::inertia::InertiaProbe::update`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveMotion<T> {
    /// The speed change since the drive's last reading and the time between them, rpm and s
    /// (zeros without a last reading).
    pub moved: (T, T),
    /// The acceleration the paper's inertia gives the torque surplus now (the delivered
    /// torque less the load torque at the measured flow, times the observer's torque scale),
    /// rpm/s.
    pub predicted_rpm_per_s: T,
    /// The reading can teach: the pump turns above the alarms' minimum speed against a
    /// positive load torque, and the dry-run alarm is not raised.
    pub turning: bool,
}

/// The alarms' state.
#[derive(Debug, Clone, PartialEq)]
pub struct Monitor<T> {
    cfg: MonitorConfig<T>,
    timers: [Timer<T>; ALARMS],
    /// The timers' `active` flags as bits, refreshed by every call that moves a timer (read
    /// every 1 ms by the controller: a field, not a loop over the timers).
    bits: u16,
    nis_avg: T,
    /// The estimate's speed at the last update, rpm.
    last_speed: Option<T>,
    /// The drive's last speed reading, rpm, and its age, s.
    last_drive_speed: Option<(T, T)>,
    /// Last measured flow and its age, s.
    last_flow: Option<(T, T)>,
    /// The drive's reading at the last update, as the inertia probe takes it.
    motion: Option<DriveMotion<T>>,
    /// The paper's rpm/s per % of torque surplus (the inertia probe's reference).
    accel: T,
    /// The same for the rotor's inertia as measured ([`Self::set_inertia`]): the dry-run
    /// rule's.
    rotor_accel: T,
    /// The dry-run rule's while the speed falls: [`Self::set_inertia`]'s, or with the inertia
    /// not measured yet the heaviest rotor the probe reports.
    coast_accel: T,
    gamma: [T; 6],
    beta: [T; 10],
}

impl<T: Real> Monitor<T> {
    /// A monitor with `config`, no alarm raised, judging load torque against the paper's
    /// curves.
    pub fn new(config: MonitorConfig<T>) -> Self {
        let par = BenchParams::<T>::paper();
        Self {
            cfg: config,
            timers: [Timer::IDLE; ALARMS],
            bits: 0,
            nis_avg: T::ZERO,
            last_speed: None,
            last_drive_speed: None,
            last_flow: None,
            motion: None,
            accel: par.accel_rpm_per_s_per_pct(),
            rotor_accel: par.accel_rpm_per_s_per_pct(),
            coast_accel: par.accel_rpm_per_s_per_pct(),
            gamma: par.gamma,
            beta: par.beta,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &MonitorConfig<T> {
        &self.cfg
    }

    /// The drive's reading at the last [`Self::update`] (`None` without a fresh one), as the
    /// inertia probe ([`crate::inertia::InertiaProbe::update`]) takes it: the alarms' own
    /// speed change and load torque, not a second copy of them.
    pub fn motion(&self) -> Option<DriveMotion<T>> {
        self.motion
    }

    /// The rotor's inertia as a factor of the paper's (the inertia probe's,
    /// [`crate::inertia::InertiaProbe::factor`]), for the load the motion shows in the dry-run
    /// rule: with the paper's J, the coast of a rotor four times as heavy at 0 % torque showed
    /// a quarter of its load and tripped dry run (latched) in a pressure loop's downward step.
    /// A factor of 1 or less, not finite, or above [`crate::inertia::InertiaProbe::RANGE`] sets
    /// the paper's.
    /// A dry pump at a steady speed shows its (small) load whatever the inertia: the factor
    /// moves only what accelerations read.
    ///
    /// `None`: not measured yet ([`crate::inertia::InertiaProbe::measured`]). A falling speed
    /// (by more than the fall [`crate::inertia::InertiaProbe::MIN_SURPLUS_PCT`] of torque gives
    /// that rotor: 54 rpm/s at the paper's J, over the reading's noise) is then read on a
    /// rotor of the probe's largest factor (4 × the paper's), the inertia that shows the most
    /// load: a rotor heavier than the paper's coasting at low torque before any move had
    /// taught the probe (a PI alone with a slow λ, registers 16 and 18, moves too gently to
    /// teach it) read dry and tripped. The price: before the inertia is measured a dry pump
    /// is judged at a steady, slowly falling or rising speed only. (The monitor starts with
    /// the paper's J, as `Some(1)`: its other users have no probe.)
    pub fn set_inertia(&mut self, factor: Option<T>) {
        // Heavier only: a lighter rotor with the paper's J shows more load on a coast, not
        // less, and a torque reading that lags (a drive's filter) reads the inertia low (at
        // 200 ms, 0.39 × on the paper's rotor: taken, every coast would read dry).
        let hi = T::from_f64(InertiaProbe::<T>::RANGE.1);
        self.rotor_accel = match factor {
            Some(f) if f > T::ONE && f <= hi => self.accel / f,
            _ => self.accel,
        };
        self.coast_accel = match factor {
            Some(_) => self.rotor_accel,
            None => self.accel / hi,
        };
    }

    /// Alarm bits now (see the module table).
    pub fn bits(&self) -> u16 {
        self.bits
    }

    fn refresh_bits(&mut self) -> u16 {
        self.bits = self
            .timers
            .iter()
            .enumerate()
            .fold(0, |acc, (i, t)| acc | (u16::from(t.active) << i));
        self.bits
    }

    /// The operator's acknowledge of the latched alarms raised now: each clears at once if
    /// its cause has gone (its clearing condition has held for its clear delay), else as
    /// soon as it has; the acknowledge is kept until then. Unlatched alarms are not touched.
    pub fn acknowledge(&mut self) {
        for t in self.timers.iter_mut() {
            if t.latched && t.active {
                t.ack = true;
                t.settle(T::ZERO, false);
            }
        }
        self.refresh_bits();
    }

    /// Latched alarms raised now that have an acknowledge waiting for their cause to go.
    pub fn acknowledge_pending(&self) -> u16 {
        self.timers
            .iter()
            .enumerate()
            .fold(0, |acc, (i, t)| acc | (u16::from(t.active && t.ack) << i))
    }

    /// Sets the overspeed limit, rpm (finite and > 0; other values are ignored).
    pub fn set_overspeed_limit_rpm(&mut self, limit_rpm: T) {
        if limit_rpm.is_finite() && limit_rpm > T::ZERO {
            self.cfg.overspeed.threshold = limit_rpm;
        }
    }

    /// The overspeed check, on its own so that it can run more often than [`Self::update`]
    /// (the controller: every 1 ms): `speed_rpm` (the drive's reading, else the estimate's)
    /// against the limit, `dt_s` since the last call. A speed that is not finite is no
    /// reading: the timers hold. ([`Self::bits`] has the result.)
    pub fn check_speed(&mut self, dt_s: T, speed_rpm: T) {
        if speed_rpm.is_finite() {
            let o = self.cfg.overspeed;
            let dt = if dt_s.is_finite() && dt_s > T::ZERO {
                dt_s
            } else {
                T::ZERO
            };
            self.timers[8].update(
                dt,
                speed_rpm > o.threshold,
                speed_rpm < o.threshold - o.hysteresis,
                o.raise_s,
                o.clear_s,
                o.latched,
            );
            self.bits = self.bits & !OVERSPEED | u16::from(self.timers[8].active) << 8;
        }
    }

    /// One update; returns the alarm bits.
    pub fn update(&mut self, m: &MonitorInputs<T>) -> u16 {
        let c = self.cfg;
        let e = &m.estimate;
        let dt = if m.dt_s.is_finite() && m.dt_s > T::ZERO {
            m.dt_s
        } else {
            T::ZERO
        };
        let pass = c.pass_through_s;
        self.timers[0].update(dt, m.pressure_fault, !m.pressure_fault, pass, pass, false);
        self.timers[1].update(dt, m.flow_fault, !m.flow_fault, pass, pass, false);
        self.timers[2].update(dt, m.vfd_link_alarm, !m.vfd_link_alarm, pass, pass, false);

        // Dry run: the load the motion shows against what the (wet) pump curve needs.
        // The acceleration from two speeds of one source: the drive's readings (however far
        // apart), else the estimate's; a switch between the two is not an acceleration.
        let accel = self.accel;
        let drive = m.vfd_speed_rpm.filter(|w| w.is_finite());
        // `moved`: the speed change since the drive's last reading and the time between them
        // (zero without one), for the inertia probe ([`Self::motion`]).
        let mut moved = (T::ZERO, T::ZERO);
        let (speed, rate) = match (drive, self.last_drive_speed) {
            (Some(w), Some((w0, age))) if age + dt > T::ZERO => {
                moved = (w - w0, age + dt);
                (w, moved.0 / moved.1)
            }
            (Some(w), _) => (w, T::ZERO),
            (None, _) => match self.last_speed {
                Some(w0) if dt > T::ZERO => (e.speed_rpm, (e.speed_rpm - w0) / dt),
                _ => (e.speed_rpm, T::ZERO),
            },
        };
        self.last_speed = Some(e.speed_rpm);
        self.last_drive_speed = match (drive, self.last_drive_speed) {
            (Some(w), _) => Some((w, T::ZERO)),
            (None, Some((w0, age))) if age + dt <= T::ONE => Some((w0, age + dt)),
            _ => None,
        };
        self.last_flow = match (m.measured_flow_lps, self.last_flow) {
            (Some(q), _) if q.is_finite() => Some((q.max(T::ZERO), T::ZERO)),
            (_, Some((q, age))) if age + dt <= T::ONE => Some((q, age + dt)),
            _ => None,
        };
        let flow = self.last_flow.map_or(e.flow_lps, |(q, _)| q);
        let delivered = match m.vfd_torque_pct {
            Some(t) if t.is_finite() => t,
            _ => electromagnetic_torque_pct(&self.gamma, applied_torque_pct(m.torque_ref_pct)),
        };
        // A fall that shows at least `MIN_SURPLUS_PCT` of torque on the heaviest rotor (54
        // rpm/s at the paper's J): not the reading's noise at a steady speed (±13 rpm/s).
        let coasting = rate < -T::from_f64(InertiaProbe::<T>::MIN_SURPLUS_PCT) * self.coast_accel;
        let rotor = if coasting {
            self.coast_accel
        } else {
            self.rotor_accel
        };
        let shown = load_torque_from_motion_pct(delivered, rate, rotor);
        let needed = load_torque_pct(&self.beta, speed, flow);
        let fast = speed > c.min_speed_rpm && needed > T::ZERO;
        let ratio = if fast { shown / needed } else { T::ONE };
        let d = c.dry_run;
        // For the inertia probe: the same reading's speed change and torque surplus, as the
        // acceleration the paper's J gives it.
        self.motion = drive.map(|_| DriveMotion {
            moved,
            predicted_rpm_per_s: accel * (delivered - e.torque_scale * needed),
            // A pump whose dry-run alarm is up is not on its load curve. (Not the rule's
            // condition: a heavy rotor's first coast reads dry on the paper's J, and it is the
            // move that teaches the probe; gated on it, rotors 3 and 4 × the paper's tripped
            // on a first downward flow step.)
            turning: fast && !self.timers[3].active,
        });
        self.timers[3].update(
            dt,
            ratio < d.threshold,
            ratio > d.threshold + d.hysteresis,
            d.raise_s,
            d.clear_s,
            d.latched,
        );

        // No flow / closed valve.
        let n = c.no_flow;
        let k2_ratio = e.valve_k2 / c.k2_reference;
        let spinning = e.speed_rpm > c.min_speed_rpm;
        let raise = spinning && (e.flow_lps < n.threshold || k2_ratio > c.closed_valve_k2_ratio);
        // Clearing is the raising condition's opposite, both halves with their margin: a
        // closed valve whose flow still reads above 1.5 l/s must not clear and re-raise in
        // turn.
        let clear = !spinning
            || (e.flow_lps > n.threshold + n.hysteresis && k2_ratio < c.closed_valve_k2_ratio);
        self.timers[4].update(dt, raise, clear, n.raise_s, n.clear_s, n.latched);

        // End of curve: the estimate, or the flow meter where the model cannot follow (a
        // broken pipe takes the bench outside its fitted curves).
        let r = c.end_of_curve;
        let most = e.flow_lps.max(flow);
        self.timers[5].update(
            dt,
            most > r.threshold,
            most < r.threshold - r.hysteresis,
            r.raise_s,
            r.clear_s,
            r.latched,
        );

        // Load changed.
        let l = c.load_changed;
        let change = (k2_ratio - T::ONE).abs();
        self.timers[6].update(
            dt,
            spinning && change > l.threshold,
            !spinning || change < l.threshold - l.hysteresis,
            l.raise_s,
            l.clear_s,
            l.latched,
        );

        // Model residual: the innovations' normalised squares, averaged; a drive's speed the
        // observer refused as impossible (out of range, or contradicted by the pressure
        // read) counts at the cap: a reading that the model cannot take.
        let mut nis = T::ZERO;
        for i in [e.pressure, e.flow, e.speed] {
            if matches!(i.used, Use::Used | Use::Rejected) && i.nis.is_finite() {
                nis = nis.max(i.nis.min(c.residual_nis_cap));
            }
        }
        if e.speed.used == Use::Implausible {
            nis = c.residual_nis_cap;
        }
        if dt > T::ZERO && c.residual_tau_s > T::ZERO {
            let a = (dt / c.residual_tau_s).min(T::ONE);
            self.nis_avg += a * (nis - self.nis_avg);
        }
        let s = c.residual;
        self.timers[7].update(
            dt,
            self.nis_avg > s.threshold,
            self.nis_avg < s.threshold - s.hysteresis,
            s.raise_s,
            s.clear_s,
            s.latched,
        );
        self.refresh_bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observer::tests::{record, record_with, Row};
    use crate::observer::{Measurements, Observer, ObserverConfig};

    /// Faults a test injects at `from_s`.
    #[derive(Clone, Copy, Default)]
    struct Inject {
        pressure_stuck: bool,
        pressure_fault: bool,
        link: bool,
    }

    /// Observer + monitor over `rows`; returns (t_s, bits) per row.
    fn alarms(rows: &[Row], from_s: f64, inject: Inject) -> Vec<(f64, u16)> {
        let mut o = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
        let mut mon = Monitor::new(MonitorConfig::paper());
        let mut stuck = None;
        rows.iter()
            .enumerate()
            .map(|(i, r)| {
                let on = r.t_s >= from_s;
                let mut p = r.p_meas;
                if inject.pressure_stuck && on {
                    p = *stuck.get_or_insert(r.p_meas);
                }
                let pf = inject.pressure_fault && on;
                let m = Measurements {
                    pressure_mca: (!pf).then_some(p),
                    flow_lps: (i % 2 == 1).then_some(r.q_meas),
                    speed_rpm: Some(r.w_meas),
                };
                let e = o.step(0.05, r.torque_pct, &m).unwrap();
                let bits = mon.update(&MonitorInputs {
                    dt_s: 0.05,
                    estimate: e,
                    torque_ref_pct: r.torque_pct,
                    vfd_torque_pct: None,
                    vfd_speed_rpm: Some(r.w_meas),
                    measured_flow_lps: (i % 2 == 1).then_some(r.q_meas),
                    pressure_fault: pf,
                    flow_fault: false,
                    vfd_link_alarm: inject.link && on,
                });
                (r.t_s, bits)
            })
            .collect()
    }

    /// First time at or after `from_s` that `bit` is set.
    fn raised(trace: &[(f64, u16)], bit: u16, from_s: f64) -> Option<f64> {
        trace
            .iter()
            .find(|(t, b)| *t >= from_s && b & bit != 0)
            .map(|(t, _)| t - from_s)
    }

    #[test]
    fn no_alarm_over_30_minutes_of_pulses() {
        let rows = record(11, 1800.0, 0.03, &[]);
        let trace = alarms(&rows, f64::INFINITY, Inject::default());
        let any: Vec<_> = trace.iter().filter(|(_, b)| *b != 0).take(5).collect();
        assert!(any.is_empty(), "false alarms: {any:?}");
    }

    #[test]
    fn each_alarm_is_raised_by_its_fault_within_its_delay() {
        let c = MonitorConfig::<f64>::paper();
        // (name, rows, fault start, injection, bit, latest raise after the fault, s)
        let dry = record_with(
            12,
            60.0,
            0.03,
            &[],
            Some(30.0),
            1.0,
            crate::params::PAPER_C_MCA,
        );
        let closed = record(13, 60.0, 0.03, &[(30.0, 10.0)]);
        let moved = record(15, 60.0, 0.03, &[(30.0, 1.3)]);
        let plain = record(16, 60.0, 0.03, &[]);
        let cases: [(&str, &[Row], Inject, u16, f64); 6] = [
            (
                "dry run",
                &dry,
                Inject::default(),
                DRY_RUN,
                c.dry_run.raise_s + 2.0,
            ),
            (
                "no flow",
                &closed,
                Inject::default(),
                NO_FLOW,
                c.no_flow.raise_s + 2.0,
            ),
            (
                "load changed",
                &moved,
                Inject::default(),
                LOAD_CHANGED,
                c.load_changed.raise_s + 2.0,
            ),
            (
                "model residual (pressure stuck)",
                &plain,
                Inject {
                    pressure_stuck: true,
                    ..Default::default()
                },
                MODEL_RESIDUAL,
                c.residual.raise_s + 10.0,
            ),
            (
                "pressure transmitter",
                &plain,
                Inject {
                    pressure_fault: true,
                    ..Default::default()
                },
                PRESSURE_TRANSMITTER,
                0.05,
            ),
            (
                "VFD link",
                &plain,
                Inject {
                    link: true,
                    ..Default::default()
                },
                VFD_LINK,
                0.05,
            ),
        ];
        for (name, rows, inject, bit, within) in cases {
            let trace = alarms(rows, 30.0, inject);
            let before: Vec<_> = trace
                .iter()
                .filter(|(t, b)| *t < 30.0 && *b != 0)
                .take(3)
                .collect();
            assert!(
                before.is_empty(),
                "{name}: alarms before the fault: {before:?}"
            );
            let after = raised(&trace, bit, 30.0);
            println!("{name}: raised {after:?} s after the fault");
            assert!(
                after.is_some_and(|t| t <= within),
                "{name}: {after:?} (limit {within} s)"
            );
        }
    }

    /// Run-out cannot be made on the synthetic bench: with the paper's curves the pump gives
    /// at most ≈ 26 l/s (85 %, valve wide open, even a broken pipe), short of 27.8. So the
    /// rule is checked on the flow it reads: estimated, or measured.
    #[test]
    fn end_of_curve_from_the_estimate_or_the_flow_meter() {
        let o = Observer::<f64>::new(ObserverConfig::paper(), 50.0).unwrap();
        for (estimated, measured) in [(28.5, None), (20.0, Some(28.5))] {
            let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
            let mut e = o.estimate_now();
            e.flow_lps = estimated;
            let input = MonitorInputs {
                dt_s: 0.05,
                estimate: e,
                torque_ref_pct: 50.0,
                vfd_torque_pct: None,
                vfd_speed_rpm: None,
                measured_flow_lps: measured,
                pressure_fault: false,
                flow_fault: false,
                vfd_link_alarm: false,
            };
            let mut t = 0.0;
            while mon.update(&input) & END_OF_CURVE == 0 {
                t += 0.05;
                assert!(t < 2.1, "not raised after {t} s");
            }
            assert!(t >= 1.9, "raised after {t} s, before its 2 s delay");
            let mut back = input;
            back.estimate.flow_lps = 20.0;
            back.measured_flow_lps = Some(20.0);
            for _ in 0..41 {
                mon.update(&back);
            }
            assert_eq!(mon.bits() & END_OF_CURVE, 0, "clears: not latched");
        }
    }

    #[test]
    fn latched_dry_run_stays_until_acknowledged_and_others_clear() {
        let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
        let o = Observer::<f64>::new(ObserverConfig::paper(), 50.0).unwrap();
        let mut e = o.estimate_now();
        let input = |e| MonitorInputs {
            dt_s: 0.05,
            estimate: e,
            torque_ref_pct: 50.0,
            vfd_torque_pct: Some(2.0),
            vfd_speed_rpm: None,
            measured_flow_lps: None,
            pressure_fault: false,
            flow_fault: false,
            vfd_link_alarm: false,
        };
        for _ in 0..60 {
            mon.update(&input(e));
        }
        assert!(
            mon.bits() & DRY_RUN != 0,
            "2 % delivered where the curve needs ~50 %"
        );
        let mut ok = input(e);
        ok.vfd_torque_pct = None;
        for _ in 0..100 {
            mon.update(&ok);
        }
        assert!(mon.bits() & DRY_RUN != 0, "latched");
        // Cured for 5 s (more than the 2 s clear delay): one acknowledge clears it at once.
        let mut cured = mon.clone();
        cured.acknowledge();
        assert_eq!(
            cured.bits() & DRY_RUN,
            0,
            "acknowledged with the cause gone"
        );
        // The cause back: an acknowledge does not clear it, but is kept, not lost...
        let stands = input(e);
        mon.update(&stands);
        mon.acknowledge();
        assert!(
            mon.bits() & DRY_RUN != 0,
            "not acknowledged while the cause stands"
        );
        assert_eq!(mon.acknowledge_pending(), DRY_RUN);
        for _ in 0..20 {
            mon.update(&stands);
        }
        assert!(mon.bits() & DRY_RUN != 0, "still dry: still raised");
        // ...and clears the alarm once the cause has gone for its clear delay, 2 s.
        let mut t = 0.0;
        while mon.bits() & DRY_RUN != 0 {
            mon.update(&ok);
            t += 0.05;
            assert!(t < 2.2, "not cleared {t} s after the cause went");
        }
        assert!(t >= 1.95, "cleared after {t} s, before its 2 s delay");
        assert_eq!(mon.acknowledge_pending(), 0);
        // Raised again: the old acknowledge is spent, a new one is needed.
        for _ in 0..60 {
            mon.update(&stands);
        }
        assert!(mon.bits() & DRY_RUN != 0);
        for _ in 0..100 {
            mon.update(&ok);
        }
        assert!(mon.bits() & DRY_RUN != 0, "latched again, no acknowledge");
        mon.acknowledge();
        assert_eq!(mon.bits() & DRY_RUN, 0);
        // Load changed is not latched: it clears by itself.
        e.valve_k2 *= 1.3;
        for _ in 0..40 {
            mon.update(&input(e));
        }
        let mut back = input(e);
        back.vfd_torque_pct = None;
        back.estimate.valve_k2 = e.valve_k2 / 1.3;
        mon.update(&input(e));
        assert!(mon.bits() & LOAD_CHANGED != 0);
        for _ in 0..40 {
            mon.update(&back);
        }
        assert_eq!(mon.bits() & LOAD_CHANGED, 0);
    }
    #[test]
    fn overspeed_raises_at_once_latches_and_clears_below_the_limit_when_acknowledged() {
        let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
        assert_eq!(
            mon.config().overspeed.threshold,
            1925.0,
            "110 % of 1 750 rpm"
        );
        for _ in 0..1000 {
            mon.check_speed(1e-3, 1900.0);
            assert_eq!(mon.bits(), 0);
        }
        mon.check_speed(1e-3, 1926.0);
        assert_eq!(mon.bits(), OVERSPEED, "the first reading over");
        mon.check_speed(1e-3, f64::NAN);
        assert_eq!(mon.bits(), OVERSPEED, "no reading: held");
        for _ in 0..3000 {
            mon.check_speed(1e-3, 0.0);
        }
        assert_eq!(mon.bits(), OVERSPEED, "latched");
        mon.acknowledge();
        assert_eq!(mon.bits(), 0, "below the limit for 3 s: acknowledged");
        mon.set_overspeed_limit_rpm(1000.0);
        mon.check_speed(1e-3, 1001.0);
        assert_eq!(mon.bits(), OVERSPEED, "the limit can be set");
        mon.acknowledge();
        for _ in 0..999 {
            mon.check_speed(1e-3, 950.0);
        }
        assert_eq!(mon.bits(), OVERSPEED, "within the 100 rpm hysteresis");
        for _ in 0..1001 {
            mon.check_speed(1e-3, 899.0);
        }
        assert_eq!(
            mon.bits(),
            0,
            "1 s below 900 rpm: the waiting acknowledge clears it"
        );
        for bad in [f64::NAN, 0.0, -5.0, f64::INFINITY] {
            mon.set_overspeed_limit_rpm(bad);
            assert_eq!(mon.config().overspeed.threshold, 1000.0, "{bad} ignored");
        }
    }

    /// Regression (defect 5a of the protection issue): a drive reading missing for one
    /// update switched the dry-run rule's speed from the drive's to the estimate's, and the
    /// switch read as an acceleration. A wet pump at a steady 1 300 rpm whose estimate is
    /// 150 rpm off the drive's reading (a curve off the paper's) must not look dry, however
    /// the readings come and go.
    #[test]
    fn a_missing_drive_reading_is_not_an_acceleration() {
        let o = Observer::<f64>::new(ObserverConfig::paper(), 50.0).unwrap();
        let e = o.estimate_now();
        let drive = e.speed_rpm + 150.0;
        let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
        for k in 0..400 {
            let reading = (k % 7 != 3).then_some(drive);
            let needed = load_torque_pct(&mon.beta, reading.unwrap_or(e.speed_rpm), e.flow_lps);
            let bits = mon.update(&MonitorInputs {
                dt_s: 0.05,
                estimate: e,
                torque_ref_pct: 50.0,
                vfd_torque_pct: Some(needed),
                vfd_speed_rpm: reading,
                measured_flow_lps: None,
                pressure_fault: false,
                flow_fault: false,
                vfd_link_alarm: false,
            });
            assert_eq!(bits & DRY_RUN, 0, "update {k}: {bits:#x}");
            // Not even one update reads dry: that would restart the clear delay of a
            // dry-run alarm waiting for its acknowledge.
            assert!(mon.timers[3].clear_now, "update {k} reads dry");
        }
    }

    /// A rotor four times the paper's coasting at 0 % torque: its speed falls at a quarter of
    /// the rate the paper's J gives its load. With the paper's J the motion shows a quarter of
    /// the load and the dry-run alarm rises after its 2 s; told the inertia
    /// ([`Monitor::set_inertia`]) it shows the whole load and stays quiet, and so it does with
    /// the inertia not measured yet (`None`: a coast is read on the heaviest rotor). A factor
    /// of 1 or less, above the probe's range or not a number is the paper's J.
    #[test]
    fn the_dry_run_rule_takes_the_inertia_measured() {
        let o = Observer::<f64>::new(ObserverConfig::paper(), 50.0).unwrap();
        let e = o.estimate_now();
        let coast = |factor: Option<f64>| {
            let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
            mon.set_inertia(factor);
            let mut w = 1500.0;
            let mut bits = 0;
            for _ in 0..50 {
                let needed = load_torque_pct(&mon.beta, w, e.flow_lps);
                bits |= mon.update(&MonitorInputs {
                    dt_s: 0.05,
                    estimate: e,
                    torque_ref_pct: 0.0,
                    vfd_torque_pct: Some(0.0),
                    vfd_speed_rpm: Some(w),
                    measured_flow_lps: Some(e.flow_lps),
                    pressure_fault: false,
                    flow_fault: false,
                    vfd_link_alarm: false,
                });
                w -= mon.accel / 4.0 * needed * 0.05;
            }
            assert!(w > 600.0, "still turning above the rule's minimum: {w}");
            bits & DRY_RUN
        };
        assert_eq!(coast(Some(4.0)), 0, "told the inertia");
        assert_eq!(coast(None), 0, "not measured yet");
        for paper in [1.0, 0.5, f64::NAN, 0.1, 5.0] {
            assert_eq!(coast(Some(paper)), DRY_RUN, "{paper}");
        }
    }

    /// A steady pump whose torque reading is off the paper's fit by 2 % teaches the inertia
    /// probe nothing (under `InertiaProbe::MIN_SURPLUS_PCT`); a 10 % surplus, a move's, does
    /// (here with no speed change to show for it).
    #[test]
    fn a_small_steady_surplus_teaches_nothing() {
        let o = Observer::<f64>::new(ObserverConfig::paper(), 50.0).unwrap();
        let e = o.estimate_now();
        for (off, teaches) in [(2.0, false), (-2.0, false), (10.0, true), (-10.0, true)] {
            let mut mon = Monitor::new(MonitorConfig::<f64>::paper());
            let needed = load_torque_pct(&mon.beta, 1300.0, e.flow_lps) * e.torque_scale;
            for _ in 0..2 {
                mon.update(&MonitorInputs {
                    dt_s: 0.05,
                    estimate: e,
                    torque_ref_pct: 50.0,
                    vfd_torque_pct: Some(needed + off),
                    vfd_speed_rpm: Some(1300.0),
                    measured_flow_lps: Some(e.flow_lps),
                    pressure_fault: false,
                    flow_fault: false,
                    vfd_link_alarm: false,
                });
            }
            let m = mon.motion().unwrap();
            let mut probe = InertiaProbe::<f64>::new();
            for _ in 0..100 {
                probe.update(m.turning, (0.0, 0.05), m.predicted_rpm_per_s);
            }
            assert_eq!(
                probe.evidence_rpm2() > 0.0,
                teaches,
                "{off}: {m:?} {probe:?}"
            );
        }
    }
}
