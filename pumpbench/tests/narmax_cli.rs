//! `identify`, narmax `simulate`/`steady`, `validate`: recovery of a known NARX, precisions,
//! and one-line errors for bad or mismatched files.

mod common;
use common::pumpbench;
use host_tests::narmax_ref::RefNarmax;
use model_core::excitation::SplitMix64;
use std::path::Path;
use std::process::Output;

fn stdout(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout.clone()).unwrap()
}

fn mape(text: &str) -> f64 {
    let line = text
        .lines()
        .find(|l| l.starts_with("mape_d_pct="))
        .expect("mape_d line");
    line["mape_d_pct=".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// A drawn NARX: na = 2, nb = 2, 4 hidden units, weights from `seed`.
fn narx(seed: u64) -> RefNarmax {
    let mut rng = SplitMix64::new(seed);
    let mut w1: Vec<Vec<f64>> = (0..4)
        .map(|_| (0..5).map(|_| rng.next_f64() - 0.5).collect())
        .collect();
    for row in &mut w1 {
        row[0] *= 0.8; // keep the output feedback contracting
        row[1] *= 0.4;
        row[2] += 1.0; // a clear input path
    }
    let w2: Vec<f64> = (0..5).map(|_| rng.next_f64() - 0.5).collect();
    RefNarmax {
        lags: [2, 2, 0, 1],
        w1,
        w2,
        u_scale: (45.0, 23.0),
        y_scale: (3.0, 1.0),
    }
}

/// A 50 ms record of `r` driven by pulses from `input_seed`, written to `dir/name`.
fn record(dir: &Path, name: &str, r: &RefNarmax, input_seed: u64, n: usize) -> String {
    let mut rng = SplitMix64::new(input_seed);
    let mut u = Vec::with_capacity(n);
    let (mut level, mut left) = (45.0, 0);
    for _ in 0..n {
        if left == 0 {
            level = rng.uniform(5.0, 85.0);
            left = 1 + (rng.next_f64() * 20.0) as usize;
        }
        left -= 1;
        u.push(level);
    }
    let y = r.free_run(&u, 3.0);
    let mut csv = String::from("t_s,torque_ref_pct,pressure_mca\n");
    for (k, (a, b)) in u.iter().zip(&y).enumerate() {
        csv += &format!("{},{a},{b}\n", k as f64 * 0.05);
    }
    let path = dir.join(name);
    std::fs::write(&path, csv).unwrap();
    path.display().to_string()
}

#[test]
fn identify_recovers_a_known_narx() {
    let dir = tempfile::tempdir().unwrap();
    let r = narx(1);
    let train = record(dir.path(), "train.csv", &r, 10, 4000);
    // Same network, an input it was not trained on.
    let fresh = record(dir.path(), "fresh.csv", &r, 99, 3000);
    let model = dir.path().join("m.json");
    let m = model.to_str().unwrap();
    let out = pumpbench(&[
        "identify", "--data", &train, "--target", "pressure", "--na", "2", "--nb", "2", "--hidden",
        "4", "--epochs", "100", "--output", m,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let e = mape(&stdout(&pumpbench(&[
        "validate",
        "--weights",
        m,
        "--data",
        &fresh,
    ])));
    eprintln!("known NARX recovered: free-run MAPE_d {e:.4} % on a fresh input");
    assert!(e < 0.1, "MAPE_d {e} %");
    for p in ["f32", "q15"] {
        let ep = mape(&stdout(&pumpbench(&[
            "validate",
            "--weights",
            m,
            "--data",
            &fresh,
            "--precision",
            p,
        ])));
        eprintln!("  {p}: {ep:.4} %");
        assert!((ep - e).abs() < 0.1, "{p}: {ep} vs f64 {e}");
    }
    // simulate without the target column starts from the model's steady state; with it,
    // the first max-lag rows are the measured seed.
    let sim = stdout(&pumpbench(&[
        "simulate",
        "--model",
        "narmax",
        "--weights",
        m,
        "--input",
        &fresh,
    ]));
    assert!(sim.starts_with("t_s,torque_ref_pct,pressure_mca\n"));
    assert_eq!(sim.lines().count(), 3001);
    let st = stdout(&pumpbench(&[
        "steady",
        "--model",
        "narmax",
        "--weights",
        m,
        "--torque-pct",
        "10:80:10",
    ]));
    assert_eq!(st.lines().count(), 9);
}

#[test]
fn bad_and_mismatched_models_fail_with_one_line_and_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let train = record(dir.path(), "train.csv", &narx(2), 3, 600);
    let good = dir.path().join("good.json");
    let g = good.to_str().unwrap();
    let out = pumpbench(&[
        "identify", "--data", &train, "--target", "pressure", "--na", "2", "--nb", "2", "--hidden",
        "2", "--epochs", "3", "--starts", "1", "--output", g,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&good).unwrap();
    let write = |name: &str, t: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, t).unwrap();
        p.display().to_string()
    };
    let lags = write("lags.json", text.replacen("\"na\": 2", "\"na\": 3", 1));
    let junk = write("junk.json", "{ not json".into());
    let fmt = write("fmt.json", text.replacen("pumpbench-narmax-1", "other", 1));
    let slow = write(
        "slow.csv",
        std::fs::read_to_string(&train)
            .unwrap()
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == 0 {
                    l.to_string()
                } else {
                    let mut c: Vec<String> = l.split(',').map(String::from).collect();
                    c[0] = format!("{}", (i - 1) as f64 * 0.1);
                    c.join(",")
                }
            })
            .collect::<Vec<_>>()
            .join("\n"),
    );
    let nocol = write(
        "nocol.csv",
        "t_s,torque_ref_pct,flow_lps\n0,10,1\n0.05,10,1\n".into(),
    );
    let gaps = write(
        "gaps.csv",
        "t_s,torque_ref_pct,pressure_mca\n0,10,1\n0.05,10,1\n0.2,10,1\n".into(),
    );
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["validate", "--weights", &lags, "--data", &train],
            "weights do not match the lags",
        ),
        (
            vec!["validate", "--weights", &junk, "--data", &train],
            "not a pumpbench model file",
        ),
        (
            vec!["validate", "--weights", &fmt, "--data", &train],
            "format 'other'",
        ),
        (
            vec!["validate", "--weights", g, "--data", &slow],
            "the model was identified at 0.05 s",
        ),
        (
            vec!["validate", "--weights", g, "--data", &nocol],
            "missing column 'pressure_mca'",
        ),
        (
            vec!["validate", "--weights", g, "--data", &gaps],
            "not uniformly sampled",
        ),
        (
            vec!["simulate", "--model", "narmax", "--input", &train],
            "needs --weights",
        ),
        (
            vec![
                "identify", "--data", &nocol, "--target", "pressure", "--na", "1", "--nb", "1",
                "--hidden", "1", "--output", "x.json",
            ],
            "missing column",
        ),
        (
            vec![
                "identify", "--data", &train, "--target", "pressure", "--na", "0", "--nb", "0",
                "--hidden", "1", "--output", "x.json",
            ],
            "at least one lag",
        ),
    ];
    for (args, expected) in cases {
        let out = pumpbench(&args);
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
    assert!(!Path::new("x.json").exists());
}

