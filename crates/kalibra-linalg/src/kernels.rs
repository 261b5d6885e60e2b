//! The filter algebra as free functions over dimension-generic matrices.
//!
//! Each kernel is written once for any `N: Dim`; with `Const` dimensions nalgebra unrolls it
//! into stack code as fast as a hand-written `SMatrix` expression (checked by `cargo xtask
//! bench`). `Dyn` sizes from [`FAER_MIN_DIM`](crate::FAER_MIN_DIM) on run faer's products
//! instead (the choice is [`crate::backend`]'s, made once per kernel call).

use nalgebra::allocator::Allocator;
use nalgebra::storage::IsContiguous;
use nalgebra::{DefaultAllocator, Dim, Matrix, OMatrix, OVector, RawStorage};

use crate::{Alloc, LinalgError, backend};

/// The documented panic of the kernels below on `Dyn` sizes that do not fit. Checked before
/// the backend is chosen: faer's branch reads some operands as raw slices by the sizes of the
/// others (`R` by `H`'s rows), where a wrong size would read the wrong entries instead of
/// panicking. For fixed sizes the comparisons are constant and vanish, which needs the check
/// inlined into the calling crate, which a plain non-generic function is not, and a call per
/// kernel would weigh on a small filter's step (`cargo xtask bench w1`).
#[inline(always)]
#[track_caller]
fn assert_shape(what: &str, found: (usize, usize), expected: (usize, usize)) {
    if found != expected {
        shape_mismatch(what, found, expected);
    }
}

/// The panic of [`assert_shape`], out of line so that the inlined check stays a comparison.
#[cold]
#[inline(never)]
#[track_caller]
fn shape_mismatch(what: &str, found: (usize, usize), expected: (usize, usize)) -> ! {
    panic!(
        "{what} is {}x{} where {}x{} is expected",
        found.0, found.1, expected.0, expected.1
    );
}

/// `A P A^T` for any `A` (r x n) and square `P` (n x n): the covariance propagation `F P F^T`,
/// the projection `H P H^T`, and `K R K^T` all use it.
///
/// ```
/// use kalibra_linalg::{propagate, Matrix2};
/// let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
/// let p = Matrix2::identity();
/// assert_eq!(propagate(&f, &p), Matrix2::new(2.0, 1.0, 1.0, 1.0));
/// ```
///
/// # Panics
/// If the `Dyn` sizes do not fit (`a`'s columns differ from `p`'s size, or `p` is not square):
/// these are the filters' hot-path kernels, and take sizes already checked where they entered (the
/// filters check their models' sizes at construction and every model answer at each step; a caller
/// with outside data checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline(always)]
pub fn propagate<R: Dim, N: Dim>(
    a: &OMatrix<f64, R, N>,
    p: &OMatrix<f64, N, N>,
) -> OMatrix<f64, R, R>
where
    // Raw allocator bounds rather than `Alloc<N, R>`: callers hold `Alloc<N, M>` and call this
    // with both `R = M` (H P H^T) and `R = N, N = M` (K R K^T); the raw bounds are implied
    // either way, a second `Alloc` instance would not be.
    DefaultAllocator: Allocator<R, N> + Allocator<N, R> + Allocator<R, R> + Allocator<N, N>,
{
    let n = p.nrows();
    assert_shape("propagate: P", p.shape(), (n, n));
    assert_shape("propagate: A", a.shape(), (a.nrows(), n));
    if let Some(par) = backend::route(a.shape_generic().0, p.shape_generic().0) {
        return backend::propagate(a, p, par);
    }
    // Fixed sizes: written out and inlined, the same sums in the same order as nalgebra's
    // out-of-line product (`cargo xtask bench smooth`).
    if is_fixed::<N>() && is_fixed::<R>() {
        let ap = mul_fixed(a, p);
        return mul_fixed_t(&ap, a);
    }
    let ap = a * p;
    ap * a.transpose()
}

/// `a b` for fixed sizes, each entry summed over `k` from left to right as nalgebra's product
/// sums it (so the bits are its bits), written out so that it inlines into its caller.
#[inline(always)]
fn mul_fixed<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    b: &OMatrix<f64, K, C>,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<K, C> + Allocator<R, C>,
{
    mul_fixed_by(a, b.shape_generic().1, |k, j| b[(k, j)])
}

