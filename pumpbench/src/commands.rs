//! Each command run from its options: the options' checks, then the output's, then the
//! inputs read and the work done by the command's module.

use crate::cli::{
    check_optional_output, need_weights, weights_input, Adapt, BenchDataArgs, ExciteArgs,
    ExportArgs, IdentifyArgs, Model, ModelChoice, PlantArgs, Precision, SimulateArgs, SteadyArgs,
    StudyArgs, ValidateArgs, VfdSimArgs,
};
use crate::error::Failure;
use crate::{
    benchdata, excite, export, input, modelfile, narmaxcmd, num, output, plant, simulate, study,
    train, vfdsim,
};

/// Runs `$body` with `$model` bound to the NARMAX model of file `$m` in precision `$p`.
macro_rules! with_narmax {
    ($m:expr, $p:expr, |$model:ident| $body:expr) => {
        match $p {
            Precision::F64 => {
                let $model = $m.build::<f64>().map_err(Failure::usage)?;
                $body
            }
            Precision::F32 => {
                let $model = $m.build::<f32>().map_err(Failure::usage)?;
                $body
            }
            Precision::Q15 => {
                let $model = narmaxcmd::quantized(&$m)?;
                $body
            }
        }
    };
}

/// `pumpbench identify`.
pub fn identify(a: IdentifyArgs) -> Result<(), Failure> {
    output::check_outputs(&[("--data", &a.data)], &[("--output", &a.output)])?;
    let o = narmaxcmd::Identify {
        starts: a.starts as usize,
        data: &a.data,
        target: a.target,
        structure: train::Structure {
            na: a.na,
            nb: a.nb,
            nc: a.nc,
            nk: a.nk,
            hidden: a.hidden,
        },
        epochs: a.epochs,
        seed: a.seed,
    };
    let model = narmaxcmd::run_identify(&o)?;
    narmaxcmd::write_model(&a.output, &model)
}

/// `pumpbench validate`.
pub fn validate(a: ValidateArgs) -> Result<(), Failure> {
    let ValidateArgs {
        weights,
        data,
        statics,
        precision,
    } = a;
    let m = modelfile::ModelFile::read(&weights)?;
    let series = narmaxcmd::read_for_model(&m, &data, true)?;
    let points = match &statics {
        None => None,
        Some(p) => {
            let cols = input::read_columns(p, &["torque_ref_pct", m.target.column()])?;
            Some(cols.rows().map(|r| (r[0], r[1])).collect::<Vec<_>>())
        }
    };
    let v = with_narmax!(m, precision, |model| narmaxcmd::validate(
        &model,
        &m,
        &series,
        points.as_deref()
    )?);
    println!("target={}", m.target.column());
    println!(
        "mape_d_pct={:.4} (free run, {} samples after the seed rows)",
        v.mape_d_pct, v.samples
    );
    if let Some((n, s)) = v.mape_s {
        println!("mape_s_pct={s:.4} ({n} steady-state points)");
    }
    Ok(())
}

/// `pumpbench excite`.
pub fn excite(a: ExciteArgs) -> Result<(), Failure> {
    let ExciteArgs {
        seed,
        seconds,
        ts_ms,
        min_pct,
        max_pct,
        min_hold_s,
        max_hold_s,
        output,
    } = a;
    if !(0.0..=100.0).contains(&min_pct) || !(0.0..=100.0).contains(&max_pct) || min_pct > max_pct {
        return Err(Failure::usage(format!(
            "--min-pct {} and --max-pct {} must satisfy 0 <= min <= max <= 100",
            num::Short(min_pct),
            num::Short(max_pct)
        )));
    }
    if min_hold_s > max_hold_s {
        return Err(Failure::usage(
            "--min-hold-s must be <= --max-hold-s".into(),
        ));
    }
    if let Some(out) = &output {
        output::check_outputs(&[], &[("--output", out)])?;
    }
    if seconds / (ts_ms * 1e-3) > 1e8 {
        return Err(Failure::usage(
            "more than 1e8 samples: shorten --seconds".into(),
        ));
    }
    let o = excite::Excite {
        seed,
        seconds,
        ts_s: ts_ms * 1e-3,
        min_pct,
        max_pct,
        min_hold_s,
        max_hold_s,
    };
    output::write_csv(output.as_deref(), |w| excite::run(&o, w))
}

