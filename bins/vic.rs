//! `vic`: the command-line front end. It parses arguments and calls the library; nothing else.

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use vic::planning::plan::{PlanFile, plan};
use vic::planning::scenario::Scenario;

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
    /// Monte Carlo of a plan on the stochastic plant: spread, 95 % ellipse, tracking error,
    /// divergence and the expected cost, next to the plan's prediction.
    ///
    /// Example: vic simulate --config config/two_link_divergent.toml --plan plan.json --policy open-loop
    Simulate(SimulateArgs),
    /// Reproduce a figure of the paper: plan and simulate every column, write the plots (PNG and
    /// SVG) and a JSON of the numbers into --out-dir, print a table.
    ///
    /// Example: vic experiment fig1 --trials 20 --out-dir results
    Experiment(ExperimentArgs),
    /// Regenerate docs/RESULTS.md: run fig1, fig2 and icub, write their figures and numbers into
    /// --out-dir/figures and the document that sets the paper's claims beside our numbers.
    ///
    /// Example: vic results --out-dir docs
    Results(ResultsArgs),
    /// Run the real-time pair: start a board and a planner in a fresh namespace, run the
    /// `stiffness` and `delayed-feedback` strategies at --latency-ms with the same noise seeds,
    /// and delayed feedback at 0 ms latency as the reference (the planner at 250 Hz); print the
    /// comparison and the board's timing, and shut everything down.
    ///
    /// Example: vic demo --latency-ms 200 --trials 3
    Demo(DemoArgs),
    /// Send a disturbance to a running board and report the tick that applied it (read from its
    /// state stream), or fail (exit 1) when no board answers or it rejects the disturbance.
    ///
    /// Examples: vic inject pulse --torque 2,0 --duration-ms 50;  vic inject field --beta 0;
    /// vic inject load --torque 0,0.5;  vic inject noise --factor 2
    Inject(InjectArgs),
    /// One snapshot of a running board's telemetry: mode (running / safe-hold / fault), tick
    /// rate, jitter, work time, command age, tracking error, stiffness, disturbances, rejected
    /// messages by reason.
    ///
    /// Example: vic status --namespace lab1 --json
    Status(StatusArgs),
    /// Watch a running board live: a refreshing view on a terminal, one line per interval when
    /// piped. Stops on Ctrl-C (or after --count snapshots).
    ///
    /// Example: vic monitor --namespace lab1
    Monitor(MonitorArgs),
    /// Identify the joint's torque noise from a log, the paper's procedure (Sec. III-B): bin the
    /// torque error by velocity, fit its mean and standard deviation with polynomials, estimate
    /// (a, b) of e = (a + b q') η by maximum likelihood and test the residual η for normality
    /// (Jarque–Bera).
    ///
    /// The log is CSV with the columns t,q,qd,qdd,tau_ff,stiffness,damping,q_d,qd_d (any order;
    /// extra columns must start with x_). The joint's parameters come from --config (a single-joint
    /// scenario), else the iCub forearm's.
    ///
    /// Example: vic identify --log elbow.csv --config config/icub_experiment.toml
    Identify(IdentifyArgs),
    /// Benchmark against the machine's own limits: the board's 1 kHz loop against cyclictest,
    /// the transport against a bare iceoryx2 ping-pong (same run, both distributions, ratios).
    ///
    /// Example: vic bench loop --seconds 30 --json
    Bench(BenchArgs),
}

#[derive(clap::Args)]
struct IdentifyArgs {
    /// The log (CSV).
    #[arg(long, value_name = "FILE.csv")]
    log: PathBuf,
    /// Single-joint scenario whose [plant] gives J, m, l_c and g (default: the iCub forearm).
    #[arg(long, short, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of velocity bins.
    #[arg(long, default_value_t = 20)]
    bins: usize,
    /// Fewest samples a bin needs to be used.
    #[arg(long, default_value_t = 30)]
    min_bin_count: usize,
    /// Degree of the polynomial fitted to the mean error (the paper: 1).
    #[arg(long, default_value_t = 1)]
    mean_degree: usize,
    /// Degree of the polynomial fitted to the error's standard deviation (the paper: 2).
    #[arg(long, default_value_t = 2)]
    std_degree: usize,
    /// Subtract the fitted mean error before estimating (a, b).
    #[arg(long)]
    subtract_mean: bool,
    /// Print one JSON object instead of the readable report.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct ResultsArgs {
    /// Monte Carlo trials per column.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(3..))]
    trials: u64,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where RESULTS.md and figures/ go.
    #[arg(long, default_value = "docs", value_name = "DIR")]
    out_dir: PathBuf,
    /// Folder of the scenario files.
    #[arg(long, default_value = "config", value_name = "DIR")]
    config_dir: PathBuf,
}

#[derive(Clone, Copy, ValueEnum)]
enum FigureArg {
    /// Two-link arm in the divergent field, each actuator type, executed open loop (Fig. 1).
    Fig1,
    /// Single joint with a 200 ms feedback delay: feedforward, delayed feedback, stiffness (Fig. 2).
    Fig2,
    /// The iCub elbow with the identified noise: predicted versus Monte Carlo expected cost.
    Icub,
}

