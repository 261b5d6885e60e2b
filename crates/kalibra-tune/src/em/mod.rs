//! Expectation-maximisation for `Qw` and `R` ([`Em`]); the M-step of each form and its
//! derivation are in `mstep.rs`, the E-step in `estep.rs`.

mod estep;
mod mstep;

use kalibra_filters::FilterError;
use kalibra_linalg::{DMatrix, DVector};
use kalibra_models::ModelError;

use crate::{CovarianceForm, FormKind, NoiseMatrices, NoiseMatrix, NoiseProblem, Parameter};
pub(crate) use estep::Known;
pub(crate) use mstep::Structure;

/// The default relative tolerance of [`Em`]: converged when an iteration raises the
/// log-likelihood by at most this fraction of its magnitude.
pub const EM_TOLERANCE: f64 = 1e-8;

/// The default cap on [`Em`]'s iterations.
pub const EM_MAX_ITERATIONS: usize = 500;

/// What made EM stop or refuse.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EmError {
    /// The filter or the smoother failed on a run at the parameters of an iteration.
    #[error("filter or smoother on run {run} at iteration {iteration}: {source}")]
    Filter {
        /// The iteration (0: the starting point).
        iteration: usize,
        /// The run.
        run: usize,
        /// What failed.
        source: FilterError,
    },
    /// The models refused the parameters of an iteration (a `Q` or `R` not a covariance).
    #[error("models at iteration {iteration}: {source}")]
    Model {
        /// The iteration (0: the starting point).
        iteration: usize,
        /// What was refused.
        source: ModelError,
    },
    /// A form EM cannot honour in closed form.
    #[error("estimate {what} by EM: {reason}")]
    Unsupported {
        /// Which matrix.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// The log has nothing to estimate a free matrix from.
    #[error("estimate {what}: the log has no {missing}")]
    NoData {
        /// Which matrix.
        what: &'static str,
        /// What the log lacks.
        missing: &'static str,
    },
    /// A setting out of its range.
    #[error("use {name} = {value}")]
    InvalidParameter {
        /// Which setting.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// More iterations asked for than [`ITERATION_LIMIT`](crate::ITERATION_LIMIT).
    #[error(
        "use at most {limit} EM iterations ({asked} asked for): each runs a filter and a \
         smoother over every run"
    )]
    TooManyIterations {
        /// The iterations asked for.
        asked: usize,
        /// [`ITERATION_LIMIT`](crate::ITERATION_LIMIT).
        limit: usize,
    },
    /// A parameter estimate or the log-likelihood left the range of f64.
    #[error("estimate {what}: it is not finite at iteration {iteration}")]
    NonFinite {
        /// Which matrix.
        what: &'static str,
        /// The iteration that produced it.
        iteration: usize,
    },
}

/// Expectation-maximisation for `Qw` and `R` of a linear-Gaussian model (Shumway and Stoffer
/// 1982), honouring each matrix's form, and when it stops: at a relative tolerance on the
/// log-likelihood's increase, or after exactly a given number of iterations.
///
/// # The method
/// Each iteration runs the Kalman filter and the Rauch-Tung-Striebel smoother (with its lag-one
/// covariances, [`kalibra_filters::smooth`]) over every run at the current parameters (the
/// E-step, which also gives their log-likelihood), then sets `Qw` and `R` to the maximisers of
/// the expected complete-data log-likelihood within their forms (the M-step; the derivation
/// for each form is in `mstep.rs`: full form `X = S`, the smoother's statistic; diagonal form
/// its diagonal; scaled form `q = tr(N^+ S) / rank N`; through `G` of full column rank,
/// `Qw`'s statistic is `G^+ S_Q G^+T`; a full form with fixed entries has no closed form and
/// is refused). Every iteration increases the log-likelihood or leaves it
/// unchanged (the EM inequality); `tests/em.rs` checks it as a property.
///
/// # Conventions
/// * `x0` and `P0` are given, not estimated; where they sit is the problem's [`Start`](crate::Start)
///   (pykalman's EM puts them at the first measurement: [`Start::UpdateFirst`](crate::Start::UpdateFirst)).
/// * A step without a measurement adds no term to `R`'s statistic or to the log-likelihood;
///   its transition counts in `Q`'s (as pykalman's masked rows).
/// * Several runs of one system add their statistics: `R`'s is divided by the number of
///   measured steps over every run, `Q`'s by the number of transitions over every run.
///
/// # Checked
/// Against pykalman 0.11.2's `KalmanFilter.em` with unconstrained `Q` and `R`, every one of
/// ten iterations to 1e-9 relative (`tests/em_pykalman.rs`, fixture written by
/// `tests/fixtures/make_pykalman_em.py`).
///
/// ```
/// use kalibra_tune::Em;
/// let em = Em::new().tolerance(1e-6)?.max_iterations(200);
/// assert_eq!(em.iteration_cap(), 200);
/// let exact = Em::new().exact_iterations(10);
/// assert_eq!(exact.iteration_cap(), 10);
/// # Ok::<(), kalibra_tune::EmError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Em {
    tolerance: f64,
    max_iterations: usize,
    exact: bool,
}

