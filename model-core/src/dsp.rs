//! The one audited module with `unsafe`: the Cortex-M4 DSP extension's dual 16×16 multiply-
//! accumulate, `SMLAD`, for the fixed-point NARMAX pass, and the FPU's square root, `VSQRT`,
//! for the observer's f32 arithmetic.
//!
//! Why `asm!`: stable Rust has no intrinsic for `SMLAD` (`core::arch::arm::__smlad` is
//! unstable), and LLVM only forms it from plain Rust in its ARMParallelDSP pass, which runs at
//! `opt-level = 3` alone and only for i16 loads it can pair: the firmware is built at
//! `opt-level = "s"`, and the fixed-point pass packs its operands itself.
//!
//! Audit: the `asm!` block reads two registers and writes one; it touches no memory
//! (`nomem`), no stack (`nostack`), and its result depends on its inputs only (`pure`). The
//! Q flag it may set on overflow is never read. It is compiled only for targets with the DSP
//! extension (the `model_core_smlad` cfg, set by `build.rs` for `thumbv7em-*`); every other
//! target uses [`smlad_portable`], which gives the same bits (tested on the target by the
//! bench's check and on the host against the definition).
//!
//! Why `asm!` for `VSQRT.F32`: `f32::sqrt` is not in `core` on stable, and `libm::sqrtf` does
//! not use the FPU on `thumbv7em` (its hardware path is gated on a target feature these
//! targets do not expose): it costs ≈ 140 instructions a call on the M4 against 14 cycles.
//! Audit: one core register in, one out, s15 saved and restored on the stack around the
//! instruction (the only memory it touches); IEEE 754 square root, correctly
//! rounded like `libm::sqrtf`, so both give the same bits (NaN for negative inputs; the
//! FPSCR's exception flags it may set are never read). Compiled only for hard-float M4F/M7
//! targets (the `model_core_vsqrt` cfg from `build.rs`); elsewhere [`sqrt_f32`] is
//! `libm::sqrtf`.
//!
//! `micromath` stays out: its `sqrt` is a fast approximation about 5 % off, where the
//! observer's covariance needs a correctly rounded one; its other functions are not needed.
#![allow(unsafe_code)]

/// √x in f32, correctly rounded: `VSQRT.F32` on a hard-float Cortex-M, else `libm::sqrtf`.
#[inline(always)]
pub fn sqrt_f32(x: f32) -> f32 {
    #[cfg(model_core_vsqrt)]
    {
        let out: u32;
        // SAFETY: FPU instructions on s15, which is saved and restored around them (Rust
        // exposes the FPU's register class only with the `vfp2` target feature, which these
        // targets do not list, so s15 cannot be named as a clobber); the bits travel in core
        // registers. Touches only the stack slot of its own push and pop.
        unsafe {
            core::arch::asm!(
                "vpush {{s15}}",
                "vmov s15, {x}",
                "vsqrt.f32 s15, s15",
                "vmov {out}, s15",
                "vpop {{s15}}",
                out = lateout(reg) out,
                x = in(reg) x.to_bits(),
                options(pure, nomem, preserves_flags)
            );
        }
        f32::from_bits(out)
    }
    #[cfg(not(model_core_vsqrt))]
    {
        libm::sqrtf(x)
    }
}

/// `acc + lo(a)·lo(b) + hi(a)·hi(b)`, the halves read as i16, wrapping in 32 bits: `SMLAD`.
#[inline(always)]
pub fn smlad(a: u32, b: u32, acc: i32) -> i32 {
    #[cfg(model_core_smlad)]
    {
        let out: i32;
        // SAFETY: a register-only instruction of the target's DSP extension (see the module
        // docs); no memory, no stack, no flags read.
        unsafe {
            core::arch::asm!(
                "smlad {out}, {a}, {b}, {acc}",
                out = lateout(reg) out,
                a = in(reg) a,
                b = in(reg) b,
                acc = in(reg) acc,
                options(pure, nomem, nostack, preserves_flags)
            );
        }
        out
    }
    #[cfg(not(model_core_smlad))]
    {
        smlad_portable(a, b, acc)
    }
}

/// [`smlad`] in portable Rust (the definition; the host's path).
#[inline(always)]
pub fn smlad_portable(a: u32, b: u32, acc: i32) -> i32 {
    let lo = i32::from(a as i16) * i32::from(b as i16);
    let hi = i32::from((a >> 16) as i16) * i32::from((b >> 16) as i16);
    acc.wrapping_add(lo).wrapping_add(hi)
}

/// Two i16 in one word for [`smlad`]: `lo` in bits 0..16, `hi` in bits 16..32.
#[inline(always)]
pub const fn pack(lo: i16, hi: i16) -> u32 {
    (lo as u16 as u32) | ((hi as u16 as u32) << 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_f32_is_libm_bit_for_bit() {
        let mut x = 1e-30f32;
        while x < 1e30 {
            assert_eq!(sqrt_f32(x).to_bits(), libm::sqrtf(x).to_bits(), "{x}");
            x *= 1.013;
        }
        assert!(sqrt_f32(-1.0).is_nan() && sqrt_f32(0.0) == 0.0);
    }

    #[test]
    fn smlad_is_two_products_and_an_add_wrapping() {
        let cases = [
            (1i16, 2i16, 3i16, 4i16, 10i32),
            (-32768, -32768, -32768, -32768, 0),
            (32767, -32768, 32767, 32767, i32::MAX),
            (-1, 1, 1, -1, i32::MIN),
        ];
        for (al, ah, bl, bh, acc) in cases {
            let want = (i64::from(acc)
                + i64::from(al) * i64::from(bl)
                + i64::from(ah) * i64::from(bh)) as i32;
            assert_eq!(smlad(pack(al, ah), pack(bl, bh), acc), want);
            assert_eq!(smlad_portable(pack(al, ah), pack(bl, bh), acc), want);
        }
    }
}
