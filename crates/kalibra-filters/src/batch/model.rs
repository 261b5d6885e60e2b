//! [`BatchModel`]: the shared linear model a [`KfBatch`](super::KfBatch) broadcasts.

use kalibra_linalg::{Definiteness, SMatrix, check_covariance, check_finite};

use crate::FilterError;

/// The shared, time-invariant linear model of a batch: `x_{k+1} = F x_k + w_k`, `w ~ N(0, Q)`,
/// `z_k = H x_k + v_k`, `v ~ N(0, R)`, stored row-major for broadcasting.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchModel<const N: usize, const M: usize> {
    pub(super) f: [[f64; N]; N],
    pub(super) q: [[f64; N]; N],
    pub(super) h: [[f64; N]; M],
    pub(super) r: [[f64; M]; M],
}

pub(super) fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> [[f64; C]; R] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

impl<const N: usize, const M: usize> BatchModel<N, M> {
    /// A model from its matrices.
    ///
    /// # Errors
    /// [`FilterError::Initial`] if `F` or `H` is not finite, or `Q` or `R` is not a symmetric
    /// positive semi-definite matrix (the check the scalar models apply).
    pub fn new(
        f: SMatrix<f64, N, N>,
        q: SMatrix<f64, N, N>,
        h: SMatrix<f64, M, N>,
        r: SMatrix<f64, M, M>,
    ) -> Result<Self, FilterError> {
        let init = FilterError::Initial;
        check_finite(&f, "transition matrix F").map_err(init)?;
        check_finite(&h, "measurement matrix H").map_err(init)?;
        check_covariance(&q, "process noise Q", Definiteness::SemiDefinite).map_err(init)?;
        check_covariance(&r, "measurement noise R", Definiteness::SemiDefinite).map_err(init)?;
        Ok(Self {
            f: rows(&f),
            q: rows(&q),
            h: rows(&h),
            r: rows(&r),
        })
    }
}
