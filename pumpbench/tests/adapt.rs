//! `simulate --model narmax --adapt output-map`: a model identified on a bench's own record
//! with the valve fixed, then that bench's record whose valve moves ±30 %, free run per valve
//! segment against the truth (the protocol). Benches with seeds used nowhere else.

mod common;
use common::{ok, pumpbench, refused, Table};
use std::path::Path;

/// Valve segments: (from, to) s; the record's valve steps at 50, 100, 150, 200 s.
const SEGMENTS: [(f64, f64); 5] = [
    (10.0, 50.0),
    (60.0, 100.0),
    (110.0, 150.0),
    (160.0, 200.0),
    (210.0, 250.1),
];

fn run(args: &[&str]) -> String {
    ok(&pumpbench(args), &args.join(" "))
}

/// The words of `line` (a command line without its paths) followed by `more`.
fn words<'a>(line: &'a str, more: &[&'a str]) -> Vec<&'a str> {
    line.split_whitespace()
        .chain(more.iter().copied())
        .collect()
}

/// The per-segment free-run MAPE (%) of `sim`'s `column` against `truth`'s `true_column`,
/// from 10 s after each step (rows with a true value of 0 left out).
fn segment_mape(sim: &str, column: &str, truth: &str, true_column: &str) -> Vec<f64> {
    let (sim, truth) = (Table::parse(sim), Table::parse(truth));
    let (t, y) = (sim.col("t_s"), sim.col(column));
    let truth_at: std::collections::HashMap<u64, f64> = truth
        .col("t_s")
        .iter()
        .zip(truth.col(true_column))
        .map(|(t, v)| (t.to_bits(), v))
        .collect();
    SEGMENTS
        .iter()
        .map(|&(a, b)| {
            let (mut sum, mut n) = (0.0, 0);
            for (t, y) in t.iter().zip(&y) {
                let v = truth_at[&t.to_bits()];
                if *t >= a && *t < b && v != 0.0 {
                    sum += ((y - v) / v).abs();
                    n += 1;
                }
            }
            assert!(n > 300, "{n} rows in {a}..{b}");
            100.0 * sum / f64::from(n)
        })
        .collect()
}

/// One bench and one target: identify on the fixed-valve record, then the valve-step record
/// through `simulate` with and without the map, in `precision`, once for each set of
/// `simulate` options in `extras` (one result each).
fn case(
    dir: &Path,
    bench: &[&str],
    target: &str,
    ts_ms: &str,
    sizes: [&str; 3],
    seed: u64,
    extras: &[&[&str]],
) -> Vec<[Vec<f64>; 3]> {
    let p = |name: &str| dir.join(format!("{target}_{name}")).display().to_string();
    let (u_id, u_val, id, val, model) = (
        p("u_id.csv"),
        p("u_val.csv"),
        p("id.csv"),
        p("val.csv"),
        p("m.json"),
    );
    let s = |k: u64| (seed + k).to_string();
    let id_s = if ts_ms == "50" { "600" } else { "1200" };
    run(&[
        "excite",
        "--seed",
        &s(0),
        "--seconds",
        id_s,
        "--ts-ms",
        ts_ms,
        "--output",
        &u_id,
    ]);
    run(&[
        "excite",
        "--seed",
        &s(1),
        "--seconds",
        "250",
        "--ts-ms",
        ts_ms,
        "--output",
        &u_val,
    ]);
    let mut a = vec![
        "bench-data",
        "--input",
        &u_id,
        "--seed",
        "3",
        "--output",
        &id,
    ];
    a.extend_from_slice(bench);
    run(&a);
    let mut a = vec![
        "bench-data",
        "--input",
        &u_val,
        "--seed",
        "4",
        "--truth",
        "--output",
        &val,
        "--valve-steps",
        "50:1.3,100:1,150:0.7,200:1",
    ];
    a.extend_from_slice(bench);
    run(&a);
    run(&[
        "identify", "--data", &id, "--target", target, "--na", sizes[0], "--nb", sizes[1],
        "--hidden", sizes[2], "--output", &model,
    ]);
    let truth = std::fs::read_to_string(&val).unwrap();
    let column = format!(
        "{target}_{}",
        if target == "pressure" { "mca" } else { "lps" }
    );
    let true_column = format!("{target}_true");
    let sim = |precision: &str, adapt: &str, extra: &[&str]| {
        let mut a = vec![
            "simulate",
            "--model",
            "narmax",
            "--weights",
            &model,
            "--input",
            &val,
            "--precision",
            precision,
            "--adapt",
            adapt,
        ];
        a.extend_from_slice(extra);
        let out = run(&a);
        segment_mape(&out, &column, &truth, &true_column)
    };
    extras
        .iter()
        .map(|extra| {
            [
                sim("q15", "off", extra),
                sim("q15", "output-map", extra),
                sim("f64", "output-map", extra),
            ]
        })
        .collect()
}

/// The targets: every valve segment ≤ 1.5 %, the fixed valve no worse than the model
/// alone by more than 0.1 point, Q15 within 0.1 point of f64. `missed`: the segments that
/// miss the 1.5 % (measured, documented in docs/narmax.md); each must still be ten times
/// better than the model alone.
fn check(what: &str, [off, q15, f64_]: [Vec<f64>; 3], missed: &[usize]) {
    let show = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.2}"))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    println!(
        "{what}: off {}, output map q15 {}, f64 {}",
        show(&off),
        show(&q15),
        show(&f64_)
    );
    assert!(
        off[1..].iter().any(|&x| x > 3.0),
        "{what}: the valve steps must matter: {off:?}"
    );
    for (k, (&a, &b)) in q15.iter().zip(&f64_).enumerate() {
        if missed.contains(&k) {
            assert!(
                a > 1.5,
                "{what}: segment {k} now meets the target: update the docs"
            );
            assert!(
                a * 10.0 < off[k],
                "{what}: segment {k}: {a:.2} % against {:.2}",
                off[k]
            );
        } else {
            assert!(a <= 1.5, "{what}: segment {k}: {a:.2} % > 1.5 %");
        }
        assert!(
            (a - b).abs() <= 0.1,
            "{what}: segment {k}: q15 {a:.3} vs f64 {b:.3}"
        );
    }
    assert!(
        q15[0] <= off[0] + 0.1,
        "{what}: fixed valve {:.3} vs {:.3}",
        q15[0],
        off[0]
    );
}

