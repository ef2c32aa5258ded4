//! The experiment's spine: a central strategy at a feedback latency → the plan it needs → how
//! that plan is executed. The demo, the sweep, the experiments, `vic simulate` and the daemons
//! all go through here, so that a strategy means the same plan and the same law everywhere.
//!
//! - [`Latency`]: the latency on the plan's grid, checked once ([`Latency::from_ms`]).
//! - [`StrategyPlan::plan_request`]: which method and which scenario edits a strategy's plan
//!   needs ([`PlanRequest`]): the feedback-only strategies get no stiffness (feedback is all
//!   they have); only the naive law is planned for the delay (Eq. 13 needs the augmented plan's
//!   gains), the predictors use the undelayed gains on their prediction; the stiffness
//!   strategies are SOOC's open-loop plans, which no delay enters.
//! - [`Strategy::feedback`]: how the plan is executed at the latency ([`Feedback`], the one law
//!   of the Monte Carlo, the lockstep pair and the live controller).

use crate::method::Method;
use crate::plan::{PlanError, PlanFile, ProgressFn, plan};
use crate::scenario::Scenario;
pub use vic_core::latency::{Latency, LatencyError};
pub use vic_core::policy::{Feedback, Strategy};

/// What a plan is made of: the method and the edits of the scenario it is made on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanRequest {
    pub method: Method,
    /// Plan without stiffness ([`Scenario::without_stiffness`]).
    pub without_stiffness: bool,
    /// The feedback delay the plan is made for ([`Scenario::with_delay`]).
    pub delay: Latency,
}

impl PlanRequest {
    /// `base` with this request's edits.
    pub fn scenario(&self, base: &Scenario) -> Scenario {
        let s = base.clone().with_delay(self.delay);
        match self.without_stiffness {
            true => s.without_stiffness(),
            false => s,
        }
    }

    /// The plan on `base` edited for this request.
    pub fn plan(
        &self,
        base: &Scenario,
        progress: Option<ProgressFn>,
    ) -> Result<PlanFile, PlanError> {
        plan(&self.scenario(base), self.method, progress)
    }
}

/// The plan a strategy needs (the plan request lives here, beside the scenario and the methods,
/// while the strategy itself is what the real-time controller executes, in `vic-core`).
pub trait StrategyPlan {
    /// The plan this strategy plays at `latency` (on the grid of the scenario it is made on).
    fn plan_request(self, latency: Latency) -> PlanRequest;
}

impl StrategyPlan for Strategy {
    fn plan_request(self, latency: Latency) -> PlanRequest {
        PlanRequest {
            method: match self {
                Strategy::Stiffness | Strategy::Replan => Method::Sooc,
                Strategy::NaiveDelayed | Strategy::Predictor | Strategy::StiffnessPredictor => {
                    Method::Ilqg
                }
            },
            without_stiffness: !self.uses_stiffness(),
            delay: match self {
                Strategy::NaiveDelayed => latency,
                _ => Latency::ZERO,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scenario(overrides: &[&str]) -> Scenario {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        Scenario::load(&root.join("config/single_joint_delay.toml"), &overrides).unwrap()
    }

    #[test]
    fn each_strategy_asks_for_its_method_stiffness_and_delay() {
        let l = Latency::from_ms(200.0, 0.01).unwrap();
        let r = |s: Strategy| {
            let r = s.plan_request(l);
            (r.method, r.without_stiffness, r.delay.knots())
        };
        assert_eq!(r(Strategy::NaiveDelayed), (Method::Ilqg, true, 20));
        assert_eq!(r(Strategy::Predictor), (Method::Ilqg, true, 0));
        assert_eq!(r(Strategy::Stiffness), (Method::Sooc, false, 0));
        assert_eq!(r(Strategy::StiffnessPredictor), (Method::Ilqg, false, 0));
        assert_eq!(r(Strategy::Replan), (Method::Sooc, false, 0));
    }

    /// The edits reach the bounds, the warm start, the delay and the resolved table (that they
    /// equal the overrides of the same keys is checked in tests/strategy_plan.rs).
    #[test]
    fn the_edits_reach_every_place_the_keys_do() {
        let base = scenario(&[]);
        let (dof, nu) = (base.model.dof(), base.model.nu());
        assert!(base.initial_stiffness > 0.0 && base.task.delay_ms > 0.0);
        assert!(base.bounds.upper[dof..nu].iter().all(|&k| k > 0.0));
        let edited = Strategy::Predictor
            .plan_request(Latency::from_ms(200.0, base.task.dt).unwrap())
            .scenario(&base);
        assert!(edited.bounds.upper[dof..nu].iter().all(|&k| k == 0.0));
        assert!(edited.bounds.lower[dof..nu].iter().all(|&k| k == 0.0));
        assert_eq!(edited.bounds.upper[..dof], base.bounds.upper[..dof]);
        assert_eq!(edited.initial_stiffness, 0.0);
        assert_eq!((edited.task.delay_ms, edited.task.delay_steps()), (0.0, 0));
        let actuator = edited.resolved["actuator"].as_table().unwrap();
        for key in ["stiffness_min", "stiffness_max", "initial_stiffness"] {
            assert_eq!(actuator[key].as_float(), Some(0.0), "{key}");
        }
        assert_eq!(edited.resolved["task"]["delay_ms"].as_float(), Some(0.0));
        let naive = Strategy::NaiveDelayed
            .plan_request(Latency::from_ms(50.0, base.task.dt).unwrap())
            .scenario(&base);
        assert_eq!((naive.task.delay_ms, naive.task.delay_steps()), (50.0, 5));
        // The stiffness strategies keep the actuator as it is.
        let stiff = Strategy::Stiffness
            .plan_request(Latency::ZERO)
            .scenario(&base);
        assert_eq!(stiff.bounds.upper, base.bounds.upper);
        assert_eq!(stiff.initial_stiffness, base.initial_stiffness);
    }

    /// The predictor plays the plan of the naive law at 0 ms (the demo's reference row).
    #[test]
    fn the_predictor_plan_is_the_naive_plan_without_latency() {
        let l = Latency::from_ms(200.0, 0.01).unwrap();
        assert_eq!(
            Strategy::Predictor.plan_request(l),
            Strategy::NaiveDelayed.plan_request(Latency::ZERO)
        );
    }
}
