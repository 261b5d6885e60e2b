//! Models whose functions are Python callables, for the EKF and the UKF.
//!
//! kalibra's model traits are infallible (a model returns a vector or a matrix), so a callable
//! that raises or returns the wrong shape cannot stop the filter directly. The first such
//! failure is kept in a [`Failure`] cell and the model returns NaN from then on; the filter then
//! stops at that step with a non-finite error, and the run raises the kept exception (as the
//! cause of a `KalibraError` naming the callable and the step) instead of the filter's error.

use std::sync::Mutex;

use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_models::{Dynamics, Measurement};
use numpy::PyArray1;
use pyo3::prelude::*;

use crate::arrays::read;
use crate::error;

/// The first failure of a callable during a run. A mutex, not a `RefCell`: maximum
/// likelihood evaluates candidates on several threads (each taking the GIL to call), so the
/// models holding it must be `Sync`.
#[derive(Default)]
pub(crate) struct Failure(Mutex<Option<PyErr>>);

impl Failure {
    /// The cell; a poisoned lock (a panic while it was held) still holds a valid `Option`.
    fn cell(&self) -> std::sync::MutexGuard<'_, Option<PyErr>> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The kept exception, if any, leaving the cell empty.
    pub fn take(&self) -> Option<PyErr> {
        self.cell().take()
    }

    fn failed(&self) -> bool {
        self.cell().is_some()
    }

    fn keep(&self, e: PyErr) {
        let mut cell = self.cell();
        if cell.is_none() {
            *cell = Some(e);
        }
    }
}

/// What a callable is called with.
enum Args<'a> {
    /// `func(x, k)`: a model function or Jacobian at a state and step.
    State(&'a DVector<f64>, usize),
    /// `func(z, zhat)`: a residual.
    Pair(&'a DVector<f64>, &'a DVector<f64>),
}

/// Calls `func` and reads its result as `shape`: a matrix exactly, a vector as any array of
/// that many values with at most one axis longer than 1 ((m,), (m, 1) or (1, m)).
fn call(
    failure: &Failure,
    func: &Py<PyAny>,
    what: &str,
    args: Args<'_>,
    shape: &[usize],
) -> Vec<f64> {
    let size = shape.iter().product();
    if failure.failed() {
        return vec![f64::NAN; size];
    }
    let at = match args {
        Args::State(_, k) => format!(" at step {k}"),
        Args::Pair(..) => String::new(),
    };
    let result = Python::attach(|py| -> PyResult<Vec<f64>> {
        let out = match args {
            Args::State(x, k) => func.call1(py, (PyArray1::from_slice(py, x.as_slice()), k)),
            Args::Pair(a, b) => func.call1(
                py,
                (
                    PyArray1::from_slice(py, a.as_slice()),
                    PyArray1::from_slice(py, b.as_slice()),
                ),
            ),
        }
        .map_err(|e| {
            let wrapped = error(format!("{what} raised{at}: {e}"));
            wrapped.set_cause(py, Some(e));
            wrapped
        })?;
        let a = read(out.bind(py), &format!("{what} (its result{at})"))?;
        let matches = if shape.len() == 1 {
            a.data.len() == size && a.shape.iter().filter(|&&d| d != 1).count() <= 1
        } else {
            a.shape == shape
        };
        if !matches {
            return Err(error(format!(
                "{what} returned shape {:?}{at}; expected {shape:?}",
                a.shape
            )));
        }
        Ok(a.data)
    });
    result.unwrap_or_else(|e| {
        failure.keep(e);
        vec![f64::NAN; size]
    })
}

/// A row-major `rows x cols` result as a matrix.
fn matrix(rows: usize, cols: usize, data: &[f64]) -> DMatrix<f64> {
    DMatrix::from_row_slice(rows, cols, data)
}

/// `x_{k+1} = f(x_k, k) + w`, `w ~ N(0, Q)`, with the Jacobian `F_jacobian(x, k)` if given
/// (the EKF requires it).
pub(crate) struct PyDynamics<'a> {
    pub f: &'a Py<PyAny>,
    pub jacobian: Option<&'a Py<PyAny>>,
    pub q: &'a DMatrix<f64>,
    pub failure: &'a Failure,
}

impl Dynamics<Dyn> for PyDynamics<'_> {
    fn state_dim(&self) -> Dyn {
        Dyn(self.q.nrows())
    }

    fn transition(&self, k: usize, x: &DVector<f64>) -> DVector<f64> {
        let n = self.q.nrows();
        DVector::from_vec(call(self.failure, self.f, "f", Args::State(x, k), &[n]))
    }

    fn jacobian(&self, k: usize, x: &DVector<f64>) -> DMatrix<f64> {
        let n = self.q.nrows();
        match self.jacobian {
            Some(func) => matrix(
                n,
                n,
                &call(self.failure, func, "F_jacobian", Args::State(x, k), &[n, n]),
            ),
            // Only the UKF runs without Jacobians, and it asks for one only to record the
            // prior's split into propagated covariance and noise (and H where the prior has no
            // Cholesky factor), which nothing `run` returns reads: the identity will do.
            None => DMatrix::identity(n, n),
        }
    }

    fn noise_cov(&self, _k: usize) -> DMatrix<f64> {
        self.q.clone()
    }
}

/// `z_k = h(x_k, k) + v`, `v ~ N(0, R)`, with the Jacobian `H_jacobian(x, k)` if given and the
/// residual `residual(z, zhat)` if given (angles), else `z - zhat`.
pub(crate) struct PyMeasurement<'a> {
    pub h: &'a Py<PyAny>,
    pub jacobian: Option<&'a Py<PyAny>>,
    pub residual: Option<&'a Py<PyAny>>,
    pub r: &'a DMatrix<f64>,
    pub n: usize,
    pub failure: &'a Failure,
}

impl Measurement<Dyn, Dyn> for PyMeasurement<'_> {
    fn meas_dim(&self) -> Dyn {
        Dyn(self.r.nrows())
    }

    fn expected_state_dim(&self) -> Option<usize> {
        Some(self.n)
    }

    fn measure(&self, k: usize, x: &DVector<f64>) -> DVector<f64> {
        let m = self.r.nrows();
        DVector::from_vec(call(self.failure, self.h, "h", Args::State(x, k), &[m]))
    }

    fn jacobian(&self, k: usize, x: &DVector<f64>) -> DMatrix<f64> {
        let (m, n) = (self.r.nrows(), self.n);
        match self.jacobian {
            Some(func) => matrix(
                m,
                n,
                &call(self.failure, func, "H_jacobian", Args::State(x, k), &[m, n]),
            ),
            // As for the dynamics: only the UKF's step record would read it.
            None => DMatrix::zeros(m, n),
        }
    }

    fn noise_cov(&self, _k: usize, _x: &DVector<f64>) -> DMatrix<f64> {
        self.r.clone()
    }

    fn residual(&self, z: &DVector<f64>, zhat: &DVector<f64>) -> DVector<f64> {
        match self.residual {
            Some(func) => {
                let m = self.r.nrows();
                DVector::from_vec(call(
                    self.failure,
                    func,
                    "residual",
                    Args::Pair(z, zhat),
                    &[m],
                ))
            }
            None => z - zhat,
        }
    }
}