/// `a b^T` for fixed sizes, in [`mul_fixed`]'s order.
#[inline(always)]
fn mul_fixed_t<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    b: &OMatrix<f64, C, K>,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<C, K> + Allocator<R, C>,
{
    mul_fixed_by(a, b.shape_generic().0, |k, j| b[(j, k)])
}

/// `a B` for the `k x cols` matrix whose entry `(k, j)` is `b(k, j)`: [`mul_fixed`] and
/// [`mul_fixed_t`] read their right factor through it.
#[inline(always)]
fn mul_fixed_by<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    cols: C,
    b: impl Fn(usize, usize) -> f64,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<R, C>,
{
    let mut out = OMatrix::zeros_generic(a.shape_generic().0, cols);
    // A whole column of `out` takes each term in turn (k outside, i inside): the entries of a
    // column sit side by side, so the compiler adds two at a time with the same sums per entry
    // (`cargo xtask bench w1`, the scalar library).
    for j in 0..out.ncols() {
        for k in 0..a.ncols() {
            let bkj = b(k, j);
            for i in 0..a.nrows() {
                let term = a[(i, k)] * bkj;
                out[(i, j)] = if k == 0 { term } else { out[(i, j)] + term };
            }
        }
    }
    out
}

/// The product `a b`: nalgebra's `a * b`, or faer's for large `Dyn` sizes.
///
/// ```
/// use kalibra_linalg::{product, Matrix2};
/// let a = Matrix2::new(1.0, 2.0, 3.0, 4.0);
/// assert_eq!(product(&a, &a), a * a);
/// ```
///
/// # Panics
/// If the `Dyn` sizes do not fit (`a`'s columns differ from `b`'s rows): these are the filters'
/// hot-path kernels, and take sizes already checked where they entered (the filters check their
/// models' sizes at construction and every model answer at each step; a caller with outside data
/// checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline(always)]
pub fn product<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    b: &OMatrix<f64, K, C>,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<K, C> + Allocator<R, C>,
{
    assert_shape("product: B", b.shape(), (a.ncols(), b.ncols()));
    let (r, k) = a.shape_generic();
    if is_fixed::<R>() && is_fixed::<K>() && is_fixed::<C>() {
        return mul_fixed(a, b);
    }
    if let Some(par) = backend::route3(r, k, b.shape_generic().1) {
        return backend::product(a, b, par);
    }
    a * b
}

/// The product `a b^T`, as [`product`] of `a` and `b`'s transpose computes it, without forming
/// the transpose for fixed sizes.
///
/// ```
/// use kalibra_linalg::{product_transpose, Matrix2};
/// let a = Matrix2::new(1.0, 2.0, 3.0, 4.0);
/// assert_eq!(product_transpose(&a, &a), a * a.transpose());
/// ```
///
/// # Panics
/// If the `Dyn` sizes do not fit (`a` and `b` differ in their number of columns): these are
/// the filters' hot-path kernels, and take sizes already checked where they entered (a caller
/// with outside data checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline(always)]
pub fn product_transpose<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    b: &OMatrix<f64, C, K>,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<C, K> + Allocator<K, C> + Allocator<R, C>,
{
    assert_shape("product_transpose: B", b.shape(), (b.nrows(), a.ncols()));
    if is_fixed::<R>() && is_fixed::<K>() && is_fixed::<C>() {
        return mul_fixed_t(a, b);
    }
    product(a, &b.transpose())
}

