//! The Python package `kalibra`: kalibra's evaluation, metrics and filters on numpy arrays.
//!
//! This crate is the native module `kalibra._kalibra`; the package around it (`python/kalibra`:
//! `__init__.py`, the type stubs and `py.typed`) re-exports everything under `kalibra`. It is a
//! thin layer, like the `kalibra` executable: arrays are read with the NPZ reader's rules and
//! evaluated by `kalibra_eval` (one implementation for the command line and Python), reports are
//! written by the executable's own writer (`kalibra_cli::output`), filters are
//! `kalibra_filters`' on run-time sizes.
//!
//! Built by maturin (`pip install ./crates/kalibra-py`), as an abi3 module for CPython 3.9 and
//! later. Every error is a Python exception (`kalibra.KalibraError`, a `ValueError`, whose
//! message names the argument and, where one is at fault, the run and step); nothing panics
//! across the boundary. Long computations release the GIL.

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod arrays;
mod callbacks;
mod eval;
mod filters;
mod metrics;
mod montecarlo;
mod shards;
mod tune;

use pyo3::prelude::*;

pyo3::create_exception!(
    kalibra,
    KalibraError,
    pyo3::exceptions::PyValueError,
    "Bad input to a kalibra function: a wrong shape or dtype, a non-finite value where one must \
     be finite, a covariance that is not positive definite, an invalid option. The message names \
     the argument and, where one is at fault, the run and step (or index)."
);

/// The error as a `kalibra.KalibraError`.
pub(crate) fn error(message: impl Into<String>) -> PyErr {
    KalibraError::new_err(message.into())
}

/// The native module `kalibra._kalibra`.
#[pymodule]
#[pyo3(name = "_kalibra")]
fn kalibra_py(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("KalibraError", m.py().get_type::<KalibraError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    eval::register(m)?;
    metrics::register(m)?;
    filters::register(m)?;
    tune::register(m)?;
    montecarlo::register(m)?;
    shards::register(m)?;
    Ok(())
}
