"""The live board from the same package: ``vic.live.Board`` streams a running ``vic-board``'s
state (1 kHz) and telemetry and sends it requests (reset, pulse, load, field, noise, stop) over
iceoryx2's official Python bindings, following docs/PROTOCOL.md.

The client is the package ``vic_client`` (python/vic_client), shipped in the same wheel and
importable under both names; it needs ``iceoryx2==0.10.0`` (``pip install vic[live]``), which
``import vic`` alone does not.

>>> from vic.live import Board          # vic-board --namespace lab running
>>> with Board("lab") as b:
...     b.reset(q0=[0.43, 2.12])       # joint angles [rad]; with no planner the board holds q0
...     ack = b.inject_pulse([2.0, 0.0], 0.05)   # torque per joint [N m] for 0.05 s
...     states = b.collect(0.5)        # NumPy structured array: states["tick"], states["q"], …

Its files' readers are there too: ``load_plan``, ``load_mcap`` (needs ``mcap``) and
``load_csv_record``; for recordings :func:`vic.read_mcap` needs no other package.
"""

from vic_client import (  # noqa: F401 (re-exported)
    Board,
    LostStatesWarning,
    Rejected,
    StateRing,
    StatesLost,
    VicError,
    config,
    load_csv_record,
    load_mcap,
    load_plan,
    namespace_files,
    prefix,
    root_dir,
)
from vic_client.protocol import *  # noqa: F401,F403 (the protocol's types, enums and constants)
