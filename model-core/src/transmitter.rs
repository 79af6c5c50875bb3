//! The 4-20 mA transmitters of the pump bench and the front end that reads them: the one
//! simulation model of them in the workspace, below every crate that simulates a reading
//! (the controller's virtual bench, pumpbench's `bench-data`, the observer's and the monitor's
//! synthetic records).
//!
//! - [`LoopConfig`]: a transmitter's span and the board's front end (a shunt read by an ADC;
//!   [`LoopConfig::typical`]: 150 Ω on a 12-bit, 3.3 V ADC, full scale 22 mA in 4 096 codes),
//!   both ways: value → loop current with NAMUR NE 43 saturation
//!   ([`LoopConfig::transmitter_ma`]) → ADC code ([`LoopConfig::code`]), and back
//!   ([`LoopConfig::current_ma`], [`LoopConfig::value`], [`LoopConfig::value_unclamped`]).
//! - [`noise`]: the transmitters' noise (a sum of four uniform draws, unit variance).
//! - The first-order lag of a transmitter (or a drive, or a water column) in its two
//!   discretisations: exact for a held value ([`lag_exact`], [`lag_to`], from [`decay`]) and
//!   the 1 ms forward step ([`lag_1ms`]).
//!
//! The controller's side, ADC code → NE 43 status → value with its fault latch, is
//! `controller::analog` (which re-exports this module's names).

use crate::excitation::SplitMix64;
use crate::Real;

/// Below this loop current (mA) the transmitter is faulty (NE 43: broken wire).
pub const FAULT_LOW_MA: f32 = 3.6;
/// Above this loop current (mA) the transmitter is faulty (NE 43: short circuit).
pub const FAULT_HIGH_MA: f32 = 21.0;
/// Lower end of the valid signal band (mA).
pub const VALID_LOW_MA: f32 = 3.8;
/// Upper end of the valid signal band (mA).
pub const VALID_HIGH_MA: f32 = 20.5;

/// The pump bench's pressure transmitter: 0..10 mca on a [`LoopConfig::typical`] loop.
pub const PRESSURE_LOOP: LoopConfig = LoopConfig::typical(0.0, 10.0);
/// The pump bench's flow transmitter: 0..30 l/s on a [`LoopConfig::typical`] loop.
pub const FLOW_LOOP: LoopConfig = LoopConfig::typical(0.0, 30.0);

