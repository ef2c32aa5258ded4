//! The real daemons, run from a tool: a `vic-board` in a fresh namespace, one `vic-planner` run
//! per strategy against it, and the plan files they read. What `vic demo` and `vic sweep latency
//! --live` share: the same processes with the same flags, so a sweep point and a demo row of the
//! same strategy, latency and seed are the same run.

use crate::cli::Classify;
use crate::views::report::StrategyResult;
use anyhow::{Context, anyhow, bail};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use vic_plan::plan::{PLAN_VERSION, PlanFile};
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Latency, PlanRequest, Strategy};
use vic_rt::daemon::Children;

/// The scenario every process of a run loads: the file and the user's overrides.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ScenarioFile<'a> {
    pub(crate) config: &'a Path,
    pub(crate) overrides: &'a [String],
}

impl ScenarioFile<'_> {
    /// `--config FILE --set ...` for a child process.
    fn args(&self, cmd: &mut Command) {
        cmd.arg("--config").arg(self.config);
        for s in self.overrides {
            cmd.args(["--set", s]);
        }
    }
}

/// How the board runs: its real-time settings.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BoardFlags {
    /// Spin before each deadline [µs] (`None`: the board's default).
    pub(crate) spin_us: Option<u64>,
    /// Without SCHED_FIFO, pinning or spin.
    pub(crate) no_rt: bool,
}

/// Starts `vic-board` (`bin`) in `namespace`, its statistics (JSON) piped.
pub(crate) fn start_board(
    bin: &Path,
    scenario: ScenarioFile,
    namespace: &str,
    flags: BoardFlags,
) -> anyhow::Result<Child> {
    let mut cmd = Command::new(bin);
    scenario.args(&mut cmd);
    cmd.args(["--namespace", namespace, "--json"]);
    if let Some(spin) = flags.spin_us {
        cmd.args(["--spin-us", &spin.to_string()]);
    }
    if flags.no_rt {
        cmd.arg("--no-rt");
    }
    cmd.stdout(Stdio::piped()).stderr(Stdio::inherit());
    cmd.spawn()
        .map_err(|e| anyhow!("cannot start {}: {e}", bin.display()))
}

/// Stops the board (it prints its statistics at the end of the current tick) and reads them.
pub(crate) fn stop_board(board: &mut Child) -> anyhow::Result<Value> {
    use std::io::Read;
    Children::terminate(board);
    let mut stdout = String::new();
    if let Some(mut s) = board.stdout.take() {
        let _ = s.read_to_string(&mut stdout);
    }
    serde_json::from_str(stdout.trim()).context("the board printed no statistics")
}

/// One planner run: a strategy, its plan, its latency, the planner's rate and its trials.
#[derive(Debug, Clone)]
pub(crate) struct PlannerRun<'a> {
    pub(crate) strategy: Strategy,
    pub(crate) plan: &'a Path,
    /// The feedback latency, on the plan's grid (`--latency-ms` of the planner).
    pub(crate) latency: Latency,
    pub(crate) rate_hz: u64,
    pub(crate) trials: u64,
    pub(crate) seed: u64,
    /// Where the planner writes the trials' trajectories (`None`: nowhere).
    pub(crate) trajectories: Option<PathBuf>,
    /// The distance from the target beyond which a trial diverged (`None`: the default).
    pub(crate) divergence: Option<f64>,
}

/// Runs `vic-planner` (`bin`) for one strategy to the end in `namespace` and reads its result.
pub(crate) fn run_planner(
    bin: &Path,
    scenario: ScenarioFile,
    namespace: &str,
    run: &PlannerRun,
) -> anyhow::Result<StrategyResult> {
    let mut cmd = Command::new(bin);
    scenario.args(&mut cmd);
    cmd.arg("--plan")
        .arg(run.plan)
        .args([
            "--strategy",
            run.strategy.name(),
            "--namespace",
            namespace,
            "--json",
        ])
        .args(["--trials", &run.trials.to_string()])
        .args(["--seed", &run.seed.to_string()])
        .args(["--latency-ms", &run.latency.ms().to_string()])
        .args(["--rate-hz", &run.rate_hz.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    if let Some(t) = &run.trajectories {
        cmd.arg("--trajectories").arg(t);
    }
    if let Some(d) = run.divergence {
        cmd.args(["--divergence", &d.to_string()]);
    }
    let out = cmd
        .output()
        .map_err(|e| anyhow!("cannot run {}: {e}", bin.display()))?;
    if !out.status.success() {
        bail!(
            "vic-planner --strategy {} failed ({})",
            run.strategy.name(),
            out.status
        );
    }
    serde_json::from_slice(&out.stdout).context("vic-planner printed no result")
}

/// Where a run's plans go: the user's folder (reused across runs) or a temporary one (removed
/// at the end).
pub(crate) struct PlanStore {
    dir: PathBuf,
    reuse: bool,
}

impl PlanStore {
    pub(crate) fn new(plans_dir: Option<&Path>, namespace: &str) -> anyhow::Result<Self> {
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

    /// The folder of the plans.
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// The plan `request` asks for on `scenario`: made afresh, or reused when the store keeps
    /// plans and holds one made from the same file text, overrides, request and plan-file
    /// version.
    pub(crate) fn plan(
        &self,
        scenario: ScenarioFile,
        request: PlanRequest,
    ) -> anyhow::Result<PathBuf> {
        use std::hash::{Hash, Hasher};
        let config = scenario.config;
        let text = vic_plan::scenario::read_text(config)
            .map_err(|e| format!("{}: cannot read: {e}", config.display()))
            .input()?;
        let method = request.method.name();
        let mut h = std::collections::hash_map::DefaultHasher::new();
        let edits = (request.without_stiffness, request.delay.ms().to_bits());
        (text, scenario.overrides, method, edits, PLAN_VERSION).hash(&mut h);
        let path = self.dir.join(format!("{method}-{:016x}.json", h.finish()));
        if self.reuse && path.is_file() {
            return Ok(path);
        }
        let base = Scenario::load(config, scenario.overrides).input()?;
        let plan = request
            .plan(&base, None)
            .map_err(|e| format!("{}: {e}", config.display()))
            .input()?;
        self.save(&path, &plan)?;
        Ok(path)
    }

    /// Writes `plan` to `path`, aside and renamed: a reader never sees half a plan.
    pub(crate) fn save(&self, path: &Path, plan: &PlanFile) -> anyhow::Result<()> {
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        plan.write(&tmp).runtime()?;
        std::fs::rename(&tmp, path).map_err(|e| anyhow!("cannot write {}: {e}", path.display()))
    }
}

impl Drop for PlanStore {
    fn drop(&mut self) {
        if !self.reuse {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_temporary_plan_store_is_removed_and_a_kept_one_is_not() {
        let ns = format!("livetest{}", std::process::id());
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
}
