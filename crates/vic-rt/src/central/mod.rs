//! The central controller: plays a plan back as command slices at 50 Hz, with the
//! strategies the paper compares, behind time-stamped delay lines on the state and command paths.
//!
//! [`Controller`] is a pure state machine like the board: it is fed the states it receives and
//! polled with the time, and says which command slices to publish now. [`Central`] is the thin
//! runtime around it ([`runtime`]): it measures each period's work on a clock into histograms,
//! turns a period over budget into an overrun, and runs the `replan` strategy's re-solves on a
//! worker thread ([`background`]). The live planner (`vic-planner`, [`run_live`]) and the
//! lockstep mode ([`lockstep`]) drive the same two.
//!
//! Latency: the feedback of knot `k` uses the state of knot `k − D` (`D` = `latency_steps`), as
//! the offline Monte Carlo does: on it directly (paper Eq. 13, [`Feedback::Delayed`]) or through
//! the prediction of the present over the commands sent since ([`Feedback::Predicted`]), one
//! code path ([`Policy::command_into`]) for both. Live, the state must also have
//! passed the sensor delay line before knot `k` is computed, and the slice must pass the command
//! delay line and reach the board before knot `k` acts; when the state of `k − D` is not there
//! yet, the freshest released state is used and the knot is counted in `stale_feedback`. A knot
//! first published after its time (a planner that woke late) is counted in `late_knots`: the
//! board acted on the knot before in its place ([`Controller::sent`]).

use vic_core::cost::TrackingCost;
use vic_core::dynamics::DiscreteDynamics;
pub use vic_core::latency::Latency;
use vic_core::model::Exogenous;
pub use vic_core::policy::Strategy;
use vic_core::policy::{Feedback, Policy};
use vic_core::replan::{Executor, ReplanOptions, Replanner};
use vic_core::scalar::{MAX_NU, MAX_NX};
mod background;
mod compute;
mod live;
mod lockstep;
mod runtime;
mod timing;
pub use compute::{ComputeTiming, ReplanTiming};
pub use live::{LiveError, run_live};
pub use lockstep::{lockstep, lockstep_polled};
pub use runtime::Central;
pub use timing::{DelayLines, PLANNER_RATES_HZ, Timing};

use crate::transport::{
    CommandSlice, Control, ControlKind, Header, Interpolation, Knot, MAX_KNOTS, Mode, StateMsg,
};
use nalgebra::DVector;
use std::collections::VecDeque;

/// Why a policy cannot be played on the board.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrackError {
    /// The policy is not for a `(q, q')` state and a `(τ, K)` control of this arm.
    #[error("the real-time board runs the impedance actuator (type 2) only")]
    NotImpedance,
    #[error("the reference has {reference} knots, the policy {steps} steps")]
    ReferenceLength { reference: usize, steps: usize },
}

/// A policy with what the board needs besides: the reference it tracks and the start state.
#[derive(Debug, Clone)]
pub struct Track {
    pub dof: usize,
    pub nx: usize,
    pub nu: usize,
    /// Plan step Δ [ns].
    pub dt_ns: u64,
    pub steps: usize,
    pub policy: Policy,
    /// The plan's discrete model: the predictor runs it over the commands in flight.
    pub dynamics: DiscreteDynamics,
    /// The plan's cost (Eq. 14): the replanner re-solves with it.
    pub cost: TrackingCost,
    pub reference: Vec<Exogenous>,
    pub x0: [f64; MAX_NX],
}

impl Track {
    /// `policy` for a `dof`-joint impedance plant (state `(q, q')`, control `(τ, K)`), planned on
    /// the grid and reference of `dynamics` with `cost`, from `x0`.
    pub fn new(
        policy: Policy,
        dynamics: DiscreteDynamics,
        cost: TrackingCost,
        x0: &[f64],
    ) -> Result<Track, TrackError> {
        let (dof, dt) = (dynamics.model.dof(), dynamics.dt);
        let reference = dynamics.exogenous.clone();
        let (nx, nu) = (x0.len(), policy.nu());
        if nx != 2 * dof || nu != 2 * dof || policy.nx() != nx || nx > MAX_NX || nu > MAX_NU {
            return Err(TrackError::NotImpedance);
        }
        if reference.len() != policy.steps() + 1 {
            return Err(TrackError::ReferenceLength {
                reference: reference.len(),
                steps: policy.steps(),
            });
        }
        let mut x = [0.0; MAX_NX];
        x[..nx].copy_from_slice(x0);
        Ok(Track {
            dof,
            nx,
            nu,
            dt_ns: (dt * 1e9).round() as u64,
            steps: policy.steps(),
            policy,
            dynamics,
            cost,
            reference,
            x0: x,
        })
    }

