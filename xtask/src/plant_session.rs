//! The plant protocol ([`controller::plant`]) from xtask's side:
//!
//! - `cargo xtask plant-stdio`: the controller's side on standard input and output, the
//!   host's session built as the QEMU board builds it ([`board_common::plant_session`]): a
//!   plant such as `examples/plant.py` runs it as its child;
//! - `cargo xtask plant-check`: the same scenario plant ([`scenario`], the virtual bench as
//!   an external plant) run against the host's session and against the QEMU board in plant
//!   mode (`pump-qemu-plant` on a pseudo-terminal), every reply compared, bit for bit; then
//!   `examples/plant.py` against both.

use crate::board::ensure_flip_link;
use crate::qemu::{announced_pty, qemu_command, spawn_with_lines, Qemu, Serial};
use crate::util::{cargo, root, run, target_dir, Result, TARGET};
use controller::plant::{PlantFrame, PlantSession, Reply, Request};
use controller::vfd::VfdReadings;
use controller::virtual_bench::{VirtualBench, VirtualBenchConfig};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// The plant-mode image's binary (boards/qemu, feature `plant`).
pub const PLANT_BINARY: &str = "pump-qemu-plant";
/// The Python example plant, from the workspace root.
pub const PLANT_PY: &str = "examples/plant.py";
/// Longest wait for one reply (QEMU's pty is polled once a second until a client opens it).
const REPLY_TIMEOUT: Duration = Duration::from_secs(10);

/// The plant-mode image.
pub fn plant_elf() -> PathBuf {
    target_dir()
        .join(TARGET)
        .join("firmware")
        .join(PLANT_BINARY)
}

/// Builds the plant-mode image (profile `firmware`, feature `plant`) at [`plant_elf`].
pub fn build_plant_firmware() -> Result {
    ensure_flip_link()?;
    run(
        "firmware build for qemu, plant mode (feature plant)",
        cargo()
            .args(["build", "-p", "board-qemu", "--features", "plant"])
            .args([
                "--bin",
                PLANT_BINARY,
                "--profile",
                "firmware",
                "--target",
                TARGET,
            ])
            .env("DEFMT_LOG", "info"),
    )
}

/// `cargo xtask plant-stdio`: the controller's side of the protocol on standard input and
/// output, until `Q` or the end of the input.
pub fn plant_stdio() -> Result {
    board_common::serve_plant(
        std::io::stdin().lock(),
        &mut std::io::stdout().lock(),
        &[],
        |_, _| {},
    )
}

/// One request and its reply line (without the `\n`), whatever carries them.
pub trait Endpoint {
    /// Sends `request` (one line, no `\n`) and returns the reply line.
    fn exchange(&mut self, request: &str) -> Result<String>;

    /// Ends the session: `Q`, answered `B`.
    fn quit(&mut self) -> Result<()> {
        match self.exchange("Q")?.as_str() {
            "B" => Ok(()),
            other => Err(format!("Q answered '{other}', not B")),
        }
    }
}

/// The host's session in this process: what `cargo xtask plant-stdio` (and `pumpbench
/// control --plant-stdio`) serve.
pub struct HostEndpoint {
    core: board_common::Controller,
    session: PlantSession,
}

impl HostEndpoint {
    /// A new session, as the board starts.
    pub fn new() -> Result<Self> {
        let (core, session) =
            board_common::plant_session().map_err(|e| format!("plant session: {e}"))?;
        Ok(Self { core, session })
    }
}

impl Endpoint for HostEndpoint {
    fn exchange(&mut self, request: &str) -> Result<String> {
        let mut reply = String::new();
        for &b in request.as_bytes().iter().chain(b"\n") {
            self.session
                .feed(b, &mut self.core, &mut reply, |_, _| {})
                .map_err(|_| "reply not written")?;
        }
        reply
            .strip_suffix('\n')
            .map(str::to_string)
            .ok_or_else(|| format!("no reply line to '{request}': {reply:?}"))
    }
}

/// A serial device (a pseudo-terminal), raw, one line at a time.
pub struct SerialEndpoint {
    file: std::fs::File,
    pending: Vec<u8>,
}

impl SerialEndpoint {
    /// Opens `path` read-write and makes it raw (no echo, no line editing, no CR/LF
    /// translation).
    pub fn open(path: &str) -> Result<Self> {
        use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| format!("{path}: {e}"))?;
        let mut t = tcgetattr(&file).map_err(|e| format!("{path}: tcgetattr: {e}"))?;
        cfmakeraw(&mut t);
        tcsetattr(&file, SetArg::TCSANOW, &t).map_err(|e| format!("{path}: tcsetattr: {e}"))?;
        Ok(Self {
            file,
            pending: vec![],
        })
    }
}

