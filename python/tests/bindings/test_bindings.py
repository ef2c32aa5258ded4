"""The `vic` package (the wheel of crates/vic-py) against the `vic` command line and against
independent readers: run by tests/python_bindings.rs with the interpreter of `VIC_PYTHON` (the
wheel installed there) and `VIC_BIN` naming the `vic` binary of the same build.

- plan, simulate and sweep: for the same scenario, overrides and seed, the package's numbers
  equal the command line's to the last bit (the written plan files, the JSON summaries, every
  trial's states and commands in `vic simulate --csv`), the solve time aside;
- read_mcap: an MCAP file written by the `mcap` package reads back to the values written, and a
  board-format file to the numbers `vic convert` reads from it;
- bad input of every kind raises a Python exception naming what is wrong, never a crash; a panic
  inside vic arrives as vic.InternalError;
- the solver runs without the GIL: another Python thread runs meanwhile.

Standalone: `VIC_BIN=target/release/vic python -m pytest python/tests/bindings` with the wheel
installed (`maturin build --release` at the root, then pip install the wheel).
"""

import json
import math
import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import vic

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "config"
VIC_BIN = os.environ.get("VIC_BIN")

needs_cli = pytest.mark.skipif(
    not VIC_BIN, reason="VIC_BIN (the vic binary to compare with) is not set"
)


def test_the_installed_package_is_this_checkouts():
    """The tests run against the installed wheel: one built from another checkout would test
    other code (rebuild it: python/README.md)."""
    installed = Path(vic.__file__).parent
    assert installed != ROOT / "python/vic", "the checkout's python/vic has no extension module"
    for name in ("__init__.py", "live.py", "_vic.pyi"):
        assert (installed / name).read_text() == (ROOT / "python/vic" / name).read_text(), (
            f"the installed vic/{name} is not this checkout's: rebuild and reinstall the wheel")


