//! `vic view`: a running namespace served live to Foxglove (feature `foxglove`, on by
//! default): open <https://app.foxglove.dev> or the desktop app, *Open connection* → *Foxglove
//! WebSocket* → `ws://HOST:PORT`, then *Import layout* `docs/foxglove-layout.json`: the hand
//! path against the plan, the joint angles against the plan, stiffness, and the loop's jitter.

use crate::cli::{
    Classify, DefaultScenarioArgs, JsonArg, NamespaceArgs, input_error, print_json, stop_on_signal,
};
use crate::ranges::{MAX_RUN_S, MAX_WAIT_S, real, seconds, whole};
use vic_plan::scenario::Scenario;
use vic_rt::record::{RecordError, ViewOptions, ViewSummary, serve_namespace};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object at the end")))]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Address to listen on. The stream is not authenticated: keep it on loopback, or reach it
    /// through an SSH tunnel (ssh -L 8765:localhost:8765 HOST).
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// Port to listen on (0: any free port, printed at start). [range: 0 to 65535]
    #[arg(long, default_value_t = 8765, value_parser = whole(0u16, u16::MAX))]
    port: u16,
    /// States shown per second (of the board's 1000; the other channels pass whole).
    /// [range: 1 to 1000]
    #[arg(long, default_value_t = 100, value_parser = whole(1u64, 1000))]
    rate_hz: u64,
    /// Stop this many seconds after the board's first state (0: at Ctrl-C / SIGTERM).
    /// [range: 0 to 604800]
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = real(0.0, MAX_RUN_S))]
    duration: f64,
    /// Seconds to wait for a board before giving up (exit 1). [range: 0.001 to 3600]
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = real(0.001, MAX_WAIT_S))]
    wait: f64,
    /// The scenario the board runs: its plant's kinematics give the hand path (/hand).
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    #[command(flatten)]
    json: JsonArg,
}

/// Serves the namespace until the duration ends or SIGINT / SIGTERM, then prints the summary.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let namespace = a.namespace.validated()?;
    let scenario = Scenario::load(&a.scenario.config, &a.scenario.set.overrides).input()?;
    let plant = scenario.model.plant.clone();
    let hand = move |q: &[f64]| plant.hand_position(q);
    let stop = stop_on_signal()?;
    let opts = ViewOptions {
        host: a.host.clone(),
        port: a.port,
        state_every: (1000 / a.rate_hz).max(1),
        duration_ns: seconds(a.duration).as_nanos() as u64,
        wait_for_board_ms: seconds(a.wait).as_millis() as u64,
    };
    let host = a.host.clone();
    let summary = serve_namespace(namespace, &opts, Some(&hand), &stop, |port| {
        eprintln!(
            "vic view: namespace \"{namespace}\" on ws://{host}:{port} (Foxglove: Open connection \
             → Foxglove WebSocket; layout: docs/foxglove-layout.json)"
        );
    })
    .map_err(classify)?;
    if a.json.json {
        print_json(&summary)
    } else {
        print_summary(&summary);
        Ok(())
    }
}

/// A port that cannot be listened on is the user's choice (exit 2); a missing board the run's.
fn classify(e: RecordError) -> anyhow::Error {
    match e {
        RecordError::View { .. } => input_error(e),
        e => anyhow::anyhow!("{e}"),
    }
}

fn print_summary(s: &ViewSummary) {
    println!(
        "served namespace \"{}\" on port {} for {:.1} s: {} states ({} shown), {} lost in {} gap(s)",
        s.namespace, s.port, s.seconds, s.states, s.states_shown, s.states_lost, s.gaps
    );
    for t in &s.topics {
        println!("  {:<14} {} messages", t.topic, t.messages);
    }
}
