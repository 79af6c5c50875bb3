//! The rotor's inertia, measured in operation from the drive's own readings.
//!
//! Every model here takes the paper's J (eq. 3: `J dω/dt = Te − TL`): the white-box bench,
//! the observer, the dry-run alarm and the pressure and flow loops, whose gains follow the
//! bench's time constant `τ = J / (∂TL/∂ω)`. A pump on another motor or impeller is not the
//! paper's: a plant with twice the paper's inertia, with the paper's J in the loop, overshot
//! 7.7..9.5 % on 1 mca pressure steps and met 3 of its 12 pressure targets.
//!
//! The measurement, on the readings the alarm monitor already takes and hands on
//! ([`crate::monitor::Monitor::motion`]; the controller owns the probe, and its tick's budget
//! pays for it): between two fresh drive readings (speed ω, delivered torque Te) the paper's J
//! predicts the speed change `x = a ∫ (Te − TL) dt` (trapezoid; `a` the paper's rpm/s per % of
//! surplus torque, TL the load-torque curve at the measured flow with the observer's torque
//! scale); the speed measured changes by `y`. The inertia is
//! `f = Σ x² / Σ x y` times the paper's over the intervals, by least squares (an inertia
//! does not change in service: the sums are only halved, ratio kept, when they grow large;
//! the speed's noise is in `y` alone and averages out). Only moves carry information: steady, `x ≈ 0` adds nothing. Until the sums
//! hold [`InertiaProbe::EVIDENCE_RPM2`] the factor is 1 (the paper's J).
//!
//! What biases it: a drive that reports its torque reference rather than its torque (a
//! torque loop's lag then reads as inertia), a load-torque curve wrong in shape (its scale is
//! the observer's), a pump running dry (its load is not the curve's: the monitor's reading
//! says not to learn while dry run is raised), and readings late by a
//! large part of a move. Its user chooses when it learns: the controller's loops teach it
//! only their own setpoint moves (a valve step's new load shows in the flow reading late: a
//! first version that learnt from valve steps read 1.03..1.12 × on the paper's rotor).
//!
//! Measured through `pumpbench control` (the controller against bench-data's plants P0..P5 of
//! docs/control.md): 1.01..1.02 on the paper's rotor, 2.01..2.03 on twice it, 0.52 on half,
//! 0.26..0.27 on a quarter, 3.0..3.2 on three times and 3.9..4.0 on four, from one scenario's
//! setpoint steps. A torque reading that lags reads low (filtered by 100 ms: 0.69 on the
//! paper's rotor, 1.57 on twice it): the drive's reading filter should be 50 ms or less.
//!
//! A speed reading that lags (a drive's filtered speed estimate) is measured with it: through
//! a first-order lag T the reading's change over an interval is about `Δy = c p + (1 − c) Δω`,
//! `p` the reading's change over the interval before, `c = e^(−dt/T)`, and `Δω = x / f`; so
//! over pairs of consecutive intervals `Δy = c p + d x` by least squares, `f = (1 − c) / d`
//! and `T ≈ dt c / (1 − c)` ([`InertiaProbe::speed_lag_s`]). (The speed ramps within an
//! interval, so this is an approximation: in the tests, J × 0.5..4 read every 50 ms through
//! 20..150 ms, the lag reads up to 23 % long and the inertia up to 16 % light.) Where `c` is
//! small ([`InertiaProbe::LAG_MIN_C`]) or `p` and `x` too alike
//! ([`InertiaProbe::LAG_MIN_SPREAD`]: a model's error then reads as a lag), or where the fit
//! reads the rotor heavier than the ratio (a lag only reads the ratio heavier: that is a
//! model's error too, a dry pump's coast), the ratio stands and no lag is read. The ratio
//! reads a rotor behind a lagging reading heavier: 1.47 × on the paper's rotor at 100 ms,
//! the pair 1.21 ×.
//! Measured through `pumpbench control --speed-lag-ms` (P0, P4 of docs/control.md, J × 2
//! behind a 20 ms drive, J × 0.5 with a 0.1 mca·s²/l water column; one scenario's pressure
//! or flow steps): 0 ms read 0; 20 ms 0..14 (under [`InertiaProbe::LAG_MIN_C`] mostly);
//! 50 ms 33..48; 100 ms 71..93; 150 ms 95..136; the inertia 1.01..1.08, 1.16..1.21,
//! 1.23..1.31 × the paper's on its rotor at 50, 100, 150 ms (2.11, 2.20..2.21, 2.28..2.31 on
//! twice it; 0.59..0.61, 0.66..0.71, 0.74..0.82 on half).

