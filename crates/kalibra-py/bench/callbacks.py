"""The per-step cost of Python callables in kalibra's EKF and UKF: W1's
4-state constant-velocity model with position measurements, one run of K steps, through
KalmanFilter (no callbacks), ExtendedKalmanFilter (f, F_jacobian, h, H_jacobian: 4 calls per
step) and UnscentedKalmanFilter (2n + 1 = 9 calls of f and 9 of h per step), beside FilterPy's
KalmanFilter, ExtendedKalmanFilter and UnscentedKalmanFilter on the same data.

    venv/bin/python crates/kalibra-py/bench/callbacks.py [--steps 20000]
"""

import argparse
import time

import numpy as np

import kalibra
from bench import F, H, P0, Q, R, X0, simulate


def per_step(f, steps, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - start)
    return best / steps * 1e6


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    steps = parser.parse_args().steps
    _, z = simulate(1, steps)
    z = z[0]
    fx = lambda x, k: F @ x
    fj = lambda x, k: F
    hx = lambda x, k: H @ x
    hj = lambda x, k: H
    kf = kalibra.KalmanFilter(F, H, Q, R, X0, P0)
    ekf = kalibra.ExtendedKalmanFilter(fx, fj, hx, hj, Q, R, X0, P0)
    ukf = kalibra.UnscentedKalmanFilter(fx, hx, Q, R, X0, P0)
    rows = [
        ("kalibra.KalmanFilter (no callbacks)", per_step(lambda: kf.run(z), steps)),
        ("kalibra.ExtendedKalmanFilter (4 callbacks)", per_step(lambda: ekf.run(z), steps)),
        ("kalibra.UnscentedKalmanFilter (18 callbacks)", per_step(lambda: ukf.run(z), steps)),
    ]
    try:
        from filterpy.kalman import (
            ExtendedKalmanFilter, JulierSigmaPoints, KalmanFilter, UnscentedKalmanFilter,
        )

        def fp_kf():
            f = KalmanFilter(dim_x=4, dim_z=2)
            f.F, f.H, f.Q, f.R, f.x, f.P = F, H, Q, R, X0.copy(), P0.copy()
            for zk in z:
                f.predict()
                f.update(zk)

        def fp_ekf():
            f = ExtendedKalmanFilter(dim_x=4, dim_z=2)
            f.F, f.Q, f.R, f.x, f.P = F, Q, R, X0.copy(), P0.copy()
            for zk in z:
                f.predict()
                f.update(zk, HJacobian=lambda x: H, Hx=lambda x: H @ x)

        def fp_ukf():
            pts = JulierSigmaPoints(4, kappa=0.0)
            f = UnscentedKalmanFilter(4, 2, 1.0, hx=lambda x: H @ x, fx=lambda x, dt: F @ x,
                                      points=pts)
            f.Q, f.R, f.x, f.P = Q, R, X0.copy(), P0.copy()
            for zk in z:
                f.predict()
                f.update(zk)

        short = min(steps, 5000)
        z_full = z
        z = z_full[:short]
        rows += [
            ("FilterPy KalmanFilter", per_step(fp_kf, short, 1)),
            ("FilterPy ExtendedKalmanFilter", per_step(fp_ekf, short, 1)),
            ("FilterPy UnscentedKalmanFilter", per_step(fp_ukf, short, 1)),
        ]
    except ImportError:
        pass
    print(f"W1 model, one run of {steps} steps: microseconds per step")
    for name, us in rows:
        print(f"  {name:<46} {us:8.1f}")


if __name__ == "__main__":
    main()
