//! `cargo xtask bench`: what the kernels cost on the MCU and what the images weigh.
//!
//! - Kernels: builds `mcu-bench` (profile `firmware`) and runs its bench image under
//!   `qemu-system-arm -M netduinoplus2 -icount shift=0`, where one instruction is 1 ns and
//!   SysTick counts at 168 MHz: instructions per call = SysTick ticks / 0.168, less the empty
//!   call measured the same way. These are instructions counted by QEMU, not cycles.
//! - Sizes, from the ELF files (the `object` crate): flash = text + rodata + data (the load
//!   image), RAM = data + bss (`.bss` and `.uninit`; the stack is not counted), for both
//!   firmware images and for mcu-bench's size probes (each links one more part of model-core);
//!   the ten largest symbols of each image; the software-f64 routines each image holds.
//! - Prints Markdown tables, writes `mcu.json` under the target directory's `bench/`, and
//!   checks the budgets: no kernel more than [`KERNEL_TOLERANCE`] over `bench/baseline.json`,
//!   no image over its flash or RAM budget ([`Board::budget`]).

use crate::board::{build_firmware, firmware_elf, Board};
use crate::elf::{read_elf, Size, Symbol};
use crate::qemu::qemu_output;
use crate::util::{cargo, field, num, root, run, target_dir, Result, TARGET};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// How much a kernel may cost over its figure in `bench/baseline.json` before the bench fails
/// (a fraction: 5 %). Counts under `-icount` are deterministic: any change is the code's.
pub const KERNEL_TOLERANCE: f64 = 0.05;

/// Fail when a firmware image holds software-f64 routines (`__aeabi_d*`, `__adddf3`, …).
///
/// Whether software f64 routines in a firmware image fail the check: the images hold none
/// (the models and the white-box parameters are compile-time data, the loop is f32).
pub const FORBID_SOFT_F64: bool = true;

/// SysTick ticks per instruction under `-icount shift=0`: 1 instruction = 1 ns, SysTick at
/// 168 MHz.
const TICKS_PER_INSTRUCTION: f64 = 0.168;

/// mcu-bench's size probes, in order, each linking one more part of model-core than the last:
/// (JSON key, binary, what it adds).
const PARTS: &[(&str, &str, &str)] = &[
    (
        "base",
        "part_base",
        "runtime only (cortex-m-rt, semihosting exit)",
    ),
    ("whitebox", "part_whitebox", "+ white-box bench, f32"),
    ("narmax_f32", "part_narmax_f32", "+ NARMAX f32"),
    (
        "narmax_fixed",
        "part_narmax_fixed",
        "+ NARMAX Q15 (compile-time statics)",
    ),
    ("observer", "part_observer", "+ observer and alarm monitor"),
];

/// Kernels held to another kernel's budget in `bench/baseline.json`: (measured, budget). The
/// longest tick in pressure control is held to the tick's max budget (the real-time bound,
/// whatever the mode); its mean, which carries the loop's period every 5 ms, has its own.
/// The tick with the NARMAX models following the load (holding register 19) is held to the
/// tick's budgets, mean and max.
const SHARED_BUDGETS: [(&str, &str); 3] = [
    ("tick_pressure_max", "tick_max"),
    ("tick_adapt_mean", "tick_mean"),
    ("tick_adapt_max", "tick_max"),
];

/// The kernels `mcu.json` has at its top level (besides `observer_update`).
const TOP_LEVEL: [&str; 10] = [
    "narmax_pressure_f32",
    "narmax_pressure_fixed",
    "narmax_flow_f32",
    "narmax_flow_fixed",
    "rk4_step",
    "tick_mean",
    "tick_max",
    "regulator_step",
    "regulator_step_max",
    "tick_pressure_mean",
];

/// The checked-in figures the bench is held to.
fn baseline_path() -> PathBuf {
    root().join("bench").join("baseline.json")
}

/// Where the bench writes its figures.
pub fn json_path() -> PathBuf {
    target_dir().join("bench").join("mcu.json")
}

/// What an ELF image holds.
#[derive(Debug, Clone, Serialize)]
pub struct Image {
    /// Sizes.
    #[serde(flatten)]
    pub size: Size,
    /// Flash budget, bytes.
    pub flash_budget: u64,
    /// RAM budget, bytes.
    pub ram_budget: u64,
    /// The largest symbols (functions and data), largest first.
    pub largest: Vec<Symbol>,
    /// Software-f64 routines linked in.
    pub soft_f64: Vec<String>,
}

