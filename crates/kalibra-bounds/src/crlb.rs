//! The posterior Cramér-Rao bound for additive Gaussian noise, as an information recursion.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, check_dim, check_finite, symmetrize,
};

use crate::BoundsError;

/// One truth sample of a measurement: the Jacobian `H_k` and the noise covariance `R_k` at a
/// truth state.
pub type MeasurementSample<N, M> = (OMatrix<f64, M, N>, OMatrix<f64, M, M>);

/// The posterior Cramér-Rao bound (Tichavsky, Muravchik, Nehorai 1998) for
/// `x_{k+1} = f_k(x_k) + w_k`, `z_k = h_k(x_k) + v_k` with Gaussian `w`, `v`: the Fisher
/// information `J_k` of the state, stepped by [`Pcrlb::predict`] (the transition) and
/// [`Pcrlb::add_measurement`] (a measurement at the current step).
///
/// Each expectation over the truth is the average over a sample of Jacobians evaluated at
/// truth states (one per Monte Carlo truth, or a single one along a trajectory).
#[derive(Clone, Debug, PartialEq)]
pub struct Pcrlb<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    info: OMatrix<f64, N, N>,
}

impl<N: Dim> Pcrlb<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// Starts from the prior covariance `P0`: `J_0 = P0^-1`.
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] unless `P0` is symmetric positive definite with an inverse
    /// within f64's range.
    pub fn new(p0: &OMatrix<f64, N, N>) -> Result<Self, BoundsError> {
        let p0 = Covariance::named(p0.clone(), "initial covariance P0")?;
        let info = p0.inverse();
        check_finite(&info, "initial information P0^-1 (beyond f64's range)")?;
        Ok(Self { info })
    }

    /// Starts from a given information matrix `J_0` (zero for no prior information is not
    /// allowed by [`Pcrlb::bound`] until measurements make it positive definite).
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] if `J_0` is not square, finite, symmetric and positive
    /// semi-definite ([`check_covariance`](kalibra_linalg::check_covariance)).
    pub fn from_information(j0: OMatrix<f64, N, N>) -> Result<Self, BoundsError> {
        kalibra_linalg::check_covariance(
            &j0,
            "initial information J0",
            kalibra_linalg::Definiteness::SemiDefinite,
        )?;
        Ok(Self { info: j0 })
    }

    /// The current information matrix `J_k`.
    pub fn information(&self) -> &OMatrix<f64, N, N> {
        &self.info
    }

    /// The bound `J_k^-1` on the error covariance of any estimator.
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] if `J_k` is not positive definite (the state is not yet
    /// determined by the prior and the measurements) or its inverse lies beyond f64's range.
    pub fn bound(&self) -> Result<OMatrix<f64, N, N>, BoundsError> {
        let bound = Covariance::named(self.info.clone(), "Fisher information J")?.inverse();
        check_finite(&bound, "bound J^-1 (beyond f64's range)")?;
        Ok(bound)
    }

    /// The transition `k -> k + 1` with process noise `Q_k`:
    /// `J <- Q^-1 - Q^-1 E[F] (J + E[F^T Q^-1 F])^-1 E[F]^T Q^-1`, the expectations being
    /// averages over `f_samples` (the Jacobian `F_k` at each truth state `x_k`).
    ///
    /// # Errors
    /// [`BoundsError::EmptySample`] for no samples; [`BoundsError::Linalg`] if `Q_k` is not
    /// positive definite, a size differs, `J + D11` is not positive definite, or the new
    /// information lies beyond f64's range; `J` is unchanged on error.
    pub fn predict(
        &mut self,
        f_samples: &[OMatrix<f64, N, N>],
        q: &OMatrix<f64, N, N>,
    ) -> Result<(), BoundsError> {
        if f_samples.is_empty() {
            return Err(BoundsError::EmptySample { what: "E[F]" });
        }
        let n = self.info.nrows();
        let q = Covariance::named(q.clone(), "process noise covariance Q")?;
        check_dim(n, q.dim(), "process noise covariance Q")?;
        let count = f_samples.len() as f64;
        let mut mean_f = self.info.clone() * 0.0;
        let mut d11 = self.info.clone() * 0.0;
        for f in f_samples {
            check_dim(n, f.nrows(), "transition Jacobian F")?;
            check_dim(n, f.ncols(), "transition Jacobian F")?;
            check_finite(f, "transition Jacobian F")?;
            // F^T Q^-1 F through one solve.
            d11 += f.transpose() * q.solve(f)?;
            mean_f += f;
        }
        d11 /= count;
        mean_f /= count;
        // D12 = -E[F]^T Q^-1, so D12^T (J + D11)^-1 D12 = Q^-1 E[F] (J + D11)^-1 E[F]^T Q^-1.
        let mut inner = &self.info + d11;
        symmetrize(&mut inner);
        let inner = Covariance::named(inner, "J + E[F^T Q^-1 F]")?;
        let qinv_f = q.solve(&mean_f)?; // Q^-1 E[F]
        let x = inner.solve(&qinv_f.transpose())?; // (J + D11)^-1 E[F]^T Q^-1
        let mut next = q.inverse() - qinv_f * x;
        symmetrize(&mut next);
        // Nothing changes unless the new information is finite (a Q near the smallest
        // subnormal has an inverse beyond f64's range).
        check_finite(&next, "Fisher information J (beyond f64's range)")?;
        self.info = next;
        Ok(())
    }

    /// A measurement at the current step: `J <- J + E[H^T R^-1 H]`, averaged over
    /// `samples` of `(H_k, R_k)` at each truth state (state-dependent noise allowed).
    ///
    /// # Errors
    /// [`BoundsError::EmptySample`] for no samples; [`BoundsError::Linalg`] if an `R_k` is not
    /// positive definite, a size differs, or the new information lies beyond f64's range; `J`
    /// is unchanged on error.
    pub fn add_measurement<M: Dim>(
        &mut self,
        samples: &[MeasurementSample<N, M>],
    ) -> Result<(), BoundsError>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        if samples.is_empty() {
            return Err(BoundsError::EmptySample {
                what: "E[H^T R^-1 H]",
            });
        }
        let n = self.info.nrows();
        let mut sum = self.info.clone() * 0.0;
        for (h, r) in samples {
            check_dim(n, h.ncols(), "measurement Jacobian H")?;
            check_finite(h, "measurement Jacobian H")?;
            let r = Covariance::<M>::named(r.clone(), "measurement noise covariance R")?;
            check_dim(h.nrows(), r.dim(), "measurement noise covariance R")?;
            sum += h.transpose() * r.solve(h)?;
        }
        sum /= samples.len() as f64;
        let mut next = &self.info + sum;
        symmetrize(&mut next);
        check_finite(&next, "Fisher information J (beyond f64's range)")?;
        self.info = next;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use kalibra_linalg::{Matrix2, SMatrix};

    /// Along one trajectory of a linear model the bound is the Kalman filter's covariance.
    #[test]
    fn linear_bound_equals_the_kalman_covariance() {
        let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
        let q = Matrix2::new(0.25, 0.5, 0.5, 1.0) + Matrix2::identity() * 1e-2;
        let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
        let r = SMatrix::<f64, 1, 1>::new(4.0);
        let p0 = Matrix2::new(10.0, 1.0, 1.0, 5.0);
        let mut bound = Pcrlb::new(&p0).unwrap();
        let mut p = p0;
        for _ in 0..20 {
            bound.predict(&[f], &q).unwrap();
            bound.add_measurement(&[(h, r)]).unwrap();
            let prior = f * p * f.transpose() + q;
            let s = h * prior * h.transpose() + r;
            let k = prior * h.transpose() / s[(0, 0)];
            p = (Matrix2::identity() - k * h) * prior;
            assert_relative_eq!(bound.bound().unwrap(), p, max_relative = 1e-10);
        }
    }

    /// Averaging over truths: with two equally likely Jacobians, D11 and E[F] differ from
    /// the single-trajectory values, and the recursion uses both (checked by hand for n = 1).
    #[test]
    fn scalar_expectations_follow_the_recursion() {
        let mut b = Pcrlb::new(&SMatrix::<f64, 1, 1>::new(2.0)).unwrap();
        let fs = [
            SMatrix::<f64, 1, 1>::new(1.0),
            SMatrix::<f64, 1, 1>::new(3.0),
        ];
        b.predict(&fs, &SMatrix::<f64, 1, 1>::new(0.5)).unwrap();
        // J0 = 0.5; D11 = E[f^2]/q = 5/0.5 = 10; E[f] = 2; J1 = 1/q - (E[f]/q)^2/(J0 + D11).
        let expect = 2.0 - 16.0 / 10.5;
        assert_relative_eq!(b.information()[(0, 0)], expect, max_relative = 1e-14);
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        assert!(Pcrlb::new(&Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_err());
        // An indefinite information matrix was accepted (only symmetry was checked).
        assert!(Pcrlb::from_information(Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_err());
        assert!(Pcrlb::from_information(-Matrix2::identity()).is_err());
        assert!(Pcrlb::from_information(Matrix2::zeros()).is_ok());
        let mut b = Pcrlb::new(&Matrix2::identity()).unwrap();
        assert!(matches!(
            b.predict(&[], &Matrix2::identity()),
            Err(BoundsError::EmptySample { .. })
        ));
        // Rank-deficient Q: the information form needs Q^-1.
        assert!(
            b.predict(&[Matrix2::identity()], &Matrix2::new(1.0, 1.0, 1.0, 1.0))
                .is_err()
        );
        let h = SMatrix::<f64, 1, 2>::new(1.0, f64::NAN);
        let r = SMatrix::<f64, 1, 1>::new(1.0);
        assert!(matches!(
            b.add_measurement(&[(h, r)]),
            Err(BoundsError::Linalg(
                kalibra_linalg::LinalgError::NonFinite { .. }
            ))
        ));
        assert!(
            b.bound().is_ok(),
            "a rejected measurement leaves J unchanged"
        );
    }
}
