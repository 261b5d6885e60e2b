use kalibra_linalg::LinalgError;

/// Why a metric could not be computed.
///
/// Messages are lowercase fragments that read after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MetricsError {
    /// A parameter is outside its valid range (a confidence level outside (0, 1), zero
    /// degrees of freedom).
    #[error("invalid parameter {name} = {value}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A step index beyond the accumulator's horizon.
    #[error("step {step} is beyond the horizon of {steps} steps")]
    StepOutOfRange {
        /// The step given.
        step: usize,
        /// The number of steps held.
        steps: usize,
    },
    /// Inputs of different sizes.
    #[error("{what} has dimension {found}, expected {expected}")]
    DimensionMismatch {
        /// Which input.
        what: &'static str,
        /// The size required.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// A covariance failed its check (not positive definite, not finite).
    #[error(transparent)]
    Linalg(#[from] LinalgError),
}
