//! The solvers' kernels compiled for AVX2 (chosen at run time, `vic_core::wide`) compute the
//! portable kernels' numbers to the bit: on every scenario of `config/`, the ILQG plan (and with a
//! feedback delay the delayed planner's) is solved with the wide kernels forbidden and then
//! allowed, and every state, control, gain, cost and the iteration count must agree bit for bit;
//! so must the SOOC plans (whose Taylor-polynomial flows the AVX2 step carries) of the iCub elbow
//! and the arm in the divergent field (the VSA arms' take too long for every test run).
//! A rounding that differed in one knot would show: the stochastic plans' optima are flat, and a
//! changed rounding moves their costs in the third digit (see `tests/ilqg_phases.rs`).
//!
//! On a CPU without AVX2 both runs take the portable kernels and the test cannot fail; it says
//! so on stderr. The CI machines have AVX2.

use std::path::Path;
use vic_core::delay::DelayedPlanner;
use vic_core::solver::{Ilqg, Solution};
use vic_core::wide;
use vic_plan::plan;
use vic_plan::scenario::Scenario;

/// Every number of a solution, as bits.
fn bits(s: &Solution) -> Vec<u64> {
    let knots = s.x.iter().chain(&s.u).flat_map(|v| v.iter().copied());
    let gains = s.gains.iter().flat_map(|g| g.iter().copied());
    knots
        .chain(gains)
        .chain([s.cost, s.expected_cost])
        .chain(s.history.iter().copied())
        .map(f64::to_bits)
        .chain([s.iterations as u64])
        .collect()
}

/// The SOOC plan (`vic plan --method sooc`) of the scenario `file` as `bits`, with the wide
/// kernels allowed or not.
fn solve_sooc(file: &Path, allow_wide: bool) -> Vec<u64> {
    wide::set_enabled(allow_wide);
    let s = Scenario::load(file, &[]).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let plain = setup.problem(s.task.steps);
    let (solution, _) = plan::plan_sooc(&s, &setup, &plain, &None).expect("plans");
    bits(&solution)
}

/// The ILQG plan of the scenario `file` as `bits`, with the wide kernels allowed or not.
fn solve(file: &Path, allow_wide: bool) -> Vec<u64> {
    wide::set_enabled(allow_wide);
    let s = Scenario::load(file, &[]).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let (steps, d) = (s.task.steps, s.task.delay_steps());
    let plain = setup.problem(steps);
    if d == 0 {
        let mut solver = Ilqg::new(&plain, s.solver.options.clone());
        bits(&solver.solve(&plain, &setup.u_init))
    } else {
        let delayed = setup.delayed(d);
        let problem = delayed.problem(steps);
        let mut planner =
            DelayedPlanner::new(&plain, &problem, &s.solver.options).expect("planner builds");
        let plan = planner
            .solve(&plain, &problem, &setup.u_init)
            .expect("plans");
        bits(&plan.solution)
    }
}

#[test]
fn the_wide_kernels_compute_the_portable_ones_bits() {
    if !wide::available() {
        eprintln!("this CPU has no AVX2: both runs take the portable kernels");
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("config/ lists")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 10, "the scenarios of config/");
    let sooc = ["icub_elbow.toml", "two_link_divergent.toml"];
    let runs = files
        .iter()
        .map(|f| (f.clone(), "ILQG", solve as fn(&Path, bool) -> Vec<u64>))
        .chain(sooc.map(|f| {
            (
                dir.join(f),
                "SOOC",
                solve_sooc as fn(&Path, bool) -> Vec<u64>,
            )
        }));
    for (file, method, solve) in runs {
        let file = &file;
        let portable = solve(file, false);
        let wide = solve(file, true);
        assert_eq!(
            portable.len(),
            wide.len(),
            "{} ({method}): plan sizes differ",
            file.display()
        );
        let first = portable.iter().zip(&wide).position(|(p, w)| p != w);
        assert_eq!(
            first,
            None,
            "{} ({method}): first differing number",
            file.display()
        );
    }
    wide::set_enabled(true);
}
