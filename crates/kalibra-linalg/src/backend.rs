//! Where the kernels choose between nalgebra's code and faer's, and faer's side of them.
//!
//! Every kernel of this crate that carries the cost of a large filter step ([`propagate`],
//! [`product`], [`innovation_covariance`], [`joseph_update`], [`standard_update`], the
//! Cholesky factorisations behind [`Covariance`], [`quad_form_symmetric`] and [`sigma_sqrt`],
//! the solves with a matrix right-hand side [`Covariance::solve`],
//! [`Covariance::solve_right`] and [`cholesky_solve_right`], the products of [`discrete_lyapunov`] and
//! [`spectral_radius`], and the UKF's sums [`add_scatter`] and [`add_cross_scatter`]) asks
//! `route` once which code to run. Solves with one vector (the quadratic forms after their
//! factorisation) stay with nalgebra: `O(n^2)` work that faer does not speed up measurably.
//!
//! Fixed sizes (every dimension a `Const`) never leave nalgebra: the test is on the types, so
//! the compiler removes the faer branch and the fixed-size code is what it was before faer
//! came in. A `Dyn` kernel whose largest dimension is at least the policy's threshold
//! ([`FAER_MIN_DIM`] unless the calling thread chose another [`KernelPolicy`]) runs faer's
//! blocked, vectorised products and Cholesky factorisation on views of nalgebra's
//! column-major storage: no copy in or out, and nalgebra types at every interface.
//!
//! faer's side exploits what the filter algebra knows: a product whose result is symmetric
//! (`A P A^T` with a symmetric `P`, `H P H^T + R`, the Joseph form, the sigma-point scatter)
//! computes only its lower triangle and mirrors it, which saves a third of `A P A^T`'s work;
//! the Joseph form is re-associated so that every product has `m` as a dimension
//! (`joseph_update` below); the Cholesky scratch faer needs lives in a per-thread buffer
//! reused from call to call, so a kernel allocates no more than its nalgebra twin (fewer:
//! nalgebra's `a.transpose()` operands are copies, faer's are views).
//!
//! [`propagate`]: crate::propagate
//! [`product`]: crate::product
//! [`innovation_covariance`]: crate::innovation_covariance
//! [`Covariance::solve`]: crate::Covariance::solve
//! [`Covariance::solve_right`]: crate::Covariance::solve_right
//! [`cholesky_solve_right`]: crate::cholesky_solve_right
//! [`Covariance`]: crate::Covariance
//! [`joseph_update`]: crate::joseph_update
//! [`standard_update`]: crate::standard_update
//! [`quad_form_symmetric`]: crate::quad_form_symmetric
//! [`sigma_sqrt`]: crate::sigma_sqrt
//! [`discrete_lyapunov`]: crate::discrete_lyapunov
//! [`spectral_radius`]: crate::spectral_radius
//! [`add_scatter`]: crate::add_scatter
//! [`add_cross_scatter`]: crate::add_cross_scatter

use std::cell::{Cell, RefCell};
use std::mem::MaybeUninit;
use std::num::NonZeroUsize;

use faer::dyn_stack::MemStack;
use faer::linalg::cholesky::llt::factor::{
    LltRegularization, cholesky_in_place, cholesky_in_place_scratch,
};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::allocator::Allocator;
use nalgebra::linalg::Cholesky;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The smallest `Dyn` dimension that the kernels hand to faer by default: the largest
/// dimension of a kernel's operands (`n` for a state covariance, `m` for the factor of `S`)
/// must reach it.
///
/// The size from which faer's Kalman step is clearly faster than nalgebra's, its margin
/// growing with `n` (`cargo xtask bench w4 --kernels`: one Kalman step with dense `F`,
/// `m = max(2, n / 4)`, one thread). Below the threshold the results are nalgebra's to the
/// bit.
pub const FAER_MIN_DIM: usize = 12;

/// The smallest dimension at which a [`KernelPolicy::with_threads`] policy runs faer's
/// products and factorisations on several threads; below it one step is too short to share.
pub const PARALLEL_MIN_DIM: usize = 512;

/// Which code the `Dyn` kernels of this crate run on the calling thread: nalgebra's, or faer's
/// from a threshold dimension on, on one thread or several.
///
/// The default ([`KernelPolicy::DEFAULT`]) hands a kernel to faer when its largest dimension
/// is at least [`FAER_MIN_DIM`], on the calling thread only. Fixed sizes always run nalgebra,
/// whatever the policy. A policy is set for a scope with [`with_kernel_policy`] and holds on
/// the thread that set it: work that thread hands to others (a Monte Carlo study's rayon
/// workers) runs the default, which keeps a study's results independent of its thread count.
///
/// ```
/// use kalibra_linalg::{KernelPolicy, propagate, with_kernel_policy, DMatrix};
/// let a = DMatrix::<f64>::from_fn(40, 40, |i, j| if i == j { 0.5 } else { 0.01 });
/// let p = DMatrix::<f64>::identity(40, 40);
/// let faer = propagate(&a, &p);
/// let nalgebra = with_kernel_policy(KernelPolicy::NALGEBRA, || propagate(&a, &p));
/// assert!((faer - nalgebra).norm() < 1e-14);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KernelPolicy {
    faer_min_dim: usize,
    threads: NonZeroUsize,
}

