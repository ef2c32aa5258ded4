//! What the three binaries (`vic`, `vic-board`, `vic-planner`) share: one error convention and the
//! argument groups that every one of them takes.
//!
//! Errors: the command-line front ends return `anyhow::Result`; an error the user can fix (a file
//! that cannot be read, a configuration key with a bad value, a flag out of range) is tagged with
//! [`InputError`] (by [`Classify::input`] or [`input_error`]) and ends the process with exit code 2,
//! anything else (a board that does not answer, a write that fails) with 1. [`finish`] prints the
//! message as `PROGRAM: error: MESSAGE` and returns the exit code.

use anyhow::anyhow;
use std::fmt::Display;
use std::path::PathBuf;
use std::process::ExitCode;
use vic_plan::strategy::Latency;
use vic_rt::transport::DEFAULT_NAMESPACE;

/// Marks an error as the user's: a file, a key or a flag that is wrong. Its message says which and
/// why; [`exit_code`] turns it into exit code 2.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub(crate) struct InputError(#[from] anyhow::Error);

/// An [`InputError`] with this message.
pub(crate) fn input_error(message: impl Display) -> anyhow::Error {
    InputError(anyhow!("{message}")).into()
}

/// Classifies the error of a `Result` whose error only needs to be shown: the user's
/// ([`Classify::input`], exit 2) or the run's ([`Classify::runtime`], exit 1).
pub(crate) trait Classify<T> {
    /// The error is the user's input (exit 2).
    fn input(self) -> anyhow::Result<T>;
    /// The error is a failure of the run (exit 1).
    fn runtime(self) -> anyhow::Result<T>;
}

impl<T, E: Display> Classify<T> for Result<T, E> {
    fn input(self) -> anyhow::Result<T> {
        self.map_err(input_error)
    }
    fn runtime(self) -> anyhow::Result<T> {
        self.map_err(|e| anyhow!("{e}"))
    }
}

/// 2 when the error (or anything it wraps) is an [`InputError`], else 1.
pub(crate) fn exit_code(error: &anyhow::Error) -> u8 {
    if error.chain().any(|e| e.is::<InputError>()) {
        2
    } else {
        1
    }
}

/// The error's message and the messages of its causes, joined by ": ", each cause left out when
/// the text before already ends with it (errors that print their source themselves).
pub(crate) fn message(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let part = cause.to_string();
        if text.is_empty() {
            text = part;
        } else if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
    }
    text
}

/// Ends a binary: exit 0 on success, else `PROGRAM: error: MESSAGE` on stderr and exit 2 (the
/// user's input) or 1 (a failure).
pub fn finish(program: &str, result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{program}: error: {}", message(&e));
            ExitCode::from(exit_code(&e))
        }
    }
}

/// Parses the command line of `program`. Help and version print and end with exit code 0; a
/// command line clap refuses (an unknown flag, a missing one, a value outside its range) prints
/// `PROGRAM: error: …` with clap's message and ends with exit code 2, as [`finish`] does.
pub fn parse<T: clap::Parser>(program: &str) -> Result<T, ExitCode> {
    T::try_parse().map_err(|e| {
        let text = e.render().to_string();
        if e.use_stderr() && text.starts_with("error: ") {
            eprint!("{program}: {text}");
        } else {
            let _ = e.print();
        }
        ExitCode::from(e.exit_code().clamp(0, 255) as u8)
    })
}

/// `--namespace`: which board the command talks to.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct NamespaceArgs {
    /// Namespace of the services (instances in different namespaces never see each other).
    #[arg(long, default_value = DEFAULT_NAMESPACE)]
    pub(crate) namespace: String,
}

impl NamespaceArgs {
    /// The namespace, checked (it names files in /dev/shm).
    pub(crate) fn validated(&self) -> anyhow::Result<&str> {
        vic_rt::transport::validate_namespace(&self.namespace).input()?;
        Ok(&self.namespace)
    }
}

/// `--set SECTION.KEY=VALUE`, repeatable: overrides of the scenario's keys.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct OverrideArgs {
    /// Override a configuration key (repeatable): --set noise.sigma=0.02
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    pub(crate) overrides: Vec<String>,
}

/// `--config FILE` (required) and its `--set` overrides.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct ScenarioArgs {
    /// Scenario file (TOML).
    #[arg(long, short, value_name = "FILE")]
    pub(crate) config: PathBuf,
    #[command(flatten)]
    pub(crate) set: OverrideArgs,
}

/// The scenario every real-time command runs when none is given.
pub(crate) const DEFAULT_SCENARIO: &str = "config/two_link_divergent.toml";

