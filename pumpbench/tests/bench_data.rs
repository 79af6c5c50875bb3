//! `pumpbench bench-data` with a bench that differs from the paper's model: valve steps, a
//! curve error, set transmitter lags, and the true state beside the readings (`--truth`).
//! Without these options the record is what it was before they existed.

mod common;
use common::{ok, pumpbench, write, Table};

/// Runs `bench-data` and returns its stdout, which must be a success.
fn bench_data(args: &[&str]) -> String {
    let mut all = vec!["bench-data"];
    all.extend_from_slice(args);
    ok(&pumpbench(&all), &format!("{args:?}"))
}

/// Index of the row at time `t_s` (exactly as written).
fn row_at(r: &Table, t_s: f64) -> usize {
    r.col("t_s")
        .iter()
        .position(|&t| t == t_s)
        .unwrap_or_else(|| panic!("no row at {t_s} s"))
}

/// `t_s,torque_ref_pct` rows every `ts_s` from 0 to `seconds` (times printed with 2 decimals,
/// so a row falls exactly on every whole second), torque `torque(t)`.
fn input(seconds: f64, ts_s: f64, torque: impl Fn(f64) -> f64) -> String {
    let mut s = String::from("t_s,torque_ref_pct\n");
    let n = (seconds / ts_s).round() as usize;
    for k in 0..=n {
        let t: f64 = format!("{:.2}", k as f64 * ts_s).parse().unwrap();
        s += &format!("{t},{}\n", torque(t));
    }
    s
}

/// The record of `u.csv` (10 rows, irregular times, torque steps, seed 7) as `bench-data`
/// writes it without valve steps, curve errors, lag options and truth columns: made by that
/// binary at commit cdcaae8, its readings re-made once when bench-data took the controller's
/// transmitter, ADC and noise model (issue 20: 22 mA over 4096 codes instead of 24 mA, the
/// sum-of-uniforms noise instead of Box-Muller; the same seed, another sequence).
const U_CSV: &str = "t_s,torque_ref_pct\n0,40\n0.05,40\n0.1,70\n0.1375,70\n0.2,25\n0.5,25\n\
                     0.5004,60\n1.25,60\n2,0\n2.1,100\n";
const U_RECORD_BEFORE: &str = "t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca
0,40,1102.38,14.2179,2.12027
0.05,40,1103.51,14.2582,2.12027
0.1,70,1102.77,14.2482,2.12027
0.1375,70,1146.18,14.4295,2.21764
0.2,25,1210.78,15.0339,2.47955
0.5,25,1027.85,13.5833,1.87180
0.5004,60,1028.21,13.5632,1.87180
1.25,60,1327.51,16.8370,3.07723
2,0,1352.10,17.1190,3.19811
2.1,100,1154.67,15.6584,2.46948
";

#[test]
fn without_the_new_options_the_record_is_byte_for_byte_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(dir.path(), "u.csv", U_CSV);
    let defaults = [
        "--rotor-inertia",
        "1",
        "--water-inertia",
        "0",
        "--drive-lag-ms",
        "0",
        "--curve-error",
        "0",
        "--flow-lag-ms",
        "40",
        "--pressure-lag-ms",
        "20",
    ];
    let plain = bench_data(&["--input", &u, "--seed", "7"]);
    assert_eq!(plain, U_RECORD_BEFORE, "as before the options existed");
    let mut args = vec!["--input", u.as_str(), "--seed", "7"];
    args.extend_from_slice(&defaults);
    assert_eq!(
        bench_data(&args),
        U_RECORD_BEFORE,
        "options at their defaults"
    );
    // A longer record with every torque step: no options = every option at its default, and
    // --truth only appends columns (the readings and their noise are the same).
    let long = write(
        dir.path(),
        "long.csv",
        &input(20.0, 0.01, |t| 5.0 + (t * 7.3).floor() * 37.0 % 80.0),
    );
    let plain = bench_data(&["--input", &long]);
    let mut args = vec!["--input", long.as_str()];
    args.extend_from_slice(&defaults);
    assert_eq!(bench_data(&args), plain);
    let truth = bench_data(&["--input", &long, "--truth"]);
    let mut lines = truth.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca,speed_true,flow_true,pressure_true,\
         k2_true"
    );
    for (with, without) in lines.zip(plain.lines().skip(1)) {
        let readings: Vec<&str> = with.split(',').take(5).collect();
        assert_eq!(readings.join(","), without);
        assert_eq!(with.split(',').count(), 9, "{with}");
    }
    assert_eq!(truth.lines().count(), plain.lines().count());
}

