//! Paper 001's three bearings-only tracking (BOT) problems as ready scenarios: the truth, the
//! platform, the filter's dynamics and bearing model, and the filter's initialisation.
//!
//! Each problem is a [`BotScenario`]: [`BotScenario::problem_i`], [`BotScenario::problem_ii`],
//! [`BotScenario::problem_iii`]. [`BotScenario::simulate`] draws one Monte Carlo run (true
//! states, bearings, the filter's initial estimate) from a seeded generator. The filters live in
//! `kalibra-filters`; this module says only how a run starts ([`BotStart`]) and from which index
//! the metrics count (`eval_from`).
//!
//! Every reading of the paper (units, geometry, noise, initialisation, indexing) is documented
//! on [`BotScenario`], where users of the re-exported types see it.

use std::f64::consts::PI;
use std::ops::Range;

use kalibra_linalg::{
    Alloc, DefaultAllocator, Dim, Gaussian, Matrix2, Matrix4, OMatrix, OVector, SMatrix, SVector,
    U1, U2, U4, Vector1, Vector2, Vector4,
};
use rand::Rng;

use kalibra_models::{
    Bearing, BearingReference, Coordinate, Dynamics, Kinematic, LinearGaussian, ModelError,
    ProcessNoise, Tabulated, simulate, standard_normal,
};

/// One knot in km/min.
const KNOT: f64 = 1.852 / 60.0;

/// Problem I: the truth's initial state `[x, xdot]` (m, m/s).
const I_X0: [f64; 2] = [80.0, 1.0];
/// Problem I: platform speed along x (m/s) and its y (m).
const I_PLATFORM_SPEED: f64 = 4.0;
const I_PLATFORM_Y: f64 = -20.0;
/// Problem I: variance of the velocity's initial estimate, (m/s)^2.
const I_INIT_VELOCITY_VAR: f64 = 1.0;

/// Problem II: target start (km), course (deg) and speed (knots).
const II_TARGET_START: [f64; 2] = [7.0, 7.0];
const II_TARGET_COURSE_DEG: f64 = -135.4;
const II_TARGET_SPEED_KN: f64 = 15.0;
/// Problem II: platform courses (deg), speed (knots) and the index of the turn.
const II_PLATFORM_COURSE_DEG: [f64; 2] = [-80.0, 146.0];
const II_PLATFORM_SPEED_KN: f64 = 5.0;
const II_TURN_INDEX: usize = 14;
/// Problem II: the filter's process-noise intensity, km^2/min^4.
const II_Q: f64 = 9.92e-8;
/// Problem II: the initial range's standard deviation (km) and the speed's (knots).
const II_INIT_RANGE_SD: f64 = 4.0;
const II_INIT_SPEED_SD_KN: f64 = 4.0;

/// Problem III: prior mean and variance per axis.
const III_MEAN: [f64; 2] = [20.0, 5.0];
const III_VAR: f64 = 0.1;

/// Which of paper 001's bearings-only problems a scenario is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BotProblem {
    /// Problem I: a target on a line, translational noise (metres, seconds).
    I,
    /// Problem II: the manoeuvring-observer problem of the paper's reference \[1\] (km, minutes).
    II,
    /// Problem III: a decelerating target seen from a platform on the unit circle
    /// (dimensionless).
    III,
}

impl BotProblem {
    /// The length unit of states and positions: `"m"`, `"km"`, or `""` (dimensionless).
    pub fn length_unit(self) -> &'static str {
        match self {
            BotProblem::I => "m",
            BotProblem::II => "km",
            BotProblem::III => "",
        }
    }

    /// The time unit of steps and velocities: `"s"`, `"min"`, or `""` (dimensionless).
    pub fn time_unit(self) -> &'static str {
        match self {
            BotProblem::I => "s",
            BotProblem::II => "min",
            BotProblem::III => "",
        }
    }
}

/// How a filter starts on a scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BotStart {
    /// The initial estimate is the estimate at index 0; the filter predicts to index 1 and
    /// updates with the measurement there, and the measurement at index 0 is used only by the
    /// initialisation (problems I and II).
    PredictFirst,
    /// The initial estimate is a prior at index 0, which the filter first updates with the
    /// measurement at index 0 (problem III).
    UpdateFirst,
}

