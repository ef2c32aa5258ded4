//! What the user sees of a plan, a run or a running board: [`plot`] (the figures), [`report`]
//! (a central controller's results), [`operator`] (the acknowledgement, snapshot and lines of
//! `vic inject`, `status` and `monitor`, read from a running board) and `monitor` (the terminal
//! view of `vic monitor`, feature `tui`).

#[cfg(feature = "tui")]
pub(crate) mod monitor;
pub(crate) mod operator;
pub mod plot;
pub mod report;
