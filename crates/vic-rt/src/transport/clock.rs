//! The time base of every message: `CLOCK_MONOTONIC`, which all processes of the machine share,
//! the sequence numbers derived from it and the sender session of a process.

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

/// This process's sender session ([`super::Header::session`]): drawn once, at random, when the
/// process first sends. A restarted sender therefore has another session, and receivers restart
/// its sequence order instead of refusing its numbers (or obeying a poisoned `u64::MAX`). Never 0,
/// so that a zeroed header is never mistaken for a live sender.
pub fn process_session() -> u32 {
    static SESSION: std::sync::OnceLock<u32> = std::sync::OnceLock::new();
    *SESSION.get_or_init(|| {
        // The kernel's randomness (no allocation: a board may draw its session from its loop);
        // the pid and the clock should it be unavailable (two processes cannot share a pid at
        // the same nanosecond).
        let mut r = 0u64;
        // SAFETY: getrandom(2) writes at most 8 bytes into `r`, which is 8 bytes long.
        unsafe { libc::getrandom((&mut r as *mut u64).cast(), 8, 0) };
        let mixed = splitmix(r ^ (std::process::id() as u64) << 32 ^ monotonic_ns());
        (mixed as u32 ^ (mixed >> 32) as u32).max(1)
    })
}

/// SplitMix64's finaliser: spreads every bit of `x` over the result.
fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}
