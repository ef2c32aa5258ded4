//! `vic experiment` and `vic results`: reproduce the paper's figures (plan and simulate every
//! column, write the plots and the numbers) and regenerate the results document that sets the
//! paper's claims beside ours.

use crate::cli::{Classify, input_error, print_json};
use crate::progress::Progress;
use crate::studies::experiment::{
    ExperimentError, ExperimentRun, Figure, delay_markdown, results_markdown, run,
    run_delay_sweeps, to_json, write_delay_outputs, write_outputs,
};
use std::path::{Path, PathBuf};

/// The Monte Carlo every figure runs with, and where its scenarios are.
#[derive(Debug, Clone)]
pub struct FigureRunOptions {
    /// Trials per column.
    pub trials: usize,
    pub seed: u64,
    /// The folder of the scenario files.
    pub config_dir: PathBuf,
}

/// Runs every column of `figure`, with a progress bar over its columns (after `label`) and the
/// solver's state on a terminal.
fn run_figure(figure: Figure, o: &FigureRunOptions, label: &str) -> anyhow::Result<ExperimentRun> {
    let progress = Progress::steps(label, 0);
    run(
        figure,
        &o.config_dir,
        o.trials,
        o.seed,
        progress.solver_callback(),
        |i, n, name| progress.step(i, n, name),
    )
    .map_err(|e| match e {
        ExperimentError::Config(c) => input_error(c),
        other => anyhow::Error::new(other),
    })
}

/// `vic experiment`: one figure, its plots and JSON written to `out_dir`, a table (or the JSON
/// document) printed.
pub fn experiment(
    figure: Figure,
    o: &FigureRunOptions,
    out_dir: &Path,
    json: bool,
) -> anyhow::Result<()> {
    if !o.config_dir.is_dir() {
        return Err(input_error(format!(
            "--config-dir {}: not a folder of scenario files",
            o.config_dir.display()
        )));
    }
    let run = run_figure(figure, o, figure.name())?;
    let files = write_outputs(&run, out_dir).runtime()?;
    if json {
        return print_json(&to_json(&run));
    }
    print_table(&run);
    if figure == Figure::Icub {
        println!("paper: C* = 0.29 predicted, C = 0.41 measured on the robot");
    }
    for f in files {
        println!("wrote {}", f.display());
    }
    Ok(())
}

fn print_table(run: &ExperimentRun) {
    println!(
        "{:<18} {:>8} {:>12} {:>12} {:>9} {:>13} {:>13} {:>9}",
        "column", "method", "final std", "RMS error", "diverged", "E[C] MC", "E[C] pred.", "mean K"
    );
    for c in &run.columns {
        let unit = &c.report.unit;
        println!(
            "{:<18} {:>8} {:>9.2} {unit:<3}{:>8} {unit:<3} {:>8.0} % {:>13} {:>13.4e} {:>9.1}",
            c.name,
            c.method,
            c.report.final_std,
            c.rms_error
                .map_or_else(|| "diverged".into(), |v| format!("{v:.2}")),
            c.diverged_fraction * 100.0,
            c.expected_cost_mc
                .map_or_else(|| "–".into(), |v| format!("{v:.4e}")),
            c.expected_cost_predicted,
            c.mean_stiffness
        );
    }
}

/// `vic results`: fig1, fig2 and icub, their figures in `out_dir/figures` and `out_dir/RESULTS.md`.
pub fn results(o: &FigureRunOptions, out_dir: &Path) -> anyhow::Result<()> {
    let mut runs = Vec::new();
    for figure in [Figure::Fig1, Figure::Fig2, Figure::Icub] {
        let r = run_figure(figure, o, figure.name())?;
        for f in write_outputs(&r, &out_dir.join("figures")).runtime()? {
            println!("wrote {}", f.display());
        }
        runs.push(r);
    }
    // Delay versus stiffness: the latency sweeps, after the paper's figures.
    let line = Progress::spinner();
    let progress = |s: &str| line.message(&format!("delay: {s}"));
    let sweeps = run_delay_sweeps(&o.config_dir, o.trials, o.seed, &progress).runtime()?;
    drop(line);
    for s in &sweeps {
        for f in write_delay_outputs(s, &out_dir.join("figures")).runtime()? {
            println!("wrote {}", f.display());
        }
    }
    let command = format!(
        "cargo run --release -- results --trials {} --seed {} --out-dir {}",
        o.trials,
        o.seed,
        out_dir.display()
    );
    let md = results_markdown(&runs, "figures", &command) + &delay_markdown(&sweeps, "figures");
    let path = out_dir.join("RESULTS.md");
    std::fs::write(&path, md)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
        .runtime()?;
    println!("wrote {}", path.display());
    Ok(())
}
