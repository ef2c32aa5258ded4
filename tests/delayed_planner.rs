//! The delayed plant planned through the undelayed one ([`DelayedPlanner`]): cold, it is the
//! undelayed guess followed by ILQG on the augmented plant (the same commands, and gains from the
//! prediction that agree with the augmented backward pass); warm, after the plan advanced, it
//! reaches the optimum that ILQG on the augmented plant finds from scratch, with fewer iterations
//! on the tail problem than a cold plan; wrong problems are errors.

use nalgebra::DVector;
use std::path::Path;
use vic_core::cost::{Cost, CostDerivatives, TrackingCost};
use vic_core::delay::{Delayed, DelayedPlanner, Offset};
use vic_core::dynamics::{DiscreteDynamics, Dynamics, Linearization};
use vic_core::solver::{Ilqg, IlqgError, IlqgOptions, Problem, StopReason};
use vic_plan::plan::{self, DelayedCost, Setup};
use vic_plan::scenario::Scenario;

/// The single joint with its 200 ms delay, its plan setup and its augmented plant.
fn load(overrides: &[&str]) -> (Scenario, Setup, Delayed<DiscreteDynamics>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let s = Scenario::load(&path, &o).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let delayed = Delayed::new(setup.dynamics.clone(), s.task.delay_steps());
    (s, setup, delayed)
}

/// The plant, its cost, the augmented plant and its cost, read some knots late.
type At<'a> = (
    Offset<'a, DiscreteDynamics>,
    Offset<'a, TrackingCost>,
    Offset<'a, Delayed<DiscreteDynamics>>,
    Offset<'a, DelayedCost<'a>>,
);

/// The problems' parts read `k` knots late.
fn at<'a>(
    setup: &'a Setup,
    delayed: &'a Delayed<DiscreteDynamics>,
    cost: &'a DelayedCost<'a>,
    k: usize,
) -> At<'a> {
    (
        Offset::new(&setup.dynamics, k),
        Offset::new(&setup.cost, k),
        Offset::new(delayed, k),
        Offset::new(cost, k),
    )
}

