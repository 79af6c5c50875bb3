//! `pumpbench study`: the paper's study end to end. Identifies its two NARMAX models (pressure
//! and flow, the paper's sizes), validates them and the white-box model on validation records
//! and steady-state points, and writes the models, a Table 1 in Markdown and the paper's
//! figures 4, 5, 7 and 8 as PNG files. With `--demo` it first makes all of its data with the
//! synthetic bench (`excite` + `bench-data`), so the whole study runs without a bench.

use crate::error::Failure;
use crate::input::{read_columns, read_input_to_integrate, read_series, Series, TorqueInput};
use crate::modelfile::{ModelFile, Target};
use crate::narmaxcmd::{self, Identify};
use crate::num::Short;
use crate::train::Structure;
use crate::{benchdata, excite, output, plots};
use model_core::{Scheme, Signals, WhiteBox};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The paper's pressure model: na = 6, nb = 6, nc = 0, nk = 1, 7 hidden units.
pub const PRESSURE_STRUCTURE: Structure = Structure {
    na: 6,
    nb: 6,
    nc: 0,
    nk: 1,
    hidden: 7,
};
/// The paper's flow model: na = 7, nb = 7, nc = 0, nk = 1, 6 hidden units.
pub const FLOW_STRUCTURE: Structure = Structure {
    na: 7,
    nb: 7,
    nc: 0,
    nk: 1,
    hidden: 6,
};
/// Accepted LM epochs (as `identify`'s default).
pub const EPOCHS: usize = 40;
/// Seed of the initial weights (as `identify`'s default).
pub const SEED: u64 = 1;
/// Seeded starts (as `identify`'s default).
pub const STARTS: usize = 4;
/// Largest RK4 step of the white-box simulation, s.
const WHITEBOX_STEP_S: f64 = 1e-3;
/// The model files `study` writes into `--out`.
const MODEL_FILES: [&str; 2] = ["pressure_model.json", "flow_model.json"];
/// Its table.
const TABLE_FILE: &str = "table1.md";
/// The data files `study --demo` writes into `--out`.
const DEMO_FILES: [&str; 5] = [
    "train_pressure.csv",
    "val_pressure.csv",
    "train_flow.csv",
    "val_flow.csv",
    "static.csv",
];

/// The data files of a study.
#[derive(Debug, Clone)]
pub struct Files {
    /// Pressure training record (`t_s,torque_ref_pct,…,pressure_mca`).
    pub train_pressure: PathBuf,
    /// Flow training record (`t_s,torque_ref_pct,…,flow_lps`).
    pub train_flow: PathBuf,
    /// Pressure validation record.
    pub val_pressure: PathBuf,
    /// Flow validation record.
    pub val_flow: PathBuf,
    /// Steady-state points `torque_ref_pct,pressure_mca,flow_lps`.
    pub statics: PathBuf,
}

/// Options of `study`.
pub struct Study {
    /// The data; `None` for `--demo` (synthetic data written into `out`).
    pub files: Option<Files>,
    /// Output folder (created if missing).
    pub out: PathBuf,
}

/// MAPEs of one model on one target, %.
#[derive(Debug, Clone, Copy)]
pub struct Scores {
    /// MAPE_s on every steady-state point.
    pub mape_s: f64,
    /// MAPE_s without the lowest-torque point (`None` if it was the only one).
    pub mape_s_without_lowest: Option<f64>,
    /// MAPE_d of the free run on the validation record (seed rows skipped).
    pub mape_d: f64,
}

