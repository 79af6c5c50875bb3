//! Reading bench CSV files: every error names the file, the line and the column.

use crate::num::Short;
use std::fmt;
use std::path::{Path, PathBuf};

/// A bad input file, or an I/O failure. Displayed as one line:
/// `FILE:LINE:COLUMN: what is wrong` (line and column 1-based, column omitted when the
/// error is about a whole row or the file).
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    /// The file.
    pub path: PathBuf,
    /// 1-based line, if known.
    pub line: Option<u64>,
    /// 1-based column and its header name, if known.
    pub column: Option<(usize, String)>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some((col, name)) = &self.column {
            write!(f, ":{col} ({name})")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for InputError {}

/// Largest CSV file read, bytes (256 MiB; a one-hour `t_s,torque_ref_pct` input with a row per
/// millisecond is 42 MB). A larger file, or a device or pipe that gives more, is refused once
/// this much has been read.
pub const MAX_CSV_BYTES: u64 = 256 << 20;

/// `bytes` as a size in a message: `256 MiB`, `16 MiB`, `100 KiB`, `10 bytes`.
pub fn size_text(bytes: u64) -> String {
    if bytes >= 1 << 20 && bytes.is_multiple_of(1 << 20) {
        format!("{} MiB", bytes >> 20)
    } else if bytes >= 1 << 10 && bytes.is_multiple_of(1 << 10) {
        format!("{} KiB", bytes >> 10)
    } else {
        format!("{bytes} bytes")
    }
}

/// Reads the whole of `path`, but no more than `cap` bytes: a regular file longer than that is
/// refused by its size without being read, anything else (a device such as /dev/zero, a pipe)
/// once `cap + 1` bytes have come. The error is a one-line message without the path.
pub fn read_bounded(path: &Path, cap: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let too_large = || format!("larger than {}, the limit for this input", size_text(cap));
    let file = std::fs::File::open(path).map_err(|e| format!("cannot open: {e}"))?;
    let meta = file.metadata().map_err(|e| format!("cannot open: {e}"))?;
    if meta.is_dir() {
        return Err("cannot read: it is a folder".into());
    }
    let mut bytes = Vec::new();
    if meta.is_file() {
        if meta.len() > cap {
            return Err(too_large());
        }
        // The file may still grow while it is read: the cap below holds anyway.
        bytes.reserve_exact(meta.len() as usize + 1);
    }
    file.take(cap.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| format!("cannot read: {e}"))?;
    if bytes.len() as u64 > cap {
        return Err(too_large());
    }
    Ok(bytes)
}

/// A CSV with a header row, from which some columns are read as finite numbers.
pub struct NumericColumns {
    /// The requested columns of every data record, row after row, in the requested order.
    values: Vec<f64>,
    /// Number of requested columns.
    width: usize,
    /// 1-based line of each row (for later error messages).
    pub lines: Vec<u64>,
    /// 1-based column index of each requested column.
    pub columns: Vec<usize>,
}

impl NumericColumns {
    /// The rows: the requested columns, in the requested order.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, f64> {
        self.values.chunks_exact(self.width.max(1))
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.lines.len()
    }
}

/// 1-based line numbers of byte offsets in `bytes` (lines end with `\n`, `\r\n` or a lone
/// `\r`), counted as the offsets come, in increasing order (the csv crate's records and
/// errors), so no table of line starts is kept.
///
/// The csv crate's own line numbers are wrong after CRLF endings and blank lines
/// (rust-csv #395, #208); its byte offsets are right, so lines are counted here.
struct LineCounter<'a> {
    bytes: &'a [u8],
    /// Bytes before this offset are counted.
    scanned: usize,
    /// Line ends among them.
    ends: u64,
}

impl<'a> LineCounter<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        LineCounter {
            bytes,
            scanned: 0,
            ends: 0,
        }
    }

    /// 1-based line of the record that the csv crate says starts at byte `offset`: its offset
    /// can point at the end of the previous line (the `\n` of a CRLF) or at skipped blank
    /// lines, so line terminators are stepped over first.
    fn line_of(&mut self, offset: u64) -> u64 {
        let bytes = self.bytes;
        let mut at = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(bytes.len());
        while at < bytes.len() && matches!(bytes[at], b'\r' | b'\n') {
            at += 1;
        }
        if at < self.scanned {
            // Not expected (offsets only grow), but right anyway: count again from the start.
            self.scanned = 0;
            self.ends = 0;
        }
        for i in self.scanned..at {
            let end = match bytes[i] {
                b'\n' => true,
                b'\r' => bytes.get(i + 1) != Some(&b'\n'),
                _ => false,
            };
            self.ends += u64::from(end);
        }
        self.scanned = at;
        self.ends + 1
    }
}

/// Longest cell or header text shown in a message, characters.
const SHOWN_CHARS: usize = 60;