use crate::scalar::Real;

/// The rotor's inertia measured, as a factor of the paper's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaProbe<T> {
    /// The acceleration the paper's J gave the torque surplus `Te − TL` at the last reading
    /// learnt from, rpm/s (NaN: none).
    last_predicted: T,
    /// Σ x², Σ x y and Σ y² over the intervals, rpm².
    sums: [T; 3],
    /// [`InertiaProbe::MIN_SURPLUS_PCT`] as the paper's acceleration, rpm/s.
    min_predicted: T,
    /// The speed change read over the last interval used, rpm (NaN: none): the next pair's
    /// `p`.
    last_moved: T,
    /// Over pairs of consecutive intervals used (`p`, then `x` and `Δy`): Σ p², Σ p x, Σ x²,
    /// Σ Δy p, Σ Δy x, Σ Δy² (rpm²), Σ dt (s) and the pairs.
    pairs: [T; 8],
}

impl<T: Real> Default for InertiaProbe<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real> InertiaProbe<T> {
    /// Σ x² before the factor is used, rpm²: about one 1 mca setpoint step's worth
    /// (80 intervals of 10 rpm predicted; the speed's noise, 0.5 rpm a reading, then moves
    /// the factor by ≈ 1 %).
    pub const EVIDENCE_RPM2: f64 = 8_000.0;
    /// The range of the factor reported.
    pub const RANGE: (f64, f64) = (0.25, 4.0);
    /// An interval longer than this is not used, s.
    pub const MAX_GAP_S: f64 = 0.1;
    /// The least torque surplus a reading teaches from, % of the rated torque (as the paper's
    /// acceleration: [`InertiaProbe::update`] takes it in rpm/s). At a steady speed a drive's torque
    /// reading off the paper's fit by δ % adds `x` with no `y`: a review's plant with a
    /// reading 2 % high, run 10 minutes in manual mode, read the paper's rotor as heavier
    /// and the next pressure steps overshot 10.5 %. Moves run at 20..60 %.
    pub const MIN_SURPLUS_PCT: f64 = 5.0;
    /// The least squared correlation of `x` and `y` for a factor: below it the readings do
    /// not say (Σ x y near 0 read 4 × or 1 × by its sign alone). Moves read 0.9 and more.
    pub const MIN_R2: f64 = 0.5;
    /// When Σ x² passes this, rpm², every sum is halved: the ratio kept, the old evidence
    /// weighing half (about 60 setpoint steps' worth; f32 sums never stop adding).
    pub const SUMS_CAP_RPM2: f64 = 500_000.0;
    /// The least `c` of the pairs' fit that says the speed reading lags: a lag of 12.5 ms at
    /// readings 50 ms apart. A reading with no lag reads 0.001 in the tests; on 200 random
    /// plants of `tools/random_plants.py` (seed 1) with a drive lagging 0..100 ms, curves off
    /// in shape by up to 30 %, but the speed read as it is, 36 read a lag over 0.05 (2.6 ms;
    /// up to 24 ms), and their pressure steps changed with it both ways: 21 figure targets
    /// fewer over six sets of 200.
    pub const LAG_MIN_C: f64 = 0.2;
    /// The least share of Σ p² Σ x² the pairs' determinant holds (1 − ρ², ρ the correlation
    /// of `p` and `x`) for a fit: where the speed read does not lag the two are all but
    /// collinear and a model's error reads as one (a rotor of 1.36 × the paper's with its
    /// speed as it is, a torque curve off in shape by −24 %: 0.25 × and 300 ms at 0.06 after
    /// its first move, then 32 ms at 0.06 and 15 ms at 0.03); with a lag they part (0.09..0.19
    /// at 50 and 100 ms). Over six sets of 200 random plants without a lag, 0.05 changed 26
    /// pressure-step runs (10 figure targets fewer), 0.075 six (the targets the same, 4
    /// comparisons fewer), 0.1 one (1 comparison fewer); with every speed read through
    /// 50 ms (set 3): 6 995, 6 954, 6 896 targets of 7 600 (6 828 without the measurement),
    /// through 100 ms 6 804, 6 741, 6 706 (6 524).
    pub const LAG_MIN_SPREAD: f64 = 0.075;
    /// The longest speed reading's lag reported, s: a drive's speed filter of 0.5 s (some
    /// ship with it) reads as this; beyond, the loops' braking would only start earlier.
    pub const MAX_SPEED_LAG_S: f64 = 0.3;

