//! `vic demo`: the real-time pair end to end. It plans the strategies of the delay experiment
//! (SOOC torque and stiffness for `stiffness`; ILQG for the latency with zero stiffness for
//! `naive-delayed`, Eq. 13; undelayed ILQG with zero stiffness for `predictor`, which predicts
//! across the latency, and for the reference row: naive-delayed at 0 ms; undelayed ILQG with
//! stiffness for `stiffness+predictor`; `replan` re-solves the SOOC plan every period on a worker
//! thread beside the 50 Hz loop), starts a `vic-board`
//! and one `vic-planner` per strategy in a fresh namespace with the same noise seeds, stops the
//! board so that it prints its timing, and merges everything into one table or JSON document.
//! The trials' hand paths (joint angles for a single joint) per strategy go into a figure beside
//! the table's JSON in `--out-dir`. The processes and the namespace's files do not outlive the
//! run, however it ends.

mod distributed;
mod verdict;

use crate::cli::{Classify, DefaultScenarioArgs, JsonArg, SeedArgs, latency_arg, sibling_binary};
use crate::daemons::live::{
    BoardFlags, PlanStore, PlannerRun, ScenarioFile, run_planner, start_board, stop_board,
};
use crate::studies::experiment::column_plot;
use crate::views::plot::Caption;
use crate::views::report::{StrategyResult, Trajectories};
use anyhow::anyhow;
use distributed::{DistributedLink, describe};
use serde_json::Value;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use vic_plan::plan::PlanFile;
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Latency, Strategy, StrategyPlan};
use vic_plan::unit::Unit;
use vic_rt::daemon::Children;

/// What `vic demo` was asked for: its flags.
#[derive(clap::Args)]
#[command(
    mut_arg("config", |a| a.help(
        "Scenario file (TOML): a two-link or single-joint plant with the impedance actuator"
    )),
    mut_arg("overrides", |a| a.help(
        "Override a configuration key (repeatable), for the plans and the board alike"
    )),
    mut_arg("seed", |a| a.help("Seed of the board's noise (the same for every strategy) [range: 0 to 18446744073709551615]")),
    mut_arg("json", |a| a.help("Print one JSON object instead of the table")),
)]
pub(crate) struct Args {
    #[command(flatten)]
    pub(crate) scenario: DefaultScenarioArgs,
    /// Feedback latency of the central controller [ms] (a whole number of plan steps).
    /// [range: 0 to 1000]
    #[arg(long, default_value_t = 200.0, value_parser = crate::ranges::real(0.0, crate::ranges::MAX_LATENCY_MS))]
    pub(crate) latency_ms: f64,
    /// Trials per strategy. [range: 1 to 100000]
    #[arg(long, default_value_t = 3, value_parser = crate::ranges::trials(1, "a strategy needs one"))]
    pub(crate) trials: u64,
    #[command(flatten)]
    pub(crate) seed: SeedArgs,
    /// Keep the plans in this folder and reuse them on the next run (default: plan afresh).
    #[arg(long, value_name = "DIR")]
    pub(crate) plans_dir: Option<PathBuf>,
    /// Use this plan for the `stiffness` strategy instead of planning (SOOC, `vic plan --out`).
    #[arg(long, value_name = "FILE")]
    pub(crate) stiffness_plan: Option<PathBuf>,
    /// Use this plan for `naive-delayed` instead of planning (ILQG for the latency, zero
    /// stiffness).
    #[arg(long, value_name = "FILE")]
    pub(crate) feedback_plan: Option<PathBuf>,
    /// Folder for the trajectories figure (trajectories.png and .svg: hand paths per strategy,
    /// like the paper's Fig. 1), the table as JSON (demo.json) and each strategy's trials.
    #[arg(long, value_name = "DIR", default_value = "vic-demo")]
    pub(crate) out_dir: PathBuf,
    /// Board spin before each deadline [µs] (default: the board's, 100; 0 with --no-rt).
    /// [range: 0 to 10000]
    #[arg(long, value_name = "US", value_parser = crate::ranges::whole(0u64, crate::ranges::MAX_SPIN_US))]
    pub(crate) spin_us: Option<u64>,
    /// Run the board without its real-time settings (no SCHED_FIFO, pinning or spin).
    #[arg(long)]
    pub(crate) no_rt: bool,
    /// Board and planners as two hosts: two namespaces joined by `vic bridge`s over Zenoh on
    /// loopback; the table adds the link's round trip (feature `zenoh`).
    #[arg(long)]
    pub(crate) distributed: bool,
    /// Run only this strategy (e.g. stiffness; every plan is still made).
    #[arg(long, value_name = "STRATEGY", value_parser = Strategy::from_name)]
    pub(crate) only: Option<Strategy>,
    #[command(flatten)]
    pub(crate) json: JsonArg,
}

