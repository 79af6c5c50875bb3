//! `pumpbench study`: the demo run end to end (data, models, Table 1, figures) and its errors.

mod common;
use common::pumpbench;
use std::path::Path;

/// The four MAPE cells of a Table 1 row, the pressure static one split into all / without the
/// lowest-torque point: `[p_static, p_static_without_lowest, p_dynamic, q_static, q_dynamic]`.
fn row_numbers(table: &str, name: &str) -> [f64; 5] {
    let line = table
        .lines()
        .find(|l| l.starts_with(&format!("| {name} |")))
        .unwrap_or_else(|| panic!("no row '{name}' in\n{table}"));
    let cells: Vec<&str> = line
        .trim_matches('|')
        .split('|')
        .map(str::trim)
        .skip(1)
        .collect();
    assert_eq!(cells.len(), 4, "{line}");
    let num = |s: &str| -> f64 {
        s.parse()
            .unwrap_or_else(|_| panic!("'{s}' is not a number in '{line}'"))
    };
    let (all, without) = cells[0]
        .split_once(" / ")
        .unwrap_or_else(|| panic!("pressure static is not 'X / Y' in '{line}'"));
    [
        num(all),
        num(without),
        num(cells[1]),
        num(cells[2]),
        num(cells[3]),
    ]
}

fn check_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{} is not a PNG",
        path.display()
    );
    assert!(
        bytes.len() > 20_000,
        "{}: only {} bytes",
        path.display(),
        bytes.len()
    );
}

#[test]
fn demo_study_writes_table_models_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let out_s = out.display().to_string();
    let run = pumpbench(&["study", "--demo", "--out", &out_s]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");

    let table = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&run.stdout),
        table,
        "stdout is the table"
    );
    let narmax = row_numbers(&table, "Black-box (NARMAX)");
    let whitebox = row_numbers(&table, "White-box");
    for v in narmax.iter().chain(&whitebox) {
        assert!(v.is_finite() && *v >= 0.0, "{table}");
    }
    // The NARMAX models do at least as well as the paper's on their validation records.
    assert!(narmax[2] <= 1.22, "pressure MAPE_d {}\n{table}", narmax[2]);
    assert!(narmax[4] <= 1.10, "flow MAPE_d {}\n{table}", narmax[4]);
    // The paper's own numbers and the data used are there.
    assert!(table.contains("| Black-box (NARMAX) | 7.67 / 1.38 | 1.22 | 2.60 | 1.10 |"));
    assert!(table.contains("| White-box | 4.50 | 10.47 | 4.75 | 3.5 |"));
    assert!(table.contains("SYNTHETIC") && table.contains("pumpbench bench-data"));

    for name in [
        "fig4_narmax_validation.png",
        "fig5_narmax_static.png",
        "fig7_whitebox_validation.png",
        "fig8_whitebox_static.png",
    ] {
        check_png(&out.join(name));
    }
    for (name, target) in [
        ("pressure_model.json", "pressure"),
        ("flow_model.json", "flow"),
    ] {
        let text = std::fs::read_to_string(out.join(name)).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["target"], target, "{name}");
    }
    let statics = std::fs::read_to_string(out.join("static.csv")).unwrap();
    assert!(statics.starts_with("torque_ref_pct,pressure_mca,flow_lps\n"));
    assert_eq!(statics.lines().count(), 18);

    // The commands the table names make the same files.
    let u = dir.path().join("u.csv").display().to_string();
    let again = dir.path().join("val_pressure.csv");
    assert!(pumpbench(&[
        "excite",
        "--seed",
        "2",
        "--seconds",
        "300",
        "--ts-ms",
        "50",
        "--output",
        &u
    ])
    .status
    .success());
    assert!(pumpbench(&[
        "bench-data",
        "--input",
        &u,
        "--seed",
        "12",
        "--output",
        &again.display().to_string()
    ])
    .status
    .success());
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(out.join("val_pressure.csv")).unwrap()
    );
}

#[test]
fn study_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Files are required without --demo: clap's usage error.
    let out = pumpbench(&["study", "--out", &d.join("x").display().to_string()]);
    assert_eq!(out.status.code(), Some(2));

    // A bad file: the one-line input error, exit 2, nothing written.
    let good = d.join("good.csv");
    std::fs::write(
        &good,
        "t_s,torque_ref_pct,pressure_mca,flow_lps\n0,10,1,5\n0.05,20,2,6\n",
    )
    .unwrap();
    let bad = d.join("bad.csv");
    std::fs::write(
        &bad,
        "t_s,torque_ref_pct,pressure_mca\n0,10,1\n0.05,abc,2\n",
    )
    .unwrap();
    let g = good.display().to_string();
    let b = bad.display().to_string();
    let result = d.join("result");
    let out = pumpbench(&[
        "study",
        "--train-pressure",
        &b,
        "--train-flow",
        &g,
        "--val-pressure",
        &g,
        "--val-flow",
        &g,
        "--static",
        &g,
        "--out",
        &result.display().to_string(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains(&format!("{b}:3:2 (torque_ref_pct): 'abc' is not a number")),
        "{stderr}"
    );
    assert!(!result.exists());

    // An output folder that cannot be created: refused before anything is read or computed,
    // as every output that cannot be written is: exit 2, one line.
    let file = d.join("a_file");
    std::fs::write(&file, "").unwrap();
    let out = pumpbench(&[
        "study",
        "--demo",
        "--out",
        &file.join("sub").display().to_string(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("cannot create the folder"), "{stderr}");
}
