"""kalibra.estimate_noise: Q and R from measurements, against the committed statsmodels and
pykalman fixtures of crates/kalibra-tune and the Kalman filter's own log-likelihood."""

import json

import numpy as np
import pytest

import kalibra

from conftest import FIXTURES, REPO

TUNE_FIXTURES = REPO / "crates" / "kalibra-tune" / "tests" / "fixtures"


def statsmodels_fixture():
    """A constant-velocity target, noise through G, a scaled Qw and a full R, three steps
    missing; statsmodels 0.15's loglike and fit (written by make_statsmodels.py)."""
    fx = json.loads((TUNE_FIXTURES / "statsmodels.json").read_text())
    z = np.array([[np.nan, np.nan] if z is None else z for z in fx["measurements"]])
    return fx, z


@pytest.fixture(scope="module")
def statsmodels_ml():
    """The fixture and its ML estimate, computed once (the slowest call of this file)."""
    fx, z = statsmodels_fixture()
    return fx, z, kalibra.estimate_noise(fx["F"], fx["H"], z, profile=False,
                                         **statsmodels_problem(fx))


def statsmodels_problem(fx):
    return dict(
        Q=("scaled", [[1.0]]), R=("full", np.eye(2)), G=fx["G"], x0=fx["x0"], P0=fx["P0"],
        start="update_first",
    )


def random_walk(steps=400, q=0.5, r=2.0, seed=7, runs=None):
    rng = np.random.default_rng(seed)
    shape = (steps,) if runs is None else (runs, steps)
    x = np.cumsum(rng.normal(0.0, np.sqrt(q), shape), axis=-1)
    return (x + rng.normal(0.0, np.sqrt(r), shape))[..., None]


def kf_log_likelihood(F, H, Q, R, x0, P0, z, start):
    out = kalibra.KalmanFilter(F, H, Q, R, x0, P0, start=start).run(z)
    return float(np.nansum(out["log_likelihood"]))


def test_ml_equals_statsmodels_fit(statsmodels_ml):
    """The ML estimate equals statsmodels' fitted one to the optimisers' tolerance (1e-4
    relative, as the Rust test of the same fixture argues), with its standard errors."""
    fx, _, est = statsmodels_ml
    assert est.method == "ml" and est.converged
    names = [p["name"] for p in est.parameters]
    assert names == ["q", "R[0,0]", "R[1,0]", "R[1,1]"] == fx["names"]
    for p, expected, bse in zip(est.parameters, fx["fit"]["params"], fx["fit"]["bse_approx"]):
        assert p["value"] == pytest.approx(expected, rel=1e-4), p["name"]
        assert p["stderr"] == pytest.approx(bse, rel=1e-3), p["name"]
        lo, hi = p["ci95"]
        assert lo < p["value"] < hi
    assert est.log_likelihood == pytest.approx(fx["fit"]["loglike"], abs=1e-6)
    q, r00, r10, r11 = (p["value"] for p in est.parameters)
    np.testing.assert_allclose(est.Qw, [[q]], rtol=1e-12)
    np.testing.assert_allclose(est.Q, np.array(fx["G"]) @ [[q]] @ np.array(fx["G"]).T, rtol=1e-12)
    np.testing.assert_allclose(est.R, [[r00, r10], [r10, r11]], rtol=1e-12)
    ident = est.identifiable
    assert ident["rank"] == ident["parameters"] == 4 and ident["unidentifiable"] == []
    assert ident["source"] == "observed information"


def test_log_likelihood_is_the_kalman_filter_s(statsmodels_ml):
    """The reported log-likelihood is the sum of KalmanFilter.run's per-update log-densities
    at the estimated Q and R (another path through the library), and the fixture's
    statsmodels loglike at the starting point."""
    fx, z, est = statsmodels_ml
    ours = kf_log_likelihood(fx["F"], fx["H"], est.Q, est.R, fx["x0"], fx["P0"], z, "update_first")
    assert est.log_likelihood == pytest.approx(ours, rel=1e-12)
    start = fx["loglike_at"][0]
    assert start["params"] == [1.0, 1.0, 0.0, 1.0]
    assert est.start_log_likelihood == pytest.approx(start["loglike"], rel=1e-9)


