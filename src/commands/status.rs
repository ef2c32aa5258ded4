//! `vic status`: one snapshot of a running board's telemetry, as text or JSON.

use crate::cli::{JsonArg, NamespaceArgs, print_json};
use crate::ranges::{MAX_WAIT_S, real, seconds};
use crate::views::operator::status;

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object")))]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Seconds to wait for the board's telemetry (it publishes at 10 Hz). [range: 0.001 to 3600]
    #[arg(long, default_value_t = 1.0, value_parser = real(0.001, MAX_WAIT_S))]
    timeout_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

/// Prints one snapshot of the telemetry of the board in `--namespace`.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let namespace = a.namespace.validated()?;
    let timeout = seconds(a.timeout_s);
    let s = status(namespace, timeout)?;
    if a.json.json {
        print_json(&s)
    } else {
        println!("{}", s.render());
        Ok(())
    }
}