/// The undelayed and the augmented problem, both read `offset` knots late, from `x0` (the
/// augmented state: the plant's state and the commands in flight).
fn problems<'a>(
    s: &Scenario,
    setup: &Setup,
    offsets: &'a At<'a>,
    x0: &[f64],
) -> (Problem<'a>, Problem<'a>) {
    let n = setup.x0.len();
    let plain = Problem {
        dynamics: &offsets.0,
        cost: &offsets.1,
        x0: x0[..n].to_vec(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let augmented = Problem {
        dynamics: &offsets.2,
        cost: &offsets.3,
        x0: x0.to_vec(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    (plain, augmented)
}

/// The undelayed first guess for the augmented plant, the commands in flight the scenario's
/// first.
fn guess(setup: &Setup, plain: &Problem, d: usize, options: &IlqgOptions) -> Vec<DVector<f64>> {
    vic_core::delay::undelayed_guess(plain, setup.u_init[0].as_slice(), d, options, &setup.u_init)
        .expect("guess")
}

#[test]
fn cold_and_warm_plans_reach_the_augmented_plants_optimum() {
    let (s, setup, delayed) = load(&["noise.kind=none"]);
    let (d, n) = (s.task.delay_steps(), setup.x0.len());
    let cost = DelayedCost::new(&setup.cost, n);
    let (start, later) = (
        at(&setup, &delayed, &cost, 0),
        at(&setup, &delayed, &cost, 2),
    );
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, augmented) = problems(&s, &setup, &start, &x0);
    let options = &s.solver.options;

    // Cold: the undelayed guess followed by ILQG on the augmented plant, which starts at its
    // optimum (no step), so the commands are the guess's to the bit; the planner's gains come
    // from the undelayed gains and the prediction's Jacobian, the reference's from the
    // 42-dimensional backward pass.
    let mut planner = DelayedPlanner::new(&plain, &augmented, options).expect("sizes fit");
    assert_eq!(planner.delay(), d);
    let cold = planner
        .solve(&plain, &augmented, &setup.u_init)
        .expect("plans");
    let guess = guess(&setup, &plain, d, options);
    let mut full = Ilqg::new(&augmented, options.clone());
    let by_hand = full.try_solve(&augmented, &guess).expect("solves");
    assert_eq!(by_hand.iterations, 0, "{:?}", by_hand.stop);
    assert_eq!(cold.solution.u, by_hand.u);
    assert!((cold.solution.cost - by_hand.cost).abs() <= 1e-12 * by_hand.cost);
    for (a, b) in cold.solution.x.iter().zip(&by_hand.x) {
        assert!((a - b).amax() <= 1e-12 * b.amax().max(1.0));
    }
    let scale = by_hand.gains.iter().map(|g| g.amax()).fold(0.0, f64::max);
    let worst = (cold.solution.gains.iter().zip(&by_hand.gains))
        .map(|(a, b)| (a - b).amax())
        .fold(0.0, f64::max);
    println!("gains: largest {scale:.6e}, largest difference {worst:.3e}");
    assert!(scale > 1.0, "the reference has feedback to compare");
    assert!(worst <= 1e-8 * scale, "{worst:e} against {scale:e}");
    // The commands issued in the last d knots act after the horizon: no feedback on them.
    let last = &by_hand.gains[s.task.steps - d..];
    assert!(last.iter().all(|g| g.amax() == 0.0));
    assert!(cold.solution.stop.converged());

    // Warm, two knots on (one 50 Hz period), from the state the plan predicts there.
    let x2 = cold.solution.x[2].as_slice().to_vec();
    let (plain2, augmented2) = problems(&s, &setup, &later, &x2);
    let warm = planner
        .resolve_shifted(&plain2, &augmented2, 2)
        .expect("replans");
    let mut fresh = DelayedPlanner::new(&plain2, &augmented2, options).expect("sizes fit");
    let recold = fresh
        .solve(&plain2, &augmented2, &setup.u_init)
        .expect("plans");
    // The independent reference: ILQG on the augmented plant alone, from the scenario's guess
    // read d knots on (what the commands issued now act on).
    let naive: Vec<DVector<f64>> = (0..s.task.steps)
        .map(|k| setup.u_init[(k + d).min(s.task.steps - 1)].clone())
        .collect();
    let mut alone = Ilqg::new(&augmented2, options.clone());
    let reference = alone.try_solve(&augmented2, &naive).expect("solves");
    println!(
        "warm: {} tail it, {} it, cost {:.12e}; cold: {} tail it, cost {:.12e}; augmented alone: {} it, cost {:.12e}",
        warm.guess_iterations,
        warm.solution.iterations,
        warm.solution.cost,
        recold.guess_iterations,
        recold.solution.cost,
        reference.iterations,
        reference.cost
    );
    assert!(warm.solution.stop.converged() && reference.stop.converged());
    let rel = |a: f64, b: f64| (a - b).abs() / b;
    assert!(rel(warm.solution.cost, recold.solution.cost) < 1e-6);
    assert!(rel(warm.solution.cost, reference.cost) < 1e-5);
    assert!(warm.solution.cost <= reference.cost * (1.0 + 1e-9));
    assert!(
        warm.guess_iterations < recold.guess_iterations,
        "warm {} vs cold {} tail iterations",
        warm.guess_iterations,
        recold.guess_iterations
    );
}

/// With the scenario's noise, a warm replan two knots on re-solves the augmented plant from its
/// previous plan shifted ([`Ilqg::resolve_shifted`]): to the bit what ILQG on the augmented
/// plant alone does from the same plan (which the planner's first plan is, from the undelayed
/// guess), and not what a start from the new undelayed guess gives. Its expected cost is that
/// of a cold plan from the same state to within 1 % (the stochastic stops on this plant are
/// many nearly equal ones).
#[test]
fn with_noise_a_warm_replan_starts_from_the_last_plan_shifted() {
    let (s, setup, delayed) = load(&[]);
    let (d, n) = (s.task.delay_steps(), setup.x0.len());
    let cost = DelayedCost::new(&setup.cost, n);
    let (start, later) = (
        at(&setup, &delayed, &cost, 0),
        at(&setup, &delayed, &cost, 2),
    );
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, augmented) = problems(&s, &setup, &start, &x0);
    let options = &s.solver.options;
    assert!(options.stochastic && augmented.dynamics.nw() > 0);
    let mut planner = DelayedPlanner::new(&plain, &augmented, options).expect("sizes fit");
    let cold = planner
        .solve(&plain, &augmented, &setup.u_init)
        .expect("plans");
    let guess = guess(&setup, &plain, d, options);
    let mut alone = Ilqg::new(&augmented, options.clone());
    let first = alone.try_solve(&augmented, &guess).expect("solves");
    assert_eq!(
        first.u, cold.solution.u,
        "the first plan is ILQG's from the guess"
    );

    // Two knots on, from the augmented state the plan's commands lead to.
    let mut x2 = x0.clone();
    for k in 0..2 {
        let mut next = vec![0.0; x2.len()];
        delayed.step(k, &x2, cold.solution.u[k].as_slice(), &mut next);
        x2 = next;
    }
    let (plain2, augmented2) = problems(&s, &setup, &later, &x2);
    let warm = planner
        .resolve_shifted(&plain2, &augmented2, 2)
        .expect("replans");
    // The commands from knot N − d − 2 on start from the planner's new undelayed guess.
    let tail = &planner.guess()[s.task.steps - d - 2..];
    let reference = alone
        .resolve_shifted_with_tail(&augmented2, 2, tail)
        .expect("re-solves");
    assert_eq!(warm.solution.u, reference.u);
    assert_eq!(warm.solution.iterations, reference.iterations);
    let mut fresh = DelayedPlanner::new(&plain2, &augmented2, options).expect("sizes fit");
    let recold = fresh
        .solve(&plain2, &augmented2, &setup.u_init)
        .expect("plans");
    println!(
        "with noise, two knots on: warm {} iterations, E = {:.6}; cold {} + {} iterations, E = {:.6}",
        warm.solution.iterations,
        warm.solution.expected_cost,
        recold.guess_iterations,
        recold.solution.iterations,
        recold.solution.expected_cost
    );
    assert_ne!(
        warm.solution.u, recold.solution.u,
        "not the cold plan's start"
    );
    assert!(warm.solution.stop.converged());
    let gap = (warm.solution.expected_cost - recold.solution.expected_cost).abs();
    assert!(gap <= 0.01 * recold.solution.expected_cost, "{gap}");

    // Where the replan starts (no iterations: the shifted plan rolled out from x2). The first
    // plan left its last d commands at their control cost's minimum, since they act after its
    // horizon; shifted, the first two act within this one, and started from them the plant
    // ends off its target. From the undelayed guess it starts about where the first plan was.
    let start_of = |tail: &[DVector<f64>]| {
        let mut solver = Ilqg::new(&augmented, options.clone());
        solver.try_solve(&augmented, &guess).expect("solves");
        solver.options.max_iterations = 0;
        let start = solver
            .resolve_shifted_with_tail(&augmented2, 2, tail)
            .expect("re-solves");
        assert_eq!(start.iterations, 0);
        start.cost
    };
    let (unplanned, from_guess) = (start_of(&[]), start_of(tail));
    println!(
        "the replan's start: cost {unplanned:.6e} from the shifted plan alone, {from_guess:.6e} \
         with its last commands from the guess; the first plan {:.6e}",
        first.cost
    );
    assert!(
        from_guess <= 1.5 * first.cost,
        "{from_guess} against {}",
        first.cost
    );
    assert!(
        unplanned > 100.0 * first.cost,
        "{unplanned} against {}",
        first.cost
    );
}

#[test]
fn wrong_problems_and_a_replan_before_a_plan_are_errors() {
    let (s, setup, delayed) = load(&["noise.kind=none"]);
    let cost = DelayedCost::new(&setup.cost, setup.x0.len());
    let start = at(&setup, &delayed, &cost, 0);
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, augmented) = problems(&s, &setup, &start, &x0);
    // The plain problem twice: no commands in flight is not a delayed plant.
    assert!(matches!(
        DelayedPlanner::new(&plain, &plain, &s.solver.options),
        Err(IlqgError::SizeMismatch { .. })
    ));
    let mut planner = DelayedPlanner::new(&plain, &augmented, &s.solver.options).expect("fits");
    assert!(matches!(
        planner.resolve_shifted(&plain, &augmented, 2),
        Err(IlqgError::NoPreviousSolution)
    ));
    assert!(matches!(
        planner.solve(&plain, &augmented, &setup.u_init[1..]),
        Err(IlqgError::InitialGuessLength { .. })
    ));
    // An augmented state that is too short.
    let short = Problem {
        dynamics: augmented.dynamics,
        cost: augmented.cost,
        x0: x0[..x0.len() - 1].to_vec(),
        horizon: augmented.horizon,
        bounds: augmented.bounds.clone(),
    };
    assert!(matches!(
        planner.solve(&plain, &short, &setup.u_init),
        Err(IlqgError::SizeMismatch { .. })
    ));
}

/// The augmented plant with what it declares of its structure hidden: no state support (the
/// solver then reads its Jacobians' nonzeros everywhere, keeps whole value Hessians and reads
/// them in every row), and a cost that does not say where its Hessian lives. With a nonzero
/// `.1`, its `A` also has that in every entry the plant's is zero (approximate Jacobians,
/// for a workspace to hold entries where a plant with a support has none).
struct Hidden<'a>(&'a Delayed<DiscreteDynamics>, f64);