/// One of paper 001's bearings-only problems: truth, platform, the filter's models and how the
/// filter starts, with every reading of the paper below.
///
/// The fields are public so a study can vary them (a `Q` sweep replaces `dynamics`); the
/// constructors are the only way to build one, and [`BotScenario::simulate`] and
/// [`BotScenario::initialize`] follow `problem` for the true initial state and the
/// initialisation, reading the noise levels from `measurement`.
///
/// # Conventions shared by the three problems
/// * Indices `i = 0 .. steps-1` are the entries of a run; the paper's step label is
///   `first_label + i` ([`BotScenario::labels`]). The sampling period is `T = 1` in each
///   problem's time unit, so index `i` is at time `i`.
/// * Bearings are four-quadrant (`atan2`) and wrapped to (-pi, pi]; so are residuals.
/// * The platform is a [`Tabulated`] table with one position per index; past its end it stays
///   put, so a filter run longer than `steps` sees a parked platform.
/// * The truth measures `x_i`, then steps to `x_{i+1}` ([`kalibra_models::Simulator`]); the filter's
///   prediction is the exact linear one, with `Qd = G Q G^T`.
///
/// # Problem I (metres, seconds; paper section IV.A, its reference \[8\])
/// * State `[x, xdot]` of a target on the line `y = 0`; `x_0 = [80, 1]`; `F = [[1, T], [0, 1]]`,
///   process noise `G w` with `G = [T^2/2, T]^T`, `Q = 0.01` (m/s^2)^2, in the truth and in the
///   filter alike.
/// * Platform at `(4k, -20)`, so the relative position is `(x_k - 4k, 20)`; the target's `y` is
///   [`Coordinate::Constant`]`(0)`. Bearings from the x axis with translational noise of
///   variance 1 m^2 per axis and `R_theta = 0.0524^2` rad^2 (the paper's value; `(3 deg)^2` is
///   `0.05236^2`): `z_k = atan2(20 + v_y, x_k - 4k + v_x) + v_theta` (eq 38).
/// * The truth draws that law exactly; the filter's [`Bearing`] reports the effective variance
///   `R_eff = R_theta + g^T diag(1, 1) g` linearised where it is asked ([`Bearing`] docs).
/// * 41 indices, labels `k = 0..40`. Initialisation (the paper gives none): from `z_0`, the
///   position that puts the target on its line at bearing `z_0`, `x = 4 * 0 + 20 / tan z_0`,
///   with the first-order variance of the three noises at `z_0`:
///   `var_x + var_y cot^2 z_0 + R_theta 20^2 / sin^4 z_0`; velocity 0 with variance 1 (m/s)^2;
///   no correlation. That is the estimate at index 0: filters predict to index 1 and update with
///   `z_1` ([`BotStart::PredictFirst`]), and metrics count from index 1 (`eval_from = 1`), as the
///   paper's figures show `k = 1..40`.
/// * The first-order variance is exact only for small noise: at the paper's noise the spread
///   of `20 / tan z_0` is about twice it (a heavy tail from bearings near 0, where `cot` is
///   steep); the tests measure both.
///
/// # Problem II (kilometres, minutes; paper section IV.B, its reference \[1\])
/// * State `[x, y, xdot, ydot]` (km, km/min), `T = 1` min, 50 indices for `t = 0..49` min,
///   labelled `k = 1..50`.
/// * Courses are nautical (clockwise from north, velocity `s (sin c, cos c)`), and 1 knot is
///   `1.852 / 60` km/min. Target from `(7, 7)` km on course -135.4 deg at 15 knots; platform from
///   `(0, 0)` on course -80 deg at 5 knots, turning instantly to 146 deg at index 14 (`t = 14`
///   min, label `k = 15`): it moves on the old course over `[0, 14]` min and on the new one
///   after. With this reading the bearing rate peaks at about 125 deg/min near `t = 25` min, as
///   the paper describes (it says 135 deg/min at the 26th minute); a turn one minute later
///   gives a peak of only about 58 deg/min. The tests check it.
/// * Near the closest approach (about 0.21 km at `t` = 24.9 min) the bearing sweeps from 91 deg
///   (index 24) to 166 deg (index 25) and through 180 deg to -139 deg (index 26): the true
///   bearing crosses +-180 deg once, between indices 25 and 26 (labels 26 and 27), so the
///   measurements jump by about -305 deg while the wrapped change is +55 deg. Residuals and
///   sigma-point bearings must wrap there.
/// * Truth without process noise (straight lines). Bearings nautical, `z = atan2(x - x_p, y -
///   y_p)`, `R = (2 deg)^2`, no translational noise.
/// * Filter `Q`: the printed "9.92e-2 km^2/s^2" is read as `9.92e-8` km^2/min^4 (the printed
///   number in m^2/min^4; taken literally in km and minutes every filter diverges), with the
///   printed `G` reordered for the state `[x, y, xdot, ydot]`: `G = [[T^2/2, 0], [0, T^2/2],
///   [T, 0], [0, T]]`, `Qd = q G G^T`.
/// * Initialisation from `z_1` (index 0), following the paper's reference \[1\]: range
///   `r ~ N(sqrt(98), 4^2)` km, speed `s ~ N(15, 4^2)` knots (the true speed), course
///   `c ~ N(z_1 + pi, pi^2 / 12)` (heading toward the observer), bearing `theta ~ N(z_1,
///   R)`, all independent, mapped to the state `[p + r u(theta), s u(c)]` (`p` the platform at
///   index 0, `u(a) = (sin a, cos a)`). The mean is the map at the means and the covariance is
///   first order: with `u' = du/da`,
///   `P_pos = var_r u u^T + r^2 R u' u'^T` at `theta = z_1`,
///   `P_vel = var_s u u^T + s^2 var_c u' u'^T` at `c = z_1 + pi`, and no position-velocity
///   correlation (the course spread is its own, not the bearing's). It is the estimate at index
///   0: filters predict to index 1 before the first update ([`BotStart::PredictFirst`]);
///   metrics count from index 0 (`eval_from = 0`).
/// * The course spread `pi / sqrt(12)` = 0.91 rad is far from small, so the first-order
///   velocity covariance is not the polar draw's: the exact cross-course variance is about half
///   the first-order one, the along-course variance about three times, and the exact mean speed
///   is shrunk by `exp(-var_c / 2)` = 0.66. The position part is close (the cross-range variance
///   is `(r^2 + var_r) R` exactly, 16% above first order). The tests measure these.
///
/// # Problem III (dimensionless, `T = 1`; paper section IV.C, its reference \[27\])
/// * State `[x, y]`; `x_0 ~ N([20, 5], 0.1 I)`, `x_{k+1} = diag(0.9, 1) x_k + w_k`,
///   `Q = [[0.1, 0.01], [0.01, 0.1]]` in the truth and the filter.
/// * Platform at `(cos k, sin k)`, `k` read as radians; bearings from the x axis with
///   `R = 0.025`, no translational noise.
/// * 51 indices, labels `k = 0..50`. The filter starts from the prior `[20, 5]`, `0.1 I` at
///   index 0 and updates it with `z_0` ([`BotStart::UpdateFirst`]); metrics count from index 0.
///
/// ```
/// use kalibra_studies::paper001::{BotScenario, BotStart};
/// use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
///
/// let scenario = BotScenario::problem_iii()?;
/// let run = scenario.simulate(&mut ChaCha8Rng::seed_from_u64(1))?;
/// assert_eq!(run.states.len(), 51);
/// assert_eq!(scenario.start, BotStart::UpdateFirst);
/// assert_eq!(scenario.labels().last(), Some(50));
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct BotScenario<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// Which problem.
    pub problem: BotProblem,
    /// The filter's dynamics: `F` and `Qd = G Q G^T`.
    pub dynamics: LinearGaussian<N>,
    /// The truth's dynamics: the filter's, except problem II's truth, which has no process
    /// noise.
    pub truth_dynamics: LinearGaussian<N>,
    /// The bearing sensor, for the truth and the filter alike (problem I's includes the
    /// translational noise: the truth draws it exactly, the filter sees it linearised).
    pub measurement: Bearing<N, Tabulated<2>>,
    /// Number of indices in a run (I: 41, II: 50, III: 51).
    pub steps: usize,
    /// The paper's label of index 0 (I: 0, II: 1, III: 0).
    pub first_label: usize,
    /// Whether the initial estimate is predicted or updated first.
    pub start: BotStart,
    /// The first index whose estimate the metrics use (I: 1, II: 0, III: 0).
    pub eval_from: usize,
}

