//! Reading bench CSV files: every error names the file, the line and the column.

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

/// A CSV with a header row, from which some columns are read as finite numbers.
pub struct NumericColumns {
    /// One row per data record: the requested columns, in the requested order.
    pub rows: Vec<Vec<f64>>,
    /// 1-based line of each row (for later error messages).
    pub lines: Vec<u64>,
    /// 1-based column index of each requested column.
    pub columns: Vec<usize>,
}

/// Start offsets of the lines of `bytes` (terminated by `\n`, `\r\n` or a lone `\r`).
///
/// The csv crate's own line numbers are wrong after CRLF endings and blank lines
/// (rust-csv #395, #208); its byte offsets are right, so lines are counted here.
fn line_starts(bytes: &[u8]) -> Vec<usize> {
    let mut starts = vec![0];
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'\n' => starts.push(i + 1),
            b'\r' if bytes.get(i + 1) != Some(&b'\n') => starts.push(i + 1),
            _ => {}
        }
        i += 1;
    }
    starts
}

/// 1-based line of the record that the csv crate says starts at byte `offset`: its offset
/// can point at the end of the previous line (the `\n` of a CRLF) or at skipped blank lines,
/// so line terminators are stepped over first.
fn line_of(bytes: &[u8], starts: &[usize], offset: u64) -> u64 {
    let mut at = offset as usize;
    while at < bytes.len() && matches!(bytes[at], b'\r' | b'\n') {
        at += 1;
    }
    starts.partition_point(|&s| s <= at) as u64
}

/// A cell or header as shown in a one-line message: control characters escaped.
fn shown(text: &str) -> String {
    text.escape_debug().to_string()
}

/// Reads `path`, requiring the named columns (any order, other columns ignored) and parsing
/// every cell of them as a finite number. Blank and whitespace-only lines are skipped.
pub fn read_columns(path: &Path, names: &[&str]) -> Result<NumericColumns, InputError> {
    let err = |line: Option<u64>, column: Option<(usize, String)>, message: String| InputError {
        path: path.to_path_buf(),
        line,
        column,
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| err(None, None, format!("cannot open: {e}")))?;
    let starts = line_starts(&bytes);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(bytes.as_slice());
    let header = reader
        .headers()
        .map_err(|e| err(Some(1), None, format!("cannot read the header: {e}")))?
        .clone();
    let header_line = header
        .position()
        .map_or(1, |p| line_of(&bytes, &starts, p.byte()));
    if header.is_empty() || header.iter().all(|h| h.is_empty()) {
        return Err(err(
            Some(header_line),
            None,
            format!("empty file: expected a header row with {}", names.join(",")),
        ));
    }
    let mut columns = Vec::with_capacity(names.len());
    for name in names {
        match header.iter().position(|h| h == *name) {
            Some(i) => columns.push(i),
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
    let mut rows = Vec::new();
    let mut lines = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map(|p| line_of(&bytes, &starts, p.byte()));
                return Err(err(line, None, format!("malformed row: {}", csv_kind(&e))));
            }
        }
        let line = record
            .position()
            .map_or(0, |p| line_of(&bytes, &starts, p.byte()));
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
        let mut row = Vec::with_capacity(columns.len());
        for (&c, name) in columns.iter().zip(names) {
            let cell = record.get(c).unwrap_or("");
            let value: f64 = cell.parse().map_err(|_| {
                err(
                    Some(line),
                    Some((c + 1, name.to_string())),
                    format!("'{}' is not a number", shown(cell)),
                )
            })?;
            if !value.is_finite() {
                return Err(err(
                    Some(line),
                    Some((c + 1, name.to_string())),
                    format!("'{}' is not a finite number", shown(cell)),
                ));
            }
            row.push(value);
        }
        rows.push(row);
        lines.push(line);
    }
    if rows.is_empty() {
        return Err(err(
            Some(header_line + 1),
            None,
            "no data rows after the header".into(),
        ));
    }
    Ok(NumericColumns {
        rows,
        lines,
        columns: columns.iter().map(|c| c + 1).collect(),
    })
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

/// Reads a `t_s,torque_ref_pct` file (other columns ignored) and checks it.
pub fn read_torque_input(path: &Path) -> Result<TorqueInput, InputError> {
    let data = read_columns(path, &["t_s", "torque_ref_pct"])?;
    let mut input = TorqueInput {
        t_s: Vec::with_capacity(data.rows.len()),
        torque_ref_pct: Vec::with_capacity(data.rows.len()),
    };
    for (row, &line) in data.rows.iter().zip(&data.lines) {
        let (t, u) = (row[0], row[1]);
        if let Some(&prev) = input.t_s.last() {
            if t <= prev {
                return Err(InputError {
                    path: path.to_path_buf(),
                    line: Some(line),
                    column: Some((data.columns[0], "t_s".into())),
                    message: format!("time {t} s is not after the previous row's {prev} s"),
                });
            }
        }
        if !(0.0..=100.0).contains(&u) {
            return Err(InputError {
                path: path.to_path_buf(),
                line: Some(line),
                column: Some((data.columns[1], "torque_ref_pct".into())),
                message: format!("torque reference {u} % is outside 0..100 %"),
            });
        }
        input.t_s.push(t);
        input.torque_ref_pct.push(u);
    }
    Ok(input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

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
/// median step).
pub fn read_series(path: &Path, y_column: &str, required: bool) -> Result<Series, InputError> {
    let input = read_torque_input(path)?;
    let with_y = match read_columns(path, &["t_s", y_column]) {
        Ok(d) => Some(d),
        Err(e) if !required && e.message.starts_with("missing column") => None,
        Err(e) => return Err(e),
    };
    let y = with_y
        .as_ref()
        .map(|d| d.rows.iter().map(|r| r[1]).collect());
    // Gaps are judged against the median step (one gap or extra sample does not move it);
    // the period reported is the mean step, span / (n − 1), equal to it for accepted data.
    let mut steps: Vec<f64> = input.t_s.windows(2).map(|p| p[1] - p[0]).collect();
    steps.sort_by(f64::total_cmp);
    let ts = steps.get(steps.len() / 2).copied().unwrap_or(0.0);
    let n = input.t_s.len();
    let mean_step = if n > 1 {
        (input.t_s[n - 1] - input.t_s[0]) / (n - 1) as f64
    } else {
        0.0
    };
    let lines = read_columns(path, &["t_s"])?.lines;
    for (pair, &line) in input.t_s.windows(2).zip(&lines[1..]) {
        let d = pair[1] - pair[0];
        if (d - ts).abs() > MAX_JITTER * ts {
            return Err(InputError {
                path: path.to_path_buf(),
                line: Some(line),
                column: None,
                message: format!(
                    "not uniformly sampled: step {d} s where the median step is {ts} s"
                ),
            });
        }
    }
    Ok(Series {
        t_s: input.t_s,
        torque_ref_pct: input.torque_ref_pct,
        y,
        sample_period_s: mean_step,
    })
}