#[derive(clap::Args)]
struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    figure: FigureArg,
    /// Monte Carlo trials per column.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(3..))]
    trials: u64,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the plots and the JSON go.
    #[arg(long, default_value = "results", value_name = "DIR")]
    out_dir: PathBuf,
    /// Folder of the scenario files.
    #[arg(long, default_value = "config", value_name = "DIR")]
    config_dir: PathBuf,
    /// Print the JSON document instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum PolicyArg {
    /// The planned commands, no feedback at all.
    OpenLoop,
    /// The plan's gains on the current state.
    Feedback,
    /// The plan's gains on the state seen --delay-ms late (default: the plan's delay).
    DelayedFeedback,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// Scenario file (TOML): the plant the plan runs on (it may differ from the plan's, e.g. in
    /// noise).
    #[arg(long, short, value_name = "FILE")]
    config: PathBuf,
    /// Plan file written by `vic plan --out`.
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// How the plan is executed.
    #[arg(long, value_enum, default_value = "open-loop")]
    policy: PolicyArg,
    /// Number of trials.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(2..))]
    trials: u64,
    /// Seed of the noise (each trial derives its own stream from it).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Feedback latency for --policy delayed-feedback [ms] (default: the plan's delay).
    #[arg(long, value_name = "D")]
    delay_ms: Option<f64>,
    /// A trial has diverged when it ends further than this from the target [mm for the arm,
    /// degrees for a single joint] (default 50 mm / 10°).
    #[arg(long, value_name = "DIST")]
    divergence: Option<f64>,
    /// Override a configuration key of the scenario (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Write every trial's states and commands to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Plot the trials (paths or angles, velocities, commands) to this PNG (and an SVG beside it).
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Print one JSON object instead of the readable report.
    #[arg(long)]
    json: bool,
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
        Command::Simulate(args) => run_simulate(args),
        Command::Experiment(args) => run_experiment(args),
        Command::Demo(args) => run_demo(args),
        Command::Inject(args) => run_inject(args),
        Command::Status(args) => run_status(args),
        Command::Monitor(args) => run_monitor(args),
        Command::Results(args) => run_results(args),
        Command::Identify(args) => run_identify(args),
        Command::Bench(args) => run_bench(args),
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
        Some(Method::Ilqg) => vic::planning::plan::Method::Ilqg,
        Some(Method::Sooc) => vic::planning::plan::Method::Sooc,
        None => scenario.solver.method,
    };
    let progress = progress_printer();
    let plan = plan(&scenario, method, progress)
        .map_err(|e| Failure::input(format!("{}: {e}", args.config.display())))?;
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        eprint!("\r\x1b[2K");
    }
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

/// Progress on stderr when it is a terminal: one line, rewritten in place; nothing when piped.
fn progress_printer() -> Option<vic::planning::plan::ProgressFn> {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return None;
    }
    Some(std::sync::Arc::new(
        |phase: &str, p: &vic::core::solver::ilqg::Progress| {
            eprint!(
                "\r\x1b[2K{phase}: iteration {} merit {:.6e} (μ {:.1e}, step {})",
                p.iteration, p.merit, p.mu, p.alpha
            );
        },
    ))
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

fn run_simulate(args: SimulateArgs) -> Result<(), Failure> {
    use vic::core::policy::Feedback;
    use vic::planning::montecarlo::run_trials;
    let scenario = Scenario::load(&args.config, &args.overrides).map_err(Failure::input)?;
    let text = std::fs::read_to_string(&args.plan)
        .map_err(|e| Failure::input(format!("{}: cannot read: {e}", args.plan.display())))?;
    let plan: PlanFile = serde_json::from_str(&text)
        .map_err(|e| Failure::input(format!("{}: not a plan file: {e}", args.plan.display())))?;
    let setup = vic::planning::plan::setup(&scenario).map_err(Failure::input)?;
    let exe = plan
        .policy(&setup)
        .map_err(|e| Failure::input(format!("{}: {e}", args.plan.display())))?;
    let dt = scenario.task.dt;
    let policy = match args.policy {
        PolicyArg::OpenLoop => Feedback::OpenLoop,
        PolicyArg::Feedback => Feedback::Full,
        PolicyArg::DelayedFeedback => {
            let steps = match args.delay_ms {
                Some(ms) => {
                    let s = ms / 1000.0 / dt;
                    if s.is_nan() || s < 0.0 || (s - s.round()).abs() > 1e-6 {
                        return Err(Failure::input(format!(
                            "--delay-ms {ms}: not a whole number of {} ms steps",
                            dt * 1000.0
                        )));
                    }
                    s.round() as usize
                }
                None => plan.summary.delay_steps,
            };
            Feedback::Delayed {
                latency_steps: steps,
            }
        }
    };
    let divergence = args
        .divergence
        .unwrap_or(if setup.dynamics.model.dof() == 1 {
            10.0
        } else {
            50.0
        });
    let trials = run_trials(&setup, &exe, policy, args.trials as usize, args.seed);
    let report = vic::planning::evaluation::summarize(&setup, &trials, divergence);
    if let Some(path) = &args.csv {
        write_trials_csv(path, &plan, &trials).map_err(Failure::runtime)?;
    }
    if let Some(png) = &args.plot {
        let title = format!("{:?}", policy);
        let column = vic::tools::experiment::column_plot(&title, &plan, &scenario, &trials);
        let svg = png.with_extension("svg");
        let draw = if scenario.model.dof() == 2 {
            vic::tools::plot::arm_figure(&[column], png, &svg)
        } else {
            vic::tools::plot::joint_figure(&[column], png, &svg)
        };
        draw.map_err(Failure::runtime)?;
    }
    let predicted = match policy {
        Feedback::OpenLoop => plan.summary.open_loop_expected_cost,
        _ => plan.summary.expected_cost,
    };
    if args.json {
        let mut v = serde_json::to_value(&report).map_err(Failure::runtime)?;
        v["policy"] = serde_json::to_value(policy).map_err(Failure::runtime)?;
        v["expected_cost_predicted"] = predicted.into();
        v["seed"] = args.seed.into();
        println!("{v}");
    } else {
        let u = &report.unit;
        println!(
            "simulate   {} with {} ({:?}), {} trials, seed {}",
            plan.scenario,
            args.config.display(),
            policy,
            report.trials,
            args.seed
        );
        println!(
            "final      std {:.3} {u}, 95 % ellipse semi-axes {:?} {u}",
            report.final_std,
            report
                .ellipse_95
                .iter()
                .map(|v| format!("{v:.3}"))
                .collect::<Vec<_>>()
        );
        println!(
            "errors     RMS {:.3} {u}, final mean {:.3} / max {:.3} {u}",
            report.rms_error, report.final_error_mean, report.final_error_max
        );
        println!(
            "diverged   {} of {} (ending > {divergence} {u} from the target)",
            report.diverged, report.trials
        );
        println!(
            "cost       Monte Carlo {:.6e} ± {:.2e}, predicted {:.6e}",
            report.expected_cost_mc, report.expected_cost_se, predicted
        );
    }
    Ok(())
}

