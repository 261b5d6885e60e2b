//! `J1`/`J2` over consecutive steps of a run ([`JSide`]): the step from one covariance to the
//! next under the cell's model ([`JWork`]), at fixed sizes for the common small models, with
//! the model's own products kept while it repeats ([`JModel`]).

use kalibra_linalg::{DMatrix, SMatrix};
use kalibra_metrics::{JHorizon, JStep, Merge, MetricsError, StepMean, j_step};

use super::cell::{MatrixCell, ModelCell, fill};
use crate::EvalError;

/// `J1`/`J2` over consecutive steps of a run.
pub(super) struct JSide {
    pub(super) horizon: JHorizon,
    pub(super) j1: StepMean,
    pub(super) j2: StepMean,
    pub(super) failed: usize,
    /// Per run, the last step fed if its covariance was valid, and the storage of that
    /// covariance (kept from cell to cell, so a cell copies into it and allocates nothing).
    pub(super) previous: Vec<(Option<usize>, DMatrix<f64>)>,
    /// The current cell's covariance.
    current: DMatrix<f64>,
    /// For the steps computed here rather than in a batch's parallel pass.
    work: JWork,
}

impl JSide {
    /// Empty, for a log with a model.
    pub(super) fn new() -> Self {
        Self {
            horizon: JHorizon::new(),
            j1: StepMean::new(0),
            j2: StepMean::new(0),
            failed: 0,
            previous: Vec::new(),
            current: DMatrix::zeros(0, 0),
            work: JWork::new(),
        }
    }

    /// One cell: its covariance if valid, its model matrices if logged (both checked), and
    /// its `J1`/`J2` step if a batch's parallel pass computed it.
    pub(super) fn push(
        &mut self,
        (run, step): (usize, usize),
        (n, m): (usize, usize),
        cov: Option<MatrixCell<'_>>,
        model: Option<ModelCell<'_>>,
        computed: Option<Result<JStep, MetricsError>>,
    ) -> Result<(), EvalError> {
        if run >= self.previous.len() {
            self.previous
                .resize_with(run + 1, || (None, DMatrix::zeros(0, 0)));
        }
        if let Some(cov) = cov {
            fill(&mut self.current, n, cov);
        }
        let follows = self.previous[run].0.is_some_and(|k| k + 1 == step);
        if let (true, Some(_), Some(cell)) = (follows, cov, &model) {
            let outcome = match computed {
                Some(outcome) => outcome,
                None => self
                    .work
                    .step(cell, (n, m), &self.previous[run].1, &self.current),
            };
            match outcome {
                Ok(js) => {
                    self.horizon.push(&js);
                    self.j1.push(step, js.j1)?;
                    self.j2.push(step, js.j2)?;
                }
                Err(_) => self.failed += 1,
            }
        }
        let slot = &mut self.previous[run];
        if cov.is_some() {
            std::mem::swap(&mut slot.1, &mut self.current);
            slot.0 = Some(step);
        } else {
            slot.0 = None;
        }
        Ok(())
    }

    /// See [`Evaluator::merge`](super::Evaluator::merge).
    pub(super) fn merge(&mut self, other: JSide) {
        self.horizon.merge(&other.horizon);
        self.j1.merge(&other.j1);
        self.j2.merge(&other.j2);
        self.failed += other.failed;
        // A run's previous covariance pairs it with its next step; runs fed to `other`
        // continue there.
        if other.previous.len() > self.previous.len() {
            self.previous
                .resize_with(other.previous.len(), || (None, DMatrix::zeros(0, 0)));
        }
        for (mine, theirs) in self.previous.iter_mut().zip(other.previous) {
            if theirs.0.is_some() {
                *mine = theirs;
            }
        }
    }

    pub(super) fn report(self, steps: usize) -> Result<Option<crate::JReport>, EvalError> {
        if self.horizon.updates() == 0 {
            return Ok(None);
        }
        let summary = self.horizon.summary(self.horizon.updates())?;
        let series = |s: &StepMean| -> Vec<Option<f64>> { (0..steps).map(|k| s.mean(k)).collect() };
        Ok(Some(crate::JReport {
            j1_per_step: series(&self.j1),
            j2_per_step: series(&self.j2),
            j1: summary.j1,
            j2: summary.j2,
            nq_mean_log10: summary.nq_mean_log10,
            nq_log10_mean: summary.nq_log10_mean,
            updates: summary.updates,
            indefinite_updates: summary.indefinite_updates,
            failed_updates: self.failed,
        }))
    }
}

/// What a `J1`/`J2` step needs besides its two covariances: the last model seen with its
/// products, and storage for the cell's products.
pub(super) struct JWork {
    model: Option<JModel>,
    /// `m x n` and `m x m` products of a cell (the `Dyn` path).
    hp: DMatrix<f64>,
    a: DMatrix<f64>,
    c: DMatrix<f64>,
}

impl JWork {
    pub(super) fn new() -> Self {
        Self {
            model: None,
            hp: DMatrix::zeros(0, 0),
            a: DMatrix::zeros(0, 0),
            c: DMatrix::zeros(0, 0),
        }
    }