/// One simulated run of a [`BotScenario`]: `states[i]` and `measurements[i]` at index `i`, and
/// the filter's initial estimate (at index 0, see [`BotStart`]).
#[derive(Clone, Debug)]
pub struct BotRun<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// True states.
    pub states: Vec<OVector<f64, N>>,
    /// Bearings (rad), wrapped to (-pi, pi].
    pub measurements: Vec<Vector1<f64>>,
    /// The filter's initial mean.
    pub init_mean: OVector<f64, N>,
    /// The filter's initial covariance.
    pub init_cov: OMatrix<f64, N, N>,
}

impl BotScenario<U2> {
    /// Problem I (metres, seconds): target on `y = 0` with state `[x, xdot]`, platform at
    /// `(4k, -20)`, translational noise; see [`BotScenario`].
    ///
    /// # Errors
    /// None in practice: the constants are valid; the signature carries the model
    /// constructors' errors.
    pub fn problem_i() -> Result<Self, ModelError> {
        let steps = 41;
        let dynamics = Kinematic::constant_velocity(1, 1.0)?
            .noise(ProcessNoise::Discrete { q: 0.01 })
            .dynamics(U2)?;
        let platform = Tabulated::new(
            (0..steps)
                .map(|k| Vector2::new(I_PLATFORM_SPEED * k as f64, I_PLATFORM_Y))
                .collect(),
        )?;
        let measurement = Bearing::from_coordinates(
            U2,
            [Coordinate::State(0), Coordinate::Constant(0.0)],
            BearingReference::XAxis,
            0.0524 * 0.0524,
            platform,
        )?
        .with_translational_noise(1.0, 1.0)?;
        Ok(Self {
            problem: BotProblem::I,
            truth_dynamics: dynamics.clone(),
            dynamics,
            measurement,
            steps,
            first_label: 0,
            start: BotStart::PredictFirst,
            eval_from: 1,
        })
    }

