//! The paper's limbs for the tests, read from the scenario files so that their numbers live in one
//! place (config/).
#![allow(dead_code)] // each test binary uses a part

pub mod alloc;
pub mod bridge;
pub mod cli;
pub mod daemons;
pub mod trial;

use std::path::Path;
use vic_core::model::{Plant, SingleJoint, TwoLink};
use vic_plan::plan::{self, Setup};
use vic_plan::scenario::Scenario;

/// A scenario of `config/` with `--set` overrides (`section.key=value`), and its plan setup.
pub fn scenario(file: &str, overrides: &[&str]) -> (Scenario, Setup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file);
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let s = Scenario::load(&path, &o).expect("scenario loads");
    let setup = plan::setup(&s).expect("scenario sets up");
    (s, setup)
}

fn plant(file: &str) -> Plant {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file);
    Scenario::load(&path, &[])
        .expect("scenario loads")
        .model
        .plant
}

/// Li & Todorov's two-link arm (config/two_link_divergent.toml).
pub fn two_link() -> TwoLink {
    match plant("two_link_divergent.toml") {
        Plant::TwoLink(p) => p,
        other => panic!("expected a two-link arm, got {other:?}"),
    }
}

/// The iCub forearm (config/icub_elbow.toml).
pub fn icub_forearm() -> SingleJoint {
    match plant("icub_elbow.toml") {
        Plant::SingleJoint(p) => p,
        other => panic!("expected a single joint, got {other:?}"),
    }
}
