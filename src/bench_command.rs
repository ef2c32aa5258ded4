//! `vic bench loop` and `vic bench ipc`: check what the user asked for, run the benchmark, print
//! its report (JSON or a table). The measuring is [`crate::bench`]'s.

use crate::bench::{cyclictest, ipc, loop_bench};
use crate::cli::{Classify, input_error, print_report, sibling_binary};
use anyhow::anyhow;
use std::path::PathBuf;

/// Progress lines on stderr, unless the output is JSON.
fn progress(json: bool) -> impl FnMut(&str) {
    move |m: &str| {
        if !json {
            eprintln!("running: {m}");
        }
    }
}

/// The board's loop against cyclictest; `require_baseline` fails when cyclictest is missing.
pub fn run_loop(
    opts: &loop_bench::Options,
    require_baseline: bool,
    json: bool,
) -> anyhow::Result<()> {
    if !opts.config.is_file() {
        return Err(input_error(format!(
            "{}: no such scenario file",
            opts.config.display()
        )));
    }
    if require_baseline && cyclictest::find().is_none() {
        return Err(anyhow!(
            "cyclictest not found: {}",
            cyclictest::INSTALL_HINT
        ));
    }
    let names: Vec<&str> = loop_bench::variants().iter().map(|v| v.name).collect();
    if let Some(bad) = opts.variants.iter().find(|v| !names.contains(&v.as_str())) {
        return Err(input_error(format!(
            "--variant {bad}: choose from {}",
            names.join(", ")
        )));
    }
    let report = loop_bench::run(opts, progress(json)).runtime()?;
    print_report(&report, json, loop_bench::print)
}

/// The running pair of `vic bench ipc` as the user gave it (the binaries are found here).
#[derive(Debug, Clone)]
pub struct PairRequest {
    pub config: PathBuf,
    pub overrides: Vec<String>,
    pub plan: PathBuf,
    /// Trials of the pair (0 skips it).
    pub trials: u64,
}

/// The transport against a bare iceoryx2 ping-pong, then the running pair.
pub fn run_ipc(iterations: u64, pair: PairRequest, json: bool) -> anyhow::Result<()> {
    let pair = if pair.trials == 0 {
        None
    } else {
        if !pair.plan.is_file() {
            return Err(input_error(format!(
                "--plan {}: no such file (make one with `vic plan --method sooc --out FILE`, \
                 or skip the running pair with --pair-trials 0)",
                pair.plan.display()
            )));
        }
        Some(ipc::PairOptions {
            board_bin: sibling_binary("vic-board")?,
            planner_bin: sibling_binary("vic-planner")?,
            config: pair.config,
            overrides: pair.overrides,
            plan: pair.plan,
            trials: pair.trials,
        })
    };
    let report = ipc::run(&ipc::Options { iterations, pair }, progress(json)).runtime()?;
    print_report(&report, json, ipc::print)
}

/// Two bridges on loopback against bare Zenoh and shared memory (`vic bench bridge`).
#[cfg(feature = "zenoh")]
pub fn run_bridge(opts: &crate::bench::bridge::Options, json: bool) -> anyhow::Result<()> {
    use crate::bench::bridge;
    let report = bridge::run(opts, progress(json)).runtime()?;
    print_report(&report, json, bridge::print)
}
