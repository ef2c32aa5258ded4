//! `vic convert`: flags, then [`vic::record_command::run_convert`].

use std::path::PathBuf;
use vic::cli::JsonArg;

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the summary as one JSON object")))]
pub struct ConvertArgs {
    /// A board's MCAP recording (vic-board --record FILE.mcap).
    #[arg(value_name = "FILE.mcap")]
    input: PathBuf,
    /// Write the CSV log (the format of vic-board --record FILE.csv and vic identify --log).
    #[arg(long, value_name = "FILE.csv")]
    csv: PathBuf,
    #[command(flatten)]
    json: JsonArg,
}

impl ConvertArgs {
    pub fn run(self) -> anyhow::Result<()> {
        vic::record_command::run_convert(&self.input, &self.csv, self.json.json)
    }
}
