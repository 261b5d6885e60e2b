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
//! [`Isa`] names the instruction sets: AVX-512 (8 lanes per vector, one vector per batch),
//! AVX2 with FMA (4 lanes, two vectors), NEON (2 lanes, four vectors) and a scalar fallback (one
//! lane at a time, the plain multiply and add of the scalar filter). [`Isa::detect`] picks the
//! best the CPU has; [`Isa::from_str`](std::str::FromStr) parses an explicit choice (the xtask
//! passes the `KALIBRA_SIMD` environment variable through it: this library reads no
//! environment). The kernels are generic over [`pulp::Simd`] and dispatched through pulp, so a
//! portable build carries every path; everything the kernel calls is `#[inline(always)]` so
//! that it is compiled inside the dispatched function, for its instruction set.
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

use std::sync::Arc;

mod ekf;
mod kernel;
mod ukf;

pub use ekf::{EkfBatch, JLanes};
pub use kalibra_models::lanes::{LaneDynamics, LaneMeasurement, LaneSigmaMeasurement, PerLane};
use kernel::{BuildSchedule, Kernel, ScheduleStep, Scheduled};
pub use ukf::UkfBatch;

use kalibra_linalg::{Definiteness, SMatrix, SVector, check_covariance, check_finite};

use crate::FilterError;

/// The SIMD lane vocabulary, defined in [`kalibra_linalg::simd`]: the runs per batch, one
/// f64 per run, and the instruction set a batch runs on.
pub use kalibra_linalg::simd::{BATCH, Isa, Lanes};

/// `isa` if this CPU runs it, with the filters' error ([`FilterError::Unsupported`]).
fn checked_isa(isa: Isa) -> Result<Isa, FilterError> {
    isa.checked().map_err(|e| FilterError::at(0, e))
}

/// The shared, time-invariant linear model of a batch: `x_{k+1} = F x_k + w_k`, `w ~ N(0, Q)`,
/// `z_k = H x_k + v_k`, `v ~ N(0, R)`, stored row-major for broadcasting.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchModel<const N: usize, const M: usize> {
    f: [[f64; N]; N],
    q: [[f64; N]; N],
    h: [[f64; N]; M],
    r: [[f64; M]; M],
}

fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> [[f64; C]; R] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

impl<const N: usize, const M: usize> BatchModel<N, M> {
    /// A model from its matrices.
    ///
    /// # Errors
    /// [`FilterError::Initial`] if `F` or `H` is not finite, or `Q` or `R` is not a symmetric
    /// positive semi-definite matrix (the check the scalar models apply).
    pub fn new(
        f: SMatrix<f64, N, N>,
        q: SMatrix<f64, N, N>,
        h: SMatrix<f64, M, N>,
        r: SMatrix<f64, M, M>,
    ) -> Result<Self, FilterError> {
        let init = FilterError::Initial;
        check_finite(&f, "transition matrix F").map_err(init)?;
        check_finite(&h, "measurement matrix H").map_err(init)?;
        check_covariance(&q, "process noise Q", Definiteness::SemiDefinite).map_err(init)?;
        check_covariance(&r, "measurement noise R", Definiteness::SemiDefinite).map_err(init)?;
        Ok(Self {
            f: rows(&f),
            q: rows(&q),
            h: rows(&h),
            r: rows(&r),
        })
    }
}

