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
            min_predicted: T::from_f64(Self::MIN_SURPLUS_PCT)
                * crate::params::BenchParams::<T>::paper().accel_rpm_per_s_per_pct(),
        }
    }

    /// The rotor's inertia as a factor of the paper's, `Σ x² / Σ x y` within
    /// [`InertiaProbe::RANGE`]; 1 until the sums hold [`InertiaProbe::EVIDENCE_RPM2`] with a
    /// squared correlation of [`InertiaProbe::MIN_R2`] (computed here, not on every reading).
    pub fn factor(&self) -> T {
        let [sxx, sxy, syy] = self.sums;
        if sxx >= T::from_f64(Self::EVIDENCE_RPM2)
            && sxy > T::ZERO
            && sxy * sxy >= T::from_f64(Self::MIN_R2) * sxx * syy
        {
            (sxx / sxy)
                .max(T::from_f64(Self::RANGE.0))
                .min(T::from_f64(Self::RANGE.1))
        } else {
            T::ONE
        }
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
            self.sums[0] += xx;
            self.sums[1] += xy;
            self.sums[2] += yy;
            if self.sums[0] > T::from_f64(Self::SUMS_CAP_RPM2) {
                for s in &mut self.sums {
                    *s = *s * T::from_f64(0.5);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::excitation::SplitMix64;

    /// A rotor of `factor` × the paper's inertia driven by a square-wave surplus, read every
    /// 10 ms with ±0.5 rpm of noise: the probe after `readings`.
    fn measured(factor: f32, readings: u32) -> InertiaProbe<f32> {
        let accel = 100.0;
        let mut p = InertiaProbe::new();
        let mut rng = SplitMix64::new(3);
        let mut w = 1000.0f32;
        let mut last = None;
        // +10 % for 0.3 s, −10 % for 0.3 s, ..., the torque ramping between readings.
        let surplus = |k: u32| {
            if (k / 30).is_multiple_of(2) {
                10.0
            } else {
                -10.0
            }
        };
        for k in 0..readings {
            let read = w + rng.uniform(-0.5, 0.5) as f32;
            p.update(
                true,
                last.map_or((0.0, 0.0), |w0| (read - w0, 0.01)),
                accel * surplus(k),
            );
            last = Some(read);
            w += accel / factor * 0.5 * (surplus(k) + surplus(k + 1)) * 0.01;
        }
        p
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