impl KernelPolicy {
    /// faer from [`FAER_MIN_DIM`] on, one thread.
    pub const DEFAULT: Self = Self::faer_from(FAER_MIN_DIM);

    /// nalgebra at every size: the code the kernels ran before faer came in.
    pub const NALGEBRA: Self = Self::faer_from(usize::MAX);

    /// faer for every `Dyn` kernel whose largest dimension is at least `min_dim`, one thread.
    pub const fn faer_from(min_dim: usize) -> Self {
        Self {
            faer_min_dim: min_dim,
            threads: NonZeroUsize::MIN,
        }
    }

    /// The same policy, with faer running on up to `threads` threads of rayon's global pool
    /// for kernels of dimension [`PARALLEL_MIN_DIM`] and more (within one filter step). Off
    /// by default: Monte Carlo studies already keep every core busy with whole runs.
    ///
    /// Results do not depend on `threads`: faer splits a matrix product's output between
    /// threads, each entry summed whole on one of them, and the kernels run products and
    /// solves with a vector output (where faer would split the sum) on one thread. A test
    /// checks it to the bit on 1, 2 and 4 threads.
    pub const fn with_threads(self, threads: NonZeroUsize) -> Self {
        Self {
            faer_min_dim: self.faer_min_dim,
            threads,
        }
    }

    /// The smallest `Dyn` dimension handed to faer (`usize::MAX`: never).
    pub const fn faer_min_dim(&self) -> usize {
        self.faer_min_dim
    }

    /// The most threads one kernel may use.
    pub const fn threads(&self) -> NonZeroUsize {
        self.threads
    }
}

impl Default for KernelPolicy {
    fn default() -> Self {
        Self::DEFAULT
    }
}

thread_local! {
    static POLICY: Cell<KernelPolicy> = const { Cell::new(KernelPolicy::DEFAULT) };
    /// faer's Cholesky scratch (one column of the dimension), grown on demand and kept, so a
    /// factorisation per step allocates nothing after the first.
    static SCRATCH: RefCell<Vec<MaybeUninit<u8>>> = const { RefCell::new(Vec::new()) };
}

/// The policy of the calling thread.
pub fn kernel_policy() -> KernelPolicy {
    POLICY.with(Cell::get)
}

/// Runs `f` with `policy` on the calling thread and restores the previous policy afterwards
/// (also when `f` panics).
///
/// ```
/// use kalibra_linalg::{KernelPolicy, kernel_policy, with_kernel_policy};
/// let inside = with_kernel_policy(KernelPolicy::NALGEBRA, kernel_policy);
/// assert_eq!(inside, KernelPolicy::NALGEBRA);
/// assert_eq!(kernel_policy(), KernelPolicy::DEFAULT);
/// ```
pub fn with_kernel_policy<T>(policy: KernelPolicy, f: impl FnOnce() -> T) -> T {
    struct Restore(KernelPolicy);
    impl Drop for Restore {
        fn drop(&mut self) {
            POLICY.with(|p| p.set(self.0));
        }
    }
    let _restore = Restore(POLICY.with(|p| p.replace(policy)));
    f()
}

/// The one decision: `None` to run nalgebra, `Some(par)` to run faer with `par`, for a kernel
/// whose operands have the dimensions `a` and `b` (the two distinct sizes of its operands).
#[inline(always)]
pub(crate) fn route<A: Dim, B: Dim>(a: A, b: B) -> Option<Par> {
    route3(a, b, b)
}

/// [`route`] for a kernel with three distinct dimensions (a product `r x k` by `k x c`).
#[inline(always)]
pub(crate) fn route3<A: Dim, B: Dim, C: Dim>(a: A, b: B, c: C) -> Option<Par> {
    // Known at compile time: the fixed-size kernels keep nalgebra's code and nothing else.
    if A::try_to_usize().is_some() && B::try_to_usize().is_some() && C::try_to_usize().is_some() {
        return None;
    }
    let size = a.value().max(b.value()).max(c.value());
    let policy = kernel_policy();
    if size < policy.faer_min_dim {
        return None;
    }
    let threads = policy.threads.get();
    if threads > 1 && size >= PARALLEL_MIN_DIM {
        Some(Par::Rayon(policy.threads))
    } else {
        Some(Par::Seq)
    }
}

