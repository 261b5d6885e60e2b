use nalgebra::allocator::Allocator;
use nalgebra::{Dim, U1};

/// Bound alias: every allocation a filter over state dimension `N` and measurement dimension
/// `M` needs.
///
/// Write `where DefaultAllocator: Alloc<N, M>` (or `Alloc<N>` when there is no measurement)
/// instead of listing the allocator bounds one by one. The trait is implemented for every type
/// that has the bounds, so it is never implemented by hand; for `Const` and `Dyn` dimensions
/// nalgebra's `DefaultAllocator` always has them.
///
/// ```
/// use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix};
///
/// fn trace_of<N: Dim>(p: &OMatrix<f64, N, N>) -> f64
/// where
///     DefaultAllocator: Alloc<N>,
/// {
///     p.trace()
/// }
/// assert_eq!(trace_of(&kalibra_linalg::Matrix2::<f64>::identity()), 2.0);
/// ```
pub trait Alloc<N: Dim, M: Dim = N>:
    Allocator<N>
    + Allocator<M>
    + Allocator<N, N>
    + Allocator<M, M>
    + Allocator<N, M>
    + Allocator<M, N>
    + Allocator<U1, N>
    + Allocator<U1, M>
{
}

impl<N: Dim, M: Dim, A> Alloc<N, M> for A where
    A: Allocator<N>
        + Allocator<M>
        + Allocator<N, N>
        + Allocator<M, M>
        + Allocator<N, M>
        + Allocator<M, N>
        + Allocator<U1, N>
        + Allocator<U1, M>
{
}
