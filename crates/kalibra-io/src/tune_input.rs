//! Reading `kalibra tune`'s inputs: MODEL.toml into a `kalibra_tune::TuneProblem`, and the
//! measurement and truth CSVs into sequences with gaps.

use std::path::Path;

use kalibra_tune::{DMatrix, DVector, Start, TuneProblem, matrix_from_rows};
use serde::Deserialize;

use crate::csv_rows::Rows;
use crate::error::Error;

/// The formats, as `kalibra tune --help` shows them.
pub const TUNE_HELP: &str = "\
MODEL.toml (n states, m measurements; matrices are arrays of rows):
  F = [[1.0, 1.0], [0.0, 1.0]]   n x n dynamics
  H = [[1.0, 0.0]]               m x n measurement matrix
  Q = [[0.25, 0.5], [0.5, 1.0]]  n x n nominal process noise (swept as 10^p Q)
  R = [[4.0]]                    m x m measurement noise
  x0 = [0.0, 0.0]                initial estimate (n values)
  P0 = [[10.0, 0.0], [0.0, 10.0]] initial covariance
  p0_as_given = true             optional: take P0 as given (asymmetric or indefinite)
  start = \"predict_first\"        optional: x0 is one step before the first measurement
                                 (default), or \"update_first\": at it
  position = [0]                 optional: state components of the position RMSE
  Any other key is an error.
MEASUREMENTS.csv: columns step, z_0, ..., z_{m-1} (components count from 0, as in
  kalibra eval's CSV); one row per step, steps 0, 1, ..., K-1 in order. A row whose
  z cells are all empty has no measurement; a partly empty row is an error.
TRUTH.csv: columns step, x_0, ..., x_{n-1}, the same K steps (empty row: unknown).
  Rows and columns in messages count from 1, the header being row 1.

EXIT CODES: 0 success, 1 bad input (the message names the file and the key, or the
row and column), 2 bad usage (a bad --p is usage).";

/// MODEL.toml as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    #[serde(rename = "F")]
    f: Vec<Vec<f64>>,
    #[serde(rename = "H")]
    h: Vec<Vec<f64>>,
    #[serde(rename = "Q")]
    q: Vec<Vec<f64>>,
    #[serde(rename = "R")]
    r: Vec<Vec<f64>>,
    x0: Vec<f64>,
    #[serde(rename = "P0")]
    p0: Vec<Vec<f64>>,
    #[serde(default)]
    p0_as_given: bool,
    #[serde(default)]
    start: Option<StartName>,
    #[serde(default)]
    position: Option<Vec<usize>>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum StartName {
    PredictFirst,
    UpdateFirst,
}

/// The model of MODEL.toml, checked for shape only (the problem checks the rest).
pub struct Model {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    as_given: bool,
    start: Start,
    /// The position components, if given.
    pub position: Option<Vec<usize>>,
}

impl Model {
    /// `n`.
    pub fn state_dim(&self) -> usize {
        self.f.nrows()
    }

    /// `m`.
    pub fn meas_dim(&self) -> usize {
        self.h.nrows()
    }

    /// The tuning problem on these measurements (and truth, read from its file).
    ///
    /// # Errors
    /// [`Error::Tune`] naming `file`, the model's file, or the truth's file for an error of the
    /// truth.
    pub fn problem(
        &self,
        file: &Path,
        measurements: Vec<Option<DVector<f64>>>,
        truth: Option<(&Path, Vec<Option<DVector<f64>>>)>,
    ) -> Result<TuneProblem, Error> {
        let build = if self.as_given {
            TuneProblem::as_given
        } else {
            TuneProblem::new
        };
        let problem = build(
            self.f.clone(),
            self.h.clone(),
            self.q.clone(),
            self.r.clone(),
            self.x0.clone(),
            self.p0.clone(),
            measurements,
        )
        .map_err(|source| Error::Tune {
            file: file.to_path_buf(),
            source,
        })?
        .with_start(self.start);
        match truth {
            Some((path, t)) => problem.with_truth(t).map_err(|source| Error::Tune {
                file: path.to_path_buf(),
                source,
            }),
            None => Ok(problem),
        }
    }
}

/// Line and column (from 1) of a byte offset.
fn line_column(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// The top-level key whose line holds byte `at`: the last `KEY =` starting a line up to the
/// end of `at`'s line (MODEL.toml has no tables).
fn key_before(text: &str, at: usize) -> Option<&str> {
    let at = at.min(text.len());
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    text[..end].lines().rev().find_map(|l| {
        let (key, _) = l.split_once('=')?;
        let key = key.trim();
        (!key.is_empty()
            && !l.starts_with([' ', '\t', '['])
            && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
        .then_some(key)
    })
}

/// Reads MODEL.toml at `path`.
///
/// # Errors
/// [`Error::Io`] for a file that cannot be read; [`Error::Model`] naming the key, or the line
/// and column, at fault.
pub fn read_model(path: &Path) -> Result<Model, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
    parse_model(path, &text)
}

/// Reads MODEL.toml from `text` (the file `path`, as messages name it): [`read_model`] on text
/// in memory, the entry point of the fuzz targets and the readers' property test.
///
/// # Errors
/// As [`read_model`].
pub fn parse_model(path: &Path, text: &str) -> Result<Model, Error> {
    let at_key = |key: &str, message: String| Error::Model {
        file: path.to_path_buf(),
        key: Some(key.to_string()),
        line: None,
        column: None,
        message,
    };
    let file: ModelFile = toml::from_str(text).map_err(|e| {
        let (key, line, column) = match e.span() {
            Some(s) => {
                let (line, column) = line_column(text, s.start);
                let key = key_before(text, s.start).map(str::to_string);
                (key, Some(line), Some(column))
            }
            None => (None, None, None),
        };
        // serde's messages name the key (`unknown field `X``, `missing field `F``); a value of
        // the wrong type is located by its line and column.
        Error::Model {
            file: path.to_path_buf(),
            key,
            line,
            column,
            message: e.message().trim_end().replace('\n', "; "),
        }
    })?;
    let matrix = |key: &'static str, rows: &[Vec<f64>]| {
        matrix_from_rows(key, rows).map_err(|e| at_key(key, e.to_string()))
    };
    if file.x0.is_empty() {
        return Err(at_key("x0", "holds no values".to_string()));
    }
    Ok(Model {
        f: matrix("F", &file.f)?,
        h: matrix("H", &file.h)?,
        q: matrix("Q", &file.q)?,
        r: matrix("R", &file.r)?,
        x0: DVector::from_vec(file.x0),
        p0: matrix("P0", &file.p0)?,
        as_given: file.p0_as_given,
        start: match file.start {
            None | Some(StartName::PredictFirst) => Start::PredictFirst,
            Some(StartName::UpdateFirst) => Start::UpdateFirst,
        },
        position: file.position,
    })
}

/// Reads a CSV of `step` and `{prefix}_0 .. {prefix}_{dim-1}` at `path`: one entry per step,
/// `None` for a row whose value cells are all empty. `what` names `dim` in messages
/// ("H has 2 rows").
///
/// # Errors
/// [`Error::Io`] for a file that cannot be read; [`Error::Csv`] naming the row and column at
/// fault.
pub fn read_series(
    path: &Path,
    prefix: &str,
    dim: usize,
    what: &str,
) -> Result<Vec<Option<DVector<f64>>>, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::read(path, e))?;
    parse_series(path, &bytes, prefix, dim, what)
}

