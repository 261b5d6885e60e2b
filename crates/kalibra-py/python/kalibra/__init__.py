"""kalibra: judge any Kalman-type filter from numpy arrays, and run kalibra's filters.

Is your filter's covariance telling the truth? ``kalibra.evaluate`` takes a filter's log as
numpy arrays (truth, estimate, covariance, innovation, innovation covariance; R runs of K
steps) and returns a report with per-step ANEES and ANIS and their chi-square bands, the
non-credibility index (NCI), RMSE per component, sliding-window errors, the innovations'
whiteness, J1/J2 and a verdict: consistent, optimistic (covariance too small) or pessimistic
(too large). It is the evaluation of the ``kalibra eval`` command, the same numbers and the
same report files, computed in Rust.

Example:
    >>> import numpy as np, kalibra
    >>> rng = np.random.default_rng(0)
    >>> truth = np.zeros((100, 10, 2))
    >>> estimate = rng.normal(size=(100, 10, 2))
    >>> covariance = np.broadcast_to(np.eye(2), (100, 10, 2, 2))
    >>> report = kalibra.evaluate(truth=truth, estimate=estimate, covariance=covariance)
    >>> report.verdict
    'consistent'
    >>> float(kalibra.nees(truth, estimate, covariance).mean() / 2) < 1.2
    True

The building blocks: ``nees``, ``nis``, ``nci``, ``chi2_band``, ``rmse``,
``sliding_window``. The filters: ``KalmanFilter`` (``run`` over a measurement sequence, or
many at once, returning numpy arrays named as ``evaluate``'s arguments), and
``ExtendedKalmanFilter`` and ``UnscentedKalmanFilter`` on your own model given as Python
callables (symmetric or scaled sigma points, adaptive kappa). Tuning: ``sweep_q``, the
J1/J2 sweep of ``Q = 10^p Q_nom`` of the ``kalibra tune`` command, and ``estimate_noise``,
``Q`` and ``R`` from the measurements alone by maximum likelihood (with intervals and what the
data identify), EM, ALS or J1/J2 on every parameter. Simulation:
``monte_carlo``, a seeded Monte Carlo of a linear model through the Kalman filter, evaluated,
all in Rust and bit-identical for any thread count; with ``shard=(i, S)`` it returns a
picklable ``Partial`` and ``merge`` of all S gives the one-process report to the bit (Dask,
job arrays). Errors are ``kalibra.KalibraError`` (a ``ValueError``) naming the
argument and, where one is at fault, the index; its attributes ``argument``, ``run``,
``step``, ``index``, ``file``, ``row`` and ``column`` hold the same facts (None where they
do not apply), so a program can tell which input to fix:

    >>> try:
    ...     kalibra.evaluate(truth=np.full((2, 3, 1), np.inf), estimate=np.zeros((2, 3, 1)),
    ...                      covariance=np.ones((2, 3, 1, 1)))
    ... except kalibra.KalibraError as e:
    ...     print(e.argument, e.run, e.step)
    truth 0 0
"""

from ._kalibra import (
    ExtendedKalmanFilter,
    KalibraError,
    KalmanFilter,
    NoiseEstimate,
    Partial,
    Report,
    TuneReport,
    UnscentedKalmanFilter,
    __version__,
    chi2_band,
    estimate_noise,
    evaluate,
    merge,
    monte_carlo,
    nci,
    nees,
    nis,
    rmse,
    sliding_window,
    sweep_q,
)

__all__ = [
    "ExtendedKalmanFilter",
    "KalibraError",
    "KalmanFilter",
    "NoiseEstimate",
    "Partial",
    "Report",
    "TuneReport",
    "UnscentedKalmanFilter",
    "__version__",
    "chi2_band",
    "estimate_noise",
    "evaluate",
    "merge",
    "monte_carlo",
    "nci",
    "nees",
    "nis",
    "rmse",
    "sliding_window",
    "sweep_q",
]
