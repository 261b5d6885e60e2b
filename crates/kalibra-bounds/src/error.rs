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
    /// An average over steps (the surrogate's ergodic averages) got fewer samples than it is
    /// defined for.
    #[error("{what}: needs at least {needed} samples, got {got}")]
    TooFewSamples {
        /// What was computed.
        what: &'static str,
        /// Samples needed.
        needed: usize,
        /// Samples given.
        got: usize,
    },
    /// A parameter outside its valid range (e.g. a confidence level outside (0, 1)).
    #[error("{what}: {reason}")]
    InvalidParameter {
        /// What was computed.
        what: &'static str,
        /// Which parameter and why it is invalid.
        reason: &'static str,
    },
    /// The surrogate's coefficient matrix `C = (I - K* H) J*` has spectral radius 1 or more
    /// (for example an axis the measurement never observes): the surrogate error process has
    /// no bounded stationary covariance.
    #[error("surrogate AR matrix has spectral radius {spectral_radius}, not below 1")]
    Unstable {
        /// The spectral radius found.
        spectral_radius: f64,
    },
    /// A covariance or information matrix failed its check (not positive definite, not
    /// finite, wrong size).
    #[error(transparent)]
    Linalg(#[from] LinalgError),
}
