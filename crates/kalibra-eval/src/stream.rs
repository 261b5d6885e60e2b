//! The evaluation fed one cell at a time: [`Evaluator`], for logs too large to hold (a CSV
//! read row by row) and as the one implementation behind [`Evaluation::evaluate`].

use kalibra_linalg::nalgebra::Cholesky;
use kalibra_linalg::{DMatrix, DVector, LinalgError, SMatrix, check_symmetric, symmetrize};
use kalibra_metrics::{
    Credibility, JHorizon, JStep, Merge, MetricsError, SquaredErrors, StepMean, j_step,
};
use rayon::prelude::*;

use crate::evaluate::{BandCache, FindingTally, reason};
use crate::log::check_times;
use crate::report::{Findings, Reason, Report, SCHEMA_VERSION, Summary, Verdict, VerdictKind};
use crate::{EvalError, Evaluation};

mod state;
pub use state::EvaluatorState;

/// A square matrix in one cell: every entry row by row, or the diagonal alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MatrixCell<'a> {
    /// `dim * dim` values, row by row (numpy's C order).
    Full(&'a [f64]),
    /// The `dim` diagonal values of a matrix whose other entries are 0.
    Diagonal(&'a [f64]),
}

/// The model matrices at one cell, each row by row: `F` (`n x n`) and `Q` (`n x n`) of the
/// prediction into the step, `H` (`m x n`) and `R` (`m x m`) of its update (see
/// [`crate::FilterLog::with_model`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelCell<'a> {
    /// `F`, `n x n`.
    pub f: &'a [f64],
    /// `H`, `m x n`.
    pub h: &'a [f64],
    /// `Q`, `n x n`.
    pub q: &'a [f64],
    /// `R`, `m x m`.
    pub r: &'a [f64],
}

/// One run and step of a log, borrowed; `None` where the array was not logged at this cell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cell<'a> {
    /// The true state, `n` values (must be finite).
    pub truth: Option<&'a [f64]>,
    /// The filter's estimate, `n` values.
    pub estimate: Option<&'a [f64]>,
    /// The filter's (posterior) covariance, `n x n`.
    pub covariance: Option<MatrixCell<'a>>,
    /// The innovation, `m` values.
    pub innovation: Option<&'a [f64]>,
    /// The innovation covariance `S`, `m x m`.
    pub innovation_cov: Option<MatrixCell<'a>>,
    /// The model matrices, for `J1`/`J2` (must be finite).
    pub model: Option<ModelCell<'a>>,
}

/// Which arrays a log holds, with their dimensions, known before its cells arrive: a CSV
/// header, the arrays of a [`crate::FilterLog`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Contents {
    /// The truth's dimension `n`, if logged.
    pub truth: Option<usize>,
    /// The estimate's dimension `n`, if logged.
    pub estimate: Option<usize>,
    /// The covariance's dimension `n`, if logged.
    pub covariance: Option<usize>,
    /// The innovation's dimension `m`, if logged.
    pub innovation: Option<usize>,
    /// The innovation covariance's dimension `m`, if logged.
    pub innovation_cov: Option<usize>,
    /// `(n, m)` of the model matrices `F`, `H`, `Q`, `R`, if logged.
    pub model: Option<(usize, usize)>,
}

impl Contents {
    /// The state dimension `n`, from the first state array logged (or the model).
    pub fn state_dim(&self) -> Option<usize> {
        self.truth
            .or(self.estimate)
            .or(self.covariance)
            .or(self.model.map(|m| m.0))
    }

    /// The measurement dimension `m`, from the first innovation array logged (or the model).
    pub fn measurement_dim(&self) -> Option<usize> {
        self.innovation
            .or(self.innovation_cov)
            .or(self.model.map(|m| m.1))
    }

    /// Checks that the arrays agree on `n` and `m`, and that none is empty.
    fn check(&self) -> Result<(), EvalError> {
        let same =
            |array, what, expected: Option<usize>, found: Option<usize>| match (expected, found) {
                (_, Some(0)) => Err(EvalError::Empty {
                    what: "an array's dimension",
                }),
                (Some(expected), Some(found)) if expected != found => Err(EvalError::Mismatch {
                    array,
                    what,
                    expected,
                    found,
                }),
                _ => Ok(()),
            };
        let (n, m) = (self.state_dim(), self.measurement_dim());
        same("truth", "state dimension", n, self.truth)?;
        same("estimate", "state dimension", n, self.estimate)?;
        same("covariance", "state dimension", n, self.covariance)?;
        same("innovation", "measurement dimension", m, self.innovation)?;
        same(
            "innovation_cov",
            "measurement dimension",
            m,
            self.innovation_cov,
        )?;
        same("F", "state dimension", n, self.model.map(|x| x.0))?;
        same("H", "measurement dimension", m, self.model.map(|x| x.1))
    }
}

/// The state side: NEES, NCI, RMSE, the diagnostic run's errors and, with a model, what
/// `J1`/`J2` need of the previous step.
struct StateSide {
    n: usize,
    /// The current cell's error `xhat - x`.
    error: Vec<f64>,
    means: StepMean,
    cred: Credibility,
    squared: SquaredErrors,
    per_run: PerRun,
    findings: FindingTally,
    /// The diagnostic run's errors, by step (sorted when finishing).
    window_series: Vec<(usize, Vec<f64>)>,
}

/// The innovation side: NIS and the diagnostic run's normalised innovations.
struct InnovationSide {
    m: usize,
    /// For the diagnostic run's normalised innovations.
    factor: Factor,
    means: StepMean,
    per_run: PerRun,
    findings: FindingTally,
    normalized: Vec<(usize, DVector<f64>)>,
}

/// `J1`/`J2` over consecutive steps of a run.
struct JSide {
    horizon: JHorizon,
    j1: StepMean,
    j2: StepMean,
    failed: usize,
    /// Per run, the last step fed if its covariance was valid, and the storage of that
    /// covariance (kept from cell to cell, so a cell copies into it and allocates nothing).
    previous: Vec<(Option<usize>, DMatrix<f64>)>,
    /// The current cell's covariance.
    current: DMatrix<f64>,
    /// For the steps computed here rather than in a batch's parallel pass.
    work: JWork,
}

/// What a `J1`/`J2` step needs besides its two covariances: the last model seen with its
/// products, and storage for the cell's products.
struct JWork {
    model: Option<JModel>,
    /// `m x n` and `m x m` products of a cell (the `Dyn` path).
    hp: DMatrix<f64>,
    a: DMatrix<f64>,
    c: DMatrix<f64>,
}