def cli(*args):
    """Runs `vic ARGS`, returns stdout; a failure fails the test with vic's message."""
    out = subprocess.run([VIC_BIN, *map(str, args)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"vic {' '.join(map(str, args))}: {out.stderr}"
    return out.stdout


def set_flags(overrides):
    flags = []
    for k, v in overrides.items():
        flags += ["--set", f"{k}={v}"]
    return flags


def without_solve_time(plan_json):
    """A plan file's JSON without the solver's wall-clock time (the one number that differs
    between two solves)."""
    plan_json = json.loads(json.dumps(plan_json))
    summary = plan_json.get("summary", plan_json)
    assert summary.pop("solve_ms") > 0
    return plan_json


# Scenario, overrides, method and delay: ILQG without and with a delay, SOOC, a single joint.
CASES = [
    ("two_link_divergent.toml", {"noise.sigma": 0.02}, "ilqg", None),
    ("two_link_divergent.toml", {}, "ilqg", 50),
    ("two_link_divergent.toml", {"noise.sigma": 0.02}, "sooc", None),
    ("single_joint_delay.toml", {"task.duration": 1.0}, "ilqg", 0),
]


@needs_cli
@pytest.mark.parametrize("config,overrides,method,delay", CASES)
def test_plan_equals_the_command_lines_to_the_last_bit(tmp_path, config, overrides, method, delay):
    path = str(CONFIG / config)
    flags = ["plan", "--config", path, *set_flags(overrides), "--method", method]
    if delay is not None:
        flags += ["--latency-ms", delay]
    cli_file = tmp_path / "cli.json"
    summary = json.loads(cli(*flags, "--out", cli_file, "--json"))

    s = vic.Scenario.load(path, set=overrides)
    p = vic.plan(s, method=method, delay_ms=delay)
    py_file = tmp_path / "py.json"
    p.save(py_file)

    cli_plan = json.loads(cli_file.read_text())
    py_plan = json.loads(py_file.read_text())
    # Python's json reads each float to the f64 serde_json wrote (shortest round trip): equal
    # dicts are equal bits.
    assert without_solve_time(py_plan) == without_solve_time(cli_plan)
    assert without_solve_time(p.summary) == without_solve_time(summary)
    # The arrays are the file's numbers.
    assert np.array_equal(p.x, np.array(cli_plan["x"]))
    assert np.array_equal(p.u, np.array(cli_plan["u"]))
    assert np.array_equal(p.gains, np.array(cli_plan["gains"]))
    assert np.array_equal(p.time, np.array(cli_plan["time"]))
    assert np.array_equal(p.reference_q[:, 0], [r["q_d"][0] for r in cli_plan["reference"]])
    assert np.array_equal(
        p.open_loop_final_covariance, np.array(cli_plan["open_loop_final_covariance"])
    )
    assert p.expected_cost == summary["expected_cost"] and p.method == method
    assert p.delay_ms == summary["delay_ms"]
    # The stiffness is the k columns.
    k = [i for i, c in enumerate(cli_plan["control_names"]) if c.startswith("k")]
    assert np.array_equal(p.stiffness, np.array(cli_plan["u"])[:, k])
    # Read back, the file is the same plan.
    again = vic.Plan.load(cli_file)
    assert np.array_equal(again.u, p.u) and again.summary == summary


@needs_cli
@pytest.mark.parametrize(
    "policy,latency",
    [("open-loop", None), ("feedback", None), ("naive-delayed", None), ("predictor", 50)],
)
def test_simulate_equals_the_command_lines_trial_by_trial(tmp_path, policy, latency):
    path = str(CONFIG / "two_link_divergent.toml")
    overrides = {"noise.sigma": 0.02}
    plan_file = tmp_path / "plan.json"
    cli("plan", "--config", path, *set_flags(overrides), "--latency-ms", 50, "--out", plan_file)
    csv = tmp_path / "trials.csv"
    flags = ["simulate", "--config", path, *set_flags(overrides), "--plan", plan_file,
             "--policy", policy, "--trials", 7, "--seed", 11, "--csv", csv, "--json"]
    if latency is not None:
        flags += ["--latency-ms", latency]
    summary = json.loads(cli(*flags))

    s = vic.Scenario.load(path, set=overrides)
    sim = vic.simulate(s, vic.Plan.load(plan_file), policy=policy, trials=7, seed=11,
                       latency_ms=latency)
    assert sim.summary == summary
    assert sim.final_std == summary["final_std"] and sim.unit == "mm"

    # Every trial's states and commands, as `vic simulate --csv` wrote them (shortest round-trip
    # decimals: exact).
    rows = np.genfromtxt(csv, delimiter=",", skip_header=1, missing_values="", filling_values=np.nan)
    trials, n1, nx = sim.x.shape
    nu = sim.u.shape[2]
    assert rows.shape == (trials * n1, 3 + nx + nu)
    for i in range(trials):
        block = rows[i * n1:(i + 1) * n1]
        assert np.array_equal(block[:, 3:3 + nx], sim.x[i], equal_nan=True)
        assert np.array_equal(block[:-1, 3 + nx:], sim.u[i], equal_nan=True)
    assert np.array_equal(sim.time, rows[:n1, 2])


@needs_cli
def test_sweep_equals_the_command_lines(tmp_path):
    path = str(CONFIG / "single_joint_delay.toml")
    overrides = {"task.duration": 1.0}
    out = json.loads(cli("sweep", "latency", "--config", path, *set_flags(overrides),
                         "--latencies", "0,100", "--strategies", "naive-delayed,stiffness",
                         "--trials", 4, "--seed", 3, "--json"))
    s = vic.Scenario.load(path, set=overrides)
    sw = vic.sweep_latency(s, latencies_ms=[0, 100], strategies=["naive-delayed", "stiffness"],
                           trials=4, seed=3)
    assert sw["sweep"] == out
    assert list(sw["strategy"]) == [p["strategy"] for p in out["points"]]
    assert list(sw["latency_ms"]) == [0.0, 100.0, 0.0, 100.0]
    for field in ("final_error_mean", "diverged_fraction", "mean_stiffness"):
        want = [math.nan if p[field] is None else p[field] for p in out["points"]]
        assert np.array_equal(sw[field], want, equal_nan=True), field


def test_a_scenario_reports_its_sizes_and_overrides():
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml",
                          set={"noise.sigma": 0.05, "task.duration": 0.5})
    assert (s.dof, s.dt) == (2, 0.01) and s.steps == round(0.5 / 0.01)
    assert s.config["noise"]["sigma"] == 0.05
    assert s.overrides == ["noise.sigma=0.05", "task.duration=0.5"]
    # A float override is written so that it reads back to the same number.
    x = 0.1 + 0.2
    assert vic.Scenario.load(CONFIG / "two_link_divergent.toml",
                             set={"noise.sigma": x}).config["noise"]["sigma"] == x


def test_an_edited_plan_simulates_what_it_holds():
    """Stiffness scaled down in an open-loop plan: the trials' spread grows (the edit reaches the
    simulation), and the plan with its own arrays simulates as the original."""
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"noise.sigma": 0.02})
    p = vic.plan(s, method="sooc")
    same = p.with_arrays(u=p.u)
    assert vic.simulate(s, same, trials=10).summary == vic.simulate(s, p, trials=10).summary
    u = p.u.copy()
    u[:, 2:] *= 0.2
    soft = p.with_arrays(u=u)
    assert np.array_equal(soft.stiffness, p.stiffness * 0.2)
    assert vic.simulate(s, soft, trials=10).final_std > vic.simulate(s, p, trials=10).final_std


