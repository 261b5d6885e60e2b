//! The filters on numpy arrays: `KalmanFilter` (kalibra's `Kf` on run-time sizes).

use kalibra_filters::{Filter, Kf, Start};
use kalibra_linalg::{DMatrix, DVector};
use kalibra_models::{LinearGaussian, LinearObservation};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{Array, new_array, read};
use crate::error;

/// A matrix argument of shape `(rows, cols)`.
fn matrix(obj: &Bound<'_, PyAny>, name: &str, rows: usize, cols: usize) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    if a.shape != [rows, cols] {
        return Err(error(format!(
            "argument {name} has shape {:?}; expected ({rows}, {cols})",
            a.shape
        )));
    }
    Ok(DMatrix::from_row_slice(rows, cols, &a.data))
}

/// The outputs of one run: per row of the measurements, row-major.
#[derive(Default)]
struct Outputs {
    estimate: Vec<f64>,
    covariance: Vec<f64>,
    prior: Vec<f64>,
    prior_covariance: Vec<f64>,
    innovation: Vec<f64>,
    innovation_cov: Vec<f64>,
    nis: Vec<f64>,
    log_likelihood: Vec<f64>,
}

/// One field of [`Outputs`].
type Field = fn(&Outputs) -> &Vec<f64>;

fn push_matrix(out: &mut Vec<f64>, m: &DMatrix<f64>) {
    // nalgebra stores columns; numpy wants rows.
    out.extend(m.transpose().iter());
}

/// The linear Kalman filter `x_k = F x_{k-1} + w`, `z_k = H x_k + v`, `w ~ N(0, Q)`,
/// `v ~ N(0, R)`, run in Rust (kalibra's `Kf`: Joseph-form update, the gain by a Cholesky solve
/// with S, every covariance symmetrised).
///
/// Args:
///     F: (n, n) transition matrix.
///     H: (m, n) measurement matrix.
///     Q: (n, n) process noise covariance, symmetric positive semi-definite.
///     R: (m, m) measurement noise covariance, symmetric positive semi-definite.
///     x0: (n,) initial mean.
///     P0: (n, n) initial covariance, symmetric positive semi-definite.
///     start: "predict_first" (default, FilterPy's order: x0 is one step before the first
///         measurement, so each row is predict then update) or "update_first" (x0 is the prior
///         at the first measurement).
///
/// Raises:
///     KalibraError: a wrong shape (naming the argument), a non-finite matrix, a Q, R or P0 that
///         is not symmetric positive semi-definite.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> kf = kalibra.KalmanFilter(F=[[1.0, 1.0], [0.0, 1.0]], H=[[1.0, 0.0]],
///     ...                           Q=0.01 * np.eye(2), R=[[1.0]], x0=[0.0, 1.0], P0=np.eye(2))
///     >>> z = np.array([[1.1], [np.nan], [2.9], [4.2]])   # no measurement at row 1
///     >>> out = kf.run(z)
///     >>> out["estimate"].shape, out["covariance"].shape, out["nis"].shape
///     ((4, 2), (4, 2, 2), (4,))
///     >>> bool(np.isnan(out["nis"][1]))
///     True
#[pyclass(module = "kalibra", frozen)]
pub struct KalmanFilter {
    dynamics: LinearGaussian<kalibra_linalg::Dyn>,
    sensor: LinearObservation<kalibra_linalg::Dyn, kalibra_linalg::Dyn>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    start: Start,
    n: usize,
    m: usize,
}

