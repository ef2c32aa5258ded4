"""The wire protocol of vic (docs/PROTOCOL.md) as ctypes structures, enumerations and constants.

Every payload is a ``#[repr(C)]`` struct on the Rust side; the ctypes structures here have the
same fields in the same order, so ctypes gives them the same natural alignment, offsets and sizes
(tests/test_client.py compares them with the document's tables). ``type_name()`` is the name
iceoryx2 compares when a service is opened: a different name is an incompatible service.
"""

import ctypes
import enum

import numpy as np

PROTOCOL_VERSION = 4
MAX_JOINTS = 2
MAX_KNOTS = 32
MIN_KNOT_DT_NS = 100_000
MAX_KNOT_DT_NS = 100_000_000
MAX_SLICE_NS = 1_000_000_000
MAX_REACH_NS = 2_000_000_000
MAX_MESSAGE_AGE_NS = 100_000_000
REJECTION_COUNT = 17
MAX_PUBLISHERS = 4
MAX_SUBSCRIBERS = 48
MAX_NODES = 64
MAX_NOTIFIERS = 4
MAX_LISTENERS = 56
STATE_BUFFER = 128
# The board counts sequence gaps per sender session in a table of this many sessions, and no gap
# larger than this (a jump, not a loss).
GAP_SESSIONS = 8
MAX_COUNTED_GAP = 1 << 24

U32, U64, F64 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double
Joints = F64 * MAX_JOINTS


class Mode(enum.IntEnum):
    IDLE = 0
    RUNNING = 1
    SAFE_HOLD = 2
    FAULT = 3


class Interpolation(enum.IntEnum):
    HOLD = 0
    LINEAR = 1


class DisturbanceKind(enum.IntEnum):
    PULSE = 0
    LOAD = 1
    FIELD = 2
    NOISE = 3


class ControlKind(enum.IntEnum):
    RESET = 0
    STOP = 1


class Rejection(enum.IntEnum):
    VERSION = 0
    JOINTS = 1
    SHAPE = 2
    NOT_FINITE = 3
    STIFFNESS_OUT_OF_BOUNDS = 4
    TORQUE_OUT_OF_BOUNDS = 5
    DAMPING_UNSTABLE = 6
    WRONG_TRIAL = 7
    OUT_OF_ORDER = 8
    FUTURE_TIMESTAMP = 9
    DISTURBANCE_OUT_OF_BOUNDS = 10
    UNKNOWN_KIND = 11
    OVERFLOW = 12
    FAULTED = 13
    EQUILIBRIUM_OUT_OF_BOUNDS = 14
    STALE = 15
    TOO_FAR_AHEAD = 16


class FaultReason(enum.IntEnum):
    NONE = 0
    JOINT_LIMIT = 1
    VELOCITY_LIMIT = 2
    NOT_FINITE = 3


class BoardEvent(enum.IntEnum):
    TELEMETRY = 1
    APPLIED = 2


def name_of(member):
    """The wire name of an enumeration member, as docs/PROTOCOL.md and the Rust side spell it
    (``Rejection.DISTURBANCE_OUT_OF_BOUNDS`` → ``"disturbance-out-of-bounds"``)."""
    return member.name.lower().replace("_", "-")


def rejections_by_name(counts):
    """Rejection counts (``Telemetry.rejected_by_reason``, indexed by :class:`Rejection`) as a
    dict reason name → count, leaving out reasons that never occurred (as ``vic status``)."""
    return {name_of(r): int(counts[r]) for r in Rejection if counts[r]}


ENUMS = {
    "Mode": Mode,
    "Interpolation": Interpolation,
    "DisturbanceKind": DisturbanceKind,
    "ControlKind": ControlKind,
    "Rejection": Rejection,
    "FaultReason": FaultReason,
    "BoardEvent": BoardEvent,
}


class _Payload(ctypes.Structure):
    """A payload: its iceoryx2 type name, and a dict view for printing and JSON."""

    TYPE_NAME = ""

    @classmethod
    def type_name(cls):
        return cls.TYPE_NAME

    def to_dict(self):
        out = {}
        for name, _ in self._fields_:
            v = getattr(self, name)
            if isinstance(v, ctypes.Structure):
                v = v.to_dict()
            elif isinstance(v, ctypes.Array):
                v = [x.to_dict() if isinstance(x, ctypes.Structure) else x for x in v]
            out[name] = v
        return out


