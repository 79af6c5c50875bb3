//! `cargo xtask qemu`: the firmware built for QEMU and run on the virtual bench, either
//! deterministic for a number of seconds of loop time, or in real time with the SCADA slave on
//! a pseudo-terminal and/or the VFD master on a host serial device.

use crate::board::{build_firmware, firmware_elf, Board};
use crate::plant_session::{build_plant_firmware, plant_elf, start_plant_qemu};
use crate::qemu::{qemu_command, qemu_log, start_pty};
use crate::util::Result;

/// `cargo xtask qemu`'s usage.
pub const QEMU_USAGE: &str = "usage: cargo xtask qemu [--scada-pty] [--vfd PTY | --plant PTY|pty] [--seconds N] [--mode 0|1|2] [--setpoint 0..10000] [--seed N] [--narmax f32|q15] [--adapt] [--head PML] [--torque PML]
  (no --scada-pty)  run the virtual bench for --seconds (default 20) of loop time, mode 2 (the
                    paper's excitation) unless --mode says otherwise, deterministic and faster
                    than real time (-icount); the kernels' cost is `cargo xtask bench`
  --scada-pty       real time, until stopped (Ctrl-C): the SCADA slave (unit 1, 19200 8N1 RTU)
                    on a pseudo-terminal; QEMU prints its path. Starts stopped (mode 0).
  --adapt           the NARMAX models follow the load from start-up (holding register 19 at 1)
  --head, --torque  the virtual bench's pump-head and load-torque curves, per mille of the
                    paper's (800..1200; defaults 1000 and 1020), e.g. the bench a record was
                    made on (cargo xtask record)
  --vfd PTY         the VFD master on USART2 to that serial device (e.g. pumpbench vfd-sim's)
  --plant PTY|pty   plant mode (the pump-qemu-plant image): no virtual bench and no VFD link,
                    an external plant closes the loop in lockstep over USART2, speaking the
                    plant protocol (controller::plant), on that serial device, or with `pty`
                    on a pseudo-terminal QEMU makes and names (python3 examples/plant.py
                    /dev/pts/N); ends when the plant sends Q. Takes no --mode, --setpoint,
                    --seed, --narmax, --adapt, --head, --torque, --seconds: the plant writes the
                    registers";

/// Options of `cargo xtask qemu`.
#[derive(Debug, PartialEq)]
struct QemuOptions {
    /// `--scada-pty`: real time, the SCADA port on a pseudo-terminal.
    scada_pty: bool,
    /// `--vfd PTY`: real time, USART2 (the VFD master) on that serial device.
    vfd: Option<String>,
    /// `--plant PTY`: plant mode, USART2 (the plant line) on that serial device, or on a
    /// pseudo-terminal of QEMU's (`pty`).
    plant: Option<String>,
    /// `--seconds N`: loop time of a deterministic run, s (default 20).
    seconds: u32,
    /// The firmware's semihosting arguments from `--mode`, `--setpoint`, `--seed`,
    /// `--narmax`, in the order given.
    firmware_args: Vec<String>,
}

impl QemuOptions {
    /// Whether QEMU runs in real time (a pty or a serial device is attached).
    fn real_time(&self) -> bool {
        self.scada_pty || self.vfd.is_some()
    }

    /// The firmware's arguments for this run: `vfd=uart` with `--vfd`; for a deterministic
    /// run, mode 2 unless `--mode` says otherwise, and `run_ms` for `--seconds`.
    fn firmware_args(&self) -> Vec<String> {
        let mut fw_args = self.firmware_args.clone();
        if self.vfd.is_some() {
            fw_args.push("vfd=uart".into());
        }
        if !self.real_time() {
            if !fw_args.iter().any(|a| a.starts_with("mode=")) {
                fw_args.push("mode=2".into());
            }
            fw_args.push(format!("run_ms={}", self.seconds * 1000 + 1));
        }
        fw_args
    }
}

fn parse_qemu_options(args: &[String]) -> Result<QemuOptions> {
    let mut o = QemuOptions {
        scada_pty: false,
        vfd: None,
        plant: None,
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
            "--plant" => o.plant = Some(value("--plant")?),
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
            "--adapt" => o.firmware_args.push("adapt".to_string()),
            "--head" => o.firmware_args.push(format!("head={}", value("--head")?)),
            "--torque" => o
                .firmware_args
                .push(format!("torque={}", value("--torque")?)),
            other => return Err(format!("unknown option '{other}'\n{QEMU_USAGE}")),
        }
    }
    if o.plant.is_some() && (o.vfd.is_some() || !o.firmware_args.is_empty()) {
        return Err(format!(
            "--plant takes no --vfd, --mode, --setpoint, --seed, --narmax, --adapt, --head or --torque\n{QEMU_USAGE}"
        ));
    }
    Ok(o)
}

/// `cargo xtask qemu ARGS`: parses `args` (before building anything), builds the QEMU image
/// and runs it; a deterministic run prints the decoded log.
pub fn qemu(args: &[String]) -> Result {
    let o = parse_qemu_options(args)?;
    if let Some(plant) = &o.plant {
        return plant_mode(plant, o.scada_pty);
    }
    build_firmware(Board::Qemu)?;
    let elf = firmware_elf(Board::Qemu);
    let fw_args = o.firmware_args();
    if o.real_time() {
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
        let (mut qemu, bridge, _, _) = start_pty(&elf, cmd, true)?;
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
    print!("{}", qemu_log(&elf, &fw_args)?);
    Ok(())
}

/// `cargo xtask qemu --plant PLANT [--scada-pty]`: the plant-mode image in real time, the plant
/// line on the serial device `plant` or (`pty`) on a pseudo-terminal QEMU names, the SCADA
/// slave on a pseudo-terminal with `--scada-pty`; until the plant sends `Q` (QEMU exits) or
/// Ctrl-C.
fn plant_mode(plant: &str, scada_pty: bool) -> Result {
    build_plant_firmware()?;
    eprintln!("==> qemu, plant mode (until the plant sends Q, or Ctrl-C)");
    let scada = if scada_pty { "pty" } else { "null" };
    let (mut qemu, ptys, _log) = start_plant_qemu(&plant_elf(), scada, plant, true)?;
    // The SCADA port as a line for clients that open it per request (mbpoll): the bridge.
    let bridge = ptys.scada.map(|p| crate::bridge::start(&p)).transpose()?;
    if let Some(b) = &bridge {
        eprintln!(
            "SCADA slave (unit 1, RTU 19200 8N1) on {0}; e.g.\n  mbpoll -m rtu -b 19200 -P none -a 1 -t 3 -r 1 -c 30 {0}",
            b.path
        );
    }
    if let Some(pty) = ptys.plant {
        eprintln!("plant line on {pty}; e.g.\n  python3 examples/plant.py {pty}");
    }
    // The log is echoed by its thread; wait for QEMU's end.
    let status = qemu.0.wait().map_err(|e| format!("qemu: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("qemu: {status}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::args;

    #[test]
    fn deterministic_runs() {
        // The golden logs' command lines.
        let o = parse_qemu_options(&args("--seconds 60 --mode 2 --narmax q15")).unwrap();
        assert!(!o.real_time());
        assert_eq!(o.firmware_args(), ["mode=2", "narmax=q15", "run_ms=60001"]);
        let o = parse_qemu_options(&args("--seconds 30 --mode 1 --setpoint 6000")).unwrap();
        assert_eq!(
            o.firmware_args(),
            ["mode=1", "setpoint=6000", "run_ms=30001"]
        );
        // Defaults: 20 s of mode 2.
        let o = parse_qemu_options(&[]).unwrap();
        assert_eq!(o.seconds, 20);
        assert_eq!(o.firmware_args(), ["mode=2", "run_ms=20001"]);
        let o = parse_qemu_options(&args("--seed 7 --narmax f32")).unwrap();
        assert_eq!(
            o.firmware_args(),
            ["seed=7", "narmax=f32", "mode=2", "run_ms=20001"]
        );
        let o = parse_qemu_options(&args("--head 950 --torque 1050")).unwrap();
        assert_eq!(
            o.firmware_args(),
            ["head=950", "torque=1050", "mode=2", "run_ms=20001"]
        );
        let o = parse_qemu_options(&args("--adapt --narmax q15")).unwrap();
        assert_eq!(
            o.firmware_args(),
            ["adapt", "narmax=q15", "mode=2", "run_ms=20001"]
        );
        assert!(parse_qemu_options(&args("--plant pty --adapt")).is_err());
    }

    #[test]
    fn real_time_runs() {
        let o = parse_qemu_options(&args("--scada-pty")).unwrap();
        assert!(o.real_time() && o.vfd.is_none());
        // Stopped at start (the firmware's default), no run_ms: until stopped.
        assert!(o.firmware_args().is_empty());
        let o = parse_qemu_options(&args("--vfd /dev/pts/9 --mode 1 --seconds 5")).unwrap();
        assert!(o.real_time() && !o.scada_pty);
        assert_eq!(o.vfd.as_deref(), Some("/dev/pts/9"));
        assert_eq!(o.firmware_args(), ["mode=1", "vfd=uart"]);
    }

    #[test]
    fn plant_mode_options() {
        let o = parse_qemu_options(&args("--plant pty")).unwrap();
        assert_eq!(o.plant.as_deref(), Some("pty"));
        let o = parse_qemu_options(&args("--scada-pty --plant /dev/pts/4")).unwrap();
        assert_eq!(o.plant.as_deref(), Some("/dev/pts/4"));
        assert!(o.scada_pty && o.firmware_args.is_empty());
        for s in [
            "--plant pty --mode 3",
            "--plant pty --vfd /dev/pts/1",
            "--seed 2 --plant x",
            "--plant pty --head 950",
        ] {
            let e = parse_qemu_options(&args(s)).unwrap_err();
            assert!(e.starts_with("--plant takes no"), "{s}: {e}");
        }
        assert_eq!(
            parse_qemu_options(&args("--plant")).unwrap_err(),
            "--plant needs a value"
        );
    }

    #[test]
    fn bad_options() {
        let e = parse_qemu_options(&args("--mode 1 --fast")).unwrap_err();
        assert_eq!(e, format!("unknown option '--fast'\n{QEMU_USAGE}"));
        assert_eq!(
            parse_qemu_options(&args("--seconds")).unwrap_err(),
            "--seconds needs a value"
        );
        assert_eq!(
            parse_qemu_options(&args("--vfd")).unwrap_err(),
            "--vfd needs a value"
        );
        for s in ["--seconds 1.5", "--seconds -1", "--seconds x"] {
            assert_eq!(
                parse_qemu_options(&args(s)).unwrap_err(),
                "--seconds takes a whole number",
                "{s}"
            );
        }
        // A value is taken as it is, even one that looks like an option.
        let o = parse_qemu_options(&args("--mode --seed")).unwrap();
        assert_eq!(o.firmware_args, ["mode=--seed"]);
    }
}
