"""The statistics of `kalibra eval` with polars reading the log and numpy computing, as a
competent user of both would write them: the second reference of `cargo xtask bench eval`
(beside eval_pandas.py), checked against kalibra's report.json the same way.

    python eval_polars.py LOG.csv|LOG.npz|LOG.json --out RESULTS.json [--window W]
                          [--confidence C] [--lags L]

Reading: the CSV with polars.read_csv (multi-threaded), placed by the run and step columns;
the JSON with polars.read_json, each nested list column flattened by `explode` into one
numpy array; the NPZ with numpy.load (polars has no NPZ reader). Computing: the same
statistics as eval_pandas.py (its docstring lists them and what differs from kalibra on
purpose), vectorised over runs and steps with no Python loop over cells, but with the
quadratic forms x^T P^-1 x through a batched Cholesky factorisation (numpy.linalg.cholesky
over every cell at once) and a forward substitution vectorised over the cells (a loop over
the n components, not the cells): ||L^-1 x||^2. Sigma_k is inverted per step as in the
pandas script. Everything after reading is eval_stats.py's, shared with eval_pandas.py, so
the two scripts differ only in reading and in the quadratic forms.
"""

import argparse
import json
import os
import sys

import numpy as np
import polars as pl

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from eval_stats import PER_CELL, evaluate  # noqa: E402  (the statistics, shared with eval_pandas.py)


def load_csv(path):
    """The per-cell arrays of a CSV log, placed by the run and step columns."""
    df = pl.read_csv(path)
    run = df.get_column("run").to_numpy()
    step = df.get_column("step").to_numpy()
    runs, steps = int(run.max()) + 1, int(step.max()) + 1
    n = sum(1 for c in df.columns if c.startswith("truth_"))
    m = sum(
        1 for c in df.columns if c.startswith("innovation_") and not c.startswith("innovation_cov_")
    )

    def block(prefix, dim, matrix):
        cols = (
            [f"{prefix}_{i}_{j}" for i in range(dim) for j in range(dim)]
            if matrix
            else [f"{prefix}_{i}" for i in range(dim)]
        )
        shape = (dim, dim) if matrix else (dim,)
        out = np.full((runs, steps) + shape, np.nan)
        out[run, step] = df.select(cols).to_numpy().astype(np.float64, copy=False).reshape(
            (-1,) + shape
        )
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
    """Each array is a list column of a one-row frame: the first list's length at each level
    gives the shape (the bench's logs are rectangular, every cell logged), and exploding the
    column level by level gives the values in C order."""
    df = pl.read_json(path)
    out = {}
    for name in PER_CELL:
        s = df.get_column(name)
        shape = []
        while s.dtype.base_type() == pl.List:
            shape.append(int(s.list.len()[0]))
            s = s.explode()
        out[name] = s.to_numpy().astype(np.float64, copy=False).reshape(shape)
    return out


def quad_forms(x, cov):
    """x^T cov^-1 x for every run and step: cov = L L^T by a batched Cholesky, then
    w = L^-1 x by forward substitution over the components, vectorised over the cells."""
    chol = np.linalg.cholesky(cov)
    n = x.shape[-1]
    w = np.empty_like(x)
    for i in range(n):  # a loop over the n components, not the cells
        acc = x[..., i] - np.einsum("...j,...j->...", chol[..., i, :i], w[..., :i])
        w[..., i] = acc / chol[..., i, i]
    return np.einsum("...i,...i->...", w, w)


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
    results = evaluate(arrays, window, args.confidence, args.lags, quad_forms=quad_forms)
    with open(args.out, "w") as f:
        json.dump(results, f)


if __name__ == "__main__":
    main()