/// One target's results: the records and curves the figures show, and both models' scores.
pub struct TargetResult {
    /// What was modelled.
    pub target: Target,
    /// Validation times, s.
    pub t_s: Vec<f64>,
    /// Validation measurement.
    pub measured: Vec<f64>,
    /// NARMAX free run (its first `skip` rows are the measurement that seeds it).
    pub narmax: Vec<f64>,
    /// White-box simulation of the validation torque.
    pub whitebox: Vec<f64>,
    /// Rows left out of MAPE_d (the NARMAX model's largest lag).
    pub skip: usize,
    /// Steady-state points `(torque %, measured)`.
    pub statics: Vec<(f64, f64)>,
    /// NARMAX steady curve `(torque %, output)`.
    pub narmax_curve: Vec<(f64, f64)>,
    /// White-box steady curve `(torque %, output)`.
    pub whitebox_curve: Vec<(f64, f64)>,
    /// NARMAX scores.
    pub narmax_scores: Scores,
    /// White-box scores.
    pub whitebox_scores: Scores,
}

fn other(message: String) -> Failure {
    Failure { code: 1, message }
}

fn bad(message: String) -> Failure {
    Failure { code: 2, message }
}

fn model_fail(e: model_core::BenchError) -> Failure {
    other(format!("white-box model: {e}"))
}

/// Steady-state points read from `path`: `(torque, pressure, flow)` rows.
fn read_statics(path: &Path) -> Result<Vec<[f64; 3]>, Failure> {
    let cols = read_columns(path, &["torque_ref_pct", "pressure_mca", "flow_lps"])?;
    for (row, line) in cols.rows().zip(&cols.lines) {
        if !(0.0..=100.0).contains(&row[0]) {
            return Err(bad(format!(
                "{}:{line}: torque reference {} % is outside 0..100 %",
                path.display(),
                Short(row[0])
            )));
        }
    }
    Ok(cols.rows().map(|r| [r[0], r[1], r[2]]).collect())
}

/// Reads every input before anything is computed or written: a bad file fails at once.
fn check_files(f: &Files) -> Result<(), Failure> {
    let tp = read_series(&f.train_pressure, "pressure_mca", true)?;
    let tf = read_series(&f.train_flow, "flow_lps", true)?;
    for (train, val, column) in [
        (&tp, &f.val_pressure, "pressure_mca"),
        (&tf, &f.val_flow, "flow_lps"),
    ] {
        let v = read_series(val, column, true)?;
        if v.t_s.len() > 1 && (v.sample_period_s / train.sample_period_s - 1.0).abs() > 1e-3 {
            return Err(bad(format!(
                "{}: sampled every {} s but its training record every {} s",
                val.display(),
                Short(v.sample_period_s),
                Short(train.sample_period_s)
            )));
        }
        // The white-box model is simulated over it: the rule of `simulate` on its times.
        read_input_to_integrate(
            val,
            WHITEBOX_STEP_S * 1e3,
            "study simulates the white-box model over a validation record in steps of 1 ms: \
             use a shorter record",
        )?;
    }
    read_statics(&f.statics)?;
    Ok(())
}

fn create_dir(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .map_err(|e| other(format!("cannot create the folder {}: {e}", dir.display())))
}

/// The demo's records: `(file, excite seed, seconds, sample period ms, bench-data seed)`.
const DEMO_RECORDS: [(&str, u64, f64, f64, u64); 4] = [
    ("train_pressure.csv", 1, 600.0, 50.0, 11),
    ("val_pressure.csv", 2, 300.0, 50.0, 12),
    ("train_flow.csv", 3, 1200.0, 100.0, 13),
    ("val_flow.csv", 4, 600.0, 100.0, 14),
];
/// Steady-state points of the demo, at 5, 10, …, 85 %.
const DEMO_STATIC_POINTS: u32 = 17;
/// Demo steady-state records: length, sample period, averaged tail, seed of the first.
const DEMO_STATIC_SECONDS: f64 = 10.0;
const DEMO_STATIC_TS_MS: f64 = 50.0;
const DEMO_STATIC_TAIL_S: f64 = 2.0;
const DEMO_STATIC_SEED: u64 = 15;