def test_the_solver_runs_without_the_gil():
    """While a plan is solved in one thread, the main thread keeps running Python: the longest
    pause between its steps inside the solve is a part of the solve (with the GIL held
    for the whole solve, it would not run at all until the solve ends: one pause as long as the
    solve)."""
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml")
    span = {}

    def solve():
        t0 = time.perf_counter()
        vic.plan(s, method="sooc")
        span["t"] = (t0, time.perf_counter())

    worker = threading.Thread(target=solve)
    stamps = []
    worker.start()
    while worker.is_alive():
        stamps.append(time.perf_counter())
        time.sleep(0.001)
    worker.join()
    t0, t1 = span["t"]
    inside = [t for t in stamps if t0 < t < t1]
    pauses = np.diff([t0, *inside, t1])
    assert t1 - t0 > 0.05, "a solve long enough to tell"
    # Held, the pause is the whole solve; three quarters leave room for a loaded machine.
    assert pauses.max() < 0.75 * (t1 - t0), (pauses.max(), t1 - t0, len(inside))


# -- MCAP --------------------------------------------------------------------------------------


def write_mcap(path, topic, messages, compression="lz4", log_times=None):
    from mcap.writer import CompressionType, Writer

    kind = {"lz4": CompressionType.LZ4, "none": CompressionType.NONE,
            "zstd": CompressionType.ZSTD}[compression]
    with open(path, "wb") as f:
        w = Writer(f, compression=kind)
        w.start()
        schema = w.register_schema(name="test", encoding="jsonschema", data=b"{}")
        ch = w.register_channel(topic=topic, message_encoding="json", schema_id=schema)
        for i, m in enumerate(messages):
            t = log_times[i] if log_times else 1000 + i
            w.add_message(ch, log_time=t, publish_time=t, data=json.dumps(m).encode(), sequence=i)
        w.finish()


def tick(i, joints=2):
    """A message of the board's tick channel (vic_rt's TickMsg)."""
    rng = np.random.default_rng(i)
    arr = lambda: [float(v) for v in rng.normal(size=joints)]  # noqa: E731
    return {"tick": i + 1, "dropped_before": 0, "deadline_ns": 10**18 + i * 10**6,
            "t": i * 1e-3, "trial": 1, "mode": 1, "trial_time": i * 1e-3, "periods": 1,
            "command_seq": 2, "disturbance_seq": 0, "q": arr(), "qd": arr(), "qdd": arr(),
            "tau": arr(), "tau_ext": arr(), "tau_ff": arr(), "stiffness": arr(),
            "damping": arr(), "q_d": arr(), "qd_d": arr()}


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_read_mcap_returns_the_values_written(tmp_path, compression):
    f = tmp_path / "x.mcap"
    msgs = [{"a": i, "b": i * 0.5, "name": f"m{i}", "v": [i, None], "inner": {"c": -i}}
            for i in range(50)]
    write_mcap(f, "/x", msgs, compression, log_times=[2**62 + i for i in range(50)])
    cols = vic.read_mcap(f, pandas=False)["/x"]
    assert cols["a"].dtype == np.int64 and list(cols["a"]) == list(range(50))
    assert np.array_equal(cols["b"], [m["b"] for m in msgs])
    assert list(cols["name"]) == [m["name"] for m in msgs]
    assert cols["v"].shape == (50, 2) and np.isnan(cols["v"][:, 1]).all()
    assert list(cols["inner.c"]) == [-i for i in range(50)]
    assert cols["log_time"].dtype == np.uint64 and int(cols["log_time"][-1]) == 2**62 + 49


