//! Periodic real-time loops: absolute deadlines on `CLOCK_MONOTONIC` (no drift), 1 ns timer
//! slack, an optional spin before each deadline, missed periods skipped and counted (never caught
//! up in a burst), and fixed-size latency histograms that never allocate while recording.

use crate::transport::{Percentiles, monotonic_ns};
use hdrhistogram::Histogram;

/// Sets this thread's timer slack to 1 ns (`prctl(PR_SET_TIMERSLACK, 1)`; no privilege needed).
/// The default 50 µs slack is otherwise the median lateness of every wake-up.
pub fn set_timer_slack_1ns() -> bool {
    // SAFETY: prctl with PR_SET_TIMERSLACK takes one integer argument and touches no memory.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) == 0 }
}

/// Sleeps until the monotonic time `deadline_ns` (absolute, so no drift accumulates), then spins
/// the last `spin_ns` if asked.
pub fn sleep_until(deadline_ns: u64, spin_ns: u64) {
    sleep_until_preparing(deadline_ns, spin_ns, || {});
}

/// [`sleep_until`], running `prepare` once at the start of the spin when there is one and the
/// deadline has not passed: work that may be done before the deadline, done in time the thread
/// would otherwise spend polling the clock. Without a spin `prepare` does not run.
pub(crate) fn sleep_until_preparing(deadline_ns: u64, spin_ns: u64, prepare: impl FnOnce()) {
    let wake = deadline_ns.saturating_sub(spin_ns);
    let ts = libc::timespec {
        tv_sec: (wake / 1_000_000_000) as libc::time_t,
        tv_nsec: (wake % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            break;
        }
    }
    if spin_ns > 0 {
        if monotonic_ns() < deadline_ns {
            prepare();
        }
        while monotonic_ns() < deadline_ns {
            std::hint::spin_loop();
        }
    }
}

/// What one wake-up of a [`Periodic`] loop looked like.
#[derive(Debug, Clone, Copy, Default)]
pub struct Wake {
    /// The deadline this tick was for [ns, monotonic].
    pub deadline_ns: u64,
    /// When the thread actually ran [ns, monotonic].
    pub woke_ns: u64,
    /// `woke − deadline` [ns].
    pub lateness_ns: u64,
    /// Whole periods skipped because the wake-up came after the next deadline.
    pub skipped: u64,
}

/// An absolute-deadline periodic schedule.
#[derive(Debug, Clone)]
pub struct Periodic {
    pub period_ns: u64,
    pub spin_ns: u64,
    next_ns: u64,
    /// Ticks that woke more than one period late, and the periods they skipped.
    pub late_ticks: u64,
    pub skipped_periods: u64,
}

impl Periodic {
    /// A schedule with deadlines at whole multiples of `period_ns`, starting at the next one.
    pub fn new(period_ns: u64, spin_ns: u64) -> Self {
        let now = monotonic_ns();
        Periodic {
            period_ns,
            spin_ns: spin_ns.min(period_ns / 2),
            next_ns: (now / period_ns + 1) * period_ns,
            late_ticks: 0,
            skipped_periods: 0,
        }
    }

    /// The deadline the next [`Periodic::wait`] waits for [ns, monotonic].
    pub fn next_deadline(&self) -> u64 {
        self.next_ns
    }

    /// Waits for the next deadline. A wake-up later than a whole period skips the missed
    /// deadlines: the next one is the first still in the future.
    pub fn wait(&mut self) -> Wake {
        self.wait_preparing(|| {})
    }

    /// [`Periodic::wait`], running `prepare` in the spin before the deadline
    /// ([`sleep_until_preparing`]). The wake-up is taken after it, so a `prepare` that ran past
    /// the deadline shows as lateness.
    pub(crate) fn wait_preparing(&mut self, prepare: impl FnOnce()) -> Wake {
        let deadline = self.next_ns;
        sleep_until_preparing(deadline, self.spin_ns, prepare);
        let woke = monotonic_ns();
        let lateness = woke.saturating_sub(deadline);
        let skipped = lateness / self.period_ns;
        if skipped > 0 {
            self.late_ticks += 1;
            self.skipped_periods += skipped;
        }
        self.next_ns = deadline + (skipped + 1) * self.period_ns;
        Wake {
            deadline_ns: deadline + skipped * self.period_ns,
            woke_ns: woke,
            lateness_ns: lateness,
            skipped,
        }
    }
}

