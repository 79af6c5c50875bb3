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