/// One row the bench image printed.
#[derive(Debug)]
struct Row {
    name: String,
    baseline: Option<String>,
    max_name: Option<String>,
    calls: u64,
    ticks: u64,
    max: u64,
}

/// The bench image's rows (`row name=… calls=… ticks=… max=…`).
fn parse_rows(out: &str) -> Result<Vec<Row>> {
    if let Some(e) = out.lines().find(|l| l.starts_with("error:")) {
        return Err(format!("mcu-bench: {e}"));
    }
    if !out.lines().any(|l| l == "done") {
        return Err(format!("mcu-bench did not finish:\n{out}"));
    }
    out.lines()
        .filter(|l| l.starts_with("row "))
        .map(|l| {
            Ok(Row {
                name: field(l, "name")?.to_string(),
                baseline: field(l, "baseline").ok().map(str::to_string),
                max_name: field(l, "max_name").ok().map(str::to_string),
                calls: num(l, "calls")?,
                ticks: num(l, "ticks")?,
                max: num(l, "max")?,
            })
        })
        .collect()
}

/// One figure of the kernel table.
#[derive(Debug)]
struct Kernel {
    name: String,
    /// Instructions per call, less the empty call.
    instructions: f64,
    /// "400" or "max of 20000".
    calls: String,
    baseline: Option<String>,
}

/// Instructions per call of every row (and the longest call of those that report it), less
/// the empty call; and the empty call's cost.
fn kernels(rows: &[Row]) -> Result<(Vec<Kernel>, f64)> {
    let ins = |ticks: f64| ticks / TICKS_PER_INSTRUCTION;
    let empty = rows
        .iter()
        .find(|r| r.name == "empty")
        .ok_or("mcu-bench printed no 'empty' row")?;
    let empty = ins(empty.ticks as f64 / empty.calls.max(1) as f64);
    let mut out = vec![];
    for r in rows.iter().filter(|r| r.name != "empty") {
        if r.calls == 0 {
            return Err(format!("mcu-bench row {} made no call", r.name));
        }
        out.push(Kernel {
            name: r.name.clone(),
            instructions: ins(r.ticks as f64 / r.calls as f64) - empty,
            calls: group(r.calls as i64),
            baseline: r.baseline.clone(),
        });
        if let Some(m) = &r.max_name {
            out.push(Kernel {
                name: m.clone(),
                instructions: ins(r.max as f64) - empty,
                calls: format!("max of {}", group(r.calls as i64)),
                baseline: None,
            });
        }
    }
    Ok((out, empty))
}

/// `mcu.json`.
#[derive(Debug, Serialize)]
pub struct Report {
    narmax_pressure_f32: i64,
    narmax_pressure_fixed: i64,
    narmax_flow_f32: i64,
    narmax_flow_fixed: i64,
    rk4_step: i64,
    tick_mean: i64,
    tick_max: i64,
    observer_update: Option<i64>,
    /// "qemu", "nucleo-f446re".
    images: BTreeMap<&'static str, Image>,
    /// Every row, instructions per call (less the empty call).
    kernels: BTreeMap<String, i64>,
    /// The size probes' flash and RAM.
    parts: BTreeMap<&'static str, Size>,
    /// The empty call's cost, taken off every kernel (instructions).
    empty_call: f64,
    /// What the figures are.
    units: &'static str,
}

/// Options of `cargo xtask bench`.
#[derive(Debug, Default, PartialEq)]
pub struct Options {
    /// Write the figures measured to `bench/baseline.json` instead of checking against it.
    pub save_baseline: bool,
}

/// `cargo xtask bench`'s usage.
pub const BENCH_USAGE: &str = "usage: cargo xtask bench [--save-baseline]
  (no option)       build and run mcu-bench in QEMU (-icount shift=0), measure both firmware
                    images; print the tables, write mcu.json under the target directory's
                    bench/; fail if a kernel costs more than 5 % over bench/baseline.json or an
                    image exceeds its flash or RAM budget
  --save-baseline   the same, then write the figures to bench/baseline.json (new budgets)";

