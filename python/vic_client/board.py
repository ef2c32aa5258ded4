"""A live board over iceoryx2's official Python bindings: the state stream, the telemetry, and the
requests a tool or a central process sends (pulse, load, field, noise, reset, stop).

The configuration is the one docs/PROTOCOL.md gives: the namespace's prefix ``vic_{ns}.``, the
user's private root directory ``/tmp/vic-{uid}/`` (0700), every other iceoryx2 setting at its
default, and the services opened with the document's limits. The bindings offer iceoryx2's plain
``ipc`` service type only, which talks to vic's services unchanged but keeps its global management
segment (a node counter) in ``/dev/shm`` instead of the private directory; see
:func:`_restrict_own_files` for what this client does about it.
"""

import ctypes
import os
import secrets
import stat
import time

import iceoryx2 as iox2
import numpy as np

from .protocol import (
    MAX_JOINTS,
    MAX_NODES,
    MAX_PUBLISHERS,
    MAX_SUBSCRIBERS,
    PROTOCOL_VERSION,
    STATE_BUFFER,
    STATE_DTYPE,
    CommandSlice,
    Control,
    ControlKind,
    Disturbance,
    DisturbanceKind,
    Header,
    Mode,
    StateMsg,
    Telemetry,
)

NODE_NAME = "vic-python"
_NAMESPACE_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-")

# (service name, payload, history, subscriber buffer) as in PROTOCOL.md; a Board opens every one
# but `command` (the central process's).
SERVICES = {
    "state": ("vic/state", StateMsg, 1, STATE_BUFFER),
    "telemetry": ("vic/telemetry", Telemetry, 1, 1),
    "command": ("vic/command", CommandSlice, 0, 8),
    "control": ("vic/control", Control, 0, 8),
    "disturbance": ("vic/disturbance", Disturbance, 0, 8),
}


class VicError(Exception):
    """A namespace, a board or a request the client cannot use; the message says why."""


def validate_namespace(ns):
    if not (1 <= len(ns) <= 32) or not set(ns) <= _NAMESPACE_CHARS:
        raise VicError(f"namespace {ns!r}: 1 to 32 characters of [A-Za-z0-9_-]")
    return ns


def prefix(ns):
    """iceoryx2's file prefix of a namespace (the `.` is in no namespace, so no prefix of one
    namespace starts another's files)."""
    return f"vic_{validate_namespace(ns)}."


def root_dir():
    return f"/tmp/vic-{os.geteuid()}/"


def ensure_root_dir():
    """Creates the private root directory (0700) if missing; refuses one that is not a directory
    of ours that nobody else may enter (as vic does)."""
    path = root_dir()
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    st = os.lstat(path)
    if not stat.S_ISDIR(st.st_mode):
        raise VicError(f"{path}: not a directory")
    if st.st_uid != os.geteuid():
        raise VicError(f"{path}: belongs to uid {st.st_uid}, not to you (uid {os.geteuid()})")
    if st.st_mode & 0o077:
        raise VicError(f"{path}: mode {st.st_mode & 0o777:o}, other users may enter it (must be 700)")
    return path


def namespace_files(ns):
    """Every file of the namespace in /dev/shm and (recursively) in the root directory."""
    pre = prefix(ns)
    found = [os.path.join("/dev/shm", f) for f in _listdir("/dev/shm") if f.startswith(pre)]
    for dirpath, _, files in os.walk(root_dir()):
        found += [os.path.join(dirpath, f) for f in files if f.startswith(pre)]
    return found


def _listdir(path):
    try:
        return os.listdir(path)
    except OSError:
        return []


def check_namespace_owner(ns):
    """Refuses a namespace with a file another user owns: that user could read or write it."""
    for path in namespace_files(ns):
        try:
            owner = os.lstat(path).st_uid
        except FileNotFoundError:
            continue
        if owner != os.geteuid():
            raise VicError(f"namespace {ns!r}: {path} belongs to uid {owner}, not to you")


def _restrict_own_files(ns):
    """Makes the namespace's files in /dev/shm owner-only.

    iceoryx2's ``ipc`` service creates its global management segment (``…global_mgmt``, a node
    counter) in /dev/shm and makes it 0666; vic's own service type keeps it in the private
    directory instead. The bindings cannot choose that type, so this client narrows the file to
    0600 right after its node is created. In the moment between, another local user could open
    it and later change the counter: node ids also carry the process id and the creation time,
    so a changed counter cannot make two nodes' ids collide.
    """
    for f in _listdir("/dev/shm"):
        if f.startswith(prefix(ns)):
            path = os.path.join("/dev/shm", f)
            try:
                st = os.lstat(path)
                if st.st_uid == os.geteuid() and st.st_mode & 0o077:
                    os.chmod(path, 0o600)
            except OSError:
                pass


def config(ns):
    """The iceoryx2 configuration of a namespace: defaults, the namespace's prefix, the private
    root directory."""
    cfg = iox2.config.default()
    cfg.global_cfg.prefix = iox2.FileName.new(prefix(ns))
    cfg.global_cfg.root_path = iox2.Path.new(root_dir())
    return cfg