impl JWork {
    fn new() -> Self {
        Self {
            model: None,
            hp: DMatrix::zeros(0, 0),
            a: DMatrix::zeros(0, 0),
            c: DMatrix::zeros(0, 0),
        }
    }

    /// The step from `P+_{k-1}` (`p0`) to `P+_k` (`p1`) under the model `cell`.
    fn step(
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
/// code, which allocates nothing, where the `Dyn` version allocates each temporary (that
/// made `J1`/`J2` cost twice the rest of a cell). The operations are the `Dyn` path's, in
/// the same order, so the values are the same to the bit (a test compares the two).
/// `None` for other sizes.
fn j_fixed(
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
struct JModel {
    /// `F`, `H`, `Q`, `R` row by row, one after the other: the key.
    values: Vec<f64>,
    h: DMatrix<f64>,
    r: DMatrix<f64>,
    /// `H^T`, `H F`, `(H F)^T` and `B = H Q H^T`.
    ht: DMatrix<f64>,
    hf: DMatrix<f64>,
    hft: DMatrix<f64>,
    b: DMatrix<f64>,
}

impl JModel {
    /// Whether `cell` holds the same values, bit for bit.
    fn is(&self, cell: &ModelCell<'_>) -> bool {
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

    fn new(cell: &ModelCell<'_>, (n, m): (usize, usize)) -> Self {
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

/// An evaluation fed one cell at a time ([`Evaluator::push`]), finished into the same
/// [`Report`] as [`Evaluation::evaluate`], which is built on it.
///
/// Cells may come in any order (run after run, step after step, or mixed); every cell of the
/// `R x K` rectangle must come exactly once, logged or not (an empty [`Cell`]), and the runs
/// and steps are learnt from the largest indices fed. Memory does not grow with the number
/// of cells beyond what the statistics need: per step the sums over runs, and per valid cell
/// the error and NEES that NCI needs (`n + 1` numbers; [`Credibility`]), one bit per cell to
/// catch repeats and gaps, per run and block of 128 steps the sums of its normalised NEES and
/// NIS (for the t-test of the runs' time averages), and the diagnostic run's series.
///
/// Sums over runs are taken in the order the cells come, so two orders of the same cells
/// agree to rounding, and run after run to the bit with [`Evaluation::evaluate`] (which
/// evaluates blocks of 128 steps apart, each in strips of 32 steps run after run, and merges
/// them: each step still takes the runs in order, and a run's sum over its steps is added
/// block by block in either case).
/// `J1`/`J2` pair a step with the step before it in the same run, when they come one after
/// the other.
///
/// ```
/// use kalibra_eval::{Cell, Contents, Evaluation, MatrixCell};
/// let contents = Contents {
///     innovation: Some(1),
///     innovation_cov: Some(1),
///     ..Contents::default()
/// };
/// let mut evaluator = Evaluation::new().lags(1)?.evaluator(contents)?;
/// for (step, nu) in [0.5, -1.0, 1.5, -0.2].iter().enumerate() {
///     let cell = Cell {
///         innovation: Some(std::slice::from_ref(nu)),
///         innovation_cov: Some(MatrixCell::Full(&[1.0])),
///         ..Cell::default()
///     };
///     evaluator.push(0, step, &cell)?;
/// }
/// let report = evaluator.finish(None)?;
/// assert_eq!(report.anis_per_step[1], Some(1.0));
/// # Ok::<(), kalibra_eval::EvalError>(())
/// ```
pub struct Evaluator {
    options: Evaluation,
    contents: Contents,
    state: Option<StateSide>,
    innovation: Option<InnovationSide>,
    j: Option<JSide>,
    runs: usize,
    steps: usize,
    /// Per run, one bit per step fed.
    seen: Vec<Vec<u64>>,
}

impl Evaluation {
    /// An [`Evaluator`] for a log holding `contents`, to be fed cell by cell.
    ///
    /// # Errors
    /// [`EvalError::NothingToEvaluate`] if the log holds neither truth, estimate and
    /// covariance nor innovation and its covariance; [`EvalError::Mismatch`] or
    /// [`EvalError::Empty`] for dimensions that disagree or are zero;
    /// [`EvalError::GroupIndex`] for a group naming a component the state does not have.
    pub fn evaluator(&self, contents: Contents) -> Result<Evaluator, EvalError> {
        contents.check()?;
        let state = match (contents.truth, contents.estimate, contents.covariance) {
            (Some(n), Some(_), Some(_)) => Some(n),
            _ => None,
        };
        let innovation = match (contents.innovation, contents.innovation_cov) {
            (Some(m), Some(_)) => Some(m),
            _ => None,
        };
        if state.is_none() && innovation.is_none() {
            return Err(EvalError::NothingToEvaluate);
        }
        if let Some(n) = state {
            for g in &self.groups {
                if let Some(&index) = g.components.iter().find(|&&i| i >= n) {
                    return Err(EvalError::GroupIndex {
                        group: g.name.clone(),
                        index,
                        dim: n,
                    });
                }
            }
        }
        Ok(Evaluator {
            options: self.clone(),
            contents,
            state: state.map(|n| StateSide {
                n,
                error: vec![0.0; n],
                means: StepMean::new(0),
                cred: Credibility::new(0, n),
                squared: SquaredErrors::new(0, n),
                per_run: PerRun::default(),
                findings: FindingTally::default(),
                window_series: Vec::new(),
            }),
            innovation: innovation.map(|m| InnovationSide {
                m,
                factor: Factor::new(m),
                means: StepMean::new(0),
                per_run: PerRun::default(),
                findings: FindingTally::default(),
                normalized: Vec::new(),
            }),
            j: (state.is_some() && contents.model.is_some()).then(|| JSide {
                horizon: JHorizon::new(),
                j1: StepMean::new(0),
                j2: StepMean::new(0),
                failed: 0,
                previous: Vec::new(),
                current: DMatrix::zeros(0, 0),
                work: JWork::new(),
            }),
            runs: 0,
            steps: 0,
            seen: Vec::new(),
        })
    }
}

/// Checks a vector cell's length.
fn vector<'a>(
    array: &'static str,
    (run, step): (usize, usize),
    dim: usize,
    v: Option<&'a [f64]>,
) -> Result<Option<&'a [f64]>, EvalError> {
    match v {
        Some(v) if v.len() != dim => Err(EvalError::CellLength {
            array,
            run,
            step,
            expected: dim,
            found: v.len(),
        }),
        other => Ok(other),
    }
}

/// Checks a square matrix cell's length.
fn square<'a>(
    array: &'static str,
    (run, step): (usize, usize),
    dim: usize,
    m: Option<MatrixCell<'a>>,
) -> Result<Option<MatrixCell<'a>>, EvalError> {
    let (values, expected) = match m {
        None => return Ok(None),
        Some(MatrixCell::Full(v)) => (v, dim * dim),
        Some(MatrixCell::Diagonal(v)) => (v, dim),
    };
    if values.len() != expected {
        return Err(EvalError::CellLength {
            array,
            run,
            step,
            expected,
            found: values.len(),
        });
    }
    Ok(m)
}

/// Reusable storage for the one factorisation each cell needs (NEES of `P`, NIS of `S`), so
/// that evaluating a cell allocates nothing: a million-cell log spent more time in the
/// allocator than in the arithmetic. The operations are those of
/// `kalibra_linalg::quad_form_once` (NEES) and of `Covariance::named` with `nis` (NIS), in
/// the same order, so the numbers are the same to the bit.
struct Factor {
    dim: usize,
    /// The matrix, then its Cholesky factor in place (empty after a failed factorisation
    /// until the next cell refills it).
    matrix: DMatrix<f64>,
    /// `L^-1 v`.
    w: DVector<f64>,
}

impl Factor {
    fn new(dim: usize) -> Self {
        Self {
            dim,
            matrix: DMatrix::zeros(dim, dim),
            w: DVector::zeros(dim),
        }
    }

    /// Loads a cell's matrix (its length checked by [`square`]).
    fn load(&mut self, cell: MatrixCell<'_>) {
        let n = self.dim;
        if self.matrix.nrows() != n {
            self.matrix = DMatrix::zeros(n, n);
        }
        match cell {
            MatrixCell::Full(v) => {
                for i in 0..n {
                    for j in 0..n {
                        self.matrix[(i, j)] = v[i * n + j];
                    }
                }
            }
            MatrixCell::Diagonal(v) => {
                self.matrix.fill(0.0);
                self.matrix.set_diagonal(&DVector::from_column_slice(v));
            }
        }
    }

    /// Factors the loaded matrix in place; `false` if it is not positive definite.
    fn factor(&mut self) -> bool {
        let matrix = std::mem::replace(&mut self.matrix, DMatrix::zeros(0, 0));
        match Cholesky::new(matrix) {
            Some(chol) => {
                self.matrix = chol.unpack_dirty();
                true
            }
            None => false,
        }
    }

    /// `w = L^-1 v` with the factor in place, and `|w|^2`.
    fn solve(&mut self, v: &[f64]) -> f64 {
        self.w.copy_from_slice(v);
        self.matrix
            .solve_lower_triangular_unchecked_mut(&mut self.w);
        self.w.norm_squared()
    }

    /// The NEES of error `v` under covariance `cell`: [`Factor::nees`] after
    /// [`Factor::load`], at a fixed size for the common dimensions (1 to 6).
    #[inline]
    fn nees_of(
        &mut self,
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<f64, LinalgError> {
        macro_rules! sizes {
            ($($n:literal)*) => {
                match self.dim {
                    $($n => return fixed::nees::<$n>(cell, v, what),)*
                    _ => {}
                }
            };
        }
        sizes!(1 2 3 4 5 6);
        self.load(cell);
        self.nees(v, what)
    }

    /// The NIS of innovation `v` under `S = cell`, and `w = L^-1 v` left in `self.w`:
    /// [`Factor::nis`] after [`Factor::load`], at a fixed size for dimensions 1 to 6.
    #[inline]
    fn nis_of(
        &mut self,
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<f64, LinalgError> {
        macro_rules! sizes {
            ($($n:literal)*) => {
                match self.dim {
                    $($n => {
                        let (q, w) = fixed::nis::<$n>(cell, v, what)?;
                        if self.w.len() != $n {
                            self.w = DVector::zeros($n);
                        }
                        self.w.copy_from_slice(w.as_slice());
                        return Ok(q);
                    })*
                    _ => {}
                }
            };
        }
        sizes!(1 2 3 4 5 6);
        self.load(cell);
        self.nis(v, what)
    }

    /// `v^T M^-1 v` as `kalibra_metrics::nees` computes it.
    fn nees(&mut self, v: &[f64], what: &'static str) -> Result<f64, LinalgError> {
        check_symmetric(&self.matrix, what)?;
        // An error can overflow although truth and estimate are finite.
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LinalgError::NonFinite { what: "vector" });
        }
        if !self.factor() {
            return Err(LinalgError::NotPositiveDefinite { what });
        }
        let q = self.solve(v);
        if q.is_finite() {
            Ok(q)
        } else {
            Err(LinalgError::NotPositiveDefinite { what })
        }
    }

    /// `v^T M^-1 v` as `Covariance::named` and `kalibra_metrics::nis` compute it (`v`
    /// finite): the matrix symmetrised first; `w` is left as the normalised innovation.
    fn nis(&mut self, v: &[f64], what: &'static str) -> Result<f64, LinalgError> {
        check_symmetric(&self.matrix, what)?;
        symmetrize(&mut self.matrix);
        if !(self.factor() && self.matrix.diagonal().iter().all(|d| d.is_finite())) {
            return Err(LinalgError::NotPositiveDefinite { what });
        }
        Ok(self.solve(v))
    }
}

/// [`Factor`]'s factorisations at a fixed size `N`, on nalgebra's stack matrices: no heap, no
/// bounds check per entry, loops of known length. The `Dyn` path spent more in loading the
/// matrix entry by entry and in `Dyn` loop overhead than in the arithmetic (a 4 x 4 NEES cost
/// about 1,100 instructions). The operations are the same generic nalgebra and kalibra-linalg
/// code as the `Dyn` path's, in the same order, so the values are the same to the bit (the
/// property test `factor_equals_the_metrics_bit_for_bit` compares them at every size).
mod fixed {
    use kalibra_linalg::nalgebra::{Cholesky, SVector};
    use kalibra_linalg::{LinalgError, SMatrix, check_symmetric, symmetrize};

    use super::MatrixCell;

    /// The cell's matrix (its length checked by `square`).
    #[inline(always)]
    fn load<const N: usize>(cell: MatrixCell<'_>) -> SMatrix<f64, N, N> {
        match cell {
            // One bounds check for the cell rather than one per entry.
            MatrixCell::Full(v) => SMatrix::from_row_slice(&v[..N * N]),
            MatrixCell::Diagonal(v) => SMatrix::from_fn(|i, j| if i == j { v[i] } else { 0.0 }),
        }
    }

    /// `w = L^-1 v` for the lower Cholesky factor `L` of `m`, or `None` if `m` is not
    /// positive definite; with `|w|^2`.
    #[inline(always)]
    fn solve<const N: usize>(
        m: SMatrix<f64, N, N>,
        v: &[f64],
    ) -> Option<(SMatrix<f64, N, N>, SVector<f64, N>, f64)> {
        let l = Cholesky::new(m)?.unpack_dirty();
        let mut w = SVector::<f64, N>::from_fn(|i, _| v[i]);
        l.solve_lower_triangular_unchecked_mut(&mut w);
        // `|w|^2` summed in index order, as nalgebra's `norm_squared` sums a `Dyn` vector
        // (its fixed-size 4-vector adds the squares pairwise, which differs in the last bit).
        let q = w.iter().fold(0.0, |sum, x| sum + x * x);
        Some((l, w, q))
    }

    /// [`super::Factor::nees`] at size `N`.
    #[inline]
    pub(super) fn nees<const N: usize>(
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<f64, LinalgError> {
        let m = load::<N>(cell);
        check_symmetric(&m, what)?;
        if !v.iter().all(|x| x.is_finite()) {
            return Err(LinalgError::NonFinite { what: "vector" });
        }
        match solve(m, v) {
            Some((_, _, q)) if q.is_finite() => Ok(q),
            _ => Err(LinalgError::NotPositiveDefinite { what }),
        }
    }

    /// [`super::Factor::nis`] at size `N`: the NIS and the normalised innovation `w`.
    #[inline]
    pub(super) fn nis<const N: usize>(
        cell: MatrixCell<'_>,
        v: &[f64],
        what: &'static str,
    ) -> Result<(f64, SVector<f64, N>), LinalgError> {
        let mut m = load::<N>(cell);
        check_symmetric(&m, what)?;
        symmetrize(&mut m);
        match solve(m, v) {
            Some((l, w, q)) if l.diagonal().iter().all(|d| d.is_finite()) => Ok((q, w)),
            _ => Err(LinalgError::NotPositiveDefinite { what }),
        }
    }
}

/// Copies a cell's `dim x dim` matrix into `out`, reusing its storage.
fn fill(out: &mut DMatrix<f64>, dim: usize, cell: MatrixCell<'_>) {
    if out.shape() != (dim, dim) {
        *out = DMatrix::zeros(dim, dim);
    }
    match cell {
        MatrixCell::Full(v) => {
            for i in 0..dim {
                for j in 0..dim {
                    out[(i, j)] = v[i * dim + j];
                }
            }
        }
        MatrixCell::Diagonal(v) => {
            out.fill(0.0);
            for (i, d) in v.iter().enumerate() {
                out[(i, i)] = *d;
            }
        }
    }
}

/// Checks that a model matrix's row-major cell holds `rows x cols` finite values.
fn check_model(
    array: &'static str,
    at: (usize, usize),
    (rows, cols): (usize, usize),
    values: &[f64],
) -> Result<(), EvalError> {
    if values.len() != rows * cols {
        return Err(EvalError::CellLength {
            array,
            run: at.0,
            step: at.1,
            expected: rows * cols,
            found: values.len(),
        });
    }
    if !values.iter().all(|v| v.is_finite()) {
        return Err(EvalError::NonFinite {
            array,
            run: at.0,
            step: at.1,
        });
    }
    Ok(())
}

/// What the pure part of a cell gives, computed on any thread: its checked model matrices
/// and the outcomes of its two factorisations (each a value, or the reason of a finding).
struct Prepared {
    nees: Option<Result<f64, Reason>>,
    nis: Option<Result<f64, Reason>>,
    /// Whether the cell's model matrices were logged, are wanted and passed the checks.
    model: bool,
}

/// The factorisation storage of one thread.
pub(crate) struct Scratch {
    p: Factor,
    s: Factor,
    /// The cell's error `xhat - x`.
    error: Vec<f64>,
}

/// The most runs an [`Evaluator`] takes (run indices `0 .. MAX_RUNS`): its per-run state is
/// about a hundred bytes a run, so the largest index fed sizes it, and a limit checked as each
/// cell comes keeps a mistaken index from allocating gigabytes. 2^24 runs (16.8 million) is
/// far beyond any Monte Carlo study that keeps NCI's per-run errors in memory.
pub const MAX_RUNS: usize = 1 << 24;

/// The most steps an [`Evaluator`] takes (step indices `0 .. MAX_STEPS`), for the same reason
/// as [`MAX_RUNS`]: per-step state is a few hundred bytes a step.
pub const MAX_STEPS: usize = 1 << 24;

/// Batches from this many cells on are prepared on several threads: below it the hand-over
/// costs more than it saves.
const PARALLEL_FROM: usize = 512;

impl Evaluator {
    /// Feeds the cell of `run` and `step`. Nothing is kept of a cell that fails.
    ///
    /// # Errors
    /// [`EvalError::IndexLimit`] for a run or step index at or beyond [`MAX_RUNS`] or
    /// [`MAX_STEPS`]; [`EvalError::DuplicateCell`] for a cell fed before; [`EvalError::CellLength`] for a
    /// value of the wrong length; [`EvalError::NonFinite`] for a non-finite truth or model
    /// matrix; [`EvalError::Metrics`] if a metric fails on data that passed the checks (not
    /// expected). A bad covariance or a non-finite estimate or innovation is a finding, not
    /// an error.
    pub fn push(&mut self, run: usize, step: usize, cell: &Cell<'_>) -> Result<(), EvalError> {
        let mut scratch = self.scratch();
        self.push_with(run, step, cell, &mut scratch)
    }

    /// [`Evaluator::push`] with the caller's factorisation storage, for a caller that feeds
    /// many cells on one thread ([`Evaluation::evaluate`]'s blocks of steps, which run in
    /// parallel with each other): no batch to build, nothing allocated per cell.
    pub(crate) fn push_with(
        &mut self,
        run: usize,
        step: usize,
        cell: &Cell<'_>,
        scratch: &mut Scratch,
    ) -> Result<(), EvalError> {
        let prepared = self.prepare((run, step), cell, scratch)?;
        self.accept((run, step), cell, prepared, None)
    }

    /// Feeds the cells of `cells`, each with its run and step, in order: the same as
    /// [`Evaluator::push`] on each, but the factorisations of a large batch run on every core
    /// (rayon), while the sums still take the cells in order, so the report does not depend on
    /// the number of threads.
    ///
    /// # Errors
    /// The first failing cell's index in `cells` and its error (as [`Evaluator::push`]); the
    /// cells before it were fed, it and those after it were not.
    pub fn push_batch(
        &mut self,
        cells: &[(usize, usize, Cell<'_>)],
    ) -> Result<(), (usize, EvalError)> {
        let this = &*self;
        let prepare = |chunk: &[(usize, usize, Cell<'_>)]| -> Vec<Result<Prepared, EvalError>> {
            let mut scratch = this.scratch();
            chunk
                .iter()
                .map(|(run, step, cell)| this.prepare((*run, *step), cell, &mut scratch))
                .collect()
        };
        let prepared: Vec<Result<Prepared, EvalError>> = if cells.len() < PARALLEL_FROM {
            prepare(cells)
        } else {
            cells
                .par_chunks(PARALLEL_FROM / 2)
                .map(prepare)
                .collect::<Vec<_>>()
                .into_iter()
                .flatten()
                .collect()
        };
        let mut computed = self.j_pass(cells, &prepared).into_iter();
        for (i, ((run, step, cell), p)) in cells.iter().zip(prepared).enumerate() {
            let p = p.map_err(|e| (i, e))?;
            let j = computed.next().flatten();
            self.accept((*run, *step), cell, p, j).map_err(|e| (i, e))?;
        }
        Ok(())
    }

    /// The `J1`/`J2` steps of a large batch, on every core: for each cell whose predecessor
    /// in the batch is the same run's previous step, both with a valid covariance, and whose
    /// model was logged, the step `accept` would compute, computed by the same code. Empty
    /// for a small batch or a log without a model; `None` where `accept` computes it itself
    /// (a run's first cell in the batch).
    fn j_pass(
        &self,
        cells: &[(usize, usize, Cell<'_>)],
        prepared: &[Result<Prepared, EvalError>],
    ) -> Vec<Option<Result<JStep, MetricsError>>> {
        if self.j.is_none() || cells.len() < PARALLEL_FROM {
            return Vec::new();
        }
        let n = self.contents.state_dim().unwrap_or(0);
        let m = self.contents.measurement_dim().unwrap_or(0);
        // The covariance entered NEES: what makes it `J`'s covariance in `accept`.
        let valid = |p: &Result<Prepared, EvalError>| {
            matches!(
                p,
                Ok(Prepared {
                    nees: Some(Ok(_)),
                    ..
                })
            )
        };
        let storage = || (JWork::new(), DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
        (0..cells.len())
            .into_par_iter()
            .with_min_len(PARALLEL_FROM / 2)
            .map_init(storage, |(work, p0, p1), i| {
                let before = cells.get(i.checked_sub(1)?)?;
                let (run, step, cell) = &cells[i];
                let model_logged = matches!(&prepared[i], Ok(p) if p.model);
                if before.0 != *run || before.1 + 1 != *step || !model_logged {
                    return None;
                }
                if !(valid(&prepared[i - 1]) && valid(&prepared[i])) {
                    return None;
                }
                let (Some(c0), Some(c1), Some(model)) =
                    (before.2.covariance, cell.covariance, cell.model)
                else {
                    return None;
                };
                fill(p0, n, c0);
                fill(p1, n, c1);
                Some(work.step(&model, (n, m), p0, p1))
            })
            .collect()
    }

    pub(crate) fn scratch(&self) -> Scratch {
        Scratch {
            p: Factor::new(self.contents.state_dim().unwrap_or(0)),
            s: Factor::new(self.contents.measurement_dim().unwrap_or(0)),
            error: Vec::with_capacity(self.contents.state_dim().unwrap_or(0)),
        }
    }

    /// The pure part of a cell: every check, and its factorisations. Changes nothing.
    fn prepare(
        &self,
        at: (usize, usize),
        cell: &Cell<'_>,
        scratch: &mut Scratch,
    ) -> Result<Prepared, EvalError> {
        let (run, step) = at;
        for (what, index, limit) in [("run", run, MAX_RUNS), ("step", step, MAX_STEPS)] {
            if index >= limit {
                return Err(EvalError::IndexLimit { what, index, limit });
            }
        }
        let (n, m) = (self.contents.state_dim(), self.contents.measurement_dim());
        let truth = vector("truth", at, n.unwrap_or(0), cell.truth)?;
        if truth.is_some_and(|x| !x.iter().all(|v| v.is_finite())) {
            return Err(EvalError::NonFinite {
                array: "truth",
                run,
                step,
            });
        }
        let estimate = vector("estimate", at, n.unwrap_or(0), cell.estimate)?;
        let cov = square("covariance", at, n.unwrap_or(0), cell.covariance)?;
        let nu = vector("innovation", at, m.unwrap_or(0), cell.innovation)?;
        let s = square("innovation_cov", at, m.unwrap_or(0), cell.innovation_cov)?;
        let model = match (cell.model, self.contents.model, &self.j) {
            (Some(c), Some((n, m)), Some(_)) => {
                check_model("F", at, (n, n), c.f)?;
                check_model("H", at, (m, n), c.h)?;
                check_model("Q", at, (n, n), c.q)?;
                check_model("R", at, (m, m), c.r)?;
                true
            }
            _ => false,
        };
        let mut nees = None;
        if let (Some(_), Some(x), Some(xhat), Some(p)) = (&self.state, truth, estimate, cov)
            && xhat.iter().all(|v| v.is_finite())
        {
            // RMSE and windows need no covariance: estimate minus truth (paper 002's sign).
            // Written in place: `clear` and `extend` through the zipped iterators cost 28
            // more instructions a cell (callgrind).
            scratch.error.resize(xhat.len(), 0.0);
            for ((e, a), b) in scratch.error.iter_mut().zip(xhat).zip(x) {
                *e = a - b;
            }
            nees = Some(
                match scratch.p.nees_of(p, &scratch.error, "state covariance P") {
                    Ok(value) => Ok(value),
                    Err(err) => Err(reason(err.into())?),
                },
            );
        }
        let mut nis = None;
        if let (Some(_), Some(nu), Some(s)) = (&self.innovation, nu, s)
            && nu.iter().all(|v| v.is_finite())
        {
            nis = Some(match scratch.s.nis_of(s, nu, "innovation covariance S") {
                Ok(value) => Ok(value),
                Err(err) => Err(reason(err.into())?),
            });
        }
        Ok(Prepared { nees, nis, model })
    }

    /// The stateful part of a cell: marks it, and adds what `prepare` found to the sums.
    fn accept(
        &mut self,
        (run, step): (usize, usize),
        cell: &Cell<'_>,
        prepared: Prepared,
        computed: Option<Result<JStep, MetricsError>>,
    ) -> Result<(), EvalError> {
        self.mark(run, step)?;
        let at = (run, step);
        let valid_cov = match (&mut self.state, cell.truth, cell.estimate) {
            (Some(side), Some(x), Some(xhat)) => {
                side.accept(&self.options, at, x, xhat, prepared.nees)?
            }
            _ => false,
        };
        if let (Some(side), Some(nu), Some(s)) =
            (&mut self.innovation, cell.innovation, cell.innovation_cov)
        {
            side.accept(&self.options, at, nu, s, prepared.nis)?;
        }
        if let Some(j) = &mut self.j {
            let n = self.contents.state_dim().unwrap_or(0);
            let m = self.contents.measurement_dim().unwrap_or(0);
            let p = cell.covariance.filter(|_| valid_cov);
            let model = cell.model.filter(|_| prepared.model);
            j.push(at, (n, m), p, model, computed)?;
        }
        Ok(())
    }

    /// Adds the cells `other` was fed, as if they had come to this evaluator after its own:
    /// per-step sums add (`self`'s first, so the result depends on the order of merges, which
    /// the caller fixes), NCI's per-run errors and NEES append after this evaluator's, counts
    /// and findings add, and the runs and steps grow to cover both. The two must have been
    /// made by the same [`Evaluation`] for the same [`Contents`], and have been fed disjoint
    /// cells; a run split between them must not have a `J1`/`J2` pair across the split (feed
    /// whole runs to each, as a Monte Carlo study cut into blocks of runs does).
    ///
    /// A study that evaluates blocks of runs on separate evaluators and merges them in block
    /// order gets the same report whatever runs the blocks in parallel; it differs from feeding
    /// every cell to one evaluator only in the rounding of the sums.
    ///
    /// # Errors
    /// [`EvalError::MergeMismatch`] for evaluators of different options or contents;
    /// [`EvalError::DuplicateCell`] for a cell both were fed.
    pub fn merge(&mut self, mut other: Evaluator) -> Result<(), EvalError> {
        if self.options != other.options || self.contents != other.contents {
            return Err(EvalError::MergeMismatch);
        }
        // Duplicates first, so that nothing changes on error.
        for (run, bits) in other.seen.iter().enumerate() {
            if let Some(mine) = self.seen.get(run)
                && let Some(w) = mine.iter().zip(bits).position(|(a, b)| a & b != 0)
            {
                let step = w * 64 + (mine[w] & bits[w]).trailing_zeros() as usize;
                return Err(EvalError::DuplicateCell { run, step });
            }
        }
        // One horizon for both, so the per-step accumulators fit.
        self.grow_steps(other.steps);
        other.grow_steps(self.steps);
        if other.seen.len() > self.seen.len() {
            self.seen.resize_with(other.seen.len(), Vec::new);
        }
        for (mine, bits) in self.seen.iter_mut().zip(other.seen) {
            if bits.len() > mine.len() {
                mine.resize(bits.len(), 0);
            }
            for (a, b) in mine.iter_mut().zip(bits) {
                *a |= b;
            }
        }
        self.runs = self.runs.max(other.runs);
        if let (Some(a), Some(b)) = (&mut self.state, other.state) {
            a.merge(b);
        }
        if let (Some(a), Some(b)) = (&mut self.innovation, other.innovation) {
            a.merge(b);
        }
        if let (Some(a), Some(b)) = (&mut self.j, other.j) {
            a.horizon.merge(&b.horizon);
            a.j1.merge(&b.j1);
            a.j2.merge(&b.j2);
            a.failed += b.failed;
            // A run's previous covariance pairs it with its next step; runs fed to `other`
            // continue there.
            if b.previous.len() > a.previous.len() {
                a.previous
                    .resize_with(b.previous.len(), || (None, DMatrix::zeros(0, 0)));
            }
            for (mine, theirs) in a.previous.iter_mut().zip(b.previous) {
                if theirs.0.is_some() {
                    *mine = theirs;
                }
            }
        }
        Ok(())
    }

    /// The number of runs learnt so far: one more than the largest run fed.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// The number of steps learnt so far: one more than the largest step fed.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Records that `(run, step)` came, growing the horizon; an error if it came before.
    fn mark(&mut self, run: usize, step: usize) -> Result<(), EvalError> {
        if run >= self.seen.len() {
            self.seen.resize_with(run + 1, Vec::new);
        }
        let bits = &mut self.seen[run];
        let (word, bit) = (step / 64, 1u64 << (step % 64));
        if word >= bits.len() {
            bits.resize(word + 1, 0);
        }
        if bits[word] & bit != 0 {
            return Err(EvalError::DuplicateCell { run, step });
        }
        bits[word] |= bit;
        self.runs = self.runs.max(run + 1);
        if step >= self.steps {
            self.grow_steps(step + 1);
        }
        Ok(())
    }

    /// Extends the horizon to `steps.end` and reserves NCI's storage for `runs` runs at
    /// `steps`: for a caller that knows the cells it will feed ([`Evaluation::evaluate`]).
    pub(crate) fn reserve(&mut self, runs: usize, steps: std::ops::Range<usize>) {
        self.grow_steps(steps.end);
        if let Some(s) = &mut self.state {
            s.cred.reserve_runs(runs, steps);
        }
    }

    /// Extends the horizon, and every per-step accumulator, to `steps` steps.
    fn grow_steps(&mut self, steps: usize) {
        self.steps = self.steps.max(steps);
        let steps = self.steps;
        if let Some(s) = &mut self.state {
            s.means.extend_steps(steps);
            s.cred.extend_steps(steps);
            s.squared.extend_steps(steps);
        }
        if let Some(s) = &mut self.innovation {
            s.means.extend_steps(steps);
        }
        if let Some(j) = &mut self.j {
            j.j1.extend_steps(steps);
            j.j2.extend_steps(steps);
        }
    }

    /// The first cell of the rectangle never fed, as (run, step).
    fn first_missing(&self) -> Option<(usize, usize)> {
        (0..self.runs).find_map(|run| {
            let bits = &self.seen[run];
            (0..self.steps)
                .find(|&k| bits.get(k / 64).is_none_or(|w| w & (1u64 << (k % 64)) == 0))
                .map(|k| (run, k))
        })
    }

    /// The report of every cell fed, with the times of the steps if logged.
    ///
    /// # Errors
    /// [`EvalError::Empty`] if no cell came; [`EvalError::MissingCell`] for a cell of the
    /// rectangle that never came; [`EvalError::InvalidOption`] for a diagnostic run beyond the
    /// log; [`EvalError::Shape`], [`EvalError::NonFinite`] or
    /// [`EvalError::TimesNotIncreasing`] for bad times; [`EvalError::Metrics`] if a metric
    /// fails on data that passed the checks (not expected).
    pub fn finish(self, times: Option<Vec<f64>>) -> Result<Report, EvalError> {
        if self.runs == 0 {
            return Err(EvalError::Empty { what: "runs" });
        }
        if let Some((run, step)) = self.first_missing() {
            return Err(EvalError::MissingCell {
                run,
                step,
                steps: self.steps,
            });
        }
        if self.options.run >= self.runs {
            return Err(EvalError::InvalidOption {
                name: "diagnostic run",
                value: self.options.run as f64,
            });
        }
        if let Some(t) = &times {
            check_times(t, self.steps)?;
        }
        let (runs, steps) = (self.runs, self.steps);
        let mut report = Report {
            schema_version: SCHEMA_VERSION,
            runs,
            steps: (0..steps).collect(),
            times,
            state_dim: self.contents.state_dim(),
            measurement_dim: self.contents.measurement_dim(),
            confidence: self.options.confidence,
            anees_per_step: Vec::new(),
            anees_band: Vec::new(),
            nees_runs_per_step: Vec::new(),
            anis_per_step: Vec::new(),
            anis_band: Vec::new(),
            nis_runs_per_step: Vec::new(),
            nci_per_step: Vec::new(),
            rmse_per_step: Vec::new(),
            window: None,
            whiteness: None,
            j: None,
            findings: Findings::default(),
            summary: Summary {
                anees: None,
                anis: None,
                nci: None,
                anees_fraction_inside: None,
                anis_fraction_inside: None,
                whiteness_fraction_inside: None,
                anees_test: None,
                anis_test: None,
                verdict: Verdict {
                    kind: VerdictKind::Undetermined,
                    statistic: None,
                    evidence: String::new(),
                    test: String::new(),
                },
            },
        };
        let mut bands = BandCache::new(self.options.confidence);
        let options = &self.options;
        if let Some(side) = self.state {
            let per_run = side.per_run.totals(runs);
            options.state_report(
                side.n,
                (runs, steps),
                &side.means,
                &side.cred,
                &side.squared,
                &per_run,
                side.findings,
                side.window_series,
                &mut bands,
                &mut report,
            )?;
        }
        if let Some(side) = self.innovation {
            let per_run = side.per_run.totals(runs);
            options.innovation_report(
                side.m,
                steps,
                &side.means,
                &per_run,
                side.findings,
                side.normalized,
                &mut bands,
                &mut report,
            )?;
        }
        if let Some(j) = self.j {
            report.j = j.report(steps)?;
        }
        report.summary.verdict =
            crate::evaluate::verdict(&report.summary, options.confidence, &report);
        Ok(report)
    }
}

impl StateSide {
    /// One cell's state side, given its NEES; returns whether its covariance was valid (it
    /// entered NEES).
    fn accept(
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
        self.squared.push_slice(step, &self.error)?;
        if run == options.run {
            self.window_series.push((step, self.error.clone()));
        }
        let n = self.n as f64;
        match nees {
            None => Ok(false),
            Some(Ok(value)) => {
                self.means.push(step, value / n)?;
                self.cred.push_nees(step, &self.error, value)?;
                self.per_run.add(run, step, value / n);
                Ok(true)
            }
            Some(Err(reason)) => {
                self.findings.add("covariance", run, step, reason);
                Ok(false)
            }
        }
    }
}

impl StateSide {
    /// See [`Evaluator::merge`].
    fn merge(&mut self, other: StateSide) {
        self.means.merge(&other.means);
        self.cred.append(other.cred);
        self.squared.merge(&other.squared);
        self.per_run.merge(other.per_run);
        self.findings.merge(other.findings);
        self.window_series.extend(other.window_series);
    }
}

/// Steps per block of the per-run sums ([`PerRun`]).
pub(crate) const RUN_SUM_STEPS: usize = 128;

/// Per run, the sum and count of a normalised statistic (NEES / n, NIS / m) over its steps,
/// for the runs' time averages that the t-test takes. Kept per block of [`RUN_SUM_STEPS`]
/// steps (`step / RUN_SUM_STEPS`) and added block after block by [`PerRun::totals`]: the sums
/// then do not depend on how the steps were cut between evaluators, as long as each block of
/// steps of a run went to one of them, so [`Evaluation::evaluate`] can evaluate blocks of
/// steps in parallel and give the bits of one pass (and of `kalibra eval`'s streaming
/// readers, which make one pass). Memory: one sum and count per run and block, an eighth of
/// a byte per cell.
#[derive(Default)]
struct PerRun {
    /// `[run][block]`: sum and count.
    blocks: Vec<Vec<(f64, usize)>>,
}

impl PerRun {
    #[inline(always)]
    fn add(&mut self, run: usize, step: usize, value: f64) {
        if run >= self.blocks.len() {
            self.blocks.resize_with(run + 1, Vec::new);
        }
        let blocks = &mut self.blocks[run];
        let b = step / RUN_SUM_STEPS;
        if b >= blocks.len() {
            blocks.resize(b + 1, (0.0, 0));
        }
        blocks[b].0 += value;
        blocks[b].1 += 1;
    }

    /// Adds `other`'s sums (each run and block from whichever evaluator saw it).
    fn merge(&mut self, other: PerRun) {
        if other.blocks.len() > self.blocks.len() {
            self.blocks.resize_with(other.blocks.len(), Vec::new);
        }
        for (mine, theirs) in self.blocks.iter_mut().zip(other.blocks) {
            if mine.is_empty() {
                *mine = theirs;
                continue;
            }
            if theirs.len() > mine.len() {
                mine.resize(theirs.len(), (0.0, 0));
            }
            for (a, b) in mine.iter_mut().zip(theirs) {
                a.0 += b.0;
                a.1 += b.1;
            }
        }
    }

    /// Each of `runs` runs' sum and count over its blocks, in block order.
    fn totals(&self, runs: usize) -> Vec<(f64, usize)> {
        let mut totals: Vec<(f64, usize)> = self
            .blocks
            .iter()
            .map(|b| b.iter().fold((0.0, 0), |(s, c), (bs, bc)| (s + bs, c + bc)))
            .collect();
        totals.resize(runs, (0.0, 0));
        totals
    }
}

impl InnovationSide {
    /// One cell's innovation side, given its NIS.
    fn accept(
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
}

impl InnovationSide {
    /// See [`Evaluator::merge`].
    fn merge(&mut self, other: InnovationSide) {
        self.means.merge(&other.means);
        self.per_run.merge(other.per_run);
        self.findings.merge(other.findings);
        self.normalized.extend(other.normalized);
    }
}

impl JSide {
    /// One cell: its covariance if valid, its model matrices if logged (both checked), and
    /// its `J1`/`J2` step if a batch's parallel pass computed it.
    fn push(
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

    fn report(self, steps: usize) -> Result<Option<crate::JReport>, EvalError> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `B B^T + I`, symmetric positive definite, from `k x k` values.
    fn spd(v: &[f64], k: usize) -> DMatrix<f64> {
        let b = DMatrix::from_column_slice(k, k, &v[..k * k]);
        &b * b.transpose() + DMatrix::identity(k, k)
    }

    fn rows(a: &DMatrix<f64>) -> Vec<f64> {
        a.transpose().iter().copied().collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        /// A cell's NEES and NIS are `kalibra_metrics::nees` and `nis` to the bit at every
        /// size, through the fixed-size factorisation (`nees_of`, `nis_of` up to 6) and the
        /// `Dyn` one (every size), for full cells (slightly asymmetric ones too, which NIS
        /// symmetrises), diagonal cells and indefinite ones (the same error).
        #[test]
        fn factor_equals_the_metrics_bit_for_bit(
            dim in 1usize..=8,
            v in proptest::collection::vec(-3.0f64..3.0, 64 + 8),
            skew in proptest::collection::vec(-1e-13f64..1e-13, 64),
            shift in prop_oneof![Just(0.0), -20.0f64..0.0],
        ) {
            let mut p = spd(&v, dim);
            // Below the symmetry tolerance, so a finding only for NEES's exact check if
            // ever; an indefinite matrix when shifted far enough.
            for i in 0..dim {
                p[(i, i)] += shift;
                for j in 0..i {
                    p[(i, j)] += skew[i * 8 + j] * p[(i, j)].abs();
                }
            }
            let x = DVector::from_column_slice(&v[64..64 + dim]);
            let diagonal = DMatrix::from_diagonal(&p.diagonal());
            let (full, diag) = (rows(&p), p.diagonal().as_slice().to_vec());
            let s_full = kalibra_linalg::Covariance::new(p.clone());
            let s_diag = kalibra_linalg::Covariance::new(diagonal.clone());
            let cases = [
                (MatrixCell::Full(&full), &p, s_full),
                (MatrixCell::Diagonal(&diag), &diagonal, s_diag),
            ];
            for (cell, matrix, s) in cases {
                let mut fast = Factor::new(dim);
                let mut slow = Factor::new(dim);
                let want = kalibra_metrics::nees(&x, matrix).map(f64::to_bits);
                let got = fast.nees_of(cell, x.as_slice(), "P").map(f64::to_bits);
                slow.load(cell);
                let dynamic = slow.nees(x.as_slice(), "P").map(f64::to_bits);
                // Errors compare by kind (the metrics name the matrix differently).
                let kind = |e: LinalgError| std::mem::discriminant(&e);
                let want = want.map_err(|e| match e {
                    MetricsError::Linalg(e) => Some(kind(e)),
                    _ => None,
                });
                prop_assert_eq!(&got.map_err(|e| Some(kind(e))), &want);
                prop_assert_eq!(&dynamic.map_err(|e| Some(kind(e))), &want);
                let want = s
                    .map_err(kalibra_metrics::MetricsError::from)
                    .and_then(|s| kalibra_metrics::nis(&x, &s))
                    .map(f64::to_bits);
                let got = fast.nis_of(cell, x.as_slice(), "S").map(f64::to_bits);
                slow.load(cell);
                let dynamic = slow.nis(x.as_slice(), "S").map(f64::to_bits);
                prop_assert_eq!(got.is_ok(), want.is_ok());
                prop_assert_eq!(dynamic.is_ok(), want.is_ok());
                if let (Ok(a), Ok(b), Ok(c)) = (got, dynamic, want) {
                    prop_assert_eq!(a, c);
                    prop_assert_eq!(b, c);
                    // The normalised innovation, which whiteness takes, to the bit too.
                    let wa: Vec<u64> = fast.w.iter().map(|v| v.to_bits()).collect();
                    let wb: Vec<u64> = slow.w.iter().map(|v| v.to_bits()).collect();
                    prop_assert_eq!(wa, wb);
                }
            }
        }

        /// The fixed-size `J1`/`J2` step gives the `Dyn` path's values to the bit, at every
        /// size it covers.
        #[test]
        fn fixed_size_j_equals_the_dyn_path_bit_for_bit(
            m in 1usize..=4,
            n in 1usize..=6,
            v in proptest::collection::vec(-2.0f64..2.0, 5 * 36 + 24),
        ) {
            let f = DMatrix::from_column_slice(n, n, &v[..n * n]);
            let h = DMatrix::from_column_slice(m, n, &v[36..36 + m * n]);
            let q = spd(&v[60..], n);
            let r = spd(&v[96..], m);
            let p0 = spd(&v[112..], n);
            let p1 = spd(&v[148..], n);
            let (fr, hr, qr, rr) = (rows(&f), rows(&h), rows(&q), rows(&r));
            let cell = ModelCell { f: &fr, h: &hr, q: &qr, r: &rr };
            let jm = JModel::new(&cell, (n, m));
            prop_assert!(jm.is(&cell));
            let fixed = j_fixed(&jm, &p0, &p1).expect("a covered size");
            let a: DMatrix<f64> = &jm.hf * &p0 * &jm.hft;
            let c: DMatrix<f64> = &jm.h * &p1 * &jm.ht;
            let dynamic = j_step(&a, &jm.b, &jm.r, &c);
            match (fixed, dynamic) {
                (Ok(x), Ok(y)) => {
                    for (p, q) in [(x.j1, y.j1), (x.j2, y.j2), (x.tr_n, y.tr_n), (x.tr_b, y.tr_b)] {
                        prop_assert_eq!(p.to_bits(), q.to_bits());
                    }
                    prop_assert_eq!(x.a_plus_b_definite, y.a_plus_b_definite);
                }
                (Err(_), Err(_)) => {}
                (x, y) => prop_assert!(false, "fixed {x:?}, dyn {y:?}"),
            }
        }
    }
}
