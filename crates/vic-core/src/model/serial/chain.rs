//! The kinematic chain of a URDF tree from a base link to a tip link: one body per moving joint,
//! each the links that move rigidly with it (fixed joints merged, joints off the chain held at
//! their zero position, as Pinocchio's reduced model locks them), in the joint's own frame.

use super::MAX_DOF;
use super::dynamics::{crba, ldl_pivots, rotation_parts, rotations};
use super::urdf::{Frame, Kind, Tree, UrdfError, UrdfReason, joint_name, link_name};

/// The mass properties of a rigid body in a frame: mass `m` [kg], first moment `h = m c` [kg m]
/// (`c` the centre of mass) and rotational inertia `I_o` about the frame's origin [kg m²].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Body {
    pub mass: f64,
    pub first_moment: [f64; 3],
    pub inertia: [[f64; 3]; 3],
}

impl Body {
    const EMPTY: Body = Body {
        mass: 0.0,
        first_moment: [0.0; 3],
        inertia: [[0.0; 3]; 3],
    };

    /// Adds a link with mass `m`, centre of mass `c` and inertia `ic` about it (both in this
    /// body's frame): `I_o += I_c + m (|c|² 1 − c cᵀ)`.
    fn add(&mut self, m: f64, c: [f64; 3], ic: [[f64; 3]; 3]) {
        self.mass += m;
        let cc: f64 = c.iter().map(|v| v * v).sum();
        for i in 0..3 {
            self.first_moment[i] += m * c[i];
            for j in 0..3 {
                let delta = if i == j { cc } else { 0.0 };
                self.inertia[i][j] += ic[i][j] + m * (delta - c[i] * c[j]);
            }
        }
    }
}

/// Position, velocity and torque limits and the joint friction of one joint, from the file.
#[derive(Debug, Clone, PartialEq)]
pub struct JointLimits {
    /// Lowest angle [rad]; −∞ for a continuous joint.
    pub lower: f64,
    /// Highest angle [rad]; +∞ for a continuous joint.
    pub upper: f64,
    /// Largest torque magnitude [N m]; +∞ when the file gives none (or 0).
    pub effort: f64,
    /// Largest speed [rad/s]; +∞ when the file gives none (or 0).
    pub velocity: f64,
    /// Viscous damping `b` [N m s/rad]: the torque `b q'` opposes the motion (in the bias).
    pub damping: f64,
    /// Coulomb friction [N m] as the file gives it; not part of the dynamics (it is not smooth).
    pub friction: f64,
}

/// One moving joint of the chain.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ChainJoint {
    pub name: String,
    /// The joint's frame at `q = 0` in the previous joint's frame (the base's for the first).
    pub origin: Frame,
    /// Unit rotation axis in the joint's frame (which passes through its origin).
    pub axis: [f64; 3],
    /// The links the joint moves rigidly, in the joint's frame.
    pub body: Body,
    /// `R(q)`'s constant parts ([`super::dynamics::rotation_parts`]).
    pub rotation_parts: [[[f64; 3]; 3]; 3],
    pub limits: JointLimits,
}

/// A serial chain of revolute joints.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Chain {
    pub joints: Vec<ChainJoint>,
    /// The tip link's frame in the last joint's frame.
    pub tip: Frame,
}