    /// Problem III (dimensionless): `x_{k+1} = diag(0.9, 1) x_k + w_k`, platform on the unit
    /// circle; see [`BotScenario`].
    ///
    /// # Errors
    /// None in practice, as [`BotScenario::problem_i`].
    pub fn problem_iii() -> Result<Self, ModelError> {
        let steps = 51;
        let dynamics = LinearGaussian::new(
            Matrix2::new(0.9, 0.0, 0.0, 1.0),
            Matrix2::new(0.1, 0.01, 0.01, 0.1),
        )?;
        let platform = Tabulated::new(
            (0..steps)
                .map(|k| Vector2::new((k as f64).cos(), (k as f64).sin()))
                .collect(),
        )?;
        let measurement = Bearing::new(U2, [0, 1], BearingReference::XAxis, 0.025, platform)?;
        Ok(Self {
            problem: BotProblem::III,
            truth_dynamics: dynamics.clone(),
            dynamics,
            measurement,
            steps,
            first_label: 0,
            start: BotStart::UpdateFirst,
            eval_from: 0,
        })
    }
}

impl BotScenario<U4> {
    /// Problem II (km, minutes): state `[x, y, xdot, ydot]`, the manoeuvring platform, nautical
    /// bearings; see [`BotScenario`].
    ///
    /// # Errors
    /// None in practice, as [`BotScenario::problem_i`].
    pub fn problem_ii() -> Result<Self, ModelError> {
        let steps = 50;
        let cv = Kinematic::constant_velocity(2, 1.0)?;
        let dynamics = cv.noise(ProcessNoise::Discrete { q: II_Q }).dynamics(U4)?;
        let truth_dynamics = LinearGaussian::new(*dynamics.f(), Matrix4::zeros())?;
        let measurement = Bearing::new(
            U4,
            [0, 1],
            BearingReference::North,
            2f64.to_radians().powi(2),
            Tabulated::new(problem_ii_platform(steps))?,
        )?;
        Ok(Self {
            problem: BotProblem::II,
            dynamics,
            truth_dynamics,
            measurement,
            steps,
            first_label: 1,
            start: BotStart::PredictFirst,
            eval_from: 0,
        })
    }
}

