//! The flow's second and third derivatives along single directions (univariate Taylor
//! polynomials; Griewank, Utke & Walther, Math. Comp. 2000): `dA_j` and `∂²Φ/∂u∂u` for
//! [`MomentDynamics::expand`](super::MomentDynamics::expand), and the costate-contracted third
//! derivatives `h3` for [`MomentDynamics::second_order`](super::MomentDynamics::second_order).
//! Several directions share one flow on a [`Taylor`], which computes the model's real part
//! (and every sine, cosine and reciprocal) once for all of them; the partial derivatives are
//! recovered from combinations of directions.

use super::derivatives::At;
use super::{MomentExpansion, lift};
use crate::dense::zero;
use crate::dynamics::Dynamics;
use crate::scalar::{MAX_NU, MAX_NX};
use crate::taylor::Taylor;
#[cfg(test)]
use num_dual::{Dual, Dual64};

/// The largest number of variables `v = (x, u)` of one knot.
const MAX_NV: usize = MAX_NX + MAX_NU;

/// `dA_j = ∂A/∂(m,u)_j` (column `i` of `dA_j` is `∂²Φ/∂v_j∂x_i`) and `∂²Φ/∂u_a∂u_b` into
/// `s.phi_uu`, from second derivatives of the flow along single directions: `w = e_a` gives
/// `∂_aa`, and `w = e_a + e_b` gives `∂_aa + 2 ∂_ab + ∂_bb`, hence `∂_ab`. [`LANES2`]
/// directions share one flow on a [`Taylor`] of order 2 (as [`flow_third_contracted`] does at
/// order 3): `nv (nv + 1) / 2` directions in `⌈nv (nv + 1) / 24⌉` flows, where nested duals
/// (`Dual<Dual64>`) take one flow per entry. An entry `∂_ab` is a combination of three
/// directions, so its rounding is relative to the largest of them (1e-15), not bit for bit that
/// of the nested duals.
pub(super) fn flow_second_derivatives(at: At, s: &mut MomentExpansion) {
    let n = at.base.nx();
    let nv = n + at.base.nu();
    let mut dirs = [Direction::default(); MAX_DIRECTIONS];
    let count = second_order_directions(nv, &mut dirs);
    let mut d2 = [[0.0; MAX_NX]; MAX_DIRECTIONS];
    directional::<2, LANES2>(at, &dirs[..count], &mut d2, None);
    // `second_order_directions` lists `e_a + e_b` after the `nv` directions `e_a`.
    store_second(s, n, nv, &d2, |pair| nv + pair);
    s.d3_ready = false;
}

/// [`flow_second_derivatives`] and the directional third derivatives that
/// [`flow_third_contracted`] contracts (into `s.d3`), from the third-order flows alone: the
/// directions `e_a` and `e_a + e_b` of the second derivatives are among the third-order ones,
/// and a [`Taylor`] of order 3 carries the second-order coefficient exactly as one of order 2
/// does (the same operations, lane by lane), so the second derivatives are
/// [`flow_second_derivatives`]'s bit for bit and its separate order-2 flows are saved.
pub(super) fn flow_second_and_third(at: At, s: &mut MomentExpansion) {
    let n = at.base.nx();
    let nv = n + at.base.nu();
    let mut dirs = [Direction::default(); MAX_DIRECTIONS];
    let count = directions(n, nv, &mut dirs);
    let mut d2 = [[0.0; MAX_NX]; MAX_DIRECTIONS];
    directional::<3, LANES>(at, &dirs[..count], &mut s.d3[..count], Some(&mut d2));
    // `directions` lists `e_a + e_b` (then `e_a − e_b`) after the `nv` directions `e_a`.
    store_second(s, n, nv, &d2, |pair| nv + 2 * pair);
    s.d3_ready = true;
    s.d3_at = at.point();
}