impl Endpoint for SerialEndpoint {
    /// `Q`: `B`, or the line closed first. The QEMU board answers `B` and exits at once
    /// (status 0, which the caller checks); QEMU closes the pseudo-terminal on exit, and the
    /// kernel may drop the `B` still in it.
    fn quit(&mut self) -> Result<()> {
        match self.exchange("Q") {
            Ok(b) if b == "B" => Ok(()),
            Ok(other) => Err(format!("Q answered '{other}', not B")),
            Err(e) if e.starts_with("the line closed") => Ok(()),
            Err(e) => Err(e),
        }
    }

    fn exchange(&mut self, request: &str) -> Result<String> {
        use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
        use std::os::fd::AsFd;
        self.file
            .write_all(format!("{request}\n").as_bytes())
            .map_err(|e| format!("plant line: {e}"))?;
        let deadline = Instant::now() + REPLY_TIMEOUT;
        loop {
            if let Some(end) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=end).collect();
                return Ok(String::from_utf8_lossy(&line[..end]).into_owned());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let ms = u16::try_from(left.as_millis()).unwrap_or(u16::MAX);
            let mut fds = [PollFd::new(self.file.as_fd(), PollFlags::POLLIN)];
            let n = poll(&mut fds, PollTimeout::from(ms)).map_err(|e| format!("poll: {e}"))?;
            if n == 0 {
                return Err(format!("no reply to '{request}' within {REPLY_TIMEOUT:?}"));
            }
            let mut buf = [0u8; 256];
            let n = self
                .file
                .read(&mut buf)
                .map_err(|e| format!("plant line: {e}"))?;
            if n == 0 {
                return Err(format!("the line closed before the reply to '{request}'"));
            }
            self.pending.extend_from_slice(&buf[..n]);
        }
    }
}

/// Frame period, ms (the protocol's: the board's answer to `H 1` is checked against it).
const PERIOD_MS: u32 = controller::plant::FRAME_PERIOD_MS;
/// The scenario's length, ms of plant time.
pub const SCENARIO_MS: u32 = 10_000;

/// The scenario plant: the virtual bench (`controller::virtual_bench`, seed 11) as an
/// external plant, through `endpoint`: hello; mode 3 (pressure) at 3 mca; the valve ×1.3
/// at 4 s; a malformed line at 5 s; the flow transmitter at 2 mA (a broken wire) from 6 to
/// 7 s; the VFD link cut from 7.5 to 8 s; mode 4 (flow) at 10 l/s from 8.5 s; Q15 NARMAX
/// from 9 s; `Q` at 10 s. Each frame: the bench's transmitter codes and its drive's speed
/// and delivered torque; the reply's torque drives the bench for the next period. Returns
/// every reply line, in order, and the bench's pressure at 4 s (mca).
pub fn scenario(endpoint: &mut impl Endpoint) -> Result<(Vec<String>, f32)> {
    let mut x = Exchanges {
        endpoint,
        replies: vec![],
    };
    let hello = x.send(Request::Hello { version: 1 })?;
    if hello
        != (Reply::Hello {
            version: 1,
            period_ms: PERIOD_MS,
        })
    {
        return Err(format!("hello answered {hello:?}"));
    }
    let write = |register, value| Request::Write { register, value };
    let mut bench = VirtualBench::new(VirtualBenchConfig::default_offsets(11))
        .map_err(|e| format!("virtual bench: {e:?}"))?;
    let mut pressure_at_4s = f32::NAN;
    for k in 0..SCENARIO_MS / PERIOD_MS {
        let t = k * PERIOD_MS;
        let writes: &[Request] = match t {
            0 => &[write(8, 3000), write(1, 3)],
            8500 => &[write(9, 1000), write(1, 4)],
            9000 => &[write(2, 1)],
            _ => &[],
        };
        for &w in writes {
            if x.send(w)? != Reply::Written {
                return Err(format!("{w} refused"));
            }
        }
        if t == 4000 {
            pressure_at_4s = bench.signals().pressure_mca;
            bench
                .set_valve_factor(1.3)
                .map_err(|e| format!("valve: {e:?}"))?;
        }
        if t == 5000 {
            let r = x.raw("S 1 2 nan 4")?;
            if r != "E finite" {
                return Err(format!("a NaN speed answered '{r}'"));
            }
        }
        bench.force_flow_ma = (6000..7000).contains(&t).then_some(2.0);
        let s = bench.signals();
        let drive = (!(7500..8000).contains(&t)).then_some(VfdReadings {
            speed_rpm: s.speed_rpm,
            torque_pct: bench.delivered_torque_pct(),
            status: 0,
        });
        let frame = PlantFrame {
            pressure_code: bench.pressure_code(),
            flow_code: bench.flow_code(),
            drive,
        };
        let torque = match x.send(Request::Frame(frame))? {
            Reply::Torque { reply, .. } => reply.torque_ref_pct,
            other => return Err(format!("frame {frame:?} answered {other:?}")),
        };
        for _ in 0..PERIOD_MS {
            bench
                .step_1ms(torque)
                .map_err(|e| format!("bench: {e:?}"))?;
        }
    }
    // The end is not among the replies compared: the QEMU board exits at `Q` and its `B`
    // may be lost with the line (see `SerialEndpoint::quit`).
    x.endpoint.quit()?;
    Ok((x.replies, pressure_at_4s))
}

