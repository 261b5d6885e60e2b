//! Dynamics and measurement models for kalibra.
//!
//! # What this crate is for
//! * The traits a filter and a truth simulation ask of a model: [`Dynamics`] (`f_k`, its
//!   Jacobian `F_k`, `Q_k`, noise sampling), [`Measurement`] (`h_k`, `H_k`, `R_k`, a residual
//!   that wraps angles, noise sampling), and their linear refinements [`LinearDynamics`] and
//!   [`LinearMeasurement`] that the Kalman filter needs.
//! * Concrete models: [`Kinematic`] constant-velocity and constant-acceleration models in any
//!   number of axes, [`LinearGaussian`] and [`LinearObservation`] for any `F, Q, H, R`,
//!   [`WithInput`] for a known control input, [`Bearing`] from a moving [`Platform`], the
//!   ballistic re-entry models (drag with an exponential air density, drag-free, radar
//!   measurements and positions converted from them), the constant-acceleration angular target
//!   ([`AngularTarget`], with a manoeuvring truth [`ManoeuvringTarget`] driven by a
//!   [`ManoeuvreProfile`]), and a 3-D target with nonlinear acceleration ([`Target3d`], per
//!   axis [`AccelAxis`], parameters [`Target3dParams`]).
//! * A [`Bearing`] whose target coordinates may be constants ([`Coordinate`], a target on a
//!   known line) and which models translational noise.
//! * Seeded truth simulation ([`Simulator`], [`simulate`], [`simulate_until`]), where the truth
//!   may use models and noise the filter does not.
//! * [`check_dynamics_jacobian`] and [`check_measurement_jacobian`]: finite-difference checks
//!   any model's tests can call.
//!
//! It holds no filters and no metrics.
//!
//! # Where each job lives
//! * `traits.rs`: the model traits; `jacobian.rs`: the finite-difference checks; `noise.rs`:
//!   noise draws through a factor; `simulate.rs`: truth simulation; `error.rs`:
//!   [`ModelError`].
//! * `kinematic.rs`, `linear.rs`, `bearing.rs`, `ballistic.rs`, `angle.rs`, `target3d.rs`: the
//!   concrete models, each with its lane-wise implementation where it has one.
//! * `lanes/`: the lane-wise model traits ([`lanes::LaneDynamics`],
//!   [`lanes::LaneMeasurement`], [`lanes::LaneSigmaMeasurement`], [`lanes::PerLane`]) and
//!   `lanes/math.rs` ([`lanes::math::wrap_angle_lanes`]); the lane layout and the lane-wise
//!   `atan2`, `sin`/`cos` and `exp` are kalibra-linalg's [`simd`](kalibra_linalg::simd),
//!   re-exported there.
//!
//! # Notation
//! `x_{k+1} = f_k(x_k) + w_k`, `w_k ~ N(0, Q_k)`; `z_k = h_k(x_k) + v_k`, `v_k ~ N(0, R_k)`.
//! `k` is a step index; models that need time hold their own sampling period or time table.
//! Dimensions are nalgebra [`Dim`](kalibra_linalg::Dim)s: `Const` for speed, `Dyn` for sizes
//! known at run time.
//!
//! # Numerical choices
//! * Noise is drawn as `L n` with `L` a semi-definite factor, so rank-deficient covariances (a
//!   white-noise-acceleration `Q`) are sampled exactly; constant-noise models factor once.
//! * Angles live in (-pi, pi]; [`wrap_angle`] is the one wrapping function.
//! * Jacobian checks use central differences with relative step [`FD_RELATIVE_STEP`].
//!
//! # Example
//! ```
//! use kalibra_models::{check_dynamics_jacobian, Dynamics, Kinematic};
//! use kalibra_linalg::{U6, Vector6};
//!
//! let ca = Kinematic::constant_acceleration(2, 0.1)?.dynamics(U6)?;
//! let x = Vector6::new(1.0, 2.0, 0.5, -0.5, 0.1, 0.0);
//! assert!(check_dynamics_jacobian(&ca, 0, &x).scaled_error < 1e-8);
//! # Ok::<(), kalibra_models::ModelError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod angle;
mod ballistic;
mod bearing;
mod error;
mod jacobian;
mod kinematic;
pub mod lanes;
mod linear;
mod noise;
mod simulate;
mod target3d;
mod traits;

pub use angle::{
    AngularTarget, Manoeuvre, ManoeuvreProfile, ManoeuvringTarget, ManoeuvringTargetParams,
};
pub use ballistic::{
    AirDensity, Ballistic, BallisticDragFree, BallisticParams, ConvertedPosition,
    ConvertedPositionParams, RadarRates, ballistic_f1, ballistic_g,
};
pub use bearing::{
    Bearing, BearingReference, Coordinate, Moving, Platform, Stationary, Tabulated, wrap_angle,
};
pub use error::ModelError;
pub use jacobian::{
    FD_RELATIVE_STEP, JacobianCheck, check_dynamics_jacobian, check_measurement_jacobian,
};
pub use kinematic::{Kinematic, Layout, Order, ProcessNoise};
pub use linear::{LinearGaussian, LinearObservation, WithInput};
pub use noise::{sample_with_factor, standard_normal};
pub use simulate::{Simulator, Truth, TruthStep, simulate, simulate_until};
pub use target3d::{AccelAxis, Target3d, Target3dParams};
pub use traits::{Dynamics, LinearDynamics, LinearMeasurement, Measurement};
