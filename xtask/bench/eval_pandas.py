"""The statistics of `kalibra eval`, written with pandas and numpy as a competent numpy user
would write them: the reference that `cargo xtask bench eval` times kalibra against, and whose
results it checks kalibra's report.json against (so both are known to have done the same work).

    python eval_pandas.py LOG.csv|LOG.npz|LOG.json --out RESULTS.json [--window W]
                          [--confidence C] [--lags L]

Reads the log in the layout `kalibra eval --help` documents (CSV with pandas.read_csv, NPZ
with numpy.load, JSON with the json module and numpy), restricted to what the benchmark
writes: every cell logged, full covariances, truth and innovations, at least two runs. Then,
vectorised over runs and steps (no Python loop over rows), with e = estimate - truth:

* per-step ANEES: mean over runs of NEES / n, NEES = e^T P^-1 e by a batched solve;
* per-step ANIS: the same with the innovation and its covariance S;
* per-step NCI (Li and Zhao 2006): mean over runs of 10 log10(NEES_i) - 10 log10(e_i^T
  Sigma_k^-1 e_i), Sigma_k = mean over runs of e e^T;
* per-step RMSE per component: sqrt(mean over runs of e_i^2);
* sliding-window RMSE, bias and standard deviation (divisor W - 1) of run 0's errors, window
  W = max(2, K // 10) unless given;
* overall ANEES and ANIS (mean over every cell), the mean NCI over steps, and the t statistic
  of the runs' time-averaged ANEES and ANIS against 1;
* the whiteness of run 0's normalised innovations w_k = L_k^-1 nu_k (S_k = L_k L_k^T): the
  sample autocorrelation at lags 1..L and the Box-Pierce statistic.

What differs from kalibra eval, on purpose:

* The chi-square bands of the per-step ANEES and ANIS use the Wilson-Hilferty approximation
  of the chi-square quantile (numpy has none, and SciPy is not installed); kalibra computes
  exact quantiles. The bench prints how far apart they are but does not require agreement.
* No p-values (they need the Student t and chi-square distributions), so no verdict.
* Sigma_k is inverted with numpy.linalg.inv (it has full rank in the benchmark's log), where
  kalibra takes a pseudo-inverse of Sigma_k scaled to unit diagonal; both agree for a
  full-rank Sigma_k.
* No checks of the covariances (kalibra leaves a non-positive-definite cell out as a finding),
  no figures, no report.md or report.html.

The results are written as JSON under the field names and shapes of kalibra's report.json, so
the bench compares the two with one JSON pointer per statistic.
"""

import argparse
import json
import os
import sys

import numpy as np
import pandas as pd

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from eval_stats import PER_CELL, evaluate  # noqa: E402  (the statistics, shared with eval_polars.py)


def load_csv(path):
    """The per-cell arrays of a CSV log, placed by the run and step columns."""
    df = pd.read_csv(path)
    run = df["run"].to_numpy()
    step = df["step"].to_numpy()
    runs, steps = int(run.max()) + 1, int(step.max()) + 1
    n = sum(1 for c in df.columns if c.startswith("truth_"))
    m = sum(1 for c in df.columns if c.startswith("innovation_") and not c.startswith("innovation_cov_"))

    def block(prefix, dim, matrix):
        cols = (
            [f"{prefix}_{i}_{j}" for i in range(dim) for j in range(dim)]
            if matrix
            else [f"{prefix}_{i}" for i in range(dim)]
        )
        shape = (dim, dim) if matrix else (dim,)
        out = np.full((runs, steps) + shape, np.nan)
        out[run, step] = df[cols].to_numpy(np.float64).reshape((-1,) + shape)
        return out

    return {
        "truth": block("truth", n, False),
        "estimate": block("estimate", n, False),
        "covariance": block("covariance", n, True),
        "innovation": block("innovation", m, False),
        "innovation_cov": block("innovation_cov", m, True),
    }


def load_npz(path):
    with np.load(path) as npz:
        return {name: npz[name].astype(np.float64, copy=False) for name in PER_CELL}


def load_json(path):
    with open(path) as f:
        log = json.load(f)
    return {name: np.asarray(log[name], dtype=np.float64) for name in PER_CELL}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log")
    parser.add_argument("--out", required=True)
    parser.add_argument("--window", type=int)
    parser.add_argument("--confidence", type=float, default=0.95)
    parser.add_argument("--lags", type=int, default=10)
    args = parser.parse_args()
    ext = args.log.rsplit(".", 1)[-1].lower()
    loaders = {"csv": load_csv, "npz": load_npz, "json": load_json}
    if ext not in loaders:
        parser.error(f"{args.log}: unknown extension .{ext} (csv, npz, json)")
    arrays = loaders[ext](args.log)
    steps = arrays["truth"].shape[1]
    window = args.window or max(2, steps // 10)
    results = evaluate(arrays, window, args.confidence, args.lags)
    with open(args.out, "w") as f:
        json.dump(results, f)


if __name__ == "__main__":
    main()
