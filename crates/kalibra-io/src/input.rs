//! Reading a filter log: the format by extension, and the arrays both readers produce.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

use kalibra_eval::{Evaluation, FilterLog, Report};

use crate::error::Error;

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

/// The log held by numpy-shaped arrays, read with the NPZ reader's rules: each item is an
/// array's name (`truth`, `estimate`, `covariance`, `innovation`, `innovation_cov`, `time`,
/// `F`, `H`, `Q`, `R`), its shape and its values in C (row-major) order. Per-cell arrays are
/// `(R, K, dim)` or `(R, K, dim, dim)`, or without the `R` axis for a single run; a cell whose
/// values are all NaN was not logged. This is how the Python package hands over numpy arrays,
/// so `kalibra.evaluate` and `kalibra eval log.npz` read the same arrays the same way.
///
/// # Errors
/// [`Error::Array`] naming the array: an unknown name, a shape that fits none of the layouts,
/// values that do not fill the shape, arrays that disagree on runs or steps, `F`, `H`, `Q`, `R`
/// not all given; [`Error::Log`] for no per-cell array; [`Error::Refused`] for what
/// [`kalibra_eval::FilterLog`] refuses (naming the array, and the run and step).
///
/// # Example
/// ```
/// // One run of two steps of a scalar state; the second step's estimate was not logged.
/// let log = kalibra_io::input::log_from_arrays(vec![
///     ("truth".to_string(), vec![2, 1], vec![0.0, 0.0]),
///     ("estimate".to_string(), vec![2, 1], vec![0.5, f64::NAN]),
///     ("covariance".to_string(), vec![2, 1, 1], vec![1.0, 1.0]),
/// ])?;
/// assert_eq!((log.runs(), log.steps()), (1, 2));
/// # Ok::<(), kalibra_io::Error>(())
/// ```
pub fn log_from_arrays<'a, D: Into<Cow<'a, [f64]>>>(
    arrays: Vec<(String, Vec<usize>, D)>,
) -> Result<FilterLog<'a>, Error> {
    let mut named = BTreeMap::new();
    for (name, shape, data) in arrays {
        let data = data.into();
        // Checked: the shape comes from the caller, and a product that wraps could match a
        // short buffer.
        let size = shape.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
        if size != Some(data.len()) {
            let message = format!(
                "array {name} holds {} values for shape {shape:?}",
                data.len()
            );
            return Err(Error::array(name, message));
        }
        named.insert(name, crate::arrays::Array { shape, data });
    }
    crate::arrays::build(named)?.checked()
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
    /// [`Error::File`]: no extension, or one that is not `.json`, `.csv` or `.npz`.
    pub fn of(path: &Path) -> Result<Self, Error> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "csv" => Ok(Self::Csv),
            "json" => Ok(Self::Json),
            "npz" => Ok(Self::Npz),
            "" => Err(Error::File {
                file: path.to_path_buf(),
                message: "no file extension; name the log .json, .csv or .npz".to_string(),
            }),
            other => Err(Error::File {
                file: path.to_path_buf(),
                message: format!(
                    "unknown extension `.{other}`; kalibra eval reads .json, .csv and .npz logs"
                ),
            }),
        }
    }
}

/// Evaluates the log `path` in the format its extension names: every format streams through
/// the evaluation, a CSV file row by row, NPZ and JSON logs run by run with their arrays read
/// side by side; a JSON log outside the layout the streaming reader takes (or one with an
/// error, whose message names the line and column or the array and index) is read whole.
///
/// # Errors
/// An [`Error`] naming the file and where in it the input is at fault, or what the
/// evaluation refused ([`Error::Evaluate`]: a `group` of the evaluation naming a component
/// the log's state does not have is one).
pub fn evaluate_log(path: &Path, evaluation: &Evaluation) -> Result<Report, Error> {
    match LogFormat::of(path)? {
        LogFormat::Csv => crate::csv_log::evaluate(path, evaluation),
        LogFormat::Json => {
            let source = || std::fs::File::open(path);
            if let Ok(report) = crate::json_stream::evaluate(&source, evaluation) {
                return Ok(report);
            }
            let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
            evaluate_json(path, &bytes, evaluation)
        }
        LogFormat::Npz => crate::npz_log::evaluate(path, evaluation),
    }
}

/// Evaluates a log held in memory, `bytes` in `format`, with the rules and messages of
/// [`evaluate_log`] (`name` is the file the messages name). This is the readers' entry point
/// for the fuzz targets (`fuzz/`) and the readers' property test (`tests/readers_fuzz.rs`):
/// every input is an error or a report, never a panic, and memory stays proportional to
/// `bytes`.
///
/// # Errors
/// As [`evaluate_log`].
pub fn evaluate_bytes(
    name: &Path,
    format: LogFormat,
    bytes: &[u8],
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    match format {
        LogFormat::Csv => crate::csv_log::evaluate_bytes(name, bytes, evaluation),
        LogFormat::Json => {
            let source = || Ok(std::io::Cursor::new(bytes));
            match crate::json_stream::evaluate(&source, evaluation) {
                Ok(report) => Ok(report),
                Err(_) => evaluate_json(name, bytes, evaluation),
            }
        }
        LogFormat::Npz => crate::npz_log::evaluate_bytes(name, bytes, evaluation),
    }
}

pub(crate) fn evaluate_json(
    path: &Path,
    bytes: &[u8],
    evaluation: &Evaluation,
) -> Result<Report, Error> {
    let log = crate::json_log::read(path, bytes)?
        .checked()
        .map_err(|e| e.in_file(path))?;
    evaluation
        .evaluate(&log)
        .map_err(|e| Error::evaluate(path, e))
}
