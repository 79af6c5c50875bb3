//! The `pumpbench` command line: contract, errors, and results against the reference.

mod common;
use common::{pumpbench, write};
use host_tests::reference::Reference;
use host_tests::stats::ErrorStats;

fn parse_csv(text: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// An input the tests have not tuned for: irregular times, steps not multiples of 1 ms.
fn irregular_input() -> Vec<(f64, f64)> {
    let mut rows = vec![];
    let mut t = 0.0;
    let mut x = 0.3f64;
    for i in 0..120 {
        x = (x * 3.9 * (1.0 - x)).clamp(0.01, 0.99); // logistic map: aperiodic, deterministic
        let u = 5.0 + 80.0 * x;
        rows.push((t, if i % 17 == 0 { 0.0 } else { u }));
        t += 0.0137 + 0.9 * x;
    }
    rows
}

fn to_csv(rows: &[(f64, f64)]) -> String {
    let mut s = String::from("t_s,torque_ref_pct\n");
    for (t, u) in rows {
        s += &format!("{t},{u}\n");
    }
    s
}

#[test]
fn simulate_matches_reference_in_f64_and_f32() {
    let dir = tempfile::tempdir().unwrap();
    let input = irregular_input();
    let path = write(dir.path(), "u.csv", &to_csv(&input));
    let reference = Reference::paper().simulate(&input);
    for (precision, tol, floor) in [("f64", 1e-6, 1e-4), ("f32", 1e-4, 1e-3)] {
        let out = pumpbench(&[
            "simulate",
            "--model",
            "whitebox",
            "--precision",
            precision,
            "--input",
            &path,
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let (header, rows) = parse_csv(&String::from_utf8(out.stdout).unwrap());
        assert_eq!(
            header[..5],
            [
                "t_s",
                "torque_ref_pct",
                "speed_rpm",
                "flow_lps",
                "pressure_mca"
            ]
        );
        assert_eq!(rows.len(), input.len());
        let mut st = [ErrorStats::default(); 3];
        for (row, r) in rows.iter().zip(&reference) {
            assert_eq!((row[0], row[1]), (r.t_s, r.u_pct), "echoed input");
            st[0].push(row[2], r.speed_rpm, 1e-9);
            st[1].push(row[3], r.flow_lps, 1e-9);
            st[2].push(row[4], r.pressure_mca, floor);
        }
        for (s, name) in st.iter().zip(["speed", "flow", "pressure"]) {
            eprintln!("{precision} {name}: {s}");
            assert!(s.max_abs <= tol, "{precision} {name}: {s}");
        }
    }
}

#[test]
fn first_row_is_the_steady_state_and_step_size_is_honoured() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "u.csv",
        "t_s,torque_ref_pct\n0,50\n0.25,80\n0.5,80\n",
    );
    let steady = pumpbench(&["steady", "--model", "whitebox", "--torque-pct", "50"]);
    let (_, s) = parse_csv(&String::from_utf8(steady.stdout).unwrap());
    let run = |step: &str| {
        let out = pumpbench(&[
            "simulate",
            "--model",
            "whitebox",
            "--step-ms",
            step,
            "--input",
            &path,
        ]);
        parse_csv(&String::from_utf8(out.stdout).unwrap()).1
    };
    let fine = run("1");
    assert_eq!(
        fine[0][2..5],
        s[0][1..4],
        "row 0 = steady state of its torque"
    );
    // Second row: the 50 % torque held 0.25 s from steady state changes nothing.
    assert!((fine[1][2] / fine[0][2] - 1.0).abs() < 1e-12);
    // Third row: RK4 at 100 ms vs 1 ms differ, but little (4th order).
    let coarse = run("100");
    let d = (coarse[2][2] / fine[2][2] - 1.0).abs();
    assert!(d > 1e-9 && d < 1e-3, "{d}");
}

#[test]
fn steady_list_and_range() {
    let out = pumpbench(&["steady", "--model", "whitebox", "--torque-pct", "5:85:5"]);
    assert!(out.status.success());
    let (header, rows) = parse_csv(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(
        header,
        ["torque_ref_pct", "speed_rpm", "flow_lps", "pressure_mca"]
    );
    assert_eq!(rows.len(), 17);
    let reference = Reference::paper();
    for row in &rows {
        let (w, q, hs) = reference.steady(row[0]);
        assert!((row[1] / w - 1.0).abs() < 1e-6 && (row[2] / q - 1.0).abs() < 1e-6);
        assert!((row[3] - hs).abs() / hs.abs().max(1e-4) < 1e-6);
    }
    assert!(
        rows.windows(2)
            .all(|p| p[1][1] > p[0][1] && p[1][2] > p[0][2]),
        "monotone"
    );
    let out = pumpbench(&[
        "steady",
        "--model",
        "whitebox",
        "--precision",
        "f32",
        "--torque-pct",
        "5,10,15",
    ]);
    assert_eq!(
        parse_csv(&String::from_utf8(out.stdout).unwrap()).1.len(),
        3
    );
}

#[test]
fn bad_files_fail_with_one_line_exit_2_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("empty.csv", "", ":1: empty file"),
        (
            "nocol.csv",
            "t_s,u\n0,1\n",
            ":1: missing column 'torque_ref_pct'",
        ),
        (
            "text.csv",
            "t_s,torque_ref_pct\n0,1\n1,x\n",
            ":3:2 (torque_ref_pct): 'x' is not a number",
        ),
        (
            "back.csv",
            "t_s,torque_ref_pct\n0,1\n2,1\n1,1\n",
            ":4:1 (t_s): time 1 s is not after",
        ),
        (
            "range.csv",
            "t_s,torque_ref_pct\n0,150\n",
            ":2:2 (torque_ref_pct): torque reference 150",
        ),
    ];
    for (name, text, expected) in cases {
        let input = write(dir.path(), name, text);
        let output = dir.path().join(format!("{name}.out"));
        let out = pumpbench(&[
            "simulate",
            "--model",
            "whitebox",
            "--input",
            &input,
            "--output",
            output.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{name}: one line: {stderr}");
        assert!(
            stderr.contains(&format!("{input}{expected}")),
            "{name}: {stderr}"
        );
        assert!(!output.exists(), "{name}: no output file");
        assert!(out.stdout.is_empty());
    }
    // Leftover temporary files: none in the output directory.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), cases.len(), "{left:?}");
    let missing = pumpbench(&[
        "simulate",
        "--model",
        "whitebox",
        "--input",
        "/nonexistent.csv",
    ]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8(missing.stderr)
        .unwrap()
        .contains("/nonexistent.csv: cannot open"));
    for args in [
        &["steady", "--model", "whitebox", "--torque-pct", "5:x:5"][..],
        &["steady", "--model", "whitebox", "--torque-pct", "120"][..],
        &[
            "simulate",
            "--model",
            "whitebox",
            "--step-ms",
            "0",
            "--input",
            "x",
        ][..],
        &["simulate", "--model", "blackbox", "--input", "x"][..],
    ] {
        assert_eq!(pumpbench(args).status.code(), Some(2), "{args:?}");
    }
}

#[test]
fn output_file_written_whole() {
    let dir = tempfile::tempdir().unwrap();
    let input = write(dir.path(), "u.csv", &to_csv(&irregular_input()));
    let output = dir.path().join("sub_out.csv");
    let out = pumpbench(&[
        "simulate",
        "--model",
        "whitebox",
        "--input",
        &input,
        "--output",
        output.to_str().unwrap(),
    ]);
    assert!(out.status.success() && out.stdout.is_empty());
    let text = std::fs::read_to_string(&output).unwrap();
    assert_eq!(text.lines().count(), 121);
}
