//! Host timing of the kernels the MCU runs, in f32 and f64 where both exist (criterion):
//! `cargo bench -p host-tests --bench kernels`. The MCU's own counts (instructions under QEMU)
//! come from `cargo xtask bench`; these are host nanoseconds, for the host tools.
// `criterion_group!` makes a public function it does not document.
#![allow(missing_docs)]
use criterion::measurement::WallTime;
use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkGroup, Criterion};
use model_core::narmax::mcu::{tanh_f32, tanh_q15, I16F16};
use model_core::narmax::{Narmax, Predictor};
use model_core::observer::{Measurements, Observer, ObserverConfig};
use model_core::{Real, Scheme, WhiteBox};
use std::hint::black_box;

use pump_models::{flow as flow_model, pressure as pressure_model};

/// Torques that change every call: 31 values between 20 and 80 %.
fn torque(k: u32) -> f32 {
    20.0 + (k % 31) as f32 * 2.0
}

/// Free-run steps of one pass, the torque changing every call.
fn free_run<P: Predictor>(g: &mut BenchmarkGroup<'_, WallTime>, name: &str, p: &P) {
    let mut st = p.state_at(P::Value::from_f64(50.0), p.output_mean());
    let mut k = 0;
    g.bench_function(name, |b| {
        b.iter(|| {
            k += 1;
            black_box(p.simulate_step(&mut st, P::Value::from_f64(f64::from(torque(k)))))
        })
    });
}

fn narmax(c: &mut Criterion) {
    let mut g = c.benchmark_group("narmax");
    macro_rules! model {
        ($name:literal, $m:ident) => {{
            let generic64 =
                Narmax::<f64, { $m::INPUTS }, { $m::HIDDEN }>::from_nnsysid(&$m::MODEL).unwrap();
            let generic32 =
                Narmax::<f32, { $m::INPUTS }, { $m::HIDDEN }>::from_nnsysid(&$m::MODEL).unwrap();
            free_run(&mut g, concat!($name, "/generic_f64"), &generic64);
            free_run(
                &mut g,
                concat!($name, "/generic_f32_libm_tanhf"),
                &generic32,
            );
            free_run(&mut g, concat!($name, "/mcu_f32"), &$m::F32);
            free_run(&mut g, concat!($name, "/mcu_q15"), &$m::Q15);
        }};
    }
    model!("pressure", pressure_model);
    model!("flow", flow_model);
    g.finish();
}

fn tanh(c: &mut Criterion) {
    let mut g = c.benchmark_group("tanh");
    let xs: Vec<f32> = (0..1024).map(|i| (i as f32 - 512.0) / 64.0).collect();
    let mut i = 0;
    let mut next = || {
        i = (i + 1) & 1023;
        xs[i]
    };
    g.bench_function("libm_tanh_f64", |b| {
        b.iter(|| black_box(libm::tanh(f64::from(next()))))
    });
    g.bench_function("libm_tanhf", |b| b.iter(|| black_box(libm::tanhf(next()))));
    g.bench_function("rational_f32", |b| b.iter(|| black_box(tanh_f32(next()))));
    g.bench_function("table_q15", |b| {
        b.iter(|| black_box(tanh_q15(I16F16::from_bits((next() * 65536.0) as i32))))
    });
    g.finish();
}

fn whitebox<T: Real>(c: &mut Criterion, precision: &str) {
    let mut g = c.benchmark_group(format!("whitebox_{precision}"));
    let bench = WhiteBox::<T>::paper();
    for scheme in [Scheme::Rk4, Scheme::Heun, Scheme::Euler] {
        let mut st = bench.steady_state(T::from_f64(50.0)).unwrap();
        let mut k = 0;
        g.bench_function(format!("step_{scheme:?}"), |b| {
            b.iter(|| {
                k += 1;
                let u = T::from_f64(if k % 400 < 200 { 30.0 } else { 70.0 });
                bench.step(&mut st, u, T::from_f64(1e-3), scheme).unwrap();
                black_box(st.speed_rpm)
            })
        });
    }
    let mut k = 0;
    g.bench_function("flow_solve", |b| {
        b.iter(|| {
            k += 1;
            let w = T::from_f64(800.0 + f64::from(k % 97) * 5.0);
            black_box(bench.flow_at(w, T::from_f64(15.0)))
        })
    });
    // The observer on 50 ms updates with pressure, flow and speed, its bench stepping 30 ↔ 70 %.
    let mut st = bench.steady_state(T::from_f64(30.0)).unwrap();
    let mut states = vec![];
    for k in 0..400 {
        let u = T::from_f64(if k % 80 < 40 { 30.0 } else { 70.0 });
        for _ in 0..50 {
            bench
                .step(&mut st, u, T::from_f64(1e-3), Scheme::Rk4)
                .unwrap();
        }
        states.push((u, bench.signals(&st)));
    }
    let obs = Observer::<T>::new(ObserverConfig::paper(), T::from_f64(30.0)).unwrap();
    g.bench_function("observer_update", |b| {
        b.iter_batched_ref(
            || (obs.clone(), 0usize),
            |(o, k)| {
                let (u, s) = states[*k % states.len()];
                *k += 1;
                let m = Measurements {
                    pressure_mca: Some(s.pressure_mca),
                    flow_lps: Some(s.flow_lps),
                    speed_rpm: Some(s.speed_rpm),
                };
                black_box(o.step(T::from_f64(0.05), u, &m).unwrap())
            },
            BatchSize::SmallInput,
        )
    });
    g.finish();
}

fn whitebox_both(c: &mut Criterion) {
    whitebox::<f32>(c, "f32");
    whitebox::<f64>(c, "f64");
}

criterion_group!(benches, narmax, tanh, whitebox_both);
criterion_main!(benches);
