//! ILQG on a linear plant with quadratic cost and additive noise is LQG (Todorov & Li 2005: the
//! exactness check): its gains, nominal and predicted expected cost must equal those of a
//! discrete-time Riccati recursion written independently here, and the moment propagation of
//! `vic_core::solver::moments` must give the same expected cost.

use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use vic_core::cost::{Cost, CostDerivatives};
use vic_core::dynamics::{Dynamics, Linearization, NoiseKind};
use vic_core::solver::moments::{self, MomentWorkspace};
use vic_core::solver::{Bounds, Ilqg, IlqgOptions, Problem, Solution};

const NX: usize = 3;
const NU: usize = 2;
const NW: usize = 2;
const HORIZON: usize = 30;
const REL: f64 = 1e-9;

/// `x[k+1] = A_k x[k] + B u[k] + d_k + G ε[k]`.
struct LinearPlant {
    a: Vec<DMatrix<f64>>,
    b: DMatrix<f64>,
    d: Vec<DVector<f64>>,
    g: DMatrix<f64>,
}

impl Dynamics for LinearPlant {
    fn nx(&self) -> usize {
        NX
    }
    fn nu(&self) -> usize {
        NU
    }
    fn nw(&self) -> usize {
        NW
    }
    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        let x = DVector::from_column_slice(x);
        let u = DVector::from_column_slice(u);
        let n = &self.a[k] * x + &self.b * u + &self.d[k];
        next.copy_from_slice(n.as_slice());
    }
    fn noise_gain(&self, _k: usize, _x: &[f64], _u: &[f64], out: &mut DMatrix<f64>) {
        out.copy_from(&self.g);
    }
    fn linearize(&self, k: usize, _x: &[f64], _u: &[f64], lin: &mut Linearization) {
        lin.a.copy_from(&self.a[k]);
        lin.b.copy_from(&self.b);
        lin.c.copy_from(&self.g);
        for m in lin.cx.iter_mut().chain(lin.cu.iter_mut()) {
            m.fill(0.0);
        }
        lin.noise = NoiseKind::Additive;
    }
}

/// `ℓ_k = ½ [e; w]ᵀ H [e; w]` with `e = x − r_k`, `w = u − v_k`; `g = ½ eᵀ Q_f e` with `e = x − r_N`.
struct QuadraticCost {
    /// Joint Hessian (n+m)×(n+m), positive definite.
    h: DMatrix<f64>,
    qf: DMatrix<f64>,
    r: Vec<DVector<f64>>,
    v: Vec<DVector<f64>>,
}

impl QuadraticCost {
    fn hxx(&self) -> DMatrix<f64> {
        self.h.view((0, 0), (NX, NX)).into_owned()
    }
    fn hux(&self) -> DMatrix<f64> {
        self.h.view((NX, 0), (NU, NX)).into_owned()
    }
    fn huu(&self) -> DMatrix<f64> {
        self.h.view((NX, NX), (NU, NU)).into_owned()
    }
    fn errors(&self, k: usize, x: &[f64], u: &[f64]) -> (DVector<f64>, DVector<f64>) {
        (
            DVector::from_column_slice(x) - &self.r[k],
            DVector::from_column_slice(u) - &self.v[k],
        )
    }
}

impl Cost for QuadraticCost {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        let (e, w) = self.errors(k, x, u);
        let z = DVector::from_iterator(NX + NU, e.iter().chain(w.iter()).copied());
        0.5 * z.dot(&(&self.h * &z))
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        let e = DVector::from_column_slice(x) - &self.r[HORIZON];
        0.5 * e.dot(&(&self.qf * &e))
    }
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        let (e, w) = self.errors(k, x, u);
        d.lx = self.hxx() * &e + self.hux().transpose() * &w;
        d.lu = self.hux() * &e + self.huu() * &w;
        d.lxx = self.hxx();
        d.luu = self.huu();
        d.lux = self.hux();
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives) {
        let e = DVector::from_column_slice(x) - &self.r[HORIZON];
        d.lx = &self.qf * e;
        d.lxx = self.qf.clone();
    }
}