/// `b C^-1` from the Cholesky factorisation `C = L L^T`: what
/// `chol.solve(&b.transpose()).transpose()` returns, to the bit (each row of `b` through
/// nalgebra's forward and back substitution, in its order of operations), written out for
/// fixed sizes up to 8 so that it inlines into its caller; nalgebra's own solve for other sizes
/// below [`FAER_MIN_DIM`](crate::FAER_MIN_DIM), faer's from there on ([`crate::backend`]).
/// The Kalman gain `K = P H^T S^-1` and the smoother's gain `G = C P-^-1` are such solves.
///
/// ```
/// use kalibra_linalg::{cholesky_solve_right, Matrix2, SMatrix};
/// let chol = Matrix2::new(4.0, 2.0, 2.0, 3.0).cholesky().unwrap();
/// let b = SMatrix::<f64, 3, 2>::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0);
/// assert_eq!(cholesky_solve_right(&chol, &b), chol.solve(&b.transpose()).transpose());
/// ```
///
/// # Panics
/// If the `Dyn` sizes do not fit (`b`'s columns differ from the factor's size): a hot-path
/// kernel, as [`product`]. Fixed sizes cannot disagree.
#[inline(always)]
pub fn cholesky_solve_right<R: Dim, D: Dim>(
    chol: &nalgebra::Cholesky<f64, D>,
    b: &OMatrix<f64, R, D>,
) -> OMatrix<f64, R, D>
where
    DefaultAllocator: Allocator<R, D> + Allocator<D, R> + Allocator<D, D>,
{
    let l = chol.l_dirty();
    let n = l.nrows();
    assert_shape("cholesky_solve_right: B", b.shape(), (b.nrows(), n));
    if let Some(par) = backend::route(b.shape_generic().0, b.shape_generic().1) {
        let mut x = b.clone();
        backend::cholesky_solve_right_in_place(l, &mut x, par);
        return x;
    }
    if !(is_fixed::<R>() && is_fixed::<D>() && n <= 8) {
        return chol.solve(&b.transpose()).transpose();
    }
    let mut x = b.clone();
    for r in 0..x.nrows() {
        // L y = b_r^T: nalgebra's `solve_lower_triangular_vector_unchecked_mut`.
        for i in 0..n {
            let coeff = x[(r, i)] / l[(i, i)];
            x[(r, i)] = coeff;
            for k in (i + 1)..n {
                x[(r, k)] += -coeff * l[(k, i)];
            }
        }
        // L^T x = y: its back substitution, whose dot product over fewer than 8 terms starts
        // from +0 and adds them in order.
        for i in (0..n).rev() {
            let mut dot = 0.0;
            for k in (i + 1)..n {
                dot += l[(k, i)] * x[(r, k)];
            }
            x[(r, i)] = (x[(r, i)] - dot) / l[(i, i)];
        }
    }
    x
}

/// Whether `D` is a compile-time size.
#[inline(always)]
fn is_fixed<D: Dim>() -> bool {
    D::try_to_usize().is_some()
}

/// `(P H^T, S)` with the innovation covariance `S = H P H^T + R` symmetrised: the first half
/// of a Kalman update, whose `P H^T` the gain `K = P H^T S^-1` reuses
/// ([`Covariance::solve_right`](crate::Covariance::solve_right)).
///
/// ```
/// use kalibra_linalg::{innovation_covariance, Matrix2, SMatrix};
/// let p = Matrix2::new(4.0, 1.0, 1.0, 2.0);
/// let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
/// let (pht, s) = innovation_covariance(&p, &h, &SMatrix::<f64, 1, 1>::new(0.5));
/// assert_eq!(pht, SMatrix::<f64, 2, 1>::new(4.0, 1.0));
/// assert_eq!(s[(0, 0)], 4.5);
/// ```
///
/// # Panics
/// If the `Dyn` sizes do not fit (`h`'s columns differ from `p`'s size, or `r`'s size from `h`'s
/// rows): these are the filters' hot-path kernels, and take sizes already checked where they
/// entered (the filters check their models' sizes at construction and every model answer at each
/// step; a caller with outside data checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline(always)]
pub fn innovation_covariance<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    h: &OMatrix<f64, M, N>,
    r: &OMatrix<f64, M, M>,
) -> (OMatrix<f64, N, M>, OMatrix<f64, M, M>)
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = h.shape();
    assert_shape("innovation_covariance: P", p.shape(), (n, n));
    assert_shape("innovation_covariance: R", r.shape(), (m, m));
    if let Some(par) = backend::route(p.shape_generic().0, r.shape_generic().0) {
        return backend::innovation_covariance(p, h, r, par);
    }
    let pht = product_transpose(p, h);
    let mut s = product(h, &pht) + r;
    symmetrize(&mut s);
    (pht, s)
}

