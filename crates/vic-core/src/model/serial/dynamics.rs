//! Rigid-body dynamics of a serial chain, generic over [`Scalar`] so that dual numbers give exact
//! derivatives: the recursive Newton–Euler algorithm (inverse dynamics), the composite rigid body
//! algorithm (the mass matrix) and forward dynamics by an `L D Lᵀ` factorisation (Cholesky's
//! without square roots). Everything lives on the stack in arrays of [`MAX_DOF`] joints.
//!
//! Vectors are in the frame of the joint they belong to; a joint's frame is its child link's
//! frame, its axis passes through the origin. `R_i` turns joint `i`'s frame into its parent's,
//! `r_i` is joint `i`'s origin in the parent's frame (a constant: the rotation follows it).

use super::MAX_DOF;
use super::chain::Chain;
use crate::scalar::{Scalar, c};

type V<S> = [S; 3];
type M3<S> = [[S; 3]; 3];
/// A square matrix over the chain's joints (the first `dof` rows and columns used).
pub(crate) type Square<S> = [[S; MAX_DOF]; MAX_DOF];

fn zero3<S: Scalar>() -> V<S> {
    [S::zero(); 3]
}

fn lift<S: Scalar>(v: &[f64; 3]) -> V<S> {
    [c(v[0]), c(v[1]), c(v[2])]
}

fn add<S: Scalar>(a: V<S>, b: V<S>) -> V<S> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn cross<S: Scalar>(a: &V<S>, b: &V<S>) -> V<S> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a × b` with a constant `b`.
fn cross_c<S: Scalar>(a: &V<S>, b: &[f64; 3]) -> V<S> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a × b` with a constant `a`.
fn c_cross<S: Scalar>(a: &[f64; 3], b: &V<S>) -> V<S> {
    [
        b[2] * a[1] - b[1] * a[2],
        b[0] * a[2] - b[2] * a[0],
        b[1] * a[0] - b[0] * a[1],
    ]
}

/// `m v` with a constant `v`.
fn mul_vc<S: Scalar>(m: &M3<S>, v: &[f64; 3]) -> V<S> {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// `a · b` with a constant `a`.
fn dot_c<S: Scalar>(a: &[f64; 3], b: &V<S>) -> S {
    b[0] * a[0] + b[1] * a[1] + b[2] * a[2]
}

fn scale_c<S: Scalar>(a: &[f64; 3], s: S) -> V<S> {
    [s * a[0], s * a[1], s * a[2]]
}

/// `m v`.
fn mul<S: Scalar>(m: &M3<S>, v: &V<S>) -> V<S> {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// `mᵀ v`.
fn mul_t<S: Scalar>(m: &M3<S>, v: &V<S>) -> V<S> {
    [0, 1, 2].map(|i| m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2])
}

/// `m v` with a constant `m`.
fn mul_c<S: Scalar>(m: &[[f64; 3]; 3], v: &V<S>) -> V<S> {
    [0, 1, 2].map(|i| v[0] * m[i][0] + v[1] * m[i][1] + v[2] * m[i][2])
}

/// The parts of `R(q) = R₀ Rot(a, q) = cos q (R₀ − P) + P + sin q Q` with `P = R₀ a aᵀ` and
/// `Q = R₀ [a]×` (Rodrigues' formula): `[R₀ − P, P, Q]`, computed once per joint.
pub(crate) fn rotation_parts(r0: &[[f64; 3]; 3], a: &[f64; 3]) -> [[[f64; 3]; 3]; 3] {
    let skew = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]];
    let mut parts = [[[0.0; 3]; 3]; 3];
    for i in 0..3 {
        let r0a: f64 = (0..3).map(|k| r0[i][k] * a[k]).sum();
        for j in 0..3 {
            parts[1][i][j] = r0a * a[j];
            parts[0][i][j] = r0[i][j] - parts[1][i][j];
            parts[2][i][j] = (0..3).map(|k| r0[i][k] * skew[k][j]).sum();
        }
    }
    parts
}

/// `R_i(q_i)` for every joint, what the algorithms below share for one configuration.
pub(crate) type Rotations<S> = [M3<S>; MAX_DOF];

/// `R_i(q_i)` for every joint.
pub(crate) fn rotations<S: Scalar>(chain: &Chain, q: &[S]) -> Rotations<S> {
    let mut out = [[[S::zero(); 3]; 3]; MAX_DOF];
    for (i, j) in chain.joints.iter().enumerate() {
        let (s, cq) = q[i].sin_cos();
        let [pc, p, ps] = &j.rotation_parts;
        for r in 0..3 {
            for k in 0..3 {
                out[i][r][k] = cq * pc[r][k] + s * ps[r][k] + p[r][k];
            }
        }
    }
    out
}

