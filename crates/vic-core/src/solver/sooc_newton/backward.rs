//! The backward pass of the stagewise Newton step: per knot from the last, the Q-function
//! (with the costate-weighted curvature of the moment step for Newton), the box-limited stage
//! QP (Tassa, Mansard & Todorov 2014), the gains and the value update.

use super::SoocSolver;
use crate::dense::{TransposedProduct, multiply, symmetrize, zero};
use crate::solver::Bounds;
use crate::solver::boxqp::{MAX_QP, QpSolution, QpStatus, SmallCholesky, solve_box_qp};
use nalgebra::{DMatrix, DVector, SMatrix};
use serde::{Deserialize, Serialize};

/// The treatment of an indefinite Newton model (far from an optimum, or near a saddle).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Indefinite {
    /// Raise the Levenberg–Marquardt μ, for every stage, until every stage QP is convex.
    #[default]
    Regularize,
    /// Convexify only the indefinite stages: their `Q_uu` by its absolute value (the
    /// saddle-free Newton step, stage by stage; see the backward pass), μ raised only when a
    /// step fails.
    SaddleFree,
}

/// The smallest eigenvalue a convexified stage `Q_uu` keeps, relative to the controls'
/// Gauss–Newton curvature (see [`convexify`]).
const EIGEN_FLOOR: f64 = 0.1;

/// The costate-weighted curvature `H` of the moment step at one knot
/// ([`crate::solver::sooc::MomentExpansion::curvature`]): computed once per Newton model,
/// for every knot in parallel, and read by every backward pass on that model (each retry at a
/// higher μ) and by [`SoocSolver::hessian_diagonal_pass`].
pub(super) struct Curvature {
    pub(super) hzz: DMatrix<f64>,
    pub(super) huz: DMatrix<f64>,
    pub(super) huu: DMatrix<f64>,
}

impl Curvature {
    pub(super) fn new(nz: usize, m: usize) -> Self {
        Curvature {
            hzz: DMatrix::zeros(nz, nz),
            huz: DMatrix::zeros(m, nz),
            huu: DMatrix::zeros(m, m),
        }
    }
}

/// Scratch of the backward pass.
pub(super) struct Backward {
    v: DMatrix<f64>,
    vv: DVector<f64>,
    va: DMatrix<f64>,
    vb: DMatrix<f64>,
    qzz: DMatrix<f64>,
    quz: DMatrix<f64>,
    quu: DMatrix<f64>,
    qz: DVector<f64>,
    qu: DVector<f64>,
    kt_quu: DMatrix<f64>,
    t_mz: DMatrix<f64>,
    /// The open-loop second derivative of the cost-to-go in `z` (every later control held):
    /// `S_k = ℓ_zz + H_zz + Aᵀ S_{k+1} A`, for the diagonal of `∇²J`.
    s: DMatrix<f64>,
    sa: DMatrix<f64>,
    sb: DMatrix<f64>,
    /// The products `aᵀ b` (nalgebra's `gemm_tr` to the bit, faster).
    tp: TransposedProduct,
}

impl Backward {
    pub(super) fn new(nz: usize, m: usize) -> Self {
        let zm = |r, c| DMatrix::zeros(r, c);
        Backward {
            v: zm(nz, nz),
            vv: DVector::zeros(nz),
            va: zm(nz, nz),
            vb: zm(nz, m),
            qzz: zm(nz, nz),
            quz: zm(m, nz),
            quu: zm(m, m),
            qz: DVector::zeros(nz),
            qu: DVector::zeros(m),
            kt_quu: zm(nz, m),
            t_mz: zm(m, nz),
            s: zm(nz, nz),
            sa: zm(nz, nz),
            sb: zm(nz, m),
            tp: TransposedProduct::new(nz, nz),
        }
    }

