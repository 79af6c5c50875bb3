//! The firmware's runs checked against the host: the on-target checks (`boards/qemu`'s
//! `selftest`: digests equal to the host's, every check passed, a fault reported), and QEMU
//! runs whose every log line must equal the same loop replayed on the host (the `controller`
//! code, the firmware's models), text and f32 bits.

use crate::qemu::{qemu_log, qemu_log_status};
use crate::util::{field, num, target_dir, Result, TARGET};
use std::path::Path;

use controller::record::RecordRow;
use pump_models::{flow as flow_model, pressure as pressure_model};

/// The on-target checks (`boards/qemu`'s `selftest`) in QEMU: their digests must equal the
/// host's of the same functions, bit for bit, every check must pass, and a fault must be
/// reported and end the run with status 1.
pub fn selftest() -> Result<String> {
    let elf = target_dir().join(TARGET).join("firmware").join("selftest");
    let log = qemu_log(&elf, &[])?;
    let mut report = check_selftest_log(&log, &board_common::selftest::digests())?;
    let (ok, fault) = qemu_log_status(&elf, &["fault".into()])?;
    check_fault_run(ok, &fault)?;
    report.push_str("on target: a bus fault is reported (HardFault at pc=…) and QEMU exits 1\n");
    Ok(report)
}

/// The selftest's log (a run without arguments) checked: every digest of `digests` (the
/// host's) equal on the target, the summary `… 0 failed`; returns the report of it, with the
/// checks' lines.
fn check_selftest_log(log: &str, digests: &[(&str, u32)]) -> Result<String> {
    let mut report = String::new();
    for &(name, host) in digests {
        let line = log
            .lines()
            .find_map(|l| l.strip_prefix(&format!("digest {name}=")))
            .ok_or_else(|| format!("selftest: no digest of {name}:\n{log}"))?;
        let target = u32::from_str_radix(line.trim_start_matches("0x"), 16)
            .map_err(|_| format!("selftest: bad digest line for {name}: {line}"))?;
        if target != host {
            return Err(format!(
                "selftest: {name} differs on the target: {target:#010x}, host {host:#010x}"
            ));
        }
        report.push_str(&format!(
            "on target: {name} bits equal the host's ({host:#010x})\n"
        ));
    }
    let summary = log
        .lines()
        .find(|l| l.starts_with("selftest:"))
        .ok_or_else(|| format!("selftest: no summary line:\n{log}"))?;
    if !summary.ends_with(" 0 failed") {
        return Err(format!("selftest: {summary}\n{log}"));
    }
    for l in log
        .lines()
        .filter(|l| l.starts_with("check ") || l.starts_with("tanh_q15"))
    {
        report.push_str(&format!("on target: {l}\n"));
    }
    Ok(report)
}

/// The selftest's `fault` run checked: exit status 1 (`ok` false) and the HardFault report in
/// its log.
fn check_fault_run(ok: bool, fault: &str) -> Result {
    if ok || !fault.contains("ERROR: HardFault at pc=") {
        return Err(format!(
            "selftest fault: expected the HardFault report and exit status 1, got exit {}:\n{fault}",
            if ok { 0 } else { 1 }
        ));
    }
    Ok(())
}