impl KalmanFilter {
    /// One run over `rows` measurement rows of `m` values (NaN rows: no measurement).
    fn run_one(&self, z: &[f64], rows: usize) -> Result<Outputs, String> {
        let (n, m) = (self.n, self.m);
        let mut zs = Vec::with_capacity(rows);
        for k in 0..rows {
            let row = &z[k * m..(k + 1) * m];
            let nan = row.iter().filter(|v| v.is_nan()).count();
            zs.push(match nan {
                0 => Some(DVector::from_column_slice(row)),
                _ if nan == m => None,
                _ => {
                    return Err(format!(
                        "row {k} holds NaN in some components only; a row is a measurement or \
                         all NaN (none)"
                    ));
                }
            });
        }
        let mut kf = Kf::new(
            &self.dynamics,
            &self.sensor,
            self.x0.clone(),
            self.p0.clone(),
        )
        .map_err(|e| e.to_string())?;
        let trajectory = kf
            .run_all(zs.iter().map(Option::as_ref), self.start)
            .map_err(|e| {
                // The filter's step index counts from x0; with predict_first row k is step k + 1.
                format!("{e} (x0 is step 0; {:?})", self.start)
            })?;
        let mut out = Outputs::default();
        let nan = |len: usize| std::iter::repeat_n(f64::NAN, len);
        for entry in &trajectory.entries()[1..] {
            out.estimate.extend(entry.mean().iter());
            push_matrix(&mut out.covariance, entry.covariance());
            match entry.record() {
                Some(rec) => {
                    out.prior.extend(rec.prior().mean.iter());
                    push_matrix(&mut out.prior_covariance, &rec.prior().cov);
                    out.innovation.extend(rec.innovation().iter());
                    push_matrix(&mut out.innovation_cov, rec.s_matrix());
                    out.nis.push(rec.nis());
                    out.log_likelihood.push(rec.log_likelihood());
                }
                None => {
                    out.prior.extend(entry.mean().iter());
                    push_matrix(&mut out.prior_covariance, entry.covariance());
                    out.innovation.extend(nan(m));
                    out.innovation_cov.extend(nan(m * m));
                    out.nis.push(f64::NAN);
                    out.log_likelihood.push(f64::NAN);
                }
            }
        }
        debug_assert_eq!(out.estimate.len(), rows * n);
        Ok(out)
    }
}

#[pymethods]
impl KalmanFilter {
    #[new]
    #[pyo3(signature = (F, H, Q, R, x0, P0, start="predict_first"))]
    #[allow(non_snake_case)]
    fn new(
        F: &Bound<'_, PyAny>,
        H: &Bound<'_, PyAny>,
        Q: &Bound<'_, PyAny>,
        R: &Bound<'_, PyAny>,
        x0: &Bound<'_, PyAny>,
        P0: &Bound<'_, PyAny>,
        start: &str,
    ) -> PyResult<Self> {
        let x0 = read(x0, "x0")?;
        let n = match x0.shape.as_slice() {
            [n] if *n > 0 => *n,
            other => {
                return Err(error(format!(
                    "argument x0 has shape {other:?}; expected (n,) with n >= 1"
                )));
            }
        };
        let h_array = read(H, "H")?;
        let m = match h_array.shape.as_slice() {
            [m, cols] if *cols == n && *m > 0 => *m,
            other => {
                return Err(error(format!(
                    "argument H has shape {other:?}; expected (m, {n}) (x0 has {n} components)"
                )));
            }
        };
        let h = DMatrix::from_row_slice(m, n, &h_array.data);
        let f = matrix(F, "F", n, n)?;
        let q = matrix(Q, "Q", n, n)?;
        let r = matrix(R, "R", m, m)?;
        let p0 = matrix(P0, "P0", n, n)?;
        let start = match start {
            "predict_first" => Start::PredictFirst,
            "update_first" => Start::UpdateFirst,
            other => {
                return Err(error(format!(
                    "argument start is {other:?}; expected \"predict_first\" or \"update_first\""
                )));
            }
        };
        let model = |e: kalibra_models::ModelError| error(e.to_string());
        let dynamics = LinearGaussian::new(f, q).map_err(model)?;
        let sensor = LinearObservation::new(h, r).map_err(model)?;
        let x0 = DVector::from_vec(x0.data);
        // Checks x0 and P0 once, here, so that a bad one is an error of the constructor.
        Kf::new(&dynamics, &sensor, x0.clone(), p0.clone())
            .map_err(|e| error(format!("arguments x0, P0: {e}")))?;
        Ok(Self {
            dynamics,
            sensor,
            x0,
            p0,
            start,
            n,
            m,
        })
    }

