//! A filter log held as arrays: `R` runs by `K` steps, each cell optional.

use std::borrow::Cow;

use rayon::prelude::*;

use crate::EvalError;
use crate::stream::{Cell, Contents, MatrixCell, ModelCell};

/// Vectors per run and step, not yet checked against a log (see [`FilterLog`]).
///
/// Values are in run-major order: run 0's steps `0..K`, then run 1's, and so on, each cell's
/// `dim` values together (numpy's C order for an array of shape `(R, K, dim)`).
///
/// The values are owned (a `Vec<f64>`) or borrowed (a `&[f64]`, read in place: the Python
/// package reads numpy's memory this way), hence the lifetime `'a` (`'static` when owned).
#[derive(Clone, Debug, PartialEq)]
pub struct Vectors<'a> {
    dim: usize,
    data: CellData<'a>,
}

#[derive(Clone, Debug, PartialEq)]
enum CellData<'a> {
    /// Every cell's values; with `nan_unlogged`, a cell whose values are all NaN was not
    /// logged (decided as each cell is read, so no pass over the values is needed up front).
    Dense {
        values: Cow<'a, [f64]>,
        nan_unlogged: bool,
    },
    Cells(Vec<Option<Vec<f64>>>),
}

impl<'a> CellData<'a> {
    fn dense(values: impl Into<Cow<'a, [f64]>>) -> Self {
        CellData::Dense {
            values: values.into(),
            nan_unlogged: false,
        }
    }
}

impl<'a> Vectors<'a> {
    /// Every cell present: `R K dim` values, owned (`Vec<f64>`) or borrowed (`&[f64]`).
    pub fn dense(dim: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self {
            dim,
            data: CellData::Dense {
                values: data.into(),
                nan_unlogged: false,
            },
        }
    }

    /// `R K dim` values, where a cell whose values are all NaN was not logged (the rule of
    /// numpy arrays, `.npz` logs and the Python package); a cell only partly NaN is logged.
    /// Nothing is scanned here: each cell is looked at as it is read.
    pub fn nan_unlogged(dim: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self {
            dim,
            data: CellData::Dense {
                values: data.into(),
                nan_unlogged: true,
            },
        }
    }

    /// One entry per cell (`R K` of them), `None` where the value was not logged.
    pub fn cells(dim: usize, cells: Vec<Option<Vec<f64>>>) -> Self {
        Self {
            dim,
            data: CellData::Cells(cells),
        }
    }
}

/// How a matrix array's cells are shared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scope {
    /// One matrix for every run and step.
    Constant,
    /// One matrix per step, the same for every run.
    PerStep,
    /// One matrix per run and step.
    PerRunStep,
}

/// How a matrix is stored in its cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Layout {
    /// `rows x cols` values, row by row (numpy's C order).
    Full,
    /// The diagonal alone (`rows` values) of a square matrix whose other entries are 0.
    Diagonal,
}

/// Matrices per run and step, per step, or one for all, not yet checked against a log (see
/// [`FilterLog`]). Full matrices are given row by row (numpy's C order), so an array of shape
/// `(R, K, rows, cols)` passes its buffer as it is, owned or borrowed (as [`Vectors`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Matrices<'a> {
    rows: usize,
    cols: usize,
    scope: Scope,
    layout: Layout,
    data: CellData<'a>,
}

impl<'a> Matrices<'a> {
    /// One `rows x cols` matrix per run and step, every cell present: `R K rows cols` values.
    pub fn dense(rows: usize, cols: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self::full(Scope::PerRunStep, rows, cols, CellData::dense(data))
    }

    /// One `rows x cols` matrix per run and step, `R K rows cols` values, where a cell whose
    /// values are all NaN was not logged (as [`Vectors::nan_unlogged`]).
    pub fn nan_unlogged(rows: usize, cols: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self::full(
            Scope::PerRunStep,
            rows,
            cols,
            CellData::Dense {
                values: data.into(),
                nan_unlogged: true,
            },
        )
    }

    /// The diagonals alone of `dim x dim` matrices per run and step (a log that records
    /// variances only): `R K dim` values.
    pub fn diagonal(dim: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self {
            rows: dim,
            cols: dim,
            scope: Scope::PerRunStep,
            layout: Layout::Diagonal,
            data: CellData::dense(data),
        }
    }

