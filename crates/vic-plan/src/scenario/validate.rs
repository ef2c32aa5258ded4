//! From the file as written ([`raw`](super::raw)) to a [`Scenario`] whose models cannot be
//! inconsistent: ranges, the keys a variant needs, and the checks that span sections.

use super::error::{ConfigError, FileCheck};
use super::raw::{
    DampingLaw, PathKind, RawActuator, RawConfig, RawCost, RawField, RawLimits, RawNoise, RawPlant,
    RawTask, StiffnessDynamics,
};
use super::stability::{check_hold_stiffness, check_substep};
use super::{CostWeights, Scenario, Task, TaskPath};
use std::path::Path;
use vic_core::latency::Latency;
use vic_core::model::{Actuator, ArmModel, Damping, Field, Noise, Plant, SingleJoint, TwoLink};
use vic_core::solver::Bounds;

/// Checks every section and builds the scenario (`resolved` is kept for plan files).
pub(super) fn validate(
    raw: RawConfig,
    path: &Path,
    resolved: toml::Table,
) -> Result<Scenario, ConfigError> {
    let check = FileCheck { path };
    let raw_plant = raw.plant.ok_or_else(|| check.missing_section("plant"))?;
    let plant = plant(raw_plant, &check)?;
    let dof = plant.dof();
    let raw_actuator = raw
        .actuator
        .ok_or_else(|| check.missing_section("actuator"))?;
    let actuator = actuator(&raw_actuator, dof, &check)?;
    let field = field(raw.field.ok_or_else(|| check.missing_section("field"))?);
    let raw_noise = raw.noise.ok_or_else(|| check.missing_section("noise"))?;
    let noise = noise(raw_noise, actuator.nx(dof), dof, &check)?;
    let model = ArmModel::new(plant, actuator, field, noise).map_err(|e| {
        let (section, key) = e.key();
        check.invalid(section, key, e.to_string())
    })?;
    let raw_cost = raw.cost.ok_or_else(|| check.missing_section("cost"))?;
    let weights = weights(raw_cost, &model, &check)?;
    let task = task(
        raw.task.ok_or_else(|| check.missing_section("task"))?,
        &model,
        &check,
    )?;
    let limits = raw_actuator.limits();
    let bounds = bounds(&limits, &model, &check)?;
    let initial_stiffness = limits.initial_stiffness.unwrap_or(match model.actuator {
        // A VSA needs a spring to move the link at all.
        Actuator::Vsa { .. } => 10.0,
        _ => 0.0,
    });
    let initial_stiffness =
        check.non_negative(initial_stiffness, "actuator", "initial_stiffness")?;
    check_substep(&model, &task, &bounds, &check)?;
    let hold_stiffness_first = raw.solver.hold_stiffness_first();
    let mut solver = raw.solver.resolve(&check)?;
    solver.options.held_first = super::solver::held_first(&model, hold_stiffness_first);
    let board = raw.board.resolve(dof, &check)?;
    check_hold_stiffness(&model, &task, &board, &check)?;
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

fn plant(raw: RawPlant, check: &FileCheck) -> Result<Plant, ConfigError> {
    let positive = |v: f64, key: &str| check.positive(v, "plant", key);
    let non_negative = |v: f64, key: &str| check.non_negative(v, "plant", key);
    Ok(match raw {
        RawPlant::SingleJoint {
            inertia,
            mass,
            com,
            length,
            gravity,
            viscosity,
        } => Plant::SingleJoint(SingleJoint {
            inertia: positive(inertia, "inertia")?,
            mass: non_negative(mass, "mass")?,
            com: non_negative(com, "com")?,
            length: positive(length, "length")?,
            gravity: non_negative(gravity, "gravity")?,
            viscosity: non_negative(viscosity, "viscosity")?,
        }),
        RawPlant::TwoLink {
            l1,
            l2,
            s2,
            m2,
            i1,
            i2,
            viscosity,
        } => Plant::TwoLink(TwoLink {
            l1: positive(l1, "l1")?,
            l2: positive(l2, "l2")?,
            s2: positive(s2, "s2")?,
            m2: positive(m2, "m2")?,
            i1: positive(i1, "i1")?,
            i2: positive(i2, "i2")?,
            viscosity,
        }),
    })
}

fn actuator(raw: &RawActuator, dof: usize, check: &FileCheck) -> Result<Actuator, ConfigError> {
    Ok(match raw {
        RawActuator::Torque { .. } => Actuator::Torque,
        RawActuator::Impedance {
            damping,
            alpha,
            slope,
            offset,
            stiffness_dynamics,
            stiffness_time_constant,
            ..
        } => {
            let damping = match damping {
                DampingLaw::Proportional => {
                    let why = "for damping = \"proportional\"";
                    let alpha = check.required(*alpha, "actuator", "alpha", why)?;
                    Damping::Proportional {
                        alpha: check.non_negative(alpha, "actuator", "alpha")?,
                    }
                }
                DampingLaw::Affine => {
                    let why = "for damping = \"affine\"";
                    Damping::Affine {
                        slope: check.required(*slope, "actuator", "slope", why)?,
                        offset: check.required(*offset, "actuator", "offset", why)?,
                    }
                }
            };
            match stiffness_dynamics {
                StiffnessDynamics::Ideal => {
                    if stiffness_time_constant.is_some() {
                        return Err(check.invalid(
                            "actuator",
                            "stiffness_time_constant",
                            "applies to stiffness_dynamics = \"first_order\" only; \
                             the ideal stiffness acts at once",
                        ));
                    }
                    Actuator::Impedance { damping }
                }
                StiffnessDynamics::FirstOrder => {
                    let why = "for stiffness_dynamics = \"first_order\" (τ_K in s)";
                    let key = "stiffness_time_constant";
                    let tau = check.required(*stiffness_time_constant, "actuator", key, why)?;
                    Actuator::ImpedanceLag {
                        damping,
                        time_constant: check.positive(tau, "actuator", key)?,
                    }
                }
            }
        }
        RawActuator::Vsa { motor_inertia, .. } => {
            let b = motor_inertia;
            if b.len() != dof || b.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(check.invalid(
                    "actuator",
                    "motor_inertia",
                    format!("must list {dof} positive motor inertias [kg m²], got {b:?}"),
                ));
            }
            Actuator::Vsa {
                motor_inertia: b.clone(),
            }
        }
    })
}

