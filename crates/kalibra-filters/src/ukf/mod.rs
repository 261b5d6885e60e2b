//! The unscented Kalman filter, with a fixed sigma-point set or with the scaling parameter
//! `kappa` chosen at every update from a grid (paper 001, section III-C).
//!
//! # Where each job lives
//! * `ukf/sigma.rs`: the sigma-point sets and their weights ([`SigmaSet`], [`SigmaWeights`]).
//! * `ukf/kappa.rs`: the adaptive kappa's criteria and grid ([`KappaCriterion`],
//!   [`KappaGrid`]), and the criterion's value and choice rule that the scalar and the batched
//!   UKF share.
//! * `ukf/space.rs`: non-Euclidean spaces ([`SigmaSpace`], [`AngleComponents`]).
//! * `ukf/points.rs`: the sigma points' placement, images, means and cross covariance, shared
//!   with the square-root UKF ([`SqrtUkf`](crate::SqrtUkf)).
//! * `ukf/filter.rs`: the filter ([`Ukf`], [`UkfPrediction`]); `ukf/predict.rs` its unscented
//!   prediction; `ukf/update.rs` its update at one kappa and the choice among a grid's
//!   (shared with the square-root UKF).

mod filter;
mod kappa;
pub(crate) mod points;
mod predict;
mod sigma;
mod space;
mod update;

pub use filter::{Ukf, UkfPrediction};
pub(crate) use filter::{Unscented, unscented_builders};
pub use kappa::{KAPPA_GRID_MAX, KappaCriterion, KappaGrid};
pub use sigma::{SigmaSet, SigmaWeights};
pub use space::{AngleComponents, SigmaSpace};
pub(crate) use update::{CandidateParts, choose_kappa, criterion_value};