def test_em_equals_pykalman_after_ten_iterations():
    """method="em" with iterations=10 runs exactly ten iterations and equals pykalman's EM
    (the committed fixture the Rust test reads) to 1e-9 relative."""
    fx = json.loads((TUNE_FIXTURES / "pykalman_em.json").read_text())
    z = np.array([[np.nan, np.nan] if z is None else z for z in fx["z"]])
    est = kalibra.estimate_noise(
        fx["f"], fx["h"], z, Q=("full", fx["q_start"]), R=("full", fx["r_start"]),
        x0=fx["x0"], P0=fx["p0"], start="update_first", method="em", iterations=10,
        profile=False,
    )
    assert est.method == "em" and est.iterations == 10 and est.converged
    for ours, theirs in ((est.Q, fx["q"][-1]), (est.R, fx["r"][-1])):
        theirs = np.array(theirs)
        assert np.abs(ours - theirs).max() <= 1e-9 * np.abs(theirs).max()
    assert est.log_likelihood == pytest.approx(fx["log_likelihood"][-1], rel=1e-9)
    assert len(est.parameters) == 6 + 3


def test_every_method_on_runs_of_a_random_walk():
    """Each estimator on 8 runs of a random walk (q = 0.5, r = 2): every estimate is near the
    truth, ML and EM reach the same maximum, and the log-likelihoods are the filter's."""
    z = random_walk(steps=300, runs=8)
    args = dict(Q=("scaled", [[1.0]]), R=("diagonal", [[1.0]]), x0=[0.0], P0=[[1.0]],
                start="update_first")
    results = {m: kalibra.estimate_noise([[1.0]], [[1.0]], z, method=m, **args)
               for m in ("ml", "em", "als")}
    for method, est in results.items():
        q, r = (p["value"] for p in est.parameters)
        assert 0.35 < q < 0.7 and 1.6 < r < 2.5, (method, q, r)
        assert est.log_likelihood == pytest.approx(
            kf_log_likelihood([[1.0]], [[1.0]], est.Q, est.R, [0.0], [[1.0]], z, "update_first"),
            rel=1e-12)
    ml, em = results["ml"], results["em"]
    assert em.log_likelihood == pytest.approx(ml.log_likelihood, abs=1e-3)
    assert [p["name"] for p in ml.parameters] == ["q", "R[0,0]"]
    als = results["als"]
    assert als.identifiable["rank"] == 2 and als.iterations == 0
    assert all(p["ci95"] is None for p in als.parameters)
    # The filter with each estimate and with the starting guess, judged on the data.
    for est in results.values():
        for which in ("estimate", "start"):
            anis = est.consistency[which]["anis"]
            assert anis["statistic"] == "anis" and anis["samples"] == z.shape[0] * z.shape[1]
    sweep = kalibra.estimate_noise([[1.0]], [[1.0]], z, method="j1j2", p=(-2, 2, 0.5), **args)
    curves = sweep.to_dict()["curves"]
    assert [len(c["points"]) for c in curves] == [9, 9]
    # At p = 0 both curves pass through the starting point.
    assert curves[0]["points"][4]["j1"] == curves[1]["points"][4]["j1"]
    # Each parameter moves to its own crossover (from its start, 1), or stays without one.
    for p, c in zip(sweep.parameters, curves):
        crossing = c["crossover"]["value"] if c["crossover"] else 1.0
        assert p["value"] == pytest.approx(crossing, rel=1e-12)
        assert p["stderr"] is None


def test_single_run_and_batch_of_one_agree():
    z = random_walk(steps=200)
    args = dict(Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]])
    one = kalibra.estimate_noise([[1.0]], [[1.0]], z, **args).to_dict()
    batch = kalibra.estimate_noise([[1.0]], [[1.0]], z[None], **args).to_dict()
    assert one == batch


