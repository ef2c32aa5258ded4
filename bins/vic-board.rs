//! `vic-board`: the simulated robot board. A 1 kHz absolute-deadline loop that integrates the
//! scenario's plant under the impedance law (Eq. 4), follows the command slices of `vic-planner`,
//! applies injected disturbances, and publishes its state every tick and telemetry at 10 Hz.
//! SIGINT/SIGTERM stop it at the end of the current tick; it prints its statistics and exits 0.
//! The flags are parsed here; [`vic::tools::board_daemon::run`] does the rest.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use vic::tools::board_daemon::{BoardOptions, run};
use vic::tools::cli::{DefaultScenarioArgs, JsonArg, NamespaceArgs, finish};

/// The simulated board: plant, impedance law and disturbances at 1 kHz.
///
/// Example: vic-board --config config/two_link_divergent.toml --namespace lab1
#[derive(Parser)]
#[command(name = "vic-board", version, about, long_about)]
#[command(
    mut_arg("config", |a| a.help("Scenario file (TOML): plant, actuator (type 2), field and noise")),
    mut_arg("json", |a| a.help("Print the final statistics as one JSON object")),
)]
struct Args {
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// Tick rate [Hz].
    #[arg(long, default_value_t = 1000)]
    rate_hz: u64,
    /// Spin this long before each deadline [µs] (0: sleep only). Default 100 (10 % of a CPU,
    /// never enough to trip the kernel's real-time throttling), 0 with --no-rt.
    #[arg(long, value_name = "US")]
    spin_us: Option<u64>,
    /// Stiffness of the safe hold [N m/rad] (default: the scenario's board.hold_stiffness, 100).
    /// The other limits (watchdog, ramp, joint and speed limits, disturbance limits) are keys
    /// of the scenario's [board] section: --set board.watchdog=0.1
    #[arg(long, value_name = "N_M_PER_RAD")]
    hold_stiffness: Option<f64>,
    /// SCHED_FIFO priority of the loop (1–99). Real-time is the default: the board asks for
    /// SCHED_FIFO, mlockall, a CPU of its own (the last one, where there are several) and a
    /// spin before each deadline, prints what it got and runs on with a warning when refused.
    #[arg(long, value_name = "PRIO", default_value_t = vic::rt::sched::DEFAULT_FIFO_PRIORITY,
          value_parser = clap::value_parser!(i32).range(1..=99))]
    fifo: i32,
    /// Pin the loop to this CPU (default: the last CPU, where there are several).
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// The old behaviour: the normal scheduler, no pinning, no spin (memory locking is still
    /// tried).
    #[arg(long)]
    no_rt: bool,
    /// Stop after this many seconds (0: run until SIGINT/SIGTERM).
    #[arg(long, default_value_t = 0.0)]
    duration_s: f64,
    #[command(flatten)]
    json: JsonArg,
    /// Record every tick (state, command in use, disturbances) from a thread outside the loop:
    /// FILE.csv is the log `vic identify --log` reads, FILE.mcap opens in Foxglove and
    /// PlotJuggler (and `vic convert` turns it into the CSV). Gaps (queue full) are marked in
    /// the file and counted in the statistics.
    #[arg(long, value_name = "FILE.csv|FILE.mcap")]
    record: Option<PathBuf>,
    /// Capacity of the recording queue [ticks].
    #[arg(long, value_name = "TICKS", default_value_t = vic::rt::record::DEFAULT_CAPACITY)]
    record_queue: usize,
}

fn main() -> ExitCode {
    let a = Args::parse();
    let options = BoardOptions {
        config: a.scenario.config,
        overrides: a.scenario.set.overrides,
        namespace: a.namespace.namespace,
        rate_hz: a.rate_hz,
        spin_us: a.spin_us.unwrap_or(if a.no_rt {
            0
        } else {
            vic::rt::sched::DEFAULT_SPIN_US
        }),
        hold_stiffness: a.hold_stiffness,
        fifo: Some(a.fifo),
        cpu: a.cpu,
        no_rt: a.no_rt,
        duration_s: a.duration_s,
        json: a.json.json,
        record: a.record,
        record_queue: a.record_queue,
    };
    finish("vic-board", run(&options))
}

#[cfg(test)]
mod tests {
    /// clap's own consistency checks (every `mut_arg` names an argument that exists, no two
    /// flags clash), which it otherwise runs only when a command is parsed.
    #[test]
    fn flags_are_consistent() {
        use clap::CommandFactory;
        super::Args::command().debug_assert();
    }
}
