//! `report.json` of `kalibra tune --method ml|em|als|j1j2` (and of the Python package's
//! `estimate_noise(...).save(dir)`): the estimate of `Q` and `R` with its parameters,
//! intervals and identifiability, in one serialisable [`NoiseReportFile`], written with its
//! human-readable [`Document`](crate::document::Document) by [`write_noise_report`].
//!
//! Every number is written as serde_json writes an `f64` (the shortest text that reads back
//! to the same bits), never rounded; a non-finite number (an interval's end at infinity) is
//! written as `null`.

use std::path::Path;

use kalibra_tune::{
    AlsEstimate, DMatrix, EmEstimate, MlEstimate, MlWarning, NoiseProblem, ParameterCurve,
};
use serde::{Deserialize, Serialize};

use crate::document::Document;
use crate::error::Error;
use crate::output;

/// The `schema_version` of [`NoiseReportFile`]: raised when a field changes meaning or is
/// removed.
pub const NOISE_SCHEMA_VERSION: u32 = 1;

/// The estimator behind a report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseMethod {
    /// Maximum likelihood (`kalibra_tune::MaximumLikelihood`).
    Ml,
    /// Expectation-maximisation (`kalibra_tune::Em`).
    Em,
    /// Autocovariance least squares (`kalibra_tune::Als`).
    Als,
    /// The J1/J2 crossover of every free parameter (`kalibra_tune::ParameterSweep`).
    J1j2,
}

impl NoiseMethod {
    /// The name as `--method` spells it.
    pub fn name(self) -> &'static str {
        match self {
            NoiseMethod::Ml => "ml",
            NoiseMethod::Em => "em",
            NoiseMethod::Als => "als",
            NoiseMethod::J1j2 => "j1j2",
        }
    }

    /// The method in words.
    pub fn words(self) -> &'static str {
        match self {
            NoiseMethod::Ml => "maximum likelihood",
            NoiseMethod::Em => "expectation-maximisation",
            NoiseMethod::Als => "autocovariance least squares",
            NoiseMethod::J1j2 => "the J1/J2 crossover of every parameter",
        }
    }
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
}

/// What the data identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IdentifiableRow {
    /// Whether every free parameter is identified.
    pub identifiable: Option<bool>,
    /// The free parameters.
    pub parameters: usize,
    /// The rank of the observed information (ML) or of the least-squares matrix (ALS).
    pub rank: Option<usize>,
    /// Its condition number (`null`: infinite, or not computed).
    pub condition: Option<f64>,
    /// The parameter combinations the data cannot separate, in words.
    pub unidentifiable: Vec<String>,
    /// In words.
    pub message: String,
}

/// A filter's consistency on the data: ANIS with its band, the innovations' whiteness and,
/// with the truth, ANEES with its band and the RMSE.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilterConsistency {
    /// ANIS over every update (mean NIS / m; 1 if consistent).
    pub anis: Option<f64>,
    /// Its 95% chi-square band `[low, high]`.
    pub anis_band: Option<[f64; 2]>,
    /// Whether ANIS lies inside its band.
    pub anis_inside: Option<bool>,
    /// The Box-Pierce p-value of the normalised innovations' whiteness (first run).
    pub whiteness_p_value: Option<f64>,
    /// Whether the innovations pass the whiteness test.
    pub white: Option<bool>,
    /// With the truth: ANEES (mean NEES / n).
    pub anees: Option<f64>,
    /// Its 95% band.
    pub anees_band: Option<[f64; 2]>,
    /// Whether ANEES lies inside its band.
    pub anees_inside: Option<bool>,
    /// With the truth: the state RMSE over every step.
    pub rmse: Option<f64>,
}

/// The consistency of the tuned filter and of the starting guess.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsistencyPair {
    /// The filter with the estimate.
    pub tuned: FilterConsistency,
    /// The filter with the starting guess (the forms' given matrices).
    pub start: FilterConsistency,
}

/// A parameter's profile log-likelihood: the log-likelihood maximised over the other free
/// parameters with this one held at each value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileRow {
    /// The parameter's name.
    pub name: String,
    /// `[value, log-likelihood]` pairs, in increasing value.
    pub points: Vec<[f64; 2]>,
    /// Whether the other parameters were re-maximised at each point (a true profile), or
    /// held at the estimate (a slice).
    pub profile: bool,
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
}

/// `report.json` of a noise estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseReportFile {
    /// [`NOISE_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The estimator.
    pub method: NoiseMethod,
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
    /// Whether the estimator met its tolerance.
    pub converged: bool,
    /// Its iterations.
    pub iterations: usize,
    /// What the data identify.
    pub identifiable: IdentifiableRow,
    /// The consistency of the tuned filter and of the starting guess.
    pub consistency: Option<ConsistencyPair>,
    /// What the user must know (not converged, a parameter at a bound, ...), in words.
    pub warnings: Vec<String>,
    /// The starting guess.
    pub start: StartRow,
    /// The profile likelihood of each parameter.
    pub profiles: Vec<ProfileRow>,
    /// `--method j1j2`: each parameter's J1/J2 curve and crossover.
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

