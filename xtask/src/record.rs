//! `cargo xtask record`: the commissioning record. The controller runs the paper's excitation
//! (mode 2) and sends a row per pressure sample over its log channel
//! ([`controller::record`]); this task reads the rows, checks their numbers (a lost row is
//! reported, never skipped in silence) and writes the CSV `pumpbench identify` takes as it
//! is.
//!
//! - QEMU: the board's log is defmt over semihosting, which does not drop a frame; the run is
//!   deterministic (`-icount`) and faster than real time (600 s of loop time in 86 s here).
//! - NUCLEO-F446RE (`--nucleo`): the image built with feature `record`, run by `probe-rs run`,
//!   its defmt over RTT printed as text (`--log-format {s}`); rows the RTT buffer dropped
//!   show as gaps.

use crate::board::{build_firmware, firmware_elf, Board};
use crate::qemu::{qemu_command, spawn_with_lines};
use crate::util::{field, num, Result};
use controller::record::{CsvCell, RecordRow};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// `cargo xtask record`'s usage.
pub const RECORD_USAGE: &str = "usage: cargo xtask record --seconds N --output REC.csv [--seed N] [--narmax f32|q15] [--head 800..1200] [--torque 800..1200] [--nucleo]
  runs the QEMU controller in mode 2 (the paper's excitation) for N s of loop time
  (1..=86400) and writes its commissioning record: a row per pressure sample (50 ms with the shipped models),
  t_s,torque_ref_pct,pressure_mca,flow_lps,speed_rpm,observer_k2,observer_flow_lps,alarms,
  status,seq; the flow on its own samples (every other row), an empty cell for a reading in
  fault. `pumpbench identify --data REC.csv --target pressure|flow` takes it as it is.
  --seed N          the excitation's and the virtual bench's seed (default 1)
  --narmax f32|q15  the NARMAX arithmetic (default f32)
  --head, --torque  the virtual bench's pump-head and load-torque curves, per mille of the
                    paper's (defaults 1000 and 1020: a bench the shipped models fit)
  --nucleo          record from a NUCLEO-F446RE with probe-rs (the image with feature
                    `record`, flashed): N s of loop time from the board's start; the board
                    starts stopped, so write mode 2 over SCADA (holding register 1) to run
                    the excitation; --seed, --narmax, --head and --torque do not apply";

/// Options of `cargo xtask record`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOptions {
    /// Loop time recorded, s.
    pub seconds: u32,
    /// The CSV to write.
    pub output: PathBuf,
    /// Seed of the excitation and the virtual bench.
    pub seed: u32,
    /// NARMAX arithmetic, `f32` or `q15`.
    pub narmax: String,
    /// The virtual bench's head curve, per mille.
    pub head: u32,
    /// The virtual bench's load-torque curve, per mille.
    pub torque: u32,
    /// From a NUCLEO-F446RE.
    pub nucleo: bool,
}

