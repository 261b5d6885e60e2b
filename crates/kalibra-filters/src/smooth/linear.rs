//! The linear KF smoother's own pass: the filter's arithmetic on the estimates alone, storing
//! exactly what the backward pass reads (the filtered and the predicted mean and covariance of
//! every step), without the step record a [`Kf`] fills at each step.
//!
//! It is [`Kf`]'s [`Smoothable::smooth`](super::Smoothable::smooth) for fixed sizes with the
//! Joseph update, the same numbers to the bit as the filter run step by step and smoothed
//! (`tests/smooth.rs`, `kf_smooth_is_its_forward_pass_smoothed`), at less cost (`cargo xtask
//! bench smooth`): the record's bookkeeping was a tenth of the smoother's instructions.
//!
//! The checks stay, in a cheaper form. Every covariance and mean the filter and the backward
//! pass check for finiteness reaches the first step's smoothed estimate: a product `A P A^T`
//! or `G v` with one NaN or infinite entry in `P` or `v` (or in `A`, `G`) has no finite entry
//! at all (each entry sums a product with it, and `0 * inf` is NaN), so NaN or an infinity in
//! any filtered, predicted or smoothed covariance, gain or mean spreads forward through the
//! predictions and Joseph updates and back through the backward steps to step 0, which is
//! checked once. What does not pass through such a product, the measurements and the factor
//! of `S`, is summed entry by entry and the sum checked at the end (NaN and the infinities
//! survive any sum; an overflow of the sum only costs the detour below). A failed check or a
//! failed Cholesky factorisation sends the whole run, from the untouched filter, through the
//! checked path ([`Kf`]'s `predict` and `update`, then [`rts::smooth_in_place`](super::rts)),
//! which returns the same typed error naming its step and leaves the filter where it failed
//! (`tests/smooth.rs`, `a_non_finite_measurement_fails_smooth_as_forward`).

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, joseph_update, propagate};
use kalibra_linalg::{
    all_finite, cholesky_solve_right, innovation_covariance, product, product_transpose, symmetrize,
};
use kalibra_models::{LinearDynamics, LinearMeasurement};
use nalgebra::Cholesky;

use super::{Smoothed, SmoothedStep};
use crate::core::PriorSplit;
use crate::{Estimate, Filter, FilterError, Kf, Start, UpdateForm};

/// The filter's state before the last element, where [`finish`] puts it back.
struct Resume<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    k: usize,
    estimate: Estimate<N>,
    split: Option<PriorSplit<N>>,
    updated: bool,
}

/// Smooths `zs` with `kf`'s models from its current estimate, and on success leaves `kf`
/// where running it over `zs` would (the last element is run through the filter itself, from
/// the estimate before it). `None`, with `kf` untouched, when the pass does not apply (run-time
/// sizes, the standard update, a filter left at a prediction) or a check failed: the caller
/// then takes the checked path.
pub(super) fn smooth<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>>(
    kf: &mut Kf<N, M, D, H>,
    zs: &[Option<&OVector<f64, M>>],
    start: Start,
) -> Option<Result<Smoothed<N>, FilterError>>
where
    DefaultAllocator: Alloc<N, M>,
{
    let fixed = N::try_to_usize().is_some() && M::try_to_usize().is_some();
    let core = kf.core();
    if !fixed || zs.is_empty() || core.is_prior() || core.update_form() != UpdateForm::Joseph {
        return None;
    }
    let predict_first = start == Start::PredictFirst;
    let (mut steps, priors, resume) = forward(kf, zs, predict_first)?;
    backward(kf, &mut steps, &priors)?;
    Some(finish(kf, zs, predict_first, resume).map(|()| Smoothed { steps }))
}

/// What [`forward`] returns: the steps holding the filtered estimates, the predicted ones, and
/// the filter's state before the last element.
type Forward<N> = (Vec<SmoothedStep<N>>, Vec<Estimate<N>>, Resume<N>);