fn start_row(problem: &NoiseProblem) -> StartRow {
    let noise = problem.noise();
    let start = noise.start();
    match noise.matrices(start.as_slice()) {
        Ok(m) => StartRow {
            q: rows(&m.q),
            qw: rows(&m.qw),
            r: rows(&m.r),
            log_likelihood: kalibra_tune::log_likelihood_of(problem, &m).ok(),
        },
        Err(_) => StartRow {
            q: Vec::new(),
            qw: rows(noise.qw_form().value()),
            r: rows(noise.r_form().value()),
            log_likelihood: None,
        },
    }
}

fn problem_row(problem: &NoiseProblem) -> ProblemRow {
    let noise = problem.noise();
    ProblemRow {
        state_dim: problem.state_dim(),
        meas_dim: problem.measurement_dim(),
        channels: noise.channels(),
        runs: problem.runs().len(),
        steps: problem.runs().iter().map(Vec::len).sum(),
        measurements: problem.measurement_count(),
        start: match problem.start() {
            kalibra_tune::Start::PredictFirst => "predict_first".into(),
            kalibra_tune::Start::UpdateFirst => "update_first".into(),
        },
        identifiable_limit: noise.identifiable_limit(),
    }
}

fn warning_words(w: &MlWarning) -> String {
    match w {
        MlWarning::NotConverged {
            stop,
            gradient,
            iterations,
        } => format!(
            "the optimiser did not converge: it stopped ({stop:?}) after {iterations} \
             iterations with a gradient of {gradient:e}"
        ),
        MlWarning::AtBound { parameter, bound } => match bound {
            kalibra_tune::Bound::Zero => format!(
                "{parameter} ran to its bound 0: the data are consistent with no such noise, \
                 and its interval reaches 0"
            ),
            kalibra_tune::Bound::Infinity => {
                format!("{parameter} ran to infinity: the data put no upper limit on it")
            }
        },
        MlWarning::Unidentifiable { message } => message.clone(),
        MlWarning::NotAMaximum { eigenvalue } => format!(
            "the estimate is not a maximum: the observed information has the negative \
             eigenvalue {eigenvalue:e}"
        ),
        MlWarning::LocalMaxima { best, other } => format!(
            "the starts reached different maxima (log-likelihood {best} and {other}); the \
             best is reported"
        ),
        MlWarning::NoInformation => "the observed information could not be computed at the \
                                     estimate, so no standard errors are given"
            .to_string(),
        other => format!("{other:?}"),
    }
}

impl NoiseReportFile {
    fn base(
        problem: &NoiseProblem,
        method: NoiseMethod,
        matrices: &kalibra_tune::NoiseMatrices,
    ) -> Self {
        Self {
            schema_version: NOISE_SCHEMA_VERSION,
            method,
            log_likelihood: kalibra_tune::log_likelihood_of(problem, matrices).ok(),
            q: rows(&matrices.q),
            qw: rows(&matrices.qw),
            r: rows(&matrices.r),
            parameters: Vec::new(),
            converged: true,
            iterations: 0,
            identifiable: IdentifiableRow {
                identifiable: None,
                parameters: problem.noise().len(),
                rank: None,
                condition: None,
                unidentifiable: Vec::new(),
                message: String::new(),
            },
            consistency: None,
            warnings: Vec::new(),
            start: start_row(problem),
            profiles: Vec::new(),
            curves: Vec::new(),
            problem: problem_row(problem),
        }
    }

    /// The report of a maximum-likelihood estimate.
    pub fn from_ml(problem: &NoiseProblem, est: &MlEstimate) -> Self {
        let mut out = Self::base(problem, NoiseMethod::Ml, &est.matrices);
        out.log_likelihood = Some(est.log_likelihood);
        out.parameters = est
            .parameters
            .iter()
            .map(|p| ParameterRow {
                name: p.parameter.name.clone(),
                value: p.value,
                stderr: p.stderr,
                ci95: p.ci95.map(|[a, b]| [finite(a), finite(b)]),
            })
            .collect();
        out.converged = est.converged;
        out.iterations = est.iterations;
        if let Some(id) = &est.identifiability {
            out.identifiable = IdentifiableRow {
                identifiable: Some(id.identifiable),
                parameters: id.parameters,
                rank: Some(id.rank),
                condition: id.condition_number,
                unidentifiable: id.flat_directions.iter().map(|c| c.text.clone()).collect(),
                message: id.message.clone(),
            };
        } else {
            out.identifiable.message =
                "the observed information could not be computed at the estimate".into();
        }
        out.warnings = est.warnings.iter().map(warning_words).collect();
        out
    }

    /// The report of an EM estimate (no intervals: EM gives none).
    pub fn from_em(problem: &NoiseProblem, est: &EmEstimate) -> Self {
        let mut out = Self::base(problem, NoiseMethod::Em, &est.matrices);
        out.log_likelihood = finite(est.final_log_likelihood()).or(out.log_likelihood);
        out.parameters = point_rows(&est.parameters, &est.values);
        out.converged = est.converged;
        out.iterations = est.iterations;
        out.identifiable.message =
            "EM does not measure identifiability; use --method ml for the rank of the \
             information"
                .into();
        if !est.converged {
            out.warnings.push(format!(
                "EM did not meet its tolerance in {} iterations",
                est.iterations
            ));
        }
        out
    }

