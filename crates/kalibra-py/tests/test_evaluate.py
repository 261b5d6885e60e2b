"""kalibra.evaluate: the same report as `kalibra eval` on the same log, and the same numbers
as a plain numpy computation."""

import json
import subprocess

import numpy as np
import pytest

import kalibra


def numpy_nees(truth, estimate, covariance):
    e = estimate - truth
    return np.einsum("...i,...i->...", e, np.linalg.solve(covariance, e[..., None])[..., 0])


def test_report_equals_the_cli_report_file_for_file(kf_npz, kf_arrays, kalibra_cli, tmp_path):
    cli_dir = tmp_path / "cli"
    done = subprocess.run(
        [kalibra_cli, "eval", str(kf_npz), "--out", str(cli_dir)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    report = kalibra.evaluate(**kf_arrays, name="kf.npz")
    py_dir = tmp_path / "py"
    report.save(py_dir)
    cli_files = sorted(p.name for p in cli_dir.iterdir())
    assert cli_files == sorted(p.name for p in py_dir.iterdir())
    assert {"report.json", "report.md", "report.html", "anees.svg", "j1j2.svg"} <= set(cli_files)
    for name in cli_files:
        assert (py_dir / name).read_bytes() == (cli_dir / name).read_bytes(), name
    assert report.to_dict() == json.loads((cli_dir / "report.json").read_text())
    assert report.to_json() + "\n" == (cli_dir / "report.json").read_text()
    assert report.markdown() == (cli_dir / "report.md").read_text()
    assert report.html() == (cli_dir / "report.html").read_text()
    assert done.stdout.splitlines()[0] == report.headline


def test_options_reach_the_evaluation_as_on_the_command_line(
    kf_npz, kf_arrays, kalibra_cli, tmp_path
):
    args = ["--confidence", "0.9", "--window", "5", "--lags", "4", "--group", "pos=0,1"]
    done = subprocess.run(
        [kalibra_cli, "eval", str(kf_npz), "--out", str(tmp_path / "cli"), *args],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    report = kalibra.evaluate(
        **kf_arrays, confidence=0.9, window=5, lags=4, groups={"pos": [0, 1]}
    )
    expected = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert report.to_dict() == expected
    assert [s["name"] for s in expected["rmse_per_step"]][-1] == "pos"


def test_evaluate_agrees_with_numpy(kf_arrays):
    a = kf_arrays
    d = kalibra.evaluate(
        truth=a["truth"],
        estimate=a["estimate"],
        covariance=a["covariance"],
        innovation=a["innovation"],
        innovation_cov=a["innovation_cov"],
    ).to_dict()
    runs, steps, n = a["truth"].shape
    m = a["innovation"].shape[-1]
    nees = numpy_nees(a["truth"], a["estimate"], a["covariance"])
    np.testing.assert_allclose(d["anees_per_step"], nees.mean(axis=0) / n, rtol=1e-12)
    nis = numpy_nees(np.zeros_like(a["innovation"]), a["innovation"], a["innovation_cov"])
    logged = ~np.isnan(nis)
    anis = np.array(
        [nis[logged[:, k], k].mean() / m if logged[:, k].any() else np.nan for k in range(steps)]
    )
    got = np.array([np.nan if v is None else v for v in d["anis_per_step"]])
    np.testing.assert_allclose(got, anis, rtol=1e-12)
    lower, upper = kalibra.chi2_band(n, runs, 0.95, normalized=True)
    assert d["anees_band"][0] == {"lower": lower, "upper": upper}
    # RMSE per component over runs, and NCI (Li and Zhao) against the MSE matrix over runs.
    e = a["estimate"] - a["truth"]
    rmse = np.sqrt((e**2).mean(axis=0))
    for i in range(n):
        np.testing.assert_allclose(d["rmse_per_step"][i]["values"], rmse[:, i], rtol=1e-12)
    np.testing.assert_allclose(kalibra.rmse(a["truth"], a["estimate"]), rmse, rtol=1e-12)
    mse = np.einsum("rki,rkj->kij", e, e) / runs
    star = numpy_nees(np.zeros_like(e), e, np.broadcast_to(mse, e.shape + (n,)))
    nci = (10 * np.log10(nees) - 10 * np.log10(star)).mean(axis=0)
    np.testing.assert_allclose(d["nci_per_step"], nci, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(
        kalibra.nci(a["truth"], a["estimate"], a["covariance"]), nci, rtol=1e-9, atol=1e-9
    )


def test_verdicts_follow_the_covariance():
    rng = np.random.default_rng(7)
    truth = np.zeros((200, 30, 3))
    estimate = rng.normal(size=truth.shape)
    eye = np.broadcast_to(np.eye(3), (200, 30, 3, 3))
    verdict = lambda c: kalibra.evaluate(truth=truth, estimate=estimate, covariance=c).verdict
    assert verdict(eye) == "consistent"
    assert verdict(0.5 * eye) == "optimistic"
    assert verdict(2.0 * eye) == "pessimistic"


def test_single_run_drops_the_run_axis(kf_arrays):
    a = {k: v[0] if k in ("truth", "estimate", "covariance") else v for k, v in kf_arrays.items()}
    d = kalibra.evaluate(truth=a["truth"], estimate=a["estimate"], covariance=a["covariance"]).to_dict()
    assert d["runs"] == 1
    n = a["truth"].shape[-1]
    np.testing.assert_allclose(
        d["anees_per_step"], numpy_nees(a["truth"], a["estimate"], a["covariance"]) / n, rtol=1e-12
    )


def test_all_nan_cells_were_not_logged_and_partly_nan_covariances_are_findings(kf_arrays):
    a = {k: kf_arrays[k].copy() for k in ("truth", "estimate", "covariance")}
    a["estimate"][1, 3] = np.nan  # all NaN: not logged
    a["covariance"][2, 5, 0, 0] = np.nan  # partly NaN: a finding
    d = kalibra.evaluate(**a).to_dict()
    state = d["findings"]["state"]
    assert state["cells"] == 1
    assert (state["first"]["run"], state["first"]["step"]) == (2, 5)
    nees = numpy_nees(a["truth"], a["estimate"], a["covariance"])
    expected = np.nanmean(nees[:, 3], axis=0) / 4
    assert d["anees_per_step"][3] == pytest.approx(expected, rel=1e-12)


def test_report_object():
    report = kalibra.evaluate(innovation=np.ones((2, 5, 1)), innovation_cov=np.ones((2, 5, 1, 1)))
    assert report.verdict in ("consistent", "optimistic", "pessimistic", "undetermined")
    assert "kalibra.Report" in repr(report)
    assert report._repr_html_().startswith("<!DOCTYPE html>")
    assert report.markdown().startswith("# kalibra report: numpy arrays")


def test_save_replaces_an_earlier_report_and_refuses_other_directories(tmp_path):
    report = kalibra.evaluate(innovation=np.ones((5, 1)), innovation_cov=np.ones((5, 1, 1)))
    out = tmp_path / "report"
    report.save(out)
    report.save(str(out))
    assert (out / "report.json").is_file()
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(OSError, match="holds no earlier report"):
        report.save(other)
    assert (other / "notes.txt").read_text() == "mine"


def test_arrays_read_in_place_keep_their_writeable_flag(kf_arrays):
    # A C-contiguous float64 array is read in place with the GIL released and set read-only
    # for the call only; a read-only one stays read-only, an array passed twice is restored
    # once, and a copied layout (Fortran order, float32) gives the same report.
    a = {k: kf_arrays[k].copy() for k in ("truth", "estimate", "covariance")}
    frozen = a["covariance"].copy()
    frozen.flags.writeable = False
    expected = kalibra.evaluate(**a).to_json()
    assert all(v.flags.writeable for v in a.values())
    assert kalibra.evaluate(truth=a["truth"], estimate=a["estimate"], covariance=frozen).to_json() == expected
    assert not frozen.flags.writeable
    kalibra.evaluate(truth=a["truth"], estimate=a["truth"], covariance=a["covariance"])
    assert a["truth"].flags.writeable
    a["truth"][0, 0, 0] += 0.0  # writeable again
    fortran = np.asfortranarray(a["covariance"])
    assert kalibra.evaluate(truth=a["truth"], estimate=a["estimate"], covariance=fortran).to_json() == expected
    assert fortran.flags.writeable
    # An error raised after the arrays were taken leaves them writeable too.
    with pytest.raises(kalibra.KalibraError):
        kalibra.evaluate(truth=a["truth"], estimate=a["estimate"][:, :-1], covariance=a["covariance"])
    assert a["truth"].flags.writeable and a["estimate"].flags.writeable
