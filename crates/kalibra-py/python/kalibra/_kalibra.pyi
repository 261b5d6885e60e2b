"""Type stubs of the native module kalibra._kalibra (see kalibra's docstrings)."""

import os
from typing import (
    Any,
    Callable,
    Iterable,
    Literal,
    Mapping,
    Optional,
    Sequence,
    Tuple,
    Union,
    final,
    overload,
)

import numpy as np
import numpy.typing as npt

_ArrayLike = npt.ArrayLike
_FloatArray = npt.NDArray[np.float64]

__version__: str
__all__ = [
    "KalibraError",
    "__version__",
    "Report",
    "evaluate",
    "nees",
    "nis",
    "nci",
    "chi2_band",
    "rmse",
    "sliding_window",
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "TuneReport",
    "sweep_q",
    "NoiseEstimate",
    "estimate_noise",
    "monte_carlo",
    "Partial",
    "merge",
]

class KalibraError(ValueError):
    """Bad input: the message names the argument and, where one is at fault, the index.

    The same facts as attributes, for a program to act on; each is None where it does not
    apply (an error of an option has no run, an error of arrays no file).
    """

    argument: str | None
    """The argument at fault (``"truth"``, ``"Q_nom"``, ``"groups"``, ...)."""
    run: int | None
    """The run at fault, from 0."""
    step: int | None
    """The step at fault, from 0."""
    index: tuple[int, ...] | None
    """Where inside the argument, outermost axis first, from 0 (a matrix's row or pivot, a
    group's component, a grid point)."""
    file: str | None
    """The file at fault."""
    row: int | None
    """The row (CSV) or line (JSON, TOML) of the file, from 1."""
    column: int | None
    """The column of the file, from 1."""

@final
class Report:
    """The consistency report of a filter log (the content of ``report.json``)."""

    @property
    def verdict(self) -> Literal["consistent", "optimistic", "pessimistic", "undetermined"]: ...
    @property
    def headline(self) -> str: ...
    def to_dict(self) -> dict[str, Any]: ...
    def to_json(self) -> str: ...
    def markdown(self) -> str: ...
    def html(self) -> str: ...
    def _repr_html_(self) -> str: ...
    def save(self, dir: Union[str, "os.PathLike[str]"]) -> None: ...

def evaluate(
    truth: Optional[_ArrayLike] = None,
    estimate: Optional[_ArrayLike] = None,
    covariance: Optional[_ArrayLike] = None,
    innovation: Optional[_ArrayLike] = None,
    innovation_cov: Optional[_ArrayLike] = None,
    *,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    time: Optional[_ArrayLike] = None,
    F: Optional[_ArrayLike] = None,
    H: Optional[_ArrayLike] = None,
    Q: Optional[_ArrayLike] = None,
    R: Optional[_ArrayLike] = None,
    name: str = "numpy arrays",
) -> Report: ...
def nees(truth: _ArrayLike, estimate: _ArrayLike, covariance: _ArrayLike) -> _FloatArray: ...
def nis(innovation: _ArrayLike, innovation_cov: _ArrayLike) -> _FloatArray: ...
def nci(truth: _ArrayLike, estimate: _ArrayLike, covariance: _ArrayLike) -> _FloatArray: ...
def chi2_band(
    dof: float, samples: int, confidence: float = 0.95, normalized: bool = False
) -> Tuple[float, float]: ...
def rmse(
    truth: _ArrayLike, estimate: _ArrayLike, over: Literal["runs", "time"] = "runs"
) -> _FloatArray: ...
def sliding_window(
    errors: _ArrayLike, window: int
) -> Tuple[_FloatArray, _FloatArray, _FloatArray]: ...

@final
class KalmanFilter:
    """The linear Kalman filter, run in Rust."""

    def __new__(
        cls,
        F: _ArrayLike,
        H: _ArrayLike,
        Q: _ArrayLike,
        R: _ArrayLike,
        x0: _ArrayLike,
        P0: _ArrayLike,
        start: Literal["predict_first", "update_first"] = "predict_first",
        form: Literal["standard", "square_root"] = "standard",
    ) -> "KalmanFilter": ...
    @property
    def state_dim(self) -> int: ...
    @property
    def measurement_dim(self) -> int: ...
    def run(self, measurements: _ArrayLike, threads: int = 0) -> dict[str, _FloatArray]: ...
    def smooth(self, measurements: _ArrayLike) -> dict[str, _FloatArray]: ...

_StateFn = Callable[[_FloatArray, int], _ArrayLike]
_ResidualFn = Callable[[_FloatArray, _FloatArray], _ArrayLike]
_Start = Literal["predict_first", "update_first"]

