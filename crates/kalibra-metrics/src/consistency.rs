//! NEES, NIS and their chi-square acceptance bands.

use kalibra_linalg::{Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector};

use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::MetricsError;

/// The normalised estimation error squared `e^T P^-1 e`, `e = x_true - x_est` (the sign does
/// not matter), factorising `P`.
///
/// ```
/// use kalibra_metrics::nees;
/// use kalibra_linalg::{Matrix2, Vector2};
/// let e = Vector2::new(1.0, 2.0);
/// assert!((nees(&e, &Matrix2::new(1.0, 0.0, 0.0, 4.0))? - 2.0).abs() < 1e-15);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::Linalg`] if `P` is not symmetric positive definite or not finite, or the
/// sizes differ (`Dyn`).
pub fn nees<N: Dim>(error: &OVector<f64, N>, cov: &OMatrix<f64, N, N>) -> Result<f64, MetricsError>
where
    DefaultAllocator: Alloc<N>,
{
    // Called once per run and step in every Monte Carlo study: factorise without keeping a
    // `Covariance` (which would copy P twice), but check what `Covariance::new` checks.
    Ok(kalibra_linalg::quad_form_once(
        cov,
        error,
        "state covariance P",
    )?)
}

/// The normalised innovation squared `nu^T S^-1 nu` with an already factorised `S` (a step
/// record keeps one).
///
/// # Errors
/// [`MetricsError::Linalg`] if the sizes differ (`Dyn`).
pub fn nis<M: Dim>(innovation: &OVector<f64, M>, s: &Covariance<M>) -> Result<f64, MetricsError>
where
    DefaultAllocator: Alloc<M>,
{
    Ok(s.quad_form(innovation)?)
}

/// A two-sided acceptance interval for a consistency statistic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChiSquareBand {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Probability that a consistent filter's statistic falls inside.
    pub confidence: f64,
}

impl ChiSquareBand {
    /// The band for the mean of `samples` independent chi-square variables with `dof` degrees of
    /// freedom: `[chi2_{(1-c)/2}(samples dof), chi2_{(1+c)/2}(samples dof)] / samples`, since
    /// the sum of the samples is chi-square with `samples * dof` degrees of freedom. This is the
    /// band of the average NEES (`dof = n`) or average NIS (`dof = m`) over `samples` Monte
    /// Carlo runs at one step.
    ///
    /// ```
    /// use kalibra_metrics::ChiSquareBand;
    /// // Bar-Shalom, Li, Kirubarajan (2001), example 5.4.2: n = 2, 50 runs, 95%: [1.5, 2.6].
    /// let band = ChiSquareBand::for_mean(2.0, 50, 0.95)?;
    /// assert!((band.lower - 1.5).abs() < 0.02 && (band.upper - 2.6).abs() < 0.02);
    /// # Ok::<(), kalibra_metrics::MetricsError>(())
    /// ```
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for `dof <= 0`, `samples == 0`, or a confidence outside
    /// (0, 1).
    pub fn for_mean(dof: f64, samples: usize, confidence: f64) -> Result<Self, MetricsError> {
        if !(dof.is_finite() && dof > 0.0) {
            return Err(MetricsError::InvalidParameter {
                name: "degrees of freedom",
                value: dof,
            });
        }
        if samples == 0 {
            return Err(MetricsError::InvalidParameter {
                name: "samples",
                value: 0.0,
            });
        }
        if !(confidence > 0.0 && confidence < 1.0) {
            return Err(MetricsError::InvalidParameter {
                name: "confidence",
                value: confidence,
            });
        }
        let total = dof * samples as f64;
        let chi2 = ChiSquared::new(total).map_err(|_| MetricsError::InvalidParameter {
            name: "degrees of freedom",
            value: total,
        })?;
        let tail = (1.0 - confidence) / 2.0;
        Ok(Self {
            lower: chi2.inverse_cdf(tail) / samples as f64,
            upper: chi2.inverse_cdf(1.0 - tail) / samples as f64,
            confidence,
        })
    }

    /// The same band divided by `dof`: for the ANEES normalised by the state dimension
    /// (`mean NEES / n`, paper 001), whose consistent value is 1.
    ///
    /// # Errors
    /// As [`ChiSquareBand::for_mean`].
    pub fn for_normalized_mean(
        dof: f64,
        samples: usize,
        confidence: f64,
    ) -> Result<Self, MetricsError> {
        let b = Self::for_mean(dof, samples, confidence)?;
        Ok(Self {
            lower: b.lower / dof,
            upper: b.upper / dof,
            confidence,
        })
    }

    /// Whether `value` lies inside (bounds included).
    pub fn contains(&self, value: f64) -> bool {
        value >= self.lower && value <= self.upper
    }
}
