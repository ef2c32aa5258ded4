//! Control limits: the two-link reach (`config/two_link_reach.toml`) with a torque limit that
//! binds. Every planned control must lie in the box, and at convergence the gradient of the total
//! deterministic cost with respect to every control, by central finite differences of
//! `Problem::rollout`, must satisfy the first-order (KKT) conditions of the box-constrained
//! problem: ~0 on free components, pointing out of the box on components at a bound.

use nalgebra::DVector;
use std::path::Path;
use vic_core::solver::{Ilqg, Problem, Solution};
use vic_plan::plan::{Setup, setup};
use vic_plan::scenario::Scenario;

const CONFIG: &str = "config/two_link_reach.toml";

/// Loads the reach scenario with `overrides` and solves it with ILQG with the scenario's options.
fn solve(overrides: &[String]) -> (Scenario, Setup, Solution) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(CONFIG);
    let scenario = Scenario::load(&path, overrides).expect("scenario loads");
    let setup = setup(&scenario).expect("scenario sets up");
    let solution = {
        let problem = problem(&scenario, &setup);
        let mut solver = Ilqg::new(&problem, scenario.solver.options.clone());
        solver.solve(&problem, &setup.u_init)
    };
    (scenario, setup, solution)
}

fn problem<'a>(scenario: &Scenario, setup: &'a Setup) -> Problem<'a> {
    setup.problem(scenario.task.steps)
}

/// First and second derivatives of the deterministic total cost with respect to every control
/// `u[k][j]` (the diagonal of the Hessian), by central differences of `Problem::rollout`. The
/// rollout does not clamp, so at a bound these are the smooth two-sided derivatives.
fn cost_derivatives(
    problem: &Problem,
    u: &[DVector<f64>],
) -> (Vec<DVector<f64>>, Vec<DVector<f64>>) {
    let (_, center) = problem.rollout(u);
    let mut v = u.to_vec();
    let mut grad = vec![DVector::zeros(u[0].len()); u.len()];
    let mut curv = grad.clone();
    for k in 0..u.len() {
        for j in 0..u[k].len() {
            let h = 1e-5 * (1.0 + u[k][j].abs());
            v[k][j] = u[k][j] + h;
            let plus = problem.rollout(&v).1;
            v[k][j] = u[k][j] - h;
            let minus = problem.rollout(&v).1;
            v[k][j] = u[k][j];
            grad[k][j] = (plus - minus) / (2.0 * h);
            curv[k][j] = (plus - 2.0 * center + minus) / (h * h);
        }
    }
    (grad, curv)
}

/// What is "~0" for a gradient component here. The reach weighs position errors by w_p = 1e6, so
/// the cost is very curved in every control (∂²J/∂u² ≈ 7e3) and a gradient component means
/// little on its own: its size is measured by the Newton step it asks for, `|∂J/∂u| / ∂²J/∂u²`,
/// relative to the torque limit. A converged solve leaves steps of ~1e-5 of the limit; a solve
/// stopped a few iterations early leaves ≥ 1e-2.
const STEP_TOLERANCE: f64 = 1e-3;

#[test]
fn torque_limited_reach_satisfies_the_kkt_conditions() {
    // The unconstrained optimum's peak torque, and a limit at 60 % of it so that it binds.
    let (_, _, free_solution) = solve(&[]);
    assert!(
        free_solution.stop.converged(),
        "unconstrained reach stopped with {:?}",
        free_solution.stop
    );
    let peak = free_solution.u.iter().map(|u| u.amax()).fold(0.0, f64::max);
    let limit = 0.6 * peak;
    let (scenario, setup, sol) = solve(&[format!("actuator.torque_limit={limit}")]);
    let problem = problem(&scenario, &setup);
    let (lower, upper) = (&setup.bounds.lower, &setup.bounds.upper);
    assert!(lower.iter().chain(upper).all(|b| b.abs() == limit));
    assert!(
        sol.stop.converged(),
        "limited reach stopped with {:?} after {} iterations",
        sol.stop,
        sol.iterations
    );

    // Every control within the limits.
    for (k, u) in sol.u.iter().enumerate() {
        for j in 0..u.len() {
            assert!(
                lower[j] <= u[j] && u[j] <= upper[j],
                "u[{k}][{j}] = {} outside [{}, {}]",
                u[j],
                lower[j],
                upper[j]
            );
        }
    }
    // The solution's cost is its rollout's.
    let (_, rolled) = problem.rollout(&sol.u);
    assert!((rolled - sol.cost).abs() <= 1e-12 * rolled.abs());

    let (grad, curv) = cost_derivatives(&problem, &sol.u);
    let (mut at_bound, mut worst_free, mut worst_bound) = (0, 0.0_f64, 0.0_f64);
    for (k, u) in sol.u.iter().enumerate() {
        for j in 0..u.len() {
            let (g, h) = (grad[k][j], curv[k][j]);
            assert!(h > 0.0, "∂²J/∂u[{k}][{j}]² = {h:e} is not positive");
            // The Newton step on u[k][j] alone, as a fraction of the limit.
            let step = -g / h / limit;
            let what = format!(
                "u[{k}][{j}] = {} (bounds [{}, {}]): ∂J/∂u = {g:e}, ∂²J/∂u² = {h:e}, Newton \
                 step {step:e} of the limit",
                u[j], lower[j], upper[j]
            );
            if u[j] == upper[j] {
                // At the upper bound the descent direction must point out of the box (up), or
                // vanish.
                at_bound += 1;
                worst_bound = worst_bound.max(-step);
                assert!(
                    step >= -STEP_TOLERANCE,
                    "{what}: descent points into the box"
                );
            } else if u[j] == lower[j] {
                at_bound += 1;
                worst_bound = worst_bound.max(step);
                assert!(
                    step <= STEP_TOLERANCE,
                    "{what}: descent points into the box"
                );
            } else {
                worst_free = worst_free.max(step.abs());
                assert!(step.abs() <= STEP_TOLERANCE, "{what}: not stationary");
            }
        }
    }
    eprintln!(
        "limit {limit:.4} N m (peak {peak:.4}), {at_bound} controls at a bound, worst Newton \
         step: free {worst_free:.3e}, into the box {worst_bound:.3e} (of the limit); cost \
         {:.6e} (unconstrained {:.6e})",
        sol.cost, free_solution.cost
    );
    assert!(at_bound > 0, "the limit does not bind");
    // The limit costs something: the constrained optimum is worse than the unconstrained one.
    assert!(sol.cost > free_solution.cost);
}