fn write_trials_csv(
    path: &PathBuf,
    plan: &PlanFile,
    trials: &[vic::planning::montecarlo::Trial],
) -> Result<(), String> {
    use std::io::Write;
    let file =
        std::fs::File::create(path).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    let mut header = vec!["trial".to_string(), "k".into(), "t".into()];
    header.extend(plan.state_names.iter().cloned());
    header.extend(plan.control_names.iter().cloned());
    let io = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
    writeln!(w, "{}", header.join(",")).map_err(io)?;
    for (i, t) in trials.iter().enumerate() {
        for (k, x) in t.x.iter().enumerate() {
            write!(w, "{i},{k},{}", plan.dt * k as f64).map_err(io)?;
            for v in x.iter() {
                write!(w, ",{v}").map_err(io)?;
            }
            match t.u.get(k) {
                Some(u) => u.iter().try_for_each(|v| write!(w, ",{v}")).map_err(io)?,
                None => (0..plan.control_names.len())
                    .try_for_each(|_| write!(w, ","))
                    .map_err(io)?,
            }
            writeln!(w).map_err(io)?;
        }
    }
    w.flush().map_err(io)
}

fn run_experiment(args: ExperimentArgs) -> Result<(), Failure> {
    use std::io::IsTerminal;
    use vic::tools::experiment::{Figure, run, to_json, write_outputs};
    let figure = match args.figure {
        FigureArg::Fig1 => Figure::Fig1,
        FigureArg::Fig2 => Figure::Fig2,
        FigureArg::Icub => Figure::Icub,
    };
    if !args.config_dir.is_dir() {
        return Err(Failure::input(format!(
            "--config-dir {}: not a folder of scenario files",
            args.config_dir.display()
        )));
    }
    let tty = std::io::stderr().is_terminal();
    let progress = progress_printer();
    let run = run(
        figure,
        &args.config_dir,
        args.trials as usize,
        args.seed,
        progress,
        |i, n, name| {
            if tty {
                eprintln!("\r\x1b[2K[{}/{n}] {name}", i + 1);
            }
        },
    )
    .map_err(|e| match e {
        vic::tools::experiment::ExperimentError::Config(c) => Failure::input(c),
        other => Failure::runtime(other),
    })?;
    if tty {
        eprint!("\r\x1b[2K");
    }
    let files = write_outputs(&run, &args.out_dir).map_err(Failure::runtime)?;
    if args.json {
        println!("{}", to_json(&run));
        return Ok(());
    }
    println!(
        "{:<18} {:>8} {:>12} {:>12} {:>9} {:>13} {:>13} {:>9}",
        "column", "method", "final std", "RMS error", "diverged", "E[C] MC", "E[C] pred.", "mean K"
    );
    for c in &run.columns {
        let unit = &c.report.unit;
        println!(
            "{:<18} {:>8} {:>9.2} {unit:<3}{:>8.2} {unit:<3} {:>8.0} % {:>13.4e} {:>13.4e} {:>9.1}",
            c.name,
            c.method,
            c.report.final_std,
            c.rms_error,
            c.diverged_fraction * 100.0,
            c.expected_cost_mc,
            c.expected_cost_predicted,
            c.mean_stiffness
        );
    }
    if figure == Figure::Icub {
        println!("paper: C* = 0.29 predicted, C = 0.41 measured on the robot");
    }
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

fn run_results(args: ResultsArgs) -> Result<(), Failure> {
    use std::io::IsTerminal;
    use vic::tools::experiment::{Figure, results_markdown, run, write_outputs};
    let tty = std::io::stderr().is_terminal();
    let mut runs = Vec::new();
    for figure in [Figure::Fig1, Figure::Fig2, Figure::Icub] {
        let r = run(
            figure,
            &args.config_dir,
            args.trials as usize,
            args.seed,
            progress_printer(),
            |i, n, name| {
                if tty {
                    eprintln!("\r\x1b[2K{} [{}/{n}] {name}", figure.name(), i + 1);
                }
            },
        )
        .map_err(|e| match e {
            vic::tools::experiment::ExperimentError::Config(c) => Failure::input(c),
            other => Failure::runtime(other),
        })?;
        for f in write_outputs(&r, &args.out_dir.join("figures")).map_err(Failure::runtime)? {
            println!("wrote {}", f.display());
        }
        runs.push(r);
    }
    if tty {
        eprint!("\r\x1b[2K");
    }
    let command = format!(
        "cargo run --release -- results --trials {} --seed {} --out-dir {}",
        args.trials,
        args.seed,
        args.out_dir.display()
    );
    let md = results_markdown(&runs, "figures", &command);
    let path = args.out_dir.join("RESULTS.md");
    std::fs::write(&path, md)
        .map_err(|e| Failure::runtime(format!("cannot write {}: {e}", path.display())))?;
    println!("wrote {}", path.display());
    Ok(())
}

fn run_identify(args: IdentifyArgs) -> Result<(), Failure> {
    use vic::core::model::Plant;
    use vic::tools::identify::{IdentifyOptions, JointParams, identify, read_log_file};
    let joint = match &args.config {
        None => JointParams::ICUB_FOREARM,
        Some(path) => {
            let s = Scenario::load(path, &[]).map_err(Failure::input)?;
            match &s.model.plant {
                Plant::SingleJoint(p) => JointParams {
                    inertia: p.inertia,
                    mass: p.mass,
                    com: p.com,
                    gravity: p.gravity,
                },
                Plant::TwoLink(_) => {
                    return Err(Failure::input(format!(
                        "{}: [plant] kind: identification needs a single joint",
                        path.display()
                    )));
                }
            }
        }
    };
    let rows = read_log_file(&args.log)
        .map_err(|e| Failure::input(format!("{}: {e}", args.log.display())))?;
    let options = IdentifyOptions {
        bins: args.bins,
        min_bin_count: args.min_bin_count,
        mean_degree: args.mean_degree,
        std_degree: args.std_degree,
        subtract_mean: args.subtract_mean,
    };
    let report = identify(&rows, &joint, &options)
        .map_err(|e| Failure::input(format!("{}: {e}", args.log.display())))?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&report).map_err(Failure::runtime)?
        );
    } else {
        println!("{report}");
    }
    Ok(())
}

