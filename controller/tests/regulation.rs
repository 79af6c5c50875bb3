//! Modes 3 and 4 on the virtual board (its bench a few percent off the model, lagged, noisy,
//! 12-bit transmitters; the drive over the Modbus VFD link), driven over SCADA as a user
//! does: the loop holds its setpoint, switches without a torque step, acts on the observer's
//! values when a transmitter fails, freezes while the drive's link is down, and a trip resets
//! it. The figures against the targets are `pumpbench control`'s (on richer plants).

mod common;

use common::{input, run, setup, setup_with, write_holding, Board};
use controller::types::{Mode, Status};
use controller::virtual_bench::VirtualBenchConfig;

/// Holding registers of the loops (controller::scada's table).
const MODE: u8 = 1;
const FAULTS: u8 = 4;
const PRESSURE_SP: u8 = 8;
const FLOW_SP: u8 = 9;
const TORQUE_MIN: u8 = 10;
const TORQUE_MAX: u8 = 11;
const LAW: u8 = 14;
const STATIC_HEAD: u8 = 20;

/// Runs `ms` ms; each step's applied torque (the board's output).
fn torques(b: &mut Board, ms: u32) -> Vec<f32> {
    (0..ms)
        .map(|_| {
            run(b, 1);
            b.io.torque_ref_pct()
        })
        .collect()
}

/// The largest torque change between two steps, % (the rate limit allows 0.2 % per ms).
fn largest_step(from: f32, t: &[f32]) -> f32 {
    let mut last = from;
    t.iter()
        .map(|&u| {
            let d = (u - last).abs();
            last = u;
            d
        })
        .fold(0.0, f32::max)
}

fn status(b: &mut Board) -> Status {
    Status::from_bits(input(b, 0))
}

/// Pressure at `sp_mca` in mode 3 from manual 40 % on the bench `bench`, after `ms` ms.
fn holding_pressure_on(bench: VirtualBenchConfig, sp_mca: f32, ms: u32) -> Board {
    let mut b = setup_with(Mode::Manual, 40.0, bench);
    run(&mut b, 3000);
    write_holding(&mut b, PRESSURE_SP, (sp_mca * 1000.0) as u16);
    write_holding(&mut b, MODE, 3);
    run(&mut b, ms);
    b
}

/// Pressure at `sp_mca` in mode 3 from manual 40 %, settled.
fn holding_pressure(sp_mca: f32) -> Board {
    let mut b = setup(Mode::Manual, 40.0);
    run(&mut b, 3000);
    write_holding(&mut b, PRESSURE_SP, (sp_mca * 1000.0) as u16);
    write_holding(&mut b, MODE, 3);
    run(&mut b, 6000);
    b
}

#[test]
fn pressure_control_holds_its_setpoint_and_enters_without_a_step() {
    let mut b = setup(Mode::Manual, 40.0);
    run(&mut b, 3000);
    let before = b.io.torque_ref_pct();
    write_holding(&mut b, PRESSURE_SP, 3000);
    write_holding(&mut b, MODE, 3);
    let t = torques(&mut b, 6000);
    assert!(
        largest_step(before, &t) <= 0.2 + 1e-4,
        "no step on the switch"
    );
    let p = b.io.bench.signals().pressure_mca;
    assert!(
        (p - 3.0).abs() < 0.06,
        "true pressure {p} within 2 % of 3 mca"
    );
    let s = status(&mut b);
    assert!(s.in_control && !s.virtual_measurement && !s.control_held && !s.holds_flow);
    // Register 26: the active setpoint, 27 the error, 0.001 mca.
    assert_eq!(input(&mut b, 26), 3000);
    assert!((input(&mut b, 27) as i16).abs() < 60);
}

