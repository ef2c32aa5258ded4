//! How the drift is integrated over one control step: the one integrator of the project (the
//! planner, the Monte Carlo and the board step the plant through [`flow`]).

use crate::model::{Actuator, ArmModel, Exogenous, Plant};
use crate::scalar::{MAX_NX, Scalar};

/// How the drift is integrated over one control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Explicit Euler (the paper's): `x += h f(x, u)`.
    Euler,
    /// Semi-implicit (symplectic) Euler: velocities first, then positions with the new
    /// velocities. Stable for undamped springs (the VSA) where explicit Euler gains energy.
    SemiImplicit,
    /// The classical fourth-order Runge–Kutta step, control and exogenous input held: error
    /// O(h⁴) per unit time against Euler's O(h), so one step per knot can stand in for ten
    /// Euler sub-steps where the sub-steps were there for accuracy rather than stability
    /// (four drift evaluations per step instead of ten; the step's derivatives take one
    /// differentiated step per knot).
    Rk4,
    /// Verwer's two-stage Rosenbrock–W step (ROS2), the actuator's stiff linear part taken
    /// implicitly: `W k₁ = f(x)`, `W k₂ = f(x + h k₁) − 2 k₁`, `x += h (3/2 k₁ + 1/2 k₂)`, with
    /// `W = I − γ h J` and `J` the Jacobian of the impedance law's spring and damper
    /// (`−M⁻¹ K_P`, `−M⁻¹ K_D`), or of a VSA's spring, with `M(q)` held at the step's start.
    /// Second order for any `J` (a W-method), and L-stable on the stiff part, so that one step
    /// per knot is stable at any stiffness: a damping rate `K_D / I` of 1575 /s asks explicit
    /// steps under 1.3 ms (Euler) or 1.8 ms (RK4). Two drift evaluations and two `dof × dof`
    /// solves a step. Without stiffness (the torque actuator) `J = 0` and it is Heun's step.
    /// Its SOOC plans cost more on the 1 ms plant than the optimum made there (one step per
    /// knot: +0.35 % on the two-link arm, +3 % on the iCub elbow, `docs/BENCHMARKS.md`), so
    /// the scenarios keep ten semi-implicit sub-steps.
    Rosenbrock,
}

/// ROS2's `γ = 1 − 1/√2`: both roots of `γ² − 2γ + 1/2 = 0` make the step second order and
/// L-stable; this one has the smaller error constant on the slow modes (the step's third-order
/// term `3γ² − 2γ³` is 0.207 against the exact 1/6, where `1 + 1/√2` gives −1.21).
const ROS2_GAMMA: f64 = 1.0 - std::f64::consts::FRAC_1_SQRT_2;

/// Integrates the drift of `model` over `dt` in `substeps` steps, control and exogenous input
/// held. The one integrator of the project: the planner, the Monte Carlo and the board use it.
#[allow(clippy::too_many_arguments)]
pub fn flow<S: Scalar>(
    model: &ArmModel,
    ex: &Exogenous,
    dt: f64,
    substeps: usize,
    integrator: Integrator,
    x: &[S],
    u: &[S],
    next: &mut [S],
) {
    flow_body(model, ex, dt, substeps, integrator, x, u, next);
}

/// [`flow`]'s body, inlined where it is compiled for a particular instruction set.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn flow_body<S: Scalar>(
    model: &ArmModel,
    ex: &Exogenous,
    dt: f64,
    substeps: usize,
    integrator: Integrator,
    x: &[S],
    u: &[S],
    next: &mut [S],
) {
    let nx = model.nx();
    let h = dt / substeps as f64;
    let mut cur = [<S as Scalar>::zero(); MAX_NX];
    cur[..nx].copy_from_slice(&x[..nx]);
    let mut xdot = [<S as Scalar>::zero(); MAX_NX];
    for _ in 0..substeps {
        let mass = model.f_and_mass(&cur[..nx], u, ex, &mut xdot[..nx]);
        match integrator {
            Integrator::Euler => {
                for i in 0..nx {
                    cur[i] += xdot[i] * h;
                }
            }
            Integrator::SemiImplicit => {
                let dof = model.dof();
                let blocks = model.second_order_states();
                // Velocities are the second half of each (position, velocity) block.
                for block in (0..blocks).step_by(2 * dof) {
                    for i in 0..dof {
                        cur[block + dof + i] += xdot[block + dof + i] * h;
                        cur[block + i] += cur[block + dof + i] * h;
                    }
                }
                // First-order states (a lagged stiffness) have no velocity: explicit Euler.
                for i in blocks..nx {
                    cur[i] += xdot[i] * h;
                }
            }
            Integrator::Rk4 => {
                // k₁ = xdot; x += h/6 (k₁ + 2k₂ + 2k₃ + k₄), kᵢ at x + cᵢ h kᵢ₋₁.
                let mut sum = xdot;
                let mut stage = [<S as Scalar>::zero(); MAX_NX];
                let mut slope = xdot;
                for (c, w) in [(0.5, 2.0), (0.5, 2.0), (1.0, 1.0)] {
                    for i in 0..nx {
                        stage[i] = cur[i] + slope[i] * (c * h);
                    }
                    model.f(&stage[..nx], u, ex, &mut slope[..nx]);
                    for i in 0..nx {
                        sum[i] += slope[i] * w;
                    }
                }
                for i in 0..nx {
                    cur[i] += sum[i] * (h / 6.0);
                }
            }
            Integrator::Rosenbrock => {
                let c = ROS2_GAMMA * h;
                let mut k1 = xdot;
                solve_stiff(model, &mass, u, c, &mut k1[..nx]);
                let mut stage = [<S as Scalar>::zero(); MAX_NX];
                for i in 0..nx {
                    stage[i] = cur[i] + k1[i] * h;
                }
                let mut k2 = [<S as Scalar>::zero(); MAX_NX];
                model.f(&stage[..nx], u, ex, &mut k2[..nx]);
                for i in 0..nx {
                    k2[i] -= k1[i] * 2.0;
                }
                solve_stiff(model, &mass, u, c, &mut k2[..nx]);
                for i in 0..nx {
                    cur[i] += k1[i] * (1.5 * h) + k2[i] * (0.5 * h);
                }
            }
        }
    }
    next[..nx].copy_from_slice(&cur[..nx]);
}

