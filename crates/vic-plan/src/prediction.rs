//! The expected cost of an executed law predicted without sampling: the closed-loop mean and
//! covariance propagation of the linearised plant under that law (full feedback, the predictor
//! over a latency, or open loop), next to which the Monte Carlo reports what the trials cost;
//! and where the prediction's own assumption, an unclamped linear law, fails.

use crate::setup::Setup;
use nalgebra::DMatrix;
use std::ops::AddAssign;
use vic_core::cost::{Cost, CostDerivatives};
use vic_core::dynamics::{Dynamics, Linearization};
use vic_core::policy::{Feedback, Policy};

/// The expected cost (Eq. 14) of executing `policy` with `feedback` on the plant of `setup`,
/// predicted without sampling: the closed-loop mean/covariance propagation of the linearised plant
/// under *that* law, the way the open-loop prediction propagates SOOC's (Eq. 10 on the mean and
/// covariance) and ILQG's `s_0` values the undelayed law. `None` for the naive delayed law
/// (Eq. 13), whose augmented state would be the past states themselves (not modelled here).
///
/// Around the nominal `(x̄_k, ū_k)`, `δx_{k+1} = A_k δx_k + B_k δu_k + w_k`, with `w_k = Σ_i (c_i +
/// Cx_i δx_k + Cu_i δu_k) ε_i` (Todorov & Li's noise model, paper Eq. 8 and 10). A predictor
/// that sees `x_{k−D}` and runs the model over the commands it sent knows the present up to the
/// noise of the last `D` steps carried forward: `δx_k − δx̂_k = e_k = Σ_{m=1..D} ε⁽ᵐ⁾_k`, with
/// `ε⁽¹⁾_{k+1} = w_k`, `ε⁽ᵐ⁺¹⁾_{k+1} = A_k ε⁽ᵐ⁾_k` (independent of the commands: they are known).
/// So on the augmented state `z = (δx, ε⁽¹⁾ … ε⁽ᴰ⁾)` (dimension `n (D + 1)`) the law is linear,
/// `δu_k = L_k (δx_k − Σ ε⁽ᵐ⁾_k)` (zero for `k < D`, before any state has arrived), and
/// `Σ_z` propagates exactly for the linearised plant: `Σ_{k+1} = F Σ Fᵀ + E Q_k Eᵀ`, `E = (I, I,
/// 0 …)`. The cost is `Σ_k ℓ(x̄, ū) + ½ tr(H_k Cov(δx, δu))` plus the terminal term. `D = 0` is
/// full feedback (ILQG's own prediction), zero gains open loop. Clamping into the bounds and
/// the nonlinearity beyond second order are not modelled: the Monte Carlo checks what they cost.
pub fn predicted_cost(setup: &Setup, policy: &Policy, feedback: Feedback) -> Option<f64> {
    predict_closed_loop(setup, policy, feedback).map(|p| p.expected_cost)
}

/// What [`predict_closed_loop`] predicts of an executed law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ClosedLoopPrediction {
    /// The expected cost ([`predicted_cost`]).
    pub expected_cost: f64,
    /// The knots at which the law's predicted standard deviation in some control, `√(K Σ Kᵀ)_ii`,
    /// exceeds the room between the nominal command and its nearer bound: there the commands are
    /// clamped in more than about one trial in six, which the linear prediction does not model.
    /// The ILQG plans with stiffness in their feedback reach this (stiffness is nearly free, so
    /// its gains are huge, and the clamped plant executes another law than the predicted one).
    pub(crate) clamped_knots: usize,
    /// The knots of the law.
    pub knots: usize,
}