/// [`read_series`] of the CSV in `bytes` (the file `path`, as messages name it).
///
/// # Errors
/// As [`read_series`], and a `dim` of 0 (no model has one).
pub fn parse_series(
    path: &Path,
    bytes: &[u8],
    prefix: &str,
    dim: usize,
    what: &str,
) -> Result<Vec<Option<DVector<f64>>>, Error> {
    if dim == 0 {
        return Err(Error::csv(
            path,
            None,
            format!("{what}, so no {prefix} columns can be read"),
        ));
    }
    let mut rows_in = Rows::new(path, bytes)?;
    let header = rows_in.header.clone();
    let expected: Vec<String> = std::iter::once("step".to_string())
        .chain((0..dim).map(|i| format!("{prefix}_{i}")))
        .collect();
    let listing = format!(
        "step, {prefix}_0, ..., {prefix}_{} ({what}; components count from 0)",
        dim - 1
    );
    if header.len() != expected.len() {
        let found = header.len().saturating_sub(1);
        return Err(Error::csv(
            path,
            Some(1),
            format!(
                "{found} value column(s), but {what}, so {dim} are expected; the columns are \
                 {listing}"
            ),
        ));
    }
    for (c, (h, want)) in header.iter().zip(&expected).enumerate() {
        if h != want {
            let hint = if c == 1 && h == format!("{prefix}_1") {
                format!("; columns count from 0: the first is `{prefix}_0`, not `{prefix}_1`")
            } else {
                String::new()
            };
            return Err(rows_in.header_error(
                c,
                format!("`{h}` where `{want}` is expected{hint}; the columns are {listing}"),
            ));
        }
    }
    let mut out = Vec::new();
    let mut record = csv::StringRecord::new();
    while let Some(line) = rows_in.next_row(&mut record)? {
        let cell = |c: usize, msg: String| rows_in.cell_error(line, c, msg);
        let step_text = &record[0];
        let step: usize = step_text.parse().map_err(|_| {
            cell(
                0,
                format!("`{step_text}` is not a whole number (0, 1, ...)"),
            )
        })?;
        if step != out.len() {
            return Err(cell(
                0,
                format!(
                    "step {step} where step {} is expected (steps run 0, 1, ... in order, one \
                     row each)",
                    out.len()
                ),
            ));
        }
        let values = (1..=dim)
            .map(|c| {
                let text = &record[c];
                if text.is_empty() {
                    Ok(None)
                } else {
                    text.parse::<f64>()
                        .map(Some)
                        .map_err(|_| cell(c, format!("`{text}` is not a number")))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let present = values.iter().filter(|v| v.is_some()).count();
        if present == 0 {
            out.push(None);
        } else if present < dim {
            let empty = values.iter().position(Option::is_none).unwrap_or(0) + 1;
            let full = values.iter().position(Option::is_some).unwrap_or(0) + 1;
            return Err(cell(
                empty,
                format!(
                    "empty, but column {} ({}) is not; a row is given whole or left all empty",
                    full + 1,
                    &header[full]
                ),
            ));
        } else {
            out.push(Some(DVector::from_iterator(
                dim,
                values.into_iter().flatten(),
            )));
        }
    }
    if out.is_empty() {
        return Err(Error::csv(path, None, "no data rows after the header"));
    }
    Ok(out)
}
