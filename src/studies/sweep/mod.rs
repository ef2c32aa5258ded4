//! Delay versus stiffness as a curve: for each feedback latency and each strategy of a central
//! controller, plan (for that latency where the strategy needs it), run the Monte Carlo and
//! report how close the movements end to the target.
//!
//! The strategies: `naive-delayed` (Eq. 13: the gains of a plan made for the delay, on the state
//! seen `D` steps late, no stiffness), `predictor` (the best delayed feedback without stiffness:
//! a Smith predictor across the latency, [`Feedback::Predicted`]), `stiffness` (the open-loop
//! SOOC plan of torque and stiffness, which no latency affects), `stiffness+predictor`, and
//! `replan` (the SOOC plan re-solved at 50 Hz from the predicted present,
//! [`vic_core::replan`]). With a [`Pulse`], every trial of every strategy receives the same
//! torque pulse, which no controller knows of.
//!
//! Each point's trials run offline (the Monte Carlo on the plan's grid, Eq. 10) or, with
//! [`Engine::Lockstep`], through the real-time code: the 1 kHz board with its own plant
//! integration and the central controller with its delay lines, on a simulated clock. The
//! central controller ticks at 50 Hz, faster where its own delay (three periods) would exceed
//! the latency ([`vic_rt::central::Timing::planner_rate_hz`]): then a strategy at a latency
//! feeds back the same states offline, in lockstep and live.

pub use vic_plan::strategy::Strategy;

mod crossing;
mod lag;
mod output;
pub use crossing::{Crossing, FinalErrorCrossing};
pub(crate) use crossing::{crossing, final_error_crossings};
pub use lag::{LagPoint, LagSweep, sweep_stiffness_lag, write_lag_outputs};
pub use output::write_figure;
pub(crate) use output::{pulse_from_flags, write_outputs};
use serde::{Deserialize, Serialize};
use std::path::Path;
use vic_plan::evaluation::summarize;
pub use vic_plan::montecarlo::Pulse;
use vic_plan::montecarlo::{Trial, run_trials_disturbed};
use vic_plan::plan::{PlanError, PlanFile, plan, setup};
use vic_plan::plan_file::commanded_stiffness;
use vic_plan::prediction::predicted_cost;
use vic_plan::scenario::{ConfigError, Scenario};
use vic_plan::strategy::{Latency, LatencyError, PlanRequest, StrategyPlan};
use vic_plan::unit::Unit;

