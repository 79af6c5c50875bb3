//! A simulated VFD on the Modbus side: an RTU slave with a [`VfdMap`]'s registers.
//!
//! It takes the torque reference (FC 06 to [`VfdMap::torque_ref_register`], 0..=counts for
//! 100 %) and answers FC 03 reads of the block at [`VfdMap::read_start`] with the actual speed,
//! torque and status it is given. Anything else for its unit gets the spec's exception (01 for
//! another function, 02 for another address, 03 for a bad quantity or a reference above 100 %);
//! frames with a bad CRC, another unit or a wrong length get silence. The firmware's virtual
//! bench and `pumpbench vfd-sim` both use it, so the master is tested against one slave on the
//! host and on the target.

use crate::scada::{crc16, signed_register};
use crate::vfd::{Frame, VfdMap};

/// Status word bit 0: the drive runs (torque reference above 0).
pub const STATUS_RUNNING: u16 = 1 << 0;
/// Status word bit 1: the drive is ready (always set by the simulator).
pub const STATUS_READY: u16 = 1 << 1;

/// What the simulated drive reports.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveValues {
    /// Actual speed, rpm.
    pub speed_rpm: f32,
    /// Actual torque, % of nominal.
    pub torque_pct: f32,
}

/// The simulated drive's Modbus side.
#[derive(Debug, Clone, PartialEq)]
pub struct VfdSim {
    map: VfdMap,
    reference_counts: u16,
    writes: u32,
}

impl VfdSim {
    /// A drive answering at `map.unit`; `None` for a map that is not valid.
    pub fn new(map: VfdMap) -> Option<Self> {
        map.is_valid().then_some(Self {
            map,
            reference_counts: 0,
            writes: 0,
        })
    }

    /// The torque reference last written, % of nominal (0..=100).
    pub fn torque_ref_pct(&self) -> f32 {
        f32::from(self.reference_counts) * 100.0 / f32::from(self.map.counts_per_100_pct)
    }

    /// Torque reference writes taken so far.
    pub fn writes(&self) -> u32 {
        self.writes
    }

    /// The status word for the drive's state.
    pub fn status(&self) -> u16 {
        STATUS_READY
            | if self.reference_counts > 0 {
                STATUS_RUNNING
            } else {
                0
            }
    }

    /// Handles one request frame; the answer (if any) goes to `out`.
    pub fn handle(&mut self, f: &[u8], values: &DriveValues, out: &mut Frame) -> Option<usize> {
        out.clear();
        let n = f.len();
        if !(4..=crate::scada::MAX_FRAME).contains(&n)
            || f[0] != self.map.unit
            || crc16(&f[..n - 2]) != u16::from_le_bytes([f[n - 2], f[n - 1]])
            || f[1] >= 0x80
        {
            return None;
        }
        let func = f[1];
        let word = |at: usize| u16::from_be_bytes([f[at], f[at + 1]]);
        let result = match func {
            3 | 6 if n != 8 => return None,
            6 if word(2) != self.map.torque_ref_register => Err(2),
            6 if word(4) > self.map.counts_per_100_pct => Err(3),
            6 => {
                self.reference_counts = word(4);
                self.writes = self.writes.wrapping_add(1);
                out.extend_from_slice(&f[..6]).ok()?;
                Ok(())
            }
            3 => {
                let (start, count) = (word(2), word(4));
                if count == 0 || count > 125 {
                    Err(3)
                } else if start != self.map.read_start || count != self.map.read_count {
                    Err(2)
                } else {
                    let mut block = [0u16; crate::vfd::MAX_READ as usize];
                    let m = &self.map;
                    block[usize::from(m.speed_offset)] =
                        signed_register(values.speed_rpm / m.rpm_per_count, 1.0);
                    block[usize::from(m.torque_offset)] =
                        signed_register(values.torque_pct, f32::from(m.counts_per_100_pct) / 100.0);
                    block[usize::from(m.status_offset)] = self.status();
                    out.extend_from_slice(&[f[0], 3, (2 * count) as u8]).ok()?;
                    for w in &block[..usize::from(count)] {
                        out.extend_from_slice(&w.to_be_bytes()).ok()?;
                    }
                    Ok(())
                }
            }
            _ => Err(1),
        };
        if let Err(code) = result {
            out.clear();
            out.extend_from_slice(&[f[0], func | 0x80, code]).ok()?;
        }
        let crc = crc16(out);
        out.extend_from_slice(&crc.to_le_bytes()).ok()?;
        Some(out.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vfd::VfdMaster;

    #[test]
    fn the_master_drives_the_simulator() {
        for map in [
            VfdMap::example_16384(),
            VfdMap {
                counts_per_100_pct: 10_000,
                rpm_per_count: 0.1,
                ..VfdMap::example_16384()
            },
        ] {
            let mut m = VfdMaster::new(map).unwrap();
            let mut sim = VfdSim::new(map).unwrap();
            let values = DriveValues {
                speed_rpm: 1234.5,
                torque_pct: 42.25,
            };
            let (mut req, mut ans) = (Frame::new(), Frame::new());
            for t in 0..4 {
                m.start(t * map.cycle_ms, 50.0, &mut req).unwrap();
                sim.handle(&req, &values, &mut ans).unwrap();
                m.receive(&ans);
            }
            assert!(!m.alarm());
            assert_eq!(m.exchanges_ok(), 4);
            assert!((sim.torque_ref_pct() - 50.0).abs() < 0.01);
            let r = m.readings().expect("readings after good reads");
            assert!((r.speed_rpm - 1234.5).abs() <= map.rpm_per_count, "{r:?}");
            assert!((r.torque_pct - 42.25).abs() < 0.01, "{r:?}");
            assert_eq!(r.status, STATUS_READY | STATUS_RUNNING);
        }
    }

    #[test]
    fn exceptions_and_silence() {
        let map = VfdMap::example_16384();
        let mut sim = VfdSim::new(map).unwrap();
        let v = DriveValues::default();
        let mut out = Frame::new();
        let mut ask = |body: &[u8]| {
            let mut f = body.to_vec();
            f.extend_from_slice(&crc16(body).to_le_bytes());
            sim.handle(&f, &v, &mut out).map(|_| out.to_vec())
        };
        assert_eq!(ask(&[1, 6, 0x20, 1, 0, 1]).unwrap()[1..3], [0x86, 2]);
        assert_eq!(ask(&[1, 6, 0x20, 0, 0x40, 1]).unwrap()[1..3], [0x86, 3]);
        assert_eq!(ask(&[1, 3, 0x21, 0, 0, 9]).unwrap()[1..3], [0x83, 2]);
        assert_eq!(ask(&[1, 3, 0x21, 0, 0, 0]).unwrap()[1..3], [0x83, 3]);
        assert_eq!(ask(&[1, 4, 0, 0, 0, 1]).unwrap()[1..3], [0x84, 1]);
        assert_eq!(ask(&[2, 3, 0x21, 0, 0, 3]), None);
        assert_eq!(ask(&[1, 3, 0x21, 0, 0, 3, 0]), None);
        assert_eq!(sim.writes(), 0);
    }
}