#[test]
fn a_valve_step_shows_in_k2_true_at_its_row_and_moves_flow_and_pressure() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(dir.path(), "u.csv", &input(5.0, 0.05, |_| 50.0));
    // Closing at 2 s (a row's time), back to nominal at 3.01 s (between rows 3 and 3.05).
    let r = Table::parse(&bench_data(&[
        "--input",
        &u,
        "--truth",
        "--valve-steps",
        "2:1.3,3.01:1",
    ]));
    let (k2, q, p) = (r.col("k2_true"), r.col("flow_true"), r.col("pressure_true"));
    let (qm, pm) = (r.col("flow_lps"), r.col("pressure_mca"));
    let (at2, at3, at305) = (row_at(&r, 2.0), row_at(&r, 3.0), row_at(&r, 3.05));
    let closed = 0.1082 * 1.3;
    for (i, &k) in k2.iter().enumerate() {
        let expected = if i < at2 || i >= at305 {
            0.1082
        } else {
            closed
        };
        assert_eq!(k, expected, "k2_true at row {i} (t = {} s)", r.rows[i][0]);
    }
    assert_eq!(at305, at3 + 1);
    // Closing the valve: less flow, more pressure, at once in the truth...
    let before = at2 - 1;
    assert!(q[at2] < q[before] - 0.5, "flow {} -> {}", q[before], q[at2]);
    assert!(
        p[at2] > p[before] + 0.3,
        "pressure {} -> {}",
        p[before],
        p[at2]
    );
    // ... and in the readings once the transmitters have followed, until it opens again.
    let settled = row_at(&r, 2.5);
    assert!(qm[settled] < qm[before] - 0.5 && pm[settled] > pm[before] + 0.3);
    assert!(q[at3] < q[before] && p[at3] > p[before]);
    // Opening again: more flow, less pressure.
    assert!(q[at305] > q[at3] + 0.5 && p[at305] < p[at3] - 0.3);
    // Before the step the bench is at its steady state with the paper's valve.
    assert!((q[before] - q[0]).abs() < 1e-9 && (p[before] - p[0]).abs() < 1e-9);
}

#[test]
fn a_valve_step_at_or_before_the_first_row_sets_the_starting_valve() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(dir.path(), "u.csv", &input(1.0, 0.1, |_| 50.0));
    let r = Table::parse(&bench_data(&[
        "--input",
        &u,
        "--truth",
        "--valve-steps",
        "-5:0.7,0:1.3",
    ]));
    let (k2, q, w) = (r.col("k2_true"), r.col("flow_true"), r.col("speed_true"));
    assert!(k2.iter().all(|&k| k == 0.1082 * 1.3));
    // At its steady state: nothing moves.
    let last = q.len() - 1;
    assert!((q[last] / q[0] - 1.0).abs() < 1e-9 && (w[last] / w[0] - 1.0).abs() < 1e-9);
}

/// Last row's true speed and flow at a constant torque of 50 %, and the first row's speed.
fn steady_truth(u: &str, curve_error: &str) -> (f64, f64, f64) {
    let r = Table::parse(&bench_data(&[
        "--input",
        u,
        "--truth",
        "--curve-error",
        curve_error,
    ]));
    let (w, q) = (r.col("speed_true"), r.col("flow_true"));
    (*w.last().unwrap(), *q.last().unwrap(), w[0])
}

