//! `kalibra.evaluate` and its `Report`: the evaluation of `kalibra eval`, on numpy arrays.

use std::path::{Path, PathBuf};

use kalibra_eval::Evaluation;
use kalibra_io::document::Document;
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{read_in_place, read_opt};
use crate::{error, eval_error, io_error};

/// The consistency report of a filter log: what `kalibra eval` writes as `report.json`, with
/// its verdict, and the files of the command's report directory on request.
///
/// Returned by `kalibra.evaluate`. `to_dict()` holds every number (the keys of `report.json`,
/// whose `schema_version` says which fields it holds); `save(dir)` writes `report.json`,
/// `report.md`, the SVG figures and a self-contained `report.html`, the same files the
/// command writes for the same log. In a notebook the report shows as its HTML page.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rng = np.random.default_rng(1)
///     >>> truth = np.zeros((50, 20, 2))
///     >>> estimate = rng.normal(size=(50, 20, 2))
///     >>> covariance = np.broadcast_to(np.eye(2), (50, 20, 2, 2))
///     >>> report = kalibra.evaluate(truth=truth, estimate=estimate, covariance=covariance)
///     >>> report.verdict
///     'consistent'
///     >>> sorted(report.to_dict())[:3]
///     ['anees_band', 'anees_per_step', 'anis_band']
#[pyclass(module = "kalibra", frozen)]
pub struct Report {
    report: kalibra_eval::Report,
    /// The log's name in the report's title.
    name: String,
}

impl Report {
    /// The report of the log named `name`.
    pub(crate) fn new(report: kalibra_eval::Report, name: &str) -> Self {
        Self {
            report,
            name: name.to_string(),
        }
    }

    fn document(&self) -> Document {
        Document::new(Path::new(&self.name), &self.report)
    }

    fn json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.report)
            .map_err(|e| error(format!("cannot serialise the report: {e}")))
    }
}

#[pymethods]
impl Report {
    /// The verdict: "consistent", "optimistic" (the covariance is too small), "pessimistic"
    /// (too large) or "undetermined" (nothing to test).
    #[getter]
    fn verdict(&self) -> PyResult<String> {
        let v = serde_json::to_value(self.report.summary.verdict.kind)
            .map_err(|e| error(e.to_string()))?;
        Ok(v.as_str().unwrap_or_default().to_string())
    }

    /// The verdict in one line of words, as `kalibra eval` prints it.
    #[getter]
    fn headline(&self) -> String {
        self.document().headline().to_string()
    }

    /// Every number of the report as a dict with the keys of `report.json` (missing values
    /// are None).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?.call_method1("loads", (self.json()?,))
    }

    /// The report as JSON text: `report.json` without its final newline.
    fn to_json(&self) -> PyResult<String> {
        self.json()
    }

    /// The report in Markdown: `report.md`.
    fn markdown(&self) -> String {
        self.document().markdown()
    }

    /// The report as one self-contained HTML page, figures inline: `report.html`.
    fn html(&self) -> String {
        self.document().html()
    }

    fn _repr_html_(&self) -> String {
        self.document().html()
    }

    /// Writes the report into directory `dir`: `report.json`, `report.md`, the SVG figures and
    /// `report.html`, the same files `kalibra eval` writes, through the same writer.
    ///
    /// Everything is written to a temporary directory beside `dir` and renamed into place, so a
    /// failure never leaves a report that looks complete. `dir` is replaced if it holds an
    /// earlier report; a directory holding anything else is refused.
    ///
    /// Raises:
    ///     OSError: `dir` holds something other than a report, or cannot be written.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<()> {
        let doc = self.document();
        py.detach(|| kalibra_io::output::write_report(&dir, &self.report, &doc))
            .map_err(|e| PyOSError::new_err(e.to_string()))
    }

    fn __repr__(&self) -> String {
        format!(
            "<kalibra.Report of {}: {} run(s) x {} steps; {}>",
            self.name,
            self.report.runs,
            self.report.steps.len(),
            self.document().headline()
        )
    }
}

