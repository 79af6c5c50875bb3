//! QEMU (`qemu-system-arm -M netduinoplus2`) running the images: deterministic runs to the
//! end (`-icount`, for the bench, the on-target checks and the replay), and real-time runs
//! with the SCADA port on a pseudo-terminal (the end-to-end test, the flood, `cargo xtask
//! qemu --scada-pty`).

use crate::defmt_log;
use crate::util::Result;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Longest a QEMU smoke run may take, s.
const QEMU_TIMEOUT_S: u32 = 120;

/// QEMU's command line for the firmware, with semihosting arguments `args`.
pub fn qemu_command(elf: &Path, args: &[String]) -> Command {
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
pub fn qemu_output(elf: &Path, args: &[String]) -> Result<String> {
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
pub fn qemu_log(elf: &Path, args: &[String]) -> Result<String> {
    let (ok, text) = qemu_log_status(elf, args)?;
    if ok {
        Ok(text)
    } else {
        let name = elf.file_name().unwrap_or_default().to_string_lossy();
        Err(format!("{name} in QEMU exited non-zero:\n{text}"))
    }
}

/// As [`qemu_log`], with whether the image exited 0.
pub fn qemu_log_status(elf: &Path, args: &[String]) -> Result<(bool, String)> {
    let io = [
        "-display", "none", "-monitor", "none", "-serial", "null", "-serial", "null",
    ];
    let (ok, out) = qemu_run(elf, args, &io)?;
    Ok((ok, defmt_log::decode(elf, &out)?))
}

/// QEMU, killed when dropped.
pub struct Qemu(pub Child);
impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// What QEMU prints on its standard output before the firmware's first defmt frame:
/// `char device redirected to /dev/pts/N (label serialK)`, one line per pty.
const QEMU_LINE: &[u8] = b"char device redirected to ";

/// QEMU's standard output in real time, split: its own text lines first (the ptys' names),
/// then the firmware's defmt frames, as they arrive.
#[derive(Debug, Default)]
pub struct StdoutSplit {
    /// Bytes not yet told apart (a line not yet complete, or too short to tell).
    pending: Vec<u8>,
    /// Whether the frames have begun (everything from then on is frames).
    frames: bool,
}

impl StdoutSplit {
    /// Takes the next `bytes` read; returns QEMU's text lines they complete (trailing
    /// whitespace removed), then the bytes that are defmt frames.
    pub fn feed(&mut self, bytes: &[u8]) -> (Vec<String>, Vec<u8>) {
        if self.frames {
            return (vec![], bytes.to_vec());
        }
        self.pending.extend_from_slice(bytes);
        let mut lines = vec![];
        loop {
            if self.pending.starts_with(QEMU_LINE) {
                let Some(end) = self.pending.iter().position(|&b| b == b'\n') else {
                    break;
                };
                let line = String::from_utf8_lossy(&self.pending[..end]).into_owned();
                lines.push(line.trim_end().to_string());
                self.pending.drain(..=end);
            } else if QEMU_LINE.starts_with(&self.pending) {
                break; // too short to tell yet
            } else {
                self.frames = true;
                return (lines, std::mem::take(&mut self.pending));
            }
        }
        (lines, vec![])
    }
}

/// The serial port a pty QEMU announces is for.
#[derive(Debug, PartialEq)]
pub enum Serial {
    /// USART1 (`serial0`): the SCADA slave.
    Scada,
    /// USART2 (`serial1`): the VFD master.
    Usart2,
}

/// The pty a line of QEMU's announces (`char device redirected to /dev/pts/N (label
/// serial0)`): the port and the path; `None` for any other line.
pub fn announced_pty(line: &str) -> Option<(Serial, Option<String>)> {
    let rest = line.strip_prefix("char device redirected to ")?;
    let path = rest.split_whitespace().next().map(str::to_string);
    Some(if rest.contains("serial1") {
        (Serial::Usart2, path)
    } else {
        (Serial::Scada, path)
    })
}

/// Starts QEMU's `cmd` running the image `elf`: the process (killed when dropped) and its
/// output lines, as they come: its own (stderr, and the ptys it names on stdout) and the
/// firmware's defmt log decoded (also echoed to the terminal if `echo`).
pub fn spawn_with_lines(
    elf: &Path,
    mut cmd: Command,
    echo: bool,
) -> Result<(Qemu, std::sync::mpsc::Receiver<String>)> {
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
        let mut stdout = stdout;
        let mut split = StdoutSplit::default();
        let mut buf = [0u8; 4096];
        while let Ok(n) = std::io::Read::read(&mut stdout, &mut buf) {
            if n == 0 {
                break;
            }
            let (mut lines, frames) = split.feed(&buf[..n]);
            if !frames.is_empty() {
                lines.extend(decoder.feed(&frames).unwrap_or_default());
            }
            for line in lines {
                if echo {
                    println!("{line}");
                }
                let _ = tx2.send(line);
            }
        }
    });
    Ok((qemu, rx))
}

