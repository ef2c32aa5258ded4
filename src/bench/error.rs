//! What can stop a benchmark (`vic bench loop`, `vic bench ipc`), each naming the program, file
//! or channel concerned. All of them are failures of the run (exit code 1): the command checks
//! the user's input before measuring.

use std::process::ExitStatus;
use vic_plan::plan::PlanError;
use vic_plan::scenario::ConfigError;
use vic_rt::board::BoardError;
use vic_rt::transport::TransportError;

/// Why cyclictest's histogram file could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HistogramError {
    #[error("cyclictest histogram, line {line}: \"{token}\": {source}")]
    Number {
        line: usize,
        token: String,
        source: std::num::ParseIntError,
    },
    #[error("cyclictest histogram, line {line}: expected `LATENCY COUNT`, got \"{text}\"")]
    Row { line: usize, text: String },
    #[error("cyclictest histogram, line {line}: latency {latency_us} µs is out of range")]
    Latency { line: usize, latency_us: usize },
    #[error("cyclictest histogram: no `# {0}:` line")]
    Missing(&'static str),
    #[error("cyclictest histogram: the buckets hold {in_buckets} samples, `# Total:` says {total}")]
    Total { in_buckets: u64, total: u64 },
}

/// Why a benchmark could not run to its end.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BenchError {
    #[error(transparent)]
    Scenario(#[from] ConfigError),
    #[error(transparent)]
    Plan(#[from] PlanError),
    #[error(transparent)]
    Board(#[from] BoardError),
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error(transparent)]
    Histogram(#[from] HistogramError),
    /// A process could not be started, waited for, or left no output (`what` says which).
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
    /// A process exited with a failure status (`stderr`: what it said, possibly nothing).
    #[error("{command} failed ({status}){}", said(.stderr))]
    Failed {
        command: String,
        status: ExitStatus,
        stderr: String,
    },
    /// The bare iceoryx2 baseline could not open a node, service or port, or send.
    #[error("{what}: {message}")]
    Iceoryx { what: String, message: String },
    /// The pong side of a ping-pong stopped answering.
    #[error("the ping side went quiet")]
    Quiet,
    /// A ping was re-sent too often without an answer.
    #[error("no answer to ping {0}")]
    NoAnswer(u64),
    /// A thread of the benchmark panicked.
    #[error("the {0} thread panicked")]
    Panicked(&'static str),
    /// A daemon did not reach a state in time (`what` says which).
    #[error("{0}")]
    Timeout(&'static str),
    /// `vic-board --json` printed no statistics object.
    #[error("vic-board printed no statistics: {0}")]
    Statistics(serde_json::Error),
    #[error("unknown variant \"{name}\"; choose from {choices}")]
    UnknownVariant { name: String, choices: String },
    #[error("no variant ran")]
    NoVariant,
    /// A variant of the loop benchmark failed.
    #[error("variant {name}: {source}")]
    Variant {
        name: &'static str,
        source: Box<BenchError>,
    },
}

impl BenchError {
    /// An I/O failure of `what` (a process or a file).
    pub(crate) fn io(what: impl Into<String>, source: std::io::Error) -> Self {
        BenchError::Io {
            what: what.into(),
            source,
        }
    }

    /// The iceoryx2 baseline failed at `what` (its errors are only `Debug`).
    pub(crate) fn iceoryx(what: impl Into<String>, error: impl std::fmt::Debug) -> Self {
        BenchError::Iceoryx {
            what: what.into(),
            message: format!("{error:?}"),
        }
    }
}

/// `": TEXT"`, or nothing when a failed process printed nothing.
fn said(stderr: &str) -> String {
    if stderr.is_empty() {
        String::new()
    } else {
        format!(": {stderr}")
    }
}