/// Why a sweep stopped.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The scenario (with the strategy's overrides) does not load: bad input.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A latency that is not a whole number of plan steps: bad input.
    #[error(transparent)]
    Latency(#[from] LatencyError),
    /// Planning or executing a strategy's plan failed.
    #[error("{strategy} at {latency_ms} ms: {source}")]
    Plan {
        strategy: &'static str,
        latency_ms: f64,
        source: PlanError,
    },
    /// The plan cannot run on the board in lockstep (an actuator the board does not run).
    #[error("{strategy} at {latency_ms} ms in lockstep: {source}")]
    Lockstep {
        strategy: &'static str,
        latency_ms: f64,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Running a point on the live daemons failed (a daemon missing or failing).
    #[error("{strategy} at {latency_ms} ms, live: {source:#}")]
    Live {
        strategy: &'static str,
        latency_ms: f64,
        source: anyhow::Error,
    },
    /// The live daemons could not be started.
    #[error("starting the live board: {0:#}")]
    LiveStart(anyhow::Error),
    /// A pulse that is not finite, starts before the movement or lasts no time: bad input.
    #[error("--pulse must be finite N m, --pulse-at-ms ≥ 0 and --pulse-ms > 0")]
    Pulse,
    /// The figure could not be drawn or written (the error names its file).
    #[error(transparent)]
    Figure(#[from] crate::views::plot::PlotError),
    /// The folder or the numbers could not be written.
    #[error("{}: {source}", path.display())]
    Write {
        path: std::path::PathBuf,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A pulse is a disturbance of the offline plant; the board takes its own (`vic inject`).
    #[error("--pulse runs offline only (the board takes no scripted pulse yet: use vic inject)")]
    PulseNotOffline,
}

impl SweepError {
    /// Whether the user's input (scenario, overrides, latencies) is at fault, not the run.
    pub fn is_input(&self) -> bool {
        matches!(
            self,
            SweepError::Config(_)
                | SweepError::Latency(_)
                | SweepError::Lockstep { .. }
                | SweepError::Pulse
                | SweepError::PulseNotOffline
        )
    }
}

/// What to sweep.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    pub latencies_ms: Vec<f64>,
    pub strategies: Vec<Strategy>,
    pub trials: usize,
    pub seed: u64,
    /// A trial ending further than this from the target (in the report's unit) diverged.
    pub divergence: Option<f64>,
    /// A torque pulse on the plant mid-movement, the same for every strategy and unknown to
    /// every controller (the disturbance-rejection variant).
    pub pulse: Option<Pulse>,
    /// Where each point's trials run.
    pub execution: Engine,
}

/// Where a point's trials run (in each, the plan is executed by its strategy's [`Feedback`]
/// at the latency).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Engine {
    /// The Monte Carlo: the plan's model on its grid (Euler–Maruyama, Eq. 10).
    #[default]
    Offline,
    /// The board (1 kHz, paper Eq. 4 and its own plant step) and the central controller
    /// (50 Hz, faster below 60 ms of latency; the latency split into its sensor and command
    /// delay lines) in lockstep on a simulated clock: the code that runs live, deterministic and as fast as it computes.
    Lockstep,
    /// The daemons themselves: one `vic-board` (real time) for the whole sweep, one
    /// `vic-planner` run per point over iceoryx2, as `vic demo` runs them. Wall-clock time:
    /// about the movement's duration per trial.
    Live,
}

/// One strategy at one latency. The errors and the Monte Carlo cost are over the trials that did
/// not diverge, `None` when every trial diverged (a diverged trial is counted, never averaged in
/// and never a sentinel number; see [`summarize`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SweepPoint {
    pub strategy: Strategy,
    pub latency_ms: f64,
    pub final_error_mean: Option<f64>,
    pub final_error_max: Option<f64>,
    /// Standard error of `final_error_mean` over the trials kept (`None` with fewer than two).
    #[serde(default)]
    pub final_error_se: Option<f64>,
    pub rms_error: Option<f64>,
    /// Trials that diverged, and their fraction.
    #[serde(default)]
    pub diverged: usize,
    pub diverged_fraction: f64,
    pub expected_cost_mc: Option<f64>,
    /// The executed policy's expected cost predicted by closed-loop covariance propagation
    /// ([`predicted_cost`]); `None` for `naive-delayed`, whose law it does not model.
    pub expected_cost_predicted: Option<f64>,
    /// Mean stiffness the trials commanded [N m/rad]: the plan's for `stiffness`, the re-solved
    /// plans' for `replan`, with the feedback's share for `stiffness+predictor`.
    pub mean_stiffness: f64,
    pub(crate) unit: Unit,
    /// Live only: what the daemons' schedule did to the trials (`None` offline and in lockstep,
    /// where nothing can be late).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) live: Option<LiveTiming>,
}

/// What the live schedule did to a point's trials, over all of them. With every count zero, each
/// state reached the central controller in its period and each slice the board, so the run is
/// the one lockstep computes on a simulated clock; a count above zero says where a loaded
/// machine made the live run differ (the feedback strategies see it, the open-loop plan not).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct LiveTiming {
    /// Knots whose feedback used a state older than the latency (its state was late).
    pub(crate) stale_feedback: usize,
    /// Knots with no state recorded.
    pub(crate) missing_states: usize,
    /// Knots whose state came from a later board tick than the knot's (a late board tick or a
    /// lost state): what was recorded and fed back there is a board period or more off.
    pub(crate) off_knot_states: usize,
    /// Knots no slice brought to the board before their time (a planner that woke late): the
    /// board may have acted on the knot before in their place. Even the open-loop plan sees it.
    #[serde(default)]
    pub(crate) late_knots: usize,
    /// Central periods whose work overran the period (the previous slice went out again).
    pub(crate) central_overruns: u64,
    /// Trials in which the board fell back to safe hold (a slice came too late).
    pub(crate) safe_hold_trials: usize,
    /// Trials that ended before their final state arrived.
    pub(crate) stalled_trials: usize,
}

