//! The lane-wise Cholesky factor and its triangular solves: one definition for every batched
//! filter, generic over how a pivot divides ([`Pivot`]).
//!
//! The batched KF and EKF multiply by the reciprocals of the pivots ([`Reciprocal`]): each
//! pivot is divided once and the other divisions by it are multiplications, which takes the
//! divider's latency off the chain of dependent operations (a division by `l_jj` and a
//! multiplication by its reciprocal differ by one rounding). The batched UKF divides by each
//! pivot ([`Divide`]) as nalgebra's Cholesky and triangular solves do, so that a lane
//! reproduces the scalar UKF's numbers to the last bit where no fused multiply-add intervenes
//! and an adaptive kappa chooses what the scalar chooses between close candidates
//! (kalibra-filters' `tests/batch_ukf.rs`).

// The kernels index matrices as the formulas do (`l[i][k] w[k]`); iterator chains would hide
// the algebra and add closures, which must not leave the dispatched function.
#![allow(clippy::needless_range_loop)]

use std::marker::PhantomData;

use pulp::Simd;

/// How a lane-wise factorisation and its solves divide by a pivot `l_jj`.
pub trait Pivot {
    /// Whether the factor keeps the reciprocals of its diagonal (and divides by multiplying).
    const RECIPROCAL: bool;

    /// `s / l_jj`, given the pivot `l_jj` and, with [`Pivot::RECIPROCAL`], its reciprocal.
    fn divide<S: Simd>(simd: S, s: S::f64s, pivot: S::f64s, reciprocal: S::f64s) -> S::f64s;
}

/// Multiplies by the reciprocal of the pivot, computed once per pivot (the batched KF and
/// EKF).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reciprocal;

impl Pivot for Reciprocal {
    const RECIPROCAL: bool = true;

    #[inline(always)]
    fn divide<S: Simd>(simd: S, s: S::f64s, _pivot: S::f64s, reciprocal: S::f64s) -> S::f64s {
        simd.mul_f64s(s, reciprocal)
    }
}

/// Divides by the pivot, as nalgebra does (the batched UKF).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Divide;

impl Pivot for Divide {
    const RECIPROCAL: bool = false;

    #[inline(always)]
    fn divide<S: Simd>(simd: S, s: S::f64s, pivot: S::f64s, _reciprocal: S::f64s) -> S::f64s {
        simd.div_f64s(s, pivot)
    }
}

/// The lower Cholesky factor `L` (`L L^T = A`) of a symmetric `D x D` matrix, one factor per
/// lane of a vector of the instruction set of `S`, with the pivot rule `P`.
///
/// A matrix that is not positive definite gives NaN or infinite entries, never a panic: `sqrt`
/// of a negative pivot is NaN, of zero 0, and its reciprocal infinite.
///
/// ```
/// use kalibra_linalg::simd::{BATCH, Divide, Isa, LaneCholesky, store};
/// use pulp::{Simd, WithSimd};
///
/// // Solves [[4, 2], [2, 5]] y = [2, 5] in every lane: y = [0, 1].
/// struct Solve;
/// impl WithSimd for Solve {
///     type Output = [[f64; BATCH]; 2];
///     #[inline(always)]
///     fn with_simd<S: Simd>(self, simd: S) -> [[f64; BATCH]; 2] {
///         let v = |x: f64| simd.splat_f64s(x);
///         let a = [[v(4.0), v(2.0)], [v(2.0), v(5.0)]];
///         let factor = LaneCholesky::<S, 2, Divide>::new(simd, &a);
///         let y = factor.solve(simd, &[v(2.0), v(5.0)]);
///         let mut out = [[0.0; BATCH]; 2];
///         for c in 0..BATCH / S::F64_LANES {
///             store::<S>(&mut out[0], c, y[0]);
///             store::<S>(&mut out[1], c, y[1]);
///         }
///         out
///     }
/// }
/// let y = Isa::detect().dispatch(Solve);
/// assert!(y[0].iter().all(|y0| y0.abs() < 1e-15));
/// assert!(y[1].iter().all(|y1| (y1 - 1.0).abs() < 1e-15));
/// ```
pub struct LaneCholesky<S: Simd, const D: usize, P> {
    /// `L`, lower triangular (its upper triangle is zero).
    pub l: [[S::f64s; D]; D],
    /// With [`Reciprocal`], `1 / l_jj`; with [`Divide`], ones (unused).
    pub inv: [S::f64s; D],
    rule: PhantomData<fn() -> P>,
}