#[derive(clap::Args)]
struct InjectArgs {
    #[command(subcommand)]
    what: InjectWhat,
    /// Namespace of the board.
    #[arg(long, global = true, default_value = vic::rt::transport::DEFAULT_NAMESPACE)]
    namespace: String,
    /// Seconds to wait for the board and its acknowledgement.
    #[arg(long, global = true, default_value_t = 2.0)]
    timeout_s: f64,
    /// Print the acknowledgement as JSON.
    #[arg(long, global = true)]
    json: bool,
}

#[derive(Subcommand)]
enum InjectWhat {
    /// A torque pulse on the joints.
    Pulse {
        /// Joint torques [N m], comma-separated (one per joint; missing joints get 0).
        #[arg(
            long,
            value_name = "T1[,T2]",
            value_delimiter = ',',
            allow_negative_numbers = true
        )]
        torque: Vec<f64>,
        /// Pulse duration [ms].
        #[arg(long, default_value_t = 50.0)]
        duration_ms: f64,
    },
    /// A steady load torque until changed (all zeros remove it).
    Load {
        /// Joint torques [N m], comma-separated.
        #[arg(
            long,
            value_name = "T1[,T2]",
            value_delimiter = ',',
            allow_negative_numbers = true
        )]
        torque: Vec<f64>,
    },
    /// Switch the divergent force field on (β > 0) or off (0). Two-link arm only.
    Field {
        /// β [N/m].
        #[arg(long, allow_negative_numbers = true)]
        beta: f64,
    },
    /// Scale the plant noise (1: as configured, 0: none).
    Noise {
        #[arg(long, allow_negative_numbers = true)]
        factor: f64,
    },
}

fn joint_torques(v: &[f64]) -> Result<[f64; 2], Failure> {
    if v.is_empty() || v.len() > 2 || v.iter().any(|x| !x.is_finite()) {
        return Err(Failure::input(format!(
            "--torque {v:?}: give one or two finite joint torques in N m, e.g. --torque 1.5,0"
        )));
    }
    let mut t = [0.0; 2];
    t[..v.len()].copy_from_slice(v);
    Ok(t)
}

