//! The ILQG workspace: iterations allocate nothing (a counting allocator), a diverging initial
//! guess is an error and not a panic, and a warm start from the shifted converged plan
//! re-converges to the cold start's cost in fewer iterations.

use crate::common;

use common::scenario as load;

use common::alloc::allocations;
use nalgebra::DVector;
use vic_core::delay::{Delayed, Offset};
use vic_core::solver::{Ilqg, IlqgError, IlqgOptions, Problem, StopReason};
use vic_plan::plan::{DelayedCost, Setup};
use vic_plan::scenario::Scenario;

fn problem<'a>(s: &Scenario, setup: &'a Setup) -> Problem<'a> {
    setup.problem(s.task.steps)
}

/// Allocations of one solve capped at `iterations` (the solution's copies are the same for
/// every cap, so a difference between caps is what the iterations allocate).
fn allocations_of_solve(
    solver: &mut Ilqg,
    problem: &Problem,
    u: &[DVector<f64>],
    iterations: usize,
) -> (u64, usize) {
    solver.options.max_iterations = iterations;
    let before = allocations();
    let sol = solver.try_solve(problem, u).expect("solves");
    (allocations() - before, sol.iterations)
}

fn assert_iterations_do_not_allocate(file: &str, overrides: &[&str], caps: (usize, usize)) {
    let (s, setup) = load(file, overrides);
    let problem = problem(&s, &setup);
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    assert_solves_do_not_allocate(file, &mut solver, &problem, &setup.u_init, caps);
}

/// Two solves of `problem` in one workspace, capped at `caps` iterations, allocate alike.
fn assert_solves_do_not_allocate(
    file: &str,
    solver: &mut Ilqg,
    problem: &Problem,
    u: &[DVector<f64>],
    caps: (usize, usize),
) {
    let (few, it_few) = allocations_of_solve(solver, problem, u, caps.0);
    let (many, it_many) = allocations_of_solve(solver, problem, u, caps.1);
    assert!(
        it_many > it_few,
        "{file}: the caps must change the work ({it_few} vs {it_many} iterations)"
    );
    assert_eq!(
        few, many,
        "{file}: {it_few} iterations allocated {few} times, {it_many} iterations {many} times"
    );
}

#[test]
fn iterations_do_not_allocate() {
    // Unbounded (Newton policy), box-bounded (the QP) and stochastic (the noise terms and merit).
    assert_iterations_do_not_allocate("two_link_reach.toml", &[], (1, 2));
    assert_iterations_do_not_allocate(
        "two_link_reach.toml",
        &["actuator.torque_limit=0.25"],
        (1, 8),
    );
    assert_iterations_do_not_allocate("icub_elbow.toml", &[], (2, 20));
}

/// The noisy delayed plant's iterations (its backward pass by the Jacobians' nonzeros, the
/// workspace with room for the nonzeros its support allows only) allocate nothing either: a
/// refill past that room would grow storage in the first solve's iterations.
#[test]
fn noisy_delayed_iterations_do_not_allocate() {
    let file = "single_joint_delay.toml";
    let (s, setup) = load(file, &[]);
    let (steps, d) = (s.task.steps, s.task.delay_steps());
    let delayed = setup.delayed(d);
    let problem = delayed.problem(steps);
    let u: Vec<DVector<f64>> = (0..steps)
        .map(|k| setup.u_init[(k + d).min(steps - 1)].clone())
        .collect();
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    assert_solves_do_not_allocate(file, &mut solver, &problem, &u, (1, 4));
}

