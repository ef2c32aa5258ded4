//! `vic bench sooc`: how the cost of the exact SOOC iteration grows with the state.
//!
//! The open-loop moment problem optimises `z = (m, vech P)` of dimension `n + n(n+1)/2`. Per knot
//! and per iteration the stagewise Newton method ([`vic_core::solver::sooc_newton`]) needs the
//! first derivatives of the moment step ([`MomentDynamics::expand`], which differentiates the
//! flow twice) and its costate-contracted second derivatives ([`MomentDynamics::second_order`],
//! the flow's third derivatives). Both are timed per knot along the scenario's first guess,
//! beside the nominal model an ILQG iteration linearises (the plant's own Jacobians, measured in
//! the same run), and the cold plan of `vic plan --method sooc` is solved once per scenario. The
//! log–log slope of each time against the moment dimension (least squares over the scenarios)
//! is what a scalable method must bring down: issue targets are stated as that slope.

use super::BenchError;
use serde::Serialize;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;
use vic_core::dynamics::{Dynamics, Linearization};
use vic_core::solver::sooc::{MomentDynamics, MomentExpansion};
use vic_core::solver::sooc_newton::SoocStop;
use vic_plan::plan;
use vic_plan::scenario::Scenario;
use vic_plan::setup::Setup;

/// What `vic bench sooc` runs.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    /// Scenario files, each a point of the curve.
    pub(crate) configs: Vec<PathBuf>,
    /// Timed passes over the horizon per model (the median pass is reported).
    pub(crate) passes: usize,
    /// Also solve each scenario's cold SOOC plan once.
    pub(crate) solve: bool,
}

/// One scenario's point of the curve.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Point {
    pub(crate) scenario: String,
    /// Plant state dimension n.
    pub(crate) n: usize,
    /// Controls.
    pub(crate) m: usize,
    /// Moment dimension n + n(n+1)/2.
    pub(crate) moment_dim: usize,
    pub(crate) horizon: usize,
    /// The plant's linearisation per knot [µs] (what an ILQG iteration differentiates).
    pub(crate) nominal_us: f64,
    /// The moment step's first derivatives per knot [µs] (every SOOC iteration).
    pub(crate) first_us: f64,
    /// The exact Newton model per knot [µs]: first derivatives with the flow's third
    /// derivatives, then the costate-contracted second derivatives.
    pub(crate) newton_us: f64,
    /// `newton_us / nominal_us`.
    pub(crate) newton_over_nominal: f64,
    /// The cold plan, when solved.
    pub(crate) solve: Option<Solve>,
}

/// The cold SOOC plan as `vic plan --method sooc` makes it.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Solve {
    pub(crate) iterations: usize,
    pub(crate) ms: f64,
    pub(crate) ms_per_iteration: f64,
    pub(crate) converged: bool,
}

