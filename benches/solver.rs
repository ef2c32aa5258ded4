//! Solver benchmarks: `cargo bench --bench solver`.
//!
//! Each case is solved once up front to print its iteration count, so the time per iteration can
//! be read off criterion's time per solve. Crocoddyl on the same reach and box reach is timed in
//! the same run by `scripts/bench_peers.sh`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::Path;
use vic_core::delay::{Delayed, DelayedPlanner, Offset};
use vic_core::replan::{ReplanOptions, Replanner};
use vic_core::solver::sooc::{MomentCost, MomentDynamics};
use vic_core::solver::sooc_newton::{SoocProblem, SoocSolver};
use vic_core::solver::{Ilqg, IlqgOptions, Problem, Solution};
use vic_plan::method::Method;
use vic_plan::plan::{self, Setup};
use vic_plan::receding::{TAIL_SHARE, TailFirst};
use vic_plan::scenario::Scenario;

fn load(file: &str, overrides: &[&str]) -> (Scenario, Setup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file);
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let s = Scenario::load(&path, &o).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    (s, setup)
}

/// ILQG on a scenario's plant as `vic plan --method ilqg` solves it (without a delay): a
/// stochastic scenario in two phases, the deterministic problem and then the stochastic one from
/// its optimum ([`plan::solve_in_phases`]; from the first guess directly the single joint's
/// stochastic solve stops at its iteration limit), on one reused workspace and one reused
/// `Solution` per phase, as Crocoddyl keeps its trajectory in the solver.
fn bench_plain(c: &mut Criterion, name: &str, file: &str, overrides: &[&str]) {
    let (s, setup) = load(file, overrides);
    let problem = setup.problem(s.task.steps);
    let options = s.solver.options.clone();
    let phases = options.stochastic && problem.dynamics.nw() > 0;
    let deterministic = IlqgOptions {
        stochastic: false,
        ..options.clone()
    };
    let mut solver = Ilqg::new(&problem, options.clone());
    let solve = |solver: &mut Ilqg, first: &mut Solution, out: &mut Solution| {
        if phases {
            solver.options = deterministic.clone();
            solver
                .try_solve_held_first_into(&problem, &setup.u_init, first)
                .expect("solves");
            solver.options = options.clone();
            solver
                .try_solve_into(&problem, &first.u, out)
                .expect("solves");
        } else {
            solver
                .try_solve_held_first_into(&problem, &setup.u_init, out)
                .expect("solves");
        }
    };
    let (mut first, mut out) = (Solution::empty(), Solution::empty());
    solve(&mut solver, &mut first, &mut out);
    let iterations = out.iterations + if phases { first.iterations } else { 0 };
    let time = out.solve_time
        + if phases {
            first.solve_time
        } else {
            Default::default()
        };
    eprintln!(
        "{name}: {iterations} iterations{}, {:?}, {:.3} ms per iteration (single run)",
        if phases {
            format!(" ({} deterministic, then stochastic)", first.iterations)
        } else {
            String::new()
        },
        out.stop,
        time.as_secs_f64() * 1e3 / iterations.max(1) as f64
    );
    c.bench_function(name, |b| {
        b.iter(|| {
            solve(&mut solver, &mut first, &mut out);
            black_box(out.cost)
        })
    });
}

