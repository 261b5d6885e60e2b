"""The smoothers: KalmanFilter.smooth against FilterPy's rts_smoother, the extended and
unscented smoothers against it on a linear model, and the outputs' shapes."""

import numpy as np
import pytest

import kalibra

# The model of test_filters.py (W1 with a correlated R).
from test_filters import F, G, H, P0, Q, R, X0


def measurements(steps=25, seed=7):
    rng = np.random.default_rng(seed)
    x = X0.copy()
    z = np.zeros((steps, 2))
    for k in range(steps):
        x = F @ x + G @ rng.normal(size=2) * np.sqrt(0.5)
        z[k] = H @ x + np.linalg.cholesky(R) @ rng.normal(size=2)
    z[4::6] = np.nan
    return z


def test_kalman_smoother_equals_filterpy_rts_smoother():
    filterpy = pytest.importorskip("filterpy.kalman")
    z = measurements()
    kf = filterpy.KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R, kf.x, kf.P = F, H, Q, R, X0.copy(), P0.copy()
    means, covs = [], []
    for row in z:
        kf.predict()
        kf.update(None if np.isnan(row).all() else row)
        means.append(kf.x.copy())
        covs.append(kf.P.copy())
    expected_mean, expected_cov, _, _ = kf.rts_smoother(np.array(means), np.array(covs))
    out = kalibra.KalmanFilter(F=F, H=H, Q=Q, R=R, x0=X0, P0=P0).smooth(z)
    assert np.max(np.abs(out["estimate"] - expected_mean)) < 1e-10
    assert np.max(np.abs(out["covariance"] - expected_cov)) < 1e-10


def test_extended_and_unscented_smoothers_equal_the_linear_one():
    z = measurements()
    linear = kalibra.KalmanFilter(F=F, H=H, Q=Q, R=R, x0=X0, P0=P0).smooth(z)
    ekf = kalibra.ExtendedKalmanFilter(
        f=lambda x, k: F @ x, F_jacobian=lambda x, k: F,
        h=lambda x, k: H @ x, H_jacobian=lambda x, k: H, Q=Q, R=R, x0=X0, P0=P0,
    ).smooth(z)
    ukf = kalibra.UnscentedKalmanFilter(
        f=lambda x, k: F @ x, h=lambda x, k: H @ x, Q=Q, R=R, x0=X0, P0=P0,
    ).smooth(z)
    for out in (ekf, ukf):
        for key in ("estimate", "covariance", "lag_one_covariance"):
            scale = np.max(np.abs(linear[key]))
            assert np.max(np.abs(out[key] - linear[key])) < 1e-9 * scale, key


def test_smooth_shapes_and_the_lag_one_row():
    z = measurements(steps=12)
    for start, first_nan in (("predict_first", False), ("update_first", True)):
        kf = kalibra.KalmanFilter(F=F, H=H, Q=Q, R=R, x0=X0, P0=P0, start=start)
        out = kf.smooth(z)
        assert out["estimate"].shape == (12, 4)
        assert out["covariance"].shape == (12, 4, 4)
        assert out["lag_one_covariance"].shape == (12, 4, 4)
        assert bool(np.isnan(out["lag_one_covariance"][0]).all()) == first_nan
        assert not np.isnan(out["lag_one_covariance"][1:]).any()
        # The last row is the filter's; every smoothed variance is at most the filtered one.
        filtered = kf.run(z)
        assert np.array_equal(out["estimate"][-1], filtered["estimate"][-1])
        variances = np.diagonal(out["covariance"], axis1=1, axis2=2)
        assert (variances <= np.diagonal(filtered["covariance"], axis1=1, axis2=2) + 1e-9).all()
    batch = kalibra.KalmanFilter(F=F, H=H, Q=Q, R=R, x0=X0, P0=P0).smooth(np.stack([z, z]))
    assert batch["lag_one_covariance"].shape == (2, 12, 4, 4)
    assert np.array_equal(batch["estimate"][1], kalibra.KalmanFilter(
        F=F, H=H, Q=Q, R=R, x0=X0, P0=P0).smooth(z)["estimate"])
