//! `kalibra.estimate_noise` and its `NoiseEstimate`: `Q` and `R` from measurements by maximum
//! likelihood, EM, ALS or J1/J2 on every parameter (`kalibra_tune`'s estimators), on numpy
//! arrays.

use std::path::{Path, PathBuf};

use kalibra_io::noise_report::NoiseReportFile;

use kalibra_tune::{
    Als, CovarianceForm, DMatrix, DVector, Em, LikelihoodFilter, MaximumLikelihood, Method,
    NoiseError, NoiseProblem, NoiseReport, NonlinearNoiseProblem, NonlinearProblemError,
    ParameterSweep, Parametrisation, ReportError, ReportOptions, Run, SigmaSet, Start,
};
use numpy::PyArrayDyn;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};
use serde::Serialize;

use crate::arrays::{new_array, read};
use crate::callbacks::{Failure, PyDynamics, PyMeasurement};
use crate::{At, error, error_at};

/// The estimators `estimate_noise` offers, by their names.
const METHODS: [&str; 4] = ["ml", "em", "als", "j1j2"];

/// The forms of a noise matrix, by their names.
const FORMS: [&str; 4] = ["fixed", "scaled", "diagonal", "full"];

/// The noise covariances `Q` and `R` estimated from measurements: what `kalibra tune
/// --method` writes as `report.json` (kalibra-tune's `NoiseReport`).
///
/// Returned by `kalibra.estimate_noise`. `Q` (n, n, the state's, `G Qw G^T`), `Qw` (the
/// channels'; `Q` itself without `G`) and `R` are the estimate as arrays; `parameters` lists
/// every free parameter on the matrices' own scale (a dict of `name`, `value`, `stderr`,
/// `ci95`, `at_bound`, `profile`); `identifiable` says what the data can separate;
/// `consistency` judges the filter with the estimate and with the starting guess on the data
/// (ANIS with its band, whiteness; ANEES and RMSE with the truth). `to_dict()` holds every
/// field (the keys of `report.json`); `save(dir)` writes `report.json`, `report.md`,
/// `report.html` and the profile figures.
#[pyclass(module = "kalibra", frozen)]
pub struct NoiseEstimate {
    report: NoiseReport,
    /// `report.json` as `kalibra tune --method` writes it (for a model given as callables, with
    /// the filter its likelihood ran through).
    file: NoiseReportFile,
    /// The (model, measurements) names of the report's title.
    names: (String, String),
}

fn matrix_array<'py>(py: Python<'py>, rows: &[Vec<f64>]) -> Bound<'py, PyArrayDyn<f64>> {
    let cols = rows.first().map_or(0, Vec::len);
    new_array(
        py,
        &[rows.len(), cols],
        rows.iter().flatten().copied().collect(),
    )
}

