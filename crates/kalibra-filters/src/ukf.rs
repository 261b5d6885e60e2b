//! The unscented Kalman filter, with a fixed sigma-point set or with the scaling parameter
//! `kappa` chosen at every update from a grid (paper 001, section III-C).

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, SqrtMethod,
    add_cross_scatter, add_scatter, all_finite, check_finite, propagate, sigma_sqrt, symmetrize,
};
use std::sync::Arc;

use kalibra_models::{Dynamics, Measurement, wrap_angle};

use crate::core::{KalmanCore, UpdateParts, check_model_output};
use crate::kalman::{core_accessors, jacobian_predict};
use crate::{Estimate, Filter, FilterError, FilterOptions, StepRecord};

/// A sigma-point set, as a value: which points and weights the unscented transform uses.
///
/// Both sets place `2n + 1` points at the mean and at `x +- sqrt(n + lambda) L_j`, with
/// `L L^T = P` the lower Cholesky factor and `L_j` its columns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SigmaSet {
    /// The symmetric set of paper 001, eqs 16-18 (Julier and Uhlmann): `lambda = kappa`,
    /// `W_0 = kappa / (n + kappa)`, `W_i = 1 / (2 (n + kappa))`, the same weights for the mean
    /// and the covariance.
    Symmetric {
        /// The scaling parameter `kappa` (`n + kappa > 0`).
        kappa: f64,
    },
    /// The scaled set (Julier 2002, Wan and van der Merwe 2000):
    /// `lambda = alpha^2 (n + kappa) - n`, `W_0^m = lambda / (n + lambda)`,
    /// `W_0^c = W_0^m + 1 - alpha^2 + beta`, `W_i = 1 / (2 (n + lambda))`.
    Scaled {
        /// Spread `alpha > 0` (small: points close to the mean).
        alpha: f64,
        /// Prior knowledge of the distribution (2 is optimal for a Gaussian).
        beta: f64,
        /// Secondary scaling `kappa`.
        kappa: f64,
    },
}

/// The weights and spread of a [`SigmaSet`] for a state dimension `n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SigmaWeights {
    /// `sqrt(n + lambda)`: the points sit at `x +- spread L_j`.
    pub spread: f64,
    /// Weight of the central point in the mean.
    pub mean_center: f64,
    /// Weight of the central point in the covariance.
    pub cov_center: f64,
    /// Weight of each of the other `2n` points (mean and covariance).
    pub other: f64,
}

impl SigmaSet {
    /// Paper 001's recommendation (after Julier and Uhlmann): the symmetric set with
    /// `kappa = 3 - n` for `n <= 3` and `kappa = 0` otherwise.
    pub fn recommended(n: usize) -> Self {
        let kappa = if n <= 3 { 3.0 - n as f64 } else { 0.0 };
        SigmaSet::Symmetric { kappa }
    }

    /// The set's `kappa`.
    pub fn kappa(&self) -> f64 {
        match *self {
            SigmaSet::Symmetric { kappa } | SigmaSet::Scaled { kappa, .. } => kappa,
        }
    }

    /// The same set with another `kappa` (what the adaptive filters vary).
    #[must_use]
    pub fn with_kappa(self, kappa: f64) -> Self {
        match self {
            SigmaSet::Symmetric { .. } => SigmaSet::Symmetric { kappa },
            SigmaSet::Scaled { alpha, beta, .. } => SigmaSet::Scaled { alpha, beta, kappa },
        }
    }

    /// The weights for state dimension `n`.
    ///
    /// ```
    /// use kalibra_filters::SigmaSet;
    /// let w = SigmaSet::Symmetric { kappa: 1.0 }.weights(2)?;
    /// assert_eq!((w.mean_center, w.other), (1.0 / 3.0, 1.0 / 6.0));
    /// assert!((w.spread - 3f64.sqrt()).abs() < 1e-15);
    /// # Ok::<(), kalibra_filters::FilterError>(())
    /// ```
    ///
    /// # Errors
    /// [`FilterError::InvalidParameter`] for a non-finite parameter, `alpha <= 0`, or
    /// `n + lambda <= 0` (no real spread).
    pub fn weights(&self, n: usize) -> Result<SigmaWeights, FilterError> {
        let nf = n as f64;
        let (lambda, extra) = match *self {
            SigmaSet::Symmetric { kappa } => {
                finite("kappa", kappa)?;
                (kappa, 0.0)
            }
            SigmaSet::Scaled { alpha, beta, kappa } => {
                finite("kappa", kappa)?;
                finite("beta", beta)?;
                finite("alpha", alpha)?;
                if alpha <= 0.0 {
                    return Err(FilterError::InvalidParameter {
                        name: "alpha",
                        value: alpha,
                    });
                }
                (
                    alpha * alpha * (nf + kappa) - nf,
                    1.0 - alpha * alpha + beta,
                )
            }
        };
        let total = nf + lambda;
        if !(total > 0.0 && total.is_finite()) {
            return Err(FilterError::InvalidParameter {
                name: "n + lambda",
                value: total,
            });
        }
        let mean_center = lambda / total;
        Ok(SigmaWeights {
            spread: total.sqrt(),
            mean_center,
            cov_center: mean_center + extra,
            other: 0.5 / total,
        })
    }
}