impl LiveTiming {
    /// Every state and slice came in its period.
    pub(crate) fn on_schedule(&self) -> bool {
        *self == Self::default()
    }
}

/// What a point's trials measured, offline or live (the fields of [`SweepPoint`] of that name;
/// `final_error`: mean, max and the mean's standard error, `diverged`: count and fraction).
struct Measured {
    final_error: (Option<f64>, Option<f64>, Option<f64>),
    rms_error: Option<f64>,
    diverged: (usize, f64),
    expected_cost_mc: Option<f64>,
    /// Mean stiffness the trials commanded ([`commanded_stiffness`]).
    mean_stiffness: f64,
    unit: Unit,
    live: Option<LiveTiming>,
}

/// The whole curve.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Sweep {
    pub(crate) scenario: String,
    pub(crate) trials: usize,
    pub(crate) seed: u64,
    /// Where the trials ran.
    #[serde(default)]
    pub execution: Engine,
    /// The pulse every trial received, if any.
    #[serde(default)]
    pub(crate) pulse: Option<Pulse>,
    pub points: Vec<SweepPoint>,
    /// Where each feedback strategy's lead over each stiffness strategy ends, by the mean final
    /// error ([`final_error_crossings`]; empty when the sweep ran fewer than two latencies of a
    /// pair).
    #[serde(default)]
    pub crossings: Vec<FinalErrorCrossing>,
}

