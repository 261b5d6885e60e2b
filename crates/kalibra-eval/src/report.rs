//! The serialisable report of an [`Evaluation`](crate::Evaluation): what `report.json` holds.
//!
//! Every per-step series has one entry per step of the log, `null` (`None`) where the step has
//! no value (nothing logged, or every cell left out as a finding). Field names are the schema;
//! a change that renames or removes a field, or changes its meaning, increments
//! [`SCHEMA_VERSION`].

use serde::{Deserialize, Serialize};

/// The version of the report's schema, written to [`Report::schema_version`].
pub const SCHEMA_VERSION: u32 = 1;

/// A two-sided acceptance interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

impl Band {
    /// Whether `value` lies inside (bounds included).
    pub fn contains(&self, value: f64) -> bool {
        value >= self.lower && value <= self.upper
    }
}

/// The RMSE per step of one component or group of components.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RmseSeries {
    /// `"x<i>"` for component `i`, or the group's name.
    pub name: String,
    /// The state components it covers.
    pub components: Vec<usize>,
    /// Per step, `sqrt(mean over runs of sum_{i in components} e_i^2)`.
    pub values: Vec<Option<f64>>,
    /// Over all steps with a value, `sqrt(mean over steps of the squared values)`.
    pub over_time: Option<f64>,
}

/// Sliding-window statistics of one component along one run
/// ([`kalibra_metrics::sliding_window`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ComponentWindow {
    /// The state component.
    pub component: usize,
    /// RMSE of each window.
    pub rmse: Vec<f64>,
    /// Bias (mean of estimate minus truth) of each window.
    pub bias: Vec<f64>,
    /// Standard deviation (divisor `W - 1`) of each window.
    pub std: Vec<f64>,
}

/// Forward-window RMSE, bias and standard deviation of the errors `estimate - truth` of one
/// run, per component.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WindowReport {
    /// The run.
    pub run: usize,
    /// The window length `W`, in samples.
    pub window: usize,
    /// The step at which each window starts. Windows count samples, the steps at which the
    /// run has a finite error; steps without one are skipped, not filled.
    pub start_steps: Vec<usize>,
    /// One entry per state component.
    pub components: Vec<ComponentWindow>,
}

/// The autocorrelation of the normalised innovations at one lag.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LagReport {
    /// The lag in steps.
    pub lag: usize,
    /// The sample autocorrelation `rho(l)`.
    pub autocorrelation: f64,
    /// The band's half-width `z / sqrt(N_l m)`.
    pub bound: f64,
    /// The pairs of steps it was computed from.
    pub pairs: usize,
    /// Whether `|rho(l)| <= bound`.
    pub inside: bool,
}

/// The whiteness test of one run's normalised innovations ([`kalibra_metrics::whiteness`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WhitenessReport {
    /// The run.
    pub run: usize,
    /// One entry per lag `1..=L`.
    pub lags: Vec<LagReport>,
    /// The fraction of lags inside their band.
    pub fraction_inside: f64,
    /// The Box-Pierce statistic over all lags.
    pub box_pierce: f64,
    /// Its p-value (chi-square with `L` degrees of freedom).
    pub p_value: f64,
    /// Whether the Box-Pierce test accepts whiteness at the report's confidence.
    pub white: bool,
}

/// `J1`/`J2` of the innovation covariance ([`kalibra_metrics::j_step`]), from the model
/// matrices and the posterior covariances.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JReport {
    /// Per step, the mean over runs of `J1k = tr(S_k^-1 R_k)` (`None` at step 0).
    pub j1_per_step: Vec<Option<f64>>,
    /// Per step, the mean over runs of `J2k = tr((A_k + B_k)^-1 B_k)`.
    pub j2_per_step: Vec<Option<f64>>,
    /// `J1`: the mean of `J1k` over every update of every run.
    pub j1: f64,
    /// `J2`: the mean of `J2k` over every update of every run.
    pub j2: f64,
    /// `nq` as the mean of `log10 tr(B_k)`.
    pub nq_mean_log10: f64,
    /// `nq` as `log10` of the mean of `tr(B_k)`.
    pub nq_log10_mean: f64,
    /// Updates used (pairs of consecutive valid posterior covariances with their matrices).
    pub updates: usize,
    /// Updates whose `A_k + B_k` was not positive definite.
    pub indefinite_updates: usize,
    /// Updates skipped because `j_step` refused them (a singular or indefinite `S_k` from the
    /// logged matrices).
    pub failed_updates: usize,
}

/// Why a cell was left out of the statistics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reason {
    /// The covariance holds NaN or an infinity.
    NonFinite,
    /// The covariance is not symmetric beyond rounding
    /// ([`SYMMETRY_TOLERANCE`](kalibra_linalg::SYMMETRY_TOLERANCE), relative).
    NotSymmetric,
    /// The covariance is symmetric but not positive definite.
    NotPositiveDefinite,
    /// The estimate or innovation holds NaN or an infinity.
    NonFiniteVector,
}

/// One cell left out of the statistics.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Finding {
    /// The array at fault (`"covariance"`, `"estimate"`, `"innovation_cov"`, `"innovation"`).
    pub array: String,
    /// Run index.
    pub run: usize,
    /// Step index.
    pub step: usize,
    /// What is wrong.
    pub reason: Reason,
}