@needs_cli
def test_read_mcap_of_a_board_recording_equals_vic_convert(tmp_path):
    f, csv = tmp_path / "board.mcap", tmp_path / "board.csv"
    msgs = [tick(i) for i in range(200)]
    write_mcap(f, "/board/tick", msgs)
    cli("convert", f, "--csv", csv)
    rec = vic.read_mcap(f, pandas=False)["/board/tick"]
    header = next(line for line in csv.read_text().splitlines() if not line.startswith("#"))
    names = header.split(",")
    rows = np.genfromtxt(csv, delimiter=",", comments="#", skip_header=2)
    assert rows.shape[0] == 200
    assert np.array_equal(rec["q"][:, 0], rows[:, names.index("q")])
    assert np.array_equal(rec["tau_ff"][:, 0], rows[:, names.index("tau_ff")])
    assert np.array_equal(rec["q"], np.array([m["q"] for m in msgs]))
    assert rec["deadline_ns"].dtype == np.uint64 or rec["deadline_ns"].dtype == np.int64
    assert int(rec["deadline_ns"][-1]) == 10**18 + 199 * 10**6


def test_read_mcap_makes_data_frames_with_pandas(tmp_path):
    pd = pytest.importorskip("pandas")
    f = tmp_path / "x.mcap"
    write_mcap(f, "/board/tick", [tick(i) for i in range(5)])
    df = vic.read_mcap(f)["/board/tick"]
    assert isinstance(df, pd.DataFrame) and len(df) == 5
    assert np.array_equal(df["q[1]"].to_numpy(), [tick(i)["q"][1] for i in range(5)])
    assert df.attrs["encoding"] == "json"


# -- bad input ---------------------------------------------------------------------------------


def raises(kind, *parts):
    """pytest.raises whose message must hold every one of `parts`."""
    class Check:
        def __enter__(self):
            self.ctx = pytest.raises(kind)
            self.info = self.ctx.__enter__()
            return self.info

        def __exit__(self, *exc):
            out = self.ctx.__exit__(*exc)
            message = str(self.info.value)
            for p in parts:
                assert p in message, (p, message)
            return out

    return Check()


def test_a_missing_scenario_file_names_the_file(tmp_path):
    missing = tmp_path / "nope.toml"
    with raises(vic.ScenarioReadError, str(missing), "cannot read") as e:
        vic.Scenario.load(missing)
    assert isinstance(e.value, vic.ScenarioError) and e.value.path == str(missing)


def test_an_unknown_key_names_the_file_the_section_and_the_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((CONFIG / "two_link_divergent.toml").read_text()
                   .replace("[noise]", "[noise]\nsigmaa = 1.0"))
    with raises(vic.ScenarioKeyError, str(bad), "[noise] sigmaa", "unknown field") as e:
        vic.Scenario.load(bad)
    assert (e.value.section, e.value.key, e.value.override) == ("noise", "sigmaa", None)
    # The same key from set= blames the entry, not the file.
    with raises(vic.ScenarioKeyError, "[noise] sigmaa", 'set={"noise.sigmaa": 1}') as e:
        vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"noise.sigmaa": 1})
    assert e.value.override == "noise.sigmaa=1"


