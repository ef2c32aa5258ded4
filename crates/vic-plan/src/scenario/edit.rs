//! Typed edits of a validated scenario: what a strategy's plan changes in the scenario it is made
//! on (the strategy module's plan requests). Each edit keeps the scenario valid and writes the new
//! values into [`Scenario::resolved`] too, so that a plan file records the scenario it was
//! made on.

use super::Scenario;
use vic_core::latency::Latency;

impl Scenario {
    /// The scenario without stiffness: the stiffness bounds and the solver's starting stiffness
    /// at 0 (`stiffness_min`, `stiffness_max` and `initial_stiffness` of `[actuator]`), so that
    /// feedback is all the plan has, from its first guess on (the paper's "delayed feedback
    /// without stiffness", Eq. 13). Nothing changes for an actuator without stiffness.
    pub fn without_stiffness(mut self) -> Scenario {
        let dof = self.model.dof();
        let Some(off) = self.model.actuator.stiffness_offset(dof) else {
            return self;
        };
        self.bounds.lower[off..off + dof].fill(0.0);
        self.bounds.upper[off..off + dof].fill(0.0);
        self.initial_stiffness = 0.0;
        for key in ["stiffness_min", "stiffness_max", "initial_stiffness"] {
            self.set_resolved("actuator", key, 0.0);
        }
        self
    }

    /// The scenario with the central feedback delay `delay` (`task.delay_ms`): the delay an ILQG
    /// plan is made for (Eq. 13). `delay` must be on this scenario's grid (made with its
    /// `task.dt`).
    pub fn with_delay(mut self, delay: Latency) -> Scenario {
        debug_assert_eq!(
            Latency::from_ms(delay.ms(), self.task.dt).map(Latency::knots),
            Ok(delay.knots()),
            "a latency of another grid"
        );
        self.task.delay_ms = delay.ms();
        self.set_resolved("task", "delay_ms", delay.ms());
        self
    }

    fn set_resolved(&mut self, section: &str, key: &str, value: f64) {
        if let toml::Value::Table(t) = self
            .resolved
            .entry(section)
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        {
            t.insert(key.to_string(), toml::Value::Float(value));
        }
    }
}
