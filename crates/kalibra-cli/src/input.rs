//! Reading a filter log: the format by extension, and the arrays both readers produce.

use std::borrow::Cow;
use std::path::Path;

use kalibra_eval::{Evaluation, FilterLog, Matrices, Report, Vectors};

/// The formats, as `kalibra eval --help` shows them.
pub const FORMATS_HELP: &str = "\
LOG FORMATS (chosen by the extension; R runs, K steps, n states, m measurements):
  .json  An object of arrays named as numpy's: truth (R,K,n), estimate (R,K,n),
         covariance (R,K,n,n), innovation (R,K,m), innovation_cov (R,K,m,m), optional
         time (K), and for J1/J2 all of F (n,n), H (m,n), Q (n,n), R (m,m), each one
         matrix for all steps, one per step (K,..) or one per run and step (R,K,..).
         A single run may drop the R axis. A cell (one run and step) that is null was
         not logged. Matrices are lists of rows. NaN, Infinity and -Infinity as
         Python's json.dump writes them are read as numbers: a cell of NaN alone was
         not logged (as in .npz); a cell partly NaN or infinite is kept, so a NaN
         covariance is a finding.
  .npz   numpy's np.savez (or np.savez_compressed) with the same array names and
         shapes as .json; a cell whose values are all NaN was not logged. float64,
         float32, int64 or int32, C order.
  .csv   One row per run and step. Columns: run, step, optional time, truth_i,
         estimate_i, covariance_i_j (every i, j; or the diagonal covariance_i_i alone),
         innovation_i, innovation_cov_i_j (or its diagonal), i and j from 0. An empty
         cell means not logged; a vector or matrix is logged whole or not at all.
         Rows and columns in messages count from 1, the header being row 1.
Truth, estimate and covariance give NEES/ANEES, NCI, RMSE and sliding windows;
innovation and innovation_cov give NIS/ANIS and whiteness; both give both.

EXIT CODES: 0 success, 1 bad input (the message names the file and the row and
column, or the array and index), 2 bad usage.";

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
    pub scope: kalibra_eval::Scope,
    pub data: Vec<f64>,
}

impl ModelArray {
    fn matrices(self) -> Matrices<'static> {
        match self.scope {
            kalibra_eval::Scope::Constant => Matrices::constant(self.rows, self.cols, self.data),
            kalibra_eval::Scope::PerStep => Matrices::per_step(self.rows, self.cols, self.data),
            kalibra_eval::Scope::PerRunStep => Matrices::dense(self.rows, self.cols, self.data),
        }
    }
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

/// The per-cell arrays, in the order the readers take them.
pub(crate) const PER_CELL: [&str; 5] = [
    "truth",
    "estimate",
    "covariance",
    "innovation",
    "innovation_cov",
];

