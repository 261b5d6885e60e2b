//! Maximum likelihood (the prediction-error method) with intervals and identifiability.
//!
//! # Method
//! [`MaximumLikelihood::estimate`] maximises [`log_likelihood`] over the free parameters of the
//! problem's [`Parametrisation`](crate::Parametrisation), on the optimiser's scale `theta`
//! (logarithms and a log-Cholesky factor, so no constraint is needed). The minimiser is BFGS
//! on `-ln L / N` (`N` the measurements present, so that the gradient tolerance does not depend
//! on the log's length), gradients by central differences whose `2 p` evaluations run side by
//! side on rayon's pool; it starts from the forms' given matrices and from that point with
//! every log-scale parameter moved by `+-ln 10` (a factor 10 either way), the starts side by
//! side too, and keeps the best (weighed in start order, so the thread count changes nothing).
//!
//! # Intervals
//! The observed information `I = -d^2 ln L / d theta^2` is the central-difference Hessian at
//! the estimate (step `1e-3` on the `theta` scale, a 0.1% change of a variance); its inverse is
//! the covariance of `theta`, carried to the natural parameters by the exact Jacobian
//! (`J I^-1 J^T`) for the standard errors. A 95% interval on a log-scale parameter (a multiplier
//! or a diagonal form's variance) is `theta +- 1.96 se(theta)` mapped through `exp`, so it is
//! asymmetric and stays positive; a full form's variance gets the same on `ln` of the variance
//! (delta method), and its covariances `value +- 1.96 se`.
//!
//! # Identifiability
//! The information's eigenvalues give its rank (eigenvalues above `1e-6` of the largest, the
//! level the finite-difference Hessian resolves) and condition number. Each eigenvector below
//! that level is a direction along which the likelihood is flat: it is carried to the natural
//! parameters by `J` and named, and the combinations the data do determine (the remaining
//! eigenvectors, carried by `J^-T`) are named with it ("the data identify only
//! `Qw[0,0] + 4 Qw[1,1]`"). Parameters in a flat direction get no standard error. A parameter
//! at a bound (below) is stated as such ("q is at its bound 0: the data cannot tell it from
//! 0") and the analysis, and the others' standard errors, are of the remaining parameters.
//!
//! # Bounds
//! A positive parameter whose likelihood stays within the 95% threshold (`chi2_1(0.95) / 2 =
//! 1.92`) of the maximum when it is divided (multiplied) by `e^10` has run to its bound 0
//! (infinity): the data cannot tell it from that bound, and the interval's end is the bound.
//! `theta` is kept within `+-40` of the start so that such a parameter stops at a finite value.

use kalibra_linalg::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::likelihood::{LikelihoodError, log_likelihood};
use crate::optim::{self, Settings, StopReason};
use crate::{NoiseMatrices, NoiseProblem, Parameter, Parametrisation};

/// Why maximum likelihood could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MlError {
    /// Both forms are fixed: there is nothing to estimate.
    #[error("nothing to estimate: both Qw and R are fixed")]
    NothingToEstimate,
    /// The log-likelihood cannot be evaluated at the starting point (for example a singular
    /// innovation covariance `S` there); the message names the run and step.
    #[error("evaluate the log-likelihood at the starting point: {0}")]
    Start(#[source] LikelihoodError),
    /// An option outside its domain.
    #[error("invalid option {name} = {value}")]
    InvalidOption {
        /// Which option.
        name: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Which bound a parameter ran to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    /// Zero: the data are consistent with no such noise.
    Zero,
    /// Infinity: the data put no upper limit on it.
    Infinity,
}

/// Something the user must know about an estimate: it is returned, never silently dropped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
#[non_exhaustive]
pub enum MlWarning {
    /// The optimiser stopped before its gradient tolerance.
    NotConverged {
        /// Why it stopped.
        stop: StopReason,
        /// The largest gradient component of `-ln L / N` at the end.
        gradient: f64,
        /// Iterations run.
        iterations: usize,
    },
    /// A parameter ran to a bound of its domain.
    AtBound {
        /// The parameter.
        parameter: String,
        /// Which bound.
        bound: Bound,
    },
    /// The data do not identify every parameter (see [`Identifiability`]).
    Unidentifiable {
        /// In words.
        message: String,
    },
    /// The observed information is not positive definite with a negative eigenvalue beyond
    /// the finite-difference level: the estimate is not a maximum (a saddle, or not
    /// converged).
    NotAMaximum {
        /// The most negative eigenvalue.
        eigenvalue: f64,
    },
    /// Starts reached different maxima; the best is reported.
    LocalMaxima {
        /// The best log-likelihood.
        best: f64,
        /// The worst converged one.
        other: f64,
    },
    /// The observed information could not be computed (a neighbour of the estimate is
    /// infeasible), so no standard errors are given.
    NoInformation,
}

/// One start of the optimiser.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartOutcome {
    /// The starting point (`theta`).
    pub theta: Vec<f64>,
    /// The log-likelihood reached (`None`: infeasible start).
    pub log_likelihood: Option<f64>,
    /// Whether it converged.
    pub converged: bool,
    /// Iterations run.
    pub iterations: usize,
}