#[test]
fn flow_control_holds_its_setpoint_and_runs_on_the_virtual_flow_meter() {
    let mut b = setup(Mode::Manual, 40.0);
    run(&mut b, 3000);
    write_holding(&mut b, FLOW_SP, 1200);
    write_holding(&mut b, MODE, 4);
    run(&mut b, 8000);
    let q = b.io.bench.signals().flow_lps;
    assert!(
        (q - 12.0).abs() < 0.24,
        "true flow {q} within 2 % of 12 l/s"
    );
    assert!(status(&mut b).holds_flow && status(&mut b).in_control);
    // The flow transmitter at 2 mA (NE 43 fault): the loop goes on on the observer's flow.
    write_holding(&mut b, FAULTS, 1 << 2);
    let t = torques(&mut b, 10_000);
    assert!(t.iter().all(|u| u.is_finite() && (0.0..=100.0).contains(u)));
    let s = status(&mut b);
    assert!(
        s.flow_fault && s.virtual_measurement && s.in_control,
        "{s:?}"
    );
    let q = b.io.bench.signals().flow_lps;
    eprintln!("flow on the virtual flow meter after 10 s: {q} l/s (setpoint 12)");
    assert!(
        (q - 12.0).abs() < 0.24,
        "true flow {q} within 2 % of 12 l/s"
    );
}

#[test]
fn a_lost_pressure_transmitter_leaves_the_loop_on_the_observer_or_holding_with_an_alarm() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, FAULTS, 1 << 1);
    let before = b.io.torque_ref_pct();
    let t = torques(&mut b, 5000);
    assert!(t.iter().all(|u| u.is_finite() && (0.0..=100.0).contains(u)));
    assert!(largest_step(before, &t) <= 0.2 + 1e-4);
    let s = status(&mut b);
    assert!(s.pressure_fault);
    assert!(
        s.virtual_measurement != s.control_held,
        "one or the other: {s:?}"
    );
    let p = b.io.bench.signals().pressure_mca;
    eprintln!("pressure transmitter lost: {s:?}, true pressure {p} mca after 5 s");
    if s.control_held {
        assert!(s.any_alarm);
        assert_eq!(t[t.len() - 1], t[t.len() - 1000], "the last torque held");
    } else {
        assert!((p - 3.0).abs() < 0.15, "on the observer's pressure: {p}");
    }
}

#[test]
fn the_vfd_link_cut_gives_0_pct_and_freezes_the_loop_which_restarts_without_a_step() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, FAULTS, 1 << 3);
    // The link takes a few failed exchanges to call its alarm.
    run(&mut b, 1500);
    let s = status(&mut b);
    assert!(!s.in_control && !s.vfd_link_ok);
    let integral = input(&mut b, 29);
    // The observer waits too (the pump does not get the torque the model would be told):
    // its valve k2 (input register 20) stays, however the coasting bench reads.
    let k2 = input(&mut b, 20);
    let t = torques(&mut b, 1000);
    assert!(t.iter().all(|&u| u == 0.0), "0 % while the link is down");
    assert_eq!(input(&mut b, 29), integral, "the integrator frozen");
    assert_eq!(input(&mut b, 20), k2, "the observer's k2 held");
    write_holding(&mut b, FAULTS, 0);
    let t = torques(&mut b, 8000);
    let k = t.iter().position(|&u| u > 0.0).unwrap_or(0);
    assert!(
        largest_step(0.0, &t) <= 0.2 + 1e-4,
        "back without a step: {:?}",
        &t[k.saturating_sub(2)..k + 10]
    );
    let p = b.io.bench.signals().pressure_mca;
    assert!((p - 3.0).abs() < 0.06, "back at 3 mca: {p}");
}