fn solvers(c: &mut Criterion) {
    // Absolute times are the host's: name it (a VM may move to another CPU between runs).
    eprintln!("machine: {}", vic::bench::Machine::detect().line());
    bench_plain(c, "two_link_reach_ddp", "two_link_reach.toml", &[]);
    bench_plain(
        c,
        "two_link_reach_box",
        "two_link_reach.toml",
        &["actuator.torque_limit=0.25"],
    );
    bench_plain(c, "two_link_divergent_ilqg", "two_link_divergent.toml", &[]);
    bench_plain(c, "single_joint_ilqg", "icub_elbow.toml", &[]);
    // The same two with the stiffness free from the first guess on (the baseline of
    // `Ilqg::try_solve_held_first`, measured in the same run).
    let free = ["solver.hold_stiffness_first=false"];
    bench_plain(
        c,
        "two_link_divergent_ilqg_free_stiffness",
        "two_link_divergent.toml",
        &free,
    );
    bench_plain(
        c,
        "single_joint_ilqg_free_stiffness",
        "icub_elbow.toml",
        &free,
    );

    // The single joint with a 200 ms delay, deterministic: the central process's replanning load.
    let (s, setup) = load("single_joint_delay.toml", &["noise.kind=none"]);
    let d = s.task.delay_steps();
    let delayed = Delayed::new(setup.dynamics.clone(), d);
    let nx = setup.x0.len();
    let cost = plan::DelayedCost::new(&setup.cost, nx);
    let problem = Problem {
        dynamics: &delayed,
        cost: &cost,
        x0: delayed.initial_state(&setup.x0, setup.u_init[0].as_slice()),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let plain = setup.problem(s.task.steps);
    // The whole plan (vic_core::delay::DelayedPlanner): the undelayed plant's plan from the
    // state the commands in flight lead to, then ILQG on the 42-dimensional delayed plant for
    // its gains.
    let mut planner = DelayedPlanner::new(&plain, &problem, &s.solver.options).expect("fits");
    let t0 = std::time::Instant::now();
    let sol = planner
        .solve(&plain, &problem, &setup.u_init)
        .expect("plans");
    eprintln!(
        "single_joint_delay_200ms: state {} dims, {} iterations on the undelayed plant, {} after it, {:.3} ms in all (single run), cost {:.10}",
        nx + d * setup.u_init[0].len(),
        sol.guess_iterations,
        sol.solution.iterations,
        t0.elapsed().as_secs_f64() * 1e3,
        sol.solution.cost
    );
    let mut group = c.benchmark_group("slow");
    group.sample_size(10);
    group.bench_function("single_joint_delay_200ms", |b| {
        b.iter(|| black_box(planner.solve(&plain, &problem, &setup.u_init)))
    });
    // Replanning: the plan advanced two knots (one 50 Hz central period at Δ = 10 ms is two);
    // the same horizon from there (reference read two knots later, its last knot held), from the
    // predicted state, warm from the shifted solution: by the planner (the undelayed plant warm,
    // then one pass on the delayed one) and, for comparison, by ILQG on the delayed plant alone.
    let (later_dynamics, later_cost) = (Offset::new(&delayed, 2), Offset::new(&cost, 2));
    let (later_plain, later_plain_cost) =
        (Offset::new(&setup.dynamics, 2), Offset::new(&setup.cost, 2));
    let x2 = sol.solution.x[2].as_slice().to_vec();
    let shifted = Problem {
        dynamics: &later_dynamics,
        cost: &later_cost,
        x0: x2.clone(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let shifted_plain = Problem {
        dynamics: &later_plain,
        cost: &later_plain_cost,
        x0: x2[..nx].to_vec(),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let warm = planner
        .resolve_shifted(&shifted_plain, &shifted, 2)
        .expect("replans");
    eprintln!(
        "single_joint_delay_200ms_warm: {} iterations on the undelayed plant, {} after, {:.3} ms (single run), cost {:.10}",
        warm.guess_iterations,
        warm.solution.iterations,
        warm.solution.solve_time.as_secs_f64() * 1e3,
        warm.solution.cost
    );
    group.bench_function("single_joint_delay_200ms_warm", |b| {
        b.iter_custom(|runs| {
            let mut timed = std::time::Duration::ZERO;
            for _ in 0..runs {
                // Back to the converged plan (not timed), then the shifted re-plan (timed).
                planner
                    .solve(&plain, &problem, &setup.u_init)
                    .expect("plans");
                let t = std::time::Instant::now();
                black_box(
                    planner
                        .resolve_shifted(&shifted_plain, &shifted, 2)
                        .expect("replans"),
                );
                timed += t.elapsed();
            }
            timed
        })
    });
    let mut alone = Ilqg::new(&problem, s.solver.options.clone());
    alone.try_solve(&problem, &sol.solution.u).expect("solves");
    let warm = alone.resolve_shifted(&shifted, 2).expect("warm start");
    eprintln!(
        "single_joint_delay_200ms_warm_augmented: {} iterations, {:.3} ms (single run), cost {:.10}",
        warm.iterations,
        warm.solve_time.as_secs_f64() * 1e3,
        warm.cost
    );
    group.bench_function("single_joint_delay_200ms_warm_augmented", |b| {
        b.iter_custom(|runs| {
            let mut timed = std::time::Duration::ZERO;
            for _ in 0..runs {
                alone.try_solve(&problem, &sol.solution.u).expect("solves");
                let t = std::time::Instant::now();
                black_box(alone.resolve_shifted(&shifted, 2).expect("warm start"));
                timed += t.elapsed();
            }
            timed
        })
    });

    // The same plan with the scenario's state-dependent noise (as `vic plan --method ilqg`
    // plans it): the undelayed tail problem, then stochastic ILQG on the 42-state plant from
    // its solution (issue 12's target row: ≤ 20 ms).
    let (s, setup) = load("single_joint_delay.toml", &[]);
    let delayed = Delayed::new(setup.dynamics.clone(), d);
    let cost = plan::DelayedCost::new(&setup.cost, nx);
    let problem = Problem {
        dynamics: &delayed,
        cost: &cost,
        x0: delayed.initial_state(&setup.x0, setup.u_init[0].as_slice()),
        horizon: s.task.steps,
        bounds: setup.bounds.clone(),
    };
    let plain = setup.problem(s.task.steps);
    let mut planner = DelayedPlanner::new(&plain, &problem, &s.solver.options).expect("fits");
    let sol = planner
        .solve(&plain, &problem, &setup.u_init)
        .expect("plans");
    eprintln!(
        "single_joint_delay_200ms_noise: {} iterations on the undelayed plant, {} stochastic on the 42-state plant, {:.3} ms (single run), expected cost {:.10}",
        sol.guess_iterations,
        sol.solution.iterations,
        sol.solution.solve_time.as_secs_f64() * 1e3,
        sol.solution.expected_cost
    );
    group.bench_function("single_joint_delay_200ms_noise", |b| {
        b.iter(|| black_box(planner.solve(&plain, &problem, &setup.u_init)))
    });
    // The central controller's load with noise (issue 12's "≤ 5 ms warm"): after the cold plan
    // (not timed), 30 replans at 50 Hz (two knots apart), each from the augmented state the
    // last plan's commands lead to; the time reported is a replan's, the sequence's mean.
    let (iterations, ms) = receding(&mut planner, &plain, &problem, &setup, &delayed, &cost);
    eprintln!(
        "single_joint_delay_200ms_noise_receding: {} stochastic iterations over {RECEDING} replans, {:.3} ms a replan (single run)",
        iterations,
        ms / RECEDING as f64
    );
    for cap in [None, Some(2)] {
        // Capped: a real-time iteration scheme (`DelayedPlanner::replan_iterations`).
        planner.replan_iterations = cap;
        let name = match cap {
            None => "single_joint_delay_200ms_noise_receding".to_string(),
            Some(c) => format!("single_joint_delay_200ms_noise_receding_capped{c}"),
        };
        group.bench_function(name, |b| {
            b.iter_custom(|runs| {
                let mut timed = std::time::Duration::ZERO;
                for _ in 0..runs {
                    let (_, ms) = receding(&mut planner, &plain, &problem, &setup, &delayed, &cost);
                    timed += std::time::Duration::from_secs_f64(ms / 1e3 / RECEDING as f64);
                }
                timed
            })
        });
    }
    planner.replan_iterations = None;

    // SOOC at full noise from the configured warm start, capped at a few iterations: the cost of
    // one iteration on the moment dynamics (z = (m, vech P): 14 dims for the type-2 arm, 44 for
    // the VSA).
    for (name, file, cap) in [
        (
            "two_link_divergent_sooc_10it",
            "two_link_divergent.toml",
            10,
        ),
        ("two_link_vsa_sooc_3it", "two_link_vsa_divergent.toml", 3),
    ] {
        let (s, setup) = load(file, &[]);
        let mut section = s.solver.clone();
        section.options.max_iterations = cap;
        section.noise_continuation = vec![1.0];
        let sol = plan::solve_sooc(&setup, &section, &setup.u_init, &None)
            .expect("SOOC solves")
            .solution;
        eprintln!(
            "{name}: {} iterations, expected cost {:.6}, {:.3} ms per iteration",
            sol.iterations,
            sol.expected_cost,
            sol.solve_time.as_secs_f64() * 1e3 / sol.iterations.max(1) as f64
        );
        group.bench_function(name, |b| {
            b.iter(|| black_box(plan::solve_sooc(&setup, &section, &setup.u_init, &None)))
        });
    }
    sooc_targets(&mut group);
    group.finish();
}

/// The two SOOC targets of the solver issue on the type-2 arm in the divergent field (N = 100):
/// the cold plan as `vic plan --method sooc` makes it ([`plan::plan_sooc`]: the deterministic
/// optimum as first guess, then the scenario's options and continuation), and the receding-horizon re-solve one 50 Hz period later,
/// from the plan's mean at knot 2 with the plan shifted by 2 knots as its warm start, run to
/// the same convergence test: over a horizon of the same length (the last control held), and
/// over the remaining movement as the central controller's replanner solves it.
fn sooc_targets(group: &mut criterion::BenchmarkGroup<criterion::measurement::WallTime>) {
    let (s, setup) = load("two_link_divergent.toml", &[]);
    let plain = setup.problem(s.task.steps);
    let (cold, (stop, _)) = plan::plan_sooc(&s, &setup, &plain, &None).expect("SOOC solves");
    eprintln!(
        "two_link_divergent_sooc_cold: {stop:?}, {} iterations, {:.1} ms (single run)",
        cold.iterations,
        cold.solve_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_cold", |b| {
        b.iter(|| black_box(plan::plan_sooc(&s, &setup, &plain, &None)))
    });
    // The same plan with one Rosenbrock step per knot instead of ten semi-implicit sub-steps
    // (`task.integrator = "rosenbrock"`, `substeps = 1`): every flow derivative a tenth as long.
    let (s_ros, setup_ros) = load(
        "two_link_divergent.toml",
        &["task.integrator=rosenbrock", "task.substeps=1"],
    );
    let plain_ros = setup_ros.problem(s_ros.task.steps);
    let (ros, (stop, _)) =
        plan::plan_sooc(&s_ros, &setup_ros, &plain_ros, &None).expect("SOOC solves");
    eprintln!(
        "two_link_divergent_sooc_cold_rosenbrock: {stop:?}, {} iterations, {:.1} ms (single run)",
        ros.iterations,
        ros.solve_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_cold_rosenbrock", |b| {
        b.iter(|| black_box(plan::plan_sooc(&s_ros, &setup_ros, &plain_ros, &None)))
    });
    // Its deterministic first phase with the stiffness free from the first guess on.
    let (s_free, setup_free) = load(
        "two_link_divergent.toml",
        &["solver.hold_stiffness_first=false"],
    );
    let plain_free = setup_free.problem(s_free.task.steps);
    group.bench_function("two_link_divergent_sooc_cold_free_stiffness", |b| {
        b.iter(|| black_box(plan::plan_sooc(&s_free, &setup_free, &plain_free, &None)))
    });

    // The plan as the warm start, moved along with everything else.
    let shift = 2;
    let planned = Setup {
        u_init: cold.u.clone(),
        ..setup.clone()
    };
    let next = planned.shifted(shift, cold.x[shift].as_slice());
    let warm = &next.u_init;
    let horizon = warm.len();
    let moments = MomentDynamics::new(&next.dynamics);
    let cost = MomentCost::new(&next.cost, horizon);
    let problem = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &next.x0,
        bounds: &next.bounds,
        horizon,
    };
    // `solve` from the shifted controls is `resolve_shifted` without the state it keeps between
    // calls, so every sample starts from the same point.
    let mut solver = SoocSolver::new(&moments, horizon, s.solver.sooc_options());
    let sol = solver.solve(&problem, warm).expect("re-solves");
    eprintln!(
        "two_link_divergent_sooc_warm_shift2: {:?}, {} iterations, {:.1} ms (single run)",
        sol.stop,
        sol.iterations,
        sol.solve_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_warm_shift2", |b| {
        b.iter(|| black_box(solver.solve(&problem, warm)))
    });

    // The same re-solve with the last 30 % of the horizon solved alone first
    // (`vic_plan::receding`), on workspaces kept between samples.
    let mut tail_first = TailFirst::new(&next, horizon, TAIL_SHARE, s.solver.sooc_options());
    let r = tail_first.resolve(&next, warm).expect("re-solves");
    eprintln!(
        "two_link_divergent_sooc_warm_shift2_tail_first: {:?}, {} + {} iterations, {:.1} ms (single run)",
        r.solution.stop,
        r.tail_iterations,
        r.solution.iterations,
        r.total_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_warm_shift2_tail_first", |b| {
        b.iter(|| black_box(tail_first.resolve(&next, warm)))
    });

    // What the central controller's replanner solves at that moment: the remaining 98 knots from
    // the mean at knot 2 (believed exact), warm-started with the plan's tail.
    let rest = planned.remaining(shift, cold.x[shift].as_slice());
    let tail = &rest.u_init;
    let moments = MomentDynamics::new(&rest.dynamics);
    let cost = MomentCost::new(&rest.cost, tail.len());
    let problem = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &rest.x0,
        bounds: &rest.bounds,
        horizon: tail.len(),
    };
    let mut solver = SoocSolver::new(&moments, tail.len(), s.solver.sooc_options());
    let sol = solver.solve(&problem, tail).expect("re-solves");
    eprintln!(
        "two_link_divergent_sooc_remaining: {:?}, {} iterations, {:.1} ms (single run)",
        sol.stop,
        sol.iterations,
        sol.solve_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_remaining", |b| {
        b.iter(|| black_box(solver.solve(&problem, tail)))
    });

    // The same re-solve by `resolve_remaining` on the workspace that solved the whole movement,
    // its last point the plan (each sample's workspace prepared untimed): from the plan's own
    // mean it meets that point again at every knot and carries the flow's third derivatives
    // there, to the same bits.
    let whole_moments = MomentDynamics::new(&setup.dynamics);
    let whole_cost = MomentCost::new(&setup.cost, s.task.steps);
    let whole = SoocProblem {
        dynamics: &whole_moments,
        cost: &whole_cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon: s.task.steps,
    };
    let at_plan = || {
        let mut w = SoocSolver::new(&whole_moments, s.task.steps, s.solver.sooc_options());
        w.solve(&whole, &cold.u).expect("solves at the plan");
        w
    };
    let sol = at_plan()
        .resolve_remaining(&problem, shift)
        .expect("re-solves");
    eprintln!(
        "two_link_divergent_sooc_remaining_carried: {:?}, {} iterations, {} knots carried, \
         {:.1} ms (single run)",
        sol.stop,
        sol.iterations,
        sol.carried_third,
        sol.solve_time.as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_sooc_remaining_carried", |b| {
        b.iter_batched(
            at_plan,
            |mut w| {
                let sol = w.resolve_remaining(&problem, shift);
                (w, black_box(sol))
            },
            criterion::BatchSize::PerIteration,
        )
    });

    // The live replanner's own re-solve at that knot (`Replanner::replan_from` with its 50 Hz
    // defaults: at most 3 Newton steps, no third derivatives): what a central period must fit.
    let file = plan::plan(&s, Method::Sooc, None).expect("plans");
    let policy = file.policy(&setup).expect("policy");
    let options = ReplanOptions::at_50_hz(setup.dynamics.dt);
    let mut replanner = Replanner::new(&policy, &setup.dynamics, &setup.cost, options);
    let x2: Vec<f64> = policy.nominal[shift].iter().copied().collect();
    let t = std::time::Instant::now();
    let outcome = replanner.replan_from(shift, &x2);
    eprintln!(
        "two_link_divergent_replan_knot2: {outcome:?}, {} iterations, {:.1} ms (single run)",
        replanner.stats.iterations,
        t.elapsed().as_secs_f64() * 1e3
    );
    group.bench_function("two_link_divergent_replan_knot2", |b| {
        b.iter(|| {
            replanner.reset();
            black_box(replanner.replan_from(shift, &x2))
        })
    });
}