impl RecordOptions {
    /// Parses `cargo xtask record`'s arguments (before anything is built).
    pub fn parse(args: &[String]) -> Result<Self> {
        let mut o = RecordOptions {
            seconds: 0,
            output: PathBuf::new(),
            seed: 1,
            narmax: "f32".into(),
            head: 1000,
            torque: 1020,
            nucleo: false,
        };
        let (mut seconds, mut output) = (None, None);
        let mut curves = false;
        let mut bench_only = false;
        let mut it = args.iter();
        let bad = |what: String| format!("{what}\n{RECORD_USAGE}");
        while let Some(a) = it.next() {
            let mut value = |name: &str| {
                it.next()
                    .cloned()
                    .ok_or_else(|| bad(format!("{name} needs a value")))
            };
            let whole = |name: &str, text: String, range: std::ops::RangeInclusive<u32>| {
                text.parse::<u32>()
                    .ok()
                    .filter(|n| range.contains(n))
                    .ok_or_else(|| {
                        bad(format!(
                            "{name} {text}: a whole number in {}..={}",
                            range.start(),
                            range.end()
                        ))
                    })
            };
            match a.as_str() {
                "--seconds" => seconds = Some(whole("--seconds", value(a)?, 1..=86_400)?),
                "--output" => output = Some(PathBuf::from(value(a)?)),
                "--seed" => {
                    o.seed = whole("--seed", value(a)?, 0..=u32::MAX)?;
                    bench_only = true;
                }
                "--narmax" => {
                    o.narmax = value(a)?;
                    if o.narmax != "f32" && o.narmax != "q15" {
                        return Err(bad(format!("--narmax {}: f32 or q15", o.narmax)));
                    }
                    bench_only = true;
                }
                "--head" => (o.head, curves) = (whole("--head", value(a)?, 800..=1200)?, true),
                "--torque" => {
                    (o.torque, curves) = (whole("--torque", value(a)?, 800..=1200)?, true)
                }
                "--nucleo" => o.nucleo = true,
                other => return Err(bad(format!("unknown option '{other}'"))),
            }
        }
        o.seconds = seconds.ok_or_else(|| bad("--seconds is needed".into()))?;
        o.output = output.ok_or_else(|| bad("--output is needed".into()))?;
        if o.nucleo && curves {
            return Err(bad(
                "--head and --torque set the virtual bench's curves: not with --nucleo".into(),
            ));
        }
        if o.nucleo && bench_only {
            return Err(bad(
                "--seed and --narmax are the QEMU board's start-up arguments: not with --nucleo (write SCADA holding register 2 for the arithmetic)".into(),
            ));
        }
        Ok(o)
    }

    /// The QEMU firmware's arguments for this record.
    pub fn firmware_args(&self) -> Vec<String> {
        vec![
            "mode=2".into(),
            "record".into(),
            format!("seed={}", self.seed),
            format!("narmax={}", self.narmax),
            format!("head={}", self.head),
            format!("torque={}", self.torque),
            format!("run_ms={}", self.seconds * 1000 + 1),
        ]
    }
}

/// `cargo xtask record ARGS`.
pub fn record(args: &[String]) -> Result {
    let o = RecordOptions::parse(args)?;
    let summary = if o.nucleo {
        record_nucleo(&o)?
    } else {
        build_firmware(Board::Qemu)?;
        record_qemu(&firmware_elf(Board::Qemu), &o)?
    };
    println!("{summary}");
    Ok(())
}

/// A decoded `rec …` line ([`crate::replay::record_text`]'s form) as its row.
pub fn parse_row(line: &str) -> Result<RecordRow> {
    let f = |key| num::<f32>(line, key);
    Ok(RecordRow {
        seq: num(line, "seq")?,
        t_ms: num(line, "t_ms")?,
        torque_pct: f("u_pct")?,
        pressure_mca: f("p_mca")?,
        flow_lps: f("q_lps")?,
        flow_sampled: num(line, "q_new")?,
        vfd_speed_rpm: f("vfd_rpm")?,
        observer_k2: f("ob_k2")?,
        observer_flow_lps: f("ob_q")?,
        alarms: num(line, "alarms")?,
        status: num(line, "status")?,
    })
}

/// The CSV being written: the rows in their order, the numbers checked. It is written to
/// `<output>.partial` and renamed to the output by [`RecordWriter::finish`]; a record that
/// fails before that leaves no CSV behind (and an older one at the output as it was).
pub struct RecordWriter {
    out: Option<std::io::BufWriter<std::fs::File>>,
    path: PathBuf,
    partial: PathBuf,
    next: Option<u32>,
    /// Rows written.
    pub rows: u64,
    /// Rows with a flow reading.
    pub flow_rows: u64,
    /// Rows missing between those written, or before the first (gaps in the numbers).
    pub lost: u64,
    /// The first gaps: (first missing number, how many).
    pub gaps: Vec<(u32, u32)>,
    /// The last row's time, ms.
    pub last_t_ms: u32,
}

