//! Bearing measurements from a (possibly moving) platform, and angle wrapping.

use std::f64::consts::PI;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, SVector, U1};

use crate::{Measurement, ModelError};

/// Wraps an angle into (-pi, pi].
///
/// ```
/// use kalibra_models::wrap_angle;
/// use std::f64::consts::PI;
/// assert_eq!(wrap_angle(PI), PI);
/// assert_eq!(wrap_angle(-PI), PI);
/// assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
/// ```
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

/// Where a sensor is at step `k`, in `D` Cartesian coordinates.
pub trait Platform<const D: usize> {
    /// The sensor position at step `k`.
    fn position(&self, k: usize) -> SVector<f64, D>;
}

/// A sensor that does not move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stationary<const D: usize>(pub SVector<f64, D>);

impl<const D: usize> Platform<D> for Stationary<D> {
    fn position(&self, _k: usize) -> SVector<f64, D> {
        self.0
    }
}

/// A sensor whose positions are given step by step; after the table's end it stays at the last
/// position.
#[derive(Clone, Debug, PartialEq)]
pub struct Tabulated<const D: usize> {
    positions: Vec<SVector<f64, D>>,
}

impl<const D: usize> Tabulated<D> {
    /// A platform from its positions at steps `0, 1, ...`.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] for an empty table, [`ModelError::NonFinite`] for a
    /// non-finite position.
    pub fn new(positions: Vec<SVector<f64, D>>) -> Result<Self, ModelError> {
        if positions.is_empty() {
            return Err(ModelError::InvalidParameter {
                name: "platform table length",
                value: 0.0,
            });
        }
        if let Some(step) = positions
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return Err(ModelError::NonFinite {
                what: "platform position",
                step,
            });
        }
        Ok(Self { positions })
    }
}

impl<const D: usize> Platform<D> for Tabulated<D> {
    fn position(&self, k: usize) -> SVector<f64, D> {
        self.positions[k.min(self.positions.len() - 1)]
    }
}

/// A sensor whose position is a function of the step.
#[derive(Clone, Copy, Debug)]
pub struct Moving<F>(pub F);

impl<const D: usize, F: Fn(usize) -> SVector<f64, D>> Platform<D> for Moving<F> {
    fn position(&self, k: usize) -> SVector<f64, D> {
        (self.0)(k)
    }
}

/// From which axis a bearing is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BearingReference {
    /// Mathematical convention, from the x axis counter-clockwise: `atan2(dy, dx)`.
    XAxis,
    /// Nautical convention, from the y axis (north) clockwise: `atan2(dx, dy)`.
    North,
}

/// A bearing `z = atan2(..)` from a platform to the target's position, in radians, wrapped to
/// (-pi, pi]; the residual wraps too.
///
/// The target position is read from state indices `[ix, iy]`, so any state layout works.
#[derive(Clone, Debug)]
pub struct Bearing<N: Dim, P> {
    n: N,
    position: [usize; 2],
    reference: BearingReference,
    variance: f64,
    platform: P,
}

impl<N: Dim, P: Platform<2>> Bearing<N, P> {
    /// A bearing sensor on `platform` with noise variance `variance` (rad^2), observing the
    /// target position at state indices `position` of a state of dimension `n`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] for an index beyond the state,
    /// [`ModelError::InvalidParameter`] for a negative or non-finite variance.
    pub fn new(
        n: N,
        position: [usize; 2],
        reference: BearingReference,
        variance: f64,
        platform: P,
    ) -> Result<Self, ModelError> {
        for &i in &position {
            if i >= n.value() {
                return Err(ModelError::DimensionMismatch {
                    what: "bearing position index",
                    expected: n.value(),
                    found: i,
                });
            }
        }
        if !(variance.is_finite() && variance >= 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "bearing variance",
                value: variance,
            });
        }
        Ok(Self {
            n,
            position,
            reference,
            variance,
            platform,
        })
    }

    /// The platform.
    pub fn platform(&self) -> &P {
        &self.platform
    }

    /// Target position relative to the platform at step `k`.
    fn offset(&self, k: usize, x: &OVector<f64, N>) -> (f64, f64)
    where
        DefaultAllocator: Alloc<N>,
    {
        let p = self.platform.position(k);
        (x[self.position[0]] - p[0], x[self.position[1]] - p[1])
    }
}