fn finite(name: &'static str, value: f64) -> Result<(), FilterError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(FilterError::InvalidParameter { name, value })
    }
}

/// How the UKF predicts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum UkfPrediction {
    /// Sigma points of the posterior through `f_k` (the general UKF).
    #[default]
    Unscented,
    /// `x- = f_k(x+)`, `P- = F P+ F^T + Q` with the Jacobian `F` (exact for linear dynamics, and
    /// what paper 001's Alg. 1 does: only the measurement statistics are unscented). Cheaper.
    Linearised,
}

/// The criterion an adaptive UKF minimises over its kappa grid at every update (paper 001,
/// section III-C). `nu = z - zhat(kappa)`, `Pz(kappa)`, `Pxz(kappa)` are the unscented
/// measurement statistics, `x+(kappa)` the updated mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum KappaCriterion {
    /// Maximum likelihood, eq 23 (UKF-ML): minimise `log|Pz| + nu^T Pz^-1 nu`.
    MaximumLikelihood,
    /// Maximum posterior probability, eq 26 with the inverses the printed formula lost
    /// restored (UKF-MPP): minimise
    /// `nu^T U nu + e^T R^-1 e - nu^T Pz^-1 nu - 1/2 log|Pz|`,
    /// `U = Pz^-1 Pxz^T P-^-1 Pxz Pz^-1`, `e = z - h(x+(kappa))`.
    /// The coefficient 1/2 on the log-determinant is the printed one (a full derivation of
    /// `-2 log p(x+|z)` gives 1); kept so that results compare with the paper and with the
    /// independent implementation's traces.
    MaximumPosterior,
    /// The pure MAP reading of eq 24: the two terms of eq 26 that come from the evidence
    /// `p(z_k | z^{k-1})` dropped, minimise `nu^T U nu + e^T R^-1 e`. Not in the paper; the
    /// spec found that it, not the restored eq 26, reproduces the paper's UKF-MPP numbers in
    /// problem III.
    PureMap,
}

/// The candidate values of an adaptive UKF's kappa.
#[derive(Clone, Debug, PartialEq)]
pub struct KappaGrid {
    values: Vec<f64>,
}

impl KappaGrid {
    /// A grid of the given values, in increasing order (ties in the criterion go to the
    /// smallest kappa, so the order matters).
    ///
    /// # Errors
    /// [`FilterError::InvalidParameter`] for an empty grid, a non-finite value, or values not
    /// strictly increasing.
    pub fn new(values: Vec<f64>) -> Result<Self, FilterError> {
        if values.is_empty() {
            return Err(FilterError::InvalidParameter {
                name: "kappa grid length",
                value: 0.0,
            });
        }
        for (i, &v) in values.iter().enumerate() {
            finite("kappa grid value", v)?;
            if i > 0 && v <= values[i - 1] {
                return Err(FilterError::InvalidParameter {
                    name: "kappa grid (not increasing)",
                    value: v,
                });
            }
        }
        Ok(Self { values })
    }

    /// `count` equidistant values from `min` to `max` inclusive.
    ///
    /// # Errors
    /// As [`KappaGrid::new`]; `count == 0`, or `count > 1` with `max <= min`.
    pub fn equidistant(min: f64, max: f64, count: usize) -> Result<Self, FilterError> {
        let values = match count {
            0 => Vec::new(),
            1 => vec![min],
            _ => {
                let step = (max - min) / (count - 1) as f64;
                (0..count).map(|i| min + step * i as f64).collect()
            }
        };
        Self::new(values)
    }

