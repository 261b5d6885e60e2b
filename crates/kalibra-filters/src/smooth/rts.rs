//! The Rauch-Tung-Striebel backward recursion, shared by the full and the fixed-lag smoother.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector, check_finite, propagate, symmetrize,
};

use std::borrow::Borrow;

use super::forward::{FilteredStep, Prediction};
use crate::{Estimate, FilterError, SigmaSpace};

/// The smoothed estimate of one step: given every measurement of the run (or, from the
/// fixed-lag smoother, every measurement up to `lag` steps later).
#[derive(Clone, Debug)]
pub struct SmoothedStep<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) step: usize,
    pub(crate) updated: bool,
    pub(crate) estimate: Estimate<N>,
    pub(crate) lag_one: Option<OMatrix<f64, N, N>>,
}

impl<N: Dim> SmoothedStep<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The step index `k`.
    pub fn step(&self) -> usize {
        self.step
    }
    /// Whether a measurement updated this step in the forward pass.
    pub fn updated(&self) -> bool {
        self.updated
    }
    /// The smoothed estimate `x_{k|n}, P_{k|n}`.
    pub fn estimate(&self) -> &Estimate<N> {
        &self.estimate
    }
    /// The smoothed mean `x_{k|n}`.
    pub fn mean(&self) -> &OVector<f64, N> {
        &self.estimate.mean
    }
    /// The smoothed covariance `P_{k|n}`.
    pub fn covariance(&self) -> &OMatrix<f64, N, N> {
        &self.estimate.cov
    }
    /// The lag-one cross-covariance `P_{k,k-1|n} = Cov(x_k, x_{k-1} | z_1..z_n)` with the
    /// previous step (what EM's M-step needs); `None` at the first step of the pass.
    pub fn lag_one(&self) -> Option<&OMatrix<f64, N, N>> {
        self.lag_one.as_ref()
    }
}

/// Every step of a smoothed run, in step order.
#[derive(Clone, Debug)]
pub struct Smoothed<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) steps: Vec<SmoothedStep<N>>,
}

impl<N: Dim> Smoothed<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The smoothed steps, in step order.
    pub fn steps(&self) -> &[SmoothedStep<N>] {
        &self.steps
    }
    /// Consumes the value, returning its steps.
    pub fn into_steps(self) -> Vec<SmoothedStep<N>> {
        self.steps
    }
}

/// One backward step, in place: `current` holds the filtered estimate at `k` on entry and the
/// smoothed one on return, from the prior of the prediction to `k + 1` with its
/// cross-covariance `C_k` and the smoothed estimate of `k + 1`; returns the lag-one covariance
/// of step `k + 1`. Written in place because building a new estimate and moving it over the
/// old one cost a copy per step (`cargo xtask bench smooth`).
///
/// `G = C P-^-1` is a Cholesky solve with `P-_{k+1}`; `x = x_k + G (x_{k+1|n} - x-_{k+1})`
/// (the difference through the state space's residual, the result normalised);
/// `P = P_k + G (P_{k+1|n} - P-_{k+1}) G^T`, symmetrised; `P_{k+1,k|n} = P_{k+1|n} G^T`.
/// Every filter symmetrises its predicted covariance, so `P-` is factored as it stands, with
/// no symmetry check. On an error `current` may hold a partly smoothed estimate.
pub(crate) fn backward_step<N: Dim>(
    k: usize,
    current: &mut Estimate<N>,
    prior: &Estimate<N>,
    cross: &OMatrix<f64, N, N>,
    next: &Estimate<N>,
    space: Option<&dyn SigmaSpace<N>>,
) -> Result<OMatrix<f64, N, N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let predicted =
        Covariance::from_symmetric(prior.cov.clone(), "predicted covariance P- (smoother)")
            .map_err(|e| FilterError::at(k + 1, e))?;
    let gain = predicted
        .solve_right(cross)
        .map_err(|e| FilterError::at(k, e))?;
    let dx = match space {
        None => &next.mean - &prior.mean,
        Some(space) => space.residual(&next.mean, &prior.mean),
    };
    current.mean += &gain * dx;
    if let Some(space) = space {
        space.normalize(&mut current.mean);
    }
    current.cov += propagate(&gain, &(&next.cov - &prior.cov));
    symmetrize(&mut current.cov);
    let lag_one = &next.cov * gain.transpose();
    let at = |e| FilterError::at(k, e);
    check_finite(&current.mean, "smoothed mean").map_err(at)?;
    check_finite(&current.cov, "smoothed covariance").map_err(at)?;
    Ok(lag_one)
}

/// The backward pass in place over `steps`, which hold the filtered estimates on entry and
/// the smoothed ones on return: `links(i)` gives the prior of the prediction from `steps[i]`
/// and its cross-covariance, for `i < links_len` (`links_len + 1 == steps.len()`, or both
/// zero). No step allocates: each smoothed estimate replaces its filtered one.
pub(crate) fn smooth_in_place<'p, N: Dim, C: Borrow<OMatrix<f64, N, N>>>(
    steps: &mut [SmoothedStep<N>],
    links_len: usize,
    mut links: impl FnMut(usize, &SmoothedStep<N>) -> (C, &'p Estimate<N>),
    space: Option<&dyn SigmaSpace<N>>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    for i in (0..links_len).rev() {
        let (head, tail) = steps.split_at_mut(i + 1);
        let (current, next) = (&mut head[i], &mut tail[0]);
        let (cross, prior) = links(i, current);
        let lag_one = backward_step(
            current.step,
            &mut current.estimate,
            prior,
            cross.borrow(),
            &next.estimate,
            space,
        )?;
        next.lag_one = Some(lag_one);
    }
    Ok(())
}

/// The smoother over a chain of filtered steps and the predictions between them
/// (`predictions.len() + 1 == filtered.len()`, or both empty).
pub(crate) fn smooth_chain<N: Dim>(
    filtered: &[FilteredStep<N>],
    predictions: &[Prediction<N>],
    space: Option<&dyn SigmaSpace<N>>,
) -> Result<Vec<SmoothedStep<N>>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let mut steps: Vec<SmoothedStep<N>> = filtered
        .iter()
        .map(|f| SmoothedStep {
            step: f.step,
            updated: f.updated,
            estimate: f.estimate.clone(),
            lag_one: None,
        })
        .collect();
    let links = predictions.len().min(steps.len().saturating_sub(1));
    smooth_in_place(
        &mut steps,
        links,
        |i, _| (&predictions[i].cross, &predictions[i].prior),
        space,
    )?;
    Ok(steps)
}
