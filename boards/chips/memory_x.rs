// The one way an MCU image gets its chip's memory layout: the build scripts of the crates that
// link one (`boards/*/build.rs`, `mcu-bench/build.rs`) `include!` this file and call
// `memory_x`. One layout per distinct chip lives beside it (`<chip>.x`); none is called
// `memory.x`, so no copy at the workspace root (the linker's working directory, searched
// first) can stand in for the right one.

/// Copies `<dir>/<chip>.x` (paths relative to the including crate) to `OUT_DIR/memory.x`,
/// where cortex-m-rt's `link.x` includes it, and reruns the build script when it or this
/// helper changes.
fn memory_x(dir: &str, chip: &str) {
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR"));
    let layout = format!("{dir}/{chip}.x");
    std::fs::copy(&layout, out.join("memory.x"))
        .unwrap_or_else(|e| panic!("copy {layout} to OUT_DIR/memory.x: {e}"));
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={layout}");
    println!("cargo:rerun-if-changed={dir}/memory_x.rs");
    println!("cargo:rerun-if-changed=build.rs");
}
