//! Non-Euclidean sigma-point spaces ([`SigmaSpace`]), and the one with angle components
//! ([`AngleComponents`]).

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OVector};
use kalibra_models::wrap_angle;

use super::SigmaWeights;
use crate::FilterError;

/// How the UKF averages and subtracts the vectors of a space that is not plain Euclidean,
/// for instance one with angle components (FilterPy's `x_mean_fn`, `residual_x` and
/// `z_mean_fn`; Stone Soup's angle types).
///
/// A state space ([`Ukf::with_state_space`](crate::Ukf::with_state_space)) uses all three methods: the predicted mean of the
/// sigma points, the deviations that form the predicted covariance, and the normalisation of
/// the updated mean `x- + K nu`. A measurement mean ([`Ukf::with_measurement_mean`](crate::Ukf::with_measurement_mean)) uses
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
