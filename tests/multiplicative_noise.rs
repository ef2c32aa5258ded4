//! ILQG on a scalar linear plant with state-multiplicative noise,
//! `x' = a x + b u + (c0 + c1 x) ε`, and a quadratic cost.
//!
//! For this plant the linearisation is exact, so the backward pass's `s_0` is the exact expected
//! cost of the closed loop `u = ū + L (x − x̄)`. It is checked against
//! * a seeded Monte Carlo estimate of that closed loop (within 3 standard errors),
//! * an exact moment recursion written here, and
//! * the exact dynamic-programming gains of the multiplicative-noise LQ problem.

use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use vic_core::cost::{Cost, CostDerivatives};
use vic_core::dynamics::{Dynamics, Linearization, NoiseKind};
use vic_core::solver::{Bounds, Ilqg, IlqgOptions, Problem, Solution};

const HORIZON: usize = 30;
const TRIALS: usize = 50_000;

/// Plant and cost parameters.
#[derive(Clone, Copy)]
struct Params {
    a: f64,
    b: f64,
    c0: f64,
    c1: f64,
    /// Running state weight, control weight and final weight: `ℓ = ½ q (x − r_k)² + ½ ρ u²`,
    /// `g = ½ q_f (x − r_N)²`.
    q: f64,
    rho: f64,
    qf: f64,
    x0: f64,
}

const PARAMS: Params = Params {
    a: 1.05,
    b: 0.2,
    c0: 0.1,
    c1: 0.3,
    q: 1.0,
    rho: 0.5,
    qf: 10.0,
    x0: 1.0,
};

/// The reference: hold, then step to 0.5 half-way.
fn reference(k: usize) -> f64 {
    if k < HORIZON / 2 { 0.0 } else { 0.5 }
}

struct ScalarPlant(Params);

impl Dynamics for ScalarPlant {
    fn nx(&self) -> usize {
        1
    }
    fn nu(&self) -> usize {
        1
    }
    fn nw(&self) -> usize {
        1
    }
    fn step(&self, _k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        next[0] = self.0.a * x[0] + self.0.b * u[0];
    }
    fn noise_gain(&self, _k: usize, x: &[f64], _u: &[f64], out: &mut DMatrix<f64>) {
        out[(0, 0)] = self.0.c0 + self.0.c1 * x[0];
    }
    fn linearize(&self, _k: usize, x: &[f64], _u: &[f64], lin: &mut Linearization) {
        lin.a[(0, 0)] = self.0.a;
        lin.b[(0, 0)] = self.0.b;
        lin.c[(0, 0)] = self.0.c0 + self.0.c1 * x[0];
        lin.cx[0][(0, 0)] = self.0.c1;
        lin.cu[0][(0, 0)] = 0.0;
        lin.noise = NoiseKind::Dependent;
    }
}

struct ScalarCost(Params);

impl Cost for ScalarCost {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        0.5 * self.0.q * (x[0] - reference(k)).powi(2) + 0.5 * self.0.rho * u[0] * u[0]
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        0.5 * self.0.qf * (x[0] - reference(HORIZON)).powi(2)
    }
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        d.lx[0] = self.0.q * (x[0] - reference(k));
        d.lu[0] = self.0.rho * u[0];
        d.lxx[(0, 0)] = self.0.q;
        d.luu[(0, 0)] = self.0.rho;
        d.lux[(0, 0)] = 0.0;
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives) {
        d.lx[0] = self.0.qf * (x[0] - reference(HORIZON));
        d.lxx[(0, 0)] = self.0.qf;
    }
}

fn solve(p: Params) -> Solution {
    let (plant, cost) = (ScalarPlant(p), ScalarCost(p));
    let problem = Problem {
        dynamics: &plant,
        cost: &cost,
        x0: vec![p.x0],
        horizon: HORIZON,
        bounds: Bounds::unbounded(1),
    };
    let mut solver = Ilqg::new(&problem, IlqgOptions::default());
    solver.solve(&problem, &vec![DVector::zeros(1); HORIZON])
}

/// Nominal and gains of a solution as plain numbers.
fn policy(sol: &Solution) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    (
        sol.x.iter().map(|x| x[0]).collect(),
        sol.u.iter().map(|u| u[0]).collect(),
        sol.gains.iter().map(|l| l[(0, 0)]).collect(),
    )
}

