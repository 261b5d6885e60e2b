//! What an [`Evaluator`](super::Evaluator) is fed: the borrowed cell types ([`Cell`],
//! [`MatrixCell`], [`ModelCell`]), what a log holds ([`Contents`]), and the checks of a cell's
//! lengths and values.

use kalibra_linalg::DMatrix;

use crate::EvalError;

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
    pub(super) fn check(&self) -> Result<(), EvalError> {
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

/// Checks a vector cell's length.
pub(super) fn vector<'a>(
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
pub(super) fn square<'a>(
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

/// Copies a cell's `dim x dim` matrix into `out`, reusing its storage.
pub(super) fn fill(out: &mut DMatrix<f64>, dim: usize, cell: MatrixCell<'_>) {
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
pub(super) fn check_model(
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
