//! `vic monitor`: flags, then [`vic::operator_command::run_monitor`].

use vic::cli::NamespaceArgs;
use vic::operator_command::MonitorOptions;

#[derive(clap::Args)]
pub struct MonitorArgs {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds between lines when piped or --plain (at least 0.1).
    #[arg(long, default_value_t = 1.0)]
    interval_s: f64,
    /// Stop after this many lines (implies --plain; default: until Ctrl-C).
    #[arg(long)]
    count: Option<u64>,
    /// One line per interval even on a terminal (as when piped).
    #[arg(long)]
    plain: bool,
    /// Torque of the pulse the p / P keys inject [N m].
    #[arg(long, default_value_t = 2.0)]
    pulse_nm: f64,
    /// Duration of that pulse [ms].
    #[arg(long, default_value_t = 100.0)]
    pulse_ms: f64,
    /// β of the divergent field the f key switches on [N/m] (two-link arm only).
    #[arg(long, default_value_t = 50.0, allow_negative_numbers = true)]
    field_beta: f64,
    /// Seconds of history in the plots.
    #[arg(long, default_value_t = 10.0)]
    window_s: f64,
}

impl MonitorArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?;
        vic::operator_command::run_monitor(
            namespace,
            MonitorOptions {
                interval_s: self.interval_s,
                count: self.count,
                plain: self.plain,
                pulse_nm: self.pulse_nm,
                pulse_ms: self.pulse_ms,
                field_beta: self.field_beta,
                window_s: self.window_s,
            },
        )
    }
}
