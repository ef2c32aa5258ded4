//! The paper's experiments, each one command: plan every column of a figure, run it on the
//! stochastic plant, and collect the numbers (and the trials, for the plots).
//!
//! - **fig1**: the two-link arm in the divergent field with each actuator, executed open loop.
//! - **fig2**: the single joint with a 200 ms feedback delay: feedforward without delay, delayed
//!   central feedback without stiffness (Eq. 13), and feedforward torque and stiffness.
//! - **icub**: the elbow with the identified torque noise and damping law: predicted versus Monte
//!   Carlo expected cost, next to the paper's C* = 0.29 (predicted) and C = 0.41 (measured).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use vic_plan::evaluation::{Report, summarize};
use vic_plan::montecarlo::{Trial, run_trials};
use vic_plan::plan::{Method, PlanFile, ProgressFn, plan, setup};
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Feedback, Latency, Strategy, StrategyPlan};
use vic_plan::unit::Unit;

mod claims;
pub use claims::*;
mod delay;
pub(crate) use delay::*;

/// The paper's iCub costs, (C* predicted, C measured on the robot), on a scale it does not state:
/// only their ratio compares with ours.
pub const PAPER_ICUB_COST: (f64, f64) = (0.29, 0.41);

/// Which experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Figure {
    Fig1,
    Fig2,
    Icub,
}

impl Figure {
    pub fn name(self) -> &'static str {
        match self {
            Figure::Fig1 => "fig1",
            Figure::Fig2 => "fig2",
            Figure::Icub => "icub",
        }
    }
}

/// What a column plans and executes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Column {
    /// The scenario's plan by a method, executed open loop.
    OpenLoop(Method),
    /// A central strategy's plan at a latency [ms], executed by the strategy
    /// ([`StrategyPlan::plan_request`], [`Strategy::feedback`]).
    Strategy(Strategy, f64),
}

/// One column of a figure: a scenario, what is planned and how it is executed.
#[derive(Debug, Clone)]
struct ColumnSpec {
    name: &'static str,
    /// The column's title in the figure.
    title: &'static str,
    what: &'static str,
    file: &'static str,
    column: Column,
}

fn columns(figure: Figure) -> Vec<ColumnSpec> {
    use Method::*;
    let c = |(name, title), what, file, column| ColumnSpec {
        name,
        title,
        what,
        file,
        column,
    };
    match figure {
        Figure::Fig1 => vec![
            c(
                ("deterministic", "deterministic (no noise)"),
                "type 2, no noise",
                "two_link_deterministic.toml",
                Column::OpenLoop(Ilqg),
            ),
            c(
                ("torque", "torque only"),
                "type 1 (torque only), noise",
                "two_link_torque_divergent.toml",
                Column::OpenLoop(Sooc),
            ),
            c(
                ("impedance", "torque + impedance"),
                "type 2 (torque + PD impedance), noise",
                "two_link_divergent.toml",
                Column::OpenLoop(Sooc),
            ),
            c(
                ("vsa", "VSA"),
                "type 3 (VSA), B = 2 kg m², noise",
                "two_link_vsa_divergent.toml",
                Column::OpenLoop(Sooc),
            ),
            c(
                ("vsa_b_over_10", "VSA, motor inertia B/10"),
                "type 3 (VSA), B/10, noise",
                "two_link_vsa_light_divergent.toml",
                Column::OpenLoop(Sooc),
            ),
        ],
        Figure::Fig2 => vec![
            c(
                ("feedforward", "torque + stiffness, no delay"),
                "torque and stiffness, no delay, open loop",
                "icub_elbow.toml",
                Column::OpenLoop(Sooc),
            ),
            c(
                ("delayed_feedback", "delayed feedback, no stiffness"),
                "no stiffness, ILQG gains on the state seen 200 ms late (Eq. 13)",
                "single_joint_delay.toml",
                Column::Strategy(Strategy::NaiveDelayed, 200.0),
            ),
            c(
                ("stiffness_delayed", "torque + stiffness, 200 ms delay"),
                "torque and stiffness, 200 ms delay, no feedback",
                "single_joint_delay.toml",
                Column::OpenLoop(Sooc),
            ),
        ],
        Figure::Icub => vec![c(
            ("icub_elbow", "iCub elbow, open loop"),
            "identified torque noise and damping law, open loop",
            "icub_experiment.toml",
            Column::OpenLoop(Sooc),
        )],
    }
}

