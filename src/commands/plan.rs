//! `vic plan`: solve a scenario's stochastic optimal control problem (ILQG for the scenario's
//! feedback delay, or SOOC for open-loop execution), write the plan file and report its summary.

use crate::cli::{Classify, JsonArg, ScenarioArgs, latency_arg, print_json};
use crate::progress::Progress;
use clap::ValueEnum;
use std::path::PathBuf;
use vic_plan::plan::{Method, PlanFile, plan};
use vic_plan::plan_file::PlanSummary;
use vic_plan::scenario::Scenario;

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Iterative LQG: a nominal plan with locally optimal feedback gains (Todorov & Li 2005),
    /// made for the scenario's feedback delay.
    Ilqg,
    /// Stochastic optimal open-loop control: torque and stiffness for execution without any
    /// feedback, optimal for the open-loop plant's mean and covariance (Berret & Jean 2020).
    Sooc,
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object with the summary instead of the readable report")))]
pub(crate) struct Args {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Planning method (default: the scenario's [solver] method, else ilqg).
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Feedback latency of the central controller the plan is made for [ms] (a whole number of
    /// time steps); instead of task.delay_ms. [range: 0 to 1000]
    #[arg(long, value_name = "MS", alias = "delay-ms", value_parser = crate::ranges::real(0.0, crate::ranges::MAX_LATENCY_MS))]
    latency_ms: Option<f64>,
    /// Write the plan (time grid, controls, states, gains, resolved config) to this JSON file.
    #[arg(long, short, value_name = "FILE")]
    out: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

/// Plans the scenario, writes the plan file if asked and prints the summary (JSON or text).
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let config = &a.scenario.config;
    let mut scenario = Scenario::load(config, &a.scenario.set.overrides).input()?;
    if let Some(ms) = a.latency_ms {
        let latency = latency_arg("--latency-ms", ms, scenario.task.dt)?;
        scenario = scenario.with_delay(latency);
    }
    let method = match a.method {
        Some(MethodArg::Ilqg) => Method::Ilqg,
        Some(MethodArg::Sooc) => Method::Sooc,
        None => scenario.solver.method,
    };
    let progress = Progress::spinner();
    let plan = plan(&scenario, method, progress.solver_callback())
        .map_err(|e| format!("{}: {e}", config.display()))
        .input()?;
    drop(progress);
    if let Some(out) = &a.out {
        plan.write(out).runtime()?;
    }
    if a.json.json {
        print_json(&plan.summary)
    } else {
        print_summary(&plan, a.out.as_ref());
        Ok(())
    }
}

/// The convergence criterion's values against their tolerances (SOOC's optimality, or ILQG's
/// stop tests), for the readable summary.
fn criterion_line(s: &PlanSummary) -> Option<String> {
    if let Some(o) = &s.optimality {
        return Some(format!(
            "projected gradient {:.1e} (tolerance {:.0e}), predicted decrease {:.1e} ({:.0e})",
            o.projected_gradient, o.gradient_tolerance, o.predicted_decrease, o.decrease_tolerance
        ));
    }
    let c = s.convergence.as_ref()?;
    let mut line = format!(
        "feedforward step {:.1e} (tolerance {:.0e})",
        c.feedforward_step, c.gradient_tolerance
    );
    if let Some(i) = c.improvement {
        let how = match c.step_length {
            Some(a) => format!("of a step of {a}"),
            None => "predicted".to_string(),
        };
        line += &format!(
            "; improvement {i:.1e} {how} (tolerance {:.0e}) at μ {:.1e} (trusted ≤ {:.1e})",
            c.tolerance, c.mu, c.trusted_mu
        );
    }
    Some(line)
}

fn print_summary(p: &PlanFile, out: Option<&PathBuf>) {
    let s = &p.summary;
    println!("plan       {} ({})", p.scenario, s.method);
    println!(
        "solver     {} after {} iterations in {:.1} ms ({})",
        if s.converged {
            "converged"
        } else {
            "did NOT converge"
        },
        s.iterations,
        s.solve_ms,
        s.stop
    );
    if let Some(line) = criterion_line(s) {
        println!("criterion  {line}");
    }
    println!(
        "cost       {:.6e} nominal, {:.6e} expected (predicted)",
        s.cost, s.expected_cost
    );
    if let Some(n) = s.clamped_feedback_knots.filter(|&n| n > 0) {
        println!(
            "warning    at {n} of {} knots the feedback's predicted spread in a control passes \
             its bound: the plant clamps it, and the expected cost above is that of a linear law \
             it does not execute (measure it with vic simulate --policy feedback); stiffness is \
             better planned open loop (--method sooc)",
            p.u.len()
        );
    }
    println!(
        "stiffness  max {:.2} N m/rad, mean {:.2} N m/rad",
        s.max_stiffness, s.mean_stiffness
    );
    println!("delay      {} steps ({:.0} ms)", s.delay_steps, s.delay_ms);
    println!(
        "accuracy   final nominal error {:.3} {}",
        s.final_error, s.final_error_unit
    );
    if let Some(out) = out {
        println!("written    {}", out.display());
    }
}
