//! Numerical stability of the plant integration: a scenario whose sub-step is too long for its
//! stiffest impedance is refused before any plan is made on it.

use super::board::BoardSection;
use super::error::{ConfigError, FileCheck};
use super::{Task, TaskPath};
use vic_core::dynamics::Integrator;
use vic_core::model::{Actuator, ArmModel, Field, Plant};
use vic_core::solver::Bounds;

/// Refuses integration sub-steps too long for the stiffest configured impedance: explicit and
/// semi-implicit Euler both diverge once `h · K_D / I > 2` (a damping rate) or `h · ω > 2` (a VSA
/// spring), RK4 once either passes about 2.78; the Rosenbrock step takes them implicitly and is
/// stable at any step. A plan made on a numerically unstable plant says nothing about the robot.
pub(super) fn check_substep(
    model: &ArmModel,
    task: &Task,
    bounds: &Bounds,
    check: &FileCheck,
) -> Result<(), ConfigError> {
    if matches!(model.actuator, Actuator::ImpedanceLag { .. })
        && task.integrator == Integrator::Rosenbrock
    {
        return Err(check.invalid(
            "task",
            "integrator",
            "\"rosenbrock\" takes the stiffness implicitly as the control it is with \
             stiffness_dynamics = \"ideal\"; a lagged stiffness is a state: use \"semi_implicit\" \
             or \"rk4\""
                .to_string(),
        ));
    }
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
    let inertia = smallest_inertia(model, task);
    let h = task.dt / task.substeps as f64;
    if let Actuator::ImpedanceLag { time_constant, .. } = model.actuator
        && h > time_constant
    {
        // Euler's factor 1 − h/τ_K on the lag turns negative: the stiffness would overshoot
        // its command and oscillate around it, which no mechanism does.
        return Err(check.invalid(
            "actuator",
            "stiffness_time_constant",
            format!(
                "{time_constant} s is shorter than the integration sub-step of {:.2} ms: the \
                 lag's Euler step would overshoot; use a longer time constant, more substeps, \
                 or stiffness_dynamics = \"ideal\"",
                h * 1000.0
            ),
        ));
    }
    let rate = match &model.actuator {
        Actuator::Impedance { damping } | Actuator::ImpedanceLag { damping, .. } => {
            damping.gain(k_max) / inertia
        }
        Actuator::Vsa { motor_inertia } => {
            let b = motor_inertia.iter().copied().fold(f64::INFINITY, f64::min);
            (k_max / inertia.min(b)).sqrt()
        }
        Actuator::Torque => return Ok(()),
    };
    // Where the step's stability region meets the real axis (a damping rate) and, for the
    // Euler steps, the imaginary axis (a spring): 2 for both Euler steps; RK4's region reaches
    // -2.785 on the real axis and ±2.828 on the imaginary one.
    let limit = match task.integrator {
        Integrator::Euler | Integrator::SemiImplicit => 2.0,
        Integrator::Rk4 => 2.78,
        // The spring and damper (a VSA's spring) are implicit in the Rosenbrock step: L-stable
        // on them at any step.
        Integrator::Rosenbrock => return Ok(()),
    };
    if h * rate >= limit {
        let needed = (task.dt * rate / limit).floor() as usize + 1;
        return Err(check.invalid(
            "task",
            "substeps",
            format!(
                "{} sub-step(s) of {:.2} ms are numerically unstable at stiffness_max = {k_max} N m/rad \
                 (rate {rate:.0}/s needs h < {:.2} ms with {}): use substeps ≥ {needed} or a lower \
                 stiffness_max",
                task.substeps,
                h * 1000.0,
                1000.0 * limit / rate,
                integrator_name(task.integrator)
            ),
        ));
    }
    Ok(())
}

/// The smallest effective inertia over the postures of the task (elbow angles between start and
/// target, with a margin): the smallest eigenvalue of M(q).
fn smallest_inertia(model: &ArmModel, task: &Task) -> f64 {
    let dof = model.dof();
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
    (0..=36)
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
        .fold(f64::INFINITY, f64::min)
}

/// The board's tick at its default rate (1 kHz) [s]: it integrates in sub-steps no longer than
/// this nor than the scenario's own sub-step.
pub(crate) const BOARD_TICK_S: f64 = 1e-3;

/// The largest negative stiffness the plant itself adds at rest [N m/rad], posture-independent:
/// the gradient of the gravity torque `m g l_c cos q` (Eq. 15) is at most `m g l_c`, and the
/// divergent field `D = (β x, 0)` adds `−β J_xᵀ J_x` with `‖J_x‖² ≤ (l1 + l2)² + l2²` (a single
/// joint: `l²`). A velocity field (curl) adds none at rest.
fn plant_negative_stiffness(model: &ArmModel) -> f64 {
    let gravity = match &model.plant {
        Plant::SingleJoint(p) => p.mass * p.gravity.abs() * p.com,
        Plant::TwoLink(_) => 0.0,
    };
    let reach_sq = match &model.plant {
        Plant::SingleJoint(p) => p.length * p.length,
        Plant::TwoLink(p) => (p.l1 + p.l2).powi(2) + p.l2 * p.l2,
    };
    let field = match model.field {
        Field::Divergent { beta } => beta.max(0.0) * reach_sq,
        Field::None | Field::Curl { .. } => 0.0,
    };
    gravity + field
}

