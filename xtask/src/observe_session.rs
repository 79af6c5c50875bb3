//! The end-to-end test's observer session: the estimates and their alarms as a user sees them
//! over Modbus.

use crate::mbpoll::{mbpoll, registers};
use crate::util::Result;
use controller::scada;
use controller::virtual_bench::VirtualBenchConfig;
use model_core::monitor;
use model_core::BenchParams;
use std::time::Duration;

/// What a user does with the observer over Modbus (mbpoll), running at 50 %: read the
/// estimates, close the valve by 30 %, fail the pressure transmitter, cut the drive's
/// link; the estimate follows and the right alarm rises.
pub fn observer_session(pty: &str, report: &mut String) -> Result {
    // Inputs 18..22 (mbpoll's 19..23): speed 0.1 rpm, flow 0.01 l/s, k2 1e-5, alarms, sd.
    let observer = || -> Result<Vec<i64>> {
        let t = mbpoll(pty, &["-a", "1", "-t", "3", "-r", "19", "-c", "5"], &[])?;
        registers(&t, 19, 5)
    };
    let holding = |register: &str, value: &str| -> Result {
        let t = mbpoll(pty, &["-a", "1", "-t", "4", "-r", register], &[value])?;
        if t.contains("Written 1 references") {
            Ok(())
        } else {
            Err(format!("write holding {register} = {value}: {t}"))
        }
    };
    // The virtual bench's valve: the paper's k2 × its configured factor (a few percent off
    // the model the observer starts from).
    let bench_k2 = f64::from(
        BenchParams::<f32>::PAPER.valve_k2 * VirtualBenchConfig::default_offsets(1).valve_factor,
    );
    let o = observer()?;
    let k2 = o[2] as f64 * 1e-5;
    report.push_str(&format!(
        "observer at 50 %: {} rpm, {} l/s (sd {}), k2 {k2:.5} (bench {bench_k2:.5}), alarms {:#04x}\n",
        o[0] as f64 / 10.0,
        o[1] as f64 / 100.0,
        o[4] as f64 / 100.0,
        o[3]
    ));
    if (k2 / bench_k2 - 1.0).abs() > 0.03 || o[3] != 0 {
        return Err(format!("observer at 50 %: {o:?}\n{report}"));
    }
    holding("4", "1300")?;
    std::thread::sleep(Duration::from_secs(4));
    let o = observer()?;
    let k2 = o[2] as f64 * 1e-5;
    report.push_str(&format!(
        "valve closed 30 % (holding 3 = 1300): k2 {k2:.5} (bench {:.5}), alarms {:#04x} (load changed)\n",
        bench_k2 * 1.3,
        o[3]
    ));
    if (k2 / (bench_k2 * 1.3) - 1.0).abs() > 0.03 || o[3] != i64::from(monitor::LOAD_CHANGED) {
        return Err(format!("after closing the valve: {o:?}\n{report}"));
    }
    holding("4", "1000")?;
    for (faults, bit, what) in [
        (
            scada::FAULT_PRESSURE_2MA,
            monitor::PRESSURE_TRANSMITTER,
            "pressure transmitter at 2 mA",
        ),
        (scada::FAULT_VFD_LINK, monitor::VFD_LINK, "VFD link cut"),
    ] {
        let faults = &faults.to_string();
        holding("5", faults)?;
        std::thread::sleep(Duration::from_secs(2));
        let o = observer()?;
        report.push_str(&format!(
            "{what} (holding 4 = {faults}): alarms {:#04x}\n",
            o[3]
        ));
        if o[3] & i64::from(bit) == 0 {
            return Err(format!(
                "{what}: alarm {bit:#x} not raised: {o:?}\n{report}"
            ));
        }
        holding("5", "0")?;
    }
    std::thread::sleep(Duration::from_secs(4));
    let o = observer()?;
    if o[3] != 0 {
        return Err(format!(
            "alarms left after the faults cleared: {o:?}\n{report}"
        ));
    }
    report.push_str("faults cleared, valve back: no alarm\n");
    Ok(())
}
