//! Gaussian sampling through a square-root factor.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, U1};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// A vector of independent standard normal draws of dimension `d`.
// Always inlined: out of line, its call costs about 20 instructions per draw of a vector,
// a tenth of the draw (`cargo xtask bench w1`'s library loop under callgrind).
#[inline(always)]
pub fn standard_normal<D: Dim, R: Rng + ?Sized>(d: D, rng: &mut R) -> OVector<f64, D>
where
    DefaultAllocator: Alloc<D>,
{
    // A plain loop over the contiguous storage rather than `from_fn_generic` (a closure LLVM
    // may leave out of line) or nalgebra's strided iterator (more work per entry): every noise
    // draw of a linear model goes through it (`cargo xtask bench w1`, whose scalar study
    // simulates its truths so).
    let mut v = OVector::<f64, D>::zeros_generic(d, U1);
    for x in v.as_mut_slice() {
        *x = StandardNormal.sample(rng);
    }
    v
}

/// A draw of `N(0, L L^T)` as `L n`, `n` standard normal. `L` may be rank-deficient (a
/// semi-definite factor), which samples exactly from a singular covariance.
// Always inlined, as the linear models' `sample_noise` that call it: out of line, a simulated
// step gets its noise back through memory and waits on it (`cargo xtask bench w1`, the scalar
// library).
#[inline(always)]
pub fn sample_with_factor<D: Dim, R: Rng + ?Sized>(
    l: &OMatrix<f64, D, D>,
    rng: &mut R,
) -> OVector<f64, D>
where
    DefaultAllocator: Alloc<D>,
{
    let n = standard_normal(l.shape_generic().1, rng);
    l * n
}