    /// `V = Q_zz + Kᵀ Q_uu K + Kᵀ Q_uz + Q_uzᵀ K`, `v = Q_z + Kᵀ Q_uu k + Kᵀ Q_u + Q_uzᵀ k`
    /// (symmetrised), and the stage's predicted decrease terms `(kᵀ Q_u, ½ kᵀ Q_uu k)` with the
    /// unregularised model.
    fn value_update(&mut self, ff: &DVector<f64>, gain: &DMatrix<f64>) -> (f64, f64) {
        let m = ff.len();
        let mut quu_k = 0.0;
        for i in 0..m {
            for j in 0..m {
                quu_k += ff[i] * self.quu[(i, j)] * ff[j];
            }
        }
        let dv = (ff.dot(&self.qu), 0.5 * quu_k);
        self.tp.apply(&mut self.kt_quu, gain, &self.quu, false);
        self.t_mz.copy_from(&self.quz);
        multiply(&mut self.t_mz, &self.quu, gain, true);
        self.v.copy_from(&self.qzz);
        self.tp.apply(&mut self.v, gain, &self.t_mz, true);
        self.tp.apply(&mut self.v, &self.quz, gain, true);
        self.vv.copy_from(&self.qz);
        self.vv.gemv(1.0, &self.kt_quu, ff, 1.0);
        self.vv.gemv_tr(1.0, gain, &self.qu, 1.0);
        self.vv.gemv_tr(1.0, &self.quz, ff, 1.0);
        symmetrize(&mut self.v);
        dv
    }
}

impl SoocSolver {
    /// The Riccati recursion of the Newton step with box-limited stage QPs; the predicted
    /// decrease terms `(Σ kᵀ Q_u, Σ ½ kᵀ Q_uu k)` and how many stages were convexified, or
    /// `None` if some stage QP is not convex at this μ. With `convexify_stages` (the
    /// [`Indefinite::SaddleFree`] treatment of a Newton model) a stage whose `Q_uu` is not
    /// positive definite is convexified ([`convexify`]) instead of failing the pass.
    pub(super) fn backward(
        &mut self,
        bounds: &Bounds,
        mu: f64,
        newton: bool,
        convexify_stages: bool,
    ) -> Option<Backstep> {
        let h = self.horizon;
        self.bw.v.copy_from(&self.derivs[h].lxx);
        self.bw.vv.copy_from(&self.derivs[h].lx);
        let mut step = Backstep::default();
        for k in (0..h).rev() {
            self.q_function(k, newton);
            if self.stage_policy(k, bounds, mu, newton, convexify_stages)? {
                step.convexified += 1;
            }
            let (d1, d2) = self.bw.value_update(&self.ff[k], &self.gains[k]);
            step.dv1 += d1;
            step.dv2 += d2;
        }
        Some(step)
    }

    /// The diagonal of the exact `∇²J` into `hess_diag`: per knot from the last,
    /// `∂²J/∂u_{k,j}²` with every other control held, `ℓ_uu + H_uu + Bᵀ S_{k+1} B`, and
    /// `S_k = ℓ_zz + H_zz + Aᵀ S_{k+1} A` (`H` the costate-weighted curvature of the moment step;
    /// needs the Newton model at the current controls: its curvature `H` in `curvatures`). A
    /// pass of its own, run only when the convergence test needs it.
    pub(super) fn hessian_diagonal_pass(&mut self) {
        let h = self.horizon;
        self.bw.s.copy_from(&self.derivs[h].lxx);
        for k in (0..h).rev() {
            self.open_loop_diagonal(k);
        }
    }

    /// One knot of [`Self::hessian_diagonal_pass`].
    fn open_loop_diagonal(&mut self, k: usize) {
        let bw = &mut self.bw;
        let e = &self.expansions[k];
        let c = &self.curvatures[k];
        let d = &self.derivs[k];
        multiply(&mut bw.sb, &bw.s, &e.b, false);
        let diag = &mut self.hess_diag[k];
        for j in 0..diag.len() {
            diag[j] = d.luu[(j, j)] + c.huu[(j, j)] + e.b.column(j).dot(&bw.sb.column(j));
        }
        multiply(&mut bw.sa, &bw.s, &e.a, false);
        bw.s.copy_from(&d.lxx);
        bw.s += &c.hzz;
        bw.tp.apply(&mut bw.s, &e.a, &bw.sa, true);
    }

