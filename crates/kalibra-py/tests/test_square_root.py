"""form="square_root": kalibra's SqrtKf and SqrtUkf behind KalmanFilter and
UnscentedKalmanFilter, equal to the standard form on a normal case, and carrying on where the
standard form fails (the ill-conditioned case of kalibra-filters'
tests/it/sqrt_ill_conditioned.rs)."""

import numpy as np
import pytest

import kalibra

from test_filters import F, H, P0, Q, R, X0, simulate


def close(a, b):
    """Largest difference relative to the largest entry of b."""
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def test_square_root_kalman_filter_equals_the_standard_one():
    _, z = simulate(2, 30)
    standard = kalibra.KalmanFilter(F, H, Q, R, X0, P0)
    square_root = kalibra.KalmanFilter(F, H, Q, R, X0, P0, form="square_root")
    run, sqrt_run = standard.run(z), square_root.run(z)
    assert set(run) == set(sqrt_run)
    for key in run:
        np.testing.assert_array_equal(np.isnan(run[key]), np.isnan(sqrt_run[key]))
        finite = ~np.isnan(run[key])
        assert close(sqrt_run[key][finite], run[key][finite]) < 1e-10, key
    smoothed, sqrt_smoothed = standard.smooth(z), square_root.smooth(z)
    for key in ("estimate", "covariance", "lag_one_covariance"):
        assert close(sqrt_smoothed[key], smoothed[key]) < 1e-10, key


def range_model(form, **kwargs):
    """A constant-velocity target seen by its range to a point (the docs' example)."""
    F2 = np.array([[1.0, 1.0], [0.0, 1.0]])
    return kalibra.UnscentedKalmanFilter(
        f=lambda x, k: F2 @ x, h=lambda x, k: np.array([np.hypot(x[0], 10.0)]),
        Q=0.01 * np.eye(2), R=[[0.25]], x0=[0.0, 1.0], P0=np.eye(2), form=form, **kwargs,
    )


@pytest.mark.parametrize("points", ["symmetric", "scaled"])
def test_square_root_unscented_filter_equals_the_standard_one(points):
    z = np.array([[10.1], [10.2], [np.nan], [10.4], [10.9], [11.6]])
    kwargs = {"points": points} if points == "symmetric" else {"points": points, "alpha": 0.5}
    standard, square_root = range_model("standard", **kwargs), range_model("square_root", **kwargs)
    run, sqrt_run = standard.run(z), square_root.run(z)
    for key in ("estimate", "covariance", "prior_covariance", "innovation_cov", "nis"):
        finite = ~np.isnan(run[key])
        assert close(sqrt_run[key][finite], run[key][finite]) < 1e-10, key
    smoothed, sqrt_smoothed = standard.smooth(z), square_root.smooth(z)
    for key in ("estimate", "covariance", "lag_one_covariance"):
        assert close(sqrt_smoothed[key], smoothed[key]) < 1e-10, key


@pytest.mark.parametrize("criterion", ["maximum_likelihood", "maximum_posterior"])
def test_square_root_unscented_filter_adapts_kappa_as_the_standard_one(criterion):
    z = np.array([[10.1], [10.6], [np.nan], [11.9], [12.5], [14.2], [15.0], [17.1]])
    kwargs = {"adaptive_kappa": criterion, "kappa_grid": [-1.0, 0.0, 0.5, 1.0, 2.0, 4.0]}
    standard, square_root = range_model("standard", **kwargs), range_model("square_root", **kwargs)
    run, sqrt_run = standard.run(z), square_root.run(z)
    np.testing.assert_array_equal(sqrt_run["kappa"], run["kappa"])
    assert np.isnan(run["kappa"][2]) and len(set(run["kappa"][~np.isnan(run["kappa"])])) > 1
    for key in ("estimate", "covariance", "innovation_cov", "nis"):
        finite = ~np.isnan(run[key])
        assert close(sqrt_run[key][finite], run[key][finite]) < 1e-10, key


def test_square_root_carries_on_where_the_standard_form_fails():
    """Near-perfect, nearly collinear scalar measurements (d = 2^-30, R = d^2; F stretches the
    third state by 1 + d, so that the second measurement sees [1, 1, 1 + d], as in
    tests/it/sqrt_ill_conditioned.rs): the standard form's covariance turns indefinite and its
    estimate overflows; the square-root form stays finite, its covariance positive
    semi-definite to rounding (the exact one has an eigenvalue near 1e-19 beside ones, below
    what a matrix of f64 shows), the unseen direction (1, -1, 0) keeps its prior variance 1
    and the estimate reproduces the measurements; the same for the smoothed run."""
    d = 2.0**-30
    F3, H3 = np.diag([1.0, 1.0, 1.0 + d]), np.array([[1.0, 1.0, 1.0]])
    x, z = np.array([1.0, -2.0, 3.0]), []
    for _ in range(10):
        z.append(H3 @ x)
        x = F3 @ x
    z = np.array(z)
    model = dict(F=F3, H=H3, Q=np.zeros((3, 3)), R=[[d * d]], x0=np.zeros(3), P0=np.eye(3),
                 start="update_first")
    with pytest.raises(kalibra.KalibraError, match="not finite"):
        kalibra.KalmanFilter(**model).run(z)
    out = kalibra.KalmanFilter(**model, form="square_root").run(z)
    assert np.isfinite(out["estimate"]).all() and np.isfinite(out["covariance"]).all()
    for p in out["covariance"]:
        np.testing.assert_array_equal(p, p.T)
        assert np.linalg.eigvalsh(p).min() >= -1e-15 * np.abs(p).max()
    unseen = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    assert abs(unseen @ out["covariance"][-1] @ unseen - 1.0) < 1e-9
    assert np.max(np.abs(out["estimate"] @ H3.T - z)) < 1e-6
    # Smoothing: the standard form fails in its forward pass; the square-root smoother (its
    # backward pass on the factors) stays finite and positive semi-definite, and every
    # smoothed estimate reproduces its measurement.
    with pytest.raises(kalibra.KalibraError):
        kalibra.KalmanFilter(**model).smooth(z)
    smoothed = kalibra.KalmanFilter(**model, form="square_root").smooth(z)
    assert np.isfinite(smoothed["estimate"]).all() and np.isfinite(smoothed["covariance"]).all()
    for p in smoothed["covariance"]:
        np.testing.assert_array_equal(p, p.T)
        assert np.linalg.eigvalsh(p).min() >= -1e-15 * np.abs(p).max()
        assert abs(unseen @ p @ unseen - 1.0) < 1e-9
    assert np.max(np.abs(smoothed["estimate"] @ H3.T - z)) < 1e-5


def test_form_is_checked():
    with pytest.raises(kalibra.KalibraError, match="argument form"):
        kalibra.KalmanFilter(F, H, Q, R, X0, P0, form="information")
    with pytest.raises(kalibra.KalibraError, match="argument form"):
        range_model("cholesky")
    assert "form=SquareRoot" in repr(kalibra.KalmanFilter(F, H, Q, R, X0, P0, form="square_root"))
