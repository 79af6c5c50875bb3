//! The end-to-end check: the firmware in QEMU in real time with its SCADA port on a
//! pseudo-terminal, driven by `mbpoll` (another Modbus implementation, libmodbus): the
//! registers and the spec's exceptions, malformed frames, then the observer's and the
//! protections' sessions and the line's checks under hostile clients.

use crate::mbpoll::{mbpoll, registers};
use crate::qemu::{qemu_command, start_pty};
use crate::util::Result;
use crate::{line, observe_session, protection_session};
use controller::scada::{published_from_registers, INPUT_REGISTERS};
use controller::types::{Published, Status};
use std::io::Write;
use std::path::Path;
use std::time::Duration;

/// The end-to-end test on the image at `elf` (built): returns its report.
pub fn run(elf: &Path) -> Result<String> {
    let mut cmd = qemu_command(elf, &["mode=0".into()]);
    cmd.args(["-display", "none", "-monitor", "none"])
        .args(["-serial", "pty", "-serial", "null"]);
    let (qemu, bridge, _, _) = start_pty(elf, cmd, false)?;
    let pty = bridge.path.clone();
    let mut report = format!("SCADA on {pty}\n");

    // Read all input registers (FC 04), decoded by the register map itself.
    let read = |report: &mut String| -> Result<Published> {
        let count = INPUT_REGISTERS.to_string();
        let t = mbpoll(&pty, &["-a", "1", "-t", "3", "-r", "1", "-c", &count], &[])?;
        let r = registers(&t, 1, INPUT_REGISTERS)?;
        report.push_str(&format!("inputs: {r:?}\n"));
        let mut words = [0u16; INPUT_REGISTERS];
        for (w, v) in words.iter_mut().zip(&r) {
            *w = *v as u16; // mbpoll prints the words unsigned
        }
        Ok(published_from_registers(&words))
    };
    let p0 = read(&mut report)?;
    if p0.torque_pct != 0.0 || Status::from_bits(p0.status).running {
        return Err(format!("stopped at start expected, read {p0:?}"));
    }
    // Setpoint 50 % and manual mode (FC 16 of two holding registers).
    let w = mbpoll(&pty, &["-a", "1", "-t", "4", "-r", "1"], &["5000", "1"])?;
    if !w.contains("Written 2 references") {
        return Err(format!("write setpoint and mode: {w}"));
    }
    std::thread::sleep(Duration::from_secs(3));
    let p = read(&mut report)?;
    let bench = model_core::WhiteBox::<f32>::paper();
    let op = bench.signals(&bench.steady_state(50.0).map_err(|e| e.to_string())?);
    let speed = f64::from(p.whitebox_speed_rpm);
    let pressure = f64::from(p.pressure_mca);
    let flow = f64::from(p.flow_lps);
    let rel = |a: f64, b: f32| (a / b as f64 - 1.0).abs();
    report.push_str(&format!(
        "after 3 s at 50 %: white-box speed {speed} rpm (model {:.1}), measured pressure {pressure} mca (model {:.3}), flow {flow} l/s (model {:.2})\n",
        op.speed_rpm, op.pressure_mca, op.flow_lps
    ));
    // Running, no alarm, the VFD link up (the extrapolation flag may be either).
    let s = Status::from_bits(p.status);
    if p.torque_pct != 50.0
        || rel(speed, op.speed_rpm) > 0.01
        || rel(pressure, op.pressure_mca) > 0.05
        || rel(flow, op.flow_lps) > 0.05
        || !(s.running && !s.any_alarm && s.vfd_link_ok)
    {
        return Err(format!("operating point at 50 % not reached:\n{report}"));
    }
    // Spec exceptions.
    // The first input register past the map (mbpoll counts from 1).
    let past = (INPUT_REGISTERS + 1).to_string();
    let t = mbpoll(&pty, &["-a", "1", "-t", "3", "-r", &past, "-c", "1"], &[])?;
    if !t.to_lowercase().contains("illegal data address") {
        return Err(format!(
            "input register {INPUT_REGISTERS}: expected exception 02, got:\n{t}"
        ));
    }
    let t = mbpoll(&pty, &["-a", "1", "-t", "4", "-r", "1"], &["10001"])?;
    if !t.to_lowercase().contains("illegal data value") {
        return Err(format!("setpoint 10001: expected exception 03, got:\n{t}"));
    }
    report.push_str(&format!(
        "exceptions 02 (input register {INPUT_REGISTERS}) and 03 (setpoint 10001): as the spec says\n"
    ));
    // Malformed frames: bad CRC, another unit; silence, then a valid request is answered.
    {
        let mut port = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&pty)
            .map_err(|e| format!("{pty}: {e}"))?;
        port.write_all(&[1, 4, 0, 0, 0, 1, 0xDE, 0xAD])
            .map_err(|e| e.to_string())?;
        std::thread::sleep(Duration::from_millis(300));
    }
    let t = mbpoll(&pty, &["-a", "2", "-t", "3", "-r", "1", "-c", "1"], &[])?;
    if !t.to_lowercase().contains("timed out") {
        return Err(format!("a request for unit 2 must get silence, got:\n{t}"));
    }
    let r2 = read(&mut report)?;
    if r2.torque_pct != 50.0 {
        return Err(format!(
            "the slave must still answer after malformed frames: {r2:?}"
        ));
    }
    report.push_str("bad CRC and unit 2: silence; the next request answered\n");
    observe_session::observer_session(&pty, &mut report)?;
    protection_session::protection_session(&pty, &mut report)?;
    line::checks(&pty, &bridge, &mut report)?;
    drop(qemu);
    Ok(report)
}