#[pymethods]
impl NoiseEstimate {
    /// The estimator: "ml", "em", "als" or "j1j2".
    #[getter]
    fn method(&self) -> &'static str {
        self.report.method.name()
    }

    /// The log-likelihood of the measurements at the estimate (natural log with the 2 pi
    /// constant; the sum of the Kalman filter's per-update log-densities), or None where the
    /// filter cannot run there.
    #[getter]
    fn log_likelihood(&self) -> Option<f64> {
        self.report.log_likelihood
    }

    /// The log-likelihood at the starting point (the forms' given matrices).
    #[getter]
    fn start_log_likelihood(&self) -> Option<f64> {
        self.report.start_log_likelihood
    }

    /// The state's process noise `Q = G Qw G^T` at the estimate, (n, n).
    #[getter(Q)]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        matrix_array(py, &self.report.q)
    }

    /// The noise of the channels `Qw` at the estimate, (g, g) (`Q` itself without `G`).
    #[getter(Qw)]
    fn qw<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        matrix_array(py, &self.report.qw)
    }

    /// The measurement noise `R` at the estimate, (m, m).
    #[getter(R)]
    fn r<'py>(&self, py: Python<'py>) -> Bound<'py, PyArrayDyn<f64>> {
        matrix_array(py, &self.report.r)
    }

    /// Every free parameter, in order (`Q`'s, then `R`'s; entries row by row of the lower
    /// triangle): a dict of `name` (`"q"`, `"r"` for a scaled form's multiplier,
    /// `"Qw[i,j]"`, `"R[i,j]"` for an entry), `value`, `stderr` and `ci95` (a `(low, high)`
    /// tuple from the observed information: ML, and converged EM; else None; an end at a
    /// bound is 0 or inf), `at_bound` (None, `"zero"` or `"infinity"`) and `profile` (the
    /// profile likelihood: a dict of `points` (value, log_likelihood, converged),
    /// `threshold` and the likelihood-ratio `interval`; None without one).
    #[getter]
    fn parameters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for p in &self.report.parameters {
            let d = PyDict::new(py);
            d.set_item("name", &p.name)?;
            d.set_item("value", p.value)?;
            d.set_item("stderr", p.stderr)?;
            d.set_item("ci95", p.ci95.map(|[lo, hi]| (lo, hi)))?;
            d.set_item(
                "at_bound",
                p.at_bound.map(|b| json_value(py, &b)).transpose()?,
            )?;
            d.set_item(
                "profile",
                p.profile
                    .as_ref()
                    .map(|pr| json_value(py, pr))
                    .transpose()?,
            )?;
            list.append(d)?;
        }
        Ok(list)
    }

    /// Whether the estimator met its stopping rule (ML: the gradient tolerance; EM: the
    /// relative tolerance, always for exact iterations; ALS: always; J1/J2: every swept
    /// parameter has a crossover).
    #[getter]
    fn converged(&self) -> bool {
        self.report.converged
    }

    /// The iterations run (ML: of the best start; EM: M-steps; ALS and J1/J2: 0).
    #[getter]
    fn iterations(&self) -> usize {
        self.report.iterations
    }

    /// What the data identify, as a dict: `source` ("observed information" or
    /// "least-squares matrix"), `parameters`, `rank`, `condition` (None: infinite),
    /// `unidentifiable` (the combinations the data cannot determine, in words) and
    /// `message`; None where it could not be computed.
    #[getter]
    fn identifiable<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.report
            .identifiability
            .as_ref()
            .map(|id| json_value(py, id))
            .transpose()
    }

    /// The filter with the estimate and with the starting guess judged on the data, as a
    /// dict `{"estimate": ..., "start": ...}`, each with `anis` (and its test), `whiteness`,
    /// `anees`, `rmse` and `rmse_per_component` (with the truth) and the `verdict` in words.
    #[getter]
    fn consistency<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_value(py, &self.report.consistency)
    }

    /// What the user must know about the estimate, in words (not converged, a parameter at a
    /// bound, unidentifiable parameters, local maxima, an ALS estimate that is not unique, a
    /// filter that failed).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.report.warnings.clone()
    }

    /// Every field as a dict with the keys of `report.json`.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_value(py, &self.file)
    }

    /// The report as JSON text: `report.json` without its final newline.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.file)
            .map_err(|e| error(format!("cannot serialise the report: {e}")))
    }

    /// Writes `report.json`, `report.md`, `report.html` and the profile figures into `dir`,
    /// as `kalibra tune --method` does and through its writer (the same bytes on the same
    /// model and data); a model given as callables gets the same files, its filter (the EKF
    /// or the UKF) named in them.
    ///
    /// Raises:
    ///     OSError: `dir` holds something other than a report, or cannot be written.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        let names = (Path::new(&self.names.0), Path::new(&self.names.1));
        py.detach(|| kalibra_io::noise_report::write_noise_report(&dir, &self.file, Some(names)))
            .map_err(|e| PyOSError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        let params: Vec<String> = self
            .report
            .parameters
            .iter()
            .map(|p| format!("{}={:.4}", p.name, p.value))
            .collect();
        format!(
            "<kalibra.NoiseEstimate method={} {}>",
            self.report.method.name(),
            params.join(" ")
        )
    }
}

/// A serialisable value as a Python object, through JSON.
fn json_value<'py>(py: Python<'py>, value: &impl Serialize) -> PyResult<Bound<'py, PyAny>> {
    let json = serde_json::to_string(value).map_err(|e| error(format!("cannot serialise: {e}")))?;
    py.import("json")?.call_method1("loads", (json,))
}