#[test]
fn a_positive_curve_error_raises_the_steady_speed_and_flow_at_a_fixed_torque() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(dir.path(), "u.csv", &input(2.0, 0.05, |_| 50.0));
    let (w0, q0, w0_first) = steady_truth(&u, "0");
    let (wp, qp, _) = steady_truth(&u, "5");
    let (wn, qn, _) = steady_truth(&u, "-5");
    // 0 %: the paper's steady state (as `steady` gives it).
    let out = pumpbench(&["steady", "--model", "whitebox", "--torque-pct", "50"]);
    let steady = Table::parse(&String::from_utf8(out.stdout).unwrap());
    assert!((w0 / steady.col("speed_rpm")[0] - 1.0).abs() < 1e-9);
    assert!((q0 / steady.col("flow_lps")[0] - 1.0).abs() < 1e-9);
    assert!(
        (w0 / w0_first - 1.0).abs() < 1e-9,
        "steady from the first row"
    );
    // A stronger pump and a lighter load: faster and more flow; the opposite for -5 %.
    assert!(wp > w0 * 1.01 && qp > q0 * 1.01, "{w0} {q0} -> {wp} {qp}");
    assert!(wn < w0 * 0.99 && qn < q0 * 0.99, "{w0} {q0} -> {wn} {qn}");
    // The readings follow the truth.
    let r = Table::parse(&bench_data(&["--input", &u, "--curve-error", "5"]));
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    assert!((mean(r.col("speed_rpm")) - wp).abs() < 1.0);
}

#[test]
fn truth_columns_equal_the_readings_within_noise_where_the_signal_is_steady() {
    let dir = tempfile::tempdir().unwrap();
    // 30 % for 3 s, then 70 %: compare over the steady stretches (the last 1.5 s of each).
    let u = write(
        dir.path(),
        "u.csv",
        &input(6.0, 0.01, |t| if t < 3.0 { 30.0 } else { 70.0 }),
    );
    let r = Table::parse(&bench_data(&["--input", &u, "--truth", "--seed", "11"]));
    let t = r.col("t_s");
    // 5 σ of noise plus one ADC code (3.7 mm, 0.011 l/s).
    for (reading, truth, bound) in [
        ("speed_rpm", "speed_true", 5.0 * 0.5),
        ("flow_lps", "flow_true", 5.0 * 0.02 + 0.011),
        ("pressure_mca", "pressure_true", 5.0 * 0.003 + 0.0037),
    ] {
        let (m, x) = (r.col(reading), r.col(truth));
        let steady: Vec<usize> = (0..t.len())
            .filter(|&i| (1.5..=3.0).contains(&t[i]) || t[i] >= 4.5)
            .collect();
        assert!(steady.len() > 250);
        let mut bias = 0.0;
        for &i in &steady {
            assert!(
                (m[i] - x[i]).abs() <= bound,
                "{reading} at {} s: {} vs {}",
                t[i],
                m[i],
                x[i]
            );
            bias += (m[i] - x[i]) / steady.len() as f64;
        }
        assert!(bias.abs() < bound / 5.0, "{reading}: mean error {bias}");
    }
    // The second stretch differs from the first: the comparison is not of constants.
    let w = r.col("speed_true");
    assert!(w[row_at(&r, 6.0)] > w[row_at(&r, 3.0)] + 100.0);
}

/// Flow and pressure errors (reading minus truth) 50 ms after the valve closes at 1 s, as
/// fractions of the step of the truth (1.36 l/s down, 2.56 mca up), and in signal units.
fn error_after_a_step(u: &str, flow_lag_ms: &str, pressure_lag_ms: &str) -> [f64; 4] {
    let r = Table::parse(&bench_data(&[
        "--input",
        u,
        "--truth",
        "--valve-steps",
        "1:1.5",
        "--flow-lag-ms",
        flow_lag_ms,
        "--pressure-lag-ms",
        pressure_lag_ms,
    ]));
    let (q, p) = (r.col("flow_true"), r.col("pressure_true"));
    let (before, at, i) = (row_at(&r, 0.99), row_at(&r, 1.0), row_at(&r, 1.05));
    let eq = r.col("flow_lps")[i] - q[i];
    let ep = r.col("pressure_mca")[i] - p[i];
    [eq / (q[before] - q[at]), ep / (p[before] - p[at]), eq, ep]
}

