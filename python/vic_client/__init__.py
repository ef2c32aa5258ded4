"""Python client of vic's live board: the wire protocol of docs/PROTOCOL.md over iceoryx2's
official Python bindings, and readers of vic's plan and recording files."""

from .board import (
    Board,
    LostStatesWarning,
    Rejected,
    StateRing,
    StatesLost,
    VicError,
    config,
    namespace_files,
    prefix,
    root_dir,
)
from .files import load_csv_record, load_mcap, load_plan
from .protocol import *  # noqa: F401,F403 (the protocol's types, enums and constants)

__version__ = "0.1.0"