    /// The evidence gathered, Σ x², rpm² (the factor is used from
    /// [`InertiaProbe::EVIDENCE_RPM2`]).
    pub fn evidence_rpm2(&self) -> T {
        self.sums[0]
    }

    /// Nothing measured: the paper's inertia.
    pub fn new() -> Self {
        Self {
            last_predicted: T::from_f64(f64::NAN),
            sums: [T::ZERO; 3],
            last_moved: T::from_f64(f64::NAN),
            pairs: [T::ZERO; 8],
            min_predicted: T::from_f64(Self::MIN_SURPLUS_PCT)
                * crate::params::BenchParams::<T>::paper().accel_rpm_per_s_per_pct(),
        }
    }

    /// The rotor's inertia as a factor of the paper's within [`InertiaProbe::RANGE`]: with a
    /// speed reading's lag measured, `(1 − c) / d` of the pairs' fit (module docs), else
    /// `Σ x² / Σ x y`; 1 until the sums hold [`InertiaProbe::EVIDENCE_RPM2`] with a squared
    /// correlation of [`InertiaProbe::MIN_R2`] (computed here, not on every reading).
    pub fn factor(&self) -> T {
        self.measured().0.unwrap_or(T::ONE)
    }

    /// The speed reading's first-order lag, s (module docs): `dt c / (1 − c)` at the pairs'
    /// mean interval, at most [`InertiaProbe::MAX_SPEED_LAG_S`]; 0 until the pairs hold
    /// [`InertiaProbe::EVIDENCE_RPM2`] of Σ x² and show a lag.
    pub fn speed_lag_s(&self) -> T {
        self.measured().1
    }

    /// [`InertiaProbe::factor`] and [`InertiaProbe::speed_lag_s`] from one fit (the
    /// controller takes both with each drive reading, on the observer's tick: its longest);
    /// the factor `None` while it is not a measurement (the evidence or the correlation
    /// short: [`InertiaProbe::factor`] then reads 1, the paper's).
    pub fn measured(&self) -> (Option<T>, T) {
        let range = |f: T| {
            f.max(T::from_f64(Self::RANGE.0))
                .min(T::from_f64(Self::RANGE.1))
        };
        let [sxx, sxy, syy] = self.sums;
        if let Some((c, d)) = self.lag_fit() {
            // A lag reads the rotor heavier by the ratio than it is, never lighter: a fit that
            // reads it heavier still is no lag (a dry pump's coast, its load not the curve's,
            // read 3.7 × and 150 ms against the ratio's 3.2 ×; the dry-run rule, told the
            // rotor that heavy, took the coast for a load and cleared).
            let f = (T::ONE - c) / d;
            if sxy > T::ZERO && f * sxy <= sxx {
                let lag = self.pairs[6] / self.pairs[7] * c / (T::ONE - c);
                return (Some(range(f)), lag.min(T::from_f64(Self::MAX_SPEED_LAG_S)));
            }
        }
        let f = (sxx >= T::from_f64(Self::EVIDENCE_RPM2)
            && sxy > T::ZERO
            && sxy * sxy >= T::from_f64(Self::MIN_R2) * sxx * syy)
            .then(|| range(sxx / sxy));
        (f, T::ZERO)
    }

    /// The pairs' fit `Δy = c p + d x` (module docs): `(c, d)` once Σ x² holds the evidence,
    /// with `c` over [`InertiaProbe::LAG_MIN_C`] and under 1, `d > 0` (a lag, a rotor) and the
    /// fit explaining [`InertiaProbe::MIN_R2`] of Σ Δy²; else `None`.
    fn lag_fit(&self) -> Option<(T, T)> {
        let [pp, px, xx, yp, yx, yy, _, _] = self.pairs;
        let det = pp * xx - px * px;
        let c = (yp * xx - yx * px) / det;
        let d = (pp * yx - px * yp) / det;
        // (Not a number fails too.)
        (xx >= T::from_f64(Self::EVIDENCE_RPM2)
            && det >= T::from_f64(Self::LAG_MIN_SPREAD) * pp * xx
            && c > T::from_f64(Self::LAG_MIN_C)
            && c < T::ONE
            && d > T::ZERO
            && c * yp + d * yx >= T::from_f64(Self::MIN_R2) * yy)
            .then_some((c, d))
    }