/// The firmware replayed on the host: the same `controller` code (the core, its links and the
/// virtual bench with its in-process drive, run by `VirtualBoard` in the firmware's task
/// order), with the options the firmware announces in its header line.
/// Returns the log lines it makes for the ticks `0..=run_ms`, and the record rows if the
/// header says `record=true`.
pub fn host_replay(header: &str, run_ms: u32) -> Result<(Vec<String>, Vec<String>)> {
    use controller::control::{Config, NarmaxModel};
    use controller::types::{Arithmetic, Mode};
    use controller::virtual_bench::{VirtualBenchConfig, VirtualBoard};
    let seed: u64 = num(header, "seed")?;
    let mode = match num::<u8>(header, "mode")? {
        0 => Mode::Stop,
        1 => Mode::Manual,
        _ => Mode::Profile,
    };
    let arithmetic = Arithmetic::from_name(field(header, "narmax")?)
        .ok_or_else(|| format!("bad 'narmax' in line: {header}"))?;
    let config = Config {
        initial_mode: mode,
        initial_setpoint_pct: controller::scada::setpoint_pct(num(header, "setpoint")?),
        profile_seed: seed,
        initial_arithmetic: arithmetic,
        // `adapt=true` may be followed by the header's ", runs until stopped".
        initial_narmax_adapt: field(header, "adapt")?.trim_end_matches(',') == "true",
        virtual_bench: true,
        ..Config::bench()
    };
    let e = |e: controller::control::Error| e.to_string();
    let ms = |s: f32| {
        model_core::narmax::mcu::firmware_period_ms(f64::from(s)).map_err(|e| e.to_string())
    };
    let p = NarmaxModel::new(
        &pressure_model::F32,
        &pressure_model::Q15,
        ms(pressure_model::SAMPLE_PERIOD_S)?,
    )
    .map_err(e)?;
    let q = NarmaxModel::new(
        &flow_model::F32,
        &flow_model::Q15,
        ms(flow_model::SAMPLE_PERIOD_S)?,
    )
    .map_err(e)?;
    // The board's curves, per mille (`head=`, `torque=`), to f32 as the firmware does.
    let per_mille = |key| num::<u32>(header, key).map(|n| n as f32 / 1000.0);
    let bench = VirtualBenchConfig {
        head_factor: per_mille("head")?,
        load_torque_factor: per_mille("torque")?,
        ..VirtualBenchConfig::default_offsets(seed)
    };
    let record = field(header, "record")? == "true";
    let mut board = VirtualBoard::new(&config, p, q, bench).map_err(e)?;
    let (pp, fp) = board.controller.sample_periods_ms();
    let (mut lines, mut rows) = (vec![], vec![]);
    for _ in 0..=run_ms {
        let out = board.tick().map_err(|e| e.to_string())?;
        if let Some(log) = out.log {
            lines.push(log_text(&log));
        }
        let published = board.controller.published();
        if let Some(row) = RecordRow::at_step(out.t_ms, published, pp, fp).filter(|_| record) {
            rows.push(record_text(&row));
        }
    }
    Ok((lines, rows))
}

/// A record row as the firmware's defmt line decodes (`rec seq=… … status=…`), f32 values
/// printed by `ryu`.
pub fn record_text(r: &RecordRow) -> String {
    let f = |x: f32| ryu::Buffer::new().format(x).to_string();
    format!(
        "rec seq={} t_ms={} u_pct={} p_mca={} q_lps={} q_new={} vfd_rpm={} ob_k2={} ob_q={} alarms={} status={}",
        r.seq,
        r.t_ms,
        f(r.torque_pct),
        f(r.pressure_mca),
        f(r.flow_lps),
        r.flow_sampled,
        f(r.vfd_speed_rpm),
        f(r.observer_k2),
        f(r.observer_flow_lps),
        r.alarms,
        r.status
    )
}

/// A log line as the firmware's defmt line decodes: the same names, f32 values printed by
/// `ryu` as defmt's decoder prints them (the shortest text that reads back to the same bits).
fn log_text(log: &controller::control::LogLine) -> String {
    let mut s = format!(
        "t_s={} mode={} narmax={}",
        log.t_ms / 1000,
        log.mode.name(),
        log.arithmetic.name()
    );
    for (name, x) in log.fields() {
        s.push_str(&format!(" {name}={}", ryu::Buffer::new().format(x)));
    }
    s.push_str(&format!(
        " alarms={} status={}",
        log.values.alarms, log.values.status
    ));
    s
}