/// Replans in the receding sequence of `single_joint_delay_200ms_noise_receding`.
const RECEDING: usize = 30;

/// A cold plan, then [`RECEDING`] replans two knots apart, each from the augmented state the
/// last plan's commands lead to: the stochastic iterations and milliseconds of the replans.
fn receding(
    planner: &mut DelayedPlanner,
    plain: &Problem,
    problem: &Problem,
    setup: &Setup,
    delayed: &Delayed<vic_core::dynamics::DiscreteDynamics>,
    cost: &plan::DelayedCost,
) -> (usize, f64) {
    use vic_core::dynamics::Dynamics;
    let shift = 2;
    let cold = planner.solve(plain, problem, &setup.u_init).expect("plans");
    let (mut u, mut z, mut at) = (cold.solution.u, problem.x0.clone(), 0);
    let (mut iterations, mut ms) = (0, 0.0);
    let nx = plain.x0.len();
    for _ in 0..RECEDING {
        for (k, uk) in u.iter().enumerate().take(shift) {
            let mut next = vec![0.0; z.len()];
            delayed.step(at + k, &z, uk.as_slice(), &mut next);
            z = next;
        }
        at += shift;
        let (dynamics, later_cost) = (Offset::new(delayed, at), Offset::new(cost, at));
        let (plain_dynamics, plain_cost) = (
            Offset::new(&setup.dynamics, at),
            Offset::new(&setup.cost, at),
        );
        let shifted = Problem {
            dynamics: &dynamics,
            cost: &later_cost,
            x0: z.clone(),
            horizon: problem.horizon,
            bounds: problem.bounds.clone(),
        };
        let shifted_plain = Problem {
            dynamics: &plain_dynamics,
            cost: &plain_cost,
            x0: z[..nx].to_vec(),
            horizon: problem.horizon,
            bounds: problem.bounds.clone(),
        };
        let t = std::time::Instant::now();
        let warm = planner
            .resolve_shifted(&shifted_plain, &shifted, shift)
            .expect("replans");
        ms += t.elapsed().as_secs_f64() * 1e3;
        iterations += warm.solution.iterations;
        u = warm.solution.u;
    }
    (iterations, ms)
}