/// What every batched filter offers ([`KfBatch`], [`EkfBatch`], [`UkfBatch`]): restart a
/// lane, update or predict and update all lanes, read a lane's estimate. Code that steps a
/// study's runs through any of them (a Monte Carlo loop, a bench) is written once against it;
/// each method is the filter's own method of the same name.
pub trait BatchFilter<const N: usize, const M: usize> {
    /// Restarts lane `lane` from its own estimate `(x, P)`.
    ///
    /// # Errors
    /// [`FilterError::Initial`] for a bad estimate; the lane is then unchanged.
    fn set_lane(
        &mut self,
        lane: usize,
        x: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError>;
    /// Updates every lane at the current step (NEES against `truth`).
    fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N>;
    /// Predicts every lane one step, then updates it.
    fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N>;
    /// Lane `lane`'s current mean.
    fn mean(&self, lane: usize) -> SVector<f64, N>;
    /// Lane `lane`'s current covariance.
    fn cov(&self, lane: usize) -> SMatrix<f64, N, N>;
}

/// [`BatchFilter`] for a filter type whose inherent methods of the same names it forwards to.
macro_rules! batch_filter {
    ($ty:ty, $($bounds:tt)*) => {
        impl<const N: usize, const M: usize, $($bounds)*> BatchFilter<N, M> for $ty {
            fn set_lane(
                &mut self,
                lane: usize,
                x: SVector<f64, N>,
                p: SMatrix<f64, N, N>,
            ) -> Result<(), FilterError> {
                <$ty>::set_lane(self, lane, x, p)
            }
            fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
                <$ty>::update(self, z, truth)
            }
            fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
                <$ty>::predict_update(self, z, truth)
            }
            fn mean(&self, lane: usize) -> SVector<f64, N> {
                <$ty>::mean(self, lane)
            }
            fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
                <$ty>::cov(self, lane)
            }
        }
    };
}

batch_filter!(KfBatch<N, M>,);
batch_filter!(EkfBatch<N, M, D, H>, D: LaneDynamics<N>, H: LaneMeasurement<N, M>);
batch_filter!(UkfBatch<N, M, D, H>, D: LaneDynamics<N>, H: LaneSigmaMeasurement<N, M>);

/// The results of one batched update, lane by lane.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchStep<const N: usize> {
    k: usize,
    nis: Lanes,
    nees: Lanes,
    error: [Lanes; N],
    // 0 where the lane's update succeeded, NaN where it failed (the kernel's health sum).
    health: Lanes,
    // The error of a lane's update, and of its NEES (the update's, or the NEES's own).
    failure: [Option<FilterError>; BATCH],
    nees_failure: [Option<FilterError>; BATCH],
    // Whether `failure` or `nees_failure` holds an error, as `finish` leaves them (it skips
    // both when neither does and every lane succeeded: the common step costs a pass over the
    // health sums). The UKF writes the two itself and never reads this.
    stored_failures: bool,
}

impl<const N: usize> BatchStep<N> {
    /// Completes the kernel's output for step `k`: the kernel's health sum is 0 for a lane
    /// whose update succeeded and NaN otherwise; the NEES is checked apart, as the scalar
    /// record's `nees` is a separate call. `x`, `p`: the lanes' states after the step.
    #[inline]
    fn finish<const M: usize>(
        &mut self,
        k: usize,
        z: &[Lanes; M],
        x: &[Lanes; N],
        p: &[[Lanes; N]; N],
    ) {
        self.k = k;
        if self.stored_failures || !self.ok().into_iter().all(|ok| ok) {
            self.name_failures(z, x, p);
        }
    }

    /// The errors of the failed lanes, and `None` for the others (off the hot path).
    #[cold]
    #[inline(never)]
    fn name_failures<const M: usize>(
        &mut self,
        z: &[Lanes; M],
        x: &[Lanes; N],
        p: &[[Lanes; N]; N],
    ) {
        let k = self.k;
        for lane in 0..BATCH {
            self.failure[lane] = (self.health[lane] != 0.0).then(|| self.explain(lane, z, x, p));
            self.nees_failure[lane] =
                (!self.nees[lane].is_finite()).then_some(FilterError::NotPositiveDefinite {
                    what: "posterior covariance P+",
                    step: k,
                });
        }
        self.stored_failures = self
            .failure
            .iter()
            .chain(&self.nees_failure)
            .any(Option::is_some);
    }