    /// One entry per run and step (`R K`), each `rows cols` values or `None` where the matrix
    /// was not logged.
    pub fn cells(rows: usize, cols: usize, cells: Vec<Option<Vec<f64>>>) -> Self {
        Self::full(Scope::PerRunStep, rows, cols, CellData::Cells(cells))
    }

    /// The diagonals alone, one entry per run and step, `None` where not logged.
    pub fn diagonal_cells(dim: usize, cells: Vec<Option<Vec<f64>>>) -> Self {
        Self {
            rows: dim,
            cols: dim,
            scope: Scope::PerRunStep,
            layout: Layout::Diagonal,
            data: CellData::Cells(cells),
        }
    }

    /// One matrix per step, shared by every run: `K rows cols` values.
    pub fn per_step(rows: usize, cols: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self::full(Scope::PerStep, rows, cols, CellData::dense(data))
    }

    /// One matrix for every run and step: `rows cols` values.
    pub fn constant(rows: usize, cols: usize, data: impl Into<Cow<'a, [f64]>>) -> Self {
        Self::full(Scope::Constant, rows, cols, CellData::dense(data))
    }

    /// How the cells are shared.
    pub fn scope(&self) -> Scope {
        self.scope
    }

    fn full(scope: Scope, rows: usize, cols: usize, data: CellData<'a>) -> Self {
        Self {
            rows,
            cols,
            scope,
            layout: Layout::Full,
            data,
        }
    }
}

/// Checked, flat storage of one array: values, owned or borrowed, and which cells are
/// present.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Array<'a> {
    pub(crate) rows: usize,
    pub(crate) cols: usize,
    scope: Scope,
    layout: Layout,
    /// Values per cell (`rows cols` for full matrices and vectors, `rows` for diagonals).
    width: usize,
    data: Cow<'a, [f64]>,
    /// A flag per cell; `None` when every cell is present, or decided by `nan_unlogged`.
    present: Option<Vec<bool>>,
    /// A cell whose values are all NaN is absent.
    nan_unlogged: bool,
    steps: usize,
}

/// The largest row or column count of a logged array: a state of 65536 components is far
/// beyond any filter whose covariances are logged, and the check keeps a dimension from data
/// from sizing an allocation.
pub const MAX_DIM: usize = 1 << 16;

impl<'a> Array<'a> {
    fn check(
        array: &'static str,
        (runs, steps): (usize, usize),
        rows: usize,
        cols: usize,
        scope: Scope,
        layout: Layout,
        data: CellData<'a>,
    ) -> Result<Self, EvalError> {
        if rows == 0 || cols == 0 {
            return Err(EvalError::Empty {
                what: "an array's dimension",
            });
        }
        // Checked before any product is formed or anything allocated: a dimension from data
        // may be `usize::MAX` (`tests/extreme_sizes.rs`).
        for (what, dim) in [("array row", rows), ("array column", cols)] {
            if dim > MAX_DIM {
                return Err(EvalError::IndexLimit {
                    what,
                    index: dim - 1,
                    limit: MAX_DIM,
                });
            }
        }
        let cells = match scope {
            Scope::Constant => 1,
            Scope::PerStep => steps,
            // Within MAX_RUNS x MAX_STEPS (`FilterLog::new`): no overflow.
            Scope::PerRunStep => runs * steps,
        };
        let width = match layout {
            Layout::Full => rows * cols,
            Layout::Diagonal => rows,
        };
        let Some(total) = cells.checked_mul(width) else {
            return Err(EvalError::IndexLimit {
                what: "array value",
                index: usize::MAX,
                limit: usize::MAX,
            });
        };
        let (data, present, nan_unlogged) = match data {
            CellData::Dense {
                values,
                nan_unlogged,
            } => {
                if values.len() != total {
                    return Err(EvalError::Shape {
                        array,
                        unit: "values",
                        expected: total,
                        found: values.len(),
                    });
                }
                (values, None, nan_unlogged)
            }
            CellData::Cells(list) => {
                if list.len() != cells {
                    return Err(EvalError::Shape {
                        array,
                        unit: "cells",
                        expected: cells,
                        found: list.len(),
                    });
                }
                // The cells' lengths first: `width` is checked against data in memory before
                // `cells * width` values are allocated.
                for (i, cell) in list.iter().enumerate() {
                    if let Some(values) = cell
                        && values.len() != width
                    {
                        let (run, step) = position(scope, steps, i);
                        return Err(EvalError::CellLength {
                            array,
                            run,
                            step,
                            expected: width,
                            found: values.len(),
                        });
                    }
                }
                let mut data = vec![f64::NAN; total];
                let mut present = vec![false; cells];
                for (i, cell) in list.into_iter().enumerate() {
                    if let Some(values) = cell {
                        if values.len() != width {
                            let (run, step) = position(scope, steps, i);
                            return Err(EvalError::CellLength {
                                array,
                                run,
                                step,
                                expected: width,
                                found: values.len(),
                            });
                        }
                        data[i * width..(i + 1) * width].copy_from_slice(&values);
                        present[i] = true;
                    }
                }
                (Cow::Owned(data), Some(present), false)
            }
        };
        Ok(Self {
            rows,
            cols,
            scope,
            layout,
            width,
            data,
            present,
            nan_unlogged,
            steps,
        })
    }