/// A linear combination of natural parameters, with its words.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Combination {
    /// `(parameter name, coefficient)`, the largest coefficient 1 in magnitude; terms below
    /// `1e-3` left out.
    pub terms: Vec<(String, f64)>,
    /// The combination as text (`Qw[0,0] + 4 Qw[1,1]`).
    pub text: String,
}

/// What the data identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// Free parameters.
    pub parameters: usize,
    /// Rank of the observed information (over the parameters not at a bound).
    pub rank: usize,
    /// Largest over smallest eigenvalue (`None` when the rank is short: infinite).
    pub condition_number: Option<f64>,
    /// The information's eigenvalues, ascending (`theta` scale; over the parameters not at
    /// a bound).
    pub eigenvalues: Vec<f64>,
    /// Directions along which the likelihood is flat, on the natural scale.
    pub flat_directions: Vec<Combination>,
    /// When the rank is short: the only combinations the data determine (linearised at the
    /// estimate, natural scale).
    pub identified: Vec<Combination>,
    /// Whether every parameter is identified (`rank == parameters`).
    pub identifiable: bool,
    /// In words.
    pub message: String,
}

/// One free parameter's estimate on the matrices' own scale.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterEstimate {
    /// Name, matrix, entry and kind.
    pub parameter: Parameter,
    /// The estimate.
    pub value: f64,
    /// Its standard error from the observed information (`None` in a flat direction or
    /// without information).
    pub stderr: Option<f64>,
    /// The 95% interval (`None` as for `stderr`); an end at a bound is that bound
    /// (`0`, or `f64::INFINITY`), and so is an end beyond f64 (`e^(theta + 1.96 se)` above
    /// `f64::MAX`): the only non-finite numbers an estimate holds.
    pub ci95: Option<[f64; 2]>,
    /// The bound it ran to, if any.
    pub at_bound: Option<Bound>,
}

/// The maximum-likelihood estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct MlEstimate {
    /// Every free parameter, in the parametrisation's order.
    pub parameters: Vec<ParameterEstimate>,
    /// The optimiser's vector at the estimate.
    pub theta: DVector<f64>,
    /// `Qw`, `R`, `Q` at the estimate.
    pub matrices: NoiseMatrices,
    /// The log-likelihood at the estimate.
    pub log_likelihood: f64,
    /// The log-likelihood at the forms' given matrices.
    pub start_log_likelihood: f64,
    /// Whether the best start met the gradient tolerance.
    pub converged: bool,
    /// Why the best start stopped.
    pub stop: StopReason,
    /// Its iterations.
    pub iterations: usize,
    /// Log-likelihood evaluations over all starts and the information.
    pub evaluations: usize,
    /// Every start.
    pub starts: Vec<StartOutcome>,
    /// The observed information on the `theta` scale (`None` if it could not be computed).
    pub information: Option<DMatrix<f64>>,
    /// What the data identify.
    pub identifiability: Option<Identifiability>,
    /// What the user must know.
    pub warnings: Vec<MlWarning>,
}

/// Maximum-likelihood options.
#[derive(Clone, Debug, PartialEq)]
pub struct MaximumLikelihood {
    gradient_tolerance: f64,
    max_iterations: usize,
    starts: Option<Vec<DVector<f64>>>,
}

impl Default for MaximumLikelihood {
    fn default() -> Self {
        Self::new()
    }
}