fn demo_excite(seed: u64, seconds: f64, ts_ms: f64, min_pct: f64, max_pct: f64) -> TorqueInput {
    let rows = excite::samples(&excite::Excite {
        seed,
        seconds,
        ts_s: ts_ms * 1e-3,
        min_pct,
        max_pct,
        min_hold_s: 0.1,
        max_hold_s: 2.0,
    });
    TorqueInput {
        t_s: rows.iter().map(|r| r.0).collect(),
        torque_ref_pct: rows.iter().map(|r| r.1).collect(),
    }
}

/// Writes the demo data into `dir`; returns the files and the equivalent commands.
fn write_demo(dir: &Path) -> Result<(Files, String), Failure> {
    let mut commands = String::new();
    for (name, seed, seconds, ts_ms, bench_seed) in DEMO_RECORDS {
        debug_assert!(DEMO_FILES.contains(&name));
        eprintln!("study: demo data {name} (excite seed {seed}, {seconds} s at {ts_ms} ms; bench-data seed {bench_seed})");
        let input = demo_excite(seed, seconds, ts_ms, 5.0, 85.0);
        output::write_csv(Some(&dir.join(name)), |w| {
            benchdata::run(&input, &benchdata::Options::with_seed(bench_seed), w)
        })?;
        let u = format!("u_{name}");
        let _ = writeln!(
            commands,
            "    pumpbench excite --seed {seed} --seconds {seconds} --ts-ms {ts_ms} --output {u}\n    \
             pumpbench bench-data --input {u} --seed {bench_seed} --output {name}"
        );
    }
    eprintln!(
        "study: demo data static.csv ({DEMO_STATIC_POINTS} constant-torque bench-data records)"
    );
    let mut rows = Vec::new();
    for k in 0..DEMO_STATIC_POINTS {
        let torque = 5.0 * f64::from(k + 1);
        let seed = DEMO_STATIC_SEED + u64::from(k);
        let input = demo_excite(1, DEMO_STATIC_SECONDS, DEMO_STATIC_TS_MS, torque, torque);
        let mut csv = Vec::new();
        benchdata::run(&input, &benchdata::Options::with_seed(seed), &mut csv)?;
        let text = String::from_utf8(csv).map_err(|e| other(e.to_string()))?;
        let (mut p, mut q, mut n) = (0.0, 0.0, 0.0);
        for line in text.lines().skip(1) {
            let cells: Vec<f64> = line.split(',').filter_map(|c| c.parse().ok()).collect();
            // t_s, torque_ref_pct, speed_rpm, flow_lps, pressure_mca
            if cells.len() == 5 && cells[0] >= DEMO_STATIC_SECONDS - DEMO_STATIC_TAIL_S - 1e-9 {
                q += cells[3];
                p += cells[4];
                n += 1.0;
            }
        }
        rows.push((torque, p / n, q / n));
    }
    output::write_csv(Some(&dir.join(DEMO_FILES[4])), |w| {
        let io = |e: std::io::Error| other(format!("cannot write the output: {e}"));
        writeln!(w, "torque_ref_pct,pressure_mca,flow_lps").map_err(io)?;
        for (u, p, q) in &rows {
            writeln!(w, "{u},{p:.6},{q:.6}").map_err(io)?;
        }
        Ok(())
    })?;
    let _ = writeln!(
        commands,
        "    for k = 0, 1, ..., 16 and T = 5(k+1) %:\n    \
         pumpbench excite --seed 1 --seconds {DEMO_STATIC_SECONDS} --ts-ms {DEMO_STATIC_TS_MS} \
         --min-pct T --max-pct T --output u_T.csv\n    \
         pumpbench bench-data --input u_T.csv --seed {DEMO_STATIC_SEED}+k --output s_T.csv\n    \
         static.csv row T: the means of pressure_mca and flow_lps over the rows of s_T.csv with \
         t_s >= {} s (its last {DEMO_STATIC_TAIL_S} s)",
        DEMO_STATIC_SECONDS - DEMO_STATIC_TAIL_S
    );
    let files = Files {
        train_pressure: dir.join(DEMO_FILES[0]),
        val_pressure: dir.join(DEMO_FILES[1]),
        train_flow: dir.join(DEMO_FILES[2]),
        val_flow: dir.join(DEMO_FILES[3]),
        statics: dir.join(DEMO_FILES[4]),
    };
    Ok((files, commands))
}