/// A cell or header as shown in a one-line message: control characters escaped, and cut after
/// [`SHOWN_CHARS`] characters (`…` and the full length then follow).
pub(crate) fn shown(text: &str) -> String {
    let n = text.chars().count();
    if n <= SHOWN_CHARS {
        return text.escape_debug().to_string();
    }
    let head: String = text.chars().take(SHOWN_CHARS).collect();
    format!("{}… ({n} characters)", head.escape_debug())
}

/// Reads `path` (at most [`MAX_CSV_BYTES`]), requiring the named columns (any order, other
/// columns ignored, no column name twice in the header) and parsing every cell of them as a
/// finite number. Blank and whitespace-only lines are skipped.
pub fn read_columns(path: &Path, names: &[&str]) -> Result<NumericColumns, InputError> {
    let mut values = Vec::new();
    let mut lines = Vec::new();
    let columns = scan_csv(path, names, &[], |line, columns, record| {
        for (c, name) in columns.iter().flatten().zip(names) {
            values.push(finite_cell(
                path,
                line,
                *c,
                name,
                record.get(*c).unwrap_or(""),
            )?);
        }
        lines.push(line);
        Ok(())
    })?;
    Ok(NumericColumns {
        values,
        width: names.len(),
        lines,
        columns: columns.iter().flatten().map(|c| c + 1).collect(),
    })
}

/// The cell `text` of 0-based column `c` (named `name`) on `line`, as a finite number.
pub(crate) fn finite_cell(
    path: &Path,
    line: u64,
    c: usize,
    name: &str,
    text: &str,
) -> Result<f64, InputError> {
    let err = |message: String| InputError {
        path: path.to_path_buf(),
        line: Some(line),
        column: Some((c + 1, name.to_string())),
        message,
    };
    let value: f64 = text
        .parse()
        .map_err(|_| err(format!("'{}' is not a number", shown(text))))?;
    if !value.is_finite() {
        return Err(err(format!("'{}' is not a finite number", shown(text))));
    }
    Ok(value)
}

/// Reads `path` (at most [`MAX_CSV_BYTES`]): a header row that has every column of `names`
/// and no column name twice, then data records of as many fields as the header (blank and
/// whitespace-only lines skipped, at least one record). Cells are trimmed. `row` is called
/// for each record with its 1-based line, the 0-based column of each of `names` then of each
/// of `optional` (`None` where the header lacks an optional one), and the record. Returns
/// those columns.
pub(crate) fn scan_csv(
    path: &Path,
    names: &[&str],
    optional: &[&str],
    mut row: impl FnMut(u64, &[Option<usize>], &csv::StringRecord) -> Result<(), InputError>,
) -> Result<Vec<Option<usize>>, InputError> {
    let err = |line: Option<u64>, column: Option<(usize, String)>, message: String| InputError {
        path: path.to_path_buf(),
        line,
        column,
        message,
    };
    let bytes = read_bounded(path, MAX_CSV_BYTES).map_err(|m| err(None, None, m))?;
    let mut lines_of = LineCounter::new(&bytes);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(bytes.as_slice());
    let header = reader
        .headers()
        .map_err(|e| err(Some(1), None, format!("cannot read the header: {e}")))?
        .clone();
    let header_line = header.position().map_or(1, |p| lines_of.line_of(p.byte()));
    if header.is_empty() || header.iter().all(|h| h.is_empty()) {
        return Err(err(
            Some(header_line),
            None,
            format!("empty file: expected a header row with {}", names.join(",")),
        ));
    }
    // Each name's first column, in one pass (a hostile header may have millions of columns).
    let mut first_of = std::collections::HashMap::with_capacity(header.len());
    for (i, h) in header.iter().enumerate() {
        if h.is_empty() {
            continue;
        }
        if let Some(&first) = first_of.get(h) {
            return Err(err(
                Some(header_line),
                Some((i + 1, shown(h))),
                format!(
                    "column '{}' appears twice in the header (columns {} and {})",
                    shown(h),
                    first + 1,
                    i + 1
                ),
            ));
        }
        first_of.insert(h, i);
    }
    // A column named as a known one but for case, `_`, `-` or spaces: a typo that would
    // otherwise be ignored without a word (`Static_Head` wrote nothing: a review).
    let key = |s: &str| -> String {
        s.chars()
            .filter(|c| !matches!(c, '_' | '-' | ' '))
            .flat_map(char::to_lowercase)
            .collect()
    };
    let known: Vec<(String, &str)> = names.iter().chain(optional).map(|n| (key(n), *n)).collect();
    for (i, h) in header.iter().enumerate() {
        if h.is_empty() || known.iter().any(|(_, n)| *n == h) {
            continue;
        }
        let k = key(h);
        if let Some((_, n)) = known.iter().find(|(kn, _)| *kn == k) {
            return Err(err(
                Some(header_line),
                Some((i + 1, shown(h))),
                format!("column '{}' is not '{n}': column names are exact", shown(h)),
            ));
        }
    }
    let mut columns = Vec::with_capacity(names.len() + optional.len());
    for name in names {
        match first_of.get(name) {
            Some(&i) => columns.push(Some(i)),
            None => {
                return Err(err(
                    Some(header_line),
                    None,
                    format!(
                        "missing column '{name}' (header is '{}')",
                        shown(&header.iter().collect::<Vec<_>>().join(","))
                    ),
                ))
            }
        }
    }
    columns.extend(optional.iter().map(|name| first_of.get(name).copied()));
    let mut rows = 0u64;
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map(|p| lines_of.line_of(p.byte()));
                return Err(err(line, None, format!("malformed row: {}", csv_kind(&e))));
            }
        }
        let line = record.position().map_or(0, |p| lines_of.line_of(p.byte()));
        if record.len() == 1 && record[0].is_empty() {
            continue; // a whitespace-only line
        }
        if record.len() != header.len() {
            return Err(err(
                Some(line),
                None,
                format!(
                    "malformed row: {} fields where the header has {}",
                    record.len(),
                    header.len()
                ),
            ));
        }
        row(line, &columns, &record)?;
        rows += 1;
    }
    if rows == 0 {
        return Err(err(
            Some(header_line + 1),
            None,
            "no data rows after the header".into(),
        ));
    }
    Ok(columns)
}

