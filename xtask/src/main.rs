//! Project tasks, run as `cargo xtask <task>`:
//!
//! - `qemu`: build the firmware for QEMU and run it on the virtual bench: a deterministic run
//!   (`-icount`), or with `--scada-pty` in real time until stopped, the SCADA slave on a
//!   pseudo-terminal.
//! - `bench`: the kernels' instructions per call on the MCU (mcu-bench under QEMU), the
//!   images' and model-core's parts' size from their ELF, checked against
//!   `bench/baseline.json` and the size budgets (see [`bench`]).
//! - `test`: everything CI checks: rustfmt, clippy `-D warnings` (host, both firmware boards
//!   and mcu-bench), the no_std crates built for the MCU, the host tests, docs, the bench and
//!   its budgets (both firmware images), QEMU runs whose every log line must equal the same
//!   loop replayed on the host bit for bit, and an end-to-end test with `mbpoll` on the SCADA
//!   port.
//!
//! Needs `qemu-system-arm` and `mbpoll` on the PATH (Debian packages of the same names).

mod bench;
mod bridge;
mod defmt_log;

/// The firmware's NARMAX models, the very files it compiles in.
#[path = "../../firmware/src/models/flow.rs"]
mod flow_model;
#[path = "../../firmware/src/models/pressure.rs"]
mod pressure_model;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::Instant;

const TARGET: &str = "thumbv7em-none-eabihf";
/// Length of the SCADA flood that measures the margins, s.
const FLOOD_S: u64 = 10;
/// Longest a QEMU smoke run may take, s.
const QEMU_TIMEOUT_S: u32 = 120;

type Result<T = ()> = std::result::Result<T, String>;

fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

fn run(what: &str, cmd: &mut Command) -> Result {
    let start = Instant::now();
    eprintln!("==> {what}");
    let status = cmd
        .current_dir(root())
        .status()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    eprintln!("    {what}: {:.1} s", start.elapsed().as_secs_f64());
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} failed ({status})"))
    }
}

/// Cargo's target directory (`CARGO_TARGET_DIR`, else `target/` at the root).
fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

/// A board's firmware image (profile `firmware`).
fn firmware_elf(board: Board) -> PathBuf {
    target_dir()
        .join(TARGET)
        .join("firmware")
        .join(board.binary())
}

/// Flash and static RAM budget of an image, bytes.
#[derive(Clone, Copy)]
struct Budget {
    flash: u64,
    ram: u64,
}

/// The QEMU image's budget (the issue's: 64 KiB flash, 16 KiB static RAM).
const QEMU_BUDGET: Budget = Budget {
    flash: 64 * 1024,
    ram: 16 * 1024,
};
/// The NUCLEO-F446RE image's budget.
const NUCLEO_BUDGET: Budget = Budget {
    flash: 64 * 1024,
    ram: 16 * 1024,
};

/// The two boards the firmware builds for.
#[derive(Clone, Copy, PartialEq)]
enum Board {
    Qemu,
    Nucleo,
}

impl Board {
    fn name(self) -> &'static str {
        match self {
            Board::Qemu => "qemu (STM32F405 netduinoplus2)",
            Board::Nucleo => "nucleo-f446re",
        }
    }
    /// The image's key in `mcu.json`.
    fn key(self) -> &'static str {
        match self {
            Board::Qemu => "qemu",
            Board::Nucleo => "nucleo-f446re",
        }
    }
    fn budget(self) -> Budget {
        match self {
            Board::Qemu => QEMU_BUDGET,
            Board::Nucleo => NUCLEO_BUDGET,
        }
    }
    /// The board's crate.
    fn package(self) -> &'static str {
        match self {
            Board::Qemu => "board-qemu",
            Board::Nucleo => "board-nucleo-f446re",
        }
    }
    /// What the board's own `.cargo/config.toml` adds, for builds from the workspace root
    /// (the Nucleo: `-C target-cpu=cortex-m4`).
    fn config_args(self) -> &'static [&'static str] {
        match self {
            Board::Qemu => &[],
            Board::Nucleo => &[
                "--config",
                "target.thumbv7em-none-eabihf.rustflags=[\"-C\", \"target-cpu=cortex-m4\"]",
            ],
        }
    }
    /// The board's firmware binary.
    fn binary(self) -> &'static str {
        match self {
            Board::Qemu => "pump-qemu",
            Board::Nucleo => "pump-nucleo-f446re",
        }
    }
}

/// `flip-link` (the linker `.cargo/config.toml` names for the MCU: it puts the stack below
/// the static data, so an overflow faults instead of corrupting them), installed with
/// `cargo install --locked` (≈ 10 s) if it is not on the PATH.
fn ensure_flip_link() -> Result {
    if Command::new("flip-link").arg("--version").output().is_ok() {
        return Ok(());
    }
    run(
        "install flip-link (the MCU images' linker)",
        cargo().args(["install", "--locked", "flip-link"]),
    )
}

fn build_firmware(board: Board) -> Result {
    ensure_flip_link()?;
    run(
        &format!(
            "firmware build for {} (profile firmware: opt-level s, LTO)",
            board.name()
        ),
        cargo()
            .args([
                "build",
                "-p",
                board.package(),
                "--profile",
                "firmware",
                "--target",
                TARGET,
            ])
            .args(board.config_args())
            .env("DEFMT_LOG", "info"),
    )
}

/// QEMU's command line for the firmware, with semihosting arguments `args`.
fn qemu_command(elf: &Path, args: &[String]) -> Command {
    let name = elf.file_name().unwrap_or_default().to_string_lossy();
    let mut semihosting = format!("enable=on,target=native,arg={name}");
    for a in args {
        semihosting.push_str(",arg=");
        semihosting.push_str(a);
    }
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args(["-cpu", "cortex-m4", "-machine", "netduinoplus2"])
        .args(["-semihosting-config", &semihosting])
        .arg("-kernel")
        .arg(elf);
    cmd
}