    #[inline]
    fn index(&self, run: usize, step: usize) -> usize {
        match self.scope {
            Scope::Constant => 0,
            Scope::PerStep => step,
            Scope::PerRunStep => run * self.steps + step,
        }
    }

    #[inline]
    fn slice(&self, run: usize, step: usize) -> Option<&[f64]> {
        self.cell_at(self.index(run, step))
    }

    /// The values of cell `i` (in storage order), if present.
    #[inline]
    fn cell_at(&self, i: usize) -> Option<&[f64]> {
        if self.present.as_ref().is_some_and(|p| !p[i]) {
            return None;
        }
        let values = &self.data[i * self.width..(i + 1) * self.width];
        // The first value decides for almost every cell: a logged one is rarely NaN there.
        if self.nan_unlogged && values[0].is_nan() && values.iter().all(|v| v.is_nan()) {
            return None;
        }
        Some(values)
    }

    /// The cell at (run, step) as a matrix cell, if logged.
    #[inline]
    fn matrix_cell(&self, run: usize, step: usize) -> Option<MatrixCell<'_>> {
        self.slice(run, step).map(|v| match self.layout {
            Layout::Full => MatrixCell::Full(v),
            Layout::Diagonal => MatrixCell::Diagonal(v),
        })
    }

    /// The first present cell holding a non-finite value, as (run, step). A large array is
    /// scanned on every core (the first in storage order is found whatever the threads).
    fn first_non_finite(&self) -> Option<(usize, usize)> {
        let cells = self.data.len() / self.width;
        let bad = |i: usize| {
            self.cell_at(i)
                .is_some_and(|v| !v.iter().all(|x| x.is_finite()))
        };
        (0..cells)
            .into_par_iter()
            .with_min_len(1 << 14)
            .position_first(bad)
            .map(|i| position(self.scope, self.steps, i))
    }

    fn require_finite(self, array: &'static str) -> Result<Self, EvalError> {
        match self.first_non_finite() {
            Some((run, step)) => Err(EvalError::NonFinite { array, run, step }),
            None => Ok(self),
        }
    }
}

fn position(scope: Scope, steps: usize, i: usize) -> (usize, usize) {
    match scope {
        Scope::Constant => (0, 0),
        Scope::PerStep => (0, i),
        Scope::PerRunStep => (i / steps, i % steps),
    }
}

/// Checks the times of `steps` steps: as many, finite, strictly increasing.
pub(crate) fn check_times(times: &[f64], steps: usize) -> Result<(), EvalError> {
    if times.len() != steps {
        return Err(EvalError::Shape {
            array: "time",
            unit: "values",
            expected: steps,
            found: times.len(),
        });
    }
    if let Some(step) = times.iter().position(|t| !t.is_finite()) {
        return Err(EvalError::NonFinite {
            array: "time",
            run: 0,
            step,
        });
    }
    if let Some(step) = (1..times.len()).find(|&k| times[k] <= times[k - 1]) {
        return Err(EvalError::TimesNotIncreasing { step });
    }
    Ok(())
}

