//! One result for every noise estimator ([`NoiseReport`]): the estimate with its intervals,
//! what the data identify, what went wrong, the profile likelihood of every parameter, and the
//! tuned filter judged on the data beside the starting guess.
//!
//! # One entry point
//! [`NoiseReport::estimate`] runs the chosen [`Method`] (maximum likelihood, EM, ALS or the
//! J1/J2 crossover of every parameter) on a [`NoiseProblem`] and fills the same fields for
//! each, so that a front end (the `kalibra tune` report, Python) writes one schema.
//!
//! # Intervals per method
//! * Maximum likelihood: the estimator's own (the observed information; module `ml`).
//! * EM: converged EM is a maximum of the same likelihood, so its standard errors and 95%
//!   intervals are those of the observed information at EM's estimate, computed as maximum
//!   likelihood computes them (the information, bounds and identifiability of
//!   [`MaximumLikelihood`] evaluated at EM's point, with no optimiser step). EM stopped before
//!   its tolerance gets none, with a warning, and so does EM whose point is more than 0.1
//!   standard errors from the maximum by a Newton step (exact iterations stop anywhere).
//! * ALS and J1/J2 are not likelihood maxima: no intervals, and no bounds read off the
//!   likelihood (which is not flat around a point that is not its maximum). ALS's
//!   identifiability is that of its least-squares matrix; J1/J2 has none (it measures no
//!   likelihood: maximum likelihood on the same problem says what the data identify).
//!
//! # Nonlinear models
//! [`NoiseReport::estimate_nonlinear`] gives maximum likelihood through the EKF or the UKF
//! ([`MaximumLikelihood::estimate_nonlinear`]) the same report. Both constructors finish in
//! one place over a [`ReportProblem`] (the linear [`NoiseProblem`] or the
//! [`NonlinearNoiseProblem`]): its likelihood is what the profiles re-maximise and its own
//! filter is what the consistency check runs, so the profiles and the check are written once.
//!
//! # Consistency on the data
//! The problem's filter (the library's [`kalibra_filters::Kf`]; for a nonlinear problem the
//! EKF or the UKF its likelihood ran through) runs over every run with the estimate
//! and with the starting guess (the forms' given matrices), and each run is judged by
//! [`kalibra_eval::Evaluation`], the library's evaluation of a log: ANIS with its chi-square
//! band (one run) or its t-test (several runs), the whiteness of the normalised innovations
//! (Box-Pierce over 10 lags, fewer on a short log) and, with the truth given, ANEES with its
//! band and the RMSE. The innovation statistics are the data's own test of the tuned filter;
//! the truth, when a simulation has it, is the test the data cannot give.
//!
//! # Profile likelihood
//! For the likelihood methods (ML and converged EM) each free parameter's profile
//! `max over the others of ln L` is computed on [`PROFILE_POINTS`] points (see that constant
//! for the number and the span), each re-maximised over the other parameters (BFGS,
//! warm-started from its neighbour nearer the estimate), the points of each parameter and the
//! parameters side by side on rayon's pool. A parameter is held at a grid value by fixing its
//! entry in the form (a scaled form becomes fixed at that multiple), so the profile is exact
//! on the matrices' own scale for every form. The likelihood-ratio 95% interval is read off
//! where the profile falls `chi2_1(0.95) / 2 = 1.92` below the maximum.

use kalibra_eval::{ConsistencyTest, Evaluation, FilterLog, Matrices, Vectors, WhitenessReport};
use kalibra_filters::{Filter, FilterError, Kf, Start};
use kalibra_linalg::{Alloc, DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector};
use kalibra_models::{Dynamics, LinearGaussian, LinearObservation, Measurement, ModelError};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::j1j2::scale_parameter;
use crate::likelihood::{LikelihoodError, log_likelihood, log_likelihood_of};
use crate::ml_nonlinear::{LikelihoodFilter, NonlinearNoiseProblem};
use crate::optim::{self, Settings, StopReason};
use crate::{
    Als, AlsError, Bound, CovarianceForm, Em, EmError, FormKind, MaximumLikelihood, MlError,
    MlEstimate, MlWarning, NoiseError, NoiseMatrices, NoiseMatrix, NoiseProblem, Parameter,
    ParameterSweep, Parametrisation, Run, SweepError,
};

/// Points of a parameter's profile: the estimate and 5 on each side, at `j / 5` of the span
/// for `j = -5..=5`. The span is `2.5` standard errors each way (on the log scale for a
/// positive parameter, where its interval is built), so the grid covers the 95% interval
/// (`1.96` standard errors) with a point beyond each end, where the profile has crossed the
/// 1.92 threshold: enough to draw the curve and read its crossing, at 10 re-maximisations per
/// parameter (each warm-started, a few BFGS iterations).
pub const PROFILE_POINTS: usize = 11;

/// The span of a profile in standard errors each way.
const PROFILE_SPAN: f64 = 2.5;
/// The span (on the log scale) of a positive parameter without a standard error: a factor
/// 10 each way.
const PROFILE_SPAN_NO_STDERR: f64 = std::f64::consts::LN_10;
/// Iterations of each profile point's re-maximisation.
const PROFILE_ITERATIONS: usize = 200;
/// The gradient tolerance of a profile point (on `-ln L / N`): looser than the estimate's,
/// which moves the profile's log-likelihood by far less than its threshold of 1.92.
const PROFILE_TOLERANCE: f64 = 1e-6;
/// `chi2_1(0.95) / 2`.
const HALF_CHI2_95: f64 = 1.920_729_410_347_062;
/// How far the re-maximised `theta` may move from its warm start (as the estimator's wall).
const PROFILE_WALL: f64 = 40.0;
/// Whiteness lags of the consistency check.
const WHITENESS_LAGS: usize = 10;

/// A likelihood problem a [`NoiseReport`] can profile and judge on its data: the linear
/// [`NoiseProblem`] (the Kalman filter's exact likelihood) and the [`NonlinearNoiseProblem`]
/// (its EKF's or UKF's). The profiles, the consistency check and the report file are written
/// once against this trait; it is sealed (implemented for these two only), since the report
/// also runs each problem's own filter.
///
/// ```
/// use kalibra_tune::{CovarianceForm, DMatrix, DVector, NoiseProblem, Parametrisation,
///     ReportProblem, Start};
///
/// fn sizes(problem: &dyn ReportProblem) -> (usize, usize, usize) {
///     (problem.state_dim(), problem.measurement_dim(), problem.measurement_count())
/// }
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let run = vec![Some(DVector::from_element(1, 0.3)), None, Some(DVector::from_element(1, 0.5))];
/// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
///     CovarianceForm::scaled(one(1.0)))?;
/// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0),
///     Start::PredictFirst, noise, vec![run])?;
/// assert_eq!(sizes(&problem), (1, 1, 2));
/// assert_eq!(problem.run_lengths(), [3]);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait ReportProblem: sealed::Sealed + Sync {
    /// The noise parametrisation.
    fn noise(&self) -> &Parametrisation;
    /// `n`, the states.
    fn state_dim(&self) -> usize;
    /// `m`, the measurements.
    fn measurement_dim(&self) -> usize;
    /// The measurements present over every run.
    fn measurement_count(&self) -> usize;
    /// The steps of each run (with or without a measurement).
    fn run_lengths(&self) -> Vec<usize>;
    /// Where `x0`, `P0` sit.
    fn start(&self) -> Start;
    /// The filter whose likelihood is maximised: `None` for the linear Kalman filter (exact),
    /// the EKF or the UKF of a nonlinear problem (the likelihood of its Gaussian
    /// approximation).
    fn likelihood_filter(&self) -> Option<LikelihoodFilter>;
    /// The log-likelihood of every run's measurements with the noise `matrices` (`q` and `r`
    /// are read).
    ///
    /// # Errors
    /// The problem's own: [`LikelihoodError`] where its filter cannot run with them.
    fn log_likelihood_at(&self, matrices: &NoiseMatrices) -> Result<f64, LikelihoodError>;
}

