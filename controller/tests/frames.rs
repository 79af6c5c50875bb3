//! Any bytes from the wire: the SCADA slave, the simulated drive and the VFD master never
//! panic, the slaves' answers are always well-formed RTU frames (right unit, CRC, length), and
//! silence or an answer leaves the slave in a state a valid request can still use. Both
//! slaves are served by one engine: the same frames get the same silences and the same
//! answers wherever their maps do not differ.

use controller::modbus::{crc16, Frame};
use controller::scada::{ScadaSlave, INPUT_REGISTERS};
use controller::vfd::{VfdMap, VfdMaster};
use controller::vfdsim::{DriveValues, VfdSim};
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
        let mut r = Frame::new();
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

    /// The SCADA map and the drive's map, both at unit 1, served by the one engine: a frame
    /// one of them does not answer, the other does not answer either (silence is the engine's
    /// alone), and a function neither serves, or a read quantity outside 1..=125, gets the
    /// same exception from both.
    #[test]
    fn both_slaves_are_served_by_one_engine(frame in frames()) {
        let mut scada = ScadaSlave::new(1).unwrap().with_virtual_bench();
        let mut drive = VfdSim::new(VfdMap::example_16384()).unwrap();
        let (mut a, mut b) = (Frame::new(), Frame::new());
        let from_scada = scada
            .handle(&frame, &[7u16; INPUT_REGISTERS], &mut a)
            .map(|n| a[..n].to_vec());
        let from_drive = drive
            .handle(&frame, &DriveValues::default(), &mut b)
            .map(|n| b[..n].to_vec());
        prop_assert_eq!(from_scada.is_none(), from_drive.is_none(), "{:02x?}", frame);
        let func = frame.get(1).copied().unwrap_or(0);
        let quantity = frame.get(4..6).map_or(0, |q| u16::from_be_bytes([q[0], q[1]]));
        if from_scada.is_some() && (!matches!(func, 3 | 4 | 6 | 16) || (func == 3 && !(1..=125).contains(&quantity))) {
            prop_assert_eq!(&from_scada, &from_drive, "{:02x?}", frame);
            prop_assert_eq!(from_scada.map(|a| a.len()), Some(5));
        }
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

/// The same malformed frames get the same silence from both slaves, and the same requests
/// outside both maps' functions or quantities the same exception.
#[test]
fn the_same_malformed_frames_get_the_same_answer_from_both_slaves() {
    let mut scada = ScadaSlave::new(1).unwrap();
    let mut drive = VfdSim::new(VfdMap::example_16384()).unwrap();
    let good = with_crc(&[1, 6, 0x20, 0, 0, 7]);
    let mut bad_crc = good.clone();
    bad_crc[7] ^= 0xFF;
    let mut long = good.clone();
    long.push(0);
    let mut unknown_bad_crc = with_crc(&[1, 0x2B, 0x0E, 1, 0]);
    unknown_bad_crc[5] ^= 1;
    let silent: Vec<Vec<u8>> = vec![
        vec![],
        vec![1],
        vec![1, 6, 0],
        good[..7].to_vec(),
        bad_crc,
        long,
        unknown_bad_crc,
        with_crc(&[1, 0x85, 0, 0, 0, 1]),
        vec![1, 0x85, 0, 0],
        with_crc(&[2, 6, 0x20, 0, 0, 7]),
        with_crc(&[0, 6, 0x20, 0, 0, 7]),
        with_crc(&[1, 3, 0x21, 0, 0, 3, 0]),
        with_crc(&[1, 16, 0, 0, 0, 1, 2, 0]),
        vec![1, 0x10, 0x30, 0x13, 0, 1, 0xFF, 0x0C],
        vec![0xFF; 300],
    ];
    let inputs = [7u16; INPUT_REGISTERS];
    let mut r = Frame::new();
    for f in &silent {
        assert_eq!(scada.handle(f, &inputs, &mut r), None, "SCADA {f:02x?}");
        assert_eq!(
            drive.handle(f, &DriveValues::default(), &mut r),
            None,
            "drive {f:02x?}"
        );
    }
    for (body, code) in [
        (&[1, 0x2B, 0x0E, 1, 0][..], 1),
        (&[1, 1, 0, 0, 0x07, 0xD1], 1),
        (&[1, 5, 0, 0, 0x12, 0x34], 1),
        (&[1, 0x0F, 0, 0, 0, 0, 0], 1),
        (&[1, 0x11], 1),
        (&[1, 3, 0, 0, 0, 0], 3),
        (&[1, 3, 0x21, 0, 0, 126], 3),
    ] {
        let f = with_crc(body);
        let want = with_crc(&[1, body[1] | 0x80, code]);
        let n = scada.handle(&f, &inputs, &mut r).expect("SCADA answers");
        assert_eq!(&r[..n], &want[..], "SCADA {body:02x?}");
        let n = drive
            .handle(&f, &DriveValues::default(), &mut r)
            .expect("drive answers");
        assert_eq!(&r[..n], &want[..], "drive {body:02x?}");
    }
    assert_eq!((scada.setpoint, drive.writes()), (0, 0));
}