/// `--config FILE` (default: the two-link arm in the divergent field) and its `--set` overrides.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct DefaultScenarioArgs {
    /// Scenario file (TOML).
    #[arg(long, short, value_name = "FILE", default_value = DEFAULT_SCENARIO)]
    pub(crate) config: PathBuf,
    #[command(flatten)]
    pub(crate) set: OverrideArgs,
}

/// `--seed`: the seed of the noise.
#[derive(Debug, Clone, Copy, clap::Args)]
pub(crate) struct SeedArgs {
    /// Seed of the noise (each trial derives its own stream from it).
    /// [range: 0 to 18446744073709551615]
    #[arg(long, default_value_t = 1, value_parser = crate::ranges::whole(0u64, u64::MAX))]
    pub(crate) seed: u64,
}

/// `--json`: print one JSON object instead of the readable report.
#[derive(Debug, Clone, Copy, clap::Args)]
pub(crate) struct JsonArg {
    /// Print one JSON object instead of the readable report.
    #[arg(long)]
    pub(crate) json: bool,
}

/// Prints `value` as one line of JSON on stdout.
pub(crate) fn print_json(value: &impl serde::Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string(value)?);
    Ok(())
}

/// A command's result: one line of JSON with `--json`, else the readable report `table` prints.
pub(crate) fn print_report<T: serde::Serialize>(
    value: &T,
    json: bool,
    table: impl FnOnce(&T),
) -> anyhow::Result<()> {
    if json {
        print_json(value)
    } else {
        table(value);
        Ok(())
    }
}

/// The latency of `ms` given with `flag` on a grid of `dt` s ([`Latency::from_ms`]), else an
/// input error naming `flag`.
pub(crate) fn latency_arg(flag: &str, ms: f64, dt: f64) -> anyhow::Result<Latency> {
    Latency::from_ms(ms, dt).map_err(|e| {
        input_error(format!(
            "{flag} {}: not a whole number of {} ms plan steps",
            e.ms, e.step_ms
        ))
    })
}

/// The distance beyond which a trial counts as diverged: the user's, else the default of the
/// model's unit (10° for a single joint, 50 mm for the arm).
pub(crate) fn divergence_or_default(chosen: Option<f64>, model: &vic_core::model::ArmModel) -> f64 {
    chosen.unwrap_or_else(|| vic_plan::unit::Unit::for_model(model).default_divergence())
}

/// A stop flag set by SIGINT or SIGTERM.
pub(crate) fn stop_on_signal() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .map_err(|e| anyhow!("cannot install the signal handler: {e}"))?;
    Ok(stop)
}

/// The binary `name` next to the running one (the demo and the benchmarks start the board and the
/// planner as separate processes).
pub(crate) fn sibling_binary(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let path = exe.with_file_name(name);
    if path.is_file() {
        Ok(path)
    } else {
        Err(anyhow!(
            "{} not found next to {} (build it with cargo build --bins)",
            name,
            exe.display()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_errors_exit_2_even_with_context() {
        let e = input_error("--rate-hz 0: use 1 to 10000");
        assert_eq!(exit_code(&e), 2);
        let e = e.context("starting the board");
        assert_eq!(exit_code(&e), 2);
        assert_eq!(exit_code(&anyhow!("no board")), 1);
        let r: Result<(), &str> = Err("bad key");
        assert_eq!(exit_code(&r.input().unwrap_err()), 2);
        assert_eq!(exit_code(&r.runtime().unwrap_err()), 1);
    }

    #[test]
    fn message_does_not_repeat_a_cause_already_printed() {
        #[derive(Debug, thiserror::Error)]
        #[error("a.toml: cannot read: {source}")]
        struct Io {
            source: std::io::Error,
        }
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "not found");
        let e: anyhow::Error = InputError(Io { source: io }.into()).into();
        assert_eq!(message(&e), "a.toml: cannot read: not found");
        assert_eq!(message(&anyhow!("inner").context("outer")), "outer: inner");
    }

    #[test]
    fn latency_arg_rejects_fractions_and_negatives_naming_the_flag() {
        assert_eq!(
            latency_arg("--latency-ms", 200.0, 0.01).unwrap().knots(),
            20
        );
        let e = latency_arg("--latency-ms", 205.0, 0.01)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "--latency-ms 205: not a whole number of 10 ms plan steps"
        );
        assert!(latency_arg("--latency-ms", -10.0, 0.01).is_err());
        assert!(latency_arg("--latency-ms", f64::NAN, 0.01).is_err());
    }
}