impl<S: Simd, const D: usize, P> Clone for LaneCholesky<S, D, P> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<S: Simd, const D: usize, P> Copy for LaneCholesky<S, D, P> {}

impl<S: Simd, const D: usize, P: Pivot> LaneCholesky<S, D, P> {
    /// The factor of the symmetric `a` (only its lower triangle is read), in nalgebra's order
    /// of operations: pivots `a_jj - sum_k l_jk^2`, then the column's entries
    /// `(a_ij - sum_k l_ik l_jk)` divided by the pivot as `P` divides.
    #[inline(always)]
    pub fn new(simd: S, a: &[[S::f64s; D]; D]) -> Self {
        let one = simd.splat_f64s(1.0);
        let mut l = [[simd.splat_f64s(0.0); D]; D];
        let mut inv = [one; D];
        for j in 0..D {
            let mut d = a[j][j];
            for k in 0..j {
                d = simd.sub_f64s(d, simd.mul_f64s(l[j][k], l[j][k]));
            }
            let ljj = simd.sqrt_f64s(d);
            l[j][j] = ljj;
            if P::RECIPROCAL {
                inv[j] = simd.div_f64s(one, ljj);
            }
            for i in (j + 1)..D {
                let mut s = a[i][j];
                for k in 0..j {
                    s = simd.sub_f64s(s, simd.mul_f64s(l[i][k], l[j][k]));
                }
                l[i][j] = P::divide(simd, s, ljj, inv[j]);
            }
        }
        Self::from_parts(l, inv)
    }

    /// A factor from its parts, as [`LaneCholesky::new`] leaves them (`inv` as documented on
    /// the field).
    #[inline(always)]
    pub fn from_parts(l: [[S::f64s; D]; D], inv: [S::f64s; D]) -> Self {
        Self {
            l,
            inv,
            rule: PhantomData,
        }
    }

    /// A factor from a lower-triangular `l` computed elsewhere (a square root that is not a
    /// Cholesky factor solves the same way), its reciprocals formed as `P` needs them.
    #[inline(always)]
    pub fn from_lower(simd: S, l: [[S::f64s; D]; D]) -> Self {
        let one = simd.splat_f64s(1.0);
        let mut inv = [one; D];
        if P::RECIPROCAL {
            for j in 0..D {
                inv[j] = simd.div_f64s(one, l[j][j]);
            }
        }
        Self::from_parts(l, inv)
    }

    /// Solves `L w = b` by forward substitution.
    #[inline(always)]
    pub fn solve_lower(&self, simd: S, b: &[S::f64s; D]) -> [S::f64s; D] {
        let l = &self.l;
        let mut w = *b;
        for i in 0..D {
            let mut s = w[i];
            for k in 0..i {
                s = simd.sub_f64s(s, simd.mul_f64s(l[i][k], w[k]));
            }
            w[i] = P::divide(simd, s, l[i][i], self.inv[i]);
        }
        w
    }

    /// Solves `L^T y = w` by backward substitution.
    #[inline(always)]
    pub fn solve_upper(&self, simd: S, w: &[S::f64s; D]) -> [S::f64s; D] {
        let l = &self.l;
        let mut y = *w;
        for i in (0..D).rev() {
            let mut s = y[i];
            for k in (i + 1)..D {
                s = simd.sub_f64s(s, simd.mul_f64s(l[k][i], y[k]));
            }
            y[i] = P::divide(simd, s, l[i][i], self.inv[i]);
        }
        y
    }

    /// Solves `A y = b` through the factor (`L L^T y = b`).
    #[inline(always)]
    pub fn solve(&self, simd: S, b: &[S::f64s; D]) -> [S::f64s; D] {
        self.solve_upper(simd, &self.solve_lower(simd, b))
    }
}