    /// The step from `P+_{k-1}` (`p0`) to `P+_k` (`p1`) under the model `cell`.
    pub(super) fn step(
        &mut self,
        cell: &ModelCell<'_>,
        (n, m): (usize, usize),
        p0: &DMatrix<f64>,
        p1: &DMatrix<f64>,
    ) -> Result<JStep, MetricsError> {
        let jm = match self.model.take() {
            Some(jm) if jm.is(cell) => self.model.insert(jm),
            _ => self.model.insert(JModel::new(cell, (n, m))),
        };
        if let Some(outcome) = j_fixed(jm, p0, p1) {
            return outcome;
        }
        if self.hp.shape() != (m, n) {
            self.hp = DMatrix::zeros(m, n);
            self.a = DMatrix::zeros(m, m);
            self.c = DMatrix::zeros(m, m);
        }
        // A = (H F) P+_{k-1} (H F)^T and C = H P+_k H^T, as products into reused storage
        // (`mul_to` is the product `*` computes, into a given matrix).
        jm.hf.mul_to(p0, &mut self.hp);
        self.hp.mul_to(&jm.hft, &mut self.a);
        jm.h.mul_to(p1, &mut self.hp);
        self.hp.mul_to(&jm.ht, &mut self.c);
        j_step(&self.a, &jm.b, &jm.r, &self.c)
    }
}

/// One `J1`/`J2` step at fixed sizes for the common small models (`m <= 4`, `n <= 6`):
/// `A = (H F) P+_{k-1} (H F)^T`, `C = H P+_k H^T` and [`j_step`] on nalgebra's fixed-size
/// code, which allocates nothing, where the `Dyn` version allocates each temporary (the
/// allocations would cost more than the rest of a cell; `cargo xtask bench eval` times it).
/// The operations are the `Dyn` path's, in the same order, so the values are the same to the
/// bit (the property test `fixed_size_j_equals_the_dyn_path_bit_for_bit` compares the two).
/// `None` for other sizes.
pub(super) fn j_fixed(
    jm: &JModel,
    p0: &DMatrix<f64>,
    p1: &DMatrix<f64>,
) -> Option<Result<JStep, MetricsError>> {
    fn at<const M: usize, const N: usize>(
        jm: &JModel,
        p0: &DMatrix<f64>,
        p1: &DMatrix<f64>,
    ) -> Result<JStep, MetricsError> {
        let mn = |x: &DMatrix<f64>| SMatrix::<f64, M, N>::from_column_slice(x.as_slice());
        let nm = |x: &DMatrix<f64>| SMatrix::<f64, N, M>::from_column_slice(x.as_slice());
        let nn = |x: &DMatrix<f64>| SMatrix::<f64, N, N>::from_column_slice(x.as_slice());
        let mm = |x: &DMatrix<f64>| SMatrix::<f64, M, M>::from_column_slice(x.as_slice());
        let a = mn(&jm.hf) * nn(p0) * nm(&jm.hft);
        let c = mn(&jm.h) * nn(p1) * nm(&jm.ht);
        j_step(&a, &mm(&jm.b), &mm(&jm.r), &c)
    }
    macro_rules! sizes {
        ($($m:literal: $($n:literal)*;)*) => {
            match (jm.h.nrows(), jm.h.ncols()) {
                $($(($m, $n) => Some(at::<$m, $n>(jm, p0, p1)),)*)*
                _ => None,
            }
        };
    }
    sizes! {
        1: 1 2 3 4 5 6;
        2: 1 2 3 4 5 6;
        3: 1 2 3 4 5 6;
        4: 1 2 3 4 5 6;
    }
}

/// The model matrices of the last cell and the products `J1`/`J2` take from them alone:
/// while the model stays the same (a constant model, or one per step repeated across runs
/// in a row), they are converted and multiplied once, not once per cell. The products are
/// the same expressions as before, so the numbers do not change.
pub(super) struct JModel {
    /// `F`, `H`, `Q`, `R` row by row, one after the other: the key.
    values: Vec<f64>,
    pub(super) h: DMatrix<f64>,
    pub(super) r: DMatrix<f64>,
    /// `H^T`, `H F`, `(H F)^T` and `B = H Q H^T`.
    pub(super) ht: DMatrix<f64>,
    pub(super) hf: DMatrix<f64>,
    pub(super) hft: DMatrix<f64>,
    pub(super) b: DMatrix<f64>,
}

impl JModel {
    /// Whether `cell` holds the same values, bit for bit.
    pub(super) fn is(&self, cell: &ModelCell<'_>) -> bool {
        let mut at = 0;
        [cell.f, cell.h, cell.q, cell.r].iter().all(|part| {
            let same = self.values.get(at..at + part.len()).is_some_and(|v| {
                v.iter()
                    .zip(part.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            });
            at += part.len();
            same
        }) && at == self.values.len()
    }

    pub(super) fn new(cell: &ModelCell<'_>, (n, m): (usize, usize)) -> Self {
        let f = DMatrix::from_row_slice(n, n, cell.f);
        let h = DMatrix::from_row_slice(m, n, cell.h);
        let q = DMatrix::from_row_slice(n, n, cell.q);
        let r = DMatrix::from_row_slice(m, m, cell.r);
        let ht = h.transpose();
        let hf = &h * &f;
        let hft = hf.transpose();
        let b: DMatrix<f64> = &h * &q * &ht;
        Self {
            values: [cell.f, cell.h, cell.q, cell.r].concat(),
            h,
            r,
            ht,
            hf,
            hft,
            b,
        }
    }
}
