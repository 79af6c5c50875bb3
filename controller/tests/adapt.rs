//! Holding register 19: the NARMAX models follow the load (model_core::narmax::adapt) on the
//! virtual board, the shipped models against a bench they were not trained on, its valve
//! moved over SCADA.

mod common;

use common::{run, setup, write_holding, Board};
use controller::types::Mode;

const VALVE: u8 = 3;
const ADAPT: u8 = 19;
const FAULTS: u8 = 4;

/// The NARMAX pressure's and flow's MAPE (%) against the bench's truth, on their samples
/// over `ms`; the free-run outputs are published every step, read on sample ticks.
fn mape(b: &mut Board, ms: u32) -> (f64, f64) {
    let (mut p, mut q, mut np, mut nq) = (0.0, 0.0, 0u32, 0u32);
    for _ in 0..ms {
        let truth = b.io.bench.signals();
        let out = b.tick().unwrap();
        let v = b.controller.published();
        if out.t_ms.is_multiple_of(50) {
            p += f64::from(
                ((v.narmax_pressure_mca - truth.pressure_mca) / truth.pressure_mca).abs(),
            );
            np += 1;
        }
        if out.t_ms.is_multiple_of(100) {
            q += f64::from(((v.narmax_flow_lps - truth.flow_lps) / truth.flow_lps).abs());
            nq += 1;
        }
    }
    (100.0 * p / f64::from(np), 100.0 * q / f64::from(nq))
}

#[test]
fn the_models_follow_a_valve_moved_30_pct_with_register_19() {
    let mut r = vec![];
    for adapt in [0, 1] {
        let mut b = setup(Mode::Profile, 0.0);
        write_holding(&mut b, ADAPT, adapt);
        run(&mut b, 30_000);
        let fixed = mape(&mut b, 20_000);
        write_holding(&mut b, VALVE, 1300);
        run(&mut b, 10_000);
        let closed = mape(&mut b, 30_000);
        write_holding(&mut b, VALVE, 700);
        run(&mut b, 10_000);
        let open = mape(&mut b, 30_000);
        println!("register 19 = {adapt}: valve fixed {fixed:.2?}, x1.3 {closed:.2?}, x0.7 {open:.2?} (pressure, flow MAPE %)");
        r.push([fixed, closed, open]);
    }
    // Off, the models run one step ahead on the measurements (their regressors measured);
    // on, free, through their maps: a harder task, and still closer to the truth.
    let [off, on] = [r[0], r[1]];
    for k in 0..3 {
        assert!(on[k].1 < off[k].1, "flow: {:?} vs {:?}", on[k], off[k]);
    }
    assert!(
        on[0].0 < off[0].0 + 0.1,
        "pressure, valve fixed: {:?} vs {:?}",
        on[0],
        off[0]
    );
    for k in 1..3 {
        assert!(
            on[k].0 * 4.0 < off[k].0,
            "pressure: {:?} vs {:?}",
            on[k],
            off[k]
        );
    }
}

/// The pressure transmitter lost while the model follows the load: the model runs on, its
/// map frozen at the valve it learnt, a virtual transmitter that followed the load.
#[test]
fn a_lost_transmitter_freezes_the_map_and_the_model_runs_on() {
    let mut b = setup(Mode::Profile, 0.0);
    write_holding(&mut b, ADAPT, 1);
    write_holding(&mut b, VALVE, 1300);
    run(&mut b, 40_000);
    write_holding(&mut b, FAULTS, 0b10);
    run(&mut b, 100);
    let (p, _) = mape(&mut b, 20_000);
    println!(
        "pressure transmitter lost, valve x1.3 learnt: NARMAX pressure MAPE {p:.2} % over 20 s"
    );
    assert!(p < 3.0, "{p}");
    // Without the map, the free run is the model trained at the nominal valve.
    write_holding(&mut b, ADAPT, 0);
    run(&mut b, 100);
    let (p0, _) = mape(&mut b, 20_000);
    println!("the same without the map: {p0:.2} %");
    assert!(p * 4.0 < p0, "{p} vs {p0}");
}

/// The valve back at the one the model was trained at while the map still holds ×1.3: the
/// map does worse than no map, falls back to the identity (the shipped model) and raises the
/// model-residual alarm for a while, in the published alarms and the status's "any alarm";
/// with register 19 off, the same valve moves raise nothing.
#[test]
fn a_fallback_raises_the_model_residual_alarm() {
    use controller::types::Status;
    use model_core::monitor::MODEL_RESIDUAL;
    for adapt in [1, 0] {
        let mut b = setup(Mode::Profile, 0.0);
        write_holding(&mut b, ADAPT, adapt);
        write_holding(&mut b, VALVE, 1300);
        run(&mut b, 40_000);
        assert_eq!(b.controller.published().alarms & MODEL_RESIDUAL, 0);
        write_holding(&mut b, VALVE, 1000);
        let (mut first, mut shown) = (None, 0u32);
        for ms in 0..10_000 {
            b.tick().unwrap();
            let p = b.controller.published();
            if p.alarms & MODEL_RESIDUAL != 0 {
                first.get_or_insert(ms);
                shown += 1;
                assert!(Status::from_bits(p.status).any_alarm);
            }
        }
        println!("register 19 = {adapt}: valve back to x1: alarm first at {first:?} ms, shown {shown} ms");
        if adapt == 1 {
            // Within two memories (ADAPT_TAU_S = 2 s) of the move.
            let first = first.expect("the map fell back");
            assert!(first < 4_000, "{first} ms");
            // Shown for 60 samples of the model that fell back (3 s of pressure samples, 6 s
            // of flow ones), unless it falls back again.
            assert!(shown >= 2_900, "{shown} ms");
        } else {
            assert_eq!(first, None);
        }
    }
}
