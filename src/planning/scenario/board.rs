//! The `[board]` section: the live board's safety limits.

use super::error::{ConfigError, FileCheck};
use super::raw::RawBoard;

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

impl RawBoard {
    /// Checks the limits of a board driving `dof` joints.
    pub(super) fn resolve(
        self,
        dof: usize,
        check: &FileCheck,
    ) -> Result<BoardSection, ConfigError> {
        let pos = |v: f64, key: &str| check.positive(v, "board", key);
        let nonneg = |v: f64, key: &str| check.non_negative(v, "board", key);
        let range = |v: Option<Vec<f64>>, default: f64, key: &str| {
            let v = v.unwrap_or_else(|| vec![default; dof]);
            if v.len() != dof || v.iter().any(|x| !x.is_finite()) {
                return Err(check.invalid(
                    "board",
                    key,
                    format!("must be {dof} finite angle(s) [rad], got {v:?}"),
                ));
            }
            Ok(v)
        };
        let joint_min = range(self.joint_min, -std::f64::consts::PI, "joint_min")?;
        let joint_max = range(self.joint_max, std::f64::consts::PI, "joint_max")?;
        if joint_min.iter().zip(&joint_max).any(|(a, b)| a >= b) {
            return Err(check.invalid(
                "board",
                "joint_max",
                format!("must exceed joint_min {joint_min:?} joint by joint, got {joint_max:?}"),
            ));
        }
        Ok(BoardSection {
            watchdog: nonneg(self.watchdog, "watchdog")?,
            ramp: nonneg(self.ramp, "ramp")?,
            hold_stiffness: pos(self.hold_stiffness, "hold_stiffness")?,
            joint_min,
            joint_max,
            velocity_max: pos(self.velocity_max, "velocity_max")?,
            future_tolerance: nonneg(self.future_tolerance, "future_tolerance")?,
            max_pulse_torque: nonneg(self.max_pulse_torque, "max_pulse_torque")?,
            max_load_torque: nonneg(self.max_load_torque, "max_load_torque")?,
            max_pulse_duration: nonneg(self.max_pulse_duration, "max_pulse_duration")?,
            max_field_beta: nonneg(self.max_field_beta, "max_field_beta")?,
            max_noise_factor: nonneg(self.max_noise_factor, "max_noise_factor")?,
        })
    }
}