/// `pumpbench vfd-sim`.
pub fn vfd_sim(a: VfdSimArgs) -> Result<(), Failure> {
    let VfdSimArgs {
        port,
        unit,
        counts_per_100,
        rpm_per_count,
        idle_ms,
        seconds,
        seed,
    } = a;
    vfdsim::run(
        &port,
        &vfdsim::Options {
            unit,
            counts_per_100_pct: counts_per_100,
            rpm_per_count,
            idle_ms,
            seconds,
            seed,
        },
    )
}

/// `pumpbench export`.
pub fn export(a: ExportArgs) -> Result<(), Failure> {
    let ExportArgs { weights, output } = a;
    check_optional_output(&[("--weights", &weights)], output.as_deref())?;
    let m = modelfile::ModelFile::read(&weights)?;
    let source = weights.display().to_string();
    output::write_csv(output.as_deref(), |w| export::run(&m, &source, w))
}

/// `pumpbench bench-data`.
pub fn bench_data(a: BenchDataArgs) -> Result<(), Failure> {
    // The options first (no file touched), then the output, then the input.
    let options = benchdata::Options {
        valve_steps: match a.valve_steps.as_deref() {
            Some(text) => benchdata::parse_valve_steps(text).map_err(Failure::usage)?,
            None => Vec::new(),
        },
        plant: plant_options(&a.plant, a.seed, &a.flow_lag_ms)?,
        truth: a.truth,
    };
    plant::true_bench(options.plant.curve_error, options.plant.rotor_inertia)
        .map_err(Failure::usage)?;
    check_optional_output(&[("--input", &a.input)], a.output.as_deref())?;
    let data =
        input::read_input_to_integrate(&a.input, benchdata::STEP_MS, benchdata::TOO_MANY_STEPS)?;
    output::write_csv(a.output.as_deref(), |w| benchdata::run(&data, &options, w))
}

/// The plant of the options shared by `bench-data` and `control`, noise seed `seed`, flow
/// transmitter lag `flow_lag_ms` (ms, as typed).
pub fn plant_options(
    a: &PlantArgs,
    seed: u64,
    flow_lag_ms: &str,
) -> Result<plant::PlantOptions, Failure> {
    Ok(plant::PlantOptions {
        seed,
        curve_error: {
            let (head_shape_pct, torque_shape_pct) =
                plant::parse_curve_shape(&a.curve_shape).map_err(Failure::usage)?;
            plant::CurveError {
                head_shape_pct,
                torque_shape_pct,
                ..plant::parse_curve_error(&a.curve_error).map_err(Failure::usage)?
            }
        },
        dynamics: plant::Dynamics {
            water_inertia: plant::parse_water_inertia(&a.water_inertia).map_err(Failure::usage)?,
            drive_lag_s: plant::parse_lag_ms("--drive-lag-ms", &a.drive_lag_ms)
                .map_err(Failure::usage)?,
            drive_slew_pct_s: plant::parse_drive_slew(&a.drive_slew_pct_s)
                .map_err(Failure::usage)?,
        },
        rotor_inertia: plant::parse_rotor_inertia(&a.rotor_inertia).map_err(Failure::usage)?,
        flow_lag_s: plant::parse_lag_ms("--flow-lag-ms", flow_lag_ms).map_err(Failure::usage)?,
        pressure_lag_s: plant::parse_lag_ms("--pressure-lag-ms", &a.pressure_lag_ms)
            .map_err(Failure::usage)?,
        pressure_noise_mca: plant::parse_pressure_noise(&a.pressure_noise)
            .map_err(Failure::usage)?,
        speed_lag_s: plant::parse_lag_ms("--speed-lag-ms", &a.speed_lag_ms)
            .map_err(Failure::usage)?,
        flow_update_s: plant::parse_lag_ms("--flow-update-ms", &a.flow_update_ms)
            .map_err(Failure::usage)?,
        static_head_mca: plant::parse_static_head(&a.static_head).map_err(Failure::usage)?,
        transmitter_delay_s: plant::parse_delay_ms(&a.transmitter_delay_ms)
            .map_err(Failure::usage)?,
    })
}

