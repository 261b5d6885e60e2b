"""Runs one command and records its wall time and peak resident memory: the timer of
`cargo xtask bench eval`.

    python measure.py RESULT.json COMMAND [ARG ...]

The command inherits this process's standard streams. RESULT.json receives
{"wall_s": seconds, "peak_rss_bytes": bytes, "exit_code": code}. The peak is
getrusage(RUSAGE_CHILDREN).ru_maxrss, the largest peak of the children waited for; the bench
starts a fresh driver per measurement, so that child is the command alone. On Linux ru_maxrss
counts kilobytes of 1024 bytes.
"""

import json
import resource
import subprocess
import sys
import time


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    result, command = sys.argv[1], sys.argv[2:]
    start = time.perf_counter()
    done = subprocess.run(command)
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    with open(result, "w") as f:
        json.dump({"wall_s": wall, "peak_rss_bytes": peak, "exit_code": done.returncode}, f)


if __name__ == "__main__":
    main()
