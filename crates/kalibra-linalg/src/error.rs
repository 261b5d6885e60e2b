/// Why a linear-algebra operation on caller data failed.
///
/// Messages are lowercase fragments that read after "failed to ...: ".
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinalgError {
    /// A matrix that must be symmetric positive definite is not (its Cholesky factorisation
    /// met a non-positive pivot).
    #[error("{what} is not positive definite")]
    NotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
    },
    /// A matrix that must be symmetric positive semi-definite has a clearly negative pivot.
    #[error("{what} is not positive semi-definite (pivot {pivot:e} at index {index})")]
    NotPositiveSemiDefinite {
        /// Which matrix.
        what: &'static str,
        /// Index of the offending pivot.
        index: usize,
        /// Value of the offending pivot.
        pivot: f64,
    },
    /// A matrix that must be symmetric is not, beyond rounding.
    #[error("{what} is not symmetric (relative asymmetry {asymmetry:e})")]
    NotSymmetric {
        /// Which matrix.
        what: &'static str,
        /// Largest `|a_ij - a_ji| / sqrt(|a_ii a_jj|)` found.
        asymmetry: f64,
    },
    /// An input holds NaN or an infinity.
    #[error("{what} holds a non-finite value")]
    NonFinite {
        /// Which input.
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
    /// An iteration did not converge: the discrete Lyapunov equation of a matrix whose
    /// spectral radius is not below 1 has no bounded solution.
    #[error("{what} did not converge in {iterations} iterations")]
    NotConvergent {
        /// Which computation.
        what: &'static str,
        /// Iterations run.
        iterations: usize,
    },
    /// An instruction set this CPU does not run ([`Isa::checked`](crate::simd::Isa::checked)).
    #[error("{what} is not supported")]
    Unsupported {
        /// What was asked for.
        what: &'static str,
    },
    /// An instruction set name that [`Isa`](crate::simd::Isa)'s parser does not know.
    #[error("parse instruction set {name:?} (expected avx512, avx2, neon, scalar or auto)")]
    UnknownIsa {
        /// The text given.
        name: String,
    },
}
