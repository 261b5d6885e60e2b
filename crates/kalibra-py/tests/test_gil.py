"""Long computations release the GIL: another Python thread keeps running meanwhile."""

import threading
import time

import numpy as np

import kalibra


def longest_pause_while(work):
    """Runs `work` in a thread and returns (its duration, the longest gap between two
    iterations of a Python loop in this thread meanwhile). A call that holds the GIL stops the
    loop for its whole duration."""
    done = threading.Event()
    took = []

    def worker():
        start = time.perf_counter()
        work()
        took.append(time.perf_counter() - start)
        done.set()

    thread = threading.Thread(target=worker)
    last = time.perf_counter()
    longest = 0.0
    thread.start()
    while not done.is_set():
        now = time.perf_counter()
        longest = max(longest, now - last)
        last = now
    thread.join()
    return took[0], longest


def test_kalman_filter_run_and_evaluate_release_the_gil():
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    kf = kalibra.KalmanFilter(F, [[1.0, 0.0]], 0.01 * np.eye(2), [[1.0]], [0.0, 0.0], np.eye(2))
    z = np.random.default_rng(0).normal(size=(1, 2000, 1)).cumsum(axis=1)
    # Enough runs for the call to take a good part of a second even in an optimised build.
    runs = 1
    while True:
        duration, _ = longest_pause_while(lambda: kf.run(np.repeat(z, runs, axis=0)))
        if duration > 0.3 or runs >= 4096:
            break
        runs *= 4
    batch = np.repeat(z, runs, axis=0)
    duration, pause = longest_pause_while(lambda: kf.run(batch))
    assert pause < duration / 3, (duration, pause)
    out = kf.run(batch)
    args = {k: out[k] for k in ("innovation", "innovation_cov")}
    duration, pause = longest_pause_while(lambda: kalibra.evaluate(**args))
    assert pause < max(duration / 3, 0.05), (duration, pause)
