"""kalibra.ExtendedKalmanFilter and UnscentedKalmanFilter with Python callables, against
FilterPy's EKF and UKF on the same inputs (1e-10), and their errors."""

import numpy as np
import pytest

import kalibra

DT = 1.0
F = np.array([[1, 0, DT, 0], [0, 1, 0, DT], [0, 0, 1, 0], [0, 0, 0, 1]], float)
G = np.array([[DT**2 / 2, 0], [0, DT**2 / 2], [DT, 0], [0, DT]])
Q = G @ G.T * 0.1
SENSOR = np.array([-200.0, -100.0])
R = np.diag([4.0, 1e-4])
X0 = np.array([0.0, 0.0, 3.0, 1.0])
P0 = np.diag([25.0, 25.0, 1.0, 1.0])


def f(x, k):
    return F @ x


def f_jacobian(x, k):
    return F


def h(x, k=0):
    d = x[:2] - SENSOR
    return np.array([np.hypot(d[0], d[1]), np.arctan2(d[1], d[0])])


def h_jacobian(x, k=0):
    d = x[:2] - SENSOR
    r2 = d @ d
    r = np.sqrt(r2)
    return np.array([[d[0] / r, d[1] / r, 0, 0], [-d[1] / r2, d[0] / r2, 0, 0]])


def measurements(steps=30, seed=21):
    rng = np.random.default_rng(seed)
    x = X0 + rng.normal(size=4) * np.sqrt(np.diag(P0))
    z = np.zeros((steps, 2))
    for k in range(steps):
        x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        z[k] = h(x) + rng.multivariate_normal(np.zeros(2), R)
    z[4::9] = np.nan
    return z


def close(a, b):
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10)


def test_ekf_equals_filterpy():
    filterpy = pytest.importorskip("filterpy.kalman")
    z = measurements()
    out = kalibra.ExtendedKalmanFilter(f, f_jacobian, h, h_jacobian, Q, R, X0, P0).run(z)
    ekf = filterpy.ExtendedKalmanFilter(dim_x=4, dim_z=2)
    ekf.x, ekf.P, ekf.F, ekf.Q, ekf.R = X0.copy(), P0.copy(), F, Q, R
    for k, zk in enumerate(z):
        ekf.predict()
        close(out["prior"][k], ekf.x)
        if not np.isnan(zk).all():
            ekf.update(zk, HJacobian=h_jacobian, Hx=h)
            close(out["innovation"][k], ekf.y)
            close(out["innovation_cov"][k], ekf.S)
        close(out["estimate"][k], ekf.x)
        close(out["covariance"][k], ekf.P)


@pytest.mark.parametrize(
    "options, points",
    [
        (dict(), lambda sp: sp.JulierSigmaPoints(4, kappa=0.0)),
        (dict(kappa=1.5), lambda sp: sp.JulierSigmaPoints(4, kappa=1.5)),
        (
            dict(points="scaled", alpha=0.5, beta=2.0, kappa=-1.0),
            lambda sp: sp.MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=-1.0),
        ),
    ],
)
def test_ukf_equals_filterpy_with_points_redrawn_from_the_prior(options, points):
    filterpy = pytest.importorskip("filterpy.kalman")
    z = measurements()
    out = kalibra.UnscentedKalmanFilter(f, h, Q, R, X0, P0, **options).run(z)
    sigma = points(filterpy)
    ukf = filterpy.UnscentedKalmanFilter(
        dim_x=4, dim_z=2, dt=DT, hx=h, fx=lambda x, dt: F @ x, points=sigma
    )
    ukf.x, ukf.P, ukf.Q, ukf.R = X0.copy(), P0.copy(), Q, R
    for k, zk in enumerate(z):
        ukf.predict()
        close(out["prior"][k], ukf.x)
        close(out["prior_covariance"][k], ukf.P)
        if not np.isnan(zk).all():
            # kalibra's UKF draws the update's sigma points from the prior; FilterPy reuses
            # the predicted ones unless they are redrawn.
            ukf.sigmas_f = sigma.sigma_points(ukf.x, ukf.P)
            ukf.update(zk)
            close(out["innovation"][k], ukf.y)
            close(out["innovation_cov"][k], ukf.S)
            close(out["log_likelihood"][k], ukf.log_likelihood)
        close(out["estimate"][k], ukf.x)
        close(out["covariance"][k], ukf.P)