    /// `Q` at knot `k` from the value `(V, v)` of knot `k + 1`: the Gauss–Newton terms plus, for
    /// Newton, the costate-weighted curvature of the moment step (`curvatures[k]`).
    fn q_function(&mut self, k: usize, newton: bool) {
        let bw = &mut self.bw;
        let e = &self.expansions[k];
        let c = &self.curvatures[k];
        let d = &self.derivs[k];
        multiply(&mut bw.va, &bw.v, &e.a, false);
        multiply(&mut bw.vb, &bw.v, &e.b, false);
        bw.qzz.copy_from(&d.lxx);
        if newton {
            bw.qzz += &c.hzz;
        }
        bw.tp.apply(&mut bw.qzz, &e.a, &bw.va, true);
        bw.quz.copy_from(&d.lux);
        if newton {
            bw.quz += &c.huz;
        }
        bw.tp.apply(&mut bw.quz, &e.b, &bw.va, true);
        bw.quu.copy_from(&d.luu);
        if newton {
            bw.quu += &c.huu;
        }
        bw.tp.apply(&mut bw.quu, &e.b, &bw.vb, true);
        bw.qz.copy_from(&d.lx);
        bw.qz.gemv_tr(1.0, &e.a, &bw.vv, 1.0);
        bw.qu.copy_from(&d.lu);
        bw.qu.gemv_tr(1.0, &e.b, &bw.vv, 1.0);
    }

    /// The stage QP on the regularised `Q_uu` within the box around `u_k` into `ff[k]`, and the
    /// gains: free rows `−(Q_uu,ff)⁻¹ Q_uz,f`, clamped rows 0. `None` when not convex (and not
    /// to be convexified); `Some(true)` when `Q_uu` was convexified.
    fn stage_policy(
        &mut self,
        k: usize,
        bounds: &Bounds,
        mu: f64,
        newton: bool,
        convexify_stage: bool,
    ) -> Option<bool> {
        let m = self.nu;
        let d = &self.derivs[k];
        let mut lo = [0.0; MAX_QP];
        let mut hi = [0.0; MAX_QP];
        let mut reg = [0.0; MAX_QP];
        let mut curvature = [0.0; MAX_QP];
        let bw = &self.bw;
        for j in 0..m {
            lo[j] = bounds.lower[j] - self.u[k][j];
            hi[j] = bounds.upper[j] - self.u[k][j];
            // μ scales the control's Gauss–Newton curvature `ℓ_uu + Bᵀ V B` (the diagonal of
            // Q_uu without the costate term), not its own cost curvature `ℓ_uu` alone: with
            // w_st = 1e-4 the stiffness's ℓ_uu is ~1e-4 of what a unit of stiffness does to
            // the expected cost through the covariance, so a μ relative to ℓ_uu could not
            // convexify an indefinite Newton model before μ reached its limit, and the solver
            // would fall back to Gauss–Newton steps that crawl (the VSA plans stall that way).
            let costate_term = if newton {
                self.curvatures[k].huu[(j, j)]
            } else {
                0.0
            };
            let gauss_newton = (bw.quu[(j, j)] - costate_term).abs();
            curvature[j] = gauss_newton.max(d.luu[(j, j)].abs()).max(1e-12);
            reg[j] = mu * curvature[j];
        }
        let mut convexified = false;
        let mut factor = SmallCholesky::EMPTY;
        loop {
            let quu = &self.bw.quu;
            let hq = |i: usize, j: usize| {
                0.5 * (quu[(i, j)] + quu[(j, i)]) + if i == j { reg[i] } else { 0.0 }
            };
            let qp = solve_box_qp(
                hq,
                self.bw.qu.as_slice(),
                &lo[..m],
                &hi[..m],
                self.ff[k].as_slice(),
                &mut factor,
            );
            if qp.status == QpStatus::NotPositiveDefinite {
                if !convexify_stage || convexified {
                    return None;
                }
                convexify(&mut self.bw.quu, &curvature[..m], &reg[..m]);
                convexified = true;
                continue;
            }
            self.ff[k].copy_from_slice(&qp.x[..m]);
            feedback_gains(&qp, &factor, &self.bw.quz, &mut self.gains[k])?;
            return Some(convexified);
        }
    }
}