def test_fixed_entries_and_dict_spelling():
    """A full R with its correlation fixed at 0: only the variances are free; the dict and the
    three-tuple spellings are the same problem."""
    rng = np.random.default_rng(11)
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    x, zs = np.zeros(2), []
    for _ in range(300):
        x = F @ x + rng.multivariate_normal(np.zeros(2), 0.01 * np.eye(2))
        zs.append(x + rng.normal(0.0, [1.0, 0.5]))
    z = np.array(zs)
    common = dict(Q=("scaled", 0.01 * np.eye(2)), x0=np.zeros(2), P0=10 * np.eye(2))
    a = kalibra.estimate_noise(F, np.eye(2), z, R=("full", np.eye(2), [(1, 0)]), **common)
    b = kalibra.estimate_noise(
        F, np.eye(2), z, R={"form": "full", "value": np.eye(2), "fixed": [(0, 1)]}, **common)
    assert [p["name"] for p in a.parameters] == ["q", "R[0,0]", "R[1,1]"]
    assert a.to_dict() == b.to_dict()
    assert a.R[0, 1] == a.R[1, 0] == 0.0
    # A plain matrix is fixed: nothing of R is estimated.
    c = kalibra.estimate_noise(F, np.eye(2), z, R=np.diag([1.0, 0.25]), **common)
    assert [p["name"] for p in c.parameters] == ["q"]
    np.testing.assert_array_equal(c.R, np.diag([1.0, 0.25]))


def test_unidentifiable_parametrisation_is_named():
    """Q's two variances of a random walk seen through their sum: the data identify only the
    sum, and the estimate says so instead of answering silently."""
    rng = np.random.default_rng(5)
    z = np.cumsum(rng.normal(0.0, 1.0, 300))[:, None] + rng.normal(0.0, 1.0, (300, 1))
    est = kalibra.estimate_noise(
        np.eye(2), [[1.0, 1.0]], z, Q=("diagonal", np.eye(2)), R=[[1.0]], x0=np.zeros(2),
        P0=np.eye(2))
    ident = est.identifiable
    assert ident["rank"] == 1 and ident["parameters"] == 2
    assert ident["unidentifiable"] and "Qw[0,0]" in ident["unidentifiable"][0]
    assert any("identif" in w for w in est.warnings)


@pytest.mark.parametrize(
    "change, argument, match",
    [
        (dict(Q=("diag", [[1.0]])), "Q", "form \"diag\" is not one of"),
        (dict(R={"form": "full", "value": [[1.0]], "scale": 2}), "R", "unknown key"),
        (dict(R=("scaled", [[1.0]], [(0, 0)])), "R", "scaled form"),
        (dict(Q=("diagonal", [[1.0, 0.5], [0.5, 1.0]])), "Q", "diagonal form"),
        (dict(Q=("full", np.eye(3)), R=[[1.0]], F=np.eye(3), H=np.ones((1, 3)),
              x0=np.zeros(3), P0=np.eye(3)), None, "identify at most"),
        (dict(F=np.eye(2)), "F", "F is 2x2"),
        (dict(P0=[[np.nan]]), "P0", "P0"),
        (dict(F=[[np.inf]]), "F", "non-finite"),
        (dict(x0=[[0.0]]), "x0", "shape"),
        (dict(z=np.ones((10, 2))), "measurements", "shape"),
        (dict(z=np.array([[1.0], [np.inf]])), "measurements", "step 1 holds an infinity"),
        (dict(z=np.full((4, 1), np.nan)), "measurements", "no measurements"),
        (dict(method="mle"), "method", "expected one of"),
        (dict(method="em", lags=5), "lags", "applies to method"),
        (dict(start="first"), "start", "predict_first"),
        (dict(G=np.ones((1, 2))), "G", "G"),
    ],
)
def test_bad_input_names_the_argument(change, argument, match):
    args = dict(F=[[1.0]], H=[[1.0]], z=random_walk(steps=50), Q=("scaled", [[1.0]]),
                R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]])
    args.update(change)
    F, H, z = args.pop("F"), args.pop("H"), args.pop("z")
    with pytest.raises(kalibra.KalibraError, match=match) as info:
        kalibra.estimate_noise(F, H, z, **args)
    assert info.value.argument == argument
    if argument == "measurements" and "step" in match:
        assert info.value.step == 1


def test_als_refuses_a_gap():
    z = random_walk(steps=100)
    z[30] = np.nan
    with pytest.raises(kalibra.KalibraError, match="by als: .*step 30"):
        kalibra.estimate_noise([[1.0]], [[1.0]], z, Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]),
                               x0=[0.0], P0=[[1.0]], method="als")


