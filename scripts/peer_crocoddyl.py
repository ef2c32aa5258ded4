#!/usr/bin/env python3
"""Crocoddyl's DDP and BoxDDP on the problems vic solves, timed in the same run.

Reads the JSON that `cargo run --release --example peer_problem` prints (one problem per file:
start state, reference per knot, weights, limits, initial guess, arm parameters and vic's own
timings and optimum), rebuilds the problem in Crocoddyl and prints one JSON line per solver
with the median time, the iterations, the optimum's cost, its distance to vic's controls and
the ratio Crocoddyl time / vic time.

Two Crocoddyl models of the same arm:

* `builtin`: Pinocchio's rigid-body dynamics of the two-link arm (DifferentialActionModelFreeFwdDynamics,
  C++), Crocoddyl's IntegratedActionModelEuler (which is the semi-implicit Euler step:
  v' = v + a dt, q' = q + v' dt) and its built-in quadratic costs. vic solves the same problem
  with `task.integrator=semi_implicit` and no joint viscosity (the built-in model has none).
* `python`: the arm of vic's paper model written as a Python ActionModelAbstract (explicit Euler,
  joint viscosity, analytic cost derivatives, dynamics Jacobians by central differences). Same
  problem as vic's default, but every knot calls into Python: its time measures Python, not
  Crocoddyl's solver.
"""

import json
import statistics
import sys
import time

import numpy as np
import crocoddyl
import pinocchio as pin


def arm_model(p):
    """The two-link planar arm in Pinocchio: link 1 inertia i1 about the shoulder (no mass of its
    own, as in vic's model), link 2 mass m2 with its centre of mass s2 beyond the elbow and
    inertia i2 about the elbow axis; no gravity (horizontal plane)."""
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
    model.appendBodyToJoint(j1, pin.Inertia(0.0, np.zeros(3), np.diag([0.0, 0.0, p["i1"]])),
                            pin.SE3.Identity())
    elbow = pin.SE3(np.eye(3), np.array([p["l1"], 0.0, 0.0]))
    j2 = model.addJoint(j1, pin.JointModelRZ(), elbow, "elbow")
    i2c = p["i2"] - p["m2"] * p["s2"] ** 2
    model.appendBodyToJoint(j2, pin.Inertia(p["m2"], np.array([p["s2"], 0.0, 0.0]),
                                            np.diag([0.0, 0.0, i2c])), pin.SE3.Identity())
    model.gravity = pin.Motion.Zero()
    return model


def state_weights(prob):
    return np.array([2 * prob["w_p"]] * 2 + [2 * prob["w_v"]] * 2)


def builtin_problem(prob):
    model = arm_model(prob["arm"])
    state = crocoddyl.StateMultibody(model)
    actuation = crocoddyl.ActuationModelFull(state)
    dt, n = prob["dt"], prob["horizon"]
    wx = crocoddyl.ActivationModelWeightedQuad(state_weights(prob))
    wu = crocoddyl.ActivationModelWeightedQuad(2.0 * np.array(prob["w_torque"]))
    lb, ub = np.array(prob["lower"]), np.array(prob["upper"])

    def knot(k, terminal):
        costs = crocoddyl.CostModelSum(state, actuation.nu)
        q = np.array(prob["q_ref"][k])
        v = np.zeros(2) if terminal else np.array(prob["qd_ref"][k])
        xref = np.concatenate([q, v])
        costs.addCost("state", crocoddyl.CostModelResidual(
            state, wx, crocoddyl.ResidualModelState(state, xref, actuation.nu)), 1.0)
        if not terminal:
            costs.addCost("control", crocoddyl.CostModelResidual(
                state, wu, crocoddyl.ResidualModelControl(state, actuation.nu)), 1.0)
        diff = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, actuation, costs)
        m = crocoddyl.IntegratedActionModelEuler(diff, 0.0 if terminal else dt)
        if not terminal and np.all(np.abs(lb) < 1e299):
            m.u_lb, m.u_ub = lb, ub
        return m

    running = [knot(k, False) for k in range(n)]
    problem = crocoddyl.ShootingProblem(np.array(prob["x0"]), running, knot(n, True))
    # One thread, like vic's solve (OpenMP threads spin against each other on a shared machine).
    problem.nthreads = 1
    return problem