/// QEMU with its SCADA port on a pseudo-terminal, started: the process (killed when
/// dropped), the [`bridge`](crate::bridge) that offers clients the port as a line (its
/// `path`), and QEMU's output lines (also echoed to the terminal if `echo`).
pub fn start_pty(
    elf: &Path,
    cmd: Command,
    echo: bool,
) -> Result<(
    Qemu,
    crate::bridge::Bridge,
    std::sync::mpsc::Receiver<String>,
    Option<String>,
)> {
    let (qemu, rx) = spawn_with_lines(elf, cmd, echo)?;
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut pty, mut second) = (None, None);
    let mut started = false;
    while pty.is_none() || !started {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = rx
            .recv_timeout(left)
            .map_err(|_| "QEMU did not announce its pty and the firmware's start")?;
        match announced_pty(&line) {
            Some((Serial::Usart2, path)) => second = path,
            Some((Serial::Scada, path)) => pty = path,
            None => {}
        }
        started |= line.starts_with("firmware:");
    }
    let pty = pty.ok_or("no pty")?;
    let bridge = crate::bridge::start(&pty)?;
    Ok((qemu, bridge, rx, second))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_line() {
        let cmd = qemu_command(
            Path::new("/t/firmware/pump-qemu"),
            &["mode=1".into(), "setpoint=5000".into()],
        );
        assert_eq!(cmd.get_program(), "qemu-system-arm");
        let args: Vec<_> = cmd.get_args().map(|a| a.to_string_lossy()).collect();
        assert_eq!(
            args,
            [
                "-cpu",
                "cortex-m4",
                "-machine",
                "netduinoplus2",
                "-semihosting-config",
                "enable=on,target=native,arg=pump-qemu,arg=mode=1,arg=setpoint=5000",
                "-kernel",
                "/t/firmware/pump-qemu",
            ]
        );
    }

    #[test]
    fn stdout_split() {
        let mut s = StdoutSplit::default();
        // Nothing to tell yet: a prefix of QEMU's line, then the rest of it in pieces.
        assert_eq!(s.feed(b"char dev"), (vec![], vec![]));
        assert_eq!(
            s.feed(b"ice redirected to /dev/pts/7 (label"),
            (vec![], vec![])
        );
        let (lines, frames) =
            s.feed(b" serial0)\r\nchar device redirected to /dev/pts/8 (label serial1)\n\x01\x02");
        assert_eq!(
            lines,
            [
                "char device redirected to /dev/pts/7 (label serial0)",
                "char device redirected to /dev/pts/8 (label serial1)"
            ]
        );
        assert_eq!(frames, [1, 2]);
        // Frames from then on, whatever they hold.
        assert_eq!(
            s.feed(b"char device redirected to x\n"),
            (vec![], b"char device redirected to x\n".to_vec())
        );
        // No QEMU line at all: the first byte is a frame's.
        let mut s = StdoutSplit::default();
        assert_eq!(s.feed(b"\x03ab"), (vec![], b"\x03ab".to_vec()));
        assert_eq!(s.feed(b""), (vec![], vec![]));
    }

    #[test]
    fn pty_announcements() {
        assert_eq!(
            announced_pty("char device redirected to /dev/pts/3 (label serial0)"),
            Some((Serial::Scada, Some("/dev/pts/3".into())))
        );
        assert_eq!(
            announced_pty("char device redirected to /dev/pts/4 (label serial1)"),
            Some((Serial::Usart2, Some("/dev/pts/4".into())))
        );
        assert_eq!(announced_pty("firmware: seed=1 mode=0"), None);
    }
}
