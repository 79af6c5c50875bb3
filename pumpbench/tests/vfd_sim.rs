//! `pumpbench vfd-sim` over a pseudo-terminal pair, driven by the controller's own VFD master
//! (the firmware's code): the link comes up, the torque written drives the simulated bench,
//! the speed read back is the bench's, and when the simulator goes away the master raises the
//! link alarm and forces 0 % torque.

use controller::modbus::Frame;
use controller::rtu::RtuFramer;
use controller::vfd::{VfdMap, VfdMaster};
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios;
use std::io::{ErrorKind, Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs the master for `ms` milliseconds of wall time against whatever is on `port`.
fn drive(m: &mut VfdMaster, port: &mut std::fs::File, start: Instant, ms: u64, pct: f32) {
    let mut framer = RtuFramer::new(5_000);
    let (mut out, mut frame) = (Frame::new(), Frame::new());
    let mut buf = [0u8; 256];
    let end = start.elapsed().as_millis() as u64 + ms;
    loop {
        let elapsed = start.elapsed();
        let now = elapsed.as_millis() as u64;
        // The framer's clock: µs, wrapping.
        let now_us = elapsed.as_micros() as u32;
        if now >= end {
            return;
        }
        match port.read(&mut buf) {
            Ok(n) => buf[..n].iter().for_each(|&b| framer.push(b, now_us)),
            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
            Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => {}
            Err(e) => panic!("pty: {e}"),
        }
        if framer.poll(now_us, &mut frame) {
            m.receive(&frame);
        }
        if m.poll(now as u32, &mut out).is_some() || m.start(now as u32, pct, &mut out).is_some() {
            port.write_all(&out).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn vfd_sim_answers_the_master_over_a_pty_and_its_loss_raises_the_alarm() {
    let pty = openpty(None, None).expect("openpty");
    let path = nix::unistd::ttyname(&pty.slave).expect("ttyname");
    let mut t = termios::tcgetattr(&pty.slave).unwrap();
    termios::cfmakeraw(&mut t);
    termios::tcsetattr(&pty.slave, termios::SetArg::TCSANOW, &t).unwrap();
    let flags = OFlag::from_bits_truncate(fcntl(&pty.master, FcntlArg::F_GETFL).unwrap());
    fcntl(&pty.master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).unwrap();
    let mut port = std::fs::File::from(pty.master);

    let mut sim = Command::new(env!("CARGO_BIN_EXE_pumpbench"))
        .args(["vfd-sim", "--port"])
        .arg(&path)
        .args(["--seconds", "4"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    std::thread::sleep(Duration::from_millis(300));
    let mut m = VfdMaster::new(VfdMap::example_16384()).unwrap();
    drive(&mut m, &mut port, start, 3000, 50.0);
    assert!(!m.alarm(), "link up");
    assert!(m.exchanges_ok() > 100, "{} exchanges", m.exchanges_ok());
    let r = m.readings().expect("readings valid while the link is up");
    // The virtual bench at 50 % settles near 1234 rpm (the model's 1233.9, a few % off).
    assert!((1150.0..1300.0).contains(&r.speed_rpm), "{r:?}");
    assert!((r.torque_pct - 50.0).abs() < 0.01, "{r:?}");
    let status = sim.wait().unwrap();
    let mut log = String::new();
    sim.stderr.take().unwrap().read_to_string(&mut log).unwrap();
    assert!(status.success(), "{log}");
    assert!(log.contains("torque_ref=50.00 %"), "{log}");
    // The simulator is gone: 3 failed exchanges (3 × 3 attempts × 100 ms) raise the alarm.
    drive(&mut m, &mut port, start, 1200, 50.0);
    assert!(m.alarm());
    assert_eq!(m.applied_torque_pct(50.0), 0.0);
}

#[test]
fn vfd_sim_refuses_what_is_not_a_serial_port() {
    let out = Command::new(env!("CARGO_BIN_EXE_pumpbench"))
        .args(["vfd-sim", "--port", "/dev/null", "--seconds", "1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/dev/null: not a serial port"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}
