//! Constant-velocity and constant-acceleration models in any number of axes.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix};

use crate::{LinearGaussian, LinearObservation, ModelError};

/// How many derivatives of position the state holds per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// Position and velocity (constant velocity, CV).
    ConstantVelocity,
    /// Position, velocity and acceleration (constant acceleration, CA).
    ConstantAcceleration,
}

impl Order {
    /// States per axis: 2 for CV, 3 for CA.
    pub fn per_axis(self) -> usize {
        match self {
            Order::ConstantVelocity => 2,
            Order::ConstantAcceleration => 3,
        }
    }
}

/// How the states of several axes are ordered in the state vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// All positions, then all velocities (then all accelerations): `[x, y, vx, vy]`.
    Blocked,
    /// Axis by axis: `[x, vx, y, vy]` (papers 000 and 003), `[px, vx, ax, py, ...]` (paper 004).
    Interleaved,
}

/// The process-noise model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProcessNoise {
    /// Piecewise-constant white noise of the highest derivative held over each step (the
    /// "discrete white noise acceleration" model for CV, "discrete Wiener process acceleration"
    /// for CA): `Q = q G G^T` per axis, with `G = [T^2/2, T]^T` (CV) or `[T^2/2, T, 1]^T` (CA).
    /// `q` is the variance of the increment. Rank one per axis.
    Discrete {
        /// Variance of the piecewise-constant acceleration (CV) or acceleration increment (CA).
        q: f64,
    },
    /// Continuous white noise of the next derivative integrated over the step, with power
    /// spectral density `q`: per axis `q [[T^3/3, T^2/2], [T^2/2, T]]` (CV) or
    /// `q [[T^5/20, T^4/8, T^3/6], [T^4/8, T^3/3, T^2/2], [T^3/6, T^2/2, T]]` (CA).
    Continuous {
        /// Power spectral density.
        q: f64,
    },
}

/// A nearly-constant-velocity or nearly-constant-acceleration model in 1, 2 or 3 (or more)
/// axes, as [`LinearGaussian`] dynamics and a position [`LinearObservation`].
///
/// The same description serves fixed sizes and sizes known at run time; the dimension type is
/// chosen when the matrices are built, and must equal `axes * order.per_axis()`.
///
/// ```
/// use kalibra_models::{Kinematic, Layout, ProcessNoise};
/// use kalibra_linalg::{Matrix2, U2, U4};
///
/// // Workload W1: [x, y, vx, vy], T = 1, Q = G G^T, positions observed with R = 100 I.
/// let w1 = Kinematic::constant_velocity(2, 1.0)?
///     .layout(Layout::Blocked)
///     .noise(ProcessNoise::Discrete { q: 1.0 });
/// let dynamics = w1.dynamics(U4)?;
/// let sensor = w1.position_measurement(U4, U2, Matrix2::identity() * 100.0)?;
/// assert_eq!(dynamics.f()[(0, 2)], 1.0);
/// assert_eq!(sensor.h()[(1, 1)], 1.0);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kinematic {
    order: Order,
    axes: usize,
    dt: f64,
    layout: Layout,
    noise: ProcessNoise,
}