fn field(raw: RawField) -> Field {
    match raw {
        RawField::None {} => Field::None,
        RawField::Divergent { beta } => Field::Divergent { beta },
        RawField::Curl { matrix } => Field::Curl { matrix },
    }
}

/// The noise model; `nx` is the state dimension the noise component indexes.
fn noise(raw: RawNoise, nx: usize, dof: usize, check: &FileCheck) -> Result<Noise, ConfigError> {
    Ok(match raw {
        RawNoise::None {} => Noise::None,
        RawNoise::State { sigma, component } => {
            // Default: the first joint velocity, where a torque disturbance enters.
            let component = component.unwrap_or(dof);
            if component >= nx {
                return Err(check.invalid(
                    "noise",
                    "component",
                    format!("{component} is out of range: the state has {nx} components (0-based)"),
                ));
            }
            Noise::StateProportional {
                sigma: check.non_negative(sigma, "noise", "sigma")?,
                component,
            }
        }
        RawNoise::Torque { a, b, sample_time } => Noise::Torque {
            a,
            b,
            sample_time: check.positive(sample_time, "noise", "sample_time")?,
        },
    })
}

/// The Eq. 14 weights; a stiffness weight is required when the actuator has a stiffness.
fn weights(raw: RawCost, model: &ArmModel, check: &FileCheck) -> Result<CostWeights, ConfigError> {
    if model.actuator.stiffness_offset(model.dof()).is_some() && raw.w_stiffness.is_none() {
        return Err(check.invalid(
            "cost",
            "w_stiffness",
            "missing, required when the actuator has stiffness",
        ));
    }
    Ok(CostWeights {
        w_torque: check.non_negative(raw.w_torque, "cost", "w_torque")?,
        w_stiffness: check.non_negative(raw.w_stiffness.unwrap_or(0.0), "cost", "w_stiffness")?,
        w_p: check.non_negative(raw.w_p, "cost", "w_p")?,
        w_v: check.non_negative(raw.w_v, "cost", "w_v")?,
    })
}

