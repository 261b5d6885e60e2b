//! `report.json` of `kalibra tune --method ml|em|als|j1j2` (and of the Python package's
//! `estimate_noise(...).save(dir)`): the estimate of `Q` and `R` with its parameters,
//! intervals and identifiability, in one serialisable [`NoiseReportFile`], written with its
//! human-readable [`Document`] by [`write_noise_report`].
//!
//! Every number is written as serde_json writes an `f64` (the shortest text that reads back
//! to the same bits), never rounded; a non-finite number (an interval's end at infinity) is
//! written as `null`.

use std::path::Path;

use kalibra_eval::ConsistencyTest;
use kalibra_tune::{
    Bound, DMatrix, FilterCheck, LikelihoodFilter, MethodKind, NoiseReport, ParameterCurve,
    ReportParameter, ReportProblem,
};
use serde::{Deserialize, Serialize};

use crate::document::Document;
use crate::error::Error;
use crate::output;

/// The `schema_version` of [`NoiseReportFile`]: raised when a field changes meaning or is
/// removed.
pub const NOISE_SCHEMA_VERSION: u32 = 1;

/// The method in words.
pub(crate) fn method_words(method: MethodKind) -> &'static str {
    match method {
        MethodKind::Ml => "maximum likelihood",
        MethodKind::Em => "expectation-maximisation",
        MethodKind::Als => "autocovariance least squares",
        MethodKind::J1j2 => "the J1/J2 crossover of every parameter",
    }
}

/// A parameter's profile log-likelihood: the log-likelihood maximised over the other free
/// parameters with this one held at each value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileRow {
    /// `[value, log-likelihood]` pairs in increasing value (`null` log-likelihood: no
    /// candidate with that value could be evaluated).
    pub points: Vec<(f64, Option<f64>)>,
    /// The log-likelihood at the estimate minus `chi2_1(0.95) / 2 = 1.92`: the profile above
    /// it is the likelihood-ratio 95% interval.
    pub threshold: f64,
    /// That interval's ends where the profile crosses the threshold (`null`: beyond the
    /// grid).
    pub interval: [Option<f64>; 2],
}

/// One free parameter on the matrices' own scale.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterRow {
    /// `q` or `r` for a scaled form's multiplier, `Qw[i,j]` or `R[i,j]` (`i >= j`) for an
    /// entry of a diagonal or full form.
    pub name: String,
    /// The estimate.
    pub value: f64,
    /// Its standard error (`null` where the method gives none or the data do not identify
    /// it).
    pub stderr: Option<f64>,
    /// The 95% interval `[low, high]` (`null` as for `stderr`; an end at infinity is `null`).
    pub ci95: Option<[Option<f64>; 2]>,
    /// The bound it ran to (`"zero"` or `"infinity"`), if any.
    pub at_bound: Option<Bound>,
    /// Its profile likelihood (maximum likelihood and converged EM).
    pub profile: Option<ProfileRow>,
}

/// What the data identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IdentifiableRow {
    /// Whether every free parameter is identified (`null`: not measured).
    pub identifiable: Option<bool>,
    /// What the rank is of: `"observed information"` or `"least-squares matrix"` (ALS).
    pub source: Option<String>,
    /// The free parameters.
    pub parameters: usize,
    /// The rank.
    pub rank: Option<usize>,
    /// The condition number (`null`: infinite, or not measured).
    pub condition: Option<f64>,
    /// The parameter combinations the data cannot determine, in words.
    pub unidentifiable: Vec<String>,
    /// In words.
    pub message: String,
}

/// A filter's consistency on the data: ANIS with its band, the innovations' whiteness and,
/// with the truth, ANEES with its band and the RMSE (from [`kalibra_tune::FilterCheck`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilterConsistency {
    /// ANIS over every update (mean NIS / m; 1 if consistent).
    pub anis: Option<f64>,
    /// Its 95% chi-square band `[low, high]` (one run).
    pub anis_band: Option<[f64; 2]>,
    /// Whether the ANIS test finds the filter consistent.
    pub anis_consistent: Option<bool>,
    /// The Box-Pierce p-value of the normalised innovations' whiteness (first run).
    pub whiteness_p_value: Option<f64>,
    /// Whether the innovations pass the whiteness test.
    pub white: Option<bool>,
    /// With the truth: ANEES (mean NEES / n).
    pub anees: Option<f64>,
    /// Its 95% band.
    pub anees_band: Option<[f64; 2]>,
    /// Whether the ANEES test finds the filter consistent.
    pub anees_consistent: Option<bool>,
    /// With the truth: the state RMSE over every component and step.
    pub rmse: Option<f64>,
    /// With the truth: the RMSE of each state component.
    pub rmse_per_component: Vec<Option<f64>>,
    /// The verdict in words.
    pub verdict: String,
}

