//! The `simulate` and `steady` commands for the white-box model.

use crate::error::Failure;
use crate::input::TorqueInput;
use crate::num::Float;
use crate::num::Short;
use indicatif::{ProgressBar, ProgressStyle};
use model_core::{Real, Scheme, Signals, WhiteBox};
use std::io::Write;

fn write_fail(e: std::io::Error) -> Failure {
    Failure {
        code: 1,
        message: format!("cannot write the output: {e}"),
    }
}

fn model_fail(e: model_core::BenchError) -> Failure {
    Failure {
        code: 1,
        message: format!("model: {e}"),
    }
}

/// What to do about an input that needs too many steps (see
/// [`crate::input::read_input_to_integrate`]).
pub const TOO_MANY_STEPS: &str = "use a larger --step-ms or a shorter input";

/// Simulates `input` with the white-box bench in `T` arithmetic, RK4, steps ≤ `step_s`.
///
/// The input's times are checked by [`crate::input::read_input_to_integrate`] (at most
/// [`crate::input::MAX_TOTAL_STEPS`] steps).
pub fn whitebox<T: Real + Float, W: Write + ?Sized>(
    input: &TorqueInput,
    step_s: f64,
    w: &mut W,
) -> Result<(), Failure> {
    let bench = WhiteBox::<T>::paper();
    let n = input.t_s.len();
    let mut state = bench
        .steady_state(T::from_f64(input.torque_ref_pct[0]))
        .map_err(model_fail)?;
    // Progress in simulated seconds, drawn only when stderr is a terminal and the run is
    // long (over 2e7 steps, ≈ 3 s of RK4 in f64).
    let (t0, total_s) = (input.t_s[0], input.t_s[n - 1] - input.t_s[0]);
    let bar = if total_s / step_s > 2e7 {
        ProgressBar::new(total_s.ceil() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("simulate {bar:40} {pos}/{len} s simulated, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    writeln!(
        w,
        "t_s,torque_ref_pct,speed_rpm,flow_lps,pressure_mca,speed_rad_s,pump_head_mca,\
         pipe_loss_mca,electromagnetic_torque_pct,load_torque_pct,extrapolated"
    )
    .map_err(write_fail)?;
    for i in 0..n {
        if i > 0 {
            let u = T::from_f64(input.torque_ref_pct[i - 1]);
            let dt = input.t_s[i] - input.t_s[i - 1];
            bench
                .advance(&mut state, u, dt, step_s, Scheme::Rk4)
                .map_err(model_fail)?;
        }
        // Values in `T`'s shortest round-trip form: no digits the model did not compute.
        let s: Signals<T> = bench.signals(&state);
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{}",
            Short(input.t_s[i]),
            Short(input.torque_ref_pct[i]),
            Short(s.speed_rpm),
            Short(s.flow_lps),
            Short(s.pressure_mca),
            Short(s.speed_rad_s),
            Short(s.pump_head_mca),
            Short(s.pipe_loss_mca),
            Short(s.electromagnetic_torque_pct),
            Short(s.load_torque_pct),
            u8::from(s.extrapolation.any()),
        )
        .map_err(write_fail)?;
        bar.set_position((input.t_s[i] - t0) as u64);
    }
    bar.finish_and_clear();
    Ok(())
}

/// Steady states of the white-box bench for each torque.
pub fn steady<T: Real + Float, W: Write + ?Sized>(
    torques: &[f64],
    w: &mut W,
) -> Result<(), Failure> {
    let bench = WhiteBox::<T>::paper();
    writeln!(w, "torque_ref_pct,speed_rpm,flow_lps,pressure_mca").map_err(write_fail)?;
    for &u in torques {
        let s = bench.signals(&bench.steady_state(T::from_f64(u)).map_err(model_fail)?);
        writeln!(
            w,
            "{},{},{},{}",
            Short(u),
            Short(s.speed_rpm),
            Short(s.flow_lps),
            Short(s.pressure_mca)
        )
        .map_err(write_fail)?;
    }
    Ok(())
}

/// Parses `5,10,15` or `start:stop:step` (stop included when hit within 1e-9 of a step).
/// Every value must lie in 0..=100 %.
pub fn parse_torque_list(s: &str) -> Result<Vec<f64>, String> {
    let num = |x: &str| -> Result<f64, String> {
        let x = x.trim();
        match x.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("--torque-pct: '{x}' is not a number")),
        }
    };
    let values = if s.contains(':') {
        let parts: Vec<&str> = s.split(':').collect();
        if parts.len() != 3 {
            return Err(format!("--torque-pct: '{s}' is not start:stop:step"));
        }
        let (a, b, step) = (num(parts[0])?, num(parts[1])?, num(parts[2])?);
        if !(step > 0.0) || b < a {
            return Err(format!(
                "--torque-pct: '{s}' needs step > 0 and stop >= start"
            ));
        }
        let n = ((b - a) / step + 1e-9).floor() as usize;
        if n > 100_000 {
            return Err(format!("--torque-pct: '{s}' gives more than 100000 points"));
        }
        // Rounded to 12 significant digits: 0.1:0.3:0.1 gives 0.3, not 0.30000000000000004.
        let round = |v: f64| format!("{v:.12e}").parse::<f64>().unwrap_or(v);
        (0..=n).map(|k| round(a + k as f64 * step)).collect()
    } else {
        s.split(',').map(num).collect::<Result<Vec<_>, _>>()?
    };
    if values.is_empty() {
        return Err("--torque-pct: no values".into());
    }
    if let Some(bad) = values.iter().find(|u| !(0.0..=100.0).contains(*u)) {
        return Err(format!(
            "--torque-pct: {} % is outside 0..100 %",
            Short(*bad)
        ));
    }
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torque_lists() {
        assert_eq!(parse_torque_list("5,10,15").unwrap(), vec![5.0, 10.0, 15.0]);
        assert_eq!(parse_torque_list("5:85:5").unwrap().len(), 17);
        assert_eq!(parse_torque_list("5:85:5").unwrap()[16], 85.0);
        assert_eq!(parse_torque_list("0:1:0.1").unwrap().len(), 11);
        assert_eq!(parse_torque_list("50").unwrap(), vec![50.0]);
        assert_eq!(
            parse_torque_list("0.1:0.3:0.1").unwrap(),
            vec![0.1, 0.2, 0.3]
        );
        for bad in [
            "", "5,,10", "a", "5:85", "5:85:0", "85:5:5", "-5", "101", "5:200:5", "nan",
        ] {
            assert!(parse_torque_list(bad).is_err(), "{bad}");
        }
    }
}