/// A plant's exchanges over an endpoint, every reply line kept.
struct Exchanges<'a, E> {
    endpoint: &'a mut E,
    replies: Vec<String>,
}

impl<E: Endpoint> Exchanges<'_, E> {
    /// `line` sent as it is; its reply, kept.
    fn raw(&mut self, line: &str) -> Result<String> {
        let reply = self.endpoint.exchange(line)?;
        self.replies.push(reply.clone());
        Ok(reply)
    }

    /// `request` sent; its reply, kept and parsed.
    fn send(&mut self, request: Request) -> Result<Reply> {
        let text = self.raw(&request.to_string())?;
        Reply::parse(text.as_bytes())
            .map_err(|e| format!("bad reply '{text}' to '{request}': {e:?}"))
    }
}

/// The pseudo-terminals QEMU made for a plant-mode run.
#[derive(Debug, Default)]
pub struct PlantPtys {
    /// USART2's, the plant line (with `plant` = `pty`).
    pub plant: Option<String>,
    /// USART1's, the SCADA slave (with `scada` = `pty`).
    pub scada: Option<String>,
}

/// QEMU running the plant-mode image, USART1 (SCADA) on the QEMU serial back-end `scada`
/// (`null`, `pty`) and USART2 (the plant line) on `plant` (`pty`: a pseudo-terminal of
/// QEMU's; else a serial device's path), once the firmware has started: the process (killed
/// when dropped), the ptys QEMU made, and QEMU's output lines (its own and the firmware's
/// decoded log; also printed if `echo`).
pub fn start_plant_qemu(
    elf: &Path,
    scada: &str,
    plant: &str,
    echo: bool,
) -> Result<(Qemu, PlantPtys, Receiver<String>)> {
    let mut cmd = qemu_command(elf, &[]);
    cmd.args(["-display", "none", "-monitor", "none"])
        .args(["-serial", scada, "-serial"]);
    if plant == "pty" {
        cmd.arg("pty");
    } else {
        // QEMU takes a host serial device by its /dev path: resolve links (socat's).
        cmd.arg(std::fs::canonicalize(plant).map_err(|e| format!("plant line {plant}: {e}"))?);
    }
    let (qemu, rx) = spawn_with_lines(elf, cmd, echo)?;
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut ptys, mut started) = (PlantPtys::default(), false);
    while (plant == "pty" && ptys.plant.is_none())
        || (scada == "pty" && ptys.scada.is_none())
        || !started
    {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = rx
            .recv_timeout(left)
            .map_err(|_| "QEMU did not announce its ptys and the firmware's start")?;
        match announced_pty(&line) {
            Some((Serial::Usart2, path)) => ptys.plant = path,
            Some((Serial::Scada, path)) => ptys.scada = path,
            None => {}
        }
        started |= line.starts_with("firmware:");
    }
    Ok((qemu, ptys, rx))
}

