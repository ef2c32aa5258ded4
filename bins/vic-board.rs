//! `vic-board`: the simulated robot board. A 1 kHz absolute-deadline loop that integrates the
//! scenario's plant under the impedance law (Eq. 4), follows the command slices of `vic-planner`,
//! applies injected disturbances, and publishes its state every tick and telemetry at 10 Hz.
//! SIGINT/SIGTERM stop it at the end of the current tick; it prints its statistics and exits 0.
//! Its flags and their help are [`vic::daemons::board::BoardOptions`];
//! [`vic::daemons::board::run`] does the rest.

use std::process::ExitCode;
use vic::cli::{finish, parse};
use vic::daemons::board::BoardOptions;

fn main() -> ExitCode {
    match parse::<BoardOptions>("vic-board") {
        Ok(options) => finish("vic-board", vic::daemons::board::run(&options)),
        Err(code) => code,
    }
}
