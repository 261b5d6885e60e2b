use kalibra_linalg::LinalgError;
use kalibra_models::ModelError;

/// Why a filter step failed. The filter's state is left as it was before the failing call.
///
/// Messages are lowercase fragments that read after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FilterError {
    /// A covariance that must be positive definite is not (a singular innovation covariance
    /// `S`, an indefinite initial covariance).
    #[error("{what} is not positive definite at step {step}")]
    NotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
        /// The step index.
        step: usize,
    },
    /// An input or a computed quantity is NaN or infinite.
    #[error("{what} is not finite at step {step}")]
    NonFinite {
        /// Which quantity.
        what: &'static str,
        /// The step index.
        step: usize,
    },
    /// A matrix that must be invertible is exactly singular (the innovation covariance `S` of
    /// a filter started with [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven), or a
    /// covariance a record's NEES solves with).
    #[error("{what} is singular at step {step}")]
    Singular {
        /// Which matrix.
        what: &'static str,
        /// The step index.
        step: usize,
    },
    /// A filter was asked for a mode it does not implement (the UKF or the SRF started with
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven)), or a batch for an instruction
    /// set the CPU does not run.
    #[error("{what} is not supported")]
    Unsupported {
        /// What was asked for.
        what: &'static str,
    },
    /// A dynamically sized input has the wrong size.
    #[error("{what} has dimension {found}, expected {expected}")]
    DimensionMismatch {
        /// Which input.
        what: &'static str,
        /// The size required.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// A filter parameter is out of its valid range (a sigma-point spread `n + lambda <= 0`,
    /// an empty or non-finite kappa grid).
    #[error("invalid parameter {name} = {value}")]
    InvalidParameter {
        /// Which parameter.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// The initial estimate failed its check.
    #[error("invalid initial estimate: {0}")]
    Initial(#[source] LinalgError),
    /// A model failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// An iteration to a steady state did not converge (a Riccati recursion whose model is
    /// not detectable, or a tolerance out of reach).
    #[error("{what} did not converge in {iterations} iterations")]
    NotConvergent {
        /// Which computation.
        what: &'static str,
        /// Iterations run.
        iterations: usize,
    },
}

impl FilterError {
    /// Attaches the step index to a linear-algebra failure (an instruction set's error, which
    /// has no step, keeps its variant).
    pub(crate) fn at(step: usize, e: LinalgError) -> Self {
        match e {
            LinalgError::NonFinite { what } => FilterError::NonFinite { what, step },
            LinalgError::DimensionMismatch {
                what,
                expected,
                found,
            } => FilterError::DimensionMismatch {
                what,
                expected,
                found,
            },
            LinalgError::NotPositiveDefinite { what }
            | LinalgError::NotPositiveSemiDefinite { what, .. }
            | LinalgError::NotSymmetric { what, .. } => {
                FilterError::NotPositiveDefinite { what, step }
            }
            LinalgError::Unsupported { what } => FilterError::Unsupported { what },
            // LinalgError is non-exhaustive: report any future variant as a definiteness failure
            // of an unnamed matrix rather than panic.
            _ => FilterError::NotPositiveDefinite {
                what: "matrix",
                step,
            },
        }
    }
}
