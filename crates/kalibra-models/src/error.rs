use kalibra_linalg::LinalgError;

/// Why a model could not be built or evaluated.
///
/// Messages are lowercase fragments that read after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A parameter is outside its valid range.
    #[error("invalid parameter {name} = {value}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A dimension does not fit the model (an odd state length for a constant-velocity model,
    /// an index beyond the state).
    #[error("{what} has dimension {found}, expected {expected}")]
    DimensionMismatch {
        /// Which input.
        what: &'static str,
        /// The size required.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// A simulated state or measurement became NaN or infinite.
    #[error("{what} became non-finite at step {step}")]
    NonFinite {
        /// Which quantity.
        what: &'static str,
        /// The step index.
        step: usize,
    },
    /// A matrix given to the model failed its check.
    #[error(transparent)]
    Linalg(#[from] LinalgError),
}
