//! `vic bench loop`, `vic bench ipc` and `vic bench bridge`: check what the user asked for, run
//! the benchmark, print its report (JSON or a table). The measuring is [`crate::bench`]'s.

use crate::bench::{cyclictest, ipc, loop_bench, sooc_scaling};
use crate::cli::{
    Classify, DefaultScenarioArgs, JsonArg, input_error, print_report, sibling_binary,
};
use crate::ranges::whole;
use anyhow::anyhow;
use clap::Subcommand;
use std::path::PathBuf;

#[derive(clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    which: BenchCommand,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// The board's periodic loop at 1 kHz with its real work (the scenario's plant, a 50 Hz
    /// planner thread streaming hold commands over the transport), under each option real-time
    /// loops use: default vs 1 ns timer slack, a 100 µs spin before the deadline, mlockall, CPU
    /// pinning, SCHED_FIFO 80 (when permitted). Then cyclictest -i1000 for the same duration
    /// (default scheduler, and -p80 when a FIFO variant ran). Runs are sequential; the whole
    /// bench takes about (variants + 2) × --seconds.
    ///
    /// Reports wake-up lateness (p50/p99/p99.9/max), tick work and CPU use per variant, and the
    /// ratio to cyclictest's p99. Without cyclictest (`apt-get install rt-tests`) it runs vic
    /// only and the JSON's "baseline" is null.
    ///
    /// Example: vic bench loop --seconds 30 --json
    Loop(BenchLoopArgs),
    /// One-way and round-trip latency of the state and command channels (vic's typed ports, real
    /// message types) against a bare iceoryx2 publish/subscribe ping-pong with the same payload
    /// sizes, both as two busy-polling threads; then the running vic-board + vic-planner pair:
    /// state age at a reader, command age at the board, pulse-injection-to-effect.
    ///
    /// Example: vic bench ipc --iterations 100000 --json
    Ipc(BenchIpcArgs),
    /// One-way latency of a command and a state through two `vic bridge`s on loopback (Zenoh
    /// TCP), beside the same ping-pong over shared memory and over bare Zenoh with the same
    /// payload, all in the same run; the ratio to bare Zenoh.
    ///
    /// Example: vic bench bridge --iterations 20000 --json
    #[cfg(feature = "zenoh")]
    Bridge(BenchBridgeArgs),
    /// How the exact SOOC iteration's cost grows with the state: per knot, the plant's
    /// linearisation (what an ILQG iteration differentiates), the moment step's first
    /// derivatives (every SOOC iteration) and the exact Newton model (with the flow's third
    /// derivatives), timed along each scenario's first guess; then each scenario's cold plan as
    /// `vic plan --method sooc` solves it. Prints the log–log slope of each time against the
    /// moment dimension n + n(n+1)/2 (least squares over the scenarios).
    ///
    /// Example: vic bench sooc --json
    Sooc(BenchSoocArgs),
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help(
    "Print one JSON object: {points: [{scenario, n, m, moment_dim, horizon, nominal_us, first_us, \
     newton_us, newton_over_nominal, solve: {iterations, ms, ms_per_iteration, converged} or null}], \
     slopes: {nominal, first, newton, ms_per_iteration}, passes}"
)))]
struct BenchSoocArgs {
    /// Scenario files, one point of the curve each (repeatable or comma-separated; at least two
    /// with different state dimensions give a slope). Default: the single joint, the two-link
    /// arm and the VSA arm in the divergent field.
    #[arg(long = "config", short, value_name = "FILE", value_delimiter = ',')]
    configs: Vec<PathBuf>,
    /// Timed passes over the horizon per model; the median pass is reported.
    /// [range: 1 to 10000]
    #[arg(long, default_value_t = 20, value_parser = whole(1u64, 10_000))]
    passes: u64,
    /// Skip the cold solves (the VSA arm's takes seconds).
    #[arg(long)]
    no_solve: bool,
    #[command(flatten)]
    json: JsonArg,
}

#[cfg(feature = "zenoh")]
#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help(
    "Print one JSON object: {shared_memory, zenoh, through_bridge: {p50_us, p99_us, max_us, n}, \
     bridge: {p50_us, p99_us, zenoh_p50_us, zenoh_p99_us, ratio_p50, ratio_p99}}"
)))]
struct BenchBridgeArgs {
    /// Round trips per channel (after 10 % more for warm-up). [range: 10 to 10000000]
    #[arg(long, default_value_t = 20_000, value_parser = whole(10u64, 10_000_000))]
    iterations: u64,
    /// Loopback TCP port of the link (the bare Zenoh pair uses the next one).
    /// [range: 1024 to 65534]
    #[arg(long, default_value_t = 17447, value_parser = whole(1024u16, 65_534))]
    port: u16,
    /// The ping–pong's two ends spin on their subscribers (by default they sleep until the
    /// other end's publisher notifies, as the bare Zenoh pair sleeps in its receiver).
    #[arg(long)]
    spin: bool,
    /// Also time each hop through the bridges (the sending bridge's wake-up, its put, the
    /// receiving callback, the local publish), from each one-way's start; adds `hops` to the JSON.
    #[arg(long)]
    trace: bool,
    #[command(flatten)]
    json: JsonArg,
}

