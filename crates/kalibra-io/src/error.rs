//! The one error of the readers and the writer: each variant carries where the input is at
//! fault (the file, the CSV row and column, the array and index, the MODEL.toml key), and
//! displays as the one message the command line prints.

use std::path::{Path, PathBuf};

use kalibra_eval::EvalError;
use kalibra_tune::TuneError;

/// What went wrong reading a log, a model or a series, or writing a report.
///
/// Every variant displays as one message that names the file (or the array, for arrays handed
/// over in memory) and where in it; the fields hold the same facts for a program to act on.
/// Rows and columns of a CSV file count from 1, the header being row 1, as the messages and a
/// spreadsheet show them; indices of arrays count from 0.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file or directory that cannot be read or written.
    #[error("{}: cannot {action}: {source}", .file.display())]
    Io {
        /// The file or directory.
        file: PathBuf,
        /// What was tried (`"read the file"`, `"write report.json"`, ...).
        action: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A CSV file (a log, measurements or truth) at fault, at a row and column where known.
    #[error("{}: {}{message}", .file.display(), csv_place(.row, .column, .column_name))]
    Csv {
        /// The file.
        file: PathBuf,
        /// The row, from 1 (the header is row 1).
        row: Option<u64>,
        /// The column, from 1.
        column: Option<usize>,
        /// The column's header, where the message names it.
        column_name: Option<String>,
        /// What is wrong there.
        message: String,
    },
    /// A JSON log that is not JSON, or not an object, at a line and column where known.
    #[error("{}: {}{message}", .file.display(), text_place(&None, .line, .column))]
    Json {
        /// The file.
        file: PathBuf,
        /// The line, from 1.
        line: Option<usize>,
        /// The column (in characters on the line), from 1.
        column: Option<usize>,
        /// What is wrong there.
        message: String,
    },
    /// An array of a log at fault: an entry of an NPZ archive, an array of a JSON log, or an
    /// array handed over in memory ([`crate::input::log_from_arrays`], where `file` is `None`).
    #[error("{}{message}", file_prefix(.file))]
    Array {
        /// The log's file, `None` for arrays handed over in memory.
        file: Option<PathBuf>,
        /// The array's name (`truth`, `covariance`, `F`, ...), as the log spells it.
        array: String,
        /// Where in the array, outermost axis first (`[2, 5, 1]` for `covariance[2][5][1]`);
        /// empty when the array as a whole is at fault.
        index: Vec<usize>,
        /// The message, naming the array.
        message: String,
    },
    /// A log at fault as a whole (no array of it is): nothing to evaluate, an archive that is
    /// not one.
    #[error("{}{message}", file_prefix(.file))]
    Log {
        /// The log's file, `None` for arrays handed over in memory.
        file: Option<PathBuf>,
        /// What is wrong.
        message: String,
    },
    /// The arrays read, refused by `kalibra_eval::FilterLog` (which names the array, and the
    /// run and step where one is at fault).
    #[error("{}{source}", file_prefix(.file))]
    Refused {
        /// The log's file, `None` for arrays handed over in memory.
        file: Option<PathBuf>,
        /// The evaluation's error.
        source: EvalError,
    },
    /// The evaluation of a log read as it streams refused it (at a CSV row, where known).
    #[error("{}: {}cannot evaluate the log: {source}", .file.display(), csv_place(.row, &None, &None))]
    Evaluate {
        /// The log's file.
        file: PathBuf,
        /// The CSV row, from 1, when the row is known.
        row: Option<u64>,
        /// The evaluation's error.
        source: EvalError,
    },
    /// MODEL.toml at fault, at a key, or a line and column, where known.
    #[error("{}: {}{message}", .file.display(), text_place(.key, .line, .column))]
    Model {
        /// The file.
        file: PathBuf,
        /// The top-level key (`F`, `x0`, ...).
        key: Option<String>,
        /// The line, from 1.
        line: Option<usize>,
        /// The column (in characters on the line), from 1.
        column: Option<usize>,
        /// What is wrong there.
        message: String,
    },
    /// The tuning problem refused the model (or the truth) of `file`.
    #[error("{}: {source}", .file.display())]
    Tune {
        /// The model's file, or the truth's for an error of the truth.
        file: PathBuf,
        /// The tuning's error.
        source: TuneError,
    },
    /// A file whose name or kind is wrong (an unknown extension, not an NPZ archive).
    #[error("{}: {message}", .file.display())]
    File {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The directory a report is written to cannot take it.
    #[error("{}: {message}", .dir.display())]
    Output {
        /// The directory, as given.
        dir: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The directory a report is written to is an empty path (which would be the current
    /// directory).
    #[error("the output directory is an empty path; name a directory")]
    EmptyOutput,
}

/// `row R, column C (NAME): `, as much of it as is known.
fn csv_place(row: &Option<u64>, column: &Option<usize>, name: &Option<String>) -> String {
    let mut place = String::new();
    if let Some(row) = row {
        place.push_str(&format!("row {row}"));
    }
    if let Some(column) = column {
        if !place.is_empty() {
            place.push_str(", ");
        }
        place.push_str(&format!("column {column}"));
        if let Some(name) = name {
            place.push_str(&format!(" ({name})"));
        }
    }
    if !place.is_empty() {
        place.push_str(": ");
    }
    place
}

/// `key K, line L, column C: `, as much of it as is known.
fn text_place(key: &Option<String>, line: &Option<usize>, column: &Option<usize>) -> String {
    let mut parts = Vec::new();
    if let Some(key) = key {
        parts.push(format!("key {key}"));
    }
    if let (Some(line), Some(column)) = (line, column) {
        parts.push(format!("line {line}, column {column}"));
    }
    if parts.is_empty() {
        String::new()
    } else {
        parts.join(", ") + ": "
    }
}

fn file_prefix(file: &Option<PathBuf>) -> String {
    file.as_ref()
        .map(|f| format!("{}: ", f.display()))
        .unwrap_or_default()
}

impl Error {
    /// The error with `file` named, where it names none yet (an error of arrays, given the
    /// file they were read from).
    pub(crate) fn in_file(mut self, path: &Path) -> Self {
        match &mut self {
            Error::Array { file, .. } | Error::Log { file, .. } | Error::Refused { file, .. }
                if file.is_none() =>
            {
                *file = Some(path.to_path_buf());
            }
            _ => {}
        }
        self
    }

    /// An error about the array `array` as a whole.
    pub(crate) fn array(array: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Array {
            file: None,
            array: array.into(),
            index: Vec::new(),
            message: message.into(),
        }
    }

    /// An error about the log as a whole.
    pub(crate) fn log(message: impl Into<String>) -> Self {
        Error::Log {
            file: None,
            message: message.into(),
        }
    }

    /// An error of `file` at `row` (or of the file as a whole).
    pub(crate) fn csv(file: &Path, row: Option<u64>, message: impl Into<String>) -> Self {
        Error::Csv {
            file: file.to_path_buf(),
            row,
            column: None,
            column_name: None,
            message: message.into(),
        }
    }

    /// A file that cannot be read.
    pub(crate) fn read(file: &Path, source: std::io::Error) -> Self {
        Error::Io {
            file: file.to_path_buf(),
            action: "read the file".to_string(),
            source,
        }
    }

    /// The evaluation of the log `file` refused it.
    pub(crate) fn evaluate(file: &Path, source: EvalError) -> Self {
        Error::Evaluate {
            file: file.to_path_buf(),
            row: None,
            source,
        }
    }

    /// The file the error names, if any.
    pub fn file(&self) -> Option<&Path> {
        match self {
            Error::Io { file, .. }
            | Error::Csv { file, .. }
            | Error::Json { file, .. }
            | Error::Evaluate { file, .. }
            | Error::Model { file, .. }
            | Error::Tune { file, .. }
            | Error::File { file, .. } => Some(file),
            Error::Array { file, .. } | Error::Log { file, .. } | Error::Refused { file, .. } => {
                file.as_deref()
            }
            Error::Output { dir, .. } => Some(dir),
            Error::EmptyOutput => None,
        }
    }
}
