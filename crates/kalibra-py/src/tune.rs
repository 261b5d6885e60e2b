//! `kalibra.sweep_q` and its `TuneReport`: the tuning of `kalibra tune`, on numpy arrays.

use std::path::{Path, PathBuf};

use kalibra_io::document::Document;
use kalibra_tune::{DMatrix, DVector, Start, TuneProblem, Tuning};
use numpy::PyArrayDyn;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;

use crate::arrays::{new_array, read};
use crate::{error, tune_error};

/// The J1/J2 sweep of `Q = 10^p Q_nom` and its recommendation: what `kalibra tune` writes as
/// `report.json`, with the command's report files on request.
///
/// Returned by `kalibra.sweep_q`. `to_dict()` holds every number (the keys of `kalibra tune`'s
/// `report.json`); `p`, `j1`, `j2` are the sweep as arrays; `crossover` and `recommended_q`
/// the answer; `save(dir)` writes the files the command writes.
#[pyclass(module = "kalibra", frozen)]
pub struct TuneReport {
    report: kalibra_tune::TuneReport,
    doc: Document,
}

#[pymethods]
impl TuneReport {
    /// The recommendation in one line of words, as `kalibra tune` prints it.
    #[getter]
    fn headline(&self) -> String {
        self.doc.headline().to_string()
    }

    /// The exponents p of the grid, (P,).
    #[getter]
    fn p<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        self.series(py, |p| p.p)
    }

    /// J1 at every p, (P,).
    #[getter]
    fn j1<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        self.series(py, |p| p.j1)
    }

    /// J2 at every p, (P,).
    #[getter]
    fn j2<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        self.series(py, |p| p.j2)
    }

    /// The crossover of J1 and J2 as a dict (p, j, nq_log10_mean, nq_mean_log10), or None when
    /// the curves do not cross on the grid (the report's findings say which way to move it).
    #[getter]
    fn crossover<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match &self.report.crossover {
            Some(c) => {
                let json = serde_json::to_string(c).map_err(|e| error(e.to_string()))?;
                Ok(Some(py.import("json")?.call_method1("loads", (json,))?))
            }
            None => Ok(None),
        }
    }

    /// The recommended process noise `Q = 10^p_c Q_nom`, (n, n), or None without a crossover.
    #[getter]
    fn recommended_q<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArrayDyn<f64>>> {
        self.report.recommended_q.as_ref().map(|rows| {
            let n = rows.len();
            new_array(py, &[n, n], rows.iter().flatten().copied().collect())
        })
    }

    /// Every number of the report as a dict with the keys of `kalibra tune`'s `report.json`.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?.call_method1("loads", (self.to_json()?,))
    }

    /// The report as JSON text: `report.json` without its final newline.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.report)
            .map_err(|e| error(format!("cannot serialise the report: {e}")))
    }

    /// The report in Markdown: `report.md`.
    fn markdown(&self) -> String {
        self.doc.markdown()
    }

    /// The report as one self-contained HTML page: `report.html`.
    fn html(&self) -> String {
        self.doc.html()
    }

    fn _repr_html_(&self) -> String {
        self.doc.html()
    }

    /// Writes `report.json`, `report.md`, `j1j2.svg` (and `rmse.svg` with a truth) and
    /// `report.html` into `dir`, as `kalibra tune` does and through its writer.
    ///
    /// Raises:
    ///     OSError: `dir` holds something other than a report, or cannot be written.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        py.detach(|| kalibra_io::output::write_report(&dir, &self.report, &self.doc))
            .map_err(|e| PyOSError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.TuneReport: {} points; {}>",
            self.report.points.len(),
            self.doc.headline()
        )
    }
}

impl TuneReport {
    fn series<'py>(
        &self,
        py: Python<'py>,
        f: fn(&kalibra_tune::TunePoint) -> f64,
    ) -> Bound<'py, PyArrayDyn<f64>> {
        let values: Vec<f64> = self.report.points.iter().map(f).collect();
        new_array(py, &[values.len()], values)
    }
}

/// A `(rows, cols)` matrix argument.
fn matrix(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    match a.shape.as_slice() {
        [r, c] => Ok(DMatrix::from_row_slice(*r, *c, &a.data)),
        other => Err(error(format!(
            "argument {name} has shape {other:?}; expected a matrix (rows, cols)"
        ))),
    }
}

