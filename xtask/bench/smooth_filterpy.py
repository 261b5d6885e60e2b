"""FilterPy's Kalman smoother on W1's model: the reference of `cargo xtask bench smooth`.

    python smooth_filterpy.py MODEL.json MEASUREMENTS.f64 RUNS STEPS TIMED OUT_PREFIX

MODEL.json holds F, H, Q, R, x0 and P0 as nested lists; MEASUREMENTS.f64 the RUNS x STEPS x m
measurements as little-endian float64. The first TIMED runs are filtered with
`KalmanFilter.batch_filter` (predict, then update, at every row: kalibra's "predict_first")
and smoothed with `KalmanFilter.rts_smoother`, one run at a time; the wall time of those runs
is measured together. Writes OUT_PREFIX.json ({"seconds": ..., "runs_timed": ...,
"versions": ...}) and the smoothed means and covariances of the timed runs to
OUT_PREFIX.means.f64 (TIMED x STEPS x n) and OUT_PREFIX.covs.f64 (TIMED x STEPS x n x n).

The bench creates the virtual environment and installs the versions it was written
against: filterpy 2.0.0 and numpy (2.x when written).
"""

import json
import sys
import time

import filterpy
import numpy as np
from filterpy.kalman import KalmanFilter


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    model_path, z_path, runs, steps, timed, out = sys.argv[1:]
    runs, steps, timed = int(runs), int(steps), int(timed)
    with open(model_path) as f:
        model = {k: np.array(v, dtype=float) for k, v in json.load(f).items()}
    n, m = model["F"].shape[0], model["H"].shape[0]
    z = np.fromfile(z_path, dtype="<f8").reshape(runs, steps, m)
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.F, kf.H, kf.Q, kf.R = model["F"], model["H"], model["Q"], model["R"]
    means = np.empty((timed, steps, n))
    covs = np.empty((timed, steps, n, n))
    start = time.perf_counter()
    for r in range(timed):
        kf.x, kf.P = model["x0"].copy(), model["P0"].copy()
        mu, cov, _, _ = kf.batch_filter(z[r])
        xs, ps, _, _ = kf.rts_smoother(mu, cov)
        means[r], covs[r] = xs, ps
    seconds = time.perf_counter() - start
    means.astype("<f8").tofile(out + ".means.f64")
    covs.astype("<f8").tofile(out + ".covs.f64")
    versions = (
        f"Python {sys.version.split()[0]}, numpy {np.__version__}, "
        f"filterpy {filterpy.__version__}"
    )
    with open(out + ".json", "w") as f:
        json.dump({"seconds": seconds, "runs_timed": timed, "versions": versions}, f)


if __name__ == "__main__":
    main()
