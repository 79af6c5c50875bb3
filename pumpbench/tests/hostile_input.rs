//! Hostile input: outputs that are inputs, outputs that cannot be written, endless or huge
//! inputs, inputs needing too many steps, sub-microsecond steps, overflowing spreads,
//! duplicate columns and extreme numbers. Each is refused with one line and exit code 2
//! before any output (or accepted, for sub-microsecond steps), and numbers are printed in
//! their shortest round-trip form.

mod common;
use common::{pumpbench, pumpbench_in, refused, write};
use std::path::Path;

/// A uniformly sampled (50 ms) record `t_s,torque_ref_pct,pressure_mca` of `n` rows.
fn record(n: usize) -> String {
    let mut s = String::from("t_s,torque_ref_pct,pressure_mca\n");
    let mut u = 40.0;
    let mut y = 2.0;
    for k in 0..n {
        if k % 7 == 0 {
            u = 10.0 + ((k * 37) % 70) as f64;
        }
        y += 0.2 * (u / 20.0 - y);
        s += &format!("{},{u},{y}\n", k as f64 * 0.05);
    }
    s
}

/// The shipped pressure model (50 ms), copied into `dir`.
fn model_copy(dir: &Path, name: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let p = dir.join(name);
    std::fs::copy(root.join("models").join("pressure.json"), &p).unwrap();
    p.display().to_string()
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Item 8: an output that resolves to an input (same path written differently, a symlink, a
/// hard link) is refused before anything is read or written; the input is left as it was.
/// The arguments of a tiny `identify` run (one hidden unit, two epochs) of the pressure column
/// of `data` into `output`.
fn identify_args<'a>(data: &'a str, output: &'a str) -> [&'a str; 17] {
    [
        "identify", "--data", data, "--target", "pressure", "--na", "1", "--nb", "1", "--hidden",
        "1", "--epochs", "2", "--starts", "1", "--output", output,
    ]
}

/// The arguments of a `study` run on the given records into the folder `out`.
fn study_args<'a>(
    [train_pressure, train_flow, val, statics]: [&'a str; 4],
    out: &'a str,
) -> [&'a str; 13] {
    [
        "study",
        "--train-pressure",
        train_pressure,
        "--train-flow",
        train_flow,
        "--val-pressure",
        val,
        "--val-flow",
        val,
        "--static",
        statics,
        "--out",
        out,
    ]
}

#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let train = write(d, "train.csv", &record(300));
    let u = write(d, "u.csv", &record(40));
    let m = model_copy(d, "m.json");
    std::os::unix::fs::symlink(d.join("train.csv"), d.join("train_link.csv")).unwrap();
    std::fs::hard_link(d.join("u.csv"), d.join("u_hard.csv")).unwrap();
    std::fs::create_dir(d.join("out")).unwrap();
    let table = write(&d.join("out"), "table1.md", &record(300));
    let identify = |output: &str| -> Vec<String> {
        identify_args("train.csv", output)
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    let cases: Vec<(Vec<String>, &str)> = vec![
        (identify("./train.csv"), &train),
        (identify("train_link.csv"), &train),
        (identify(&train), &train),
        (
            [
                "simulate",
                "--model",
                "whitebox",
                "--input",
                &u,
                "--output",
                "u_hard.csv",
            ]
            .map(String::from)
            .to_vec(),
            &u,
        ),
        (
            [
                "simulate",
                "--model",
                "narmax",
                "--weights",
                &m,
                "--input",
                &u,
                "--output",
                "./m.json",
            ]
            .map(String::from)
            .to_vec(),
            &m,
        ),
        (
            ["bench-data", "--input", "u.csv", "--output", &u]
                .map(String::from)
                .to_vec(),
            &u,
        ),
        (
            ["export", "--weights", &m, "--output", "m.json"]
                .map(String::from)
                .to_vec(),
            &m,
        ),
        (
            [
                "steady",
                "--model",
                "narmax",
                "--weights",
                "m.json",
                "--torque-pct",
                "50",
                "--output",
                &m,
            ]
            .map(String::from)
            .to_vec(),
            &m,
        ),
        (
            study_args(["out/table1.md", &train, &train, &train], "out")
                .map(String::from)
                .to_vec(),
            &table,
        ),
    ];
    for (args, input) in &cases {
        let before = std::fs::read(input).unwrap();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = pumpbench_in(Some(d), &args);
        refused(&out, &["same file"], &format!("{args:?}"));
        assert_eq!(
            std::fs::read(input).unwrap(),
            before,
            "{args:?}: input unchanged"
        );
    }
    assert_eq!(
        files_in(d),
        [
            "m.json",
            "out",
            "train.csv",
            "train_link.csv",
            "u.csv",
            "u_hard.csv"
        ],
        "nothing written"
    );
    assert_eq!(files_in(&d.join("out")), ["table1.md"]);
}

/// Items 9 and 10: `bench-data` follows `simulate`'s rule on the input's times: more than 2e9
/// steps is refused before any output with the row located; sub-microsecond steps are fine.
#[test]
fn bench_data_checks_the_times_as_simulate_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, text) in [
        ("huge.csv", "t_s,torque_ref_pct\n0,10\n1e308,20\n"),
        ("long.csv", "t_s,torque_ref_pct\n0,10\n1,10\n1e7,20\n"),
    ] {
        let input = write(d, name, text);
        let at = if name == "huge.csv" { ":3:1" } else { ":4:1" };
        for args in [
            vec!["bench-data", "--input", &input],
            vec!["simulate", "--model", "whitebox", "--input", &input],
        ] {
            let out = pumpbench(&args);
            refused(
                &out,
                &[&format!("{input}{at} (t_s): "), "more than 2e9 steps"],
                &format!("{args:?}"),
            );
        }
        let output = d.join(format!("{name}.out"));
        let out = pumpbench(&[
            "bench-data",
            "--input",
            &input,
            "--output",
            output.to_str().unwrap(),
        ]);
        refused(&out, &["more than 2e9 steps"], name);
        assert!(!output.exists());
    }
    let tiny = write(d, "tiny.csv", "t_s,torque_ref_pct\n0,10\n1e-7,20\n1,30\n");
    for args in [
        vec!["bench-data", "--input", &tiny],
        vec!["simulate", "--model", "whitebox", "--input", &tiny],
    ] {
        let out = pumpbench(&args);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let times: Vec<&str> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap())
            .collect();
        assert_eq!(times, ["0", "1e-7", "1"], "{args:?}: {text}");
    }
}

