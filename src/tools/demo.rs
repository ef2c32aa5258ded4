//! `vic demo`: the real-time pair end to end. It plans the two strategies of the paper's delay
//! experiment (SOOC torque and stiffness for `stiffness`; ILQG for the latency with zero stiffness
//! for `delayed-feedback`, Eq. 13; and delayed feedback planned for 0 ms as the reference), starts
//! a `vic-board` and one `vic-planner` per strategy in a fresh namespace with the same noise seeds,
//! stops the board so that it prints its timing, and merges everything into one table or JSON
//! document. The processes and the namespace's files do not outlive the run, however it ends.

use crate::planning::plan::{Method, PLAN_VERSION, plan};
use crate::planning::scenario::Scenario;
use crate::rt::daemon::Children;
use crate::tools::cli::{Classify, sibling_binary, whole_steps};
use crate::tools::plan_command::write_plan;
use crate::tools::report::StrategyResult;
use anyhow::{Context, anyhow, bail};
use serde_json::Value;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// What `vic demo` was asked for.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// A two-link or single-joint scenario with the impedance actuator.
    pub config: PathBuf,
    /// Overrides for the plans and the board alike.
    pub overrides: Vec<String>,
    /// Feedback latency of the central controller [ms] (a whole number of plan steps).
    pub latency_ms: f64,
    /// Trials per strategy.
    pub trials: u64,
    /// Seed of the board's noise (the same for every strategy).
    pub seed: u64,
    /// Keep the plans here and reuse them on the next run (default: plan afresh).
    pub plans_dir: Option<PathBuf>,
    /// Plan files to use instead of planning.
    pub stiffness_plan: Option<PathBuf>,
    pub feedback_plan: Option<PathBuf>,
    /// Board spin before each deadline [µs] (None: the board's default).
    pub spin_us: Option<u64>,
    /// Start the board with `--no-rt`.
    pub no_rt: bool,
    pub json: bool,
}

/// The plan files of the strategies.
struct DemoPlans {
    stiffness: PathBuf,
    feedback: PathBuf,
    /// Delayed feedback planned for, and run at, 0 ms (absent when the latency is 0 already).
    feedback_at_zero: Option<PathBuf>,
}

/// One planner run: a strategy, its plan, its latency and the planner's rate.
struct StrategyRun<'a> {
    name: &'static str,
    plan: &'a Path,
    latency_ms: f64,
    rate_hz: u64,
}

/// Plans, runs every strategy against one board, prints the comparison and the board's timing.
pub fn run(o: &DemoOptions) -> anyhow::Result<()> {
    let scenario = Scenario::load(&o.config, &o.overrides).input()?;
    whole_steps("--latency-ms", o.latency_ms, scenario.task.dt * 1000.0)?;
    let board_bin = sibling_binary("vic-board")?;
    let planner_bin = sibling_binary("vic-planner")?;
    let namespace = format!("demo{}", std::process::id());
    let store = PlanStore::new(o.plans_dir.as_deref(), &namespace)?;
    let plans = plan_strategies(o, &store)?;
    let mut children = Children::new(&namespace);
    children
        .children
        .push(start_board(o, &board_bin, &namespace)?);
    let results = strategy_runs(o, &plans)
        .iter()
        .map(|r| run_planner(o, &planner_bin, &namespace, r))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut board = children.children.pop().expect("the board was started");
    let stats = stop_board(&mut board)?;
    drop(children);
    drop(store);
    let leftover = crate::rt::transport::namespace_files(&namespace);
    if o.json {
        println!("{}", document(o, &results, &stats, &leftover));
        return Ok(());
    }
    print_table(&results, &stats);
    if !leftover.is_empty() {
        eprintln!("vic: warning: files left in /dev/shm: {leftover:?}");
    }
    Ok(())
}

/// Where the demo's plans go: the user's folder (reused across runs) or a temporary one (removed
/// at the end).
struct PlanStore {
    dir: PathBuf,
    reuse: bool,
}

impl PlanStore {
    fn new(plans_dir: Option<&Path>, namespace: &str) -> anyhow::Result<Self> {
        let store = match plans_dir {
            Some(d) => PlanStore {
                dir: d.to_path_buf(),
                reuse: true,
            },
            None => PlanStore {
                dir: std::env::temp_dir().join(format!("vic-{namespace}")),
                reuse: false,
            },
        };
        std::fs::create_dir_all(&store.dir)
            .map_err(|e| anyhow!("cannot create {}: {e}", store.dir.display()))?;
        Ok(store)
    }