/// A transmitter's noise, unit variance, one draw from `rng`: the sum of four uniform draws
/// (24 bits of a SplitMix64 word each), scaled to unit variance. Bounded (±√12 ≈ ±3.46 σ),
/// cheap on an MCU without `log`/`cos`, and the same sequence on host and target. (Out of
/// line: inlined at the virtual bench's two transmitters it cost the QEMU image 144 B more,
/// for 12 instructions less on the longest tick, `cargo xtask bench`.)
#[inline(never)]
pub fn noise(rng: &mut SplitMix64) -> f32 {
    let mut s = 0.0f32;
    for _ in 0..4 {
        s += (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
    }
    (s - 2.0) * 1.732_050_8
}

/// A first-order lag's decay over `h_s` seconds, `e^(−h/τ)` (τ = `tau_s`, s; 0 without a
/// lag, `tau_s` ≤ 0): the one law of the workspace's first-order lags ([`lag_exact`],
/// [`lag_to`], the observer's process model).
#[inline]
pub fn decay<T: Real>(h_s: T, tau_s: T) -> T {
    if tau_s > T::ZERO {
        (-h_s / tau_s).exp()
    } else {
        T::ZERO
    }
}

/// `x` after `h_s` seconds of a first-order lag (time constant `tau_s`, s; ≤ 0: none, the
/// target) toward a held `target`: `target + (x − target) · e^(−h/τ)`. The observer's
/// process model (its drive and water column) and pumpbench's `bench-data` (its drive) use it.
#[inline]
pub fn lag_to<T: Real>(x: T, target: T, h_s: T, tau_s: T) -> T {
    if tau_s > T::ZERO {
        target + (x - target) * decay(h_s, tau_s)
    } else {
        target
    }
}

/// One step of a transmitter's first-order lag (time constant `tau_s`, s; ≤ 0: none), exactly
/// discretised for a value held over the step (`h_s`, s): the reading moves by
/// `(1 − e^(−h/τ)) · (value − reading)`. pumpbench's `bench-data` (f64, any step) and the
/// observer's synthetic records (f64, 1 ms) use it.
#[inline]
pub fn lag_exact<T: Real>(reading: &mut T, value: T, h_s: T, tau_s: T) {
    if tau_s <= T::ZERO {
        *reading = value;
    } else {
        *reading += (T::ONE - decay(h_s, tau_s)) * (value - *reading);
    }
}

/// The process value behind a transmitter's reading, from the reading now (`reading`) and
/// `h_s` seconds before (`previous`), for a first-order lag of `tau_s` (s; ≤ 0: none, the
/// reading itself): `x = y + τ·dy/dt` (the lag `τ·dy/dt + y = x` solved for `x`), the
/// derivative a backward difference, `reading + τ/h · (reading − previous)`. Exact while the
/// process value moves along a ramp behind a continuous lag (behind the 1 ms steps of
/// `bench-data` and the virtual bench, within half a step); for a smooth series, a model's
/// prediction of a reading. On a noisy reading it amplifies the noise by up to `1 + 2τ/h`.
#[inline]
pub fn unlag<T: Real>(reading: T, previous: T, h_s: T, tau_s: T) -> T {
    if tau_s <= T::ZERO || h_s <= T::ZERO {
        reading
    } else {
        reading + tau_s / h_s * (reading - previous)
    }
}

/// One 1 ms step of the same lag by forward Euler (the reading moves by `1 ms / τ` of the
/// gap; τ ≤ 1 ms: none): no `exp` on the MCU. In effect a lag about 0.5 ms shorter than τ:
/// its step response stays within 0.94 % of the step of [`lag_exact`]'s at τ = 20 ms, 0.47 %
/// at 40 ms (test `the_two_lag_steps`). The virtual bench (`controller::virtual_bench`) uses
/// it.
#[inline]
pub fn lag_1ms(reading: &mut f32, value: f32, tau_s: f32) {
    let coefficient = if tau_s > 1e-3 { 1e-3 / tau_s } else { 1.0 };
    *reading += (value - *reading) * coefficient;
}

/// One 4-20 mA input: the shunt and ADC that read it, and the transmitter's span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopConfig {
    /// Shunt resistor, Ω (> 0): the ADC reads I · R.
    pub shunt_ohm: f32,
    /// ADC reference voltage, V (> 0).
    pub adc_ref_v: f32,
    /// ADC resolution, bits (1..=16).
    pub adc_bits: u8,
    /// Engineering value at 4 mA (e.g. 0 mca).
    pub value_at_4ma: f32,
    /// Engineering value at 20 mA (e.g. 10 mca); may be below `value_at_4ma`.
    pub value_at_20ma: f32,
    /// Consecutive good samples that clear a fault (≥ 1).
    pub clear_samples: u16,
}

impl LoopConfig {
    /// A 150 Ω shunt on a 12-bit, 3.3 V ADC (full scale 22 mA), span `lo..hi`, faults clear
    /// after 3 good samples.
    pub const fn typical(value_at_4ma: f32, value_at_20ma: f32) -> Self {
        Self {
            shunt_ohm: 150.0,
            adc_ref_v: 3.3,
            adc_bits: 12,
            value_at_4ma,
            value_at_20ma,
            clear_samples: 3,
        }
    }

    /// `true` if every field is usable (finite, positive shunt and reference, 1..=16 bits,
    /// a non-empty span, at least one clearing sample).
    pub fn is_valid(&self) -> bool {
        self.shunt_ohm.is_finite()
            && self.shunt_ohm > 0.0
            && self.adc_ref_v.is_finite()
            && self.adc_ref_v > 0.0
            && (1..=16).contains(&self.adc_bits)
            && self.value_at_4ma.is_finite()
            && self.value_at_20ma.is_finite()
            && self.value_at_4ma != self.value_at_20ma
            && self.clear_samples >= 1
    }

    /// The ADC code of a loop current (mA), rounded to the nearest code within 0..=full scale
    /// (2^bits − 1); NaN reads 0. The inverse of [`Self::current_ma`] within half a code.
    #[inline]
    pub fn code(&self, current_ma: f32) -> u16 {
        let full = ((1u32 << self.adc_bits) - 1) as f32;
        let code = current_ma * 1e-3 * self.shunt_ohm / self.adc_ref_v * full + 0.5;
        if code.is_nan() {
            0
        } else {
            code.clamp(0.0, full) as u16
        }
    }

