//! Any bytes from the wire: the SCADA slave and the VFD master never panic, the slave's
//! answers are always well-formed RTU frames (right unit, CRC, length), and silence or an
//! answer leaves the slave in a state a valid request can still use.

use controller::scada::{crc16, Response, ScadaSlave, INPUT_REGISTERS};
use controller::vfd::{Frame, VfdMap, VfdMaster};
use proptest::prelude::*;

fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// Frames that look like requests for unit 1 (valid CRC), plus raw noise.
fn frames() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..300),
        (any::<u8>(), proptest::collection::vec(any::<u8>(), 0..40))
            .prop_map(|(func, body)| with_crc(&[&[1, func][..], &body].concat())),
        (
            prop_oneof![Just(3u8), Just(4), Just(6), Just(16)],
            any::<u16>(),
            any::<u16>()
        )
            .prop_map(|(func, a, b)| with_crc(
                &[&[1, func][..], &a.to_be_bytes(), &b.to_be_bytes()].concat()
            )),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn slave_answers_are_well_formed(frame in frames()) {
        let mut s = ScadaSlave::new(1).unwrap();
        let inputs = [7u16; INPUT_REGISTERS];
        let mut r = Response::new();
        if let Some(n) = s.handle(&frame, &inputs, &mut r) {
            let a = &r[..n];
            prop_assert!(n >= 5 && a[0] == 1, "{a:?}");
            prop_assert_eq!(crc16(&a[..n - 2]).to_le_bytes(), [a[n - 2], a[n - 1]]);
            prop_assert!(a[1] == frame[1] || a[1] == frame[1] | 0x80);
            if a[1] & 0x80 != 0 {
                prop_assert!(n == 5 && (1..=3).contains(&a[2]), "{a:?}");
            }
        }
        prop_assert!(s.setpoint <= 10_000);
        // Still answers a valid request.
        let ok = with_crc(&[1, 4, 0, 0, 0, 1]);
        prop_assert!(s.handle(&ok, &inputs, &mut r).is_some());
    }

    #[test]
    fn master_takes_any_bytes(frames in proptest::collection::vec(frames(), 0..8)) {
        let mut m = VfdMaster::new(VfdMap::example_16384()).unwrap();
        let mut out = Frame::new();
        let mut now = 0u32;
        for f in &frames {
            m.start(now, 42.0, &mut out);
            m.receive(f);
            now = now.wrapping_add(150);
            m.poll(now, &mut out);
            if let Some(r) = m.readings() {
                prop_assert!(r.speed_rpm.is_finite() && r.torque_pct.is_finite());
            }
            prop_assert!((0.0..=100.0).contains(&m.applied_torque_pct(42.0)));
        }
    }
}
