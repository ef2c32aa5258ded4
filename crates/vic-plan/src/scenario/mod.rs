//! Scenario files: TOML with sections `[plant]`, `[actuator]`, `[field]`, `[noise]`, `[cost]`,
//! `[task]`, `[solver]` and `[board]` (the live board's limits), plus `--set section.key=value`
//! overrides. Every number of the paper lives in these files; the code holds no physical
//! constant.
//!
//! Loading happens in two stages, like ripgrep's flags: the file is read into plain serde types
//! that reject unknown keys ([`raw`]), then validated into a typed [`Scenario`] whose models cannot
//! be inconsistent ([`validate`]). Every error names the file, the key and what is wrong.

mod board;
mod built_in;
mod edit;
mod error;
mod overrides;
mod raw;
mod sections;
mod solver;
mod stability;
mod validate;

pub use board::{BOARD_RANGES, BoardRange, BoardSection, JOINT_LIMIT_RAD};
pub use built_in::{exists, is_folder, read as read_text};
pub use error::ConfigError;
pub use solver::SolverSection;

use error::FileCheck;
use std::path::{Path, PathBuf};
use vic_core::dynamics::Integrator;
use vic_core::latency::Latency;
use vic_core::model::ArmModel;
use vic_core::solver::Bounds;

/// The reference movement.
#[derive(Debug, Clone, PartialEq)]
pub enum TaskPath {
    /// Minimum-jerk joint movement between two postures [rad].
    Joint { start: Vec<f64>, target: Vec<f64> },
    /// Straight hand path with a minimum-jerk speed profile [m].
    Hand { start: [f64; 2], target: [f64; 2] },
}

/// The task: path, timing and feedback delay.
#[derive(Debug, Clone, PartialEq)]
pub struct Task {
    pub path: TaskPath,
    /// Movement duration T [s].
    pub duration: f64,
    /// Time step Δ of the Euler–Maruyama discretisation (Eq. 10) [s].
    pub dt: f64,
    /// Number of steps N = T / Δ.
    pub steps: usize,
    /// Central feedback delay [ms] (a whole number of steps).
    pub delay_ms: f64,
    /// Integration sub-steps per control step (default 1: the paper's Euler step).
    pub substeps: usize,
    /// Integrator of the drift (default explicit Euler).
    pub integrator: Integrator,
}

impl Task {
    /// The central feedback delay on the task's grid.
    pub fn delay(&self) -> Latency {
        Latency::from_ms(self.delay_ms, self.dt).expect("validated: a whole number of steps")
    }

    /// The delay in whole control steps.
    pub fn delay_steps(&self) -> usize {
        self.delay().knots()
    }
}

/// The weights of the Eq. 14 cost: control effort (torque, stiffness), final position and
/// final velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct CostWeights {
    pub(crate) w_torque: f64,
    pub(crate) w_stiffness: f64,
    pub w_p: f64,
    pub w_v: f64,
}

/// A validated scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Where it came from (for messages).
    pub source: PathBuf,
    pub model: ArmModel,
    pub weights: CostWeights,
    pub task: Task,
    pub bounds: Bounds,
    pub initial_stiffness: f64,
    pub solver: SolverSection,
    /// The live board's limits (`[board]`).
    pub board: BoardSection,
    /// The configuration after overrides, as resolved (written into plan files).
    pub resolved: toml::Table,
}

impl Scenario {
    /// Reads a scenario file (or, for a missing `config/NAME.toml`, the built-in copy of
    /// `config/`: [`read_text`]) and applies `section.key=value` overrides.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scenario, ConfigError> {
        let text = built_in::read(path).map_err(|source| ConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Scenario::from_str(&text, path, overrides)
    }

    /// Parses a scenario from text (`path` is used in messages only).
    pub fn from_str(
        text: &str,
        path: &Path,
        overrides: &[String],
    ) -> Result<Scenario, ConfigError> {
        let check = FileCheck { path };
        let mut resolved: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| check.syntax(e.to_string().trim_end()))?;
        for assignment in overrides {
            overrides::apply_override(&mut resolved, assignment)?;
        }
        let checked = move || {
            let mut tagged = resolved.clone();
            raw::retag(&mut tagged)
                .map_err(|(section, key, message)| check.invalid(section, key, message))?;
            let raw: raw::RawConfig = serde_path_to_error::deserialize(toml::Value::Table(tagged))
                .map_err(|e| check.serde_error(e, sections::tag_of))?;
            validate::validate(raw, path, resolved)
        };
        checked().map_err(|e| e.blame_override(overrides))
    }
}

#[cfg(test)]
mod doc_tests;
#[cfg(test)]
mod tests;
