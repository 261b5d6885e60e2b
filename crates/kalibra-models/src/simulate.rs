//! Seeded truth simulation.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OVector, check_dim, check_finite};
use rand::Rng;

use crate::{Dynamics, Measurement, ModelError};

/// One simulated step: the true state `x_k` and its measurement `z_k`.
pub type TruthStep<N, M> = (OVector<f64, N>, OVector<f64, M>);

/// Steps a true state and measures it, one step at a time, without storing the history: the
/// building block of Monte Carlo runs that stream into accumulators.
///
/// Each [`Simulator::step`] first measures the current state `x_k` (`z_k = h_k(x_k) + v_k`,
/// then normalised), then advances it (`x_{k+1} = f_k(x_k) + w_k`). The draws per step are
/// therefore always `v_k` then `w_k`, from the one generator passed in, so a run is fixed by its
/// seed. The truth's models need not be the filter's: give the simulator the true dynamics and
/// sensor (with noise the filter does not model, or a different `Q`), and the filter its own.
#[derive(Clone, Debug)]
pub struct Simulator<N: Dim, D, H>
where
    DefaultAllocator: Alloc<N>,
{
    dynamics: D,
    measurement: H,
    x: OVector<f64, N>,
    k: usize,
}

impl<N: Dim, D: Dynamics<N>, H> Simulator<N, D, H>
where
    DefaultAllocator: Alloc<N>,
{
    /// A simulator at state `x0` and step `k0`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if `x0` does not fit the dynamics,
    /// [`ModelError::Linalg`] if it is not finite.
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        k0: usize,
    ) -> Result<Self, ModelError> {
        check_dim(dynamics.state_dim().value(), x0.nrows(), "initial state")?;
        check_finite(&x0, "initial state")?;
        Ok(Self {
            dynamics,
            measurement,
            x: x0,
            k: k0,
        })
    }

    /// The current true state `x_k`.
    pub fn state(&self) -> &OVector<f64, N> {
        &self.x
    }

    /// The current step index `k`.
    pub fn step_index(&self) -> usize {
        self.k
    }

    /// Measures `x_k`, advances to `k + 1`, and returns `(x_k, z_k)`.
    ///
    /// # Errors
    /// [`ModelError::NonFinite`] if the measurement or the next state is not finite (a
    /// diverging truth), or a model's sampling error; [`ModelError::InvalidParameter`] at step
    /// `usize::MAX`.
    pub fn step<M: Dim, R: Rng + ?Sized>(
        &mut self,
        rng: &mut R,
    ) -> Result<TruthStep<N, M>, ModelError>
    where
        H: Measurement<N, M>,
        DefaultAllocator: Alloc<N, M>,
    {
        let k = self.k;
        // Checked before anything is drawn: a step index at usize::MAX has no successor.
        let Some(next_k) = k.checked_add(1) else {
            return Err(ModelError::InvalidParameter {
                name: "step index (usize::MAX has no next step)",
                value: k as f64,
            });
        };
        let mut z = self.measurement.measure(k, &self.x)
            + self.measurement.sample_noise(k, &self.x, rng)?;
        self.measurement.normalize(&mut z);
        if !kalibra_linalg::all_finite(&z) {
            return Err(ModelError::NonFinite {
                what: "simulated measurement",
                step: k,
            });
        }
        let next = self.dynamics.transition(k, &self.x) + self.dynamics.sample_noise(k, rng)?;
        if !kalibra_linalg::all_finite(&next) {
            return Err(ModelError::NonFinite {
                what: "simulated state",
                step: k + 1,
            });
        }
        let x = std::mem::replace(&mut self.x, next);
        self.k = next_k;
        Ok((x, z))
    }
}

/// A simulated run: true states and their measurements, `states[i]` and `measurements[i]` at
/// step `first_step + i`.
#[derive(Clone, Debug)]
pub struct Truth<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Step index of the first entry.
    pub first_step: usize,
    /// True states.
    pub states: Vec<OVector<f64, N>>,
    /// Noisy measurements of the states.
    pub measurements: Vec<OVector<f64, M>>,
}

impl<N: Dim, M: Dim> Truth<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether the run is empty.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }
}

/// Simulates `steps` steps from `x0` at step 0: states `x_0 .. x_{steps-1}` and their
/// measurements. Draw order as in [`Simulator::step`].
///
/// ```
/// use kalibra_models::{simulate, Kinematic};
/// use kalibra_linalg::{Matrix2, U2, U4, Vector4};
/// use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?);
/// let mut rng = ChaCha8Rng::seed_from_u64(7);
/// let truth = simulate(&f, &h, Vector4::new(0.0, 0.0, 10.0, 5.0), 50, &mut rng)?;
/// assert_eq!(truth.len(), 50);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
///
/// # Errors
/// As [`Simulator::new`] and [`Simulator::step`], and [`ModelError::InvalidParameter`] for
/// more `steps` than memory holds (checked before the first step).
pub fn simulate<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>, R: Rng + ?Sized>(
    dynamics: D,
    measurement: H,
    x0: OVector<f64, N>,
    steps: usize,
    rng: &mut R,
) -> Result<Truth<N, M>, ModelError>
where
    DefaultAllocator: Alloc<N, M>,
{
    // The truth's `steps` states are reserved first: a count that no memory holds (such as
    // `usize::MAX`) is an error at once, not a loop that ends when memory does
    // (`tests/extreme_sizes.rs`).
    let too_many = |_| ModelError::InvalidParameter {
        name: "steps (more states than memory holds)",
        value: steps as f64,
    };
    let mut truth = Truth {
        first_step: 0,
        states: Vec::new(),
        measurements: Vec::new(),
    };
    truth.states.try_reserve_exact(steps).map_err(too_many)?;
    truth
        .measurements
        .try_reserve_exact(steps)
        .map_err(too_many)?;
    record(truth, dynamics, measurement, x0, steps, rng, |_, _| false)
}