/// `acc += w sum_j (x_j - c)(x_j - c)^T`: the weighted scatter of sigma points about their
/// mean, as the unscented transform adds it to a covariance.
///
/// nalgebra adds one outer product per point; from [`FAER_MIN_DIM`](crate::FAER_MIN_DIM) on
/// (the larger of the dimension and the number of points) faer packs the deviations into one
/// matrix and forms the lower triangle of `D D^T` in one product, added to both triangles of
/// `acc`: `O(n)` allocations of `n x n` temporaries become two.
///
/// ```
/// use kalibra_linalg::{add_scatter, Matrix2, Vector2};
/// let mut acc = Matrix2::zeros();
/// add_scatter(&mut acc, &[Vector2::new(1.0, 0.0), Vector2::new(-1.0, 0.0)], &Vector2::zeros(), 0.5);
/// assert_eq!(acc, Matrix2::new(1.0, 0.0, 0.0, 0.0));
/// ```
///
/// # Panics
/// If a point or `c` differs in length from `acc` (possible only with `Dyn` sizes).
#[inline]
pub fn add_scatter<D: Dim>(
    acc: &mut OMatrix<f64, D, D>,
    points: &[OVector<f64, D>],
    center: &OVector<f64, D>,
    weight: f64,
) where
    DefaultAllocator: Alloc<D>,
{
    if let Some(par) = backend::route(center.shape_generic().0, nalgebra::Dyn(points.len())) {
        return backend::add_scatter(acc, points, center, weight, par);
    }
    for x in points {
        let d = x - center;
        *acc += &d * d.transpose() * weight;
    }
}

/// `acc += w sum_j a_j (u_j - v_j)^T` over the columns `a_j` of `a` and the pairs `u_j`, `v_j`:
/// the unscented cross-covariance `Pxz` from the columns of the prior's factor and the
/// differences of the sigma measurements on either side.
///
/// nalgebra adds one outer product per column; from
/// [`FAER_MIN_DIM`](crate::FAER_MIN_DIM) on faer forms `A (U - V)^T` in one product.
///
/// # Panics
/// If `plus` and `minus` do not both hold one vector per column of `a`, or the sizes differ
/// from `acc`'s (possible only with `Dyn` sizes).
#[inline]
pub fn add_cross_scatter<N: Dim, M: Dim>(
    acc: &mut OMatrix<f64, N, M>,
    a: &OMatrix<f64, N, N>,
    plus: &[OVector<f64, M>],
    minus: &[OVector<f64, M>],
    weight: f64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    assert!(
        plus.len() == a.ncols() && minus.len() == a.ncols(),
        "one pair of vectors per column"
    );
    if let Some(par) = backend::route(a.shape_generic().0, acc.shape_generic().1) {
        return backend::add_cross_scatter(acc, a, plus, minus, weight, par);
    }
    for (j, (u, v)) in plus.iter().zip(minus).enumerate() {
        let dz = u - v;
        *acc += a.column(j) * dz.transpose() * weight;
    }
}

/// Replaces `m` by `(m + m^T) / 2`, removing the asymmetry that rounding leaves in products.
///
/// # Panics
/// If `m` is not square (a programming error: covariances are square by type for `Const`
/// sizes and by construction for `Dyn`).
#[inline(always)]
pub fn symmetrize<D: Dim>(m: &mut OMatrix<f64, D, D>)
where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    assert_eq!(n, m.ncols(), "symmetrize needs a square matrix");
    if D::try_to_usize().is_none() {
        // Over the raw slice tile by tile (no bounds check per entry, and the strided
        // triangle stays in cache): the same arithmetic.
        backend::symmetrize_slice(m.as_mut_slice(), n);
        return;
    }
    for j in 0..n {
        for i in (j + 1)..n {
            let mean = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = mean;
            m[(j, i)] = mean;
        }
    }
}

