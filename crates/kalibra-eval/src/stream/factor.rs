//! The one factorisation each cell needs (NEES of `P`, NIS of `S`), into reusable storage:
//! [`Factor`], at a fixed size through [`super::fixed`] for the common dimensions.

use kalibra_linalg::nalgebra::Cholesky;
use kalibra_linalg::{DMatrix, DVector, LinalgError, check_symmetric, symmetrize};

use super::cell::{MatrixCell, fill};
use super::fixed;

/// Reusable storage for the one factorisation each cell needs (NEES of `P`, NIS of `S`), so
/// that evaluating a cell allocates nothing (on a large log the allocator would otherwise
/// cost more than the arithmetic; `cargo xtask bench eval` times it). The operations are those of
/// `kalibra_linalg::quad_form_once` (NEES) and of `Covariance::named` with `nis` (NIS), in
/// the same order, so the numbers are the same to the bit.
pub(super) struct Factor {
    dim: usize,
    /// The matrix, then its Cholesky factor in place (empty after a failed factorisation
    /// until the next cell refills it).
    matrix: DMatrix<f64>,
    /// `L^-1 v`.
    pub(super) w: DVector<f64>,
}

impl Factor {
    pub(super) fn new(dim: usize) -> Self {
        Self {
            dim,
            matrix: DMatrix::zeros(dim, dim),
            w: DVector::zeros(dim),
        }
    }

    /// Loads a cell's matrix (its length checked by [`super::cell::square`]).
    pub(super) fn load(&mut self, cell: MatrixCell<'_>) {
        fill(&mut self.matrix, self.dim, cell);
    }

    /// Factors the loaded matrix in place; `false` if it is not positive definite.
    fn factor(&mut self) -> bool {
        let matrix = std::mem::replace(&mut self.matrix, DMatrix::zeros(0, 0));
        match Cholesky::new(matrix) {
            Some(chol) => {
                self.matrix = chol.unpack_dirty();
                true
            }
            None => false,
        }
    }

    /// `w = L^-1 v` with the factor in place, and `|w|^2`.
    fn solve(&mut self, v: &[f64]) -> f64 {
        self.w.copy_from_slice(v);
        self.matrix
            .solve_lower_triangular_unchecked_mut(&mut self.w);
        self.w.norm_squared()
    }

    /// The NEES of error `v` under covariance `cell`: [`Factor::nees`] after
    /// [`Factor::load`], at a fixed size for the common dimensions ([`fixed::at_size`]).
    #[inline]
    pub(super) fn nees_of(
        &mut self,
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<f64, LinalgError> {
        if let Some(q) = fixed::at_size!(self.dim, N => fixed::nees::<N>(cell, v, what)) {
            return q;
        }
        self.load(cell);
        self.nees(v, what)
    }

    /// The NIS of innovation `v` under `S = cell`, and `w = L^-1 v` left in `self.w`:
    /// [`Factor::nis`] after [`Factor::load`], at a fixed size for the common dimensions
    /// ([`fixed::at_size`]).
    #[inline]
    pub(super) fn nis_of(
        &mut self,
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<f64, LinalgError> {
        let at_size = fixed::at_size!(self.dim, N => {
            let (q, w) = fixed::nis::<N>(cell, v, what)?;
            if self.w.len() != N {
                self.w = DVector::zeros(N);
            }
            self.w.copy_from_slice(w.as_slice());
            q
        });
        if let Some(q) = at_size {
            return Ok(q);
        }
        self.load(cell);
        self.nis(v, what)
    }

    /// `v^T M^-1 v` as `kalibra_metrics::nees` computes it.
    pub(super) fn nees(&mut self, v: &[f64], what: &'static str) -> Result<f64, LinalgError> {
        check_symmetric(&self.matrix, what)?;
        // An error can overflow although truth and estimate are finite.
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LinalgError::NonFinite { what: "vector" });
        }
        if !self.factor() {
            return Err(LinalgError::NotPositiveDefinite { what });
        }
        let q = self.solve(v);
        if q.is_finite() {
            Ok(q)
        } else {
            Err(LinalgError::NotPositiveDefinite { what })
        }
    }

    /// `v^T M^-1 v` as `Covariance::named` and `kalibra_metrics::nis` compute it (`v`
    /// finite): the matrix symmetrised first; `w` is left as the normalised innovation.
    pub(super) fn nis(&mut self, v: &[f64], what: &'static str) -> Result<f64, LinalgError> {
        check_symmetric(&self.matrix, what)?;
        symmetrize(&mut self.matrix);
        if !(self.factor() && self.matrix.diagonal().iter().all(|d| d.is_finite())) {
            return Err(LinalgError::NotPositiveDefinite { what });
        }
        Ok(self.solve(v))
    }
}
