//! The on-target checks (`boards/qemu`'s `selftest` binary; `cargo xtask test` runs it in
//! QEMU and compares its results with the same functions run on the host, bit for bit).
use controller::modbus::{crc16, request_at_end, Frame};
use controller::rtu::{gap_us, RtuFramer};
use model_core::narmax::mcu::{tanh_f32, tanh_q15, I16F16, TANH_Q15_MAX_ERROR};

/// A 32-bit digest of a stream of words (order-sensitive; for comparing results, not for
/// security).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Digest(pub u32);

impl Digest {
    /// The empty stream's.
    pub const fn new() -> Self {
        Self(0x811C_9DC5)
    }
    /// Takes one word.
    pub fn add(&mut self, w: u32) {
        self.0 = (self.0.rotate_left(5) ^ w).wrapping_mul(0x9E37_79B1);
    }
}

impl Default for Digest {
    fn default() -> Self {
        Self::new()
    }
}

/// Inputs of the float checks: 4 097 points from −20 to 20 (the NARMAX pre-activations'
/// range and beyond), then 1 024 points from 1e-6 to 1e4 by factors (positive-only
/// functions).
fn grid(i: u32) -> f32 {
    if i <= 4096 {
        -20.0 + 40.0 * i as f32 / 4096.0
    } else {
        1e-6 * libm::powf(10.0, 10.0 * (i - 4097) as f32 / 1023.0)
    }
}
/// Points of [`grid`].
const GRID: u32 = 4097 + 1024;

/// The digests of the results' bits of `libm`'s `tanhf`, `expf`, `sqrtf` (the ones the
/// product uses in f32), the model's `tanh_f32`, and `tanh_q15` over every Q16 input in
/// [−8, 8) (its whole table): `(name, digest)`.
pub fn digests() -> [(&'static str, u32); 5] {
    let mut d = [Digest::new(); 5];
    for i in 0..GRID {
        let x = grid(i);
        d[0].add(libm::tanhf(x).to_bits());
        d[1].add(libm::expf(x.min(80.0)).to_bits());
        d[2].add(libm::sqrtf(libm::fabsf(x)).to_bits());
        d[3].add(tanh_f32(x).to_bits());
    }
    for x in -(8 << 16)..(8 << 16) {
        d[4].add(tanh_q15(I16F16::from_bits(x)).to_bits() as u16 as u32);
    }
    [
        ("libm_tanhf", d[0].0),
        ("libm_expf", d[1].0),
        ("libm_sqrtf", d[2].0),
        ("tanh_f32", d[3].0),
        ("tanh_q15", d[4].0),
    ]
}

/// `tanh_q15` against `libm::tanhf` on 65 536 points of [−8, 8): the largest error must
/// stay within the table's bound ([`TANH_Q15_MAX_ERROR`]) plus tanhf's own rounding.
pub fn tanh_table() -> Result<f32, &'static str> {
    let mut worst = 0.0f32;
    for k in 0..65_536i32 {
        let x_q16 = (k - 32_768) * 16;
        let exact = libm::tanhf(x_q16 as f32 / 65_536.0);
        let got = f32::from(tanh_q15(I16F16::from_bits(x_q16)).to_bits()) / 32_768.0;
        worst = worst.max(libm::fabsf(got - exact));
    }
    if worst as f64 <= TANH_Q15_MAX_ERROR + 1e-7 {
        Ok(worst)
    } else {
        Err("tanh_q15 off the table's error bound")
    }
}

fn with_crc(body: &[u8]) -> Frame {
    let mut f = Frame::new();
    let _ = f.extend_from_slice(body);
    let _ = f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// The RTU framer as the boards use it: a request found by its content right after noise,
/// a frame ended by the gap mark, a frame ended by silence, time wrapping.
pub fn framer() -> Result<(), &'static str> {
    let req = with_crc(&[1, 4, 0, 0, 0, 18]);
    let mut out = Frame::new();
    let mut f = RtuFramer::new(10_000);
    for (k, &b) in [0x55u8, 0xAA, 0x13].iter().chain(req.iter()).enumerate() {
        f.push(b, k as u32);
    }
    if !f.take_if(&mut out, request_at_end) || out[..] != req[..] {
        return Err("a request after noise is not found by its content");
    }
    let mut f = RtuFramer::new(gap_us(19_200));
    for &b in req.iter() {
        f.push(b, u32::MAX - 100);
    }
    if f.poll((u32::MAX - 100).wrapping_add(gap_us(19_200) - 1), &mut out) {
        return Err("a frame ended before the gap");
    }
    if !f.poll((u32::MAX - 100).wrapping_add(gap_us(19_200)), &mut out) || out[..] != req[..] {
        return Err("a frame not ended by the gap across the time wrap");
    }
    for &b in req.iter() {
        f.push(b, 0);
    }
    if !f.end_frame(&mut out) || out[..] != req[..] {
        return Err("a frame not ended by the gap timer's mark");
    }
    if gap_us(19_200) != 2006 {
        return Err("3.5 characters at 19 200 baud are not 2 006 µs");
    }
    Ok(())
}
