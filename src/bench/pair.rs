//! The running pair of `vic bench ipc`: `vic-board` and `vic-planner` as separate processes in a
//! fresh namespace, with a tool that polls their state at 1 kHz and injects torque pulses: what
//! the planner sees (state age), what the board uses (command age) and how fast a disturbance
//! takes effect.

use super::{BenchError, Dist};
use serde::Serialize;
use std::ffi::OsStr;
use std::path::PathBuf;
use std::time::Duration;
use vic_rt::realtime::{LatencyHistogram, Periodic, set_timer_slack_1ns};
use vic_rt::transport::{Disturbance, DisturbanceKind, Header, StateMsg, ToolPorts, monotonic_ns};

type Result<T, E = BenchError> = std::result::Result<T, E>;

/// Options of the end-to-end run of the pair.
#[derive(Debug, Clone)]
pub(crate) struct PairOptions {
    pub(crate) board_bin: PathBuf,
    pub(crate) planner_bin: PathBuf,
    pub(crate) config: PathBuf,
    pub(crate) overrides: Vec<String>,
    /// A plan for the `stiffness` strategy (`vic plan --method sooc --out`).
    pub(crate) plan: PathBuf,
    /// Trials the planner runs (about 1.5 s each).
    pub(crate) trials: u64,
}

/// The end-to-end figures of the running pair.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Pair {
    /// Age of the newest state at a reader polling at 1 kHz on the whole-millisecond deadlines
    /// the planner's loop uses, with the planner's subscription (now − the state's publish
    /// stamp): what the planner sees at each of its ticks.
    pub(crate) state_age_us: Dist,
    /// Age of the command slice the board used at each tick, from its own statistics (slices are
    /// sent at 50 Hz and cover 320 ms: up to 20 ms by design).
    pub(crate) command_age_us: Dist,
    /// Pulse published (at a phase spread over the period) → first board state carrying it (its
    /// publish stamp): the pulse has been applied to the plant by then.
    pub(crate) pulse_to_effect_us: Dist,
    /// Pulse published → that state received by the injecting tool.
    pub(crate) pulse_to_observed_us: Dist,
    pub(crate) pulses: u64,
    /// The board's own statistics over the run (jitter, work, command age, ticks …).
    pub(crate) board: serde_json::Value,
    pub(crate) trials: u64,
}