/// Item 9, for `study`: the white-box run over a validation record follows the same rule.
#[test]
fn study_checks_the_times_of_its_validation_records_as_simulate_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = "t_s,torque_ref_pct,pressure_mca,flow_lps\n0,10,1,5\n1.5e6,20,2,6\n3e6,30,3,7\n";
    let train = write(d, "train.csv", text);
    let val = write(d, "val.csv", text);
    let statics = write(
        d,
        "static.csv",
        "torque_ref_pct,pressure_mca,flow_lps\n50,2,10\n",
    );
    let out = d.join("out");
    let out = pumpbench(&study_args(
        [&train, &train, &val, &statics],
        out.to_str().unwrap(),
    ));
    refused(
        &out,
        &[&format!(
            "{val}:4:1 (t_s): the input needs more than 2e9 steps of 1 ms"
        )],
        "study",
    );
    assert!(!d.join("out").exists());
}

/// Item 11: every command with an output checks it can be written (its folder exists, it is not
/// a folder) before reading its inputs or computing anything.
#[test]
fn unwritable_outputs_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let train = write(d, "train.csv", &record(3000));
    let u = write(d, "u.csv", &record(40));
    let m = model_copy(d, "m.json");
    let a_file = write(d, "a_file", "");
    std::fs::create_dir(d.join("folder")).unwrap();
    let folder = d.join("folder").display().to_string();
    let missing = "/nonexistent/dir/out.csv".to_string();
    let under_file = format!("{a_file}/out.csv");
    for output in [&missing, &under_file, &folder] {
        let commands: Vec<Vec<&str>> = vec![
            vec![
                "identify", "--data", &train, "--target", "pressure", "--na", "6", "--nb", "6",
                "--hidden", "7", "--epochs", "100", "--output", output,
            ],
            vec![
                "simulate", "--model", "whitebox", "--input", &u, "--output", output,
            ],
            vec![
                "simulate",
                "--model",
                "narmax",
                "--weights",
                &m,
                "--input",
                &u,
                "--output",
                output,
            ],
            vec![
                "steady",
                "--model",
                "whitebox",
                "--torque-pct",
                "50",
                "--output",
                output,
            ],
            vec!["excite", "--seconds", "10", "--output", output],
            vec!["bench-data", "--input", &u, "--output", output],
            vec!["export", "--weights", &m, "--output", output],
        ];
        for args in commands {
            let out = pumpbench(&args);
            let err = refused(&out, &[output.as_str()], &format!("{args:?}"));
            assert!(!err.contains("identify:"), "no training: {err}");
        }
    }
    // A bad input is still reported as such when the output is fine.
    let out = pumpbench(&[
        "simulate",
        "--model",
        "whitebox",
        "--input",
        &a_file,
        "--output",
        &d.join("ok.csv").display().to_string(),
    ]);
    refused(&out, &["empty file"], "empty input");
    // study: a folder that cannot be made, or an output inside it that is a folder.
    std::fs::create_dir_all(d.join("res").join("pressure_model.json")).unwrap();
    for out_dir in [format!("{a_file}/sub"), d.join("res").display().to_string()] {
        let out = pumpbench(&study_args([&train, &train, &train, &train], &out_dir));
        let err = refused(&out, &[&out_dir], &out_dir);
        assert!(!err.contains("identif"), "{err}");
    }
    assert_eq!(
        files_in(d),
        ["a_file", "folder", "m.json", "res", "train.csv", "u.csv"]
    );
}

