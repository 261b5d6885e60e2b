"""Extreme but finite inputs reach the library's typed errors as a KalibraError with a clear
message, promptly: values of opposite signs near the float64 limit, and counts at 2**64 - 1."""

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


@pytest.mark.parametrize(
    "option, message",
    [
        (dict(window=USIZE_MAX), "window"),
        (dict(lags=USIZE_MAX), "lag"),
        (dict(groups={"pos": [0, USIZE_MAX]}), f"group pos names component {USIZE_MAX}"),
    ],
)
def test_largest_counts_are_refused_promptly(option, message):
    start = time.monotonic()
    with pytest.raises(kalibra.KalibraError, match=message):
        kalibra.evaluate(**log(), **option)
    assert time.monotonic() - start < 30