/// `pumpbench study`.
pub fn study(a: StudyArgs) -> Result<(), Failure> {
    let StudyArgs {
        train_pressure,
        train_flow,
        val_pressure,
        val_flow,
        statics,
        demo,
        out,
    } = a;
    let files = match (
        demo,
        train_pressure,
        train_flow,
        val_pressure,
        val_flow,
        statics,
    ) {
        (false, Some(tp), Some(tf), Some(vp), Some(vf), Some(st)) => Some(study::Files {
            train_pressure: tp,
            train_flow: tf,
            val_pressure: vp,
            val_flow: vf,
            statics: st,
        }),
        (true, ..) => None,
        _ => {
            return Err(Failure::usage(
                "study needs --demo or all of --train-pressure, --train-flow, \
                 --val-pressure, --val-flow, --static"
                    .into(),
            ))
        }
    };
    study::run(&study::Study { files, out })
}

/// The output map's memory when `--adapt-tau-s` is not given, s: long against the bench's
/// time constants (0.2..0.7 s), short against a valve's move being followed.
pub const DEFAULT_ADAPT_TAU_S: f64 = 2.0;

/// `pumpbench simulate`.
pub fn simulate(a: SimulateArgs) -> Result<(), Failure> {
    let SimulateArgs {
        choice:
            ModelChoice {
                model,
                precision,
                weights,
            },
        step_ms,
        input,
        output,
        adapt,
        adapt_tau_s,
        sensor_lag_ms,
    } = a;
    let mut inputs = vec![("--input", input.as_path())];
    inputs.extend(weights.as_deref().map(|w| ("--weights", w)));
    check_optional_output(&inputs, output.as_deref())?;
    match model {
        Model::Whitebox => {
            if adapt != Adapt::Off || adapt_tau_s.is_some() || sensor_lag_ms.is_some() {
                return Err(Failure::usage(
                    "--adapt and --sensor-lag-ms are for NARMAX models (--model narmax)".into(),
                ));
            }
            let data = input::read_input_to_integrate(&input, step_ms, simulate::TOO_MANY_STEPS)?;
            let step_s = step_ms * 1e-3;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::whitebox::<f64, _>(&data, step_s, w),
                Precision::F32 => simulate::whitebox::<f32, _>(&data, step_s, w),
                Precision::Q15 => Err(Failure::usage(
                    "--precision q15 is for NARMAX models".into(),
                )),
            })
        }
        Model::Narmax => {
            let m = need_weights(weights)?;
            let adapt = match (adapt, adapt_tau_s) {
                (Adapt::Off, None) => None,
                (Adapt::Off, Some(_)) => {
                    return Err(Failure::usage(
                        "--adapt-tau-s is the output map's: give --adapt output-map".into(),
                    ))
                }
                (Adapt::OutputMap, tau) => Some(tau.unwrap_or(DEFAULT_ADAPT_TAU_S)),
            };
            let sensor_lag_s = sensor_lag_ms
                .map(|t| crate::plant::parse_lag_ms("--sensor-lag-ms", &t))
                .transpose()
                .map_err(Failure::usage)?;
            let series = narmaxcmd::read_for_model(&m, &input, adapt.is_some())?;
            with_narmax!(m, precision, |model| output::write_csv(
                output.as_deref(),
                |w| { narmaxcmd::simulate(&model, &m, &series, adapt, sensor_lag_s, w) }
            ))
        }
    }
}

/// `pumpbench steady`.
pub fn steady(a: SteadyArgs) -> Result<(), Failure> {
    let SteadyArgs {
        choice:
            ModelChoice {
                model,
                precision,
                weights,
            },
        torque_pct,
        output,
    } = a;
    let inputs = weights_input(weights.as_deref());
    check_optional_output(&inputs, output.as_deref())?;
    match model {
        Model::Whitebox => {
            let torques = simulate::parse_torque_list(&torque_pct).map_err(Failure::usage)?;
            output::write_csv(output.as_deref(), |w| match precision {
                Precision::F64 => simulate::steady::<f64, _>(&torques, w),
                Precision::F32 => simulate::steady::<f32, _>(&torques, w),
                Precision::Q15 => Err(Failure::usage(
                    "--precision q15 is for NARMAX models".into(),
                )),
            })
        }
        Model::Narmax => {
            let m = need_weights(weights)?;
            let torques = simulate::parse_torque_list(&torque_pct).map_err(Failure::usage)?;
            with_narmax!(m, precision, |model| output::write_csv(
                output.as_deref(),
                |w| { narmaxcmd::steady(&model, &m, &torques, w) }
            ))
        }
    }
}
