//! The observer's guards: f32 against f64, hours at rest, a transmitter at 2 mA, and random
//! inputs (no NaN out, the covariance positive).

use super::tests::{record, run, Row};
use super::*;
use proptest::prelude::*;

#[test]
fn f32_follows_f64_within_1e_3() {
    let rows = record(5, 60.0, 0.03, &[(20.0, 1.3), (40.0, 0.8)]);
    let a = run::<f64>(&rows, 1e9, 1e9);
    let b = run::<f32>(&rows, 1e9, 1e9);
    let mut worst: f64 = 0.0;
    for (x, y) in a.iter().zip(&b) {
        for (u, v) in [
            (x.speed_rpm, y.speed_rpm),
            (x.flow_lps, y.flow_lps),
            (x.valve_k2, y.valve_k2),
            (x.pressure_mca, y.pressure_mca),
        ] {
            worst = worst.max((f64::from(v) / u - 1.0).abs());
        }
    }
    println!("f32 vs f64: worst relative difference {worst:.2e}");
    assert!(worst < 1e-3, "{worst}");
}

/// Eight hours at rest (nothing to observe: no pressure in span, little flow), then the
/// pulses: the variances stay at most their initial ones, and the estimates are right
/// within seconds instead of slamming k2 to its limits.
#[test]
fn hours_at_rest_do_not_inflate_the_covariance() {
    let mut o = Observer::<f32>::new(ObserverConfig::paper(), 0.0).unwrap();
    let c = ObserverConfig::<f32>::paper();
    for _ in 0..(8 * 3600 * 20) {
        o.step(0.05, 0.0, &Measurements::default()).unwrap();
    }
    for i in 0..STATES {
        let cap = c.initial_sigma[i] * c.initial_sigma[i];
        assert!(o.covariance()[i][i] <= cap * 1.0001, "variance {i}");
    }
    let rows = super::tests::record(8, 40.0, 0.03, &[]);
    let mut worst: f64 = 0.0;
    for (i, r) in rows.iter().enumerate() {
        let m = Measurements {
            pressure_mca: Some(r.p_meas as f32),
            flow_lps: (i % 2 == 1).then_some(r.q_meas as f32),
            speed_rpm: Some(r.w_meas as f32),
        };
        let e = o.step(0.05, r.torque_pct as f32, &m).unwrap();
        if r.t_s > 5.0 {
            worst = worst.max((f64::from(e.valve_k2) / r.k2 - 1.0).abs());
        }
    }
    println!(
        "after 8 h at rest: k2 worst {:.2} % from 5 s of pulses",
        worst * 100.0
    );
    assert!(worst < 0.03);
}

/// A pressure transmitter at 2 mA (−1.25 mca on a 0..10 mca span) for 20 s: not used;
/// the estimates stay within 5 % and recover after.
#[test]
fn a_transmitter_at_2_ma_is_not_used() {
    // Not used means: the estimate is exactly what it is with the cells empty, and the
    // flow and k2 stay right through the 20 s from what remains.
    let rows = record(6, 80.0, 0.03, &[]);
    let run = |faulted: bool| {
        let mut o = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
        let mut out = vec![];
        for (i, r) in rows.iter().enumerate() {
            let fault = (30.0..50.0).contains(&r.t_s);
            let pressure = match (fault, faulted) {
                (false, _) => Some(r.p_meas),
                (true, true) => Some(-1.25),
                (true, false) => None,
            };
            let m = Measurements {
                pressure_mca: pressure,
                flow_lps: (i % 2 == 1).then_some(r.q_meas),
                speed_rpm: Some(r.w_meas),
            };
            let e = o.step(0.05, r.torque_pct, &m).unwrap();
            if fault && faulted {
                assert_eq!(e.pressure.used, Use::Implausible);
            }
            out.push((r, e));
        }
        out
    };
    let (faulted, missing) = (run(true), run(false));
    for ((r, a), (_, b)) in faulted.iter().zip(&missing) {
        assert_eq!(
            (a.flow_lps, a.valve_k2, a.speed_rpm),
            (b.flow_lps, b.valve_k2, b.speed_rpm),
            "{} s",
            r.t_s
        );
    }
    let window: Vec<_> = faulted
        .iter()
        .filter(|(r, _)| (30.0..50.0).contains(&r.t_s))
        .collect();
    let mape = |f: &dyn Fn(&Row, &Estimate<f64>) -> f64| {
        100.0 * window.iter().map(|(r, e)| f(r, e).abs()).sum::<f64>() / window.len() as f64
    };
    let (flow, k2) = (
        mape(&|r, e| e.flow_lps / r.flow - 1.0),
        mape(&|r, e| e.valve_k2 / r.k2 - 1.0),
    );
    println!("pressure at 2 mA for 20 s: flow MAPE {flow:.2} %, k2 {k2:.2} %");
    assert!(flow < 1.0 && k2 < 1.0);
}