impl Chain {
    /// The chain of `tree` from `base` to `tip` (link names).
    pub fn new(tree: &Tree, base: &str, tip: &str) -> Result<Chain, UrdfError> {
        let (base, tip_link) = (tree.link(base)?, tree.link(tip)?);
        let tip = tip_link;
        let path = tree.path(base, tip)?;
        for &j in &path {
            let joint = &tree.joints[j];
            let at = || joint_name(&joint.name);
            if let Kind::Other(kind) = joint.kind {
                return Err(tree.error(&at(), UrdfReason::UnsupportedJoint(kind)));
            }
            if !joint.finite_origin {
                return Err(tree.error(&at(), UrdfReason::NonFinite("origin")));
            }
        }
        let moving: Vec<usize> = path
            .iter()
            .copied()
            .filter(|&j| matches!(tree.joints[j].kind, Kind::Rotation { .. }))
            .collect();
        if moving.is_empty() {
            return Err(tree.error(&link_name(&tree.links[tip].name), UrdfReason::NoJoints));
        }
        if moving.len() > MAX_DOF {
            let reason = UrdfReason::TooManyJoints(moving.len());
            return Err(tree.error(&link_name(&tree.links[tip].name), reason));
        }
        let mut joints = Vec::with_capacity(moving.len());
        // Where the next moving joint's parent link sits, in the current body's frame.
        let mut upstream = tree.rigid_subtree(base, Some(moving[0]))?;
        let mut tip_frame = None;
        for (k, &j) in moving.iter().enumerate() {
            let joint = &tree.joints[j];
            let parent_frame = upstream
                .iter()
                .find(|(l, _)| *l == joint.parent)
                .map(|(_, f)| *f)
                .ok_or_else(|| tree.error(&joint_name(&joint.name), UrdfReason::Loop))?;
            let links = tree.rigid_subtree(joint.child, moving.get(k + 1).copied())?;
            let body = body(tree, &links, joint.child)?;
            if let Some((_, f)) = links.iter().find(|(l, _)| *l == tip) {
                tip_frame = Some(*f);
            }
            let origin = parent_frame.then(&joint.origin);
            if !finite(&origin) {
                let reason = UrdfReason::NonFinite("origin (too large)");
                return Err(tree.error(&joint_name(&joint.name), reason));
            }
            let axis = axis(tree, j)?;
            joints.push(ChainJoint {
                name: joint.name.clone(),
                rotation_parts: rotation_parts(&origin.rot, &axis),
                origin,
                axis,
                body,
                limits: limits(tree, j)?,
            });
            upstream = links;
        }
        let tip = tip_frame
            .ok_or_else(|| tree.error(&link_name(&tree.links[tip_link].name), UrdfReason::Loop))?;
        if !finite(&tip) {
            let reason = UrdfReason::NonFinite("origin (too large)");
            return Err(tree.error(&link_name(&tree.links[tip_link].name), reason));
        }
        let chain = Chain { joints, tip };
        // The mass matrix at q = 0 is positive definite: every joint moves some inertia about
        // its axis that the joints before it do not already account for.
        let m = crba::<f64>(&chain, &rotations(&chain, &[0.0; MAX_DOF]));
        let n = chain.joints.len();
        let pivots = ldl_pivots(&m, n);
        if let Some(i) = pivots[..n].iter().position(|&d| d.is_nan() || d <= 0.0) {
            let at = joint_name(&chain.joints[i].name);
            return Err(tree.error(&at, UrdfReason::SingularMassMatrix));
        }
        Ok(chain)
    }
}

fn finite(f: &Frame) -> bool {
    f.rot
        .iter()
        .flatten()
        .chain(f.pos.iter())
        .all(|v| v.is_finite())
}

/// The unit axis of joint `j`.
fn axis(tree: &Tree, j: usize) -> Result<[f64; 3], UrdfError> {
    let joint = &tree.joints[j];
    let at = joint_name(&joint.name);
    if !joint.axis_norm.is_finite() {
        return Err(tree.error(&at, UrdfReason::NonFinite("axis")));
    }
    if joint.axis_norm < 1e-9 {
        return Err(tree.error(&at, UrdfReason::ZeroAxis));
    }
    Ok(joint.axis)
}