/// Runs `vic-board` and `vic-planner --strategy stiffness` in a fresh namespace, injects a small
/// torque pulse every 100 ms and records the state age, the pulse-to-effect delay and the board's
/// statistics.
pub(crate) fn run_pair(o: &PairOptions) -> Result<Pair> {
    let ns = super::unique_namespace("bp");
    let mut guard = vic_rt::daemon::Children::new(&ns);
    guard
        .children
        .push(spawn_daemon(o, &o.board_bin, &ns, &[])?);
    let tool = ToolPorts::open(&ns)?;
    let t0 = std::time::Instant::now();
    while tool.latest_state().is_none() {
        if t0.elapsed() > Duration::from_secs(10) {
            return Err(BenchError::Timeout(
                "vic-board published no state within 10 s",
            ));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let trials = o.trials.to_string();
    let planner_args: [&OsStr; 6] = [
        "--plan".as_ref(),
        o.plan.as_os_str(),
        "--strategy".as_ref(),
        "stiffness".as_ref(),
        "--trials".as_ref(),
        trials.as_ref(),
    ];
    guard
        .children
        .push(spawn_daemon(o, &o.planner_bin, &ns, &planner_args)?);
    let mut probe = Probe::default();
    let deadline = std::time::Instant::now() + Duration::from_secs(20 + 5 * o.trials);
    let planner = guard.children.last_mut().expect("the planner");
    let planner_status = probe.until_exit(&tool, planner, deadline)?;
    if !planner_status.success() {
        return Err(BenchError::Failed {
            command: "vic-planner".into(),
            status: planner_status,
            stderr: String::new(),
        });
    }
    guard.children.pop();
    let mut board = guard.children.pop().expect("the board");
    vic_rt::daemon::Children::terminate(&mut board);
    let mut stdout = String::new();
    if let Some(mut s) = board.stdout.take() {
        use std::io::Read;
        let _ = s.read_to_string(&mut stdout);
    }
    drop(tool);
    drop(guard);
    let stats: serde_json::Value =
        serde_json::from_str(stdout.trim()).map_err(BenchError::Statistics)?;
    Ok(probe.pair(stats, o.trials))
}

/// Starts `binary` (the board or the planner) on the pair's scenario in namespace `ns`, with
/// `--json` and the extra `args`; its statistics come back on a pipe.
fn spawn_daemon(
    o: &PairOptions,
    binary: &std::path::Path,
    ns: &str,
    args: &[&OsStr],
) -> Result<std::process::Child> {
    use std::process::{Command, Stdio};
    let mut command = Command::new(binary);
    command
        .arg("--config")
        .arg(&o.config)
        .args(args)
        .args(["--namespace", ns, "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    for s in &o.overrides {
        command.args(["--set", s]);
    }
    command
        .spawn()
        .map_err(|e| BenchError::io(format!("cannot start {}", binary.display()), e))
}

/// What the measuring tool of the pair records at 1 kHz.
#[derive(Default)]
struct Probe {
    age: LatencyHistogram,
    effect: LatencyHistogram,
    observed: LatencyHistogram,
}

impl Probe {
    /// Polls the states at 1 kHz on whole-millisecond deadlines and injects a pulse every 100 ms
    /// until `planner` exits (its status), or fails at `deadline`.
    fn until_exit(
        &mut self,
        tool: &ToolPorts,
        planner: &mut std::process::Child,
        deadline: std::time::Instant,
    ) -> Result<std::process::ExitStatus> {
        set_timer_slack_1ns();
        let mut periodic = Periodic::new(1_000_000, 0);
        let mut pulse_seq = 0u64;
        let mut pending: Option<(u64, u64)> = None;
        let mut tick = 0u64;
        loop {
            let wake = periodic.wait();
            tick += 1;
            self.drain(tool, &mut pending);
            if tick.is_multiple_of(100) && pending.is_none() {
                // At a phase spread over the period (379 µs steps), not on the board's deadlines.
                pulse_seq += 1;
                let phase = (pulse_seq * 379_000) % 900_000;
                vic_rt::realtime::sleep_until(wake.deadline_ns + phase, 0);
                let t = monotonic_ns();
                let d = Disturbance {
                    header: Header::new(pulse_seq, t),
                    kind: DisturbanceKind::Pulse as u32,
                    torque: [0.05, 0.0],
                    duration_ns: 1_000_000,
                    value: 0.0,
                    ..Default::default()
                };
                if tool.publish_disturbance(&d).is_ok() {
                    pending = Some((pulse_seq, t));
                }
            }
            if tick.is_multiple_of(50) {
                if let Some(status) = planner
                    .try_wait()
                    .map_err(|e| BenchError::io("vic-planner", e))?
                {
                    return Ok(status);
                }
                if std::time::Instant::now() > deadline {
                    return Err(BenchError::Timeout("vic-planner did not finish in time"));
                }
            }
        }
    }

    /// Takes the states that arrived: the age of the newest, and the delays of the pulse
    /// `pending` (its sequence number and publish time) once a state carries it.
    fn drain(&mut self, tool: &ToolPorts, pending: &mut Option<(u64, u64)>) {
        let mut newest: Option<StateMsg> = None;
        tool.drain_states(|s| {
            if let Some((seq, t_inject)) = *pending
                && s.disturbance_seq >= seq
            {
                self.effect
                    .record(s.header.time_ns.saturating_sub(t_inject));
                self.observed
                    .record(monotonic_ns().saturating_sub(t_inject));
                *pending = None;
            }
            newest = Some(*s);
        });
        let now = monotonic_ns();
        if let Some(s) = newest {
            self.age.record(now.saturating_sub(s.header.time_ns));
        }
    }

    /// The figures, with the board's own statistics `stats`.
    fn pair(&self, stats: serde_json::Value, trials: u64) -> Pair {
        let ca = &stats["command_age_us"];
        let f = |k: &str| ca[k].as_f64().unwrap_or(f64::NAN);
        Pair {
            state_age_us: Dist::from_histogram(&self.age),
            command_age_us: Dist {
                p50_us: f("p50"),
                p99_us: f("p99"),
                p999_us: f("p999"),
                max_us: f("max"),
                count: ca["count"].as_u64().unwrap_or(0),
            },
            pulse_to_effect_us: Dist::from_histogram(&self.effect),
            pulse_to_observed_us: Dist::from_histogram(&self.observed),
            pulses: self.effect.count(),
            board: stats,
            trials,
        }
    }
}
