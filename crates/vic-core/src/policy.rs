//! The one thing that is executed: a plan's commands, its nominal states and its feedback gains,
//! and the law that turns a seen state into a command (paper Eq. 9 and 13). The Monte Carlo, the
//! lockstep pair and the live central controller all call [`Policy::control_into`].

use crate::dynamics::Dynamics;
use crate::scalar::{MAX_NU, MAX_NX};
use crate::solver::Bounds;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Which state the feedback of a [`Policy`] acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Feedback {
    /// The commands as planned, no feedback at all (the paper's feedforward execution).
    #[serde(rename = "open-loop")]
    OpenLoop,
    /// `u = ū + L (x − x̄)` with the present state (Eq. 9).
    #[serde(rename = "feedback")]
    Full,
    /// `u_k = ū_k + L_{k−D} (x_{k−D} − x̄_{k−D})`: a controller that sees the state `D` steps late
    /// (Eq. 13 with a plan made for that delay; a naive delayed controller with one made without).
    #[serde(rename = "delayed-feedback")]
    Delayed { latency_steps: usize },
    /// The best a controller that sees the state `D` steps late can do without stiffness: it
    /// predicts the present state from the one it sees by running the noise-free model over the
    /// commands it applied since (a Smith predictor, [`predict_present`]) and feeds the present
    /// gain back on the prediction, `u_k = ū_k + L_k (x̂_k − x̄_k)`. Without noise the prediction is
    /// exact and the delay costs nothing (the paper's footnote 1); with noise its error grows with
    /// `D`. Execute an undelayed plan with it.
    #[serde(rename = "predictor")]
    Predicted { latency_steps: usize },
    /// Receding-horizon stiffness planning (the replanner of the `replan` module): every central
    /// period the controller predicts the present from the state seen `D` steps late and
    /// re-solves the open-loop plan of torque and stiffness from it. The law lives in the
    /// replanner (it changes the plan); a [`Policy`] alone plays its plan open loop under it.
    #[serde(rename = "replan")]
    Replan { latency_steps: usize },
}

impl Feedback {
    /// The knot whose state the controller sees at knot `k`, if any.
    pub fn seen_knot(self, k: usize) -> Option<usize> {
        match self {
            Feedback::OpenLoop => None,
            Feedback::Full => Some(k),
            Feedback::Delayed { latency_steps }
            | Feedback::Predicted { latency_steps }
            | Feedback::Replan { latency_steps } => k.checked_sub(latency_steps),
        }
    }
}

impl std::fmt::Display for Feedback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Feedback::OpenLoop => write!(f, "open loop"),
            Feedback::Full => write!(f, "feedback"),
            Feedback::Delayed { latency_steps } => {
                write!(f, "delayed feedback ({latency_steps} steps)")
            }
            Feedback::Predicted { latency_steps } => {
                write!(f, "predictor ({latency_steps} steps)")
            }
            Feedback::Replan { latency_steps } => write!(f, "replan ({latency_steps} steps)"),
        }
    }
}

/// How a central controller that sees the state `D` steps late commands the joint: the one list
/// of strategy names that `vic-planner --strategy`, `vic simulate --policy`, the lockstep pair, the
/// sweep and the demo share.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// Eq. 13: the gains of a plan made for the delay on the state seen `D` steps late, no
    /// stiffness (the paper's delayed feedback).
    NaiveDelayed,
    /// The best delayed feedback without stiffness: a Smith predictor across the latency
    /// ([`Feedback::Predicted`]) with the gains of an undelayed plan.
    Predictor,
    /// The open-loop plan of torque and stiffness (SOOC), no central feedback.
    Stiffness,
    /// The plan's torque and stiffness plus the predictor's feedback on top. (In JSON too it is
    /// called as on the command line.)
    #[serde(rename = "stiffness+predictor")]
    StiffnessPredictor,
    /// Receding-horizon stiffness planning: the SOOC plan re-solved every central period from
    /// the present predicted over the commands in flight ([`Feedback::Replan`]).
    Replan,
}

