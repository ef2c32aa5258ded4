//! What the binaries call: [`operator`] (inject, status, monitor), [`experiment`] (the paper's
//! figures), [`identify`] (noise identification), [`plot`], [`bench`] and [`launch`] (turning a
//! scenario into the board's and the central controller's configuration).

pub mod bench;
pub mod experiment;
pub mod identify;
pub mod launch;
pub mod operator;
pub mod plot;
pub mod report;
pub mod sweep;
