//! Typed errors of the bounds.

use kalibra_linalg::LinalgError;

/// What can go wrong computing a bound.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BoundsError {
    /// An expectation over an empty sample of truth states.
    #[error("{what}: the sample of truth states is empty")]
    EmptySample {
        /// Which expectation.
        what: &'static str,
    },
    /// A step index outside the trajectory, or too short a trajectory.
    #[error("{what}: needs {needed} steps, the trajectory has {got}")]
    TooShort {
        /// What was computed.
        what: &'static str,
        /// Steps needed.
        needed: usize,
        /// Steps available.
        got: usize,
    },
    /// A covariance or information matrix failed its check (not positive definite, not
    /// finite, wrong size).
    #[error(transparent)]
    Linalg(#[from] LinalgError),
}