fn random_matrix(rng: &mut StdRng, rows: usize, cols: usize, scale: f64) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| scale * rng.random_range(-1.0..1.0))
}

fn random_vector(rng: &mut StdRng, n: usize, scale: f64) -> DVector<f64> {
    DVector::from_fn(n, |_, _| scale * rng.random_range(-1.0..1.0))
}

/// A seeded problem: a time-varying, mildly unstable plant with a drift term, a cost with
/// state–control cross terms and moving references.
fn problem_data(seed: u64) -> (LinearPlant, QuadraticCost, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let a0 = DMatrix::identity(NX, NX) * 1.02 + random_matrix(&mut rng, NX, NX, 0.15);
    let da = random_matrix(&mut rng, NX, NX, 0.05);
    let plant = LinearPlant {
        a: (0..HORIZON)
            .map(|k| &a0 + &da * (0.3 * k as f64).sin())
            .collect(),
        b: random_matrix(&mut rng, NX, NU, 0.5),
        d: (0..HORIZON)
            .map(|_| random_vector(&mut rng, NX, 0.05))
            .collect(),
        g: random_matrix(&mut rng, NX, NW, 0.2),
    };
    let w = random_matrix(&mut rng, NX + NU, NX + NU, 1.0);
    let v = random_matrix(&mut rng, NX, NX, 1.0);
    let cost = QuadraticCost {
        h: w.transpose() * &w + DMatrix::identity(NX + NU, NX + NU) * 0.1,
        qf: (v.transpose() * &v + DMatrix::identity(NX, NX)) * 10.0,
        r: (0..=HORIZON)
            .map(|_| random_vector(&mut rng, NX, 1.0))
            .collect(),
        v: (0..HORIZON)
            .map(|_| random_vector(&mut rng, NU, 0.5))
            .collect(),
    };
    let x0 = random_vector(&mut rng, NX, 2.0).as_slice().to_vec();
    (plant, cost, x0)
}

/// The LQG solution by the Riccati recursion on the value `V_k(x) = ½ xᵀ S_k x + s_kᵀ x + σ_k`
/// (absolute coordinates, affine terms included).
struct Riccati {
    /// Feedback gains `K_k` of `u = k_k + K_k x`.
    gains: Vec<DMatrix<f64>>,
    feedforward: Vec<DVector<f64>>,
    /// `S_0 ..= S_N`.
    s_mat: Vec<DMatrix<f64>>,
    /// `V_0(x0)` of the deterministic problem.
    deterministic_value: f64,
    /// `V_0(x0)` of the stochastic problem.
    stochastic_value: f64,
}

fn riccati(plant: &LinearPlant, cost: &QuadraticCost, x0: &[f64]) -> Riccati {
    let (q, p, r) = (cost.hxx(), cost.hux(), cost.huu());
    let rn = &cost.r[HORIZON];
    let mut s_mat = cost.qf.clone();
    let mut s_vec = -(&cost.qf * rn);
    let mut sigma_det = 0.5 * rn.dot(&(&cost.qf * rn));
    let mut sigma_noise = 0.0;
    let mut gains = vec![DMatrix::zeros(NU, NX); HORIZON];
    let mut feedforward = vec![DVector::zeros(NU); HORIZON];
    let mut all_s = vec![s_mat.clone()];
    for k in (0..HORIZON).rev() {
        let (a, b, d) = (&plant.a[k], &plant.b, &plant.d[k]);
        let (rk, vk) = (&cost.r[k], &cost.v[k]);
        // ℓ_k(x, u) = ½ xᵀ Q x + ½ uᵀ R u + uᵀ P x + qᵀ x + ρᵀ u + ℓ_k(0, 0).
        let lq = -(&q * rk) - p.transpose() * vk;
        let lr = -(&p * rk) - &r * vk;
        let l0 = cost.running(k, &[0.0; NX], &[0.0; NU]);
        let sd_s = &s_mat * d + &s_vec;
        let qxx = &q + a.transpose() * &s_mat * a;
        let quu = &r + b.transpose() * &s_mat * b;
        let qux = &p + b.transpose() * &s_mat * a;
        let qx = lq + a.transpose() * &sd_s;
        let qu = lr + b.transpose() * &sd_s;
        let q0 = l0 + 0.5 * d.dot(&(&s_mat * d)) + s_vec.dot(d) + sigma_det;
        sigma_noise += 0.5 * (plant.g.transpose() * &s_mat * &plant.g).trace();
        let quu_inv = quu.try_inverse().expect("Q_uu invertible");
        let gain = -(&quu_inv * &qux);
        let ff = -(&quu_inv * &qu);
        s_mat = &qxx + qux.transpose() * &gain;
        s_mat = (&s_mat + s_mat.transpose()) * 0.5;
        s_vec = qx + qux.transpose() * &ff;
        sigma_det = q0 + 0.5 * qu.dot(&ff);
        gains[k] = gain;
        feedforward[k] = ff;
        all_s.push(s_mat.clone());
    }
    all_s.reverse();
    let x0 = DVector::from_column_slice(x0);
    let deterministic_value = 0.5 * x0.dot(&(&s_mat * &x0)) + s_vec.dot(&x0) + sigma_det;
    Riccati {
        gains,
        feedforward,
        s_mat: all_s,
        deterministic_value,
        stochastic_value: deterministic_value + sigma_noise,
    }
}

