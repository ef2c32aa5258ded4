//! `vic convert`: a board's MCAP recording to the CSV log that `vic identify` reads, or the
//! states of a namespace recording (`vic record`) to a CSV table. A file its recorder never
//! closed (killed, a full disk) is read up to its last whole chunk, and the output says so.

use crate::cli::{Classify, JsonArg, input_error, print_json};
use std::io::Write;
use std::path::PathBuf;
use vic_rt::record::{
    RecordError, RecordFormat, TICK_TOPIC, board_recording, read_recording, write_csv,
    write_states_csv,
};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object")))]
pub(crate) struct Args {
    /// A board's MCAP recording (vic-board --record FILE.mcap), or a namespace recording
    /// (vic record --out FILE.mcap): its states.
    #[arg(value_name = "FILE.mcap")]
    input: PathBuf,
    /// Write the CSV log (the format of vic-board --record FILE.csv and vic identify --log; for
    /// a namespace recording, one row per state).
    #[arg(long, value_name = "FILE.csv")]
    csv: PathBuf,
    #[command(flatten)]
    json: JsonArg,
}

/// What `vic convert` reports.
#[derive(Debug, serde::Serialize)]
struct ConvertSummary {
    input: PathBuf,
    output: PathBuf,
    /// `board` (vic-board --record) or `namespace` (vic record).
    kind: &'static str,
    rows: usize,
    gaps: usize,
    joints: usize,
    /// Set when the recording was not closed (its recorder killed, its disk full): why reading
    /// stopped at its unfinished end.
    truncated: Option<String>,
}

/// Converts the board recording (MCAP) to the CSV log `--csv`.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let (input, output) = (a.input.as_path(), a.csv.as_path());
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
    let as_input = |e: RecordError| match e {
        RecordError::Io { .. } | RecordError::Mcap { .. } | RecordError::Format { .. } => {
            input_error(e)
        }
        e => anyhow::anyhow!("{e}"),
    };
    let file = read_recording(input).map_err(as_input)?;
    let truncated = file.truncated.clone();
    let board = file.messages.iter().any(|(t, _, _)| t == TICK_TOPIC);
    let out = std::fs::File::create(output)
        .map_err(|e| format!("--csv {}: {e}", output.display()))
        .input()?;
    let mut w = std::io::BufWriter::new(out);
    let written = |e: std::io::Error| anyhow::anyhow!("{}: {e}", output.display());
    let summary = if board {
        let rec = board_recording(file, input).map_err(as_input)?;
        write_csv(&rec, &mut w).map_err(written)?;
        ConvertSummary {
            input: input.into(),
            output: output.into(),
            kind: "board",
            rows: rec.samples.len(),
            gaps: rec.gaps.len(),
            joints: rec.joints,
            truncated,
        }
    } else {
        let s = write_states_csv(&file, input, &mut w).map_err(as_input)?;
        ConvertSummary {
            input: input.into(),
            output: output.into(),
            kind: "namespace",
            rows: s.rows,
            gaps: s.gaps,
            joints: s.joints,
            truncated,
        }
    };
    w.flush().map_err(written)?;
    if a.json.json {
        print_json(&summary)
    } else {
        println!(
            "{} → {}: {} recording, {} rows, {} gap(s), {} joint(s)",
            input.display(),
            output.display(),
            summary.kind,
            summary.rows,
            summary.gaps,
            summary.joints
        );
        if let Some(t) = &summary.truncated {
            println!("  recovered: {t}");
        }
        Ok(())
    }
}
