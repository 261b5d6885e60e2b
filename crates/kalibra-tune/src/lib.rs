//! Choose the noise covariances `Q` and `R` of a Kalman-type filter from recorded measurements.
//!
//! # What this crate is for
//! An engineer with a measurement log and a model whose noise levels can only be guessed needs
//! a `Q` and an `R`, and to know how far the data support them. This crate holds the methods
//! that answer from the data:
//! * the offline `Q` sweep of Saha, Goswami and Ghosh ([`Tuning::tune`] on a [`TuneProblem`]:
//!   `F`, `H`, `Q_nom`, `R`, `x0`, `P0` and measurements with gaps), which runs a Kalman filter
//!   at every `Q = 10^p Q_nom` of a grid and reports `J1`, `J2`, `nq`, their crossover and the
//!   recommended `Q` in a serialisable [`TuneReport`]; it is the library behind `kalibra tune`;
//! * the tuning helpers the reproduced studies use: [`grid`] and [`sweep`] (any function over
//!   a grid of exponents, in parallel, results in grid order), two-point initialisation
//!   ([`two_point_init`]) and the adaptive initial covariance and process noise of Saha, Ghosh
//!   and Goswami ([`p_ad`], [`q_ad`]).
//! * parametrised noise ([`Parametrisation`]): `Q = G Qw G^T` with an optional `G`, `Qw` and
//!   `R` each fixed, scaled, diagonal or full (log-Cholesky), with chosen entries fixed, mapped
//!   to and from an unconstrained vector for the estimators, and refused when it asks for more
//!   than the `n m + m (m + 1) / 2` parameters innovations can identify.
//! * maximum likelihood ([`MaximumLikelihood::estimate`]): the exact log-likelihood of the
//!   innovations maximised over the free parameters from several starts, with standard errors
//!   and 95% intervals on the matrices' own scale, and what the data cannot identify named in
//!   words.
//! * the same for nonlinear models ([`MaximumLikelihood::estimate_nonlinear`] on a
//!   [`NonlinearNoiseProblem`]): any model implementing kalibra's model traits, its likelihood
//!   from the EKF or the UKF ([`LikelihoodFilter`]) with the model's noise replaced by each
//!   candidate's `Q` and `R` ([`WithProcessNoise`], [`WithMeasurementNoise`]), with the
//!   linear report ([`NoiseReport::estimate_nonlinear`]).
//!
//! * one report for every estimator ([`NoiseReport::estimate`] with a [`Method`]): the
//!   estimate, intervals, identifiability and warnings in words, the profile likelihood of
//!   every parameter, and the tuned filter and the starting guess judged on the data.
//!
//! It is not for judging a filter's logs (that is `kalibra-eval`, which the report calls to
//! judge the tuned filter's run) and it does no I/O: reading MODEL.toml and measurement files belongs to `kalibra-io`.
//!
//! # Notation
//! `n` states, `m` measurements; the model `x_k = F x_{k-1} + w_k`, `z_k = H x_k + v_k` with
//! `w_k ~ N(0, Q)`, `v_k ~ N(0, R)`; `x0`, `P0` the initial estimate and covariance, taken at
//! the step before the first measurement or at the first measurement according to
//! [`Start`]. A measurement sequence is one `Option` per step (`None`: no measurement, the
//! filter predicts through).
//!
//! # Numerical choices
//! Every filter run is the library's own [`kalibra_filters::Kf`] (for a nonlinear model its
//! `Ekf` or `Ukf`), so the numbers are those of a user's filter with the same matrices;
//! sweeps over a grid evaluate each point independently and in parallel and return them in
//! grid order, so results do not depend on the thread count (thread pools as `kalibra-sim` builds them, [`kalibra_sim::in_pool`]).
//! Grid points are computed as `from + i step`, never by accumulation.
//!
//! # Where each job lives
//! * `sweep_q`: the offline `Q` sweep ([`Tuning`], [`TuneProblem`], [`TuneReport`],
//!   [`TuneError`]).
//! * `tuning`: [`grid`], [`sweep`], [`two_point_init`], [`p_ad`], [`q_ad`] and their
//!   [`TuningError`].
//! * `em`: expectation-maximisation for `Qw` and `R` honouring their forms ([`Em`],
//!   [`EmEstimate`], [`EmError`]); the M-step of each form and its derivation in `em/mstep.rs`.
//! * `als`: autocovariance least squares ([`Als`], [`AlsEstimate`], [`AlsError`]).
//! * `j1j2`: the J1/J2 crossover on every free parameter around an estimate
//!   ([`ParameterSweep`], [`ParameterCurve`], [`SweepError`]).
//! * `noise`: what is known of the noise ([`Parametrisation`] of `Q = G Qw G^T` and `R` from
//!   [`CovarianceForm`]s) and the map between an optimiser's vector and the matrices;
//!   `problem`: [`NoiseProblem`], the model, the initial estimate and the runs of
//!   measurements the estimators work on; `error`: their [`NoiseError`].
//! * `likelihood`: [`log_likelihood`], the exact Gaussian log-likelihood of the innovations
//!   (the sum of `StepRecord::log_likelihood` over the library's `Kf`).
//! * `ml`: [`MaximumLikelihood`] -> [`MlEstimate`] (estimates, standard errors and 95% intervals
//!   from the observed information, [`Identifiability`], [`MlWarning`]s); `optim`: its BFGS
//!   minimiser and finite differences (why not argmin: in `optim`'s docs).
//! * `report`: [`NoiseReport`], the one result of every [`Method`] and of nonlinear maximum
//!   likelihood, with [`Profile`]s and the [`Consistency`] of the tuned filter on the data
//!   ([`ReportError`]), over any [`ReportProblem`].
//! * `ml_nonlinear`: maximum likelihood through the EKF or the UKF ([`NonlinearNoiseProblem`],
//!   [`LikelihoodFilter`], [`NonlinearProblemError`], the noise-replacing models
//!   [`WithProcessNoise`] and [`WithMeasurementNoise`]); the optimiser, the information and
//!   the report are `ml`'s, shared.
//!
//! # Example
//! ```
//! use kalibra_tune::{DMatrix, DVector, TuneProblem, Tuning};
//!
//! // A scalar random walk seen directly, tuned over Q = 10^p * 0.1 for p in -3..=3.
//! let one = |v: f64| DMatrix::from_element(1, 1, v);
//! let zs: Vec<Option<DVector<f64>>> = [0.3, -0.1, 0.8, 1.1, 0.6, 1.9, 2.2, 1.7]
//!     .iter()
//!     .map(|&z| Some(DVector::from_element(1, z)))
//!     .collect();
//! let problem = TuneProblem::new(one(1.0), one(1.0), one(0.1), one(0.5),
//!     DVector::zeros(1), one(1.0), zs)?;
//! let report = Tuning::new().exponents(-3.0, 3.0, 0.5)?.tune(&problem)?;
//! assert_eq!(report.points.len(), 13);
//! # Ok::<(), kalibra_tune::TuneError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod als;
mod em;
mod error;
mod j1j2;
mod kernel;
mod likelihood;
mod ml;
mod ml_nonlinear;
mod noise;
mod optim;
mod problem;
mod report;
mod sweep_q;
mod tuning;