/// The model matrices of a linear(ised) filter, for `J1`/`J2`: `F[k]` and `Q[k]` are those of
/// the prediction from step `k - 1` to step `k`, `H[k]` and `R[k]` those of the update at step
/// `k` (so `F[0]` and `Q[0]` are never used).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Model<'a> {
    pub(crate) f: Array<'a>,
    pub(crate) h: Array<'a>,
    pub(crate) q: Array<'a>,
    pub(crate) r: Array<'a>,
}

/// A filter's log as arrays: `R` runs of `K` steps, and per run and step an optional truth and
/// estimate (`n`), covariance (`n x n` or its diagonal), innovation (`m`) and innovation
/// covariance (`m x m`); optionally the times of the steps and the model matrices `F`, `H`,
/// `Q`, `R` (for `J1`/`J2`, with the posterior covariance).
///
/// Built by [`FilterLog::new`] and the `with_*` methods, each of which checks its array against
/// the log (number of cells, length of each cell, dimensions shared with the arrays already
/// given) and returns an [`EvalError`] naming the array, and the run and step where one cell is
/// at fault. A cell that is `None` was not logged at that step.
///
/// The truth, the times and the model matrices must be finite (else an error). Estimates,
/// covariances and innovations may hold anything: a NaN, asymmetric or indefinite covariance
/// is a finding about the filter, which the evaluation counts and leaves out
/// ([`crate::Findings`]).
///
/// ```
/// use kalibra_eval::{FilterLog, Matrices, Vectors};
/// // One run of two steps of a scalar state.
/// let log = FilterLog::new(1, 2)?
///     .with_truth(Vectors::dense(1, vec![0.0, 1.0]))?
///     .with_estimate(Vectors::cells(1, vec![Some(vec![0.1]), None]))?
///     .with_covariance(Matrices::diagonal(1, vec![0.04, 0.04]))?;
/// assert_eq!((log.runs(), log.steps(), log.state_dim()), (1, 2, Some(1)));
/// assert!(FilterLog::new(1, 2)?.with_truth(Vectors::dense(2, vec![0.0; 3])).is_err());
/// # Ok::<(), kalibra_eval::EvalError>(())
/// ```
///
/// The arrays' values are owned or borrowed ([`Vectors::dense`] takes a `Vec<f64>` or a
/// `&[f64]`): a log of borrowed arrays, `FilterLog<'a>`, reads them in place; one of owned
/// arrays is a `FilterLog<'static>`.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterLog<'a> {
    runs: usize,
    steps: usize,
    pub(crate) times: Option<Vec<f64>>,
    pub(crate) truth: Option<Array<'a>>,
    pub(crate) estimate: Option<Array<'a>>,
    pub(crate) covariance: Option<Array<'a>>,
    pub(crate) innovation: Option<Array<'a>>,
    pub(crate) innovation_cov: Option<Array<'a>>,
    pub(crate) model: Option<Model<'a>>,
}

impl<'a> FilterLog<'a> {
    /// An empty log of `runs` runs and `steps` steps.
    ///
    /// # Errors
    /// [`EvalError::Empty`] for zero runs or steps; [`EvalError::IndexLimit`] for more than
    /// [`MAX_RUNS`](crate::MAX_RUNS) runs or [`MAX_STEPS`](crate::MAX_STEPS) steps, which no
    /// evaluation takes.
    pub fn new(runs: usize, steps: usize) -> Result<Self, EvalError> {
        if runs == 0 {
            return Err(EvalError::Empty { what: "runs" });
        }
        if steps == 0 {
            return Err(EvalError::Empty { what: "steps" });
        }
        for (what, count, limit) in [
            ("run", runs, crate::MAX_RUNS),
            ("step", steps, crate::MAX_STEPS),
        ] {
            if count > limit {
                return Err(EvalError::IndexLimit {
                    what,
                    index: count - 1,
                    limit,
                });
            }
        }
        Ok(Self {
            runs,
            steps,
            times: None,
            truth: None,
            estimate: None,
            covariance: None,
            innovation: None,
            innovation_cov: None,
            model: None,
        })
    }

