"""Sharded Monte Carlo: ``monte_carlo(..., shard=(i, S))`` and ``merge`` give the one-process
report bit for bit (any S, any thread counts, any order, through pickle and bytes), refuse
what is not exactly the S shards of one study with a ``KalibraError``, and run on a Dask
``LocalCluster`` of worker processes (the example, in this process and as a script)."""

import importlib.util
import math
import pathlib
import pickle
import random
import struct
import subprocess
import sys

import numpy as np
import pytest

import kalibra

HERE = pathlib.Path(__file__).resolve().parent
EXAMPLE = HERE.parent / "examples" / "dask_monte_carlo.py"

F = np.array([[1.0, 1.0], [0.0, 1.0]])
H = np.array([[1.0, 0.0]])
Q = np.array([[0.25, 0.5], [0.5, 1.0]])
R = np.array([[4.0]])
MODEL = (F, H, Q, R, np.zeros(2), np.eye(2))
# Options that reach every part of the report: groups, a window, J1/J2 (the model is logged),
# an optimistic filter.
OPTIONS = dict(steps=30, seed=5, filter_R=R / 2, groups={"pos": [0], "vel": [1]}, window=4)


def bits(value):
    """The report's values with every float as its 8 bytes: equal only if equal to the bit
    (NaN included, where == would say unequal)."""
    if isinstance(value, float):
        return ("f", struct.pack("<d", value))
    if isinstance(value, dict):
        return {k: bits(v) for k, v in value.items()}
    if isinstance(value, list):
        return [bits(v) for v in value]
    return value


def report_bits(report):
    return bits(report.to_dict())


def shards(count, runs, threads=(1, 2, 0), **options):
    """The partials of all `count` shards, each with its own thread count."""
    opts = {**OPTIONS, **options}
    return [
        kalibra.monte_carlo(*MODEL, runs=runs, shard=(i, count), threads=threads[i % len(threads)], **opts)
        for i in range(count)
    ]


@pytest.mark.parametrize(
    "runs, count",
    [(150, 1), (150, 2), (150, 3), (150, 7), (150, 64), (150, 70), (5, 3), (5, 8), (1, 2)],
)
def test_merge_is_the_one_process_report_bit_for_bit(runs, count):
    whole = kalibra.monte_carlo(*MODEL, runs=runs, **OPTIONS)
    parts = shards(count, runs)
    # More shards than blocks (min(runs, 64)): the extra shards are empty, and still needed.
    assert sum(p.blocks for p in parts) == min(runs, 64)
    assert [p.blocks == 0 for p in parts].count(True) == max(0, count - min(runs, 64))
    random.Random(count).shuffle(parts)  # any order
    merged = kalibra.merge(parts)
    assert report_bits(merged) == report_bits(whole)
    assert merged.to_json() == whole.to_json()
    # The checks have something to check: the study is not trivially uniform.
    assert whole.verdict == "optimistic" or runs < 10
    assert whole.to_dict()["j"] is not None


def test_the_thread_count_is_not_part_of_the_study():
    whole = kalibra.monte_carlo(*MODEL, runs=100, threads=3, **OPTIONS)
    for threads in [(1,), (2,), (4, 1)]:
        assert report_bits(kalibra.merge(shards(3, 100, threads))) == report_bits(whole)


def test_partials_pickle_and_round_trip_through_bytes():
    parts = shards(3, 90)
    part = parts[1]
    assert (part.shard, part.shard_count, part.runs, part.seed) == (1, 3, 90, 5)
    assert part.version == f"kalibra {kalibra.__version__}"
    assert len(part.config_hash) == 16 and int(part.config_hash, 16) >= 0
    assert part.blocks == 21  # blocks 21 .. 42 of 64
    assert "shard 1/3" in repr(part)
    data = part.to_bytes()
    again = pickle.loads(pickle.dumps(part))
    assert isinstance(again, kalibra.Partial)
    assert again.to_bytes() == data
    assert kalibra.Partial.from_bytes(data).to_bytes() == data
    # merge takes the bytes as well as the partials.
    whole = kalibra.monte_carlo(*MODEL, runs=90, **OPTIONS)
    mixed = [parts[0].to_bytes(), again, parts[2]]
    assert report_bits(kalibra.merge(mixed)) == report_bits(whole)
    assert report_bits(kalibra.merge(iter(parts))) == report_bits(whole)


def refused(parts, *words):
    with pytest.raises(kalibra.KalibraError) as caught:
        kalibra.merge(parts)
    message = str(caught.value)
    for word in words:
        assert word in message, message
    return message