impl Dynamics for Hidden<'_> {
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
        self.0.step(k, x, u, next)
    }
    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut nalgebra::DMatrix<f64>) {
        self.0.noise_gain(k, x, u, out)
    }
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        self.0.linearize(k, x, u, lin);
        lin.a
            .iter_mut()
            .filter(|v| **v == 0.0)
            .for_each(|v| *v = self.1);
    }
}

struct HiddenCost<'a>(&'a DelayedCost<'a>);

impl Cost for HiddenCost<'_> {
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
    fn nonnegative(&self) -> bool {
        self.0.nonnegative()
    }
}

/// What the delayed plant and its cost declare of their structure (the shift register's unit
/// columns, the rows of the noise, the cost Hessian's support) only saves reads and writes: the
/// stochastic ILQG solve on the augmented plant with the noise is the solve without them, to
/// the bit (commands, gains, costs and iterations).
#[test]
fn the_declared_structure_changes_no_plan() {
    let (s, setup, delayed) = load(&[]);
    let n = setup.x0.len();
    let cost = DelayedCost::new(&setup.cost, n);
    assert!(cost.hessian_support().is_some());
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let plain = setup.problem(s.task.steps);
    let u0 = guess(&setup, &plain, delayed.steps(), &s.solver.options);
    let (hidden, hidden_cost) = (Hidden(&delayed, 0.0), HiddenCost(&cost));
    let solve = |dynamics: &dyn Dynamics, cost: &dyn Cost| {
        let problem = Problem {
            dynamics,
            cost,
            x0: x0.clone(),
            horizon: s.task.steps,
            bounds: setup.bounds.clone(),
        };
        let mut solver = Ilqg::new(&problem, s.solver.options.clone());
        let sol = solver.try_solve(&problem, &u0).expect("solves");
        let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let u: Vec<_> = sol.u.iter().flat_map(|u| bits(u.as_slice())).collect();
        let gains: Vec<_> = sol.gains.iter().flat_map(|g| bits(g.as_slice())).collect();
        (
            u,
            gains,
            sol.cost.to_bits(),
            sol.expected_cost.to_bits(),
            sol.iterations,
        )
    };
    let declared = solve(&delayed, &cost);
    assert!(declared.4 > 3, "{} iterations", declared.4);
    assert!(declared == solve(&hidden, &hidden_cost));
}

