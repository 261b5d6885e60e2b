//! The batched extended Kalman filter: [`BATCH`] runs of one nonlinear model, the model
//! evaluated lane by lane and the covariance algebra stepped together.

use kalibra_linalg::{SMatrix, SVector};
use kalibra_models::lanes::{LaneDynamics, LaneMeasurement};
use pulp::{Simd, WithSimd};

use super::kernel::Kernel;
use super::lanes::{LaneState, lane_accessors, lane_estimates};
use super::{BATCH, BatchStep, Isa, Lanes};
use crate::FilterError;

/// One step of the batch as a single pulp operation: the model's prediction (`f(x)`, `F`, `Q`;
/// with `PREDICT`), its innovation, `H` and `R`, then the kernel's covariance algebra, all
/// compiled inside one dispatched function for the batch's instruction set, which runs fewer
/// instructions than one dispatch for each of the three (`cargo xtask bench w2`).
struct Step<'a, const N: usize, const M: usize, const PREDICT: bool, D, H> {
    dynamics: &'a D,
    measurement: &'a H,
    /// The step the prediction leaves (`k`); the update is at `k + 1` with `PREDICT`, at `k`
    /// without.
    k: usize,
    x: &'a mut [Lanes; N],
    p: &'a mut [[Lanes; N]; N],
    gain: &'a mut [[Lanes; M]; N],
    f: &'a mut [[Lanes; N]; N],
    q: &'a mut [[Lanes; N]; N],
    h: &'a mut [[Lanes; N]; M],
    r: &'a mut [[Lanes; M]; M],
    nu: &'a mut [Lanes; M],
    z: &'a [Lanes; M],
    truth: &'a [Lanes; N],
    out: &'a mut BatchStep<N>,
    terms: Option<&'a mut JLanes<M>>,
}

impl<const N: usize, const M: usize, const PREDICT: bool, D, H> WithSimd
    for Step<'_, N, M, PREDICT, D, H>
where
    D: LaneDynamics<N>,
    H: LaneMeasurement<N, M>,
{
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let k = if PREDICT {
            self.dynamics
                .predict_lanes(simd, self.k, self.x, self.f, self.q);
            self.k + 1
        } else {
            self.k
        };
        self.measurement
            .innovate_lanes(simd, k, self.x, self.z, self.nu, self.h, self.r);
        Kernel::<N, M, PREDICT, _, _, _, _> {
            f: &*self.f,
            q: &*self.q,
            h: &*self.h,
            r: &*self.r,
            innovation: Some(&*self.nu),
            x: self.x,
            p: self.p,
            z: self.z,
            truth: self.truth,
            gain: self.gain,
            out: self.out,
            terms: self.terms,
        }
        .with_simd(simd);
    }
}

/// The J1/J2 step terms of a batched update (paper 003, eqs 10-15), lane by lane:
/// `A_k = H F P+_{k-1} F^T H^T`, `B_k = H Q H^T`, `C_k = H P+_k H^T` and `R_k`, and from them
/// the traces `J1k = tr(S_k^-1 R_k)` (with `S_k = A_k + B_k + R_k`), `J2k = tr((A_k + B_k)^-1
/// B_k)`, `tr(N_k) = tr((A_k + B_k)^-1 (A_k - C_k))` and `tr(B_k)`, formed as
/// `kalibra_metrics::j_step` forms them (through Cholesky factors, symmetrised sums).
///
/// A lane whose `A_k + B_k` is not positive definite (an indefinite prior) has NaN traces:
/// pass its matrices to `j_step`, which solves by LU there.
#[derive(Clone, Debug, PartialEq)]
pub struct JLanes<const M: usize> {
    pub(super) a: [[Lanes; M]; M],
    pub(super) b: [[Lanes; M]; M],
    pub(super) c: [[Lanes; M]; M],
    pub(super) r: [[Lanes; M]; M],
    pub(super) j1: Lanes,
    pub(super) j2: Lanes,
    pub(super) tr_n: Lanes,
    pub(super) tr_b: Lanes,
}

