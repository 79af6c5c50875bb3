//! The firmware's start-up arguments, read with semihosting `SYS_GET_CMDLINE` (QEMU:
//! `-semihosting-config enable=on,target=native,arg=pump-qemu,arg=mode=2,…`), each
//! `key=value`: `mode=0|1|2` (start-up mode, default 0 stop), `setpoint=0..10000` (0.01 %),
//! `seed=N` (profile and bench seed, 0..=4294967295, default 1), `narmax=f32|q15` (NARMAX
//! arithmetic), `run_ms=N` (exit 0 after N ms; default: run until QEMU is stopped),
//! `vfd=uart` (the VFD master on USART2 instead of the in-process drive), `record` (the
//! commissioning record: a row per pressure sample in the log, `controller::record`), `adapt`
//! (the NARMAX models follow the load from start-up: holding register 19 at 1),
//! `head=800..1200` and `torque=800..1200` (the virtual bench's pump-head and load-torque
//! curves, per mille of the paper's; defaults 1000 and 1020). A bad argument is reported and
//! the firmware exits with status 1.

use controller::types::{Arithmetic, Mode};

/// Start-up options from the semihosting command line.
pub struct Args {
    /// Start-up mode (`mode=0|1|2`).
    pub mode: Mode,
    /// Start-up setpoint, the SCADA register's 0.01 % units (`setpoint=0..10000`).
    pub setpoint: u16,
    /// Profile and bench seed: 32 bits, so that no 64-bit division (≈ 1.1 KB) is linked
    /// for printing it.
    pub seed: u32,
    /// Stop QEMU after this many ms of loop time (`run_ms=N`); run forever without it.
    pub run_ms: Option<u32>,
    /// The VFD on USART2 (`vfd=uart`) instead of the virtual drive.
    pub vfd_uart: bool,
    /// The NARMAX arithmetic (`narmax=f32|q15`).
    pub arithmetic: Arithmetic,
    /// The commissioning record on (`record`).
    pub record: bool,
    /// The NARMAX models follow the load from start-up (`adapt`).
    pub adapt: bool,
    /// The virtual bench's pump-head curve, per mille of the paper's (`head=800..1200`).
    pub head_pml: u32,
    /// The virtual bench's load-torque curve, per mille of the paper's (`torque=800..1200`).
    pub torque_pml: u32,
}

/// The range of `head=` and `torque=`, per mille.
const CURVE_PML: core::ops::RangeInclusive<u32> = 800..=1200;

/// A decimal `u32`, digits only.
fn number(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u32, |n, &d| {
        d.is_ascii_digit()
            .then(|| n.checked_mul(10)?.checked_add(u32::from(d - b'0')))
            .flatten()
    })
}

/// The arguments, as bytes: no UTF-8 validation and no `str::parse` linked (≈ 0.6 KB of
/// flash); a bad word is returned as given.
pub fn parse_args(line: &[u8]) -> Result<Args, &[u8]> {
    let mut a = Args {
        mode: Mode::Stop,
        setpoint: 0,
        seed: 1,
        run_ms: None,
        vfd_uart: false,
        arithmetic: Arithmetic::F32,
        record: false,
        adapt: false,
        head_pml: 1000,
        torque_pml: 1020,
    };
    // The first word is the program name; words are separated by ASCII spaces. (The name
    // taken with `next`, not `skip(1)`: `Skip` linked an out-of-line `Iterator::nth`.)
    let mut words = line.split(|&b| b == b' ').filter(|w| !w.is_empty());
    let _program = words.next();
    for word in words {
        let (key, value) = match word.iter().position(|&b| b == b'=') {
            Some(k) => (&word[..k], &word[k + 1..]),
            None => (word, &word[word.len()..]),
        };
        let n = || number(value).ok_or(word);
        match key {
            b"mode" => {
                a.mode = match value {
                    b"0" => Mode::Stop,
                    b"1" => Mode::Manual,
                    b"2" => Mode::Profile,
                    _ => return Err(word),
                }
            }
            b"setpoint" => a.setpoint = u16::try_from(n()?).map_err(|_| word)?,
            b"seed" => a.seed = n()?,
            b"run_ms" => a.run_ms = Some(n()?),
            b"vfd" if value == b"uart" => a.vfd_uart = true,
            b"record" if value.is_empty() => a.record = true,
            b"adapt" if value.is_empty() => a.adapt = true,
            b"head" | b"torque" => {
                let pml = n()?;
                if !CURVE_PML.contains(&pml) {
                    return Err(word);
                }
                *if key == b"head" {
                    &mut a.head_pml
                } else {
                    &mut a.torque_pml
                } = pml;
            }
            b"narmax" => {
                a.arithmetic = match value {
                    b"f32" => Arithmetic::F32,
                    b"q15" => Arithmetic::Q15,
                    _ => return Err(word),
                }
            }
            _ => return Err(word),
        }
    }
    Ok(a)
}

/// The semihosting command line into `buf`; empty if the host gives none.
pub fn command_line(buf: &mut [u8]) -> &[u8] {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: SYS_GET_CMDLINE writes at most `block[1]` bytes to `block[0]`, a live buffer,
    // and the length it wrote back to `block[1]`.
    let failed = unsafe {
        cortex_m_semihosting::syscall1(
            cortex_m_semihosting::nr::GET_CMDLINE,
            core::ptr::addr_of_mut!(block) as usize,
        )
    } != 0;
    let n = if failed { 0 } else { block[1].min(buf.len()) };
    // The line is NUL-terminated; QEMU 7.2 reports the buffer's length, not the line's.
    let n = buf[..n].iter().position(|&b| b == 0).unwrap_or(n);
    &buf[..n]
}