/// The recursive Newton–Euler algorithm: the joint torques `τ = M(q) q'' + C(q, q') + g(q)`
/// (+ `B q'`, the joints' viscous damping, when `damping`) for gravity `gravity` [m/s²] in the
/// base frame. Base at rest; gravity enters as an upward acceleration of the base.
pub(crate) fn rnea<S: Scalar>(
    chain: &Chain,
    gravity: &[f64; 3],
    rot: &Rotations<S>,
    qd: &[S],
    qdd: &[S],
    damping: bool,
) -> [S; MAX_DOF] {
    let n = chain.joints.len();
    let (mut w, mut al) = (zero3::<S>(), zero3::<S>());
    let mut a: V<S> = lift(&gravity.map(|g| -g));
    let mut f = [zero3::<S>(); MAX_DOF];
    let mut m = [zero3::<S>(); MAX_DOF];
    for (i, j) in chain.joints.iter().enumerate() {
        let (r, ax, body) = (&j.origin.pos, &j.axis, &j.body);
        // The origin's acceleration, then the angular velocity and acceleration, in frame i.
        let t = add(add(a, cross_c(&al, r)), cross(&w, &cross_c(&w, r)));
        a = mul_t(&rot[i], &t);
        let wp = mul_t(&rot[i], &w);
        let spin = scale_c(ax, qd[i]);
        w = add(wp, spin);
        al = add(
            add(mul_t(&rot[i], &al), scale_c(ax, qdd[i])),
            cross(&wp, &spin),
        );
        // Newton and Euler about the origin: f = m a + α × h + ω × (ω × h),
        // n = I α + ω × (I ω) + h × a.
        let h = &body.first_moment;
        let wh = cross_c(&w, h);
        f[i] = add(
            add(
                [a[0] * body.mass, a[1] * body.mass, a[2] * body.mass],
                cross_c(&al, h),
            ),
            cross(&w, &wh),
        );
        let iw = mul_c(&body.inertia, &w);
        let ha = c_cross(h, &a);
        m[i] = add(add(mul_c(&body.inertia, &al), cross(&w, &iw)), ha);
    }
    let mut tau = [S::zero(); MAX_DOF];
    for i in (0..n).rev() {
        let j = &chain.joints[i];
        tau[i] = dot_c(&j.axis, &m[i]);
        if damping {
            tau[i] += qd[i] * j.limits.damping;
        }
        if i > 0 {
            let rf = mul(&rot[i], &f[i]);
            let rn = add(mul(&rot[i], &m[i]), c_cross(&j.origin.pos, &rf));
            f[i - 1] = add(f[i - 1], rf);
            m[i - 1] = add(m[i - 1], rn);
        }
    }
    tau
}

/// The composite rigid body algorithm: the mass matrix `M(q)` (symmetric, `dof × dof`).
pub(crate) fn crba<S: Scalar>(chain: &Chain, rot: &Rotations<S>) -> Square<S> {
    let n = chain.joints.len();
    // Composite bodies (joint i and all below it) in frame i: mass, first moment, inertia.
    let mut cm = [0.0; MAX_DOF];
    let mut ch = [zero3::<S>(); MAX_DOF];
    let mut ci = [[zero3::<S>(); 3]; MAX_DOF];
    for (i, j) in chain.joints.iter().enumerate() {
        cm[i] = j.body.mass;
        ch[i] = lift(&j.body.first_moment);
        ci[i] = j.body.inertia.map(|row| lift(&row));
    }
    for i in (1..n).rev() {
        // Into the parent's frame: h' = R h + m r,
        // I' = R I Rᵀ + m (|r|² 1 − r rᵀ) + 2 (r · R h) 1 − R h rᵀ − r (R h)ᵀ.
        let (r, mass) = (&chain.joints[i].origin.pos, cm[i]);
        let rh = mul(&rot[i], &ch[i]);
        let mut ri = [zero3::<S>(); 3];
        for (a, row) in ri.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                *v = rot[i][a][0] * ci[i][0][b]
                    + rot[i][a][1] * ci[i][1][b]
                    + rot[i][a][2] * ci[i][2][b];
            }
        }
        let rr: f64 = r.iter().map(|v| v * v).sum();
        let r_rh = dot_c(r, &rh);
        for a in 0..3 {
            ch[i - 1][a] += rh[a] + c::<S>(mass * r[a]);
            for b in 0..3 {
                let rir =
                    ri[a][0] * rot[i][b][0] + ri[a][1] * rot[i][b][1] + ri[a][2] * rot[i][b][2];
                let delta = if a == b { 1.0 } else { 0.0 };
                let point = mass * (rr * delta - r[a] * r[b]);
                let cross_terms = r_rh * (2.0 * delta) - rh[a] * r[b] - rh[b] * r[a];
                ci[i - 1][a][b] += rir + cross_terms + point;
            }
        }
        cm[i - 1] += mass;
    }
    let mut mm = [[S::zero(); MAX_DOF]; MAX_DOF];
    for i in 0..n {
        // The force that accelerates composite i about its axis at a unit rate, carried up.
        let ax = &chain.joints[i].axis;
        let mut nv = mul_vc(&ci[i], ax);
        let mut fv = c_cross(ax, &ch[i]);
        mm[i][i] = dot_c(ax, &nv);
        for j in (1..=i).rev() {
            let rf = mul(&rot[j], &fv);
            nv = add(mul(&rot[j], &nv), c_cross(&chain.joints[j].origin.pos, &rf));
            fv = rf;
            mm[j - 1][i] = dot_c(&chain.joints[j - 1].axis, &nv);
            mm[i][j - 1] = mm[j - 1][i];
        }
    }
    mm
}

