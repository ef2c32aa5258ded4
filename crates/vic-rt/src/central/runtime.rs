//! The runtime around the pure [`Controller`]: what a period's work takes on a clock, the
//! histograms it goes into, the overrun a period over budget turns into, and the worker thread
//! of the `replan` strategy's re-solves ([`Background`]). The live loop ([`super::run_live`])
//! and the lockstep mode ([`super::lockstep`]) both poll through it.

use super::background::Background;
use super::compute::{ComputeTiming, ReplanTiming};
use super::{Controller, Resolve, Strategy, Timing, Track};
use crate::realtime::LatencyHistogram;
use crate::transport::{CommandSlice, Control, monotonic_ns};
use vic_core::replan::{ReplanStats, Replanner};

/// The central controller with its live parts: the pure [`Controller`] (everything a trial's
/// outcome depends on), timed on a clock, with the re-solves on a worker thread when asked.
pub struct Central {
    /// The pure state machine: fed the states and the time, it says what to publish.
    pub controller: Controller,
    /// The compute time of every period (all trials), on the clock [ns].
    compute: LatencyHistogram,
    compute_budget_ns: u64,
    overruns: u64,
    /// The clock the work is measured with when injected ([`Central::set_clock`]); the real
    /// monotonic clock otherwise.
    injected_clock: Option<fn() -> u64>,
    /// Whether work measured on the *real* clock may turn a period into an overrun: true live,
    /// false in [`super::lockstep`], where the outcome must not depend on how loaded the machine
    /// that runs the simulation is (an injected clock still decides, as the overrun tests need).
    pub(super) real_clock_overruns: bool,
    /// The `replan` strategy's re-solves over all trials, and their compute time [ns] (real clock).
    replan_stats: ReplanStats,
    replan_time: LatencyHistogram,
    /// Where the re-solves run when not inline ([`Central::replan_in_background`]).
    background: Option<Background>,
}

impl Central {
    pub fn new(track: Track, strategy: Strategy, timing: Timing) -> Self {
        Central {
            controller: Controller::new(track, strategy, timing),
            compute: LatencyHistogram::new(),
            // The lookahead is two planner periods by default: the budget is one period.
            compute_budget_ns: (timing.lookahead_ns / 2).max(1),
            overruns: 0,
            injected_clock: None,
            real_clock_overruns: true,
            replan_stats: ReplanStats::default(),
            replan_time: LatencyHistogram::new(),
            background: None,
        }
    }

    /// Runs the `replan` strategy's re-solves on a worker thread, one period ahead (see
    /// [`super::background`]'s module documentation): a re-solve longer than the period then
    /// never holds the slices back. `wait` waits for each at the next period (deterministic, for
    /// lockstep and tests). Nothing for the other strategies.
    pub fn replan_in_background(&mut self, wait: bool) {
        if let Some(r) = &mut self.controller.replanner {
            r.options.lead_steps = r.options.period_steps;
            self.background = Some(Background::start(r, wait));
        }
    }

    /// Sets the compute budget of a period [ns] (default: half the lookahead, one planner period).
    pub fn set_compute_budget_ns(&mut self, ns: u64) {
        self.compute_budget_ns = ns.max(1);
    }

    /// Replaces the clock the compute time is measured with (monotonic ns); tests inject slow
    /// periods with it.
    pub fn set_clock(&mut self, clock: fn() -> u64) {
        self.injected_clock = Some(clock);
    }

    fn clock(&self) -> fn() -> u64 {
        self.injected_clock.unwrap_or(monotonic_ns)
    }

    /// The compute time per period and the overruns, over every trial so far.
    pub fn compute_timing(&self) -> ComputeTiming {
        ComputeTiming {
            compute_us: self.compute.percentiles(),
            budget_us: self.compute_budget_ns as f64 * 1e-3,
            overruns: self.overruns,
            replan: self.controller.replanner.as_ref().map(|_| ReplanTiming {
                solve_us: self.replan_time.percentiles(),
                stats: self.replan_stats,
                late: self.background.as_ref().map_or(0, |b| b.late),
                skipped: self.background.as_ref().map_or(0, |b| b.skipped),
            }),
        }
    }

    /// [`Controller::begin_trial`], and a re-solve still running on the worker is dropped.
    pub fn begin_trial(&mut self, trial: u32, seed: u64, start_ns: u64, now_ns: u64) -> Control {
        if let Some(b) = &mut self.background {
            b.begin_trial();
        }
        self.controller.begin_trial(trial, seed, start_ns, now_ns)
    }

    /// [`Controller::poll`], timed: the work of the period (adopting what the worker sent back,
    /// releasing states, computing the knots due) is measured on the clock. A period whose work
    /// took longer than the budget sends the previous slice again, never nothing.
    pub fn poll(&mut self, now_ns: u64, out: &mut Vec<CommandSlice>) {
        let clock = self.clock();
        let t0 = clock();
        let c = &mut self.controller;
        if let (Some(b), Some(r)) = (&mut self.background, &mut c.replanner) {
            b.collect(
                r,
                c.knots.len(),
                &mut self.replan_stats,
                &mut self.replan_time,
            );
        }
        let mut resolve = Timed {
            clock,
            background: self.background.as_mut(),
            stats: &mut self.replan_stats,
            time: &mut self.replan_time,
        };
        c.compute_due(now_ns, &mut resolve);
        let work = clock().saturating_sub(t0);
        self.compute.record(work);
        let overrun = work > self.compute_budget_ns
            && (self.injected_clock.is_some() || self.real_clock_overruns);
        if c.publish(now_ns, overrun, out) {
            self.overruns += 1;
        }
    }
}

/// The runtime's re-solves: handed to the worker when there is one, else inline and timed.
struct Timed<'a> {
    clock: fn() -> u64,
    background: Option<&'a mut Background>,
    stats: &'a mut ReplanStats,
    time: &'a mut LatencyHistogram,
}

impl Resolve for Timed<'_> {
    fn command_into<'a>(
        &mut self,
        r: &mut Replanner,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) {
        if let Some(b) = &mut self.background {
            return b.command_into(r, k, seen, applied, scratch, u);
        }
        let t0 = (self.clock)();
        let before = r.stats;
        r.command_into(k, seen, applied, scratch, u);
        if r.stats.solves > before.solves {
            self.time.record((self.clock)().saturating_sub(t0));
            self.stats.add(&r.stats.since(&before));
        }
    }
}