/// What a backward pass predicts: the decrease terms `(Σ kᵀ Q_u, Σ ½ kᵀ Q_uu k)` and how many
/// stage `Q_uu` were convexified (0: the model is the regularised Newton one throughout).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Backstep {
    pub(super) dv1: f64,
    pub(super) dv2: f64,
    pub(super) convexified: usize,
}

/// Replaces an indefinite stage `Q_uu` by its absolute value, `|Q_uu + R|` with `R` the
/// regularisation, each eigenvalue `λ` by `max(|λ|, EIGEN_FLOOR)`, in the coordinates in which
/// each control's Gauss–Newton curvature `c_j` is 1 (so the floor and the eigenvectors do not
/// depend on units); then `R` is taken off again so that the value update sees the stage cost
/// the step minimises.
///
/// Why: regularising with one μ for the whole horizon damps every stage because a few are
/// indefinite. Adding `½ δuᵀ (|Q| − Q) δu`, positive semidefinite, to one stage's model keeps the
/// others' Newton steps; the modified model is convex in the controls, so its minimiser is a
/// descent direction of `J` (the saddle-free Newton step of Dauphin et al. 2014, stage by stage),
/// and along negative curvature it moves by `|g / λ|` instead of stopping. It reaches the same
/// optima in fewer steps where few stages are indefinite (the divergent arm, the single joint),
/// in more on the torque-only arm; on the light VSA arm (B/10) it is what converges at all,
/// where one μ for every stage still creeps far above the optimum after thousands of steps
/// (docs/BENCHMARKS.md, "Every scenario", gives the light VSA arm's SOOC plan).
fn convexify(quu: &mut DMatrix<f64>, curvature: &[f64], reg: &[f64]) {
    let m = curvature.len();
    let s: [f64; MAX_QP] = std::array::from_fn(|j| {
        if j < m {
            1.0 / curvature[j].sqrt()
        } else {
            1.0
        }
    });
    // Padded with the identity to the fixed size: no allocation, and the padding's eigenvalues
    // (1) are kept as they are.
    let mut scaled = SMatrix::<f64, MAX_QP, MAX_QP>::identity();
    for i in 0..m {
        for j in 0..m {
            let h = 0.5 * (quu[(i, j)] + quu[(j, i)]) + if i == j { reg[i] } else { 0.0 };
            scaled[(i, j)] = s[i] * h * s[j];
        }
    }
    let eigen = scaled.symmetric_eigen();
    let v = &eigen.eigenvectors;
    for i in 0..m {
        for j in 0..m {
            let mut h = 0.0;
            for (l, lambda) in eigen.eigenvalues.iter().enumerate() {
                h += v[(i, l)] * lambda.abs().max(EIGEN_FLOOR) * v[(j, l)];
            }
            quu[(i, j)] = h / (s[i] * s[j]) - if i == j { reg[i] } else { 0.0 };
        }
    }
}

