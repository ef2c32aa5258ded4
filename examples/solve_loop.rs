//! Solves one scenario's ILQG problem N times in one process, for whole-process A/B timing of two
//! builds (`/usr/bin/time -v`, alternated): `cargo run --release --example solve_loop --
//! config/two_link_reach.toml 3000 [KEY=VALUE ...]`. It times what `benches/solver.rs` times,
//! not `vic plan` (which adds the scenario's method and, for stochastic plans, a deterministic
//! first phase): `Ilqg::try_solve_into` (one reused `Solution`) from the scenario's first guess, or with a feedback delay the
//! delayed planner (the undelayed tail problem and the delayed gains), cold every time.
//! Prints the sum of the costs exactly (shortest round-trip form): two builds that compute the
//! same plans print the same.

use std::path::Path;
use vic_core::delay::DelayedPlanner;
use vic_core::solver::{Ilqg, Solution};
use vic_plan::plan;
use vic_plan::scenario::Scenario;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(file), Some(n)) = (
        args.first(),
        args.get(1).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!("usage: solve_loop CONFIG.toml N [KEY=VALUE ...]");
        std::process::exit(2);
    };
    let s = Scenario::load(Path::new(file), &args[2..]).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let setup = plan::setup(&s).expect("scenario sets up");
    let (steps, d) = (s.task.steps, s.task.delay_steps());
    let plain = setup.problem(steps);
    let mut sum = 0.0;
    if d == 0 {
        let mut solver = Ilqg::new(&plain, s.solver.options.clone());
        let mut out = Solution::empty();
        for _ in 0..n {
            solver
                .try_solve_into(&plain, &setup.u_init, &mut out)
                .expect("solves");
            sum += out.cost;
        }
    } else {
        let delayed = setup.delayed(d);
        let problem = delayed.problem(steps);
        let mut planner =
            DelayedPlanner::new(&plain, &problem, &s.solver.options).unwrap_or_else(|e| {
                eprintln!("{file}: {e}");
                std::process::exit(2)
            });
        for _ in 0..n {
            let plan = planner
                .solve(&plain, &problem, &setup.u_init)
                .expect("plans");
            sum += plan.solution.cost;
        }
    }
    println!("{sum:e}");
}