mod sealed {
    /// What the report runs that users do not: the problem's own filter over every run.
    pub trait Sealed {
        /// The problem's filter with `matrices` over every run, judged by the evaluation
        /// (an error in words where it cannot run).
        fn check(
            &self,
            matrices: &crate::NoiseMatrices,
            truth: Option<&[crate::Run]>,
        ) -> Result<super::FilterCheck, String>;
    }
}

impl ReportProblem for NoiseProblem {
    fn noise(&self) -> &Parametrisation {
        NoiseProblem::noise(self)
    }
    fn state_dim(&self) -> usize {
        NoiseProblem::state_dim(self)
    }
    fn measurement_dim(&self) -> usize {
        NoiseProblem::measurement_dim(self)
    }
    fn measurement_count(&self) -> usize {
        NoiseProblem::measurement_count(self)
    }
    fn run_lengths(&self) -> Vec<usize> {
        self.runs().iter().map(Vec::len).collect()
    }
    fn start(&self) -> Start {
        NoiseProblem::start(self)
    }
    fn likelihood_filter(&self) -> Option<LikelihoodFilter> {
        None
    }
    fn log_likelihood_at(&self, matrices: &NoiseMatrices) -> Result<f64, LikelihoodError> {
        log_likelihood_of(self, matrices)
    }
}

impl sealed::Sealed for NoiseProblem {
    fn check(
        &self,
        matrices: &NoiseMatrices,
        truth: Option<&[Run]>,
    ) -> Result<FilterCheck, String> {
        let model = |e: ModelError| e.to_string();
        let dynamics = LinearGaussian::new(self.f().clone(), matrices.q.clone()).map_err(model)?;
        let sensor = LinearObservation::new(self.h().clone(), matrices.r.clone()).map_err(model)?;
        check_runs(
            self.state_dim(),
            self.measurement_dim(),
            self.runs(),
            self.start(),
            truth,
            || Kf::new(&dynamics, &sensor, self.x0().clone(), self.p0().clone()),
        )
        .map_err(|e| e.to_string())
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> ReportProblem
    for NonlinearNoiseProblem<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
    NonlinearNoiseProblem<N, M, D, H>: Sync,
{
    fn noise(&self) -> &Parametrisation {
        NonlinearNoiseProblem::noise(self)
    }
    fn state_dim(&self) -> usize {
        NonlinearNoiseProblem::state_dim(self)
    }
    fn measurement_dim(&self) -> usize {
        NonlinearNoiseProblem::measurement_dim(self)
    }
    fn measurement_count(&self) -> usize {
        NonlinearNoiseProblem::measurement_count(self)
    }
    fn run_lengths(&self) -> Vec<usize> {
        self.runs().iter().map(Vec::len).collect()
    }
    fn start(&self) -> Start {
        NonlinearNoiseProblem::start(self)
    }
    fn likelihood_filter(&self) -> Option<LikelihoodFilter> {
        Some(self.filter())
    }
    fn log_likelihood_at(&self, matrices: &NoiseMatrices) -> Result<f64, LikelihoodError> {
        self.log_likelihood_of(matrices)
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> sealed::Sealed
    for NonlinearNoiseProblem<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn check(
        &self,
        matrices: &NoiseMatrices,
        truth: Option<&[Run]>,
    ) -> Result<FilterCheck, String> {
        self.check_filter_at(matrices, truth)
            .map_err(|e| e.to_string())
    }
}

/// The estimator a [`NoiseReport`] runs, with its options.
#[derive(Clone, Debug, PartialEq)]
pub enum Method {
    /// Maximum likelihood ([`MaximumLikelihood`]).
    MaximumLikelihood(MaximumLikelihood),
    /// Expectation-maximisation ([`Em`]).
    Em(Em),
    /// Autocovariance least squares ([`Als`]).
    Als(Als),
    /// The J1/J2 crossover of every parameter around the starting point ([`ParameterSweep`]).
    J1J2(ParameterSweep),
}

impl Method {
    /// The method's name in a report.
    pub fn kind(&self) -> MethodKind {
        match self {
            Method::MaximumLikelihood(_) => MethodKind::Ml,
            Method::Em(_) => MethodKind::Em,
            Method::Als(_) => MethodKind::Als,
            Method::J1J2(_) => MethodKind::J1j2,
        }
    }
}

/// A method's name, as `report.json` writes it (`"ml"`, `"em"`, `"als"`, `"j1j2"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MethodKind {
    /// Maximum likelihood.
    Ml,
    /// Expectation-maximisation.
    Em,
    /// Autocovariance least squares.
    Als,
    /// The J1/J2 crossover of every parameter.
    J1j2,
}

impl MethodKind {
    /// `"ml"`, `"em"`, `"als"` or `"j1j2"`.
    pub fn name(self) -> &'static str {
        match self {
            MethodKind::Ml => "ml",
            MethodKind::Em => "em",
            MethodKind::Als => "als",
            MethodKind::J1j2 => "j1j2",
        }
    }
}

/// What a [`NoiseReport`] computes beside the estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReportOptions {
    profile: bool,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self::new()
    }
}

impl ReportOptions {
    /// Everything: the profile likelihood of every parameter (likelihood methods) and the
    /// consistency of the estimate and the starting guess.
    pub fn new() -> Self {
        Self { profile: true }
    }

    /// Whether to compute the profiles (the costliest part: [`PROFILE_POINTS`] `- 1`
    /// re-maximisations per parameter).
    pub fn profile(mut self, profile: bool) -> Self {
        self.profile = profile;
        self
    }
}

/// Why a report could not be made. Troubles with an estimate (non-convergence, a bound, an
/// unidentified parameter, a filter that fails at the estimate) are [`NoiseReport::warnings`]
/// instead.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// Maximum likelihood refused.
    #[error("maximum likelihood: {0}")]
    Ml(#[source] MlError),
    /// EM refused.
    #[error("EM: {0}")]
    Em(#[source] EmError),
    /// ALS refused.
    #[error("ALS: {0}")]
    Als(#[source] AlsError),
    /// The J1/J2 sweep failed.
    #[error("J1/J2 sweep: {0}")]
    Sweep(#[source] SweepError),
    /// Fewer scalar measurements than free parameters: the data cannot determine them.
    #[error(
        "{measurements} scalar measurements cannot determine {parameters} free noise \
         parameters; record more, or fix or scale some entries"
    )]
    TooFewMeasurements {
        /// Scalar measurements present (measurement vectors times `m`).
        measurements: usize,
        /// Free parameters.
        parameters: usize,
    },
    /// The starting guess's matrices could not be formed.
    #[error("starting guess: {0}")]
    Start(#[source] NoiseError),
    /// The truth has a different number of runs than the measurements.
    #[error("truth has {found} runs, the measurements {expected}")]
    TruthRuns {
        /// Runs of measurements.
        expected: usize,
        /// Runs of truth.
        found: usize,
    },
    /// A truth run whose length differs from its measurements'.
    #[error("truth of run {run} has {found} steps, its measurements {expected}")]
    TruthLength {
        /// The run.
        run: usize,
        /// Steps of measurements.
        expected: usize,
        /// Steps of truth.
        found: usize,
    },
    /// A true state of the wrong length or with NaN or an infinity (give `None` for a step
    /// without a truth).
    #[error(
        "truth at run {run}, step {step} is not a finite vector of n = {expected} values \
         (give None for a step without a truth)"
    )]
    TruthValue {
        /// The run.
        run: usize,
        /// The step.
        step: usize,
        /// `n`.
        expected: usize,
    },
}

