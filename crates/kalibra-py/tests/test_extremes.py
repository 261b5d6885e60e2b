"""Extreme but finite inputs come back promptly, as an answer or as the library's typed error
in a KalibraError with a clear message: values of opposite signs near the float64 limit (in a
log and in the measurements of a Q sweep), and counts at 2**64 - 1."""

import time

import numpy as np
import pytest

import kalibra

USIZE_MAX = 2**64 - 1


def log(runs=2, steps=3):
    return dict(
        truth=np.zeros((runs, steps, 1)),
        estimate=np.full((runs, steps, 1), 0.5),
        covariance=np.ones((runs, steps, 1, 1)),
    )


def test_error_beyond_float64_is_a_clear_error():
    arrays = log()
    # Each value is finite; their difference, the estimation error, is not.
    arrays["truth"][0, 1, 0] = 1e308
    arrays["estimate"][0, 1, 0] = -1.5e308
    with pytest.raises(
        kalibra.KalibraError,
        match=r"estimation error estimate - truth at run 0, step 1 lies beyond f64's range",
    ):
        kalibra.evaluate(**arrays)


@pytest.mark.parametrize("option", [dict(window=USIZE_MAX), dict(lags=USIZE_MAX)])
def test_largest_window_and_lags_are_an_answer_at_once(option):
    # Longer than the series: the report leaves them out, and nothing is reserved for them.
    start = time.monotonic()
    report = kalibra.evaluate(**log(), **option).to_dict()
    assert report["runs"] == 2
    assert time.monotonic() - start < 30


def test_largest_group_index_is_refused():
    with pytest.raises(kalibra.KalibraError, match=f"group pos names component {USIZE_MAX}"):
        kalibra.evaluate(**log(), groups={"pos": [0, USIZE_MAX]})


def test_tune_extremes_are_clear_errors():
    # The model of `kalibra tune`'s fixtures; measurements of opposite signs near the float64
    # limit, each finite, the filter's innovation between them not.
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    Q = np.array([[0.5, 0.5], [0.5, 1.0]])
    R = np.array([[4.0]])
    x0 = np.array([0.0, 1.0])
    P0 = np.array([[10.0, 0.0], [0.0, 1.0]])
    z = np.array([[1e308], [-1.5e308], [0.0], [0.5]])
    start = time.monotonic()
    with pytest.raises(
        kalibra.KalibraError, match=r"filter at p = -6: innovation is not finite at step 2"
    ):
        kalibra.sweep_q(F, H, Q, R, x0, P0, z)
    with pytest.raises(kalibra.KalibraError, match=r"more than MAX_THREADS \(4096\)"):
        kalibra.sweep_q(F, H, Q, R, x0, P0, np.zeros((4, 1)), threads=USIZE_MAX)
    assert time.monotonic() - start < 30
