//! Scenario files: TOML with sections `[plant]`, `[actuator]`, `[field]`, `[noise]`, `[cost]`,
//! `[task]`, `[solver]` and `[board]` (the live board's limits), plus `--set section.key=value` overrides. Every number of the paper lives
//! in these files; the code holds no physical constant.
//!
//! Loading happens in two stages, like ripgrep's flags: the file is read into plain structs that
//! reject unknown keys, then validated into a typed [`Scenario`] whose models cannot be
//! inconsistent. Every error names the file, the key and what is wrong.

use crate::core::dynamics::Integrator;
use crate::core::model::{Actuator, ArmModel, Damping, Field, Noise, Plant, SingleJoint, TwoLink};
use crate::core::solver::{Bounds, IlqgOptions};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A configuration error: which file, which key, what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("{path}: [{section}] {key}: {message}")]
    Invalid {
        path: PathBuf,
        section: String,
        key: String,
        message: String,
    },
    #[error("--set {assignment}: {message}")]
    Override { assignment: String, message: String },
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    plant: Option<RawPlant>,
    actuator: Option<RawActuator>,
    field: Option<RawField>,
    noise: Option<RawNoise>,
    cost: Option<RawCost>,
    task: Option<RawTask>,
    #[serde(default)]
    solver: RawSolver,
    #[serde(default)]
    board: RawBoard,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    kind: String,
    // single joint
    inertia: Option<f64>,
    mass: Option<f64>,
    com: Option<f64>,
    length: Option<f64>,
    gravity: Option<f64>,
    // two-link
    l1: Option<f64>,
    l2: Option<f64>,
    s2: Option<f64>,
    m2: Option<f64>,
    i1: Option<f64>,
    i2: Option<f64>,
    // both: a number (single joint) or a 2×2 matrix (two-link)
    viscosity: Option<toml::Value>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawActuator {
    #[serde(rename = "type")]
    kind: String,
    damping: Option<String>,
    alpha: Option<f64>,
    slope: Option<f64>,
    offset: Option<f64>,
    motor_inertia: Option<Vec<f64>>,
    torque_limit: Option<f64>,
    stiffness_min: Option<f64>,
    stiffness_max: Option<f64>,
    /// Stiffness of the initial guess handed to the solver [N m/rad].
    initial_stiffness: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawField {
    kind: String,
    beta: Option<f64>,
    matrix: Option<[[f64; 2]; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    kind: String,
    sigma: Option<f64>,
    component: Option<usize>,
    a: Option<f64>,
    b: Option<f64>,
    sample_time: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCost {
    w_torque: f64,
    w_stiffness: Option<f64>,
    w_p: f64,
    w_v: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTask {
    kind: String,
    start_deg: Option<Vec<f64>>,
    target_deg: Option<Vec<f64>>,
    hand_start: Option<[f64; 2]>,
    hand_target: Option<[f64; 2]>,
    duration: f64,
    dt: f64,
    #[serde(default)]
    delay_ms: f64,
    substeps: Option<usize>,
    integrator: Option<String>,
}

/// The `[solver]` section: the method and the solver's options (every key optional).
#[derive(Debug, Clone, PartialEq)]
pub struct IlqgSection {
    /// The planning method.
    pub method: Method,
    pub options: IlqgOptions,
    /// SOOC: fractions of the noise solved in turn, ending at 1 (default [1.0]: the stagewise
    /// Newton solver converges from the deterministic plan directly, and intermediate stages only
    /// add iterations — measured on two_link_divergent: 22 Newton steps at [1.0], 44 over
    /// [0.1, 0.3, 1.0], same optimum).
    pub noise_continuation: Vec<f64>,
}

impl Default for IlqgSection {
    fn default() -> Self {
        IlqgSection {
            method: Method::Ilqg,
            options: IlqgOptions::default(),
            noise_continuation: vec![1.0],
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSolver {
    method: Option<String>,
    max_iterations: Option<usize>,
    tolerance: Option<f64>,
    gradient_tolerance: Option<f64>,
    mu_init: Option<f64>,
    mu_min: Option<f64>,
    mu_max: Option<f64>,
    stochastic: Option<bool>,
    damp_short_steps: Option<bool>,
    noise_continuation: Option<Vec<f64>>,
}

impl RawSolver {
    fn resolve(self, cx: &Ctx) -> Result<IlqgSection, ConfigError> {
        let d = IlqgOptions::default();
        let method = match self.method.as_deref().unwrap_or("ilqg") {
            "ilqg" => Method::Ilqg,
            "sooc" => Method::Sooc,
            other => {
                return Err(cx.err(
                    "solver",
                    "method",
                    format!("unknown method \"{other}\"; expected \"ilqg\" or \"sooc\""),
                ));
            }
        };
        let noise_continuation = self.noise_continuation.unwrap_or_else(|| vec![1.0]);
        if noise_continuation.last() != Some(&1.0)
            || noise_continuation
                .iter()
                .any(|f| !(f.is_finite() && *f > 0.0))
        {
            return Err(cx.err(
                "solver",
                "noise_continuation",
                format!("must be positive fractions ending with 1.0, got {noise_continuation:?}"),
            ));
        }
        Ok(IlqgSection {
            noise_continuation,
            method,
            options: IlqgOptions {
                max_iterations: self.max_iterations.unwrap_or(d.max_iterations),
                tolerance: self.tolerance.unwrap_or(d.tolerance),
                gradient_tolerance: self.gradient_tolerance.unwrap_or(d.gradient_tolerance),
                mu_init: self.mu_init.unwrap_or(d.mu_init),
                mu_min: self.mu_min.unwrap_or(d.mu_min),
                mu_max: self.mu_max.unwrap_or(d.mu_max),
                stochastic: self.stochastic.unwrap_or(d.stochastic),
                damp_short_steps: self.damp_short_steps.unwrap_or(d.damp_short_steps),
                shrink_below_step: d.shrink_below_step,
            },
        })
    }
}

/// The `[board]` section: the live board's safety limits (every key optional; defaults below).
#[derive(Debug, Clone, PartialEq)]
pub struct BoardSection {
    /// How long the last valid command stays in force once no command covers the present [s]
    /// before the board ramps to its safe hold (default 0.05).
    pub watchdog: f64,
    /// Duration of the ramp into the safe hold [s] (default 0.1).
    pub ramp: f64,
    /// Stiffness of the safe hold [N m/rad] (default 100).
    pub hold_stiffness: f64,
    /// Plant guard: joint range [rad] and speed limit [rad/s]; leaving them latches a fault that
    /// only a reset clears (defaults ±π, 20 rad/s).
    pub joint_min: Vec<f64>,
    pub joint_max: Vec<f64>,
    pub velocity_max: f64,
    /// A message stamped later than the board's clock by more than this is rejected [s]
    /// (default 0.005).
    pub future_tolerance: f64,
    /// Largest disturbances the board accepts: pulse and load torque [N m], pulse duration [s],
    /// field β [N/m], noise factor (defaults 20, 10, 2, 500, 10).
    pub max_pulse_torque: f64,
    pub max_load_torque: f64,
    pub max_pulse_duration: f64,
    pub max_field_beta: f64,
    pub max_noise_factor: f64,
}

impl BoardSection {
    fn defaults(dof: usize) -> Self {
        BoardSection {
            watchdog: 0.05,
            ramp: 0.1,
            hold_stiffness: 100.0,
            joint_min: vec![-std::f64::consts::PI; dof],
            joint_max: vec![std::f64::consts::PI; dof],
            velocity_max: 20.0,
            future_tolerance: 0.005,
            max_pulse_torque: 20.0,
            max_load_torque: 10.0,
            max_pulse_duration: 2.0,
            max_field_beta: 500.0,
            max_noise_factor: 10.0,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBoard {
    watchdog: Option<f64>,
    ramp: Option<f64>,
    hold_stiffness: Option<f64>,
    joint_min: Option<Vec<f64>>,
    joint_max: Option<Vec<f64>>,
    velocity_max: Option<f64>,
    future_tolerance: Option<f64>,
    max_pulse_torque: Option<f64>,
    max_load_torque: Option<f64>,
    max_pulse_duration: Option<f64>,
    max_field_beta: Option<f64>,
    max_noise_factor: Option<f64>,
}

impl RawBoard {
    fn resolve(self, dof: usize, cx: &Ctx) -> Result<BoardSection, ConfigError> {
        let d = BoardSection::defaults(dof);
        let pos =
            |v: Option<f64>, dflt: f64, key: &str| cx.positive(v.unwrap_or(dflt), "board", key);
        let nonneg =
            |v: Option<f64>, dflt: f64, key: &str| cx.non_negative(v.unwrap_or(dflt), "board", key);
        let range = |v: Option<Vec<f64>>, dflt: Vec<f64>, key: &str| {
            let v = v.unwrap_or(dflt);
            if v.len() != dof || v.iter().any(|x| !x.is_finite()) {
                return Err(cx.err(
                    "board",
                    key,
                    format!("must be {dof} finite angle(s) [rad], got {v:?}"),
                ));
            }
            Ok(v)
        };
        let joint_min = range(self.joint_min, d.joint_min, "joint_min")?;
        let joint_max = range(self.joint_max, d.joint_max, "joint_max")?;
        if joint_min.iter().zip(&joint_max).any(|(a, b)| a >= b) {
            return Err(cx.err(
                "board",
                "joint_max",
                format!("must exceed joint_min {joint_min:?} joint by joint, got {joint_max:?}"),
            ));
        }
        Ok(BoardSection {
            watchdog: nonneg(self.watchdog, d.watchdog, "watchdog")?,
            ramp: nonneg(self.ramp, d.ramp, "ramp")?,
            hold_stiffness: pos(self.hold_stiffness, d.hold_stiffness, "hold_stiffness")?,
            joint_min,
            joint_max,
            velocity_max: pos(self.velocity_max, d.velocity_max, "velocity_max")?,
            future_tolerance: nonneg(
                self.future_tolerance,
                d.future_tolerance,
                "future_tolerance",
            )?,
            max_pulse_torque: nonneg(
                self.max_pulse_torque,
                d.max_pulse_torque,
                "max_pulse_torque",
            )?,
            max_load_torque: nonneg(self.max_load_torque, d.max_load_torque, "max_load_torque")?,
            max_pulse_duration: nonneg(
                self.max_pulse_duration,
                d.max_pulse_duration,
                "max_pulse_duration",
            )?,
            max_field_beta: nonneg(self.max_field_beta, d.max_field_beta, "max_field_beta")?,
            max_noise_factor: nonneg(
                self.max_noise_factor,
                d.max_noise_factor,
                "max_noise_factor",
            )?,
        })
    }
}

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
    /// Time step Δ [s].
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
    /// The delay in whole control steps.
    pub fn delay_steps(&self) -> usize {
        (self.delay_ms / 1000.0 / self.dt).round() as usize
    }
}

/// Eq. 14 weights.
#[derive(Debug, Clone, PartialEq)]
pub struct CostWeights {
    pub w_torque: f64,
    pub w_stiffness: f64,
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
    pub solver: IlqgSection,
    /// The live board's limits (`[board]`).
    pub board: BoardSection,
    /// The configuration after overrides, as resolved (written into plan files).
    pub resolved: toml::Table,
}

impl Scenario {
    /// Reads a scenario file and applies `section.key=value` overrides.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scenario, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
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
        let syntax = |message: String| ConfigError::Syntax {
            path: path.to_path_buf(),
            message,
        };
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| syntax(e.to_string().trim_end().to_string()))?;
        for assignment in overrides {
            apply_override(&mut table, assignment)?;
        }
        let raw: RawConfig = serde_path_to_error::deserialize(toml::Value::Table(table.clone()))
            .map_err(|e| {
                let p = e.path().to_string();
                let (section, key) = match p.split_once('.') {
                    Some((s, k)) => (s.to_string(), k.to_string()),
                    None => (p.clone(), String::new()),
                };
                let message = e.into_inner().to_string();
                if key.is_empty() {
                    syntax(format!(
                        "{}{message}",
                        if p == "." {
                            String::new()
                        } else {
                            format!("[{p}] ")
                        }
                    ))
                } else {
                    ConfigError::Invalid {
                        path: path.to_path_buf(),
                        section,
                        key,
                        message,
                    }
                }
            })?;
        validate(raw, path, table)
    }
}

fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let err = |message: &str| ConfigError::Override {
        assignment: assignment.to_string(),
        message: message.to_string(),
    };
    let (key, value) = assignment
        .split_once('=')
        .ok_or_else(|| err("expected section.key=value"))?;
    let (section, field) = key
        .trim()
        .split_once('.')
        .ok_or_else(|| err("expected section.key=value"))?;
    if section.is_empty() || field.is_empty() || field.contains('.') {
        return Err(err("expected section.key=value"));
    }
    let value = value.trim();
    // A TOML value if it parses as one (numbers, booleans, arrays), else a bare string.
    let parsed = format!("v = {value}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value.to_string()));
    let entry = table
        .entry(section.to_string())
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let toml::Value::Table(sec) = entry else {
        return Err(err(&format!("{section} is not a section")));
    };
    sec.insert(field.to_string(), parsed);
    Ok(())
}

struct Ctx<'a> {
    path: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, section: &str, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.to_path_buf(),
            section: section.into(),
            key: key.into(),
            message: message.into(),
        }
    }
    fn need<T>(&self, v: Option<T>, section: &str, key: &str, why: &str) -> Result<T, ConfigError> {
        v.ok_or_else(|| self.err(section, key, format!("missing, required {why}")))
    }
    fn positive(&self, v: f64, section: &str, key: &str) -> Result<f64, ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(section, key, format!("must be a positive number, got {v}")))
        }
    }
    fn non_negative(&self, v: f64, section: &str, key: &str) -> Result<f64, ConfigError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(section, key, format!("must be a number ≥ 0, got {v}")))
        }
    }
    fn missing_section(&self, section: &str) -> ConfigError {
        ConfigError::Syntax {
            path: self.path.to_path_buf(),
            message: format!("missing section [{section}]"),
        }
    }
}

