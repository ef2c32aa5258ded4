//! Reading a URDF document into a checked kinematic tree: every link and joint by name, each link
//! with at most one parent joint, every number that the chain uses finite. The XML itself is read
//! by `urdf-rs`; mesh files are never opened.

use super::MAX_DOF;
use std::collections::HashMap;

/// Why a URDF document cannot be used as a serial chain: the file, the element at fault
/// (`joint 'name'`, `link 'name'`, or `robot` for the document as a whole) and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {element}: {reason}")]
pub struct UrdfError {
    /// The file's path, or `<string>` for a document given as text.
    pub file: String,
    /// The element at fault.
    pub element: String,
    /// What is wrong with it.
    pub reason: UrdfReason,
}

/// What is wrong with an element of a URDF document.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrdfReason {
    #[error("malformed URDF: {0}")]
    Malformed(String),
    #[error("not in the file")]
    NotFound,
    #[error("defined twice")]
    Duplicate,
    #[error("names the link '{0}', which is not in the file")]
    UnknownLink(String),
    #[error("is the child of two joints, '{0}' and '{1}' (a kinematic loop)")]
    TwoParents(String, String),
    #[error("lies on a kinematic loop")]
    Loop,
    #[error("is not downstream of the base link '{0}'")]
    NotDownstream(String),
    #[error(
        "is a {0} joint on the chain; only revolute, continuous and fixed joints are supported"
    )]
    UnsupportedJoint(&'static str),
    #[error("no revolute or continuous joint between the base and the tip")]
    NoJoints,
    #[error("{0} moving joints on the chain; at most {max} are supported", max = MAX_DOF)]
    TooManyJoints(usize),
    #[error("mass {0} kg: a link that a joint moves needs a positive mass")]
    NonPositiveMass(f64),
    #[error("moves no inertia about its axis: the mass matrix is singular")]
    SingularMassMatrix,
    #[error("inertia is not positive semidefinite")]
    InertiaNotPositiveSemidefinite,
    #[error("negative {0} ({1})")]
    Negative(&'static str, f64),
    #[error("non-finite {0}")]
    NonFinite(&'static str),
    #[error("axis has zero length")]
    ZeroAxis,
    #[error("lower limit {lower} is above the upper limit {upper}")]
    LimitOrder { lower: f64, upper: f64 },
}

/// The kind of a joint, as far as a serial chain is concerned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Kind {
    /// Revolute or continuous: one rotation about the axis.
    Rotation {
        continuous: bool,
    },
    Fixed,
    /// A joint a chain cannot carry (prismatic, floating, planar, spherical, or one that mimics
    /// another).
    Other(&'static str),
}

/// A rigid transform: a point `p` of the child frame is `rot p + pos` in the parent frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Frame {
    pub rot: [[f64; 3]; 3],
    pub pos: [f64; 3],
}

impl Frame {
    pub const IDENTITY: Frame = Frame {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        pos: [0.0; 3],
    };

    /// The URDF pose `xyz`, `rpy`: rotation `Rz(yaw) Ry(pitch) Rx(roll)`, then translation.
    pub fn from_pose(xyz: [f64; 3], rpy: [f64; 3]) -> Frame {
        let (sr, cr) = rpy[0].sin_cos();
        let (sp, cp) = rpy[1].sin_cos();
        let (sy, cy) = rpy[2].sin_cos();
        Frame {
            rot: [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ],
            pos: xyz,
        }
    }

    /// `self ∘ child`: the child frame's transform to this frame's parent.
    pub fn then(&self, child: &Frame) -> Frame {
        let mut out = Frame::IDENTITY;
        for i in 0..3 {
            for j in 0..3 {
                out.rot[i][j] = (0..3).map(|k| self.rot[i][k] * child.rot[k][j]).sum();
            }
            out.pos[i] = self.pos[i] + (0..3).map(|k| self.rot[i][k] * child.pos[k]).sum::<f64>();
        }
        out
    }
}

/// A link's mass properties in its own frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Inertial {
    pub mass: f64,
    /// The centre of mass and the orientation of the inertia's axes.
    pub origin: Frame,
    /// The rotational inertia about the centre of mass in the `origin` axes.
    pub inertia: [[f64; 3]; 3],
}