fn csv_kind(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("{len} fields where the header has {expected_len}"),
        csv::ErrorKind::Utf8 { .. } => "not valid UTF-8".into(),
        other => format!("{other:?}"),
    }
}

/// A torque-reference input: `(t_s, torque_ref_pct)` rows, times strictly increasing,
/// torques within 0..=100 %.
#[derive(Debug, Clone, PartialEq)]
pub struct TorqueInput {
    /// Times, s.
    pub t_s: Vec<f64>,
    /// Torque references, % of nominal.
    pub torque_ref_pct: Vec<f64>,
}

/// Reads a `t_s,torque_ref_pct` file (other columns ignored) and checks it; returns it with
/// the line of each row and the column of `t_s` (1-based).
fn read_torque(path: &Path) -> Result<(TorqueInput, Vec<u64>, usize), InputError> {
    let data = read_columns(path, &["t_s", "torque_ref_pct"])?;
    let mut input = TorqueInput {
        t_s: Vec::with_capacity(data.len()),
        torque_ref_pct: Vec::with_capacity(data.len()),
    };
    for row in data.rows() {
        input.t_s.push(row[0]);
        input.torque_ref_pct.push(row[1]);
    }
    check_time_and_torque(path, &input, &data.lines, data.columns[0], data.columns[1])?;
    let t_column = data.columns[0];
    Ok((input, data.lines, t_column))
}

/// The rule on a torque input's rows: times strictly increasing, torques within 0..=100 %.
/// `lines` are the rows' lines, `t_column` and `u_column` the 1-based columns.
fn check_time_and_torque(
    path: &Path,
    input: &TorqueInput,
    lines: &[u64],
    t_column: usize,
    u_column: usize,
) -> Result<(), InputError> {
    for (k, (&t, &u)) in input.t_s.iter().zip(&input.torque_ref_pct).enumerate() {
        if k > 0 {
            let prev = input.t_s[k - 1];
            if t <= prev {
                return Err(InputError {
                    path: path.to_path_buf(),
                    line: Some(lines[k]),
                    column: Some((t_column, "t_s".into())),
                    message: format!(
                        "time {} s is not after the previous row's {} s",
                        Short(t),
                        Short(prev)
                    ),
                });
            }
        }
        if !(0.0..=100.0).contains(&u) {
            return Err(InputError {
                path: path.to_path_buf(),
                line: Some(lines[k]),
                column: Some((u_column, "torque_ref_pct".into())),
                message: format!("torque reference {} % is outside 0..100 %", Short(u)),
            });
        }
    }
    Ok(())
}

/// Most integration steps one run of the white-box bench may take (`simulate`, `bench-data`,
/// the white-box runs of `study`): about 5 min of f64 RK4 on this machine. An input needing
/// more is refused before any output, as a mistake in its times (or in `--step-ms`).
pub const MAX_TOTAL_STEPS: f64 = 2e9;

/// Integration steps for an interval of `dt_s` in steps no longer than `max_step_s` (at least
/// one: any interval > 0 is integrated, however short).
pub fn steps_for(dt_s: f64, max_step_s: f64) -> f64 {
    (dt_s / max_step_s).ceil().max(1.0)
}

