//! Singular values of the local observability matrix along a trajectory.

use kalibra_linalg::{Alloc, DMatrix, DefaultAllocator, Dim, OMatrix, check_finite};

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
/// # Errors
/// [`BoundsError::TooShort`] if the trajectory lacks steps `k .. k + depth - 1` (or
/// `depth == 0`); [`BoundsError::Linalg`] for non-finite Jacobians.
pub fn observability_singular_values<N: Dim, M: Dim>(
    f: &[OMatrix<f64, N, N>],
    h: &[OMatrix<f64, M, N>],
    k: usize,
    depth: usize,
) -> Result<Vec<f64>, BoundsError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let needed = k + depth;
    if depth == 0 || h.len() < needed || f.len() + 1 < needed {
        return Err(BoundsError::TooShort {
            what: "observability matrix",
            needed,
            got: h.len().min(f.len() + 1),
        });
    }
    let n = h[k].ncols();
    let m = h[k].nrows();
    let mut o = DMatrix::<f64>::zeros(depth * m, n);
    // Phi = F_{j-1} ... F_k, starting from the identity.
    let mut phi = DMatrix::<f64>::identity(n, n);
    for (i, j) in (k..needed).enumerate() {
        check_finite(&h[j], "measurement Jacobian H")?;
        let hj = DMatrix::from_column_slice(m, n, h[j].as_slice());
        o.view_mut((i * m, 0), (m, n)).copy_from(&(hj * &phi));
        if j + 1 < needed {
            check_finite(&f[j], "transition Jacobian F")?;
            phi = DMatrix::from_column_slice(n, n, f[j].as_slice()) * phi;
        }
    }
    let mut sv: Vec<f64> = o.singular_values().iter().copied().collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    Ok(sv)
}

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
        assert!(observability_singular_values(&f, &h, 0, 0).is_err());
    }
}
