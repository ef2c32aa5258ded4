//! `vic monitor`: flags, then [`vic::tools::operator_command::run_monitor`].

use vic::tools::cli::NamespaceArgs;

#[derive(clap::Args)]
pub struct MonitorArgs {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds between snapshots (at least 0.1).
    #[arg(long, default_value_t = 1.0)]
    interval_s: f64,
    /// Stop after this many snapshots (default: until Ctrl-C).
    #[arg(long)]
    count: Option<u64>,
}

impl MonitorArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?;
        vic::tools::operator_command::run_monitor(namespace, self.interval_s, self.count)
    }
}
