//! The commissioning record: one row per pressure sample, for `pumpbench identify` on a bench
//! that is not ours.
//!
//! The board makes a row after each step on which the pressure transmitter was sampled
//! ([`RecordRow::at_step`], from the step's [`Published`] values, no work in the 1 ms core)
//! and sends it over its log channel: defmt over semihosting on QEMU, defmt over RTT on the
//! Nucleo. `cargo xtask record` reads the rows and writes the CSV
//! ([`RecordRow::CSV_HEADER`], [`RecordRow::csv_cells`]).
//!
//! - **Nothing lost silently.** Each row carries its sample number ([`RecordRow::seq`], the
//!   pressure samples since start): a row the log channel dropped is a gap in the numbers,
//!   and in the CSV a gap in `t_s`, which `identify`'s uniform-sampling rule refuses.
//! - **Only measurements.** A reading the controller does not trust is an empty cell: the
//!   pressure while its transmitter is in fault (NE 43), the flow except on the flow
//!   transmitter's own sample ticks (every 100 ms with the shipped models) or while it is in
//!   fault, the drive's speed while its reads fail. `identify` takes the rows whose target
//!   cell is filled; they must be uniformly sampled.
//! - The torque is the applied reference of the sampling step, the input the NARMAX models
//!   take in the firmware ([`crate::control`]).

use crate::types::{Published, Status};

/// One row of the commissioning record, in the core's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordRow {
    /// Pressure samples taken before this one since start (0, 1, 2, …): consecutive rows
    /// differ by 1.
    pub seq: u32,
    /// The sampling step's time, ms.
    pub t_ms: u32,
    /// Applied torque reference, % (0..=100).
    pub torque_pct: f32,
    /// Pressure reading, mca (the transmitter's span; meaningful unless status bit 4, the
    /// transmitter's fault, is set).
    pub pressure_mca: f32,
    /// Flow reading, l/s (meaningful on a flow sample, [`RecordRow::flow_sampled`], unless
    /// status bit 5 is set).
    pub flow_lps: f32,
    /// The flow transmitter was sampled on this step.
    pub flow_sampled: bool,
    /// The drive's speed, rpm (0 while its reads fail: status bit 6).
    pub vfd_speed_rpm: f32,
    /// The observer's valve coefficient k2, √mca/(l/s).
    pub observer_k2: f32,
    /// The observer's flow, l/s.
    pub observer_flow_lps: f32,
    /// Alarm bits (SCADA input register 21's).
    pub alarms: u16,
    /// Status bits ([`Status::bits`]).
    pub status: u16,
}

impl RecordRow {
    /// The CSV header `cargo xtask record` writes; `t_s`, `torque_ref_pct` and the readings
    /// are what `pumpbench identify` reads.
    pub const CSV_HEADER: &'static str = "t_s,torque_ref_pct,pressure_mca,flow_lps,speed_rpm,observer_k2,observer_flow_lps,alarms,status,seq";

    /// The row of the step at `t_ms` whose values are `p`, if the pressure transmitter was
    /// sampled on it (every `pressure_period_ms`; the flow every `flow_period_ms`, a multiple
    /// of it: [`crate::control::Controller::sample_periods_ms`]); `None` on other steps or
    /// for a period of 0.
    pub fn at_step(
        t_ms: u32,
        p: &Published,
        pressure_period_ms: u32,
        flow_period_ms: u32,
    ) -> Option<Self> {
        if pressure_period_ms == 0 || !t_ms.is_multiple_of(pressure_period_ms) {
            return None;
        }
        Some(Self {
            seq: t_ms / pressure_period_ms,
            t_ms,
            torque_pct: p.torque_pct,
            pressure_mca: p.pressure_mca,
            flow_lps: p.flow_lps,
            flow_sampled: flow_period_ms != 0 && t_ms.is_multiple_of(flow_period_ms),
            vfd_speed_rpm: p.vfd_speed_rpm,
            observer_k2: p.observer_valve_k2,
            observer_flow_lps: p.observer_flow_lps,
            alarms: p.alarms,
            status: p.status,
        })
    }

    /// The pressure, if it is a measurement (the transmitter not in fault), mca.
    pub fn pressure(&self) -> Option<f32> {
        (!Status::from_bits(self.status).pressure_fault).then_some(self.pressure_mca)
    }

    /// The flow, if it was sampled on this step and is a measurement, l/s.
    pub fn flow(&self) -> Option<f32> {
        (self.flow_sampled && !Status::from_bits(self.status).flow_fault).then_some(self.flow_lps)
    }

    /// The drive's speed, if its reads succeed, rpm.
    pub fn speed(&self) -> Option<f32> {
        (!Status::from_bits(self.status).vfd_readings_invalid).then_some(self.vfd_speed_rpm)
    }