/// Simulates from `x0` at step 0 until `stop(k, x_k)` is true (that state is not recorded) or
/// `max_steps` states are recorded: for a re-entry truth, `stop` is "below ground".
///
/// # Errors
/// As [`Simulator::new`] and [`Simulator::step`].
pub fn simulate_until<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>, R: Rng + ?Sized>(
    dynamics: D,
    measurement: H,
    x0: OVector<f64, N>,
    max_steps: usize,
    rng: &mut R,
    stop: impl FnMut(usize, &OVector<f64, N>) -> bool,
) -> Result<Truth<N, M>, ModelError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let truth = Truth {
        first_step: 0,
        states: Vec::new(),
        measurements: Vec::new(),
    };
    record(truth, dynamics, measurement, x0, max_steps, rng, stop)
}

/// [`simulate_until`] into `truth` (empty, perhaps with room reserved).
fn record<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>, R: Rng + ?Sized>(
    mut truth: Truth<N, M>,
    dynamics: D,
    measurement: H,
    x0: OVector<f64, N>,
    max_steps: usize,
    rng: &mut R,
    mut stop: impl FnMut(usize, &OVector<f64, N>) -> bool,
) -> Result<Truth<N, M>, ModelError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let mut sim = Simulator::new(dynamics, measurement, x0, 0)?;
    while truth.len() < max_steps && !stop(sim.step_index(), sim.state()) {
        let (x, z) = sim.step(rng)?;
        truth.states.push(x);
        truth.measurements.push(z);
    }
    Ok(truth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Kinematic, LinearGaussian, check_dynamics_jacobian};
    use kalibra_linalg::{Matrix2, OMatrix, U2, U4, Vector2, Vector4};
    use rand_chacha::ChaCha8Rng;
    use rand_chacha::rand_core::SeedableRng;

    fn w1() -> (LinearGaussian<U4>, crate::LinearObservation<U4, U2>) {
        let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
        (
            cv.dynamics(U4).unwrap(),
            cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)
                .unwrap(),
        )
    }

    #[test]
    fn same_seed_same_truth_other_seed_other_truth() {
        let (f, h) = w1();
        let x0 = Vector4::new(0.0, 0.0, 10.0, 5.0);
        let a = simulate(&f, &h, x0, 20, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let b = simulate(&f, &h, x0, 20, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let c = simulate(&f, &h, x0, 20, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        assert_eq!(a.states, b.states);
        assert_eq!(a.measurements, b.measurements);
        assert_ne!(a.states[5], c.states[5]);
        assert_eq!(a.states[0], x0);
    }

    #[test]
    fn sampled_noise_has_the_model_covariance() {
        // 2e5 draws: the standard error of each covariance entry is below 1% of its scale,
        // so a 3% tolerance fails only on a real error.
        let (f, _) = w1();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 200_000;
        let mut acc = OMatrix::<f64, U4, U4>::zeros();
        for _ in 0..n {
            let w = f.sample_noise(0, &mut rng).unwrap();
            acc += w * w.transpose();
        }
        acc /= n as f64;
        let q = f.q().matrix();
        for (a, b) in acc.iter().zip(q.iter()) {
            assert!((a - b).abs() < 0.03 * q.max(), "{acc} vs {q}");
        }
    }

    #[test]
    fn stops_when_told_and_reports_divergence() {
        let (f, h) = w1();
        let truth = simulate_until(
            &f,
            &h,
            Vector4::new(0.0, 0.0, 1.0, 0.0),
            100,
            &mut ChaCha8Rng::seed_from_u64(1),
            |_, x| x[0] > 5.5,
        )
        .unwrap();
        assert!(truth.states.iter().all(|x| x[0] <= 5.5));
        assert!(truth.len() < 100);
        let exploding = LinearGaussian::new(Matrix2::identity() * 1e200, Matrix2::zeros()).unwrap();
        let sensor =
            crate::LinearObservation::new(Matrix2::identity(), Matrix2::identity()).unwrap();
        let err = simulate(
            &exploding,
            &sensor,
            Vector2::new(1e200, 0.0),
            3,
            &mut ChaCha8Rng::seed_from_u64(1),
        );
        assert!(matches!(err, Err(ModelError::NonFinite { .. })));
    }

    #[test]
    fn jacobian_checker_catches_a_wrong_derivative() {
        struct Wrong;
        impl Dynamics<U2> for Wrong {
            fn state_dim(&self) -> U2 {
                U2
            }
            fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
                Vector2::new(x[0] * x[1], x[1].sin())
            }
            fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> Matrix2<f64> {
                // d(sin y)/dy written as sin y instead of cos y.
                Matrix2::new(x[1], x[0], 0.0, x[1].sin())
            }
            fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
                Matrix2::zeros()
            }
        }
        let check = check_dynamics_jacobian(&Wrong, 0, &Vector2::new(1.0, 0.3));
        assert!(check.scaled_error > 0.1, "{check:?}");
    }
}