impl RecordWriter {
    /// Starts the CSV for `path` (in `<path>.partial`) and writes the header.
    pub fn create(path: &Path) -> Result<Self> {
        let mut partial = path.as_os_str().to_owned();
        partial.push(".partial");
        let partial = PathBuf::from(partial);
        let file = std::fs::File::create(&partial)
            .map_err(|e| format!("cannot write {}: {e}", partial.display()))?;
        let mut w = Self {
            out: Some(std::io::BufWriter::new(file)),
            path: path.to_path_buf(),
            partial,
            next: None,
            rows: 0,
            flow_rows: 0,
            lost: 0,
            gaps: vec![],
            last_t_ms: 0,
        };
        w.line(RecordRow::CSV_HEADER)?;
        Ok(w)
    }

    fn line(&mut self, text: &str) -> Result {
        let out = self.out.as_mut().ok_or("the record is closed")?;
        writeln!(out, "{text}").map_err(|e| format!("{}: {e}", self.partial.display()))
    }

    fn gap(&mut self, first: u32, missing: u32) {
        self.lost += u64::from(missing);
        if self.gaps.len() < 10 {
            self.gaps.push((first, missing));
        }
    }

    /// Writes `row`. The first row must be number 0 (rows before it are counted lost); a row
    /// whose number is not the next one's is a gap (counted, the rows missing not written); a
    /// row numbered before it is an error (the board restarted: a watchdog reset, a power
    /// cut).
    pub fn push(&mut self, row: &RecordRow) -> Result {
        let next = self.next.unwrap_or(0);
        if row.seq < next {
            return Err(format!(
                "record row {} came after row {}: the board restarted (a reset?): no CSV written",
                row.seq,
                next - 1
            ));
        }
        if row.seq > next {
            self.gap(next, row.seq - next);
        }
        self.next = row.seq.checked_add(1);
        let ryu = |x: f32| {
            let mut b = ryu::Buffer::new();
            let mut s = CsvCell::new();
            let _ = s.push_str(b.format(x));
            s
        };
        let cells = row.csv_cells(ryu);
        let text: Vec<&str> = cells.iter().map(|c| c.as_str()).collect();
        self.line(&text.join(","))?;
        self.rows += 1;
        self.flow_rows += u64::from(row.flow().is_some());
        self.last_t_ms = row.t_ms;
        Ok(())
    }

    /// Ends the record made by `source`, which should have run to `end_ms` of loop time:
    /// the CSV renamed to the output, and the summary line; an error if no row came, if the
    /// record stops short of `end_ms` (no CSV then), or if rows were lost (the CSV is kept:
    /// `identify` refuses its gaps).
    pub fn finish(mut self, source: &str, end_ms: u32) -> Result<String> {
        let mut out = self.out.take().ok_or("the record is closed")?;
        out.flush()
            .map_err(|e| format!("{}: {e}", self.partial.display()))?;
        drop(out);
        if self.rows == 0 || self.last_t_ms < end_ms {
            let _ = std::fs::remove_file(&self.partial);
        }
        if self.rows == 0 {
            return Err(format!("{source}: no record row arrived"));
        }
        if self.last_t_ms < end_ms {
            return Err(format!(
                "{source}: the record stops at {} s, short of {} s: no CSV written",
                f64::from(self.last_t_ms) / 1000.0,
                f64::from(end_ms) / 1000.0
            ));
        }
        std::fs::rename(&self.partial, &self.path).map_err(|e| {
            format!(
                "cannot rename {} to {}: {e}",
                self.partial.display(),
                self.path.display()
            )
        })?;
        let summary = format!(
            "record: {} rows to {} s ({} with a flow reading), {} lost, from {source} -> {}",
            self.rows,
            f64::from(self.last_t_ms) / 1000.0,
            self.flow_rows,
            self.lost,
            self.path.display()
        );
        if self.lost > 0 {
            let gaps: Vec<String> = self
                .gaps
                .iter()
                .map(|(first, n)| format!("{n} from row {first}"))
                .collect();
            return Err(format!(
                "{summary}\nrows lost ({}): the CSV has gaps there, which identify refuses",
                gaps.join(", ")
            ));
        }
        Ok(summary)
    }
}

