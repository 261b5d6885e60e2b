//! The sigma-point formulas the scalar [`Ukf`](super::Ukf) and the square-root
//! [`SqrtUkf`](crate::SqrtUkf) share: the points placed at `x +- spread L_j` for a factor `L`
//! of the covariance (the Cholesky factor of `P` for the one, the carried factor for the
//! other), their images through the models, their means and the cross covariance. The
//! filters differ only in how they turn the deviations into a covariance (a sum of outer
//! products, or a QR factorisation), so both stay equal bit for bit where their factors are.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, U1};
use kalibra_models::{Dynamics, Measurement};

use super::{SigmaSpace, SigmaWeights};
use crate::FilterError;
use crate::core::check_model_output;

/// A mean of sigma points and the central point's deviation from it.
pub(crate) type Centred<D> = (OVector<f64, D>, OVector<f64, D>);

/// The central point `f(x)`, returned, and the `2n` outer points `f(x +- spread L_j)` written
/// to `out` (`out[j]` the plus point, `out[n + j]` the minus point). Every answer of the model
/// is checked as it comes (a `Dyn` model may return any length), before a sum mixes it with
/// the others.
pub(crate) fn transform<N: Dim, D: Dynamics<N>>(
    dynamics: &D,
    k: usize,
    x: &OVector<f64, N>,
    l: &OMatrix<f64, N, N>,
    w: &SigmaWeights,
    out: &mut [OVector<f64, N>],
) -> Result<OVector<f64, N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let n = x.nrows();
    let fx = "predicted sigma point f(x)";
    let x0 = dynamics.transition(k, x);
    check_model_output(fx, &x0, (n, 1), k)?;
    for j in 0..n {
        let d = l.column(j) * w.spread;
        let (plus, minus) = (
            dynamics.transition(k, &(x + &d)),
            dynamics.transition(k, &(x - &d)),
        );
        check_model_output(fx, &plus, (n, 1), k)?;
        check_model_output(fx, &minus, (n, 1), k)?;
        out[j] = plus;
        out[n + j] = minus;
    }
    Ok(x0)
}

/// The weighted mean `W_0^m x0 + W sum_i x_i` of the central point and the outer ones.
pub(crate) fn plain_mean<N: Dim>(
    x0: &OVector<f64, N>,
    points: &[OVector<f64, N>],
    w: &SigmaWeights,
) -> OVector<f64, N>
where
    DefaultAllocator: Alloc<N>,
{
    let mut mean = x0 * w.mean_center;
    for xi in points {
        mean += xi * w.other;
    }
    mean
}

/// The mean of the transformed points in a state space, the outer points replaced by their
/// residuals from it, and the central point's residual, returned with the mean.
pub(crate) fn space_deviations<N: Dim>(
    space: &dyn SigmaSpace<N>,
    k: usize,
    x0: OVector<f64, N>,
    points: &mut [OVector<f64, N>],
    w: &SigmaWeights,
) -> Result<Centred<N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let n = x0.nrows();
    let mut all = Vec::with_capacity(points.len() + 1);
    all.push(x0);
    all.extend(points.iter().cloned());
    let mean = space.mean(&all, w);
    check_model_output("state space's sigma-point mean", &mean, (n, 1), k)?;
    let residual = "state space's sigma-point residual";
    let d0 = space.residual(&all[0], &mean);
    check_model_output(residual, &d0, (n, 1), k)?;
    for (slot, xi) in points.iter_mut().zip(&all[1..]) {
        *slot = space.residual(xi, &mean);
        check_model_output(residual, slot, (n, 1), k)?;
    }
    Ok((mean, d0))
}

/// `measurement.residual(a, b)`, its length checked.
pub(crate) fn residual<N: Dim, M: Dim, H: Measurement<N, M>>(
    measurement: &H,
    k: usize,
    a: &OVector<f64, M>,
    b: &OVector<f64, M>,
) -> Result<OVector<f64, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let e = measurement.residual(a, b);
    check_model_output("measurement residual", &e, (a.nrows(), 1), k).map(|()| e)
}

/// The sigma points of `x` with factor `l` through `h`, given the central measurement `z0`.
///
/// Without a measurement `mean`, the outer measurements are written to `out` as residuals
/// from `z0` (so bearings are unwrapped around the central one and never straddle +-pi), and
/// the predicted measurement is `z0 + dbar`, `dbar = W sum_i out[i]`, not yet normalised;
/// with one, `out` holds the residuals from its (normalised) mean. Returned: the predicted
/// measurement and the central point's deviation from it (`-dbar` without a mean), so that
/// a point's deviation is `out[i] + e0` without a mean and `out[i]` with one.
#[allow(clippy::too_many_arguments)]
pub(crate) fn measure<N: Dim, M: Dim, H: Measurement<N, M>>(
    measurement: &H,
    k: usize,
    x: &OVector<f64, N>,
    l: &OMatrix<f64, N, N>,
    w: &SigmaWeights,
    z0: &OVector<f64, M>,
    mean: Option<&dyn SigmaSpace<M>>,
    out: &mut [OVector<f64, M>],
) -> Result<Centred<M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (n, m) = (x.nrows(), z0.nrows());
    let measured = |at: &OVector<f64, N>| {
        let z = measurement.measure(k, at);
        check_model_output("sigma measurement h(x)", &z, (m, 1), k).map(|()| z)
    };
    match mean {
        None => {
            for j in 0..n {
                let d = l.column(j) * w.spread;
                out[j] = residual(measurement, k, &measured(&(x + &d))?, z0)?;
                out[n + j] = residual(measurement, k, &measured(&(x - &d))?, z0)?;
            }
            let mut dbar = OVector::<f64, M>::zeros_generic(z0.shape_generic().0, U1);
            for d in out.iter() {
                dbar += d * w.other;
            }
            Ok((z0 + &dbar, -dbar))
        }
        Some(mean) => {
            // The sigma measurements as measured, averaged by the chosen mean, then their
            // residuals from it.
            let mut points = Vec::with_capacity(2 * n + 1);
            points.push(z0.clone());
            for sign in [1.0, -1.0] {
                for j in 0..n {
                    let d = l.column(j) * (sign * w.spread);
                    points.push(measured(&(x + &d))?);
                }
            }
            let mut zhat = mean.mean(&points, w);
            measurement.normalize(&mut zhat);
            check_model_output("measurement space's sigma-point mean", &zhat, (m, 1), k)?;
            for (slot, zi) in out.iter_mut().zip(&points[1..]) {
                *slot = residual(measurement, k, zi, &zhat)?;
            }
            let e0 = residual(measurement, k, z0, &zhat)?;
            Ok((zhat, e0))
        }
    }
}

/// The cross covariance `Pxz = sum_i W_i (X_i - x)(Z_i - zhat)^T` from the factor `l` and the
/// measurement deviations `dz` of [`measure`]: the central point has no state deviation, and
/// the measurements' mean cancels between each pair, so it is
/// `W spread sum_j L_j (dz_j - dz_{n+j})^T` (`m` the measurement's dimension).
pub(crate) fn cross_covariance<N: Dim, M: Dim>(
    l: &OMatrix<f64, N, N>,
    dz: &[OVector<f64, M>],
    m: M,
    w: &SigmaWeights,
) -> OMatrix<f64, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = l.nrows();
    let mut pxz = OMatrix::<f64, N, M>::zeros_generic(l.shape_generic().0, m);
    for j in 0..n {
        let d = &dz[j] - &dz[n + j];
        pxz += l.column(j) * d.transpose() * (w.spread * w.other);
    }
    pxz
}
