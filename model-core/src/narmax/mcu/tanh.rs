//! tanh for the two passes: a rational approximation in f32, a table with linear
//! interpolation in Q15.

use fixed::types::{I16F16, I1F15};

include!(concat!(env!("OUT_DIR"), "/tanh_table.rs"));

/// Largest |[`tanh_f32`]`(x)` − tanh(x)| over every f32 x (exhaustive test `tanh_f32_error`).
pub const TANH_F32_MAX_ERROR: f32 = 4e-7;

/// tanh by a rational approximation (see the module docs): within [`TANH_F32_MAX_ERROR`],
/// odd, ±1 beyond ±7.905, NaN for NaN. About 25 instructions on a Cortex-M4F, one divide.
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const A1: f32 = 4.893_524_6e-3;
    const A3: f32 = 6.372_619e-4;
    const A5: f32 = 1.485_722_4e-5;
    const A7: f32 = 5.122_297e-8;
    const A9: f32 = -8.604_672e-11;
    const A11: f32 = 2.000_188e-13;
    const A13: f32 = -2.760_768_5e-16;
    const B0: f32 = 4.893_525e-3;
    const B2: f32 = 2.268_434_7e-3;
    const B4: f32 = 1.185_347_1e-4;
    const B6: f32 = 1.198_258_4e-6;
    // Comparisons, not f32::min/max/clamp: those are library calls on FPv4 (and `clamp`
    // panics on NaN bounds checks it cannot see through).
    #[allow(clippy::manual_clamp)]
    let x = if x > CLAMP {
        CLAMP
    } else if x < -CLAMP {
        -CLAMP
    } else {
        x
    };
    let x2 = x * x;
    let p = x * (A1 + x2 * (A3 + x2 * (A5 + x2 * (A7 + x2 * (A9 + x2 * (A11 + x2 * A13))))));
    let q = B0 + x2 * (B2 + x2 * (B4 + x2 * B6));
    p / q
}

/// Largest |[`tanh_q15`] − tanh| over all Q16 inputs, in real units (exhaustive test
/// `tanh_q15_error`): the interpolation error h²/8·max|tanh''| = 2.3e-5, plus the table's
/// and the result's rounding, and 3.1e-5 where the table saturates at 1 − 2⁻¹⁵.
pub const TANH_Q15_MAX_ERROR: f64 = 4.72e-5;

/// tanh of a Q16 value ([`I16F16`], `x / 65536`) as Q15 ([`I1F15`], `/ 32768`), by the table (module docs): the
/// input saturated to [−8, 8) (one `SSAT`), an index and a fraction, one interpolation; no
/// branch, no sign handling (the table covers both signs).
#[inline(always)]
pub fn tanh_q15(x: I16F16) -> I1F15 {
    const END: i32 = TANH_TABLE_MAX << 16;
    let shift = 16 - TANH_STEP_LOG2;
    let c = x.to_bits().clamp(-END, END - 1);
    // 0 ≤ u < 2·END, so i + 1 ≤ 2·END >> shift, the table's last index.
    let u = (c + END) as u32;
    let i = (u >> shift) as usize;
    let frac = (u & ((1 << shift) - 1)) as i32;
    let (y0, y1) = (
        i32::from(TANH_Q15[i].to_bits()),
        i32::from(TANH_Q15[i + 1].to_bits()),
    );
    // Between y0 and y1, both within ±32767: no saturation needed.
    I1F15::from_bits((y0 + (((y1 - y0) * frac + (1 << (shift - 1))) >> shift)) as i16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_q15_error() {
        // Every non-negative Q16 input up to 10 (odd symmetry covers the rest), then a sparse
        // sweep to the end of the range.
        let mut worst: f64 = 0.0;
        let mut check = |bits: i32| {
            let x = I16F16::from_bits(bits);
            let err = (tanh_q15(x).to_num::<f64>() - x.to_num::<f64>().tanh()).abs();
            worst = worst.max(err);
        };
        for bits in 0..(10 << 16) {
            check(bits);
            check(-bits);
        }
        for bits in (10 << 16..i32::MAX).step_by(65_537) {
            check(bits);
        }
        check(i32::MIN);
        check(i32::MAX);
        assert!(worst <= TANH_Q15_MAX_ERROR, "max tanh error {worst:e}");
        assert!(
            worst > 0.5 * TANH_Q15_MAX_ERROR,
            "documented bound is loose: {worst:e}"
        );
    }

    /// Every f32 from 0 to +∞ (odd symmetry covers the rest: checked on a sweep), two threads.
    #[test]
    fn tanh_f32_error() {
        let worst = std::thread::scope(|s| {
            let halves: Vec<_> = [(0u32, 0x3F80_0000u32), (0x3F80_0000, 0x7F80_0001)]
                .into_iter()
                .map(|(a, b)| {
                    s.spawn(move || {
                        let mut worst = 0.0f64;
                        for bits in a..b {
                            let x = f32::from_bits(bits);
                            let e = (f64::from(tanh_f32(x)) - f64::from(x).tanh()).abs();
                            worst = worst.max(e);
                        }
                        worst
                    })
                })
                .collect();
            halves
                .into_iter()
                .map(|h| h.join().unwrap())
                .fold(0.0, f64::max)
        });
        for bits in (0..0x7F80_0000u32).step_by(9973) {
            let x = f32::from_bits(bits);
            assert_eq!(tanh_f32(-x), -tanh_f32(x), "odd at {x:e}");
        }
        assert!(tanh_f32(f32::NAN).is_nan());
        assert!(
            worst <= f64::from(TANH_F32_MAX_ERROR),
            "max error {worst:e}"
        );
        assert!(
            worst > 0.5 * f64::from(TANH_F32_MAX_ERROR),
            "bound loose: {worst:e}"
        );
        eprintln!("tanh_f32: max |error| over every f32 ≥ 0: {worst:.3e}");
    }
}
