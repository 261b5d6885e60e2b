//! Reading `kalibra tune`'s inputs: MODEL.toml into a `kalibra_tune::TuneProblem`, and the
//! measurement and truth CSVs into sequences with gaps.

use std::path::Path;

use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, FormKind, NoiseError, NoiseProblem, Parametrisation, Run,
    Start, TuneProblem, matrix_from_rows,
};
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
  G = [[0.5], [1.0]]             optional: n x g, noise entering through g channels,
                                 Q = G Qw G^T (then the Q given is the g x g Qw)
  Any other key is an error.
  For --method ml, em, als or j1j2, Q and R may each be a table (after the keys above):
    [Q]
    form = \"diagonal\"            fixed (the value), scaled (a positive multiple of the
                                 value), diagonal (each diagonal entry free and positive)
                                 or full (any symmetric positive-definite matrix)
    value = [[0.1, 0.0], [0.0, 1.0]]  the fixed value, the nominal or the starting point
    fixed = [[1, 1]]             optional: entries [row, col] (from 0) held at the value
                                 (diagonal and full forms)
  or inline: R = { form = \"scaled\", value = [[4.0]] }. A plain Q matrix is the scaled
  form, a plain R the fixed one. At most n m + m (m + 1) / 2 parameters can be free.
MEASUREMENTS.csv: columns step, z_0, ..., z_{m-1} (components count from 0, as in
  kalibra eval's CSV); one row per step, steps 0, 1, ..., K-1 in order. A row whose
  z cells are all empty has no measurement (als needs every step); a partly empty row
  is an error.
TRUTH.csv: columns step, x_0, ..., x_{n-1}, the same K steps (empty row: unknown).
  Rows and columns in messages count from 1, the header being row 1.

METHODS: without --method, a file with plain Q and R and no G is swept as Q = 10^p Q
  (the J1/J2 crossover; --p, --threads), any other file is estimated by ml. ml: maximum
  likelihood with standard errors, 95% intervals and identifiability; em:
  expectation-maximisation (--iterations N runs exactly N iterations); als:
  autocovariance least squares; j1j2: the J1/J2 crossover of every free parameter, each
  multiplied by 10^p over --p (default -3:3:0.25) around the starting point.

EXIT CODES: 0 success, 1 bad input (the message names the file and the key, or the
row and column) or an estimator that failed, 2 bad usage (a bad --p is usage).";

/// MODEL.toml as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    #[serde(rename = "F")]
    f: Vec<Vec<f64>>,
    #[serde(rename = "H")]
    h: Vec<Vec<f64>>,
    #[serde(rename = "G", default)]
    g: Option<Vec<Vec<f64>>>,
    #[serde(rename = "Q")]
    q: NoiseSpec,
    #[serde(rename = "R")]
    r: NoiseSpec,
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

/// `Q` or `R` as written: a plain matrix (today's files) or a table with a form.
#[derive(Debug)]
enum NoiseSpec {
    Matrix(Vec<Vec<f64>>),
    Form(FormTable),
}

/// The table `[Q]` or `[R]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FormTable {
    form: FormKind,
    value: Vec<Vec<f64>>,
    #[serde(default)]
    fixed: Vec<[usize; 2]>,
}

impl<'de> Deserialize<'de> for NoiseSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = NoiseSpec;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(
                    "a matrix (an array of rows) or a table with `form` and `value` (and \
                     optionally `fixed`)",
                )
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                seq: A,
            ) -> Result<NoiseSpec, A::Error> {
                Vec::<Vec<f64>>::deserialize(serde::de::value::SeqAccessDeserializer::new(seq))
                    .map(NoiseSpec::Matrix)
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> Result<NoiseSpec, A::Error> {
                FormTable::deserialize(serde::de::value::MapAccessDeserializer::new(map))
                    .map(NoiseSpec::Form)
            }
        }
        d.deserialize_any(Visit)
    }
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(rename_all = "snake_case")]
enum StartName {
    PredictFirst,
    UpdateFirst,
}

/// `Q` or `R` of MODEL.toml, checked for shape: its form (`None` for a plain matrix), the
/// matrix and the fixed entries.
#[derive(Debug, Clone)]
struct Noise {
    form: Option<FormKind>,
    value: DMatrix<f64>,
    fixed: Vec<(usize, usize)>,
}

impl Noise {
    /// The form the estimators take: a plain matrix is `plain`'s form (scaled for `Q`, whose
    /// multiplier today's sweep varies; fixed for `R`, which it never changes).
    fn form(&self, plain: FormKind) -> CovarianceForm {
        let v = self.value.clone();
        let form = match self.form.unwrap_or(plain) {
            FormKind::Fixed => CovarianceForm::fixed(v),
            FormKind::Scaled => CovarianceForm::scaled(v),
            FormKind::Diagonal => CovarianceForm::diagonal(v),
            FormKind::Full => CovarianceForm::full(v),
        };
        self.fixed.iter().fold(form, |f, &(i, j)| f.fix(i, j))
    }
}

