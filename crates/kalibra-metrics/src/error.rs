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
    /// A matrix to be solved with is singular to working precision (for example `A_k + B_k`
    /// of an update whose prior covariance is indefinite and happens to be singular).
    #[error("{what} is singular to working precision")]
    Singular {
        /// Which matrix.
        what: &'static str,
    },
    /// A summary was asked of an accumulator that holds nothing.
    #[error("no {what} to summarise")]
    Empty {
        /// What is missing (for example `"filter updates"`).
        what: &'static str,
    },
    /// A horizon average was asked with a divisor below the number of updates pushed.
    #[error("divisor {divisor} is below the {updates} updates pushed")]
    DivisorBelowUpdates {
        /// The divisor given.
        divisor: usize,
        /// The number of updates pushed.
        updates: usize,
    },
    /// A point of a parameter sweep cannot be used (non-finite, or out of sweep order).
    #[error("sweep point {index} {reason}")]
    InvalidSweep {
        /// Index of the offending point.
        index: usize,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A hypothesis test or a batch-means summary got fewer samples than it is defined for.
    #[error("{what}: needs at least {needed} samples, got {got}")]
    TooFewSamples {
        /// What was computed.
        what: &'static str,
        /// Samples needed.
        needed: usize,
        /// Samples given.
        got: usize,
    },
    /// A NaN or an infinity in a sample series given to a hypothesis test; a statistic of it
    /// would be meaningless. (Vector and matrix inputs of the other metrics report through
    /// [`MetricsError::Linalg`]; a series has a position worth reporting.)
    #[error("{what}: sample {index} is not finite")]
    NonFiniteSample {
        /// What was computed.
        what: &'static str,
        /// Index of the first offending sample.
        index: usize,
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
    /// A covariance failed its check (not positive definite, not finite).
    #[error(transparent)]
    Linalg(#[from] LinalgError),
}