/// The numbers of one column (the JSON the command writes).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ColumnResult {
    pub name: String,
    pub(crate) description: String,
    pub(crate) scenario: String,
    pub method: String,
    pub(crate) policy: String,
    /// Spread of the final hand position [mm] (arm) — the largest principal standard deviation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) final_std_mm: Option<f64>,
    /// Spread of the final joint angle [deg] (single joint).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) final_std_deg: Option<f64>,
    /// RMS distance to the reference over the movement (mm or deg, see `report.unit`), over the
    /// trials that did not diverge (`None` when all did).
    pub(crate) rms_error: Option<f64>,
    pub(crate) diverged_fraction: f64,
    /// Monte Carlo expected cost over the trials that did not diverge (`None` when all did).
    pub(crate) expected_cost_mc: Option<f64>,
    pub(crate) expected_cost_predicted: f64,
    pub plan_converged: bool,
    pub plan_iterations: usize,
    pub(crate) plan_solve_ms: f64,
    pub(crate) max_stiffness: f64,
    pub(crate) mean_stiffness: f64,
    pub(crate) report: Report,
}

/// A whole experiment: its columns' numbers, and what the plots need.
pub struct ExperimentRun {
    pub figure: Figure,
    pub(crate) trials: usize,
    pub seed: u64,
    pub columns: Vec<ColumnResult>,
    /// Per column: the plan, the scenario it ran on, the execution and the trials.
    pub(crate) data: Vec<ColumnData>,
}

/// What a column ran: enough to plot it or to run it again with another seed.
pub(crate) struct ColumnData {
    pub(crate) plan: PlanFile,
    pub(crate) scenario: Scenario,
    pub(crate) policy: Feedback,
    pub(crate) trials: Vec<Trial>,
}

/// Errors of an experiment: a scenario that does not load, a plan that cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error(transparent)]
    Config(#[from] vic_plan::scenario::ConfigError),
    #[error("{}: {source}", path.display())]
    Plan {
        path: PathBuf,
        source: vic_plan::plan::PlanError,
    },
    #[error("{}: {source}", path.display())]
    Latency {
        path: PathBuf,
        source: vic_plan::strategy::LatencyError,
    },
}

/// Runs every column of `figure` with scenarios from `config_dir`.
pub fn run(
    figure: Figure,
    config_dir: &Path,
    trials: usize,
    seed: u64,
    progress: Option<ProgressFn>,
    mut on_column: impl FnMut(usize, usize, &str),
) -> Result<ExperimentRun, ExperimentError> {
    let specs = columns(figure);
    let mut out = Vec::new();
    let mut data = Vec::new();
    for (i, spec) in specs.iter().enumerate() {
        on_column(i, specs.len(), spec.name);
        let path: PathBuf = config_dir.join(spec.file);
        let file = Scenario::load(&path, &[])?;
        let plan_error = |source| ExperimentError::Plan {
            path: path.clone(),
            source,
        };
        // The scenario planned on, its method and the law that executes the plan.
        let (scenario, method, policy) = match spec.column {
            Column::OpenLoop(method) => (file, method, Feedback::OpenLoop),
            Column::Strategy(strategy, latency_ms) => {
                let latency = Latency::from_ms(latency_ms, file.task.dt).map_err(|source| {
                    ExperimentError::Latency {
                        path: path.clone(),
                        source,
                    }
                })?;
                let request = strategy.plan_request(latency);
                let feedback = strategy.feedback(latency.knots());
                (request.scenario(&file), request.method, feedback)
            }
        };
        let plan_file = plan(&scenario, method, progress.clone()).map_err(plan_error)?;
        let set = setup(&scenario).map_err(plan_error)?;
        let exe = plan_file.policy(&set).map_err(plan_error)?;
        let predicted = match policy {
            Feedback::OpenLoop => plan_file.summary.open_loop_expected_cost,
            _ => plan_file.summary.expected_cost,
        };
        let trial_data = run_trials(&set, &exe, policy, trials, seed);
        out.push(column_result(
            spec.name,
            spec.what,
            spec.file,
            method,
            &plan_file,
            &set,
            policy,
            predicted,
            &trial_data,
        ));
        data.push(ColumnData {
            plan: plan_file,
            scenario,
            policy,
            trials: trial_data,
        });
    }
    Ok(ExperimentRun {
        figure,
        trials,
        seed,
        columns: out,
        data,
    })
}

