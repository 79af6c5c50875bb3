//! What every task uses: cargo and the workspace's paths, a step run with its time, and the
//! `key=value` fields of the firmware's and the bench's log lines.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// The MCU's target triple (both boards, mcu-bench).
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// A task's result: its error is the message `cargo xtask` prints.
pub type Result<T = ()> = std::result::Result<T, String>;

/// The cargo that runs xtask (`CARGO`), else `cargo` on the PATH, with the MCU images' paths
/// of crates.io sources trimmed ([`trimmed_registry_paths`]).
pub fn cargo() -> Command {
    let mut c = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    c.args(mcu_rustflags(&[]));
    c
}

/// `--config` and its value: the MCU target's flags `extra` and the paths trimmed
/// ([`trimmed_registry_paths`]), in one array. Cargo joins the array with the one in
/// `.cargo/config.toml`, but of two `--config` values for the same key only the last counts:
/// a board that adds flags (the Nucleo's CPU) passes them here, after [`cargo`]'s. Nothing
/// when there is nothing to add.
pub fn mcu_rustflags(extra: &[&str]) -> Vec<String> {
    let mut flags: Vec<String> = extra.iter().map(|f| format!("{f:?}")).collect();
    flags.extend(trimmed_registry_paths().unwrap_or_default());
    if flags.is_empty() {
        return vec![];
    }
    vec![
        "--config".to_string(),
        format!("target.{TARGET}.rustflags=[{}]", flags.join(", ")),
    ]
}

/// The `rustc` flags (TOML strings, quoted) that map each of cargo's registry source
/// directories, `$CARGO_HOME/registry/src/<index>/`, to nothing in the MCU target's file
/// paths (`rustc --remap-path-prefix`): a panic location in a dependency then reads
/// `rmodbus-0.13.0/src/lib.rs`, not the builder's home directory. The images are the same
/// bytes whoever builds them, and ≈ 0.4 KB smaller (each path was ≈ 60 bytes of flash);
/// [`mcu_rustflags`] puts them in the target's flags. `None`, with a warning, if none is
/// found or one is not UTF-8 (the images then carry the full paths, ≈ 0.4 KB more).
pub fn trimmed_registry_paths() -> Option<Vec<String>> {
    static CONFIG: std::sync::OnceLock<Option<Vec<String>>> = std::sync::OnceLock::new();
    CONFIG
        .get_or_init(|| {
            let dirs = registry_src_dirs();
            if dirs.is_empty() || dirs.iter().any(|d| d.to_str().is_none()) {
                eprintln!(
                    "warning: no crates.io source directory found, or one not UTF-8 ($CARGO_HOME/registry/src): the MCU images keep their dependencies' full paths (≈ 0.4 KB of flash)"
                );
                return None;
            }
            let flags: Vec<String> = dirs
                .iter()
                .filter_map(|d| {
                    // JSON's string escapes are TOML's.
                    serde_json::to_string(&format!("--remap-path-prefix={}/=", d.to_str()?)).ok()
                })
                .collect();
            Some(flags)
        })
        .clone()
}

/// The directories under `$CARGO_HOME/registry/src` (cargo's home: `CARGO_HOME`, else
/// `$HOME/.cargo`); empty if there is none.
fn registry_src_dirs() -> Vec<PathBuf> {
    // Absolute, as cargo makes a relative `CARGO_HOME` (and as it gives rustc the paths).
    let Some(home) = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cargo")))
        .and_then(|h| std::path::absolute(h).ok())
    else {
        return vec![];
    };
    let Ok(entries) = std::fs::read_dir(home.join("registry").join("src")) else {
        return vec![];
    };
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    dirs
}

/// The workspace's root directory.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// Runs `cmd` at the workspace root as the step `what`, printing its name and its time (s);
/// an error if it cannot start or exits non-zero.
pub fn run(what: &str, cmd: &mut Command) -> Result {
    let start = Instant::now();
    eprintln!("==> {what}");
    let status = cmd
        .current_dir(root())
        .status()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    eprintln!("    {what}: {:.1} s", start.elapsed().as_secs_f64());
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} failed ({status})"))
    }
}

/// Cargo's target directory (`CARGO_TARGET_DIR`, else `target/` at the root).
pub fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

/// The value of the first whitespace-separated word `key=value` of `line` (an error naming
/// the line if there is none).
pub fn field<'a>(line: &'a str, key: &str) -> Result<&'a str> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .ok_or_else(|| format!("no '{key}=' in line: {line}"))
}

/// [`field`] parsed as a `T` (an error naming the line if it does not parse).
pub fn num<T: std::str::FromStr>(line: &str, key: &str) -> Result<T> {
    field(line, key)?
        .parse()
        .map_err(|_| format!("bad '{key}' in line: {line}"))
}

/// A command line's words (tests: `args("--seconds 5 --output r")`).
#[cfg(test)]
pub fn args(s: &str) -> Vec<String> {
    s.split_whitespace().map(str::to_string).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_of_a_line() {
        let line = "row name=narmax_f32 baseline=x calls=400 ticks=12345 max=7";
        assert_eq!(field(line, "name"), Ok("narmax_f32"));
        assert_eq!(field(line, "calls"), Ok("400"));
        assert_eq!(num::<u64>(line, "ticks"), Ok(12345));
        // A key is a whole word's prefix up to '=': `max` is not `max_name`, `base` is not
        // `baseline`.
        assert_eq!(field("max_name=a max=3", "max"), Ok("3"));
        assert!(field(line, "base").is_err());
        assert!(field(line, "row").is_err());
        assert_eq!(
            field(line, "seed"),
            Err(format!("no 'seed=' in line: {line}"))
        );
        assert_eq!(
            num::<u8>(line, "ticks"),
            Err(format!("bad 'ticks' in line: {line}"))
        );
        assert_eq!(field("a= b=1", "a"), Ok(""));
    }

    #[test]
    fn paths() {
        assert!(root().join("xtask").join("Cargo.toml").is_file());
        assert!(root().join("Cargo.toml").is_file());
    }

    /// The trimmed directories hold the MCU's dependencies (rmodbus among them), and the
    /// `--config` value names each as a TOML string.
    #[test]
    fn registry_paths_are_trimmed() {
        let dirs = registry_src_dirs();
        assert!(
            dirs.iter().any(|d| std::fs::read_dir(d).unwrap().any(|e| e
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("rmodbus-"))),
            "{dirs:?}"
        );
        let flags = trimmed_registry_paths().unwrap();
        for d in &dirs {
            let flag = format!("\"--remap-path-prefix={}/=\"", d.display());
            assert!(flags.contains(&flag), "{flags:?}");
        }
        // One array with a board's own flags: cargo keeps only the last `--config` of a key.
        let config = mcu_rustflags(&["-C", "target-cpu=cortex-m4"]);
        assert_eq!(config[0], "--config");
        assert!(config[1].starts_with(
            "target.thumbv7em-none-eabihf.rustflags=[\"-C\", \"target-cpu=cortex-m4\", \"--remap-path-prefix="
        ));
    }
}