    /// The scalar filter's error for a failed lane (off the hot path).
    #[cold]
    #[inline(never)]
    fn explain<const M: usize>(
        &self,
        lane: usize,
        z: &[Lanes; M],
        x: &[Lanes; N],
        p: &[[Lanes; N]; N],
    ) -> FilterError {
        let k = self.k;
        if z.iter().any(|zi| !zi[lane].is_finite()) {
            return FilterError::NonFinite {
                what: "measurement",
                step: k,
            };
        }
        if (0..N).any(|i| (0..N).any(|j| !p[i][j][lane].is_finite()))
            || (0..N).any(|i| !x[i][lane].is_finite())
        {
            return FilterError::NonFinite {
                what: "predicted covariance (process noise Q?)",
                step: k,
            };
        }
        if !self.nis[lane].is_finite() {
            return FilterError::NotPositiveDefinite {
                what: "innovation covariance S",
                step: k,
            };
        }
        FilterError::NonFinite {
            what: "posterior estimate",
            step: k,
        }
    }

    fn new() -> Self {
        Self {
            k: 0,
            nis: [0.0; BATCH],
            nees: [0.0; BATCH],
            error: [[0.0; BATCH]; N],
            health: [0.0; BATCH],
            failure: std::array::from_fn(|_| None),
            nees_failure: std::array::from_fn(|_| None),
            stored_failures: false,
        }
    }

    /// The step index of the update.
    pub fn step(&self) -> usize {
        self.k
    }

    /// Lane `lane`'s update: its NIS `nu^T S^-1 nu`, or the error of the update (the lane's
    /// state is then as before it, as the scalar filter's is).
    ///
    /// # Errors
    /// The [`FilterError`] the scalar filter's update would return for this lane.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn nis(&self, lane: usize) -> Result<f64, FilterError> {
        match &self.failure[lane] {
            Some(e) => Err(e.clone()),
            None => Ok(self.nis[lane]),
        }
    }

    /// Lane `lane`'s NEES `e^T P+^-1 e` against the truth given to the update, through the
    /// Cholesky factor of `P+` as the scalar record's `nees`.
    ///
    /// # Errors
    /// The update's error ([`BatchStep::nis`]), or [`FilterError::NotPositiveDefinite`] if
    /// `P+` has no Cholesky factor.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn nees(&self, lane: usize) -> Result<f64, FilterError> {
        match (&self.failure[lane], &self.nees_failure[lane]) {
            (Some(e), _) | (None, Some(e)) => Err(e.clone()),
            (None, None) => Ok(self.nees[lane]),
        }
    }

    /// Whether every lane's update and NEES succeeded.
    pub fn all_ok(&self) -> bool {
        self.failure
            .iter()
            .chain(&self.nees_failure)
            .all(Option::is_none)
    }

    /// Lane by lane, whether the update and the NEES succeeded: `ok()[lane]` is
    /// `nees(lane).is_ok()` (and then `nis(lane)` is `Ok` too). With [`BatchStep::nis_lanes`],
    /// [`BatchStep::nees_lanes`] and [`BatchStep::errors`] a study takes a whole batch's
    /// results per step without a call per lane; [`BatchStep::nees`] gives a failed lane's
    /// error.
    #[inline]
    pub fn ok(&self) -> [bool; BATCH] {
        let mut ok = [false; BATCH];
        for ((ok, health), nees) in ok.iter_mut().zip(&self.health).zip(&self.nees) {
            // `&`, not `&&`: no branch per lane.
            *ok = (*health == 0.0) & nees.is_finite();
        }
        ok
    }

    /// Every lane's NIS, as [`BatchStep::nis`] gives it where that is `Ok`; the entry of a
    /// lane whose update failed is meaningless (see [`BatchStep::ok`]).
    pub fn nis_lanes(&self) -> &Lanes {
        &self.nis
    }

    /// Every lane's NEES, as [`BatchStep::nees`] gives it where that is `Ok`; the entry of a
    /// failed lane is meaningless (see [`BatchStep::ok`]).
    pub fn nees_lanes(&self) -> &Lanes {
        &self.nees
    }

    /// Every lane's estimation error `x - x+`, component by component: `errors()[i][lane]` is
    /// [`BatchStep::error`]`(lane)[i]` (meaningful where the update succeeded).
    pub fn errors(&self) -> &[Lanes; N] {
        &self.error
    }

    /// Lane `lane`'s estimation error `x - x+` (meaningful when [`BatchStep::nis`] is `Ok`).
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn error(&self, lane: usize) -> [f64; N] {
        std::array::from_fn(|i| self.error[i][lane])
    }
}