/// One free parameter's estimate on the matrices' own scale.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReportParameter {
    /// `q` or `r` for a scaled form's multiplier, `Qw[i,j]` or `R[i,j]` (`i >= j`) for an
    /// entry of a diagonal or full form.
    pub name: String,
    /// The estimate.
    pub value: f64,
    /// Its standard error (likelihood methods; `None` where the data do not identify it).
    pub stderr: Option<f64>,
    /// Its 95% interval `[low, high]` (as `stderr`); an end at a bound is that bound, `0` or
    /// `f64::INFINITY` (which `serde_json` writes as `null`).
    pub ci95: Option<[f64; 2]>,
    /// The bound it ran to, if any.
    pub at_bound: Option<Bound>,
    /// Its profile likelihood (likelihood methods, when asked for).
    pub profile: Option<Profile>,
}

/// One point of a profile likelihood.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfilePoint {
    /// The parameter's value (natural scale).
    pub value: f64,
    /// The log-likelihood maximised over the other parameters (`None`: no candidate with this
    /// value could be evaluated, for example a full form that cannot hold it).
    pub log_likelihood: Option<f64>,
    /// Whether the re-maximisation met its tolerance.
    pub converged: bool,
}

/// A parameter's profile likelihood around the estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// The points, ascending in value; the estimate is one of them.
    pub points: Vec<ProfilePoint>,
    /// `ln L` at the estimate minus `chi2_1(0.95) / 2`: the profile above it is the
    /// likelihood-ratio 95% interval.
    pub threshold: f64,
    /// That interval's ends where the profile crosses the threshold on the grid (linear
    /// interpolation between points); `None` for an end the grid does not reach.
    pub interval: [Option<f64>; 2],
}

/// What the data identify, in numbers and words.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReportIdentifiability {
    /// What the numbers are of: `"observed information"` (the log-likelihood's curvature at
    /// the estimate) or `"least-squares matrix"` (ALS).
    pub source: String,
    /// Free parameters.
    pub parameters: usize,
    /// Rank.
    pub rank: usize,
    /// Condition number (`None`: infinite, the rank is short).
    pub condition: Option<f64>,
    /// The parameter combinations the data cannot determine, in words.
    pub unidentifiable: Vec<String>,
    /// In words: what the data identify.
    pub message: String,
}

/// A filter judged on the data ([`kalibra_eval::Evaluation`] of its run).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilterCheck {
    /// ANIS (mean NIS over `m`) with its test: the chi-square band of one run, or the t-test
    /// over several.
    pub anis: Option<ConsistencyTest>,
    /// The whiteness of the first run's normalised innovations.
    pub whiteness: Option<WhitenessReport>,
    /// ANEES (mean NEES over `n`) with its test, with the truth given.
    pub anees: Option<ConsistencyTest>,
    /// The RMSE of the estimate over every state component and step with a truth.
    pub rmse: Option<f64>,
    /// The RMSE of each state component, with the truth given.
    pub rmse_per_component: Vec<Option<f64>>,
    /// The verdict in words (consistent, optimistic or pessimistic, with its evidence).
    pub verdict: String,
}

/// The tuned filter and the starting guess judged on the same data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// The filter with the estimate (`None`: it could not run; see the warnings).
    pub estimate: Option<FilterCheck>,
    /// The filter with the starting guess.
    pub start: Option<FilterCheck>,
}

/// The result of any noise estimator, in one schema ([`NoiseReport::estimate`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// The method.
    pub method: MethodKind,
    /// The log-likelihood of the measurements at the estimate (`None` if the filter cannot
    /// run there).
    pub log_likelihood: Option<f64>,
    /// The log-likelihood at the starting guess.
    pub start_log_likelihood: Option<f64>,
    /// `Q = G Qw G^T`, `n x n`, row by row.
    pub q: Vec<Vec<f64>>,
    /// `Qw`, row by row.
    pub qw: Vec<Vec<f64>>,
    /// `R`, row by row.
    pub r: Vec<Vec<f64>>,
    /// Every free parameter, in the parametrisation's order.
    pub parameters: Vec<ReportParameter>,
    /// Whether the method met its stopping rule (ML: the gradient tolerance; EM: the
    /// relative tolerance; ALS: always; J1/J2: every swept parameter has a crossover).
    pub converged: bool,
    /// Iterations (ML: of the best start; EM: M-steps; ALS and J1/J2: 0, not iterative).
    pub iterations: usize,
    /// What the data identify (`None` for J1/J2, and where the information cannot be
    /// computed).
    pub identifiability: Option<ReportIdentifiability>,
    /// What the user must know, in words: non-convergence, bounds, unidentified
    /// combinations, a filter that failed.
    pub warnings: Vec<String>,
    /// The filter with the estimate and with the starting guess, judged on the data.
    pub consistency: Consistency,
    /// The J1/J2 curves of every parameter (method J1/J2).
    pub j1j2: Option<Vec<crate::ParameterCurve>>,
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

/// What each method hands to the common part of the report.
struct Fit {
    matrices: NoiseMatrices,
    values: Vec<f64>,
    converged: bool,
    iterations: usize,
    /// The likelihood's view at the estimate (ML: its own; EM: evaluated there).
    view: Option<MlEstimate>,
    /// Whether the view's intervals apply (a likelihood maximum).
    intervals: bool,
    identifiability: Option<ReportIdentifiability>,
    warnings: Vec<String>,
    curves: Option<Vec<crate::ParameterCurve>>,
}

