//! model-core's NARMAX forward passes (the generic f32 one, and the MCU passes in f32 and Q15)
//! against the independent f64 one.

use host_tests::narmax_ref::RefNarmax;
use model_core::excitation::SplitMix64;
use model_core::narmax::mcu::{NarxF32, NarxQ15, NnsysidModel};
use model_core::narmax::{Lags, Narmax, Predictor, Scaling};

use pump_models::{flow as flow_model, pressure as pressure_model};

/// A random network of the paper's pressure size, scaled like a pressure model, and its
/// model-core twins. Weights uniform in ±`w`, as a trained network's are.
fn models(lags: [usize; 4], hidden: usize, seed: u64, w: f64) -> (RefNarmax, Narmax<f32, 16, 8>) {
    let mut rng = SplitMix64::new(seed);
    let n = lags[0] + lags[1] + lags[2];
    let w1: Vec<Vec<f64>> = (0..hidden)
        .map(|_| (0..=n).map(|_| w * (2.0 * rng.next_f64() - 1.0)).collect())
        .collect();
    let w2: Vec<f64> = (0..=hidden)
        .map(|_| w * (2.0 * rng.next_f64() - 1.0) / hidden as f64)
        .collect();
    let r = RefNarmax {
        lags,
        w1,
        w2,
        u_scale: (45.0, 23.0),
        y_scale: (2.4, 1.4),
    };
    let flat: Vec<f32> = r.w1.iter().flatten().map(|&x| x as f32).collect();
    let w2f: Vec<f32> = r.w2.iter().map(|&x| x as f32).collect();
    let m = Narmax::new(
        Lags {
            na: lags[0],
            nb: lags[1],
            nc: lags[2],
            nk: lags[3],
        },
        hidden,
        &flat,
        &w2f,
        Scaling {
            mean: 45.0,
            std: 23.0,
        },
        Scaling {
            mean: 2.4,
            std: 1.4,
        },
        [0.0, 100.0],
        [-100.0, 100.0],
    )
    .unwrap();
    (r, m)
}

/// Pulses 5..85 % and a response that moves with them (a first-order filter of u²).
fn data(seed: u64, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut rng = SplitMix64::new(seed);
    let (mut u, mut y) = (vec![], vec![]);
    let (mut level, mut left, mut state) = (45.0, 0, 2.4);
    for _ in 0..n {
        if left == 0 {
            level = rng.uniform(5.0, 85.0);
            left = 1 + (rng.next_f64() * 30.0) as usize;
        }
        left -= 1;
        state += 0.2 * (level * level / 1500.0 - state);
        u.push(level);
        y.push(state + 0.01 * (rng.next_f64() - 0.5));
    }
    (u, y)
}

/// The per-step f32 criterion: |f32 − f64| ≤ 1e-5 relative to the value (floor: 1e-2 of the
/// output's std, for outputs crossing zero).
fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(0.014)
}

#[test]
fn f32_matches_f64_per_step_one_step_ahead_and_free_run() {
    for (lags, hidden, seed) in [
        ([6, 6, 0, 1], 7, 1),
        ([7, 7, 0, 1], 6, 2),
        ([3, 2, 2, 2], 4, 3),
    ] {
        let (r, m) = models(lags, hidden, seed, 0.6);
        let (u, y) = data(seed + 10, 6000);
        let reference = r.one_step(&u, &y, y[0]);
        let mut st = m.state_at(u[0] as f32, y[0] as f32);
        let mut worst: f64 = 0.0;
        for t in 0..u.len() {
            let p = m.predict_step(&mut st, u[t] as f32, y[t] as f32).y as f64;
            worst = worst.max(rel(p, reference[t]));
        }
        eprintln!("{lags:?} one-step f32 vs f64: max rel {worst:.2e}");
        assert!(worst <= 1e-5, "{lags:?}: one-step {worst:e}");
        if lags[2] == 0 {
            let reference = r.free_run(&u, y[0]);
            let mut st = m.state_at(u[0] as f32, y[0] as f32);
            let mut worst: f64 = 0.0;
            for t in 0..u.len() {
                let p = m.simulate_step(&mut st, u[t] as f32).y as f64;
                worst = worst.max(rel(p, reference[t]));
            }
            eprintln!("{lags:?} free-run f32 vs f64: max rel {worst:.2e}");
            assert!(worst <= 1e-5, "{lags:?}: free run {worst:e}");
        }
    }
}

/// `r` as model-core's NNSYSID input, with training ranges `u_range`, `y_range`.
fn spec<'a>(
    r: &'a RefNarmax,
    w1: &'a [f64],
    u_range: [f64; 2],
    y_range: [f64; 2],
) -> NnsysidModel<'a> {
    NnsysidModel {
        lags: Lags {
            na: r.lags[0],
            nb: r.lags[1],
            nc: r.lags[2],
            nk: r.lags[3],
        },
        hidden: r.w1.len(),
        w1,
        w2: &r.w2,
        u_scale: Scaling {
            mean: r.u_scale.0,
            std: r.u_scale.1,
        },
        y_scale: Scaling {
            mean: r.y_scale.0,
            std: r.y_scale.1,
        },
        u_range,
        y_range,
    }
}

/// The range of `x` widened by a tenth of its span each side.
fn range_of(x: &[f64]) -> [f64; 2] {
    let (lo, hi) = x
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    [lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)]
}