/// A solve into a reused `Solution` allocates nothing at all, and gives what a fresh solve
/// gives to the bit, whether the reused one held a plan of the same size or of another.
#[test]
fn a_solve_into_a_reused_solution_allocates_nothing() {
    let bits = |v: &[DVector<f64>]| -> Vec<u64> {
        v.iter()
            .flat_map(|x| x.iter().map(|v| v.to_bits()))
            .collect()
    };
    for (file, overrides) in [
        ("two_link_reach.toml", &[][..]),
        ("two_link_reach.toml", &["actuator.torque_limit=0.25"][..]),
        ("icub_elbow.toml", &[][..]),
    ] {
        // A plan of another size first (the single joint): the reused storage must take the
        // shape of this problem's.
        let (s2, setup2) = load("single_joint_delay.toml", &[]);
        let other = problem(&s2, &setup2);
        let (s, setup) = load(file, overrides);
        let problem = problem(&s, &setup);
        let mut solver = Ilqg::new(&problem, s.solver.options.clone());
        let fresh = solver.try_solve(&problem, &setup.u_init).expect("solves");
        let mut out = Ilqg::new(&other, s2.solver.options.clone())
            .try_solve(&other, &setup2.u_init)
            .expect("solves");
        for round in 0..2 {
            let before = allocations();
            solver
                .try_solve_into(&problem, &setup.u_init, &mut out)
                .expect("solves");
            let allocated = allocations() - before;
            if round == 1 {
                assert_eq!(
                    allocated, 0,
                    "{file} {overrides:?}: a solve into a reused solution"
                );
            }
            let what = format!("{file} {overrides:?}, round {round}");
            assert_eq!(bits(&out.x), bits(&fresh.x), "{what}: x");
            assert_eq!(bits(&out.u), bits(&fresh.u), "{what}: u");
            let gains = |g: &[nalgebra::DMatrix<f64>]| -> Vec<u64> {
                g.iter()
                    .flat_map(|m| m.iter().map(|v| v.to_bits()))
                    .collect()
            };
            assert_eq!(gains(&out.gains), gains(&fresh.gains), "{what}: gains");
            assert_eq!(
                out.gains[0].shape(),
                fresh.gains[0].shape(),
                "{what}: gain shape"
            );
            assert_eq!(out.cost.to_bits(), fresh.cost.to_bits(), "{what}: cost");
            assert_eq!(out.history, fresh.history, "{what}: history");
            assert_eq!((out.iterations, out.stop), (fresh.iterations, fresh.stop));
            // The same shapes now: the next solve must write every entry in place.
            out.x
                .iter_mut()
                .chain(&mut out.u)
                .for_each(|v| v.fill(f64::NAN));
            out.gains.iter_mut().for_each(|m| m.fill(f64::NAN));
            out.history.push(f64::NAN);
        }
    }
}

