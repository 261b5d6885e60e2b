//! J1/J2 on every parameter ([`ParameterSweep`]).

use kalibra_filters::{Filter, FilterError, Kf};
use kalibra_linalg::{DMatrix, Dyn};
use kalibra_metrics::{JHorizon, MetricsError, SweepPoint, crossover, j_step};
use kalibra_models::{LinearGaussian, LinearObservation, ModelError};
use serde::{Deserialize, Serialize};

use crate::{FormKind, NoiseMatrices, NoiseMatrix, NoiseProblem, Parameter, ParameterKind};

/// The default first exponent of a parameter sweep.
pub const J_SWEEP_FROM: f64 = -3.0;
/// The default last exponent of a parameter sweep.
pub const J_SWEEP_TO: f64 = 3.0;
/// The default exponent step of a parameter sweep.
pub const J_SWEEP_STEP: f64 = 0.25;

/// What made a parameter sweep fail.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SweepError {
    /// The grid is empty, not finite, not increasing, or gives a `10^p` outside the normal
    /// range.
    #[error("use a finite increasing grid of exponents: point {index} (p = {p}) {reason}")]
    InvalidGrid {
        /// The point's index.
        index: usize,
        /// Its exponent.
        p: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// The estimate's matrices do not match the problem's sizes.
    #[error(
        "sweep around the estimate: {what} is {found_rows}x{found_cols}, expected {expected}x{expected}"
    )]
    Shape {
        /// Which matrix.
        what: &'static str,
        /// Its rows.
        found_rows: usize,
        /// Its columns.
        found_cols: usize,
        /// The expected size.
        expected: usize,
    },
    /// The models refused a point's noise matrices.
    #[error("sweep {parameter} at p = {p}: {source}")]
    Model {
        /// The parameter swept.
        parameter: String,
        /// The exponent.
        p: f64,
        /// What was refused.
        source: ModelError,
    },
    /// The filter failed at a point.
    #[error("sweep {parameter} at p = {p}, run {run}: {source}")]
    Filter {
        /// The parameter swept.
        parameter: String,
        /// The exponent.
        p: f64,
        /// The run.
        run: usize,
        /// What failed.
        source: FilterError,
    },
    /// The parameter's value at a point (its estimate times `10^p`, or a scaled form's
    /// multiplier of the estimate) is beyond f64.
    #[error("sweep {parameter} at p = {p}: its value leaves the range of f64")]
    OutOfRange {
        /// The parameter swept.
        parameter: String,
        /// The exponent (NaN: the estimate's own multiplier).
        p: f64,
    },
    /// The metrics of an update failed at a point.
    #[error("sweep {parameter} at p = {p}: {source}")]
    Metrics {
        /// The parameter swept.
        parameter: String,
        /// The exponent.
        p: f64,
        /// What failed.
        source: MetricsError,
    },
}

/// One point of a parameter's curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// The exponent: the parameter is its estimate times `10^p`.
    pub p: f64,
    /// The parameter's value at this point.
    pub value: f64,
    /// `J1`, averaged over every update of every run.
    pub j1: f64,
    /// `J2`, averaged likewise.
    pub j2: f64,
}

/// Where a parameter's `J1` and `J2` cross.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurveCrossover {
    /// The exponent `p_c` (interpolated).
    pub p: f64,
    /// The parameter's value there: the estimate times `10^p_c`.
    pub value: f64,
    /// `J1 = J2` there.
    pub j: f64,
}

/// One parameter's `J1`/`J2` curve around the estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterCurve {
    /// The parameter.
    pub parameter: Parameter,
    /// Its value at the estimate.
    pub value: f64,
    /// The curve, in grid order (empty when skipped).
    pub points: Vec<CurvePoint>,
    /// The first crossing of `J1` and `J2`, if they cross on the grid.
    pub crossover: Option<CurveCrossover>,
    /// Why the parameter was not swept, if it was not.
    pub skipped: Option<String>,
}

