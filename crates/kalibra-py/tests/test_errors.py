"""Bad input is a kalibra.KalibraError (a ValueError) naming the argument; dtypes and
layouts numpy users have are accepted."""

import numpy as np
import pytest

import kalibra


def good(runs=3, steps=4, n=2):
    rng = np.random.default_rng(3)
    return dict(
        truth=np.zeros((runs, steps, n)),
        estimate=rng.normal(size=(runs, steps, n)),
        covariance=np.broadcast_to(np.eye(n), (runs, steps, n, n)).copy(),
    )


def test_kalibra_error_is_a_value_error():
    assert issubclass(kalibra.KalibraError, ValueError)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(covariance=np.eye(2)), "array covariance has shape"),
        (dict(truth=np.zeros((3, 5, 2))), "array truth has 3 runs of 5 steps"),
        (dict(estimate=np.zeros((3, 4, 3))), "estimate"),
        (dict(truth=np.full((3, 4, 2), np.inf)), "array truth holds a non-finite value at run 0, step 0"),
        (dict(F=np.eye(2)), "arrays F, H, Q and R go together"),
        (dict(time=np.zeros(4)), "times do not increase strictly at step 1"),
        (dict(truth=np.array([["a", "b"]])), "argument truth: dtype <U1 is not a number type"),
        (dict(truth=np.zeros((3, 4, 2), dtype=complex)), "argument truth: dtype complex128"),
    ],
)
def test_evaluate_names_the_argument(change, message):
    with pytest.raises(kalibra.KalibraError, match=message):
        kalibra.evaluate(**{**good(), **change})


@pytest.mark.parametrize(
    "option, message",
    [
        (dict(confidence=1.5), "confidence"),
        (dict(window=1), "window"),
        (dict(lags=0), "lags"),
        (dict(groups={"pos": [0, 7]}), "group pos names component 7"),
        (dict(groups={"pos": "x"}), "argument groups: group pos is not a list"),
    ],
)
def test_evaluate_options_are_checked(option, message):
    with pytest.raises(kalibra.KalibraError, match=message):
        kalibra.evaluate(**good(), **option)


def test_nothing_to_evaluate():
    with pytest.raises(kalibra.KalibraError, match="holds none of"):
        kalibra.evaluate()


def test_float32_noncontiguous_and_lists_give_the_float64_report():
    g = good()
    expected = kalibra.evaluate(**g).to_dict()
    # Values exactly representable in float32, so the report must be identical.
    g32 = {k: v.astype(np.float32) for k, v in g.items()}
    g = {k: v.astype(np.float32).astype(np.float64) for k, v in g.items()}
    assert kalibra.evaluate(**g32).to_dict() == kalibra.evaluate(**g).to_dict()
    # A transposed view (Fortran order) and a strided slice are read in logical order.
    wide = np.zeros((3, 8, 2))
    wide[:, ::2] = g["estimate"]
    fortran = np.asfortranarray(g["covariance"])
    strided = dict(truth=g["truth"], estimate=wide[:, ::2], covariance=fortran)
    assert not strided["estimate"].flags.c_contiguous
    assert kalibra.evaluate(**strided).to_dict() == kalibra.evaluate(**g).to_dict()
    lists = {k: v.tolist() for k, v in g.items()}
    assert kalibra.evaluate(**lists).to_dict() == kalibra.evaluate(**g).to_dict()
    assert expected["runs"] == 3


def test_integer_arrays_are_read():
    ints = dict(
        innovation=np.ones((3, 4, 1), dtype=np.int64),
        innovation_cov=np.ones((3, 4, 1, 1), dtype=np.int32),
    )
    floats = {k: v.astype(float) for k, v in ints.items()}
    assert kalibra.evaluate(**ints).to_dict() == kalibra.evaluate(**floats).to_dict()