def _bytes_of(sample, size):
    return ctypes.string_at(sample.payload_ptr, size)


class StateRing:
    """The last ``capacity`` states as one numpy structured array (``STATE_DTYPE``), oldest first.

    ``count`` is every state ever pushed; a reader keeps its own position in that count, so
    several readers (an iterator, an acknowledgement wait) never take states from one another.
    """

    def __init__(self, capacity=10_000):
        self.capacity = capacity
        self._buf = np.zeros(capacity, dtype=STATE_DTYPE)
        self.count = 0

    def push(self, record_bytes):
        self._buf[self.count % self.capacity] = np.frombuffer(record_bytes, dtype=STATE_DTYPE)[0]
        self.count += 1

    def since(self, position):
        """States pushed at or after ``position`` still held (a copy), and the new position."""
        first = max(position, self.count - self.capacity)
        idx = np.arange(first, self.count) % self.capacity
        return self._buf[idx].copy(), self.count

    def array(self):
        """Every state held, oldest first (a copy)."""
        return self.since(0)[0]


class Board:
    """A client of the board in ``namespace``: ``Board("lab")`` waits up to ``timeout`` seconds
    for the board's services, then subscribes to its states and telemetry and can send
    disturbances and trial controls (as ``vic inject`` and a central process do).

    Use it as a context manager (or call :meth:`close`) so its ports are released at once.
    """

    def __init__(self, namespace="vic", timeout=5.0, ring=10_000):
        self.namespace = validate_namespace(namespace)
        iox2.set_log_level(iox2.LogLevel.Error)
        ensure_root_dir()
        check_namespace_owner(namespace)
        self._node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(NODE_NAME))
            .config(config(namespace))
            .create(iox2.ServiceType.Ipc)
        )
        _restrict_own_files(namespace)
        services = self._open_services(timeout)
        self._state_sub = services["state"].subscriber_builder().buffer_size(STATE_BUFFER).create()
        self._telemetry_sub = services["telemetry"].subscriber_builder().buffer_size(1).create()
        # Publishers are opened at the first send: a client that only watches takes no slot a
        # sender (the central process, `vic inject`) needs.
        self._services = services
        self._control_pub = None
        self._disturbance_pub = None
        self.session = secrets.randbelow(2**32 - 1) + 1
        self._seq = 0
        self.ring = StateRing(ring)
        self.latest = None
        self.lost = 0
        self._telemetry = None

    def _open_services(self, timeout):
        deadline = time.monotonic() + timeout
        while True:
            try:
                return {k: self._open(*s) for k, s in SERVICES.items() if k != "command"}
            except Exception as e:  # the bindings' open errors share no base class
                if time.monotonic() >= deadline:
                    raise VicError(
                        f"no board in namespace {self.namespace!r} after {timeout} s "
                        f"(start one with: vic-board --namespace {self.namespace}): {e!r}"
                    ) from e
                time.sleep(0.05)

    def _open(self, name, payload, history, _buffer):
        # The settings every vic port opens its services with; iceoryx2 refuses a mismatch.
        return (
            self._node.service_builder(iox2.ServiceName.new(name))
            .publish_subscribe(payload)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(STATE_BUFFER)
            .history_size(history)
            .enable_safe_overflow(True)
            .open()
        )

    # -- receiving ---------------------------------------------------------------------------

    def poll(self):
        """Moves every state waiting in the subscriber's buffer into the ring; returns how many.

        The buffer holds 128 states (128 ms at 1 kHz): poll at least that often to miss none.
        Missed ticks are counted in ``lost``.
        """
        n = 0
        size = ctypes.sizeof(StateMsg)
        while True:
            sample = self._state_sub.receive()
            if sample is None:
                return n
            raw = _bytes_of(sample, size)
            sample.delete()
            record = np.frombuffer(raw, dtype=STATE_DTYPE)[0]
            if self.latest is not None and record["tick"] > self.latest["tick"] + 1:
                self.lost += int(record["tick"] - self.latest["tick"] - 1)
            self.ring.push(raw)
            self.latest = record.copy()
            n += 1

    def states(self, timeout=None, batch=False):
        """Iterates over the states from now on, oldest first, each a numpy record of
        ``STATE_DTYPE`` (``s["tick"]``, ``s["q"]`` …); with ``batch=True``, arrays of the states
        that arrived since the last step. Ends after ``timeout`` seconds (None: never)."""
        end = None if timeout is None else time.monotonic() + timeout
        position = self.ring.count
        while end is None or time.monotonic() < end:
            self.poll()
            new, position = self.ring.since(position)
            if batch and len(new):
                yield new
            elif not batch:
                yield from new
            time.sleep(0.001)

    def collect(self, seconds):
        """The states of the next ``seconds`` as one structured array."""
        parts = list(self.states(timeout=seconds, batch=True))
        return np.concatenate(parts) if parts else np.zeros(0, dtype=STATE_DTYPE)

    def since_tick(self, tick):
        """The states held in the ring from ``tick`` on (those an acknowledgement wait already
        took included), oldest first."""
        self.poll()
        held = self.ring.array()
        return held[held["tick"] >= tick]

    def wait_state(self, predicate, timeout=2.0):
        """Polls until a new state satisfies ``predicate(record)``; returns it, or raises."""
        for s in self.states(timeout=timeout):
            if predicate(s):
                return s
        raise VicError(f"namespace {self.namespace!r}: no matching state within {timeout} s")

    def telemetry(self):
        """The newest telemetry (a :class:`Telemetry` ctypes copy; ``.to_dict()`` for a dict),
        or None when the board has published none yet."""
        size = ctypes.sizeof(Telemetry)
        while True:
            sample = self._telemetry_sub.receive()
            if sample is None:
                return self._telemetry
            self._telemetry = Telemetry.from_buffer_copy(_bytes_of(sample, size))
            sample.delete()

    # -- sending -----------------------------------------------------------------------------

    def _header(self):
        self._seq += 1
        return Header(PROTOCOL_VERSION, self.session, self._seq, time.monotonic_ns())

    @staticmethod
    def _joints(values):
        values = [float(v) for v in np.atleast_1d(values)]
        if len(values) > MAX_JOINTS:
            raise VicError(f"{len(values)} joint values: a message carries at most {MAX_JOINTS}")
        return (ctypes.c_double * MAX_JOINTS)(*values, *[0.0] * (MAX_JOINTS - len(values)))

    def _publisher(self, service):
        """The publisher of ``service`` ("control" or "disturbance"), opened at its first use."""
        attr = f"_{service}_pub"
        pub = getattr(self, attr)
        if pub is None:
            pub = self._services[service].publisher_builder().create()
            setattr(self, attr, pub)
        return pub

    def _disturb(self, kind, torque=(), duration_ns=0, value=0.0, wait=2.0):
        msg = Disturbance(
            header=self._header(),
            kind=kind,
            torque=self._joints(torque),
            duration_ns=duration_ns,
            value=value,
        )
        self.poll()
        self._publisher("disturbance").send_copy(msg)
        return self._ack(msg.header.seq, "disturbance_seq", wait)

    def _ack(self, seq, field, wait):
        """The state that acknowledges request ``seq`` (its ``field`` equals it), or just the seq
        when ``wait`` is None."""
        if wait is None:
            return seq
        try:
            return self.wait_state(lambda s: s[field] == seq, wait)
        except VicError:
            raise VicError(
                f"namespace {self.namespace!r}: request {seq} not acknowledged within {wait} s "
                "(rejected? see telemetry().rejected_by_reason)"
            ) from None

    def inject_pulse(self, torque, duration_s=0.05, wait=2.0):
        """A torque pulse [N m per joint] for ``duration_s``. Returns the state that acknowledges
        it (``s["disturbance_tick"]`` is the tick it was applied at), or raises after ``wait``
        seconds; ``wait=None`` returns the request's seq at once."""
        return self._disturb(DisturbanceKind.PULSE, torque, int(round(duration_s * 1e9)), wait=wait)

    def inject_load(self, torque, wait=2.0):
        """A steady load torque until changed (zeros remove it)."""
        return self._disturb(DisturbanceKind.LOAD, torque, wait=wait)

    def set_field(self, beta, wait=2.0):
        """The divergent field's β [N/m] (0: off; two-link arm only)."""
        return self._disturb(DisturbanceKind.FIELD, value=beta, wait=wait)

    def set_noise(self, factor, wait=2.0):
        """Multiplies the plant noise by ``factor``."""
        return self._disturb(DisturbanceKind.NOISE, value=factor, wait=wait)

    def reset(self, q0, qd0=(0.0, 0.0), trial=1, seed=0, start_in_s=0.05, wait=2.0):
        """Puts the plant at ``q0``, ``qd0`` and starts trial ``trial`` ``start_in_s`` from now
        (the noise reseeded from ``(seed, trial)``). With no central process sending commands,
        the board's watchdog then ramps into the safe hold: the arm holds ``q0`` with the hold
        stiffness, and a pulse moves it and it springs back. Returns the acknowledging state."""
        header = self._header()
        msg = Control(
            header=header,
            kind=ControlKind.RESET,
            trial=trial,
            seed=seed,
            start_ns=header.time_ns + int(start_in_s * 1e9),
            q0=self._joints(q0),
            qd0=self._joints(qd0),
        )
        self.poll()
        self._publisher("control").send_copy(msg)
        return self._ack(header.seq, "reset_seq", wait)

    def stop(self):
        """Ends the trial: the board goes idle, holding the arm at its posture, until the next reset."""
        self._publisher("control").send_copy(Control(header=self._header(), kind=ControlKind.STOP))

    # -- lifetime ----------------------------------------------------------------------------

    def close(self):
        for port in ("_state_sub", "_telemetry_sub", "_control_pub", "_disturbance_pub"):
            p = self.__dict__.pop(port, None)
            if p is not None:
                p.delete()
        self._services = None
        self._node = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @staticmethod
    def mode_name(value):
        return Mode(int(value)).name.lower().replace("_", "-")