/// The model of MODEL.toml, checked for shape only (the problem checks the rest).
pub struct Model {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    g: Option<DMatrix<f64>>,
    q: Noise,
    r: Noise,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    as_given: bool,
    start: Start,
    /// The position components, if given.
    pub position: Option<Vec<usize>>,
    /// Line and column (from 1) where each top-level key or table is defined.
    places: Vec<(String, usize, usize)>,
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

    /// Whether the file is today's sweep model: plain `Q` and `R` matrices and no `G`, which
    /// `kalibra tune` without `--method` sweeps as `Q = 10^p Q_nom`.
    pub fn is_plain(&self) -> bool {
        self.g.is_none() && self.q.form.is_none() && self.r.form.is_none()
    }

    /// The noise estimation problem on these runs of measurements: `Q = G Qw G^T` and `R` in
    /// the forms of their tables (a plain `Q` matrix is scaled, a plain `R` fixed).
    ///
    /// # Errors
    /// [`Error::Model`] naming `file`, the key at fault (`G`, `Q`, `R`, `F`, `H`, `x0`,
    /// `P0`) and its line and column, for a parametrisation or model the estimators refuse
    /// (a wrong shape, a matrix that is not a covariance, more free parameters than the data
    /// can identify); [`Error::Csv`] naming `measurements` and the row of a non-finite
    /// measurement.
    pub fn noise_problem(
        &self,
        file: &Path,
        measurements: &Path,
        runs: Vec<Run>,
    ) -> Result<NoiseProblem, Error> {
        let noise = Parametrisation::new(
            self.g.clone(),
            self.q.form(FormKind::Scaled),
            self.r.form(FormKind::Fixed),
        )
        .map_err(|e| self.noise_error(file, e))?;
        NoiseProblem::new(
            self.f.clone(),
            self.h.clone(),
            self.x0.clone(),
            self.p0.clone(),
            self.start,
            noise,
            runs,
        )
        .map_err(|e| match e {
            NoiseError::NonFiniteMeasurement { step, .. } => Error::Csv {
                file: measurements.to_path_buf(),
                row: Some(step as u64 + 2),
                column: None,
                column_name: None,
                message: "holds a non-finite value (NaN or an infinity); leave the row's z \
                          cells empty for a step without a measurement"
                    .to_string(),
            },
            other => self.noise_error(file, other),
        })
    }

    /// A refusal of the estimators as an error of MODEL.toml at the key it concerns.
    fn noise_error(&self, file: &Path, e: NoiseError) -> Error {
        let key = match &e {
            NoiseError::Shape { matrix, .. }
            | NoiseError::Matrix { matrix, .. }
            | NoiseError::NotDiagonal { matrix, .. }
            | NoiseError::ZeroNominal { matrix }
            | NoiseError::FixedEntryOutOfRange { matrix, .. }
            | NoiseError::FixedEntryInScaled { matrix }
            | NoiseError::Infeasible { matrix, .. } => Some(file_key(matrix)),
            NoiseError::Empty { what } | NoiseError::NonFinite { what } => Some(file_key(what)),
            NoiseError::NotPositive { name, .. } => Some(if name.starts_with('R') || name == "r" {
                "R"
            } else {
                "Q"
            }),
            _ => None,
        };
        let (line, column) = key
            .and_then(|k| self.places.iter().find(|(p, _, _)| p == k))
            .map_or((None, None), |(_, l, c)| (Some(*l), Some(*c)));
        let message = match (&e, self.g.is_some()) {
            // The library names `Q`'s form `Qw`, the matrix of the noise channels; without
            // `G` the file's `Q` is that matrix.
            (_, false) => e.to_string().replace("Qw", "Q"),
            _ => e.to_string(),
        };
        Error::Model {
            file: file.to_path_buf(),
            key: key.map(str::to_string),
            line,
            column,
            message,
        }
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
            self.q.value.clone(),
            self.r.value.clone(),
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

/// The key of MODEL.toml that holds the library's matrix `name` (`Qw` is the file's `Q`).
fn file_key(name: &str) -> &'static str {
    match name {
        "F" => "F",
        "H" => "H",
        "G" => "G",
        "R" => "R",
        "x0" => "x0",
        "P0" => "P0",
        _ => "Q",
    }
}

/// Where each top-level key (`F = ...`) or table (`[Q]`) starts: line and column from 1.
fn places(text: &str) -> Vec<(String, usize, usize)> {
    let mut out = Vec::new();
    let mut in_table = false;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let column = line.len() - trimmed.len() + 1;
        if let Some(rest) = trimmed.strip_prefix('[')
            && let Some((name, _)) = rest.split_once(']')
        {
            in_table = true;
            out.push((name.trim().to_string(), i + 1, column));
        } else if !in_table
            && !line.starts_with([' ', '\t'])
            && let Some((key, _)) = trimmed.split_once('=')
        {
            let key = key.trim();
            if !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                out.push((key.to_string(), i + 1, column));
            }
        }
    }
    out
}

