//! The observer when a sensor is lost, on benches it was not tuned on: `bench-data` records
//! with water-column inertia, a drive with its own torque lag, slow flow transmitters and
//! curves off in all four sign combinations, 300 s with the valve ×1.3 at 60 s, back at
//! 120 s, ×0.7 at 180 s, back at 240 s. Each record three times: whole, flow cells empty from
//! 150 s (the flow meter fails), speed cells empty from 150 s (the VFD's speed is lost), so
//! two of the valve steps happen while the sensor is gone. Through `pumpbench observe
//! --precision f32` (the MCU's arithmetic), against the bench's truth:
//! - flow without the meter and speed without the VFD's, MAPE over 150..300 s: ≤ 1 % (≤ 2 %
//!   at the hard end of the ranges, all at once);
//! - k2 MAPE per valve segment, from 2 s after each step: ≤ 3 %;
//! - flow, speed and k2 within 2 σ (the σ the observer publishes) on ≥ 90 % of the rows.

mod common;
use common::{ok, pumpbench, write, Table};
use std::path::Path;

/// How a bench differs from the paper's model.
struct Bench {
    name: &'static str,
    /// mca·s²/l.
    inertia: &'static str,
    drive_lag_ms: &'static str,
    flow_lag_ms: &'static str,
    /// Head and load-torque curve errors, %.
    curves: &'static str,
    /// The MAPE limit of flow and speed without their sensors, %.
    limit_pct: f64,
}

const BENCHES: [Bench; 7] = [
    // The bench of the issue: all dynamics, a 150 ms flow transmitter, curves off.
    Bench {
        name: "issue",
        inertia: "0.05",
        drive_lag_ms: "30",
        flow_lag_ms: "150",
        curves: "5,-5",
        limit_pct: 1.0,
    },
    // Curves 8 % off in the four sign combinations.
    Bench {
        name: "head+8 torque+8",
        inertia: "0.05",
        drive_lag_ms: "25",
        flow_lag_ms: "100",
        curves: "8,8",
        limit_pct: 1.0,
    },
    Bench {
        name: "head+8 torque-8",
        inertia: "0.05",
        drive_lag_ms: "25",
        flow_lag_ms: "100",
        curves: "8,-8",
        limit_pct: 1.0,
    },
    Bench {
        name: "head-8 torque+8",
        inertia: "0.05",
        drive_lag_ms: "25",
        flow_lag_ms: "100",
        curves: "-8,8",
        limit_pct: 1.0,
    },
    Bench {
        name: "head-8 torque-8",
        inertia: "0.05",
        drive_lag_ms: "25",
        flow_lag_ms: "100",
        curves: "-8,-8",
        limit_pct: 1.0,
    },
    // The soft end of the ranges: no inertia, no drive lag, a 40 ms transmitter.
    Bench {
        name: "soft end",
        inertia: "0",
        drive_lag_ms: "0",
        flow_lag_ms: "40",
        curves: "5,-5",
        limit_pct: 1.0,
    },
    // The hard end, all at once.
    Bench {
        name: "hard end",
        inertia: "0.1",
        drive_lag_ms: "50",
        flow_lag_ms: "200",
        curves: "5,5",
        limit_pct: 2.0,
    },
];

const STEPS: &str = "60:1.3,120:1,180:0.7,240:1";
const LOST_FROM_S: f64 = 150.0;

/// The three records of `b`: whole, no flow from 150 s, no speed from 150 s.
fn records(dir: &Path, u: &str, b: &Bench) -> [String; 3] {
    let text = ok(
        &pumpbench(&[
            "bench-data",
            "--input",
            u,
            "--seed",
            "11",
            "--truth",
            "--valve-steps",
            STEPS,
            "--curve-error",
            b.curves,
            "--water-inertia",
            b.inertia,
            "--drive-lag-ms",
            b.drive_lag_ms,
            "--flow-lag-ms",
            b.flow_lag_ms,
        ]),
        b.name,
    );
    let blank = |column: usize| {
        let mut out = String::new();
        for (k, line) in text.lines().enumerate() {
            let mut cells: Vec<&str> = line.split(',').collect();
            if k > 0 && cells[0].parse::<f64>().unwrap() >= LOST_FROM_S {
                cells[column] = "";
            }
            out += &cells.join(",");
            out.push('\n');
        }
        out
    };
    // t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca,...
    let tag = b.name.replace(' ', "_");
    [
        write(dir, &format!("{tag}.csv"), &text),
        write(dir, &format!("{tag}_no_flow.csv"), &blank(3)),
        write(dir, &format!("{tag}_no_speed.csv"), &blank(2)),
    ]
}