/// The drive's speed reading stuck at 0 rpm for 20 s of the paper's pulses: wherever the
/// pump makes more pressure than it can at 0 rpm, the reading is not used (`Implausible`),
/// and the speed, flow and k2 stay right from the transmitters; on the same record whole,
/// every speed reading is judged possible (a real speed never is refused: the pulses stop
/// and start the pump), and so is a speed stuck at 1 rpm (only an exact 0 is judged).
#[test]
fn a_speed_reading_stuck_at_zero_is_not_used() {
    let rows = record(6, 80.0, 0.03, &[]);
    let mut o = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
    let mut clean = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
    let mut at_one = Observer::<f64>::new(ObserverConfig::paper(), 20.0).unwrap();
    let (mut refused, mut pumping) = (0u32, 0u32);
    let mut sum: [f64; 3] = [0.0; 3];
    for (i, r) in rows.iter().enumerate() {
        let stuck = (30.0..50.0).contains(&r.t_s);
        let m = Measurements {
            pressure_mca: Some(r.p_meas),
            flow_lps: (i % 2 == 1).then_some(r.q_meas),
            speed_rpm: Some(if stuck { 0.0 } else { r.w_meas }),
        };
        let e = o.step(0.05, r.torque_pct, &m).unwrap();
        let whole = Measurements {
            speed_rpm: Some(r.w_meas),
            ..m
        };
        let c = clean.step(0.05, r.torque_pct, &whole).unwrap();
        assert_ne!(c.speed.used, Use::Implausible, "{} s: a real speed", r.t_s);
        let one = Measurements {
            speed_rpm: Some(if stuck { 1.0 } else { r.w_meas }),
            ..m
        };
        let s = at_one.step(0.05, r.torque_pct, &one).unwrap();
        assert_ne!(
            s.speed.used,
            Use::Implausible,
            "{} s: 1 rpm is judged by the gate",
            r.t_s
        );
        if stuck && r.p_meas > 1.0 {
            pumping += 1;
            refused += u32::from(e.speed.used == Use::Implausible);
            sum[0] += (e.speed_rpm / r.speed - 1.0).abs();
            sum[1] += (e.flow_lps / r.flow - 1.0).abs();
            sum[2] += (e.valve_k2 / r.k2 - 1.0).abs();
        }
    }
    let mape = sum.map(|s| 100.0 * s / f64::from(pumping));
    println!(
        "speed stuck at 0 for 20 s: {refused} of {pumping} readings refused; MAPE speed {:.2} %, flow {:.2} %, k2 {:.2} %",
        mape[0], mape[1], mape[2]
    );
    assert!(pumping > 100 && refused == pumping);
    assert!(mape.iter().all(|&m| m < 1.0), "{mape:?}");
}

fn channel() -> impl Strategy<Value = Option<f64>> {
    prop_oneof![
        3 => Just(None),
        6 => (-10.0..2000.0f64).prop_map(Some),
        1 => prop_oneof![
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(1e30),
            Just(-1e30)
        ]
        .prop_map(Some),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Random torques (NaN and ±∞ among them), steps, dropped and wild measurements: no
    /// NaN out, the covariance symmetric with a positive diagonal and positive 2×2 minors,
    /// k2 in range.
    #[test]
    fn never_nan_and_covariance_stays_positive(
        steps in proptest::collection::vec(
            (prop_oneof![8 => -20.0..120.0f64, 1 => Just(f64::NAN), 1 => Just(f64::INFINITY)],
             prop_oneof![8 => 0.001..0.3f64, 1 => Just(0.05)],
             channel(), channel(), channel()),
            1..120)
    ) {
        for f32_too in [false, true] {
            let mut o64 = Observer::<f64>::new(ObserverConfig::paper(), 30.0).unwrap();
            let mut o32 = Observer::<f32>::new(ObserverConfig::paper(), 30.0).unwrap();
            for &(u, dt, p, q, w) in &steps {
                let m = Measurements { pressure_mca: p, flow_lps: q, speed_rpm: w };
                let e = o64.step(dt, u, &m).unwrap();
                prop_assert!(estimate_finite(&e));
                check(o64.covariance(), o64.state(), o64.config())?;
                if f32_too {
                    let m32 = Measurements {
                        pressure_mca: p.map(|v| v as f32),
                        flow_lps: q.map(|v| v as f32),
                        speed_rpm: w.map(|v| v as f32),
                    };
                    let e = o32.step(dt as f32, u as f32, &m32).unwrap();
                    prop_assert!(estimate_finite(&e));
                    check(o32.covariance(), o32.state(), o32.config())?;
                }
            }
        }
    }
}

fn check<T: Real>(
    p: &[[T; STATES]; STATES],
    x: &[T; STATES],
    c: &ObserverConfig<T>,
) -> Result<(), TestCaseError> {
    for i in 0..STATES {
        prop_assert!(p[i][i] > T::ZERO, "variance {i}: {:?}", p[i][i]);
        for j in 0..STATES {
            prop_assert!(p[i][j] == p[j][i]);
            // Every 2×2 principal minor of a positive definite matrix is positive.
            if i != j {
                let minor =
                    p[i][i].to_f64() * p[j][j].to_f64() - p[i][j].to_f64() * p[j][i].to_f64();
                prop_assert!(
                    minor > -1e-9 * p[i][i].to_f64() * p[j][j].to_f64(),
                    "minor {i},{j}"
                );
            }
        }
    }
    prop_assert!(c.k2_range.0 <= x[K2] && x[K2] <= c.k2_range.1);
    Ok(())
}