/// The noise-free trajectory of the Riccati policy and its cost.
fn riccati_rollout(
    plant: &LinearPlant,
    cost: &QuadraticCost,
    x0: &[f64],
    lqg: &Riccati,
) -> (Vec<DVector<f64>>, Vec<DVector<f64>>, f64) {
    let mut x = vec![DVector::from_column_slice(x0)];
    let mut u = Vec::new();
    let mut total = 0.0;
    for k in 0..HORIZON {
        let uk = &lqg.feedforward[k] + &lqg.gains[k] * &x[k];
        let mut next = vec![0.0; NX];
        plant.step(k, x[k].as_slice(), uk.as_slice(), &mut next);
        total += cost.running(k, x[k].as_slice(), uk.as_slice());
        u.push(uk);
        x.push(DVector::from_vec(next));
    }
    total += cost.terminal(x[HORIZON].as_slice());
    (x, u, total)
}

fn assert_rel(what: &str, actual: f64, expected: f64, rel: f64) {
    assert!(
        (actual - expected).abs() <= rel * expected.abs(),
        "{what}: {actual:.15e} vs {expected:.15e} (relative error {:.2e})",
        (actual - expected).abs() / expected.abs()
    );
}

fn assert_matrix_rel(what: &str, actual: &DMatrix<f64>, expected: &DMatrix<f64>, rel: f64) {
    let err = (actual - expected).amax();
    assert!(
        err <= rel * expected.amax(),
        "{what}: max error {err:e} relative to {:e}\nactual {actual}\nexpected {expected}",
        expected.amax()
    );
}

fn solve(plant: &LinearPlant, cost: &QuadraticCost, x0: &[f64], stochastic: bool) -> Solution {
    let problem = Problem {
        dynamics: plant,
        cost,
        x0: x0.to_vec(),
        horizon: HORIZON,
        bounds: Bounds::unbounded(NU),
    };
    let options = IlqgOptions {
        stochastic,
        ..IlqgOptions::default()
    };
    let mut solver = Ilqg::new(&problem, options);
    let u_init = vec![DVector::zeros(NU); HORIZON];
    solver.solve(&problem, &u_init)
}

/// The value Hessians a stochastic solve leaves for its line search's merit are the Riccati
/// recursion's `S_{k+1}` at every knot: on the plant's size that the backward pass takes by the
/// Jacobians' nonzeros, whose stochastic pass writes them in place of a copy.
#[test]
fn the_merit_reads_the_riccati_value_hessians() {
    for seed in [7, 8] {
        let (plant, cost, x0) = problem_data(seed);
        let lqg = riccati(&plant, &cost, &x0);
        let problem = Problem {
            dynamics: &plant,
            cost: &cost,
            x0: x0.clone(),
            horizon: HORIZON,
            bounds: Bounds::unbounded(NU),
        };
        let mut solver = Ilqg::new(&problem, IlqgOptions::default());
        let sol = solver.solve(&problem, &vec![DVector::zeros(NU); HORIZON]);
        assert!(
            sol.stop.converged(),
            "seed {seed}: stopped with {:?}",
            sol.stop
        );
        let hessians = solver.value_hessians();
        assert_eq!(hessians.len(), HORIZON);
        for (k, s) in hessians.iter().enumerate() {
            assert_matrix_rel(
                &format!("seed {seed}: S_{}", k + 1),
                s,
                &lqg.s_mat[k + 1],
                REL,
            );
        }
    }
}