    /// Number of runs `R`.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// Number of steps `K`.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The state dimension `n`, once an array of the state is given.
    pub fn state_dim(&self) -> Option<usize> {
        [&self.truth, &self.estimate, &self.covariance]
            .into_iter()
            .flatten()
            .map(|a| a.rows)
            .next()
            .or_else(|| self.model.as_ref().map(|m| m.f.rows))
    }

    /// The measurement dimension `m`, once an array of the innovations is given.
    pub fn measurement_dim(&self) -> Option<usize> {
        [&self.innovation, &self.innovation_cov]
            .into_iter()
            .flatten()
            .map(|a| a.rows)
            .next()
            .or_else(|| self.model.as_ref().map(|m| m.h.rows))
    }

    /// The times of the steps, if given.
    pub fn times(&self) -> Option<&[f64]> {
        self.times.as_deref()
    }

    /// Which arrays the log holds, as an [`crate::Evaluator`] is told them.
    pub fn contents(&self) -> Contents {
        let dim = |a: &Option<Array<'_>>| a.as_ref().map(|a| a.rows);
        Contents {
            truth: dim(&self.truth),
            estimate: dim(&self.estimate),
            covariance: dim(&self.covariance),
            innovation: dim(&self.innovation),
            innovation_cov: dim(&self.innovation_cov),
            model: self.model.as_ref().map(|m| (m.f.rows, m.h.rows)),
        }
    }

