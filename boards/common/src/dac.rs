//! The torque reference as a DAC code: the analog output a board drives into the VFD's
//! torque input (on the Nucleo: DAC channel 1, 0-3.3 V, amplified ×3.03 to the VFD's 0-10 V).

use model_core::units::applied_torque_pct;

/// Full scale of a 12-bit DAC, code (the STM32F4's DAC in 12-bit right-aligned mode).
pub const DAC12_FULL_SCALE: u16 = 4095;

/// The DAC code of a torque reference of `torque_pct` %: 0 % → 0 (0 V), 100 % →
/// `full_scale` (the DAC's reference voltage), linear between and rounded to the nearest
/// code (halves up). Below 0 % gives 0 and above 100 % gives `full_scale` (+∞ too); NaN
/// gives 0, the torque off.
pub fn torque_code(torque_pct: f32, full_scale: u16) -> u16 {
    // The torque rule (NaN → 0, clamped to 0..=100 %), then the code.
    (applied_torque_pct(torque_pct) / 100.0 * f32::from(full_scale) + 0.5) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    const FS: u16 = DAC12_FULL_SCALE;

    #[test]
    fn the_ends_and_the_middle() {
        assert_eq!(torque_code(0.0, FS), 0);
        assert_eq!(torque_code(100.0, FS), FS);
        // 50 % is code 2 047.5: halves round up.
        assert_eq!(torque_code(50.0, FS), FS.div_ceil(2));
    }

    #[test]
    fn outside_the_range_clamps_and_nan_is_off() {
        for pct in [-0.0, -1e-6, -5.0, -1e30, f32::NEG_INFINITY] {
            assert_eq!(torque_code(pct, FS), 0, "{pct} %");
        }
        for pct in [100.000_01, 150.0, 1e30, f32::INFINITY] {
            assert_eq!(torque_code(pct, FS), FS, "{pct} %");
        }
        assert_eq!(torque_code(f32::NAN, FS), 0);
        assert_eq!(torque_code(-f32::NAN, FS), 0);
    }

    /// Every code is the nearest one to the exact value, and each code's own percentage
    /// comes back as that code.
    #[test]
    fn nearest_code_and_round_trip() {
        for k in 0..=2_000_000u32 {
            let pct = k as f32 * 100.0 / 2_000_000.0;
            let exact = f64::from(pct) / 100.0 * f64::from(FS);
            let code = torque_code(pct, FS);
            assert!(
                (f64::from(code) - exact).abs() <= 0.5 + 1e-3,
                "{pct} % → {code}, exact {exact}"
            );
        }
        for code in 0..=FS {
            let pct = f32::from(code) / f32::from(FS) * 100.0;
            assert_eq!(torque_code(pct, FS), code, "{pct} %");
        }
    }

    #[test]
    fn monotonic() {
        let mut last = 0;
        for k in -1000..=101_000i32 {
            let code = torque_code(k as f32 / 1000.0, FS);
            assert!(code >= last, "{} %: {code} < {last}", k as f32 / 1000.0);
            last = code;
        }
    }

    #[test]
    fn other_resolutions() {
        assert_eq!(torque_code(100.0, 255), 255);
        assert_eq!(torque_code(50.0, 255), 128);
        assert_eq!(torque_code(100.0, u16::MAX), u16::MAX);
        assert_eq!(torque_code(37.0, 0), 0);
    }
}
