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
import statistics

import numpy as np
import pandas as pd

PER_CELL = ("truth", "estimate", "covariance", "innovation", "innovation_cov")


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


def quad_forms(x, cov):
    """x^T cov^-1 x for every run and step, by a batched solve."""
    return np.einsum("...i,...i->...", x, np.linalg.solve(cov, x[..., None])[..., 0])


def wilson_hilferty(p_normal, dof):
    """The chi-square quantile with `dof` degrees of freedom at the normal quantile `p_normal`
    (Wilson and Hilferty 1931)."""
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + p_normal * np.sqrt(a)) ** 3


def bands(counts, dof, confidence):
    """The two-sided band of the mean of `counts` values of chi-square(dof) / dof."""
    z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2.0)
    total = dof * counts
    lower = wilson_hilferty(-z, total) / total
    upper = wilson_hilferty(z, total) / total
    return [{"lower": lo, "upper": up} for lo, up in zip(lower.tolist(), upper.tolist())]


def t_statistic(per_run):
    d = per_run - 1.0
    return float(d.mean() / np.sqrt(d.var(ddof=1) / d.size))


def evaluate(a, window, confidence, lags):
    truth, estimate, cov = a["truth"], a["estimate"], a["covariance"]
    innov, s = a["innovation"], a["innovation_cov"]
    runs, steps, n = truth.shape
    m = innov.shape[-1]
    e = estimate - truth

    nees = quad_forms(e, cov)  # (runs, steps)
    nis = quad_forms(innov, s)
    anees = nees.mean(axis=0) / n
    anis = nis.mean(axis=0) / m

    # Sigma_k = (1 / R) sum_i e_i e_i^T, one (n, n) matrix per step, by a batched matmul.
    e_by_step = e.transpose(1, 0, 2)  # (steps, runs, n)
    sigma = e_by_step.transpose(0, 2, 1) @ e_by_step / runs
    sigma_inv = np.linalg.inv(sigma)
    q_sigma = np.einsum("rki,rki->rk", (e[..., None, :] @ sigma_inv)[..., 0, :], e)
    nci = (10.0 * np.log10(nees) - 10.0 * np.log10(q_sigma)).mean(axis=0)

    rmse = np.sqrt((e**2).mean(axis=0))  # (steps, n)

    # Forward windows of run 0's errors: (windows, n, W) views, no copy.
    win = np.lib.stride_tricks.sliding_window_view(e[0], window, axis=0)
    w_bias = win.mean(axis=-1)
    w_std = win.std(axis=-1, ddof=1)
    w_rmse = np.sqrt((win**2).mean(axis=-1))

    # Whiteness of run 0: w_k = L_k^-1 nu_k.
    chol = np.linalg.cholesky(s[0])
    w = np.linalg.solve(chol, innov[0][..., None])[..., 0]  # (steps, m)
    lags = min(lags, steps - 2)
    z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2.0)
    lag_reports = []
    box_pierce = 0.0
    for lag in range(1, lags + 1):  # a loop over the lags, not the rows
        head, tail = w[:-lag], w[lag:]
        rho = (head * tail).sum() / np.sqrt((head**2).sum() * (tail**2).sum())
        pairs = steps - lag
        box_pierce += pairs * m * rho**2
        lag_reports.append(
            {"lag": lag, "autocorrelation": float(rho), "bound": z / np.sqrt(pairs * m), "pairs": pairs}
        )

    counts = np.full(steps, runs)
    return {
        "runs": runs,
        "steps": steps,
        "state_dim": n,
        "measurement_dim": m,
        "anees_per_step": anees.tolist(),
        "anees_band": bands(counts, n, confidence),
        "anis_per_step": anis.tolist(),
        "anis_band": bands(counts, m, confidence),
        "nci_per_step": nci.tolist(),
        "rmse_per_step": [
            {"name": f"x{i}", "components": [i], "values": rmse[:, i].tolist()} for i in range(n)
        ],
        "window": {
            "run": 0,
            "window": window,
            "start_steps": list(range(steps - window + 1)),
            "components": [
                {
                    "component": i,
                    "rmse": w_rmse[:, i].tolist(),
                    "bias": w_bias[:, i].tolist(),
                    "std": w_std[:, i].tolist(),
                }
                for i in range(n)
            ],
        },
        "whiteness": {"run": 0, "lags": lag_reports, "box_pierce": float(box_pierce)},
        "summary": {
            "anees": float(nees.mean() / n),
            "anis": float(nis.mean() / m),
            "nci": float(nci.mean()),
            "anees_test": {"t": t_statistic(nees.mean(axis=1) / n)},
            "anis_test": {"t": t_statistic(nis.mean(axis=1) / m)},
        },
    }


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