/// `dA_j` and `∂²Φ/∂u_a∂u_b` from the second derivatives `d2` along `e_a` (row `a`) and
/// `e_a + e_b` (row `plus(p)` for the `p`-th pair `a < b` in lexicographic order).
fn store_second(
    s: &mut MomentExpansion,
    n: usize,
    nv: usize,
    d2: &[[f64; MAX_NX]],
    plus: impl Fn(usize) -> usize,
) {
    let mut put = |a: usize, b: usize, d: &[f64; MAX_NX]| {
        for (r, &v) in d[..n].iter().enumerate() {
            if b < n {
                s.da[a][(r, b)] = v;
            }
            if a < n {
                s.da[b][(r, a)] = v;
            }
            if a >= n && b >= n {
                s.phi_uu[a - n][b - n][r] = v;
                s.phi_uu[b - n][a - n][r] = v;
            }
        }
    };
    let mut pair = 0;
    for a in 0..nv {
        put(a, a, &d2[a]);
        for b in a + 1..nv {
            let mut d = [0.0; MAX_NX];
            for r in 0..n {
                d[r] = (d2[plus(pair)][r] - d2[a][r] - d2[b][r]) / 2.0;
            }
            pair += 1;
            put(a, b, &d);
        }
    }
}

/// How many directions [`flow_third_contracted`] takes the flow along for `n` states and `nv`
/// variables (the length [`crate::solver::sooc::MomentExpansion`] sizes `d3` for).
pub(super) fn third_order_direction_count(n: usize, nv: usize) -> usize {
    let mut dirs = [Direction::default(); MAX_DIRECTIONS];
    directions(n, nv, &mut dirs)
}

/// `s.h3 = 2 Σ_{r,c} T_{rc} ∂³Φ_r/∂x_c∂v_a∂v_b` with `T = s.t2`, from third derivatives of the
/// flow along single directions (univariate Taylor polynomials; Griewank, Utke & Walther, Math.
/// Comp. 2000). Along `w` the flow gives `D³Φ[w] = Σ_{ijk} ∂³Φ/∂v_i∂v_j∂v_k w_i w_j w_k`, so
///
/// * `w = e_a` gives `∂_aaa`;
/// * `w = e_a ± e_b` give `∂_aaa ± 3 ∂_aab + 3 ∂_abb ± ∂_bbb`, hence `∂_aab` and `∂_abb`;
/// * `w = e_a + e_b + e_c` gives `6 ∂_abc` plus entries already known.
///
/// The directions go through the flow [`LANES`] at a time on one [`Taylor`] of order 3, which
/// computes the real part (and every sine, cosine and reciprocal of the model) once for all of them:
/// where a triple-nested dual (`Dual<Dual<Dual64>>`, one flow per entry) carries eight numbers
/// and multiplies with 27 products, a lane carries three derivatives and 11 products. The
/// entries are combinations of a few directions, so their rounding is that of the largest
/// term combined (relative 1e-15 of it), not the nested duals' bits. The directional
/// derivatives are those [`flow_second_and_third`] kept in `s.d3` at this point if it ran,
/// computed here otherwise.
pub(super) fn flow_third_contracted(at: At, s: &mut MomentExpansion) {
    let n = at.base.nx();
    let nv = n + at.base.nu();
    let mut dirs = [Direction::default(); MAX_DIRECTIONS];
    let count = directions(n, nv, &mut dirs);
    if !s.d3_ready {
        directional::<3, LANES>(at, &dirs[..count], &mut s.d3[..count], None);
        s.d3_ready = true;
        s.d3_at = at.point();
    }
    // Moved out for the loop (no allocation), back at the end.
    let d3 = std::mem::take(&mut s.d3);
    // Back from the directions to the entries, in the order `directions` lists them.
    zero(&mut s.h3);
    let mut next = d3.iter();
    // cube[a] = ∂_aaa; pair[a][b] = ∂_aab (a ≠ b), each a row per state.
    let mut cube = [[0.0; MAX_NX]; MAX_NV];
    let mut pair = [[[0.0; MAX_NX]; MAX_NV]; MAX_NV];
    for a in 0..nv {
        cube[a] = *next.next().expect("one direction per cube");
        if a < n {
            contract_triple(s, n, [a, a, a], &cube[a][..n]);
        }
    }
    for a in 0..nv {
        for b in a + 1..nv {
            let plus = next.next().expect("e_a + e_b");
            let minus = next.next().expect("e_a - e_b");
            for r in 0..n {
                pair[a][b][r] = (plus[r] - minus[r] - 2.0 * cube[b][r]) / 6.0;
                pair[b][a][r] = (plus[r] + minus[r] - 2.0 * cube[a][r]) / 6.0;
            }
            // The states come first in v: a multiset has a state index iff its smallest does.
            if a < n {
                contract_triple(s, n, [a, a, b], &pair[a][b][..n]);
                contract_triple(s, n, [a, b, b], &pair[b][a][..n]);
            }
        }
    }
    let mut d = [0.0; MAX_NX];
    for a in 0..n.min(nv) {
        for b in a + 1..nv {
            for c in b + 1..nv {
                let sum = next.next().expect("e_a + e_b + e_c");
                for r in 0..n {
                    let known = cube[a][r]
                        + cube[b][r]
                        + cube[c][r]
                        + 3.0
                            * (pair[a][b][r]
                                + pair[b][a][r]
                                + pair[a][c][r]
                                + pair[c][a][r]
                                + pair[b][c][r]
                                + pair[c][b][r]);
                    d[r] = (sum[r] - known) / 6.0;
                }
                contract_triple(s, n, [a, b, c], &d[..n]);
            }
        }
    }
    s.d3 = d3;
}

