//! [`KfSchedule`]: the covariances of a linear batch computed once for every batch that
//! follows it.

use kalibra_linalg::SMatrix;

use super::kernel::{BuildSchedule, ScheduleStep};
use super::lanes::initial_cov;
use super::model::rows;
use super::{BatchModel, Isa, checked_isa};
use crate::FilterError;

/// The covariances of a Kalman filter on one [`BatchModel`] from one prior `P0`: an update at
/// step 0, then a prediction and an update at each later step, computed once for every batch
/// that follows it ([`KfBatch::scheduled`](crate::batch::KfBatch::scheduled)).
///
/// A linear filter's `P-`, `S`, `K` and `P+` depend on the model and `P0` alone, never on the
/// measurements, so a Monte Carlo study whose runs share both computes the same covariance
/// sequence in every run. A schedule holds it (computed by the batched kernel's own code on
/// one vector of the instruction set), and a batch that follows it computes only what differs
/// between runs: the means, the innovations, the NIS and the NEES. Every number is the one the
/// batch computes without a schedule, to the bit (on the same instruction set); a batch leaves
/// the schedule where its lanes' covariances would part (see [`KfBatch::scheduled`](crate::batch::KfBatch::scheduled)).
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
    pub(super) isa: Isa,
    pub(super) model: BatchModel<N, M>,
    pub(super) p0: [[f64; N]; N],
    pub(super) steps: Vec<ScheduleStep<N, M>>,
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
    /// and the later ones itself, and fails where [`KfBatch::new`](crate::batch::KfBatch::new)'s batch fails.
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