def test_nees_names_the_bad_cell():
    g = good()
    g["covariance"][1, 2] = [[1.0, 0.0], [0.0, -1.0]]
    with pytest.raises(kalibra.KalibraError, match=r"argument covariance at \(1, 2\)"):
        kalibra.nees(**g)
    with pytest.raises(kalibra.KalibraError, match="argument covariance has shape"):
        kalibra.nees(g["truth"], g["estimate"], g["covariance"][0])
    with pytest.raises(kalibra.KalibraError, match="argument estimate has shape"):
        kalibra.nees(g["truth"], g["estimate"][0], g["covariance"])


def test_building_block_arguments():
    with pytest.raises(kalibra.KalibraError, match="degrees of freedom"):
        kalibra.chi2_band(0, 10)
    with pytest.raises(kalibra.KalibraError, match="confidence"):
        kalibra.chi2_band(2, 10, 1.0)
    with pytest.raises(kalibra.KalibraError, match="window"):
        kalibra.sliding_window(np.ones(10), 1)
    with pytest.raises(kalibra.KalibraError, match="column 1"):
        kalibra.sliding_window(np.array([[1.0, 1.0], [2.0, np.nan], [3.0, 3.0]]), 2)
    with pytest.raises(kalibra.KalibraError, match="argument over"):
        kalibra.rmse(np.zeros((2, 2)), np.zeros((2, 2)), over="space")
    with pytest.raises(kalibra.KalibraError, match="argument innovation_cov has shape"):
        kalibra.nis(np.zeros((4, 2)), np.zeros((4, 2)))


def raised(call):
    """The KalibraError `call` raises."""
    with pytest.raises(kalibra.KalibraError) as info:
        call()
    return info.value


PLACES = ("argument", "run", "step", "index", "file", "row", "column")


def test_error_attributes_name_the_argument_run_and_step():
    e = raised(lambda: kalibra.evaluate(**{**good(), "truth": np.full((3, 4, 2), np.inf)}))
    assert (e.argument, e.run, e.step) == ("truth", 0, 0)
    # Arrays in memory have no file, and the error no index inside the argument.
    assert (e.index, e.file, e.row, e.column) == (None, None, None, None)


@pytest.mark.parametrize(
    "change, argument, step",
    [
        (dict(covariance=np.eye(2)), "covariance", None),
        # The later array disagrees with the first: the estimate is named.
        (dict(estimate=np.zeros((3, 5, 2))), "estimate", None),
        # A model given in part: the first array missing is named.
        (dict(F=np.eye(2)), "H", None),
        (dict(time=np.zeros(4)), "time", 1),
        (dict(truth=np.array([["a", "b"]])), "truth", None),
    ],
)
def test_error_attributes_of_evaluate(change, argument, step):
    e = raised(lambda: kalibra.evaluate(**{**good(), **change}))
    assert (e.argument, e.step, e.run) == (argument, step, None)


@pytest.mark.parametrize(
    "option, argument, index",
    [
        (dict(confidence=1.5), "confidence", None),
        (dict(window=1), "window", None),
        (dict(lags=0), "lags", None),
        (dict(groups={"pos": [0, 7]}), "groups", (7,)),
        (dict(groups={"pos": "x"}), "groups", None),
    ],
)
def test_error_attributes_of_options(option, argument, index):
    e = raised(lambda: kalibra.evaluate(**good(), **option))
    assert (e.argument, e.index) == (argument, index)
    assert (e.run, e.step, e.file) == (None, None, None)


def test_error_attributes_of_sweep_q_name_the_matrix():
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    asymmetric = np.array([[1.0, 0.5], [0.0, 1.0]])
    z = np.zeros((10, 1))
    e = raised(lambda: kalibra.sweep_q(F, H, asymmetric, np.eye(1), np.zeros(2), np.eye(2), z))
    assert e.argument == "Q_nom", str(e)
    assert "Q_nom" in str(e)


def test_error_attributes_default_to_none():
    e = kalibra.KalibraError("made by hand")
    assert all(getattr(e, name) is None for name in PLACES)
    # Set on one error, not on the class.
    raised(lambda: kalibra.evaluate(**{**good(), "truth": np.full((3, 4, 2), np.inf)}))
    assert kalibra.KalibraError.argument is None
