//! The building blocks: NEES, NIS, NCI, chi-square bands, RMSE and sliding windows on numpy
//! arrays, each computed by `kalibra_metrics` (NCI through `kalibra_eval`, as in `evaluate`).

use kalibra_linalg::{Covariance, DMatrix, DVector};
use kalibra_metrics::{ChiSquareBand, SquaredErrors};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

use crate::arrays::{Array, new_array, read};
use crate::{error, eval_error, io_error};

/// `index` (a flat index over `shape`) as the tuple numpy prints, `(r, k)`.
fn index_text(shape: &[usize], mut index: usize) -> String {
    let mut parts = vec![0; shape.len()];
    for (p, &d) in parts.iter_mut().zip(shape).rev() {
        *p = index % d.max(1);
        index /= d.max(1);
    }
    let parts: Vec<String> = parts.iter().map(ToString::to_string).collect();
    format!("({})", parts.join(", "))
}

/// Checks that `vector` is `(..., dim)` and `matrix` is `(..., dim, dim)` with the same leading
/// shape (and `other`, when given, the same shape as `vector`); returns `dim`.
fn check_cells(vectors: &[(&str, &Array)], (mname, matrix): (&str, &Array)) -> PyResult<usize> {
    let (vname, first) = vectors[0];
    let Some(&dim) = first.shape.last() else {
        return Err(error(format!(
            "argument {vname} is a scalar; expected (..., dim), e.g. (R, K, dim) or (K, dim)"
        )));
    };
    for (name, v) in &vectors[1..] {
        if v.shape != first.shape {
            return Err(error(format!(
                "argument {name} has shape {:?}, but {vname} has {:?}; they must agree",
                v.shape, first.shape
            )));
        }
    }
    let mut expected = first.shape.clone();
    expected.push(dim);
    if matrix.shape != expected {
        return Err(error(format!(
            "argument {mname} has shape {:?}; expected {expected:?} (one {dim}x{dim} matrix per \
             cell of {vname})",
            matrix.shape
        )));
    }
    if dim == 0 {
        return Err(error(format!("argument {vname} has vectors of length 0")));
    }
    Ok(dim)
}

/// `v^T M^-1 v` per cell, `v` the vector `vector(cell)`; NaN where a cell holds a NaN.
fn quadratic_forms(
    vector: impl Fn(usize) -> Vec<f64>,
    (mname, matrix): (&str, &Array),
    leading: &[usize],
    dim: usize,
    form: impl Fn(DVector<f64>, DMatrix<f64>) -> Result<f64, String>,
) -> PyResult<Vec<f64>> {
    let cells: usize = leading.iter().product();
    (0..cells)
        .map(|c| {
            let v = vector(c);
            let m = &matrix.data[c * dim * dim..(c + 1) * dim * dim];
            if v.iter().chain(m).any(|x| x.is_nan()) {
                return Ok(f64::NAN);
            }
            form(DVector::from_vec(v), DMatrix::from_row_slice(dim, dim, m)).map_err(|e| {
                error(format!(
                    "argument {mname} at {}: {e}",
                    index_text(leading, c)
                ))
            })
        })
        .collect()
}

