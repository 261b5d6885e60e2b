//! kalibra: build, tune and judge Kalman-type filters, and reproduce the published studies that
//! specify them.
//!
//! This facade re-exports the workspace's crates under short names; depend on the individual
//! crates (`kalibra-filters`, `kalibra-metrics`, ...) to take only what you need.
//!
//! | module | crate | job |
//! |---|---|---|
//! | [`linalg`] | `kalibra-linalg` | dimension-generic matrices, checked covariances, filter kernels |
//! | [`models`] | `kalibra-models` | dynamics and measurement traits, CV/CA, ballistic and bearing models, truth simulation |
//! | [`filters`] | `kalibra-filters` | the `Filter` trait, KF and EKF, step records |
//! | [`metrics`] | `kalibra-metrics` | NEES, NIS, chi-square bands, RMSE accumulators, J1/J2/nq, ITSE, hypothesis tests |
//! | [`bounds`] | `kalibra-bounds` | posterior Cramér-Rao bound, observability along a trajectory |
//! | [`sim`] | `kalibra-sim` | seeded parallel Monte Carlo, identical for any thread count; Q sweeps, initial tuning |
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

pub use kalibra_bounds as bounds;
pub use kalibra_filters as filters;
pub use kalibra_linalg as linalg;
pub use kalibra_metrics as metrics;
pub use kalibra_models as models;

pub use kalibra_sim as sim;

/// The README's example, compiled and run as a doctest so that it stays true.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
