//! The E-step of EM: filter and smooth every run at the current `Q`, `R` and sum what the
//! M-step needs, with the log-likelihood of the current parameters on the way.

use kalibra_filters::smooth::Smoothable;
use kalibra_filters::{Kf, Start};
use kalibra_linalg::{DMatrix, DVector, Dyn};
use kalibra_models::{LinearGaussian, LinearObservation};

use super::EmError;

/// The linear-Gaussian model's known parts: `F`, `H`, the initial estimate and where it sits.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Known<'a> {
    pub(crate) f: &'a DMatrix<f64>,
    pub(crate) h: &'a DMatrix<f64>,
    pub(crate) x0: &'a DVector<f64>,
    pub(crate) p0: &'a DMatrix<f64>,
    pub(crate) start: Start,
}

/// The smoother's sums over every run, and the log-likelihood of the parameters they were
/// computed at.
#[derive(Clone, Debug)]
pub(crate) struct Statistics {
    /// `sum E[e_k e_k^T]` over every transition, `e_k = x_k - F x_{k-1}`.
    pub(crate) transition: DMatrix<f64>,
    /// The number of transitions (steps with or without a measurement, after the first).
    pub(crate) transitions: usize,
    /// `sum E[(z_k - H x_k)(z_k - H x_k)^T]` over every step with a measurement.
    pub(crate) measurement: DMatrix<f64>,
    /// The number of steps with a measurement.
    pub(crate) measured: usize,
    /// `sum_k -1/2 (m ln 2 pi + ln det S_k + nu_k^T S_k^-1 nu_k)` over those steps.
    pub(crate) log_likelihood: f64,
}

/// Filters and smooths every run at `(q, r)` and sums the statistics.
///
/// # Errors
/// [`EmError::Filter`] (with `run`) for a filter or smoother failure: an innovation or
/// predicted covariance without a Cholesky factor, a non-finite estimate; [`EmError::Model`]
/// for a `Q` or `R` the models refuse.
pub(crate) fn expectation(
    known: Known<'_>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    runs: &[Vec<Option<DVector<f64>>>],
    iteration: usize,
) -> Result<Statistics, EmError> {
    let (n, m) = (known.f.nrows(), known.h.nrows());
    let dynamics = LinearGaussian::new(known.f.clone(), q.clone())
        .map_err(|source| EmError::Model { iteration, source })?;
    let observation = LinearObservation::new(known.h.clone(), r.clone())
        .map_err(|source| EmError::Model { iteration, source })?;
    let mut stats = Statistics {
        transition: DMatrix::zeros(n, n),
        transitions: 0,
        measurement: DMatrix::zeros(m, m),
        measured: 0,
        log_likelihood: 0.0,
    };
    let half_log_two_pi = 0.5 * m as f64 * std::f64::consts::TAU.ln();
    for (run, zs) in runs.iter().enumerate() {
        let at = |source| EmError::Filter {
            iteration,
            run,
            source,
        };
        let mut kf: Kf<Dyn, Dyn, _, _> =
            Kf::new(&dynamics, &observation, known.x0.clone(), known.p0.clone()).map_err(at)?;
        let pass = kf
            .forward(zs.iter().map(Option::as_ref), known.start)
            .map_err(at)?;
        let smoothed = pass.smooth().map_err(at)?;
        let steps = smoothed.steps();
        // With predict-first the pass's step 0 is x0 and measurement i belongs to step i + 1.
        let offset = usize::from(known.start == Start::PredictFirst);
        for (i, z) in zs.iter().enumerate() {
            let Some(z) = z else { continue };
            let k = i + offset;
            // The prior at step k: x0 at update-first's first step, else the prediction into it.
            let (prior_mean, prior_cov) = match k.checked_sub(1) {
                Some(p) => {
                    let prior = pass.predictions()[p].prior();
                    (&prior.mean, &prior.cov)
                }
                None => (known.x0, known.p0),
            };
            let nu = z - known.h * prior_mean;
            let s = known.h * prior_cov * known.h.transpose() + r;
            let chol = s.cholesky().ok_or(EmError::Filter {
                iteration,
                run,
                source: kalibra_filters::FilterError::NotPositiveDefinite {
                    what: "innovation covariance S",
                    step: k,
                },
            })?;
            let log_det = 2.0 * chol.l().diagonal().map(f64::ln).sum();
            let quadratic = nu.dot(&chol.solve(&nu));
            stats.log_likelihood -= half_log_two_pi + 0.5 * (log_det + quadratic);

            let step = &steps[k];
            let residual = z - known.h * step.mean();
            stats.measurement += &residual * residual.transpose()
                + known.h * step.covariance() * known.h.transpose();
            stats.measured += 1;
        }
        for pair in steps.windows(2) {
            let (before, after) = (&pair[0], &pair[1]);
            let Some(lag_one) = after.lag_one() else {
                continue;
            };
            let e = after.mean() - known.f * before.mean();
            // P_{k,k-1|n} F^T: the cross term, once and transposed.
            let cross = lag_one * known.f.transpose();
            stats.transition += &e * e.transpose()
                + known.f * before.covariance() * known.f.transpose()
                + after.covariance()
                - &cross
                - cross.transpose();
            stats.transitions += 1;
        }
    }
    Ok(stats)
}