/// Solves `(I − c J) k = r` in place (`r` in, `k` out) for the Rosenbrock step's `J`: the
/// actuator's stiff linear part with the mass matrix `m` held, in `dof × dof` solves.
///
/// - Impedance (`q'' ∋ −M⁻¹ (K_P q + K_D q')`): the rows `k_q − c k_v = r_q`,
///   `k_v + c M⁻¹ (K_P k_q + K_D k_v) = r_v` give `(M + c K_D + c² K_P) k_v = M r_v − c K_P r_q`,
///   then `k_q = r_q + c k_v`.
/// - VSA (`q'' ∋ M⁻¹ K (θ − q)`, `θ'' ∋ −B⁻¹ K (θ − q)`): with `d = k_θ − k_q`,
///   `(M + c² (M B⁻¹ + I) K) d = M (r_θ − r_q + c (r_θ' − r_q'))`, then
///   `k_q' = r_q' + c M⁻¹ K d`, `k_θ' = r_θ' − c B⁻¹ K d`, `k_q = r_q + c k_q'`,
///   `k_θ = r_θ + c k_θ'`.
/// - Torque: `J = 0`, `k = r`.
#[inline(always)]
fn solve_stiff<S: Scalar>(model: &ArmModel, m: &[[S; 2]; 2], u: &[S], c: f64, r: &mut [S]) {
    let n = model.dof();
    let mul = |a: &[[S; 2]; 2], v: &[S], out: &mut [S; 2]| {
        for i in 0..n {
            out[i] = <S as Scalar>::zero();
            for j in 0..n {
                out[i] += a[i][j] * v[j];
            }
        }
    };
    match &model.actuator {
        // A lagged stiffness is a state, not the control this solve reads: the step is taken
        // explicitly (`J = 0`), and scenarios refuse this integrator for that actuator.
        Actuator::Torque | Actuator::ImpedanceLag { .. } => {}
        Actuator::Impedance { damping } => {
            let mut w = *m;
            let mut rhs = [<S as Scalar>::zero(); 2];
            mul(m, &r[n..2 * n], &mut rhs);
            for i in 0..n {
                let k = u[n + i];
                w[i][i] += damping.gain(k) * c + k * (c * c);
                rhs[i] -= k * r[i] * c;
            }
            let mut kv = [<S as Scalar>::zero(); 2];
            Plant::solve_with(&w, n, &rhs[..n], &mut kv[..n]);
            // Element by element: a slice copy of one or two numbers is a call to memcpy.
            #[allow(clippy::manual_memcpy)]
            for i in 0..n {
                r[n + i] = kv[i];
                r[i] += kv[i] * c;
            }
        }
        Actuator::Vsa { motor_inertia } => {
            let mut e = [<S as Scalar>::zero(); 2];
            for i in 0..n {
                e[i] = r[2 * n + i] - r[i] + (r[3 * n + i] - r[n + i]) * c;
            }
            let mut rhs = [<S as Scalar>::zero(); 2];
            mul(m, &e[..n], &mut rhs);
            let mut w = *m;
            for (i, row) in w.iter_mut().enumerate().take(n) {
                for j in 0..n {
                    let k = u[n + j];
                    row[j] += m[i][j] * k * (c * c / motor_inertia[j]);
                    if i == j {
                        row[j] += k * (c * c);
                    }
                }
            }
            let mut d = [<S as Scalar>::zero(); 2];
            Plant::solve_with(&w, n, &rhs[..n], &mut d[..n]);
            let mut t = [<S as Scalar>::zero(); 2];
            for i in 0..n {
                t[i] = u[n + i] * d[i];
            }
            let mut s = [<S as Scalar>::zero(); 2];
            Plant::solve_with(m, n, &t[..n], &mut s[..n]);
            for i in 0..n {
                r[n + i] += s[i] * c;
                r[3 * n + i] -= t[i] * (c / motor_inertia[i]);
                r[i] += r[n + i] * c;
                r[2 * n + i] += r[3 * n + i] * c;
            }
        }
    }
}