/// Reads a `t_s,torque_ref_pct` file (other columns ignored; `t_s` strictly increasing,
/// torques within 0..=100 %) that is to be integrated in steps no longer than `max_step_ms`
/// milliseconds, and refuses it if that needs more than [`MAX_TOTAL_STEPS`] steps, naming the
/// row where the count passes the limit; `advice` ends that message.
///
/// The one rule on an input's times for every command that integrates one (`simulate`,
/// `bench-data`, `study`): any interval > 0 is accepted, one shorter than a step being
/// integrated in one step of its length.
pub fn read_input_to_integrate(
    path: &Path,
    max_step_ms: f64,
    advice: &str,
) -> Result<TorqueInput, InputError> {
    let max_step_s = max_step_ms * 1e-3;
    let (input, lines, t_column) = read_torque(path)?;
    let mut steps = 0.0;
    for (k, pair) in input.t_s.windows(2).enumerate() {
        steps += steps_for(pair[1] - pair[0], max_step_s);
        if !(steps <= MAX_TOTAL_STEPS) {
            return Err(InputError {
                path: path.to_path_buf(),
                line: Some(lines[k + 1]),
                column: Some((t_column, "t_s".into())),
                message: format!(
                    "the input needs more than {} steps of {} ms to reach this row's time {} \
                     s from {} s: {advice}",
                    Short(MAX_TOTAL_STEPS),
                    Short(max_step_ms),
                    Short(pair[1]),
                    Short(input.t_s[0])
                ),
            });
        }
    }
    Ok(input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn read_torque_input(path: &Path) -> Result<TorqueInput, InputError> {
        read_torque(path).map(|r| r.0)
    }

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    fn error_of(text: &str) -> String {
        let f = file(text);
        let e = read_torque_input(f.path()).unwrap_err();
        e.to_string().replace(&f.path().display().to_string(), "F")
    }

    #[test]
    fn good_file_with_extra_columns_and_any_order() {
        let f = file("note,torque_ref_pct,t_s\na,10,0\nb,20.5,0.5\n");
        let i = read_torque_input(f.path()).unwrap();
        assert_eq!(i.t_s, vec![0.0, 0.5]);
        assert_eq!(i.torque_ref_pct, vec![10.0, 20.5]);
    }

    #[test]
    fn bad_files_name_line_and_column() {
        assert_eq!(
            error_of(""),
            "F:1: empty file: expected a header row with t_s,torque_ref_pct"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n"),
            "F:2: no data rows after the header"
        );
        assert_eq!(
            error_of("t_s,torque\n0,1\n"),
            "F:1: missing column 'torque_ref_pct' (header is 't_s,torque')"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,10\n1,abc\n"),
            "F:3:2 (torque_ref_pct): 'abc' is not a number"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,10\n1,10\n0.5,10\n"),
            "F:4:1 (t_s): time 0.5 s is not after the previous row's 1 s"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,10\n1,10\n1,10\n"),
            "F:4:1 (t_s): time 1 s is not after the previous row's 1 s"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,101\n"),
            "F:2:2 (torque_ref_pct): torque reference 101 % is outside 0..100 %"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,NaN\n"),
            "F:2:2 (torque_ref_pct): 'NaN' is not a finite number"
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,1\n1,2,3\n"),
            "F:3: malformed row: 3 fields where the header has 2"
        );
        assert!(error_of("t_s,torque_ref_pct\n0,").contains("F:2:2 (torque_ref_pct): '' is not"));
    }

    #[test]
    fn lines_are_right_with_crlf_cr_and_blank_lines() {
        let bad = ": 'x' is not a number";
        assert_eq!(
            error_of("t_s,torque_ref_pct\r\n0,50\r\n1,60\r\n2,x\r\n"),
            format!("F:4:2 (torque_ref_pct){bad}")
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\r0,50\r1,60\r2,x\r"),
            format!("F:4:2 (torque_ref_pct){bad}")
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,50\n\n\n\n1,x\n"),
            format!("F:6:2 (torque_ref_pct){bad}")
        );
        assert_eq!(
            error_of("t_s,torque_ref_pct\n0,50\n   \n1,x\n"),
            format!("F:4:2 (torque_ref_pct){bad}")
        );
        assert!(error_of("t_s,torque_ref_pct\n0,50\n\n1,60\n\n1,70\n").starts_with("F:6:1 (t_s)"));
        assert!(error_of("\n\nt_s,u\n0,1\n").starts_with("F:3: missing column"));
        // A newline inside a quoted cell is escaped: the message stays on one line.
        let e = error_of("t_s,torque_ref_pct\n0,50\n\"1\n2\",60\n");
        assert_eq!(e.lines().count(), 1, "{e}");
        assert!(e.contains("'1\\n2' is not a number"), "{e}");
    }

    #[test]
    fn reading_stops_at_the_cap_for_files_devices_and_pipes() {
        let f = file("0123456789");
        assert_eq!(read_bounded(f.path(), 10).unwrap(), b"0123456789");
        assert_eq!(
            read_bounded(f.path(), 9).unwrap_err(),
            "larger than 9 bytes, the limit for this input"
        );
        let e = read_bounded(Path::new("/dev/zero"), 4 << 10).unwrap_err();
        assert_eq!(e, "larger than 4 KiB, the limit for this input");
        // An endless pipe: refused after cap + 1 bytes; the writer then sees a broken pipe.
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let writer = {
            let fifo = fifo.clone();
            std::thread::spawn(move || {
                let mut w = std::fs::OpenOptions::new().write(true).open(fifo).unwrap();
                let chunk = [b'1'; 4096];
                let mut sent = 0usize;
                while w.write_all(&chunk).is_ok() {
                    sent += chunk.len();
                }
                sent
            })
        };
        let e = read_bounded(&fifo, 100 << 10).unwrap_err();
        assert!(e.starts_with("larger than 100 KiB"), "{e}");
        let sent = writer.join().unwrap();
        assert!(
            sent < 1 << 20,
            "the reader stopped early: {sent} bytes sent"
        );
        assert!(read_bounded(dir.path(), 10).unwrap_err().contains("folder"));
        assert_eq!(size_text(MAX_CSV_BYTES), "256 MiB");
    }

    #[test]
    fn a_column_name_twice_is_refused() {
        assert_eq!(
            error_of("t_s,torque_ref_pct,t_s\n0,1,2\n"),
            "F:1:3 (t_s): column 't_s' appears twice in the header (columns 1 and 3)"
        );
        assert_eq!(
            error_of("\nnote,t_s,note ,torque_ref_pct\na,0,b,1\n"),
            "F:2:3 (note): column 'note' appears twice in the header (columns 1 and 3)"
        );
        // Empty names (trailing commas) are no names.
        let f = file("t_s,torque_ref_pct,,\n0,1,,\n");
        assert_eq!(read_torque_input(f.path()).unwrap().t_s, vec![0.0]);
    }

    #[test]
    fn long_text_is_cut_in_messages() {
        let e = error_of(&format!("t_s,torque_ref_pct\n0,{}\n", "9x".repeat(500)));
        assert!(
            e.ends_with(&format!(
                "'{}… (1000 characters)' is not a number",
                "9x".repeat(30)
            )),
            "{e}"
        );
        // The finite-number check shows the cell the same way (1000 nines overflow to inf).
        let e = error_of(&format!("t_s,torque_ref_pct\n0,{}\n", "9".repeat(1000)));
        assert!(
            e.ends_with("… (1000 characters)' is not a finite number"),
            "{e}"
        );
        assert_eq!(shown("a\nb"), "a\\nb");
    }

    #[test]
    fn step_count_is_limited_and_located() {
        let at_limit = file("t_s,torque_ref_pct\n0,10\n\n2e6,20\n");
        let input = read_input_to_integrate(at_limit.path(), 1.0, "advice").unwrap();
        assert_eq!(input.t_s, vec![0.0, 2e6]);
        let over = file("t_s,torque_ref_pct\n0,10\n1e6,10\n\n2000000.001,20\n3e6,20\n");
        let e = read_input_to_integrate(over.path(), 1.0, "advice")
            .unwrap_err()
            .to_string()
            .replace(&over.path().display().to_string(), "F");
        assert_eq!(
            e,
            "F:5:1 (t_s): the input needs more than 2e9 steps of 1 ms to reach this row's time \
             2000000.001 s from 0 s: advice"
        );
        // Any interval > 0 is one step at least, however short.
        let tiny = file("t_s,torque_ref_pct\n0,10\n5e-324,20\n1e-7,30\n");
        assert!(read_input_to_integrate(tiny.path(), 1.0, "").is_ok());
        assert_eq!(steps_for(5e-324, 1e-3), 1.0);
        assert_eq!(steps_for(0.0105, 1e-3), 11.0);
    }
}

/// A uniformly sampled record: times, torque and optionally one output column.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Times, s, strictly increasing.
    pub t_s: Vec<f64>,
    /// Torque references, %.
    pub torque_ref_pct: Vec<f64>,
    /// The output column, if the file has it.
    pub y: Option<Vec<f64>>,
    /// Sample period read from `t_s` (mean spacing), s.
    pub sample_period_s: f64,
}