/// The options of a sweep of every parameter: the grid of exponents.
///
/// # The method
/// For each free parameter of the [`Parametrisation`](crate::Parametrisation), with every other
/// one held at the estimate, the parameter is multiplied by `10^p` for each `p` of a grid
/// (default [`J_SWEEP_FROM`] to [`J_SWEEP_TO`] by [`J_SWEEP_STEP`]); a Kalman filter runs over
/// every run at each point and `J1 = tr(S^-1 R)`, `J2 = tr((A + B)^-1 B)` are averaged over
/// all updates of all runs (`kalibra_metrics::j_step`, the same metrics as the `Q` sweep), and
/// their first crossing ([`kalibra_metrics::crossover`], with `nq = p`) is reported with the
/// parameter's value there.
///
/// How a parameter is multiplied:
/// * a scaled form's multiplier `s`: `s 10^p`;
/// * a diagonal form's variance: that entry times `10^p`;
/// * a full form's variance `X_ii`: `X <- D X D` with `D = diag(1, .., 10^(p/2), .., 1)`, so the
///   variance is multiplied by `10^p` and the correlations are kept (multiplying the entry
///   alone can leave the matrix indefinite);
/// * a full form's covariance `X_ij`, `i != j`: not swept (it has no scale of its own), and
///   reported as such ([`ParameterCurve::skipped`]).
///
/// At `p = 0` every curve passes through the estimate itself, so the `J1`, `J2` of that point
/// agree across curves. When `Qw` is a scaled form and `R` fixed, the multiplier's curve is
/// the `Q` sweep of [`Tuning::tune`](crate::Tuning::tune) with `Q_nom` the estimate (checked
/// by `tests/j1j2.rs`).
///
/// ```
/// use kalibra_tune::{CovarianceForm, DMatrix, DVector, NoiseMatrices, NoiseProblem,
///     ParameterSweep, Parametrisation, Start};
///
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(0.1)),
///     CovarianceForm::scaled(one(0.5)))?;
/// let zs = [0.3, -0.1, 0.8, 1.1, 0.6, 1.9, 2.2, 1.7];
/// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
/// let problem = NoiseProblem::new(one(1.0), one(1.0), DVector::zeros(1), one(1.0),
///     Start::PredictFirst, noise, vec![run])?;
/// // Around the starting point: q = r = 1.
/// let estimate = NoiseMatrices { qw: one(0.1), r: one(0.5), q: one(0.1) };
/// let curves = ParameterSweep::new().sweep(&problem, &estimate)?;
/// assert_eq!(curves.len(), 2);
/// // J1 falls and J2 rises as q grows.
/// let q = &curves[0].points;
/// assert!(q[0].j1 > q[q.len() - 1].j1 && q[0].j2 < q[q.len() - 1].j2);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ParameterSweep {
    grid: Vec<f64>,
}

impl Default for ParameterSweep {
    fn default() -> Self {
        Self::new()
    }
}

impl ParameterSweep {
    /// The default grid, [`J_SWEEP_FROM`] to [`J_SWEEP_TO`] by [`J_SWEEP_STEP`] (each point
    /// `from + i step`).
    pub fn new() -> Self {
        let count = ((J_SWEEP_TO - J_SWEEP_FROM) / J_SWEEP_STEP).round() as usize;
        Self {
            grid: (0..=count)
                .map(|i| J_SWEEP_FROM + i as f64 * J_SWEEP_STEP)
                .collect(),
        }
    }

    /// An explicit grid of exponents, strictly increasing.
    ///
    /// # Errors
    /// [`SweepError::InvalidGrid`] for an empty grid, a non-finite or non-increasing point,
    /// or a `10^p` that is zero, subnormal or infinite.
    pub fn grid(mut self, grid: Vec<f64>) -> Result<Self, SweepError> {
        if grid.is_empty() {
            return Err(SweepError::InvalidGrid {
                index: 0,
                p: f64::NAN,
                reason: "is missing: the grid is empty",
            });
        }
        for (index, &p) in grid.iter().enumerate() {
            let bad = |reason| Err(SweepError::InvalidGrid { index, p, reason });
            if !p.is_finite() {
                return bad("is not finite");
            }
            if !10f64.powf(p).is_normal() {
                return bad("gives a scale 10^p that is zero, subnormal or infinite");
            }
            if index > 0 && p <= grid[index - 1] {
                return bad("does not increase p");
            }
        }
        self.grid = grid;
        Ok(self)
    }

    /// The grid of exponents.
    pub fn exponents(&self) -> &[f64] {
        &self.grid
    }

    /// Sweeps every free parameter of `problem` in turn around `estimate` (the matrices of
    /// an estimator's result, or of the starting point); see the type's docs.
    ///
    /// # Errors
    /// [`SweepError::Shape`] when `estimate` does not fit the problem; [`SweepError::Model`],
    /// [`SweepError::Filter`], [`SweepError::Metrics`] naming the parameter and the point
    /// that failed; [`SweepError::OutOfRange`] for a parameter value beyond f64.
    pub fn sweep(
        &self,
        problem: &NoiseProblem,
        estimate: &NoiseMatrices,
    ) -> Result<Vec<ParameterCurve>, SweepError> {
        let noise = problem.noise();
        let g_dim = noise.qw_form().dim();
        let m = noise.measurement_dim();
        for (what, x, expected) in [("Qw", &estimate.qw, g_dim), ("R", &estimate.r, m)] {
            if x.shape() != (expected, expected) {
                return Err(SweepError::Shape {
                    what,
                    found_rows: x.nrows(),
                    found_cols: x.ncols(),
                    expected,
                });
            }
        }
        noise
            .parameters()
            .into_iter()
            .map(|parameter| self.curve(problem, estimate, parameter))
            .collect()
    }

