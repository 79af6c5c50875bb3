//! The SCADA port flooded while the VFD link is busy: the firmware's margins (its last
//! `margin:` line) and the checks that nothing was lost.

use crate::line::{frame, loop_rate, two_answers, Port};
use crate::qemu::{qemu_command, start_pty, Qemu};
use crate::util::{cargo, num, root, Result};
use std::path::Path;
use std::time::{Duration, Instant};

/// Length of the SCADA flood that measures the margins, s.
pub const FLOOD_S: u64 = 10;

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
pub fn flood(elf: &Path, seconds: u64, icount: bool) -> Result<String> {
    let mut cmd = qemu_command(
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
    let sim = cargo()
        .current_dir(root())
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
    // For a failure's report: the slowest answer, and the first request unanswered (when
    // in the flood, which kind, how many bytes of an answer came).
    let mut slowest = Duration::ZERO;
    let mut first_miss: Option<String> = None;
    while t0.elapsed() < Duration::from_secs(seconds) {
        let asked = Instant::now();
        if sent % 10 == 9 {
            let (a, b) = (frame(&[1, 4, 0, 0, 0, 18]), frame(&[1, 3, 0, 0, 0, 3]));
            port.send(&[a, b].concat())?;
            sent += 2;
            let both = port.recv(41 + 11, Duration::from_secs(1));
            let ok = two_answers(&both, 18);
            answered += 2 * u32::from(ok);
            if !ok && first_miss.is_none() {
                first_miss = Some(format!(
                    "two requests in one write at {:.3} s: {} of 52 bytes back in {} ms",
                    (asked - t0).as_secs_f64(),
                    both.len(),
                    asked.elapsed().as_millis()
                ));
            }
        } else {
            sent += 1;
            if let Some(r) = port.inputs(0, 18, Duration::from_secs(1))? {
                answered += 1;
                status_or |= r[0];
                status_and &= r[0];
            } else if first_miss.is_none() {
                first_miss = Some(format!(
                    "a read at {:.3} s: no right answer in {} ms",
                    (asked - t0).as_secs_f64(),
                    asked.elapsed().as_millis()
                ));
            }
        }
        slowest = slowest.max(asked.elapsed());
    }
    let (s1, wall) = (port.samples("after the flood")?, t0.elapsed().as_secs_f64());
    let rate = loop_rate(s0, s1, wall);
    // The firmware logs its margins once a second; the last line covers the flood.
    std::thread::sleep(Duration::from_millis(1500));
    drop(qemu);
    let lines: Vec<String> = log.try_iter().collect();
    // The client's side, for the record and for a failure's diagnosis.
    let client = format!(
        "  client: slowest answer {} ms{}; {}\n",
        slowest.as_millis(),
        first_miss.map_or(String::new(), |m| format!(", first unanswered: {m}")),
        bridge.stats.summary()
    );
    verdict(
        &Seen {
            seconds,
            icount,
            sent,
            answered,
            status_and,
            status_or,
            wall,
            rate,
        },
        &lines,
    )
    .map(|r| r + &client)
    .map_err(|e| e + &client)
}

/// What the client saw of a flood.
#[derive(Debug, Clone, Copy)]
struct Seen {
    /// The flood's length, s.
    seconds: u64,
    /// Run under `-icount shift=0` (the rate not checked).
    icount: bool,
    /// Requests sent.
    sent: u32,
    /// Requests answered rightly.
    answered: u32,
    /// The status register (input 0) of every answer, and-ed.
    status_and: u16,
    /// The same, or-ed.
    status_or: u16,
    /// The flood's wall time, s.
    wall: f64,
    /// The loop's rate against the wall clock (see [`loop_rate`]).
    rate: f64,
}

/// The flood's report from what the client saw and the firmware's log `lines` (its last
/// `margin:` line: `lost` and `bytes`; its errors and warnings); an error with the report if
/// a check fails.
fn verdict(seen: &Seen, lines: &[String]) -> Result<String> {
    let margin = lines
        .iter()
        .rev()
        .find(|l| l.starts_with("margin:"))
        .ok_or("the firmware logged no margin line")?
        .clone();
    let get = |k: &str| -> Result<u64> { num(&margin, k) };
    let (lost, bytes) = (get("lost")?, get("bytes")?);
    let mut report = format!(
        "flood, {} s {}, VFD on USART2 to pumpbench vfd-sim: {} of {} requests answered ({:.0}/s), loop at {:+.2} % of wall time{}\n  firmware: {margin}\n  rx_wait_bound = usart_max + masked_max; {}\n",
        seen.seconds,
        if seen.icount { "under -icount shift=0" } else { "in real time" },
        seen.answered,
        seen.sent,
        f64::from(seen.sent) / seen.wall,
        seen.rate * 100.0,
        if seen.icount { " (QEMU's clock, not checked)" } else { "" },
        if seen.icount {
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
    if seen.answered != seen.sent {
        return Err(format!(
            "{} requests unanswered or wrong under the flood\n{report}",
            seen.sent - seen.answered
        ));
    }
    if lost != 0 {
        return Err(format!("{lost} received bytes lost\n{report}"));
    }
    if bytes < u64::from(seen.sent) * 8 {
        let sent = seen.sent;
        return Err(format!("the firmware counted {bytes} bytes received, fewer than the {sent} requests hold\n{report}"));
    }
    let (status_and, status_or) = (seen.status_and, seen.status_or);
    if status_and & 0b1000 == 0 || status_or & 0b100_0000 != 0 {
        return Err(format!("the VFD link failed during the flood (status seen: and {status_and:#06b}, or {status_or:#09b})\n{report}"));
    }
    if !seen.icount && seen.rate.abs() > 0.01 {
        return Err(format!("the loop's rate depends on the flood\n{report}"));
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SEEN: Seen = Seen {
        seconds: 10,
        icount: false,
        sent: 4000,
        answered: 4000,
        status_and: 0b1001,
        status_or: 0b1011,
        wall: 10.0,
        rate: 0.001,
    };

    fn log(margin: &str) -> Vec<String> {
        vec![
            "firmware: virtual bench, mode=1".into(),
            "margin: steps=1 bytes=0 lost=0".into(),
            margin.into(),
            "t_s=10 mode=manual".into(),
        ]
    }

    const MARGIN: &str = "margin: steps=10001 control_max=9900 usart_max=700 masked_max=4400 rx_wait_bound=5100 bytes=32000 lost=0";

    #[test]
    fn a_good_flood() {
        let report = verdict(&SEEN, &log(MARGIN)).unwrap();
        assert!(report.starts_with("flood, 10 s in real time, VFD on USART2 to pumpbench vfd-sim: 4000 of 4000 requests answered (400/s), loop at +0.10 % of wall time\n"), "{report}");
        assert!(
            report.contains(&format!("  firmware: {MARGIN}\n")),
            "{report}"
        );
        assert!(report.contains("virtual ns in real time"), "{report}");
        let mut lines = log(MARGIN);
        lines.push("WARN: a warning".into());
        let report = verdict(&SEEN, &lines).unwrap();
        assert!(
            report.ends_with("  firmware said: WARN: a warning\n"),
            "{report}"
        );
        // Under -icount the rate is reported, not checked.
        let icount = Seen {
            icount: true,
            rate: -0.4,
            ..SEEN
        };
        let report = verdict(&icount, &log(MARGIN)).unwrap();
        assert!(report.contains("under -icount shift=0"), "{report}");
        assert!(report.contains("(QEMU's clock, not checked)"), "{report}");
        assert!(report.contains("counts are instructions"), "{report}");
    }

    #[test]
    fn failed_floods() {
        let fails = |seen: Seen, margin: &str, why: &str| {
            let e = verdict(&seen, &log(margin)).unwrap_err();
            assert!(e.starts_with(why), "{e}");
        };
        fails(
            Seen {
                answered: 3999,
                ..SEEN
            },
            MARGIN,
            "1 requests unanswered or wrong under the flood\n",
        );
        fails(
            SEEN,
            &MARGIN.replace("lost=0", "lost=3"),
            "3 received bytes lost\n",
        );
        fails(
            SEEN,
            &MARGIN.replace("bytes=32000", "bytes=31999"),
            "the firmware counted 31999 bytes received, fewer than the 4000 requests hold\n",
        );
        fails(
            Seen {
                status_and: 0b0001,
                ..SEEN
            },
            MARGIN,
            "the VFD link failed during the flood",
        );
        fails(
            Seen {
                status_or: 0b100_1011,
                ..SEEN
            },
            MARGIN,
            "the VFD link failed during the flood",
        );
        fails(
            Seen {
                rate: 0.011,
                ..SEEN
            },
            MARGIN,
            "the loop's rate depends on the flood\n",
        );
        fails(
            Seen {
                rate: -0.011,
                ..SEEN
            },
            MARGIN,
            "the loop's rate depends on the flood\n",
        );
        let e = verdict(&SEEN, &["t_s=1".to_string()]).unwrap_err();
        assert_eq!(e, "the firmware logged no margin line");
        assert!(verdict(&SEEN, &log("margin: steps=1 lost=0")).is_err());
    }
}