/// Largest deviation of one time step from the median step accepted as sampling jitter (a
/// larger one means missing or extra samples).
pub const MAX_JITTER: f64 = 0.1;

/// Reads `t_s,torque_ref_pct` and, if present (or required), the column `y_column`; checks
/// that times are strictly increasing and uniformly spaced (every step within 10 % of the
/// median step). A row whose `y_column` cell is empty is not a sample of it and is left out
/// (a controller's record, `cargo xtask record`, has the flow on every other pressure row,
/// and no reading where its transmitter was in fault); the rows left must be uniformly
/// spaced, so a missing sample is refused as a gap.
pub fn read_series(path: &Path, y_column: &str, required: bool) -> Result<Series, InputError> {
    let (input, lines, _) = read_torque(path)?;
    let (names, optional): (&[&str], &[&str]) = if required {
        (&[y_column], &[])
    } else {
        (&[], &[y_column])
    };
    let mut cells: Vec<Option<f64>> = Vec::with_capacity(lines.len());
    let columns = scan_csv(path, names, optional, |line, columns, record| {
        if let Some(c) = columns[0] {
            let text = record.get(c).unwrap_or("");
            cells.push(if text.is_empty() {
                None
            } else {
                Some(finite_cell(path, line, c, y_column, text)?)
            });
        }
        Ok(())
    })?;
    let Some(y_col) = columns[0] else {
        let mean_step = check_uniform(path, &input.t_s, &lines)?;
        return Ok(Series {
            t_s: input.t_s,
            torque_ref_pct: input.torque_ref_pct,
            y: None,
            sample_period_s: mean_step,
        });
    };
    let keep: Vec<usize> = (0..cells.len()).filter(|&k| cells[k].is_some()).collect();
    let empty_cell = |k: usize| {
        InputError {
        path: path.to_path_buf(),
        line: Some(lines[k]),
        column: Some((y_col + 1, y_column.to_string())),
        message: format!(
            "empty cell where a {y_column} sample was due (a reading in fault?): the samples around it are uniformly spaced only with it"
        ),
    }
    };
    if keep.is_empty() {
        return Err(InputError {
            path: path.to_path_buf(),
            line: None,
            column: Some((y_col + 1, y_column.to_string())),
            message: format!("no row has a value of {y_column}: every cell is empty"),
        });
    }
    let pick = |v: &[f64]| keep.iter().map(|&k| v[k]).collect::<Vec<f64>>();
    let t_s = pick(&input.t_s);
    let kept_lines: Vec<u64> = keep.iter().map(|&k| lines[k]).collect();
    let mean_step = check_uniform(path, &t_s, &kept_lines).map_err(|e| {
        // The first step that breaks the rule: if a row of the file stands where the missing
        // sample was due and its cell is empty, that cell is named (a reading in fault); if
        // no row stands there, the rule's own message (a lost row).
        let med = median_step(&t_s);
        let Some(i) =
            (1..keep.len()).find(|&i| ((t_s[i] - t_s[i - 1]) - med).abs() > MAX_JITTER * med)
        else {
            return e;
        };
        let due = t_s[i - 1] + med;
        (keep[i - 1] + 1..keep[i])
            .find(|&k| (input.t_s[k] - due).abs() <= MAX_JITTER * med && cells[k].is_none())
            .map_or(e, empty_cell)
    })?;
    let left_out = cells.len() - keep.len();
    if left_out > 0 {
        eprintln!(
            "pumpbench: {}: {left_out} of {} rows have an empty {y_column} cell: left out, {} rows taken",
            path.display(),
            cells.len(),
            keep.len()
        );
    }
    Ok(Series {
        t_s,
        torque_ref_pct: pick(&input.torque_ref_pct),
        y: Some(keep.iter().filter_map(|&k| cells[k]).collect()),
        sample_period_s: mean_step,
    })
}