/// The white-box bench on a record's torque column: the state AT each row's time, from the
/// steady state of the first row's torque, each torque held until the next row's time.
fn whitebox_record(series: &Series) -> Result<Vec<Signals<f64>>, Failure> {
    let bench = WhiteBox::<f64>::paper();
    let (t, u) = (&series.t_s, &series.torque_ref_pct);
    let mut state = bench.steady_state(u[0]).map_err(model_fail)?;
    let mut out = Vec::with_capacity(t.len());
    out.push(bench.signals(&state));
    for i in 1..t.len() {
        bench
            .advance(
                &mut state,
                u[i - 1],
                t[i] - t[i - 1],
                WHITEBOX_STEP_S,
                Scheme::Rk4,
            )
            .map_err(model_fail)?;
        out.push(bench.signals(&state));
    }
    Ok(out)
}

fn target_of(s: &Signals<f64>, target: Target) -> f64 {
    match target {
        Target::Pressure => s.pressure_mca,
        Target::Flow => s.flow_lps,
    }
}

/// `points` without those at the lowest torque (`None` if nothing would be left).
fn without_lowest(points: &[(f64, f64)]) -> Option<Vec<(f64, f64)>> {
    let lowest = points.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let rest: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.0 > lowest).collect();
    (!rest.is_empty()).then_some(rest)
}

/// Torques of the steady curves: 5..85 % in 1 % steps.
fn curve_torques() -> impl Iterator<Item = f64> {
    (5..=85).map(f64::from)
}

fn evaluate(model: &ModelFile, val: &Path, statics: &[[f64; 3]]) -> Result<TargetResult, Failure> {
    let target = model.target;
    let column = match target {
        Target::Pressure => 1,
        Target::Flow => 2,
    };
    let points: Vec<(f64, f64)> = statics.iter().map(|r| (r[0], r[column])).collect();
    let rest = without_lowest(&points);
    let series = narmaxcmd::read_for_model(model, val, true)?;
    let measured = series.y.clone().unwrap_or_default();

    // NARMAX: the existing `validate`, then the free run and steady curve for the figures.
    let net = model.build::<f64>().map_err(bad)?;
    let v = narmaxcmd::validate(&net, model, &series, Some(&points))?;
    let v_rest = match &rest {
        Some(r) => narmaxcmd::validate(&net, model, &series, Some(r))?.mape_s,
        None => None,
    };
    let narmax = narmaxcmd::free_run(&net, &series)?;
    let mut narmax_curve = Vec::new();
    for u in curve_torques() {
        narmax_curve.push((u, narmaxcmd::steady_of(&net, u)?));
    }
    let skip = model.lags().max_lag().min(measured.len());
    let narmax_scores = Scores {
        mape_s: v.mape_s.map_or(f64::NAN, |s| s.1),
        mape_s_without_lowest: v_rest.map(|s| s.1),
        mape_d: v.mape_d_pct,
    };

    // White box: the same rows, the same points.
    let whitebox: Vec<f64> = whitebox_record(&series)?
        .iter()
        .map(|s| target_of(s, target))
        .collect();
    let bench = WhiteBox::<f64>::paper();
    let steady = |u: f64| -> Result<f64, Failure> {
        Ok(target_of(
            &bench.signals(&bench.steady_state(u).map_err(model_fail)?),
            target,
        ))
    };
    let mape_s_of = |pts: &[(f64, f64)]| -> Result<f64, Failure> {
        let ys: Vec<f64> = pts.iter().map(|p| p.1).collect();
        let model_ys = pts
            .iter()
            .map(|p| steady(p.0))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(narmaxcmd::mape_pct(&ys, &model_ys))
    };
    let whitebox_scores = Scores {
        mape_s: mape_s_of(&points)?,
        mape_s_without_lowest: rest.as_deref().map(mape_s_of).transpose()?,
        mape_d: narmaxcmd::mape_pct(&measured[skip..], &whitebox[skip..]),
    };
    let whitebox_curve = curve_torques()
        .map(|u| steady(u).map(|y| (u, y)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(TargetResult {
        target,
        t_s: series.t_s,
        measured,
        narmax,
        whitebox,
        skip,
        statics: points,
        narmax_curve,
        whitebox_curve,
        narmax_scores,
        whitebox_scores,
    })
}

fn identify(
    data: &Path,
    target: Target,
    structure: Structure,
    out: &Path,
) -> Result<ModelFile, Failure> {
    let s = structure;
    eprintln!(
        "study: identifying the {} model (na={} nb={} nc={} nk={}, {} hidden; {EPOCHS} epochs, \
         seed {SEED}, {STARTS} starts) on {}",
        target.column(),
        s.na,
        s.nb,
        s.nc,
        s.nk,
        s.hidden,
        data.display()
    );
    let model = narmaxcmd::run_identify(&Identify {
        data,
        target,
        structure,
        epochs: EPOCHS,
        seed: SEED,
        starts: STARTS,
    })?;
    let name = match target {
        Target::Pressure => MODEL_FILES[0],
        Target::Flow => MODEL_FILES[1],
    };
    narmaxcmd::write_model(&out.join(name), &model)?;
    Ok(model)
}

/// The paper's Table 1 (MAPE, %): black box, white box; pressure static (all / without the
/// 5 % point), pressure dynamic, flow static, flow dynamic.
pub const PAPER_TABLE: [(&str, [&str; 4]); 2] = [
    (
        "Black-box (NARMAX)",
        ["7.67 / 1.38", "1.22", "2.60", "1.10"],
    ),
    ("White-box", ["4.50", "10.47", "4.75", "3.5"]),
];

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "n/a".into()
    }
}

