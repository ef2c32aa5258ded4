//! The delayed planner's warm replans with the scenario's noise, as a receding horizon: for
//! each delay, a cold plan, then four replans each `shift` knots later from the augmented state
//! the last plan's commands lead to; prints the replans' iterations and time summed over the
//! four, and the last one's expected cost. Then the central controller's steady load: 30
//! replans two knots apart (50 Hz), each replan's iterations and the mean time of a replan,
//! over all 30 and over the last 20, converged and capped at 2 iterations (the criterion cases
//! `…_noise_receding` and `…_receding_capped2` time the same in `docs/BENCHMARKS.md`, "Solver"):
//! `cargo run --release --example delay_replans [config/single_joint_delay.toml]`.

use std::path::Path;
use vic_core::delay::{Delayed, DelayedPlanner, Offset};
use vic_core::dynamics::Dynamics;
use vic_core::solver::Problem;
use vic_plan::plan;
use vic_plan::scenario::Scenario;

/// What a receding sequence took: each replan's iterations and milliseconds, and the last
/// replan's expected cost.
struct Sequence {
    iterations: Vec<usize>,
    ms: Vec<f64>,
    last: f64,
}

fn main() {
    let file = std::env::args()
        .nth(1)
        .unwrap_or("config/single_joint_delay.toml".into());
    for delay in [100, 150, 200, 250] {
        let mut line = format!("delay {delay} ms:");
        for shift in [1, 2, 3, 5] {
            let q = sequence(&file, delay, shift, 4, None);
            let (iterations, ms) = (q.iterations.iter().sum::<usize>(), q.ms.iter().sum::<f64>());
            line += &format!(
                " shift {shift}: {iterations} it, {ms:.0} ms, E {:.3};",
                q.last
            );
        }
        println!("{line}");
    }
    for (delay, cap) in [100, 150, 200, 250]
        .into_iter()
        .flat_map(|d| [(d, None), (d, Some(2))])
    {
        let q = sequence(&file, delay, 2, 30, cap);
        let mean = |ms: &[f64]| ms.iter().sum::<f64>() / ms.len() as f64;
        println!(
            "delay {delay} ms, 30 replans 2 knots apart{}: iterations {:?}, {:.2} ms a replan ({:.2} over the last 20), E {:.3}",
            cap.map(|c| format!(", capped at {c}")).unwrap_or_default(),
            q.iterations,
            mean(&q.ms),
            mean(&q.ms[10..]),
            q.last
        );
    }
}

/// A cold plan at `delay` ms, then `replans` replans each `shift` knots later, each of at most
/// `cap` iterations if given (`DelayedPlanner::replan_iterations`).
fn sequence(
    file: &str,
    delay: usize,
    shift: usize,
    replans: usize,
    cap: Option<usize>,
) -> Sequence {
    let set = [format!("task.delay_ms={delay}")];
    let s = Scenario::load(Path::new(file), &set).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let delayed = Delayed::new(setup.dynamics.clone(), s.task.delay_steps());
    let nx = setup.x0.len();
    let cost = plan::DelayedCost::new(&setup.cost, nx);
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let problem = Problem {
        dynamics: &delayed,
        cost: &cost,
        x0: x0.clone(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let plain = setup.problem(s.task.steps);
    let mut planner = DelayedPlanner::new(&plain, &problem, &s.solver.options).expect("sizes fit");
    planner.replan_iterations = cap;
    let cold = planner
        .solve(&plain, &problem, &setup.u_init)
        .expect("plans");
    let (mut u, mut z, mut at) = (cold.solution.u, x0.clone(), 0);
    let mut out = Sequence {
        iterations: Vec::new(),
        ms: Vec::new(),
        last: 0.0,
    };
    for _ in 0..replans {
        for (k, uk) in u.iter().enumerate().take(shift) {
            let mut next = vec![0.0; z.len()];
            delayed.step(at + k, &z, uk.as_slice(), &mut next);
            z = next;
        }
        at += shift;
        let (later, later_cost) = (Offset::new(&delayed, at), Offset::new(&cost, at));
        let (plain_later, plain_cost) = (
            Offset::new(&setup.dynamics, at),
            Offset::new(&setup.cost, at),
        );
        let shifted = Problem {
            dynamics: &later,
            cost: &later_cost,
            x0: z.clone(),
            horizon: s.task.steps,
            bounds: setup.bounds.clone(),
        };
        let shifted_plain = Problem {
            dynamics: &plain_later,
            cost: &plain_cost,
            x0: z[..nx].to_vec(),
            horizon: s.task.steps,
            bounds: setup.bounds.clone(),
        };
        let t = std::time::Instant::now();
        let warm = planner
            .resolve_shifted(&shifted_plain, &shifted, shift)
            .expect("replans");
        out.ms.push(t.elapsed().as_secs_f64() * 1e3);
        out.iterations.push(warm.solution.iterations);
        out.last = warm.solution.expected_cost;
        u = warm.solution.u;
    }
    out
}