/// The `transmitter` entry `identify` wrote in the model file at `path`.
fn transmitter(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["transmitter"].clone()
}

/// The transmitter's lag `identify` wrote in the model file of `target` in `dir`: (lag, ms;
/// trusted).
fn file_lag(dir: &Path, target: &str) -> (f64, bool) {
    let t = transmitter(&dir.join(format!("{target}_m.json")));
    (
        t["lag_s"].as_f64().unwrap() * 1e3,
        t["trusted"].as_bool().unwrap(),
    )
}

/// The CSV at `path` with every `every`-th row's `speed_rpm` cell emptied.
fn with_empty_speed(path: &str, every: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let c = header.split(',').position(|h| h == "speed_rpm").unwrap();
    let rows: Vec<String> = lines
        .enumerate()
        .map(|(k, l)| {
            let mut cells: Vec<&str> = l.split(',').collect();
            if k % every == every / 2 {
                cells[c] = "";
            }
            cells.join(",")
        })
        .collect();
    format!("{header}\n{}\n", rows.join("\n"))
}

/// The reading (`--sensor-lag-ms 0`), the default, and a given lag.
const READING: &[&str] = &["--sensor-lag-ms", "0"];

#[test]
fn the_output_map_follows_the_valve_pressure_and_flow() {
    let dir = tempfile::tempdir().unwrap();
    let bench = ["--curve-error", "-4,6", "--drive-lag-ms", "15"];
    // The prediction of the reading: the valve ×0.7 segment misses, 2.08 % (the pump at
    // 5..10 % torque gives 0.02..0.3 mca there, where a few mm are several percent; the
    // reading itself is that far off the truth).
    // By default, taken back through the transmitter's lag that identify found from the
    // record's speed (bench-data's pressure transmitter: 20 ms; flow: 40 ms): every segment
    // meets, the ×0.7 one too; and so with the stated lag.
    // (target, period ms, sizes, seed, stated lag ms, the lag found within, segments the
    // reading misses)
    let runs = [
        ("pressure", "50", ["6", "6", "7"], 901, "20", 3.0, &[3][..]),
        ("flow", "100", ["7", "7", "6"], 911, "40", 5.0, &[][..]),
    ];
    for (target, ts, sizes, seed, stated_ms, within, reading_misses) in runs {
        let stated_lag: &[&str] = &["--sensor-lag-ms", stated_ms];
        let [reading, default, stated] = case(
            dir.path(),
            &bench,
            target,
            ts,
            sizes,
            seed,
            &[READING, &[], stated_lag],
        )
        .try_into()
        .unwrap();
        let (lag, trusted) = file_lag(dir.path(), target);
        println!("{target} transmitter: {stated_ms} ms, identify found {lag:.1} ms");
        let stated_ms: f64 = stated_ms.parse().unwrap();
        assert!(trusted && (lag - stated_ms).abs() <= within, "{lag} ms");
        check(&format!("{target}, the reading"), reading, reading_misses);
        check(&format!("{target}, identify's lag"), default, &[]);
        check(
            &format!("{target}, --sensor-lag-ms {stated_ms}"),
            stated,
            &[],
        );
    }
}

