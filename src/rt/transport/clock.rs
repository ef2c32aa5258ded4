//! The time base of every message: `CLOCK_MONOTONIC`, which all processes of the machine share,
//! and the sequence numbers derived from it.

/// The current time on `clock` in nanoseconds (`CLOCK_MONOTONIC`, a thread's CPU time, ...).
pub(crate) fn clock_ns(clock: libc::clockid_t) -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clocks used here always exist on Linux.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// The current time on `CLOCK_MONOTONIC` in nanoseconds: the time base of every message, common
/// to all processes of the machine.
pub fn monotonic_ns() -> u64 {
    clock_ns(libc::CLOCK_MONOTONIC)
}

/// The first sequence number of a publisher that starts now: its start time on the monotonic
/// clock. Receivers refuse sequence numbers that go backwards or repeat; starting from the clock
/// lets a restarted publisher (a planner after a crash, a second `vic inject`) continue upward
/// without any state shared between processes.
pub fn session_seq() -> u64 {
    monotonic_ns()
}