    /// The loop current (mA) a transmitter with this span drives for `value` (engineering
    /// units): 4..20 mA over the span, saturated at NE 43's measuring range
    /// ([`VALID_LOW_MA`]..=[`VALID_HIGH_MA`]) as a healthy transmitter does; NaN stays NaN.
    #[inline]
    pub fn transmitter_ma(&self, value: f32) -> f32 {
        let span = self.value_at_20ma - self.value_at_4ma;
        (4.0 + 16.0 * (value - self.value_at_4ma) / span).clamp(VALID_LOW_MA, VALID_HIGH_MA)
    }

    /// Loop current (mA) for an ADC code (codes above full scale read as full scale).
    pub fn current_ma(&self, code: u16) -> f32 {
        let full = ((1u32 << self.adc_bits) - 1) as f32;
        let code = (code as f32).min(full);
        code / full * self.adc_ref_v / self.shunt_ohm * 1000.0
    }

    /// Engineering value for a loop current, clamped to the span (4..20 mA): what the
    /// controller's input uses.
    pub fn value(&self, current_ma: f32) -> f32 {
        self.value_unclamped(current_ma.clamp(4.0, 20.0))
    }

    /// Engineering value for a loop current on the span's line, not clamped (3.8 mA on a
    /// 0..10 span is −0.125): what a logger records over the measuring range.
    pub fn value_unclamped(&self, current_ma: f32) -> f32 {
        self.value_at_4ma + (current_ma - 4.0) / 16.0 * (self.value_at_20ma - self.value_at_4ma)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `unlag` gives back a process value lagged at 1 ms (as `bench-data` and the virtual bench
    /// lag it) from readings taken every 50 or 100 ms: on a ramp within the 1 ms steps' half
    /// step, on a smooth process within a fifth of the reading's own error; without a lag it
    /// is the reading.
    #[test]
    fn unlag_gives_back_the_process_value_behind_a_lag() {
        let process = |t: f64| 2.0 + 0.8 * t + (1.3 * t).sin();
        for (h_ms, tau) in [(50u32, 0.02), (50, 0.06), (100, 0.15)] {
            let h = f64::from(h_ms) * 1e-3;
            // The reading settled on the ramp 0.8 t + 2 before t = 0 (a lag of τ behind it).
            let mut reading = 2.0 - 0.8 * tau;
            let ramp = |t: f64| 2.0 + 0.8 * t;
            let mut ramp_reading = reading;
            let (mut prev, mut prev_ramp) = (reading, ramp_reading);
            let (mut worst, mut worst_lagged, mut worst_ramp) = (0.0f64, 0.0f64, 0.0f64);
            for ms in 1..=10_000u32 {
                let t = f64::from(ms) * 1e-3;
                lag_exact(&mut reading, process(t), 1e-3, tau);
                lag_exact(&mut ramp_reading, ramp(t), 1e-3, tau);
                if ms % h_ms == 0 {
                    let x = unlag(reading, prev, h, tau);
                    worst = worst.max((x - process(t)).abs());
                    worst_lagged = worst_lagged.max((reading - process(t)).abs());
                    let r = unlag(ramp_reading, prev_ramp, h, tau);
                    worst_ramp = worst_ramp.max((r - ramp(t)).abs());
                    (prev, prev_ramp) = (reading, ramp_reading);
                }
            }
            // On the ramp: the lag's 1 ms steps (the value held over each) lag half a step
            // more than a continuous lag; the slope × 1 ms bounds that.
            assert!(worst_ramp < 0.8e-3, "h {h} τ {tau}: ramp {worst_ramp:e}");
            // Measured: 15, 14 and 13 % of the reading's own error (the inverse of one lag
            // step with the value held over the sample, tried first, was 77, 35 and 30 %).
            assert!(
                worst < 0.2 * worst_lagged,
                "h {h} τ {tau}: {worst:.5} against the reading's {worst_lagged:.5}"
            );
        }
        assert_eq!(unlag(2.0, 1.0, 0.05, 0.0), 2.0);
        assert_eq!(unlag(2.0f32, 1.0, 0.0, 0.1), 2.0);
    }

    /// The exact lag follows 1 − e^(−t/τ) of a step; the 1 ms forward step follows it within
    /// the bounds its docs state.
    #[test]
    fn the_two_lag_steps() {
        for (tau, bound) in [(0.02f32, 0.0094), (0.04, 0.0047)] {
            let (mut exact, mut euler, mut worst) = (0.0f64, 0.0f32, 0.0f64);
            for n in 1..=2000 {
                lag_exact(&mut exact, 1.0, 1e-3, f64::from(tau));
                lag_1ms(&mut euler, 1.0, tau);
                worst = worst.max((exact - f64::from(euler)).abs());
                // The exact step response, 1 − e^(−t/τ), at every step.
                let t = n as f64 * 1e-3;
                let response = 1.0 - (-t / f64::from(tau)).exp();
                assert!((exact - response).abs() < 1e-12, "{tau}, {n}: {exact}");
            }
            assert!(worst <= bound && worst > 0.9 * bound, "{tau}: {worst}");
        }
        let (mut x, mut y) = (0.25f64, 0.25f32);
        lag_exact(&mut x, 1.0, 1e-3, 0.0);
        lag_1ms(&mut y, 1.0, 0.0);
        assert_eq!((x, y), (1.0, 1.0), "no lag: the value itself");
    }

    #[test]
    fn every_code_is_its_own_current_encoded() {
        for c in [
            LoopConfig::typical(0.0, 10.0),
            LoopConfig {
                adc_bits: 16,
                ..LoopConfig::typical(0.0, 10.0)
            },
        ] {
            let full = (1u32 << c.adc_bits) - 1;
            for k in 0..=full {
                assert_eq!(u32::from(c.code(c.current_ma(k as u16))), k, "{c:?}");
            }
            assert_eq!(u32::from(c.code(1e3)), full, "above full scale");
            assert_eq!((c.code(-1.0), c.code(f32::NAN)), (0, 0));
        }
        // The typical front end: 22 mA over 4 095 steps.
        let c = LoopConfig::typical(0.0, 10.0);
        assert!((c.current_ma(4095) - 22.0).abs() < 1e-5);
        assert_eq!(c.code(12.0), (12.0f32 / 22.0 * 4095.0).round() as u16);
    }

    #[test]
    fn noise_has_unit_variance_and_is_bounded() {
        let mut rng = SplitMix64::new(5);
        let n = 100_000;
        let xs: Vec<f32> = (0..n).map(|_| noise(&mut rng)).collect();
        let mean = xs.iter().sum::<f32>() / n as f32;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f32>() / n as f32;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
            "{mean} {var}"
        );
        assert!(xs.iter().all(|x| x.abs() <= 12f32.sqrt()));
    }

    /// The closed form toward a held target is the exact step of the same lag: both follow
    /// 1 − e^(−t/τ) of a step; no lag (τ ≤ 0) gives the target, and a decay of 0.
    #[test]
    fn lag_to_is_the_exact_lag() {
        let tau = 0.03f64;
        let (mut to, mut exact) = (0.0f64, 0.0f64);
        for n in 1..=500 {
            to = lag_to(to, 1.0, 1e-3, tau);
            lag_exact(&mut exact, 1.0, 1e-3, tau);
            let response = 1.0 - (-(n as f64) * 1e-3 / tau).exp();
            assert!((to - response).abs() < 1e-12, "{n}: {to}");
            assert!((to - exact).abs() < 1e-12, "{n}: {to} {exact}");
        }
        assert_eq!(decay(1e-3f32, 0.02), (-1e-3f32 / 0.02).exp());
        assert_eq!((decay(1e-3f64, 0.0), decay(1e-3f64, -1.0)), (0.0, 0.0));
        assert_eq!(lag_to(0.25f32, 1.0, 1e-3, 0.0), 1.0);
    }

    /// A healthy transmitter saturates inside NE 43's measuring range however far the
    /// process leaves its span; NaN stays NaN.
    #[test]
    fn the_transmitter_saturates_at_ne43s_measuring_range() {
        let c = LoopConfig::typical(0.0, 10.0);
        assert_eq!(c.transmitter_ma(-1e6), VALID_LOW_MA);
        assert_eq!(c.transmitter_ma(1e6), VALID_HIGH_MA);
        assert!(c.transmitter_ma(f32::NAN).is_nan());
        assert_eq!(c.transmitter_ma(0.0), 4.0);
        assert_eq!(c.transmitter_ma(10.0), 20.0);
    }
}
