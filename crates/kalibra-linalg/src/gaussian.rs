//! A mean and a covariance, the value a function returns when it returns a Gaussian.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::{Alloc, LinalgError, check_dim};

/// A Gaussian `N(mean, cov)` given by its mean and covariance, as plain data.
///
/// Functions that compute both a mean and a covariance (an initial estimate from the first
/// measurements, a moment match) return this type, so callers read `mean` and `cov` by name
/// instead of a positional tuple. It checks nothing: the covariance is whatever the function
/// computed and documents (symmetric, and positive semi-definite unless it says otherwise).
/// Check it once with [`Covariance::new`](crate::Covariance::new) or
/// [`PsdMatrix::new`](crate::PsdMatrix::new) where an invariant is needed.
///
/// The fields are named as in the filters' estimates (`mean`, `cov`), so an estimate and a
/// `Gaussian` read alike.
///
/// ```
/// use kalibra_linalg::{Gaussian, Matrix2, Vector2};
///
/// let g = Gaussian {
///     mean: Vector2::new(1.0, 2.0),
///     cov: Matrix2::new(4.0, 1.0, 1.0, 3.0),
/// };
/// // Destructure by name: the mean and the covariance cannot be mixed up.
/// let Gaussian { mean, cov } = g;
/// assert_eq!((mean[1], cov[(0, 1)]), (2.0, 1.0));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Gaussian<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The mean `x`.
    pub mean: OVector<f64, N>,
    /// The covariance `P`.
    pub cov: OMatrix<f64, N, N>,
}

impl<N: Dim> Gaussian<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The Gaussian with mean `mean` and covariance `cov`.
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if the covariance is not `n x n` for a mean of
    /// length `n` (possible with `Dyn` sizes only; `Const` sizes are checked by the compiler).
    pub fn new(mean: OVector<f64, N>, cov: OMatrix<f64, N, N>) -> Result<Self, LinalgError> {
        check_dim(mean.len(), cov.nrows(), "covariance rows")?;
        check_dim(mean.len(), cov.ncols(), "covariance columns")?;
        Ok(Self { mean, cov })
    }

    /// The dimension `n`.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix2, Vector2};

    #[test]
    fn new_keeps_both_parts_by_name() {
        let g = Gaussian::new(Vector2::new(1.0, -1.0), Matrix2::new(2.0, 0.5, 0.5, 1.0)).unwrap();
        assert_eq!(g.mean, Vector2::new(1.0, -1.0));
        assert_eq!(g.cov, Matrix2::new(2.0, 0.5, 0.5, 1.0));
        assert_eq!(g.dim(), 2);
    }

    #[test]
    fn new_rejects_mismatched_dynamic_sizes() {
        let err = Gaussian::new(DVector::zeros(2), DMatrix::zeros(3, 3)).unwrap_err();
        assert_eq!(
            err,
            LinalgError::DimensionMismatch {
                what: "covariance rows",
                expected: 2,
                found: 3
            }
        );
        assert!(Gaussian::new(DVector::zeros(2), DMatrix::zeros(2, 3)).is_err());
    }
}
