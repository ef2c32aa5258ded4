//! `vic experiment`: flags, then [`vic::reproduce::experiment`].

use clap::ValueEnum;
use std::path::PathBuf;
use vic::cli::{JsonArg, SeedArgs};
use vic::reproduce::{FigureRunOptions, experiment};
use vic::studies::experiment::Figure;

#[derive(Clone, Copy, ValueEnum)]
enum FigureArg {
    /// Two-link arm in the divergent field, each actuator type, executed open loop (Fig. 1).
    Fig1,
    /// Single joint with a 200 ms feedback delay: feedforward, delayed feedback, stiffness (Fig. 2).
    Fig2,
    /// The iCub elbow with the identified noise: predicted versus Monte Carlo expected cost.
    Icub,
}

/// The Monte Carlo of every column and the folder of the scenarios (`vic experiment` and
/// `vic results`).
#[derive(clap::Args)]
#[command(mut_arg("seed", |a| a.help("Seed of the noise")))]
pub struct FigureRunArgs {
    /// Monte Carlo trials per column.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(3..))]
    trials: u64,
    #[command(flatten)]
    seed: SeedArgs,
    /// Folder of the scenario files.
    #[arg(long, default_value = "config", value_name = "DIR")]
    config_dir: PathBuf,
}

impl FigureRunArgs {
    pub fn options(self) -> FigureRunOptions {
        FigureRunOptions {
            trials: self.trials as usize,
            seed: self.seed.seed,
            config_dir: self.config_dir,
        }
    }
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the JSON document instead of the table")))]
pub struct ExperimentArgs {
    /// Which experiment.
    #[arg(value_enum)]
    figure: FigureArg,
    #[command(flatten)]
    run: FigureRunArgs,
    /// Where the plots and the JSON go.
    #[arg(long, default_value = "results", value_name = "DIR")]
    out_dir: PathBuf,
    #[command(flatten)]
    json: JsonArg,
}

impl ExperimentArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let figure = match self.figure {
            FigureArg::Fig1 => Figure::Fig1,
            FigureArg::Fig2 => Figure::Fig2,
            FigureArg::Icub => Figure::Icub,
        };
        experiment(figure, &self.run.options(), &self.out_dir, self.json.json)
    }
}