/// The shipped models on a fresh 300 s synthetic record: fixed point and f32 within 0.1
/// MAPE points of f64, and all of them under the paper's black-box MAPE_d.
#[test]
fn shipped_models_fixed_point_within_a_tenth_of_a_point_over_300_s() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for (model, ts, seed, paper) in [("pressure", "50", 21, 1.22), ("flow", "100", 22, 1.10)] {
        let u = dir.path().join(format!("u_{model}.csv"));
        let d = dir.path().join(format!("d_{model}.csv"));
        let (u, d) = (u.to_str().unwrap(), d.to_str().unwrap());
        let seed = seed.to_string();
        stdout(&pumpbench(&[
            "excite",
            "--seed",
            &seed,
            "--seconds",
            "300",
            "--ts-ms",
            ts,
            "--output",
            u,
        ]));
        stdout(&pumpbench(&[
            "bench-data",
            "--input",
            u,
            "--seed",
            &seed,
            "--output",
            d,
        ]));
        let weights = root.join("models").join(format!("{model}.json"));
        let w = weights.to_str().unwrap();
        let m = |p: &str| {
            mape(&stdout(&pumpbench(&[
                "validate",
                "--weights",
                w,
                "--data",
                d,
                "--precision",
                p,
            ])))
        };
        let (f64_, f32_, q15) = (m("f64"), m("f32"), m("q15"));
        eprintln!(
            "{model}: MAPE_d f64 {f64_:.4} %, f32 {f32_:.4} %, q15 {q15:.4} % (paper {paper} %)"
        );
        assert!(
            (q15 - f64_).abs() <= 0.1,
            "{model}: q15 {q15} vs f64 {f64_}"
        );
        assert!(
            (f32_ - f64_).abs() <= 0.01,
            "{model}: f32 {f32_} vs f64 {f64_}"
        );
        assert!(
            f64_ <= paper,
            "{model}: {f64_} % above the paper's {paper} %"
        );
    }
}