impl Strategy {
    pub const ALL: [Strategy; 5] = [
        Strategy::NaiveDelayed,
        Strategy::Predictor,
        Strategy::Stiffness,
        Strategy::StiffnessPredictor,
        Strategy::Replan,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Strategy::NaiveDelayed => "naive-delayed",
            Strategy::Predictor => "predictor",
            Strategy::Stiffness => "stiffness",
            Strategy::StiffnessPredictor => "stiffness+predictor",
            Strategy::Replan => "replan",
        }
    }

    /// What the strategy does, in plain words for a reader who has not met the names (the
    /// demo's legend and verdict).
    pub fn plain(self) -> &'static str {
        match self {
            Strategy::NaiveDelayed => "delayed feedback as planned for the latency, no stiffness",
            Strategy::Predictor => "delayed feedback on the predicted present, no stiffness",
            Strategy::Stiffness => "planned torque and stiffness, no feedback at all",
            Strategy::StiffnessPredictor => "planned stiffness plus the predictor's feedback",
            Strategy::Replan => "stiffness re-planned every period from the predicted present",
        }
    }

    /// The strategy called `name`, or an error that lists the names.
    pub fn from_name(name: &str) -> Result<Strategy, UnknownStrategy> {
        Strategy::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or_else(|| UnknownStrategy(name.to_string()))
    }

    /// How its plan is executed by a controller that sees the state `latency_steps` late.
    pub fn feedback(self, latency_steps: usize) -> Feedback {
        match self {
            Strategy::NaiveDelayed => Feedback::Delayed { latency_steps },
            Strategy::Predictor | Strategy::StiffnessPredictor => {
                Feedback::Predicted { latency_steps }
            }
            Strategy::Stiffness => Feedback::OpenLoop,
            Strategy::Replan => Feedback::Replan { latency_steps },
        }
    }

    /// Whether it commands stiffness: the feedback-only strategies send none, whatever the plan
    /// holds (feedback is all they have).
    pub fn uses_stiffness(self) -> bool {
        matches!(
            self,
            Strategy::Stiffness | Strategy::StiffnessPredictor | Strategy::Replan
        )
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A strategy name that is not one of [`Strategy::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown strategy \"{0}\" (one of naive-delayed, predictor, stiffness, stiffness+predictor, \
     replan)"
)]
pub struct UnknownStrategy(pub String);

impl std::str::FromStr for Strategy {
    type Err = UnknownStrategy;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Strategy::from_name(s)
    }
}

/// A state the controller has seen: the state at knot `knot`, fed back through the gain of knot
/// `gain` (the same knot, unless a live controller falls back to an older state).
#[derive(Debug, Clone, Copy)]
pub struct Seen<'a> {
    pub gain: usize,
    pub knot: usize,
    pub x: &'a [f64],
}

/// A plan ready to execute.
#[derive(Debug, Clone)]
pub struct Policy {
    /// Command acting at each step `0..N` (with a plan delay `d`, command `k − d`; the hold
    /// command before).
    pub acting: Vec<DVector<f64>>,
    /// Nominal states `x̄_0 ..= x̄_N`.
    pub nominal: Vec<DVector<f64>>,
    /// Gains `L_k` per step (m×n); zero for an open-loop plan.
    pub gains: Vec<DMatrix<f64>>,
    /// Delay the plan was made for [steps].
    pub plan_delay: usize,
    /// Control limits: every command is clamped into them.
    pub bounds: Bounds,
}

impl Policy {
    /// Number of control steps N.
    pub fn steps(&self) -> usize {
        self.acting.len()
    }

    /// Control dimension.
    pub fn nu(&self) -> usize {
        self.acting.first().map_or(0, |u| u.len())
    }

    /// State dimension.
    pub fn nx(&self) -> usize {
        self.nominal.first().map_or(0, |x| x.len())
    }

    /// The command at knot `k` (Eq. 9 / 13): `u = ū_k + L_j (x_l − x̄_l)` for the seen state
    /// (`j = seen.gain`, `l = seen.knot`), or `ū_k` with none; then clamped into the bounds.
    /// Allocates nothing.
    pub(crate) fn control_into(&self, k: usize, seen: Option<Seen<'_>>, u: &mut [f64]) {
        let nu = self.nu();
        u[..nu].copy_from_slice(self.acting[k].as_slice());
        if let Some(s) = seen.filter(|s| s.gain < self.gains.len()) {
            let gain = &self.gains[s.gain];
            let nominal = &self.nominal[s.knot];
            // L (x − x̄) summed column by column, then added: the order of a matrix-vector
            // product, so that every caller gets the same numbers to the last digit.
            let mut fb = [0.0; MAX_NU];
            for c in 0..gain.ncols() {
                let dx = s.x[c] - nominal[c];
                for r in 0..nu {
                    fb[r] = if c == 0 {
                        gain[(r, c)] * dx
                    } else {
                        gain[(r, c)] * dx + fb[r]
                    };
                }
            }
            for r in 0..nu {
                u[r] += fb[r];
            }
        }
        self.bounds.clamp(&mut u[..nu]);
    }
}

impl Policy {
    /// The command of knot `k` under `feedback` for a controller holding the state `x` of knot
    /// `seen` (or none yet): Eq. 9 / 13 on it, or for the predictor the gain of knot `k` on the
    /// present predicted from it over the commands `applied` since (`applied` yields the
    /// commands of knots `seen..k`). The Monte Carlo and the central controller both call this,
    /// so that offline, lockstep and live execute one law. A live controller whose state of
    /// `k − D` has not arrived passes an older one: the naive law then applies the gain of
    /// `k − D` to it (Eq. 13 with a stale state), the predictor simply predicts over more
    /// commands. `scratch` holds the prediction (`≥ nx`). Allocates nothing.
    #[allow(clippy::too_many_arguments)]
    pub fn command_into<'a>(
        &self,
        dynamics: &dyn Dynamics,
        k: usize,
        feedback: Feedback,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) {
        let seen = match (feedback, seen) {
            (Feedback::OpenLoop | Feedback::Replan { .. }, _) | (_, None) => None,
            (Feedback::Predicted { .. }, Some((l, x))) => {
                predict_present(dynamics, l, x, applied, scratch);
                Some(Seen {
                    gain: k,
                    knot: k,
                    x: &scratch[..x.len()],
                })
            }
            (Feedback::Full | Feedback::Delayed { .. }, Some((l, x))) => {
                let gain = feedback.seen_knot(k).unwrap_or(l);
                Some(Seen { gain, knot: l, x })
            }
        };
        self.control_into(k, seen, u);
    }
}

/// The present state `x̂_k` predicted from the state `x_seen` of knot `j = k − D`: the noise-free
/// step of `dynamics` applied over the commands `applied[j..k]` that acted since (a Smith
/// predictor). With `D = 0` it is `x_seen` itself. Allocates nothing (`n ≤ MAX_NX`).
pub(crate) fn predict_present<'a>(
    dynamics: &dyn Dynamics,
    seen_knot: usize,
    x_seen: &[f64],
    applied: impl IntoIterator<Item = &'a [f64]>,
    out: &mut [f64],
) {
    let n = x_seen.len();
    out[..n].copy_from_slice(x_seen);
    let mut next = [0.0; MAX_NX];
    for (j, u) in applied.into_iter().enumerate() {
        dynamics.step(seen_knot + j, &out[..n], u, &mut next[..n]);
        out[..n].copy_from_slice(&next[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::Strategy;

    #[test]
    fn a_strategy_has_one_name_on_the_command_line_and_in_json() {
        for s in Strategy::ALL {
            let json = serde_json::to_string(&s).unwrap();
            assert_eq!(json, format!("\"{}\"", s.name()));
            assert_eq!(serde_json::from_str::<Strategy>(&json).unwrap(), s);
            assert_eq!(Strategy::from_name(s.name()), Ok(s));
        }
    }
}
