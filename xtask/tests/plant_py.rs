//! `examples/plant.py` (the README's plant in Python) closes the loop against `cargo xtask
//! plant-stdio` (the host's plant session): it holds 3 mca within 5 % after 10 s. The same
//! script against the QEMU board is part of `cargo xtask plant-check`. Needs `python3`.

use std::path::Path;
use std::process::Command;

#[test]
fn the_python_plant_holds_3_mca_through_plant_stdio() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let out = Command::new("python3")
        .arg(root.join("examples/plant.py"))
        .args(["--", env!("CARGO_BIN_EXE_xtask"), "plant-stdio"])
        .output()
        .expect("python3 on the PATH");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}: {text}{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.starts_with("pressure ") && text.contains(" mca after 10 s"),
        "{text}"
    );
}
