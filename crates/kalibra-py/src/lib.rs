//! The Python package `kalibra`: kalibra's evaluation, metrics and filters on numpy arrays.
//!
//! This crate is the native module `kalibra._kalibra`; the package around it (`python/kalibra`:
//! `__init__.py`, the type stubs and `py.typed`) re-exports everything under `kalibra`. It is a
//! thin layer, like the `kalibra` executable: arrays are read with the NPZ reader's rules and
//! evaluated by `kalibra_eval` (one implementation for the command line and Python), reports are
//! written by the executable's own writer (`kalibra_io::output`), filters are
//! `kalibra_filters`' on run-time sizes.
//!
//! Built by maturin (`pip install ./crates/kalibra-py`), as an abi3 module for CPython 3.9 and
//! later. Every error is a Python exception (`kalibra.KalibraError`, a `ValueError`, whose
//! message names the argument and, where one is at fault, the run and step, and whose
//! attributes `argument`, `run`, `step`, `index`, `file`, `row` and `column` hold the same
//! facts for a program: `At`); nothing panics across the boundary. Long computations release
//! the GIL.

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod arrays;
mod callbacks;
mod estimate;
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
     the argument and, where one is at fault, the run and step (or index); the attributes \
     argument, run, step, index, file, row and column hold the same facts (None where they do \
     not apply)."
);

/// Where an error is at fault: `kalibra.KalibraError`'s attributes, `None` where they do not
/// apply.
#[derive(Debug, Default, Clone, PartialEq)]
pub(crate) struct At {
    /// The argument at fault (`truth`, `Q_nom`, `groups`, ...).
    pub argument: Option<String>,
    /// The run (from 0).
    pub run: Option<usize>,
    /// The step (from 0).
    pub step: Option<usize>,
    /// The position inside the argument, outermost axis first (from 0).
    pub index: Option<Vec<usize>>,
    /// The file.
    pub file: Option<String>,
    /// The row (CSV) or line (JSON, TOML) of the file, from 1.
    pub row: Option<u64>,
    /// The column of the file, from 1.
    pub column: Option<usize>,
}

/// The names of [`At`]'s fields, as `KalibraError`'s attributes.
const AT_FIELDS: [&str; 7] = ["argument", "run", "step", "index", "file", "row", "column"];

impl At {
    /// The argument named at the start of `message` (`argument NAME ...`), if any: how the
    /// package's own messages name it.
    fn from_message(message: &str) -> Self {
        let argument = message.strip_prefix("argument ").and_then(|rest| {
            let end = rest
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            (end > 0).then(|| rest[..end].to_string())
        });
        Self {
            argument,
            ..Self::default()
        }
    }

    /// Where an evaluation's error is at fault.
    pub(crate) fn of_eval(e: &kalibra_eval::EvalError) -> Self {
        use kalibra_eval::EvalError as E;
        let argument = |a: &str| Some(a.to_string());
        match e {
            E::Shape { array, .. } | E::Mismatch { array, .. } => Self {
                argument: argument(array),
                ..Self::default()
            },
            E::CellLength {
                array, run, step, ..
            }
            | E::NonFinite { array, run, step } => Self {
                argument: argument(array),
                run: Some(*run),
                step: Some(*step),
                ..Self::default()
            },
            E::TimesNotIncreasing { step } => Self {
                argument: argument("time"),
                step: Some(*step),
                ..Self::default()
            },
            E::InvalidOption { name, .. } => Self {
                argument: argument(name),
                ..Self::default()
            },
            E::GroupIndex { index, .. } => Self {
                argument: argument("groups"),
                index: Some(vec![*index]),
                ..Self::default()
            },
            E::DuplicateCell { run, step } | E::MissingCell { run, step, .. } => Self {
                run: Some(*run),
                step: Some(*step),
                ..Self::default()
            },
            _ => Self::default(),
        }
    }