    /// The cell of `run` and `step`, borrowed (every array `None` beyond the log).
    pub fn cell(&self, run: usize, step: usize) -> Cell<'_> {
        if run >= self.runs || step >= self.steps {
            return Cell::default();
        }
        #[inline(always)]
        fn vector<'s>(a: &'s Option<Array<'_>>, run: usize, step: usize) -> Option<&'s [f64]> {
            a.as_ref().and_then(|a| a.slice(run, step))
        }
        #[inline(always)]
        fn matrix<'s>(a: &'s Option<Array<'_>>, run: usize, step: usize) -> Option<MatrixCell<'s>> {
            a.as_ref().and_then(|a| a.matrix_cell(run, step))
        }
        let model = self.model.as_ref().and_then(|m| {
            Some(ModelCell {
                f: m.f.slice(run, step)?,
                h: m.h.slice(run, step)?,
                q: m.q.slice(run, step)?,
                r: m.r.slice(run, step)?,
            })
        });
        Cell {
            truth: vector(&self.truth, run, step),
            estimate: vector(&self.estimate, run, step),
            covariance: matrix(&self.covariance, run, step),
            innovation: vector(&self.innovation, run, step),
            innovation_cov: matrix(&self.innovation_cov, run, step),
            model,
        }
    }

    fn vectors(&self, array: &'static str, v: Vectors<'a>) -> Result<Array<'a>, EvalError> {
        Array::check(
            array,
            (self.runs, self.steps),
            v.dim,
            1,
            Scope::PerRunStep,
            Layout::Full,
            v.data,
        )
    }

    fn matrices(&self, array: &'static str, m: Matrices<'a>) -> Result<Array<'a>, EvalError> {
        Array::check(
            array,
            (self.runs, self.steps),
            m.rows,
            m.cols,
            m.scope,
            m.layout,
            m.data,
        )
    }

    fn same(
        array: &'static str,
        what: &'static str,
        expected: Option<usize>,
        found: usize,
    ) -> Result<(), EvalError> {
        match expected {
            Some(expected) if expected != found => Err(EvalError::Mismatch {
                array,
                what,
                expected,
                found,
            }),
            _ => Ok(()),
        }
    }

    fn square(array: &'static str, a: &Array<'_>) -> Result<(), EvalError> {
        Self::same(array, "columns (a square matrix)", Some(a.rows), a.cols)
    }

    /// The times of the `K` steps.
    ///
    /// # Errors
    /// [`EvalError::Shape`] for a length other than `K`, [`EvalError::NonFinite`] or
    /// [`EvalError::TimesNotIncreasing`] for bad values.
    pub fn with_times(mut self, times: Vec<f64>) -> Result<Self, EvalError> {
        check_times(&times, self.steps)?;
        self.times = Some(times);
        Ok(self)
    }

    /// The true states (`n` per cell; must be finite).
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::Mismatch`] (a state
    /// dimension other than the log's), [`EvalError::NonFinite`].
    pub fn with_truth(mut self, truth: Vectors<'a>) -> Result<Self, EvalError> {
        let a = self.vectors("truth", truth)?.require_finite("truth")?;
        Self::same("truth", "state dimension", self.state_dim(), a.rows)?;
        self.truth = Some(a);
        Ok(self)
    }

    /// The filter's estimates (`n` per cell).
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::Mismatch`].
    pub fn with_estimate(mut self, estimate: Vectors<'a>) -> Result<Self, EvalError> {
        let a = self.vectors("estimate", estimate)?;
        Self::same("estimate", "state dimension", self.state_dim(), a.rows)?;
        self.estimate = Some(a);
        Ok(self)
    }

    /// The filter's (posterior) covariances, `n x n` or diagonals.
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::Mismatch`] (not square,
    /// or a state dimension other than the log's).
    pub fn with_covariance(mut self, covariance: Matrices<'a>) -> Result<Self, EvalError> {
        let a = self.matrices("covariance", covariance)?;
        Self::square("covariance", &a)?;
        Self::same("covariance", "state dimension", self.state_dim(), a.rows)?;
        self.covariance = Some(a);
        Ok(self)
    }

    /// The innovations (`m` per cell).
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::Mismatch`].
    pub fn with_innovation(mut self, innovation: Vectors<'a>) -> Result<Self, EvalError> {
        let a = self.vectors("innovation", innovation)?;
        Self::same(
            "innovation",
            "measurement dimension",
            self.measurement_dim(),
            a.rows,
        )?;
        self.innovation = Some(a);
        Ok(self)
    }

    /// The innovation covariances `S`, `m x m` or diagonals.
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::Mismatch`].
    pub fn with_innovation_cov(mut self, s: Matrices<'a>) -> Result<Self, EvalError> {
        let a = self.matrices("innovation_cov", s)?;
        Self::square("innovation_cov", &a)?;
        Self::same(
            "innovation_cov",
            "measurement dimension",
            self.measurement_dim(),
            a.rows,
        )?;
        self.innovation_cov = Some(a);
        Ok(self)
    }

    /// The model matrices for `J1`/`J2`: `F` (`n x n`) and `Q` (`n x n`) of the prediction
    /// into step `k`, `H` (`m x n`) and `R` (`m x m`) of the update at step `k`; each may be
    /// constant, per step, or per run and step ([`Matrices`]), and must be finite. `J1`/`J2`
    /// also need the posterior [`FilterLog::with_covariance`].
    ///
    /// # Errors
    /// [`EvalError::Shape`], [`EvalError::CellLength`], [`EvalError::NonFinite`], and
    /// [`EvalError::Mismatch`] for sizes that disagree with each other or with the log.
    pub fn with_model(
        mut self,
        f: Matrices<'a>,
        h: Matrices<'a>,
        q: Matrices<'a>,
        r: Matrices<'a>,
    ) -> Result<Self, EvalError> {
        let f = self.matrices("F", f)?.require_finite("F")?;
        let h = self.matrices("H", h)?.require_finite("H")?;
        let q = self.matrices("Q", q)?.require_finite("Q")?;
        let r = self.matrices("R", r)?.require_finite("R")?;
        Self::square("F", &f)?;
        Self::square("Q", &q)?;
        Self::square("R", &r)?;
        let n = f.rows;
        Self::same("F", "state dimension", self.state_dim(), n)?;
        Self::same("Q", "state dimension", Some(n), q.rows)?;
        Self::same("H", "columns (state dimension)", Some(n), h.cols)?;
        Self::same("H", "measurement dimension", self.measurement_dim(), h.rows)?;
        Self::same("R", "measurement dimension", Some(h.rows), r.rows)?;
        self.model = Some(Model { f, h, q, r });
        Ok(self)
    }
}