impl<N: Dim, P: Platform<2>> Measurement<N, U1> for Bearing<N, P>
where
    DefaultAllocator: Alloc<N, U1>,
{
    fn meas_dim(&self) -> U1 {
        U1
    }

    fn measure(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, U1> {
        let (dx, dy) = self.offset(k, x);
        let z = match self.reference {
            BearingReference::XAxis => dy.atan2(dx),
            BearingReference::North => dx.atan2(dy),
        };
        OVector::<f64, U1>::new(z)
    }

    /// Undefined (non-finite) when the target sits on the platform; filters report that as an
    /// error.
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, U1, N> {
        let (dx, dy) = self.offset(k, x);
        let r2 = dx * dx + dy * dy;
        let (gx, gy) = match self.reference {
            BearingReference::XAxis => (-dy / r2, dx / r2),
            BearingReference::North => (dy / r2, -dx / r2),
        };
        let mut h = OMatrix::<f64, U1, N>::zeros_generic(U1, self.n);
        h[(0, self.position[0])] = gx;
        h[(0, self.position[1])] = gy;
        h
    }

    fn noise_cov(&self, _k: usize, _x: &OVector<f64, N>) -> OMatrix<f64, U1, U1> {
        OMatrix::<f64, U1, U1>::new(self.variance)
    }

    fn residual(&self, z: &OVector<f64, U1>, zhat: &OVector<f64, U1>) -> OVector<f64, U1> {
        OVector::<f64, U1>::new(wrap_angle(z[0] - zhat[0]))
    }

    fn normalize(&self, z: &mut OVector<f64, U1>) {
        z[0] = wrap_angle(z[0]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check_measurement_jacobian;
    use kalibra_linalg::{U4, Vector2, Vector4};

    #[test]
    fn bearing_jacobians_match_finite_differences_for_both_references() {
        let platform = Moving(|k: usize| Vector2::new((k as f64).cos(), (k as f64).sin()));
        for reference in [BearingReference::XAxis, BearingReference::North] {
            let m = Bearing::new(U4, [0, 1], reference, 1e-3, platform).unwrap();
            for x in [
                Vector4::new(20.0, 5.0, 1.0, 0.0),
                Vector4::new(-3.0, -0.1, 0.0, 2.0),
                Vector4::new(-7.0, 1e-3, 0.0, 0.0),
            ] {
                let check = check_measurement_jacobian(&m, 3, &x);
                assert!(check.scaled_error < 1e-7, "{reference:?} at {x}: {check:?}");
            }
        }
    }

    #[test]
    fn residual_does_not_jump_across_pi() {
        let m = Bearing::new(
            U4,
            [0, 1],
            BearingReference::XAxis,
            1e-3,
            Stationary(Vector2::zeros()),
        )
        .unwrap();
        let z = OVector::<f64, U1>::new(PI - 0.01);
        let zhat = OVector::<f64, U1>::new(-PI + 0.01);
        assert!((m.residual(&z, &zhat)[0] + 0.02).abs() < 1e-12);
        let north = Bearing::new(
            U4,
            [0, 1],
            BearingReference::North,
            1e-3,
            Stationary(Vector2::zeros()),
        )
        .unwrap();
        // Due east of the platform is 90 degrees nautical, 0 mathematical.
        let east = Vector4::new(1.0, 0.0, 0.0, 0.0);
        assert!((north.measure(0, &east)[0] - PI / 2.0).abs() < 1e-15);
        assert!(m.measure(0, &east)[0].abs() < 1e-15);
    }

    #[test]
    fn rejects_bad_construction() {
        let p = Stationary(Vector2::zeros());
        assert!(matches!(
            Bearing::new(U4, [0, 4], BearingReference::XAxis, 1.0, p),
            Err(ModelError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            Bearing::new(U4, [0, 1], BearingReference::XAxis, f64::NAN, p),
            Err(ModelError::InvalidParameter { .. })
        ));
        assert!(matches!(
            Tabulated::<2>::new(vec![]),
            Err(ModelError::InvalidParameter { .. })
        ));
    }
}