impl Options {
    /// `cargo xtask bench`'s arguments (after `bench`): none, or `--save-baseline` (anything
    /// after it is ignored).
    pub fn parse(args: &[String]) -> Result<Self> {
        match args.first().map(String::as_str) {
            None => Ok(Options::default()),
            Some("--save-baseline") => Ok(Options {
                save_baseline: true,
            }),
            Some(other) => Err(format!("unknown option '{other}'\n{BENCH_USAGE}")),
        }
    }
}

/// Thousands separated by spaces, as the docs (docs/measurements.md) write them.
fn group(n: i64) -> String {
    let digits = n.unsigned_abs().to_string();
    let mut s = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            s.push(' ');
        }
        s.push(c);
    }
    if n < 0 {
        format!("−{s}")
    } else {
        s
    }
}

/// A figure of the checked-in baseline: `kernels.<name>`, else the top-level key.
fn baseline_kernel(baseline: &serde_json::Value, name: &str) -> Option<f64> {
    baseline
        .get("kernels")
        .and_then(|k| k.get(name))
        .or_else(|| baseline.get(name))
        .and_then(serde_json::Value::as_f64)
}

/// Builds and measures everything, prints the tables, writes `mcu.json`, then checks the
/// budgets (or saves the baseline). Leaves the QEMU firmware image built last.
pub fn run_bench(o: &Options) -> Result {
    let start = Instant::now();
    let baseline: Option<serde_json::Value> = match std::fs::read_to_string(baseline_path()) {
        Ok(text) => Some(
            serde_json::from_str(&text)
                .map_err(|e| format!("{}: {e}", baseline_path().display()))?,
        ),
        Err(_) => None,
    };
    // The firmware images, one per board crate.
    let mut images = BTreeMap::new();
    for board in [Board::Nucleo, Board::Qemu] {
        build_firmware(board)?;
        let (size, largest, soft_f64) = read_elf(&firmware_elf(board), 10)?;
        let budget = board.budget();
        images.insert(
            board.key(),
            Image {
                size,
                flash_budget: budget.flash,
                ram_budget: budget.ram,
                largest,
                soft_f64,
            },
        );
    }
    run(
        "mcu-bench build (profile firmware: opt-level s, LTO; the bench and the size probes)",
        cargo().args([
            "build",
            "-p",
            "mcu-bench",
            "--profile",
            "firmware",
            "--target",
            TARGET,
        ]),
    )?;
    let bin_dir = target_dir().join(TARGET).join("firmware");
    let mut parts = BTreeMap::new();
    let mut part_sizes = vec![];
    for (key, bin, _) in PARTS {
        let elf = bin_dir.join(bin);
        // Each probe runs its parts once and must exit 0 (a probe that faults measures
        // nothing).
        qemu_output(&elf, &[])?;
        let (size, _, _) = read_elf(&elf, 0)?;
        parts.insert(*key, size);
        part_sizes.push(size);
    }
    eprintln!("==> mcu-bench in QEMU (netduinoplus2, -icount shift=0)");
    let rows = parse_rows(&qemu_output(&bin_dir.join("mcu-bench"), &[])?)?;
    let (kernels, empty) = kernels(&rows)?;
    let rounded: BTreeMap<String, i64> = kernels
        .iter()
        .map(|k| (k.name.clone(), k.instructions.round() as i64))
        .collect();
    let get = |name: &str| {
        rounded
            .get(name)
            .copied()
            .ok_or_else(|| format!("mcu-bench measured no '{name}'"))
    };
    let report = Report {
        narmax_pressure_f32: get(TOP_LEVEL[0])?,
        narmax_pressure_fixed: get(TOP_LEVEL[1])?,
        narmax_flow_f32: get(TOP_LEVEL[2])?,
        narmax_flow_fixed: get(TOP_LEVEL[3])?,
        rk4_step: get(TOP_LEVEL[4])?,
        tick_mean: get(TOP_LEVEL[5])?,
        tick_max: get(TOP_LEVEL[6])?,
        observer_update: rounded.get("observer_update").copied(),
        images,
        kernels: rounded.clone(),
        parts,
        empty_call: (empty * 10.0).round() / 10.0,
        units: "kernels: instructions per call counted by QEMU (-icount shift=0: SysTick ticks / 0.168), less the empty call; sizes: bytes",
    };

    // The tables.
    let base = baseline.as_ref();
    print!("{}", tables(&report, &kernels, &part_sizes, base, empty));

    let json = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())? + "\n";
    let path = json_path();
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(&path, &json).map_err(|e| format!("{}: {e}", path.display()))?;
    println!("\nwrote {}", path.display());
    if o.save_baseline {
        std::fs::write(baseline_path(), &json)
            .map_err(|e| format!("{}: {e}", baseline_path().display()))?;
        println!("wrote {} (the new budgets)", baseline_path().display());
    }
    eprintln!("    bench: {:.1} s", start.elapsed().as_secs_f64());

    // The budgets.
    let failed = budget_failures(base, o.save_baseline, &rounded, &report.images);
    if failed.is_empty() {
        println!(
            "bench: every kernel within +{:.0} % of bench/baseline.json, every image within its budget",
            100.0 * KERNEL_TOLERANCE
        );
        Ok(())
    } else {
        for f in &failed {
            println!("BUDGET FAILED: {f}");
        }
        Err(format!("bench: {} budget(s) exceeded", failed.len()))
    }
}

