//! `kalibra.monte_carlo`: a seeded Monte Carlo of a linear-Gaussian model through kalibra's
//! Kalman filter, evaluated, entirely in Rust.

use kalibra_filters::{Kf, Start};
use kalibra_linalg::{DMatrix, DVector, semidefinite_factor};
use kalibra_models::{LinearGaussian, LinearObservation, sample_with_factor, simulate};
use kalibra_sim::MonteCarlo;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{new_array, read};
use crate::error;
use crate::eval::{Report, evaluation};
use crate::filters::run_filter;

/// Why a run failed (a model's or the filter's error, as text).
#[derive(Debug)]
struct RunFailure(String);

impl std::fmt::Display for RunFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RunFailure {}

fn fail(e: impl std::fmt::Display) -> RunFailure {
    RunFailure(e.to_string())
}

/// One run's log, row-major per step.
struct RunLog {
    truth: Vec<f64>,
    estimate: Vec<f64>,
    covariance: Vec<f64>,
    innovation: Vec<f64>,
    innovation_cov: Vec<f64>,
}

fn square(obj: &Bound<'_, PyAny>, name: &str, dim: Option<usize>) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    match (a.shape.as_slice(), dim) {
        ([r, c], Some(d)) if *r == d && *c == d => Ok(DMatrix::from_row_slice(d, d, &a.data)),
        ([r, c], None) if r == c && *r > 0 => Ok(DMatrix::from_row_slice(*r, *c, &a.data)),
        (other, _) => Err(error(format!(
            "argument {name} has shape {other:?}; expected {}",
            dim.map_or("a square matrix".to_string(), |d| format!("({d}, {d})"))
        ))),
    }
}