impl Args {
    /// The scenario the board and the planners load.
    fn scenario_file(&self) -> ScenarioFile<'_> {
        ScenarioFile {
            config: &self.scenario.config,
            overrides: &self.scenario.set.overrides,
        }
    }
}

/// The plan files of the strategies.
struct DemoPlans {
    /// SOOC: `stiffness` and `replan`.
    stiffness: PathBuf,
    /// Undelayed ILQG with stiffness allowed: `stiffness+predictor`.
    stiffness_feedback: PathBuf,
    feedback: PathBuf,
    /// Delayed feedback planned for, and run at, 0 ms (absent when the latency is 0 already).
    feedback_at_zero: Option<PathBuf>,
}

/// One planner run: a strategy, its plan, its latency and the planner's rate.
struct StrategyRun<'a> {
    strategy: Strategy,
    plan: &'a Path,
    latency: Latency,
    rate_hz: u64,
}

/// Plans, runs every strategy against one board, draws the trajectories, prints the comparison
/// and the board's timing.
pub(crate) fn run(o: Args) -> anyhow::Result<()> {
    let o = &o;
    let scenario = Scenario::load(&o.scenario.config, &o.scenario.set.overrides).input()?;
    let latency = latency_arg("--latency-ms", o.latency_ms, scenario.task.dt)?;
    o.distributed.then(DistributedLink::available).transpose()?;
    let board_bin = sibling_binary("vic-board")?;
    let planner_bin = sibling_binary("vic-planner")?;
    std::fs::create_dir_all(&o.out_dir)
        .map_err(|e| format!("--out-dir {}: cannot create: {e}", o.out_dir.display()))
        .input()?;
    let namespace = format!("demo{}", std::process::id());
    let store = PlanStore::new(o.plans_dir.as_deref(), &namespace)?;
    let plans = plan_strategies(o, &store, latency)?;
    let mut runs = strategy_runs(&plans, latency);
    runs.retain(|r| o.only.is_none_or(|s| s == r.strategy));
    let mut children = Children::new(&namespace);
    let scenario_file = o.scenario_file();
    let flags = BoardFlags {
        spin_us: o.spin_us,
        no_rt: o.no_rt,
    };
    children
        .children
        .push(start_board(&board_bin, scenario_file, &namespace, flags)?);
    let link = o.distributed.then(|| DistributedLink::start(&namespace));
    let link = link.transpose()?;
    let planner_ns = link.as_ref().map_or(namespace.as_str(), |l| l.central_ns());
    let results = runs
        .iter()
        .map(|r| {
            let run = PlannerRun {
                strategy: r.strategy,
                plan: r.plan,
                latency: r.latency,
                rate_hz: r.rate_hz,
                trials: o.trials,
                seed: o.seed.seed,
                trajectories: Some(o.out_dir.join(format!("{}.json", r.stem()))),
                divergence: None,
            };
            run_planner(&planner_bin, scenario_file, planner_ns, &run)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let link = link.map(DistributedLink::stop).transpose()?;
    let mut board = children.children.pop().expect("the board was started");
    let stats = stop_board(&mut board)?;
    drop(children);
    let figure = trajectories_figure(o, &scenario, &runs)?;
    drop(store);
    let leftover = vic_rt::transport::namespace_files(&namespace);
    // The offline curve of the same scenario and seed says where the run's latency sits; the
    // live rows stand on their own if it cannot be made.
    if std::io::stderr().is_terminal() {
        eprintln!("the offline curve (Monte Carlo, predictor and stiffness, 0-300 ms) ...");
    }
    let (config, overrides) = (&o.scenario.config, &o.scenario.set.overrides);
    let offline = verdict::offline_curve(config, overrides, latency.ms(), o.seed.seed)
        .inspect_err(|e| eprintln!("vic: warning: no offline curve for the verdict: {e:#}"))
        .ok();
    let verdict = verdict::verdict(&results, latency.ms(), offline.as_ref());
    let mut doc = document(o, &results, &stats, &leftover, &figure);
    doc["link"] = link.clone().unwrap_or_default();
    doc["verdict"] = verdict.json;
    let json_path = o.out_dir.join("demo.json");
    std::fs::write(&json_path, format!("{doc:#}"))
        .map_err(|e| anyhow!("cannot write {}: {e}", json_path.display()))?;
    if o.json.json {
        println!("{doc}");
        return Ok(());
    }
    print_table(&results, &stats);
    link.inspect(|l| println!("{}", describe(l, o.latency_ms)));
    println!("strategies:");
    for line in verdict::legend(&results) {
        println!("{line}");
    }
    println!(
        "trajectories: {} (and .svg); table as JSON: {}",
        figure[0].display(),
        json_path.display()
    );
    if !leftover.is_empty() {
        eprintln!("vic: warning: files left in /dev/shm: {leftover:?}");
    }
    // Last, where a reader looks first.
    println!("verdict:");
    for line in &verdict.lines {
        println!("  {line}");
    }
    Ok(())
}

/// The trials of every run side by side, like the paper's Fig. 1 (hand paths on top) for the
/// arm, Fig. 2 for a single joint; returns the PNG and SVG paths.
fn trajectories_figure(
    o: &Args,
    scenario: &Scenario,
    runs: &[StrategyRun],
) -> anyhow::Result<[PathBuf; 2]> {
    let columns = runs
        .iter()
        .map(|r| {
            let path = o.out_dir.join(format!("{}.json", r.stem()));
            let text = std::fs::read_to_string(&path)
                .map_err(|e| anyhow!("{}: cannot read: {e}", path.display()))?;
            let traj: Trajectories = serde_json::from_str(&text)
                .map_err(|e| anyhow!("{}: not trajectories: {e}", path.display()))?;
            let plan = PlanFile::read(r.plan).input()?;
            let divergence = Unit::for_model(&scenario.model).default_divergence();
            Ok(column_plot(
                &r.label(),
                &plan,
                scenario,
                &traj.to_trials(),
                divergence,
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let png = o.out_dir.join("trajectories.png");
    let svg = o.out_dir.join("trajectories.svg");
    let caption = figure_caption(scenario, runs, o.trials);
    crate::views::plot::captioned_figure(&columns, &caption, &png, &svg)?;
    Ok([png, svg])
}

/// How a figure marks the trials that diverged.
const DIVERGED_NOTE: &str = crate::studies::experiment::DIVERGED_NOTE;

/// The figure's title and caption: what the columns are and how to read them.
fn figure_caption(scenario: &Scenario, runs: &[StrategyRun], trials: u64) -> Caption {
    let latency = runs.iter().map(|r| r.latency.ms()).fold(0.0, f64::max);
    let arm = scenario.model.dof() == 2;
    let columns: Vec<String> = runs
        .iter()
        .map(|r| match r.latency.is_zero() && latency > 0.0 {
            true => format!("{} at 0 ms (reference)", r.strategy.name()),
            false => format!("{} ({})", r.strategy.name(), r.strategy.plain()),
        })
        .collect();
    let rows = if arm {
        "Top: hand paths of every trial (grey), their mean (black), the spread across the path \
         (blue) and the 95 % ellipse of the final hand position (red). Middle: joint angles \
         and velocities. Bottom: the commands the board executed, torque and stiffness per \
         joint."
    } else {
        "Top: joint angle of every trial with the reference. Middle: velocity. Bottom: the \
         commands the board executed, torque and stiffness."
    };
    let rows = format!("{rows} {DIVERGED_NOTE}");
    Caption {
        title: format!(
            "Delayed feedback against planned stiffness at {latency} ms of feedback latency \
             (live, {trials} trial{} per column)",
            if trials == 1 { "" } else { "s" }
        ),
        text: format!("Columns, left to right: {}. {rows}", columns.join("; ")),
    }
}

/// The plans of the strategies, the SOOC plan beside the ILQG ones on another thread.
fn plan_strategies(o: &Args, store: &PlanStore, latency: Latency) -> anyhow::Result<DemoPlans> {
    if std::io::stderr().is_terminal() {
        eprintln!("planning (SOOC for stiffness, ILQG for delayed feedback) ...");
    }
    let scenario = o.scenario_file();
    let plan_for =
        |strategy: Strategy, latency| store.plan(scenario, strategy.plan_request(latency));
    let given_or_planned = |given: &Option<PathBuf>, strategy| match given {
        Some(p) => Ok(p.clone()),
        None => plan_for(strategy, latency),
    };
    std::thread::scope(|s| {
        let stiffness = s.spawn(|| given_or_planned(&o.stiffness_plan, Strategy::Stiffness));
        let stiffness_feedback = s.spawn(|| plan_for(Strategy::StiffnessPredictor, latency));
        let feedback = given_or_planned(&o.feedback_plan, Strategy::NaiveDelayed);
        // The reference row: central feedback without latency (planned for none, the planner
        // fast enough that its own loop adds one knot at most): with 0 ms latency, delayed
        // feedback works. The same plan is the predictor's undelayed one.
        let feedback_at_zero = match latency.is_zero() {
            true => Ok(None),
            false => plan_for(Strategy::NaiveDelayed, Latency::ZERO).map(Some),
        };
        let stiffness = stiffness.join().map_err(|_| anyhow!("planning panicked"))?;
        let stiffness_feedback = stiffness_feedback
            .join()
            .map_err(|_| anyhow!("planning panicked"))?;
        Ok(DemoPlans {
            stiffness: stiffness?,
            stiffness_feedback: stiffness_feedback?,
            feedback: feedback?,
            feedback_at_zero: feedback_at_zero?,
        })
    })
}

/// The rows: naive-delayed at 0 ms (the reference), then the five strategies at the latency,
/// each with the planner at the rate that gives it its offline meaning
/// ([`Timing::planner_rate_hz`]: 250 Hz at 0 ms for the feedback strategies, 50 Hz from 60 ms).
fn strategy_runs(plans: &DemoPlans, latency: Latency) -> Vec<StrategyRun<'_>> {
    let at = |strategy, plan, latency| StrategyRun {
        strategy,
        plan,
        latency,
        rate_hz: vic_rt::central::Timing::planner_rate_hz(strategy, latency),
    };
    let mut runs = Vec::new();
    if let Some(p) = &plans.feedback_at_zero {
        runs.push(at(Strategy::NaiveDelayed, p, Latency::ZERO));
    }
    // The predictor runs the undelayed plan's gains on the predicted present (at 0 ms latency
    // the feedback plan is that plan).
    let undelayed = plans.feedback_at_zero.as_ref().unwrap_or(&plans.feedback);
    runs.push(at(Strategy::NaiveDelayed, &plans.feedback, latency));
    runs.push(at(Strategy::Predictor, undelayed, latency));
    runs.push(at(Strategy::Stiffness, &plans.stiffness, latency));
    runs.push(at(
        Strategy::StiffnessPredictor,
        &plans.stiffness_feedback,
        latency,
    ));
    runs.push(at(Strategy::Replan, &plans.stiffness, latency));
    runs
}

impl StrategyRun<'_> {
    /// The column title and the file stem of this run.
    fn label(&self) -> String {
        format!("{} {} ms", self.strategy.name(), self.latency.ms())
    }
    fn stem(&self) -> String {
        format!(
            "{}-{}ms",
            self.strategy.name().replace('+', "-"),
            self.latency.ms()
        )
    }
}

/// The JSON document: the run's parameters, every strategy with the board's timing, the board's
/// statistics and what was left in /dev/shm.
fn document(
    o: &Args,
    results: &[StrategyResult],
    stats: &Value,
    leftover: &[String],
    figure: &[PathBuf; 2],
) -> Value {
    let strategies: Vec<Value> = results
        .iter()
        .map(|r| {
            let mut v = serde_json::to_value(r).unwrap_or_default();
            for key in ["jitter_us", "work_us", "command_age_us", "late_ticks"] {
                v[key] = stats[key].clone();
            }
            v
        })
        .collect();
    serde_json::json!({
        "config": o.scenario.config.display().to_string(),
        "overrides": o.scenario.set.overrides,
        "latency_ms": o.latency_ms,
        "trials": o.trials,
        "seed": o.seed.seed,
        "strategies": strategies,
        "board": stats,
        "leftover_shm_files": leftover,
        "figure": figure.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    })
}

fn print_table(results: &[StrategyResult], stats: &Value) {
    let unit = results
        .first()
        .map_or(vic_plan::unit::Unit::Millimetre, |r| r.unit);
    println!(
        "{:<19} {:>8} {:>11} {:>12} {:>11} {:>9} {:>26} {:>8}",
        "strategy",
        "latency",
        "RMS error",
        "final error",
        "max error",
        "diverged",
        "compute p50/p99/max [µs]",
        "overruns"
    );
    let num = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let f = |v: Option<f64>| v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.2} {unit}"));
    for r in results {
        let c = &r.central.compute_us;
        println!(
            "{:<19} {:>5} ms {:>11} {:>12} {:>11} {:>5} / {:<2} {:>8.1} /{:>7.1} /{:>8.1} {:>8}",
            r.name,
            r.latency_ms,
            f(r.rms_error),
            f(r.final_error_max),
            f(r.max_error),
            r.diverged,
            r.trials,
            c.p50,
            c.p99,
            c.max,
            r.central.overruns
        );
    }
    let (w, a, j) = (
        &stats["work_us"],
        &stats["command_age_us"],
        &stats["jitter_us"],
    );
    println!(
        "final error = max over trials; compute = the central loop's work per period (overrun: \
         over its period, the previous slice sent again)"
    );
    println!(
        "board: {} ticks, {} late; jitter p50 {:.1} / p99 {:.1} / max {:.1} µs, work p50 {:.1} / \
         p99 {:.1} µs, command age p50 {:.0} / p99 {:.0} µs",
        stats["ticks"],
        stats["late_ticks"],
        num(&j["p50"]),
        num(&j["p99"]),
        num(&j["max"]),
        num(&w["p50"]),
        num(&w["p99"]),
        num(&a["p50"]),
        num(&a["p99"]),
    );
    // The board says which real-time settings were in force (vic-board's `realtime`).
    if let Ok(rt) = serde_json::from_value::<vic_rt::sched::RtSettings>(stats["realtime"].clone()) {
        println!("board real-time settings: {}", rt.describe());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `vic demo --latency-ms LATENCY --trials 1 --json`, the other flags at their defaults.
    fn options(latency_ms: f64) -> Args {
        use clap::{Args as _, FromArgMatches};
        let latency = latency_ms.to_string();
        let args = ["demo", "--latency-ms", &latency, "--trials", "1", "--json"];
        let matches = Args::augment_args(clap::Command::new("demo")).get_matches_from(args);
        Args::from_arg_matches(&matches).expect("the flags parse")
    }

    #[test]
    fn the_zero_latency_reference_runs_only_when_the_latency_is_not_zero() {
        let plans = DemoPlans {
            stiffness: "s.json".into(),
            stiffness_feedback: "sf.json".into(),
            feedback: "f.json".into(),
            feedback_at_zero: Some("f0.json".into()),
        };
        let rows = |o: &Args, plans: &DemoPlans| -> Vec<(&'static str, String, f64, u64)> {
            let latency = Latency::from_ms(o.latency_ms, 0.01).expect("on the grid");
            strategy_runs(plans, latency)
                .iter()
                .map(|r| {
                    let plan = r.plan.display().to_string();
                    (r.strategy.name(), plan, r.latency.ms(), r.rate_hz)
                })
                .collect()
        };
        let row = |n, p: &str, l, r| (n, p.to_string(), l, r);
        assert_eq!(
            rows(&options(200.0), &plans),
            [
                row("naive-delayed", "f0.json", 0.0, 250),
                row("naive-delayed", "f.json", 200.0, 50),
                // The predictor plays the undelayed plan's gains.
                row("predictor", "f0.json", 200.0, 50),
                row("stiffness", "s.json", 200.0, 50),
                row("stiffness+predictor", "sf.json", 200.0, 50),
                // The replanner re-solves the stiffness plan.
                row("replan", "s.json", 200.0, 50),
            ]
        );
        let plans = DemoPlans {
            feedback_at_zero: None,
            ..plans
        };
        assert_eq!(
            rows(&options(0.0), &plans),
            [
                // At 0 ms the feedback strategies' planner is fast (its own delay fits in
                // one knot); the open-loop plan and the replanner keep the 20 ms period.
                row("naive-delayed", "f.json", 0.0, 250),
                row("predictor", "f.json", 0.0, 250),
                row("stiffness", "s.json", 0.0, 50),
                row("stiffness+predictor", "sf.json", 0.0, 250),
                row("replan", "s.json", 0.0, 50),
            ]
        );
    }

    #[test]
    fn the_document_gives_every_strategy_the_board_timing() {
        let stats = serde_json::json!({
            "jitter_us": {"p50": 1.0}, "work_us": {"p50": 2.0},
            "command_age_us": {"p50": 3.0}, "late_ticks": 4, "ticks": 5
        });
        let result: StrategyResult = serde_json::from_value(serde_json::json!({
            "name": "stiffness", "latency_ms": 200.0, "sensor_latency_ms": 90.0,
            "command_latency_ms": 90.0, "trials": 1, "unit": "mm", "rms_error": 1.0,
            "final_error_mean": 1.0, "final_error_max": 1.0, "final_errors": [1.0],
            "max_error": 2.0, "diverged": 0, "safe_hold_trials": 0, "fault_trials": 0,
            "stale_feedback": 0, "missing_states": 0, "expected_cost": 0.5
        }))
        .unwrap();
        let figure = ["t.png".into(), "t.svg".into()];
        let doc = document(&options(200.0), &[result], &stats, &[], &figure);
        let s = &doc["strategies"][0];
        assert_eq!(s["late_ticks"], 4);
        assert_eq!(s["work_us"]["p50"], 2.0);
        assert_eq!(doc["board"]["ticks"], 5);
        assert_eq!(doc["latency_ms"], 200.0);
    }
}