/// The bench's Markdown tables: the kernels (instructions per call less the `empty` call's,
/// against their reference row and `base`, `bench/baseline.json`), the images, the size
/// probes (`part_sizes`, in [`PARTS`]' order), each image's largest symbols and its software
/// f64.
fn tables(
    report: &Report,
    kernels: &[Kernel],
    part_sizes: &[Size],
    base: Option<&serde_json::Value>,
    empty: f64,
) -> String {
    let rounded = &report.kernels;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "\n### Kernels on the Cortex-M4 (QEMU netduinoplus2, instructions per call, less the empty call: {empty:.1})\n"
    );
    let _ = writeln!(
        t,
        "| kernel | instructions per call | calls | compared with | ratio | bench/baseline.json | change |"
    );
    let _ = writeln!(t, "|---|---:|---:|---|---:|---:|---:|");
    for k in kernels {
        let n = rounded[&k.name];
        let (vs, ratio) = match k.baseline.as_ref().and_then(|b| Some((b, rounded.get(b)?))) {
            Some((b, &bn)) if bn > 0 => (b.as_str(), format!("{:.2}×", n as f64 / bn as f64)),
            _ => ("", String::new()),
        };
        let (old, change) = match base.and_then(|b| baseline_kernel(b, &k.name)) {
            Some(old) if old > 0.0 => (
                group(old.round() as i64),
                format!("{:+.1} %", 100.0 * (n as f64 / old - 1.0)),
            ),
            _ => ("—".into(), "new".into()),
        };
        let _ = writeln!(
            t,
            "| {} | {} | {} | {vs} | {ratio} | {old} | {change} |",
            k.name,
            group(n),
            k.calls
        );
    }
    let _ = writeln!(t, "\n### Images (bytes, from the ELF)\n");
    let _ = writeln!(
        t,
        "| image | flash | of budget | RAM | of budget | text | rodata | data | bss | flash, RAM in bench/baseline.json |"
    );
    let _ = writeln!(t, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (key, im) in &report.images {
        let s = &im.size;
        let old = base
            .and_then(|b| {
                let i = b.get("images")?.get(*key)?;
                Some(format!(
                    "{}, {}",
                    group(i.get("flash")?.as_i64()?),
                    group(i.get("ram")?.as_i64()?)
                ))
            })
            .unwrap_or_else(|| "—".into());
        let _ = writeln!(
            t,
            "| {key} | {} | {:.1} % of {} | {} | {:.1} % of {} | {} | {} | {} | {} | {old} |",
            group(s.flash as i64),
            100.0 * s.flash as f64 / im.flash_budget as f64,
            group(im.flash_budget as i64),
            group(s.ram as i64),
            100.0 * s.ram as f64 / im.ram_budget as f64,
            group(im.ram_budget as i64),
            group(s.text as i64),
            group(s.rodata as i64),
            group(s.data as i64),
            group(s.bss as i64),
        );
    }
    let _ = writeln!(
        t,
        "\n### model-core by part (mcu-bench size probes, bytes)\n"
    );
    let _ = writeln!(
        t,
        "| probe | links | flash | RAM | flash added | RAM added |"
    );
    let _ = writeln!(t, "|---|---|---:|---:|---:|---:|");
    for (i, (_, bin, what)) in PARTS.iter().enumerate() {
        let s = part_sizes[i];
        let (df, dr) = match i.checked_sub(1).map(|j| part_sizes[j]) {
            Some(p) => (
                format!("+{}", group(s.flash as i64 - p.flash as i64)),
                format!("+{}", group(s.ram as i64 - p.ram as i64)),
            ),
            None => (String::new(), String::new()),
        };
        let _ = writeln!(
            t,
            "| {bin} | {what} | {} | {} | {df} | {dr} |",
            group(s.flash as i64),
            group(s.ram as i64)
        );
    }
    for (key, im) in &report.images {
        let _ = writeln!(t, "\n### The ten largest symbols, {key} image\n");
        let _ = writeln!(t, "| bytes | symbol |");
        let _ = writeln!(t, "|---:|---|");
        for s in &im.largest {
            let _ = writeln!(t, "| {} | `{}` |", group(s.bytes as i64), s.name);
        }
    }
    let _ = writeln!(t);
    for (key, im) in &report.images {
        let _ = writeln!(
            t,
            "software f64 in the {key} image ({} routines{}): {}",
            im.soft_f64.len(),
            if FORBID_SOFT_F64 {
                ", forbidden"
            } else {
                ", reported only: FORBID_SOFT_F64 is off"
            },
            if im.soft_f64.is_empty() {
                "none".to_string()
            } else {
                im.soft_f64.join(" ")
            }
        );
    }
    t
}

