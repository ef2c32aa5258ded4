//! Rolling a trajectory out and linearising along it.

use super::backward::reads_in_place;
use super::*;

/// A policy to roll out: the nominal it was made around, the feedforward steps and the gains.
pub(super) type Policy<'a> = (&'a Trajectory, &'a [DVector<f64>], &'a [DMatrix<f64>]);

/// Rolls `traj` forward from `traj.x[0]`. With a policy `(nominal, l, L)` the controls are
/// `clamp(ū + α l + L (x − x̄))`; without, `traj.u` is used as it is. On divergence (a non-finite
/// state or cost) returns the step at which it happened; also once the running costs so far
/// exceed `limit` (pass `∞` for a full rollout; a finite limit only for a cost that is never
/// negative, whose total can then only be larger).
///
/// With `fused` (and a model linearised in order, see [`linearize`]) the knots are linearised on
/// the way ([`Dynamics::linearize_with`] with the step): a complete rollout leaves `traj` as [`linearize`]
/// would, without evaluating the drift twice per knot. The callers fuse the rollouts that are
/// accepted unless the line search backtracks: the first guess and the full step.
pub(super) fn rollout(
    problem: &Problem,
    traj: &mut Trajectory,
    policy: Option<Policy>,
    bounds: Option<&Bounds>,
    alpha: f64,
    limit: f64,
    fused: bool,
) -> Result<(), usize> {
    let fused = fused && !traj.parallel;
    let pattern = fused && !reads_in_place(problem.dynamics.nx(), problem.dynamics.nu());
    traj.linearized = false;
    let mut cost = 0.0;
    for k in 0..problem.horizon {
        if let Some((nom, ff, gains)) = policy {
            let (xs, us) = (&mut traj.x, &mut traj.u);
            let uk = &mut us[k];
            uk.copy_from(&nom.u[k]);
            uk.axpy(alpha, &ff[k], 1.0);
            // u += L (x − x̄), without a temporary.
            for r in 0..uk.len() {
                let mut acc = 0.0;
                for c in 0..xs[k].len() {
                    acc += gains[k][(r, c)] * (xs[k][c] - nom.x[k][c]);
                }
                uk[r] += acc;
            }
            if let Some(b) = bounds {
                b.clamp(uk.as_mut_slice());
            }
        }
        let (head, tail) = traj.x.split_at_mut(k + 1);
        let (x, u, next) = (
            head[k].as_slice(),
            traj.u[k].as_slice(),
            tail[0].as_mut_slice(),
        );
        if fused {
            // After the trajectory's first linearisation every knot holds one of this model's
            // (a rollout stopped early leaves new ones in its first knots): the model and the
            // cost then write only what can change.
            let (lin, d) = (&mut traj.lin[k], &mut traj.derivs[k]);
            let refill = traj.relinearizable;
            problem
                .dynamics
                .linearize_with(k, x, u, Some(next), refill, lin);
            if traj.differentiated {
                problem.cost.running_derivatives_again(k, x, u, d);
            } else {
                problem.cost.running_derivatives(k, x, u, d);
            }
            if pattern {
                let support = traj.supported.then_some(&traj.support);
                traj.sparse[k].assign(lin, support);
            }
        } else {
            problem.dynamics.step(k, x, u, next);
        }
        let running = problem.cost.running(k, x, u);
        traj.running[k] = running;
        cost += running;
        if cost > limit || !tail[0].iter().all(|v| v.is_finite()) {
            return Err(k + 1);
        }
    }
    let end = traj.x[problem.horizon].as_slice();
    traj.terminal = problem.cost.terminal(end);
    cost += traj.terminal;
    traj.cost = cost;
    if !cost.is_finite() {
        return Err(problem.horizon);
    }
    if fused {
        let h = problem.horizon;
        problem.cost.terminal_derivatives(end, &mut traj.derivs[h]);
        traj.linearized = true;
        traj.relinearizable = true;
        traj.differentiated = true;
    }
    Ok(())
}

/// Linearises the dynamics and differentiates the cost along `traj`. Knots are independent: when
/// the model says a linearisation is expensive
/// ([`Structure::parallel_linearization`](crate::dynamics::Structure)) they
/// are linearised in parallel, otherwise in order (thread hand-offs would cost more than they
/// save, and a sequential pass allocates nothing). Each knot's result is computed the same way
/// either way, so the solution does not depend on the thread count.
pub(super) fn linearize(problem: &Problem, traj: &mut Trajectory) {
    use rayon::prelude::*;
    let h = problem.horizon;
    let (xs, us) = (&traj.x, &traj.u);
    let pattern = !reads_in_place(problem.dynamics.nx(), problem.dynamics.nu());
    let (again, differentiated) = (traj.relinearizable, traj.differentiated);
    let support = traj.supported.then_some(&traj.support);
    let knot = |k: usize,
                lin: &mut Linearization,
                sparse: &mut SparseLinearization,
                d: &mut CostDerivatives| {
        let (x, u) = (xs[k].as_slice(), us[k].as_slice());
        if again {
            problem.dynamics.linearize_with(k, x, u, None, true, lin);
        } else {
            problem.dynamics.linearize(k, x, u, lin);
        }
        if pattern {
            sparse.assign(lin, support);
        }
        if differentiated {
            problem.cost.running_derivatives_again(k, x, u, d);
        } else {
            problem.cost.running_derivatives(k, x, u, d);
        }
    };
    if traj.parallel {
        traj.lin[..h]
            .par_iter_mut()
            .zip(traj.sparse[..h].par_iter_mut())
            .zip(traj.derivs[..h].par_iter_mut())
            .enumerate()
            .with_min_len(8)
            .for_each(|(k, ((lin, sparse), d))| knot(k, lin, sparse, d));
    } else {
        for (k, ((lin, sparse), d)) in traj.lin[..h]
            .iter_mut()
            .zip(traj.sparse[..h].iter_mut())
            .zip(traj.derivs[..h].iter_mut())
            .enumerate()
        {
            knot(k, lin, sparse, d);
        }
    }
    problem
        .cost
        .terminal_derivatives(xs[h].as_slice(), &mut traj.derivs[h]);
    traj.linearized = true;
    traj.relinearizable = true;
    traj.differentiated = true;
}

impl Trajectory {
    /// A trajectory for `problem`'s sizes with room for its plant's nonzeros
    /// ([`Trajectory::make_room`]): its first solve allocates nothing more.
    pub(super) fn with_room(problem: &Problem, horizon: usize) -> Self {
        let d = problem.dynamics;
        let (nx, nu) = (d.nx(), d.nu());
        let mut traj = Trajectory::new(nx, nu, d.nw(), horizon);
        let structure = d.structure(Some(&mut traj.support));
        traj.supported = structure.supported && traj.support.fits(nx, nu);
        traj.parallel = structure.parallel_linearization;
        traj.make_room(nx, nu);
        traj
    }

    /// Room in `sparse` for every nonzero the plant's support allows (every entry when it
    /// declares none), where the backward pass reads the patterns
    /// ([`SparseLinearization::make_room`]).
    pub(super) fn make_room(&mut self, nx: usize, nu: usize) {
        if !reads_in_place(nx, nu) {
            let support = self.supported.then_some(&self.support);
            for sp in &mut self.sparse {
                sp.make_room(support);
            }
        }
    }
}

/// [`linearize`] unless a fused rollout already did.
pub(super) fn ensure_linearized(problem: &Problem, traj: &mut Trajectory) {
    if !traj.linearized {
        linearize(problem, traj);
    }
}
