//! Scheduling of the calling thread: the real-time policy (`SCHED_FIFO`), CPU pinning and memory
//! locking. Every call can fail without privilege (or inside a container that drops
//! `CAP_SYS_NICE`); callers treat a failure as a warning and run on, as ros2_control does.
//!
//! Never busy-poll forever under `SCHED_FIFO`: on a 2-CPU machine the kernel's real-time
//! throttling (`/proc/sys/kernel/sched_rt_runtime_us`, 95 % by default) pauses such a thread for
//! about 50 ms per second.

/// Why the OS refused a scheduling request.
#[derive(Debug, thiserror::Error)]
pub enum SchedError {
    /// A `SCHED_FIFO` priority outside 1–99.
    #[error("SCHED_FIFO priority {0}: use 1 to 99")]
    Priority(i32),
    /// A CPU number beyond what a CPU set holds.
    #[error("CPU {0} is out of range")]
    CpuOutOfRange(usize),
    /// The kernel refused to change the policy (`EPERM` without `CAP_SYS_NICE` or with a zero
    /// real-time budget).
    #[error("{0}")]
    Policy(std::io::Error),
    /// The kernel refused to pin the thread to the CPU.
    #[error("CPU {cpu}: {source}")]
    Affinity { cpu: usize, source: std::io::Error },
}

/// The scheduling policy of a thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SchedPolicy {
    /// The default time-sharing scheduler (`SCHED_OTHER`).
    Other,
    /// Fixed-priority real-time, first in first out, priority 1–99.
    Fifo(i32),
}

/// Puts the calling thread under `policy`.
pub fn set_policy(policy: SchedPolicy) -> Result<(), SchedError> {
    let (p, prio) = match policy {
        SchedPolicy::Other => (libc::SCHED_OTHER, 0),
        SchedPolicy::Fifo(prio) => {
            if !(1..=99).contains(&prio) {
                return Err(SchedError::Priority(prio));
            }
            (libc::SCHED_FIFO, prio)
        }
    };
    let param = libc::sched_param {
        sched_priority: prio,
    };
    // SAFETY: pid 0 is the calling thread; `param` is a valid sched_param.
    let r = unsafe { libc::sched_setscheduler(0, p, &param) };
    if r == 0 {
        Ok(())
    } else {
        Err(SchedError::Policy(std::io::Error::last_os_error()))
    }
}

/// The calling thread's policy.
pub fn policy() -> SchedPolicy {
    // SAFETY: pid 0 is the calling thread.
    let p = unsafe { libc::sched_getscheduler(0) };
    if p == libc::SCHED_FIFO {
        let mut param = libc::sched_param { sched_priority: 0 };
        // SAFETY: `param` is a valid, writable sched_param.
        unsafe { libc::sched_getparam(0, &mut param) };
        SchedPolicy::Fifo(param.sched_priority)
    } else {
        SchedPolicy::Other
    }
}

/// Whether this process may use `SCHED_FIFO`: tries it on a short-lived thread, which leaves the
/// caller's own policy untouched.
pub fn fifo_permitted() -> bool {
    std::thread::spawn(|| set_policy(SchedPolicy::Fifo(1)).is_ok())
        .join()
        .unwrap_or(false)
}

/// Number of CPUs this process may run on.
pub fn cpu_count() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Pins the calling thread to CPU `cpu`.
pub fn pin_to_cpu(cpu: usize) -> Result<(), SchedError> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes inside it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    if cpu >= 8 * std::mem::size_of::<libc::cpu_set_t>() {
        return Err(SchedError::CpuOutOfRange(cpu));
    }
    unsafe { libc::CPU_SET(cpu, &mut set) };
    // SAFETY: pid 0 is the calling thread; `set` is a valid cpu_set_t of the size given.
    let r = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
    if r == 0 {
        Ok(())
    } else {
        Err(SchedError::Affinity {
            cpu,
            source: std::io::Error::last_os_error(),
        })
    }
}

/// Releases the memory locked by [`crate::rt::realtime::lock_memory`].
pub fn unlock_memory() -> bool {
    // SAFETY: munlockall takes no argument.
    unsafe { libc::munlockall() == 0 }
}

/// CPU time the calling thread has used [ns] (`CLOCK_THREAD_CPUTIME_ID`).
pub fn thread_cpu_ns() -> u64 {
    crate::rt::transport::clock::clock_ns(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// CPU time (user + system) used by the reaped children of this process [ns].
pub fn children_cpu_ns() -> u64 {
    // SAFETY: a zeroed rusage is valid; getrusage fills it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) };
    let t = |tv: libc::timeval| tv.tv_sec as u64 * 1_000_000_000 + tv.tv_usec as u64 * 1000;
    t(ru.ru_utime) + t(ru.ru_stime)
}

/// The kernel's real-time budget: `sched_rt_runtime_us` out of `sched_rt_period_us`, if readable.
pub fn rt_budget() -> Option<(i64, i64)> {
    let read = |f: &str| {
        std::fs::read_to_string(format!("/proc/sys/kernel/{f}"))
            .ok()?
            .trim()
            .parse::<i64>()
            .ok()
    };
    Some((read("sched_rt_runtime_us")?, read("sched_rt_period_us")?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policy_round_trips_on_a_scratch_thread() {
        std::thread::spawn(|| {
            assert_eq!(policy(), SchedPolicy::Other);
            if set_policy(SchedPolicy::Fifo(10)).is_ok() {
                assert_eq!(policy(), SchedPolicy::Fifo(10));
                set_policy(SchedPolicy::Other).unwrap();
            }
            assert_eq!(policy(), SchedPolicy::Other);
            assert!(set_policy(SchedPolicy::Fifo(0)).is_err());
        })
        .join()
        .unwrap();
    }

    #[test]
    fn pinning_to_cpu_zero_works_and_absurd_cpus_fail() {
        std::thread::spawn(|| {
            assert!(pin_to_cpu(0).is_ok());
            assert!(pin_to_cpu(1 << 20).is_err());
        })
        .join()
        .unwrap();
    }
}