    /// The values.
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

/// How the UKF averages and subtracts the vectors of a space that is not plain Euclidean,
/// for instance one with angle components (FilterPy's `x_mean_fn`, `residual_x` and
/// `z_mean_fn`; Stone Soup's angle types).
///
/// A state space ([`Ukf::with_state_space`]) uses all three methods: the predicted mean of the
/// sigma points, the deviations that form the predicted covariance, and the normalisation of
/// the updated mean `x- + K nu`. A measurement mean ([`Ukf::with_measurement_mean`]) uses
/// [`SigmaSpace::mean`] for `zhat`; the deviations there come from the measurement model's
/// own residual. [`AngleComponents`] is the ready-made space with angles at given positions.
pub trait SigmaSpace<D: Dim>: Send + Sync + std::fmt::Debug
where
    DefaultAllocator: Alloc<D>,
{
    /// The weighted mean of sigma points: `points[0]` is the central point, weighted
    /// `weights.mean_center`, every other point is weighted `weights.other` (the weights sum to
    /// one; the central one may be negative).
    fn mean(&self, points: &[OVector<f64, D>], weights: &SigmaWeights) -> OVector<f64, D>;

    /// The deviation `a - b` (angles wrapped); plain subtraction by default.
    fn residual(&self, a: &OVector<f64, D>, b: &OVector<f64, D>) -> OVector<f64, D> {
        a - b
    }

    /// Brings `x` back into its canonical range (angles into `(-pi, pi]`); nothing by default.
    fn normalize(&self, _x: &mut OVector<f64, D>) {}

    /// Checks that the space fits vectors of dimension `dim` (used once, when it is attached).
    ///
    /// # Errors
    /// A [`FilterError`] if it does not; none by default.
    fn check(&self, _dim: usize) -> Result<(), FilterError> {
        Ok(())
    }
}

/// A vector space whose components at the given positions are angles in radians: their mean is
/// the circular mean `atan2(sum w_i sin a_i, sum w_i cos a_i)`, their residual and
/// normalisation wrap into `(-pi, pi]` ([`wrap_angle`]); the other components are plain.
///
/// ```
/// use kalibra_filters::{AngleComponents, SigmaSpace, SigmaWeights};
/// use kalibra_linalg::Vector2;
/// use std::f64::consts::PI;
///
/// let heading = AngleComponents::new([0]);
/// let w = SigmaWeights { spread: 1.0, mean_center: 0.0, cov_center: 0.0, other: 0.5 };
/// // Two headings either side of +-pi average to pi, not to 0.
/// let mean = heading.mean(&[Vector2::zeros(), Vector2::new(PI - 0.1, 1.0), Vector2::new(-PI + 0.1, 3.0)], &w);
/// assert!((mean[0] - PI).abs() < 1e-12 && (mean[1] - 2.0).abs() < 1e-12);
/// ```
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AngleComponents {
    indices: Vec<usize>,
}

impl AngleComponents {
    /// Angles at the given component positions.
    pub fn new(indices: impl IntoIterator<Item = usize>) -> Self {
        let mut indices: Vec<usize> = indices.into_iter().collect();
        indices.sort_unstable();
        indices.dedup();
        Self { indices }
    }

