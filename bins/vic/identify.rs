//! `vic identify`: flags, then [`vic::identify_command::run`].

use std::path::PathBuf;
use vic::cli::JsonArg;
use vic::studies::identify::IdentifyOptions;

#[derive(clap::Args)]
pub struct IdentifyArgs {
    /// The log (CSV).
    #[arg(long, value_name = "FILE.csv")]
    log: PathBuf,
    /// Single-joint scenario whose [plant] gives J, m, l_c and g (default: the iCub forearm).
    #[arg(long, short, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Number of velocity bins.
    #[arg(long, default_value_t = 20)]
    bins: usize,
    /// Fewest samples a bin needs to be used.
    #[arg(long, default_value_t = 30)]
    min_bin_count: usize,
    /// Degree of the polynomial fitted to the mean error (the paper: 1).
    #[arg(long, default_value_t = 1)]
    mean_degree: usize,
    /// Degree of the polynomial fitted to the error's standard deviation (the paper: 2).
    #[arg(long, default_value_t = 2)]
    std_degree: usize,
    /// Subtract the fitted mean error before estimating (a, b).
    #[arg(long)]
    subtract_mean: bool,
    #[command(flatten)]
    json: JsonArg,
}

impl IdentifyArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let options = IdentifyOptions {
            bins: self.bins,
            min_bin_count: self.min_bin_count,
            mean_degree: self.mean_degree,
            std_degree: self.std_degree,
            subtract_mean: self.subtract_mean,
        };
        vic::identify_command::run(&self.log, self.config.as_ref(), &options, self.json.json)
    }
}