/// Directions a [`Taylor`] carries through one flow: enough to fill SIMD registers several
/// times over, few enough that the lanes of a partly filled last flow cost little.
const LANES: usize = 8;

/// Directions a second-order [`Taylor`] carries through one flow: the `nv (nv + 1) / 2 = 36`
/// directions of the type-2 arm (`nv = 8`) in three flows with none empty (eight lanes: five
/// flows, four lanes empty), and the single joint's ten in one.
const LANES2: usize = 12;

/// The most directions [`directions`] lists: `nv + nv (nv − 1) + C(nv, 3)` at `nv = 12`.
const MAX_DIRECTIONS: usize =
    MAX_NV + MAX_NV * (MAX_NV - 1) + MAX_NV * (MAX_NV - 1) * (MAX_NV - 2) / 6;

/// A direction `w = Σ_j weight_j e_{index_j}` over `v = (x, u)` with at most three terms.
#[derive(Clone, Copy, Default)]
struct Direction {
    index: [usize; 3],
    weight: [f64; 3],
    len: usize,
}

/// Lists into `out` the directions [`flow_third_contracted`] needs, in the order it reads them
/// back: `e_a` for every `a`; `e_a + e_b`, `e_a − e_b` for every `a < b`; `e_a + e_b + e_c` for
/// every `a < b < c` with `a` a state. Returns how many.
fn directions(n: usize, nv: usize, out: &mut [Direction; MAX_DIRECTIONS]) -> usize {
    let mut count = 0;
    let mut push = |index: &[usize], weights: &[f64]| {
        out[count] = Direction::along(index, weights);
        count += 1;
    };
    for a in 0..nv {
        push(&[a], &[1.0]);
    }
    for a in 0..nv {
        for b in a + 1..nv {
            push(&[a, b], &[1.0, 1.0]);
            push(&[a, b], &[1.0, -1.0]);
        }
    }
    for a in 0..n.min(nv) {
        for b in a + 1..nv {
            for c in b + 1..nv {
                push(&[a, b, c], &[1.0, 1.0, 1.0]);
            }
        }
    }
    count
}

/// Lists into `out` the directions [`flow_second_derivatives`] needs, in the order it reads
/// them back: `e_a` for every `a`, then `e_a + e_b` for every `a < b`. Returns how many.
fn second_order_directions(nv: usize, out: &mut [Direction; MAX_DIRECTIONS]) -> usize {
    let mut count = 0;
    let mut push = |index: &[usize], weights: &[f64]| {
        out[count] = Direction::along(index, weights);
        count += 1;
    };
    for a in 0..nv {
        push(&[a], &[1.0]);
    }
    for a in 0..nv {
        for b in a + 1..nv {
            push(&[a, b], &[1.0, 1.0]);
        }
    }
    count
}

impl Direction {
    /// `Σ_j weights_j e_{index_j}` (at most three terms).
    fn along(index: &[usize], weights: &[f64]) -> Self {
        let mut d = Direction {
            len: index.len(),
            ..Direction::default()
        };
        d.index[..index.len()].copy_from_slice(index);
        d.weight[..weights.len()].copy_from_slice(weights);
        d
    }
}