    /// The positions of the angle components, increasing.
    pub fn indices(&self) -> &[usize] {
        &self.indices
    }
}

impl<D: Dim> SigmaSpace<D> for AngleComponents
where
    DefaultAllocator: Alloc<D>,
{
    fn mean(&self, points: &[OVector<f64, D>], weights: &SigmaWeights) -> OVector<f64, D> {
        let weight = |i: usize| {
            if i == 0 {
                weights.mean_center
            } else {
                weights.other
            }
        };
        let mut mean = points[0].clone() * weights.mean_center;
        for p in &points[1..] {
            mean += p * weights.other;
        }
        for &a in &self.indices {
            let (mut sin, mut cos) = (0.0, 0.0);
            for (i, p) in points.iter().enumerate() {
                sin += weight(i) * p[a].sin();
                cos += weight(i) * p[a].cos();
            }
            mean[a] = wrap_angle(sin.atan2(cos));
        }
        mean
    }

    fn residual(&self, a: &OVector<f64, D>, b: &OVector<f64, D>) -> OVector<f64, D> {
        let mut d = a - b;
        for &i in &self.indices {
            d[i] = wrap_angle(d[i]);
        }
        d
    }

    fn normalize(&self, x: &mut OVector<f64, D>) {
        for &i in &self.indices {
            x[i] = wrap_angle(x[i]);
        }
    }

    fn check(&self, dim: usize) -> Result<(), FilterError> {
        match self.indices.last() {
            Some(&last) if last >= dim => Err(FilterError::InvalidParameter {
                name: "angle component index",
                value: last as f64,
            }),
            _ => Ok(()),
        }
    }
}

/// The unscented Kalman filter (Julier and Uhlmann), paper 001 eqs 16-22.
///
/// Update: the `2n + 1` sigma points of the prior through `h_k`, each measurement taken as a
/// residual from the central point's (so sigma bearings are unwrapped around the central
/// bearing and never straddle +-pi), `zhat = Z_0 + sum W_i (Z_i - Z_0)`,
/// `Pz = sum W_i (Z_i - zhat)(Z_i - zhat)^T + R`, `Pxz = sum W_i (X_i - x-)(Z_i - zhat)^T`,
/// `K = Pxz Pz^-1`, `x+ = x- + K nu`, `P+ = P- - K Pz K^T` (eq 7), symmetrised. `R` is the
/// model's `R_k` at the prior mean.
///
/// With [`Ukf::with_adaptive_kappa`] the update is computed for every kappa of a grid and
/// the one minimising a [`KappaCriterion`] is kept (UKF-ML, UKF-MPP); ties go to the smallest
/// kappa and kappas whose criterion is not finite are never chosen.
///
/// The step record is the Kalman filter's: `S = Pz`, `K`, and as `H` the statistical
/// linearisation `Pxz^T P-^-1` (equal to `H` for a linear measurement; the model's Jacobian at
/// the prior mean when `P-` is singular). On linear-Gaussian models the UKF equals the KF for
/// any valid sigma set (tested).
///
/// ```
/// use kalibra_filters::{Filter, SigmaSet, Ukf};
/// use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};
/// use kalibra_linalg::{Matrix4, U4, Vector1, Vector2, Vector4};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?.dynamics(U4)?;
/// let sensor = Bearing::new(U4, [0, 1], BearingReference::XAxis, 1e-4, Stationary(Vector2::zeros()))?;
/// let x0 = Vector4::new(100.0, 10.0, -1.0, 0.0);
/// let mut ukf = Ukf::new(cv, sensor, x0, Matrix4::identity() * 10.0, SigmaSet::recommended(4))?;
/// ukf.predict()?;
/// let record = ukf.update(&Vector1::new(0.11))?;
/// // NIS = nu^2 / S for a scalar measurement, from the record's innovation and S.
/// let direct = record.innovation()[0].powi(2) / record.s_matrix()[(0, 0)];
/// assert!((record.nis() - direct).abs() <= 1e-12 * direct);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Ukf<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    core: KalmanCore<N, M>,
    set: SigmaSet,
    prediction: UkfPrediction,
    adaptive: Option<(KappaCriterion, KappaGrid)>,
    last_kappa: Option<f64>,
    // Scratch for the 2n transformed points, allocated once so that a step allocates nothing
    // on the fixed-size path.
    scratch_z: Vec<OVector<f64, M>>,
    scratch_x: Vec<OVector<f64, N>>,
    // The optional non-Euclidean spaces; `None` keeps the plain arithmetic, bit for bit.
    state_space: Option<Arc<dyn SigmaSpace<N>>>,
    measurement_mean: Option<Arc<dyn SigmaSpace<M>>>,
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A UKF at step 0 with initial mean `x0`, covariance `p0` and sigma set `set`, predicting
    /// with [`UkfPrediction::Unscented`].
    ///
    /// # Errors
    /// [`FilterError::Initial`] for a bad initial estimate (as [`crate::Kf::new`]),
    /// [`FilterError::DimensionMismatch`] for a measurement model built for another state
    /// dimension (as [`crate::Kf::new`]), [`FilterError::InvalidParameter`] for a sigma set
    /// invalid at this dimension.
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
    ) -> Result<Self, FilterError> {
        Self::with_options(dynamics, measurement, x0, p0, set, FilterOptions::default())
    }

    /// As [`Ukf::new`] with [`FilterOptions`] (the first step and the initial check; the
    /// update form is always eq 7's `P- - K Pz K^T`, since the UKF has no `H` for a Joseph
    /// form).
    ///
    /// # Errors
    /// As [`Ukf::new`]; [`FilterError::Unsupported`] for
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven).
    pub fn with_options(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        crate::core::reject_as_given(
            &options,
            "the UKF with an as-given initial covariance (sigma points need P's square root)",
        )?;
        crate::kalman::check_model_sizes(&dynamics, &measurement)?;
        let (n, m) = (dynamics.state_dim(), measurement.meas_dim());
        set.weights(n.value())?;
        let core = KalmanCore::new(n, m, x0, p0, options)?;
        let zeros_z = OVector::<f64, M>::zeros_generic(m, nalgebra::U1);
        let zeros_x = OVector::<f64, N>::zeros_generic(n, nalgebra::U1);
        Ok(Self {
            dynamics,
            measurement,
            core,
            set,
            prediction: UkfPrediction::default(),
            adaptive: None,
            last_kappa: None,
            scratch_z: vec![zeros_z; 2 * n.value()],
            scratch_x: vec![zeros_x; 2 * n.value()],
            state_space: None,
            measurement_mean: None,
        })
    }

    /// The same filter with a non-Euclidean state space (FilterPy's `x_mean_fn` and
    /// `residual_x`): the unscented prediction averages its sigma points with
    /// [`SigmaSpace::mean`] and forms the covariance from [`SigmaSpace::residual`]s, and the
    /// updated mean `x- + K nu` is [`SigmaSpace::normalize`]d. With [`AngleComponents`] an
    /// angle in the state near `+-pi` averages to near `pi`, where the plain mean gives about 0.
    /// A prediction with a space collects its sigma points in a fresh `Vec` (one allocation
    /// per step); without one the filter keeps its allocation-free path, bit for bit.
    ///
    /// # Errors
    /// [`SigmaSpace::check`]'s error if the space does not fit the state dimension.
    pub fn with_state_space(
        mut self,
        space: impl SigmaSpace<N> + 'static,
    ) -> Result<Self, FilterError> {
        space.check(self.dynamics.state_dim().value())?;
        self.state_space = Some(Arc::new(space));
        Ok(self)
    }

    /// The same filter forming the predicted measurement `zhat` with `mean` (FilterPy's
    /// `z_mean_fn`) from the sigma points' measurements, for instance the circular mean of
    /// [`AngleComponents`]. By default `zhat` is the central measurement plus the mean of the
    /// others' residuals from it, which handles angles through the model's residual; the option
    /// serves models whose residual does not wrap, or a circular mean by choice.
    ///
    /// # Errors
    /// [`SigmaSpace::check`]'s error if `mean` does not fit the measurement dimension.
    pub fn with_measurement_mean(
        mut self,
        mean: impl SigmaSpace<M> + 'static,
    ) -> Result<Self, FilterError> {
        mean.check(self.measurement.meas_dim().value())?;
        self.measurement_mean = Some(Arc::new(mean));
        Ok(self)
    }

    /// The same filter predicting as `prediction` says.
    #[must_use]
    pub fn with_prediction(mut self, prediction: UkfPrediction) -> Self {
        self.prediction = prediction;
        self
    }

    /// The same filter choosing kappa at every update: the value of `grid` minimising
    /// `criterion` (UKF-ML, UKF-MPP of paper 001). The prediction keeps the set's own kappa.
    ///
    /// # Errors
    /// [`FilterError::InvalidParameter`] if a grid value gives an invalid sigma set.
    pub fn with_adaptive_kappa(
        mut self,
        criterion: KappaCriterion,
        grid: KappaGrid,
    ) -> Result<Self, FilterError> {
        let n = self.dynamics.state_dim().value();
        for &kappa in grid.values() {
            self.set.with_kappa(kappa).weights(n)?;
        }
        self.adaptive = Some((criterion, grid));
        Ok(self)
    }

    /// The sigma set (its kappa is the one used when not adapting, and in the prediction).
    pub fn sigma_set(&self) -> SigmaSet {
        self.set
    }

    /// The kappa of the last update (the chosen one when adapting); `None` before the first.
    pub fn last_kappa(&self) -> Option<f64> {
        self.last_kappa
    }

    /// The dynamics model.
    pub fn dynamics(&self) -> &D {
        &self.dynamics
    }

    /// The measurement model.
    pub fn measurement(&self) -> &H {
        &self.measurement
    }

    /// The prediction and the state space, for the unscented smoother (`smooth::unscented`).
    pub(crate) fn smoother_parts(&self) -> (UkfPrediction, Option<&Arc<dyn SigmaSpace<N>>>) {
        (self.prediction, self.state_space.as_ref())
    }

    fn unscented_predict(&mut self) -> Result<(), FilterError> {
        let k = self.core.step();
        let n = self.dynamics.state_dim().value();
        let w = self.set.weights(n)?;
        let x = self.core.mean().clone();
        let (l, _) = sigma_sqrt(self.core.cov(), "covariance for sigma points")
            .map_err(|e| FilterError::at(k, e))?;
        // Every answer of the model is checked as it comes (a `Dyn` model may return any
        // length), before a sum mixes it with the others; the filter is untouched until the
        // core stores the prediction.
        let fx = "predicted sigma point f(x)";
        let x0 = self.dynamics.transition(k, &x);
        check_model_output(fx, &x0, (n, 1), k)?;
        for j in 0..n {
            let d = l.column(j) * w.spread;
            let (plus, minus) = (
                self.dynamics.transition(k, &(&x + &d)),
                self.dynamics.transition(k, &(&x - &d)),
            );
            check_model_output(fx, &plus, (n, 1), k)?;
            check_model_output(fx, &minus, (n, 1), k)?;
            self.scratch_x[j] = plus;
            self.scratch_x[n + j] = minus;
        }
        let (mean, mut cov) = match &self.state_space {
            None => {
                let mut mean = &x0 * w.mean_center;
                for xi in &self.scratch_x {
                    mean += xi * w.other;
                }
                let d0 = &x0 - &mean;
                let mut cov = &d0 * d0.transpose() * w.cov_center;
                if N::try_to_usize().is_some() {
                    // Fixed sizes: the loop written out, as in the KF core (see there).
                    for xi in &self.scratch_x {
                        let d = xi - &mean;
                        cov += &d * d.transpose() * w.other;
                    }
                } else {
                    add_scatter(&mut cov, &self.scratch_x, &mean, w.other);
                }
                (mean, cov)
            }
            Some(space) => {
                let mut points = Vec::with_capacity(2 * n + 1);
                points.push(x0);
                points.extend(self.scratch_x.iter().cloned());
                let mean = space.mean(&points, &w);
                check_model_output("state space's sigma-point mean", &mean, (n, 1), k)?;
                let residual = "state space's sigma-point residual";
                let d0 = space.residual(&points[0], &mean);
                check_model_output(residual, &d0, (n, 1), k)?;
                let mut cov = &d0 * d0.transpose() * w.cov_center;
                for xi in &points[1..] {
                    let d = space.residual(xi, &mean);
                    check_model_output(residual, &d, (n, 1), k)?;
                    cov += &d * d.transpose() * w.other;
                }
                (mean, cov)
            }
        };
        symmetrize(&mut cov);
        let f = self.dynamics.jacobian(k, &x);
        check_model_output("transition Jacobian F", &f, (n, n), k)?;
        let q = self.dynamics.noise_cov(k);
        check_model_output("process noise covariance Q", &q, (n, n), k)?;
        let (propagated, noise) = if self.core.is_prior() {
            // A second prediction without an update: carry the split through the Jacobian and
            // count what the unscented transform adds beyond it as propagated, so the parts
            // still sum to the unscented prior (and equal the KF's split for linear f).
            let (_, old_noise) = self.core.prior_split();
            let carried_noise = propagate(&f, old_noise);
            (&cov - &carried_noise, carried_noise + q)
        } else {
            (cov, q)
        };
        self.core.predict_split::<false>(mean, f, propagated, noise)
    }

    fn unscented_update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        let k = self.core.step();
        self.core
            .check_measurement(self.measurement.meas_dim().value(), z)?;
        let prior: Estimate<N> = self.core.update_prior().clone();
        let n = prior.mean.nrows();
        let (l, method) = sigma_sqrt(&prior.cov, "prior covariance for sigma points")
            .map_err(|e| FilterError::at(k, e))?;
        let m = self.measurement.meas_dim().value();
        let r = self.measurement.noise_cov(k, &prior.mean);
        check_model_output("measurement noise covariance R", &r, (m, m), k)?;
        check_finite(&r, "measurement noise covariance R").map_err(|e| FilterError::at(k, e))?;
        let z0 = self.measurement.measure(k, &prior.mean);
        check_model_output("predicted measurement h(x)", &z0, (m, 1), k)?;
        let spaces = Spaces {
            state: self.state_space.as_deref(),
            measurement_mean: self.measurement_mean.as_deref(),
        };

        let best = match &self.adaptive {
            None => {
                let kappa = self.set.kappa();
                let w = self.set.weights(n)?;
                let c = candidate(
                    &self.measurement,
                    &mut self.scratch_z,
                    k,
                    &prior,
                    &l,
                    &z0,
                    &r,
                    z,
                    w,
                    spaces,
                )?;
                (kappa, c)
            }
            Some((criterion, grid)) => {
                let r_chol = Covariance::from_symmetric(r.clone(), "R").ok();
                let mut best: Option<(f64, f64, Candidate<N, M>)> = None;
                let mut first_error = None;
                for &kappa in grid.values() {
                    let w = self.set.with_kappa(kappa).weights(n)?;
                    let c = match candidate(
                        &self.measurement,
                        &mut self.scratch_z,
                        k,
                        &prior,
                        &l,
                        &z0,
                        &r,
                        z,
                        w,
                        spaces,
                    ) {
                        Ok(c) => c,
                        Err(e) => {
                            first_error.get_or_insert(e);
                            continue;
                        }
                    };
                    let value = criterion_value(
                        *criterion,
                        &self.measurement,
                        k,
                        z,
                        &c,
                        &l,
                        method,
                        r_chol.as_ref(),
                    );
                    // Strictly smaller: ties keep the smaller kappa; NaN never wins.
                    if value.is_finite() && best.as_ref().is_none_or(|(b, _, _)| value < *b) {
                        best = Some((value, kappa, c));
                    }
                }
                match best {
                    Some((_, kappa, c)) => (kappa, c),
                    None => {
                        return Err(first_error.unwrap_or(FilterError::NonFinite {
                            what: "adaptive kappa criterion (every grid value)",
                            step: k,
                        }));
                    }
                }
            }
        };
        let (kappa, c) = best;
        // The statistical linearisation H = Pxz^T P-^-1, through the Cholesky factor.
        let h = match method {
            SqrtMethod::Cholesky => l
                .solve_lower_triangular(&c.pxz)
                .and_then(|y| l.tr_solve_lower_triangular(&y))
                .map(|ht| ht.transpose()),
            _ => None,
        }
        .unwrap_or_else(|| self.measurement.jacobian(k, &prior.mean));
        check_model_output("measurement Jacobian H", &h, (m, n), k)?;
        self.last_kappa = Some(kappa);
        self.core.commit_update(UpdateParts {
            zhat: c.zhat,
            innovation: c.nu,
            h,
            r,
            s: c.s,
            gain: c.gain,
            mean: c.mean,
            cov: c.cov,
        })
    }
}

