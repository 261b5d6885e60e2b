//! Singular values of the local observability matrix along a trajectory.

use kalibra_linalg::{
    Alloc, DMatrix, DefaultAllocator, Dim, LinalgError, OMatrix, binary_exponent, check_dim,
    check_finite, ldexp,
};

use crate::BoundsError;

/// The singular values, largest first, of `O_k = [H_k; H_{k+1} F_k; ...;
/// H_{k+d-1} F_{k+d-2} ... F_k]` (`d = depth` blocks), where `f[j]` is the transition Jacobian
/// from step `j` to `j + 1` and `h[j]` the measurement Jacobian at step `j`, both at the true
/// state. Saha, Ghosh and Goswami (2014, Fig. 3) plot such values without defining the
/// matrix; this is the usual local (`depth = n`) observability matrix of the linearised system.
///
/// ```
/// use kalibra_bounds::observability_singular_values;
/// use kalibra_linalg::{Matrix2, SMatrix};
/// let f = vec![Matrix2::new(1.0, 1.0, 0.0, 1.0); 3];
/// let h = vec![SMatrix::<f64, 1, 2>::new(1.0, 0.0); 3];
/// let sv = observability_singular_values(&f, &h, 0, 2)?;
/// assert_eq!(sv.len(), 2);
/// assert!(sv[1] > 0.0); // position measurements of a constant-velocity target: observable
/// # Ok::<(), kalibra_bounds::BoundsError>(())
/// ```
///
/// # Numerical choices
/// The stacked matrix is scaled by the power of two that brings its largest entry into
/// `[1, 2)` before the SVD (nalgebra's, at most [`OBSERVABILITY_SVD_MAX_ITERATIONS`]
/// iterations) and the singular values scaled back, so Jacobians from subnormal to 1e308
/// scales give their singular values.
///
/// # Errors
/// [`BoundsError::TooShort`] if the trajectory lacks steps `k .. k + depth - 1` (or
/// `depth == 0`); [`BoundsError::Linalg`] for non-finite Jacobians, Jacobians whose sizes
/// differ from `h[k]`'s (`Dyn`: a `DimensionMismatch` naming both sizes, before a panic
/// inside nalgebra), a product of Jacobians or a singular value beyond f64's range, or an SVD
/// that does not converge.
pub fn observability_singular_values<N: Dim, M: Dim>(
    f: &[OMatrix<f64, N, N>],
    h: &[OMatrix<f64, M, N>],
    k: usize,
    depth: usize,
) -> Result<Vec<f64>, BoundsError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let got = h.len().min(f.len().saturating_add(1));
    let too_short = |needed| BoundsError::TooShort {
        what: "observability matrix",
        needed,
        got,
    };
    let needed = k.checked_add(depth).ok_or(too_short(usize::MAX))?;
    if depth == 0 || h.len() < needed || f.len() + 1 < needed {
        return Err(too_short(needed));
    }
    let n = h[k].ncols();
    let m = h[k].nrows();
    let rows = depth.checked_mul(m).ok_or(BoundsError::InvalidParameter {
        what: "observability matrix",
        reason: "depth times the measurement dimension overflows usize",
    })?;
    let mut o = DMatrix::<f64>::zeros(rows, n);
    // Phi = F_{j-1} ... F_k, starting from the identity.
    let mut phi = DMatrix::<f64>::identity(n, n);
    for (i, j) in (k..needed).enumerate() {
        check_dim(m, h[j].nrows(), "measurement Jacobian H rows")?;
        check_dim(n, h[j].ncols(), "measurement Jacobian H columns")?;
        check_finite(&h[j], "measurement Jacobian H")?;
        let hj = DMatrix::from_column_slice(m, n, h[j].as_slice());
        o.view_mut((i * m, 0), (m, n)).copy_from(&(hj * &phi));
        if j + 1 < needed {
            check_dim(n, f[j].nrows(), "transition Jacobian F rows")?;
            check_dim(n, f[j].ncols(), "transition Jacobian F columns")?;
            check_finite(&f[j], "transition Jacobian F")?;
            phi = DMatrix::from_column_slice(n, n, f[j].as_slice()) * phi;
        }
    }
    // A product beyond f64's range would reach the SVD as inf or NaN, where nalgebra's
    // iteration need not end.
    check_finite(&o, "product of Jacobians in the observability matrix")?;
    let Some(exponent) = binary_exponent(o.amax()) else {
        return Ok(vec![0.0; n.min(rows)]);
    };
    let o = o.map(|v| ldexp(v, -exponent));
    let svd = o
        .try_svd(false, false, f64::EPSILON, OBSERVABILITY_SVD_MAX_ITERATIONS)
        .ok_or(LinalgError::NotConvergent {
            what: "SVD of the observability matrix",
            iterations: OBSERVABILITY_SVD_MAX_ITERATIONS,
        })?;
    let mut sv: Vec<f64> = svd
        .singular_values
        .iter()
        .map(|&s| ldexp(s, exponent))
        .collect();
    if !sv.iter().all(|s| s.is_finite()) {
        return Err(LinalgError::NonFinite {
            what: "singular value (beyond f64's range)",
        }
        .into());
    }
    sv.sort_by(|a, b| b.total_cmp(a));
    Ok(sv)
}

