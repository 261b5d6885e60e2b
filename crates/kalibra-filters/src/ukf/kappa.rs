//! The adaptive UKF's choice of kappa: the criteria ([`KappaCriterion`]) and the grid
//! ([`KappaGrid`]).

use super::sigma::finite;
use crate::FilterError;

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

/// The most values [`KappaGrid::equidistant`] makes: each kappa costs a sigma-point update
/// per step, and a grid of millions is a mistaken count, not a search.
pub const KAPPA_GRID_MAX: usize = 1 << 16;

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
    /// As [`KappaGrid::new`]; `count == 0` or above [`KAPPA_GRID_MAX`], or `count > 1` with
    /// `max <= min`.
    pub fn equidistant(min: f64, max: f64, count: usize) -> Result<Self, FilterError> {
        // Checked before the values are collected: `usize::MAX` values cannot be held.
        if count > KAPPA_GRID_MAX {
            return Err(FilterError::InvalidParameter {
                name: "kappa grid length (above KAPPA_GRID_MAX)",
                value: count as f64,
            });
        }
        let values = match count {
            0 => Vec::new(),
            1 => vec![min],
            _ => {
                let step = (max - min) / (count - 1) as f64;
                if step.is_finite() {
                    (0..count).map(|i| min + step * i as f64).collect()
                } else {
                    // Ends of opposite signs near the limit: their difference overflows, the
                    // values between them do not (`tests/extreme_floats.rs`).
                    let last = (count - 1) as f64;
                    (0..count)
                        .map(|i| {
                            let w = i as f64 / last;
                            min * (1.0 - w) + max * w
                        })
                        .collect()
                }
            }
        };
        Self::new(values)
    }

    /// The values.
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

impl KappaCriterion {
    /// The criterion's value for one candidate kappa (smaller is better), from `ln|Pz|`, the
    /// NIS `nu^T Pz^-1 nu` and, for the posterior criteria only (evaluated when needed), the
    /// prior's term `nu^T U nu` and the measurement's `e^T R^-1 e`. The scalar [`Ukf`] and the
    /// batched [`UkfBatch`](crate::batch::UkfBatch) both call it, so a lane's choice is the
    /// scalar's (`tests/batch_ukf.rs`).
    ///
    /// [`Ukf`]: super::Ukf
    #[inline]
    pub(crate) fn value(
        self,
        log_det: f64,
        nis: f64,
        posterior_terms: impl FnOnce() -> (f64, f64),
    ) -> f64 {
        if self == KappaCriterion::MaximumLikelihood {
            return log_det + nis;
        }
        let (prior_term, meas_term) = posterior_terms();
        match self {
            KappaCriterion::PureMap => prior_term + meas_term,
            _ => prior_term + meas_term - nis - 0.5 * log_det,
        }
    }

    /// Whether a candidate's `value` replaces the best so far (`None` before the first):
    /// strictly smaller wins, so ties keep the smaller kappa, and a non-finite value never
    /// wins.
    #[inline]
    pub(crate) fn improves(value: f64, best: Option<f64>) -> bool {
        value.is_finite() && best.is_none_or(|best| value < best)
    }
}