    /// The report of an ALS estimate (no intervals; identifiability from the least-squares
    /// matrix's rank).
    pub fn from_als(problem: &NoiseProblem, est: &AlsEstimate) -> Self {
        let mut out = Self::base(problem, NoiseMethod::Als, &est.matrices);
        out.parameters = point_rows(&est.parameters, &est.values);
        out.identifiable = IdentifiableRow {
            identifiable: Some(est.unique()),
            parameters: est.free,
            rank: Some(est.rank),
            condition: finite(est.condition),
            unidentifiable: Vec::new(),
            message: est.warning().unwrap_or_else(|| {
                format!(
                    "the autocovariances at {} lags determine all {} free entries (the \
                     least-squares matrix has full rank {})",
                    est.lags, est.free, est.rank
                )
            }),
        };
        if let Some(w) = est.warning() {
            out.warnings.push(w);
        }
        if est.constrained {
            out.warnings.push(
                "the unconstrained least-squares solution was not positive semi-definite; \
                 the constrained one is reported"
                    .into(),
            );
        }
        out
    }

    /// The report of the J1/J2 crossover of every parameter around the starting point: the
    /// estimate takes each parameter at its crossover (the others at the start).
    pub fn from_j1j2(problem: &NoiseProblem, curves: Vec<ParameterCurve>) -> Self {
        let noise = problem.noise();
        let start = noise.start();
        let matrices = noise.matrices(start.as_slice()).ok();
        let mut values: Vec<f64> = curves.iter().map(|c| c.value).collect();
        let mut warnings = Vec::new();
        for (v, c) in values.iter_mut().zip(&curves) {
            match (&c.crossover, &c.skipped) {
                (Some(x), _) => *v = x.value,
                (None, Some(why)) => warnings.push(format!(
                    "{} was not swept: {why}; it stays at its starting value",
                    c.parameter.name
                )),
                (None, None) => warnings.push(format!(
                    "J1 and J2 of {} do not cross on the grid; it stays at its starting value \
                     (widen --p)",
                    c.parameter.name
                )),
            }
        }
        let params: Vec<_> = curves.iter().map(|c| c.parameter.clone()).collect();
        let crossed = matrices
            .as_ref()
            .and_then(|m| with_values(noise, m, &params, &values));
        let mut out = match (&crossed, &matrices) {
            (Some(m), _) | (None, Some(m)) => Self::base(problem, NoiseMethod::J1j2, m),
            (None, None) => {
                let m = kalibra_tune::NoiseMatrices {
                    qw: noise.qw_form().value().clone(),
                    r: noise.r_form().value().clone(),
                    q: DMatrix::zeros(0, 0),
                };
                Self::base(problem, NoiseMethod::J1j2, &m)
            }
        };
        out.parameters = point_rows(&params, &values);
        out.identifiable.message =
            "the J1/J2 crossover does not measure identifiability; use --method ml".into();
        out.warnings = warnings;
        out.curves = curves;
        out
    }
}

/// Rows without intervals.
fn point_rows(params: &[kalibra_tune::Parameter], values: &[f64]) -> Vec<ParameterRow> {
    params
        .iter()
        .zip(values)
        .map(|(p, &v)| ParameterRow {
            name: p.name.clone(),
            value: v,
            stderr: None,
            ci95: None,
        })
        .collect()
}

/// The matrices with each parameter set to its value, through the parametrisation (so `Q`
/// follows `G`); `None` if the values are not a valid point.
fn with_values(
    noise: &kalibra_tune::Parametrisation,
    base: &kalibra_tune::NoiseMatrices,
    params: &[kalibra_tune::Parameter],
    values: &[f64],
) -> Option<kalibra_tune::NoiseMatrices> {
    let (mut qw, mut r) = (base.qw.clone(), base.r.clone());
    for (p, &v) in params.iter().zip(values) {
        let (x, form) = match p.matrix {
            kalibra_tune::NoiseMatrix::Qw => (&mut qw, noise.qw_form()),
            kalibra_tune::NoiseMatrix::R => (&mut r, noise.r_form()),
        };
        match p.entry {
            Some((i, j)) if i == j && form.kind() == kalibra_tune::FormKind::Full => {
                // Keep the correlations, as the sweep does.
                let s = (v / x[(i, i)]).sqrt();
                for k in 0..x.nrows() {
                    x[(i, k)] *= s;
                    x[(k, i)] *= s;
                }
            }
            Some((i, j)) => {
                x[(i, j)] = v;
                x[(j, i)] = v;
            }
            None => *x = form.value() * v,
        }
    }
    let theta = noise.theta_of(&qw, &r).ok()?;
    noise.matrices(theta.as_slice()).ok()
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