/// The median of the steps between successive times (0 for fewer than two).
fn median_step(t_s: &[f64]) -> f64 {
    let mut steps: Vec<f64> = t_s.windows(2).map(|p| p[1] - p[0]).collect();
    steps.sort_by(f64::total_cmp);
    steps.get(steps.len() / 2).copied().unwrap_or(0.0)
}

/// The rule on a record's times for the commands that read a uniformly sampled record
/// (`identify`, `validate`, `simulate --model narmax`, `study`, `observe`): every step within
/// [`MAX_JITTER`] of the median step. `t_s` is strictly increasing, `lines` are the rows'
/// lines. Returns the sample period: the mean step, span / (n − 1), equal to the median for
/// accepted data (0 for one row).
fn check_uniform(path: &Path, t_s: &[f64], lines: &[u64]) -> Result<f64, InputError> {
    // Gaps are judged against the median step (one gap or extra sample does not move it);
    // the period reported is the mean step, span / (n − 1), equal to it for accepted data.
    let ts = median_step(t_s);
    let n = t_s.len();
    let mean_step = if n > 1 {
        (t_s[n - 1] - t_s[0]) / (n - 1) as f64
    } else {
        0.0
    };
    let bad = |line: u64, message: String| InputError {
        path: path.to_path_buf(),
        line: Some(line),
        column: None,
        message,
    };
    for (pair, &line) in t_s.windows(2).zip(&lines[1..]) {
        let d = pair[1] - pair[0];
        if !((d - ts).abs() <= MAX_JITTER * ts) {
            return Err(bad(
                line,
                format!(
                    "not uniformly sampled: step {} s where the median step is {} s",
                    Short(d),
                    Short(ts)
                ),
            ));
        }
    }
    if !mean_step.is_finite() {
        return Err(bad(
            lines[n - 1],
            format!(
                "the times span {} s to {} s: more than an f64 holds",
                Short(t_s[0]),
                Short(t_s[n - 1])
            ),
        ));
    }
    Ok(mean_step)
}

/// A uniformly sampled record whose other cells may be empty: `observe`'s input.
#[derive(Debug, Clone, PartialEq)]
pub struct GappyRecord {
    /// Times, s (strictly increasing, uniformly sampled) and torque references, % (0..=100):
    /// in every row.
    pub input: TorqueInput,
    /// The columns asked for besides those two, in the order asked: `None` for an optional
    /// column the header lacks, else each row's cell (`None` where it is empty).
    pub columns: Vec<Option<Vec<Option<f64>>>>,
    /// 1-based line of each row.
    pub lines: Vec<u64>,
    /// 1-based column of `t_s`.
    pub t_column: usize,
    /// Sample period (mean step), s.
    pub sample_period_s: f64,
}

