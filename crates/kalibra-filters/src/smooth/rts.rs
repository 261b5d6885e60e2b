//! The Rauch-Tung-Striebel backward recursion, shared by the full and the fixed-lag smoother.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector, check_finite, propagate, symmetrize,
};

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

/// One backward step: the smoothed estimate at `k` from the filtered one, the prediction to
/// `k + 1` and the smoothed step `k + 1`, whose lag-one covariance it sets.
///
/// `G = C P-^-1` is a Cholesky solve with `P-_{k+1}`; `x = x_k + G (x_{k+1|n} - x-_{k+1})`
/// (the difference through the state space's residual, the result normalised);
/// `P = P_k + G (P_{k+1|n} - P-_{k+1}) G^T`, symmetrised; `P_{k+1,k|n} = P_{k+1|n} G^T`.
fn backward_step<N: Dim>(
    filtered: &FilteredStep<N>,
    prediction: &Prediction<N>,
    next: &mut SmoothedStep<N>,
    space: Option<&dyn SigmaSpace<N>>,
) -> Result<Estimate<N>, FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    let k = filtered.step;
    let next_estimate = &next.estimate;
    let prior = &prediction.prior;
    let predicted = Covariance::named(prior.cov.clone(), "predicted covariance P- (smoother)")
        .map_err(|e| FilterError::at(k + 1, e))?;
    let gain = predicted
        .solve_right(&prediction.cross)
        .map_err(|e| FilterError::at(k, e))?;
    let dx = match space {
        None => &next_estimate.mean - &prior.mean,
        Some(space) => space.residual(&next_estimate.mean, &prior.mean),
    };
    let mut mean = &filtered.estimate.mean + &gain * dx;
    if let Some(space) = space {
        space.normalize(&mut mean);
    }
    let mut cov = &filtered.estimate.cov + propagate(&gain, &(&next_estimate.cov - &prior.cov));
    symmetrize(&mut cov);
    let lag_one = &next_estimate.cov * gain.transpose();
    let at = |e| FilterError::at(k, e);
    check_finite(&mean, "smoothed mean").map_err(at)?;
    check_finite(&cov, "smoothed covariance").map_err(at)?;
    next.lag_one = Some(lag_one);
    Ok(Estimate { mean, cov })
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
    let Some(last) = filtered.last() else {
        return Ok(Vec::new());
    };
    let mut reversed = Vec::with_capacity(filtered.len());
    let mut next = SmoothedStep {
        step: last.step,
        updated: last.updated,
        estimate: last.estimate.clone(),
        lag_one: None,
    };
    for (step, prediction) in filtered.iter().zip(predictions).rev() {
        let estimate = backward_step(step, prediction, &mut next, space)?;
        reversed.push(std::mem::replace(
            &mut next,
            SmoothedStep {
                step: step.step,
                updated: step.updated,
                estimate,
                lag_one: None,
            },
        ));
    }
    reversed.push(next);
    reversed.reverse();
    Ok(reversed)
}
