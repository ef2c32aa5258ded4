//! The scenario file as written: plain serde types that reject unknown keys and hold the one set
//! of defaults. A section whose variant a key selects (`[actuator] type = "vsa"`) is an enum: the
//! loader turns the key into serde's external tagging ([`retag`]) so that errors keep their key.
//! The `[board]` section is the validated [`BoardSection`](super::BoardSection) with its joint
//! range optional ([`RawBoard`](super::board::RawBoard)), its defaults beside it.

use super::sections::TAGGED;
use crate::method::Method;
use serde::Deserialize;
use vic_core::dynamics::Integrator;
use vic_core::solver::sooc_newton::Indefinite;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawConfig {
    pub plant: Option<RawPlant>,
    pub actuator: Option<RawActuator>,
    pub field: Option<RawField>,
    pub noise: Option<RawNoise>,
    pub cost: Option<RawCost>,
    pub task: Option<RawTask>,
    #[serde(default)]
    pub solver: RawSolver,
    #[serde(default)]
    pub board: super::board::RawBoard,
}

/// Rewrites each tagged section `{ kind = "x", rest… }` as `{ x = { rest… } }`, the form serde's
/// externally tagged enums read while tracking the key path. A missing or non-string tag is
/// reported as `(section, key, message)`.
pub(super) fn retag(table: &mut toml::Table) -> Result<(), (&'static str, &'static str, String)> {
    for (section, tag) in TAGGED {
        let Some(toml::Value::Table(body)) = table.get_mut(section) else {
            continue;
        };
        let variant = match body.remove(tag) {
            Some(toml::Value::String(v)) => v,
            Some(other) => {
                return Err((section, tag, format!("must be a string, got {other}")));
            }
            None => {
                return Err((
                    section,
                    tag,
                    "missing, required: it selects the model".to_string(),
                ));
            }
        };
        let body = std::mem::take(body);
        table.insert(
            section.to_string(),
            toml::Value::Table(toml::Table::from_iter([(
                variant,
                toml::Value::Table(body),
            )])),
        );
    }
    Ok(())
}

/// `[plant]`, by `kind`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawPlant {
    SingleJoint {
        inertia: f64,
        mass: f64,
        com: f64,
        length: f64,
        gravity: f64,
        #[serde(default)]
        viscosity: f64,
    },
    TwoLink {
        l1: f64,
        l2: f64,
        s2: f64,
        m2: f64,
        i1: f64,
        i2: f64,
        #[serde(default)]
        viscosity: [[f64; 2]; 2],
    },
}

/// `[actuator]`, by `type`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawActuator {
    Torque {
        torque_limit: Option<f64>,
    },
    Impedance {
        #[serde(default)]
        damping: DampingLaw,
        alpha: Option<f64>,
        slope: Option<f64>,
        offset: Option<f64>,
        torque_limit: Option<f64>,
        stiffness_min: Option<f64>,
        stiffness_max: Option<f64>,
        /// Stiffness of the initial guess handed to the solver [N m/rad].
        initial_stiffness: Option<f64>,
        /// How the realised stiffness follows its command.
        #[serde(default)]
        stiffness_dynamics: StiffnessDynamics,
        /// `τ_K` [s], for `stiffness_dynamics = "first_order"`.
        stiffness_time_constant: Option<f64>,
    },
    Vsa {
        motor_inertia: Vec<f64>,
        torque_limit: Option<f64>,
        stiffness_min: Option<f64>,
        stiffness_max: Option<f64>,
        initial_stiffness: Option<f64>,
    },
}

/// The limits every actuator type may set.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct RawLimits {
    pub torque_limit: Option<f64>,
    pub stiffness_min: Option<f64>,
    pub stiffness_max: Option<f64>,
    pub initial_stiffness: Option<f64>,
}

impl RawActuator {
    pub fn limits(&self) -> RawLimits {
        match *self {
            RawActuator::Torque { torque_limit } => RawLimits {
                torque_limit,
                ..RawLimits::default()
            },
            RawActuator::Impedance {
                torque_limit,
                stiffness_min,
                stiffness_max,
                initial_stiffness,
                ..
            }
            | RawActuator::Vsa {
                torque_limit,
                stiffness_min,
                stiffness_max,
                initial_stiffness,
                ..
            } => RawLimits {
                torque_limit,
                stiffness_min,
                stiffness_max,
                initial_stiffness,
            },
        }
    }
}

/// `[actuator] damping`: how the damping follows the stiffness (Eq. 4's `K_D`).
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum DampingLaw {
    #[default]
    Proportional,
    Affine,
}

/// `[actuator] stiffness_dynamics`: whether the impedance's stiffness acts at once or lags its
/// command.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum StiffnessDynamics {
    /// The stiffness is a control that acts at once (the paper's type 2).
    #[default]
    Ideal,
    /// `K' = (K_c − K) / τ_K`.
    FirstOrder,
}

/// `[field]`, by `kind`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawField {
    None {},
    Divergent { beta: f64 },
    Curl { matrix: [[f64; 2]; 2] },
}

/// `[noise]`, by `kind`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawNoise {
    None {},
    State {
        sigma: f64,
        /// State component the noise drives (default: the first joint velocity).
        component: Option<usize>,
    },
    Torque {
        a: f64,
        b: f64,
        sample_time: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCost {
    pub(crate) w_torque: f64,
    /// Required when the actuator has a stiffness.
    pub(crate) w_stiffness: Option<f64>,
    pub w_p: f64,
    pub w_v: f64,
}

/// `[task] kind`: which movement the reference follows.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum PathKind {
    Joint,
    Hand,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawTask {
    pub kind: PathKind,
    pub(crate) start_deg: Option<Vec<f64>>,
    pub(crate) target_deg: Option<Vec<f64>>,
    pub(crate) hand_start: Option<[f64; 2]>,
    pub(crate) hand_target: Option<[f64; 2]>,
    pub duration: f64,
    pub dt: f64,
    #[serde(default)]
    pub delay_ms: f64,
    #[serde(default = "one")]
    pub substeps: usize,
    #[serde(default = "euler")]
    pub integrator: Integrator,
}

fn one() -> usize {
    1
}

fn euler() -> Integrator {
    Integrator::Euler
}

/// `[solver]`: every key optional. An absent key keeps the solver's own default
/// ([`IlqgOptions::default`](vic_core::solver::IlqgOptions), [`SoocOptions::default`](vic_core::solver::sooc_newton::SoocOptions)):
/// the defaults live there only.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSolver {
    #[serde(default)]
    pub method: Method,
    /// ILQG's and SOOC's (per noise stage) iteration limit.
    pub max_iterations: Option<usize>,
    pub tolerance: Option<f64>,
    pub gradient_tolerance: Option<f64>,
    pub mu_init: Option<f64>,
    pub mu_min: Option<f64>,
    pub mu_max: Option<f64>,
    pub stochastic: Option<bool>,
    pub damp_short_steps: Option<bool>,
    /// SOOC: what to do with an indefinite Newton model.
    pub indefinite: Option<Indefinite>,
    /// SOOC: the relative gain per step below which the Newton model adds the flow's third
    /// derivatives.
    pub third_derivatives_below: Option<f64>,
    /// SOOC: every other Newton step keeps the previous point's third derivatives.
    pub keep_third_derivatives: Option<bool>,
    /// Deterministic solves hold an impedance's stiffness at its lower limit first, then free
    /// it (default true; see [`super::solver::held_first`]).
    pub hold_stiffness_first: Option<bool>,
}
