//! Square roots of symmetric positive semi-definite matrices.

use nalgebra::{DefaultAllocator, Dim, OMatrix};

use crate::{Alloc, LinalgError, check_finite};

/// Pivot tolerance of [`semidefinite_factor`], relative to the largest diagonal entry and the
/// dimension: elimination stops when every remaining pivot is at most
/// `PIVOT_TOLERANCE * n * max_i a_ii` (LAPACK's `pstrf` uses `n eps max a_ii`; this is a few
/// hundred times looser so that rounding left by products such as `G G^T` is always absorbed).
/// Variances that small beside the largest one are treated as zero.
pub const PIVOT_TOLERANCE: f64 = 1e-13;

/// A square root `L` with `L L^T = A` for a symmetric positive semi-definite `A`, and the
/// numerical rank of `A`.
///
/// Cholesky elimination with diagonal pivoting (the largest remaining pivot first, as LAPACK's
/// `pstrf`), stopped when every remaining pivot is below the tolerance
/// ([`PIVOT_TOLERANCE`]): the rank-deficient directions get zero columns. Pivoting bounds the
/// growth of rounding, so rank-deficient matrices such as `Q = G G^T` factor reliably; without
/// it, a nearly collinear `G` leaves pivots of the wrong sign. The rows of `L` are returned in the
/// original order, so `L` is lower triangular only up to that permutation (for a positive
/// definite `A` with no pivoting needed, it is the Cholesky factor). What remains after the
/// stop must be negligible: a clearly negative pivot, or a remaining off-diagonal entry beyond
/// the tolerance, means `A` is indefinite.
///
/// ```
/// use kalibra_linalg::{semidefinite_factor, Matrix2};
/// // Rank one: [1 1; 1 1] = [1 0; 1 0] [1 0; 1 0]^T.
/// let (l, rank) = semidefinite_factor(&Matrix2::new(1.0, 1.0, 1.0, 1.0), "Q")?;
/// assert_eq!(rank, 1);
/// assert!((l * l.transpose() - Matrix2::new(1.0, 1.0, 1.0, 1.0)).norm() < 1e-15);
/// # Ok::<(), kalibra_linalg::LinalgError>(())
/// ```
///
/// # Errors
/// [`LinalgError::NotPositiveSemiDefinite`] for an indefinite `a`, [`LinalgError::NonFinite`]
/// for NaN or infinite entries, [`LinalgError::DimensionMismatch`] if `a` is not square.
pub fn semidefinite_factor<D: Dim>(
    a: &OMatrix<f64, D, D>,
    what: &'static str,
) -> Result<(OMatrix<f64, D, D>, usize), LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    let n = a.nrows();
    crate::check_dim(n, a.ncols(), what)?;
    check_finite(a, what)?;
    let (nr, nc) = a.shape_generic();
    // Work in permuted coordinates: row i of `l` and `w` belongs to original index perm[i].
    let mut w = a.clone();
    let mut l = OMatrix::<f64, D, D>::zeros_generic(nr, nc);
    let mut perm: Vec<usize> = (0..n).collect();
    let max_diag = (0..n).map(|i| a[(i, i)]).fold(0.0f64, f64::max);
    let tol = PIVOT_TOLERANCE * n as f64 * max_diag;
    // d[i]: diagonal of the current Schur complement.
    let mut d: Vec<f64> = (0..n).map(|i| a[(i, i)]).collect();
    let mut rank = n;
    for j in 0..n {
        let (p, &dp) =
            d.iter().enumerate().skip(j).fold(
                (j, &d[j]),
                |best, (i, v)| if *v > *best.1 { (i, v) } else { best },
            );
        if dp <= tol {
            rank = j;
            break;
        }
        if p != j {
            d.swap(p, j);
            perm.swap(p, j);
            w.swap_rows(p, j);
            w.swap_columns(p, j);
            l.swap_rows(p, j);
        }
        let ljj = dp.sqrt();
        l[(j, j)] = ljj;
        for i in (j + 1)..n {
            let mut s = w[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            let lij = s / ljj;
            l[(i, j)] = lij;
            d[i] -= lij * lij;
        }
    }
    // What the elimination left must be negligible: for PSD remainders |S_ij| <= sqrt(S_ii S_jj).
    for j in rank..n {
        for i in j..n {
            let mut s = w[(i, j)];
            for k in 0..rank {
                s -= l[(i, k)] * l[(j, k)];
            }
            if s.is_nan() || s.abs() > 100.0 * tol.max(f64::MIN_POSITIVE) {
                return Err(LinalgError::NotPositiveSemiDefinite {
                    what,
                    index: perm[j],
                    pivot: s,
                });
            }
        }
    }
    // A semi-definite matrix's factor is bounded by the root of its largest diagonal entry;
    // an entry that overflowed (off-diagonal 1e257 beside a diagonal of 1e-103) means it is
    // not semi-definite (`tests/extreme_floats.rs`).
    if let Some(k) = l.iter().position(|v| !v.is_finite()) {
        return Err(LinalgError::NotPositiveSemiDefinite {
            what,
            index: perm[k % n.max(1)],
            pivot: f64::NAN,
        });
    }
    // Back to the original row order.
    let mut out = OMatrix::<f64, D, D>::zeros_generic(nr, nc);
    for (i, &orig) in perm.iter().enumerate() {
        out.set_row(orig, &l.row(i));
    }
    Ok((out, rank))
}

/// How [`sigma_sqrt`] obtained its factor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SqrtMethod {
    /// The standard Cholesky factorisation succeeded: the matrix is positive definite.
    Cholesky,
    /// Cholesky failed and the semi-definite factorisation ([`semidefinite_factor`]) was used:
    /// the matrix is singular to working precision; the factor has zero columns where the
    /// matrix has no variance.
    SemiDefinite,
}

