//! The `vic` command line: [`Cli`] (what `bins/vic.rs` parses) and one module per
//! subcommand, each with its flags (a clap `Args`) and its `run`, from the flags as typed to the
//! printed report. A module checks what clap cannot (ranges of seconds, namespaces, latencies on
//! the plan's grid) and calls the studies, daemons and views for the work; errors carry the exit
//! code of [`crate::cli`]'s convention (2: the user's input, 1: a failure).

mod bench;
#[cfg(feature = "zenoh")]
mod bridge;
mod convert;
mod demo;
mod experiment;
mod identify;
mod inject;
mod monitor;
mod plan;
pub mod record;
mod results;
mod simulate;
mod status;
mod sweep;
#[cfg(feature = "foxglove")]
mod view;

use clap::{Parser, Subcommand};

/// Plan and run variable-impedance control under noise, unstable force fields and feedback
/// delays.
///
/// Scenarios are TOML files (see config/); every command that reads one takes
/// `--set section.key=value` to override any key, e.g. `--set noise.sigma=0.1`.
#[derive(Parser)]
#[command(name = "vic", version, about, long_about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Plan a movement: solve the scenario's stochastic optimal control problem and print (or
    /// write) the plan.
    ///
    /// Example: vic plan --config config/icub_elbow.toml --out plan.json
    Plan(plan::Args),
    /// Monte Carlo of a plan on the stochastic plant: spread, 95 % ellipse, tracking error,
    /// divergence and the expected cost, next to the plan's prediction.
    ///
    /// Example: vic simulate --config config/two_link_divergent.toml --plan plan.json --policy open-loop
    Simulate(simulate::Args),
    /// Reproduce a figure of the paper: plan and simulate every column, write the plots (PNG and
    /// SVG) and a JSON of the numbers into --out-dir, print a table.
    ///
    /// Example: vic experiment fig1 --trials 20 --out-dir results
    Experiment(experiment::Args),
    /// Regenerate docs/RESULTS.md: run fig1, fig2 and icub, write their figures and numbers into
    /// --out-dir/figures and the document that sets the paper's claims beside our numbers.
    ///
    /// Example: vic results --out-dir docs
    Results(results::Args),
    /// Delay versus stiffness as a curve: for each feedback latency and strategy (naive-delayed,
    /// predictor, stiffness, stiffness+predictor, replan), plan, run the trials (Monte Carlo by
    /// default, --lockstep or --live on the daemons) and report the final error, divergence and
    /// cost; --pulse adds a torque pulse no controller knows of; --out-dir receives the figure.
    ///
    /// Example: vic sweep latency --config config/single_joint_delay.toml --out-dir sweep
    Sweep(sweep::Args),
    /// Run the real-time pair: start a board and a planner in a fresh namespace, run the five
    /// strategies of a central controller (naive-delayed, predictor, stiffness,
    /// stiffness+predictor, replan) at --latency-ms with the same noise seeds, and naive-delayed
    /// at 0 ms as the reference (the planner at 250 Hz); print the comparison, the board's timing
    /// and the central loop's compute time, write the trajectories figure, and shut everything
    /// down.
    ///
    /// Example: vic demo --latency-ms 200 --trials 3
    Demo(demo::Args),
    /// Send a disturbance to a running board and report the tick that applied it (read from its
    /// state stream), or fail (exit 1) when no board answers or it rejects the disturbance.
    ///
    /// Examples: vic inject pulse --torque 2,0 --duration-ms 50;  vic inject field --beta 0;
    /// vic inject load --torque 0,0.5;  vic inject noise --factor 2
    Inject(inject::Args),
    /// One snapshot of a running board's telemetry: mode (running / safe-hold / fault), tick
    /// rate, jitter, work time, command age, tracking error, stiffness, disturbances, rejected
    /// messages by reason.
    ///
    /// Example: vic status --namespace lab1 --json
    Status(status::Args),
    /// Watch a running board live: on a terminal a live view (the board's mode, rolling plots of
    /// the joint angles, tracking error, stiffness and torque, the loop's jitter and late ticks,
    /// command age, rejections by reason, the disturbances in force); piped, with --plain or with
    /// --count, one line per interval.
    ///
    /// Keys: p / P push the chosen joint one way or the other (1, 2 choose the joint), f switches
    /// the field on and off, r clears the plots and the disturbances, q / Esc / Ctrl-C quit.
    ///
    /// Example: vic monitor --namespace lab1
    Monitor(monitor::Args),
    /// One end of a namespace split across two hosts over Zenoh: beside the board
    /// (`--side board`) or beside the central process (`--side central`). Messages cross as
    /// their wire bytes with the sender's session, sequence number and time stamp.
    ///
    /// The link is mutual TLS with the pair's keys (`vic bridge keygen --out DIR`).
    ///
    /// Example: vic bridge --side board --namespace lab1 --listen tls/0.0.0.0:7447 --keys DIR
    #[cfg(feature = "zenoh")]
    Bridge(bridge::Args),
    /// Record a running namespace to MCAP from outside the board: states (1 kHz), command
    /// slices, control requests, disturbances and telemetry, each on its own JSON-schema channel
    /// (Foxglove and PlotJuggler open it as it is). States it missed are counted and marked.
    ///
    /// Example: vic record --namespace lab1 --out run.mcap --duration 60
    Record(record::Args),
    /// Serve a running namespace live to Foxglove over its WebSocket protocol: the recording's
    /// channels (the same topics and schemas as vic record's MCAP files), the plan the board
    /// executes (/reference) and the hand path (/hand). Open ws://127.0.0.1:8765 in Foxglove
    /// and import docs/foxglove-layout.json.
    ///
    /// Example: vic view --namespace lab1
    #[cfg(feature = "foxglove")]
    View(view::Args),
    /// Convert a board's MCAP recording (vic-board --record run.mcap) to the CSV log that
    /// vic identify reads (gaps marked as in the board's own CSV).
    ///
    /// Example: vic convert run.mcap --csv run.csv
    Convert(convert::Args),
    /// Identify the joint's torque noise from a log, the paper's procedure (Sec. III-B): bin the
    /// torque error by velocity, fit its mean and standard deviation with polynomials, estimate
    /// (a, b) of e = (a + b q') η by maximum likelihood and test the residual η for normality
    /// (Jarque–Bera).
    ///
    /// The log is CSV with the columns t,q,qd,qdd,tau_ff,stiffness,damping,q_d,qd_d (any order;
    /// extra columns must start with x_). The joint's parameters come from --config (a single-joint
    /// scenario), else the iCub forearm's.
    ///
    /// Example: vic identify --log elbow.csv --config config/icub_experiment.toml
    Identify(identify::Args),
    /// Benchmark against the machine's own limits: the board's 1 kHz loop against cyclictest,
    /// the transport against a bare iceoryx2 ping-pong (same run, both distributions, ratios).
    ///
    /// Example: vic bench loop --seconds 30 --json
    Bench(bench::Args),
}

impl Cli {
    /// Runs the subcommand.
    pub fn run(self) -> anyhow::Result<()> {
        match self.command {
            Command::Plan(a) => plan::run(a),
            Command::Simulate(a) => simulate::run(a),
            Command::Experiment(a) => experiment::run(a),
            Command::Results(a) => results::run(a),
            Command::Demo(a) => demo::run(a),
            Command::Inject(a) => inject::run(a),
            Command::Status(a) => status::run(a),
            Command::Monitor(a) => monitor::run(a),
            #[cfg(feature = "zenoh")]
            Command::Bridge(a) => bridge::run(a),
            Command::Identify(a) => identify::run(a),
            Command::Record(a) => record::run(a),
            #[cfg(feature = "foxglove")]
            Command::View(a) => view::run(a),
            Command::Convert(a) => convert::run(a),
            Command::Bench(a) => bench::run(a),
            Command::Sweep(a) => sweep::run(a),
        }
    }
}

#[cfg(test)]
mod tests {
    /// clap's own consistency checks (every `mut_arg` names an argument that exists, no two
    /// flags clash), which it otherwise runs only when a command is parsed.
    #[test]
    fn flags_are_consistent() {
        use clap::CommandFactory;
        super::Cli::command().debug_assert();
    }
}
