"""kalibra.monte_carlo: seeded, bit-identical for any thread count, and its log is what
KalmanFilter and evaluate give on the same simulated data."""

import numpy as np
import pytest

import kalibra

F = np.array([[1.0, 1.0], [0.0, 1.0]])
H = np.array([[1.0, 0.0]])
Q = np.array([[0.25, 0.5], [0.5, 1.0]]) * 0.1
R = np.array([[4.0]])
X0 = np.array([0.0, 1.0])
P0 = np.diag([10.0, 1.0])
ARGS = (F, H, Q, R, X0, P0)


def test_bit_identical_for_any_thread_count():
    one = kalibra.monte_carlo(*ARGS, runs=64, steps=40, seed=5, threads=1).to_dict()
    two = kalibra.monte_carlo(*ARGS, runs=64, steps=40, seed=5, threads=2).to_dict()
    assert one == two
    other = kalibra.monte_carlo(*ARGS, runs=64, steps=40, seed=6, threads=2).to_dict()
    assert other != one


def test_log_is_the_filter_and_the_evaluation_of_the_simulated_data():
    report, log = kalibra.monte_carlo(*ARGS, runs=20, steps=30, seed=9, return_log=True)
    assert log["truth"].shape == (20, 30, 2) and log["innovation_cov"].shape == (20, 30, 1, 1)
    # The filter's estimates are KalmanFilter's on the same measurements (update first: x0,
    # P0 is the prior at the first measurement). The measurements are z = truth + innovation
    # terms, recovered here as H x- + innovation.
    out = kalibra.KalmanFilter(F, H, Q, R, X0, P0, start="update_first")
    z = np.einsum("ij,rkj->rki", H, np.concatenate(
        [np.broadcast_to(X0, (20, 1, 2)), log["estimate"][:, :-1] @ F.T], axis=1
    )) + log["innovation"]
    run = out.run(z)
    np.testing.assert_allclose(run["estimate"], log["estimate"], rtol=1e-9, atol=1e-9)
    again = kalibra.evaluate(**{k: v for k, v in log.items()})
    # The study evaluates each Monte Carlo block (here one run) on its own evaluator and merges
    # them; evaluate sums every cell in one sequence: the same report to rounding.
    _close(again.to_dict(), report.to_dict())
    assert report.to_dict()["j"] is not None


def _close(a, b, path="report", rel=1e-12):
    """Every number of two report dicts within `rel` (relative), everything else equal."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}", rel)
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (u, v) in enumerate(zip(a, b)):
            _close(u, v, f"{path}[{i}]", rel)
    elif isinstance(a, float) and isinstance(b, float):
        assert abs(a - b) <= rel * max(abs(a), abs(b), 1.0), f"{path}: {a} vs {b}"
    elif path.endswith("evidence"):
        pass  # prose with numbers printed from the values above
    else:
        assert a == b, path


def test_blocks_of_runs_agree_with_evaluate_to_rounding():
    # 150 runs: blocks of two and three runs, evaluated in parallel and merged in order; one
    # evaluator run after run (evaluate) sums in another association.
    report, log = kalibra.monte_carlo(*ARGS, runs=150, steps=40, seed=3, return_log=True)
    again = kalibra.evaluate(**log)
    _close(report.to_dict(), again.to_dict())
    one, two = (
        kalibra.monte_carlo(*ARGS, runs=150, steps=40, seed=3, threads=t).to_dict() for t in (1, 2)
    )
    assert one == two == report.to_dict()


def test_consistent_and_optimistic_filters():
    assert kalibra.monte_carlo(*ARGS, runs=200, steps=50, seed=2).verdict == "consistent"
    assert kalibra.monte_carlo(*ARGS, runs=200, steps=50, seed=2, filter_R=R / 4).verdict == "optimistic"
    assert kalibra.monte_carlo(*ARGS, runs=200, steps=50, seed=2, filter_Q=Q * 50).verdict == "pessimistic"


def test_arguments_are_checked():
    with pytest.raises(kalibra.KalibraError, match="runs and steps"):
        kalibra.monte_carlo(*ARGS, runs=0)
    # Refused before a run is simulated (the evaluator's limits), not after 2^24 runs.
    with pytest.raises(kalibra.KalibraError, match="can be at most 16777216"):
        kalibra.monte_carlo(*ARGS, runs=2**24 + 1)
    with pytest.raises(kalibra.KalibraError, match="can be at most 16777216"):
        kalibra.monte_carlo(*ARGS, steps=2**40)
    with pytest.raises(kalibra.KalibraError, match="argument filter_R has shape"):
        kalibra.monte_carlo(*ARGS, filter_R=np.eye(2))
    with pytest.raises(kalibra.KalibraError, match="argument H has shape"):
        kalibra.monte_carlo(F, np.eye(3), Q, R, X0, P0)
    with pytest.raises(kalibra.KalibraError, match="confidence"):
        kalibra.monte_carlo(*ARGS, confidence=2.0)