/// Runs an image in QEMU to its end, deterministic and faster than real time (`-icount
/// shift=0,sleep=off`), with `io` for its display and serial ports; returns whether it exited
/// 0 and its standard output.
fn qemu_run(elf: &Path, args: &[String], io: &[&str]) -> Result<(bool, Vec<u8>)> {
    let start = Instant::now();
    let mut cmd = qemu_command(elf, args);
    cmd.args(io).args(["-icount", "shift=0,sleep=off"]);
    let out = Command::new("timeout")
        .arg(QEMU_TIMEOUT_S.to_string())
        .arg(cmd.get_program())
        .args(cmd.get_args())
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| {
            format!("cannot start qemu-system-arm (apt-get install qemu-system-arm): {e}")
        })?;
    let name = elf.file_name().unwrap_or_default().to_string_lossy();
    eprintln!(
        "    qemu {name} {}: {:.1} s, {}",
        args.join(" "),
        start.elapsed().as_secs_f64(),
        out.status
    );
    Ok((out.status.success(), out.stdout))
}

/// The text an image (the bench, a size probe) writes over semihosting, run by [`qemu_run`]
/// with `-nographic`; an error if it exits non-zero.
fn qemu_output(elf: &Path, args: &[String]) -> Result<String> {
    let (ok, out) = qemu_run(elf, args, &["-nographic"])?;
    let text = String::from_utf8_lossy(&out).into_owned();
    if ok {
        Ok(text)
    } else {
        let name = elf.file_name().unwrap_or_default().to_string_lossy();
        Err(format!("{name} in QEMU exited non-zero:\n{text}"))
    }
}

/// A board's image run by [`qemu_run`], its serial ports unconnected: its defmt log, decoded
/// (an error if it exits non-zero).
fn qemu_log(elf: &Path, args: &[String]) -> Result<String> {
    let (ok, text) = qemu_log_status(elf, args)?;
    if ok {
        Ok(text)
    } else {
        let name = elf.file_name().unwrap_or_default().to_string_lossy();
        Err(format!("{name} in QEMU exited non-zero:\n{text}"))
    }
}

/// As [`qemu_log`], with whether the image exited 0.
fn qemu_log_status(elf: &Path, args: &[String]) -> Result<(bool, String)> {
    let io = [
        "-display", "none", "-monitor", "none", "-serial", "null", "-serial", "null",
    ];
    let (ok, out) = qemu_run(elf, args, &io)?;
    Ok((ok, defmt_log::decode(elf, &out)?))
}

/// The on-target checks (`boards/qemu`'s `selftest`) in QEMU: their digests must equal the
/// host's of the same functions, bit for bit, every check must pass, and a fault must be
/// reported and end the run with status 1.
fn selftest() -> Result<String> {
    let elf = target_dir().join(TARGET).join("firmware").join("selftest");
    let log = qemu_log(&elf, &[])?;
    let mut report = String::new();
    for (name, host) in firmware::selftest::digests() {
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
    let (ok, fault) = qemu_log_status(&elf, &["fault".into()])?;
    if ok || !fault.contains("ERROR: HardFault at pc=") {
        return Err(format!(
            "selftest fault: expected the HardFault report and exit status 1, got exit {}:\n{fault}",
            if ok { 0 } else { 1 }
        ));
    }
    report.push_str("on target: a bus fault is reported (HardFault at pc=…) and QEMU exits 1\n");
    Ok(report)
}

fn field<'a>(line: &'a str, key: &str) -> Result<&'a str> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .ok_or_else(|| format!("no '{key}=' in line: {line}"))
}

fn num<T: std::str::FromStr>(line: &str, key: &str) -> Result<T> {
    field(line, key)?
        .parse()
        .map_err(|_| format!("bad '{key}' in line: {line}"))
}