fn run_inject(args: InjectArgs) -> Result<(), Failure> {
    use vic::tools::operator::{OperatorError, Request};
    vic::rt::transport::validate_namespace(&args.namespace).map_err(Failure::input)?;
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0) {
        return Err(Failure::input(format!(
            "--timeout-s {}: must be a positive number of seconds",
            args.timeout_s
        )));
    }
    let request = match &args.what {
        InjectWhat::Pulse {
            torque,
            duration_ms,
        } => {
            if !(duration_ms.is_finite() && *duration_ms > 0.0) {
                return Err(Failure::input(format!(
                    "--duration-ms {duration_ms}: must be a positive number of milliseconds"
                )));
            }
            Request::Pulse {
                torque: joint_torques(torque)?,
                duration: duration_ms / 1e3,
            }
        }
        InjectWhat::Load { torque } => Request::Load {
            torque: joint_torques(torque)?,
        },
        InjectWhat::Field { beta } => {
            if !beta.is_finite() {
                return Err(Failure::input("--beta must be a finite number of N/m"));
            }
            Request::Field { beta: *beta }
        }
        InjectWhat::Noise { factor } => {
            if !(factor.is_finite() && *factor >= 0.0) {
                return Err(Failure::input(format!("--factor {factor}: must be ≥ 0")));
            }
            Request::Noise { factor: *factor }
        }
    };
    let ack = vic::tools::operator::inject(
        &args.namespace,
        request,
        std::time::Duration::from_secs_f64(args.timeout_s),
    )
    .map_err(|e| match e {
        OperatorError::Transport(e) => Failure::runtime(e),
        e => Failure::runtime(e),
    })?;
    if args.json {
        println!("{}", serde_json::to_string(&ack).map_err(Failure::runtime)?);
    } else {
        let effect = match ack.effect_after_ticks {
            Some(0) => ", in effect at that tick".to_string(),
            Some(n) => format!(", in effect {n} tick(s) later"),
            None => String::new(),
        };
        println!(
            "applied by the board in \"{}\" at tick {} ({:.0} µs after sending{effect}); mode {}, τ_ext {:?} N m",
            ack.namespace, ack.tick, ack.latency_us, ack.mode, ack.tau_ext
        );
    }
    Ok(())
}

#[derive(clap::Args)]
struct StatusArgs {
    /// Namespace of the board.
    #[arg(long, default_value = vic::rt::transport::DEFAULT_NAMESPACE)]
    namespace: String,
    /// Seconds to wait for the board's telemetry (it publishes at 10 Hz).
    #[arg(long, default_value_t = 1.0)]
    timeout_s: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

fn run_status(args: StatusArgs) -> Result<(), Failure> {
    vic::rt::transport::validate_namespace(&args.namespace).map_err(Failure::input)?;
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0) {
        return Err(Failure::input("--timeout-s must be a positive number"));
    }
    let s = vic::tools::operator::status(
        &args.namespace,
        std::time::Duration::from_secs_f64(args.timeout_s),
    )
    .map_err(Failure::runtime)?;
    if args.json {
        println!("{}", serde_json::to_string(&s).map_err(Failure::runtime)?);
    } else {
        println!("{}", s.render());
    }
    Ok(())
}

#[derive(clap::Args)]
struct MonitorArgs {
    /// Namespace of the board.
    #[arg(long, default_value = vic::rt::transport::DEFAULT_NAMESPACE)]
    namespace: String,
    /// Seconds between snapshots.
    #[arg(long, default_value_t = 1.0)]
    interval_s: f64,
    /// Stop after this many snapshots (default: until Ctrl-C).
    #[arg(long)]
    count: Option<u64>,
}

fn run_monitor(args: MonitorArgs) -> Result<(), Failure> {
    use std::io::{IsTerminal, Write};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    vic::rt::transport::validate_namespace(&args.namespace).map_err(Failure::input)?;
    if !(args.interval_s.is_finite() && args.interval_s >= 0.1) {
        return Err(Failure::input("--interval-s must be at least 0.1"));
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .map_err(|e| Failure::runtime(format!("cannot install the signal handler: {e}")))?;
    }
    let tty = std::io::stdout().is_terminal();
    let mut shown = 0u64;
    vic::tools::operator::monitor(
        &args.namespace,
        std::time::Duration::from_secs_f64(args.interval_s),
        &stop,
        |s| {
            let mut out = std::io::stdout().lock();
            let text = match s {
                Some(s) if tty => s.render(),
                Some(s) => s.line(),
                None => format!("no board in namespace \"{}\" (waiting)", args.namespace),
            };
            // On a terminal: clear and redraw in place.
            let ok = if tty {
                write!(out, "\x1b[H\x1b[2J{text}\n(Ctrl-C to quit)\n")
            } else {
                writeln!(out, "{text}")
            };
            let _ = out.flush();
            shown += 1;
            ok.is_ok() && args.count.is_none_or(|c| shown < c)
        },
    )
    .map_err(Failure::runtime)?;
    Ok(())
}

#[derive(clap::Args)]
struct DemoArgs {
    /// Scenario file (TOML): a two-link or single-joint plant with the impedance actuator.
    #[arg(
        long,
        short,
        value_name = "FILE",
        default_value = "config/two_link_divergent.toml"
    )]
    config: PathBuf,
    /// Override a configuration key (repeatable), for the plans and the board alike.
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Feedback latency of the central controller [ms] (a whole number of plan steps).
    #[arg(long, default_value_t = 200.0)]
    latency_ms: f64,
    /// Trials per strategy.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    trials: u64,
    /// Seed of the board's noise (the same for every strategy).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Keep the plans in this folder and reuse them on the next run (default: plan afresh).
    #[arg(long, value_name = "DIR")]
    plans_dir: Option<PathBuf>,
    /// Use this plan for the `stiffness` strategy instead of planning (SOOC, `vic plan --out`).
    #[arg(long, value_name = "FILE")]
    stiffness_plan: Option<PathBuf>,
    /// Use this plan for `delayed-feedback` instead of planning (ILQG for the latency, zero
    /// stiffness).
    #[arg(long, value_name = "FILE")]
    feedback_plan: Option<PathBuf>,
    /// Board spin before each deadline [µs] (0: sleep only).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn sibling_binary(name: &str) -> Result<PathBuf, Failure> {
    let exe = std::env::current_exe().map_err(Failure::runtime)?;
    let path = exe.with_file_name(name);
    if path.is_file() {
        Ok(path)
    } else {
        Err(Failure::runtime(format!(
            "{} not found next to {} (build it with cargo build --bins)",
            name,
            exe.display()
        )))
    }
}

