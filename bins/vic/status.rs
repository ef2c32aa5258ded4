//! `vic status`: flags, then [`vic::operator_command::run_status`].

use vic::cli::{JsonArg, NamespaceArgs, positive_seconds};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object")))]
pub struct StatusArgs {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds to wait for the board's telemetry (it publishes at 10 Hz).
    #[arg(long, default_value_t = 1.0)]
    timeout_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

impl StatusArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?;
        let timeout = positive_seconds("--timeout-s", self.timeout_s)?;
        vic::operator_command::run_status(namespace, timeout, self.json.json)
    }
}
