"""A live board over iceoryx2's official Python bindings: the state stream, the telemetry, and the
requests a tool or a central process sends (pulse, load, field, noise, reset, stop).

The configuration is the one docs/PROTOCOL.md gives: the namespace's prefix ``vic_{ns}.``, the
user's private root directory (:func:`root_dir`, 0700), every other iceoryx2 setting at its
default, and the services opened with the document's limits. The bindings offer iceoryx2's plain
``ipc`` service type only, which talks to vic's services unchanged but keeps its global management
segment (a node counter) in ``/dev/shm`` instead of the private directory, and creates a missing
one world-writable (0666). So this client never creates it: every vic process of a namespace makes
it owner-only, and the client opens only such a file (:func:`check_global_file`).
"""

import ctypes
import hashlib
import os
import secrets
import stat
import time
import warnings

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
    Rejection,
    StateMsg,
    Telemetry,
    name_of,
    rejections_by_name,
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


class Rejected(VicError):
    """The board rejected a request: ``reasons`` are the names of the rejection counters that
    rose after it was sent (docs/PROTOCOL.md, "Rejections"), e.g. ``["disturbance-out-of-bounds"]``,
    and ``seq`` is the request's sequence number."""

    def __init__(self, message, reasons, seq):
        super().__init__(message)
        self.reasons = reasons
        self.seq = seq


class StatesLost(VicError):
    """States the board published were not received (the client polled too rarely: the
    subscriber's buffer holds 128 ms). ``count`` is how many; raised with ``on_loss="raise"``."""

    def __init__(self, message, count):
        super().__init__(message)
        self.count = count


class LostStatesWarning(UserWarning):
    """States were lost (see :class:`StatesLost`); issued with ``on_loss="warn"``, the default."""


ON_LOSS = ("warn", "raise", "ignore")


def validate_namespace(ns):
    if not (1 <= len(ns) <= 32) or not set(ns) <= _NAMESPACE_CHARS:
        raise VicError(f"namespace {ns!r}: 1 to 32 characters of [A-Za-z0-9_-]")
    return ns


def prefix(ns):
    """iceoryx2's file prefix of a namespace (the `.` is in no namespace, so no prefix of one
    namespace starts another's files)."""
    return f"vic_{validate_namespace(ns)}."


RUNTIME_DIR_VAR = "VIC_RUNTIME_DIR"
MAX_ROOT_PATH = 26  # bytes, the final / included: iceoryx2's event sockets live in it (as vic)


def _session_runtime_dir():
    """``$XDG_RUNTIME_DIR`` when it is an absolute path to a directory of ours that nobody else
    may enter and short enough for its ``vic/`` (``MAX_ROOT_PATH``), else None."""
    path = os.environ.get("XDG_RUNTIME_DIR")
    if not path or not os.path.isabs(path):
        return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    fits = len(os.path.join(path, "vic/").encode()) <= MAX_ROOT_PATH
    ok = fits and stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and not st.st_mode & 0o077
    return path if ok else None


def _root_place():
    given = os.environ.get(RUNTIME_DIR_VAR)
    if given:
        return given.rstrip("/") + "/", "given"
    session = _session_runtime_dir()
    if session is not None:
        return os.path.join(session, "vic") + "/", "session"
    return f"/tmp/vic-{os.geteuid()}/", "tmp"


def root_dir():
    """The private root directory, chosen as vic chooses it: ``$VIC_RUNTIME_DIR/`` if set, else
    ``$XDG_RUNTIME_DIR/vic/`` if that is our private directory, else ``/tmp/vic-{uid}/``."""
    return _root_place()[0]


