//! The iteration's decisions: convergence tests, the regularisation schedule and the
//! backtracking line search on the merit.

use super::*;

impl Ilqg {
    /// Rolls the candidate out from `x0` under the nominal plan, its feedforward scaled by
    /// `alpha` and its gains (clamped to the bounds); false if the rollout diverged or its cost
    /// passed `limit` (see [`rollout`]); `fused` linearises it on the way.
    pub(super) fn roll_candidate(
        &mut self,
        problem: &Problem,
        alpha: f64,
        limit: f64,
        fused: bool,
    ) -> bool {
        self.candidate.x[0].copy_from_slice(&problem.x0);
        let policy = Some((&self.nominal, &self.ff[..], &self.gains[..]));
        rollout(
            problem,
            &mut self.candidate,
            policy,
            Some(&problem.bounds),
            alpha,
            limit,
            fused,
        )
        .is_ok()
    }

    /// The largest feedforward step relative to its control, `max |l_k| / (|ū_k| + 1)`: zero at
    /// a first-order optimum (projected onto the limits, since clamped components get `l = 0`).
    pub(super) fn feedforward_gradient(&self) -> f64 {
        self.ff
            .iter()
            .zip(&self.nominal.u)
            .flat_map(|(l, u)| {
                l.iter()
                    .zip(u.iter())
                    .map(|(l, u)| l.abs() / (u.abs() + 1.0))
            })
            .fold(0.0, f64::max)
    }

    /// After an accepted step of length α: a long step means the local model was trusted, so μ
    /// falls (Tassa's schedule); only a short step helping means the quadratic model overshoots
    /// (typically in the stiffness, whose effect is bilinear), and the next Newton step is damped.
    pub(super) fn update_regularization(&self, reg: &mut Regularization, alpha: f64) {
        if alpha >= self.options.shrink_below_step || !self.options.damp_short_steps {
            reg.decrease(&self.options);
        } else {
            // No limit check here: a rejected step checks it.
            let _ = reg.increase(&self.options);
        }
    }

    /// Backtracking line search on the merit: rolls the policy `ū + α l + L (x − x̄)` out into
    /// `candidate` for decreasing α and accepts the first that improves the merit by a positive
    /// fraction of the predicted improvement `−α (dv1 + α dv2)` (Armijo-like). When the merit is
    /// the cost and the cost is never negative, a candidate's rollout stops as soon as its cost
    /// passes the nominal's: it would be rejected anyway, so the steps taken are the same, and
    /// the long steps the early iterations reject cost a fraction of a rollout.
    ///
    /// The trial of step length `fuse` is linearised on the way ([`rollout`]): the caller asks
    /// for the length it expects to be accepted, since a rejected trial's Jacobians are wasted
    /// (they cost about two rollouts of the arm).
    pub(super) fn line_search(
        &mut self,
        problem: &Problem,
        pass: &BackwardPass,
        merit_now: f64,
        stochastic: bool,
        fuse: Option<f64>,
    ) -> Option<Step> {
        let limit = if !stochastic && problem.cost.nonnegative() {
            merit_now
        } else {
            f64::INFINITY
        };
        for alpha in ALPHAS {
            if !self.roll_candidate(problem, alpha, limit, fuse == Some(alpha)) {
                continue;
            }
            let merit_new = self.merit(problem, stochastic, true);
            let predicted = -alpha * (pass.dv1 + alpha * pass.dv2);
            let actual = merit_now - merit_new;
            let ratio = if predicted > 0.0 {
                actual / predicted
            } else {
                actual.signum()
            };
            if actual > 0.0 && ratio > 1e-4 {
                return Some(Step {
                    alpha,
                    before: merit_now,
                    after: merit_new,
                });
            }
        }
        None
    }

    /// The line-search merit of the nominal (or the candidate): its cost plus the noise cost
    /// `Σ_k ½ Σ_i c_iᵀ S_{k+1} c_i` with the value Hessians `S` of the last backward pass frozen.
    /// Its gradient is exactly the noise part of the backward pass's `Q_x`, `Q_u` (the `Cxᵀ S c`,
    /// `Cuᵀ S c` terms), so an ILQG step is a descent direction for it. The fully propagated
    /// expected cost ([`crate::solver::moments::expected_cost`]) also moves with the linearisation itself, which
    /// ILQG's first-order step does not see (Todorov & Li 2005), and makes a poor merit.
    pub(super) fn merit(&mut self, problem: &Problem, stochastic: bool, candidate: bool) -> f64 {
        let traj = if candidate {
            &self.candidate
        } else {
            &self.nominal
        };
        if !stochastic {
            return traj.cost;
        }
        let g = &mut self.noise_scratch;
        // The rows where the noise can act (the delayed plant's: the plant's), the only ones
        // of the value Hessians kept (see `backward`).
        let rows = traj.noise_rows();
        let (first, len) = (rows.start, rows.len());
        let mut noise = 0.0;
        for k in 0..problem.horizon {
            problem
                .dynamics
                .noise_gain(k, traj.x[k].as_slice(), traj.u[k].as_slice(), g);
            let s = &self.value_hessians[k];
            for i in 0..g.ncols() {
                let c = g.view((first, i), (len, 1));
                let mut q = 0.0;
                for a in 0..len {
                    // A zero entry would add exactly 0, so it is skipped.
                    if c[a] != 0.0 {
                        q += c[a] * s.view((first, first + a), (len, 1)).dot(&c);
                    }
                }
                noise += 0.5 * q;
            }
        }
        traj.cost + noise
    }
}