/// Runs the sweep on the scenario at `path` (with `overrides`); `progress` is told each point.
///
/// A plan is made once per distinct [`PlanRequest`]: `stiffness` and `replan` share the one SOOC
/// plan, `predictor` the one undelayed ILQG plan without stiffness, and only `naive-delayed` is
/// planned again for each latency (Eq. 13 needs the augmented plan).
pub fn sweep_latency(
    path: &Path,
    overrides: &[String],
    opts: &SweepOptions,
    progress: &dyn Fn(&str),
) -> Result<Sweep, SweepError> {
    if opts.execution != Engine::Offline && opts.pulse.is_some() {
        return Err(SweepError::PulseNotOffline);
    }
    let live = match opts.execution {
        Engine::Live => Some(LiveRig::start(path, overrides)?),
        _ => None,
    };
    let base = Scenario::load(path, overrides)?;
    // Plan request → the scenario and its plan; a handful of entries at most.
    let mut plans: Vec<(PlanRequest, (Scenario, PlanFile))> = Vec::new();
    let mut points = Vec::new();
    for &strategy in &opts.strategies {
        for &latency_ms in &opts.latencies_ms {
            progress(&format!("{} at {latency_ms} ms", strategy.name()));
            let plan_error = |source| SweepError::Plan {
                strategy: strategy.name(),
                latency_ms,
                source,
            };
            let latency = Latency::from_ms(latency_ms, base.task.dt)?;
            let request = strategy.plan_request(latency);
            let i = match plans.iter().position(|(r, _)| *r == request) {
                Some(i) => i,
                None => {
                    let s = request.scenario(&base);
                    let p = plan(&s, request.method, None).map_err(plan_error)?;
                    plans.push((request, (s, p)));
                    plans.len() - 1
                }
            };
            let (s, p) = &plans[i].1;
            let set = setup(s).map_err(plan_error)?;
            let feedback = strategy.feedback(latency.knots());
            let policy = p.policy(&set).map_err(plan_error)?;
            let m = match opts.execution {
                Engine::Live => {
                    let rig = live.as_ref().expect("started above");
                    let (r, trials) =
                        rig.point(i, p, strategy, latency, opts).map_err(|source| {
                            SweepError::Live {
                                strategy: strategy.name(),
                                latency_ms,
                                source,
                            }
                        })?;
                    let fraction = r.diverged as f64 / r.trials.max(1) as f64;
                    // The daemons' report has no spread: the recorded trials give it.
                    let divergence = opts
                        .divergence
                        .unwrap_or_else(|| Unit::for_model(&s.model).default_divergence());
                    let se = summarize(&set, &trials, divergence).final_error_se;
                    Measured {
                        final_error: (r.final_error_mean, r.final_error_max, se),
                        rms_error: r.rms_error,
                        diverged: (r.diverged, fraction),
                        expected_cost_mc: r.expected_cost,
                        mean_stiffness: executed_stiffness(&set, &trials),
                        unit: r.unit,
                        live: Some(LiveTiming {
                            stale_feedback: r.stale_feedback,
                            missing_states: r.missing_states,
                            off_knot_states: r.off_knot_states,
                            late_knots: r.late_knots,
                            central_overruns: r.central.overruns,
                            safe_hold_trials: r.safe_hold_trials,
                            stalled_trials: r.stalled_trials,
                        }),
                    }
                }
                Engine::Offline | Engine::Lockstep => {
                    let trials = match opts.execution {
                        Engine::Lockstep => {
                            let point = Point { strategy, latency };
                            lockstep_trials(s, &set, p, point, opts)?
                        }
                        _ => run_trials_disturbed(
                            &set,
                            &policy,
                            feedback,
                            opts.pulse.as_ref(),
                            opts.trials,
                            opts.seed,
                        ),
                    };
                    let divergence = opts
                        .divergence
                        .unwrap_or_else(|| Unit::for_model(&s.model).default_divergence());
                    let r = summarize(&set, &trials, divergence);
                    Measured {
                        final_error: (r.final_error_mean, r.final_error_max, r.final_error_se),
                        rms_error: r.rms_error,
                        diverged: (r.diverged, r.diverged_fraction),
                        expected_cost_mc: r.expected_cost_mc,
                        mean_stiffness: executed_stiffness(&set, &trials),
                        unit: r.unit,
                        live: None,
                    }
                }
            };
            points.push(SweepPoint {
                strategy,
                latency_ms,
                final_error_mean: m.final_error.0,
                final_error_max: m.final_error.1,
                final_error_se: m.final_error.2,
                rms_error: m.rms_error,
                diverged: m.diverged.0,
                diverged_fraction: m.diverged.1,
                expected_cost_mc: m.expected_cost_mc,
                expected_cost_predicted: predicted_cost(&set, &policy, feedback),
                mean_stiffness: m.mean_stiffness,
                unit: m.unit,
                live: m.live,
            });
        }
    }
    let mut sweep = Sweep {
        scenario: path.display().to_string(),
        trials: opts.trials,
        seed: opts.seed,
        execution: opts.execution,
        pulse: opts.pulse,
        points,
        crossings: Vec::new(),
    };
    sweep.crossings = final_error_crossings(&sweep);
    Ok(sweep)
}

/// The live daemons of a sweep: one board in a fresh namespace, the plans in a temporary folder
/// (one file per plan of the sweep, written when a point first needs it). Dropping it stops the
/// board and removes the namespace and the plans.
struct LiveRig<'a> {
    scenario: crate::daemons::live::ScenarioFile<'a>,
    namespace: String,
    planner: std::path::PathBuf,
    store: crate::daemons::live::PlanStore,
    _board: vic_rt::daemon::Children,
}

impl<'a> LiveRig<'a> {
    fn start(path: &'a Path, overrides: &'a [String]) -> Result<Self, SweepError> {
        use crate::cli::sibling_binary;
        use crate::daemons::live::{BoardFlags, PlanStore, ScenarioFile, start_board};
        let namespace = format!("sweep{}", std::process::id());
        let scenario = ScenarioFile {
            config: path,
            overrides,
        };
        let board_bin = sibling_binary("vic-board").map_err(SweepError::LiveStart)?;
        let planner = sibling_binary("vic-planner").map_err(SweepError::LiveStart)?;
        let store = PlanStore::new(None, &namespace).map_err(SweepError::LiveStart)?;
        let mut board = vic_rt::daemon::Children::new(&namespace);
        let child = start_board(&board_bin, scenario, &namespace, BoardFlags::default())
            .map_err(SweepError::LiveStart)?;
        board.children.push(child);
        Ok(LiveRig {
            scenario,
            namespace,
            planner,
            store,
            _board: board,
        })
    }