/// Most iterations of the SVD in [`observability_singular_values`] (nalgebra's default is
/// unbounded): far more than a matrix of finite, scaled entries needs.
pub const OBSERVABILITY_SVD_MAX_ITERATIONS: usize = 10_000;

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::{Matrix2, SMatrix};

    #[test]
    fn velocity_only_measurements_leave_position_unobservable() {
        let f = vec![Matrix2::new(1.0, 1.0, 0.0, 1.0); 4];
        let h = vec![SMatrix::<f64, 1, 2>::new(0.0, 1.0); 4];
        let sv = observability_singular_values(&f, &h, 1, 2).unwrap();
        assert!(sv[0] > 1.0);
        assert!(sv[1].abs() < 1e-12, "{sv:?}");
    }

    #[test]
    fn matches_a_hand_built_matrix() {
        let f = vec![
            Matrix2::new(1.0, 2.0, 0.0, 1.0),
            Matrix2::new(0.5, 0.0, 1.0, 1.0),
        ];
        let h = vec![SMatrix::<f64, 1, 2>::new(1.0, 1.0); 3];
        let sv = observability_singular_values(&f, &h, 0, 3).unwrap();
        let rows = [h[0], h[1] * f[0], h[2] * f[1] * f[0]];
        let o = DMatrix::from_fn(3, 2, |i, j| rows[i][(0, j)]);
        let mut expect: Vec<f64> = o.singular_values().iter().copied().collect();
        expect.sort_by(|a, b| b.total_cmp(a));
        assert_eq!(sv, expect);
        assert!(observability_singular_values(&f, &h, 1, 3).is_err());
        assert!(observability_singular_values(&f, &h, usize::MAX, 3).is_err());
        assert!(observability_singular_values(&f, &h, 1, usize::MAX).is_err());
        assert!(observability_singular_values(&f, &h, 0, 0).is_err());
    }

    /// Jacobians whose `Dyn` sizes disagree were a panic inside nalgebra.
    #[test]
    fn dyn_sizes_are_checked() {
        let f = vec![DMatrix::<f64>::identity(2, 2); 3];
        let h = vec![DMatrix::<f64>::identity(1, 2); 3];
        assert!(observability_singular_values(&f, &h, 0, 3).is_ok());
        let mut wide_h = h.clone();
        wide_h[1] = DMatrix::identity(1, 3);
        let mut tall_f = f.clone();
        tall_f[1] = DMatrix::identity(3, 2);
        for (f, h) in [(&f, &wide_h), (&tall_f, &h)] {
            assert!(matches!(
                observability_singular_values(f, h, 0, 3),
                Err(BoundsError::Linalg(LinalgError::DimensionMismatch {
                    expected: 2,
                    found: 3,
                    ..
                }))
            ));
        }
    }

    /// Jacobians at the ends of f64's range give their singular values, scaled; a product
    /// beyond it is an error, not a hang or NaN inside `Ok`.
    #[test]
    fn extreme_scales() {
        let f = vec![Matrix2::new(1.0, 1.0, 0.0, 1.0); 2];
        let h = vec![SMatrix::<f64, 1, 2>::new(1.0, 0.0); 2];
        let base = observability_singular_values(&f, &h, 0, 2).unwrap();
        for p in [-1060, -1000, 1000, 1020] {
            let hp: Vec<_> = h.iter().map(|m| m.map(|v| ldexp(v, p))).collect();
            let sv = observability_singular_values(&f, &hp, 0, 2).unwrap();
            for (a, b) in sv.iter().zip(&base) {
                assert!((a / ldexp(*b, p) - 1.0).abs() < 1e-12, "2^{p}: {sv:?}");
            }
        }
        let huge = vec![Matrix2::new(1e200, 0.0, 0.0, 1e200); 2];
        assert!(observability_singular_values(&huge, &h, 0, 2).is_ok());
        let h3 = vec![SMatrix::<f64, 1, 2>::new(1.0, 0.0); 3];
        assert!(matches!(
            observability_singular_values(&huge, &h3, 0, 3),
            Err(BoundsError::Linalg(LinalgError::NonFinite { .. }))
        ));
        let zero = vec![SMatrix::<f64, 1, 2>::zeros(); 2];
        assert_eq!(
            observability_singular_values(&f, &zero, 0, 2).unwrap(),
            vec![0.0, 0.0]
        );
    }
}