/// Item 12: inputs are read up to a cap (256 MiB for CSV, 16 MiB for a model file); a larger
/// file, or an endless device, is refused once the cap is passed.
#[test]
fn oversized_and_endless_inputs_are_refused_at_the_cap() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let csv_cap: u64 = 256 << 20;
    let model_cap: u64 = 16 << 20;
    // Sparse files one byte over the caps (no disk used): refused by their size.
    let big_csv = d.join("big.csv");
    std::fs::File::create(&big_csv)
        .unwrap()
        .set_len(csv_cap + 1)
        .unwrap();
    let big_json = d.join("big.json");
    std::fs::File::create(&big_json)
        .unwrap()
        .set_len(model_cap + 1)
        .unwrap();
    let (c, j) = (big_csv.to_str().unwrap(), big_json.to_str().unwrap());
    let u = write(d, "u.csv", &record(40));
    let model = d.join("m.json").display().to_string();
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (
            vec!["simulate", "--model", "whitebox", "--input", c],
            c,
            "256 MiB",
        ),
        (vec!["export", "--weights", j], j, "16 MiB"),
        (
            vec!["simulate", "--model", "whitebox", "--input", "/dev/zero"],
            "/dev/zero",
            "256 MiB",
        ),
        (
            vec!["bench-data", "--input", "/dev/zero"],
            "/dev/zero",
            "256 MiB",
        ),
        (
            vec![
                "identify",
                "--data",
                "/dev/zero",
                "--target",
                "flow",
                "--na",
                "1",
                "--nb",
                "1",
                "--hidden",
                "1",
                "--output",
                &model,
            ],
            "/dev/zero",
            "256 MiB",
        ),
        (
            vec!["export", "--weights", "/dev/zero"],
            "/dev/zero",
            "16 MiB",
        ),
        (
            vec!["validate", "--weights", "/dev/zero", "--data", &u],
            "/dev/zero",
            "16 MiB",
        ),
    ];
    for (args, file, cap) in cases {
        let out = pumpbench(&args);
        refused(
            &out,
            &[&format!("{file}: "), "larger than", cap],
            &format!("{args:?}"),
        );
    }
}

/// Item 13: a target whose spread overflows is named as such (it is not constant), and one
/// beyond the model file's range is refused before training; nothing is written.
#[test]
fn identify_names_an_overflowing_or_out_of_range_target() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, big, expected) in [
        ("overflow.csv", 1e300, "not finite"),
        ("range.csv", 1e100, "out of range"),
    ] {
        let mut text = String::from("t_s,torque_ref_pct,pressure_mca\n");
        for k in 0..400 {
            let y = if k % 2 == 0 { big } else { -big };
            text += &format!("{},{},{y:e}\n", k as f64 * 0.05, 10 + (k * 7) % 60);
        }
        let data = write(d, name, &text);
        let model = d.join(format!("{name}.json"));
        let out = pumpbench(&identify_args(&data, model.to_str().unwrap()));
        let err = refused(&out, &[&data, "pressure_mca", expected], name);
        assert!(!err.contains("constant"), "{err}");
        assert!(!model.exists(), "{name}: no model file");
    }
}

/// Item 13: a column name twice in a header is refused, naming it, the file and the line.
#[test]
fn duplicate_column_names_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = write(d, "dup.csv", "\nt_s,torque_ref_pct,t_s\n0,10,5\n1,10,6\n");
    let out = pumpbench(&["simulate", "--model", "whitebox", "--input", &input]);
    refused(
        &out,
        &[&format!("{input}:2:3 (t_s): column 't_s' appears twice")],
        "dup",
    );
    let input = write(
        d,
        "dup2.csv",
        "t_s,pressure_mca,torque_ref_pct, pressure_mca\n0,1,10,2\n0.05,1,10,2\n",
    );
    let out = pumpbench(&[
        "validate",
        "--weights",
        &model_copy(d, "m.json"),
        "--data",
        &input,
    ]);
    refused(
        &out,
        &[&format!(
            "{input}:1:4 (pressure_mca): column 'pressure_mca' appears twice"
        )],
        "dup2",
    );
}

