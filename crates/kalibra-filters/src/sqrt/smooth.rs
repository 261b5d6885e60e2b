//! The square-root Rauch-Tung-Striebel smoother over a [`SqrtKf`](crate::SqrtKf) run: the
//! backward pass on Cholesky factors, so that it survives where the covariance form's
//! Cholesky solve with `P-_{k+1}` fails.
//!
//! One backward step is one QR triangularisation of the `2n x 2n` array
//!
//! ```text
//! [ F S_k   sqrt(Q) ]      [ S-_{k+1}    0     ]
//! [ S_k        0    ]  ->  [ X         S_hat   ]
//! ```
//!
//! (the forward prediction's array with the filtered factor under it; Park and Kailath 1996,
//! the array form). Multiplying out the two sides: `S- S-^T = F P_k F^T + Q = P-_{k+1}`,
//! `X S-^T = P_k F^T`, so the smoother gain is `G = X S-^-1` (one triangular solve, no
//! `P-_{k+1}` formed or factored), and `S_hat S_hat^T = P_k - G P- G^T`, the covariance of
//! `x_k` given `x_{k+1}`. Then `P_{k|n} = S_hat S_hat^T + G P_{k+1|n} G^T`, whose factor is the
//! triangularisation of `[S_hat, G S_{k+1|n}]`: a sum of two Gram matrices, positive
//! semi-definite in any arithmetic. The mean and the lag-one covariance are the covariance
//! form's (`x_k + G (x_{k+1|n} - x-_{k+1})`, `P_{k+1|n} G^T`).

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, check_finite, symmetrize};

use super::qr::{Array, lower_root_of_sum};
use crate::smooth::{Smoothed, SmoothedStep};
use crate::{Estimate, FilterError};

/// The filtered estimate of one step, with its factor.
#[derive(Clone, Debug)]
pub(crate) struct FactorStep<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) step: usize,
    pub(crate) updated: bool,
    pub(crate) estimate: Estimate<N>,
    pub(crate) factor: OMatrix<f64, N, N>,
}

/// What the prediction from one step to the next used: `F_k`, the root of `Q_k` and the
/// predicted mean.
#[derive(Clone, Debug)]
pub(crate) struct FactorLink<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) f: OMatrix<f64, N, N>,
    pub(crate) q_root: OMatrix<f64, N, N>,
    pub(crate) prior_mean: OVector<f64, N>,
}

/// The backward pass over `steps` and the `links` between them (`links.len() + 1 ==
/// steps.len()`, or both empty), with a QR work array.
pub(crate) fn smooth_factors<N: Dim>(
    steps: &[FactorStep<N>],
    links: &[FactorLink<N>],
    scratch: &mut Vec<f64>,
) -> Result<Smoothed<N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let Some(last) = steps.last() else {
        return Ok(Smoothed { steps: Vec::new() });
    };
    let mut out: Vec<SmoothedStep<N>> = Vec::with_capacity(steps.len());
    let mut next = SmoothedStep {
        step: last.step,
        updated: last.updated,
        estimate: last.estimate.clone(),
        lag_one: None,
    };
    let mut next_factor = last.factor.clone();
    for (filtered, link) in steps.iter().zip(links).rev() {
        let (estimate, factor, lag_one) =
            backward(filtered, link, &next_factor, &next.estimate, scratch)?;
        next.lag_one = Some(lag_one);
        let step = SmoothedStep {
            step: filtered.step,
            updated: filtered.updated,
            estimate,
            lag_one: None,
        };
        out.push(std::mem::replace(&mut next, step));
        next_factor = factor;
    }
    out.push(next);
    out.reverse();
    Ok(Smoothed { steps: out })
}

/// A backward step's smoothed estimate, its factor, and the lag-one covariance of the step
/// after it.
type Backward<N> = (Estimate<N>, OMatrix<f64, N, N>, OMatrix<f64, N, N>);

/// One backward step (module docs): the smoothed estimate of step `k`, its factor, and the
/// lag-one covariance `P_{k+1,k|n}` of the step after it.
fn backward<N: Dim>(
    filtered: &FactorStep<N>,
    link: &FactorLink<N>,
    next_factor: &OMatrix<f64, N, N>,
    next: &Estimate<N>,
    scratch: &mut Vec<f64>,
) -> Result<Backward<N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let k = filtered.step;
    let s = &filtered.factor;
    let n = s.nrows();
    let d = s.shape_generic().0;
    let mut t = Array::zeroed(scratch, 2 * n, 2 * n);
    t.put_transposed(0, 0, &(&link.f * s));
    t.put_transposed(n, 0, &link.q_root);
    t.put_transposed(0, n, s);
    t.triangularise();
    let predicted: OMatrix<f64, N, N> = t.lower_block(0, 0, (d, d));
    let x: OMatrix<f64, N, N> = t.lower_block(n, 0, (d, d));
    let conditional: OMatrix<f64, N, N> = t.lower_block(n, n, (d, d));
    // G^T = S-^-T X^T.
    let gain = predicted
        .tr_solve_lower_triangular(&x.transpose())
        .ok_or(FilterError::NotPositiveDefinite {
            what: "predicted covariance factor (square-root smoother)",
            step: k + 1,
        })?
        .transpose();
    let at = |e| FilterError::at(k, e);
    check_finite(&gain, "smoother gain").map_err(at)?;
    let mean = &filtered.estimate.mean + &gain * (&next.mean - &link.prior_mean);
    let factor = lower_root_of_sum(scratch, &conditional, &(&gain * next_factor));
    let mut cov = &factor * factor.transpose();
    symmetrize(&mut cov);
    let lag_one = &next.cov * gain.transpose();
    check_finite(&mean, "smoothed mean").map_err(at)?;
    check_finite(&cov, "smoothed covariance").map_err(at)?;
    Ok((Estimate { mean, cov }, factor, lag_one))
}
