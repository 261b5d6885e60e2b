"""pykalman's EM on the model of `cargo xtask bench tune`: its reference per iteration.

    python tune_pykalman.py MODEL.json MEASUREMENTS.f64 STEPS ITERATIONS REPEATS OUT.json

MODEL.json holds F, H, x0, P0 and the starting covariances q_start, r_start (nested lists);
MEASUREMENTS.f64 the STEPS x m measurements as little-endian float64. `KalmanFilter.em(Z,
n_iter=ITERATIONS, em_vars=["transition_covariance", "observation_covariance"])` estimates a
full Q and a full R (x0, P0 known, the prior at the first measurement: kalibra's
`Start::UpdateFirst`), timed REPEATS times, the shortest kept; then the log-likelihood of the
estimate (`loglikelihood(Z)`, outside the timing). Writes OUT.json with the seconds, the
iterations, Q, R, the log-likelihood and the versions.

The bench creates the virtual environment and installs pykalman 0.11.2 (with numpy), the
version the fixture of crates/kalibra-tune/tests/em_pykalman.rs was written with.
"""

import json
import sys
import time

import numpy as np
import pykalman
from pykalman import KalmanFilter


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    model_path, z_path, steps, iterations, repeats, out = sys.argv[1:]
    steps, iterations, repeats = int(steps), int(iterations), int(repeats)
    with open(model_path) as f:
        model = {k: np.array(v, dtype=float) for k, v in json.load(f).items()}
    n, m = model["F"].shape[0], model["H"].shape[0]
    z = np.fromfile(z_path, dtype="<f8").reshape(steps, m)
    best, kf = None, None
    for _ in range(repeats):
        kf = KalmanFilter(
            transition_matrices=model["F"], observation_matrices=model["H"],
            transition_covariance=model["q_start"], observation_covariance=model["r_start"],
            transition_offsets=np.zeros(n), observation_offsets=np.zeros(m),
            initial_state_mean=model["x0"], initial_state_covariance=model["P0"],
        )
        start = time.perf_counter()
        kf = kf.em(z, n_iter=iterations,
                   em_vars=["transition_covariance", "observation_covariance"])
        seconds = time.perf_counter() - start
        best = seconds if best is None else min(best, seconds)
    report = {
        "seconds": best,
        "iterations": iterations,
        "repeats": repeats,
        "Q": kf.transition_covariance.tolist(),
        "R": kf.observation_covariance.tolist(),
        "loglike": float(kf.loglikelihood(z)),
        "versions": (
            f"Python {sys.version.split()[0]}, pykalman {pykalman.__version__}, "
            f"numpy {np.__version__}"
        ),
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