/// A matrix square root `L` (lower triangular, `L L^T = P`) for generating sigma points.
///
/// Tries the standard Cholesky factorisation first. When it fails, which happens for a
/// covariance that is singular to working precision (a state with no uncertainty left, a
/// rank-deficient initial covariance), it falls back to [`semidefinite_factor`], which zeroes the
/// columns of directions without variance: the sigma points then collapse onto the mean along
/// those directions, which is the correct limit. A clearly indefinite `P` is an error, never
/// silently repaired.
///
/// # Errors
/// As [`semidefinite_factor`].
pub fn sigma_sqrt<D: Dim>(
    p: &OMatrix<f64, D, D>,
    what: &'static str,
) -> Result<(OMatrix<f64, D, D>, SqrtMethod), LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    if let Some(chol) = crate::covariance::cholesky(p.clone()) {
        let l = chol.unpack();
        // `all_finite` folds over the raw slice (about one instruction per entry, against
        // seven for nalgebra's element iterator): this runs at every UKF step.
        if crate::all_finite(&l) {
            return Ok((l, SqrtMethod::Cholesky));
        }
    }
    let (l, _) = semidefinite_factor(p, what)?;
    Ok((l, SqrtMethod::SemiDefinite))
}

/// A symmetric positive semi-definite matrix with a square-root factor: the type for noise
/// covariances, which are often rank-deficient (`Q = G G^T`), and for sampling.
///
/// Checked once at construction: finite, symmetric to
/// [`SYMMETRY_TOLERANCE`](crate::SYMMETRY_TOLERANCE) (then made exactly symmetric), and
/// factorable by [`semidefinite_factor`].
#[derive(Clone, Debug)]
pub struct PsdMatrix<D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    matrix: OMatrix<f64, D, D>,
    factor: OMatrix<f64, D, D>,
    rank: usize,
}

impl<D: Dim> PsdMatrix<D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Checks and factorises `matrix`.
    ///
    /// # Errors
    /// [`LinalgError::NonFinite`], [`LinalgError::NotSymmetric`],
    /// [`LinalgError::NotPositiveSemiDefinite`] or [`LinalgError::DimensionMismatch`].
    pub fn new(matrix: OMatrix<f64, D, D>) -> Result<Self, LinalgError> {
        Self::named(matrix, "noise covariance")
    }

    /// As [`PsdMatrix::new`], with the name the errors report.
    ///
    /// # Errors
    /// As [`PsdMatrix::new`].
    pub fn named(mut matrix: OMatrix<f64, D, D>, what: &'static str) -> Result<Self, LinalgError> {
        crate::check_symmetric(&matrix, what)?;
        crate::symmetrize(&mut matrix);
        let (factor, rank) = semidefinite_factor(&matrix, what)?;
        Ok(Self {
            matrix,
            factor,
            rank,
        })
    }

    /// The matrix.
    pub fn matrix(&self) -> &OMatrix<f64, D, D> {
        &self.matrix
    }

    /// The lower-triangular factor `L`, `L L^T = A`.
    pub fn factor(&self) -> &OMatrix<f64, D, D> {
        &self.factor
    }

    /// Numerical rank (non-zero columns of the factor).
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Dimension of the (square) matrix.
    pub fn dim(&self) -> usize {
        self.matrix.nrows()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Matrix2, Matrix4, SMatrix, Vector4};
    use approx::assert_relative_eq;

    #[test]
    fn factors_a_rank_deficient_white_noise_acceleration_q() {
        let t = 1.0;
        let g = SMatrix::<f64, 4, 2>::new(t * t / 2.0, 0.0, 0.0, t * t / 2.0, t, 0.0, 0.0, t);
        let q = g * g.transpose();
        let psd = PsdMatrix::new(q).unwrap();
        assert_eq!(psd.rank(), 2);
        assert_relative_eq!(psd.factor() * psd.factor().transpose(), q, epsilon = 1e-14);
    }

    #[test]
    fn matches_cholesky_on_definite_input() {
        let p = Matrix4::from_diagonal(&Vector4::new(4.0, 3.0, 2.0, 1.0)) + Matrix4::repeat(0.1);
        let (l, rank) = semidefinite_factor(&p, "P").unwrap();
        assert_eq!(rank, 4);
        // Diagonal already in decreasing order: no pivoting, so it is the Cholesky factor.
        assert_relative_eq!(
            l,
            nalgebra::linalg::Cholesky::new(p).unwrap().l(),
            epsilon = 1e-14
        );
        assert_eq!(sigma_sqrt(&p, "P").unwrap().1, SqrtMethod::Cholesky);
    }

    #[test]
    fn falls_back_on_singular_and_rejects_indefinite() {
        let singular = Matrix2::new(1.0, 1.0, 1.0, 1.0);
        let (l, how) = sigma_sqrt(&singular, "P").unwrap();
        assert_eq!(how, SqrtMethod::SemiDefinite);
        assert_relative_eq!(l * l.transpose(), singular, epsilon = 1e-15);
        let indefinite = Matrix2::new(0.0, 1.0, 1.0, 0.0);
        assert!(matches!(
            sigma_sqrt(&indefinite, "P"),
            Err(LinalgError::NotPositiveSemiDefinite { .. })
        ));
        let negative = Matrix2::new(1.0, 0.0, 0.0, -1.0);
        assert!(matches!(
            PsdMatrix::new(negative),
            Err(LinalgError::NotPositiveSemiDefinite { .. })
        ));
        assert_eq!(PsdMatrix::new(Matrix2::zeros()).unwrap().rank(), 0);
    }
}