impl Drop for RecordWriter {
    /// A record that did not reach [`RecordWriter::finish`] leaves no partial CSV behind.
    fn drop(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}

/// Longest a QEMU record may take on the wall clock for `seconds` of loop time: QEMU runs
/// ≈ 7 times faster than real time here (600 s in 86 s); real time is the bound.
fn qemu_wall_limit(seconds: u32) -> Duration {
    Duration::from_secs(60 + u64::from(seconds))
}

/// The record from the QEMU board `elf` (on its virtual bench, with `o`'s options) into
/// `o.output`; the summary. A row the log channel dropped (the board warns) is a gap; any
/// other warning is reported; an error, QEMU's end before the record's, or the time limit
/// end it without a CSV.
pub fn record_qemu(elf: &Path, o: &RecordOptions) -> Result<String> {
    let args = o.firmware_args();
    let mut cmd = qemu_command(elf, &args);
    cmd.args([
        "-display", "none", "-monitor", "none", "-serial", "null", "-serial", "null",
    ])
    .args(["-icount", "shift=0,sleep=off"]);
    eprintln!(
        "==> record: {} s of loop time from the QEMU board ({})",
        o.seconds,
        args.join(" ")
    );
    let (mut qemu, lines) = spawn_with_lines(elf, cmd, false)?;
    let mut w = RecordWriter::create(&o.output)?;
    let start = Instant::now();
    let deadline = start + qemu_wall_limit(o.seconds);
    let mut header = None;
    let mut shown = 0;
    let mut other = vec![];
    let mut warnings = vec![];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let line = match lines.recv_timeout(left) {
            Ok(l) => l,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                return Err(format!(
                    "record: no end after {} s on the wall clock: no CSV written",
                    qemu_wall_limit(o.seconds).as_secs()
                ))
            }
            Err(_) => {
                let status = qemu.0.wait().map(|s| s.to_string()).unwrap_or_default();
                let tail = other[other.len().saturating_sub(5)..].join("\n");
                return Err(format!(
                    "record: QEMU ended ({status}) before the record did, at {} s: no CSV written\n{tail}",
                    f64::from(w.last_t_ms) / 1000.0
                ));
            }
        };
        if line.starts_with("rec ") {
            w.push(&parse_row(&line)?)?;
            // Progress: every tenth of the record.
            let tenth = (u64::from(w.last_t_ms) * 10) / (u64::from(o.seconds) * 1000);
            if tenth > shown {
                shown = tenth;
                eprintln!(
                    "    {:>6.1} / {} s, {} rows, {:.0} s",
                    f64::from(w.last_t_ms) / 1000.0,
                    o.seconds,
                    w.rows,
                    start.elapsed().as_secs_f64()
                );
            }
        } else if line.starts_with("firmware:") {
            header = Some(line);
        } else if line.starts_with("done:") {
            if num::<u32>(&line, "lost")? != 0 {
                return Err(format!("record: the board lost serial bytes: {line}"));
            }
            break;
        } else if line.starts_with("ERROR") {
            return Err(format!("record: the board says: {line}: no CSV written"));
        } else if line.starts_with("WARN") {
            // A dropped row shows as a gap in the numbers; the rest is reported.
            if !line.contains("record row") {
                warnings.push(line);
            }
        } else if !line.starts_with("t_s=") && !line.starts_with("margin:") {
            other.push(line);
        }
    }
    for w in &warnings {
        eprintln!("record: the board warned: {w}");
    }
    let header = header.ok_or("record: no 'firmware:' header line")?;
    let source = format!(
        "the QEMU board (seed {}, narmax {}, head {} ‰, torque {} ‰)",
        field(&header, "seed")?,
        field(&header, "narmax")?,
        field(&header, "head")?,
        field(&header, "torque")?
    );
    w.finish(&source, o.seconds * 1000)
}