    /// The row's cells in [`RecordRow::CSV_HEADER`]'s order, f32 values in their shortest
    /// exact decimal form (written by `fmt`, e.g. `ryu`'s), an absent reading empty; `t_s`
    /// in ms written as seconds with three decimals (exact).
    pub fn csv_cells(&self, fmt: impl Fn(f32) -> CsvCell) -> [CsvCell; 10] {
        let opt = |x: Option<f32>| x.map(&fmt).unwrap_or_default();
        let int = |n: u32| {
            let mut s = heapless::String::new();
            let _ = core::fmt::write(&mut s, format_args!("{n}"));
            s
        };
        let mut t = heapless::String::new();
        let _ = core::fmt::write(
            &mut t,
            format_args!("{}.{:03}", self.t_ms / 1000, self.t_ms % 1000),
        );
        [
            t,
            fmt(self.torque_pct),
            opt(self.pressure()),
            opt(self.flow()),
            opt(self.speed()),
            fmt(self.observer_k2),
            fmt(self.observer_flow_lps),
            int(u32::from(self.alarms)),
            int(u32::from(self.status)),
            int(self.seq),
        ]
    }
}

/// One CSV cell: a number's text (at most 24 bytes: an f32's shortest form is at most 15).
pub type CsvCell = heapless::String<24>;

/// The row as defmt sends it (`rec seq=… t_ms=… u_pct=… p_mca=… q_lps=… q_new=… vfd_rpm=…
/// ob_k2=… ob_q=… alarms=… status=…`): the values travel as their bits, the host prints f32s
/// in their shortest exact form, so the CSV holds the controller's numbers bit for bit.
#[cfg(feature = "defmt")]
impl defmt::Format for RecordRow {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "rec seq={=u32} t_ms={=u32} u_pct={=f32} p_mca={=f32} q_lps={=f32} q_new={=bool} vfd_rpm={=f32} ob_k2={=f32} ob_q={=f32} alarms={=u16} status={=u16}",
            self.seq,
            self.t_ms,
            self.torque_pct,
            self.pressure_mca,
            self.flow_lps,
            self.flow_sampled,
            self.vfd_speed_rpm,
            self.observer_k2,
            self.observer_flow_lps,
            self.alarms,
            self.status
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shortest(x: f32) -> CsvCell {
        let mut s = heapless::String::new();
        let _ = core::fmt::write(&mut s, format_args!("{x}"));
        s
    }

    #[test]
    fn a_row_on_each_pressure_sample_numbered_from_zero() {
        let p = Published {
            torque_pct: 42.5,
            pressure_mca: 3.25,
            flow_lps: 12.5,
            vfd_speed_rpm: 1400.0,
            observer_valve_k2: 0.11,
            observer_flow_lps: 12.25,
            alarms: 0x40,
            status: Status::from_bits(0x9).bits(),
            ..Published::default()
        };
        let rows: Vec<_> = (0..=200)
            .filter_map(|t| RecordRow::at_step(t, &p, 50, 100))
            .collect();
        assert_eq!(rows.len(), 5);
        for (k, r) in rows.iter().enumerate() {
            assert_eq!(r.seq, k as u32);
            assert_eq!(r.t_ms, 50 * k as u32);
            assert_eq!(r.flow_sampled, k % 2 == 0);
            assert_eq!(r.flow(), (k % 2 == 0).then_some(12.5));
        }
        let cells = rows[1].csv_cells(shortest);
        let text: Vec<&str> = cells.iter().map(|c| c.as_str()).collect();
        assert_eq!(
            text,
            ["0.050", "42.5", "3.25", "", "1400", "0.11", "12.25", "64", "9", "1"]
        );
        assert_eq!(RecordRow::CSV_HEADER.split(',').count(), cells.len());
        assert_eq!(RecordRow::at_step(0, &p, 0, 100), None);
        assert_eq!(RecordRow::at_step(60, &p, 50, 100), None);
    }

    #[test]
    fn a_reading_in_fault_is_an_empty_cell() {
        let faults = Status {
            pressure_fault: true,
            flow_fault: true,
            vfd_readings_invalid: true,
            ..Status::from_bits(0)
        };
        let p = Published {
            status: faults.bits(),
            ..Published::default()
        };
        let r = RecordRow::at_step(1_000, &p, 50, 100).unwrap();
        assert_eq!((r.pressure(), r.flow(), r.speed()), (None, None, None));
        let cells = r.csv_cells(shortest);
        assert_eq!(
            [
                cells[0].as_str(),
                &cells[2],
                &cells[3],
                &cells[4],
                &cells[9]
            ],
            ["1.000", "", "", "", "20"]
        );
    }
}