def test_save_writes_report_json(tmp_path, statsmodels_ml):
    """save(dir) writes report.json, readable by json.load, with the documented fields."""
    _, _, est = statsmodels_ml
    est.save(tmp_path / "out")
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert {"method", "log_likelihood", "Q", "Qw", "R", "parameters", "converged",
            "iterations", "identifiable", "consistency", "warnings"} <= set(report)
    assert report["method"] == "ml"
    assert report["log_likelihood"] == est.log_likelihood
    np.testing.assert_array_equal(report["Q"], est.Q)
    np.testing.assert_array_equal(report["Qw"], est.Qw)
    np.testing.assert_array_equal(report["R"], est.R)
    assert report["converged"] is True and report["iterations"] == est.iterations
    assert report["identifiable"]["rank"] == 4
    for row, p in zip(report["parameters"], est.parameters):
        assert set(row) >= {"name", "value", "stderr", "ci95"}
        assert row["name"] == p["name"] and row["value"] == p["value"]
        assert tuple(row["ci95"]) == p["ci95"]
    assert report == est.to_dict()


def test_estimation_releases_the_gil():
    """Another Python thread keeps running while the estimator works (the GIL is released
    after the arguments are read)."""
    from test_gil import longest_pause_while

    z = random_walk(steps=1000, runs=2)
    duration, pause = longest_pause_while(lambda: kalibra.estimate_noise(
        [[1.0]], [[1.0]], z, Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]), x0=[0.0],
        P0=[[1.0]], profile=False))
    assert pause < duration / 3, (duration, pause)


def test_truth_adds_anees_and_rmse_and_profiles_bracket_the_estimate():
    """With the truth, the filter with the estimate gets ANEES and RMSE beside the starting
    guess's; each parameter's profile likelihood peaks at the estimate and its likelihood-ratio
    interval lies about the value."""
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0.0, np.sqrt(0.5), (2, 300)), axis=1)
    z = (x + rng.normal(0.0, np.sqrt(2.0), x.shape))[..., None]
    est = kalibra.estimate_noise([[1.0]], [[1.0]], z, Q=("scaled", [[0.01]]),
                                 R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]],
                                 start="update_first", truth=x[..., None])
    tuned, guess = est.consistency["estimate"], est.consistency["start"]
    assert tuned["anees"]["statistic"] == "anees" and tuned["rmse"] is not None
    # The starting q is 50 times too small: the tuned filter's error is smaller.
    assert tuned["rmse"] < guess["rmse"]
    for p in est.parameters:
        prof = p["profile"]
        best = max(pt["log_likelihood"] for pt in prof["points"])
        assert best == pytest.approx(est.log_likelihood, abs=1e-6)
        lo, hi = prof["interval"]
        assert lo < p["value"] < hi
        assert prof["threshold"] == pytest.approx(est.log_likelihood - 1.9207294103470620)
    with pytest.raises(kalibra.KalibraError, match="argument truth") as info:
        kalibra.estimate_noise([[1.0]], [[1.0]], z, Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]),
                               x0=[0.0], P0=[[1.0]], truth=x[:1, :, None], profile=False)
    assert info.value.argument == "truth"
    with pytest.raises(kalibra.KalibraError, match="argument truth has shape"):
        kalibra.estimate_noise([[1.0]], [[1.0]], z, Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]),
                               x0=[0.0], P0=[[1.0]], truth=np.zeros((2, 300, 2)))


