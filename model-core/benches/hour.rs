//! One hour of bench at a 1 ms step (3.6 M steps) per scheme and precision, on the host.
//! `cargo bench -p model-core --bench hour` prints a Markdown table (quoted in
//! docs/measurements.md, "Host speed").
use model_core::excitation::PulseTrain;
use model_core::{Real, Scheme, WhiteBox};
use std::hint::black_box;
use std::time::Instant;

fn run<T: Real>(scheme: Scheme) -> (f64, f64) {
    let bench = WhiteBox::<T>::paper();
    let mut state = bench.steady_state(T::from_f64(20.0)).unwrap();
    let mut pulses = PulseTrain::paper(1);
    let mut remaining = 3600.0;
    let start = Instant::now();
    let mut last = 0.0;
    while remaining > 0.0 {
        let p = pulses.next_pulse();
        let hold = p.hold_s.min(remaining);
        bench
            .advance(
                &mut state,
                T::from_f64(p.torque_ref_pct),
                hold,
                1e-3,
                scheme,
            )
            .unwrap();
        remaining -= hold;
        last = black_box(state.speed_rpm).to_f64();
    }
    (start.elapsed().as_secs_f64(), last)
}

fn main() {
    println!("| scheme | precision | 1 h at 1 ms (3.6 M steps), s | ns/step |");
    println!("|---|---|---|---|");
    for scheme in [Scheme::Rk4, Scheme::Heun, Scheme::Euler] {
        let (t64, _) = run::<f64>(scheme);
        println!("| {scheme:?} | f64 | {t64:.3} | {:.0} |", t64 / 3.6e6 * 1e9);
        let (t32, _) = run::<f32>(scheme);
        println!("| {scheme:?} | f32 | {t32:.3} | {:.0} |", t32 / 3.6e6 * 1e9);
    }
}