#[allow(clippy::too_many_arguments)]
fn column_result(
    name: &str,
    what: &str,
    file: &str,
    method: Method,
    plan_file: &PlanFile,
    set: &vic_plan::plan::Setup,
    policy: Feedback,
    predicted: f64,
    trials: &[Trial],
) -> ColumnResult {
    let unit = Unit::for_model(&set.dynamics.model);
    let report = summarize(set, trials, unit.default_divergence());
    let s = &plan_file.summary;
    ColumnResult {
        name: name.into(),
        description: what.into(),
        scenario: file.into(),
        method: method.name().into(),
        policy: match policy {
            Feedback::OpenLoop => "open-loop".into(),
            Feedback::Full => "feedback".into(),
            Feedback::Delayed { latency_steps } => {
                format!("delayed-feedback ({latency_steps} steps)")
            }
            Feedback::Predicted { latency_steps } => format!("predictor ({latency_steps} steps)"),
            Feedback::Replan { latency_steps } => format!("replan ({latency_steps} steps)"),
        },
        final_std_mm: (unit == Unit::Millimetre).then_some(report.final_std),
        final_std_deg: (unit == Unit::Degree).then_some(report.final_std),
        rms_error: report.rms_error,
        diverged_fraction: report.diverged_fraction,
        expected_cost_mc: report.expected_cost_mc,
        expected_cost_predicted: predicted,
        plan_converged: s.converged,
        plan_iterations: s.iterations,
        plan_solve_ms: s.solve_ms,
        max_stiffness: s.max_stiffness,
        mean_stiffness: s.mean_stiffness,
        report,
    }
}

/// The same experiment with the same plans, simulated again with another seed.
pub fn resimulate(run: &ExperimentRun, seed: u64) -> Result<ExperimentRun, ExperimentError> {
    let mut columns = Vec::new();
    let mut data = Vec::new();
    for (c, d) in run.columns.iter().zip(&run.data) {
        let plan_error = |source| ExperimentError::Plan {
            path: d.scenario.source.clone(),
            source,
        };
        let set = setup(&d.scenario).map_err(plan_error)?;
        let exe = d.plan.policy(&set).map_err(plan_error)?;
        let trials = run_trials(&set, &exe, d.policy, run.trials, seed);
        let method = if c.method == "sooc" {
            Method::Sooc
        } else {
            Method::Ilqg
        };
        columns.push(column_result(
            &c.name,
            &c.description,
            &c.scenario,
            method,
            &d.plan,
            &set,
            d.policy,
            c.expected_cost_predicted,
            &trials,
        ));
        data.push(ColumnData {
            plan: d.plan.clone(),
            scenario: d.scenario.clone(),
            policy: d.policy,
            trials,
        });
    }
    Ok(ExperimentRun {
        figure: run.figure,
        trials: run.trials,
        seed,
        columns,
        data,
    })
}

/// The JSON document of an experiment.
pub(crate) fn to_json(run: &ExperimentRun) -> serde_json::Value {
    let mut v = serde_json::json!({
        "figure": run.figure.name(),
        "trials": run.trials,
        "seed": run.seed,
        "columns": run.columns,
    });
    if run.figure == Figure::Icub {
        let (predicted, measured) = PAPER_ICUB_COST;
        v["paper"] = serde_json::json!({
            "expected_cost_predicted": predicted,
            "expected_cost_measured": measured
        });
    }
    v
}

