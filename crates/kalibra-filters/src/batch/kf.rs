//! [`KfBatch`]: the batched linear Kalman filter, with or without a [`KfSchedule`].

use std::sync::Arc;

use kalibra_linalg::{SMatrix, SVector, check_finite};

use super::kernel::{Kernel, ScheduleStep, Scheduled};
use super::lanes::{LaneState, checked_estimate, lane_accessors};
use super::{BATCH, BatchModel, BatchStep, Isa, KfSchedule, Lanes};
use crate::FilterError;

/// [`BATCH`] Kalman filters on one [`BatchModel`], stepped together (see the
/// [module docs](crate::batch)).
#[derive(Clone, Debug)]
pub struct KfBatch<const N: usize, const M: usize> {
    model: BatchModel<N, M>,
    // While the batch follows a schedule (`schedule` is `Some`), the lanes' `p` and `gain` are
    // not written: every lane's are the schedule's after its first `at` updates
    // ([`KfBatch::leave_schedule`] writes them back).
    lanes: LaneState<N, M>,
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
        let lanes = LaneState::new(isa, &x0, p0)?;
        Ok(Self::at_start(model, lanes, None))
    }

    /// A batch at step 0 with lanes already checked.
    fn at_start(
        model: BatchModel<N, M>,
        lanes: LaneState<N, M>,
        schedule: Option<Arc<KfSchedule<N, M>>>,
    ) -> Self {
        Self {
            model,
            lanes,
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
            schedule.model.clone(),
            LaneState::at_start(schedule.isa, x, p),
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
                for (row, p_row) in self.lanes.p.iter_mut().zip(p) {
                    for (entry, value) in row.iter_mut().zip(p_row) {
                        entry[lane] = *value;
                    }
                }
                for (row, k_row) in self.lanes.gain.iter_mut().zip(&gain) {
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
        // Checked before the batch leaves its schedule, so that a refused estimate changes
        // nothing.
        let p = checked_estimate(&x, p)?;
        self.leave_schedule([false; BATCH]);
        self.lanes.write_lane(lane, &x, &p);
        Ok(())
    }

    lane_accessors!(lanes);

    /// Lane `lane`'s current covariance.
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
        assert!(lane < BATCH, "lane {lane} of a batch of {BATCH}");
        match self.schedule_step() {
            Some(step) => SMatrix::from_fn(|i, j| step.posterior[i][j]),
            None => self.lanes.cov(lane),
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
        self.lanes.k += 1;
        self.run::<true>(z, truth)
    }

    fn run<const PREDICT: bool>(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        let isa = self.lanes.isa;
        // (Borrowed, not cloned: an `Arc` clone per step is two atomic operations.)
        if let Some(schedule) = &self.schedule {
            match schedule.steps.get(self.at) {
                Some(step) if step.predicted == PREDICT => {
                    let all_kept = isa.dispatch(Scheduled::<N, M, PREDICT> {
                        f: &self.model.f,
                        h: &self.model.h,
                        step,
                        x: &mut self.lanes.x,
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
                    self.out
                        .finish(self.lanes.k, z, &self.lanes.x, &self.lanes.p);
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
            x: &mut self.lanes.x,
            p: &mut self.lanes.p,
            z,
            truth,
            gain: &mut self.lanes.gain,
            out: &mut self.out,
            terms: None,
        });
        self.out
            .finish(self.lanes.k, z, &self.lanes.x, &self.lanes.p);
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
            None => self.lanes.gain(lane),
        }
    }
}
