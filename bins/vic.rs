//! `vic`: the command-line front end. It parses arguments and calls the library; nothing else.

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use vic::config::Scenario;
use vic::plan::{PlanFile, plan};

/// Plan and run variable-impedance control under noise, unstable force fields and feedback
/// delays.
///
/// Scenarios are TOML files (see config/); every command that reads one takes
/// `--set section.key=value` to override any key, e.g. `--set noise.sigma=0.1`.
#[derive(Parser)]
#[command(name = "vic", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Plan a movement: solve the scenario's stochastic optimal control problem and print (or
    /// write) the plan.
    ///
    /// Example: vic plan --config config/icub_elbow.toml --out plan.json
    Plan(PlanArgs),
}

#[derive(Clone, Copy, ValueEnum)]
enum Method {
    /// Iterative LQG: a nominal plan with locally optimal feedback gains (Todorov & Li 2005),
    /// made for the scenario's feedback delay.
    Ilqg,
    /// Stochastic optimal open-loop control: torque and stiffness for execution without any
    /// feedback, optimal for the open-loop plant's mean and covariance (Berret & Jean 2020).
    Sooc,
}

#[derive(clap::Args)]
struct PlanArgs {
    /// Scenario file (TOML).
    #[arg(long, short, value_name = "FILE")]
    config: PathBuf,
    /// Planning method (default: the scenario's [solver] method, else ilqg).
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// Central feedback delay in ms (a whole number of time steps); overrides task.delay_ms.
    #[arg(long, value_name = "D")]
    delay_ms: Option<f64>,
    /// Override a configuration key (repeatable): --set noise.sigma=0.05
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Write the plan (time grid, controls, states, gains, resolved config) to this JSON file.
    #[arg(long, short, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Print one JSON object with the summary instead of the readable report.
    #[arg(long)]
    json: bool,
}

/// A failure and the exit code it deserves: 2 for bad input, 1 for everything else.
struct Failure {
    code: u8,
    message: String,
}

impl Failure {
    fn input(message: impl std::fmt::Display) -> Self {
        Failure {
            code: 2,
            message: message.to_string(),
        }
    }
    fn runtime(message: impl std::fmt::Display) -> Self {
        Failure {
            code: 1,
            message: message.to_string(),
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Plan(args) => run_plan(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("vic: error: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}

fn run_plan(args: PlanArgs) -> Result<(), Failure> {
    let mut overrides = args.overrides.clone();
    if let Some(d) = args.delay_ms {
        overrides.push(format!("task.delay_ms={d}"));
    }
    let scenario = Scenario::load(&args.config, &overrides).map_err(Failure::input)?;
    let method = match args.method {
        Some(Method::Ilqg) => vic::plan::Method::Ilqg,
        Some(Method::Sooc) => vic::plan::Method::Sooc,
        None => scenario.solver.method,
    };
    let plan = plan(&scenario, method)
        .map_err(|e| Failure::input(format!("{}: {e}", args.config.display())))?;
    if let Some(out) = &args.out {
        let text = serde_json::to_string(&plan).map_err(Failure::runtime)?;
        std::fs::write(out, text)
            .map_err(|e| Failure::runtime(format!("cannot write {}: {e}", out.display())))?;
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&plan.summary).map_err(Failure::runtime)?
        );
    } else {
        print_summary(&plan, args.out.as_ref());
    }
    Ok(())
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
    println!(
        "cost       {:.6e} nominal, {:.6e} expected (predicted)",
        s.cost, s.expected_cost
    );
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