#[test]
fn delayed_iterations_do_not_allocate() {
    let (s, setup) = load("single_joint_delay.toml", &["noise.kind=none"]);
    let delayed = Delayed::new(setup.dynamics.clone(), s.task.delay_steps());
    let cost = DelayedCost::new(&setup.cost, setup.x0.len());
    let problem = Problem {
        dynamics: &delayed,
        cost: &cost,
        x0: delayed.initial_state(&setup.x0, setup.u_init[0].as_slice()),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    let (few, a) = allocations_of_solve(&mut solver, &problem, &setup.u_init, 1);
    let (many, b) = allocations_of_solve(&mut solver, &problem, &setup.u_init, 6);
    assert!(b > a);
    assert_eq!(few, many, "{a} iterations: {few} allocations, {b}: {many}");
}

#[test]
fn a_diverging_initial_guess_is_an_error() {
    let (s, setup) = load("two_link_reach.toml", &[]);
    let problem = problem(&s, &setup);
    let mut solver = Ilqg::new(&problem, IlqgOptions::default());
    let wild = vec![DVector::from_element(2, 1e300); s.task.steps];
    match solver.try_solve(&problem, &wild) {
        Err(IlqgError::DivergingInitialGuess { step, horizon }) => {
            assert!(step >= 1 && step <= horizon)
        }
        other => panic!("expected a diverging-guess error, got {other:?}"),
    }
    assert_eq!(
        solver.resolve_shifted(&problem, 1).unwrap_err(),
        IlqgError::NoPreviousSolution
    );
    // The workspace still solves afterwards.
    assert!(
        solver
            .try_solve(&problem, &setup.u_init)
            .unwrap()
            .stop
            .converged()
    );
    // A replacement tail longer than the horizon, or of the wrong size, is refused.
    let steps = s.task.steps;
    let long = vec![DVector::zeros(2); steps + 1];
    assert_eq!(
        solver
            .resolve_shifted_with_tail(&problem, 1, &long)
            .unwrap_err(),
        IlqgError::InitialGuessLength {
            got: steps + 1,
            want: steps
        }
    );
    let wrong = vec![DVector::zeros(3); 2];
    assert_eq!(
        solver
            .resolve_shifted_with_tail(&problem, 1, &wrong)
            .unwrap_err(),
        IlqgError::ControlSize {
            knot: steps - 2,
            got: 3,
            want: 2
        }
    );
}

/// A solve whose first backward pass never finds a positive definite `Q_uu` (control weights
/// of −10⁶ against a regularisation limit of 1) stops at the limit without convergence
/// figures: there are none to report, and infinities would not survive a plan file's JSON.
#[test]
fn no_backward_pass_means_no_convergence_figures() {
    let (s, mut setup) = load("two_link_reach.toml", &[]);
    for w in &mut setup.cost.control_weights {
        *w = -1e6;
    }
    let bad = problem(&s, &setup);
    let options = IlqgOptions {
        mu_max: 1.0,
        ..IlqgOptions::default()
    };
    let sol = Ilqg::new(&bad, options)
        .try_solve(&bad, &setup.u_init)
        .expect("starts");
    assert_eq!(
        (sol.stop, sol.iterations),
        (StopReason::RegularizationLimit, 0)
    );
    assert_eq!(sol.convergence, None);
    // With the scenario's weights the same workspace reports finite figures.
    let (s, setup) = load("two_link_reach.toml", &[]);
    let plain = problem(&s, &setup);
    let sol = Ilqg::new(&plain, IlqgOptions::default()).solve(&plain, &setup.u_init);
    let c = sol.convergence.expect("figures");
    assert!(c.feedforward_step.is_finite() && c.met(), "{c:?}");
}

/// The plan advanced `shift` knots: the same horizon from the predicted state, reference read
/// `shift` knots later. Warm (shifted solution) and cold (the scenario's guess) must agree.
fn warm_matches_cold(file: &str, overrides: &[&str], shift: usize) {
    let (s, setup) = load(file, overrides);
    let first = problem(&s, &setup);
    let mut solver = Ilqg::new(&first, s.solver.options.clone());
    let sol = solver.try_solve(&first, &setup.u_init).expect("solves");
    assert!(sol.stop.converged());
    let (dynamics, cost) = (
        Offset::new(&setup.dynamics, shift),
        Offset::new(&setup.cost, shift),
    );
    let later = Problem {
        dynamics: &dynamics,
        cost: &cost,
        x0: sol.x[shift].as_slice().to_vec(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let warm = solver.resolve_shifted(&later, shift).expect("warm start");
    let mut cold_solver = Ilqg::new(&later, s.solver.options.clone());
    let cold = cold_solver
        .try_solve(&later, &setup.u_init)
        .expect("cold start");
    println!(
        "{file}: warm {} it, cost {:.12e}; cold {} it, cost {:.12e}",
        warm.iterations, warm.cost, cold.iterations, cold.cost
    );
    assert!(warm.stop.converged() && cold.stop.converged());
    let rel = (warm.cost - cold.cost).abs() / cold.cost;
    assert!(
        rel < 1e-5,
        "{file}: warm {} vs cold {} (rel {rel:e})",
        warm.cost,
        cold.cost
    );
    assert!(
        warm.iterations <= cold.iterations,
        "{file}: warm {} iterations, cold {}",
        warm.iterations,
        cold.iterations
    );
}

#[test]
fn shifted_warm_start_reconverges_to_the_cold_cost() {
    warm_matches_cold("two_link_reach.toml", &[], 5);
    warm_matches_cold("two_link_reach.toml", &["actuator.torque_limit=0.25"], 3);
}

/// Without noise the delayed problem is the undelayed one from the state the commands in flight
/// lead to: the first guess from the undelayed plant is already the delayed optimum.
#[test]
fn undelayed_guess_is_the_deterministic_delayed_optimum() {
    let (s, setup) = load("single_joint_delay.toml", &["noise.kind=none"]);
    let d = s.task.delay_steps();
    let steps = s.task.steps;
    let delayed = setup.delayed(d);
    let problem = delayed.problem(steps);
    let plain = setup.problem(s.task.steps);
    let guess = vic_core::delay::undelayed_guess(
        &plain,
        setup.u_init[0].as_slice(),
        d,
        &s.solver.options,
        &setup.u_init,
    )
    .expect("undelayed guess");
    let shifted: Vec<DVector<f64>> = (0..steps)
        .map(|k| setup.u_init[(k + d).min(steps - 1)].clone())
        .collect();
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    let from_guess = solver.try_solve(&problem, &guess).expect("solves");
    let guess_cost = problem.rollout(&guess).1;
    let cold = solver.try_solve(&problem, &shifted).expect("solves");
    println!(
        "guess {guess_cost:.12e}; from it {} it {:.12e}; cold {} it {:.12e}",
        from_guess.iterations, from_guess.cost, cold.iterations, cold.cost
    );
    assert!(from_guess.stop.converged() && cold.stop.converged());
    // The guess is within the solver's tolerance of the optimum the cold start finds.
    assert!((guess_cost - cold.cost).abs() / cold.cost < 1e-5);
    assert!(from_guess.cost <= cold.cost * (1.0 + 1e-9));
    assert!(from_guess.iterations * 5 <= cold.iterations);
}

/// The delayed plant with nonzeros where its Jacobians have zeros (and no support declared):
/// another plant of the same size, whose linearisations fill the whole buffer.
struct Filled<'a>(&'a Delayed<vic_core::dynamics::DiscreteDynamics>);

impl vic_core::dynamics::Dynamics for Filled<'_> {
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
    }
    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut nalgebra::DMatrix<f64>) {
        self.0.noise_gain(k, x, u, out);
    }
    fn linearize(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        lin: &mut vic_core::dynamics::Linearization,
    ) {
        self.0.linearize(k, x, u, lin);
        for m in std::iter::once(&mut lin.a).chain(lin.cx.iter_mut()) {
            m.iter_mut().filter(|v| **v == 0.0).for_each(|v| *v = 1e-3);
        }
    }
    fn structure(
        &self,
        _support: Option<&mut vic_core::dynamics::StateSupport>,
    ) -> vic_core::dynamics::Structure {
        vic_core::dynamics::Structure {
            parallel_linearization: false,
            supported: false,
        }
    }
}

