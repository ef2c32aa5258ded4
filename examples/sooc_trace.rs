//! Prints SOOC's progress on the receding-horizon re-solve of a scenario, step by step (`J`,
//! relative μ, step length): the cold plan as `vic plan --method sooc` makes it, then the plan
//! shifted by SHIFT knots (default 2, one 50 Hz period) re-solved from its mean at that knot.
//! `cargo run --release --example sooc_trace -- config/two_link_divergent.toml [SHIFT] [KEY=VALUE ...]`.

use std::path::Path;
use std::sync::Arc;
use vic_core::solver::sooc::{MomentCost, MomentDynamics};
use vic_core::solver::sooc_newton::{SoocProblem, SoocSolver};
use vic_plan::plan;
use vic_plan::scenario::Scenario;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(file) = args.first() else {
        eprintln!("usage: sooc_trace CONFIG.toml [SHIFT] [KEY=VALUE ...]");
        std::process::exit(2);
    };
    let shift: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(2);
    let overrides: Vec<String> = args
        .iter()
        .skip(1)
        .filter(|a| a.contains('='))
        .cloned()
        .collect();
    let s = Scenario::load(Path::new(file), &overrides).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let setup = plan::setup(&s).expect("scenario sets up");
    let plain = setup.problem(s.task.steps);
    // COLD=1: the cold plan's steps too (each phase: the deterministic warm start, then SOOC).
    let progress: Option<plan::ProgressFn> = std::env::var("COLD").ok().map(|_| {
        Arc::new(|phase: &str, p: &vic_core::solver::ilqg::Progress| {
            println!(
                "  {phase} {:3}  J = {:.12e}  mu = {:.3e}  alpha = {:.4}",
                p.iteration, p.merit, p.mu, p.alpha
            )
        }) as plan::ProgressFn
    });
    let (cold, (stop, optimality)) =
        plan::plan_sooc(&s, &setup, &plain, &progress).expect("SOOC solves");
    println!(
        "cold: {stop:?}, {} iterations, {:.1} ms, J = {:.9e}, {optimality:?}",
        cold.iterations,
        cold.solve_time.as_secs_f64() * 1e3,
        cold.expected_cost
    );

    // SHRINK=1: the remaining movement (horizon N - SHIFT), as the central controller's
    // replanner re-solves; SHRINK=moments: the same from the plan's whole moment state at that
    // knot (mean and covariance), where the plan's tail is already optimal; SHRINK=carry: the
    // same as SHRINK=1 by `resolve_remaining` on the workspace that solved the whole movement
    // (each REPEAT re-solves the whole movement from the plan first, untimed).
    let shrink = std::env::var("SHRINK").ok();
    // The plan as the warm start, moved along with everything else.
    let planned = plan::Setup {
        u_init: cold.u.clone(),
        ..setup.clone()
    };
    let next = match shrink {
        Some(_) => planned.remaining(shift, cold.x[shift].as_slice()),
        None => planned.shifted(shift, cold.x[shift].as_slice()),
    };
    let warm = &next.u_init;
    let horizon = warm.len();
    let moments = MomentDynamics::new(&next.dynamics);
    let cost = MomentCost::new(&next.cost, horizon);
    let z0: Vec<f64> = if shrink.as_deref() == Some("moments") {
        let sizing = MomentDynamics::new(&setup.dynamics);
        let mut z = sizing.initial_state(&setup.x0);
        let mut after = z.clone();
        for (k, u) in cold.u.iter().take(shift).enumerate() {
            use vic_core::dynamics::Dynamics;
            sizing.step(k, &z, u.as_slice(), &mut after);
            std::mem::swap(&mut z, &mut after);
        }
        z
    } else {
        next.x0.clone()
    };
    let problem = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &z0,
        bounds: &next.bounds,
        horizon,
    };
    let full_moments = MomentDynamics::new(&setup.dynamics);
    let full_cost = MomentCost::new(&setup.cost, s.task.steps);
    let full = SoocProblem {
        dynamics: &full_moments,
        cost: &full_cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon: s.task.steps,
    };
    let carry = shrink.as_deref() == Some("carry");
    let mut solver = if carry {
        SoocSolver::new(&full_moments, s.task.steps, s.solver.sooc_options())
    } else {
        SoocSolver::new(&moments, horizon, s.solver.sooc_options())
    };
    let solve = |solver: &mut SoocSolver| {
        if carry {
            // A fresh workspace of the whole horizon each time (the last re-solve shrank it).
            let observer = solver.observer.take();
            *solver = SoocSolver::new(&full_moments, s.task.steps, s.solver.sooc_options());
            let whole = solver
                .solve(&full, &cold.u)
                .expect("solves the whole movement");
            assert_eq!(
                whole.iterations, 0,
                "the plan is the whole movement's optimum"
            );
            solver.observer = observer;
            solver.resolve_remaining(&problem, shift)
        } else {
            solver.solve(&problem, warm)
        }
    };
    solver.observer = Some(Arc::new(|p| {
        println!(
            "  step {:3}  J = {:.12e}  mu = {:.3e}  alpha = {:.4}",
            p.iteration, p.merit, p.mu, p.alpha
        )
    }));
    // REPEAT=N: the warm re-solve N more times, silently, for a profiler.
    let repeat: usize = std::env::var("REPEAT")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(0);
    let mut sol = solve(&mut solver).expect("re-solves");
    solver.observer = None;
    for _ in 0..repeat {
        sol = solve(&mut solver).expect("re-solves");
    }
    println!(
        "warm after {shift} knots: {:?}, {} iterations ({} without third derivatives, {} knots' \
         carried), {:.1} ms, J = {:.12e}, {:?}",
        sol.stop,
        sol.iterations,
        sol.without_third,
        sol.carried_third,
        sol.solve_time.as_secs_f64() * 1e3,
        sol.expected_cost,
        sol.optimality
    );
}
