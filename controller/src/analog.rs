//! The 4-20 mA transmitters and the ADC that reads them, both ways: the one model of them in
//! the workspace.
//!
//! - Decoding, as the controller's inputs do ([`AnalogInput`]): ADC code → loop current →
//!   NAMUR NE 43 status → engineering value.
//! - Encoding, as the virtual bench (`crate::virtual_bench`) and `pumpbench bench-data` make their
//!   readings: value + [`noise`] → loop current with the transmitter's span, saturated at NE
//!   43's measuring range ([`LoopConfig::transmitter_ma`]) → ADC code
//!   ([`LoopConfig::code`]).
//!
//! The front end is a shunt read by an ADC ([`LoopConfig::typical`]: 150 Ω on a 12-bit,
//! 3.3 V ADC, full scale 22 mA in 4 096 codes).
//!
//! NE 43 bands (loop current I):
//! - 3.8 ≤ I ≤ 20.5 mA: a measurement (3.8..4 and 20..20.5 mA are under/over range, the value
//!   is clamped to the span and flagged);
//! - I < 3.6 mA (broken wire) or I > 21 mA (short): a **fault**, flagged on the sample that
//!   shows it; the value is not used;
//! - 3.6..3.8 and 20.5..21 mA: no fault is raised, but the value is clamped and flagged out of
//!   range.
//!
//! A fault clears with hysteresis: only after [`LoopConfig::clear_samples`] consecutive samples
//! inside the 3.8..20.5 mA band.
//!
//! Every bound is read with one ADC step of tolerance (0.0054 mA on the typical loop): the
//! ADC cannot place a current closer than that, and a healthy transmitter at NE 43's 3.8 mA
//! floor reads one code under it.

use model_core::excitation::SplitMix64;
use model_core::Real;

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
/// cheap on an MCU without `log`/`cos`, and the same sequence on host and target.
pub fn noise(rng: &mut SplitMix64) -> f32 {
    let mut s = 0.0f32;
    for _ in 0..4 {
        s += (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
    }
    (s - 2.0) * 1.732_050_8
}

/// One step of a transmitter's first-order lag (time constant `tau_s`, s; ≤ 0: none), exactly
/// discretised for a value held over the step (`h_s`, s): the reading moves by
/// `(1 − e^(−h/τ)) · (value − reading)`. pumpbench's `bench-data` (f64, any step) uses it.
pub fn lag_exact<T: Real>(reading: &mut T, value: T, h_s: T, tau_s: T) {
    if tau_s <= T::ZERO {
        *reading = value;
    } else {
        *reading += (T::ONE - (-h_s / tau_s).exp()) * (value - *reading);
    }
}

/// One 1 ms step of the same lag by forward Euler (the reading moves by `1 ms / τ` of the
/// gap; τ ≤ 1 ms: none): no `exp` on the MCU. In effect a lag about 0.5 ms shorter than τ:
/// its step response stays within 0.94 % of the step of [`lag_exact`]'s at τ = 20 ms, 0.47 %
/// at 40 ms (test `the_two_lag_steps`). The virtual bench uses it.
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

/// The state of one input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Status {
    /// A measurement inside 4..20 mA.
    #[default]
    Ok,
    /// A measurement outside 4..20 mA but not a fault: the value is clamped to the span.
    OutOfRange,
    /// NE 43 fault (or not yet cleared): the value must not be used.
    Fault,
}

/// One sample of an input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Engineering value, clamped to the span; the last good value while in fault.
    pub value: f32,
    /// Loop current, mA.
    pub current_ma: f32,
    /// What the sample means.
    pub status: Status,
}

/// A 4-20 mA input with its fault latch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalogInput {
    config: LoopConfig,
    faulted: bool,
    good_run: u16,
    last_good: f32,
}