/// The smallest safe-hold stiffness of a board [N m/rad]. Held at `q*` with stiffness `k`, the
/// joint's static balance under a steady load `τ` is `(k − k_p) δ = τ`, where `k_p` is the
/// plant's own negative stiffness ([`plant_negative_stiffness`]: gravity, the scenario's field).
/// The hold is stable only when `k > k_p`, and the largest load the board accepts
/// (`board.max_load_torque`) must not push a joint held in the middle of its range to a joint
/// limit (a fault): `δ ≤ r`, `r` half the narrowest range `(joint_max − joint_min) / 2`. Hence
/// `k ≥ k_p + max_load_torque / r`. A pulse (at most `board.max_pulse_torque`) is transient and
/// is caught by the damping; a field switched on later with a larger β (up to
/// `board.max_field_beta`) is the operator's choice and is not assumed here.
pub(super) fn hold_stiffness_min(model: &ArmModel, board: &BoardSection) -> f64 {
    let half_range = board
        .joint_min
        .iter()
        .zip(&board.joint_max)
        .map(|(lo, hi)| 0.5 * (hi - lo))
        .fold(f64::INFINITY, f64::min);
    plant_negative_stiffness(model) + board.max_load_torque / half_range
}

/// Refuses a safe-hold stiffness the board cannot hold stably: the impedance law's damping
/// `K_D = gain(k)` (Eq. 4) must not be negative (it would pump energy in), `k` must reach
/// [`hold_stiffness_min`] (the plant's own negative stiffness plus the largest load within half
/// the joint range), and the board's semi-implicit Euler step `h = min(dt / substeps, 1 ms)` must
/// satisfy both `h · K_D / I < 2` and `h · sqrt(k / I) < 2` at the smallest inertia of the task's
/// postures (a VSA: the spring against the lighter of link and motor).
pub(super) fn check_hold_stiffness(
    model: &ArmModel,
    task: &Task,
    board: &BoardSection,
    check: &FileCheck,
) -> Result<(), ConfigError> {
    let k = board.hold_stiffness;
    let inertia = smallest_inertia(model, task);
    let rate = match &model.actuator {
        Actuator::Impedance { damping } | Actuator::ImpedanceLag { damping, .. } => {
            let d = damping.gain(k);
            if d < 0.0 {
                return Err(check.invalid(
                    "board",
                    "hold_stiffness",
                    format!(
                        "{k} N m/rad gives a negative damping {d} N m s/rad under the actuator's \
                         damping law: the hold would pump energy into the arm; raise it"
                    ),
                ));
            }
            check_hold_minimum(model, board, check)?;
            (d / inertia).max((k / inertia).sqrt())
        }
        Actuator::Vsa { motor_inertia } => {
            check_hold_minimum(model, board, check)?;
            let b = motor_inertia.iter().copied().fold(f64::INFINITY, f64::min);
            (k / inertia.min(b)).sqrt()
        }
        // The board runs the impedance law only; it refuses other actuators itself.
        Actuator::Torque => return Ok(()),
    };
    let h = (task.dt / task.substeps as f64).min(BOARD_TICK_S);
    if h * rate >= 2.0 {
        return Err(check.invalid(
            "board",
            "hold_stiffness",
            format!(
                "{k} N m/rad is numerically unstable on the board's {:.2} ms step (rate {rate:.0}/s \
                 at the smallest inertia {inertia:.4} kg m² needs h < {:.2} ms): lower it",
                h * 1000.0,
                2000.0 / rate
            ),
        ));
    }
    Ok(())
}

/// Refuses a hold stiffness below [`hold_stiffness_min`].
fn check_hold_minimum(
    model: &ArmModel,
    board: &BoardSection,
    check: &FileCheck,
) -> Result<(), ConfigError> {
    let (k, k_min, k_p) = (
        board.hold_stiffness,
        hold_stiffness_min(model, board),
        plant_negative_stiffness(model),
    );
    if k < k_min || k <= k_p {
        return Err(check.invalid(
            "board",
            "hold_stiffness",
            format!(
                "{k} N m/rad is below the {k_min:.3} N m/rad this board needs: the plant's own \
                 negative stiffness (gravity, field) is {k_p:.3} N m/rad, and the largest load \
                 (max_load_torque = {} N m) must not push a held joint past half its range; \
                 raise it",
                board.max_load_torque
            ),
        ));
    }
    Ok(())
}

/// The integrator as the scenario file names it.
fn integrator_name(i: Integrator) -> &'static str {
    match i {
        Integrator::Euler => "euler",
        Integrator::SemiImplicit => "semi_implicit",
        Integrator::Rk4 => "rk4",
        Integrator::Rosenbrock => "rosenbrock",
    }
}
