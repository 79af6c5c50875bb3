use model_core::{Scheme, WhiteBox};
fn main() {
    let b = WhiteBox::<f64>::paper();
    for u in [0.0, 5.0, 15.0, 50.0, 75.0, 85.0, 100.0] {
        let s = b.steady_state(u).unwrap();
        let g = b.signals(&s);
        println!(
            "u={u:5} w={:.3} q={:.4} hs={:.5} head={:.4} loss+hs={:.4} te={:.4} ft={:.4} ex={:?}",
            g.speed_rpm,
            g.flow_lps,
            g.pressure_mca,
            g.pump_head_mca,
            g.pipe_loss_mca + g.pressure_mca,
            g.electromagnetic_torque_pct,
            g.load_torque_pct,
            g.extrapolation.any()
        );
    }
    println!("flow at 1749 rpm: {}", b.flow_at(1749.0, 0.0));
    for (a, z) in [(5.0, 15.0), (75.0, 85.0)] {
        let mut s = b.steady_state(a).unwrap();
        let w0 = s.speed_rpm;
        let w1 = b.steady_state(z).unwrap().speed_rpm;
        let mut t = 0.0;
        while (s.speed_rpm - w0) < 0.632 * (w1 - w0) {
            b.step(&mut s, z, 1e-4, Scheme::Rk4).unwrap();
            t += 1e-4;
        }
        println!("tau {a}->{z}: {t:.3}");
    }
}
