//! Rauch-Tung-Striebel smoothers: every step's estimate given the whole log (or, fixed-lag,
//! the log up to a few steps later), with the lag-one cross-covariances that EM needs.
//!
//! # What is here
//! * [`Smoothable`]: the filters a smoother runs over, [`Kf`](crate::Kf),
//!   [`Ekf`](crate::Ekf) and [`Ukf`](crate::Ukf), with provided methods that run and smooth in
//!   one call ([`Smoothable::smooth`], [`Smoothable::smooth_fixed_lag`]); the square-root
//!   filters ([`SqrtKf`](crate::SqrtKf), [`SqrtUkf`](crate::SqrtUkf)) as the KF and the UKF,
//!   over the covariances their factors stand for, except that the `SqrtKf`'s
//!   [`Smoothable::smooth`] runs the square-root backward pass on its factors (one QR
//!   triangularisation per step, `sqrt/smooth.rs`), which carries on where the covariance
//!   form's solve with `P-_{k+1}` fails (`tests/sqrt_ill_conditioned.rs`).
//! * [`ForwardPass`]: a run stored for smoothing ([`Smoothable::forward`]), smoothed later
//!   without the filter ([`ForwardPass::smooth`]) into [`Smoothed`] steps.
//! * [`FixedLagSmoother`]: one measurement at a time, memory for `lag + 2` steps.
//!
//! # The recursion
//! With `x_k, P_k` the filtered estimate of step `k` (the posterior, or the prediction at a
//! step without a measurement), `x-_{k+1}, P-_{k+1}` the prediction from it and
//! `C_k = Cov(x_k, x_{k+1})` the prediction's cross-covariance, from the last step back:
//!
//! `G_k = C_k (P-_{k+1})^-1`, `x_{k|n} = x_k + G_k (x_{k+1|n} - x-_{k+1})`,
//! `P_{k|n} = P_k + G_k (P_{k+1|n} - P-_{k+1}) G_k^T`, and the lag-one covariance
//! `P_{k+1,k|n} = Cov(x_{k+1}, x_k | z_1..z_n) = P_{k+1|n} G_k^T` (de Jong's form of
//! Shumway and Stoffer's lag-one recursion, property 6.3; pykalman's `_smooth_pair`).
//!
//! * Linear RTS (Rauch, Tung and Striebel 1965) over the [`Kf`](crate::Kf):
//!   `C_k = P_k F_k^T` with the model's `F_k`.
//! * Extended RTS over the [`Ekf`](crate::Ekf): the same with the forward pass's
//!   linearisation, the Jacobian `F_k` at the filtered mean `x_k`, the one its prediction used.
//! * Unscented RTS (Sarkka 2008) over the [`Ukf`](crate::Ukf): `C_k` from the sigma points the
//!   filter's prediction drew (same set, weights and square root), the predicted estimate the
//!   filter's own; with a state space ([`Ukf::with_state_space`](crate::Ukf::with_state_space),
//!   for instance an [`AngleComponents`](crate::AngleComponents) heading) the deviations and
//!   the difference `x_{k+1|n} - x-_{k+1}` go through its residual and the smoothed mean is
//!   normalised, so a heading smooths across `+-pi`.
//!
//! The smoothed estimate of the last step is the filter's. With [`Start::PredictFirst`] the
//! initial estimate is step 0 of the pass and is smoothed too (EM's initial-state update needs
//! it); with [`Start::UpdateFirst`] it is the prior of the first measurement's step, which the
//! pass starts at.
//!
//! # Numerical choices
//! * `G_k` is a Cholesky solve with the predicted covariance `P-_{k+1}` (`G P- = C`), never an
//!   explicit inverse; a predicted covariance without a factor is a
//!   [`FilterError::NotPositiveDefinite`] naming its step.
//! * The smoothed covariance is symmetrised after every step, as the filters do; the lag-one
//!   covariance is not symmetric and is left as computed.
//! * The filter's own prior is used, never recomputed, and `C_k` is evaluated with the
//!   arguments of the filter's prediction, so the smoother sees exactly the forward pass (the
//!   unscented one evaluates the dynamics at the sigma points a second time to form `C_k`).
//! * A smoothed mean or covariance that overflows is a [`FilterError::NonFinite`] naming its
//!   step.
//!
//! # Checked
//! Against FilterPy 2.0.0's `KalmanFilter.rts_smoother` and `UnscentedKalmanFilter.rts_smoother`
//! and pykalman's `KalmanFilter.smooth` and lag-one covariances, from fixtures written by
//! `tests/fixtures/smooth/make_fixtures.py` (`tests/smooth_fixtures.rs`); the fixed-lag
//! smoother against the full one, and the PSD order, the last step and the KF = EKF = UKF
//! agreement on linear models by property tests (`tests/smooth.rs`).
//!
//! [`Start::PredictFirst`]: crate::Start::PredictFirst
//! [`Start::UpdateFirst`]: crate::Start::UpdateFirst
//! [`FilterError::NotPositiveDefinite`]: crate::FilterError::NotPositiveDefinite
//! [`FilterError::NonFinite`]: crate::FilterError::NonFinite

mod fixed_lag;
mod forward;
mod linear;
mod rts;
mod smoothable;
mod unscented;

pub use fixed_lag::FixedLagSmoother;
pub use forward::{FilteredStep, ForwardPass, Prediction};
pub use rts::{Smoothed, SmoothedStep};
pub use smoothable::Smoothable;