/// Evaluates a filter log held as numpy arrays: is the filter's covariance telling the truth?
///
/// The same evaluation as `kalibra eval` on an NPZ file with these arrays (one implementation
/// underneath). Shapes, with R runs, K steps, n states and m measurements; a single run may
/// drop the R axis:
///
/// * truth, estimate: (R, K, n); covariance: (R, K, n, n), the filter's posterior P.
/// * innovation: (R, K, m); innovation_cov: (R, K, m, m), its covariance S.
/// * time: (K,), optional, strictly increasing.
/// * F (n, n), H (m, n), Q (n, n), R (m, m), optional and all four together (for J1/J2): one
///   matrix for all steps, one per step (K, ...) or one per run and step (R, K, ...).
///
/// C-contiguous float64 arrays are read in place, without a copy, with the GIL released (as
/// numpy's own functions do); each such array is set non-writeable for the duration of the
/// call and its flag restored after. Do not change them from another thread during the call
/// (through another view, say): the result would be undefined. Other dtypes and layouts are
/// copied first.
///
/// A cell (one run and step) whose values are all NaN was not logged. Truth, estimate and
/// covariance give NEES/ANEES, NCI, RMSE and sliding windows; innovation and innovation_cov
/// give NIS/ANIS and whiteness. A covariance that is NaN, asymmetric or not positive definite
/// at a cell is a finding (counted in the report), not an error.
///
/// Args:
///     confidence: of every band and test, in (0, 1).
///     window: sliding window in samples, at least 2 (default: a tenth of the steps).
///     groups: state components whose joint RMSE is reported, {"position": [0, 1], ...}.
///     lags: largest lag of the innovation whiteness test, at least 1.
///     name: the log's name in the report's title.
///
/// Returns:
///     Report: the verdict, every number (`to_dict()`) and the report files (`save(dir)`).
///
/// Raises:
///     KalibraError: a wrong shape or dtype (naming the argument), arrays that disagree on runs
///         or steps, a non-finite truth, an invalid option.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> rng = np.random.default_rng(0)
///     >>> truth = np.zeros((100, 10, 2))
///     >>> estimate = 2.0 * rng.normal(size=(100, 10, 2))   # errors of variance 4
///     >>> covariance = np.broadcast_to(np.eye(2), (100, 10, 2, 2))  # the filter claims 1
///     >>> kalibra.evaluate(truth=truth, estimate=estimate, covariance=covariance).verdict
///     'optimistic'
#[pyfunction]
#[pyo3(signature = (
    truth=None, estimate=None, covariance=None, innovation=None, innovation_cov=None, *,
    confidence=0.95, window=None, groups=None, lags=10, time=None,
    F=None, H=None, Q=None, R=None, name="numpy arrays"
))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn evaluate(
    py: Python<'_>,
    truth: Option<&Bound<'_, PyAny>>,
    estimate: Option<&Bound<'_, PyAny>>,
    covariance: Option<&Bound<'_, PyAny>>,
    innovation: Option<&Bound<'_, PyAny>>,
    innovation_cov: Option<&Bound<'_, PyAny>>,
    confidence: f64,
    window: Option<usize>,
    groups: Option<&Bound<'_, PyDict>>,
    lags: usize,
    time: Option<&Bound<'_, PyAny>>,
    F: Option<&Bound<'_, PyAny>>,
    H: Option<&Bound<'_, PyAny>>,
    Q: Option<&Bound<'_, PyAny>>,
    R: Option<&Bound<'_, PyAny>>,
    name: &str,
) -> PyResult<Report> {
    let given = [
        ("truth", truth),
        ("estimate", estimate),
        ("covariance", covariance),
        ("innovation", innovation),
        ("innovation_cov", innovation_cov),
        ("time", time),
        ("F", F),
        ("H", H),
        ("Q", Q),
        ("R", R),
    ];
    let evaluation = evaluation(confidence, window, groups, lags)?;
    let per_cell = [
        "truth",
        "estimate",
        "covariance",
        "innovation",
        "innovation_cov",
    ];
    // The per-cell arrays (all but 240 MB of a 1000 x 1000 log) are read in place without the
    // GIL, the small ones copied; the guards set the arrays writeable again as they drop,
    // after the evaluation.
    let mut held = Vec::new();
    for (array, obj) in given {
        let Some(obj) = obj.filter(|o| !o.is_none()) else {
            continue;
        };
        if per_cell.contains(&array) {
            held.push((array, read_in_place(obj, array)?));
        } else if let Some(a) = read_opt(Some(obj), array)? {
            held.push((array, crate::arrays::InPlace::Copied(a)));
        }
    }
    let arrays: Vec<(String, Vec<usize>, &[f64])> = held
        .iter()
        .map(|(array, a)| (array.to_string(), a.shape(), a.data()))
        .collect();
    let report = py.detach(|| {
        let log = kalibra_io::input::log_from_arrays(arrays).map_err(|e| io_error(&e))?;
        evaluation.evaluate(&log).map_err(|e| eval_error(&e))
    })?;
    drop(held);
    Ok(Report::new(report, name))
}

/// The evaluation with `evaluate`'s options; errors name the option.
pub(crate) fn evaluation(
    confidence: f64,
    window: Option<usize>,
    groups: Option<&Bound<'_, PyDict>>,
    lags: usize,
) -> PyResult<Evaluation> {
    let mut named = Vec::new();
    if let Some(groups) = groups {
        for (key, value) in groups.iter() {
            let group: String = key
                .extract()
                .map_err(|_| error(format!("argument groups: key {key} is not a string")))?;
            let components: Vec<usize> = value.extract().map_err(|_| {
                error(format!(
                    "argument groups: group {group} is not a list of component indices (0, 1, ...)"
                ))
            })?;
            named.push((group, components));
        }
    }
    evaluation_of(confidence, window, &named, lags).map_err(|e| eval_error(&e))
}

/// The evaluation of options already read from Python (the groups in the order given): also
/// how `kalibra.merge` rebuilds a sharded study's evaluation from its partial results.
pub(crate) fn evaluation_of(
    confidence: f64,
    window: Option<usize>,
    groups: &[(String, Vec<usize>)],
    lags: usize,
) -> Result<Evaluation, kalibra_eval::EvalError> {
    let mut evaluation = Evaluation::new().confidence(confidence)?.lags(lags)?;
    if let Some(w) = window {
        evaluation = evaluation.window(w)?;
    }
    for (group, components) in groups {
        evaluation = evaluation.group(group.clone(), components.clone())?;
    }
    Ok(evaluation)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Report>()?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    Ok(())
}
