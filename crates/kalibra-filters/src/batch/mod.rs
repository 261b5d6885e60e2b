//! Batched Kalman filtering: [`BATCH`] Monte Carlo runs of one linear model stepped together,
//! in structure-of-arrays layout, with the SIMD instruction set chosen at run time.
//!
//! # What it is for
//! A Monte Carlo study runs thousands of independent filters on the same model. [`KfBatch`]
//! steps [`BATCH`] = 8 of them at once: every entry of every per-run quantity (state, covariance,
//! measurement, truth) is an array of 8 lanes, one per run, and the shared model matrices
//! `F, H, Q, R` are broadcast across the lanes. The arithmetic is the scalar [`Kf`](crate::Kf)'s
//! (predict `F P F^T + Q`, symmetrised; `S = H P H^T + R`, symmetrised and factorised by
//! Cholesky; `K` by a solve with that factor; Joseph update, symmetrised; NIS and NEES through
//! Cholesky factors), written out over fixed sizes `N`, `M` in the same order of operations,
//! so a lane agrees with the scalar filter of its run to rounding (fused multiply-adds where
//! the instruction set has them are the one difference).
//!
//! [`EkfBatch`] is the extended Kalman filter on the same kernel: the model is evaluated lane
//! by lane (`f(x)`, `F`, `Q`, the innovation `z (-) h(x)`, `H`, `R`) through
//! [`LaneDynamics`] and [`LaneMeasurement`], which [`PerLane`] implements for any scalar
//! model by calling it once per lane and which a model may implement itself to evaluate its
//! lanes together; the per-lane Jacobians are then loaded into the kernel in place of the
//! broadcast matrices, and the covariance algebra is the KF's, vector by vector.
//!
//! A linear KF's covariances (`P-`, `S`, `K`, `P+`) depend on the model and the prior alone, so
//! a study whose runs share both computes them once, as a [`KfSchedule`], and its batches
//! follow it ([`KfBatch::scheduled`]): each step then computes only the lanes' means, NIS and
//! NEES, with the same numbers to the bit.
//!
//! It is not a general filter API: the scalar filters are the reference and the interface for
//! one filter; this is how studies step many.
//!
//! # Dispatch
//! [`Isa`] (defined in [`kalibra_linalg::simd`], re-exported here) names the instruction sets:
//! AVX-512 (8 lanes per vector, one vector per batch), AVX2 with FMA (4 lanes, two vectors),
//! NEON (2 lanes, four vectors) and a scalar fallback (one lane at a time, the plain multiply
//! and add of the scalar filter). [`Isa::detect`] picks the best the CPU has;
//! [`Isa::from_str`](std::str::FromStr) parses an explicit choice (the xtask passes the
//! `KALIBRA_SIMD` environment variable through it: this library reads no environment). The
//! kernels are generic over [`pulp::Simd`] and dispatched through [`Isa::dispatch`], so a
//! portable build carries every path; everything the kernel calls is `#[inline(always)]` so
//! that it is compiled inside the dispatched function, for its instruction set.
//!
//! # Where each job lives
//! * `batch/model.rs`: [`BatchModel`], the broadcast linear model.
//! * `batch/filter.rs`: [`BatchFilter`], the interface the three batched filters share.
//! * `batch/step.rs`: [`BatchStep`], one update's results and per-lane errors.
//! * `batch/lanes.rs`: the lane state the three filters hold (means, covariances, gains, step
//!   index, instruction set) and the initial checks of a lane's estimate.
//! * `batch/kernel.rs`: the KF/EKF step as a pulp operation (the covariance algebra, the
//!   schedule's builder and its mean-only step); the lane-wise Cholesky factor it solves with
//!   is [`kalibra_linalg::simd::LaneCholesky`].
//! * `batch/kf.rs`: [`KfBatch`]; `batch/schedule.rs`: [`KfSchedule`]; `batch/ekf.rs`:
//!   [`EkfBatch`] and its J1/J2 terms ([`JLanes`]); `batch/ukf.rs`: [`UkfBatch`].
//!
//! # Per-lane errors
//! A lane whose measurement is not finite, whose `S` is not positive definite, or whose
//! posterior is not finite fails alone: its state is left as it was (as the scalar filter's
//! is after a failed update), its [`BatchStep::nis`] is the [`FilterError`] the scalar
//! filter would return, and the other lanes go on.
//!
//! # Example
//! ```
//! use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch};
//! use kalibra_linalg::{Matrix1, Matrix2, Vector2};
//! use nalgebra::SMatrix;
//!
//! let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
//! let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
//! let model = BatchModel::new(f, Matrix2::identity() * 0.01, h, Matrix1::new(1.0))?;
//! let mut kf = KfBatch::new(Isa::detect(), model, Vector2::zeros(), Matrix2::identity())?;
//! // Eight runs, eight measurements; lane 3's is NaN and fails alone.
//! let mut z = [[0.5; BATCH]; 1];
//! z[0][3] = f64::NAN;
//! let truth = [[0.0; BATCH]; 2];
//! let step = kf.update(&z, &truth);
//! assert!(step.nis(3).is_err());
//! assert!(step.nis(0).is_ok_and(|nis| nis > 0.0));
//! # Ok::<(), kalibra_filters::FilterError>(())
//! ```

mod ekf;
mod filter;
mod kernel;
mod kf;
mod lanes;
mod model;
mod schedule;
mod step;
mod ukf;

pub use ekf::{EkfBatch, JLanes};
pub use filter::BatchFilter;
pub use kalibra_models::lanes::{LaneDynamics, LaneMeasurement, LaneSigmaMeasurement, PerLane};
pub use kf::KfBatch;
pub use model::BatchModel;
pub use schedule::KfSchedule;
pub use step::BatchStep;
pub use ukf::UkfBatch;

use crate::FilterError;

/// The SIMD lane vocabulary, defined in [`kalibra_linalg::simd`]: the runs per batch, one
/// f64 per run, and the instruction set a batch runs on.
pub use kalibra_linalg::simd::{BATCH, Isa, Lanes};

/// `isa` if this CPU runs it, with the filters' error ([`FilterError::Unsupported`]).
fn checked_isa(isa: Isa) -> Result<Isa, FilterError> {
    isa.checked().map_err(|e| FilterError::at(0, e))
}
