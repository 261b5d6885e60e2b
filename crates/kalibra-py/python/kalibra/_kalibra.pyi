"""Type stubs of the native module kalibra._kalibra (see kalibra's docstrings)."""

import os
from typing import Any, Callable, Literal, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]

__version__: str

class KalibraError(ValueError):
    """Bad input: the message names the argument and, where one is at fault, the index."""

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
    truth: Optional[ArrayLike] = None,
    estimate: Optional[ArrayLike] = None,
    covariance: Optional[ArrayLike] = None,
    innovation: Optional[ArrayLike] = None,
    innovation_cov: Optional[ArrayLike] = None,
    *,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    time: Optional[ArrayLike] = None,
    F: Optional[ArrayLike] = None,
    H: Optional[ArrayLike] = None,
    Q: Optional[ArrayLike] = None,
    R: Optional[ArrayLike] = None,
    name: str = "numpy arrays",
) -> Report: ...
def nees(truth: ArrayLike, estimate: ArrayLike, covariance: ArrayLike) -> FloatArray: ...
def nis(innovation: ArrayLike, innovation_cov: ArrayLike) -> FloatArray: ...
def nci(truth: ArrayLike, estimate: ArrayLike, covariance: ArrayLike) -> FloatArray: ...
def chi2_band(
    dof: float, samples: int, confidence: float = 0.95, normalized: bool = False
) -> Tuple[float, float]: ...
def rmse(
    truth: ArrayLike, estimate: ArrayLike, over: Literal["runs", "time"] = "runs"
) -> FloatArray: ...
def sliding_window(
    errors: ArrayLike, window: int
) -> Tuple[FloatArray, FloatArray, FloatArray]: ...

class KalmanFilter:
    """The linear Kalman filter, run in Rust."""

    def __init__(
        self,
        F: ArrayLike,
        H: ArrayLike,
        Q: ArrayLike,
        R: ArrayLike,
        x0: ArrayLike,
        P0: ArrayLike,
        start: Literal["predict_first", "update_first"] = "predict_first",
    ) -> None: ...
    @property
    def state_dim(self) -> int: ...
    @property
    def measurement_dim(self) -> int: ...
    def run(self, measurements: ArrayLike, threads: int = 0) -> dict[str, FloatArray]: ...

StateFn = Callable[[FloatArray, int], ArrayLike]
ResidualFn = Callable[[FloatArray, FloatArray], ArrayLike]
Start = Literal["predict_first", "update_first"]

class ExtendedKalmanFilter:
    """The extended Kalman filter on a model given as Python callables."""

    def __init__(
        self,
        f: StateFn,
        F_jacobian: StateFn,
        h: StateFn,
        H_jacobian: StateFn,
        Q: ArrayLike,
        R: ArrayLike,
        x0: ArrayLike,
        P0: ArrayLike,
        *,
        residual: Optional[ResidualFn] = None,
        start: Start = "predict_first",
    ) -> None: ...
    def run(self, measurements: ArrayLike) -> dict[str, FloatArray]: ...

class UnscentedKalmanFilter:
    """The unscented Kalman filter on a model given as Python callables."""

    def __init__(
        self,
        f: StateFn,
        h: StateFn,
        Q: ArrayLike,
        R: ArrayLike,
        x0: ArrayLike,
        P0: ArrayLike,
        *,
        points: Literal["symmetric", "scaled"] = "symmetric",
        kappa: Optional[float] = None,
        alpha: float = 1.0,
        beta: float = 2.0,
        adaptive_kappa: Optional[Literal["maximum_likelihood", "maximum_posterior"]] = None,
        kappa_grid: Optional[Sequence[float]] = None,
        residual: Optional[ResidualFn] = None,
        start: Start = "predict_first",
    ) -> None: ...
    def run(self, measurements: ArrayLike) -> dict[str, FloatArray]: ...

class TuneReport:
    """The J1/J2 sweep of Q = 10^p Q_nom and its recommendation (``kalibra tune``'s report)."""

    @property
    def headline(self) -> str: ...
    @property
    def p(self) -> FloatArray: ...
    @property
    def j1(self) -> FloatArray: ...
    @property
    def j2(self) -> FloatArray: ...
    @property
    def crossover(self) -> Optional[dict[str, Any]]: ...
    @property
    def recommended_q(self) -> Optional[FloatArray]: ...
    def to_dict(self) -> dict[str, Any]: ...
    def to_json(self) -> str: ...
    def markdown(self) -> str: ...
    def html(self) -> str: ...
    def _repr_html_(self) -> str: ...
    def save(self, dir: Union[str, "os.PathLike[str]"]) -> None: ...

def sweep_q(
    F: ArrayLike,
    H: ArrayLike,
    Q_nom: ArrayLike,
    R: ArrayLike,
    x0: ArrayLike,
    P0: ArrayLike,
    measurements: ArrayLike,
    *,
    p: Tuple[float, float, float] = (-6.0, 6.0, 0.5),
    truth: Optional[ArrayLike] = None,
    start: Start = "predict_first",
    position: Optional[Sequence[int]] = None,
    p0_as_given: bool = False,
    threads: int = 0,
    names: Tuple[str, str] = ("model", "measurements"),
) -> TuneReport: ...

def monte_carlo(
    F: ArrayLike,
    H: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike,
    x0: ArrayLike,
    P0: ArrayLike,
    *,
    runs: int = 100,
    steps: int = 100,
    seed: int = 0,
    threads: int = 0,
    filter_Q: Optional[ArrayLike] = None,
    filter_R: Optional[ArrayLike] = None,
    confidence: float = 0.95,
    window: Optional[int] = None,
    groups: Optional[Mapping[str, Sequence[int]]] = None,
    lags: int = 10,
    return_log: bool = False,
) -> Union[Report, Tuple[Report, dict[str, FloatArray]]]: ...