/// A slow flow transmitter (150 ms; bench D of docs/narmax.md; excitation seeds used nowhere
/// else): the model predicts its readings, which are themselves 2.7..3.6 % off the process
/// value on such a bench, and so is the model, map or not. Taken back through the lag
/// identify found (by default) or the transmitter's stated time constant
/// (`--sensor-lag-ms 150`), every segment meets the target.
#[test]
fn a_slow_transmitter_taken_back_through_its_lag() {
    let dir = tempfile::tempdir().unwrap();
    let bench = ["--curve-error", "5,-5", "--flow-lag-ms", "150"];
    let sizes = ["7", "7", "6"];
    let lagged: &[&str] = &["--sensor-lag-ms", "150"];
    let [[_, reading, _], default, stated] = case(
        dir.path(),
        &bench,
        "flow",
        "100",
        sizes,
        941,
        &[READING, &[], lagged],
    )
    .try_into()
    .unwrap();
    let (lag, trusted) = file_lag(dir.path(), "flow");
    println!("flow transmitter: 150 ms, identify found {lag:.1} ms");
    assert!(trusted && (lag - 150.0).abs() <= 8.0, "{lag} ms");
    println!("flow, 150 ms transmitter, the map's prediction of the reading: {reading:.2?}");
    assert!(reading.iter().all(|&x| x > 1.5), "{reading:?}");
    check("flow, 150 ms transmitter, identify's lag", default, &[]);
    check("flow, 150 ms transmitter, --sensor-lag-ms 150", stated, &[]);
}

