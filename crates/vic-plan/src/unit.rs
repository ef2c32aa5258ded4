//! The unit positions are reported in, decided once for every report: the hand in millimetres for
//! the two-link arm (a reaching error is a distance), the joint angle in degrees for a single
//! joint (an elbow error is an angle).

use serde::{Deserialize, Serialize};
use vic_core::model::ArmModel;

/// The unit of reported positions and position errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Unit {
    /// Hand position of the two-link arm [mm].
    #[serde(rename = "mm")]
    Millimetre,
    /// Joint angle of a single joint [deg].
    #[serde(rename = "deg")]
    Degree,
}

impl Unit {
    /// The unit for a model's positions: degrees for one joint, millimetres of hand for the arm.
    pub fn for_model(model: &ArmModel) -> Unit {
        if model.dof() == 1 {
            Unit::Degree
        } else {
            Unit::Millimetre
        }
    }

    /// Factor from the SI value (m or rad) to this unit.
    pub fn scale(self) -> f64 {
        match self {
            Unit::Millimetre => 1000.0,
            Unit::Degree => 1.0_f64.to_degrees(),
        }
    }

    /// The unit's symbol, as written in reports and files.
    pub fn name(self) -> &'static str {
        match self {
            Unit::Millimetre => "mm",
            Unit::Degree => "deg",
        }
    }

    /// Default divergence threshold: a trial ending further than this from the target has not
    /// reached it (5 cm of hand, 10° of joint).
    pub fn default_divergence(self) -> f64 {
        match self {
            Unit::Millimetre => 50.0,
            Unit::Degree => 10.0,
        }
    }

    /// Distance beyond which a trial counts as "far" from the target (5 cm of hand, 5° of joint).
    pub(crate) fn far_threshold(self) -> f64 {
        match self {
            Unit::Millimetre => 50.0,
            Unit::Degree => 5.0,
        }
    }
}

impl std::fmt::Display for Unit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
