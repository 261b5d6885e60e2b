use nalgebra::linalg::Cholesky;
use nalgebra::storage::IsContiguous;
use nalgebra::{DefaultAllocator, Dim, Matrix, OMatrix, OVector, Storage, U1};

use crate::{Alloc, LinalgError, backend, check_finite};

/// The Cholesky factorisation of `m` (its lower triangle), by nalgebra or, for large `Dyn`
/// sizes, by faer ([`crate::backend`]); `None` for a non-positive or NaN pivot.
#[inline(always)]
pub(crate) fn cholesky<D: Dim>(m: OMatrix<f64, D, D>) -> Option<Cholesky<f64, D>>
where
    DefaultAllocator: Alloc<D>,
{
    let d = m.shape_generic().0;
    match backend::route(d, d) {
        Some(par) => backend::cholesky(m, par),
        None => Cholesky::new(m),
    }
}

/// Largest relative asymmetry `|a_ij - a_ji| / sqrt(|a_ii a_jj|)` accepted from a matrix that
/// is meant to be symmetric. Products such as `F P F^T` leave asymmetry of a few ulps; anything
/// near this bound is a bug in the caller, not rounding.
pub const SYMMETRY_TOLERANCE: f64 = 1e-8;

/// A symmetric positive definite matrix with its Cholesky factor.
///
/// The invariant is checked once, at construction: the matrix is finite, symmetric to
/// [`SYMMETRY_TOLERANCE`] (then made exactly symmetric), and its Cholesky factorisation
/// succeeds. Afterwards every solve, quadratic form and log-determinant reuses the factor.
///
/// ```
/// use kalibra_linalg::{Covariance, LinalgError, Matrix2};
///
/// let ok = Covariance::new(Matrix2::new(2.0, 0.5, 0.5, 1.0))?;
/// assert!((ok.log_det() - (2.0f64 * 1.0 - 0.25).ln()).abs() < 1e-14);
///
/// let indefinite = Covariance::new(Matrix2::new(1.0, 2.0, 2.0, 1.0));
/// assert!(matches!(indefinite, Err(LinalgError::NotPositiveDefinite { .. })));
/// # Ok::<(), LinalgError>(())
/// ```
#[derive(Clone, Debug)]
pub struct Covariance<D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    matrix: OMatrix<f64, D, D>,
    chol: Cholesky<f64, D>,
}

