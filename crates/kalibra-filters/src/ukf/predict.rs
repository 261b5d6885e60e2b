//! The scalar UKF's unscented prediction: the posterior's sigma points through `f_k`.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, add_scatter, sigma_sqrt, symmetrize};
use kalibra_models::{Dynamics, Measurement};

use super::Ukf;
use super::points::{plain_mean, space_deviations, transform};
use crate::FilterError;
use crate::core::check_model_output;

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(super) fn unscented_predict(&mut self) -> Result<(), FilterError> {
        let k = self.core.step();
        let n = self.dynamics.state_dim().value();
        let w = self.sigma.set.weights(n)?;
        let x = self.core.mean().clone();
        let (l, _) = sigma_sqrt(self.core.cov(), "covariance for sigma points")
            .map_err(|e| FilterError::at(k, e))?;
        // The filter is untouched until the core stores the prediction.
        let points = &mut self.sigma.scratch_x;
        let x0 = transform(&self.dynamics, k, &x, &l, &w, points)?;
        let (mean, mut cov) = match &self.sigma.state_space {
            None => {
                let mean = plain_mean(&x0, points, &w);
                let d0 = &x0 - &mean;
                let mut cov = &d0 * d0.transpose() * w.cov_center;
                if N::try_to_usize().is_some() {
                    // Fixed sizes: the loop written out, as in the KF core (see there).
                    for xi in points.iter() {
                        let d = xi - &mean;
                        cov += &d * d.transpose() * w.other;
                    }
                } else {
                    add_scatter(&mut cov, points, &mean, w.other);
                }
                (mean, cov)
            }
            Some(space) => {
                let (mean, d0) = space_deviations(space.as_ref(), k, x0, points, &w)?;
                let mut cov = &d0 * d0.transpose() * w.cov_center;
                for d in points.iter() {
                    cov += d * d.transpose() * w.other;
                }
                (mean, cov)
            }
        };
        symmetrize(&mut cov);
        let f = self.dynamics.jacobian(k, &x);
        check_model_output("transition Jacobian F", &f, (n, n), k)?;
        let q = self.dynamics.noise_cov(k);
        check_model_output("process noise covariance Q", &q, (n, n), k)?;
        self.core.predict_unscented(mean, f, cov, q)
    }
}