impl NoiseReport {
    /// Runs `method` on `problem` and reports (see the module docs); `truth`, one sequence of
    /// true states per run and step (`None` where unknown), adds ANEES and RMSE.
    ///
    /// ```
    /// use kalibra_tune::{CovarianceForm, DMatrix, DVector, MaximumLikelihood, Method,
    ///     MethodKind, NoiseProblem, NoiseReport, Parametrisation, ReportOptions, Start};
    ///
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let zs = [0.1, 0.5, 0.2, 1.1, 1.6, 1.2, 2.3, 2.0, 2.9, 3.4, 2.8, 3.9, 4.4, 4.1, 5.2];
    /// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    ///     CovarianceForm::scaled(one(1.0)))?;
    /// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0),
    ///     Start::PredictFirst, noise, vec![run])?;
    /// let method = Method::MaximumLikelihood(MaximumLikelihood::new());
    /// let report = NoiseReport::estimate(&problem, &method, ReportOptions::new(), None)?;
    /// assert_eq!(report.method, MethodKind::Ml);
    /// assert_eq!(report.parameters[0].name, "q");
    /// assert!(report.consistency.estimate.as_ref().unwrap().anis.is_some());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// The method's own refusal ([`ReportError::Ml`], [`ReportError::Em`],
    /// [`ReportError::Als`], [`ReportError::Sweep`]); [`ReportError::TooFewMeasurements`];
    /// [`ReportError::Start`]; [`ReportError::TruthRuns`], [`ReportError::TruthLength`],
    /// [`ReportError::TruthValue`] for a truth that does not fit the measurements.
    pub fn estimate(
        problem: &NoiseProblem,
        method: &Method,
        options: ReportOptions,
        truth: Option<&[Run]>,
    ) -> Result<NoiseReport, ReportError> {
        let start = prepare(problem, truth)?;
        let fit = match method {
            Method::MaximumLikelihood(ml) => fit_ml(problem, ml)?,
            Method::Em(em) => fit_em(problem, em)?,
            Method::Als(als) => fit_als(problem, als)?,
            Method::J1J2(sweep) => fit_j1j2(problem, sweep, &start)?,
        };
        Ok(finish(problem, method.kind(), fit, &start, options, truth))
    }

    /// Maximum likelihood through the EKF or the UKF
    /// ([`MaximumLikelihood::estimate_nonlinear`]) with the report of
    /// [`NoiseReport::estimate`]: the same intervals, identifiability and warnings, each
    /// parameter's profile likelihood re-maximised through the same filter, and the problem's
    /// own filter (the EKF or the UKF the estimate used) run over the data with the estimate
    /// and with the starting guess and judged by the same evaluation (ANIS with its band,
    /// whiteness; ANEES and RMSE with `truth`). A warning says that the likelihood is the
    /// filter's Gaussian approximation's (a quasi-likelihood).
    ///
    /// ```
    /// use kalibra_linalg::{DMatrix, DVector, Dyn};
    /// use kalibra_models::{LinearGaussian, LinearObservation};
    /// use kalibra_tune::{CovarianceForm, LikelihoodFilter, MaximumLikelihood,
    ///     NonlinearNoiseProblem, NoiseReport, Parametrisation, ReportOptions, Start};
    ///
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let zs = [0.1, 0.5, 0.2, 1.1, 1.6, 1.2, 2.3, 2.0, 2.9, 3.4, 2.8, 3.9, 4.4, 4.1, 5.2];
    /// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    ///     CovarianceForm::scaled(one(1.0)))?;
    /// let problem = NonlinearNoiseProblem::new(LinearGaussian::new(one(1.0), one(1.0))?,
    ///     LinearObservation::<Dyn, Dyn>::new(one(1.0), one(1.0))?, LikelihoodFilter::Ekf,
    ///     DVector::zeros(1), one(1.0), Start::PredictFirst, noise, vec![run])?;
    /// let report = NoiseReport::estimate_nonlinear(&problem, &MaximumLikelihood::new(),
    ///     ReportOptions::new(), None)?;
    /// assert!(report.parameters.iter().all(|p| p.profile.is_some()));
    /// assert!(report.consistency.estimate.as_ref().unwrap().anis.is_some());
    /// assert!(report.consistency.start.as_ref().unwrap().whiteness.is_some());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`ReportError::Ml`] for the estimator's refusal; [`ReportError::TooFewMeasurements`];
    /// [`ReportError::Start`]; [`ReportError::TruthRuns`], [`ReportError::TruthLength`],
    /// [`ReportError::TruthValue`] for a truth that does not fit the measurements.
    pub fn estimate_nonlinear<N: Dim, M: Dim, D, H>(
        problem: &NonlinearNoiseProblem<N, M, D, H>,
        ml: &MaximumLikelihood,
        options: ReportOptions,
        truth: Option<&[Run]>,
    ) -> Result<NoiseReport, ReportError>
    where
        DefaultAllocator: Alloc<N, M>,
        D: Dynamics<N>,
        H: Measurement<N, M>,
        NonlinearNoiseProblem<N, M, D, H>: Sync,
    {
        let start = prepare(problem, truth)?;
        let est = ml.estimate_nonlinear(problem).map_err(ReportError::Ml)?;
        let mut fit = ml_fit(est);
        let filter = match problem.filter() {
            LikelihoodFilter::Ekf => "EKF",
            LikelihoodFilter::Ukf(_) => "UKF",
        };
        fit.warnings.push(format!(
            "the likelihood is that of the {filter}'s Gaussian approximation (a \
             quasi-likelihood): the intervals and profiles are those of that approximation"
        ));
        Ok(finish(problem, MethodKind::Ml, fit, &start, options, truth))
    }
}

/// The checks every report makes before its method runs: the truth fits the measurements,
/// there are at least as many scalar measurements as free parameters, the starting guess has
/// matrices (returned).
fn prepare(
    problem: &dyn ReportProblem,
    truth: Option<&[Run]>,
) -> Result<NoiseMatrices, ReportError> {
    if let Some(truth) = truth {
        check_truth(problem, truth)?;
    }
    let noise = problem.noise();
    let scalars = problem.measurement_count() * problem.measurement_dim();
    if scalars < noise.len() {
        return Err(ReportError::TooFewMeasurements {
            measurements: scalars,
            parameters: noise.len(),
        });
    }
    noise
        .matrices(noise.start().as_slice())
        .map_err(ReportError::Start)
}

/// The parts of a report common to every method and problem: the log-likelihoods, the
/// parameters with their profiles, and the filter with the estimate and with the starting
/// guess judged on the data.
fn finish(
    problem: &dyn ReportProblem,
    method: MethodKind,
    fit: Fit,
    start: &NoiseMatrices,
    options: ReportOptions,
    truth: Option<&[Run]>,
) -> NoiseReport {
    let noise = problem.noise();
    let mut warnings = fit.warnings;
    let log_likelihood = match problem.log_likelihood_at(&fit.matrices) {
        Ok(l) => Some(l),
        Err(e) => {
            warnings.push(format!("the log-likelihood at the estimate: {e}"));
            None
        }
    };
    let start_log_likelihood = problem.log_likelihood_at(start).ok();
    let params = noise.parameters();
    let mut parameters: Vec<ReportParameter> = params
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let from_view = fit.view.as_ref().map(|v| &v.parameters[i]);
            let intervals = fit.intervals;
            ReportParameter {
                name: p.name.clone(),
                value: fit.values[i],
                stderr: from_view.and_then(|v| v.stderr).filter(|_| intervals),
                ci95: from_view.and_then(|v| v.ci95).filter(|_| intervals),
                at_bound: from_view.and_then(|v| v.at_bound).filter(|_| intervals),
                profile: None,
            }
        })
        .collect();
    if options.profile
        && fit.intervals
        && let (Some(view), Some(ll)) = (&fit.view, log_likelihood)
    {
        let profiles: Vec<Option<Profile>> = (0..params.len())
            .into_par_iter()
            .map(|i| profile(problem, view, &parameters[i], i, ll))
            .collect();
        for (p, prof) in parameters.iter_mut().zip(profiles) {
            p.profile = prof;
        }
    }
    let estimate_check = match problem.check(&fit.matrices, truth) {
        Ok(c) => Some(c),
        Err(e) => {
            warnings.push(format!("the filter with the estimate: {e}"));
            None
        }
    };
    let start_check = match problem.check(start, truth) {
        Ok(c) => Some(c),
        Err(e) => {
            warnings.push(format!("the filter with the starting guess: {e}"));
            None
        }
    };
    NoiseReport {
        method,
        log_likelihood,
        start_log_likelihood,
        q: rows_of(&fit.matrices.q),
        qw: rows_of(&fit.matrices.qw),
        r: rows_of(&fit.matrices.r),
        parameters,
        converged: fit.converged,
        iterations: fit.iterations,
        identifiability: fit.identifiability,
        warnings,
        consistency: Consistency {
            estimate: estimate_check,
            start: start_check,
        },
        j1j2: fit.curves,
    }
}