def test_bad_values_are_refused_with_the_key():
    path = CONFIG / "two_link_divergent.toml"
    with raises(vic.ScenarioKeyError, "[task] dt"):
        vic.Scenario.load(path, set={"task.dt": -0.01})
    with raises(ValueError, "noise.sigma", "not a finite number"):
        vic.Scenario.load(path, set={"noise.sigma": float("nan")})
    with raises(TypeError, "noise.sigma", "not dict"):
        vic.Scenario.load(path, set={"noise.sigma": {}})
    with raises(TypeError, "set must be a dict"):
        vic.Scenario.load(path, set=["noise.sigma=1"])
    with raises(vic.OverrideError, "sigma", "section.key"):
        vic.Scenario.load(path, set={"sigma": 1.0})
    with raises(vic.ScenarioSyntaxError, "<string>"):
        vic.Scenario.from_str("this is not toml")
    with raises(TypeError):
        vic.Scenario.load(42)


def test_bad_arguments_of_plan_and_simulate():
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"task.duration": 0.3})
    with raises(ValueError, "method", "ilqg", "sooc", "lqg"):
        vic.plan(s, method="lqg")
    with raises(ValueError, "delay_ms=25", "whole number of 10 ms"):
        vic.plan(s, delay_ms=25)
    with raises(ValueError, "delay_ms=NaN", "0 to 1000 ms"):
        vic.plan(s, delay_ms=float("nan"))
    with raises(TypeError, "delay_ms"):
        vic.plan(s, delay_ms="50")
    with raises(TypeError, "scenario"):
        vic.plan(3.0)
    p = vic.plan(s)
    with raises(ValueError, "trials=1", "2 to 100000"):
        vic.simulate(s, p, trials=1)
    with raises(TypeError, "trials"):
        vic.simulate(s, p, trials="3")
    with raises(ValueError, "seed=-1"):
        vic.simulate(s, p, seed=-1)
    with raises(ValueError, "policy", "open-loop"):
        vic.simulate(s, p, policy="closed")
    with raises(TypeError, "plan must be a vic.Plan"):
        vic.simulate(s, {"u": []})
    with raises(ValueError, "divergence"):
        vic.simulate(s, p, divergence=float("inf"))
    # A plan of another scenario (other steps) does not run on this one.
    longer = vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"task.duration": 0.5})
    with raises(vic.PlanError, "steps", "do not match"):
        vic.simulate(longer, p)
    with raises(ValueError, "strateg", "one of"):
        vic.sweep_latency(s, latencies_ms=[0], strategies=["fast"])


def test_wrong_arrays_are_refused_with_their_shape_or_entry():
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"task.duration": 0.3})
    p = vic.plan(s)
    n, m = p.u.shape
    with raises(ValueError, "u has shape", f"({n}, {m - 1})", f"expected ({n}, {m})"):
        p.with_arrays(u=p.u[:, 1:])
    u = p.u.copy()
    u[3, 1] = np.nan
    with raises(ValueError, "u[3, 1] is NaN", "finite"):
        p.with_arrays(u=u)
    with raises(ValueError, "gains has shape"):
        p.with_arrays(gains=np.zeros((n, m)))
    with raises(TypeError, "numbers"):
        p.with_arrays(x=np.array([["a"]]))


def test_bad_plan_files_and_recordings(tmp_path):
    with raises(vic.PlanFileError, "nope.json", "cannot read"):
        vic.Plan.load(tmp_path / "nope.json")
    junk = tmp_path / "junk.json"
    junk.write_text('{"version": 1}')
    with raises(vic.PlanFileError, "junk.json", "not a plan file"):
        vic.Plan.load(junk)
    # A plan whose states are ragged (a hostile or damaged file).
    s = vic.Scenario.load(CONFIG / "two_link_divergent.toml", set={"task.duration": 0.3})
    good = tmp_path / "good.json"
    vic.plan(s).save(good)
    raw = json.loads(good.read_text())
    raw["x"][4] = raw["x"][4][:-1]
    ragged = tmp_path / "ragged.json"
    ragged.write_text(json.dumps(raw))
    with raises(vic.PlanFileError, "ragged.json", "x[4] has 3 values, state_names has 4"):
        vic.Plan.load(ragged)
    with raises(vic.PlanFileError, "cannot write"):
        vic.Plan.load(good).save(tmp_path / "no" / "such" / "dir.json")
    with raises(vic.RecordingError, "junk.json", "not an MCAP file"):
        vic.read_mcap(junk)
    zstd = tmp_path / "zstd.mcap"
    write_mcap(zstd, "/x", [{"a": 1}], compression="zstd")
    with raises(vic.RecordingError, "zstd.mcap"):
        vic.read_mcap(zstd)