/// [`predicted_cost`] with the knots where the prediction's own assumption, an unclamped linear
/// law, fails ([`ClosedLoopPrediction::clamped_knots`]).
pub(crate) fn predict_closed_loop(
    setup: &Setup,
    policy: &Policy,
    feedback: Feedback,
) -> Option<ClosedLoopPrediction> {
    let d = match feedback {
        Feedback::OpenLoop | Feedback::Full => 0,
        Feedback::Predicted { latency_steps } => latency_steps,
        // The naive law's augmented state, and the replanner's changing plan, are not modelled.
        Feedback::Delayed { .. } | Feedback::Replan { .. } => return None,
    };
    let dynamics = &setup.dynamics;
    let (n, m, p) = (dynamics.nx(), policy.nu(), dynamics.nw());
    let nz = n * (d + 1);
    let mut sigma = DMatrix::<f64>::zeros(nz, nz);
    let mut lin = Linearization::new(n, m, p);
    let mut cd = CostDerivatives::new(n, m);
    let mut total = 0.0;
    let mut clamped_knots = 0;
    for k in 0..policy.steps() {
        let (x, u) = (policy.nominal[k].as_slice(), policy.acting[k].as_slice());
        dynamics.linearize(k, x, u, &mut lin);
        setup.cost.running_derivatives(k, x, u, &mut cd);
        // δu = K z.
        let mut gain_z = DMatrix::<f64>::zeros(m, nz);
        if feedback != Feedback::OpenLoop && k >= d {
            let l = &policy.gains[k];
            gain_z.columns_mut(0, n).copy_from(l);
            for j in 1..=d {
                gain_z.columns_mut(j * n, n).copy_from(&(-l));
            }
        }
        // (δx, δu) = M z, and the cost of its covariance.
        let mut sel = DMatrix::<f64>::zeros(n + m, nz);
        sel.view_mut((0, 0), (n, n)).fill_with_identity();
        sel.rows_mut(n, m).copy_from(&gain_z);
        let cov = &sel * &sigma * sel.transpose();
        let u_k = &policy.acting[k];
        let clamped = (0..m).any(|i| {
            let room = (u_k[i] - policy.bounds.lower[i]).min(policy.bounds.upper[i] - u_k[i]);
            cov[(n + i, n + i)].max(0.0).sqrt() > room
        });
        clamped_knots += usize::from(clamped);
        let mut h = DMatrix::<f64>::zeros(n + m, n + m);
        h.view_mut((0, 0), (n, n)).copy_from(&cd.lxx);
        h.view_mut((n, n), (m, m)).copy_from(&cd.luu);
        h.view_mut((n, 0), (m, n)).copy_from(&cd.lux);
        h.view_mut((0, n), (n, m)).copy_from(&cd.lux.transpose());
        total += setup.cost.running(k, x, u) + 0.5 * (&h * &cov).trace();
        // The noise covariance Q = Σ_i c_i c_iᵀ + N_i Σ_z N_iᵀ, N_i = Cx_i S + Cu_i K.
        let mut q = &lin.c * lin.c.transpose();
        for i in 0..p {
            let mut ni = &lin.cu[i] * &gain_z;
            ni.columns_mut(0, n).add_assign(&lin.cx[i]);
            q += &ni * &sigma * ni.transpose();
        }
        // z⁺ = F z + E w.
        let mut f = DMatrix::<f64>::zeros(nz, nz);
        let bk = &lin.b * &gain_z;
        f.rows_mut(0, n).copy_from(&bk);
        f.view_mut((0, 0), (n, n)).add_assign(&lin.a);
        for j in 1..d {
            f.view_mut((n * (j + 1), n * j), (n, n)).copy_from(&lin.a);
        }
        let mut next = &f * &sigma * f.transpose();
        next.view_mut((0, 0), (n, n)).add_assign(&q);
        if d > 0 {
            next.view_mut((n, n), (n, n)).add_assign(&q);
            next.view_mut((0, n), (n, n)).add_assign(&q);
            next.view_mut((n, 0), (n, n)).add_assign(&q);
        }
        sigma = next;
    }
    let xn = policy.nominal[policy.steps()].as_slice();
    setup.cost.terminal_derivatives(xn, &mut cd);
    let px = sigma.view((0, 0), (n, n));
    total += setup.cost.terminal(xn) + 0.5 * (&cd.lxx * px).trace();
    total.is_finite().then_some(ClosedLoopPrediction {
        expected_cost: total,
        clamped_knots,
        knots: policy.steps(),
    })
}