/// The normalised estimation error squared per cell, `e^T P^-1 e` with `e = estimate - truth`.
///
/// Args:
///     truth, estimate: (..., n), e.g. (R, K, n) for R runs of K steps, or (K, n).
///     covariance: (..., n, n), the filter's covariance P at each cell.
///
/// Returns:
///     numpy.ndarray: the leading shape, (R, K) or (K,); NaN where a cell holds a NaN (not
///     logged). Its mean over runs divided by n is the ANEES of `evaluate`.
///
/// Raises:
///     KalibraError: shapes that disagree; a covariance that is not symmetric positive definite
///         or holds an infinity (naming the cell's index).
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> kalibra.nees(np.zeros(2), np.array([1.0, 2.0]), np.diag([1.0, 4.0]))
///     array(2.)
#[pyfunction]
fn nees<'py>(
    py: Python<'py>,
    truth: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    covariance: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let (x, xhat, p) = (
        read(truth, "truth")?,
        read(estimate, "estimate")?,
        read(covariance, "covariance")?,
    );
    let n = check_cells(&[("truth", &x), ("estimate", &xhat)], ("covariance", &p))?;
    let leading = x.leading(1).to_vec();
    let values = py.detach(|| {
        let error_at = |c: usize| {
            let (t, e) = (&x.data[c * n..(c + 1) * n], &xhat.data[c * n..(c + 1) * n]);
            e.iter().zip(t).map(|(e, t)| e - t).collect()
        };
        quadratic_forms(error_at, ("covariance", &p), &leading, n, |e, p| {
            kalibra_metrics::nees(&e, &p).map_err(|e| e.to_string())
        })
    })?;
    Ok(new_array(py, &leading, values))
}

/// The normalised innovation squared per cell, `nu^T S^-1 nu`.
///
/// Args:
///     innovation: (..., m), e.g. (R, K, m) or (K, m).
///     innovation_cov: (..., m, m), the innovation covariance S at each cell.
///
/// Returns:
///     numpy.ndarray: the leading shape, (R, K) or (K,); NaN where a cell holds a NaN (no
///     measurement). Its mean over runs divided by m is the ANIS of `evaluate`.
///
/// Raises:
///     KalibraError: shapes that disagree; an S that is not symmetric positive definite or holds
///         an infinity (naming the cell's index).
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> kalibra.nis(np.array([[2.0], [np.nan]]), np.array([[[4.0]], [[np.nan]]]))
///     array([ 1., nan])
#[pyfunction]
fn nis<'py>(
    py: Python<'py>,
    innovation: &Bound<'py, PyAny>,
    innovation_cov: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let (nu, s) = (
        read(innovation, "innovation")?,
        read(innovation_cov, "innovation_cov")?,
    );
    let m = check_cells(&[("innovation", &nu)], ("innovation_cov", &s))?;
    let leading = nu.leading(1).to_vec();
    let values = py.detach(|| {
        let vector = |c: usize| nu.data[c * m..(c + 1) * m].to_vec();
        quadratic_forms(vector, ("innovation_cov", &s), &leading, m, |nu, s| {
            let s = Covariance::new(s).map_err(|e| e.to_string())?;
            kalibra_metrics::nis(&nu, &s).map_err(|e| e.to_string())
        })
    })?;
    Ok(new_array(py, &leading, values))
}

/// The non-credibility index per step (Li and Zhao), in dB: how far the filter's covariance is
/// from the Monte Carlo mean-square error, 0 if credible, above 0 optimistic.
///
/// The `nci_per_step` of `evaluate` on the same arrays: cells that were not logged (all NaN)
/// or whose covariance is NaN, asymmetric or not positive definite are left out, and a step
/// needs at least 2 valid runs.
///
/// Args:
///     truth, estimate: (R, K, n).
///     covariance: (R, K, n, n).
///
/// Returns:
///     numpy.ndarray: (K,), NaN at steps with fewer than 2 valid runs.
///
/// Raises:
///     KalibraError: as `evaluate`.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rng = np.random.default_rng(0)
///     >>> est = 2.0 * rng.normal(size=(2000, 1, 1))        # errors of variance 4
///     >>> cov = np.ones((2000, 1, 1, 1))                    # the filter claims 1
///     >>> round(float(kalibra.nci(np.zeros_like(est), est, cov)[0]), 1)  # 10 log10(4)
///     6.0
#[pyfunction]
fn nci<'py>(
    py: Python<'py>,
    truth: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    covariance: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let arrays: Vec<(String, Vec<usize>, Vec<f64>)> = [
        ("truth", truth),
        ("estimate", estimate),
        ("covariance", covariance),
    ]
    .into_iter()
    .map(|(name, obj)| read(obj, name).map(|a| (name.to_string(), a.shape, a.data)))
    .collect::<PyResult<_>>()?;
    let values = py.detach(|| {
        let log = kalibra_io::input::log_from_arrays(arrays).map_err(|e| io_error(&e))?;
        let report = kalibra_eval::Evaluation::new()
            .evaluate(&log)
            .map_err(|e| eval_error(&e))?;
        Ok::<_, PyErr>(report.nci_per_step)
    })?;
    let k = values.len();
    let values = values.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect();
    Ok(new_array(py, &[k], values))
}