impl NoiseReport {
    /// The recommendation in words, for the top of a report: the method, every parameter
    /// with its interval, whether it converged, what the data identify, the warnings, and
    /// what the estimate changed in the filter's consistency on the data.
    ///
    /// ```
    /// # use kalibra_tune::{CovarianceForm, DMatrix, DVector, MaximumLikelihood, Method,
    /// #     NoiseProblem, NoiseReport, Parametrisation, ReportOptions, Start};
    /// # let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// # let zs = [0.1, 0.5, 0.2, 1.1, 1.6, 1.2, 2.3, 2.0, 2.9, 3.4, 2.8, 3.9, 4.4, 4.1, 5.2];
    /// # let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// # let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    /// #     CovarianceForm::scaled(one(1.0)))?;
    /// # let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0),
    /// #     Start::PredictFirst, noise, vec![run])?;
    /// let method = Method::MaximumLikelihood(MaximumLikelihood::new());
    /// let report = NoiseReport::estimate(&problem, &method, ReportOptions::new(), None)?;
    /// assert!(report.summary().starts_with("Maximum likelihood recommends q = "));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn summary(&self) -> String {
        let method = match self.method {
            MethodKind::Ml => "Maximum likelihood",
            MethodKind::Em => "EM",
            MethodKind::Als => "ALS",
            MethodKind::J1j2 => "The J1/J2 crossover",
        };
        let params: Vec<String> = self
            .parameters
            .iter()
            .map(|p| match p.ci95 {
                Some([lo, hi]) => format!(
                    "{} = {} (95% interval {} to {})",
                    p.name,
                    significant(p.value),
                    significant(lo),
                    if hi.is_finite() {
                        significant(hi)
                    } else {
                        "infinity".to_string()
                    }
                ),
                None => format!("{} = {}", p.name, significant(p.value)),
            })
            .collect();
        let mut out = format!("{method} recommends {}", params.join(", "));
        out.push_str(&match (self.converged, self.iterations) {
            (true, 0) => ".".to_string(),
            (true, i) => format!(", converged in {i} iterations."),
            (false, i) => format!(", but did not converge ({i} iterations)."),
        });
        if let (Some(l), Some(s)) = (self.log_likelihood, self.start_log_likelihood) {
            out.push_str(&format!(
                " The log-likelihood is {l:.3} against {s:.3} at the starting guess."
            ));
        }
        if let Some(id) = &self.identifiability {
            out.push_str(&format!(" Identifiability: {}.", id.message));
        }
        let anis = |c: &Option<FilterCheck>| {
            c.as_ref()
                .and_then(|c| c.anis.as_ref())
                .map(|a| (a.value, a.outcome))
        };
        if let (Some((e, eo)), Some((s, so))) = (
            anis(&self.consistency.estimate),
            anis(&self.consistency.start),
        ) {
            out.push_str(&format!(
                " On the data the tuned filter's ANIS is {e:.3} ({}), the starting guess's \
                 {s:.3} ({}).",
                outcome(eo),
                outcome(so)
            ));
        }
        for w in &self.warnings {
            out.push_str(&format!(" Warning: {w}."));
        }
        out
    }
}

fn outcome(kind: kalibra_eval::VerdictKind) -> &'static str {
    match kind {
        kalibra_eval::VerdictKind::Consistent => "consistent",
        kalibra_eval::VerdictKind::Optimistic => "optimistic: its covariance is too small",
        kalibra_eval::VerdictKind::Pessimistic => "pessimistic: its covariance is too large",
        kalibra_eval::VerdictKind::Undetermined => "undetermined",
    }
}

/// Four significant digits.
fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 15) as usize;
    if !(1e-4..1e6).contains(&v.abs()) {
        return format!("{v:.3e}");
    }
    format!("{v:.digits$}")
}

fn check_truth(problem: &dyn ReportProblem, truth: &[Run]) -> Result<(), ReportError> {
    let runs = problem.run_lengths();
    if truth.len() != runs.len() {
        return Err(ReportError::TruthRuns {
            expected: runs.len(),
            found: truth.len(),
        });
    }
    let n = problem.state_dim();
    for (run, (t, steps)) in truth.iter().zip(runs).enumerate() {
        if t.len() != steps {
            return Err(ReportError::TruthLength {
                run,
                expected: steps,
                found: t.len(),
            });
        }
        for (step, x) in t.iter().enumerate() {
            if let Some(x) = x
                && (x.len() != n || x.iter().any(|v| !v.is_finite()))
            {
                return Err(ReportError::TruthValue {
                    run,
                    step,
                    expected: n,
                });
            }
        }
    }
    Ok(())
}

/// An [`MlWarning`] in words.
pub(crate) fn warning_text(w: &MlWarning) -> String {
    match w {
        MlWarning::NotConverged {
            stop,
            gradient,
            iterations,
        } => format!(
            "the optimiser did not converge: it stopped after {iterations} iterations ({}) \
             with a gradient of {gradient:.2e} on -ln L / N; the estimate is where it stopped",
            match stop {
                StopReason::Gradient => "gradient tolerance met",
                StopReason::MaxIterations => "iteration limit",
                StopReason::LineSearch => "no step along the search direction improved it",
            }
        ),
        MlWarning::AtBound { parameter, bound } => match bound {
            Bound::Zero => format!(
                "{parameter} ran to its bound 0: the data are consistent with no such noise \
                 (its interval starts at 0)"
            ),
            Bound::Infinity => format!(
                "{parameter} ran to its bound infinity: the data put no upper limit on it \
                 (its interval ends at infinity)"
            ),
        },
        MlWarning::Unidentifiable { message } => message.clone(),
        MlWarning::NotAMaximum { eigenvalue } => format!(
            "the estimate is not a maximum of the likelihood: its curvature has the negative \
             eigenvalue {eigenvalue:.3e} (a saddle, or not converged)"
        ),
        MlWarning::LocalMaxima { best, other } => format!(
            "the starts reached different maxima (ln L = {best:.6} and {other:.6}); the best \
             is reported"
        ),
        MlWarning::NoInformation => "the observed information could not be computed (a \
             neighbour of the estimate cannot be evaluated): no standard errors"
            .to_string(),
    }
}

fn identifiability_of(view: &MlEstimate) -> Option<ReportIdentifiability> {
    view.identifiability
        .as_ref()
        .map(|id| ReportIdentifiability {
            source: "observed information".to_string(),
            parameters: id.parameters,
            rank: id.rank,
            condition: id.condition_number,
            unidentifiable: id.flat_directions.iter().map(|c| c.text.clone()).collect(),
            message: id.message.clone(),
        })
}