def ensure_root_dir():
    """Creates the private root directory (0700) if missing; refuses one that is not a directory
    of ours that nobody else may enter (as vic does), saying what to do."""
    path, place = _root_place()
    elsewhere = (
        f"set {RUNTIME_DIR_VAR} to a directory of yours that only you may enter (mkdir -m 700 "
        f"DIR, an absolute path of at most {MAX_ROOT_PATH} bytes), the same for every vic process "
        "and Python client of the namespace"
    )
    if not os.path.isabs(path) or len(path.encode()) > MAX_ROOT_PATH:
        raise VicError(
            f"iceoryx2 directory {path}: {RUNTIME_DIR_VAR} must be an absolute path of at most "
            f"{MAX_ROOT_PATH} bytes; {elsewhere}"
        )
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError as e:
        raise VicError(f"iceoryx2 directory {path}: cannot create it: {e}; {elsewhere}") from e
    st = os.lstat(path)
    uid = os.geteuid()
    if place == "tmp" and st.st_uid != uid:
        in_the_way = (
            "another user made it first and only they or an administrator can remove it (/tmp "
            f"is sticky); meanwhile {elsewhere}"
        )
    else:
        in_the_way = f"remove it, or {elsewhere}"
    if not stat.S_ISDIR(st.st_mode):
        raise VicError(f"iceoryx2 directory {path}: it is not a directory; {in_the_way}")
    if st.st_uid != uid:
        raise VicError(
            f"iceoryx2 directory {path}: it belongs to uid {st.st_uid}, not to you (uid {uid}); "
            f"{in_the_way}"
        )
    if st.st_mode & 0o077:
        raise VicError(
            f"iceoryx2 directory {path}: its mode is {st.st_mode & 0o777:o}: other users may "
            f"enter it (it must be 700); make it private (chmod 700 {path}) if nothing of "
            "another user is in it, or remove it"
        )
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
            raise VicError(
                f"namespace {ns!r}: {path} belongs to uid {owner}, not to you; another user "
                "holds this namespace (or made the file first, and only they or an "
                "administrator can remove it from the sticky /dev/shm): use another namespace"
            )


# The type name iceoryx2 gives the global file's content; the file's name carries its SHA-1.
_COUNTER_TYPE = "iceoryx2::node::global_management_segment::State"


def global_file(ns):
    """The global management file of iceoryx2's plain ``ipc`` service for namespace ``ns`` in
    /dev/shm, as iceoryx2 names it:
    ``{prefix}{sha1 of the type name}_node.{major}_{minor}_{patch}.global_mgmt``."""
    major, minor, patch = _iceoryx2_version()
    digest = hashlib.sha1(_COUNTER_TYPE.encode()).hexdigest()
    return f"/dev/shm/{prefix(ns)}{digest}_node.{major}_{minor}_{patch}.global_mgmt"


def _iceoryx2_version():
    from importlib.metadata import version

    return tuple(int(p) for p in version("iceoryx2").split(".")[:3])


def check_global_file(ns):
    """The ``os.stat_result`` of the namespace's global file if a vic process made it (a regular
    file of ours that nobody else may open), None while it is missing; raises :class:`VicError`
    naming the file, its owner or mode, and what to do, for any other file.

    The plain ``ipc`` service creates a missing file world-writable (0666): another local user
    could open it in that moment and keep a writable handle. A file of ours in /dev/shm (sticky)
    cannot be removed or replaced by another user, so one that passes this check stays the file
    the node opens.
    """
    path = global_file(ns)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    if not stat.S_ISREG(st.st_mode):
        raise VicError(f"namespace {ns!r}: {path} is not a regular file; use another namespace")
    if st.st_uid != os.geteuid():
        raise VicError(
            f"namespace {ns!r}: {path} belongs to uid {st.st_uid}, not to you (uid "
            f"{os.geteuid()}); another user made it and only they or an administrator can "
            "remove it: use another namespace"
        )
    if st.st_mode & 0o077:
        raise VicError(
            f"namespace {ns!r}: {path} has mode {st.st_mode & 0o777:o}: other users may have "
            "opened it for writing (a client of the plain ipc service created it); stop the "
            "namespace's processes, remove the file and start the board again"
        )
    return st