impl Default for Em {
    fn default() -> Self {
        Self::new()
    }
}

impl Em {
    /// Stops at [`EM_TOLERANCE`] or after [`EM_MAX_ITERATIONS`] iterations.
    pub fn new() -> Self {
        Self {
            tolerance: EM_TOLERANCE,
            max_iterations: EM_MAX_ITERATIONS,
            exact: false,
        }
    }

    /// Converged when an iteration raises the log-likelihood `l` by at most
    /// `tolerance * max(|l|, 1)`.
    ///
    /// # Errors
    /// [`EmError::InvalidParameter`] unless `tolerance` is finite and positive.
    pub fn tolerance(mut self, tolerance: f64) -> Result<Self, EmError> {
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(EmError::InvalidParameter {
                name: "EM tolerance",
                value: tolerance,
            });
        }
        self.tolerance = tolerance;
        Ok(self)
    }

    /// Stops after at most `iterations` iterations (not converged then).
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self.exact = false;
        self
    }

    /// Runs exactly `iterations` iterations, whatever the log-likelihood does (a comparison
    /// with another implementation's `n_iter`); the result is reported as converged.
    pub fn exact_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self.exact = true;
        self
    }

    /// The most iterations EM runs.
    pub fn iteration_cap(&self) -> usize {
        self.max_iterations
    }

    /// Estimates the problem's free noise parameters by EM from its starting point (the
    /// given matrices of the forms; a scaled form starts at its nominal matrix).
    ///
    /// ```
    /// use kalibra_tune::{CovarianceForm, DMatrix, DVector, Em, NoiseProblem, Parametrisation,
    ///     Start};
    ///
    /// // A scalar random walk: q and r both unknown, started at 1.
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    ///     CovarianceForm::scaled(one(1.0)))?;
    /// let zs = [0.3, -0.1, 0.8, 1.1, 0.6, 1.9, 2.2, 1.7, 2.5, 2.4];
    /// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(10.0),
    ///     Start::PredictFirst, noise, vec![run])?;
    /// let fit = Em::new().exact_iterations(20).estimate(&problem)?;
    /// assert_eq!(fit.iterations, 20);
    /// // EM never lowers the likelihood.
    /// assert!(fit.log_likelihood.windows(2).all(|w| w[1] >= w[0] - 1e-9));
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`EmError::TooManyIterations`] for a cap above [`ITERATION_LIMIT`](crate::ITERATION_LIMIT)
    /// (checked first, so the time EM may take is bounded by that many E-steps);
    /// [`EmError::Unsupported`] for a full form with fixed entries (no closed-form M-step) or
    /// a `G` without full column rank; [`EmError::NoData`] when a free matrix has nothing to
    /// be estimated from; [`EmError::Filter`], [`EmError::Model`] and [`EmError::NonFinite`]
    /// naming the iteration whose parameters, log-likelihood or multiplier left f64.
    pub fn estimate(&self, problem: &NoiseProblem) -> Result<EmEstimate, EmError> {
        if self.max_iterations > crate::ITERATION_LIMIT {
            return Err(EmError::TooManyIterations {
                asked: self.max_iterations,
                limit: crate::ITERATION_LIMIT,
            });
        }
        let noise = problem.noise();
        let known = Known {
            f: problem.f(),
            h: problem.h(),
            x0: problem.x0(),
            p0: problem.p0(),
            start: problem.start(),
        };
        let qw = structure(noise.qw_form());
        let r = structure(noise.r_form());
        let (qw, r, log_likelihood, iterations, converged) = self.iterate(
            known,
            noise.g(),
            (&qw, noise.qw_form().value().clone()),
            (&r, noise.r_form().value().clone()),
            problem.runs(),
        )?;
        let q = match noise.g() {
            Some(g) => g * &qw * g.transpose(),
            None => qw.clone(),
        };
        let parameters = noise.parameters();
        let values: Vec<f64> = parameters
            .iter()
            .map(|p| natural_value(p, noise.qw_form(), noise.r_form(), &qw, &r))
            .collect();
        // A multiplier beyond f64 (a finite matrix over a tiny nominal one).
        if !values.iter().all(|v| v.is_finite()) {
            return Err(EmError::NonFinite {
                what: "multiplier",
                iteration: iterations,
            });
        }
        Ok(EmEstimate {
            matrices: NoiseMatrices { qw, r, q },
            parameters,
            values,
            log_likelihood,
            iterations,
            converged,
        })
    }

    /// Runs EM from the starting matrices: see the type's docs. Returns `Qw`, `R`,
    /// the log-likelihoods, the iterations and whether it converged.
    #[allow(clippy::type_complexity)]
    pub(crate) fn iterate(
        &self,
        known: Known<'_>,
        g: Option<&DMatrix<f64>>,
        qw: (&Structure, DMatrix<f64>),
        r: (&Structure, DMatrix<f64>),
        runs: &[Vec<Option<DVector<f64>>>],
    ) -> Result<(DMatrix<f64>, DMatrix<f64>, Vec<f64>, usize, bool), EmError> {
        let (qw_structure, mut qw_now) = qw;
        let (r_structure, mut r_now) = r;
        let g_pinv = g.map(mstep::left_pseudo_inverse).transpose()?;
        let full_q = |qw: &DMatrix<f64>| match g {
            Some(g) => g * qw * g.transpose(),
            None => qw.clone(),
        };
        let mut log_likelihood = Vec::with_capacity(self.max_iterations.min(1024) + 1);
        let mut iteration = 0;
        let converged = loop {
            let stats = estep::expectation(known, &full_q(&qw_now), &r_now, runs, iteration)?;
            // Every term is finite (the filter checks its steps), but their sum may not be.
            if !stats.log_likelihood.is_finite() {
                return Err(EmError::NonFinite {
                    what: "log-likelihood",
                    iteration,
                });
            }
            log_likelihood.push(stats.log_likelihood);
            if let [.., before, now] = log_likelihood[..]
                && !self.exact
                && (now - before).abs() <= self.tolerance * now.abs().max(1.0)
            {
                break true;
            }
            if iteration == self.max_iterations {
                break self.exact;
            }
            if *qw_structure != Structure::Fixed {
                if stats.transitions == 0 {
                    return Err(EmError::NoData {
                        what: "Qw",
                        missing: "transition (every run has one step)",
                    });
                }
                let mut s = stats.transition / stats.transitions as f64;
                if let Some(pinv) = &g_pinv {
                    s = pinv * s * pinv.transpose();
                }
                qw_now = mstep::maximise(qw_structure, &s, &qw_now, "Qw")?;
            }
            if *r_structure != Structure::Fixed {
                if stats.measured == 0 {
                    return Err(EmError::NoData {
                        what: "R",
                        missing: "measurement",
                    });
                }
                let s = stats.measurement / stats.measured as f64;
                r_now = mstep::maximise(r_structure, &s, &r_now, "R")?;
            }
            iteration += 1;
            for (what, x) in [("Qw", &qw_now), ("R", &r_now)] {
                if !x.iter().all(|v| v.is_finite()) {
                    return Err(EmError::NonFinite { what, iteration });
                }
            }
        };
        Ok((qw_now, r_now, log_likelihood, iteration, converged))
    }
}