def test_callables_through_the_ekf_and_the_ukf_equal_the_linear_estimate():
    """A linear model given as callables: the EKF's and the UKF's likelihoods are the Kalman
    filter's, so their ML estimates equal the linear one to the optimiser's tolerance."""
    z = random_walk(steps=150, seed=9)
    args = dict(Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]],
                profile=False)
    linear = kalibra.estimate_noise([[1.0]], [[1.0]], z, **args)
    f = lambda x, k: x
    one = lambda x, k: np.eye(1)
    ekf = kalibra.estimate_noise(f, f, z, F_jacobian=one, H_jacobian=one, **args)
    ukf = kalibra.estimate_noise(f, f, z, kind="ukf", **args)
    for est in (ekf, ukf):
        assert est.method == "ml" and est.converged
        assert est.log_likelihood == pytest.approx(linear.log_likelihood, abs=1e-6)
        for p, q in zip(est.parameters, linear.parameters):
            assert p["name"] == q["name"]
            assert p["value"] == pytest.approx(q["value"], rel=1e-4)
            assert p["stderr"] == pytest.approx(q["stderr"], rel=1e-2)
        assert any("quasi-likelihood" in w for w in est.warnings)
    with pytest.raises(kalibra.KalibraError, match="F_jacobian and H_jacobian are required"):
        kalibra.estimate_noise(f, f, z, **args)
    with pytest.raises(kalibra.KalibraError, match="\"ml\" only") as info:
        kalibra.estimate_noise(f, f, z, method="em", kind="ukf", **args)
    assert info.value.argument == "method"

    def broken(x, k):
        raise RuntimeError("model failed")

    with pytest.raises(kalibra.KalibraError, match="model failed"):
        kalibra.estimate_noise(broken, f, z, kind="ukf", **args)


def test_callables_report_has_profiles_consistency_and_saves_the_full_report(tmp_path):
    """A model given as callables gets the linear report: a profile per parameter holding the
    estimate, the EKF judged with the estimate and with the starting guess (with the truth,
    ANEES and RMSE too), and save(dir) writes report.json, report.md and report.html."""
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.normal(0.0, np.sqrt(0.5), 120))
    z = (x + rng.normal(0.0, np.sqrt(2.0), x.shape))[:, None]
    f = lambda x, k: x
    one = lambda x, k: np.eye(1)
    est = kalibra.estimate_noise(f, f, z, F_jacobian=one, H_jacobian=one, Q=("scaled", [[0.05]]),
                                 R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]],
                                 truth=x[:, None], names=("walk", "z"))
    for p in est.parameters:
        lo, hi = p["profile"]["interval"]
        assert lo < p["value"] < hi
    for which in ("estimate", "start"):
        check = est.consistency[which]
        assert check["anis"]["statistic"] == "anis" and check["whiteness"] is not None
        assert check["rmse"] is not None
    assert est.to_dict()["problem"]["filter"] == "ekf"
    est.save(tmp_path / "out")
    files = {p.name for p in (tmp_path / "out").iterdir()}
    assert {"report.json", "report.md", "report.html"} <= files
    assert "extended Kalman filter" in (tmp_path / "out" / "report.md").read_text()
    assert json.loads((tmp_path / "out" / "report.json").read_text()) == est.to_dict()
    quick = kalibra.estimate_noise(f, f, z, kind="ukf", Q=("scaled", [[0.05]]),
                                   R=("scaled", [[1.0]]), x0=[0.0], P0=[[1.0]], profile=False)
    assert all(p["profile"] is None for p in quick.parameters)
    assert quick.consistency["estimate"]["anis"] is not None


def test_save_is_kalibra_tune_s_report_file_for_file(kalibra_cli, tmp_path):
    """save(dir) on the CLI's noise fixture writes what `kalibra tune --method ml --out` does,
    byte for byte (the same estimator, report and writer)."""
    import subprocess

    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    model = tomllib.loads((FIXTURES / "noise_model.toml").read_text())
    z = np.genfromtxt(FIXTURES / "noise_measurements.csv", delimiter=",", skip_header=1)[:, 1:]
    done = subprocess.run(
        [kalibra_cli, "tune", str(FIXTURES / "noise_model.toml"),
         str(FIXTURES / "noise_measurements.csv"), "--method", "ml", "--out", str(tmp_path / "cli")],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    est = kalibra.estimate_noise(
        model["F"], model["H"], z, G=model["G"], x0=model["x0"], P0=model["P0"],
        Q=(model["Q"]["form"], model["Q"]["value"]), R=(model["R"]["form"], model["R"]["value"]),
        names=("noise_model.toml", "noise_measurements.csv"),
    )
    est.save(tmp_path / "py")
    cli_files = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert cli_files == sorted(p.name for p in (tmp_path / "py").iterdir())
    assert {"report.json", "report.md", "report.html"} <= set(cli_files)
    for name in cli_files:
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name
    assert est.to_dict() == json.loads((tmp_path / "cli" / "report.json").read_text())
