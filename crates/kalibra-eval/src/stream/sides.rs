//! The state side (NEES, NCI, RMSE, the diagnostic run's errors) and the innovation side
//! (NIS, the diagnostic run's normalised innovations) of an [`Evaluator`](super::Evaluator):
//! what one cell adds to each, and how two evaluators' sides merge.

use kalibra_linalg::DVector;
use kalibra_metrics::{Credibility, CredibilityRows, Merge, SquaredErrors, StepMean};

use super::cell::MatrixCell;
use super::factor::Factor;
use super::per_run::PerRun;
use crate::evaluate::FindingTally;
use crate::report::Reason;
use crate::{EvalError, Evaluation};

/// The state side: NEES, NCI, RMSE and the diagnostic run's errors.
pub(super) struct StateSide {
    pub(super) n: usize,
    /// The current cell's error `xhat - x`.
    error: Vec<f64>,
    pub(super) means: StepMean,
    /// NCI's storage, settled: read it only after [`StateSide::settle`].
    pub(super) cred: Credibility,
    /// Cells for `cred` not yet settled into it, in the order fed.
    rows: CredibilityRows,
    pub(super) squared: SquaredErrors,
    pub(super) per_run: PerRun,
    pub(super) findings: FindingTally,
    /// The diagnostic run's errors, by step (sorted when finishing).
    pub(super) window_series: Vec<(usize, Vec<f64>)>,
}

/// The innovation side: NIS and the diagnostic run's normalised innovations.
pub(super) struct InnovationSide {
    pub(super) m: usize,
    /// For the diagnostic run's normalised innovations.
    factor: Factor,
    pub(super) means: StepMean,
    pub(super) per_run: PerRun,
    pub(super) findings: FindingTally,
    pub(super) normalized: Vec<(usize, DVector<f64>)>,
}

/// Cells [`StateSide`] holds in its [`CredibilityRows`] before settling them into NCI's
/// storage: few enough to stay in cache while settled (0.6 MB for `n = 4`), many enough that
/// each settling appends several runs' cells to each step's vector at once; `1 << 16` timed the
/// same and faulted in more pages (`cargo xtask bench eval`, NPZ).
const SETTLE_CELLS: usize = 1 << 14;

impl StateSide {
    /// Moves the cells not yet settled into NCI's storage, `cred`.
    pub(super) fn settle(&mut self) {
        self.cred.settle(&mut self.rows);
    }

    /// The state side of an `n`-state log, empty.
    pub(super) fn new(n: usize) -> Self {
        Self {
            n,
            error: vec![0.0; n],
            means: StepMean::new(0),
            cred: Credibility::new(0, n),
            rows: CredibilityRows::new(),
            squared: SquaredErrors::new(0, n),
            per_run: PerRun::default(),
            findings: FindingTally::default(),
            window_series: Vec::new(),
        }
    }

    /// One cell's state side, given its NEES; returns whether its covariance was valid (it
    /// entered NEES).
    pub(super) fn accept(
        &mut self,
        options: &Evaluation,
        (run, step): (usize, usize),
        x: &[f64],
        xhat: &[f64],
        nees: Option<Result<f64, Reason>>,
    ) -> Result<bool, EvalError> {
        if !xhat.iter().all(|v| v.is_finite()) {
            self.findings
                .add("estimate", run, step, Reason::NonFiniteVector);
            return Ok(false);
        }
        // RMSE and windows need no covariance: estimate minus truth (paper 002's sign).
        for ((e, a), b) in self.error.iter_mut().zip(xhat).zip(x) {
            *e = a - b;
        }
        if !self.error.iter().all(|v| v.is_finite()) {
            return Err(EvalError::OutOfRange {
                what: "estimation error estimate - truth",
                run,
                step,
            });
        }
        self.squared.push_slice(step, &self.error)?;
        if run == options.run {
            self.window_series.push((step, self.error.clone()));
        }
        let n = self.n as f64;
        match nees {
            None => Ok(false),
            Some(Ok(value)) => {
                self.means.push(step, value / n)?;
                self.rows.push_nees(&self.cred, step, &self.error, value)?;
                if self.rows.len() >= SETTLE_CELLS {
                    self.cred.settle(&mut self.rows);
                }
                self.per_run.add(run, step, value / n);
                Ok(true)
            }
            Some(Err(reason)) => {
                self.findings.add("covariance", run, step, reason);
                Ok(false)
            }
        }
    }

    /// See [`Evaluator::merge`](super::Evaluator::merge).
    pub(super) fn merge(&mut self, mut other: StateSide) {
        self.settle();
        other.settle();
        self.means.merge(&other.means);
        self.cred.append(other.cred);
        self.squared.merge(&other.squared);
        self.per_run.merge(other.per_run);
        self.findings.merge(other.findings);
        self.window_series.extend(other.window_series);
    }
}

impl InnovationSide {
    /// The innovation side of an `m`-measurement log, empty.
    pub(super) fn new(m: usize) -> Self {
        Self {
            m,
            factor: Factor::new(m),
            means: StepMean::new(0),
            per_run: PerRun::default(),
            findings: FindingTally::default(),
            normalized: Vec::new(),
        }
    }

    /// One cell's innovation side, given its NIS.
    pub(super) fn accept(
        &mut self,
        options: &Evaluation,
        (run, step): (usize, usize),
        nu: &[f64],
        s: MatrixCell<'_>,
        nis: Option<Result<f64, Reason>>,
    ) -> Result<(), EvalError> {
        let value = match nis {
            None => {
                self.findings
                    .add("innovation", run, step, Reason::NonFiniteVector);
                return Ok(());
            }
            Some(Err(reason)) => {
                self.findings.add("innovation_cov", run, step, reason);
                return Ok(());
            }
            Some(Ok(value)) => value,
        };
        let m = self.m as f64;
        self.means.push(step, value / m)?;
        self.per_run.add(run, step, value / m);
        if run == options.run {
            // The diagnostic run's normalised innovation: factor S again here, once per step
            // of one run, rather than carry every cell's factor from `prepare`.
            self.factor
                .nis_of(s, nu, "innovation covariance S")
                .map_err(kalibra_metrics::MetricsError::from)?;
            self.normalized.push((step, self.factor.w.clone()));
        }
        Ok(())
    }

    /// See [`Evaluator::merge`](super::Evaluator::merge).
    pub(super) fn merge(&mut self, other: InnovationSide) {
        self.means.merge(&other.means);
        self.per_run.merge(other.per_run);
        self.findings.merge(other.findings);
        self.normalized.extend(other.normalized);
    }
}
