//! Prints ILQG's progress on a scenario, iteration by iteration (step length, μ, merit):
//! `cargo run --release --example ilqg_trace -- config/single_joint_delay.toml task.delay_ms=0`
//! (`HELD=1`: from the first guess as the plans' deterministic phases solve, see below).

use nalgebra::DVector;
use std::path::Path;
use vic_core::solver::{Ilqg, Problem};
use vic_plan::plan;
use vic_plan::scenario::Scenario;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let file = args
        .first()
        .cloned()
        .unwrap_or("config/single_joint_delay.toml".into());
    let s = Scenario::load(Path::new(&file), &args[1.min(args.len())..]).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let (steps, d) = (s.task.steps, s.task.delay_steps());
    let delayed = setup.delayed(d);
    let problem = delayed.problem(steps);
    let plain = setup.problem(s.task.steps);
    let u_init: Vec<DVector<f64>> = if std::env::var("UNDELAYED").is_ok() {
        let t = std::time::Instant::now();
        let u = vic_core::delay::undelayed_guess(
            &plain,
            setup.u_init[0].as_slice(),
            d,
            &s.solver.options,
            &setup.u_init,
        )
        .expect("undelayed solve");
        println!("undelayed guess: {:.2} ms", t.elapsed().as_secs_f64() * 1e3);
        u
    } else {
        (0..steps)
            .map(|k| setup.u_init[(k + d).min(steps - 1)].clone())
            .collect()
    };
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    solver.on_iteration = Some(Box::new(|p| {
        println!(
            "{:4} alpha {:8.5} mu {:10.3e} merit {:.10e}",
            p.iteration, p.alpha, p.mu, p.merit
        )
    }));
    // HELD=1: as the plans' deterministic phases solve from a first guess, an impedance's
    // stiffness held at its lower limit first (`Ilqg::try_solve_held_first`).
    let mut sol = if std::env::var("HELD").is_ok() {
        solver.try_solve_held_first(&problem, &u_init)
    } else {
        solver.try_solve(&problem, &u_init)
    }
    .expect("solves");
    let (later_dynamics, later_cost) = (
        vic_core::delay::Offset::new(&delayed.dynamics, 2),
        vic_core::delay::Offset::new(&delayed.cost, 2),
    );
    if std::env::var("WARM").is_ok() {
        println!(
            "cold: {} iterations; warm re-solve two knots later:",
            sol.iterations
        );
        let later = Problem {
            dynamics: &later_dynamics,
            cost: &later_cost,
            x0: sol.x[2].as_slice().to_vec(),
            horizon: steps,
            bounds: setup.bounds.clone(),
        };
        sol = solver.resolve_shifted(&later, 2).expect("warm start");
    }
    println!(
        "{} iterations, {:?}, cost {:.10e}, expected {:.10e}, {:.2} ms",
        sol.iterations,
        sol.stop,
        sol.cost,
        sol.expected_cost,
        sol.solve_time.as_secs_f64() * 1e3
    );
}
