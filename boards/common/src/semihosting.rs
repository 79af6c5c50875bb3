//! Ending a run under a debugger or QEMU through semihosting (target only, feature
//! `semihosting`): the QEMU board's exit, panic and fault paths.

/// Ends the run with exit status 0 (`ok`) or 1 (QEMU's exit status; a debugger reports it).
/// The call is a `BKPT`: without a debugger or QEMU behind it, it faults.
pub fn exit(ok: bool) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}
