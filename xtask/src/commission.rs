//! `cargo xtask commission-check`: the README's commissioning procedure, end to end on QEMU,
//! on a bench whose curves are not those the shipped models were trained on (pump head
//! −5 %, load torque +5 %: `head=950 torque=1050`):
//!
//! 1. `cargo xtask record --seconds 600` on that bench (seed 5);
//! 2. `pumpbench identify` of both models on the record, the shipped models' sizes;
//! 3. `pumpbench export` of both into a copy of the workspace's `models/src/`;
//! 4. the QEMU firmware rebuilt from that copy (its own target directory);
//! 5. the shipped and the rebuilt firmware run 120 s of the excitation with another seed (6)
//!    on the same bench: the RMS of their NARMAX residuals (measured − one-step prediction,
//!    the log's once-a-second `res_nx_p` and `res_nx_q`, after the first 10 s) must drop for
//!    both models.

use crate::board::{ensure_flip_link, firmware_elf, Board};
use crate::qemu::qemu_log;
use crate::record::{record_qemu, RecordOptions};
use crate::util::{cargo, num, root, run, target_dir, Result, TARGET};
use std::path::{Path, PathBuf};

/// The record's length, s (the README's procedure).
const RECORD_S: u32 = 600;
/// The comparison runs' length, s.
const RUN_S: u32 = 120;
/// Log lines left out at the start of a comparison run (the start from rest), s.
const SKIP_S: u32 = 10;
/// The bench's curves, per mille of the paper's (head, torque).
const CURVES: (u32, u32) = (950, 1050);

/// The whole check; the report of it.
pub fn commission_check() -> Result<String> {
    let dir = target_dir().join("commission");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let shipped = firmware_elf(Board::Qemu);
    crate::board::build_firmware(Board::Qemu)?;

    // 1. The record.
    let rec = dir.join("rec.csv");
    let o = RecordOptions {
        seconds: RECORD_S,
        output: rec.clone(),
        seed: 5,
        narmax: "f32".into(),
        head: CURVES.0,
        torque: CURVES.1,
        nucleo: false,
    };
    let mut report = format!("{}\n", record_qemu(&shipped, &o)?);

    // 2. Identification, 3. export into a copy of the workspace.
    let ws = dir.join("ws");
    copy_workspace(&ws)?;
    for (target, sizes) in [("pressure", ["6", "6", "7"]), ("flow", ["7", "7", "6"])] {
        let model = dir.join(format!("{target}.json"));
        pumpbench(
            &format!("identify {target} on the record"),
            &[
                "identify".as_ref(),
                "--data".as_ref(),
                rec.as_os_str(),
                "--target".as_ref(),
                target.as_ref(),
                "--na".as_ref(),
                sizes[0].as_ref(),
                "--nb".as_ref(),
                sizes[1].as_ref(),
                "--hidden".as_ref(),
                sizes[2].as_ref(),
                "--output".as_ref(),
                model.as_os_str(),
            ],
        )?;
        let rs = ws.join("models").join("src").join(format!("{target}.rs"));
        pumpbench(
            &format!("export {target} into the copy's models/src"),
            &[
                "export".as_ref(),
                "--weights".as_ref(),
                model.as_os_str(),
                "--output".as_ref(),
                rs.as_os_str(),
            ],
        )?;
    }

    // 4. The firmware rebuilt from the copy.
    ensure_flip_link()?;
    let copy_target = dir.join("target");
    run(
        "firmware build for qemu from the copy with the new models",
        cargo()
            .args(["build", "-p", "board-qemu", "--bin", "pump-qemu"])
            .args(["--profile", "firmware", "--target", TARGET])
            .arg("--manifest-path")
            .arg(ws.join("Cargo.toml"))
            .env("CARGO_TARGET_DIR", &copy_target)
            .env("DEFMT_LOG", "info"),
    )
    .map_err(|e| format!("{e} (the copy: {})", ws.display()))?;
    let rebuilt = copy_target
        .join(TARGET)
        .join("firmware")
        .join(Board::Qemu.binary());

    // 5. Both on the bench, another excitation.
    let args = vec![
        "mode=2".to_string(),
        "seed=6".into(),
        format!("head={}", CURVES.0),
        format!("torque={}", CURVES.1),
        format!("run_ms={}", RUN_S * 1000 + 1),
    ];
    let before = residuals_rms(&qemu_log(&shipped, &args)?)?;
    let after = residuals_rms(&qemu_log(&rebuilt, &args)?)?;
    for (k, name, unit) in [(0, "pressure", "mca"), (1, "flow", "l/s")] {
        report.push_str(&format!(
            "commissioning: NARMAX {name} residual RMS on the bench (head {} ‰, torque {} ‰), {} s of another excitation: shipped {:.5} {unit}, re-identified {:.5} {unit} ({:.2}×)\n",
            CURVES.0,
            CURVES.1,
            RUN_S - SKIP_S,
            before[k],
            after[k],
            after[k] / before[k]
        ));
        // Also fails if either is NaN.
        if after[k].partial_cmp(&before[k]) != Some(std::cmp::Ordering::Less) {
            return Err(format!(
                "{report}commissioning: the re-identified {name} model's residuals did not drop"
            ));
        }
    }
    let _ = std::fs::remove_dir_all(&ws);
    Ok(report)
}