impl AnalogInput {
    /// A new input; `None` if the configuration is not valid. Starts without a fault, the
    /// last good value at the 4 mA value.
    pub fn new(config: LoopConfig) -> Option<Self> {
        config.is_valid().then_some(Self {
            config,
            faulted: false,
            good_run: 0,
            last_good: config.value_at_4ma,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &LoopConfig {
        &self.config
    }

    /// `true` while a fault is latched.
    pub fn faulted(&self) -> bool {
        self.faulted
    }

    /// Takes one ADC sample.
    pub fn sample(&mut self, code: u16) -> Reading {
        let i = self.config.current_ma(code);
        // One ADC step of tolerance on every bound, as on the 4..20 mA one below: a
        // transmitter saturated at 3.8 mA (NE 43's floor, where it sits at rest when the
        // process is below its span) reads one code under it (code 707 = 3.798 mA on the
        // typical loop) and must clear a fault.
        let lsb = self.config.current_ma(1);
        let fault = !(FAULT_LOW_MA - lsb..=FAULT_HIGH_MA + lsb).contains(&i);
        let valid = (VALID_LOW_MA - lsb..=VALID_HIGH_MA + lsb).contains(&i);
        if fault {
            self.faulted = true;
            self.good_run = 0;
        } else if self.faulted {
            if valid {
                self.good_run = self.good_run.saturating_add(1);
                if self.good_run >= self.config.clear_samples {
                    self.faulted = false;
                }
            } else {
                self.good_run = 0;
            }
        }
        if self.faulted {
            return Reading {
                value: self.last_good,
                current_ma: i,
                status: Status::Fault,
            };
        }
        let value = self.config.value(i);
        self.last_good = value;
        // 4.000 mA must not read as out of range at 3.9997 mA.
        Reading {
            value,
            current_ma: i,
            status: if (4.0 - lsb..=20.0 + lsb).contains(&i) {
                Status::Ok
            } else {
                Status::OutOfRange
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// ADC code for a loop current (the shared encoder).
    fn code(c: &LoopConfig, ma: f32) -> u16 {
        c.code(ma)
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

    /// Value → transmitter → ADC code → input: within one code's worth of the value inside
    /// the span, for a rising and a falling span.
    #[test]
    fn a_value_encoded_reads_back_within_one_code() {
        for c in [
            LoopConfig::typical(0.0, 10.0),
            LoopConfig::typical(0.0, 30.0),
            LoopConfig::typical(30.0, -5.0),
        ] {
            let (lo, hi) = (c.value_at_4ma, c.value_at_20ma);
            let lsb = c.current_ma(1) / 16.0 * (hi - lo).abs();
            let mut a = AnalogInput::new(c).unwrap();
            for k in 0..=1000 {
                let v = lo + (hi - lo) * k as f32 / 1000.0;
                let r = a.sample(c.code(c.transmitter_ma(v)));
                assert!((r.value - v).abs() <= lsb, "{c:?}: {v} → {r:?}");
                assert_ne!(r.status, Status::Fault);
                let back = c.value_unclamped(c.current_ma(c.code(c.transmitter_ma(v))));
                assert!(
                    (back - v).abs() <= lsb / 2.0 + 1e-5 * v.abs(),
                    "{v} → {back}"
                );
            }
        }
    }

    /// NE 43 through the shared model: a healthy transmitter saturates inside the measuring
    /// range and never reads as a fault, however far the process leaves the span; a current
    /// forced outside the fault bounds (a broken wire, a short) does, within one code.
    #[test]
    fn ne43_edges_through_the_shared_transmitter() {
        let c = LoopConfig::typical(0.0, 10.0);
        assert_eq!(c.transmitter_ma(-1e6), VALID_LOW_MA);
        assert_eq!(c.transmitter_ma(1e6), VALID_HIGH_MA);
        assert!(c.transmitter_ma(f32::NAN).is_nan());
        for v in [-1e6, -3.0, -0.125, 10.3125, 12.0, 1e6] {
            let mut a = AnalogInput::new(c).unwrap();
            let r = a.sample(c.code(c.transmitter_ma(v)));
            assert_eq!(r.status, Status::OutOfRange, "{v}");
            assert_eq!(r.value, v.clamp(0.0, 10.0), "{v}");
        }
        let lsb = c.current_ma(1);
        for (ma, fault) in [
            (FAULT_LOW_MA, false),
            (FAULT_LOW_MA - 2.0 * lsb, true),
            (FAULT_HIGH_MA, false),
            (FAULT_HIGH_MA + 2.0 * lsb, true),
            (2.0, true),
        ] {
            let mut a = AnalogInput::new(c).unwrap();
            assert_eq!(
                a.sample(c.code(ma)).status == Status::Fault,
                fault,
                "{ma} mA"
            );
        }
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

    #[test]
    fn scales_within_a_code() {
        let c = LoopConfig::typical(0.0, 10.0);
        let mut a = AnalogInput::new(c).unwrap();
        for (ma, expected) in [(4.0, 0.0), (12.0, 5.0), (20.0, 10.0)] {
            let r = a.sample(code(&c, ma));
            let lsb_value = c.current_ma(1) / 16.0 * 10.0;
            assert!((r.value - expected).abs() <= lsb_value, "{ma} mA → {r:?}");
            assert_eq!(r.status, Status::Ok);
        }
        // Inverted span (20 mA = the low end) works too.
        let mut inv = AnalogInput::new(LoopConfig::typical(30.0, 0.0)).unwrap();
        assert!((inv.sample(code(&c, 20.0)).value).abs() < 0.02);
    }

    #[test]
    fn namur_bands() {
        let c = LoopConfig::typical(0.0, 10.0);
        let mut a = AnalogInput::new(c).unwrap();
        let r = a.sample(code(&c, 3.9));
        assert_eq!((r.status, r.value), (Status::OutOfRange, 0.0));
        let r = a.sample(code(&c, 20.4));
        assert_eq!((r.status, r.value), (Status::OutOfRange, 10.0));
        // 3.7 mA: between the bands, no fault, clamped.
        assert_eq!(a.sample(code(&c, 3.7)).status, Status::OutOfRange);
        assert!(!a.faulted());
    }

    #[test]
    fn fault_within_one_sample_and_clears_with_hysteresis() {
        let c = LoopConfig::typical(0.0, 10.0);
        let mut a = AnalogInput::new(c).unwrap();
        let good = a.sample(code(&c, 12.0)).value;
        for ma in [0.0, 3.5, 21.2, 30.0] {
            let mut b = a;
            let r = b.sample(code(&c, ma));
            assert_eq!(r.status, Status::Fault, "{ma} mA");
            assert_eq!(r.value, good, "keeps the last good value");
        }
        let r = a.sample(code(&c, 2.0));
        assert_eq!(r.status, Status::Fault);
        // Back between the bands (3.7 mA): still faulted, the run does not start.
        assert_eq!(a.sample(code(&c, 3.7)).status, Status::Fault);
        // Two good samples are not enough, the third clears.
        assert_eq!(a.sample(code(&c, 8.0)).status, Status::Fault);
        assert_eq!(a.sample(code(&c, 8.0)).status, Status::Fault);
        let r = a.sample(code(&c, 8.0));
        assert_eq!(r.status, Status::Ok);
        assert!((r.value - 2.5).abs() < 0.01);
        // A fault in the middle of a good run restarts it.
        a.sample(code(&c, 25.0));
        a.sample(code(&c, 8.0));
        a.sample(code(&c, 25.0));
        a.sample(code(&c, 8.0));
        assert!(a.faulted());
    }

    /// Regression (defect 1 of the protection issue): a fault injected at rest never
    /// cleared: a healthy transmitter at NE 43's floor (3.8 mA, the outlet below the span)
    /// reads code 707 = 3.798 mA, one step under the 3.8 mA bound that clears a fault.
    #[test]
    fn a_transmitter_at_its_floor_clears_a_fault() {
        let c = LoopConfig::typical(0.0, 10.0);
        let floor = code(&c, VALID_LOW_MA);
        assert_eq!(floor, 707);
        assert!(c.current_ma(floor) < VALID_LOW_MA);
        let mut a = AnalogInput::new(c).unwrap();
        assert_eq!(a.sample(code(&c, 2.0)).status, Status::Fault);
        a.sample(floor);
        a.sample(floor);
        let r = a.sample(floor);
        assert!(!a.faulted(), "3 samples at the floor clear the fault");
        assert_eq!((r.status, r.value), (Status::OutOfRange, 0.0));
        // Two codes under the floor still do not clear it; at the fault bound, one code of
        // tolerance, two are a fault.
        assert_eq!(a.sample(code(&c, 2.0)).status, Status::Fault);
        for _ in 0..5 {
            assert_eq!(a.sample(floor - 2).status, Status::Fault);
        }
        let mut b = AnalogInput::new(c).unwrap();
        let at = code(&c, FAULT_LOW_MA);
        assert_ne!(b.sample(at).status, Status::Fault);
        assert_eq!(b.sample(at - 2).status, Status::Fault);
    }

    #[test]
    fn every_code_gives_a_finite_clamped_value() {
        let c = LoopConfig::typical(-1.0, 4.0);
        let mut a = AnalogInput::new(c).unwrap();
        for code in 0..=u16::MAX {
            let r = a.sample(code);
            assert!(
                r.value.is_finite() && (-1.0..=4.0).contains(&r.value),
                "{code}: {r:?}"
            );
        }
    }

    #[test]
    fn bad_configurations_are_refused() {
        let ok = LoopConfig::typical(0.0, 10.0);
        for bad in [
            LoopConfig {
                shunt_ohm: 0.0,
                ..ok
            },
            LoopConfig {
                adc_ref_v: f32::NAN,
                ..ok
            },
            LoopConfig { adc_bits: 0, ..ok },
            LoopConfig { adc_bits: 17, ..ok },
            LoopConfig {
                value_at_20ma: 0.0,
                ..ok
            },
            LoopConfig {
                clear_samples: 0,
                ..ok
            },
        ] {
            assert!(AnalogInput::new(bad).is_none(), "{bad:?}");
        }
    }
}
