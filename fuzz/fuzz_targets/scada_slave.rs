//! Any frame: the slave never panics, answers only well-formed frames, keeps its invariants.
#![no_main]
use controller::modbus::{crc16, Frame};
use controller::scada::{ScadaSlave, INPUT_REGISTERS};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut s = ScadaSlave::new(1).unwrap();
    let mut r = Frame::new();
    if let Some(n) = s.handle(data, &[1; INPUT_REGISTERS], &mut r) {
        assert!(n >= 5 && r[0] == 1);
        assert_eq!(crc16(&r[..n - 2]).to_le_bytes(), [r[n - 2], r[n - 1]]);
    }
    assert!(s.setpoint <= 10_000);
});