fn matrix_of<const M: usize>(m: &[[Lanes; M]; M], lane: usize) -> SMatrix<f64, M, M> {
    SMatrix::from_fn(|i, j| m[i][j][lane])
}

impl<const M: usize> JLanes<M> {
    fn new() -> Self {
        let zero = [[[0.0; BATCH]; M]; M];
        Self {
            a: zero,
            b: zero,
            c: zero,
            r: zero,
            j1: [0.0; BATCH],
            j2: [0.0; BATCH],
            tr_n: [0.0; BATCH],
            tr_b: [0.0; BATCH],
        }
    }

    /// Lane `lane`'s `A_k`. Every accessor panics if `lane >= BATCH`.
    pub fn a(&self, lane: usize) -> SMatrix<f64, M, M> {
        matrix_of(&self.a, lane)
    }
    /// Lane `lane`'s `B_k`.
    pub fn b(&self, lane: usize) -> SMatrix<f64, M, M> {
        matrix_of(&self.b, lane)
    }
    /// Lane `lane`'s `C_k`.
    pub fn c(&self, lane: usize) -> SMatrix<f64, M, M> {
        matrix_of(&self.c, lane)
    }
    /// Lane `lane`'s `R_k`.
    pub fn r(&self, lane: usize) -> SMatrix<f64, M, M> {
        matrix_of(&self.r, lane)
    }
    /// Lane `lane`'s `J1k`.
    pub fn j1(&self, lane: usize) -> f64 {
        self.j1[lane]
    }
    /// Lane `lane`'s `J2k` (NaN if `A_k + B_k` is not positive definite).
    pub fn j2(&self, lane: usize) -> f64 {
        self.j2[lane]
    }
    /// Lane `lane`'s `tr(N_k)` (NaN if `A_k + B_k` is not positive definite).
    pub fn tr_n(&self, lane: usize) -> f64 {
        self.tr_n[lane]
    }
    /// Lane `lane`'s `tr(B_k)`.
    pub fn tr_b(&self, lane: usize) -> f64 {
        self.tr_b[lane]
    }
}

/// [`BATCH`] extended Kalman filters on one model, stepped together: the scalar
/// [`Ekf`](crate::Ekf)'s arithmetic (Joseph update, symmetrised covariances, Cholesky of `S`),
/// with the model evaluated per lane through [`LaneDynamics`] and [`LaneMeasurement`] and the
/// covariance algebra in the batch kernel of [`KfBatch`](super::KfBatch), on per-lane
/// Jacobians. See the [module docs](super) for the layout, dispatch and per-lane errors.
///
/// ```
/// use kalibra_filters::batch::{BATCH, EkfBatch, Isa, PerLane};
/// use kalibra_linalg::{Matrix1, Matrix2, Vector2};
/// use kalibra_models::{LinearGaussian, LinearObservation};
/// use nalgebra::SMatrix;
///
/// let dynamics = LinearGaussian::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 0.01)?;
/// let sensor = LinearObservation::new(SMatrix::<f64, 1, 2>::new(1.0, 0.0), Matrix1::new(1.0))?;
/// let mut ekf = EkfBatch::new(Isa::detect(), PerLane(dynamics), PerLane(sensor), Vector2::zeros(), Matrix2::identity())?;
/// let z = [[0.5; BATCH]; 1];
/// let step = ekf.predict_update(&z, &[[0.0; BATCH]; 2]);
/// assert!(step.all_ok());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct EkfBatch<const N: usize, const M: usize, D, H> {
    dynamics: D,
    measurement: H,
    lanes: LaneState<N, M>,
    // Per-lane model evaluations of the current step (kept to avoid re-zeroing each step).
    f: [[Lanes; N]; N],
    q: [[Lanes; N]; N],
    h: [[Lanes; N]; M],
    r: [[Lanes; M]; M],
    nu: [Lanes; M],
    out: BatchStep<N>,
    terms: JLanes<M>,
}

