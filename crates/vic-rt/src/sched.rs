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

/// Tries to lock the process's memory (`mlockall`); a failure is only a warning for callers.
pub fn lock_memory() -> bool {
    // SAFETY: mlockall takes flags only.
    unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0 }
}

/// Releases the memory locked by [`lock_memory`].
pub fn unlock_memory() -> bool {
    // SAFETY: munlockall takes no argument.
    unsafe { libc::munlockall() == 0 }
}

/// CPU time the calling thread has used [ns] (`CLOCK_THREAD_CPUTIME_ID`).
pub fn thread_cpu_ns() -> u64 {
    crate::transport::clock::clock_ns(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// CPU time (user + system) used by the reaped children of this process [ns].
pub fn children_cpu_ns() -> u64 {
    // SAFETY: a zeroed rusage is valid; getrusage fills it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) };
    let t = |tv: libc::timeval| tv.tv_sec as u64 * 1_000_000_000 + tv.tv_usec as u64 * 1000;
    t(ru.ru_utime) + t(ru.ru_stime)
}

/// The real-time settings a board asks for by default (`vic-board` without `--no-rt`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtRequest {
    /// `SCHED_FIFO` priority of the loop (None: the normal scheduler).
    pub fifo: Option<i32>,
    /// The CPU to pin the loop to; with `auto_cpu`, None picks the last CPU of the process's
    /// set when it has more than one.
    pub cpu: Option<usize>,
    pub(crate) auto_cpu: bool,
    /// Spin before each deadline [µs].
    pub spin_us: u64,
}

/// Priority asked for by default: cyclictest's customary `-p80`, the figure the loop is compared
/// with (above the kernel's threaded interrupt handlers, at 50).
pub const DEFAULT_FIFO_PRIORITY: i32 = 80;
/// Spin before each deadline by default [µs]: with `SCHED_FIFO` what brings the wake-up p99
/// under cyclictest's on these machines (docs/BENCHMARKS.md, "Wake-up jitter"), 10 % of one CPU
/// at 1 kHz, far below the real-time throttling budget (95 %), so it can never trip it.
pub(crate) const DEFAULT_SPIN_US: u64 = 100;

impl RtRequest {
    /// The defaults: `SCHED_FIFO` 80, a CPU of its own where there is more than one, 100 µs spin.
    pub fn default_rt() -> RtRequest {
        RtRequest {
            fifo: Some(DEFAULT_FIFO_PRIORITY),
            cpu: None,
            auto_cpu: true,
            spin_us: DEFAULT_SPIN_US,
        }
    }
    /// `--no-rt`: the normal scheduler, no pinning, no spin.
    pub fn none() -> RtRequest {
        RtRequest {
            fifo: None,
            cpu: None,
            auto_cpu: false,
            spin_us: 0,
        }
    }
}

/// The settings in force for a loop, and what the OS refused.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct RtSettings {
    /// Whether real-time settings were asked for (false with `--no-rt`).
    pub requested: bool,
    /// `SCHED_FIFO` priority in force (None: the normal scheduler).
    pub fifo: Option<i32>,
    /// `mlockall` in force.
    pub memory_locked: bool,
    /// The CPU the loop is pinned to.
    pub cpu: Option<usize>,
    /// Spin before each deadline [µs].
    pub spin_us: u64,
    /// Timer slack set to 1 ns.
    pub timer_slack_1ns: bool,
    /// What was asked for and refused, with the reason.
    pub refused: Vec<String>,
}

impl RtSettings {
    /// One line: what is in force, then what was refused.
    pub fn describe(&self) -> String {
        let mut parts = vec![match self.fifo {
            Some(p) => format!("SCHED_FIFO {p}"),
            None => "normal scheduler".to_string(),
        }];
        parts.push(
            if self.memory_locked {
                "memory locked"
            } else {
                "memory not locked"
            }
            .into(),
        );
        parts.push(match self.cpu {
            Some(c) => format!("CPU {c}"),
            None => "any CPU".to_string(),
        });
        parts.push(format!("spin {} µs", self.spin_us));
        if self.timer_slack_1ns {
            parts.push("timer slack 1 ns".into());
        }
        let mut line = parts.join(", ");
        if !self.refused.is_empty() {
            line.push_str("; refused: ");
            line.push_str(&self.refused.join("; "));
        }
        line
    }
}

/// The CPUs the calling thread may run on.
pub(crate) fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity writes into it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    let size = std::mem::size_of::<libc::cpu_set_t>();
    // SAFETY: `set` is a valid cpu_set_t of `size` bytes.
    if unsafe { libc::sched_getaffinity(0, size, &mut set) } != 0 {
        return Vec::new();
    }
    // SAFETY: CPU_ISSET reads the set within its size.
    (0..8 * size)
        .filter(|&c| unsafe { libc::CPU_ISSET(c, &set) })
        .collect()
}

/// Applies `req` to the calling thread (the loop's): pins it, raises it to `SCHED_FIFO`. A
/// refusal is recorded, not an error: the loop runs on with what it got. `memory_locked` and
/// `timer_slack_1ns` say what the caller obtained before (process-wide).
pub fn apply_realtime(req: &RtRequest, memory_locked: bool, timer_slack_1ns: bool) -> RtSettings {
    let mut got = RtSettings {
        requested: req.fifo.is_some() || req.auto_cpu || req.cpu.is_some(),
        memory_locked,
        spin_us: req.spin_us,
        timer_slack_1ns,
        ..RtSettings::default()
    };
    if got.requested && !memory_locked {
        got.refused
            .push("mlockall (page faults may add jitter)".into());
    }
    let cpu = req.cpu.or_else(|| {
        let cpus = allowed_cpus();
        (req.auto_cpu && cpus.len() > 1).then(|| cpus[cpus.len() - 1])
    });
    if let Some(c) = cpu {
        match pin_to_cpu(c) {
            Ok(()) => got.cpu = Some(c),
            Err(e) => got.refused.push(format!("pinning: {e}")),
        }
    }
    if let Some(p) = req.fifo {
        match set_policy(SchedPolicy::Fifo(p)) {
            Ok(()) => got.fifo = Some(p),
            Err(e) => got.refused.push(format!("SCHED_FIFO {p}: {e}")),
        }
    }
    got
}