/// A velocity on a nautical course (deg) at a speed (knots), in km/min.
fn nautical_velocity(course_deg: f64, speed_kn: f64) -> Vector2<f64> {
    BearingReference::North.direction(course_deg.to_radians()) * (speed_kn * KNOT)
}

/// Problem II's platform per minute: the first course up to the turn index, the second after.
fn problem_ii_platform(steps: usize) -> Vec<Vector2<f64>> {
    let v1 = nautical_velocity(II_PLATFORM_COURSE_DEG[0], II_PLATFORM_SPEED_KN);
    let v2 = nautical_velocity(II_PLATFORM_COURSE_DEG[1], II_PLATFORM_SPEED_KN);
    let turn = II_TURN_INDEX as f64;
    (0..steps)
        .map(|i| {
            let t = i as f64;
            // Positions from the start and from the turn directly, not accumulated, so no
            // rounding builds up along the table.
            if i <= II_TURN_INDEX {
                v1 * t
            } else {
                v1 * turn + v2 * (t - turn)
            }
        })
        .collect()
}

impl<N: Dim> BotScenario<N>
where
    DefaultAllocator: Alloc<N> + Alloc<N, U1>,
{
    /// The paper's step labels of indices `0 .. steps`.
    pub fn labels(&self) -> Range<usize> {
        self.first_label..self.first_label + self.steps
    }

    /// State indices of the target position (I: `[0]`, II and III: `[0, 1]`).
    pub fn position_indices(&self) -> &'static [usize] {
        match self.problem {
            BotProblem::I => &[0],
            BotProblem::II | BotProblem::III => &[0, 1],
        }
    }

    /// State indices of the target velocity (I: `[1]`, II: `[2, 3]`); `None` for problem III,
    /// whose state has no velocity.
    pub fn velocity_indices(&self) -> Option<&'static [usize]> {
        match self.problem {
            BotProblem::I => Some(&[1]),
            BotProblem::II => Some(&[2, 3]),
            BotProblem::III => None,
        }
    }

    /// Draws one run: the true initial state (problem III draws it from its prior; I and II
    /// start at fixed states and draw nothing here), then per index the bearing noise and the
    /// process noise (see [`kalibra_models::Simulator::step`]), then the filter's initial estimate from
    /// the bearings ([`BotScenario::initialize`]). A run is fixed by the generator's state.
    ///
    /// ```
    /// use kalibra_studies::paper001::BotScenario;
    /// use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
    ///
    /// let run = BotScenario::problem_ii()?.simulate(&mut ChaCha8Rng::seed_from_u64(3))?;
    /// assert_eq!((run.states.len(), run.measurements.len()), (50, 50));
    /// assert_eq!(run.states[0][0], 7.0);
    /// # Ok::<(), kalibra_models::ModelError>(())
    /// ```
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if the state dimension does not fit `problem`,
    /// [`ModelError::NonFinite`] if the truth or the initial estimate is not finite, and the
    /// models' sampling errors.
    pub fn simulate<R: Rng + ?Sized>(&self, rng: &mut R) -> Result<BotRun<N>, ModelError> {
        let n = self.truth_dynamics.state_dim();
        let x0 = match self.problem {
            BotProblem::I => to_vector(n, &SVector::<f64, 2>::from(I_X0))?,
            BotProblem::II => {
                let v = nautical_velocity(II_TARGET_COURSE_DEG, II_TARGET_SPEED_KN);
                let [x, y] = II_TARGET_START;
                to_vector(n, &Vector4::new(x, y, v[0], v[1]))?
            }
            BotProblem::III => {
                // Explicit type: the generic allocator bounds in scope confuse inference.
                let n0: Vector2<f64> = standard_normal::<U2, R>(U2, rng);
                let draw = Vector2::from(III_MEAN) + n0 * III_VAR.sqrt();
                to_vector(n, &draw)?
            }
        };
        let truth = simulate(&self.truth_dynamics, &self.measurement, x0, self.steps, rng)?;
        let init = self.initialize(&truth.measurements)?;
        Ok(BotRun {
            states: truth.states,
            measurements: truth.measurements,
            init_mean: init.mean,
            init_cov: init.cov,
        })
    }

    /// The filter's initial mean and covariance at index 0 from a run's bearings (problems I
    /// and II read the bearing at index 0; problem III ignores them): see the
    /// [`BotScenario`] docs for each problem's formula.
    ///
    /// ```
    /// use kalibra_studies::paper001::BotScenario;
    /// use kalibra_linalg::{Gaussian, Vector1};
    ///
    /// // Problem I: a bearing of 45 degrees puts the target 20 m along x from the platform.
    /// let s = BotScenario::problem_i()?;
    /// let Gaussian { mean: x, cov: p } = s.initialize(&[Vector1::new(std::f64::consts::FRAC_PI_4)])?;
    /// assert!((x[0] - 20.0).abs() < 1e-12 && x[1] == 0.0);
    /// // 1 + 1 * cot^2 + R_theta 20^2 / sin^4 at 45 degrees.
    /// assert!((p[(0, 0)] - (2.0 + 0.0524_f64.powi(2) * 1600.0)).abs() < 1e-9);
    /// # Ok::<(), kalibra_models::ModelError>(())
    /// ```
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if problem I or II gets no bearing or the state
    /// dimension does not fit `problem`, [`ModelError::NonFinite`] if the estimate is not finite
    /// (problem I with a bearing of 0 or pi, parallel to the target's line).
    pub fn initialize(&self, measurements: &[Vector1<f64>]) -> Result<Gaussian<N>, ModelError> {
        let n = self.dynamics.state_dim();
        let first = || {
            measurements
                .first()
                .map(|z| z[0])
                .ok_or(ModelError::DimensionMismatch {
                    what: "bearings for the initialisation",
                    expected: 1,
                    found: 0,
                })
        };
        let (mean, cov) = match self.problem {
            BotProblem::I => {
                let (m, p) = self.line_initialisation(first()?);
                (to_vector(n, &m)?, to_matrix(n, &p)?)
            }
            BotProblem::II => {
                let polar = Polar {
                    range: 98f64.sqrt(),
                    var_range: II_INIT_RANGE_SD.powi(2),
                    bearing: first()?,
                    var_bearing: self.measurement.variance(),
                    speed: II_TARGET_SPEED_KN * KNOT,
                    var_speed: (II_INIT_SPEED_SD_KN * KNOT).powi(2),
                    course: first()? + PI,
                    var_course: PI * PI / 12.0,
                };
                let origin = self.measurement.shift(0);
                let (m, p) = polar.first_order(self.measurement.reference(), origin);
                (to_vector(n, &m)?, to_matrix(n, &p)?)
            }
            BotProblem::III => (
                to_vector(n, &Vector2::from(III_MEAN))?,
                to_matrix(n, &(Matrix2::identity() * III_VAR))?,
            ),
        };
        if !(kalibra_linalg::all_finite(&mean) && kalibra_linalg::all_finite(&cov)) {
            return Err(ModelError::NonFinite {
                what: "initial estimate",
                step: 0,
            });
        }
        Ok(Gaussian { mean, cov })
    }

    /// Problem I's estimate from one bearing: the point of the target's line at bearing `z`,
    /// with the first-order variance of the three noises.
    ///
    /// The line is `d_y` = constant (the y coordinate is a constant, so `d = -shift` at the
    /// zero state gives it), and `z = angle(d_x + v_x, d_y + v_y) + v_theta` inverts to
    /// `d_x = (d_y + v_y) rho(z - v_theta) - v_x` with `rho = u_x / u_y` for the unit vector
    /// `u` of the bearing (`cot` from the x axis). Its gradient at zero noise gives the
    /// variance `var_x + var_y rho^2 + R_theta d_y^2 rho'^2`, `rho' = (u'_x u_y - u_x u'_y) /
    /// u_y^2` (`-1 / sin^2` from the x axis).
    fn line_initialisation(&self, z: f64) -> (Vector2<f64>, Matrix2<f64>) {
        let m = &self.measurement;
        let reference = m.reference();
        let shift = m.shift(0);
        let dy = -shift[1];
        let u = reference.direction(z);
        let du = reference.direction(z + PI / 2.0);
        let rho = u[0] / u[1];
        let drho = (du[0] * u[1] - u[0] * du[1]) / (u[1] * u[1]);
        let (var_x, var_y) = m.translational_variance();
        let var = var_x + var_y * rho * rho + m.variance() * dy * dy * drho * drho;
        (
            Vector2::new(shift[0] + dy * rho, 0.0),
            Matrix2::new(var, 0.0, 0.0, I_INIT_VELOCITY_VAR),
        )
    }
}

