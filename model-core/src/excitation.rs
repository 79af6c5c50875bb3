//! The paper's excitation: pulses of uncorrelated amplitudes, uniform in a torque range, held
//! for random times. Seeded and reproducible on every target.
//!
//! The generator is SplitMix64 (Steele, Lea, Flood 2014), written out here (ten lines)
//! rather than taken from `rand`: its sequence is fixed by this crate's tests, so an
//! excitation made on the host with a seed is bit-for-bit the one the firmware makes.

use core::num::NonZeroU32;

/// SplitMix64 pseudo-random generator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator from a seed (any value).
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

/// One pulse: a torque reference held for a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pulse {
    /// Torque reference, % of nominal torque.
    pub torque_ref_pct: f64,
    /// How long it is held, s.
    pub hold_s: f64,
}

/// Pulses with amplitudes uniform in `[min_pct, max_pct)` and holds uniform in
/// `[min_hold_s, max_hold_s)`, optionally rounded up to a multiple of a sample period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PulseTrain {
    rng: SplitMix64,
    /// Lowest amplitude, % (paper: 5).
    pub min_pct: f64,
    /// Highest amplitude, % (paper: 85).
    pub max_pct: f64,
    /// Shortest hold, s.
    pub min_hold_s: f64,
    /// Longest hold, s.
    pub max_hold_s: f64,
    /// If > 0, holds are rounded to a whole number (≥ 1) of this period, s.
    pub period_s: f64,
}

impl PulseTrain {
    /// The paper's range 5..85 %, holds of 0.5..3 s, no rounding.
    pub const fn paper(seed: u64) -> Self {
        Self {
            rng: SplitMix64::new(seed),
            min_pct: 5.0,
            max_pct: 85.0,
            min_hold_s: 0.5,
            max_hold_s: 3.0,
            period_s: 0.0,
        }
    }

    /// Next pulse.
    pub fn next_pulse(&mut self) -> Pulse {
        let torque_ref_pct = self.rng.uniform(self.min_pct, self.max_pct);
        let mut hold_s = self.rng.uniform(self.min_hold_s, self.max_hold_s);
        if self.period_s > 0.0 {
            let n = libm::round(hold_s / self.period_s).max(1.0);
            hold_s = n * self.period_s;
        }
        Pulse {
            torque_ref_pct,
            hold_s,
        }
    }
}

impl Iterator for PulseTrain {
    type Item = Pulse;
    fn next(&mut self) -> Option<Pulse> {
        Some(self.next_pulse())
    }
}

/// A [`PulseTrain`] on a grid of whole-millisecond steps: yields `(t_ms, torque_ref_pct)` for
/// each step, the torque to hold from `t_ms` to `t_ms + step_ms`. Hold times are rounded to
/// whole steps (at least one). The firmware's built-in excitation, and its host replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteppedPulses {
    train: PulseTrain,
    step_ms: u32,
    t_ms: u32,
    next_change_ms: u32,
    torque_ref_pct: f64,
}

impl SteppedPulses {
    /// Steps of `step_ms` (≥ 1) ms through `train`.
    pub fn new(mut train: PulseTrain, step_ms: u32) -> Self {
        let step_ms = step_ms.max(1);
        train.period_s = step_ms as f64 * 1e-3;
        Self {
            train,
            step_ms,
            t_ms: 0,
            next_change_ms: 0,
            torque_ref_pct: 0.0,
        }
    }
}

impl Iterator for SteppedPulses {
    type Item = (u32, f64);
    fn next(&mut self) -> Option<(u32, f64)> {
        if self.t_ms == self.next_change_ms {
            let p = self.train.next_pulse();
            self.torque_ref_pct = p.torque_ref_pct;
            let steps = libm::round(p.hold_s * 1e3 / self.step_ms as f64) as u32;
            self.next_change_ms = self
                .next_change_ms
                .checked_add(steps.max(1) * self.step_ms)?;
        }
        let t = self.t_ms;
        self.t_ms = self.t_ms.checked_add(self.step_ms)?;
        Some((t, self.torque_ref_pct))
    }
}

/// The paper's pulses (amplitudes uniform in 5..85 %, holds uniform in 0.5..3 s) on a grid of
/// whole-millisecond steps, in f32 and integer arithmetic only: the firmware's built-in
/// excitation (an MCU without double-precision hardware would otherwise carry software f64).
/// Yields `(t_ms, torque_ref_pct)` like [`SteppedPulses`], with the same distribution but not
/// the same sequence: amplitudes take 24 random bits, holds are drawn in whole milliseconds
/// and rounded to whole steps (at least one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McuPulses {
    rng: SplitMix64,
    /// Not 0 by its type: the divisions by it need no check (nor the panic path that comes
    /// with one, ≈ 0.1 KB of an MCU image).
    step_ms: NonZeroU32,
    t_ms: u32,
    next_change_ms: u32,
    torque_ref_pct: f32,
}

impl McuPulses {
    /// Lowest amplitude, %.
    pub const MIN_PCT: f32 = 5.0;
    /// Highest amplitude (excluded), %.
    pub const MAX_PCT: f32 = 85.0;
    /// Shortest hold, ms.
    pub const MIN_HOLD_MS: u32 = 500;
    /// Longest hold (excluded), ms.
    pub const MAX_HOLD_MS: u32 = 3000;

    /// The paper's pulses from `seed`, on steps of `step_ms` (≥ 1) ms.
    pub const fn paper(seed: u64, step_ms: u32) -> Self {
        Self {
            rng: SplitMix64::new(seed),
            step_ms: match NonZeroU32::new(step_ms) {
                Some(n) => n,
                None => NonZeroU32::MIN,
            },
            t_ms: 0,
            next_change_ms: 0,
            torque_ref_pct: 0.0,
        }
    }

