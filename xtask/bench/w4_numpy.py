"""The W4 step in numpy: the timer beside `cargo xtask bench w4`.

    python w4_numpy.py --sizes 8,16,... [--steps 20] [--warm-up 5] [--blocks 3] [--budget 1.0]

Per state dimension n (m = max(2, n // 4)) the same problem as the Rust bench, drawn from
numpy's generator instead of ChaCha8 (the timings do not depend on the values): F = 0.95 U
with U the orthogonal factor of a Gaussian matrix, H Gaussian / sqrt(n), Q, R and P0 of the
form A A^T / k + c I, and measurements and truths simulated from them. One step is what a numpy
user writes for the KF the bench times:

    P = F P F^T + Q (symmetrised)                              predict
    S = H P H^T + R, K = solve(S, H P)^T                       gain by LU (numpy has no
                                                               triangular or Cholesky solve)
    P = (I - K H) P (I - K H)^T + K R K^T (symmetrised)        Joseph update
    NEES = e^T solve(P, e)                                     one more LU

After --warm-up steps, blocks of --steps steps are timed until at least --blocks blocks and
--budget seconds; the best block counts. One JSON line per size on standard output:
{"n": n, "m": m, "seconds_per_step": t}. Set OPENBLAS_NUM_THREADS=1 (the bench does) for the
one-thread figures.
"""

import argparse
import json
import time

import numpy as np


def spd(rng, k, c):
    a = rng.standard_normal((k, k))
    s = a @ a.T / k + c * np.eye(k)
    return 0.5 * (s + s.T)


def problem(n, rng):
    m = max(2, n // 4)
    f = 0.95 * np.linalg.qr(rng.standard_normal((n, n)))[0]
    h = rng.standard_normal((m, n)) / np.sqrt(n)
    q = 0.1 * spd(rng, n, 0.1)
    r = spd(rng, m, 0.1)
    p0 = spd(rng, n, 1.0)
    lq, lr = np.linalg.cholesky(q), np.linalg.cholesky(r)
    x = rng.standard_normal(n)
    states, measurements = [], []
    for _ in range(64):
        states.append(x)
        measurements.append(h @ x + lr @ rng.standard_normal(m))
        x = f @ x + lq @ rng.standard_normal(n)
    return f, h, q, r, p0, states, measurements


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", required=True)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--warm-up", type=int, default=5)
    parser.add_argument("--blocks", type=int, default=3)
    parser.add_argument("--budget", type=float, default=1.0)
    args = parser.parse_args()
    for n in (int(s) for s in args.sizes.split(",")):
        rng = np.random.default_rng(2012 + n)
        f, h, q, r, p, states, measurements = problem(n, rng)
        m = h.shape[0]
        eye = np.eye(n)
        x = np.zeros(n)
        k = 0
        nees = 0.0

        def run(steps):
            nonlocal x, p, k, nees
            for _ in range(steps):
                i = k % len(measurements)
                x = f @ x
                p = f @ p @ f.T + q
                p = 0.5 * (p + p.T)
                hp = h @ p
                s = hp @ h.T + r
                s = 0.5 * (s + s.T)
                gain = np.linalg.solve(s, hp).T
                x = x + gain @ (measurements[i] - h @ x)
                ikh = eye - gain @ h
                p = ikh @ p @ ikh.T + gain @ r @ gain.T
                p = 0.5 * (p + p.T)
                e = states[i] - x
                nees += e @ np.linalg.solve(p, e)
                k += 1

        run(args.warm_up)
        best, blocks, start = float("inf"), 0, time.perf_counter()
        while blocks < args.blocks or time.perf_counter() - start < args.budget:
            t = time.perf_counter()
            run(args.steps)
            best = min(best, (time.perf_counter() - t) / args.steps)
            blocks += 1
        if not np.isfinite(nees):
            raise SystemExit(f"non-finite NEES at n = {n}")
        print(json.dumps({"n": n, "m": m, "seconds_per_step": best}), flush=True)


if __name__ == "__main__":
    main()