#[test]
fn a_trip_acts_in_pressure_control_and_resets_the_loop() {
    let mut b = holding_pressure(3.0);
    // A dry run: the pump loses its prime; the dry-run protection trips to 0 %.
    write_holding(&mut b, FAULTS, 1);
    run(&mut b, 3000);
    let s = status(&mut b);
    assert!(s.tripped && !s.in_control, "{s:?}");
    assert_eq!(b.io.torque_ref_pct(), 0.0);
    assert_eq!(
        input(&mut b, 29),
        0,
        "no integral published: the loop is gone"
    );
    write_holding(&mut b, FAULTS, 0);
    run(&mut b, 1000);
    write_holding(&mut b, MODE, 0);
    run(&mut b, 3000);
    assert!(
        !status(&mut b).tripped,
        "acknowledged once the cause has gone"
    );
    write_holding(&mut b, MODE, 3);
    let t = torques(&mut b, 8000);
    assert!(
        largest_step(0.0, &t) <= 0.2 + 1e-4,
        "restart without a step"
    );
    let p = b.io.bench.signals().pressure_mca;
    assert!((p - 3.0).abs() < 0.06, "back at 3 mca: {p}");
}

#[test]
fn every_mode_switch_moves_the_torque_at_the_rate_limit() {
    let mut b = holding_pressure(3.0);
    for (mode, ms) in [
        (1u16, 2000),
        (4, 4000),
        (2, 3000),
        (3, 4000),
        (0, 2000),
        (4, 4000),
    ] {
        let before = b.io.torque_ref_pct();
        write_holding(&mut b, FLOW_SP, 1000);
        write_holding(&mut b, MODE, mode);
        let t = torques(&mut b, ms);
        // The profile's own pulses are steps (its excitation), not the switch's: look at
        // the first 100 ms only there.
        let seen = if mode == 2 { &t[..50] } else { &t[..] };
        assert!(
            largest_step(before, seen) <= 0.2 + 1e-4,
            "mode {mode}: a step of {}",
            largest_step(before, seen)
        );
    }
}

#[test]
fn the_torque_stays_within_its_limits_and_the_pi_alone_also_holds() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, TORQUE_MAX, 3500);
    write_holding(&mut b, PRESSURE_SP, 6000);
    let t = torques(&mut b, 3000);
    assert!(t.iter().all(|&u| u <= 35.0));
    let s = status(&mut b);
    assert!(s.limited && s.in_control, "{s:?}");
    write_holding(&mut b, TORQUE_MAX, 10000);
    write_holding(&mut b, TORQUE_MIN, 2000);
    write_holding(&mut b, PRESSURE_SP, 0);
    let t = torques(&mut b, 3000);
    assert!(t[1500..].iter().all(|&u| u >= 20.0 - 1e-4));
    write_holding(&mut b, TORQUE_MIN, 0);
    write_holding(&mut b, LAW, 1);
    write_holding(&mut b, PRESSURE_SP, 2500);
    run(&mut b, 10_000);
    let p = b.io.bench.signals().pressure_mca;
    assert!((p - 2.5).abs() < 0.05, "PI alone at 2.5 mca: {p}");
    assert_eq!(input(&mut b, 28), 0, "no feedforward");
}

/// A bench further from the model: heavier rotor, heavier load, another valve, slower
/// transmitters.
#[test]
fn pressure_and_flow_hold_on_a_bench_further_from_the_model() {
    let other = VirtualBenchConfig {
        inertia_factor: 1.3,
        load_torque_factor: 1.06,
        valve_factor: 0.9,
        pressure_lag_s: 0.05,
        flow_lag_s: 0.15,
        ..VirtualBenchConfig::default_offsets(99)
    };
    let mut b = holding_pressure_on(other, 2.5, 8000);
    let p = b.io.bench.signals().pressure_mca;
    assert!((p - 2.5).abs() < 0.05, "{p}");
    write_holding(&mut b, FLOW_SP, 1500);
    write_holding(&mut b, MODE, 4);
    run(&mut b, 8000);
    let q = b.io.bench.signals().flow_lps;
    assert!((q - 15.0).abs() < 0.3, "{q}");
}