/// The rows of a `(K, dim)` sequence: a vector, or `None` for a row of NaN.
fn sequence(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Option<DVector<f64>>>> {
    let a = read(obj, name)?;
    let [_, dim] = a.shape[..] else {
        return Err(error(format!(
            "argument {name} has shape {:?}; expected (K, dim), one row per step",
            a.shape
        )));
    };
    if dim == 0 {
        return Err(error(format!("argument {name} has rows of length 0")));
    }
    a.data
        .chunks(dim)
        .enumerate()
        .map(|(k, row)| match row.iter().filter(|v| v.is_nan()).count() {
            0 => Ok(Some(DVector::from_column_slice(row))),
            nan if nan == dim => Ok(None),
            _ => Err(error(format!(
                "argument {name}: row {k} holds NaN in some components only; a row is all \
                 values or all NaN (none)"
            ))),
        })
        .collect()
}

/// Tunes the process noise of a linear model from recorded measurements: sweeps
/// `Q = 10^p Q_nom`, runs the Kalman filter at every p, and reports J1 and J2 (from the
/// innovations alone), both nq, their crossover and the recommended Q, as `kalibra tune` does
/// (papers 000 and 003's offline method; the same library underneath).
///
/// Args:
///     F: (n, n), H: (m, n), Q_nom: (n, n) the nominal process noise, R: (m, m), x0: (n,),
///         P0: (n, n).
///     measurements: (K, m), one row per step; a row of NaN has no measurement.
///     p: the grid of exponents as (from, to, step), `to` included.
///     truth: (K, n) true states (a row of NaN: unknown), for the RMSE at every p.
///     start: "predict_first" (default: x0 is one step before the first measurement) or
///         "update_first".
///     position: state components of the position RMSE.
///     p0_as_given: take P0 as given (asymmetric or indefinite, as some papers print it).
///     threads: for the sweep (0: one per core); the results do not depend on it.
///     names: the (model, measurements) names in the report's title.
///
/// Returns:
///     TuneReport: J1, J2 per p, the crossover and the recommended Q; `save(dir)` writes the
///     command's files.
///
/// Raises:
///     KalibraError: shapes that disagree (naming the matrix), non-finite values, a Q_nom, R or
///         P0 that is not symmetric positive semi-definite, no measurement at all, a bad grid.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rng = np.random.default_rng(3)
///     >>> F = np.array([[1.0, 1.0], [0.0, 1.0]]); H = np.array([[1.0, 0.0]])
///     >>> Q_true = np.array([[0.25, 0.5], [0.5, 1.0]]) * 0.01
///     >>> x, zs = np.zeros(2), []
///     >>> for k in range(400):
///     ...     x = F @ x + rng.multivariate_normal(np.zeros(2), Q_true)
///     ...     zs.append(H @ x + rng.normal(0.0, 1.0, 1))
///     >>> t = kalibra.sweep_q(F, H, np.array([[0.25, 0.5], [0.5, 1.0]]), np.eye(1),
///     ...                     np.zeros(2), 10 * np.eye(2), np.array(zs), p=(-4, 2, 0.25))
///     >>> t.j1.shape == t.p.shape, t.crossover is not None
///     (True, True)
#[pyfunction]
#[pyo3(signature = (
    F, H, Q_nom, R, x0, P0, measurements, *, p=(-6.0, 6.0, 0.5), truth=None,
    start="predict_first", position=None, p0_as_given=false, threads=0,
    names=("model".to_string(), "measurements".to_string())
))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn sweep_q(
    py: Python<'_>,
    F: &Bound<'_, PyAny>,
    H: &Bound<'_, PyAny>,
    Q_nom: &Bound<'_, PyAny>,
    R: &Bound<'_, PyAny>,
    x0: &Bound<'_, PyAny>,
    P0: &Bound<'_, PyAny>,
    measurements: &Bound<'_, PyAny>,
    p: (f64, f64, f64),
    truth: Option<&Bound<'_, PyAny>>,
    start: &str,
    position: Option<Vec<usize>>,
    p0_as_given: bool,
    threads: usize,
    names: (String, String),
) -> PyResult<TuneReport> {
    let x0 = read(x0, "x0")?;
    if x0.shape.len() != 1 {
        return Err(error(format!(
            "argument x0 has shape {:?}; expected (n,)",
            x0.shape
        )));
    }
    let build = if p0_as_given {
        TuneProblem::as_given
    } else {
        TuneProblem::new
    };
    let tune_error = |e: kalibra_tune::TuneError| tune_error(&e);
    let mut problem = build(
        matrix(F, "F")?,
        matrix(H, "H")?,
        matrix(Q_nom, "Q_nom")?,
        matrix(R, "R")?,
        DVector::from_vec(x0.data),
        matrix(P0, "P0")?,
        sequence(measurements, "measurements")?,
    )
    .map_err(tune_error)?;
    problem = problem.with_start(match start {
        "predict_first" => Start::PredictFirst,
        "update_first" => Start::UpdateFirst,
        other => {
            return Err(error(format!(
                "argument start is {other:?}; expected \"predict_first\" or \"update_first\""
            )));
        }
    });
    if let Some(t) = truth.filter(|t| !t.is_none()) {
        problem = problem
            .with_truth(sequence(t, "truth")?)
            .map_err(tune_error)?;
    }
    let mut tuning = Tuning::new()
        .exponents(p.0, p.1, p.2)
        .map_err(|e| error(format!("argument p: {e}")))?
        .threads(threads);
    if let Some(position) = position {
        tuning = tuning.position(position);
    }
    let report = py.detach(|| tuning.tune(&problem)).map_err(tune_error)?;
    let doc = Document::tune(Path::new(&names.0), Path::new(&names.1), &report);
    Ok(TuneReport { report, doc })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<TuneReport>()?;
    m.add_function(wrap_pyfunction!(sweep_q, m)?)?;
    Ok(())
}