/// A seeded Monte Carlo of the linear-Gaussian model `x_k = F x_{k-1} + w`, `z_k = H x_k + v`
/// through kalibra's Kalman filter, evaluated as `evaluate` does: entirely in Rust, in parallel
/// over runs, and bit-identical for any thread count (run i draws from ChaCha8 stream i of
/// `seed`).
///
/// Each run draws its initial state from N(x0, P0) and simulates `steps` steps with noise
/// w ~ N(0, Q), v ~ N(0, R), measuring every step; the filter starts from (x0, P0) as the
/// prior at the first measurement, with its own `filter_Q` and `filter_R` (default: the true
/// Q and R, a consistent filter; smaller ones make it optimistic). The log (truth, estimate,
/// covariance, innovation, its covariance, and F, H and the filter's Q, R for J1/J2) is
/// evaluated with `evaluate`'s options.
///
/// Args:
///     F: (n, n), H: (m, n), Q: (n, n), R: (m, m), x0: (n,), P0: (n, n): the true model.
///     runs, steps: the size; seed: of the study; threads: 0 for one per core.
///     filter_Q, filter_R: the filter's noise, if not the true one.
///     confidence, window, groups, lags: as for `evaluate`.
///     return_log: also return the log as a dict of arrays (evaluate's argument names).
///
/// Returns:
///     Report, or (Report, dict[str, numpy.ndarray]) with return_log.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> F = np.array([[1.0, 1.0], [0.0, 1.0]]); H = np.array([[1.0, 0.0]])
///     >>> Q = np.array([[0.25, 0.5], [0.5, 1.0]]); R = np.array([[4.0]])
///     >>> args = (F, H, Q, R, np.zeros(2), np.eye(2))
///     >>> kalibra.monte_carlo(*args, runs=200, steps=50, seed=1).verdict
///     'consistent'
///     >>> kalibra.monte_carlo(*args, runs=200, steps=50, seed=1, filter_R=R / 4).verdict
///     'optimistic'
#[pyfunction]
#[pyo3(signature = (
    F, H, Q, R, x0, P0, *, runs=100, steps=100, seed=0, threads=0, filter_Q=None,
    filter_R=None, confidence=0.95, window=None, groups=None, lags=10, return_log=false
))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn monte_carlo<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    H: &Bound<'py, PyAny>,
    Q: &Bound<'py, PyAny>,
    R: &Bound<'py, PyAny>,
    x0: &Bound<'py, PyAny>,
    P0: &Bound<'py, PyAny>,
    runs: usize,
    steps: usize,
    seed: u64,
    threads: usize,
    filter_Q: Option<&Bound<'py, PyAny>>,
    filter_R: Option<&Bound<'py, PyAny>>,
    confidence: f64,
    window: Option<usize>,
    groups: Option<&Bound<'py, PyDict>>,
    lags: usize,
    return_log: bool,
) -> PyResult<Bound<'py, PyAny>> {
    if runs == 0 || steps == 0 {
        return Err(error(format!(
            "arguments runs and steps must be at least 1 (got {runs} and {steps})"
        )));
    }
    let x0 = read(x0, "x0")?;
    let n = match x0.shape.as_slice() {
        [n] if *n > 0 => *n,
        other => {
            return Err(error(format!(
                "argument x0 has shape {other:?}; expected (n,) with n >= 1"
            )));
        }
    };
    let x0 = DVector::from_vec(x0.data);
    let f = square(F, "F", Some(n))?;
    let h_array = read(H, "H")?;
    let m = match h_array.shape.as_slice() {
        [m, c] if *c == n && *m > 0 => *m,
        other => {
            return Err(error(format!(
                "argument H has shape {other:?}; expected (m, {n}) (x0 has {n} components)"
            )));
        }
    };
    let h = DMatrix::from_row_slice(m, n, &h_array.data);
    let q = square(Q, "Q", Some(n))?;
    let r = square(R, "R", Some(m))?;
    let p0 = square(P0, "P0", Some(n))?;
    let fq = match filter_Q.filter(|o| !o.is_none()) {
        Some(o) => square(o, "filter_Q", Some(n))?,
        None => q.clone(),
    };
    let fr = match filter_R.filter(|o| !o.is_none()) {
        Some(o) => square(o, "filter_R", Some(m))?,
        None => r.clone(),
    };
    let evaluation = evaluation(confidence, window, groups, lags)?;
    let model = |what: &str, e: kalibra_models::ModelError| error(format!("{what}: {e}"));
    let truth_dynamics = LinearGaussian::new(f.clone(), q).map_err(|e| model("F, Q", e))?;
    let truth_sensor = LinearObservation::new(h.clone(), r).map_err(|e| model("H, R", e))?;
    let dynamics = LinearGaussian::new(f.clone(), fq.clone()).map_err(|e| model("filter_Q", e))?;
    let sensor = LinearObservation::new(h.clone(), fr.clone()).map_err(|e| model("filter_R", e))?;
    let (l0, _) = semidefinite_factor(&p0, "initial covariance P0")
        .map_err(|e| error(format!("argument P0: {e}")))?;
    Kf::new(&dynamics, &sensor, x0.clone(), p0.clone())
        .map_err(|e| error(format!("arguments x0, P0: {e}")))?;

    let one = |_run: usize, rng: &mut _| -> Result<RunLog, RunFailure> {
        let start = &x0 + sample_with_factor(&l0, rng);
        let truth = simulate(&truth_dynamics, &truth_sensor, start, steps, rng).map_err(fail)?;
        let zs: Vec<Option<DVector<f64>>> = truth.measurements.into_iter().map(Some).collect();
        let mut kf = Kf::new(&dynamics, &sensor, x0.clone(), p0.clone()).map_err(fail)?;
        let out = run_filter(&mut kf, &zs, Start::UpdateFirst, |_, _, _| {}).map_err(fail)?;
        Ok(RunLog {
            truth: truth
                .states
                .iter()
                .flat_map(|x| x.iter().copied())
                .collect(),
            estimate: out.estimate,
            covariance: out.covariance,
            innovation: out.innovation,
            innovation_cov: out.innovation_cov,
        })
    };
    let rows = |mat: &DMatrix<f64>| mat.transpose().iter().copied().collect::<Vec<f64>>();
    let model_arrays = [
        ("F", vec![n, n], rows(&f)),
        ("H", vec![m, n], rows(&h)),
        ("Q", vec![n, n], rows(&fq)),
        ("R", vec![m, m], rows(&fr)),
    ];
    let (report, log) = py
        .detach(|| {
            let logs = MonteCarlo::new(runs, seed)
                .threads(threads)
                .map(one)
                .map_err(|e| e.to_string())?;
            let gather = |field: fn(&RunLog) -> &Vec<f64>| -> Vec<f64> {
                logs.iter().flat_map(|l| field(l).iter().copied()).collect()
            };
            let mut arrays = vec![
                (
                    "truth".to_string(),
                    vec![runs, steps, n],
                    gather(|l| &l.truth),
                ),
                (
                    "estimate".to_string(),
                    vec![runs, steps, n],
                    gather(|l| &l.estimate),
                ),
                (
                    "covariance".to_string(),
                    vec![runs, steps, n, n],
                    gather(|l| &l.covariance),
                ),
                (
                    "innovation".to_string(),
                    vec![runs, steps, m],
                    gather(|l| &l.innovation),
                ),
                (
                    "innovation_cov".to_string(),
                    vec![runs, steps, m, m],
                    gather(|l| &l.innovation_cov),
                ),
            ];
            arrays.extend(
                model_arrays
                    .iter()
                    .map(|(name, shape, data)| (name.to_string(), shape.clone(), data.clone())),
            );
            // The arrays are copied only when the caller wants them back.
            let (given, kept) = if return_log {
                (arrays.clone(), Some(arrays))
            } else {
                (arrays, None)
            };
            let log = kalibra_cli::input::log_from_arrays(given)?;
            let report = evaluation.evaluate(&log).map_err(|e| e.to_string())?;
            Ok::<_, String>((report, kept))
        })
        .map_err(error)?;
    let report = Bound::new(py, Report::new(report, "monte carlo"))?.into_any();
    match log {
        None => Ok(report),
        Some(arrays) => {
            let dict = PyDict::new(py);
            for (name, shape, data) in arrays {
                dict.set_item(name, new_array(py, &shape, data))?;
            }
            Ok(PyTuple::new(py, [report, dict.into_any()])?.into_any())
        }
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(monte_carlo, m)?)?;
    Ok(())
}
