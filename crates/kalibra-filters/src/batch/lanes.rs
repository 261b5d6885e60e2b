//! The lane state the three batched filters hold ([`LaneState`]: instruction set, step index,
//! means, covariances, gains) and its accessors, with the initial checks of a lane's estimate
//! as the scalar filters check an initial estimate.

use kalibra_linalg::{SMatrix, SVector, check_finite};

use super::{BATCH, Isa, Lanes, checked_isa};
use crate::FilterError;

/// What [`KfBatch`](super::KfBatch), [`EkfBatch`](super::EkfBatch) and
/// [`UkfBatch`](super::UkfBatch) each keep of their lanes: the instruction set, the step
/// index, and every lane's mean, covariance and gain, entry by entry (`x[i][lane]`).
#[derive(Clone, Debug)]
pub(super) struct LaneState<const N: usize, const M: usize> {
    pub isa: Isa,
    pub k: usize,
    pub x: [Lanes; N],
    pub p: [[Lanes; N]; N],
    pub gain: [[Lanes; M]; N],
}

impl<const N: usize, const M: usize> LaneState<N, M> {
    /// [`BATCH`] lanes at step 0, each from the estimate `(x0, P0)`, on instruction set `isa`.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if
    /// `x0` is not finite or `P0` not symmetric positive semi-definite (the scalar check).
    pub fn new(
        isa: Isa,
        x0: &SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        let isa = checked_isa(isa)?;
        let p0 = checked_estimate(x0, p0)?;
        Ok(Self::at_start(
            isa,
            std::array::from_fn(|i| [x0[i]; BATCH]),
            std::array::from_fn(|i| std::array::from_fn(|j| [p0[(i, j)]; BATCH])),
        ))
    }

    /// Lanes at step 0 with means `x` and covariances `p`, already checked, and zero gains.
    pub fn at_start(isa: Isa, x: [Lanes; N], p: [[Lanes; N]; N]) -> Self {
        Self {
            isa,
            k: 0,
            x,
            p,
            gain: [[[0.0; BATCH]; M]; N],
        }
    }

    /// Restarts lane `lane` from its own estimate `(x, P)`, checked as [`LaneState::new`]
    /// checks the shared one; the lane is unchanged if the check fails.
    pub fn set_lane(
        &mut self,
        lane: usize,
        x: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let p = checked_estimate(&x, p)?;
        self.write_lane(lane, &x, &p);
        Ok(())
    }

    /// Writes the estimate `(x, P)`, both already checked, into lane `lane`.
    pub fn write_lane(&mut self, lane: usize, x: &SVector<f64, N>, p: &SMatrix<f64, N, N>) {
        for i in 0..N {
            self.x[i][lane] = x[i];
            for j in 0..N {
                self.p[i][j][lane] = p[(i, j)];
            }
        }
    }

    /// Lane `lane`'s mean.
    pub fn mean(&self, lane: usize) -> SVector<f64, N> {
        SVector::from_fn(|i, _| self.x[i][lane])
    }

    /// Lane `lane`'s covariance.
    pub fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
        SMatrix::from_fn(|i, j| self.p[i][j][lane])
    }

    /// Lane `lane`'s gain.
    pub fn gain(&self, lane: usize) -> SMatrix<f64, N, M> {
        SMatrix::from_fn(|i, j| self.gain[i][j][lane])
    }
}

/// An initial estimate `(x, P)` checked as the scalar filters check one: `x` finite, `P`
/// symmetric positive semi-definite; `P` comes back symmetrised as they keep it.
pub(super) fn checked_estimate<const N: usize>(
    x: &SVector<f64, N>,
    p: SMatrix<f64, N, N>,
) -> Result<SMatrix<f64, N, N>, FilterError> {
    check_finite(x, "initial mean").map_err(FilterError::Initial)?;
    initial_cov(p)
}

/// An initial covariance checked as the scalar filters check one, and symmetrised as they keep
/// it.
pub(super) fn initial_cov<const N: usize>(
    p: SMatrix<f64, N, N>,
) -> Result<SMatrix<f64, N, N>, FilterError> {
    Ok(kalibra_linalg::PsdMatrix::named(p, "initial covariance")
        .map_err(FilterError::Initial)?
        .matrix()
        .clone_owned())
}

/// The accessors every batched filter forwards to its [`LaneState`] at `self.<path>`: the
/// instruction set, the step index and the lanes' means.
macro_rules! lane_accessors {
    ($($path:ident).+) => {
        /// The instruction set the batch runs on.
        pub fn isa(&self) -> Isa {
            self.$($path).+.isa
        }

        /// The current step index.
        pub fn step_index(&self) -> usize {
            self.$($path).+.k
        }

        /// Lane `lane`'s current mean.
        ///
        /// # Panics
        /// If `lane >= BATCH`.
        pub fn mean(&self, lane: usize) -> SVector<f64, N> {
            self.$($path).+.mean(lane)
        }

        /// Every lane's current mean, entry by entry (`means()[i][lane]`).
        pub fn means(&self) -> &[Lanes; N] {
            &self.$($path).+.x
        }
    };
}

/// The restart and the covariance accessor of a batched filter whose covariances are its
/// [`LaneState`]'s at `self.<path>` (the EKF's and the UKF's; the KF's may follow a schedule).
macro_rules! lane_estimates {
    ($($path:ident).+) => {
        /// Restarts lane `lane` from its own estimate `(x, P)` (for instance runs with their
        /// own priors), checked as the constructor checks the shared one.
        ///
        /// # Errors
        /// [`FilterError::Initial`] as the constructor; the lane is then unchanged.
        ///
        /// # Panics
        /// If `lane >= BATCH`.
        pub fn set_lane(
            &mut self,
            lane: usize,
            x: SVector<f64, N>,
            p: SMatrix<f64, N, N>,
        ) -> Result<(), FilterError> {
            self.$($path).+.set_lane(lane, x, p)
        }

        /// Lane `lane`'s current covariance.
        ///
        /// # Panics
        /// If `lane >= BATCH`.
        pub fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
            self.$($path).+.cov(lane)
        }
    };
}

pub(super) use {lane_accessors, lane_estimates};
