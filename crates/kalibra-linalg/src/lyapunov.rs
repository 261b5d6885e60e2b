//! The discrete Lyapunov equation `X = A X A^T + Q`.

use nalgebra::{DefaultAllocator, Dim, OMatrix};

use crate::{Alloc, LinalgError, check_dim, check_finite, check_symmetric, propagate, symmetrize};

/// Most doublings [`discrete_lyapunov`] runs: `2^64` terms of the series, far beyond any
/// spectral radius that is below 1 in floating point.
pub const LYAPUNOV_MAX_DOUBLINGS: usize = 64;

/// Solves the discrete Lyapunov equation `X = A X A^T + Q` for the stationary covariance of
/// `x_{k+1} = A x_k + w_k`, `w_k ~ N(0, Q)`.
///
/// # Method
/// Smith's doubling iteration: `X_0 = Q`, `A_0 = A`, `X_{j+1} = X_j + A_j X_j A_j^T`,
/// `A_{j+1} = A_j^2`, so `X_j` sums the first `2^j` terms of `sum_i A^i Q (A^i)^T`. It converges
/// quadratically when the spectral radius of `A` is below 1 and needs only products, no
/// eigen-decomposition, so it works for any `Dim`. It stops when an increment is below
/// `2^-52` of `X` in the Frobenius norm; each `X_j` is symmetrised.
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] if `A` and `Q` differ in size or are not square,
/// [`LinalgError::NonFinite`] for non-finite input, [`LinalgError::NotSymmetric`] for an
/// asymmetric `Q`, and [`LinalgError::NotConvergent`] when the series does not converge in
/// [`LYAPUNOV_MAX_DOUBLINGS`] doublings (a spectral radius of 1 or more on a direction `Q`
/// excites: the stationary covariance is unbounded).
///
/// ```
/// use kalibra_linalg::{discrete_lyapunov, Matrix1};
/// // Scalar AR(1): x' = a x + w, var(w) = q, stationary variance q / (1 - a^2).
/// let x = discrete_lyapunov(&Matrix1::new(0.9), &Matrix1::new(1.0))?;
/// assert!((x[(0, 0)] - 1.0 / (1.0 - 0.81)).abs() < 1e-12);
/// assert!(discrete_lyapunov(&Matrix1::new(1.0), &Matrix1::new(1.0)).is_err());
/// # Ok::<(), kalibra_linalg::LinalgError>(())
/// ```
pub fn discrete_lyapunov<N: Dim>(
    a: &OMatrix<f64, N, N>,
    q: &OMatrix<f64, N, N>,
) -> Result<OMatrix<f64, N, N>, LinalgError>
where
    DefaultAllocator: Alloc<N>,
{
    check_dim(a.nrows(), a.ncols(), "Lyapunov matrix A")?;
    check_dim(a.nrows(), q.nrows(), "Lyapunov noise Q")?;
    check_dim(a.nrows(), q.ncols(), "Lyapunov noise Q")?;
    check_finite(a, "Lyapunov matrix A")?;
    check_finite(q, "Lyapunov noise Q")?;
    check_symmetric(q, "Lyapunov noise Q")?;
    let mut x = q.clone();
    let mut power = a.clone();
    for _ in 0..LYAPUNOV_MAX_DOUBLINGS {
        let increment = propagate(&power, &x);
        let (inc, total) = (increment.norm(), x.norm());
        if !(inc.is_finite() && total.is_finite()) {
            break;
        }
        x += increment;
        symmetrize(&mut x);
        if inc <= f64::EPSILON * total {
            return Ok(x);
        }
        power = &power * &power;
    }
    Err(LinalgError::NotConvergent {
        what: "discrete Lyapunov doubling",
        iterations: LYAPUNOV_MAX_DOUBLINGS,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, Matrix2, Matrix3};

    #[test]
    fn solves_the_equation() {
        let a = Matrix3::new(0.5, 0.2, 0.0, -0.1, 0.7, 0.3, 0.05, 0.0, 0.9);
        let q = Matrix3::new(1.0, 0.2, 0.0, 0.2, 2.0, 0.1, 0.0, 0.1, 0.5);
        let x = discrete_lyapunov(&a, &q).unwrap();
        let residual = a * x * a.transpose() + q - x;
        assert!(residual.norm() < 1e-12 * x.norm());
        // Dyn sizes run the same code.
        let xd = discrete_lyapunov(
            &DMatrix::from_column_slice(3, 3, a.as_slice()),
            &DMatrix::from_column_slice(3, 3, q.as_slice()),
        )
        .unwrap();
        assert!((xd - DMatrix::from_column_slice(3, 3, x.as_slice())).norm() < 1e-14);
    }

    #[test]
    fn a_unit_root_not_excited_is_fine_and_an_excited_one_is_an_error() {
        let a = Matrix2::new(1.0, 0.0, 0.0, 0.5);
        let x = discrete_lyapunov(&a, &Matrix2::new(0.0, 0.0, 0.0, 1.0)).unwrap();
        assert!((x[(1, 1)] - 4.0 / 3.0).abs() < 1e-12);
        assert!(matches!(
            discrete_lyapunov(&a, &Matrix2::identity()),
            Err(LinalgError::NotConvergent { .. })
        ));
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let a = Matrix2::identity() * 0.5;
        assert!(discrete_lyapunov(&a, &Matrix2::new(1.0, 0.5, 0.0, 1.0)).is_err());
        assert!(discrete_lyapunov(&(a * f64::NAN), &Matrix2::identity()).is_err());
        assert!(
            discrete_lyapunov(&DMatrix::<f64>::identity(2, 2), &DMatrix::identity(3, 3)).is_err()
        );
    }
}
