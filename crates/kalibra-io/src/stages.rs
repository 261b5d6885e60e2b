//! Where the time of `kalibra eval` goes, stage by stage, for `cargo xtask bench eval`: each
//! stage of a reader run alone on one thread, one after another, with the file held in
//! memory. Nothing here runs when a log is evaluated: the readers carry no timing code. Not
//! part of the stable API.

use std::path::Path;

use kalibra_eval::{Evaluation, Report};

use crate::error::Error;
use crate::input::LogFormat;

/// Seconds per stage.
#[derive(Clone, Copy, Debug)]
pub struct Stages {
    /// Reading the file into memory (and, for a CSV, cutting it into blocks at record ends).
    pub read: f64,
    /// CSV: finding the rows and fields (the line ends and commas, counted with memchr);
    /// JSON: the first pass, finding where each array lies.
    pub tokenise: f64,
    /// CSV: reading the rows with their numbers, less the tokenising (the reader finds the
    /// fields as it parses the numbers); JSON: the second pass, the cells and their numbers on
    /// a reader thread with the evaluation on this one (so `evaluate` is NaN).
    pub parse: f64,
    /// CSV: feeding the parsed cells to the evaluator and finishing the report.
    pub evaluate: f64,
    /// CSV: the fields; JSON: the cells of the per-cell arrays.
    pub values: usize,
}

/// The stages of evaluating the log `path` (CSV or JSON; `None` for an NPZ log, whose values
/// need no tokenising or parsing, or a JSON log the streaming reader does not take), and the
/// report.
///
/// # Errors
/// As [`crate::input::evaluate_log`].
pub fn stages(path: &Path, evaluation: &Evaluation) -> Result<Option<(Stages, Report)>, Error> {
    match LogFormat::of(path)? {
        LogFormat::Csv => crate::csv_log::stages(path, evaluation).map(Some),
        LogFormat::Json => crate::json_stream::stages(path, evaluation),
        LogFormat::Npz => Ok(None),
    }
}