/// A link of the document.
#[derive(Debug, Clone)]
pub(crate) struct Link {
    pub name: String,
    pub inertial: Inertial,
    /// Non-finite numbers in the inertial element, found when the link is used.
    pub finite: bool,
}

/// A joint of the document.
#[derive(Debug, Clone)]
pub(crate) struct Joint {
    pub name: String,
    pub kind: Kind,
    pub parent: usize,
    pub child: usize,
    pub origin: Frame,
    /// Unit axis in the child frame (checked when the joint is on the chain).
    pub axis: [f64; 3],
    pub axis_norm: f64,
    pub finite_origin: bool,
    pub lower: f64,
    pub upper: f64,
    pub effort: f64,
    pub velocity: f64,
    pub damping: f64,
    pub friction: f64,
}

/// A URDF document as a tree of links joined by joints.
#[derive(Debug, Clone)]
pub(crate) struct Tree {
    pub file: String,
    pub links: Vec<Link>,
    pub joints: Vec<Joint>,
    /// The joint whose child each link is (`None` for a root).
    pub parent_joint: Vec<Option<usize>>,
    link_index: HashMap<String, usize>,
}

impl Tree {
    /// Parses a document; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Tree, UrdfError> {
        let malformed = |e: String| error(file, "robot", UrdfReason::Malformed(e));
        let robot = urdf_rs::read_from_string(&dynamics_only(text).map_err(malformed)?)
            .map_err(|e| malformed(e.to_string()))?;
        let mut links = Vec::with_capacity(robot.links.len());
        let mut link_index = HashMap::new();
        for l in &robot.links {
            if link_index.insert(l.name.clone(), links.len()).is_some() {
                return Err(error(file, &link_name(&l.name), UrdfReason::Duplicate));
            }
            let i = &l.inertial;
            let t = &i.inertia;
            let numbers = [i.mass.value, t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz];
            let pose = i.origin.xyz.iter().chain(i.origin.rpy.iter());
            let finite = numbers.iter().chain(pose).all(|v| v.is_finite());
            links.push(Link {
                name: l.name.clone(),
                inertial: Inertial {
                    mass: i.mass.value,
                    origin: Frame::from_pose(i.origin.xyz.0, i.origin.rpy.0),
                    inertia: [
                        [t.ixx, t.ixy, t.ixz],
                        [t.ixy, t.iyy, t.iyz],
                        [t.ixz, t.iyz, t.izz],
                    ],
                },
                finite,
            });
        }
        let mut joints = Vec::with_capacity(robot.joints.len());
        let mut joint_names = HashMap::new();
        let mut parent_joint = vec![None; links.len()];
        for j in &robot.joints {
            let at = || joint_name(&j.name);
            if joint_names.insert(j.name.clone(), joints.len()).is_some() {
                return Err(error(file, &at(), UrdfReason::Duplicate));
            }
            let find = |name: &str| {
                link_index
                    .get(name)
                    .copied()
                    .ok_or_else(|| error(file, &at(), UrdfReason::UnknownLink(name.to_string())))
            };
            let (parent, child) = (find(&j.parent.link)?, find(&j.child.link)?);
            if let Some(first) = parent_joint[child].replace(joints.len()) {
                let first: &Joint = &joints[first];
                let reason = UrdfReason::TwoParents(first.name.clone(), j.name.clone());
                return Err(error(file, &link_name(&links[child].name), reason));
            }
            use urdf_rs::JointType as T;
            let kind = match j.joint_type {
                // A joint that mimics another is not a degree of freedom of its own.
                T::Revolute | T::Continuous if j.mimic.is_some() => Kind::Other("mimic"),
                T::Revolute => Kind::Rotation { continuous: false },
                T::Continuous => Kind::Rotation { continuous: true },
                T::Fixed => Kind::Fixed,
                T::Prismatic => Kind::Other("prismatic"),
                T::Floating => Kind::Other("floating"),
                T::Planar => Kind::Other("planar"),
                T::Spherical => Kind::Other("spherical"),
            };
            let axis = j.axis.xyz.0;
            let axis_norm = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
            let pose = j.origin.xyz.iter().chain(j.origin.rpy.iter());
            let (damping, friction) = j
                .dynamics
                .as_ref()
                .map_or((0.0, 0.0), |d| (d.damping, d.friction));
            joints.push(Joint {
                name: j.name.clone(),
                kind,
                parent,
                child,
                origin: Frame::from_pose(j.origin.xyz.0, j.origin.rpy.0),
                axis: axis.map(|a| a / axis_norm),
                axis_norm,
                finite_origin: pose.into_iter().all(|v| v.is_finite()),
                lower: j.limit.lower,
                upper: j.limit.upper,
                effort: j.limit.effort,
                velocity: j.limit.velocity,
                damping,
                friction,
            });
        }
        Ok(Tree {
            file: file.to_string(),
            links,
            joints,
            parent_joint,
            link_index,
        })
    }

    /// The index of a link by name.
    pub fn link(&self, name: &str) -> Result<usize, UrdfError> {
        self.link_index
            .get(name)
            .copied()
            .ok_or_else(|| self.error(&link_name(name), UrdfReason::NotFound))
    }

    /// The joints from `base` down to `tip`, in order from the base.
    pub fn path(&self, base: usize, tip: usize) -> Result<Vec<usize>, UrdfError> {
        let mut path = Vec::new();
        let mut link = tip;
        while link != base {
            let Some(j) = self.parent_joint[link] else {
                let reason = UrdfReason::NotDownstream(self.links[base].name.clone());
                return Err(self.error(&link_name(&self.links[tip].name), reason));
            };
            path.push(j);
            if path.len() > self.joints.len() {
                return Err(self.error(&link_name(&self.links[link].name), UrdfReason::Loop));
            }
            link = self.joints[j].parent;
        }
        path.reverse();
        Ok(path)
    }

    /// Every link that moves rigidly with `start` when every joint but `stop` is held at its
    /// zero position, with its frame in `start`'s: the links below `start`, not below `stop`.
    pub fn rigid_subtree(
        &self,
        start: usize,
        stop: Option<usize>,
    ) -> Result<Vec<(usize, Frame)>, UrdfError> {
        let mut out = vec![(start, Frame::IDENTITY)];
        let mut next = 0;
        while next < out.len() {
            let (link, frame) = out[next];
            next += 1;
            for (j, joint) in self.joints.iter().enumerate() {
                if joint.parent != link || Some(j) == stop {
                    continue;
                }
                if !joint.finite_origin {
                    let reason = UrdfReason::NonFinite("origin");
                    return Err(self.error(&joint_name(&joint.name), reason));
                }
                if out.len() > self.links.len() {
                    let reason = UrdfReason::Loop;
                    return Err(self.error(&link_name(&self.links[link].name), reason));
                }
                out.push((joint.child, frame.then(&joint.origin)));
            }
        }
        Ok(out)
    }

    /// An error about an element of this document.
    pub fn error(&self, element: &str, reason: UrdfReason) -> UrdfError {
        error(&self.file, element, reason)
    }
}

/// The document without what the dynamics do not read: the links' visual and collision
/// elements and the materials (meshes, textures and colours, which `urdf-rs` would check).
fn dynamics_only(text: &str) -> Result<String, String> {
    let mut robot: xml::Element = text.parse().map_err(|e| format!("{e:?}"))?;
    robot.children.retain_mut(|c| match c {
        xml::Xml::ElementNode(e) if e.name == "material" => false,
        xml::Xml::ElementNode(e) if e.name == "link" => {
            e.children.retain(|c| {
                !matches!(c, xml::Xml::ElementNode(v) if v.name == "visual" || v.name == "collision")
            });
            true
        }
        _ => true,
    });
    Ok(robot.to_string())
}

/// An error about an element of a file.
pub(crate) fn error(file: &str, element: &str, reason: UrdfReason) -> UrdfError {
    UrdfError {
        file: file.to_string(),
        element: element.to_string(),
        reason,
    }
}

/// How a link is named in errors.
pub(crate) fn link_name(name: &str) -> String {
    format!("link '{name}'")
}

/// How a joint is named in errors.
pub(crate) fn joint_name(name: &str) -> String {
    format!("joint '{name}'")
}