/// Regressions of the hostile review: a link cut shorter than the ramp down, a change of law,
/// manual from automatic, a slow loop rate on a stop, a setpoint the torque cannot reach.
#[test]
fn a_short_link_cut_comes_back_without_a_step() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, FAULTS, 1 << 3);
    // Until the alarm stands (the link takes its failed exchanges), then 100 ms more.
    for _ in 0..3000 {
        run(&mut b, 1);
        if !status(&mut b).vfd_link_ok {
            break;
        }
    }
    assert!(!status(&mut b).vfd_link_ok, "the link alarm");
    run(&mut b, 100);
    write_holding(&mut b, FAULTS, 0);
    let before = b.io.torque_ref_pct();
    let t = torques(&mut b, 4000);
    assert!(
        largest_step(before, &t) <= 0.2 + 1e-4,
        "a step of {} after a short cut",
        largest_step(before, &t)
    );
}

#[test]
fn a_change_of_law_in_pressure_control_is_bumpless() {
    let mut b = holding_pressure(3.0);
    for law in [1u16, 0] {
        let before = b.io.torque_ref_pct();
        write_holding(&mut b, LAW, law);
        let t = torques(&mut b, 3000);
        assert!(largest_step(before, &t) <= 0.2 + 1e-4, "law {law}");
        let worst = (0..3000)
            .map(|_| {
                run(&mut b, 1);
                (b.io.bench.signals().pressure_mca - 3.0).abs()
            })
            .fold(0.0f32, f32::max);
        assert!(worst < 0.06, "law {law}: {worst} mca off after 3 s");
    }
}

/// Register 20 written under a running pressure loop: the models take another static head
/// (here a wrong one, 1 mca of lift the bench does not have, then the paper's again), the
/// torque does not step, and the loop holds its setpoint through the wrong model. The
/// observer's k2 moves with the head so that the model still passes through the operating
/// point: the feedforward still holds it, and the integral (input register 29, 0.01 %) stays
/// small (at a k2 left where it was, the model at 1 mca of lift is ≈ 20 % of torque short).
#[test]
fn a_static_head_written_in_pressure_control_is_bumpless() {
    let mut b = holding_pressure(3.0);
    for head in [1000i16, -252] {
        let before = b.io.torque_ref_pct();
        write_holding(&mut b, STATIC_HEAD, head as u16);
        let mut t = torques(&mut b, 100);
        let integral = input(&mut b, 29) as i16;
        assert!(integral.abs() < 300, "{head}: the integral at {integral}");
        t.extend(torques(&mut b, 2900));
        assert!(
            largest_step(before, &t) <= 0.2 + 1e-4,
            "{head}: a step of {}",
            largest_step(before, &t)
        );
        let worst = (0..3000)
            .map(|_| {
                run(&mut b, 1);
                (b.io.bench.signals().pressure_mca - 3.0).abs()
            })
            .fold(0.0f32, f32::max);
        assert!(worst < 0.06, "{head}: {worst} mca off after 3 s");
    }
}

#[test]
fn manual_from_pressure_control_holds_the_torque_until_a_setpoint_is_written() {
    let mut b = holding_pressure(3.0);
    let held = b.io.torque_ref_pct();
    write_holding(&mut b, MODE, 1); // register 0 still holds 0 %
    let t = torques(&mut b, 2000);
    assert!(t.iter().all(|&u| (u - held).abs() < 1e-4), "held at {held}");
    write_holding(&mut b, 0, 3000);
    let t = torques(&mut b, 1000);
    assert_eq!(t[t.len() - 1], 30.0, "the new manual setpoint");
}