    /// Where a tuning's error is at fault (the matrix, or the step of the measurements or the
    /// truth).
    pub(crate) fn of_tune(e: &kalibra_tune::TuneError) -> Self {
        use kalibra_tune::TuneError as T;
        let argument = |a: &str| Some(a.to_string());
        match e {
            T::NotSquare { matrix, .. }
            | T::Shape { matrix, .. }
            | T::NotSymmetric { matrix, .. } => Self {
                argument: argument(matrix),
                ..Self::default()
            },
            T::Ragged { matrix, row, .. } => Self {
                argument: argument(matrix),
                index: Some(vec![*row]),
                ..Self::default()
            },
            T::NotPositiveSemiDefinite { matrix, index, .. } => Self {
                argument: argument(matrix),
                index: Some(vec![*index]),
                ..Self::default()
            },
            T::NonFinite { what, step } => Self {
                // The sequence's argument is `measurements`.
                argument: argument(if *what == "measurement" {
                    "measurements"
                } else {
                    what
                }),
                step: *step,
                ..Self::default()
            },
            T::MeasurementLength { step, .. } => Self {
                argument: argument("measurements"),
                step: Some(*step),
                ..Self::default()
            },
            T::TruthLength { step, .. } => Self {
                argument: argument("truth"),
                step: Some(*step),
                ..Self::default()
            },
            T::TruthSteps { .. } => Self {
                argument: argument("truth"),
                ..Self::default()
            },
            T::NoMeasurements => Self {
                argument: argument("measurements"),
                ..Self::default()
            },
            T::InvalidGrid { index, .. } => Self {
                argument: argument("p"),
                index: Some(vec![*index]),
                ..Self::default()
            },
            _ => Self::default(),
        }
    }

    /// Where a reader's error is at fault: the file, row and column, or the array (the
    /// argument, for arrays handed over in memory) and index.
    pub(crate) fn of_io(e: &kalibra_io::Error) -> Self {
        use kalibra_io::Error as I;
        let file = e.file().map(|f| f.display().to_string());
        let at = match e {
            I::Array { array, index, .. } => Self {
                argument: Some(array.clone()),
                index: (!index.is_empty()).then(|| index.clone()),
                ..Self::default()
            },
            I::Refused { source, .. } => Self::of_eval(source),
            I::Evaluate { row, source, .. } => Self {
                row: *row,
                ..Self::of_eval(source)
            },
            I::Csv { row, column, .. } => Self {
                row: *row,
                column: *column,
                ..Self::default()
            },
            I::Json { line, column, .. } | I::Model { line, column, .. } => Self {
                row: line.map(|l| l as u64),
                column: *column,
                ..Self::default()
            },
            I::Tune { source, .. } => Self::of_tune(source),
            _ => Self::default(),
        };
        Self { file, ..at }
    }
}

/// The error as a `kalibra.KalibraError`, its attributes set from `at`.
pub(crate) fn error_at(message: impl Into<String>, at: &At) -> PyErr {
    let err = KalibraError::new_err(message.into());
    Python::attach(|py| {
        let value = err.value(py);
        // Setting an attribute on a fresh exception instance cannot fail but for memory; the
        // message is what matters then, so a failure leaves the class's None.
        let _ = value.setattr("argument", at.argument.clone());
        let _ = value.setattr("run", at.run);
        let _ = value.setattr("step", at.step);
        let _ = value.setattr(
            "index",
            at.index
                .as_ref()
                .and_then(|i| pyo3::types::PyTuple::new(py, i).ok()),
        );
        let _ = value.setattr("file", at.file.clone());
        let _ = value.setattr("row", at.row);
        let _ = value.setattr("column", at.column);
    });
    err
}

/// The error as a `kalibra.KalibraError`; `argument` is set when the message starts by
/// naming one (`argument NAME ...`).
pub(crate) fn error(message: impl Into<String>) -> PyErr {
    let message = message.into();
    let at = At::from_message(&message);
    error_at(message, &at)
}

/// An evaluation's error as a `kalibra.KalibraError`.
pub(crate) fn eval_error(e: &kalibra_eval::EvalError) -> PyErr {
    error_at(e.to_string(), &At::of_eval(e))
}

/// A tuning's error as a `kalibra.KalibraError`.
pub(crate) fn tune_error(e: &kalibra_tune::TuneError) -> PyErr {
    error_at(e.to_string(), &At::of_tune(e))
}

/// A reader's error as a `kalibra.KalibraError`.
pub(crate) fn io_error(e: &kalibra_io::Error) -> PyErr {
    error_at(e.to_string(), &At::of_io(e))
}

/// The native module `kalibra._kalibra`.
#[pymodule]
#[pyo3(name = "_kalibra")]
fn kalibra_py(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let error_type = m.py().get_type::<KalibraError>();
    // Class-level None: an error raised without a place still answers every attribute.
    for field in AT_FIELDS {
        error_type.setattr(field, m.py().None())?;
    }
    m.add("KalibraError", error_type)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    eval::register(m)?;
    metrics::register(m)?;
    filters::register(m)?;
    tune::register(m)?;
    estimate::register(m)?;
    montecarlo::register(m)?;
    shards::register(m)?;
    Ok(())
}
