//! `pumpbench vfd-sim`: a simulated VFD on a serial port: a Modbus RTU slave with the
//! controller's VFD register map ([`controller::vfdsim::VfdSim`], the code the firmware's
//! virtual bench runs) driving a virtual bench ([`controller::virtual_bench::VirtualBench`]) in real
//! time with the torque reference it is written.

use crate::error::Failure;
use controller::modbus::Frame;
use controller::rtu::RtuFramer;
use controller::vfd::VfdMap;
use controller::vfdsim::{DriveValues, VfdSim};
use controller::virtual_bench::{VirtualBench, VirtualBenchConfig};
use nix::sys::termios::{self, SetArg};
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::time::{Duration, Instant};

/// Options of `vfd-sim`.
pub struct Options {
    /// Unit address.
    pub unit: u8,
    /// Counts for 100 % torque.
    pub counts_per_100_pct: u16,
    /// rpm per count of the speed register.
    pub rpm_per_count: f32,
    /// Silence that ends a frame, ms (the framer counts µs: 1000 × this, saturating).
    pub idle_ms: u32,
    /// Stop after this long, s (None: until killed).
    pub seconds: Option<f64>,
    /// Noise seed of the virtual bench.
    pub seed: u64,
}

/// Opens `path` as a raw serial line (8N1, no echo, no line editing), non-blocking reads.
pub fn open_raw(path: &Path) -> Result<File, Failure> {
    let fail = |what: &str, e: &dyn std::fmt::Display| Failure {
        code: 1,
        message: format!("{}: {what}: {e}", path.display()),
    };
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(nix::fcntl::OFlag::O_NOCTTY.bits() | nix::fcntl::OFlag::O_NONBLOCK.bits())
        .open(path)
        .map_err(|e| fail("cannot open", &e))?;
    let mut t = termios::tcgetattr(&file).map_err(|e| fail("not a serial port", &e))?;
    termios::cfmakeraw(&mut t);
    termios::cfsetspeed(&mut t, termios::BaudRate::B19200).map_err(|e| fail("speed", &e))?;
    termios::tcsetattr(&file, SetArg::TCSANOW, &t).map_err(|e| fail("raw mode", &e))?;
    Ok(file)
}

/// Runs the simulator on `port` until `seconds` have passed (or forever).
pub fn run(port: &Path, o: &Options) -> Result<(), Failure> {
    let map = VfdMap {
        unit: o.unit,
        counts_per_100_pct: o.counts_per_100_pct,
        rpm_per_count: o.rpm_per_count,
        ..VfdMap::example_16384()
    };
    let mut sim = VfdSim::new(map).ok_or_else(|| {
        Failure::usage("bad drive map (unit 1..247, counts > 0, finite rpm scale)".into())
    })?;
    let mut bench = VirtualBench::new(VirtualBenchConfig::default_offsets(o.seed))
        .map_err(|e| Failure::usage(format!("virtual bench: {e}")))?;
    let mut file = open_raw(port)?;
    eprintln!(
        "vfd-sim: unit {} on {}, 19200 8N1; torque reference at {:#06x} ({} = 100 %), speed/torque/status at {:#06x}",
        map.unit,
        port.display(),
        map.torque_ref_register,
        map.counts_per_100_pct,
        map.read_start
    );
    let start = Instant::now();
    let mut framer = RtuFramer::new(o.idle_ms.saturating_mul(1000));
    let (mut frame, mut answer) = (Frame::new(), Frame::new());
    let mut sim_ms: u64 = 0;
    let mut buf = [0u8; 256];
    let io_err = |e: std::io::Error| Failure {
        code: 1,
        message: format!("{}: {e}", port.display()),
    };
    loop {
        let elapsed = start.elapsed();
        let now_ms = elapsed.as_millis() as u64;
        // The framer's clock: µs, wrapping.
        let now_us = elapsed.as_micros() as u32;
        match file.read(&mut buf) {
            Ok(n) => {
                for &b in &buf[..n] {
                    framer.push(b, now_us);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
            // The other end closed (EIO on a pty): keep waiting for it to reopen.
            Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => {}
            Err(e) => return Err(io_err(e)),
        }
        while sim_ms < now_ms {
            bench.step_1ms(sim.torque_ref_pct()).map_err(|e| Failure {
                code: 1,
                message: format!("virtual bench: {e}"),
            })?;
            sim_ms += 1;
            if sim_ms.is_multiple_of(1000) {
                eprintln!(
                    "vfd-sim: t={} s torque_ref={:.2} % speed={:.1} rpm writes={}",
                    sim_ms / 1000,
                    sim.torque_ref_pct(),
                    bench.signals().speed_rpm,
                    sim.writes()
                );
            }
        }
        if framer.poll(now_us, &mut frame) {
            let values = DriveValues {
                speed_rpm: bench.signals().speed_rpm,
                torque_pct: bench.delivered_torque_pct(),
            };
            if let Some(n) = sim.handle(&frame, &values, &mut answer) {
                file.write_all(&answer[..n]).map_err(io_err)?;
            }
        }
        if o.seconds.is_some_and(|s| elapsed.as_secs_f64() >= s) {
            return Ok(());
        }
        std::thread::sleep(Duration::from_micros(500));
    }
}
