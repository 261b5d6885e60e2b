//! The scalar UKF's unscented prediction: the posterior's sigma points through `f_k`.

use kalibra_linalg::{
    Alloc, DefaultAllocator, Dim, add_scatter, propagate, sigma_sqrt, symmetrize,
};
use kalibra_models::{Dynamics, Measurement};

use super::Ukf;
use crate::FilterError;
use crate::core::check_model_output;

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(super) fn unscented_predict(&mut self) -> Result<(), FilterError> {
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
}
