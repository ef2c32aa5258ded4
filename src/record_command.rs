//! `vic record` (an MCAP recording of a live namespace, from outside the board) and `vic
//! convert` (a board's MCAP recording to the CSV log that `vic identify` reads).

use crate::cli::{Classify, input_error, print_json, stop_on_signal};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;
use vic_rt::record::{ExternalOptions, ExternalSummary, RecordError, RecordFormat};
use vic_rt::record::{read_board_mcap, record_namespace, write_csv};

/// What `vic record` was asked for.
#[derive(Debug, Clone)]
pub struct RecordArgs {
    pub namespace: String,
    pub out: PathBuf,
    /// Stop after this long from the first state (None: at SIGINT/SIGTERM).
    pub duration: Option<Duration>,
    /// How long to wait for a board.
    pub wait: Duration,
    /// The scenario and plan of the run, if the user names them (their paths and the plan's
    /// hash go into the file's metadata).
    pub scenario: Option<PathBuf>,
    pub plan: Option<PathBuf>,
    pub json: bool,
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
pub fn run_record(a: &RecordArgs) -> anyhow::Result<()> {
    vic_rt::transport::validate_namespace(&a.namespace).input()?;
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
        let bytes = std::fs::read(p)
            .map_err(|e| format!("--plan {}: {e}", p.display()))
            .input()?;
        metadata.insert("plan".into(), p.display().to_string());
        metadata.insert("plan_fnv1a64".into(), fnv1a64(&bytes));
    }
    let stop = stop_on_signal()?;
    let opts = ExternalOptions {
        duration_ns: a.duration.map_or(0, |d| d.as_nanos() as u64),
        wait_for_board_ms: a.wait.as_millis() as u64,
        metadata,
    };
    let summary = record_namespace(&a.namespace, &a.out, &opts, &stop).map_err(classify)?;
    if a.json {
        print_json(&summary)
    } else {
        print_summary(&summary);
        Ok(())
    }
}

/// A file the user named is their input; a board that is missing or a failed write is the run's.
fn classify(e: RecordError) -> anyhow::Error {
    match e {
        RecordError::Format { .. } => input_error(e),
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

/// What `vic convert` reports.
#[derive(Debug, serde::Serialize)]
pub struct ConvertSummary {
    pub input: PathBuf,
    pub output: PathBuf,
    pub rows: usize,
    pub gaps: usize,
    pub joints: usize,
}

/// Converts the board recording `input` (MCAP) to the CSV log `output`.
pub fn run_convert(input: &Path, output: &Path, json: bool) -> anyhow::Result<()> {
    if RecordFormat::from_path(input).input()? != RecordFormat::Mcap {
        return Err(input_error(format!(
            "{}: vic convert reads a board's MCAP recording (FILE.mcap)",
            input.display()
        )));
    }
    if RecordFormat::from_path(output).input()? != RecordFormat::Csv {
        return Err(input_error(format!(
            "--csv {}: the output is a CSV log (FILE.csv)",
            output.display()
        )));
    }
    let rec = read_board_mcap(input).map_err(|e| match e {
        RecordError::Io { .. } | RecordError::Mcap { .. } | RecordError::Format { .. } => {
            input_error(e)
        }
        e => anyhow::anyhow!("{e}"),
    })?;
    let file = std::fs::File::create(output)
        .map_err(|e| format!("--csv {}: {e}", output.display()))
        .input()?;
    let mut w = std::io::BufWriter::new(file);
    write_csv(&rec, &mut w)
        .and_then(|()| w.flush())
        .map_err(|e| format!("{}: {e}", output.display()))
        .runtime()?;
    let summary = ConvertSummary {
        input: input.into(),
        output: output.into(),
        rows: rec.samples.len(),
        gaps: rec.gaps.len(),
        joints: rec.joints,
    };
    if json {
        print_json(&summary)
    } else {
        println!(
            "{} → {}: {} rows, {} gap(s), {} joint(s)",
            input.display(),
            output.display(),
            summary.rows,
            summary.gaps,
            summary.joints
        );
        Ok(())
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
