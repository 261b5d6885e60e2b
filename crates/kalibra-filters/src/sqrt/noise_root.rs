//! The square root of a noise covariance, kept between steps.

use kalibra_linalg::{
    Alloc, DefaultAllocator, Dim, LinalgError, OMatrix, semidefinite_factor, symmetrize,
};

/// A square root `L L^T = C` of the last noise covariance `C` a model returned (`Q_k` or `R_k`),
/// recomputed only when the model returns a different matrix: time-invariant models (most)
/// factor once, so a step pays one comparison instead of a pivoted factorisation.
#[derive(Clone, Debug)]
pub(crate) struct NoiseRoot<D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// The last covariance, NaN before the first (NaN equals nothing, so the first call
    /// factors), and its root.
    cov: OMatrix<f64, D, D>,
    root: OMatrix<f64, D, D>,
}

impl<D: Dim> NoiseRoot<D>
where
    DefaultAllocator: Alloc<D>,
{
    /// An empty cache for `d x d` covariances.
    pub(crate) fn new(d: D) -> Self {
        Self {
            cov: OMatrix::<f64, D, D>::from_element_generic(d, d, f64::NAN),
            root: OMatrix::<f64, D, D>::zeros_generic(d, d),
        }
    }

    /// A square root of `cov` (symmetrised first, as the standard filters' products symmetrise
    /// what it enters): the pivoted factor of [`semidefinite_factor`], so a rank-deficient
    /// noise (`Q = G G^T`, a perfect measurement) has one.
    ///
    /// # Errors
    /// [`semidefinite_factor`]'s: an indefinite or non-finite `cov`.
    pub(crate) fn root(
        &mut self,
        cov: &OMatrix<f64, D, D>,
        what: &'static str,
    ) -> Result<&OMatrix<f64, D, D>, LinalgError> {
        if &self.cov != cov {
            let mut sym = cov.clone();
            symmetrize(&mut sym);
            let (root, _) = semidefinite_factor(&sym, what)?;
            self.root = root;
            self.cov.clone_from(cov);
        }
        Ok(&self.root)
    }

    /// The root of the last covariance [`NoiseRoot::root`] accepted.
    pub(crate) fn last(&self) -> &OMatrix<f64, D, D> {
        &self.root
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::Matrix2;

    #[test]
    fn recomputes_only_for_a_new_matrix_and_refuses_an_indefinite_one() {
        let mut cache = NoiseRoot::new(kalibra_linalg::U2);
        let q = Matrix2::new(4.0, 2.0, 2.0, 2.0);
        let l = *cache.root(&q, "Q").unwrap();
        assert!((l * l.transpose() - q).amax() < 1e-14);
        let q2 = Matrix2::new(1.0, 0.0, 0.0, 9.0);
        let l2 = *cache.root(&q2, "Q").unwrap();
        assert!((l2 * l2.transpose() - q2).amax() < 1e-14);
        let bad = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        assert!(matches!(
            cache.root(&bad, "Q"),
            Err(LinalgError::NotPositiveSemiDefinite { .. })
        ));
    }
}
