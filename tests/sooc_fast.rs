//! The fast SOOC solver ([`SoocFastSolver`]: exact gradient by the covariance adjoint, projected
//! Newton–CG steps): its gradient against finite differences of the open-loop expected cost, its
//! optima against the exact stagewise Newton solver's, and its verdict against its criterion.

use nalgebra::DVector;
use std::path::Path;
use vic_core::dynamics::Dynamics;
use vic_core::solver::Solution;
use vic_core::solver::sooc::{MomentCost, MomentDynamics};
use vic_core::solver::sooc_fast::{SoocFastOptions, SoocFastSolver};
use vic_core::solver::sooc_newton::{Optimality, SoocProblem, SoocStop};
use vic_plan::plan::{Setup, plan_sooc, plan_sooc_fast, predict_open_loop, setup};
use vic_plan::scenario::Scenario;

fn scenario(stem: &str) -> (Scenario, Setup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(format!("{stem}.toml"));
    let s = Scenario::load(&path, &[]).expect("scenario loads");
    let setup = setup(&s).expect("scenario sets up");
    (s, setup)
}

/// `u_init` with every stiffness set to `k` and the torques moved off 0 by a smooth pattern, so
/// that every control has a gradient of its own.
fn start(s: &Scenario, setup: &Setup, k: f64) -> Vec<DVector<f64>> {
    let dof = s.model.dof();
    let off = s.model.actuator.stiffness_offset(dof);
    setup
        .u_init
        .iter()
        .enumerate()
        .map(|(t, u)| {
            let mut u = u.clone();
            for i in 0..dof {
                u[i] += 0.3 * ((0.05 * t as f64) + i as f64).sin();
                if let Some(off) = off {
                    u[off + i] = k * (1.0 + 0.2 * (0.03 * t as f64 + i as f64).cos());
                }
            }
            setup.bounds.clamp(u.as_mut_slice());
            u
        })
        .collect()
}

/// The solver's exact gradient against central differences of the open-loop expected cost
/// ([`predict_open_loop`], the covariance rollout every plan reports), every 5th knot, every
/// control, relative to the largest gradient component.
fn gradient_matches_finite_differences(stem: &str) {
    let (s, setup) = scenario(stem);
    let mut u = start(&s, &setup, s.initial_stiffness);
    let moments = MomentDynamics::new(&setup.dynamics);
    let cost = MomentCost::new(&setup.cost, u.len());
    let problem = SoocProblem {
        dynamics: &moments,
        cost: &cost,
        x0: &setup.x0,
        bounds: &setup.bounds,
        horizon: u.len(),
    };
    let mut solver = SoocFastSolver::new(&moments, u.len(), SoocFastOptions::default());
    let grad = solver.gradient(&problem, &u).expect("gradient").to_vec();
    let largest = grad.iter().map(|g| g.amax()).fold(0.0, f64::max);
    assert!(largest > 0.0);
    let (mut worst, mut checked) = (0.0_f64, 0);
    for k in (0..u.len()).step_by(5) {
        for i in 0..setup.dynamics.nu() {
            let v = u[k][i];
            let h = 1e-6 * (1.0 + v.abs());
            u[k][i] = v + h;
            let plus = predict_open_loop(&setup, &u).expected_cost;
            u[k][i] = v - h;
            let minus = predict_open_loop(&setup, &u).expected_cost;
            u[k][i] = v;
            let fd = (plus - minus) / (2.0 * h);
            let err = (fd - grad[k][i]).abs() / largest;
            worst = worst.max(err);
            checked += 1;
            assert!(
                err < 1e-5,
                "{stem}: ∂J/∂u[{k}][{i}] = {:e}, finite differences {fd:e}",
                grad[k][i]
            );
        }
    }
    eprintln!("{stem}: {checked} components, worst error {worst:.2e} of the largest {largest:.3e}");
}

#[test]
fn sooc_fast_gradient_matches_finite_differences_on_the_divergent_arm() {
    gradient_matches_finite_differences("two_link_divergent");
}

#[test]
fn sooc_fast_gradient_matches_finite_differences_on_the_vsa_arm() {
    gradient_matches_finite_differences("two_link_vsa_divergent");
}

/// The exact Newton solver's plan and the fast one's, from the same start (what `vic plan
/// --method sooc` and `--method sooc-fast` make).
fn both(stem: &str) -> (Setup, Solution, Verdict, Solution, Verdict) {
    let (s, setup) = scenario(stem);
    let plain = setup.problem(s.task.steps);
    let (exact, ve) = plan_sooc(&s, &setup, &plain, &None).expect("exact plan");
    let (fast, vf) = plan_sooc_fast(&s, &setup, &plain, &None).expect("fast plan");
    eprintln!(
        "{stem}: exact J = {:.9e} ({:?}, {} iterations, {:.1} ms); fast J = {:.9e} ({:?}, {} \
         iterations, {:.1} ms, {:?}); fast − exact = {:+.2e} of J",
        exact.expected_cost,
        ve.0,
        exact.iterations,
        exact.solve_time.as_secs_f64() * 1e3,
        fast.expected_cost,
        vf.0,
        fast.iterations,
        fast.solve_time.as_secs_f64() * 1e3,
        vf.1,
        (fast.expected_cost - exact.expected_cost) / exact.expected_cost
    );
    (setup, exact, ve, fast, vf)
}

