//! kalibra: build, tune and judge Kalman-type filters.
//!
//! This is the front door: [`prelude`] brings what a first program needs into scope, [`Error`]
//! is the one error type every crate's error converts into, and the modules below re-export
//! the workspace's crates under short names. Depend on the individual crates
//! (`kalibra-filters`, `kalibra-metrics`, ...) to take only what you need. The repository's
//! `examples/` folder has complete programs: a user's own nonlinear model through the EKF and
//! UKF with a Monte Carlo consistency check, a Q sweep with J1/J2, a surrogate bound from one
//! trajectory, and a KF over a CSV file.
//!
//! | module | crate | job |
//! |---|---|---|
//! | [`linalg`] | `kalibra-linalg` | dimension-generic matrices, checked covariances, `Gaussian`, filter kernels, Lyapunov solver |
//! | [`models`] | `kalibra-models` | dynamics and measurement traits, CV/CA, linear-Gaussian, bearings, ballistic re-entry, angular and 3-D manoeuvring targets, truth simulation |
//! | [`filters`] | `kalibra-filters` | the `Filter` trait, KF, EKF, UKF (adaptive kappa), shifted Rayleigh filter, constant-gain KF, step records |
//! | [`metrics`] | `kalibra-metrics` | NEES, NIS, chi-square bands, NCI, RMSE accumulators, sliding windows, J1/J2/nq, ITSE, hypothesis tests |
//! | [`bounds`] | `kalibra-bounds` | posterior Cramér-Rao bound, observability, Spall-Wei surrogate bounds |
//! | [`eval`] | `kalibra-eval` | any filter's logged estimates, covariances and innovations judged: bands, NCI, RMSE, whiteness, J1/J2, a verdict |
//! | [`sim`] | `kalibra-sim` | seeded parallel Monte Carlo, identical for any thread count; Q sweeps, initial tuning |
//!
//! The reproduced papers are not part of the library: they live beside it in the
//! `kalibra-studies` crate and run with `cargo xtask reproduce`.
//!
//! # Example
//! ```
//! use kalibra::filters::{Filter, Kf, Start};
//! use kalibra::linalg::{Matrix2, Matrix4, U2, U4, Vector4};
//! use kalibra::models::{simulate, Kinematic};
//! use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
//!
//! let cv = Kinematic::constant_velocity(2, 1.0)?;
//! let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?);
//! let truth = simulate(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), 50, &mut ChaCha8Rng::seed_from_u64(1))?;
//! let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), Matrix4::identity() * 100.0)?;
//! let records = kf.run_collect(truth.measurements.iter().map(Some), Start::UpdateFirst)?;
//! assert_eq!(records.len(), 50);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
pub use kalibra_bounds as bounds;
pub use kalibra_eval as eval;
pub use kalibra_filters as filters;
pub use kalibra_linalg as linalg;
pub use kalibra_metrics as metrics;
pub use kalibra_models as models;
pub use kalibra_sim as sim;
pub use kalibra_tune as tune;

pub mod prelude;

/// Any error of kalibra's crates: the type a program that uses several of them can return.
///
/// Every crate's error converts into it with `?`, so a function that builds a model, runs a
/// filter and computes a metric returns `Result<_, kalibra::Error>`. The variants keep the
/// crate's typed error, so a caller can still match on what went wrong.
///
/// ```
/// fn consistency() -> Result<f64, kalibra::Error> {
///     let band = kalibra::metrics::ChiSquareBand::for_normalized_mean(4.0, 100, 0.95)?;
///     let cv = kalibra::models::Kinematic::constant_velocity(2, 1.0)?;
///     let _f = cv.dynamics(kalibra::linalg::U4)?;
///     Ok(band.upper)
/// }
/// assert!(consistency().unwrap() > 1.0);
/// ```
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A matrix computation failed (not positive definite, not finite, wrong size).
    #[error(transparent)]
    Linalg(#[from] kalibra_linalg::LinalgError),
    /// A model could not be built or simulated.
    #[error(transparent)]
    Model(#[from] kalibra_models::ModelError),
    /// A filter step or construction failed.
    #[error(transparent)]
    Filter(#[from] kalibra_filters::FilterError),
    /// A metric or hypothesis test could not be computed.
    #[error(transparent)]
    Metrics(#[from] kalibra_metrics::MetricsError),
    /// A bound (CRLB, surrogate) could not be computed.
    #[error(transparent)]
    Bounds(#[from] kalibra_bounds::BoundsError),
    /// A filter log could not be evaluated (its arrays are malformed).
    #[error(transparent)]
    Eval(#[from] kalibra_eval::EvalError),
    /// A tuning problem from recorded measurements could not be built or tuned.
    #[error(transparent)]
    Tune(#[from] kalibra_tune::TuneError),
    /// A tuning helper (grid, initial tuning) failed.
    #[error(transparent)]
    Tuning(#[from] kalibra_tune::TuningError),
    /// A Monte Carlo run failed (the lowest-numbered failing run).
    #[error("Monte Carlo run {run} failed: {source}")]
    Run {
        /// The run index.
        run: usize,
        /// Its error.
        #[source]
        source: Box<Error>,
    },
    /// The Monte Carlo thread pool could not be built.
    #[error("Monte Carlo thread pool of {threads} threads: {message}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// rayon's message.
        message: String,
    },
    /// Another failure of the Monte Carlo harness, rendered.
    #[error("Monte Carlo harness: {0}")]
    Harness(String),
}

impl From<kalibra_sim::SimError<Error>> for Error {
    fn from(e: kalibra_sim::SimError<Error>) -> Self {
        match e {
            kalibra_sim::SimError::Run { run, source } => Error::Run {
                run,
                source: Box::new(source),
            },
            kalibra_sim::SimError::ThreadPool { threads, message } => {
                Error::ThreadPool { threads, message }
            }
            // `SimError` is non-exhaustive: a harness failure added later keeps its message.
            other => Error::Harness(other.to_string()),
        }
    }
}

/// The README's example, compiled and run as a doctest so that it stays true.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
