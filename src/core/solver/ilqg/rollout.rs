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
pub(super) fn rollout(
    problem: &Problem,
    traj: &mut Trajectory,
    policy: Option<Policy>,
    bounds: Option<&Bounds>,
    alpha: f64,
    limit: f64,
) -> Result<(), usize> {
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
        problem.dynamics.step(
            k,
            head[k].as_slice(),
            traj.u[k].as_slice(),
            tail[0].as_mut_slice(),
        );
        cost += problem
            .cost
            .running(k, head[k].as_slice(), traj.u[k].as_slice());
        if cost > limit || !tail[0].iter().all(|v| v.is_finite()) {
            return Err(k + 1);
        }
    }
    cost += problem.cost.terminal(traj.x[problem.horizon].as_slice());
    traj.cost = cost;
    if cost.is_finite() {
        Ok(())
    } else {
        Err(problem.horizon)
    }
}

/// Linearises the dynamics and differentiates the cost along `traj`. Knots are independent: when
/// the model says a linearisation is expensive
/// ([`Dynamics::parallel_linearization`](crate::core::dynamics::Dynamics::parallel_linearization)) they
/// are linearised in parallel, otherwise in order (thread hand-offs would cost more than they
/// save, and a sequential pass allocates nothing). Each knot's result is computed the same way
/// either way, so the solution does not depend on the thread count.
pub(super) fn linearize(problem: &Problem, traj: &mut Trajectory) {
    use rayon::prelude::*;
    let h = problem.horizon;
    let (xs, us) = (&traj.x, &traj.u);
    let pattern = !reads_in_place(problem.dynamics.nx(), problem.dynamics.nu());
    let knot = |k: usize,
                lin: &mut Linearization,
                sparse: &mut SparseLinearization,
                d: &mut CostDerivatives| {
        let (x, u) = (xs[k].as_slice(), us[k].as_slice());
        problem.dynamics.linearize(k, x, u, lin);
        if pattern {
            sparse.assign(lin);
        }
        problem.cost.running_derivatives(k, x, u, d);
    };
    if problem.dynamics.parallel_linearization() {
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
}
