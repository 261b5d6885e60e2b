"""The statistics both reference scripts of `cargo xtask bench eval` compute once they hold
the log as numpy arrays (eval_pandas.py's docstring lists them and what differs from kalibra
on purpose): numpy only, vectorised over runs and steps. `evaluate` takes the quadratic form
x^T P^-1 x as a parameter, since the two scripts compute it two ways.
"""

import statistics

import numpy as np

PER_CELL = ("truth", "estimate", "covariance", "innovation", "innovation_cov")


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


def evaluate(a, window, confidence, lags, quad_forms=quad_forms):
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
