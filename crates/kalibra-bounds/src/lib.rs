//! Bounds for kalibra: what the best possible filter could achieve, and how well a trajectory
//! lets the state be seen.
//!
//! # What this crate is for
//! * [`Pcrlb`]: the posterior Cramér-Rao lower bound of Tichavsky, Muravchik and Nehorai (1998)
//!   for additive Gaussian noise, as a recursion on the Fisher information `J_k`. Expectations
//!   over the truth are averages over the sample of truth states the caller passes: many Monte
//!   Carlo truths, or one trajectory (then the bound is the Kalman covariance with Jacobians
//!   evaluated at the true state).
//! * [`observability_singular_values`]: the singular values of the local observability matrix
//!   `O_k = [H_k; H_{k+1} F_k; H_{k+2} F_{k+1} F_k; ...]` along a trajectory.
//! * [`Surrogate`] and [`ErgodicAverage`]: the surrogate uncertainty bound of Spall and Wei
//!   (2023) from the averaged gain and Jacobian along one long trajectory, with
//!   [`gaussian_half_widths`] and [`Ellipsoid`]. Whether that trajectory's error has settled
//!   into a stationary distribution is a hypothesis test, not a bound: batch means, the runs
//!   test, the paired t-test and the two-sample Kolmogorov-Smirnov test live in
//!   `kalibra_metrics::hypothesis`.
//!
//! Like the metrics, bounds take data (Jacobians, noise covariances), not models or filters.
//!
//! # Notation
//! `x_{k+1} = f_k(x_k) + w_k`, `w_k ~ N(0, Q_k)`; `z_k = h_k(x_k) + v_k`, `v_k ~ N(0, R_k)`;
//! `F_k = df_k/dx` at the true `x_k`, `H_k = dh_k/dx` at the true `x_k`. With
//! `D11 = E[F^T Q^-1 F]`, `D12 = -E[F]^T Q^-1`, `D22 = Q^-1 + E[H^T R^-1 H]`:
//! `J_{k+1} = D22 - D12^T (J_k + D11)^-1 D12`, `J_0 = P0^-1`, and the bound is
//! `E[(x_k - x^_k)(x_k - x^_k)^T] >= J_k^-1`.
//!
//! # Numerical choices
//! Every inverse that appears in the recursion is a Cholesky solve; `Q_k` must be positive
//! definite (the information form needs `Q^-1`; a rank-deficient `Q` is reported as an error,
//! not regularised). The bound itself, `J^-1`, is formed explicitly because it is the output.
//!
//! # Where each job lives
//! * `crlb`: the PCRLB recursion ([`Pcrlb`], [`MeasurementSample`]).
//! * `observability`: [`observability_singular_values`].
//! * `surrogate`: the surrogate bound ([`Surrogate`], [`ErgodicAverage`], [`Ellipsoid`],
//!   [`gaussian_half_widths`]).
//! * `error`: [`BoundsError`].
//!
//! # Example
//! ```
//! use kalibra_bounds::Pcrlb;
//! use kalibra_linalg::{Matrix1, Matrix2};
//! // A random walk observed directly: the bound is the Kalman filter's covariance.
//! let mut bound = Pcrlb::new(&Matrix1::new(10.0))?;
//! bound.predict(&[Matrix1::new(1.0)], &Matrix1::new(1.0))?;
//! bound.add_measurement(&[(Matrix1::new(1.0), Matrix1::new(4.0))])?;
//! // Kalman: P- = 11, P+ = 11 * 4 / 15.
//! assert!((bound.bound()?[(0, 0)] - 44.0 / 15.0).abs() < 1e-12);
//! # let _ = Matrix2::<f64>::zeros();
//! # Ok::<(), kalibra_bounds::BoundsError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod crlb;
mod error;
mod observability;
mod surrogate;

pub use crlb::{MeasurementSample, Pcrlb};
pub use error::BoundsError;
pub use observability::{OBSERVABILITY_SVD_MAX_ITERATIONS, observability_singular_values};
pub use surrogate::{
    COVARIANCE_AFTER_MAX_ITERATIONS, Ellipsoid, ErgodicAverage, Surrogate, gaussian_half_widths,
};