    /// One fresh drive reading: `learn` (the caller's choice: the pump turning, its moves
    /// wanted), `moved` the speed change since the last reading and the time between them
    /// (rpm, s; zeros without a last reading: they add nothing) and `predicted_rpm_per_s` the
    /// acceleration the paper's inertia gives the torque surplus now
    /// ([`crate::monitor::DriveMotion`]). An interval is used when both its readings were
    /// learnt from (with a surplus of [`InertiaProbe::MIN_SURPLUS_PCT`] at least), finite, and
    /// at most [`InertiaProbe::MAX_GAP_S`] apart.
    // Out of line: inlined into the controller's step, the QEMU image grew by 1 140 B (LLVM
    // then kept `Controller::step` out of the control task); the call costs a few
    // instructions once a drive reading (`cargo xtask bench`).
    #[inline(never)]
    pub fn update(&mut self, learn: bool, moved: (T, T), predicted_rpm_per_s: T) {
        let a0 = self.last_predicted;
        self.last_predicted = if learn && predicted_rpm_per_s.abs() >= self.min_predicted {
            predicted_rpm_per_s
        } else {
            T::from_f64(f64::NAN)
        };
        let (dw, dt) = moved;
        // x: the speed change the paper's J predicts (trapezoid), y = dw the one measured.
        let x = T::from_f64(0.5) * (a0 + self.last_predicted) * dt;
        let (xx, xy, yy) = (x * x, x * dw, dw * dw);
        // Not learning, no last reading learnt from, or a value not finite: `xy` or `yy` is
        // NaN or infinite.
        if xy.is_finite() && yy.is_finite() && dt <= T::from_f64(Self::MAX_GAP_S) {
            // The pair with the interval before, when that one was used too.
            let p = self.last_moved;
            if p.is_finite() {
                let l = &mut self.pairs;
                l[0] += p * p;
                l[1] += p * x;
                l[2] += xx;
                l[3] += dw * p;
                l[4] += xy;
                l[5] += yy;
                l[6] += dt;
                l[7] += T::ONE;
            }
            self.last_moved = dw;
            self.sums[0] += xx;
            self.sums[1] += xy;
            self.sums[2] += yy;
            if self.sums[0] > T::from_f64(Self::SUMS_CAP_RPM2) {
                for s in self.sums.iter_mut().chain(&mut self.pairs) {
                    *s = *s * T::from_f64(0.5);
                }
            }
        } else {
            self.last_moved = T::from_f64(f64::NAN);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::SplitMix64;

    /// A rotor of `factor` × the paper's inertia driven by a square-wave surplus (±10 % for
    /// `half` readings each, ramping between readings), read every `every_s` with ±0.5 rpm of
    /// noise through a first-order lag of `lag_s` (the rotor's speed integrated in steps of
    /// 1 ms, the lag exactly over each): the probe after `readings`.
    fn driven(
        factor: f32,
        lag_s: f32,
        every_s: f32,
        half: u32,
        readings: u32,
    ) -> InertiaProbe<f32> {
        let accel = 100.0;
        let mut p = InertiaProbe::new();
        let mut rng = SplitMix64::new(3);
        let (mut w, mut seen) = (1000.0f32, 1000.0f32);
        let mut last = None;
        let surplus = |k: u32| {
            if (k / half).is_multiple_of(2) {
                10.0
            } else {
                -10.0
            }
        };
        let steps = (every_s * 1e3).round() as u32;
        for k in 0..readings {
            let read = seen + rng.uniform(-0.5, 0.5) as f32;
            p.update(
                true,
                last.map_or((0.0, 0.0), |w0| (read - w0, every_s)),
                accel * surplus(k),
            );
            last = Some(read);
            for j in 0..steps {
                let s =
                    surplus(k) + (surplus(k + 1) - surplus(k)) * (j as f32 + 0.5) / steps as f32;
                w += accel / factor * s * 1e-3;
                seen += (w - seen)
                    * if lag_s > 0.0 {
                        1.0 - (-1e-3 / lag_s).exp()
                    } else {
                        1.0
                    };
            }
        }
        p
    }

    /// Read every 10 ms, the speed as it is, 0.3 s each way.
    fn measured(factor: f32, readings: u32) -> InertiaProbe<f32> {
        driven(factor, 0.0, 0.01, 30, readings)
    }

    /// Read every 50 ms (as the controller takes its readings, with each observer step)
    /// through a lag of `lag_s`, 0.5 s each way.
    fn measured_lagged(factor: f32, lag_s: f32, readings: u32) -> InertiaProbe<f32> {
        driven(factor, lag_s, 0.05, 10, readings)
    }

    /// A speed read through a lag: the lag measured, the inertia nearer than the ratio
    /// alone reads it (J × 0.5..4, lags to 150 ms: the pairs' fit within 16 % low, the ratio
    /// up to 2 × high; the lag within 23 % high); none read where there is none, and there
    /// the ratio stands.
    #[test]
    fn a_lagging_speed_reading_is_measured_with_the_inertia() {
        for f in [0.5f32, 1.0, 2.0, 4.0] {
            for lag in [0.0f32, 0.02, 0.05, 0.1, 0.15] {
                let p = measured_lagged(f, lag, 400);
                let (got_f, got_lag) = (p.factor(), p.speed_lag_s());
                let [sxx, sxy, _] = p.sums;
                let ratio = sxx / sxy;
                if lag == 0.0 {
                    assert_eq!((got_f, got_lag), (ratio.clamp(0.25, 4.0), 0.0), "J {f}");
                    continue;
                }
                assert!((got_f / f - 1.0).abs() < 0.2, "J {f}, lag {lag}: × {got_f}");
                assert!(
                    (got_f / f - 1.0).abs() < (ratio / f - 1.0).abs(),
                    "J {f}, lag {lag}: × {got_f}, the ratio × {ratio}"
                );
                assert!(
                    (got_lag - lag).abs() < 0.25 * lag + 0.003,
                    "J {f}, lag {lag}: {got_lag} s"
                );
            }
        }
    }

    #[test]
    fn the_inertia_is_measured_from_moves() {
        for f in [0.5, 1.0, 2.0, 3.0] {
            let got = measured(f, 1000).factor();
            assert!((got / f - 1.0).abs() < 0.02, "{f}: {got}");
        }
    }

    #[test]
    fn nothing_is_measured_without_motion_or_evidence() {
        let mut p = InertiaProbe::<f32>::new();
        for _ in 0..1000 {
            p.update(true, (0.0, 0.01), 0.0);
        }
        assert_eq!(p.factor(), 1.0);
        // 0.1 s of one move: 900 rpm² of evidence, not enough.
        let p = measured(2.0, 10);
        assert!(p.sums[0] > 0.0 && p.factor() == 1.0, "{p:?}");
        // 1 s: enough.
        let mut p = measured(2.0, 100);
        assert!(p.sums[0] >= 8_000.0 && p.factor() > 1.5, "{p:?}");
        // Not learning: nothing moves.
        let before = p;
        for _ in 0..100 {
            p.update(false, (10.0, 0.01), 1000.0);
        }
        assert_eq!(p.sums, before.sums);
    }

    /// A surplus with no motion to match it (a torque reading off the paper's fit at a
    /// steady speed, the speed's noise alone): `Σ x y` near 0, of either sign, is no factor.
    #[test]
    fn a_surplus_the_speed_does_not_follow_is_no_factor() {
        let mut rng = SplitMix64::new(5);
        for bias in [400.0f32, -400.0] {
            let mut p = InertiaProbe::<f32>::new();
            for _ in 0..20_000 {
                p.update(true, (rng.uniform(-0.7, 0.7) as f32, 0.01), bias);
            }
            assert!(p.sums[0] >= 8_000.0, "{p:?}");
            assert_eq!(p.factor(), 1.0, "{bias}: {p:?}");
        }
    }

    /// Hours of moves: the sums stay bounded ([`InertiaProbe::SUMS_CAP_RPM2`]), the factor
    /// right.
    #[test]
    fn the_sums_stay_bounded() {
        let p = measured(2.0, 200_000);
        assert!(p.sums[0] <= 500_000.0, "{p:?}");
        assert!((p.factor() / 2.0 - 1.0).abs() < 0.02, "{p:?}");
    }

    #[test]
    fn bad_readings_gaps_and_pauses_are_not_used() {
        let mut p = InertiaProbe::<f32>::new();
        let step = (10.0, 0.01);
        p.update(true, (0.0, 0.0), 1000.0);
        p.update(true, step, f32::NAN);
        assert!(p.last_predicted.is_nan());
        p.update(true, step, 1000.0);
        assert_eq!(p.sums, [0.0; 3], "the interval after a bad reading");
        p.update(true, step, 1000.0);
        assert_eq!(p.sums, [100.0; 3]);
        p.update(true, (10.0, 0.11), 1000.0);
        assert_eq!(p.sums, [100.0; 3], "a gap");
        p.update(false, step, 1000.0);
        p.update(true, step, 1000.0);
        assert_eq!(p.sums, [100.0; 3], "the interval after a pause");
        p.update(true, (f32::INFINITY, 0.01), 1000.0);
        assert_eq!(p.sums, [100.0; 3], "a speed not finite");
        assert!(p.factor().is_finite());
    }
}