/// The cells of one family of statistics (state or innovation) left out as findings.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FindingCount {
    /// Cells (run, step) left out.
    pub cells: usize,
    /// Distinct steps with at least one cell left out.
    pub steps: usize,
    /// Cells with a non-finite covariance.
    pub non_finite: usize,
    /// Cells with an asymmetric covariance.
    pub not_symmetric: usize,
    /// Cells with a covariance that is not positive definite.
    pub not_positive_definite: usize,
    /// Cells with a non-finite estimate or innovation.
    pub non_finite_vector: usize,
    /// The first such cell, in run-major order (run 0's steps first).
    pub first: Option<Finding>,
}

/// Findings about the filter under test: cells whose numbers cannot be trusted, left out of
/// the statistics they would poison (NEES, NCI, RMSE and `J1`/`J2` for the state; NIS and
/// whiteness for the innovations).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Findings {
    /// Estimates and their covariances.
    pub state: FindingCount,
    /// Innovations and their covariances.
    pub innovation: FindingCount,
}

/// The verdict on the filter's covariance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictKind {
    /// The statistic is compatible with a consistent filter at the report's confidence.
    Consistent,
    /// The statistic is too large: the filter's covariance is too small.
    Optimistic,
    /// The statistic is too small: the filter's covariance is too large.
    Pessimistic,
    /// Nothing to test (no valid NEES or NIS).
    Undetermined,
}

/// How a consistency statistic was tested.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TestMethod {
    /// Several runs: a two-sided one-sample t-test of the runs' time-averaged normalised
    /// statistics against 1 (runs are independent; steps within a run need not be).
    RunAverageT,
    /// One run: the time average against its chi-square band (Bar-Shalom, Li and
    /// Kirubarajan 2001, sec. 5.4.2), which takes the steps as independent.
    TimeAverageChiSquare,
}

/// The test of one normalised consistency statistic (ANEES or ANIS).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsistencyTest {
    /// `"anees"` or `"anis"`.
    pub statistic: String,
    /// The mean over every valid cell of the statistic divided by its degrees of freedom.
    pub value: f64,
    /// Valid cells.
    pub samples: usize,
    /// How it was tested.
    pub method: TestMethod,
    /// The chi-square band of the time average (one run).
    pub band: Option<Band>,
    /// The t statistic (several runs).
    pub t: Option<f64>,
    /// The two-sided p-value (several runs).
    pub p_value: Option<f64>,
    /// The outcome.
    pub outcome: VerdictKind,
}

/// The verdict with its evidence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// Consistent, optimistic or pessimistic.
    pub kind: VerdictKind,
    /// The statistic the verdict rests on: `"anees"` when the truth is logged, else `"anis"`.
    pub statistic: Option<String>,
    /// The evidence in one sentence, with numbers.
    pub evidence: String,
    /// The test behind it, in words.
    pub test: String,
}

/// The headline numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// ANEES over every valid cell (mean NEES / n).
    pub anees: Option<f64>,
    /// ANIS over every valid cell (mean NIS / m).
    pub anis: Option<f64>,
    /// Mean of the per-step NCI in dB over the steps that have one.
    pub nci: Option<f64>,
    /// Fraction of the steps with an ANEES that lie inside their band.
    pub anees_fraction_inside: Option<f64>,
    /// Fraction of the steps with an ANIS that lie inside their band.
    pub anis_fraction_inside: Option<f64>,
    /// Fraction of the whiteness lags inside their band.
    pub whiteness_fraction_inside: Option<f64>,
    /// The ANEES test.
    pub anees_test: Option<ConsistencyTest>,
    /// The ANIS test.
    pub anis_test: Option<ConsistencyTest>,
    /// The verdict.
    pub verdict: Verdict,
}

/// The report of an evaluation (`report.json`). Series fields are empty when the log holds
/// nothing to compute them from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// Number of runs `R`.
    pub runs: usize,
    /// The step indices `0..K`.
    pub steps: Vec<usize>,
    /// The times of the steps, if logged.
    pub times: Option<Vec<f64>>,
    /// State dimension `n`, if any state array was logged.
    pub state_dim: Option<usize>,
    /// Measurement dimension `m`, if any innovation array was logged.
    pub measurement_dim: Option<usize>,
    /// The confidence of every band and test.
    pub confidence: f64,
    /// Per step, mean NEES over the valid runs divided by `n`.
    pub anees_per_step: Vec<Option<f64>>,
    /// Per step, the chi-square band of that mean for the number of valid runs.
    pub anees_band: Vec<Option<Band>>,
    /// Per step, the runs with a valid NEES.
    pub nees_runs_per_step: Vec<usize>,
    /// Per step, mean NIS over the valid runs divided by `m`.
    pub anis_per_step: Vec<Option<f64>>,
    /// Per step, the chi-square band of that mean.
    pub anis_band: Vec<Option<Band>>,
    /// Per step, the runs with a valid NIS.
    pub nis_runs_per_step: Vec<usize>,
    /// Per step, the non-credibility index in dB (at least 2 valid runs; positive means
    /// optimistic).
    pub nci_per_step: Vec<Option<f64>>,
    /// RMSE per step, per component then per group.
    pub rmse_per_step: Vec<RmseSeries>,
    /// Sliding-window statistics of one run.
    pub window: Option<WindowReport>,
    /// Whiteness of one run's normalised innovations.
    pub whiteness: Option<WhitenessReport>,
    /// `J1`/`J2` when the model matrices are logged.
    pub j: Option<JReport>,
    /// Cells left out of the statistics.
    pub findings: Findings,
    /// The headline numbers and the verdict.
    pub summary: Summary,
}
