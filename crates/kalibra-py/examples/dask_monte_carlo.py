"""A kalibra Monte Carlo study on Dask: shards on worker processes, merged into the report of
the one-process run, bit for bit.

The example starts its own ``dask.distributed.LocalCluster`` (a scheduler and two worker
processes, one thread each): on a real cluster, pass the scheduler's address to ``Client``
instead and nothing else changes. Each task runs ``kalibra.monte_carlo(..., shard=(i, S))``,
which returns a picklable ``kalibra.Partial`` (its blocks of runs, evaluated and kept apart);
the client gathers the S partials and ``kalibra.merge`` folds them into the report, which is
checked against ``kalibra.monte_carlo`` run whole in this process.

    pip install ./crates/kalibra-py "dask[distributed]"
    python crates/kalibra-py/examples/dask_monte_carlo.py [--shards 4 --runs 2000 --steps 200]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import kalibra

# A constant-velocity target with a position sensor, the filter slightly optimistic about its
# measurement noise.
F = np.array([[1.0, 1.0], [0.0, 1.0]])
H = np.array([[1.0, 0.0]])
Q = np.array([[0.25, 0.5], [0.5, 1.0]])
R = np.array([[4.0]])
MODEL = (F, H, Q, R, np.zeros(2), np.eye(2))


def study(runs: int, steps: int, seed: int) -> dict:
    """The study's arguments, the same on the client and on every worker."""
    return dict(
        runs=runs,
        steps=steps,
        seed=seed,
        filter_R=R * 0.8,
        groups={"position": [0], "velocity": [1]},
        threads=1,
    )


def shard(i: int, count: int, options: dict) -> kalibra.Partial:
    """Shard ``i`` of ``count``: what one Dask task runs (on a worker process)."""
    return kalibra.monte_carlo(*MODEL, **options, shard=(i, count))


def run(shards: int = 4, runs: int = 2000, steps: int = 200, seed: int = 7, workers: int = 2):
    """Runs the study as ``shards`` Dask tasks on a LocalCluster of ``workers`` processes and
    in this process; returns (merged report, one-process report, seconds on Dask)."""
    from dask.distributed import Client, LocalCluster

    options = study(runs, steps, seed)
    with LocalCluster(
        n_workers=workers, processes=True, threads_per_worker=1, dashboard_address=None
    ) as cluster, Client(cluster) as client:
        start = time.perf_counter()
        futures = client.map(shard, range(shards), count=shards, options=options, pure=False)
        parts = client.gather(futures)  # picklable Partials, shipped from the workers
        merged = kalibra.merge(parts)
        seconds = time.perf_counter() - start
    whole = kalibra.monte_carlo(*MODEL, **options)
    return merged, whole, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shards", type=int, default=4)
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    merged, whole, seconds = run(args.shards, args.runs, args.steps, workers=args.workers)
    same = merged.to_json() == whole.to_json()
    print(f"{args.shards} shards on {args.workers} Dask workers: {seconds:.2f} s")
    print(f"merged report: {merged.headline}")
    print(f"bit-identical to the one-process run: {same}")
    if not same:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
