//! Kalman-type filters for kalibra.
//!
//! # What this crate is for
//! * [`Filter`]: a recursive estimator stepped by `predict` and `update`, with provided methods
//!   that run it over a measurement sequence from anywhere (a simulation, a log file, a sensor),
//!   with gaps where a step has no measurement, reporting the updates ([`Filter::run`]) or every
//!   step's estimate ([`Filter::run_all`], a [`Trajectory`]). It is dyn-compatible: a bank of
//!   different filters is one `Vec<Box<dyn Filter<N, M>>>`.
//! * [`Kf`] (linear models), [`Ekf`] (nonlinear models) and [`ConstantGainKf`] (a fixed gain,
//!   the user's or the steady-state one), sharing one numerical core.
//! * [`StepRecord`]: what each update computed (prior and posterior, innovation, `S`, `K`, `H`,
//!   `R`, `F`, and the split of the prior covariance into `F P+ F^T` and `Q` that the J1/J2
//!   metrics need), so metrics never recompute and never see the filter.
//! * [`steady_state`]: the limit of the discrete Riccati recursion of a time-invariant model
//!   and its gain.
//!
//! * [`Ukf`]: the unscented Kalman filter with a [`SigmaSet`] value (paper 001's symmetric set,
//!   eqs 16-18, or the scaled set), angle-aware through the measurement residual and, as an
//!   option, in the state and the measurement mean ([`SigmaSpace`], [`AngleComponents`]), and with
//!   kappa chosen per update on a [`KappaGrid`] by a [`KappaCriterion`] (UKF-ML, UKF-MPP).
//! * [`Srf`]: the shifted Rayleigh filter for bearings (paper 001, Alg. 2, typos fixed) on any
//!   [`BearingSensor`], with [`shifted_rayleigh_moments`] evaluated stably.
//! * [`SqrtKf`] and [`SqrtUkf`] ([`sqrt`]): the KF and the UKF carrying a Cholesky factor of the
//!   covariance, for problems where the standard filters' covariance loses definiteness.
//! * [`smooth`]: Rauch-Tung-Striebel smoothers over the [`Kf`], [`Ekf`] and [`Ukf`] ([`Smoothable`]),
//!   full and fixed-lag, with the lag-one covariances EM needs.
//!
//! Every filter yields the same [`StepRecord`].
//!
//! # Where each job lives
//! * `filter.rs`: [`Filter`] and its runs; `record.rs`: [`StepRecord`]; `error.rs`:
//!   [`FilterError`].
//! * `core.rs`: the numerical core the KF, EKF and constant-gain KF share; `kalman.rs`: [`Kf`]
//!   and [`Ekf`]; `as_given.rs`: the as-given algebra; `constant_gain.rs`; `steady.rs`.
//! * `ukf/`: the UKF, one idea per file (`sigma.rs`, `kappa.rs`, `space.rs`, `filter.rs`,
//!   `predict.rs`, `update.rs`; see [`Ukf`]).
//! * `srf.rs` and `rayleigh.rs`: the shifted Rayleigh filter and its moments.
//! * [`batch`]: the batched KF, EKF and UKF, stepping many Monte Carlo runs at once (its module
//!   docs list its files); the SIMD vocabulary they use is kalibra-linalg's
//!   [`simd`](kalibra_linalg::simd).
//!
//! # Notation
//! `x-_k, P-_k` the prior (predicted) estimate at step `k`, `x+_k, P+_k` the posterior;
//! `nu_k = z_k - h_k(x-_k)` the innovation, `S_k = H_k P-_k H_k^T + R_k`, `K_k = P-_k H_k^T S_k^-1`.
//!
//! # Numerical choices
//! * Joseph-form covariance update by default ([`UpdateForm`]) for the KF and EKF; the UKF
//!   uses eq 7's `P- - K Pz K^T` and the SRF its eq 28; all symmetrised after every prediction
//!   and update.
//! * The gain is a Cholesky solve with `S`, whose factor the record keeps for NIS and
//!   likelihoods; no explicit inverse.
//! * A failing step returns a typed [`FilterError`] and leaves the filter as it was.
//! * The initial covariance is checked ([`InitialCheck`]); [`Kf::as_given`] and
//!   [`Ekf::as_given`] are the explicit opt-in to start from one as given (asymmetric or
//!   indefinite, as paper 000 prints it), with a type parameter ([`AsGiven`]) choosing that
//!   algebra so the checked filters pay nothing for it, and records that say what was not
//!   checked ([`StepRecord::initial_check`]).
//! * With `Const` dimensions a step allocates nothing: every matrix, the record included, lives
//!   inline.
//!
//! # Example
//! ```
//! use kalibra_filters::{Ekf, Filter};
//! use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};
//! use kalibra_linalg::{Matrix4, U4, Vector1, Vector2, Vector4};
//!
//! let cv = Kinematic::constant_velocity(2, 1.0)?.dynamics(U4)?;
//! let sensor = Bearing::new(U4, [0, 1], BearingReference::XAxis, 1e-4, Stationary(Vector2::zeros()))?;
//! let mut ekf = Ekf::new(cv, sensor, Vector4::new(100.0, 10.0, -1.0, 0.0), Matrix4::identity() * 10.0)?;
//! ekf.predict()?;
//! let record = ekf.update(&Vector1::new(0.11))?;
//! // NIS = nu^2 / S for a scalar measurement, from the record's innovation and S.
//! let direct = record.innovation()[0].powi(2) / record.s_matrix()[(0, 0)];
//! assert!((record.nis() - direct).abs() <= 1e-12 * direct);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod as_given;
pub mod batch;
mod constant_gain;
mod core;
mod error;
mod filter;
mod kalman;
mod rayleigh;
mod record;
pub mod smooth;
pub mod sqrt;
mod srf;
mod steady;
mod ukf;

pub use crate::core::{AsGiven, Checked, Checking, FilterOptions, InitialCheck, UpdateForm};
pub use constant_gain::ConstantGainKf;
pub use error::FilterError;
pub use filter::{Filter, Start, Trajectory, TrajectoryEntry};
pub use kalman::{Ekf, Kf};
pub use rayleigh::{ShiftedRayleigh, shifted_rayleigh_moments};
pub use record::{Estimate, StepRecord};
pub use smooth::{FixedLagSmoother, ForwardPass, Smoothable, Smoothed, SmoothedStep};
pub use sqrt::{SqrtKf, SqrtUkf};
pub use srf::{BearingSensor, Srf};
pub use steady::{RICCATI_MAX_ITERATIONS, RICCATI_TOLERANCE, SteadyState, steady_state};
pub use ukf::{
    AngleComponents, KAPPA_GRID_MAX, KappaCriterion, KappaGrid, SigmaSet, SigmaSpace, SigmaWeights,
    Ukf, UkfPrediction,
};
