//! The SOOC workspace: its iterations allocate nothing (a counting allocator), so a re-solve
//! in the central controller's period costs arithmetic only.

use crate::common;

use common::alloc::allocations;
use nalgebra::DVector;
use std::path::Path;
use vic_core::solver::Solution;
use vic_core::solver::sooc::{MomentCost, MomentDynamics};
use vic_core::solver::sooc_newton::{SoocProblem, SoocSolution, SoocSolver};
use vic_plan::plan::{self, Setup};
use vic_plan::scenario::Scenario;

fn load(file: &str) -> (Scenario, Setup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file);
    let s = Scenario::load(&path, &[]).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    (s, setup)
}

/// The divergent arm's plan (SOOC, cold) and the setup whose warm start is that plan.
fn divergent_plan() -> (Scenario, Setup, Solution, Setup) {
    let (s, setup) = load("two_link_divergent.toml");
    let horizon = s.task.steps;
    let (plan, _) = plan::plan_sooc(&s, &setup, &setup.problem(horizon), &None).expect("plans");
    let planned = Setup {
        u_init: plan.u.clone(),
        ..setup.clone()
    };
    (s, setup, plan, planned)
}

/// A pool of one thread: the allocation counter is per thread.
fn one_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool")
}

/// The same steps, stop, cost and controls, to the bit.
fn assert_same_bits(a: &SoocSolution, b: &SoocSolution) {
    assert_eq!((a.iterations, a.stop), (b.iterations, b.stop));
    assert_eq!(a.expected_cost.to_bits(), b.expected_cost.to_bits());
    for (x, y) in a.u.iter().zip(&b.u) {
        assert!(x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()));
    }
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
/// `vic_core::dense::multiply`: nalgebra's matrixmultiply allocates its packing buffers per call).
#[test]
fn iterations_do_not_allocate() {
    assert_iterations_do_not_allocate("icub_elbow.toml", (2, 8));
    assert_iterations_do_not_allocate("two_link_divergent.toml", (2, 5));
    assert_iterations_do_not_allocate("two_link_vsa_divergent.toml", (1, 3));
}

/// `resolve_remaining` on the workspace that solved the whole movement gives, to the bit, what a
/// new workspace's solve of the remaining movement gives: from the plan's own mean at knot 2 it
/// takes every knot's flow third derivatives from the previous solve (their points are the
/// same to the bit), from any other state none. It allocates no more than that solve, and a
/// call that does not fit leaves the workspace as it was.
#[test]
fn a_re_solve_of_the_remaining_movement_carries_only_exact_third_derivatives() {
    let (s, setup, plan, planned) = divergent_plan();
    let options = s.solver.sooc_options();
    let horizon = s.task.steps;
    let moments = MomentDynamics::new(&setup.dynamics);
    let cost = MomentCost::new(&setup.cost, horizon);
    let whole = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon,
    };
    let pool = one_thread();
    let at_plan = plan.x[2].as_slice().to_vec();
    let mut beside = at_plan.clone();
    beside[2] += 1e-6;
    for (x2, carried) in [(at_plan, horizon - 2), (beside, 0)] {
        let rest = planned.remaining(2, &x2);
        let rest_moments = MomentDynamics::new(&rest.dynamics);
        let rest_cost = MomentCost::new(&rest.cost, horizon - 2);
        let problem = SoocProblem {
            dynamics: &rest_moments,
            cost: &rest_cost,
            x0: &rest.x0,
            bounds: &rest.bounds,
            horizon: horizon - 2,
        };
        let mut solver = SoocSolver::new(&moments, horizon, options.clone());
        assert!(
            solver.resolve_remaining(&problem, 2).is_err(),
            "nothing solved yet"
        );
        let again = solver.solve(&whole, &plan.u).expect("solves");
        assert_eq!(
            again.iterations, 0,
            "the plan is the optimum: {:?}",
            again.stop
        );
        assert!(
            solver.resolve_remaining(&problem, 3).is_err(),
            "98 knots are not 97"
        );
        let (resolved, resolve_allocations) = pool.install(|| {
            let before = allocations();
            let sol = solver.resolve_remaining(&problem, 2).expect("re-solves");
            (sol, allocations() - before)
        });
        let mut new = SoocSolver::new(&rest_moments, horizon - 2, options.clone());
        let (fresh, fresh_allocations) = pool.install(|| {
            let before = allocations();
            let sol = new.solve(&problem, &rest.u_init).expect("solves");
            (sol, allocations() - before)
        });
        eprintln!(
            "remaining movement: {:?} in {} steps, {} knots carried, {:.1} ms (a new \
             workspace: {:.1} ms); allocations {resolve_allocations} / {fresh_allocations}",
            resolved.stop,
            resolved.iterations,
            resolved.carried_third,
            resolved.solve_time.as_secs_f64() * 1e3,
            fresh.solve_time.as_secs_f64() * 1e3,
        );
        eprintln!(
            "BITS {} {}",
            resolved.expected_cost.to_bits(),
            fresh.expected_cost.to_bits()
        );
        assert_eq!(resolved.carried_third, carried);
        assert_eq!(fresh.carried_third, 0);
        assert_same_bits(&resolved, &fresh);
        assert!(resolve_allocations <= fresh_allocations);
    }
}

