//! `vic record`: flags, then [`vic::record_command::run_record`].

use std::path::PathBuf;
use vic::cli::{JsonArg, NamespaceArgs, non_negative_seconds, positive_seconds};
use vic::record_command::{RecordArgs as Run, run_record};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object")))]
pub struct RecordArgs {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// The MCAP file to write (truncated if it exists).
    #[arg(long, value_name = "FILE.mcap")]
    out: PathBuf,
    /// Stop this many seconds after the board's first state (0: at Ctrl-C / SIGTERM).
    #[arg(long, value_name = "S", default_value_t = 0.0)]
    duration: f64,
    /// Seconds to wait for a board before giving up (exit 1).
    #[arg(long, value_name = "S", default_value_t = 2.0)]
    wait: f64,
    /// The scenario the run uses (its path goes into the file's metadata).
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// The plan the run uses (its path and hash go into the file's metadata).
    #[arg(long, value_name = "FILE")]
    plan: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

impl RecordArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?.to_string();
        let duration = non_negative_seconds("--duration", self.duration)?;
        run_record(&Run {
            namespace,
            out: self.out,
            duration: (!duration.is_zero()).then_some(duration),
            wait: positive_seconds("--wait", self.wait)?,
            scenario: self.scenario,
            plan: self.plan,
            json: self.json.json,
        })
    }
}