/// `chi2_1(0.95) / 2`: the log-likelihood drop of a 95% likelihood-ratio interval.
const HALF_CHI2_95: f64 = 1.920_729_410_347_062;
/// `z_0.975`.
const Z95: f64 = 1.959_963_984_540_054;
/// How far `theta` may move from the start (a factor `e^40`).
const WALL: f64 = 40.0;
/// Eigenvalues below this fraction of the largest count as zero.
const RANK_TOLERANCE: f64 = 1e-6;
/// The step of the information's finite differences on the `theta` scale.
const HESSIAN_STEP: f64 = 1e-3;

impl MaximumLikelihood {
    /// Gradient tolerance `1e-8` on `-ln L / N`, at most 500 iterations per start, the default
    /// starts (see the module docs).
    pub fn new() -> Self {
        Self {
            gradient_tolerance: 1e-8,
            max_iterations: 500,
            starts: None,
        }
    }

    /// The gradient tolerance on `-ln L / N` (largest component).
    ///
    /// # Errors
    /// [`MlError::InvalidOption`] unless positive and finite.
    pub fn gradient_tolerance(mut self, tolerance: f64) -> Result<Self, MlError> {
        if !(tolerance.is_finite() && tolerance > 0.0) {
            return Err(MlError::InvalidOption {
                name: "gradient tolerance",
                value: tolerance,
            });
        }
        self.gradient_tolerance = tolerance;
        Ok(self)
    }

    /// The iteration limit of each start.
    pub fn max_iterations(mut self, iterations: usize) -> Self {
        self.max_iterations = iterations;
        self
    }

    /// Explicit starting points on the `theta` scale, replacing the default ones (the first
    /// is the reference for the bounds of `theta`).
    pub fn starts(mut self, starts: Vec<DVector<f64>>) -> Self {
        self.starts = Some(starts);
        self
    }

    fn default_starts(noise: &Parametrisation) -> Vec<DVector<f64>> {
        let start = noise.start();
        let log_scale: Vec<bool> = noise
            .parameters()
            .iter()
            .map(|p| p.positive() && noise_is_log(noise, p))
            .collect();
        let shifted = |by: f64| {
            DVector::from_iterator(
                start.len(),
                start
                    .iter()
                    .zip(&log_scale)
                    .map(|(t, &log)| if log { t + by } else { *t }),
            )
        };
        let ln10 = std::f64::consts::LN_10;
        vec![start.clone(), shifted(ln10), shifted(-ln10)]
    }