fn fit_ml(problem: &NoiseProblem, ml: &MaximumLikelihood) -> Result<Fit, ReportError> {
    Ok(ml_fit(ml.estimate(problem).map_err(ReportError::Ml)?))
}

/// A maximum-likelihood estimate (linear or through the EKF or the UKF) as the report's fit.
fn ml_fit(est: MlEstimate) -> Fit {
    Fit {
        matrices: est.matrices.clone(),
        values: est.parameters.iter().map(|p| p.value).collect(),
        converged: est.converged,
        iterations: est.iterations,
        identifiability: identifiability_of(&est),
        warnings: est.warnings.iter().map(warning_text).collect(),
        intervals: true,
        view: Some(est),
        curves: None,
    }
}

/// The likelihood's view (information, bounds, identifiability, intervals) at `matrices`,
/// computed as maximum likelihood computes it, without moving from the point. `None` when
/// the point has no `theta` (a variance of exactly 0) or cannot be evaluated.
fn view_at(problem: &NoiseProblem, matrices: &NoiseMatrices) -> Option<MlEstimate> {
    let theta = problem.noise().theta_of(&matrices.qw, &matrices.r).ok()?;
    let mut view = MaximumLikelihood::new()
        .max_iterations(0)
        .starts(vec![theta])
        .estimate(problem)
        .ok()?;
    // Not an optimiser run: its iteration limit of 0 is no convergence failure.
    view.warnings
        .retain(|w| !matches!(w, MlWarning::NotConverged { .. }));
    Some(view)
}

/// The largest offset from the likelihood's maximum, in standard errors, that still counts
/// as at it: it moves an interval's centre by a tenth of its half-width's 1.96 standard
/// errors at most.
const NEWTON_OFFSET_LIMIT: f64 = 0.1;

/// The Newton step `I^-1 d ln L / d theta` from the view's point, each component over its
/// standard error `sqrt((I^-1)_ii)`, largest in magnitude; `None` without an invertible
/// information or a gradient.
fn newton_offset(problem: &NoiseProblem, view: &MlEstimate) -> Option<f64> {
    let info = view.information.as_ref()?;
    let cov = info.clone().try_inverse()?;
    let theta = view.theta.as_slice();
    let ll = |t: &[f64]| log_likelihood(problem, t).ok();
    let score = DVector::from_vec(optim::gradient(&ll, theta, view.log_likelihood)?);
    let step = &cov * score;
    (0..step.len())
        .map(|i| (cov[(i, i)] > 0.0).then(|| step[i].abs() / cov[(i, i)].sqrt()))
        .try_fold(0.0f64, |m, r| r.map(|r| m.max(r)))
}

fn fit_em(problem: &NoiseProblem, em: &Em) -> Result<Fit, ReportError> {
    let est = em.estimate(problem).map_err(ReportError::Em)?;
    let mut warnings = Vec::new();
    if !est.converged {
        warnings.push(format!(
            "EM did not converge: it stopped after {} iterations, before the log-likelihood's \
             relative increase fell below its tolerance; no intervals are given (they hold at \
             a maximum)",
            est.iterations
        ));
    }
    let view = view_at(problem, &est.matrices);
    // EM's stopping rule (or an exact number of iterations) need not put it at the maximum
    // the intervals are centred on: a Newton step from its point, in standard errors, says
    // how far off it is.
    let offset = view.as_ref().and_then(|v| newton_offset(problem, v));
    let at_maximum = est.converged && offset.is_none_or(|o| o <= NEWTON_OFFSET_LIMIT);
    if est.converged && !at_maximum {
        warnings.push(format!(
            "EM's estimate is {:.2} standard errors from the likelihood's maximum (a Newton \
             step from it): no intervals are given; run more iterations",
            offset.unwrap_or(f64::NAN)
        ));
    }
    match &view {
        Some(v) => warnings.extend(v.warnings.iter().map(warning_text)),
        None => warnings.push(
            "the observed information at EM's estimate could not be computed (a variance is \
             0 or the likelihood cannot be evaluated nearby): no intervals"
                .to_string(),
        ),
    }
    Ok(Fit {
        values: est.values.clone(),
        converged: est.converged,
        iterations: est.iterations,
        identifiability: view.as_ref().and_then(identifiability_of),
        intervals: at_maximum,
        view,
        warnings,
        matrices: est.matrices,
        curves: None,
    })
}

fn fit_als(problem: &NoiseProblem, als: &Als) -> Result<Fit, ReportError> {
    let est = als.estimate(problem).map_err(ReportError::Als)?;
    let mut warnings = Vec::new();
    if let Some(w) = est.warning() {
        warnings.push(w);
    }
    if est.constrained {
        warnings.push(
            "the unconstrained ALS solution was not positive semi-definite: the constrained \
             least-squares solution is reported"
                .to_string(),
        );
    }
    for (p, v) in est.parameters.iter().zip(&est.values) {
        if p.positive() && *v <= 0.0 {
            warnings.push(format!(
                "{} = {v:e} is at its bound 0: the autocovariances are fitted best with no \
                 such noise",
                p.name
            ));
        }
    }
    let unidentifiable = est.warning().into_iter().collect();
    let identifiability = Some(ReportIdentifiability {
        source: "least-squares matrix".to_string(),
        parameters: est.free,
        rank: est.rank,
        condition: est.condition.is_finite().then_some(est.condition),
        unidentifiable,
        message: if est.unique() {
            format!(
                "the autocovariances at {} lags determine all {} parameters (rank {}, \
                 condition number {:.3e})",
                est.lags, est.free, est.rank, est.condition
            )
        } else {
            est.warning().unwrap_or_default()
        },
    });
    Ok(Fit {
        values: est.values.clone(),
        converged: true,
        iterations: 0,
        view: None,
        intervals: false,
        identifiability,
        warnings,
        matrices: est.matrices,
        curves: None,
    })
}

fn fit_j1j2(
    problem: &NoiseProblem,
    sweep: &ParameterSweep,
    start: &NoiseMatrices,
) -> Result<Fit, ReportError> {
    let curves = sweep.sweep(problem, start).map_err(ReportError::Sweep)?;
    let noise = problem.noise();
    let mut warnings = vec![
        "J1/J2 moves each parameter to its own crossover with the others at the starting \
         guess; the crossovers are combined, not found jointly, and carry no interval"
            .to_string(),
    ];
    let (mut qw, mut r) = (start.qw.clone(), start.r.clone());
    let mut converged = true;
    for curve in &curves {
        let p = &curve.parameter;
        if let Some(reason) = &curve.skipped {
            warnings.push(format!("{} is not swept: {reason}", p.name));
            continue;
        }
        let Some(c) = &curve.crossover else {
            converged = false;
            warnings.push(format!(
                "{}: J1 and J2 do not cross on the grid; it stays at its starting value",
                p.name
            ));
            continue;
        };
        let scale = 10f64.powf(c.p);
        match p.matrix {
            NoiseMatrix::Qw => qw = scale_parameter(noise.qw_form().kind(), &qw, p, scale),
            NoiseMatrix::R => r = scale_parameter(noise.r_form().kind(), &r, p, scale),
        }
    }
    let q = match noise.g() {
        Some(g) => g * &qw * g.transpose(),
        None => qw.clone(),
    };
    let matrices = NoiseMatrices { qw, r, q };
    let values = noise
        .parameters()
        .iter()
        .map(|p| {
            crate::em::natural_value(
                p,
                noise.qw_form(),
                noise.r_form(),
                &matrices.qw,
                &matrices.r,
            )
        })
        .collect();
    Ok(Fit {
        identifiability: None,
        matrices,
        values,
        converged,
        iterations: 0,
        view: None,
        intervals: false,
        warnings,
        curves: Some(curves),
    })
}

