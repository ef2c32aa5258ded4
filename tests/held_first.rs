//! Deterministic solves that hold an impedance's stiffness at its lower limit first
//! (`Ilqg::try_solve_held_first`): they must end where the free solve from the same first guess
//! ends (the deterministic problem has one optimum here: both stop within the solver's
//! tolerance of it), in fewer iterations, with the progress counted on across both solves;
//! stochastic solves and actuators whose stiffness carries the torque are not held; a held start
//! that cannot be rolled out falls back to the free solve.

use crate::common;

use common::scenario as load;

use nalgebra::DMatrix;
use std::sync::{Arc, Mutex};
use vic_core::dynamics::{Dynamics, Linearization};
use vic_core::solver::{Ilqg, StopReason};

/// On the impedance scenarios the scenario's first guess (inverse-dynamics torques, the
/// configured stiffness) solved deterministically: held first and free reach the same cost to
/// 1e-6 (the solver's relative tolerance on a step's gain), the held one in fewer iterations. A
/// held solve that stopped at the held optimum would be above it by far more than 1e-6 on every
/// scenario, so the check can fail.
#[test]
fn holding_the_stiffness_first_reaches_the_free_optimum() {
    for file in [
        "icub_elbow.toml",
        "icub_experiment.toml",
        "two_link_divergent.toml",
        "two_link_curl.toml",
    ] {
        let (s, setup) = load(file, &["solver.stochastic=false"]);
        let dof = s.model.dof();
        assert_eq!(
            s.solver.options.held_first,
            (dof..s.model.nu()).collect::<Vec<_>>(),
            "{file}: the stiffnesses are held"
        );
        let problem = setup.problem(s.task.steps);
        let mut free = Ilqg::new(&problem, s.solver.options.clone());
        let free = free.try_solve(&problem, &setup.u_init).expect("solves");
        let mut held = Ilqg::new(&problem, s.solver.options.clone());
        let numbers = Arc::new(Mutex::new(Vec::new()));
        let sink = numbers.clone();
        held.on_iteration = Some(Box::new(move |p| sink.lock().unwrap().push(p.iteration)));
        let held = held
            .try_solve_held_first(&problem, &setup.u_init)
            .expect("solves");

        // Where the stiffness stays held: the held problem's optimum, for scale.
        let mut pinned = setup.problem(s.task.steps);
        for i in dof..s.model.nu() {
            pinned.bounds.upper[i] = pinned.bounds.lower[i];
        }
        let at_lower = Ilqg::new(&pinned, s.solver.options.clone())
            .try_solve(&pinned, &setup.u_init)
            .expect("solves");
        let rel = (held.cost - free.cost).abs() / free.cost;
        println!(
            "{file}: free {} it, J = {:.12e}; held first {} it, J = {:.12e} (rel {rel:.1e}); held only J = {:.12e}",
            free.iterations, free.cost, held.iterations, held.cost, at_lower.cost
        );
        assert!(free.stop.converged() && held.stop.converged(), "{file}");
        assert!(rel <= 1e-6, "{file}: {rel:e}");
        assert!(
            (at_lower.cost - free.cost) / free.cost > 1e-5,
            "{file}: holding alone would pass the test above"
        );
        assert!(held.iterations < free.iterations, "{file}");
        assert_eq!(held.history.len(), held.iterations, "{file}");
        let numbers = numbers.lock().unwrap().clone();
        assert_eq!(
            numbers,
            (1..=held.iterations).collect::<Vec<_>>(),
            "{file}: the progress counts on over both solves"
        );
    }
}

