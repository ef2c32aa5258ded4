//! `vic identify`: the paper's noise identification (Sec. III-B) on a joint log, with the joint's
//! parameters from a single-joint scenario (else the iCub forearm's).

use crate::cli::{Classify, JsonArg, input_error, print_report};
use crate::ranges::whole;
use crate::studies::identify::{
    IdentifyError, IdentifyOptions, JointParams, identify, read_log_file,
};
use std::path::{Path, PathBuf};
use vic_core::model::Plant;
use vic_plan::scenario::Scenario;

#[derive(clap::Args)]
pub(crate) struct Args {
    /// The log (CSV).
    #[arg(long, value_name = "FILE.csv")]
    log: PathBuf,
    /// Single-joint scenario whose [plant] gives J, m, l_c and g (default: the iCub forearm).
    #[arg(long, short, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of velocity bins. [range: 1 to 10000]
    #[arg(long, default_value_t = 20, value_parser = whole(1usize, 10_000))]
    bins: usize,
    /// Fewest samples a bin needs to be used. [range: 1 to 1000000000]
    #[arg(long, default_value_t = 30, value_parser = whole(1usize, 1_000_000_000))]
    min_bin_count: usize,
    /// Degree of the polynomial fitted to the mean error (the paper: 1). [range: 0 to 10]
    #[arg(long, default_value_t = 1, value_parser = whole(0usize, 10))]
    mean_degree: usize,
    /// Degree of the polynomial fitted to the error's standard deviation (the paper: 2).
    /// [range: 0 to 10]
    #[arg(long, default_value_t = 2, value_parser = whole(0usize, 10))]
    std_degree: usize,
    /// Subtract the fitted mean error before estimating (a, b).
    #[arg(long)]
    subtract_mean: bool,
    #[command(flatten)]
    json: JsonArg,
}

/// Identifies the noise of the log at `--log` and prints the report (JSON or text).
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let options = IdentifyOptions {
        bins: a.bins,
        min_bin_count: a.min_bin_count,
        mean_degree: a.mean_degree,
        std_degree: a.std_degree,
        subtract_mean: a.subtract_mean,
    };
    let log = &a.log;
    let joint = match &a.config {
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
    let report = identify(&rows, &joint, &options)
        .map_err(|e| format!("{}: {e}", log.display()))
        .input()?;
    print_report(&report, a.json.json, |r| println!("{r}"))
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
