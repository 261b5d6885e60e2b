//! The numerical core shared by the Kalman-type filters: predict and update as algebra on
//! `F, Q, H, R` and the residual, separate from model evaluation (so that a batched kernel can
//! later reuse the same model calls and the same step record).

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, all_finite, check_dim,
    check_finite, check_symmetric, cholesky_solve_right, innovation_covariance, joseph_update,
    propagate, standard_update, symmetrize,
};

use crate::as_given::lu_solve;
use crate::record::Unchecked;
use crate::{Estimate, FilterError, StepRecord};

/// Checks the shape of what a user's model returned at step `k`: a `Dyn`
/// model answering with a vector or matrix of the wrong size is a
/// [`FilterError::DimensionMismatch`] naming both sizes, before anything is computed from it,
/// not a panic inside nalgebra. Nothing to check for fixed sizes, whose types hold the shape.
pub(crate) fn check_model_output<R: Dim, C: Dim, S: nalgebra::RawStorage<f64, R, C>>(
    what: &'static str,
    m: &nalgebra::Matrix<f64, R, C, S>,
    (rows, cols): (usize, usize),
    k: usize,
) -> Result<(), FilterError> {
    if R::try_to_usize().is_some() && C::try_to_usize().is_some() {
        return Ok(());
    }
    check_dim(rows, m.nrows(), what)
        .and_then(|()| check_dim(cols, m.ncols(), what))
        .map_err(|e| FilterError::at(k, e))
}

/// Which covariance update a filter applies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum UpdateForm {
    /// `(I - K H) P (I - K H)^T + K R K^T`: symmetric positive semi-definite for any gain.
    #[default]
    Joseph,
    /// `(I - K H) P`: cheaper, correct only at the optimal gain, as printed in some papers.
    Standard,
}

/// How strictly the initial covariance is checked.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum InitialCheck {
    /// Finite, symmetric and positive semi-definite.
    #[default]
    PositiveSemiDefinite,
    /// Finite and symmetric only: for studying a filter started from an indefinite `P0` (such
    /// as paper 000's printed one, symmetrised). Metrics on such runs must report the
    /// indefiniteness.
    SymmetricOnly,
    /// Nothing but size and finiteness: `P0` as given, asymmetric or indefinite (paper 000's
    /// printed `P0` entry by entry), for reproducing a paper's arithmetic.
    ///
    /// The filter then carries every covariance as computed, never symmetrised, and
    /// solves for the gain `K = P- H^T S^-1` exactly (also for an asymmetric `P-`, as
    /// `K^T = S^-T H P-^T`) by an LU factorisation of `S`, which it checks only for exact
    /// singularity ([`FilterError::Singular`]). Every record says so
    /// ([`StepRecord::initial_check`](crate::StepRecord::initial_check)): its `S` has no
    /// Cholesky factor ([`StepRecord::s`](crate::StepRecord::s) is `None`), its NIS, NEES and
    /// log-likelihood are computed by LU, and its `A`, `B`, `C` are not symmetrised.
    ///
    /// The opt-in is a constructor, [`Kf::as_given`](crate::Kf::as_given) or
    /// [`Ekf::as_given`](crate::Ekf::as_given), which makes a filter of type
    /// `Kf<N, M, D, H, AsGiven>`: the algebra is chosen by the type ([`Checking`]), so the
    /// checked filters carry no trace of it (a run-time flag tested in the update stops the
    /// update inlining into its caller and lengthens the step: `cargo xtask bench w1`). Every `with_options` constructor returns [`FilterError::Unsupported`] for
    /// this variant; the UKF (whose sigma points need a square root of `P`), the SRF and the
    /// constant-gain KF have no as-given form.
    AsGiven,
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for super::Checked {}
    impl Sealed for super::AsGiven {}
}

/// Which algebra a [`Kf`](crate::Kf) or [`Ekf`](crate::Ekf) runs, as a type: [`Checked`] (the
/// default) or [`AsGiven`] ([`InitialCheck::AsGiven`]). Sealed: the two markers are the only
/// implementors.
pub trait Checking:
    sealed::Sealed + Clone + Copy + std::fmt::Debug + Default + Send + Sync + 'static
{
    /// Whether the filter runs [`InitialCheck::AsGiven`]'s algebra.
    const AS_GIVEN: bool;
}

