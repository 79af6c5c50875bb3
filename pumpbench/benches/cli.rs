//! `cargo bench -p pumpbench --bench cli`: the host tool's two long jobs, timed through the
//! CLI as a user runs them (release build), printed as a Markdown table:
//! - `simulate --model whitebox`: bench-seconds simulated per wall-clock second, RK4 at 1 ms,
//!   f64 and f32, on 600 s of the paper's pulses;
//! - `identify`: wall time to train the paper's pressure model (na = nb = 6, 7 tanh units,
//!   40 Levenberg-Marquardt epochs, 4 random starts) on 600 s sampled every 50 ms.
use std::path::Path;
use std::process::Command;
use std::time::Instant;

fn pumpbench(args: &[&str]) -> f64 {
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_pumpbench"))
        .args(args)
        .output()
        .expect("run pumpbench");
    assert!(
        out.status.success(),
        "pumpbench {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    start.elapsed().as_secs_f64()
}

fn main() {
    let dir = std::env::temp_dir().join(format!("pumpbench-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let p = |name: &str| dir.join(name).to_str().expect("utf-8 temp path").to_owned();
    let (u, d, m, out) = (p("u.csv"), p("d.csv"), p("m.json"), p("sim.csv"));
    pumpbench(&[
        "excite",
        "--seed",
        "1",
        "--seconds",
        "600",
        "--ts-ms",
        "50",
        "--output",
        &u,
    ]);
    println!("| job | precision | wall s | rate |");
    println!("|---|---|---|---|");
    for precision in ["f64", "f32"] {
        let t = pumpbench(&[
            "simulate",
            "--model",
            "whitebox",
            "--precision",
            precision,
            "--input",
            &u,
            "--output",
            &out,
        ]);
        println!(
            "| simulate 600 s, RK4 1 ms | {precision} | {t:.2} | {:.0} bench-s/s |",
            600.0 / t
        );
    }
    pumpbench(&["bench-data", "--input", &u, "--seed", "11", "--output", &d]);
    let t = pumpbench(&[
        "identify", "--data", &d, "--target", "pressure", "--na", "6", "--nb", "6", "--hidden",
        "7", "--epochs", "40", "--seed", "1", "--output", &m,
    ]);
    println!(
        "| identify pressure 12→7→1, 12 001 samples, 40 epochs, 4 starts | f64 | {t:.1} | — |"
    );
    let _ = std::fs::remove_dir_all(Path::new(&dir));
}