/// Reads a uniformly sampled record (the rule of [`read_series`]) with `t_s` and
/// `torque_ref_pct` in every row, as [`read_torque`] checks them, and the columns `names`
/// (required in the header) and `optional` (read if the header has them), whose cells may be
/// empty (a missing value). A non-empty cell must parse as a number; `NaN`, `inf` and numbers
/// beyond f64 (`1e999`) are kept as NaN or ±inf, for the caller to judge.
pub fn read_gappy_series(
    path: &Path,
    names: &[&str],
    optional: &[&str],
) -> Result<GappyRecord, InputError> {
    let mut required = vec!["t_s", "torque_ref_pct"];
    required.extend_from_slice(names);
    let all: Vec<&str> = required.iter().chain(optional).copied().collect();
    let mut input = TorqueInput {
        t_s: Vec::new(),
        torque_ref_pct: Vec::new(),
    };
    let mut cells: Vec<Vec<Option<f64>>> = vec![Vec::new(); all.len() - 2];
    let mut lines = Vec::new();
    let columns = scan_csv(path, &required, optional, |line, columns, record| {
        let err = |c: usize, name: &str, message: String| InputError {
            path: path.to_path_buf(),
            line: Some(line),
            column: Some((c + 1, name.to_string())),
            message,
        };
        for (k, (column, name)) in columns.iter().zip(&all).enumerate() {
            let Some(c) = *column else { continue };
            let text = record.get(c).unwrap_or("");
            if k < 2 {
                if text.is_empty() {
                    return Err(err(
                        c,
                        name,
                        format!("empty cell: {name} is needed on every row"),
                    ));
                }
                let v = finite_cell(path, line, c, name, text)?;
                [&mut input.t_s, &mut input.torque_ref_pct][k].push(v);
            } else if text.is_empty() {
                cells[k - 2].push(None);
            } else {
                let v: f64 = text.parse().map_err(|_| {
                    err(
                        c,
                        name,
                        format!(
                            "'{}' is not a number (an empty cell is a missing value)",
                            shown(text)
                        ),
                    )
                })?;
                cells[k - 2].push(Some(v));
            }
        }
        lines.push(line);
        Ok(())
    })?;
    let (t_column, u_column) = match columns[..2] {
        [Some(t), Some(u)] => (t + 1, u + 1),
        _ => unreachable!("required columns are found or refused"),
    };
    check_time_and_torque(path, &input, &lines, t_column, u_column)?;
    let sample_period_s = check_uniform(path, &input.t_s, &lines)?;
    let columns = columns[2..]
        .iter()
        .zip(cells)
        .map(|(c, v)| c.map(|_| v))
        .collect();
    Ok(GappyRecord {
        input,
        columns,
        lines,
        t_column,
        sample_period_s,
    })
}

#[cfg(test)]
mod series_tests {
    use super::*;
    use std::io::Write;

    fn read(text: &str, y: &str, required: bool) -> Result<Series, String> {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        read_series(f.path(), y, required)
            .map_err(|e| e.to_string().replace(&f.path().display().to_string(), "F"))
    }

    /// A controller's record: the flow on every other row, the pressure on every row.
    const RECORD: &str = "t_s,torque_ref_pct,pressure_mca,flow_lps\n0.000,10,1.5,5\n0.050,20,1.6,\n0.100,30,1.7,6\n0.150,40,1.8,\n0.200,50,1.9,7\n0.250,60,2.0,\n0.300,70,2.1,8\n";

    #[test]
    fn rows_with_an_empty_target_cell_are_not_samples() {
        let q = read(RECORD, "flow_lps", true).unwrap();
        assert_eq!(q.t_s, [0.0, 0.1, 0.2, 0.3]);
        assert_eq!(q.torque_ref_pct, [10.0, 30.0, 50.0, 70.0]);
        assert_eq!(q.y, Some(vec![5.0, 6.0, 7.0, 8.0]));
        assert!((q.sample_period_s - 0.1).abs() < 1e-12);
        let p = read(RECORD, "pressure_mca", true).unwrap();
        assert_eq!(p.t_s.len(), 7);
        assert!((p.sample_period_s - 0.05).abs() < 1e-12);
        // An optional target column that is there is read the same way.
        assert_eq!(read(RECORD, "flow_lps", false).unwrap(), q);
        assert_eq!(read(RECORD, "speed_rpm", false).unwrap().y, None);
    }