/// Manual entered from mode 3 holds the loop's torque until register 0 is written: a write of
/// the value it already holds (0 %, the operator asking for 0 % again) ends the hold, after
/// the switch or with it (before the same step, as a multi-register write of 0..1 lands), and
/// the torque goes to it at the switch rate.
#[test]
fn any_write_of_the_manual_setpoint_ends_manual_modes_hold() {
    for case in ["after", "setpoint first", "mode first"] {
        let mut b = holding_pressure(3.0);
        let held = b.io.torque_ref_pct();
        match case {
            "after" => {
                write_holding(&mut b, MODE, 1);
                run(&mut b, 500);
                assert_eq!(b.io.torque_ref_pct(), held, "held");
                write_holding(&mut b, 0, 0);
            }
            "setpoint first" => {
                write_holding(&mut b, 0, 0);
                write_holding(&mut b, MODE, 1);
            }
            _ => {
                write_holding(&mut b, MODE, 1);
                write_holding(&mut b, 0, 0);
            }
        }
        let t = torques(&mut b, 1500);
        assert_eq!(t[t.len() - 1], 0.0, "{case}: 0 % after the write");
        assert!(
            largest_step(held, &t) <= 0.2 + 1e-4,
            "{case}: at the switch rate"
        );
    }
}

#[test]
fn a_low_limit_written_under_a_running_loop_is_reached_at_the_rate() {
    let mut b = holding_pressure(3.0);
    let before = b.io.torque_ref_pct();
    assert!(before < 80.0, "{before}");
    write_holding(&mut b, TORQUE_MIN, 9000);
    let t = torques(&mut b, 1000);
    assert!(
        largest_step(before, &t) <= 0.2 + 1e-4,
        "a step of {}",
        largest_step(before, &t)
    );
    assert!(t[500..].iter().all(|&u| u >= 90.0 - 1e-4), "then within it");
}

#[test]
fn a_low_limit_is_reached_at_the_switch_rate_on_a_switch_and_the_links_return() {
    let mut b = setup(Mode::Stop, 0.0);
    run(&mut b, 1000);
    write_holding(&mut b, TORQUE_MIN, 5000);
    write_holding(&mut b, PRESSURE_SP, 6000);
    write_holding(&mut b, MODE, 3);
    let t = torques(&mut b, 3000);
    assert!(
        largest_step(0.0, &t) <= 0.2 + 1e-4,
        "from stop into mode 3 with the low limit at 50 %: a step of {}",
        largest_step(0.0, &t)
    );
    assert!(t[500..].iter().all(|&u| u >= 50.0 - 1e-4), "then within it");
    write_holding(&mut b, FAULTS, 1 << 3);
    run(&mut b, 1500);
    assert!(!status(&mut b).vfd_link_ok, "the link alarm");
    assert_eq!(b.io.torque_ref_pct(), 0.0, "0 % while the link is down");
    write_holding(&mut b, FAULTS, 0);
    let t = torques(&mut b, 3000);
    assert!(
        largest_step(0.0, &t) <= 0.2 + 1e-4,
        "the link's return: a step of {}",
        largest_step(0.0, &t)
    );
    assert!(t[2500..].iter().all(|&u| u >= 50.0 - 1e-4));
}

#[test]
fn bit_7_stays_set_while_a_cleared_trip_still_holds_0_pct() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, FAULTS, 1); // dry run: the trip
    run(&mut b, 3000);
    assert!(status(&mut b).tripped);
    // Acknowledged while the cause stands (kept), and mode 3 written before the trip
    // clears: no restart, the torque held at 0 % until mode 0 is seen.
    write_holding(&mut b, MODE, 0);
    write_holding(&mut b, MODE, 3);
    write_holding(&mut b, FAULTS, 0);
    run(&mut b, 5000);
    assert_eq!(input(&mut b, 23), 0, "the trip has cleared");
    assert_eq!(b.io.torque_ref_pct(), 0.0, "still held");
    let s = status(&mut b);
    assert!(s.tripped && !s.running && !s.in_control, "{s:?}");
    write_holding(&mut b, MODE, 0);
    run(&mut b, 10);
    assert!(!status(&mut b).tripped, "released by mode 0");
    write_holding(&mut b, MODE, 3);
    run(&mut b, 1000);
    assert!(b.io.torque_ref_pct() > 0.0, "restarted");
}

