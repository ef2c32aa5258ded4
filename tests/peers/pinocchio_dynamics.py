#!/usr/bin/env python3
"""Pinocchio's dynamics of URDF chains, for vic's cross-check (crates/vic-core/tests/pinocchio.rs).

Reads on stdin a JSON list of cases, each {"file", "base", "tip", "gravity", "states": [{"q", "v",
"tau"}, ...]}, and writes on stdout one result per case: the chain's joint names and, per state,
the mass matrix "M", the bias torques "bias" (Pinocchio's nonlinear effects, rnea with a = 0, plus
the file's joint damping times v), the forward dynamics "aba" (aba with tau - damping v) and the
tip link's position in the base link's frame "tip".

The chain is Pinocchio's reduced model: every joint not between the base and the tip link is
locked at 0 (buildReducedModel), as vic holds the joints off the chain. Gravity is given in the
base link's frame and turned into Pinocchio's world frame. Needs the pip package pin==4.0.0
(import name pinocchio) and numpy; the URDF's meshes are not read.
"""

import json
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin


def chain_joints(path, base, tip):
    """The moving joints from base to tip, read from the XML on its own."""
    root = ET.parse(path).getroot()
    parent = {j.find("child").get("link"): j for j in root.findall("joint")}
    names, link = [], tip
    while link != base:
        joint = parent[link]
        if joint.get("type") in ("revolute", "continuous"):
            names.append(joint.get("name"))
        link = joint.find("parent").get("link")
    return names[::-1]


def reduced_model(path, base, tip, gravity):
    full = pin.buildModelFromUrdf(path)
    keep = chain_joints(path, base, tip)
    lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in keep]
    model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    assert list(model.names)[1:] == keep, (list(model.names), keep)
    assert not np.any(model.armature), "vic's URDF chains have no armature"
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    base_placement = data.oMf[model.getFrameId(base)].copy()
    model.gravity.linear = base_placement.rotation @ np.asarray(gravity, dtype=float)
    return model, data, base_placement, keep


def configuration(model, q):
    """Pinocchio's q for the joint angles (a continuous joint is (cos, sin))."""
    out = pin.neutral(model)
    for k, joint in enumerate(list(model.joints)[1:]):
        if joint.nq == 2:
            out[joint.idx_q : joint.idx_q + 2] = [np.cos(q[k]), np.sin(q[k])]
        else:
            out[joint.idx_q] = q[k]
    return out


def run(case):
    model, data, base_placement, names = reduced_model(
        case["file"], case["base"], case["tip"], case["gravity"]
    )
    tip = model.getFrameId(case["tip"])
    damping = np.asarray(model.damping)
    results = []
    for s in case["states"]:
        q = configuration(model, s["q"])
        v, tau = np.asarray(s["v"]), np.asarray(s["tau"])
        m = pin.crba(model, data, q)
        m = np.triu(m) + np.triu(m, 1).T
        bias = pin.nonLinearEffects(model, data, q, v) + damping * v
        acc = pin.aba(model, data, q, v, tau - damping * v)
        pin.framesForwardKinematics(model, data, q)
        tip_pos = base_placement.actInv(data.oMf[tip]).translation
        results.append(
            {
                "M": m.tolist(),
                "bias": bias.tolist(),
                "aba": acc.tolist(),
                "tip": tip_pos.tolist(),
            }
        )
    return {"joints": names, "damping": damping.tolist(), "results": results}


def main():
    cases = json.load(sys.stdin)
    json.dump([run(c) for c in cases], sys.stdout)


if __name__ == "__main__":
    main()
