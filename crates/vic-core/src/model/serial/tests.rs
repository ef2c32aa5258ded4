//! The URDF chains against the hand-written paper plants, the dual numbers against finite
//! differences, RNEA against CRBA, energy along a simulated motion, and the refusals.

use super::*;
use crate::model::plant::{Plant, SingleJoint, TwoLink};
use num_dual::Dual64;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// A file of `config/`.
pub(super) fn config(name: &str) -> String {
    let path = format!("{}/../../config/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

pub(super) fn panda() -> SerialChain {
    SerialChain::from_urdf_str(&config("panda.urdf"), "panda_link0", "panda_hand").unwrap()
}

fn icub_arm() -> SerialChain {
    SerialChain::from_urdf_str(&config("icub.urdf"), "chest", "r_hand")
        .unwrap()
        .with_gravity([0.0, -9.81, 0.0])
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1.0)
}

fn random_state(rng: &mut StdRng, n: usize) -> ([f64; MAX_DOF], [f64; MAX_DOF], [f64; MAX_DOF]) {
    let mut v = [[0.0; MAX_DOF]; 3];
    for (k, scale) in [2.5, 3.0, 20.0].into_iter().enumerate() {
        for x in v[k].iter_mut().take(n) {
            *x = rng.random_range(-scale..scale);
        }
    }
    (v[0], v[1], v[2])
}

/// Mass matrix, bias and forward dynamics of a URDF chain and a hand-written plant agree to
/// `1e-12` (relative) on random states.
fn agrees_with(chain: &SerialChain, plant: &Plant) {
    let n = plant.dof();
    assert_eq!(chain.dof(), n);
    let mut rng = StdRng::seed_from_u64(62);
    for _ in 0..200 {
        let (q, qd, tau) = random_state(&mut rng, n);
        let (m, mh) = (chain.mass_matrix(&q[..n]), plant.mass_matrix(&q[..n]));
        let mut bh = [0.0; 2];
        plant.bias_torque(&q[..n], &qd[..n], &mut bh);
        let b = chain.bias(&q[..n], &qd[..n]);
        let mut rhs = [0.0; 2];
        for i in 0..n {
            rhs[i] = tau[i] - bh[i];
        }
        let mut ah = [0.0; 2];
        Plant::solve_with(&mh, n, &rhs[..n], &mut ah[..n]);
        let a = chain.forward_dynamics(&q[..n], &qd[..n], &tau[..n]);
        for i in 0..n {
            for j in 0..n {
                assert!(close(m[i][j], mh[i][j], 1e-12), "M {m:?} vs {mh:?}");
            }
            assert!(
                close(b[i], bh[i], 1e-12),
                "bias {b:?} vs {bh:?} at {q:?} {qd:?}"
            );
            assert!(close(a[i], ah[i], 1e-12), "q'' {a:?} vs {ah:?}");
        }
    }
}

#[test]
fn the_single_joint_urdf_is_the_icub_elbow_of_the_paper() {
    let chain =
        SerialChain::from_urdf_str(&config("single_joint.urdf"), "upper_arm", "hand").unwrap();
    // config/icub_elbow.toml's plant (no viscosity key: 0).
    let elbow = SingleJoint {
        inertia: 5.08e-3,
        mass: 0.812,
        com: 0.103,
        length: 0.273,
        gravity: 9.81,
        viscosity: 0.0,
    };
    let plant = Plant::SingleJoint(elbow);
    agrees_with(&chain, &plant);
    // The tip in the vertical (x, z) plane is the hand-written model's (x, y).
    for q in [-1.0, 0.0, 0.4] {
        let (p, h) = (chain.tip_position(&[q]), plant.hand_position(&[q]));
        assert!(close(p[0], h[0], 1e-14) && close(p[2], h[1], 1e-14) && p[1].abs() < 1e-15);
    }
    let limits = chain.limits(0);
    assert_eq!((limits.effort, limits.damping), (20.0, 0.0));
}

#[test]
fn the_two_link_urdf_is_the_planar_arm_of_the_paper() {
    let chain = SerialChain::from_urdf_str(&config("two_link.urdf"), "torso", "hand").unwrap();
    // config/two_link_*.toml's arm with the diagonal of its viscosity (URDF has no coupling).
    let arm = TwoLink {
        l1: 0.30,
        l2: 0.33,
        s2: 0.16,
        m2: 1.0,
        i1: 0.025,
        i2: 0.045,
        viscosity: [[0.05, 0.0], [0.0, 0.05]],
    };
    let plant = Plant::TwoLink(arm);
    agrees_with(&chain, &plant);
    let q = [0.3, 1.2];
    let (p, h) = (chain.tip_position(&q), plant.hand_position(&q));
    assert!(close(p[0], h[0], 1e-14) && close(p[1], h[1], 1e-14) && p[2] == 0.0);
    assert_eq!(
        chain.joint_names().collect::<Vec<_>>(),
        ["shoulder", "elbow"]
    );
}

/// A wrong mass or length in the file makes the comparison fail: the check can fail.
#[test]
fn the_comparison_sees_a_changed_parameter() {
    let text = config("two_link.urdf").replace("<mass value=\"1.0\"/>", "<mass value=\"1.001\"/>");
    let chain = SerialChain::from_urdf_str(&text, "torso", "hand").unwrap();
    let arm = Plant::TwoLink(TwoLink {
        l1: 0.30,
        l2: 0.33,
        s2: 0.16,
        m2: 1.0,
        i1: 0.025,
        i2: 0.045,
        viscosity: [[0.05, 0.0], [0.0, 0.05]],
    });
    let r = std::panic::catch_unwind(|| agrees_with(&chain, &arm));
    assert!(r.is_err());
}

#[test]
fn dual_numbers_give_the_derivatives_of_forward_dynamics() {
    // ∂q''/∂(q, q', τ) column by column with dual numbers, against central differences.
    for chain in [panda(), icub_arm()] {
        let n = chain.dof();
        let mut rng = StdRng::seed_from_u64(7);
        for _ in 0..5 {
            let (q, qd, tau) = random_state(&mut rng, n);
            let x: Vec<f64> = [&q[..n], &qd[..n], &tau[..n]].concat();
            let eval = |x: &[f64]| chain.forward_dynamics(&x[..n], &x[n..2 * n], &x[2 * n..]);
            for k in 0..3 * n {
                let xd: Vec<Dual64> = x
                    .iter()
                    .enumerate()
                    .map(|(i, &v)| Dual64::new(v, if i == k { 1.0 } else { 0.0 }))
                    .collect();
                let exact = chain.forward_dynamics(&xd[..n], &xd[n..2 * n], &xd[2 * n..]);
                let h = 1e-6;
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[k] += h;
                xm[k] -= h;
                let (ap, am) = (eval(&xp), eval(&xm));
                for i in 0..n {
                    let fd = (ap[i] - am[i]) / (2.0 * h);
                    let d = exact[i].eps;
                    assert!(
                        (d - fd).abs() <= 1e-5 * d.abs().max(fd.abs()).max(1.0),
                        "∂q''_{i}/∂x_{k}: dual {d}, finite difference {fd}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_derivatives_through_the_inverse_dynamics_are_the_dual_numbers_of_forward_dynamics() {
    // −M⁻¹ ∂τ_ID/∂x against the forward dynamics carried through in dual numbers, and
    // ∂q''/∂τ against M⁻¹ from the mass matrix.
    for chain in [panda(), icub_arm()] {
        let n = chain.dof();
        let mut rng = StdRng::seed_from_u64(8);
        for _ in 0..10 {
            let (q, qd, tau) = random_state(&mut rng, n);
            let fd = chain.forward_dynamics_derivatives(&q[..n], &qd[..n], &tau[..n]);
            let plain = chain.forward_dynamics(&q[..n], &qd[..n], &tau[..n]);
            let m = chain.mass_matrix(&q[..n]);
            for k in 0..3 * n {
                let dir = |i: usize, v: f64| Dual64::new(v, if i == k { 1.0 } else { 0.0 });
                let qx: Vec<Dual64> = (0..n).map(|i| dir(i, q[i])).collect();
                let qdx: Vec<Dual64> = (0..n).map(|i| dir(n + i, qd[i])).collect();
                let taux: Vec<Dual64> = (0..n).map(|i| dir(2 * n + i, tau[i])).collect();
                let exact = chain.forward_dynamics(&qx, &qdx, &taux);
                let (block, j) = (k / n, k % n);
                for i in 0..n {
                    let ours = [fd.d_q, fd.d_qd, fd.d_tau][block][i][j];
                    assert!(
                        close(ours, exact[i].eps, 1e-9),
                        "{k} {i}: {ours} vs {}",
                        exact[i].eps
                    );
                    assert_eq!(fd.qdd[i], plain[i]);
                }
            }
            // M (∂q''/∂τ) = 1.
            for i in 0..n {
                for j in 0..n {
                    let mm: f64 = (0..n).map(|k| m[i][k] * fd.d_tau[k][j]).sum();
                    assert!((mm - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9);
                }
            }
        }
    }
}

#[test]
fn newton_euler_agrees_with_the_composite_mass_matrix() {
    // τ = RNEA(q, q', q'') equals M(q) q'' + bias(q, q') from CRBA, and forward dynamics
    // inverts it: two algorithms that share only the kinematics.
    for chain in [panda(), icub_arm()] {
        let n = chain.dof();
        let mut rng = StdRng::seed_from_u64(11);
        for _ in 0..100 {
            let (q, qd, qdd) = random_state(&mut rng, n);
            let tau = chain.inverse_dynamics(&q[..n], &qd[..n], &qdd[..n]);
            let (m, b) = (chain.mass_matrix(&q[..n]), chain.bias(&q[..n], &qd[..n]));
            for i in 0..n {
                let mq: f64 = (0..n).map(|j| m[i][j] * qdd[j]).sum();
                assert!(
                    close(tau[i], mq + b[i], 1e-12),
                    "{i}: {} vs {}",
                    tau[i],
                    mq + b[i]
                );
                for j in 0..n {
                    assert_eq!(m[i][j], m[j][i]);
                }
            }
            let back = chain.forward_dynamics(&q[..n], &qd[..n], &tau[..n]);
            for i in 0..n {
                assert!(close(back[i], qdd[i], 1e-9), "{back:?} vs {qdd:?}");
            }
        }
    }
}

#[test]
fn energy_changes_by_the_work_of_the_torques_and_the_damping() {
    // d/dt (T + V) = q'·(τ − B q'), integrated with RK4 on the state and the work together.
    let chain = panda();
    let n = chain.dof();
    let energy = |x: &[f64]| {
        let m = chain.mass_matrix(&x[..n]);
        let qd = &x[n..2 * n];
        let t: f64 = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| 0.5 * qd[i] * m[i][j] * qd[j])
            .sum();
        t + chain.potential_energy(&x[..n])
    };
    let torque = |t: f64| [0, 1, 2, 3, 4, 5, 6].map(|i| 3.0 * (2.0 * t + i as f64).sin());
    let deriv = |t: f64, x: &[f64]| {
        let tau = torque(t);
        let a = chain.forward_dynamics(&x[..n], &x[n..2 * n], &tau[..n]);
        let mut d = vec![0.0; 2 * n + 1];
        d[..n].copy_from_slice(&x[n..2 * n]);
        d[n..2 * n].copy_from_slice(&a[..n]);
        d[2 * n] = (0..n)
            .map(|i| x[n + i] * (tau[i] - chain.limits(i).damping * x[n + i]))
            .sum();
        d
    };
    let mut x = vec![0.0; 2 * n + 1];
    x[..n].copy_from_slice(&[0.1, -0.4, 0.2, -1.8, 0.3, 1.5, 0.6]);
    x[n..2 * n].copy_from_slice(&[0.5, -0.3, 0.8, 0.2, -1.0, 0.6, 1.2]);
    let e0 = energy(&x);
    let dt = 1e-4;
    for k in 0..3000 {
        let t = k as f64 * dt;
        let k1 = deriv(t, &x);
        let at = |x: &[f64], d: &[f64], s: f64| -> Vec<f64> {
            x.iter().zip(d).map(|(a, b)| a + s * b).collect()
        };
        let k2 = deriv(t + dt / 2.0, &at(&x, &k1, dt / 2.0));
        let k3 = deriv(t + dt / 2.0, &at(&x, &k2, dt / 2.0));
        let k4 = deriv(t + dt, &at(&x, &k3, dt));
        for i in 0..x.len() {
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    let (change, work) = (energy(&x) - e0, x[2 * n]);
    assert!(work.abs() > 1.0, "the torques do work: {work}");
    assert!(
        (change - work).abs() < 1e-8 * work.abs().max(1.0),
        "energy change {change} vs work {work}"
    );
    // The damping's share is above the tolerance: leaving it out of the balance fails.
    assert!(chain.limits(0).damping > 0.0);
}

#[test]
fn the_real_arms_have_seven_joints_with_the_files_limits() {
    let p = panda();
    assert_eq!(p.dof(), 7);
    assert_eq!(p.limits(3).lower, -3.0718);
    assert_eq!(p.limits(3).effort, 87.0);
    assert_eq!(p.limits(0).damping, 0.003);
    let names: Vec<_> = icub_arm().joint_names().map(String::from).collect();
    assert_eq!(names[0], "r_shoulder_pitch");
    assert_eq!(names[6], "r_wrist_yaw");
    let three =
        SerialChain::from_urdf_str(&config("three_link_planar.urdf"), "torso", "fingertips")
            .unwrap();
    assert_eq!(three.dof(), 3);
    let tip = three.tip_position(&[0.0; 3]);
    assert!(close(tip[0], 0.3255 + 0.2555 + 0.189, 1e-15));
}

/// A minimal two-joint document with `joint2` and `link2` replaced as the test asks.
fn doc(joint2: &str, link2_inertial: &str) -> String {
    let inertial = r#"<inertial><origin xyz="0.1 0 0"/><mass value="1"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;
    format!(
        r#"<robot name="r">
        <link name="base"/>
        <link name="link1">{inertial}</link>
        <link name="link2">{link2_inertial}</link>
        <link name="other"/>
        <joint name="joint1" type="revolute"><parent link="base"/><child link="link1"/>
          <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
        {joint2}
        </robot>"#
    )
}

fn joint2(kind: &str, extra: &str) -> String {
    format!(
        r#"<joint name="joint2" type="{kind}"><parent link="link1"/><child link="link2"/>
        <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/>{extra}</joint>"#
    )
}

#[test]
fn every_unusable_document_is_refused_with_the_element_and_the_reason() {
    let good_inertial = r#"<inertial><mass value="0.5"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;
    let ok = doc(&joint2("revolute", ""), good_inertial);
    let chain = SerialChain::from_urdf_str(&ok, "base", "link2").unwrap();
    assert_eq!(chain.dof(), 2);
    let refused = |text: &str, base: &str, tip: &str| {
        SerialChain::from_urdf_str(text, base, tip).unwrap_err()
    };
    use UrdfReason as R;
    let cases: Vec<(String, &str, &str, &str, R)> = vec![
        (
            doc(&joint2("prismatic", ""), good_inertial),
            "base",
            "link2",
            "joint 'joint2'",
            R::UnsupportedJoint("prismatic"),
        ),
        (
            doc(&joint2("floating", ""), good_inertial),
            "base",
            "link2",
            "joint 'joint2'",
            R::UnsupportedJoint("floating"),
        ),
        (
            doc(&joint2("planar", ""), good_inertial),
            "base",
            "link2",
            "joint 'joint2'",
            R::UnsupportedJoint("planar"),
        ),
        (
            doc(
                &joint2("revolute", r#"<mimic joint="joint1"/>"#),
                good_inertial,
            ),
            "base",
            "link2",
            "joint 'joint2'",
            R::UnsupportedJoint("mimic"),
        ),
        (
            doc(&joint2("revolute", ""), ""),
            "base",
            "link2",
            "link 'link2'",
            R::NonPositiveMass(0.0),
        ),
        (
            doc(&joint2("revolute", ""), &good_inertial.replace("0.5", "-2")),
            "base",
            "link2",
            "link 'link2'",
            R::NonPositiveMass(-2.0),
        ),
        (
            doc(
                &joint2("revolute", ""),
                &good_inertial.replace("iyy=\"0.01\"", "iyy=\"-0.01\""),
            ),
            "base",
            "link2",
            "link 'link2'",
            R::InertiaNotPositiveSemidefinite,
        ),
        // A point mass on the last axis: joint 2 moves no inertia.
        (
            doc(&joint2("revolute", ""), &good_inertial.replace("0.01", "0")),
            "base",
            "link2",
            "joint 'joint2'",
            R::SingularMassMatrix,
        ),
        (
            doc(&joint2("revolute", ""), good_inertial),
            "base",
            "nowhere",
            "link 'nowhere'",
            R::NotFound,
        ),
        (
            doc(&joint2("revolute", ""), good_inertial),
            "attic",
            "link2",
            "link 'attic'",
            R::NotFound,
        ),
        (
            doc(&joint2("revolute", ""), good_inertial),
            "link2",
            "base",
            "link 'base'",
            R::NotDownstream("link2".into()),
        ),
        (
            doc(&joint2("revolute", ""), good_inertial),
            "base",
            "other",
            "link 'other'",
            R::NotDownstream("base".into()),
        ),
        (
            doc(
                &format!(
                    "{}{}",
                    joint2("revolute", ""),
                    r#"<joint name="back" type="fixed"><parent link="link2"/><child link="link1"/></joint>"#
                ),
                good_inertial,
            ),
            "base",
            "link2",
            "link 'link1'",
            R::TwoParents("joint1".into(), "back".into()),
        ),
        (
            doc(
                &joint2("revolute", "").replace("0.3 0 0", "nan 0 0"),
                good_inertial,
            ),
            "base",
            "link2",
            "joint 'joint2'",
            R::NonFinite("origin"),
        ),
        (
            doc(
                &joint2("revolute", "").replace("0 0 1", "0 0 0"),
                good_inertial,
            ),
            "base",
            "link2",
            "joint 'joint2'",
            R::ZeroAxis,
        ),
        (
            doc(
                &joint2("revolute", "<dynamics damping=\"inf\"/>"),
                good_inertial,
            ),
            "base",
            "link2",
            "joint 'joint2'",
            R::NonFinite("damping"),
        ),
        (
            doc(
                &joint2("revolute", ""),
                &good_inertial.replace("0.5", "NaN"),
            ),
            "base",
            "link2",
            "link 'link2'",
            R::NonFinite("inertial"),
        ),
        (
            doc(&joint2("fixed", ""), good_inertial),
            "link1",
            "link2",
            "link 'link2'",
            R::NoJoints,
        ),
    ];
    for (text, base, tip, element, reason) in cases {
        let e = refused(&text, base, tip);
        assert_eq!((e.element.as_str(), &e.reason), (element, &reason), "{e}");
        assert_eq!(e.file, "<string>");
    }
    // A loop with no root: both links have one parent, walking up never reaches the base.
    let looped = r#"<robot name="r"><link name="a"/><link name="b"/><link name="base"/>
        <joint name="ab" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>
        <joint name="ba" type="revolute"><parent link="b"/><child link="a"/><axis xyz="0 0 1"/></joint>
        </robot>"#;
    assert_eq!(refused(looped, "base", "b").reason, R::Loop);
    assert!(matches!(
        refused("<robot", "a", "b").reason,
        R::Malformed(_)
    ));
    // Eight moving joints.
    let mut long = String::from(r#"<robot name="r"><link name="l0"/>"#);
    for i in 1..=8 {
        long += &format!(
            r#"<link name="l{i}">{good_inertial}</link><joint name="j{i}" type="continuous">
            <parent link="l{}"/><child link="l{i}"/><axis xyz="1 0 0"/></joint>"#,
            i - 1
        );
    }
    long += "</robot>";
    assert_eq!(refused(&long, "l0", "l8").reason, R::TooManyJoints(8));
    assert_eq!(
        SerialChain::from_urdf_str(&long, "l1", "l8").unwrap().dof(),
        7
    );
    // The source named for the errors is the caller's.
    let e = SerialChain::from_urdf("<robot", "arm.urdf", "a", "b").unwrap_err();
    assert_eq!(e.file, "arm.urdf");
}

#[test]
fn joints_off_the_chain_are_held_at_zero_and_ignored_when_they_cannot_move() {
    // The panda's prismatic fingers hang off the hand: the chain to the hand carries them.
    let with_fingers = panda();
    let text = config("panda.urdf");
    let hand_only = SerialChain::from_urdf_str(&text, "panda_link0", "panda_link8").unwrap();
    // The tip differs, the dynamics do not: the hand and fingers ride on joint 7 either way.
    let q = [0.1, -0.4, 0.2, -1.8, 0.3, 1.5, 0.6];
    assert_eq!(with_fingers.mass_matrix(&q), hand_only.mass_matrix(&q));
    // A prismatic joint off the chain of the planar arm is not refused.
    let extra = r#"<link name="slider"/><joint name="slide" type="prismatic"><parent link="torso"/>
        <child link="slider"/><axis xyz="1 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint></robot>"#;
    let text = config("two_link.urdf").replace("</robot>", extra);
    assert!(SerialChain::from_urdf_str(&text, "torso", "hand").is_ok());
}