pub use error::NoiseError;
pub use likelihood::{LikelihoodError, log_likelihood, log_likelihood_of};
pub use ml::{
    Bound, Combination, Identifiability, MaximumLikelihood, MlError, MlEstimate, MlWarning,
    ParameterEstimate, StartOutcome,
};
pub use ml_nonlinear::{
    LikelihoodFilter, NonlinearNoiseProblem, NonlinearProblemError, NonlinearRun,
    WithMeasurementNoise, WithProcessNoise,
};
pub use noise::{
    CovarianceForm, FormKind, NoiseMatrices, NoiseMatrix, Parameter, ParameterKind, Parametrisation,
};
pub use optim::StopReason;
pub use problem::{NoiseProblem, Run};
pub use report::{
    Consistency, FilterCheck, Method, MethodKind, NoiseReport, PROFILE_POINTS, Profile,
    ProfilePoint, ReportError, ReportIdentifiability, ReportOptions, ReportParameter,
    ReportProblem,
};

pub use als::{ALS_LAGS, ALS_MAX_ITERATIONS, ALS_RANK_TOLERANCE, Als, AlsError, AlsEstimate};
pub use em::{EM_MAX_ITERATIONS, EM_TOLERANCE, Em, EmError, EmEstimate};
pub use j1j2::{
    CurveCrossover, CurvePoint, J_SWEEP_FROM, J_SWEEP_STEP, J_SWEEP_TO, ParameterCurve,
    ParameterSweep, SweepError,
};
/// The start convention of a [`TuneProblem`] (predict first or update first), re-exported so
/// that a caller (the `kalibra` executable) needs no other kalibra crate.
pub use kalibra_filters::Start;
/// The sigma set and the prediction of the UKF a [`NonlinearNoiseProblem`] may use,
/// re-exported so that a caller needs no other kalibra crate to choose them.
pub use kalibra_filters::{SigmaSet, UkfPrediction};
/// The matrix and vector types of a [`TuneProblem`].
pub use kalibra_linalg::{DMatrix, DVector};
pub use sweep_q::{
    InitialCovariance, JDivisor, NoCrossover, PointRmse, RmseMinimum, TUNE_SCHEMA_VERSION,
    TuneCrossover, TuneError, TuneFindings, TunePoint, TuneProblem, TuneReport, Tuning,
    matrix_from_rows,
};
pub use tuning::{GRID_MAX_POINTS, TuningError, grid, p_ad, q_ad, sweep, two_point_init};

/// The most iterations [`Em`] and [`MaximumLikelihood`] may be asked for (each iteration runs
/// a filter over every run, a few times for maximum likelihood): a larger cap or exact count
/// is refused with a typed error before anything runs, so that an estimate's time is bounded.
pub const ITERATION_LIMIT: usize = 100_000;