/// A Gaussian polar description of a target: position `origin + range u(bearing)`, velocity
/// `speed u(course)`, all six quantities independent.
#[derive(Clone, Copy, Debug)]
struct Polar {
    range: f64,
    var_range: f64,
    bearing: f64,
    var_bearing: f64,
    speed: f64,
    var_speed: f64,
    course: f64,
    var_course: f64,
}

impl Polar {
    /// The state `[position, velocity]` at the means, with the first-order covariance: for a
    /// map `a u(b)` of independent `a`, `b` the Jacobian columns are `u` and `a u'`, so the
    /// covariance is `var_a u u^T + a^2 var_b u' u'^T`.
    fn first_order(
        &self,
        reference: BearingReference,
        origin: Vector2<f64>,
    ) -> (Vector4<f64>, Matrix4<f64>) {
        let block = |a: f64, var_a: f64, b: f64, var_b: f64| {
            let u = reference.direction(b);
            let du = reference.direction(b + PI / 2.0);
            (
                u * a,
                u * u.transpose() * var_a + du * du.transpose() * (a * a * var_b),
            )
        };
        let (pos, p_pos) = block(self.range, self.var_range, self.bearing, self.var_bearing);
        let (vel, p_vel) = block(self.speed, self.var_speed, self.course, self.var_course);
        let pos = pos + origin;
        let mut p = Matrix4::zeros();
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&p_pos);
        p.fixed_view_mut::<2, 2>(2, 2).copy_from(&p_vel);
        (Vector4::new(pos[0], pos[1], vel[0], vel[1]), p)
    }
}

/// A fixed-size vector as the scenario's state type, checking the dimension.
fn to_vector<N: Dim, const D: usize>(
    n: N,
    v: &SVector<f64, D>,
) -> Result<OVector<f64, N>, ModelError>
where
    DefaultAllocator: Alloc<N>,
{
    check_state_dim(n, D)?;
    Ok(OVector::<f64, N>::from_fn_generic(n, U1, |i, _| v[i]))
}

/// A fixed-size matrix as the scenario's covariance type, checking the dimension.
fn to_matrix<N: Dim, const D: usize>(
    n: N,
    m: &SMatrix<f64, D, D>,
) -> Result<OMatrix<f64, N, N>, ModelError>
where
    DefaultAllocator: Alloc<N>,
{
    check_state_dim(n, D)?;
    Ok(OMatrix::<f64, N, N>::from_fn_generic(n, n, |i, j| {
        m[(i, j)]
    }))
}

fn check_state_dim<N: Dim>(n: N, expected: usize) -> Result<(), ModelError> {
    if n.value() == expected {
        Ok(())
    } else {
        Err(ModelError::DimensionMismatch {
            what: "bearings-only scenario state",
            expected,
            found: n.value(),
        })
    }
}

#[cfg(test)]
mod tests;
