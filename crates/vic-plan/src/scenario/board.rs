//! The `[board]` section: the live board's safety limits.

use super::error::{ConfigError, FileCheck};
use serde::Deserialize;

/// The `[board]` section as written (defaults in [`BoardSection`]'s documentation).
pub(super) type RawBoard = BoardSection<Option<Vec<f64>>>;

impl Default for RawBoard {
    fn default() -> Self {
        BoardSection {
            watchdog: 0.05,
            ramp: 0.1,
            hold_stiffness: 100.0,
            joint_min: None,
            joint_max: None,
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

/// The `[board]` section: the live board's safety limits (every key optional; defaults below).
///
/// The file's section is the same struct with the joint range optional (`J = Option<Vec<f64>>`,
/// `RawBoard`: the number of joints comes from the plant), so that the keys are written once;
/// `RawBoard::resolve` checks every limit and fills in the joint range.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoardSection<J = Vec<f64>> {
    /// How long the last valid command stays in force once no command covers the present [s]
    /// before the board ramps to its safe hold (default 0.05).
    pub watchdog: f64,
    /// Duration of the ramp into the safe hold [s] (default 0.1).
    pub ramp: f64,
    /// Stiffness of the safe hold [N m/rad] (default 100).
    pub hold_stiffness: f64,
    /// Plant guard: joint range [rad] and speed limit [rad/s]; leaving them latches a fault that
    /// only a reset clears (defaults ±π, 20 rad/s).
    pub joint_min: J,
    pub joint_max: J,
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

/// The physically sensible range of a bounded `[board]` key. A value outside it is a typo or a
/// hazard (a hold stiffness of 1e308, a watchdog of an hour, a pulse of 10 kN m), refused when the
/// scenario is read, before a board runs on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardRange {
    pub key: &'static str,
    pub min: f64,
    /// Whether `min` itself is allowed (a stiffness or a speed limit of 0 is not).
    pub min_inclusive: bool,
    pub max: f64,
    pub unit: &'static str,
}

impl BoardRange {
    const fn closed(key: &'static str, min: f64, max: f64, unit: &'static str) -> BoardRange {
        BoardRange {
            key,
            min,
            min_inclusive: true,
            max,
            unit,
        }
    }
    const fn positive(key: &'static str, max: f64, unit: &'static str) -> BoardRange {
        BoardRange {
            key,
            min: 0.0,
            min_inclusive: false,
            max,
            unit,
        }
    }

    /// Whether `v` lies in the range (NaN and infinities never do).
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite() && (v > self.min || (self.min_inclusive && v == self.min)) && v <= self.max
    }

    /// "[0.001, 1] s", "(0, 1000] N m/rad".
    pub fn describe(&self) -> String {
        let open = if self.min_inclusive { '[' } else { '(' };
        format!("{open}{}, {}] {}", self.min, self.max, self.unit)
    }
}

/// The bounded keys of `[board]` (the joint range is checked per joint against
/// [`JOINT_LIMIT_RAD`]). Watchdog: at least one 1 kHz tick, at most 1 s (the plant would drift on
/// a stale command for longer). Hold stiffness: positive, at most 1000 N m/rad (a human-scale arm;
/// the integration must also be stable at it, checked with the plant). Speeds, torques, durations
/// and the field: an order of magnitude above the paper's arm and its experiments.
pub const BOARD_RANGES: [BoardRange; 10] = [
    BoardRange::closed("watchdog", 0.001, 1.0, "s"),
    BoardRange::closed("ramp", 0.0, 2.0, "s"),
    BoardRange::positive("hold_stiffness", 1000.0, "N m/rad"),
    BoardRange::positive("velocity_max", 100.0, "rad/s"),
    BoardRange::closed("future_tolerance", 0.0, 0.1, "s"),
    BoardRange::closed("max_pulse_torque", 0.0, 200.0, "N m"),
    BoardRange::closed("max_load_torque", 0.0, 200.0, "N m"),
    BoardRange::closed("max_pulse_duration", 0.0, 10.0, "s"),
    BoardRange::closed("max_field_beta", 0.0, 5000.0, "N/m"),
    BoardRange::closed("max_noise_factor", 0.0, 100.0, "×"),
];

/// Largest joint limit magnitude [rad]: one turn either way.
pub const JOINT_LIMIT_RAD: f64 = 2.0 * std::f64::consts::PI;

impl RawBoard {
    /// Checks the limits of a board driving `dof` joints.
    pub(super) fn resolve(
        self,
        dof: usize,
        check: &FileCheck,
    ) -> Result<BoardSection, ConfigError> {
        let bounded = |v: f64, key: &str| {
            let r = BOARD_RANGES
                .iter()
                .find(|r| r.key == key)
                .expect("every bounded key has a range");
            if r.contains(v) {
                Ok(v)
            } else {
                Err(check.invalid(
                    "board",
                    key,
                    format!("must be in {}, got {v:?}", r.describe()),
                ))
            }
        };
        let range = |v: Option<Vec<f64>>, default: f64, key: &str| {
            let v = v.unwrap_or_else(|| vec![default; dof]);
            let inside = |x: &f64| x.is_finite() && x.abs() <= JOINT_LIMIT_RAD;
            if v.len() != dof || !v.iter().all(inside) {
                return Err(check.invalid(
                    "board",
                    key,
                    format!(
                        "must be {dof} angle(s) in [-{JOINT_LIMIT_RAD:.4}, {JOINT_LIMIT_RAD:.4}] rad, got {v:?}"
                    ),
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
            watchdog: bounded(self.watchdog, "watchdog")?,
            ramp: bounded(self.ramp, "ramp")?,
            hold_stiffness: bounded(self.hold_stiffness, "hold_stiffness")?,
            joint_min,
            joint_max,
            velocity_max: bounded(self.velocity_max, "velocity_max")?,
            future_tolerance: bounded(self.future_tolerance, "future_tolerance")?,
            max_pulse_torque: bounded(self.max_pulse_torque, "max_pulse_torque")?,
            max_load_torque: bounded(self.max_load_torque, "max_load_torque")?,
            max_pulse_duration: bounded(self.max_pulse_duration, "max_pulse_duration")?,
            max_field_beta: bounded(self.max_field_beta, "max_field_beta")?,
            max_noise_factor: bounded(self.max_noise_factor, "max_noise_factor")?,
        })
    }
}
