//! Triangularisation by Householder reflections: the one orthogonal kernel of the square-root
//! filters.
//!
//! Given a wide matrix `W` (`r x c`, `c >= r`), it finds the lower-triangular `L` (`r x r`, with
//! a non-negative diagonal) and an orthogonal `Theta` with `W Theta = [L 0]`, so that
//! `L L^T = W W^T` without `W W^T` ever being formed. The work is done on `T = W^T`, stored
//! column-major in a slice the filter owns, so that the stacked arrays (`[F S, sqrt(Q)]`, the
//! measurement update's `(m + n) x (m + n)` array) need no `DimSum` size types and a step
//! allocates nothing: the QR factorisation `T = Q R` gives `L = R^T`.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, binary_exponent, ldexp};

/// A column-major `rows x cols` work array (`rows >= cols`) holding `T = W^T`.
pub(crate) struct Array<'a> {
    data: &'a mut [f64],
    rows: usize,
    cols: usize,
}

impl<'a> Array<'a> {
    /// A zeroed `rows x cols` array in the front of `scratch`, grown if it is too short (the
    /// filters size it once, at construction, so this never allocates on a step).
    pub(crate) fn zeroed(scratch: &'a mut Vec<f64>, rows: usize, cols: usize) -> Self {
        let len = rows * cols;
        if scratch.len() < len {
            scratch.resize(len, 0.0);
        }
        let data = &mut scratch[..len];
        data.fill(0.0);
        Self { data, rows, cols }
    }

    /// Writes `block^T` with its top-left corner at `(row, col)`: the block is a block of `W`
    /// whose top-left corner is at `(col, row)`.
    pub(crate) fn put_transposed<R: Dim, C: Dim, S>(
        &mut self,
        row: usize,
        col: usize,
        block: &nalgebra::Matrix<f64, R, C, S>,
    ) where
        S: nalgebra::RawStorage<f64, R, C>,
    {
        for j in 0..block.nrows() {
            for i in 0..block.ncols() {
                self.data[(row + i) + (col + j) * self.rows] = block[(j, i)];
            }
        }
    }

    /// Reduces the array to upper-triangular form `R` (in place, Householder reflections from
    /// the left, each chosen to avoid cancellation), then flips the sign of each row of `R`
    /// whose diagonal entry is negative, so that `L = R^T` has a non-negative diagonal (the
    /// Cholesky factor's convention; `L L^T` is unchanged).
    pub(crate) fn triangularise(&mut self) {
        // Squares and dot products of entries beyond about 1e150 (or below 1e-150) leave f64's
        // range: such an array is scaled by a power of two first, which is exact, and scaled
        // back at the end; arrays within the range are not touched, bit for bit (the test
        // `entries_whose_squares_leave_the_range_are_scaled`).
        let largest = self.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let shift = match binary_exponent(largest) {
            Some(e) if e.abs() > 450 => e,
            _ => 0,
        };
        if shift != 0 {
            self.data.iter_mut().for_each(|v| *v = ldexp(*v, -shift));
        }
        self.reflect();
        if shift != 0 {
            self.data.iter_mut().for_each(|v| *v = ldexp(*v, shift));
        }
    }

    /// [`Array::triangularise`] on an array within range.
    fn reflect(&mut self) {
        let (rows, cols) = (self.rows, self.cols);
        for j in 0..cols.min(rows) {
            let col = &mut self.data[j * rows..(j + 1) * rows];
            let squares: f64 = col[j..].iter().map(|v| v * v).sum();
            if squares == 0.0 {
                continue;
            }
            let norm = squares.sqrt();
            let x0 = col[j];
            // alpha of the opposite sign to x0, so v = x - alpha e1 has no cancellation; v is
            // kept in the column, and 2 / v^T v = 1 / (alpha (alpha - x0)), written as two
            // quotients so that tiny columns do not underflow to an infinite beta.
            let alpha = if x0 > 0.0 { -norm } else { norm };
            col[j] = x0 - alpha;
            let beta = (1.0 / alpha) * (1.0 / (alpha - x0));
            let (head, tail) = self.data.split_at_mut((j + 1) * rows);
            let v = &head[j * rows + j..(j + 1) * rows];
            for other in tail.chunks_exact_mut(rows) {
                let dot: f64 = v.iter().zip(&other[j..]).map(|(a, b)| a * b).sum();
                let t = dot * beta;
                for (o, a) in other[j..].iter_mut().zip(v) {
                    *o -= t * a;
                }
            }
            let col = &mut self.data[j * rows..(j + 1) * rows];
            col[j] = alpha;
            col[j + 1..].fill(0.0);
        }
        for j in 0..cols.min(rows) {
            if self.data[j + j * rows] < 0.0 {
                for c in j..cols {
                    self.data[j + c * rows] = -self.data[j + c * rows];
                }
            }
        }
    }

