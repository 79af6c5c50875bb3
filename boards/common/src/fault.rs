//! The HardFault entry both boards use, and its report (target only).

pub use cortex_m_rt::ExceptionFrame;

/// Logs a HardFault: the faulting `pc` and `lr` from the stacked frame `ef`, or, with `None`,
/// that the stack overflowed (the frame is lost).
#[cfg(feature = "defmt")]
pub fn report(ef: Option<&ExceptionFrame>) {
    match ef {
        Some(ef) => defmt::error!(
            "HardFault at pc={=u32:#010x} lr={=u32:#010x}",
            ef.pc(),
            ef.lr()
        ),
        None => defmt::error!("HardFault: stack overflow"),
    }
}

/// Logs a panic once, with its source file and line (a panic while logging it, or on
/// another path after it, logs nothing more), interrupts off: each board's `#[panic_handler]`
/// calls it, then ends its own way (QEMU: exit with status 1; the Nucleo: `udf`, into the
/// HardFault handler that takes the torque reference off and resets). The message is not
/// formatted: that links `core::fmt` (≈ 1.4 KB of the 64 KiB image) for a path that only a
/// bug takes, and the file and line find it.
#[cfg(feature = "defmt")]
pub fn report_panic(info: &core::panic::PanicInfo) {
    use core::sync::atomic::{AtomicBool, Ordering};
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    if !PANICKED.swap(true, Ordering::Relaxed) {
        let (file, line) = info.location().map_or(("?", 0), |l| (l.file(), l.line()));
        defmt::error!("panic at {=str}:{=u32}", file, line);
    }
}

/// Defines the `HardFault` handler: a trampoline that survives a stack overflow, then
/// `$handler`, a `fn(Option<&`[`ExceptionFrame`]`>) -> !` of the board (`None` after
/// a stack overflow, when the stacked frame is lost).
///
/// flip-link puts the stack at the bottom of RAM, below `.data`/`.bss`: an overflow leaves SP
/// below RAM, where cortex-m-rt's own trampoline (and the handler's first push) would fault
/// again and lock the core up. This one moves SP back to the top of the stack first. A
/// macro, not a function: `global_asm!` names the handler with `sym`, which must be an item
/// of the board's crate, and the handler is what differs between boards (QEMU: log and exit
/// with status 1; the Nucleo: torque reference off, log, reset).
#[macro_export]
macro_rules! hard_fault_trampoline {
    ($handler:path) => {
        ::core::arch::global_asm!(
            ".section .HardFaultTrampoline, \"ax\"",
            ".global HardFault",
            ".type HardFault,%function",
            ".thumb_func",
            "HardFault:",
            // A stack overflow leaves SP below the stack's bottom (_stack_end): move it back
            // to the top and pass no frame.
            "  mrs r0, MSP",
            "  ldr r1, =_stack_end",
            "  cmp r0, r1",
            "  bhs 1f",
            "  ldr r1, =_stack_start",
            "  msr MSP, r1",
            "  movs r0, #0",
            "1:",
            "  b {handler}",
            ".ltorg",
            handler = sym __firmware_hard_fault,
        );

        /// Called only by the `HardFault` trampoline, with the exception frame (or null
        /// after a stack overflow).
        ///
        /// # Safety
        /// `ef` is null or points at the stacked exception frame.
        unsafe extern "C" fn __firmware_hard_fault(
            ef: *const $crate::fault::ExceptionFrame,
        ) -> ! {
            // SAFETY: the trampoline passes the stacked frame, or null.
            $handler(unsafe { ef.as_ref() })
        }
    };
}
