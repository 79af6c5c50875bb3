//! The 4-20 mA inputs as the controller reads them: ADC code → loop current → NAMUR NE 43
//! status → engineering value ([`AnalogInput`]), with its fault latch.
//!
//! The transmitters' simulation model (span → loop current saturated at NE 43's measuring
//! range, loop current → ADC code, the noise, the first-order lag in both discretisations) and
//! the front end's description ([`LoopConfig`]) live below, in `model_core::transmitter`, the
//! one model of them in the workspace; this module re-exports them under their old names for
//! the virtual bench (`crate::virtual_bench`) and `pumpbench bench-data`.
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

pub use model_core::transmitter::{
    lag_1ms, lag_exact, noise, LoopConfig, FAULT_HIGH_MA, FAULT_LOW_MA, FLOW_LOOP, PRESSURE_LOOP,
    VALID_HIGH_MA, VALID_LOW_MA,
};

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

    /// Reads one ADC code without counting it as a sample: the fault state neither latches
    /// nor clears (its timing stays the models' sampling's, whatever else reads the loop); a
    /// code outside the fault bounds, or a latched fault, reads as [`Status::Fault`] with
    /// the last good value. The control loops' extra readings (every 5 ms) use it.
    pub fn peek(&self, code: u16) -> Reading {
        let mut probe = *self;
        let r = probe.sample(code);
        if self.faulted && r.status != Status::Fault {
            return Reading {
                value: self.last_good,
                current_ma: r.current_ma,
                status: Status::Fault,
            };
        }
        r
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

    /// ADC code for a loop current (the shared encoder).
    fn code(c: &LoopConfig, ma: f32) -> u16 {
        c.code(ma)
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
        // (Its saturation itself is tested next to it, in `model_core::transmitter`.)
        let c = LoopConfig::typical(0.0, 10.0);
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