    #[test]
    fn a_lost_sample_is_a_gap_and_an_empty_column_is_refused() {
        // The row at 0.100 s lost: a 0.2 s step among 0.1 s ones for the flow.
        let lost = RECORD.replace("0.100,30,1.7,6\n", "");
        let e = read(&lost, "flow_lps", true).unwrap_err();
        assert!(e.contains("not uniformly sampled"), "{e}");
        // The pressure in fault at 0.100 s (an empty cell) is a gap in the pressure, named.
        let fault = RECORD.replace("0.100,30,1.7,6", "0.100,30,,6");
        let e = read(&fault, "pressure_mca", true).unwrap_err();
        assert!(
            e.starts_with("F:4:3 (pressure_mca): empty cell where a pressure_mca sample was due"),
            "{e}"
        );
        // The flow in fault on one of its samples (every other row of 41): named too.
        let long: String = (0..41)
            .map(|k| {
                let q = if k % 2 == 0 && k != 20 { "5" } else { "" };
                format!("{:.3},10,1.5,{q}\n", f64::from(k) * 0.05)
            })
            .fold(
                "t_s,torque_ref_pct,pressure_mca,flow_lps\n".into(),
                |s, l| s + &l,
            );
        let e = read(&long, "flow_lps", true).unwrap_err();
        assert!(e.starts_with("F:22:4 (flow_lps): empty cell where"), "{e}");
        // A row lost before an empty cell further on: the lost row is what is reported.
        let both = RECORD
            .replace("0.050,20,1.6,\n", "")
            .replace("0.250,60,2.0,", "0.250,60,,");
        let e = read(&both, "pressure_mca", true).unwrap_err();
        assert!(
            e.contains("not uniformly sampled") && !e.contains("empty"),
            "{e}"
        );
        // Empty cells at the start or the end only: the rows left are taken.
        let ends = RECORD
            .replace("0.000,10,1.5,5", "0.000,10,,5")
            .replace("0.300,70,2.1,8", "0.300,70,,8");
        assert_eq!(read(&ends, "pressure_mca", true).unwrap().t_s.len(), 5);
        let none = "t_s,torque_ref_pct,flow_lps\n0,1,\n1,2,\n";
        let e = read(none, "flow_lps", true).unwrap_err();
        assert!(e.contains("no row has a value of flow_lps"), "{e}");
        let bad = RECORD.replace(",1.8,", ",x,");
        assert!(read(&bad, "pressure_mca", true)
            .unwrap_err()
            .contains("'x' is not a number"));
    }
}

#[cfg(test)]
mod gappy_tests {
    use super::*;
    use std::io::Write;

    fn read(text: &str) -> Result<GappyRecord, String> {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        read_gappy_series(f.path(), &["p"], &["q", "absent"])
            .map_err(|e| e.to_string().replace(&f.path().display().to_string(), "F"))
    }

    #[test]
    fn empty_cells_are_missing_and_non_finite_text_is_kept() {
        let r = read("q,t_s,p,torque_ref_pct\n1,0,,10\n,0.05,NaN,20\n1e999,0.1,-inf,30\n").unwrap();
        assert_eq!(r.input.t_s, [0.0, 0.05, 0.1]);
        assert_eq!(r.input.torque_ref_pct, [10.0, 20.0, 30.0]);
        assert_eq!(r.lines, [2, 3, 4]);
        assert_eq!(r.t_column, 2);
        assert!((r.sample_period_s - 0.05).abs() < 1e-12);
        let p = r.columns[0].as_ref().unwrap();
        assert!(p[0].is_none() && p[1].is_some_and(f64::is_nan) && p[2] == Some(f64::NEG_INFINITY));
        assert_eq!(
            r.columns[1],
            Some(vec![Some(1.0), None, Some(f64::INFINITY)])
        );
        assert_eq!(r.columns[2], None);
    }

    #[test]
    fn the_times_and_torques_follow_the_series_rules() {
        for (text, expected) in [
            (
                "t_s,torque_ref_pct,p\n0,10,1\n,10,1\n",
                "F:3:1 (t_s): empty cell: t_s is needed on every row",
            ),
            (
                "t_s,torque_ref_pct,p\n0,10,1\n0.05,x,1\n",
                "F:3:2 (torque_ref_pct): 'x' is not a number",
            ),
            (
                "t_s,torque_ref_pct,p\n0,10,1\n0.05,10,x\n",
                "F:3:3 (p): 'x' is not a number (an empty cell is a missing value)",
            ),
            (
                "t_s,torque_ref_pct,p\n0,10,1\n0.05,101,1\n",
                "F:3:2 (torque_ref_pct): torque reference 101 % is outside 0..100 %",
            ),
            (
                "t_s,torque_ref_pct,p\n0,10,1\n0,10,1\n",
                "F:3:1 (t_s): time 0 s is not after the previous row's 0 s",
            ),
            (
                "t_s,torque_ref_pct,p\n0,10,1\n1,10,1\n1.5,10,1\n",
                "F:4: not uniformly sampled: step 0.5 s where the median step is 1 s",
            ),
            (
                "t_s,torque_ref_pct\n0,10\n",
                "F:1: missing column 'p' (header is 't_s,torque_ref_pct')",
            ),
            (
                "t_s,torque_ref_pct,p,q,q\n0,10,1,1,1\n",
                "F:1:5 (q): column 'q' appears twice in the header (columns 4 and 5)",
            ),
            (
                "t_s,torque_ref_pct,p\n",
                "F:2: no data rows after the header",
            ),
        ] {
            assert_eq!(read(text).unwrap_err(), expected, "{text}");
        }
    }
}
