//! Re-solves for the central controller's replanning, on the workspace of the previous solve:
//! over a horizon of the same length ([`SoocSolver::resolve_shifted`]) or over the rest of the
//! movement ([`SoocSolver::resolve_remaining`]).

use super::{SoocError, SoocProblem, SoocSolution, SoocSolver};
use crate::dynamics::Dynamics;

impl SoocSolver {
    /// Re-solves for a receding horizon: the previous solution shifted by `shift` knots (the last
    /// control repeated) warm-starts `problem`, whose initial state and reference are the new
    /// ones. The workspace is reused; the problem must have the previous one's size.
    pub fn resolve_shifted(
        &mut self,
        problem: &SoocProblem,
        shift: usize,
    ) -> Result<SoocSolution, SoocError> {
        self.check(problem)?;
        if !self.solved {
            return Err(SoocError::NoPreviousSolution);
        }
        let h = self.horizon;
        let s = shift.min(h.saturating_sub(1));
        self.u.rotate_left(s);
        for k in h - s..h {
            let (head, tail) = self.u.split_at_mut(k);
            tail[0].copy_from(&head[k - 1]);
        }
        self.run(problem, false)
    }

    /// Re-solves the rest of the movement `advanced` knots later: `problem` is the previous one
    /// from knot `advanced` on (`vic_plan::setup::Setup::remaining`: the same plant, the
    /// reference and the exogenous inputs from that knot, `advanced` knots fewer) from a new
    /// initial state, warm-started with the previous solution's tail. The workspace shrinks
    /// with the horizon (nothing is allocated; later calls continue from the shorter horizon).
    ///
    /// What it carries over besides the controls: the flow's derivatives at the previous
    /// solution (first, second and third). Where the new start is the previous plan's own mean
    /// at that knot (a re-solve that believes the plan), the rollout meets the previous end
    /// point bit for bit at every knot: the first expansion computes only what the covariance
    /// changes, and the exact Newton model needs no third-order flows for its first step.
    /// Wherever a point differs they are taken anew
    /// ([`crate::solver::sooc::MomentDynamics::expand_reusing_third`]), so a problem that
    /// is not the previous one's rest (another plant model) must go to [`SoocSolver::solve`]
    /// instead. The result is that of [`SoocSolver::solve`] from the same controls on a new
    /// workspace, to the bit.
    pub fn resolve_remaining(
        &mut self,
        problem: &SoocProblem,
        advanced: usize,
    ) -> Result<SoocSolution, SoocError> {
        if !self.solved {
            return Err(SoocError::NoPreviousSolution);
        }
        let remaining = self.horizon.saturating_sub(advanced);
        let got = (problem.dynamics.n(), problem.dynamics.nu(), problem.horizon);
        let want = (self.n, self.nu, remaining);
        if advanced == 0 || remaining == 0 || got != want {
            return Err(SoocError::SizeMismatch { got, want });
        }
        // Every check before the workspace changes: a refused call leaves it as it was.
        self.check_for(problem, remaining)?;
        self.drop_front(advanced);
        self.run(problem, true)
    }

    /// Fits the workspace to `problem`'s horizon for a solve from new controls: a shorter
    /// horizon drops knots from the front (nothing is allocated), a longer one takes a new
    /// workspace (the observer and the options stay).
    pub(super) fn fit(&mut self, problem: &SoocProblem) {
        let h = problem.horizon;
        if h < self.horizon {
            self.drop_front(self.horizon - h);
        } else if h > self.horizon {
            let observer = self.observer.take();
            *self = SoocSolver::new(problem.dynamics, h, self.options.clone());
            self.observer = observer;
        }
    }

    /// Drops the first `by` knots of every per-knot buffer: knot k becomes knot k − by.
    fn drop_front(&mut self, by: usize) {
        fn advance<T>(v: &mut Vec<T>, by: usize) {
            v.drain(..by);
        }
        self.horizon -= by;
        advance(&mut self.z, by);
        advance(&mut self.u, by);
        advance(&mut self.cand_z, by);
        advance(&mut self.cand_u, by);
        advance(&mut self.expansions, by);
        advance(&mut self.curvatures, by);
        advance(&mut self.derivs, by);
        advance(&mut self.lam, by);
        advance(&mut self.grad, by);
        advance(&mut self.ff, by);
        advance(&mut self.gains, by);
        advance(&mut self.hess_diag, by);
    }
}
