//! What every `pumpbench` CLI test does: run the binary, write an input file, check a refusal.
#![allow(dead_code)] // each test file uses its own part of it

use std::path::Path;
use std::process::{Command, Output};

/// Runs `pumpbench` with `args` in `dir` (the test's working folder if `None`).
pub fn pumpbench_in(dir: Option<&Path>, args: &[&str]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pumpbench"));
    if let Some(d) = dir {
        c.current_dir(d);
    }
    c.args(args).output().expect("run pumpbench")
}

/// Runs `pumpbench` with `args`.
pub fn pumpbench(args: &[&str]) -> Output {
    pumpbench_in(None, args)
}

/// Writes `text` to `dir/name`; returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// Exit code 2, nothing on stdout, one line on stderr containing every `expected`; returns it.
pub fn refused(out: &Output, expected: &[&str], what: &str) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{what}: {err}");
    assert_eq!(err.lines().count(), 1, "{what}: one line: {err}");
    assert!(out.stdout.is_empty(), "{what}: no output on stdout");
    for e in expected {
        assert!(err.contains(e), "{what}: expected '{e}' in: {err}");
    }
    err
}

/// Asserts that `out` is a success; returns its stdout.
pub fn ok(out: &Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

/// A numeric CSV: its header and rows.
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows of numbers.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Parses `text` (a header line, then rows of numbers).
    pub fn parse(text: &str) -> Table {
        let mut lines = text.lines();
        let header = lines.next().unwrap().split(',').map(String::from).collect();
        let rows = lines
            .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
            .collect();
        Table { header, rows }
    }

    /// The column `name`.
    pub fn col(&self, name: &str) -> Vec<f64> {
        let i = self
            .header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.header));
        self.rows.iter().map(|r| r[i]).collect()
    }
}