/// The `L D Lᵀ` factors of a symmetric `m` (`n × n`): `L` unit lower triangular, `D` diagonal
/// (all positive when `m` is positive definite).
pub(crate) fn ldl<S: Scalar>(m: &Square<S>, n: usize) -> (Square<S>, [S; MAX_DOF]) {
    let mut l = [[S::zero(); MAX_DOF]; MAX_DOF];
    let mut d = [S::zero(); MAX_DOF];
    for j in 0..n {
        let mut dj = m[j][j];
        for k in 0..j {
            dj -= l[j][k] * l[j][k] * d[k];
        }
        d[j] = dj;
        for i in j + 1..n {
            let mut v = m[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k] * d[k];
            }
            l[i][j] = v / dj;
        }
    }
    (l, d)
}

/// The pivots `D` of `m`'s `L D Lᵀ` factorisation.
pub(crate) fn ldl_pivots(m: &Square<f64>, n: usize) -> [f64; MAX_DOF] {
    ldl(m, n).1
}

/// Solves `m x = b` for a symmetric positive definite `m` (`n × n`) by `L D Lᵀ`.
pub(crate) fn solve<S: Scalar>(m: &Square<S>, n: usize, b: &[S]) -> [S; MAX_DOF] {
    let (l, d) = ldl(m, n);
    solve_factored(&l, &d, n, b)
}

/// Solves `L D Lᵀ x = b` with the factors of [`ldl`].
pub(crate) fn solve_factored<S: Scalar>(
    l: &Square<S>,
    d: &[S; MAX_DOF],
    n: usize,
    b: &[S],
) -> [S; MAX_DOF] {
    let mut x = [S::zero(); MAX_DOF];
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i][k] * x[k];
        }
        x[i] = v;
    }
    for i in 0..n {
        x[i] = x[i] / d[i];
    }
    for i in (0..n).rev() {
        let mut v = x[i];
        for k in i + 1..n {
            v -= l[k][i] * x[k];
        }
        x[i] = v;
    }
    x
}

/// Every joint's frame in the base frame: `(rotation, origin)`, and the tip's last.
fn frames<S: Scalar>(chain: &Chain, q: &[S]) -> ([M3<S>; MAX_DOF + 1], [V<S>; MAX_DOF + 1]) {
    let rot = rotations(chain, q);
    let mut rs = [[zero3::<S>(); 3]; MAX_DOF + 1];
    let mut ps = [zero3::<S>(); MAX_DOF + 1];
    let mut r: M3<S> = [0, 1, 2].map(|i| [0, 1, 2].map(|j| c(if i == j { 1.0 } else { 0.0 })));
    let mut p = zero3::<S>();
    let n = chain.joints.len();
    for i in 0..=n {
        let offset = if i < n {
            &chain.joints[i].origin.pos
        } else {
            &chain.tip.pos
        };
        p = add(p, mul_vc(&r, offset));
        let local: M3<S> = if i < n {
            rot[i]
        } else {
            chain.tip.rot.map(|row| lift(&row))
        };
        let mut next = [zero3::<S>(); 3];
        for (a, row) in next.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                *v = r[a][0] * local[0][b] + r[a][1] * local[1][b] + r[a][2] * local[2][b];
            }
        }
        r = next;
        rs[i] = r;
        ps[i] = p;
    }
    (rs, ps)
}

/// The tip link's origin in the base frame [m].
pub(crate) fn tip_position<S: Scalar>(chain: &Chain, q: &[S]) -> [S; 3] {
    frames(chain, q).1[chain.joints.len()]
}

/// The potential energy in gravity `gravity` [J], zero with every centre of mass at the base's
/// origin: `V = −g · Σ (m_i p_i + R_i h_i)`.
pub(crate) fn potential_energy<S: Scalar>(chain: &Chain, gravity: &[f64; 3], q: &[S]) -> S {
    let (rs, ps) = frames(chain, q);
    let mut v = S::zero();
    for (i, j) in chain.joints.iter().enumerate() {
        let com = mul_vc(&rs[i], &j.body.first_moment);
        let moment = [0, 1, 2].map(|k| ps[i][k] * j.body.mass + com[k]);
        v -= dot_c(gravity, &moment);
    }
    v
}