/// Per trial: whether it diverged, by the rule of the reports ([`summarize`]): its final
/// position is further than `divergence` (mm of hand for the arm, degrees for a joint) from the
/// plan's final reference, or is not finite.
pub(crate) fn diverged_trials(
    plan: &PlanFile,
    scenario: &Scenario,
    trials: &[Trial],
    divergence: f64,
) -> Vec<bool> {
    let model = &scenario.model;
    let scale = Unit::for_model(model).scale();
    let Some(goal) = plan.reference.last() else {
        return vec![false; trials.len()];
    };
    let mut x = nalgebra::DVector::zeros(model.nx());
    for (xi, q) in x.iter_mut().zip(&goal.q_d[..model.dof()]) {
        *xi = *q;
    }
    let target = vic_plan::montecarlo::position(model, &x);
    trials
        .iter()
        .map(|t| {
            let Some(last) = t.x.last() else {
                return true;
            };
            let end = vic_plan::montecarlo::position(model, last);
            let d = end
                .iter()
                .zip(&target)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt()
                * scale;
            !d.is_finite() || d > divergence
        })
        .collect()
}

/// The plot data of one column (hand paths for the arm, joint angles and commands for all);
/// a trial that ends further than `divergence` from the target (see [`diverged_trials`]) is
/// marked diverged, and the 95 % ellipse is of the others.
pub(crate) fn column_plot(
    title: &str,
    plan: &PlanFile,
    scenario: &Scenario,
    trials: &[Trial],
    divergence: f64,
) -> crate::views::plot::ColumnPlot {
    let model = &scenario.model;
    let dof = model.dof();
    let hand = |x: &[f64]| -> [f64; 2] { model.plant.hand_position(&x[..2]) };
    let diverged = diverged_trials(plan, scenario, trials, divergence);
    let finals: Vec<[f64; 2]> = if dof == 2 {
        trials
            .iter()
            .zip(&diverged)
            .filter(|(_, lost)| !**lost)
            .map(|(t, _)| hand(t.x.last().expect("non-empty").as_slice()))
            .collect()
    } else {
        vec![]
    };
    crate::views::plot::ColumnPlot {
        title: title.to_string(),
        time: plan.time.clone(),
        dof,
        hand: if dof == 2 {
            trials
                .iter()
                .map(|t| t.x.iter().map(|x| hand(x.as_slice())).collect())
                .collect()
        } else {
            vec![]
        },
        q: trials
            .iter()
            .map(|t| t.x.iter().map(|x| x.as_slice()[..dof].to_vec()).collect())
            .collect(),
        qd: trials
            .iter()
            .map(|t| {
                t.x.iter()
                    .map(|x| x.as_slice()[dof..2 * dof].to_vec())
                    .collect()
            })
            .collect(),
        u: trials
            .iter()
            .map(|t| t.u.iter().map(|u| u.iter().copied().collect()).collect())
            .collect(),
        control_names: plan.control_names.clone(),
        reference_hand: if dof == 2 {
            plan.reference
                .iter()
                .map(|r| model.plant.hand_position(&r.q_d))
                .collect()
        } else {
            vec![]
        },
        reference_q: plan
            .reference
            .iter()
            .map(|r| r.q_d[..dof].to_vec())
            .collect(),
        ellipse: confidence_ellipse(&finals),
        dashed_ellipse: None,
        diverged,
    }
}