/// Timing and path: the duration and the delay must be whole numbers of steps.
fn task(raw: RawTask, model: &ArmModel, check: &FileCheck) -> Result<Task, ConfigError> {
    let duration = check.positive(raw.duration, "task", "duration")?;
    let dt = check.positive(raw.dt, "task", "dt")?;
    let steps = duration / dt;
    if (steps - steps.round()).abs() > 1e-6 || steps.round() < 2.0 {
        return Err(check.invalid(
            "task",
            "dt",
            format!("the duration {duration} s must be a whole number (≥ 2) of steps of {dt} s"),
        ));
    }
    let delay_ms = check.non_negative(raw.delay_ms, "task", "delay_ms")?;
    if let Err(e) = Latency::from_ms(delay_ms, dt) {
        return Err(check.invalid(
            "task",
            "delay_ms",
            format!(
                "{delay_ms} ms is not a whole number of {} ms steps",
                e.step_ms
            ),
        ));
    }
    let path = task_path(&raw, model, check)?;
    if raw.substeps == 0 {
        return Err(check.invalid("task", "substeps", "must be at least 1"));
    }
    Ok(Task {
        path,
        duration,
        dt,
        steps: steps.round() as usize,
        delay_ms,
        substeps: raw.substeps,
        integrator: raw.integrator,
    })
}

/// The reference path: joint postures in degrees (one per joint), or hand points within reach.
fn task_path(raw: &RawTask, model: &ArmModel, check: &FileCheck) -> Result<TaskPath, ConfigError> {
    let dof = model.dof();
    match raw.kind {
        PathKind::Joint => {
            let why = "for kind = \"joint\" (degrees, one per joint)";
            let start = check.required(raw.start_deg.clone(), "task", "start_deg", why)?;
            let target = check.required(raw.target_deg.clone(), "task", "target_deg", why)?;
            for (key, v) in [("start_deg", &start), ("target_deg", &target)] {
                if v.len() != dof {
                    return Err(check.invalid(
                        "task",
                        key,
                        format!("must have {dof} entries, got {}", v.len()),
                    ));
                }
            }
            Ok(TaskPath::Joint {
                start: start.iter().map(|d| d.to_radians()).collect(),
                target: target.iter().map(|d| d.to_radians()).collect(),
            })
        }
        PathKind::Hand => {
            if dof != 2 {
                return Err(check.invalid("task", "kind", "a hand path needs the two-link arm"));
            }
            let why = "for kind = \"hand\" ([x, y] in m, shoulder at the origin)";
            let start = check.required(raw.hand_start, "task", "hand_start", why)?;
            let target = check.required(raw.hand_target, "task", "hand_target", why)?;
            for (key, v) in [("hand_start", start), ("hand_target", target)] {
                if model.plant.inverse_kinematics(v).is_none() {
                    return Err(check.invalid(
                        "task",
                        key,
                        format!("{v:?} m is out of the arm's reach"),
                    ));
                }
            }
            Ok(TaskPath::Hand { start, target })
        }
    }
}

/// Control limits: a symmetric torque limit and the stiffness range. Equal stiffness limits fix
/// the stiffness (stiffness_max = 0: an impedance actuator without stiffness, the paper's
/// "delayed feedback without stiffness").
fn bounds(limits: &RawLimits, model: &ArmModel, check: &FileCheck) -> Result<Bounds, ConfigError> {
    let dof = model.dof();
    let mut bounds = Bounds::unbounded(model.nu());
    if let Some(limit) = limits.torque_limit {
        let limit = check.positive(limit, "actuator", "torque_limit")?;
        bounds.lower[..dof].fill(-limit);
        bounds.upper[..dof].fill(limit);
    }
    if let Some(off) = model.actuator.stiffness_offset(dof) {
        let lo = limits.stiffness_min.unwrap_or(0.0);
        let lo = check.non_negative(lo, "actuator", "stiffness_min")?;
        let hi = limits.stiffness_max.unwrap_or(f64::INFINITY);
        if hi.is_nan() || hi < lo {
            return Err(check.invalid(
                "actuator",
                "stiffness_max",
                format!("must be at least stiffness_min ({lo}), got {hi}"),
            ));
        }
        bounds.lower[off..off + dof].fill(lo);
        bounds.upper[off..off + dof].fill(hi);
    }
    Ok(bounds)
}