    /// Maximises the log-likelihood.
    ///
    /// ```
    /// use kalibra_tune::{CovarianceForm, DMatrix, DVector, MaximumLikelihood, NoiseProblem,
    ///     Parametrisation, Start};
    ///
    /// // A scalar random walk observed in noise, both variances unknown.
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let zs = [0.1, 0.5, 0.2, 1.1, 1.6, 1.2, 2.3, 2.0, 2.9, 3.4, 2.8, 3.9, 4.4, 4.1, 5.2];
    /// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    ///     CovarianceForm::scaled(one(1.0)))?;
    /// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0),
    ///     kalibra_tune::Start::PredictFirst, noise, vec![run])?;
    /// let est = MaximumLikelihood::new().estimate(&problem)?;
    /// assert!(est.converged);
    /// assert!(est.log_likelihood >= est.start_log_likelihood);
    /// assert_eq!(est.parameters[0].parameter.name, "q");
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`MlError::InvalidOption`] for more iterations than
    /// [`ITERATION_LIMIT`](crate::ITERATION_LIMIT);
    /// [`MlError::NothingToEstimate`]; [`MlError::Start`] when the likelihood cannot be
    /// evaluated at the forms' given matrices (the message names the cause: a singular `S`
    /// at a run and step, a non-finite density). Non-convergence, a parameter at a bound,
    /// unidentifiable parameters and local maxima are [`MlWarning`]s of the estimate.
    pub fn estimate(&self, problem: &NoiseProblem) -> Result<MlEstimate, MlError> {
        self.estimate_with(problem.noise(), problem.measurement_count(), &|theta| {
            log_likelihood(problem, theta)
        })
    }

    /// [`MaximumLikelihood::estimate`] on any log-likelihood of `noise`'s `theta` (a
    /// nonlinear model's through the EKF or the UKF, `ml_nonlinear`), with `measurements`
    /// the measurements it sums over (the objective's scale). A candidate where `ll` fails is
    /// infeasible: a backtrack of the line search, never a panic.
    pub(crate) fn estimate_with(
        &self,
        noise: &Parametrisation,
        measurements: usize,
        ll: &(dyn Fn(&[f64]) -> Result<f64, LikelihoodError> + Sync),
    ) -> Result<MlEstimate, MlError> {
        // Checked first, so that an estimate's time is bounded by that many iterations.
        if self.max_iterations > crate::ITERATION_LIMIT {
            return Err(MlError::InvalidOption {
                name: "max iterations (at most kalibra_tune::ITERATION_LIMIT = 100000)",
                value: self.max_iterations as f64,
            });
        }
        if noise.is_empty() {
            return Err(MlError::NothingToEstimate);
        }
        let reference = noise.start();
        let start_ll = ll(reference.as_slice()).map_err(MlError::Start)?;
        let starts = self
            .starts
            .clone()
            .unwrap_or_else(|| Self::default_starts(noise));
        let scale = measurements as f64;
        let wall_at = match starts.first() {
            Some(s) => s.clone(),
            None => reference.clone(),
        };
        let objective = |theta: &[f64]| -> Option<f64> {
            if theta
                .iter()
                .zip(wall_at.iter())
                .any(|(t, w)| (t - w).abs() > WALL)
            {
                return None;
            }
            ll(theta).ok().map(|l| -l / scale)
        };
        let settings = Settings {
            gradient_tolerance: self.gradient_tolerance,
            max_iterations: self.max_iterations,
        };
        // The starts are independent: they run side by side on rayon's pool, and their
        // outcomes are weighed below in start order, so the estimate does not depend on the
        // number of threads (`cargo xtask bench tune` times 1 and 2 threads).
        let runs: Vec<Option<optim::Outcome>> = starts
            .par_iter()
            .map(|s| {
                if s.len() == noise.len() {
                    optim::minimise(&objective, s.as_slice(), settings)
                } else {
                    None
                }
            })
            .collect();
        let mut outcomes = Vec::new();
        let mut best: Option<optim::Outcome> = None;
        let mut evaluations = 1;
        for (s, out) in starts.iter().zip(runs) {
            outcomes.push(StartOutcome {
                theta: s.iter().copied().collect(),
                log_likelihood: out.as_ref().map(|o| -o.f * scale),
                converged: out.as_ref().is_some_and(|o| o.stop == StopReason::Gradient),
                iterations: out.as_ref().map_or(0, |o| o.iterations),
            });
            if let Some(o) = out {
                evaluations += o.evaluations;
                let better = best.as_ref().is_none_or(|b| {
                    let (conv_o, conv_b) = (
                        o.stop == StopReason::Gradient,
                        b.stop == StopReason::Gradient,
                    );
                    (conv_o && !conv_b) || (conv_o == conv_b && o.f < b.f)
                });
                if better {
                    best = Some(o);
                }
            }
        }
        // The reference start is feasible (checked above); if explicit starts all failed,
        // fall back to it.
        let best = match best {
            Some(b) => b,
            None => {
                // Every start failed: say why the first one did (a singular S there, ...).
                if let Some(first) = starts.first()
                    && let Err(e) = ll(first.as_slice())
                {
                    return Err(MlError::Start(e));
                }
                let o = optim::minimise(&objective, reference.as_slice(), settings).ok_or(
                    MlError::Start(LikelihoodError::NonFinite { run: 0, update: 0 }),
                )?;
                evaluations += o.evaluations;
                o
            }
        };
        let mut warnings = Vec::new();
        let converged = best.stop == StopReason::Gradient;
        if !converged {
            warnings.push(MlWarning::NotConverged {
                stop: best.stop,
                gradient: best.gradient_norm(),
                iterations: best.iterations,
            });
        }
        let log_likelihood_best = -best.f * scale;
        let converged_lls: Vec<f64> = outcomes
            .iter()
            .filter(|o| o.converged)
            .filter_map(|o| o.log_likelihood)
            .collect();
        if let Some(worst) = converged_lls.iter().copied().reduce(f64::min)
            && log_likelihood_best - worst > 1e-3
        {
            warnings.push(MlWarning::LocalMaxima {
                best: log_likelihood_best,
                other: worst,
            });
        }
        let theta = best.x.clone();
        // The estimate is feasible (the optimiser only accepts feasible points).
        let matrices = noise
            .matrices(&theta)
            .map_err(|e| MlError::Start(LikelihoodError::Noise(e)))?;
        let natural = noise
            .natural(&theta)
            .map_err(|e| MlError::Start(LikelihoodError::Noise(e)))?;
        let jac = noise
            .jacobian(&theta)
            .map_err(|e| MlError::Start(LikelihoodError::Noise(e)))?;
        let params = noise.parameters();
        let p = params.len();

        // Observed information on the theta scale, of ln L (not of the scaled objective).
        let ll = |t: &[f64]| ll(t).ok();
        let information = optim::hessian(&ll, &theta, log_likelihood_best, HESSIAN_STEP)
            .map(|h| DMatrix::from_fn(p, p, |i, j| -h[i][j]));
        evaluations += 2 * p * p + 1;
        // Bounds: a positive log-scale parameter whose likelihood is flat towards 0 or
        // infinity.
        let mut at_bound = vec![None; p];
        for (i, param) in params.iter().enumerate() {
            if !(param.positive() && noise_is_log(noise, param)) {
                continue;
            }
            let mut flat = |step: f64| {
                let mut t = theta.clone();
                t[i] += step;
                evaluations += 1;
                ll(&t).is_some_and(|l| log_likelihood_best - l < HALF_CHI2_95)
            };
            let (down, up) = (flat(-10.0), flat(10.0));
            // Flat both ways: the side the estimate moved to from the start is the bound it
            // ran to (a variance of 1e-13 is flat both ways, all of it near 0).
            let bound = match (down, up) {
                (true, false) => Some(Bound::Zero),
                (false, true) => Some(Bound::Infinity),
                (true, true) if theta[i] < wall_at[i] => Some(Bound::Zero),
                (true, true) => Some(Bound::Infinity),
                (false, false) => None,
            };
            if let Some(bound) = bound {
                at_bound[i] = Some(bound);
                warnings.push(MlWarning::AtBound {
                    parameter: param.name.clone(),
                    bound,
                });
            }
        }
        let identifiability = information
            .as_ref()
            .map(|info| identifiability(info, &jac, &params, &at_bound));
        let mut stderr_theta: Vec<Option<f64>> = vec![None; p];
        let mut stderr_nat: Vec<Option<f64>> = vec![None; p];
        match (&information, &identifiability) {
            (Some(info), Some(id)) => {
                if let Some(min) = id.eigenvalues.first()
                    && *min < -RANK_TOLERANCE * id.eigenvalues.last().copied().unwrap_or(0.0)
                {
                    warnings.push(MlWarning::NotAMaximum { eigenvalue: *min });
                }
                if !id.identifiable {
                    warnings.push(MlWarning::Unidentifiable {
                        message: id.message.clone(),
                    });
                }
                // A parameter at a bound is not estimated inside its domain: the others'
                // covariance is that of the interior block, so its flat direction does not
                // leak into theirs.
                let interior: Vec<usize> = (0..p).filter(|&i| at_bound[i].is_none()).collect();
                let (sub_cov, sub_flat) =
                    pseudo_inverse(&info.select_rows(&interior).select_columns(&interior));
                let mut cov = DMatrix::zeros(p, p);
                for (a, &i) in interior.iter().enumerate() {
                    for (b, &j) in interior.iter().enumerate() {
                        cov[(i, j)] = sub_cov[(a, b)];
                    }
                }
                let mut flat: Vec<DVector<f64>> = sub_flat
                    .iter()
                    .map(|v| {
                        let mut full = DVector::zeros(p);
                        for (a, &i) in interior.iter().enumerate() {
                            full[i] = v[a];
                        }
                        full
                    })
                    .collect();
                flat.extend((0..p).filter(|i| at_bound[*i].is_some()).map(|i| {
                    let mut e = DVector::zeros(p);
                    e[i] = 1.0;
                    e
                }));
                for i in 0..p {
                    // A parameter with weight in a flat direction has no standard error.
                    let in_flat = flat.iter().any(|v| v[i].abs() > 1e-3);
                    if !in_flat && cov[(i, i)] > 0.0 {
                        stderr_theta[i] = Some(cov[(i, i)].sqrt());
                        stderr_nat[i] = Some(natural_stderr(&jac, &cov, i));
                    }
                }
            }
            _ => warnings.push(MlWarning::NoInformation),
        }
        let parameters = params
            .into_iter()
            .enumerate()
            .map(|(i, parameter)| {
                let value = natural[i];
                let ci95 = match (stderr_theta[i], stderr_nat[i]) {
                    (Some(se_t), Some(se)) => {
                        let mut ci = if parameter.positive() && noise_is_log(noise, &parameter) {
                            [(theta[i] - Z95 * se_t).exp(), (theta[i] + Z95 * se_t).exp()]
                        } else if parameter.positive() {
                            let r = Z95 * se / value;
                            [value * (-r).exp(), value * r.exp()]
                        } else {
                            [value - Z95 * se, value + Z95 * se]
                        };
                        // For a multiplier `theta = ln s`: exp(theta) is s; for a diagonal
                        // variance likewise; the full form's log-variance is `ln value`.
                        match at_bound[i] {
                            Some(Bound::Zero) => ci[0] = 0.0,
                            Some(Bound::Infinity) => ci[1] = f64::INFINITY,
                            None => {}
                        }
                        Some(ci)
                    }
                    _ => None,
                };
                ParameterEstimate {
                    parameter,
                    value,
                    stderr: stderr_nat[i],
                    ci95,
                    at_bound: at_bound[i],
                }
            })
            .collect();
        Ok(MlEstimate {
            parameters,
            theta: DVector::from_vec(theta),
            matrices,
            log_likelihood: log_likelihood_best,
            start_log_likelihood: start_ll,
            converged,
            stop: best.stop,
            iterations: best.iterations,
            evaluations,
            starts: outcomes,
            information,
            identifiability,
            warnings,
        })
    }
}

