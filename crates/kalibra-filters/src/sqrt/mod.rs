//! Square-root filters: the [`Kf`](crate::Kf) and the [`Ukf`](crate::Ukf) carrying a
//! lower-triangular Cholesky factor `S` of the covariance (`P = S S^T`) instead of `P`.
//!
//! # What they are for
//! A covariance computed as `P` can stop being positive definite in double precision: a
//! near-perfect measurement against a large prior leaves a posterior whose smallest variance
//! is below the rounding of its largest, and the Joseph form's products, or the UKF's
//! `P- - K Pz K^T`, can then return an indefinite matrix. What follows depends on the
//! rounding: a later `S` fails its Cholesky factorisation
//! ([`FilterError::NotPositiveDefinite`](crate::FilterError)), which the standard filters
//! report, or, as in the committed case below, every step succeeds on an indefinite covariance
//! and the estimate drifts from the exact one with no error at all. A factor changed only by orthogonal transformations stands for a
//! positive semi-definite covariance whatever the rounding, and carries about twice the
//! precision of `P` (its condition number is the square root of `P`'s), so these filters carry
//! on where the standard ones stop. The committed case is `tests/sqrt_ill_conditioned.rs`.
//!
//! # The two steps
//! * **Prediction** (both filters): `S-` is the triangular factor of the QR factorisation of
//!   `[F S+, sqrt(Q)]^T` (for the UKF, of the weighted sigma-point deviations beside
//!   `sqrt(Q)`), `S- S-^T = F P+ F^T + Q` without forming that sum.
//! * **KF update: the QR array form**, not a sequence of Cholesky rank-one downdates. The QR
//!   factorisation of the transposed pre-array `[[sqrt(R), H S-], [0, S-]]` (`(m + n)` square)
//!   yields `[[S_z, 0], [Kbar, S+]]`: the factor of the innovation covariance, the scaled gain
//!   `Kbar = K S_z` and the posterior factor in one orthogonal pass. Downdating `S-` by the
//!   columns of `K S_z` computes the same `S+` with hyperbolic rotations, which are not
//!   orthogonal: in exactly the case these filters exist for (a posterior variance far below the
//!   prior's), a downdate subtracts nearly equal numbers and can fail outright, while the array
//!   form never subtracts. The cost is one QR factorisation of an `(m + n)`-square array per
//!   update.
//! * **UKF update** (after Van der Merwe and Wan, 2001): the measurement's factor `S_z` from the
//!   QR factorisation of the weighted sigma deviations beside `sqrt(R)`, then a rank-one update
//!   (or downdate, for a negative central weight) with the central point. For the posterior
//!   factor, Van der Merwe and Wan downdate `S-` by the `m` columns of `K S_z`; that is the
//!   downdate the KF avoids, and it fails on the committed ill-conditioned case's first update.
//!   Here the posterior is instead the spread of the sigma points' errors,
//!   `P+ = sum_i W_i (dx_i - K dz_i)(dx_i - K dz_i)^T + K R K^T` (equal to `P- - K Pz K^T` for
//!   the optimal gain, and the array form's analogue: the KF's array form computes the same
//!   `S+` as the factor of `[(I - K H) S-, K sqrt(R)]`), whose factor is one more QR
//!   factorisation; only a negative central weight needs a downdate, with the central point's
//!   error `K dz_0`, which fails only when the central weight's correction is larger than the
//!   rest, a typed [`FilterError::NotPositiveDefinite`](crate::FilterError).
//!
//! The noise square roots are pivoted semi-definite factors
//! ([`kalibra_linalg::semidefinite_factor`]), so a rank-deficient `Q = G G^T` or a singular `R`
//! is accepted; they are recomputed only when the model returns a different matrix.
//!
//! Both filters yield the standard filters' [`StepRecord`](crate::StepRecord), with the
//! covariances formed from the factors, so every metric reads them unchanged.

mod cholupdate;
mod kf;
mod noise_root;
mod qr;
mod smooth;
mod ukf;

pub use kf::SqrtKf;
pub use ukf::SqrtUkf;