    /// The planned command of step `k` (no feedback).
    fn acting(&self, k: usize) -> [f64; MAX_NU] {
        let mut a = [0.0; MAX_NU];
        a[..self.nu].copy_from_slice(self.policy.acting[k].as_slice());
        a
    }
}

/// What one trial gave, as seen by the central controller.
#[derive(Debug, Clone)]
pub struct TrialRecord {
    /// States at the knots `0..=N` (missing knots repeat the previous state).
    pub x: Vec<DVector<f64>>,
    /// Commands sent per knot.
    pub u: Vec<DVector<f64>>,
    /// Knots whose feedback used a state older than the latency (at 0 ms: older than the knot
    /// before, the freshest state that can exist when a knot is computed).
    pub stale_feedback: usize,
    /// Knots with no state recorded.
    pub missing_states: usize,
    /// Knots whose state was recorded from a later tick than the knot's (the board skipped the
    /// knot's tick, or its state was lost): the truth recorded there, and what the feedback saw
    /// of that knot, is up to a few board periods off.
    pub off_knot_states: usize,
    /// Knots of the movement that no slice published before the knot's time carried (a slice
    /// sent late, e.g. by a planner that woke a period or more late, or never sent): the board
    /// may have acted on the knot before (or the reset's hold) in its place, within the watchdog
    /// time without any safe hold. Even the open-loop plan then ends elsewhere.
    pub late_knots: usize,
    /// The board went to safe hold or fault during the movement.
    pub safe_hold: bool,
    pub fault: bool,
    /// The trial ended (time limit, stop request, board silent) before its final state arrived.
    pub stalled: bool,
}

/// The central controller: a pure state machine fed with the time and the states received, which
/// says which command slices to publish. No clock, histogram or thread: [`Central`] adds those.
pub struct Controller {
    pub track: Track,
    pub strategy: Strategy,
    pub timing: Timing,
    trial: u32,
    start_ns: u64,
    /// Sequence numbers continue upward from the controller's start time, also across restarts
    /// ([`crate::transport::session_seq`]); the board refuses numbers that go backwards.
    seq: u64,
    control_seq: u64,
    /// The reset that started the present trial: states of any other (a trial of the same
    /// number before a restart of this controller) are ignored.
    reset_seq: u64,
    recorded: Vec<Option<[f64; MAX_NX]>>,
    seen: Vec<Option<[f64; MAX_NX]>>,
    latest_seen: Option<usize>,
    sensor_line: VecDeque<(u64, usize, [f64; MAX_NX])>,
    command_line: VecDeque<(u64, CommandSlice)>,
    knots: Vec<Knot>,
    sent_u: Vec<[f64; MAX_NU]>,
    /// Per knot: a slice carrying it was published ([`Controller::sent`]).
    published: Vec<bool>,
    stale_feedback: usize,
    off_knot_states: usize,
    late_knots: usize,
    safe_hold: bool,
    fault: bool,
    /// A state acknowledging this trial's reset arrived.
    acknowledged: bool,
    /// The live loop gave up on this trial before its end (see [`TrialRecord::stalled`]).
    pub stalled: bool,
    /// The last slice published in this trial: what an overrunning period sends again.
    last_slice: Option<CommandSlice>,
    /// The `replan` strategy's receding-horizon planner (reset at every trial).
    replanner: Option<Box<Replanner>>,
}

/// Where the `replan` strategy's command of a knot comes from: the replanner, re-solving inline
/// ([`Inline`], the pure controller's), or the runtime's, which times the re-solves or hands
/// them to the worker thread.
pub(crate) trait Resolve {
    /// The command of knot `k` into `u` (see [`Replanner::command_into`]).
    fn command_into<'a>(
        &mut self,
        replanner: &mut Replanner,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    );
}

/// The re-solves run inline, untimed.
pub(crate) struct Inline;

impl Resolve for Inline {
    fn command_into<'a>(
        &mut self,
        replanner: &mut Replanner,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) {
        replanner.command_into(k, seen, applied, scratch, u);
    }
}