/// The limits and friction of joint `j`, checked.
fn limits(tree: &Tree, j: usize) -> Result<JointLimits, UrdfError> {
    let joint = &tree.joints[j];
    let at = joint_name(&joint.name);
    let continuous = matches!(joint.kind, Kind::Rotation { continuous: true });
    let (lower, upper) = if continuous {
        (f64::NEG_INFINITY, f64::INFINITY)
    } else {
        (joint.lower, joint.upper)
    };
    if lower.is_nan() || upper.is_nan() {
        return Err(tree.error(&at, UrdfReason::NonFinite("limit")));
    }
    if lower > upper {
        return Err(tree.error(&at, UrdfReason::LimitOrder { lower, upper }));
    }
    let mut checked = [0.0; 4];
    let values = [
        ("effort limit", joint.effort),
        ("velocity limit", joint.velocity),
        ("damping", joint.damping),
        ("friction", joint.friction),
    ];
    for (out, (what, v)) in checked.iter_mut().zip(values) {
        if v.is_nan() || (v.is_infinite() && !what.ends_with("limit")) {
            return Err(tree.error(&at, UrdfReason::NonFinite(what)));
        }
        if v < 0.0 {
            return Err(tree.error(&at, UrdfReason::Negative(what, v)));
        }
        *out = v;
    }
    let none_is_infinite = |v: f64| if v > 0.0 { v } else { f64::INFINITY };
    Ok(JointLimits {
        lower,
        upper,
        effort: none_is_infinite(checked[0]),
        velocity: none_is_infinite(checked[1]),
        damping: checked[2],
        friction: checked[3],
    })
}

/// The body of the links `links` (with their frames in the joint's), whose first, `moved`, is
/// the joint's child: it needs a positive mass; the others may be massless frames. Every inertia
/// is positive semidefinite; a point mass (zero inertia, as the iCub's wrist) is allowed, and
/// [`Chain::new`] checks that the mass matrix is positive definite.
fn body(tree: &Tree, links: &[(usize, Frame)], moved: usize) -> Result<Body, UrdfError> {
    let mut body = Body::EMPTY;
    for &(l, frame) in links {
        let link = &tree.links[l];
        let at = link_name(&link.name);
        if !link.finite {
            return Err(tree.error(&at, UrdfReason::NonFinite("inertial")));
        }
        let i = &link.inertial;
        if l == moved && i.mass <= 0.0 {
            return Err(tree.error(&at, UrdfReason::NonPositiveMass(i.mass)));
        }
        if i.mass < 0.0 {
            return Err(tree.error(&at, UrdfReason::Negative("mass", i.mass)));
        }
        if !positive_semidefinite(&i.inertia) {
            return Err(tree.error(&at, UrdfReason::InertiaNotPositiveSemidefinite));
        }
        // The inertial frame in the joint's frame: the centre of mass and the inertia's axes.
        let f = frame.then(&i.origin);
        let mut ic = [[0.0; 3]; 3];
        for (r, row) in ic.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = (0..3)
                    .flat_map(|a| (0..3).map(move |b| (a, b)))
                    .map(|(a, b)| f.rot[r][a] * i.inertia[a][b] * f.rot[c][b])
                    .sum();
            }
        }
        body.add(i.mass, f.pos, ic);
    }
    let numbers = body
        .first_moment
        .iter()
        .chain(body.inertia.iter().flatten());
    if !body.mass.is_finite() || numbers.into_iter().any(|v| !v.is_finite()) {
        let at = link_name(&tree.links[moved].name);
        return Err(tree.error(&at, UrdfReason::NonFinite("mass properties (too large)")));
    }
    Ok(body)
}

/// Positive semidefinite to a rounding tolerance: `m + ε 1` positive definite by Sylvester's
/// criterion (every leading principal minor positive; no iteration, so huge or odd numbers cannot
/// make it loop), `ε` 1e-9 of the largest entry plus 1e-12 kg m² (files write 1e-35 for 0).
fn positive_semidefinite(m: &[[f64; 3]; 3]) -> bool {
    let scale = m.iter().flatten().fold(0.0_f64, |a, v| a.max(v.abs()));
    let eps = 1e-9 * scale + 1e-12;
    let mut s = *m;
    for (i, row) in s.iter_mut().enumerate() {
        row[i] += eps;
    }
    s[0][0] > 0.0 && s[0][0] * s[1][1] - s[0][1] * s[1][0] > 0.0 && det(&s) > 0.0
}

fn det(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}