/// Item 13: numbers in CSV output and in messages are in their shortest round-trip form.
#[test]
fn numbers_are_printed_in_their_shortest_round_trip_form() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tiny = write(d, "tiny.csv", "t_s,torque_ref_pct\n0,10\n5e-324,20\n");
    for args in [
        vec!["simulate", "--model", "whitebox", "--input", &tiny],
        vec![
            "simulate",
            "--model",
            "whitebox",
            "--precision",
            "f32",
            "--input",
            &tiny,
        ],
        vec!["bench-data", "--input", &tiny],
    ] {
        let out = pumpbench(&args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let row = text.lines().nth(2).unwrap();
        assert!(row.starts_with("5e-324,20,"), "{args:?}: {row}");
        assert!(row.len() < 300, "{args:?}: {row}");
    }
    let late = write(d, "late.csv", "t_s,torque_ref_pct\n1e300,10\n1e300,20\n");
    let out = pumpbench(&["simulate", "--model", "whitebox", "--input", &late]);
    let err = refused(
        &out,
        &["time 1e300 s is not after the previous row's 1e300 s"],
        "late",
    );
    assert!(err.len() < 200, "{err}");
    let big = write(d, "big.csv", "t_s,torque_ref_pct\n0,1e308\n");
    let out = pumpbench(&["simulate", "--model", "whitebox", "--input", &big]);
    let err = refused(&out, &["torque reference 1e308 % is outside"], "1e308");
    assert!(err.len() < 200, "{err}");
    let out = pumpbench(&[
        "steady",
        "--model",
        "whitebox",
        "--torque-pct",
        "5e-324,1e300",
    ]);
    let err = refused(&out, &["1e300 % is outside"], "steady");
    assert!(err.len() < 200, "{err}");
    // NARMAX output rows echo t_s and torque in the same form.
    let mut u = String::from("t_s,torque_ref_pct\n");
    for k in 0..30 {
        let torque = if k == 3 { "0.00001" } else { "50" };
        u += &format!("{:.2},{torque}\n", 1000.0 + k as f64 * 0.05);
    }
    let u = write(d, "u.csv", &u);
    let out = pumpbench(&[
        "simulate",
        "--model",
        "narmax",
        "--weights",
        &model_copy(d, "m2.json"),
        "--input",
        &u,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert!(rows[1].starts_with("1e3,50,"), "{}", rows[1]);
    assert!(rows[4].starts_with("1000.15,1e-5,"), "{}", rows[4]);
}

/// A long header or cell is shortened in the message (the whole header of a 256 MiB file of
/// zero bytes was once echoed: a 1 GiB "line").
#[test]
fn long_cells_and_headers_are_shortened_in_messages() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let long = "x".repeat(100_000);
    for (name, text, expected) in [
        (
            "header.csv",
            format!("t_s,{long}\n0,1\n"),
            ":1: missing column 'torque_ref_pct'",
        ),
        (
            "cell.csv",
            format!("t_s,torque_ref_pct\n0,1{long}\n"),
            ":2:2 (torque_ref_pct): '1xxx",
        ),
    ] {
        let input = write(d, name, &text);
        let out = pumpbench(&["simulate", "--model", "whitebox", "--input", &input]);
        let err = refused(&out, &[&format!("{input}{expected}")], name);
        assert!(err.len() < 400, "{name}: {} bytes", err.len());
    }
}

/// Issue 21, defect 3: a model whose period the firmware cannot run (not a whole number of
/// milliseconds from 1 to 1000: the controller ticks every 1 ms and the observer refuses
/// steps over 1 s) is refused by `export` with exit 2 naming the rule, and nothing is
/// written; the shipped 50 ms passes.
#[test]
fn export_refuses_periods_the_firmware_cannot_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let shipped = std::fs::read_to_string(model_copy(d, "shipped.json")).unwrap();
    assert!(
        shipped.contains("\"sample_period_s\": 0.05,"),
        "the model's period field"
    );
    for (period, runs) in [
        ("1e-300", false),
        ("0.0504", false),
        ("20", false),
        ("0.0005", false),
        ("0.05", true),
        ("0.1", true),
    ] {
        let m = write(
            d,
            &format!("m{period}.json"),
            &shipped.replace(
                "\"sample_period_s\": 0.05,",
                &format!("\"sample_period_s\": {period},"),
            ),
        );
        let out_path = d.join(format!("m{period}.rs"));
        let out = pumpbench(&[
            "export",
            "--weights",
            &m,
            "--output",
            &out_path.display().to_string(),
        ]);
        if runs {
            common::ok(&out, period);
            assert!(out_path.exists(), "{period}: written");
        } else {
            refused(
                &out,
                &[
                    "sample_period_s",
                    "whole number of milliseconds from 1 to 1000",
                ],
                period,
            );
            assert!(!out_path.exists(), "{period}: nothing written");
        }
    }
}
