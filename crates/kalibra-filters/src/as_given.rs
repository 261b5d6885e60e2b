//! The algebra of a filter started with [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven):
//! general (non-symmetric) solves by LU factorisation with partial pivoting.
//!
//! The matrices are copied to dynamic storage: nalgebra's LU needs a `DimMin` bound that a
//! generic `M: Dim` does not carry, and this path serves studies of a paper's arithmetic, not
//! the hot path. The elimination is nalgebra's either way, so the results equal those of an LU
//! on fixed-size matrices (tested against paper 000's replay).

use kalibra_linalg::{Alloc, DMatrix, DefaultAllocator, Dim, OMatrix};
use nalgebra::allocator::Allocator;

fn to_dyn<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> DMatrix<f64>
where
    DefaultAllocator: Allocator<R, C>,
{
    DMatrix::from_iterator(m.nrows(), m.ncols(), m.iter().copied())
}

/// `A^-1 B` for a square `A`, by LU with partial pivoting; `None` if `A` is exactly singular.
pub(crate) fn lu_solve<M: Dim, C: Dim>(
    a: &OMatrix<f64, M, M>,
    b: &OMatrix<f64, M, C>,
) -> Option<OMatrix<f64, M, C>>
where
    DefaultAllocator: Alloc<M> + Allocator<M, C>,
{
    let x = to_dyn(a).lu().solve(&to_dyn(b))?;
    let (rows, cols) = b.shape_generic();
    Some(OMatrix::<f64, M, C>::from_iterator_generic(
        rows,
        cols,
        x.iter().copied(),
    ))
}

/// `ln det A` by LU; NaN unless the determinant is positive and finite (a Gaussian density
/// needs a positive determinant).
pub(crate) fn lu_ln_det<M: Dim>(a: &OMatrix<f64, M, M>) -> f64
where
    DefaultAllocator: Alloc<M>,
{
    let det = to_dyn(a).lu().determinant();
    if det > 0.0 && det.is_finite() {
        det.ln()
    } else {
        f64::NAN
    }
}
