//! `vic bridge`: flags, then [`vic::tools::bridge_command::run`].

use std::time::Duration;
use vic::rt::bridge::{BridgeOptions, Link, Side};
use vic::tools::cli::{JsonArg, NamespaceArgs, non_negative_seconds};

#[derive(Clone, Copy, clap::ValueEnum)]
enum SideArg {
    /// Beside the board: forwards its state, telemetry and events to the link, and the
    /// commands, resets and disturbances from the link to the board.
    Board,
    /// Beside the central process: plays the board to it (state from the link, its commands to
    /// the link).
    Central,
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the final counts as one JSON object")))]
#[command(group(clap::ArgGroup::new("endpoint").required(true).args(["listen", "connect"])))]
pub struct BridgeArgs {
    /// Which daemon this bridge stands beside.
    #[arg(long, value_enum)]
    side: SideArg,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Wait for the other bridge on this Zenoh endpoint, e.g. tcp/0.0.0.0:7447.
    #[arg(long, value_name = "ENDPOINT")]
    listen: Option<String>,
    /// Connect to the other bridge, e.g. tcp/robot.local:7447 (retried until it answers).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Option<String>,
    /// The name both bridges share (key expressions vic/NAME/...); default: the namespace.
    #[arg(long)]
    link_name: Option<String>,
    /// Messages are forwarded as they are published (the local daemons notify the bridge) and as
    /// they arrive from the link; this is only the longest the bridge waits before looking at the
    /// local subscribers without a notification [ms] (1 to 60000).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=60_000))]
    safety_interval_ms: u64,
    /// Re-stamp the messages forwarded to the board with this host's clock: needed across hosts
    /// whose monotonic clocks differ (the age check then covers bridge → board only).
    #[arg(long)]
    restamp: bool,
    /// Stop after this many seconds (0: run until SIGINT/SIGTERM).
    #[arg(long, default_value_t = 0.0)]
    duration_s: f64,
    #[command(flatten)]
    json: JsonArg,
}

impl BridgeArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let namespace = self.namespace.validated()?.to_string();
        let duration = non_negative_seconds("--duration-s", self.duration_s)?;
        let link = match (self.listen, self.connect) {
            (Some(e), None) => Link::Listen(e),
            (None, Some(e)) => Link::Connect(e),
            _ => unreachable!("clap requires exactly one of --listen and --connect"),
        };
        let options = BridgeOptions {
            link_name: self.link_name.unwrap_or_else(|| namespace.clone()),
            namespace,
            side: match self.side {
                SideArg::Board => Side::Board,
                SideArg::Central => Side::Central,
            },
            link,
            safety_interval: Duration::from_millis(self.safety_interval_ms),
            restamp: self.restamp,
        };
        vic::tools::bridge_command::run(&options, duration, self.json.json)
    }
}
