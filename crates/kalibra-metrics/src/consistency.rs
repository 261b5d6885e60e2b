//! NEES, NIS and their chi-square acceptance bands.

use kalibra_linalg::{Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector};

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

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
/// [`MetricsError::Linalg`] if the sizes differ (`Dyn`), the innovation holds NaN or an
/// infinity (before, the NIS came back as NaN or inf inside `Ok`), or its form lies beyond
/// f64's range.
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

/// The smallest degrees of freedom [`ChiSquareBand::for_mean`] accepts: below it the
/// chi-square quantiles of statrs lose their accuracy, and at subnormal values it panicked.
/// Consistency statistics have a dimension as degrees of freedom, at least 1.
pub const CHI_SQUARE_MIN_DOF: f64 = 1e-3;

/// Total degrees of freedom from which [`ChiSquareBand`] uses the Wilson-Hilferty
/// approximation instead of statrs' inverse CDF (see [`ChiSquareBand::for_mean`]).
pub const WILSON_HILFERTY_FROM: f64 = 1e7;

/// The `p` quantile of chi-square with `k` degrees of freedom by Wilson and Hilferty's cube
/// of a normal, for large `k`.
/// The same quantile divided by the number of samples, `dof` being `k / samples`: computed
/// as `dof (...)^3`, finite even where `k` is not.
fn wilson_hilferty_mean(dof: f64, k: f64, p: f64) -> f64 {
    let z = Normal::standard().inverse_cdf(p);
    let a = 2.0 / (9.0 * k);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
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
    /// # Numerical choices
    /// Quantiles come from statrs' inverse chi-square CDF up to `samples dof` of
    /// [`WILSON_HILFERTY_FROM`], and from the Wilson-Hilferty approximation
    /// `k (1 - 2/(9k) + z sqrt(2/(9k)))^3` beyond: its error falls as `1/k` (3e-10 of the band's
    /// half-width at `k = 1e7`, where the two agree to that), while statrs' inversion loses
    /// accuracy above about `1e8` (at `1e15` its band no longer contains the mean, at `1e18` its
    /// bounds coincide, and at `1e300` it panics).
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for `dof` below [`CHI_SQUARE_MIN_DOF`] or not finite
    /// (statrs panicked on subnormal degrees of freedom), `samples == 0`, a confidence outside
    /// (0, 1) or so close to 1 that `(1 + confidence) / 2` rounds to 1 (the upper quantile is
    /// then infinite), or a band beyond f64's range (`dof` near `f64::MAX`).
    pub fn for_mean(dof: f64, samples: usize, confidence: f64) -> Result<Self, MetricsError> {
        if !(dof.is_finite() && dof >= CHI_SQUARE_MIN_DOF) {
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
        let tail = (1.0 - confidence) / 2.0;
        if 1.0 - tail >= 1.0 {
            return Err(MetricsError::InvalidParameter {
                name: "confidence",
                value: confidence,
            });
        }
        let band = Self::quantiles(dof, samples, total, tail, confidence)?;
        if !(band.lower.is_finite() && band.upper.is_finite()) {
            return Err(MetricsError::InvalidParameter {
                name: "degrees of freedom (band beyond f64's range)",
                value: dof,
            });
        }
        Ok(band)
    }

    /// The band's quantiles, unchecked (see [`ChiSquareBand::for_mean`]).
    fn quantiles(
        dof: f64,
        samples: usize,
        total: f64,
        tail: f64,
        confidence: f64,
    ) -> Result<Self, MetricsError> {
        if total >= WILSON_HILFERTY_FROM {
            // The band of the mean directly, `dof (1 - a + z sqrt(a))^3`: the total's quantile
            // divided by the samples would overflow for a total beyond f64's range (dof near
            // f64::MAX, or usize::MAX samples), where the band itself is finite.
            return Ok(Self {
                lower: wilson_hilferty_mean(dof, total, tail),
                upper: wilson_hilferty_mean(dof, total, 1.0 - tail),
                confidence,
            });
        }
        let (lower, upper) = {
            let chi2 = ChiSquared::new(total).map_err(|_| MetricsError::InvalidParameter {
                name: "degrees of freedom",
                value: total,
            })?;
            (chi2.inverse_cdf(tail), chi2.inverse_cdf(1.0 - tail))
        };
        Ok(Self {
            lower: lower / samples as f64,
            upper: upper / samples as f64,
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

#[cfg(test)]
mod band_tests {
    use super::*;

    /// The two quantile methods meet at the switch, and the band stays right far beyond it.
    #[test]
    fn bands_at_huge_degrees_of_freedom() {
        let k = WILSON_HILFERTY_FROM;
        let chi2 = ChiSquared::new(k).unwrap();
        let half_width = 1.96 * (2.0 * k).sqrt();
        for p in [0.025, 0.975] {
            assert!(
                (chi2.inverse_cdf(p) - wilson_hilferty_mean(k, k, p)).abs() < 1e-9 * half_width
            );
        }
        for dof in [1e8, 1e12, 1e15, 1e18] {
            let b = ChiSquareBand::for_mean(dof, 1, 0.95).unwrap();
            // Mean dof, half-width about 1.96 sqrt(2 dof).
            let half = 1.96 * (2.0 * dof).sqrt();
            assert!(b.lower < dof && dof < b.upper, "{dof:e}: {b:?}");
            assert!(
                ((b.upper - b.lower) / (2.0 * half) - 1.0).abs() < 1e-3,
                "{dof:e}: {b:?}"
            );
        }
        // At 1e300 the band is narrower than one ulp of the mean: both bounds round to it.
        let b = ChiSquareBand::for_mean(1e300, 1, 0.95).unwrap();
        assert_eq!((b.lower, b.upper), (1e300, 1e300));
        // The most samples a count can hold: a band around the mean, at once.
        let b = ChiSquareBand::for_mean(2.0, usize::MAX, 0.95).unwrap();
        assert!(b.lower < 2.0 && 2.0 < b.upper && b.upper - b.lower < 1e-8);
    }
}
