//! From a scenario and a plan to what the real-time layer runs: the board's configuration and the
//! central controller's [`Track`]. The real-time layer never sees a scenario file.

use vic_plan::plan::{PlanError, PlanFile, Setup};
use vic_plan::scenario::Scenario;
use vic_rt::board::BoardConfig;
use vic_rt::central::{Track, TrackError};
use vic_rt::transport::MAX_JOINTS;

/// The board of a scenario at `period_ns`: its `[board]` limits, its stiffness and torque
/// bounds, and enough sub-steps to integrate at least as finely as the planner did.
pub fn board_config(s: &Scenario, period_ns: u64) -> BoardConfig {
    let dof = s.model.dof();
    let b = &s.board;
    let finite_or = |v: f64, d: f64| if v.is_finite() { v } else { d };
    let ns = |sec: f64| (sec * 1e9).round() as u64;
    let mut joint_min = [-std::f64::consts::PI; MAX_JOINTS];
    let mut joint_max = [std::f64::consts::PI; MAX_JOINTS];
    joint_min[..dof].copy_from_slice(&b.joint_min[..dof]);
    joint_max[..dof].copy_from_slice(&b.joint_max[..dof]);
    BoardConfig {
        period_ns,
        substeps: ((period_ns as f64 * 1e-9) / (s.task.dt / s.task.substeps as f64))
            .ceil()
            .max(1.0) as usize,
        integrator: s.task.integrator,
        hold_stiffness: b.hold_stiffness,
        watchdog_ns: ns(b.watchdog),
        ramp_ns: ns(b.ramp),
        joint_min,
        joint_max,
        velocity_max: b.velocity_max,
        future_tolerance_ns: ns(b.future_tolerance),
        max_pulse_torque: b.max_pulse_torque,
        max_load_torque: b.max_load_torque,
        max_pulse_ns: ns(b.max_pulse_duration),
        max_field_beta: b.max_field_beta,
        max_noise_factor: b.max_noise_factor,
        stiffness_max: finite_or(s.bounds.upper.get(dof).copied().unwrap_or(1e4), 1e4),
        // A board without a torque limit is a hazard: 100 N m when the scenario has none.
        torque_max: finite_or(s.bounds.upper[0].abs().max(s.bounds.lower[0].abs()), 100.0),
        max_catch_up: 50,
    }
}

/// Why a plan file cannot be played on the board of a scenario.
#[derive(Debug, thiserror::Error)]
pub(crate) enum LaunchError {
    /// The plan does not fit the scenario (steps, dimensions).
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The policy cannot run on the real-time board (actuator, reference length).
    #[error(transparent)]
    Track(#[from] TrackError),
}

/// The track the central controller plays back for `plan` on the scenario set up as `setup`.
pub(crate) fn track(plan: &PlanFile, setup: &Setup) -> Result<Track, LaunchError> {
    Ok(Track::new(
        plan.policy(setup)?,
        setup.dynamics.clone(),
        setup.cost.clone(),
        &setup.x0,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;
    use vic_plan::scenario::Scenario;
    use vic_rt::central::{Controller, Latency, Strategy, Timing};
    use vic_rt::transport::{Mode, StateMsg};

    fn central() -> Controller {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let s = Scenario::load(
            &root.join("config/two_link_divergent.toml"),
            &["noise.sigma=0.02".into()],
        )
        .unwrap();
        let setup = vic_plan::plan::setup(&s).unwrap();
        let text = std::fs::read_to_string(
            root.join("tests/data/realtime/two_link_divergent_sigma002_sooc.json"),
        )
        .unwrap();
        let plan: PlanFile = serde_json::from_str(&text).unwrap();
        let timing = Timing::split(Latency::ZERO, 20_000_000);
        Controller::new(track(&plan, &setup).unwrap(), Strategy::Stiffness, timing)
    }

    #[test]
    fn states_of_a_trial_before_a_restart_are_not_mixed_in() {
        let mut c = central();
        let reset = c.begin_trial(0, 1, 1_000_000_000, 0);
        // A state of "trial 0" from before this controller started (another reset), in safe
        // hold 100 ms into the movement: not ours.
        let stale = StateMsg {
            trial: 0,
            mode: Mode::SafeHold as u32,
            trial_time_ns: 100_000_000,
            reset_seq: reset.header.seq - 7,
            ..Default::default()
        };
        c.on_state(&stale, 0);
        let r = c.record();
        assert!(!r.safe_hold, "an old trial's safe hold counted");
        assert_eq!(r.missing_states, c.track.steps + 1);
        // The same state from our reset is recorded.
        c.on_state(
            &StateMsg {
                reset_seq: reset.header.seq,
                ..stale
            },
            0,
        );
        let r = c.record();
        assert!(r.safe_hold);
        assert_eq!(r.missing_states, c.track.steps);
    }
}
