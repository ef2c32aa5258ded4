//! `vic convert`: a board's MCAP recording to the CSV log that `vic identify` reads.

use crate::cli::{Classify, JsonArg, input_error, print_json};
use std::io::Write;
use std::path::PathBuf;
use vic_rt::record::{RecordError, RecordFormat, read_board_mcap, write_csv};

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object")))]
pub(crate) struct Args {
    /// A board's MCAP recording (vic-board --record FILE.mcap).
    #[arg(value_name = "FILE.mcap")]
    input: PathBuf,
    /// Write the CSV log (the format of vic-board --record FILE.csv and vic identify --log).
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
    rows: usize,
    gaps: usize,
    joints: usize,
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
    if a.json.json {
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