#[test]
fn transmitter_lags_are_set_by_their_options() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(dir.path(), "u.csv", &input(1.5, 0.01, |_| 50.0));
    // No lag: within 5 σ of noise and a code of the truth.
    let [_, _, q, p] = error_after_a_step(&u, "0", "0");
    assert!(q.abs() < 0.111 && p.abs() < 0.0187, "{q} {p}");
    // The defaults: e^(-50/40) = 0.29 of the flow step and e^(-50/20) = 0.08 of the pressure
    // step are left (the truth moves a little meanwhile).
    let [fq, fp, ..] = error_after_a_step(&u, "40", "20");
    assert!(
        (fq - 0.287).abs() < 0.08 && (fp - 0.082).abs() < 0.03,
        "{fq} {fp}"
    );
    // 2 s lags: nearly the whole step is left (e^(-0.025) = 0.975).
    let [fq, fp, ..] = error_after_a_step(&u, "2000", "2000");
    assert!(fq > 0.9 && fp > 0.9, "{fq} {fp}");
    // Each option sets its own transmitter.
    let [fq, _, _, p] = error_after_a_step(&u, "2000", "0");
    assert!(fq > 0.9 && p.abs() < 0.0187, "{fq} {p}");
    let [_, fp, q, _] = error_after_a_step(&u, "0", "2000");
    assert!(fp > 0.9 && q.abs() < 0.111, "{fp} {q}");
}