/// The standard error of natural parameter `i`, `sqrt((J C J^T)_ii)`, with row `i` of `J`
/// brought to a largest entry near 1 by a power of two first: a variance near `1e300` has a
/// representable standard error whose square is not.
fn natural_stderr(jac: &DMatrix<f64>, cov: &DMatrix<f64>, i: usize) -> f64 {
    let row = jac.row(i);
    let Some(e) = kalibra_linalg::binary_exponent(row.amax()) else {
        return 0.0;
    };
    let row = row.map(|v| kalibra_linalg::ldexp(v, -e));
    let variance = (&row * cov * row.transpose())[(0, 0)];
    kalibra_linalg::ldexp(variance.max(0.0).sqrt(), e)
}

/// Whether `param`'s own `theta` entry is the logarithm of its natural value (a multiplier, a
/// diagonal form's variance), so that its interval is the mapped `theta` interval.
fn noise_is_log(noise: &crate::Parametrisation, param: &Parameter) -> bool {
    let form = match param.matrix {
        crate::NoiseMatrix::Qw => noise.qw_form(),
        crate::NoiseMatrix::R => noise.r_form(),
    };
    matches!(
        form.kind(),
        crate::FormKind::Scaled | crate::FormKind::Diagonal
    )
}

/// The pseudo-inverse of a symmetric information matrix on the eigenvectors above the rank
/// tolerance, and the eigenvectors below it (the flat directions).
fn pseudo_inverse(info: &DMatrix<f64>) -> (DMatrix<f64>, Vec<DVector<f64>>) {
    let p = info.nrows();
    // nalgebra's eigen-decomposition panics on an empty matrix (every parameter at a bound).
    if p == 0 {
        return (info.clone(), Vec::new());
    }
    let eig = info.clone().symmetric_eigen();
    let max = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(*v));
    let mut inv = DMatrix::zeros(p, p);
    let mut flat = Vec::new();
    for k in 0..p {
        let v = eig.eigenvectors.column(k).into_owned();
        let l = eig.eigenvalues[k];
        if l > RANK_TOLERANCE * max {
            inv += &v * v.transpose() / l;
        } else {
            flat.push(v);
        }
    }
    (inv, flat)
}