    /// The plan of `config` with `overrides` by `method`: made afresh, or reused when the
    /// store keeps plans and holds one made from the same file text, overrides, method and
    /// plan-file version.
    fn plan(&self, config: &Path, overrides: &[String], method: Method) -> anyhow::Result<PathBuf> {
        use std::hash::{Hash, Hasher};
        let text = std::fs::read_to_string(config)
            .map_err(|e| format!("{}: cannot read: {e}", config.display()))
            .input()?;
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (text, overrides, method.name(), PLAN_VERSION).hash(&mut h);
        let path = self
            .dir
            .join(format!("{}-{:016x}.json", method.name(), h.finish()));
        if self.reuse && path.is_file() {
            return Ok(path);
        }
        let scenario = Scenario::load(config, overrides).input()?;
        let plan = plan(&scenario, method, None)
            .map_err(|e| format!("{}: {e}", config.display()))
            .input()?;
        // Written aside and renamed: a reader never sees half a plan.
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        write_plan(&plan, &tmp)?;
        std::fs::rename(&tmp, &path)
            .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
        Ok(path)
    }
}

impl Drop for PlanStore {
    fn drop(&mut self) {
        if !self.reuse {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// The plans of the strategies, the SOOC plan beside the ILQG ones on another thread.
fn plan_strategies(o: &DemoOptions, store: &PlanStore) -> anyhow::Result<DemoPlans> {
    let mut feedback_overrides = o.overrides.clone();
    feedback_overrides.push("actuator.stiffness_max=0".into());
    // The reference row: central feedback without latency (planned for none, the planner at
    // 250 Hz so that its own loop adds only a few ms): with 0 ms latency, delayed feedback works.
    let mut zero_overrides = feedback_overrides.clone();
    zero_overrides.push("task.delay_ms=0".into());
    feedback_overrides.push(format!("task.delay_ms={}", o.latency_ms));
    if std::io::stderr().is_terminal() {
        eprintln!("planning (SOOC for stiffness, ILQG for delayed feedback) ...");
    }
    let given_or_planned = |given: &Option<PathBuf>, overrides: &[String], method| match given {
        Some(p) => Ok(p.clone()),
        None => store.plan(&o.config, overrides, method),
    };
    std::thread::scope(|s| {
        let stiffness = s.spawn(|| given_or_planned(&o.stiffness_plan, &o.overrides, Method::Sooc));
        let feedback = given_or_planned(&o.feedback_plan, &feedback_overrides, Method::Ilqg);
        let feedback_at_zero = if o.latency_ms == 0.0 {
            Ok(None)
        } else {
            store
                .plan(&o.config, &zero_overrides, Method::Ilqg)
                .map(Some)
        };
        let stiffness = stiffness.join().map_err(|_| anyhow!("planning panicked"))?;
        Ok(DemoPlans {
            stiffness: stiffness?,
            feedback: feedback?,
            feedback_at_zero: feedback_at_zero?,
        })
    })
}

fn strategy_runs<'a>(o: &DemoOptions, plans: &'a DemoPlans) -> Vec<StrategyRun<'a>> {
    let mut runs = vec![
        StrategyRun {
            name: "stiffness",
            plan: &plans.stiffness,
            latency_ms: o.latency_ms,
            rate_hz: 50,
        },
        StrategyRun {
            name: "naive-delayed",
            plan: &plans.feedback,
            latency_ms: o.latency_ms,
            rate_hz: 50,
        },
    ];
    if let Some(p) = &plans.feedback_at_zero {
        runs.push(StrategyRun {
            name: "naive-delayed",
            plan: p,
            latency_ms: 0.0,
            rate_hz: 250,
        });
    }
    runs
}

/// `--config FILE --set ...` for a child process.
fn scenario_args(cmd: &mut Command, o: &DemoOptions) {
    cmd.arg("--config").arg(&o.config);
    for s in &o.overrides {
        cmd.args(["--set", s]);
    }
}

/// Starts `vic-board` in `namespace`, its statistics (JSON) piped.
fn start_board(o: &DemoOptions, bin: &Path, namespace: &str) -> anyhow::Result<Child> {
    let mut cmd = Command::new(bin);
    scenario_args(&mut cmd, o);
    cmd.args(["--namespace", namespace, "--json"]);
    if let Some(spin) = o.spin_us {
        cmd.args(["--spin-us", &spin.to_string()]);
    }
    if o.no_rt {
        cmd.arg("--no-rt");
    }
    cmd.stdout(Stdio::piped()).stderr(Stdio::inherit());
    cmd.spawn()
        .map_err(|e| anyhow!("cannot start {}: {e}", bin.display()))
}

/// Runs `vic-planner` for one strategy to the end and reads its result.
fn run_planner(
    o: &DemoOptions,
    bin: &Path,
    namespace: &str,
    run: &StrategyRun,
) -> anyhow::Result<StrategyResult> {
    let mut cmd = Command::new(bin);
    scenario_args(&mut cmd, o);
    cmd.arg("--plan")
        .arg(run.plan)
        .args(["--strategy", run.name, "--namespace", namespace, "--json"])
        .args(["--trials", &o.trials.to_string()])
        .args(["--seed", &o.seed.to_string()])
        .args(["--latency-ms", &run.latency_ms.to_string()])
        .args(["--rate-hz", &run.rate_hz.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let out = cmd
        .output()
        .map_err(|e| anyhow!("cannot run {}: {e}", bin.display()))?;
    if !out.status.success() {
        bail!(
            "vic-planner --strategy {} failed ({})",
            run.name,
            out.status
        );
    }
    serde_json::from_slice(&out.stdout).context("vic-planner printed no result")
}

/// Stops the board (it prints its statistics at the end of the current tick) and reads them.
fn stop_board(board: &mut Child) -> anyhow::Result<Value> {
    use std::io::Read;
    Children::terminate(board);
    let mut stdout = String::new();
    if let Some(mut s) = board.stdout.take() {
        let _ = s.read_to_string(&mut stdout);
    }
    serde_json::from_str(stdout.trim()).context("the board printed no statistics")
}

/// The JSON document: the run's parameters, every strategy with the board's timing, the board's
/// statistics and what was left in /dev/shm.
fn document(
    o: &DemoOptions,
    results: &[StrategyResult],
    stats: &Value,
    leftover: &[String],
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
        "config": o.config.display().to_string(),
        "overrides": o.overrides,
        "latency_ms": o.latency_ms,
        "trials": o.trials,
        "seed": o.seed,
        "strategies": strategies,
        "board": stats,
        "leftover_shm_files": leftover,
    })
}

fn print_table(results: &[StrategyResult], stats: &Value) {
    let unit = results
        .first()
        .map_or(crate::planning::unit::Unit::Millimetre, |r| r.unit);
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
    let num = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let j = &stats["jitter_us"];
    let f = |v: Option<f64>| v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.2} {unit}"));
    for r in results {
        println!(
            "{:<17} {:>5} ms {:>10} {:>12} {:>10} {:>5} / {:<2} {:>8.1} /{:>7.1} /{:>8.1} {:>6}",
            r.name,
            r.latency_ms,
            f(r.rms_error),
            f(r.final_error_max),
            f(r.max_error),
            r.diverged,
            r.trials,
            num(&j["p50"]),
            num(&j["p99"]),
            num(&j["max"]),
            stats["late_ticks"]
        );
    }
    let w = &stats["work_us"];
    let a = &stats["command_age_us"];
    println!(
        "board: {} ticks, work p50 {:.1} / p99 {:.1} µs, command age p50 {:.0} / p99 {:.0} µs; final error = max over trials",
        stats["ticks"],
        num(&w["p50"]),
        num(&w["p99"]),
        num(&a["p50"]),
        num(&a["p99"]),
    );
    // The board says which real-time settings were in force (vic-board's `realtime`).
    if let Ok(rt) =
        serde_json::from_value::<crate::rt::sched::RtSettings>(stats["realtime"].clone())
    {
        println!("board real-time settings: {}", rt.describe());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(latency_ms: f64) -> DemoOptions {
        DemoOptions {
            config: "config/two_link_divergent.toml".into(),
            overrides: vec![],
            latency_ms,
            trials: 1,
            seed: 1,
            plans_dir: None,
            stiffness_plan: None,
            feedback_plan: None,
            spin_us: None,
            no_rt: false,
            json: true,
        }
    }

    #[test]
    fn the_zero_latency_reference_runs_only_when_the_latency_is_not_zero() {
        let plans = DemoPlans {
            stiffness: "s.json".into(),
            feedback: "f.json".into(),
            feedback_at_zero: Some("f0.json".into()),
        };
        let runs = strategy_runs(&options(200.0), &plans);
        let rows: Vec<_> = runs
            .iter()
            .map(|r| (r.name, r.latency_ms, r.rate_hz))
            .collect();
        assert_eq!(
            rows,
            [
                ("stiffness", 200.0, 50),
                ("naive-delayed", 200.0, 50),
                ("naive-delayed", 0.0, 250)
            ]
        );
        let plans = DemoPlans {
            feedback_at_zero: None,
            ..plans
        };
        assert_eq!(strategy_runs(&options(0.0), &plans).len(), 2);
    }

    #[test]
    fn a_temporary_plan_store_is_removed_and_a_kept_one_is_not() {
        let ns = format!("demotest{}", std::process::id());
        let tmp = PlanStore::new(None, &ns).unwrap();
        let dir = tmp.dir.clone();
        assert!(dir.is_dir());
        drop(tmp);
        assert!(!dir.exists());
        let kept = std::env::temp_dir().join(format!("vic-kept-{ns}"));
        drop(PlanStore::new(Some(&kept), &ns).unwrap());
        assert!(kept.is_dir());
        std::fs::remove_dir_all(&kept).unwrap();
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
        let doc = document(&options(200.0), &[result], &stats, &[]);
        let s = &doc["strategies"][0];
        assert_eq!(s["late_ticks"], 4);
        assert_eq!(s["work_us"]["p50"], 2.0);
        assert_eq!(doc["board"]["ticks"], 5);
        assert_eq!(doc["latency_ms"], 200.0);
    }
}