/// The Python argument of a library matrix name (`Qw` is given as `Q`).
fn argument_of(matrix: &str) -> &str {
    match matrix {
        "Qw" | "q" => "Q",
        "r" => "R",
        other => other.split('[').next().unwrap_or(other),
    }
}

/// A noise problem's error as a `KalibraError` naming the argument.
fn noise_error(e: &NoiseError) -> PyErr {
    use NoiseError as N;
    let named = |matrix: &str| At {
        argument: Some(argument_of(matrix).to_string()),
        ..At::default()
    };
    let at = match e {
        N::Shape { matrix, .. }
        | N::Matrix { matrix, .. }
        | N::NotDiagonal { matrix, .. }
        | N::ZeroNominal { matrix }
        | N::FixedEntryOutOfRange { matrix, .. }
        | N::FixedEntryInScaled { matrix }
        | N::Infeasible { matrix, .. } => named(matrix),
        N::Empty { what } | N::NonFinite { what } => named(what),
        N::NotPositive { name, .. } => named(name),
        N::NonFiniteMeasurement { run, step } | N::MeasurementLength { run, step, .. } => At {
            argument: Some("measurements".into()),
            run: Some(*run),
            step: Some(*step),
            ..At::default()
        },
        N::NoMeasurements => named("measurements"),
        _ => At::default(),
    };
    let message = match (&at.argument, e) {
        // NaN rows were read as missing steps already: what is left is an infinity.
        (_, N::NonFiniteMeasurement { run, step }) => format!(
            "argument measurements: run {run}, step {step} holds an infinity (a row of NaN is \
             a missing measurement)"
        ),
        (Some(a), _) => format!("argument {a}: {e}"),
        (None, _) => format!("arguments Q, R: {e}"),
    };
    error_at(message, &at)
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

/// A form's fixed entries: `(row, col)` pairs.
fn fixed_entries(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<(usize, usize)>> {
    obj.extract::<Vec<(usize, usize)>>().map_err(|_| {
        error(format!(
            "argument {name}: fixed must be a list of (row, col) pairs of non-negative integers"
        ))
    })
}

/// A noise form from its name, value and fixed entries.
fn form_named(
    kind: &str,
    value: &Bound<'_, PyAny>,
    fixed: Option<&Bound<'_, PyAny>>,
    name: &str,
) -> PyResult<CovarianceForm> {
    let value = matrix(value, name)?;
    let mut form = match kind {
        "fixed" => CovarianceForm::fixed(value),
        "scaled" => CovarianceForm::scaled(value),
        "diagonal" => CovarianceForm::diagonal(value),
        "full" => CovarianceForm::full(value),
        other => {
            return Err(error(format!(
                "argument {name}: form {other:?} is not one of {}",
                FORMS.map(|f| format!("{f:?}")).join(", ")
            )));
        }
    };
    if let Some(fixed) = fixed.filter(|f| !f.is_none()) {
        for (row, col) in fixed_entries(fixed, name)? {
            form = form.fix(row, col);
        }
    }
    Ok(form)
}

/// A noise argument: a matrix (fixed), `(form, value)`, `(form, value, fixed)`, or a dict
/// with the keys `form`, `value` and optionally `fixed`.
fn form_of(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<CovarianceForm> {
    if let Ok(dict) = obj.cast::<PyDict>() {
        for key in dict.keys() {
            let key: String = key.extract().unwrap_or_else(|_| key.to_string());
            if !["form", "value", "fixed"].contains(&key.as_str()) {
                return Err(error(format!(
                    "argument {name}: unknown key {key:?}; expected \"form\", \"value\" and \
                     optionally \"fixed\""
                )));
            }
        }
        let kind = dict
            .get_item("form")?
            .ok_or_else(|| error(format!("argument {name}: the dict has no \"form\"")))?;
        let kind: String = kind
            .extract()
            .map_err(|_| error(format!("argument {name}: \"form\" must be a string")))?;
        let value = dict
            .get_item("value")?
            .ok_or_else(|| error(format!("argument {name}: the dict has no \"value\"")))?;
        let fixed = dict.get_item("fixed")?;
        return form_named(&kind, &value, fixed.as_ref(), name);
    }
    if let Ok(tuple) = obj.cast::<PyTuple>()
        && tuple.len() > 0
        && tuple.get_item(0)?.is_instance_of::<PyString>()
    {
        let kind: String = tuple.get_item(0)?.extract()?;
        return match tuple.len() {
            2 => form_named(&kind, &tuple.get_item(1)?, None, name),
            3 => form_named(&kind, &tuple.get_item(1)?, Some(&tuple.get_item(2)?), name),
            k => Err(error(format!(
                "argument {name}: a tuple of {k} items; expected (form, value) or (form, value, \
                 fixed)"
            ))),
        };
    }
    if obj.is_instance_of::<PyString>() {
        let kind: String = obj.extract()?;
        return Err(error(format!(
            "argument {name} is the string {kind:?}; give (form, value), a dict or a matrix"
        )));
    }
    Ok(CovarianceForm::fixed(matrix(obj, name)?))
}

/// The runs of `(K, dim)` or `(R, K, dim)` rows of argument `name` (`measurements`, with
/// `dim` the rows of `H`, or `truth`, with `dim` the states): a row of NaN is a step without
/// one.
fn runs_of(obj: &Bound<'_, PyAny>, name: &str, dim: usize, why: &str) -> PyResult<Vec<Run>> {
    let a = read(obj, name)?;
    let (runs, k) = match a.shape.as_slice() {
        [k, d] if *d == dim => (1, *k),
        [r, k, d] if *d == dim => (*r, *k),
        other => {
            return Err(error(format!(
                "argument {name} has shape {other:?}; expected (K, {dim}) or (R, K, {dim}) \
                 ({why})"
            )));
        }
    };
    let batch = a.shape.len() == 3;
    (0..runs)
        .map(|r| {
            a.data[r * k * dim..(r + 1) * k * dim]
                .chunks(dim)
                .enumerate()
                .map(
                    |(step, row)| match row.iter().filter(|v| v.is_nan()).count() {
                        0 => Ok(Some(DVector::from_column_slice(row))),
                        nan if nan == dim => Ok(None),
                        _ => {
                            let run = if batch {
                                format!("run {r}, ")
                            } else {
                                String::new()
                            };
                            Err(error_at(
                                format!(
                                    "argument {name}: {run}step {step} holds NaN in some \
                                 components only; a row is all values or all NaN (none)"
                                ),
                                &At {
                                    argument: Some(name.into()),
                                    run: Some(r),
                                    step: Some(step),
                                    ..At::default()
                                },
                            ))
                        }
                    },
                )
                .collect()
        })
        .collect()
}

/// A report's error as a `KalibraError`: the truth's errors name it, the rest are the
/// estimator's refusal.
fn report_error(e: &ReportError, method: &str) -> PyErr {
    let truth = |run: Option<usize>, step: Option<usize>| At {
        argument: Some("truth".into()),
        run,
        step,
        ..At::default()
    };
    match e {
        ReportError::TruthRuns { .. } => {
            error_at(format!("argument truth: {e}"), &truth(None, None))
        }
        ReportError::TruthLength { run, .. } => {
            error_at(format!("argument truth: {e}"), &truth(Some(*run), None))
        }
        ReportError::TruthValue { run, step, .. } => error_at(
            format!("argument truth: {e}"),
            &truth(Some(*run), Some(*step)),
        ),
        ReportError::TooFewMeasurements { .. } => error_at(
            format!("argument measurements: {e}"),
            &At {
                argument: Some("measurements".into()),
                ..At::default()
            },
        ),
        _ => error(format!("estimate the noise by {method}: {e}")),
    }
}

/// The estimator of `method` with its options.
fn estimator(
    method: &str,
    iterations: Option<usize>,
    tolerance: Option<f64>,
    lags: Option<usize>,
    p: Option<(f64, f64, f64)>,
) -> PyResult<Method> {
    let only = |name: &str, given: bool, methods: &str| {
        if given {
            Err(error(format!(
                "argument {name} applies to method {methods}, not {method:?}"
            )))
        } else {
            Ok(())
        }
    };
    let tolerance_error = |e: String| error(format!("argument tolerance: {e}"));
    match method {
        "ml" => {
            only("lags", lags.is_some(), "\"als\"")?;
            only("p", p.is_some(), "\"j1j2\"")?;
            let mut ml = MaximumLikelihood::new();
            if let Some(t) = tolerance {
                ml = ml
                    .gradient_tolerance(t)
                    .map_err(|e| tolerance_error(e.to_string()))?;
            }
            if let Some(i) = iterations {
                ml = ml.max_iterations(i);
            }
            Ok(Method::MaximumLikelihood(ml))
        }
        "em" => {
            only("lags", lags.is_some(), "\"als\"")?;
            only("p", p.is_some(), "\"j1j2\"")?;
            let mut em = Em::new();
            if let Some(t) = tolerance {
                em = em
                    .tolerance(t)
                    .map_err(|e| tolerance_error(e.to_string()))?;
            }
            if let Some(i) = iterations {
                em = em.exact_iterations(i);
            }
            Ok(Method::Em(em))
        }
        "als" => {
            only("iterations", iterations.is_some(), "\"ml\" and \"em\"")?;
            only("tolerance", tolerance.is_some(), "\"ml\" and \"em\"")?;
            only("p", p.is_some(), "\"j1j2\"")?;
            let mut als = Als::new();
            if let Some(l) = lags {
                als = als
                    .lags(l)
                    .map_err(|e| error(format!("argument lags: {e}")))?;
            }
            Ok(Method::Als(als))
        }
        "j1j2" => {
            only("iterations", iterations.is_some(), "\"ml\" and \"em\"")?;
            only("tolerance", tolerance.is_some(), "\"ml\" and \"em\"")?;
            only("lags", lags.is_some(), "\"als\"")?;
            let mut sweep = ParameterSweep::new();
            if let Some((from, to, step)) = p {
                if !(step.is_finite() && step > 0.0 && from.is_finite() && to >= from) {
                    return Err(error(format!(
                        "argument p: (from, to, step) = ({from}, {to}, {step}) is not a grid \
                         (from <= to, step > 0)"
                    )));
                }
                let count = ((to - from) / step + 1e-9).floor() as usize;
                let grid = (0..=count).map(|i| from + i as f64 * step).collect();
                sweep = sweep
                    .grid(grid)
                    .map_err(|e| error(format!("argument p: {e}")))?;
            }
            Ok(Method::J1J2(sweep))
        }
        other => Err(error(format!(
            "argument method is {other:?}; expected one of {}",
            METHODS.map(|m| format!("{m:?}")).join(", ")
        ))),
    }
}

/// The callables of a nonlinear model: `f`, `h`, their Jacobians and the residual.
struct Callables {
    f: Py<PyAny>,
    f_jacobian: Option<Py<PyAny>>,
    h: Py<PyAny>,
    h_jacobian: Option<Py<PyAny>>,
    residual: Option<Py<PyAny>>,
}

/// An optional callable argument.
fn callable(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Py<PyAny>>> {
    match obj.filter(|o| !o.is_none()) {
        Some(o) if o.is_callable() => Ok(Some(o.clone().unbind())),
        Some(o) => Err(error(format!(
            "argument {name} is not callable (a {})",
            o.get_type()
        ))),
        None => Ok(None),
    }
}

/// Maximum likelihood through the EKF or the UKF on a model given as callables.
#[allow(clippy::too_many_arguments)]
fn estimate_nonlinear(
    py: Python<'_>,
    model: Callables,
    kind: &str,
    measurements: &Bound<'_, PyAny>,
    noise: Parametrisation,
    (x0, p0): (DVector<f64>, DMatrix<f64>),
    start: Start,
    ml: &MaximumLikelihood,
    (options, truth, names): (ReportOptions, Option<Vec<Run>>, (String, String)),
) -> PyResult<NoiseEstimate> {
    let (n, m) = (noise.state_dim(), noise.measurement_dim());
    let filter = match kind {
        "ekf" => {
            if model.f_jacobian.is_none() || model.h_jacobian.is_none() {
                return Err(error(
                    "arguments F_jacobian and H_jacobian are required for kind=\"ekf\" \
                     (or use kind=\"ukf\")",
                ));
            }
            LikelihoodFilter::Ekf
        }
        "ukf" => LikelihoodFilter::Ukf(SigmaSet::recommended(n)),
        other => {
            return Err(error(format!(
                "argument kind is {other:?}; expected \"ekf\" or \"ukf\""
            )));
        }
    };
    let runs = runs_of(measurements, "measurements", m, &format!("R is {m}x{m}"))?;
    // The models' own noise is replaced by every candidate's; these only size them.
    let start_matrices = noise
        .matrices(noise.start().as_slice())
        .map_err(|e| noise_error(&e))?;
    let failure = Failure::default();
    let dynamics = PyDynamics {
        f: &model.f,
        jacobian: model.f_jacobian.as_ref(),
        q: &start_matrices.q,
        failure: &failure,
    };
    let measurement = PyMeasurement {
        h: &model.h,
        jacobian: model.h_jacobian.as_ref(),
        residual: model.residual.as_ref(),
        r: &start_matrices.r,
        n,
        failure: &failure,
    };
    let problem =
        NonlinearNoiseProblem::new(dynamics, measurement, filter, x0, p0, start, noise, runs)
            .map_err(|e| match e {
                NonlinearProblemError::Noise(e) => noise_error(&e),
                other => error(format!("arguments F, H (the model's callables): {other}")),
            })?;
    if let Some(e) = failure.take() {
        return Err(e);
    }
    // The GIL is released so that the optimiser's threads can each take it to call the
    // model; the calls themselves run one at a time.
    let result =
        py.detach(|| NoiseReport::estimate_nonlinear(&problem, ml, options, truth.as_deref()));
    if let Some(e) = failure.take() {
        return Err(e);
    }
    let report = result.map_err(|e| match e {
        ReportError::Ml(e) => error(format!("estimate the noise by ml through the {kind}: {e}")),
        other => report_error(&other, "ml"),
    })?;
    let file = NoiseReportFile::new(&problem, &report);
    Ok(NoiseEstimate {
        report,
        file,
        names,
    })
}

/// Estimates the noise covariances `Q` and `R` of a linear model from its measurements alone:
/// `x_k = F x_{k-1} + G w_k`, `z_k = H x_k + v_k`, `w_k ~ N(0, Qw)`, `v_k ~ N(0, R)`
/// (without `G`, `Qw` is `Q`), with what is known of `Qw` and `R` stated by their forms.
/// The estimators are `kalibra tune --method`'s (the same library underneath).
///
/// A nonlinear model `x_k = f(x_{k-1}, k-1) + G w_k`, `z_k = h(x_k, k) + v_k` is given by
/// callables in place of F and H, as `ExtendedKalmanFilter` and `UnscentedKalmanFilter` take
/// them: its likelihood is that of the EKF (with `F_jacobian` and `H_jacobian`) or of the UKF
/// (`kind="ukf"`, the recommended symmetric sigma points), maximised over the same forms
/// (method "ml" only), with the same report: the profiles are re-maximised through that
/// filter, and the consistency runs it with the estimate and with the starting guess.
///
/// Args:
///     F: (n, n), or the callable f(x, k) -> (n,) of a nonlinear model.
///     H: (m, n), or the callable h(x, k) -> (m,).
///     measurements: (K, m), one row per step, or (R, K, m) for R runs of the same system
///         (each from x0, P0); a row of NaN has no measurement.
///     Q, R: what is known of `Qw` (g, g; `Q` itself without `G`) and of `R` (m, m), each
///         one of:
///         - a matrix: fixed, nothing estimated;
///         - `(form, value)`, with form `"fixed"` (the value), `"scaled"` (a positive
///           multiple of the value, the nominal matrix: one parameter `q` or `r`),
///           `"diagonal"` (each diagonal entry free and positive, starting at the value's) or
///           `"full"` (any symmetric positive-definite matrix, starting at the value);
///         - `(form, value, fixed)` or `{"form": ..., "value": ..., "fixed": [...]}`, where
///           `fixed` lists `(row, col)` entries of a diagonal or full form held at the
///           value's.
///     x0: (n,), P0: (n, n) the initial estimate and covariance.
///     G: (n, g), the channels through which process noise enters; default none.
///     method: "ml" (maximum likelihood, with standard errors, 95% intervals and what the
///         data identify), "em" (expectation-maximisation), "als" (autocovariance least
///         squares; every step measured) or "j1j2" (J1/J2 on every parameter around the
///         starting point; each parameter's value is its crossover).
///     start: "predict_first" (default: x0 is one step before the first measurement) or
///         "update_first".
///     truth: the true states, (K, n) or (R, K, n) as the measurements (a row of NaN:
///         unknown), for the ANEES and RMSE of the filter with the estimate and with the
///         starting guess.
///     iterations: "ml": the iteration cap of each start; "em": exactly this many iterations.
///     tolerance: "ml": the gradient tolerance on -ln L / N; "em": the relative tolerance on
///         the log-likelihood's increase.
///     lags: "als": the autocovariance lags (default 10).
///     p: "j1j2": the grid of exponents (from, to, step), `to` included (default -3 to 3 by
///         0.25); each parameter is its starting value times 10^p.
///     F_jacobian, H_jacobian: for callables F and H, their Jacobians (x, k) -> (n, n) and
///         (m, n) (the EKF).
///     residual: for callables, residual(z, zhat) -> (m,) (angles); default z - zhat.
///     kind: for callables, "ekf" (default) or "ukf".
///     names: the (model, measurements) names in the saved report's title.
///     profile: compute the profile likelihood of every parameter (ML and converged EM; 10
///         re-maximisations per parameter, the costliest part, and for callables each one
///         runs the filter through Python); default True.
///
/// Returns:
///     NoiseEstimate: `method`, `log_likelihood`, `Q`, `Qw`, `R`, `parameters` (name, value,
///     stderr, ci95, profile), `converged`, `iterations`, `identifiable`, `consistency`,
///     `warnings`; `save(dir)` writes `report.json`, `report.md` and `report.html`.
///
/// Raises:
///     KalibraError: naming the argument: a shape that disagrees, a non-finite value, an
///         unknown form or method, a value its form cannot take, more free parameters than
///         innovations can identify (n m + m (m + 1) / 2), or the estimator's refusal (a
///         singular innovation covariance at the start, a gap in the log for ALS).
///
/// The GIL is released while the estimator runs.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rng = np.random.default_rng(1)
///     >>> x, zs = 0.0, []
///     >>> for k in range(500):                       # a random walk, q = 0.5, r = 2
///     ...     x += rng.normal(0.0, 0.5 ** 0.5)
///     ...     zs.append([x + rng.normal(0.0, 2.0 ** 0.5)])
///     >>> est = kalibra.estimate_noise([[1.0]], [[1.0]], np.array(zs),
///     ...     Q=("scaled", [[1.0]]), R=("scaled", [[1.0]]), x0=[0.0], P0=[[10.0]])
///     >>> [p["name"] for p in est.parameters], est.converged
///     (['q', 'r'], True)
///     >>> lo, hi = est.parameters[0]["ci95"]
///     >>> bool(lo < 0.5 < hi)
///     True
#[pyfunction]
#[pyo3(signature = (
    F, H, measurements, *, Q, R, x0, P0, G=None, method="ml", start="predict_first",
    truth=None, iterations=None, tolerance=None, lags=None, p=None, profile=true,
    F_jacobian=None, H_jacobian=None, residual=None, kind="ekf", names=None
))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn estimate_noise(
    py: Python<'_>,
    F: &Bound<'_, PyAny>,
    H: &Bound<'_, PyAny>,
    measurements: &Bound<'_, PyAny>,
    Q: &Bound<'_, PyAny>,
    R: &Bound<'_, PyAny>,
    x0: &Bound<'_, PyAny>,
    P0: &Bound<'_, PyAny>,
    G: Option<&Bound<'_, PyAny>>,
    method: &str,
    start: &str,
    truth: Option<&Bound<'_, PyAny>>,
    iterations: Option<usize>,
    tolerance: Option<f64>,
    lags: Option<usize>,
    p: Option<(f64, f64, f64)>,
    profile: bool,
    F_jacobian: Option<&Bound<'_, PyAny>>,
    H_jacobian: Option<&Bound<'_, PyAny>>,
    residual: Option<&Bound<'_, PyAny>>,
    kind: &str,
    names: Option<(String, String)>,
) -> PyResult<NoiseEstimate> {
    let chosen = estimator(method, iterations, tolerance, lags, p)?;
    let start = match start {
        "predict_first" => Start::PredictFirst,
        "update_first" => Start::UpdateFirst,
        other => {
            return Err(error(format!(
                "argument start is {other:?}; expected \"predict_first\" or \"update_first\""
            )));
        }
    };
    let x0 = read(x0, "x0")?;
    if x0.shape.len() != 1 {
        return Err(error(format!(
            "argument x0 has shape {:?}; expected (n,)",
            x0.shape
        )));
    }
    let p0 = matrix(P0, "P0")?;
    let g = G
        .filter(|g| !g.is_none())
        .map(|g| matrix(g, "G"))
        .transpose()?;
    let qw = form_of(Q, "Q")?;
    let r = form_of(R, "R")?;
    if F.is_callable() || H.is_callable() {
        let (Some(f), Some(h)) = (callable(Some(F), "F")?, callable(Some(H), "H")?) else {
            return Err(error(
                "arguments F, H: give both as matrices or both as callables",
            ));
        };
        let Method::MaximumLikelihood(ml) = chosen else {
            return Err(error(format!(
                "argument method is {method:?}; a model given as callables is estimated by \
                 \"ml\" only"
            )));
        };
        let model = Callables {
            f,
            f_jacobian: callable(F_jacobian, "F_jacobian")?,
            h,
            h_jacobian: callable(H_jacobian, "H_jacobian")?,
            residual: callable(residual, "residual")?,
        };
        let noise = Parametrisation::new(g, qw, r).map_err(|e| noise_error(&e))?;
        let initial = (DVector::from_vec(x0.data), p0);
        let n = noise.state_dim();
        let truth = truth
            .filter(|t| !t.is_none())
            .map(|t| runs_of(t, "truth", n, &format!("the model has {n} states")))
            .transpose()?;
        let report = (
            ReportOptions::new().profile(profile),
            truth,
            names.unwrap_or_else(|| ("model".into(), "measurements".into())),
        );
        return estimate_nonlinear(
            py,
            model,
            kind,
            measurements,
            noise,
            initial,
            start,
            &ml,
            report,
        );
    }
    for (name, given) in [
        ("F_jacobian", F_jacobian),
        ("H_jacobian", H_jacobian),
        ("residual", residual),
    ] {
        if given.is_some_and(|g| !g.is_none()) {
            return Err(error(format!(
                "argument {name} applies to a model given as callables F, H"
            )));
        }
    }
    let f = matrix(F, "F")?;
    let h = matrix(H, "H")?;
    let m = h.nrows();
    let runs = runs_of(measurements, "measurements", m, &format!("H has {m} rows"))?;
    let noise = Parametrisation::new(g, qw, r).map_err(|e| noise_error(&e))?;
    let problem = NoiseProblem::new(f, h, DVector::from_vec(x0.data), p0, start, noise, runs)
        .map_err(|e| noise_error(&e))?;
    let n = problem.state_dim();
    let truth = truth
        .filter(|t| !t.is_none())
        .map(|t| runs_of(t, "truth", n, &format!("the model has {n} states")))
        .transpose()?;
    let options = ReportOptions::new().profile(profile);
    let report = py
        .detach(|| NoiseReport::estimate(&problem, &chosen, options, truth.as_deref()))
        .map_err(|e| report_error(&e, method))?;
    let file = NoiseReportFile::new(&problem, &report);
    Ok(NoiseEstimate {
        report,
        file,
        names: names.unwrap_or_else(|| ("model".into(), "measurements".into())),
    })
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NoiseEstimate>()?;
    m.add_function(wrap_pyfunction!(estimate_noise, m)?)?;
    Ok(())
}
