//! The SOOC workspace: its iterations allocate nothing (a counting allocator), so a re-solve
//! in the central controller's period costs arithmetic only.

mod common;

use common::alloc::{Counting, allocations};
use nalgebra::DVector;
use std::path::Path;
use vic::core::solver::sooc::{MomentCost, MomentDynamics};
use vic::core::solver::sooc_newton::{SoocProblem, SoocSolver};
use vic::planning::plan::{self, Setup};
use vic::planning::scenario::Scenario;

#[global_allocator]
static GLOBAL: Counting = Counting;

fn load(file: &str) -> (Scenario, Setup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file);
    let s = Scenario::load(&path, &[]).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    (s, setup)
}

/// Allocations of one solve from `u0`, on one thread (the counter is
/// per thread; in a pool of one every knot runs there), and the iterations it made.
fn allocations_of_solve(
    solver: &mut SoocSolver,
    problem: &SoocProblem,
    u0: &[DVector<f64>],
    pool: &rayon::ThreadPool,
) -> (u64, usize) {
    pool.install(|| {
        let before = allocations();
        let sol = solver.solve(problem, u0).expect("solves");
        (allocations() - before, sol.iterations)
    })
}

/// A solve of `caps.1` iterations allocates what one of `caps.0` does (the solution's copies,
/// per solve): its iterations allocate nothing.
fn assert_iterations_do_not_allocate(file: &str, caps: (usize, usize)) {
    let (s, setup) = load(file);
    let horizon = s.task.steps;
    let moments = MomentDynamics::new(&setup.dynamics);
    let cost = MomentCost::new(&setup.cost, horizon);
    let problem = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let capped = |cap| {
        let mut options = s.solver.sooc_options();
        options.max_iterations = cap;
        SoocSolver::new(&moments, horizon, options)
    };
    let (mut few_solver, mut many_solver) = (capped(caps.0), capped(caps.1));
    let u0 = &setup.u_init;
    // A first solve each sizes whatever grows once (rayon's pool).
    allocations_of_solve(&mut few_solver, &problem, u0, &pool);
    allocations_of_solve(&mut many_solver, &problem, u0, &pool);
    let (few, it_few) = allocations_of_solve(&mut few_solver, &problem, u0, &pool);
    let (many, it_many) = allocations_of_solve(&mut many_solver, &problem, u0, &pool);
    assert!(
        it_many > it_few,
        "{file}: {it_few} and {it_many} iterations"
    );
    assert_eq!(
        few, many,
        "{file}: {it_few} iterations allocated {few} times, {it_many} iterations {many} times"
    );
}

/// The single joint, the impedance arm and the VSA arm (products larger than 5×5 by
/// `core::dense::multiply`: nalgebra's matrixmultiply allocated its packing buffers per call).
#[test]
fn iterations_do_not_allocate() {
    assert_iterations_do_not_allocate("icub_elbow.toml", (2, 8));
    assert_iterations_do_not_allocate("two_link_divergent.toml", (2, 5));
    assert_iterations_do_not_allocate("two_link_vsa_divergent.toml", (1, 3));
}
