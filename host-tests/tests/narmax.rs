//! model-core's NARMAX forward pass (f32 and fixed point) against the independent f64 one.

use host_tests::narmax_ref::RefNarmax;
use model_core::excitation::SplitMix64;
use model_core::narmax::fixed::NarmaxQ;
use model_core::narmax::{Lags, Narmax, Scaling};

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

#[test]
fn fixed_point_one_step_error_within_its_stated_bound() {
    for (lags, hidden, seed, w) in [
        ([6, 6, 0, 1], 7, 1, 0.6),
        ([7, 7, 0, 1], 6, 2, 2.0),
        ([6, 6, 0, 1], 7, 4, 5.0),
    ] {
        let (r, m) = models(lags, hidden, seed, w);
        let q: NarmaxQ<16, 8> = NarmaxQ::quantize(&m).unwrap();
        let (u, y) = data(seed + 20, 6000);
        let reference = r.one_step(&u, &y, y[0]);
        // Regressors are clamped to the model's ranges: |φ| ≤ max scaled |u|, |y|.
        let phi_max_data = u
            .iter()
            .map(|v| ((v - 45.0) / 23.0).abs())
            .chain(y.iter().map(|v| ((v - 2.4) / 1.4).abs()))
            .fold(0.0, f64::max);
        let bound = q.one_step_error_bound(phi_max_data) * 1.4;
        let mut st = q.state_at(u[0] as f32, y[0] as f32);
        let mut worst: f64 = 0.0;
        for t in 0..u.len() {
            let p = q.predict_step(&mut st, u[t] as f32, y[t] as f32).y as f64;
            worst = worst.max((p - reference[t]).abs());
        }
        eprintln!("{lags:?} w={w}: fixed-point one-step max |error| {worst:.2e} mca, bound {bound:.2e} mca");
        assert!(worst <= bound, "{lags:?}: {worst:e} > bound {bound:e}");
        assert!(bound < 0.01, "bound too loose to be useful: {bound}");
    }
}