impl<D: Dim> Covariance<D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Checks `matrix` and factorises it.
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if it is not square, [`LinalgError::NonFinite`] if it
    /// holds NaN or an infinity, [`LinalgError::NotSymmetric`] beyond [`SYMMETRY_TOLERANCE`],
    /// [`LinalgError::NotPositiveDefinite`] if the Cholesky factorisation fails.
    pub fn new(matrix: OMatrix<f64, D, D>) -> Result<Self, LinalgError> {
        Self::named(matrix, "covariance")
    }

    /// As [`Covariance::new`], with the name the errors report (for example `"innovation
    /// covariance S"`).
    ///
    /// # Errors
    /// As [`Covariance::new`].
    pub fn named(mut matrix: OMatrix<f64, D, D>, what: &'static str) -> Result<Self, LinalgError> {
        check_symmetric(&matrix, what)?;
        crate::symmetrize(&mut matrix);
        Self::from_symmetric(matrix, what)
    }

    /// Factorises a matrix the caller guarantees to be finite and exactly symmetric (the
    /// filters' own products after [`symmetrize`](crate::symmetrize)); only positive
    /// definiteness is checked.
    ///
    /// # Errors
    /// [`LinalgError::NotPositiveDefinite`] if the Cholesky factorisation fails, which includes
    /// NaN entries.
    #[inline(always)]
    pub fn from_symmetric(
        matrix: OMatrix<f64, D, D>,
        what: &'static str,
    ) -> Result<Self, LinalgError> {
        match cholesky(matrix.clone()) {
            // A NaN pivot passes nalgebra's `> 0` test only as false, so NaN input lands in
            // the error branch; the finite check on the factor's diagonal catches overflow.
            Some(chol) if chol.l_dirty().diagonal().iter().all(|d| d.is_finite()) => {
                Ok(Self { matrix, chol })
            }
            _ => Err(LinalgError::NotPositiveDefinite { what }),
        }
    }

    /// A diagonal covariance from its (positive, finite) variances.
    ///
    /// # Errors
    /// [`LinalgError::NonFinite`] or [`LinalgError::NotPositiveDefinite`] for a bad variance.
    pub fn from_diagonal(variances: &OVector<f64, D>) -> Result<Self, LinalgError> {
        Self::named(OMatrix::from_diagonal(variances), "diagonal covariance")
    }

    /// The matrix.
    pub fn matrix(&self) -> &OMatrix<f64, D, D> {
        &self.matrix
    }

    /// The Cholesky decomposition `L L^T` of the matrix.
    pub fn cholesky(&self) -> &Cholesky<f64, D> {
        &self.chol
    }

    /// The lower-triangular factor `L` (a fresh matrix with zeros above the diagonal).
    pub fn factor(&self) -> OMatrix<f64, D, D> {
        self.chol.l()
    }

    /// Dimension of the (square) matrix.
    pub fn dim(&self) -> usize {
        self.matrix.nrows()
    }

    /// Consumes the value, returning the matrix.
    pub fn into_matrix(self) -> OMatrix<f64, D, D> {
        self.matrix
    }

    /// Solves `C x = b` for `x` with the stored factor.
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if `b` has the wrong number of rows (possible only with
    /// `Dyn` dimensions); [`LinalgError::NonFinite`] naming `"right-hand side"` for a non-finite
    /// `b`, and `"solution"` for a solution beyond f64's range.
    pub fn solve<C: Dim, S>(
        &self,
        b: &Matrix<f64, D, C, S>,
    ) -> Result<OMatrix<f64, D, C>, LinalgError>
    where
        S: Storage<f64, D, C>,
        DefaultAllocator: nalgebra::allocator::Allocator<D, C>,
    {
        crate::check_dim(self.dim(), b.nrows(), "right-hand side")?;
        let x = if let Some(par) = backend::route(b.shape_generic().0, b.shape_generic().1) {
            let mut x = b.clone_owned();
            backend::cholesky_solve_in_place(self.chol.l_dirty(), &mut x, par);
            x
        } else {
            self.chol.solve(b)
        };
        finite_solution(x, b.iter().all(|v| v.is_finite()))
    }

    /// Solves `x C = b` for `x`, that is `b C^-1`, with the stored factor: the Kalman gain
    /// `K = P H^T S^-1` is `s.solve_right(&pht)`.
    ///
    /// ```
    /// use kalibra_linalg::{Covariance, Matrix2, SMatrix};
    /// let s = Covariance::new(Matrix2::new(2.0, 0.0, 0.0, 4.0))?;
    /// let k = s.solve_right(&SMatrix::<f64, 1, 2>::new(1.0, 1.0))?;
    /// assert!((k - SMatrix::<f64, 1, 2>::new(0.5, 0.25)).norm() < 1e-15);
    /// # Ok::<(), kalibra_linalg::LinalgError>(())
    /// ```
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if `b` has the wrong number of columns (possible only
    /// with `Dyn` dimensions); [`LinalgError::NonFinite`] as [`Covariance::solve`].
    pub fn solve_right<R: Dim>(
        &self,
        b: &OMatrix<f64, R, D>,
    ) -> Result<OMatrix<f64, R, D>, LinalgError>
    where
        DefaultAllocator:
            nalgebra::allocator::Allocator<R, D> + nalgebra::allocator::Allocator<D, R>,
    {
        crate::check_dim(self.dim(), b.ncols(), "right-hand side columns")?;
        let x = crate::cholesky_solve_right(&self.chol, b);
        finite_solution(x, crate::all_finite(b))
    }

    /// The quadratic form `v^T C^-1 v`, computed as `|L^-1 v|^2` (one triangular solve).
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if `v` has the wrong length (possible only with `Dyn`
    /// dimensions); [`LinalgError::NonFinite`] naming `"vector"` if `v` holds NaN or an
    /// infinity, and naming `"quadratic form"` if the form of a finite `v` lies beyond f64's
    /// range, so that no `Ok` holds a NaN or an infinity (`tests/it/extreme_floats.rs`).
    pub fn quad_form<S>(&self, v: &Matrix<f64, D, U1, S>) -> Result<f64, LinalgError>
    where
        S: Storage<f64, D, U1>,
    {
        crate::check_dim(self.dim(), v.nrows(), "vector")?;
        let mut w = v.clone_owned();
        // The factor is non-singular by construction, so the solve cannot fail. nalgebra's
        // at every size: an O(n^2) solve gains nothing from faer, and routing it lengthens
        // the small step (`cargo xtask bench w4 --kernels`).
        self.chol
            .l_dirty()
            .solve_lower_triangular_unchecked_mut(&mut w);
        let q = w.norm_squared();
        if q.is_finite() {
            return Ok(q);
        }
        // A non-finite input always reaches the result: look for the culprit only then.
        Err(LinalgError::NonFinite {
            what: if v.iter().all(|x| x.is_finite()) {
                "quadratic form"
            } else {
                "vector"
            },
        })
    }

    /// `ln det C`, from the factor's diagonal.
    pub fn log_det(&self) -> f64 {
        self.chol.ln_determinant()
    }

    /// `tr(C^-1 B)` for a square `B` of the same size, by a solve.
    ///
    /// # Errors
    /// [`LinalgError::DimensionMismatch`] if `b` has the wrong size; [`LinalgError::NonFinite`]
    /// for a non-finite `b` or a trace beyond f64's range.
    pub fn trace_solve(&self, b: &OMatrix<f64, D, D>) -> Result<f64, LinalgError> {
        crate::check_dim(self.dim(), b.ncols(), "matrix")?;
        let t = self.solve(b)?.trace();
        if t.is_finite() {
            Ok(t)
        } else {
            Err(LinalgError::NonFinite { what: "trace" })
        }
    }

    /// The explicit inverse. Prefer [`Covariance::solve`]; this exists for reporting.
    pub fn inverse(&self) -> OMatrix<f64, D, D> {
        self.chol.inverse()
    }
}

/// `Ok(x)` if the solution `x` is finite; otherwise the error names the right-hand side when
/// it was not finite, or the solution (beyond f64's range).
fn finite_solution<R: Dim, C: Dim>(
    x: OMatrix<f64, R, C>,
    rhs_finite: bool,
) -> Result<OMatrix<f64, R, C>, LinalgError>
where
    DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
{
    if crate::all_finite(&x) {
        Ok(x)
    } else if rhs_finite {
        Err(LinalgError::NonFinite { what: "solution" })
    } else {
        Err(LinalgError::NonFinite {
            what: "right-hand side",
        })
    }
}

/// `v^T C^-1 v` for a covariance used once: the checks of [`Covariance::new`] (square,
/// finite, symmetric to [`SYMMETRY_TOLERANCE`], positive definite) without keeping the matrix
/// and its factor. The factorisation reads the lower triangle.
///
/// ```
/// use kalibra_linalg::{quad_form_once, Matrix2, Vector2};
/// let q = quad_form_once(&Matrix2::new(4.0, 0.0, 0.0, 1.0), &Vector2::new(2.0, 1.0), "P")?;
/// assert!((q - 2.0).abs() < 1e-15);
/// # Ok::<(), kalibra_linalg::LinalgError>(())
/// ```
///
/// # Errors
/// As [`Covariance::new`], and [`LinalgError::DimensionMismatch`] or
/// [`LinalgError::NonFinite`] for the vector.
pub fn quad_form_once<D: Dim, S: Storage<f64, D> + IsContiguous>(
    cov: &OMatrix<f64, D, D>,
    v: &Matrix<f64, D, U1, S>,
    what: &'static str,
) -> Result<f64, LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    check_symmetric(cov, what)?;
    quad_form_symmetric(cov, v, what)
}

/// `v^T C^-1 v` for a matrix the caller guarantees to be finite and exactly symmetric (a
/// filter's own covariance after [`symmetrize`](crate::symmetrize), as
/// [`Covariance::from_symmetric`] takes): only the vector and positive definiteness are
/// checked. A Monte Carlo study computes one NEES per run and step, and re-checking a
/// covariance the filter has just checked cost about a twentieth of a Kalman step.
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] or [`LinalgError::NonFinite`] for the vector,
/// [`LinalgError::NotPositiveDefinite`] if the factorisation fails (which includes NaN
/// entries the caller let through).
#[inline(always)]
pub fn quad_form_symmetric<D: Dim, S: Storage<f64, D> + IsContiguous>(
    cov: &OMatrix<f64, D, D>,
    v: &Matrix<f64, D, U1, S>,
    what: &'static str,
) -> Result<f64, LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    crate::check_dim(cov.nrows(), v.nrows(), "vector")?;
    check_finite(v, "vector")?;
    let chol = cholesky(cov.clone()).ok_or(LinalgError::NotPositiveDefinite { what })?;
    let mut w = v.clone_owned();
    chol.l_dirty().solve_lower_triangular_unchecked_mut(&mut w);
    let q = w.norm_squared();
    if q.is_finite() {
        Ok(q)
    } else {
        Err(LinalgError::NotPositiveDefinite { what })
    }
}

