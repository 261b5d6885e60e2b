//! [`Factor`](super::factor::Factor)'s factorisations at a fixed size `N`, on nalgebra's stack
//! matrices: no heap, no bounds check per entry, loops of known length, where the `Dyn` path
//! spends more in loading the matrix entry by entry and in `Dyn` loop overhead than in the
//! arithmetic (`cargo xtask bench eval` times the whole evaluation). The operations are the
//! same generic nalgebra and kalibra-linalg code as the `Dyn` path's, in the same order, so
//! the values are the same to the bit: the property test
//! `factor_equals_the_metrics_bit_for_bit` compares them at every size.
//!
//! It is not kalibra-linalg's `quad_form_once` at `Const<N>`: that one takes `|w|^2` with
//! nalgebra's fixed-size `norm_squared`, which adds a 4-vector's squares pairwise and so
//! differs in the last bit from the `Dyn` sum the metrics crate computes.

use kalibra_linalg::nalgebra::{Cholesky, SVector};
use kalibra_linalg::{LinalgError, SMatrix, check_symmetric, symmetrize};

use super::cell::MatrixCell;

/// `Some(body)` with the constant `$n` set to `dim` when `dim` is one of the fixed sizes, 1 to
/// 6; `None` for any other size. The one list of sizes that [`Factor`](super::factor::Factor)'s
/// NEES and NIS take at a fixed size.
macro_rules! at_size {
    ($dim:expr, $n:ident => $body:expr) => {
        $crate::stream::fixed::at_size!(@sizes $dim, $n => $body; 1 2 3 4 5 6)
    };
    (@sizes $dim:expr, $n:ident => $body:expr; $($size:literal)*) => {
        match $dim {
            $($size => {
                const $n: usize = $size;
                Some($body)
            })*
            _ => None,
        }
    };
}
pub(super) use at_size;

/// The cell's matrix (its length checked by `square`).
#[inline(always)]
fn load<const N: usize>(cell: MatrixCell<'_>) -> SMatrix<f64, N, N> {
    match cell {
        // One bounds check for the cell rather than one per entry.
        MatrixCell::Full(v) => SMatrix::from_row_slice(&v[..N * N]),
        MatrixCell::Diagonal(v) => SMatrix::from_fn(|i, j| if i == j { v[i] } else { 0.0 }),
    }
}

/// `w = L^-1 v` for the lower Cholesky factor `L` of `m`, or `None` if `m` is not
/// positive definite; with `|w|^2`.
#[inline(always)]
fn solve<const N: usize>(
    m: SMatrix<f64, N, N>,
    v: &[f64],
) -> Option<(SMatrix<f64, N, N>, SVector<f64, N>, f64)> {
    let l = Cholesky::new(m)?.unpack_dirty();
    let mut w = SVector::<f64, N>::from_fn(|i, _| v[i]);
    l.solve_lower_triangular_unchecked_mut(&mut w);
    // `|w|^2` summed in index order, as nalgebra's `norm_squared` sums a `Dyn` vector
    // (its fixed-size 4-vector adds the squares pairwise, which differs in the last bit).
    let q = w.iter().fold(0.0, |sum, x| sum + x * x);
    Some((l, w, q))
}

/// [`super::Factor::nees`] at size `N`.
#[inline]
pub(super) fn nees<const N: usize>(
    cell: MatrixCell<'_>,
    v: &[f64],
    what: &'static str,
) -> Result<f64, LinalgError> {
    let m = load::<N>(cell);
    check_symmetric(&m, what)?;
    if !v.iter().all(|x| x.is_finite()) {
        return Err(LinalgError::NonFinite { what: "vector" });
    }
    match solve(m, v) {
        Some((_, _, q)) if q.is_finite() => Ok(q),
        _ => Err(LinalgError::NotPositiveDefinite { what }),
    }
}

/// [`super::Factor::nis`] at size `N`: the NIS and the normalised innovation `w`.
#[inline]
pub(super) fn nis<const N: usize>(
    cell: MatrixCell<'_>,
    v: &[f64],
    what: &'static str,
) -> Result<(f64, SVector<f64, N>), LinalgError> {
    let mut m = load::<N>(cell);
    check_symmetric(&m, what)?;
    symmetrize(&mut m);
    match solve(m, v) {
        Some((l, w, q)) if l.diagonal().iter().all(|d| d.is_finite()) => Ok((q, w)),
        _ => Err(LinalgError::NotPositiveDefinite { what }),
    }
}
