//! NUCLEO-F446RE board glue (placeholder, being written).
pub fn run() -> ! {
    loop {}
}