/// Log–log slopes against the moment dimension (null with fewer than two distinct dimensions).
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Slopes {
    pub(crate) nominal: Option<f64>,
    pub(crate) first: Option<f64>,
    pub(crate) newton: Option<f64>,
    pub(crate) ms_per_iteration: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub(crate) struct Report {
    pub(crate) points: Vec<Point>,
    pub(crate) slopes: Slopes,
    pub(crate) passes: usize,
}

/// The scenarios of the curve by default: one joint, the two-link arm, the VSA arm.
pub(crate) const DEFAULT_CONFIGS: [&str; 3] = [
    "config/icub_elbow.toml",
    "config/two_link_divergent.toml",
    "config/two_link_vsa_divergent.toml",
];

pub(crate) fn run(opts: &Options, mut progress: impl FnMut(&str)) -> Result<Report, BenchError> {
    let mut points = Vec::with_capacity(opts.configs.len());
    for path in &opts.configs {
        progress(&format!("{}", path.display()));
        points.push(point(path, opts)?);
    }
    let slope = |f: &dyn Fn(&Point) -> Option<f64>| {
        let xy: Vec<(f64, f64)> = points
            .iter()
            .filter_map(|p| f(p).map(|y| (p.moment_dim as f64, y)))
            .collect();
        log_log_slope(&xy)
    };
    let slopes = Slopes {
        nominal: slope(&|p| Some(p.nominal_us)),
        first: slope(&|p| Some(p.first_us)),
        newton: slope(&|p| Some(p.newton_us)),
        ms_per_iteration: slope(&|p| p.solve.as_ref().map(|s| s.ms_per_iteration)),
    };
    Ok(Report {
        points,
        slopes,
        passes: opts.passes,
    })
}

fn point(path: &Path, opts: &Options) -> Result<Point, BenchError> {
    let s = Scenario::load(path, &[])?;
    let setup = plan::setup(&s)?;
    let base = &setup.dynamics;
    let (n, m) = (base.nx(), base.nu());
    let horizon = s.task.steps;

    let mut knots = Knots::new(&setup, horizon);
    let nz = knots.moment_dim();
    let nominal_us = per_knot(opts.passes, horizon, |k| knots.nominal(k));
    let first_us = per_knot(opts.passes, horizon, |k| knots.first(k));
    let newton_us = per_knot(opts.passes, horizon, |k| knots.newton(k));

    let solve = if opts.solve {
        let plain = setup.problem(horizon);
        let (sol, (stop, optimality)) = plan::plan_sooc(&s, &setup, &plain, &None)?;
        let ms = sol.solve_time.as_secs_f64() * 1e3;
        Some(Solve {
            iterations: sol.iterations,
            ms,
            ms_per_iteration: ms / sol.iterations.max(1) as f64,
            converged: stop == SoocStop::Converged && optimality.met(),
        })
    } else {
        None
    };
    Ok(Point {
        scenario: path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned()),
        n,
        m,
        moment_dim: nz,
        horizon,
        nominal_us,
        first_us,
        newton_us,
        newton_over_nominal: newton_us / nominal_us,
        solve,
    })
}

/// The three models of the curve at the knots of a scenario's first guess (its means and
/// moments rolled out from the first-guess controls), each taken by one call; `cargo bench`'s
/// `sooc_scaling` group times the same calls.
pub struct Knots<'a> {
    setup: &'a Setup,
    moments: MomentDynamics<'a>,
    x: Vec<Vec<f64>>,
    z: Vec<Vec<f64>>,
    /// A costate of the moment problem's size; the timing does not depend on its values.
    lam: Vec<f64>,
    lin: Linearization,
    e: MomentExpansion,
}

impl<'a> Knots<'a> {
    pub fn new(setup: &'a Setup, horizon: usize) -> Self {
        let base = &setup.dynamics;
        let moments = MomentDynamics::new(base);
        let (n, nz) = (base.nx(), moments.nx());
        let mut x = vec![setup.x0.clone()];
        let mut z = vec![moments.initial_state(&setup.x0)];
        for k in 0..horizon {
            let u = setup.u_init[k].as_slice();
            let (mut xn, mut zn) = (vec![0.0; n], vec![0.0; nz]);
            base.step(k, &x[k], u, &mut xn);
            moments.step(k, &z[k], u, &mut zn);
            x.push(xn);
            z.push(zn);
        }
        Knots {
            setup,
            lam: (0..nz).map(|i| 1.0 / (1.0 + i as f64)).collect(),
            lin: Linearization::new(n, base.nu(), base.nw()),
            e: MomentExpansion::for_dynamics(&moments),
            moments,
            x,
            z,
        }
    }

    /// The moment dimension n + n(n+1)/2.
    pub fn moment_dim(&self) -> usize {
        self.moments.nx()
    }

    /// The plant's linearisation at knot `k` (ILQG's model).
    pub fn nominal(&mut self, k: usize) {
        let u = self.setup.u_init[k].as_slice();
        self.setup
            .dynamics
            .linearize(k, &self.x[k], u, &mut self.lin);
        black_box(&self.lin);
    }

