//! model-core's white-box bench against the independent f64 reference and the paper.

use host_tests::reference::{RefSample, Reference};
use host_tests::stats::ErrorStats;
use model_core::excitation::PulseTrain;
use model_core::{BenchError, BenchState, Real, Scheme, WhiteBox};

/// A seeded pulse excitation of `seconds` s (amplitudes 5..85 %, holds 0.5..3 s), as rows
/// `(t_s, u_pct)`, with extra rows every `grid_s` so the comparison sees inside each hold.
fn pulse_input(seed: u64, seconds: f64, grid_s: f64) -> Vec<(f64, f64)> {
    let mut rows = Vec::new();
    let mut t = 0.0;
    for pulse in PulseTrain::paper(seed) {
        if t >= seconds {
            break;
        }
        let end = (t + pulse.hold_s).min(seconds);
        let mut s = t;
        while s < end - 1e-12 {
            rows.push((s, pulse.torque_ref_pct));
            s += grid_s;
        }
        t = end;
    }
    rows.push((seconds, rows.last().unwrap().1));
    rows
}

/// model-core on the same input, 1 ms RK4, from the first torque's steady state.
fn model_run<T: Real>(input: &[(f64, f64)], scheme: Scheme, step_s: f64) -> Vec<[f64; 3]> {
    let bench = WhiteBox::<T>::paper();
    let mut state = bench.steady_state(T::from_f64(input[0].1)).unwrap();
    let mut out = Vec::with_capacity(input.len());
    for (i, &(t, _)) in input.iter().enumerate() {
        if i > 0 {
            let (t_prev, u_prev) = input[i - 1];
            bench
                .advance(&mut state, T::from_f64(u_prev), t - t_prev, step_s, scheme)
                .unwrap();
        }
        let s = bench.signals(&state);
        out.push([
            s.speed_rpm.to_f64(),
            s.flow_lps.to_f64(),
            s.pressure_mca.to_f64(),
        ]);
    }
    out
}

fn compare(model: &[[f64; 3]], reference: &[RefSample], pressure_floor: f64) -> [ErrorStats; 3] {
    let mut st = [ErrorStats::default(); 3];
    for (m, r) in model.iter().zip(reference) {
        st[0].push(m[0], r.speed_rpm, 1e-9);
        st[1].push(m[1], r.flow_lps, 1e-9);
        st[2].push(m[2], r.pressure_mca, pressure_floor);
    }
    st
}

fn assert_within(st: &[ErrorStats; 3], tol: f64, what: &str) {
    let names = ["speed", "flow", "pressure"];
    for (s, name) in st.iter().zip(names) {
        eprintln!("{what} {name}: {s}");
    }
    for (s, name) in st.iter().zip(names) {
        assert!(
            s.max_abs <= tol,
            "{what}: {name} relative error {s} exceeds {tol:e}"
        );
    }
}

#[test]
fn f64_rk4_matches_reference_on_120s_pulses() {
    let input = pulse_input(2026, 120.0, 0.05);
    let reference = Reference::paper().simulate(&input);
    let model = model_run::<f64>(&input, Scheme::Rk4, 1e-3);
    assert_within(&compare(&model, &reference, 1e-4), 1e-6, "f64 RK4 1 ms");
}

#[test]
fn f32_rk4_matches_reference_on_120s_pulses() {
    let input = pulse_input(7, 120.0, 0.05);
    let reference = Reference::paper().simulate(&input);
    let model = model_run::<f32>(&input, Scheme::Rk4, 1e-3);
    assert_within(&compare(&model, &reference, 1e-3), 1e-4, "f32 RK4 1 ms");
    // Kahan compensation keeps f32 good at a 10x smaller step too.
    let model = model_run::<f32>(&input, Scheme::Rk4, 1e-4);
    assert_within(&compare(&model, &reference, 1e-3), 1e-4, "f32 RK4 0.1 ms");
}