/// The checked algebra (every covariance symmetrised, `S` factorised by Cholesky): the default
/// [`Checking`] of every filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Checked;

/// [`InitialCheck::AsGiven`]'s algebra: covariances as computed, the gain by LU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AsGiven;

impl Checking for Checked {
    const AS_GIVEN: bool = false;
}

impl Checking for AsGiven {
    const AS_GIVEN: bool = true;
}

/// Rejects [`InitialCheck::AsGiven`] in the options of a constructor without an as-given form.
pub(crate) fn reject_as_given(
    options: &FilterOptions,
    what: &'static str,
) -> Result<(), FilterError> {
    if options.initial_check == InitialCheck::AsGiven {
        return Err(FilterError::Unsupported { what });
    }
    Ok(())
}

/// Options shared by the Kalman-type filters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterOptions {
    /// Step index of the initial estimate.
    pub first_step: usize,
    /// Covariance update form.
    pub update: UpdateForm,
    /// Check applied to the initial covariance.
    pub initial_check: InitialCheck,
}

/// Where the current estimate lives inside the core's record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// The current estimate is `record.posterior`; `record` describes the update that produced
    /// it if `has_record`, otherwise the posterior is the initial estimate.
    Posterior,
    /// The current estimate is `record.prior`, with its split into `record.propagated` and
    /// `record.process_noise` and the last Jacobian in `record.f`; the other fields are stale.
    Prior,
}

/// A prior covariance's propagated and process-noise parts, which a prediction without an
/// update before it carries apart.
pub(crate) type PriorSplit<N> = (OMatrix<f64, N, N>, OMatrix<f64, N, N>);

/// The record's prior fields as the last update left them, kept while an update with no
/// prediction before it runs ([`KalmanCore::begin_update`]).
pub(crate) struct SavedPrior<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    prior: Estimate<N>,
    f: OMatrix<f64, N, N>,
    propagated: OMatrix<f64, N, N>,
    process_noise: OMatrix<f64, N, N>,
}

/// An update computed outside the core (unscented, shifted Rayleigh): what the step record
/// stores.
pub(crate) struct UpdateParts<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) zhat: OVector<f64, M>,
    pub(crate) innovation: OVector<f64, M>,
    pub(crate) h: OMatrix<f64, M, N>,
    pub(crate) r: OMatrix<f64, M, M>,
    pub(crate) s: Covariance<M>,
    pub(crate) gain: OMatrix<f64, N, M>,
    pub(crate) mean: OVector<f64, N>,
    pub(crate) cov: OMatrix<f64, N, N>,
}

/// The state of a Kalman-type filter, kept inside one step record so that a step writes each
/// result once, where the record needs it, and copies nothing twice (with `Const` sizes the
/// record is about a kilobyte: copying it around per step cost a quarter of the W1 run time).
#[derive(Clone, Debug)]
pub(crate) struct KalmanCore<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    record: StepRecord<N, M>,
    phase: Phase,
    has_record: bool,
    update: UpdateForm,
}