    fn curve(
        &self,
        problem: &NoiseProblem,
        estimate: &NoiseMatrices,
        parameter: Parameter,
    ) -> Result<ParameterCurve, SweepError> {
        let noise = problem.noise();
        let (form, base) = match parameter.matrix {
            NoiseMatrix::Qw => (noise.qw_form(), &estimate.qw),
            NoiseMatrix::R => (noise.r_form(), &estimate.r),
        };
        let value = match parameter.entry {
            Some((i, j)) => base[(i, j)],
            None => crate::noise::multiplier(base, form.value()),
        };
        let out_of_range = |p: f64| SweepError::OutOfRange {
            parameter: parameter.name.clone(),
            p,
        };
        if !value.is_finite() {
            return Err(out_of_range(f64::NAN));
        }
        if parameter.kind == ParameterKind::Covariance {
            return Ok(ParameterCurve {
                parameter,
                value,
                points: Vec::new(),
                crossover: None,
                skipped: Some(
                    "an off-diagonal entry has no scale of its own; the variances' sweeps \
                     keep the correlations"
                        .to_owned(),
                ),
            });
        }
        let mut points = Vec::with_capacity(self.grid.len());
        for &p in &self.grid {
            let scale = 10f64.powf(p);
            let scaled = scale_parameter(form.kind(), base, &parameter, scale);
            let (qw, r) = match parameter.matrix {
                NoiseMatrix::Qw => (&scaled, &estimate.r),
                NoiseMatrix::R => (&estimate.qw, &scaled),
            };
            let (j1, j2) = j_at(problem, qw, r, &parameter.name, p)?;
            // The matrices were finite (the models check them); the value itself may not be
            // (a multiplier of a tiny nominal matrix).
            let value = value * scale;
            if !value.is_finite() {
                return Err(out_of_range(p));
            }
            points.push(CurvePoint { p, value, j1, j2 });
        }
        let sweep: Vec<SweepPoint> = points
            .iter()
            .map(|c| SweepPoint {
                p: c.p,
                nq: c.p,
                j1: c.j1,
                j2: c.j2,
            })
            .collect();
        let crossing = crossover(&sweep).map_err(|source| SweepError::Metrics {
            parameter: parameter.name.clone(),
            p: f64::NAN,
            source,
        })?;
        let crossover = match crossing {
            Some(c) => {
                let at = value * 10f64.powf(c.p);
                if !at.is_finite() {
                    return Err(out_of_range(c.p));
                }
                Some(CurveCrossover {
                    p: c.p,
                    value: at,
                    j: c.j,
                })
            }
            None => None,
        };
        Ok(ParameterCurve {
            parameter,
            value,
            points,
            crossover,
            skipped: None,
        })
    }
}

/// `base` with `parameter` (a multiplier or a variance, never a covariance) multiplied by
/// `scale` as the sweep does it (see [`ParameterSweep`]): the whole matrix for a multiplier,
/// the entry of a diagonal form, `D X D` for a full form's variance so that its correlations
/// are kept.
pub(crate) fn scale_parameter(
    kind: FormKind,
    base: &DMatrix<f64>,
    parameter: &Parameter,
    scale: f64,
) -> DMatrix<f64> {
    match (kind, parameter.entry) {
        (FormKind::Full, Some((i, _))) => {
            let mut d = DMatrix::identity(base.nrows(), base.nrows());
            d[(i, i)] = scale.sqrt();
            &d * base * &d
        }
        (_, Some((i, _))) => {
            let mut x = base.clone();
            x[(i, i)] *= scale;
            x
        }
        (_, None) => base * scale,
    }
}

/// `J1` and `J2` of a Kalman filter with `Qw` and `R` over every run, averaged over all
/// updates.
fn j_at(
    problem: &NoiseProblem,
    qw: &DMatrix<f64>,
    r: &DMatrix<f64>,
    parameter: &str,
    p: f64,
) -> Result<(f64, f64), SweepError> {
    let q = match problem.noise().g() {
        Some(g) => g * qw * g.transpose(),
        None => qw.clone(),
    };
    let model = |source| SweepError::Model {
        parameter: parameter.to_owned(),
        p,
        source,
    };
    let dynamics = LinearGaussian::new(problem.f().clone(), q).map_err(model)?;
    let sensor = LinearObservation::new(problem.h().clone(), r.clone()).map_err(model)?;
    let mut horizon = JHorizon::new();
    for (run, zs) in problem.runs().iter().enumerate() {
        let filter = |source| SweepError::Filter {
            parameter: parameter.to_owned(),
            p,
            run,
            source,
        };
        let mut kf: Kf<Dyn, Dyn, _, _> = Kf::new(
            &dynamics,
            &sensor,
            problem.x0().clone(),
            problem.p0().clone(),
        )
        .map_err(filter)?;
        let records = kf
            .run_collect(zs.iter().map(Option::as_ref), problem.start())
            .map_err(filter)?;
        for rec in &records {
            let step = j_step(
                &rec.compute_a(),
                &rec.compute_b(),
                rec.r(),
                &rec.compute_c(),
            )
            .map_err(|source| SweepError::Metrics {
                parameter: parameter.to_owned(),
                p,
                source,
            })?;
            horizon.push(&step);
        }
    }
    let summary = horizon
        .summary(horizon.updates())
        .map_err(|source| SweepError::Metrics {
            parameter: parameter.to_owned(),
            p,
            source,
        })?;
    Ok((summary.j1, summary.j2))
}
