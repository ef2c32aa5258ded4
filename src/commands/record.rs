//! `vic record`: an MCAP recording of a live namespace, from outside the board (states, command
//! slices, control requests, disturbances and telemetry, each on its own channel).

use crate::cli::{Classify, JsonArg, NamespaceArgs, input_error, print_json, stop_on_signal};
use crate::ranges::{MAX_RUN_S, MAX_WAIT_S, real, seconds};
use std::collections::BTreeMap;
use std::path::PathBuf;
use vic_plan::bounded_read::MAX_PLAN_BYTES;
use vic_rt::record::{
    ExternalOptions, ExternalSummary, RecordError, RecordFormat, record_namespace,
};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object")))]
pub(crate) struct Args {
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// The MCAP file to write: a new file (an existing one is refused without --force; a
    /// symbolic link is never followed). It is written under a temporary name in the same
    /// directory and takes this name once the board's first state arrived.
    #[arg(long, value_name = "FILE.mcap")]
    out: PathBuf,
    /// Replace an existing --out (once the board's first state arrived: a recording that finds
    /// no board leaves it as it was). A symbolic link is replaced, not followed.
    #[arg(long)]
    force: bool,
    /// Stop this many seconds after the board's first state (0: at Ctrl-C / SIGTERM).
    /// [range: 0 to 604800]
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = real(0.0, MAX_RUN_S))]
    duration: f64,
    /// Seconds to wait for a board before giving up (exit 1). [range: 0.001 to 3600]
    #[arg(long, value_name = "S", default_value_t = 2.0, value_parser = real(0.001, MAX_WAIT_S))]
    wait: f64,
    /// The scenario the run uses (its path goes into the file's metadata).
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// The plan the run uses (its path and hash go into the file's metadata).
    #[arg(long, value_name = "FILE")]
    plan: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

/// FNV-1a (64 bit) of `bytes`, in hex: identifies a plan file in a recording's metadata (not a
/// security hash; it tells which plan a run used).
pub fn fnv1a64(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Records the namespace until the duration ends or SIGINT / SIGTERM, then prints the summary.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let namespace = a.namespace.validated()?;
    let (duration, wait) = (seconds(a.duration), seconds(a.wait));
    if RecordFormat::from_path(&a.out).input()? != RecordFormat::Mcap {
        return Err(input_error(format!(
            "--out {}: vic record writes MCAP (FILE.mcap); vic convert makes the CSV of a board recording",
            a.out.display()
        )));
    }
    let mut metadata = BTreeMap::new();
    metadata.insert(
        "command_line".to_string(),
        std::env::args().collect::<Vec<_>>().join(" "),
    );
    if let Some(s) = &a.scenario {
        metadata.insert("scenario".into(), s.display().to_string());
    }
    if let Some(p) = &a.plan {
        let bytes = vic_plan::bounded_read::read_at_most(p, MAX_PLAN_BYTES, "plan file")
            .map_err(|e| format!("--plan {}: {e}", p.display()))
            .input()?;
        metadata.insert("plan".into(), p.display().to_string());
        metadata.insert("plan_fnv1a64".into(), fnv1a64(&bytes));
    }
    let stop = stop_on_signal()?;
    let opts = ExternalOptions {
        duration_ns: duration.as_nanos() as u64,
        wait_for_board_ms: wait.as_millis() as u64,
        metadata,
        replace: a.force,
    };
    let summary = record_namespace(namespace, &a.out, &opts, &stop).map_err(classify)?;
    if a.json.json {
        print_json(&summary)
    } else {
        print_summary(&summary);
        Ok(())
    }
}

/// A file the user named is their input (also one that exists already); a board that is missing
/// or a failed write (a full disk) is the run's.
fn classify(e: RecordError) -> anyhow::Error {
    match e {
        RecordError::Format { .. } | RecordError::Exists { .. } => input_error(e),
        e => anyhow::anyhow!("{e}"),
    }
}

fn print_summary(s: &ExternalSummary) {
    println!(
        "recorded {} ({:.1} s, namespace \"{}\"): {} states (ticks {} to {}), {} lost in {} gap(s)",
        s.path.display(),
        s.seconds,
        s.namespace,
        s.states,
        s.first_tick,
        s.last_tick,
        s.states_lost,
        s.gaps
    );
    for t in &s.topics {
        println!("  {:<14} {} messages", t.topic, t.messages);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn fnv1a64_matches_the_published_test_vectors() {
        // From the FNV reference (draft-eastlake-fnv): "" and "a".
        assert_eq!(super::fnv1a64(b""), "cbf29ce484222325");
        assert_eq!(super::fnv1a64(b"a"), "af63dc4c8601ec8c");
        assert_eq!(super::fnv1a64(b"foobar"), "85944171f73967e8");
    }
}