fn validate(raw: RawConfig, path: &Path, resolved: toml::Table) -> Result<Scenario, ConfigError> {
    let cx = Ctx { path };
    let p = raw.plant.ok_or_else(|| cx.missing_section("plant"))?;
    let plant = match p.kind.as_str() {
        "single_joint" => {
            let why = "for a single joint";
            let viscosity = match &p.viscosity {
                None => 0.0,
                Some(v) => v
                    .as_float()
                    .or(v.as_integer().map(|i| i as f64))
                    .ok_or_else(|| {
                        cx.err("plant", "viscosity", "must be a number for a single joint")
                    })?,
            };
            Plant::SingleJoint(SingleJoint {
                inertia: cx.positive(
                    cx.need(p.inertia, "plant", "inertia", why)?,
                    "plant",
                    "inertia",
                )?,
                mass: cx.non_negative(cx.need(p.mass, "plant", "mass", why)?, "plant", "mass")?,
                com: cx.non_negative(cx.need(p.com, "plant", "com", why)?, "plant", "com")?,
                length: cx.positive(
                    cx.need(p.length, "plant", "length", why)?,
                    "plant",
                    "length",
                )?,
                gravity: cx.non_negative(
                    cx.need(p.gravity, "plant", "gravity", why)?,
                    "plant",
                    "gravity",
                )?,
                viscosity: cx.non_negative(viscosity, "plant", "viscosity")?,
            })
        }
        "two_link" => {
            let why = "for a two-link arm";
            let viscosity: [[f64; 2]; 2] = match &p.viscosity {
                None => [[0.0; 2]; 2],
                Some(v) => v.clone().try_into().map_err(|_| {
                    cx.err(
                        "plant",
                        "viscosity",
                        "must be a 2×2 matrix [[b11, b12], [b21, b22]]",
                    )
                })?,
            };
            let get = |v: Option<f64>, key: &str| -> Result<f64, ConfigError> {
                cx.positive(cx.need(v, "plant", key, why)?, "plant", key)
            };
            Plant::TwoLink(TwoLink {
                l1: get(p.l1, "l1")?,
                l2: get(p.l2, "l2")?,
                s2: get(p.s2, "s2")?,
                m2: get(p.m2, "m2")?,
                i1: get(p.i1, "i1")?,
                i2: get(p.i2, "i2")?,
                viscosity,
            })
        }
        other => {
            return Err(cx.err(
                "plant",
                "kind",
                format!("unknown plant \"{other}\"; expected \"single_joint\" or \"two_link\""),
            ));
        }
    };
    let dof = plant.dof();

    let a = raw.actuator.ok_or_else(|| cx.missing_section("actuator"))?;
    let actuator = match a.kind.as_str() {
        "torque" => Actuator::Torque,
        "impedance" => {
            let damping = match a.damping.as_deref().unwrap_or("proportional") {
                "proportional" => Damping::Proportional {
                    alpha: cx.non_negative(
                        cx.need(
                            a.alpha,
                            "actuator",
                            "alpha",
                            "for damping = \"proportional\"",
                        )?,
                        "actuator",
                        "alpha",
                    )?,
                },
                "affine" => Damping::Affine {
                    slope: cx.need(a.slope, "actuator", "slope", "for damping = \"affine\"")?,
                    offset: cx.need(a.offset, "actuator", "offset", "for damping = \"affine\"")?,
                },
                other => {
                    return Err(cx.err("actuator", "damping", format!(
                        "unknown damping law \"{other}\"; expected \"proportional\" or \"affine\""
                    )));
                }
            };
            Actuator::Impedance { damping }
        }
        "vsa" => {
            let b = cx.need(
                a.motor_inertia.clone(),
                "actuator",
                "motor_inertia",
                "for type = \"vsa\"",
            )?;
            if b.len() != dof || b.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(cx.err(
                    "actuator",
                    "motor_inertia",
                    format!("must list {dof} positive motor inertias [kg m²], got {b:?}"),
                ));
            }
            Actuator::Vsa { motor_inertia: b }
        }
        other => {
            return Err(cx.err(
                "actuator",
                "type",
                format!(
                    "unknown actuator \"{other}\"; expected \"torque\", \"impedance\" or \"vsa\""
                ),
            ));
        }
    };
    if matches!(actuator, Actuator::Torque)
        && (a.stiffness_max.is_some() || a.stiffness_min.is_some() || a.initial_stiffness.is_some())
    {
        return Err(cx.err(
            "actuator",
            "stiffness_max",
            "a torque actuator has no stiffness",
        ));
    }

    let f = raw.field.ok_or_else(|| cx.missing_section("field"))?;
    let field = match f.kind.as_str() {
        "none" => Field::None,
        "divergent" => Field::Divergent {
            beta: cx.need(f.beta, "field", "beta", "for kind = \"divergent\" (N/m)")?,
        },
        "curl" => Field::Curl {
            matrix: cx.need(
                f.matrix,
                "field",
                "matrix",
                "for kind = \"curl\" (2×2, N s/m)",
            )?,
        },
        other => {
            return Err(cx.err(
                "field",
                "kind",
                format!("unknown field \"{other}\"; expected \"none\", \"divergent\" or \"curl\""),
            ));
        }
    };

    let nx = actuator.nx(dof);
    let n = raw.noise.ok_or_else(|| cx.missing_section("noise"))?;
    let noise = match n.kind.as_str() {
        "none" => Noise::None,
        "state" => {
            let sigma = cx.need(n.sigma, "noise", "sigma", "for kind = \"state\"")?;
            let component = n.component.unwrap_or(dof);
            if component >= nx {
                return Err(cx.err(
                    "noise",
                    "component",
                    format!("{component} is out of range: the state has {nx} components (0-based)"),
                ));
            }
            Noise::StateProportional {
                sigma: cx.non_negative(sigma, "noise", "sigma")?,
                component,
            }
        }
        "torque" => Noise::Torque {
            a: cx.need(n.a, "noise", "a", "for kind = \"torque\"")?,
            b: cx.need(n.b, "noise", "b", "for kind = \"torque\"")?,
            sample_time: cx.positive(
                cx.need(
                    n.sample_time,
                    "noise",
                    "sample_time",
                    "for kind = \"torque\" (s)",
                )?,
                "noise",
                "sample_time",
            )?,
        },
        other => {
            return Err(cx.err(
                "noise",
                "kind",
                format!("unknown noise \"{other}\"; expected \"none\", \"state\" or \"torque\""),
            ));
        }
    };
    let model =
        ArmModel::new(plant, actuator, field, noise).map_err(|m| cx.err("field", "kind", m))?;

    let c = raw.cost.ok_or_else(|| cx.missing_section("cost"))?;
    let weights = CostWeights {
        w_torque: cx.non_negative(c.w_torque, "cost", "w_torque")?,
        w_stiffness: cx.non_negative(c.w_stiffness.unwrap_or(0.0), "cost", "w_stiffness")?,
        w_p: cx.non_negative(c.w_p, "cost", "w_p")?,
        w_v: cx.non_negative(c.w_v, "cost", "w_v")?,
    };
    if model.actuator.stiffness_offset(dof).is_some() && c.w_stiffness.is_none() {
        return Err(cx.err(
            "cost",
            "w_stiffness",
            "missing, required when the actuator has stiffness",
        ));
    }

    let t = raw.task.ok_or_else(|| cx.missing_section("task"))?;
    let duration = cx.positive(t.duration, "task", "duration")?;
    let dt = cx.positive(t.dt, "task", "dt")?;
    let steps_f = duration / dt;
    if (steps_f - steps_f.round()).abs() > 1e-6 || steps_f.round() < 2.0 {
        return Err(cx.err(
            "task",
            "dt",
            format!("the duration {duration} s must be a whole number (≥ 2) of steps of {dt} s"),
        ));
    }
    let delay_ms = cx.non_negative(t.delay_ms, "task", "delay_ms")?;
    let delay_steps = delay_ms / 1000.0 / dt;
    if (delay_steps - delay_steps.round()).abs() > 1e-6 {
        return Err(cx.err(
            "task",
            "delay_ms",
            format!(
                "{delay_ms} ms is not a whole number of {} ms steps",
                dt * 1000.0
            ),
        ));
    }
    let task_path = match t.kind.as_str() {
        "joint" => {
            let why = "for kind = \"joint\" (degrees, one per joint)";
            let start = cx.need(t.start_deg, "task", "start_deg", why)?;
            let target = cx.need(t.target_deg, "task", "target_deg", why)?;
            for (key, v) in [("start_deg", &start), ("target_deg", &target)] {
                if v.len() != dof {
                    return Err(cx.err(
                        "task",
                        key,
                        format!("must have {dof} entries, got {}", v.len()),
                    ));
                }
            }
            TaskPath::Joint {
                start: start.iter().map(|d| d.to_radians()).collect(),
                target: target.iter().map(|d| d.to_radians()).collect(),
            }
        }
        "hand" => {
            if dof != 2 {
                return Err(cx.err("task", "kind", "a hand path needs the two-link arm"));
            }
            let why = "for kind = \"hand\" ([x, y] in m, shoulder at the origin)";
            let start = cx.need(t.hand_start, "task", "hand_start", why)?;
            let target = cx.need(t.hand_target, "task", "hand_target", why)?;
            for (key, v) in [("hand_start", start), ("hand_target", target)] {
                if model.plant.inverse_kinematics(v).is_none() {
                    return Err(cx.err("task", key, format!("{v:?} m is out of the arm's reach")));
                }
            }
            TaskPath::Hand { start, target }
        }
        other => {
            return Err(cx.err(
                "task",
                "kind",
                format!("unknown task \"{other}\"; expected \"joint\" or \"hand\""),
            ));
        }
    };
    let substeps = t.substeps.unwrap_or(1);
    if substeps == 0 {
        return Err(cx.err("task", "substeps", "must be at least 1"));
    }
    let integrator = match t.integrator.as_deref().unwrap_or("euler") {
        "euler" => Integrator::Euler,
        "semi_implicit" => Integrator::SemiImplicit,
        other => {
            return Err(cx.err(
                "task",
                "integrator",
                format!("unknown integrator \"{other}\"; expected \"euler\" or \"semi_implicit\""),
            ));
        }
    };
    let task = Task {
        path: task_path,
        duration,
        dt,
        steps: steps_f.round() as usize,
        delay_ms,
        substeps,
        integrator,
    };

    let nu = model.nu();
    let mut bounds = Bounds::unbounded(nu);
    if let Some(limit) = a.torque_limit {
        let limit = cx.positive(limit, "actuator", "torque_limit")?;
        for i in 0..dof {
            bounds.lower[i] = -limit;
            bounds.upper[i] = limit;
        }
    }
    if let Some(off) = model.actuator.stiffness_offset(dof) {
        let lo = cx.non_negative(a.stiffness_min.unwrap_or(0.0), "actuator", "stiffness_min")?;
        let hi = a.stiffness_max.unwrap_or(f64::INFINITY);
        // Equal limits fix the stiffness (stiffness_max = 0: an impedance actuator without
        // stiffness, the paper's "delayed feedback without stiffness").
        if hi.is_nan() || hi < lo {
            return Err(cx.err(
                "actuator",
                "stiffness_max",
                format!("must be at least stiffness_min ({lo}), got {hi}"),
            ));
        }
        for i in 0..dof {
            bounds.lower[off + i] = lo;
            bounds.upper[off + i] = hi;
        }
    }
    let initial_stiffness = a.initial_stiffness.unwrap_or(match model.actuator {
        // A VSA needs a spring to move the link at all.
        Actuator::Vsa { .. } => 10.0,
        _ => 0.0,
    });
    let initial_stiffness = cx.non_negative(initial_stiffness, "actuator", "initial_stiffness")?;

    check_substep(&model, &task, &bounds, &cx)?;

    let solver = raw.solver.resolve(&cx)?;
    let o = &solver.options;
    if o.max_iterations == 0 {
        return Err(cx.err("solver", "max_iterations", "must be at least 1"));
    }
    cx.non_negative(o.tolerance, "solver", "tolerance")?;
    cx.non_negative(o.mu_init, "solver", "mu_init")?;
    cx.positive(o.mu_max, "solver", "mu_max")?;
    let board = raw.board.resolve(dof, &cx)?;

    Ok(Scenario {
        source: path.to_path_buf(),
        model,
        weights,
        task,
        bounds,
        initial_stiffness,
        solver,
        board,
        resolved,
    })
}