/// A latency histogram in ns with fixed bounds (1 ns to 60 s, 3 significant digits), allocated
/// once: recording saturates instead of resizing, so it never allocates.
pub struct LatencyHistogram {
    h: Histogram<u64>,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    pub fn new() -> Self {
        let mut h = Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("valid bounds");
        h.auto(false);
        LatencyHistogram { h }
    }
    /// Records a value in ns (allocation-free).
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.h.saturating_record(ns.max(1));
    }
    pub fn count(&self) -> u64 {
        self.h.len()
    }
    /// p50, p99, p99.9 and max in µs.
    pub fn percentiles(&self) -> Percentiles {
        if self.h.is_empty() {
            return Percentiles::default();
        }
        let us = |v: u64| v as f64 / 1000.0;
        Percentiles {
            p50: us(self.h.value_at_quantile(0.5)),
            p99: us(self.h.value_at_quantile(0.99)),
            p999: us(self.h.value_at_quantile(0.999)),
            max: us(self.h.max()),
            count: self.h.len(),
        }
    }
    pub fn reset(&mut self) {
        self.h.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_loop_keeps_its_deadlines() {
        set_timer_slack_1ns();
        let mut p = Periodic::new(1_000_000, 0);
        let mut h = LatencyHistogram::new();
        let first = p.wait();
        // The first wake-up may itself have skipped periods (a loaded machine): they lie before
        // `first.deadline_ns`.
        let skipped_before = p.skipped_periods;
        let mut last = first.deadline_ns;
        for _ in 0..50 {
            let w = p.wait();
            assert_eq!((w.deadline_ns - last) % 1_000_000, 0);
            assert!(w.deadline_ns > last);
            last = w.deadline_ns;
            h.record(w.lateness_ns);
        }
        // No drift: 50 ticks later the deadline is 50 periods on, plus any skipped.
        assert_eq!(
            last - first.deadline_ns,
            (50 + p.skipped_periods - skipped_before) * 1_000_000
        );
        assert_eq!(h.count(), 50);
        assert!(h.percentiles().p50 >= 0.0);
    }

    #[test]
    fn the_spin_runs_its_preparation_once_before_the_deadline() {
        set_timer_slack_1ns();
        // With a spin: at most once, before the deadline, and the wake-up comes after both. A
        // sleep that returned past the deadline (a loaded machine) leaves no time for it.
        let mut p = Periodic::new(1_000_000, 200_000);
        let mut prepared = 0;
        for _ in 0..20 {
            let (deadline, mut ran) = (p.next_deadline(), Vec::new());
            let w = p.wait_preparing(|| ran.push(monotonic_ns()));
            assert!(ran.len() <= 1);
            if let Some(&at) = ran.first() {
                assert!(at < deadline, "prepared at {at} for {deadline}");
                assert!(w.woke_ns >= deadline);
                prepared += 1;
            }
        }
        assert!(prepared > 0, "no wake-up of 20 came before its deadline");
        // Without a spin the preparation never runs: there is no time before the deadline.
        let mut p = Periodic::new(1_000_000, 0);
        let mut ran = 0;
        for _ in 0..5 {
            p.wait_preparing(|| ran += 1);
        }
        assert_eq!(ran, 0);
        // A deadline already past: no time left, no preparation.
        let mut ran = false;
        sleep_until_preparing(monotonic_ns().saturating_sub(1_000_000), 100_000, || {
            ran = true
        });
        assert!(!ran);
    }

    #[test]
    fn histogram_saturates_instead_of_growing() {
        let mut h = LatencyHistogram::new();
        h.record(u64::MAX);
        h.record(0);
        assert_eq!(h.count(), 2);
    }
}
