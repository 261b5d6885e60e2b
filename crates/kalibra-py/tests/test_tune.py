"""kalibra.sweep_q: the same sweep and report as `kalibra tune` on the same model and data."""

import json
import subprocess

import numpy as np
import pytest

import kalibra

from conftest import FIXTURES


def load_fixture():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    model = tomllib.loads((FIXTURES / "tune_model.toml").read_text())
    z = np.genfromtxt(FIXTURES / "tune_measurements.csv", delimiter=",", skip_header=1)[:, 1:]
    x = np.genfromtxt(FIXTURES / "tune_truth.csv", delimiter=",", skip_header=1)[:, 1:]
    return model, z, x


def test_sweep_equals_the_cli_report_file_for_file(kalibra_cli, tmp_path):
    model, z, x = load_fixture()
    args = ["--p", "-4:2:0.5"]
    done = subprocess.run(
        [
            kalibra_cli, "tune", str(FIXTURES / "tune_model.toml"),
            str(FIXTURES / "tune_measurements.csv"), "--truth", str(FIXTURES / "tune_truth.csv"),
            "--out", str(tmp_path / "cli"), *args,
        ],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    report = kalibra.sweep_q(
        model["F"], model["H"], model["Q"], model["R"], model["x0"], model["P0"], z,
        p=(-4, 2, 0.5), truth=x, position=model["position"],
        names=("tune_model.toml", "tune_measurements.csv"),
    )
    report.save(tmp_path / "py")
    cli_files = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert cli_files == sorted(p.name for p in (tmp_path / "py").iterdir())
    assert "rmse.svg" in cli_files
    for name in cli_files:
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name
    expected = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert report.to_dict() == expected
    assert done.stdout.splitlines()[0] == report.headline
    np.testing.assert_array_equal(report.p, [pt["p"] for pt in expected["points"]])
    np.testing.assert_array_equal(report.j1, [pt["j1"] for pt in expected["points"]])
    if expected["crossover"] is not None:
        assert report.crossover == expected["crossover"]
        np.testing.assert_array_equal(report.recommended_q, expected["recommended_q"])


def test_results_do_not_depend_on_threads():
    model, z, _ = load_fixture()
    args = (model["F"], model["H"], model["Q"], model["R"], model["x0"], model["P0"], z)
    assert kalibra.sweep_q(*args, threads=1).to_dict() == kalibra.sweep_q(*args, threads=2).to_dict()


def test_sweep_errors_name_the_argument():
    F, H, Q, R = np.eye(2), np.array([[1.0, 0.0]]), np.eye(2), np.eye(1)
    z = np.ones((10, 1))
    with pytest.raises(kalibra.KalibraError, match="R"):
        kalibra.sweep_q(F, H, Q, np.eye(2), np.zeros(2), np.eye(2), z)
    with pytest.raises(kalibra.KalibraError, match="argument p"):
        kalibra.sweep_q(F, H, Q, R, np.zeros(2), np.eye(2), z, p=(1, 0, 0.5))
    with pytest.raises(kalibra.KalibraError, match="argument measurements has shape"):
        kalibra.sweep_q(F, H, Q, R, np.zeros(2), np.eye(2), np.ones(10))
    with pytest.raises(kalibra.KalibraError, match="Q_nom"):
        kalibra.sweep_q(F, H, -Q, R, np.zeros(2), np.eye(2), z)