/// Makes (or reuses from `dir`) the plan of one strategy.
fn demo_plan(
    config: &std::path::Path,
    overrides: &[String],
    method: vic::planning::plan::Method,
    dir: &std::path::Path,
    reuse: bool,
) -> Result<PathBuf, Failure> {
    use std::hash::{Hash, Hasher};
    let text = std::fs::read_to_string(config)
        .map_err(|e| Failure::input(format!("{}: cannot read: {e}", config.display())))?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    (
        text,
        overrides,
        method.name(),
        vic::planning::plan::PLAN_VERSION,
    )
        .hash(&mut h);
    let path = dir.join(format!("{}-{:016x}.json", method.name(), h.finish()));
    if reuse && path.is_file() {
        return Ok(path);
    }
    let scenario = Scenario::load(config, overrides).map_err(Failure::input)?;
    let plan = plan(&scenario, method, None)
        .map_err(|e| Failure::input(format!("{}: {e}", config.display())))?;
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(
        &tmp,
        serde_json::to_string(&plan).map_err(Failure::runtime)?,
    )
    .and_then(|_| std::fs::rename(&tmp, &path))
    .map_err(|e| Failure::runtime(format!("cannot write {}: {e}", path.display())))?;
    Ok(path)
}

fn run_demo(args: DemoArgs) -> Result<(), Failure> {
    use std::process::{Command as Proc, Stdio};
    let scenario = Scenario::load(&args.config, &args.overrides).map_err(Failure::input)?;
    let dt_ms = scenario.task.dt * 1000.0;
    let steps = args.latency_ms / dt_ms;
    if !(steps >= 0.0 && (steps - steps.round()).abs() < 1e-6) {
        return Err(Failure::input(format!(
            "--latency-ms {}: not a whole number of {dt_ms} ms plan steps",
            args.latency_ms
        )));
    }
    let board_bin = sibling_binary("vic-board")?;
    let planner_bin = sibling_binary("vic-planner")?;
    let namespace = format!("demo{}", std::process::id());
    let tmp_dir = std::env::temp_dir().join(format!("vic-{namespace}"));
    let (dir, reuse) = match &args.plans_dir {
        Some(d) => (d.clone(), true),
        None => (tmp_dir.clone(), false),
    };
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::runtime(format!("cannot create {}: {e}", dir.display())))?;
    let mut df_overrides = args.overrides.clone();
    df_overrides.push("actuator.stiffness_max=0".into());
    // The reference row: central feedback without latency (planned for none, the planner at
    // 250 Hz so that its own loop adds only a few ms) — the paper's "with 0 ms latency,
    // delayed feedback works".
    let mut zero_overrides = df_overrides.clone();
    zero_overrides.push("task.delay_ms=0".into());
    df_overrides.push(format!("task.delay_ms={}", args.latency_ms));
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        eprintln!("planning (SOOC for stiffness, ILQG for delayed feedback) ...");
    }
    let (sooc, (ilqg, ilqg0)) = std::thread::scope(|s| {
        let a = s.spawn(|| {
            if let Some(p) = &args.stiffness_plan {
                return Ok(p.clone());
            }
            demo_plan(
                &args.config,
                &args.overrides,
                vic::planning::plan::Method::Sooc,
                &dir,
                reuse,
            )
        });
        let b = s.spawn(|| {
            let delayed = match &args.feedback_plan {
                Some(p) => Ok(p.clone()),
                None => demo_plan(
                    &args.config,
                    &df_overrides,
                    vic::planning::plan::Method::Ilqg,
                    &dir,
                    reuse,
                ),
            };
            let zero = if args.latency_ms == 0.0 {
                Ok(None)
            } else {
                demo_plan(
                    &args.config,
                    &zero_overrides,
                    vic::planning::plan::Method::Ilqg,
                    &dir,
                    reuse,
                )
                .map(Some)
            };
            (delayed, zero)
        });
        let b = match b.join() {
            Ok((x, y)) => (Ok(x), Ok(y)),
            Err(_) => (Err(()), Err(())),
        };
        (a.join(), b)
    });
    let sooc = sooc.map_err(|_| Failure::runtime("planning panicked"))??;
    let ilqg = ilqg.map_err(|_| Failure::runtime("planning panicked"))??;
    let ilqg0 = ilqg0.map_err(|_| Failure::runtime("planning panicked"))??;

    let mut guard = vic::rt::daemon::Children::new(&namespace);
    let mut board = Proc::new(&board_bin);
    board
        .arg("--config")
        .arg(&args.config)
        .args(["--namespace", &namespace, "--json"])
        .args(["--spin-us", &args.spin_us.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for o in &args.overrides {
        board.args(["--set", o]);
    }
    guard.children.push(
        board
            .spawn()
            .map_err(|e| Failure::runtime(format!("cannot start {}: {e}", board_bin.display())))?,
    );
    let mut results = Vec::new();
    let mut runs = vec![
        ("stiffness", &sooc, args.latency_ms, 50),
        ("delayed-feedback", &ilqg, args.latency_ms, 50),
    ];
    if let Some(p) = &ilqg0 {
        runs.push(("delayed-feedback", p, 0.0, 250));
    }
    for (name, plan_path, latency_ms, rate_hz) in runs {
        let mut p = Proc::new(&planner_bin);
        p.arg("--config")
            .arg(&args.config)
            .arg("--plan")
            .arg(plan_path)
            .args(["--strategy", name, "--namespace", &namespace, "--json"])
            .args(["--trials", &args.trials.to_string()])
            .args(["--seed", &args.seed.to_string()])
            .args(["--latency-ms", &latency_ms.to_string()])
            .args(["--rate-hz", &rate_hz.to_string()])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        for o in &args.overrides {
            p.args(["--set", o]);
        }
        let out = p
            .output()
            .map_err(|e| Failure::runtime(format!("cannot run {}: {e}", planner_bin.display())))?;
        if !out.status.success() {
            return Err(Failure::runtime(format!(
                "vic-planner --strategy {name} failed ({})",
                out.status
            )));
        }
        let r: vic::tools::report::StrategyResult = serde_json::from_slice(&out.stdout)
            .map_err(|e| Failure::runtime(format!("vic-planner printed no result: {e}")))?;
        results.push(r);
    }
    // Stop the board: it prints its statistics at the end of the current tick.
    let mut child = guard.children.pop().expect("the board");
    vic::rt::daemon::Children::terminate(&mut child);
    let mut stdout = String::new();
    if let Some(mut s) = child.stdout.take() {
        use std::io::Read;
        let _ = s.read_to_string(&mut stdout);
    }
    let stats: serde_json::Value = serde_json::from_str(stdout.trim())
        .map_err(|e| Failure::runtime(format!("the board printed no statistics: {e}")))?;
    drop(guard);
    if args.plans_dir.is_none() {
        let _ = std::fs::remove_dir_all(&tmp_dir);
    }
    let leftover = vic::rt::transport::namespace_files(&namespace);
    let strategies: Vec<serde_json::Value> = results
        .iter()
        .map(|r| {
            let mut v = serde_json::to_value(r).unwrap_or_default();
            v["jitter_us"] = stats["jitter_us"].clone();
            v["work_us"] = stats["work_us"].clone();
            v["command_age_us"] = stats["command_age_us"].clone();
            v["late_ticks"] = stats["late_ticks"].clone();
            v
        })
        .collect();
    if args.json {
        let doc = serde_json::json!({
            "config": args.config.display().to_string(),
            "overrides": args.overrides,
            "latency_ms": args.latency_ms,
            "trials": args.trials,
            "seed": args.seed,
            "strategies": strategies,
            "board": stats,
            "leftover_shm_files": leftover,
        });
        println!("{doc}");
        return Ok(());
    }
    let unit = results.first().map_or("mm".to_string(), |r| r.unit.clone());
    println!(
        "{:<17} {:>8} {:>10} {:>12} {:>10} {:>9} {:>26} {:>6}",
        "strategy",
        "latency",
        "RMS error",
        "final error",
        "max error",
        "diverged",
        "jitter p50/p99/max [µs]",
        "late"
    );
    let j = &stats["jitter_us"];
    let f = |v: f64| {
        if v >= 1e9 {
            "diverged".to_string()
        } else {
            format!("{v:.2} {unit}")
        }
    };
    for r in &results {
        println!(
            "{:<17} {:>5} ms {:>10} {:>12} {:>10} {:>5} / {:<2} {:>8.1} /{:>7.1} /{:>8.1} {:>6}",
            r.name,
            r.latency_ms,
            f(r.rms_error),
            f(r.final_error_max),
            f(r.max_error),
            r.diverged,
            r.trials,
            j["p50"].as_f64().unwrap_or(f64::NAN),
            j["p99"].as_f64().unwrap_or(f64::NAN),
            j["max"].as_f64().unwrap_or(f64::NAN),
            stats["late_ticks"]
        );
    }
    let w = &stats["work_us"];
    let a = &stats["command_age_us"];
    println!(
        "board: {} ticks, work p50 {:.1} / p99 {:.1} µs, command age p50 {:.0} / p99 {:.0} µs; final error = max over trials",
        stats["ticks"],
        w["p50"].as_f64().unwrap_or(f64::NAN),
        w["p99"].as_f64().unwrap_or(f64::NAN),
        a["p50"].as_f64().unwrap_or(f64::NAN),
        a["p99"].as_f64().unwrap_or(f64::NAN),
    );
    if !leftover.is_empty() {
        eprintln!("vic: warning: files left in /dev/shm: {leftover:?}");
    }
    Ok(())
}

#[derive(clap::Args)]
struct BenchArgs {
    #[command(subcommand)]
    which: BenchCommand,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// The board's periodic loop at 1 kHz with its real work (the scenario's plant, a 50 Hz
    /// planner thread streaming hold commands over the transport), under each option real-time
    /// loops use: default vs 1 ns timer slack, a 100 µs spin before the deadline, mlockall, CPU
    /// pinning, SCHED_FIFO 80 (when permitted). Then cyclictest -i1000 for the same duration
    /// (default scheduler, and -p80 when a FIFO variant ran). Runs are sequential; the whole
    /// bench takes about (variants + 2) × --seconds.
    ///
    /// Reports wake-up lateness (p50/p99/p99.9/max), tick work and CPU use per variant, and the
    /// ratio to cyclictest's p99. Without cyclictest (`apt-get install rt-tests`) it runs vic
    /// only and the JSON's "baseline" is null.
    ///
    /// Example: vic bench loop --seconds 30 --json
    Loop(BenchLoopArgs),
    /// One-way and round-trip latency of the state and command channels (vic's Endpoint, real
    /// message types) against a bare iceoryx2 publish/subscribe ping-pong with the same payload
    /// sizes, both as two busy-polling threads; then the running vic-board + vic-planner pair:
    /// state age at a reader, command age at the board, pulse-injection-to-effect.
    ///
    /// Example: vic bench ipc --iterations 100000 --json
    Ipc(BenchIpcArgs),
}

#[derive(clap::Args)]
struct BenchLoopArgs {
    /// Seconds per variant and per cyclictest run.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..=3600))]
    seconds: u64,
    /// Run only these variants (repeatable or comma-separated): sleep-slack50, sleep, spin,
    /// spin-mlock, spin-mlock-pin, fifo, fifo-spin.
    #[arg(long = "variant", value_name = "NAME", value_delimiter = ',')]
    variants: Vec<String>,
    /// Skip cyclictest (the JSON's "baseline" is null).
    #[arg(long)]
    no_baseline: bool,
    /// Fail (exit 1) when cyclictest is not installed, instead of running vic only.
    #[arg(long, conflicts_with = "no_baseline")]
    require_baseline: bool,
    /// Scenario whose plant the board integrates (impedance actuator).
    #[arg(
        long,
        short,
        value_name = "FILE",
        default_value = "config/two_link_divergent.toml"
    )]
    config: PathBuf,
    /// Override a configuration key (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Print one JSON object: {"vic": {p50_us, p99_us, p999_us, max_us, cpu_percent, …},
    /// "baseline": {…} or null, "ratio_p99": …, "variants": […], …}.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct BenchIpcArgs {
    /// Ping-pongs per transport (after 1000 not recorded).
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    iterations: u64,
    /// Trials of the running pair (about 1.5 s each; 0 skips the pair).
    #[arg(long, default_value_t = 5)]
    pair_trials: u64,
    /// Scenario of the pair.
    #[arg(
        long,
        short,
        value_name = "FILE",
        default_value = "config/two_link_divergent.toml"
    )]
    config: PathBuf,
    /// Overrides for the pair's board and planner.
    #[arg(
        long = "set",
        value_name = "SECTION.KEY=VALUE",
        default_value = "noise.sigma=0.02"
    )]
    overrides: Vec<String>,
    /// SOOC plan the pair's planner plays (stiffness strategy).
    #[arg(
        long,
        value_name = "FILE",
        default_value = "tests/data/realtime/two_link_divergent_sigma002_sooc.json"
    )]
    plan: PathBuf,
    /// Print one JSON object: {"vic": {p50_us, p99_us, …}, "baseline": {…}, "ratio_p50": …,
    /// "pair": {…}, …} (one-way latency of the state channel in the summary).
    #[arg(long)]
    json: bool,
}