/// A combination `sum c_i name_i`, scaled so the largest `|c_i|` is 1.
fn combination(coefficients: &DVector<f64>, params: &[Parameter]) -> Combination {
    let max = coefficients.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // The sign that makes the largest coefficient positive.
    let sign = coefficients
        .iter()
        .find(|v| v.abs() == max)
        .map_or(1.0, |v| v.signum());
    let mut terms = Vec::new();
    let mut text = String::new();
    for (c, p) in coefficients.iter().zip(params) {
        let c = sign * c / max;
        if c.abs() < 1e-3 {
            continue;
        }
        terms.push((p.name.clone(), c));
        let mag = format_coefficient(c.abs());
        let name = &p.name;
        let term = if mag.is_empty() {
            name.clone()
        } else {
            format!("{mag} {name}")
        };
        if text.is_empty() {
            text = if c < 0.0 { format!("-{term}") } else { term };
        } else {
            text.push_str(if c < 0.0 { " - " } else { " + " });
            text.push_str(&term);
        }
    }
    Combination { terms, text }
}

/// A coefficient to three significant digits, empty for 1.
fn format_coefficient(c: f64) -> String {
    if (c - 1.0).abs() < 5e-4 {
        return String::new();
    }
    let digits = (2 - c.log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{c:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Rank, condition number and the named flat and identified directions of `info`. A
/// parameter at a bound is stated as such (the data cannot tell it from the bound) and left
/// out of the analysis of the others: its flat direction, carried by a Jacobian that
/// vanishes there (`d s / d ln s = s` near 0), would otherwise be named after whichever
/// other parameter it leans on.
fn identifiability(
    info: &DMatrix<f64>,
    jac: &DMatrix<f64>,
    params: &[Parameter],
    at_bound: &[Option<Bound>],
) -> Identifiability {
    let p = info.nrows();
    let interior: Vec<usize> = (0..p).filter(|&i| at_bound[i].is_none()).collect();
    if interior.len() < p {
        let inner = identifiability(
            &info.select_rows(&interior).select_columns(&interior),
            &jac.select_rows(&interior).select_columns(&interior),
            &interior
                .iter()
                .map(|&i| params[i].clone())
                .collect::<Vec<_>>(),
            &vec![None; interior.len()],
        );
        let mut statements = Vec::new();
        let mut flat_directions = Vec::new();
        for (i, bound) in at_bound.iter().enumerate() {
            let name = &params[i].name;
            let Some(bound) = bound else { continue };
            statements.push(match bound {
                Bound::Zero => format!("{name} is at its bound 0: the data cannot tell it from 0"),
                Bound::Infinity => {
                    format!("{name} is at its bound infinity: the data put no upper limit on it")
                }
            });
            flat_directions.push(Combination {
                terms: vec![(name.clone(), 1.0)],
                text: name.clone(),
            });
        }
        flat_directions.extend(inner.flat_directions);
        let others = match interior.len() {
            0 => String::new(),
            1 if inner.identifiable => format!("; {} is identified", params[interior[0]].name),
            _ if inner.identifiable => {
                let names: Vec<&str> = interior.iter().map(|&i| params[i].name.as_str()).collect();
                format!("; {} are identified", names.join(", "))
            }
            _ => format!("; of the others, {}", inner.message),
        };
        return Identifiability {
            parameters: p,
            rank: inner.rank,
            condition_number: None,
            eigenvalues: inner.eigenvalues,
            message: format!("{}{others}", statements.join("; ")),
            flat_directions,
            identified: inner.identified,
            identifiable: false,
        };
    }
    if p == 0 {
        // Every parameter at a bound: nothing left to analyse (and nalgebra's
        // eigen-decomposition panics on an empty matrix).
        return Identifiability {
            parameters: 0,
            rank: 0,
            condition_number: None,
            eigenvalues: Vec::new(),
            flat_directions: Vec::new(),
            identified: Vec::new(),
            identifiable: true,
            message: String::new(),
        };
    }
    let eig = info.clone().symmetric_eigen();
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let eigenvalues: Vec<f64> = order.iter().map(|&k| eig.eigenvalues[k]).collect();
    let max = eigenvalues.last().copied().unwrap_or(0.0).max(0.0);
    let rank = eigenvalues
        .iter()
        .filter(|&&l| l > RANK_TOLERANCE * max)
        .count();
    let min = eigenvalues.first().copied().unwrap_or(0.0);
    let condition_number = (rank == p && min > 0.0).then(|| max / min);
    // Only the directions matter (each combination is scaled to a largest coefficient of 1),
    // so `J` is taken at a power-of-two scale near 1: `J v` cannot overflow for a `J` near
    // f64::MAX (the natural values' scale).
    let jac = &match kalibra_linalg::binary_exponent(jac.amax()) {
        Some(e) => jac.map(|v| kalibra_linalg::ldexp(v, -e)),
        None => jac.clone(),
    };
    let jac_inv_t = jac.clone().try_inverse().map(|j| j.transpose());
    let mut flat_directions = Vec::new();
    let mut identified = Vec::new();
    for &k in &order {
        let v = eig.eigenvectors.column(k).into_owned();
        if eig.eigenvalues[k] > RANK_TOLERANCE * max {
            if rank < p
                && let Some(jt) = &jac_inv_t
            {
                identified.push(combination(&(jt * &v), params));
            }
        } else {
            flat_directions.push(combination(&(jac * &v), params));
        }
    }
    let identifiable = rank == p;
    let message = if identifiable {
        format!(
            "all {p} parameters are identified (information rank {rank}, condition number {})",
            condition_number.map_or("infinite".to_string(), |c| format!("{c:.3e}"))
        )
    } else {
        let flat: Vec<&str> = flat_directions.iter().map(|c| c.text.as_str()).collect();
        let ident: Vec<&str> = identified.iter().map(|c| c.text.as_str()).collect();
        format!(
            "the data identify only {} of {p} parameter combinations: {}; the likelihood is \
             flat along {}",
            rank,
            if ident.is_empty() {
                "none".to_string()
            } else {
                ident.join("; ")
            },
            flat.join("; ")
        )
    };
    Identifiability {
        parameters: p,
        rank,
        condition_number,
        eigenvalues,
        flat_directions,
        identified,
        identifiable,
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{NoiseMatrix, ParameterKind};

    fn param(name: &str) -> Parameter {
        Parameter {
            name: name.to_string(),
            matrix: NoiseMatrix::Qw,
            entry: None,
            kind: ParameterKind::Variance,
        }
    }

    #[test]
    fn combinations_read_as_words() {
        let params = [param("q_pos"), param("q_vel")];
        let c = combination(&DVector::from_vec(vec![-0.25, -1.0]), &params);
        assert_eq!(c.text, "0.25 q_pos + q_vel");
        let c = combination(&DVector::from_vec(vec![0.25, 1.0]), &params);
        assert_eq!(c.text, "0.25 q_pos + q_vel");
        let c = combination(&DVector::from_vec(vec![1.0, -4.0]), &params);
        assert_eq!(c.text, "-0.25 q_pos + q_vel");
        assert_eq!(format_coefficient(4.0), "4");
        assert_eq!(format_coefficient(0.123_456), "0.123");
        assert_eq!(format_coefficient(1234.6), "1235");
    }

    /// An information matrix of rank 1, `w w^T` with `w = (1, 4)`: the likelihood depends
    /// only on `theta_0 + 4 theta_1`, which is what the identified combination must say.
    #[test]
    fn a_rank_deficient_information_is_named() {
        let params = [param("q_pos"), param("q_vel")];
        let w = DVector::from_vec(vec![1.0, 4.0]);
        let info = &w * w.transpose() * 10.0;
        let id = identifiability(&info, &DMatrix::identity(2, 2), &params, &[None, None]);
        assert_eq!(id.rank, 1);
        assert!(!id.identifiable);
        assert_eq!(id.identified.len(), 1);
        assert_eq!(id.identified[0].text, "0.25 q_pos + q_vel");
        assert_eq!(id.flat_directions[0].text, "q_pos - 0.25 q_vel");
        assert!(
            id.message.contains("identify only 1 of 2"),
            "{}",
            id.message
        );
        assert!(id.condition_number.is_none());
        let full = identifiability(
            &DMatrix::identity(2, 2),
            &DMatrix::identity(2, 2),
            &params,
            &[None, None],
        );
        assert!(full.identifiable && full.condition_number == Some(1.0));
    }
}