/// Exact expected cost of `u = ū + L (x − x̄)` on the plant with parameters `p`: the mean follows
/// the nominal and the variance `P' = (a + b L)² P + c1² P + (c0 + c1 x̄)²`.
fn exact_expected_cost(p: Params, xbar: &[f64], ubar: &[f64], gains: &[f64]) -> f64 {
    let mut var = 0.0;
    let mut total = 0.0;
    for k in 0..HORIZON {
        let (x, u, l) = (xbar[k], ubar[k], gains[k]);
        total += 0.5 * p.q * ((x - reference(k)).powi(2) + var);
        total += 0.5 * p.rho * (u * u + l * l * var);
        let acl = p.a + p.b * l;
        var = acl * acl * var + p.c1 * p.c1 * var + (p.c0 + p.c1 * x).powi(2);
    }
    total + 0.5 * p.qf * ((xbar[HORIZON] - reference(HORIZON)).powi(2) + var)
}

#[test]
fn gains_are_the_exact_dynamic_programming_gains() {
    // V_k(x) = ½ S_k x² + s_k x + σ_k; E V(a x + b u + (c0 + c1 x) ε) adds ½ S (c0 + c1 x)², so
    // S picks up c1² S and the optimal gain is −a b S / (ρ + b² S).
    let p = PARAMS;
    let sol = solve(p);
    assert!(sol.stop.converged(), "stopped with {:?}", sol.stop);
    let mut s = p.qf;
    for k in (0..HORIZON).rev() {
        let gain = -p.a * p.b * s / (p.rho + p.b * p.b * s);
        let l = sol.gains[k][(0, 0)];
        assert!(
            (l - gain).abs() <= 1e-9 * gain.abs(),
            "L_{k} = {l}, expected {gain}"
        );
        s = p.q + p.a * p.a * s + p.c1 * p.c1 * s + p.a * p.b * s * gain;
    }
}

#[test]
fn predicted_expected_cost_is_the_exact_one() {
    let p = PARAMS;
    let sol = solve(p);
    assert!(sol.stop.converged(), "stopped with {:?}", sol.stop);
    let (xbar, ubar, gains) = policy(&sol);
    let exact = exact_expected_cost(p, &xbar, &ubar, &gains);
    assert!(
        (sol.expected_cost - exact).abs() <= 1e-9 * exact,
        "predicted {} vs exact {exact}",
        sol.expected_cost
    );
}

#[test]
fn predicted_expected_cost_matches_monte_carlo() {
    let p = PARAMS;
    let sol = solve(p);
    assert!(sol.stop.converged(), "stopped with {:?}", sol.stop);
    let (xbar, ubar, gains) = policy(&sol);
    let (plant, cost) = (ScalarPlant(p), ScalarCost(p));

    let mut rng = StdRng::seed_from_u64(2024);
    let (mut sum, mut sum_sq) = (0.0, 0.0);
    for _ in 0..TRIALS {
        let mut x = p.x0;
        let mut c = 0.0;
        for k in 0..HORIZON {
            let u = ubar[k] + gains[k] * (x - xbar[k]);
            c += cost.running(k, &[x], &[u]);
            let eps: f64 = rng.sample(StandardNormal);
            // x' = a x + b u + (c0 + c1 x) ε, written out rather than through the plant's methods.
            let next = p.a * x + p.b * u + (p.c0 + p.c1 * x) * eps;
            // The plant's own step and noise gain describe the same transition.
            let mut det = [0.0];
            plant.step(k, &[x], &[u], &mut det);
            let mut g = DMatrix::zeros(1, 1);
            plant.noise_gain(k, &[x], &[u], &mut g);
            assert!((det[0] + g[(0, 0)] * eps - next).abs() <= 1e-12 * (1.0 + next.abs()));
            x = next;
        }
        c += cost.terminal(&[x]);
        sum += c;
        sum_sq += c * c;
    }
    let n = TRIALS as f64;
    let mean = sum / n;
    let se = ((sum_sq / n - mean * mean) * n / (n - 1.0) / n).sqrt();
    let predicted = sol.expected_cost;
    eprintln!(
        "predicted {predicted:.6}, deterministic {:.6}, Monte Carlo {mean:.6} ± {se:.6}",
        sol.cost
    );
    assert!(
        (predicted - mean).abs() <= 3.0 * se,
        "predicted {predicted}, Monte Carlo {mean} ± {se} (standard error), {TRIALS} trials"
    );

    // The check has power: the noise adds far more than the Monte Carlo uncertainty, and a
    // prediction that ignored the state-dependence of the noise (c1 = 0) would be rejected.
    assert!(
        predicted - sol.cost > 20.0 * se,
        "noise cost {} vs standard error {se}",
        predicted - sol.cost
    );
    let additive_only = exact_expected_cost(Params { c1: 0.0, ..p }, &xbar, &ubar, &gains);
    assert!(
        (additive_only - mean).abs() > 6.0 * se,
        "additive-only prediction {additive_only} is indistinguishable from {mean} ± {se}"
    );
}
