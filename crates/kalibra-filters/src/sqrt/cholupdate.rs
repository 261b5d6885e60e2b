//! Rank-one update and downdate of a Cholesky factor (the square-root UKF's central point and
//! posterior).

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};

/// Replaces the lower-triangular `l` by the factor of `l l^T + sign x x^T` (`sign` is `1.0` for
/// an update, `-1.0` for a downdate), column by column: Givens rotations for an update,
/// hyperbolic ones for a downdate (LINPACK's `dchud`/`dchdd` in lower-triangular form). `x` is
/// consumed as work space.
///
/// An update never fails. A downdate fails, returning `false` with `l` partly changed (callers
/// work on a copy), when the result is not positive definite to working precision: a pivot
/// `l_kk^2 - x_k^2` that is not positive while `x_k` is not zero. A zero column of `l` met with
/// a zero `x_k` (a semi-definite factor) is left as it is.
#[must_use]
pub(crate) fn rank_one<N: Dim>(
    l: &mut OMatrix<f64, N, N>,
    x: &mut OVector<f64, N>,
    sign: f64,
) -> bool
where
    DefaultAllocator: Alloc<N>,
{
    let n = l.nrows();
    for k in 0..n {
        let (lkk, xk) = (l[(k, k)], x[k]);
        if xk == 0.0 {
            continue;
        }
        if sign > 0.0 {
            let r = lkk.hypot(xk);
            let (c, s) = (lkk / r, xk / r);
            l[(k, k)] = r;
            for i in k + 1..n {
                let (lik, xi) = (l[(i, k)], x[i]);
                l[(i, k)] = c * lik + s * xi;
                x[i] = c * xi - s * lik;
            }
        } else {
            let r2 = (lkk - xk) * (lkk + xk);
            if r2.is_nan() || r2 <= 0.0 {
                return false;
            }
            let r = r2.sqrt();
            let (c, s) = (r / lkk, xk / lkk);
            l[(k, k)] = r;
            for i in k + 1..n {
                let lik = (l[(i, k)] - s * x[i]) / c;
                l[(i, k)] = lik;
                x[i] = c * x[i] - s * lik;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::{Matrix3, Vector3};

    fn check(l0: Matrix3<f64>, x: Vector3<f64>, sign: f64) {
        let mut l = l0;
        assert!(rank_one(&mut l, &mut x.clone(), sign));
        let expected = l0 * l0.transpose() + x * x.transpose() * sign;
        assert!((l * l.transpose() - expected).amax() < 1e-13);
        assert!((0..3).all(|i| l[(i, i)] > 0.0));
    }

    #[test]
    fn update_and_downdate_reproduce_the_rank_one_change() {
        let l0 = Matrix3::new(2.0, 0.0, 0.0, 0.5, 1.5, 0.0, -0.3, 0.2, 1.0);
        check(l0, Vector3::new(0.7, -0.2, 0.4), 1.0);
        check(l0, Vector3::new(0.7, -0.2, 0.4), -1.0);
        // A factor with a zero column is updated through it.
        let semi = Matrix3::new(1.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.2, 0.0, 1.0);
        let mut l = semi;
        let x = Vector3::new(0.0, 1.0, 0.5);
        assert!(rank_one(&mut l, &mut x.clone(), 1.0));
        let expected = semi * semi.transpose() + x * x.transpose();
        assert!((l * l.transpose() - expected).amax() < 1e-14);
    }

    #[test]
    fn a_downdate_past_definiteness_fails() {
        let mut l = Matrix3::identity();
        assert!(!rank_one(&mut l, &mut Vector3::new(0.0, 1.5, 0.0), -1.0));
    }
}
