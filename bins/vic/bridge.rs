//! `vic bridge`: flags, then [`vic::bridge_command::run`].

use std::time::Duration;
use vic::cli::{JsonArg, NamespaceArgs, input_error, non_negative_seconds};
use vic_rt::bridge::{BridgeOptions, Link, Side, Stamps};

#[derive(Clone, Copy, clap::ValueEnum)]
enum SideArg {
    /// Beside the board: forwards its state, telemetry and events to the link, and the
    /// commands, resets and disturbances from the link to the board.
    Board,
    /// Beside the central process: plays the board to it (state from the link, its commands to
    /// the link).
    Central,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum StampsArg {
    /// Translate the stamps into this host's clock (measured over the link): two machines.
    Translate,
    /// Forward them unchanged: one machine.
    Keep,
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
    /// Board side: what to do with the time stamps of the messages forwarded to the board.
    /// `translate` measures the offset to the central host's clock (probes over the link, a few
    /// per second) and moves every stamp into this host's clock, so that the board's age check
    /// covers the link; nothing is forwarded until the first probe came back. `keep` forwards the
    /// senders' stamps: only when both daemons share one machine's clock.
    #[arg(long, value_enum, default_value = "translate")]
    stamps: StampsArg,
    /// Central side, tests only: pretend this host's clock is ahead by MS milliseconds.
    #[arg(long, hide = true, default_value_t = 0, allow_negative_numbers = true)]
    clock_skew_ms: i64,
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
        if self.clock_skew_ms != 0 && !matches!(self.side, SideArg::Central) {
            return Err(input_error("--clock-skew-ms: only with --side central"));
        }
        let clock_skew_ns = self
            .clock_skew_ms
            .checked_mul(1_000_000)
            .ok_or_else(|| input_error("--clock-skew-ms: too large"))?;
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
            stamps: match self.stamps {
                StampsArg::Translate => Stamps::Translate,
                StampsArg::Keep => Stamps::Keep,
            },
            clock_skew_ns,
        };
        vic::bridge_command::run(&options, duration, self.json.json)
    }
}
