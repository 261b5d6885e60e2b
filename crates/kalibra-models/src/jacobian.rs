//! Finite-difference checks of analytic Jacobians, for any model's tests.

use kalibra_linalg::nalgebra::allocator::Allocator;
use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};

use crate::{Dynamics, Measurement};

/// Relative step of the central differences: near the cube root of machine epsilon, which
/// balances truncation error (O(h^2)) against rounding (O(eps / h)).
pub const FD_RELATIVE_STEP: f64 = 6e-6;

/// An analytic Jacobian beside its central-difference estimate.
#[derive(Clone, Debug)]
pub struct JacobianCheck<R: Dim, C: Dim>
where
    DefaultAllocator: Allocator<R, C>,
{
    /// The model's Jacobian.
    pub analytic: OMatrix<f64, R, C>,
    /// The central-difference estimate.
    pub numeric: OMatrix<f64, R, C>,
    /// `max_ij |analytic - numeric|`.
    pub max_abs_error: f64,
    /// `max_ij |analytic - numeric| / (1 + |analytic_ij|)`: relative for large entries, absolute
    /// for small ones. Central differences give about 1e-9 on smooth models; a wrong derivative
    /// gives O(1).
    pub scaled_error: f64,
}

fn compare<R: Dim, C: Dim>(
    analytic: OMatrix<f64, R, C>,
    numeric: OMatrix<f64, R, C>,
) -> JacobianCheck<R, C>
where
    DefaultAllocator: Allocator<R, C>,
{
    let mut max_abs_error = 0.0f64;
    let mut scaled_error = 0.0f64;
    for (a, n) in analytic.iter().zip(numeric.iter()) {
        // NaN must not hide: treat it as an infinite error.
        let e = if (a - n).is_nan() {
            f64::INFINITY
        } else {
            (a - n).abs()
        };
        max_abs_error = max_abs_error.max(e);
        scaled_error = scaled_error.max(e / (1.0 + a.abs()));
    }
    JacobianCheck {
        analytic,
        numeric,
        max_abs_error,
        scaled_error,
    }
}

fn steps<N: Dim>(x: &OVector<f64, N>) -> impl Iterator<Item = (usize, f64)> + '_
where
    DefaultAllocator: Alloc<N>,
{
    x.iter()
        .enumerate()
        .map(|(j, v)| (j, FD_RELATIVE_STEP * v.abs().max(1.0)))
}

/// Checks `Dynamics::jacobian` at `(k, x)` against central differences of `transition`.
pub fn check_dynamics_jacobian<N: Dim, D: Dynamics<N>>(
    model: &D,
    k: usize,
    x: &OVector<f64, N>,
) -> JacobianCheck<N, N>
where
    DefaultAllocator: Alloc<N>,
{
    let n = x.shape_generic().0;
    let mut numeric = OMatrix::<f64, N, N>::zeros_generic(n, n);
    for (j, h) in steps(x) {
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[j] += h;
        xm[j] -= h;
        let col = (model.transition(k, &xp) - model.transition(k, &xm)) / (2.0 * h);
        numeric.set_column(j, &col);
    }
    compare(model.jacobian(k, x), numeric)
}

/// Checks `Measurement::jacobian` at `(k, x)` against central differences of `measure`, taking
/// differences through the model's `residual` so that angles wrapping at +-pi do not spoil
/// the estimate.
pub fn check_measurement_jacobian<N: Dim, M: Dim, H: Measurement<N, M>>(
    model: &H,
    k: usize,
    x: &OVector<f64, N>,
) -> JacobianCheck<M, N>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = x.shape_generic().0;
    let m = model.meas_dim();
    let mut numeric = OMatrix::<f64, M, N>::zeros_generic(m, n);
    for (j, h) in steps(x) {
        let (mut xp, mut xm) = (x.clone(), x.clone());
        xp[j] += h;
        xm[j] -= h;
        let col = model.residual(&model.measure(k, &xp), &model.measure(k, &xm)) / (2.0 * h);
        numeric.set_column(j, &col);
    }
    compare(model.jacobian(k, x), numeric)
}