/// A thread of another process under `SCHED_FIFO` and pinned to one CPU: another real-time loop
/// the calling one would share its CPU with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RivalLoop {
    pub pid: u32,
    pub tid: u32,
    /// The thread's name (`/proc/PID/task/TID/comm`).
    pub name: String,
    pub priority: i32,
}

/// The `SCHED_FIFO` threads pinned to `cpu` alone, of every user process but `own_pid` (read from
/// `/proc`; threads that vanish or cannot be read are skipped). Two loops at the same priority on
/// one CPU preempt each other and miss their deadlines, without any error.
pub fn fifo_threads_pinned_to(cpu: usize, own_pid: u32) -> Vec<RivalLoop> {
    let mut found = Vec::new();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return found;
    };
    for p in procs.flatten() {
        let Some(pid) = p.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
            continue;
        };
        // Kernel threads (the CPU's migration thread, threaded interrupts) have an empty
        // command line; they are the kernel's, not another loop.
        let user = std::fs::read(p.path().join("cmdline")).is_ok_and(|c| !c.is_empty());
        if pid == own_pid || !user {
            continue;
        }
        let Ok(tasks) = std::fs::read_dir(p.path().join("task")) else {
            continue;
        };
        for t in tasks.flatten() {
            let Some(tid) = t.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
                continue;
            };
            if let Some(priority) = fifo_pinned(&t.path(), cpu) {
                let name = std::fs::read_to_string(t.path().join("comm"))
                    .map(|n| n.trim().to_string())
                    .unwrap_or_default();
                found.push(RivalLoop {
                    pid,
                    tid,
                    name,
                    priority,
                });
            }
        }
    }
    found
}

/// The `SCHED_FIFO` priority of the thread at `/proc/PID/task/TID` when it is pinned to `cpu`
/// alone.
fn fifo_pinned(task: &std::path::Path, cpu: usize) -> Option<i32> {
    let stat = std::fs::read_to_string(task.join("stat")).ok()?;
    // Fields after the parenthesised name (which may hold spaces) start at field 3, `state`;
    // field 40 is rt_priority, 41 the policy (1: SCHED_FIFO).
    let rest: Vec<&str> = stat
        .get(stat.rfind(')')? + 1..)?
        .split_whitespace()
        .collect();
    let field = |n: usize| rest.get(n - 3).and_then(|v| v.parse::<i64>().ok());
    if field(41)? != i64::from(libc::SCHED_FIFO) {
        return None;
    }
    let status = std::fs::read_to_string(task.join("status")).ok()?;
    let allowed = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))?
        .trim();
    (allowed == cpu.to_string()).then(|| field(40).map(|p| p as i32))?
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

    #[test]
    fn realtime_settings_report_what_the_os_granted() {
        std::thread::spawn(|| {
            let cpus_before = allowed_cpus().len();
            let got = apply_realtime(&RtRequest::default_rt(), true, true);
            assert!(got.requested);
            // What is reported in force is what the thread has, and each refusal is listed.
            assert_eq!(
                got.fifo.is_some(),
                policy() == SchedPolicy::Fifo(DEFAULT_FIFO_PRIORITY)
            );
            assert_eq!(
                got.fifo.is_none(),
                got.refused.iter().any(|r| r.contains("SCHED_FIFO"))
            );
            // Pinning to a CPU of the thread's own set is always permitted.
            assert_eq!(got.cpu.is_some(), cpus_before > 1);
            if let Some(c) = got.cpu {
                assert_eq!(allowed_cpus(), vec![c]);
            }
            assert!(got.describe().contains("spin 100 µs"));
            let none = apply_realtime(&RtRequest::none(), false, false);
            assert!(!none.requested && none.refused.is_empty() && none.cpu.is_none());
        })
        .join()
        .unwrap();
    }

    /// A thread of this process pinned to CPU 0 under `SCHED_FIFO` is found by its tid (as
    /// another process's loop would be), not once it is back under the normal scheduler, and not
    /// when the caller excludes its own process.
    #[test]
    fn a_pinned_fifo_thread_is_found_in_proc() {
        let pid = std::process::id();
        std::thread::spawn(move || {
            // SAFETY: gettid has no preconditions.
            let tid = unsafe { libc::gettid() } as u32;
            pin_to_cpu(0).unwrap();
            if set_policy(SchedPolicy::Fifo(7)).is_err() {
                return; // not permitted here: nothing to find
            }
            let found = fifo_threads_pinned_to(0, 0);
            let me = found.iter().find(|r| r.tid == tid);
            assert_eq!(me.map(|r| (r.pid, r.priority)), Some((pid, 7)), "{found:?}");
            assert!(fifo_threads_pinned_to(1, 0).iter().all(|r| r.tid != tid));
            assert!(fifo_threads_pinned_to(0, pid).iter().all(|r| r.tid != tid));
            set_policy(SchedPolicy::Other).unwrap();
            assert!(fifo_threads_pinned_to(0, 0).iter().all(|r| r.tid != tid));
        })
        .join()
        .unwrap();
    }
}
