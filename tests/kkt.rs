//! Control limits: the two-link reach (`config/two_link_reach.toml`) with a torque limit that
//! binds. Every planned control must lie in the box, and at convergence the gradient of the total
//! deterministic cost with respect to every control, by central finite differences of
//! `Problem::rollout`, must satisfy the first-order (KKT) conditions of the box-constrained
//! problem: ~0 on free components, pointing out of the box on components at a bound.

use nalgebra::DVector;
use std::path::Path;
use vic::config::Scenario;
use vic::plan::{Setup, setup};
use vic::solver::{Ilqg, Problem, Solution};

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
    Problem {
        dynamics: &setup.dynamics,
        cost: &setup.cost,
        x0: setup.x0.clone(),
        horizon: scenario.task.steps,
        bounds: setup.bounds.clone(),
    }
}

/// Gradient of the deterministic total cost with respect to every control, by central
/// differences of `Problem::rollout` (the rollout itself does not clamp, so the derivative at a
/// bound is the smooth two-sided one).
fn cost_gradient(problem: &Problem, u: &[DVector<f64>]) -> Vec<DVector<f64>> {
    let mut v = u.to_vec();
    let mut grad = vec![DVector::zeros(u[0].len()); u.len()];
    for k in 0..u.len() {
        for j in 0..u[k].len() {
            let h = 1e-5 * (1.0 + u[k][j].abs());
            v[k][j] = u[k][j] + h;
            let plus = problem.rollout(&v).1;
            v[k][j] = u[k][j] - h;
            let minus = problem.rollout(&v).1;
            v[k][j] = u[k][j];
            grad[k][j] = (plus - minus) / (2.0 * h);
        }
    }
    grad
}

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

    // Scale of the gradient: the control-effort term alone, ∂(Δ uᵀ W u)/∂u = 2 Δ w u, which the
    // tracking terms must balance at a free optimum.
    let dt = scenario.task.dt;
    let w = scenario.weights.w_torque;
    let scale = sol
        .u
        .iter()
        .map(|u| 2.0 * dt * w * u.amax())
        .fold(0.0, f64::max);
    let grad = cost_gradient(&problem, &sol.u);
    let tol = 1e-3 * scale;
    let (mut at_bound, mut worst_free, mut worst_bound) = (0, 0.0_f64, 0.0_f64);
    for (k, (u, g)) in sol.u.iter().zip(&grad).enumerate() {
        for j in 0..u.len() {
            if u[j] == upper[j] {
                // Raising u would leave the box; the cost must not fall when u is lowered.
                at_bound += 1;
                worst_bound = worst_bound.max(g[j]);
                assert!(
                    g[j] <= tol,
                    "u[{k}][{j}] at its upper bound with gradient {:e} (scale {scale:e})",
                    g[j]
                );
            } else if u[j] == lower[j] {
                at_bound += 1;
                worst_bound = worst_bound.max(-g[j]);
                assert!(
                    g[j] >= -tol,
                    "u[{k}][{j}] at its lower bound with gradient {:e} (scale {scale:e})",
                    g[j]
                );
            } else {
                worst_free = worst_free.max(g[j].abs());
                assert!(
                    g[j].abs() <= tol,
                    "free u[{k}][{j}] = {} has gradient {:e} (scale {scale:e})",
                    u[j],
                    g[j]
                );
            }
        }
    }
    eprintln!(
        "limit {limit:.4} N m (peak {peak:.4}), {at_bound} controls at a bound, worst free \
         gradient {worst_free:.3e}, worst inward gradient at a bound {worst_bound:.3e}, \
         scale {scale:.3e}, cost {:.6e} (unconstrained {:.6e})",
        sol.cost, free_solution.cost
    );
    assert!(at_bound > 0, "the limit does not bind");
    // The limit costs something: the constrained optimum is worse than the unconstrained one.
    assert!(sol.cost > free_solution.cost);
}
