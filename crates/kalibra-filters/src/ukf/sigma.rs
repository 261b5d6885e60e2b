//! Sigma-point sets ([`SigmaSet`]) and their weights ([`SigmaWeights`]).

use crate::FilterError;

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

/// `Ok` for a finite parameter value, [`FilterError::InvalidParameter`] otherwise.
pub(super) fn finite(name: &'static str, value: f64) -> Result<(), FilterError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(FilterError::InvalidParameter { name, value })
    }
}
