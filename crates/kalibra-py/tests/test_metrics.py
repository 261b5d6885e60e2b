"""The building blocks against plain numpy."""

import numpy as np
import pytest

import kalibra


def test_nees_and_nis_per_cell_with_nan_cells():
    rng = np.random.default_rng(11)
    runs, steps, n = 5, 7, 3
    a = rng.normal(size=(runs, steps, n, n))
    cov = a @ np.swapaxes(a, -1, -2) + n * np.eye(n)
    truth = rng.normal(size=(runs, steps, n))
    est = truth + rng.normal(size=(runs, steps, n))
    est[2, 4] = np.nan
    e = est - truth
    expected = np.einsum("...i,...i->...", e, np.linalg.solve(cov, e[..., None])[..., 0])
    got = kalibra.nees(truth, est, cov)
    assert got.shape == (runs, steps) and got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    assert np.isnan(got[2, 4])
    np.testing.assert_allclose(kalibra.nees(truth[0], est[0], cov[0]), expected[0], rtol=1e-12)
    np.testing.assert_allclose(kalibra.nis(e, cov), expected, rtol=1e-12)
    # Fortran order and a transposed view are read in their logical order, not memory order.
    np.testing.assert_array_equal(kalibra.nees(truth, est, np.asfortranarray(cov)), got)
    swapped = np.swapaxes(np.swapaxes(cov, -1, -2).copy(), -1, -2)
    assert not swapped.flags.c_contiguous
    np.testing.assert_array_equal(kalibra.nees(truth, est, swapped), got)


def test_chi2_band_matches_the_textbook():
    # Bar-Shalom, Li and Kirubarajan (2001), example 5.4.2: n = 2, 50 runs, 95%: [1.5, 2.6].
    lower, upper = kalibra.chi2_band(2, 50, 0.95)
    assert lower == pytest.approx(1.5, abs=0.02) and upper == pytest.approx(2.6, abs=0.02)
    nl, nu = kalibra.chi2_band(2, 50, 0.95, normalized=True)
    assert (nl, nu) == pytest.approx((lower / 2, upper / 2), rel=1e-15)
    # One sample of chi-square(1) at 95%: [0.000982, 5.024].
    assert kalibra.chi2_band(1, 1, 0.95) == pytest.approx((0.000982069, 5.02388619), rel=1e-6)


def test_rmse_over_runs_and_over_time():
    rng = np.random.default_rng(5)
    truth = rng.normal(size=(4, 6, 2))
    est = truth + rng.normal(size=(4, 6, 2))
    e = est - truth
    np.testing.assert_allclose(kalibra.rmse(truth, est), np.sqrt((e**2).mean(axis=0)), rtol=1e-14)
    np.testing.assert_allclose(
        kalibra.rmse(truth, est, over="time"), np.sqrt((e**2).mean(axis=1)), rtol=1e-14
    )
    np.testing.assert_allclose(
        kalibra.rmse(truth[1], est[1], over="time"), np.sqrt((e[1] ** 2).mean(axis=0)), rtol=1e-14
    )
    est[0, 2] = np.nan
    got = kalibra.rmse(truth, est)
    np.testing.assert_allclose(got[2], np.sqrt((e[1:, 2] ** 2).mean(axis=0)), rtol=1e-14)


def test_sliding_window_against_numpy():
    rng = np.random.default_rng(9)
    errors = 1e3 + rng.normal(size=(50, 3))
    w = 7
    rmse, bias, std = kalibra.sliding_window(errors, w)
    windows = np.lib.stride_tricks.sliding_window_view(errors, w, axis=0)  # (44, 3, 7)
    assert rmse.shape == bias.shape == std.shape == (50 - w + 1, 3)
    np.testing.assert_allclose(bias, windows.mean(axis=-1), rtol=1e-13)
    np.testing.assert_allclose(std, windows.std(axis=-1, ddof=1), rtol=1e-9)
    np.testing.assert_allclose(rmse, np.sqrt((windows**2).mean(axis=-1)), rtol=1e-13)
    r1, b1, s1 = kalibra.sliding_window(errors[:, 1], w)
    np.testing.assert_array_equal(b1, bias[:, 1])
    assert r1.shape == (44,)