/// What a covariance-like input must be beyond symmetric, for [`check_covariance`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Definiteness {
    /// Positive semi-definite, as [`PsdMatrix`](crate::PsdMatrix) checks it (the pivoted
    /// factorisation [`semidefinite_factor`](crate::semidefinite_factor) succeeds): noise
    /// covariances, which are often rank-deficient, and covariances that are only propagated.
    SemiDefinite,
    /// Positive definite, as [`Covariance`] checks it (the Cholesky factorisation succeeds):
    /// covariances that are solved with.
    Definite,
}

/// The one check of a covariance-like input that enters a public function: square, finite,
/// symmetric to [`SYMMETRY_TOLERANCE`] (relative asymmetry `|a_ij - a_ji| / sqrt(|a_ii
/// a_jj|)`) and positive semi-definite or definite as `definiteness` asks: exactly what
/// [`PsdMatrix::named`](crate::PsdMatrix::named) or [`Covariance::named`] accept, for a
/// function that needs the matrix checked but not the type (it factorises a copy and drops
/// it). Every function of the workspace that takes a covariance checks it through this, one
/// of those two constructors, or their filters' initial check, so the tolerance and the
/// definiteness test are the same everywhere.
///
/// ```
/// use kalibra_linalg::{check_covariance, Definiteness, LinalgError, Matrix2};
///
/// let rank_one = Matrix2::new(1.0, 1.0, 1.0, 1.0);
/// check_covariance(&rank_one, "Q", Definiteness::SemiDefinite)?;
/// assert!(check_covariance(&rank_one, "S", Definiteness::Definite).is_err());
/// let indefinite = Matrix2::new(1.0, 2.0, 2.0, 1.0);
/// assert!(matches!(
///     check_covariance(&indefinite, "Q", Definiteness::SemiDefinite),
///     Err(LinalgError::NotPositiveSemiDefinite { .. })
/// ));
/// let asymmetric = Matrix2::new(1.0, 0.5, 0.0, 1.0);
/// assert!(matches!(
///     check_covariance(&asymmetric, "Q", Definiteness::SemiDefinite),
///     Err(LinalgError::NotSymmetric { .. })
/// ));
/// # Ok::<(), LinalgError>(())
/// ```
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] (not square), [`LinalgError::NonFinite`],
/// [`LinalgError::NotSymmetric`], and [`LinalgError::NotPositiveSemiDefinite`] or
/// [`LinalgError::NotPositiveDefinite`], naming `what`.
pub fn check_covariance<D: Dim>(
    m: &OMatrix<f64, D, D>,
    what: &'static str,
    definiteness: Definiteness,
) -> Result<(), LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    // Through the checked types themselves, so that there is one definition of each check.
    match definiteness {
        Definiteness::SemiDefinite => crate::PsdMatrix::named(m.clone(), what).map(drop),
        Definiteness::Definite => Covariance::named(m.clone(), what).map(drop),
    }
}