class Header(_Payload):
    TYPE_NAME = "vic::Header/4"
    _fields_ = [("version", U32), ("session", U32), ("seq", U64), ("time_ns", U64)]


class StateMsg(_Payload):
    TYPE_NAME = "vic::State/4"
    _fields_ = [
        ("header", Header),
        ("joints", U32),
        ("trial", U32),
        ("tick", U64),
        ("mode", U32),
        ("_pad", U32),
        ("trial_time_ns", U64),
        ("q", Joints),
        ("qd", Joints),
        ("tau", Joints),
        ("tau_ext", Joints),
        ("stiffness", Joints),
        ("command_seq", U64),
        ("disturbance_seq", U64),
        ("disturbance_tick", U64),
        ("watchdog_deadline_ns", U64),
        ("reset_seq", U64),
    ]


class Knot(_Payload):
    TYPE_NAME = "vic::Knot/1"
    _fields_ = [("tau_ff", Joints), ("stiffness", Joints), ("q_d", Joints), ("qd_d", Joints)]


class CommandSlice(_Payload):
    TYPE_NAME = "vic::CommandSlice/4"
    _fields_ = [
        ("header", Header),
        ("joints", U32),
        ("trial", U32),
        ("interpolation", U32),
        ("count", U32),
        ("start_ns", U64),
        ("knot_dt_ns", U64),
        ("knots", Knot * MAX_KNOTS),
    ]


class Disturbance(_Payload):
    TYPE_NAME = "vic::Disturbance/4"
    _fields_ = [
        ("header", Header),
        ("kind", U32),
        ("_pad", U32),
        ("torque", Joints),
        ("duration_ns", U64),
        ("value", F64),
    ]


class Control(_Payload):
    TYPE_NAME = "vic::Control/4"
    _fields_ = [
        ("header", Header),
        ("kind", U32),
        ("trial", U32),
        ("seed", U64),
        ("start_ns", U64),
        ("q0", Joints),
        ("qd0", Joints),
    ]


class Percentiles(_Payload):
    TYPE_NAME = "vic::Percentiles/1"
    _fields_ = [("p50", F64), ("p99", F64), ("p999", F64), ("max", F64), ("count", U64)]


class Telemetry(_Payload):
    TYPE_NAME = "vic::Telemetry/4"
    _fields_ = [
        ("header", Header),
        ("mode", U32),
        ("trial", U32),
        ("tick", U64),
        ("tick_rate_hz", F64),
        ("jitter_us", Percentiles),
        ("work_us", Percentiles),
        ("command_age_us", Percentiles),
        ("late_ticks", U64),
        ("missed_periods", U64),
        ("rejected_messages", U64),
        ("safe_hold_ticks", U64),
        ("tracking_error", F64),
        ("stiffness", Joints),
        ("tau_ext", Joints),
        ("field_beta", F64),
        ("noise_factor", F64),
        ("joints", U32),
        ("fault_reason", U32),
        ("rejected_by_reason", U64 * REJECTION_COUNT),
        ("watchdog_trips", U64),
        ("disturbance_seq", U64),
        ("disturbance_tick", U64),
        ("dropped_messages", U64),
    ]

    def rejections(self):
        """The rejection counts by reason name (``{"disturbance-out-of-bounds": 1}``), leaving
        out reasons that never occurred; ``rejected_by_reason`` holds the raw array."""
        return rejections_by_name(self.rejected_by_reason)


PAYLOADS = {
    "Header": Header,
    "StateMsg": StateMsg,
    "Knot": Knot,
    "CommandSlice": CommandSlice,
    "Disturbance": Disturbance,
    "Control": Control,
    "Percentiles": Percentiles,
    "Telemetry": Telemetry,
}

# numpy's structured dtype of a state: the same offsets as the ctypes structure (numpy derives it
# from the structure), so a received sample's bytes are one record without any conversion.
STATE_DTYPE = np.dtype(StateMsg)
TELEMETRY_DTYPE = np.dtype(Telemetry)
