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
    /// A statistical test or summary got fewer samples than it is defined for.
    #[error("{what}: needs at least {needed} samples, got {got}")]
    TooFewSamples {
        /// What was computed.
        what: &'static str,
        /// Samples needed.
        needed: usize,
        /// Samples given.
        got: usize,
    },
    /// A NaN or an infinity in the input series; a statistic of it would be meaningless.
    #[error("{what}: sample {index} is not finite")]
    NonFinite {
        /// What was computed.
        what: &'static str,
        /// Index of the first offending sample.
        index: usize,
    },
    /// Two samples that must pair up element by element differ in length.
    #[error("{what}: the samples differ in length ({left} and {right})")]
    LengthMismatch {
        /// What was computed.
        what: &'static str,
        /// Length of the first sample.
        left: usize,
        /// Length of the second sample.
        right: usize,
    },
    /// A parameter outside its valid range (e.g. a batch size of zero).
    #[error("{what}: {reason}")]
    InvalidParameter {
        /// What was computed.
        what: &'static str,
        /// Which parameter and why it is invalid.
        reason: &'static str,
    },
    /// Valid input on which a test statistic is undefined (zero variance, all samples on one
    /// side of the median); reported rather than returned as a NaN p-value.
    #[error("{what}: {reason}")]
    Degenerate {
        /// What was computed.
        what: &'static str,
        /// Why the statistic is undefined.
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
