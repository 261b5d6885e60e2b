#!/usr/bin/env bash
# Runs two builds of the `kalibra` executable on the committed fixtures and compares what they
# write, byte for byte: `kalibra eval` on every fixture log (default options and a second set),
# `kalibra tune` on the tuning fixture. A refactor that keeps results prints "identical".
#
# Usage: xtask/scripts/compare_cli.sh OLD_KALIBRA NEW_KALIBRA
# (for instance a release build of the last commit before a refactor and one of HEAD).
set -euo pipefail
old="$(realpath "$1")"
new="$(realpath "$2")"
fixtures="$(cd "$(dirname "$0")/../../crates/kalibra-cli/tests/fixtures" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for side in old new; do
    kalibra="${!side}"
    mkdir -p "$work/$side"
    # Each side runs in its own directory with the same relative --out names, so that the
    # "report written to ..." lines compare too.
    (
        cd "$work/$side"
        for log in kf.csv kf.json kf.npz kf_python.json; do
            "$kalibra" eval "$fixtures/$log" --out "eval-$log" > "eval-$log.stdout" 2>&1
            "$kalibra" eval "$fixtures/$log" --out "eval-opts-$log" --confidence 0.99 --window 5 \
                --group position=0,1 --group velocity=2,3 --lags 3 > "eval-opts-$log.stdout" 2>&1
        done
        "$kalibra" tune "$fixtures/tune_model.toml" "$fixtures/tune_measurements.csv" \
            --truth "$fixtures/tune_truth.csv" --out tune > tune.stdout 2>&1
        "$kalibra" tune "$fixtures/tune_model.toml" "$fixtures/tune_measurements.csv" \
            --p -3:3:0.25 --threads 1 --out tune-grid > tune-grid.stdout 2>&1
    )
done
files=$(cd "$work/old" && find . -type f | wc -l)
if diff -r "$work/old" "$work/new"; then
    echo "identical: $files files (10 runs of kalibra eval and kalibra tune, with their output)"
else
    echo "differ (above)"
    exit 1
fi