/// [`BATCH`] Kalman filters on one [`BatchModel`], stepped together (see the
/// [module docs](self)).
#[derive(Clone, Debug)]
pub struct KfBatch<const N: usize, const M: usize> {
    isa: Isa,
    model: BatchModel<N, M>,
    k: usize,
    x: [Lanes; N],
    // While the batch follows a schedule (`schedule` is `Some`), `p` and `gain` are not
    // written: every lane's are the schedule's after its first `at` updates
    // ([`KfBatch::leave_schedule`] writes them back).
    p: [[Lanes; N]; N],
    gain: [[Lanes; M]; N],
    out: BatchStep<N>,
    schedule: Option<Arc<KfSchedule<N, M>>>,
    at: usize,
}

impl<const N: usize, const M: usize> KfBatch<N, M> {
    /// [`BATCH`] filters at step 0, each from the estimate `(x0, P0)`, on instruction set `isa`.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if
    /// `x0` is not finite or `P0` not symmetric positive semi-definite (the scalar check).
    pub fn new(
        isa: Isa,
        model: BatchModel<N, M>,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        let isa = checked_isa(isa)?;
        let (x, p) = initial_lanes(&x0, p0)?;
        Ok(Self::at_start(isa, model, x, p, None))
    }

    /// A batch at step 0 with lanes `(x, P)`, already checked.
    fn at_start(
        isa: Isa,
        model: BatchModel<N, M>,
        x: [Lanes; N],
        p: [[Lanes; N]; N],
        schedule: Option<Arc<KfSchedule<N, M>>>,
    ) -> Self {
        Self {
            isa,
            model,
            k: 0,
            x,
            p,
            gain: [[[0.0; BATCH]; M]; N],
            out: BatchStep::new(),
            schedule,
            at: 0,
        }
    }

    /// [`BATCH`] filters at step 0 from the estimate `(x0, P0)` of `schedule` (its model, prior
    /// and instruction set), which follow the schedule's covariances instead of computing them:
    /// every number is the one [`KfBatch::new`] with the same arguments gives, to the bit, but
    /// an update computes only the lanes' means, NIS and NEES. A batch leaves the schedule, and
    /// from then on computes its lanes' covariances itself, when a lane's update fails (its
    /// covariance then differs from the others'), when [`KfBatch::set_lane`] restarts a lane,
    /// when it predicts where the schedule did not (or not where it did), or past the
    /// schedule's end.
    ///
    /// # Errors
    /// [`FilterError::Initial`] if `x0` is not finite.
    pub fn scheduled(
        schedule: Arc<KfSchedule<N, M>>,
        x0: SVector<f64, N>,
    ) -> Result<Self, FilterError> {
        check_finite(&x0, "initial mean").map_err(FilterError::Initial)?;
        let x = std::array::from_fn(|i| [x0[i]; BATCH]);
        let p = std::array::from_fn(|i| std::array::from_fn(|j| [schedule.p0[i][j]; BATCH]));
        Ok(Self::at_start(
            schedule.isa,
            schedule.model.clone(),
            x,
            p,
            Some(schedule),
        ))
    }

    /// Whether the batch still follows a schedule ([`KfBatch::scheduled`]).
    pub fn is_scheduled(&self) -> bool {
        self.schedule.is_some()
    }

