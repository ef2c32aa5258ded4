"""vic in Python: plan, simulate and sweep variable-impedance movements, and read recordings.

The same library as the ``vic`` command line (one wheel, built by maturin from
``crates/vic-py``): for the same scenario and seed, :func:`plan` and :func:`simulate` give the
numbers ``vic plan`` and ``vic simulate`` give, to the last bit. Arrays are NumPy ``float64``;
the solver and the trials run without the GIL.

>>> import vic
>>> s = vic.Scenario.load("config/single_joint_delay.toml", set={"noise.sigma": 0.05})
>>> p = vic.plan(s, method="sooc")               # stochastic optimal open-loop control
>>> p.time.shape, p.stiffness.shape, p.expected_cost
>>> sim = vic.simulate(s, p, policy="open-loop", trials=50, seed=1)
>>> sim.x.shape, sim.final_std, sim.unit          # (50, N+1, nx), spread, "deg"

Units: time [s], joint angles [rad], velocities [rad/s], torques [N m], stiffness [N m/rad],
latencies [ms]; final errors and spreads in :attr:`Plan.final_error_unit` (mm of hand for the
two-link arm, degrees for a single joint).

Errors are exceptions of this package, one per class (:class:`ScenarioKeyError` names the file
and the ``[section] key``, :class:`PlanError`, :class:`PlanFileError`, :class:`RecordingError`);
wrong argument types raise ``TypeError`` and values out of range ``ValueError``. A bug inside
vic raises :class:`InternalError` instead of crashing the interpreter.
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterable, Optional, Sequence, Union

import numpy as np

from . import _vic
from ._vic import (
    InternalError,
    OverrideError,
    PlanError,
    PlanFileError,
    RecordingError,
    Scenario,
    ScenarioError,
    ScenarioKeyError,
    ScenarioReadError,
    ScenarioSyntaxError,
    VicError,
)

__version__ = _vic.__version__

__all__ = [
    "Scenario",
    "Plan",
    "Simulation",
    "plan",
    "simulate",
    "sweep_latency",
    "read_mcap",
    "VicError",
    "ScenarioError",
    "ScenarioReadError",
    "ScenarioSyntaxError",
    "ScenarioKeyError",
    "OverrideError",
    "PlanError",
    "PlanFileError",
    "RecordingError",
    "InternalError",
]

PathLike = Union[str, "os.PathLike[str]"]


def _array(t) -> np.ndarray:
    """A ``(dtype, shape, bytearray)`` triple of the extension as a NumPy array (no copy)."""
    dtype, shape, buf = t
    return np.frombuffer(buf, dtype=np.dtype(dtype)).reshape(shape)


def _array_in(name: str, a: Any):
    """An array argument as the extension takes it: its shape and float64 bytes (the extension
    checks the shape and that every entry is finite)."""
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be an array of numbers, not of dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype="<f8")
    return (list(arr.shape), arr.tobytes())


def _seed(seed: Any) -> int:
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool):
        raise TypeError(f"seed must be a whole number, not {type(seed).__name__}")
    if not 0 <= int(seed) < 2**64:
        raise ValueError(f"seed={seed}: 0 to 2**64 - 1")
    return int(seed)


def _scenario(scenario: Any) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, (str, os.PathLike)):
        return Scenario.load(scenario)
    raise TypeError(
        "scenario must be a vic.Scenario or the path of a scenario file, "
        f"not {type(scenario).__name__}"
    )


class Plan:
    """A plan: the nominal movement, its commands and feedback gains, and the solver's summary.

    Made by :func:`plan` or read by :meth:`Plan.load` (the JSON of ``vic plan --out``). Arrays
    (NumPy ``float64``; N steps of ``dt`` seconds, n states, m controls, ``dof`` joints):

    - ``time`` (N+1,) [s]: the knots ``0, dt, …, N dt``;
    - ``x`` (N+1, n): nominal states, columns ``state_names`` (``q``/``q1, q2`` [rad], then
      ``*_dot`` [rad/s], then a VSA's motor angles and speeds);
    - ``u`` (N, m): commands, columns ``control_names`` (torques ``tau*`` [N m], then the
      stiffnesses ``k*`` [N m/rad] when the actuator has them). With a feedback delay of d steps,
      command k acts at step k + d;
    - ``feedforward`` (N, dof) [N m] and ``stiffness`` (N, dof) [N m/rad]: those columns of ``u``
      (``stiffness`` is ``None`` for a torque-only actuator);
    - ``gains`` (N, m, n): feedback gains L_k of ``u = ū + L (x − x̄)`` (zeros for SOOC);
    - ``reference_q``, ``reference_qd`` (N+1, dof): the desired movement [rad, rad/s];
    - ``open_loop_final_covariance`` (n, n): the final state's covariance executed open loop
      (predicted by moment propagation), and ``open_loop_final_position_covariance``: the hand's
      [m²] (2, 2) or the joint angle's [rad²] (1, 1).

    The summary is ``summary`` (the dict ``vic plan --json`` prints) and attributes of the same
    names: ``method``, ``converged``, ``stop``, ``iterations``, ``cost``, ``expected_cost``,
    ``solve_ms`` [ms], ``max_stiffness``, ``mean_stiffness`` [N m/rad], ``delay_steps``,
    ``delay_ms`` [ms], ``final_error`` (in ``final_error_unit``), ``open_loop_expected_cost``,
    ``open_loop_final_std`` (in ``final_error_unit``).
    """

    _SUMMARY = (
        "method",
        "converged",
        "stop",
        "iterations",
        "cost",
        "expected_cost",
        "solve_ms",
        "max_stiffness",
        "mean_stiffness",
        "delay_steps",
        "delay_ms",
        "final_error",
        "final_error_unit",
        "open_loop_expected_cost",
        "open_loop_final_std",
    )

    def __init__(self, inner: "_vic.Plan"):
        if not isinstance(inner, _vic.Plan):
            raise TypeError("make a Plan with vic.plan(...) or vic.Plan.load(path)")
        self._p = inner
        arrays = inner.arrays()
        self.time: np.ndarray = _array(arrays["time"])
        self.x: np.ndarray = _array(arrays["x"])
        self.u: np.ndarray = _array(arrays["u"])
        self.gains: np.ndarray = _array(arrays["gains"])
        self.reference_q: np.ndarray = _array(arrays["reference_q"])
        self.reference_qd: np.ndarray = _array(arrays["reference_qd"])
        self.open_loop_final_covariance: np.ndarray = _array(arrays["open_loop_final_covariance"])
        self.open_loop_final_position_covariance: np.ndarray = _array(
            arrays["open_loop_final_position_covariance"]
        )
        self.summary: Dict[str, Any] = inner.summary()
        self.state_names = list(inner.state_names)
        self.control_names = list(inner.control_names)
        self.dt: float = inner.dt
        self.scenario: str = inner.scenario
        self.dof = sum(1 for c in self.control_names if c.startswith("tau"))

    @property
    def feedforward(self) -> np.ndarray:
        """The torque commands (N, dof) [N m] (a VSA's motor torques)."""
        return self.u[:, : self.dof]

    @property
    def stiffness(self) -> Optional[np.ndarray]:
        """The stiffness commands (N, dof) [N m/rad], or None without a stiffness control."""
        cols = [i for i, c in enumerate(self.control_names) if c.startswith("k")]
        return self.u[:, cols] if cols else None

    @property
    def config(self) -> Dict[str, Any]:
        """The scenario's configuration as resolved (after the overrides)."""
        return self._p.config

    def __getattr__(self, name: str):
        if name in Plan._SUMMARY:
            return self.summary[name]
        raise AttributeError(f"Plan has no attribute {name!r}")

    def column(self, name: str) -> np.ndarray:
        """A state (of ``x``) or a control (of ``u``) by its name, e.g. ``"q1"``, ``"k2"``."""
        if name in self.state_names:
            return self.x[:, self.state_names.index(name)]
        if name in self.control_names:
            return self.u[:, self.control_names.index(name)]
        raise KeyError(
            f"no state or control named {name!r} (states {self.state_names}, "
            f"controls {self.control_names})"
        )

    def save(self, path: PathLike) -> None:
        """Writes the plan file (the format ``vic plan --out`` writes and ``vic simulate --plan``
        reads). Raises :class:`PlanFileError` when it cannot be written."""
        self._p.save(os.fspath(path))

    @classmethod
    def load(cls, path: PathLike) -> "Plan":
        """Reads a plan file (``vic plan --out``, :meth:`save`). Raises :class:`PlanFileError`
        when it cannot be read, is not a plan, or its arrays do not fit together."""
        return cls(_vic.Plan.load(os.fspath(path)))

    def predict_open_loop(self, scenario: Union[Scenario, PathLike]) -> Dict[str, Any]:
        """The plan's commands executed open loop (gains ignored) on ``scenario``, predicted
        without sampling by propagating the state's mean and covariance (the moments of the
        Euler–Maruyama plant, Eq. 10): ``mean`` (N+1, n) the mean state at each knot,
        ``final_covariance`` (n, n) and ``expected_cost`` (on the plan's own scenario, the
        summary's ``open_loop_expected_cost``). Raises :class:`PlanError` when the plan does not
        fit the scenario."""
        out = self._p.predict_open_loop(_scenario(scenario))
        return {
            "mean": _array(out["mean"]),
            "final_covariance": _array(out["final_covariance"]),
            "expected_cost": out["expected_cost"],
        }

    def with_arrays(self, u=None, x=None, gains=None) -> "Plan":
        """The same plan with ``u`` (N, m), ``x`` (N+1, n) or ``gains`` (N, m, n) replaced, e.g.
        the stiffness scaled to simulate what it buys. Each must have the shape of the array it
        replaces and finite entries (else ``ValueError``). The summary stays the original's."""
        args = {}
        for name, a in (("u", u), ("x", x), ("gains", gains)):
            if a is not None:
                args[name] = _array_in(name, a)
        return Plan(self._p.with_arrays(**args))

    def __repr__(self) -> str:
        return (
            f"<vic.Plan {self.method} of {self.scenario}: {len(self.u)} steps of {self.dt} s, "
            f"expected cost {self.expected_cost:.6g}>"
        )


def plan(
    scenario: Union[Scenario, PathLike],
    method: Optional[str] = None,
    delay_ms: Optional[float] = None,
) -> Plan:
    """Plans a movement, as ``vic plan`` does.

    ``method``: ``"ilqg"`` (a nominal plan with locally optimal feedback gains, made for the
    feedback delay) or ``"sooc"`` (torque and stiffness for execution without feedback); default
    the scenario's ``[solver] method``. ``delay_ms``: the feedback latency the plan is made for
    [ms], a whole number of steps (default the scenario's ``task.delay_ms``). Raises
    :class:`PlanError` when the solver fails.
    """
    if delay_ms is not None and not isinstance(delay_ms, (int, float, np.number)):
        raise TypeError(f"delay_ms must be a number of ms, not {type(delay_ms).__name__}")
    return Plan(_vic.plan(_scenario(scenario), method, None if delay_ms is None else float(delay_ms)))


class Simulation:
    """The trials of :func:`simulate` and their summary.

    Arrays: ``x`` (trials, N+1, n) states, ``u`` (trials, N, m) the commands executed (after
    feedback and clamping), ``cost`` (trials,) each trial's realised cost, ``time`` (N+1,) [s].
    A trial that blew up has non-finite states from there on.

    ``summary`` is the dict ``vic simulate --json`` prints; its entries are attributes too:
    ``trials``, ``unit`` ("mm" of hand or "deg" of joint), ``final_std``, ``ellipse_95``
    (semi-axes of the 95 % ellipse of the final position), ``rms_error``, ``final_error_mean``,
    ``final_error_max`` (over the trials that did not diverge; None when all did),
    ``diverged``, ``diverged_fraction``, ``far_fraction``, ``expected_cost_mc``,
    ``expected_cost_se``, ``expected_cost_predicted``, ``policy``, ``seed``; all distances in
    ``unit``.
    """

    def __init__(self, result: Dict[str, Any], time: np.ndarray):
        self.x: np.ndarray = _array(result["x"])
        self.u: np.ndarray = _array(result["u"])
        self.cost: np.ndarray = _array(result["cost"])
        self.time = time
        self.summary: Dict[str, Any] = result["summary"]

    def __getattr__(self, name: str):
        summary = self.__dict__.get("summary", {})
        if name in summary:
            return summary[name]
        raise AttributeError(f"Simulation has no attribute {name!r}")

    def __repr__(self) -> str:
        s = self.summary
        return (
            f"<vic.Simulation {s['trials']} trials: final std {s['final_std']:.4g} {s['unit']}, "
            f"{s['diverged']} diverged>"
        )


def simulate(
    scenario: Union[Scenario, PathLike],
    plan: Plan,
    policy: str = "open-loop",
    trials: int = 20,
    seed: int = 1,
    latency_ms: Optional[float] = None,
    divergence: Optional[float] = None,
) -> Simulation:
    """Runs a Monte Carlo of ``plan`` on the scenario's stochastic plant, as ``vic simulate``.

    ``policy``: ``"open-loop"`` (the commands alone), ``"feedback"`` (the plan's gains on the
    present state), ``"naive-delayed"`` (the gains on the state seen ``latency_ms`` late; default
    the plan's delay), ``"predictor"`` (a Smith predictor across ``latency_ms``, default 0),
    ``"stiffness"``, ``"stiffness+predictor"`` or ``"replan"`` (the central strategies).
    ``trials``: 2 to 100000; ``seed``: each trial derives its own noise stream from it, so the
    result does not depend on the threads. ``divergence``: a trial ending further than this from
    the target has diverged [mm of hand for the arm, degrees for a joint; default 50 mm / 10°].
    The scenario may differ from the plan's (e.g. in noise) but not in its steps and sizes
    (else :class:`PlanError`).
    """
    if not isinstance(plan, Plan):
        raise TypeError(f"plan must be a vic.Plan, not {type(plan).__name__}")
    if not isinstance(trials, (int, np.integer)) or isinstance(trials, bool):
        raise TypeError(f"trials must be a whole number, not {type(trials).__name__}")
    result = _vic.simulate(
        _scenario(scenario),
        plan._p,
        policy,
        int(trials),
        _seed(seed),
        None if latency_ms is None else float(latency_ms),
        None if divergence is None else float(divergence),
    )
    return Simulation(result, plan.time)


_POINT_FIELDS = (
    "latency_ms",
    "final_error_mean",
    "final_error_max",
    "rms_error",
    "diverged",
    "diverged_fraction",
    "expected_cost_mc",
    "expected_cost_predicted",
    "mean_stiffness",
)


def sweep_latency(
    scenario: Union[Scenario, PathLike],
    latencies_ms: Sequence[float] = (0, 20, 50, 100, 150, 200, 300),
    strategies: Sequence[str] = ("naive-delayed", "predictor", "stiffness"),
    trials: int = 20,
    seed: int = 1,
    divergence: Optional[float] = None,
    pulse: Optional[Union[float, Sequence[float]]] = None,
    pulse_at_ms: float = 400.0,
    pulse_ms: float = 50.0,
    engine: str = "offline",
) -> Dict[str, Any]:
    """Delay versus stiffness as a curve, as ``vic sweep latency --json``: for each strategy and
    latency, plan (for the latency where the strategy needs it) and run the trials.

    The scenario is re-read from its file with its overrides (a scenario made by
    ``Scenario.from_str`` has no file to sweep). ``strategies``: ``naive-delayed``,
    ``predictor``, ``stiffness``, ``stiffness+predictor``, ``replan`` (slow). ``pulse``: a torque
    pulse [N m] on the first joint (or one per joint) from ``pulse_at_ms`` for ``pulse_ms``
    [ms], unknown to every controller. ``engine``: ``"offline"`` (the Monte Carlo) or
    ``"lockstep"`` (the 1 kHz board and the 50 Hz controller on a simulated clock).

    Returns a dict of arrays, one entry per point (strategy-major): ``strategy`` (str),
    ``latency_ms`` [ms], ``final_error_mean``, ``final_error_max``, ``rms_error`` (in ``unit``;
    NaN where every trial diverged), ``diverged``, ``diverged_fraction``, ``expected_cost_mc``,
    ``expected_cost_predicted`` (NaN where not predicted), ``mean_stiffness`` [N m/rad]; and
    ``unit``, ``crossings`` (where each feedback strategy's lead ends) and ``sweep`` (the whole
    JSON of ``vic sweep latency --json``).
    """
    if isinstance(pulse, (int, float, np.number)):
        pulse = [float(pulse)]
    sweep = _vic.sweep_latency(
        _scenario(scenario),
        [float(v) for v in latencies_ms],
        [str(s) for s in strategies],
        int(trials),
        _seed(seed),
        None if divergence is None else float(divergence),
        None if pulse is None else [float(t) for t in pulse],
        float(pulse_at_ms),
        float(pulse_ms),
        engine,
    )
    points = sweep["points"]
    out: Dict[str, Any] = {"strategy": np.array([p["strategy"] for p in points], dtype=str)}
    for field in _POINT_FIELDS:
        values = [p.get(field) for p in points]
        if field == "diverged":
            out[field] = np.array(values, dtype=np.int64)
        else:
            out[field] = np.array([np.nan if v is None else v for v in values], dtype=float)
    out["unit"] = points[0]["unit"] if points else None
    out["crossings"] = sweep.get("crossings", [])
    out["sweep"] = sweep
    return out


def _column_array(value) -> np.ndarray:
    if isinstance(value, tuple):
        return _array(value)
    return np.array(value, dtype=object)


def read_mcap(path: PathLike, pandas: Optional[bool] = None) -> Dict[str, Any]:
    """Every channel of an MCAP recording (``vic-board --record run.mcap``, ``vic record``) as
    columns: ``{topic: table}`` in the order of the channels' first messages.

    Each JSON field of the messages is a column (nested objects as ``outer.inner``), beside
    ``log_time`` and ``publish_time`` [ns, CLOCK_MONOTONIC of the recording machine] and
    ``sequence``. Numbers are ``int64``/``uint64`` when every message has a whole number there,
    else ``float64`` (a missing or non-finite value is NaN); per-joint lists are 2-D
    (messages, joints). Messages of another encoding keep their bytes in ``data``.

    ``pandas``: a ``pandas.DataFrame`` per topic (2-D columns split into ``q[0]``, ``q[1]``, …;
    the encoding and schema in ``DataFrame.attrs``) when True, or when None and pandas is
    installed; else a dict of NumPy arrays. Raises :class:`RecordingError` for a file that is not
    MCAP or cannot be read.
    """
    channels = _vic.read_mcap_columns(os.fspath(path))
    if pandas is None:
        try:
            import pandas as _pd  # noqa: F401
        except ImportError:
            pandas = False
        else:
            pandas = True
    out: Dict[str, Any] = {}
    for topic, (info, columns) in channels.items():
        cols = {name: _column_array(v) for name, v in columns.items()}
        if pandas:
            import pandas as pd

            flat = {}
            for name, a in cols.items():
                if a.ndim == 2:
                    for j in range(a.shape[1]):
                        flat[f"{name}[{j}]"] = a[:, j]
                else:
                    flat[name] = a
            df = pd.DataFrame(flat)
            df.attrs.update(info)
            out[topic] = df
        else:
            out[topic] = cols
    return out