/// A water column of its own lags the flow and the pressure behind the speed too, by an
/// amount that changes with the flow: identify finds the whole lag long, takes out the part
/// that differs between low and high speeds, and what is left is the transmitter's (bench F
/// of docs/narmax.md, its own excitation seeds). A speed four samples late leaves a fit that
/// explains nothing: the lag is not used and `simulate` gives the prediction of the reading,
/// byte for byte `--sensor-lag-ms 0`. A few empty speed cells are left out; over 1 %, or no
/// `speed_rpm` column, no lag.
#[test]
fn a_water_column_is_taken_apart_and_a_late_speed_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bench = [
        "--curve-error",
        "-5",
        "--water-inertia",
        "0.1",
        "--drive-lag-ms",
        "20",
    ];
    let [reading, default] = case(
        d,
        &bench,
        "pressure",
        "50",
        ["6", "6", "7"],
        961,
        &[READING, &[]],
    )
    .try_into()
    .unwrap();
    let t = &transmitter(&d.join("pressure_m.json"));
    let (lag, found) = (
        t["lag_s"].as_f64().unwrap() * 1e3,
        t["found_lag_s"].as_f64().unwrap() * 1e3,
    );
    println!(
        "water column 0.1, 20 ms transmitter: found {found} ms, the transmitter's {lag:.1} ms"
    );
    assert!(t["trusted"] == true && found > 50.0, "{t}");
    assert!((lag - 20.0).abs() <= 8.0, "{t}");
    check("pressure behind a water column, the reading", reading, &[]);
    check(
        "pressure behind a water column, identify's lag",
        default,
        &[],
    );

    let id = d.join("pressure_id.csv").display().to_string();
    let p = |name: &str| d.join(name).display().to_string();
    let [late, bare, m, m_bare, val] = [
        "late.csv",
        "bare.csv",
        "m.json",
        "bare.json",
        "pressure_val.csv",
    ]
    .map(p);
    let sizes = "--target pressure --na 6 --nb 6 --hidden 7 --epochs 10";
    let identify = |data: &str, model: &str| {
        let out = pumpbench(&words(
            &format!("identify {sizes} --data"),
            &[data, "--output", model],
        ));
        ok(&out, "identify");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let table = Table::parse(&std::fs::read_to_string(&id).unwrap());
    let (t_s, u, w, y) = (
        table.col("t_s"),
        table.col("torque_ref_pct"),
        table.col("speed_rpm"),
        table.col("pressure_mca"),
    );
    // The speed four samples late (200 ms: a drive polled far slower than the record).
    let rows: String = (0..t_s.len())
        .map(|k| format!("{},{},{},{}\n", t_s[k], u[k], w[k.saturating_sub(4)], y[k]))
        .collect();
    std::fs::write(
        &late,
        format!("t_s,torque_ref_pct,speed_rpm,pressure_mca\n{rows}"),
    )
    .unwrap();
    let err = identify(&late, &m);
    assert!(err.contains("not used"), "{err}");
    let late_entry = transmitter(Path::new(&m));
    assert_eq!(late_entry["trusted"], false, "{late_entry}");
    let sim = |extra: &[&str]| {
        let line = "simulate --model narmax --precision q15 --adapt output-map --weights";
        run(&words(line, &[&m, "--input", &val])
            .into_iter()
            .chain(extra.iter().copied())
            .collect::<Vec<_>>())
    };
    assert_eq!(sim(&[]), sim(READING));
    // A few speed cells empty (a VFD read that failed, in the controller's record): the lag
    // is still found; over 1 % of them: not.
    std::fs::write(&late, with_empty_speed(&id, 1000)).unwrap();
    identify(&late, &m);
    let after = &transmitter(Path::new(&m));
    assert_eq!(
        (&after["lag_s"], &after["trusted"]),
        (&t["lag_s"], &t["trusted"]),
        "12 speed cells empty: {after}"
    );
    std::fs::write(&late, with_empty_speed(&id, 50)).unwrap();
    let err = identify(&late, &m);
    assert!(err.contains("(over 1 %)"), "{err}");
    // Without the speed column.
    let rows: String = (0..t_s.len())
        .map(|k| format!("{},{},{}\n", t_s[k], u[k], y[k]))
        .collect();
    std::fs::write(&bare, format!("t_s,torque_ref_pct,pressure_mca\n{rows}")).unwrap();
    let err = identify(&bare, &m_bare);
    assert!(err.contains("no speed_rpm column"), "{err}");
    assert!(!std::fs::read_to_string(&m_bare)
        .unwrap()
        .contains("transmitter"));
}