    /// The schedule's update the batch made last, while it follows one (`None` before its
    /// first update: `p` and `gain` still hold `P0` and zeros then).
    fn schedule_step(&self) -> Option<&ScheduleStep<N, M>> {
        let schedule = self.schedule.as_ref()?;
        self.at.checked_sub(1).map(|k| &schedule.steps[k])
    }

    /// Stops following the schedule: every lane's covariance and gain become the schedule's
    /// after the updates made, but those of the lanes in `failed`, whose last update failed
    /// and which keep the prior.
    fn leave_schedule(&mut self, failed: [bool; BATCH]) {
        if let Some(step) = self.schedule_step() {
            let (prior, posterior, gain) = (step.prior, step.posterior, step.gain);
            for (lane, failed) in failed.into_iter().enumerate() {
                let p = if failed { &prior } else { &posterior };
                for (row, p_row) in self.p.iter_mut().zip(p) {
                    for (entry, value) in row.iter_mut().zip(p_row) {
                        entry[lane] = *value;
                    }
                }
                for (row, k_row) in self.gain.iter_mut().zip(&gain) {
                    for (entry, value) in row.iter_mut().zip(k_row) {
                        entry[lane] = *value;
                    }
                }
            }
        }
        self.schedule = None;
    }

    /// Restarts lane `lane` from its own estimate `(x, P)` (for instance runs with their own
    /// priors), checked as [`KfBatch::new`] checks the shared one.
    ///
    /// # Errors
    /// [`FilterError::Initial`] as [`KfBatch::new`]; the lane is then unchanged.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn set_lane(
        &mut self,
        lane: usize,
        x: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        check_finite(&x, "initial mean").map_err(FilterError::Initial)?;
        // Checked before the batch leaves its schedule, so that a refused estimate changes
        // nothing.
        let p = initial_cov(p)?;
        self.leave_schedule([false; BATCH]);
        write_lane(&mut self.x, &mut self.p, lane, &x, &p);
        Ok(())
    }

    /// The instruction set the batch runs on.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// The current step index.
    pub fn step_index(&self) -> usize {
        self.k
    }

    /// Lane `lane`'s current mean.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn mean(&self, lane: usize) -> SVector<f64, N> {
        SVector::from_fn(|i, _| self.x[i][lane])
    }

    /// Lane `lane`'s current covariance.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
        assert!(lane < BATCH, "lane {lane} of a batch of {BATCH}");
        match self.schedule_step() {
            Some(step) => SMatrix::from_fn(|i, j| step.posterior[i][j]),
            None => SMatrix::from_fn(|i, j| self.p[i][j][lane]),
        }
    }

    /// Updates every lane at the current step with its measurement `z[i][lane]` and computes
    /// its NIS, and its NEES against the true state `truth[i][lane]` (pass zeros where there
    /// is no truth and ignore the NEES).
    pub fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.run::<false>(z, truth)
    }

    /// Predicts every lane from step `k` to `k + 1`, then updates it as [`KfBatch::update`]
    /// does: one pass over the batch. A lane whose update fails keeps its prediction (the
    /// scalar filter's state after a prediction and a failed update).
    pub fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.k += 1;
        self.run::<true>(z, truth)
    }

    fn run<const PREDICT: bool>(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        let isa = self.isa;
        // (Borrowed, not cloned: an `Arc` clone per step is two atomic operations.)
        if let Some(schedule) = &self.schedule {
            match schedule.steps.get(self.at) {
                Some(step) if step.predicted == PREDICT => {
                    let all_kept = isa.dispatch(Scheduled::<N, M, PREDICT> {
                        f: &self.model.f,
                        h: &self.model.h,
                        step,
                        x: &mut self.x,
                        z,
                        truth,
                        out: &mut self.out,
                    });
                    self.at += 1;
                    if !all_kept {
                        // A failed lane keeps its prior: the lanes' covariances differ now.
                        // (`finish` reads `p` only for failed lanes, so it is written first.)
                        self.leave_schedule(self.out.health.map(|h| h != 0.0));
                    }
                    self.out.finish(self.k, z, &self.x, &self.p);
                    return &self.out;
                }
                _ => self.leave_schedule([false; BATCH]),
            }
        }
        isa.dispatch(Kernel::<N, M, PREDICT, _, _, _, _> {
            f: &self.model.f,
            q: &self.model.q,
            h: &self.model.h,
            r: &self.model.r,
            innovation: None,
            x: &mut self.x,
            p: &mut self.p,
            z,
            truth,
            gain: &mut self.gain,
            out: &mut self.out,
            terms: None,
        });
        self.out.finish(self.k, z, &self.x, &self.p);
        &self.out
    }

    /// Lane `lane`'s gain `K` of the last update (meaningful when its [`BatchStep::nis`] is
    /// `Ok`).
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn gain(&self, lane: usize) -> SMatrix<f64, N, M> {
        assert!(lane < BATCH, "lane {lane} of a batch of {BATCH}");
        match self.schedule_step() {
            Some(step) => SMatrix::from_fn(|i, j| step.gain[i][j]),
            None => SMatrix::from_fn(|i, j| self.gain[i][j][lane]),
        }
    }
}