/// The update at one kappa.
#[derive(Clone, Debug)]
struct Candidate<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    zhat: OVector<f64, M>,
    nu: OVector<f64, M>,
    s: Covariance<M>,
    pxz: OMatrix<f64, N, M>,
    gain: OMatrix<f64, N, M>,
    mean: OVector<f64, N>,
    cov: OMatrix<f64, N, N>,
}

/// The optional non-Euclidean spaces of an update.
struct Spaces<'a, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    state: Option<&'a dyn SigmaSpace<N>>,
    measurement_mean: Option<&'a dyn SigmaSpace<M>>,
}

impl<N: Dim, M: Dim> Clone for Spaces<'_, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn clone(&self) -> Self {
        *self
    }
}

impl<N: Dim, M: Dim> Copy for Spaces<'_, N, M> where DefaultAllocator: Alloc<N, M> {}

/// The unscented measurement update with weights `w`, the prior's factor `l` and the central
/// measurement `z0` given (they do not depend on kappa).
#[allow(clippy::too_many_arguments)]
fn candidate<N: Dim, M: Dim, H: Measurement<N, M>>(
    measurement: &H,
    scratch: &mut [OVector<f64, M>],
    k: usize,
    prior: &Estimate<N>,
    l: &OMatrix<f64, N, N>,
    z0: &OVector<f64, M>,
    r: &OMatrix<f64, M, M>,
    z: &OVector<f64, M>,
    w: SigmaWeights,
    spaces: Spaces<'_, N, M>,
) -> Result<Candidate<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = prior.mean.nrows();
    let m = z0.nrows();
    let x = &prior.mean;
    // The model's answers are checked as they come, as in the prediction.
    let (hx, residual) = ("sigma measurement h(x)", "measurement residual");
    let measured = |at: &OVector<f64, N>| {
        let z = measurement.measure(k, at);
        check_model_output(hx, &z, (m, 1), k).map(|()| z)
    };
    let residual_of = |a: &OVector<f64, M>, b: &OVector<f64, M>| {
        let e = measurement.residual(a, b);
        check_model_output(residual, &e, (m, 1), k).map(|()| e)
    };
    // Fixed sizes write the sigma-point sums out, run-time sizes call the kernels (which may
    // hand them to faer): the same arithmetic below the faer threshold, but the kernel calls
    // changed how the compiler inlined the fixed-size update (W2's UKF step, callgrind).
    let fixed = N::try_to_usize().is_some() && M::try_to_usize().is_some();
    let (zhat, mut pz) = match spaces.measurement_mean {
        None => {
            // Sigma measurements as residuals from the central one: unwrapped around it.
            for j in 0..n {
                let d = l.column(j) * w.spread;
                scratch[j] = residual_of(&measured(&(x + &d))?, z0)?;
                scratch[n + j] = residual_of(&measured(&(x - &d))?, z0)?;
            }
            let mut dbar = OVector::<f64, M>::zeros_generic(z0.shape_generic().0, nalgebra::U1);
            for d in scratch.iter() {
                dbar += d * w.other;
            }
            let mut pz = &dbar * dbar.transpose() * w.cov_center;
            if fixed {
                for d in scratch.iter() {
                    let dd = d - &dbar;
                    pz += &dd * dd.transpose() * w.other;
                }
            } else {
                add_scatter(&mut pz, scratch, &dbar, w.other);
            }
            (z0 + &dbar, pz)
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
            let mut zhat = mean.mean(&points, &w);
            measurement.normalize(&mut zhat);
            check_model_output("measurement space's sigma-point mean", &zhat, (m, 1), k)?;
            for (slot, zi) in scratch.iter_mut().zip(&points[1..]) {
                *slot = residual_of(zi, &zhat)?;
            }
            let e0 = residual_of(z0, &zhat)?;
            let mut pz = &e0 * e0.transpose() * w.cov_center;
            for e in scratch.iter() {
                pz += e * e.transpose() * w.other;
            }
            (zhat, pz)
        }
    };
    pz += r;
    symmetrize(&mut pz);
    // The central point has no state deviation, and the mean cancels between each pair.
    let mut pxz = OMatrix::<f64, N, M>::zeros_generic(x.shape_generic().0, z0.shape_generic().0);
    if fixed {
        for j in 0..n {
            let dz = &scratch[j] - &scratch[n + j];
            pxz += l.column(j) * dz.transpose() * (w.spread * w.other);
        }
    } else {
        add_cross_scatter(
            &mut pxz,
            l,
            &scratch[..n],
            &scratch[n..],
            w.spread * w.other,
        );
    }
    let mut zhat = zhat;
    if spaces.measurement_mean.is_none() {
        measurement.normalize(&mut zhat);
        check_model_output("normalized measurement", &zhat, (m, 1), k)?;
    }
    let nu = residual_of(z, &zhat)?;
    let s = Covariance::from_symmetric(pz, "innovation covariance Pz").map_err(|e| {
        let e = if all_finite(&zhat) {
            e
        } else {
            LinalgError::NonFinite {
                what: "sigma-point measurements",
            }
        };
        FilterError::at(k, e)
    })?;
    // Sizes agree by construction: `pxz` has as many columns as `S` has rows.
    let gain = s.solve_right(&pxz).map_err(|e| FilterError::at(k, e))?;
    let mut mean = x + &gain * &nu;
    if let Some(space) = spaces.state {
        space.normalize(&mut mean);
        check_model_output("state space's normalized mean", &mean, (n, 1), k)?;
    }
    let cov = &prior.cov - propagate(&gain, s.matrix());
    Ok(Candidate {
        zhat,
        nu,
        s,
        pxz,
        gain,
        mean,
        cov,
    })
}