impl Controller {
    pub fn new(track: Track, strategy: Strategy, timing: Timing) -> Self {
        let n = track.steps;
        // One re-solve per planner period (half the lookahead, the runtime's compute budget), on
        // the plan's grid.
        let replanner = (strategy == Strategy::Replan).then(|| {
            let period_ns = (timing.lookahead_ns / 2).max(1);
            let options = ReplanOptions {
                period_steps: (period_ns.div_ceil(track.dt_ns) as usize).max(1),
                ..ReplanOptions::at_50_hz(track.dynamics.dt)
            };
            Box::new(Replanner::new(
                &track.policy,
                &track.dynamics,
                &track.cost,
                options,
            ))
        });
        Controller {
            strategy,
            timing,
            trial: 0,
            start_ns: 0,
            seq: crate::transport::session_seq(),
            control_seq: crate::transport::session_seq(),
            reset_seq: 0,
            recorded: vec![None; n + 1],
            seen: vec![None; n + 1],
            latest_seen: None,
            sensor_line: VecDeque::with_capacity(4 * n),
            command_line: VecDeque::new(),
            knots: Vec::with_capacity(n),
            sent_u: Vec::with_capacity(n),
            published: vec![false; n],
            stale_feedback: 0,
            off_knot_states: 0,
            late_knots: 0,
            safe_hold: false,
            fault: false,
            acknowledged: false,
            stalled: false,
            last_slice: None,
            replanner,
            track,
        }
    }

    /// Starts trial `trial` at monotonic time `start_ns`; returns the reset request for the board.
    pub fn begin_trial(&mut self, trial: u32, seed: u64, start_ns: u64, now_ns: u64) -> Control {
        self.trial = trial;
        self.start_ns = start_ns;
        self.recorded.iter_mut().for_each(|r| *r = None);
        self.seen.iter_mut().for_each(|r| *r = None);
        self.latest_seen = None;
        self.sensor_line.clear();
        self.command_line.clear();
        self.knots.clear();
        self.sent_u.clear();
        self.published.iter_mut().for_each(|p| *p = false);
        self.stale_feedback = 0;
        self.off_knot_states = 0;
        self.late_knots = 0;
        self.safe_hold = false;
        self.fault = false;
        self.acknowledged = false;
        self.stalled = false;
        self.last_slice = None;
        if let Some(r) = &mut self.replanner {
            r.reset();
        }
        let dof = self.track.dof;
        self.control_seq += 1;
        self.reset_seq = self.control_seq;
        let mut c = Control {
            header: Header::new(self.control_seq, now_ns),
            kind: ControlKind::Reset as u32,
            trial,
            seed,
            start_ns,
            ..Default::default()
        };
        c.q0[..dof].copy_from_slice(&self.track.x0[..dof]);
        c.qd0[..dof].copy_from_slice(&self.track.x0[dof..2 * dof]);
        c
    }

    /// How long before a trial's start the controller must begin: the first slice has to cross
    /// the command delay line (two planner periods of margin).
    pub fn lead_time_ns(&self, planner_period_ns: u64) -> u64 {
        self.timing.command_latency_ns + 2 * planner_period_ns
    }

    /// The request that stops the trial.
    pub fn stop(&mut self, now_ns: u64) -> Control {
        self.control_seq += 1;
        Control {
            header: Header::new(self.control_seq, now_ns),
            kind: ControlKind::Stop as u32,
            trial: self.trial,
            ..Default::default()
        }
    }

    /// A state arrived at `recv_ns`: record it (truth, for the results) and put it in the sensor
    /// delay line (what the controller will see).
    pub fn on_state(&mut self, s: &StateMsg, recv_ns: u64) {
        if s.trial != self.trial || s.reset_seq != self.reset_seq {
            return;
        }
        self.acknowledged = true;
        let mode = Mode::from_u32(s.mode);
        if mode == Mode::Idle {
            return;
        }
        let (dof, dt) = (self.track.dof, self.track.dt_ns);
        let k = (s.trial_time_ns / dt) as usize;
        if k > self.track.steps {
            return;
        }
        // The first state at or after the knot time (exact unless the board skipped that tick).
        let mut x = [0.0; MAX_NX];
        x[..dof].copy_from_slice(&s.q[..dof]);
        x[dof..2 * dof].copy_from_slice(&s.qd[..dof]);
        if k < self.track.steps || s.trial_time_ns == k as u64 * dt {
            match mode {
                Mode::SafeHold if k < self.track.steps => self.safe_hold = true,
                Mode::Fault => self.fault = true,
                _ => {}
            }
        }
        if self.recorded[k].is_none() {
            self.off_knot_states += (s.trial_time_ns != k as u64 * dt) as usize;
            self.recorded[k] = Some(x);
            self.sensor_line
                .push_back((recv_ns + self.timing.sensor_latency_ns, k, x));
        }
    }