class PythonArm(crocoddyl.ActionModelAbstract):
    """vic's arm and cost at one knot, explicit Euler, in Python."""

    def __init__(self, prob, k, terminal):
        crocoddyl.ActionModelAbstract.__init__(self, crocoddyl.StateVector(4), 2, 0)
        self.p, self.dt, self.terminal = prob["arm"], prob["dt"], terminal
        q = np.array(prob["q_ref"][k])
        v = np.zeros(2) if terminal else np.array(prob["qd_ref"][k])
        self.xref = np.concatenate([q, v])
        self.wx = state_weights(prob) / 2.0
        self.wu = np.array(prob["w_torque"])
        self.bv = np.array(self.p["viscosity"])
        lb, ub = np.array(prob["lower"]), np.array(prob["upper"])
        if not terminal and np.all(np.abs(lb) < 1e299):
            self.u_lb, self.u_ub = lb, ub

    def f(self, x, u):
        p = self.p
        q2, v1, v2 = x[1], x[2], x[3]
        h = p["m2"] * p["l1"] * p["s2"]
        m11 = p["i1"] + p["i2"] + p["m2"] * p["l1"] ** 2 + 2 * h * np.cos(q2)
        m12 = p["i2"] + h * np.cos(q2)
        mass = np.array([[m11, m12], [m12, p["i2"]]])
        c = h * np.sin(q2) * np.array([-v2 * (2 * v1 + v2), v1 * v1])
        a = np.linalg.solve(mass, u - c - self.bv @ x[2:])
        return np.concatenate([x[2:], a])

    def cost(self, x, u):
        r = x - self.xref
        lx = float(self.wx @ (r * r))
        if self.terminal:
            return lx
        return self.dt * (lx + float(self.wu @ (u * u)))

    def calc(self, data, x, u=None):
        if u is None or self.terminal:
            data.xnext[:] = x
            data.cost = self.cost(x, None)
        else:
            data.xnext[:] = x + self.dt * self.f(x, u)
            data.cost = self.cost(x, u)

    def calcDiff(self, data, x, u=None):
        r = x - self.xref
        s = 1.0 if (u is None or self.terminal) else self.dt
        data.Lx[:] = s * 2 * self.wx * r
        data.Lxx[:, :] = s * np.diag(2 * self.wx)
        if u is None or self.terminal:
            return
        data.Lu[:] = self.dt * 2 * self.wu * u
        data.Luu[:, :] = self.dt * np.diag(2 * self.wu)
        z = np.concatenate([x, u])
        eps = 1e-7
        jac = np.zeros((4, 6))
        for j in range(6):
            zp, zm = z.copy(), z.copy()
            zp[j] += eps
            zm[j] -= eps
            jac[:, j] = (self.f(zp[:4], zp[4:]) - self.f(zm[:4], zm[4:])) / (2 * eps)
        data.Fx[:, :] = np.eye(4) + self.dt * jac[:, :4]
        data.Fu[:, :] = self.dt * jac[:, 4:]


def python_problem(prob):
    n = prob["horizon"]
    running = [PythonArm(prob, k, False) for k in range(n)]
    return crocoddyl.ShootingProblem(np.array(prob["x0"]), running, PythonArm(prob, n, True))


def solve(problem, prob, box, runs):
    us0 = [np.array(u) for u in prob["u_init"]]
    xs0 = problem.rollout(us0)
    solver_type = crocoddyl.SolverBoxDDP if box else crocoddyl.SolverDDP
    times, solver = [], None
    for _ in range(runs):
        solver = solver_type(problem)
        t = time.perf_counter()
        solver.solve(xs0, us0, 200, False)
        times.append((time.perf_counter() - t) * 1e3)
    return solver, times


def cpu_model():
    """The CPU the times were taken on (absolute times are the host's)."""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def main():
    prob = json.load(open(sys.argv[1]))
    model = sys.argv[2]
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 50
    box = all(abs(v) < 1e299 for v in prob["lower"])
    problem = builtin_problem(prob) if model == "builtin" else python_problem(prob)
    solver, times = solve(problem, prob, box, runs)
    u = np.array([np.array(v) for v in solver.us])
    u_vic = np.array(prob["vic"]["u"])
    median = statistics.median(times)
    vic = prob["vic"]
    print(json.dumps({
        "problem": prob["name"],
        "cpu_model": cpu_model(),
        "crocoddyl_model": model,
        "crocoddyl_solver": "BoxDDP" if box else "DDP",
        "runs": runs,
        "crocoddyl_median_ms": median,
        "crocoddyl_min_ms": min(times),
        "crocoddyl_iterations": solver.iter,
        "crocoddyl_cost": solver.cost,
        "vic_median_ms": vic["median_ms"],
        "vic_min_ms": vic["min_ms"],
        "vic_iterations": vic["iterations"],
        "vic_cost": vic["cost"],
        "cost_rel_diff": abs(solver.cost - vic["cost"]) / abs(vic["cost"]),
        "max_abs_u_diff": float(np.max(np.abs(u - u_vic))),
        "ratio_crocoddyl_over_vic": median / vic["median_ms"],
        "ms_per_iteration": {"crocoddyl": median / max(solver.iter, 1),
                             "vic": vic["median_ms"] / max(vic["iterations"], 1)},
    }))


if __name__ == "__main__":
    main()