/// A faer view of a nalgebra matrix's column-major storage.
#[inline]
fn view<R: Dim, C: Dim>(m: &OMatrix<f64, R, C>) -> MatRef<'_, f64>
where
    DefaultAllocator: Allocator<R, C>,
{
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// A mutable faer view of a nalgebra matrix's column-major storage.
#[inline]
fn view_mut<R: Dim, C: Dim>(m: &mut OMatrix<f64, R, C>) -> MatMut<'_, f64>
where
    DefaultAllocator: Allocator<R, C>,
{
    let (r, c) = m.shape();
    MatMut::from_column_major_slice_mut(m.as_mut_slice(), r, c)
}

/// Side of the square tiles in which the triangle-pair loops below walk a matrix: the strided
/// side of each pair of tiles (a row of the upper one) then stays in cache, where a plain
/// column-by-column loop touches a new cache line per entry.
const TILE: usize = 16;

/// Calls `f(lower, upper)` with the column-major offsets of `(i, j)` and `(j, i)` for every
/// `i > j` of an `n` x `n` matrix, tile by tile.
#[inline(always)]
fn for_each_pair(n: usize, mut f: impl FnMut(usize, usize)) {
    for jb in (0..n).step_by(TILE) {
        for ib in (jb..n).step_by(TILE) {
            for i in ib..(ib + TILE).min(n) {
                for j in jb..(jb + TILE).min(n).min(i) {
                    f(i + j * n, j + i * n);
                }
            }
        }
    }
}

/// Whether a square matrix equals its transpose exactly (a filter's own covariances do,
/// after `symmetrize`). `n^2 / 2` comparisons, nothing beside a product's `n^3`.
fn is_exactly_symmetric<D: Dim>(m: &OMatrix<f64, D, D>) -> bool
where
    DefaultAllocator: Allocator<D, D>,
{
    let s = m.as_slice();
    let mut exact = true;
    for_each_pair(m.nrows(), |lo, up| exact &= s[lo] == s[up]);
    exact
}

/// Copies the strict lower triangle onto the upper one.
fn mirror_lower<D: Dim>(m: &mut OMatrix<f64, D, D>)
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let s = m.as_mut_slice();
    for_each_pair(n, |lo, up| s[up] = s[lo]);
}

/// `(m + m^T) / 2` for an `n` x `n` matrix in column-major order, tile by tile.
pub(crate) fn symmetrize_slice(s: &mut [f64], n: usize) {
    for_each_pair(n, |lo, up| {
        let mean = 0.5 * (s[lo] + s[up]);
        s[lo] = mean;
        s[up] = mean;
    });
}

/// `par` for a product or solve whose output is `rows` x `cols`: sequential for a vector
/// output. faer splits a matrix-vector product's sum between threads (each adds a share of the
/// columns, then the shares are added), which would make its bits depend on the thread count;
/// a matrix output it splits by blocks of the output, each summed whole on one thread.
fn par_for(par: Par, rows: usize, cols: usize) -> Par {
    if rows <= 1 || cols <= 1 {
        Par::Seq
    } else {
        par
    }
}

/// `dst = [dst +] alpha lhs * rhs` (faer's `matmul`, with [`par_for`]).
fn mul(
    dst: MatMut<'_, f64>,
    accum: Accum,
    lhs: MatRef<'_, f64>,
    rhs: MatRef<'_, f64>,
    alpha: f64,
    par: Par,
) {
    let par = par_for(par, dst.nrows(), dst.ncols());
    matmul(dst, accum, lhs, rhs, alpha, par);
}

/// `dst` (lower triangle) `= [dst +] lhs * rhs`, the upper triangle untouched.
fn lower_product(
    dst: MatMut<'_, f64>,
    accum: Accum,
    lhs: MatRef<'_, f64>,
    rhs: MatRef<'_, f64>,
    par: Par,
) {
    let par = par_for(par, dst.nrows(), dst.ncols());
    triangular::matmul(
        dst,
        BlockStructure::TriangularLower,
        accum,
        lhs,
        BlockStructure::Rectangular,
        rhs,
        BlockStructure::Rectangular,
        1.0,
        par,
    );
}

/// `a * b`.
pub(crate) fn product<R: Dim, K: Dim, C: Dim>(
    a: &OMatrix<f64, R, K>,
    b: &OMatrix<f64, K, C>,
    par: Par,
) -> OMatrix<f64, R, C>
where
    DefaultAllocator: Allocator<R, K> + Allocator<K, C> + Allocator<R, C>,
{
    let mut out = OMatrix::<f64, R, C>::zeros_generic(a.shape_generic().0, b.shape_generic().1);
    mul(
        view_mut(&mut out),
        Accum::Replace,
        view(a),
        view(b),
        1.0,
        par,
    );
    out
}

