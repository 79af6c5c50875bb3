//! A simulated VFD on the Modbus side: an RTU slave with a [`VfdMap`]'s registers, served by
//! the crate's one slave engine ([`crate::modbus::serve`]).
//!
//! | holding register | access | meaning |
//! |---|---|---|
//! | [`VfdMap::torque_ref_register`] | FC 03, FC 06 | torque reference, 0..=[`VfdMap::counts_per_100_pct`] counts |
//! | [`VfdMap::read_start`] + [`VfdMap::speed_offset`] | FC 03 | actual speed, signed, [`VfdMap::rpm_per_count`] rpm per count |
//! | [`VfdMap::read_start`] + [`VfdMap::torque_offset`] | FC 03 | actual torque, signed, the reference's scaling |
//! | [`VfdMap::read_start`] + [`VfdMap::status_offset`] | FC 03 | status word ([`STATUS_RUNNING`], [`STATUS_READY`]) |
//!
//! The read block is the [`VfdMap::read_count`] registers from [`VfdMap::read_start`] (those
//! not named above read 0); any part of it can be read, and it wins over the reference where
//! the two overlap. The drive serves FC 03 and FC 06 only: anything else for its unit, FC 04
//! and FC 16 included, is answered 01 (it has no input registers, and takes one register at a
//! time); 02 for an address outside the map (a write to anything but the reference, a read
//! leaving the block and the reference); 03 for a quantity outside 1..=125 or a reference
//! above 100 %. Frames with a bad CRC, for another unit, or of the wrong length for their
//! function get silence. The firmware's virtual bench and `pumpbench vfd-sim` both use it, so
//! the master is tested against one slave on the host and on the target.

use crate::modbus::{serve, signed_register, Exception, Frame, RegisterMap};
use crate::vfd::{VfdMap, MAX_READ};

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

    /// Handles one request frame `f` (the bytes between two silences), the drive reporting
    /// `values`; the answer (if any) goes to `out` and its length is returned, `None` being
    /// silence (see the module docs).
    pub fn handle(&mut self, f: &[u8], values: &DriveValues, out: &mut Frame) -> Option<usize> {
        let m = &self.map;
        let mut block = [0u16; MAX_READ as usize];
        // (`get_mut`, not indexing: the map's offsets are checked where it is made, and no
        // bounds check links the panic's formatting into the image, ≈ 0.6 KB.)
        for (offset, v) in [
            (
                m.speed_offset,
                signed_register(values.speed_rpm / m.rpm_per_count, 1.0),
            ),
            (
                m.torque_offset,
                signed_register(values.torque_pct, f32::from(m.counts_per_100_pct) / 100.0),
            ),
            (m.status_offset, self.status()),
        ] {
            if let Some(w) = block.get_mut(usize::from(offset)) {
                *w = v;
            }
        }
        let unit = m.unit;
        serve(unit, &mut DriveMap { sim: self, block }, f, out)
    }
}

/// The drive's register map for one request: the simulator and its read block.
struct DriveMap<'a> {
    sim: &'a mut VfdSim,
    block: [u16; MAX_READ as usize],
}

impl DriveMap<'_> {
    /// The holding register at `address`, if the map has one.
    fn register(&self, address: u32) -> Option<u16> {
        let m = &self.sim.map;
        let in_block = address
            .checked_sub(u32::from(m.read_start))
            .filter(|&k| k < u32::from(m.read_count));
        match in_block {
            Some(k) => self.block.get(usize::try_from(k).ok()?).copied(),
            None => {
                (address == u32::from(m.torque_ref_register)).then_some(self.sim.reference_counts)
            }
        }
    }
}

impl RegisterMap for DriveMap<'_> {
    fn serves(&self, function: u8) -> bool {
        matches!(function, 3 | 6)
    }

    fn read_holding_registers(&self, address: u16, out: &mut [u16]) -> Result<(), Exception> {
        for (k, w) in (u32::from(address)..).zip(out.iter_mut()) {
            *w = self.register(k).ok_or(Exception::IllegalDataAddress)?;
        }
        Ok(())
    }

    fn write_holding_registers(&mut self, address: u16, values: &[u16]) -> Result<(), Exception> {
        let m = &self.sim.map;
        let &[v] = values else {
            // Not served (FC 16): one register at a time.
            return Err(Exception::IllegalFunction);
        };
        if address != m.torque_ref_register {
            return Err(Exception::IllegalDataAddress);
        }
        if v > m.counts_per_100_pct {
            return Err(Exception::IllegalDataValue);
        }
        self.sim.reference_counts = v;
        self.sim.writes = self.sim.writes.wrapping_add(1);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::crc16;
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

    /// The drive's map as the engine serves it: any part of the read block, the reference
    /// read back, one register per write; FC 16 is not served (01), whatever its length is
    /// right; a frame of the wrong length for its function is silence.
    #[test]
    fn the_map_reads_any_part_of_the_block_and_the_reference() {
        let map = VfdMap::example_16384();
        let mut sim = VfdSim::new(map).unwrap();
        let v = DriveValues {
            speed_rpm: 1500.0,
            torque_pct: -25.0,
        };
        let mut out = Frame::new();
        let mut ask = |sim: &mut VfdSim, body: &[u8]| {
            let mut f = body.to_vec();
            f.extend_from_slice(&crc16(body).to_le_bytes());
            sim.handle(&f, &v, &mut out).map(|_| out.to_vec())
        };
        let with_crc = |body: &[u8]| {
            let mut f = body.to_vec();
            f.extend_from_slice(&crc16(body).to_le_bytes());
            f
        };
        assert_eq!(
            ask(&mut sim, &[1, 6, 0x20, 0, 0x20, 0]),
            Some(with_crc(&[1, 6, 0x20, 0, 0x20, 0]))
        );
        assert_eq!(sim.writes(), 1);
        assert_eq!(
            ask(&mut sim, &[1, 3, 0x21, 1, 0, 2]),
            Some(with_crc(&[1, 3, 4, 0xF0, 0, 0, 3])),
            "torque -4096 counts, status running and ready"
        );
        assert_eq!(
            ask(&mut sim, &[1, 3, 0x21, 0, 0, 1]),
            Some(with_crc(&[1, 3, 2, 0x05, 0xDC])),
            "speed 1500 rpm"
        );
        assert_eq!(
            ask(&mut sim, &[1, 3, 0x20, 0, 0, 1]),
            Some(with_crc(&[1, 3, 2, 0x20, 0])),
            "the reference read back"
        );
        for (body, code) in [
            (&[1, 3, 0x20, 0, 0, 2][..], 2),
            (&[1, 3, 0x20, 0xFF, 0, 2], 2),
            (&[1, 3, 0x21, 2, 0, 2], 2),
            (&[1, 3, 0xFF, 0xFF, 0, 2], 2),
            (&[1, 6, 0x21, 0, 0, 0], 2),
            (&[1, 16, 0x20, 0, 0, 1, 2, 0, 0], 1),
        ] {
            assert_eq!(
                ask(&mut sim, body),
                Some(with_crc(&[1, body[1] | 0x80, code])),
                "{body:02x?}"
            );
        }
        for body in [&[1, 4, 0x21, 0, 0, 1, 0][..], &[1, 16, 0x20, 0, 0, 1, 2, 0]] {
            assert_eq!(ask(&mut sim, body), None, "{body:02x?}");
        }
        assert_eq!(sim.writes(), 1);
    }
}