/// `K` with free rows `−(Q_uu,ff)⁻¹ Q_uz,f` (the QP's factor of the free block) and clamped
/// rows 0; `None` if the free block has no factor.
fn feedback_gains(
    qp: &QpSolution,
    factor: &SmallCholesky,
    quz: &DMatrix<f64>,
    gain: &mut DMatrix<f64>,
) -> Option<()> {
    let (m, nz) = gain.shape();
    zero(gain);
    let mut free = [0usize; MAX_QP];
    let mut nf = 0;
    for j in 0..m {
        if qp.free[j] {
            free[nf] = j;
            nf += 1;
        }
    }
    if nf == 0 {
        return Some(());
    }
    if !qp.factored {
        return None;
    }
    let mut col = [0.0; MAX_QP];
    for c in 0..nz {
        for (i, &j) in free[..nf].iter().enumerate() {
            col[i] = -quz[(j, c)];
        }
        factor.solve(&mut col[..nf]);
        for (i, &j) in free[..nf].iter().enumerate() {
            gain[(j, c)] = col[i];
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `S (Q + R) S` with `S = diag(1/√c)`: the matrix [`convexify`] works on.
    fn scaled(q: &DMatrix<f64>, c: &[f64], reg: &[f64]) -> DMatrix<f64> {
        DMatrix::from_fn(c.len(), c.len(), |i, j| {
            (q[(i, j)] + if i == j { reg[i] } else { 0.0 }) / (c[i] * c[j]).sqrt()
        })
    }

    #[test]
    fn convexify_takes_the_absolute_value_in_the_scaled_coordinates() {
        // Units far apart (a torque and a stiffness), indefinite, every |λ| above the floor.
        let c: [f64; 3] = [4e4, 1e-4, 2.0];
        let reg = [0.5, 1e-6, 0.0];
        let a = DMatrix::from_row_slice(3, 3, &[3.0, -2.0, 0.5, -2.0, -1.0, 0.3, 0.5, 0.3, 0.7]);
        let s = DMatrix::from_diagonal(&DVector::from_iterator(3, c.iter().map(|c| c.sqrt())));
        let mut q = &s * &a * &s;
        for j in 0..3 {
            q[(j, j)] -= reg[j];
        }
        let before = scaled(&q, &c, &reg);
        let eig = before.clone().symmetric_eigen();
        assert!(eig.eigenvalues.min() < 0.0, "the case is indefinite");
        assert!(eig.eigenvalues.iter().all(|l| l.abs() > EIGEN_FLOOR));
        let mut after = q.clone();
        convexify(&mut after, &c, &reg);
        let m = scaled(&after, &c, &reg);
        // |A| is the unique positive definite square root of A²: M² = A² and M > 0.
        let diff = (&m * &m - &before * &before).abs().max();
        assert!(diff < 1e-12 * before.norm_squared(), "M² − A² = {diff}");
        assert!(m.clone().symmetric_eigen().eigenvalues.min() > 0.0);
        // What was added, in the original units, is positive semidefinite.
        let added = (&after - &q).symmetric_eigen().eigenvalues.min();
        assert!(added > -1e-9 * q.norm(), "added {added}");
    }

    #[test]
    fn convexify_keeps_a_positive_definite_matrix_and_floors_small_eigenvalues() {
        let c = [1.0, 9.0];
        let reg = [0.0, 0.0];
        let pd = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 9.0]);
        let mut same = pd.clone();
        convexify(&mut same, &c, &reg);
        assert!((&same - &pd).abs().max() < 1e-12);
        // Singular: eigenvalues 0 and 2 in the scaled coordinates; the 0 is raised to the floor.
        let singular = DMatrix::from_row_slice(2, 2, &[1.0, 3.0, 3.0, 9.0]);
        let mut raised = singular.clone();
        convexify(&mut raised, &c, &reg);
        let mut l: Vec<f64> = scaled(&raised, &c, &reg)
            .symmetric_eigen()
            .eigenvalues
            .iter()
            .copied()
            .collect();
        l.sort_by(f64::total_cmp);
        assert!(
            (l[0] - EIGEN_FLOOR).abs() < 1e-12 && (l[1] - 2.0).abs() < 1e-12,
            "{l:?}"
        );
    }
}