#[test]
fn a_stop_takes_at_most_2_s_whatever_the_loop_rate_and_shows_running_meanwhile() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, 12, 1); // 0.1 %/s for the loop
    write_holding(&mut b, MODE, 0);
    run(&mut b, 50);
    assert!(b.io.torque_ref_pct() > 0.0);
    assert!(status(&mut b).running, "running while a torque is applied");
    run(&mut b, 2000);
    assert_eq!(b.io.torque_ref_pct(), 0.0);
    assert!(!status(&mut b).running);
}

#[test]
fn the_reference_waits_while_the_torque_cannot_reach_it() {
    let mut b = holding_pressure(3.0);
    write_holding(&mut b, TORQUE_MAX, 3500);
    write_holding(&mut b, PRESSURE_SP, 6000);
    run(&mut b, 5000);
    assert!(status(&mut b).limited);
    write_holding(&mut b, PRESSURE_SP, 1500);
    let t = torques(&mut b, 2000);
    let off = t.iter().position(|&u| u < 35.0 - 1e-3).unwrap_or(t.len());
    eprintln!("off the 35 % limit {off} ms after the setpoint came within reach");
    // With the reference run on to 6 mca it took 450 ms (the review's measurement).
    assert!(off < 300, "off the limit after {off} ms");
}

/// Behind a pressure transmitter much slower than the observer's own (300 ms against 20),
/// untold: the observer widens its lag's uncertainty to the lag the loop measures beyond its
/// own, so its k2 moves less during the setpoint steps and the loop keeps the lesson of the
/// first step (before, the observer read the reading's delay as the valve moving and the
/// loop's probe undid its lessons).
#[test]
fn the_observers_lag_uncertainty_covers_the_lag_measured() {
    use controller::control::observer_pressure_lag_sd_s;
    use model_core::observer::K2;
    let slow = VirtualBenchConfig {
        pressure_lag_s: 0.3,
        ..VirtualBenchConfig::default_offsets(7)
    };
    let mut b = holding_pressure_on(slow, 2.0, 6000);
    let k2_held = b.controller.observer().state()[K2];
    let (mut peaks, mut k2_off) = (vec![], 0.0f32);
    for (from, to) in [(2.0f32, 4.0f32), (4.0, 1.0), (1.0, 3.0)] {
        write_holding(&mut b, PRESSURE_SP, (to * 1000.0) as u16);
        let mut peak = 0.0f32;
        for _ in 0..6000 {
            run(&mut b, 1);
            let p = b.io.bench.signals().pressure_mca;
            peak = peak.max((p - to) * (to - from).signum());
            let k2 = b.controller.observer().state()[K2];
            k2_off = k2_off.max((k2 / k2_held - 1.0).abs());
        }
        peaks.push(100.0 * peak / (to - from).abs());
    }
    let measured = b.controller.measured_lag_s()[0];
    let c = *b.controller.observer().config();
    println!(
        "overshoots {peaks:?} %, k2 off {k2_off}, measured {measured} s, lag {} ± {} s",
        c.pressure_lag_s, c.pressure_lag_sd_s
    );
    // The steps after the first under the 5 % (3.3, 3.5 %; 9.7 and 15.4 % with the
    // observer's 40 ms, whose lessons were undone: 85 ms measured, 175 now), and the
    // observer's k2 off where it held before the steps (the valve does not move) by 9.5 %
    // at most (22 % with the 40 ms).
    assert!(peaks[1] < 5.0 && peaks[2] < 5.0, "{peaks:?} %");
    assert!(measured > 0.15, "{measured} s measured");
    assert!(k2_off < 0.15, "k2 off by {k2_off}");
    assert_eq!(c.pressure_lag_s, 0.02);
    assert_eq!(
        c.pressure_lag_sd_s,
        observer_pressure_lag_sd_s(measured, c.pressure_lag_s)
    );
}
