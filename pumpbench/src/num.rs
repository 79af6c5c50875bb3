//! Numbers as pumpbench prints them, in CSV output and in messages: the shortest form that
//! reads back to the same value (f64 or f32), in plain or exponent notation, whichever is
//! shorter (plain on a tie): `0.05`, `1734.25`, `0.0015`, `1e-3`, `5e-324`, `1e308`, `1e3`.
//!
//! Rust's `{}` alone gives the shortest digits but never an exponent (`5e-324` would be 324
//! characters); `{:e}` alone writes `5e-2` for `0.05`.

use std::fmt::{self, Display, LowerExp, Write as _};

/// A number displayed in its shortest round-trip form (see the module documentation).
#[derive(Debug, Clone, Copy)]
pub struct Short<T>(pub T);

/// Fixed-size text buffer for the exponent form (at most 1 + 17 + 1 + 1 + 5 characters for an
/// f64: sign, digits, point, `e`, exponent).
struct Buf {
    bytes: [u8; 40],
    len: usize,
}

impl fmt::Write for Buf {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        if end > self.bytes.len() {
            return Err(fmt::Error);
        }
        self.bytes[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// Length of the plain (`{}`) form of the number whose exponent form (`{:e}`) is `exp`, or
/// `None` for a form without an exponent (inf, NaN).
fn plain_len(exp: &str) -> Option<usize> {
    let (mantissa, power) = exp.split_once('e')?;
    let power: i64 = power.parse().ok()?;
    let sign = usize::from(mantissa.starts_with('-'));
    let digits = mantissa.bytes().filter(u8::is_ascii_digit).count() as i64;
    let len = if power >= 0 {
        // Digits then zeros up to the point, and a fraction if digits are left over.
        if digits <= power + 1 {
            power + 1
        } else {
            digits + 1
        }
    } else {
        // "0." then -power - 1 zeros, then the digits.
        digits + 1 - power
    };
    Some(sign + usize::try_from(len).ok()?)
}

/// The floating-point types [`Short`] prints.
pub trait Float: Display + LowerExp + Copy {
    /// The value as an f64 (exact).
    fn to_f64(self) -> f64;
}

impl Float for f64 {
    fn to_f64(self) -> f64 {
        self
    }
}

impl Float for f32 {
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl<T: Float> Display for Short<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Fast path, the usual CSV value: plain is never longer for a non-integer in
        // 0.01..1e15 (exponent -2..14 with a fraction; below 2^53, so its shortest digits
        // have a fraction too) nor for an integer below 1000.
        let x = self.0.to_f64();
        let a = x.abs();
        let fraction = x.fract() != 0.0;
        if (fraction && (0.01..1e15).contains(&a)) || (!fraction && a < 1000.0) {
            return write!(f, "{}", self.0);
        }
        let mut buf = Buf {
            bytes: [0; 40],
            len: 0,
        };
        if write!(buf, "{:e}", self.0).is_ok() {
            if let Ok(exp) = std::str::from_utf8(&buf.bytes[..buf.len]) {
                if plain_len(exp).is_some_and(|plain| plain > exp.len()) {
                    return f.write_str(exp);
                }
            }
        }
        write!(f, "{}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s<T: Float>(x: T) -> String {
        Short(x).to_string()
    }

    #[test]
    fn shortest_form_either_notation() {
        assert_eq!(s(5e-324), "5e-324");
        assert_eq!(s(1e308), "1e308");
        assert_eq!(s(-1.5e300), "-1.5e300");
        assert_eq!(s(f64::MAX), "1.7976931348623157e308");
        assert_eq!(s(0.05), "0.05");
        assert_eq!(s(1e-7), "1e-7");
        assert_eq!(s(0.01), "0.01");
        assert_eq!(s(0.001), "1e-3");
        assert_eq!(s(0.0015), "0.0015");
        assert_eq!(s(100.0), "100");
        assert_eq!(s(1000.0), "1e3");
        assert_eq!(s(1100.0), "1100");
        assert_eq!(s(1734.2918), "1734.2918");
        assert_eq!(s(0.1 + 0.2), "0.30000000000000004");
        assert_eq!(s(0.0), "0");
        assert_eq!(s(-0.0), "-0");
        assert_eq!(s(f64::INFINITY), "inf");
        assert_eq!(s(f64::NAN), "NaN");
        assert_eq!(s(10.282024f32), "10.282024");
        assert_eq!(s(1e-45f32), "1e-45");
        assert_eq!(s(f32::MAX), "3.4028235e38");
    }

    #[test]
    fn plain_length_is_predicted_and_both_forms_round_trip() {
        let mut x = 1.234_567_890_123e-320_f64;
        while x < 1e300 {
            for v in [x, -x, x.round(), (x * 7.0).trunc() / 8.0] {
                let exp = format!("{v:e}");
                assert_eq!(plain_len(&exp), Some(format!("{v}").len()), "{v:e}");
                let shown = s(v);
                assert_eq!(shown.parse::<f64>().unwrap().to_bits(), v.to_bits());
                let plain = format!("{v}");
                let shortest = if exp.len() < plain.len() {
                    &exp
                } else {
                    &plain
                };
                assert_eq!(&shown, shortest, "{v:e}");
                let v32 = v as f32;
                let (plain32, exp32) = (format!("{v32}"), format!("{v32:e}"));
                let shortest32 = if exp32.len() < plain32.len() {
                    &exp32
                } else {
                    &plain32
                };
                assert_eq!(&s(v32), shortest32, "{v32:e}");
            }
            x *= 3.7;
        }
        // Around the fast path's edges.
        for v in [
            0.01,
            0.0099999,
            0.010000000000000002,
            999.0,
            1000.0,
            999.5,
            1e15,
            999999999999999.9,
            1e15 + 0.5,
            123456789012345.6,
            9007199254740993.0,
            0.015,
            0.001,
            0.0015,
            -0.0,
        ] {
            let (plain, exp) = (format!("{v}"), format!("{v:e}"));
            let shortest = if exp.len() < plain.len() { exp } else { plain };
            assert_eq!(s(v), shortest, "{v:e}");
            assert_eq!(s(-v), format!("-{shortest}").replace("--", ""), "{v:e}");
        }
    }
}