    /// The block of `L = R^T` with top-left corner `(row, col)` of `L`, of the given size, that
    /// is, the transpose of `R`'s block at `(col, row)`.
    pub(crate) fn lower_block<R: Dim, C: Dim>(
        &self,
        row: usize,
        col: usize,
        (r, c): (R, C),
    ) -> OMatrix<f64, R, C>
    where
        DefaultAllocator: nalgebra::allocator::Allocator<R, C>,
    {
        OMatrix::<f64, R, C>::from_fn_generic(r, c, |i, j| {
            self.data[(col + j) + (row + i) * self.rows]
        })
    }
}

/// The lower-triangular `L` with `L L^T = A A^T + B B^T` for two `n x n` matrices (the
/// square-root KF's prediction: `A = F S`, `B = sqrt(Q)`), by the QR factorisation of the
/// `2n x n` array `[A^T; B^T]`.
pub(crate) fn lower_root_of_sum<N: Dim>(
    scratch: &mut Vec<f64>,
    a: &OMatrix<f64, N, N>,
    b: &OMatrix<f64, N, N>,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    let n = a.nrows();
    let mut t = Array::zeroed(scratch, 2 * n, n);
    t.put_transposed(0, 0, a);
    t.put_transposed(n, 0, b);
    t.triangularise();
    let d = a.shape_generic().0;
    t.lower_block(0, 0, (d, d))
}

/// The lower-triangular `L` with `L L^T = A A^T` for a square `A` (a square root that is not
/// triangular, such as [`kalibra_linalg::semidefinite_factor`]'s pivoted one).
pub(crate) fn lower_root<N: Dim>(
    scratch: &mut Vec<f64>,
    a: &OMatrix<f64, N, N>,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    let n = a.nrows();
    let mut t = Array::zeroed(scratch, n, n);
    t.put_transposed(0, 0, a);
    t.triangularise();
    let d = a.shape_generic().0;
    t.lower_block(0, 0, (d, d))
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::{Matrix3, SMatrix};

    #[test]
    fn the_root_of_a_sum_reproduces_the_sum_and_is_lower_triangular() {
        let a = Matrix3::new(1.0, 2.0, 0.5, -1.0, 3.0, 0.25, 0.0, 1.0, 4.0);
        let b = Matrix3::new(0.1, 0.0, 0.0, 0.2, 0.3, 0.0, -0.1, 0.0, 0.5);
        let l = lower_root_of_sum(&mut Vec::new(), &a, &b);
        let expected = a * a.transpose() + b * b.transpose();
        assert!((l * l.transpose() - expected).amax() < 1e-13 * expected.amax());
        for i in 0..3 {
            assert!(l[(i, i)] >= 0.0);
            for j in i + 1..3 {
                assert_eq!(l[(i, j)], 0.0);
            }
        }
        // The Cholesky factor is unique with a positive diagonal.
        let chol = expected.cholesky().unwrap().unpack();
        assert!((l - chol).amax() < 1e-13 * chol.amax());
    }

    #[test]
    fn entries_whose_squares_leave_the_range_are_scaled() {
        for scale in [1e200, 1e-200] {
            let a = Matrix3::new(1.0, 2.0, 0.5, -1.0, 3.0, 0.25, 0.0, 1.0, 4.0) * scale;
            let l = lower_root(&mut Vec::new(), &a) / scale;
            let a = a / scale;
            assert!((l * l.transpose() - a * a.transpose()).amax() < 1e-13 * 30.0);
        }
    }

    #[test]
    fn a_zero_column_and_a_tall_array_are_handled() {
        // W = [A 0]: the second block contributes nothing; a zero row of A gives a zero row of L.
        let a = SMatrix::<f64, 3, 3>::new(0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 3.0, 0.0, 1.0);
        let l = lower_root(&mut vec![1.0; 2], &a);
        assert!((l * l.transpose() - a * a.transpose()).amax() < 1e-14);
        assert_eq!(l.row(0).amax(), 0.0);
    }
}