/// Checks that `m` is square, finite and symmetric to [`SYMMETRY_TOLERANCE`] (relative
/// asymmetry `|a_ij - a_ji| / sqrt(|a_ii a_jj|)`): the one check every matrix meant as a
/// covariance passes, before any factorisation.
///
/// # Errors
/// [`LinalgError::DimensionMismatch`], [`LinalgError::NonFinite`] or
/// [`LinalgError::NotSymmetric`], naming `what`.
pub fn check_symmetric<D: Dim>(
    m: &OMatrix<f64, D, D>,
    what: &'static str,
) -> Result<(), LinalgError>
where
    DefaultAllocator: Alloc<D>,
{
    crate::check_dim(m.nrows(), m.ncols(), what)?;
    check_finite(m, what)?;
    let asymmetry = relative_asymmetry(m);
    if asymmetry > SYMMETRY_TOLERANCE {
        return Err(LinalgError::NotSymmetric { what, asymmetry });
    }
    Ok(())
}

/// Largest `|a_ij - a_ji| / sqrt(|a_ii a_jj|)`, with an absolute fallback when a diagonal is 0.
fn relative_asymmetry<D: Dim>(m: &OMatrix<f64, D, D>) -> f64
where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    // Fast path, branch-free: filters symmetrise every covariance they produce, so the
    // matrices checked per step (NEES of every run and step) are usually exactly symmetric.
    let mut exact = true;
    for j in 0..n {
        for i in (j + 1)..n {
            exact &= m[(i, j)] == m[(j, i)];
        }
    }
    if exact {
        return 0.0;
    }
    let mut worst = 0.0f64;
    for j in 0..n {
        for i in (j + 1)..n {
            let diff = (m[(i, j)] - m[(j, i)]).abs();
            if diff == 0.0 {
                continue;
            }
            let scale = (m[(i, i)] * m[(j, j)]).abs().sqrt();
            let rel = if scale > 0.0 {
                diff / scale
            } else {
                f64::INFINITY
            };
            worst = worst.max(rel);
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DMatrix, DVector, Matrix3, Vector3};
    use approx::assert_relative_eq;

    fn spd3() -> Matrix3<f64> {
        Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0)
    }

    #[test]
    fn quad_form_and_solve_match_the_inverse() {
        let c = Covariance::new(spd3()).unwrap();
        let v = Vector3::new(0.3, -1.0, 2.0);
        let inv = spd3().try_inverse().unwrap();
        assert_relative_eq!(
            c.quad_form(&v).unwrap(),
            (v.transpose() * inv * v)[0],
            epsilon = 1e-13
        );
        assert_relative_eq!(c.solve(&v).unwrap(), inv * v, epsilon = 1e-13);
        assert_relative_eq!(c.log_det(), spd3().determinant().ln(), epsilon = 1e-13);
        assert_relative_eq!(
            c.trace_solve(&Matrix3::identity()).unwrap(),
            inv.trace(),
            epsilon = 1e-13
        );
    }

    #[test]
    fn rejects_bad_input_with_typed_errors() {
        let mut nan = spd3();
        nan[(1, 1)] = f64::NAN;
        assert!(matches!(
            Covariance::new(nan),
            Err(LinalgError::NonFinite { .. })
        ));
        let mut inf = spd3();
        inf[(0, 2)] = f64::INFINITY;
        assert!(matches!(
            Covariance::new(inf),
            Err(LinalgError::NonFinite { .. })
        ));
        let mut asym = spd3();
        asym[(0, 1)] += 0.1;
        assert!(matches!(
            Covariance::new(asym),
            Err(LinalgError::NotSymmetric { .. })
        ));
        let indefinite = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 1.0));
        assert!(matches!(
            Covariance::new(indefinite),
            Err(LinalgError::NotPositiveDefinite { .. })
        ));
        let not_square = DMatrix::<f64>::zeros(2, 3);
        assert!(matches!(
            Covariance::<nalgebra::Dyn>::new(not_square),
            Err(LinalgError::DimensionMismatch { .. })
        ));
    }

    #[test]
    fn dynamic_size_checks_operand_dimensions() {
        let c =
            Covariance::new(DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 2.0]))).unwrap();
        let wrong = DVector::from_vec(vec![1.0, 2.0, 3.0]);
        assert!(matches!(
            c.quad_form(&wrong),
            Err(LinalgError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            c.solve(&wrong),
            Err(LinalgError::DimensionMismatch { .. })
        ));
    }

    #[test]
    fn rounding_asymmetry_is_accepted_and_removed() {
        let mut m = spd3();
        m[(0, 1)] += 1e-14;
        let c = Covariance::new(m).unwrap();
        assert_eq!(c.matrix()[(0, 1)], c.matrix()[(1, 0)]);
    }
}