/// The M-step's view of a form: what EM may change.
pub(crate) fn structure(form: &CovarianceForm) -> Structure {
    let value = form.value();
    let d = form.dim();
    match form.kind() {
        FormKind::Fixed => Structure::Fixed,
        FormKind::Scaled => Structure::Scaled {
            nominal: value.clone(),
        },
        FormKind::Diagonal => Structure::Diagonal {
            fixed: (0..d)
                .map(|i| form.is_fixed(i, i).then(|| value[(i, i)]))
                .collect(),
        },
        FormKind::Full => Structure::Full {
            fixed: (0..d)
                .flat_map(|i| (0..=i).map(move |j| (i, j)))
                .filter(|&(i, j)| form.is_fixed(i, j))
                .map(|(i, j)| (i, j, value[(i, j)]))
                .collect(),
        },
    }
}

/// A free parameter's value on the matrices' own scale: the entry, or for a multiplier the
/// `s` of `X = s V` (the least-squares ratio `<X, V> / <V, V>`, exact when `X` is a multiple).
pub(crate) fn natural_value(
    parameter: &Parameter,
    qw_form: &CovarianceForm,
    r_form: &CovarianceForm,
    qw: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> f64 {
    let (form, x) = match parameter.matrix {
        NoiseMatrix::Qw => (qw_form, qw),
        NoiseMatrix::R => (r_form, r),
    };
    match parameter.entry {
        Some((i, j)) => x[(i, j)],
        None => crate::noise::multiplier(x, form.value()),
    }
}

/// EM's result: the estimate, the log-likelihood of every iterate and how it stopped.
#[derive(Clone, Debug, PartialEq)]
pub struct EmEstimate {
    /// The estimate: `Qw`, `R` and `Q = G Qw G^T`.
    pub matrices: NoiseMatrices,
    /// The free parameters, in the parametrisation's order.
    pub parameters: Vec<Parameter>,
    /// Their estimates on the matrices' own scale (an entry, or a scaled form's multiplier).
    pub values: Vec<f64>,
    /// The log-likelihood of the starting point and of every iterate:
    /// `log_likelihood[i]` after `i` iterations, the last one the estimate's; non-decreasing
    /// up to rounding.
    pub log_likelihood: Vec<f64>,
    /// The number of iterations (M-steps) run.
    pub iterations: usize,
    /// Whether the relative tolerance was met (always true for exact iterations).
    pub converged: bool,
}

impl EmEstimate {
    /// The log-likelihood at the estimate.
    pub fn final_log_likelihood(&self) -> f64 {
        self.log_likelihood.last().copied().unwrap_or(f64::NAN)
    }
}