/// `solve` over a shorter horizon fits the workspace of a longer one (the central controller's
/// re-solves over a shrinking rest of the movement): it allocates what a solve on a workspace of
/// that size does, and gives its result to the bit, although the workspace holds a previous
/// solve's steps. Back to the longer horizon it takes a new workspace, with the same result as
/// one; a call refused for its warm start's length leaves the workspace as it was.
#[test]
fn a_solve_over_a_shorter_horizon_reuses_the_workspace_to_the_bit() {
    let (s, setup, plan, planned) = divergent_plan();
    let mut options = s.solver.sooc_options();
    // A re-solve's cap, as the replanner's: the steps from a state off the plan, unconverged.
    options.max_iterations = 3;
    let horizon = s.task.steps;
    let moments = MomentDynamics::new(&setup.dynamics);
    let cost = MomentCost::new(&setup.cost, horizon);
    let whole = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon,
    };
    let pool = one_thread();
    let mut reused = SoocSolver::new(&moments, horizon, options.clone());
    // From the start the plan was made for: the workspace ends with that solve's steps.
    let first = reused.solve(&whole, &setup.u_init).expect("solves");
    assert!(first.iterations > 0);

    let k0 = 6;
    let mut x = plan.x[k0].as_slice().to_vec();
    x[0] += 1e-2;
    let rest = planned.remaining(k0, &x);
    let rest_moments = MomentDynamics::new(&rest.dynamics);
    let rest_cost = MomentCost::new(&rest.cost, horizon - k0);
    let problem = SoocProblem {
        dynamics: &rest_moments,
        cost: &rest_cost,
        x0: &rest.x0,
        bounds: &rest.bounds,
        horizon: horizon - k0,
    };
    assert!(
        reused.solve(&problem, &plan.u).is_err(),
        "100 controls for 94 knots"
    );
    assert_eq!(reused.horizon(), horizon, "a refused call changes nothing");
    let (fitted, fitted_allocations) = pool.install(|| {
        let before = allocations();
        let sol = reused.solve(&problem, &rest.u_init).expect("re-solves");
        (sol, allocations() - before)
    });
    assert_eq!(reused.horizon(), horizon - k0);
    let mut new = SoocSolver::new(&rest_moments, horizon - k0, options.clone());
    // Its first solve sizes what grows once (rayon's pool); the second is counted.
    new.solve(&problem, &rest.u_init).expect("solves");
    let (fresh, fresh_allocations) = pool.install(|| {
        let before = allocations();
        let sol = new.solve(&problem, &rest.u_init).expect("solves");
        (sol, allocations() - before)
    });
    let fresh_once = SoocSolver::new(&rest_moments, horizon - k0, options.clone())
        .solve(&problem, &rest.u_init)
        .expect("solves");
    eprintln!(
        "rest of the movement from knot {k0}, 1 cm off: {:?} after {} steps; allocations \
         {fitted_allocations} fitted, {fresh_allocations} on its own workspace",
        fitted.stop, fitted.iterations
    );
    assert!(fitted.iterations > 0);
    assert_same_bits(&fitted, &fresh_once);
    assert_same_bits(&fresh, &fresh_once);
    assert_eq!(fitted_allocations, fresh_allocations);

    // Back to the whole movement: a new workspace, the same result.
    let again = reused.solve(&whole, &setup.u_init).expect("solves");
    assert_eq!(reused.horizon(), horizon);
    assert_same_bits(&again, &first);
}
