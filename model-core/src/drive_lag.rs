//! The drive's torque lag, measured in operation from its own torque readings.
//!
//! A drive does not deliver the torque it is sent at once: its torque loop (and the reading's
//! own delay) lags it, by a few ms on a fast vector drive, 50..100 ms on a slow one. The
//! paper's eq. (4) maps the reference `u` to the electromagnetic torque `Te(u)`; the reading
//! `y` follows it as a first-order lag of time constant `T`: `dy/dt = (Te(u) − y) / T`.
//! Between two fresh readings `dt` apart, `Δy ≈ x / T − b dt / T` with `x = (Te(ū) − y₀) dt`
//! (ū the reference's mean over the interval, y₀ the first reading) and `b` an offset between
//! the torque asked and the one read (a reading on another zero, a Te(u) a little off): `1 /
//! T` and `b / T` by least squares over the intervals, so a steady offset is no lag. A delay
//! `D` of the reading reads as part of the lag (≈ `T + D`), and so does the interval's own
//! discretisation (≈ `dt / 2` more): what a rule that acts on the torque applied has to wait
//! for either way.
//!
//! Until the gap's spread about its offset holds [`DriveLagProbe::EVIDENCE`] the lag is 0
//! (none measured): steady, the reading's noise is all there is. The controller's loops use
//! it to start braking a setpoint move early enough for a drive that lags
//! (`controller::regulate`; docs/control.md, The loop).
//!
//! What biases it: a drive whose reading is its reference (reads ≈ 0: no lag seen), a torque
//! reading on another scale than the reference's (a 20 ms drive read at 0.8, 0.9, 1.1 × its
//! torque reads 86, 38, 31 ms: more lag; [`DriveLagProbe::MAX_S`] bounds it), noise on the
//! readings (less lag: the noise of the first reading of an interval enters both sides),
//! readings far apart (an interval longer than [`DriveLagProbe::MAX_GAP_S`] is skipped).

use crate::equations::electromagnetic_torque_pct;
use crate::scalar::Real;

/// The drive's torque lag measured from its readings (s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveLagProbe<T> {
    /// Σ x², Σ x dt, Σ dt², Σ x Δy and Σ dt Δy over the intervals used (x in %·s, dt in s,
    /// Δy in %).
    sums: [T; 5],
    /// Since the last reading taken: ∫ u dt (%·s) and the time (s).
    since: [T; 2],
    /// The last reading taken, % (none yet).
    last_reading: Option<T>,
    /// The lag as of the last reading, s.
    lag_s: T,
}

impl<T: Real> Default for DriveLagProbe<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> DriveLagProbe<T> {
    /// Evidence before a lag is reported, (%·s)²: the spread of x about its offset, as of 20
    /// intervals of 5 ms with a ±10 % gap (one setpoint move holds several times it).
    pub const EVIDENCE: f64 = 20.0 * (10.0 * 0.005) * (10.0 * 0.005);
    /// The longest interval between readings used, s.
    pub const MAX_GAP_S: f64 = 0.05;
    /// The longest lag reported, s: a drive's torque loop and its reading lag far less (the
    /// random plants of docs/control.md draw drives to 100 ms); the bound keeps a reading on
    /// another scale from braking the loop's moves early by much (a reading 0.8 × the torque
    /// read a 20 ms drive as 86 ms).
    pub const MAX_S: f64 = 0.15;
    /// Σ x² beyond which the sums are halved (the ratios kept: a drive's lag does not change
    /// in service, but f32 sums must not grow without end).
    const SUMS_CAP: f64 = 1.0e4;

    /// A probe with nothing measured.
    pub fn new() -> Self {
        Self {
            sums: [T::ZERO; 5],
            since: [T::ZERO; 2],
            last_reading: None,
            lag_s: T::ZERO,
        }
    }

    /// The torque reference `torque_ref_pct` (%) applied for `dt_s` s.
    #[inline]
    pub fn applied(&mut self, dt_s: T, torque_ref_pct: T) {
        self.since[0] += torque_ref_pct * dt_s;
        self.since[1] += dt_s;
    }

    /// A fresh torque reading from the drive (% of nominal torque): the interval since the
    /// last one enters the fit, the torque asked over it eq. (4)'s `Te(ū)` on `gamma` (the
    /// bench's γ; taken as the reference itself, its slope of ≈ 0.92 on the paper's bench
    /// read as 100 ms of lag on a drive with none). A value not finite, or no usable interval
    /// before it, adds nothing.
    #[inline(never)]
    pub fn read(&mut self, reading: T, gamma: &[T; 6]) {
        let [integral, dt] = self.since;
        self.since = [T::ZERO; 2];
        let Some(y0) = self.last_reading.replace(reading) else {
            return;
        };
        if !(dt > T::ZERO && dt <= T::from_f64(Self::MAX_GAP_S)) {
            return;
        }
        let x = (electromagnetic_torque_pct(gamma, integral / dt) - y0) * dt;
        let dy = reading - y0;
        let add = [x * x, x * dt, dt * dt, x * dy, dt * dy];
        // (A product not finite: the sums as they were.)
        if !(add[3].is_finite() && add[4].is_finite()) {
            return;
        }
        for (s, a) in self.sums.iter_mut().zip(add) {
            *s += a;
        }
        let [xx, xd, dd, xy, dy] = self.sums;
        if xx > T::from_f64(Self::SUMS_CAP) {
            for s in &mut self.sums {
                *s = *s * T::from_f64(0.5);
            }
        }
        // x's spread about its offset, and its covariance with Δy's (the offset's part out).
        let spread = xx - xd * xd / dd;
        let cov = xy - xd * dy / dd;
        if spread >= T::from_f64(Self::EVIDENCE) && cov > T::ZERO {
            self.lag_s = (spread / cov).min(T::from_f64(Self::MAX_S));
        }
    }

