"""statsmodels' maximum likelihood on the model of `cargo xtask bench tune`: its reference.

    python tune_statsmodels.py MODEL.json MEASUREMENTS.f64 STEPS REPEATS GTOL OUT.json

MODEL.json holds F, G, H, x0, P0 and the starting variances qw_start, r_start (nested lists);
MEASUREMENTS.f64 the STEPS x m measurements as little-endian float64. The model: `x_k = F
x_{k-1} + G w_k`, `w_k ~ N(0, diag(q_1, q_2))`, `z_k = H x_k + v_k`, `v_k ~ N(0, diag(r_1,
r_2))`, four free variances. The `MLEModel` subclass parametrises them as kalibra's diagonal
forms do (the optimiser sees their logarithms), with x0, P0 known as the prior at the first
measurement (`initialization="known"`: kalibra's `Start::UpdateFirst`), and starts from the same
variances.

`fit()` minimises `-loglike / nobs` by L-BFGS-B (its default method) to the projected-gradient
tolerance GTOL (the same tolerance on the same function as kalibra's BFGS; `factr = 10`, so
that the gradient decides when it stops) and computes the standard errors from the observed
information (`cov_type="approx"`, the numerical Hessian, as kalibra reports). It is timed
REPEATS times and the shortest time kept. Writes OUT.json with the seconds, the estimate, its
log-likelihood and standard errors, whether it converged, and the versions.

The bench creates the virtual environment and installs statsmodels 0.15.0 (with numpy and
scipy), the version the fixture of crates/kalibra-tune/tests/statsmodels.rs was written with.
"""

import json
import sys
import time

import numpy as np
import scipy
import statsmodels
from statsmodels.tsa.statespace.mlemodel import MLEModel


class DiagonalNoise(MLEModel):
    def __init__(self, endog, model):
        n = model["F"].shape[0]
        g = model["G"].shape[1]
        super().__init__(endog, k_states=n, k_posdef=g, initialization="known",
                         initial_state=model["x0"], initial_state_cov=model["P0"])
        self["design"] = model["H"]
        self["transition"] = model["F"]
        self["selection"] = model["G"]
        self.g = g
        self.start = np.concatenate([np.diag(model["qw_start"]), np.diag(model["r_start"])])

    @property
    def param_names(self):
        m = self.k_endog
        return [f"Qw[{i},{i}]" for i in range(self.g)] + [f"R[{i},{i}]" for i in range(m)]

    @property
    def start_params(self):
        return self.start

    def transform_params(self, unconstrained):
        return np.exp(unconstrained)

    def untransform_params(self, constrained):
        return np.log(constrained)

    def update(self, params, **kwargs):
        params = super().update(params, **kwargs)
        self["state_cov"] = np.diag(params[: self.g])
        self["obs_cov"] = np.diag(params[self.g:])


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    model_path, z_path, steps, repeats, gtol, out = sys.argv[1:]
    steps, repeats, gtol = int(steps), int(repeats), float(gtol)
    with open(model_path) as f:
        model = {k: np.array(v, dtype=float) for k, v in json.load(f).items()}
    m = model["H"].shape[0]
    endog = np.fromfile(z_path, dtype="<f8").reshape(steps, m)
    best, res = None, None
    for _ in range(repeats):
        start = time.perf_counter()
        mod = DiagonalNoise(endog, model)
        res = mod.fit(method="lbfgs", maxiter=1000, disp=False, pgtol=gtol, factr=10.0,
                      cov_type="approx")
        bse = res.bse
        seconds = time.perf_counter() - start
        best = seconds if best is None else min(best, seconds)
    report = {
        "seconds": best,
        "repeats": repeats,
        "names": res.model.param_names,
        "params": [float(v) for v in res.params],
        "bse": [float(v) for v in bse],
        "loglike": float(res.llf),
        "converged": bool(res.mle_retvals["converged"]),
        "iterations": int(res.mle_retvals["iterations"]),
        "evaluations": int(res.mle_retvals["fcalls"]),
        "versions": (
            f"Python {sys.version.split()[0]}, statsmodels {statsmodels.__version__}, "
            f"numpy {np.__version__}, scipy {scipy.__version__}"
        ),
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
