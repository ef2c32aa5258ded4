"""vic's files as numpy arrays: a plan (``vic plan --out plan.json``), an MCAP recording
(``vic-board --record run.mcap`` or ``vic record``) and a CSV recording (``--record run.csv``)."""

import json
import struct
from types import SimpleNamespace

import numpy as np


def load_plan(path):
    """A plan file: ``time`` (N+1), ``x`` (N+1 × n, columns ``state_names``), ``u`` (N × m,
    columns ``control_names``, e.g. tau1, tau2, k1, k2), ``gains`` (N × m × n), ``q_d``/``qd_d``
    of the reference, and ``summary``, ``config``, ``scenario`` as read. ``column(name)`` picks a
    state or control by name."""
    with open(path) as f:
        raw = json.load(f)
    if raw.get("version") != 1:
        raise ValueError(f"{path}: plan version {raw.get('version')!r}, this client reads 1")
    plan = SimpleNamespace(
        path=str(path),
        scenario=raw["scenario"],
        config=raw["config"],
        summary=raw["summary"],
        dt=raw["dt"],
        time=np.asarray(raw["time"], dtype=float),
        state_names=raw["state_names"],
        control_names=raw["control_names"],
        x=np.asarray(raw["x"], dtype=float),
        u=np.asarray(raw["u"], dtype=float),
        gains=np.asarray(raw["gains"], dtype=float),
    )
    ref = raw.get("reference") or []
    plan.q_d = np.asarray([r["q_d"] for r in ref], dtype=float) if ref else None
    plan.qd_d = np.asarray([r["qd_d"] for r in ref], dtype=float) if ref else None

    def column(name):
        if name in plan.state_names:
            return plan.x[:, plan.state_names.index(name)]
        if name in plan.control_names:
            return plan.u[:, plan.control_names.index(name)]
        raise KeyError(f"{path}: no state or control named {name!r}")

    plan.column = column
    return plan


def _columns(messages):
    """One numpy array per key of JSON messages that share their keys (numbers as float or
    int64, lists as 2-D arrays, others as object arrays)."""
    if not messages:
        return {}
    out = {}
    for key in messages[0]:
        values = [m.get(key) for m in messages]
        try:
            arr = np.asarray(values)
        except ValueError:  # ragged lists
            arr = np.asarray(values, dtype=object)
        out[key] = arr
    return out


def _read_records(path, topics):
    """The messages and metadata of an MCAP file read front to back, stopping where the file
    ends early: a recording whose writer was killed (SIGKILL, power loss) has no summary and
    ends in the middle of a record, which the seeking reader refuses. Returns
    ``(by_topic, times, metadata, complete)``."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    by_topic, times, metadata, channels = {}, {}, {}, {}
    complete = True
    with open(path, "rb") as f:
        records = StreamReader(f, validate_crcs=True).records
        while True:
            try:
                r = next(records)
            except StopIteration:
                break
            # Truncated: keep what came before. Where the cut falls decides the error: inside
            # a record's length prefix the reader's struct.unpack fails.
            except (McapError, ValueError, EOFError, struct.error):
                complete = False
                break
            if isinstance(r, Channel):
                channels[r.id] = r
            elif isinstance(r, Metadata):
                metadata[r.name] = dict(r.metadata)
            elif isinstance(r, Message):
                channel = channels[r.channel_id]
                if topics is not None and channel.topic not in topics:
                    continue
                if channel.message_encoding != "json":
                    raise ValueError(f"{path}: {channel.topic} is {channel.message_encoding}, not json")
                by_topic.setdefault(channel.topic, []).append(json.loads(r.data))
                times.setdefault(channel.topic, []).append(r.log_time)
    return by_topic, times, metadata, complete


def load_mcap(path, topics=None):
    """An MCAP recording as ``{topic: {key: array}}`` plus ``"_log_time_ns"`` per topic (the
    message log times) and the metadata records under ``"_metadata"``. A recording cut short
    (its writer killed) is read up to the last whole chunk, and ``"_complete"`` is False then.
    Needs the ``mcap`` package (``pip install mcap``)."""
    by_topic, times, metadata, complete = _read_records(path, topics)
    out = {}
    for topic, msgs in by_topic.items():
        cols = _columns(msgs)
        cols["_log_time_ns"] = np.asarray(times[topic], dtype=np.uint64)
        out[topic] = cols
    out["_metadata"] = metadata
    out["_complete"] = complete
    return out


def load_csv_record(path):
    """A CSV recording of ``vic-board --record run.csv`` as ``{column: array}``; the ``x_``
    columns keep their names. Comment lines (the banner, gaps, non-finite rows) are skipped."""
    header, rows = None, []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            fields = line.rstrip("\n").split(",")
            if header is None:
                header = fields
            else:
                rows.append([float(v) for v in fields])
    if header is None:
        raise ValueError(f"{path}: no header line")
    data = np.asarray(rows, dtype=float).reshape(-1, len(header))
    return {name: data[:, i] for i, name in enumerate(header)}