impl<const N: usize, const M: usize, D, H> EkfBatch<N, M, D, H>
where
    D: LaneDynamics<N>,
    H: LaneMeasurement<N, M>,
{
    /// [`BATCH`] filters at step 0, each from the estimate `(x0, P0)`, on instruction set `isa`.
    ///
    /// # Errors
    /// [`FilterError::Unsupported`] if the CPU does not run `isa`; [`FilterError::Initial`] if
    /// `x0` is not finite or `P0` not symmetric positive semi-definite (the scalar check).
    pub fn new(
        isa: Isa,
        dynamics: D,
        measurement: H,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        let lanes = LaneState::new(isa, &x0, p0)?;
        Ok(Self {
            dynamics,
            measurement,
            lanes,
            f: [[[0.0; BATCH]; N]; N],
            q: [[[0.0; BATCH]; N]; N],
            h: [[[0.0; BATCH]; N]; M],
            r: [[[0.0; BATCH]; M]; M],
            nu: [[0.0; BATCH]; M],
            out: BatchStep::new(),
            terms: JLanes::new(),
        })
    }

    lane_accessors!(lanes);

    lane_estimates!(lanes);

    /// Lane `lane`'s gain `K` of the last update (meaningful when its [`BatchStep::nis`] is
    /// `Ok`).
    ///
    /// # Panics
    /// If `lane >= BATCH`.
    pub fn gain(&self, lane: usize) -> SMatrix<f64, N, M> {
        self.lanes.gain(lane)
    }

    /// Every lane's gain `K` of the last update, entry by entry (`gains()[i][j][lane]`;
    /// meaningful for the lanes whose [`BatchStep::nis`] is `Ok`).
    pub fn gains(&self) -> &[[Lanes; M]; N] {
        &self.lanes.gain
    }

    /// Predicts every lane from step `k` to `k + 1` (`f_k`, `F_k` and `Q_k` at the lane's
    /// estimate), then updates it with its measurement `z[i][lane]` (the innovation, `H` and
    /// `R` at the lane's prediction) and computes its NIS, and its NEES against
    /// `truth[i][lane]` (pass zeros where there is no truth and ignore the NEES). A lane whose
    /// update fails keeps its prediction, as the scalar filter does.
    pub fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.run::<true>(z, truth, false)
    }

    /// [`EkfBatch::predict_update`], and the J1/J2 step terms of every lane's update (meaningful
    /// for a lane whose [`BatchStep::nis`] is `Ok`).
    pub fn predict_update_j(
        &mut self,
        z: &[Lanes; M],
        truth: &[Lanes; N],
    ) -> (&BatchStep<N>, &JLanes<M>) {
        self.run::<true>(z, truth, true);
        (&self.out, &self.terms)
    }

    /// Updates every lane at the current step without a prediction (a filter whose first
    /// measurement is at its initial step), as [`EkfBatch::predict_update`] updates.
    pub fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
        self.run::<false>(z, truth, false)
    }

    fn run<const PREDICT: bool>(
        &mut self,
        z: &[Lanes; M],
        truth: &[Lanes; N],
        terms: bool,
    ) -> &BatchStep<N> {
        let lanes = &mut self.lanes;
        lanes.isa.dispatch(Step::<N, M, PREDICT, _, _> {
            dynamics: &self.dynamics,
            measurement: &self.measurement,
            k: lanes.k,
            x: &mut lanes.x,
            p: &mut lanes.p,
            gain: &mut lanes.gain,
            f: &mut self.f,
            q: &mut self.q,
            h: &mut self.h,
            r: &mut self.r,
            nu: &mut self.nu,
            z,
            truth,
            out: &mut self.out,
            terms: terms.then_some(&mut self.terms),
        });
        if PREDICT {
            self.lanes.k += 1;
        }
        self.out
            .finish(self.lanes.k, z, &self.lanes.x, &self.lanes.p);
        &self.out
    }
}
