//! The end-to-end test's protection session: the trips, their acknowledges and the
//! protections' settings as a user tries them over Modbus.

use crate::mbpoll::{mbpoll, registers};
use crate::util::Result;
use controller::types::Status;
use model_core::monitor;
use std::time::{Duration, Instant};

/// The protections as a user tries them over Modbus (mbpoll), running at 50 %: a dry
/// run injected trips the torque to 0 % by the time its alarm is up and holds it; an
/// acknowledge while the fault stands keeps 0 %; fault cleared, acknowledged, manual
/// again: running. An overspeed limit written low trips within 0.5 s. At rest, a
/// transmitter fault clears within 3 s of its removal; one stop write acknowledges a
/// cured dry run (the protection set to warn) within 3 s.
pub fn protection_session(pty: &str, report: &mut String) -> Result {
    // Input registers 0..=25 (mbpoll's 1..=26): 0 status, 1 torque, 21 alarms, 23 causes.
    let inputs = || -> Result<Vec<i64>> {
        let t = mbpoll(pty, &["-a", "1", "-t", "3", "-r", "1", "-c", "26"], &[])?;
        registers(&t, 1, 26)
    };
    let holding = |register: u16, value: u16| -> Result {
        let (r, v) = ((register + 1).to_string(), value.to_string());
        let t = mbpoll(pty, &["-a", "1", "-t", "4", "-r", &r], &[&v])?;
        if t.contains("Written 1 references") {
            Ok(())
        } else {
            Err(format!("write holding {register} = {value}: {t}"))
        }
    };
    // Polls until `done` holds, at most `limit`: the time it took and the last read.
    let until = |limit: Duration, done: &dyn Fn(&[i64]) -> bool| -> Result<(f64, Vec<i64>)> {
        let start = Instant::now();
        loop {
            let r = inputs()?;
            if done(&r) {
                return Ok((start.elapsed().as_secs_f64(), r));
            }
            if start.elapsed() > limit {
                return Err(format!("not within {limit:?}: {r:?}"));
            }
        }
    };
    // The status word's trip flag (input 0) and the alarms (input 21, the trip causes input
    // 23), as the core and the monitor define them.
    let tripped = |status: i64| Status::from_bits(status as u16).tripped;
    const DRY_RUN: i64 = monitor::DRY_RUN as i64;
    let r = inputs()?;
    if r[1] != 5000 || tripped(r[0]) {
        return Err(format!(
            "running at 50 % expected before the dry run: {r:?}"
        ));
    }
    // Dry run: 0 % by the time the alarm is up, and staying there.
    holding(4, 1)?;
    let start = Instant::now();
    let (mut zero_s, mut r) = (None, inputs()?);
    while r[21] & DRY_RUN == 0 {
        if start.elapsed() > Duration::from_secs(10) {
            return Err(format!("dry run: no alarm after 10 s: {r:?}"));
        }
        r = inputs()?;
        if r[1] == 0 {
            zero_s.get_or_insert(start.elapsed().as_secs_f64());
        }
    }
    let alarm_s = start.elapsed().as_secs_f64();
    report.push_str(&format!(
        "dry run injected (holding 4 = 1): torque 0 % seen after {zero_s:.2?} s, alarm up after {alarm_s:.2} s with torque {} (0.01 %), status {:#06x}, trip causes {:#06x}\n",
        r[1], r[0], r[23]
    ));
    if r[1] != 0 || !tripped(r[0]) || alarm_s > 7.0 {
        return Err(format!(
            "dry run: torque not 0 % with the alarm up\n{report}"
        ));
    }
    std::thread::sleep(Duration::from_secs(2));
    holding(1, 0)?;
    std::thread::sleep(Duration::from_secs(2));
    let r = inputs()?;
    report.push_str(&format!(
        "acknowledged (mode 0) with the fault still injected: torque {}\n",
        r[1]
    ));
    if r[1] != 0 {
        return Err(format!(
            "torque after an acknowledge while dry: {r:?}\n{report}"
        ));
    }
    holding(4, 0)?;
    std::thread::sleep(Duration::from_secs(3));
    holding(1, 0)?;
    let (clear_s, _) = until(Duration::from_secs(10), &|r| !tripped(r[0]))
        .map_err(|e| format!("trip not cleared: {e}"))?;
    holding(1, 1)?;
    let (run_s, _) = until(Duration::from_secs(3), &|r| r[1] == 5000)
        .map_err(|e| format!("not running again: {e}"))?;
    report.push_str(&format!(
        "fault cleared, acknowledged: trip cleared after {clear_s:.2} s; manual again: 50 % after {run_s:.2} s\n"
    ));
    std::thread::sleep(Duration::from_secs(3));
    // Overspeed limit written low at 50 % (≈ 1 260 rpm).
    holding(5, 1000)?;
    let (trip_s, r) = until(Duration::from_secs(2), &|r| r[1] == 0)
        .map_err(|e| format!("overspeed limit 1000 rpm: {e}"))?;
    report.push_str(&format!(
        "overspeed limit 1000 rpm at 50 %: torque 0 % within {trip_s:.2} s (trip causes {:#06x})\n",
        r[23]
    ));
    if trip_s > 0.5 || r[23] != i64::from(monitor::OVERSPEED) {
        return Err(format!("overspeed trip: {r:?}\n{report}"));
    }
    holding(5, 1925)?;
    std::thread::sleep(Duration::from_secs(3));
    holding(1, 0)?;
    until(Duration::from_secs(5), &|r| !tripped(r[0]) && r[21] == 0)
        .map_err(|e| format!("overspeed not acknowledged: {e}"))?;
    // Defect 1: a transmitter fault injected at rest clears within 3 s of its removal.
    std::thread::sleep(Duration::from_secs(2));
    holding(4, 2)?;
    std::thread::sleep(Duration::from_secs(1));
    holding(4, 0)?;
    let (clear_s, _) = until(Duration::from_secs(3), &|r| r[21] & 1 == 0)
        .map_err(|e| format!("pressure transmitter fault at rest: {e}"))?;
    report.push_str(&format!(
        "pressure transmitter fault at rest, removed: cleared after {clear_s:.2} s\n"
    ));
    // Defect 2: the dry run as a warning, 4 s dry at 50 %, 12 s wet, one stop write.
    // Overspeed as a warning too: the dry pump runs away to the drive's speed limit
    // (2 100 rpm, over the 1 925 rpm limit) and would trip on it.
    holding(6, 0)?;
    holding(1, 1)?;
    std::thread::sleep(Duration::from_secs(3));
    holding(4, 1)?;
    std::thread::sleep(Duration::from_secs(4));
    holding(4, 0)?;
    std::thread::sleep(Duration::from_secs(12));
    let r = inputs()?;
    if r[21] & DRY_RUN == 0 || r[1] != 5000 {
        return Err(format!(
            "dry run as a warning: alarm latched at 50 % expected: {r:?}"
        ));
    }
    holding(1, 0)?;
    let (ack_s, _) = until(Duration::from_secs(3), &|r| r[21] & DRY_RUN == 0)
        .map_err(|e| format!("a cured dry run, one stop write: {e}"))?;
    report.push_str(&format!(
        "dry run as a warning, cured 12 s: one stop write acknowledged it after {ack_s:.2} s\n"
    ));
    // Back to the defaults, running at 50 % as before.
    holding(6, 0b011)?;
    holding(1, 1)?;
    std::thread::sleep(Duration::from_secs(3));
    Ok(())
}