/// Line and column (from 1) of a byte offset.
fn line_column(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// The key whose line holds byte `at`: the last `KEY =` starting a line up to the end of
/// `at`'s line, as `TABLE.KEY` inside a table (`[Q]`), or the table itself when its header is
/// the last such line.
fn key_before(text: &str, at: usize) -> Option<String> {
    let at = at.min(text.len());
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    let mut table: Option<&str> = None;
    let mut found = None;
    for l in text[..end].lines() {
        if let Some(rest) = l.trim_start().strip_prefix('[')
            && let Some((name, _)) = rest.split_once(']')
        {
            table = Some(name.trim());
            found = Some(name.trim().to_string());
            continue;
        }
        let Some((key, _)) = l.split_once('=') else {
            continue;
        };
        let key = key.trim();
        if !key.is_empty()
            && !l.starts_with([' ', '\t', '['])
            && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            found = Some(match table {
                Some(t) => format!("{t}.{key}"),
                None => key.to_string(),
            });
        }
    }
    found
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
                let key = key_before(text, s.start);
                (key, Some(line), Some(column))
            }
            None => (None, None, None),
        };
        // serde's messages name the key (`unknown field `X``, `missing field `F``); a value of
        // the wrong type is located by its line and column.
        let mut message = e.message().trim_end().replace('\n', "; ");
        if message.starts_with("unknown field")
            && key
                .as_ref()
                .is_some_and(|k| k.starts_with("Q.") || k.starts_with("R."))
        {
            // TOML puts every key after `[Q]` into that table.
            message.push_str(
                " (a table [Q] or [R] holds form, value and fixed only; write the top-level \
                 keys before the first table)",
            );
        }
        Error::Model {
            file: path.to_path_buf(),
            key,
            line,
            column,
            message,
        }
    })?;
    let places = places(text);
    let located = |key: &str, message: String| {
        let (line, column) = places
            .iter()
            .find(|(p, _, _)| p == key)
            .map_or((None, None), |(_, l, c)| (Some(*l), Some(*c)));
        Error::Model {
            file: path.to_path_buf(),
            key: Some(key.to_string()),
            line,
            column,
            message,
        }
    };
    let matrix = |key: &'static str, rows: &[Vec<f64>]| {
        matrix_from_rows(key, rows).map_err(|e| at_key(key, e.to_string()))
    };
    let noise = |key: &'static str, spec: &NoiseSpec| match spec {
        NoiseSpec::Matrix(rows) => Ok(Noise {
            form: None,
            value: matrix(key, rows)?,
            fixed: Vec::new(),
        }),
        NoiseSpec::Form(table) => {
            let value = matrix_from_rows(key, &table.value)
                .map_err(|e| located(key, format!("value: {e}")))?;
            let dim = value.nrows();
            let mut fixed = Vec::new();
            for &[i, j] in &table.fixed {
                if i >= dim || j >= dim {
                    return Err(located(
                        key,
                        format!(
                            "fixed entry [{i}, {j}] is outside the {dim}x{dim} value (entries \
                             count from 0)"
                        ),
                    ));
                }
                fixed.push((i, j));
            }
            Ok(Noise {
                form: Some(table.form),
                value,
                fixed,
            })
        }
    };
    if file.x0.is_empty() {
        return Err(at_key("x0", "holds no values".to_string()));
    }
    let g = match &file.g {
        Some(rows) => Some(matrix_from_rows("G", rows).map_err(|e| located("G", e.to_string()))?),
        None => None,
    };
    Ok(Model {
        f: matrix("F", &file.f)?,
        h: matrix("H", &file.h)?,
        g,
        q: noise("Q", &file.q)?,
        r: noise("R", &file.r)?,
        x0: DVector::from_vec(file.x0),
        p0: matrix("P0", &file.p0)?,
        as_given: file.p0_as_given,
        start: match file.start {
            None | Some(StartName::PredictFirst) => Start::PredictFirst,
            Some(StartName::UpdateFirst) => Start::UpdateFirst,
        },
        position: file.position,
        places,
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
