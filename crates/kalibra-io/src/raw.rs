//! What the log readers produce before `kalibra_eval` checks it: the arrays' names, their
//! cells and shapes, and the rules all the array formats share (the shape of a per-cell
//! array, the model arrays given together). The bottom of the readers: it imports only the
//! error.

use std::borrow::Cow;

use kalibra_eval::{FilterLog, Matrices, Scope, Vectors};

use crate::error::Error;

/// The arrays a log may hold, by name, in every format (CSV columns aside): the NPZ archive's
/// and the JSON object's entries, and the Python package's keyword arguments.
pub const ARRAY_NAMES: [&str; 10] = [
    "truth",
    "estimate",
    "covariance",
    "innovation",
    "innovation_cov",
    "time",
    "F",
    "H",
    "Q",
    "R",
];

/// [`ARRAY_NAMES`] as the error messages list them (a test keeps the two equal).
pub(crate) const KNOWN: &str =
    "truth, estimate, covariance, innovation, innovation_cov, time, F, H, Q, R";

/// The per-cell arrays, in the order the readers take them.
pub(crate) const PER_CELL: [&str; 5] = [
    "truth",
    "estimate",
    "covariance",
    "innovation",
    "innovation_cov",
];

/// The model arrays, in the order `FilterLog::with_model` takes them.
pub(crate) const MODEL: [&str; 4] = ["F", "H", "Q", "R"];

/// The error of a log without any per-cell array.
pub(crate) fn no_per_cell_array() -> Error {
    Error::log("the log holds none of truth, estimate, covariance, innovation, innovation_cov")
}

/// The cells of an array as read, in run-major order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum CellValues<'a> {
    /// One entry per cell, `None` where not logged.
    Sparse(Vec<Option<Vec<f64>>>),
    /// Every cell's values in one buffer, owned or borrowed, a cell of all NaN not logged:
    /// arrays handed over whole (`log_from_arrays`), read in place and never scanned up front
    /// (the evaluation looks at each cell as it reads it).
    NanUnlogged(Cow<'a, [f64]>),
}

impl From<Vec<Option<Vec<f64>>>> for CellValues<'_> {
    fn from(cells: Vec<Option<Vec<f64>>>) -> Self {
        Self::Sparse(cells)
    }
}

/// One array of vectors: `dim` values per cell.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct VectorArray<'a> {
    pub dim: usize,
    pub cells: CellValues<'a>,
}

/// One array of square matrices per run and step: full (`dim * dim` values, row by row) or
/// diagonal (`dim` values).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MatrixArray<'a> {
    pub dim: usize,
    pub diagonal: bool,
    pub cells: CellValues<'a>,
}

/// A model matrix array: constant, per step or per run and step, every cell present.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ModelArray {
    pub rows: usize,
    pub cols: usize,
    pub scope: Scope,
    pub data: Vec<f64>,
}

impl ModelArray {
    /// The model array `name` of shape `shape` in a log of `runs` runs of `steps` steps: one
    /// matrix, one per step or one per run and step.
    pub(crate) fn of_shape(
        name: &str,
        shape: &[usize],
        data: Vec<f64>,
        (runs, steps): (usize, usize),
    ) -> Result<Self, Error> {
        let (scope, rows, cols) = match shape {
            [r, c] => (Scope::Constant, *r, *c),
            [k, r, c] if *k == steps => (Scope::PerStep, *r, *c),
            [rr, k, r, c] if (*rr, *k) == (runs, steps) => (Scope::PerRunStep, *r, *c),
            other => {
                return Err(Error::array(
                    name,
                    format!(
                        "array {name} has shape {other:?}; expected one matrix (rows, cols), \
                         one per step ({steps}, rows, cols) or one per run and step ({runs}, \
                         {steps}, rows, cols)"
                    ),
                ));
            }
        };
        Ok(Self {
            rows,
            cols,
            scope,
            data,
        })
    }

    pub(crate) fn matrices(self) -> Matrices<'static> {
        match self.scope {
            Scope::Constant => Matrices::constant(self.rows, self.cols, self.data),
            Scope::PerStep => Matrices::per_step(self.rows, self.cols, self.data),
            Scope::PerRunStep => Matrices::dense(self.rows, self.cols, self.data),
        }
    }

    /// The matrix of `run` and `step` of a log of `steps` steps, row by row.
    pub(crate) fn cell(&self, run: usize, step: usize, steps: usize) -> &[f64] {
        let size = self.rows * self.cols;
        let index = match self.scope {
            Scope::Constant => 0,
            Scope::PerStep => step,
            Scope::PerRunStep => run * steps + step,
        };
        &self.data[index * size..(index + 1) * size]
    }
}

/// Whether the model arrays `F`, `H`, `Q`, `R` are given; all four go together, so a log
/// with only some of them (`present`) is an error naming one that is missing.
pub(crate) fn model_given(present: &[&str]) -> Result<bool, Error> {
    if present.is_empty() {
        return Ok(false);
    }
    match MODEL.iter().find(|m| !present.contains(m)) {
        Some(missing) => Err(Error::array(
            *missing,
            format!(
                "arrays F, H, Q and R go together (for J1/J2); the log has {} but not {missing}",
                present.join(", ")
            ),
        )),
        None => Ok(true),
    }
}