/// `vic bench loop` and `vic bench ipc`: parse, call the library, print.
fn run_bench(args: BenchArgs) -> Result<(), Failure> {
    let progress = |json: bool| {
        move |m: &str| {
            if !json {
                eprintln!("running: {m}");
            }
        }
    };
    match args.which {
        BenchCommand::Loop(a) => {
            if !a.config.is_file() {
                return Err(Failure::input(format!(
                    "{}: no such scenario file",
                    a.config.display()
                )));
            }
            if a.require_baseline && vic::tools::bench::cyclictest::find().is_none() {
                return Err(Failure::runtime(format!(
                    "cyclictest not found: {}",
                    vic::tools::bench::cyclictest::INSTALL_HINT
                )));
            }
            let names: Vec<&str> = vic::tools::bench::loop_bench::variants()
                .iter()
                .map(|v| v.name)
                .collect();
            if let Some(bad) = a.variants.iter().find(|v| !names.contains(&v.as_str())) {
                return Err(Failure::input(format!(
                    "--variant {bad}: choose from {}",
                    names.join(", ")
                )));
            }
            let opts = vic::tools::bench::loop_bench::Options {
                seconds: a.seconds,
                config: a.config,
                overrides: a.overrides,
                variants: a.variants,
                baseline: !a.no_baseline,
            };
            let report = vic::tools::bench::loop_bench::run(&opts, progress(a.json))
                .map_err(Failure::runtime)?;
            if a.json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(Failure::runtime)?
                );
            } else {
                vic::tools::bench::loop_bench::print(&report);
            }
        }
        BenchCommand::Ipc(a) => {
            let pair = if a.pair_trials == 0 {
                None
            } else {
                if !a.plan.is_file() {
                    return Err(Failure::input(format!(
                        "--plan {}: no such file (make one with `vic plan --method sooc --out FILE`, \
                         or skip the running pair with --pair-trials 0)",
                        a.plan.display()
                    )));
                }
                Some(vic::tools::bench::ipc::PairOptions {
                    board_bin: sibling_binary("vic-board")?,
                    planner_bin: sibling_binary("vic-planner")?,
                    config: a.config,
                    overrides: a.overrides,
                    plan: a.plan,
                    trials: a.pair_trials,
                })
            };
            let opts = vic::tools::bench::ipc::Options {
                iterations: a.iterations,
                pair,
            };
            let report =
                vic::tools::bench::ipc::run(&opts, progress(a.json)).map_err(Failure::runtime)?;
            if a.json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(Failure::runtime)?
                );
            } else {
                vic::tools::bench::ipc::print(&report);
            }
        }
    }
    Ok(())
}
