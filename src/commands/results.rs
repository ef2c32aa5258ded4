//! `vic results`: regenerate docs/RESULTS.md, the document that sets the paper's claims beside
//! our numbers: fig1, fig2 and icub, the latency sweeps, their figures in `--out-dir/figures`.

use super::experiment::{FigureRunArgs, run_figure};
use crate::cli::Classify;
use crate::progress::Progress;
use crate::studies::experiment::{
    Figure, delay_markdown, results_markdown, run_delay_sweeps, write_delay_outputs, write_outputs,
};
use std::path::PathBuf;

#[derive(clap::Args)]
pub(crate) struct Args {
    #[command(flatten)]
    run: FigureRunArgs,
    /// Where RESULTS.md and figures/ go.
    #[arg(long, default_value = "docs", value_name = "DIR")]
    out_dir: PathBuf,
}

/// fig1, fig2 and icub, their figures in `out_dir/figures` and `out_dir/RESULTS.md`.
pub(crate) fn run(a: Args) -> anyhow::Result<()> {
    let (o, out_dir) = (&a.run, &a.out_dir);
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
    let sweeps =
        run_delay_sweeps(&o.config_dir, o.trials as usize, o.seed.seed, &progress).runtime()?;
    drop(line);
    for s in &sweeps {
        for f in write_delay_outputs(s, &out_dir.join("figures")).runtime()? {
            println!("wrote {}", f.display());
        }
    }
    let command = format!(
        "cargo run --release -- results --trials {} --seed {} --out-dir {}",
        o.trials,
        o.seed.seed,
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