fn test_parts(t: Option<&ConsistencyTest>) -> (Option<f64>, Option<[f64; 2]>, Option<bool>) {
    match t {
        Some(t) => (
            Some(t.value),
            t.band.map(|b| [b.lower, b.upper]),
            Some(t.outcome == kalibra_eval::VerdictKind::Consistent),
        ),
        None => (None, None, None),
    }
}

impl From<&FilterCheck> for FilterConsistency {
    fn from(c: &FilterCheck) -> Self {
        let (anis, anis_band, anis_consistent) = test_parts(c.anis.as_ref());
        let (anees, anees_band, anees_consistent) = test_parts(c.anees.as_ref());
        Self {
            anis,
            anis_band,
            anis_consistent,
            whiteness_p_value: c.whiteness.as_ref().map(|w| w.p_value),
            white: c.whiteness.as_ref().map(|w| w.white),
            anees,
            anees_band,
            anees_consistent,
            rmse: c.rmse,
            rmse_per_component: c.rmse_per_component.clone(),
            verdict: c.verdict.clone(),
        }
    }
}

/// The consistency of the tuned filter and of the starting guess (`null`: the filter could
/// not run; the warnings say why).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsistencyPair {
    /// The filter with the estimate.
    pub tuned: Option<FilterConsistency>,
    /// The filter with the starting guess (the forms' given matrices).
    pub start: Option<FilterConsistency>,
}

/// The starting guess: the forms' given matrices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartRow {
    /// `Q = G Qw G^T` at the start.
    #[serde(rename = "Q")]
    pub q: Vec<Vec<f64>>,
    /// `Qw` at the start.
    #[serde(rename = "Qw")]
    pub qw: Vec<Vec<f64>>,
    /// `R` at the start.
    #[serde(rename = "R")]
    pub r: Vec<Vec<f64>>,
    /// The log-likelihood there (`null` if it cannot be evaluated).
    pub log_likelihood: Option<f64>,
}

/// The problem's sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProblemRow {
    /// `n`, the states.
    pub state_dim: usize,
    /// `m`, the measurements.
    pub meas_dim: usize,
    /// `g`, the noise channels (`n` without `G`).
    pub channels: usize,
    /// The runs.
    pub runs: usize,
    /// The steps over every run.
    pub steps: usize,
    /// The measurements present over every run.
    pub measurements: usize,
    /// `"predict_first"` or `"update_first"`.
    pub start: String,
    /// `n m + m (m + 1) / 2`, the most free parameters innovations can identify.
    pub identifiable_limit: usize,
    /// The filter of a nonlinear model's likelihood, `"ekf"` or `"ukf"`; absent for a linear
    /// model (the Kalman filter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<String>,
}

/// `report.json` of a noise estimate: [`kalibra_tune::NoiseReport`] with the names the
/// command line documents (`Q`, `Qw`, `R`, `identifiable`, `ci95` with `null` for an end at
/// infinity), the starting guess and the problem's sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseReportFile {
    /// [`NOISE_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The estimator: `"ml"`, `"em"`, `"als"` or `"j1j2"`.
    pub method: MethodKind,
    /// The log-likelihood at the estimate (natural log, with the `2 pi` constant).
    pub log_likelihood: Option<f64>,
    /// The estimate of the full `n x n` process noise `G Qw G^T`.
    #[serde(rename = "Q")]
    pub q: Vec<Vec<f64>>,
    /// The estimate of the channels' process noise `Qw` (`Q` itself without `G`).
    #[serde(rename = "Qw")]
    pub qw: Vec<Vec<f64>>,
    /// The estimate of `R`.
    #[serde(rename = "R")]
    pub r: Vec<Vec<f64>>,
    /// Every free parameter.
    pub parameters: Vec<ParameterRow>,
    /// The estimate in words ([`NoiseReport::summary`]).
    pub summary: String,
    /// Whether the estimator met its stopping rule.
    pub converged: bool,
    /// Its iterations.
    pub iterations: usize,
    /// What the data identify.
    pub identifiable: IdentifiableRow,
    /// The consistency of the tuned filter and of the starting guess.
    pub consistency: ConsistencyPair,
    /// What the user must know (not converged, a parameter at a bound, ...), in words.
    pub warnings: Vec<String>,
    /// The starting guess.
    pub start: StartRow,
    /// `j1j2`: each parameter's J1/J2 curve and crossover.
    pub curves: Vec<ParameterCurve>,
    /// The problem's sizes.
    pub problem: ProblemRow,
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn parameter_row(p: &ReportParameter) -> ParameterRow {
    ParameterRow {
        name: p.name.clone(),
        value: p.value,
        stderr: p.stderr,
        ci95: p.ci95.map(|[a, b]| [finite(a), finite(b)]),
        at_bound: p.at_bound,
        profile: p.profile.as_ref().map(|pr| ProfileRow {
            points: pr
                .points
                .iter()
                .map(|pt| (pt.value, pt.log_likelihood))
                .collect(),
            threshold: pr.threshold,
            interval: pr.interval,
        }),
    }
}

