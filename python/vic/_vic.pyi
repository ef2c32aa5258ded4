"""Type stubs of the extension module vic._vic (crates/vic-py). Use the package `vic`: it wraps
these in NumPy arrays and documents them; arrays cross as (dtype, shape, bytearray) triples."""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

_Path = Union[str, "os.PathLike[str]"]
_Array = Tuple[str, Tuple[int, ...], bytearray]
_ArrayIn = Tuple[List[int], bytes]

__version__: str

class VicError(Exception): ...

class ScenarioError(VicError):
    path: Optional[str]
    """The scenario file."""
    section: Optional[str]
    """The section of the faulty key, None when the error is not one key's."""
    key: Optional[str]
    """The faulty key, None when the error is not one key's."""
    override: Optional[str]
    """The set= entry ("section.key=value") that wrote the key, when one did."""

class ScenarioReadError(ScenarioError): ...
class ScenarioSyntaxError(ScenarioError): ...
class ScenarioKeyError(ScenarioError): ...
class OverrideError(ScenarioError): ...
class PlanError(VicError): ...
class PlanFileError(VicError): ...
class RecordingError(VicError): ...
class InternalError(VicError): ...

class Scenario:
    """A scenario file, loaded and validated (``vic plan --config FILE --set k=v``)."""

    @staticmethod
    def load(path: _Path, set: Optional[Dict[str, Any]] = None) -> "Scenario":
        """Reads the scenario file at ``path`` (a missing ``config/NAME.toml`` is the built-in
        copy) with ``set`` overrides ``{"section.key": value}``: a bool, int, finite float, list
        of those, or a str taken as the command line takes the text after ``=``. Raises a
        ScenarioError subclass naming the file and the key."""
    @staticmethod
    def from_str(
        text: str, path: _Path = "<string>", set: Optional[Dict[str, Any]] = None
    ) -> "Scenario":
        """A scenario from TOML text (``path`` names it in messages)."""
    @property
    def path(self) -> str: ...
    @property
    def overrides(self) -> List[str]:
        """The overrides as ``section.key=value``, as ``--set`` takes them."""
    @property
    def dof(self) -> int:
        """Joints: 1 (single joint) or 2 (two-link arm)."""
    @property
    def nx(self) -> int:
        """State dimension n."""
    @property
    def nu(self) -> int:
        """Control dimension m."""
    @property
    def dt(self) -> float:
        """Time step Δ [s]."""
    @property
    def steps(self) -> int:
        """Steps N = duration / Δ."""
    @property
    def duration(self) -> float:
        """Movement duration [s]."""
    @property
    def delay_ms(self) -> float:
        """The central feedback delay an ILQG plan is made for [ms]."""
    @property
    def method(self) -> str:
        """The scenario's ``[solver] method``: "ilqg" or "sooc"."""
    @property
    def config(self) -> Dict[str, Any]:
        """The configuration after the overrides (as written into plan files)."""

class Plan:
    @staticmethod
    def load(path: _Path) -> "Plan": ...
    def save(self, path: _Path) -> None: ...
    def arrays(self) -> Dict[str, _Array]: ...
    def summary(self) -> Dict[str, Any]: ...
    def predict_open_loop(self, scenario: Scenario) -> Dict[str, Any]: ...
    def with_arrays(
        self,
        u: Optional[_ArrayIn] = None,
        x: Optional[_ArrayIn] = None,
        gains: Optional[_ArrayIn] = None,
    ) -> "Plan": ...
    @property
    def config(self) -> Dict[str, Any]: ...
    @property
    def scenario(self) -> str: ...
    @property
    def dt(self) -> float: ...
    @property
    def state_names(self) -> List[str]: ...
    @property
    def control_names(self) -> List[str]: ...
    @property
    def version(self) -> int: ...

def plan(scenario: Scenario, method: Optional[str] = None, delay_ms: Optional[float] = None) -> Plan: ...
def simulate(
    scenario: Scenario,
    plan: Plan,
    policy: str = "open-loop",
    trials: int = 20,
    seed: int = 1,
    latency_ms: Optional[float] = None,
    divergence: Optional[float] = None,
) -> Dict[str, Any]: ...
def sweep_latency(
    scenario: Scenario,
    latencies_ms: Sequence[float],
    strategies: Sequence[str],
    trials: int = 20,
    seed: int = 1,
    divergence: Optional[float] = None,
    pulse: Optional[Sequence[float]] = None,
    pulse_at_ms: float = 400.0,
    pulse_ms: float = 50.0,
    engine: str = "offline",
) -> Dict[str, Any]: ...
def read_mcap_columns(
    path: _Path,
) -> Dict[str, Tuple[Dict[str, Any], Dict[str, Union[_Array, List[Any]]]]]: ...
def _panic(message: str) -> None: ...