    /// Trial time at monotonic `now` [ns].
    fn trial_time(&self, now_ns: u64) -> u64 {
        now_ns.saturating_sub(self.start_ns)
    }

    /// The state the controller feeds back at knot `k`: that of `k − D` once it has passed the
    /// sensor line, else the freshest older one (counted in `stale_feedback`); none before `D`.
    fn seen_for(&mut self, k: usize) -> Option<(usize, [f64; MAX_NX])> {
        let j = self.feedback().seen_knot(k)?;
        // Without latency the state of knot `k` cannot exist before the knot is computed: the
        // state of `k − 1` is the freshest any controller can have, and using it is not stale.
        let possible = match self.timing.latency_steps {
            0 => j.checked_sub(1),
            _ => Some(j),
        };
        let stale = |used: Option<usize>| match (used, possible) {
            (_, None) => false,
            (None, Some(_)) => true,
            (Some(l), Some(p)) => l < p,
        };
        match (self.seen[j], self.latest_seen) {
            (Some(x), _) => Some((j, x)),
            (None, Some(l)) if l < j => {
                self.stale_feedback += usize::from(stale(Some(l)));
                self.seen[l].map(|x| (l, x))
            }
            _ => {
                self.stale_feedback += usize::from(stale(None));
                None
            }
        }
    }

    /// How the policy is executed: the strategy's feedback at the configured latency.
    pub fn feedback(&self) -> Feedback {
        self.strategy.feedback(self.timing.latency_steps)
    }

    fn compute_knot(&mut self, k: usize, resolve: &mut impl Resolve) -> Knot {
        let seen = self.seen_for(k);
        let feedback = self.feedback();
        let t = &self.track;
        let (dof, nx, nu) = (t.dof, t.nx, t.nu);
        let mut u = [0.0; MAX_NU];
        let mut predicted = [0.0; MAX_NX];
        let from = seen.map_or(k, |(l, _)| l);
        let seen = seen.as_ref().map(|(l, x)| (*l, &x[..nx]));
        // The commands in flight: the controller sent them, so it knows them exactly.
        let applied = self.sent_u[from..k].iter().map(|u| &u[..nu]);
        match &mut self.replanner {
            Some(r) => resolve.command_into(r, k, seen, applied, &mut predicted, &mut u),
            None => Executor::Plan {
                policy: &t.policy,
                feedback,
            }
            .command_into(&t.dynamics, k, seen, applied, &mut predicted, &mut u),
        }
        if !self.strategy.uses_stiffness() {
            // No stiffness: the feedback alone must hold the arm (clamped again, should the
            // bounds exclude zero stiffness).
            u[dof..2 * dof].iter_mut().for_each(|v| *v = 0.0);
            t.policy.bounds.clamp(&mut u[..nu]);
        }
        let r = &t.reference[k];
        let mut knot = Knot::default();
        knot.tau_ff[..dof].copy_from_slice(&u[..dof]);
        knot.stiffness[..dof].copy_from_slice(&u[dof..2 * dof]);
        knot.q_d = r.q_d;
        knot.qd_d = r.qd_d;
        self.sent_u.push(u);
        knot
    }

    /// Called at each planner tick: releases states from the sensor line, computes the knots due,
    /// and returns the slices that leave the command delay line now (oldest first). The pure
    /// controller never overruns: [`Central::poll`] times the work and decides.
    pub fn poll(&mut self, now_ns: u64, out: &mut Vec<CommandSlice>) {
        self.compute_due(now_ns, &mut Inline);
        self.publish(now_ns, false, out);
    }

    /// The work of a period: releases the states that have passed the sensor line by `now_ns` and
    /// computes the knots due (the `replan` strategy's commands through `resolve`).
    pub(crate) fn compute_due(&mut self, now_ns: u64, resolve: &mut impl Resolve) {
        while let Some(&(release, k, x)) = self.sensor_line.front() {
            if release > now_ns {
                break;
            }
            self.sensor_line.pop_front();
            self.seen[k] = Some(x);
            if self.latest_seen.is_none_or(|l| l < k) {
                self.latest_seen = Some(k);
            }
        }
        let (dt, steps) = (self.track.dt_ns, self.track.steps);
        let horizon = self.arrival(now_ns) + self.timing.lookahead_ns;
        while self.knots.len() < steps && (self.knots.len() as u64) * dt < horizon {
            let k = self.knots.len();
            let knot = self.compute_knot(k, resolve);
            self.knots.push(knot);
        }
    }

    /// Trial time at which a slice sent at `now_ns` reaches the board.
    fn arrival(&self, now_ns: u64) -> u64 {
        self.trial_time(now_ns + self.timing.command_latency_ns)
    }