impl NoiseReportFile {
    /// `report.json` of `report`, the estimate on `problem` (a linear
    /// [`kalibra_tune::NoiseProblem`] or a [`kalibra_tune::NonlinearNoiseProblem`]).
    pub fn new<P: ReportProblem + ?Sized>(problem: &P, report: &NoiseReport) -> Self {
        let noise = problem.noise();
        let (sq, sqw, sr) = match noise.matrices(noise.start().as_slice()) {
            Ok(m) => (rows(&m.q), rows(&m.qw), rows(&m.r)),
            Err(_) => (
                Vec::new(),
                rows(noise.qw_form().value()),
                rows(noise.r_form().value()),
            ),
        };
        let identifiable = match &report.identifiability {
            Some(id) => IdentifiableRow {
                identifiable: Some(id.rank == id.parameters),
                source: Some(id.source.clone()),
                parameters: id.parameters,
                rank: Some(id.rank),
                condition: id.condition,
                unidentifiable: id.unidentifiable.clone(),
                message: id.message.clone(),
            },
            None => IdentifiableRow {
                identifiable: None,
                source: None,
                parameters: noise.len(),
                rank: None,
                condition: None,
                unidentifiable: Vec::new(),
                message: "not measured".into(),
            },
        };
        Self {
            schema_version: NOISE_SCHEMA_VERSION,
            method: report.method,
            log_likelihood: report.log_likelihood,
            q: report.q.clone(),
            qw: report.qw.clone(),
            r: report.r.clone(),
            parameters: report.parameters.iter().map(parameter_row).collect(),
            summary: report.summary(),
            converged: report.converged,
            iterations: report.iterations,
            identifiable,
            consistency: ConsistencyPair {
                tuned: report.consistency.estimate.as_ref().map(Into::into),
                start: report.consistency.start.as_ref().map(Into::into),
            },
            warnings: report.warnings.clone(),
            start: StartRow {
                q: sq,
                qw: sqw,
                r: sr,
                log_likelihood: report.start_log_likelihood,
            },
            curves: report.j1j2.clone().unwrap_or_default(),
            problem: ProblemRow {
                state_dim: problem.state_dim(),
                meas_dim: problem.measurement_dim(),
                channels: noise.channels(),
                runs: problem.run_lengths().len(),
                steps: problem.run_lengths().iter().sum(),
                measurements: problem.measurement_count(),
                start: match problem.start() {
                    kalibra_tune::Start::PredictFirst => "predict_first".into(),
                    kalibra_tune::Start::UpdateFirst => "update_first".into(),
                },
                identifiable_limit: noise.identifiable_limit(),
                filter: problem.likelihood_filter().map(|f| {
                    match f {
                        LikelihoodFilter::Ekf => "ekf",
                        _ => "ukf",
                    }
                    .to_string()
                }),
            },
        }
    }
}

/// Writes `report.json`, `report.md`, `report.html` and the figures of `report` into `out`
/// (see [`output::write_report`] for how `out` is replaced); the document is
/// [`Document::noise`] with `files` (MODEL.toml and the measurements) named in its title.
///
/// # Errors
/// As [`output::write_report`].
pub fn write_noise_report(
    out: &Path,
    report: &NoiseReportFile,
    files: Option<(&Path, &Path)>,
) -> Result<(), Error> {
    output::write_report(out, report, &Document::noise(files, report))
}

/// Writes `json` as `dir/report.json`, creating `dir`: the report of a model given as
/// callables, which has no figures (the Python package writes through here, so that file
/// access stays in this crate, `tests/it/architecture.rs`).
pub fn write_report_json(dir: &Path, json: &str) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("report.json"), json)
}