#[derive(clap::Args)]
#[command(
    mut_arg("config", |a| a.help("Scenario whose plant the board integrates (impedance actuator)")),
    mut_arg("json", |a| a.help(
        "Print one JSON object: {\"vic\": {p50_us, p99_us, p999_us, max_us, cpu_percent, …}, \
         \"baseline\": {…} or null, \"ratio_p99\": …, \"variants\": […], …}"
    )),
)]
struct BenchLoopArgs {
    /// Seconds per variant and per cyclictest run. [range: 1 to 3600]
    #[arg(long, default_value_t = 30, value_parser = whole(1u64, 3600))]
    seconds: u64,
    /// Run only these variants (repeatable or comma-separated): sleep-slack50, sleep, spin,
    /// spin-mlock, spin-mlock-pin, fifo, fifo-spin.
    #[arg(long = "variant", value_name = "NAME", value_delimiter = ',')]
    variants: Vec<String>,
    /// Skip cyclictest (the JSON's "baseline" is null).
    #[arg(long)]
    no_baseline: bool,
    /// Fail (exit 1) when cyclictest is not installed, instead of running vic only.
    #[arg(long, conflicts_with = "no_baseline")]
    require_baseline: bool,
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    #[command(flatten)]
    json: JsonArg,
}

#[derive(clap::Args)]
#[command(
    mut_arg("config", |a| a.help("Scenario of the pair")),
    mut_arg("overrides", |a| a
        .help("Overrides for the pair's board and planner")
        .default_value("noise.sigma=0.02")),
    mut_arg("json", |a| a.help(
        "Print one JSON object: {\"vic\": {p50_us, p99_us, …}, \"baseline\": {…}, \"ratio_p50\": …, \
         \"pair\": {…}, …} (one-way latency of the state channel in the summary)"
    )),
)]
struct BenchIpcArgs {
    /// Ping-pongs per transport (after 1000 not recorded). [range: 1 to 100000000]
    #[arg(long, default_value_t = 100_000, value_parser = whole(1u64, 100_000_000))]
    iterations: u64,
    /// Trials of the running pair (about 1.5 s each; 0 skips the pair). [range: 0 to 1000]
    #[arg(long, default_value_t = 5, value_parser = whole(0u64, 1000))]
    pair_trials: u64,
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    /// SOOC plan the pair's planner plays (stiffness strategy).
    #[arg(
        long,
        value_name = "FILE",
        default_value = "tests/data/realtime/two_link_divergent_sigma002_sooc.json"
    )]
    plan: PathBuf,
    #[command(flatten)]
    json: JsonArg,
}

/// Runs the benchmark asked for.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    match args.which {
        BenchCommand::Loop(a) => {
            let opts = loop_bench::Options {
                seconds: a.seconds,
                config: a.scenario.config,
                overrides: a.scenario.set.overrides,
                variants: a.variants,
                baseline: !a.no_baseline,
            };
            run_loop(&opts, a.require_baseline, a.json.json)
        }
        BenchCommand::Ipc(a) => {
            let pair = PairRequest {
                config: a.scenario.config,
                overrides: a.scenario.set.overrides,
                plan: a.plan,
                trials: a.pair_trials,
            };
            run_ipc(a.iterations, pair, a.json.json)
        }
        #[cfg(feature = "zenoh")]
        BenchCommand::Bridge(a) => run_bridge(
            &crate::bench::bridge::Options {
                iterations: a.iterations,
                port: a.port,
                spin: a.spin,
                trace: a.trace,
            },
            a.json.json,
        ),
        BenchCommand::Sooc(a) => run_sooc(a),
    }
}

/// The SOOC iteration's cost against the moment dimension (`vic bench sooc`).
fn run_sooc(a: BenchSoocArgs) -> anyhow::Result<()> {
    let configs = if a.configs.is_empty() {
        sooc_scaling::DEFAULT_CONFIGS
            .iter()
            .map(PathBuf::from)
            .collect()
    } else {
        a.configs
    };
    for c in &configs {
        vic_plan::scenario::Scenario::load(c, &[]).input()?;
    }
    let opts = sooc_scaling::Options {
        configs,
        passes: a.passes as usize,
        solve: !a.no_solve,
    };
    let report = sooc_scaling::run(&opts, progress(a.json.json)).runtime()?;
    print_report(&report, a.json.json, sooc_scaling::print)
}

/// Progress lines on stderr, unless the output is JSON.
fn progress(json: bool) -> impl FnMut(&str) {
    move |m: &str| {
        if !json {
            eprintln!("running: {m}");
        }
    }
}

/// The board's loop against cyclictest; `require_baseline` fails when cyclictest is missing.
fn run_loop(opts: &loop_bench::Options, require_baseline: bool, json: bool) -> anyhow::Result<()> {
    if !vic_plan::scenario::exists(&opts.config) {
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
struct PairRequest {
    config: PathBuf,
    overrides: Vec<String>,
    plan: PathBuf,
    /// Trials of the pair (0 skips it).
    trials: u64,
}

/// The transport against a bare iceoryx2 ping-pong, then the running pair.
fn run_ipc(iterations: u64, pair: PairRequest, json: bool) -> anyhow::Result<()> {
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
fn run_bridge(opts: &crate::bench::bridge::Options, json: bool) -> anyhow::Result<()> {
    use crate::bench::bridge;
    let report = bridge::run(opts, progress(json)).runtime()?;
    print_report(&report, json, bridge::print)
}