/// Waits for QEMU to end (the firmware exits after `Q`); its `done:` line, or an error
/// with what it logged.
pub fn qemu_done(mut qemu: Qemu, log: &Receiver<String>) -> Result<String> {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut lines = vec![];
    loop {
        while let Ok(line) = log.try_recv() {
            lines.push(line);
        }
        if let Some(status) = qemu.0.try_wait().map_err(|e| format!("qemu: {e}"))? {
            // The last lines may still be on their way.
            std::thread::sleep(Duration::from_millis(100));
            lines.extend(log.try_iter());
            let done = lines.iter().find(|l| l.starts_with("done:")).cloned();
            return match (status.success(), done) {
                (true, Some(done)) => Ok(done),
                _ => Err(format!("QEMU ended {status}:\n{}", lines.join("\n"))),
            };
        }
        if Instant::now() > deadline {
            return Err(format!("QEMU did not end after Q:\n{}", lines.join("\n")));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Runs `examples/plant.py` with `args`; its output, or an error with it.
fn python_plant(args: &[&str]) -> Result<String> {
    let out = Command::new("python3")
        .arg(root().join(PLANT_PY))
        .args(args)
        .current_dir(root())
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot start python3: {e}"))?;
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    if out.status.success() {
        Ok(text.trim_end().to_string())
    } else {
        Err(format!(
            "{PLANT_PY} {}: {}:\n{text}",
            args.join(" "),
            out.status
        ))
    }
}

/// `cargo xtask plant-check`: the scenario against the host's session and against the QEMU
/// board, every reply identical; then `examples/plant.py` against `cargo xtask plant-stdio`
/// (this executable) and against the board.
pub fn plant_check() -> Result {
    let start = Instant::now();
    build_plant_firmware()?;
    let elf = plant_elf();
    eprintln!("==> plant protocol: the scenario plant against the host and the QEMU board");
    let (host, host_p) = scenario(&mut HostEndpoint::new()?)?;
    let t0 = Instant::now();
    let (qemu, pty, log) = start_plant_qemu(&elf, "null", "pty", false)?;
    let pty = pty.plant.ok_or("no plant pty")?;
    let (board, board_p) = scenario(&mut SerialEndpoint::open(&pty)?)?;
    let done = qemu_done(qemu, &log)?;
    let board_s = t0.elapsed().as_secs_f64();
    if let Some(k) = (0..host.len().max(board.len())).find(|&k| host.get(k) != board.get(k)) {
        return Err(format!(
            "reply {k} differs: host '{}', QEMU '{}'",
            host.get(k).map_or("(none)", String::as_str),
            board.get(k).map_or("(none)", String::as_str)
        ));
    }
    let frames = host.iter().filter(|l| l.starts_with("T ")).count();
    eprintln!(
        "    {} replies ({frames} frames, {} s of plant time) identical, bit for bit; bench pressure at 4 s: {host_p} mca (host), {board_p} mca (QEMU); QEMU session {board_s:.1} s; {done}",
        host.len(),
        SCENARIO_MS / 1000
    );
    eprintln!("==> {PLANT_PY} against cargo xtask plant-stdio and against the QEMU board");
    // Through cargo, not this executable's path: `cargo xtask test` rebuilds xtask (clippy,
    // the tests) while it runs, and the running binary's path is then gone.
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let on_host = python_plant(&[
        "--",
        &cargo,
        "run",
        "-q",
        "-p",
        "xtask",
        "--",
        "plant-stdio",
    ])?;
    let (qemu, pty, log) = start_plant_qemu(&elf, "null", "pty", false)?;
    let on_board = python_plant(&[&pty.plant.ok_or("no plant pty")?])?;
    qemu_done(qemu, &log)?;
    eprintln!("    host: {on_host}\n    QEMU: {on_board}");
    if on_host != on_board {
        return Err("the Python plant ended differently on the host and the board".into());
    }
    eprintln!("    plant check: {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scenario on the host alone: it runs to its end, closes the pressure loop, and
    /// two runs answer the same (the QEMU side is `cargo xtask plant-check`).
    #[test]
    fn the_scenario_runs_on_the_host() {
        let (a, p) = scenario(&mut HostEndpoint::new().unwrap()).unwrap();
        let (b, _) = scenario(&mut HostEndpoint::new().unwrap()).unwrap();
        assert_eq!(a, b);
        assert_eq!(a[..3], ["H 1 5", "K", "K"]);
        // The host's session answers the end (`HostEndpoint::quit` checks its `B`); it is
        // not among the replies compared.
        assert!(a.last().is_some_and(|l| l.starts_with("T ")));
        assert!(a.contains(&"E finite".to_string()));
        assert_eq!(
            a.iter().filter(|l| l.starts_with("T ")).count() as u32,
            SCENARIO_MS / PERIOD_MS
        );
        assert!((p - 3.0).abs() < 0.15, "pressure at 4 s: {p} mca");
    }
}
