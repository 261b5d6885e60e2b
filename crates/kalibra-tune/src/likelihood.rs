//! The exact Gaussian log-likelihood of the innovations (the prediction-error decomposition).

use kalibra_filters::{Filter, FilterError, Kf};
use kalibra_models::{LinearGaussian, LinearObservation, ModelError};

use crate::{NoiseError, NoiseMatrices, NoiseProblem};

/// Why the log-likelihood could not be computed at a candidate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LikelihoodError {
    /// The candidate is not a valid parameter vector.
    #[error(transparent)]
    Noise(#[from] NoiseError),
    /// The model refused the candidate's `Q` or `R`.
    #[error("model: {0}")]
    Model(#[source] ModelError),
    /// The filter failed in a run, most often a singular innovation covariance `S` (a
    /// candidate with `R` and `H P- H^T` both singular in some direction).
    #[error("filter, run {run}: {source}")]
    Filter {
        /// The run.
        run: usize,
        /// The filter's error (it names the step).
        #[source]
        source: FilterError,
    },
    /// A step's log-density, or the sum up to it, is not finite.
    #[error("log-likelihood not finite at run {run}, update {update}")]
    NonFinite {
        /// The run.
        run: usize,
        /// The update (counting measurements present) within the run.
        update: usize,
    },
}

/// The exact log-likelihood of the measurements of every run at `theta`:
/// `sum over updates of -(m ln(2 pi) + ln det S_k + nu_k^T S_k^-1 nu_k) / 2`, the natural
/// logarithm with the `2 pi` constant, i.e. the sum of [`kalibra_filters::StepRecord::log_likelihood`]
/// over a [`Kf`] run with the candidate's `Q = G Qw G^T` and `R` (each run from `x0`, `P0`).
///
/// ```
/// use kalibra_tune::{log_likelihood, CovarianceForm, DMatrix, DVector, NoiseProblem,
///     Parametrisation, Start};
///
/// // One measurement, update first: nu = z - x0, S = P0 + R.
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let noise = Parametrisation::new(None, CovarianceForm::fixed(one(1.0)),
///     CovarianceForm::scaled(one(1.0)))?;
/// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(2.0),
///     Start::UpdateFirst, noise, vec![vec![Some(DVector::from_element(1, 1.5))]])?;
/// let ll = log_likelihood(&problem, &[0.0])?;
/// let s: f64 = 3.0;
/// let expected = -0.5 * ((2.0 * std::f64::consts::PI).ln() + s.ln() + 1.5 * 1.5 / s);
/// assert!((ll - expected).abs() < 1e-14);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`LikelihoodError::Noise`] for an invalid `theta`; [`LikelihoodError::Model`],
/// [`LikelihoodError::Filter`] (a singular `S`) and [`LikelihoodError::NonFinite`] at a
/// candidate the filter cannot run.
pub fn log_likelihood(problem: &NoiseProblem, theta: &[f64]) -> Result<f64, LikelihoodError> {
    let matrices = problem.noise().matrices(theta)?;
    log_likelihood_of(problem, &matrices)
}

/// [`log_likelihood`] at given matrices (`q` and `r` are used; `qw` is not read).
///
/// # Errors
/// As [`log_likelihood`], without the parameter-vector errors.
pub fn log_likelihood_of(
    problem: &NoiseProblem,
    matrices: &NoiseMatrices,
) -> Result<f64, LikelihoodError> {
    let dynamics = LinearGaussian::new(problem.f().clone(), matrices.q.clone())
        .map_err(LikelihoodError::Model)?;
    let sensor = LinearObservation::new(problem.h().clone(), matrices.r.clone())
        .map_err(LikelihoodError::Model)?;
    // The allocation-free loop; where it cannot vouch for its answer the filter runs and
    // names the failure.
    if let Some(total) = crate::kernel::log_likelihood(problem, &matrices.q, &matrices.r) {
        return Ok(total);
    }
    filter_log_likelihood(problem, &dynamics, &sensor)
}

/// The log-likelihood through [`Kf`]: the reference the fast loop is tested against, and the
/// path that names a failure.
pub(crate) fn filter_log_likelihood(
    problem: &NoiseProblem,
    dynamics: &LinearGaussian<kalibra_linalg::Dyn>,
    sensor: &LinearObservation<kalibra_linalg::Dyn, kalibra_linalg::Dyn>,
) -> Result<f64, LikelihoodError> {
    let mut total = 0.0;
    for (run, zs) in problem.runs().iter().enumerate() {
        let mut kf = Kf::new(dynamics, sensor, problem.x0().clone(), problem.p0().clone())
            .map_err(|source| LikelihoodError::Filter { run, source })?;
        let mut update = 0;
        let mut bad = None;
        kf.run(zs.iter().map(Option::as_ref), problem.start(), |rec| {
            total += rec.log_likelihood();
            // A non-finite term makes the sum non-finite, and so does an overflowing sum of
            // finite ones: one check finds both.
            if !total.is_finite() && bad.is_none() {
                bad = Some(update);
            }
            update += 1;
        })
        .map_err(|source| LikelihoodError::Filter { run, source })?;
        if let Some(update) = bad {
            return Err(LikelihoodError::NonFinite { run, update });
        }
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CovarianceForm, Parametrisation};
    use kalibra_filters::Start;
    use kalibra_linalg::{DMatrix, DVector};

    /// The likelihood of a scalar random walk by hand (the textbook recursion, no library
    /// code), against the library's: they agree to rounding.
    #[test]
    fn scalar_random_walk_by_hand() {
        let zs = [0.3, -0.2, 0.9, 1.4, 1.1];
        let (q, r, x0, p0) = (0.4, 0.7, 0.1, 2.0);
        let one = |v: f64| DMatrix::from_element(1, 1, v);
        let noise = Parametrisation::new(
            None,
            CovarianceForm::scaled(one(1.0)),
            CovarianceForm::scaled(one(1.0)),
        )
        .unwrap();
        let run: Vec<_> = zs
            .iter()
            .enumerate()
            .map(|(k, &z)| (k != 2).then(|| DVector::from_element(1, z)))
            .collect();
        let problem = NoiseProblem::new(
            one(1.0),
            one(1.0),
            DVector::from_element(1, x0),
            one(p0),
            Start::PredictFirst,
            noise,
            vec![run],
        )
        .unwrap();
        let (mut x, mut p, mut ll) = (x0, p0, 0.0);
        for (k, &z) in zs.iter().enumerate() {
            p += q;
            if k == 2 {
                continue;
            }
            let s = p + r;
            let nu = z - x;
            ll += -0.5 * ((2.0 * std::f64::consts::PI).ln() + s.ln() + nu * nu / s);
            let gain = p / s;
            x += gain * nu;
            p *= 1.0 - gain;
        }
        let ours = log_likelihood(&problem, &[q.ln(), r.ln()]).unwrap();
        assert!((ours - ll).abs() < 1e-12 * ll.abs(), "{ours} vs {ll}");
    }
}