/// The two-sided chi-square band of the mean of `samples` independent chi-square variables of
/// `dof` degrees of freedom: where the mean NEES (dof = n) or mean NIS (dof = m) over `samples`
/// runs of a consistent filter falls with probability `confidence`.
///
/// Args:
///     dof: degrees of freedom of one sample, positive.
///     samples: how many samples are averaged, at least 1.
///     confidence: in (0, 1).
///     normalized: divide the band by dof, for the ANEES and ANIS of `evaluate` (mean / n).
///
/// Returns:
///     tuple[float, float]: (lower, upper).
///
/// Example:
///     >>> import kalibra
///     >>> lower, upper = kalibra.chi2_band(2, 50, 0.95)   # Bar-Shalom et al.: [1.5, 2.6]
///     >>> round(lower, 1), round(upper, 1)
///     (1.5, 2.6)
#[pyfunction]
#[pyo3(signature = (dof, samples, confidence=0.95, normalized=false))]
fn chi2_band(dof: f64, samples: usize, confidence: f64, normalized: bool) -> PyResult<(f64, f64)> {
    let band = if normalized {
        ChiSquareBand::for_normalized_mean(dof, samples, confidence)
    } else {
        ChiSquareBand::for_mean(dof, samples, confidence)
    }
    .map_err(|e| error(e.to_string()))?;
    Ok((band.lower, band.upper))
}

/// The root-mean-square error of `estimate - truth`, per component.
///
/// Args:
///     truth, estimate: (R, K, n) or (K, n).
///     over: "runs" for the RMSE over runs at each step, (K, n), as `evaluate` reports it per
///         component; "time" for the RMSE over the steps of each run, (R, n) or (n,).
///
/// Cells with a NaN or an infinity (not logged) are left out; NaN where no cell remains.
///
/// Returns:
///     numpy.ndarray: (K, n) for over="runs", (R, n) or (n,) for over="time".
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> est = np.array([[[3.0], [1.0]], [[-4.0], [np.nan]]])   # 2 runs, 2 steps, n = 1
///     >>> kalibra.rmse(np.zeros_like(est), est)
///     array([[3.53553391],
///            [1.        ]])
#[pyfunction]
#[pyo3(signature = (truth, estimate, over="runs"))]
fn rmse<'py>(
    py: Python<'py>,
    truth: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    over: &str,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let (x, xhat) = (read(truth, "truth")?, read(estimate, "estimate")?);
    if x.shape != xhat.shape {
        return Err(error(format!(
            "argument estimate has shape {:?}, but truth has {:?}; they must agree",
            xhat.shape, x.shape
        )));
    }
    let (runs, steps, n) = match x.shape.as_slice() {
        [r, k, n] => (*r, *k, *n),
        [k, n] => (1, *k, *n),
        other => {
            return Err(error(format!(
                "argument truth has shape {other:?}; expected (R, K, n) or (K, n)"
            )));
        }
    };
    let errors: Vec<f64> = xhat.data.iter().zip(&x.data).map(|(e, t)| e - t).collect();
    let cell = |r: usize, k: usize| {
        let c = (r * steps + k) * n;
        let e = &errors[c..c + n];
        e.iter().all(|v| v.is_finite()).then_some(e)
    };
    match over {
        "runs" => {
            let mut acc = SquaredErrors::new(steps, n);
            for r in 0..runs {
                for k in 0..steps {
                    if let Some(e) = cell(r, k) {
                        acc.push_slice(k, e).map_err(|e| error(e.to_string()))?;
                    }
                }
            }
            let values = (0..steps)
                .flat_map(|k| (0..n).map(move |i| (k, i)))
                .map(|(k, i)| acc.rmse(k, i).map_err(|e| error(e.to_string())))
                .collect::<PyResult<_>>()?;
            Ok(new_array(py, &[steps, n], values))
        }
        "time" => {
            let mut values = Vec::with_capacity(runs * n);
            for r in 0..runs {
                for i in 0..n {
                    let series: Vec<f64> = (0..steps)
                        .filter_map(|k| cell(r, k).map(|e| e[i]))
                        .collect();
                    values.push(kalibra_metrics::rmse(&series).unwrap_or(f64::NAN));
                }
            }
            let shape = if x.shape.len() == 3 {
                vec![runs, n]
            } else {
                vec![n]
            };
            Ok(new_array(py, &shape, values))
        }
        other => Err(error(format!(
            "argument over is {other:?}; expected \"runs\" or \"time\""
        ))),
    }
}