/// The scaling benchmark of the SOOC iteration (`vic bench sooc` prints the log–log slopes): one
/// pass over the horizon of the plant's linearisation (ILQG's model), of the moment step's first
/// derivatives (every SOOC iteration), and of the exact Newton model (first derivatives with the
/// flow's third, then the costate-contracted second derivatives), along the first guess, on
/// moment dimensions 5, 14 and 44.
fn sooc_scaling(c: &mut Criterion) {
    use vic::bench::sooc_scaling::Knots;
    let mut group = c.benchmark_group("sooc_scaling");
    for file in [
        "icub_elbow.toml",
        "two_link_divergent.toml",
        "two_link_vsa_divergent.toml",
    ] {
        let (s, setup) = load(file, &[]);
        let horizon = s.task.steps;
        let mut knots = Knots::new(&setup, horizon);
        let stem = file.trim_end_matches(".toml");
        let nz = knots.moment_dim();
        group.bench_function(format!("nominal/nz{nz}_{stem}"), |b| {
            b.iter(|| (0..horizon).for_each(|k| knots.nominal(k)))
        });
        group.bench_function(format!("first/nz{nz}_{stem}"), |b| {
            b.iter(|| (0..horizon).for_each(|k| knots.first(k)))
        });
        group.bench_function(format!("newton/nz{nz}_{stem}"), |b| {
            b.iter(|| (0..horizon).for_each(|k| knots.newton(k)))
        });
    }
    group.finish();
}

criterion_group!(benches, solvers, sooc_scaling);
criterion_main!(benches);
