//! Project tasks, run as `cargo xtask <task>`:
//!
//! - `qemu`: build the firmware (release, thumbv7em-none-eabihf) and run it in QEMU
//!   `netduinoplus2` with deterministic instruction counting (`-icount shift=0`).
//! - `test`: everything CI checks: rustfmt, clippy `-D warnings` (host and firmware), the
//!   no_std crates built for the MCU, the host tests, the firmware build and its size, and the
//!   QEMU smoke run, whose samples must equal bit for bit model-core replayed on the host.
//!
//! Needs `qemu-system-arm` on the PATH for the QEMU steps (Debian: `qemu-system-arm`).

use model_core::excitation::{PulseTrain, SteppedPulses};
use model_core::narmax::fixed::NarmaxQ;
use model_core::{Scheme, WhiteBox};

/// The firmware's NARMAX models, the very files it compiles in.
#[path = "../../firmware/src/models/flow.rs"]
mod flow_model;
#[path = "../../firmware/src/models/pressure.rs"]
mod pressure_model;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::Instant;

const TARGET: &str = "thumbv7em-none-eabihf";
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

fn firmware_elf() -> PathBuf {
    let target_dir = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"));
    target_dir.join(TARGET).join("firmware").join("firmware")
}

fn build_firmware() -> Result {
    run(
        "firmware build (profile firmware: opt-level s, LTO)",
        cargo().args([
            "build",
            "-p",
            "firmware",
            "--profile",
            "firmware",
            "--target",
            TARGET,
        ]),
    )
}

/// Runs the firmware in QEMU; returns its standard output.
fn qemu_output(elf: &Path) -> Result<String> {
    let start = Instant::now();
    let out = Command::new("timeout")
        .arg(QEMU_TIMEOUT_S.to_string())
        .args([
            "qemu-system-arm",
            "-cpu",
            "cortex-m4",
            "-machine",
            "netduinoplus2",
        ])
        .args([
            "-nographic",
            "-semihosting-config",
            "enable=on,target=native",
        ])
        .args(["-icount", "shift=0", "-kernel"])
        .arg(elf)
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| {
            format!("cannot start qemu-system-arm (apt-get install qemu-system-arm): {e}")
        })?;
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!(
        "    qemu: {:.1} s, {}",
        start.elapsed().as_secs_f64(),
        out.status
    );
    if !out.status.success() {
        return Err(format!(
            "firmware in QEMU exited with {}:\n{text}",
            out.status
        ));
    }
    Ok(text)
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

