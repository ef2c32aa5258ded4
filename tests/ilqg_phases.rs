//! The solver in phases (backward pass, line search, regularisation, convergence test) computes
//! what a single-function solver computes: on reference problems the final cost, the predicted
//! expected cost and the iteration count match pinned numbers (first recorded from the
//! single-function solver, commit 5fdd56a) to 1e-12 relative. The single-joint cases' numbers
//! carry the rounding of the written-out drift Jacobian (`vic_core::model::jacobian`, not dual
//! numbers); the two-link reaches' are the same either way.
//!
//! The deterministic cases are well conditioned: a change of rounding moves them by far less than
//! the tolerance. The stochastic single joint is not: its optimum is flat in the stiffness, and
//! one different rounding per knot moves its converged expected cost by percents (skipping the
//! box QP for Newton steps inside the box does, see `vic_core::solver::ilqg::policy`). It therefore
//! pins the arithmetic bit for bit, on this kind of machine (the libm's sin/cos variant included).

use crate::common;

use common::scenario as load;

use nalgebra::DVector;
use vic_core::cost::{Cost, CostDerivatives};
use vic_core::solver::{Ilqg, Problem};

/// (cost, expected cost, accepted iterations) of a solve.
fn solve(file: &str, overrides: &[&str], delay: Option<usize>) -> (f64, f64, usize) {
    let (s, setup) = load(file, overrides);
    let steps = s.task.steps;
    match delay {
        None => {
            let problem = setup.problem(steps);
            let mut solver = Ilqg::new(&problem, s.solver.options.clone());
            let sol = solver.solve(&problem, &setup.u_init);
            (sol.cost, sol.expected_cost, sol.iterations)
        }
        Some(d) => {
            let delayed = setup.delayed(d);
            let problem = delayed.problem(steps);
            let u_init: Vec<DVector<f64>> = (0..steps)
                .map(|k| setup.u_init[(k + d).min(steps - 1)].clone())
                .collect();
            let mut solver = Ilqg::new(&problem, s.solver.options.clone());
            let sol = solver.solve(&problem, &u_init);
            (sol.cost, sol.expected_cost, sol.iterations)
        }
    }
}

fn check(name: &str, got: (f64, f64, usize), want: (f64, f64, usize)) {
    println!("{name}: ({:e}, {:e}, {})", got.0, got.1, got.2);
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-300);
    assert!(
        rel(got.0, want.0) < 1e-12 && rel(got.1, want.1) < 1e-12 && got.2 == want.2,
        "{name}: got {got:?}, recorded {want:?}"
    );
}

#[test]
fn reach_matches_the_unsplit_solver() {
    check(
        "reach",
        solve("two_link_reach.toml", &[], None),
        (29.537331653422974, 29.537331653422974, 2),
    );
}

#[test]
fn box_reach_matches_the_unsplit_solver() {
    check(
        "box reach",
        solve("two_link_reach.toml", &["actuator.torque_limit=0.25"], None),
        (43.17748234934694, 43.17748234934694, 12),
    );
}

#[test]
fn stochastic_single_joint_matches_the_unsplit_solver() {
    check(
        "icub elbow",
        solve("icub_elbow.toml", &[], None),
        (0.597708431059092, 41.48540080234872, 186),
    );
}

#[test]
fn delayed_single_joint_matches_the_unsplit_solver() {
    check(
        "delay 5 steps",
        solve("single_joint_delay.toml", &["noise.kind=none"], Some(5)),
        (0.5594016859369245, 0.5594016859369245, 31),
    );
}

/// The same cost without the claim that it is never negative: the line search then rolls every
/// candidate out to the end.
struct Unclaimed<'a>(&'a dyn Cost);

impl Cost for Unclaimed<'_> {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        self.0.running(k, x, u)
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        self.0.terminal(x)
    }
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        self.0.running_derivatives(k, x, u, d)
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives) {
        self.0.terminal_derivatives(x, d)
    }
}

/// Cutting a candidate's rollout short once its cost passes the nominal's (a nonnegative cost)
/// rejects exactly the steps a full rollout rejects: the same iterations, the same plan to the
/// bit, on problems whose early line searches reject long steps.
#[test]
fn rollouts_cut_short_take_the_same_steps() {
    for (file, overrides) in [
        ("two_link_reach.toml", &["actuator.torque_limit=0.25"][..]),
        (
            "single_joint_delay.toml",
            &["noise.kind=none", "task.delay_ms=0"][..],
        ),
    ] {
        let (s, setup) = load(file, overrides);
        assert!(setup.cost.nonnegative());
        let unclaimed = Unclaimed(&setup.cost);
        let solve = |cost: &dyn Cost| {
            let problem = Problem {
                dynamics: &setup.dynamics,
                cost,
                x0: setup.x0.clone(),
                horizon: s.task.steps,
                bounds: setup.bounds.clone(),
            };
            Ilqg::new(&problem, s.solver.options.clone()).solve(&problem, &setup.u_init)
        };
        let (cut, full) = (solve(&setup.cost), solve(&unclaimed));
        println!(
            "{file}: {} iterations, history {:?}",
            cut.iterations,
            &cut.history[..cut.history.len().min(4)]
        );
        assert!(cut.iterations > 5, "{file}: too easy to tell");
        assert_eq!(cut.iterations, full.iterations, "{file}");
        assert_eq!(cut.history, full.history, "{file}");
        assert_eq!(cut.u, full.u, "{file}");
    }
}