impl Kinematic {
    /// A model of the given order, with `Layout::Blocked` and `ProcessNoise::Discrete { q: 1 }`
    /// until changed.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] for `axes == 0`, `axes` whose state length overflows
    /// `usize`, or a non-positive or non-finite `dt`.
    pub fn new(order: Order, axes: usize, dt: f64) -> Result<Self, ModelError> {
        if axes == 0 {
            return Err(ModelError::InvalidParameter {
                name: "axes",
                value: 0.0,
            });
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "dt",
                value: dt,
            });
        }
        // The state length `axes * per_axis` must be a usize (`tests/extreme_sizes.rs`).
        if axes.checked_mul(order.per_axis()).is_none() {
            return Err(ModelError::InvalidParameter {
                name: "axes (state length beyond usize)",
                value: axes as f64,
            });
        }
        Ok(Self {
            order,
            axes,
            dt,
            layout: Layout::Blocked,
            noise: ProcessNoise::Discrete { q: 1.0 },
        })
    }

    /// A constant-velocity model.
    ///
    /// # Errors
    /// As [`Kinematic::new`].
    pub fn constant_velocity(axes: usize, dt: f64) -> Result<Self, ModelError> {
        Self::new(Order::ConstantVelocity, axes, dt)
    }

    /// A constant-acceleration model.
    ///
    /// # Errors
    /// As [`Kinematic::new`].
    pub fn constant_acceleration(axes: usize, dt: f64) -> Result<Self, ModelError> {
        Self::new(Order::ConstantAcceleration, axes, dt)
    }

    /// With the given state ordering.
    pub fn layout(mut self, layout: Layout) -> Self {
        self.layout = layout;
        self
    }

    /// With the given process noise.
    pub fn noise(mut self, noise: ProcessNoise) -> Self {
        self.noise = noise;
        self
    }

    /// The state length, `axes * order.per_axis()`.
    pub fn state_len(&self) -> usize {
        self.axes * self.order.per_axis()
    }

    /// Index in the state of derivative `deriv` (0 position, 1 velocity, 2 acceleration) of
    /// axis `axis`.
    ///
    /// # Panics
    /// If `axis` or `deriv` is out of range (a programming error).
    pub fn index(&self, axis: usize, deriv: usize) -> usize {
        let per = self.order.per_axis();
        assert!(
            axis < self.axes && deriv < per,
            "axis {axis} or derivative {deriv} out of range"
        );
        match self.layout {
            Layout::Blocked => deriv * self.axes + axis,
            Layout::Interleaved => axis * per + deriv,
        }
    }

    /// State indices of the positions, axis by axis.
    pub fn position_indices(&self) -> Vec<usize> {
        (0..self.axes).map(|a| self.index(a, 0)).collect()
    }

    /// State indices of the velocities, axis by axis.
    pub fn velocity_indices(&self) -> Vec<usize> {
        (0..self.axes).map(|a| self.index(a, 1)).collect()
    }

    fn check_state_dim<N: Dim>(&self, n: N) -> Result<(), ModelError> {
        if n.value() == self.state_len() {
            Ok(())
        } else {
            Err(ModelError::DimensionMismatch {
                what: "kinematic state",
                expected: self.state_len(),
                found: n.value(),
            })
        }
    }

    /// Per-axis transition block (row-major, `per x per`).
    fn axis_transition(&self) -> [[f64; 3]; 3] {
        let t = self.dt;
        [[1.0, t, t * t / 2.0], [0.0, 1.0, t], [0.0, 0.0, 1.0]]
    }

    /// Per-axis noise block.
    fn axis_noise(&self) -> Result<[[f64; 3]; 3], ModelError> {
        let t = self.dt;
        let per = self.order.per_axis();
        let mut out = [[0.0; 3]; 3];
        match self.noise {
            ProcessNoise::Discrete { q } => {
                check_q(q)?;
                let g: [f64; 3] = if per == 2 {
                    [t * t / 2.0, t, 0.0]
                } else {
                    [t * t / 2.0, t, 1.0]
                };
                for (i, row) in out.iter_mut().enumerate().take(per) {
                    for (j, v) in row.iter_mut().enumerate().take(per) {
                        *v = q * g[i] * g[j];
                    }
                }
            }
            ProcessNoise::Continuous { q } => {
                check_q(q)?;
                let (t2, t3) = (t * t, t * t * t);
                if per == 2 {
                    out[0][0] = q * t3 / 3.0;
                    out[0][1] = q * t2 / 2.0;
                    out[1][0] = q * t2 / 2.0;
                    out[1][1] = q * t;
                } else {
                    let (t4, t5) = (t3 * t, t3 * t2);
                    let block = [
                        [t5 / 20.0, t4 / 8.0, t3 / 6.0],
                        [t4 / 8.0, t3 / 3.0, t2 / 2.0],
                        [t3 / 6.0, t2 / 2.0, t],
                    ];
                    for i in 0..3 {
                        for j in 0..3 {
                            out[i][j] = q * block[i][j];
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    fn block_matrix<N: Dim>(&self, n: N, block: &[[f64; 3]; 3]) -> OMatrix<f64, N, N>
    where
        DefaultAllocator: Alloc<N>,
    {
        let per = self.order.per_axis();
        let mut m = OMatrix::<f64, N, N>::zeros_generic(n, n);
        for a in 0..self.axes {
            for i in 0..per {
                for j in 0..per {
                    m[(self.index(a, i), self.index(a, j))] = block[i][j];
                }
            }
        }
        m
    }

    /// The transition matrix `F` for a state of dimension `n`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if `n` is not [`Kinematic::state_len`].
    pub fn transition_matrix<N: Dim>(&self, n: N) -> Result<OMatrix<f64, N, N>, ModelError>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check_state_dim(n)?;
        Ok(self.block_matrix(n, &self.axis_transition()))
    }

    /// The process-noise covariance `Q` for a state of dimension `n`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] for the wrong `n`, [`ModelError::InvalidParameter`] for
    /// a negative or non-finite `q`.
    pub fn noise_matrix<N: Dim>(&self, n: N) -> Result<OMatrix<f64, N, N>, ModelError>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check_state_dim(n)?;
        Ok(self.block_matrix(n, &self.axis_noise()?))
    }

    /// The dynamics as a [`LinearGaussian`] model.
    ///
    /// # Errors
    /// As [`Kinematic::noise_matrix`].
    pub fn dynamics<N: Dim>(&self, n: N) -> Result<LinearGaussian<N>, ModelError>
    where
        DefaultAllocator: Alloc<N>,
    {
        LinearGaussian::new(self.transition_matrix(n)?, self.noise_matrix(n)?)
    }

    /// The measurement of all positions (`m = axes`), with noise covariance `r`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if `n` or `m` does not fit the model,
    /// [`ModelError::Linalg`] if `r` is not a valid covariance.
    pub fn position_measurement<N: Dim, M: Dim>(
        &self,
        n: N,
        m: M,
        r: OMatrix<f64, M, M>,
    ) -> Result<LinearObservation<N, M>, ModelError>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        self.check_state_dim(n)?;
        if m.value() != self.axes {
            return Err(ModelError::DimensionMismatch {
                what: "position measurement",
                expected: self.axes,
                found: m.value(),
            });
        }
        let mut h = OMatrix::<f64, M, N>::zeros_generic(m, n);
        for a in 0..self.axes {
            h[(a, self.index(a, 0))] = 1.0;
        }
        LinearObservation::new(h, r)
    }
}

fn check_q(q: f64) -> Result<(), ModelError> {
    if q.is_finite() && q >= 0.0 {
        Ok(())
    } else {
        Err(ModelError::InvalidParameter {
            name: "q",
            value: q,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use kalibra_linalg::{Dyn, Matrix4, SMatrix, U4, U6, U9};

    #[test]
    fn w1_matrices_match_the_scenario() {
        let t = 1.0;
        let m = Kinematic::constant_velocity(2, t).unwrap();
        let f = m.transition_matrix(U4).unwrap();
        assert_eq!(
            f,
            Matrix4::new(1., 0., t, 0., 0., 1., 0., t, 0., 0., 1., 0., 0., 0., 0., 1.)
        );
        let g = SMatrix::<f64, 4, 2>::new(t * t / 2.0, 0.0, 0.0, t * t / 2.0, t, 0.0, 0.0, t);
        assert_relative_eq!(
            m.noise_matrix(U4).unwrap(),
            g * g.transpose(),
            epsilon = 1e-15
        );
    }

    #[test]
    fn interleaved_ca_has_per_axis_blocks() {
        let dt = 0.05;
        let m = Kinematic::constant_acceleration(3, dt)
            .unwrap()
            .layout(Layout::Interleaved);
        let f = m.transition_matrix(U9).unwrap();
        assert_eq!(f[(3, 4)], dt);
        assert_eq!(f[(4, 4)], 1.0);
        assert_eq!(f[(3, 5)], dt * dt / 2.0);
        assert_eq!(f[(0, 3)], 0.0);
        let q = m.noise_matrix(U9).unwrap();
        assert_relative_eq!(q[(6, 8)], dt * dt / 2.0, epsilon = 1e-15);
        assert_eq!(m.position_indices(), vec![0, 3, 6]);
        assert_eq!(m.velocity_indices(), vec![1, 4, 7]);
    }

    #[test]
    fn continuous_noise_is_positive_definite_and_dyn_matches_const() {
        let m = Kinematic::constant_velocity(3, 2.0)
            .unwrap()
            .noise(ProcessNoise::Continuous { q: 0.5 });
        let fixed = m.dynamics(U6).unwrap();
        let dynamic = m.dynamics(Dyn(6)).unwrap();
        assert_eq!(fixed.q().rank(), 6);
        assert_eq!(fixed.f().as_slice(), dynamic.f().as_slice());
        assert_eq!(
            fixed.q().matrix().as_slice(),
            dynamic.q().matrix().as_slice()
        );
    }

    #[test]
    fn rejects_bad_parameters_and_dimensions() {
        assert!(matches!(
            Kinematic::constant_velocity(0, 1.0),
            Err(ModelError::InvalidParameter { .. })
        ));
        assert!(matches!(
            Kinematic::constant_velocity(1, -1.0),
            Err(ModelError::InvalidParameter { .. })
        ));
        assert!(matches!(
            Kinematic::constant_velocity(1, f64::NAN),
            Err(ModelError::InvalidParameter { .. })
        ));
        let m = Kinematic::constant_velocity(2, 1.0).unwrap();
        assert!(matches!(
            m.dynamics(U6),
            Err(ModelError::DimensionMismatch { .. })
        ));
        let bad_q = m.noise(ProcessNoise::Discrete { q: -1.0 });
        assert!(matches!(
            bad_q.dynamics(U4),
            Err(ModelError::InvalidParameter { .. })
        ));
    }
}
