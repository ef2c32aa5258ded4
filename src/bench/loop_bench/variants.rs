//! The ways `vic bench loop` runs the board's loop: from a plain sleep to spin + `SCHED_FIFO` +
//! locked memory + a pinned CPU.

use super::{FIFO_PRIORITY, SPIN_US};
use serde::Serialize;

/// One way to run the loop.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Variant {
    pub(crate) name: &'static str,
    pub(crate) description: &'static str,
    /// `prctl(PR_SET_TIMERSLACK, 1)` (else the default 50 µs).
    pub(crate) timer_slack_1ns: bool,
    /// Spin this long before each deadline [µs] (0: sleep only).
    pub(crate) spin_us: u64,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
    pub(crate) mlock: bool,
    /// Pin the loop thread to the machine's last CPU.
    pub(crate) pin: bool,
    /// `SCHED_FIFO` priority.
    pub(crate) fifo: Option<i32>,
}

/// Every variant, from the plainest loop to everything at once.
pub(crate) fn variants() -> Vec<Variant> {
    let v = |name, description, slack, spin_us, mlock, pin, fifo| Variant {
        name,
        description,
        timer_slack_1ns: slack,
        spin_us,
        mlock,
        pin,
        fifo,
    };
    let rt = Some(FIFO_PRIORITY);
    vec![
        v(
            "sleep-slack50",
            "absolute clock_nanosleep, default 50 µs timer slack",
            false,
            0,
            false,
            false,
            None,
        ),
        v(
            "sleep",
            "absolute clock_nanosleep, timer slack 1 ns",
            true,
            0,
            false,
            false,
            None,
        ),
        v(
            "spin",
            "sleep, then spin the last 100 µs",
            true,
            SPIN_US,
            false,
            false,
            None,
        ),
        v(
            "spin-mlock",
            "spin + mlockall (vic-board where SCHED_FIFO is refused and there is one CPU)",
            true,
            SPIN_US,
            true,
            false,
            None,
        ),
        v(
            "spin-mlock-pin",
            "spin + mlockall + pinned to the last CPU",
            true,
            SPIN_US,
            true,
            true,
            None,
        ),
        v(
            "fifo",
            "sleep + SCHED_FIFO 80 + mlockall + pinned",
            true,
            0,
            true,
            true,
            rt,
        ),
        v(
            "fifo-spin",
            "spin + SCHED_FIFO 80 + mlockall + pinned (vic-board's default)",
            true,
            SPIN_US,
            true,
            true,
            rt,
        ),
    ]
}

/// The variant compared with cyclictest in the headline (the target names "the spin option").
pub(crate) const HEADLINE: &str = "spin-mlock";