    /// The state dimension n.
    #[getter]
    fn state_dim(&self) -> usize {
        self.n
    }

    /// The measurement dimension m.
    #[getter]
    fn measurement_dim(&self) -> usize {
        self.m
    }

    /// Runs the filter from (x0, P0) over a measurement sequence, or over R sequences at once.
    ///
    /// Args:
    ///     measurements: (K, m), one row per step; a row of NaN has no measurement (the filter
    ///         predicts through it). Or (R, K, m): R independent runs, each from (x0, P0).
    ///
    /// Returns:
    ///     dict[str, numpy.ndarray]: per row (and run), with a leading R axis for (R, K, m):
    ///     "estimate" (K, n) and "covariance" (K, n, n), the posterior (the prediction at rows
    ///     without a measurement); "prior" (K, n) and "prior_covariance" (K, n, n);
    ///     "innovation" (K, m) and "innovation_cov" (K, m, m), the residual and its covariance
    ///     S; "nis" (K,); "log_likelihood" (K,), ln N(innovation; 0, S). The last four are NaN
    ///     at rows without a measurement. The names are `evaluate`'s arguments.
    ///
    /// Raises:
    ///     KalibraError: a wrong shape, a row that is NaN in some components only, a step
    ///         whose S is not positive definite or whose output is not finite (naming the run
    ///         and step).
    fn run<'py>(
        &self,
        py: Python<'py>,
        measurements: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let z: Array = read(measurements, "measurements")?;
        let m = self.m;
        let (runs, rows, batch) = match z.shape.as_slice() {
            [k, mm] if *mm == m => (1, *k, false),
            [r, k, mm] if *mm == m => (*r, *k, true),
            other => {
                return Err(error(format!(
                    "argument measurements has shape {other:?}; expected (K, {m}) or (R, K, {m}) \
                     (H has {m} rows)"
                )));
            }
        };
        let outputs = py.detach(|| {
            (0..runs)
                .map(|r| {
                    self.run_one(&z.data[r * rows * m..(r + 1) * rows * m], rows)
                        .map_err(|e| {
                            let run = if batch {
                                format!(" run {r}:")
                            } else {
                                String::new()
                            };
                            error(format!("argument measurements:{run} {e}"))
                        })
                })
                .collect::<PyResult<Vec<Outputs>>>()
        })?;
        let (n, lead) = (self.n, if batch { vec![runs, rows] } else { vec![rows] });
        let shape = |tail: &[usize]| [lead.as_slice(), tail].concat();
        let dict = PyDict::new(py);
        let gather =
            |f: Field| -> Vec<f64> { outputs.iter().flat_map(|o| f(o).iter().copied()).collect() };
        let fields: [(&str, Vec<usize>, Field); 8] = [
            ("estimate", shape(&[n]), |o| &o.estimate),
            ("covariance", shape(&[n, n]), |o| &o.covariance),
            ("prior", shape(&[n]), |o| &o.prior),
            ("prior_covariance", shape(&[n, n]), |o| &o.prior_covariance),
            ("innovation", shape(&[m]), |o| &o.innovation),
            ("innovation_cov", shape(&[m, m]), |o| &o.innovation_cov),
            ("nis", shape(&[]), |o| &o.nis),
            ("log_likelihood", shape(&[]), |o| &o.log_likelihood),
        ];
        for (key, shape, field) in fields {
            dict.set_item(key, new_array(py, &shape, gather(field)))?;
        }
        Ok(dict)
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.KalmanFilter n={} m={} start={:?}>",
            self.n, self.m, self.start
        )
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<KalmanFilter>()?;
    Ok(())
}