#[test]
fn mcu_f32_pass_matches_f64_per_step_one_step_ahead_and_free_run() {
    for (lags, hidden, seed) in [
        ([6, 6, 0, 1], 7, 1),
        ([7, 7, 0, 1], 6, 2),
        ([3, 2, 0, 2], 4, 3),
    ] {
        let (r, _) = models(lags, hidden, seed, 0.6);
        let (u, y) = data(seed + 10, 6000);
        let w1: Vec<f64> = r.w1.iter().flatten().copied().collect();
        // Wide ranges: nothing is clamped, so the reference (which never clamps) applies.
        let f: NarxF32<8, 8> = NarxF32::new(&spec(&r, &w1, [0.0, 100.0], [-100.0, 100.0])).unwrap();
        let reference = r.one_step(&u, &y, y[0]);
        let mut st = f.state_at(u[0] as f32, y[0] as f32);
        let mut worst: f64 = 0.0;
        for t in 0..u.len() {
            let p = f.predict_step(&mut st, u[t] as f32, y[t] as f32).y as f64;
            worst = worst.max(rel(p, reference[t]));
        }
        let reference = r.free_run(&u, y[0]);
        let mut st = f.state_at(u[0] as f32, y[0] as f32);
        let mut worst_free: f64 = 0.0;
        for t in 0..u.len() {
            let p = f.simulate_step(&mut st, u[t] as f32).y as f64;
            worst_free = worst_free.max(rel(p, reference[t]));
        }
        eprintln!(
            "{lags:?} MCU f32 vs f64: one-step max rel {worst:.2e}, free run {worst_free:.2e}"
        );
        assert!(worst <= 1e-5, "{lags:?}: one-step {worst:e}");
        assert!(worst_free <= 1e-5, "{lags:?}: free run {worst_free:e}");
    }
}

#[test]
fn fixed_point_one_step_error_within_its_stated_bound() {
    for (lags, hidden, seed, w) in [
        ([6, 6, 0, 1], 7, 1, 0.6),
        ([7, 7, 0, 1], 6, 2, 2.0),
        ([6, 6, 0, 1], 7, 4, 5.0),
        ([3, 2, 0, 2], 4, 5, 1.0),
    ] {
        let (r, _) = models(lags, hidden, seed, w);
        let (u, y) = data(seed + 20, 6000);
        let w1: Vec<f64> = r.w1.iter().flatten().copied().collect();
        let model = spec(&r, &w1, range_of(&u), range_of(&y));
        let q: NarxQ15<8, 8> = NarxQ15::new(&model).unwrap();
        let reference = r.one_step(&u, &y, y[0]);
        let bound = NarxQ15::<8, 8>::one_step_error_bound(&model).unwrap() * r.y_scale.1;
        let mut st = q.state_at(u[0] as f32, y[0] as f32);
        let mut worst: f64 = 0.0;
        for t in 0..u.len() {
            let p = q.predict_step(&mut st, u[t] as f32, y[t] as f32).y as f64;
            worst = worst.max((p - reference[t]).abs());
        }
        eprintln!(
            "{lags:?} w={w}: Q15 one-step max |error| {worst:.2e} mca, bound {bound:.2e} mca"
        );
        assert!(worst <= bound, "{lags:?}: {worst:e} > bound {bound:e}");
        // The bound is asserted useful (< 0.01 mca) for weights up to ±2 (the shipped models'
        // largest is 3.06, most are under 1). With weights of ±5 the Q15 pass's error is
        // 1.6e-3 mca and its bound 1.5e-2 (the I16F16 pass it replaced: 3.7e-4 and 7.3e-3):
        // reported in docs/narmax.md, not asserted.
        if w <= 2.0 {
            assert!(bound < 0.01, "bound too loose to be useful: {bound}");
        }
    }
}

/// pumpbench runs the passes padded to its capacity: the same bits as the firmware's
/// exact-size statics, for both shipped models, free run and one-step-ahead.
#[test]
fn padded_passes_give_the_firmware_bits() {
    fn run<const F: usize, const H: usize>(
        f: &NarxF32<F, H>,
        q: &NarxQ15<F, H>,
        ts: usize,
    ) -> Vec<(u32, u32, bool)> {
        let mut rng = SplitMix64::new(ts as u64);
        let (mut sf, mut sq) = (f.state_at(40.0, 2.0), q.state_at(40.0, 2.0));
        let mut out = vec![];
        let mut u = 40.0;
        for t in 0..3000 {
            if t % 37 == 0 {
                u = rng.uniform(0.0, 95.0) as f32;
            }
            let (a, b) = if t % 3 == 0 {
                (
                    f.predict_step(&mut sf, u, 2.5),
                    q.predict_step(&mut sq, u, 2.5),
                )
            } else {
                (f.simulate_step(&mut sf, u), q.simulate_step(&mut sq, u))
            };
            out.push((a.y.to_bits(), b.y.to_bits(), a.clamped || b.clamped));
        }
        out
    }
    let wide_f = |m| NarxF32::<32, 32>::new(m).unwrap();
    let wide_q = |m| NarxQ15::<32, 32>::new(m).unwrap();
    let p = &pressure_model::MODEL;
    assert_eq!(
        run(&pressure_model::F32, &pressure_model::Q15, 50),
        run(&wide_f(p), &wide_q(p), 50)
    );
    let q = &flow_model::MODEL;
    assert_eq!(
        run(&flow_model::F32, &flow_model::Q15, 100),
        run(&wide_f(q), &wide_q(q), 100)
    );
}