/// RMS of the log's NARMAX residuals (`res_nx_p`, `res_nx_q`) after [`SKIP_S`].
fn residuals_rms(log: &str) -> Result<[f64; 2]> {
    let mut sums = [0.0f64; 2];
    let mut n = 0u32;
    for line in log.lines().filter(|l| l.starts_with("t_s=")) {
        if num::<u32>(line, "t_s")? < SKIP_S {
            continue;
        }
        for (s, key) in sums.iter_mut().zip(["res_nx_p", "res_nx_q"]) {
            *s += num::<f64>(line, key)?.powi(2);
        }
        n += 1;
    }
    if n == 0 {
        return Err(format!("no log line after {SKIP_S} s:\n{log}"));
    }
    Ok(sums.map(|s| (s / f64::from(n)).sqrt()))
}

/// `pumpbench ARGS` (the workspace's, dev profile) as the step `what`.
fn pumpbench(what: &str, args: &[&std::ffi::OsStr]) -> Result {
    run(
        what,
        cargo()
            .args(["run", "-q", "-p", "pumpbench", "--"])
            .args(args),
    )
}

/// The workspace's files (git's tracked and untracked-but-not-ignored ones, as they are on
/// disk) copied to `to`.
fn copy_workspace(to: &Path) -> Result {
    let out = std::process::Command::new("git")
        .args([
            "ls-files",
            "-z",
            "--cached",
            "--others",
            "--exclude-standard",
        ])
        .current_dir(root())
        .output()
        .map_err(|e| format!("git ls-files: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "git ls-files: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let mut n = 0;
    for name in out.stdout.split(|&b| b == 0).filter(|n| !n.is_empty()) {
        let rel = PathBuf::from(String::from_utf8_lossy(name).into_owned());
        let from = root().join(&rel);
        if !from.is_file() {
            continue; // deleted on disk, or a submodule
        }
        let dest = to.join(&rel);
        if let Some(parent) = dest.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        std::fs::copy(&from, &dest).map_err(|e| format!("{}: {e}", from.display()))?;
        n += 1;
    }
    if n == 0 {
        return Err("git ls-files listed no file".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn residuals_after_the_start() {
        let log = "firmware: x\n\
                   t_s=0 res_nx_p=100 res_nx_q=100\n\
                   margin: steps=1\n\
                   t_s=10 res_nx_p=0.3 res_nx_q=-4\n\
                   t_s=11 res_nx_p=-0.4 res_nx_q=0\n";
        let r = residuals_rms(log).unwrap();
        assert!((r[0] - (0.125f64).sqrt()).abs() < 1e-12, "{r:?}");
        assert!((r[1] - 8f64.sqrt()).abs() < 1e-12, "{r:?}");
        assert!(residuals_rms("t_s=1 res_nx_p=1 res_nx_q=1\n").is_err());
        assert!(residuals_rms("t_s=12 res_nx_p=x res_nx_q=1\n").is_err());
    }
}