    /// Next pulse: (torque, %; hold, whole steps ≥ 1).
    fn draw(&mut self) -> (f32, u32) {
        let unit = (self.rng.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32);
        let pct = Self::MIN_PCT + (Self::MAX_PCT - Self::MIN_PCT) * unit;
        let span = u64::from(Self::MAX_HOLD_MS - Self::MIN_HOLD_MS);
        let hold_ms = Self::MIN_HOLD_MS + (((self.rng.next_u64() >> 32) * span) >> 32) as u32;
        let steps = (hold_ms + self.step_ms.get() / 2) / self.step_ms;
        (pct, steps.max(1))
    }
}

impl Iterator for McuPulses {
    type Item = (u32, f32);
    fn next(&mut self) -> Option<(u32, f32)> {
        if self.t_ms == self.next_change_ms {
            let (pct, steps) = self.draw();
            self.torque_ref_pct = pct;
            self.next_change_ms = self
                .next_change_ms
                .checked_add(steps.checked_mul(self.step_ms.get())?)?;
        }
        let t = self.t_ms;
        self.t_ms = self.t_ms.checked_add(self.step_ms.get())?;
        Some((t, self.torque_ref_pct))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproducible_and_in_range() {
        let a: [Pulse; 64] = core::array::from_fn({
            let mut t = PulseTrain::paper(42);
            move |_| t.next_pulse()
        });
        let mut t = PulseTrain::paper(42);
        let mut mean = 0.0;
        for p in a {
            assert_eq!(p, t.next_pulse());
            assert!((5.0..85.0).contains(&p.torque_ref_pct) && (0.5..3.0).contains(&p.hold_s));
            mean += p.torque_ref_pct / 64.0;
        }
        assert!((mean - 45.0).abs() < 8.0, "mean {mean}");
        // SplitMix64's published first output for seed 0.
        assert_eq!(SplitMix64::new(0).next_u64(), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn stepped_pulses_follow_the_train() {
        let mut train = PulseTrain::paper(5);
        train.period_s = 0.002;
        let mut stepped = SteppedPulses::new(PulseTrain::paper(5), 2);
        let mut t = 0u32;
        for _ in 0..20 {
            let p = train.next_pulse();
            let steps = libm::round(p.hold_s / 0.002) as u32;
            for _ in 0..steps {
                assert_eq!(stepped.next(), Some((t, p.torque_ref_pct)));
                t += 2;
            }
        }
    }

    #[test]
    fn mcu_pulses_have_the_papers_ranges_and_spread() {
        let mut p = McuPulses::paper(9, 5);
        let (mut n, mut mean, mut holds, mut last) = (0u32, 0.0f64, vec![], (0u32, -1.0f32));
        let mut start = 0;
        for (t, u) in p.by_ref().take(2_000_000 / 5) {
            assert_eq!(t % 5, 0);
            assert!((5.0..85.0).contains(&u), "{u}");
            if u != last.1 {
                if last.1 >= 0.0 {
                    holds.push(t - start);
                }
                start = t;
                n += 1;
                mean += f64::from(u);
            }
            last = (t, u);
        }
        mean /= f64::from(n);
        assert!((mean - 45.0).abs() < 2.0, "mean {mean}");
        assert!(holds.iter().all(|h| (500..=3000).contains(h) && h % 5 == 0));
        let hold_mean = holds.iter().map(|&h| f64::from(h)).sum::<f64>() / holds.len() as f64;
        assert!(
            (hold_mean - 1750.0).abs() < 60.0,
            "mean hold {hold_mean} ms"
        );
        // Reproducible.
        let a: Vec<_> = McuPulses::paper(3, 1).take(10_000).collect();
        let b: Vec<_> = McuPulses::paper(3, 1).take(10_000).collect();
        assert_eq!(a, b);
    }

    /// The firmware's pulses are fixed: the first six changes of seed 3 (time, ms; torque,
    /// f32 bits) on steps of 0 (taken as 1), 1, 5 and 7 ms, as the code made them before
    /// its step became a `NonZeroU32` (printed by that code, 6bdaa2d). A change here changes
    /// every excitation recorded with a seed.
    #[test]
    fn mcu_pulses_are_pinned() {
        // The torques (f32 bits) are the same for every step; their times round to it.
        let bits = [
            1096890212, 1113073378, 1102218592, 1098710167, 1110516693, 1114865636,
        ];
        let times: [(u32, [u32; 6]); 4] = [
            (0, [0, 2250, 2932, 5022, 7743, 10464]),
            (1, [0, 2250, 2932, 5022, 7743, 10464]),
            (5, [0, 2250, 2930, 5020, 7740, 10460]),
            (7, [0, 2247, 2926, 5019, 7742, 10465]),
        ];
        for (step, at) in times {
            let mut changes = Vec::new();
            let mut last = f32::NAN;
            for (t, u) in McuPulses::paper(3, step).take(40_000) {
                if u.to_bits() != last.to_bits() {
                    changes.push((t, u.to_bits()));
                    last = u;
                }
            }
            let pinned: Vec<_> = at.into_iter().zip(bits).collect();
            assert_eq!(changes[..6], pinned[..], "step {step} ms");
        }
    }

    #[test]
    fn holds_round_to_the_period() {
        let mut t = PulseTrain::paper(1);
        t.period_s = 0.05;
        for _ in 0..100 {
            let h = t.next_pulse().hold_s / 0.05;
            assert!((h - libm::round(h)).abs() < 1e-9 && h >= 1.0);
        }
    }
}
