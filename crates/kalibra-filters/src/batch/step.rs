//! [`BatchStep`]: the results of one batched update, lane by lane, and the scalar filter's
//! error for each failed lane.

use super::{BATCH, Lanes};
use crate::FilterError;

/// The results of one batched update, lane by lane.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchStep<const N: usize> {
    pub(super) k: usize,
    pub(super) nis: Lanes,
    pub(super) nees: Lanes,
    pub(super) error: [Lanes; N],
    // 0 where the lane's update succeeded, NaN where it failed (the kernel's health sum).
    pub(super) health: Lanes,
    // The error of a lane's update, and of its NEES (the update's, or the NEES's own).
    pub(super) failure: [Option<FilterError>; BATCH],
    pub(super) nees_failure: [Option<FilterError>; BATCH],
    // Whether `failure` or `nees_failure` holds an error, as `finish` leaves them (it skips
    // both when neither does and every lane succeeded: the common step costs a pass over the
    // health sums). The UKF writes the two itself and never reads this.
    pub(super) stored_failures: bool,
}

impl<const N: usize> BatchStep<N> {
    /// Completes the kernel's output for step `k`: the kernel's health sum is 0 for a lane
    /// whose update succeeded and NaN otherwise; the NEES is checked apart, as the scalar
    /// record's `nees` is a separate call. `x`, `p`: the lanes' states after the step.
    #[inline]
    pub(super) fn finish<const M: usize>(
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

    pub(super) fn new() -> Self {
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