#[test]
fn bad_adaptation_options_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = common::write(d, "u.csv", "t_s,torque_ref_pct\n0,10\n0.05,20\n");
    let r = pumpbench(&words(
        "simulate --model whitebox --adapt output-map --input",
        &[&input],
    ));
    refused(
        &r,
        &["--adapt and --sensor-lag-ms are for NARMAX"],
        "white box",
    );
    let r = pumpbench(&words(
        "simulate --model whitebox --sensor-lag-ms 100 --input",
        &[&input],
    ));
    refused(
        &r,
        &["--sensor-lag-ms are for NARMAX"],
        "white box, sensor lag",
    );
    // The shipped pressure model on `input`, with `extra` options.
    let shipped = |input: &str, extra: &str| {
        let line = "simulate --model narmax --weights ../models/pressure.json";
        pumpbench(&words(line, &words(extra, &["--input", input])))
    };
    let r = shipped(&input, "--adapt-tau-s 5");
    refused(
        &r,
        &["--adapt-tau-s is the output map's"],
        "a memory without the map",
    );
    refused(
        &shipped(&input, "--adapt output-map"),
        &["pressure_mca"],
        "no measurement column",
    );
    let rec = common::write(
        d,
        "r.csv",
        &(0..40)
            .map(|k| format!("{},30,2.0\n", f64::from(k) * 0.05))
            .fold("t_s,torque_ref_pct,pressure_mca\n".to_string(), |s, l| {
                s + &l
            }),
    );
    let r = shipped(&rec, "--adapt output-map --adapt-tau-s 0.01");
    refused(&r, &["--adapt-tau-s 0.01"], "memory too short");
    for bad in ["-1", "2001", "nan", "x"] {
        let r = shipped(&rec, &format!("--sensor-lag-ms {bad}"));
        refused(&r, &["--sensor-lag-ms"], bad);
    }
    let r = shipped(&rec, "--adapt output-map --adapt-tau-s 61");
    refused(
        &r,
        &["--adapt-tau-s 61: must be within 0.1..=60 s"],
        "memory too long",
    );
}

/// A pump under pressure control holds its torque: the samples then show one operating point.
/// The map must still follow a valve step there (a review: a −50 % pressure at 70 % torque put
/// the first map into a reset loop, 103 % off), without falling back.
#[test]
fn the_output_map_follows_the_valve_at_a_held_torque() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name).display().to_string();
    let [u, id, m, held_csv, val] = ["u.csv", "id.csv", "m.json", "held.csv", "val.csv"].map(p);
    let bench = "--curve-error 5,-3";
    run(&words(
        "excite --seed 931 --seconds 600 --ts-ms 50 --output",
        &[&u],
    ));
    run(&words(
        &format!("bench-data {bench} --seed 5 --input"),
        &[&u, "--output", &id],
    ));
    let sizes = "--target pressure --na 6 --nb 6 --hidden 7";
    run(&words(
        &format!("identify {sizes} --data"),
        &[&id, "--output", &m],
    ));
    let held: String = (0..=2400)
        .map(|k| format!("{:.2},70\n", f64::from(k) * 0.05))
        .fold("t_s,torque_ref_pct\n".into(), |s, l| s + &l);
    std::fs::write(&held_csv, held).unwrap();
    let valve = format!("bench-data {bench} --seed 6 --truth --valve-steps 40:0.7,80:1.3 --input");
    run(&words(&valve, &[&held_csv, "--output", &val]));
    let line = "simulate --model narmax --precision q15 --adapt output-map --weights";
    let out = pumpbench(&words(line, &[&m, "--input", &val]));
    let sim = ok(&out, "simulate");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(" 0 fallbacks"), "{err}");
    let truth = std::fs::read_to_string(&val).unwrap();
    let (sim, truth) = (Table::parse(&sim), Table::parse(&truth));
    let (t, y, v) = (
        sim.col("t_s"),
        sim.col("pressure_mca"),
        truth.col("pressure_true"),
    );
    for (from, to) in [(10.0, 40.0), (50.0, 80.0), (90.0, 120.1)] {
        let e: Vec<f64> = (0..t.len())
            .filter(|&k| t[k] >= from && t[k] < to)
            .map(|k| ((y[k] - v[k]) / v[k]).abs())
            .collect();
        let mape = 100.0 * e.iter().sum::<f64>() / e.len() as f64;
        println!("held torque, {from}..{to} s: {mape:.3} %");
        assert!(mape <= 1.5, "{from}..{to} s: {mape:.2} %");
    }
}
