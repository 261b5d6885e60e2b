//! What a first program needs, in one `use`: models, filters, metrics, bounds, Monte Carlo,
//! and the entry points of the two jobs that start from data, judging a log
//! ([`Evaluation::evaluate`] on a [`FilterLog`]) and tuning Q ([`Tuning::tune`] on a
//! [`TuneProblem`]).
//!
//! ```
//! use kalibra::prelude::*;
//!
//! // A 2-D constant-velocity target, positions measured, a Kalman filter, and the consistency
//! // of one run: NEES per step against its chi-square band.
//! let cv = Kinematic::constant_velocity(2, 1.0)?;
//! let f = cv.dynamics(U4)?;
//! let h = cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?;
//! let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
//! let truth = simulate(&f, &h, x0, 50, &mut MonteCarlo::new(1, 7).rng(0))?;
//! let mut kf = Kf::new(&f, &h, x0, Matrix4::identity() * 100.0)?;
//! let records = kf.run_collect(truth.measurements.iter().map(Some), Start::UpdateFirst)?;
//! let band = ChiSquareBand::for_normalized_mean(4.0, 1, 0.99)?;
//! let inside = records
//!     .iter()
//!     .zip(&truth.states)
//!     .filter(|(r, x)| band.contains(r.nees(&(*x - &r.posterior().mean)).unwrap_or(f64::NAN) / 4.0))
//!     .count();
//! assert!(inside > 40);
//! # Ok::<(), kalibra::Error>(())
//! ```

pub use crate::Error;

pub use kalibra_linalg::{
    Covariance, DMatrix, DVector, Dim, Dyn, Gaussian, Matrix1, Matrix2, Matrix3, Matrix4, OMatrix,
    OVector, SMatrix, SVector, U1, U2, U3, U4, U6, Vector1, Vector2, Vector3, Vector4, Vector6,
};

pub use kalibra_models::{
    Dynamics, Kinematic, LinearDynamics, LinearGaussian, LinearMeasurement, LinearObservation,
    Measurement, ProcessNoise, Simulator, Truth, simulate,
};

pub use kalibra_filters::{
    ConstantGainKf, Ekf, Filter, FilterOptions, Kf, SigmaSet, Smoothable, SqrtKf, SqrtUkf, Srf,
    Start, StepRecord, Ukf,
};

pub use kalibra_metrics::{
    ChiSquareBand, Credibility, JHorizon, SquaredErrors, StepMean, crossover, j_step, nees, nis,
    rmse, sliding_window, time_average,
};

pub use kalibra_bounds::{ErgodicAverage, Pcrlb, Surrogate};

pub use kalibra_sim::{ChaCha8Rng, MonteCarlo};

pub use kalibra_tune::{TuneProblem, TuneReport, Tuning, grid, sweep};

pub use kalibra_eval::{Evaluation, Evaluator, FilterLog, Matrices, Report, Vectors, VerdictKind};
