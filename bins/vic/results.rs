//! `vic results`: flags, then [`vic::reproduce::results`].

use crate::experiment::FigureRunArgs;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ResultsArgs {
    #[command(flatten)]
    run: FigureRunArgs,
    /// Where RESULTS.md and figures/ go.
    #[arg(long, default_value = "docs", value_name = "DIR")]
    out_dir: PathBuf,
}

impl ResultsArgs {
    pub fn run(self) -> anyhow::Result<()> {
        vic::reproduce::results(&self.run.options(), &self.out_dir)
    }
}