/// Checks the firmware's log lines against the host replay, text and f32 bits.
/// With the record on, its rows too; returns how many log lines and rows were compared.
fn check_golden(output: &str, run_ms: u32) -> Result<(usize, usize)> {
    let header = finished_run_header(output)?;
    let (host, rows) = host_replay(header, run_ms)?;
    let target_rows: Vec<&str> = output.lines().filter(|l| l.starts_with("rec ")).collect();
    if target_rows.len() != rows.len() {
        return Err(format!(
            "the firmware sent {} record rows, the host replay made {}",
            target_rows.len(),
            rows.len()
        ));
    }
    for (t, h) in target_rows.iter().zip(&rows) {
        if t != h {
            return Err(format!("firmware: {t}\nhost:     {h}"));
        }
    }
    Ok((compare_lines(output, &host)?, rows.len()))
}

/// The header line (`firmware: …`) of a run's log that ran to its end (`done`).
fn finished_run_header(output: &str) -> Result<&str> {
    let header = output
        .lines()
        .find(|l| l.starts_with("firmware:"))
        .ok_or("no 'firmware:' header line")?;
    if !output.lines().any(|l| l.starts_with("done")) {
        return Err("the firmware did not print 'done'".into());
    }
    Ok(header)
}

/// The log lines (`t_s=…`) of the firmware's `output` against the `host`'s, as text: as many,
/// at least one, each equal; returns how many.
fn compare_lines(output: &str, host: &[String]) -> Result<usize> {
    let target: Vec<&str> = output.lines().filter(|l| l.starts_with("t_s=")).collect();
    if target.len() != host.len() || target.is_empty() {
        return Err(format!(
            "the firmware logged {} lines, the host replay {}",
            target.len(),
            host.len()
        ));
    }
    for (t, h) in target.iter().zip(host) {
        if t != h {
            return Err(format!("firmware: {t}\nhost:     {h}"));
        }
    }
    Ok(target.len())
}