/// The runs, steps and cell shape of a per-cell array with `cell_dims` trailing dimensions;
/// a single run may drop the leading R axis. The NPZ reader and arrays handed over whole
/// share it, so both read an array the same way.
pub(crate) fn cell_shape(
    array: &str,
    shape: &[usize],
    cell_dims: usize,
) -> Result<(usize, usize, Vec<usize>), Error> {
    let (runs, rest) = match shape.len() - cell_dims.min(shape.len()) {
        2 => (shape[0], &shape[1..]),
        1 => (1, shape),
        _ => {
            let expected = if cell_dims == 1 {
                "(R, K, dim) or (K, dim)"
            } else {
                "(R, K, dim, dim) or (K, dim, dim)"
            };
            return Err(Error::array(
                array,
                format!("array {array} has shape {shape:?}; expected {expected}"),
            ));
        }
    };
    Ok((runs, rest[0], rest[1..].to_vec()))
}

/// What a reader found, before `kalibra_eval` checks it.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct RawLog<'a> {
    pub runs: usize,
    pub steps: usize,
    pub time: Option<Vec<f64>>,
    pub truth: Option<VectorArray<'a>>,
    pub estimate: Option<VectorArray<'a>>,
    pub covariance: Option<MatrixArray<'a>>,
    pub innovation: Option<VectorArray<'a>>,
    pub innovation_cov: Option<MatrixArray<'a>>,
    /// `F`, `H`, `Q`, `R`.
    pub model: Option<[ModelArray; 4]>,
    /// The per-cell array that fixed `runs` and `steps` (for the error when another disagrees).
    pub shape_from: Option<&'static str>,
}

fn matrices(m: MatrixArray<'_>) -> Matrices<'_> {
    match (m.cells, m.diagonal) {
        (CellValues::Sparse(cells), true) => Matrices::diagonal_cells(m.dim, cells),
        (CellValues::Sparse(cells), false) => Matrices::cells(m.dim, m.dim, cells),
        // Only `log_from_arrays` gives these, and numpy's arrays hold full matrices.
        (CellValues::NanUnlogged(data), _) => Matrices::nan_unlogged(m.dim, m.dim, data),
    }
}

fn vectors(v: VectorArray<'_>) -> Vectors<'_> {
    match v.cells {
        CellValues::Sparse(cells) => Vectors::cells(v.dim, cells),
        CellValues::NanUnlogged(data) => Vectors::nan_unlogged(v.dim, data),
    }
}

impl<'a> RawLog<'a> {
    /// Stores the per-cell array `array` (one of [`PER_CELL`]) of `runs x steps` cells of
    /// `rows x cols` values (`cols` is ignored for vectors). The first such array fixes the
    /// runs and steps; another that disagrees, or a non-square covariance, is an error.
    pub fn put_cells(
        &mut self,
        array: &'static str,
        (runs, steps): (usize, usize),
        (rows, cols): (usize, usize),
        cells: CellValues<'a>,
    ) -> Result<(), Error> {
        match self.shape_from {
            None => {
                self.shape_from = Some(array);
                (self.runs, self.steps) = (runs, steps);
            }
            Some(first) if (self.runs, self.steps) != (runs, steps) => {
                return Err(Error::array(
                    array,
                    format!(
                        "array {array} has {runs} runs of {steps} steps, but array {first} has \
                         {} runs of {} steps",
                        self.runs, self.steps
                    ),
                ));
            }
            Some(_) => {}
        }
        let matrix = |cells| {
            if rows == cols {
                Ok(MatrixArray {
                    dim: rows,
                    diagonal: false,
                    cells,
                })
            } else {
                Err(Error::array(
                    array,
                    format!("array {array} holds {rows}x{cols} matrices; a covariance is square"),
                ))
            }
        };
        let vector = |cells| VectorArray { dim: rows, cells };
        match array {
            "covariance" => self.covariance = Some(matrix(cells)?),
            "innovation_cov" => self.innovation_cov = Some(matrix(cells)?),
            "truth" => self.truth = Some(vector(cells)),
            "estimate" => self.estimate = Some(vector(cells)),
            _ => self.innovation = Some(vector(cells)),
        }
        Ok(())
    }

    /// The runs and steps, or the error of a log without any per-cell array.
    pub fn require_cells(&self) -> Result<(usize, usize), Error> {
        match self.shape_from {
            Some(_) => Ok((self.runs, self.steps)),
            None => Err(no_per_cell_array()),
        }
    }

    /// The checked log; an error names the array at fault.
    pub fn checked(self) -> Result<FilterLog<'a>, Error> {
        self.filter_log()
            .map_err(|source| Error::Refused { file: None, source })
    }

    fn filter_log(self) -> Result<FilterLog<'a>, kalibra_eval::EvalError> {
        let mut log = FilterLog::new(self.runs, self.steps)?;
        if let Some(t) = self.time {
            log = log.with_times(t)?;
        }
        if let Some(a) = self.truth {
            log = log.with_truth(vectors(a))?;
        }
        if let Some(a) = self.estimate {
            log = log.with_estimate(vectors(a))?;
        }
        if let Some(a) = self.covariance {
            log = log.with_covariance(matrices(a))?;
        }
        if let Some(a) = self.innovation {
            log = log.with_innovation(vectors(a))?;
        }
        if let Some(a) = self.innovation_cov {
            log = log.with_innovation_cov(matrices(a))?;
        }
        if let Some([f, h, q, r]) = self.model {
            log = log.with_model(f.matrices(), h.matrices(), q.matrices(), r.matrices())?;
        }
        Ok(log)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_listed_names_are_the_names() {
        assert_eq!(KNOWN, ARRAY_NAMES.join(", "));
    }
}