/// The firmware replayed on the host: the same `controller` code (the core, its links and the
/// virtual bench with its in-process drive, run by `VirtualBoard` in the firmware's task
/// order), with the options the firmware announces in its header line.
/// Returns the log lines it makes for the ticks `0..=run_ms`.
fn host_replay(header: &str, run_ms: u32) -> Result<Vec<String>> {
    use controller::bench::{VirtualBenchConfig, VirtualBoard};
    use controller::control::{Config, NarmaxModel};
    use controller::types::{Arithmetic, Mode};
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
    let mut board =
        VirtualBoard::new(&config, p, q, VirtualBenchConfig::default_offsets(seed)).map_err(e)?;
    let mut lines = vec![];
    for _ in 0..=run_ms {
        if let Some(log) = board.tick().map_err(|e| e.to_string())?.log {
            lines.push(log_text(&log));
        }
    }
    Ok(lines)
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
fn check_golden(output: &str, run_ms: u32) -> Result<usize> {
    let header = output
        .lines()
        .find(|l| l.starts_with("firmware:"))
        .ok_or("no 'firmware:' header line")?;
    if !output.lines().any(|l| l.starts_with("done")) {
        return Err("the firmware did not print 'done'".into());
    }
    let target: Vec<&str> = output.lines().filter(|l| l.starts_with("t_s=")).collect();
    let host = host_replay(header, run_ms)?;
    if target.len() != host.len() || target.is_empty() {
        return Err(format!(
            "the firmware logged {} lines, the host replay {}",
            target.len(),
            host.len()
        ));
    }
    for (t, h) in target.iter().zip(&host) {
        if t != h {
            return Err(format!("firmware: {t}\nhost:     {h}"));
        }
    }
    Ok(target.len())
}

/// Options of `cargo xtask qemu`.
struct QemuOptions {
    scada_pty: bool,
    vfd: Option<String>,
    seconds: u32,
    firmware_args: Vec<String>,
}

fn parse_qemu_options(args: &[String]) -> Result<QemuOptions> {
    let mut o = QemuOptions {
        scada_pty: false,
        vfd: None,
        seconds: 20,
        firmware_args: vec![],
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |name: &str| {
            it.next()
                .cloned()
                .ok_or_else(|| format!("{name} needs a value"))
        };
        match a.as_str() {
            "--scada-pty" => o.scada_pty = true,
            "--vfd" => o.vfd = Some(value("--vfd")?),
            "--seconds" => {
                o.seconds = value("--seconds")?
                    .parse()
                    .map_err(|_| "--seconds takes a whole number")?
            }
            "--mode" => o.firmware_args.push(format!("mode={}", value("--mode")?)),
            "--setpoint" => o
                .firmware_args
                .push(format!("setpoint={}", value("--setpoint")?)),
            "--seed" => o.firmware_args.push(format!("seed={}", value("--seed")?)),
            "--narmax" => o
                .firmware_args
                .push(format!("narmax={}", value("--narmax")?)),
            other => return Err(format!("unknown option '{other}'\n{QEMU_USAGE}")),
        }
    }
    Ok(o)
}

const QEMU_USAGE: &str = "usage: cargo xtask qemu [--scada-pty] [--vfd PTY] [--seconds N] [--mode 0|1|2] [--setpoint 0..10000] [--seed N] [--narmax f32|q15]
  (no --scada-pty)  run the virtual bench for --seconds (default 20) of loop time, mode 2 (the
                    paper's excitation) unless --mode says otherwise, deterministic and faster
                    than real time (-icount); the kernels' cost is `cargo xtask bench`
  --scada-pty       real time, until stopped (Ctrl-C): the SCADA slave (unit 1, 19200 8N1 RTU)
                    on a pseudo-terminal; QEMU prints its path. Starts stopped (mode 0).
  --vfd PTY         the VFD master on USART2 to that serial device (e.g. pumpbench vfd-sim's)";

const BENCH_USAGE: &str = "usage: cargo xtask bench [--save-baseline]
  (no option)       build and run mcu-bench in QEMU (-icount shift=0), measure both firmware
                    images; print the tables, write mcu.json under the target directory's
                    bench/; fail if a kernel costs more than 5 % over bench/baseline.json or an
                    image exceeds its flash or RAM budget
  --save-baseline   the same, then write the figures to bench/baseline.json (new budgets)";

fn qemu(args: &[String]) -> Result {
    let o = parse_qemu_options(args)?;
    build_firmware(Board::Qemu)?;
    let elf = firmware_elf(Board::Qemu);
    let mut fw_args = o.firmware_args.clone();
    if o.vfd.is_some() {
        fw_args.push("vfd=uart".into());
    }
    if o.scada_pty || o.vfd.is_some() {
        let mut cmd = qemu_command(&elf, &fw_args);
        cmd.args(["-display", "none", "-monitor", "none"]);
        cmd.args(["-serial", if o.scada_pty { "pty" } else { "null" }]);
        cmd.arg("-serial");
        match &o.vfd {
            // QEMU takes a host serial device by its /dev path: resolve links (socat's).
            Some(p) => cmd.arg(std::fs::canonicalize(p).map_err(|e| format!("--vfd {p}: {e}"))?),
            None => cmd.arg("null"),
        };
        eprintln!("==> qemu (real time, until stopped: Ctrl-C)");
        if !o.scada_pty {
            let status = cmd
                .status()
                .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
            return if status.success() {
                Ok(())
            } else {
                Err(format!("qemu: {status}"))
            };
        }
        let (mut qemu, bridge, _, _) = e2e::start_pty(&elf, cmd, true)?;
        let pty = bridge.path.clone();
        eprintln!(
            "SCADA slave (unit 1, RTU 19200 8N1) on {pty}; e.g.\n  mbpoll -m rtu -b 19200 -P none -a 1 -t 3 -r 1 -c 18 {pty}\n  mbpoll -m rtu -b 19200 -P none -a 1 -t 4 -r 1 -1 {pty} 5000 1"
        );
        // Report what the line dropped (answers nobody read), when it changes.
        let mut reported = 0;
        let status = loop {
            if let Some(status) = qemu.0.try_wait().map_err(|e| format!("qemu: {e}"))? {
                break status;
            }
            std::thread::sleep(std::time::Duration::from_secs(1));
            let dropped = bridge.stats.dropped();
            if dropped != reported {
                reported = dropped;
                eprintln!("{}", bridge.stats.summary());
            }
        };
        return if status.success() {
            Ok(())
        } else {
            Err(format!("qemu: {status}"))
        };
    }
    if !fw_args.iter().any(|a| a.starts_with("mode=")) {
        fw_args.push("mode=2".into());
    }
    fw_args.push(format!("run_ms={}", o.seconds * 1000 + 1));
    print!("{}", qemu_log(&elf, &fw_args)?);
    Ok(())
}

/// The end-to-end check: the firmware in QEMU in real time with its SCADA port on a
/// pseudo-terminal, driven by `mbpoll` (another Modbus implementation, libmodbus).
mod e2e {
    use super::{qemu_command, Result};
    use std::io::{BufRead, BufReader, Write};
    use std::path::Path;
    use std::process::{Child, Command, Stdio};
    use std::time::{Duration, Instant};

    /// QEMU, killed when dropped.
    pub struct Qemu(pub Child);
    impl Drop for Qemu {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    /// `mbpoll` in RTU mode (19200 8N1, 1 s timeout, one poll): `args`, the port, `values`.
    fn mbpoll(pty: &str, args: &[&str], values: &[&str]) -> Result<String> {
        let out = Command::new("mbpoll")
            .args(["-m", "rtu", "-b", "19200", "-P", "none", "-o", "1", "-1"])
            .args(args)
            .arg(pty)
            .args(values)
            .output()
            .map_err(|e| format!("cannot run mbpoll (apt-get install mbpoll): {e}"))?;
        let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
        text.push_str(&String::from_utf8_lossy(&out.stderr));
        Ok(text)
    }

    /// Registers `[n]: value` from an mbpoll read (1-based references as mbpoll prints them).
    fn registers(text: &str, first: usize, count: usize) -> Result<Vec<i64>> {
        (first..first + count)
            .map(|r| {
                let key = format!("[{r}]:");
                text.lines()
                    .find_map(|l| l.trim().strip_prefix(&key))
                    .and_then(|v| v.split_whitespace().next()?.parse().ok())
                    .ok_or_else(|| format!("register {r} not in mbpoll's answer:\n{text}"))
            })
            .collect()
    }

    /// QEMU with its SCADA port on a pseudo-terminal, started: the process (killed when
    /// dropped), the [`bridge`](crate::bridge) that offers clients the port as a line (its
    /// `path`), and QEMU's output lines (also echoed to the terminal if `echo`).
    pub fn start_pty(
        elf: &Path,
        mut cmd: Command,
        echo: bool,
    ) -> Result<(
        Qemu,
        crate::bridge::Bridge,
        std::sync::mpsc::Receiver<String>,
        Option<String>,
    )> {
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd
            .spawn()
            .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
        let stderr = child.stderr.take().ok_or("no stderr")?;
        let stdout = child.stdout.take().ok_or("no stdout")?;
        let qemu = Qemu(child);
        // QEMU names the pty on stderr; the firmware logs on stdout (semihosting).
        let (tx, rx) = std::sync::mpsc::channel();
        let tx2 = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(|l| l.ok()) {
                if echo {
                    eprintln!("{line}");
                }
                let _ = tx.send(line);
            }
        });
        // Standard output: QEMU's own text lines first (the pty's name), then the firmware's
        // defmt frames.
        let mut decoder = crate::defmt_log::LogDecoder::new(elf)?;
        std::thread::spawn(move || {
            const QEMU_LINE: &[u8] = b"char device redirected to ";
            let mut stdout = stdout;
            let mut pending = Vec::new();
            let mut frames = false;
            let mut buf = [0u8; 4096];
            while let Ok(n) = std::io::Read::read(&mut stdout, &mut buf) {
                if n == 0 {
                    break;
                }
                let mut lines = vec![];
                if frames {
                    lines = decoder.feed(&buf[..n]).unwrap_or_default();
                } else {
                    pending.extend_from_slice(&buf[..n]);
                    loop {
                        if pending.starts_with(QEMU_LINE) {
                            let Some(end) = pending.iter().position(|&b| b == b'\n') else {
                                break;
                            };
                            let line = String::from_utf8_lossy(&pending[..end]).into_owned();
                            lines.push(line.trim_end().to_string());
                            pending.drain(..=end);
                        } else if QEMU_LINE.starts_with(&pending) {
                            break; // too short to tell yet
                        } else {
                            frames = true;
                            lines.extend(decoder.feed(&pending).unwrap_or_default());
                            pending.clear();
                            break;
                        }
                    }
                }
                for line in lines {
                    if echo {
                        println!("{line}");
                    }
                    let _ = tx2.send(line);
                }
            }
        });
        let deadline = Instant::now() + Duration::from_secs(20);
        let (mut pty, mut second) = (None, None);
        let mut started = false;
        while pty.is_none() || !started {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = rx
                .recv_timeout(left)
                .map_err(|_| "QEMU did not announce its pty and the firmware's start")?;
            // "char device redirected to /dev/pts/N (label serial0)"
            if let Some(rest) = line.strip_prefix("char device redirected to ") {
                let path = rest.split_whitespace().next().map(str::to_string);
                if rest.contains("serial1") {
                    second = path;
                } else {
                    pty = path;
                }
            }
            started |= line.starts_with("firmware:");
        }
        let pty = pty.ok_or("no pty")?;
        let bridge = crate::bridge::start(&pty)?;
        Ok((qemu, bridge, rx, second))
    }

    /// What a user does with the observer over Modbus (mbpoll), running at 50 %: read the
    /// estimates, close the valve by 30 %, fail the pressure transmitter, cut the drive's
    /// link; the estimate follows and the right alarm rises.
    fn observer_session(pty: &str, report: &mut String) -> Result {
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
        // The virtual bench's valve is the paper's k2 × 1.02 (a few percent off the model).
        let bench_k2 = 0.1082 * 1.02;
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
        if (k2 / (bench_k2 * 1.3) - 1.0).abs() > 0.03 || o[3] != 1 << 6 {
            return Err(format!("after closing the valve: {o:?}\n{report}"));
        }
        holding("4", "1000")?;
        for (faults, bit, what) in [
            ("2", 0, "pressure transmitter at 2 mA"),
            ("8", 2, "VFD link cut"),
        ] {
            holding("5", faults)?;
            std::thread::sleep(Duration::from_secs(2));
            let o = observer()?;
            report.push_str(&format!(
                "{what} (holding 4 = {faults}): alarms {:#04x}\n",
                o[3]
            ));
            if o[3] & (1 << bit) == 0 {
                return Err(format!(
                    "{what}: alarm bit {bit} not raised: {o:?}\n{report}"
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

    /// The protections as a user tries them over Modbus (mbpoll), running at 50 %: a dry
    /// run injected trips the torque to 0 % by the time its alarm is up and holds it; an
    /// acknowledge while the fault stands keeps 0 %; fault cleared, acknowledged, manual
    /// again: running. An overspeed limit written low trips within 0.5 s. At rest, a
    /// transmitter fault clears within 3 s of its removal; one stop write acknowledges a
    /// cured dry run (the protection set to warn) within 3 s.
    fn protection_session(pty: &str, report: &mut String) -> Result {
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
        const TRIPPED: i64 = 1 << 7;
        const DRY_RUN: i64 = 1 << 3;
        let r = inputs()?;
        if r[1] != 5000 || r[0] & TRIPPED != 0 {
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
        if r[1] != 0 || r[0] & TRIPPED == 0 || alarm_s > 7.0 {
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
        let (clear_s, _) = until(Duration::from_secs(10), &|r| r[0] & TRIPPED == 0)
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
        if trip_s > 0.5 || r[23] != 1 << 8 {
            return Err(format!("overspeed trip: {r:?}\n{report}"));
        }
        holding(5, 1925)?;
        std::thread::sleep(Duration::from_secs(3));
        holding(1, 0)?;
        until(Duration::from_secs(5), &|r| {
            r[0] & TRIPPED == 0 && r[21] == 0
        })
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

    pub fn run(elf: &Path) -> Result<String> {
        let mut cmd = qemu_command(elf, &["mode=0".into()]);
        cmd.args(["-display", "none", "-monitor", "none"])
            .args(["-serial", "pty", "-serial", "null"]);
        let (qemu, bridge, _, _) = start_pty(elf, cmd, false)?;
        let pty = bridge.path.clone();
        let mut report = format!("SCADA on {pty}\n");

        // Read all input registers (FC 04).
        let read = |report: &mut String| -> Result<Vec<i64>> {
            let t = mbpoll(&pty, &["-a", "1", "-t", "3", "-r", "1", "-c", "18"], &[])?;
            let r = registers(&t, 1, 18)?;
            report.push_str(&format!("inputs: {r:?}\n"));
            Ok(r)
        };
        let r0 = read(&mut report)?;
        if r0[1] != 0 || r0[0] & 1 != 0 {
            return Err(format!("stopped at start expected, read {r0:?}"));
        }
        // Setpoint 50 % and manual mode (FC 16 of two holding registers).
        let w = mbpoll(&pty, &["-a", "1", "-t", "4", "-r", "1"], &["5000", "1"])?;
        if !w.contains("Written 2 references") {
            return Err(format!("write setpoint and mode: {w}"));
        }
        std::thread::sleep(Duration::from_secs(3));
        let r = read(&mut report)?;
        let bench = model_core::WhiteBox::<f32>::paper();
        let op = bench.signals(&bench.steady_state(50.0).map_err(|e| e.to_string())?);
        let speed = r[6] as f64 / 10.0;
        let pressure = (r[2] as i16) as f64 / 1000.0;
        let flow = r[3] as f64 / 100.0;
        let rel = |a: f64, b: f32| (a / b as f64 - 1.0).abs();
        report.push_str(&format!(
            "after 3 s at 50 %: white-box speed {speed} rpm (model {:.1}), measured pressure {pressure} mca (model {:.3}), flow {flow} l/s (model {:.2})\n",
            op.speed_rpm, op.pressure_mca, op.flow_lps
        ));
        if r[1] != 5000
            || rel(speed, op.speed_rpm) > 0.01
            || rel(pressure, op.pressure_mca) > 0.05
            || rel(flow, op.flow_lps) > 0.05
            || r[0] & 0b1011 != 0b1001
        {
            return Err(format!("operating point at 50 % not reached:\n{report}"));
        }
        // Spec exceptions.
        let t = mbpoll(&pty, &["-a", "1", "-t", "3", "-r", "27", "-c", "1"], &[])?;
        if !t.to_lowercase().contains("illegal data address") {
            return Err(format!(
                "input register 26: expected exception 02, got:\n{t}"
            ));
        }
        let t = mbpoll(&pty, &["-a", "1", "-t", "4", "-r", "1"], &["10001"])?;
        if !t.to_lowercase().contains("illegal data value") {
            return Err(format!("setpoint 10001: expected exception 03, got:\n{t}"));
        }
        report.push_str(
            "exceptions 02 (input register 26) and 03 (setpoint 10001): as the spec says\n",
        );
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
        if r2[1] != 5000 {
            return Err(format!(
                "the slave must still answer after malformed frames: {r2:?}"
            ));
        }
        report.push_str("bad CRC and unit 2: silence; the next request answered\n");
        observer_session(&pty, &mut report)?;
        protection_session(&pty, &mut report)?;
        crate::line::checks(&pty, &bridge, &mut report)?;
        drop(qemu);
        Ok(report)
    }
}

/// The SCADA line under hostile clients (regressions of a hostile run): traffic must not slow
/// the loop, a client that stops reading must not stop the controller, an answer nobody read
/// must not reach the next client, and noise or back-to-back requests must be taken at the
/// rate QEMU allows.
mod line {
    use super::Result;
    use crate::bridge::Bridge;
    use controller::modbus::crc16;
    use nix::fcntl::{open, OFlag};
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use nix::sys::stat::Mode;
    use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
    use nix::unistd::{read, write};
    use std::os::fd::{AsFd, OwnedFd};
    use std::time::{Duration, Instant};

    /// A raw client port.
    struct Port(OwnedFd);

    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&crc16(body).to_le_bytes());
        f
    }

    impl Port {
        fn open(path: &str) -> Result<Self> {
            let fd = open(
                path,
                OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK,
                Mode::empty(),
            )
            .map_err(|e| format!("{path}: {e}"))?;
            let mut t = tcgetattr(&fd).map_err(|e| e.to_string())?;
            cfmakeraw(&mut t);
            tcsetattr(&fd, SetArg::TCSANOW, &t).map_err(|e| e.to_string())?;
            Ok(Self(fd))
        }

        /// Writes all of `bytes` (the port is non-blocking: waits while it is full).
        fn send(&self, mut bytes: &[u8]) -> Result {
            let end = Instant::now() + Duration::from_secs(5);
            while !bytes.is_empty() {
                match write(&self.0, bytes) {
                    Ok(n) => bytes = &bytes[n..],
                    Err(nix::errno::Errno::EAGAIN) if Instant::now() < end => {
                        std::thread::sleep(Duration::from_millis(1))
                    }
                    Err(e) => return Err(format!("client write: {e}")),
                }
            }
            Ok(())
        }

        /// Up to `n` bytes received within `timeout`.
        fn recv(&self, n: usize, timeout: Duration) -> Vec<u8> {
            let end = Instant::now() + timeout;
            let mut got = Vec::new();
            let mut buf = [0u8; 512];
            while got.len() < n {
                let left = end.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    break;
                }
                let ms = left.as_millis().clamp(1, 1000) as u16;
                let mut fds = [PollFd::new(self.0.as_fd(), PollFlags::POLLIN)];
                if poll(&mut fds, PollTimeout::from(ms)).unwrap_or(0) > 0 {
                    if let Ok(k) = read(&self.0, &mut buf) {
                        got.extend_from_slice(&buf[..k]);
                    }
                }
            }
            got
        }

        /// Input registers `start..start + count` (FC 04), or `None` without a valid answer
        /// within `timeout`.
        fn inputs(&self, start: u16, count: u16, timeout: Duration) -> Result<Option<Vec<u16>>> {
            let [a, b] = start.to_be_bytes();
            self.send(&frame(&[1, 4, a, b, 0, count as u8]))?;
            let n = 5 + 2 * usize::from(count);
            let ans = self.recv(n, timeout);
            let ok = ans.len() == n
                && ans[..3] == [1, 4, 2 * count as u8]
                && crc16(&ans[..n - 2]).to_le_bytes() == ans[n - 2..];
            Ok(ok.then(|| {
                ans[3..n - 2]
                    .chunks(2)
                    .map(|w| u16::from_be_bytes([w[0], w[1]]))
                    .collect()
            }))
        }

        /// The sample counter (input 9: +1 per 50 ms pressure sample).
        fn samples(&self, when: &str) -> Result<u16> {
            self.inputs(9, 1, Duration::from_secs(1))?
                .map(|r| r[0])
                .ok_or_else(|| format!("no answer to a read of the sample counter ({when})"))
        }
    }

    /// SCADA flooded for `seconds` with the VFD link busy: the VFD master on USART2 talking to
    /// `pumpbench vfd-sim` (a drive over a serial line: its interrupts, its queue), and
    /// requests back to back as fast as the answers come, one in ten sent as two requests in
    /// one write. Fails if any request goes unanswered or wrong, if a received byte was lost
    /// (the firmware counts a full queue or an overrun), or if the drive's link fails.
    ///
    /// In real time (`icount` false) it also fails if the loop's sample counter strays from
    /// the wall clock by more than 1 %. With `-icount shift=0` (`icount` true) QEMU's clock
    /// advances one ns per instruction while the core runs, so the firmware's margins are
    /// instruction counts; its clock then runs slower than the wall's whenever the host
    /// emulates under 1 G instructions/s, so the rate is reported, not checked. Returns the
    /// report, with the firmware's last `margin:` line.
    pub fn flood(elf: &std::path::Path, seconds: u64, icount: bool) -> Result<String> {
        use crate::e2e::{start_pty, Qemu};
        let mut cmd = crate::qemu_command(
            elf,
            &["mode=1".into(), "setpoint=5000".into(), "vfd=uart".into()],
        );
        cmd.args(["-display", "none", "-monitor", "none"])
            .args(["-serial", "pty", "-serial", "pty"]);
        if icount {
            cmd.args(["-icount", "shift=0"]);
        }
        let (qemu, bridge, log, vfd_pty) = start_pty(elf, cmd, false)?;
        let vfd_pty = vfd_pty.ok_or("QEMU announced no pty for USART2")?;
        let sim = std::process::Command::new(std::env::var_os("CARGO").unwrap_or("cargo".into()))
            .current_dir(crate::root())
            .args([
                "run",
                "--quiet",
                "-p",
                "pumpbench",
                "--",
                "vfd-sim",
                "--port",
                &vfd_pty,
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start pumpbench vfd-sim: {e}"))?;
        let _sim = Qemu(sim); // killed when dropped
        let port = Port::open(&bridge.path)?;
        // The drive's link up (status bit 3) before the flood.
        let t = Instant::now();
        loop {
            let ok = port
                .inputs(0, 1, Duration::from_secs(1))?
                .is_some_and(|r| r[0] & 0b1000 != 0);
            if ok {
                break;
            }
            if t.elapsed() > Duration::from_secs(60) {
                return Err("the VFD link over USART2 to pumpbench vfd-sim did not come up".into());
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        let (s0, t0) = (port.samples("before the flood")?, Instant::now());
        let (mut sent, mut answered, mut status_or) = (0u32, 0u32, 0u16);
        let mut status_and = 0xFFFFu16;
        while t0.elapsed() < Duration::from_secs(seconds) {
            if sent % 10 == 9 {
                let (a, b) = (frame(&[1, 4, 0, 0, 0, 18]), frame(&[1, 3, 0, 0, 0, 3]));
                port.send(&[a, b].concat())?;
                sent += 2;
                let both = port.recv(41 + 11, Duration::from_secs(1));
                let ok = both.len() == 52
                    && both[..3] == [1, 4, 36]
                    && crc16(&both[..39]).to_le_bytes() == both[39..41]
                    && both[41..44] == [1, 3, 6]
                    && crc16(&both[41..50]).to_le_bytes() == both[50..52];
                answered += 2 * u32::from(ok);
            } else {
                sent += 1;
                if let Some(r) = port.inputs(0, 18, Duration::from_secs(1))? {
                    answered += 1;
                    status_or |= r[0];
                    status_and &= r[0];
                }
            }
        }
        let (s1, wall) = (port.samples("after the flood")?, t0.elapsed().as_secs_f64());
        let rate = f64::from(s1.wrapping_sub(s0)) / (wall * 20.0) - 1.0;
        // The firmware logs its margins once a second; the last line covers the flood.
        std::thread::sleep(Duration::from_millis(1500));
        drop(qemu);
        let lines: Vec<String> = log.try_iter().collect();
        let margin = lines
            .iter()
            .rev()
            .find(|l| l.starts_with("margin:"))
            .ok_or("the firmware logged no margin line")?
            .clone();
        let get = |k: &str| -> Result<u64> { crate::num(&margin, k) };
        let (lost, bytes) = (get("lost")?, get("bytes")?);
        let mut report = format!(
            "flood, {seconds} s {}, VFD on USART2 to pumpbench vfd-sim: {answered} of {sent} requests answered ({:.0}/s), loop at {:+.2} % of wall time{}\n  firmware: {margin}\n  rx_wait_bound = usart_max + masked_max; {}\n",
            if icount { "under -icount shift=0" } else { "in real time" },
            f64::from(sent) / wall,
            rate * 100.0,
            if icount { " (QEMU's clock, not checked)" } else { "" },
            if icount {
                "counts are instructions (QEMU -icount shift=0)"
            } else {
                "counts are QEMU's virtual ns in real time: the host's speed, not the MCU's"
            }
        );
        for l in lines
            .iter()
            .filter(|l| l.starts_with("ERROR") || l.starts_with("WARN"))
        {
            report.push_str(&format!("  firmware said: {l}\n"));
        }
        if answered != sent {
            return Err(format!(
                "{} requests unanswered or wrong under the flood\n{report}",
                sent - answered
            ));
        }
        if lost != 0 {
            return Err(format!("{lost} received bytes lost\n{report}"));
        }
        if bytes < u64::from(sent) * 8 {
            return Err(format!("the firmware counted {bytes} bytes received, fewer than the {sent} requests hold\n{report}"));
        }
        if status_and & 0b1000 == 0 || status_or & 0b100_0000 != 0 {
            return Err(format!("the VFD link failed during the flood (status seen: and {status_and:#06b}, or {status_or:#09b})\n{report}"));
        }
        if !icount && rate.abs() > 0.01 {
            return Err(format!("the loop's rate depends on the flood\n{report}"));
        }
        Ok(report)
    }

    pub fn checks(pty: &str, bridge: &Bridge, report: &mut String) -> Result {
        // 1. Traffic does not slow the loop: 50 reads a second for 10 s, sample counter
        //    (20 per second) against wall time.
        let port = Port::open(pty)?;
        let (s0, t0) = (port.samples("before 10 s of reads")?, Instant::now());
        let mut reads = 0;
        while t0.elapsed() < Duration::from_secs(10) {
            let t = Instant::now();
            port.inputs(0, 18, Duration::from_secs(1))?
                .ok_or("a read under traffic got no answer")?;
            reads += 1;
            std::thread::sleep(Duration::from_millis(20).saturating_sub(t.elapsed()));
        }
        let (s1, wall) = (
            port.samples("after 10 s of reads")?,
            t0.elapsed().as_secs_f64(),
        );
        let rate = f64::from(s1.wrapping_sub(s0)) / (wall * 20.0) - 1.0;
        report.push_str(&format!(
            "{reads} reads in {wall:.1} s ({:.0}/s): loop at {:+.2} % of wall time (sample counter)\n",
            f64::from(reads) / wall,
            rate * 100.0
        ));
        if rate.abs() > 0.01 {
            return Err(format!(
                "the loop's rate depends on traffic: {:+.2} % of wall time (limit ±1 %)\n{report}",
                rate * 100.0
            ));
        }
        // 2. Noise is taken fast: 2000 bytes, then a read is answered within 1 s.
        port.send(&[0x55; 2000])?;
        let t = Instant::now();
        std::thread::sleep(Duration::from_millis(20));
        port.inputs(17, 1, Duration::from_secs(1))?
            .ok_or("no answer within 1 s to a read after 2000 bytes of noise")?;
        report.push_str(&format!(
            "2000 bytes of noise, then a read: answered {} ms after the noise\n",
            t.elapsed().as_millis()
        ));
        // 3. Back-to-back writes, one every 10 ms (no 10 ms silence ever): all answered.
        let mut answered = 0;
        let t = Instant::now();
        for i in 0..100u16 {
            let next = t + Duration::from_millis(10 * u64::from(i));
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
            let [a, b] = (i * 50).to_be_bytes();
            let w = frame(&[1, 6, 0, 0, a, b]);
            port.send(&w)?;
            answered += usize::from(port.recv(8, Duration::from_millis(500)) == w);
        }
        report.push_str(&format!(
            "100 setpoint writes, one every 10 ms: {answered} answered in {:.2} s\n",
            t.elapsed().as_secs_f64()
        ));
        if answered != 100 {
            return Err(format!(
                "only {answered} of 100 back-to-back writes answered"
            ));
        }
        // Two requests in one write (no gap at all): both answered, in order.
        let (a, b) = (frame(&[1, 4, 0, 17, 0, 1]), frame(&[1, 3, 0, 0, 0, 3]));
        port.send(&[a, b].concat())?;
        let both = port.recv(7 + 11, Duration::from_secs(1));
        let ok = both.len() == 18
            && both[..3] == [1, 4, 2]
            && crc16(&both[..5]).to_le_bytes() == both[5..7]
            && both[7..10] == [1, 3, 6]
            && crc16(&both[7..16]).to_le_bytes() == both[16..18];
        if !ok {
            return Err(format!("two requests in one write: got {both:02x?}"));
        }
        report.push_str("two requests in one write: both answered, in order\n");
        drop(port);
        // 4. A client that sends and never reads (answers pile up: 25 KB in 12 s) does not
        //    stop the controller.
        let s0 = Port::open(pty)?.samples("before a client that reads nothing")?;
        let t = Instant::now();
        let flood = Port::open(pty)?;
        let mut sent = 0;
        while t.elapsed() < Duration::from_secs(12) {
            flood.send(&frame(&[1, 4, 0, 0, 0, 18]))?;
            sent += 1;
            std::thread::sleep(Duration::from_millis(20));
        }
        drop(flood);
        std::thread::sleep(Duration::from_millis(100));
        let after = Port::open(pty)?;
        let s1 = after.samples("after a client that read nothing")?;
        let wall = t.elapsed().as_secs_f64();
        let rate = f64::from(s1.wrapping_sub(s0)) / (wall * 20.0) - 1.0;
        report.push_str(&format!(
            "a client sent {sent} reads in 12 s and read none: the loop ran on at {:+.2} % of wall time; {}\n",
            rate * 100.0,
            bridge.stats.summary()
        ));
        if rate.abs() > 0.02 {
            return Err(format!(
                "the controller stalled under a client that does not read:\n{report}"
            ));
        }
        drop(after);
        // 5. An answer nobody read does not reach the next client: a read of input 17 sent,
        //    the port closed unread (at once, or once the answer is in its queue); then a
        //    read of another shape gets its own answer.
        for i in 0..4 {
            let gone = Port::open(pty)?;
            gone.send(&frame(&[1, 4, 0, 17, 0, 1]))?;
            std::thread::sleep(Duration::from_millis(if i % 2 == 0 { 0 } else { 30 }));
            drop(gone);
            std::thread::sleep(Duration::from_millis(20));
            let next = Port::open(pty)?;
            // The stale answer (7 bytes) ahead of this one would spoil its header and CRC.
            next.inputs(0, 18, Duration::from_secs(1))?.ok_or(
                "after an unread answer, the next client's read got no valid answer of its own",
            )?;
        }
        report.push_str(
            "an answer left unread by a client that closed: not seen by the next client (4 of 4)\n",
        );
        Ok(())
    }
}

/// The two 20 s QEMU runs (NARMAX f32 and Q15) against the same loop replayed on the host.
fn replay(elf: &Path) -> Result {
    eprintln!("==> QEMU runs against the host replay (netduinoplus2, -icount shift=0,sleep=off)");
    const RUN_MS: u32 = 20_000;
    for narmax in ["f32", "q15"] {
        let args = [
            "mode=2".to_string(),
            format!("narmax={narmax}"),
            format!("run_ms={}", RUN_MS + 1),
        ];
        let out = qemu_log(elf, &args)?;
        let n = check_golden(&out, RUN_MS)?;
        println!(
            "QEMU run, NARMAX {narmax}: {n} log lines (white-box, measured, NARMAX, residuals) equal the host replay, bit for bit"
        );
    }
    Ok(())
}

fn test() -> Result {
    let start = Instant::now();
    run("rustfmt", cargo().args(["fmt", "--all", "--check"]))?;
    run(
        "clippy (host)",
        cargo().args(["clippy", "--all-targets", "--", "-D", "warnings"]),
    )?;
    for board in [Board::Qemu, Board::Nucleo] {
        run(
            &format!("clippy (board {})", board.name()),
            cargo()
                .args(["clippy", "-p", board.package(), "--target", TARGET])
                .args(board.config_args())
                .args(["--profile", "firmware", "--", "-D", "warnings"]),
        )?;
    }
    run(
        "clippy (mcu-bench, profile firmware)",
        cargo().args([
            "clippy",
            "-p",
            "mcu-bench",
            "--target",
            TARGET,
            "--profile",
            "firmware",
            "--",
            "-D",
            "warnings",
        ]),
    )?;
    run(
        "no_std crates build for the MCU (model-core, controller)",
        cargo().args([
            "build",
            "-p",
            "model-core",
            "-p",
            "controller",
            "--target",
            TARGET,
        ]),
    )?;
    run("host tests", cargo().args(["test"]))?;
    run(
        "doc (model-core, controller, warnings denied)",
        cargo()
            .args(["doc", "--no-deps", "-p", "model-core", "-p", "controller"])
            .env("RUSTDOCFLAGS", "-D warnings"),
    )?;
    eprintln!("==> bench: kernels in QEMU, image sizes, budgets");
    bench::run_bench(&bench::Options::default())?;
    let elf = firmware_elf(Board::Qemu);
    build_firmware(Board::Qemu)?;
    eprintln!("==> on-target checks in QEMU (boards/qemu selftest)");
    print!("{}", selftest()?);
    replay(&elf)?;
    eprintln!("==> end to end: QEMU in real time, SCADA on a pty, mbpoll as the client");
    print!("{}", e2e::run(&elf)?);
    eprintln!("==> SCADA flooded, the VFD on USART2 busy: in real time, then -icount shift=0");
    print!("{}", line::flood(&elf, FLOOD_S, false)?);
    print!("{}", line::flood(&elf, FLOOD_S, true)?);
    eprintln!(
        "all checks passed in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("qemu") => qemu(&args[1..]),
        Some("test") => test(),
        Some("bench") => match args.get(1).map(String::as_str) {
            None => bench::run_bench(&bench::Options::default()),
            Some("--save-baseline") => bench::run_bench(&bench::Options {
                save_baseline: true,
            }),
            Some(other) => Err(format!("unknown option '{other}'\n{BENCH_USAGE}")),
        },
        Some("flood") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", line::flood(&firmware_elf(Board::Qemu), FLOOD_S, false)?);
            print!("{}", line::flood(&firmware_elf(Board::Qemu), FLOOD_S, true)?);
            Ok(())
        }),
        Some("replay") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", selftest()?);
            replay(&firmware_elf(Board::Qemu))
        }),
        Some("e2e") => build_firmware(Board::Qemu).and_then(|()| {
            print!("{}", e2e::run(&firmware_elf(Board::Qemu))?);
            Ok(())
        }),
        _ => Err(format!("usage: cargo xtask <qemu|bench|test|replay|e2e|flood>\n  qemu   build the firmware and run it in QEMU on the virtual bench\n  bench  the kernels' instructions per call on the MCU, image sizes, checked against bench/baseline.json and the budgets\n  test   fmt, clippy, tests, the bench and its budgets, QEMU runs against the host, mbpoll end to end\n  replay only the on-target checks and the QEMU runs against the host replay\n  e2e    only the mbpoll end-to-end test\n  flood  only the margins under a SCADA flood with the VFD link busy\n{QEMU_USAGE}\n{BENCH_USAGE}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
