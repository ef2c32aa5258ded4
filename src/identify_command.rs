//! `vic identify`: the paper's noise identification (Sec. III-B) on a joint log, with the joint's
//! parameters from a single-joint scenario (else the iCub forearm's).

use crate::cli::{Classify, input_error, print_report};
use crate::studies::identify::{
    IdentifyError, IdentifyOptions, JointParams, identify, read_log_file,
};
use std::path::{Path, PathBuf};
use vic_core::model::Plant;
use vic_plan::scenario::Scenario;

/// Identifies the noise of the log at `log` and prints the report (JSON or text).
pub fn run(
    log: &Path,
    config: Option<&PathBuf>,
    options: &IdentifyOptions,
    json: bool,
) -> anyhow::Result<()> {
    let joint = match config {
        None => JointParams::ICUB_FOREARM,
        Some(path) => joint_of(path)?,
    };
    let rows = read_log_file(log)
        .map_err(|e| match e {
            // It names the file already.
            IdentifyError::Open { .. } => e.to_string(),
            e => format!("{}: {e}", log.display()),
        })
        .input()?;
    let report = identify(&rows, &joint, options)
        .map_err(|e| format!("{}: {e}", log.display()))
        .input()?;
    print_report(&report, json, |r| println!("{r}"))
}

/// The inertia, mass, centre of mass and gravity of the single joint of the scenario at `path`.
fn joint_of(path: &Path) -> anyhow::Result<JointParams> {
    let s = Scenario::load(path, &[]).input()?;
    match &s.model.plant {
        Plant::SingleJoint(p) => Ok(JointParams {
            inertia: p.inertia,
            mass: p.mass,
            com: p.com,
            gravity: p.gravity,
        }),
        Plant::TwoLink(_) => Err(input_error(format!(
            "{}: [plant] kind: identification needs a single joint",
            path.display()
        ))),
    }
}