/// `A P A^T`: `A P` in full, then only the lower triangle of `(A P) A^T` when `P` is exactly
/// symmetric (the result then is too), mirrored.
pub(crate) fn propagate<R: Dim, N: Dim>(
    a: &OMatrix<f64, R, N>,
    p: &OMatrix<f64, N, N>,
    par: Par,
) -> OMatrix<f64, R, R>
where
    DefaultAllocator: Allocator<R, N> + Allocator<N, R> + Allocator<R, R> + Allocator<N, N>,
{
    let r = a.shape_generic().0;
    let ap = product(a, p, par);
    let mut out = OMatrix::<f64, R, R>::zeros_generic(r, r);
    if is_exactly_symmetric(p) {
        lower_product(
            view_mut(&mut out),
            Accum::Replace,
            view(&ap),
            view(a).transpose(),
            par,
        );
        mirror_lower(&mut out);
    } else {
        mul(
            view_mut(&mut out),
            Accum::Replace,
            view(&ap),
            view(a).transpose(),
            1.0,
            par,
        );
    }
    out
}

/// `(P H^T, H P H^T + R)`, the second exactly symmetric: its lower triangle plus the
/// symmetric part of `R`, mirrored (what symmetrising the full sum gives, to rounding).
pub(crate) fn innovation_covariance<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    h: &OMatrix<f64, M, N>,
    r: &OMatrix<f64, M, M>,
    par: Par,
) -> (OMatrix<f64, N, M>, OMatrix<f64, M, M>)
where
    DefaultAllocator: Allocator<N, N> + Allocator<M, N> + Allocator<N, M> + Allocator<M, M>,
{
    let (m, n) = h.shape_generic();
    let mut pht = OMatrix::<f64, N, M>::zeros_generic(n, m);
    mul(
        view_mut(&mut pht),
        Accum::Replace,
        view(p),
        view(h).transpose(),
        1.0,
        par,
    );
    let mut s = OMatrix::<f64, M, M>::zeros_generic(m, m);
    lower_product(view_mut(&mut s), Accum::Replace, view(h), view(&pht), par);
    let mm = m.value();
    let (rs, ss) = (r.as_slice(), s.as_mut_slice());
    for j in 0..mm {
        for i in j..mm {
            let v = ss[i + j * mm] + 0.5 * (rs[i + j * mm] + rs[j + i * mm]);
            ss[i + j * mm] = v;
            ss[j + i * mm] = v;
        }
    }
    (pht, s)
}

/// The symmetric part `(m + m^T) / 2` of a square matrix, or `m` itself when it is exactly
/// symmetric already.
fn symmetric_part<D: Dim>(m: &OMatrix<f64, D, D>) -> std::borrow::Cow<'_, OMatrix<f64, D, D>>
where
    DefaultAllocator: Allocator<D, D>,
{
    if is_exactly_symmetric(m) {
        std::borrow::Cow::Borrowed(m)
    } else {
        let mut s = m.clone();
        symmetrize_slice(s.as_mut_slice(), m.nrows());
        std::borrow::Cow::Owned(s)
    }
}

/// The Joseph form `(I - K H) P (I - K H)^T + K R K^T`, exactly symmetric: the symmetric
/// parts of `P` and `R` stand in for them (what symmetrising nalgebra's full result gives, to
/// rounding), and only the lower triangle is computed, then mirrored.
///
/// With `A = I - K H` and `m` measurements beside `n` states, forming `A` and then `(A P) A^T`
/// costs `3 n^3 + 3 n^2 m` flops. The same products re-associated, `T = A P = P - K (H P)` and
/// `T A^T + K R K^T = T - (T H^T - K R) K^T`, cost `7 n^2 m + 2 n m^2`: every product has `m`
/// as one dimension. That is cheaper while `m < 0.6 n` (`n^3` against `3.9 n^3` at
/// `m = n / 4`), and the kernel picks the cheaper association. Both evaluate the same
/// expression, with rounding errors of the same order (`eps |K| |H| |P|` per entry).
pub(crate) fn joseph_update<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    k: &OMatrix<f64, N, M>,
    h: &OMatrix<f64, M, N>,
    r: &OMatrix<f64, M, M>,
    par: Par,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Allocator<N, N> + Allocator<M, N> + Allocator<N, M> + Allocator<M, M>,
{
    let (n, m) = k.shape_generic();
    let p = symmetric_part(p);
    let r = symmetric_part(r);
    let mut kr = OMatrix::<f64, N, M>::zeros_generic(n, m);
    if 5 * m.value() < 3 * n.value() {
        // T = P - K (H P).
        let hp = product(h, &p, par);
        let mut t = p.into_owned();
        mul(view_mut(&mut t), Accum::Add, view(k), view(&hp), -1.0, par);
        // W = T H^T - K R; the result is T - W K^T.
        mul(
            view_mut(&mut kr),
            Accum::Replace,
            view(k),
            view(&r),
            -1.0,
            par,
        );
        mul(
            view_mut(&mut kr),
            Accum::Add,
            view(&t),
            view(h).transpose(),
            1.0,
            par,
        );
        let w = kr;
        let (rows, cols) = (t.nrows(), t.ncols());
        triangular::matmul(
            view_mut(&mut t),
            BlockStructure::TriangularLower,
            Accum::Add,
            view(&w),
            BlockStructure::Rectangular,
            view(k).transpose(),
            BlockStructure::Rectangular,
            -1.0,
            par_for(par, rows, cols),
        );
        // Above the diagonal `t` still holds T, whose upper triangle is not the result's.
        mirror_lower(&mut t);
        return t;
    }
    let mut ikh = OMatrix::<f64, N, N>::zeros_generic(n, n);
    mul(
        view_mut(&mut ikh),
        Accum::Replace,
        view(k),
        view(h),
        -1.0,
        par,
    );
    for i in 0..n.value() {
        ikh[(i, i)] += 1.0;
    }
    let ikh_p = product(&ikh, &p, par);
    mul(
        view_mut(&mut kr),
        Accum::Replace,
        view(k),
        view(&r),
        1.0,
        par,
    );
    let mut out = OMatrix::<f64, N, N>::zeros_generic(n, n);
    lower_product(
        view_mut(&mut out),
        Accum::Replace,
        view(&ikh_p),
        view(&ikh).transpose(),
        par,
    );
    lower_product(
        view_mut(&mut out),
        Accum::Add,
        view(&kr),
        view(k).transpose(),
        par,
    );
    mirror_lower(&mut out);
    out
}