#[test]
fn bad_options_are_refused_with_one_line_exit_2_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let u = write(d, "u.csv", &input(1.0, 0.05, |_| 50.0));
    let cases: &[(&str, &str, &str)] = &[
        ("--valve-steps", "20", "item 1 '20': expected T:FACTOR"),
        ("--valve-steps", "20:1.3,40:x", "item 2 '40:x': factor 'x'"),
        (
            "--valve-steps",
            "x:1.3",
            "item 1 'x:1.3': time 'x' is not a number",
        ),
        (
            "--valve-steps",
            "inf:1.3",
            "time 'inf' is not a finite number",
        ),
        (
            "--valve-steps",
            "20:nan",
            "factor 'nan' is not a finite number",
        ),
        (
            "--valve-steps",
            "20:inf",
            "factor 'inf' is not a finite number",
        ),
        ("--valve-steps", "20:0", "factor 0 is outside 0.2..5"),
        ("--valve-steps", "20:-1", "factor -1 is outside 0.2..5"),
        ("--valve-steps", "20:0.19", "factor 0.19 is outside 0.2..5"),
        ("--valve-steps", "20:5.01", "factor 5.01 is outside 0.2..5"),
        (
            "--valve-steps",
            "20:1.3,40:0.7,30:1",
            "item 3 '30:1': time 30 s",
        ),
        (
            "--valve-steps",
            "20:1.3,20:0.7",
            "item 2 '20:0.7': time 20 s",
        ),
        ("--valve-steps", "20:1.3,", "item 2 '': expected T:FACTOR"),
        ("--valve-steps", "", "no steps given"),
        ("--valve-steps", "20:1\n3", "item 1 '20:1\\n3'"),
        (
            "--curve-error",
            "20.5",
            "--curve-error 20.5: must be within -20..20 %",
        ),
        ("--curve-error", "-25", "--curve-error -25: must be within"),
        (
            "--curve-error",
            "nan",
            "--curve-error 'nan': not a finite number",
        ),
        (
            "--curve-error",
            "-inf",
            "--curve-error '-inf': not a finite number",
        ),
        ("--curve-error", "5%", "--curve-error '5%': not a number"),
        (
            "--curve-error",
            "5,-25",
            "--curve-error -25: must be within",
        ),
        (
            "--curve-error",
            "5,8,1",
            "expected PCT or HEAD_PCT,TORQUE_PCT",
        ),
        ("--curve-error", "5,", "--curve-error '': not a number"),
        (
            "--water-inertia",
            "-0.1",
            "--water-inertia -0.1: must be 0 or within 0.001..10 mca·s²/l",
        ),
        ("--water-inertia", "1e-4", "--water-inertia 1e-4: must be 0"),
        ("--water-inertia", "10.5", "--water-inertia 10.5: must be 0"),
        (
            "--water-inertia",
            "nan",
            "--water-inertia 'nan': not a finite number",
        ),
        (
            "--water-inertia",
            "0.1x",
            "--water-inertia '0.1x': not a number",
        ),
        (
            "--drive-lag-ms",
            "-1",
            "--drive-lag-ms -1: must be within 0..2000 ms",
        ),
        (
            "--drive-lag-ms",
            "2001",
            "--drive-lag-ms 2001: must be within",
        ),
        // The value as typed, not in its shortest form (3e3).
        (
            "--drive-lag-ms",
            "3000",
            "--drive-lag-ms 3000: must be within 0..2000 ms",
        ),
        (
            "--flow-update-ms",
            " 3000",
            "--flow-update-ms 3000: must be within 0..2000 ms",
        ),
        (
            "--drive-lag-ms",
            "inf",
            "--drive-lag-ms 'inf': not a finite",
        ),
        (
            "--flow-lag-ms",
            "-1",
            "--flow-lag-ms -1: must be within 0..2000 ms",
        ),
        (
            "--flow-lag-ms",
            "2000.5",
            "--flow-lag-ms 2000.5: must be within",
        ),
        (
            "--flow-lag-ms",
            "inf",
            "--flow-lag-ms 'inf': not a finite number",
        ),
        (
            "--pressure-lag-ms",
            "1e4",
            "--pressure-lag-ms 1e4: must be within",
        ),
        (
            "--pressure-lag-ms",
            "NaN",
            "--pressure-lag-ms 'NaN': not a finite",
        ),
        (
            "--pressure-lag-ms",
            "20ms",
            "--pressure-lag-ms '20ms': not a number",
        ),
        (
            "--transmitter-delay-ms",
            "1500",
            "--transmitter-delay-ms 1500: must be within 0..1000 ms",
        ),
        (
            "--transmitter-delay-ms",
            "-inf",
            "--transmitter-delay-ms '-inf': not a finite number",
        ),
        (
            "--drive-slew-pct-s",
            "5",
            "--drive-slew-pct-s 5: must be 0 or within 10..100000 %/s",
        ),
        (
            "--drive-slew-pct-s",
            "-100",
            "--drive-slew-pct-s -100: must be 0 or within",
        ),
    ];
    for (k, (option, value, expected)) in cases.iter().enumerate() {
        let output = d.join(format!("out{k}.csv"));
        let out = pumpbench(&[
            "bench-data",
            "--input",
            &u,
            option,
            value,
            "--output",
            output.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        let what = format!("{option} {value:?}");
        assert_eq!(out.status.code(), Some(2), "{what}: {err}");
        assert_eq!(err.lines().count(), 1, "{what}: one line: {err}");
        assert!(err.contains(option), "{what}: names the option: {err}");
        assert!(
            err.contains(expected),
            "{what}: expected '{expected}' in: {err}"
        );
        assert!(
            out.stdout.is_empty() && !output.exists(),
            "{what}: no output"
        );
    }
    let left: Vec<_> = std::fs::read_dir(d).unwrap().collect();
    assert_eq!(left.len(), 1, "only the input, no partial files");
    // The limits themselves are accepted.
    let r = Table::parse(&bench_data(&[
        "--input",
        &u,
        "--truth",
        "--curve-error",
        "-20",
        "--flow-lag-ms",
        "2000",
        "--pressure-lag-ms",
        "0",
        "--valve-steps",
        "0.2:0.2,0.5:5",
    ]));
    assert_eq!(r.col("k2_true").last(), Some(&(0.1082 * 5.0)));
    bench_data(&["--input", &u, "--curve-error", "20"]);
}

/// The true rows of a record of `u` with `extra` options (seed 1, truth columns).
fn truth_of(u: &str, extra: &[&str]) -> Table {
    let mut args = vec!["--input", u, "--truth"];
    args.extend_from_slice(extra);
    Table::parse(&bench_data(&args))
}

/// Water inertia makes the flow a state: after a torque step it lags the inertia-free bench's,
/// the more the larger the inertia, and settles to the same steady state; a valve step moves
/// the flow over a time, not at once.
#[test]
fn water_inertia_delays_the_flow_and_keeps_the_steady_state() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(
        dir.path(),
        "u.csv",
        &input(8.0, 0.01, |t| if t < 1.0 { 30.0 } else { 60.0 }),
    );
    let steps = ["--valve-steps", "5:1.3"];
    let none = truth_of(&u, &steps);
    let light = truth_of(&u, &[steps[0], steps[1], "--water-inertia", "0.02"]);
    let heavy = truth_of(&u, &[steps[0], steps[1], "--water-inertia", "0.1"]);
    let q = |r: &Table, t: f64| r.col("flow_true")[row_at(r, t)];
    // At rest before the step, all three are the same steady state.
    for r in [&light, &heavy] {
        assert!((q(r, 0.5) / q(&none, 0.5) - 1.0).abs() < 1e-9);
    }
    // 50 ms after the torque step the flow has risen less with more inertia.
    let (q0, ql, qh) = (q(&none, 1.05), q(&light, 1.05), q(&heavy, 1.05));
    let base = q(&none, 1.0);
    assert!(
        q0 - base > ql - base && ql - base > qh - base && qh > base,
        "rise 50 ms after the step: {} {} {}",
        q0 - base,
        ql - base,
        qh - base
    );
    // Settled again well before the valve step.
    for r in [&light, &heavy] {
        assert!((q(r, 4.9) / q(&none, 4.9) - 1.0).abs() < 1e-4);
    }
    // The valve closes at 5 s: without inertia the flow drops at once, with it over tens of ms.
    let drop = |r: &Table| (q(r, 4.99) - q(r, 5.01)) / (q(r, 4.99) - q(r, 7.9));
    assert!(drop(&none) > 0.5, "no inertia: {}", drop(&none));
    assert!(
        drop(&heavy) < 0.5 * drop(&none),
        "inertia 0.1: {}",
        drop(&heavy)
    );
    // Pressure follows the flow through the valve: Hs = k2² Q² − c at every row.
    let (p, k2, qq) = (
        heavy.col("pressure_true"),
        heavy.col("k2_true"),
        heavy.col("flow_true"),
    );
    for i in 0..p.len() {
        let hs = k2[i] * k2[i] * qq[i] * qq[i] - 0.252;
        assert!(
            (p[i] - hs).abs() < 1e-6 * (1.0 + hs.abs()),
            "row {i}: {} {hs}",
            p[i]
        );
    }
}