#[test]
fn cheaper_schemes_converge_with_their_order() {
    // Heun (2nd order) and Euler (1st order) are cheaper; their error must shrink with the
    // step as their order says: ÷4 and ÷2 for a halved step (within 30 %).
    let input = pulse_input(11, 30.0, 0.1);
    let reference = Reference::paper().simulate(&input);
    for (scheme, order) in [(Scheme::Heun, 2.0), (Scheme::Euler, 1.0)] {
        let e1 = compare(&model_run::<f64>(&input, scheme, 2e-3), &reference, 1e-4)[0].max_abs;
        let e2 = compare(&model_run::<f64>(&input, scheme, 1e-3), &reference, 1e-4)[0].max_abs;
        let ratio = e1 / e2;
        let expected = 2f64.powf(order);
        eprintln!(
            "{scheme:?}: max speed error {e1:.3e} at 2 ms, {e2:.3e} at 1 ms, ratio {ratio:.2}"
        );
        assert!(
            (ratio / expected - 1.0).abs() < 0.3,
            "{scheme:?}: ratio {ratio}, expected ≈ {expected}"
        );
    }
}

#[test]
fn steady_states_match_reference() {
    let reference = Reference::paper();
    let bench = WhiteBox::<f64>::paper();
    let mut st = [ErrorStats::default(); 3];
    for k in 1..=17 {
        let u = 5.0 * k as f64;
        let (w, q, hs) = reference.steady(u);
        let s = bench.signals(&bench.steady_state(u).unwrap());
        st[0].push(s.speed_rpm, w, 1e-9);
        st[1].push(s.flow_lps, q, 1e-9);
        st[2].push(s.pressure_mca, hs, 1e-4);
    }
    assert_within(&st, 1e-6, "steady 5..85 %");
}

#[test]
fn steady_state_is_where_the_simulation_settles() {
    let bench = WhiteBox::<f64>::paper();
    for u in [0.0, 5.0, 45.0, 85.0, 100.0] {
        let mut state = BenchState::at_rest();
        bench
            .advance(&mut state, u, 60.0, 1e-3, Scheme::Rk4)
            .unwrap();
        let steady = bench.steady_state(u).unwrap();
        let rel = (state.speed_rpm - steady.speed_rpm).abs() / steady.speed_rpm;
        assert!(
            rel < 1e-9,
            "u={u}: settled {} vs steady {}",
            state.speed_rpm,
            steady.speed_rpm
        );
    }
}

/// 63 % rise time of the speed after a torque step, s.
fn time_constant(bench: &WhiteBox<f64>, from: f64, to: f64) -> f64 {
    let mut s = bench.steady_state(from).unwrap();
    let w0 = s.speed_rpm;
    let w1 = bench.steady_state(to).unwrap().speed_rpm;
    let dt = 1e-4;
    let mut t = 0.0;
    while (s.speed_rpm - w0) < 0.632 * (w1 - w0) {
        bench.step(&mut s, to, dt, Scheme::Rk4).unwrap();
        t += dt;
    }
    t
}

#[test]
fn the_units_table_is_reproduced() {
    // docs/bench.md, "What this model gives against the paper's own operating points": what
    // the unit system of "Units (the paper prints none)" gives, as printed there (rounded).
    let bench = WhiteBox::<f64>::paper();
    let at = |u: f64| bench.signals(&bench.steady_state(u).unwrap());
    let close = |x: f64, printed: f64, half_ulp: f64, what: &str| {
        assert!(
            (x - printed).abs() <= half_ulp,
            "{what}: {x} vs the printed {printed}"
        );
    };
    close(at(5.0).speed_rpm, 320.0, 5.0, "speed at 5 % (≈ 320 rpm)");
    close(
        at(85.0).speed_rpm,
        1629.0,
        5.0,
        "speed at 85 % (≈ 1629 rpm)",
    );
    close(
        bench.flow_at(1749.0, 0.0),
        21.9,
        0.05,
        "flow at 1749 rpm (≈ 21.9 l/s)",
    );
    close(at(85.0).flow_lps, 20.4, 0.05, "flow at 85 % (≈ 20.4 l/s)");
    close(
        at(5.0).pressure_mca,
        0.06,
        0.005,
        "pressure at 5 % (≈ 0.06 mca)",
    );
    close(
        time_constant(&bench, 5.0, 15.0),
        0.78,
        0.015,
        "τ 5→15 % (≈ 0.78 s)",
    );
    close(
        time_constant(&bench, 75.0, 85.0),
        0.22,
        0.005,
        "τ 75→85 % (≈ 0.22 s)",
    );
}