/// The `ORDER`-th derivative of the flow along each of `dirs` into `out` (one row per
/// direction, one entry per state), and the second into `second` if given; `L` directions to
/// a flow on one [`Taylor`].
fn directional<const ORDER: usize, const L: usize>(
    at: At,
    dirs: &[Direction],
    out: &mut [[f64; MAX_NX]],
    mut second: Option<&mut [[f64; MAX_NX]]>,
) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let (mut xt, mut ut) = lift::<Taylor<L, ORDER>>(x, u);
    let mut flow = [Taylor::<L, ORDER>::constant(0.0); MAX_NX];
    for (first, chunk) in dirs.chunks(L).enumerate() {
        let first = first * L;
        for (l, d) in chunk.iter().enumerate() {
            for j in 0..d.len {
                lane(&mut xt, &mut ut, n, d.index[j])[l] = d.weight[j];
            }
        }
        base.flow(k, &xt[..n], &ut[..m], &mut flow[..n]);
        for (l, d) in chunk.iter().enumerate() {
            for j in 0..d.len {
                lane(&mut xt, &mut ut, n, d.index[j])[l] = 0.0;
            }
            for (r, o) in flow[..n].iter().enumerate() {
                out[first + l][r] = o.v[ORDER - 1][l];
            }
            if let Some(second) = second.as_deref_mut() {
                for (r, o) in flow[..n].iter().enumerate() {
                    second[first + l][r] = o.v[1][l];
                }
            }
        }
    }
}

/// The first-derivative lanes of entry `j` of `v = (x, u)`.
fn lane<'a, const ORDER: usize, const L: usize>(
    x: &'a mut [Taylor<L, ORDER>],
    u: &'a mut [Taylor<L, ORDER>],
    n: usize,
    j: usize,
) -> &'a mut [f64; L] {
    if j < n {
        &mut x[j].v[0]
    } else {
        &mut u[j - n].v[0]
    }
}

/// The same contraction as [`flow_third_contracted`] by triple-nested dual numbers (seeds: `x_c`
/// outermost, `v_a`, `v_b`), one flow per distinct triple: the independent reference its tests
/// compare against.
#[cfg(test)]
fn flow_third_contracted_nested(at: At, s: &mut MomentExpansion) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let nv = n + m;
    let (mut x3, mut u3) = lift::<Dual<Dual<Dual64>>>(x, u);
    let mut out = [Dual::from_re(Dual::from_re(Dual64::from(0.0))); MAX_NX];
    zero(&mut s.h3);
    let mut d = [0.0; MAX_NX];
    for a in 0..nv {
        for b in a..nv {
            for c in 0..n.min(a + 1) {
                seed3(&mut x3, &mut u3, n, [c, a, b], 1.0);
                base.flow(k, &x3[..n], &u3[..m], &mut out[..n]);
                seed3(&mut x3, &mut u3, n, [c, a, b], 0.0);
                for (dr, o) in d.iter_mut().zip(&out[..n]) {
                    *dr = o.eps.eps.eps;
                }
                contract_triple(s, n, [c, a, b], &d[..n]);
            }
        }
    }
}

#[cfg(test)]
/// Seeds (or clears) the three levels of a triple-nested dual: `x_c` outermost, then `v_a`, `v_b`.
fn seed3(
    x: &mut [Dual<Dual<Dual64>>],
    u: &mut [Dual<Dual<Dual64>>],
    n: usize,
    [c, a, b]: [usize; 3],
    value: f64,
) {
    x[c].eps = Dual::from_re(Dual64::from(value));
    if a < n {
        x[a].re.eps = Dual64::from(value);
    } else {
        u[a - n].re.eps = Dual64::from(value);
    }
    if b < n {
        x[b].re.re.eps = value;
    } else {
        u[b - n].re.re.eps = value;
    }
}

/// Adds `2 Σ_r T_{r c'} d_r` to `h3[a', b']` for every distinct ordering `(c', a', b')` of the
/// triple whose `c'` is a state index (`d_r = ∂³Φ_r` along the triple, `T = s.t2`).
fn contract_triple(s: &mut MomentExpansion, n: usize, [c, a, b]: [usize; 3], d: &[f64]) {
    let orders = [
        [c, a, b],
        [c, b, a],
        [a, c, b],
        [a, b, c],
        [b, c, a],
        [b, a, c],
    ];
    for (i, o) in orders.iter().enumerate() {
        if o[0] >= n || orders[..i].contains(o) {
            continue;
        }
        let w: f64 = d
            .iter()
            .enumerate()
            .map(|(r, dr)| s.t2[(r, o[0])] * dr)
            .sum();
        s.h3[(o[1], o[2])] += 2.0 * w;
    }
}