/// The budgets a bench's figures break: every kernel of `base` (`bench/baseline.json`; none
/// when saving it, `save_baseline`) measured (`rounded`) and at most [`KERNEL_TOLERANCE`] over
/// it, every image within its flash and RAM budget and free of software f64 (when
/// [`FORBID_SOFT_F64`]); one message per failure.
fn budget_failures(
    base: Option<&serde_json::Value>,
    save_baseline: bool,
    rounded: &BTreeMap<String, i64>,
    images: &BTreeMap<&'static str, Image>,
) -> Vec<String> {
    let mut failed = vec![];
    match base {
        _ if save_baseline => {}
        None => failed.push(format!(
            "no {}: the kernels have no budget (cargo xtask bench --save-baseline writes one)",
            baseline_path().display()
        )),
        Some(b) => {
            let names: Vec<String> = match b.get("kernels").and_then(|k| k.as_object()) {
                Some(k) => k.keys().cloned().collect(),
                None => TOP_LEVEL.iter().map(|s| s.to_string()).collect(),
            };
            let shared = SHARED_BUDGETS
                .iter()
                .map(|&(measured, budget)| (measured.to_string(), budget));
            let own = names.iter().map(|n| (n.clone(), n.as_str()));
            for (name, budget) in own.chain(shared) {
                let Some(old) = baseline_kernel(b, budget) else {
                    continue;
                };
                match rounded.get(&name) {
                    None if budget == name => failed.push(format!(
                        "kernel {name}: in bench/baseline.json ({old}) but not measured (rename or remove it there)"
                    )),
                    None => failed.push(format!(
                        "kernel {name}: held to bench/baseline.json's {budget} but not measured"
                    )),
                    Some(&n) if n as f64 > old * (1.0 + KERNEL_TOLERANCE) => failed.push(format!(
                        "kernel {name}: {} instructions per call, {:+.1} % over bench/baseline.json's {}{} (limit +{:.0} %)",
                        group(n),
                        100.0 * (n as f64 / old - 1.0),
                        if budget == name { String::new() } else { format!("{budget} ") },
                        group(old.round() as i64),
                        100.0 * KERNEL_TOLERANCE
                    )),
                    Some(_) => {}
                }
            }
        }
    }
    for (key, im) in images {
        for (what, n, budget) in [
            ("flash", im.size.flash, im.flash_budget),
            ("RAM", im.size.ram, im.ram_budget),
        ] {
            if n > budget {
                failed.push(format!(
                    "{key} image: {what} {} B, {} B over its budget of {} B",
                    group(n as i64),
                    group((n - budget) as i64),
                    group(budget as i64)
                ));
            }
        }
        if FORBID_SOFT_F64 && !im.soft_f64.is_empty() {
            failed.push(format!(
                "{key} image: software f64 routines linked in: {}",
                im.soft_f64.join(" ")
            ));
        }
    }
    failed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_and_kernels() {
        let out = "mcu-bench: …\nrow name=empty calls=10 ticks=168 max=17\nrow name=a calls=2 ticks=3360 max=1700\nrow name=b baseline=a max_name=b_max calls=4 ticks=3360 max=1008\ndone\n";
        let rows = parse_rows(out).unwrap();
        let (k, empty) = kernels(&rows).unwrap();
        assert!((empty - 100.0).abs() < 1e-9);
        let names: Vec<&str> = k.iter().map(|k| k.name.as_str()).collect();
        assert_eq!(names, ["a", "b", "b_max"]);
        assert!((k[0].instructions - 9900.0).abs() < 1e-6);
        assert!((k[1].instructions - 4900.0).abs() < 1e-6);
        assert!((k[2].instructions - 5900.0).abs() < 1e-6);
        assert_eq!(k[1].baseline.as_deref(), Some("a"));
        assert!(parse_rows("row name=a calls=1 ticks=1 max=1\n").is_err());
        assert!(parse_rows("error: a: failed\ndone\n").is_err());
    }

    #[test]
    fn grouping() {
        assert_eq!(group(0), "0");
        assert_eq!(group(999), "999");
        assert_eq!(group(1000), "1 000");
        assert_eq!(group(65536), "65 536");
        assert_eq!(group(-1234567), "−1 234 567");
    }

    fn image(flash: u64, ram: u64, soft_f64: &[&str]) -> Image {
        Image {
            size: Size {
                flash,
                ram,
                ..Size::default()
            },
            flash_budget: 1000,
            ram_budget: 100,
            largest: vec![],
            soft_f64: soft_f64.iter().map(|s| s.to_string()).collect(),
        }
    }

    #[test]
    fn budgets() {
        let base: serde_json::Value = serde_json::from_str(
            r#"{"tick_mean": 1, "kernels": {"a": 1000, "b": 200, "gone": 5}}"#,
        )
        .unwrap();
        let measured = |a: i64, b: i64| -> BTreeMap<String, i64> {
            [
                ("a".to_string(), a),
                ("b".to_string(), b),
                ("new".to_string(), 9),
                ("tick_adapt_mean".to_string(), 1),
            ]
            .into()
        };
        let images: BTreeMap<&'static str, Image> = [
            ("qemu", image(1000, 100, &[])),
            ("nucleo-f446re", image(10, 1, &[])),
        ]
        .into();
        // Within +5 % (1 050 of 1 000 is the limit), a kernel faster, a new one: only the
        // kernel the baseline has and the bench no longer measures fails.
        let failed = budget_failures(Some(&base), false, &measured(1050, 100), &images);
        assert_eq!(
            failed,
            ["kernel gone: in bench/baseline.json (5) but not measured (rename or remove it there)"]
        );
        let mut base_ok = base.clone();
        base_ok["kernels"].as_object_mut().unwrap().remove("gone");
        assert!(budget_failures(Some(&base_ok), false, &measured(1050, 100), &images).is_empty());
        // One instruction over the limit.
        assert_eq!(
            budget_failures(Some(&base_ok), false, &measured(1051, 100), &images),
            ["kernel a: 1 051 instructions per call, +5.1 % over bench/baseline.json's 1 000 (limit +5 %)"]
        );
        // Without `kernels`, the top-level figures are the budgets.
        let top: serde_json::Value =
            serde_json::from_str(r#"{"rk4_step": 100, "tick_mean": 10}"#).unwrap();
        let m: BTreeMap<String, i64> = [
            ("rk4_step".to_string(), 106),
            ("tick_mean".to_string(), 10),
            ("tick_adapt_mean".to_string(), 10),
        ]
        .into();
        assert_eq!(budget_failures(Some(&top), false, &m, &images).len(), 1);
        // The longest tick in pressure control is held to the tick's max budget.
        let top: serde_json::Value = serde_json::from_str(r#"{"tick_max": 100}"#).unwrap();
        let m = |n: i64| -> BTreeMap<String, i64> {
            [
                ("tick_max".to_string(), 100),
                ("tick_pressure_max".to_string(), n),
                ("tick_adapt_max".to_string(), 100),
            ]
            .into()
        };
        assert!(budget_failures(Some(&top), false, &m(105), &images).is_empty());
        assert_eq!(
            budget_failures(Some(&top), false, &m(106), &images),
            ["kernel tick_pressure_max: 106 instructions per call, +6.0 % over bench/baseline.json's tick_max 100 (limit +5 %)"]
        );
        // A row held to another's budget must be measured.
        let mut gone = m(100);
        gone.remove("tick_adapt_max");
        assert_eq!(
            budget_failures(Some(&top), false, &gone, &images),
            ["kernel tick_adapt_max: held to bench/baseline.json's tick_max but not measured"]
        );
        // No baseline: a failure, unless it is being saved.
        assert_eq!(
            budget_failures(None, false, &measured(1, 1), &images).len(),
            1
        );
        assert!(budget_failures(None, true, &measured(1, 1), &images).is_empty());
        assert!(budget_failures(Some(&base), true, &measured(9999, 1), &images).is_empty());
        // Images: one byte over a budget, software f64 (checked when saving too).
        let over: BTreeMap<&'static str, Image> = [
            ("qemu", image(1001, 100, &[])),
            ("nucleo-f446re", image(10, 101, &["__adddf3"])),
        ]
        .into();
        assert_eq!(
            budget_failures(Some(&base_ok), true, &measured(1, 1), &over),
            [
                "nucleo-f446re image: RAM 101 B, 1 B over its budget of 100 B",
                "nucleo-f446re image: software f64 routines linked in: __adddf3",
                "qemu image: flash 1 001 B, 1 B over its budget of 1 000 B",
            ]
        );
    }

    #[test]
    fn options() {
        let args = |s: &str| -> Vec<String> { s.split_whitespace().map(str::to_string).collect() };
        assert_eq!(Options::parse(&[]), Ok(Options::default()));
        assert!(!Options::default().save_baseline);
        assert_eq!(
            Options::parse(&args("--save-baseline")),
            Ok(Options {
                save_baseline: true
            })
        );
        assert_eq!(
            Options::parse(&args("--save")),
            Err(format!("unknown option '--save'\n{BENCH_USAGE}"))
        );
    }

    #[test]
    fn the_tables() {
        let out = "row name=empty calls=10 ticks=168 max=17\nrow name=a calls=2 ticks=3360 max=1700\nrow name=b baseline=a max_name=b_max calls=4 ticks=3360 max=1008\ndone\n";
        let (k, empty) = kernels(&parse_rows(out).unwrap()).unwrap();
        let rounded: BTreeMap<String, i64> = k
            .iter()
            .map(|k| (k.name.clone(), k.instructions.round() as i64))
            .collect();
        let report = Report {
            narmax_pressure_f32: 0,
            narmax_pressure_fixed: 0,
            narmax_flow_f32: 0,
            narmax_flow_fixed: 0,
            rk4_step: 0,
            tick_mean: 0,
            tick_max: 0,
            observer_update: None,
            images: [("qemu", image(900, 50, &[]))].into(),
            kernels: rounded,
            parts: BTreeMap::new(),
            empty_call: 100.0,
            units: "",
        };
        let base: serde_json::Value = serde_json::from_str(
            r#"{"kernels": {"a": 9000, "b_max": 5900}, "images": {"qemu": {"flash": 1000, "ram": 40}}}"#,
        )
        .unwrap();
        let sizes: Vec<Size> = (0..PARTS.len() as u64)
            .map(|i| Size {
                flash: 1000 + 2500 * i,
                ram: 10 * i,
                ..Size::default()
            })
            .collect();
        let t = tables(&report, &k, &sizes, Some(&base), empty);
        for row in [
            "less the empty call: 100.0)",
            "| a | 9 900 | 2 |  |  | 9 000 | +10.0 % |",
            "| b | 4 900 | 4 | a | 0.49× | — | new |",
            "| b_max | 5 900 | max of 4 |  |  | 5 900 | +0.0 % |",
            "| qemu | 900 | 90.0 % of 1 000 | 50 | 50.0 % of 100 | 0 | 0 | 0 | 0 | 1 000, 40 |",
            "| part_base | runtime only (cortex-m-rt, semihosting exit) | 1 000 | 0 |  |  |",
            "| part_whitebox | + white-box bench, f32 | 3 500 | 10 | +2 500 | +10 |",
            "software f64 in the qemu image (0 routines, forbidden): none",
        ] {
            assert!(t.contains(&format!("{row}\n")), "{row} not in:\n{t}");
        }
        // Without a baseline, every kernel is new.
        let t = tables(&report, &k, &sizes, None, empty);
        assert!(t.contains("| a | 9 900 | 2 |  |  | — | new |\n"), "{t}");
        assert!(
            t.contains(
                "| qemu | 900 | 90.0 % of 1 000 | 50 | 50.0 % of 100 | 0 | 0 | 0 | 0 | — |\n"
            ),
            "{t}"
        );
    }
}
