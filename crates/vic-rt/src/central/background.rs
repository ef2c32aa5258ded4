//! The `replan` strategy's re-solves on a worker thread, so that a re-solve longer than the
//! central period never holds the slices back (live on the arm one can take many 20 ms periods,
//! docs/BENCHMARKS.md, "Live replanner"; inline, each such period would overrun and resend the
//! previous slice).
//!
//! The law is [`Replanner`]'s with `lead_steps` = one period: at a replanning knot `k` the
//! controller predicts the state of knot `k0 = k + lead` (over the commands in flight, then over
//! the plan's commands of `k..k0`, which it goes on sending), hands `(k0, x̂, warm start)` to the
//! worker, and adopts the worker's plan at the first knot it has not computed yet — `k0` when
//! the re-solve came back within the period, later (counted in `late`) when it did not. One
//! re-solve is in flight at a time: a replanning knot that finds the worker busy is skipped
//! (counted in `skipped`). With `wait` the controller waits for each re-solve at the next period
//! instead, which makes the outcome independent of the machine (lockstep and the tests: then it
//! executes exactly what the Monte Carlo executes with the same `lead_steps`).

use crate::realtime::LatencyHistogram;
use crate::transport::monotonic_ns;
use nalgebra::DVector;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::thread::JoinHandle;
use vic_core::replan::{ReplanOutcome, ReplanStats, Replanner};
use vic_core::scalar::MAX_NX;

/// A re-solve asked of the worker.
struct Request {
    /// The trial it belongs to (results of an earlier trial are dropped).
    trial: u64,
    k0: usize,
    x: [f64; MAX_NX],
    nx: usize,
    /// The plan's commands from `k0` on (the warm start).
    warm: Vec<DVector<f64>>,
}

/// What the worker sends back.
struct Reply {
    trial: u64,
    k0: usize,
    /// The new commands from `k0` on, if the re-solve was accepted.
    commands: Option<Vec<DVector<f64>>>,
    /// The worker's statistics of this one re-solve.
    stats: ReplanStats,
    solve_ns: u64,
}

/// The worker thread and the controller's side of it.
pub(super) struct Background {
    requests: Option<Sender<Request>>,
    replies: Receiver<Reply>,
    worker: Option<JoinHandle<()>>,
    /// Wait for each re-solve at the next period (deterministic) instead of adopting it when it
    /// has come back.
    wait: bool,
    in_flight: bool,
    trial: u64,
    /// Re-solves adopted after the knot they were made for (part of their plan was too late).
    pub late: u64,
    /// Replanning knots skipped because the previous re-solve was still running.
    pub skipped: u64,
}

impl Background {
    /// Starts a worker that re-solves with a copy of `replanner` (its model, cost and options).
    pub(super) fn start(replanner: &Replanner, wait: bool) -> Background {
        let (requests, inbox) = channel::<Request>();
        let (outbox, replies) = channel::<Reply>();
        let mut own = replanner.clone();
        let worker = std::thread::Builder::new()
            .name("vic-replan".into())
            .spawn(move || {
                while let Ok(r) = inbox.recv() {
                    own.adopt(r.k0, r.k0, &r.warm);
                    let before = own.stats;
                    let t0 = monotonic_ns();
                    let outcome = own.replan_from(r.k0, &r.x[..r.nx]);
                    let solve_ns = monotonic_ns().saturating_sub(t0);
                    let commands = matches!(outcome, ReplanOutcome::Accepted { .. })
                        .then(|| own.tail(r.k0).to_vec());
                    let stats = own.stats.since(&before);
                    let reply = Reply {
                        trial: r.trial,
                        k0: r.k0,
                        commands,
                        stats,
                        solve_ns,
                    };
                    if outbox.send(reply).is_err() {
                        break;
                    }
                }
            })
            .expect("spawning the re-solve thread");
        Background {
            requests: Some(requests),
            replies,
            worker: Some(worker),
            wait,
            in_flight: false,
            trial: 0,
            late: 0,
            skipped: 0,
        }
    }

    /// A new trial: a re-solve still running belongs to the old one and will be dropped.
    pub(super) fn begin_trial(&mut self) {
        self.trial += 1;
    }

    /// At a period's start: adopts the re-solve that came back (waits for it with `wait`), from
    /// knot `next` (the first not computed yet) on, and accounts for it.
    pub(super) fn collect(
        &mut self,
        replanner: &mut Replanner,
        next: usize,
        stats: &mut ReplanStats,
        time: &mut LatencyHistogram,
    ) {
        while self.in_flight {
            let reply = if self.wait {
                match self.replies.recv() {
                    Ok(r) => r,
                    Err(_) => return self.in_flight = false,
                }
            } else {
                match self.replies.try_recv() {
                    Ok(r) => r,
                    Err(TryRecvError::Empty) => return,
                    Err(TryRecvError::Disconnected) => return self.in_flight = false,
                }
            };
            self.in_flight = false;
            if reply.trial != self.trial {
                continue;
            }
            time.record(reply.solve_ns);
            stats.add(&reply.stats);
            if let Some(c) = reply.commands {
                self.late += (next > reply.k0) as u64;
                replanner.adopt(reply.k0, next.max(reply.k0), &c);
            }
        }
    }

    /// The command of knot `k` (see [`Replanner::command_into`]): the plan's, after handing a
    /// re-solve to the worker at a replanning knot (when it is free).
    pub(super) fn command_into<'a>(
        &mut self,
        replanner: &Replanner,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) {
        if let Some(k0) = replanner.predict_for(k, seen, applied, scratch) {
            if self.in_flight {
                self.skipped += 1;
            } else if let Some(tx) = &self.requests {
                let nx = seen.map_or(0, |(_, x)| x.len());
                let mut x = [0.0; MAX_NX];
                x[..nx].copy_from_slice(&scratch[..nx]);
                let request = Request {
                    trial: self.trial,
                    k0,
                    x,
                    nx,
                    warm: replanner.tail(k0).to_vec(),
                };
                self.in_flight = tx.send(request).is_ok();
            }
        }
        replanner.plan_command_into(k, u);
    }
}

impl Drop for Background {
    /// Closes the request channel and joins the worker (it finishes the re-solve it is in).
    fn drop(&mut self) {
        self.requests = None;
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}
