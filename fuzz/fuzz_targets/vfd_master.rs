//! Any response bytes, cut into frames by the first byte: the master never panics and its
//! outputs stay finite and in range.
#![no_main]
use controller::modbus::Frame;
use controller::vfd::{VfdMap, VfdMaster};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut m = VfdMaster::new(VfdMap::example_16384()).unwrap();
    let mut out = Frame::new();
    let mut now = 0u32;
    let mut rest = data;
    while let Some((&len, tail)) = rest.split_first() {
        let (frame, next) = tail.split_at((len as usize).min(tail.len()));
        m.start(now, 50.0, &mut out);
        m.receive(frame);
        now = now.wrapping_add(60);
        m.poll(now, &mut out);
        if let Some(r) = m.readings() {
            assert!(r.speed_rpm.is_finite() && r.torque_pct.is_finite());
        }
        rest = next;
    }
});
