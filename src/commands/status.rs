//! `vic status`: one snapshot of a running board's telemetry, as text or JSON.

use crate::cli::{JsonArg, NamespaceArgs, positive_seconds, print_json};
use crate::views::operator::status;

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object")))]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds to wait for the board's telemetry (it publishes at 10 Hz).
    #[arg(long, default_value_t = 1.0)]
    timeout_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

/// Prints one snapshot of the telemetry of the board in `--namespace`.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let namespace = a.namespace.validated()?;
    let timeout = positive_seconds("--timeout-s", a.timeout_s)?;
    let s = status(namespace, timeout)?;
    if a.json.json {
        print_json(&s)
    } else {
        println!("{}", s.render());
        Ok(())
    }
}