    /// The moment step's first derivatives at knot `k` (every SOOC iteration).
    pub fn first(&mut self, k: usize) {
        let u = self.setup.u_init[k].as_slice();
        self.moments.expand(k, &self.z[k], u, &mut self.e);
        black_box(&self.e);
    }

    /// The exact Newton model at knot `k`: the first derivatives with the flow's third, then
    /// the costate-contracted second derivatives.
    pub fn newton(&mut self, k: usize) {
        let u = self.setup.u_init[k].as_slice();
        self.moments
            .expand_with_third(k, &self.z[k], u, &mut self.e);
        self.moments
            .second_order(k, &self.z[k], u, &self.lam, true, &mut self.e);
        black_box(&self.e);
    }
}

/// The median over `passes` of one pass over the horizon's knots, per knot [µs] (after one
/// pass not timed).
fn per_knot(passes: usize, horizon: usize, mut at: impl FnMut(usize)) -> f64 {
    (0..horizon).for_each(&mut at);
    let mut times: Vec<f64> = (0..passes.max(1))
        .map(|_| {
            let start = Instant::now();
            (0..horizon).for_each(&mut at);
            start.elapsed().as_secs_f64() * 1e6 / horizon as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// The least-squares slope of `ln y` against `ln x`; `None` with fewer than two distinct `x`.
pub(crate) fn log_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = points.iter().map(|&(x, y)| (x.ln(), y.ln())).collect();
    let count = logs.len() as f64;
    let mx = logs.iter().map(|p| p.0).sum::<f64>() / count;
    let my = logs.iter().map(|p| p.1).sum::<f64>() / count;
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 1e-12).then(|| sxy / sxx)
}

/// The readable report: a row per scenario, then the slopes.
pub(crate) fn print(r: &Report) {
    println!(
        "{:<28} {:>3} {:>3} {:>4} {:>12} {:>12} {:>12} {:>9} {:>16}",
        "scenario", "n", "m", "n_z", "nominal µs", "first µs", "Newton µs", "Newton/", "cold solve"
    );
    println!(
        "{:<28} {:>3} {:>3} {:>4} {:>12} {:>12} {:>12} {:>9}",
        "", "", "", "", "per knot", "per knot", "per knot", "nominal"
    );
    for p in &r.points {
        let solve = p.solve.as_ref().map_or_else(
            || "-".to_string(),
            |s| {
                format!(
                    "{:.0} ms, {} it{}",
                    s.ms,
                    s.iterations,
                    if s.converged { "" } else { " (not converged)" }
                )
            },
        );
        println!(
            "{:<28} {:>3} {:>3} {:>4} {:>12.2} {:>12.1} {:>12.1} {:>8.0}× {:>16}",
            p.scenario,
            p.n,
            p.m,
            p.moment_dim,
            p.nominal_us,
            p.first_us,
            p.newton_us,
            p.newton_over_nominal,
            solve
        );
    }
    let f = |s: Option<f64>| s.map_or_else(|| "-".to_string(), |s| format!("{s:.2}"));
    println!(
        "log–log slope against n_z: nominal {}, first derivatives {}, Newton model {}, \
         ms per solve iteration {} (median of {} passes over the horizon)",
        f(r.slopes.nominal),
        f(r.slopes.first),
        f(r.slopes.newton),
        f(r.slopes.ms_per_iteration),
        r.passes
    );
}

#[cfg(test)]
mod tests {
    use super::log_log_slope;

    #[test]
    fn slope_of_a_power_law_is_its_exponent() {
        let pts: Vec<(f64, f64)> = [5.0, 14.0, 44.0]
            .iter()
            .map(|&x: &f64| (x, 3.0 * x.powf(2.7)))
            .collect();
        assert!((log_log_slope(&pts).unwrap() - 2.7).abs() < 1e-12);
        assert_eq!(log_log_slope(&[(5.0, 1.0), (5.0, 2.0)]), None);
    }
}
