//! Progress on stderr for long work (plans, the paper's figures, the latency sweeps), drawn by
//! `indicatif` only when stderr is a terminal: scripts, pipes and `--json` see nothing, and the
//! line is erased when the work ends (also on an early return: [`Drop`]).

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Arc;
use std::time::Duration;
use vic_core::solver::ilqg::Progress as SolverProgress;
use vic_plan::plan::ProgressFn;

/// One progress line: a spinner with the solver's state, or a bar over known steps.
pub(crate) struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A spinner for work of unknown length (a solve).
    pub(crate) fn spinner() -> Self {
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed}] {wide_msg}")
                .expect("valid template"),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Progress { bar }
    }

    /// A bar over `steps` steps named `what` (e.g. "fig1").
    pub(crate) fn steps(what: &str, steps: u64) -> Self {
        let bar = ProgressBar::new(steps);
        bar.set_style(
            ProgressStyle::with_template("{prefix} [{elapsed}] {bar:24} {pos}/{len} {wide_msg}")
                .expect("valid template"),
        );
        bar.set_prefix(what.to_string());
        bar.enable_steady_tick(Duration::from_millis(120));
        Progress { bar }
    }

    /// Whether anything is drawn (stderr is a terminal).
    pub(crate) fn is_drawn(&self) -> bool {
        !self.bar.is_hidden()
    }

    /// Starts step `index` (0-based) of `steps`, named `name`.
    pub(crate) fn step(&self, index: usize, steps: usize, name: &str) {
        self.bar.set_length(steps as u64);
        self.bar.set_position(index as u64);
        self.bar.set_message(name.to_string());
    }

    /// Replaces the message.
    pub(crate) fn message(&self, text: &str) {
        self.bar.set_message(text.to_string());
    }

    /// The planner's per-iteration callback writing into this line (`None` when nothing is
    /// drawn, so the planner does not format messages for nobody).
    pub(crate) fn solver_callback(&self) -> Option<ProgressFn> {
        if !self.is_drawn() {
            return None;
        }
        let bar = self.bar.clone();
        Some(Arc::new(move |phase: &str, p: &SolverProgress| {
            bar.set_message(format!(
                "{phase}: iteration {} merit {:.6e} (μ {:.1e}, step {})",
                p.iteration, p.merit, p.mu, p.alpha
            ));
        }))
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}
