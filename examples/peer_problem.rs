//! vic's side of the Crocoddyl comparison (`scripts/bench_peers.sh`): builds the two-link reach of
//! `config/two_link_reach.toml` with the given `--set`-style overrides, solves it with ILQG `runs`
//! times, and prints the problem (start, reference per knot, weights, limits, initial guess, arm
//! parameters) with vic's timings and optimum as JSON, for `scripts/peer_crocoddyl.py` to
//! rebuild the same problem in Crocoddyl.
//!
//! `cargo run --release --example peer_problem -- NAME RUNS [KEY=VALUE ...]`

use std::path::Path;
use std::time::Instant;
use vic_core::model::Plant;
use vic_core::solver::Ilqg;
use vic_plan::plan;
use vic_plan::scenario::Scenario;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().cloned().unwrap_or_else(|| "reach".into());
    let runs: usize = args.get(1).and_then(|r| r.parse().ok()).unwrap_or(200);
    let overrides = args.get(2..).unwrap_or(&[]).to_vec();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/two_link_reach.toml");
    let s = Scenario::load(&path, &overrides).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    let Plant::TwoLink(arm) = &s.model.plant else {
        panic!("the peer problem is the two-link arm")
    };
    let problem = setup.problem(s.task.steps);
    let mut solver = Ilqg::new(&problem, s.solver.options.clone());
    solver.options.stochastic = false;
    let mut sol = solver.try_solve(&problem, &setup.u_init).expect("solves");
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        // Into the same `Solution` every time, as Crocoddyl's solver keeps its trajectory and
        // gains in its own storage: both sides time the solve, not the allocator.
        let t = Instant::now();
        solver
            .try_solve_into(&problem, &setup.u_init, &mut sol)
            .expect("solves");
        std::hint::black_box(&sol);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let reference = &setup.cost.reference;
    let out = serde_json::json!({
        "name": name,
        "overrides": overrides,
        "dt": s.task.dt,
        "horizon": s.task.steps,
        "integrator": format!("{:?}", setup.dynamics.integrator),
        "substeps": setup.dynamics.substeps,
        "arm": {"l1": arm.l1, "l2": arm.l2, "s2": arm.s2, "m2": arm.m2, "i1": arm.i1, "i2": arm.i2,
                "viscosity": arm.viscosity},
        "x0": setup.x0,
        "q_ref": reference.iter().map(|r| r.q_d).collect::<Vec<_>>(),
        "qd_ref": reference.iter().map(|r| r.qd_d).collect::<Vec<_>>(),
        "w_torque": setup.cost.control_weights,
        "w_p": setup.cost.w_p,
        "w_v": setup.cost.w_v,
        "lower": setup.bounds.lower.iter().map(|v| if v.is_finite() { *v } else { -1e300 }).collect::<Vec<_>>(),
        "upper": setup.bounds.upper.iter().map(|v| if v.is_finite() { *v } else { 1e300 }).collect::<Vec<_>>(),
        "u_init": setup.u_init.iter().map(|u| u.as_slice().to_vec()).collect::<Vec<_>>(),
        "vic": {
            "runs": runs,
            "median_ms": times[runs / 2],
            "min_ms": times[0],
            "iterations": sol.iterations,
            "stop": format!("{:?}", sol.stop),
            "cost": sol.cost,
            "u": sol.u.iter().map(|u| u.as_slice().to_vec()).collect::<Vec<_>>(),
        }
    });
    println!("{out}");
}
