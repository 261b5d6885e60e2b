"""Shared fixtures: the repository's committed filter log and the `kalibra` executable."""

import os
import pathlib
import shutil

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
FIXTURES = REPO / "crates" / "kalibra-cli" / "tests" / "fixtures"


@pytest.fixture
def kf_npz():
    """The path of kf.npz: 4 runs x 25 steps of a CV Kalman filter (n = 4, m = 2) with
    steps without a measurement (NaN innovation cells), time and F, H, Q, R."""
    return FIXTURES / "kf.npz"


@pytest.fixture
def kf_arrays(kf_npz):
    with np.load(kf_npz) as archive:
        return {name: archive[name] for name in archive.files}


@pytest.fixture
def kalibra_cli():
    """The `kalibra` executable: $KALIBRA_CLI (set by .ci/run, which builds it), else the
    workspace's debug build, else one on PATH; skipped when none is there."""
    given = os.environ.get("KALIBRA_CLI")
    if given:
        assert pathlib.Path(given).is_file(), f"KALIBRA_CLI={given} does not exist"
        return given
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for candidate in (target / "debug" / "kalibra", target / "release" / "kalibra"):
        if candidate.is_file():
            return str(candidate)
    found = shutil.which("kalibra")
    if found is None:
        pytest.skip("no kalibra executable (cargo build -p kalibra-cli)")
    return found