#[test]
fn paper_operating_points_differ_as_documented() {
    // docs/bench.md states these differences to the paper's own operating points.
    let bench = WhiteBox::<f64>::paper();
    let w5 = bench.steady_state(5.0).unwrap().speed_rpm;
    let w85 = bench.steady_state(85.0).unwrap().speed_rpm;
    let q_nom = bench.flow_at(1749.0, 0.0);
    let d5 = (w5 / 351.0 - 1.0) * 100.0;
    let d85 = (w85 / 1749.0 - 1.0) * 100.0;
    let dq = (q_nom / 19.2 - 1.0) * 100.0;
    eprintln!("5 %: {w5:.1} rpm ({d5:+.1} %), 85 %: {w85:.1} rpm ({d85:+.1} %), flow at 1749 rpm {q_nom:.2} l/s ({dq:+.1} %)");
    assert!((d5 - -8.9).abs() < 0.1);
    assert!((d85 - -6.9).abs() < 0.1);
    assert!((dq - 14.0).abs() < 0.1);
}

#[test]
fn edge_torques_and_big_steps() {
    let reference = Reference::paper();
    // Torque 0 and 100 %: steady states exist and match the reference.
    let bench = WhiteBox::<f64>::paper();
    for u in [0.0, 100.0] {
        let s = bench.signals(&bench.steady_state(u).unwrap());
        let (w, q, _) = reference.steady(u);
        assert!((s.speed_rpm / w - 1.0).abs() < 1e-6 && (s.flow_lps / q - 1.0).abs() < 1e-6);
        assert!(
            s.extrapolation.any(),
            "0 and 100 % lie outside the fitted speed range"
        );
    }
    // A step 5 → 85 → 5 % and 0 → 100 → 0 %, f64 and f32, against the reference.
    for (a, b) in [(5.0, 85.0), (0.0, 100.0)] {
        let input = [(0.0, a), (4.0, b), (8.0, a), (12.0, a)];
        let fine: Vec<(f64, f64)> = (0..=1200)
            .map(|i| {
                let t = i as f64 * 0.01;
                let u = input.iter().rev().find(|r| r.0 <= t + 1e-12).unwrap().1;
                (t, u)
            })
            .collect();
        let r = reference.simulate(&fine);
        assert_within(
            &compare(&model_run::<f64>(&fine, Scheme::Rk4, 1e-3), &r, 1e-4),
            1e-6,
            "step f64",
        );
        assert_within(
            &compare(&model_run::<f32>(&fine, Scheme::Rk4, 1e-3), &r, 1e-3),
            1e-4,
            "step f32",
        );
    }
}

#[test]
fn zero_speed_and_the_no_flow_region() {
    let reference = Reference::paper();
    let bench = WhiteBox::<f64>::paper();
    // At rest the pump cannot lift the static head: no flow, pressure −c.
    let rest = bench.state_at_speed(0.0, 0.0).unwrap();
    let s = bench.signals(&rest);
    assert_eq!(s.flow_lps, 0.0);
    assert!((s.pressure_mca + 0.252).abs() < 1e-12);
    // With a higher static head (c = −3 mca: 3 m to lift before the valve passes water) the
    // no-flow region is wide: flow is 0 up to a threshold speed, then rises continuously.
    let mut bench = bench;
    bench.set_load(0.1082, -3.0).unwrap();
    let mut reference = reference;
    reference.c = -3.0;
    let mut threshold = None;
    let mut last = 0.0;
    for i in 0..=2000 {
        let w = i as f64;
        let q = bench.flow_at(w, last);
        let q_ref = reference.flow(w);
        assert!(
            (q - q_ref).abs() <= 1e-9 * q_ref.max(1.0),
            "w={w}: {q} vs {q_ref}"
        );
        assert!(q >= 0.0 && q.is_finite());
        if q > 0.0 && threshold.is_none() {
            threshold = Some(w);
        }
        assert!(q + 1e-12 >= last, "flow must not fall with speed: {w}");
        last = q;
    }
    let threshold = threshold.expect("flow starts somewhere below 2000 rpm");
    assert!(threshold > 300.0, "no-flow region up to {threshold} rpm");
    // The bench still integrates through the region: start at rest, spin up, spin down.
    let mut state = BenchState::at_rest();
    for u in [0.0, 60.0, 0.0] {
        bench
            .advance(&mut state, u, 10.0, 1e-3, Scheme::Rk4)
            .unwrap();
        let s = bench.signals(&state);
        assert!(s.speed_rpm.is_finite() && s.flow_lps >= 0.0);
    }
}