/// The covariances of a Kalman filter on one [`BatchModel`] from one prior `P0`: an update at
/// step 0, then a prediction and an update at each later step, computed once for every batch
/// that follows it ([`KfBatch::scheduled`]).
///
/// A linear filter's `P-`, `S`, `K` and `P+` depend on the model and `P0` alone, never on the
/// measurements, so a Monte Carlo study whose runs share both computes the same covariance
/// sequence in every run. A schedule holds it (computed by the batched kernel's own code on
/// one vector of the instruction set), and a batch that follows it computes only what differs
/// between runs: the means, the innovations, the NIS and the NEES. Every number is the one the
/// batch computes without a schedule, to the bit (on the same instruction set); a batch leaves
/// the schedule where its lanes' covariances would part (see [`KfBatch::scheduled`]).
///
/// Memory: per update, `3 N^2 + N M + M^2 + N + M` numbers (66 for `N = 4`, `M = 2`: 528
/// bytes).
///
/// ```
/// use std::sync::Arc;
/// use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch, KfSchedule};
/// use kalibra_linalg::{Matrix1, Matrix2, Vector2};
/// use nalgebra::SMatrix;
///
/// let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
/// let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
/// let model = BatchModel::new(f, Matrix2::identity() * 0.01, h, Matrix1::new(1.0))?;
/// let p0 = Matrix2::identity();
/// let schedule = Arc::new(KfSchedule::new(Isa::detect(), model.clone(), p0, 10)?);
/// let mut fast = KfBatch::scheduled(schedule, Vector2::zeros())?;
/// let mut full = KfBatch::new(Isa::detect(), model, Vector2::zeros(), p0)?;
/// let (z, truth) = ([[0.5; BATCH]; 1], [[0.0; BATCH]; 2]);
/// assert_eq!(fast.update(&z, &truth), full.update(&z, &truth));
/// assert_eq!(fast.predict_update(&z, &truth), full.predict_update(&z, &truth));
/// assert_eq!(fast.cov(0), full.cov(0));
/// assert!(fast.is_scheduled());
/// # Ok::<(), kalibra_filters::FilterError>(())
/// ```
#[derive(Clone, PartialEq)]
pub struct KfSchedule<const N: usize, const M: usize> {
    isa: Isa,
    model: BatchModel<N, M>,
    p0: [[f64; N]; N],
    steps: Vec<ScheduleStep<N, M>>,
}

impl<const N: usize, const M: usize> std::fmt::Debug for KfSchedule<N, M> {
    /// The instruction set, model, prior and length; not every step's matrices.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KfSchedule")
            .field("isa", &self.isa)
            .field("model", &self.model)
            .field("p0", &self.p0)
            .field("updates", &self.steps.len())
            .finish()
    }
}