def _wait_for_global_file(ns, timeout):
    """Waits up to ``timeout`` seconds for the board (any vic process) to have made the
    namespace's global file; returns its stat, or raises :class:`VicError`."""
    deadline = time.monotonic() + timeout
    while True:
        st = check_global_file(ns)
        if st is not None:
            return st
        if time.monotonic() >= deadline:
            raise VicError(
                f"no board in namespace {ns!r} after {timeout} s (start one with: vic-board "
                f"--namespace {ns}); {global_file(ns)} is missing, and this client never "
                "creates a namespace's files (iceoryx2's Python bindings would make that one "
                "world-writable)"
            )
        time.sleep(0.05)


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

    States the client did not receive in time (it must poll at least every 128 ms) are counted
    in ``lost`` and, by ``on_loss``, reported: ``"warn"`` (a :class:`LostStatesWarning`, the
    default), ``"raise"`` (:class:`StatesLost` from the call that found them) or ``"ignore"``.

    Use it as a context manager (or call :meth:`close`) so its ports are released at once.
    """

    def __init__(self, namespace="vic", timeout=5.0, ring=10_000, on_loss="warn"):
        self.namespace = validate_namespace(namespace)
        if on_loss not in ON_LOSS:
            raise VicError(f"on_loss={on_loss!r}: one of {', '.join(ON_LOSS)}")
        self.on_loss = on_loss
        iox2.set_log_level(iox2.LogLevel.Error)
        deadline = time.monotonic() + timeout
        ensure_root_dir()
        before = _wait_for_global_file(namespace, timeout)
        check_namespace_owner(namespace)
        self._node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(NODE_NAME))
            .config(config(namespace))
            .create(iox2.ServiceType.Ipc)
        )
        # The node opened the file checked above, unless the namespace's last vic process
        # removed it in between and the node made a new one (world-writable): then narrow it
        # and refuse, as no board is left anyway.
        path = global_file(namespace)
        after = os.lstat(path)
        if (after.st_ino, after.st_dev) != (before.st_ino, before.st_dev) or after.st_mode & 0o077:
            if after.st_uid == os.geteuid():
                os.chmod(path, 0o600)
            self._node = None
            raise VicError(
                f"namespace {namespace!r}: the board's processes exited while this client "
                "connected; start the board again"
            )
        services = self._open_services(max(0.0, deadline - time.monotonic()))
        self._state_sub = services["state"].subscriber_builder().buffer_size(STATE_BUFFER).create()
        self._telemetry_sub = services["telemetry"].subscriber_builder().buffer_size(1).create()
        # Publishers are opened at the first send: a client that only watches takes no slot a
        # sender (the central process, `vic inject`) needs.
        self._services = services
        self._control_pub = None
        self._disturbance_pub = None
        self.session = secrets.randbelow(2**32 - 1) + 1
        # The last seq sent of each kind: the board numbers (and counts gaps in) each kind of
        # message apart, so each kind has its own counter.
        self.seq = {"control": 0, "disturbance": 0}
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
        Missed ticks are counted in ``lost`` and reported as ``on_loss`` says.
        """
        n = gap = 0
        size = ctypes.sizeof(StateMsg)
        while True:
            sample = self._state_sub.receive()
            if sample is None:
                break
            raw = _bytes_of(sample, size)
            sample.delete()
            record = np.frombuffer(raw, dtype=STATE_DTYPE)[0]
            if self.latest is not None and record["tick"] > self.latest["tick"] + 1:
                gap += int(record["tick"] - self.latest["tick"] - 1)
            self.ring.push(raw)
            self.latest = record.copy()
            n += 1
        if gap:
            self.lost += gap
            if self.on_loss != "ignore":
                msg = (
                    f"namespace {self.namespace!r}: {gap} states lost before tick "
                    f"{int(self.latest['tick'])} ({self.lost} in all): poll at least every "
                    "128 ms, or pass on_loss='ignore'"
                )
                if self.on_loss == "raise":
                    raise StatesLost(msg, gap)
                warnings.warn(msg, LostStatesWarning, stacklevel=2)
        return n

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

    def _drain_telemetry(self):
        size = ctypes.sizeof(Telemetry)
        while True:
            sample = self._telemetry_sub.receive()
            if sample is None:
                return self._telemetry
            self._telemetry = Telemetry.from_buffer_copy(_bytes_of(sample, size))
            sample.delete()

    def telemetry(self, timeout=2.0):
        """The newest telemetry (a :class:`Telemetry` ctypes copy; ``.to_dict()`` for a dict,
        ``.rejections()`` for the rejection counts by name). Right after connecting it waits up
        to ``timeout`` seconds for the board's first one (the board publishes one every 100
        ticks), polling the states meanwhile, and raises :class:`VicError` if none came."""
        deadline = time.monotonic() + timeout
        while self._drain_telemetry() is None:
            if time.monotonic() >= deadline:
                raise VicError(
                    f"namespace {self.namespace!r}: no telemetry from the board within {timeout} s"
                )
            self.poll()
            time.sleep(0.002)
        return self._telemetry

    def rejections(self):
        """The board's rejection counts by reason name (``{"disturbance-out-of-bounds": 1}``),
        from the newest telemetry; reasons that never occurred are left out."""
        return rejections_by_name(self.telemetry().rejected_by_reason)

    @property
    def joints(self):
        """The number of joints of the board's plant."""
        self.poll()
        if self.latest is not None:
            return int(self.latest["joints"])
        return int(self.telemetry().joints)

    # -- sending -----------------------------------------------------------------------------

    def _header(self, kind):
        self.seq[kind] += 1
        return Header(PROTOCOL_VERSION, self.session, self.seq[kind], time.monotonic_ns())

    def _joints(self, values, what):
        """``values`` as a message's joint array, refused unless there is one per joint of the
        board."""
        values = [float(v) for v in np.atleast_1d(values)]
        joints = self.joints
        if len(values) != joints:
            raise VicError(
                f"namespace {self.namespace!r}: {what} has {len(values)} values, the board has "
                f"{joints} joint{'s' if joints != 1 else ''}"
            )
        return (ctypes.c_double * MAX_JOINTS)(*values, *[0.0] * (MAX_JOINTS - len(values)))

    def _publisher(self, service):
        """The publisher of ``service`` ("control" or "disturbance"), opened at its first use."""
        attr = f"_{service}_pub"
        pub = getattr(self, attr)
        if pub is None:
            pub = self._services[service].publisher_builder().create()
            setattr(self, attr, pub)
        return pub

    def _disturb(self, kind, torque=None, duration_ns=0, value=0.0, wait=2.0):
        torque = self._joints(np.zeros(self.joints) if torque is None else torque, "the torque")
        header = self._header("disturbance")
        msg = Disturbance(
            header=header, kind=kind, torque=torque, duration_ns=duration_ns, value=value
        )
        return self._send("disturbance", msg, "disturbance_seq", wait)

    def _send(self, service, msg, field, wait):
        """Sends ``msg`` and, unless ``wait`` is None, waits up to ``wait`` seconds for the state
        that acknowledges it (its ``field`` equals the message's seq) and returns that state.

        The board publishes no answer to a rejected message; it counts it in the telemetry by
        reason. So while waiting, every telemetry published after the send is compared with the
        one before it: when a rejection counter rose, :class:`Rejected` is raised at once, with
        the reasons named (within about 100 ms, the telemetry's period). A message of another
        sender rejected in the same moment would be named too.
        """
        if wait is None:
            self.poll()
            self._publisher(service).send_copy(msg)
            return msg.header.seq
        before = list(self.telemetry().rejected_by_reason)
        seq, sent_ns = msg.header.seq, msg.header.time_ns
        self.poll()
        position = self.ring.count
        self._publisher(service).send_copy(msg)
        deadline = time.monotonic() + wait
        while True:
            self.poll()
            new, position = self.ring.since(position)
            hit = new[new[field] == seq]
            if len(hit):
                return hit[0]
            tel = self._drain_telemetry()
            if tel.header.time_ns > sent_ns:
                rose = [
                    name_of(r)
                    for r in Rejection
                    if tel.rejected_by_reason[r] > before[r]
                ]
                if rose:
                    raise Rejected(
                        f"namespace {self.namespace!r}: the board rejected {service} request "
                        f"{seq} ({', '.join(rose)}; docs/PROTOCOL.md, Rejections)",
                        rose,
                        seq,
                    )
            if time.monotonic() >= deadline:
                raise VicError(
                    f"namespace {self.namespace!r}: {service} request {seq} neither acknowledged "
                    f"nor counted as rejected within {wait} s"
                )
            time.sleep(0.001)

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

    def reset(self, q0, qd0=None, trial=1, seed=0, start_in_s=0.05, wait=2.0):
        """Puts the plant at ``q0``, ``qd0`` and starts trial ``trial`` ``start_in_s`` from now
        (the noise reseeded from ``(seed, trial)``). With no central process sending commands,
        the board's watchdog then ramps into the safe hold: the arm holds ``q0`` with the hold
        stiffness, and a pulse moves it and it springs back. ``q0`` [rad] and ``qd0`` [rad/s]
        (default zeros) have one value per joint of the board, or :class:`VicError` is raised
        before anything is sent. Returns the acknowledging state; :class:`Rejected` names the
        reason when the board refuses it."""
        q0 = self._joints(q0, "the posture q0")
        qd0 = self._joints(np.zeros(self.joints) if qd0 is None else qd0, "the velocity qd0")
        header = self._header("control")
        msg = Control(
            header=header,
            kind=ControlKind.RESET,
            trial=trial,
            seed=seed,
            start_ns=header.time_ns + int(start_in_s * 1e9),
            q0=q0,
            qd0=qd0,
        )
        return self._send("control", msg, "reset_seq", wait)

    def stop(self):
        """Ends the trial: the board goes idle, holding the arm at its posture, until the next reset."""
        msg = Control(header=self._header("control"), kind=ControlKind.STOP)
        self._publisher("control").send_copy(msg)

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