/// Forward sliding-window RMSE, bias and standard deviation of an error series: the window k
/// holds samples k .. k + window - 1 (`kalibra_metrics::sliding_window`, exact to rounding
/// even for errors on a large offset).
///
/// Args:
///     errors: (N,) one series, or (N, c) c series side by side (e.g. the components of
///         `estimate - truth` of one run).
///     window: samples per window, at least 2 and at most N.
///
/// Returns:
///     tuple[numpy.ndarray, numpy.ndarray, numpy.ndarray]: (rmse, bias, std), each (N - window
///     + 1,) or (N - window + 1, c); std divides by window - 1.
///
/// Raises:
///     KalibraError: a window below 2 or above N, a NaN or infinite error (naming the column).
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rmse, bias, std = kalibra.sliding_window(np.array([1.0, 3.0, 3.0, 5.0]), 2)
///     >>> bias
///     array([2., 3., 4.])
#[pyfunction]
#[allow(clippy::type_complexity)]
fn sliding_window<'py>(
    py: Python<'py>,
    errors: &Bound<'py, PyAny>,
    window: usize,
) -> PyResult<(
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
)> {
    let e = read(errors, "errors")?;
    let (len, cols) = match e.shape.as_slice() {
        [n] => (*n, 1),
        [n, c] => (*n, *c),
        other => {
            return Err(error(format!(
                "argument errors has shape {other:?}; expected (N,) or (N, c)"
            )));
        }
    };
    let columns = py.detach(|| {
        (0..cols)
            .map(|c| {
                let series: Vec<f64> = (0..len).map(|k| e.data[k * cols + c]).collect();
                kalibra_metrics::sliding_window(&series, window).map_err(|err| {
                    let column = if e.shape.len() == 2 {
                        format!(" column {c}")
                    } else {
                        String::new()
                    };
                    error(format!("argument errors{column} (window {window}): {err}"))
                })
            })
            .collect::<PyResult<Vec<_>>>()
    })?;
    let windows = columns.first().map_or(0, kalibra_metrics::WindowStats::len);
    let shape: Vec<usize> = if e.shape.len() == 2 {
        vec![windows, cols]
    } else {
        vec![windows]
    };
    let gather = |f: fn(&kalibra_metrics::WindowStats) -> &Vec<f64>| {
        (0..windows)
            .flat_map(|w| columns.iter().map(move |s| f(s)[w]))
            .collect::<Vec<f64>>()
    };
    Ok((
        new_array(py, &shape, gather(|s| &s.rmse)),
        new_array(py, &shape, gather(|s| &s.bias)),
        new_array(py, &shape, gather(|s| &s.std)),
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(nees, m)?)?;
    m.add_function(wrap_pyfunction!(nis, m)?)?;
    m.add_function(wrap_pyfunction!(nci, m)?)?;
    m.add_function(wrap_pyfunction!(chi2_band, m)?)?;
    m.add_function(wrap_pyfunction!(rmse, m)?)?;
    m.add_function(wrap_pyfunction!(sliding_window, m)?)?;
    Ok(())
}
