"""kalibra.KalmanFilter against FilterPy on the same inputs, and its arguments."""

import numpy as np
import pytest

import kalibra

DT = 1.0
F = np.array([[1, 0, DT, 0], [0, 1, 0, DT], [0, 0, 1, 0], [0, 0, 0, 1]], float)
G = np.array([[DT**2 / 2, 0], [0, DT**2 / 2], [DT, 0], [0, DT]])
Q = G @ G.T * 0.5
H = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], float)
R = np.array([[25.0, 3.0], [3.0, 16.0]])
X0 = np.array([0.0, 0.0, 5.0, -2.0])
P0 = np.diag([100.0, 100.0, 9.0, 9.0])


def simulate(runs, steps, seed=16):
    rng = np.random.default_rng(seed)
    x = np.tile(X0, (runs, 1)) + rng.normal(size=(runs, 4)) * np.sqrt(np.diag(P0))
    truth = np.zeros((runs, steps, 4))
    z = np.zeros((runs, steps, 2))
    for k in range(steps):
        x = x @ F.T + rng.multivariate_normal(np.zeros(4), Q, size=runs)
        truth[:, k] = x
        z[:, k] = x @ H.T + rng.multivariate_normal(np.zeros(2), R, size=runs)
    z[:, 5::7] = np.nan  # no measurement at every seventh step
    return truth, z


def test_kalman_filter_equals_filterpy():
    filterpy = pytest.importorskip("filterpy.kalman")
    _, z = simulate(1, 40)
    z = z[0]
    out = kalibra.KalmanFilter(F, H, Q, R, X0, P0).run(z)
    kf = filterpy.KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R, kf.x, kf.P = F, H, Q, R, X0.copy(), P0.copy()
    for k, zk in enumerate(z):
        kf.predict()
        np.testing.assert_allclose(out["prior"][k], kf.x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(out["prior_covariance"][k], kf.P, rtol=1e-10, atol=1e-10)
        if np.isnan(zk).all():
            kf.update(None)
            assert np.isnan(out["innovation"][k]).all() and np.isnan(out["nis"][k])
        else:
            kf.update(zk)
            np.testing.assert_allclose(out["innovation"][k], kf.y, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(out["innovation_cov"][k], kf.S, rtol=1e-10, atol=1e-10)
            np.testing.assert_allclose(out["nis"][k], kf.mahalanobis**2, rtol=1e-10)
            np.testing.assert_allclose(out["log_likelihood"][k], kf.log_likelihood, rtol=1e-10)
        np.testing.assert_allclose(out["estimate"][k], kf.x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(out["covariance"][k], kf.P, rtol=1e-10, atol=1e-10)


def test_batch_runs_equal_single_runs_and_feed_evaluate():
    truth, z = simulate(30, 25)
    kf = kalibra.KalmanFilter(F, H, Q, R, X0, P0)
    out = kf.run(z)
    assert out["estimate"].shape == (30, 25, 4) and out["covariance"].shape == (30, 25, 4, 4)
    assert out["nis"].shape == (30, 25)
    one = kf.run(z[7])
    for key in out:
        np.testing.assert_array_equal(out[key][7], one[key])
    for threads in (1, 3):
        again = kf.run(z, threads=threads)
        for key in out:
            np.testing.assert_array_equal(again[key], out[key])
    args = ("estimate", "covariance", "innovation", "innovation_cov")
    report = kalibra.evaluate(truth=truth, **{k: out[k] for k in args})
    assert report.verdict == "consistent"
    np.testing.assert_allclose(
        kalibra.nis(out["innovation"], out["innovation_cov"]), out["nis"], rtol=1e-12
    )


def test_update_first_starts_at_the_first_measurement():
    _, z = simulate(1, 3)
    out = kalibra.KalmanFilter(F, H, Q, R, X0, P0, start="update_first").run(z[0])
    np.testing.assert_array_equal(out["prior"][0], X0)
    np.testing.assert_array_equal(out["prior_covariance"][0], P0)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(F=np.eye(3)), r"argument F has shape \[3, 3\]; expected \(4, 4\)"),
        (dict(H=np.eye(4)[:2, :3]), r"argument H has shape \[2, 3\]; expected \(m, 4\)"),
        (dict(R=np.eye(3)), "argument R has shape"),
        (dict(x0=np.zeros((4, 1))), "argument x0 has shape"),
        (dict(Q=-np.eye(4)), "process noise covariance Q"),
        (dict(R=np.array([[1.0, 2.0], [0.0, 1.0]])), "measurement noise covariance R"),
        (dict(P0=np.full((4, 4), np.nan)), "arguments x0, P0"),
        (dict(start="later"), "argument start"),
    ],
)
def test_constructor_names_the_argument(change, message):
    args = dict(F=F, H=H, Q=Q, R=R, x0=X0, P0=P0)
    with pytest.raises(kalibra.KalibraError, match=message):
        kalibra.KalmanFilter(**{**args, **change})


def test_run_errors_name_the_row():
    kf = kalibra.KalmanFilter(F, H, Q, R, X0, P0)
    with pytest.raises(kalibra.KalibraError, match=r"argument measurements has shape \[5, 3\]"):
        kf.run(np.zeros((5, 3)))
    z = np.zeros((40, 5, 2))
    z[17, 3, 0] = np.nan
    z[30, 2, 1] = np.nan
    for threads in (0, 1, 2):
        with pytest.raises(kalibra.KalibraError, match="run 17: row 3 holds NaN in some"):
            kf.run(z, threads=threads)
    z = np.zeros((5, 2))
    z[2] = np.inf
    with pytest.raises(kalibra.KalibraError, match="not finite"):
        kf.run(z)