#[test]
fn bad_input_is_refused_and_state_kept() {
    let bench = WhiteBox::<f32>::paper();
    let mut state = bench.steady_state(30.0).unwrap();
    let before = state;
    for (u, err) in [
        (f32::NAN, BenchError::NonFiniteTorque),
        (f32::INFINITY, BenchError::NonFiniteTorque),
        (f32::NEG_INFINITY, BenchError::NonFiniteTorque),
        (-0.01, BenchError::TorqueOutOfRange),
        (100.01, BenchError::TorqueOutOfRange),
    ] {
        assert_eq!(bench.step(&mut state, u, 1e-3, Scheme::Rk4), Err(err));
        assert_eq!(
            bench.advance(&mut state, u, 1.0, 1e-3, Scheme::Rk4),
            Err(err)
        );
        assert_eq!(bench.steady_state(u).map(|_| ()), Err(err));
        assert_eq!(state, before);
    }
    for dt in [0.0, -1e-3, f32::NAN, 0.2] {
        assert_eq!(
            bench.step(&mut state, 50.0, dt, Scheme::Rk4),
            Err(BenchError::InvalidStep)
        );
        assert_eq!(state, before);
    }
    let mut b = bench;
    assert!(b.set_load(f32::NAN, 0.2).is_err() && b.set_load(-1.0, 0.2).is_err());
    assert_eq!(b, bench);
}

mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Any torque sequence in 0..100 % keeps every signal finite and physical.
        #[test]
        fn any_torque_sequence_stays_physical(
            holds in proptest::collection::vec((0.0f64..=100.0, 0.001f64..2.0), 1..12),
            f32_model in any::<bool>(),
            scheme in prop_oneof![Just(Scheme::Rk4), Just(Scheme::Heun), Just(Scheme::Euler)],
        ) {
            if f32_model { check::<f32>(&holds, scheme)?; } else { check::<f64>(&holds, scheme)?; }
        }
    }

    fn check<T: Real>(holds: &[(f64, f64)], scheme: Scheme) -> Result<(), TestCaseError> {
        let bench = WhiteBox::<T>::paper();
        let top = bench
            .steady_state(T::from_f64(100.0))
            .unwrap()
            .speed_rpm
            .to_f64();
        let mut state = BenchState::at_rest();
        for &(u, d) in holds {
            bench
                .advance(&mut state, T::from_f64(u), d, 1e-3, scheme)
                .unwrap();
            let s = bench.signals(&state);
            let v = [
                s.speed_rpm,
                s.flow_lps,
                s.pressure_mca,
                s.pump_head_mca,
                s.load_torque_pct,
            ]
            .map(|x| x.to_f64());
            prop_assert!(v.iter().all(|x| x.is_finite()), "{v:?}");
            prop_assert!(v[0] >= 0.0 && v[0] <= top * (1.0 + 1e-4), "speed {}", v[0]);
            prop_assert!(v[1] >= 0.0 && v[1] < 27.8, "flow {}", v[1]);
            prop_assert!(v[2] >= -0.2521, "pressure {}", v[2]);
            if v[1] > 0.0 {
                let balance = s.pump_head_mca.to_f64() - s.pipe_loss_mca.to_f64() - v[2];
                prop_assert!(
                    balance.abs() < 1e-3 * (1.0 + v[3].abs()),
                    "head balance {balance}"
                );
            }
        }
        Ok(())
    }
}