impl<const N: usize, const M: usize> KfSchedule<N, M> {
    /// The covariances of `updates` updates (the first at step 0, each later one after a
    /// prediction) from `P0` on `model`, computed on instruction set `isa`. It holds fewer if a
    /// step's prior, gain, factor of `S` or posterior is not finite: a batch computes that step
    /// and the later ones itself, and fails where [`KfBatch::new`]'s batch fails.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if
    /// `P0` is not symmetric positive semi-definite (the scalar check);
    /// [`FilterError::InvalidParameter`] if the memory for `updates` steps cannot be had.
    pub fn new(
        isa: Isa,
        model: BatchModel<N, M>,
        p0: SMatrix<f64, N, N>,
        updates: usize,
    ) -> Result<Self, FilterError> {
        let isa = checked_isa(isa)?;
        let p0 = rows(&initial_cov(p0)?);
        let mut steps = Vec::new();
        steps
            .try_reserve_exact(updates)
            .map_err(|_| FilterError::InvalidParameter {
                name: "updates",
                value: updates as f64,
            })?;
        isa.dispatch(BuildSchedule {
            f: &model.f,
            q: &model.q,
            h: &model.h,
            r: &model.r,
            p0: &p0,
            updates,
            out: &mut steps,
        });
        Ok(Self {
            isa,
            model,
            p0,
            steps,
        })
    }

    /// The number of updates the schedule holds.
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// The instruction set it was computed on (and its batches run on).
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// `P+` after update `k` (`None` past the schedule).
    pub fn posterior(&self, k: usize) -> Option<SMatrix<f64, N, N>> {
        let step = self.steps.get(k)?;
        Some(SMatrix::from_fn(|i, j| step.posterior[i][j]))
    }
}

/// An initial covariance checked as the scalar filters check one, and symmetrised as they keep
/// it.
fn initial_cov<const N: usize>(p: SMatrix<f64, N, N>) -> Result<SMatrix<f64, N, N>, FilterError> {
    Ok(kalibra_linalg::PsdMatrix::named(p, "initial covariance")
        .map_err(FilterError::Initial)?
        .matrix()
        .clone_owned())
}

/// The lanes of a batch that all start from `(x0, P0)`, checked as the scalar filters check an
/// initial estimate (and `P0` symmetrised as they keep it).
fn initial_lanes<const N: usize>(
    x0: &SVector<f64, N>,
    p0: SMatrix<f64, N, N>,
) -> Result<([Lanes; N], [[Lanes; N]; N]), FilterError> {
    check_finite(x0, "initial mean").map_err(FilterError::Initial)?;
    let p0 = initial_cov(p0)?;
    Ok((
        std::array::from_fn(|i| [x0[i]; BATCH]),
        std::array::from_fn(|i| std::array::from_fn(|j| [p0[(i, j)]; BATCH])),
    ))
}

/// Sets lane `lane` to the estimate `(x, P)` (`x` already checked), after the initial check
/// of `P`; the lane is unchanged if it fails.
fn set_lane_estimate<const N: usize>(
    xs: &mut [Lanes; N],
    ps: &mut [[Lanes; N]; N],
    lane: usize,
    x: &SVector<f64, N>,
    p: SMatrix<f64, N, N>,
) -> Result<(), FilterError> {
    write_lane(xs, ps, lane, x, &initial_cov(p)?);
    Ok(())
}

/// Writes the estimate `(x, P)`, both already checked, into lane `lane`.
fn write_lane<const N: usize>(
    xs: &mut [Lanes; N],
    ps: &mut [[Lanes; N]; N],
    lane: usize,
    x: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
) {
    for i in 0..N {
        xs[i][lane] = x[i];
        for j in 0..N {
            ps[i][j][lane] = p[(i, j)];
        }
    }
}