/// A stochastic solve, a VSA (whose springs carry the motor torque: at zero stiffness nothing
/// moves the link) and `hold_stiffness_first = false` hold nothing: `try_solve_held_first` is
/// `try_solve` to the bit.
#[test]
fn stochastic_solves_vsas_and_the_switch_off_are_not_held() {
    for (file, overrides) in [
        ("icub_elbow.toml", &[][..]),
        (
            "two_link_vsa_divergent.toml",
            &["solver.stochastic=false"][..],
        ),
        (
            "two_link_divergent.toml",
            &[
                "solver.stochastic=false",
                "solver.hold_stiffness_first=false",
            ][..],
        ),
    ] {
        let (s, setup) = load(file, overrides);
        if file.contains("vsa") || overrides.len() == 2 {
            assert!(s.solver.options.held_first.is_empty(), "{file}");
        }
        let mut problem = setup.problem(s.task.steps);
        problem.horizon = problem.horizon.min(60);
        let u = &setup.u_init[..problem.horizon];
        let mut options = s.solver.options.clone();
        options.max_iterations = 15;
        let a = Ilqg::new(&problem, options.clone())
            .try_solve(&problem, u)
            .expect("solves");
        let b = Ilqg::new(&problem, options)
            .try_solve_held_first(&problem, u)
            .expect("solves");
        let bits = |v: &[nalgebra::DVector<f64>]| -> Vec<u64> {
            v.iter()
                .flat_map(|x| x.iter().map(|e| e.to_bits()))
                .collect()
        };
        assert_eq!(a.iterations, b.iterations, "{file}");
        assert_eq!(bits(&a.u), bits(&b.u), "{file}");
        assert_eq!(
            a.expected_cost.to_bits(),
            b.expected_cost.to_bits(),
            "{file}"
        );
    }
}

/// The iteration limit bounds both solves together: the free solve gets what the held one left
/// (none when the held solve used them all, and the plan is then the held solve's, stopped at the
/// limit).
#[test]
fn the_iteration_limit_counts_both_solves() {
    let (s, setup) = load("two_link_divergent.toml", &["solver.stochastic=false"]);
    let problem = setup.problem(s.task.steps);
    for limit in [1, 2, 4] {
        let mut options = s.solver.options.clone();
        options.max_iterations = limit;
        let mut solver = Ilqg::new(&problem, options);
        let sol = solver
            .try_solve_held_first(&problem, &setup.u_init)
            .expect("solves");
        assert_eq!(sol.iterations, limit, "limit {limit}");
        assert_eq!(sol.stop, StopReason::MaxIterations, "limit {limit}");
        assert_eq!(
            solver.options.max_iterations, limit,
            "the limit is restored"
        );
    }
}

/// The scenario's plant, except that a step with the stiffness below 1 N m/rad leaves the
/// finite numbers: a plant that the held stiffness (0) cannot roll out.
struct NeedsStiffness<'a>(&'a dyn Dynamics);

impl Dynamics for NeedsStiffness<'_> {
    fn nx(&self) -> usize {
        self.0.nx()
    }
    fn nu(&self) -> usize {
        self.0.nu()
    }
    fn nw(&self) -> usize {
        self.0.nw()
    }
    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.0.step(k, x, u, next);
        if u[1] < 1.0 {
            next.fill(f64::NAN);
        }
    }
    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        self.0.noise_gain(k, x, u, out);
    }
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        self.0.linearize(k, x, u, lin);
    }
}

/// When the held start cannot be rolled out, the solve is the free one from the first guess, to
/// the bit (and not an error).
#[test]
fn a_held_start_that_diverges_falls_back_to_the_free_solve() {
    let (s, setup) = load("icub_elbow.toml", &["solver.stochastic=false"]);
    let plant = NeedsStiffness(&setup.dynamics);
    let mut problem = setup.problem(s.task.steps);
    problem.dynamics = &plant;
    assert!(!s.solver.options.held_first.is_empty());
    let mut options = s.solver.options.clone();
    options.max_iterations = 10;
    let free = Ilqg::new(&problem, options.clone())
        .try_solve(&problem, &setup.u_init)
        .expect("the free start rolls out");
    let held = Ilqg::new(&problem, options)
        .try_solve_held_first(&problem, &setup.u_init)
        .expect("falls back");
    let bits = |v: &[nalgebra::DVector<f64>]| -> Vec<u64> {
        v.iter()
            .flat_map(|x| x.iter().map(|e| e.to_bits()))
            .collect()
    };
    assert!(free.iterations > 0);
    assert_eq!(held.iterations, free.iterations);
    assert_eq!(bits(&held.u), bits(&free.u));
    assert_eq!(held.cost.to_bits(), free.cost.to_bits());
}
