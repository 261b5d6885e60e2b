//! The unscented smoother's prediction (Sarkka 2008): the cross-covariance of the filter's own
//! sigma points and their images, for the [`Ukf`] and the [`SqrtUkf`].

use std::sync::Arc;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, sigma_sqrt};
use kalibra_models::{Dynamics, LinearDynamics, LinearMeasurement, Measurement};

use super::smoothable::linearised_cross;
use super::{Smoothable, Smoothed};
use crate::{
    Filter, FilterError, SigmaSpace, SigmaWeights, SqrtKf, SqrtUkf, Start, Ukf, UkfPrediction,
};

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Smoothable<N, M> for Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The unscented prediction's `C_k = sum_i Wc_i (X_i - x_k)(f(X_i) - x-_{k+1})^T` over the
    /// sigma points the filter drew (the same set, weights and square root of `P_k`), both
    /// deviations through the state space's residual; `P_k F_k^T` for
    /// [`UkfPrediction::Linearised`]. The central point's state deviation is zero, so it adds
    /// nothing.
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        if self.smoother_parts().0 == UkfPrediction::Linearised {
            return linearised_cross(self, |ukf, k, x| ukf.dynamics().jacobian(k, x));
        }
        let (k, x, p) = (
            self.step_index(),
            self.mean().clone(),
            self.covariance().clone(),
        );
        self.predict()?;
        // The prediction succeeded with these very points, so the weights are valid, the square
        // root exists and every image has the state's size.
        let w = self.sigma_set().weights(x.nrows())?;
        let (l, _) =
            sigma_sqrt(&p, "covariance for sigma points").map_err(|e| FilterError::at(k, e))?;
        let space = self.smoother_parts().1;
        Ok(cross(self.dynamics(), k, &x, &l, &w, space, self.mean()))
    }

    fn smoother_space(&self) -> Option<Arc<dyn SigmaSpace<N>>> {
        self.smoother_parts().1.cloned()
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Smoothable<N, M> for SqrtUkf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// As the [`Ukf`]'s, over the points the filter drew from its factor.
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        if self.smoother_parts().0 == UkfPrediction::Linearised {
            return linearised_cross(self, |ukf, k, x| ukf.dynamics().jacobian(k, x));
        }
        let (k, x, l) = (
            self.step_index(),
            self.mean().clone(),
            self.factor().clone(),
        );
        self.predict()?;
        let w = self.sigma_set().weights(x.nrows())?;
        let space = self.smoother_parts().1;
        Ok(cross(self.dynamics(), k, &x, &l, &w, space, self.mean()))
    }

    fn smoother_space(&self) -> Option<Arc<dyn SigmaSpace<N>>> {
        self.smoother_parts().1.cloned()
    }
}

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>> Smoothable<N, M>
    for SqrtKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// `P_k F_k^T`, with `P_k` the covariance the factor stands for (the record's).
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        linearised_cross(self, |kf, k, _| kf.dynamics().matrix(k))
    }

    /// The square-root smoother: the backward pass on the filter's Cholesky factors (one QR
    /// triangularisation per step, no predicted covariance factored), so that it carries on
    /// where the covariance form's Cholesky solve with `P-_{k+1}` fails (the test
    /// `tests/sqrt_ill_conditioned.rs`); equal to it where both work (`tests/sqrt_kf.rs`).
    /// [`Smoothable::forward`] and the fixed-lag smoother keep the covariance form.
    fn smooth<'z, I>(&mut self, measurements: I, start: Start) -> Result<Smoothed<N>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        self.smooth_factors(measurements, start)
    }
}

/// `sum_i W_i (X_i - x)(f(X_i) - predicted)^T` over the outer points `x +- spread L_j`.
fn cross<N: Dim>(
    dynamics: &impl Dynamics<N>,
    k: usize,
    x: &OVector<f64, N>,
    l: &OMatrix<f64, N, N>,
    w: &SigmaWeights,
    space: Option<&Arc<dyn SigmaSpace<N>>>,
    predicted: &OVector<f64, N>,
) -> OMatrix<f64, N, N>
where
    DefaultAllocator: Alloc<N>,
{
    let deviation = |a: &OVector<f64, N>, b: &OVector<f64, N>| match space {
        None => a - b,
        Some(space) => space.residual(a, b),
    };
    let (rows, cols) = l.shape_generic();
    let mut cross = OMatrix::<f64, N, N>::zeros_generic(rows, cols);
    for j in 0..x.nrows() {
        let d = l.column(j) * w.spread;
        for point in [x + &d, x - &d] {
            let image = dynamics.transition(k, &point);
            cross += deviation(&point, x) * deviation(&image, predicted).transpose() * w.other;
        }
    }
    cross
}