#[cfg(test)]
mod tests {
    use super::super::MomentDynamics;
    use super::super::derivatives::{seed_inner, seed_outer};
    use super::*;
    use crate::dynamics::DiscreteDynamics;
    use crate::dynamics::Integrator;
    use crate::model::Plant;
    use crate::model::plant::tests::{arm, joint};
    use crate::model::{Actuator, ArmModel, Damping, Exogenous, Field, Noise};

    fn discretised(plant: Plant, actuator: Actuator, field: Field) -> DiscreteDynamics {
        let exo = Exogenous {
            q_d: [0.4, 1.2],
            qd_d: [0.3, -0.2],
            tau_ext: [0.1, -0.05],
        };
        // The first joint's velocity drives the noise (the paper's σ q1' I).
        let component = plant.dof();
        DiscreteDynamics {
            model: ArmModel {
                plant,
                actuator,
                field,
                noise: Noise::StateProportional {
                    sigma: 0.3,
                    component,
                },
            },
            dt: 0.01,
            substeps: 10,
            integrator: Integrator::SemiImplicit,
            exogenous: vec![exo; 3],
        }
    }

    /// The two-link arm's three actuators in the divergent field and the single joint.
    fn cases() -> [(&'static str, DiscreteDynamics); 4] {
        let impedance = Actuator::Impedance {
            damping: Damping::Proportional { alpha: 0.1 },
        };
        let vsa = Actuator::Vsa {
            motor_inertia: vec![0.05, 0.05],
        };
        let divergent = Field::Divergent { beta: 200.0 };
        [
            ("two-link torque", arm(), Actuator::Torque, divergent),
            ("two-link impedance", arm(), impedance.clone(), divergent),
            ("two-link VSA", arm(), vsa, divergent),
            ("single-joint impedance", joint(), impedance, Field::None),
        ]
        .map(|(what, plant, actuator, field)| (what, discretised(plant, actuator, field)))
    }

    /// `dA_j` and `∂²Φ/∂u∂u` from second-order directions agree with nested duals seeded on
    /// each pair `(v_a, v_b)` (every entry its own derivative arithmetic, no combination), to
    /// the rounding of the combinations (relative 1e-11 of the largest entry).
    #[test]
    fn second_derivatives_from_directions_match_nested_duals() {
        for (what, base) in cases() {
            let (n, m) = (base.nx(), base.nu());
            let moments = MomentDynamics::new(&base);
            let x: Vec<f64> = (0..n).map(|i| 0.3 + 0.17 * i as f64).collect();
            let u: Vec<f64> = (0..m).map(|i| 2.0 + 3.0 * i as f64).collect();
            let mut z = vec![0.0; n + n * (n + 1) / 2];
            z[..n].copy_from_slice(&x);
            let mut s = MomentExpansion::for_dynamics(&moments);
            moments.expand(1, &z, &u, &mut s);
            let (mut x2, mut u2) = lift::<Dual<Dual64>>(&x, &u);
            let mut out = [Dual::from_re(Dual64::from(0.0)); MAX_NX];
            let (mut diff, mut scale) = (0.0f64, 0.0f64);
            for a in 0..n + m {
                for b in 0..n + m {
                    seed_inner(&mut x2, &mut u2, n, a, 1.0);
                    seed_outer(&mut x2, &mut u2, n, b, 1.0);
                    base.flow(1, &x2[..n], &u2[..m], &mut out[..n]);
                    seed_inner(&mut x2, &mut u2, n, a, 0.0);
                    seed_outer(&mut x2, &mut u2, n, b, 0.0);
                    for r in 0..n {
                        let ours = if b < n {
                            s.da[a][(r, b)]
                        } else if a >= n {
                            s.phi_uu[a - n][b - n][r]
                        } else {
                            continue; // ∂²Φ/∂x_a∂u_b is dA_b's column a, checked at (b, a)
                        };
                        let theirs = out[r].eps.eps;
                        diff = diff.max((ours - theirs).abs());
                        scale = scale.max(theirs.abs());
                    }
                }
            }
            eprintln!("{what}: largest difference {diff:e}, entries up to {scale:e}");
            assert!(scale > 0.0, "{what}: no second derivatives: vacuous");
            assert!(
                diff <= 1e-11 * scale,
                "{what}: largest difference {diff:e} against entries up to {scale:e}"
            );
        }
    }

    /// A moment state `z`, control `u` and costate `λ` away from any symmetry: stiffness
    /// positive, a diagonal-dominant covariance, costates of both signs.
    fn point(base: &DiscreteDynamics) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (n, m) = (base.nx(), base.nu());
        let nz = n + n * (n + 1) / 2;
        let mut z = vec![0.0; nz];
        for (i, zi) in z[..n].iter_mut().enumerate() {
            *zi = 0.3 + 0.17 * i as f64;
        }
        let u: Vec<f64> = (0..m).map(|i| 2.0 + 3.0 * i as f64).collect();
        let mut e = n;
        for a in 0..n {
            for b in a..n {
                z[e] = if a == b {
                    1e-2
                } else {
                    1e-3 * (a + 2 * b) as f64
                };
                e += 1;
            }
        }
        let lam: Vec<f64> = (0..nz).map(|i| ((i * 7 % 5) as f64 - 2.0) * 1e3).collect();
        (z, u, lam)
    }