@final
class ExtendedKalmanFilter:
    """The extended Kalman filter on a model given as Python callables."""

    def __new__(
        cls,
        f: _StateFn,
        F_jacobian: _StateFn,
        h: _StateFn,
        H_jacobian: _StateFn,
        Q: _ArrayLike,
        R: _ArrayLike,
        x0: _ArrayLike,
        P0: _ArrayLike,
        *,
        residual: Optional[_ResidualFn] = None,
        start: _Start = "predict_first",
    ) -> "ExtendedKalmanFilter": ...
    def run(self, measurements: _ArrayLike) -> dict[str, _FloatArray]: ...
    def smooth(self, measurements: _ArrayLike) -> dict[str, _FloatArray]: ...

@final
class UnscentedKalmanFilter:
    """The unscented Kalman filter on a model given as Python callables."""

    def __new__(
        cls,
        f: _StateFn,
        h: _StateFn,
        Q: _ArrayLike,
        R: _ArrayLike,
        x0: _ArrayLike,
        P0: _ArrayLike,
        *,
        points: Literal["symmetric", "scaled"] = "symmetric",
        kappa: Optional[float] = None,
        alpha: float = 1.0,
        beta: float = 2.0,
        adaptive_kappa: Optional[Literal["maximum_likelihood", "maximum_posterior"]] = None,
        kappa_grid: Optional[Sequence[float]] = None,
        residual: Optional[_ResidualFn] = None,
        start: _Start = "predict_first",
        form: Literal["standard", "square_root"] = "standard",
    ) -> "UnscentedKalmanFilter": ...
    def run(self, measurements: _ArrayLike) -> dict[str, _FloatArray]: ...
    def smooth(self, measurements: _ArrayLike) -> dict[str, _FloatArray]: ...

@final
class TuneReport:
    """The J1/J2 sweep of Q = 10^p Q_nom and its recommendation (``kalibra tune``'s report)."""

    @property
    def headline(self) -> str: ...
    @property
    def p(self) -> _FloatArray: ...
    @property
    def j1(self) -> _FloatArray: ...
    @property
    def j2(self) -> _FloatArray: ...
    @property
    def crossover(self) -> Optional[dict[str, Any]]: ...
    @property
    def recommended_q(self) -> Optional[_FloatArray]: ...
    def to_dict(self) -> dict[str, Any]: ...
    def to_json(self) -> str: ...
    def markdown(self) -> str: ...
    def html(self) -> str: ...
    def _repr_html_(self) -> str: ...
    def save(self, dir: Union[str, "os.PathLike[str]"]) -> None: ...

def sweep_q(
    F: _ArrayLike,
    H: _ArrayLike,
    Q_nom: _ArrayLike,
    R: _ArrayLike,
    x0: _ArrayLike,
    P0: _ArrayLike,
    measurements: _ArrayLike,
    *,
    p: Tuple[float, float, float] = ...,  # (-6.0, 6.0, 0.5)
    truth: Optional[_ArrayLike] = None,
    start: _Start = "predict_first",
    position: Optional[Sequence[int]] = None,
    p0_as_given: bool = False,
    threads: int = 0,
    names: Tuple[str, str] = ...,  # ("model", "measurements")
) -> TuneReport: ...

_Form = Literal["fixed", "scaled", "diagonal", "full"]
# What is known of a noise matrix: a matrix (fixed), (form, value), (form, value, fixed) or
# {"form": form, "value": value, "fixed": [(row, col), ...]} ("fixed" optional).
_NoiseSpec = Union[
    _ArrayLike,
    Tuple[_Form, _ArrayLike],
    Tuple[_Form, _ArrayLike, Sequence[Tuple[int, int]]],
    Mapping[str, Any],
]

@final
class NoiseEstimate:
    """Q and R estimated from measurements (``kalibra tune --method``'s report)."""

    @property
    def method(self) -> Literal["ml", "em", "als", "j1j2"]: ...
    @property
    def log_likelihood(self) -> Optional[float]: ...
    @property
    def start_log_likelihood(self) -> Optional[float]: ...
    @property
    def Q(self) -> _FloatArray: ...
    @property
    def Qw(self) -> _FloatArray: ...
    @property
    def R(self) -> _FloatArray: ...
    # One dict per free parameter: name (str), value (float), stderr (float or None), ci95
    # ((low, high) or None), at_bound (None, "zero" or "infinity"), profile (dict or None).
    @property
    def parameters(self) -> list[dict[str, Any]]: ...
    @property
    def converged(self) -> bool: ...
    @property
    def iterations(self) -> int: ...
    # source, parameters, rank, condition (None: infinite), unidentifiable (list of str),
    # message.
    @property
    def identifiable(self) -> Optional[dict[str, Any]]: ...
    # {"estimate": ..., "start": ...}: anis, whiteness, anees, rmse, rmse_per_component,
    # verdict (each None where it does not apply).
    @property
    def consistency(self) -> dict[str, Any]: ...
    @property
    def warnings(self) -> list[str]: ...
    def to_dict(self) -> dict[str, Any]: ...
    def to_json(self) -> str: ...
    # report.json, report.md, report.html and the profile figures (for callables too).
    def save(self, dir: Union[str, "os.PathLike[str]"]) -> None: ...