/// A workspace keeps its linearisations from one solve to the next when the plant declares the
/// same support (they are refilled, not cleared): a noisy solve on the augmented plant in a
/// workspace that last solved another plant with the same support (another forearm mass, read
/// some knots late), or the same problem, is the solve in a fresh workspace, to the bit; and so
/// is one after a plant that declares nothing.
#[test]
fn a_workspace_refilled_across_solves_gives_the_fresh_plans() {
    let (s, setup, delayed) = load(&[]);
    let (_, other_setup, other) = load(&["plant.mass=1.3"]);
    let n = setup.x0.len();
    let (cost, other_cost) = (
        DelayedCost::new(&setup.cost, n),
        DelayedCost::new(&other_setup.cost, n),
    );
    let late = (Offset::new(&other, 3), Offset::new(&other_cost, 3));
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let plain = setup.problem(s.task.steps);
    let u0 = guess(&setup, &plain, delayed.steps(), &s.solver.options);
    fn problem<'a>(
        (dynamics, cost): (&'a dyn Dynamics, &'a dyn Cost),
        x0: &[f64],
        s: &Scenario,
        setup: &Setup,
    ) -> Problem<'a> {
        Problem {
            dynamics,
            cost,
            x0: x0.to_vec(),
            horizon: s.task.steps,
            bounds: setup.bounds.clone(),
        }
    }
    let problem = |parts| problem(parts, &x0, &s, &setup);
    let (here, there) = (problem((&delayed, &cost)), problem((&late.0, &late.1)));
    let hidden = (Hidden(&other, 1e-6), HiddenCost(&other_cost));
    let elsewhere = problem((&hidden.0, &hidden.1));
    let bits = |sol: &vic_core::solver::Solution| {
        let mut all: Vec<u64> = sol
            .u
            .iter()
            .flat_map(|u| u.iter().map(|v| v.to_bits()))
            .collect();
        all.extend(sol.gains.iter().flat_map(|g| g.iter().map(|v| v.to_bits())));
        all.extend([
            sol.cost.to_bits(),
            sol.expected_cost.to_bits(),
            sol.iterations as u64,
        ]);
        all
    };
    let fresh = |p: &Problem| {
        let mut solver = Ilqg::new(p, s.solver.options.clone());
        bits(&solver.try_solve(p, &u0).expect("solves"))
    };
    let (want_here, want_there) = (fresh(&here), fresh(&there));
    assert_ne!(want_here, want_there);
    let mut solver = Ilqg::new(&here, s.solver.options.clone());
    for (p, want, what) in [
        (&here, &want_here, "first"),
        (
            &there,
            &want_there,
            "after another plant with the same support",
        ),
        (&here, &want_here, "again, after it"),
        (
            &elsewhere,
            &fresh(&elsewhere),
            "a plant that declares nothing",
        ),
        (&here, &want_here, "after that one"),
    ] {
        let got = bits(&solver.try_solve(p, &u0).expect("solves"));
        assert!(&got == want, "{what}");
    }
}