/// The figures of one observed record.
#[derive(Debug)]
struct Figures {
    flow_mape_lost: f64,
    speed_mape_lost: f64,
    k2_mape_worst_segment: f64,
    coverage: [f64; 3],
}

fn figures(record: &str) -> Figures {
    let truth = Table::parse(
        &std::fs::read_to_string(record)
            .unwrap()
            .replace(",,", ",0,"),
    );
    let est = Table::parse(&ok(
        &pumpbench(&["observe", "--data", record, "--precision", "f32"]),
        record,
    ));
    let t = truth.col("t_s");
    let n = t.len();
    let mape = |e: &[f64], tr: &[f64], rows: &[usize]| {
        100.0
            * rows
                .iter()
                .map(|&i| (e[i] / tr[i] - 1.0).abs())
                .sum::<f64>()
            / rows.len() as f64
    };
    let lost: Vec<usize> = (0..n).filter(|&i| t[i] >= LOST_FROM_S).collect();
    let (q, w, k) = (
        est.col("flow_lps"),
        est.col("speed_rpm"),
        est.col("valve_k2"),
    );
    let (qt, wt, kt) = (
        truth.col("flow_true"),
        truth.col("speed_true"),
        truth.col("k2_true"),
    );
    let k2_mape_worst_segment = [0.0, 60.0, 120.0, 180.0, 240.0]
        .iter()
        .map(|&from| {
            let rows: Vec<usize> = (0..n)
                .filter(|&i| t[i] >= from + 2.0 && t[i] < from + 60.0)
                .collect();
            mape(&k, &kt, &rows)
        })
        .fold(0.0, f64::max);
    let cover = |e: &[f64], tr: &[f64], sd: &[f64]| {
        100.0
            * (0..n)
                .filter(|&i| (e[i] - tr[i]).abs() <= 2.0 * sd[i])
                .count() as f64
            / n as f64
    };
    Figures {
        flow_mape_lost: mape(&q, &qt, &lost),
        speed_mape_lost: mape(&w, &wt, &lost),
        k2_mape_worst_segment,
        coverage: [
            cover(&q, &qt, &est.col("flow_sd_lps")),
            cover(&w, &wt, &est.col("speed_sd_rpm")),
            cover(&k, &kt, &est.col("valve_k2_sd")),
        ],
    }
}

#[test]
fn a_lost_sensor_is_covered_on_benches_the_observer_was_not_tuned_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let u = d.join("u.csv");
    ok(
        &pumpbench(&[
            "excite",
            "--seed",
            "3",
            "--seconds",
            "300",
            "--output",
            u.to_str().unwrap(),
        ]),
        "excite",
    );
    let u = u.to_str().unwrap();
    let mut failures = vec![];
    for b in &BENCHES {
        let [whole, no_flow, no_speed] = records(d, u, b);
        for (variant, record) in [
            ("whole", &whole),
            ("no flow", &no_flow),
            ("no speed", &no_speed),
        ] {
            let f = figures(record);
            println!(
                "{:16} {variant:9} flow MAPE 150-300 s {:5.2} %, speed {:5.2} %, k2 worst \
                 segment {:5.2} %; within 2 σ: flow {:5.1} %, speed {:5.1} %, k2 {:5.1} %",
                b.name,
                f.flow_mape_lost,
                f.speed_mape_lost,
                f.k2_mape_worst_segment,
                f.coverage[0],
                f.coverage[1],
                f.coverage[2]
            );
            let lost_mape = match variant {
                "no flow" => f.flow_mape_lost,
                "no speed" => f.speed_mape_lost,
                _ => f.flow_mape_lost.max(f.speed_mape_lost),
            };
            if lost_mape > b.limit_pct
                || f.k2_mape_worst_segment > 3.0
                || f.coverage.iter().any(|&c| c < 90.0)
            {
                failures.push(format!("{} {variant}: {f:?}", b.name));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
