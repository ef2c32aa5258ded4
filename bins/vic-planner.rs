//! `vic-planner`: the central controller. A 50 Hz loop that plays a plan back to `vic-board` as
//! command slices, with a strategy (`naive-delayed`, `predictor`, `stiffness`,
//! `stiffness+predictor`) and delay lines on the
//! state and command paths; runs N trials and prints their errors. The flags are parsed here;
//! [`vic::central_daemon::run`] does the rest.

use std::process::ExitCode;
use vic::central_daemon::CentralOptions;
use vic::cli::finish;

fn main() -> ExitCode {
    let options: CentralOptions = clap::Parser::parse();
    finish("vic-planner", vic::central_daemon::run(&options))
}