/// With noise the undelayed guess holds the impedance's stiffness at its lower limit on every
/// knot (the augmented solve re-plans it under the noise; see `delay::planner`'s
/// `tail_bounds`), where the free tail's optimum buys some; and the plan from the held guess is
/// as good as the plan from the free one: its expected cost within the stochastic stops' band
/// (1 %) of it or below. Without noise
/// nothing is held (`cold_and_warm_plans_reach_the_augmented_plants_optimum`: the plan is the
/// free tail's optimum).
#[test]
fn with_noise_the_guess_holds_the_stiffness_and_plans_as_well() {
    let (s, setup, delayed) = load(&[]);
    let (d, n) = (s.task.delay_steps(), setup.x0.len());
    let cost = DelayedCost::new(&setup.cost, n);
    let start = at(&setup, &delayed, &cost, 0);
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, augmented) = problems(&s, &setup, &start, &x0);
    let options = &s.solver.options;
    assert!(options.stochastic && augmented.dynamics.nw() > 0);
    let stiffness = options.held_first.clone();
    assert!(!stiffness.is_empty(), "the impedance's stiffness is named");

    let held = guess(&setup, &plain, d, options);
    let free = {
        let mut deterministic = options.clone();
        deterministic.stochastic = false;
        guess(&setup, &plain, d, &deterministic)
    };
    let at_lower = |u: &[DVector<f64>]| {
        u.iter()
            .all(|u| stiffness.iter().all(|&i| u[i] == setup.bounds.lower[i]))
    };
    assert!(
        at_lower(&held),
        "the held guess's stiffness leaves its lower limit"
    );
    assert!(
        !at_lower(&free),
        "the free tail's optimum buys no stiffness: nothing to compare"
    );

    let plan = |u: &[DVector<f64>]| {
        Ilqg::new(&augmented, options.clone())
            .try_solve(&augmented, u)
            .expect("solves")
    };
    let (from_held, from_free) = (plan(&held), plan(&free));
    println!(
        "from the held guess: {} iterations, E = {:.6}; from the free one: {} iterations, E = {:.6}",
        from_held.iterations,
        from_held.expected_cost,
        from_free.iterations,
        from_free.expected_cost
    );
    assert!(from_held.stop.converged() && from_free.stop.converged());
    assert!(
        from_held.expected_cost <= 1.01 * from_free.expected_cost,
        "{} against {}",
        from_held.expected_cost,
        from_free.expected_cost
    );
}