/// The 95 % confidence ellipse of 2-D points: centre, semi-axes (major first), major-axis angle.
pub(crate) fn confidence_ellipse(points: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2], f64)> {
    let pts: Vec<&[f64; 2]> = points
        .iter()
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let c = [
        pts.iter().map(|p| p[0]).sum::<f64>() / n,
        pts.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let (mut a, mut b, mut d) = (0.0, 0.0, 0.0);
    for p in &pts {
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        a += x * x / (n - 1.0);
        b += x * y / (n - 1.0);
        d += y * y / (n - 1.0);
    }
    let disc = ((a - d) * (a - d) / 4.0 + b * b).sqrt();
    let (l1, l2) = ((a + d) / 2.0 + disc, ((a + d) / 2.0 - disc).max(0.0));
    let k = 5.991_464_547_107_979_f64; // χ²(2) at 95 %
    Some((
        c,
        [(k * l1).sqrt(), (k * l2).sqrt()],
        0.5 * (2.0 * b).atan2(a - d),
    ))
}

/// Writes the experiment's figure (PNG and SVG) and JSON into `dir`; returns the files written.
pub fn write_outputs(run: &ExperimentRun, dir: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let name = run.figure.name();
    let json_path = dir.join(format!("{name}.json"));
    let text = serde_json::to_string_pretty(&to_json(run)).map_err(|e| e.to_string())?;
    std::fs::write(&json_path, text)
        .map_err(|e| format!("cannot write {}: {e}", json_path.display()))?;
    let specs = columns(run.figure);
    let mut plots: Vec<crate::views::plot::ColumnPlot> = run
        .columns
        .iter()
        .zip(&run.data)
        .map(|(c, d)| {
            let title = specs
                .iter()
                .find(|s| s.name == c.name)
                .map_or_else(|| c.name.replace('_', " "), |s| s.title.to_string());
            let divergence = Unit::for_model(&d.scenario.model).default_divergence();
            column_plot(&title, &d.plan, &d.scenario, &d.trials, divergence)
        })
        .collect();
    let png = dir.join(format!("{name}.png"));
    let svg = dir.join(format!("{name}.svg"));
    // As in the paper, the B/10 VSA shows as a dashed ellipse in the VSA column too.
    if run.figure == Figure::Fig1 && plots.len() == 5 {
        let light = plots[4].ellipse;
        plots[3].dashed_ellipse = light;
    }
    crate::views::plot::captioned_figure(&plots, &figure_caption(run), &png, &svg)
        .map_err(|e| e.to_string())?;
    Ok(vec![json_path, png, svg])
}

/// What every column figure's caption says of the trials that diverged.
pub(crate) const DIVERGED_NOTE: &str = "A trial that diverged (ended more than the divergence \
     distance from the target, or blew up) is dashed, counted under its column's title and left \
     out of the mean, the spread, the ellipse and the axis ranges.";

/// The title and caption of an experiment's figure: what the columns are and how to read them.
fn figure_caption(run: &ExperimentRun) -> crate::views::plot::Caption {
    let trials = format!("{} trials per column, seed {}", run.trials, run.seed);
    let (title, text) = match run.figure {
        Figure::Fig1 => (
            format!(
                "Fig. 1: reaching in a divergent field with each actuator, open loop ({trials})"
            ),
            "Columns: the deterministic plan on the noise-free arm (ILQG), then SOOC plans of the \
             noisy arm in the divergent field with torque only, torque with a PD impedance, and a \
             variable-stiffness actuator (VSA) with motor inertia B and B/10, executed without \
             feedback. Top: hand paths of every trial (grey), their mean (black), the spread \
             across the path (blue), the reference (dashed) to the target (circle) and the 95 % \
             ellipse of the final hand position (red; dashed in the VSA column: B/10's). Middle: \
             joint angles and velocities, mean ± std, the reference dashed. Bottom: the commands \
             per joint, torque τ (the VSA's: its motors') and stiffness K."
                .to_string(),
        ),
        Figure::Fig2 => (
            format!("Fig. 2: a single joint with 200 ms of feedback delay ({trials})"),
            "Columns: a plan of torque and stiffness without delay, executed open loop; delayed \
             feedback without stiffness (the gains of a plan made for the delay on the state seen \
             200 ms late, Eq. 13); the plan of torque and stiffness with 200 ms of delay, which \
             an open-loop plan does not see. Top: the joint angle of every trial and the \
             reference (dashed). Middle: velocity. Bottom: the commands, torque τ₁ and \
             stiffness K₁."
                .to_string(),
        ),
        Figure::Icub => (
            format!("The iCub elbow, −60° to −30° in 1.5 s, open loop ({trials})"),
            "The open-loop SOOC plan of torque and stiffness for the identified torque noise \
             e = (a + b q') η and damping law K_D = 0.075 K_P − 0.0015. Top: the elbow angle of \
             every trial and the reference (dashed). Middle: velocity. Bottom: the plan, torque \
             τ₁ and stiffness K₁. Near the start and the end, torque and stiffness alternate \
             from knot to knot: the noise's amplitude is set by the velocity at each knot, and \
             the plan meets the larger kicks with the stiffer (more damped) knots; averaging \
             each pair of knots costs 5.6 % more (docs/GUIDE.md, \"Why the iCub plan \
             alternates\")."
                .to_string(),
        ),
    };
    let text = match run.figure {
        Figure::Icub => text,
        _ => format!("{text} {DIVERGED_NOTE}"),
    };
    crate::views::plot::Caption { title, text }
}