/// Why the filter could not be judged.
#[derive(Debug, thiserror::Error)]
pub(crate) enum CheckError {
    #[error("model: {0}")]
    Model(#[from] ModelError),
    #[error("run {run}: {source}")]
    Filter { run: usize, source: FilterError },
    #[error("evaluation: {0}")]
    Eval(#[from] kalibra_eval::EvalError),
}

/// Runs a filter made by `filter_of` (a fresh one from `x0`, `P0` for each run) over every
/// run and judges the log with [`kalibra_eval::Evaluation`]: the one filter check of the
/// Kalman filter, the EKF and the UKF.
pub(crate) fn check_runs<N: Dim, M: Dim, F: Filter<N, M>>(
    n: usize,
    m: usize,
    runs: &[Vec<Option<OVector<f64, M>>>],
    start: Start,
    truth: Option<&[Run]>,
    mut filter_of: impl FnMut() -> Result<F, FilterError>,
) -> Result<FilterCheck, CheckError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let steps = runs.iter().map(Vec::len).max().unwrap_or(0);
    let cells = runs.len() * steps;
    let mut innovation = vec![None; cells];
    let mut s = vec![None; cells];
    let mut estimate = vec![None; cells];
    let mut covariance = vec![None; cells];
    for (run, zs) in runs.iter().enumerate() {
        let filter = |source| CheckError::Filter { run, source };
        let mut kf = filter_of().map_err(filter)?;
        let trajectory = kf
            .run_all(zs.iter().map(Option::as_ref), start)
            .map_err(filter)?;
        // Entry 0 is the initial estimate; entry i + 1 belongs to step i of the run.
        for (step, entry) in trajectory.entries()[1..].iter().enumerate() {
            let cell = run * steps + step;
            if let Some(rec) = entry.record() {
                innovation[cell] = Some(rec.innovation().iter().copied().collect());
                s[cell] = Some(row_major(rec.s_matrix()));
            }
            estimate[cell] = Some(entry.mean().iter().copied().collect());
            covariance[cell] = Some(row_major(entry.covariance()));
        }
    }
    let mut log = FilterLog::new(runs.len(), steps)?
        .with_innovation(Vectors::cells(m, innovation))?
        .with_innovation_cov(Matrices::cells(m, m, s))?;
    // The evaluation shortens the lags itself on a short log.
    let mut evaluation = Evaluation::new()
        .lags(WHITENESS_LAGS)?
        .group("state", (0..n).collect())?;
    if let Some(truth) = truth {
        let mut t = vec![None; cells];
        for (run, xs) in truth.iter().enumerate() {
            for (step, x) in xs.iter().enumerate() {
                t[run * steps + step] = x.as_ref().map(|x| x.iter().copied().collect());
            }
        }
        log = log
            .with_truth(Vectors::cells(n, t))?
            .with_estimate(Vectors::cells(n, estimate))?
            .with_covariance(Matrices::cells(n, n, covariance))?;
    } else {
        evaluation = Evaluation::new().lags(WHITENESS_LAGS)?;
    }
    let report = evaluation.evaluate(&log)?;
    let rmse_of = |name: &str| {
        report
            .rmse_per_step
            .iter()
            .find(|r| r.name == name)
            .and_then(|r| r.over_time)
    };
    Ok(FilterCheck {
        anis: report.summary.anis_test.clone(),
        whiteness: report.whiteness.clone(),
        anees: report.summary.anees_test.clone(),
        rmse: truth.and_then(|_| rmse_of("state")),
        rmse_per_component: if truth.is_some() {
            (0..n).map(|i| rmse_of(&format!("x{i}"))).collect()
        } else {
            Vec::new()
        },
        verdict: format!(
            "{}: {}",
            outcome(report.summary.verdict.kind),
            report.summary.verdict.evidence
        ),
    })
}

fn row_major<D: Dim>(m: &OMatrix<f64, D, D>) -> Vec<f64>
where
    DefaultAllocator: Alloc<D>,
{
    (0..m.nrows())
        .flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)]))
        .collect()
}

/// The form of `matrix` with parameter `param` held at `value` and its other free entries
/// starting at `warm` (the warm start); `None` when no positive-definite starting matrix
/// holds that value with the form's fixed entries.
fn held_form(
    form: &CovarianceForm,
    param: &Parameter,
    value: f64,
    warm: &DMatrix<f64>,
) -> Option<CovarianceForm> {
    let d = form.dim();
    match (form.kind(), param.entry) {
        (FormKind::Scaled, _) | (_, None) => Some(CovarianceForm::fixed(form.value() * value)),
        (FormKind::Diagonal, Some((i, _))) => {
            let mut start = DMatrix::from_diagonal(&warm.diagonal());
            for k in 0..d {
                if form.is_fixed(k, k) {
                    start[(k, k)] = form.value()[(k, k)];
                }
            }
            start[(i, i)] = value;
            let mut out = CovarianceForm::diagonal(start);
            for k in 0..d {
                if form.is_fixed(k, k) {
                    out = out.fix(k, k);
                }
            }
            Some(out.fix(i, i))
        }
        (FormKind::Full, Some((i, j))) => {
            let mut start = warm.clone();
            for a in 0..d {
                for b in 0..=a {
                    if form.is_fixed(a, b) {
                        start[(a, b)] = form.value()[(a, b)];
                        start[(b, a)] = form.value()[(a, b)];
                    }
                }
            }
            if i == j {
                // Keep the correlations: D X D with D scaling row and column i.
                let s = (value / start[(i, i)]).sqrt();
                if !s.is_finite() || s <= 0.0 {
                    return None;
                }
                for k in 0..d {
                    if k != i {
                        start[(i, k)] *= s;
                        start[(k, i)] *= s;
                    }
                }
                start[(i, i)] = value;
            } else {
                start[(i, j)] = value;
                start[(j, i)] = value;
                // Grow the free variances of rows i and j until the start is positive
                // definite (a covariance beyond them needs larger variances).
                let mut tries = 0;
                while start.clone().cholesky().is_none() {
                    tries += 1;
                    if tries > 60 || (form.is_fixed(i, i) && form.is_fixed(j, j)) {
                        return None;
                    }
                    for k in [i, j] {
                        if !form.is_fixed(k, k) {
                            start[(k, k)] *= 2.0;
                        }
                    }
                }
            }
            let mut out = CovarianceForm::full(start);
            for a in 0..d {
                for b in 0..=a {
                    if form.is_fixed(a, b) {
                        out = out.fix(a, b);
                    }
                }
            }
            Some(out.fix(i, j))
        }
        (FormKind::Fixed, _) => None,
    }
}