/// Whether the model arrays `F`, `H`, `Q`, `R` are given; all four go together, so a log
/// with only some of them (`present`) is an error naming one that is missing.
pub(crate) fn model_given(present: &[&str]) -> Result<bool, String> {
    if present.is_empty() {
        return Ok(false);
    }
    match ["F", "H", "Q", "R"].iter().find(|m| !present.contains(m)) {
        Some(missing) => Err(format!(
            "arrays F, H, Q and R go together (for J1/J2); the log has {} but not {missing}",
            present.join(", ")
        )),
        None => Ok(true),
    }
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
    ) -> Result<(), String> {
        match self.shape_from {
            None => {
                self.shape_from = Some(array);
                (self.runs, self.steps) = (runs, steps);
            }
            Some(first) if (self.runs, self.steps) != (runs, steps) => {
                return Err(format!(
                    "array {array} has {runs} runs of {steps} steps, but array {first} has {} \
                     runs of {} steps",
                    self.runs, self.steps
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
                Err(format!(
                    "array {array} holds {rows}x{cols} matrices; a covariance is square"
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
    pub fn require_cells(&self) -> Result<(usize, usize), String> {
        match self.shape_from {
            Some(_) => Ok((self.runs, self.steps)),
            None => Err(
                "the log holds none of truth, estimate, covariance, innovation, innovation_cov"
                    .to_string(),
            ),
        }
    }

    /// The checked log; an error names the file and the array at fault.
    pub fn build(self, file: &Path) -> Result<FilterLog<'a>, String> {
        self.checked()
            .map_err(|e| format!("{}: {e}", file.display()))
    }

    /// The checked log; an error names the array at fault.
    fn checked(self) -> Result<FilterLog<'a>, kalibra_eval::EvalError> {
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

/// The log held by numpy-shaped arrays, read with the NPZ reader's rules: each item is an
/// array's name (`truth`, `estimate`, `covariance`, `innovation`, `innovation_cov`, `time`,
/// `F`, `H`, `Q`, `R`), its shape and its values in C (row-major) order. Per-cell arrays are
/// `(R, K, dim)` or `(R, K, dim, dim)`, or without the `R` axis for a single run; a cell whose
/// values are all NaN was not logged. This is how the Python package hands over numpy arrays,
/// so `kalibra.evaluate` and `kalibra eval log.npz` read the same arrays the same way.
///
/// # Errors
/// A message naming the array: an unknown name, a shape that fits none of the layouts, values
/// that do not fill the shape, arrays that disagree on runs or steps, `F`, `H`, `Q`, `R` not all
/// given, or what [`kalibra_eval::FilterLog`] refuses (naming the run and step).
///
/// # Example
/// ```
/// // One run of two steps of a scalar state; the second step's estimate was not logged.
/// let log = kalibra_cli::input::log_from_arrays(vec![
///     ("truth".to_string(), vec![2, 1], vec![0.0, 0.0]),
///     ("estimate".to_string(), vec![2, 1], vec![0.5, f64::NAN]),
///     ("covariance".to_string(), vec![2, 1, 1], vec![1.0, 1.0]),
/// ])?;
/// assert_eq!((log.runs(), log.steps()), (1, 2));
/// # Ok::<(), String>(())
/// ```
pub fn log_from_arrays<'a, D: Into<Cow<'a, [f64]>>>(
    arrays: Vec<(String, Vec<usize>, D)>,
) -> Result<FilterLog<'a>, String> {
    let mut named = std::collections::BTreeMap::new();
    for (name, shape, data) in arrays {
        let data = data.into();
        // Checked: the shape comes from the caller, and a product that wraps could match a
        // short buffer.
        let size = shape.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
        if size != Some(data.len()) {
            return Err(format!(
                "array {name} holds {} values for shape {shape:?}",
                data.len()
            ));
        }
        named.insert(name, crate::arrays::Array { shape, data });
    }
    crate::arrays::build(named)?
        .checked()
        .map_err(|e| e.to_string())
}

/// A log's format, chosen by its file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// `.json`: an object of named arrays.
    Json,
    /// `.csv`: one row per run and step.
    Csv,
    /// `.npz`: numpy's archive of `.npy` arrays.
    Npz,
}

impl LogFormat {
    /// The format `path`'s extension names (case-insensitive).
    ///
    /// # Errors
    /// A message naming the file: no extension, or one that is not `.json`, `.csv` or `.npz`.
    pub fn of(path: &Path) -> Result<Self, String> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "csv" => Ok(Self::Csv),
            "json" => Ok(Self::Json),
            "npz" => Ok(Self::Npz),
            "" => Err(format!(
                "{}: no file extension; name the log .json, .csv or .npz",
                path.display()
            )),
            other => Err(format!(
                "{}: unknown extension `.{other}`; kalibra eval reads .json, .csv and .npz logs",
                path.display()
            )),
        }
    }
}

/// Evaluates the log `path` in the format its extension names: a CSV file streams through
/// the evaluation row by row; JSON and NPZ logs are read whole into a `FilterLog` (their
/// arrays are stored whole in the file).
///
/// # Errors
/// One message naming the file and where in it the input is at fault, or what the
/// evaluation refused.
pub fn evaluate_log(path: &Path, evaluation: &Evaluation) -> Result<Report, String> {
    match LogFormat::of(path)? {
        LogFormat::Csv => crate::csv_log::evaluate(path, evaluation),
        LogFormat::Json => evaluate_json(path, &read_bytes(path)?, evaluation),
        LogFormat::Npz => crate::npz_log::evaluate(path, evaluation),
    }
}

/// Evaluates a log held in memory, `bytes` in `format`, with the rules and messages of
/// [`evaluate_log`] (`name` is the file the messages name). This is the readers' entry point
/// for the fuzz targets (`fuzz/`) and the readers' property test: every input is an error
/// or a report, never a panic, and memory stays proportional to `bytes`.
///
/// # Errors
/// As [`evaluate_log`].
pub fn evaluate_bytes(
    name: &Path,
    format: LogFormat,
    bytes: &[u8],
    evaluation: &Evaluation,
) -> Result<Report, String> {
    match format {
        LogFormat::Csv => crate::csv_log::evaluate_bytes(name, bytes, evaluation),
        LogFormat::Json => evaluate_json(name, bytes, evaluation),
        LogFormat::Npz => crate::npz_log::evaluate_bytes(name, bytes, evaluation),
    }
}

fn evaluate_json(path: &Path, bytes: &[u8], evaluation: &Evaluation) -> Result<Report, String> {
    let log = crate::json_log::read(path, bytes)?.build(path)?;
    evaluation
        .evaluate(&log)
        .map_err(|e| evaluation_error(path.display(), &e))
}

/// The message of an error evaluating the log `file`. A `--group` naming a component the
/// log's state does not have is the option's fault, not the log's, and says so.
pub(crate) fn evaluation_error(
    file: impl std::fmt::Display,
    e: &kalibra_eval::EvalError,
) -> String {
    match e {
        kalibra_eval::EvalError::GroupIndex { group, index, dim } => format!(
            "--group {group}: component {index} is not in the state of {file}, which has {dim} \
             components (0 to {})",
            dim.saturating_sub(1)
        ),
        other => format!("{file}: cannot evaluate the log: {other}"),
    }
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, String> {
    std::fs::read(path).map_err(|e| format!("{}: cannot read the file: {e}", path.display()))
}
