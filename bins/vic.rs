//! `vic`: the command-line front end. It parses the flags into [`vic::commands::Cli`] and runs
//! the subcommand; errors end the process with exit code 2 (bad input) or 1 (a failure).

use std::process::ExitCode;

fn main() -> ExitCode {
    match vic::cli::parse::<vic::commands::Cli>("vic") {
        Ok(cli) => vic::cli::finish("vic", cli.run()),
        Err(code) => code,
    }
}