/// Checks the firmware's samples against model-core's f32 bench run on the host with the
/// excitation the firmware announces in its first line.
fn check_golden(output: &str) -> Result<usize> {
    let header = output
        .lines()
        .find(|l| l.starts_with("firmware:"))
        .ok_or("no 'firmware:' header line")?;
    let step_ms: u32 = num(header, "step_ms")?;
    let seed: u64 = num(header, "seed")?;
    let duration_ms: u32 = num(header, "duration_ms")?;
    let mut samples = std::collections::BTreeMap::new();
    let mut narmax_lines = std::collections::BTreeMap::new();
    for line in output.lines() {
        let into = if line.starts_with("sample ") {
            &mut samples
        } else if line.starts_with("narmax ") {
            &mut narmax_lines
        } else {
            continue;
        };
        let t: u32 = num(line, "t_ms")?;
        into.insert(t, field(line, "bits")?.to_string());
    }
    if !output.lines().any(|l| l == "done") {
        return Err("the firmware did not print 'done'".into());
    }
    let bench = WhiteBox::<f32>::paper();
    let e = |e: model_core::narmax::NarmaxError| e.to_string();
    let (p_f32, f_f32) = (
        pressure_model::model().map_err(e)?,
        flow_model::model().map_err(e)?,
    );
    let (p_q15, f_q15) = (
        NarmaxQ::quantize(&p_f32).map_err(e)?,
        NarmaxQ::quantize(&f_f32).map_err(e)?,
    );
    let p_ms = (pressure_model::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;
    let f_ms = (flow_model::SAMPLE_PERIOD_S * 1000.0 + 0.5) as u32;
    let mut schedule = SteppedPulses::new(PulseTrain::paper(seed), step_ms).peekable();
    let u0 = schedule.peek().map_or(0.0, |&(_, u)| u as f32);
    let st = &mut bench.steady_state(u0).map_err(|e| e.to_string())?;
    let s0 = bench.signals(st);
    let p_st = &mut p_f32.state_at(u0, s0.pressure_mca);
    let pq_st = &mut p_q15.state_at(u0, s0.pressure_mca);
    let f_st = &mut f_f32.state_at(u0, s0.flow_lps);
    let fq_st = &mut f_q15.state_at(u0, s0.flow_lps);
    let (mut p, mut pq, mut f, mut fq) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut checked = 0;
    for (t_ms, torque) in schedule {
        if t_ms > duration_ms {
            break;
        }
        let u = torque as f32;
        if t_ms % p_ms == 0 {
            p = p_f32.simulate_step(p_st, u).y;
            pq = p_q15.simulate_step(pq_st, u).y;
        }
        if t_ms % f_ms == 0 {
            f = f_f32.simulate_step(f_st, u).y;
            fq = f_q15.simulate_step(fq_st, u).y;
        }
        if let Some(bits) = narmax_lines.get(&t_ms) {
            let host = format!(
                "{:08x},{:08x},{:08x},{:08x}",
                p.to_bits(),
                pq.to_bits(),
                f.to_bits(),
                fq.to_bits()
            );
            if *bits != host {
                return Err(format!(
                    "t_ms={t_ms}: firmware NARMAX bits {bits}, host bits {host} (pressure {p} {pq}, flow {f} {fq})"
                ));
            }
            checked += 1;
        }
        if let Some(bits) = samples.get(&t_ms) {
            let s = bench.signals(st);
            let host = format!(
                "{:08x},{:08x},{:08x}",
                s.speed_rpm.to_bits(),
                s.flow_lps.to_bits(),
                s.pressure_mca.to_bits()
            );
            if *bits != host {
                return Err(format!(
                    "t_ms={t_ms}: firmware bits {bits}, host f32 bits {host} (speed {} flow {} pressure {})",
                    s.speed_rpm, s.flow_lps, s.pressure_mca
                ));
            }
            checked += 1;
        }
        bench
            .step(st, u, step_ms as f32 * 1e-3, Scheme::Rk4)
            .map_err(|e| e.to_string())?;
    }
    let total = samples.len() + narmax_lines.len();
    if checked != total || checked == 0 {
        return Err(format!("checked {checked} of {total} lines"));
    }
    Ok(checked)
}

fn llvm_size() -> Option<PathBuf> {
    let out = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .ok()?;
    let sysroot = String::from_utf8(out.stdout).ok()?;
    let host = std::env::var("HOST_TRIPLE").unwrap_or_else(|_| "x86_64-unknown-linux-gnu".into());
    let p = Path::new(sysroot.trim())
        .join("lib/rustlib")
        .join(host)
        .join("bin/llvm-size");
    p.exists().then_some(p)
}

fn print_size(elf: &Path) -> Result {
    match llvm_size() {
        Some(tool) => run("firmware size (llvm-size)", Command::new(tool).arg(elf)),
        None => {
            eprintln!("    llvm-size not found (rustup component add llvm-tools); skipped");
            Ok(())
        }
    }
}

fn qemu() -> Result {
    build_firmware()?;
    let out = qemu_output(&firmware_elf())?;
    print!("{out}");
    let ticks: f64 = out
        .lines()
        .find(|l| l.starts_with("timing "))
        .map(|l| num(l, "systick_ticks_per_step"))
        .transpose()?
        .unwrap_or(0.0);
    // -icount shift=0: 1 instruction = 1 ns; SysTick counts at 168 MHz.
    println!(
        "≈ {:.0} instructions per RK4 step (SysTick ticks / 0.168 under -icount shift=0)",
        ticks / 0.168
    );
    if let Some(l) = out.lines().find(|l| l.starts_with("timing narmax")) {
        let mut parts = vec![];
        for key in ["pressure_f32", "pressure_q15", "flow_f32", "flow_q15"] {
            let t: f64 = num(l, key)?;
            parts.push(format!("{key} ≈ {:.0}", t / 0.168));
        }
        println!("instructions per NARMAX step: {}", parts.join(", "));
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
    run(
        "clippy (firmware)",
        cargo().args([
            "clippy", "-p", "firmware", "--target", TARGET, "--", "-D", "warnings",
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
        "doc (model-core, warnings denied)",
        cargo()
            .args(["doc", "--no-deps", "-p", "model-core"])
            .env("RUSTDOCFLAGS", "-D warnings"),
    )?;
    build_firmware()?;
    let elf = firmware_elf();
    print_size(&elf)?;
    eprintln!("==> QEMU smoke run (netduinoplus2, -icount shift=0)");
    let out = qemu_output(&elf)?;
    let n = check_golden(&out)?;
    println!(
        "QEMU smoke run: {n} lines (white-box, NARMAX f32 and fixed point) equal model-core on the host, bit for bit"
    );
    eprintln!(
        "all checks passed in {:.0} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn main() -> ExitCode {
    let task = std::env::args().nth(1);
    let result = match task.as_deref() {
        Some("qemu") => qemu(),
        Some("test") => test(),
        _ => Err("usage: cargo xtask <qemu|test>\n  qemu  build the firmware and run it in QEMU\n  test  fmt, clippy, tests, firmware build and size, QEMU smoke run".into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