/// Joseph-form covariance update `(I - K H) P (I - K H)^T + K R K^T`, symmetrised.
///
/// It keeps `P` symmetric positive semi-definite for any gain `K`, not only the optimal one,
/// at the cost of two extra products over [`standard_update`]. At the optimal gain
/// `K = P H^T S^-1` both forms agree to rounding (a property test checks it).
///
/// # Panics
/// If the `Dyn` sizes do not fit (`k` is not `n x m`, `h` not `m x n` or `r` not `m x m` for `p` of
/// `n x n`): these are the filters' hot-path kernels, and take sizes already checked where they
/// entered (the filters check their models' sizes at construction and every model answer at each
/// step; a caller with outside data checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline(always)]
pub fn joseph_update<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    k: &OMatrix<f64, N, M>,
    h: &OMatrix<f64, M, N>,
    r: &OMatrix<f64, M, M>,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = h.shape();
    assert_shape("joseph_update: P", p.shape(), (n, n));
    assert_shape("joseph_update: K", k.shape(), (n, m));
    assert_shape("joseph_update: R", r.shape(), (m, m));
    if let Some(par) = backend::route(p.shape_generic().0, r.shape_generic().0) {
        return backend::joseph_update(p, k, h, r, par);
    }
    let mut ikh = -product(k, h);
    for i in 0..ikh.nrows() {
        ikh[(i, i)] += 1.0;
    }
    let mut out = propagate(&ikh, p) + propagate(k, r);
    symmetrize(&mut out);
    out
}

/// Standard covariance update `(I - K H) P`, symmetrised. Correct only at the optimal gain;
/// kept for comparison with papers that print it.
///
/// # Panics
/// If the `Dyn` sizes do not fit (`k` is not `n x m` or `h` not `m x n` for `p` of `n x n`): these
/// are the filters' hot-path kernels, and take sizes already checked where they entered (the
/// filters check their models' sizes at construction and every model answer at each step; a caller
/// with outside data checks with [`check_dim`] first). Fixed sizes cannot disagree.
#[inline]
pub fn standard_update<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    k: &OMatrix<f64, N, M>,
    h: &OMatrix<f64, M, N>,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (m, n) = h.shape();
    assert_shape("standard_update: P", p.shape(), (n, n));
    assert_shape("standard_update: K", k.shape(), (n, m));
    if let Some(par) = backend::route(p.shape_generic().0, h.shape_generic().0) {
        return backend::standard_update(p, k, h, par);
    }
    let mut out = p - k * (h * p);
    symmetrize(&mut out);
    out
}

/// Checks that every entry of `m` is finite.
///
/// # Errors
/// [`LinalgError::NonFinite`] naming `what`.
#[inline]
pub fn check_finite<R: Dim, C: Dim, S: RawStorage<f64, R, C> + IsContiguous>(
    m: &Matrix<f64, R, C, S>,
    what: &'static str,
) -> Result<(), LinalgError> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(LinalgError::NonFinite { what })
    }
}

/// Whether every entry of `m` is finite. A non-short-circuiting `&` reduction over the
/// contiguous storage: it has no data-dependent branches and vectorises, and filters run it
/// on every matrix of every step, where nalgebra's strided iterator costs more per entry
/// (`cargo xtask bench w1`).
#[inline]
pub fn all_finite<R: Dim, C: Dim, S: RawStorage<f64, R, C> + IsContiguous>(
    m: &Matrix<f64, R, C, S>,
) -> bool {
    m.as_slice().iter().fold(true, |ok, v| ok & v.is_finite())
}