/// Refuses integration sub-steps too long for the stiffest configured impedance: explicit and
/// semi-implicit Euler both diverge once `h · K_D / I > 2` (a damping rate) or `h · ω > 2` (a VSA
/// spring). A plan made on a numerically unstable plant says nothing about the robot.
fn check_substep(
    model: &ArmModel,
    task: &Task,
    bounds: &Bounds,
    cx: &Ctx,
) -> Result<(), ConfigError> {
    let dof = model.dof();
    let Some(off) = model.actuator.stiffness_offset(dof) else {
        return Ok(());
    };
    let k_max = bounds.upper[off..off + dof]
        .iter()
        .copied()
        .fold(0.0, f64::max);
    if !k_max.is_finite() {
        return Ok(());
    }
    // Smallest effective inertia over the postures of the task (elbow angles between start and
    // target, with a margin): the smallest eigenvalue of M(q).
    let elbow = |path: &TaskPath| -> (f64, f64) {
        let ends = match path {
            TaskPath::Joint { start, target } => [
                start.get(1).copied().unwrap_or(0.0),
                target.get(1).copied().unwrap_or(0.0),
            ],
            TaskPath::Hand { start, target } => {
                [*start, *target].map(|p| model.plant.inverse_kinematics(p).map_or(0.0, |q| q[1]))
            }
        };
        (ends[0].min(ends[1]) - 0.3, ends[0].max(ends[1]) + 0.3)
    };
    let (lo, hi) = elbow(&task.path);
    let inertia = (0..=36)
        .map(|i| {
            let q = [0.0, lo + (hi - lo) * i as f64 / 36.0];
            let m = model.plant.mass_matrix(&q);
            if dof == 1 {
                m[0][0]
            } else {
                let (tr, det) = (m[0][0] + m[1][1], m[0][0] * m[1][1] - m[0][1] * m[1][0]);
                0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt())
            }
        })
        .fold(f64::INFINITY, f64::min);
    let rate = match &model.actuator {
        Actuator::Impedance { damping } => damping.gain(k_max) / inertia,
        Actuator::Vsa { motor_inertia } => {
            let b = motor_inertia.iter().copied().fold(f64::INFINITY, f64::min);
            (k_max / inertia.min(b)).sqrt()
        }
        Actuator::Torque => return Ok(()),
    };
    let h = task.dt / task.substeps as f64;
    if h * rate >= 2.0 {
        let needed = (task.dt * rate / 2.0).floor() as usize + 1;
        return Err(cx.err(
            "task",
            "substeps",
            format!(
                "{} sub-step(s) of {:.2} ms are numerically unstable at stiffness_max = {k_max} N m/rad \
                 (rate {rate:.0}/s needs h < {:.2} ms): use substeps ≥ {needed} or a lower stiffness_max",
                task.substeps,
                h * 1000.0,
                2000.0 / rate
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ELBOW: &str = r#"
[plant]
kind = "single_joint"
inertia = 5.08e-3
mass = 0.812
com = 0.103
length = 0.273
gravity = 9.81
[actuator]
type = "impedance"
alpha = 0.2
[field]
kind = "none"
[noise]
kind = "state"
sigma = 0.03
[cost]
w_torque = 1.0
w_stiffness = 1e-4
w_p = 1e6
w_v = 1e5
[task]
kind = "joint"
start_deg = [-60.0]
target_deg = [-30.0]
duration = 1.5
dt = 0.01
"#;

    fn load(extra: &[&str]) -> Result<Scenario, ConfigError> {
        let o: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
        Scenario::from_str(ELBOW, Path::new("elbow.toml"), &o)
    }

    #[test]
    fn parses_a_valid_scenario() {
        let s = load(&[]).unwrap();
        assert_eq!(s.task.steps, 150);
        assert_eq!(s.model.nu(), 2);
        assert_eq!(s.bounds.lower[1], 0.0);
    }

    #[test]
    fn overrides_change_values_and_errors_name_the_key() {
        let s = load(&["noise.sigma=0.1", "task.delay_ms=200"]).unwrap();
        assert_eq!(
            s.model.noise,
            Noise::StateProportional {
                sigma: 0.1,
                component: 1
            }
        );
        assert_eq!(s.task.delay_steps(), 20);
        let e = load(&["cost.w_p=abc"]).unwrap_err().to_string();
        assert!(e.contains("elbow.toml") && e.contains("[cost] w_p"), "{e}");
        let e = load(&["cost.bogus=1"]).unwrap_err().to_string();
        assert!(e.contains("bogus"), "{e}");
        let e = load(&["actuator.type=spring"]).unwrap_err().to_string();
        assert!(e.contains("[actuator] type") && e.contains("spring"), "{e}");
        let e = load(&["task.dt=0.007"]).unwrap_err().to_string();
        assert!(e.contains("[task] dt"), "{e}");
        let e = load(&["novalue"]).unwrap_err().to_string();
        assert!(e.contains("section.key=value"), "{e}");
        let e = load(&["task.delay_ms=15"]).unwrap_err().to_string();
        assert!(e.contains("delay_ms"), "{e}");
    }

    #[test]
    fn syntax_errors_name_the_file() {
        let e = Scenario::from_str("[plant\n", Path::new("bad.toml"), &[]).unwrap_err();
        assert!(matches!(e, ConfigError::Syntax { .. }));
        assert!(e.to_string().starts_with("bad.toml"));
        let e = Scenario::from_str("", Path::new("empty.toml"), &[])
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing section [plant]"), "{e}");
    }
}

/// How a plan is made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// ILQG: a nominal plan with locally optimal feedback gains (DESIGN §4), made for the
    /// scenario's feedback delay.
    Ilqg,
    /// Stochastic optimal open-loop control: torque and stiffness for execution without feedback,
    /// optimal for the open-loop plant's mean and covariance (DESIGN §5). Delay-free by nature.
    Sooc,
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::Ilqg => "ilqg",
            Method::Sooc => "sooc",
        }
    }
}