/// The profile log-likelihood at one value of parameter `index`, re-maximised over the
/// others from the warm start `warm`. Returns the maximum and the matrices there.
fn profile_point(
    problem: &dyn ReportProblem,
    param: &Parameter,
    value: f64,
    warm: &NoiseMatrices,
) -> Option<(f64, bool, NoiseMatrices)> {
    let noise = problem.noise();
    let (qw_form, r_form) = match param.matrix {
        NoiseMatrix::Qw => (
            held_form(noise.qw_form(), param, value, &warm.qw)?,
            noise.r_form().clone(),
        ),
        NoiseMatrix::R => (
            noise.qw_form().clone(),
            held_form(noise.r_form(), param, value, &warm.r)?,
        ),
    };
    // The problem's likelihood under the held parametrisation: the runs are not copied.
    let held = Parametrisation::new(noise.g().cloned(), qw_form, r_form).ok()?;
    let ll = |theta: &[f64]| -> Result<f64, LikelihoodError> {
        problem.log_likelihood_at(&held.matrices(theta)?)
    };
    if held.is_empty() {
        let m = held.matrices(&[]).ok()?;
        let ll = problem.log_likelihood_at(&m).ok()?;
        return Some((ll, true, m));
    }
    // Warm start: the neighbour's other parameters (the held entry is not read, or is set).
    let theta0 = held
        .theta_of(&warm.qw, &warm.r)
        .ok()
        .filter(|t| ll(t.as_slice()).is_ok())
        .unwrap_or_else(|| held.start());
    let scale = problem.measurement_count() as f64;
    let objective = |theta: &[f64]| -> Option<f64> {
        if theta
            .iter()
            .zip(theta0.iter())
            .any(|(t, w)| (t - w).abs() > PROFILE_WALL)
        {
            return None;
        }
        ll(theta).ok().map(|l| -l / scale)
    };
    let out = optim::minimise(
        &objective,
        theta0.as_slice(),
        Settings {
            gradient_tolerance: PROFILE_TOLERANCE,
            max_iterations: PROFILE_ITERATIONS,
        },
    )?;
    let m = held.matrices(&out.x).ok()?;
    Some((-out.f * scale, out.stop == StopReason::Gradient, m))
}

/// The profile of parameter `index` (see the module docs and [`PROFILE_POINTS`]).
fn profile(
    problem: &dyn ReportProblem,
    view: &MlEstimate,
    param: &ReportParameter,
    index: usize,
    ll_max: f64,
) -> Option<Profile> {
    let meta = &view.parameters[index].parameter;
    let value = param.value;
    let side = PROFILE_POINTS / 2;
    if let Some(bound) = param.at_bound {
        return bound_profile(problem, view, meta, value, bound, ll_max);
    }
    // Grid values at offsets j = -side..=side of the span.
    let at = |j: isize| -> f64 {
        let frac = j as f64 / side as f64;
        if meta.positive() {
            let se_log = param
                .stderr
                .filter(|s| s.is_finite() && *s > 0.0 && value > 0.0)
                .map_or(PROFILE_SPAN_NO_STDERR, |s| {
                    (PROFILE_SPAN * s / value).min(PROFILE_SPAN * 4.0)
                });
            value * (se_log * frac).exp()
        } else {
            let scale = match meta.matrix {
                NoiseMatrix::Qw => &view.matrices.qw,
                NoiseMatrix::R => &view.matrices.r,
            };
            let (i, j2) = meta.entry.unwrap_or((0, 0));
            let fallback = 0.5 * (scale[(i, i)] * scale[(j2, j2)]).sqrt();
            let span = param
                .stderr
                .filter(|s| s.is_finite() && *s > 0.0)
                .map_or(fallback, |s| PROFILE_SPAN * s);
            value + span * frac
        }
    };
    let walk = |dir: isize| -> Vec<ProfilePoint> {
        let mut warm = view.matrices.clone();
        let mut out = Vec::new();
        for k in 1..=side as isize {
            let v = at(dir * k);
            match profile_point(problem, meta, v, &warm) {
                Some((ll, converged, m)) => {
                    warm = m;
                    out.push(ProfilePoint {
                        value: v,
                        log_likelihood: Some(ll),
                        converged,
                    });
                }
                None => out.push(ProfilePoint {
                    value: v,
                    log_likelihood: None,
                    converged: false,
                }),
            }
        }
        out
    };
    let (down, up) = rayon::join(|| walk(-1), || walk(1));
    let mut points: Vec<ProfilePoint> = down.into_iter().rev().collect();
    points.push(ProfilePoint {
        value,
        log_likelihood: Some(ll_max),
        converged: true,
    });
    points.extend(up);
    let threshold = ll_max - HALF_CHI2_95;
    let centre = side;
    let crossing = |range: Vec<usize>| -> Option<f64> {
        let mut prev = centre;
        for k in range {
            let (a, b) = (&points[prev], &points[k]);
            let (la, lb) = (a.log_likelihood?, b.log_likelihood?);
            if lb < threshold {
                let t = (la - threshold) / (la - lb);
                return Some(a.value + t * (b.value - a.value));
            }
            prev = k;
        }
        None
    };
    let low = crossing((0..centre).rev().collect());
    let high = crossing((centre + 1..points.len()).collect());
    // A profile without a point is nothing to draw.
    if points.iter().all(|p| p.log_likelihood.is_none()) {
        return None;
    }
    Some(Profile {
        points,
        threshold,
        interval: [low, high],
    })
}

/// The profile of a parameter at a bound: the estimate (at the bound's side) and
/// `PROFILE_POINTS - 1` points log-spaced over five decades from the parameter's starting
/// value towards the other side (`start 10^-4 .. start 10` for a bound at 0, `start / 10 ..
/// start 10^4` at infinity), walked from the estimate; the crossing of the threshold is the
/// one-sided 95% limit the data put on it.
fn bound_profile(
    problem: &dyn ReportProblem,
    view: &MlEstimate,
    meta: &Parameter,
    value: f64,
    bound: Bound,
    ll_max: f64,
) -> Option<Profile> {
    let noise = problem.noise();
    let start = noise.natural(noise.start().as_slice()).ok()?;
    let index = noise.parameters().iter().position(|p| p == meta)?;
    let reference = start[index];
    let count = PROFILE_POINTS - 1;
    let decades = |k: usize| 5.0 * k as f64 / (count - 1) as f64;
    let grid: Vec<f64> = (0..count)
        .map(|k| match bound {
            Bound::Zero => reference * 10f64.powf(decades(k) - 4.0),
            Bound::Infinity => reference * 10f64.powf(3.0 - decades(k)),
        })
        .collect();
    let threshold = ll_max - HALF_CHI2_95;
    let mut warm = view.matrices.clone();
    let mut walked = vec![ProfilePoint {
        value,
        log_likelihood: Some(ll_max),
        converged: true,
    }];
    let mut limit = None;
    for v in grid {
        let point = profile_point(problem, meta, v, &warm);
        let ll = point.as_ref().map(|p| p.0);
        if let (Some(l), Some(prev)) = (ll, walked.last())
            && limit.is_none()
            && l < threshold
            && let Some(lp) = prev.log_likelihood
        {
            let t = (lp - threshold) / (lp - l);
            limit = Some(prev.value + t * (v - prev.value));
        }
        walked.push(ProfilePoint {
            value: v,
            log_likelihood: ll,
            converged: point.as_ref().is_some_and(|p| p.1),
        });
        if let Some((_, _, m)) = point {
            warm = m;
        }
    }
    walked.sort_by(|a, b| a.value.total_cmp(&b.value));
    Some(Profile {
        points: walked,
        threshold,
        interval: match bound {
            Bound::Zero => [Some(0.0), limit],
            Bound::Infinity => [limit, None],
        },
    })
}