fn row(name: &str, p: &Scores, q: &Scores) -> String {
    let p_static = match p.mape_s_without_lowest {
        Some(w) => format!("{} / {}", pct(p.mape_s), pct(w)),
        None => pct(p.mape_s),
    };
    format!(
        "| {name} | {p_static} | {} | {} | {} |\n",
        pct(p.mape_d),
        pct(q.mape_s),
        pct(q.mape_d)
    )
}

const TABLE_HEAD: &str =
    "| Model | Pressure static | Pressure dynamic | Flow static | Flow dynamic |\n\
                          |---|---|---|---|---|\n";

/// Table 1 in Markdown: this run's MAPEs, the paper's, and what data was used.
pub fn table1(p: &TargetResult, q: &TargetResult, lowest_pct: f64, data: &str) -> String {
    let mut s = String::from("# Table 1: MAPE of the models, %\n\n");
    s += TABLE_HEAD;
    s += &row("Black-box (NARMAX)", &p.narmax_scores, &q.narmax_scores);
    s += &row("White-box", &p.whitebox_scores, &q.whitebox_scores);
    let _ = write!(
        s,
        "\nStatic: MAPE_s over {} steady-state points; pressure static is \"all points / without \
         the lowest-torque point ({} %)\". Dynamic: MAPE_d of the free run over the \
         validation record, the first {} (pressure) and {} (flow) rows left out (they seed the \
         NARMAX models); the white-box model is simulated from the steady state of the first \
         row's torque (RK4, steps <= 1 ms). NARMAX models: pressure na={} nb={} nc={} nk={} with \
         {} hidden units, flow na={} nb={} nc={} nk={} with {} hidden units ({EPOCHS} LM epochs, \
         seed {SEED}, {STARTS} starts), f64.\n\n",
        p.statics.len(),
        Short(lowest_pct),
        p.skip,
        q.skip,
        PRESSURE_STRUCTURE.na,
        PRESSURE_STRUCTURE.nb,
        PRESSURE_STRUCTURE.nc,
        PRESSURE_STRUCTURE.nk,
        PRESSURE_STRUCTURE.hidden,
        FLOW_STRUCTURE.na,
        FLOW_STRUCTURE.nb,
        FLOW_STRUCTURE.nc,
        FLOW_STRUCTURE.nk,
        FLOW_STRUCTURE.hidden,
    );
    s += "## The paper's Table 1, for comparison\n\n";
    s += TABLE_HEAD;
    for (name, cells) in PAPER_TABLE {
        let _ = writeln!(s, "| {name} | {} |", cells.join(" | "));
    }
    s += "\nPressure static: all points / without the 5 % point.\n\n";
    s += data;
    s
}