#[test]
fn riccati_reference_is_self_consistent() {
    // The deterministic value from the recursion equals the cost of rolling its policy out, and
    // the noise term equals ½ Σ_k Σ_i c_iᵀ S_{k+1} c_i.
    let (plant, cost, x0) = problem_data(7);
    let lqg = riccati(&plant, &cost, &x0);
    let (_, _, rolled) = riccati_rollout(&plant, &cost, &x0, &lqg);
    assert_rel("V_0 vs rollout", lqg.deterministic_value, rolled, 1e-12);
    let noise: f64 = (0..HORIZON)
        .map(|k| {
            (0..NW)
                .map(|i| {
                    let c = plant.g.column(i);
                    0.5 * c.dot(&(&lqg.s_mat[k + 1] * c))
                })
                .sum::<f64>()
        })
        .sum();
    assert!(noise > 0.0);
    assert_rel(
        "noise term",
        lqg.stochastic_value - lqg.deterministic_value,
        noise,
        1e-12,
    );
}

#[test]
fn ilqg_equals_lqg_on_a_linear_quadratic_problem() {
    for seed in [7, 8, 9] {
        let (plant, cost, x0) = problem_data(seed);
        let lqg = riccati(&plant, &cost, &x0);
        let (x_opt, u_opt, cost_opt) = riccati_rollout(&plant, &cost, &x0, &lqg);
        let sol = solve(&plant, &cost, &x0, true);
        let tag = format!("seed {seed}");
        assert!(sol.stop.converged(), "{tag}: stopped with {:?}", sol.stop);
        // One Newton step solves an LQ problem exactly.
        assert_eq!(sol.iterations, 1, "{tag}: iterations");
        let scale = u_opt.iter().map(|u| u.amax()).fold(0.0, f64::max);
        assert_eq!(
            (sol.u.len(), sol.gains.len()),
            (HORIZON, HORIZON),
            "{tag}: sizes"
        );
        for (k, (gain, expected)) in sol.gains.iter().zip(&lqg.gains).enumerate() {
            assert_matrix_rel(&format!("{tag}: L_{k}"), gain, expected, REL);
        }
        for (k, (u, expected)) in sol.u.iter().zip(&u_opt).enumerate() {
            assert!(
                (u - expected).amax() <= REL * scale,
                "{tag}: u_{k} = {u} vs {expected}"
            );
        }
        let xscale = x_opt.iter().map(|x| x.amax()).fold(0.0, f64::max);
        for (k, (x, expected)) in sol.x.iter().zip(&x_opt).enumerate() {
            assert!((x - expected).amax() <= REL * xscale, "{tag}: x_{k}");
        }
        assert_eq!(sol.x.len(), HORIZON + 1, "{tag}: states");
        assert_rel(&format!("{tag}: cost"), sol.cost, cost_opt, REL);
        assert_rel(
            &format!("{tag}: expected cost"),
            sol.expected_cost,
            lqg.stochastic_value,
            REL,
        );
        // The noise matters: the expected cost is measurably above the deterministic one.
        assert!(lqg.stochastic_value - lqg.deterministic_value > 1e-3 * lqg.stochastic_value);
    }
}

#[test]
fn deterministic_ddp_has_the_same_gains_and_no_noise_cost() {
    let (plant, cost, x0) = problem_data(8);
    let lqg = riccati(&plant, &cost, &x0);
    let sol = solve(&plant, &cost, &x0, false);
    assert!(sol.stop.converged(), "stopped with {:?}", sol.stop);
    // Additive noise does not change LQG gains (certainty equivalence).
    for k in 0..HORIZON {
        assert_matrix_rel(&format!("L_{k}"), &sol.gains[k], &lqg.gains[k], REL);
    }
    assert_rel("cost", sol.cost, lqg.deterministic_value, REL);
    assert_rel(
        "expected cost",
        sol.expected_cost,
        lqg.deterministic_value,
        REL,
    );
}