/// A workspace that solved another plant of the same size solves the delayed single joint (its
/// noise included) as a fresh workspace does, to the bit: what the delayed plant relies on
/// between the linearisations of one solve (the zeros it does not rewrite, the rows its
/// support names) is set up anew by each solve.
#[test]
fn a_workspace_from_another_plant_solves_the_delayed_plant_as_a_fresh_one() {
    use vic_core::dynamics::Dynamics;
    let (s, setup) = load("single_joint_delay.toml", &[]);
    let delayed = Delayed::new(setup.dynamics.clone(), s.task.delay_steps());
    let cost = DelayedCost::new(&setup.cost, setup.x0.len());
    let filled = Filled(&delayed);
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, other) = [&delayed as &dyn Dynamics, &filled]
        .map(|dynamics| Problem {
            dynamics,
            cost: &cost,
            x0: x0.clone(),
            horizon: s.task.steps,
            bounds: setup.bounds.clone(),
        })
        .into();
    let bits = |sol: &vic_core::solver::Solution| -> Vec<u64> {
        let mut all = vec![sol.cost.to_bits(), sol.expected_cost.to_bits()];
        for v in sol
            .u
            .iter()
            .map(|u| u.as_slice())
            .chain(sol.gains.iter().map(|g| g.as_slice()))
        {
            all.extend(v.iter().map(|e| e.to_bits()));
        }
        all
    };
    let mut options = s.solver.options.clone();
    options.max_iterations = 4;
    let fresh = Ilqg::new(&plain, options.clone()).solve(&plain, &setup.u_init);
    let mut reused = Ilqg::new(&plain, options);
    let first = reused.solve(&other, &setup.u_init);
    assert_ne!(
        bits(&first),
        bits(&fresh),
        "the other plant must plan differently"
    );
    let again = reused.solve(&plain, &setup.u_init);
    assert!(fresh.iterations >= 2, "the solve must relinearise");
    assert_eq!(bits(&again), bits(&fresh));
}