/// The value of `criterion` for one candidate (smaller is better); NaN when it cannot be
/// evaluated (a singular `P-` or `R` for the posterior criteria).
#[allow(clippy::too_many_arguments)]
fn criterion_value<N: Dim, M: Dim, H: Measurement<N, M>>(
    criterion: KappaCriterion,
    measurement: &H,
    k: usize,
    z: &OVector<f64, M>,
    c: &Candidate<N, M>,
    l: &OMatrix<f64, N, N>,
    method: SqrtMethod,
    r: Option<&Covariance<M>>,
) -> f64
where
    DefaultAllocator: Alloc<N, M>,
{
    let nis = quad_or_non_finite(&c.s, &c.nu);
    if criterion == KappaCriterion::MaximumLikelihood {
        return c.s.log_det() + nis;
    }
    // nu^T U nu = (K nu)^T P-^-1 (K nu) = |L^-1 K nu|^2: the prior's density at x+.
    let step = &c.gain * &c.nu;
    let prior_term = match method {
        SqrtMethod::Cholesky => l
            .solve_lower_triangular(&step)
            .map_or(f64::NAN, |y| y.norm_squared()),
        _ => f64::NAN,
    };
    // A model answering with the wrong length here makes the criterion NaN (this kappa never
    // wins), as a failed factorisation does; the update's own checks caught the others.
    let zc = measurement.measure(k, &c.mean);
    if zc.nrows() != z.nrows() {
        return f64::NAN;
    }
    let e = measurement.residual(z, &zc);
    if e.nrows() != z.nrows() {
        return f64::NAN;
    }
    let meas_term = r.map_or(f64::NAN, |r| quad_or_non_finite(r, &e));
    match criterion {
        KappaCriterion::PureMap => prior_term + meas_term,
        _ => prior_term + meas_term - nis - 0.5 * c.s.log_det(),
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Filter<N, M> for Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        match self.prediction {
            UkfPrediction::Unscented => self.unscented_predict(),
            UkfPrediction::Linearised => {
                jacobian_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
            }
        }
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        self.unscented_update(z)
    }
}

/// `v^T S^-1 v` as a score term: `+inf` when it lies beyond f64's range, NaN for a non-finite
/// `v` (what the unchecked form gave before `quad_form` refused both).
fn quad_or_non_finite<M: Dim>(s: &Covariance<M>, v: &OVector<f64, M>) -> f64
where
    DefaultAllocator: Alloc<M>,
{
    s.quad_form(v).unwrap_or_else(|_| {
        if v.iter().all(|x| x.is_finite()) {
            f64::INFINITY
        } else {
            f64::NAN
        }
    })
}