def test_ukf_equals_kf_on_a_linear_model():
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    z = measurements()  # any numbers will do for the comparison
    kf = kalibra.KalmanFilter(F, H, Q, R, X0, P0).run(z)
    ukf = kalibra.UnscentedKalmanFilter(f, lambda x, k: H @ x, Q, R, X0, P0).run(z)
    for key in ("estimate", "covariance", "innovation", "nis"):
        np.testing.assert_allclose(ukf[key], kf[key], rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("criterion", ["maximum_likelihood", "maximum_posterior"])
def test_adaptive_kappa_picks_from_the_grid(criterion):
    z = measurements()
    grid = [-1.0, 0.0, 1.0, 2.0]
    out = kalibra.UnscentedKalmanFilter(
        f, h, Q, R, X0, P0, adaptive_kappa=criterion, kappa_grid=grid
    ).run(z)
    measured = ~np.isnan(z).all(axis=1)
    assert set(out["kappa"][measured]) <= set(grid)
    assert np.isnan(out["kappa"][~measured]).all()


def test_maximum_likelihood_kappa_minimises_its_criterion_at_the_first_update():
    z = measurements()[:1]
    grid = [-1.0, 0.0, 1.0, 2.0, 3.0]
    adaptive = kalibra.UnscentedKalmanFilter(
        f, h, Q, R, X0, P0, adaptive_kappa="maximum_likelihood", kappa_grid=grid,
        start="update_first",
    ).run(z)

    def criterion(kappa):
        one = kalibra.UnscentedKalmanFilter(f, h, Q, R, X0, P0, kappa=kappa, start="update_first").run(z)
        nu, s = one["innovation"][0], one["innovation_cov"][0]
        return np.linalg.slogdet(s)[1] + nu @ np.linalg.solve(s, nu)

    assert adaptive["kappa"][0] == grid[int(np.argmin([criterion(c) for c in grid]))]


def test_batch_of_runs_through_callbacks():
    z = np.stack([measurements(seed=s) for s in range(3)])
    ekf = kalibra.ExtendedKalmanFilter(f, f_jacobian, h, h_jacobian, Q, R, X0, P0)
    out = ekf.run(z)
    assert out["estimate"].shape == (3, 30, 4)
    np.testing.assert_array_equal(out["estimate"][2], ekf.run(z[2])["estimate"])


def test_a_failing_callable_names_itself_and_the_step():
    def h_fails(x, k):
        if k == 3:
            raise ZeroDivisionError("boom")
        return h(x)

    ukf = kalibra.UnscentedKalmanFilter(f, h_fails, Q, R, X0, P0)
    with pytest.raises(kalibra.KalibraError, match="h raised at step 3: ZeroDivisionError: boom") as info:
        ukf.run(measurements())
    assert isinstance(info.value.__cause__, ZeroDivisionError)
    z = np.stack([measurements(), measurements()])
    with pytest.raises(kalibra.KalibraError, match="run 0: h raised at step 3"):
        ukf.run(z)


def test_wrong_results_and_arguments():
    bad_shape = kalibra.ExtendedKalmanFilter(
        f, lambda x, k: np.eye(3), h, h_jacobian, Q, R, X0, P0
    )
    with pytest.raises(kalibra.KalibraError, match=r"F_jacobian returned shape \[3, 3\] at step 0"):
        bad_shape.run(measurements())
    column = kalibra.ExtendedKalmanFilter(
        lambda x, k: (F @ x)[:, None], f_jacobian, h, h_jacobian, Q, R, X0, P0
    )
    assert column.run(measurements())["estimate"].shape == (30, 4)
    with pytest.raises(kalibra.KalibraError, match="argument f is not callable"):
        kalibra.UnscentedKalmanFilter(F, h, Q, R, X0, P0)
    with pytest.raises(kalibra.KalibraError, match="argument R has shape"):
        kalibra.UnscentedKalmanFilter(f, h, Q, np.zeros((2, 3)), X0, P0)
    with pytest.raises(kalibra.KalibraError, match="needs kappa_grid"):
        kalibra.UnscentedKalmanFilter(f, h, Q, R, X0, P0, adaptive_kappa="maximum_likelihood")
    with pytest.raises(kalibra.KalibraError, match="argument points"):
        kalibra.UnscentedKalmanFilter(f, h, Q, R, X0, P0, points="cubature")
    with pytest.raises(kalibra.KalibraError, match="invalid filter"):
        kalibra.UnscentedKalmanFilter(f, h, Q, R, X0, P0, kappa=-4.0)


def test_residual_wraps_bearings():
    def wrap(z, zhat):
        d = z - zhat
        d[1] = (d[1] + np.pi) % (2 * np.pi) - np.pi
        return d

    x0 = np.array([-300.0, -100.0, 0.0, 0.0])  # due west of the sensor: bearing near pi
    z = np.array([[100.0, np.pi - 1e-3], [100.0, -np.pi + 1e-3]])
    still = np.eye(4)
    out = kalibra.ExtendedKalmanFilter(
        lambda x, k: x, lambda x, k: still, h, h_jacobian, np.zeros((4, 4)), R, x0, P0,
        residual=wrap,
    ).run(z)
    assert np.abs(out["innovation"][:, 1]).max() < 0.01