impl<N: Dim, M: Dim> KalmanCore<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) fn new(
        n: N,
        m: M,
        x0: OVector<f64, N>,
        mut p0: OMatrix<f64, N, N>,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        let init = |e: LinalgError| FilterError::Initial(e);
        check_dim(n.value(), x0.nrows(), "initial mean").map_err(init)?;
        check_dim(n.value(), p0.nrows(), "initial covariance").map_err(init)?;
        check_dim(n.value(), p0.ncols(), "initial covariance").map_err(init)?;
        check_finite(&x0, "initial mean").map_err(init)?;
        match options.initial_check {
            InitialCheck::PositiveSemiDefinite => {
                p0 = kalibra_linalg::PsdMatrix::named(p0, "initial covariance")
                    .map_err(init)?
                    .matrix()
                    .clone();
            }
            InitialCheck::SymmetricOnly => {
                check_symmetric(&p0, "initial covariance").map_err(init)?;
                symmetrize(&mut p0);
            }
            InitialCheck::AsGiven => check_finite(&p0, "initial covariance").map_err(init)?,
        }
        let zeros_nn = || OMatrix::<f64, N, N>::zeros_generic(n, n);
        let placeholder_s =
            Covariance::from_symmetric(OMatrix::<f64, M, M>::identity_generic(m, m), "placeholder")
                .map_err(init)?;
        let record = StepRecord {
            k: options.first_step,
            prior: Estimate {
                mean: x0.clone(),
                cov: p0.clone(),
            },
            posterior: Estimate { mean: x0, cov: p0 },
            predicted_measurement: OVector::<f64, M>::zeros_generic(m, nalgebra::U1),
            innovation: OVector::<f64, M>::zeros_generic(m, nalgebra::U1),
            s: placeholder_s,
            gain: OMatrix::<f64, N, M>::zeros_generic(n, m),
            h: OMatrix::<f64, M, N>::zeros_generic(m, n),
            r: OMatrix::<f64, M, M>::zeros_generic(m, m),
            f: OMatrix::<f64, N, N>::identity_generic(n, n),
            propagated: zeros_nn(),
            process_noise: zeros_nn(),
            unchecked: Unchecked::new(options.initial_check),
        };
        Ok(Self {
            record,
            phase: Phase::Posterior,
            has_record: false,
            update: options.update,
        })
    }

    /// Checks a constant gain for the constant-gain filter and switches to the Joseph update,
    /// since `(I - K H) P-` is the covariance only at the optimal gain.
    pub(crate) fn accept_fixed_gain(
        &mut self,
        gain: &OMatrix<f64, N, M>,
    ) -> Result<(), FilterError> {
        let init = |e: LinalgError| FilterError::Initial(e);
        let (n, m) = (self.record.gain.nrows(), self.record.gain.ncols());
        check_dim(n, gain.nrows(), "constant gain rows").map_err(init)?;
        check_dim(m, gain.ncols(), "constant gain columns").map_err(init)?;
        check_finite(gain, "constant gain").map_err(init)?;
        self.update = UpdateForm::Joseph;
        Ok(())
    }

    fn current(&self) -> &Estimate<N> {
        match self.phase {
            Phase::Posterior => &self.record.posterior,
            Phase::Prior => &self.record.prior,
        }
    }

    pub(crate) fn mean(&self) -> &OVector<f64, N> {
        &self.current().mean
    }
    pub(crate) fn cov(&self) -> &OMatrix<f64, N, N> {
        &self.current().cov
    }
    pub(crate) fn step(&self) -> usize {
        self.record.k
    }
    /// The record of the update at the current step; none after a prediction.
    pub(crate) fn record(&self) -> Option<&StepRecord<N, M>> {
        (self.phase == Phase::Posterior && self.has_record).then_some(&self.record)
    }

    /// Predicts from step `k` to `k + 1` given the predicted mean, the transition Jacobian and
    /// the process noise, all evaluated by the caller.
    pub(crate) fn predict<const AS_GIVEN: bool>(
        &mut self,
        x_pred: OVector<f64, N>,
        f: OMatrix<f64, N, N>,
        q: OMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let rec = &self.record;
        let (propagated, noise) = match self.phase {
            Phase::Posterior => (propagate(&f, &rec.posterior.cov), q),
            // A second prediction without an update: carry both parts.
            Phase::Prior => (
                propagate(&f, &rec.propagated),
                propagate(&f, &rec.process_noise) + q,
            ),
        };
        self.predict_split::<AS_GIVEN>(x_pred, f, propagated, noise)
    }

    /// [`KalmanCore::predict`] for a caller that has tested that an update ran since the last
    /// prediction ([`KalmanCore::is_prior`] is false): the posterior is read at its fixed place,
    /// with no run-time choice of field (`cargo xtask bench w1`, the scalar library).
    #[inline(always)]
    pub(crate) fn predict_after_update<const AS_GIVEN: bool>(
        &mut self,
        x_pred: OVector<f64, N>,
        f: OMatrix<f64, N, N>,
        q: OMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let propagated = propagate(&f, &self.record.posterior.cov);
        self.predict_split::<AS_GIVEN>(x_pred, f, propagated, q)
    }

    /// The covariance update the filter applies.
    pub(crate) fn update_form(&self) -> UpdateForm {
        self.update
    }

    /// Puts the core where its own predictions and updates would have left it after a pass
    /// computed outside it (the KF smoother's, `smooth/linear.rs`), so that the next step runs
    /// as usual: at step `k` with `estimate` as the posterior, or, with `split` (its
    /// propagated and process-noise parts), as the prior of a prediction no update followed;
    /// `updated` when that posterior is an update's. The rest of the record is left for the
    /// next prediction and update to overwrite, which the caller runs at once.
    pub(crate) fn resume(
        &mut self,
        k: usize,
        estimate: Estimate<N>,
        split: Option<PriorSplit<N>>,
        updated: bool,
    ) {
        let rec = &mut self.record;
        rec.k = k;
        match split {
            None => {
                rec.posterior = estimate;
                self.phase = Phase::Posterior;
                self.has_record |= updated;
            }
            Some((propagated, noise)) => {
                rec.prior = estimate;
                rec.propagated = propagated;
                rec.process_noise = noise;
                self.phase = Phase::Prior;
            }
        }
    }

    /// Whether the current estimate is a prior (a prediction ran since the last update).
    pub(crate) fn is_prior(&self) -> bool {
        self.phase == Phase::Prior
    }

    /// The parts of the current prior covariance: carried from the last posterior, and process
    /// noise added since (both meaningful only when [`KalmanCore::is_prior`]).
    pub(crate) fn prior_split(&self) -> (&OMatrix<f64, N, N>, &OMatrix<f64, N, N>) {
        (&self.record.propagated, &self.record.process_noise)
    }

    /// Predicts from step `k` to `k + 1` given the predicted mean, the Jacobian to record, and
    /// the prior covariance already split into its propagated and process-noise parts (the
    /// unscented prediction computes the first part itself).
    #[inline(always)]
    pub(crate) fn predict_split<const AS_GIVEN: bool>(
        &mut self,
        x_pred: OVector<f64, N>,
        f: OMatrix<f64, N, N>,
        propagated: OMatrix<f64, N, N>,
        noise: OMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let k = self.record.k;
        let mut p = &propagated + &noise;
        if !AS_GIVEN {
            symmetrize(&mut p);
        }
        // Non-finite inputs always reach the outputs, so check the outputs on the hot path and
        // look for the culprit only when they fail.
        if !(all_finite(&p) && all_finite(&x_pred)) {
            check_finite(&f, "transition Jacobian F").map_err(|e| FilterError::at(k, e))?;
            check_finite(&x_pred, "predicted mean").map_err(|e| FilterError::at(k + 1, e))?;
            return Err(FilterError::NonFinite {
                what: "predicted covariance (process noise Q?)",
                step: k + 1,
            });
        }
        let rec = &mut self.record;
        rec.prior.mean = x_pred;
        rec.prior.cov = p;
        rec.f = f;
        rec.propagated = propagated;
        rec.process_noise = noise;
        rec.k = k + 1;
        self.phase = Phase::Prior;
        Ok(())
    }

    /// Predicts from step `k` to `k + 1` with an unscented prior covariance `cov` (symmetric),
    /// recording the Jacobian `f` and the process noise `q`. After an update the whole of `cov`
    /// less `q` counts as propagated; at a second prediction without an update the old noise
    /// part is carried through the Jacobian and what the unscented transform adds beyond it
    /// counts as propagated, so the parts still sum to the unscented prior (and equal the
    /// KF's split for linear `f`).
    pub(crate) fn predict_unscented(
        &mut self,
        mean: OVector<f64, N>,
        f: OMatrix<f64, N, N>,
        cov: OMatrix<f64, N, N>,
        q: OMatrix<f64, N, N>,
    ) -> Result<(), FilterError> {
        let (propagated, noise) = if self.is_prior() {
            let (_, old_noise) = self.prior_split();
            let carried_noise = propagate(&f, old_noise);
            (&cov - &carried_noise, carried_noise + q)
        } else {
            (cov, q)
        };
        self.predict_split::<false>(mean, f, propagated, noise)
    }

    /// The prior of an update at the current step: the prediction, or, after an update with
    /// no prediction since (a filter that starts by updating), the current posterior. Nothing
    /// changes until the update succeeds ([`KalmanCore::begin_record`]), so a failed update
    /// leaves the filter and its last record as they were.
    ///
    /// The posterior comes from an out-of-line call because, when both fields are plain reads,
    /// the compiler loads both matrices and blends them on every step (`cargo xtask bench w1`,
    /// the scalar library).
    #[inline(always)]
    pub(crate) fn update_prior(&self) -> &Estimate<N> {
        match self.phase {
            Phase::Prior => &self.record.prior,
            Phase::Posterior => self.posterior_cold(),
        }
    }

    /// The posterior, out of line (see [`KalmanCore::update_prior`]).
    #[cold]
    #[inline(never)]
    fn posterior_cold(&self) -> &Estimate<N> {
        &self.record.posterior
    }

    /// The last update's posterior, which a prediction after it starts from.
    #[inline(always)]
    pub(crate) fn posterior(&self) -> &Estimate<N> {
        &self.record.posterior
    }

    /// On a successful update's way into the record: when no prediction ran since the last
    /// update, the prior is that update's posterior, all of it counted as "propagated"
    /// (`B_k = 0`, `F = I`).
    #[inline(always)]
    fn begin_record(&mut self) {
        if self.phase == Phase::Posterior {
            self.begin_record_cold();
        }
    }

    /// [`KalmanCore::begin_record`]'s copy, out of line: an update with no prediction before
    /// it is rare, and its code inlined would lengthen every update (`cargo xtask bench w1`).
    #[cold]
    #[inline(never)]
    fn begin_record_cold(&mut self) {
        let rec = &mut self.record;
        rec.prior = rec.posterior.clone();
        rec.propagated = rec.prior.cov.clone();
        rec.process_noise.fill(0.0);
        rec.f.fill_with_identity();
        self.phase = Phase::Prior;
    }

    /// Puts the prior of the coming update where a prediction leaves it, the record's prior
    /// field, so that the update reads it at one fixed place. After a prediction there is
    /// nothing to do; after an update with no prediction since (rare), the record's prior
    /// fields take the posterior ([`KalmanCore::begin_record`]) and their old values come back,
    /// to be put back by [`KalmanCore::undo_begin_update`] if the update fails, so that a
    /// failed update leaves the filter and its last record as they were.
    ///
    /// A run-time choice between the prior and the posterior field instead makes the compiler
    /// read the prior through a pointer and keep less of the prediction in registers, which
    /// lengthens the step (`cargo xtask bench w1`, the scalar library).
    ///
    /// The saved fields come back by value, not boxed: a fixed-size step must not allocate,
    /// even the first update of an update-first run (`tests/no_alloc.rs`).
    #[inline(always)]
    pub(crate) fn begin_update(&mut self) -> Option<SavedPrior<N>> {
        match self.phase {
            Phase::Prior => None,
            Phase::Posterior => Some(self.begin_update_cold()),
        }
    }

    /// [`KalmanCore::begin_update`] after an update, out of line.
    #[cold]
    #[inline(never)]
    fn begin_update_cold(&mut self) -> SavedPrior<N> {
        let rec = &self.record;
        let saved = SavedPrior {
            prior: rec.prior.clone(),
            f: rec.f.clone(),
            propagated: rec.propagated.clone(),
            process_noise: rec.process_noise.clone(),
        };
        self.begin_record();
        saved
    }

    /// Undoes [`KalmanCore::begin_update`] after a failed update: the record's prior fields
    /// and the phase as they were.
    #[cold]
    #[inline(never)]
    pub(crate) fn undo_begin_update(&mut self, saved: SavedPrior<N>) {
        let SavedPrior {
            prior,
            f,
            propagated,
            process_noise,
        } = saved;
        let rec = &mut self.record;
        rec.prior = prior;
        rec.f = f;
        rec.propagated = propagated;
        rec.process_noise = process_noise;
        self.phase = Phase::Posterior;
    }

    /// The record's prior field: an update's prior once [`KalmanCore::begin_update`] ran.
    #[inline(always)]
    pub(crate) fn prior(&self) -> &Estimate<N> {
        &self.record.prior
    }

    /// The record of the update just stored by [`KalmanCore::update`].
    pub(crate) fn updated_record(&self) -> &StepRecord<N, M> {
        &self.record
    }

    /// Stores an update computed by the caller (the unscented and shifted Rayleigh filters) and
    /// returns its record. The posterior is symmetrised here and checked for finiteness.
    pub(crate) fn commit_update(
        &mut self,
        mut parts: UpdateParts<N, M>,
    ) -> Result<&StepRecord<N, M>, FilterError> {
        symmetrize(&mut parts.cov);
        self.check_and_store(parts)
    }

    /// Checks that an update's posterior is finite, then writes it into the record and makes it
    /// current. Non-finite inputs always reach the posterior, so the hot path checks only the
    /// outputs and names the culprit (a non-finite innovation) only when they fail.
    fn check_and_store(
        &mut self,
        parts: UpdateParts<N, M>,
    ) -> Result<&StepRecord<N, M>, FilterError> {
        self.check_posterior(&parts)?;
        self.begin_record();
        self.store(parts);
        Ok(&self.record)
    }

    /// Checks that an update's posterior is finite (the first half of
    /// [`KalmanCore::check_and_store`]).
    #[inline(always)]
    fn check_posterior(&self, parts: &UpdateParts<N, M>) -> Result<(), FilterError> {
        let k = self.record.k;
        if !(all_finite(&parts.mean) && all_finite(&parts.cov)) {
            check_finite(&parts.innovation, "innovation").map_err(|e| FilterError::at(k, e))?;
            return Err(FilterError::NonFinite {
                what: "posterior estimate",
                step: k,
            });
        }
        Ok(())
    }

    /// Writes a checked update into the record, whose prior fields hold its prior, and makes
    /// its posterior current.
    #[inline(always)]
    fn store(&mut self, parts: UpdateParts<N, M>) {
        let rec = &mut self.record;
        rec.posterior.mean = parts.mean;
        rec.posterior.cov = parts.cov;
        rec.predicted_measurement = parts.zhat;
        rec.innovation = parts.innovation;
        rec.s = parts.s;
        rec.gain = parts.gain;
        rec.h = parts.h;
        rec.r = parts.r;
        self.phase = Phase::Posterior;
        self.has_record = true;
    }

    /// Updates at the current step with the predicted measurement, the innovation (residual),
    /// the measurement Jacobian and the noise, all evaluated by the caller; with `fixed_gain`
    /// (the constant-gain filter) instead of the optimal gain. The KF and EKF pass `None`, a
    /// constant the compiler folds away, so their hot path carries no branch for it.
    ///
    /// The prior is the record's prior field: the caller has run
    /// [`KalmanCore::begin_update`]. On success [`KalmanCore::updated_record`] has the record.
    pub(crate) fn update<const AS_GIVEN: bool>(
        &mut self,
        zhat: OVector<f64, M>,
        innovation: OVector<f64, M>,
        h: OMatrix<f64, M, N>,
        r: OMatrix<f64, M, M>,
        fixed_gain: Option<&OMatrix<f64, N, M>>,
    ) -> Result<(), FilterError> {
        if AS_GIVEN {
            return self.update_as_given(zhat, innovation, h, r, fixed_gain);
        }
        let k = self.record.k;
        let at = |e| FilterError::at(k, e);
        let form = self.update;
        let prior = &self.record.prior;
        // The kernels write fixed sizes out in nalgebra's order and are always inlined, so the
        // step keeps its matrices in registers instead of passing them through memory to
        // out-of-line products (`cargo xtask bench w1`, the scalar library); run-time sizes may
        // go to faer.
        let (pht, s) = innovation_covariance(&prior.cov, &h, &r);
        let s = Covariance::from_symmetric(s, "innovation covariance S").map_err(|e| {
            // NaN in H or R makes the factorisation fail too: name the real culprit.
            let culprit = check_finite(&h, "measurement Jacobian H")
                .and_then(|()| check_finite(&r, "measurement noise covariance R"));
            at(culprit.err().unwrap_or(e))
        })?;
        let gain = match fixed_gain {
            Some(gain) => gain.clone(),
            // K = P H^T S^-1: a solve with the factor of S (sizes agree by construction),
            // whose non-finite results the posterior check below catches.
            None => cholesky_solve_right(s.cholesky(), &pht),
        };
        let x_post = &prior.mean + &gain * &innovation;
        let p_post = match form {
            UpdateForm::Joseph => joseph_update(&prior.cov, &gain, &h, &r),
            UpdateForm::Standard => standard_update(&prior.cov, &gain, &h),
        };
        let parts = UpdateParts {
            zhat,
            innovation,
            h,
            r,
            s,
            gain,
            mean: x_post,
            cov: p_post,
        };
        self.check_posterior(&parts)?;
        self.store(parts);
        Ok(())
    }

    /// The update of [`InitialCheck::AsGiven`]: the Kalman update in exact arithmetic for an
    /// asymmetric or indefinite prior, nothing symmetrised, the gain `K = P- H^T S^-1` as
    /// `(S^-T (H P-^T))^T` by LU. The products are written as a textbook (and paper 000's
    /// replay) writes them, so that a study reproduces that arithmetic to the bit.
    fn update_as_given(
        &mut self,
        zhat: OVector<f64, M>,
        innovation: OVector<f64, M>,
        h: OMatrix<f64, M, N>,
        r: OMatrix<f64, M, M>,
        fixed_gain: Option<&OMatrix<f64, N, M>>,
    ) -> Result<(), FilterError> {
        let k = self.record.k;
        let form = self.update;
        let prior = &self.record.prior;
        let s = &h * &prior.cov * h.transpose() + &r;
        let gain = match fixed_gain {
            Some(gain) => gain.clone(),
            None => lu_solve(&s.transpose(), &(&h * prior.cov.transpose()))
                .ok_or(FilterError::Singular {
                    what: "innovation covariance S",
                    step: k,
                })?
                .transpose(),
        };
        let mean = &prior.mean + &gain * &innovation;
        let cov = match form {
            UpdateForm::Joseph => {
                let n = h.shape_generic().1;
                let ikh = OMatrix::<f64, N, N>::identity_generic(n, n) - &gain * &h;
                &ikh * &prior.cov * ikh.transpose() + &gain * &r * gain.transpose()
            }
            UpdateForm::Standard => &prior.cov - &gain * (&h * &prior.cov),
        };
        if !(all_finite(&mean) && all_finite(&cov)) {
            check_finite(&innovation, "innovation").map_err(|e| FilterError::at(k, e))?;
            check_finite(&s, "innovation covariance S").map_err(|e| FilterError::at(k, e))?;
            return Err(FilterError::NonFinite {
                what: "posterior estimate",
                step: k,
            });
        }
        let rec = &mut self.record;
        rec.posterior.mean = mean;
        rec.posterior.cov = cov;
        rec.predicted_measurement = zhat;
        rec.innovation = innovation;
        if let Some(unchecked) = rec.unchecked.as_mut() {
            unchecked.s = Some(s);
        }
        rec.gain = gain;
        rec.h = h;
        rec.r = r;
        self.phase = Phase::Posterior;
        self.has_record = true;
        Ok(())
    }

    /// Checks the length and finiteness of a measurement handed in from outside.
    pub(crate) fn check_measurement(
        &self,
        m: usize,
        z: &OVector<f64, M>,
    ) -> Result<(), FilterError> {
        check_dim(m, z.nrows(), "measurement").map_err(|e| FilterError::at(self.step(), e))?;
        check_finite(z, "measurement").map_err(|e| FilterError::at(self.step(), e))
    }
}
