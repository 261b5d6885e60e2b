"""Every docstring example runs and prints what it shows; every public name has a docstring
and a stub."""

import doctest
import pathlib

import pytest

import kalibra

PUBLIC = [getattr(kalibra, name) for name in kalibra.__all__ if name != "__version__"]
STUBS = (pathlib.Path(kalibra.__file__).parent / "_kalibra.pyi").read_text()


def examples():
    finder = doctest.DocTestFinder(exclude_empty=True)
    tests = finder.find(kalibra, "kalibra", globs={})
    for obj in PUBLIC:
        name = f"kalibra.{obj.__name__}"
        tests += finder.find(obj, name, module=False, globs={})
    return [t for t in tests if t.examples]


@pytest.mark.parametrize("test", examples(), ids=lambda t: t.name)
def test_docstring_example(test):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert runner.failures == 0, f"{test.name}: see the output above"


def test_examples_were_found():
    names = {t.name for t in examples()}
    assert {"kalibra", "kalibra.evaluate", "kalibra.nees", "kalibra.Report"} <= names


@pytest.mark.parametrize("obj", PUBLIC, ids=lambda o: o.__name__)
def test_documented_and_stubbed(obj):
    assert obj.__doc__ and len(obj.__doc__) > 40
    assert f"def {obj.__name__}(" in STUBS or f"class {obj.__name__}" in STUBS


def test_package_is_typed():
    assert (pathlib.Path(kalibra.__file__).parent / "py.typed").is_file()


def test_stubs_match_the_module():
    """mypy's stubtest finds every stub signature at runtime and the other way round. Its one
    complaint left is PEP 800's 'disjoint base', which it also raises when the @final classes
    carry @disjoint_base; PyO3 classes cannot be subclassed, so @final is the accurate marker."""
    pytest.importorskip("mypy")
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "--concise", "kalibra"],
        capture_output=True,
        text=True,
    )
    problems = [
        line
        for line in done.stdout.splitlines()
        if line.strip() and "disjoint base" not in line
    ]
    assert not problems, "\n".join(problems)


def test_monte_carlo_s_return_type_follows_its_arguments(tmp_path):
    """A typed caller gets a Report, a Partial for shard=(i, S), and a (Report, log) pair for
    return_log=True, without narrowing the result itself (mypy --strict on a use of each)."""
    pytest.importorskip("mypy")
    import subprocess
    import sys

    program = tmp_path / "typed_use.py"
    program.write_text(
        "from typing import assert_type\n"
        "import numpy as np\n"
        "import kalibra\n"
        "I = np.eye(2)\n"
        "report = kalibra.monte_carlo(I, I, I, I, np.zeros(2), I, runs=8, steps=5)\n"
        "assert_type(report, kalibra.Report)\n"
        "part = kalibra.monte_carlo(I, I, I, I, np.zeros(2), I, runs=8, steps=5, shard=(0, 2))\n"
        "assert_type(part, kalibra.Partial)\n"
        "pair = kalibra.monte_carlo(I, I, I, I, np.zeros(2), I, runs=8, steps=5, return_log=True)\n"
        "assert_type(pair[0], kalibra.Report)\n"
        "merged: kalibra.Report = kalibra.merge([part])\n"
    )
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--no-incremental", str(program)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
