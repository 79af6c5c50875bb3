//! What the virtual-board tests share: the board with the compiled-in models, running it, and
//! SCADA reads and writes through the slave's own frames.
#![allow(dead_code)] // each test file uses its part

use controller::control::{Config, LogLine, NarmaxModel};
use controller::modbus::{crc16, Frame};
use controller::types::Mode;
use controller::virtual_bench::{VirtualBenchConfig, VirtualBoard};

use pump_models::{flow as flow_model, pressure as pressure_model};

/// The virtual board with the compiled-in models.
pub type Board = VirtualBoard<
    { pressure_model::FRAMES },
    { pressure_model::HIDDEN },
    { flow_model::FRAMES },
    { flow_model::HIDDEN },
>;

/// The board with a virtual bench (default offsets, noise seed 7), started in `mode` at a
/// torque setpoint of `setpoint_pct`.
pub fn setup(mode: Mode, setpoint_pct: f32) -> Board {
    setup_with(mode, setpoint_pct, VirtualBenchConfig::default_offsets(7))
}

/// [`setup`] with the virtual bench `bench`.
pub fn setup_with(mode: Mode, setpoint_pct: f32, bench: VirtualBenchConfig) -> Board {
    let cfg = Config {
        initial_mode: mode,
        initial_setpoint_pct: setpoint_pct,
        virtual_bench: true,
        ..Config::bench()
    };
    let p = NarmaxModel::new(&pressure_model::F32, &pressure_model::Q15, 50).unwrap();
    let q = NarmaxModel::new(&flow_model::F32, &flow_model::Q15, 100).unwrap();
    Board::new(&cfg, p, q, bench).unwrap()
}

/// `ms` milliseconds; the log lines.
pub fn run(b: &mut Board, ms: u32) -> Vec<LogLine> {
    let mut logs = vec![];
    for _ in 0..ms {
        logs.extend(b.tick().unwrap().log);
    }
    logs
}

/// `body` with its CRC.
pub fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// Writes one holding register over SCADA (FC 06), asserting the echo.
pub fn write_holding(b: &mut Board, register: u8, value: u16) {
    let [hi, lo] = value.to_be_bytes();
    let mut r = Frame::new();
    let req = with_crc(&[1, 6, 0, register, hi, lo]);
    let n = b.scada.handle(&req, &mut r).expect("an answer");
    assert_eq!(&r[..n], &req[..], "write of holding {register} echoed");
}

/// One input register.
pub fn input(b: &mut Board, register: u8) -> u16 {
    let mut r = Frame::new();
    let n = b
        .scada
        .handle(&with_crc(&[1, 4, 0, register, 0, 1]), &mut r)
        .unwrap();
    assert_eq!(n, 7);
    u16::from_be_bytes([r[3], r[4]])
}