/// Linearisations and cost derivatives along a trajectory, as `moments::expected_cost` takes them.
fn along(
    plant: &LinearPlant,
    cost: &QuadraticCost,
    x: &[DVector<f64>],
    u: &[DVector<f64>],
) -> (Vec<Linearization>, Vec<CostDerivatives>) {
    let mut lin = Vec::new();
    let mut derivs = Vec::new();
    for k in 0..HORIZON {
        let mut l = Linearization::new(NX, NU, NW);
        plant.linearize(k, x[k].as_slice(), u[k].as_slice(), &mut l);
        lin.push(l);
        let mut d = CostDerivatives::new(NX, NU);
        cost.running_derivatives(k, x[k].as_slice(), u[k].as_slice(), &mut d);
        derivs.push(d);
    }
    let mut d = CostDerivatives::new(NX, NU);
    cost.terminal_derivatives(x[HORIZON].as_slice(), &mut d);
    derivs.push(d);
    (lin, derivs)
}

#[test]
fn moment_propagation_gives_the_lqg_expected_cost() {
    let (plant, cost, x0) = problem_data(9);
    let lqg = riccati(&plant, &cost, &x0);
    let sol = solve(&plant, &cost, &x0, true);
    let (lin, derivs) = along(&plant, &cost, &sol.x, &sol.u);
    let mut ws = MomentWorkspace::new(NX, NU);
    let mut sigmas = Vec::new();
    let total = moments::expected_cost(
        sol.cost,
        &lin,
        &derivs,
        Some(&sol.gains),
        &mut ws,
        |k, s| sigmas.push((k, s.clone())),
    );
    assert_rel(
        "closed-loop expected cost",
        total,
        lqg.stochastic_value,
        REL,
    );
    assert_rel(
        "closed-loop expected cost vs solution",
        total,
        sol.expected_cost,
        REL,
    );

    // The covariances it visits are those of δx' = (A + B L) δx + G ε.
    assert_eq!(
        sigmas.iter().map(|(k, _)| *k).collect::<Vec<_>>(),
        (0..=HORIZON).collect::<Vec<_>>()
    );
    let mut sigma = DMatrix::zeros(NX, NX);
    for (k, visited) in &sigmas {
        assert_matrix_rel(&format!("Σ_{k}"), visited, &sigma, 1e-12);
        if *k < HORIZON {
            let acl = &plant.a[*k] + &plant.b * &lqg.gains[*k];
            sigma = &acl * &sigma * acl.transpose() + &plant.g * plant.g.transpose();
        }
    }
    assert_matrix_rel("final covariance", ws.final_covariance(), &sigma, 1e-12);
}

#[test]
fn open_loop_moments_match_the_exact_open_loop_expected_cost() {
    // With no feedback the state spreads as Σ' = A Σ Aᵀ + G Gᵀ, and for a quadratic cost
    // E[C] = C(x̄, ū) + ½ Σ_k tr(Hxx Σ_k) + ½ tr(Q_f Σ_N) exactly.
    let (plant, cost, x0) = problem_data(10);
    let sol = solve(&plant, &cost, &x0, true);
    let (lin, derivs) = along(&plant, &cost, &sol.x, &sol.u);
    let mut ws = MomentWorkspace::new(NX, NU);
    let total = moments::expected_cost(sol.cost, &lin, &derivs, None, &mut ws, |_, _| {});
    let mut sigma = DMatrix::zeros(NX, NX);
    let mut expected = sol.cost;
    for k in 0..HORIZON {
        expected += 0.5 * (cost.hxx() * &sigma).trace();
        sigma = &plant.a[k] * &sigma * plant.a[k].transpose() + &plant.g * plant.g.transpose();
    }
    expected += 0.5 * (&cost.qf * &sigma).trace();
    assert_rel("open-loop expected cost", total, expected, 1e-12);
    // Feedback helps: the closed loop's expected cost is lower.
    assert!(sol.expected_cost < expected);
}
