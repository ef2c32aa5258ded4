//! Running the real daemons in tests: plans from fixtures, unique namespaces, and a guard that
//! kills every child and removes the namespaces' files whatever happens.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use vic::views::report::StrategyResult;

pub const CONFIG: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/config/two_link_divergent.toml"
);
/// At the paper's σ = 0.05 the SOOC plan's final spread is 6.5 mm (1 σ); at 0.02 it is 2.6 mm, so
/// "every trial within 1 cm" is a sharp test rather than a lottery.
pub const SIGMA: &str = "noise.sigma=0.02";

/// The fixture plan if it still loads with this version of the code, else a fresh one (cached in
/// the target folder).
pub fn plan_or_fixture(fixture: &str, method: &str, extra: &[&str]) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/realtime")
        .join(fixture);
    let loads = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str::<vic_plan::plan::PlanFile>(&t).ok())
        .is_some();
    if loads {
        return path;
    }
    let cached = Path::new(env!("CARGO_TARGET_TMPDIR")).join(fixture);
    if !cached.is_file() {
        let mut c = Command::new(env!("CARGO_BIN_EXE_vic"));
        c.args([
            "plan", "--config", CONFIG, "--method", method, "--set", SIGMA,
        ])
        .arg("--out")
        .arg(&cached);
        for e in extra {
            c.arg(e);
        }
        assert!(c.status().unwrap().success(), "vic plan failed");
    }
    cached
}

/// The SOOC plan (stiffness strategy) at σ = 0.02.
pub fn sooc_plan() -> PathBuf {
    plan_or_fixture("two_link_divergent_sigma002_sooc.json", "sooc", &[])
}

/// The ILQG plan for a 200 ms delay without stiffness (delayed-feedback strategy) at σ = 0.02.
pub fn ilqg_plan() -> PathBuf {
    plan_or_fixture(
        "two_link_divergent_sigma002_ilqg200_k0.json",
        "ilqg",
        &["--latency-ms", "200", "--set", "actuator.stiffness_max=0"],
    )
}

/// The ILQG plan for no delay without stiffness (delayed feedback at 0 ms) at σ = 0.02.
pub fn ilqg0_plan() -> PathBuf {
    plan_or_fixture(
        "two_link_divergent_sigma002_ilqg0_k0.json",
        "ilqg",
        &["--set", "actuator.stiffness_max=0"],
    )
}

/// A namespace no other test (or test run) uses.
pub fn unique_namespace(tag: &str) -> String {
    format!(
        "{tag}{}x{}",
        std::process::id(),
        vic_rt::transport::monotonic_ns() % 1_000_000
    )
}

/// Children and namespaces that must not outlive the test.
#[derive(Default)]
pub struct Daemons {
    pub children: Vec<Child>,
    pub namespaces: Vec<String>,
}

impl Daemons {
    /// Starts `vic-board` at σ = 0.02 in `ns` with `extra` arguments (stdout piped: its JSON
    /// statistics; stderr piped).
    pub fn board(&mut self, ns: &str, extra: &[&str]) -> usize {
        if !self.namespaces.iter().any(|n| n == ns) {
            self.namespaces.push(ns.to_string());
        }
        let child = Command::new(env!("CARGO_BIN_EXE_vic-board"))
            .args([
                "--config",
                CONFIG,
                "--set",
                SIGMA,
                "--namespace",
                ns,
                "--json",
            ])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        self.children.push(child);
        self.children.len() - 1
    }

    /// Starts `vic-planner` in the background (stdout piped).
    pub fn planner(&mut self, ns: &str, plan: &Path, strategy: &str, trials: usize) -> usize {
        let child = planner_command(ns, plan, strategy, trials)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        self.children.push(child);
        self.children.len() - 1
    }

    pub fn pid(&self, i: usize) -> libc::pid_t {
        self.children[i].id() as libc::pid_t
    }

    /// Sends `signal` to child `i` and waits for it; returns its exit status and output.
    pub fn signal_and_wait(&mut self, i: usize, signal: libc::c_int) -> std::process::Output {
        // SAFETY: kill(2) on a child we spawned and have not reaped.
        unsafe { libc::kill(self.pid(i), signal) };
        let child = std::mem::replace(&mut self.children[i], Command::new("true").spawn().unwrap());
        child.wait_with_output().unwrap()
    }

    /// Waits for child `i` to exit by itself.
    pub fn wait(&mut self, i: usize) -> std::process::Output {
        let child = std::mem::replace(&mut self.children[i], Command::new("true").spawn().unwrap());
        child.wait_with_output().unwrap()
    }
}

impl Drop for Daemons {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        for ns in &self.namespaces {
            vic_rt::transport::remove_namespace(ns);
        }
    }
}

/// The `vic-planner` command line for a live run (200 ms latency, seed 11).
pub fn planner_command(ns: &str, plan: &Path, strategy: &str, trials: usize) -> Command {
    planner_command_at(ns, plan, strategy, trials, "200")
}

/// The same at another feedback latency [ms].
pub fn planner_command_at(
    ns: &str,
    plan: &Path,
    strategy: &str,
    trials: usize,
    latency_ms: &str,
) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_vic-planner"));
    c.args([
        "--config",
        CONFIG,
        "--set",
        SIGMA,
        "--namespace",
        ns,
        "--json",
    ])
    .arg("--plan")
    .arg(plan)
    .args([
        "--strategy",
        strategy,
        "--latency-ms",
        latency_ms,
        "--seed",
        "11",
    ])
    .args(["--trials", &trials.to_string()]);
    c
}

/// Runs `vic-planner` to the end and returns its results.
pub fn run_planner(
    ns: &str,
    plan: &Path,
    strategy: &str,
    trials: usize,
    lockstep: bool,
) -> StrategyResult {
    let mut c = planner_command(ns, plan, strategy, trials);
    if lockstep {
        c.arg("--lockstep");
    }
    // Its log is kept and repeated in the failure message, which the harness prints last:
    // interleaved with the other tests' output it may be cut off.
    let out = c.stderr(Stdio::piped()).output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    eprint!("{log}");
    assert!(
        out.status.success(),
        "vic-planner {strategy} in namespace {ns} failed ({}):\n{log}",
        out.status
    );
    serde_json::from_slice(&out.stdout).unwrap()
}