def test_merge_refuses_what_is_not_one_study_cut_once():
    parts = shards(3, 60)
    assert issubclass(kalibra.KalibraError, ValueError)
    refused([], "no partial results")
    refused(parts[:2], "missing shard(s) [2] of 3")
    refused([parts[0], parts[2]], "missing shard(s) [1] of 3")
    refused(parts + [parts[1]], "shard 1/3 is given twice")
    refused([parts[0]] + shards(2, 60)[1:], "does not fit a study cut into 3 shards")
    # Other studies: another seed, other runs, any other option that changes the report.
    for other in [dict(seed=6), dict(runs=61), dict(lags=3), dict(filter_R=R), dict(confidence=0.9),
                  dict(groups={"vel": [1], "pos": [0]}), dict(window=None), dict(steps=31)]:
        runs = other.pop("runs", 60)
        part = kalibra.monte_carlo(*MODEL, runs=runs, shard=(1, 3), **{**OPTIONS, **other})
        refused([parts[0], part, parts[2]], "shard 1 belongs to another study")
    moved = (F, H, Q, R, np.array([0.0, 1e-300]), np.eye(2))
    part = kalibra.monte_carlo(*moved, runs=60, shard=(1, 3), **OPTIONS)
    refused([parts[0], part, parts[2]], "another study")
    refused([parts[0], "shard 1", parts[2]], "item 1 is a str")


def fnv1a(data):
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def resealed(body):
    """`body` with a valid checksum: an edit that only the reader's own checks can catch."""
    return body + struct.pack("<Q", fnv1a(body))


def test_damaged_bytes_are_refused_never_a_panic():
    part = shards(2, 8)[0]
    data = part.to_bytes()
    body = data[:-8]
    for bad in [b"", b"1234567", data[:-1], data[:100], data[:-9] + data[-8:], b"x" + data[1:]]:
        with pytest.raises(kalibra.KalibraError, match="truncated or damaged"):
            kalibra.Partial.from_bytes(bad)
        refused([bad], "truncated or damaged")
    # Another format version, with a valid checksum, is named as such.
    key = b"\x66format\x01"
    assert body.count(key) == 1
    with pytest.raises(kalibra.KalibraError, match="format version 2; this kalibra"):
        kalibra.Partial.from_bytes(resealed(body.replace(key, b"\x66format\x02")))
    # A configuration edited under its identity's hash.
    key = b"\x64lags\x0a"
    assert body.count(key) == 1
    edited = kalibra.Partial.from_bytes(resealed(body.replace(key, b"\x64lags\x0b")))
    refused([edited, shards(2, 8)[1]], "does not match its hash")
    # Random edits under a valid checksum: a KalibraError or, rarely, a merge that still
    # passes every check (an edited float, say); never another exception, never a panic.
    rng = random.Random(1)
    other = shards(2, 8)[1]
    outcomes = {"refused": 0, "merged": 0}
    for _ in range(300):
        edit = bytearray(body)
        for _ in range(rng.randint(1, 4)):
            at = rng.randrange(len(edit))
            edit[at] = rng.randrange(256) if rng.random() < 0.7 else edit[at] ^ (1 << rng.randrange(8))
        try:
            kalibra.merge([kalibra.Partial.from_bytes(resealed(bytes(edit))), other])
            outcomes["merged"] += 1
        except kalibra.KalibraError:
            outcomes["refused"] += 1
    assert outcomes["refused"] > 100, outcomes


def test_shard_arguments_are_checked():
    for shard in [(2, 2), (0, 0), (5, 3), (-1, 2), (0, -2)]:
        with pytest.raises(kalibra.KalibraError, match="argument shard"):
            kalibra.monte_carlo(*MODEL, runs=10, steps=5, shard=shard)
    with pytest.raises(kalibra.KalibraError, match="shard and return_log"):
        kalibra.monte_carlo(*MODEL, runs=10, steps=5, shard=(0, 2), return_log=True)
    with pytest.raises(TypeError):
        kalibra.monte_carlo(*MODEL, runs=10, steps=5, shard=3)


def test_unaligned_arrays_are_read():
    # Pickle's out-of-band buffers (how Dask ships arrays) can be unaligned; a kalibra function
    # once raised PanicException on them.
    unaligned = np.frombuffer(b"\0" + F.tobytes(), dtype=np.float64, offset=1).reshape(2, 2)
    assert not unaligned.flags.aligned
    a = kalibra.monte_carlo(unaligned, *MODEL[1:], runs=4, steps=5)
    b = kalibra.monte_carlo(*MODEL, runs=4, steps=5)
    assert report_bits(a) == report_bits(b)


def load_example():
    spec = importlib.util.spec_from_file_location("dask_monte_carlo", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_dask_local_cluster_gives_the_one_process_report():
    pytest.importorskip("dask.distributed")  # installed by .ci/run, so this runs in CI
    example = load_example()
    merged, whole, _ = example.run(shards=5, runs=300, steps=40, seed=3, workers=2)
    assert report_bits(merged) == report_bits(whole)
    assert not math.isnan(merged.to_dict()["summary"]["anees"])


def test_dask_example_runs_as_a_script():
    pytest.importorskip("dask.distributed")
    out = subprocess.run(
        [sys.executable, str(EXAMPLE), "--shards", "3", "--runs", "200", "--steps", "30"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert "bit-identical to the one-process run: True" in out.stdout
