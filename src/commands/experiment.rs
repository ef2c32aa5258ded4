//! `vic experiment`: reproduce a figure of the paper (plan and simulate every column, write the
//! plots and the numbers, print a table); [`FigureRunArgs`] and [`run_figure`] are shared with
//! `vic results`.

use crate::cli::{Classify, JsonArg, SeedArgs, input_error, print_json};
use crate::progress::Progress;
use crate::studies::experiment::{
    ExperimentError, ExperimentRun, Figure, run as run_columns, to_json, write_outputs,
};
use clap::ValueEnum;
use std::path::PathBuf;

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
#[command(mut_arg("seed", |a| a.help("Seed of the noise [range: 0 to 18446744073709551615]")))]
pub(crate) struct FigureRunArgs {
    /// Monte Carlo trials per column. [range: 3 to 100000]
    #[arg(long, default_value_t = 20, value_parser = crate::ranges::trials(3, "the 95 % ellipse of the final positions needs three"))]
    pub(crate) trials: u64,
    #[command(flatten)]
    pub(crate) seed: SeedArgs,
    /// Folder of the scenario files.
    #[arg(long, default_value = "config", value_name = "DIR")]
    pub(crate) config_dir: PathBuf,
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print the JSON document instead of the table")))]
pub(crate) struct Args {
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

/// Runs every column of `figure`, with a progress bar over its columns (after `label`) and the
/// solver's state on a terminal.
pub(crate) fn run_figure(
    figure: Figure,
    o: &FigureRunArgs,
    label: &str,
) -> anyhow::Result<ExperimentRun> {
    let progress = Progress::steps(label, 0);
    run_columns(
        figure,
        &o.config_dir,
        o.trials as usize,
        o.seed.seed,
        progress.solver_callback(),
        |i, n, name| progress.step(i, n, name),
    )
    .map_err(|e| match e {
        ExperimentError::Config(c) => input_error(c),
        other => anyhow::Error::new(other),
    })
}

/// One figure, its plots and JSON written to `--out-dir`, a table (or the JSON document) printed.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let figure = match a.figure {
        FigureArg::Fig1 => Figure::Fig1,
        FigureArg::Fig2 => Figure::Fig2,
        FigureArg::Icub => Figure::Icub,
    };
    let o = &a.run;
    if !vic_plan::scenario::is_folder(&o.config_dir) {
        return Err(input_error(format!(
            "--config-dir {}: not a folder of scenario files",
            o.config_dir.display()
        )));
    }
    let run = run_figure(figure, o, figure.name())?;
    let files = write_outputs(&run, &a.out_dir).runtime()?;
    if a.json.json {
        return print_json(&to_json(&run));
    }
    print_table(&run);
    if figure == Figure::Icub {
        println!("{}", icub_comparison(&run));
    }
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

/// The paper's iCub costs beside ours: on a scale the paper does not state (Eq. 14's weights
/// give 10²–10⁵ here), so the comparable figure is the ratio measured / predicted.
fn icub_comparison(run: &ExperimentRun) -> String {
    let ours = run
        .columns
        .first()
        .and_then(|c| c.expected_cost_mc.map(|mc| mc / c.expected_cost_predicted))
        .map_or_else(
            || "no Monte Carlo cost here".to_string(),
            |r| format!("here Monte Carlo / predicted = {r:.2}"),
        );
    let (predicted, measured) = crate::studies::experiment::PAPER_ICUB_COST;
    format!(
        "paper: C* = {predicted} predicted, C = {measured} measured on the robot (ratio {:.2}), on a \
         cost scale it does not state: compare the ratios, not the costs; {ours}",
        measured / predicted
    )
}

fn print_table(run: &ExperimentRun) {
    println!(
        "{:<18} {:>8} {:>12} {:>12} {:>9} {:>13} {:>13} {:>9}",
        "column", "method", "final std", "RMS error", "diverged", "E[C] MC", "E[C] pred.", "mean K"
    );
    for c in &run.columns {
        let unit = &c.report.unit;
        println!(
            "{:<18} {:>8} {:>12} {:>12} {:>7.0} % {:>13} {:>13.4e} {:>9.1}",
            c.name,
            c.method,
            format!("{:.2} {unit}", c.report.final_std),
            c.rms_error
                .map_or_else(|| "diverged".into(), |v| format!("{v:.2} {unit}")),
            c.diverged_fraction * 100.0,
            c.expected_cost_mc
                .map_or_else(|| "–".into(), |v| format!("{v:.4e}")),
            c.expected_cost_predicted,
            c.mean_stiffness
        );
    }
}