    /// Runs the trials of one point: plan number `i` of the sweep (`plan`) with `strategy` at
    /// `latency`, the central controller at the rate that gives the strategy its offline meaning
    /// ([`vic_rt::central::Timing::planner_rate_hz`]).
    fn point(
        &self,
        i: usize,
        plan: &PlanFile,
        strategy: Strategy,
        latency: Latency,
        opts: &SweepOptions,
    ) -> anyhow::Result<(crate::views::report::StrategyResult, Vec<Trial>)> {
        use crate::daemons::live::{PlannerRun, run_planner};
        let file = self.store.dir().join(format!("plan-{i}.json"));
        if !file.is_file() {
            self.store.save(&file, plan)?;
        }
        let traj = self.store.dir().join("trajectories.json");
        let run = PlannerRun {
            strategy,
            plan: &file,
            latency,
            rate_hz: vic_rt::central::Timing::planner_rate_hz(strategy, latency),
            trials: opts.trials as u64,
            seed: opts.seed,
            trajectories: Some(traj.clone()),
            divergence: opts.divergence,
        };
        let result = run_planner(&self.planner, self.scenario, &self.namespace, &run)?;
        let text = std::fs::read_to_string(&traj)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", traj.display()))?;
        let trajectories: crate::views::report::Trajectories = serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: not trajectories: {e}", traj.display()))?;
        Ok((result, trajectories.to_trials()))
    }
}

/// The mean stiffness `trials` commanded on `set`'s model (the plan's for `stiffness`, the new
/// plans' for `replan`, the feedback's for `stiffness+predictor`).
fn executed_stiffness(set: &vic_plan::plan::Setup, trials: &[Trial]) -> f64 {
    commanded_stiffness(&set.dynamics.model, trials.iter().flat_map(|t| &t.u)).1
}

/// One point of the sweep.
#[derive(Debug, Clone, Copy)]
struct Point {
    strategy: Strategy,
    latency: Latency,
}

/// The board's period in lockstep [ns] (1 kHz).
const BOARD_PERIOD_NS: u64 = 1_000_000;

/// A point's trials through the board and the central controller in lockstep, as `vic-planner
/// --lockstep` runs them: at the rate that gives the strategy its offline meaning
/// ([`Timing::planner_rate_hz`]), the latency split into the sensor and command delay lines
/// beside the slices' lookahead of two periods.
fn lockstep_trials(
    s: &Scenario,
    set: &vic_plan::plan::Setup,
    plan: &PlanFile,
    point: Point,
    opts: &SweepOptions,
) -> Result<Vec<vic_plan::montecarlo::Trial>, SweepError> {
    use vic_rt::central::{Central, Timing, lockstep};
    let fail = |e: Box<dyn std::error::Error + Send + Sync>| SweepError::Lockstep {
        strategy: point.strategy.name(),
        latency_ms: point.latency.ms(),
        source: e,
    };
    let track = crate::daemons::launch::track(plan, set).map_err(|e| fail(e.into()))?;
    let period_ns = 1_000_000_000 / Timing::planner_rate_hz(point.strategy, point.latency);
    let timing = Timing::split(point.latency, period_ns);
    let mut central = Central::new(track, point.strategy, timing);
    let cfg = crate::daemons::launch::board_config(s, BOARD_PERIOD_NS);
    let mut board =
        vic_rt::board::Board::new(s.model.clone(), cfg, &set.x0).map_err(|e| fail(e.into()))?;
    let records = lockstep(
        &mut board,
        &mut central,
        BOARD_PERIOD_NS,
        period_ns,
        opts.trials,
        opts.seed,
    );
    Ok(crate::views::report::to_trials(set, &records))
}