/// probe-rs, killed when dropped.
struct Probe(std::process::Child);
impl Drop for Probe {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The record from a NUCLEO-F446RE: the image with feature `record` built and run by
/// `probe-rs run` (flashed, then its RTT log as text with its level), rows until
/// `o.seconds` of loop time since the board's start. An error line, probe-rs's end before
/// the record's, a restart of the board, or 30 s without a row end it without a CSV.
fn record_nucleo(o: &RecordOptions) -> Result<String> {
    use std::io::BufRead;
    crate::board::build_nucleo_record()?;
    let elf = firmware_elf(Board::Nucleo);
    let mut child = std::process::Command::new("probe-rs")
        .args(["run", "--chip", "STM32F446RETx", "--log-format", "{L} {s}"])
        .arg(&elf)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| {
            format!("cannot start probe-rs (cargo install --locked probe-rs-tools): {e}")
        })?;
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let mut probe = Probe(child);
    let (tx, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(|l| l.ok())
        {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut w = RecordWriter::create(&o.output)?;
    let end_ms = o.seconds * 1000;
    eprintln!(
        "==> record: {} s from the NUCLEO-F446RE (write mode 2 over SCADA to run the excitation)",
        o.seconds
    );
    while w.last_t_ms < end_ms || w.rows == 0 {
        let line = match lines.recv_timeout(Duration::from_secs(30)) {
            Ok(l) => l,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                return Err("record: no line from probe-rs in 30 s: no CSV written".into())
            }
            Err(_) => {
                let status = probe.0.wait().map(|s| s.to_string()).unwrap_or_default();
                return Err(format!(
                    "record: probe-rs ended ({status}) at {} s of the record: no CSV written",
                    f64::from(w.last_t_ms) / 1000.0
                ));
            }
        };
        if let Some(k) = line.find("rec seq=") {
            w.push(&parse_row(&line[k..])?)?;
        } else if line.starts_with("ERROR") {
            return Err(format!("record: the board says: {line}: no CSV written"));
        } else if line.starts_with("WARN") && !line.contains("record row") {
            eprintln!("record: the board warned: {line}");
        }
    }
    drop(probe);
    w.finish("the NUCLEO-F446RE (probe-rs, RTT)", end_ms)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::args;

    #[test]
    fn options() {
        let o = RecordOptions::parse(&args("--seconds 600 --output r.csv")).unwrap();
        assert_eq!((o.seconds, o.seed, o.head, o.torque), (600, 1, 1000, 1020));
        assert_eq!(
            o.firmware_args(),
            args("mode=2 record seed=1 narmax=f32 head=1000 torque=1020 run_ms=600001")
        );
        let o = RecordOptions::parse(&args(
            "--seconds 5 --output r.csv --seed 7 --narmax q15 --head 950 --torque 1050",
        ))
        .unwrap();
        assert_eq!(
            o.firmware_args(),
            args("mode=2 record seed=7 narmax=q15 head=950 torque=1050 run_ms=5001")
        );
        for (bad, says) in [
            ("--output r.csv", "--seconds is needed"),
            ("--seconds 5", "--output is needed"),
            (
                "--seconds 0 --output r",
                "--seconds 0: a whole number in 1..=86400",
            ),
            ("--seconds x --output r", "--seconds x"),
            ("--seconds 5 --output r --head 1300", "--head 1300"),
            ("--seconds 5 --output r --narmax f64", "--narmax f64"),
            (
                "--seconds 5 --output r --nucleo --torque 900",
                "--head and --torque set",
            ),
            (
                "--seconds 5 --output r --nucleo --seed 3",
                "--seed and --narmax are",
            ),
            (
                "--seconds 5 --output r --narmax q15 --nucleo",
                "--seed and --narmax are",
            ),
            ("--seconds 5 --output r --fast", "unknown option '--fast'"),
            ("--seconds", "--seconds needs a value"),
        ] {
            let e = RecordOptions::parse(&args(bad)).unwrap_err();
            assert!(e.starts_with(says), "{bad}: {e}");
            assert!(e.ends_with(RECORD_USAGE), "{bad}");
        }
    }

    fn row(seq: u32) -> RecordRow {
        RecordRow {
            seq,
            t_ms: 50 * seq,
            torque_pct: 12.5,
            pressure_mca: 1.0 / 3.0,
            flow_lps: 7.25,
            flow_sampled: seq.is_multiple_of(2),
            vfd_speed_rpm: 1000.0,
            observer_k2: 0.1082,
            observer_flow_lps: 7.0,
            alarms: 0,
            status: 9,
        }
    }

    #[test]
    fn a_decoded_line_reads_back_to_the_same_bits() {
        let r = row(3);
        assert_eq!(parse_row(&crate::replay::record_text(&r)), Ok(r));
        assert!(parse_row("rec seq=1 t_ms=50").is_err());
    }

    #[test]
    fn the_csv_and_its_gaps() {
        let dir = tempdir();
        let path = dir.join("r.csv");
        let mut w = RecordWriter::create(&path).unwrap();
        for seq in [0, 1, 2, 5, 6] {
            w.push(&row(seq)).unwrap();
        }
        assert!(w.push(&row(4)).unwrap_err().contains("the board restarted"));
        let e = w.finish("test", 300).unwrap_err();
        assert!(
            e.contains("5 rows to 0.3 s (3 with a flow reading), 2 lost"),
            "{e}"
        );
        assert!(e.contains("rows lost (2 from row 3)"), "{e}");
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], RecordRow::CSV_HEADER);
        assert_eq!(
            lines[1],
            "0.000,12.5,0.33333334,7.25,1000.0,0.1082,7.0,0,9,0"
        );
        assert_eq!(lines[2], "0.050,12.5,0.33333334,,1000.0,0.1082,7.0,0,9,1");
        assert_eq!(lines.len(), 6);
        // A record that stops short leaves no CSV, and the one before stays.
        let mut w = RecordWriter::create(&path).unwrap();
        w.push(&row(0)).unwrap();
        w.push(&row(1)).unwrap();
        let e = w.finish("test", 100).unwrap_err();
        assert!(e.contains("stops at 0.05 s, short of 0.1 s"), "{e}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
        let mut w = RecordWriter::create(&path).unwrap();
        w.push(&row(0)).unwrap();
        assert!(w.finish("test", 0).unwrap().contains("1 rows to 0 s"));
        let w = RecordWriter::create(&path).unwrap();
        assert!(w.finish("test", 0).unwrap_err().contains("no record row"));
        // Rows lost before the first one that came are counted; a record dropped before its
        // end leaves nothing.
        let mut w = RecordWriter::create(&dir.join("late.csv")).unwrap();
        w.push(&row(3)).unwrap();
        let e = w.finish("test", 150).unwrap_err();
        assert!(e.contains("3 lost") && e.contains("3 from row 0"), "{e}");
        let mut w = RecordWriter::create(&dir.join("dropped.csv")).unwrap();
        w.push(&row(0)).unwrap();
        drop(w);
        assert!(!dir.join("dropped.csv").exists() && !dir.join("dropped.csv.partial").exists());
        assert!(!dir.join("r.csv.partial").exists());
        let _ = std::fs::remove_dir_all(dir);
    }

    fn tempdir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("xtask-record-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }
}