def estimate_noise(
    F: Union[_ArrayLike, _StateFn],
    H: Union[_ArrayLike, _StateFn],
    measurements: _ArrayLike,
    *,
    Q: _NoiseSpec,
    R: _NoiseSpec,
    x0: _ArrayLike,
    P0: _ArrayLike,
    G: Optional[_ArrayLike] = None,
    method: Literal["ml", "em", "als", "j1j2"] = "ml",
    start: _Start = "predict_first",
    truth: Optional[_ArrayLike] = None,
    iterations: Optional[int] = None,
    tolerance: Optional[float] = None,
    lags: Optional[int] = None,
    p: Optional[Tuple[float, float, float]] = None,
    profile: bool = True,
    F_jacobian: Optional[_StateFn] = None,
    H_jacobian: Optional[_StateFn] = None,
    residual: Optional[_ResidualFn] = None,
    kind: Literal["ekf", "ukf"] = "ekf",
    names: Optional[Tuple[str, str]] = None,
) -> NoiseEstimate: ...

# The return type follows `shard` and `return_log`: a shard's partial, the report with the
# simulated log, or the report (the last overload takes what is known only at run time).
@overload
def monte_carlo(
    F: _ArrayLike,
    H: _ArrayLike,
    Q: _ArrayLike,
    R: _ArrayLike,
    x0: _ArrayLike,
    P0: _ArrayLike,
    *,
    runs: int = 100,
    steps: int = 100,
    seed: int = 0,
    threads: int = 0,
    filter_Q: Optional[_ArrayLike] = None,
    filter_R: Optional[_ArrayLike] = None,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    return_log: Literal[False] = False,
    shard: Tuple[int, int],
) -> Partial: ...

@overload
def monte_carlo(
    F: _ArrayLike,
    H: _ArrayLike,
    Q: _ArrayLike,
    R: _ArrayLike,
    x0: _ArrayLike,
    P0: _ArrayLike,
    *,
    runs: int = 100,
    steps: int = 100,
    seed: int = 0,
    threads: int = 0,
    filter_Q: Optional[_ArrayLike] = None,
    filter_R: Optional[_ArrayLike] = None,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    return_log: Literal[True],
    shard: None = None,
) -> Tuple[Report, dict[str, _FloatArray]]: ...

@overload
def monte_carlo(
    F: _ArrayLike,
    H: _ArrayLike,
    Q: _ArrayLike,
    R: _ArrayLike,
    x0: _ArrayLike,
    P0: _ArrayLike,
    *,
    runs: int = 100,
    steps: int = 100,
    seed: int = 0,
    threads: int = 0,
    filter_Q: Optional[_ArrayLike] = None,
    filter_R: Optional[_ArrayLike] = None,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    return_log: Literal[False] = False,
    shard: None = None,
) -> Report: ...

@overload
def monte_carlo(
    F: _ArrayLike,
    H: _ArrayLike,
    Q: _ArrayLike,
    R: _ArrayLike,
    x0: _ArrayLike,
    P0: _ArrayLike,
    *,
    runs: int = 100,
    steps: int = 100,
    seed: int = 0,
    threads: int = 0,
    filter_Q: Optional[_ArrayLike] = None,
    filter_R: Optional[_ArrayLike] = None,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    return_log: bool = False,
    shard: Optional[Tuple[int, int]] = None,
) -> Union[Report, Tuple[Report, dict[str, _FloatArray]], Partial]: ...

@final
class Partial:
    """One shard's partial result of ``monte_carlo(..., shard=(i, S))``: picklable, and
    ``merge`` of all S shards' is the one-process report to the bit."""

    @staticmethod
    def from_bytes(data: bytes) -> Partial: ...
    def to_bytes(self) -> bytes: ...
    def __reduce__(self) -> Tuple[Callable[[bytes], Partial], Tuple[bytes]]: ...
    @property
    def shard(self) -> int: ...
    @property
    def shard_count(self) -> int: ...
    @property
    def runs(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def config_hash(self) -> str: ...
    @property
    def version(self) -> str: ...
    @property
    def blocks(self) -> int: ...

def merge(parts: Iterable[Union[Partial, bytes]]) -> Report: ...