    /// The lag measured, s (0 ..= [`DriveLagProbe::MAX_S`]): 0 until the sums hold
    /// [`DriveLagProbe::EVIDENCE`]; where the readings never moved toward the torque asked,
    /// the last lag measured (0 if none).
    pub fn lag_s(&self) -> T {
        self.lag_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::SplitMix64;
    use crate::transmitter::lag_1ms;

    /// Eq. (4) as the identity: Te(u) = u.
    const UNIT: [f32; 6] = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

    /// A drive lagging `lag_s` behind references stepping ±`step` % about 50 % every 0.3 s
    /// (ramped at 200 %/s, as the loops' rate limit), read every `every` ms with ±0.1 % of
    /// noise, for `ms` ms (1 ms steps); Te = u.
    fn measured(lag_s: f32, step: f32, every: u32, ms: u32) -> DriveLagProbe<f32> {
        let mut p = DriveLagProbe::new();
        let mut rng = SplitMix64::new(5);
        let (mut u, mut te) = (50.0f32, 50.0f32);
        for k in 0..ms {
            let target = if (k / 300) % 2 == 0 {
                50.0 + step
            } else {
                50.0 - step
            };
            u += (target - u).clamp(-0.2, 0.2);
            lag_1ms(&mut te, u, lag_s);
            let reading = (k % every == every - 1).then(|| te + rng.uniform(-0.1, 0.1) as f32);
            p.applied(0.001, u);
            if let Some(r) = reading {
                p.read(r, &UNIT);
            }
        }
        p
    }

    #[test]
    fn the_lag_is_measured_from_moves() {
        for (lag, every) in [(0.02, 5), (0.05, 5), (0.1, 5), (0.05, 10)] {
            let got = measured(lag, 20.0, every, 6_000).lag_s();
            // The interval reads as about half of it more.
            let want = lag + 0.5e-3 * every as f32;
            assert!(
                (got / want - 1.0).abs() < 0.1,
                "{lag} every {every} ms: {got}"
            );
        }
        // No lag: under the interval.
        let got = measured(0.0, 20.0, 5, 6_000).lag_s();
        assert!(got < 0.005, "{got}");
    }

    #[test]
    fn nothing_is_measured_without_moves_or_evidence() {
        // Steady: the noise alone.
        let p = measured(0.05, 0.0, 5, 6_000);
        assert_eq!(p.lag_s(), 0.0, "{p:?}");
        // 10 ms of one move: not enough.
        let p = measured(0.05, 20.0, 5, 10);
        assert_eq!(p.lag_s(), 0.0, "{p:?}");
        // Readings too far apart, and values not finite: nothing.
        let mut p = DriveLagProbe::<f32>::new();
        for k in 0..2_000u32 {
            let u = if (k / 300) % 2 == 0 { 70.0 } else { 30.0 };
            p.applied(0.06, u);
            p.read(50.0, &UNIT);
            p.applied(0.001, f32::NAN);
            p.read(u, &UNIT);
            p.applied(0.001, u);
            p.read(f32::INFINITY, &UNIT);
        }
        assert_eq!(p.lag_s(), 0.0, "{p:?}");
    }

    #[test]
    fn a_steady_offset_is_no_lag() {
        // The reading 3 % under the torque asked, at rest and through the moves.
        let mut p = DriveLagProbe::<f32>::new();
        let (mut u, mut te) = (50.0f32, 47.0f32);
        for k in 0..6_000u32 {
            let target = if (k / 300) % 2 == 0 { 70.0 } else { 30.0 };
            u += (target - u).clamp(-0.2, 0.2);
            lag_1ms(&mut te, u - 3.0, 0.05);
            p.applied(0.001, u);
            if k % 5 == 4 {
                p.read(te, &UNIT);
            }
        }
        let got = p.lag_s();
        assert!((got / 0.0525 - 1.0).abs() < 0.1, "{got}");
        // At rest only: nothing.
        let mut p = DriveLagProbe::<f32>::new();
        for k in 0..6_000u32 {
            p.applied(0.001, 50.0);
            if k % 5 == 4 {
                p.read(47.0, &UNIT);
            }
        }
        assert_eq!(p.lag_s(), 0.0, "{p:?}");
    }

    #[test]
    fn a_reading_that_never_follows_reads_no_lag() {
        let mut p = DriveLagProbe::<f32>::new();
        for k in 0..6_000u32 {
            let u = if (k / 300) % 2 == 0 { 70.0 } else { 30.0 };
            p.applied(0.001, u);
            if k % 5 == 4 {
                p.read(50.0, &UNIT);
            }
        }
        assert_eq!(p.lag_s(), 0.0, "{p:?}");
    }
}