    /// After the period's work: puts the slice of the knots computed into the command delay line
    /// (with `overrun`, the previous slice again: the lookahead of two periods covers the one
    /// missed, and the knots computed late go out with the next period's slice), and returns in
    /// `out` the slices that leave it now. Whether the previous slice was sent again.
    pub(crate) fn publish(
        &mut self,
        now_ns: u64,
        overrun: bool,
        out: &mut Vec<CommandSlice>,
    ) -> bool {
        let (dt, dof) = (self.track.dt_ns, self.track.dof);
        let first = ((self.arrival(now_ns) / dt) as usize).saturating_sub(1);
        let last = self.knots.len();
        let mut resent = false;
        if overrun && let Some(mut c) = self.last_slice {
            resent = true;
            self.seq += 1;
            c.header = Header::new(self.seq, 0);
            self.command_line
                .push_back((now_ns + self.timing.command_latency_ns, c));
        } else if first < last {
            let last = last.min(first + MAX_KNOTS);
            self.seq += 1;
            let mut c = CommandSlice {
                header: Header::new(self.seq, 0),
                joints: dof as u32,
                trial: self.trial,
                interpolation: Interpolation::Hold as u32,
                start_ns: first as u64 * dt,
                knot_dt_ns: dt,
                count: (last - first) as u32,
                ..Default::default()
            };
            c.knots[..last - first].copy_from_slice(&self.knots[first..last]);
            self.last_slice = Some(c);
            self.command_line
                .push_back((now_ns + self.timing.command_latency_ns, c));
        }
        while let Some(&(release, _)) = self.command_line.front() {
            if release > now_ns {
                break;
            }
            let (_, mut c) = self.command_line.pop_front().expect("non-empty");
            c.header.time_ns = now_ns;
            out.push(c);
        }
        resent
    }

    /// The slices `sent` (what [`Controller::poll`] or [`Central::poll`] returned) were published
    /// at monotonic `at_ns` (live: the clock read after the last one went out; lockstep: the
    /// poll's time). Counts the knots they bring for the first time after the knot's time has
    /// come (`late_knots`).
    ///
    /// A knot `k` published at `at_ns ≤ start + k Δ` is in time for the board whatever its
    /// schedule: the board's trial time never runs ahead of the controller's (it starts at its
    /// first tick at or after the start), and the period `[kΔ, kΔ + 1 ms)` is integrated by a
    /// step that takes its messages after that period's end. A knot published later may have
    /// been needed before it arrived.
    pub fn sent(&mut self, sent: &[CommandSlice], at_ns: u64) {
        let (dt, steps) = (self.track.dt_ns, self.track.steps);
        let now = self.trial_time(at_ns);
        for c in sent.iter().filter(|c| c.trial == self.trial) {
            let first = (c.start_ns / dt) as usize;
            let last = (first + c.count as usize).min(steps);
            for k in first..last {
                if !self.published[k] {
                    self.published[k] = true;
                    self.late_knots += (k as u64 * dt < now) as usize;
                }
            }
        }
    }

    /// Whether a state acknowledging the present trial's reset has arrived.
    pub fn acknowledged(&self) -> bool {
        self.acknowledged
    }

    /// Whether the final state of the trial has arrived (or the board faulted).
    pub fn trial_done(&self) -> bool {
        self.recorded[self.track.steps].is_some() || self.fault
    }

    /// The trial as recorded.
    pub fn record(&self) -> TrialRecord {
        let t = &self.track;
        let mut missing = 0;
        let mut last = t.x0;
        let x = self
            .recorded
            .iter()
            .map(|r| {
                match r {
                    Some(x) => last = *x,
                    None => {
                        missing += 1;
                        if self.fault {
                            last = [f64::NAN; MAX_NX];
                        }
                    }
                }
                DVector::from_column_slice(&last[..t.nx])
            })
            .collect();
        let u = (0..t.steps)
            .map(|k| {
                DVector::from_column_slice(
                    &self.sent_u.get(k).copied().unwrap_or(t.acting(k))[..t.nu],
                )
            })
            .collect();
        TrialRecord {
            x,
            u,
            stale_feedback: self.stale_feedback,
            missing_states: missing,
            off_knot_states: self.off_knot_states,
            // Knots never published count too: the board acted on another one there.
            late_knots: self.late_knots + self.published.iter().filter(|p| !**p).count(),
            safe_hold: self.safe_hold,
            fault: self.fault,
            stalled: self.stalled || !self.trial_done(),
        }
    }
}