/// The standard form `P - K (H P)`, symmetrised.
pub(crate) fn standard_update<N: Dim, M: Dim>(
    p: &OMatrix<f64, N, N>,
    k: &OMatrix<f64, N, M>,
    h: &OMatrix<f64, M, N>,
    par: Par,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Allocator<N, N> + Allocator<M, N> + Allocator<N, M> + Allocator<M, M>,
{
    let hp = product(h, p, par);
    let mut out = p.clone();
    mul(
        view_mut(&mut out),
        Accum::Add,
        view(k),
        view(&hp),
        -1.0,
        par,
    );
    let n = out.nrows();
    symmetrize_slice(out.as_mut_slice(), n);
    out
}

/// `acc += w sum_j (x_j - c)(x_j - c)^T`: the deviations packed into one faer matrix, the
/// lower triangle of `w D D^T` in one product, added to both triangles of `acc`.
pub(crate) fn add_scatter<D: Dim>(
    acc: &mut OMatrix<f64, D, D>,
    points: &[OVector<f64, D>],
    center: &OVector<f64, D>,
    weight: f64,
    par: Par,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    let n = center.nrows();
    assert_eq!(acc.nrows(), n, "scatter and accumulator differ in size");
    let c = center.as_slice();
    let mut d = faer::Mat::<f64>::zeros(n, points.len());
    for (j, x) in points.iter().enumerate() {
        assert_eq!(x.nrows(), n, "a sigma point differs in size");
        for (i, (xi, ci)) in x.as_slice().iter().zip(c).enumerate() {
            d[(i, j)] = xi - ci;
        }
    }
    let mut s = faer::Mat::<f64>::zeros(n, n);
    let par = par_for(par, n, n);
    triangular::matmul(
        s.as_mut(),
        BlockStructure::TriangularLower,
        Accum::Replace,
        d.as_ref(),
        BlockStructure::Rectangular,
        d.as_ref().transpose(),
        BlockStructure::Rectangular,
        weight,
        par,
    );
    let a = acc.as_mut_slice();
    for j in 0..n {
        a[j + j * n] += s[(j, j)];
        for i in (j + 1)..n {
            a[i + j * n] += s[(i, j)];
            a[j + i * n] += s[(i, j)];
        }
    }
}

/// `acc += w A (U - V)^T` in one faer product.
pub(crate) fn add_cross_scatter<N: Dim, M: Dim>(
    acc: &mut OMatrix<f64, N, M>,
    a: &OMatrix<f64, N, N>,
    plus: &[OVector<f64, M>],
    minus: &[OVector<f64, M>],
    weight: f64,
    par: Par,
) where
    DefaultAllocator: Allocator<N, N> + Allocator<N, M> + Allocator<M>,
{
    let m = acc.ncols();
    let mut dt = faer::Mat::<f64>::zeros(a.ncols(), m);
    for (j, (u, v)) in plus.iter().zip(minus).enumerate() {
        assert!(
            u.nrows() == m && v.nrows() == m,
            "a sigma measurement differs in size"
        );
        for (i, (ui, vi)) in u.as_slice().iter().zip(v.as_slice()).enumerate() {
            dt[(j, i)] = ui - vi;
        }
    }
    mul(view_mut(acc), Accum::Add, view(a), dt.as_ref(), weight, par);
}

/// The Cholesky factorisation of the lower triangle of `m` in place, as nalgebra's
/// `Cholesky` (its upper triangle keeps `m`'s, which nalgebra's factor ignores too). `None`
/// for a non-positive (or NaN) pivot.
pub(crate) fn cholesky<D: Dim>(mut m: OMatrix<f64, D, D>, par: Par) -> Option<Cholesky<f64, D>>
where
    DefaultAllocator: Allocator<D, D>,
{
    let n = m.nrows();
    let req = cholesky_in_place_scratch::<f64>(n, par, Default::default());
    let factored = SCRATCH.with(|scratch| {
        let mut scratch = scratch.borrow_mut();
        let bytes = req.unaligned_bytes_required();
        if scratch.len() < bytes {
            scratch.resize(bytes, MaybeUninit::uninit());
        }
        cholesky_in_place(
            view_mut(&mut m),
            LltRegularization::default(),
            par,
            MemStack::new(&mut scratch[..bytes]),
            Default::default(),
        )
    });
    factored.ok().map(|_| Cholesky::pack_dirty(m))
}

/// `C^-1 B` in place, with `l` holding `C`'s factor in its lower triangle.
pub(crate) fn cholesky_solve_in_place<D: Dim, C: Dim>(
    l: &OMatrix<f64, D, D>,
    b: &mut OMatrix<f64, D, C>,
    par: Par,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<D, C>,
{
    let par = par_for(par, b.nrows(), b.ncols());
    let mut x = view_mut(b);
    solve_lower_triangular_in_place(view(l), x.as_mut(), par);
    solve_upper_triangular_in_place(view(l).transpose(), x, par);
}

/// `B C^-1` in place (a solve on the transposed view), with `l` holding `C`'s factor.
pub(crate) fn cholesky_solve_right_in_place<R: Dim, D: Dim>(
    l: &OMatrix<f64, D, D>,
    b: &mut OMatrix<f64, R, D>,
    par: Par,
) where
    DefaultAllocator: Allocator<D, D> + Allocator<R, D>,
{
    let par = par_for(par, b.nrows(), b.ncols());
    let mut xt = view_mut(b).transpose_mut();
    solve_lower_triangular_in_place(view(l), xt.as_mut(), par);
    solve_upper_triangular_in_place(view(l).transpose(), xt, par);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        Covariance, DMatrix, DVector, Dyn, LinalgError, discrete_lyapunov, innovation_covariance,
        product, propagate, quad_form_symmetric, sigma_sqrt, spectral_radius, standard_update,
    };
    use nalgebra::Const;

    /// Deterministic entries in (-1, 1) without a random-number crate: a hash of the position
    /// and a seed through an integer mixer.
    fn entries(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
        DMatrix::from_fn(rows, cols, |i, j| {
            let mut x = (i as u64) << 32 ^ (j as u64) ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15);
            x ^= x >> 33;
            x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
            x ^= x >> 33;
            x = x.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
            x ^= x >> 33;
            (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        })
    }

    fn spd(n: usize, seed: u64) -> DMatrix<f64> {
        let a = entries(n, n, seed);
        let s = &a * a.transpose() / n as f64 + DMatrix::identity(n, n) * 0.5;
        (&s + s.transpose()) * 0.5
    }

    fn on<T>(policy: KernelPolicy, f: impl FnOnce() -> T) -> T {
        with_kernel_policy(policy, f)
    }

    const FAER: KernelPolicy = KernelPolicy::faer_from(0);

    /// `|a - b| <= tol |b|` in the Frobenius norm.
    fn close(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) -> bool {
        (a - b).norm() <= tol * b.norm()
    }

    #[test]
    fn every_kernel_agrees_with_nalgebra() {
        for (n, m) in [(12, 3), (13, 2), (13, 12), (31, 8), (40, 40), (40, 23)] {
            let seed = (n * 100 + m) as u64;
            let a = entries(n, n, seed);
            let p = spd(n, seed + 1);
            let h = entries(m, n, seed + 2);
            let r = spd(m, seed + 3);
            let both = |f: &dyn Fn() -> DMatrix<f64>| (on(FAER, f), on(KernelPolicy::NALGEBRA, f));
            let check = |what: &str, (x, y): (DMatrix<f64>, DMatrix<f64>)| {
                assert!(
                    close(&x, &y, 1e-13),
                    "{what} at n = {n}, m = {m}: {}",
                    (&x - &y).norm()
                );
            };
            check("A P A^T", both(&|| propagate(&a, &p)));
            check("A A A^T (not symmetric)", both(&|| propagate(&a, &a)));
            check("H P H^T", both(&|| propagate(&h, &p)));
            check("P H^T", both(&|| innovation_covariance(&p, &h, &r).0));
            check("S", both(&|| innovation_covariance(&p, &h, &r).1));
            check("A A", both(&|| product(&a, &a)));
            let s = innovation_covariance(&p, &h, &r).1;
            let pht = &p * h.transpose();
            let gain = |policy| {
                on(policy, || {
                    let s = Covariance::from_symmetric(s.clone(), "S").unwrap();
                    s.solve_right(&pht).unwrap()
                })
            };
            let (kf, kn) = (gain(FAER), gain(KernelPolicy::NALGEBRA));
            check("K", (kf.clone(), kn));
            // Any gain, not only the optimal one: the Joseph form is exact algebra for all.
            let k = &kf * 0.7;
            check("Joseph", both(&|| crate::joseph_update(&p, &k, &h, &r)));
            check("standard", both(&|| standard_update(&p, &k, &h)));
            check(
                "L",
                both(&|| Covariance::from_symmetric(p.clone(), "P").unwrap().factor()),
            );
            check("sigma sqrt", both(&|| sigma_sqrt(&p, "P").unwrap().0));
            check(
                "C^-1 A",
                both(&|| Covariance::new(p.clone()).unwrap().solve(&a).unwrap()),
            );
            let v: DVector<f64> = entries(n, 1, seed + 4).column(0).into_owned();
            let quad = |policy| {
                on(policy, || {
                    let c = Covariance::new(p.clone()).unwrap();
                    let once = quad_form_symmetric(&p, &v, "P").unwrap();
                    (c.quad_form(&v).unwrap(), once)
                })
            };
            let ((f1, f2), (n1, n2)) = (quad(FAER), quad(KernelPolicy::NALGEBRA));
            assert!((f1 - n1).abs() <= 1e-13 * n1 && (f2 - n2).abs() <= 1e-13 * n2);
            let points: Vec<DVector<f64>> = (0..2 * n)
                .map(|j| entries(n, 1, seed + 10 + j as u64).column(0).into_owned())
                .collect();
            let center: DVector<f64> = entries(n, 1, seed + 5).column(0).into_owned();
            check(
                "scatter",
                both(&|| {
                    let mut acc = p.clone();
                    crate::add_scatter(&mut acc, &points, &center, 0.3);
                    acc
                }),
            );
            let (plus, minus): (Vec<DVector<f64>>, Vec<DVector<f64>>) = (0..n)
                .map(|j| {
                    let u = entries(m, 1, seed + 900 + j as u64).column(0).into_owned();
                    (
                        u,
                        entries(m, 1, seed + 700 + j as u64).column(0).into_owned(),
                    )
                })
                .unzip();
            check(
                "cross scatter",
                both(&|| {
                    let mut acc = pht.clone();
                    crate::add_cross_scatter(&mut acc, &a, &plus, &minus, 0.7);
                    acc
                }),
            );
            let stable = &a * (0.9 / spectral_radius(&a).unwrap());
            check(
                "Lyapunov",
                both(&|| discrete_lyapunov(&stable, &p).unwrap()),
            );
            let (rf, rn) = (
                on(FAER, || spectral_radius(&a).unwrap()),
                on(KernelPolicy::NALGEBRA, || spectral_radius(&a).unwrap()),
            );
            assert!((rf - rn).abs() <= 1e-12 * rn);
        }
    }

    #[test]
    fn symmetric_outputs_are_exactly_symmetric() {
        let (n, m) = (40, 10);
        let p = spd(n, 1);
        let h = entries(m, n, 2);
        let r = spd(m, 3);
        let k = entries(n, m, 4) * 0.1;
        on(FAER, || {
            for x in [
                propagate(&entries(n, n, 5), &p),
                innovation_covariance(&p, &h, &r).1,
                crate::joseph_update(&p, &k, &h, &r),
                crate::joseph_update(&p, &entries(n, n, 6), &entries(n, n, 7), &spd(n, 8)),
            ] {
                assert_eq!(x, x.transpose());
            }
        });
    }

    #[test]
    fn fixed_sizes_never_reach_faer_and_dyn_sizes_follow_the_policy() {
        on(FAER, || {
            assert_eq!(route(Const::<40>, Const::<40>), None);
            assert_eq!(route(Dyn(2), Const::<2>), Some(Par::Seq));
        });
        assert_eq!(route(Dyn(FAER_MIN_DIM - 1), Dyn(2)), None);
        assert_eq!(route(Dyn(FAER_MIN_DIM), Dyn(2)), Some(Par::Seq));
        on(KernelPolicy::NALGEBRA, || {
            assert_eq!(route(Dyn(100_000), Dyn(2)), None);
        });
        let threads = NonZeroUsize::new(3).unwrap();
        on(KernelPolicy::DEFAULT.with_threads(threads), || {
            assert_eq!(route(Dyn(PARALLEL_MIN_DIM - 1), Dyn(2)), Some(Par::Seq));
            assert_eq!(
                route(Dyn(PARALLEL_MIN_DIM), Dyn(2)),
                Some(Par::Rayon(threads))
            );
        });
    }

    #[test]
    fn a_policy_holds_for_its_scope_even_through_a_panic() {
        assert_eq!(kernel_policy(), KernelPolicy::DEFAULT);
        let inner = on(KernelPolicy::NALGEBRA, || on(FAER, kernel_policy));
        assert_eq!(inner, FAER);
        let caught = std::panic::catch_unwind(|| on(FAER, || panic!("inside")));
        assert!(caught.is_err());
        assert_eq!(kernel_policy(), KernelPolicy::DEFAULT);
        assert_eq!(KernelPolicy::default(), KernelPolicy::DEFAULT);
        assert_eq!(KernelPolicy::NALGEBRA.faer_min_dim(), usize::MAX);
        assert_eq!(KernelPolicy::DEFAULT.threads().get(), 1);
    }

    #[test]
    fn bad_matrices_are_errors_on_the_faer_path_too() {
        let n = 40;
        on(FAER, || {
            let mut indefinite = spd(n, 1);
            indefinite[(7, 7)] = -1.0;
            assert!(matches!(
                Covariance::from_symmetric(indefinite.clone(), "P"),
                Err(LinalgError::NotPositiveDefinite { .. })
            ));
            let v = DVector::from_element(n, 1.0);
            assert!(quad_form_symmetric(&indefinite, &v, "P").is_err());
            let mut nan = spd(n, 2);
            nan[(3, 3)] = f64::NAN;
            assert!(Covariance::from_symmetric(nan.clone(), "P").is_err());
            // The semi-definite fallback of the sigma points still sees the indefiniteness.
            assert!(sigma_sqrt(&indefinite, "P").is_err());
        });
    }

    #[test]
    fn the_factor_and_its_solves_read_only_the_lower_triangle() {
        let n = 40;
        let p = spd(n, 9);
        let mut dirty = p.clone();
        for j in 0..n {
            for i in 0..j {
                dirty[(i, j)] = f64::NAN;
            }
        }
        let l = cholesky(dirty, Par::Seq).expect("lower triangle is positive definite");
        let reference = nalgebra::linalg::Cholesky::new(p.clone()).unwrap();
        let mut b = entries(n, 3, 10);
        let expected = reference.solve(&b);
        cholesky_solve_in_place(l.l_dirty(), &mut b, Par::Seq);
        assert!(close(&b, &expected, 1e-13));
        let mut bt = entries(3, n, 11);
        let expected = reference.solve(&bt.transpose()).transpose();
        cholesky_solve_right_in_place(l.l_dirty(), &mut bt, Par::Seq);
        assert!(close(&bt, &expected, 1e-13));
    }

    #[test]
    fn tiles_cover_every_pair_once() {
        for n in [0, 1, 2, 15, 16, 17, 33] {
            let mut seen = vec![0u8; n * n];
            for_each_pair(n, |lo, up| {
                seen[lo] += 1;
                seen[up] += 1;
            });
            for j in 0..n {
                for i in 0..n {
                    assert_eq!(seen[i + j * n], u8::from(i != j), "n = {n}, ({i}, {j})");
                }
            }
        }
    }

    #[test]
    fn parallel_kernels_give_the_sequential_bits() {
        let n = PARALLEL_MIN_DIM;
        for m in [1, 2, n / 4] {
            parallel_case(n, m);
        }
        // Sizes that are no multiple of faer's blocks.
        parallel_case(n + 89, 3);
    }

    /// The kernels of a step at `n` states and `m` measurements on 1, 2 and 4 threads.
    fn parallel_case(n: usize, m: usize) {
        let (a, p) = (entries(n, n, 1) / (n as f64).sqrt(), spd(n, 2));
        let (h, r) = (entries(m, n, 3), spd(m, 4));
        let k = entries(n, m, 5) * 0.01;
        let v: DVector<f64> = entries(n, 1, 6).column(0).into_owned();
        let run = |threads: usize| {
            let policy = KernelPolicy::DEFAULT.with_threads(NonZeroUsize::new(threads).unwrap());
            on(policy, || {
                let c = Covariance::from_symmetric(p.clone(), "P").unwrap();
                let (pht, s) = innovation_covariance(&p, &h, &r);
                (
                    (propagate(&a, &p), propagate(&h, &p), pht, s),
                    crate::joseph_update(&p, &k, &h, &r),
                    standard_update(&p, &k, &h),
                    (
                        c.factor(),
                        c.solve(&v).unwrap(),
                        c.solve_right(&k.transpose()).unwrap(),
                    ),
                    (product(&h, &a), product(&a, &k)),
                )
            })
        };
        let one = run(1);
        for threads in [2, 4] {
            assert!(run(threads) == one, "m = {m}, {threads} threads");
        }
    }
}