/// A receding sequence with noise: a cold plan, then `replans` replans two knots apart, each
/// from the augmented state the last plan's commands lead to; each replan's iterations, stop
/// and expected cost.
fn receding(cap: Option<usize>, replans: usize) -> Vec<(usize, StopReason, f64)> {
    let (s, setup, delayed) = load(&[]);
    let cost = DelayedCost::new(&setup.cost, setup.x0.len());
    let start = at(&setup, &delayed, &cost, 0);
    let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
    let (plain, augmented) = problems(&s, &setup, &start, &x0);
    let mut planner =
        DelayedPlanner::new(&plain, &augmented, &s.solver.options).expect("sizes fit");
    planner.replan_iterations = cap;
    let cold = planner
        .solve(&plain, &augmented, &setup.u_init)
        .expect("plans");
    let (mut u, mut z) = (cold.solution.u, x0);
    let mut out = Vec::new();
    for r in 0..replans {
        for (k, uk) in u.iter().enumerate().take(2) {
            let mut next = vec![0.0; z.len()];
            delayed.step(2 * r + k, &z, uk.as_slice(), &mut next);
            z = next;
        }
        let later = at(&setup, &delayed, &cost, 2 * (r + 1));
        let (plain, augmented) = problems(&s, &setup, &later, &z);
        let warm = planner
            .resolve_shifted(&plain, &augmented, 2)
            .expect("replans");
        let sol = warm.solution;
        out.push((sol.iterations, sol.stop, sol.expected_cost));
        u = sol.u;
    }
    out
}

/// Replans capped at two iterations (a real-time iteration scheme) never take more, stop
/// unconverged where the converged sequence needed more (its first replan after the cold
/// plan), and 30 replans (0.6 s at 50 Hz) later end where the converged replans end: the last
/// expected cost within 0.5 %.
#[test]
fn capped_replans_carry_their_iterations_forward() {
    let (replans, cap) = (30, 2);
    let free = receding(None, replans);
    let capped = receding(Some(cap), replans);
    println!("converged replans: {free:?}\ncapped at {cap}: {capped:?}");
    assert!(
        free[0].0 > cap,
        "the first converged replan needs more than the cap"
    );
    assert!(free.iter().all(|r| r.1.converged()));
    assert!(capped.iter().all(|r| r.0 <= cap));
    assert_eq!(capped[0].1, StopReason::MaxIterations);
    let (a, b) = (free[replans - 1].2, capped[replans - 1].2);
    assert!((a - b).abs() <= 5e-3 * a, "{a} against {b}");
}
