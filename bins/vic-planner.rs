//! `vic-planner`: the central controller. A 50 Hz loop that plays a plan back to `vic-board` as
//! command slices, with a strategy (`naive-delayed`, `predictor`, `stiffness`,
//! `stiffness+predictor`) and delay lines on the
//! state and command paths; runs N trials and prints their errors. The flags are parsed here;
//! [`vic::daemons::central::run`] does the rest.

use std::process::ExitCode;
use vic::cli::{finish, parse};
use vic::daemons::central::CentralOptions;

fn main() -> ExitCode {
    match parse::<CentralOptions>("vic-planner") {
        Ok(options) => finish("vic-planner", vic::daemons::central::run(&options)),
        Err(code) => code,
    }
}
