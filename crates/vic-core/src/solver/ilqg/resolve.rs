//! Re-solves from the previous solution shifted (receding-horizon replanning), reusing the
//! workspace.

use super::{Ilqg, IlqgError, Solution};
use crate::dense::zero;
use crate::solver::Problem;
use nalgebra::DVector;
use std::time::Instant;

impl Ilqg {
    /// Whether the workspace holds a solution that [`Ilqg::resolve_shifted`] can shift.
    pub(crate) fn has_solution(&self) -> bool {
        self.solved
    }

    /// Re-solves after the plan has advanced `shift` knots (receding-horizon replanning): the
    /// previous solution is shifted, its last knot repeated, and rolled out from the new
    /// `problem.x0` under its own feedback gains, `u_k = ū_{k+s} + L_{k+s} (x_k − x̄_{k+s})`
    /// (the closed-loop policy of Eq. 9 keeps an unstable plant near the old nominal where an
    /// open-loop replay would drift). The workspace is reused; nothing is allocated but the
    /// returned copy of the solution.
    pub fn resolve_shifted(
        &mut self,
        problem: &Problem,
        shift: usize,
    ) -> Result<Solution, IlqgError> {
        self.resolve_shifted_with_tail(problem, shift, &[])
    }

    /// [`Ilqg::resolve_shifted`] with the shifted plan's last `tail.len()` controls replaced by
    /// `tail` (clamped to the limits; they run open loop in the first rollout), for a plan
    /// whose last controls were free: the delayed plant's last `d` commands act after the
    /// horizon, so the plan leaves them at their control cost's minimum, and shifted they act
    /// within it (the `delay` module's planner replaces them with its undelayed guess).
    pub fn resolve_shifted_with_tail(
        &mut self,
        problem: &Problem,
        shift: usize,
        tail: &[DVector<f64>],
    ) -> Result<Solution, IlqgError> {
        let start = Instant::now();
        self.check_size(problem)?;
        if !self.solved {
            return Err(IlqgError::NoPreviousSolution);
        }
        let horizon = self.dims.3;
        let nu = self.dims.1;
        if tail.len() > horizon {
            return Err(IlqgError::InitialGuessLength {
                got: tail.len(),
                want: horizon,
            });
        }
        let from = horizon - tail.len();
        if let Some((i, u)) = tail.iter().enumerate().find(|(_, u)| u.len() != nu) {
            return Err(IlqgError::ControlSize {
                knot: from + i,
                got: u.len(),
                want: nu,
            });
        }
        let s = shift.min(horizon);
        shift_knots(&mut self.nominal.u, s);
        shift_knots(&mut self.gains, s);
        shift_knots(&mut self.nominal.x, s);
        for (k, u) in (from..horizon).zip(tail) {
            self.nominal.u[k].copy_from(u);
            problem.bounds.clamp(self.nominal.u[k].as_mut_slice());
            zero(&mut self.gains[k]);
        }
        self.nominal.linearized = false;
        self.nominal.start_solve(problem);
        self.candidate.start_solve(problem);
        for l in &mut self.ff {
            zero(l);
        }
        self.solved = false;
        if self.roll_candidate(problem, 0.0, f64::INFINITY, true) {
            std::mem::swap(&mut self.nominal, &mut self.candidate);
        } else {
            // The old gains do not hold the plant from here: replay the shifted controls.
            self.replay(problem)?;
        }
        let mut out = Solution::empty();
        self.iterate(problem, start, &mut out);
        Ok(out)
    }
}

/// Moves every knot `s` places earlier and repeats the last knot into the `s` freed places
/// (in place: no allocation).
fn shift_knots<T: Clone>(knots: &mut [T], s: usize) {
    let n = knots.len();
    if s == 0 || n == 0 {
        return;
    }
    let s = s.min(n - 1);
    knots.rotate_left(s);
    let (head, tail) = knots.split_at_mut(n - s);
    for t in tail {
        t.clone_from(&head[n - s - 1]);
    }
}