def test_a_panic_inside_vic_is_a_python_exception():
    with raises(vic.InternalError, "internal error in vic", "boom") as e:
        vic._vic._panic("boom")
    assert isinstance(e.value, vic.VicError)
    # The interpreter and the module go on working.
    assert vic.Scenario.load(CONFIG / "two_link_divergent.toml").dof == 2


# -- the examples ------------------------------------------------------------------------------


def load_example(name, monkeypatch):
    """An example of python/examples imported with matplotlib made unimportable: an example
    needs it to draw only, never to compute."""
    import importlib.util
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    spec = importlib.util.spec_from_file_location(name, ROOT / "python/examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_examples_compute_without_matplotlib(monkeypatch, tmp_path):
    ex = load_example("plan_and_plot", monkeypatch)
    overrides = ex.parse_set(["noise.sigma=0.02", "task.duration=0.4"])
    s, p, sim = ex.compute(str(CONFIG / "two_link_divergent.toml"), "sooc", overrides, trials=5)
    assert s.config["noise"]["sigma"] == 0.02 and s.steps == 40
    assert sim.x.shape == (5, 41, 4) and p.stiffness.shape == (40, 2)
    with pytest.raises(ImportError):
        import matplotlib  # noqa: F401

    ex = load_example("read_recording", monkeypatch)
    f = tmp_path / "r.mcap"
    write_mcap(f, "/board/tick", [tick(i) for i in range(30)])
    lines, rec = ex.summarize(f)
    assert lines[0].startswith("/board/tick: 30 messages over 0.000 s") and "stiffness" in lines[0]

    ex = load_example("delay_sweep", monkeypatch)
    sw = ex.compute(str(CONFIG / "single_joint_delay.toml"), [0.0, 50.0], ["stiffness"], trials=3)
    assert list(sw["latency_ms"]) == [0.0, 50.0]
    # The open-loop plan sees no latency: the same trials at every latency.
    assert sw["final_error_mean"][0] == sw["final_error_mean"][1]


def test_the_open_loop_prediction_is_the_plans_and_the_trials_mean():
    """The predicted open-loop moments: on the plan's own scenario the expected cost and final
    covariance are the plan summary's (computed alike when planning), and the predicted mean is
    the mean of 400 trials executed open loop within 4 standard errors at every knot."""
    s = vic.Scenario.load(CONFIG / "single_joint_delay.toml", set={"task.duration": 1.0})
    p = vic.plan(s, method="sooc")
    pred = p.predict_open_loop(s)
    assert pred["expected_cost"] == p.open_loop_expected_cost
    assert np.array_equal(pred["final_covariance"], p.open_loop_final_covariance)
    sim = vic.simulate(s, p, policy="open-loop", trials=400, seed=5)
    mc_mean = sim.x.mean(axis=0)
    se = sim.x.std(axis=0, ddof=1) / np.sqrt(400)
    assert pred["mean"].shape == mc_mean.shape
    assert (np.abs(mc_mean - pred["mean"]) <= 4 * se + 1e-9).all()
    # and the sample covariance of the final state agrees with the predicted one to 20 %
    final = sim.x[:, -1, :2]
    assert np.allclose(np.cov(final.T), pred["final_covariance"][:2, :2], rtol=0.2)


def test_the_wheel_holds_the_live_client_as_vic_live():
    """vic.live is the client of python/vic_client, shipped in the same installed package (not
    taken from the checkout: no PYTHONPATH)."""
    pytest.importorskip("iceoryx2")
    import vic.live
    import vic_client

    assert vic.live.Board is vic_client.Board
    installed = Path(vic.__file__).parent.parent
    assert Path(vic_client.__file__).parent.parent == installed
    assert (installed / "vic_client" / "protocol.py").read_text() == (
        ROOT / "python/vic_client/protocol.py").read_text()
    assert vic.live.MAX_JOINTS == vic_client.MAX_JOINTS