/// Runs the study.
pub fn run(o: &Study) -> Result<(), Failure> {
    let start = Instant::now();
    let out = &o.out;
    // Every output checked before any input is read: none is an input, all can be written.
    let mut names: Vec<&str> = MODEL_FILES.to_vec();
    names.push(TABLE_FILE);
    names.extend(plots::FIGURES);
    let inputs: Vec<output::Named> = match &o.files {
        Some(f) => vec![
            ("--train-pressure", f.train_pressure.as_path()),
            ("--train-flow", f.train_flow.as_path()),
            ("--val-pressure", f.val_pressure.as_path()),
            ("--val-flow", f.val_flow.as_path()),
            ("--static", f.statics.as_path()),
        ],
        None => {
            names.extend(DEMO_FILES);
            Vec::new()
        }
    };
    output::check_outputs_in_folder(&inputs, "--out", out, &names)?;
    let (files, data) = match &o.files {
        Some(f) => {
            check_files(f)?;
            create_dir(out)?;
            let data = format!(
                "Data: pressure training {}, pressure validation {}, flow training {}, flow \
                 validation {}, steady-state points {}.\n",
                f.train_pressure.display(),
                f.val_pressure.display(),
                f.train_flow.display(),
                f.val_flow.display(),
                f.statics.display()
            );
            (f.clone(), data)
        }
        None => {
            create_dir(out)?;
            let (f, commands) = write_demo(out)?;
            let data = format!(
                "Data: SYNTHETIC, made by --demo (the white-box bench plus transmitter lag, noise \
                 and 12-bit quantisation; nothing measured). The white-box model is the \
                 generator of this data, so its MAPEs here measure only the transmitter lag, noise \
                 and quantisation, not a model error. Files: train_pressure.csv, val_pressure.csv, \
                 train_flow.csv, val_flow.csv and static.csv in this folder. The same files come \
                 from these pumpbench commands (excite's other options at their defaults: \
                 5..85 %, holds 0.1..2 s):\n\n{commands}"
            );
            (f, data)
        }
    };
    let statics = read_statics(&files.statics)?;
    let lowest_pct = statics.iter().map(|r| r[0]).fold(f64::INFINITY, f64::min);
    let pm = identify(
        &files.train_pressure,
        Target::Pressure,
        PRESSURE_STRUCTURE,
        out,
    )?;
    let fm = identify(&files.train_flow, Target::Flow, FLOW_STRUCTURE, out)?;
    eprintln!(
        "study: validating both models on the validation records and the steady-state points"
    );
    let p = evaluate(&pm, &files.val_pressure, &statics)?;
    let q = evaluate(&fm, &files.val_flow, &statics)?;
    let table = table1(&p, &q, lowest_pct, &data);
    output::write_csv(Some(&out.join(TABLE_FILE)), |w| {
        w.write_all(table.as_bytes())
            .map_err(|e| other(format!("cannot write table1.md: {e}")))
    })?;
    eprintln!("study: drawing the figures");
    plots::figures(out, &p, &q)?;
    print!("{table}");
    eprintln!(
        "study: done in {:.1} s; results in {}",
        start.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}
