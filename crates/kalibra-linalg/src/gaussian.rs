//! A mean and a covariance, the value a function returns when it returns a Gaussian.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

use crate::Alloc;

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
    /// # Panics
    /// If the dimensions disagree (`Dyn` sizes only; `Const` sizes are checked by the
    /// compiler): a programmer's mistake, not a property of data.
    pub fn new(mean: OVector<f64, N>, cov: OMatrix<f64, N, N>) -> Self {
        assert_eq!(
            (cov.nrows(), cov.ncols()),
            (mean.len(), mean.len()),
            "Gaussian::new: the covariance must be n x n for a mean of length n"
        );
        Self { mean, cov }
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
        let g = Gaussian::new(Vector2::new(1.0, -1.0), Matrix2::new(2.0, 0.5, 0.5, 1.0));
        assert_eq!(g.mean, Vector2::new(1.0, -1.0));
        assert_eq!(g.cov, Matrix2::new(2.0, 0.5, 0.5, 1.0));
        assert_eq!(g.dim(), 2);
    }

    #[test]
    #[should_panic(expected = "must be n x n")]
    fn new_rejects_mismatched_dynamic_sizes() {
        let _ = Gaussian::new(DVector::zeros(2), DMatrix::zeros(3, 3));
    }
}
