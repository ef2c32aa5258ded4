//! `vic`: the command-line front end. It parses the flags into [`vic::commands::Cli`] and runs
//! the subcommand; errors end the process with exit code 2 (bad input) or 1 (a failure).

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = vic::commands::Cli::parse();
    vic::cli::finish("vic", cli.run())
}