/// Checks a run-time dimension (the boundary where `Dyn` sizes meet).
///
/// # Errors
/// [`LinalgError::DimensionMismatch`] if `found != expected`.
#[inline]
pub fn check_dim(expected: usize, found: usize, what: &'static str) -> Result<(), LinalgError> {
    if expected == found {
        Ok(())
    } else {
        Err(LinalgError::DimensionMismatch {
            what,
            expected,
            found,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Matrix2, Matrix4, SMatrix};
    use approx::assert_relative_eq;

    #[test]
    fn joseph_equals_standard_at_the_optimal_gain() {
        let p = Matrix4::new(
            4.0, 1.0, 0.5, 0.0, 1.0, 3.0, 0.2, 0.1, 0.5, 0.2, 2.0, 0.3, 0.0, 0.1, 0.3, 1.0,
        );
        let h = SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        let r = Matrix2::new(0.5, 0.1, 0.1, 0.7);
        let s = propagate(&h, &p) + r;
        let k = p * h.transpose() * s.try_inverse().unwrap();
        assert_relative_eq!(
            joseph_update(&p, &k, &h, &r),
            standard_update(&p, &k, &h),
            epsilon = 1e-12
        );
    }

    /// Entries spread over many binades and both signs (with zeros, signed zeros and
    /// infinities among them), from a 64-bit linear congruential sequence.
    fn entries<R: Dim, C: Dim>(seed: u64, r: R, c: C) -> OMatrix<f64, R, C>
    where
        DefaultAllocator: Allocator<R, C>,
    {
        let mut state = seed;
        OMatrix::from_fn_generic(r, c, |_, _| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            match state >> 60 {
                0 => 0.0,
                1 => -0.0,
                2 if seed % 2 == 1 => f64::INFINITY,
                _ => {
                    let mantissa = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                    mantissa * f64::powi(2.0, ((state >> 4) % 40) as i32 - 20)
                }
            }
        })
    }

    /// The bits of every entry, NaN as one pattern (its payload is not part of the promise).
    fn bits<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> Vec<u64>
    where
        DefaultAllocator: Allocator<R, C>,
    {
        m.iter()
            .map(|v| if v.is_nan() { u64::MAX } else { v.to_bits() })
            .collect()
    }

    /// The written-out fixed-size products give nalgebra's bits, so that the filters' numbers
    /// do not depend on which of the two computed them.
    fn fixed_products_are_nalgebras<const R: usize, const K: usize, const C: usize>() {
        use nalgebra::Const;
        for seed in 0..64 {
            let a = entries(seed, Const::<R>, Const::<K>);
            let b = entries(seed + 1000, Const::<K>, Const::<C>);
            let bt = b.transpose();
            let p = entries(seed + 2000, Const::<K>, Const::<K>);
            assert_eq!(bits(&product(&a, &b)), bits(&(a * b)), "a b, seed {seed}");
            assert_eq!(
                bits(&product_transpose(&a, &bt)),
                bits(&(a * b)),
                "a b^T, seed {seed}"
            );
            assert_eq!(
                bits(&propagate(&a, &p)),
                bits(&(a * p * a.transpose())),
                "a p a^T, seed {seed}"
            );
        }
    }

    /// The written-out solve gives nalgebra's bits, on factors of `A A^T + I` (positive
    /// definite) and right-hand sides with signed zeros and infinities.
    fn fixed_solves_are_nalgebras<const R: usize, const N: usize>() {
        use nalgebra::Const;
        for seed in 0..64 {
            let a = entries(2 * seed, Const::<N>, Const::<N>);
            let c = a * a.transpose() + OMatrix::<f64, Const<N>, Const<N>>::identity();
            let Some(chol) = c.cholesky() else {
                continue;
            };
            let b = entries(seed + 3000, Const::<R>, Const::<N>);
            assert_eq!(
                bits(&cholesky_solve_right(&chol, &b)),
                bits(&chol.solve(&b.transpose()).transpose()),
                "seed {seed}"
            );
        }
    }

    #[test]
    fn fixed_solves_equal_nalgebras_to_the_bit() {
        fixed_solves_are_nalgebras::<4, 4>();
        fixed_solves_are_nalgebras::<4, 2>();
        fixed_solves_are_nalgebras::<1, 1>();
        fixed_solves_are_nalgebras::<3, 5>();
        fixed_solves_are_nalgebras::<2, 8>();
        fixed_solves_are_nalgebras::<8, 3>();
        fixed_solves_are_nalgebras::<9, 2>();
    }

    #[test]
    fn fixed_products_equal_nalgebras_to_the_bit() {
        fixed_products_are_nalgebras::<4, 4, 4>();
        fixed_products_are_nalgebras::<2, 4, 4>();
        fixed_products_are_nalgebras::<4, 2, 1>();
        fixed_products_are_nalgebras::<3, 5, 2>();
        fixed_products_are_nalgebras::<1, 1, 1>();
        fixed_products_are_nalgebras::<6, 3, 6>();
    }

    #[test]
    fn symmetrize_averages_triangles() {
        let mut m = Matrix2::new(1.0, 2.0, 4.0, 1.0);
        symmetrize(&mut m);
        assert_eq!(m, Matrix2::new(1.0, 3.0, 3.0, 1.0));
    }
}
