//! `mbpoll` (another Modbus implementation, libmodbus) as the SCADA client of the end-to-end
//! test and its sessions, and the registers out of its answers.

use crate::util::Result;
use std::process::Command;

/// `mbpoll` in RTU mode (19200 8N1, 1 s timeout, one poll): `args`, the port, `values`.
pub fn mbpoll(pty: &str, args: &[&str], values: &[&str]) -> Result<String> {
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
pub fn registers(text: &str, first: usize, count: usize) -> Result<Vec<i64>> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An answer in mbpoll's layout (`-t 3 -r 19 -c 5`).
    const READ: &str = "mbpoll 1.4-12 - FieldTalk(tm) Modbus(R) Master Simulator
Copyright © 2015-2019 Pascal JEAN, https://github.com/epsilonrt/mbpoll
Protocol configuration: Modbus RTU
Slave configuration...: address = [1]
                        start reference = 19, count = 5
Communication.........: /dev/pts/3,      19200-8N1
                        t/o 1.00 s, poll rate 1000 ms
Data type.............: 16-bit register, input register table

-- Polling slave 1...
[19]: 	12503
[20]: 	1450
[21]: 	-3
[22]: 	64 (0x40)
[23]: 	  17
";

    #[test]
    fn registers_of_an_answer() {
        assert_eq!(registers(READ, 19, 5), Ok(vec![12503, 1450, -3, 64, 17]));
        assert_eq!(registers(READ, 21, 2), Ok(vec![-3, 64]));
        assert_eq!(registers(READ, 19, 0), Ok(vec![]));
        // A register not in the answer (mbpoll's [1] is not its [19]).
        let e = registers(READ, 23, 2).unwrap_err();
        assert!(
            e.starts_with("register 24 not in mbpoll's answer:\n"),
            "{e}"
        );
        assert!(registers(READ, 1, 1).is_err());
        assert!(registers("[19]: x\n", 19, 1).is_err());
        assert!(registers("Read input register failed: Connection timed out\n", 19, 1).is_err());
    }
}