type Verdict = (SoocStop, Optimality);

/// The fast plan is as good as the exact optimum (within 0.05 % of its expected cost, or lower),
/// its cost is its controls' open-loop expected cost, its controls lie in the box, and it says
/// `Converged` exactly when its stated criterion passed.
fn as_good_as_the_exact_optimum(stem: &str) {
    let (setup, exact, _, fast, (stop, optimality)) = both(stem);
    let j = predict_open_loop(&setup, &fast.u).expected_cost;
    assert!(
        (j - fast.expected_cost).abs() <= 1e-12 * j,
        "{stem}: {j} vs {}",
        fast.expected_cost
    );
    assert!(
        fast.expected_cost <= exact.expected_cost * (1.0 + 5e-4),
        "{stem}: fast J = {} against the exact optimum's {}",
        fast.expected_cost,
        exact.expected_cost
    );
    let (lo, hi) = (&setup.bounds.lower, &setup.bounds.upper);
    for (k, u) in fast.u.iter().enumerate() {
        for i in 0..u.len() {
            assert!(
                lo[i] <= u[i] && u[i] <= hi[i],
                "{stem}: u[{k}][{i}] outside the box"
            );
        }
    }
    assert_eq!(
        stop == SoocStop::Converged,
        optimality.met(),
        "{stem}: {stop:?} with {optimality:?}"
    );
}

#[test]
fn sooc_fast_reaches_the_exact_optimum_on_the_divergent_arm() {
    as_good_as_the_exact_optimum("two_link_divergent");
}

#[test]
#[ignore = "issue 61: on the VSA arm the Newton–CG steps stay above the exact optimum (about 1 % \
            after the iteration limit); the exact solver is the reference there"]
fn sooc_fast_reaches_the_exact_optimum_on_the_vsa_arm() {
    as_good_as_the_exact_optimum("two_link_vsa_divergent");
}

#[test]
fn sooc_fast_reaches_the_exact_optimum_on_the_torque_only_arm() {
    as_good_as_the_exact_optimum("two_link_torque_divergent");
}

#[test]
fn sooc_fast_reaches_the_exact_optimum_on_the_curl_field_arm() {
    as_good_as_the_exact_optimum("two_link_curl");
}

/// Time of one exact gradient (the covariance adjoint's pass: `O(n³)` per knot) against the
/// moment dimension `n + n(n+1)/2` of the single joint, the two-link arm and the VSA arm, median
/// of 5, with the log–log slope printed. A measurement, not a check: run with `--ignored`.
#[test]
#[ignore = "a timing measurement (issue 61): cargo test --release --test offline -- --ignored \
            sooc_fast_gradient_time"]
fn sooc_fast_gradient_time_against_the_moment_dimension() {
    let mut points = Vec::new();
    for stem in ["icub_elbow", "two_link_divergent", "two_link_vsa_divergent"] {
        let (s, setup) = scenario(stem);
        let u = start(&s, &setup, s.initial_stiffness);
        let moments = MomentDynamics::new(&setup.dynamics);
        let cost = MomentCost::new(&setup.cost, u.len());
        let problem = SoocProblem {
            dynamics: &moments,
            cost: &cost,
            x0: &setup.x0,
            bounds: &setup.bounds,
            horizon: u.len(),
        };
        let mut solver = SoocFastSolver::new(&moments, u.len(), SoocFastOptions::default());
        let mut times: Vec<f64> = (0..5)
            .map(|_| {
                let t = std::time::Instant::now();
                let g = solver.gradient(&problem, &u).expect("gradient");
                assert!(g.iter().all(|v| v.iter().all(|x| x.is_finite())));
                t.elapsed().as_secs_f64()
            })
            .collect();
        times.sort_by(f64::total_cmp);
        let n = setup.dynamics.nx();
        let nz = n + n * (n + 1) / 2;
        let per_knot = times[2] / u.len() as f64;
        eprintln!(
            "{stem}: n = {n}, moment dimension {nz}, gradient {:.3} ms, {:.2} µs per knot",
            times[2] * 1e3,
            per_knot * 1e6
        );
        points.push((n as f64, nz as f64, per_knot));
    }
    let slope = |x: fn(&(f64, f64, f64)) -> f64| {
        let (a, b) = (&points[0], &points[points.len() - 1]);
        (b.2 / a.2).ln() / (x(b) / x(a)).ln()
    };
    eprintln!(
        "log-log slope of the gradient's time per knot: {:.2} against the moment dimension, {:.2} \
         against n",
        slope(|p| p.1),
        slope(|p| p.0)
    );
}