    /// The second derivatives from the third-order flows ([`flow_second_and_third`]) are the
    /// second-order flows' bit for bit, and so are the moment step's first derivatives and the
    /// contraction that reuses the third derivatives computed with them.
    #[test]
    fn expanding_with_the_third_derivatives_changes_no_bit() {
        for (what, base) in cases() {
            let moments = MomentDynamics::new(&base);
            let (z, u, lam) = point(&base);
            let mut apart = MomentExpansion::for_dynamics(&moments);
            moments.expand(1, &z, &u, &mut apart);
            moments.second_order(1, &z, &u, &lam, true, &mut apart);
            let mut fused = MomentExpansion::for_dynamics(&moments);
            moments.expand_with_third(1, &z, &u, &mut fused);
            assert!(
                fused.d3_ready,
                "{what}: the third derivatives were not kept"
            );
            moments.second_order(1, &z, &u, &lam, true, &mut fused);
            assert_eq!(apart.a, fused.a, "{what}: ∂z⁺/∂z");
            assert_eq!(apart.b, fused.b, "{what}: ∂z⁺/∂u");
            assert_eq!(apart.da, fused.da, "{what}: dA_j");
            assert_eq!(apart.phi_uu, fused.phi_uu, "{what}: ∂²Φ/∂u∂u");
            assert_eq!(
                apart.h3, fused.h3,
                "{what}: the contracted third derivatives"
            );
            assert!(apart.h3.abs().max() > 0.0, "{what}: vacuous");
            // A plain expansion elsewhere drops them: the next contraction computes its own.
            let mut x2 = z.clone();
            x2[0] += 0.1;
            moments.expand(1, &x2, &u, &mut fused);
            assert!(
                !fused.d3_ready,
                "{what}: third derivatives of another point kept"
            );
        }
    }

    /// The contracted third derivatives from univariate Taylor polynomials agree with the
    /// triple-nested duals (one flow per entry, every entry its own derivative arithmetic) on
    /// the three actuators of the two-link arm in the divergent field and on the single joint,
    /// to the rounding of the combinations (relative 1e-9 of the largest entry).
    #[test]
    fn taylor_third_derivatives_match_nested_duals() {
        for (what, base) in cases() {
            let moments = MomentDynamics::new(&base);
            let (z, u, lam) = point(&base);
            let mut s = MomentExpansion::for_dynamics(&moments);
            moments.expand(1, &z, &u, &mut s);
            moments.second_order(1, &z, &u, &lam, true, &mut s);
            let taylor = s.h3.clone();
            flow_third_contracted_nested(At::new(&base, 1, &z, &u), &mut s);
            let nested = s.h3.clone();
            let scale = nested.abs().max();
            assert!(
                scale > 0.0,
                "{what}: no third derivatives: the test is vacuous"
            );
            let diff = (&taylor - &nested).abs().max();
            eprintln!("{what}: largest difference {diff:e}, entries up to {scale:e}");
            assert!(
                diff <= 1e-9 * scale,
                "{what}: largest difference {diff:e} against entries up to {scale:e}"
            );
        }
    }
}