/// The two 20 s QEMU runs (NARMAX f32 and Q15) against the same loop replayed on the host.
pub fn replay(elf: &Path) -> Result {
    eprintln!("==> QEMU runs against the host replay (netduinoplus2, -icount shift=0,sleep=off)");
    const RUN_MS: u32 = 20_000;
    // The Q15 run on a bench with other curves, the commissioning record on, the models
    // following the load (holding register 19).
    for (narmax, extra) in [("f32", ""), ("q15", " head=950 torque=1070 record adapt")] {
        let mut args = vec![
            "mode=2".to_string(),
            format!("narmax={narmax}"),
            format!("run_ms={}", RUN_MS + 1),
        ];
        args.extend(extra.split_whitespace().map(str::to_string));
        let out = qemu_log(elf, &args)?;
        let (n, rows) = check_golden(&out, RUN_MS)?;
        let rows = if rows > 0 {
            format!(" and {rows} record rows")
        } else {
            String::new()
        };
        println!(
            "QEMU run, NARMAX {narmax}{extra}: {n} log lines (white-box, measured, NARMAX, residuals){rows} equal the host replay, bit for bit"
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str =
        "firmware: virtual bench, SCADA unit 1 on USART1, VFD virtual, mode=2 setpoint=0 seed=1 narmax=f32 head=1000 torque=1020 record=false adapt=false";

    /// A log as the firmware writes it: the header, the lines, margins between, `done`.
    fn log(header: &str, lines: &[String]) -> String {
        log_with_rows(header, lines, &[])
    }

    /// [`log`] with record rows after the lines.
    fn log_with_rows(header: &str, lines: &[String], rows: &[String]) -> String {
        let mut s = format!("{header}\n");
        for l in lines {
            s.push_str(&format!("{l}\nmargin: steps=1 control_max=1\n"));
        }
        for r in rows {
            s.push_str(&format!("{r}\n"));
        }
        s + "done: steps=3001 control_max=1 rx_wait_bound=1 lost=0\n"
    }

    #[test]
    fn host_replay_follows_the_header() {
        let (f32, rows) = host_replay(HEADER, 3000).unwrap();
        assert!(rows.is_empty());
        // One line a second, ticks 0..=3000.
        assert_eq!(f32.len(), 4);
        for (i, l) in f32.iter().enumerate() {
            assert!(
                l.starts_with(&format!("t_s={i} mode=profile narmax=f32 u_pct=")),
                "{l}"
            );
            assert!(l.contains(" alarms=") && l.contains(" status="), "{l}");
        }
        // The same run again: the same text; another arithmetic, seed or mode: not.
        assert_eq!(host_replay(HEADER, 3000).unwrap().0, f32);
        let q15 = host_replay(&HEADER.replace("narmax=f32", "narmax=q15"), 3000)
            .unwrap()
            .0;
        assert!(q15[1].starts_with("t_s=1 mode=profile narmax=q15 "));
        assert_ne!(
            q15[1].split_once(" u_pct").unwrap().1,
            f32[1].split_once(" u_pct").unwrap().1
        );
        let seed = host_replay(&HEADER.replace("seed=1", "seed=2"), 3000)
            .unwrap()
            .0;
        assert_ne!(seed[1], f32[1]);
        // Other curves: other values.
        for curves in ["head=950 torque=1020", "head=1000 torque=1070"] {
            let other = host_replay(&HEADER.replace("head=1000 torque=1020", curves), 3000);
            assert_ne!(other.unwrap().0[2], f32[2], "{curves}");
        }
        let manual = host_replay(
            &HEADER.replace("mode=2 setpoint=0", "mode=1 setpoint=6000"),
            3000,
        )
        .unwrap()
        .0;
        assert!(manual[1].starts_with("t_s=1 mode=manual narmax=f32 u_pct=60.0 "));
        // A header without its options is refused.
        assert!(host_replay("firmware: mode=2 seed=1 narmax=f32", 10).is_err());
        assert!(host_replay(&HEADER.replace("narmax=f32", "narmax=f16"), 10).is_err());
        assert!(host_replay(&HEADER.replace("seed=1", "seed=x"), 10).is_err());
        assert!(host_replay(&HEADER.replace(" head=1000", ""), 10).is_err());
        assert!(host_replay(&HEADER.replace(" adapt=false", ""), 10).is_err());
    }

    /// `adapt=true`: the models follow the load, and their free run with its map is what the
    /// log lines show.
    #[test]
    fn the_header_switches_the_models_following_the_load() {
        let plain = host_replay(HEADER, 5000).unwrap().0;
        let header = HEADER.replace("adapt=false", "adapt=true");
        let adapted = host_replay(&header, 5000).unwrap().0;
        let nx = |l: &str| {
            l.split(' ')
                .find(|w| w.starts_with("nx_p="))
                .unwrap()
                .to_string()
        };
        assert_eq!(nx(&plain[0]), nx(&adapted[0]), "the same start");
        assert_ne!(nx(&plain[5]), nx(&adapted[5]), "a free run through its map");
        assert_eq!(
            host_replay(&format!("{header}, runs until stopped"), 5000)
                .unwrap()
                .0,
            adapted
        );
    }

    #[test]
    fn record_rows_of_the_replay() {
        let header = HEADER.replace("record=false", "record=true");
        let (lines, rows) = host_replay(&header, 3000).unwrap();
        // The record does not change the run.
        assert_eq!(lines, host_replay(HEADER, 3000).unwrap().0);
        // A row per 50 ms pressure sample, ticks 0..=3000, the flow on every other one.
        assert_eq!(rows.len(), 61);
        for (k, r) in rows.iter().enumerate() {
            assert!(
                r.starts_with(&format!("rec seq={k} t_ms={} u_pct=", 50 * k)),
                "{r}"
            );
            assert!(r.contains(&format!(" q_new={} ", k % 2 == 0)), "{r}");
        }
        let good = log_with_rows(&header, &lines, &rows);
        assert_eq!(check_golden(&good, 3000), Ok((4, 61)));
        // A row lost, or one value off: refused.
        assert!(check_golden(&log_with_rows(&header, &lines, &rows[1..]), 3000).is_err());
        let mut off = rows.clone();
        off[7] = off[7].replace(" alarms=0 ", " alarms=1 ");
        assert_ne!(off, rows);
        let e = check_golden(&log_with_rows(&header, &lines, &off), 3000).unwrap_err();
        assert!(e.starts_with("firmware: rec seq=7 "), "{e}");
    }

    #[test]
    fn golden_comparison() {
        let host = host_replay(HEADER, 3000).unwrap().0;
        let good = log(HEADER, &host);
        assert_eq!(finished_run_header(&good), Ok(HEADER));
        assert_eq!(compare_lines(&good, &host), Ok(4));
        assert_eq!(check_golden(&good, 3000), Ok((4, 0)));
        // One value one digit off: the text differs, and the error shows both lines.
        let mut off = host.clone();
        let last = off[2].pop().unwrap();
        off[2].push(if last == '9' { '8' } else { '9' });
        let e = compare_lines(&log(HEADER, &off), &host).unwrap_err();
        assert_eq!(e, format!("firmware: {}\nhost:     {}", off[2], host[2]));
        assert!(check_golden(&log(HEADER, &off), 3000).is_err());
        // A line missing, a line more, no line at all.
        assert!(compare_lines(&log(HEADER, &host[..3]), &host).is_err());
        assert!(check_golden(&log(HEADER, &host), 2000).is_err());
        assert!(compare_lines(&log(HEADER, &[]), &[]).is_err());
        // A run that did not finish, or has no header.
        let unfinished = good.replace("done:", "margin:");
        assert!(finished_run_header(&unfinished).is_err());
        assert!(check_golden(&unfinished, 3000).is_err());
        assert!(finished_run_header(&good.replace("firmware:", "firmware ")).is_err());
        // The header's own options decide the replay: another seed does not match.
        let other = log(&HEADER.replace("seed=1", "seed=3"), &host);
        assert!(check_golden(&other, 3000).is_err());
    }

    #[test]
    fn selftest_log() {
        let digests = [("sinf", 0x1234_5678), ("tanh_q15", 0xDEAD_BEEF)];
        let good = "digest sinf=0x12345678\ndigest tanh_q15=0xdeadbeef\ntanh_q15 against libm::tanhf: largest error 0.0001\ncheck tanh_table: ok\ncheck rtu_framer: ok\nselftest: 4 checks, 0 failed\n";
        let report = check_selftest_log(good, &digests).unwrap();
        assert_eq!(
            report,
            "on target: sinf bits equal the host's (0x12345678)\n\
             on target: tanh_q15 bits equal the host's (0xdeadbeef)\n\
             on target: tanh_q15 against libm::tanhf: largest error 0.0001\n\
             on target: check tanh_table: ok\n\
             on target: check rtu_framer: ok\n"
        );
        // A digest one bit off, missing, or unreadable.
        let e = check_selftest_log(&good.replace("0x12345678", "0x12345679"), &digests);
        assert_eq!(
            e.unwrap_err(),
            "selftest: sinf differs on the target: 0x12345679, host 0x12345678"
        );
        assert!(check_selftest_log(&good.replace("digest sinf", "digest cosf"), &digests).is_err());
        assert!(check_selftest_log(&good.replace("0x12345678", "0xZZ"), &digests).is_err());
        // A failed check, or no summary.
        assert!(check_selftest_log(&good.replace(" 0 failed", " 1 failed"), &digests).is_err());
        assert!(check_selftest_log(&good.replace(" 0 failed", " 10 failed"), &digests).is_err());
        assert!(check_selftest_log(&good.replace("selftest:", "self test:"), &digests).is_err());
        // The host's own digests, as the target prints them, pass.
        let host = board_common::selftest::digests();
        let mut printed = String::new();
        for (name, d) in host {
            printed.push_str(&format!("digest {name}={d:#010x}\n"));
        }
        printed.push_str("selftest: 7 checks, 0 failed\n");
        assert!(check_selftest_log(&printed, &host).is_ok());
    }

    #[test]
    fn fault_run() {
        let report =
            "selftest: reading 0xFFFF_FFF0 (a bus fault)\nERROR: HardFault at pc=0x0800_1234\n";
        assert_eq!(check_fault_run(false, report), Ok(()));
        assert!(check_fault_run(true, report).is_err());
        assert!(check_fault_run(false, "ERROR: the read returned 0: no fault\n").is_err());
    }
}