/// The filter's steps over `zs` as `forward::Recorder` runs them, the arithmetic of
/// `KalmanCore::predict` and `KalmanCore::update` (fixed sizes, Joseph form); `None` if a
/// check fails.
fn forward<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>>(
    kf: &Kf<N, M, D, H>,
    zs: &[Option<&OVector<f64, M>>],
    predict_first: bool,
) -> Option<Forward<N>>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (dynamics, measurement) = (kf.dynamics(), kf.measurement());
    let mut k = kf.step_index();
    let mut x = kf.mean().clone();
    let mut p = kf.covariance().clone();
    let m = measurement.meas_dim();
    // The sum of the measurements and of the factors' diagonals of `S` (see the module docs).
    let mut sum_m = OVector::<f64, M>::zeros_generic(m, nalgebra::U1);
    let mut steps = Vec::with_capacity(zs.len() + 1);
    let mut priors = Vec::with_capacity(zs.len());
    let step = |k, updated, x: &OVector<f64, N>, p: &OMatrix<f64, N, N>| SmoothedStep {
        step: k,
        updated,
        estimate: Estimate {
            mean: x.clone(),
            cov: p.clone(),
        },
        lag_one: None,
    };
    if predict_first {
        steps.push(step(k, false, &x, &p));
    }
    let (mut split, mut updated): (Option<PriorSplit<N>>, bool) = (None, false);
    let mut resume = None;
    let last = zs.len() - 1;
    for (i, z) in zs.iter().enumerate() {
        if i == last {
            resume = Some(Resume {
                k,
                estimate: Estimate {
                    mean: x.clone(),
                    cov: p.clone(),
                },
                split: split.clone(),
                updated,
            });
        }
        if i > 0 || predict_first {
            x = dynamics.transition(k, &x);
            let (f, q) = (dynamics.matrix(k), dynamics.noise_cov(k));
            let (propagated, noise) = match &split {
                None => (propagate(&f, &p), q),
                Some((propagated, noise)) => carry(&f, propagated, noise, q),
            };
            split = None;
            p = &propagated + &noise;
            symmetrize(&mut p);
            k += 1;
            priors.push(Estimate {
                mean: x.clone(),
                cov: p.clone(),
            });
            if z.is_none() {
                split = Some((propagated, noise));
            }
        }
        if let Some(z) = z {
            sum_m += *z;
            let zhat = measurement.measure(k, &x);
            let innovation = measurement.residual(z, &zhat);
            let (h, r) = (measurement.matrix(k), measurement.noise_cov(k, &x));
            let (pht, s) = innovation_covariance(&p, &h, &r);
            let chol = Cholesky::new(s)?;
            sum_m += chol.l_dirty().diagonal();
            let gain = cholesky_solve_right(&chol, &pht);
            x = &x + product(&gain, &innovation);
            p = joseph_update(&p, &gain, &h, &r);
        }
        updated = z.is_some();
        steps.push(step(k, updated, &x, &p));
    }
    all_finite(&sum_m).then_some((steps, priors, resume?))
}

/// A second prediction without an update between: both parts of the prior's covariance are
/// carried through `F` (as `KalmanCore::predict` does). Out of line, so that the common
/// prediction after an update does not move the parts out of their `Option` each step
/// (`cargo xtask bench smooth`).
#[cold]
#[inline(never)]
fn carry<N: Dim>(
    f: &OMatrix<f64, N, N>,
    propagated: &OMatrix<f64, N, N>,
    noise: &OMatrix<f64, N, N>,
    q: OMatrix<f64, N, N>,
) -> PriorSplit<N>
where
    DefaultAllocator: Alloc<N>,
{
    (propagate(f, propagated), propagate(f, noise) + q)
}

/// The backward pass in place, the arithmetic of `rts::backward_step` with `C_k = P_k F_k^T`;
/// `None` if a check fails.
fn backward<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>>(
    kf: &Kf<N, M, D, H>,
    steps: &mut [SmoothedStep<N>],
    priors: &[Estimate<N>],
) -> Option<()>
where
    DefaultAllocator: Alloc<N, M>,
{
    let dynamics = kf.dynamics();
    for (i, prior) in priors.iter().enumerate().rev() {
        let (head, tail) = steps.split_at_mut(i + 1);
        let (current, next) = (&mut head[i], &mut tail[0]);
        let cross = product_transpose(&current.estimate.cov, &dynamics.matrix(current.step));
        let current = &mut current.estimate;
        let chol = Cholesky::new(prior.cov.clone())?;
        let gain = cholesky_solve_right(&chol, &cross);
        current.mean += product(&gain, &(&next.estimate.mean - &prior.mean));
        current.cov += propagate(&gain, &(&next.estimate.cov - &prior.cov));
        symmetrize(&mut current.cov);
        next.lag_one = Some(product_transpose(&next.estimate.cov, &gain));
    }
    // Where every non-finite entry ends (see the module docs); a predicted covariance's factor
    // has a finite diagonal when the covariance is finite.
    let first = &steps.first()?.estimate;
    (all_finite(&first.mean) && all_finite(&first.cov)).then_some(())
}

/// Leaves `kf` where running it over `zs` would: at the estimate before the last element
/// (a prior with its split, or a posterior), then the last element through the filter itself,
/// so that its record is the filter's own.
fn finish<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>>(
    kf: &mut Kf<N, M, D, H>,
    zs: &[Option<&OVector<f64, M>>],
    predict_first: bool,
    resume: Resume<N>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let Resume {
        k,
        estimate,
        split,
        updated,
    } = resume;
    kf.core_mut().resume(k, estimate, split, updated);
    if zs.len() > 1 || predict_first {
        kf.predict()?;
    }
    if let Some(Some(z)) = zs.last() {
        kf.update(z)?;
    }
    Ok(())
}