/// The drive's torque lag delays the speed's response to a torque step (about by the lag)
/// and keeps the steady state.
#[test]
fn the_drive_lag_delays_the_speed_and_keeps_the_steady_state() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(
        dir.path(),
        "u.csv",
        &input(6.0, 0.01, |t| if t < 1.0 { 30.0 } else { 60.0 }),
    );
    let none = truth_of(&u, &[]);
    let lag = truth_of(&u, &["--drive-lag-ms", "50"]);
    let w = |r: &Table, t: f64| r.col("speed_true")[row_at(r, t)];
    let base = w(&none, 1.0);
    assert_eq!(w(&lag, 1.0), base);
    // 20 ms after the step the lagged drive has delivered about 1 − e^{−20/50} ≈ 0.33 of the
    // extra torque: the speed has risen by much less.
    let (r0, r1) = (w(&none, 1.02) - base, w(&lag, 1.02) - base);
    assert!(r1 > 0.0 && r1 < 0.5 * r0, "{r0} {r1}");
    // Settled to the same speed.
    assert!((w(&lag, 5.9) / w(&none, 5.9) - 1.0).abs() < 1e-6);
    // Both at once, with a two-sided curve error, run and stay finite and positive.
    let both = truth_of(
        &u,
        &[
            "--drive-lag-ms",
            "50",
            "--water-inertia",
            "0.1",
            "--curve-error",
            "-8,8",
        ],
    );
    assert!(both
        .col("flow_true")
        .iter()
        .all(|q| q.is_finite() && *q > 0.0));
}

/// `--rotor-inertia F` reaches the bench: the speed's first rise after a torque step is
/// 1 / F of the paper's rotor's (the true speed, `--truth`), the steady speed the same.
#[test]
fn a_heavier_rotor_accelerates_slower() {
    let dir = tempfile::tempdir().unwrap();
    let u = write(
        dir.path(),
        "u.csv",
        &input(4.0, 0.01, |t| if t < 3.0 { 40.0 } else { 60.0 }),
    );
    let rise = |f: &str| {
        let r = Table::parse(&bench_data(&[
            "--input",
            &u,
            "--truth",
            "--rotor-inertia",
            f,
        ]));
        let w = r.col("speed_true");
        let (k0, k1) = (row_at(&r, 3.0), row_at(&r, 3.01));
        (w[k0], w[k1] - w[k0])
    };
    let (w1, r1) = rise("1");
    for (f, factor) in [("0.5", 0.5), ("2", 2.0)] {
        let (w, r) = rise(f);
        assert!((w / w1 - 1.0).abs() < 1e-6, "{f}: steady {w} against {w1}");
        assert!(
            (r * factor / r1 - 1.0).abs() < 0.08,
            "{f}: {r} against {r1}"
        );
    }
}
